"""Singular covariances, EM's round-off iterates, empty and
all-missing readings. Every answer is checked against pykalman (an independent implementation whose smoother and
filter use pseudo-inverses), a closed form or an invariant; every refusal is one line naming what is wrong."""
import warnings

import numpy as np
import pytest

import locbook as lb
from locbook.errors import ConvergenceError
from locbook.tracking.results import KalmanResult
from locbook.tracking.smoother import rts_smoother

pykalman = pytest.importorskip("pykalman")

H = np.hstack([np.eye(2), np.zeros((2, 2))])
R = np.diag([0.5, 0.8])
X0 = np.array([0.1, -0.2, 0.3, 0.1])


def _model():
    return lb.constant_velocity(1.0, 0.05, dim=2)


def _readings(rng, T=25, runs=None):
    z = rng.normal(size=((runs,) if runs else ()) + (T, 2)).cumsum(axis=-2)
    z[..., 5:8, :] = np.nan                                   # three steps without a reading
    return z


def _run(Q, P0, z):
    return lb.kalman_filter(_model().F, Q, X0, P0, lb.LinearMeasurement(z, H, R), predict_first=False,
                            outputs=("x_pred", "P_pred", "P_cross"))


def _pykalman(Q, P0, **kw):
    return pykalman.KalmanFilter(transition_matrices=_model().F, observation_matrices=H, transition_covariance=Q,
                                 observation_covariance=R, initial_state_mean=X0, initial_state_covariance=P0, **kw)


def _one_line(exc) -> str:
    text = str(exc.value)
    assert "\n" not in text and "Traceback" not in text
    return text


# -- the smoother on singular predicted covariances --------------------------------------------------------------
SINGULAR_STARTS = {
    "Q = 0, P0 = 0 (every state deterministic)": (np.zeros((4, 4)), np.zeros((4, 4))),
    "white-noise Q (rank 2), no velocity prior": (_model().Q, np.diag([1.0, 1.0, 0.0, 0.0])),
    "position noise only, known start": (np.diag([0.1, 0.1, 0.0, 0.0]), np.zeros((4, 4))),
    "Q = 0, a rank-1 prior": (np.zeros((4, 4)), np.outer([1.0, 2.0, 0.5, 0.0], [1.0, 2.0, 0.5, 0.0])),
}


@pytest.mark.parametrize("case", list(SINGULAR_STARTS))
def test_rts_smoother_with_a_singular_prediction_equals_pykalmans_smoother(case):
    Q, P0 = SINGULAR_STARTS[case]
    z = _readings(np.random.default_rng(1))
    smooth = rts_smoother(_run(Q, P0, z))
    means, covs = _pykalman(Q, P0).smooth(np.ma.masked_invalid(z))
    np.testing.assert_allclose(smooth.mean, means, rtol=0, atol=1e-9)
    np.testing.assert_allclose(smooth.cov, covs, rtol=0, atol=1e-9)


