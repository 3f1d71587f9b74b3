"""Document 000 (Dogan 2015): EKF variants and multi-rate fusion against filterpy, serial = parallel = KF on a
linear model, the default trajectory, and the Tables 3.7-3.12 plan."""
import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter, KalmanFilter

import locbook as lb
from locbook.scenarios import dogan as dg

ANCHORS = dg.ANCHORS_M


def _scenario(seed=0, runs=3, steps=240):
    """Random CA trajectories (the model itself), RSS every 10th step, accelerometer every step."""
    rng = np.random.default_rng(seed)
    model = dg.motion_model()
    F, Q = model.F, model.Q
    truth = np.zeros((runs, steps, 6))
    truth[:, 0] = model.state_from(rng.uniform(1, 6, (runs, 2)), rng.normal(0, 0.3, (runs, 2)))
    for k in range(1, steps):
        truth[:, k] = truth[:, k - 1] @ F.T + rng.multivariate_normal(np.zeros(6), Q, runs)
    channel = lb.PathLossModel(dg.REF_POWER_DBM, dg.PATH_LOSS_EXP, dg.SIGMA_RSS_DB)
    power = channel.sample_rss_dbm(lb.pairwise_distance_m(truth[..., model.position_index], ANCHORS), rng=rng)
    power[:, np.arange(steps) % 10 != 0] = np.nan
    acc = truth[..., model.acceleration_index] + 0.015 * rng.standard_normal((runs, steps, 2))
    x0 = truth[:, 0] + rng.normal(0, 1, (runs, 6)) * [1, 0.08, 0.015, 1, 0.08, 0.015]
    P0 = np.diag([4, 0.0065, 0.00023, 4, 0.0065, 0.00023])
    return model, channel, power, acc, x0, P0


def _filterpy_track(model, channel, power, acc, x0, P0, mode, fusion):
    """Per-run filterpy ExtendedKalmanFilter with the RSS model written from Eq. (2.2) alone."""
    idx = model.position_index
    p0, ple, s2 = channel.ref_power_dbm, channel.path_loss_exp, channel.sigma_db**2
    h_acc = model.derivative_measurement_matrix(2)

    def h(x, j):
        return np.array([p0 - 10 * ple * np.log10(np.linalg.norm(x[idx] - ANCHORS[j]))])

    def jac(x, j):
        diff = x[idx] - ANCHORS[j]
        out = np.zeros((1, 6))
        out[0, idx] = -10 * ple / np.log(10) * diff / (diff @ diff)
        return out

    xs, Ps = np.empty(power.shape[:2] + (6,)), np.empty(power.shape[:2] + (6, 6))
    for b in range(power.shape[0]):
        f = ExtendedKalmanFilter(6, 1)
        f.x, f.P, f.F, f.Q = x0[b].copy(), P0.copy(), model.F, model.Q
        for k in range(power.shape[1]):
            f.predict()
            if fusion:
                f.update(acc[b, k], lambda x: h_acc, lambda x: h_acc @ x, R=0.015**2 * np.eye(2))
            z = power[b, k]
            if np.isfinite(z[0]):
                if mode == "parallel":
                    f.update(z, lambda x: np.vstack([jac(x, j) for j in range(4)]),
                             lambda x: np.concatenate([h(x, j) for j in range(4)]), R=s2 * np.eye(4))
                else:
                    for j in np.argsort(-z):          # Table 3.3: strongest anchor first
                        f.update(z[j:j + 1], lambda x, j=j: jac(x, j), lambda x, j=j: h(x, j), R=np.array([[s2]]))
            xs[b, k], Ps[b, k] = f.x, f.P
    return xs, Ps


@pytest.mark.parametrize("mode", ["parallel", "serial"])
@pytest.mark.parametrize("fusion", [False, True])
def test_rss_ekf_equals_filterpy(mode, fusion):
    model, channel, power, acc, x0, P0 = _scenario()
    meas = ([lb.LinearMeasurement(acc, model.derivative_measurement_matrix(2), 0.015**2 * np.eye(2))] if fusion
            else []) + [lb.RssMeasurement(power, ANCHORS, channel, model.position_index, mode=mode)]
    ours = lb.extended_kalman_filter(model.F, model.Q, x0, P0, meas)
    xs, Ps = _filterpy_track(model, channel, power, acc, x0, P0, mode, fusion)
    np.testing.assert_allclose(ours.mean, xs, atol=1e-9)
    np.testing.assert_allclose(ours.cov, Ps, atol=1e-9)


