"""Every notebook of the suite, executed at the quick profile, produces its reports."""
import csv
import json
from pathlib import Path

import pytest

import locbook
from locbook.suite import load_suite, read_parameters, run_suite
from locbook.suite.bracket import SITE_NUMBER_COLUMNS

SUITE = load_suite()
pytestmark = pytest.mark.notebooks


@pytest.mark.installed
def test_every_notebook_declares_typed_parameters_and_is_committed_without_outputs():
    import nbformat
    for exp in SUITE.experiments:
        params = read_parameters(exp.notebook)            # raises on a missing annotation
        assert "seed" in params, exp.id
        assert exp.unruled_numeric_parameters() == [], exp.id   # every number has a declared range
        for profile in ("quick", "full"):
            exp.parameters(profile)                        # profile values match the declared types
        nb = nbformat.read(str(exp.notebook), as_version=4)
        assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code"), exp.id


@pytest.mark.installed
def test_one_notebook_per_document_runs_from_the_package_and_reads_its_own_data(tmp_path):
    """The installed pass's notebook check (docs/testing.md): the first experiment of every document, run at the
    quick profile, writes its page, summary and figures and the site's index, and every data file its kernel read
    is one of the data files of the locbook this process imported (the installed copy, in that pass)."""
    first = {}
    for exp in SUITE.experiments:
        first.setdefault(exp.document.key, exp)
    assert len(first) == len({e.document.key for e in SUITE.experiments}) > 1
    run = run_suite(SUITE, list(first.values()), "quick", jobs=2, report_root=tmp_path, progress="quiet")
    assert {o.id: o.status for o in run.outcomes} == {e.id: "ok" for e in first.values()}, \
        [o.error for o in run.outcomes]
    folder, package = run.report_dir, Path(locbook.__file__).resolve().parent
    assert (folder / "index.html").exists()
    for exp in first.values():
        assert (folder / exp.id / f"{exp.id}.html").exists() and (folder / exp.id / "summary.md").exists(), exp.id
        assert list((folder / exp.id).glob("*.png")), exp.id
        data = json.loads((folder / exp.id / "run.json").read_text())["data"]
        assert data, exp.id
        assert all(Path(p).resolve().is_relative_to(package) for p in data), (exp.id, package, list(data))


@pytest.fixture(scope="module")
def quick_reports(tmp_path_factory):
    root = tmp_path_factory.mktemp("reports")
    run = run_suite(SUITE, SUITE.experiments, "quick", jobs=2, report_root=root, progress="quiet")
    return run.report_dir, run.outcomes


def test_quick_profile_runs_every_notebook(quick_reports):
    folder, outcomes = quick_reports
    assert {o.id: o.status for o in outcomes} == {e.id: "ok" for e in SUITE.experiments}, [o.error for o in outcomes]
    assert (folder / "index.html").exists()
    for exp in SUITE.experiments:
        assert (folder / exp.id / f"{exp.id}.html").exists()
        assert (folder / exp.id / "summary.md").exists()
        assert list((folder / exp.id).glob("*.png")), exp.id
    # the data files each experiment read are recorded with their hashes (the printed-value tables)
    data = {exp.id: json.loads((folder / exp.id / "run.json").read_text())["data"] for exp in SUITE.experiments}
    assert any(p.endswith("data/printed/ozkaya2011.csv") for p in data["ozkaya2011-nn-sim"])
    assert any(p.endswith("data/printed/dogan2015.csv") for p in data["dogan2015-tracking"])
    assert [p.split("/")[-1] for p in data["george-tracking"]] == ["george.csv"]


def test_numbers_csv_holds_the_printed_numbers(quick_reports):
    folder, _ = quick_reports
    with open(folder / "numbers.csv") as fh:
        reader = csv.DictReader(fh)
        assert tuple(reader.fieldnames) == SITE_NUMBER_COLUMNS     # an experiment's columns, then its bracket
        rows = {(r["experiment"], r["quantity"]): r for r in reader}
    assert {r["bracket"] for r in rows.values()} == {""}      # no bracket was run for this folder
    # printed values exactly as printed (the text of locbook/data/printed/george.csv)
    c_raw = rows[("george-tracking", "mean error C without filter")]
    assert c_raw["printed"] == "2.2867" and c_raw["where"].startswith("Fig. 5")
    assert rows[("george-tracking", "mean error C with Kalman filter")]["printed"] == "1.0378"
    assert rows[("george-tracking", "error reduction")]["printed"] == "54.62"
    assert rows[("george-tracking", "error reduction (abstract)")]["printed"] == "more than 50%"
    # sigma is an assumed 3 dB by default, not chosen from the printed C (1.83 dB, fitted, is an
    # alternative): the rows are reproductions and name no calibration
    assert c_raw["kind"] == "reproduction" and c_raw["calibrated_from"] == ""
    assert rows[("george-tracking", "error reduction (abstract)")]["kind"] == "claim"
