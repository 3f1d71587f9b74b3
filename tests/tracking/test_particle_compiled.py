"""The particle filter's compiled path: the fused RSS log-likelihood equals the model's numpy
log-likelihood (and a closed form) across the model's options, its building blocks equal numpy's (the pairwise sum bit
for bit, log10 within 2 ulp), the filter gives the same particles, decisions and estimates with numba on and off for a
fixed seed, and the compiled filter allocates no temporary of the size of the readings times the particles."""
import tracemalloc

import numpy as np
import pytest

import locbook as lb
from locbook.tracking import _compiled
from locbook.tracking import particle as P

pytest.importorskip("numba")
from locbook.tracking import _particle_kernels as K  # noqa: E402

pytestmark = pytest.mark.compiled

ANCHORS = np.array([[0.0, 0.0], [20.0, 0.0], [20.0, 15.0], [0.0, 15.0], [10.0, 7.5]])
# an office's walls: a long one, a short one, a diagonal, and one through an anchor's column
WALLS = np.array([[[5.0, -1.0], [5.0, 16.0]], [[12.0, 4.0], [12.0, 9.0]], [[0.0, 10.0], [8.0, 14.0]],
                  [[10.0, 0.0], [10.0, 5.0]]])


def _rel(a, b):
    """max |a - b| / |b| over the finite entries; the infinite ones must be equal."""
    a, b = np.asarray(a), np.asarray(b)
    fin = np.isfinite(b)
    np.testing.assert_array_equal(a[~fin], b[~fin])
    return float(np.max(np.abs(a[fin] - b[fin]) / np.maximum(np.abs(b[fin]), 1e-300), initial=0.0))


def _models(R, T):
    rng = np.random.default_rng(5)
    m = len(ANCHORS)
    yield "scalar", lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.5, 4.0, min_distance_m=0.1))
    yield "per anchor", lb.RssModel(ANCHORS, lb.PathLossModel(rng.uniform(-45, -35, m), rng.uniform(2, 3, m),
                                                              rng.uniform(2, 6, m), ref_distance_m=2.0))
    yield "per run and step", lb.RssModel(ANCHORS, lb.PathLossModel(
        rng.uniform(-45, -35, (R, T, m)), rng.uniform(2, 3, (R, T, m)), rng.uniform(2, 6, (R, T, 1)),
        min_distance_m=0.5), per_step_channel=True)
    yield "per-run anchors", lb.RssModel(ANCHORS + rng.uniform(-1, 1, (R, m, 2)),
                                         lb.PathLossModel(-40.0, 2.5, 4.0, min_distance_m=1.0))
    heights = np.column_stack([ANCHORS, rng.uniform(2, 3, m)])
    yield "tag height", lb.RssModel(heights, lb.PathLossModel(-40.0, 2.5, 4.0), tag_height_m=1.2)
    walls = np.array([[[5.0, -1.0], [5.0, 16.0]]])
    yield "walls without loss", lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.5, 4.0, min_distance_m=0.1), walls)
    yield "walls with a loss", lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.5, 4.0, wall_attenuation_db=3.5), WALLS)
    yield "walls, per-run anchors, per-anchor sigma", lb.RssModel(
        ANCHORS + rng.uniform(-1, 1, (R, m, 2)), lb.PathLossModel(-40.0, 2.5, rng.uniform(2, 6, m),
                                                                 wall_attenuation_db=2.0), WALLS)


@pytest.mark.parametrize("shared", [False, True])
def test_fused_likelihood_equals_the_numpy_likelihood_across_the_model_options(shared):
    R, T, N = 3, 4, 700
    rng = np.random.default_rng(0)
    x = rng.uniform(-2, 22, (N, 2) if shared else (R, N, 2))
    x[..., :3, :] = ANCHORS[:3] + 1e-3                      # inside every near-field clamp
    z = rng.uniform(-80, -40, (R, len(ANCHORS)))
    z[1, 2] = np.nan                                        # not heard: left out
    z[2, :] = np.nan                                        # a run that heard nothing: 0
    for name, model in _models(R, T):
        for step in (0, T - 1):
            ours = P._fused_rss_log_likelihood(model, z, x, step)
            ref = model.log_likelihood(z, x, step, constant=False)
            assert ours.shape == ref.shape == (R, N), name
            assert _rel(ours, ref) < 1e-12, name
            assert np.all(ours[2] == 0.0), name


