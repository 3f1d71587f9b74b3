"""The particle filter against the Kalman posterior of a linear-Gaussian problem, the RSS model's likelihood
against a direct computation, the kernel MAP and the N_eff trigger."""
import re
import warnings

import numpy as np
import pytest

import locbook as lb
from locbook.tracking.resampling import RESAMPLING_METHODS


@pytest.mark.parametrize("method", RESAMPLING_METHODS)
def test_sir_posterior_of_a_linear_gaussian_problem_equals_the_kalman_posterior(method):
    rng = np.random.default_rng(0)
    R, Ns, K = 4, 40_000, 5
    m0, P0 = np.array([1.0, -2.0]), np.diag([4.0, 1.0])
    r = 0.5
    truth = np.array([2.0, -1.5])
    z = truth + np.sqrt(r) * rng.standard_normal((R, K, 2))
    particles = m0 + rng.standard_normal((R, Ns, 2)) @ np.linalg.cholesky(P0).T

    def loglik(x, k):
        return -0.5 * np.sum((z[:, k, None, :] - x) ** 2, axis=-1) / r

    res = lb.particle_filter(None, loglik, rng=rng, n_steps=K, initial_particles_m=particles, spread_m=0.0,
                             resampling=method)
    # conjugate posterior after all K steps (static state, z_k = x + v)
    info = np.linalg.inv(P0) + K / r * np.eye(2)
    post_P = np.linalg.inv(info)
    post_m = (post_P @ (np.linalg.solve(P0, m0)[:, None] + z.sum(axis=1).T / r)).T
    tol = 5 * np.sqrt(np.diag(post_P) / (Ns / 10))           # resampling leaves ~Ns/10 distinct ancestors
    assert np.all(np.abs(res.mean[:, -1] - post_m) < tol)
    np.testing.assert_allclose(np.diagonal(res.cov[:, -1], axis1=-2, axis2=-1).mean(axis=0), np.diag(post_P),
                               rtol=0.1)
    np.testing.assert_allclose(res.cov[:, -1].mean(axis=0)[0, 1], post_P[0, 1], atol=0.1 * post_P[0, 0])
    assert res.resampled.all()


@pytest.mark.parametrize("ref_distance_m", [1.0, 2.0])
def test_rss_model_likelihood_with_per_run_anchors_leaves_out_missing_readings(ref_distance_m):
    rng = np.random.default_rng(1)
    ch = lb.PathLossModel(-20.0, 4.0, 6.0, ref_distance_m=ref_distance_m, min_distance_m=1e-3)
    x = rng.uniform(0, 50, (2, 7, 3))
    s = rng.uniform(0, 50, (2, 4, 3))
    z = rng.uniform(-90, -50, (2, 4))
    z[1, 2] = np.nan
    ours = lb.RssModel(s, ch).log_likelihood(z, x, constant=False)
    for r in range(2):
        for i in range(7):
            d = np.linalg.norm(x[r, i] - s[r], axis=-1)
            h = -20 - 40 * np.log10(d / ref_distance_m)
            keep = np.isfinite(z[r])
            assert ours[r, i] == pytest.approx(-np.sum((z[r, keep] - h[keep]) ** 2) / 72.0)


def test_kernel_map_finds_the_mode_and_neff_triggers_resampling():
    rng = np.random.default_rng(2)
    x = np.concatenate([rng.normal(3.0, 1.0, (1, 3000, 2)), rng.normal(-6.0, 3.0, (1, 1000, 2))], axis=1)
    w = np.full((1, 4000), 1 / 4000)
    mode = lb.kernel_map_estimate(x, w)
    assert np.linalg.norm(mode[0] - 3.0) < 0.6
    res = lb.particle_filter(None, lambda p, k: -0.5 * p[..., 0] ** 2 * (k + 1), rng=rng, n_steps=4,
                             initial_particles_m=rng.normal(0, 1, (3, 500, 1)), spread_m=0.0, resample_threshold=0.5)
    np.testing.assert_array_equal(res.resampled, res.n_eff < 250.0)
    assert res.resampled.any() and not res.resampled.all()


# ---------------------------------------------------------------------------------------------------------------
# a run whose likelihoods all collapse is isolated (flagged, NaN from that step), not fatal
# ---------------------------------------------------------------------------------------------------------------
READERS = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
BAYES_MODEL = lb.RssModel(READERS, lb.PathLossModel(-40.0, 2.0, 3.0, min_distance_m=0.1))


