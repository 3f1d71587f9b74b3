"""Typed notebook parameters: read the cell tagged ``parameters`` and check values against it.

Every assignment in that cell must carry a type annotation (``seed: int = 0  # why``); supported
annotations are ``int``, ``float``, ``bool``, ``str``, ``list[T]``, ``tuple[T, ...]`` and
``Literal[...]``. Allowed ranges come from ``[parameter_rules]`` in ``notebooks/experiments.toml``
(:class:`ParameterRule`); every float must be finite unless its rule says ``allow_inf``.

Values given on the command line (``-p NAME=VALUE``) are read as TOML values (``-p q_grid=[0.1, 0.2]``,
``-p sigma_db=2.5``, ``-p trajectory=zigzag``; a bare word is a string). Papermill alone only warns about
unknown names and never checks types; locbook stops before anything executes with a
:class:`~locbook.errors.ParameterError` that names the parameter, the value and what is allowed.
"""
from __future__ import annotations

import ast
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import ParameterError

__all__ = ["NotebookParameter", "ParameterRule", "read_parameters", "check_value", "parse_cli_value",
           "resolve_parameters", "is_numeric_annotation"]


@dataclass(frozen=True)
class NotebookParameter:
    name: str
    annotation: str
    default: Any
    help: str


@dataclass(frozen=True)
class ParameterRule:
    """Allowed values of a numeric parameter (applied to every number, also inside lists).

    ``ge``/``gt``/``le``/``lt``: bounds; ``allow_inf``: infinities allowed (NaN never is);
    ``min_items``/``max_items``: length of a list parameter.
    """

    ge: float | None = None
    gt: float | None = None
    le: float | None = None
    lt: float | None = None
    allow_inf: bool = False
    min_items: int | None = None
    max_items: int | None = None

    KEYS = ("ge", "gt", "le", "lt", "allow_inf", "min_items", "max_items")

    @classmethod
    def from_toml(cls, name: str, raw, where: str) -> "ParameterRule":
        if not isinstance(raw, dict):
            raise ParameterError(f"{where}: the rule for {name!r} must be a table such as {{ ge = 0 }}, got {raw!r}")
        unknown = set(raw) - set(cls.KEYS)
        if unknown:
            raise ParameterError(f"{where}: the rule for {name!r} has unknown key(s) {sorted(unknown)}; "
                                 f"allowed: {', '.join(cls.KEYS)}")
        return cls(**raw)

    def describe(self) -> str:
        parts = [f"{op} {v}" for op, v in ((">=", self.ge), (">", self.gt), ("<=", self.le), ("<", self.lt))
                 if v is not None]
        if self.min_items is not None:
            parts.append(f"at least {self.min_items} item(s)")
        if self.max_items is not None:
            parts.append(f"at most {self.max_items} item(s)")
        parts.append("infinite allowed" if self.allow_inf else "finite")
        return ", ".join(parts)

    def violation(self, value) -> str:
        """Why ``value`` breaks this rule ('' if it does not)."""
        if isinstance(value, (list, tuple)):
            if self.min_items is not None and len(value) < self.min_items:
                return f"needs at least {self.min_items} item(s), got {len(value)}"
            if self.max_items is not None and len(value) > self.max_items:
                return f"allows at most {self.max_items} item(s), got {len(value)}"
            for item in value:
                why = ParameterRule(self.ge, self.gt, self.le, self.lt, self.allow_inf).violation(item)
                if why:
                    return f"item {item!r}: {why}"
            return ""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return ""
        if math.isnan(value):
            return "NaN is not a value"
        if math.isinf(value) and not self.allow_inf:
            return "must be finite"
        for op, bound, ok in ((">=", self.ge, lambda b: value >= b), (">", self.gt, lambda b: value > b),
                              ("<=", self.le, lambda b: value <= b), ("<", self.lt, lambda b: value < b)):
            if bound is not None and not ok(bound):
                return f"must be {op} {bound}"
        return ""


FINITE = ParameterRule()


def _parameters_cell(nb):
    cells = [c for c in nb.cells if "parameters" in c.get("metadata", {}).get("tags", [])]
    if len(cells) != 1:
        raise ParameterError(f"a notebook needs exactly one cell tagged 'parameters', found {len(cells)}")
    return cells[0]


