"""The static package along its seams: the former single module ``locbook.static.localization`` still gives every
public name it had (the same objects as their new homes), no static module exceeds 800 lines, the static modules
import one another without a circle and without function-level imports (only scipy's lazy ones)."""
import ast
import importlib
from pathlib import Path

import locbook.static
from locbook.static import localization

STATIC = Path(locbook.static.__file__).parent

# the public names of locbook.static.localization before the split, and where each lives now
HOMES = {
    "LocalizationResult": "result", "LOCALIZATION_STATUSES": "result",
    "check_anchor_geometry": "checks", "ANCHOR_CONDITION_RTOL": "checks", "implausible_powers": "checks",
    "IMPLAUSIBLE_SIGMAS": "checks", "GOODNESS_OF_FIT_ALPHA": "checks",
    "lateration_system": "lateration", "lateration_ls": "lateration", "lateration_wls": "lateration",
    "LATERATION_PAIRS": "lateration", "LATERATION_VARIANTS": "lateration",
    "lateration_box_ls": "box_ls", "BOX_LS_SOLVERS": "box_ls",
    "rss_ml_position": "rss_ml",
    "grid_ml_position": "grid_ml", "GRID_ML_BLOCK_BYTES": "grid_ml",
}


def _modules():
    return sorted(p for p in STATIC.glob("*.py") if p.name != "__init__.py")


def test_the_former_module_re_exports_every_public_name_from_its_home():
    assert sorted(localization.__all__) == sorted(HOMES)
    for name, home in HOMES.items():
        module = importlib.import_module(f"locbook.static.{home}")
        assert getattr(localization, name) is getattr(module, name), name
        assert name in module.__all__, (home, name)


def test_no_static_module_is_over_800_lines():
    long = {p.name: n for p in _modules() if (n := len(p.read_text(encoding="utf-8").splitlines())) > 800}
    assert long == {}


def _relative_imports(path: Path) -> tuple[set[str], list[str]]:
    """The static modules ``path`` imports at module level, and every import inside a function (as text)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    top = set()
    for node in tree.body:
        if isinstance(node, ast.ImportFrom) and node.level == 1:
            top.add(node.module.split(".")[0] if node.module else "")
            top |= {alias.name for alias in node.names} if not node.module else set()
    nested = []
    for func in ast.walk(tree):
        if isinstance(func, (ast.FunctionDef, ast.AsyncFunctionDef)):
            for node in ast.walk(func):
                if isinstance(node, ast.Import):
                    nested += [alias.name for alias in node.names]
                elif isinstance(node, ast.ImportFrom):
                    nested.append("." * node.level + (node.module or ""))
    return top, nested


def test_static_modules_import_no_module_inside_a_function_but_scipy():
    nested = {p.name: [m for m in _relative_imports(p)[1] if not m.startswith("scipy")] for p in _modules()}
    assert {name: found for name, found in nested.items() if found} == {}


def test_static_modules_import_one_another_without_a_circle():
    names = {p.stem for p in _modules()}
    graph = {p.stem: _relative_imports(p)[0] & names for p in _modules()}
    done, path = set(), []

    def visit(node):
        assert node not in path, " -> ".join(path[path.index(node):] + [node])
        if node in done:
            return
        path.append(node)
        for dep in sorted(graph[node]):
            visit(dep)
        path.pop()
        done.add(node)

    for node in sorted(graph):
        visit(node)
    assert graph["localization"] >= {"result", "checks", "lateration", "box_ls", "rss_ml", "grid_ml"}
