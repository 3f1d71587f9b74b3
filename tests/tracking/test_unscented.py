"""Unscented Kalman filter: weights against filterpy, the UKF = KF invariant on linear models, the nonlinear
RSS update against an independent filterpy loop, missing readings, the printed variants, and the guard."""
import numpy as np
import pytest
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

import locbook as lb

ANCHORS = np.array([[0.0, 0.0], [30.0, 0.0], [30.0, 10.0], [0.0, 10.0]])


@pytest.mark.parametrize("n, alpha, beta, kappa", [(8, 1e-3, 2.0, 0.0), (6, 1e-3, 2.0, 0.0), (4, 1.0, 2.0, -1.0),
                                                    (3, 0.5, 0.0, 1.0)])
def test_weights_equal_filterpy_and_sum_to_one(n, alpha, beta, kappa):
    w = lb.unscented_weights(n, alpha, beta, kappa)
    ref = MerweScaledSigmaPoints(n, alpha, beta, kappa)
    np.testing.assert_allclose(w.mean, ref.Wm, rtol=1e-9)      # filterpy forms lambda / (n + lambda) (round-off)
    np.testing.assert_allclose(w.cov, ref.Wc, rtol=1e-9)
    assert w.mean.sum() == pytest.approx(1.0, abs=1e-9)
    # closed form of lambda / (n + lambda) (Gudipati Eq. (3.22), corrected)
    assert w.mean[0] == pytest.approx(1.0 - n / (alpha**2 * (n + kappa)), rel=1e-12)


def test_printed_weight_of_eq_3_22_sums_to_2n_over_n_plus_lambda():
    n, alpha = 8, 1e-3
    w = lb.unscented_weights(n, alpha, variant="literal_gudipati2017")
    n_plus_lambda = alpha**2 * n
    assert w.mean.sum() == pytest.approx(2 * n / n_plus_lambda, rel=1e-12)
    assert w.mean[0] == pytest.approx(n / n_plus_lambda, rel=1e-12)


def test_the_old_weights_keyword_warns_at_the_caller_and_gives_the_same_numbers():
    """``weights=`` (the earlier keyword) is ``variant=`` for one release: one DeprecationWarning naming it, the same
    run."""
    model = lb.constant_velocity(1.0, 0.05)
    z = np.random.default_rng(2).normal(size=(3, 8, 2)) + np.arange(8)[:, None]
    args = (model.F, model.Q, np.zeros(4), np.eye(4),
            lb.LinearMeasurement(z, model.position_measurement_matrix(), np.eye(2)))
    with pytest.warns(DeprecationWarning,
                      match=r"unscented_kalman_filter\(weights='literal_gudipati2017'\) is "
                            r"deprecated: use unscented_kalman_filter\(variant='literal_gudipati2017'\)") as caught:
        old = lb.unscented_kalman_filter(*args, alpha=1.0, weights="literal_gudipati2017")
    assert len(caught) == 1 and caught[0].filename == __file__
    new = lb.unscented_kalman_filter(*args, alpha=1.0, variant="literal_gudipati2017")
    np.testing.assert_array_equal(old.mean, new.mean)
    np.testing.assert_array_equal(old.cov, new.cov)
    with pytest.raises(TypeError, match="give variant= only"):
        lb.unscented_kalman_filter(*args, weights="corrected", variant="literal_gudipati2017")


