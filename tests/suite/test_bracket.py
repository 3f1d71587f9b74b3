"""``locbook bracket``: points from declared readings, bracket verdicts of a toy notebook whose arithmetic is known
(value = 10 a + b + seed against a printed 16.0; twice = 2 a against a printed 3.0), the findings page, and the
bracket columns of the suite's numbers.csv."""
import csv
import re
import textwrap

import pytest

from locbook.reproduce.interpretations import interpretations_for, load_interpretation_file
from locbook.suite import SuiteError, load_suite
from locbook.suite.bracket import (
    BRACKET_COLUMNS,
    SITE_NUMBER_COLUMNS,
    bracket_gaps,
    bracket_of_rows,
    bracket_points,
    bracket_rows,
    experiment_interpretations,
    find_experiment,
)
from locbook.suite.cli import main
from toy_suite import HEADER, READINGS

OFFSET_ONLY = f"""{HEADER}
offset,george-study,b,,0.0,[0.5],,,,printed,Table 9,toy offset
"""
WITH_GAP = f"""{HEADER}
offset,george-study,b,,0.0,[0.5],,,,printed,Table 9,toy offset
hidden,george-study,,locbook.toy.HIDDEN,1,[2],,,,assumed,Table 9,a module constant no parameter sets
"""


def _readings(tmp_path, text, name="george.csv"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def _suite(toy):
    return load_suite(toy / "notebooks" / "experiments.toml")


def bracket(toy, readings, *args, reports="reports"):
    return main(["--suite", str(toy / "notebooks" / "experiments.toml"), "bracket", "george-study", "--interpretations",
                 str(readings), "--reports", str(toy / reports), "--progress", "plain", *args])


def _table(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


# -- the points ---------------------------------------------------------------------------------------------

def test_points_are_the_default_then_each_other_value_one_reading_at_a_time(stoy, tmp_path):
    exp = find_experiment(_suite(stoy), "george-study")
    found = experiment_interpretations(exp, load_interpretation_file(_readings(tmp_path, READINGS)))
    points = bracket_points(exp, "quick", found)
    assert [p.label for p in points] == ["default", "slope: a=1.3", "slope: a=0.0", "slope: a=2.0", "offset: b=0.5"]
    assert points[0].parameters == {"seed": 3}                           # the profile's own values
    assert points[1].parameters == {"seed": 3, "a": 1.3}                 # one reading changed, the rest as profiled
    assert len({p.key for p in points}) == len(points)


def test_a_value_equal_to_the_profile_is_not_run_twice_and_shared_values_share_a_point(stoy, tmp_path):
    exp = find_experiment(_suite(stoy), "george-study")
    text = (f"{HEADER}\nslope,george-study,a,,1.0,[1.3],,1.0,2.0,assumed,s,r\n"
            "same,george-study,a,,,[2.0],[2.0],,,assumed,s,r\n")
    points = bracket_points(exp, "quick", load_interpretation_file(_readings(tmp_path, text)))
    # the range's low end equals the default (1.0): skipped; a = 2.0 is named by both readings: one point, marked
    # fitted for the reading that declares it so
    assert [p.label for p in points] == ["default", "slope: a=1.3", "slope, same [fitted]: a=2.0"]


def test_a_shared_point_keeps_its_own_key_when_a_later_reading_names_it_again(stoy, tmp_path):
    # 'same' names a = 2.0, which 'slope' made its first alternative point, not its last: the merged point must keep
    # its own folder (key), not the key of the point appended last (found in review: two points shared a folder)
    exp = find_experiment(_suite(stoy), "george-study")
    text = (f"{HEADER}\nslope,george-study,a,,1.0,\"[2.0, 1.3]\",,,,assumed,s,r\n"
            "same,george-study,a,,,[2.0],,,,assumed,s,r\n")
    points = bracket_points(exp, "quick", load_interpretation_file(_readings(tmp_path, text)))
    assert [p.label for p in points] == ["default", "slope, same: a=2.0", "slope: a=1.3"]
    assert len({p.key for p in points}) == len(points)


def test_a_reading_value_the_notebook_refuses_is_an_error_before_anything_runs(stoy, tmp_path):
    exp = find_experiment(_suite(stoy), "george-study")
    bad = load_interpretation_file(_readings(tmp_path, f"{HEADER}\nslope,george-study,a,,1.0,[7.0],,,,assumed,s,r\n"))
    with pytest.raises(SuiteError, match=r"interpretation george/slope of 'george-study'.*'a' = 7.0 is not allowed"):
        bracket_points(exp, "quick", bad)
    unknown = load_interpretation_file(
        _readings(tmp_path, f"{HEADER}\nslope,george-study,nope,,1.0,[2.0],,,,assumed,s,r\n"))
    with pytest.raises(SuiteError, match="names parameter 'nope', which 'george-study' does not declare"):
        bracket_points(exp, "quick", unknown)
    with pytest.raises(SuiteError, match="no interpretations are declared for experiment 'george-study'"):
        other = OFFSET_ONLY.replace("george-study", "x-y")
        experiment_interpretations(exp, load_interpretation_file(_readings(tmp_path, other)))


def test_gaps_are_the_unswept_readings_that_name_other_values(tmp_path):
    found = load_interpretation_file(_readings(tmp_path, WITH_GAP))
    assert [r.name for r in bracket_gaps(found)] == ["hidden"]
    # a gap with nothing else to try cannot move a row
    assert bracket_gaps(load_interpretation_file(_readings(tmp_path, WITH_GAP.replace("[2]", "[]")))) == []


def test_a_bad_readings_file_is_one_line_and_exit_status_2(stoy, tmp_path, capsys):
    path = _readings(tmp_path, f"{HEADER}\nslope,george-study,a,,1.0,[1.0],,,,assumed,s,r\n")
    assert bracket(stoy, path) == 2
    err = capsys.readouterr().err
    assert "the default 1.0 is also among the alternatives" in err and "Traceback" not in err


def test_the_declared_readings_of_every_experiment_give_valid_points():
    """Every packaged reading names a parameter and values its notebook accepts (checked as a bracket would)."""
    suite = load_suite()
    for exp in suite.experiments:
        found = interpretations_for(exp.id)
        if found:
            points = bracket_points(exp, "quick", found)
            assert points[0].label == "default"


# -- verdicts ------------------------------------------------------------------------------------------------

@pytest.mark.notebooks
def test_a_toy_bracket_gives_each_row_its_verdict_and_the_site_shows_it(stoy, tmp_path, capsys):
    assert main(["--suite", str(stoy / "notebooks" / "experiments.toml"), "run", "george-study", "--reports",
                 str(stoy / "reports"), "--progress", "plain"]) == 0
    assert bracket(stoy, _readings(tmp_path, READINGS), "--jobs", "2") == 0
    out = capsys.readouterr().out
    # the live lines and the scoreboard name each point by its interpretation and value, never by its folder's hash
    assert re.findall(r"george-study-[0-9a-f]{6,}", out) == []
    for label in ("slope: a=1.3", "slope: a=0.0", "slope: a=2.0", "offset: b=0.5"):
        assert f"running {label} ..." in out and re.search(rf"^{re.escape(label)}\s+ok\b", out, re.M), label
    assert re.search(r"^default\s+cached\b", out, re.M)
    # the default point is the quick report run just before: reused, not executed again
    assert "4 executed, 1 cached" in out and "default: the same run as" in out
    assert ("bracket of george-study: 0 default, 1 other_interpretation, 0 fitted_only, "
                                    "0 between, "
                                    "0 outside, 0 open, 1 loose") in out
    folder = stoy / "reports" / "brackets" / "george-study"
    rows = {r["quantity"]: r for r in _table(folder / "bracket.csv")}
    assert tuple(_table(folder / "bracket.csv")[0]) == BRACKET_COLUMNS
    # value = 10 a + b + 3: 13 by default (window 16 +- (0.05 + 2 x 0.375 + 1) = 14.2 .. 17.8: a miss), 16 at
    # a = 1.3; over the points a = 1.3, 0, 2 and b = 0.5 it spans 3 .. 23
    value = rows["value"]
    assert value["verdict"] == "miss" and value["bracket"] == "other_interpretation"
    assert value["reached_by"] == "slope: a=1.3" and value["closest_interpretation"] == "slope: a=1.3"
    assert float(value["band_low"]) == pytest.approx(3.0) and float(value["band_high"]) == pytest.approx(23.0)
    assert float(value["closest"]) == pytest.approx(16.0) and value["points"] == "5"
    # twice = 2 a against 3.0 +- 1.05: a window of +-35 % is loose whatever a is, so no reading makes it within;
    # the printed value is inside it by default and at a = 1.3, 2.0 and b = 0.5 (a = 0 gives 0: a miss)
    assert (rows["twice"]["verdict"], rows["twice"]["bracket"]) == ("loose", "loose")
    assert rows["twice"]["loose_under"] == "default; slope: a=1.3; slope: a=2.0; offset: b=0.5"
    assert (rows["twice"]["band_low"], rows["twice"]["band_high"]) == ("0", "4")
    points = _table(folder / "points.csv")
    assert [p["status"] for p in points] == ["cached"] + ["ok"] * 4 and points[1]["value"] == "1.3"
    import json  # the points ran without figures (only their numbers are read); the reused default with them
    for point in folder.glob("george-study-*"):
        saved = json.loads((point / "manifest.json").read_text()).get("figures_saved", True)
        assert saved is (point.name == "george-study-default"), point.name
    assert (folder / "george-study-default" / "george-study.ipynb").read_bytes() == \
        (stoy / "reports" / "quick" / "george-study" / "george-study.ipynb").read_bytes()
    # every scored row under every point, for the conclusions pages
    values = _table(folder / "values.csv")
    assert len(values) == 2 * 5 and {v["basis"] for v in values} == {"default", "assumed", "textual"}
    # a second bracket serves every point from its cache (figureless reports validate as such)
    assert bracket(stoy, _readings(tmp_path, READINGS), "--jobs", "2") == 0
    assert "0 executed, 5 cached" in capsys.readouterr().out

    # the suite's numbers.csv carries each row's bracket once the site is rebuilt (any later run; --force renders
    # the experiment's page again too)
    assert main(["--suite", str(stoy / "notebooks" / "experiments.toml"), "run", "george-study", "--reports",
                 str(stoy / "reports"), "--progress", "plain", "--force"]) == 0
    site = _table(stoy / "reports" / "quick" / "numbers.csv")
    assert tuple(site[0]) == SITE_NUMBER_COLUMNS
    by = {r["quantity"]: r for r in site}
    assert (by["value"]["bracket"], by["value"]["bracket_interpretations"]) == ("other_interpretation",
                                                                               "at quick: slope: a=1.3")
    assert (by["twice"]["bracket"], by["twice"]["bracket_interpretations"]) == (
        "loose", "this report; at quick: slope: a=1.3; slope: a=2.0; offset: b=0.5")
    # the experiment's page (rendered when it ran, after the bracket) shows each row's bracket beside its verdict
    page = (stoy / "reports" / "quick" / "george-study" / "report.md").read_text()
    assert "| verdict | bracket | bracket_interpretations |" in page
    assert "| other_interpretation | at quick: slope: a=1.3 |" in page
    index = (stoy / "reports" / "quick" / "index.md").read_text()
    assert ("Interpretation brackets of the 2 scored rows (`quick` profile): 0 reproduced under the default "
            "interpretation; 1 reproduced only under another textual (or assumed) interpretation; 0 reached only "
            "under an interpretation fitted") in index
    assert "[george](george-findings.md)" in index and "This is the `quick` profile" in index
    # the findings page is written from the same rows as numbers.csv and the index
    findings = (stoy / "reports" / "quick" / "george-findings.md").read_text()
    assert "default 0; other interpretation 1; fitted only 0; between 0; outside 0; open 0; loose 1" in findings
    assert "## Other interpretation (1)" in findings and "slope: a=1.3" in findings

    # a -p run's rows were computed under another reading than the bracket's default: no bracket there
    assert main(["--suite", str(stoy / "notebooks" / "experiments.toml"), "run", "george-study", "--reports",
                 str(stoy / "reports"), "--progress", "plain", "-p", "a=1.3"]) == 0
    (custom,) = (stoy / "reports").glob("quick-a-1-3-*")
    assert {r["bracket"] for r in _table(custom / "numbers.csv")} == {""}
    # only the offset reading: nothing reaches value (13 and 13.5): outside, with its band
    assert bracket(stoy, _readings(tmp_path, OFFSET_ONLY), reports="offset") == 0
    value = {r["quantity"]: r for r in _table(stoy / "offset" / "brackets" / "george-study" / "bracket.csv")}["value"]
    assert value["bracket"] == "outside" and (value["band_low"], value["band_high"]) == ("13", "13.5")
    # a gap that names other values leaves it open, naming the gap
    assert bracket(stoy, _readings(tmp_path, WITH_GAP), reports="gap") == 0
    value = {r["quantity"]: r for r in _table(stoy / "gap" / "brackets" / "george-study" / "bracket.csv")}["value"]
    assert value["bracket"] == "open" and value["open_interpretations"] == "hidden (gap: locbook.toy.HIDDEN)"


def test_the_site_bracket_of_a_row_follows_its_own_verdict_first():
    """bracket_of_rows: a row within in this report is 'default' whatever the bracket's profile said; otherwise
    the bracket's other readings decide; unscored and unmatched rows have none."""
    bracket = [{"printed_id": "p", "quantity": "q", "where": "w", "bracket": "other_interpretation",
                "reached_by": "r: x=1",
                "open_interpretations": "", "band_low": "1", "band_high": "2", "points": "3", "profile": "quick"},
               {"printed_id": "o", "quantity": "q (500 runs)", "where": "w", "bracket": "outside", "reached_by": "",
                "open_interpretations": "", "band_low": "1", "band_high": "2", "points": "3", "profile": "quick"}]
    row = {"printed_id": "p", "quantity": "q", "where": "w", "kind": "reproduction"}
    out = bracket_of_rows([{**row, "verdict": "within"}, {**row, "verdict": "miss"},
                           {**row, "verdict": "consistent", "kind": "arithmetic"},
                           # another profile's run count in the quantity: matched on (printed_id, where)
                           {**row, "printed_id": "o", "quantity": "q (20 runs)", "verdict": "miss"},
                           # loose here: at worst loose, whatever the bracket's own runs gave
                           {**row, "printed_id": "o", "quantity": "q (20 runs)", "verdict": "loose"},
                           {**row, "printed_id": "z", "verdict": "miss"}], bracket)
    assert [(r["bracket"], r["bracket_interpretations"]) for r in out] == [
        ("default", ""), ("other_interpretation", "at quick: r: x=1"), ("", ""),
        ("outside", "at quick: band 1 .. 2 over 3 runs"),
        ("loose", "this report"), ("", "")]
    # within under the default at the bracket's profile, a miss here (another profile's window): open, not outside,
    # and not reachable either (the other readings were judged by the wider windows too)
    for b in ({**bracket[1], "bracket": "default"}, {**bracket[0], "bracket": "default"}):
        (row,) = bracket_of_rows([{**row, "printed_id": b["printed_id"], "quantity": "q", "verdict": "miss"}], [b])
        assert row["bracket"] == "open" and "within at quick under the default interpretation, not here" in \
            row["bracket_interpretations"]
    # at the bracket's own profile a value other than its default run's means a stale bracket: open, named so
    b = {**bracket[0], "ours": "1.5"}
    same, other, fine = bracket_of_rows([{**row, "verdict": "miss", "reproduced": "1.5000000000001"},
                                         {**row, "verdict": "miss", "reproduced": "1.6"},
                                         {**row, "verdict": "within", "reproduced": "1.6"}], [b], "quick")
    assert same["bracket"] == "other_interpretation"
    assert other["bracket"] == "open" and other["bracket_interpretations"] == (
        "this report and its quick bracket disagree: the bracket's default run gave 1.5, this report 1.6 (made by "
        "other code or parameters; run the older of the two again)")
    assert fine["bracket"] == "default"                 # within here whatever the bracket says
    (full,) = bracket_of_rows([{**row, "verdict": "miss", "reproduced": "1.6"}], [b], "full")
    assert full["bracket"] == "other_interpretation"               # another profile's run: values differ by design


# -- verdicts from hand-written point reports (no notebook) ---------------------------------------------------

def _numbers(folder, *rows):
    from locbook.reproduce.report import NUMBER_COLUMNS
    folder.mkdir(parents=True)
    with open(folder / "numbers.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=NUMBER_COLUMNS)
        writer.writeheader()
        for r in rows:
            writer.writerow({"printed_id": "T | v | ", "quantity": "v", "where": "T, v", "kind": "reproduction",
                             "printed": "16.0", **r})


def _hand_points(stoy, tmp_path, text):
    exp = find_experiment(_suite(stoy), "george-study")
    return exp, bracket_points(exp, "quick", load_interpretation_file(_readings(tmp_path, text)))


RANGE_ONLY = f"{HEADER}\nslope,george-study,a,,1.0,[],,0.0,2.0,assumed,s,r\n"


def test_a_range_whose_runs_straddle_the_printed_value_is_open_not_outside(stoy, tmp_path):
    exp, points = _hand_points(stoy, tmp_path, RANGE_ONLY)
    assert [p.label for p in points] == ["default", "slope: a=0.0", "slope: a=2.0"]
    folder = tmp_path / "b"
    for p, value in zip(points, ("13", "3", "23")):        # 10 a + 3: a miss everywhere, 16 lies between a = 1 and 2
        _numbers(folder / p.key, {"reproduced": value, "verdict": "miss"})
    (row,) = bracket_rows(exp, points, folder, {p.key: "ok" for p in points}, [], "quick")
    assert row["bracket"] == "open" and row["open_interpretations"].startswith("slope between a=1 and 2 (ours 13 .. 23")
    # the same runs on one side of the printed value: every reading misses it
    for p, value in zip(points, ("13", "3", "15")):
        (folder / p.key / "numbers.csv").unlink()
        (folder / p.key).rmdir()
        _numbers(folder / p.key, {"reproduced": value, "verdict": "miss"})
    (row,) = bracket_rows(exp, points, folder, {p.key: "ok" for p in points}, [], "quick")
    assert (row["bracket"], row["band_low"], row["band_high"], row["points"]) == ("outside", "3", "15", 3)


def test_a_point_that_failed_or_did_not_produce_the_row_leaves_it_open(stoy, tmp_path):
    exp, points = _hand_points(stoy, tmp_path, OFFSET_ONLY)
    folder = tmp_path / "b"
    _numbers(folder / points[0].key, {"reproduced": "13", "verdict": "miss"})
    _numbers(folder / points[1].key, {"printed_id": "renamed", "reproduced": "13.5", "verdict": "miss"})
    (row,) = bracket_rows(exp, points, folder, {p.key: "ok" for p in points}, [], "quick")
    assert (row["bracket"], row["open_interpretations"]) == ("open", "offset: b=0.5 (row not produced)")
    (row,) = bracket_rows(exp, points, folder, {points[0].key: "ok", points[1].key: "failed"}, [], "quick")
    assert (row["bracket"], row["open_interpretations"]) == ("open", "offset: b=0.5 (failed)")
    # no default point, no bracket: an earlier bracket.csv is kept as it was
    (folder / "bracket.csv").write_text("kept\n")
    from locbook.suite.bracket import write_bracket_outputs
    from locbook.suite.runner import Outcome
    write_bracket_outputs(exp, points, folder, [Outcome(points[0].key, "interrupted", 1.0),
                                                Outcome(points[1].key, "ok", 1.0)], [], "quick", _suite(stoy))
    assert (folder / "bracket.csv").read_text() == "kept\n"


def test_a_damaged_bracket_file_labels_nothing(tmp_path):
    from locbook.suite.bracket import load_bracket
    (tmp_path / "bracket.csv").write_text("experiment,printed_id\nx,y\n")            # another layout
    assert load_bracket(tmp_path) == []
    (tmp_path / "bracket.csv").write_text(",".join(BRACKET_COLUMNS) + "\nx,y\n")     # a short row
    assert load_bracket(tmp_path) == []
    (tmp_path / "bracket.csv").write_bytes(b"\xff\xfe not utf-8")
    assert load_bracket(tmp_path) == []


def test_int_range_ends_are_the_whole_numbers_inside_the_range():
    from locbook.reproduce.interpretations import Interpretation
    from locbook.suite.bracket import _sweep_values
    r = Interpretation("d", "n", ("e",), "k", "", 1, (), 0.5, 2.5, "assumed", "s", "r")
    assert _sweep_values(r, "int") == [1, 2] and _sweep_values(r, "int | None") == [1, 2]
    assert _sweep_values(r, "float") == [0.5, 2.5]


def test_a_profile_that_sets_a_reading_off_its_default_is_refused(stoy, tmp_path):
    exp = find_experiment(_suite(stoy), "george-study")
    text = f"{HEADER}\nseed_reading,george-study,seed,,7,[8],,,,assumed,s,r\n"     # the quick profile sets seed = 3
    with pytest.raises(SuiteError, match="the quick profile of 'george-study' sets seed = 3, not the declared "
                                         "default 7"):
        bracket_points(exp, "quick", load_interpretation_file(_readings(tmp_path, text)))


def test_values_fitted_together_get_one_joint_point(stoy, tmp_path):
    exp = find_experiment(_suite(stoy), "george-study")
    text = (f"{HEADER}\nslope,george-study,a,,1.0,\"[1.3, 2.0]\",[1.3],,,assumed,s,r\n"
            f"offset,george-study,b,,0.0,[0.5],[0.5],,,assumed,s,r\n")
    points = bracket_points(exp, "quick", load_interpretation_file(_readings(tmp_path, text)))
    assert [p.label for p in points] == ["default", "slope [fitted]: a=1.3", "slope: a=2.0", "offset [fitted]: b=0.5",
                                         "fitted interpretations together [fitted]: a=1.3, b=0.5"]
    assert points[-1].parameters == {"seed": 3, "a": 1.3, "b": 0.5}
    # one fitted reading alone is its own one-at-a-time point: nothing joint
    alone = load_interpretation_file(_readings(tmp_path, text.replace("[0.5],[0.5]", "[0.5],")))
    single = bracket_points(exp, "quick", alone)
    assert not any(p.together for p in single)


def _with_bracket_table(toy, table):
    path = toy / "notebooks" / "experiments.toml"
    text = path.read_text()
    path.write_text(text.replace("a = { ge = 0, le = 5 }\n", "a = { ge = 0, le = 5 }\n" + table, 1))
    return _suite(toy)


def test_bracket_settings_are_set_at_every_point_and_checked(stoy, tmp_path):
    suite = _with_bracket_table(stoy, '[experiment.bracket]\nparameters = { tag = "q" }\nreason = "toy: not scored"\n')
    exp = find_experiment(suite, "george-study")
    points = bracket_points(exp, "quick", load_interpretation_file(_readings(tmp_path, READINGS)))
    assert [p.parameters.get("tag") for p in points] == ["q"] * 5          # the default point too
    assert points[0].parameters == {"seed": 3, "tag": "q"}


def test_a_bracket_setting_may_not_touch_what_the_readings_sweep(stoy, tmp_path):
    exp_a = find_experiment(_with_bracket_table(stoy, '[experiment.bracket]\nparameters = { a = 2.0 }\nreason = "x"\n'),
                            "george-study")
    with pytest.raises(SuiteError, match="sets 'a', a parameter its interpretations sweep"):
        bracket_points(exp_a, "quick", load_interpretation_file(_readings(tmp_path, READINGS)))


@pytest.mark.parametrize("table, message", [
    ('[experiment.bracket]\nparameters = { tag = "q" }\n', r"sets parameters without a 'reason'"),
    ('[experiment.bracket]\nparams = { tag = "q" }\nreason = "x"\n', r"takes a table 'parameters', a string 'reason'"),
    ('[experiment.bracket]\nfactorial = ["a"]\n', r"factorial must list two or more distinct interpretation names"),
    ('[experiment.bracket]\nlargest_error_m = -1.0\nlargest_error_reason = "x"\n',
     r"largest_error_m must be a positive"),
    ('[experiment.bracket]\nlargest_error_m = 9.4\n', r"largest_error_m and largest_error_reason go together"),
])
def test_a_malformed_bracket_table_is_refused(stoy, table, message):
    with pytest.raises(SuiteError, match=message):
        _with_bracket_table(stoy, table)


def test_a_bracket_setting_the_notebook_does_not_declare_is_refused(stoy, tmp_path):
    exp = find_experiment(_with_bracket_table(stoy, '[experiment.bracket]\nparameters = { nope = 1 }\nreason = "x"\n'),
                          "george-study")
    with pytest.raises(SuiteError, match="sets 'nope', which 'george-study' does not declare"):
        bracket_points(exp, "quick", load_interpretation_file(_readings(tmp_path, READINGS)))


# -- bracket points run without figures ------------------------------------------------------------------------

def _figure_report(tmp_path, monkeypatch, off):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import locbook as lb
    monkeypatch.setenv("LOCBOOK_OUTPUT_DIR", str(tmp_path))
    if off:
        monkeypatch.setenv("LOCBOOK_FIGURES", "off")
    else:
        monkeypatch.delenv("LOCBOOK_FIGURES", raising=False)
    report = lb.Report("george-study")
    fig, ax = plt.subplots()
    ax.plot([0, 1], [1, 0])
    report.figure(fig, "line", "a line")
    (tmp_path / "george-study.ipynb").write_text('{"cells": [], "metadata": {}, "nbformat": 4, "nbformat_minor": 5}')
    return fig, plt


def test_figures_off_records_the_caption_saves_no_file_and_the_report_still_validates(tmp_path, monkeypatch):
    import json

    from locbook.suite.runner import _validate_report
    fig, plt = _figure_report(tmp_path, monkeypatch, off=True)
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["figures"] == [{"name": "line", "file": "", "caption": "a line"}]
    assert manifest["figures_saved"] is False
    assert not list(tmp_path.glob("*.png")) and not plt.fignum_exists(fig.number)     # closed unsaved
    assert _validate_report(tmp_path, "george-study", figures=False) == ""
    assert "its figures were not saved" in _validate_report(tmp_path, "george-study")    # a run that wanted them
    # a figure without its file in a report that claims its figures were saved is damage, as before
    manifest.pop("figures_saved")
    (tmp_path / "manifest.json").write_text(json.dumps(manifest))
    assert "listed in the manifest but missing" in _validate_report(tmp_path, "george-study", figures=False)


def test_figures_on_by_default(tmp_path, monkeypatch):
    import json
    _figure_report(tmp_path, monkeypatch, off=False)
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["figures"][0]["file"] == "line.png" and (tmp_path / "line.png").is_file()
    assert "figures_saved" not in manifest


def test_a_run_without_figures_has_its_own_cache_key(stoy, tmp_path):
    from locbook.suite.runner import cache_key
    exp = find_experiment(_suite(stoy), "george-study")
    kw = dict(source="s", versions={"v": "1"})
    assert cache_key(exp, "quick", {"seed": 3}, **kw) == cache_key(exp, "quick", {"seed": 3}, figures=True, **kw)
    assert cache_key(exp, "quick", {"seed": 3}, **kw) != cache_key(exp, "quick", {"seed": 3}, figures=False, **kw)


def test_a_reading_that_requires_another_value_runs_each_of_its_values_with_it(stoy, tmp_path):
    exp = find_experiment(_suite(stoy), "george-study")
    text = (f"{HEADER},requires\nlabel,george-study,tag,,'x',['p'],,,,assumed,s,r,\n"
            f"slope_p,george-study,a,,1.0,,,0.5,2.0,assumed,s,r,{{ tag = 'p' }}\n")
    points = bracket_points(exp, "quick", load_interpretation_file(_readings(tmp_path, text)))
    # a = 1.0 under tag p is the point of tag = 'p' itself: shared; both range ends run with tag = 'p'
    assert [p.label for p in points] == ["default", "label, slope_p: tag='p'", "slope_p: a=0.5 with tag='p'",
                                         "slope_p: a=2.0 with tag='p'"]
    assert points[2].parameters == {"seed": 3, "a": 0.5, "tag": "p"}
    bad = f"{HEADER},requires\nslope_p,george-study,a,,1.0,,,0.5,2.0,assumed,s,r,{{ zz = 1 }}\n"
    with pytest.raises(SuiteError, match="requires parameter 'zz', which 'george-study' does not declare"):
        bracket_points(exp, "quick", load_interpretation_file(_readings(tmp_path, bad)))


def test_a_reading_with_requires_keeps_its_own_default_run_in_the_range_check(stoy, tmp_path):
    """The default value under what a reading requires runs on a point shared with the reading that sets only
    that value; the range check must see it there (found in review: ): 10 a + 3 misses 16 at a = 0.5 (8) and
    at a = 1.0 under tag p (here 20 by hand), straddling it: open, not outside."""
    text = (f"{HEADER},requires\nlabel,george-study,tag,,'x',['p'],,,,assumed,s,r,\n"
            f"slope_p,george-study,a,,1.0,,,0.5,1.0,assumed,s,r,{{ tag = 'p' }}\n")
    exp, points = _hand_points(stoy, tmp_path, text)
    # the range's high end is the default: one point, the reading listed once
    assert [p.label for p in points] == ["default", "label, slope_p: tag='p'", "slope_p: a=0.5 with tag='p'"]
    assert points[1].interpretation_values == {"label": "p", "slope_p": 1.0}
    folder = tmp_path / "b"
    for p, value in zip(points, ("13", "20", "8")):
        _numbers(folder / p.key, {"reproduced": value, "verdict": "miss"})
    (row,) = bracket_rows(exp, points, folder, {p.key: "ok" for p in points}, [], "quick")
    assert row["bracket"] == "open"
    assert row["open_interpretations"].startswith("slope_p between a=0.5 and 1 (ours 8 .. 20")


def test_the_fitted_together_point_is_not_a_run_of_one_range_reading(stoy, tmp_path):
    text = (f"{HEADER}\nslope,george-study,a,,1.0,[1.3],[1.3],0.0,2.0,assumed,s,r\n"
            f"offset,george-study,b,,0.0,[0.5],[0.5],,,assumed,s,r\n")
    exp, points = _hand_points(stoy, tmp_path, text)
    assert points[-1].together
    folder = tmp_path / "b"
    # every one-reading run misses low; only the joint run (a = 1.3 and b = 0.5) lands above 16
    for p, value in zip(points, ("13", "14", "3", "14.5", "13.5", "30")):
        _numbers(folder / p.key, {"reproduced": value, "verdict": "miss"})
    (row,) = bracket_rows(exp, points, folder, {p.key: "ok" for p in points}, [], "quick")
    # no crossing of one range reading is claimed; the printed 16 lies between the runs 14.5 and 30
    assert row["bracket"] == "between" and row["open_interpretations"] == "", row
    assert row["between"] == "slope: a=2.0 (14.5) and fitted interpretations together [fitted]: a=1.3, b=0.5 (30)"


def test_a_bracket_setting_a_profile_sets_is_refused(stoy, tmp_path):
    # the default point must stay the profile's own run: the site compares its rows with the bracket's default
    exp = find_experiment(_with_bracket_table(stoy, '[experiment.bracket]\nparameters = { seed = 4 }\nreason = "x"\n'),
                          "george-study")
    with pytest.raises(SuiteError, match="sets 'seed', which a profile sets"):
        bracket_points(exp, "quick", load_interpretation_file(_readings(tmp_path, OFFSET_ONLY)))


# -- tiers, combinations, Monte-Carlo margins, implausible values -------------------------------------

def test_the_factorial_runs_every_combination_of_the_textual_values(stoy, tmp_path):
    # a = 1.0 (default) or 1.3 (textual) or 2.0 (fitted); b = 0.0 or 0.5: the fitted value is never combined
    text = (f"{HEADER}\nslope,george-study,a,,1.0,\"[1.3, 2.0]\",[2.0],,,printed,s,r\n"
            f"offset,george-study,b,,0.0,[0.5],,,,printed,s,r\n")
    suite = _with_bracket_table(stoy, '[experiment.bracket]\nfactorial = ["slope", "offset"]\n')
    exp = find_experiment(suite, "george-study")
    points = bracket_points(exp, "quick", load_interpretation_file(_readings(tmp_path, text)))
    assert [p.label for p in points] == ["default", "slope: a=1.3", "slope [fitted]: a=2.0", "offset: b=0.5",
                                         "interpretations together: a=1.3, b=0.5"]
    joint = points[-1]
    assert joint.parameters == {"seed": 3, "a": 1.3, "b": 0.5} and not joint.fitted and joint.basis == "textual"
    assert points[2].fitted and points[2].basis == "fitted" and points[0].basis == "default"
    assert len({p.key for p in points}) == len(points)
    toml = stoy / "notebooks" / "experiments.toml"
    toml.write_text(toml.read_text().replace('factorial = ["slope", "offset"]', 'factorial = ["slope", "nope"]'))
    unknown = _suite(stoy)
    with pytest.raises(SuiteError, match="factorial of 'george-study' names 'nope', which is not an interpretation"):
        bracket_points(find_experiment(unknown, "george-study"), "quick",
                       load_interpretation_file(_readings(tmp_path, text)))


def _tier_points(stoy, tmp_path):
    text = (f"{HEADER}\nslope,george-study,a,,1.0,\"[1.3, 2.0]\",[2.0],,,printed,s,r\n")
    return _hand_points(stoy, tmp_path, text)       # default, slope a=1.3 (textual), slope a=2.0 (fitted)


@pytest.mark.parametrize("values, verdicts, tier", [
    (("13", "16", "16.1"), ("miss", "within", "within"), "other_interpretation"),   # a textual point reaches it
    (("13", "14", "16.1"), ("miss", "miss", "within"), "fitted_only"),       # only the fitted point does
    (("13", "19", "25"), ("miss", "miss", "miss"), "between"),               # 16 lies inside the band 13 .. 25
])
def test_a_row_reached_only_by_a_fitted_value_is_its_own_tier(stoy, tmp_path, values, verdicts, tier):
    exp, points = _tier_points(stoy, tmp_path)
    folder = tmp_path / "b"
    for p, value, verdict in zip(points, values, verdicts):
        _numbers(folder / p.key, {"reproduced": value, "verdict": verdict})
    (row,) = bracket_rows(exp, points, folder, {p.key: "ok" for p in points}, [], "quick")
    assert row["bracket"] == tier, row
    if tier == "between":
        assert row["between"] == "default (13) and slope: a=1.3 (19)"


@pytest.mark.parametrize("se, tier", [("0.5", "open"), ("0.1", "outside")])
def test_outside_needs_the_printed_value_beyond_both_monte_carlo_errors(stoy, tmp_path, se, tier):
    """Printed 16.0; every point misses low, the nearest at 14.6 (a gap of 1.4). The margin is the rounding plus 2
    standard errors of the difference of two runs of equal error: 0.05 + 2 * 0.5 * sqrt(2) = 1.46 covers the gap
    (open: more runs would decide); 0.05 + 2 * 0.1 * sqrt(2) = 0.33 does not (outside)."""
    exp, points = _tier_points(stoy, tmp_path)
    folder = tmp_path / "b"
    for p, value in zip(points, ("13", "14.6", "12")):
        _numbers(folder / p.key, {"reproduced": value, "verdict": "miss", "mc_std_error": se, "rounding": "0.05"})
    (row,) = bracket_rows(exp, points, folder, {p.key: "ok" for p in points}, [], "quick")
    margin = 0.05 + 2 * float(se) * 2 ** 0.5
    assert (1.4 <= margin) == (tier == "open")          # the fact the verdict must follow
    assert row["bracket"] == tier, row
    assert "1.4 from slope: a=1.3 (14.6)" in (row["outside_margin"] or row["open_interpretations"])


def test_an_implausible_value_is_named_and_left_out_of_the_band(stoy, tmp_path):
    suite = _with_bracket_table(stoy, '[experiment.bracket]\nlargest_error_m = 9.43\n'
                                      'largest_error_reason = "the 5 m x 8 m room\'s diagonal"\n')
    exp = find_experiment(suite, "george-study")
    points = bracket_points(exp, "quick", load_interpretation_file(_readings(
        tmp_path, f"{HEADER}\nslope,george-study,a,,1.0,\"[1.3, 2.0]\",,,,printed,s,r\n")))
    folder = tmp_path / "b"
    # printed 16 m: the 45.6 m point would put it between; it is implausible (over 9.43 m), so nothing reaches 16
    for p, value in zip(points, ("3", "45.6", "4")):
        _numbers(folder / p.key, {"reproduced": value, "verdict": "miss", "unit": "m", "printed": "6.0"})
    (row,) = bracket_rows(exp, points, folder, {p.key: "ok" for p in points}, [], "quick")
    assert row["implausible"].startswith("slope: a=1.3 gave 45.6 m, over the largest plausible error 9.43 m")
    assert (row["band_low"], row["band_high"]) == ("3", "4") and row["bracket"] == "outside"
    (site,) = bracket_of_rows([{"printed_id": row["printed_id"], "quantity": row["quantity"], "where": row["where"],
                                "kind": "reproduction", "verdict": "miss", "reproduced": "3"}], [row])
    assert site["bracket"] == "outside" and "implausible, left out of the band: slope: a=1.3 gave 45.6 m" in \
        site["bracket_interpretations"]


def test_an_implausible_default_run_neither_hides_a_reading_nor_makes_a_crossing(stoy, tmp_path):
    """Found in review: the default run being implausible must not drop the first other reading, and an
    implausible range end must not make the row open by 'straddling' the printed value."""
    suite = _with_bracket_table(stoy, '[experiment.bracket]\nlargest_error_m = 9.43\nlargest_error_reason = "room"\n')
    exp = find_experiment(suite, "george-study")
    text = f"{HEADER}\nslope,george-study,a,,1.0,\"[1.3, 2.0]\",,,,printed,s,r\n"
    points = bracket_points(exp, "quick", load_interpretation_file(_readings(tmp_path, text)))
    folder = tmp_path / "b"
    for p, value, verdict in zip(points, ("20", "4.0", "3"), ("miss", "within", "miss")):
        _numbers(folder / p.key, {"reproduced": value, "verdict": verdict, "unit": "m", "printed": "4.0"})
    (row,) = bracket_rows(exp, points, folder, {p.key: "ok" for p in points}, [], "quick")
    assert row["bracket"] == "other_interpretation" and row["reached_by"] == "slope: a=1.3", row
    ranged = f"{HEADER}\nslope,george-study,a,,1.0,[],,0.5,2.0,printed,s,r\n"
    points = bracket_points(exp, "quick", load_interpretation_file(_readings(tmp_path, ranged)))
    folder = tmp_path / "c"
    for p, value in zip(points, ("3", "2", "45")):          # default 3, a = 0.5 gives 2, a = 2 gives 45 m
        _numbers(folder / p.key, {"reproduced": value, "verdict": "miss", "unit": "m", "printed": "4.0"})
    (row,) = bracket_rows(exp, points, folder, {p.key: "ok" for p in points}, [], "quick")
    assert row["open_interpretations"] == "" and row["bracket"] == "outside" and "45 m" in row["implausible"], row


def test_a_row_no_run_gave_a_value_is_open_not_outside(stoy, tmp_path):
    exp, points = _tier_points(stoy, tmp_path)
    folder = tmp_path / "b"
    for p in points:
        _numbers(folder / p.key, {"reproduced": "nan", "verdict": "miss"})
    (row,) = bracket_rows(exp, points, folder, {p.key: "ok" for p in points}, [], "quick")
    assert row["bracket"] == "open" and row["open_interpretations"] == "no plausible run produced a value"


def test_the_margin_counts_the_sources_monte_carlo_error_once():
    from locbook.suite.bracket import _margin
    row = {"rounding": "0.005", "mc_std_error": "0.1", "ambiguity": "0.2"}
    assert _margin(row) == pytest.approx(0.005 + 0.2 + 2 * 0.1 * 2 ** 0.5)
    own = {**row, "ambiguity_basis": "Monte-Carlo error of the thesis's own 1000-run statistic (2 standard errors)"}
    assert _margin(own) == pytest.approx(0.005 + 0.2 + 2 * 0.1)


def test_a_printed_value_written_with_words_or_a_unit_is_read_as_its_number(stoy, tmp_path):
    # review of the regenerated reports: Gudipati's '3.83m' lay inside the band and was called outside
    exp, points = _tier_points(stoy, tmp_path)
    folder = tmp_path / "b"
    for p, value in zip(points, ("3", "20", "5")):
        _numbers(folder / p.key, {"reproduced": value, "verdict": "miss", "printed": "3.83m"})
    (row,) = bracket_rows(exp, points, folder, {p.key: "ok" for p in points}, [], "quick")
    assert row["bracket"] == "between" and row["closest"] == "3", row
