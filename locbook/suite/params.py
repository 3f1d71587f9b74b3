"""Typed notebook parameters: read the cell tagged ``parameters`` and check values against it.

Every assignment in that cell must carry a type annotation (``seed: int = 0  # why``); annotations are built
from ``int``, ``float``, ``bool``, ``str``, ``list[T]``, ``tuple[T, ...]``, ``Literal[...]`` and ``| None``.
Allowed ranges come from ``[parameter_rules]`` in ``notebooks/experiments.toml`` (:class:`ParameterRule`);
every float must be finite unless its rule says ``allow_inf`` (NaN never is).

Checking is pydantic's: the annotation is evaluated with ``int``/``float``/``bool``/``str`` bound to strict,
constrained types (``Annotated[float, Strict(), Field(ge=0, allow_inf_nan=False)]``) built from the rule, so a
rule applies to every number, also inside lists, and ``min_items``/``max_items`` to the list itself. A
``Literal`` compares by value, as pydantic's does (``Literal[1]`` would accept ``True``; the suite's are strings).

Reading is Python's own parser (:mod:`ast`), not ``papermill.inspect_notebook``: papermill 2.7's
``PythonTranslator.PARAMETER_PATTERN`` skips any line with a second ``=`` (a help comment such as
``# None = Table 6.1``) and cannot match ``Literal["a", "b"]`` or ``float | None`` (nteract/papermill#906),
so it loses 53 of the suite's 260 parameters, in 21 of its 28 notebooks, with a logged warning at most.

Values given on the command line (``-p NAME=VALUE``) are read as TOML values (``-p q_grid=[0.1, 0.2]``,
``-p sigma_db=2.5``, ``-p trajectory=zigzag``; a bare word is a string). Papermill alone only warns about
unknown names and never checks types; locbook stops before anything executes with a
:class:`~locbook.errors.ParameterError` that names the parameter, the value and what is allowed.
"""
from __future__ import annotations

import ast
import functools
import math
import numbers
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, Strict, TypeAdapter, ValidationError
from pydantic_core import PydanticCustomError

from ..errors import ParameterError

__all__ = ["NotebookParameter", "ParameterRule", "read_parameters", "check_value", "parse_cli_value",
           "resolve_parameters", "is_numeric_annotation", "RENAMED_PARAMETERS"]


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

    @classmethod
    def from_toml(cls, name: str, raw, where: str) -> "ParameterRule":
        """The rule ``raw`` (a TOML table) for parameter ``name``, checked by :class:`RuleTable`; a
        :class:`ParameterError` of one line naming ``where``, the parameter, the key and the value."""
        try:
            return RuleTable.model_validate(raw).rule()
        except ValidationError as exc:
            raise ParameterError(f"{where}: {rule_errors_text(name, raw, [dict(e) for e in exc.errors()])}") from None

    def describe(self) -> str:
        parts = [f"{op} {v}" for op, v in ((">=", self.ge), (">", self.gt), ("<=", self.le), ("<", self.lt))
                 if v is not None]
        if self.min_items is not None:
            parts.append(f"at least {self.min_items} item(s)")
        if self.max_items is not None:
            parts.append(f"at most {self.max_items} item(s)")
        parts.append("infinite allowed" if self.allow_inf else "finite")
        return ", ".join(parts)


FINITE = ParameterRule()


def _rule_value(key: str):
    """A key's check: ``allow_inf`` true or false, ``*_items`` a whole number, a bound a number (never a boolean)."""
    kind = bool if key == "allow_inf" else int if key.endswith("_items") else numbers.Real
    wanted = "true or false" if kind is bool else "a whole number" if kind is int else "a number"

    def check(value):
        if not isinstance(value, kind) or (kind is not bool and isinstance(value, bool)):
            raise PydanticCustomError("rule", "{text}", {"text": f"needs {key} to be {wanted}, got {value!r}"})
        return value
    return AfterValidator(check)


class RuleTable(BaseModel):
    """The schema of a rule's TOML table, ``{ ge = 0 }`` (:class:`ParameterRule`); values kept as written (an
    integer bound stays an ``int``, :func:`_whole_bounds`). The experiment list's schema uses it for
    ``[parameter_rules]`` (:mod:`locbook.suite.spec_schema`)."""
    model_config = ConfigDict(extra="forbid")
    ge: Annotated[Any, _rule_value("ge")] = None
    gt: Annotated[Any, _rule_value("gt")] = None
    le: Annotated[Any, _rule_value("le")] = None
    lt: Annotated[Any, _rule_value("lt")] = None
    allow_inf: Annotated[Any, _rule_value("allow_inf")] = False
    min_items: Annotated[Any, _rule_value("min_items")] = None
    max_items: Annotated[Any, _rule_value("max_items")] = None

    def rule(self) -> ParameterRule:
        return ParameterRule(**self.model_dump(exclude_unset=True))


