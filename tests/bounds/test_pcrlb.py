"""Posterior CRLB: Stone Soup's PCRBMetric and its published test numbers, the KF covariance, and the
equivalence of the Tichavsky and Riccati forms."""
from datetime import datetime, timedelta

import numpy as np
import pytest
from stonesoup.base import Property
from stonesoup.metricgenerator.pcrbmetric import PCRBMetric
from stonesoup.models.measurement.linear import LinearGaussian
from stonesoup.models.measurement.nonlinear import NonLinearGaussianMeasurement
from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel, ConstantVelocity
from stonesoup.types.array import CovarianceMatrix, StateVector, StateVectors
from stonesoup.types.groundtruth import GroundTruthPath, GroundTruthState
from stonesoup.types.state import GaussianState

import locbook as lb
from locbook.bounds.pcrlb import PCRLB_FORMS

# Stone Soup's own PCRB test (stonesoup/metricgenerator/tests/test_pcrbmetric.py): two constant-velocity axes,
# q = 0.05, position measured with R = diag(5, 5), prior diag(5, 10, 5, 10), 21 steps of 1 s
STONESOUP_POSITION_BOUND = [3.16227766, 2.73899281, 2.70945734, 2.57092567, 2.41880754, 2.28452324, 2.1740353,
                            2.08692291, 2.02108617, 1.97375227, 1.94170446, 1.92149958, 1.90979313, 1.90367124,
                            1.90086597, 1.89980342, 1.8995155, 1.899484, 1.89947979, 1.89943311, 1.89934607]


def _groundtruth(states):
    now = datetime(2026, 1, 1)
    return GroundTruthPath([GroundTruthState(StateVector(s), timestamp=now + timedelta(seconds=i))
                            for i, s in enumerate(states)])


@pytest.mark.parametrize("form", PCRLB_FORMS)
def test_stonesoup_pcrb_scenario(form):
    model = lb.constant_velocity(1.0, 0.05, layout="axis_major", noise="continuous")
    ss_transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(0.05), ConstantVelocity(0.05)])
    np.testing.assert_allclose(model.Q, ss_transition.covar(time_interval=timedelta(seconds=1)), atol=1e-15)
    H = model.position_measurement_matrix()
    jz = np.broadcast_to(lb.linear_measurement_information(H, np.diag([5.0, 5.0])), (20, 4, 4))
    info = lb.posterior_crlb(np.linalg.inv(np.diag([5.0, 10.0, 5.0, 10.0])), model.F, model.Q, jz, form=form)
    bound = lb.position_bound_m(info, model.position_index)
    np.testing.assert_allclose(bound, STONESOUP_POSITION_BOUND, rtol=0, atol=5e-9)
    # and the metric itself on the same inputs
    truth = _groundtruth([[i, 1.0, i, 1.0] for i in range(21)])
    measurement = LinearGaussian(ndim_state=4, mapping=[0, 2], noise_covar=CovarianceMatrix(np.diag([5.0, 5.0])))
    metric = PCRBMetric._compute_pcrb_single(
        GaussianState(StateVector([0, 0, 0, 0]), CovarianceMatrix(np.diag([5.0, 10.0, 5.0, 10.0]))), ss_transition,
        measurement, truth, StateVectors([StateVector([[-10], [10]])]), 1.0, [0, 2], None)
    np.testing.assert_allclose(np.linalg.inv(info), metric["inverse_j"], rtol=1e-10, atol=1e-12)


class _RssToAnchor(NonLinearGaussianMeasurement):
    """RSS from one anchor (Dogan Eq. (2.2)), written from the model alone; Stone Soup differentiates it numerically."""

    translation_offset: StateVector = Property(default=None, doc="anchor position")
    ref_power_dbm: float = Property(default=-48.0)
    path_loss_exp: float = Property(default=3.0)

    @property
    def ndim_meas(self):
        return 1

    def function(self, state, noise=False, **kwargs):
        p = np.asarray(state.state_vector, float)[list(self.mapping), :]
        d = np.sqrt(np.sum((p - np.asarray(self.translation_offset, float).reshape(2, 1)) ** 2, axis=0))
        # Stone Soup's numerical Jacobian evaluates many perturbed states (columns) in one call
        return StateVectors(np.atleast_2d(self.ref_power_dbm - 10.0 * self.path_loss_exp * np.log10(d)))


