"""The NIS guard's divergence flags reach the scenarios' callers: every scenario function that runs a
Kalman-family filter returns the per-run flags on request, combined correctly where it filters a subset of runs or
in segments, and the notebooks' summary helpers count them.

Facts used: a filter whose measurement noise is set far below the noise in the data has an innovation far beyond
its own covariance at every update, so every run is flagged at its first update; a filter whose assumed noise
exceeds the data's never is (each NIS is then stochastically smaller than chi-square, and 20 consecutive
exceedances of the 0.999 quantile have probability below 1e-57); and the guard of the concatenated NIS of
segments is the guard of the unsegmented filter (same recursion, so the same NIS)."""
from dataclasses import replace

import numpy as np
import pytest
from scipy.stats import chi2

import locbook as lb
from locbook import benchmark as bm
from locbook.scenarios import dogan as dg
from locbook.scenarios import george
from locbook.scenarios import gudipati as gu
from locbook.scenarios import measured as ko
from locbook.scenarios import palvai as pv
from locbook.tracking.divergence import DivergenceFlags, divergence_note, divergence_rows
from locbook.tracking.results import DIVERGENCE_PROBABILITY, DIVERGENCE_WINDOW

# ------------------------------------------------------------------------------------------------ the helper

def test_flags_count_scatter_and_note():
    f = DivergenceFlags(np.array([True, False, True]), np.array([4, -1, 8]))
    assert (f.n_diverged, f.n_runs, f.median_first_step) == (2, 3, 6.0)
    full = f.scatter(np.array([False, True, True, False, True]))
    np.testing.assert_array_equal(full.diverged, [False, True, False, False, True])
    np.testing.assert_array_equal(full.diverged_step, [-1, 4, -1, -1, 8])
    assert (full.n_diverged, full.n_runs) == (2, 3)              # the runs left out are not counted
    np.testing.assert_array_equal(full.unflagged(np.arange(5) * 10.0), [20.0])
    assert f.clause().startswith("2 of 3 runs flagged diverged by the NIS guard (20 updates beyond chi2 0.999)")
    assert divergence_note("", f).endswith("averaged here as the source averaged every run")
    assert divergence_note("why", f).startswith("why; 2 of 3 runs")
    assert divergence_note("", f, averaged="kept in the mean").endswith("chi2 0.999); kept in the mean")
    assert divergence_note("", f, averaged=False).endswith("chi2 0.999)")
    none = DivergenceFlags(np.zeros(4, bool), np.full(4, -1))
    assert divergence_note("why", none) == "why" and np.isnan(none.median_first_step)
    assert divergence_note("", {"EKF": f, "KF": none, "RSS only": None}).startswith("EKF: 2 of 3 runs")
    rows = divergence_rows({("EKF", "6 dB"): f, "KF": none, "RSS only": None}, step_s=0.5)
    assert [(r["filter"], r["setting"], r["runs flagged"], r["runs"]) for r in rows] == [("EKF", "6 dB", 2, 3),
                                                                                        ("KF", "", 0, 4)]
    assert rows[0]["median first time (s)"] == 3.0


def test_from_nis_follows_the_rule_with_an_offset():
    bound = chi2.ppf(DIVERGENCE_PROBABILITY, 2)
    nis = np.full((2, 40), 0.5 * bound)
    dof = np.full((2, 40), 2)
    nis[0, 7:7 + DIVERGENCE_WINDOW] = 2 * bound                  # exactly one window: flagged at its first step
    nis[1, 7:7 + DIVERGENCE_WINDOW - 1] = 2 * bound              # one update short: not flagged
    f = DivergenceFlags.from_nis(nis, dof, step_offset=3)
    np.testing.assert_array_equal(f.diverged, [True, False])
    np.testing.assert_array_equal(f.diverged_step, [10, -1])


# ------------------------------------------------------------------------------------------------ George

def _george_fixes(n_runs, sigma_m, rng):
    truth = george.trajectory_m("centerline")                  # constant velocity: the KF's model is exact
    return truth, truth + sigma_m * rng.standard_normal((n_runs,) + truth.shape)


