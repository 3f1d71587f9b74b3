"""What a notebook records: reproduced-versus-printed numbers, figures, tables and assumptions.

A notebook creates one :class:`Report` and calls :meth:`Report.number`, :meth:`Report.figure`,
:meth:`Report.table` and :meth:`Report.assumption`. Under ``locbook run`` the files go to the
experiment's staging folder (environment variable ``LOCBOOK_OUTPUT_DIR``); run interactively they go to
a scratch folder in the system's temporary directory, so exploring never touches ``reports/``.

Each number row carries the columns of ``numbers.csv``:
``experiment, quantity, where, unit, reported, reproduced, tolerance, lower, upper, within_tolerance,
mc_std_error, tolerance_basis, note``. The tolerance is either symmetric (``tolerance``) or an
acceptance interval (``lower``, ``upper``); its basis (Monte-Carlo standard error, a stated ambiguity)
is written beside it.
"""
from __future__ import annotations

import csv
import json
import math
import os
import re
import tempfile
from html import escape
from pathlib import Path

import numpy as np

__all__ = ["Report", "NUMBER_COLUMNS", "Table"]

NUMBER_COLUMNS = (
    "experiment", "quantity", "where", "unit", "reported", "reproduced", "tolerance", "lower", "upper",
    "within_tolerance", "mc_std_error", "tolerance_basis", "note",
)
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


def _fmt(value, digits=4):
    if value is None or value == "":
        return ""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return "" if not math.isfinite(value) else f"{float(value):.{digits}g}"
    return str(value)


class Table:
    """Rows of a table (list of dicts) that display as HTML in Jupyter and save as CSV."""

    def __init__(self, rows: list[dict], caption: str = ""):
        self.rows = [dict(r) for r in rows]
        self.caption = caption
        self.columns = list(dict.fromkeys(k for r in self.rows for k in r))

    def _repr_html_(self):
        head = "".join(f"<th>{escape(c)}</th>" for c in self.columns)
        body = "".join(
            "<tr>" + "".join(f"<td>{escape(_fmt(r.get(c, '')))}</td>" for c in self.columns) + "</tr>"
            for r in self.rows
        )
        cap = f"<caption>{escape(self.caption)}</caption>" if self.caption else ""
        return f"<table>{cap}<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"

    def to_markdown(self) -> str:
        lines = ["| " + " | ".join(self.columns) + " |", "|" + "---|" * len(self.columns)]
        for r in self.rows:
            lines.append("| " + " | ".join(_fmt(r.get(c, "")).replace("|", "\\|") for c in self.columns) + " |")
        return "\n".join(lines)

    def write_csv(self, path: Path):
        with open(path, "w", newline="") as fh:
            writer = csv.DictWriter(fh, fieldnames=self.columns)
            writer.writeheader()
            for r in self.rows:
                writer.writerow({c: _fmt(r.get(c, ""), 10) for c in self.columns})

    def __repr__(self):
        return self.to_markdown()


