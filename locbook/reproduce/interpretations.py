"""Every document's unprinted assumptions and contested interpretations, declared as data.

One CSV per document, ``locbook/data/interpretations/<document>.csv`` (package data, beside the printed values of
:mod:`.printed_values`), lines starting with ``#`` being comments. One row per interpretation, with the columns
:data:`INTERPRETATION_COLUMNS`:

``name``
    snake_case, unique within the document.
``experiments``
    the experiment ids (``notebooks/experiments.toml``) it applies to, separated by spaces.
``parameter``
    the notebook parameter that sets it, as in each listed notebook's parameters cell; empty when no notebook
    parameter sets it yet, and then ``where`` must name the module attribute that holds it (the gap is visible).
``where``
    a dotted path ``package.module.attribute[.attribute]`` (``locbook.scenarios.dogan.Q_PER_STEP``); optional when
    ``parameter`` is given.
``default``
    the value used today, as a TOML value (``0.3``, ``'rest'``, ``[1.0, 2.0]``); empty means the notebook's
    ``None`` (the notebook resolves it, e.g. to a printed value or a calibration, as ``reason`` says).
``alternatives``
    a TOML array of the other plausible values (empty or ``[]``: none named).
``fitted``
    a TOML array of those alternatives that nothing in the text supports and that were chosen because they fit
    printed results (empty: none); rows computed under one are calibrations, and a bracket marks it ``[fitted]``
    where it reaches a row. Every other alternative has the basis :meth:`Interpretation.alternative_basis` gives:
    ``textual`` (another interpretation the text supports) unless the interpretation is ``assumed`` (the text is silent:
    a plausible value).
``low``, ``high``
    a plausible range of a numeric interpretation (both or neither).
``basis``
    one of :data:`BASES`, the basis of the default:
    ``printed`` (the text prints the value), ``textual`` (not printed as a value, but the text supports it: the
    ``quotes`` say which words), ``assumed`` (the text says nothing that decides it: our choice, the field's
    standard model or a plausible range, as ``reason`` says), ``fitted`` (nothing in the text supports it and it was
    chosen because it fits printed results: rows that use it are calibrations). Agreement with the printed numbers
    is never an argument for or against an interpretation.
``source``
    where the source prints the value or leaves it open (section, equation, table).
``quotes`` (a file written before this column existed still loads: its quotes are empty, and its basis
``fitted_to_output``, the earlier name, reads as ``fitted``)
    the words of the source the default and the alternatives rest on, quoted, each with its section (and, where
    useful, the line of the text): required for a ``printed`` or ``textual`` basis
    (``tests/reproduce/test_interpretations.py`` checks that each such interpretation quotes the text); for
    ``assumed``, what the text says around the gap, if anything.
``reason``
    why the default and why the alternatives, argued from the quotes (required); where two interpretations are equally
    textual, it says so and names the field's standard model the default follows.
``requires`` (optional last column, :data:`OPTIONAL_INTERPRETATION_COLUMNS`)
    a TOML inline table of other parameters this interpretation acts only together with (``{ r_mode = 'isotropic' }``:
    George's isotropic R is used only when ``r_mode`` is ``'isotropic'``); a bracket sets them at each of this
    interpretation's points, its default value included. Empty: none.

Rules (:func:`interpretations` raises :class:`InterpretationsError` naming the file, the line and the problem): the
columns exactly as above; a known basis; a unique snake_case name; at least one experiment; ``parameter`` or
``where``; every TOML value parses (``alternatives`` and ``fitted`` as arrays); the default is not among the
alternatives, and every fitted value is; ``requires`` a table of parameter names other than the interpretation's own
(and only with a ``parameter``); ``low <= high``, both numbers, and a numeric default inside ``[low, high]``; a
``fitted`` interpretation names at least one alternative or a range, so that a sweep can test the printed numbers under
an interpretation not chosen from them.

This module only declares and validates; it imports nothing from the suite (the suite's tests check each
``parameter`` against the notebooks, ``tests/reproduce/test_interpretations.py``).
"""
from __future__ import annotations

import csv
import io
import math
import os
import re
import tomllib
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

from .._text import decode_utf8
from ..errors import LocbookError

__all__ = ["Interpretation", "InterpretationsError", "interpretations", "interpretations_for",
           "load_interpretation_file", "INTERPRETATIONS_DIR", "INTERPRETATION_COLUMNS",
           "OPTIONAL_INTERPRETATION_COLUMNS", "BASES", "utf8_text", "read_declaration", "MAX_DECLARATION_BYTES"]

INTERPRETATIONS_DIR = Path(__file__).resolve().parents[1] / "data" / "interpretations"    # package data of locbook.data
INTERPRETATION_COLUMNS = ("name", "experiments", "parameter", "where", "default", "alternatives", "fitted", "low",
                          "high", "basis", "source", "quotes", "reason")
