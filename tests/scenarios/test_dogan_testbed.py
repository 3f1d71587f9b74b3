"""Document 000 (Dogan 2015), Ch. 2 and Ch. 5: the printed MLE cost (2.4) against the RSS-domain likelihood, the
calibration LS (5.1) against its closed-form sampling law, the test-bed time grid and the single-walk window."""
import numpy as np
import pytest

import locbook as lb
from locbook.scenarios import dogan as dg
from locbook.scenarios import dogan_testbed as tb
from locbook.tracking.divergence import DivergenceFlags


def test_eq24_cost_is_the_rss_likelihood_scaled_and_has_the_grid_ml_minimiser():
    rng = np.random.default_rng(3)
    channel = lb.PathLossModel(-48.0, 3.0, 6.0)
    # off the anchors (the cost clips d at 1e-9 there)
    grid = np.stack(np.meshgrid(np.arange(-2.95, 10.6, 0.1), np.arange(-2.95, 12.2, 0.1)), -1).reshape(-1, 2)
    truth = rng.uniform((0, 0), dg.ROOM_M, (20, 2))
    rss = channel.sample_rss_dbm(lb.pairwise_distance_m(truth, dg.ANCHORS_M), rng=rng)
    cost = dg.mle_cost_eq24(grid, rss, channel)                                        # (20, G)
    rss_domain = np.sum((rss[:, None, :] - channel.mean_rss_dbm(lb.pairwise_distance_m(grid, dg.ANCHORS_M))) ** 2, -1)
    np.testing.assert_allclose(cost * 30.0**2, rss_domain, rtol=1e-9)                # (10 alpha)^2 = 900
    np.testing.assert_array_equal(grid[np.argmin(cost, axis=1)],
                                  lb.grid_ml_position(rss, lb.RssModel(dg.ANCHORS_M, channel), grid).position_m)


def test_calibration_ls_matches_cvxpy_and_its_sampling_law():
    points = tb.calibration_points_m()
    assert points.shape == (24, 2)
    channel = lb.PathLossModel(tb.TESTBED_REF_POWER_DBM, tb.TESTBED_PATH_LOSS_EXP, tb.TESTBED_FIT_SIGMA_DB)
    power, distance = tb.simulate_calibration(points, channel, tb.CALIBRATION_PACKETS, np.random.default_rng(1))
    one = tb.fit_calibration(power[0], distance)                                          # cvxpy
    d = np.broadcast_to(distance[:, None, :], power[0].shape).ravel()
    design = np.stack([np.ones(d.size), -10 * np.log10(d)], -1)
    normal = np.linalg.solve(design.T @ design, design.T @ power[0].ravel())           # Eq. (5.1) directly
    np.testing.assert_allclose([one.ref_power_dbm, one.path_loss_exp], normal, rtol=1e-6, atol=1e-6)
    assert d.size == 2880 != tb.PRINTED_MEASUREMENT_COUNT.value                               # the print says 3360
    # repeated calibrations: unbiased, with the OLS covariance sigma^2 (M^T M)^-1
    n_runs = 4000
    study = tb.calibration_study(points, channel, tb.CALIBRATION_PACKETS, n_runs, np.random.default_rng(2))
    law_sd = channel.sigma_db * np.sqrt(np.diag(np.linalg.inv(design.T @ design)))
    for est, true, sd in ((study.ref_power_dbm, -52.0, law_sd[0]), (study.path_loss_exp, 1.8, law_sd[1])):
        assert abs(est.mean() - true) < 4 * sd / np.sqrt(n_runs)
        assert est.std(ddof=1) == pytest.approx(sd, rel=4 / np.sqrt(2 * n_runs))      # sd of a sample sd
    # E[s^2] = sigma^2 with n - 2 degrees of freedom
    assert np.mean(study.residual_sigma_db**2) == pytest.approx(5.8**2, rel=4 * np.sqrt(2 / 2878) / np.sqrt(n_runs))


