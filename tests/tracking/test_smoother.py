"""The Rauch-Tung-Striebel smoother against filterpy's (an independent implementation), and its invariants."""
import numpy as np
import pytest

import locbook as lb
from locbook.tracking.smoother import rts_smoother
from oracles import filterpy_kalman, filterpy_rts

pytest.importorskip("filterpy.kalman")


def _cv_problem(rng, T=60, runs=3, missing=True):
    dt, q = 0.5, 0.3
    model = lb.constant_velocity(dt, q, dim=2)
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    R = np.diag([0.8, 1.3])
    truth = np.cumsum(rng.normal(0, 0.3, (runs, T, 2)), axis=1)
    z = truth + rng.normal(0, 1.0, (runs, T, 2))
    if missing:
        z[:, 10:14] = np.nan                              # four steps without a reading
    x0 = np.zeros(4)
    P0 = np.diag([4.0, 4.0, 1.0, 1.0])
    return model, H, R, z, x0, P0


def test_rts_smoother_equals_filterpy_on_every_run():
    rng = np.random.default_rng(1)
    model, H, R, z, x0, P0 = _cv_problem(rng)
    run = lb.kalman_filter(model.F, model.Q, np.broadcast_to(x0, (3, 4)), P0, lb.LinearMeasurement(z, H, R),
                           outputs=("x_pred", "P_pred"))
    smooth = rts_smoother(run, model.F)
    means, covs = filterpy_kalman(model.F, model.Q, H, R, z, x0, P0)          # a step with NaN: prediction only
    xs, Ps, Ks = filterpy_rts(model.F, model.Q, means, covs)
    for r in range(3):
        np.testing.assert_allclose(run.mean[r], means[r], atol=1e-9)
        np.testing.assert_allclose(smooth.mean[r], xs[r], atol=1e-9)
        np.testing.assert_allclose(smooth.cov[r], Ps[r], atol=1e-9)
        np.testing.assert_allclose(smooth.gain[r], Ks[r, :-1], atol=1e-9)


def test_the_last_step_is_the_filter_and_smoothing_never_adds_uncertainty():
    rng = np.random.default_rng(2)
    model, H, R, z, x0, P0 = _cv_problem(rng, runs=2)
    run = lb.kalman_filter(model.F, model.Q, np.broadcast_to(x0, (2, 4)), P0, lb.LinearMeasurement(z, H, R),
                           outputs=("x_pred", "P_pred"))
    smooth = rts_smoother(run, model.F)
    np.testing.assert_array_equal(smooth.mean[:, -1], run.mean[:, -1])
    # P_filtered - P_smoothed is positive semi-definite at every step
    assert np.linalg.eigvalsh(run.cov - smooth.cov).min() > -1e-10


def test_rts_smoother_refuses_a_run_without_its_predictions():
    rng = np.random.default_rng(3)
    model, H, R, z, x0, P0 = _cv_problem(rng, runs=1)
    run = lb.kalman_filter(model.F, model.Q, x0, P0, lb.LinearMeasurement(z[0], H, R))
    with pytest.raises(ValueError, match="outputs=\\('x_pred', 'P_pred', 'P_cross'\\)"):
        rts_smoother(run, model.F)
    every_other = lb.kalman_filter(model.F, model.Q, x0, P0, lb.LinearMeasurement(z[0], H, R),
                                   record=np.arange(0, 60, 2), outputs=("x_pred", "P_pred"))
    with pytest.raises(ValueError, match="every step recorded"):
        rts_smoother(every_other, model.F)


def test_one_covariance_for_every_run_gives_the_per_run_smoother():
    """A linear run whose covariance is the same in every run is smoothed with one covariance recursion; each run
    equals the general smoother applied to that run alone."""
    from locbook.tracking.results import KalmanResult
    rng = np.random.default_rng(4)
    model, H, R, z, x0, P0 = _cv_problem(rng, runs=3, missing=False)
    run = lb.kalman_filter(model.F, model.Q, np.broadcast_to(x0, (3, 4)), P0, lb.LinearMeasurement(z, H, R),
                           outputs=("x_pred", "P_pred", "P_cross"))
    smooth = rts_smoother(run)
    for r in range(3):
        alone = rts_smoother(KalmanResult(run.mean[r], run.cov[r], run.steps, run.x_pred[r], run.P_pred[r],
                                          P_cross=run.P_cross[r]))
        np.testing.assert_allclose(smooth.mean[r], alone.mean, atol=1e-12)
        np.testing.assert_allclose(smooth.cov[r], alone.cov, atol=1e-12)
        np.testing.assert_allclose(smooth.gain[r], alone.gain, atol=1e-12)


def test_rts_smoother_of_a_run_with_no_steps_is_empty():
    meas = lb.LinearMeasurement(np.zeros((0, 2)), np.eye(2), np.eye(2))
    run = lb.kalman_filter(np.eye(2), 0.01 * np.eye(2), np.zeros(2), np.eye(2), [meas],
                           outputs=("x_pred", "P_pred", "P_cross"))
    s = lb.rts_smoother(run)
    assert s.mean.shape == (0, 2) and s.cov.shape == (0, 2, 2) and s.gain.shape == (0, 2, 2)
