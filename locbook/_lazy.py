"""Names imported on first use (PEP 562), for locbook and its subpackages.

A package lists where each public name lives; ``import locbook`` then loads no submodule, and a kernel or a CLI
call pays only for the names it touches (pandas, matplotlib and cvxpy load with the first name that needs them).
"""
from __future__ import annotations

import sys
from importlib import import_module
from importlib.util import find_spec


def lazy_exports(package: str, homes: dict[str, str]):
    """``(__getattr__, __dir__)`` for the module ``package`` whose public names live in its submodules: ``homes``
    maps each name to its submodule, relative to ``package`` (``"models.channel"``). A name is imported on first
    access and then kept in the package's namespace, so later accesses cost nothing. A submodule is imported on
    first access too (``locbook.tracking.functional`` without an import statement, as scipy allows)."""

    def __getattr__(name: str):
        module = homes.get(name)
        if module is None:
            if not name.startswith("__") and find_spec(f"{package}.{name}") is not None:
                return import_module(f".{name}", package)
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(import_module(f".{module}", package), name)
        setattr(sys.modules[package], name, value)
        return value

    def __dir__():
        return sorted(set(homes) | {n for n in vars(sys.modules[package]) if not n.startswith("_")})

    return __getattr__, __dir__


def skip_iri_format_checker() -> None:
    """Spare a process that reads notebooks the 2-3 s import of ``rfc3987_syntax``, which builds a lark grammar so
    that jsonschema can check the ``iri`` string format, a format no notebook schema uses. jsonschema imports it
    under ``suppress(ImportError)``; a ``None`` entry in ``sys.modules`` makes that import fail, so the checker is
    left out. Called by the ``locbook`` command and its worker processes only (not on ``import locbook``), and
    only if nothing imported the package already."""
    sys.modules.setdefault("rfc3987_syntax", None)

