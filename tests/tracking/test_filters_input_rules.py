"""Missing components, singular covariances and input checks of the filters.

Independent references: filterpy's KalmanFilter updated with the rows present (H and R reduced by hand),
and the RSS likelihood recomputed with the silent reader removed.
"""
import re
import warnings

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from hypothesis import given, settings
from hypothesis.extra.numpy import arrays

import locbook as lb
from oracles import filterpy_kalman

MODEL = lb.constant_velocity(1.0, 0.05)
H = MODEL.position_measurement_matrix()
R = np.array([[0.5, 0.1], [0.1, 0.8]])
X0, P0 = np.array([0.0, 0.0, 1.0, 0.5]), np.eye(4)


def filterpy_reference(z):
    """filterpy, updating at every step with only the components present (reduced H and R)."""
    return filterpy_kalman(MODEL.F, MODEL.Q, H, R, z, X0, P0, components=True)


def _track(seed=0, T=15):
    rng = np.random.default_rng(seed)
    return np.cumsum(rng.normal(size=(T, 2)), axis=0) + rng.normal(scale=0.7, size=(T, 2))


def test_kalman_filter_updates_with_the_components_present():
    z = _track()
    z[3, 0] = np.nan                  # one component missing: the other must still update
    z[7, 1] = np.nan
    z[10] = np.nan                    # all missing: prediction only
    x_ref, P_ref = filterpy_reference(z)
    for joseph in (True, False):      # the short form (I - K H) P equals Joseph's in exact arithmetic
        res = lb.kalman_filter(MODEL.F, MODEL.Q, X0, P0, lb.LinearMeasurement(z, H, R), joseph=joseph,
                               outputs=("innovation",))
        np.testing.assert_allclose(res.mean, x_ref, rtol=0, atol=1e-9)
        np.testing.assert_allclose(res.cov, P_ref, rtol=0, atol=1e-9)
    assert np.isnan(res.innovation[3, 0]) and np.isfinite(res.innovation[3, 1])


@settings(max_examples=50, deadline=None, derandomize=True)
@given(mask=arrays(bool, (12, 2)))
def test_property_random_masks_kf_and_ekf_agree_with_filterpy(mask):
    z = np.where(mask, np.nan, _track(3, 12))
    x_ref, P_ref = filterpy_reference(z)
    kf = lb.kalman_filter(MODEL.F, MODEL.Q, X0, P0, lb.LinearMeasurement(z, H, R))
    np.testing.assert_allclose(kf.mean, x_ref, rtol=0, atol=1e-9)
    ekf = lb.extended_kalman_filter(MODEL.F, MODEL.Q, X0, P0, [lb.LinearMeasurement(z, H, R)])
    np.testing.assert_allclose(ekf.mean, x_ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ekf.cov, P_ref, rtol=0, atol=1e-9)


def test_singular_innovation_covariance_is_an_error_naming_the_step():
    z = _track()
    with pytest.raises(lb.SingularCovarianceError, match="at step 0"):
        lb.kalman_filter(MODEL.F, np.zeros((4, 4)), X0, np.zeros((4, 4)), lb.LinearMeasurement(z, H, np.zeros((2, 2))))
    anchors = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]])
    power = np.full((2, 5, 3), -60.0)
    power[:, 0] = np.nan                              # no reading at step 0: the failure comes at step 1
    for mode in ("parallel", "serial"):
        meas = lb.RssMeasurement(power, anchors, lb.PathLossModel(-40.0, 2.0, 0.0), MODEL.position_index, mode=mode)
        with pytest.raises(lb.SingularCovarianceError, match=r"at step 1 \(run index \(0,\)\)"):
            lb.extended_kalman_filter(MODEL.F, np.zeros((4, 4)), np.zeros((2, 4)) + 3.0, np.zeros((4, 4)), [meas])


