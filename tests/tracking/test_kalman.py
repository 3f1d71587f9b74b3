"""One result and one argument order for the Kalman family: the functional predict / update against filterpy's
functions, the per-step Gaussian log-likelihood and S against scipy and filterpy's KalmanFilter, and the layout of the
innovations and S of several streams and serial updates, checked by exact identities of the Gaussian model (the chain
rule of densities: sequential updates with independent noises give the joint density of the stacked readings)."""
import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from filterpy.kalman import predict as fp_predict
from filterpy.kalman import update as fp_update
from scipy.stats import multivariate_normal

import locbook as lb
from locbook.errors import SingularCovarianceError
from locbook.tracking import _compiled
from locbook.tracking.functional import predict, update

try:
    import numba  # noqa: F401
    HAVE_NUMBA = True
except ImportError:
    HAVE_NUMBA = False

MODEL = lb.constant_velocity(1.0, 0.05)
H = MODEL.position_measurement_matrix()


def _problem(batch=4, steps=25, seed=0):
    rng = np.random.default_rng(seed)
    z = rng.normal(size=(batch, steps, 2)) * [2.0, 0.5] + np.arange(steps)[:, None] * [0.3, -0.2]
    R = np.array([[2.0, 0.3], [0.3, 0.7]])
    x0 = rng.normal(size=(batch, 4))
    P0 = np.diag([4.0, 3.0, 1.0, 1.0])
    return z, R, x0, P0


def _spd(rng, n):
    A = rng.normal(size=(n, n))
    return A @ A.T + n * np.eye(n)


