"""`locbook --version` and `locbook list` answer at once: they import only what they need.
The times themselves are measured by benchmarks/bench_startup.py, not asserted here."""
import subprocess
import sys

import pytest

pytestmark = pytest.mark.installed

HEAVY = ("numpy", "scipy", "pandas", "matplotlib", "cvxpy", "pydantic", "papermill", "nbformat", "jinja2", "rich")
#: what `locbook list` may import beyond `locbook --version`: the experiment list is checked by its pydantic schema
#: (locbook.suite.spec_schema), about 0.05 s of a start-up that stays well under a second (the target;
#: benchmarks/bench_startup.py measures it). pydantic and its own dependencies only.
LIST_MAY_IMPORT = {"pydantic", "pydantic_core", "typing_extensions", "annotated_types", "typing_inspection"}


def _modules_after(code: str) -> set[str]:
    out = subprocess.run([sys.executable, "-c", code + "\nimport sys; print(' '.join(sys.modules))"],
                         capture_output=True, text=True, check=True).stdout.split()
    return {name.split(".")[0] for name in out}


def test_version_and_list_import_no_heavy_package():
    version = _modules_after("from locbook.suite.cli import main\n"
                             "try:\n    main(['--version'])\nexcept SystemExit as exc:\n    assert exc.code == 0")
    listing = _modules_after("import contextlib, io\nfrom locbook.suite.cli import main\n"
                             "with contextlib.redirect_stdout(io.StringIO()) as out:\n    assert main(['list']) == 0\n"
                             "assert 'experiments;' in out.getvalue()")
    assert not version & set(HEAVY), version & set(HEAVY)
    assert not listing & (set(HEAVY) - LIST_MAY_IMPORT), listing & set(HEAVY)
    beyond = {name for name in listing - version if name not in sys.stdlib_module_names and not name.startswith("_")}
    assert beyond <= LIST_MAY_IMPORT, beyond - LIST_MAY_IMPORT
    assert "pydantic" in listing        # the list is checked by its schema (else this test's allowance is stale)


def test_import_locbook_loads_no_submodule_but_the_data_audit_hook():
    loaded = _modules_after("import locbook")
    assert not loaded & set(HEAVY), loaded & set(HEAVY)
    submodules = subprocess.run([sys.executable, "-c", "import sys, locbook; "
                                 "print(' '.join(m for m in sys.modules if m.startswith('locbook.')))"],
                                capture_output=True, text=True, check=True).stdout.split()
    # the lazy-export helper, and the hook that records the data files a kernel reads (LOCBOOK_DATA_LOG)
    assert sorted(submodules) == ["locbook._datalog", "locbook._lazy"]


def test_show_and_the_worker_skip_jsonschemas_iri_grammar_but_still_validate_notebooks():
    """``locbook show`` reads a notebook (nbformat, hence jsonschema) without building rfc3987_syntax's grammar
    (2-3 s of every worker's start-up, the bracket benchmark); nbformat still refuses a broken notebook."""
    shown = _modules_after("import contextlib, io\nfrom locbook.suite.cli import main\n"
                           "with contextlib.redirect_stdout(io.StringIO()):\n"
                           "    assert main(['show', 'george-tracking']) == 0\n"
                           "import nbformat, pytest\nnb = nbformat.v4.new_notebook()\n"
                           "nb.cells = [{'cell_type': 'code'}]\n"
                           "with pytest.raises(nbformat.ValidationError):\n    nbformat.validate(nb)")
    assert "nbformat" in shown and "jsonschema" in shown
    assert "lark" not in shown       # the parser rfc3987_syntax builds its grammar with (its key is present, None)
