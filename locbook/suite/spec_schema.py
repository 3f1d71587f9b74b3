"""The schema of ``notebooks/experiments.toml`` (:mod:`locbook.suite.spec` describes the file): pydantic models of
its tables, and the one line of the first broken rule (:func:`one_line`), in the order the rules are read: the
documents, the suite's ``[parameter_rules]``, then each experiment in file order, its keys in field order.

Values are kept as TOML gives them (``Any`` with a check): a rule's integer bound stays an ``int``, which
:func:`locbook.suite.params._whole_bounds` relies on. A rule is :class:`locbook.suite.params.RuleTable`
(:meth:`~locbook.suite.params.ParameterRule.from_toml` checks by it too).
"""
from __future__ import annotations

import math
import re
from pathlib import Path
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError, ValidationInfo, model_validator
from pydantic_core import PydanticCustomError

from .params import RuleTable, rule_errors_text

__all__ = ["SuiteFile", "one_line", "PROFILES", "DOCUMENT_KEYS", "DATA_KINDS", "SAFE_NAME"]

PROFILES = ("quick", "full")
#: the five source documents, the measured data sets (any data set: ``locbook run --data``), and the cross-document
#: benchmark
DOCUMENT_KEYS = ("dogan2015", "gudipati2017", "palvai2008", "george", "ozkaya2011", "measured", "benchmark")
#: experiment ids and report folder names: lower-case letters, digits and single hyphens
SAFE_NAME = re.compile(r"^[a-z0-9]+(-[a-z0-9]+)*$")
#: what a data set can hold, as ``[experiment.data_run] needs`` names it: a recording of each role of
#: :data:`locbook.data.dataset.ROLES`, and "scored": a recording the static methods are scored on (a static one, or a
#: track with a true position per epoch: :func:`locbook.scenarios.measured.scored_recordings`)
DATA_KINDS = {"calibration": "calibration recording", "static": "static recording", "track": "track recording",
              "scored": "scored recording (a static recording, or a track with a true position per epoch)"}


def _refuse(text: str, kind: str = "part"):
    """A rule's refusal inside a model. ``kind`` "whole": ``text`` is the line after the file; "part": the line
    after ``<file>: experiment '<id>': `` (or the table's own place), which :func:`one_line` puts in front."""
    raise PydanticCustomError(kind, "{text}", {"text": text})


class _Table(BaseModel):
    """A table of the file: no key but its fields; values as TOML gives them."""
    model_config = ConfigDict(extra="forbid")


# -- [documents.<key>] --------------------------------------------------------------------------------------------
def _string(key: str):
    def check(value):
        if not isinstance(value, str):
            _refuse(f"{key} must be a string, got {value!r}")
        return value
    return AfterValidator(check)


def _year(value):
    if isinstance(value, bool) or not isinstance(value, (str, int)):
        _refuse(f"year must be a string or a whole number, got {value!r}")
    return str(value)


def _document_key(key):
    if key not in DOCUMENT_KEYS:
        _refuse(f"unknown document key {key!r}; expected one of {DOCUMENT_KEYS}", "whole")
    return key


class _Document(_Table):
    title: Annotated[Any, _string("title")]
    authors: Annotated[Any, _string("authors")]
    year: Annotated[Any, AfterValidator(_year)]
    source: Annotated[Any, _string("source")]


# -- [experiment.bracket], [experiment.data_run] ------------------------------------------------------------------
def _factorial(value):
    if not isinstance(value, list) or not all(isinstance(n, str) and n for n in value) \
            or len(set(value)) != len(value) or len(value) == 1:
        _refuse(f"[experiment.bracket] factorial must list two or more distinct interpretation names, got {value!r}")
    return tuple(value)


def _largest(value):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        _refuse(f"[experiment.bracket] largest_error_m must be a positive number of metres, got {value!r}")
    return float(value)


