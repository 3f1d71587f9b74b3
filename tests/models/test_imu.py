"""Heading motion model, waypoint trajectories, IMU models and dead reckoning, fusion of two estimates, and the
exponent estimators of Gudipati 2017, each against closed forms or an independent computation."""
import cvxpy as cp
import numpy as np
import pytest

import locbook as lb


def test_heading_model_blocks_are_eqs_3_2_and_3_3():
    dt, q, qa = 0.4, 0.3, 0.02
    m = lb.HeadingKinematicModel(dt, q, qa)
    A = np.array([[1, 0, dt, 0, dt**2 / 2, 0], [0, 1, 0, dt, 0, dt**2 / 2], [0, 0, 1, 0, dt, 0],
                  [0, 0, 0, 1, 0, dt], [0, 0, 0, 0, 1, 0], [0, 0, 0, 0, 0, 1]])
    Q = q * np.array([[dt**4 / 4, 0, dt**3 / 2, 0, dt**2 / 2, 0], [0, dt**4 / 4, 0, dt**3 / 2, 0, dt**2 / 2],
                      [dt**3 / 2, 0, dt**2, 0, dt, 0], [0, dt**3 / 2, 0, dt**2, 0, dt],
                      [dt**2 / 2, 0, dt, 0, 1, 0], [0, dt**2 / 2, 0, dt, 0, 1]])
    np.testing.assert_allclose(m.F[:6, :6], A, atol=1e-15)
    np.testing.assert_allclose(m.Q[:6, :6], Q, atol=1e-15)
    np.testing.assert_allclose(m.F[6:, 6:], [[1, dt], [0, 1]])
    np.testing.assert_allclose(m.Q[6:, 6:], qa * np.array([[dt**2, dt], [dt, 1]]))
    assert not np.any(m.F[:6, 6:]) and not np.any(m.Q[:6, 6:])
    lit = lb.HeadingKinematicModel(dt, q, qa, heading="literal_gudipati2017")
    np.testing.assert_allclose(lit.F[6:, 6:], np.eye(2))
    np.testing.assert_allclose(lit.Q[6:, 6:], qa * dt * np.eye(2))


U_PATH = [[2.0, 2.0], [28.0, 2.0], [28.0, 8.0], [2.0, 8.0]]


def test_u_path_trajectory_geometry_and_derivatives():
    r = 1.0
    tr = lb.waypoint_trajectory(U_PATH, speed_m_s=0.8, accel_m_s2=0.5, dt_s=0.005, turn_radius_m=r)
    # length: legs 26 + 6 + 26 minus two tangent cuts of r per corner, plus two quarter circles
    assert tr.length_m == pytest.approx(58 - 4 * r + np.pi * r, abs=1e-9)
    np.testing.assert_allclose(tr.position_m[0], U_PATH[0], atol=1e-12)
    np.testing.assert_allclose(tr.position_m[-1], U_PATH[-1], atol=1e-9)
    np.testing.assert_allclose(tr.velocity_m_s[[0, -1]], 0.0, atol=1e-12)
    assert tr.heading_rad[-1] == pytest.approx(np.pi)
    # derivatives where they are continuous (away from the jumps of the acceleration at ramp and arc ends)
    t = tr.time_s
    for value, deriv in ((tr.position_m, tr.velocity_m_s), (tr.velocity_m_s, tr.acceleration_m_s2),
                         (tr.heading_rad[:, None], tr.yaw_rate_rad_s[:, None])):
        num = np.gradient(value, t, axis=0)
        err = np.abs(num - deriv).max(axis=-1)[1:-1]
        assert np.quantile(err, 0.98) < 1e-5 and err.max() < 0.5    # central differences: O(dt^2) on the arcs
    # centripetal acceleration v^2 / r on the arcs, yaw rate v / r
    on_arc = np.abs(tr.yaw_rate_rad_s) > 0
    speed = np.linalg.norm(tr.velocity_m_s, axis=-1)
    np.testing.assert_allclose(np.abs(tr.yaw_rate_rad_s[on_arc]), speed[on_arc] / r, rtol=1e-12)
    marks = tr.indices_every(1.0)
    assert marks.size == int(np.floor(tr.length_m)) + 1
    assert np.all(np.diff(tr.arc_length_m[marks]) > 0.99)


