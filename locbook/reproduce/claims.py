"""The claims and conclusions each source states about its results, declared as data and judged from the rows.

One CSV per document, ``locbook/data/claims/<document>.csv`` (package data; ``#`` lines are comments), transcribed
by the locbook authors, with the columns :data:`CLAIM_COLUMNS`:

``id``
    snake_case, unique within the document.
``location``
    where the claim stands (section, table, figure caption, conclusion item; the line of the text).
``claim``
    the source's words, as printed.
``kind``
    one of :data:`CLAIM_KINDS`: ``ranking`` (A better than B), ``trend`` (against a parameter), ``effect``
    (adding X changes Y), ``bound`` (against the CRLB/PCRLB), ``value`` (a restated number), ``statement``
    (anything no row can test).
``evidence``
    a TOML inline table: a short name -> the row of a suite's numbers.csv it stands for, written
    ``"<experiment> | <printed_id>"`` (empty: no row measures the claim; ``note`` says what would).
``test``
    an expression over the evidence names that is true when the claim holds (:func:`evaluate`): numbers, names,
    ``+ - * /``, ``abs()``, comparisons (chains allowed), ``and``/``or``/``not``, ``increasing(...)`` /
    ``decreasing(...)`` (strictly, in the order given), ``verdict(name)`` (a ``claim`` row's own verdict).
``ambiguity``, ``alt_test``
    why the wording admits another interpretation, and the test under it (both or neither).
``inconsistency``
    an inconsistency inside the source that bears on the claim or its rows.
``note``
    what a reader needs besides.

A test is judged three ways (:func:`evaluate`): on the printed values (does the source's own table support its
claim?), on our values under the default interpretation, and on our values under each other interpretation a bracket
ran. Our values carry their Monte-Carlo standard errors: a comparison is decided only where the difference clears two
standard errors of the difference (else it is undecidable); printed values are compared as printed.
"""
from __future__ import annotations

import ast
import csv
import io
import math
import re
import tomllib
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from ..errors import LocbookError
from .interpretations import read_declaration

__all__ = ["Claim", "ClaimsError", "CLAIM_COLUMNS", "CLAIM_KINDS", "CLAIMS_DIR", "claims", "load_claims_file",
           "Value", "evaluate", "HOLDS", "FAILS", "UNDECIDABLE", "outcome_word"]

CLAIMS_DIR = Path(__file__).resolve().parents[1] / "data" / "claims"      # package data of locbook.data
CLAIM_COLUMNS = ("id", "location", "claim", "kind", "evidence", "test", "ambiguity", "alt_test", "inconsistency",
                 "note")
CLAIM_KINDS = ("ranking", "trend", "effect", "bound", "value", "statement")
HOLDS, FAILS, UNDECIDABLE = True, False, None
_ID = re.compile(r"[a-z][a-z0-9_]*\Z")
_FUNCTIONS = ("increasing", "decreasing", "abs", "verdict")


class ClaimsError(LocbookError, ValueError):
    """A claims file that breaks a rule; the message names the file, the line and the problem on one line."""

    def __init__(self, message: str):
        super().__init__(str(message).replace("\r", " ").replace("\n", " "))


@dataclass(frozen=True)
class Claim:
    """One claim of a document (a row of its claims CSV); ``evidence``: name -> (experiment, printed_id)."""

    document: str
    id: str
    location: str
    claim: str
    kind: str
    evidence: dict = field(hash=False)
    test: str
    ambiguity: str = ""
    alt_test: str = ""
    inconsistency: str = ""
    note: str = ""

    @property
    def testable(self) -> bool:
        return bool(self.test)


def outcome_word(outcome) -> str:
    """``holds`` / ``fails`` / ``undecidable`` for a three-valued outcome."""
    return {True: "holds", False: "fails"}.get(outcome, "undecidable")


@dataclass(frozen=True)
class Value:
    """A number with its standard error (0 for a printed value or an exact one); ``verdict``: a claim row's own."""

    value: float
    se: float = 0.0
    verdict: str = ""