class _Bracket(_Table):
    """``[experiment.bracket]``; its shape (the table, its keys, ``parameters`` a table) is one rule."""
    parameters: Annotated[dict, Field(strict=True)] = {}
    factorial: Annotated[Any, AfterValidator(_factorial)] = ()
    largest_error_m: Annotated[Any, AfterValidator(_largest)] = None
    largest_error_reason: Annotated[Any, _string("[experiment.bracket] largest_error_reason")] = ""
    reason: Any = ""

    @model_validator(mode="after")
    def _together(self):
        # after the keys' own checks, in the order the rules have always been reported
        if (self.largest_error_m is None) != (not self.largest_error_reason.strip()):
            _refuse("[experiment.bracket] largest_error_m and largest_error_reason go together (the reason says "
                    "where the area is printed)")
        if not isinstance(self.reason, str):
            _refuse("[experiment.bracket] reason must be a string")
        if self.parameters and not self.reason.strip():
            _refuse("[experiment.bracket] sets parameters without a 'reason'")
        return self


_BRACKET_SHAPE = ("[experiment.bracket] takes a table 'parameters', a string 'reason', a list 'factorial' of "
                  "interpretation names, and 'largest_error_m' (a positive number) with 'largest_error_reason'")


def _needs(value):
    if not isinstance(value, list) or not value or not all(isinstance(k, str) for k in value) \
            or len(set(value)) != len(value):
        _refuse(f"[experiment.data_run] needs must list one or more distinct kinds of {', '.join(DATA_KINDS)}, "
                f"got {value!r}")
    bad = [k for k in value if k not in DATA_KINDS]
    if bad:
        _refuse(f"[experiment.data_run] needs: unknown kind {bad[0]!r}; expected one of {', '.join(DATA_KINDS)}")
    return tuple(value)


def _run_parameters(value):
    if not isinstance(value, dict):
        _refuse("[experiment.data_run] parameters must be a table of parameter values")
    if "data" in value:
        _refuse("[experiment.data_run] parameters cannot set 'data' (the run's data set sets it)")
    return dict(value)


class _DataRun(_Table):
    model_config = ConfigDict(extra="forbid", validate_default=True)    # a missing ``needs`` is refused by its check
    needs: Annotated[Any, AfterValidator(_needs)] = None
    parameters: Annotated[Any, AfterValidator(_run_parameters)] = {}


# -- [[experiment]] -----------------------------------------------------------------------------------------------
def _context(info: ValidationInfo) -> dict:
    """What :meth:`SuiteFile.read` passes: the file's folder, the declared document keys, the ids seen so far."""
    assert info.context is not None, "the schema is validated by SuiteFile.read"
    return info.context


def _id(value):
    if not isinstance(value, str) or not SAFE_NAME.match(value):
        _refuse(f"experiment id {value!r} must be lower-case letters, digits and hyphens ([a-z0-9-], e.g. "
                "'george-tracking'); it names a folder under reports/", "whole")
    return value


def _document(key, info: ValidationInfo):
    """Declared, its key prefixes the id, and the id is new (these three in this order, after the id's own rule,
    before the other keys: a duplicate is found as the experiments are read, in file order)."""
    eid, context = info.data.get("id"), _context(info)
    if eid is None:            # the id's own error comes first
        return key
    if not isinstance(key, str) or key not in context["documents"]:
        _refuse(f"experiment {eid!r} names undeclared document {key!r}", "whole")
    if not eid.startswith(key + "-"):
        _refuse(f"experiment id {eid!r} must start with its document key '{key}-'", "whole")
    if eid in context["seen"]:
        _refuse(f"duplicate experiment id {eid!r}", "whole")
    context["seen"].add(eid)
    return key


def _profiles(value, info: ValidationInfo):
    if not isinstance(value, dict) or set(value) != set(PROFILES):
        _refuse(f"experiment {info.data.get('id')!r} must define exactly the profiles {PROFILES}", "whole")
    for profile in PROFILES:
        if not isinstance(value[profile], dict):
            _refuse(f"[experiment.profiles.{profile}] must be a table of parameter values, got {value[profile]!r}")
    return {p: dict(value[p]) for p in PROFILES}


