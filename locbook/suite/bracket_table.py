"""An interpretation bracket's tables, as written and as read back: the columns of bracket.csv, values.csv and
points.csv, loading them (a damaged file or another layout reads as none), and each numbers.csv row's bracket verdict
(:func:`bracket_of_rows`, which the suite's reports apply).

Below :mod:`locbook.suite.bracket` (which runs a bracket and writes these tables) and used by the site, findings and
conclusions pages: reading a bracket needs neither the runner nor the bracket's sweep.
"""
from __future__ import annotations

import csv
import math
from pathlib import Path

from ..reproduce.report import NUMBER_COLUMNS
from ..reproduce.scoring import BRACKETS, JUDGED_KINDS, SCORED_VERDICTS
from .files import read_csv
from .spec import PROFILES, finite_float

__all__ = ["BRACKET_ROW_COLUMNS", "SITE_NUMBER_COLUMNS", "BRACKET_COLUMNS", "VALUE_COLUMNS", "POINT_COLUMNS",
           "DEFAULT_POINT", "index_rows", "find_row", "is_scored", "SAME_RESULT_RTOL", "same_number", "four_digits",
           "bracket_of_rows", "brackets_root",
           "NoBracket", "read_table", "load_bracket", "load_values", "counts"]


#: the columns a suite's numbers.csv adds to an experiment's (:data:`~locbook.reproduce.report.NUMBER_COLUMNS`)
BRACKET_ROW_COLUMNS = ("bracket", "bracket_interpretations")


SITE_NUMBER_COLUMNS = (*NUMBER_COLUMNS, *BRACKET_ROW_COLUMNS)


BRACKET_COLUMNS = ("experiment", "printed_id", "quantity", "where", "unit", "kind", "printed", "ours", "verdict",
                   "bracket", "reached_by", "open_interpretations", "loose_under", "between", "band_low", "band_high",
                   "outside_margin", "implausible", "closest", "closest_interpretation", "points", "profile")


#: the columns of a bracket's values.csv: every scored row under every point (the conclusions pages judge each
#: claim under every interpretation from it)
VALUE_COLUMNS = ("experiment", "printed_id", "quantity", "where", "point", "interpretation", "basis", "ours",
                 "mc_std_error", "verdict")


POINT_COLUMNS = ("point", "interpretations", "parameter", "value", "status", "folder", "generated_by",
                 "interpretations_file", "settings")


DEFAULT_POINT = "default"


def _row_key(r: dict) -> tuple[str, str, str]:
    return (r["printed_id"], r["quantity"], r["where"])


def index_rows(rows: list[dict]) -> tuple[dict, dict]:
    """Rows by (printed_id, quantity, where), and by (printed_id, where) where that pair is unique (quantities
    that name a run count differ between profiles)."""
    full, loose, seen = {}, {}, {}
    for r in rows:
        full.setdefault(_row_key(r), r)
        pair = (r["printed_id"], r["where"])
        seen[pair] = seen.get(pair, 0) + 1
        loose[pair] = r
    return full, {k: v for k, v in loose.items() if seen[k] == 1}


def find_row(indexed: tuple[dict, dict], r: dict) -> dict | None:
    full, loose = indexed
    return full.get(_row_key(r)) or loose.get((r.get("printed_id", ""), r.get("where", "")))


def is_scored(r: dict) -> bool:
    return r.get("kind") in JUDGED_KINDS and r.get("verdict") in SCORED_VERDICTS


#: Relative tolerance within which a report's value and its bracket's default run are one result: what another
#: machine of the same kind gives for the same code and parameters (docs/reports.md, "Across machines": numpy's
#: and numba's vector code; measured at most 5e-8 over the full profile), with a margin of 20. A stale bracket
#: (other code or parameters) moves a Monte-Carlo result by far more.
SAME_RESULT_RTOL = 1e-6


def same_number(a, b) -> bool:
    """Two CSV cells of ``ours`` hold the same result (numbers within :data:`SAME_RESULT_RTOL`, anything else as
    text)."""
    x, y = finite_float(a), finite_float(b)
    if x is None or y is None:
        return str(a).strip() == str(b).strip()
    return math.isclose(x, y, rel_tol=SAME_RESULT_RTOL, abs_tol=1e-12)