def test_george_mis_tuned_kf_flags_every_run_at_its_first_update():
    truth, fixes = _george_fixes(30, 1.0, np.random.default_rng(1))
    # R, P0 and Q all far below the fixes' 1 m errors: the innovation is beyond its covariance from the first update
    kw = dict(q=1e-3, r_mode="isotropic", r_iso_m2=1e-6, init_velocity_var=1e-6)
    pos, flags = george.track_with_kalman(fixes, truth, with_divergence=True, **kw)
    np.testing.assert_array_equal(pos, george.track_with_kalman(fixes, truth, **kw))
    assert flags.n_diverged == flags.n_runs == 30
    np.testing.assert_array_equal(flags.diverged_step, 1)      # point 0 is the first fix; the first update is point 1
    _, true_start = george.track_with_kalman(fixes, truth, init="true_start", with_divergence=True, **kw)
    np.testing.assert_array_equal(true_start.diverged_step, 0)


def test_george_well_tuned_kf_flags_nothing():
    truth, fixes = _george_fixes(200, 0.5, np.random.default_rng(2))
    _, flags = george.track_with_kalman(fixes, truth, q=1e-4, r_mode="isotropic", r_iso_m2=1.0, with_divergence=True)
    assert flags.n_diverged == 0 and flags.n_runs == 200


def test_george_runs_without_fixes_are_neither_flagged_nor_counted():
    truth, fixes = _george_fixes(12, 1.0, np.random.default_rng(3))
    fixes[[2, 5, 9]] = np.nan                                    # failed calibrations
    kw = dict(q=1e-3, r_mode="isotropic", r_iso_m2=1e-6)
    pos, flags = george.track_with_kalman(fixes, truth, with_divergence=True, **kw)
    assert np.isnan(pos[[2, 5, 9]]).all()
    assert flags.n_runs == 9 and flags.n_diverged == 9
    assert not flags.diverged[[2, 5, 9]].any() and (flags.diverged_step[[2, 5, 9]] == -1).all()
    keep = np.ones(12, bool)
    keep[[2, 5, 9]] = False
    _, alone = george.track_with_kalman(fixes[keep], truth, with_divergence=True, **kw)
    np.testing.assert_array_equal(flags.diverged_step[keep], alone.diverged_step)


# ------------------------------------------------------------------------------------------------ Dogan

@pytest.fixture(scope="module")
def dogan_case():
    tr = dg.walk_trajectory(speed_m_s=0.5)
    tr = tr.head(400)
    rng = np.random.default_rng(5)
    channel = lb.PathLossModel(dg.REF_POWER_DBM, dg.PATH_LOSS_EXP, 6.0)
    rss = dg.simulate_rss(tr, channel, 40, rng)
    fix = dg.mle_positions(rss, channel).position_m
    return tr, channel, rss, fix


def test_dogan_run_filter_maps_the_flags_onto_the_trajectory_grid(dogan_case):
    tr, channel, rss, fix = dogan_case
    bad = dg.run_filter("kalman_filter", tr, rss, fix, np.full(2, 1e-6), channel)   # R far below the fixes' errors
    assert bad.n_diverged == 40
    np.testing.assert_array_equal(bad.diverged_step, tr.rss_steps[1])    # the first update: the second RSS epoch
    assert bad.nis.shape == (40, tr.time_s.size) and np.isnan(bad.nis[:, :tr.rss_steps[1]]).all()
    mse = np.mean((fix - tr.position_m[tr.rss_steps]) ** 2, axis=(0, 1))
    good = dg.run_filter("kalman_filter", tr, rss, fix, 4 * mse, channel)      # R above the fixes' error
    assert good.n_diverged == 0


def test_dogan_per_epoch_segments_are_judged_as_one_filter(dogan_case):
    tr, channel, rss, fix = dogan_case
    for mse in (np.full(2, 1e-6), np.full(2, 0.1)):
        one = dg.run_filter("kalman_filter", tr, rss, fix, mse, channel)
        seg = dg.run_filter("kalman_filter", tr, rss, fix, np.tile(mse, (tr.rss_steps.size, 1)), channel)
        np.testing.assert_allclose(seg.nis, one.nis, rtol=1e-9)
        np.testing.assert_array_equal(seg.diverged, one.diverged)
        np.testing.assert_array_equal(seg.diverged_step, one.diverged_step)
    assert 0 < one.n_diverged < 40                              # the second setting flags some runs, not all
    # each segment holds one RSS update, so no segment alone could ever complete a window of 20
    assert np.diff(tr.rss_steps).max() < DIVERGENCE_WINDOW * np.diff(tr.rss_steps).min()


