"""Gudipati 2017 scenario: printed tables, the walk simulation and the 8-D fusion UKF against an independent
filterpy loop."""
import warnings
from dataclasses import replace

import numpy as np
import pytest
from filterpy.kalman import MerweScaledSigmaPoints, UnscentedKalmanFilter

import locbook as lb
from locbook.scenarios import gudipati as gu


def test_table_5_1_average_row_arithmetic():
    labels, dist, cells, avg = gu.table_5_1()
    assert labels == ["n = 1.03", "n = 3.1", "n = 1.72", "n = 1.2"]
    np.testing.assert_allclose(dist, np.arange(1, 10))
    mean = cells.mean(axis=0)
    assert mean[-1] == pytest.approx(7.535)                 # the printed 7.77 is the thesis's error (Table 5.1)
    # the printed average's rounding (0.005) plus that of the mean of four cells printed to 0.01 (0.005)
    assert np.all(np.abs(mean[:-1] - avg[:-1]) <= 0.01 + 1e-12)


def test_table_5_2_and_the_anchor_layout():
    assert gu.ANCHOR_IDS == ("12", "13", "14", "15", "16", "17")
    assert gu.ROOM_M == (30.0, 10.0)
    ch = gu.channel_model(("13",))
    # Eq. (3.7) at 10 m for anchor 13: S - 10 C
    assert ch.mean_rss_dbm(np.array([10.0]))[0] == pytest.approx(gu.REF_POWER_DBM[1] - 10 * gu.PATH_LOSS_EXP[1])
    assert len(gu.calibration_distances_m("span")) == 20 and len(gu.calibration_distances_m("sixty")) == 60


def _quiet(settings):
    return replace(settings, shadowing_sigma_db=0.0, fast_sigma_db=0.0, accel_sigma_m_s2=0.0, gyro_sigma_rad_s=0.0,
                   accel_residual_bias_m_s2=0.0, gyro_residual_bias_rad_s=0.0)


def test_noise_free_inertial_only_error_is_the_integration_rule_only():
    # the acceleration jumps at the ramp and arc ends, so the trapezoid rule converges at first order in dt
    worst = {}
    for dt in (0.02, 0.01):
        w = gu.simulate_walk("u", 4, _quiet(gu.WalkSettings(dt_s=dt)), 2, np.random.default_rng(0))
        worst[dt] = gu.walk_errors(w, gu.track(w, "inertial_only")).per_point_m.max()
    assert worst[0.01] / worst[0.02] == pytest.approx(0.5, abs=0.05)
    assert worst[0.01] < 0.25


def test_noise_free_rss_only_error_is_the_register_quantisation_only():
    s = _quiet(gu.WalkSettings())
    w = gu.simulate_walk("linear", 6, s, 2, np.random.default_rng(0))
    err = gu.walk_errors(w, gu.track(w, "rss_only")).mean_m
    w_fine = replace(w, rss_dbm=gu.channel_model(w.anchor_ids).mean_rss_dbm(
        lb.pairwise_distance_m(w.truth.position_m, w.anchors_m))[None].repeat(2, 0))
    exact = gu.walk_errors(w_fine, gu.track(w_fine, "rss_only")).per_point_m
    # averaging dB over the centred window costs little inside; the end points' windows are one-sided
    assert exact[:, 1:-1].max() < 0.01 and exact.max() < 0.25
    assert err[0] > exact.mean()                             # the 1 dB register steps cost accuracy


def test_kf_needs_the_fix_covariance():
    w = gu.simulate_walk("linear", 4, gu.WalkSettings(), 2, np.random.default_rng(0))
    with pytest.raises(ValueError, match="fix_covariance"):
        gu.track(w, "kf")


@pytest.mark.slow
def test_shadowing_calibration_hits_its_target_with_the_same_streams():
    s = gu.WalkSettings()
    target = 3.0
    sig = gu.calibrate_shadowing(target, "linear", 6, s, 10, 42, tol_db=1e-4)
    got = gu.rss_only_mean_error("linear", 6, replace(s, shadowing_sigma_db=sig), 10, 42)
    assert got == pytest.approx(target, abs=0.05)