def test_orientation_gain_averages_to_zero_over_the_circle():
    theta = np.arange(0, 360, 15.0)
    assert abs(tb.orientation_gain_db(theta).mean()) < 1e-12                            # cos(t), cos(2t + phi)
    g = tb.orientation_gain_db(np.array([0.0, 180.0]), quadrupole_db=0.0, dipole_db=2.0)
    np.testing.assert_allclose(g, [2.0, -2.0])


def test_testbed_grid_and_single_walk_window():
    assert dg.walk_trajectory(rss_every=tb.TESTBED_RSS_EVERY).rss_steps.size == 41    # from rest: 81 s
    traj = dg.walk_trajectory(start="moving", rss_every=tb.TESTBED_RSS_EVERY)
    assert traj.rss_steps.size == 40 and np.allclose(np.diff(traj.time_s[traj.rss_steps]), 2.0)   # 1 packet / 2 s
    lo, hi = lb.single_run_interval(np.linspace(0, 1, 100001), 0.9)
    assert (lo, hi) == pytest.approx((0.05, 0.95))
    with pytest.raises(lb.ParameterError):
        lb.single_run_interval([1.0, 2.0], 1.0)
    run = dg.run_channel(traj, 6.0, 1.8, 30, np.random.default_rng(4), sigma_acc_values=(0.0152,), ref_power_dbm=-52.0)
    rows = tb.testbed_rows(run, 0.0152)
    assert len(rows) == len(tb.PRINTED_TESTBED_RMSE) + 4
    # every row recomputed from the raw errors: per-walk RMSE, hand-interpolated 5 % / 95 % order statistics
    per_walk = {key: np.sqrt(np.mean(err**2, axis=1)) for key, err in run.errors.items()}
    only = {f: per_walk[(f, None)] for f in ("parallel_ekf", "serial_ekf", "kalman_filter")}
    reduction = {f: 100.0 * (only[f] - per_walk[(f, 0.0152)]) / only[f] for f in only}
    expected = [per_walk["static_mle"], per_walk[("serial_ekf", None)], per_walk[("serial_ekf", 0.0152)],
                per_walk[("parallel_ekf", None)], per_walk[("parallel_ekf", 0.0152)],
                per_walk[("kalman_filter", None)], per_walk[("kalman_filter", 0.0152)],
                reduction["parallel_ekf"], reduction["serial_ekf"], reduction["kalman_filter"],
                (reduction["parallel_ekf"] + reduction["serial_ekf"] + reduction["kalman_filter"]) / 3]
    printed = [3.16, 1.93, 1.54, 1.78, 1.52, 2.04, 1.85, 100 * 0.26 / 1.78, 100 * 0.39 / 1.93, 100 * 0.19 / 2.04, 15.0]
    for r, values, value in zip(rows, expected, printed, strict=True):
        assert r["lower"] <= r["median_single_walk"] <= r["upper"]
        lo, hi = _central_interval(values, 0.90)
        assert r["printed"] == pytest.approx(value, rel=1e-12)
        assert r["lower"] == pytest.approx(lo, rel=1e-12) and r["upper"] == pytest.approx(hi, rel=1e-12)
        assert r["median_single_walk"] == pytest.approx(np.sort(values)[14:16].mean(), rel=1e-12)   # 30 walks
        assert r["mean_single_walk"] == pytest.approx(np.mean(values), rel=1e-12)
        assert r["sd_single_walk"] == pytest.approx(np.std(values, ddof=1), rel=1e-12)
        assert r["mc_se"] == pytest.approx(np.std(values, ddof=1) / np.sqrt(30), rel=1e-12)


def _central_interval(values, coverage):
    """Order statistics with linear interpolation at (n - 1) q, written out (numpy's default definition)."""
    x = np.sort(np.asarray(values, float))
    out = []
    for q in (0.5 * (1 - coverage), 1 - 0.5 * (1 - coverage)):
        h = (x.size - 1) * q
        j = int(np.floor(h))
        out.append(x[j] + (h - j) * (x[min(j + 1, x.size - 1)] - x[j]))
    return tuple(out)


