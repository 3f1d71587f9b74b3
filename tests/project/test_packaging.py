"""A real package: the wheel ships the notebooks, the experiment list and the data; an installed
locbook runs its experiments from any folder, copies its notebooks out, and tells its version and parameters."""
import os
import subprocess
import sys
import sysconfig
import tomllib
from pathlib import Path

import pytest
from setuptools import find_packages

from builders import REPO_ROOT
from locbook import __version__
from locbook.suite import load_suite
from locbook.suite.catalog import copy_notebooks, list_text, show_text
from locbook.suite.cli import main
from locbook.suite.spec import SuiteError

pytestmark = pytest.mark.installed

REPO = REPO_ROOT


def test_the_package_list_is_every_package_on_disk_plus_the_notebooks():
    config = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]
    on_disk = set(find_packages(str(REPO), include=["locbook", "locbook.*"]))
    assert set(config["packages"]) == on_disk | {"locbook.notebooks"}
    assert config["package-dir"] == {"locbook.notebooks": "notebooks"}


def test_version_list_and_show(capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["--version"])
    assert exit_.value.code == 0 and capsys.readouterr().out.strip() == f"locbook {__version__}"
    suite = load_suite(REPO / "notebooks" / "experiments.toml")
    text = list_text(suite, REPO / "reports")
    assert all(exp.id in text for exp in suite.experiments)
    shown = show_text(suite, "george-tracking", REPO / "reports")
    # the type, the default, the profile values, the rule of experiments.toml and the cell's comment
    assert "n_monte_carlo: int = 300   [quick 300, full 10000]   allowed: >= 2, finite" in shown
    assert "repetitions of the whole experiment" in shown
    assert "trajectory: Literal['centerline', 'zigzag']" in shown
    with pytest.raises(SuiteError, match="unknown experiment"):
        show_text(suite, "no-such-experiment", REPO / "reports")


def test_list_says_which_machine_each_profiles_times_came_from(tmp_path):
    """`locbook list` showed full faster than quick with times from two machines, unlabelled. A label equal to this
    machine's says only that the CPU model is the same (a committed report may come from another machine of that
    model, under another load), never "this machine"."""
    import json

    from locbook.suite.catalog import machine_label
    suite = load_suite(REPO / "notebooks" / "experiments.toml")
    for profile, eid, seconds, machine in (("quick", "george-crlb", 4.0, machine_label()),
                                           ("full", "george-crlb", 2.0, "Some CPU, 64 CPUs"),
                                           ("full", "george-geometry", 3.0, None)):
        folder = tmp_path / profile / eid
        folder.mkdir(parents=True)
        record = {"experiment": eid, "profile": profile, "seconds": seconds}
        if machine:
            record["machine"] = machine
        (folder / "report.json").write_text(json.dumps(record))
    text = list_text(suite, tmp_path)
    assert f"quick times measured on: {machine_label()} (the CPU model of this machine)" in text
    assert "(this machine)" not in text
    assert "full times measured on: Some CPU, 64 CPUs; a machine not recorded" in text


def test_the_console_script_and_python_m_locbook_answer_with_the_distributions_version(tmp_path):
    """The entry points the package declares (pyproject's [project.scripts] and locbook/__main__.py), started from a
    folder outside the source tree, print the version the installed distribution's metadata records."""
    from importlib.metadata import version
    script = Path(sys.executable).parent / "locbook"
    if not script.exists():
        pytest.skip(f"no console script beside {sys.executable} (locbook not installed into this environment)")
    for command in ([str(script), "--version"], [sys.executable, "-m", "locbook", "--version"]):
        done = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, check=True)
        assert done.stdout.strip() == f"locbook {version('locbook')}", command


def test_copy_notebooks_never_overwrites_without_force(tmp_path):
    suite = load_suite(REPO / "notebooks" / "experiments.toml")
    dest = copy_notebooks(suite, tmp_path / "notebooks")
    copied = load_suite(dest / "experiments.toml")           # the copy is a complete suite
    assert [e.id for e in copied.experiments] == [e.id for e in suite.experiments]
    assert copied.repository is None and copied.default_reports() == Path.cwd() / "reports"
    (dest / "george" / "tracking.ipynb").write_text("my edits")
    with pytest.raises(SuiteError, match="already exist"):
        copy_notebooks(suite, dest)
    assert (dest / "george" / "tracking.ipynb").read_text() == "my edits"
    copy_notebooks(suite, dest, force=True)
    assert (dest / "george" / "tracking.ipynb").read_bytes() == (REPO / "notebooks/george/tracking.ipynb").read_bytes()