#: columns an interpretations file may add after :data:`INTERPRETATION_COLUMNS`
OPTIONAL_INTERPRETATION_COLUMNS = ("requires",)
#: The basis of an interpretation's default: printed by the source, supported by its text, assumed where the text is
#: silent, or fitted to the source's printed output with no textual support.
BASES = ("printed", "textual", "assumed", "fitted")



class InterpretationsError(LocbookError, ValueError):
    """An interpretations file that breaks a rule of the declaration; the message names the file, the line and the
    problem, on one line (a cell's line breaks are shown as ``\\n``)."""

    def __init__(self, message: str):
        super().__init__(str(message).replace("\r\n", "\\n").replace("\n", "\\n").replace("\r", "\\r"))


#: The largest declaration file read (an interpretations CSV, a study or experiment list TOML): the packaged ones are
#: tens of kilobytes, so more is not a declaration (``--suite /dev/zero``, a data file given by mistake).
MAX_DECLARATION_BYTES = 16 * 2 ** 20


def read_declaration(path, error: type[Exception] = InterpretationsError, what: str = "an interpretations file") -> str:
    """The UTF-8 text of the declaration file ``path`` (:func:`utf8_text`), read only up to
    :data:`MAX_DECLARATION_BYTES`: a larger file raises ``error`` naming it, its size and the limit, before it is
    read whole. OSError (missing, unreadable) propagates."""
    with open(path, "rb") as fh:
        data = fh.read(MAX_DECLARATION_BYTES + 1)
        if len(data) > MAX_DECLARATION_BYTES:
            size = os.fstat(fh.fileno()).st_size     # 0 for a device or a pipe, which may never end
            held = f"is {size / 2 ** 20:.1f} MiB" if size > MAX_DECLARATION_BYTES else "holds more and has no size"
            raise error(f"{path}: {what} {held}, over the limit of {MAX_DECLARATION_BYTES // 2 ** 20} MiB for a "
                        "declaration; is it the right file?")
    return utf8_text(data, path, error)


def utf8_text(data: bytes, path, error: type[Exception] = InterpretationsError) -> str:
    """``data`` (the bytes of the text file ``path``) decoded as UTF-8 (a leading byte-order mark dropped); a byte
    that is not UTF-8 raises ``error`` naming the file, the line and the column (1-based, in bytes)."""
    def fail(line, column, offset, _line_bytes):
        raise error(f"{path}, line {line}, column {column}: byte 0x{data[offset]:02x} is not UTF-8 text; save the "
                    "file as UTF-8")
    return decode_utf8(data, fail)


_NAME = re.compile(r"[a-z][a-z0-9_]*\Z")
_WHERE = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)+\Z")


@dataclass(frozen=True)
class Interpretation:
    """One unprinted assumption or contested interpretation of a document (a row of its interpretations CSV).

    ``default`` is the value used today (``None``: the notebook parameter's ``None``); ``alternatives`` the other
    plausible values; ``low``/``high`` a plausible range (both ``None`` if not numeric or not given);
    ``parameter`` the notebook parameter that sets it (``""`` if none does: then ``where`` names the attribute).
    """

    document: str
    name: str
    experiments: tuple[str, ...]
    parameter: str
    where: str
    default: Any
    alternatives: tuple
    low: float | None
    high: float | None
    basis: str
    source: str
    reason: str
    fitted: tuple = ()
    #: the source's words the default and the alternatives rest on (the ``quotes`` column)
    quotes: str = ""
    #: other parameters set with each of this interpretation's values (the ``requires`` column): name -> value
    requires: dict = field(default_factory=dict, hash=False, compare=False)

    @property
    def is_gap(self) -> bool:
        """True when no notebook parameter sets this interpretation (it lives in a module: :attr:`where`)."""
        return not self.parameter

    @property
    def is_calibration(self) -> bool:
        """True when the default was chosen because it fits printed output (rows using it are calibrations)."""
        return self.basis == "fitted"

    def is_fitted(self, value) -> bool:
        """True when ``value`` is one of the alternatives chosen because it fits printed results."""
        return any(_key(value) == _key(f) for f in self.fitted)

    def alternative_basis(self, value) -> str:
        """The basis of one of this interpretation's values: the declared basis for the default, ``fitted`` for a fitted
        alternative, ``assumed`` for another value of an assumed interpretation (the text is silent), else ``textual``
        (another interpretation the text supports)."""
        if self.default is not None and _key(value) == _key(self.default):
            return self.basis
        if self.is_fitted(value):
            return "fitted"
        return "assumed" if self.basis == "assumed" else "textual"

    @property
    def values(self) -> tuple:
        """The default followed by the alternatives: the discrete values a sweep of this interpretation visits."""
        return (self.default, *self.alternatives)