def test_functional_predict_equals_filterpy():
    rng = np.random.default_rng(1)
    x, P = rng.normal(size=(5, 4)), np.stack([_spd(rng, 4) for _ in range(5)])
    xp, Pp = predict(x, P, MODEL.F, MODEL.Q)
    for b in range(5):
        fx, fP = fp_predict(x[b], P[b], MODEL.F, MODEL.Q)
        np.testing.assert_allclose(xp[b], fx, rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(Pp[b], fP, rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("m", [1, 2, 3])
def test_functional_update_equals_filterpy(m):
    """x, P (Joseph form), the innovation and S of filterpy's update function, run by run; the log-likelihood is
    scipy's logpdf of the innovation under N(0, S) (filterpy's update function evaluates it at the posterior mean, its
    KalmanFilter class at the innovation, as here: see test_log_likelihood_and_S_equal_filterpy_kalmanfilter)."""
    rng = np.random.default_rng(m)
    n, B = 4, 6
    x, P = rng.normal(size=(B, n)), np.stack([_spd(rng, n) for _ in range(B)])
    Hm, R, z = rng.normal(size=(m, n)), _spd(rng, m), rng.normal(size=(B, m)) * 3
    out = update(x, P, z, Hm, R)
    for b in range(B):
        fx, fP, y, _, S, _ = fp_update(x[b], P[b], z[b], R, Hm, return_all=True)
        np.testing.assert_allclose(out.x[b], fx, rtol=1e-11, atol=1e-12)
        np.testing.assert_allclose(out.P[b], fP, rtol=1e-11, atol=1e-12)
        np.testing.assert_allclose(out.innovation[b], y, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(out.S[b], S, rtol=1e-12)
        assert out.log_likelihood[b] == pytest.approx(multivariate_normal.logpdf(y, cov=S), rel=1e-11)
        assert out.nis[b] == pytest.approx(y @ np.linalg.solve(S, y), rel=1e-11)
    assert (out.dof == m).all()


def test_functional_update_skips_missing_readings():
    """A NaN component is left out: the update equals filterpy's with the present rows of H and R only; its innovation
    and its row and column of S are NaN; a run without readings keeps its prior with NIS, dof and log-likelihood 0."""
    rng = np.random.default_rng(5)
    x, P = rng.normal(size=(3, 4)), _spd(rng, 4)
    Hm, R = rng.normal(size=(3, 4)), _spd(rng, 3)
    z = rng.normal(size=(3, 3))
    z[0, 1] = np.nan
    z[2] = np.nan
    out = update(x, P, z, Hm, R)
    keep = [0, 2]
    fx, fP, y, _, S, _ = fp_update(x[0], P, z[0, keep], R[np.ix_(keep, keep)], Hm[keep], return_all=True)
    np.testing.assert_allclose(out.x[0], fx, rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(out.P[0], fP, rtol=1e-11, atol=1e-12)
    np.testing.assert_allclose(out.innovation[0, keep], y, rtol=1e-12)
    np.testing.assert_allclose(out.S[0][np.ix_(keep, keep)], S, rtol=1e-12)
    assert np.isnan(out.innovation[0, 1]) and np.isnan(out.S[0, 1]).all() and np.isnan(out.S[0, :, 1]).all()
    assert out.log_likelihood[0] == pytest.approx(multivariate_normal.logpdf(y, cov=S), rel=1e-11)
    assert out.dof.tolist() == [2, 3, 0]
    np.testing.assert_array_equal(out.x[2], x[2])
    np.testing.assert_array_equal(out.P[2], P)
    assert out.nis[2] == 0 and out.log_likelihood[2] == 0


def test_functional_update_errors_name_the_argument_and_run():
    rng = np.random.default_rng(2)
    with pytest.raises(ValueError, match="R must be symmetric"):
        update(np.zeros(4), np.eye(4), np.zeros(2), H, np.array([[1.0, 0.5], [0.0, 1.0]]))
    with pytest.raises(ValueError, match=r"H must have shape \(2, 4\)"):
        update(np.zeros(4), np.eye(4), np.zeros(2), H[:, :3], np.eye(2))
    with pytest.raises(ValueError, match=r"F must have shape \(4, 4\)"):
        predict(np.zeros(4), np.eye(4), np.eye(3), np.eye(4))
    P = np.stack([np.eye(4), np.zeros((4, 4))])
    with pytest.raises(SingularCovarianceError, match=r"run index \(1,\)"):
        update(rng.normal(size=(2, 4)), P, np.ones((2, 2)), H, np.zeros((2, 2)))


def test_log_likelihood_and_S_equal_filterpy_kalmanfilter():
    """The KF's per-step log-likelihood, innovation and S against filterpy's KalmanFilter (``log_likelihood``, ``y``,
    ``S`` after each update) and scipy's multivariate normal; the total is their sum."""
    z, R, x0, P0 = _problem()
    res = lb.kalman_filter(MODEL.F, MODEL.Q, x0, P0, lb.LinearMeasurement(z, H, R), outputs=("innovation", "S"))
    for b in range(z.shape[0]):
        kf = KalmanFilter(dim_x=4, dim_z=2)
        kf.F, kf.H, kf.Q, kf.R, kf.x, kf.P = MODEL.F, H, MODEL.Q, R, x0[b].copy(), P0.copy()
        for k, zz in enumerate(z[b]):
            kf.predict()
            kf.update(zz)
            np.testing.assert_allclose(res.innovation[b, k], kf.y, rtol=1e-10, atol=1e-11)
            np.testing.assert_allclose(res.S[b, k], kf.S, rtol=1e-10)
            assert res.log_likelihood[b, k] == pytest.approx(kf.log_likelihood, rel=1e-10)
            assert res.log_likelihood[b, k] == pytest.approx(
                multivariate_normal.logpdf(res.innovation[b, k], cov=res.S[b, k]), rel=1e-10)
    np.testing.assert_allclose(res.total_log_likelihood, res.log_likelihood.sum(axis=-1), rtol=1e-14)


def test_serial_updates_and_several_streams_give_the_joint_density():
    """With independent noises the sequential updates' log-likelihoods add up to the joint density of the stacked
    readings (the chain rule; exact for linear streams): a serial stream with diagonal R, and two streams of one step,
    equal one parallel update; their innovations are each taken at the state updated so far, and S is block diagonal
    (the sequential innovations are independent), so logpdf(innovation; 0, S) is the same total again."""
    z, _, x0, P0 = _problem(batch=3)
    R = np.diag([2.0, 0.7])
    full = ("innovation", "S", "x_pred")
    par = lb.extended_kalman_filter(MODEL.F, MODEL.Q, x0, P0, lb.LinearMeasurement(z, H, R), outputs=full)
    ser = lb.extended_kalman_filter(MODEL.F, MODEL.Q, x0, P0, lb.LinearMeasurement(z, H, R, mode="serial"),
                                    outputs=full)
    two = lb.extended_kalman_filter(MODEL.F, MODEL.Q, x0, P0, [lb.LinearMeasurement(z[..., :1], H[:1], R[:1, :1]),
                                                               lb.LinearMeasurement(z[..., 1:], H[1:], R[1:, 1:])],
                                    outputs=full)
    for res in (ser, two):
        np.testing.assert_allclose(res.mean, par.mean, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(res.log_likelihood, par.log_likelihood, rtol=1e-10)
        assert (res.S[..., 0, 1] == 0).all() and (res.S[..., 1, 0] == 0).all()          # block diagonal
        # the first reading's innovation is taken at the prior, the second at the state updated by the first
        np.testing.assert_allclose(res.innovation[..., 0], par.innovation[..., 0], rtol=1e-10, atol=1e-10)
        logpdf = [[multivariate_normal.logpdf(res.innovation[b, k], cov=res.S[b, k]) for k in range(z.shape[1])]
                  for b in range(z.shape[0])]
        np.testing.assert_allclose(res.log_likelihood, logpdf, rtol=1e-10)
    np.testing.assert_allclose(two.x_pred, par.x_pred, rtol=1e-12, atol=1e-12)


def test_ukf_and_numba_ekf_log_likelihood_equal_the_kf():
    """On a linear model the UKF is the KF (its unscented transform is exact), log-likelihood, innovation and S
    included; the compiled EKF gives the numpy EKF's log-likelihood (to round-off)."""
    z, R, x0, P0 = _problem(batch=3)
    z[1, 4, 0] = np.nan
    z[:, 7] = np.nan
    kf = lb.kalman_filter(MODEL.F, MODEL.Q, x0, P0, lb.LinearMeasurement(z, H, R), outputs=("innovation", "S"))
    ukf = lb.unscented_kalman_filter(MODEL.F, MODEL.Q, x0, P0, lb.LinearMeasurement(z, H, R), alpha=1.0,
                                     outputs=("innovation", "S"))
    np.testing.assert_allclose(ukf.log_likelihood, kf.log_likelihood, rtol=1e-9)
    np.testing.assert_allclose(ukf.innovation, kf.innovation, rtol=1e-9, atol=1e-10)
    np.testing.assert_allclose(ukf.S, kf.S, rtol=1e-9)
    assert np.isnan(kf.log_likelihood[:, 7]).all() and np.isnan(kf.innovation[1, 4, 0])
    assert np.isnan(kf.S[1, 4, 0]).all() and np.isfinite(kf.S[1, 4, 1, 1])
    np.testing.assert_allclose(kf.total_log_likelihood, np.nansum(kf.log_likelihood, axis=-1))
    if HAVE_NUMBA:
        saved = _compiled._NUMBA_ENABLED, _compiled._NUMBA_MIN_WORK
        try:
            _compiled._NUMBA_ENABLED, _compiled._NUMBA_MIN_WORK = True, 0
            Rs = np.stack([R, 2 * R, R])                 # batched R: no shared covariance, the compiled path runs
            setup = lb.tracking._loop._setup(MODEL.F, MODEL.Q, x0, P0, [lb.LinearMeasurement(z, H, Rs)], None, "ekf")
            assert _compiled._compiled_ekf(setup, [lb.LinearMeasurement(z, H, Rs)], True) is not None
            fast = lb.extended_kalman_filter(MODEL.F, MODEL.Q, x0, P0, lb.LinearMeasurement(z, H, Rs))
            _compiled._NUMBA_ENABLED = False
            slow = lb.extended_kalman_filter(MODEL.F, MODEL.Q, x0, P0, lb.LinearMeasurement(z, H, Rs))
        finally:
            _compiled._NUMBA_ENABLED, _compiled._NUMBA_MIN_WORK = saved
        np.testing.assert_allclose(fast.log_likelihood, slow.log_likelihood, rtol=1e-11)


def test_serial_rss_innovations_sit_in_their_anchors_columns():
    """A serial RSS stream updates strongest reading first; its innovations and variances are recorded in the
    anchors' columns, so the NIS and log-likelihood are the sums of the scalar terms over the columns, and S is
    diagonal with NaN at a missing anchor."""
    anchors = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    ch = lb.PathLossModel(-40.0, 2.5, 3.0)
    rng = np.random.default_rng(3)
    truth = np.array([3.0, 4.0])
    d = np.linalg.norm(truth - anchors, axis=-1)
    z = -40.0 - 25.0 * np.log10(d) + rng.normal(0, 3.0, size=(2, 6, 4))
    z[0, 2, 1] = np.nan
    meas = lb.RssMeasurement(z, anchors, ch, np.array([0, 1]), mode="serial")
    res = lb.extended_kalman_filter(np.eye(4), 0.01 * np.eye(4), np.r_[5.0, 5.0, 0, 0], np.diag([9.0, 9.0, 1, 1]),
                                    meas, outputs=("innovation", "S"))
    var = np.diagonal(res.S, axis1=-2, axis2=-1)
    off = res.S - var[..., None] * np.eye(4)
    assert np.nanmax(np.abs(off)) == 0
    assert np.isnan(res.innovation[0, 2, 1]) and np.isnan(var[0, 2, 1])
    np.testing.assert_allclose(res.nis, np.nansum(res.innovation ** 2 / var, axis=-1), rtol=1e-12)
    scalar = -0.5 * (res.innovation ** 2 / var + np.log(2 * np.pi * var))
    np.testing.assert_allclose(res.log_likelihood, np.nansum(scalar, axis=-1), rtol=1e-12)
    assert (res.nis_dof == np.isfinite(z).sum(-1)).all()


def test_literal_george_records_the_previous_posterior_as_its_prior():
    z, R, x0, P0 = _problem(batch=2, steps=6)
    res = lb.kalman_filter(MODEL.F, MODEL.Q, x0, P0, lb.LinearMeasurement(z, H, R), variant="literal_george",
                           outputs=("x_pred", "P_pred"))
    np.testing.assert_array_equal(res.x_pred[:, 1:], res.mean[:, :-1])
    np.testing.assert_array_equal(res.P_pred[:, 1:], res.cov[:, :-1])


def test_the_old_standard_variant_warns_at_the_caller_and_gives_the_same_numbers():
    """``variant="standard"`` (the earlier keyword) is ``"corrected"`` for one release; the result says
    ``"corrected"``."""
    z, R, x0, P0 = _problem(batch=3, steps=8)
    with pytest.warns(DeprecationWarning, match=r"kalman_filter\(variant='standard'\) is deprecated: use "
                                                r"kalman_filter\(variant='corrected'\)") as caught:
        old = lb.kalman_filter(MODEL.F, MODEL.Q, x0, P0, lb.LinearMeasurement(z, H, R), variant="standard")
    assert len(caught) == 1 and caught[0].filename == __file__
    new = lb.kalman_filter(MODEL.F, MODEL.Q, x0, P0, lb.LinearMeasurement(z, H, R))
    np.testing.assert_array_equal(old.mean, new.mean)
    np.testing.assert_array_equal(old.cov, new.cov)
    assert (old.variant == new.variant == "corrected"
            and lb.tracking.kalman.KF_VARIANTS == ("corrected", "literal_george"))
    with pytest.raises(ValueError, match=r"variant must be one of \('corrected', 'literal_george'\)"):
        lb.kalman_filter(MODEL.F, MODEL.Q, x0, P0, lb.LinearMeasurement(z, H, R), variant="literal_george2015")


def test_one_argument_order_and_clear_refusals():
    z, R, x0, P0 = _problem(batch=2, steps=5)
    stream = lb.LinearMeasurement(z, H, R)
    a = lb.kalman_filter(MODEL.F, MODEL.Q, x0, P0, stream)
    b = lb.extended_kalman_filter(MODEL.F, MODEL.Q, x0, P0, [stream])
    np.testing.assert_array_equal(a.mean, b.mean)
    with pytest.raises(ValueError, match="kalman_filter takes LinearMeasurement streams"):
        lb.kalman_filter(MODEL.F, MODEL.Q, x0, P0, lb.RssMeasurement(z, np.zeros((2, 2)), lb.PathLossModel(-40, 2, 3),
                                                                     np.array([0, 1])))
    with pytest.raises(ValueError, match="outputs must name fields among"):
        lb.extended_kalman_filter(MODEL.F, MODEL.Q, x0, P0, stream, outputs=("K",))
    with pytest.raises(ValueError, match="measurements must be a measurement stream or a list"):
        lb.unscented_kalman_filter(MODEL.F, MODEL.Q, x0, P0, 3)