def test_a_missing_component_with_zero_noise_does_not_stop_the_filter():
    """R = diag(0, 0.8), no x-spread in the prior and Q = 0: the full S = diag(0, .) is singular, but component 0
    is never heard, so every update uses component 1 alone (filterpy with the reduced H/R); an all-missing step is
    prediction only."""
    z = _track()
    z[:, 0] = np.nan
    z[4] = np.nan
    r_zero, p0, q0 = np.diag([0.0, 0.8]), np.diag([0.0, 1.0, 0.0, 1.0]), np.zeros((4, 4))
    res = lb.kalman_filter(MODEL.F, q0, X0, p0, lb.LinearMeasurement(z, H, r_zero))
    kf = KalmanFilter(dim_x=4, dim_z=2)
    kf.F, kf.Q, kf.x, kf.P = MODEL.F, q0, X0.copy(), p0.copy()
    for k, zk in enumerate(z):
        kf.predict()
        assert kf.P[0, 0] == 0.0                          # the full S really is singular at every step
        if np.isfinite(zk[1]):
            kf.update(zk[1:], R=r_zero[1:, 1:], H=H[1:])
        np.testing.assert_allclose(res.mean[k], kf.x, rtol=0, atol=1e-9)
        np.testing.assert_allclose(res.cov[k], kf.P, rtol=0, atol=1e-9)
    ekf = lb.extended_kalman_filter(MODEL.F, q0, X0, p0, [lb.LinearMeasurement(z, H, r_zero)])
    np.testing.assert_allclose(ekf.mean, res.mean, rtol=0, atol=1e-9)


def test_singular_three_component_update_names_the_offending_run():
    """Run 1's third component has zero noise and the prior zero spread; run 0 is fine: the error names run 1."""
    H3 = np.vstack([H, [[0.0, 0.0, 1.0, 0.0]]])
    R3 = np.stack([np.eye(3), np.diag([1.0, 1.0, 0.0])])
    z = np.ones((2, 4, 3))
    with pytest.raises(lb.SingularCovarianceError, match=r"at step 0 \(run index \(1,\)\)"):
        lb.kalman_filter(MODEL.F, np.zeros((4, 4)), X0, np.zeros((4, 4)), lb.LinearMeasurement(z, H3, R3))
    with pytest.raises(lb.SingularCovarianceError, match=r"at step 0 \(run index \(1,\)\)"):
        lb.extended_kalman_filter(MODEL.F, np.zeros((4, 4)), X0, np.zeros((4, 4)), [lb.LinearMeasurement(z, H3, R3)])


_READERS = np.array([[0.0, 0.0], [8.0, 0.0], [0.0, 6.0]])
_BAYES = lb.RssModel(_READERS, lb.PathLossModel(-52.0, 2.3, sigma_db=3.0, min_distance_m=0.1))


