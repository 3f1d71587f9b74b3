"""Failures that adversarial use of the suite found (issue 26): relative report paths, corrupt cached reports,
a lost Dask scheduler, a full disk, raw parameter values in report.md and file modes. Runs on the toy suite of
tests/test_suite.py."""
import csv
import errno
import json
import os
import stat
import subprocess
import sys

import pytest

from locbook.suite import load_suite, run_suite
from locbook.suite.cli import main
from test_suite import alive, processes_mentioning, run, set_profile, toy, wait_for  # noqa: F401 (toy: fixture)

pytestmark = pytest.mark.notebooks


@pytest.fixture(autouse=True)
def fixed_source(monkeypatch):
    """Other work may edit locbook's source while these tests run; the cache key's source part is held fixed
    so that 'cached' depends on what each test does only."""
    monkeypatch.setattr("locbook.suite.runner._source_fingerprint", lambda: "fixed source")


def _suite_args(toy):
    return ["--suite", str(toy / "notebooks" / "experiments.toml")]


# -- item 1: relative --reports / --out ---------------------------------------------------------------------

def test_relative_reports_and_out_folders_work_from_any_cwd(toy, tmp_path, monkeypatch, capsys):
    work = tmp_path / "elsewhere"
    work.mkdir()
    monkeypatch.chdir(work)
    assert main([*_suite_args(toy), "run", "george-one", "--reports", "rel-reports"]) == 0, capsys.readouterr()
    folder = work / "rel-reports" / "quick" / "george-one"
    assert (folder / "report.md").is_file() and (folder / "numbers.csv").is_file()
    assert main([*_suite_args(toy), "run", "george-two", "--out", "rel-out"]) == 0, capsys.readouterr()
    assert (work / "rel-out" / "george-two" / "report.md").is_file()
    # nothing was written relative to the notebooks' folder, where the kernels run
    assert not list((toy / "notebooks").glob("rel-*"))
    # the API resolves too: run_suite with a relative report_root
    suite = load_suite(toy / "notebooks" / "experiments.toml")
    result = run_suite(suite, suite.experiments[:1], "quick", report_root="api-reports", progress="quiet",
                       force=True)
    assert result.report_dir.is_absolute() and result.count("ok") == 1, result.outcomes


# -- item 3: corrupt cached reports are not cached ----------------------------------------------------------

def test_non_utf8_numbers_csv_is_not_served_and_does_not_crash_the_run(toy, capsys):
    assert run(toy) == 0
    folder = toy / "reports" / "quick"
    numbers = folder / "george-one" / "numbers.csv"
    numbers.write_bytes(numbers.read_bytes() + b"\xff\xfe garbage \x80\n")
    capsys.readouterr()
    assert run(toy) == 0
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    assert "george-one: ok" in out and "george-two: cached" in out
    assert sum("george-one" in line and "numbers.csv" in line and "not UTF-8" in line
               for line in out.splitlines()) == 1, out
    numbers.read_bytes().decode("utf-8")          # replaced by a fresh, valid report
    # an experiment NOT selected with a corrupt numbers.csv: the suite files are still rebuilt
    other = folder / "george-two" / "numbers.csv"
    other.write_bytes(b"\xff" * 20)
    assert run(toy, "george-one", "--force") == 0
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    rows = list(csv.DictReader((folder / "numbers.csv").read_text(encoding="utf-8").splitlines()))
    assert [r["experiment"] for r in rows] == ["george-one"]
    assert main([*_suite_args(toy), "list", "--reports", str(toy / "reports")]) == 0
    assert main([*_suite_args(toy), "show", "george-two", "--reports", str(toy / "reports")]) == 0


@pytest.mark.parametrize("damage", [b"{ not json", b"[1, 2]", b'{"experiment": "george-two"}', b"\xff\xfe"])
def test_a_corrupt_report_json_is_not_served_as_cached(toy, capsys, damage):
    assert run(toy) == 0
    (toy / "reports" / "quick" / "george-one" / "report.json").write_bytes(damage)
    capsys.readouterr()
    assert run(toy) == 0
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    assert "george-one: ok" in out and "george-two: cached" in out
    assert sum("george-one" in line and "report.json" in line for line in out.splitlines()) == 1, out
    record = json.loads((toy / "reports" / "quick" / "george-one" / "report.json").read_text())
    assert record["experiment"] == "george-one"


# -- item 12: report.md escapes parameter values; kernel-stderr.log is not executable ----------------------

STRING_PARAM = 'label: str = "plain"  # free text\n'


def test_string_parameters_are_escaped_in_report_md(toy):
    from test_suite import PARAMS, _notebook
    _notebook(toy / "notebooks" / "one.ipynb", PARAMS + STRING_PARAM)
    payload = "<script>alert(1)</script><img src=x onerror=alert(2)>&amp;"
    assert run(toy, "george-one", "-p", f"label={json.dumps(payload)}") == 0
    made = next(p for p in (toy / "reports").iterdir() if p.name.startswith("quick-label-"))
    page = (made / "george-one" / "report.md").read_text(encoding="utf-8")
    assert "<script>" not in page and "<img" not in page and "&amp;amp;" in page
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in page
    html = (made / "george-one" / "report.html").read_text(encoding="utf-8")
    assert "<script>alert" not in html


def test_kernel_stderr_log_has_the_mode_of_the_other_report_files(toy):
    old = os.umask(0o022)
    try:
        assert run(toy, "george-one") == 0
    finally:
        os.umask(old)
    folder = toy / "reports" / "quick" / "george-one"
    mode = lambda name: stat.S_IMODE((folder / name).stat().st_mode)
    assert mode("kernel-stderr.log") == mode("numbers.csv") == mode("report.md") == 0o644