def rule_errors_text(name: str, raw, errors: list[dict]) -> str:
    """The first broken rule of one rule table (:class:`RuleTable`'s ``errors``) in words: the table, unknown keys,
    then the keys in the order written."""
    if any(e["type"] == "model_type" for e in errors):
        return f"the rule for {name!r} must be a table such as {{ ge = 0 }}, got {raw!r}"
    unknown = sorted(e["loc"][-1] for e in errors if e["type"] == "extra_forbidden")
    if unknown:
        return f"the rule for {name!r} has unknown key(s) {unknown}; allowed: {', '.join(RuleTable.model_fields)}"
    keys = list(raw)
    first = min(errors, key=lambda e: keys.index(e["loc"][-1]) if e["loc"][-1] in keys else len(keys))
    return f"the rule for {name!r} {first.get('ctx', {}).get('text') or first['msg']}"


def _parameters_cell(nb):
    cells = [c for c in nb.cells if "parameters" in c.get("metadata", {}).get("tags", [])]
    if len(cells) != 1:
        raise ParameterError(f"a notebook needs exactly one cell tagged 'parameters', found {len(cells)}")
    return cells[0]


def read_notebook(notebook_path: str | Path):
    """The notebook, or a :class:`ParameterError` naming the file if it is missing or not a notebook."""
    try:
        import nbformat  # here, not at import: nbformat's schema checks cost a notebook kernel a second
        return nbformat.read(str(notebook_path), as_version=4)
    except FileNotFoundError:
        raise ParameterError(f"{notebook_path}: notebook does not exist") from None
    except Exception as exc:  # nbformat raises JSON, validation and encoding errors of several types
        raise ParameterError(f"{notebook_path}: not a readable Jupyter notebook "
                             f"({type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''})") from None


def read_parameters(notebook_path: str | Path) -> dict[str, NotebookParameter]:
    """Parse the parameters cell of a notebook into ``{name: NotebookParameter}``; every default is checked
    against its annotation (finite numbers)."""
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
            try:
                default = ast.literal_eval(node.value)
            except ValueError as exc:
                raise ParameterError(
                    f"{notebook_path}: parameter {node.target.id!r} needs a literal default value"
                ) from exc
            last = lines[node.end_lineno - 1]
            help_text = last.split("#", 1)[1].strip() if "#" in last else ""
            param = NotebookParameter(node.target.id, ast.unparse(node.annotation), default, help_text)
            try:
                check_value(param, default)   # also rejects an unsupported annotation before anything runs
            except ParameterError as exc:
                raise ParameterError(f"{notebook_path}: default value: {exc}") from None
            params[param.name] = param
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


def _not_nan(value: float) -> float:
    if math.isnan(value):
        raise PydanticCustomError("not_a_number", "NaN is not a value")
    return value


#: The whole-number bound a rule's bound means for an ``int``: n >= x iff n >= ceil(x), n > x iff n > floor(x),
#: n <= x iff n <= floor(x), n < x iff n < ceil(x) (pydantic refuses a fractional bound on an int).
_WHOLE = {"ge": math.ceil, "gt": math.floor, "le": math.floor, "lt": math.ceil}


def _whole_bounds(bounds: dict) -> dict:
    """``bounds`` as the int bounds they mean (:data:`_WHOLE`); an infinite bound every int meets is dropped, one
    none meets (or a NaN bound) is refused naming it."""
    out = {}
    for key, x in bounds.items():
        if x is None or isinstance(x, int):
            out[key] = x
        elif math.isinf(x) and (x < 0) == (key in ("ge", "gt")):   # -inf below or +inf above: no constraint
            out[key] = None
        elif math.isfinite(x):
            out[key] = _WHOLE[key](x)
        else:
            raise ParameterError(f"the rule {key} = {x} admits no whole number; an int parameter needs a finite bound")
    return out


@functools.lru_cache(maxsize=None)
def _adapter(annotation: str, rule: ParameterRule | None):
    """A pydantic ``TypeAdapter`` for ``annotation`` with ``rule`` applied to every number and to the list
    (``None``: the type alone, any float including NaN and infinities)."""
    import types
    import typing
    from typing import Literal

    checks = rule or ParameterRule(allow_inf=True)
    bounds = {"ge": checks.ge, "gt": checks.gt, "le": checks.le, "lt": checks.lt}
    number = Field(**bounds, allow_inf_nan=checks.allow_inf)
    nan = [AfterValidator(_not_nan)] if rule is not None and rule.allow_inf else []   # NaN is never a value
    namespace = {
        "__builtins__": {}, "Literal": Literal, "list": list, "tuple": tuple, "None": None,
        "int": Annotated[int, Strict(), Field(**_whole_bounds(bounds))],   # Strict: no bool, no 2.0, no "2"
        "float": Annotated[float, Strict(), number, *nan],
        "bool": Annotated[bool, Strict()], "str": Annotated[str, Strict()],
    }
    try:
        kind = eval(compile(ast.parse(annotation, mode="eval"), "<annotation>", "eval"), namespace)
    except Exception:   # a name outside the namespace, or an expression that builds no type
        raise ParameterError(f"unsupported parameter annotation {annotation!r}") from None
    if kind in (list, tuple):   # items of any type: no rule could reach them
        raise ParameterError(f"unsupported parameter annotation {annotation!r}; name the items' type, "
                             f"e.g. {annotation}[float]")

    def sized(t):   # min_items/max_items: the parameter's own list, not lists inside it
        if typing.get_origin(t) in (list, tuple):
            return Annotated[t, Field(min_length=checks.min_items, max_length=checks.max_items)]
        if typing.get_origin(t) in (typing.Union, types.UnionType):
            return typing.Union[tuple(sized(a) for a in typing.get_args(t))]
        return t

    try:
        return TypeAdapter(sized(kind) if checks.min_items is not None or checks.max_items is not None else kind)
    except Exception:   # pydantic cannot build a validator for it (e.g. Literal[object])
        raise ParameterError(f"unsupported parameter annotation {annotation!r}") from None


