"""Garbage from a user function, masked
readings, peer-style calls (filterpy, pykalman) and complex or NaN motion. Each case gets a correct answer (checked
against a closed form or an independent library: filterpy, pykalman) or one line naming the function, argument and
step, never numpy's raw message and never a finite answer from NaN or masked input."""
import ast
import re
import warnings

import numpy as np
import pytest

import locbook as lb
from builders import MASKED_ANCHORS as ANCHORS
from builders import exact_distances as _distances
from builders import masked as _masked

MODEL = lb.constant_velocity(1.0, 0.05)
H = MODEL.position_measurement_matrix()
R = np.array([[0.5, 0.1], [0.1, 0.8]])
X0, P0 = np.array([0.0, 0.0, 1.0, 0.5]), np.eye(4)
T = 12

# numpy's own texts that must never reach the user
NUMPY_TEXTS = ("operands could not be broadcast", "matmul", "inhomogeneous", "Casting complex", "setting an array "
               "element", "gufunc", "could not convert")


def _track(seed=0, steps=T):
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.normal(size=(steps, 2)), axis=0) + rng.normal(scale=0.7, size=(steps, 2))


def _position(x):
    return x[..., :2]


def _position_jacobian(x):
    return np.broadcast_to(H, np.shape(x)[:-1] + H.shape).copy()


def _one_line(exc_info, *needles):
    text = str(exc_info.value)
    assert "\n" not in text, text
    assert not any(t in text for t in NUMPY_TEXTS), text
    for needle in needles:
        assert needle in text, text
    return text


EKF = lb.extended_kalman_filter
UKF = lb.unscented_kalman_filter


# -- a user function's NaN is an error naming it (EKF and UKF alike), never a missing reading ------------------
def _nan_like(shape):
    return np.full(shape, np.nan)


@pytest.mark.parametrize("filt", [EKF, UKF], ids=["ekf", "ukf"])
@pytest.mark.parametrize("which", ["h", "jacobian", "residual"])
def test_a_nan_from_h_jacobian_or_residual_is_an_error_naming_the_function_and_step(filt, which):
    if filt is UKF and which == "jacobian":
        pytest.skip("the UKF does not call the jacobian")
    z = _track()
    z[:2] = np.nan                              # no reading at steps 0 and 1: the functions fail at step 2
    good = dict(h=_position, jacobian=_position_jacobian)
    parts = dict(good, residual=None)
    if which == "residual":
        parts["residual"] = lambda a, b: _nan_like(np.broadcast_shapes(np.shape(a), np.shape(b)))
    else:
        parts[which] = lambda x: _nan_like(np.shape(good[which](x)))
    meas = lb.NonlinearMeasurement(z, parts["h"], R, jacobian=parts["jacobian"], residual=parts["residual"],
                                   name="fix")
    with pytest.raises(ValueError) as exc:
        filt(MODEL.F, MODEL.Q, X0, P0, meas)
    _one_line(exc, f"fix: {which} returned NaN at step 2", "present")


@pytest.mark.parametrize("filt", [EKF, UKF], ids=["ekf", "ukf"])
def test_nan_from_h_where_the_reading_is_missing_is_not_used_and_equals_the_filter_without_that_component(filt):
    # component 1 never read: h may be NaN there; the answer is the KF on component 0 alone (a linear h: exact)
    z = _track(1)
    z[:, 1] = np.nan
    h = lambda x: np.stack([x[..., 0], np.full(np.shape(x)[:-1], np.nan)], axis=-1)
    J = lambda x: np.broadcast_to(np.array([[1.0, 0, 0, 0], [np.nan] * 4]), np.shape(x)[:-1] + (2, 4)).copy()
    res = filt(MODEL.F, MODEL.Q, X0, P0, lb.NonlinearMeasurement(z, h, np.diag([0.5, 0.8]), jacobian=J))
    ref = lb.kalman_filter(MODEL.F, MODEL.Q, X0, P0, lb.LinearMeasurement(z[:, :1], H[:1], [[0.5]]))
    np.testing.assert_allclose(res.mean, ref.mean, rtol=0, atol=1e-8)
    np.testing.assert_allclose(res.cov, ref.cov, rtol=0, atol=1e-8)


@pytest.mark.parametrize("filt", [EKF, UKF], ids=["ekf", "ukf"])
@pytest.mark.parametrize("h, last", [(lambda x: x[..., 0].sum(), None), (lambda x: x[..., :3], 3),
                                     (lambda x: x[..., :1], 1)], ids=["scalar", "three", "one"])