def test_serial_order_matters_for_rss():
    """The serial EKF re-linearises after each scalar update, so unlike the linear case its result depends
    on the order (Tables 3.3-3.4)."""
    model, channel, power, acc, x0, P0 = _scenario(seed=3)
    runs = [lb.extended_kalman_filter(model.F, model.Q, x0, P0, [lb.RssMeasurement(
        power, ANCHORS, channel, model.position_index, mode="serial", order=o)]).mean for o in ("descending", "given")]
    assert np.max(np.abs(runs[0] - runs[1])) > 1e-3


def test_serial_parallel_and_kf_agree_on_a_linear_model():
    """Serial and parallel updates of a linear measurement with diagonal R equal filterpy's KalmanFilter and
    locbook's kalman_filter; and a stream with missing rows equals updating with the present rows only."""
    rng = np.random.default_rng(7)
    model = dg.motion_model()
    H = np.vstack([model.position_measurement_matrix(), model.derivative_measurement_matrix(2)])
    R = np.diag([2.0, 3.0, 0.01, 0.02])
    T = 60
    z = rng.normal(0, 1, (2, T, 4)).cumsum(axis=1)
    x0, P0 = np.zeros(6), np.eye(6)
    par = lb.extended_kalman_filter(model.F, model.Q, x0, P0, [lb.LinearMeasurement(z, H, R)])
    ser = lb.extended_kalman_filter(model.F, model.Q, x0, P0, [lb.LinearMeasurement(z, H, R, mode="serial")])
    kf = lb.kalman_filter(model.F, model.Q, x0, P0, lb.LinearMeasurement(z, H, R))
    np.testing.assert_allclose(ser.mean, par.mean, atol=1e-9)
    np.testing.assert_allclose(ser.cov, par.cov, atol=1e-12)
    np.testing.assert_allclose(par.mean, kf.mean, atol=1e-9)
    f = KalmanFilter(6, 4)
    f.x, f.P, f.F, f.Q, f.H, f.R = x0.copy(), P0.copy(), model.F, model.Q, H, R
    for k in range(T):
        f.predict()
        f.update(z[0, k])
        np.testing.assert_allclose(par.mean[0, k], f.x, atol=1e-9)
        np.testing.assert_allclose(par.cov[0, k], f.P, atol=1e-9)
    # position rows only every 10th step: identical to a two-stream filter (acc every step, position sometimes)
    zm = z.copy()
    zm[:, np.arange(T) % 10 != 0, :2] = np.nan
    one = lb.extended_kalman_filter(model.F, model.Q, x0, P0, [lb.LinearMeasurement(zm, H, R)])
    two = lb.extended_kalman_filter(model.F, model.Q, x0, P0, [
        lb.LinearMeasurement(zm[..., 2:], H[2:], R[2:, 2:]), lb.LinearMeasurement(zm[..., :2], H[:2], R[:2, :2])])
    np.testing.assert_allclose(one.mean, two.mean, atol=1e-9)
    with pytest.raises(ValueError, match="diagonal R"):
        lb.LinearMeasurement(z, H, R + 0.1, mode="serial")


def test_default_trajectory():
    """The default walk: 24 m at 0.3 m/s -> 80 s = 1600 steps of 50 ms and 160 RSS epochs; the accelerometer truth
    integrates to the velocity; the rest start ramps up over 2 s."""
    tr = dg.walk_trajectory(start="moving")
    assert tr.time_s.size == 1600 and tr.rss_steps.size == 160
    speed = np.hypot(tr.velocity_m_s[:, 0], tr.velocity_m_s[:, 1])
    np.testing.assert_allclose(speed, 0.3, atol=1e-12)
    vel = tr.velocity_m_s
    np.testing.assert_allclose(vel[0] + np.cumsum(tr.acceleration_m_s2[1:], axis=0) * dg.DT_S, vel[1:], atol=1e-12)
    assert np.sum(np.linalg.norm(tr.acceleration_m_s2, axis=1) > 1) == 3      # three sharp turns
    np.testing.assert_allclose(tr.position_m[0], dg.WAYPOINTS_M[0])
    path = np.sum(np.linalg.norm(np.diff(tr.position_m, axis=0), axis=1))
    assert abs(path - (24.0 - 0.3 * dg.DT_S)) < 0.02          # corners are cut by at most one step
    rest = dg.walk_trajectory()                                # the default start: from rest, 2 s ramp
    assert (rest.start == "rest" and rest.time_s.size == 1620 and rest.velocity_m_s[0, 0] == 0.0
            and rest.velocity_m_s[0, 1] == 0.0)
    np.testing.assert_allclose(rest.acceleration_m_s2[1:40, 1], 0.15, atol=1e-9)
    with pytest.raises(lb.ParameterError, match="start"):
        dg.walk_trajectory(start="standing")


