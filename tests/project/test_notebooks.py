"""Every notebook of the suite, executed at the quick profile, produces its reports; and every command README.md
shows runs. One module, so that README's `locbook run` is served from the same quick run (its cache) instead of
executing the 28 notebooks a second time: pytest-xdist's `--dist loadfile` keeps a module on one worker.

README: every command README.md shows is executed here, in the order written, as a user of a clone would type it
(the reports in a temporary folder instead of the clone's `reports/`), and must succeed. The install line and the
test commands are what `.ci/run` itself runs (checked to be there); `jupyter lab` opens a server, so its notebook is
checked to exist and JupyterLab to be installed. README's Python blocks run as written, and a block a command's
``--method NAME=FILE.py:function`` names is saved to that file first."""
import csv
import importlib.util
import json
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import locbook
from builders import REPO_ROOT
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


def test_every_notebooks_own_defaults_are_its_quick_profile():
    """'Run all' in Jupyter gives the quick report: every value the quick profile sets equals the default written in
    the notebook's parameters cell (read from the notebook's text, not through the suite's resolver)."""
    import ast

    import nbformat
    differ = []
    for exp in SUITE.experiments:
        nb = nbformat.read(str(exp.notebook), as_version=4)
        cell, = [c for c in nb.cells if "parameters" in c.metadata.get("tags", [])]
        written = {node.target.id: ast.literal_eval(node.value) for node in ast.parse(cell.source).body
                   if isinstance(node, ast.AnnAssign)}
        quick = exp.profiles["quick"]
        assert quick, exp.id                               # a quick profile that sets nothing would pass vacuously
        differ += [(exp.id, name, written.get(name), value) for name, value in quick.items()
                   if written.get(name) != value or type(written.get(name)) is not type(value)]
    assert differ == [], differ


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


REPO = REPO_ROOT
README = REPO / "README.md"
SUITE_FILE = REPO / "notebooks" / "experiments.toml"


def _blocks(language: str) -> list[str]:
    return re.findall(rf"```{language}\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)


def _commands() -> list[str]:
    """Every shell command of README's bash blocks: comments dropped, `&&` chains split."""
    out = []
    for block in _blocks("bash"):
        for line in block.splitlines():
            line = re.sub(r"\s+#.*$", "", line).strip()
            out += [part.strip() for part in line.split("&&") if part.strip()]
    return out


def _in_clone() -> bool:
    return README.exists() and Path(locbook.__file__).resolve().parent == REPO / "locbook"


@pytest.fixture(scope="module")
def clone():
    if not _in_clone():
        pytest.skip("README's commands are for a clone (this run imports an installed locbook)")
    return REPO


def test_readme_shows_commands_of_every_kind():
    commands = _commands()
    assert any(c.startswith("locbook run") for c in commands) and any(c.startswith("locbook data") for c in commands)
    assert any(c.startswith("python -m pytest -q") for c in commands)


def _method_files(commands: list[str]) -> dict[str, str]:
    """The files README's ``--method`` / ``--tracker`` options name (``NAME=FILE.py:function``), each the Python block
    that defines its function: written where the commands run, as a reader would save it."""
    files = {}
    for command in commands:
        for file, function in re.findall(r"--(?:method|tracker)\s+\S+?=(\S+\.py):(\w+)", command):
            block = next((b for b in _blocks("python") if f"def {function}(" in b), None)
            assert block is not None, f"README's {command!r} names {function}, which no Python block defines"
            files[file] = block
    return files


def test_every_readme_command_runs(clone, quick_reports, tmp_path):
    ci = (REPO / ".ci" / "run").read_text()
    # README's first `locbook run` is the quick run above, repeated: given its reports (a copy) it must serve all of
    # them from its cache, which is what a user who runs it twice sees; the later commands execute as written
    reports = tmp_path / "reports"
    shutil.copytree(quick_reports[0].parent, reports)
    ran = []
    for file, block in _method_files(_commands()).items():
        (tmp_path / file).write_text(block, encoding="utf-8")
    for command in _commands():
        args = shlex.split(command)
        if args[0] in ("python3", "python") and args[1:3] == ["-m", "venv"] or args[0] == ".":
            assert "venv .venv" in ci and ". .venv/bin/activate" in ci, command      # CI's own first steps
        elif args[0] == "pip":
            assert '-e ".[test]"' in ci, command
        elif args[:3] == ["python", "-m", "pytest"]:
            assert command in ci, command
        elif args[:2] == ["jupyter", "lab"]:
            assert (REPO / args[2]).is_file(), command
            assert importlib.util.find_spec("jupyterlab") is not None, "JupyterLab is installed with locbook"
        elif args[0] == "locbook":
            extra = ["--suite", str(SUITE_FILE)]
            if args[1] in ("run", "study", "bracket"):
                extra += ["--reports", str(reports), "--progress", "plain"]
            elif args[1] == "compare":
                extra += ["--reports", str(reports)]
            proc = subprocess.run([sys.executable, "-m", "locbook", *args[1:], *extra], cwd=tmp_path,
                                  capture_output=True, text=True, timeout=1800)
            assert proc.returncode == 0, f"{command}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
            if args[1:] == ["run"]:         # SUITE is this clone's suite file (load_suite's default)
                assert f"0 executed, {len(SUITE.experiments)} cached, 0 failed" in proc.stdout, proc.stdout[-3000:]
            ran.append(command)
        else:
            pytest.fail(f"README shows a command this test does not know how to run: {command}")
    assert len(ran) >= 10
    assert (reports / "quick" / "index.html").is_file()


def test_readme_python_block_runs(clone, tmp_path):
    for block in _blocks("python"):
        proc = subprocess.run([sys.executable, "-c", block], cwd=tmp_path, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr[-3000:]
