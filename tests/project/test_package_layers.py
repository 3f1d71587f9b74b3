"""The library's layers: the models, filters, estimators, bounds, data and reproduction modules never import a
per-document scenario module or the suite (a scenario builds on the library, never the other way round).

Every module is parsed with `ast` (nothing is imported); an import anywhere in its text counts, at module level or
inside a function.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

import locbook

PACKAGE_DIR = Path(locbook.__file__).parent
#: the library's core: subpackages and top-level modules that a scenario or the suite may use, not the reverse
CORE = ("models", "tracking", "static", "bounds", "data", "reproduce", "geometry.py", "metrics.py", "montecarlo.py",
        "battery.py", "inertial_trackers.py", "plotting.py", "errors.py")
UPPER = ("locbook.scenarios", "locbook.suite")


def _imported(path: Path, text: str | None = None) -> set[str]:
    """The absolute names of the modules the imports of `path` (or `text`, read as that file) name; relative
    imports resolved against the file's package."""
    parts = list(path.relative_to(PACKAGE_DIR.parent).with_suffix("").parts)
    package = parts[:-1]            # a module's package; for __init__.py, the package itself
    names = set()
    tree = ast.parse(path.read_text(encoding="utf-8") if text is None else text, filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names |= {alias.name for alias in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = package[: len(package) - node.level + 1] if node.level else []
            prefix = ".".join(base + ([node.module] if node.module else []))
            names |= {prefix} | {f"{prefix}.{alias.name}" for alias in node.names}
    return names


def _core_files() -> list[Path]:
    files = []
    for entry in CORE:
        target = PACKAGE_DIR / entry
        files += sorted(target.rglob("*.py")) if target.is_dir() else [target]
    return files


@pytest.mark.parametrize("path", _core_files(), ids=lambda p: str(p.relative_to(PACKAGE_DIR)))
def test_a_core_module_imports_no_scenario_and_no_suite_module(path):
    upward = sorted(n for n in _imported(path) if any(n == u or n.startswith(u + ".") for u in UPPER))
    assert not upward, f"{path.relative_to(PACKAGE_DIR)} imports {upward}"


def test_the_check_sees_an_upward_import():
    """The scan resolves relative imports: a core module's ``from ..scenarios import dogan`` is found, and an
    ``__init__.py``'s ``from .scenarios`` is its own package's subpackage."""
    names = _imported(PACKAGE_DIR / "tracking" / "probe.py",
                      "from ..scenarios import dogan\nfrom ..suite.files import x\n")
    assert {"locbook.scenarios", "locbook.scenarios.dogan", "locbook.suite.files"} <= names
    assert "locbook.tracking.kalman" in _imported(PACKAGE_DIR / "tracking" / "__init__.py", "from .kalman import x\n")
