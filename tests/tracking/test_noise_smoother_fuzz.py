"""Property-based fuzzing of the smoother, the noise fits and the online filter (bounded example counts:
the module runs in well under a minute).

Inputs: random linear-Gaussian models of 1-3 states and 0-2 readings per step whose covariances have any rank (0
included: deterministic states, a zero R), NaN-filled and all-missing readings, empty run axes, and one special
value (NaN, inf, 1e300, -5, 0) placed in F, Q, R, x0, P0 or the readings. The rule:

- a correct answer, checked by invariants: the smoother equals a hand-written RTS smoother (the pseudo-inverse
  gain, pykalman's form), its covariances are covariances and never exceed the filter's (P_filtered - P_smoothed is
  positive semi-definite), its last step is the filter's; EM's log-likelihood never decreases and its Q and R are
  covariances; ML never ends below its start, and a multiplier the likelihood does not depend on is flagged ``flat``
  with NaN estimates; the online filter equals the batch call;
- or a clear locbook error (LocbookError, or a ValueError of one line with no raw numpy/scipy text);
- never a raw LinAlgError / IndexError / numpy ValueError, never a finite answer from a non-finite model or an
  all-missing set of readings.
"""
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import locbook as lb
from locbook.errors import LocbookError
from locbook.tracking.smoother import rts_smoother

pytestmark = pytest.mark.fuzz

SPECIAL = [np.nan, np.inf, -np.inf, 1e300, -5.0, 0.0]
TARGETS = ["none", "z", "F", "Q", "R", "x0", "P0"]
RAW = ("could not be broadcast", "operands could not", "cannot reshape", "shape mismatch", "out of bounds",
       "too many indices", "ingular matrix", "zero-size array", "matmul: Input operand", "did not converge",
       "inhomogeneous", "unhashable")
SETTINGS = dict(deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])


