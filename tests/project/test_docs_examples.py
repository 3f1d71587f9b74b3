"""The docs run: every ```python block of docs/ executes (the blocks of one page in order, in one namespace, like a
notebook), every `locbook ...` line of their shell blocks is parsed by the CLI's own argument parser and the cheap ones
are run, the Examples section of every public name's docstring (``locbook._API``) passes doctest, and (marked ``docs``)
the Sphinx build passes with warnings as errors.

A block that cannot run here is fenced ```python no-run: REASON (the reason is required). README's commands and
Python blocks are run by tests/project/test_notebooks.py, and docs/your-data.md's by
tests/scenarios/test_measured.py (with fewer resamples), not again here."""
import argparse
import doctest
import importlib
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import locbook
from builders import REPO_ROOT

REPO = REPO_ROOT
DOCS = REPO / "docs"
GENERATED = ("_build", "api")                 # the build's output and its generated API pages (docs/conf.py)
PAGES = sorted(p for p in DOCS.rglob("*.md") if not set(p.relative_to(DOCS).parts) & set(GENERATED)) \
    if DOCS.is_dir() else []
FENCE = re.compile(r"^```([^\n]*)\n(.*?)^```", re.S | re.M)
#: pages whose blocks another test runs (the whole measured-data protocol takes minutes as written: that test runs it
#: with fewer resamples)
RUN_ELSEWHERE = {"your-data.md": "tests/scenarios/test_measured.py::test_the_python_example_of_docs_your_data_runs"}
#: `locbook` commands cheap enough to run as written (in a temporary folder)
CHEAP = re.compile(r"^locbook (--help|--version|list\b|show \S+$|data example )")


def _pages():
    if not PAGES:
        pytest.skip("the docs are not beside the tests (an installed package)")
    return PAGES


def _blocks(page: Path, language: str) -> list[tuple[str, str]]:
    """(fence info after the language, code) of each block of ``language`` on the page."""
    out = []
    for info, code in FENCE.findall(page.read_text(encoding="utf-8")):
        words = info.split(None, 1)
        if words and words[0] == language:
            out.append((words[1] if len(words) > 1 else "", code))
    return out


def _page_id(page: Path) -> str:
    return str(page.relative_to(DOCS))


def _page_params():
    return [p for p in PAGES if _page_id(p) not in RUN_ELSEWHERE
            and any(not info.startswith("no-run") for info, _ in _blocks(p, "python"))]


@pytest.mark.parametrize("page", _page_params(), ids=_page_id)
def test_every_python_block_of_a_page_runs(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)               # whatever a block writes lands here
    monkeypatch.setenv("MPLBACKEND", "Agg")
    namespace = {"__name__": "__docs__"}
    for i, (info, code) in enumerate(_blocks(page, "python")):
        if info.startswith("no-run"):
            assert re.match(r"no-run: \S", info), f"block {i + 1}: a no-run block says why (```python no-run: REASON)"
            continue
        assert info == "", f"block {i + 1}: unknown fence marker {info!r} (only `no-run: REASON`)"
        if "filterpy" in code:
            pytest.importorskip("filterpy")
        exec(compile(code, f"{page.name}, python block {i + 1}", "exec"), namespace)