def read_notebook(notebook_path: str | Path):
    """The notebook, or a :class:`ParameterError` naming the file if it is missing or not a notebook."""
    try:
        import nbformat   # here, not at import: nbformat's schema checks cost a notebook kernel a second
        return nbformat.read(str(notebook_path), as_version=4)
    except FileNotFoundError:
        raise ParameterError(f"{notebook_path}: notebook does not exist") from None
    except Exception as exc:  # nbformat raises JSON, validation and encoding errors of several types
        raise ParameterError(f"{notebook_path}: not a readable Jupyter notebook "
                             f"({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})") from None


def read_parameters(notebook_path: str | Path) -> dict[str, NotebookParameter]:
    """Parse the parameters cell of a notebook into ``{name: NotebookParameter}``."""
    nb = read_notebook(notebook_path)
    try:
        source = _parameters_cell(nb).source
    except ParameterError as exc:
        raise ParameterError(f"{notebook_path}: {exc}") from None
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


def is_numeric_annotation(annotation: str) -> bool:
    """True for ``int``, ``float`` and lists/tuples of them (the parameters that need a range rule)."""
    names = {n.id for n in ast.walk(ast.parse(annotation, mode="eval")) if isinstance(n, ast.Name)}
    return bool(names & {"int", "float"}) and "Literal" not in names


def _annotation_checker(annotation: str):
    """A predicate ``value -> bool`` for an annotation string."""
    node = ast.parse(annotation, mode="eval").body

    def build(n):
        if (isinstance(n, ast.BinOp) and isinstance(n.op, ast.BitOr) and isinstance(n.right, ast.Constant)
                and n.right.value is None):
            inner = build(n.left)                 # ``float | None``: None means "the source's printed value"
            return lambda v: v is None or inner(v)
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


def _to_float(value, annotation):
    """ints where floats are declared become floats (TOML ``2`` for a float parameter)."""
    if annotation in ("float", "float | None") and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if annotation in ("list[float]", "list[float] | None", "tuple[float, ...]") and isinstance(value, (list, tuple)):
        return [float(v) if isinstance(v, int) and not isinstance(v, bool) else v for v in value]
    if annotation == "list[list[float]]" and isinstance(value, (list, tuple)):
        return [_to_float(v, "list[float]") for v in value]
    return value


def check_value(param: NotebookParameter, value, rule: ParameterRule | None = None) -> Any:
    """Return ``value`` (ints promoted where floats are declared) if it matches the parameter's annotation and
    rule, else raise a :class:`ParameterError` naming the parameter, the value and what is allowed."""
    if not _annotation_checker(param.annotation)(value):
        raise ParameterError(
            f"parameter {param.name!r} expects {param.annotation}, got {value!r} ({type(value).__name__})"
            + (f"; write a TOML array, e.g. {param.name}=[0.1, 0.2]" if param.annotation.startswith(("list", "tuple"))
               and isinstance(value, str) else "")
        )
    rule = rule or FINITE
    why = rule.violation(value)
    if why:
        raise ParameterError(f"parameter {param.name!r} = {value!r} is not allowed: {why} "
                             f"(allowed: {param.annotation}, {rule.describe()})")
    return _to_float(value, param.annotation)


def parse_cli_value(param: NotebookParameter, text: str, rule: ParameterRule | None = None) -> Any:
    """Convert the text of ``-p NAME=VALUE`` (a TOML value; a bare word is a string) and check it."""
    stripped = text.strip()
    if param.annotation == "str":
        value = text
    else:
        try:
            value = tomllib.loads(f"v = {stripped}")["v"]
        except tomllib.TOMLDecodeError:
            value = stripped   # a bare word: a string (valid for str and Literal of strings only)
        if isinstance(value, str) and param.annotation == "bool" and stripped.lower() in ("true", "false"):
            value = stripped.lower() == "true"
    return check_value(param, value, rule)


def resolve_parameters(notebook_path, declared: dict[str, NotebookParameter], profile_values: dict,
                       cli_values: dict[str, str], context: str,
                       rules: dict[str, ParameterRule] | None = None) -> dict:
    """Profile values (typed, from TOML) then command-line overrides (text), all checked by name, type and rule."""
    rules = rules or {}
    resolved = {}

    def known(name):
        if name not in declared:
            raise ParameterError(f"{context}: unknown parameter {name!r} (not in {Path(notebook_path).name}); "
                                 f"known: {', '.join(sorted(declared))}")
        return declared[name]

    for name, value in profile_values.items():
        resolved[name] = check_value(known(name), value, rules.get(name))
    for name, text in cli_values.items():
        resolved[name] = parse_cli_value(known(name), text, rules.get(name))
    return resolved