def outcome(call):
    """``("ok", result)`` or ``("error", exc)`` for a clear error; anything else fails the test."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)      # overflow warnings are fine; the result is checked
            return "ok", call()
    except LocbookError as exc:
        assert "\n" not in str(exc), f"a message of several lines: {exc}"
        return "error", exc
    except ValueError as exc:
        text = str(exc)
        assert type(exc) is ValueError, f"unexpected {type(exc).__name__}: {text}"
        assert "\n" not in text, f"a message of several lines: {text}"
        assert not any(raw in text for raw in RAW), f"a raw numpy message: {text}"
        return "error", exc


def _psd(rng, n, rank, scale):
    """A random ``(n, n)`` covariance of the given rank (0: the zero matrix)."""
    G = rng.normal(size=(n, rank)) * scale
    return G @ G.T


@st.composite
def models(draw, min_steps=1, fitting=False):
    """A random linear model and readings, with at most one special value (``fitting``: mostly readings to fit)."""
    seed = draw(st.integers(0, 10_000))
    rng = np.random.default_rng(seed)
    n = draw(st.integers(1, 3))
    m = draw(st.sampled_from([1, 2, 1, 2, 1, 2, 0] if fitting else [0, 1, 2]))
    T = draw(st.integers(min_steps, 7))
    batch = draw(st.sampled_from([(), (1,), (3,), (), (1,), (3,), (0,)] if fitting else [(), (0,), (1,), (3,)]))
    F = np.eye(n) + 0.3 * rng.normal(size=(n, n)) * draw(st.sampled_from([0.0, 1.0]))
    Q = _psd(rng, n, draw(st.integers(0, n)), draw(st.sampled_from([1e-3, 0.3, 1.0])))
    P0 = _psd(rng, n, draw(st.integers(0, n)), draw(st.sampled_from([0.1, 1.0, 10.0])))
    R = _psd(rng, m, draw(st.integers(0, m) if m else st.just(0)), 1.0) + draw(st.sampled_from([0.0, 0.5])) * np.eye(m)
    H = rng.normal(size=(m, n))
    x0 = rng.normal(size=n)
    z = rng.normal(size=batch + (T, m)) * 2.0
    missing = draw(st.sampled_from(["none", "some", "none", "some", "all"] if fitting else ["none", "some", "all"]))
    if missing == "some":
        z[rng.random(z.shape) < 0.3] = np.nan
    elif missing == "all":
        z[...] = np.nan
    args = dict(F=F, Q=Q, R=R, H=H, x0=x0, P0=P0, z=z)
    target = draw(st.sampled_from(TARGETS + ["none"] * 4 if fitting else TARGETS))
    value = draw(st.sampled_from(SPECIAL))
    if target != "none" and args[target].size:
        a = args[target]
        i = np.unravel_index(draw(st.integers(0, a.size - 1)), a.shape)
        a[i] = value
        if target in ("Q", "R", "P0"):
            a[i[::-1]] = value                  # a symmetric pair: reaches the filter past the symmetry check
    else:
        target = "none"
    return args, target, value, missing


def _corrupt(target, value):
    """The special value makes the model invalid (a NaN reading is a missing one; anything else is garbage unless it
    is a finite value in a place where any finite value is legal)."""
    if target == "none" or target == "z" and np.isnan(value):
        return False
    if not np.isfinite(value):
        return True
    return target in ("Q", "R", "P0")          # -5 or 0 or 1e300 there may break positive semi-definiteness


def _filter(a, predict_first):
    return lb.kalman_filter(a["F"], a["Q"], a["x0"], a["P0"], lb.LinearMeasurement(a["z"], a["H"], a["R"]),
                            predict_first=predict_first, outputs=("x_pred", "P_pred", "P_cross"))


def _reference_rts(x, P, x_pred, P_pred, cross):
    """A hand-written RTS smoother of one run with the pseudo-inverse gain (pykalman's kalman_smoother form)."""
    T = x.shape[0]
    xs, Ps = x.copy(), P.copy()
    for k in range(T - 2, -1, -1):
        w, V = np.linalg.eigh(P_pred[k + 1])
        keep = w > 1e-12 * max(w[-1], 0.0)
        inv = (V[:, keep] / w[keep]) @ V[:, keep].T
        C = cross[k + 1] @ inv
        xs[k] = x[k] + C @ (xs[k + 1] - x_pred[k + 1])
        Ps[k] = P[k] + C @ (Ps[k + 1] - P_pred[k + 1]) @ C.T
    return xs, Ps


def _min_eig(A):
    return np.linalg.eigvalsh(0.5 * (A + np.swapaxes(A, -1, -2)))[..., 0] if A.size else np.zeros(A.shape[:-2])


@settings(max_examples=200, **SETTINGS)
@given(problem=models(), predict_first=st.booleans())
def test_fuzz_rts_smoother(problem, predict_first):
    args, target, value, missing = problem
    status, run = outcome(lambda: _filter(args, predict_first))
    if status == "error":
        event("filter: error")
        return
    assert not _corrupt(target, value) or np.isfinite(value) and target in ("Q", "R", "P0"), \
        f"the filter answered from a non-finite {target} ({value})"
    status, sm = outcome(lambda: rts_smoother(run))
    event(f"smoother: {status}")
    if status == "error":
        assert not np.isfinite(run.cov).all() or not np.isfinite(run.P_pred).all(), f"refused a finite run: {sm}"
        return
    T, n = run.mean.shape[-2:]
    assert sm.mean.shape == run.mean.shape and sm.cov.shape == run.cov.shape and sm.gain.shape == run.cov.shape[:-3] + (
        T - 1, n, n)
    if sm.mean.size == 0:
        return
    np.testing.assert_array_equal(sm.mean[..., -1, :], run.mean[..., -1, :])
    scale = max(1.0, float(np.abs(run.cov).max()))
    assert np.all(_min_eig(sm.cov) >= -1e-9 * scale), "a smoothed covariance that is not a covariance"
    assert np.all(_min_eig(run.cov - sm.cov) >= -1e-9 * scale), "smoothing added uncertainty"
    flat = lambda a, tail: a.reshape((-1,) + a.shape[a.ndim - tail:])
    for r, (x, P, xp, Pp, D, xs, Ps) in enumerate(zip(*(flat(a, t) for a, t in (
            (run.mean, 2), (run.cov, 3), (run.x_pred, 2), (run.P_pred, 3), (run.P_cross, 3), (sm.mean, 2),
            (sm.cov, 3))))):
        ref_x, ref_P = _reference_rts(x, P, xp, Pp, D)
        tol = 1e-6 * max(1.0, float(np.abs(ref_x).max()), scale)
        np.testing.assert_allclose(xs, ref_x, rtol=0, atol=tol, err_msg=f"run {r}")
        np.testing.assert_allclose(Ps, ref_P, rtol=0, atol=tol, err_msg=f"run {r}")


@settings(max_examples=200, **SETTINGS)
@given(problem=models(min_steps=2, fitting=True), per_run=st.booleans(), n_iter=st.integers(1, 4),
       fit=st.sampled_from([("Q", "R"), ("Q",), ("R",)]))
def test_fuzz_fit_noise_em(problem, per_run, n_iter, fit):
    args, target, value, missing = problem
    status, res = outcome(lambda: lb.fit_noise_em(args["F"], args["Q"], args["x0"], args["P0"],
                                                  lb.LinearMeasurement(args["z"], args["H"], args["R"]),
                                                  n_iter=n_iter, fit=fit, per_run=per_run))
    event(f"em: {status}" + (f" ({type(res).__name__}: {str(res)[:40]})" if status == "error" else ""))
    if status == "error":
        return
    z = args["z"]
    assert np.all(np.isfinite(z), axis=-1).any(), "EM answered with no step of readings to fit"
    if per_run:
        assert np.all(np.isfinite(z), axis=-1).any(axis=-1).all(), "EM answered for a run without readings"
    assert not (target != "z" and not np.isfinite(value)) or target == "none", \
        f"EM answered from a non-finite {target} ({value})"
    assert np.all(np.isfinite(res.Q)) and np.all(np.isfinite(res.R[0])) and np.all(np.isfinite(res.history))
    for name, A in (("Q", res.Q), ("R", res.R[0])):
        scale = max(float(np.abs(A).max(initial=0.0)), 1e-300)
        assert np.all(_min_eig(A) >= -1e-8 * scale), f"EM's {name} is not a covariance"
    # EM never lowers the likelihood (Shumway and Stoffer 1982), up to round-off
    h = res.history
    assert np.all(np.diff(h, axis=-1) >= -1e-7 * np.maximum(np.abs(h[..., 1:]), 1.0)), f"the likelihood fell: {h}"


@settings(max_examples=60, **SETTINGS)
@given(problem=models(min_steps=2, fitting=True), per_run=st.booleans(),
       fit_Q=st.sampled_from(["scale", "diagonal", None]))
def test_fuzz_fit_noise_ml(problem, per_run, fit_Q):
    args, target, value, missing = problem
    status, res = outcome(lambda: lb.fit_noise_ml(args["F"], args["Q"], args["x0"], args["P0"],
                                                  lb.LinearMeasurement(args["z"], args["H"], args["R"]),
                                                  fit_Q=fit_Q, per_run=per_run, max_iter=50))
    event(f"ml: {status}" + (f" ({type(res).__name__}: {str(res)[:40]})" if status == "error" else ""))
    if status == "error":
        return
    z = args["z"]
    assert np.isfinite(z).any(), "ML answered with no readings to fit"
    assert not (target != "z" and not np.isfinite(value)) or target == "none", \
        f"ML answered from a non-finite {target} ({value})"
    ll, ll0 = np.asarray(res.log_likelihood), np.asarray(res.initial_log_likelihood)
    assert np.all(ll >= ll0 - 1e-9 * np.maximum(np.abs(ll0), 1.0)), "ML ended below its start"
    # a flat multiplier is NaN, every other one finite and within its bounds
    scales = np.concatenate([s for s in (res.q_scale, *res.r_scale) if s is not None], axis=-1)
    assert scales.shape == res.flat.shape
    assert np.all(np.isnan(scales) == res.flat)
    assert np.all((scales[~res.flat] >= 1e-4 * (1 - 1e-9)) & (scales[~res.flat] <= 1e4 * (1 + 1e-9)))
    assert not np.any(res.at_bound & res.flat)


@settings(max_examples=60, **SETTINGS)
@given(problem=models(), kind=st.sampled_from(["kf", "ekf", "ukf"]))
def test_fuzz_online_filter_equals_the_batch_call(problem, kind):
    args, target, value, missing = problem
    batch_fn = {"kf": lb.kalman_filter, "ekf": lb.extended_kalman_filter, "ukf": lb.unscented_kalman_filter}[kind]
    stream = lambda z: lb.LinearMeasurement(z, args["H"], args["R"])
    status, full = outcome(lambda: batch_fn(args["F"], args["Q"], args["x0"], args["P0"], stream(args["z"]),
                                            divergence_window=0))
    status_online, last = outcome(lambda: _online(kind, args, stream))
    event(f"batch {status}, online {status_online}" + (f" ({str(last)[:70]})" if status_online == "error" and
                                                          status == "ok" else ""))
    if status == "error" or status_online == "error":
        return        # the online filter may refuse at a later step what the batch call refuses up front, and both
        # refuse with a clear line (checked by outcome)
    assert np.all(np.isfinite(full.mean)) and np.all(np.isfinite(full.cov))
    if last is not None:
        np.testing.assert_allclose(last.mean[..., -1, :], full.mean[..., -1, :], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(last.cov[..., -1, :, :], full.cov[..., -1, :, :], rtol=1e-9, atol=1e-9)


def _online(kind, args, stream):
    f = lb.OnlineFilter(kind, args["F"], args["Q"], args["x0"], args["P0"], divergence_window=0)
    last = None
    for k in range(args["z"].shape[-2]):
        last = f.step(stream(args["z"][..., k:k + 1, :]))
    return last
