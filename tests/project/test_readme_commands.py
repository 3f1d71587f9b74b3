"""Every command README.md shows is executed here, in the order written, as a user of a clone would type it
(the reports in a temporary folder instead of the clone's `reports/`), and must succeed. The install line and the
test commands are what `.ci/run` itself runs (checked to be there); `jupyter lab` opens a server, so its notebook is
checked to exist and JupyterLab to be installed. README's Python blocks run as written, and a block a command's
``--method NAME=FILE.py:function`` names is saved to that file first."""
import importlib.util
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from builders import REPO_ROOT

REPO = REPO_ROOT
README = REPO / "README.md"
SUITE = REPO / "notebooks" / "experiments.toml"

pytestmark = pytest.mark.notebooks      # the commands execute notebooks (several minutes in all)


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
    import locbook
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


def test_every_readme_command_runs(clone, tmp_path):
    ci = (REPO / ".ci" / "run").read_text()
    reports = tmp_path / "reports"
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
            extra = ["--suite", str(SUITE)]
            if args[1] in ("run", "study", "bracket"):
                extra += ["--reports", str(reports), "--progress", "plain"]
            proc = subprocess.run([sys.executable, "-m", "locbook", *args[1:], *extra], cwd=tmp_path,
                                  capture_output=True, text=True, timeout=1800)
            assert proc.returncode == 0, f"{command}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
            ran.append(command)
        else:
            pytest.fail(f"README shows a command this test does not know how to run: {command}")
    assert len(ran) >= 10
    assert (reports / "quick" / "index.html").is_file()


def test_readme_python_block_runs(clone, tmp_path):
    for block in _blocks("python"):
        proc = subprocess.run([sys.executable, "-c", block], cwd=tmp_path, capture_output=True, text=True, timeout=600)
        assert proc.returncode == 0, proc.stderr[-3000:]
