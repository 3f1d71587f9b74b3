"""Property-based fuzzing of every public filter (bounded example counts: the module runs in well under a
minute).

Inputs: NaN / inf / huge / tiny values placed in z, F, Q, R, x0, P0 (one entry, or a symmetric pair), the readings
and the weights; empty batches, zero steps, int and float32 dtypes, non-contiguous (strided) arrays. The rule:

- a correct answer: equal to filterpy (per run, the components present) on finite well-posed input, and equal to
  the float64 contiguous answer for int / float32 / strided input;
- or NaN with a per-run flag (particle filters: ``diverged``, the collapse of the likelihood);
- or a clear locbook error (LocbookError, or a ValueError whose message names the argument);
- never a raw numpy / scipy exception (IndexError, LinAlgError, ZeroDivisionError, FloatingPointError, a broadcast
  or reshape ValueError), never a finite (or NaN) answer from non-finite input without a flag.
"""
import contextlib
import re
import warnings

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import locbook as lb
from locbook.errors import LocbookError
from locbook.tracking import _compiled as K
from locbook.tracking.resampling import RESAMPLING_METHODS

pytestmark = pytest.mark.fuzz

MODEL = lb.constant_velocity(1.0, 0.05)
F0, Q0 = MODEL.F, MODEL.Q
H0 = MODEL.position_measurement_matrix()
R0 = np.array([[0.5, 0.1], [0.1, 0.8]])
X00, P00 = np.array([0.0, 0.0, 1.0, 0.5]), np.eye(4)
ANCHORS = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
CHANNEL = lb.PathLossModel(-40.0, 2.0, 2.0)

SPECIAL = [np.nan, np.inf, -np.inf, 1e300, -1e300, 1e-300, 0.0, 1e150, -5.0]
TARGETS = ["none", "z", "F", "Q", "R", "x0", "P0"]
RAW = ("could not be broadcast", "operands could not", "cannot reshape", "shape mismatch", "out of bounds",
       "too many indices", "singular matrix", "zero-size array", "matmul: Input operand")
SETTINGS = dict(deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])

try:
    import numba  # noqa: F401
    HAVE_NUMBA = True
except ImportError:
    HAVE_NUMBA = False


@contextlib.contextmanager
def ekf_path(path):
    saved = K._NUMBA_ENABLED, K._NUMBA_MIN_WORK
    K._NUMBA_ENABLED, K._NUMBA_MIN_WORK = path == "numba", 0
    try:
        yield
    finally:
        K._NUMBA_ENABLED, K._NUMBA_MIN_WORK = saved