def test_a_scalar_or_wrong_shape_h_is_one_line_naming_h_and_the_shape(filt, h, last):
    meas = lb.NonlinearMeasurement(_track(), h, R, jacobian=_position_jacobian, name="fix")
    with pytest.raises(ValueError) as exc:
        filt(MODEL.F, MODEL.Q, X0, P0, meas)
    text = _one_line(exc, "fix: h returned shape", "it must return shape")
    got = ast.literal_eval(re.search(r"returned shape (\([\d, ]*\))", text).group(1))
    assert got == () if last is None else got[-1] == last


@pytest.mark.parametrize("filt", [EKF, UKF], ids=["ekf", "ukf"])
def test_a_complex_h_is_refused_not_cut_to_its_real_part(filt):
    meas = lb.NonlinearMeasurement(_track(), lambda x: x[..., :2] + 1e-3j, R, jacobian=_position_jacobian, name="fix")
    with warnings.catch_warnings():
        warnings.simplefilter("error")          # numpy's ComplexWarning would be the old, silent path
        with pytest.raises(ValueError) as exc:
            filt(MODEL.F, MODEL.Q, X0, P0, meas)
    _one_line(exc, "fix: h returned complex values")


# -- a masked reading is a reading not heard, in the one converter (the static estimators': tests/static/)
@pytest.mark.parametrize("filt", [lb.kalman_filter, EKF, UKF], ids=["kf", "ekf", "ukf"])
def test_masked_readings_are_missing_readings_in_every_kalman_filter(filt):
    z = _track(2)
    where = np.zeros(z.shape, bool)
    where[3, 0] = where[5] = where[8, 1] = True
    got = filt(MODEL.F, MODEL.Q, X0, P0, lb.LinearMeasurement(_masked(z, where), H, R))
    ref = filt(MODEL.F, MODEL.Q, X0, P0, lb.LinearMeasurement(np.where(where, np.nan, z), H, R))
    np.testing.assert_array_equal(got.mean, ref.mean)
    np.testing.assert_array_equal(got.cov, ref.cov)
    assert np.all(np.abs(got.mean[..., :2] - z).max() < 50)      # the 1e3 under the mask was never read


def test_masked_rss_readings_are_not_heard():
    anchors = np.array([[0.0, 0.0], [20.0, 0.0], [0.0, 20.0], [20.0, 20.0]])
    channel = lb.PathLossModel(-40.0, 2.0, 2.0)
    truth = np.stack([np.linspace(2, 18, T), np.linspace(3, 15, T)], -1)
    power = -40.0 - 20 * np.log10(np.linalg.norm(truth[:, None] - anchors, axis=-1))
    where = np.zeros(power.shape, bool)
    where[::3, 1] = True
    x0 = np.array([2.0, 3.0, 1.0, 1.0])
    for filt in (EKF, UKF):
        run = lambda p: filt(MODEL.F, MODEL.Q, x0, P0, lb.RssMeasurement(p, anchors, channel, MODEL.position_index))
        np.testing.assert_array_equal(run(_masked(power, where)).mean, run(np.where(where, np.nan, power)).mean)


def test_pykalman_robot_masked_observations_agree_with_pykalman():
    """pykalman's own robot data, its observations a masked array (the first one masked), passed as they come: the
    filtered means and covariances equal pykalman's filter and the data set's stored MATLAB ones."""
    pykalman = pytest.importorskip("pykalman")
    from pykalman.datasets import load_robot
    d = load_robot()
    obs = d.observations
    assert np.ma.isMaskedArray(obs) and np.ma.getmaskarray(obs).any()
    steps, n = obs.shape[0], d.transition_matrix.shape[0]
    u = np.zeros((steps, n))
    u[1:] = d.transition_offsets[:steps - 1]       # pykalman's b_{t-1} moves t - 1 to t: the control of step t, B = I
    meas = lb.LinearMeasurement(obs, d.observation_matrix, d.observation_covariance, offset=d.observation_offset)
    run = lb.kalman_filter(d.transition_matrix, d.transition_covariance, d.initial_state_mean,
                           d.initial_state_covariance, meas, B=np.eye(n), u=u, predict_first=False)
    kf = pykalman.KalmanFilter(d.transition_matrix, d.observation_matrix, d.transition_covariance,
                               d.observation_covariance, d.transition_offsets, d.observation_offset,
                               d.initial_state_mean, d.initial_state_covariance)
    means, covs = kf.filter(obs)
    np.testing.assert_allclose(run.mean, means, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.cov, covs, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.mean[:500], d.filtered_state_means[:500], rtol=0, atol=1e-9)