def _as_lists(value):
    """Tuples as lists: papermill writes a tuple into the notebook as a string."""
    if isinstance(value, (list, tuple)):
        return [_as_lists(v) for v in value]
    return value


#: pydantic error types that are a rule's, with what the rule says
_RULE_ERRORS = {"greater_than_equal": (">=", "ge"), "greater_than": (">", "gt"), "less_than_equal": ("<=", "le"),
                "less_than": ("<", "lt")}


def _why(error: dict, rule: ParameterRule) -> str:
    """The rule a pydantic error reports, in the words of :meth:`ParameterRule.describe`."""
    kind, ctx, value = error["type"], error.get("ctx", {}), error.get("input")
    if isinstance(value, float) and math.isnan(value):   # whichever check saw it first
        why = "NaN is not a value"
    elif kind in _RULE_ERRORS:
        op, key = _RULE_ERRORS[kind]
        why = f"must be {op} {getattr(rule, key)}"
    elif kind in ("finite_number", "not_a_number"):
        why = "must be finite"
    elif kind == "too_short":
        return f"needs at least {rule.min_items} item(s), got {ctx.get('actual_length')}"
    elif kind == "too_long":
        return f"allows at most {rule.max_items} item(s), got {ctx.get('actual_length')}"
    else:
        return error["msg"]
    inside = any(isinstance(part, int) for part in error["loc"])   # an index: a number inside a list
    return f"item {value!r}: {why}" if inside else why


def check_value(param: NotebookParameter, value, rule: ParameterRule | None = None) -> Any:
    """Return ``value`` as pydantic validated it (ints become floats where floats are declared, tuples lists)
    if it matches the parameter's annotation and rule, else raise a :class:`ParameterError` naming the
    parameter, the value and what is allowed."""
    try:
        _adapter(param.annotation, None).validate_python(value)    # the type first, then the rule
    except ValidationError:
        raise ParameterError(
            f"parameter {param.name!r} expects {param.annotation}, got {value!r} ({type(value).__name__})"
            + (f"; write a TOML array, e.g. {param.name}=[0.1, 0.2]" if param.annotation.startswith(("list", "tuple"))
               and isinstance(value, str) else "")
        ) from None
    rule = rule or FINITE
    try:
        return _as_lists(_adapter(param.annotation, rule).validate_python(value))
    except ValidationError as exc:
        # pydantic checks a list's items before its length; in a union (``float | None``) the other members'
        # type errors are noise: report a rule's error
        order = {**{k: 0 for k in (*_RULE_ERRORS, "finite_number", "not_a_number")}, "too_short": 1, "too_long": 1}
        first = min(exc.errors(), key=lambda e: order.get(e["type"], 2))
        raise ParameterError(f"parameter {param.name!r} = {value!r} is not allowed: {_why(first, rule)} "
                             f"(allowed: {param.annotation}, {rule.describe()})") from None


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


#: notebook parameters renamed when "reading" came to mean only a sensor measurement: old name -> new name (an old
#: name is refused with the new one named)
RENAMED_PARAMETERS = {"noise_reading": "noise_interpretation", "other_readings": "other_interpretations"}


def resolve_parameters(notebook_path, declared: dict[str, NotebookParameter], profile_values: dict,
                       cli_values: dict[str, str], context: str,
                       rules: dict[str, ParameterRule] | None = None) -> dict:
    """Profile values (typed, from TOML) then command-line overrides (text), all checked by name, type and rule."""
    rules = rules or {}
    resolved = {}

    def known(name):
        if name not in declared and RENAMED_PARAMETERS.get(name) in declared:
            raise ParameterError(f"{context}: parameter {name!r} was renamed {RENAMED_PARAMETERS[name]!r} (not in "
                                 f"{Path(notebook_path).name}); give -p {RENAMED_PARAMETERS[name]}=...")
        if name not in declared:
            raise ParameterError(f"{context}: unknown parameter {name!r} (not in {Path(notebook_path).name}); "
                                 f"known: {', '.join(sorted(declared))}")
        return declared[name]

    for name, value in profile_values.items():
        resolved[name] = check_value(known(name), value, rules.get(name))
    for name, text in cli_values.items():
        resolved[name] = parse_cli_value(known(name), text, rules.get(name))
    return resolved