# -- the expression -------------------------------------------------------------------------------------------
_ALLOWED = (ast.Expression, ast.BoolOp, ast.And, ast.Or, ast.UnaryOp, ast.Not, ast.USub, ast.UAdd, ast.BinOp,
            ast.Add, ast.Sub, ast.Mult, ast.Div, ast.Compare, ast.Lt, ast.LtE, ast.Gt, ast.GtE, ast.Call, ast.Name,
            ast.Load, ast.Constant)


def _parse(text: str, names: set[str], where: str) -> ast.Expression:
    try:
        tree = ast.parse(text, mode="eval")
    except SyntaxError as exc:
        raise ClaimsError(f"{where}: test {text!r} is not an expression ({exc.msg})") from None
    for node in ast.walk(tree):
        if not isinstance(node, _ALLOWED):
            raise ClaimsError(f"{where}: test {text!r} uses {type(node).__name__}, which is not allowed (numbers, "
                              "evidence names, + - * /, comparisons, and/or/not, increasing(), decreasing(), abs(), "
                              "verdict())")
        if isinstance(node, ast.Constant) and (isinstance(node.value, bool) or not isinstance(node.value,
                                                                                              (int, float))):
            raise ClaimsError(f"{where}: test {text!r} holds the constant {node.value!r}; only numbers are allowed")
        if isinstance(node, ast.Call):
            if not isinstance(node.func, ast.Name) or node.func.id not in _FUNCTIONS or node.keywords:
                raise ClaimsError(f"{where}: test {text!r} calls something other than {', '.join(_FUNCTIONS)}")
            if node.func.id == "verdict" and (len(node.args) != 1 or not isinstance(node.args[0], ast.Name)):
                raise ClaimsError(f"{where}: verdict() takes one evidence name")
        if isinstance(node, ast.Name) and node.id not in _FUNCTIONS and node.id not in names:
            raise ClaimsError(f"{where}: test {text!r} names {node.id!r}, which is not in evidence "
                              f"({', '.join(sorted(names)) or 'empty'})")
    _kind(tree.body, text, where)
    return tree


def _kind(node, text: str, where: str) -> str:
    """``number`` or ``truth``: what ``node`` yields; a number where a truth is needed (or the reverse), a bare
    function name, or a function given the wrong number of arguments is refused here, at load time."""
    def need(child, want):
        got = _kind(child, text, where)
        if got != want:
            raise ClaimsError(f"{where}: test {text!r}: {ast.unparse(child)!r} is a {got} where a {want} is "
                              "needed")
    if isinstance(node, ast.Constant):
        return "number"
    if isinstance(node, ast.Name):
        if node.id in _FUNCTIONS:
            raise ClaimsError(f"{where}: test {text!r}: {node.id} is a function; call it")
        return "number"
    if isinstance(node, ast.BoolOp):
        for v in node.values:
            need(v, "truth")
        return "truth"
    if isinstance(node, ast.UnaryOp):
        need(node.operand, "truth" if isinstance(node.op, ast.Not) else "number")
        return "truth" if isinstance(node.op, ast.Not) else "number"
    if isinstance(node, ast.BinOp):
        need(node.left, "number")
        need(node.right, "number")
        return "number"
    if isinstance(node, ast.Compare):
        for child in (node.left, *node.comparators):
            need(child, "number")
        return "truth"
    if isinstance(node, ast.Call):
        name, args = node.func.id, node.args
        if name == "verdict":
            if args[0].id in _FUNCTIONS:
                raise ClaimsError(f"{where}: test {text!r}: {args[0].id} is a function; call it")
            return "truth"
        if name == "abs" and len(args) != 1:
            raise ClaimsError(f"{where}: test {text!r}: abs() takes one argument")
        if name in ("increasing", "decreasing") and len(args) < 2:
            raise ClaimsError(f"{where}: test {text!r}: {name}() needs two or more arguments")
        for a in args:
            need(a, "number")
        return "number" if name == "abs" else "truth"
    raise ClaimsError(f"{where}: test {text!r} uses {type(node).__name__}")