def test_table_plan_covers_every_printed_cell():
    """88 printed cells (16 + 12 + 12 + 6 + 24 + 18, Tables 3.7-3.12), 9 channel settings."""
    cells = dg.printed_tables()
    assert len(cells) == 88
    assert all((c["table"], c["row"]) in dg.TABLE_SETTINGS for c in cells)
    assert len(dg.CHANNELS) == 9
    assert dg.table_channels()[(6, 3.0)] == (True, (0.015, 0.0075, 0.0015, 0.00075))


def test_channel_runs_are_reproducible_and_subset_invariant():
    tr = dg.walk_trajectory(waypoints_m=((1, 1), (1, 4), (4, 4)), speed_m_s=0.6)
    a = dg.run_channels(tr, 6, seed=5, channels=[(5, 3.0), (4, 3.0)])
    b = dg.run_channels(tr, 6, seed=5, channels=[(4, 3.0)])
    for key, err in b[(4, 3.0)].errors.items():
        np.testing.assert_array_equal(err, a[(4, 3.0)].errors[key])
    rows = dg.table_rows(a)
    assert {r["table"] for r in rows} == {"3.7", "3.8"} and len(rows) == 2 * 4 + 2 * 3


def test_mle_reaches_the_grid_optimum():
    """The grid + LM estimate's RSS-domain cost is never above the best point of a fine 5 cm grid."""
    rng = np.random.default_rng(11)
    channel = lb.PathLossModel(-48.0, 3.0, 6.0)
    truth = rng.uniform([0, 0], [7.6, 9.2], (40, 2))
    power = channel.sample_rss_dbm(lb.pairwise_distance_m(truth, ANCHORS), rng=rng)
    est = dg.mle_positions(power, channel)
    xs, ys = np.arange(-3, 10.6, 0.05), np.arange(-3, 12.2, 0.05)
    fine = np.stack(np.meshgrid(xs, ys, indexing="ij"), -1).reshape(-1, 2)
    best = lb.grid_ml_position(power, lb.RssModel(ANCHORS, channel), fine)
    cost = np.sum((power - channel.mean_rss_dbm(lb.pairwise_distance_m(est.position_m, ANCHORS))) ** 2, -1)
    assert np.all(cost <= best.cost + 1e-9) and np.all(est.converged)


@pytest.mark.parametrize("start, noise_interpretation", [("rest", "printed"), ("moving", "printed"),
                                                        ("rest", "sigma_acc"), ("moving", "sigma_acc")])
def test_record_tables_kinds_repeats_and_miss_notes(tmp_path, monkeypatch, start, noise_interpretation):
    """The MLE column is a reproduction; a filter column is calibrated exactly when the rows were computed under a
    reading fitted to output (the moving start's speed from Fig. 3.2, Q from sigma_ACC fitted to Table 3.9), naming
    each, else a reproduction; the repeats of one setting link to the cell they repeat and get no verdict; a miss
    names the readings tested and the reading it was computed under."""
    monkeypatch.setenv("LOCBOOK_OUTPUT_DIR", str(tmp_path))
    report = lb.Report("x")
    cells = {(c["table"], c["row"], c["column"]): c for c in dg.printed_tables()}
    keys = [("3.7", "sigma_rss_db=6", "static_mle"), ("3.8", "sigma_rss_db=6", "serial_ekf"),
            ("3.9", "sigma_acc=0.015", "serial_ekf"), ("3.11", "ple=3", "static_mle"),
            ("3.9", "sigma_acc=0.0015", "kalman_filter")]
    rows = [dict(table=k[0], row=k[1], column=k[2], printed=cells[k]["value"], printed_value=cells[k]["printed"],
                 reproduced=cells[k]["value"] * (2.0 if k[1] == "sigma_acc=0.0015" else 1.0),
                 mc_se=0.001) for k in keys]
    counts = dg.record_tables(report, rows, variants={keys[-1]: {"start moving, Q printed": 1.5}}, start=start,
                              noise_interpretation=noise_interpretation)
    out = {r["where"]: r for r in report.numbers}
    mle = out["Table 3.7, sigma_rss_db=6, static_mle"]
    assert mle["kind"] == "reproduction" and mle["verdict"] == "within" and not mle["calibrated_from"]
    serial = out["Table 3.8, sigma_rss_db=6, serial_ekf"]
    if (start, noise_interpretation) == ("rest", "printed"):
        assert serial["kind"] == "reproduction" and serial["calibrated_from"] == ""
    else:
        assert serial["kind"] == "calibrated"
        assert ("24 meter" in serial["calibrated_from"]) == (start == "moving")
        assert ("Table 3.9" in serial["calibrated_from"]) == (noise_interpretation == "sigma_acc")
    # the thesis's Monte-Carlo error widens the window: 2 x its relative standard error of the printed value
    assert serial["ambiguity"] == pytest.approx(2 * dg.thesis_repeat_error() * 1.47114, rel=1e-12)
    repeat = out["Table 3.9, sigma_acc=0.015, serial_ekf"]
    assert repeat["same_as"] == "Table 3.8 | sigma_rss_db=6 | serial_ekf" and repeat["verdict"] == ""
    assert out["Table 3.11, ple=3, static_mle"]["same_as"] == "Table 3.7 | sigma_rss_db=6 | static_mle"
    miss = out["Table 3.9, sigma_acc=0.0015, kalman_filter"]
    assert miss["verdict"] == "miss" and "start moving, Q printed: 1.500" in miss["note"]
    assert ("Q printed as a constant" in miss["note"]) == (noise_interpretation == "printed")
    assert counts == {"within": 2, "linked": 2, "miss": 1}


