"""The particle filter for any model: resampling to another count and from log-weights against Stone Soup's
resamplers (the same uniforms, so the same indices, where its API lets us give them; the closed-form count
distribution where it does not), one run without the run axis, kinematic motion x = F x + w (the process noise drawn
has covariance Q, singular or not; the posterior of a linear-Gaussian problem is the Kalman filter's), mirror
reflection at the walls, and the final log-weights against scipy's logsumexp."""
import numpy as np
import pytest
from scipy.special import logsumexp
from stonesoup.resampler import particle as ss_particle
from stonesoup.types.state import ParticleState, StateVectors

import locbook as lb
from locbook.tracking.particle import ParticleFilterResult, particle_filter
from locbook.tracking.resampling import RESAMPLING_METHODS, counts_to_indices


# -- resampling against Stone Soup ---------------------------------------------------------------------------------
def _stone_soup(resampler, weights, nparts=None):
    """Stone Soup's ancestor indices for ``weights (N,)`` (the particles' states are their indices)."""
    with np.errstate(divide="ignore"):                   # log(0) = -inf: a zero weight, in Stone Soup too
        log_w = np.log(weights / weights.sum())
        state = ParticleState(StateVectors(np.arange(weights.size, dtype=float)[None]), log_weight=log_w)
        return np.asarray(resampler.resample(state, nparts=nparts).state_vector)[0].astype(int)


def _weights(n, seed):
    rng = np.random.default_rng(seed)
    w = rng.random(n) ** 3
    w[rng.choice(n, 3, replace=False)] = 0.0            # zero weights are never drawn by either
    return w


@pytest.mark.parametrize("method", ["systematic", "stratified"])
@pytest.mark.parametrize("n_out", [None, 1, 8, 23, 64, 500])
@pytest.mark.parametrize("seed", range(4))
def test_systematic_and_stratified_give_stone_soups_indices_on_the_same_uniforms(method, n_out, seed, monkeypatch):
    """Stone Soup sums the weights sorted ascending (a stable argsort), locbook in the particles' order: on the sorted
    weights and the same uniforms the two draw the same particles, for N -> N and for N -> nparts (up and down)."""
    w = _weights(23, seed)
    m = w.size if n_out is None else n_out
    order = np.argsort(w, kind="stable")                # Stone Soup's order (of the log-weights: the same)
    # the uniforms locbook's resample draws from this seed: one per row (systematic), one per stratum (stratified),
    # given to Stone Soup as its np.random.uniform(low, high) = low + (high - low) u
    u = np.random.default_rng(100 + seed).random(() if method == "systematic" else (1, m)).reshape(-1)
    monkeypatch.setattr(np.random, "uniform", lambda low, high, size=None: low + (high - low) * (
        u if method == "stratified" else u[0]))
    theirs = _stone_soup({"systematic": ss_particle.SystematicResampler(),
                          "stratified": ss_particle.StratifiedResampler()}[method], w, n_out)
    ours = lb.resample(w[order], rng=np.random.default_rng(100 + seed), method=method, n_out=n_out)
    assert ours.shape == (m,)
    np.testing.assert_array_equal(order[ours], theirs)
    # the same from unnormalised log-weights far beyond exp's range, -inf for the zero weights
    with np.errstate(divide="ignore"):
        log_w = np.log(w[order]) + 1500.0
    ours_log = lb.resample(log_w, rng=np.random.default_rng(100 + seed), method=method, n_out=n_out, log_weights=True)
    np.testing.assert_array_equal(order[ours_log], theirs)
    assert np.all(w[theirs] > 0)


@pytest.mark.parametrize("n_out", [None, 3, 40])
def test_systematic_resample_with_n_out_is_algorithm_2_with_m_points(n_out):
    """Arulampalam et al. (2002), Alg. 2 written out with M sample points u_i = (u + i) / M."""
    rng = np.random.default_rng(7)
    for _ in range(20):
        w = rng.random(int(rng.integers(2, 30))) ** 2
        u = rng.random()
        m = w.size if n_out is None else n_out
        c, j, loop = np.cumsum(w / w.sum()), 0, []
        for i in range(m):
            while (u + i) / m > c[j]:
                j += 1
            loop.append(j)
        np.testing.assert_array_equal(lb.systematic_resample(w, u, n_out=n_out), loop)


