"""A data run runs the data: which experiments a data set can run, the data run's own parameters, the
console line and exit status of a data run, and a data set's page (results first, its own attribution, no
reproduction vocabulary).

Data sets are written to tmp_path by locbook's example generator (``roles=`` for static-only, track-only and
calibration-only sets); the pages are built from hand-written results.csv / fits.csv, never from a run of ours. One
slow test runs `locbook run --data` on a static-only set end to end.
"""
from __future__ import annotations

import json
import re
from pathlib import Path

import nbformat
import numpy as np
import pandas as pd
import pytest

from locbook.data.dataset import load_dataset
from locbook.data.example import write_example_dataset
from locbook.errors import ParameterError
from locbook.suite import load_suite, runner, site
from locbook.suite import run as suite_run
from locbook.suite.spec import SuiteError
from toy_suite import STATIC_ROWS, document_toml, example, experiment_toml, suite_toml, write_data_folder

#: the reproduction vocabulary no page about a data set may use (words, so "within" but not "withinness")
BANNED = re.compile(r"\b(reproduc\w*|within|loose|miss|missed|printed|calibrated within)\b", re.I)
#: what each data experiment needs (kinds of locbook.suite.spec.DATA_KINDS); the benchmark's data scenarios are both
#: built from scored recordings (its tracking one from the tracks with truth: benchmark.measured_tracking_scenario)
NEEDS = {"measured-calibration": ("calibration",), "measured-localization": ("scored",),
         "measured-tracking": ("track",), "benchmark-cross-document": ("scored",)}


@pytest.fixture(scope="module")
def suite():
    return load_suite()


def visible_text(html: str) -> str:
    """An HTML page's text as a reader sees it: without its inlined style sheet, its tags and its entities."""
    import html as html_module
    body = re.sub(r"<style>.*?</style>", " ", html, flags=re.S)
    return html_module.unescape(re.sub(r"<[^>]+>", " ", body))


# -- declarations ----------------------------------------------------------------------------------------------

def test_every_experiment_that_takes_a_data_set_declares_what_it_needs(suite):
    takes = {e.id for e in suite.experiments if "data" in e.declared_parameters()}
    assert takes == set(NEEDS)
    for e in suite.experiments:
        if e.id in NEEDS:
            assert e.data_run is not None and e.data_run.needs == NEEDS[e.id], e.id
        else:
            assert e.data_run is None, e.id
    bench = next(e for e in suite.experiments if e.id == "benchmark-cross-document")
    assert bench.data_run.parameters == {"synthetic": False}
    assert all(not e.data_run.parameters for e in suite.experiments if e.data_run and e is not bench)


def test_particle_settings_are_equal_where_one_method_appears_on_two_pages(suite):
    """measured-tracking and the benchmark run the same particle filter on a data set: the same particles, runs and
    bootstrap per profile, so a method gives the same numbers on every page of one run."""
    by_id = {e.id: e for e in suite.experiments}
    expected = {"quick": (500, 4), "full": (2000, 10)}
    for profile, (particles, runs) in expected.items():
        for eid in ("measured-tracking", "benchmark-cross-document"):
            p = by_id[eid].parameters(profile)
            assert (p["n_particles"], p["particle_runs"]) == (particles, runs), (eid, profile)
        assert by_id["measured-tracking"].parameters(profile)["n_bootstrap"] == \
            by_id["benchmark-cross-document"].parameters(profile)["n_bootstrap"]


def _toy_suite(root: Path, data_run: str) -> Path:
    """A toy experiment list whose one notebook declares ``data`` and ``n``; ``data_run`` is the TOML of the first
    experiment's [experiment.data_run] table (the second experiment declares none)."""
    nbdir = root / "notebooks"
    nbdir.mkdir(parents=True)
    nb = nbformat.v4.new_notebook()
    cell = nbformat.v4.new_code_cell('data: str = "x"  # a data set\nn: int = 2  # a count\n')
    cell.metadata["tags"] = ["parameters"]
    nb.cells = [cell, nbformat.v4.new_code_cell("pass")]
    nbformat.write(nb, nbdir / "toy.ipynb")
    toml = suite_toml(
        experiment_toml("measured-one", "toy.ipynb", title="one", section="s", document="measured", extra=data_run),
        experiment_toml("measured-two", "toy.ipynb", title="two", section="s", document="measured"),
        document=document_toml("measured", year="2021"), rules={"n": {"ge": 1}})
    (nbdir / "experiments.toml").write_text(toml)
    return nbdir / "experiments.toml"