@pytest.mark.parametrize("call, message", [
    (lambda: lb.kalman_filter(MODEL.F, MODEL.Q, X0, P0, lb.LinearMeasurement(_track(), H[:, :3], R)),
     r"H must have shape \(m, 4\)"),
    (lambda: lb.kalman_filter(MODEL.F, MODEL.Q, X0, np.ones(4), lb.LinearMeasurement(_track(), H, R)),
     r"P0 must have shape \(4, 4\)"),
    (lambda: lb.extended_kalman_filter(MODEL.F, MODEL.Q, X0, P0, [lb.LinearMeasurement(_track(), H, R)], record=[20]),
     r"record must be distinct integer step indices in \[0, 15\)"),
    (lambda: lb.RssMeasurement(np.zeros((3, 3)), _READERS, lb.PathLossModel(-40.0, 2.0, sigma_db=[3.0, 4.0]), [0, 1]),
     r"channel.sigma_db must be a scalar or end in \(1,\) or \(3,\)"),
    (lambda: lb.RssModel(_READERS, lb.PathLossModel(-40.0, 2.0, 3.0)).jacobian(np.zeros((5, 3))),
     r"positions_m must have shape \(\.\.\., \*, 2\)"),
    (lambda: lb.particle_filter(np.zeros((2, 3, 3)), _BAYES, rng=np.random.default_rng(0), n_particles=10,
                                region_m=([0, 0], [8, 6]), spread_m=float("nan")), "spread_m must be finite"),
    (lambda: lb.particle_filter(np.zeros((2, 3, 3)), _BAYES, rng=np.random.default_rng(0), n_particles=10,
                                region_m=([0, 0], [8, -6])), "region_m needs upper > lower"),
    (lambda: lb.particle_filter(np.zeros((2, 3, 4)), _BAYES, rng=np.random.default_rng(0), n_particles=10,
                                region_m=([0, 0], [8, 6])), r"rss_dbm must have shape \(runs, steps, 3\)"),
    (lambda: lb.particle_filter(np.zeros((2, 3, 3)), _BAYES, rng=np.random.default_rng(0), n_particles=10,
                                region_m=([0, 0], [8, 6]), initial_position_m=[1.0, 1.0]),
     r"initial_position_m must have shape \(runs, 2\)"),
    (lambda: lb.grid_bayes_filter(np.zeros((2, 3, 3)), _BAYES, np.zeros((5, 3))),
     r"cells_m must have shape \(\.\.\., \*, 2\)"),
    (lambda: lb.grid_bayes_filter(np.zeros((2, 3, 3)), _BAYES, np.zeros((5, 2)), float("nan")),
     "spread_m must be finite"),
    (lambda: lb.grid_bayes_filter(np.zeros((2, 3, 3)), _BAYES, np.zeros((5, 2)), velocity_m=np.zeros((4, 2))),
     r"velocity_m must have shape \(2,\) or \(steps, 2\)"),
    (lambda: lb.grid_bayes_filter(np.zeros((2, 3, 3)), _BAYES, np.zeros((5, 2)), initial_belief=np.ones(4)),
     r"initial_belief must have shape \(5,\) or \(2, 5\)"),
    (lambda: _BAYES.log_likelihood(np.zeros((2, 4)), np.zeros((5, 2))), r"rss_dbm must have shape \(\.\.\., 3\)"),
    (lambda: _BAYES.log_likelihood(np.zeros((2, 3)), np.zeros((1, 5, 2))), "no silent broadcasting"),
    (lambda: _BAYES.log_likelihood(np.zeros((2, 3)), np.full((5, 2), np.nan)), "positions_m must be finite"),
    (lambda: lb.RssModel(_READERS, lb.PathLossModel(ref_power_dbm=np.zeros((2, 4, 3)), path_loss_exp=2.3, sigma_db=5.0),
                                per_step_channel=True).log_likelihood(
        np.zeros((2, 3)), np.zeros((5, 2)), step=-1), r"step must be an integer in \[0, 4\)"),
    (lambda: lb.systematic_resample([0.5, -0.1, 0.6], 0.3), "weights must be non-negative"),
    (lambda: lb.systematic_resample([[0.5, 0.5]], [0.3, 0.2]), r"uniforms must be draws in \[0, 1\)"),
    (lambda: lb.reflect_into_box([[np.nan, 1.0]], [0, 0], [5, 5]), "position_m must be finite"),
    (lambda: MODEL.state_from(np.zeros((3, 3))), r"position must have shape \(\.\.\., 2\)"),
])
def test_bad_input_names_the_argument_more(call, message):
    with pytest.raises(ValueError, match=message):
        call()


