"""George and Vadivukkarasi (locbook.scenarios.george): runs whose calibration failed have no fixes and are left out
of the notebooks' statistics and counted (docs/filters.md, "Missing readings and bad input"), never averaged in as
NaN."""
import numpy as np
import pytest

import locbook as lb
from locbook.scenarios import george


def _hand_built_runs():
    """Three runs on the 25 marked points: run 0 off by (0.3, 0.4) m everywhere (C = 0.5 m), run 1 failed its
    calibration (no fixes), run 2 off by (0.6, 0.8) m (C = 1.0 m)."""
    truth = george.trajectory_m()
    fixes = np.stack([truth + [0.3, 0.4], np.full(truth.shape, np.nan), truth + [0.6, 0.8]])
    ok = np.array([True, False, True])
    runs = george.CorridorRuns(truth, np.zeros((5, 2)), np.zeros((3, 5, 4)), np.full(3, -45.0),
                               np.array([2.2, 0.7, 2.1]), np.zeros((3, truth.shape[0], 4)), fixes, ok)
    return truth, runs


def test_failed_calibration_is_left_out_of_the_single_experiment_window_and_counted():
    _, runs = _hand_built_runs()
    c_all = lb.mean_error_m(runs.fix_error_m, axis=-1)
    assert np.isnan(c_all[1])
    # the notebook's scoring before the fix: a NaN run breaks the window
    with pytest.raises(ValueError, match="NaN or inf"):
        lb.Ambiguity.single_experiment(c_all, what="one walk", source="test")
    c = runs.calibrated(c_all)
    np.testing.assert_allclose(c, [0.5, 1.0], rtol=1e-12)
    amb = lb.Ambiguity.single_experiment(c, what="one walk", source="test")
    assert amb.size == pytest.approx(2.0 * np.std([0.5, 1.0], ddof=1), rel=1e-12)
    note = runs.failed_calibration_note()
    assert "1 of 3 runs left out" in note and "over the other 2" in note
    assert runs.failed_calibration_note("q = 0.01").startswith("q = 0.01; 1 of 3")


def test_calibrated_selects_runs_along_the_given_axis_and_checks_its_length():
    _, runs = _hand_built_runs()
    by_q = np.arange(6.0).reshape(2, 3)                       # (q, runs)
    np.testing.assert_array_equal(runs.calibrated(by_q, axis=1), [[0.0, 2.0], [3.0, 5.0]])
    np.testing.assert_array_equal(runs.calibrated(runs.fix_error_m), runs.fix_error_m[[0, 2]])
    with pytest.raises(ValueError, match="one entry per run"):
        runs.calibrated(by_q)                                  # axis 0 holds 2 entries, not 3 runs


@pytest.mark.parametrize("offset, failed", [(-0.01, False), (0.01, True)])
def test_noise_free_calibration_fails_exactly_below_the_threshold(offset, failed):
    """Without shadowing the fit returns the true exponent, so the rule turns on at it; a successful run's fixes are
    exact and nothing is counted, a failed one has none."""
    n_true = 2.0
    truth = george.trajectory_m()
    rng = lb.streams(7, "calibration", "tracking")
    runs = george.simulate_corridor(4, truth, lb.PathLossModel(-45.0, n_true, 0.0), rng_calibration=rng["calibration"],
                                    rng_tracking=rng["tracking"], min_path_loss_exp=n_true + offset)
    np.testing.assert_allclose(runs.path_loss_exp, n_true, rtol=1e-9)
    assert runs.n_failed_calibrations == (4 if failed else 0)
    if failed:
        assert np.isnan(runs.fixes_m).all() and runs.calibrated(runs.fix_error_m).shape == (0, truth.shape[0])
        assert runs.failed_calibration_note().startswith("4 of 4 runs left out")
    else:
        np.testing.assert_allclose(runs.fixes_m, np.broadcast_to(truth, runs.fixes_m.shape), atol=1e-9)
        assert runs.failed_calibration_note("x") == "x"