W8 = np.array([0.02, 0.33, 0.05, 0.25, 0.01, 0.17, 0.12, 0.05])
DRAWS = 3000


def _count_rows(indices, n):
    return np.stack([np.bincount(row, minlength=n) for row in np.atleast_2d(indices)])


def _assert_binomial_law(counts, k, p, offset=0.0):
    """Each column of ``counts`` (DRAWS rows) minus ``offset`` against Binomial(k, p): the mean within 5 standard
    errors and the sample variance within 5 of its standard errors, sqrt((mu4 - var^2) / DRAWS) with the binomial
    mu4 = k p q (1 + 3 (k - 2) p q)."""
    var = k * p * (1 - p)
    mu4 = var * (1 + 3 * (k - 2) * p * (1 - p))
    assert np.all(np.abs(counts.mean(axis=0) - offset - k * p) <= 5 * np.sqrt(var / DRAWS) + 1e-12)
    assert np.all(np.abs(counts.var(axis=0, ddof=1) - var) <= 5 * np.sqrt((mu4 - var ** 2) / DRAWS) + 1e-12)


@pytest.mark.parametrize("n_out", [None, 5, 50])
def test_multinomial_counts_have_the_multinomial_law_like_stone_soups(n_out, monkeypatch):
    """locbook draws the counts (numpy's multinomial), Stone Soup M uniforms on the sorted CDF: no shared uniforms, so
    both are held to the closed form, c_j ~ Binomial(M, w_j), over 3000 draws each."""
    n = W8.size
    m = n if n_out is None else n_out
    gen = np.random.default_rng(8)
    monkeypatch.setattr(np.random, "rand", lambda *shape: gen.random(shape))
    theirs = _count_rows([_stone_soup(ss_particle.MultinomialResampler(), W8, n_out) for _ in range(DRAWS)], n)
    ours = _count_rows(lb.resample(np.broadcast_to(W8, (DRAWS, n)), rng=np.random.default_rng(9), method="multinomial",
                                   n_out=n_out), n)
    for counts in (ours, theirs):
        assert np.all(counts.sum(axis=1) == m)
        _assert_binomial_law(counts, m, W8)


def test_residual_resampling_equals_stone_soup_where_it_is_deterministic_and_has_its_law_elsewhere(monkeypatch):
    # dyadic weights: N w_j integers exactly, so both copy floor(N w_j) and draw nothing
    w = np.array([3, 0, 2, 1, 0, 1, 1, 0], float) / 8
    theirs = _stone_soup(ss_particle.ResidualResampler(), w)
    np.testing.assert_array_equal(np.sort(theirs), [0, 0, 0, 2, 2, 3, 5, 6])
    for seed in range(3):
        np.testing.assert_array_equal(lb.resample(w, rng=np.random.default_rng(seed), method="residual"),
                                      np.sort(theirs))
    # general weights: floor(N w) copies plus a multinomial draw of the rest from the residuals (Douc et al. 2005)
    n = W8.size
    gen = np.random.default_rng(10)
    monkeypatch.setattr(np.random, "rand", lambda *shape: gen.random(shape))
    theirs = _count_rows([_stone_soup(ss_particle.ResidualResampler(), W8) for _ in range(DRAWS)], n)
    ours = _count_rows(lb.resample(np.broadcast_to(W8, (DRAWS, n)), rng=np.random.default_rng(11), method="residual"),
                       n)
    floor = np.floor(n * W8)
    rest = n - floor.sum()
    r = (n * W8 - floor) / rest
    for counts in (ours, theirs):
        assert np.all(counts >= floor) and np.all(counts <= floor + rest)
        _assert_binomial_law(counts, rest, r, offset=floor)