def _and(values):
    values = list(values)
    if any(v is False for v in values):
        return False
    return None if any(v is None for v in values) else True


def _or(values):
    values = list(values)
    if any(v is True for v in values):
        return True
    return None if any(v is None for v in values) else False


def _compare(op, a: Value, b: Value):
    """a op b, decided only beyond 2 standard errors of the difference (exactly, when both are exact)."""
    d = b.value - a.value                  # > 0: a < b
    s = 2.0 * math.hypot(a.se, b.se)
    if not (math.isfinite(d) and math.isfinite(s)):
        return None
    if s > 0 and abs(d) <= s:
        return None
    if isinstance(op, (ast.Lt, ast.LtE)):
        return d > 0 or (isinstance(op, ast.LtE) and d == 0)
    return d < 0 or (isinstance(op, ast.GtE) and d == 0)


def _monotone(args: list[Value], op):
    return _and(_compare(op, x, y) for x, y in zip(args, args[1:]))


def _eval(node, env: dict[str, Value]):
    if isinstance(node, ast.Expression):
        return _eval(node.body, env)
    if isinstance(node, ast.Constant):
        return Value(float(node.value))
    if isinstance(node, ast.Name):
        return env[node.id]
    if isinstance(node, ast.BoolOp):
        parts = [_truth(_eval(v, env)) for v in node.values]
        return _and(parts) if isinstance(node.op, ast.And) else _or(parts)
    if isinstance(node, ast.UnaryOp):
        x = _eval(node.operand, env)
        if isinstance(node.op, ast.Not):
            t = _truth(x)
            return None if t is None else not t
        return Value(-x.value, x.se) if isinstance(node.op, ast.USub) else x
    if isinstance(node, ast.BinOp):
        a, b = _eval(node.left, env), _eval(node.right, env)
        if isinstance(node.op, (ast.Add, ast.Sub)):
            sign = 1.0 if isinstance(node.op, ast.Add) else -1.0
            return Value(a.value + sign * b.value, math.hypot(a.se, b.se))
        if isinstance(node.op, ast.Mult):
            return Value(a.value * b.value, math.hypot(b.value * a.se, a.value * b.se))
        if b.value == 0:
            return Value(math.nan, math.nan)
        q = a.value / b.value
        return Value(q, math.hypot(a.se / b.value, q * b.se / b.value))
    if isinstance(node, ast.Compare):
        left, out = _eval(node.left, env), []
        for op, right_node in zip(node.ops, node.comparators):
            right = _eval(right_node, env)
            out.append(_compare(op, left, right))
            left = right
        return _and(out)
    if isinstance(node, ast.Call):
        name = node.func.id
        if name == "verdict":
            return {"within": True, "miss": False}.get(env[node.args[0].id].verdict)
        args = [_eval(a, env) for a in node.args]
        if name == "abs":
            return Value(abs(args[0].value), args[0].se)
        return _monotone(args, ast.Lt() if name == "increasing" else ast.Gt())
    raise TypeError(type(node).__name__)       # excluded by _parse


def _truth(x):
    return None if isinstance(x, Value) else x        # (a number where a truth is needed is refused at load time)


def evaluate(test: str, env: dict[str, Value]):
    """The three-valued outcome of ``test`` on ``env`` (evidence name -> :class:`Value`): True (holds), False
    (fails) or None (undecidable: within Monte-Carlo error, a missing or non-finite value, a loose claim row)."""
    tree = _parse(test, set(env), "test")
    if _kind(tree.body, test, "test") != "truth":
        raise ClaimsError(f"test {test!r} is a number, not a statement that holds or fails (compare it)")
    if any(not math.isfinite(v.value) for v in env.values() if isinstance(v, Value) and not v.verdict):
        return None
    return _truth(_eval(tree, env))


