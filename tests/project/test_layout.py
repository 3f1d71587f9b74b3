"""tests/ mirrors locbook/: every test module lives in a folder named after a locbook subpackage (tests/tracking/ for
locbook/tracking/, ...) or in tests/project/ (packaging, docs, the CLI's start-up, notebooks, the site), and no test
module imports another one: what several modules share is a fixture in a conftest.py or a helper in a module of
tests/ that is not a test module (builders.py, toy_suite.py, oracles.py). docs/testing.md, "Where tests live"."""
import ast

from builders import REPO_ROOT, TESTS_DIR

#: the folders a test module may live in: locbook's subpackages, and project/ for what belongs to no subpackage
FOLDERS = {p.parent.name for p in (REPO_ROOT / "locbook").glob("*/__init__.py")} | {"project"}


def _test_modules():
    return sorted(TESTS_DIR.rglob("test_*.py"))


def test_the_folders_are_the_subpackages_and_project():
    assert {"models", "tracking", "static", "bounds", "data", "suite", "scenarios", "reproduce"} <= FOLDERS
    folders = {p.name for p in TESTS_DIR.iterdir() if p.is_dir() and p.name != "__pycache__"}
    assert folders <= FOLDERS, f"folders of tests/ named after no locbook subpackage: {sorted(folders - FOLDERS)}"


def test_every_test_module_lives_in_a_subpackage_folder_or_project():
    modules = _test_modules()
    assert len(modules) > 100                                   # the walk found the modules
    misplaced = [str(p.relative_to(TESTS_DIR)) for p in modules
                 if len(p.relative_to(TESTS_DIR).parts) != 2 or p.parent.name not in FOLDERS]
    assert misplaced == [], f"test modules outside tests/<subpackage>/ or tests/project/: {misplaced}"


def test_test_module_names_are_unique():
    # pytest imports a module of a folder without __init__.py by its file name: two of one name would clash
    names = [p.name for p in _test_modules()]
    assert sorted({n for n in names if names.count(n) > 1}) == []


def _imported(path):
    """The top-level names of every module ``path`` imports (at module level or inside a function)."""
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            yield from (alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.module.split(".")[0]


def test_no_test_module_imports_another():
    python_files = sorted(TESTS_DIR.rglob("*.py"))
    found = [(str(p.relative_to(TESTS_DIR)), name) for p in python_files for name in _imported(p)
             if name.startswith("test_") or name == "conftest"]
    assert found == [], f"imports of test modules (move what they share to conftest.py or a helper): {found}"


def test_the_layout_check_sees_a_test_module_import(tmp_path):
    path = tmp_path / "test_x.py"
    path.write_text("def f():\n    from test_other import helper\nimport conftest\nfrom builders import REPO_ROOT\n")
    assert sorted(_imported(path)) == ["builders", "conftest", "test_other"]