def test_a_mask_where_no_reading_is_accepted_is_an_error_naming_the_argument():
    anchors = np.ma.array(ANCHORS, mask=np.zeros(ANCHORS.shape, bool))
    anchors[2, 0] = np.ma.masked
    with pytest.raises(ValueError) as exc:
        lb.lateration_ls(anchors, _distances()[1])
    _one_line(exc, "anchors_m must not be masked", "index (2, 0)")
    with pytest.raises(ValueError) as exc:
        lb.kalman_filter(MODEL.F, MODEL.Q, X0, P0, lb.LinearMeasurement(_track(), np.ma.array(H, mask=H == 1), R))
    _one_line(exc, "LinearMeasurement.H must not be masked")


# -- peer-style calls ----------------------------------------------------------------------------------------
def _varying_F(steps=T):
    rng = np.random.default_rng(5)
    return [MODEL.F + 0.02 * rng.normal(size=(4, 4)) for _ in range(steps)]


@pytest.mark.parametrize("as_list", [True, False], ids=["list", "stack"])
def test_a_filterpy_list_or_unmarked_stack_of_per_step_F_is_refused_naming_per_step(as_list):
    Fs = _varying_F()
    F = Fs if as_list else np.stack(Fs)
    with pytest.raises(ValueError) as exc:
        lb.kalman_filter(F, MODEL.Q, X0, P0, lb.LinearMeasurement(_track(), H, R))
    _one_line(exc, "F has 12 matrices", "per_step(F)")


def test_per_step_F_equals_filterpy_batch_filter_with_its_list_of_Fs():
    filterpy_kalman = pytest.importorskip("filterpy.kalman")
    Fs, z = _varying_F(), _track(6)
    kf = filterpy_kalman.KalmanFilter(dim_x=4, dim_z=2)
    kf.x, kf.P, kf.Q, kf.H, kf.R = X0.copy(), P0.copy(), MODEL.Q, H, R
    means, covs, _, _ = kf.batch_filter(list(z), Fs=Fs)
    res = lb.kalman_filter(lb.per_step(np.stack(Fs)), MODEL.Q, X0, P0, lb.LinearMeasurement(z, H, R))
    np.testing.assert_allclose(res.mean, means, rtol=0, atol=1e-9)
    np.testing.assert_allclose(res.cov, covs, rtol=0, atol=1e-9)


@pytest.mark.parametrize("name, stack", [("H", np.stack), ("Q", list), ("R", list)], ids=["H", "Q_list", "R_list"])
def test_a_stack_of_H_and_filterpy_lists_of_Q_and_R_are_refused_too(name, stack):
    args = dict(Q=MODEL.Q, H=H, R=R)
    args[name] = stack([args[name]] * T)
    with pytest.raises(ValueError) as exc:
        EKF(MODEL.F, args["Q"], X0, P0, lb.LinearMeasurement(_track(), args["H"], args["R"]))
    _one_line(exc, f"per_step({name})")


def test_an_array_of_covariances_stays_a_documented_run_axis():
    # a sweep of T noise levels on one track (as fit_noise_ml evaluates its candidates): T runs, each the plain KF
    z, scales = _track(9), np.linspace(0.5, 2.0, T)
    res = lb.kalman_filter(MODEL.F, scales[:, None, None] * MODEL.Q, X0, P0, lb.LinearMeasurement(z, H, R))
    for i in (0, 7):
        one = lb.kalman_filter(MODEL.F, scales[i] * MODEL.Q, X0, P0, lb.LinearMeasurement(z, H, R))
        np.testing.assert_allclose(res.mean[i], one.mean, rtol=0, atol=1e-12)


def test_fit_noise_ml_candidates_are_runs_even_when_as_many_as_the_steps():
    # fit_noise_ml evaluates 2p + 1 = 5 candidate (Q, R) as a run axis; on 5 steps that must not read as per-step Q
    z = _track(10, 5)
    fit = lb.fit_noise_ml(MODEL.F, MODEL.Q, X0, P0, lb.LinearMeasurement(z, H, R), kind="kf", fit_Q="scale",
                          fit_R="scale")
    assert np.isfinite(fit.log_likelihood) and fit.log_likelihood >= fit.initial_log_likelihood