def _rss_runs(runs=4, steps=8, seed=3):
    rng = np.random.default_rng(seed)
    pos = 5 + np.cumsum(0.3 * rng.standard_normal((runs, steps, 2)), axis=1)
    return BAYES_MODEL.mean_rss_dbm(pos.reshape(-1, 2))[0].reshape(runs, steps, 4) + 3 * rng.standard_normal(
        (runs, steps, 4))


@pytest.mark.parametrize("threshold", [None, 0.5])
def test_particle_filter_isolates_a_run_whose_rss_reading_overflows_the_likelihood(threshold):
    """A reading of 1e300 dBm overflows every particle's likelihood to -inf: that run used to abort the whole batch
    with "weights must be finite" naming no run or step. Now that run is flagged diverged at that step with NaN
    estimates from there on, and every other run is bit-identical to the batch where that reading was sane."""
    good = _rss_runs()
    bad = good.copy()
    bad[2, 5, 1] = 1e300
    kw = dict(n_particles=300, region_m=([0.0, 0.0], [10.0, 10.0]), resample_threshold=threshold)
    ref = lb.particle_filter(good, BAYES_MODEL, rng=np.random.default_rng(7), **kw)
    with pytest.warns(RuntimeWarning, match=r"1 of 4 runs \(first: run 2, step 5"):
        res = lb.particle_filter(bad, BAYES_MODEL, rng=np.random.default_rng(7), **kw)
    assert res.diverged.tolist() == [False, False, True, False]
    assert res.diverged_step.tolist() == [-1, -1, 5, -1]
    assert ref.n_diverged == 0 and res.n_diverged == 1
    others = [0, 1, 3]
    for name in ("mean", "cov", "map_m", "n_eff", "resampled", "particles_m", "weights"):
        np.testing.assert_array_equal(getattr(res, name)[others], getattr(ref, name)[others], err_msg=name)
    np.testing.assert_array_equal(res.mean[2, :5], ref.mean[2, :5])
    assert np.isnan(res.mean[2, 5:]).all() and np.isnan(res.cov[2, 5:]).all()
    assert np.isnan(res.map_m[2, 5:]).all() and np.isnan(res.n_eff[2, 5:]).all()
    assert np.isnan(res.weights[2]).all() and np.isnan(res.particles_m[2]).all()


@pytest.mark.parametrize("method", ["systematic", "stratified"])
@pytest.mark.parametrize("collapse", [-np.inf, np.nan, np.inf])
def test_particle_filter_isolates_a_run_whose_likelihood_collapses(method, collapse):
    """A log-likelihood that is -inf for every particle, NaN for some or +inf (garbage) flags that run at that step;
    the others are bit-identical to the run with a sane likelihood (with these schemes the random draws do not depend
    on the weights)."""
    rng0 = np.random.default_rng(0)
    start = rng0.normal(0, 1, (3, 200, 2))
    z = rng0.normal(0, 1, (3, 6, 2))

    def loglik(x, k, broken=False):
        out = -0.5 * np.sum((z[:, k, None, :] - x) ** 2, axis=-1)
        if broken and k == 3:
            if np.isnan(collapse):
                out[1, :5] = np.nan           # NaN for a few particles only: still garbage
            else:
                out[1] = collapse
        return out

    kw = dict(n_steps=6, initial_particles_m=start, spread_m=0.1, resampling=method)
    ref = lb.particle_filter(None, loglik, rng=np.random.default_rng(1), **kw)
    with pytest.warns(RuntimeWarning, match=r"1 of 3 runs \(first: run 1, step 3"):
        res = lb.particle_filter(None, lambda x, k: loglik(x, k, True), rng=np.random.default_rng(1), **kw)
    assert res.diverged.tolist() == [False, True, False] and res.diverged_step.tolist() == [-1, 3, -1]
    for name in ("mean", "cov", "map_m", "n_eff", "resampled", "particles_m", "weights"):
        np.testing.assert_array_equal(getattr(res, name)[[0, 2]], getattr(ref, name)[[0, 2]], err_msg=name)
    np.testing.assert_array_equal(res.mean[1, :3], ref.mean[1, :3])
    assert np.isnan(res.mean[1, 3:]).all() and np.isnan(res.cov[1, 3:]).all()
    assert np.isnan(res.weights[1]).all() and not res.resampled[1, 3:].any()