def test_fused_likelihood_of_a_state_sees_its_position_columns_and_a_1e300_reading_gives_minus_inf():
    model = lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.5, 4.0, min_distance_m=0.1))
    rng = np.random.default_rng(1)
    states = rng.uniform(0, 15, (2, 400, 4))                # (x, vx, y, vy): positions at columns 0 and 2
    z = rng.uniform(-80, -40, (2, len(ANCHORS)))
    z[1, 3] = 1e300                                         # every particle's likelihood overflows in run 1
    ours = P._fused_rss_log_likelihood(model, z, states, 0, np.array([0, 2]))
    ref = model.log_likelihood(z, states[..., [0, 2]], 0, constant=False)
    assert np.all(ours[1] == -np.inf) and np.all(ref[1] == -np.inf)
    assert _rel(ours, ref) < 1e-12


def test_fused_likelihood_equals_the_closed_form_at_known_distances():
    """A tag at (0, 0) with anchors at 1 m, 10 m and 100 m: h = P0, P0 - 10 n, P0 - 20 n exactly."""
    n, p0, sigma = 2.0, -40.0, 4.0
    model = lb.RssModel(np.array([[1.0, 0.0], [0.0, 10.0], [-100.0, 0.0]]), lb.PathLossModel(p0, n, sigma))
    z = np.array([[-41.0, -62.0, -77.0]])
    want = -0.5 * ((-41.0 - p0) ** 2 + (-62.0 - (p0 - 10 * n)) ** 2 + (-77.0 - (p0 - 20 * n)) ** 2) / sigma**2
    assert P._fused_rss_log_likelihood(model, z, np.zeros((1, 2)), 0)[0, 0] == pytest.approx(want, rel=1e-15)


def test_compiled_wall_counts_are_numpys_exactly():
    """The kernel's wall counts equal lb.wall_crossings on particles everywhere, on the wall lines and at their ends
    (the same expressions in the same order: the same signs, so the same integers)."""
    rng = np.random.default_rng(3)
    pos = np.concatenate([rng.uniform(-2, 22, (4000, 2)),
                          WALLS.reshape(-1, 2),                                            # the walls' ends
                          WALLS[:, 0] + rng.random((len(WALLS), 1)) * (WALLS[:, 1] - WALLS[:, 0])])   # on the walls
    n = pos.shape[0]
    buf = np.zeros(n)
    for j, (ax, ay) in enumerate(ANCHORS):
        out = np.zeros(n)
        for i0 in range(0, n, 512):
            part = np.ascontiguousarray(pos[i0:i0 + 512].T)
            K._crossings(part, part.shape[1], ax, ay, WALLS, buf[:part.shape[1]])
            out[i0:i0 + part.shape[1]] = buf[:part.shape[1]]
        np.testing.assert_array_equal(out, lb.wall_crossings(pos, ANCHORS[j:j + 1], WALLS)[:, 0])
    assert lb.wall_crossings(pos, ANCHORS, WALLS).max() >= 2          # some paths cross two walls


def test_fused_likelihood_refuses_what_numpy_refuses():
    plain = lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.5, 4.0))
    far = np.full((1, 10, 2), 1e200)                        # distances overflow: numpy's error
    with pytest.raises(ValueError, match="overflow"):
        P._fused_rss_log_likelihood(plain, np.full((1, 5), -60.0), far, 0)
    nan = np.ones((1, 10, 2))
    nan[0, 4, 1] = np.nan
    with pytest.raises(ValueError, match="positions_m"):
        P._fused_rss_log_likelihood(plain, np.full((1, 5), -60.0), nan, 0)


@pytest.mark.parametrize("n", [0, 1, 7, 8, 9, 127, 128, 129, 1000, 4097, 10_000, 65_537])
def test_pairwise_sum_is_numpys_sum_bit_for_bit(n):
    a = np.random.default_rng(n).random(n) * np.random.default_rng(n + 1).random(n) ** 8
    assert K._pairwise_sum(a, 0, n) == a.sum()