def test_testbed_rows_on_hand_made_walks():
    # 21 walks whose per-walk RMSEs are known exactly: errors constant over the epochs of a walk
    k = np.arange(21.0)
    walks = lambda rmse: np.repeat(np.asarray(rmse, float)[:, None], 7, axis=1)       # (21 runs, 7 epochs)
    errors = {"static_mle": walks(2.0 + 0.1 * k)}
    offsets = {"parallel_ekf": 0.0, "serial_ekf": 3.0, "kalman_filter": 10.0}          # reductions 10+k, 13+k, 20+k %
    for name, off in offsets.items():
        before = 1.0 + 0.05 * k
        errors[(name, None)] = walks(before)
        errors[(name, 0.5)] = walks(before * (1 - (10.0 + off + k) / 100))
    run = dg.ChannelRun(6.0, 1.8, np.zeros(2), errors)
    rows = {(r["filter"], r["case"]): r for r in tb.testbed_rows(run, 0.5)}
    # h = 20 * 0.05 = 1 and 20 * 0.95 = 19: the 2nd and 20th smallest walks, exactly
    static = rows[("static_mle", "ONLY RSS")]
    assert (static["lower"], static["median_single_walk"], static["upper"]) == pytest.approx((2.1, 3.0, 3.9), abs=1e-12)
    assert static["mean_single_walk"] == pytest.approx(3.0, abs=1e-12)
    assert static["sd_single_walk"] == pytest.approx(0.1 * np.std(k, ddof=1), rel=1e-12)
    assert static["mc_rmse"] == pytest.approx(np.sqrt(np.mean((2.0 + 0.1 * k) ** 2)), rel=1e-12)
    assert static["printed_value"].text == "3.16"
    red = rows[("kalman_filter", "reduction % (derived)")]                            # 20 + k: [21, 39], median 30
    assert (red["lower"], red["median_single_walk"], red["upper"]) == pytest.approx((21.0, 30.0, 39.0), abs=1e-9)
    assert red["printed"] == pytest.approx(9.3137, abs=1e-4) and red["printed_value"] is None
    pooled = lambda v: np.sqrt(np.mean(v**2))
    before, after = 1.0 + 0.05 * k, (1.0 + 0.05 * k) * (1 - (20.0 + k) / 100)
    assert red["mc_rmse"] == pytest.approx(100 * (pooled(before) - pooled(after)) / pooled(before), rel=1e-12)
    assert rows[("parallel_ekf", "reduction % (derived)")]["printed"] == pytest.approx(14.6067, abs=1e-4)
    mean = rows[("mean of the three", "reduction %")]                                 # 14.33 + k: [15.33, 33.33]
    assert (mean["lower"], mean["median_single_walk"], mean["upper"]) == pytest.approx(
        (1 + 43 / 3, 10 + 43 / 3, 19 + 43 / 3), abs=1e-9)
    assert mean["printed_value"].text == "approximately by 15%"


def test_printed_testbed_reductions_are_the_printed_pairs():
    """Ch. 5: the three reductions derived from the printed pairs (Figs. 5.9-5.11), and their mean, which the thesis
    rounds to 'approximately 15%' (20.2, 14.6 and 9.3 %, mean 14.7 %)."""
    red = tb.printed_reductions_pct()
    assert red["serial_ekf"] == pytest.approx(100 * (1.93 - 1.54) / 1.93, rel=1e-12)
    assert red["parallel_ekf"] == pytest.approx(100 * (1.78 - 1.52) / 1.78, rel=1e-12)
    assert red["kalman_filter"] == pytest.approx(100 * (2.04 - 1.85) / 2.04, rel=1e-12)
    assert abs(np.mean(list(red.values())) - tb.PRINTED_FUSION_REDUCTION.value) < tb.PRINTED_FUSION_REDUCTION.rounding


