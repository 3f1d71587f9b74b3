"""Ozkaya (2011) simulation tables on the scoreboard: each printed setting compared once, repeats linked to
their first printing, windows from the thesis's own Monte-Carlo error, printed inputs read from the data file."""
import math

import numpy as np
import pytest

import locbook as lb
from locbook.scenarios import ozkaya as oz
from locbook.scenarios import ozkaya_tables as ozt


def test_simulation_channel_and_calibration_constants_come_from_tables_6_1_and_6_2():
    # Sec. 7.2.1: every simulated reader uses Reader 2's offline values of Table 6.1
    p = lb.printed("ozkaya2011")
    assert (oz.ALPHA_DBM, oz.PATH_LOSS_EXP, oz.SIGMA_DB) == tuple(
        float(p.get("Table 6.1", "Reader 2", s).text) for s in ("alpha_dbm", "path_loss_exp", "sigma_db"))
    assert oz.OFFLINE_PARAMETERS["alpha_dbm"][0] == float(p.get("Table 6.1", "Reader 1", "alpha_dbm").text)
    assert oz.AUTO_PARAMETERS["path_loss_exp"][1] == float(p.get("Table 6.2", "Reader 2", "path_loss_exp").text)
    assert len(oz.R3_CALIBRATION_DISTANCES_M[0]) == 5 and len(oz.R3_CALIBRATION_DISTANCES_M[1]) == 3
    assert [r["row"] for r in oz.literature_table("5.3")] == ["elevator", "building wall", "wooden door with windows",
                                                               "separating floors"]


def test_repeated_settings_link_to_their_first_printing():
    """Table 7.5's 'Default (5 m, 8 m)' NN (k = 14) is Table 7.1's 28-cell row; Table 7.45's offline NN repeats it;
    Table 7.3's 5.2 dB row is Table 7.2's 3-reader default; Table 7.46's grid filter is Table 7.7's MMSE column at 5.2
    dB."""
    first = ozt._first_printings()
    cases = {(t, r): c for t, r, col, c in oz.simulation_cases() if col is None}
    assert first[(cases[("7.5", "Default (5 m, 8 m)")], "rmse_m")].id == "Table 7.1 | 28 | rmse_m"
    assert first[(cases[("7.45", "Parameter-based offline NN")], "rmse_m")].id == "Table 7.1 | 28 | rmse_m"
    assert first[(cases[("7.3", "5.2")], "median_m")].id == "Table 7.2 | 3 | median_m"
    assert first[(cases[("7.46", "Grid-based Bayesian")], "rmse_m")].id == "Table 7.7 | MMSE | rmse_m@sigma=5.2"


def test_thesis_monte_carlo_ambiguity_is_two_standard_errors_of_a_thesis_sized_run():
    assert oz.THESIS_RUNS == 1000                                   # Sec. 7.2.1
    assert oz.thesis_monte_carlo_ambiguity(0.03, 1000).size == pytest.approx(0.06)
    # from 250 runs our SE is twice the thesis's: the ambiguity is half of 2 of our SEs
    assert oz.thesis_monte_carlo_ambiguity(0.06, 250).size == pytest.approx(0.06)


def test_record_tables_compares_each_printed_value_once(tmp_path, monkeypatch):
    monkeypatch.setenv("LOCBOOK_OUTPUT_DIR", str(tmp_path))
    monkeypatch.setenv("LOCBOOK_EXPERIMENT", "ozkaya2011-nn-sim")
    report = lb.Report()
    n_runs = 60
    # every simulation reading is supported by the text: rows computed under either noise reading are
    # reproductions
    rows = oz.run_tables(["7.2", "7.3", "7.6"], n_runs, 5, interpretations={"reader_noise": "common_mode"})
    oz.record_tables(report, rows, n_runs)
    recorded = report.numbers
    assert all(r["kind"] == "reproduction" and not r["calibrated_from"] for r in recorded)
    assert not any("crlb" in r["printed_id"] for r in recorded)       # CRLB is compared in ozkaya2011-crlb only
    judged = [r["printed_id"] for r in recorded if r["verdict"]]
    assert len(judged) == len(set(judged))
    ids = {r["printed_id"] for r in recorded}
    linked = [r for r in recorded if r["same_as"]]
    assert linked and all(r["same_as"] in ids and r["verdict"] == "" for r in linked)
    # Table 7.3's 5.2 dB row and Table 7.6's '40 / 3' row are the default of Table 7.2 row 3
    assert {r["printed_id"] for r in linked if r["same_as"] == "Table 7.2 | 3 | rmse_m"} >= {
        "Table 7.3 | 5.2 | rmse_m", "Table 7.6 | 40 / 3 | rmse_m"}
    for r in recorded:
        if r["verdict"] in ("miss", "loose"):
            assert r["note"]
        if r["verdict"]:
            # window = rounding + 2 SE + the thesis's own MC error
            half = r["rounding"] + 2 * r["mc_std_error"] + r["ambiguity"]
            assert r["window_high"] - float(r["printed"]) == pytest.approx(half)
            assert math.isfinite(r["mc_std_error"]) and r["mc_std_error"] > 0


def test_statistic_standard_errors_shrink_with_the_number_of_runs():
    case = oz.SimCase("nn")
    # 400 runs at least: a 100-run bootstrap SE of the 90th percentile scatters from 2.4 to 7 times the 1600-run one
    se = {n: oz.summarize(oz.run_case(case, n, 3), np.random.default_rng(0)) for n in (400, 6400)}
    for stat in oz.STATISTICS:
        ratio = se[400][stat + "_se"] / se[6400][stat + "_se"]
        # sqrt(16) = 4 within bootstrap scatter (no shrinking gives 1, a 1/n law 16)
        assert 2.0 < ratio < 8.0, stat