def test_no_run_blocks_are_rare_and_say_why():
    blocks = [info for page in _pages() for info, _ in _blocks(page, "python")]
    skipped = [info for info in blocks if info.startswith("no-run")]
    assert all(re.match(r"no-run: \S", info) for info in skipped), skipped
    assert len(skipped) <= max(2, len(blocks) // 5), skipped


def _locbook_lines() -> list[tuple[str, str]]:
    """(page, command) for every `locbook ...` line of every shell block: comments dropped, `&&` chains split."""
    out = []
    for page in _pages():
        for language in ("bash", "sh", "console"):
            for _, code in _blocks(page, language):
                for line in code.splitlines():
                    line = re.sub(r"\s+#.*$", "", line).strip()
                    out += [(_page_id(page), part.strip()) for part in line.split("&&")
                            if part.strip().startswith("locbook ")]
    return out


class _Parsed(Exception):
    pass


def _parse_only(argv: list[str]) -> argparse.Namespace:
    """The CLI's own parser on ``argv``, stopped right after parsing (nothing runs)."""
    from locbook.suite import cli
    real = argparse.ArgumentParser.parse_args

    def parse_then_stop(self, args=None, namespace=None):
        raise _Parsed(real(self, args, namespace))
    argparse.ArgumentParser.parse_args = parse_then_stop
    try:
        cli.main(argv)
    except _Parsed as done:
        return done.args[0]
    finally:
        argparse.ArgumentParser.parse_args = real
    raise AssertionError(f"locbook {' '.join(argv)}: the CLI returned without parsing its arguments")


def test_docs_show_locbook_commands():
    commands = [c for _, c in _locbook_lines()]
    assert any(c.startswith("locbook run") for c in commands) and any(c.startswith("locbook data example")
                                                                      for c in commands)


@pytest.mark.parametrize("command", [c for _, c in _locbook_lines()] if PAGES else [])
def test_every_locbook_command_of_the_docs_parses(command, capsys):
    argv = shlex.split(command)[1:]
    if argv in (["--version"], ["--help"]) or argv[-1:] == ["--help"]:
        with pytest.raises(SystemExit) as stop:
            _parse_only(argv)
        assert stop.value.code == 0
        return
    try:
        args = _parse_only(argv)
    except SystemExit as error:            # argparse's usage error, printed to stderr
        pytest.fail(f"{command}: {capsys.readouterr().err.strip()} (exit {error.code})")
    assert args.command == argv[next(i for i, a in enumerate(argv) if not a.startswith("-"))]


@pytest.mark.parametrize("command", [c for _, c in _locbook_lines() if CHEAP.match(c)] if PAGES else [])
def test_the_cheap_locbook_commands_of_the_docs_run(command, tmp_path):
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(Path(locbook.__file__).parents[1]),
                                                         os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-m", "locbook", *shlex.split(command)[1:]], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip() or any(tmp_path.iterdir())


# --- the public API's docstring examples -----------------------------------------------------------------------
#: the entry points a user calls first: each has a numpydoc Examples section
FIRST_CALLED = ("PathLossModel", "RssModel", "constant_velocity", "kalman_filter", "extended_kalman_filter",
                "unscented_kalman_filter", "rts_smoother", "particle_filter", "grid_bayes_filter", "fit_noise_ml",
                "OnlineFilter", "posterior_crlb", "rss_crlb_m", "rmse_m")
MODULES = sorted({module for _, module, _ in locbook._API})


def _public(module: str) -> list[tuple[str, object]]:
    names = [n for _, m, ns in locbook._API if m == module for n in ns]
    home = importlib.import_module(f"locbook.{module}")
    return [(name, getattr(home, name)) for name in names]


def _examples(name: str, obj) -> list[doctest.DocTest]:
    """The doctests of ``obj``'s own docstring (not its members'), with ``np`` and ``lb`` imported."""
    finder = doctest.DocTestFinder(recurse=False, exclude_empty=True)
    return finder.find(obj, f"locbook.{name}", globs={"np": np, "lb": locbook}) if getattr(obj, "__doc__", None) \
        else []


def test_docstring_examples_of_the_public_api_pass():
    """Every Examples section of a public name's docstring, module by module (a module without one has nothing to
    run); the failures are named by module."""
    failed, ran = {}, 0
    for module in MODULES:
        tests = [t for name, obj in _public(module) for t in _examples(name, obj) if t.examples]
        runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
        with np.printoptions(legacy=False):
            for test in tests:
                runner.run(test)
        result = runner.summarize(verbose=False)
        ran += result.attempted
        if result.failed:
            failed[module] = result.failed
    assert ran >= len(FIRST_CALLED) and not failed, f"doctest failures by module: {failed}"


@pytest.mark.parametrize("name", FIRST_CALLED)
def test_the_first_called_entry_points_have_examples(name):
    obj = getattr(locbook, name)
    assert re.search(r"^\s*Examples\n\s*-{8}\n", obj.__doc__, re.M), f"{name}: no numpydoc Examples section"
    assert any(t.examples for t in _examples(name, obj))


# --- the build ---------------------------------------------------------------------------------------------------
@pytest.mark.docs
@pytest.mark.slow
def test_the_docs_build_without_warnings(tmp_path):
    pytest.importorskip("sphinx")
    pytest.importorskip("myst_parser")
    if not (DOCS / "conf.py").exists():
        pytest.skip("the docs are not beside the tests (an installed package)")
    done = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", str(DOCS),
                           str(tmp_path / "html")], capture_output=True, text=True, timeout=1200)
    assert done.returncode == 0, done.stderr[-4000:]
    assert (tmp_path / "html" / "api" / "kalman-family.html").exists()
