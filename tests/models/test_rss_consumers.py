"""Every RSS consumer agrees with the one measurement model: the EKF stream's update is filterpy's EKF update
with RssModel's mean and Jacobian, the UKF's h is RssModel's mean, the static bound is RssModel's Fisher information
(closed form of Patwari et al. 2003, Eq. (5) as the oracle), the RSS ML fix is a stationary point of the model's
cost, and the compiled row kernel is the numpy formula, also inside the near-field clamp (where the clamped mean is
flat: its derivative, its information and the anchor-sigma inflation are 0)."""
import dataclasses

import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter

import locbook as lb
from locbook.models.rss import rss_mean_jacobian
from locbook.tracking import _kernels

ANCHORS = np.array([[0.0, 0.0], [8.0, 0.5], [1.0, 7.0], [7.5, 6.0]])
CHANNEL = lb.PathLossModel(np.array([-44.0, -47.0, -50.0, -46.0]), np.array([2.0, 2.4, 2.8, 1.9]), 3.0)


CLAMPED = dataclasses.replace(CHANNEL, min_distance_m=1e-3)


def _stream(z, mode="parallel", channel=CHANNEL, **kw):
    return lb.RssMeasurement(z, ANCHORS, channel, [0, 1], mode=mode, **kw)


@pytest.mark.parametrize("x_pos", [[3.0, 2.5], [0.0004, 0.0003]])        # the second inside the 1 mm clamp
def test_parallel_ekf_update_is_filterpys_with_the_models_mean_and_jacobian(x_pos):
    x0 = np.array([x_pos[0], x_pos[1], 0.2, -0.1])
    P0 = np.diag([1.0, 1.5, 0.3, 0.3])
    z = np.array([[-60.0, -62.0, -68.0, -59.0]])
    res = lb.extended_kalman_filter(np.eye(4), np.zeros((4, 4)), x0, P0, _stream(z, channel=CLAMPED),
                                    predict_first=False)
    model = lb.RssModel(ANCHORS, CLAMPED)

    def hjac(x):
        H = np.zeros((4, 4))
        H[:, :2] = model.position_jacobian(np.ravel(x)[None, :2])[0, 0]          # filterpy's states are columns
        return H

    ekf = ExtendedKalmanFilter(dim_x=4, dim_z=4)
    ekf.x, ekf.P, ekf.R = x0[:, None].copy(), P0.copy(), 9.0 * np.eye(4)
    ekf.update(z[0][:, None], hjac, lambda x: model.mean_rss_dbm(x[None, :2, 0])[0, 0][:, None])
    np.testing.assert_allclose(res.mean[0], ekf.x[:, 0], rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(res.cov[0], ekf.P, rtol=1e-9, atol=1e-12)
    if np.hypot(*x_pos) < 1e-3:                                 # inside the clamp of anchor 0: no correction from it
        assert np.all(hjac(x0)[0] == 0.0)


@pytest.mark.parametrize("mode", ["parallel", "serial"])
def test_a_state_on_an_anchor_without_a_clamp_is_a_named_error_and_a_clamp_makes_the_ekf_finite(mode):
    x0 = np.array([8.0, 0.5, 0.0, 0.0])                          # exactly on anchor 1, its reading the strongest
    z = np.array([[-60.0, -50.0, -68.0, -59.0]])                 # (the serial update linearises there first)
    args = (np.eye(4), np.zeros((4, 4)), x0, np.eye(4))
    for run in (lb.extended_kalman_filter, lb.unscented_kalman_filter):    # the UKF's centre sigma point is x0
        with pytest.raises(lb.SingularCovarianceError, match="on an anchor at step 0 .*no near-field clamp"):
            run(*args, _stream(z, mode), predict_first=False)
    res = lb.extended_kalman_filter(*args, _stream(z, mode, channel=CLAMPED), predict_first=False)
    assert np.isfinite(res.mean).all()


def test_stream_mean_and_jacobian_are_the_models_with_the_channels_clamp():
    ch = lb.PathLossModel(CHANNEL.ref_power_dbm, CHANNEL.path_loss_exp, CHANNEL.sigma_db, min_distance_m=0.5)
    meas = lb.RssMeasurement(np.zeros((1, 4)), ANCHORS, ch, [0, 1])
    assert meas.clamp_m == 0.5
    model = lb.RssModel(ANCHORS, ch)
    pos = np.array([[0.3, 0.1], [4.0, 3.0], [7.6, 6.2], [8.0, 0.5]])     # inside, outside, inside, on an anchor
    h = meas.model.mean(pos, step=0)                   # the stream's model in points form: 4 points, no run axis
    grad = meas.model.jacobian(pos, step=0)
    np.testing.assert_array_equal(h, model.mean_rss_dbm(pos)[0])
    np.testing.assert_array_equal(grad, model.position_jacobian(pos)[0])
    variance = np.diagonal(meas.model.covariance(pos, step=0), axis1=-2, axis2=-1)
    np.testing.assert_array_equal(variance, np.broadcast_to(ch.sigma_db**2, (4, 4)))


def test_ukf_h_is_the_models_mean():
    meas = _stream(np.zeros((1, 4)), channel=CLAMPED)
    model = lb.RssModel(ANCHORS, CLAMPED)
    sigma_points = np.random.default_rng(3).uniform(-1, 9, (9, 4))
    sigma_points[0, :2] = ANCHORS[2] + 1e-4                                # one within the clamp
    np.testing.assert_array_equal(meas.model.mean(sigma_points, step=0), model.mean_rss_dbm(sigma_points[:, :2])[0])


def test_crlb_information_is_the_models_fisher_information_and_its_closed_form():
    rng = np.random.default_rng(4)
    pos = rng.uniform(0.5, 7.5, (6, 2))
    n, sigma = 2.6, 4.0
    model = lb.RssModel(ANCHORS, lb.PathLossModel(0.0, n, sigma, min_distance_m=0.2))
    info = lb.rss_position_information(pos, model)
    np.testing.assert_array_equal(info, model.fisher_information(pos)[0])
    diff = pos[:, None, :] - ANCHORS
    d2 = np.sum(diff**2, -1)
    beta2 = (10 * n / (sigma * np.log(10))) ** 2                              # Patwari et al. (2003), Eq. (5)
    np.testing.assert_allclose(info, beta2 * np.einsum("pj,pji,pjk->pik", 1 / d2**2, diff, diff), rtol=1e-13)
    near = ANCHORS[1] + [0.1, -0.05]                                          # within 0.2 m of anchor 1: no term
    np.testing.assert_allclose(lb.rss_position_information(near, model),
                               lb.rss_position_information(near, lb.RssModel(ANCHORS[[0, 2, 3]],
                                                                             lb.PathLossModel(0.0, n, sigma))),
                               rtol=1e-14)


def test_rss_ml_fix_is_a_stationary_point_of_the_models_cost():
    truth = np.array([[3.0, 2.0], [5.5, 4.5], [1.5, 5.0]])
    model = lb.RssModel(ANCHORS, CHANNEL)
    z = model.mean_rss_dbm(truth)[0] + np.random.default_rng(5).normal(0, 3.0, (3, 4))
    fix = lb.rss_ml_position(z, model, tol_m=1e-12)
    assert fix.converged.all()
    resid = z - model.mean_rss_dbm(fix.position_m)[0]
    gradient = np.einsum("pj,pji->pi", resid, model.position_jacobian(fix.position_m)[0])    # -(1/2) d cost / dp
    assert np.max(np.abs(gradient)) < 1e-6 * np.max(np.abs(model.position_jacobian(fix.position_m)))


def test_compiled_row_kernel_is_the_numpy_model():
    """The EKF kernel's RSS rows (every lane at once) against the numpy model, lane by lane: outside the clamp, inside
    it, on the anchor, and a missing reading (zero innovation, unit variance, zero Jacobian, no degree of freedom)."""
    clamp, sigma, anchor_sigma, ple, p0 = 1e-3, 3.0, 0.4, 2.4, -47.0
    meas = lb.RssMeasurement(np.zeros((1, 4)), ANCHORS, lb.PathLossModel(p0, ple, sigma, min_distance_m=clamp), [0, 1],
                             anchor_sigma_m=anchor_sigma)
    j = 1                                               # the reading of anchor 1
    offsets = np.array([[2.0, 1.0], [3e-4, -2e-4], [0.0, 0.0], [1.0, 1.0]])
    W = len(offsets)
    x = np.zeros((4, W))
    x[:2] = (ANCHORS[j] + offsets).T
    z = np.array([-60.0, -61.0, -62.0, np.nan])
    Z = np.zeros((W, 1, 4))
    Z[:, 0, j] = z
    A = np.zeros((1, 1, 4, 3))
    A[0, 0, :, :2] = ANCHORS
    chan = [np.full((1, 4), v) for v in (p0, ple, sigma)]
    Hr, nu, var = np.full((1, 4, W), 7.0), np.full((1, W), 7.0), np.full((1, W), 7.0)
    valid, dof = np.zeros((1, W), np.bool_), np.zeros(W, np.int64)
    scratch = [np.empty(W) for _ in range(5)]
    got = _kernels._nb_rss_rows(x, 0, np.arange(W), np.full(W, j), 0, 0, 0, Z, A, *chan, np.array([0, 1, 0]), 2,
                                np.nan, 2, 1.0, clamp, anchor_sigma, Hr, nu, var, valid, dof, *scratch)
    assert got == 3 and dof.tolist() == [1, 1, 1, 0] and valid[0].tolist() == [True, True, True, False]
    for w in range(3):
        h, grad, d2 = rss_mean_jacobian(x[:2, w] - ANCHORS[j], p0, ple, min_distance_m=clamp)
        d = np.sqrt(d2)
        # the logarithm is musl's (vectorised) against numpy's: within 2 ulp of each other
        # (tests/tracking/test_vecmath.py)
        assert abs(nu[0, w] - (z[w] - h)) <= 4 * np.spacing(abs(h))
        # the kernel may fuse a multiply and an add (one rounding instead of two): a few ulp
        np.testing.assert_allclose(Hr[0, :2, w], grad, rtol=8 * np.finfo(float).eps, atol=0)
        np.testing.assert_allclose(var[0, w], meas.variance_db2(d, ple, sigma), rtol=8 * np.finfo(float).eps, atol=0)
        if np.hypot(*offsets[w]) < clamp:
            assert grad.tolist() == [0.0, 0.0] and Hr[0, :2, w].tolist() == [0.0, 0.0] and var[0, w] == sigma**2
    assert nu[0, 3] == 0.0 and var[0, 3] == 1.0 and Hr[0, :2, 3].tolist() == [0.0, 0.0]