def test_interpretations_summary_counts_fusion_cells_within_the_tolerance_per_interpretation():
    # hand-made deviations |ours / printed - 1| (exact in binary): the chosen reading from rows, others from variants
    cells = {  # key: (printed, chosen, A, B)
        ("3.8", "sigma_rss_db=3", "parallel_ekf"): (4.0, 4.5, 5.0, 3.0),     # 0.125, 0.25, 0.25
        ("3.8", "sigma_rss_db=3", "serial_ekf"): (8.0, 6.0, 8.0, 9.0),       # 0.25, 0, 0.125
        ("3.10", "y", "kalman_filter"): (2.0, 2.5, 2.25, 1.5),               # 0.25, 0.125, 0.25
        ("3.9", "sigma_acc=0.015", "parallel_ekf"): (1.0, 9.0, 9.0, 9.0),    # a repeat (REPEATED_ROWS): left out
        ("3.7", "sigma_rss_db=6", "serial_ekf"): (1.0, 9.0, 9.0, 9.0),       # ONLY RSS table: left out
    }
    rows = [{"table": k[0], "row": k[1], "column": k[2], "printed": v[0], "reproduced": v[1]} for k, v in cells.items()]
    variants = {k: {"A": v[2], "B": v[3]} for k, v in cells.items()}
    rows.append({"table": "3.10", "row": "x", "column": "kalman_filter", "printed": 1.0, "reproduced": 9.0})
    variants[("3.10", "x", "kalman_filter")] = {"R per epoch": 9.0}          # one reading only: left out
    assert ("3.9", "sigma_acc=0.015") in dg.REPEATED_ROWS
    out = {(s["interpretation"], s["filters"]): s
           for s in dg.interpretations_summary(rows, variants, "chosen", ["A", "B"])}
    assert [k for k in out] == [(r, f) for r in ("chosen", "A", "B") for f in ("EKFs", "KF (MLE)")]
    expect = {("chosen", "EKFs"): (2, 1, 18.75), ("chosen", "KF (MLE)"): (1, 0, 25.0),
              ("A", "EKFs"): (2, 1, 12.5), ("A", "KF (MLE)"): (1, 1, 12.5),
              ("B", "EKFs"): (2, 1, 18.75), ("B", "KF (MLE)"): (1, 0, 25.0)}
    for key, (n, within, median) in expect.items():
        assert (out[key]["cells"], out[key]["within_20_pct"]) == (n, within)
        assert out[key]["median_abs_deviation_pct"] == pytest.approx(median, rel=1e-12)
    wide = dg.interpretations_summary(rows, variants, "chosen", ["A"], tolerance=0.25)     # the bound is inclusive
    assert [s["within_25_pct"] for s in wide] == [2, 1, 2, 1]
    with pytest.raises(ValueError, match="tolerance"):
        dg.interpretations_summary(rows, variants, "chosen", ["A"], tolerance=20)


