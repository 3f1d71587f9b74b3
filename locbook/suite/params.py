"""Typed notebook parameters: read the cell tagged ``parameters`` and check values against it.

Every assignment in that cell must carry a type annotation (``seed: int = 0  # why``); supported
annotations are ``int``, ``float``, ``bool``, ``str``, ``list[T]``, ``tuple[T, ...]`` and
``Literal[...]``. Papermill alone only warns about unknown names and never checks types; locbook stops
before execution with a :class:`~locbook.errors.ParameterError` that names the parameter.
"""
from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import nbformat

from ..errors import ParameterError

__all__ = ["NotebookParameter", "read_parameters", "check_value", "parse_cli_value", "resolve_parameters"]


@dataclass(frozen=True)
class NotebookParameter:
    name: str
    annotation: str
    default: Any
    help: str


def _parameters_cell(nb):
    cells = [c for c in nb.cells if "parameters" in c.get("metadata", {}).get("tags", [])]
    if len(cells) != 1:
        raise ParameterError(f"a notebook needs exactly one cell tagged 'parameters', found {len(cells)}")
    return cells[0]


def read_parameters(notebook_path: str | Path) -> dict[str, NotebookParameter]:
    """Parse the parameters cell of a notebook into ``{name: NotebookParameter}``."""
    nb = nbformat.read(str(notebook_path), as_version=4)
    source = _parameters_cell(nb).source
    lines = source.splitlines()
    params: dict[str, NotebookParameter] = {}
    try:
        tree = ast.parse(source)
    except SyntaxError as exc:
        raise ParameterError(f"{notebook_path}: the parameters cell is not valid Python: {exc}") from exc
    for node in tree.body:
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and node.value is not None:
            annotation = ast.unparse(node.annotation)
            _annotation_checker(annotation)  # reject unsupported annotations early
            try:
                default = ast.literal_eval(node.value)
            except ValueError as exc:
                raise ParameterError(
                    f"{notebook_path}: parameter {node.target.id!r} needs a literal default value"
                ) from exc
            last = lines[node.end_lineno - 1]
            help_text = last.split("#", 1)[1].strip() if "#" in last else ""
            params[node.target.id] = NotebookParameter(node.target.id, annotation, default, help_text)
            check_value(params[node.target.id], default)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            target = ast.unparse(node.targets[0] if isinstance(node, ast.Assign) else node.target)
            raise ParameterError(
                f"{notebook_path}: parameter {target!r} has no type annotation; write `{target}: <type> = ...`"
            )
        elif not isinstance(node, ast.Expr):  # docstrings/comments are fine, logic is not
            raise ParameterError(f"{notebook_path}: the parameters cell may only hold annotated assignments")
    return params


def _annotation_checker(annotation: str):
    """A predicate ``value -> bool`` for an annotation string."""
    node = ast.parse(annotation, mode="eval").body

    def build(n):
        if isinstance(n, ast.Name):
            simple = {
                "int": lambda v: isinstance(v, int) and not isinstance(v, bool),
                "float": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
                "bool": lambda v: isinstance(v, bool),
                "str": lambda v: isinstance(v, str),
            }
            if n.id in simple:
                return simple[n.id]
        if isinstance(n, ast.Subscript) and isinstance(n.value, ast.Name):
            kind = n.value.id
            if kind == "list":
                inner = build(n.slice)
                return lambda v: isinstance(v, (list, tuple)) and all(inner(x) for x in v)
            if kind == "tuple":
                parts = n.slice.elts if isinstance(n.slice, ast.Tuple) else [n.slice]
                if len(parts) == 2 and isinstance(parts[1], ast.Constant) and parts[1].value is Ellipsis:
                    inner = build(parts[0])
                    return lambda v: isinstance(v, (list, tuple)) and all(inner(x) for x in v)
                checks = [build(p) for p in parts]
                return lambda v: (isinstance(v, (list, tuple)) and len(v) == len(checks)
                                  and all(c(x) for c, x in zip(checks, v)))
            if kind == "Literal":
                options = [ast.literal_eval(e) for e in (n.slice.elts if isinstance(n.slice, ast.Tuple) else [n.slice])]
                return lambda v: v in options and type(v) in {type(o) for o in options}
        raise ParameterError(f"unsupported parameter annotation {annotation!r}")

    return build(node)


def check_value(param: NotebookParameter, value) -> Any:
    """Return ``value`` if it matches the parameter's annotation, else raise naming the parameter."""
    if not _annotation_checker(param.annotation)(value):
        raise ParameterError(
            f"parameter {param.name!r} expects {param.annotation}, got {value!r} ({type(value).__name__})"
        )
    if param.annotation == "float" and isinstance(value, int):
        return float(value)
    return value


def parse_cli_value(param: NotebookParameter, text: str) -> Any:
    """Convert the text of ``-p NAME=VALUE`` to the parameter's type (then checked)."""
    ann = param.annotation
    try:
        if ann == "str":
            value = text
        elif ann == "bool":
            low = text.strip().lower()
            if low not in ("true", "false", "1", "0", "yes", "no"):
                raise ValueError(text)
            value = low in ("true", "1", "yes")
        elif ann == "int":
            value = int(text)
        elif ann == "float":
            value = float(text)
        else:
            try:
                value = ast.literal_eval(text)
            except (ValueError, SyntaxError):
                value = text  # a bare word for a Literal of strings
    except ValueError:
        raise ParameterError(f"parameter {param.name!r} expects {ann}, got {text!r}") from None
    return check_value(param, value)


def resolve_parameters(notebook_path, declared: dict[str, NotebookParameter], profile_values: dict,
                       cli_values: dict[str, str], context: str) -> dict:
    """Profile values (typed, from TOML) then command-line overrides (text), all checked by name and type."""
    resolved = {}
    for name, value in profile_values.items():
        if name not in declared:
            raise ParameterError(f"{context}: unknown parameter {name!r} (not in {Path(notebook_path).name}); "
                                 f"known: {', '.join(sorted(declared))}")
        resolved[name] = check_value(declared[name], value)
    for name, text in cli_values.items():
        if name not in declared:
            raise ParameterError(f"{context}: unknown parameter {name!r} (not in {Path(notebook_path).name}); "
                                 f"known: {', '.join(sorted(declared))}")
        resolved[name] = parse_cli_value(declared[name], text)
    return resolved