def outcome(call, names):
    """``("ok", result)`` or ``("error", exc)`` for a clear error; anything else fails the test."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)      # overflow warnings are fine; the result is checked
            return "ok", call()
    except LocbookError as exc:
        return "error", exc
    except ValueError as exc:
        text = str(exc)
        assert type(exc) is ValueError, f"unexpected {type(exc).__name__}: {text}"
        assert not any(raw in text for raw in RAW), f"a raw numpy message: {text}"
        assert any(name in text for name in names), f"the message names no argument {names}: {text}"
        return "error", exc


def strided(a):
    """The same values in a non-contiguous view (every other element of a larger array along the last axis)."""
    a = np.asarray(a)
    if a.ndim == 0:
        return a
    big = np.zeros(a.shape[:-1] + (2 * a.shape[-1],), dtype=a.dtype)
    big[..., ::2] = a
    return big[..., ::2]


def _track(batch, T, seed):
    rng = np.random.default_rng(seed)
    z = np.cumsum(rng.normal(size=batch + (T, 2)), axis=-2) + rng.normal(scale=0.7, size=batch + (T, 2))
    z[rng.random(z.shape) < 0.15] = np.nan
    return z


@st.composite
def problems(draw):
    """A KF problem with at most one corruption, a dtype and a memory layout."""
    batch = draw(st.sampled_from([(), (0,), (1,), (3,)]))
    T = draw(st.sampled_from([0, 1, 5]))
    args = dict(z=_track(batch, T, draw(st.integers(0, 50))), F=F0.copy(), Q=Q0.copy(), R=R0.copy(), x0=X00.copy(),
                P0=P00.copy())
    target = draw(st.sampled_from(TARGETS))
    value = draw(st.sampled_from(SPECIAL))
    if target != "none" and args[target].size:
        a = args[target]
        i = np.unravel_index(draw(st.integers(0, a.size - 1)), a.shape)
        a[i] = value
        if target in ("Q", "R", "P0") and draw(st.booleans()):
            a[i[::-1]] = value                  # a symmetric pair: reaches the filter past the symmetry check
    else:
        target = "none"
    dtype = draw(st.sampled_from(["float64", "float32", "int"]))
    layout = draw(st.sampled_from(["contiguous", "strided"]))
    return args, target, value, dtype, layout


def _convert(args, dtype, layout):
    out = {}
    for k, v in args.items():
        if dtype == "float32":
            with np.errstate(over="ignore"):       # 1e300 becomes inf in float32: the filter must refuse it
                v = v.astype(np.float32)
        elif dtype == "int" and np.all(np.isfinite(v)) and np.all(np.abs(v) < 1e9):
            v = np.round(v).astype(np.int64)
        out[k] = strided(v) if layout == "strided" else v
    return out


def _as_float64(args):
    return {k: np.asarray(v, dtype=float).copy() for k, v in args.items()}


def filterpy_kf(z, F, Q, R, x0, P0):
    """filterpy's KalmanFilter per run with the components present; None where filterpy fails or is not finite."""
    batch = z.shape[:-2]
    flat = z.reshape((-1,) + z.shape[-2:])
    xs = np.empty(flat.shape[:-1] + (4,))
    for b in range(flat.shape[0]):
        f = KalmanFilter(dim_x=4, dim_z=2)
        f.F, f.Q, f.x, f.P = F, Q, x0.copy(), P0.copy()
        for k in range(flat.shape[1]):
            f.predict()
            keep = np.isfinite(flat[b, k])
            if keep.any():
                try:
                    f.update(flat[b, k, keep], R=R[np.ix_(keep, keep)], H=H0[keep])
                except np.linalg.LinAlgError:
                    return None
            xs[b, k] = f.x
    return xs.reshape(batch + z.shape[-2:-1] + (4,)) if np.all(np.isfinite(xs)) else None


def _well_posed(target, value):
    return target == "none" or (target == "z" and np.isnan(value))


def _check_kalman_like(kind, res, args64, target, value, reference):
    """The rule for a Kalman-family result (the filter returned): finite states and covariances, never from
    non-finite input, the guard's fields of the batch's shape; equal to filterpy on well-posed input."""
    if target != "none" and not np.isfinite(value) and not (target == "z" and np.isnan(value)):
        pytest.fail(f"{kind}: an answer from a non-finite {target} ({value}) without an error")
    assert np.all(np.isfinite(res.mean)) and np.all(np.isfinite(res.cov)), f"{kind}: non-finite output without a flag"
    batch = res.mean.shape[:-2]
    assert res.diverged.shape == batch and res.diverged_step.shape == batch
    assert res.nis.shape == batch + (args64["z"].shape[-2],)
    if _well_posed(target, value) and reference is not None:
        np.testing.assert_allclose(res.mean, reference, rtol=1e-7, atol=1e-7, err_msg=kind)


FILTER_NAMES = ["kalman_filter", "ekf numpy", "ekf numba", "ukf", "ekf nonlinear", "ukf nonlinear"]


def _run(kind, a):
    if kind == "kalman_filter":
        return lb.kalman_filter(a["F"], a["Q"], a["x0"], a["P0"], lb.LinearMeasurement(a["z"], H0, a["R"]))
    if kind.endswith("nonlinear"):            # the linear model written as a NonlinearMeasurement (h = H x)
        stream = [lb.NonlinearMeasurement(a["z"], lambda x: x @ H0.T, a["R"],
                                          jacobian=lambda x: np.broadcast_to(H0, x.shape[:-1] + H0.shape))]
        kind = kind.split()[0] + " numpy"
    else:
        stream = [lb.LinearMeasurement(a["z"], H0, a["R"])]
    if kind == "ukf" or kind.startswith("ukf "):
        return lb.unscented_kalman_filter(a["F"], a["Q"], a["x0"], a["P0"], stream, alpha=1.0)
    with ekf_path(kind.split()[1]):
        return lb.extended_kalman_filter(a["F"], a["Q"], a["x0"], a["P0"], stream)