def test_sir_particles_with_minus_inf_likelihood_are_only_dropped():
    """-inf for some particles is a legitimate zero weight (an impossible state), not a collapse."""
    rng = np.random.default_rng(2)
    start = rng.normal(0, 1, (2, 400, 1))
    res = lb.particle_filter(None, lambda x, k: np.where(x[..., 0] > 0, 0.0, -np.inf), rng=rng, n_steps=1,
                             initial_particles_m=start)
    assert not res.diverged.any()
    assert np.all(res.mean[:, 0, 0] > 0)


def test_grid_bayes_filter_isolates_a_run_whose_likelihood_collapses():
    """The grid filter had the same fault silently: a collapsed run's belief became NaN with no flag."""
    good = _rss_runs(3, 6, seed=4)
    bad = good.copy()
    bad[1, 2, 0] = 1e300
    cells = np.stack(np.meshgrid(np.arange(0.5, 10, 1.0), np.arange(0.5, 10, 1.0)), -1).reshape(-1, 2)
    ref = lb.grid_bayes_filter(good, BAYES_MODEL, cells, 1.0)
    with pytest.warns(RuntimeWarning, match=r"1 of 3 runs \(first: run 1, step 2"):
        res = lb.grid_bayes_filter(bad, BAYES_MODEL, cells, 1.0)
    assert res.diverged.tolist() == [False, True, False] and res.diverged_step.tolist() == [-1, 2, -1]
    assert ref.n_diverged == 0 and res.n_diverged == 1
    for name in ("mean", "cov", "map_m", "n_eff", "weights"):
        np.testing.assert_array_equal(getattr(res, name)[[0, 2]], getattr(ref, name)[[0, 2]])
    np.testing.assert_array_equal(res.mean[1, :2], ref.mean[1, :2])
    assert np.isnan(res.mean[1, 2:]).all() and np.isnan(res.weights[1]).all()


def test_sir_without_particles_is_a_clear_error():
    """Used to end in numpy's "zero-size array to reduction operation maximum"."""
    with pytest.raises(ValueError, match=r"initial_particles_m must hold at least one particle.*\(2, 0, 2\)"):
        lb.particle_filter(None, lambda x, k: np.zeros(x.shape[:2]), rng=np.random.default_rng(0), n_steps=2,
                           initial_particles_m=np.zeros((2, 0, 2)))


# ---------------------------------------------------------------------------------------------------------------
# Found in review: a collapse is not silent. Every run collapsed: an error; some runs: one RuntimeWarning
# ---------------------------------------------------------------------------------------------------------------
def _grid_cells():
    return np.stack(np.meshgrid(np.arange(0.5, 10, 1.0), np.arange(0.5, 10, 1.0)), -1).reshape(-1, 2)


def _bayes_filters():
    """particle_filter and grid_bayes_filter on the same readings."""
    yield "particle_filter", lambda rss: lb.particle_filter(rss, BAYES_MODEL, rng=np.random.default_rng(7),
                                                            n_particles=200, region_m=([0.0, 0.0], [10.0, 10.0]))
    yield "grid_bayes_filter", lambda rss: lb.grid_bayes_filter(rss, BAYES_MODEL, _grid_cells(), 1.0)


def test_every_run_collapsing_is_an_error_naming_the_likelihood_and_the_first_step():
    """With every run collapsed the filters returned all-NaN with n_diverged equal to the run count: a units bug
    (1e300 dBm in every run, a likelihood that is -inf everywhere) became NaN instead of an error. Now a ValueError
    names the likelihood (or rss_dbm), the first step and run, before anything is returned."""
    start = np.random.default_rng(0).normal(0, 1, (3, 50, 2))
    with pytest.raises(ValueError, match=r"log_likelihood.*every run \(3 of 3\).*step 0 \(run 0\)"):
        lb.particle_filter(None, lambda x, k: np.full(x.shape[:2], -np.inf), rng=np.random.default_rng(1), n_steps=4,
                           initial_particles_m=start)

    def staggered(x, k):                # run 1 collapses at step 1, the others at step 2
        out = -0.5 * np.sum(x ** 2, axis=-1)
        out[1] = -np.inf if k >= 1 else out[1]
        out[:] = np.nan if k >= 2 else out
        return out
    with pytest.raises(ValueError, match=r"log_likelihood.*every run \(3 of 3\).*step 1 \(run 1\)"):
        lb.particle_filter(None, staggered, rng=np.random.default_rng(1), n_steps=4, initial_particles_m=start)
    rss = _rss_runs()
    rss[:, 3, 1] = 1e300                                                           # every run: a units bug
    for name, call in _bayes_filters():
        with pytest.raises(ValueError, match=r"rss_dbm.*every run \(4 of 4\).*step 3 \(run 0\).*1e\+300"):
            call(rss)


