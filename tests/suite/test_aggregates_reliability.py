"""The aggregates of studies and brackets (study.csv, bracket.csv, the index and numbers.csv) never
hold less than before because a run was interrupted, failed or ran partially; reader errors of study, suite and
readings files are one line (exit status 2); studies too large to run are refused before anything is drawn; study
points have collision-free keys and one folder per declaration; the Markdown writers show HTML as text.

No notebook executes here: a point's report is written as the runner promotes one (the files
:func:`locbook.suite.runner.report_cached` checks, with the cache key of the point), and a "run" is a stand-in for
:func:`locbook.suite.runner.run_tasks` that writes this run's reports and then the aggregates, as the runner does.
The toy notebook's arithmetic is known (value = 10 a + b + seed, tests/suite/test_study.py), so every row is checked
against it."""
import csv
import json
import signal
import textwrap
from dataclasses import replace
from pathlib import Path

import nbformat
import pytest
from nbformat.v4 import new_notebook

from locbook.reproduce.interpretations import InterpretationsError, load_interpretation_file
from locbook.reproduce.report import NUMBER_COLUMNS, Table
from locbook.suite import SuiteError, load_suite, runner, site
from locbook.suite import study as study_module
from locbook.suite.bracket import (
    SITE_NUMBER_COLUMNS,
    bracket_points,
    experiment_interpretations,
    find_experiment,
    write_bracket_outputs,
)
from locbook.suite.cli import main
from locbook.suite.findings import findings_markdown
from locbook.suite.runner import Outcome, SuiteRun, cache_key
from locbook.suite.study import expand_study, load_studies, load_study, study_folder, write_study_outputs
from toy_suite import HEADER, READINGS

INTERRUPTED = f"interrupted by {signal.SIGINT.name}"


def _suite(repo):
    return load_suite(repo / "notebooks" / "experiments.toml")


def _value(parameters: dict) -> float:
    """The toy notebook's value (tests/toy_suite.py, STUDY_BODY): 10 a + b + seed, with the notebook's defaults."""
    return 10 * parameters.get("a", 1.0) + parameters.get("b", 0.0) + parameters.get("seed", 1)


def _promoted(folder: Path, exp, profile: str, parameters: dict, *, figures: bool = True, value=None) -> None:
    """The report of one point as the runner promotes it: the executed notebook, manifest, numbers.csv (the toy's
    value row), the pages, report.json and run.json with this point's cache key (so the runner's cache test holds)."""
    folder.mkdir(parents=True, exist_ok=True)
    nbformat.write(new_notebook(), str(folder / f"{exp.id}.ipynb"))
    manifest = {"experiment": exp.id, "figures": [], "tables": [], "n_numbers": 1, "n_assumptions": 0}
    if not figures:
        manifest["figures_saved"] = False
    (folder / "manifest.json").write_text(json.dumps(manifest))
    ours = _value(parameters) if value is None else value
    with open(folder / "numbers.csv", "w", newline="", encoding="utf-8") as fh:
        writer = csv.DictWriter(fh, fieldnames=NUMBER_COLUMNS)
        writer.writeheader()
        writer.writerow({"experiment": exp.id, "document": "george", "printed_id": "Table 9 | value | ",
                         "quantity": "value", "where": "Table 9, value", "unit": "m", "kind": "reproduction",
                         "printed": "16.0", "reproduced": repr(float(ours)),
                         "verdict": "within" if abs(ours - 16.0) <= 1.05 else "miss", "rounding": "0.05"})
    for name in ("summary.md", "report.md", "report.html"):
        (folder / name).write_text("report\n", encoding="utf-8")
    (folder / "report.json").write_text(json.dumps({"experiment": exp.id, "profile": profile}))
    (folder / "run.json").write_text(json.dumps({
        "cache_key": cache_key(exp, profile, parameters, figures=figures), "status": "ok", "data": {}, "modules": {}}))


def _table(path):
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def _fake_run_tasks(finished: int, *, signum=signal.SIGINT, fail_writes=False):
    """A stand-in for runner.run_tasks: a ``--force`` run stopped by ``signum`` after its first ``finished`` tasks
    (their reports written again), the rest interrupted or not run; then the aggregates, as the runner writes them."""
    def fake(suite, tasks, profile, report_dir, *, write_reports, **_options):
        outcomes = []
        for i, t in enumerate(tasks):
            if i < finished:
                _promoted(report_dir / t.key, t.experiment, profile, t.parameters, figures=t.figures)
                outcomes.append(Outcome(t.key, "ok", 1.0))
            else:
                outcomes.append(Outcome(t.key, "interrupted" if i == finished else "not run", 0.0))
        run = SuiteRun(outcomes, report_dir, interrupted_by=signum)
        try:
            write_reports(report_dir, outcomes)
        except OSError:
            if not fail_writes:
                raise
            run.disk_full = str(report_dir)
        return run
    return fake