# -- readings opened as notebook parameters --------------------------------------------------------------
def test_mle_bounds_room_projects_the_fix_onto_the_room():
    """'room': every fix inside the room inset by MLE_ROOM_INSET_M (off the corner anchors); a fix the unconstrained MLE
    put there is unchanged, one outside moves to the nearest point of that box (no point of a 1 cm grid over it is
    closer)."""
    rng = np.random.default_rng(3)
    channel = lb.PathLossModel(-48.0, 3.0, 8.0)
    truth = rng.uniform([0, 0], [7.6, 9.2], (200, 2))
    power = channel.sample_rss_dbm(lb.pairwise_distance_m(truth, ANCHORS), rng=rng)
    free = dg.mle_positions(power, channel).position_m
    room = dg.mle_positions(power, channel, bounds="room").position_m
    lo, hi = dg.MLE_ROOM_INSET_M, np.array([7.6, 9.2]) - dg.MLE_ROOM_INSET_M
    assert 0 < lo < 0.5
    inside = np.all((free >= lo) & (free <= hi), axis=-1)
    assert inside.any() and (~inside).any()
    np.testing.assert_array_equal(room[inside], free[inside])
    assert np.all((room >= lo) & (room <= hi))
    xs, ys = np.arange(lo, hi[0] + 1e-9, 0.01), np.arange(lo, hi[1] + 1e-9, 0.01)
    grid = np.stack(np.meshgrid(xs, ys, indexing="ij"), -1).reshape(-1, 2)
    for f, r in zip(free[~inside][:5], room[~inside][:5]):
        assert np.linalg.norm(f - r) <= np.min(np.linalg.norm(grid - f, axis=-1)) + 1e-12
    with pytest.raises(lb.ParameterError, match="bounds"):
        dg.mle_positions(power, channel, bounds="box")


@pytest.mark.parametrize("step", [0.5, 0.25, 0.1])
def test_mle_grid_step_sets_the_start_grid_the_fix_descends_from(step):
    """Levenberg-Marquardt starts at the best point of the grid of that step over the room +- 3 m: the fix's RSS-domain
    cost is never above the best cost on that grid, and every problem converges."""
    rng = np.random.default_rng(7)
    channel = lb.PathLossModel(-48.0, 3.0, 6.0)
    truth = rng.uniform([0, 0], [7.6, 9.2], (30, 2))
    power = channel.sample_rss_dbm(lb.pairwise_distance_m(truth, ANCHORS), rng=rng)
    est = dg.mle_positions(power, channel, grid_step_m=step)
    xs, ys = np.arange(-3, 10.6 + 1e-9, step), np.arange(-3, 12.2 + 1e-9, step)
    grid = np.stack(np.meshgrid(xs, ys, indexing="ij"), -1).reshape(-1, 2)
    d = np.maximum(lb.pairwise_distance_m(grid, ANCHORS), 1e-3)          # the grid passes through the anchors
    grid_cost = np.sum((power[:, None, :] - channel.mean_rss_dbm(d)) ** 2, -1)
    cost = np.sum((power - channel.mean_rss_dbm(lb.pairwise_distance_m(est.position_m, ANCHORS))) ** 2, -1)
    assert np.all(cost <= grid_cost.min(axis=-1) + 1e-9) and np.all(est.converged)
    with pytest.raises(lb.ParameterError, match="grid_step_m"):
        dg.mle_positions(power, channel, grid_step_m=0.0)


def test_room_sets_the_corner_anchors_the_scaled_path_and_the_smc_starts():
    """A room of sides (w, l): anchors at its four corners in Sec. 5.4's order, Fig. 3.1's path at the same fractions
    of the sides as in the default room, SMC trajectories starting inside it; the default room changes nothing."""
    np.testing.assert_array_equal(dg.corner_anchors([6.0, 10.0]), [[0, 0], [6, 0], [6, 10], [0, 10]])
    assert dg.room_waypoints(dg.WAYPOINTS_M, [7.6, 9.2]) is dg.WAYPOINTS_M
    scaled = np.asarray(dg.room_waypoints(dg.WAYPOINTS_M, [6.0, 10.0]))
    np.testing.assert_allclose(scaled / [6.0, 10.0], np.asarray(dg.WAYPOINTS_M) / [7.6, 9.2], rtol=1e-12)
    states = dg.smc_trajectories(400, 2, np.random.default_rng(1), room_m=(6.0, 10.0))
    start = states[:, 0, [0, 3]]
    assert np.all((start >= 0) & (start <= [6.0, 10.0])) and start[:, 1].max() > 9.2
    for bad in ([6.0], [6.0, -1.0], [6.0, np.inf]):
        with pytest.raises(lb.ParameterError, match="room_m"):
            dg.corner_anchors(bad)