def test_trajectory_rejects_a_turn_radius_that_does_not_fit():
    with pytest.raises(ValueError, match="too large for leg 1"):
        lb.waypoint_trajectory(U_PATH, speed_m_s=1.0, accel_m_s2=0.5, dt_s=0.1, turn_radius_m=3.5)
    with pytest.raises(ValueError, match="needs turn_radius_m > 0"):
        lb.waypoint_trajectory(U_PATH, speed_m_s=1.0, accel_m_s2=0.5, dt_s=0.1)


def test_noise_free_imu_readings_are_the_rotated_truth_and_calibration_removes_the_bias():
    rng = np.random.default_rng(0)
    tr = lb.waypoint_trajectory(U_PATH, speed_m_s=0.8, accel_m_s2=0.5, dt_s=0.05, turn_radius_m=1.0)
    acc = lb.accelerometer_readings(tr.acceleration_m_s2, tr.heading_rad, bias_m_s2=0.0, sigma_m_s2=0.0, rng=rng)
    # body frame: forward = tangential acceleration, left = v^2 kappa
    speed = np.linalg.norm(tr.velocity_m_s, axis=-1)
    np.testing.assert_allclose(acc[:, 1], speed * tr.yaw_rate_rad_s, atol=1e-12)
    np.testing.assert_allclose(lb.body_to_world(acc, tr.heading_rad), tr.acceleration_m_s2, atol=1e-12)
    # stationary calibration: 1000 samples at rest estimate -b within 4 sigma / sqrt(N)
    bias, sigma, n = np.array([0.05, -0.03]), 0.02, 1000
    rest = lb.accelerometer_readings(np.zeros((200, n, 2)), np.zeros((200, n)), bias_m_s2=bias, sigma_m_s2=sigma,
                                     rng=rng)
    est = lb.stationary_bias(rest)
    assert est.shape == (200, 1, 2)
    np.testing.assert_allclose(est.mean(axis=0)[0], -bias, atol=4 * sigma / np.sqrt(200 * n))
    assert est.std(axis=0).mean() == pytest.approx(sigma / np.sqrt(n), rel=0.15)
    gyro = lb.gyroscope_readings(np.zeros((50, 500)), bias_rad_s=0.01, sigma_rad_s=0.005, rng=rng)
    assert lb.stationary_bias(gyro, axis=-1).mean() == pytest.approx(-0.01, abs=4 * 0.005 / np.sqrt(50 * 500))


def test_dead_reckoning_of_the_true_acceleration_and_the_drift_of_a_bias():
    tr = lb.waypoint_trajectory([[0.0, 5.0], [30.0, 5.0]], speed_m_s=1.0, accel_m_s2=0.5, dt_s=0.01)
    v, p = lb.dead_reckon(tr.acceleration_m_s2, 0.01, position0_m=tr.position_m[0])
    # trapezoid: exact on the linear pieces of the speed, half a step of each of the two acceleration jumps
    dv_max = 2 * 0.5 * 0.01 * 0.5
    np.testing.assert_allclose(v, tr.velocity_m_s, atol=dv_max + 1e-12)
    assert np.abs(p - tr.position_m).max() <= dv_max * tr.time_s[-1] + 1e-9     # the velocity error integrated
    # a constant acceleration error e gives e t^2 / 2 exactly with the trapezoid rule
    e = 0.02
    _, p_bias = lb.dead_reckon(tr.acceleration_m_s2 + [e, 0.0], 0.01, position0_m=tr.position_m[0])
    np.testing.assert_allclose(p_bias[:, 0] - p[:, 0], e * tr.time_s**2 / 2, atol=1e-9)
    heading = lb.integrate(np.full(101, 0.1), 0.01, 1.0)
    assert heading[-1] == pytest.approx(1.0 + 0.1 * 1.0)