@pytest.mark.parametrize("table, message", [
    ('[experiment.data_run]\nneeds = ["track"]\nwants = 1', "[experiment.data_run] has unknown key 'wants'"),
    ('[experiment.data_run]\nneeds = ["walking"]', "needs: unknown kind 'walking'"),
    ('[experiment.data_run]\nneeds = []', "needs must list one or more distinct kinds"),
    ('[experiment.data_run]\nneeds = "track"', "needs must list one or more distinct kinds"),
    ('[experiment.data_run]\nneeds = ["track"]\nparameters = 3', "parameters must be a table"),
    ('[experiment.data_run]\nneeds = ["track"]\nparameters = { data = "y" }', "cannot set 'data'"),
])
def test_a_malformed_data_run_table_is_one_line_naming_the_file_and_the_key(tmp_path, table, message):
    path = _toy_suite(tmp_path, table)
    with pytest.raises(SuiteError) as info:
        load_suite(path)
    text = str(info.value)
    assert message in text and str(path) in text and "measured-one" in text and "\n" not in text


def test_data_run_parameters_apply_to_a_data_run_only_and_an_undeclared_one_fails_at_validation(tmp_path):
    good = load_suite(_toy_suite(tmp_path / "good", '[experiment.data_run]\nneeds = ["track"]\nparameters = { n = 7 }'))
    one, two = good.experiments
    assert one.parameters("quick", data_run=True) == {"n": 7}
    assert one.parameters("quick") == {}                                # not a data run: the notebook's default
    assert one.parameters("quick", {"n": "9"}, data_run=True) == {"n": 9}   # -p wins
    assert two.parameters("quick", data_run=True) == {}                 # declares none: nothing applied
    with pytest.raises(ParameterError, match="parameter .n. = 0 is not allowed"):
        load_suite(_toy_suite(tmp_path / "rule", '[experiment.data_run]\nneeds = ["track"]\nparameters = { n = 0 }'))\
            .experiments[0].parameters("quick", data_run=True)
    bad = load_suite(_toy_suite(tmp_path / "bad", '[experiment.data_run]\nneeds = ["track"]\n'
                                                  'parameters = { synthetic = false }')).experiments[0]
    assert bad.parameters("quick") == {}
    with pytest.raises(ParameterError) as info:
        bad.parameters("quick", data_run=True)
    assert "unknown parameter 'synthetic'" in str(info.value) and "[experiment.data_run]" in str(info.value)


# -- which experiments a data set can run ------------------------------------------------------------------------

def _selection(suite, folder):
    kinds = suite_run.data_kinds(load_dataset(folder))
    data = [e for e in suite.experiments if e.id in NEEDS]
    kept, left_out = suite_run.select_for_data(data, kinds, requested=())
    return kinds, [e.id for e in kept], left_out


def test_a_static_only_set_runs_everything_but_tracking(suite, tmp_path):
    kinds, kept, left_out = _selection(suite, example(tmp_path / "s", ("calibration", "static")))
    assert kinds == {"calibration", "static", "scored"}
    assert kept == ["measured-calibration", "measured-localization", "benchmark-cross-document"]
    assert left_out == {"measured-tracking": "the data set has no track recording"}