def _toml_value(text: str, where: str, column: str):
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError as exc:
        raise InterpretationsError(f"{where}: {column} {text!r} is not a TOML value ({exc}); strings need quotes, "
                                   f"e.g. 'rest'") from None


def _number(text: str, where: str, column: str) -> float | None:
    if text == "":
        return None
    value = _toml_value(text, where, column)
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InterpretationsError(f"{where}: {column} must be a finite number, got {text!r}")
    return float(value)


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _key(value):
    """A comparable key under which 1 and 1.0 are the same value but True and 1 are not (Python's == equates them)."""
    if isinstance(value, bool):
        return ("bool", value)
    if _is_number(value):
        return ("number", float(value))
    if isinstance(value, (list, tuple)):
        return ("array", tuple(_key(v) for v in value))
    if isinstance(value, dict):
        return ("table", tuple(sorted((k, _key(v)) for k, v in value.items())))
    return (type(value).__name__, value)


def _interpretation(document: str, row: dict, where: str) -> Interpretation:
    cells = {k: (row.get(k) or "").strip() for k in INTERPRETATION_COLUMNS + OPTIONAL_INTERPRETATION_COLUMNS}
    name = cells["name"]
    if not _NAME.match(name):
        raise InterpretationsError(f"{where}: name {name!r} must be snake_case (lower-case letters, digits, "
                                   "underscores)")
    where = f"{where} ({name})"
    if cells["basis"] == "fitted_to_output":      # the earlier name, in a file of one's own
        cells["basis"] = "fitted"
    if cells["basis"] not in BASES:
        raise InterpretationsError(f"{where}: unknown basis {cells['basis']!r}; allowed: {', '.join(BASES)}")
    experiments = tuple(cells["experiments"].split())
    if not experiments:
        raise InterpretationsError(f"{where}: experiments is empty; list the experiment ids the interpretation "
                                   "applies to")
    if len(set(experiments)) != len(experiments):
        raise InterpretationsError(f"{where}: experiments lists an experiment twice: {cells['experiments']!r}")
    if not cells["parameter"] and not cells["where"]:
        raise InterpretationsError(f"{where}: needs a parameter or, if no notebook parameter sets it, where (the "
                                   f"module attribute that holds it)")
    if cells["parameter"] and not cells["parameter"].isidentifier():
        raise InterpretationsError(f"{where}: parameter {cells['parameter']!r} is not a Python name")
    if cells["where"] and not _WHERE.match(cells["where"]):
        raise InterpretationsError(f"{where}: where {cells['where']!r} must be a dotted path such as "
                                   f"locbook.scenarios.dogan.Q_PER_STEP")
    for column in ("source", "reason"):
        if not cells[column]:
            raise InterpretationsError(f"{where}: {column} is empty")
    default = None if cells["default"] == "" else _toml_value(cells["default"], where, "default")
    alternatives = () if cells["alternatives"] in ("", "[]") else _toml_value(cells["alternatives"], where,
                                                                                "alternatives")
    if not isinstance(alternatives, (list, tuple)):
        raise InterpretationsError(f"{where}: alternatives must be a TOML array such as ['moving'] or [0.5, 1.0], "
                                   f"got {cells['alternatives']!r}")
    alternatives = tuple(alternatives)
    keys = [_key(a) for a in alternatives]
    if default is not None and _key(default) in keys:
        raise InterpretationsError(f"{where}: the default {cells['default']} is also among the alternatives")
    if len(set(keys)) != len(keys):
        raise InterpretationsError(f"{where}: alternatives repeat a value: {cells['alternatives']}")
    fitted = () if cells["fitted"] in ("", "[]") else _toml_value(cells["fitted"], where, "fitted")
    if not isinstance(fitted, (list, tuple)):
        raise InterpretationsError(f"{where}: fitted must be a TOML array of alternatives, got {cells['fitted']!r}")
    stray = [f for f in fitted if _key(f) not in keys]
    if stray:
        raise InterpretationsError(f"{where}: fitted names {stray}, which are not among the alternatives "
                                   f"{cells['alternatives'] or '[]'}")
    low, high = _number(cells["low"], where, "low"), _number(cells["high"], where, "high")
    if (low is None) != (high is None):
        raise InterpretationsError(f"{where}: give both low and high, or neither")
    if low is not None:
        if low > high:
            raise InterpretationsError(f"{where}: low {cells['low']} > high {cells['high']}")
        if default is not None and not _is_number(default):
            raise InterpretationsError(f"{where}: a range [low, high] needs a numeric default, got {cells['default']}")
        if default is not None and not low <= default <= high:
            raise InterpretationsError(f"{where}: the default {cells['default']} is outside [low, high] = "
                                       f"[{cells['low']}, {cells['high']}]")
    if cells["basis"] == "fitted" and not alternatives and low is None:
        raise InterpretationsError(f"{where}: a fitted interpretation needs at least one alternative or a range "
                                   f"[low, high], so that a sweep can test the printed numbers under an interpretation "
                                   f"not chosen from them")
    requires = {} if cells["requires"] == "" else _toml_value(cells["requires"], where, "requires")
    if not isinstance(requires, dict) or not all(k.isidentifier() for k in requires):
        raise InterpretationsError(f"{where}: requires must be a TOML inline table of parameter names, such as "
                                   f"{{ r_mode = 'isotropic' }}, got {cells['requires']!r}")
    if requires and not cells["parameter"]:
        raise InterpretationsError(f"{where}: requires needs the interpretation's own parameter (a gap is not swept)")
    if cells["parameter"] in requires:
        raise InterpretationsError(f"{where}: requires names the interpretation's own parameter {cells['parameter']!r}")
    return Interpretation(document, name, experiments, cells["parameter"], cells["where"], default, alternatives, low,
                          high, cells["basis"], cells["source"], cells["reason"], tuple(fitted), cells["quotes"],
                          dict(requires))