@pytest.mark.parametrize("kind", [k for k in FILTER_NAMES if HAVE_NUMBA or k != "ekf numba"])
@settings(max_examples=60, **SETTINGS)
@given(problem=problems())
def test_fuzz_kalman_family(kind, problem):
    args, target, value, dtype, layout = problem
    given_args = _convert(args, dtype, layout)
    args64 = _as_float64(given_args)              # the values the filter is given, as float64 contiguous arrays
    status, res = outcome(lambda: _run(kind, given_args), ("z", "F", "Q", "R", "x0", "P0", "H", "measurements",
                                                             "LinearMeasurement", "nonlinear measurement"))
    if status == "error":
        return
    reference = None
    if _well_posed(target, value) and args64["z"].size:
        reference = filterpy_kf(**args64)
        assert reference is not None, "filterpy fails where we answered"
    _check_kalman_like(kind, res, args64, target, value, reference)
    if dtype != "float64" or layout != "contiguous":
        status64, res64 = outcome(lambda: _run(kind, args64), ("z",))
        assert status64 == "ok"
        np.testing.assert_allclose(res.mean, res64.mean, rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(res.diverged, res64.diverged)


@st.composite
def rss_problems(draw):
    batch = draw(st.sampled_from([(), (0,), (2,)]))
    T = draw(st.sampled_from([0, 1, 4]))
    rng = np.random.default_rng(draw(st.integers(0, 50)))
    pos = 5 + np.cumsum(0.3 * rng.standard_normal(batch + (T, 2)), axis=-2)
    z = CHANNEL.sample_rss_dbm(np.linalg.norm(pos[..., None, :] - ANCHORS, axis=-1), rng=rng)
    if z.size:
        z.reshape(-1)[draw(st.integers(0, z.size - 1))] = draw(st.sampled_from(SPECIAL))
    mode = draw(st.sampled_from(["parallel", "serial"]))
    return z, mode, draw(st.sampled_from(["float64", "float32"])), draw(st.booleans())


@settings(max_examples=40, **SETTINGS)
@given(problem=rss_problems(), path=st.sampled_from(["numpy", "numba"] if HAVE_NUMBA else ["numpy"]),
       unscented=st.booleans())
def test_fuzz_rss_streams(problem, path, unscented):
    z, mode, dtype, is_strided = problem
    with np.errstate(over="ignore"):
        given_z = z.astype(dtype)
    given_z = strided(given_z) if is_strided else given_z

    def call(power):
        meas = lb.RssMeasurement(power, ANCHORS, CHANNEL, MODEL.position_index, mode=mode)
        x0 = MODEL.state_from(np.array([5.0, 5.0]))
        if unscented:
            return lb.unscented_kalman_filter(F0, Q0, x0, P00, [meas], alpha=1.0)
        with ekf_path(path):
            return lb.extended_kalman_filter(F0, Q0, x0, P00, [meas])

    status, res = outcome(lambda: call(given_z), ("rss_dbm", "RssMeasurement"))
    if status == "error":
        return
    finite_input = not np.isinf(z).any()
    assert finite_input, "an answer from an infinite reading without an error"
    assert np.all(np.isfinite(res.mean)) and np.all(np.isfinite(res.cov))
    ref = call(np.asarray(given_z, dtype=float).copy())
    np.testing.assert_allclose(res.mean, ref.mean, rtol=1e-12, atol=1e-12)


@st.composite
def particle_problems(draw):
    runs = draw(st.sampled_from([0, 1, 3]))
    T = draw(st.sampled_from([0, 1, 4]))
    rng = np.random.default_rng(draw(st.integers(0, 50)))
    model = lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.0, 3.0, min_distance_m=0.1))
    pos = 5 + np.cumsum(0.3 * rng.standard_normal((runs, T, 2)), axis=1)
    rss = model.mean_rss_dbm(pos.reshape(-1, 2))[0].reshape(runs, T, 4) + 3 * rng.standard_normal((runs, T, 4))
    corrupt = None
    if rss.size and draw(st.booleans()):
        corrupt = np.unravel_index(draw(st.integers(0, rss.size - 1)), rss.shape)
        rss[corrupt] = draw(st.sampled_from(SPECIAL))
    return model, rss, corrupt, draw(st.sampled_from(["float64", "float32", "int"])), draw(st.booleans())