# -- 1. an interrupted or failed --force study keeps every good row -------------------------------------------------

def _complete_study(repo):
    """The toy study (8 points: 2 grid x 2 paired list rows x 2 replicates) after a complete run."""
    suite = _suite(repo)
    study = load_study(suite, "toy")
    points = expand_study(study)
    folder = study_folder(suite, study, repo / "reports")
    for p in points:
        _promoted(folder / p.key, p.experiment, study.profile, p.parameters)
    write_study_outputs(study, points, folder, [Outcome(p.key, "ok", 1.0) for p in points])
    return suite, study, points, folder


def test_an_interrupted_forced_study_keeps_the_rows_of_every_up_to_date_point(stoy, monkeypatch, capsys):
    suite, study, points, folder = _complete_study(stoy)
    before = _table(folder / "study.csv")
    plots = sorted(p.name for p in (folder / "plots").glob("*.png"))
    assert len(before) == 8 and plots        # one collected row per point; plots of value against a and b
    monkeypatch.setattr(runner, "run_tasks", _fake_run_tasks(finished=2))
    code = main(["--suite", str(stoy / "notebooks" / "experiments.toml"), "study", "toy", "--force", "--reports",
                 str(stoy / "reports"), "--progress", "quiet"])
    assert code == 128 + signal.SIGINT
    rows = _table(folder / "study.csv")
    assert [r["folder"] for r in rows] == [p.key for p in points]          # all 8 points, in point order
    by_key = {p.key: p for p in points}
    assert all(float(r["ours"]) == _value(by_key[r["folder"]].parameters) for r in rows)
    assert sorted(p.name for p in (folder / "plots").glob("*.png")) == plots
    err = capsys.readouterr().err
    assert "nothing else was changed" not in err
    assert f"{INTERRUPTED}: finished reports are kept; study.csv was rebuilt from the 8 of 8 points" in err


def test_a_failed_point_keeps_its_earlier_row_and_a_stale_one_is_left_out(stoy):
    suite, study, points, folder = _complete_study(stoy)
    # point 3's forced rerun failed (its earlier report stays, the runner keeps it); point 4's report is stale
    run = json.loads((folder / points[4].key / "run.json").read_text())
    (folder / points[4].key / "run.json").write_text(json.dumps({**run, "cache_key": "another key"}))
    outcomes = [Outcome(p.key, "failed" if i == 3 else "ok" if i < 3 else "not run", 1.0)
                for i, p in enumerate(points)]
    written = write_study_outputs(study, points, folder, outcomes)
    assert [r["folder"] for r in _table(folder / "study.csv")] == [p.key for i, p in enumerate(points) if i != 4]
    assert (written.kept, written.points) == (7, 8)
    assert "the other 1 have no up-to-date report yet" in written.describe()


def test_a_full_disk_never_empties_the_study_or_deletes_its_plots(stoy, monkeypatch):
    suite, study, points, folder = _complete_study(stoy)
    before, plots = (folder / "study.csv").read_bytes(), {p: p.read_bytes() for p in (folder / "plots").glob("*.png")}
    # nothing finished this time (the disk was full from the start): every earlier report still counts
    write_study_outputs(study, points, folder, [Outcome(p.key, "not run", 0.0) for p in points])
    assert (folder / "study.csv").read_bytes() == before
    assert {p: p.read_bytes() for p in (folder / "plots").glob("*.png")} == plots
    # and a write that fails leaves the earlier files as they were

    def full(path, write):
        raise OSError(28, "No space left on device", str(path))
    monkeypatch.setattr("locbook.suite.study.atomic_write", full)
    with pytest.raises(OSError):
        write_study_outputs(study, points, folder, [Outcome(p.key, "ok", 1.0) for p in points[:2]])
    assert (folder / "study.csv").read_bytes() == before
    assert {p: p.read_bytes() for p in (folder / "plots").glob("*.png")} == plots