@pytest.mark.parametrize("alpha", [1e-3, 0.5])
def test_fusion_ukf_equals_an_independent_filterpy_loop(alpha):
    """The 8-D model, body-frame inertial stream then RSS stream at every step, against filterpy's UKF with the
    sigma points redrawn around the current estimate before each update (Gudipati Eq. (3.18))."""
    s = gu.WalkSettings()
    w = gu.simulate_walk("u", 6, s, 1, np.random.default_rng(3))
    T = 60
    w = replace(w, rss_dbm=w.rss_dbm[:, :T], acc_m_s2=w.acc_m_s2[:, :T], gyro_rad_s=w.gyro_rad_s[:, :T],
                report_steps=np.arange(T))
    model = lb.HeadingKinematicModel(s.dt_s, s.q, s.q_angular)
    x0, P0 = gu._initial(w, model, 8)
    imu, rss = gu._imu_stream(w, False), gu._rss_stream(w, model)
    ours = lb.unscented_kalman_filter(model.F, model.Q, x0, P0, [imu, rss], alpha=alpha, beta=2.0, kappa=0.0)
    points = MerweScaledSigmaPoints(8, alpha=alpha, beta=2.0, kappa=0.0)
    a, ch = w.anchors_m, rss.channel

    def h_rss(x):
        return ch.ref_power_dbm - 10 * ch.path_loss_exp * np.log10(np.linalg.norm(x[:2] - a, axis=1))

    def h_imu(x):
        c, sn = np.cos(x[6]), np.sin(x[6])
        return np.array([c * x[4] + sn * x[5], -sn * x[4] + c * x[5], x[7]])

    f = UnscentedKalmanFilter(8, 3, s.dt_s, h_imu, lambda x, dt: model.F @ x, points)
    f.x, f.P, f.Q = x0.copy(), P0.copy(), model.Q
    z_imu = np.concatenate([w.acc_m_s2[0], w.gyro_rad_s[0, :, None]], axis=-1)
    r_rss = (s.shadowing_sigma_db**2 + s.fast_sigma_db**2) * np.eye(6)        # the settings' total RSS variance
    per_step = s.imu_rate_hz * s.dt_s
    r_imu = np.diag([s.accel_sigma_m_s2**2 / per_step + s.accel_residual_bias_m_s2**2] * 2
                    + [s.gyro_sigma_rad_s**2 / per_step + s.gyro_residual_bias_rad_s**2])
    for k in range(T):
        f.predict()
        f.sigmas_f = points.sigma_points(f.x, f.P)
        f.update(z_imu[k], R=r_imu, hx=h_imu)
        f.sigmas_f = points.sigma_points(f.x, f.P)
        f.update(w.rss_dbm[0, k], R=r_rss, hx=h_rss)
        np.testing.assert_allclose(ours.mean[0, k], f.x, atol=1e-5, err_msg=f"step {k}")
        np.testing.assert_allclose(ours.cov[0, k], f.P, atol=1e-5, err_msg=f"step {k}")


def test_report_windows_equal_a_brute_force_average_and_unheard_packets_are_left_out():
    s = gu.WalkSettings()
    w = gu.simulate_walk("u", 6, s, 2, np.random.default_rng(0))
    rss = w.rss_dbm.copy()
    rss[0, 100:140, 1] = np.nan                              # anchor 1 not heard for 4 s
    w = replace(w, rss_dbm=rss)
    arc = w.truth.arc_length_m
    ref = []
    for k in w.report_steps:
        win = (arc >= arc[k] - 0.5) & (arc <= arc[k] + 0.5)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)      # a window with nothing heard: NaN, as expected
            ref.append(np.nanmean(np.where(np.isfinite(rss[:, win]), rss[:, win], np.nan), axis=1))
    ref = np.stack(ref, 1)
    expected = lb.lateration_ls(w.anchors_m, gu.channel_model(w.anchor_ids).range_m(ref), ref_index=5).position_m
    np.testing.assert_allclose(gu.rss_only_fixes(w), expected, atol=1e-9)


def test_the_ed_floor_is_not_heard_and_the_ceiling_saturates():
    out = gu.ed_register_dbm(np.array([-95.0, -91.4, -90.6, -3.0]))
    assert np.isnan(out[0]) and out[1] == -91.0 and out[2] == -91.0 and out[3] == -7.0