# -- the file -----------------------------------------------------------------------------------------------
def _claim(document: str, row: dict, where: str) -> Claim:
    cells = {k: (row.get(k) or "").strip() for k in CLAIM_COLUMNS}
    if not _ID.match(cells["id"]):
        raise ClaimsError(f"{where}: id {cells['id']!r} must be snake_case")
    where = f"{where} ({cells['id']})"
    for column in ("location", "claim"):
        if not cells[column]:
            raise ClaimsError(f"{where}: {column} is empty")
    if cells["kind"] not in CLAIM_KINDS:
        raise ClaimsError(f"{where}: unknown kind {cells['kind']!r}; allowed: {', '.join(CLAIM_KINDS)}")
    evidence = {}
    if cells["evidence"]:
        try:
            table = tomllib.loads(f"v = {cells['evidence']}")["v"]
        except tomllib.TOMLDecodeError as exc:
            raise ClaimsError(f"{where}: evidence is not a TOML inline table ({exc})") from None
        if not isinstance(table, dict):
            raise ClaimsError(f"{where}: evidence must be a TOML inline table of name = \"experiment | printed_id\"")
        for name, selector in table.items():
            if not name.isidentifier() or name in _FUNCTIONS:
                raise ClaimsError(f"{where}: evidence name {name!r} must be a plain name")
            if not isinstance(selector, str) or " | " not in selector:
                raise ClaimsError(f"{where}: evidence {name} = {selector!r} must read \"<experiment> | <printed_id>\"")
            experiment, printed_id = (part.strip() for part in selector.split(" | ", 1))
            evidence[name] = (experiment, printed_id)
    for column in ("test", "alt_test"):
        if cells[column]:
            if not evidence:
                raise ClaimsError(f"{where}: {column} needs evidence")
            tree = _parse(cells[column], set(evidence), f"{where}: {column}")
            if _kind(tree.body, cells[column], where) != "truth":
                raise ClaimsError(f"{where}: {column} {cells[column]!r} is a number, not a statement that holds or "
                                  "fails (compare it)")
    if bool(cells["ambiguity"]) != bool(cells["alt_test"]) and cells["test"]:
        raise ClaimsError(f"{where}: ambiguity and alt_test go together (the test under the other interpretation)")
    return Claim(document, cells["id"], cells["location"], cells["claim"], cells["kind"], evidence, cells["test"],
                 cells["ambiguity"], cells["alt_test"], cells["inconsistency"], cells["note"])


def load_claims_file(path: str | Path, document: str | None = None) -> tuple[Claim, ...]:
    """The validated claims of one CSV file (``document``: its stem unless given)."""
    path = Path(path)
    document = document or path.stem
    text = read_declaration(path, ClaimsError, "a claims file")
    lines = [(n, line) for n, line in enumerate(io.StringIO(text, newline=""), start=1) if not line.startswith("#")]
    if not lines:
        raise ClaimsError(f"{path}: no header line; the columns must be {', '.join(CLAIM_COLUMNS)}")
    reader = csv.DictReader(line for _, line in lines)
    try:
        columns = tuple(reader.fieldnames or ())
        rows = list(reader)
    except csv.Error as exc:
        raise ClaimsError(f"{path}: not well-formed CSV ({exc})") from None
    if columns != CLAIM_COLUMNS:
        raise ClaimsError(f"{path}, line {lines[0][0]}: columns must be {', '.join(CLAIM_COLUMNS)}; got "
                          f"{', '.join(columns)}")
    out, seen = [], set()
    for i, row in enumerate(rows):
        where = f"{path}, claim {i + 1}"
        if None in row or any(v is None for v in row.values()):
            raise ClaimsError(f"{where}: expected {len(CLAIM_COLUMNS)} fields")
        claim = _claim(document, row, where)
        if claim.id in seen:
            raise ClaimsError(f"{where}: duplicate id {claim.id!r}")
        seen.add(claim.id)
        out.append(claim)
    return tuple(out)


@lru_cache(maxsize=None)
def claims(document: str) -> tuple[Claim, ...]:
    """The declared claims of ``document`` (empty when it has no claims file), validated; cached."""
    path = CLAIMS_DIR / f"{document}.csv"
    return load_claims_file(path, document) if path.is_file() else ()