def test_a_study_whose_aggregate_could_not_be_written_says_so(stoy, monkeypatch, capsys):
    _complete_study(stoy)

    def full(path, write):
        raise OSError(28, "No space left on device", str(path))
    monkeypatch.setattr("locbook.suite.study.atomic_write", full)
    monkeypatch.setattr(runner, "run_tasks", _fake_run_tasks(finished=1, signum=None, fail_writes=True))
    code = main(["--suite", str(stoy / "notebooks" / "experiments.toml"), "study", "toy", "--force", "--reports",
                 str(stoy / "reports"), "--progress", "quiet"])
    err = capsys.readouterr().err
    assert code == 3 and "study.csv was not rewritten (an earlier one is kept as it was)" in err


# -- 1. an interrupted --force bracket keeps every point that still holds ------------------------------------------

def _complete_bracket(repo, tmp_path):
    suite = _suite(repo)
    exp = find_experiment(suite, "george-study")
    readings_path = tmp_path / "george.csv"
    readings_path.write_text(READINGS)
    points = bracket_points(exp, "quick", experiment_interpretations(exp, load_interpretation_file(readings_path)))
    folder = repo / "reports" / "brackets" / exp.id
    for p in points:
        _promoted(folder / p.key, exp, "quick", p.parameters, figures=False)
    write_bracket_outputs(exp, points, folder, [Outcome(p.key, "ok", 1.0) for p in points], [], "quick", suite)
    return suite, exp, points, folder, readings_path


def test_an_interrupted_forced_bracket_keeps_its_band(stoy, tmp_path, monkeypatch, capsys):
    suite, exp, points, folder, readings_path = _complete_bracket(stoy, tmp_path)
    # default (a = 1): 13; slope a = 1.3: 16 (within), a = 0: 3, a = 2: 23; offset b = 0.5: 13.5
    values = sorted(_value(p.parameters) for p in points)
    (before,) = [r for r in _table(folder / "bracket.csv") if r["quantity"] == "value"]
    assert (float(before["band_low"]), float(before["band_high"]), int(before["points"])) == \
        (values[0], values[-1], len(points))
    assert before["bracket"] == "other_interpretation" and before["reached_by"] == "slope: a=1.3"
    monkeypatch.setattr(runner, "run_tasks", _fake_run_tasks(finished=1))
    code = main(["--suite", str(stoy / "notebooks" / "experiments.toml"), "bracket", "george-study",
                 "--interpretations", str(readings_path), "--force", "--reports", str(stoy / "reports"),
                 "--progress", "quiet"])
    assert code == 128 + signal.SIGINT
    (after,) = [r for r in _table(folder / "bracket.csv") if r["quantity"] == "value"]
    assert after == before
    assert [r["status"] for r in _table(folder / "points.csv")] == ["ok"] + ["cached"] * (len(points) - 1)
    out, err = capsys.readouterr()
    assert f"bracket.csv was rebuilt from the {len(points)} of {len(points)} points" in err
    assert "bracket of george-study: 0 default, 1 other_interpretation" in out


def test_a_bracket_whose_default_point_was_interrupted_is_rebuilt_from_its_earlier_report(stoy, tmp_path):
    suite, exp, points, folder, _path = _complete_bracket(stoy, tmp_path)
    before = (folder / "bracket.csv").read_bytes()
    (folder / "bracket.csv").unlink()
    written = write_bracket_outputs(exp, points, folder, [Outcome(points[0].key, "interrupted", 1.0)], [], "quick",
                                    suite)
    assert written.written and (folder / "bracket.csv").read_bytes() == before


# -- 5. reader errors are one line, exit status 2 --------------------------------------------------------------------

def _one_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.startswith("locbook: error: ") and len(err.splitlines()) == 1 and "Traceback" not in err, err
    return err


def test_a_study_file_that_is_not_utf8_is_one_line_naming_file_line_and_column(stoy, tmp_path, capsys):
    path = tmp_path / "study.toml"
    path.write_bytes(b'[[study]]\nname = "s"\n# caf\xe9\nexperiments = ["george-study"]\n')
    assert main(["--suite", str(stoy / "notebooks" / "experiments.toml"), "study", str(path), "--reports",
                 str(tmp_path / "r")]) == 2
    assert f"{path}, line 3, column 6: byte 0xe9 is not UTF-8 text" in _one_line(capsys)


def test_a_suite_file_that_is_not_utf8_is_one_line(toy, tmp_path, capsys):
    suite_file = toy / "notebooks" / "experiments.toml"
    suite_file.write_bytes(suite_file.read_bytes().replace(b'title = "t"', b'title = "\xff"', 1))
    assert main(["--suite", str(suite_file), "list"]) == 2
    assert f"{suite_file}, line 3, column 10: byte 0xff is not UTF-8 text" in _one_line(capsys)