@pytest.mark.parametrize("n_out", [3, 20, 999])
def test_residual_resampling_to_another_count_keeps_floor_m_w_copies(n_out):
    """Stone Soup's residual resampler refuses nparts != N; locbook's copies floor(M w_j) and draws M - sum floor(M w)
    from the residuals: unbiased (E[c_j] = M w_j) with the residual multinomial's variance."""
    n = W8.size
    counts = _count_rows(lb.resample(np.broadcast_to(W8, (DRAWS, n)), rng=np.random.default_rng(12), method="residual",
                                     n_out=n_out), n)
    floor = np.floor(n_out * W8)
    rest = n_out - floor.sum()
    r = (n_out * W8 - floor) / rest
    assert np.all(counts.sum(axis=1) == n_out) and np.all(counts >= floor) and np.all(counts <= floor + rest)
    _assert_binomial_law(counts, rest, r, offset=floor)
    with pytest.raises(NotImplementedError):         # what Stone Soup does not offer
        _stone_soup(ss_particle.ResidualResampler(), W8, n_out)


@pytest.mark.parametrize("method", RESAMPLING_METHODS)
def test_log_weights_resample_like_their_normalised_exponentials_in_batches(method):
    rng = np.random.default_rng(13)
    log_w = rng.normal(0.0, 30.0, (3, 4, 25)) + np.array([-2000.0, 0.0, 900.0])[:, None, None]
    log_w[0, 1, :5] = -np.inf
    w = np.exp(log_w - logsumexp(log_w, axis=-1, keepdims=True))          # scipy's normalisation
    for n_out in (None, 7, 60):
        ours = lb.resample(log_w, rng=np.random.default_rng(14), method=method, n_out=n_out, log_weights=True)
        ref = lb.resample(w, rng=np.random.default_rng(14), method=method, n_out=n_out)
        np.testing.assert_array_equal(ours, ref)
        assert ours.shape == (3, 4, 25 if n_out is None else n_out)
        assert not np.any(np.take_along_axis(np.isneginf(log_w), ours, -1) if n_out is None else
                          np.isneginf(log_w[0, 1, ours[0, 1]]))
    idx, done = lb.resample_where(log_w, rng=np.random.default_rng(15), method=method, threshold=5.0, log_weights=True)
    np.testing.assert_array_equal(done, lb.effective_sample_size(w) < 5.0)


def test_log_weights_without_any_weight_or_with_nan_name_the_row():
    log_w = np.zeros((2, 3, 4))
    log_w[1, 2] = -np.inf
    with pytest.raises(ValueError, match=r"row \(1, 2\) is -inf for every particle"):
        lb.resample(log_w, rng=np.random.default_rng(0), log_weights=True)
    for bad in (np.nan, np.inf):
        log_w = np.zeros((2, 3, 4))
        log_w[0, 1, 3] = bad
        with pytest.raises(ValueError, match=r"row \(0, 1\) holds 1 NaN or \+inf value\(s\), the first at particle 3"):
            lb.resample(log_w, rng=np.random.default_rng(0), method="residual", log_weights=True)
        with pytest.raises(ValueError, match=r"row \(0, 1\)"):
            lb.systematic_resample(log_w, np.zeros((2, 3)), log_weights=True)
    for n_out, message in ((0, "n_out must be >= 1"), (2.5, "n_out must be an integer")):
        with pytest.raises(ValueError, match=message):
            lb.resample(W8, rng=np.random.default_rng(0), n_out=n_out)


def test_n_out_equal_to_n_is_the_default_draw_and_counts_to_indices_takes_a_total():
    for method in RESAMPLING_METHODS:
        w = np.random.default_rng(16).random((5, 30))
        np.testing.assert_array_equal(lb.resample(w, rng=np.random.default_rng(17), method=method),
                                      lb.resample(w, rng=np.random.default_rng(17), method=method, n_out=30))
    np.testing.assert_array_equal(counts_to_indices([2, 0, 3, 1], n_out=6), [0, 0, 2, 2, 2, 3])
    np.testing.assert_array_equal(counts_to_indices([[0, 1], [1, 0]], n_out=1), [[1], [0]])
    with pytest.raises(ValueError, match="must sum to n_out = 5"):
        counts_to_indices([2, 0, 3, 1], n_out=5)


