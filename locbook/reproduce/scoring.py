"""The scoreboard's rules: what kind of agreement a row is, its window, and its verdict.

Every row of ``numbers.csv`` compares one printed quantity (a :class:`~locbook.reproduce.Printed`) with our
number, and says what kind of comparison it is:

``reproduction``
    our own simulation or analysis, with only documented assumptions, none chosen from this number or one
    tied to it;
``calibrated``
    an input was chosen or fitted from a printed number; the row names which input and from which printed
    number (``calibrated_from``). It shows agreement and is never counted as a reproduction;
``arithmetic``
    checks the source's own arithmetic (a table average, a percentage) from its other printed numbers;
``claim``
    a printed qualitative statement ("more than 50 %", an ordering), checked as stated: one-sided where it
    is one-sided (``relation`` ``>``, ``>=``, ``<``, ``<=`` against a threshold);
``shown``
    printed and transcribed, nothing to compare.

The window of a reproduction or calibrated row is ``printed +- (rounding + 2 SE + ambiguity)``: half a unit
in the last printed digit, two Monte-Carlo standard errors of our estimate (from run-level values), and a
named protocol ambiguity whose size and source the row states (:class:`Ambiguity`). The verdict:

- ``miss``: our value is outside the window;
- ``loose``: inside, but the window is wider than +-25 % of the printed value (:data:`WITHIN_LIMIT`), so
  agreement says little;
- ``within``: inside a window no wider than +-25 %.

A claim is ``within`` when it holds for our value minus (or plus) two standard errors, ``loose`` when it holds
for our value but not with that margin, ``miss`` when it fails. An arithmetic row is ``consistent`` when the
recomputed value lies within the printed rounding (plus the stated rounding of the inputs), else
``inconsistent``. A ``shown`` row has no verdict, and neither has a row that repeats a printed quantity
compared elsewhere (``same_as``): each printed quantity is counted once.
"""
from __future__ import annotations

import math
from collections import Counter
from dataclasses import dataclass

import numpy as np

from .printed_values import printed_number, printed_rounding

__all__ = ["KINDS", "VERDICTS", "JUDGED_KINDS", "CLAIM_RELATIONS", "WITHIN_LIMIT", "Ambiguity", "Score",
           "score", "SCORED_VERDICTS", "VERDICT_COLUMNS", "BRACKETS", "verdict_column", "scoreboard_counts",
           "verdict_counts_text"]

KINDS = ("reproduction", "calibrated", "arithmetic", "claim", "shown")
#: kinds that get within / loose / miss
JUDGED_KINDS = ("reproduction", "calibrated", "claim")
VERDICTS = ("within", "loose", "miss", "consistent", "inconsistent", "")
CLAIM_RELATIONS = (">", ">=", "<", "<=")
#: a window wider than this fraction of the printed value gives "loose", never "within"
WITHIN_LIMIT = 0.25
#: the verdicts a judged row (:data:`JUDGED_KINDS`) can have
SCORED_VERDICTS = ("within", "loose", "miss")
#: verdict columns of the kind-by-verdict tables ("linked": repeats of a quantity compared elsewhere)
VERDICT_COLUMNS = ("within", "loose", "miss", "consistent", "inconsistent", "no verdict", "linked")
#: The bracket verdicts (the tiers), in the order the headline counts them: reproduced under the default
#: interpretation; under another textual (or, where the text is silent, assumed) interpretation; only under an
#: interpretation fitted to printed output; between interpretations (the printed value inside the band of our values, no
#: single interpretation within); outside every interpretation (beyond the band widened by both Monte-Carlo errors);
#: open (a setting that could matter not swept, a point not run, or a margin Monte-Carlo error could close); loose (a
#: window too wide to decide).
BRACKETS = ("default", "other_interpretation", "fitted_only", "between", "outside", "open", "loose")


def verdict_column(row: dict) -> str:
    """The column of :data:`VERDICT_COLUMNS` a ``numbers.csv`` row is counted in."""
    if row.get("same_as"):
        return "linked"
    return row.get("verdict") or "no verdict"


def verdict_counts_text(counter) -> str:
    """One kind's rows by verdict column, ``"3 within, 1 loose, 2 miss"``: in :data:`VERDICT_COLUMNS` order, the same
    on every line and every run (not by size), columns without rows left out."""
    return ", ".join(f"{counter[v]} {v}" for v in VERDICT_COLUMNS if counter.get(v))


def scoreboard_counts(rows) -> dict[str, Counter]:
    """``{kind: Counter(verdict column -> rows)}`` over ``numbers.csv`` rows (kinds in :data:`KINDS` order)."""
    counts: dict[str, Counter] = {k: Counter() for k in KINDS}
    for r in rows:
        counts.setdefault(r.get("kind", ""), Counter())[verdict_column(r)] += 1
    return {k: c for k, c in counts.items() if c}