@pytest.mark.parametrize("call, message", [
    (lambda: lb.kalman_filter(MODEL.F, np.ones(4), X0, P0, lb.LinearMeasurement(_track(), H, R)),
     r"Q must have shape \(4, 4\)"),
    (lambda: lb.kalman_filter(MODEL.F, MODEL.Q, X0, P0, lb.LinearMeasurement(_track(), H, np.ones(2))),
     r"R must have shape \(2, 2\)"),
    (lambda: lb.kalman_filter(MODEL.F, MODEL.Q, X0[:3], P0, lb.LinearMeasurement(_track(), H, R)), "x0 must end in"),
    (lambda: lb.kalman_filter(MODEL.F * np.nan, MODEL.Q, X0, P0, lb.LinearMeasurement(_track(), H, R)),
     "F must be finite"),
    (lambda: lb.kalman_filter(MODEL.F, MODEL.Q, X0, P0, lb.LinearMeasurement(np.full((3, 2), np.inf), H, R)),
     "z must be finite"),
    (lambda: lb.extended_kalman_filter(MODEL.F, np.ones(4), X0, P0, [lb.LinearMeasurement(_track(), H, R)]),
     r"Q must have shape \(4, 4\)"),
    (lambda: lb.LinearMeasurement(_track(), H[:1], R), "H must have 2 rows"),
    (lambda: lb.RssMeasurement(np.zeros((3, 4)), np.zeros((3, 2)), lb.PathLossModel(-40.0, 2.0), [0, 1]),
     "has 4 anchors"),
    (lambda: lb.constant_velocity(float("nan"), 1.0), "dt_s must be finite"),
    (lambda: lb.constant_velocity(1.0, float("nan")), "process noise q must be finite"),
    (lambda: lb.grid_transition_matrix(np.zeros((3, 2)), float("nan")), "spread_m must be finite"),
    (lambda: lb.RssModel(np.zeros((3, 2)), lb.PathLossModel(ref_power_dbm=np.nan, path_loss_exp=2.3, sigma_db=5.0)),
     "ref_power_dbm must be finite"),
    (lambda: lb.RssModel(np.zeros((3, 2)), lb.PathLossModel(-52.0, path_loss_exp=[2.0, np.nan, 2.0], sigma_db=5.0)),
     "path_loss_exp must be finite"),
    (lambda: lb.RssModel(np.zeros((3, 2)), lb.PathLossModel(-52.0, 2.3, sigma_db=-1.0)),
     "sigma_db must be (a )?non-negative"),
    (lambda: lb.RssModel(np.ones((3, 2)), lb.PathLossModel(-52.0, 2.3, sigma_db=0.0)).log_likelihood(
        np.zeros((1, 3)), np.zeros((2, 2))),
     "the likelihood needs sigma_db > 0"),
    (lambda: lb.grid_bayes_filter(np.zeros((2, 3, 4)), lb.RssModel(np.zeros((3, 2)), lb.PathLossModel(-52.0, 2.3, 5.0)),
                                  np.zeros((5, 2))),
     r"rss_dbm must have shape \(runs, steps, 3\)"),
    (lambda: lb.simulate_states(MODEL.F, np.diag([1.0, 1.0, -1.0, 1.0]), X0, 3, rng=np.random.default_rng(0)),
     "Q must be positive semi-definite"),
    (lambda: lb.posterior_crlb(np.eye(4), MODEL.F, np.ones(4), np.zeros((3, 4, 4))), r"Q must have shape"),
])
def test_bad_input_names_the_argument(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_likelihood_leaves_out_a_silent_reader_only():
    readers = np.array([[0.0, 0.0], [8.0, 0.0], [0.0, 6.0], [8.0, 6.0]])
    model = lb.RssModel(readers,
                        lb.PathLossModel(ref_power_dbm=[-50.0, -52.0, -51.0, -49.0], path_loss_exp=2.2, sigma_db=4.0))
    cells = np.array([[1.0, 1.0], [4.0, 3.0], [7.0, 5.0]])
    rss = np.array([[-60.0, np.nan, -63.0, -65.0]])
    reduced = lb.RssModel(readers[[0, 2, 3]], lb.PathLossModel(ref_power_dbm=[-50.0, -51.0, -49.0], path_loss_exp=2.2,
                                                               sigma_db=4.0))
    np.testing.assert_allclose(model.log_likelihood(rss, cells), reduced.log_likelihood(rss[:, [0, 2, 3]], cells),
                               rtol=1e-12)
    flat = model.log_likelihood(np.full((1, 4), np.nan), cells)
    np.testing.assert_array_equal(flat, np.zeros((1, 3)))            # nobody heard: flat, a prediction only


def test_uniform_proposal_starts_from_equal_weights():
    """spread_m = inf draws new particles: their weights must be this step's likelihood alone."""
    readers = np.array([[0.0, 0.0], [8.0, 0.0], [0.0, 6.0]])
    model = lb.RssModel(readers, lb.PathLossModel(-52.0, 2.3, sigma_db=3.0, min_distance_m=0.1))
    rng = np.random.default_rng(5)
    rss = model.mean_rss_dbm(np.array([[2.0, 3.0]]))[0, 0] + rng.normal(scale=3.0, size=(2, 4, 3))
    res = lb.particle_filter(rss, model, rng=np.random.default_rng(1), n_particles=200, region_m=([0, 0], [8, 6]),
                             spread_m=np.inf, resample_threshold=1e-6)       # never resamples
    assert not res.resampled.any()
    loglik = model.log_likelihood(rss[:, -1], res.particles_m, 3)
    expected = np.exp(loglik - loglik.max(axis=1, keepdims=True))
    np.testing.assert_allclose(res.weights, expected / expected.sum(axis=1, keepdims=True), rtol=1e-9)


# ---------------------------------------------------------------------------------------------------------------
# covariances checked up front, zero steps, run axes on F, H and Q
# ---------------------------------------------------------------------------------------------------------------
ANCHORS = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
CHANNEL = lb.PathLossModel(-40.0, 2.0, 2.0)


def _rss(T=6):
    rng = np.random.default_rng(4)
    pos = 5 + np.cumsum(0.2 * rng.standard_normal((T, 2)), axis=0)
    return CHANNEL.sample_rss_dbm(np.linalg.norm(pos[:, None] - ANCHORS, axis=-1), rng=rng)


def _every_filter(Q=MODEL.Q, R_=R, P=P0):
    """Each filter with the given Q, R and P0 (the RSS filters take R through a LinearMeasurement stream)."""
    z = _track()
    rss = lb.RssMeasurement(_rss(z.shape[0]), ANCHORS, CHANNEL, MODEL.position_index)
    yield lambda: lb.kalman_filter(MODEL.F, Q, X0, P, lb.LinearMeasurement(z, H, R_))
    for flt in (lb.extended_kalman_filter, lb.unscented_kalman_filter):
        yield lambda flt=flt: flt(MODEL.F, Q, X0, P, [lb.LinearMeasurement(z, H, R_), rss])


NOT_SYMMETRIC = np.array([[0.5, 0.3], [0.1, 0.8]])
Q_NOT_PSD = MODEL.Q - 0.2 * np.eye(4)          # a negative eigenvalue, still symmetric


@pytest.mark.parametrize("kw, message", [
    (dict(R_=NOT_SYMMETRIC), r"R must be symmetric"),
    (dict(P=np.eye(4) + np.triu(np.ones((4, 4)), 1)), r"P0 must be symmetric"),
    (dict(Q=MODEL.Q + 0.1 * np.triu(np.ones((4, 4)), 1)), r"Q must be symmetric"),
    (dict(Q=Q_NOT_PSD), r"Q must be positive semi-definite"),
    (dict(P=np.diag([1.0, -1.0, 1.0, 1.0])), r"P0 must be positive semi-definite.*-1"),
    (dict(R_=np.array([[1.0, 2.0], [2.0, 1.0]])), r"R must be positive semi-definite.*-1"),
])
def test_covariances_are_checked_up_front_naming_the_argument(kw, message):
    """A non-symmetric R or P0 used to be accepted; a Q that is not positive semi-definite surfaced steps later as an
    innovation-covariance error blaming R. Each is now refused before the first step, naming the argument."""
    for call in _every_filter(**kw):
        with pytest.raises(ValueError, match=message):
            call()


def test_round_off_asymmetry_is_accepted():
    P = MODEL.F @ np.diag([1.0, 2.0, 0.3, 0.4]) @ MODEL.F.T      # symmetric to round-off only
    P[0, 1] *= 1 + 1e-14
    for call in _every_filter(P=P, Q=MODEL.G @ MODEL.G.T * 0.05):      # rank 2: eigenvalues 0 to round-off
        call()


def test_kalman_filter_with_zero_steps_returns_an_empty_result():
    """Used to end in numpy's "cannot reshape array of size 0"."""
    for z in (np.empty((0, 2)), np.empty((3, 0, 2))):
        res = lb.kalman_filter(MODEL.F, MODEL.Q, X0, P0, lb.LinearMeasurement(z, H, R), outputs=("innovation",))
        batch = z.shape[:-2]
        assert res.mean.shape == batch + (0, 4) and res.cov.shape == batch + (0, 4, 4)
        assert res.innovation.shape == batch + (0, 2) and res.nis.shape == batch + (0,)
        assert res.diverged.shape == batch and res.n_diverged == 0
    for flt in (lb.extended_kalman_filter, lb.unscented_kalman_filter):
        res = flt(MODEL.F, MODEL.Q, X0, P0, [lb.LinearMeasurement(np.empty((3, 0, 2)), H, R)])
        assert res.mean.shape == (3, 0, 4) and res.diverged.shape == (3,) and res.n_diverged == 0


def _per_run_filterpy(z, Fs, Hs, Qs, x0, P):
    """filterpy's KalmanFilter, one filter per run with that run's F, H and Q."""
    return filterpy_kalman(Fs, Qs, Hs, R, z, x0, P, per_run=("F", "Q", "H"))[0]


def test_run_axes_on_F_H_and_Q_equal_one_filter_per_run():
    """Batched F (and H in kalman_filter) used to crash with a raw broadcast error although the docstrings allow run
    axes; the EKF and UKF crashed with a batched Q when x0, P0 and z carried none. Each run now equals filterpy with
    that run's matrices."""
    runs = 3
    Fs = np.stack([lb.constant_velocity(dt, 0.05).F for dt in (0.5, 1.0, 2.0)])
    Qs = np.stack([lb.constant_velocity(1.0, q).Q for q in (0.01, 0.1, 1.0)])
    Hs = np.stack([H, 2.0 * H, np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 1.0]])])
    z = _track(5, 10)
    zb = np.broadcast_to(z, (runs,) + z.shape)
    ref = _per_run_filterpy(zb, Fs, Hs, Qs, X0, P0)
    res = lb.kalman_filter(Fs, Qs, X0, P0, lb.LinearMeasurement(z, Hs, R))                   # run axes on F, H, Q only
    np.testing.assert_allclose(res.mean, ref, rtol=0, atol=1e-9)
    Hb = np.broadcast_to(H, (runs,) + H.shape)
    ref = _per_run_filterpy(zb, Fs, Hb, Qs, X0, P0)
    for flt in (lb.extended_kalman_filter, lb.unscented_kalman_filter):
        out = flt(Fs, Qs, X0, P0, [lb.LinearMeasurement(z, H, R)])
        np.testing.assert_allclose(out.mean, ref, rtol=0, atol=1e-8)
        out = flt(MODEL.F, Qs, X0, P0, [lb.LinearMeasurement(z, H, R)])  # a batched Q alone
        np.testing.assert_allclose(out.mean, _per_run_filterpy(zb, [MODEL.F] * runs, Hb, Qs, X0, P0), rtol=0, atol=1e-8)


