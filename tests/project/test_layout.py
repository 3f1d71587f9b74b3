"""tests/ mirrors locbook/: every test module lives in a folder named after a locbook subpackage (tests/tracking/ for
locbook/tracking/, ...) or in tests/project/ (packaging, docs, the CLI's start-up, notebooks, the site), and no test
module imports another one: what several modules share is a fixture in a conftest.py or a helper in a module of
tests/ that is not a test module (builders.py, toy_suite.py, oracles.py). docs/testing.md, "Where tests live".
No comment or docstring of locbook/, tests/ or a notebook's code cites this project's tracker by number."""
import ast
import json
import re
import tomllib

import yaml

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


#: "issue NN", "issues NN, MM", "issue #NN" with digits: a tracker number says nothing to a reader of the package
ISSUE_REFERENCE = re.compile(r"[Ii]ssues? ?#?[0-9]+")
#: the third-party projects whose trackers may be cited, as "<project> issue NN" (a filterpy test's origin)
THIRD_PARTY_TRACKERS = {"filterpy"}


def _issue_references(text):
    """The "issue NN" references in ``text`` that name no tracker of :data:`THIRD_PARTY_TRACKERS`, with their line."""
    for m in ISSUE_REFERENCE.finditer(text):
        before = re.search(r"([\w.-]+)\s+$", text[:m.start()])
        if before is None or before.group(1).lower() not in THIRD_PARTY_TRACKERS:
            yield text.count("\n", 0, m.start()) + 1, m.group()


def _scanned_texts():
    """(label, text) of every .py file of locbook/, tests/ and benchmarks/, pyproject.toml, the suite file, the
    package's data tables (.csv, .toml), every page of docs/ and README, and every code cell of the notebooks.
    benchmarks/RESULTS.md is a log of measurements by the work that made them, and stays out."""
    for folder in ("locbook", "tests", "benchmarks"):
        for path in sorted((REPO_ROOT / folder).rglob("*.py")):
            yield str(path.relative_to(REPO_ROOT)), path.read_text(encoding="utf-8")
    for name in ("pyproject.toml", "notebooks/experiments.toml"):
        yield name, (REPO_ROOT / name).read_text(encoding="utf-8")
    for pattern in ("*.csv", "*.toml"):
        for path in sorted((REPO_ROOT / "locbook" / "data").rglob(pattern)):
            yield str(path.relative_to(REPO_ROOT)), path.read_text(encoding="utf-8")
    for path in [REPO_ROOT / "README.md", *sorted((REPO_ROOT / "docs").rglob("*.md"))]:
        yield str(path.relative_to(REPO_ROOT)), path.read_text(encoding="utf-8")
    for folder in ("locbook", "notebooks"):
        for path in sorted((REPO_ROOT / folder).rglob("*.ipynb")):
            cells = json.loads(path.read_text(encoding="utf-8"))["cells"]
            for i, cell in enumerate(cells):
                if cell["cell_type"] == "code":
                    yield f"{path.relative_to(REPO_ROOT)} cell {i}", "".join(cell["source"])


def test_no_issue_numbers_in_the_package_the_tests_the_docs_or_the_notebooks():
    texts = list(_scanned_texts())
    assert any(label.startswith("docs/") for label, _ in texts)
    assert sum(label.startswith("locbook/") for label, _ in texts) > 100      # the walk found the package
    assert sum(".ipynb cell" in label for label, _ in texts) > 50               # and the notebooks' code cells
    found = [f"{label}:{line}: {ref}" for label, text in texts for line, ref in _issue_references(text)]
    assert found == [], f"tracker numbers (say what is meant instead): {found}"


def test_the_issue_check_sees_a_reference_and_allows_a_third_party_tracker():
    # the numbers in braces, so that this file's source passes its own check
    text = (f"# before issue {47}\n# filterpy issue {172}: a 1-D walk\n# Issues {28}, 45\n# see issue #{3}\n"
            "# reissued 2 times\n")
    assert list(_issue_references(text)) == [(1, f"issue {47}"), (3, f"Issues {28}"), (4, f"issue #{3}")]


def test_the_licence_and_the_citation_file_agree_with_pyproject():
    """LICENSE is the licence pyproject declares, CITATION.cff (Citation File Format 1.2.0) names the same version
    and licence, and README and docs/sources.md say how to cite locbook."""
    project = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    assert project["license"] == {"text": "MIT"}
    assert (REPO_ROOT / "LICENSE").read_text(encoding="utf-8").startswith("MIT License\n")
    cff = yaml.safe_load((REPO_ROOT / "CITATION.cff").read_text(encoding="utf-8"))
    assert cff["cff-version"] == "1.2.0" and cff["type"] == "software"
    assert str(cff["version"]) == project["version"] and cff["license"] == "MIT"
    assert cff["title"].startswith("locbook") and cff["authors"] and cff["message"]
    assert "CITATION.cff" in (REPO_ROOT / "README.md").read_text(encoding="utf-8")
    sources = (REPO_ROOT / "docs" / "sources.md").read_text(encoding="utf-8")
    assert "## Citing locbook" in sources and f"version = {{{project['version']}}}" in sources