# -- one run without the run axis ----------------------------------------------------------------------------------
ANCHORS = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 8.0], [10.0, 8.0]])
RSS = lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.5, 4.0, min_distance_m=0.1))
BOX = ([0.0, 0.0], [10.0, 8.0])
FIELDS = ("mean", "cov", "map_m", "n_eff", "resampled", "particles_m", "weights", "diverged", "diverged_step",
          "log_weights")


def _readings(seed, runs=None, steps=6):
    rng = np.random.default_rng(seed)
    pos = 5 + np.cumsum(0.4 * rng.standard_normal((steps, 2)), axis=0)
    rss = RSS.mean_rss_dbm(pos)[0] + 4 * rng.standard_normal((steps, 4))
    rss[2, 1] = np.nan
    return rss if runs is None else np.broadcast_to(rss, (runs,) + rss.shape)


def _assert_single_is_run_0(one, batched):
    assert isinstance(one, ParticleFilterResult)
    for f in FIELDS:
        a, b = getattr(one, f), getattr(batched, f)
        assert np.shape(a) == np.shape(b)[1:], f
        np.testing.assert_array_equal(a, b[0], err_msg=f)
    assert one.clouds.keys() == batched.clouds.keys()
    for t in one.clouds:
        np.testing.assert_array_equal(one.clouds[t], batched.clouds[t][0])


@pytest.mark.parametrize("kwargs", [
    dict(n_particles=300, region_m=BOX, cloud_steps=(0, 4)),
    dict(n_particles=300, initial_sd_m=0.7, region_m=BOX, resampling="residual", resample_threshold=0.5),
    dict(n_particles=300, region_m=BOX, motion=lb.constant_velocity(1.0, 0.05), weight_smoothing="sqrt"),
])
def test_one_run_of_readings_t_by_m_gives_the_one_run_result_without_the_run_axis(kwargs):
    rss = _readings(0)
    extra = {"initial_position_m": [5.0, 4.0]} if "initial_sd_m" in kwargs else {}
    one = particle_filter(rss, RSS, rng=np.random.default_rng(1), **kwargs, **extra)
    batched = particle_filter(rss[None], RSS, rng=np.random.default_rng(1), **kwargs,
                              **{k: np.asarray(v)[None] for k, v in extra.items()})
    _assert_single_is_run_0(one, batched)
    d = 4 if "motion" in kwargs else 2
    assert one.mean.shape == (6, d) and one.cov.shape == (6, d, d) and one.particles_m.shape == (300, d)
    assert one.diverged.shape == () and not one.diverged and one.diverged_step == -1
    with pytest.raises(ValueError, match=r"single run .* initial_position_m without the run axis"):
        particle_filter(rss, RSS, rng=np.random.default_rng(1), n_particles=10, initial_position_m=[[5.0, 4.0]])


def test_one_run_with_callables_sees_and_returns_arrays_without_the_run_axis():
    rng = np.random.default_rng(2)
    z = rng.normal(0.0, 1.0, (5, 2))
    start = rng.normal(0.0, 1.0, (400, 2))
    seen = []

    def loglik_one(x, t):
        seen.append(x.shape)
        return -0.5 * np.sum((z[t] - x) ** 2, axis=-1)

    def move_one(x, t, rng):
        return 0.9 * x + 0.3 * rng.standard_normal(x.shape)

    one = particle_filter(None, loglik_one, rng=np.random.default_rng(3), n_steps=5, initial_particles_m=start,
                          transition=move_one, resampling="stratified", cloud_steps=(2,))
    assert set(seen) == {(400, 2)}
    batched = particle_filter(None, lambda x, t: loglik_one(x[0], t)[None], rng=np.random.default_rng(3), n_steps=5,
                              initial_particles_m=start[None], transition=lambda x, t, rng: move_one(x, t, rng),
                              resampling="stratified", cloud_steps=(2,))
    _assert_single_is_run_0(one, batched)
    # a start (dim,) is one run too
    one = particle_filter(None, loglik_one, rng=np.random.default_rng(4), n_steps=5, initial_position_m=[0.5, 0.5],
                          n_particles=50, initial_covariance=np.diag([1.0, 0.0]))
    assert one.mean.shape == (5, 2) and one.particles_m.shape == (50, 2)
    with pytest.raises(ValueError, match=r"log_likelihood must return \(400,\) for a single run"):
        particle_filter(None, lambda x, t: loglik_one(x, t)[None], rng=np.random.default_rng(3), n_steps=2,
                        initial_particles_m=start)