@pytest.mark.slow
def test_printed_sign_stream_jacobian_and_the_ins_drift_covariance():
    s = replace(gu.WalkSettings(), shadowing_sigma_db=1.5)
    w = gu.simulate_walk("linear", 6, s, 300, np.random.default_rng(0))
    model = lb.HeadingKinematicModel(s.dt_s, s.q, s.q_angular)
    m = gu._rss_stream(w, model, "printed_3_12")
    x = np.random.default_rng(1).standard_normal((4, 8))
    x[:, :2] += [10, 4]
    num = np.stack([(m.h(x + 1e-6 * e) - m.h(x - 1e-6 * e)) / 2e-6 for e in np.eye(8)], -1)
    np.testing.assert_allclose(m.jacobian(x), num, atol=1e-6)
    np.testing.assert_allclose(m.h(x), -gu._rss_stream(w, model).channel.mean_rss_dbm(
        np.linalg.norm(x[:, None, :2] - w.anchors_m, axis=-1)), atol=1e-12)
    # the closed-form drift variance against the dead-reckoning errors of 300 walks (per axis, pooled)
    e = gu.inertial_only(w)[:, w.report_steps] - w.truth.position_m[w.report_steps]
    mc = (e**2).mean(axis=(0, 2))
    cf = gu.ins_drift_covariance(w)[:, 0, 0]
    k = slice(10, None)
    np.testing.assert_allclose(mc[k], cf[k], rtol=0.15)
    # position fusion is Eqs. (4.8)-(4.9) of the two estimates
    cov = np.diag([4.0, 9.0])
    z, R = gu.position_fusion(w, cov)
    ref_z, ref_R = lb.fuse_estimates(gu.rss_only_fixes(w), cov, gu.inertial_only(w)[:, w.report_steps],
                                     gu.ins_drift_covariance(w))
    np.testing.assert_allclose(z, ref_z)


# -- the readings opened as notebook parameters -----------------------------------------------------------

def test_anchor_layouts_place_16_and_17_at_the_wall_midpoints_and_the_walk_uses_them():
    L, W = gu.ROOM_M
    long_, short = (gu.anchors_m(gu.ANCHOR_IDS, k) for k in gu.ANCHOR_LAYOUTS)
    np.testing.assert_array_equal(long_[:4], short[:4])                 # the corners do not move (Sec. 5.1)
    np.testing.assert_array_equal(long_[4:], [[L / 2, 0.0], [L / 2, W]])
    np.testing.assert_array_equal(short[4:], [[0.0, W / 2], [L, W / 2]])
    np.testing.assert_array_equal(gu.anchors_m(gu.ANCHOR_IDS), long_)   # the default layout
    with pytest.raises(ValueError, match="anchor_layout"):
        gu.anchors_m(gu.ANCHOR_IDS, "ceiling")
    # noise-free readings are Eq. (3.7) at the distances to the chosen layout's anchors, quantised by the register
    s = replace(_quiet(gu.WalkSettings()), anchor_layout="corners_and_short_wall_midpoints")
    w = gu.simulate_walk("u", 6, s, 1, np.random.default_rng(0))
    np.testing.assert_array_equal(w.anchors_m, short)
    d = np.linalg.norm(w.truth.position_m[:, None] - short, axis=-1)
    mean = gu.REF_POWER_DBM - 10 * gu.PATH_LOSS_EXP * np.log10(np.maximum(d, 0.1))
    np.testing.assert_allclose(w.rss_dbm[0], np.minimum(np.round(mean), -7.0), atol=1e-9)
    x, y, bound = gu.crlb_map_m(6, 3.0, spacing_m=1.0, layout="corners_and_short_wall_midpoints")
    i, j = np.argmin(np.abs(y - W / 2)), np.argmin(np.abs(x - 0.5))
    assert bound[i, j] < gu.crlb_map_m(6, 3.0, spacing_m=1.0)[2][i, j]  # beside the short wall's anchor: tighter


class _Rows:
    """A stand-in for lb.Report that keeps what record_ch6 records."""

    def __init__(self):
        self.rows = []

    def number(self, quantity, printed, reproduced=None, **kw):
        self.rows.append((quantity, printed, reproduced))