@pytest.mark.parametrize("mle_r", ["constant", "per_epoch"])
def test_every_step_rmse_scores_the_filters_at_every_grid_step(mle_r):
    """'every_step' records the same recursion at every 20 Hz step from the first RSS epoch: its errors at the RSS
    epochs equal the RSS-epoch run's, and the table RMSE is the root mean square over runs and every step; the MLE
    column stays at the RSS epochs."""
    tr = dg.walk_trajectory(waypoints_m=((1.0, 1.0), (1.0, 4.0), (4.0, 4.0)), speed_m_s=0.5)
    # every filter on the 20 Hz grid (an ONLY-RSS filter at the RSS rate has only the RSS epochs:
    # test_dogan_rss_only_step)
    kw = dict(sigma_acc_values=(0.0075,), mle_r=mle_r, rss_only_step="imu_rate")
    a = dg.run_channel(tr, 6.0, 3.0, 5, np.random.default_rng(4), **kw)
    b = dg.run_channel(tr, 6.0, 3.0, 5, np.random.default_rng(4), rmse_epochs="every_step", **kw)
    for key in [(f, c) for f in dg.FILTERS for c in (None, 0.0075)]:
        every = b.errors[("every_step",) + key]
        assert every.shape == (5, tr.time_s.size - tr.rss_steps[0])
        np.testing.assert_allclose(every[:, tr.rss_steps - tr.rss_steps[0]], a.errors[key], rtol=0, atol=1e-12)
        np.testing.assert_allclose(b.errors[key], a.errors[key], rtol=0, atol=1e-12)
        assert dg.scored_errors(b, key, "every_step") is every
    runs = {(6.0, 3.0): b}
    rows = {r["column"]: r for r in dg.table_rows(runs,
                                                  "every_step") if r["table"] == "3.7" and r["row"] == "sigma_rss_db=6"}
    every = b.errors[("every_step", "serial_ekf", None)]
    assert rows["serial_ekf"]["reproduced"] == pytest.approx(np.sqrt(np.mean(every**2)), rel=1e-12)
    assert rows["static_mle"]["reproduced"] == pytest.approx(np.sqrt(np.mean(b.errors["static_mle"] ** 2)), rel=1e-12)
    with pytest.raises(lb.ParameterError, match="rmse_epochs"):
        dg.scored_errors(b, ("serial_ekf", None), "all")


def test_pcrlb_per_epoch_mse_mle():
    """The per-epoch MSE_MLE: equal epochs give the constant bound; P_0 comes from epoch 0 (the bound at step 0 is
    sqrt(MSE_x + MSE_y) of epoch 0); a worse fix at one epoch leaves the linear bound unchanged before that epoch and
    never lowers it after; too few epochs for the horizon is refused."""
    n = 200
    const = dg.pcrlb_m("linear", fusion=True, sigma_rss_db=6.0, mse_mle_m2=np.array([2.0, 3.0]), n_steps=n)
    epochs = np.tile([2.0, 3.0], (n // dg.RSS_EVERY, 1))
    np.testing.assert_allclose(dg.pcrlb_m("linear", fusion=True, sigma_rss_db=6.0, mse_mle_m2=epochs, n_steps=n), const,
                               rtol=1e-12)
    varied = epochs.copy()
    varied[0] = [0.5, 0.25]
    varied[7] = [20.0, 30.0]
    bound = dg.pcrlb_m("linear", fusion=True, sigma_rss_db=6.0, mse_mle_m2=varied, n_steps=n)
    assert bound[0] == pytest.approx(np.sqrt(0.75), rel=1e-12)
    only_7 = epochs.copy()
    only_7[7] = [20.0, 30.0]
    worse = dg.pcrlb_m("linear", fusion=True, sigma_rss_db=6.0, mse_mle_m2=only_7, n_steps=n)
    np.testing.assert_allclose(worse[:7 * dg.RSS_EVERY], const[:7 * dg.RSS_EVERY], rtol=1e-12)
    assert np.all(worse >= const - 1e-12) and worse[7 * dg.RSS_EVERY] > const[7 * dg.RSS_EVERY]
    with pytest.raises(lb.ParameterError, match="per-epoch"):
        dg.pcrlb_m("linear", fusion=True, sigma_rss_db=6.0, mse_mle_m2=epochs[:5], n_steps=n)