def test_a_stack_with_runs_elsewhere_in_the_call_is_still_runs():
    # x0 with a run axis of T: the F stack is T runs, each filter equal to the KF with its own F
    Fs = np.stack(_varying_F())
    z = _track(7)
    res = lb.kalman_filter(Fs, MODEL.Q, np.broadcast_to(X0, (T, 4)), P0, lb.LinearMeasurement(z, H, R))
    for i in (0, 5):
        one = lb.kalman_filter(Fs[i], MODEL.Q, X0, P0, lb.LinearMeasurement(z, H, R))
        np.testing.assert_allclose(res.mean[i], one.mean, rtol=0, atol=1e-12)


def test_column_shaped_readings_are_refused_with_the_shape_to_pass():
    z = _track()
    with pytest.raises(ValueError) as exc:
        lb.LinearMeasurement(z[..., None], H, R)                       # (T, m, 1), filterpy's column per step
    _one_line(exc, "(12, 2, 1)", "z[..., 0]")
    with pytest.raises(ValueError) as exc:                             # (T, 1, 1): T runs of one step, or T steps?
        lb.kalman_filter(MODEL.F, MODEL.Q, X0, P0, lb.LinearMeasurement(z[:, :1, None], H[:1], R[:1, :1]))
    _one_line(exc, "(12, 1, 1)", "pass shape (12, 1)", "x0 its run axis")
    # the same readings with runs stated by x0 are runs of one step: each the KF's one update in closed form
    runs = lb.kalman_filter(MODEL.F, MODEL.Q, np.broadcast_to(X0, (T, 4)), P0,
                            lb.LinearMeasurement(z[:, :1, None], H[:1], R[:1, :1]))
    Pp = MODEL.F @ P0 @ MODEL.F.T + MODEL.Q
    xp = MODEL.F @ X0
    K = Pp[:, :1] / (Pp[0, 0] + R[0, 0])
    np.testing.assert_allclose(runs.mean[:, 0], xp + (z[:, :1] - xp[0]) @ K.T, rtol=0, atol=1e-12)


def test_online_filter_runs_of_one_reading_each_stay_runs():
    z = _track(8)[:, :1]                                               # 12 runs, one reading each
    online = lb.OnlineFilter("kf", MODEL.F, MODEL.Q, X0, P0)
    step = online.step(lb.LinearMeasurement(z[:, None, :], H[:1], R[:1, :1]))
    batch = lb.kalman_filter(MODEL.F, MODEL.Q, np.broadcast_to(X0, (T, 4)), P0,
                             lb.LinearMeasurement(z[:, None, :], H[:1], R[:1, :1]))
    np.testing.assert_allclose(step.mean, batch.mean, rtol=0, atol=1e-12)


@pytest.mark.parametrize("points, kw, needle", [("julier", dict(alpha=0.5), "alpha=0.5"),
                                                ("julier", dict(beta=0.0), "beta=0.0"),
                                                ("cubature", dict(alpha=1.0), "alpha=1.0"),
                                                ("cubature", dict(kappa=1.0), "kappa=1.0")])
def test_sigma_point_sets_refuse_parameters_they_would_ignore(points, kw, needle):
    with pytest.raises(ValueError) as exc:
        lb.unscented_weights(4, points=points, **kw)
    _one_line(exc, f"points={points!r} does not use {needle}")
    with pytest.raises(ValueError) as exc:
        UKF(MODEL.F, MODEL.Q, X0, P0, lb.LinearMeasurement(_track(), H, R), points=points, **kw)
    _one_line(exc, needle)


def test_julier_weights_with_its_kappa_are_julier_and_uhlmanns():
    # Julier and Uhlmann 1997: W0 = kappa / (n + kappa), Wi = 1 / (2 (n + kappa)), one set for mean and covariance
    w = lb.unscented_weights(3, kappa=2.0, points="julier")
    np.testing.assert_allclose(w.mean, [2 / 5] + [1 / 10] * 6, rtol=1e-15)
    np.testing.assert_allclose(w.cov, w.mean, rtol=1e-15)