def _check_flags(res, rss, corrupt, estimates):
    """A collapsed run is flagged with NaN estimates from its step; no other run is NaN; flags have the runs' shape."""
    runs = rss.shape[0]
    assert res.diverged.shape == (runs,) and res.diverged_step.shape == (runs,)
    for r in range(runs):
        est = estimates[r]
        if res.diverged[r]:
            k = res.diverged_step[r]
            assert corrupt is not None and corrupt[0] == r and k == corrupt[1]
            assert np.all(np.isnan(est[k:])) and np.all(np.isfinite(est[:k]))
        else:
            assert np.all(np.isfinite(est)), "NaN estimates without a flag"


@settings(max_examples=40, **SETTINGS)
@given(problem=particle_problems(), which=st.sampled_from(["particle", "grid"]))
def test_fuzz_bayes_filters(problem, which):
    model, rss, corrupt, dtype, is_strided = problem
    with np.errstate(over="ignore"):
        given_rss = rss.astype(np.float32) if dtype == "float32" else rss
    if dtype == "int" and np.all(np.isfinite(rss)) and np.all(np.abs(rss) < 1e9):
        given_rss = np.round(rss).astype(np.int64)
    given_rss = strided(given_rss) if is_strided else given_rss
    cells = np.stack(np.meshgrid(np.arange(0.5, 10, 2.0), np.arange(0.5, 10, 2.0)), -1).reshape(-1, 2)

    def call(values):
        if which == "grid":
            return lb.grid_bayes_filter(values, model, cells, 1.0)
        return lb.particle_filter(values, model, rng=np.random.default_rng(0), n_particles=50,
                                  region_m=([0.0, 0.0], [10.0, 10.0]))

    status, res = outcome(lambda: call(given_rss), ("rss_dbm",))
    values = np.asarray(given_rss, dtype=float)       # what the filter was given (float32 turns 1e300 into inf)
    if status == "error":
        assert corrupt is not None, "an error on sane readings"
        if "collapsed in every run" in str(res):      # a collapse is an error only when no run is left
            assert values.shape[0] == 1, "one bad reading collapsed every run"
            assert f"step {corrupt[1]} (run {corrupt[0]})" in str(res)
        else:
            assert np.isinf(values[corrupt]), "an error on finite readings"
        return
    _check_flags(res, values, corrupt, res.mean)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ref = call(np.asarray(given_rss, dtype=float).copy())
    told = [w for w in caught if issubclass(w.category, RuntimeWarning) and "collapsed in" in str(w.message)]
    assert len(told) == (1 if res.n_diverged else 0), "a collapse must be told once (and only a collapse)"
    np.testing.assert_array_equal(res.mean, ref.mean)


@settings(max_examples=40, **SETTINGS)
@given(runs=st.sampled_from([0, 1, 3]), steps=st.sampled_from([1, 3]), bad=st.sampled_from([None, *SPECIAL]),
       method=st.sampled_from(list(RESAMPLING_METHODS)))
def test_fuzz_particle_filter_callback_likelihood(runs, steps, bad, method):
    rng = np.random.default_rng(0)
    start = rng.normal(0, 1, (runs, 30, 2))
    z = rng.normal(0, 1, (runs, steps, 2))

    def loglik(x, k):
        out = -0.5 * np.sum((z[:, k, None, :] - x) ** 2, axis=-1)
        if bad is not None and runs and k == steps - 1:
            out[0, :3] = bad
        return out

    status, res = outcome(lambda: lb.particle_filter(None, loglik, rng=np.random.default_rng(1), n_steps=steps,
                                                     initial_particles_m=start, spread_m=0.1, resampling=method),
                          ("log_likelihood",))
    collapse = bad is not None and runs and (np.isnan(bad) or bad == np.inf)
    if collapse and runs == 1:                   # every run collapsed: an error naming the likelihood and step
        assert status == "error" and re.search(rf"log_likelihood collapsed in every run.*step {steps - 1} \(run 0\)",
                                               str(res)), res
        return
    assert status == "ok"
    assert res.diverged.shape == (runs,)
    assert res.diverged.tolist() == ([True] + [False] * (runs - 1) if collapse else [False] * runs)
    finite = np.isfinite(res.mean).all(axis=(-2, -1))
    np.testing.assert_array_equal(finite, ~res.diverged)


@settings(max_examples=60, **SETTINGS)
@given(n=st.sampled_from([1, 2, 7, 20]), rows=st.sampled_from([(), (0,), (3,)]), bad=st.sampled_from([None, *SPECIAL]),
       method=st.sampled_from(list(RESAMPLING_METHODS)), dtype=st.sampled_from(["float64", "float32", "int"]),
       is_strided=st.booleans(), where=st.booleans())