def test_a_track_only_set_runs_everything_and_without_truth_no_static_scoring(suite, tmp_path):
    kinds, kept, left_out = _selection(suite, example(tmp_path / "t", ("calibration", "track")))
    assert kinds == {"calibration", "track", "scored"} and kept == list(NEEDS) and left_out == {}
    kinds, kept, left_out = _selection(suite, example(tmp_path / "u", ("calibration", "track"), truth=False))
    assert kinds == {"calibration", "track"}
    assert kept == ["measured-calibration", "measured-tracking"]
    assert list(left_out) == ["measured-localization", "benchmark-cross-document"]
    assert all(why.startswith("the data set has no scored recording") for why in left_out.values())
    # the benchmark's data scenarios: none from tracks without truth (so it would have nothing to run)
    from locbook import benchmark as bm
    ds = load_dataset(tmp_path / "u")
    assert bm.measured_static_scenario(ds) is None and bm.measured_tracking_scenario(ds) is None


def test_a_calibration_only_set_runs_the_calibration_only(suite, tmp_path):
    kinds, kept, left_out = _selection(suite, example(tmp_path / "c", ("calibration",)))
    assert kinds == {"calibration"} and kept == ["measured-calibration"]
    assert set(left_out) == {"measured-localization", "measured-tracking", "benchmark-cross-document"}
    assert left_out["benchmark-cross-document"] == ("the data set has no scored recording (a static recording, or a "
                                                    "track with a true position per epoch)")
    # a declaration that accepts several kinds names each it did not find
    from locbook.suite.spec import DataRun
    assert DataRun(("scored", "track")).missing({"calibration"}) == (
        "the data set has no scored recording (a static recording, or a track with a true position per epoch) and "
        "no track recording")
    assert DataRun(("scored", "track")).missing({"calibration", "track"}) == ""


def test_an_inapplicable_experiment_asked_for_by_id_is_refused(suite, tmp_path):
    data = [e for e in suite.experiments if e.id in NEEDS]
    with pytest.raises(SuiteError, match="measured-tracking cannot run on this data set: the data set has no track"):
        suite_run.select_for_data(data, frozenset({"calibration", "static", "scored"}), requested={"measured-tracking"})
    with pytest.raises(SuiteError, match="no selected experiment can run on this data set"):
        suite_run.select_for_data([e for e in data if e.id == "measured-tracking"], frozenset({"calibration"}), ())


# -- the command line, without executing a notebook --------------------------------------------------------------

@pytest.fixture
def no_execution(monkeypatch):
    """run_tasks replaced by a stand-in that records the tasks, reports each as executed and rebuilds the folder's
    pages, so that the command line is tested to the point where notebooks would run."""
    seen = {}

    def run_tasks(suite, tasks, profile, report_dir, *, write_reports, progress="plain", **_kwargs):
        seen["tasks"], seen["report_dir"] = {t.key: t.parameters for t in tasks}, report_dir
        report_dir.mkdir(parents=True, exist_ok=True)
        outcomes = [runner.Outcome(t.key, "ok", 0.0) for t in tasks]
        write_reports(report_dir, outcomes)
        return runner.SuiteRun(outcomes, report_dir)

    monkeypatch.setattr(runner, "run_tasks", run_tasks)
    return seen


def test_a_data_run_leaves_out_what_the_set_cannot_run_says_so_and_exits_0(tmp_path, capsys, no_execution):
    from locbook.suite.cli import main
    folder = example(tmp_path / "s", ("calibration", "static"), name="mine")
    assert main(["run", "--data", str(folder), "--reports", str(tmp_path / "r"), "--progress", "plain"]) == 0
    out = capsys.readouterr().out
    assert "measured-tracking: left out: the data set has no track recording\n" in out
    assert list(no_execution["tasks"]) == ["measured-calibration", "measured-localization", "benchmark-cross-document"]
    assert no_execution["tasks"]["benchmark-cross-document"]["synthetic"] is False
    assert all("synthetic" not in p for k, p in no_execution["tasks"].items() if k != "benchmark-cross-document")
    # recorded for the data set's page, with the manifest's own title and attribution
    page = tmp_path / "r" / "quick" / "data-mine"
    record = json.loads((page / "dataset.json").read_text())
    ds = load_dataset(folder)
    assert (record["title"], record["attribution"], record["licence"]) == (ds.title, ds.attribution, ds.license)
    assert record["manifest"] == str(ds.root / "dataset.toml") and record["geometry"] == ds.geometry_text
    assert record["left out"] == {"measured-tracking": "the data set has no track recording"}
    md = (page / "index.md").read_text()
    assert "measured-tracking: left out: the data set has no track recording." in md
    assert ds.attribution in md and not BANNED.search(md)