def bracket_of_rows(rows: list[dict], bracket: list[dict], profile: str | None = None) -> list[dict]:
    """``rows`` (numbers.csv rows of one experiment) with ``bracket`` and ``bracket_interpretations`` set from that
    experiment's ``bracket`` rows: ``default`` when the row itself is within here, else what the bracket's other
    interpretations gave (other_interpretation / fitted_only / open / between / loose / outside, each interpretation
    named with the bracket's profile, e.g.
    ``at quick: ...``). A row loose here is at worst ``loose``; a row the bracket had within under the default but
    that is not within here (another profile's window) is ``open`` whatever the other interpretations gave there: they
    were not run at this profile. ``profile``: the report's; where it is the bracket's, a row whose value here
    differs from the bracket's default run is ``open``: the bracket is stale (made by other code or parameters).
    Empty for rows the bracket does not cover or does not score. Where no bracket.csv exists at all (``bracket`` a
    :class:`NoBracket`), a row keeps the bracket columns the profile's numbers.csv gave it, if its value and verdict
    there are the same (:func:`_previous_columns`): a missing bracket is no new verdict."""
    if isinstance(bracket, NoBracket):
        kept = _previous_columns(bracket.folder, profile)
        return [{**r, **kept.get(_site_key(r), {"bracket": "", "bracket_interpretations": ""})} for r in rows]
    indexed = index_rows(bracket)
    out = []
    for r in rows:
        b = find_row(indexed, r) if is_scored(r) else None
        if b is None:
            out.append({**r, "bracket": "", "bracket_interpretations": ""})
            continue
        at = f"at {b.get('profile') or '?'}: "
        if r["verdict"] == "within" and not (b.get("implausible") or "").startswith(DEFAULT_POINT + " gave"):
            verdict, interpretations = "default", ""
        elif profile is not None and profile == b.get("profile") and not same_number(r.get("reproduced"),
                                                                                       b.get("ours")):
            verdict, interpretations = "open", (f"this report and its {profile} bracket disagree: the bracket's "
                                                f"default run gave {b.get('ours')}, this report {r.get('reproduced')} "
                                                "(made by other code or parameters; run the older of the two again)")
        elif b.get("bracket") == "default":
            # within under the default at the bracket's profile (a wider window), not here: the other interpretations'
            # verdicts there say nothing about this report's window
            verdict, interpretations = "open", (f"within {at[:-2]} under the default interpretation, not here: the "
                                                "interpretations were not run at this profile")
        elif b.get("bracket") in ("other_interpretation", "fitted_only"):
            verdict, interpretations = b["bracket"], at + b["reached_by"]
        elif b.get("open_interpretations") or b.get("bracket") == "open":
            verdict, interpretations = "open", at + (b.get("open_interpretations") or "")
        elif b.get("bracket") == "between":
            verdict, interpretations = "between", f"{at}between {b.get('between')}"
        elif r["verdict"] == "loose" or b.get("loose_under"):
            under = [x for x in (b.get("loose_under") or "").split("; ") if x and x != DEFAULT_POINT]
            verdict, interpretations = "loose", "; ".join((["this report"] if r["verdict"] == "loose" else [])
                                                          + ([at + "; ".join(under)] if under else []))
        else:
            verdict, interpretations = "outside", (f"{at}band {four_digits(b.get('band_low', ''))} .. "
                                                   f"{four_digits(b.get('band_high', ''))} over {b.get('points')} runs"
                                                   + (f"; {b['outside_margin']}" if b.get("outside_margin") else ""))
        if b.get("implausible"):
            interpretations += f" (implausible, left out of the band: {b['implausible']})"
        out.append({**r, "bracket": verdict, "bracket_interpretations": interpretations})
    return out


def _site_key(r: dict) -> tuple:
    """A numbers row as the bracket columns belong to it: the row and what it said (value, verdict)."""
    return (r.get("experiment", ""), r.get("printed_id", ""), r.get("quantity", ""), r.get("where", ""),
            str(r.get("reproduced", "")).strip(), r.get("verdict", ""))


def _previous_columns(bracket_folder: Path, profile: str | None) -> dict[tuple, dict]:
    """The bracket columns of the rows of ``numbers.csv`` in the profile's reports folder beside the brackets
    (``<reports>/<profile>/`` for ``<reports>/brackets/<experiment>``), by :func:`_site_key`; empty for a report of
    no known profile or a folder without one (its numbers are read as written: a damaged file keeps nothing)."""
    if profile not in PROFILES:
        return {}
    rows = read_csv(Path(bracket_folder).parent.parent / profile / "numbers.csv")
    out = {}
    for r in rows:
        if None in r or r.get("bracket") is None or r.get("bracket_interpretations") is None:
            return {}      # another layout, or a short row
        if r["bracket"] in BRACKETS:         # a retired tier name (an older numbers.csv) is no verdict of today's
            out[_site_key(r)] = {"bracket": r["bracket"], "bracket_interpretations": r["bracket_interpretations"]}
    return out


def brackets_root(report_dir: Path) -> Path:
    """Where the brackets of a run's reports folder live: ``<reports>/brackets`` beside ``<reports>/<profile>``."""
    return Path(report_dir).parent / "brackets"


class NoBracket(list):
    """What :func:`load_bracket` returns where no bracket.csv exists (an empty list): ``folder`` is where it looked,
    so that :func:`bracket_of_rows` keeps the bracket columns a profile's numbers.csv already holds (a copy of
    ``reports/<profile>`` without ``reports/brackets`` beside it has lost no verdict)."""

    def __init__(self, folder: Path):
        super().__init__()
        self.folder = Path(folder)


def read_table(path: Path, columns) -> list[dict] | None:
    """The rows of the CSV file ``path`` if its header is ``columns`` and every row is whole; None if it is
    damaged or of another layout (a file is never read other than as written)."""
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            reader = csv.DictReader(fh)
            if tuple(reader.fieldnames or ()) != columns:
                return None
            rows = list(reader)
    except (OSError, ValueError, csv.Error):
        return None
    return None if any(None in r or any(v is None for v in r.values()) for r in rows) else rows


def load_bracket(folder: Path) -> list[dict]:
    """The rows of ``<folder>/bracket.csv``; empty if it is damaged or of another layout (a header other than
    :data:`BRACKET_COLUMNS`, a short row): a report is never labelled from a file that cannot be read as written;
    a :class:`NoBracket` (empty) if there is none."""
    path = Path(folder) / "bracket.csv"
    if not path.is_file():
        return NoBracket(folder)
    return read_table(path, BRACKET_COLUMNS) or []


def load_values(folder: Path) -> list[dict]:
    """The rows of ``<folder>/values.csv`` (every scored row under every point), empty if absent, damaged or of
    another layout."""
    return read_table(Path(folder) / "values.csv", VALUE_COLUMNS) or []


def four_digits(text: str) -> str:
    """A number of bracket.csv to 4 significant digits for a row's bracket_interpretations (text as it is)."""
    value = finite_float(text)
    return text if value is None else f"{value:.4g}"


def counts(rows: list[dict]) -> dict[str, int]:
    """Bracket verdict counts of bracket.csv rows (or numbers rows with a ``bracket`` column)."""
    return {b: sum(r.get("bracket") == b for r in rows) for b in BRACKETS}