# -- kinematic motion ----------------------------------------------------------------------------------------------
MOTIONS = {
    "CV discrete (rank 2)": lb.constant_velocity(0.5, 0.2),
    "CV wiener (rank 2)": lb.constant_velocity(0.5, 0.2, noise="wiener"),
    "CA discrete axis-major (rank 2)": lb.constant_acceleration(0.5, 0.3),
    "CV continuous (full rank)": lb.constant_velocity(0.5, 0.2, noise="continuous"),
    "CA isotropic 3-D (full rank)": lb.constant_acceleration(1.0, 0.1, dim=3, noise="isotropic"),
}


@pytest.mark.parametrize("name", list(MOTIONS))
def test_the_process_noise_drawn_has_covariance_q_even_when_q_is_singular(name):
    """One step of x = F x + w on 3 runs of 20000 particles with a flat likelihood and no resampling: the moves
    w = x_1 - F x_0 have sample covariance Q within 5 standard errors per entry, Var(S_ij) = (Q_ii Q_jj + Q_ij^2) / M
    for M Gaussian moves; a singular Q's moves stay in its range (the column space of G)."""
    motion = MOTIONS[name]
    n = motion.n_state
    rng = np.random.default_rng(20)
    start = rng.normal(0.0, 2.0, (3, 20000, n))
    res = particle_filter(None, lambda x, t: np.zeros(x.shape[:2]), rng=np.random.default_rng(21), n_steps=2,
                          initial_particles_m=start, motion=motion, resample_every=5, cloud_steps=(0, 1))
    assert not res.resampled.any()
    np.testing.assert_array_equal(res.clouds[0], start)
    moves = (res.clouds[1] - start @ motion.F.T).reshape(-1, n)
    Q = motion.Q
    m = moves.shape[0]
    S = moves.T @ moves / m                                     # the moves have mean 0
    se = np.sqrt((np.outer(np.diag(Q), np.diag(Q)) + Q ** 2) / m)
    assert np.all(np.abs(S - Q) <= 5 * se), np.max(np.abs(S - Q) / se)
    assert np.all(np.abs(moves.mean(axis=0)) <= 5 * np.sqrt(np.diag(Q) / m))
    rank = np.linalg.matrix_rank(Q)
    if "rank 2" in name:
        assert rank == 2 < n
        u, s, _ = np.linalg.svd(Q)
        off_range = moves @ u[:, rank:]
        assert np.max(np.abs(off_range)) < 1e-12 * np.max(np.abs(moves))
    else:
        assert rank == n


def _kalman_problem(seed, steps=15):
    motion = lb.constant_velocity(1.0, 0.05)
    r = 0.5
    x0, P0 = np.array([0.0, 0.0, 1.0, 0.5]), np.diag([1.0, 1.0, 0.25, 0.25])
    rng = np.random.default_rng(seed)
    truth = lb.simulate_states(motion.F, motion.Q, rng.multivariate_normal(x0, P0), steps - 1, rng=rng)
    z = truth[:, :2] + np.sqrt(r) * rng.standard_normal((steps, 2))
    return motion, r, x0, P0, z