@pytest.mark.parametrize("data, message", [
    (b"# a comment\n" + HEADER.encode() + b"\nslope,george-study,a,,1.0,[1.3],,,,assumed,T\xe4ble 9,r\n",
     "line 3, column 45: byte 0xe4 is not UTF-8 text"),        # the 45th byte of its line
    (HEADER.encode() + b"\nslope,george-study,a,,1.0,[1.3],,,,assumed,s,r\n"
     b'offset,george-study,b,,0.0,[0.5],,,,printed,s,"' + b"x" * 200_000 + b'"\n',
     "line 3: not a well-formed CSV row (field larger than field limit"),
])
def test_a_readings_file_that_cannot_be_read_is_one_line(stoy, tmp_path, capsys, data, message):
    path = tmp_path / "george.csv"
    path.write_bytes(data)
    with pytest.raises(InterpretationsError, match=str(path).replace(".", r"\.") + ", " + message.replace("(", r"\(")):
        load_interpretation_file(path)
    assert main(["--suite", str(stoy / "notebooks" / "experiments.toml"), "bracket", "george-study",
                 "--interpretations", str(path), "--reports", str(tmp_path / "r")]) == 2
    assert message in _one_line(capsys)


def test_a_line_break_inside_a_cell_stays_on_the_error_line(tmp_path):
    path = tmp_path / "george.csv"
    path.write_text(HEADER.replace("experiments", '"exp\neriments"') + "\n")       # a quoted header cell
    with pytest.raises(InterpretationsError) as info:
        load_interpretation_file(path)
    assert "\n" not in str(info.value) and "got name, exp\\neriments, parameter" in str(info.value)
    path.write_text(HEADER + '\nslope,george-study,a,,1.0,"[2.0,\n2.0]",,,,assumed,s,r\n')     # rows start on line 2
    with pytest.raises(InterpretationsError, match=r"line 2 \(slope\): alternatives repeat a value: \[2\.0,\\n2\.0\]$"):
        load_interpretation_file(path)


def test_a_declaration_file_too_large_is_refused_before_it_is_read_whole(stoy, tmp_path, capsys):
    big = tmp_path / "big.toml"
    with open(big, "wb") as fh:           # sparse: 64 MiB of NUL bytes that take no disk space
        fh.write(b'[[study]]\nname = "s"\n')
        fh.truncate(64 * 2 ** 20)
    assert main(["--suite", str(stoy / "notebooks" / "experiments.toml"), "study", str(big)]) == 2
    assert f"{big}: the study file is 64.0 MiB, over the limit of 16 MiB for a declaration" in _one_line(capsys)
    assert main(["--suite", str(big), "list"]) == 2
    assert f"{big}: the experiment list is 64.0 MiB, over the limit" in _one_line(capsys)
    csv_path = big.rename(tmp_path / "george.csv")
    with pytest.raises(InterpretationsError, match="an interpretations file is 64.0 MiB, over the limit of 16 MiB"):
        load_interpretation_file(csv_path)
    from locbook.reproduce.interpretations import MAX_DECLARATION_BYTES
    assert MAX_DECLARATION_BYTES == 16 * 2 ** 20         # the limit the messages state


# -- 7. a study too large to run is refused before anything is drawn ------------------------------------------------

@pytest.mark.parametrize("body, count", [
    ("samples = 1000000000\n[study.parameters]\na = { random = { low = 0.5, high = 2.0 } }",
     "1 experiments x 1000000000 samples x 1 replicates = 1000000000 runs"),
    ("[study.parameters]\na = { grid = [" + ", ".join(["1.0"] * 1000) + "] }\nb = { grid = ["
     + ", ".join(["1.0"] * 1000) + "] }\nsleep_s = { grid = [" + ", ".join(["1.0"] * 1000) + "] }",
     "1 experiments x 1000 a (grid) x 1000 b (grid) x 1000 sleep_s (grid) x 1 replicates = 1000000000 runs"),
    ("replicates = 1000000", "1 experiments x 1000000 replicates = 1000000 runs"),
])
def test_a_study_of_too_many_runs_names_its_factors_and_the_limit(stoy, tmp_path, body, count):
    path = tmp_path / "big.toml"
    path.write_text(f'[[study]]\nname = "big"\nexperiments = ["george-study"]\n{body}\n')
    with pytest.raises(SuiteError) as info:
        load_study(_suite(stoy), path)          # the declaration alone: nothing drawn, nothing expanded
    assert f"{count}, more than the limit of {study_module.MAX_STUDY_RUNS}" in str(info.value)
    assert str(info.value).startswith(f"{path}: study 'big': ")