def test_sigma_points_reproduce_mean_and_covariance():
    rng = np.random.default_rng(1)
    A = rng.standard_normal((3, 5, 5))
    P = A @ np.swapaxes(A, -1, -2) + 0.1 * np.eye(5)
    x = rng.standard_normal((3, 5))
    for alpha in (1e-3, 1.0):
        w = lb.unscented_weights(5, alpha)
        X = lb.sigma_points(x, P, w.lam)
        mean, cov, cross = lb.unscented_transform(X, X, w)
        np.testing.assert_allclose(mean, x, atol=1e-8)
        np.testing.assert_allclose(cov, P, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(cross, P, rtol=1e-6, atol=1e-6)


def _linear_setup(rng, batch=(5,), T=40):
    model = lb.constant_velocity(0.5, 0.3)
    truth = lb.simulate_states(model.F, model.Q, np.array([1.0, 2.0, 0.5, -0.2]), T - 1, rng=rng)
    H = model.position_measurement_matrix()
    R = np.array([[0.8, 0.1], [0.1, 0.5]])
    z = truth[..., :2] + rng.multivariate_normal(np.zeros(2), R, size=batch + (T,))
    z[0, 3, 1] = np.nan                     # a missing component
    z[1, 7, :] = np.nan                     # a step without any reading
    return model, H, R, z


@pytest.mark.parametrize("alpha", [1e-3, 0.1, 1.0])
def test_ukf_equals_kf_on_a_linear_model(alpha):
    rng = np.random.default_rng(7)
    model, H, R, z = _linear_setup(rng)
    x0, P0 = np.zeros(4), np.diag([4.0, 4.0, 1.0, 1.0])
    kf = lb.kalman_filter(model.F, model.Q, x0, P0, lb.LinearMeasurement(z, H, R))
    ukf = lb.unscented_kalman_filter(model.F, model.Q, x0, P0, [lb.LinearMeasurement(z, H, R)], alpha=alpha)
    np.testing.assert_allclose(ukf.mean, kf.mean, atol=1e-9)
    np.testing.assert_allclose(ukf.cov, kf.cov, atol=1e-9)
    assert ukf.floored_updates == 0


def _rss_data(rng, T=30, sigma_db=4.0):
    model = lb.constant_velocity(1.0, 0.05)
    start = np.array([3.0, 4.0, 0.6, 0.1])
    truth = lb.simulate_states(model.F, model.Q, start, T - 1, rng=rng)
    channel = lb.PathLossModel(np.array([-40.0, -45.0, -42.0, -38.0]), np.array([1.8, 3.1, 1.7, 1.2]), sigma_db)
    d = lb.pairwise_distance_m(truth[:, :2], ANCHORS)
    z = channel.sample_rss_dbm(d, rng=rng)
    return model, channel, start, z


def _filterpy_ukf(model, channel, z, x0, P0, alpha):
    """An independent UKF loop: filterpy's UnscentedKalmanFilter, sigma points redrawn around the prediction
    before each update (Gudipati Eq. (3.18))."""
    points = MerweScaledSigmaPoints(4, alpha=alpha, beta=2.0, kappa=0.0)

    def hx(s):
        d = np.linalg.norm(s[:2] - ANCHORS, axis=1)
        return channel.ref_power_dbm - 10 * channel.path_loss_exp * np.log10(d)

    ukf = UnscentedKalmanFilter(4, 4, model.dt_s, hx, lambda s, dt: model.F @ s, points)
    ukf.x, ukf.P, ukf.Q = x0.copy(), P0.copy(), model.Q
    ukf.R = channel.sigma_db**2 * np.eye(4)
    xs, Ps = [], []
    for zk in z:
        ukf.predict()
        ukf.sigmas_f = points.sigma_points(ukf.x, ukf.P)
        ukf.update(zk)
        xs.append(ukf.x.copy())
        Ps.append(ukf.P.copy())
    return np.array(xs), np.array(Ps)


@pytest.mark.parametrize("alpha", [1e-3, 0.5, 1.0])
def test_rss_ukf_equals_an_independent_filterpy_loop(alpha):
    rng = np.random.default_rng(3)
    model, channel, start, z = _rss_data(rng)
    x0, P0 = start + np.array([1.0, -1.0, 0.0, 0.0]), np.diag([2.0, 2.0, 0.5, 0.5])
    ours = lb.unscented_kalman_filter(model.F, model.Q, x0, P0,
                                      [lb.RssMeasurement(z, ANCHORS, channel, model.position_index)], alpha=alpha)
    ref_x, ref_P = _filterpy_ukf(model, channel, z, x0, P0, alpha)
    np.testing.assert_allclose(ours.mean, ref_x, atol=1e-8)
    np.testing.assert_allclose(ours.cov, ref_P, atol=1e-8)


def test_rss_ukf_batched_equals_runs_one_by_one_and_a_nan_drops_that_anchor():
    rng = np.random.default_rng(11)
    runs = [_rss_data(rng) for _ in range(3)]
    model, channel, start, _ = runs[0]
    z = np.stack([r[3] for r in runs])
    z[1, 5, 2] = np.nan
    x0, P0 = start, np.diag([2.0, 2.0, 0.5, 0.5])
    meas = lambda zz: [lb.RssMeasurement(zz, ANCHORS, channel, model.position_index)]
    batched = lb.unscented_kalman_filter(model.F, model.Q, x0, P0, meas(z))
    for i in range(3):
        one = lb.unscented_kalman_filter(model.F, model.Q, x0, P0, meas(z[i]))
        np.testing.assert_allclose(batched.mean[i], one.mean, atol=1e-9)
    # step 5 of run 1 without anchor 2 equals an update with three anchors only
    before = lb.unscented_kalman_filter(model.F, model.Q, x0, P0, meas(z[1, :5]))
    x_prior = before.mean[-1] @ model.F.T
    P_prior = model.F @ before.cov[-1] @ model.F.T + model.Q
    keep = [0, 1, 3]
    three = lb.PathLossModel(channel.ref_power_dbm[keep], channel.path_loss_exp[keep], channel.sigma_db)
    alone = lb.unscented_kalman_filter(np.eye(4), np.zeros((4, 4)), x_prior, P_prior,
                                       [lb.RssMeasurement(z[1, 5:6][:, keep], ANCHORS[keep], three,
                                                          model.position_index)])
    np.testing.assert_allclose(batched.mean[1, 5], alone.mean[0], atol=1e-9)
    np.testing.assert_allclose(batched.cov[1, 5], alone.cov[0], atol=1e-9)


def test_serial_rss_ukf_in_given_order_equals_scalar_updates_one_by_one():
    rng = np.random.default_rng(5)
    model, channel, start, z = _rss_data(rng, T=1)
    P0 = np.diag([2.0, 2.0, 0.5, 0.5])
    serial = lb.unscented_kalman_filter(model.F, model.Q, start, P0, [lb.RssMeasurement(
        z, ANCHORS, channel, model.position_index, mode="serial", order="given")], alpha=1.0)
    x, P = start @ model.F.T, model.F @ P0 @ model.F.T + model.Q
    for j in range(4):
        ch = lb.PathLossModel(channel.ref_power_dbm[j:j + 1], channel.path_loss_exp[j:j + 1], channel.sigma_db)
        r = lb.unscented_kalman_filter(np.eye(4), np.zeros((4, 4)), x, P, [lb.RssMeasurement(
            z[:, j:j + 1], ANCHORS[j:j + 1], ch, model.position_index)], alpha=1.0, predict_first=False)
        x, P = r.mean[0], r.cov[0]
    np.testing.assert_allclose(serial.mean[0], x, atol=1e-10)
    np.testing.assert_allclose(serial.cov[0], P, atol=1e-10)


def test_nonlinear_measurement_stream_equals_the_rss_stream():
    rng = np.random.default_rng(2)
    model, channel, start, z = _rss_data(rng)
    P0 = np.diag([2.0, 2.0, 0.5, 0.5])

    def h(x):
        d = np.linalg.norm(x[..., None, :2] - ANCHORS, axis=-1)
        return channel.ref_power_dbm - 10 * channel.path_loss_exp * np.log10(d)

    def jac(x):
        diff = x[..., None, :2] - ANCHORS
        g = -(10 * channel.path_loss_exp / np.log(10))[:, None] * diff / np.sum(diff**2, -1)[..., None]
        return np.concatenate([g, np.zeros(g.shape)], axis=-1)

    generic = lb.NonlinearMeasurement(z, h, channel.sigma_db**2 * np.eye(4), jacobian=jac, name="rss as a function")
    rss = lb.RssMeasurement(z, ANCHORS, channel, model.position_index)
    for run in (lb.unscented_kalman_filter, lb.extended_kalman_filter):
        a = run(model.F, model.Q, start, P0, [generic])
        b = run(model.F, model.Q, start, P0, [rss])
        np.testing.assert_allclose(a.mean, b.mean, atol=1e-9)
        np.testing.assert_allclose(a.cov, b.cov, atol=1e-9)
    with pytest.raises(ValueError, match="rss as a function: the EKF needs its jacobian"):
        lb.extended_kalman_filter(model.F, model.Q, start, P0,
                                  [lb.NonlinearMeasurement(z, h, np.eye(4), name="rss as a function")])


def test_printed_innovation_covariance_without_r_is_singular_with_four_anchors():
    rng = np.random.default_rng(4)
    model, channel, start, z = _rss_data(rng)
    with pytest.raises(lb.SingularCovarianceError, match="step 0"):
        lb.unscented_kalman_filter(model.F, model.Q, start, np.diag([2.0, 2.0, 0.5, 0.5]),
                                   [lb.RssMeasurement(z, ANCHORS, channel, model.position_index)],
                                   innovation_noise=False)


def test_a_covariance_that_is_not_positive_definite_is_named():
    rng = np.random.default_rng(4)
    model, channel, start, z = _rss_data(rng)
    # a P0 that is no covariance is refused up front, naming P0
    with pytest.raises(ValueError, match="P0 must be positive semi-definite.*-1"):
        lb.unscented_kalman_filter(np.eye(4), np.zeros((4, 4)), start, np.diag([2.0, -1.0, 0.5, 0.5]),
                                   [lb.RssMeasurement(z, ANCHORS, channel, model.position_index)])
    # a singular one is a covariance, but has no Cholesky factor for the sigma points: named at the step
    with pytest.raises(lb.SingularCovarianceError, match="state covariance P is not positive definite at step 0"):
        lb.unscented_kalman_filter(np.eye(4), np.zeros((4, 4)), start, np.diag([2.0, 0.0, 0.5, 0.5]),
                                   [lb.RssMeasurement(z, ANCHORS, channel, model.position_index)])


def _stonesoup_ukf(z, x0, P0, anchors, channel, alpha, dt=1.0, q=0.05):
    """Stone Soup's UnscentedKalmanPredictor + UnscentedKalmanUpdater on the same RSS scenario (axis-major CV
    model from Stone Soup itself); returns its F, Q and the posterior means and covariances."""
    from datetime import datetime, timedelta

    from stonesoup.models.measurement.nonlinear import NonLinearGaussianMeasurement
    from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel, ConstantVelocity
    from stonesoup.predictor.kalman import UnscentedKalmanPredictor
    from stonesoup.types.array import CovarianceMatrix, StateVector, StateVectors
    from stonesoup.types.detection import Detection
    from stonesoup.types.hypothesis import SingleHypothesis
    from stonesoup.types.state import GaussianState
    from stonesoup.updater.kalman import UnscentedKalmanUpdater

    class Rss(NonLinearGaussianMeasurement):
        @property
        def ndim_meas(self):
            return anchors.shape[0]

        def function(self, state, noise=False, **kwargs):
            pos = np.asarray(state.state_vector, float)[[0, 2]]             # (2, N sigma points)
            d = np.linalg.norm(pos.T[:, None, :] - anchors, axis=-1)        # (N, m)
            out = (channel.ref_power_dbm - 10 * channel.path_loss_exp * np.log10(d)).T   # (m, N)
            return StateVector(out) if out.shape[1] == 1 else StateVectors(out)

    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(q), ConstantVelocity(q)])
    meas = Rss(ndim_state=4, mapping=(0, 2),
               noise_covar=CovarianceMatrix(channel.sigma_db**2 * np.eye(anchors.shape[0])))
    predictor = UnscentedKalmanPredictor(transition, alpha=alpha, beta=2.0, kappa=0.0)
    updater = UnscentedKalmanUpdater(meas, alpha=alpha, beta=2.0, kappa=0.0)
    t0 = datetime(2026, 1, 1)
    state = GaussianState(StateVector(x0), CovarianceMatrix(P0), timestamp=t0)
    xs, Ps = [], []
    for k, zk in enumerate(z):
        pred = predictor.predict(state, timestamp=t0 + timedelta(seconds=dt * (k + 1)))
        state = updater.update(SingleHypothesis(pred, Detection(StateVector(zk), measurement_model=meas,
                                                                timestamp=pred.timestamp)))
        xs.append(np.asarray(state.state_vector, float).ravel())
        Ps.append(np.asarray(state.covar, float))
    F = transition.matrix(time_interval=timedelta(seconds=dt))
    Q = transition.covar(time_interval=timedelta(seconds=dt))
    return np.asarray(F, float), np.asarray(Q, float), np.array(xs), np.array(Ps)


