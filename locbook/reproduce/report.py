"""What a notebook records: reproduced-versus-printed numbers, figures, tables and assumptions.

A notebook creates one :class:`Report` and calls :meth:`Report.number`, :meth:`Report.figure`,
:meth:`Report.table` and :meth:`Report.assumption`. Under ``locbook run`` the files go to the
experiment's staging folder (environment variable ``LOCBOOK_OUTPUT_DIR``); run interactively they go to
a scratch folder of the session (one per process) in the system's temporary directory, so exploring never touches
``reports/``.

Each number row compares one printed quantity (:class:`locbook.reproduce.Printed`, read from the document's
printed-values file) with our number, under the rules of :mod:`locbook.reproduce.scoring`: its ``kind``
(reproduction, calibrated, arithmetic, claim, shown), its window (printed rounding + 2 Monte-Carlo standard
errors + a named ambiguity) and its verdict (within, loose, miss). The columns are :data:`NUMBER_COLUMNS`.
"""
from __future__ import annotations

import csv
import json
import math
import os
import re
import tempfile
import time
from html import escape
from pathlib import Path

import numpy as np

from .printed_values import Printed
from .scoring import KINDS, Ambiguity, score

__all__ = ["Report", "NUMBER_COLUMNS", "Table", "markdown_text"]

NUMBER_COLUMNS = (
    "experiment", "document", "printed_id", "quantity", "where", "unit", "kind", "printed", "reproduced",
    "verdict", "window_low", "window_high", "rounding", "mc_std_error", "ambiguity", "ambiguity_basis",
    "relation", "calibrated_from", "same_as", "note",
)
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")
#: where Markdown starts raw HTML (CommonMark 0.31, "Raw HTML" and "Autolinks"): "<" before a letter (a tag, an
#: autolink), "/" (a closing tag), "!" (a comment, a declaration, CDATA) or "?" (a processing instruction)
_HTML_START = re.compile(r"<(?=[A-Za-z/!?])")


def markdown_text(text) -> str:
    """``text`` for a Markdown file, with every "<" that could open raw HTML written as ``&lt;`` (a viewer shows
    it as typed; a "<" before a space or a digit, as in ``N_eff < 0.5``, stays as it is)."""
    return _HTML_START.sub("&lt;", str(text))


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


#: LaTeX's special characters and what stands for each in text
_LATEX = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#", "_": r"\_", "{": r"\{",
          "}": r"\}", "~": r"\textasciitilde{}", "^": r"\textasciicircum{}"}


def _latex(text) -> str:
    """``text`` as LaTeX text: each special character escaped, a line break a space."""
    return "".join(_LATEX.get(ch, ch) for ch in " ".join(str(text).split("\n")))


def _is_number(text: str) -> bool:
    try:
        return math.isfinite(float(text))
    except ValueError:
        return False


class Table:
    """Rows of a table (list of dicts) that display as HTML in Jupyter and save as CSV and LaTeX."""

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
        """A Markdown table: "|" escaped, a newline a space, and HTML shown as text (:func:`markdown_text`)."""
        def cell(value) -> str:
            return markdown_text(value).replace("|", "\\|").replace("\r\n", " ").replace("\n", " ").replace("\r", " ")
        lines = ["| " + " | ".join(cell(c) for c in self.columns) + " |", "|" + "---|" * len(self.columns)]
        for r in self.rows:
            lines.append("| " + " | ".join(cell(_fmt(r.get(c, ""))) for c in self.columns) + " |")
        return "\n".join(lines)

    def to_latex(self) -> str:
        """A LaTeX ``tabular`` in booktabs style (``\\toprule``, ``\\midrule``, ``\\bottomrule``; the paper's preamble
        needs ``\\usepackage{booktabs}``): columns whose every value is a number right-aligned, the values as the CSV
        writes them, LaTeX's special characters escaped; the caption a comment line above it."""
        cells = [[_fmt(r.get(c, ""), 10) for c in self.columns] for r in self.rows]
        numeric = [bool(self.rows) and all(_is_number(row[i]) or row[i] == "" for row in cells)
                   for i in range(len(self.columns))]
        lines = [f"% {_latex(' '.join(self.caption.split()))}"] if self.caption else []
        lines += [f"\\begin{{tabular}}{{{''.join('r' if n else 'l' for n in numeric) or 'l'}}}", "\\toprule",
                  " & ".join(_latex(c) for c in self.columns) + " \\\\", "\\midrule"]
        lines += [" & ".join(_latex(v) for v in row) + " \\\\" for row in cells]
        return "\n".join(lines + ["\\bottomrule", "\\end{tabular}", ""])

    def write_latex(self, path: Path):
        Path(path).write_text(self.to_latex(), encoding="utf-8")

    def write_csv(self, path: Path):
        with open(path, "w", newline="", encoding="utf-8") as fh:    # as the runner reads it, whatever the locale
            writer = csv.DictWriter(fh, fieldnames=self.columns)
            writer.writeheader()
            for r in self.rows:
                writer.writerow({c: _fmt(r.get(c, ""), 10) for c in self.columns})

    def __repr__(self):
        return self.to_markdown()


