"""RSS filters with receivers that move or differ per run, and the variance inflation for uncertain receiver
positions (Palvai 2008, Eq. (4.28), Sec. 4.4's sigma_3; the inflation is our extension)."""
import numpy as np
import pytest

import locbook as lb

CH = lb.PathLossModel(-20.0, 4.0, 6.0)


def _static(dim=3):
    """A static target: identity motion with a small random-walk noise (Palvai Eq. (3.5))."""
    return np.eye(dim), 1.0 * np.eye(dim)


@pytest.mark.parametrize("run", [lb.extended_kalman_filter, lb.unscented_kalman_filter])
@pytest.mark.parametrize("mode", ["parallel", "serial"])
def test_per_run_receivers_equal_runs_one_by_one(run, mode):
    rng = np.random.default_rng(0)
    R, T, m = 3, 6, 4
    receivers = rng.uniform(0, 50, (R, T, m, 3))
    target = np.array([25.0, 20.0, 30.0])
    z = CH.sample_rss_dbm(np.linalg.norm(receivers - target, axis=-1), rng=rng)
    z[1, 2, 3] = np.nan
    F, Q = _static()
    x0, P0 = np.full(3, 25.0), 100.0 * np.eye(3)
    batched = run(F, Q, x0, P0, [lb.RssMeasurement(z, lb.per_step(receivers), CH, np.arange(3), mode=mode)])
    for r in range(R):
        one = run(F, Q, x0, P0, [lb.RssMeasurement(z[r], lb.per_step(receivers[r]), CH, np.arange(3), mode=mode)])
        np.testing.assert_allclose(batched.mean[r], one.mean, atol=1e-9)
        np.testing.assert_allclose(batched.cov[r], one.cov, atol=1e-9)


def test_receivers_repeated_over_steps_equal_fixed_anchors():
    rng = np.random.default_rng(1)
    anchors = rng.uniform(0, 50, (5, 3))
    z = CH.sample_rss_dbm(np.broadcast_to(np.linalg.norm(anchors - 20.0, axis=-1), (2, 7, 5)), rng=rng)
    F, Q = _static()
    fixed = lb.extended_kalman_filter(F, Q, np.full(3, 25.0), 100 * np.eye(3),
                                      [lb.RssMeasurement(z, anchors, CH, np.arange(3))])
    per_step = lb.extended_kalman_filter(F, Q, np.full(3, 25.0), 100 * np.eye(3),
                                         [lb.RssMeasurement(z, lb.per_step(np.broadcast_to(anchors, (2, 7, 5, 3))), CH,
                                                            np.arange(3))])
    np.testing.assert_allclose(per_step.mean, fixed.mean, atol=1e-12)


def test_variance_inflation_is_the_first_order_propagation_of_the_receiver_error():
    """One EKF update with sigma_3 = 5 m equals a plain update whose R is sigma^2 + (10 n / ln 10)^2 sigma_3^2 / d^2
    at the predicted position; and that R matches the Monte-Carlo variance of the predicted power."""
    rng = np.random.default_rng(2)
    s = np.array([[10.0, 40.0, 5.0], [45.0, 10.0, 20.0]])
    x0, P0 = np.array([25.0, 25.0, 25.0]), 50.0 * np.eye(3)
    z = np.array([[-70.0, -72.0]])
    sig3 = 5.0
    inflated = lb.extended_kalman_filter(np.eye(3), np.zeros((3, 3)), x0, P0,
                                         [lb.RssMeasurement(z, s, CH, np.arange(3), anchor_sigma_m=sig3)],
                                         predict_first=False)
    d = np.linalg.norm(x0 - s, axis=-1)
    var = CH.sigma_db**2 + (40 / np.log(10)) ** 2 * sig3**2 / d**2
    H = -(40 / np.log(10)) * (x0 - s) / d[:, None] ** 2
    h = -20 - 40 * np.log10(d)
    S = H @ P0 @ H.T + np.diag(var)
    K = P0 @ H.T @ np.linalg.inv(S)
    np.testing.assert_allclose(inflated.mean[0], x0 + K @ (z[0] - h), atol=1e-9)
    # the inflation term against Monte Carlo: variance of 40 log10 |x - (s + e)|, e ~ N(0, sig3^2 I)
    e = sig3 * rng.standard_normal((200_000, 3))
    mc = np.var(40 * np.log10(np.linalg.norm(x0 - (s[0] + e), axis=-1)))
    assert mc == pytest.approx((40 / np.log(10)) ** 2 * sig3**2 / d[0] ** 2, rel=0.05)