@pytest.mark.parametrize("alpha", [1e-3, 0.5])
def test_rss_ukf_equals_stone_soup(alpha):
    rng = np.random.default_rng(8)
    channel = lb.PathLossModel(np.array([-40.0, -45.0, -42.0, -38.0]), np.array([1.8, 3.1, 1.7, 1.2]), 4.0)
    truth = np.stack([np.linspace(3, 20, 25), np.full(25, 4.0)], -1) + 0.2 * rng.standard_normal((25, 2))
    z = channel.sample_rss_dbm(lb.pairwise_distance_m(truth, ANCHORS), rng=rng)
    x0 = np.array([4.0, 0.5, 3.0, 0.0])                                   # axis-major [x, vx, y, vy]
    P0 = np.diag([2.0, 0.5, 2.0, 0.5])
    F, Q, ref_x, ref_P = _stonesoup_ukf(z, x0, P0, ANCHORS, channel, alpha)
    ours = lb.unscented_kalman_filter(F, Q, x0, P0, [lb.RssMeasurement(z, ANCHORS, channel, np.array([0, 2]))],
                                      alpha=alpha, beta=2.0, kappa=0.0)
    np.testing.assert_allclose(ours.mean, ref_x, atol=1e-8)
    np.testing.assert_allclose(ours.cov, ref_P, atol=1e-8)