def test_run_axes_that_do_not_broadcast_are_named():
    with pytest.raises(ValueError, match=r"run \(batch\) axes.*z \(3,\).*Q \(2,\)"):
        lb.kalman_filter(MODEL.F, np.stack([MODEL.Q] * 2), X0, P0, lb.LinearMeasurement(np.zeros((3, 5, 2)), H, R))


# ---------------------------------------------------------------------------------------------------------------
# Found in review: the covariance check's tolerance follows the input's precision and each variance's own scale
# ---------------------------------------------------------------------------------------------------------------
def _float32_sample_covariance(seed=0):
    """The sample covariance, in float32, of two perfectly correlated components: singular, with a round-off
    eigenvalue of either sign at float32 precision (about 6e-8 relative)."""
    e = np.random.default_rng(seed).normal(size=(50, 1)).astype(np.float32)
    X = np.hstack([e, np.float32(2.3) * e])
    Xc = X - X.mean(0)
    return Xc.T @ Xc / np.float32(49)


def test_a_singular_float32_sample_covariance_is_accepted():
    """Refused as 'R must be positive semi-definite, -1.12e-07': the tolerance, 1e-8 of the largest entry, was below
    float32 precision. Each filter now runs, and the KF equals filterpy given the same (float64) values."""
    R32 = _float32_sample_covariance()
    assert R32.dtype == np.float32 and np.linalg.eigvalsh(R32.astype(float))[0] < 0      # the case reported
    R64 = R32.astype(float)
    z = _track()
    ref, _ = filterpy_kalman(MODEL.F, MODEL.Q, H, R64, z, X0, P0)
    res = lb.kalman_filter(MODEL.F, MODEL.Q, X0, P0, lb.LinearMeasurement(z, H, R32))
    np.testing.assert_allclose(res.mean, ref, rtol=0, atol=1e-9)
    for call in _every_filter(R_=R32):
        assert np.all(np.isfinite(call().mean))
    for call in _every_filter(Q=np.kron(np.eye(2, dtype=np.float32), R32) * np.float32(0.01)):     # a float32 Q alike
        assert np.all(np.isfinite(call().mean))
    # float32 precision is no licence for a real negative eigenvalue
    with pytest.raises(ValueError, match="R must be positive semi-definite"):
        lb.kalman_filter(MODEL.F, MODEL.Q, X0, P0,
                         lb.LinearMeasurement(z, H, R32 - np.float32(1e-3) * np.eye(2, dtype=np.float32)))