def test_truth_conditioned_rss_bound_equals_stonesoup():
    # Dogan's CA model (axis-major [x, vx, ax, y, vy, ay]) with the full-rank per-step Q of Eq. (3.24)
    model = lb.constant_acceleration(0.05, 0.0, layout="axis_major")
    Q = 2.3e-5 * np.eye(6)
    anchors = np.array([[0.0, 0.0], [7.6, 0.0], [7.6, 9.2], [0.0, 9.2]])
    sigma, steps = 6.0, 40
    truth = np.zeros((steps + 1, 6))
    truth[:, 0], truth[:, 3] = np.linspace(1.0, 3.0, steps + 1), np.linspace(1.5, 6.0, steps + 1)
    prior = np.diag([4.9, 0.0065, 0.00023, 4.9, 0.0065, 0.00023])
    jz = lb.rss_state_information(truth[1:], lb.RssModel(anchors, lb.PathLossModel(0.0, 3.0, sigma)),
                                  model.position_index)
    info = lb.posterior_crlb(np.linalg.inv(prior), model.F, Q, jz)

    class _CA:            # a transition model Stone Soup can use: our F and Q
        ndim_state = 6

        def jacobian(self, state, **kwargs):
            return model.F

        def covar(self, **kwargs):
            return Q

    measurement = _RssToAnchor(ndim_state=6, mapping=(0, 3), noise_covar=CovarianceMatrix([[sigma**2]]))
    metric = PCRBMetric._compute_pcrb_single(
        GaussianState(StateVector(np.zeros(6)), CovarianceMatrix(prior)), _CA(), measurement, _groundtruth(truth),
        StateVectors([StateVector(a) for a in anchors]), 1.0, [0, 3], None)
    np.testing.assert_allclose(lb.position_bound_m(info, model.position_index), metric["position_RMSE"], rtol=1e-6)


def test_tichavsky_form_equals_riccati_form_and_the_kf_covariance():
    rng = np.random.default_rng(0)
    model = lb.constant_acceleration(0.05, 0.0, layout="axis_major")
    Q = 2.3e-5 * np.eye(6)
    H = np.zeros((2, 6))
    H[0, 2] = H[1, 5] = 1.0                                             # accelerometer, Dogan Eq. (3.18)
    steps = 60
    jz = np.zeros((steps, 6, 6))
    jz[:] = lb.linear_measurement_information(H, 0.0152**2 * np.eye(2))
    Hp = model.position_measurement_matrix()
    jz[9::10] += lb.linear_measurement_information(Hp, np.diag([4.9, 4.9]))   # MLE fixes at every 10th step
    P0 = np.diag([4.9, 0.0065, 0.00023, 4.9, 0.0065, 0.00023])
    a = lb.posterior_crlb(np.linalg.inv(P0), model.F, Q, jz, form="tichavsky")
    b = lb.posterior_crlb(np.linalg.inv(P0), model.F, Q, jz, form="riccati")
    np.testing.assert_allclose(a, b, rtol=1e-8)
    # linear-Gaussian: the bound is the KF's own (data-independent) covariance; both sensors at every step
    Hs = np.vstack([H, Hp])
    R = np.diag([0.0152**2, 0.0152**2, 4.9, 4.9])
    info = lb.posterior_crlb(np.linalg.inv(P0), model.F, Q, np.broadcast_to(lb.linear_measurement_information(Hs, R),
                                                                            (steps, 6, 6)))
    kf = lb.kalman_filter(model.F, Q, np.zeros(6), P0, lb.LinearMeasurement(rng.normal(size=(steps, 4)), Hs, R))
    np.testing.assert_allclose(np.linalg.inv(info[1:]), kf.cov, rtol=1e-7, atol=1e-14)


def test_rss_information_regularisations():
    idx = np.array([0, 3])
    state = np.zeros(6)
    state[[0, 3]] = [0.3, 0.4]                                          # 0.5 m from the anchor at the origin
    anchors = np.array([[0.0, 0.0]])

    def rss(min_distance_m=0.0, height_m=None):        # the anchor, height_m above the tag
        a = anchors if height_m is None else np.column_stack([anchors, [height_m]])
        return lb.RssModel(a, lb.PathLossModel(0.0, 3.0, 6.0, min_distance_m=min_distance_m),
                           tag_height_m=None if height_m is None else 0.0)

    beta2 = (10 * 3.0 / (6.0 * np.log(10))) ** 2
    plain = lb.rss_state_information(state, rss(), idx)
    u = np.array([0.6, 0.8])
    np.testing.assert_allclose(plain[np.ix_(idx, idx)], beta2 * np.outer(u, u) / 0.25)
    assert np.count_nonzero(plain) == 4
    # the clamped model's mean is flat within d_min (its derivative is 0: a reading there carries no information);
    # outside d_min the clamp changes nothing
    clipped = lb.rss_state_information(state, rss(1.0), idx)
    np.testing.assert_array_equal(clipped, 0.0)
    channel = lb.PathLossModel(-40.0, 3.0, min_distance_m=1.0)
    eps = 1e-6
    for e in np.eye(2) * eps:
        assert (channel.mean_rss_dbm(np.linalg.norm(state[idx] + e))
                == channel.mean_rss_dbm(np.linalg.norm(state[idx] - e)))
    np.testing.assert_array_equal(lb.rss_state_information(state, rss(0.4), idx), plain)
    np.testing.assert_array_equal(lb.rss_state_information(np.zeros(6), rss(1.0), idx), 0.0)
    lifted = lb.rss_state_information(state, rss(height_m=1.2), idx)
    d2 = 0.25 + 1.44
    np.testing.assert_allclose(lifted[np.ix_(idx, idx)], beta2 * np.outer([0.3, 0.4], [0.3, 0.4]) / d2**2)
    with pytest.raises(lb.DegenerateGeometryError, match="undefined at an anchor"):
        lb.rss_state_information(np.zeros(6), rss(), idx)