@pytest.mark.slow
def test_covariance_stays_symmetric_positive_definite_over_1e5_steps_at_alpha_1e_3():
    rng = np.random.default_rng(0)
    T = 100_000
    model = lb.constant_velocity(0.1, 0.01)
    anchors = np.array([[0.0, 0.0], [20.0, 0.0], [10.0, 15.0]])
    t = np.arange(T) * 0.1
    pos = np.stack([10 + 5 * np.cos(0.05 * t), 6 + 4 * np.sin(0.05 * t)], -1)       # laps around the anchors
    ch = lb.PathLossModel(-40.0, 2.5, 3.0)
    z = ch.sample_rss_dbm(lb.pairwise_distance_m(pos, anchors), rng=rng)
    res = lb.unscented_kalman_filter(model.F, model.Q, np.r_[pos[0], 0.0, 0.0], np.eye(4),
                                     [lb.RssMeasurement(z, anchors, ch, model.position_index)], alpha=1e-3)
    assert np.linalg.eigvalsh(res.cov).min() > 0
    np.testing.assert_array_equal(res.cov, np.swapaxes(res.cov, -1, -2))
    assert res.floored_updates == 0
    err = np.linalg.norm(res.mean[:, :2] - pos, axis=-1)
    assert err[-10_000:].mean() < 2.0 and np.isfinite(res.mean).all()