def test_record_testbed_records_each_printed_walk_value_with_its_flags_and_the_best_filter_claim(tmp_path, monkeypatch):
    monkeypatch.setenv("LOCBOOK_OUTPUT_DIR", str(tmp_path))
    k = np.arange(21.0)
    walks = lambda rmse: np.repeat(np.asarray(rmse, float)[:, None], 7, axis=1)
    errors = {"static_mle": walks(2.0 + 0.1 * k)}
    divergence = {}
    for name, level in {"parallel_ekf": 1.0, "serial_ekf": 1.2, "kalman_filter": 1.1}.items():
        errors[(name, None)] = walks(level + 0.05 * k)
        errors[(name, 0.5)] = walks(0.9 * (level + 0.05 * k))
        for case in (None, 0.5):
            flagged = np.zeros(21, bool)
            flagged[:2 if (name, case) == ("serial_ekf", 0.5) else 0] = True      # 2 of 21 walks of one case
            divergence[(name, case)] = DivergenceFlags(flagged, np.where(flagged, 3, -1))
    run = dg.ChannelRun(6.0, 1.8, np.zeros(2), errors, divergence=divergence)
    rows = tb.testbed_rows(run, 0.5)
    assert tb.testbed_flags(rows[0], run, 0.5) is None                                      # the MLE has no guard
    mean_row = next(r for r in rows if r["filter"] == "mean of the three")
    assert set(tb.testbed_flags(mean_row, run, 0.5)) == {f"{n} {c}" for n in dg.FILTERS
                                                         for c in ("ONLY RSS", "RSS/IMU")}
    report = lb.Report("test")
    tb.record_testbed(report, rows, run, 0.5)
    recorded = report.numbers
    # the seven printed walk values and the printed 15 %, then the arithmetic mean of the printed pairs, then the claim
    assert len(recorded) == len(tb.PRINTED_TESTBED_RMSE) + 1 + 2
    by_id = {r["printed_id"]: r for r in recorded}
    mle = by_id[tb.PRINTED_TESTBED_RMSE[("static_mle", None)].id]
    assert mle["kind"] == "reproduction" and mle["reproduced"] == pytest.approx(3.0, abs=1e-12)
    assert "flagged" not in mle["note"]
    fused = by_id[tb.PRINTED_TESTBED_RMSE[("serial_ekf", "fusion")].id]
    assert fused["kind"] == "reproduction" and "2 of 21 runs flagged diverged" in fused["note"]   # the text's readings
    assert "flagged" not in by_id[tb.PRINTED_TESTBED_RMSE[("serial_ekf", None)].id]["note"]
    assert "2 of 21" in by_id[tb.PRINTED_FUSION_REDUCTION.id]["note"]       # the mean covers every filter
    arithmetic = by_id[tb.PRINTED_FUSION_REDUCTION_CH6.id]
    assert arithmetic["reproduced"] == pytest.approx(np.mean(list(tb.printed_reductions_pct().values())), rel=1e-12)
    claim = by_id[tb.PRINTED_ACCURACY.id]                                                   # best: parallel EKF fused
    assert "(parallel_ekf RSS/IMU)" in claim["quantity"]
    assert claim["reproduced"] == pytest.approx(0.9 * (1.0 + 0.05 * 10), rel=1e-12)
    # a walk run under a reading fitted to output makes every filter row a calibration naming it; the MLE stays
    report = lb.Report("test2")
    tb.record_testbed(report, rows, run, 0.5, start="moving", noise_interpretation="sigma_acc")
    by_id = {r["printed_id"]: r for r in report.numbers}
    fused = by_id[tb.PRINTED_TESTBED_RMSE[("serial_ekf", "fusion")].id]
    assert fused["kind"] == "calibrated" and fused["calibrated_from"] == dg.calibrated_from_text("moving", "sigma_acc")
    assert by_id[tb.PRINTED_TESTBED_RMSE[("static_mle", None)].id]["kind"] == "reproduction"