@pytest.mark.parametrize("method", gu.FUSED_METHODS)
def test_the_fused_headline_is_the_chosen_methods_mean_error(method):
    rng = np.random.default_rng(0)
    R, K = 5, 7
    errors = {(p, na, m): gu.WalkErrors(*(lambda e: (e.mean(1), np.sqrt((e**2).mean(1)), e))(rng.uniform(0, 5, (R, K))))
              for p in gu.PATHS for na in gu.ANCHOR_SETS for m in gu.METHODS}
    flags = dict.fromkeys(errors)
    rep = _Rows()
    gu.record_ch6(rep, errors, flags, headline_anchors=6, shadowing_sigma_db=1.0, calibrated=False, ukf_alpha=1.0,
                  near_turn=np.arange(K) < 2, fused_method=method)
    for path, item in (("linear", "linear path"), ("u", "U-path")):
        printed = gu.PRINTED.get("Ch. VI text", item, "fused")
        got = [v for q, p, v in rep.rows if p == printed]
        assert got == [pytest.approx(errors[(path, 6, method)].mean_m.mean())]
        assert any(gu.METHOD_LABELS[method] in q for q, p, _ in rep.rows if p == printed)
    abstract = gu.PRINTED.get("Abstract", "30m x 10m area", "positional accuracy")
    assert [v for _, p, v in rep.rows if p == abstract] == [pytest.approx(errors[("linear", 6, method)].mean_m.mean())]
    with pytest.raises(ValueError, match="fused_method"):
        gu.record_ch6(_Rows(), errors, flags, headline_anchors=6, shadowing_sigma_db=1.0, calibrated=False,
                      ukf_alpha=1.0, near_turn=np.arange(K) < 2, fused_method="pf")


def test_a_2_s_filter_step_filters_once_per_report_point_on_single_packets():
    # 0.5 m/s x 2 s = the 1 m report spacing: after the start ramp every step is a report point, each window one packet
    s = replace(gu.WalkSettings(), dt_s=2.0)
    w = gu.simulate_walk("linear", 6, s, 3, np.random.default_rng(1))
    np.testing.assert_allclose(np.diff(w.truth.time_s), 2.0)
    T = w.truth.time_s.size
    assert w.report_steps.size >= T - 2 and np.all(np.diff(w.report_steps[1:]) == 1)
    k = w.report_steps
    arc = w.truth.arc_length_m
    single = (np.abs(arc[k][:, None] - arc[None, :]) <= gu.REPORT_SPACING_M / 2).sum(axis=1) == 1
    assert single.sum() >= k.size - 4                        # all but the ramps' windows hold one packet
    expected = lb.lateration_ls(w.anchors_m, gu.channel_model(w.anchor_ids).range_m(w.rss_dbm[:, k]),
                                ref_index=5).position_m
    np.testing.assert_allclose(gu.rss_only_fixes(w)[:, single], expected[:, single], atol=1e-9)   # no averaging
    cov = gu.fix_covariance_from(gu.simulate_walk("linear", 6, s, 10, np.random.default_rng(2)))
    for m in ("kf", "ekf", "ukf"):
        assert np.all(np.isfinite(gu.track(w, m, fix_covariance=cov, ukf_alpha=1.0)))


@pytest.mark.parametrize("r_m", [0.5, 2.0])
def test_the_u_path_turn_radius_sets_the_arcs(r_m):
    tr = gu.path_trajectory("u", replace(gu.WalkSettings(), turn_radius_m=r_m))
    (x0, y0), _, (x2, y2), _ = gu.PATHS["u"]
    legs = 2 * (x2 - x0) + (y2 - y0)
    # two corners: each cuts r off both legs it joins and adds a quarter circle pi r / 2
    assert tr.length_m == pytest.approx(legs - 4 * r_m + np.pi * r_m, abs=1e-9)
    on_arc = np.abs(tr.yaw_rate_rad_s) > 0
    speed = np.linalg.norm(tr.velocity_m_s, axis=-1)
    np.testing.assert_allclose(np.abs(tr.yaw_rate_rad_s[on_arc]), speed[on_arc] / r_m, rtol=1e-12)


def test_imu_frame_world_takes_the_readings_as_world_accelerations():
    s = _quiet(gu.WalkSettings())
    body = gu.simulate_walk("u", 4, s, 1, np.random.default_rng(0))
    world = gu.simulate_walk("u", 4, replace(s, imu_frame="world"), 1, np.random.default_rng(0))
    a = body.truth.acceleration_m_s2
    np.testing.assert_allclose(world.acc_m_s2[0], a, atol=1e-12)
    back = body.truth.heading_rad == np.pi                   # the return leg: the body frame is the world turned round
    assert back.sum() > 100
    np.testing.assert_allclose(body.acc_m_s2[0, back], -a[back], atol=1e-12)
    # world-frame readings are integrated as they are: the gyroscope's heading plays no part in dead reckoning
    spun = replace(world, gyro_rad_s=world.gyro_rad_s + 0.3)
    np.testing.assert_array_equal(gu.inertial_only(spun), gu.inertial_only(world))
    assert not np.allclose(gu.inertial_only(replace(body, gyro_rad_s=body.gyro_rad_s + 0.3)), gu.inertial_only(body))