def _weight_rows(n, rng):
    """Rows of weights that stress a systematic search: uneven, flat (every point on a cumulative sum when u = 0),
    dyadic steps, most weight on one particle, long runs of zeros, and tiny weights beside large ones."""
    uneven = np.exp(-0.5 * ((rng.random(n) - 0.5) / 0.05) ** 2)
    dyadic = np.repeat([0.5, 0.25, 0.125, 0.0625, 0.0625], -(-n // 5))[:n]
    spike = np.full(n, 1e-12)
    spike[n // 3] = 1.0
    zeros = np.where(rng.random(n) < 0.9, 0.0, rng.random(n))
    zeros[-1] = 1.0
    mixed = 10.0 ** rng.uniform(-300, 0, n)
    rows = np.stack([uneven, np.ones(n), dyadic, spike, zeros, mixed])
    return rows / rows.sum(-1, keepdims=True)


def test_compiled_systematic_resampling_keeps_the_ancestors_with_thousands_of_rows():
    """The k-th resampled row is shifted by 2k (the one-call search of systematic_resample): with 20,000 rows the
    shift reaches 4e4, where the points and the cumulative sums keep fewer bits; draws of 0 and zero weights put
    points on the sums."""
    from locbook.tracking.resampling import systematic_resample
    rng = np.random.default_rng(3)
    w = rng.random((20_000, 3)) ** 4
    w[::7, 1] = 0.0
    w /= w.sum(-1, keepdims=True)
    u = rng.random(20_000)
    u[::5] = 0.0
    x = rng.random((20_000, 3, 2))
    out, log_w = np.empty_like(x), np.empty_like(w)
    K._nb_systematic(w, u, np.ones(20_000, bool), x, out, log_w)
    idx = systematic_resample(w, u)
    np.testing.assert_array_equal(out, np.take_along_axis(x, idx[..., None], axis=1))


@pytest.mark.parametrize("n", [1, 2, 5, 64, 1000, 10_007])
def test_compiled_systematic_resampling_draws_the_ancestors_of_systematic_resample(n):
    """The kernel's histogram search against the searchsorted reference on the same weights and draws, including
    draws 0 and just below 1 that put points exactly on (or one ulp from) cumulative sums; runs not resampled keep
    their particles and their log-weights."""
    from locbook.tracking.resampling import systematic_resample
    rng = np.random.default_rng(n)
    w = np.concatenate([_weight_rows(n, rng)] * 3)
    u = np.concatenate([np.zeros(6), np.full(6, np.nextafter(1.0, 0.0)), rng.random(6)])
    do = np.ones(w.shape[0], bool)
    do[[4, 11]] = False
    x = rng.random((w.shape[0], n, 3))
    out, log_w = np.empty_like(x), np.empty_like(w)
    K._nb_systematic(w, u, do, x, out, log_w)
    idx = systematic_resample(w[do], u[do])
    np.testing.assert_array_equal(out[do], np.take_along_axis(x[do], idx[..., None], axis=1))
    np.testing.assert_array_equal(out[~do], x[~do])
    np.testing.assert_array_equal(log_w[do], np.log(1.0 / n))
    np.testing.assert_array_equal(log_w[~do], np.log(np.maximum(w[~do], 1e-300)))


def test_log10_is_within_two_ulp_of_numpy_and_exact_at_powers_of_ten():
    rng = np.random.default_rng(2)
    x = np.concatenate([np.exp(rng.uniform(-700, 700, 200_000)), 10.0 ** np.arange(-300, 301),
                        [0.0, 5e-324, 1e-310, np.inf, np.sqrt(2), np.sqrt(0.5), 1.0]])
    out, work = np.empty_like(x), np.empty_like(x)
    K._log10_block(x, out, work, x.size)
    with np.errstate(divide="ignore"):
        ref = np.log10(x)
    fin = np.isfinite(ref) & (ref != 0)
    assert np.max(np.abs(out[fin] - ref[fin]) / np.spacing(np.abs(ref[fin]))) <= 2.0
    np.testing.assert_array_equal(out[~fin], ref[~fin])
    exact = (x >= 1e-22) & (x <= 1e22) & np.isin(x, 10.0 ** np.arange(-22, 23))     # exactly representable powers
    np.testing.assert_array_equal(out[exact], np.round(ref[exact]))


def _scenario(R=6, T=6, seed=3):
    rng = np.random.default_rng(seed)
    model = lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.5, 4.0, min_distance_m=0.1))
    pos = np.clip(7 + np.cumsum(0.5 * rng.standard_normal((R, T, 2)), axis=1), 0.5, 14.5)
    rss = model.mean_rss_dbm(pos.reshape(-1, 2))[0].reshape(R, T, -1) + 4 * rng.standard_normal((R, T, 5))
    rss[0, 2, 1] = np.nan
    return model, rss


def _both(monkeypatch, fn):
    """fn() with numba off, then on (the compiled path for any size)."""
    monkeypatch.setattr(P, "_NUMBA_MIN_PARTICLES", 0)
    monkeypatch.setattr(_compiled, "_NUMBA_ENABLED", False)
    plain = fn()
    monkeypatch.setattr(_compiled, "_NUMBA_ENABLED", True)
    fast = fn()
    # the compiled path ran (a kernel that failed would have turned it off, and this would compare numpy with numpy)
    assert _compiled._NUMBA_ENABLED and "locbook.tracking._particle_kernels" in _compiled._KERNEL_MODULES
    return plain, fast


CASES = {
    "systematic every step": dict(),
    "N_eff-triggered": dict(resample_threshold=0.5),
    "stratified": dict(resampling="stratified"),
    "literal cdf": dict(resampling_cdf="literal_ozkaya2011"),
    "velocity, per-axis spread": dict(velocity_m=[0.1, -0.2], spread_m=[0.3, 0.6]),
    "fresh uniform proposal": dict(spread_m=np.inf),
    "sqrt smoothing": dict(weight_smoothing="sqrt", resample_threshold=0.5),
    "clouds": dict(cloud_steps=(0, 3)),
    "office walls with a loss": dict(walls=WALLS),
}


@pytest.mark.parametrize("case", list(CASES))
def test_the_filter_gives_the_same_results_with_numba_on_and_off(monkeypatch, case):
    """The same random draws in the same order: the same particles and resampling decisions; the weights and the
    estimates agree to round-off (the likelihood's log10 and the moments' sums differ in the last bits)."""
    model, rss = _scenario()
    kw = dict(n_particles=3000, region_m=([0.0, 0.0], [20.0, 15.0]), **CASES[case])
    if "walls" in kw:
        model = lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.5, 4.0, wall_attenuation_db=3.5), kw.pop("walls"))
    plain, fast = _both(monkeypatch, lambda: lb.particle_filter(rss, model, rng=np.random.default_rng(4), **kw))
    np.testing.assert_array_equal(fast.particles_m, plain.particles_m)
    np.testing.assert_array_equal(fast.resampled, plain.resampled)
    np.testing.assert_array_equal(fast.map_m, plain.map_m)
    for name in ("mean", "cov", "n_eff", "weights"):
        np.testing.assert_allclose(getattr(fast, name), getattr(plain, name), rtol=1e-11, atol=1e-13, err_msg=name)
    np.testing.assert_allclose(fast.log_weights, plain.log_weights, rtol=1e-11, atol=1e-11)
    assert fast.clouds.keys() == plain.clouds.keys()
    for t in plain.clouds:
        np.testing.assert_array_equal(fast.clouds[t], plain.clouds[t])