def test_the_particle_posterior_of_a_linear_gaussian_track_is_the_kalman_filters():
    """CV motion (singular discrete white-noise Q), Gaussian position readings as a callable log-likelihood. The PF
    is run as 40 independent replicates of 5000 particles on one track (40 runs of the same readings); the exact
    posterior is locbook.kalman_filter's (predict_first=False: the prior is at the first reading, as the PF's).

    The Monte-Carlo window is derived from the replicates, not from N_eff of one step (resampling makes the error of a
    step inherit the errors of all earlier steps, about 1.7 times the single-step 1 / sqrt(N_eff) error here): the
    run average of the PF means has standard error s / sqrt(40), s the spread across runs (a t statistic with 39
    degrees of freedom; 5 of them at 60 comparisons fail by chance with probability < 1e-3). The weighted covariance
    about the run's own weighted mean underestimates P by the variance of that mean (E[cov] = P - Var(mean), to
    first order), which the spread of the means estimates; so cov + Var_runs(mean) is compared with P."""
    motion, r, x0, P0, z = _kalman_problem(30)
    H = motion.position_measurement_matrix()
    kf = lb.kalman_filter(motion.F, motion.Q, x0, P0, lb.LinearMeasurement(z, H, r * np.eye(2)), predict_first=False)
    runs, steps = 40, z.shape[0]

    def loglik(x, t):                  # the full states (R, N, 4); the readings are the positions
        return -0.5 * np.sum((z[t] - x[..., motion.position_index]) ** 2, axis=-1) / r

    def run(m):
        return particle_filter(None, loglik, rng=np.random.default_rng(31), n_steps=steps, motion=m, n_particles=5000,
                               initial_position_m=np.broadcast_to(x0, (runs, 4)), initial_covariance=P0)

    res = run(motion)
    assert res.mean.shape == (runs, steps, 4) and res.cov.shape == (runs, steps, 4, 4)
    mean, se = res.mean.mean(axis=0), res.mean.std(axis=0, ddof=1) / np.sqrt(runs)
    sd = np.sqrt(np.diagonal(kf.cov, axis1=-2, axis2=-1))
    assert np.all(se < 0.02 * sd)                              # the window is narrow against the posterior
    assert np.all(np.abs(mean - kf.mean) <= 5 * se), np.max(np.abs(mean - kf.mean) / se)
    dev = res.mean - mean
    var_of_mean = np.einsum("rti,rtj->tij", dev, dev) / (runs - 1)
    cov, cov_se = res.cov.mean(axis=0), res.cov.std(axis=0, ddof=1) / np.sqrt(runs)
    assert np.all(np.abs(cov + var_of_mean - kf.cov) <= 5 * cov_se), np.max(np.abs(cov + var_of_mean - kf.cov) / cov_se)
    # the window can fail: a process noise of 3 q is seen far outside it (the covariances grow)
    wrong = run(lb.constant_velocity(1.0, 0.15))
    assert np.max(np.abs(wrong.cov.mean(axis=0) - kf.cov) / cov_se) > 20


def test_an_rss_model_sees_the_positions_in_either_state_layout():
    """The RSS likelihood is evaluated at x[..., position_index]: the same as a callable that picks the positions, and
    an axis-major state ([x, vx, y, vy]) gives the derivative-major result permuted (G, F and Q are the same model)."""
    rss = _readings(5, runs=2)
    cv, cv_axis = lb.constant_velocity(1.0, 0.05), lb.constant_velocity(1.0, 0.05, layout="axis_major")
    start = (np.array([[5.0, 4.0, 0.0, 0.0], [4.0, 5.0, 0.1, 0.0]])[:, None]
             + np.random.default_rng(39).normal(0.0, 1.0, (2, 500, 4)) * np.sqrt([1.0, 1.0, 0.1, 0.1]))
    kw = dict(initial_particles_m=start)
    res = particle_filter(rss, RSS, rng=np.random.default_rng(40), motion=cv, **kw)
    direct = particle_filter(None, lambda x, t: RSS.log_likelihood(rss[:, t], x[..., [0, 1]], t, constant=False),
                             rng=np.random.default_rng(40), n_steps=rss.shape[1], motion=cv, **kw)
    for f in FIELDS:
        np.testing.assert_array_equal(getattr(res, f), getattr(direct, f), err_msg=f)
    perm = np.array([0, 2, 1, 3])                   # axis-major state = derivative-major state[perm]
    kw_axis = dict(initial_particles_m=start[..., perm])
    np.testing.assert_array_equal(cv_axis.position_index, [0, 2])
    axis = particle_filter(rss, RSS, rng=np.random.default_rng(40), motion=cv_axis, **kw_axis)
    np.testing.assert_allclose(axis.mean, res.mean[..., perm], rtol=0, atol=1e-12)
    np.testing.assert_allclose(axis.cov, res.cov[..., perm[:, None], perm], rtol=0, atol=1e-12)
    # a position start is a state at rest
    rest = particle_filter(rss, RSS, rng=np.random.default_rng(41), motion=cv, n_particles=50,
                           initial_position_m=[[5.0, 4.0], [4.0, 5.0]], cloud_steps=(0,))
    np.testing.assert_array_equal(rest.clouds[0][0, 0], [5.0, 4.0, 0.0, 0.0])