def test_the_benchmark_keeps_its_synthetic_scenarios_outside_a_data_run_and_p_wins(tmp_path, no_execution):
    from locbook.suite.cli import main
    assert main(["run", "benchmark-cross-document", "--reports", str(tmp_path / "r"), "--quiet"]) == 0
    assert "synthetic" not in no_execution["tasks"]["benchmark-cross-document"]     # the notebook's True
    folder = example(tmp_path / "s", ("calibration", "static"))
    assert main(["run", "benchmark", "--data", str(folder), "-p", "synthetic=true", "--reports",
                 str(tmp_path / "r"), "--quiet"]) == 0
    assert no_execution["tasks"]["benchmark-cross-document"]["synthetic"] is True


def test_asking_by_id_for_what_the_set_cannot_run_is_one_line_and_exit_2(tmp_path, capsys, no_execution):
    from locbook.suite.cli import EXIT_BAD_INPUT, main
    folder = example(tmp_path / "s", ("calibration", "static"))
    assert main(["run", "measured-tracking", "--data", str(folder), "--reports", str(tmp_path / "r")]) \
        == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("locbook: error: measured-tracking cannot run on this data set: "
                                                   "the data set has no track recording")
    assert not (tmp_path / "r").exists() and "tasks" not in no_execution
    # a document key selects without asking for each: what the set cannot run is left out
    assert main(["run", "measured", "--data", str(folder), "--reports", str(tmp_path / "r"), "--quiet"]) == 0
    assert list(no_execution["tasks"]) == ["measured-calibration", "measured-localization"]


def test_data_example_takes_the_generators_options_and_check_reads_a_2d_set(tmp_path, capsys):
    from locbook.suite.cli import main
    assert main(["data", "example", str(tmp_path / "cli"), "--roles", "calibration,track", "--two-d",
                 "--native-scans", "--speed", "0.5", "--seed", "4", "--name", "flat"]) == 0
    lib = write_example_dataset(tmp_path / "lib", np.random.default_rng(4), seed_note=4, name="flat",
                                roles=("calibration", "track"), two_d=True, native_scans=True, speed_m_s=0.5)
    cli_files = sorted(p.name for p in (tmp_path / "cli").iterdir())
    assert cli_files == sorted(p.name for p in lib.iterdir())
    for name in cli_files:                      # the command writes what the library function writes
        assert (tmp_path / "cli" / name).read_bytes() == (lib / name).read_bytes(), name
    capsys.readouterr()
    assert main(["data", "check", str(tmp_path / "cli")]) == 0          # a 2-D set: no anchor heights to print
    out = capsys.readouterr().out
    ds = load_dataset(tmp_path / "cli")
    assert ds.dimension == 2 and ds.tag_height_m is None and f"geometry: {ds.geometry_text}" in out
    assert "runs measured-calibration, measured-localization, measured-tracking, benchmark-cross-document" in out
    assert main(["data", "example", str(tmp_path / "x"), "--roles", "static"]) == 2      # no calibration


# -- a data set's page ------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def data_folder(tmp_path_factory, suite):
    root = tmp_path_factory.mktemp("page")
    folder = example(root / "set", ("calibration", "static"), name="mine")
    report_dir = root / "reports" / "quick" / "data-mine"
    record = write_data_folder(report_dir, folder, suite)
    return report_dir, record, load_dataset(folder)