def test_fuzz_resampling(n, rows, bad, method, dtype, is_strided, where):
    rng = np.random.default_rng(3)
    w = rng.random(rows + (n,)) + 0.01
    if bad is not None and w.size:
        w.reshape(-1)[0] = bad
    with np.errstate(over="ignore"):
        given_w = w.astype(np.float32) if dtype == "float32" else w
    if dtype == "int":
        given_w = np.ceil(np.where(np.isfinite(w) & (np.abs(w) < 1e9), w, 1.0) * 3).astype(np.int64)
    given_w = strided(given_w) if is_strided else given_w

    def call(values, seed=5):
        if where:
            return lb.resample_where(values, rng=np.random.default_rng(seed), method=method, threshold=n / 2)[0]
        return lb.resample(values, rng=np.random.default_rng(seed), method=method)

    status, idx = outcome(lambda: call(given_w), ("weights",))
    values = np.asarray(given_w, dtype=float)
    sane = values.shape[-1] > 0 and np.all(np.isfinite(values)) and np.all(values >= 0) and np.all(
        values.sum(axis=-1) > 0) and np.all(np.isfinite(values.sum(axis=-1)))
    if status == "error":
        assert not sane, f"an error on sane weights: {idx}"
        return
    assert sane, "indices from weights that are not a distribution"
    assert idx.shape == values.shape and idx.dtype.kind == "i"
    assert np.all((idx >= 0) & (idx < n))
    np.testing.assert_array_equal(idx, call(values.copy()))
    # a particle of zero weight is never drawn (resample_where keeps the rows it does not resample as they are)
    zero = values == 0
    if zero.any() and not where:
        drawn = np.zeros(values.shape, bool)
        np.put_along_axis(drawn, idx, True, -1)
        assert not (drawn & zero).any()


@settings(max_examples=30, **SETTINGS)
@given(n=st.sampled_from([0, 1, 5]), bad=st.sampled_from([None, *SPECIAL]),
       u=st.sampled_from([0.0, 0.5, 0.999, 1.0, -0.1,
                                                                                              np.nan]))
def test_fuzz_systematic_resample(n, bad, u):
    w = np.linspace(1.0, 2.0, n)
    if bad is not None and n:
        w[0] = bad
    status, idx = outcome(lambda: lb.systematic_resample(w[None], np.array([u])), ("weights", "uniforms"))
    sane = n > 0 and np.all(np.isfinite(w)) and np.all(w >= 0) and w.sum() > 0 and np.isfinite(w.sum())
    if status == "error":
        assert not (sane and 0 <= u < 1)
        return
    assert sane and 0 <= u < 1
    assert np.all((idx >= 0) & (idx < n))


# -- a masked reading is a missing reading -----------------------------------------------------------
@settings(max_examples=60, **SETTINGS)
@given(seed=st.integers(0, 10_000), batch=st.sampled_from([(), (3,), (70,)]), share=st.sampled_from([0.1, 0.4]),
       garbage=st.sampled_from([0.0, 1e3, np.inf, np.nan]), filt=st.sampled_from(["kf", "ekf", "ukf"]),
       path=st.sampled_from(["numpy", "numba"] if HAVE_NUMBA else ["numpy"]))
def test_property_masked_readings_equal_nan_readings_on_every_path(seed, batch, share, garbage, filt, path):
    """Masked readings (any value under the mask) give bit for bit the filter on NaN there, on the numpy and the
    compiled paths (70 runs: past the shared-covariance threshold, different masks per run)."""
    rng = np.random.default_rng(seed)
    z = _track(batch, 8, seed)
    where = rng.random(z.shape) < share
    run = dict(kf=lb.kalman_filter, ekf=lb.extended_kalman_filter, ukf=lb.unscented_kalman_filter)[filt]
    with ekf_path(path):
        got = run(F0, Q0, X00, P00, lb.LinearMeasurement(np.ma.array(np.where(where, garbage, z), mask=where), H0, R0))
        ref = run(F0, Q0, X00, P00, lb.LinearMeasurement(np.where(where, np.nan, z), H0, R0))
    np.testing.assert_array_equal(got.mean, ref.mean)
    np.testing.assert_array_equal(got.cov, ref.cov)