def test_some_runs_collapsing_give_one_warning_with_the_count_and_the_first_run_and_step():
    rss = _rss_runs()
    rss[2, 5, 1] = 1e300
    rss[1, 6, 0] = -1e300
    rss[3, 6, 2] = 1e300
    for name, call in _bayes_filters():
        with pytest.warns(RuntimeWarning) as record:
            res = call(rss)
        assert len(record) == 1, [str(w.message) for w in record]
        assert re.search(r"3 of 4 runs.*run 2, step 5", str(record[0].message)), str(record[0].message)
        assert res.diverged.tolist() == [False, True, True, True]
        assert res.diverged_step.tolist() == [-1, 6, 5, 6]
    start = np.random.default_rng(0).normal(0, 1, (3, 50, 2))

    def loglik(x, k):
        out = -0.5 * np.sum(x ** 2, axis=-1)
        if k == 2:
            out[2] = np.nan
        return out
    with pytest.warns(RuntimeWarning) as record:
        res = lb.particle_filter(None, loglik, rng=np.random.default_rng(1), n_steps=4, initial_particles_m=start)
    assert len(record) == 1 and re.search(r"log_likelihood.*1 of 3 runs.*run 2, step 2", str(record[0].message))
    with warnings.catch_warnings():
        warnings.simplefilter("error")                                            # no collapse: no warning
        lb.particle_filter(None, lambda x, k: -0.5 * np.sum(x ** 2, axis=-1), rng=np.random.default_rng(1), n_steps=4,
                           initial_particles_m=start)
        for name, call in _bayes_filters():
            call(_rss_runs())
        assert lb.particle_filter(None, lambda x, k: np.zeros(x.shape[:2]), rng=np.random.default_rng(0), n_steps=2,
                                  initial_particles_m=np.zeros((0, 5,
                                                                2))).n_diverged == 0   # no runs: nothing collapsed


# -- size guard ------------------------------------------------------------------------------------
def _guard_model():
    return lb.RssModel(np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]]),
                       lb.PathLossModel(-40.0, 2.0, 4.0, min_distance_m=0.1))


@pytest.mark.parametrize("prior", ["uniform", "at a start", "kinematic"])
def test_a_billion_particles_are_refused_before_anything_is_allocated(prior):
    import tracemalloc
    kw = {"uniform": dict(region_m=((0, 0), (10, 10))), "at a start": dict(initial_position_m=np.zeros((1, 2))),
          "kinematic": dict(region_m=((0, 0), (10, 10)), motion=lb.constant_velocity(1.0, 0.1, dim=2))}[prior]
    state = 4 if prior == "kinematic" else 2
    tracemalloc.start()
    try:
        with pytest.raises(ValueError) as exc:
            lb.particle_filter(np.full((1, 5, 3), -60.0), _guard_model(), rng=np.random.default_rng(0),
                               n_particles=10**9, **kw)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    text = str(exc.value)
    assert "\n" not in text and text.startswith("n_particles: a particle cloud")
    assert f"1 x 1,000,000,000 x {state} float64 values, would take {8e9 * state / 2**30:.3g} GiB" in text
    assert "MAX_ARRAY_BYTES = 2 GiB" in text
    assert peak < 50 * 2**20                                  # refused from the arguments, not after a try


def test_the_particle_size_limit_is_the_stated_bytes_of_runs_x_particles_x_state(monkeypatch):
    import locbook.tracking.bayes as bayes
    R, N, d = 3, 1000, 2
    rss = np.full((R, 4, 3), -60.0)
    monkeypatch.setattr(bayes, "MAX_ARRAY_BYTES", 8 * R * N * d)             # exactly one cloud: allowed
    res = lb.particle_filter(rss, _guard_model(), rng=np.random.default_rng(0), n_particles=N,
                             region_m=((0, 0), (10, 10)))
    assert res.particles_m.shape == (R, N, d)
    monkeypatch.setattr(bayes, "MAX_ARRAY_BYTES", 8 * R * N * d - 1)
    with pytest.raises(ValueError, match="^n_particles: a particle cloud"):
        lb.particle_filter(rss, _guard_model(), rng=np.random.default_rng(0), n_particles=N,
                           region_m=((0, 0), (10, 10)))
    with pytest.raises(ValueError, match="^initial_particles_m: a particle cloud"):
        lb.particle_filter(rss, _guard_model(), rng=np.random.default_rng(0), initial_particles_m=np.ones((R, N, d)))