def load_interpretation_file(path: str | Path, document: str | None = None) -> tuple[Interpretation, ...]:
    """The validated interpretations of one CSV file (``document``: its stem unless given). Errors name the file, the
    line and the problem (:class:`InterpretationsError`)."""
    path = Path(path)
    document = document or path.stem
    text = read_declaration(path)
    # the lines as open(path, newline="") gave them (\n, \r\n or \r ends a line), numbered as in the file
    lines = [(number, line) for number, line in enumerate(io.StringIO(text, newline=""), start=1)
             if not line.startswith("#")]
    if not lines:
        raise InterpretationsError(f"{path}: no header line; the columns must be {', '.join(INTERPRETATION_COLUMNS)}")
    reader = csv.DictReader(line for _, line in lines)
    try:
        columns = tuple(reader.fieldnames or ())
    except csv.Error as exc:
        raise InterpretationsError(f"{path}, line {lines[0][0]}: not a well-formed CSV header ({exc})") from None
    # a file of one's own written before the quotes column still loads: its quotes are empty
    unquoted = tuple(c for c in INTERPRETATION_COLUMNS if c != "quotes")
    if columns not in (INTERPRETATION_COLUMNS, INTERPRETATION_COLUMNS + OPTIONAL_INTERPRETATION_COLUMNS, unquoted,
                       unquoted + OPTIONAL_INTERPRETATION_COLUMNS):
        raise InterpretationsError(f"{path}, line {lines[0][0]}: columns must be "
                                   f"{', '.join(INTERPRETATION_COLUMNS)} (then optionally "
                                   f"{', '.join(OPTIONAL_INTERPRETATION_COLUMNS)}); got {', '.join(columns)}")
    out, seen = [], {}
    rows = iter(reader)
    while True:
        # the line the row starts on: reader.line_num counts the non-comment lines read so far (a quoted field
        # may span several)
        at = reader.line_num
        while at < len(lines) - 1 and lines[at][1] in ("", "\n", "\r\n", "\r"):   # the csv module skips blank lines
            at += 1
        number = lines[min(at, len(lines) - 1)][0]
        try:
            row = next(rows)
        except StopIteration:
            break
        except csv.Error as exc:     # a field over the csv module's size limit, a stray quote
            raise InterpretationsError(f"{path}, line {number}: not a well-formed CSV row ({exc})") from None
        where = f"{path}, line {number}"
        if None in row or any(v is None for v in row.values()):
            raise InterpretationsError(f"{where}: expected {len(columns)} fields ({', '.join(columns)})")
        interp = _interpretation(document, row, where)
        if interp.name in seen:
            raise InterpretationsError(f"{where}: duplicate name {interp.name!r} (first on line {seen[interp.name]})")
        seen[interp.name] = number
        out.append(interp)
    return tuple(out)


@lru_cache(maxsize=None)
def interpretations(document: str) -> tuple[Interpretation, ...]:
    """The declared interpretations of ``document`` (``"dogan2015"``, ``"george"``, ...), validated; cached."""
    path = INTERPRETATIONS_DIR / f"{document}.csv"
    if not path.is_file():
        known = sorted(p.stem for p in INTERPRETATIONS_DIR.glob("*.csv"))
        raise KeyError(f"no interpretations declared for document {document!r}; known: {known}")
    return load_interpretation_file(path, document)


def interpretations_for(experiment_id: str) -> tuple[Interpretation, ...]:
    """Every declared interpretation (of any document) that applies to ``experiment_id``, in file order."""
    return tuple(r for path in sorted(INTERPRETATIONS_DIR.glob("*.csv")) for r in interpretations(path.stem)
                 if experiment_id in r.experiments)