def test_a_study_built_by_hand_is_guarded_too_and_the_limit_itself_is_allowed(stoy):
    limit, study_size = study_module.MAX_STUDY_RUNS, study_module.study_size
    study = load_studies(_suite(stoy))["toy"]           # 4 parameter points
    assert study_size(study) == 8
    with pytest.raises(SuiteError, match=f"= {4 * (limit // 4 + 1)} runs, more than the limit"):
        expand_study(replace(study, replicates=limit // 4 + 1))
    assert study_size(replace(study, replicates=limit // 4)) == limit


# -- 10. a partial run keeps what it did not touch ----------------------------------------------------------------

def _experiment_report(folder: Path, exp_id: str, value: str, verdict: str) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "summary.md").write_text("summary\n")
    (folder / "report.json").write_text(json.dumps({"experiment": exp_id, "profile": "full"}))
    with open(folder / "numbers.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=NUMBER_COLUMNS)
        writer.writeheader()
        writer.writerow({"experiment": exp_id, "document": "george", "printed_id": "Table 1 | mean | ",
                         "quantity": "mean", "where": "Table 1", "kind": "reproduction", "printed": "0.0",
                         "reproduced": value, "verdict": verdict})


def test_a_copy_without_its_brackets_keeps_every_rows_bracket_columns(toy):
    """reports/full copied without reports/brackets beside it: the index and numbers.csv keep each row's bracket,
    except a row whose value changed since (its bracket would be stale)."""
    suite = _suite(toy)
    report_dir = toy / "copy" / "full"
    _experiment_report(report_dir / "george-one", "george-one", "0.5", "miss")
    _experiment_report(report_dir / "george-two", "george-two", "0.25", "miss")
    with open(report_dir / "numbers.csv", "w", newline="") as fh:      # the site table of an earlier run
        writer = csv.DictWriter(fh, fieldnames=SITE_NUMBER_COLUMNS)
        writer.writeheader()
        for eid, value in (("george-one", "0.5"), ("george-two", "0.125")):
            writer.writerow({"experiment": eid, "document": "george", "printed_id": "Table 1 | mean | ",
                             "quantity": "mean", "where": "Table 1", "kind": "reproduction", "printed": "0.0",
                             "reproduced": value, "verdict": "miss", "bracket": "other_interpretation",
                             "bracket_interpretations": "at quick: offset: b=0.5"})
    site.write_suite_reports(suite, report_dir)
    rows = {r["experiment"]: r for r in _table(report_dir / "numbers.csv")}
    assert (rows["george-one"]["bracket"], rows["george-one"]["bracket_interpretations"]) == \
        ("other_interpretation", "at quick: offset: b=0.5")
    assert (rows["george-two"]["bracket"], rows["george-two"]["bracket_interpretations"]) == ("", "")   # 0.125 -> 0.25
    assert "1 reproduced only under another textual" in (report_dir / "index.md").read_text()


def test_the_index_links_every_data_set_folder_present_whatever_page_it_holds(toy):
    suite = _suite(toy)
    report_dir = toy / "reports" / "full"
    _experiment_report(report_dir / "george-one", "george-one", "0.5", "miss")
    (report_dir / "data-danis2022").mkdir()
    (report_dir / "data-danis2022" / "index.md").write_text("# committed: no index.html\n")
    (report_dir / "data-empty").mkdir()          # neither page: not a data set's reports
    site.write_suite_reports(suite, report_dir)
    md = (report_dir / "index.md").read_text()
    html = (report_dir / "index.html").read_text()
    assert "[danis2022](data-danis2022/index.md)" in md and "data-empty" not in md
    assert 'href="data-danis2022/index.md"' in html and "data-empty" not in html


# -- 12. collision-free point keys, one folder per declaration, HTML shown as text -----------------------------

def test_points_whose_old_40_bit_keys_collide_are_two_points(stoy, tmp_path):
    # sha256('{"seed": 1144321}') and sha256('{"seed": 1683134}') share their first 10 hex digits (faade71638)
    path = tmp_path / "s.toml"
    path.write_text('[[study]]\nname = "s"\nexperiments = ["george-study"]\n[study.parameters]\n'
                    'seed = { grid = [1144321, 1683134] }\n')
    points = expand_study(load_study(_suite(stoy), path))
    assert [p.parameters["seed"] for p in points] == [1144321, 1683134]
    assert len({p.key for p in points}) == 2
    # a real repeat is still one: the values compared after checking (1 and 1.0 of a float parameter are one)
    path.write_text('[[study]]\nname = "s"\nexperiments = ["george-study"]\n[study.parameters]\n'
                    'a = { grid = [1, 1.0] }\n')
    with pytest.raises(SuiteError, match=r"point 2 of 'george-study' repeats point 1 \({'a': 1.0}\)"):
        expand_study(load_study(_suite(stoy), path))


def test_two_declarations_of_one_name_never_share_a_folder(stoy, tmp_path, monkeypatch, capsys):
    suite, study, points, folder = _complete_study(stoy)
    record = json.loads((folder / "study.json").read_text())
    assert record["declared_in"] == str(suite.path) and record["study"] == "toy"
    other = tmp_path / "toy.toml"      # another study named toy: other values of a
    other.write_text(textwrap.dedent("""
        [[study]]
        name = "toy"
        experiments = ["george-study"]
        [study.parameters]
        a = { grid = [2.0, 3.0] }
        """))
    with pytest.raises(SuiteError, match=f"{folder} holds the study 'toy' declared in {suite.path}; this 'toy' of "
                                         f"{other} is declared differently"):
        study_module.check_claim(load_study(suite, other), folder)
    monkeypatch.setattr(runner, "run_tasks", _fake_run_tasks(finished=99, signum=None))
    before = (folder / "study.csv").read_bytes()
    assert main(["--suite", str(suite.path), "study", str(other), "--reports", str(stoy / "reports")]) == 2
    assert "is declared differently: give it another name" in _one_line(capsys)
    assert (folder / "study.csv").read_bytes() == before
    # the same declaration copied to another file is the same study; the suite's own, edited, is still its own
    copy = tmp_path / "copy.toml"
    copy.write_text(suite.path.read_text())
    study_module.check_claim(load_studies(suite, copy)["toy"], folder)
    study_module.check_claim(replace(study, replicates=1), folder)


def test_figure_and_table_captions_are_text_in_markdown(tmp_path, stoy):
    from locbook.suite.pages import md_captions
    from locbook.suite.site import page_html, page_markdown
    exp = find_experiment(_suite(stoy), "george-study")
    caption = 'sigma = <script>alert("x")</script> & <img src=x onerror=alert(1)>'
    (tmp_path / "f.png").write_bytes(b"png")
    (tmp_path / "t.csv").write_text("a\n1\n")
    (tmp_path / "manifest.json").write_text(json.dumps({
        "figures": [{"name": "f", "file": "f.png", "caption": caption}, {"name": "g", "file": "", "caption": caption}],
        "tables": [{"name": "t", "file": "t.csv", "caption": caption}]}))
    md = page_markdown(exp, "quick", {}, tmp_path, [], "v")
    assert "<script" not in md and "<img" not in md and md.count("&lt;script>") == 4
    # a folder without its manifest (committed reports) reads the captions back from report.md as typed
    (tmp_path / "report.md").write_text(md)
    (tmp_path / "manifest.json").unlink()
    assert md_captions(tmp_path) == {"f.png": caption, "t.csv": caption}
    html = page_html(exp, "quick", {}, tmp_path, [], "v")
    assert "<script>alert" not in html and "&lt;script&gt;alert" in html


def test_findings_and_markdown_tables_show_html_as_text():
    row = {"experiment": "george-study", "printed_id": "T | <b>v</b>", "printed": "16.0", "reproduced": "13",
           "verdict": "miss", "kind": "reproduction", "bracket": "other_interpretation",
           "bracket_interpretations": "at quick: slope: tag='<script>alert(1)</script>'", "note": "<iframe src=x>"}
    md = findings_markdown("george", "A <i>B</i>", 2015, [row], "quick")
    assert "<script" not in md and "<b>" not in md and "<i>" not in md
    assert "&lt;script>alert(1)&lt;/script>" in md
    table = Table([{"note": "N_eff < 0.5 <a href=x>link</a>", "<th>": 1}]).to_markdown()
    assert "<a" not in table and "<th>" not in table and "N_eff < 0.5 &lt;a href=x>link&lt;/a>" in table