def test_the_repositorys_largest_particle_workloads_are_inside_the_limit():
    """The largest clouds in use: Ozkaya's test bed runs its 10,000-particle filters in blocks of
    ``max_particle_runs`` run-particle pairs (2-D); the notebooks' others are smaller (100 runs x 10,000 in
    bench_particle, 1000 runs x 1000 in the SIR sweep). Each stays far inside the limit, with a 4-value state too."""
    from locbook.scenarios.ozkaya_testbed import MethodSettings
    from locbook.tracking.bayes import MAX_ARRAY_BYTES
    for pairs in (MethodSettings().max_particle_runs, 100 * 10_000, 1000 * 1000):
        assert 8 * pairs * 4 < MAX_ARRAY_BYTES / 8


def test_kernel_map_estimate_checks_its_block_before_allocating(monkeypatch):
    """Its density is evaluated for every run x candidate x 2048 particles x dim at once (before the guard: 78 GiB
    for 10,000 runs of 3,000 particles in 2-D, allocated without a word)."""
    import locbook.tracking.bayes as bayes
    rng = np.random.default_rng(0)
    x, w = rng.normal(size=(3, 500, 2)), np.full((3, 500), 1 / 500)
    monkeypatch.setattr(bayes, "MAX_ARRAY_BYTES", 8 * 3 * 256 * 500 * 2)
    assert lb.kernel_map_estimate(x, w).shape == (3, 2)
    monkeypatch.setattr(bayes, "MAX_ARRAY_BYTES", 8 * 3 * 256 * 500 * 2 - 1)
    with pytest.raises(ValueError, match=r"^particles_m: the kernel density's block for n_candidates = 256 .*"
                                         r"3 x 256 x 500 x 2 float64 values"):
        lb.kernel_map_estimate(x, w)
    with pytest.raises(ValueError, match="^n_candidates must be >= 1"):
        lb.kernel_map_estimate(x, w, n_candidates=0)


def test_the_clouds_kept_count_against_the_limit(monkeypatch):
    import locbook.tracking.bayes as bayes
    rss = np.full((2, 6, 3), -60.0)
    monkeypatch.setattr(bayes, "MAX_ARRAY_BYTES", 8 * 3 * 2 * 100 * 2)       # three clouds of 2 runs x 100 x 2
    run = lambda steps: lb.particle_filter(rss, _guard_model(), rng=np.random.default_rng(0), n_particles=100,
                                           region_m=((0, 0), (10, 10)), cloud_steps=steps)
    assert sorted(run([0, 2, 5, 9]).clouds) == [0, 2, 5]           # step 9 does not exist: nothing kept
    with pytest.raises(ValueError, match=r"^cloud_steps: the 4 clouds kept .* 4 x 2 x 100 x 2 float64 values"):
        run(range(4))


def test_kernel_map_estimate_of_no_particles_is_one_line():
    """Before: numpy's "attempt to get argmax of an empty sequence"."""
    with pytest.raises(ValueError, match=r"^particles_m \(R, N, dim\) must hold at least one particle per run"):
        lb.kernel_map_estimate(np.zeros((1, 0, 2)), np.zeros((1, 0)))


#: the masked-reading test's readers (the corners in another order than READERS) and model
MASKED_READERS = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
MASKED_MODEL = lb.RssModel(MASKED_READERS, lb.PathLossModel(-40.0, 2.0, 3.0, min_distance_m=0.1))


def test_a_single_runs_masked_reading_is_not_heard_in_the_particle_filter():
    truth = np.stack([np.linspace(1, 9, 8), np.linspace(2, 8, 8)], -1)
    power = MASKED_MODEL.mean_rss_dbm(truth[None])[0] + np.random.default_rng(3).normal(0, 3, (8, 4))
    where = np.zeros(power.shape, bool)
    where[::2, 1] = True
    masked = np.ma.array(np.where(where, 1e3, power), mask=where)      # 1e3 dBm under the mask: never read
    kw = dict(n_particles=200, region_m=([0.0, 0.0], [10.0, 10.0]))
    got = lb.particle_filter(masked, MASKED_MODEL, rng=np.random.default_rng(7), **kw)
    ref = lb.particle_filter(np.where(where, np.nan, power), MASKED_MODEL, rng=np.random.default_rng(7), **kw)
    np.testing.assert_array_equal(got.mean, ref.mean)
