"""Property-based fuzzing of the functions a user hands to the filters (bounded example counts: the module
runs in seconds).

A NonlinearMeasurement (``h``, ``jacobian``, ``residual``, ``mean``, ``R(x)``) and a NonlinearMotion (``f`` and its
``jacobian``) on a linear model, so that the EKF and the UKF (alpha = 1) must equal the KF on the same readings. One of
those functions at a time misbehaves: it returns a wrong shape, a scalar, NaN or inf in one component, complex values,
a list, None or text, or it raises. The rule:

- a function the filter does not call (the UKF's jacobians, the EKF's mean), or a NaN in a component whose reading is
  never present, changes nothing: the KF's answer;
- a list is an array: the KF's answer;
- the function's own exception reaches the caller unchanged;
- anything else is one ValueError line naming the function (``"<stream name>: h"``, ``"<motion name>: f"``), never
  numpy's raw text or a ComplexWarning, and never a finite answer from the bad output.
"""
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import locbook as lb

pytestmark = pytest.mark.fuzz

MODEL = lb.constant_velocity(1.0, 0.05)
F, Q = MODEL.F, MODEL.Q
H = MODEL.position_measurement_matrix()
R = np.array([[0.5, 0.1], [0.1, 0.8]])
X0, P0 = np.array([0.0, 0.0, 1.0, 0.5]), np.eye(4)
SETTINGS = dict(deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
RAW = ("could not be broadcast", "operands could not", "cannot reshape", "matmul", "gufunc", "inhomogeneous",
       "setting an array element", "could not convert", "Casting complex", "too large for float64")

SLOTS = ("h", "jacobian", "residual", "mean", "R", "f", "f_jacobian")
BEHAVIOURS = ("ok", "list", "wrong_shape", "scalar", "nan", "inf", "complex", "none", "text", "raises")
NAMES = dict(h="fix: h", jacobian="fix: jacobian", residual="fix: residual", mean="fix: mean", R="fix: R(x)",
             f="cv: f", f_jacobian="cv: jacobian")


class UserBoom(Exception):
    """The user's own failure inside a function."""


def _good(slot):
    """The well-behaved function of each slot (a linear model, so the filters equal the KF)."""
    return dict(h=lambda x: x[..., :2],
                jacobian=lambda x: np.broadcast_to(H, np.shape(x)[:-1] + H.shape).copy(),
                residual=lambda a, b: np.subtract(a, b),
                mean=lambda values, weights: weights @ values,
                R=lambda x: np.broadcast_to(R, np.shape(x)[:-1] + R.shape).copy(),
                f=lambda x: x @ F.T,
                f_jacobian=lambda x: F)[slot]


def _spoil(fn, behaviour, component, axis):
    """``fn`` misbehaving as ``behaviour``; ``component``: the entry of output axis ``axis`` made NaN or inf."""
    def spoilt(*args):
        out = np.array(fn(*args), dtype=float)
        if behaviour == "ok":
            return out
        if behaviour == "list":
            return out.tolist()
        if behaviour == "wrong_shape":
            return np.concatenate([out, np.take(out, [0], axis=-1)], axis=-1)
        if behaviour == "scalar":
            return 0.0
        if behaviour in ("nan", "inf"):
            index = [slice(None)] * out.ndim
            index[axis] = component % out.shape[axis]
            out[tuple(index)] = np.nan if behaviour == "nan" else np.inf
            return out
        if behaviour == "complex":
            return out + 1e-3j
        if behaviour == "none":
            return None
        if behaviour == "text":
            return "not a number"
        raise UserBoom("the user's function failed")
    return spoilt


@st.composite
def cases(draw):
    filt = draw(st.sampled_from(["ekf", "ukf"]))
    batch = draw(st.sampled_from([(), (3,)]))
    T = draw(st.sampled_from([1, 6]))
    rng = np.random.default_rng(draw(st.integers(0, 30)))
    z = np.cumsum(rng.normal(size=batch + (T, 2)), axis=-2)
    missing = draw(st.sampled_from(["none", "some", "component 1", "all"]))
    if missing == "some":
        z[rng.random(z.shape) < 0.3] = np.nan
    elif missing == "component 1":
        z[..., 1] = np.nan
    elif missing == "all":
        z[...] = np.nan
    return filt, z, draw(st.sampled_from(SLOTS)), draw(st.sampled_from(BEHAVIOURS)), draw(st.integers(0, 1))


def _expected(filt, z, slot, behaviour, component):
    """``"ok"``, ``"boom"`` or ``"error"`` by the module docstring's rule."""
    called = {"f"} | ({"f_jacobian"} if filt == "ekf" else set())      # the prediction runs at every step
    if np.isfinite(z).any():                                           # the updates run only where readings are
        called |= {"h", "residual", "R"} | ({"jacobian"} if filt == "ekf" else {"mean"})
    if slot not in called or behaviour in ("ok", "list"):
        return "ok"
    if behaviour == "raises":
        return "boom"
    if behaviour in ("nan", "inf") and slot in ("h", "jacobian", "residual", "mean"):
        # a reading's component: used (an error) only where that reading is present
        return "error" if np.isfinite(z[..., component]).any() else "ok"
    return "error"


def _run(filt, motion, meas):
    if filt == "ekf":
        return lb.extended_kalman_filter(motion, Q, X0, P0, meas)
    return lb.unscented_kalman_filter(motion, Q, X0, P0, meas, alpha=1.0)


@settings(max_examples=250, **SETTINGS)
@given(case=cases())
def test_property_user_functions_give_the_kf_answer_their_own_error_or_one_line_naming_them(case):
    filt, z, slot, behaviour, component = case
    fns = {s: _good(s) for s in SLOTS}
    fns[slot] = _spoil(fns[slot], behaviour, component, axis=-2 if slot in ("jacobian", "f_jacobian") else -1)
    meas = lb.NonlinearMeasurement(z, fns["h"], fns["R"], jacobian=fns["jacobian"], residual=fns["residual"],
                                   mean=fns["mean"], name="fix")
    motion = lb.NonlinearMotion(fns["f"], jacobian=fns["f_jacobian"], name="cv")
    expected = _expected(filt, z, slot, behaviour, component)
    with warnings.catch_warnings():
        warnings.simplefilter("error", np.exceptions.ComplexWarning)
        try:
            res = _run(filt, motion, meas)
        except UserBoom:
            assert expected == "boom", f"{slot} {behaviour}: the user's exception, expected {expected}"
            return
        except ValueError as exc:
            text = str(exc)
            assert expected == "error", f"{slot} {behaviour}: {text}"
            assert "\n" not in text and not any(raw in text for raw in RAW), text
            assert NAMES[slot] in text, f"{slot} {behaviour}: the message does not name {NAMES[slot]}: {text}"
            return
    assert expected == "ok", f"{slot} {behaviour}: a finite answer where {expected} was due"
    ref = lb.kalman_filter(F, Q, X0, P0, lb.LinearMeasurement(z, H, R))
    np.testing.assert_allclose(res.mean, ref.mean, rtol=0, atol=1e-7)
    np.testing.assert_allclose(res.cov, ref.cov, rtol=0, atol=1e-7)


SIGNATURES = {"x": (lambda x: x @ F.T, lambda x: F), "x, dt": (lambda x, dt: x @ F.T, lambda x, dt: F),
              "x, k, extra": (lambda x, k, extra: x @ F.T, lambda x, k, extra: F)}


@settings(max_examples=30, **SETTINGS)
@given(uses_step=st.booleans(), takes=st.sampled_from(sorted(SIGNATURES)), filt=st.sampled_from(["ekf", "ukf"]))
def test_property_a_motion_whose_signature_does_not_fit_gets_one_line_saying_what_to_pass(uses_step, takes, filt):
    fn, jac = SIGNATURES[takes]
    motion = lb.NonlinearMotion(fn, jacobian=jac, uses_step=uses_step, name="cv")
    meas = lb.LinearMeasurement(np.cumsum(np.ones((5, 2)), axis=0), H, R)
    if takes == ("x, dt" if uses_step else "x"):                      # the signature fits: the KF's answer
        ref = lb.kalman_filter(F, Q, X0, P0, meas)
        np.testing.assert_allclose(_run(filt, motion, meas).mean, ref.mean, rtol=0, atol=1e-7)
        return
    with pytest.raises(ValueError) as exc:
        _run(filt, motion, meas)
    text = str(exc.value)
    assert "\n" not in text and text.startswith("cv: ") and "cannot be called as" in text, text
    assert ("uses_step=False" if uses_step else "uses_step=True") in text, text


@settings(max_examples=60, **SETTINGS)
@given(value=st.sampled_from(["nan", "inf", "-inf", "complex", "none"]), step=st.integers(0, 4),
       filt=st.sampled_from(["ekf", "ukf"]))
def test_property_a_motion_that_fails_at_one_step_is_named_at_that_step(value, step, filt):
    def f(x, k):
        out = x @ F.T
        if k != step:
            return out
        return dict(nan=out * np.nan, inf=out + np.inf, complex=out + 1j, none=None).get(value, out - np.inf)
    motion = lb.NonlinearMotion(f, jacobian=lambda x, k: F, uses_step=True, name="cv")
    meas = lb.LinearMeasurement(np.cumsum(np.ones((5, 2)), axis=0), H, R)
    with warnings.catch_warnings():
        warnings.simplefilter("error", np.exceptions.ComplexWarning)
        with pytest.raises(ValueError) as exc:
            _run(filt, motion, meas)
    text = str(exc.value)
    assert "\n" not in text and text.startswith("cv: f returned") and not any(raw in text for raw in RAW), text
    if value in ("nan", "inf", "-inf"):
        assert f"at step {step}" in text, text