def _notebook(value, info: ValidationInfo):
    if not isinstance(value, str):
        _refuse(f"notebook must be a path relative to the experiment list, got {value!r}")
    notebook = (_context(info)["folder"] / value).resolve()
    if not notebook.is_file():
        _refuse(f"notebook {value} does not exist")
    return notebook


class _Experiment(_Table):
    """One ``[[experiment]]``; the field order is the order its rules are checked in."""
    id: Annotated[Any, AfterValidator(_id)]
    document: Annotated[Any, AfterValidator(_document)]
    title: Annotated[Any, _string("title")]
    section: Annotated[Any, _string("section")]
    profiles: Annotated[Any, AfterValidator(_profiles)]
    notebook: Annotated[Any, AfterValidator(_notebook)]
    parameter_rules: dict[str, RuleTable] = {}
    bracket: _Bracket = _Bracket()
    data_run: _DataRun | None = None


class SuiteFile(BaseModel):
    """The whole file. Its other top-level keys are left alone: ``[[study]]`` is :mod:`locbook.suite.study`'s to
    check (a study file of its own holds no experiments), and today's files hold no others."""
    model_config = ConfigDict(extra="allow")
    documents: dict[Annotated[str, AfterValidator(_document_key)], _Document] = {}
    parameter_rules: dict[str, RuleTable] = {}
    experiment: list[_Experiment] = []

    @classmethod
    def read(cls, data: dict, folder: Path) -> "SuiteFile":
        """``data`` (the parsed TOML) validated; ``folder`` holds the file (notebook paths are relative to it)."""
        documents = data.get("documents")
        return cls.model_validate(data, context={"folder": folder, "seen": set(),
                                                 "documents": set(documents) if isinstance(documents, dict) else ()})


# -- the first broken rule, in words ------------------------------------------------------------------------------
def _errors(exc: ValidationError) -> list[dict[str, Any]]:
    return [dict(e) for e in exc.errors()]


def _text(error: dict) -> str:
    return error.get("ctx", {}).get("text") or error["msg"]


def _position(keys, key) -> int:
    return keys.index(key) if key in keys else len(keys)


def _rank(error: dict, data: dict) -> tuple:
    """The order the rules are read in (module docstring): a table's shape, missing and unknown keys before its
    values; a model's keys in field order, a rule's in the order written."""
    loc, kind = error["loc"], error["type"]
    top = _position(list(SuiteFile.model_fields), loc[0])
    if len(loc) == 1:
        return (top, -1)
    table = data[loc[0]]       # present: a default is not validated
    where = loc[1] if isinstance(loc[1], int) else _position(list(table), loc[1])
    rest = loc[2:]
    if loc[0] == "parameter_rules":
        return (top, where, *_rule_rank(rest, kind, table[loc[1]]))
    if not rest:
        return (top, where, -1)
    model = _Document if loc[0] == "documents" else _Experiment
    if rest == ("[key]",):          # a document's key, before its table
        return (top, where, -1)
    if kind in ("missing", "extra_forbidden") and len(rest) == 1:
        return (top, where, 0, 0 if kind == "missing" else 1)
    if loc[0] == "documents":
        return (top, where, 1, _position(list(model.model_fields), rest[0]))
    field = _position(list(model.model_fields), rest[0])
    sub = rest[1:]
    if rest[0] == "parameter_rules" and sub:
        raw = table[loc[1]]["parameter_rules"]
        return (top, where, 1, field, _position(list(raw), sub[0]), *_rule_rank(sub[1:], kind, raw[sub[0]]))
    if rest[0] in ("bracket", "data_run") and sub:
        inner = _Bracket if rest[0] == "bracket" else _DataRun
        shape = kind == "extra_forbidden" or (rest[0] == "bracket" and sub == ("parameters",))
        return (top, where, 1, field, 0 if shape else 1, _position(list(inner.model_fields), sub[0]))
    return (top, where, 1, field, -1)