def test_the_filter_with_motion_and_a_callable_likelihood_matches_with_numba_on_and_off(monkeypatch):
    model, rss = _scenario()
    cv = lb.constant_velocity(1.0, 0.05)
    kw = dict(n_particles=2000, region_m=([0.0, 0.0], [20.0, 15.0]), motion=cv)
    plain, fast = _both(monkeypatch, lambda: lb.particle_filter(rss, model, rng=np.random.default_rng(5), **kw))
    np.testing.assert_array_equal(fast.particles_m, plain.particles_m)
    np.testing.assert_allclose(fast.mean, plain.mean, rtol=1e-11, atol=1e-12)

    def loglik(x, t):
        return model.log_likelihood(rss[:, t], x, t, constant=False)

    start = np.random.default_rng(6).uniform(0, 15, (6, 2000, 2))
    # resampled only when N_eff drops below half, so that the final weights are not all 1/N
    plain, fast = _both(monkeypatch, lambda: lb.particle_filter(None, loglik, rng=np.random.default_rng(7),
                                                                n_steps=rss.shape[1], initial_particles_m=start,
                                                                resample_threshold=0.5))
    assert not np.all(plain.weights == plain.weights[:, :1])
    assert not plain.resampled.all() and plain.resampled.any()
    np.testing.assert_array_equal(fast.particles_m, plain.particles_m)     # the same likelihood: the same decisions
    np.testing.assert_allclose(fast.weights, plain.weights, rtol=1e-13, atol=0)   # exp within 2 ulp of numpy's
    np.testing.assert_allclose(fast.mean, plain.mean, rtol=1e-12, atol=1e-12)