@pytest.mark.parametrize("frame", ["body", "world"])
def test_inertial_measurement_jacobian_equals_finite_differences(frame):
    rng = np.random.default_rng(3)
    x = rng.standard_normal((5, 8))
    h = lb.inertial_measurement_function(frame)
    J = lb.inertial_measurement_jacobian(8, frame)(x)
    eps = 1e-6
    num = np.stack([(h(x + eps * np.eye(8)[i]) - h(x - eps * np.eye(8)[i])) / (2 * eps) for i in range(8)], -1)
    np.testing.assert_allclose(J, num, atol=1e-8)


def test_fusion_equals_the_information_form_and_follows_the_missing_rule():
    rng = np.random.default_rng(2)
    A, B = rng.standard_normal((2, 6, 2, 2))
    R1 = A @ np.swapaxes(A, -1, -2) + 0.1 * np.eye(2)
    R2 = B @ np.swapaxes(B, -1, -2) + 0.1 * np.eye(2)
    z1, z2 = rng.standard_normal((2, 6, 2))
    z, R = lb.fuse_estimates(z1, R1, z2, R2)
    info = np.linalg.inv(R1) + np.linalg.inv(R2)
    np.testing.assert_allclose(R, np.linalg.inv(info), atol=1e-12)
    ref = np.linalg.solve(info, np.linalg.solve(R1, z1[..., None]) + np.linalg.solve(R2, z2[..., None]))[..., 0]
    np.testing.assert_allclose(z, ref, atol=1e-12)
    z1[1] = np.nan
    z2[2, 0] = np.nan
    z1[3] = z2[3] = np.nan
    z, R = lb.fuse_estimates(z1, R1, z2, R2)
    np.testing.assert_array_equal(z[1], z2[1])
    np.testing.assert_array_equal(R[2], R1[2])
    assert np.all(np.isnan(z[3])) and np.all(np.isnan(R[3]))


def test_exponent_estimators_on_noise_free_data_and_least_squares_against_cvxpy():
    d = np.arange(0.5, 10.01, 0.5)
    S, C = -43.64, 3.1
    M = S - 10 * C * np.log10(d)
    assert lb.path_loss_exp_ratio_estimate(d, M, S) == pytest.approx(C, rel=1e-12)   # D = 1 m (0/0) left out
    assert lb.path_loss_exp_given_ref_power(d, M, S) == pytest.approx(C, rel=1e-12)
    rng = np.random.default_rng(9)
    noisy = M + 2.0 * rng.standard_normal(d.shape)
    noisy[3] = np.nan
    c = cp.Variable()
    keep = np.isfinite(noisy)
    cp.Problem(cp.Minimize(cp.sum_squares(noisy[keep] - S + 10 * c * np.log10(d[keep])))).solve()
    assert lb.path_loss_exp_given_ref_power(d, noisy, S) == pytest.approx(float(c.value), rel=1e-6)
    with pytest.raises(lb.DegenerateGeometryError, match="0/0"):
        lb.path_loss_exp_ratio_estimate(np.ones(3), np.full(3, -40.0), -40.0)


def test_ratio_estimator_is_unbiased_with_its_closed_form_variance():
    """C_hat = -(1/N) sum (M_s - S_hat) / (10 L_s) with M_s = S - 10 C L_s + e_s and S_hat = S + e_0 is unbiased, with
    Var = sigma^2 / N^2 * sum 1 / (10 L_s)^2 + sigma_0^2 * (mean 1 / (10 L_s))^2."""
    rng = np.random.default_rng(4)
    d = np.arange(0.5, 10.01, 0.5)
    d = d[d != 1.0]
    L = np.log10(d)
    S, C, sigma, sigma0 = -40.42, 1.72, 1.0, 0.3
    R = 200_000
    M = S - 10 * C * L + sigma * rng.standard_normal((R, d.size))
    S_hat = S + sigma0 * rng.standard_normal(R)
    est = lb.path_loss_exp_ratio_estimate(np.broadcast_to(d, M.shape), M, S_hat)
    var = sigma**2 / d.size**2 * np.sum(1 / (10 * L) ** 2) + sigma0**2 * np.mean(1 / (10 * L)) ** 2
    assert abs(est.mean() - C) < 4 * np.sqrt(var / R)
    assert est.var() == pytest.approx(var, rel=0.02)