@pytest.mark.parametrize("P, message", [
    (np.diag([1e8, 1e8, -0.1, -0.1]), r"P0 must be positive semi-definite.*P0\[2, 2\] = -0.1"),   # a sign typo
    (np.diag([1e8, 1.0, -1e-3, 1.0]), r"P0 must be positive semi-definite.*P0\[2, 2\] = -0.001"),
    (np.block([[np.diag([1e8, 1e8]), np.zeros((2, 2))], [np.zeros((2, 2)), np.array([[0.1, 0.2], [0.2, 0.1]])]]),
     r"P0 must be positive semi-definite.*-0.1"),                  # |correlation| 2 in a small block
    (np.array([[1e8, 0, 1e-3, 0], [0, 1e8, 0, 0], [1e-3, 0, 0, 0], [0, 0, 0, 1.0]]),   # a zero variance, a covariance
     r"P0 must be positive semi-definite.*variance P0\[2, 2\] is 0 but its covariance P0\[0, 2\]"),
])
def test_a_covariance_that_is_not_positive_semi_definite_is_refused_at_any_scale(P, message):
    """The tolerance was relative to the largest entry, so a diffuse prior (1e8) hid a negative variance of -0.1 or a
    small block that is not a covariance: accepted, the filter ran on. The test is now made on each entry's own scale
    (the correlation-scaled matrix D^-1/2 A D^-1/2, D = diag(A)), so a negative variance is refused at any scale."""
    for call in _every_filter(P=P):
        with pytest.raises(ValueError, match=message):
            call()
    for call in _every_filter(Q=P * 1e-6):
        with pytest.raises(ValueError, match=message.replace("P0", "Q").replace(r"-0.1", "-1e-07")
                           .replace("-0.001", "-1e-09")):
            call()


