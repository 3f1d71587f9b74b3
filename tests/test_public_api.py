"""The curated top-level API (issue 27): one home module per name, listed in docs/architecture.md's table, constants left in their
modules, every name importable and defined where the table says."""
import inspect
import re
from pathlib import Path

import pytest

import locbook

API_DOC = Path(__file__).resolve().parents[1] / "docs" / "architecture.md"


def readme_table_rows() -> list[tuple[str, str, tuple[str, ...]]]:
    if not API_DOC.exists():   # the installed package is tested without the clone's docs
        pytest.skip("docs/architecture.md is not beside the tests")
    text = API_DOC.read_text(encoding="utf-8")
    section = text.split("\n## Public API\n", 1)[1].split("\n## ", 1)[0]
    rows = []
    for line in section.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) != 3 or cells[0] in ("role", "") or set(cells[0]) <= set("-: "):
            continue
        module = cells[1].strip("`")
        names = tuple(re.findall(r"`([^`]+)`", cells[2]))
        rows.append((cells[0], module, names))
    return rows


def expected_rows():
    return [(role, f"locbook.{module}", tuple(names)) for role, module, names in locbook._API]


def render_table() -> str:
    lines = ["| role | module | names |", "|---|---|---|"]
    for role, module, names in expected_rows():
        lines.append(f"| {role} | `{module}` | " + ", ".join(f"`{n}`" for n in names) + " |")
    return "\n".join(lines)


def test_readme_lists_exactly_the_public_api():
    assert readme_table_rows() == expected_rows(), "docs/architecture.md's Public API table should read:\n" + render_table()


def test_every_public_name_has_one_home_and_is_defined_there():
    names = [n for _, _, ns in locbook._API for n in ns]
    assert len(names) == len(set(names)), sorted({n for n in names if names.count(n) > 1})
    assert set(locbook.__all__) == {"__version__", *names}
    for _, module, ns in locbook._API:
        for name in ns:
            value = getattr(locbook, name)
            if inspect.isclass(value) or inspect.isfunction(value):
                assert value.__module__ == f"locbook.{module}", (name, value.__module__, module)


def test_constants_stay_in_their_modules():
    constants = [n for n in locbook.__all__ if n != "__version__" and re.fullmatch(r"[A-Z][A-Z0-9_]+", n)]
    assert constants == []


def test_an_unknown_name_is_an_attribute_error_naming_it():
    with pytest.raises(AttributeError, match="no attribute 'kalman_filtre'"):
        locbook.kalman_filtre