@dataclass(frozen=True)
class Ambiguity:
    """A named protocol ambiguity that widens a window: its size (in the quantity's unit), what it is, and
    where the source leaves it open (document and section)."""

    size: float
    what: str
    source: str

    def __post_init__(self):
        if not (isinstance(self.size, (int, float)) and math.isfinite(self.size) and self.size >= 0):
            raise ValueError(f"an ambiguity's size must be a finite number >= 0, got {self.size!r}")
        if not str(self.what).strip() or not str(self.source).strip():
            raise ValueError("an ambiguity needs both what it is and its source (document and section)")

    def describe(self) -> str:
        return f"{self.what} ({self.source})"

    @classmethod
    def single_experiment(cls, per_run, what: str, source: str, *, k: float = 2.0) -> "Ambiguity":
        """The source measured ONE experiment (one walk, one calibration), whose value scatters as one of our runs
        does: the window widens by ``k`` sample standard deviations (``ddof=1``) of our run-level values
        ``per_run`` (at least two finite values)."""
        values = np.asarray(per_run, dtype=float).ravel()
        if values.size < 2 or not np.all(np.isfinite(values)):
            raise ValueError(f"a single-experiment ambiguity needs at least two finite run-level values, got "
                             f"{values.size} value(s){'' if np.all(np.isfinite(values)) else ' with NaN or inf'}")
        return cls(k * float(np.std(values, ddof=1)), what, source)

    @classmethod
    def spread(cls, values, centre: float, what: str, source: str) -> "Ambiguity":
        """A quantity the source leaves undefined, whose plausible interpretations give ``values``: the window widens by
        the largest distance of any of them from ``centre`` (our number's interpretation)."""
        values = np.asarray(values, dtype=float).ravel()
        if values.size == 0:
            raise ValueError("a spread ambiguity needs at least one value of the alternative interpretations")
        return cls(float(np.max(np.abs(values - centre))), what, source)


@dataclass(frozen=True)
class Score:
    """A row's window and verdict. ``low``/``high`` bound the accepted values of our number (one of them
    infinite for a one-sided claim); NaN where the kind has no window."""

    verdict: str
    low: float
    high: float
    rounding: float
    half_width: float
    relative_half_width: float


_NO_WINDOW = dict(low=math.nan, high=math.nan, rounding=math.nan, half_width=math.nan, relative_half_width=math.nan)


def score(kind: str, printed_text: str, reproduced: float | None, *, mc_std_error: float | None = None,
          ambiguity: Ambiguity | None = None, relation: str | None = None, threshold: float | None = None,
          linked: bool = False) -> Score:
    """Window and verdict of one row under the rules of this module.

    ``printed_text`` is the number as printed (its digits set the rounding; for a claim, the statement, whose
    one number is the threshold unless ``threshold`` is given). ``mc_std_error`` is the Monte-Carlo standard
    error of ``reproduced`` from run-level values (None or 0 for a deterministic number). ``linked`` rows repeat
    a quantity compared elsewhere and get no verdict."""
    if kind not in KINDS:
        raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
    if kind == "claim":
        if relation not in CLAIM_RELATIONS:
            raise ValueError(f"a claim needs relation in {CLAIM_RELATIONS}, got {relation!r}")
    elif relation is not None or threshold is not None:
        raise ValueError("relation and threshold belong to claim rows only")
    se = 0.0 if mc_std_error is None else float(mc_std_error)
    if not (math.isfinite(se) and se >= 0):
        raise ValueError(f"mc_std_error must be finite and >= 0, got {mc_std_error!r}")
    if kind == "shown" or linked:
        return Score("", **_NO_WINDOW)
    if reproduced is None or not math.isfinite(float(reproduced)):
        raise ValueError(f"a {kind} row needs a finite reproduced value, got {reproduced!r}")
    ours = float(reproduced)
    if kind == "claim":
        if ambiguity is not None:
            raise ValueError("a claim is checked as stated: it takes no ambiguity")
        limit = printed_number(printed_text) if threshold is None else float(threshold)
        above = relation.startswith(">")
        holds = _holds(relation, ours, limit)
        margin = _holds(relation, ours - 2 * se if above else ours + 2 * se, limit)
        verdict = "within" if margin else "loose" if holds else "miss"
        low, high = (limit, math.inf) if above else (-math.inf, limit)
        return Score(verdict, low, high, 0.0, 2 * se, math.nan)
    value = printed_number(printed_text)
    rounding = printed_rounding(printed_text)
    half = rounding + 2 * se + (ambiguity.size if ambiguity else 0.0)
    inside = abs(ours - value) <= half * (1 + 1e-12)
    relative = half / abs(value) if value != 0 else math.inf
    if kind == "arithmetic":
        verdict = "consistent" if inside else "inconsistent"
    else:
        verdict = "miss" if not inside else "loose" if relative > WITHIN_LIMIT else "within"
    return Score(verdict, value - half, value + half, rounding, half, relative)


def _holds(relation: str, ours: float, limit: float) -> bool:
    return {">": ours > limit, ">=": ours >= limit, "<": ours < limit, "<=": ours <= limit}[relation]