@pytest.mark.parametrize("motion", [lb.constant_velocity(1.0, 0.0),
                                    lb.constant_acceleration(1.0, 0.0, layout="derivative_major")])
def test_a_particle_leaving_the_region_is_mirrored_with_its_velocity_and_acceleration(motion):
    """Without noise, folding after every step is folding the free trajectory p(t) = p0 + v0 t + a0 t^2 / 2 into the
    box (the mirror image of a CV / CA path is one), with the derivatives reversed on each axis folded an odd number
    of times."""
    lower, upper = np.array([0.0, 0.0]), np.array([10.0, 8.0])
    p0, v0 = np.array([[9.5, 1.0], [2.0, 7.0]]), np.array([[1.0, -1.5], [-3.1, 4.2]])
    a0 = np.array([[0.2, -0.1], [0.5, 0.3]]) if motion.order == 2 else np.zeros((2, 2))
    start = motion.state_from(p0, v0, a0 if motion.order == 2 else None)[None]       # (1 run, 2 particles, n)
    steps = 9
    res = particle_filter(None, lambda x, t: np.zeros(x.shape[:2]), rng=np.random.default_rng(0), n_steps=steps,
                          initial_particles_m=start, motion=motion, region_m=(lower, upper), resample_every=100)
    t = steps - 1
    free_p, free_v = p0 + v0 * t + a0 * t ** 2 / 2, v0 + a0 * t
    width = upper - lower
    folded = np.mod(free_p - lower, 2 * width)
    sign = np.where(folded > width, -1.0, 1.0)
    final = res.particles_m[0]
    np.testing.assert_allclose(final[:, motion.position_index], lower + np.where(sign < 0, 2 * width - folded, folded),
                               atol=1e-9)
    np.testing.assert_allclose(final[:, motion.velocity_index], sign * free_v, atol=1e-9)
    if motion.order == 2:
        np.testing.assert_allclose(final[:, motion.acceleration_index], sign * a0, atol=1e-12)
    assert np.all((final[:, motion.position_index] >= lower) & (final[:, motion.position_index] <= upper))
    assert np.any(sign < 0)                       # the test does cross walls


def test_motion_refuses_the_random_walk_arguments_and_unknown_models():
    cv = lb.constant_velocity(1.0, 0.1)
    base = dict(n_particles=20, region_m=BOX)
    rss = _readings(0, runs=1)
    for extra, name in ((dict(spread_m=0.5), "spread_m"), (dict(velocity_m=[0.1, 0.0]), "velocity_m"),
                        (dict(transition=lambda x, t, rng: x), "transition")):
        with pytest.raises(ValueError, match=f"motion moves the particles .* excludes {name}"):
            particle_filter(rss, RSS, rng=np.random.default_rng(0), motion=cv, **base, **extra)
    with pytest.raises(ValueError, match="motion must be a motion model"):
        particle_filter(rss, RSS, rng=np.random.default_rng(0), motion="cv", **base)
    heading = lb.HeadingKinematicModel(1.0, 0.1, 0.01)
    with pytest.raises(ValueError, match=r"region_m mirrors the motion at the walls; motion=HeadingKinematicModel"):
        particle_filter(rss, RSS, rng=np.random.default_rng(0), motion=heading, **base)
    with pytest.raises(ValueError, match="motion has 3 position axes, the RssModel 2"):
        particle_filter(rss, RSS, rng=np.random.default_rng(0), motion=lb.constant_velocity(1.0, 0.1, dim=3), **base)
    with pytest.raises(ValueError, match=r"initial_position_m must have shape \(runs, 4\) or \(runs, 2\)"):
        particle_filter(rss, RSS, rng=np.random.default_rng(0), motion=cv, n_particles=5,
                        initial_position_m=[[1.0] * 3])
    with pytest.raises(ValueError, match="initial_covariance must be symmetric positive semi-definite"):
        particle_filter(rss, RSS, rng=np.random.default_rng(0), n_particles=5, initial_position_m=[[1.0, 1.0]],
                        initial_covariance=np.diag([1.0, -1.0]))
    with pytest.raises(ValueError, match="initial_sd_m .* or initial_covariance, not both"):
        particle_filter(rss, RSS, rng=np.random.default_rng(0), n_particles=5, initial_position_m=[[1.0, 1.0]],
                        initial_sd_m=1.0, initial_covariance=np.eye(2))
    # a heading model without a region moves by its F and Q (drawn from an eigen-factor of Q)
    res = particle_filter(rss, RSS, rng=np.random.default_rng(0), motion=heading, n_particles=30,
                          initial_position_m=[[5.0, 4.0]])
    assert res.mean.shape == (1, 6, 8)