def test_filterpy_style_fx_x_dt_gets_a_line_saying_what_to_pass():
    fx = lambda x, dt: x @ np.array([[1, 0, dt, 0], [0, 1, 0, dt], [0, 0, 1, 0], [0, 0, 0, 1.0]]).T
    motion = lb.NonlinearMotion(fx, jacobian=lambda x, dt: MODEL.F, name="cv")
    for filt in (EKF, UKF):
        with pytest.raises(ValueError) as exc:
            filt(motion, MODEL.Q, X0, P0, lb.LinearMeasurement(_track(), H, R))
        _one_line(exc, "cv:", "cannot be called as", "lambda x: fx(x, dt)", "uses_step=True")
    # bound as the line says, the motion is the KF's (a linear f): equal results
    bound = lb.NonlinearMotion(lambda x: fx(x, 1.0), jacobian=lambda x: MODEL.F)
    np.testing.assert_allclose(EKF(bound, MODEL.Q, X0, P0, lb.LinearMeasurement(_track(), H, R)).mean,
                               lb.kalman_filter(MODEL.F, MODEL.Q, X0, P0, lb.LinearMeasurement(_track(), H, R)).mean,
                               rtol=0, atol=1e-12)


def test_a_list_with_none_is_a_step_without_a_reading_and_a_ragged_one_says_to_use_nan():
    z = _track().tolist()
    z[4] = None                                  # filterpy's batch_filter takes None for a step without reading
    with_none = lb.LinearMeasurement(z, H, R)    # taken as filterpy means it: that step's readings are all missing
    assert np.isnan(with_none.z[4]).all() and np.isfinite(np.delete(with_none.z, 4, axis=0)).all()
    ragged = [row for row in z]
    ragged[3] = [ragged[3][0], None]             # a None inside a row of a list whose rows differ: use NaN
    ragged[4] = [1.0]
    with pytest.raises(ValueError) as exc:
        lb.LinearMeasurement(ragged, H, R)
    _one_line(exc, "LinearMeasurement.z", "NaN")
    z[4] = [np.nan, np.nan]                      # the same step written with NaN: prediction only, as filterpy's None
    filterpy_kalman = pytest.importorskip("filterpy.kalman")
    kf = filterpy_kalman.KalmanFilter(dim_x=4, dim_z=2)
    kf.x, kf.P, kf.F, kf.Q, kf.H, kf.R = X0.copy(), P0.copy(), MODEL.F, MODEL.Q, H, R
    zs = [None if i == 4 else np.array(row) for i, row in enumerate(z)]
    means, _, _, _ = kf.batch_filter(zs)
    np.testing.assert_allclose(lb.kalman_filter(MODEL.F, MODEL.Q, X0, P0, lb.LinearMeasurement(z, H, R)).mean, means,
                               rtol=0, atol=1e-9)


# -- complex or NaN motion -----------------------------------------------------------------------------------
@pytest.mark.parametrize("filt", [EKF, UKF], ids=["ekf", "ukf"])
def test_a_complex_motion_f_is_refused(filt):
    motion = lb.NonlinearMotion(lambda x: x @ MODEL.F.T + 1e-3j, jacobian=lambda x: MODEL.F, name="cv")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError) as exc:
            filt(motion, MODEL.Q, X0, P0, lb.LinearMeasurement(_track(), H, R))
    _one_line(exc, "cv: f returned complex values")


@pytest.mark.parametrize("filt", [EKF, UKF], ids=["ekf", "ukf"])
def test_a_nan_from_a_nonlinear_motion_names_the_motion_and_the_step(filt):
    f = lambda x, k: x @ MODEL.F.T * (np.nan if k == 3 else 1.0)
    motion = lb.NonlinearMotion(f, jacobian=lambda x, k: MODEL.F, uses_step=True, name="cv")
    with pytest.raises(ValueError) as exc:
        filt(motion, MODEL.Q, X0, P0, lb.LinearMeasurement(_track(), H, R))
    text = _one_line(exc, "cv: f returned NaN at step 3")
    assert "too large for float64" not in text


def test_a_nan_jacobian_of_the_motion_names_it():
    motion = lb.NonlinearMotion(lambda x: x @ MODEL.F.T, jacobian=lambda x: np.full((4, 4), np.nan), name="cv")
    with pytest.raises(ValueError) as exc:
        EKF(motion, MODEL.Q, X0, P0, lb.LinearMeasurement(_track(), H, R))
    _one_line(exc, "cv: jacobian returned NaN at step 0")


def test_complex_readings_are_refused_by_the_converter():
    with pytest.raises(ValueError) as exc:
        lb.LinearMeasurement(_track() + 0j, H, R)
    _one_line(exc, "LinearMeasurement.z must be real")
    with pytest.raises(ValueError) as exc:
        lb.lateration_ls(ANCHORS, _distances()[1] + 1e-9j)
    _one_line(exc, "distance_m must be real")