def test_a_collapsed_run_is_isolated_the_same_way_on_the_compiled_path(monkeypatch):
    model, rss = _scenario(R=4)
    bad = rss.copy()
    bad[2, 3, 1] = 1e300
    kw = dict(n_particles=1000, region_m=([0.0, 0.0], [20.0, 15.0]))

    def run():
        with pytest.warns(RuntimeWarning, match=r"1 of 4 runs \(first: run 2, step 3"):
            return lb.particle_filter(bad, model, rng=np.random.default_rng(8), **kw)

    plain, fast = _both(monkeypatch, run)
    assert fast.diverged.tolist() == [False, False, True, False] and fast.diverged_step[2] == 3
    for name in ("mean", "particles_m", "weights"):
        a, b = getattr(fast, name), getattr(plain, name)
        np.testing.assert_array_equal(np.isnan(a), np.isnan(b))
        np.testing.assert_allclose(a[[0, 1, 3]], b[[0, 1, 3]], rtol=1e-11, atol=1e-12)


def test_the_compiled_filter_allocates_no_readings_times_particles_temporary(monkeypatch):
    """numpy's likelihood makes (R, N, m, dim) offsets and (R, N, m) means and residuals; the compiled path keeps a
    few (R, N) and (R, N, dim) buffers. Peak of numpy's allocations (tracemalloc) over one (R, N, dim) array."""
    model, rss = _scenario(R=10, T=3)
    n = 5000
    cloud = 10 * n * 2 * 8

    def peak():
        def run():
            lb.particle_filter(rss, model, rng=np.random.default_rng(9), n_particles=n,
                               region_m=([0.0, 0.0], [20.0, 15.0]))
        run()                               # numba compiles or loads its kernels (Python objects) outside the count
        tracemalloc.start()
        try:
            run()
            return tracemalloc.get_traced_memory()[1] / cloud
        finally:
            tracemalloc.stop()

    plain, fast = _both(monkeypatch, peak)
    # particles and their spare (2 clouds) + logits, weights, log-weights, final log-weights (4 half clouds) = 4,
    # and the random walk's block of normals (512 KiB = 0.33 cloud here) and the small outputs
    assert fast < 4.0 + 1.5 * 2**20 / cloud
    assert plain > 2 * len(ANCHORS)          # the (R, N, m, dim) offsets alone are m clouds


def test_kernels_that_cannot_compile_turn_the_compiled_path_off_with_a_warning(monkeypatch):
    model, rss = _scenario(R=2, T=3)
    kw = dict(n_particles=500, region_m=([0.0, 0.0], [20.0, 15.0]))
    monkeypatch.setattr(_compiled, "_NUMBA_ENABLED", False)
    plain = lb.particle_filter(rss, model, rng=np.random.default_rng(10), **kw)

    def broken(*args):
        raise RuntimeError("no compiler here")

    monkeypatch.setattr(_compiled, "_NUMBA_ENABLED", True)
    monkeypatch.setattr(P, "_NUMBA_MIN_PARTICLES", 0)
    monkeypatch.setattr(_compiled, "_KERNEL_MODULES", {})              # not tried yet in this session
    monkeypatch.setattr(K, "_nb_moments", broken)
    with pytest.warns(RuntimeWarning, match="compiled particle filter failed.*no compiler here") as caught:
        res = lb.particle_filter(rss, model, rng=np.random.default_rng(10), **kw)
    assert [w.filename for w in caught] == [__file__]                 # once, at the caller's line
    assert _compiled._NUMBA_ENABLED is False
    np.testing.assert_array_equal(res.mean, plain.mean)