class Report:
    """Collects one experiment's outputs. ``experiment`` defaults to ``LOCBOOK_EXPERIMENT``."""

    def __init__(self, experiment: str | None = None):
        self.experiment = os.environ.get("LOCBOOK_EXPERIMENT") or experiment or "interactive"
        out = os.environ.get("LOCBOOK_OUTPUT_DIR")
        if out:
            self.output_dir = Path(out)
        else:
            self.output_dir = Path(tempfile.gettempdir()) / "locbook-interactive" / self.experiment
        self.output_dir.mkdir(parents=True, exist_ok=True)
        self.numbers: list[dict] = []
        self.figures: list[dict] = []
        self.tables: list[dict] = []
        self.assumptions: list[dict] = []
        self._save_manifest()

    # -- numbers ---------------------------------------------------------------------------------
    def number(self, quantity: str, where: str, reported, reproduced, *, unit: str = "",
               tolerance: float | None = None, lower: float | None = None, upper: float | None = None,
               tolerance_basis: str = "", mc_std_error: float | None = None, note: str = "",
               interval_holds: str = "reproduced") -> dict:
        """Record a reproduced value beside the value the source printed.

        Give either ``tolerance`` (accept ``|reproduced - reported| <= tolerance``) or an acceptance
        interval ``lower``/``upper``; ``tolerance_basis`` says where it comes from. With none of them the
        row is shown without a verdict (``within_tolerance`` empty).

        ``interval_holds="reported"`` turns ``lower``/``upper`` into a prediction interval from the reproduction
        (e.g. the spread of single simulated runs, when the source printed one measured run): the verdict is
        then whether the *printed* value lies inside it.
        """
        if interval_holds not in ("reproduced", "reported"):
            raise ValueError(f"interval_holds must be 'reproduced' or 'reported', got {interval_holds!r}")
        if interval_holds == "reported" and (tolerance is not None or reported is None):
            raise ValueError("a prediction interval needs lower/upper and a reported value, not a tolerance")
        reproduced = float(reproduced)
        reported = float(reported) if reported is not None else None
        if tolerance is not None and (lower is not None or upper is not None):
            raise ValueError("give either a symmetric tolerance or an interval (lower, upper), not both")
        if tolerance is not None:
            if tolerance < 0 or reported is None:
                raise ValueError("a symmetric tolerance needs a reported value and tolerance >= 0")
            lower, upper = reported - tolerance, reported + tolerance
        verdict = ""
        if lower is not None or upper is not None:
            lo = -math.inf if lower is None else float(lower)
            hi = math.inf if upper is None else float(upper)
            tested = reproduced if interval_holds == "reproduced" else float(reported)
            verdict = bool(lo <= tested <= hi)
        row = {
            "experiment": self.experiment, "quantity": quantity, "where": where, "unit": unit,
            "reported": reported, "reproduced": reproduced, "tolerance": tolerance,
            "lower": lower, "upper": upper, "within_tolerance": verdict,
            "mc_std_error": mc_std_error, "tolerance_basis": tolerance_basis, "note": note,
        }
        self.numbers.append(row)
        Table(self.numbers).write_csv(self.output_dir / "numbers.csv")
        self._save_manifest()
        return row

    def numbers_table(self) -> Table:
        """The recorded numbers, for display at the end of a notebook."""
        cols = ("quantity", "where", "unit", "reported", "reproduced", "lower", "upper",
                "within_tolerance", "mc_std_error", "tolerance_basis")
        return Table([{c: r[c] for c in cols} for r in self.numbers], "Reproduced versus printed")

    # -- figures, tables, assumptions -------------------------------------------------------------
    def figure(self, fig, name: str, caption: str = "", dpi: int = 110) -> Path:
        """Save a matplotlib figure as ``<name>.png``; the caption says what it reproduces."""
        self._check_name(name)
        path = self.output_dir / f"{name}.png"
        # fixed metadata keeps PNG bytes identical between identical runs
        fig.savefig(path, dpi=dpi, bbox_inches="tight", metadata={"Software": None})
        self.figures = [f for f in self.figures if f["name"] != name]
        self.figures.append({"name": name, "file": path.name, "caption": caption})
        self._save_manifest()
        return path

    def table(self, name: str, rows: list[dict], caption: str = "") -> Table:
        """Save rows (list of dicts) as ``<name>.csv`` and return them for display."""
        self._check_name(name)
        table = Table(rows, caption)
        table.write_csv(self.output_dir / f"{name}.csv")
        self.tables = [t for t in self.tables if t["name"] != name]
        self.tables.append({"name": name, "file": f"{name}.csv", "caption": caption})
        self._save_manifest()
        return table

    def assumption(self, name: str, value, reason: str) -> None:
        """Record an assumed value (a parameter the source never printed) and why it was chosen."""
        self.assumptions = [a for a in self.assumptions if a["name"] != name]
        self.assumptions.append({"name": name, "value": value if isinstance(value, (int, float, str, bool))
                                 else json.dumps(value), "reason": reason})
        Table(self.assumptions).write_csv(self.output_dir / "assumptions.csv")
        self._save_manifest()

    def assumptions_table(self) -> Table:
        return Table(self.assumptions, "Assumptions (values the source does not print)")

    @staticmethod
    def _check_name(name):
        if not _NAME.match(name):
            raise ValueError(f"output name {name!r} must be letters, digits, '_', '-' or '.'")

    def _save_manifest(self):
        manifest = {"experiment": self.experiment, "figures": self.figures, "tables": self.tables,
                    "n_numbers": len(self.numbers), "n_assumptions": len(self.assumptions)}
        (self.output_dir / "manifest.json").write_text(json.dumps(manifest, indent=1))