def _user() -> str:
    import getpass
    try:
        name = getpass.getuser()
    except Exception:        # no user name in the environment or the password database
        name = str(os.getuid()) if hasattr(os, "getuid") else "user"
    return re.sub(r"[^A-Za-z0-9_.-]", "_", name)


#: this process's scratch folder (one Jupyter session, one kernel), made on its first Report
_SESSION_DIR: Path | None = None


def _session_dir() -> Path:
    """``<tmp>/locbook-interactive-<user>/session-<date>-<time>-<random>/``: made once per process, so two sessions
    (two kernels, two users) never write into each other's files, and a session's folders sort by their start."""
    global _SESSION_DIR
    if _SESSION_DIR is None or not _SESSION_DIR.is_dir():
        base = Path(tempfile.gettempdir()) / f"locbook-interactive-{_user()}"
        base.mkdir(parents=True, exist_ok=True)
        _SESSION_DIR = Path(tempfile.mkdtemp(prefix=time.strftime("session-%Y%m%d-%H%M%S-"), dir=base))
    return _SESSION_DIR


#: the vector formats every saved figure is also written in, with the metadata that keeps their bytes fixed (no
#: creation date)
FIGURE_EXPORTS = {"pdf": {"CreationDate": None}, "svg": {"Date": None}}


#: a figure whose data draw more vertices or markers than this has them drawn as an embedded image in the PDF and SVG
#: copies (its ticks and text stay vector): a map or a cloud of 10^5 points would otherwise make files of megabytes
DENSE_VERTICES = 3000
#: the resolution of those embedded images (dots per inch)
VECTOR_RASTER_DPI = 200


def _vertex_count(artist) -> int:
    """How many vertices or markers an artist draws (0 for one that is not data: text, spines, legends)."""
    from matplotlib.collections import Collection
    from matplotlib.lines import Line2D
    if isinstance(artist, Line2D):
        return len(artist.get_xydata())
    if isinstance(artist, Collection):
        offsets = len(artist.get_offsets()) if artist.get_offsets() is not None else 0
        vertices = sum(len(p.vertices) for p in artist.get_paths())
        return max(offsets, vertices)
    return 0


def _rasterize_dense(fig) -> None:
    """For the vector copies (the PNG is saved before): in a figure whose data artists draw more than
    :data:`DENSE_VERTICES` vertices or markers together (one cloud, or a small cloud in each of many panels), mark
    every data artist of more than 500 of them as rasterized; a sparse figure, and short lines, stay vector."""
    counts = [(artist, _vertex_count(artist)) for ax in fig.axes for artist in ax.get_children()]
    if sum(n for _a, n in counts) > DENSE_VERTICES:
        for artist, n in counts:
            if n > 500:
                artist.set_rasterized(True)


def _figures_on() -> bool:
    """False where the environment sets ``LOCBOOK_FIGURES=off`` (:meth:`Report.figure`)."""
    return os.environ.get("LOCBOOK_FIGURES", "").strip().lower() != "off"


def _show_saved_png(fig, png: Path, dpi: int) -> None:
    """Under ``locbook run`` (``LOCBOOK_OUTPUT_DIR`` set) in a kernel drawing with matplotlib's inline backend:
    show the PNG just saved as the cell's output and close the figure, so the inline backend does not draw it a
    second time (drawing is most of a light notebook's time). The page then shows the report's own file, at the
    size the inline backend would give it (``figure.dpi``). Anywhere else nothing is shown: an interactive session
    keeps its live figures."""
    if not os.environ.get("LOCBOOK_OUTPUT_DIR"):
        return
    import matplotlib
    if "inline" not in matplotlib.get_backend():
        return
    import matplotlib.pyplot as plt
    from IPython.display import Image, display
    data = png.read_bytes()
    width_px = int.from_bytes(data[16:20], "big")          # the IHDR chunk's width: PNG's first 8 + 8 bytes
    display(Image(data=data, format="png", width=max(1, round(width_px * fig.dpi / dpi))))
    plt.close(fig)