def test_at_6_db_the_only_runs_without_c_are_those_whose_fitted_exponent_is_below_one():
    """The notebook's failing case (sigma 6 dB, the reading's range end): an independent per-location fit (numpy
    polyfit of P = A - 10 n log10 d, averaged over the five points, Sec. 6) finds the failed runs, and every other run
    has a finite C, so the scored window can be built."""
    truth = george.trajectory_m()
    rng = lb.streams(20150, "calibration", "tracking")
    runs = george.simulate_corridor(300, truth, lb.PathLossModel(-45.0, george.PRINTED_N.value, 6.0),
                                    rng_calibration=rng["calibration"], rng_tracking=rng["tracking"])
    x = -10.0 * np.log10(lb.pairwise_distance_m(np.asarray(george.DEFAULT_CALIBRATION_POINTS_M), george.ANCHORS_M))
    n_hand = np.array([[np.polyfit(x[i], runs.calibration_rss_dbm[r, i], 1)[0] for i in range(x.shape[0])]
                       for r in range(300)]).mean(axis=1)
    c_all = lb.mean_error_m(runs.fix_error_m, axis=-1)
    np.testing.assert_array_equal(~np.isfinite(c_all), n_hand < george.MIN_PLAUSIBLE_PATH_LOSS_EXP)
    assert runs.n_failed_calibrations > 0                     # the case the notebook met
    c = runs.calibrated(c_all)
    assert c.size == 300 - runs.n_failed_calibrations and np.isfinite(c).all()
    lb.Ambiguity.single_experiment(c, what="one walk", source="test")


def test_the_setup_agrees_with_the_numbers_the_paper_prints():
    """The printed-values table holds every number of the paper; the scenario's setup follows it: four anchors at the
    corridor's corners, five calibration locations inside it, 25 marked points, the TX power levels from 3 to 31."""
    p = george.PRINTED

    def value(location, item, statistic):
        return p.get(location, item, statistic).value

    width, length = value("Sec. 5", "corridor", "width"), value("Sec. 5", "corridor", "length")
    assert len(george.ANCHORS_M) == value("Sec. 5", "anchors", "count") == 4
    assert {tuple(a) for a in george.ANCHORS_M} == {(0.0, 0.0), (width, 0.0), (0.0, length), (width, length)}
    cal = np.array(george.DEFAULT_CALIBRATION_POINTS_M)
    assert len(cal) == value("Sec. 6", "calibration locations", "count")
    assert np.all((cal > 0) & (cal < [width, length]))
    assert george.trajectory_m().shape == (value("Fig. 5", "marked trajectory points", "cross 1-25"), 2)
    levels = sorted(george.CC2420_PA_LEVEL_DBM)
    assert (levels[0], levels[-1]) == (value("Sec. 2.C", "TX power level", "lowest"),
                                       value("Sec. 2.C", "TX power level", "highest"))


def test_no_george_default_is_fitted_and_the_fitted_sigma_is_only_an_alternative():
    # 1.83 dB was chosen from the printed C without filter; the default is the assumed sigma
    from locbook.reproduce.interpretations import interpretations
    rows = {r.name: r for r in interpretations("george")}
    assert all(r.basis != "fitted" for r in rows.values())
    for name in ("shadowing", "crlb_shadowing"):
        r = rows[name]
        assert george.SIGMA_FITTED_DB in r.fitted and r.default != george.SIGMA_FITTED_DB
        assert r.low <= r.default <= r.high
    # Eq. (8) differences the other anchors against anchor 1, the first listed corner (Sec. 5): reference row 0
    assert rows["reference_anchor"].default == 0 and tuple(george.ANCHORS_M[0]) == (0.0, 0.0)


def test_track_with_kalman_old_standard_variant_warns_at_the_caller_and_gives_the_same_numbers():
    """``variant="standard"`` (the earlier keyword) is ``"corrected"`` for one release."""
    truth = george.trajectory_m("centerline")
    fixes = truth + np.random.default_rng(2).standard_normal((4,) + truth.shape)
    with pytest.warns(DeprecationWarning, match=r"track_with_kalman\(variant='standard'\) is deprecated: use "
                                                r"track_with_kalman\(variant='corrected'\)") as caught:
        old = george.track_with_kalman(fixes, truth, q=0.05, variant="standard")
    assert len(caught) == 1 and caught[0].filename == __file__
    np.testing.assert_array_equal(old, george.track_with_kalman(fixes, truth, q=0.05))
