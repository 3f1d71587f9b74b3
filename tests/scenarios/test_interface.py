"""Every scenario module matches the one declared interface (locbook.scenarios.interface.DocumentScenario)."""
import ast
import collections
import importlib
import inspect
import pkgutil
import typing
from pathlib import Path

import pytest

import locbook.scenarios
from locbook.scenarios.interface import DocumentScenario

P = inspect.Parameter
POSITIONAL = (P.POSITIONAL_ONLY, P.POSITIONAL_OR_KEYWORD)


def _deprecated(name: str) -> bool:
    """An old module path kept for one release (its docstring starts "Deprecated"): it re-exports, defines nothing."""
    source = (Path(locbook.scenarios.__path__[0]) / f"{name}.py").read_text(encoding="utf-8")
    return (ast.get_docstring(ast.parse(source)) or "").startswith("Deprecated")


def _modules():
    names = [m.name for m in pkgutil.iter_modules(locbook.scenarios.__path__)
             if m.name != "interface" and not _deprecated(m.name)]
    return [importlib.import_module(f"locbook.scenarios.{n}") for n in names]


def _own_functions(module):
    """The public functions ``module`` defines (not those it imports or gathers from another module)."""
    return {n: f for n, f in vars(module).items()
            if inspect.isfunction(f) and not n.startswith("_") and f.__module__ == module.__name__}


def _return_type(func):
    ann = inspect.signature(func).return_annotation
    if ann is inspect.Signature.empty:
        return None
    hint = eval(ann, vars(inspect.getmodule(func))) if isinstance(ann, str) else ann
    return type(None) if hint is None else (typing.get_origin(hint) or hint)


def problems(func, name: str) -> list[str]:
    """Why ``func`` does not have the signature of ``DocumentScenario.<name>`` (empty: it has)."""
    want = list(inspect.signature(getattr(DocumentScenario, name)).parameters.values())[1:]      # without self
    have = list(inspect.signature(func).parameters.values())
    fixed = [p for p in want if p.kind == P.POSITIONAL_ONLY]
    open_ended = any(p.kind in (P.VAR_POSITIONAL, P.VAR_KEYWORD) for p in want)
    out = []
    lead = have[:len(fixed)]
    if len(lead) < len(fixed) or any(p.kind not in POSITIONAL for p in lead):
        out.append(f"needs {len(fixed)} leading positional parameters")
    if any(p.default is not P.empty for p in lead):
        out.append("a leading parameter has a default the interface does not give")
    extra = have[len(fixed):]
    if not open_ended and any(p.default is P.empty and p.kind not in (P.VAR_POSITIONAL, P.VAR_KEYWORD) for p in extra):
        out.append("a parameter beyond the interface's has no default")
    want_type = _return_type(getattr(DocumentScenario, name))
    got = _return_type(func)
    if want_type is not object and got is not None and not issubclass(got, want_type):
        out.append(f"returns {got}, the interface {want_type}")
    if want_type is not object and got is None:
        out.append("has no return annotation")
    return out


def test_every_module_matches_the_interface_for_each_name_it_defines():
    checked = collections.Counter()
    for module in _modules():
        for name, func in _own_functions(module).items():
            if hasattr(DocumentScenario, name):
                assert problems(func, name) == [], (module.__name__, name, problems(func, name))
                checked[name] += 1
    # each declared name is one at least two modules share (else it would not need declaring)
    assert all(checked[n] >= 2 for n in ("printed_tables", "table_view", "table_rows", "record_tables", "noise_fit",
                                         "crlb_m")), checked


def test_a_name_two_modules_define_is_declared():
    """Distinct names where the meaning differs: a public function name defined by two scenario modules is one of the
    interface's (so it has one signature), never two unrelated functions that happen to share a name."""
    owners = collections.defaultdict(list)
    for module in _modules():
        for name in _own_functions(module):
            owners[name].append(module.__name__)
    shared = {n: m for n, m in owners.items() if len(m) > 1}
    assert {n for n in shared if not hasattr(DocumentScenario, n)} == set(), shared


def _record_tables(report, rows, *, label=""):
    return None


def _table_rows_needs_more(runs, rmse_epochs):
    return []


def _table_view_keyword_only(*, rows, table) -> list[dict]:
    return []


def _printed_tables_of_a_dict() -> dict:
    return {}


@pytest.mark.parametrize("func, name, why", [
    (_table_rows_needs_more, "table_rows", "no default"),
    (_table_view_keyword_only, "table_view", "leading positional"),
    (_printed_tables_of_a_dict, "printed_tables", "returns"),
    (lambda report: None, "record_tables", "leading positional"),
])
def test_the_check_rejects_a_signature_off_the_interface(func, name, why):
    assert any(why in p for p in problems(func, name))
    assert problems(_record_tables, "record_tables") == []