def test_badly_scaled_rank_deficient_covariances_are_accepted():
    """Round-off is judged on each variance's scale, so genuine covariances whose variances span 16 orders of magnitude,
    rank-deficient (eigenvalues 0 to round-off, of either sign), in float64 and float32, are accepted."""
    rng = np.random.default_rng(6)
    for trial in range(20):
        B = np.diag([1e4, 1.0, 1e-4, 1e-4]) @ rng.normal(size=(4, 2))            # rank 2
        P = B @ B.T
        assert np.linalg.eigvalsh(P / np.sqrt(np.outer(np.diag(P), np.diag(P))))[0] < 1e-12
        for covariance in (P, P.astype(np.float32), (P @ np.eye(4)).T):
            lb.kalman_filter(MODEL.F, MODEL.Q, X0, covariance, lb.LinearMeasurement(_track(), H, R))
        lb.extended_kalman_filter(MODEL.F, B @ B.T * 1e-3, X0, P0, [lb.LinearMeasurement(_track(), H, R)])
    P = np.diag([1e8, 1e8, 0.0, 0.0])                                            # zero variances, zero covariances
    lb.kalman_filter(MODEL.F, MODEL.Q, X0, P, lb.LinearMeasurement(_track(), H, R))


def _overflowing_filters():
    """Every Kalman-family path, run 1 given readings of 1.5e308 (m, or dBm) from step 2 on: the state overflows."""
    rng = np.random.default_rng(9)
    z = np.cumsum(rng.normal(size=(3, 8, 2)), axis=1)
    z[1, 2:] = 1.5e308
    uneven = z.copy()
    uneven[0, 1, 1] = np.nan                             # a missing pattern that differs between runs: batched paths
    power = CHANNEL.sample_rss_dbm(np.linalg.norm(5 + rng.normal(size=(3, 8, 1, 2)) - ANCHORS, axis=-1), rng=rng)
    power[1, 2:] = 1.5e308
    x0 = MODEL.state_from(np.array([5.0, 5.0]))
    yield "kalman_filter (one covariance)", lambda: lb.kalman_filter(MODEL.F, MODEL.Q, x0, P0,
                                                                     lb.LinearMeasurement(z, H, R))
    yield "kalman_filter (batched)", lambda: lb.kalman_filter(MODEL.F, MODEL.Q, x0, P0,
                                                              lb.LinearMeasurement(uneven, H, R))
    diag = np.diag(np.diag(R))
    for flt in (lb.extended_kalman_filter, lb.unscented_kalman_filter):
        kw = {} if flt is lb.extended_kalman_filter else dict(alpha=1.0)
        yield f"{flt.__name__} linear", lambda flt=flt, kw=kw: flt(MODEL.F, MODEL.Q, x0, P0,
                                                                   [lb.LinearMeasurement(z, H, R)], **kw)
        yield f"{flt.__name__} linear batched", lambda flt=flt, kw=kw: flt(MODEL.F, MODEL.Q, x0, P0,
                                                                           [lb.LinearMeasurement(uneven, H, R)], **kw)
        yield f"{flt.__name__} linear serial", lambda flt=flt, kw=kw: flt(
            MODEL.F, MODEL.Q, x0, P0, [lb.LinearMeasurement(uneven, H, diag, mode="serial")], **kw)
        for mode in ("parallel", "serial"):
            yield f"{flt.__name__} RSS {mode}", lambda flt=flt, kw=kw, mode=mode: flt(
                MODEL.F, MODEL.Q, x0, P0, [lb.RssMeasurement(power, ANCHORS, CHANNEL, MODEL.position_index, mode=mode)],
                **kw)


@pytest.mark.parametrize("name, call", list(_overflowing_filters()), ids=[n for n, _ in _overflowing_filters()])
def test_an_overflowing_reading_is_named_as_an_overflow_not_as_a_bad_noise_covariance(name, call):
    """One run's overflow stops the batch (the Kalman family's documented exception to batch isolation), but the
    message used to blame the innovation covariance and R ('the measurement noise (R, sigma_db) must be positive';
    the UKF's 'unscented innovation covariance ... is singular'). It now names the overflow of the reading or state,
    the step and the run."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)          # numpy's overflow warnings on the way
        with pytest.raises(lb.SingularCovarianceError) as info:
            call()
    text = str(info.value)
    assert re.search(r"overflow", text) and "reading" in text, text
    assert re.search(r"at step [2-7]\b.*\(run index \(1,\)\)", text), text
    assert "must be positive" not in text and "innovation covariance" not in text, text
