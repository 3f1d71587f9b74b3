"""The scoreboard's rules (locbook/reproduce/scoring.py), the printed-values files and the report rows built on them."""
import csv
import math

import pytest

import locbook as lb
from locbook.reproduce.printed_values import PRINTED_DIR, printed_number, printed_rounding
from locbook.reproduce.scoring import WITHIN_LIMIT, score
from locbook.suite import site


@pytest.mark.parametrize("text, value, rounding", [
    ("2.2867", 2.2867, 0.00005), ("1.0", 1.0, 0.05), ("24", 24.0, 0.5), ("about 6", 6.0, 0.5),
    ("more than 50%", 50.0, 0.5), ("-42", -42.0, 0.5), ("1.5e-3", 1.5e-3, 0.5e-4), ("0.00023", 0.00023, 0.000005),
])
def test_printed_text_gives_its_number_and_half_a_unit_in_its_last_digit(text, value, rounding):
    assert printed_number(text) == value
    assert math.isclose(printed_rounding(text), rounding, rel_tol=1e-12)


@pytest.mark.parametrize("text", ["", "n/a", "1.54 -> 0.86"])
def test_a_text_without_exactly_one_number_is_refused(text):
    with pytest.raises(ValueError, match="exactly one number"):
        printed_number(text)


def test_window_is_rounding_plus_two_standard_errors_plus_the_named_ambiguity():
    amb = lb.Ambiguity(0.10, "cell layout", "Ozkaya 2011 Sec. 7.2.1")
    s = score("reproduction", "1.87", 1.90, mc_std_error=0.02, ambiguity=amb)
    assert math.isclose(s.half_width, 0.005 + 0.04 + 0.10)
    assert math.isclose(s.low, 1.87 - 0.145) and math.isclose(s.high, 1.87 + 0.145)
    assert s.verdict == "within"
    assert score("reproduction", "1.87", 1.87 + 0.146, mc_std_error=0.02, ambiguity=amb).verdict == "miss"
    assert score("reproduction", "1.87", 1.87 - 0.144, mc_std_error=0.02, ambiguity=amb).verdict == "within"


def test_a_window_wider_than_a_quarter_of_the_printed_value_is_loose_never_within():
    wide = lb.Ambiguity(0.26 * 2.0, "one measured run", "doc Sec. 5")
    assert score("reproduction", "2.00", 2.0, ambiguity=wide).verdict == "loose"
    narrow = lb.Ambiguity(0.24 * 2.0 - 0.005, "one measured run", "doc Sec. 5")
    assert score("reproduction", "2.00", 2.0, ambiguity=narrow).verdict == "within"
    assert WITHIN_LIMIT == 0.25
    # a calibrated row follows the same window rules
    assert score("calibrated", "2.00", 2.0, ambiguity=wide).verdict == "loose"


def test_a_one_sided_claim_is_checked_as_stated():
    # "more than 50 %": 48.9 is a miss, whatever window a two-sided reading would give
    assert score("claim", "more than 50%", 48.9, relation=">", mc_std_error=0.5).verdict == "miss"
    assert score("claim", "more than 50%", 52.0, relation=">", mc_std_error=0.5).verdict == "within"
    assert score("claim", "more than 50%", 50.6, relation=">", mc_std_error=0.5).verdict == "loose"
    s = score("claim", "more than 50%", 52.0, relation=">")
    assert s.low == 50 and s.high == math.inf
    assert score("claim", "below 4 m", 3.0, relation="<").verdict == "within"
    assert score("claim", "EKF better than KF", -0.1, relation="<", threshold=0.0).verdict == "within"
    with pytest.raises(ValueError, match="relation"):
        score("claim", "more than 50%", 52.0)
    with pytest.raises(ValueError, match="no ambiguity"):
        score("claim", "more than 50%", 52.0, relation=">", ambiguity=lb.Ambiguity(1, "x", "y"))


def test_arithmetic_shown_and_linked_rows():
    assert score("arithmetic", "1.55", 1.554).verdict == "consistent"
    assert score("arithmetic", "1.55", 1.56).verdict == "inconsistent"
    assert score("shown", "1.55", None).verdict == ""
    assert score("reproduction", "1.55", 9.0, linked=True).verdict == ""
    with pytest.raises(ValueError, match="kind"):
        score("agreement", "1.55", 1.55)
    with pytest.raises(ValueError, match="finite reproduced"):
        score("reproduction", "1.55", float("nan"))


def test_ambiguity_needs_a_size_a_name_and_a_source():
    with pytest.raises(ValueError, match="source"):
        lb.Ambiguity(0.1, "layout", "")
    with pytest.raises(ValueError, match="size"):
        lb.Ambiguity(-0.1, "layout", "Sec. 1")


def _report(tmp_path, monkeypatch):
    monkeypatch.setenv("LOCBOOK_OUTPUT_DIR", str(tmp_path))
    monkeypatch.setenv("LOCBOOK_EXPERIMENT", "george-tracking")
    return lb.Report()


def test_report_rows_keep_the_printed_text_and_name_calibrations(tmp_path, monkeypatch):
    report = _report(tmp_path, monkeypatch)
    c_raw = lb.printed("george").get("Fig. 5 text", "mean error C without filter", "Eq. (15), 25 points")
    with pytest.raises(ValueError, match="calibrated_from"):
        report.number("C", c_raw, 2.3, kind="calibrated")
    with pytest.raises(TypeError, match="Printed"):
        report.number("C", 2.2867, 2.3, kind="reproduction")
    row = report.number("C", c_raw, 2.3, kind="calibrated", calibrated_from="sigma chosen from 2.2867 m")
    assert row["printed"] == "2.2867" and row["verdict"] == "miss"     # window: rounding only
    with open(tmp_path / "numbers.csv") as fh:
        written = list(csv.DictReader(fh))
    assert written[0]["printed"] == "2.2867" and tuple(written[0]) == lb.reproduce.report.NUMBER_COLUMNS
    wide = report.number("C", c_raw, 2.3, kind="reproduction",
                         ambiguity=lb.Ambiguity(1.0, "one walk", "George Sec. 6"))
    assert wide["verdict"] == "loose" and "one walk" in wide["note"]
    assert wide["window_low"] >= 0                                     # an error in metres is not negative