def test_the_data_page_opens_with_the_results_table(data_folder):
    report_dir, record, ds = data_folder
    lines = (report_dir / "index.md").read_text().splitlines()
    assert lines[0] == f"# {ds.title}"
    first = next(i for i, line in enumerate(lines) if line.startswith("|"))
    assert lines.index("## Results") < first < lines.index("## Channel fits") < lines.index(
        "## Experiments on this data set")
    header = [c.strip() for c in lines[first].strip("|").split("|")]
    assert header[:5] == ["method", "recording", "epochs", "coverage", "mean (m)"]
    assert {"median (m)", "p90 (m)", "CE95 (m)", "bound median (m)", "ratio", "ratio note", "settings"} <= set(header)
    body = [[c.strip() for c in line.strip("|").split("|")] for line in lines[first + 2:]]
    body = body[:next(i for i, r in enumerate(body) if r == [""])]
    # per method in the file's order, its pooled row first, then its recordings in the file's order
    assert [(r[0].strip("*"), r[1]) for r in body] == [("lls", "pooled"), ("lls", "points"), ("lls", "walk_a"),
                                                      ("grid_ml", "pooled"), ("grid_ml", "points"),
                                                      ("grid_ml", "walk_a"), ("knn", "pooled (= points)")]
    mean = header.index("mean (m)")
    assert [r[mean] for r in body] == ["3.0", "3.1", "2.9", "1.2", "1.3", "1.1", "1.5"]
    ratio, note = header.index("ratio"), header.index("ratio note")
    assert (body[0][ratio], body[3][ratio]) == ("n/a", "0.94")         # no ratio from a degenerate bound
    text = "\n".join(lines)
    assert f"{body[0][note].strip('[]')}. n/a: the bound is degenerate at 2 of 40 epochs" in text
    # the answer: the lowest pooled mean error of the hand-written rows
    best = min((float(m), meth) for r, meth, m in STATIC_ROWS if r == "pooled")
    assert f"static localization, {best[1]} {best[0]:g} m (CRLB median 1.25 m)" in text
    assert "![" in text and "(measured-localization/cdf.png)" in text
    assert "measured-tracking: left out: the data set has no track recording." in text


def test_the_data_page_names_the_manifests_attribution_and_no_reproduction_word(data_folder, suite):
    report_dir, record, ds = data_folder
    md, html = (report_dir / "index.md").read_text(), (report_dir / "index.html").read_text()
    for text in (md, visible_text(html)):
        assert ds.attribution in text and ds.license in text and ds.geometry_text in text
        assert BANNED.search(text) is None, BANNED.search(text)
        assert "the data set's authors" not in text and "(2021-)" not in text
    # the channel fits: the pooled ones and each anchor's by the fit the methods ran on (the notebook's default)
    fits = md[md.index("## Channel fits"):md.index("## Experiments")]
    assert fits.count("| per_anchor | closed_form |") == 2 and "| per_anchor | huber |" not in fits
    assert fits.count("| pooled |") == 2
    # the bookkeeping: each experiment's last run, the cached one said as such, the one left out with why
    book = md[md.index("## Experiments"):]
    assert "| cached |" in book and "| ok |" in book and "left out: the data set has no track recording" in book
    assert "not run: it has not run on this data set yet" in book                      # the benchmark


def test_the_data_pages_first_html_table_is_the_results_table(data_folder):
    report_dir, _record, _ds = data_folder
    html = (report_dir / "index.html").read_text()
    after_title = html[html.index("</h1>"):]
    first = re.search(r"<table[^>]*>", after_title).group(0)
    assert "results" in first and after_title.index(first) < after_title.index('id="fits"')
    assert 'src="measured-localization/cdf.png"' in html


def test_the_profile_index_shows_each_data_set_by_its_manifest_answer_first(data_folder, suite):
    report_dir, _record, ds = data_folder
    site.write_suite_reports(suite, report_dir.parent)
    md = (report_dir.parent / "index.md").read_text()
    line = next(x for x in md.splitlines() if x.startswith("- [mine](data-mine/index.md): "))
    assert line.index("Lowest mean error") < line.index(ds.attribution)
    assert "grid_ml 1.2 m" in line
    html = (report_dir.parent / "index.html").read_text()
    assert 'href="data-mine/index.html"' in html and ds.attribution in html