def test_dogan_channel_run_carries_flags_keyed_like_its_errors(dogan_case):
    tr = dogan_case[0]
    run = dg.run_channel(tr, 6.0, 3.0, 10, np.random.default_rng(6), sigma_acc_values=(0.0152,))
    filter_keys = {k for k in run.errors if isinstance(k, tuple) and k[0] in dg.FILTERS}
    assert set(run.divergence) == filter_keys
    assert all(isinstance(f, DivergenceFlags) and f.n_runs == 10 for f in run.divergence.values())
    err, flags = dg.only_acc_errors(tr, 0.0152, 5, np.random.default_rng(7), with_divergence=True)
    assert err.shape == (5, tr.time_s.size - 1) and flags.n_runs == 5


# ------------------------------------------------------------------------------------------------ Gudipati

def test_gudipati_mis_tuned_filters_are_flagged_and_non_filters_have_no_flags():
    s = replace(gu.WalkSettings(), shadowing_sigma_db=4.0, filter_sigma_db=0.01)
    w = gu.simulate_walk("linear", 4, s, 6, np.random.default_rng(8))
    for method in ("ekf", "ukf"):
        est, flags = gu.track(w, method, with_divergence=True)
        np.testing.assert_array_equal(est, gu.track(w, method))
        assert flags.n_diverged == flags.n_runs == 6, method
    est, flags = gu.track(w, "rss_only", with_divergence=True)
    assert flags is None and est.shape[0] == 6


# ------------------------------------------------------------------------------------------------ Palvai

def test_palvai_ekf_flags_follow_the_filter_noise():
    data_setup = pv.Setup(dim=2, sigma_db=4.0)
    rng = np.random.default_rng(9)
    loc = pv.draw_locations(20, 30, 2, rng)
    z = pv.measure(data_setup, loc, rng)
    x0 = rng.uniform(0, pv.AREA_M, (20, 2))
    P0 = 100.0 * np.eye(2)
    # R, Q and P0 so small that the estimate stays at x0 and an innovation within the bound (|nu| < 4e-6 dB against
    # readings 4 dB apart) has a chance of about 1e-6 per update
    tight = dict(process_sd_m=1e-8)
    est, flags = pv.ekf_path(replace(data_setup, sigma_db=1e-6), loc, z, x0, 1e-14 * np.eye(2), with_divergence=True,
                             **tight)
    assert est.shape == (20, 30, 2) and flags.n_diverged == 20 and (flags.diverged_step == 0).all()
    _, calm = pv.ekf_path(replace(data_setup, sigma_db=8.0), loc, z, x0, P0, with_divergence=True)
    assert calm.n_diverged == 0
    # all readings in one update: one update per run, fewer than the window, never flagged
    _, batch = pv.ekf_path(replace(data_setup, sigma_db=1e-6), loc, z, x0, 1e-14 * np.eye(2), schedule="batch",
                           with_divergence=True, **tight)
    assert batch.n_diverged == 0 and batch.n_runs == 20


# ------------------------------------------------------------------------------------------------ the trackers

def test_benchmark_trackers_return_flags_of_the_kalman_trackers():
    sc = bm.tracking_scenario("george-walk")
    rng = np.random.default_rng(10)
    rss = sc.rss_dbm(8, rng)
    x0 = bm.initial_states(sc, bm.TrackerSettings(), 8, rng)
    # a walk the model believes nearly still (q) and readings it believes exact: every Kalman tracker is misspecified
    ts = bm.TrackerSettings(n_particles=50, q=1e-4)
    kalman = ("kf_on_ml", "ekf", "ekf_serial", "ukf")
    mis = replace(sc, channel=lb.PathLossModel(sc.channel.ref_power_dbm, sc.channel.path_loss_exp, 0.01,
                                               min_distance_m=sc.channel.min_distance_m), fix_cov_m2=1e-6 * np.eye(2))
    out, flags = bm.run_trackers(mis, rss, x0, ts, np.random.default_rng(11), trackers=kalman + ("particle",),
                                 with_divergence=True)
    assert set(flags) == set(kalman) and set(out) == set(kalman) | {"particle"}
    assert all(flags[k].n_diverged == flags[k].n_runs == 8 for k in kalman)
    plain = bm.run_trackers(mis, rss, x0, ts, np.random.default_rng(11), trackers=kalman)
    for k in kalman:
        np.testing.assert_array_equal(plain[k], out[k])
    rows, est, bound, cell_flags = bm.tracking_cells(sc, ts, 4, np.random.default_rng(12), n_bootstrap=20,
                                                     with_divergence=True)
    assert set(cell_flags) == set(kalman) and all(f.n_runs == 4 for f in cell_flags.values())