def test_repeats_link_to_the_compared_quantity_and_are_counted_once(tmp_path, monkeypatch):
    report = _report(tmp_path, monkeypatch)
    oz = lb.printed("ozkaya2011")
    first, again = oz.get("Table 7.1", "28", "rmse_m"), oz.get("Table 7.5", "Default (5 m, 8 m)", "rmse_m")
    assert first.text == again.text
    report.number("rmse", first, first.value, kind="reproduction")
    linked = report.number("rmse", again, first.value, kind="reproduction", same_as=first)
    assert linked["verdict"] == "" and linked["same_as"] == first.id and "compared there" in linked["note"]
    counts = site.scoreboard_counts(report.numbers)
    assert counts["reproduction"]["within"] == 1 and counts["reproduction"]["linked"] == 1
    assert site.double_counted(report.numbers) == []
    report.number("rmse", first, first.value, kind="reproduction")
    assert site.double_counted(report.numbers) == [("ozkaya2011", first.id, ["george-tracking"] * 2)]


def test_every_printed_values_file_is_well_formed():
    for path in sorted(PRINTED_DIR.glob("*.csv")):
        values = lb.printed(path.stem)
        assert len(values) > 0
        for p in values:
            if p.statistic == "claim" and not any(c.isdigit() for c in p.text):
                continue                            # a quoted statement: the row that checks it gives the threshold
            printed_number(p.text)                  # each printed text holds exactly one number
    with pytest.raises(KeyError, match="known"):
        lb.printed("nobody2099")


def test_single_experiment_ambiguity_is_k_sample_standard_deviations():
    import statistics
    runs = [2.1, 2.6, 1.9, 2.4, 3.0, 2.2]
    amb = lb.Ambiguity.single_experiment(runs, "one walk", "Sec. 6")
    assert math.isclose(amb.size, 2 * statistics.stdev(runs), rel_tol=1e-14)
    assert math.isclose(lb.Ambiguity.single_experiment(runs, "one walk", "Sec. 6", k=1.0).size, statistics.stdev(runs),
                        rel_tol=1e-14)
    assert (amb.what, amb.source) == ("one walk", "Sec. 6")
    with pytest.raises(ValueError, match="at least two finite"):
        lb.Ambiguity.single_experiment([2.0], "one walk", "Sec. 6")
    with pytest.raises(ValueError, match="NaN or inf"):
        lb.Ambiguity.single_experiment([2.0, float("nan"), 3.0], "one walk", "Sec. 6")


def test_spread_ambiguity_is_the_largest_distance_from_our_reading():
    assert lb.Ambiguity.spread([1.2, 0.7, 1.05], 1.0, "three curves", "Fig. 3.4").size == pytest.approx(0.3, abs=1e-15)
    assert lb.Ambiguity.spread([4, 6], 5, "tolerance halved or doubled", "Sec. 7").size == 1.0
    with pytest.raises(ValueError, match="at least one value"):
        lb.Ambiguity.spread([], 1.0, "none", "nowhere")


def test_ozkaya_settling_reading_moves_with_the_tolerance_as_counted_by_hand():
    from locbook.scenarios import ozkaya as oz
    curve = [5.0, 3.0, 1.0, 0.35, 0.18, 0.12, 0.1, 0.1, 0.1]     # final value 0.1
    # within 0.1 of 0.1 from 0.18 (recursion 5); within 0.05 from 0.12 (6); within 0.2 also from 0.18 (5)
    settled, amb = oz.settling_interpretation(curve, 0.1, "Sec. 7.2.2.2")
    assert settled == 5 and amb.size == 1.0 and amb.source == "Sec. 7.2.2.2" and "0.1 m" in amb.what


def test_index_cells_are_shaded_by_the_share_of_each_verdict():
    """120 within and 15 missed shades a cell 88.9 % green and 11.1 % red, not solid red."""
    from collections import Counter

    from locbook.suite.pages import verdict_shares as _shares
    style = _shares(Counter(within=120, miss=15))
    assert style == "background: linear-gradient(to right, var(--within) 0.0% 88.9%, var(--miss) 88.9% 100.0%)"
    assert _shares(Counter()) == ""
    assert _shares(Counter(loose=1)) == "background: linear-gradient(to right, var(--loose) 0.0% 100.0%)"


def test_verdict_counts_read_in_one_fixed_order_not_by_size():
    """The scoreboard and `locbook list` count a kind's rows in VERDICT_COLUMNS order whatever the sizes: two runs
    whose counts differ read column by column (a miss never jumps ahead of within because it is more common)."""
    from collections import Counter

    from locbook.reproduce.scoring import VERDICT_COLUMNS, verdict_counts_text
    assert VERDICT_COLUMNS[:3] == ("within", "loose", "miss")
    assert verdict_counts_text(Counter({"miss": 5, "within": 1, "no verdict": 2})) == "1 within, 5 miss, 2 no verdict"
    assert verdict_counts_text(Counter({"within": 5, "miss": 1, "linked": 0})) == "5 within, 1 miss"
    assert verdict_counts_text(Counter()) == ""