def _rule_rank(rest: tuple, kind: str, raw) -> tuple:
    if not rest:
        return (-1,)
    return (0,) if kind == "extra_forbidden" else (1, _position(list(raw), rest[0]))


def one_line(exc: ValidationError, data: dict, path: Path) -> str:
    """The first broken rule (:func:`_rank`) as the house's line: the file, the table or experiment, the key."""
    errors = _errors(exc)
    error = min(enumerate(errors), key=lambda e: (_rank(e[1], data), e[0]))[1]
    loc, kind = error["loc"], error["type"]
    same = [e for e in errors if e["loc"][:2] == loc[:2]]     # the errors of the same table
    if loc == ("documents",):
        return f"{path}: [documents.<key>] must be tables of title, authors, year, source, got {data['documents']!r}"
    if loc == ("parameter_rules",):
        return f"{path}: [parameter_rules] must be a table of rules by parameter name"
    if loc == ("experiment",):
        return f"{path}: experiments are [[experiment]] tables (an array of tables), got {data['experiment']!r}"
    if loc[0] == "parameter_rules":
        return f"{path}: [parameter_rules]: {rule_errors_text(loc[1], data['parameter_rules'][loc[1]], same)}"
    if loc[0] == "documents":
        key, doc = loc[1], data["documents"][loc[1]]
        if kind == "whole":
            return f"{path}: {_text(error)}"
        if len(loc) == 2:
            return f"{path}: document {key!r} must be a table of title, authors, year, source, got {doc!r}"
        fields = sorted(_Document.model_fields)
        missing = sorted(e["loc"][2] for e in same if e["type"] == "missing")
        if missing:
            return f"{path}: document {key!r} lacks {missing}"
        if kind == "extra_forbidden":
            unknown = sorted(e["loc"][2] for e in same if e["type"] == kind)
            return f"{path}: document {key!r} has unknown fields {unknown}; expected {fields}"
        return f"{path}: document {key!r}: {_text(error)}"
    # an experiment: loc is ("experiment", index, key, ...)
    raw = data["experiment"][loc[1]]
    if len(loc) == 2:
        return f"{path}: experiment {loc[1] + 1} must be a table ([[experiment]]), got {raw!r}"
    eid, key, sub = raw.get("id", "?"), loc[2], loc[3:]
    missing = sorted(e["loc"][2] for e in same if e["type"] == "missing" and len(e["loc"]) == 3)
    if missing:
        return f"{path}: experiment {eid!r} lacks {missing}"
    if kind == "extra_forbidden" and not sub:
        unknown = sorted(e["loc"][2] for e in same if e["type"] == kind and len(e["loc"]) == 3)
        return (f"{path}: experiment {eid!r} has unknown key(s) {unknown}; allowed: "
                f"{', '.join(_Experiment.model_fields)}")
    if kind == "whole":
        return f"{path}: {_text(error)}"
    if key == "parameter_rules":
        if not sub:
            return f"{path}: experiment {eid!r} must be a table of rules by parameter name"
        inner = [e for e in same if e["loc"][2:4] == (key, sub[0])]
        return f"{path}: experiment {eid!r}: {rule_errors_text(sub[0], raw[key][sub[0]], inner)}"
    if key == "bracket" and (kind in ("model_type", "extra_forbidden") or sub == ("parameters",)):
        return f"{path}: experiment {eid!r}: {_BRACKET_SHAPE}"
    if key == "data_run" and kind == "model_type":
        return f"{path}: experiment {eid!r}: [experiment.data_run] must be a table with the keys needs, parameters"
    if key == "data_run" and kind == "extra_forbidden":
        unknown = sorted(e["loc"][3] for e in same if e["loc"][2] == key and e["type"] == kind and len(e["loc"]) == 4)
        return (f"{path}: experiment {eid!r}: [experiment.data_run] has unknown key {unknown[0]!r}; expected "
                f"needs, parameters")
    return f"{path}: experiment {eid!r}: {_text(error)}"