# -- the readings under the rule, the path geometry and the filter step ------------------------------------

def test_no_gudipati_default_is_fitted_and_the_fitted_shadowing_is_an_alternative():
    from locbook.reproduce.interpretations import interpretations
    rows = {r.name: r for r in interpretations("gudipati2017")}
    assert all(r.basis != "fitted" for r in rows.values())
    shadow = rows["tracking_shadowing"]
    assert shadow.fitted and all(v in shadow.alternatives for v in shadow.fitted)
    # one assumed channel with the calibration notebook
    assert shadow.default == gu.WalkSettings().shadowing_sigma_db
    assert shadow.default == rows["calibration_shadowing"].default


@pytest.mark.parametrize("linear", list(gu.LINEAR_PATHS_Y_M))
@pytest.mark.parametrize("u", list(gu.U_PATH_MARGINS_M))
def test_every_declared_path_geometry_runs_over_the_length_of_the_hall(linear, u):
    # Sec. 5.3: "a linear path and a U-path over the length of the room" (30 m x 10 m, Sec. 5.1)
    paths = gu.path_waypoints_m(linear, u)
    L, W = gu.ROOM_M
    (x0, y0), (x1, y1) = paths["linear"]
    assert (x0, x1) == (0.0, L) and y0 == y1 == gu.LINEAR_PATHS_Y_M[linear] and 0 < y0 < W
    m = gu.U_PATH_MARGINS_M[u]
    (a, b, c, d) = (np.array(p) for p in paths["u"])
    np.testing.assert_allclose([a, b, c, d], [[m, m], [L - m, m], [L - m, W - m], [m, W - m]])
    assert 0 < m < W / 2                                        # two legs along the long walls, inside the hall
    tr = gu.path_trajectory("u", replace(gu.WalkSettings(), linear_path=linear, u_path=u))
    legs = 2 * (L - 2 * m) + (W - 2 * m)
    r = gu.WalkSettings().turn_radius_m
    assert tr.length_m == pytest.approx(legs - 4 * r + np.pi * r, abs=1e-9)
    assert np.all((tr.position_m >= 0) & (tr.position_m <= [L, W]))
    with pytest.raises(ValueError, match="u_path"):
        gu.path_waypoints_m(linear, "along_the_walls")


def test_the_default_paths_are_the_default_labels_and_each_figure_names_a_path_and_anchor_set():
    assert gu.PATHS == gu.path_waypoints_m()
    for path, anchors in gu.FIGURE_PATHS.values():
        assert path in gu.PATHS and (anchors is None or anchors in gu.ANCHOR_SETS)


@pytest.mark.parametrize("speed", [0.3, 0.5, 1.5])
def test_the_default_filter_step_is_one_step_per_report_point(speed):
    # dt_s None: the time to travel the 1 m report spacing, so each report point is one filter step
    dt = gu.filter_step_s(None, speed)
    assert dt == pytest.approx(gu.REPORT_SPACING_M / speed)
    assert gu.filter_step_s(0.1, speed) == 0.1
    s = replace(gu.WalkSettings(), speed_m_s=speed, dt_s=dt)
    tr = gu.path_trajectory("linear", s)
    cruise = np.isclose(np.linalg.norm(tr.velocity_m_s, axis=-1), speed)
    steps = np.diff(tr.arc_length_m)[cruise[1:] & cruise[:-1]]
    np.testing.assert_allclose(steps, gu.REPORT_SPACING_M, rtol=1e-9)
    with pytest.raises(ValueError, match="dt_s"):
        gu.filter_step_s(0.0, speed)


def test_track_old_ukf_weights_keyword_warns_at_the_caller_and_gives_the_same_numbers():
    """``ukf_weights=`` (the earlier keyword) is ``ukf_variant=`` for one release."""
    w = gu.simulate_walk("linear", 4, gu.WalkSettings(), 1, np.random.default_rng(8))
    with pytest.warns(DeprecationWarning, match=r"track\(ukf_weights='corrected'\) is deprecated: use "
                                                r"track\(ukf_variant='corrected'\)") as caught:
        old = gu.track(w, "ukf", ukf_weights="corrected")
    assert len(caught) == 1 and caught[0].filename == __file__
    np.testing.assert_array_equal(old, gu.track(w, "ukf", ukf_variant="corrected"))