@pytest.mark.notebooks
def test_a_wheel_installed_in_a_fresh_venv_runs_george_from_an_empty_folder(tmp_path):
    """Build the wheel, install it (without dependencies) into a new virtual environment whose dependencies come
    from this one, and run the george experiments from an empty folder: reports land in ./reports."""
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(wheels), str(REPO)],
                   check=True, capture_output=True)
    wheel = next(wheels.glob("locbook-*.whl"))
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    site = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                               check=True, capture_output=True, text=True).stdout.strip())
    # the wheel first: with this environment's packages already on the path, pip would see this environment's
    # locbook (an installed one, of the same version) and install nothing
    subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "-q", "--no-deps", str(wheel)],
                   check=True, capture_output=True)
    assert list(site.glob("locbook-*.dist-info")), "the wheel was not installed into the fresh environment"
    # this environment's packages after the fresh one's own (a plain path line: its editable locbook is not loaded)
    (site / "deps.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    empty = tmp_path / "empty"
    empty.mkdir()
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["PATH"] = f"{venv / 'bin'}:{env['PATH']}"
    env["JUPYTER_PATH"] = str(Path(sys.prefix) / "share" / "jupyter")     # nbconvert's templates of the borrowed deps
    where = subprocess.run([str(python), "-c", "import locbook; print(locbook.__file__)"], cwd=empty, env=env,
                           check=True, capture_output=True, text=True).stdout.strip()
    assert where.startswith(str(site)), where                       # the wheel's locbook, not the clone's
    run = subprocess.run([str(venv / "bin" / "locbook"), "run", "george"], cwd=empty, env=env,
                         capture_output=True, text=True, timeout=1800)
    assert run.returncode == 0, run.stdout + run.stderr
    reports = empty / "reports" / "quick"
    suite = load_suite(REPO / "notebooks" / "experiments.toml")
    for exp in suite.select(["george"]):
        assert (reports / exp.id / "report.md").is_file(), exp.id
    assert (reports / "index.html").is_file()
    copied = subprocess.run([str(venv / "bin" / "locbook"), "notebooks", "mine"], cwd=empty, env=env,
                            capture_output=True, text=True)
    assert copied.returncode == 0, copied.stderr
    assert (empty / "mine" / "experiments.toml").is_file() and (empty / "mine" / "george" / "tracking.ipynb").is_file()


def test_the_data_log_tracks_the_imported_packages_own_data_wherever_it_is_installed(tmp_path):
    """A kernel may import another locbook than the runner (an installed one, while the runner's roots name a
    source tree): the data files of the locbook it imports are still logged, so the cache notices them.

    The package is the one the subprocess imports, which it reports: this test process may import another (the clone's
    source tree, when the tests run from a clone beside a non-editable install)."""
    import hashlib
    import json
    log = tmp_path / "read.log"
    env = {**os.environ, "LOCBOOK_DATA_LOG": str(log), "LOCBOOK_DATA_ROOTS": str(tmp_path / "elsewhere")}
    done = subprocess.run([sys.executable, "-c", "import locbook; locbook.printed('george'); "
                           "open(locbook.__file__).read(); print(locbook.__file__)"],
                          cwd=tmp_path, env=env, check=True, capture_output=True, text=True)
    package = Path(done.stdout.strip()).resolve().parent
    george = package / "data" / "printed" / "george.csv"
    assert [json.loads(line) for line in log.read_text().splitlines()] == [
        {"path": str(george), "sha256": hashlib.sha256(george.read_bytes()).hexdigest()}]


def test_the_docs_state_every_exit_status_of_locbook_run():
    from locbook.suite import cli
    readme = (REPO / "docs" / "running.md").read_text(encoding="utf-8")
    section = readme.split("## Interrupts, concurrent runs and the cache", 1)[1].split("\n## ", 1)[0]
    table = dict(line.strip("|").split("|", 1)[0:2] for line in section.splitlines()
                 if line.startswith("| ") and not line.startswith("| status"))
    statuses = {k.strip(): v.strip() for k, v in table.items()}
    assert set(statuses) == {str(cli.EXIT_OK), str(cli.EXIT_FAILED), str(cli.EXIT_BAD_INPUT),
                             str(cli.EXIT_DISK_FULL), "130 / 143"}
    assert "no space left" in statuses[str(cli.EXIT_DISK_FULL)] and "bad input" in statuses[str(cli.EXIT_BAD_INPUT)]
    assert len({cli.EXIT_OK, cli.EXIT_FAILED, cli.EXIT_BAD_INPUT, cli.EXIT_DISK_FULL, 130, 143}) == 6