def test_rts_smoother_of_deterministic_motion_is_the_motion_itself():
    """Q = 0 and P0 = 0: every state is F^k x0 whatever the readings; the smoother must say so with P = 0."""
    F = _model().F
    smooth = rts_smoother(_run(np.zeros((4, 4)), np.zeros((4, 4)), _readings(np.random.default_rng(2))))
    expected = np.array([np.linalg.matrix_power(F, k) @ X0 for k in range(25)])
    np.testing.assert_allclose(smooth.mean, expected, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(smooth.cov, 0.0)
    np.testing.assert_array_equal(smooth.gain, 0.0)


def test_a_singular_run_leaves_the_other_runs_of_the_batch_bit_identical():
    rng = np.random.default_rng(3)
    z = _readings(rng, runs=3)
    P0 = np.stack([np.eye(4), np.zeros((4, 4)), 2 * np.eye(4)])     # run 1: a known start, Q singular
    Q = _model().Q
    run = lb.kalman_filter(_model().F, Q, np.broadcast_to(X0, (3, 4)), P0, lb.LinearMeasurement(z, H, R),
                           predict_first=False, outputs=("x_pred", "P_pred", "P_cross"))
    smooth = rts_smoother(run)
    for r in range(3):
        alone = rts_smoother(KalmanResult(run.mean[r], run.cov[r], run.steps, run.x_pred[r], run.P_pred[r],
                                          P_cross=run.P_cross[r]))
        np.testing.assert_array_equal(smooth.mean[r], alone.mean)
        np.testing.assert_array_equal(smooth.cov[r], alone.cov)
    means, covs = _pykalman(Q, P0[1]).smooth(np.ma.masked_invalid(z[1]))
    np.testing.assert_allclose(smooth.mean[1], means, rtol=0, atol=1e-9)
    # smoothing never adds uncertainty, and the smoothed covariances are covariances
    assert np.linalg.eigvalsh(run.cov - smooth.cov).min() > -1e-12
    assert np.linalg.eigvalsh(smooth.cov).min() > -1e-12


def test_rts_smoother_of_zero_runs_is_empty():
    z = np.zeros((0, 25, 2))
    run = lb.kalman_filter(_model().F, _model().Q, X0, np.eye(4), lb.LinearMeasurement(z, H, R),
                           outputs=("x_pred", "P_pred", "P_cross"))
    smooth = rts_smoother(run)
    assert smooth.mean.shape == (0, 25, 4) and smooth.cov.shape == (0, 25, 4, 4) and smooth.gain.shape == (0, 24, 4, 4)


def test_rts_smoother_refuses_a_non_finite_covariance_in_one_line():
    run = _run(_model().Q, np.eye(4), _readings(np.random.default_rng(4)))
    P_pred = run.P_pred.copy()
    P_pred[7, 1, 1] = np.nan
    broken = KalmanResult(run.mean, run.cov, run.steps, run.x_pred, P_pred, P_cross=run.P_cross)
    with pytest.raises(ValueError) as exc:
        rts_smoother(broken)
    assert "P_pred is not finite at step 7" in _one_line(exc)


def test_rts_smoother_refuses_mismatched_shapes_in_one_line():
    run = _run(_model().Q, np.eye(4), _readings(np.random.default_rng(5)))
    broken = KalmanResult(run.mean, run.cov, run.steps, run.x_pred[:-1], run.P_pred, P_cross=run.P_cross)
    with pytest.raises(ValueError) as exc:
        rts_smoother(broken)
    assert "x_pred must have the shape (25, 4)" in _one_line(exc)


# -- EM: round-off iterates, singular starts, nothing to fit -----------------------------------------------------
@pytest.mark.parametrize("P0", [np.eye(4), np.zeros((4, 4))], ids=["P0 = I", "P0 = 0"])
def test_em_from_Q_zero_stays_at_its_fixed_point_and_fits_R_as_pykalman(P0):
    """Q = 0 is a fixed point of EM (the smoother sees deterministic motion, so every residual e_k and the covariance
    terms cancel). Its M-step sums those terms with round-off of some 1e-17 below zero, which must not be refused as
    the caller's non-PSD Q; R's iterates are pykalman's."""
    z = _readings(np.random.default_rng(6), T=40)
    Q0 = np.zeros((4, 4))
    fit = lb.fit_noise_em(_model().F, Q0, X0, P0, lb.LinearMeasurement(z, H, R), n_iter=6)
    assert np.abs(fit.Q).max() <= 1e-10
    theirs = _pykalman(Q0, P0, em_vars=["transition_covariance", "observation_covariance"]).em(
        np.ma.masked_invalid(z), n_iter=6)
    np.testing.assert_allclose(fit.R[0], theirs.observation_covariance, rtol=1e-6, atol=1e-9)
    assert np.all(np.diff(fit.history) >= -1e-9 * np.abs(fit.history[1:]))


def test_em_still_refuses_a_start_that_is_not_a_covariance():
    z = _readings(np.random.default_rng(7))
    with pytest.raises(ValueError) as exc:
        lb.fit_noise_em(_model().F, np.diag([0.1, 0.1, -0.05, 0.1]), X0, np.eye(4), lb.LinearMeasurement(z, H, R))
    assert "Q must be positive semi-definite" in _one_line(exc)


def test_em_projects_round_off_of_an_iterate_and_refuses_more_as_lost_precision():
    """The M-step's Q and R are averages of conditional second moments (positive semi-definite): eigenvalues below 0
    within 1e-8 of the terms' scale are round-off and become 0; beyond it the E-step lost its precision."""
    from locbook.tracking.noise import _psd_iterate
    V = np.linalg.qr(np.random.default_rng(12).normal(size=(3, 3)))[0]
    A = V @ np.diag([2.0, 1.0, -3e-10]) @ V.T
    fixed = _psd_iterate("Q", A, 1.0, 2)
    np.testing.assert_allclose(np.linalg.eigvalsh(fixed), [0.0, 1.0, 2.0], atol=1e-14)
    np.testing.assert_allclose(fixed, V @ np.diag([2.0, 1.0, 0.0]) @ V.T, atol=1e-14)
    regular = V @ np.diag([2.0, 1.0, 1e-3]) @ V.T
    assert _psd_iterate("Q", regular, 1.0, 2) is regular             # a covariance is kept as it is
    with pytest.raises(ConvergenceError) as exc:
        _psd_iterate("R", V @ np.diag([2.0, 1.0, -1e-3]) @ V.T, 1.0, 4)
    assert "M-step's R of iteration 4 has the eigenvalue -0.001" in _one_line(exc)


@pytest.mark.parametrize("per_run", [False, True])
def test_em_on_all_missing_readings_refuses_instead_of_R_zero(per_run):
    z = np.full((2, 30, 2), np.nan)
    with pytest.raises(ValueError) as exc:
        lb.fit_noise_em(_model().F, _model().Q, X0, np.eye(4), lb.LinearMeasurement(z, H, R), per_run=per_run)
    assert "no readings to fit from" in _one_line(exc)


@pytest.mark.parametrize("per_run", [False, True])
def test_em_on_zero_width_readings_refuses_in_one_line(per_run):
    z = np.zeros((3, 30, 0))
    with pytest.raises(ValueError) as exc:
        lb.fit_noise_em(_model().F, _model().Q, X0, np.eye(4), lb.LinearMeasurement(z, np.zeros((0, 4)),
                                                                                  np.zeros((0, 0))), per_run=per_run)
    assert "zero components" in _one_line(exc)


def test_em_per_run_names_the_run_without_readings():
    z = _readings(np.random.default_rng(9), runs=3)
    z[2] = np.nan
    with pytest.raises(ValueError) as exc:
        lb.fit_noise_em(_model().F, _model().Q, X0, np.eye(4), lb.LinearMeasurement(z, H, R), fit=("Q",))
    assert "run (2,)" in _one_line(exc)


# -- ML: nothing to fit, flat likelihoods ------------------------------------------------------------------------
@pytest.mark.parametrize("per_run", [False, True])
def test_ml_on_all_missing_readings_refuses_instead_of_returning_its_start(per_run):
    z = np.full((2, 30, 2), np.nan)
    with pytest.raises(ValueError) as exc:
        lb.fit_noise_ml(_model().F, _model().Q, X0, np.eye(4), lb.LinearMeasurement(z, H, R), per_run=per_run)
    assert "no readings to fit from" in _one_line(exc)


def test_ml_per_run_flags_a_run_without_readings_flat_with_nan_estimates():
    z = _readings(np.random.default_rng(10), T=40, runs=3)
    z[1] = np.nan
    fit = lb.fit_noise_ml(_model().F, _model().Q, X0, np.eye(4), lb.LinearMeasurement(z, H, R))
    np.testing.assert_array_equal(fit.flat, [[False, False], [True, True], [False, False]])
    # NaN where a multiplier scales the given matrix; its zero entries are 0 whatever the multiplier
    np.testing.assert_array_equal(np.isnan(fit.Q[1]), _model().Q != 0)
    np.testing.assert_array_equal(fit.Q[1][_model().Q == 0], 0.0)
    np.testing.assert_array_equal(np.isnan(fit.R[0][1]), R != 0)
    assert np.isnan(fit.q_scale[1]).all() and np.isnan(fit.r_scale[0][1]).all()
    assert not fit.at_bound[1].any()
    # the other runs are their own fits (the per-run objective is separable)
    alone = lb.fit_noise_ml(_model().F, _model().Q, X0, np.eye(4), lb.LinearMeasurement(z[[0, 2]], H, R))
    np.testing.assert_allclose(fit.Q[[0, 2]], alone.Q, rtol=1e-6)
    assert not alone.flat.any()


def test_ml_pooled_flags_a_stream_without_readings_and_fits_the_rest_as_without_it():
    z = _readings(np.random.default_rng(11), T=40, runs=3)
    silent = lb.LinearMeasurement(np.full_like(z, np.nan), H, R)
    fit = lb.fit_noise_ml(_model().F, _model().Q, X0, np.eye(4), [lb.LinearMeasurement(z, H, R), silent],
                          per_run=False)
    np.testing.assert_array_equal(fit.flat, [False, False, True])
    np.testing.assert_array_equal(np.isnan(fit.R[1]), R != 0)
    assert np.isnan(fit.r_scale[1]).all()
    without = lb.fit_noise_ml(_model().F, _model().Q, X0, np.eye(4), lb.LinearMeasurement(z, H, R), per_run=False)
    np.testing.assert_allclose(fit.Q, without.Q, rtol=1e-6)
    np.testing.assert_allclose(fit.R[0], without.R[0], rtol=1e-6)
    np.testing.assert_allclose(fit.log_likelihood, without.log_likelihood, rtol=1e-12)


def test_rts_smoother_of_one_step_runs_is_the_filter():
    z = _readings(np.random.default_rng(13), T=1, runs=3)
    run = lb.kalman_filter(_model().F, _model().Q, np.broadcast_to(X0, (3, 4)), np.eye(4),
                           lb.LinearMeasurement(z, H, R), outputs=("x_pred", "P_pred", "P_cross"))
    smooth = rts_smoother(run)
    np.testing.assert_array_equal(smooth.mean, run.mean)
    np.testing.assert_array_equal(smooth.cov, run.cov)
    assert smooth.gain.shape == (3, 0, 4, 4)


# -- EM's self-checks: what exact arithmetic guarantees, refused with one line where float64 breaks it --------------
H1, R1, Z1 = np.array([[-0.13]]), np.array([[0.5]]), np.array([[0.21], [-1.07]])


def test_em_whose_likelihood_falls_says_so_instead_of_returning_the_iterate():
    """EM never lowers the likelihood (Shumway and Stoffer 1982): a fall beyond round-off is an E-step without
    precision, an error naming the iteration (per run: the run; pooled: the sum)."""
    from locbook.tracking.noise import _check_em_step
    z = np.zeros((2, 1))
    _check_em_step([np.array(-10.0), np.array(-10.0 - 1e-9)], False, 1, z)         # round-off: accepted
    with pytest.raises(ConvergenceError) as exc:
        _check_em_step([np.array([-10.0, -3.0]), np.array([-9.0, -3.5])], True, 2, z)
    assert "fell from -3 to -3.5 in run (1,) at iteration 2" in _one_line(exc)


@pytest.mark.parametrize("H, z, x0", [(-0.1321048632913019, [0.2098002302, -1.0713387463], 0.6404226504432821),
                                      (-0.13, [0.21, -1.07], 0.0)])
def test_em_from_a_q_of_1e300_is_monotone_or_an_error(H, z, x0):
    """From Q = 1e300 the filter's P - K S K^T cancels 1e300 against 1e300; depending on the last bits the M-step's
    R comes out near 1e265 and the likelihood falls (about -345 to -616 on the first case): EM must then refuse."""
    try:
        fit = lb.fit_noise_em(np.eye(1), np.array([[1e300]]), np.array([x0]), np.zeros((1, 1)),
                              lb.LinearMeasurement(np.array(z)[:, None], np.array([[H]]), R1), n_iter=3,
                              per_run=False)
    except ConvergenceError as exc:
        assert "log-likelihood fell" in str(exc) and "\n" not in str(exc)
        return
    assert np.all(np.diff(fit.history) >= -1e-7 * np.abs(fit.history[1:]))


@pytest.mark.parametrize("fit", [("Q",), ("R",), ("Q", "R")])
def test_em_on_a_reading_of_1e300_names_the_readings_not_the_callers_R(fit):
    """Its log-likelihood under R = 0.5 is -inf (before the fix: a history of -inf returned as a fit, or "R must be
    finite" about the M-step's own R)."""
    z = np.array([[1e300], [-1.07]])
    with pytest.raises(ValueError) as exc:
        lb.fit_noise_em(np.eye(1), np.array([[0.3]]), np.zeros(1), np.zeros((1, 1)), lb.LinearMeasurement(z, H1, R1),
                        n_iter=2, fit=fit, per_run=False)
    assert "log-likelihood of measurement.z is -inf at iteration 0 (the largest |z| is 1e+300)" in _one_line(exc)


def test_em_whose_m_step_overflows_says_so_in_one_line():
    """z = 1e160 against R = 1e300 has a finite likelihood, but the R M-step squares the residual: 1e320."""
    z = np.array([[1e160], [-1.07]])
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        with pytest.raises(ConvergenceError) as exc:
            lb.fit_noise_em(np.eye(1), np.array([[0.3]]), np.zeros(1), np.zeros((1, 1)),
                            lb.LinearMeasurement(z, H1, np.array([[1e300]])), n_iter=2, fit=("R",), per_run=False)
    assert "M-step's R of iteration 1 overflows float64" in _one_line(exc) and "1e+160" in str(exc.value)


@pytest.mark.parametrize("per_run", [False, True])
def test_ml_on_a_reading_of_1e300_names_the_readings_not_the_callers_Q(per_run):
    """Before: per run, "Q must be finite" about the optimiser's own NaN step; pooled, the start returned as the fit
    with a log-likelihood of -inf."""
    z = _readings(np.random.default_rng(14), T=20, runs=2)
    z[0, 3, 0] = 1e300
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        with pytest.raises(ValueError) as exc:
            lb.fit_noise_ml(_model().F, _model().Q, X0, np.eye(4), lb.LinearMeasurement(z, H, R), per_run=per_run)
    assert "log-likelihood of the readings at the given noise is -inf in run (0,)" in _one_line(exc)


def test_rts_smoother_names_a_wrong_residual_in_one_line():
    run = lb.kalman_filter(_model().F, _model().Q, X0, np.eye(4), lb.LinearMeasurement(
        _readings(np.random.default_rng(15)), H, R), outputs=("x_pred", "P_pred"))
    with pytest.raises(ValueError) as exc:
        rts_smoother(run, _model().F, residual=lambda a, b: (a - b)[..., :2])
    assert "residual(a, b) must return the states' shape (4,), got (2,)" in _one_line(exc)