def test_an_experiment_page_of_a_data_run_names_the_data_set_not_the_document(data_folder, suite, tmp_path):
    from locbook.suite import site
    _report_dir, record, ds = data_folder
    exp = next(e for e in suite.experiments if e.id == "measured-localization")
    summary = site.summary_markdown(exp, "quick", [], "v", record)
    page = site.page_markdown(exp, "quick", {}, tmp_path, [], "v", record)
    html = visible_text(site.page_html(exp, "quick", {}, tmp_path, [], "v", record))
    for text in (summary, page, html):
        assert ds.title in text and ds.attribution in text and "the data set's authors" not in text
        assert BANNED.search(text) is None, BANNED.search(text)
    # the suite's own pages keep their wording
    assert "reproducing" in site.summary_markdown(exp, "quick", [], "v")


def test_a_data_run_page_says_which_parameters_the_data_run_set(data_folder, suite, tmp_path):
    """The parameters table names who set each value: --data sets `data`, [experiment.data_run] sets the benchmark's
    `synthetic = false` (a -p giving another value is the user's), the profile the rest."""
    from locbook.suite import site
    _report_dir, record, _ds = data_folder
    bench = next(e for e in suite.experiments if e.id == "benchmark-cross-document")

    def set_by(params, dataset):
        lines = site.page_markdown(bench, "quick", params, tmp_path, [], "v", dataset).splitlines()
        return {c[0]: c[2] for c in ([x.strip() for x in line.strip("|").split("|")] for line in lines
                                     if line.startswith("| ")) if len(c) == 4}

    run = {"data": ["/x"], "synthetic": False, "n_runs": 40}
    seen = set_by(run, record)
    assert (seen["data"], seen["synthetic"], seen["n_runs"]) == ("--data", "data run ([experiment.data_run])",
                                                               "profile / -p")
    assert seen["seed"] == "notebook default"
    assert set_by({**run, "synthetic": True}, record)["synthetic"] == "profile / -p"     # -p synthetic=true
    assert set(set_by(run, None)[k] for k in run) == {"profile / -p"}                   # the suite's own page


# -- end to end ------------------------------------------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.notebooks
def test_a_static_only_data_set_runs_clean_end_to_end(tmp_path):
    """`locbook run --data <static-only set> --profile quick` exits 0 (it needs the measured notebooks' results
    tables and the benchmark's `synthetic` parameter)."""
    from locbook.suite.cli import main
    folder = example(tmp_path / "s", ("calibration", "static"), name="stat")
    assert main(["run", "--data", str(folder), "--profile", "quick", "--reports", str(tmp_path / "r"), "--quiet"]) == 0
    page = tmp_path / "r" / "quick" / "data-stat"
    assert not (page / "measured-tracking").exists()
    md = (page / "index.md").read_text()
    assert "measured-tracking: left out: the data set has no track recording." in md
    results = pd.read_csv(page / "measured-localization" / "results.csv")
    assert set(results["recording"]) == {"pooled", "points"}
    bench = pd.read_csv(page / "benchmark-cross-document" / "benchmark.csv")
    assert set(bench["scenario"]) == {"data-stat"}                  # the data set's scenarios only
    assert BANNED.search(md) is None


@pytest.mark.slow
@pytest.mark.notebooks
def test_a_track_only_data_set_without_truth_runs_clean_end_to_end(tmp_path):
    """Tracks with no true position (a reference path or nothing): the calibration and the trackers run, the static
    methods and the benchmark (nothing of theirs can be scored) are left out, and the run exits 0."""
    from locbook.suite.cli import main
    folder = example(tmp_path / "t", ("calibration", "track"), truth=False, name="walks")
    assert main(["run", "--data", str(folder), "--profile", "quick", "--reports", str(tmp_path / "r"), "--quiet"]) == 0
    page = tmp_path / "r" / "quick" / "data-walks"
    assert sorted(p.name for p in page.iterdir() if p.is_dir() and not p.name.startswith(".")) == [
        "measured-calibration", "measured-tracking"]
    md = (page / "index.md").read_text()
    assert "measured-localization: left out: the data set has no scored recording" in md
    assert BANNED.search(md) is None