@pytest.mark.slow
def test_measured_tracks_return_flags_of_the_kalman_trackers():
    data = ko.load("kolakowski2021")
    model = ko.channel(ko.calibrate(data))
    kw = dict(seed=13, n_particles=20, particle_runs=1, n_bootstrap=20, block_s=10.0, recordings=["robot"])

    def flags_of(m):
        proto = ko.protocol(data, m, knn_k=5, q=0.05, spread_m=0.3)
        return ko.tracking_results(data, m, proto, **kw)["tracks"]["robot"][2]

    flags = flags_of(model)
    assert set(flags) == {"kf_on_ml", "ekf", "ekf_serial", "ukf"}
    assert all(f.n_runs == 1 for f in flags.values())
    # the same recording with the readings' noise assumed 100 times smaller: the EKF loses consistency at once
    tight = lb.PathLossModel(model.ref_power_dbm, model.path_loss_exp, np.asarray(model.sigma_db) / 100,
                             min_distance_m=model.min_distance_m)
    assert flags_of(tight)["ekf"].n_diverged == 1


# ------------------------------------------------------------------------------------------------ Dogan's tables

def _fabricated_channel():
    """A 6 dB, alpha = 3 channel (Table 3.7's 6 dB row) with hand-made errors: the parallel EKF flags 2 of 4 runs."""
    e = np.ones((4, 5))
    none = DivergenceFlags(np.zeros(4, bool), np.full(4, -1))
    two = DivergenceFlags(np.array([True, False, True, False]), np.array([30, -1, 50, -1]))
    run = dg.ChannelRun(6.0, 3.0, np.ones(2), errors={"static_mle": e, **{(f, None): e for f in dg.FILTERS}},
                        divergence={(f, None): (two if f == "parallel_ekf" else none) for f in dg.FILTERS})
    return {(6.0, 3.0): run}


def test_dogan_table_rows_and_notes_carry_the_flags():
    runs = _fabricated_channel()
    rows = dg.table_rows(runs)
    by = {(r["table"], r["column"]): r for r in rows}
    assert by[("3.7", "static_mle")]["divergence"] is None
    assert by[("3.7", "parallel_ekf")]["divergence"].n_diverged == 2
    report = lb.Report()
    dg.record_tables(report, rows)
    notes = {r["quantity"]: r["note"] for r in report.numbers if r["where"].startswith("Table 3.7")}
    assert "2 of 4 runs flagged diverged by the NIS guard" in notes["RMSE parallel_ekf"]
    assert "flagged" not in notes["RMSE serial_ekf"] and "flagged" not in notes["RMSE static_mle"]
    table = dg.divergence_table(runs, dt_s=0.05)
    assert [(r["filter"], r["runs flagged"], r["runs"]) for r in table] == [("parallel_ekf", 2, 4),
                                                                            ("serial_ekf", 0, 4),
                                                                           ("kalman_filter", 0, 4)]
    assert table[0]["median first time (s)"] == pytest.approx(2.0)
    tails = {t["filter"]: t for t in dg.tail_rows(runs)}
    assert tails["parallel_ekf"]["runs flagged diverged"] == 2 and tails["static_mle"]["runs flagged diverged"] == ""


def test_george_kalman_error_vs_q_is_the_mean_error_of_each_filtered_run():
    truth, fixes = _george_fixes(8, 1.0, np.random.default_rng(4))
    fixes[3] = np.nan                                            # a failed calibration: NaN error, not counted
    q_grid = [1e-3, 0.1, 10.0]
    errors, flags = george.kalman_error_vs_q(fixes, truth, q_grid, r_mode="isotropic", r_iso_m2=2.0)
    assert errors.shape == (3, 8) and len(flags) == 3
    for i, q in enumerate(q_grid):
        est, one = george.track_with_kalman(fixes, truth, q=q, r_mode="isotropic", r_iso_m2=2.0, with_divergence=True)
        by_hand = np.sqrt(((est - truth) ** 2).sum(-1)).mean(-1)      # Eq. (15): mean Euclidean error per run
        np.testing.assert_allclose(errors[i], by_hand, rtol=1e-14, equal_nan=True)
        np.testing.assert_array_equal(flags[i].diverged, one.diverged)
    assert np.isnan(errors[:, 3]).all() and np.isfinite(np.delete(errors, 3, axis=1)).all()
