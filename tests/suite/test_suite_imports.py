"""The suite's modules import one another without a circle (the suite as a DAG).

Every module of locbook/suite is parsed with `ast` (nothing is imported); each import of a locbook.suite module,
at module level or inside a function, is an edge. A cycle means some module must dodge it with a function-level
import, which is what the layering forbids.
"""
from __future__ import annotations

import ast
from pathlib import Path

import locbook.suite

SUITE_DIR = Path(locbook.suite.__file__).parent
PACKAGE = "locbook.suite"


def _target(module: str, node: ast.ImportFrom | ast.Import) -> list[str]:
    """The locbook.suite modules one import statement of `module` names (``from . import x`` names ``x``)."""
    if isinstance(node, ast.Import):
        names = [alias.name for alias in node.names]
    else:
        if node.level:
            base = module.split(".")[: len(module.split(".")) - node.level]
            prefix = ".".join(base + ([node.module] if node.module else []))
        else:
            prefix = node.module or ""
        names = [prefix] + [f"{prefix}.{alias.name}" for alias in node.names]
    modules = {f"{PACKAGE}.{p.stem}" for p in SUITE_DIR.glob("*.py") if p.stem != "__init__"}
    return sorted({n for n in names if n in modules})


def import_graph() -> dict[str, set[str]]:
    """Each locbook.suite module -> the locbook.suite modules it imports anywhere in its text."""
    graph: dict[str, set[str]] = {}
    for path in sorted(SUITE_DIR.glob("*.py")):
        if path.stem == "__init__":
            continue
        module = f"{PACKAGE}.{path.stem}"
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        graph[module] = {t for node in ast.walk(tree) if isinstance(node, (ast.Import, ast.ImportFrom))
                         for t in _target(module, node) if t != module}
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of `graph` as a path that starts and ends at the same module, or None (depth-first search)."""
    state: dict[str, int] = {}          # 1: on the current path, 2: finished
    path: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        path.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return path[path.index(nxt):] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        path.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node)
            if found:
                return found
    return None


def test_find_cycle_names_a_cycle_and_accepts_a_dag():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_graph_sees_relative_and_function_level_imports():
    tree = ast.parse("def f():\n    from .runner import run_tasks\n    from . import site\n")
    found = {t for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)
             for t in _target(f"{PACKAGE}.study", node)}
    assert found == {f"{PACKAGE}.runner", f"{PACKAGE}.site"}


def test_suite_import_graph_has_no_cycle():
    graph = import_graph()
    assert len(graph) >= 10, "the suite's modules were not found"
    cycle = find_cycle(graph)
    assert cycle is None, "locbook.suite imports in a circle: " + " -> ".join(cycle or [])