def test_polyline_trajectory_walks_at_constant_speed_with_impulse_turns():
    """Sharp corners at constant speed: |v| is the speed, the acceleration is the backward difference of the
    velocity (zero on the legs, an impulse of |dv| / dt at each turn), the arc length the distance walked."""
    path = [[0.0, 0.0], [3.0, 0.0], [3.0, 4.0]]
    tr = lb.polyline_trajectory(path, speed_m_s=0.5, dt_s=0.1)
    assert tr.time_s.size == round(7.0 / 0.5 / 0.1) and tr.start == "moving"
    np.testing.assert_allclose(np.linalg.norm(tr.velocity_m_s, axis=-1), 0.5, rtol=1e-15)
    np.testing.assert_allclose(tr.velocity_m_s[0] + np.cumsum(tr.acceleration_m_s2[1:], axis=0) * 0.1,
                               tr.velocity_m_s[1:], atol=1e-12)
    big = np.linalg.norm(tr.acceleration_m_s2, axis=-1) > 1e-9
    assert big.sum() == 1 and np.linalg.norm(tr.acceleration_m_s2[big]) == pytest.approx(0.5 * np.sqrt(2) / 0.1)
    np.testing.assert_allclose(tr.arc_length_m, 0.5 * tr.time_s, rtol=1e-15)
    np.testing.assert_allclose(tr.heading_rad[[0, -1]], [0.0, np.pi / 2])
    # from rest: uniform ramp over ramp_s to the speed, half the ramp added to the duration
    rest = lb.polyline_trajectory(path, speed_m_s=0.5, dt_s=0.1, start="rest", ramp_s=2.0, rss_every=4)
    assert rest.time_s.size == round((14.0 + 1.0) / 0.1)
    np.testing.assert_allclose(rest.acceleration_m_s2[1:20, 0], 0.25, rtol=1e-12)
    np.testing.assert_array_equal(rest.rss_steps, np.arange(0, rest.time_s.size, 4))
    with pytest.raises(lb.ParameterError, match="start"):
        lb.polyline_trajectory(path, speed_m_s=0.5, dt_s=0.1, start="standing")
    with pytest.raises(lb.ParameterError, match="repeated"):
        lb.polyline_trajectory([[0.0, 0.0], [0.0, 0.0]], speed_m_s=0.5, dt_s=0.1)


def test_trajectory_states_follow_the_model_layout_and_head_cuts_every_field():
    tr = lb.polyline_trajectory([[0.0, 0.0], [3.0, 0.0], [3.0, 4.0]], speed_m_s=0.5, dt_s=0.1, rss_every=10)
    ca = lb.constant_acceleration(0.1, 1.0, layout="axis_major")           # [x, vx, ax, y, vy, ay]
    x = tr.states(ca)
    np.testing.assert_array_equal(x[:, [0, 3]], tr.position_m)
    np.testing.assert_array_equal(x[:, [1, 4]], tr.velocity_m_s)
    np.testing.assert_array_equal(x[:, [2, 5]], tr.acceleration_m_s2)
    cv = lb.constant_velocity(0.1, 1.0)                                    # [x, y, vx, vy]: no acceleration
    np.testing.assert_array_equal(tr.states(cv), np.concatenate([tr.position_m, tr.velocity_m_s], axis=-1))
    head = tr.head(25)
    assert head.time_s.size == 25 and head.position_m.shape == (25, 2) and head.arc_length_m.size == 25
    np.testing.assert_array_equal(head.rss_steps, [0, 10, 20])
    no_arc = lb.Trajectory(tr.time_s, tr.position_m, tr.velocity_m_s, tr.acceleration_m_s2)
    with pytest.raises(lb.ParameterError, match="arc_length_m"):
        no_arc.indices_every(1.0)