class Report:
    """Collects one experiment's outputs. ``experiment`` defaults to ``LOCBOOK_EXPERIMENT``."""

    def __init__(self, experiment: str | None = None):
        self.experiment = os.environ.get("LOCBOOK_EXPERIMENT") or experiment or "interactive"
        out = os.environ.get("LOCBOOK_OUTPUT_DIR")
        if out:
            self.output_dir = Path(out)
            # The runner makes this folder before it starts the notebook and removes it when the run stops or
            # gives the experiment up; a kernel still starting then must not make it again (a stopped run's
            # staging would outlive the run), so a missing folder is an error here, never created.
            if not self.output_dir.is_dir():
                raise FileNotFoundError(f"LOCBOOK_OUTPUT_DIR={out} is not an existing folder: under locbook run "
                                        "the run that made it has stopped and removed it; set it to an "
                                        "existing folder, or unset it to write to a scratch folder")
        else:
            # one scratch folder per session (process): no other session or user writes into it
            self.output_dir = _session_dir() / self.experiment
            self.output_dir.mkdir(parents=True, exist_ok=True)
        from ..plotting import use_house_style
        use_house_style()              # every report figure in one palette and one look
        self.numbers: list[dict] = []
        self.figures: list[dict] = []
        self.tables: list[dict] = []
        self.assumptions: list[dict] = []
        self._save_manifest()

    # -- numbers ---------------------------------------------------------------------------------
    def number(self, quantity: str, printed: Printed, reproduced=None, *, kind: str,
               mc_std_error: float | None = None, ambiguity: Ambiguity | None = None,
               relation: str | None = None, threshold: float | None = None, calibrated_from: str = "",
               same_as: Printed | None = None, note: str = "", miss_note: str = "",
               loose_note: str = "") -> dict:
        """Record our value of one printed quantity, with its kind, window and verdict.

        ``printed`` comes from the document's printed-values file (``lb.printed(document).get(...)``), never
        typed in. ``kind`` is one of ``reproduction``, ``calibrated``, ``arithmetic``, ``claim``, ``shown``
        (:mod:`locbook.reproduce.scoring`). ``mc_std_error`` is the Monte-Carlo standard error of ``reproduced``
        from run-level values; ``ambiguity`` names a protocol ambiguity, its size (in the unit) and source.
        A ``calibrated`` row says in ``calibrated_from`` which input was chosen from which printed number. A
        ``claim`` gives ``relation`` (``>``, ``>=``, ``<``, ``<=``) against the printed threshold. ``same_as``
        marks a quantity the source prints again: the row is kept for reading but compared (and counted)
        only at the printed quantity it names.

        The note is built here from the verdict, so that a notebook never computes a window: ``miss_note`` (the
        likely reason for a miss) is used only when the verdict is ``miss`` or ``inconsistent`` (outside printed +-
        (rounding + 2 SE + ambiguity); a claim that fails), ``loose_note`` only when it is ``loose`` (a window wider
        than +-25 %; a claim that holds for our value but not beyond 2 standard errors), after the automatic
        sentence that says why it is loose. ``note`` is always kept. The parts are joined by ``"; "``:
        ``[why loose]; [miss_note or loose_note]; [note]``.
        """
        if not isinstance(printed, Printed):
            raise TypeError("printed must be a locbook.reproduce.Printed from the document's printed-values file, "
                            f"got {type(printed).__name__}")
        if kind not in KINDS:
            raise ValueError(f"kind must be one of {KINDS}, got {kind!r}")
        if kind == "calibrated" and not calibrated_from.strip():
            raise ValueError("a calibrated row must say which input was chosen from which printed number "
                             "(calibrated_from)")
        if kind != "calibrated" and calibrated_from:
            raise ValueError("calibrated_from belongs to calibrated rows only")
        if same_as is not None and (same_as.document != printed.document or same_as.id == printed.id):
            raise ValueError("same_as must name another printed quantity of the same document")
        if kind == "shown" and reproduced is not None:
            raise ValueError("a shown row has nothing to compare; record our value with another kind")
        ours = None if reproduced is None else float(reproduced)
        s = score(kind, printed.text, ours, mc_std_error=mc_std_error, ambiguity=ambiguity,
                  relation=relation, threshold=threshold, linked=same_as is not None)
        reason = miss_note if s.verdict in ("miss", "inconsistent") else loose_note if s.verdict == "loose" else ""
        if reason:
            note = f"{reason}; {note}" if note else reason
        low = s.low
        if printed.unit == "m" and math.isfinite(low):
            low = max(low, 0.0)                      # distances and errors are not negative
        if s.verdict == "loose":                     # say why it is loose, before any other note
            part = {"rounding": s.rounding, "2 Monte-Carlo standard errors": s.half_width - s.rounding
                    - (ambiguity.size if ambiguity else 0.0)}
            if ambiguity:
                part[ambiguity.what] = ambiguity.size
            widest = max(part, key=part.get)
            why = (f"the window is +-{s.relative_half_width:.0%} of the printed value (more than +-25 %), "
                   f"mostly {widest}") if kind != "claim" else (
                   "the claim holds for our estimate but not beyond 2 Monte-Carlo standard errors")
            note = f"{why}; {note}" if note else why
        if same_as is not None and not note:
            note = f"the source prints this quantity again at {same_as.where}; compared there"
        row = {
            "experiment": self.experiment, "document": printed.document, "printed_id": printed.id,
            "quantity": quantity, "where": printed.where, "unit": printed.unit, "kind": kind,
            "printed": printed.text, "reproduced": ours, "verdict": s.verdict, "window_low": low,
            "window_high": s.high, "rounding": s.rounding, "mc_std_error": mc_std_error,
            "ambiguity": ambiguity.size if ambiguity else None,
            "ambiguity_basis": ambiguity.describe() if ambiguity else "", "relation": relation or "",
            "calibrated_from": calibrated_from, "same_as": same_as.id if same_as is not None else "",
            "note": note,
        }
        self.numbers.append(row)
        Table(self.numbers).write_csv(self.output_dir / "numbers.csv")
        self._save_manifest()
        return row

    def numbers_table(self) -> Table:
        """The recorded numbers, for display at the end of a notebook."""
        cols = ("quantity", "where", "unit", "kind", "printed", "reproduced", "window_low", "window_high",
                "verdict", "note")
        return Table([{c: r[c] for c in cols} for r in self.numbers], "Reproduced versus printed")

    def misses_table(self) -> Table:
        """The recorded rows judged ``miss``, ``loose`` or ``inconsistent``, each with its note (the likely
        reason), for display beside the full table."""
        rows = [{"where": r["where"], "kind": r["kind"], "printed": r["printed"], "reproduced": r["reproduced"],
                 "verdict": r["verdict"], "reason": r["note"]}
                for r in self.numbers if r["verdict"] in ("miss", "loose", "inconsistent")]
        return Table(rows, "Misses and loose agreements, with the likely reason")

    # -- figures, tables, assumptions -------------------------------------------------------------
    def figure(self, fig, name: str, caption: str = "", dpi: int = 110) -> Path:
        """Save a matplotlib figure as ``<name>.png``, and for a paper as ``<name>.pdf`` and ``<name>.svg`` (vector;
        every format's bytes equal between identical runs); the caption says what it reproduces. Under
        ``locbook run`` the cell shows that file and the figure is closed (drawn once, :func:`_show_saved_png`).
        Where the environment sets ``LOCBOOK_FIGURES=off`` (the points of ``locbook bracket``, whose numbers are all
        that is read of them) the figure is closed unsaved and the manifest lists its caption without a file."""
        self._check_name(name)
        path = self.output_dir / f"{name}.png"
        if _figures_on():
            # fixed metadata (and SVG's id salt) keep the bytes identical between identical runs
            fig.savefig(path, dpi=dpi, bbox_inches="tight", metadata={"Software": None})
            import matplotlib
            _rasterize_dense(fig)
            with matplotlib.rc_context({"svg.hashsalt": f"locbook-{name}"}):
                for fmt, metadata in FIGURE_EXPORTS.items():
                    fig.savefig(path.with_suffix(f".{fmt}"), dpi=VECTOR_RASTER_DPI, bbox_inches="tight",
                                metadata=metadata)
            _show_saved_png(fig, path, dpi)
        else:
            import matplotlib.pyplot as plt
            plt.close(fig)
        self.figures = [f for f in self.figures if f["name"] != name]
        entry = {"name": name, "file": path.name if _figures_on() else "", "caption": caption}
        if _figures_on():
            entry["exports"] = [f"{name}.{fmt}" for fmt in FIGURE_EXPORTS]
        self.figures.append(entry)
        self._save_manifest()
        return path

    def table(self, name: str, rows: list[dict], caption: str = "") -> Table:
        """Save rows (list of dicts) as ``<name>.csv`` and return them for display."""
        self._check_name(name)
        table = Table(rows, caption)
        table.write_csv(self.output_dir / f"{name}.csv")
        table.write_latex(self.output_dir / f"{name}.tex")
        self.tables = [t for t in self.tables if t["name"] != name]
        self.tables.append({"name": name, "file": f"{name}.csv", "caption": caption, "exports": [f"{name}.tex"]})
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
        if not _figures_on():
            manifest["figures_saved"] = False     # its figures list captions without files
        (self.output_dir / "manifest.json").write_text(json.dumps(manifest, indent=1), encoding="utf-8")