def test_a_gaussian_prior_with_initial_covariance_has_that_covariance_even_if_singular():
    P0 = np.array([[2.0, 0.6, 0.0, 0.0], [0.6, 0.5, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.3]])
    x0 = np.array([1.0, -1.0, 0.5, 2.0])
    m = 2 * 30000
    res = particle_filter(None, lambda x, t: np.zeros(x.shape[:2]), rng=np.random.default_rng(50), n_steps=1,
                          initial_position_m=np.broadcast_to(x0, (2, 4)), initial_covariance=P0, n_particles=m // 2,
                          motion=lb.constant_velocity(1.0, 0.1), resample_every=3, cloud_steps=(0,))
    x = res.clouds[0].reshape(-1, 4)
    S = np.cov(x.T)
    se = np.sqrt((np.outer(np.diag(P0), np.diag(P0)) + P0 ** 2) / m)
    assert np.all(np.abs(S - P0) <= 5 * se + 1e-15)
    assert np.all(np.abs(x.mean(axis=0) - x0) <= 5 * np.sqrt(np.diag(P0) / m) + 1e-15)
    np.testing.assert_array_equal(x[:, 2], 0.5)               # no variance on that axis: exactly x0


# -- log-weights ---------------------------------------------------------------------------------------------------
def test_log_weights_of_the_last_update_are_exact_where_the_weights_underflow():
    """One update from equal weights: log w = ll - logsumexp(ll) (scipy), exactly, with -inf for an impossible
    particle and values far below log(1e-300) where ``weights`` keeps the filter's 1e-300 floor."""
    rng = np.random.default_rng(60)
    start = rng.normal(0.0, 1.0, (2, 300, 2))
    ll = -rng.uniform(0.0, 3000.0, (2, 300))
    ll[0, :4] = -np.inf
    kw = dict(n_steps=1, initial_particles_m=start, resample_every=2)
    res = particle_filter(None, lambda x, t: ll, rng=np.random.default_rng(61), **kw)
    expected = ll - logsumexp(ll, axis=-1, keepdims=True)
    np.testing.assert_array_equal(np.isneginf(res.log_weights), np.isneginf(ll))
    finite = np.isfinite(ll)
    np.testing.assert_allclose(res.log_weights[finite], expected[finite], rtol=1e-12, atol=1e-9)
    assert res.log_weights[finite].min() < -1000
    big = expected > np.log(1e-290)
    np.testing.assert_allclose(np.exp(res.log_weights[big]), res.weights[big], rtol=1e-10)
    # "sqrt" smoothing tempers the likelihood: log w = ll / 2 normalised
    res = particle_filter(None, lambda x, t: ll, rng=np.random.default_rng(61), weight_smoothing="sqrt", **kw)
    np.testing.assert_allclose(res.log_weights[finite], (ll / 2 - logsumexp(ll / 2, axis=-1, keepdims=True))[finite],
                               rtol=1e-12, atol=1e-9)
    # resampled at the last step: equal weights
    res = particle_filter(None, lambda x, t: ll, rng=np.random.default_rng(61), n_steps=1, initial_particles_m=start)
    np.testing.assert_allclose(res.log_weights, -np.log(300), rtol=1e-14)
