"""What every report page shares: rendering a Jinja2 template of ``templates/``, links to files present, captions,
and the figures and tables of a report folder.

The lowest layer of the report pages: :mod:`locbook.suite.site` (the suite's pages) and
:mod:`locbook.suite.site_data` (a data set's page) both render through it.
"""
from __future__ import annotations

import functools
import math
import re
from collections import Counter
from pathlib import Path

from ..reproduce.report import markdown_text
from ..reproduce.scoring import BRACKETS, VERDICT_COLUMNS, scoreboard_counts, verdict_column
from .files import read_csv
from .spec import finite_float

__all__ = ["render", "caption_md", "number_text", "first_file", "md_captions", "page_outputs", "verdict_shares",
           "verdict_chips", "bracket_chips", "experiment_line", "index_entry"]


def caption_md(text: str) -> str:
    """A caption on one line of Markdown (a newline would end the image or the list item), HTML shown as text."""
    return markdown_text(" ".join(str(text).split("\n")))


_TEMPLATES = Path(__file__).with_name("templates")


#: verdicts whose cells are coloured (site.css, ``.v-<verdict>``); "no verdict" and "linked" stay plain
_COLORED = ("within", "loose", "miss", "consistent", "inconsistent", "default", "other_interpretation", "fitted_only",
            "between", "open", "outside")


#: the formats a figure or table is also saved in (:meth:`locbook.reproduce.report.Report.figure` and ``table``)
EXPORT_SUFFIXES = ("pdf", "svg", "tex")


#: a table a notebook saved is shown inline up to this many rows (longer ones: the link to the CSV file)
_INLINE_TABLE_ROWS = 200


@functools.lru_cache(maxsize=1)
def _environment():
    from jinja2 import Environment, FileSystemLoader, StrictUndefined
    env = Environment(loader=FileSystemLoader(str(_TEMPLATES)), autoescape=True, undefined=StrictUndefined,
                      trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True)
    env.globals["colored"] = _COLORED
    return env


def render(template: str, **context) -> str:
    return _environment().get_template(template).render(**context)


def number_text(value, digits: int) -> str:
    try:
        x = float(value)
    except (TypeError, ValueError):
        return "" if value is None else str(value)
    return f"{x:.{digits}g}" if math.isfinite(x) else str(value)


def first_file(folder: Path, *names: str) -> str | None:
    """The first of ``names`` (paths relative to ``folder``) that is a file, as a link; ``None`` if none is."""
    return next((name for name in names if (folder / name).is_file()), None)


def md_captions(folder: Path) -> dict[str, str]:
    """Captions of figures and tables as report.md states them (for a folder without its manifest)."""
    try:
        text = (folder / "report.md").read_text(encoding="utf-8")
    except OSError:
        return {}
    out = {f: c for c, f in re.findall(r"^!\[(.*)\]\(([^)\s]+)\)\s*$", text, re.M)}
    out.update({f: c for f, c in re.findall(r"^- \[[^\]]*\]\(([^)\s]+)\): (.*)$", text, re.M)})
    # report.md writes "<" as "&lt;" where it could open HTML (markdown_text); the HTML page escapes it itself
    return {f: c.replace("&lt;", "<") for f, c in out.items()}


def page_outputs(folder: Path, manifest: dict) -> tuple[list[dict], list[dict]]:
    """Figures and tables of the page, each a file present in ``folder``. From manifest.json; a folder
    without one (committed reports: the manifest is not committed) shows the PNG and CSV files it holds."""
    if (folder / "manifest.json").is_file():
        figures = [dict(f) for f in manifest.get("figures", [])]
        tables = [dict(t) for t in manifest.get("tables", [])]
    else:
        captions = md_captions(folder)
        order = list(captions)            # the order report.md shows them in, then the others by name
        figures = [{"name": p.stem, "file": p.name, "caption": captions.get(p.name, "")}
                   for p in sorted(folder.glob("*.png"),
                                   key=lambda p: (order.index(p.name) if p.name in order else len(order), p.name))]
        tables = [{"name": p.stem, "file": p.name, "caption": captions.get(p.name, "")}
                  for p in sorted(folder.glob("*.csv")) if p.name not in ("numbers.csv", "assumptions.csv")]
    figures = [f for f in figures if f.get("file") and (folder / f["file"]).is_file()]
    tables = [t for t in tables if t.get("file") and (folder / t["file"]).is_file()]
    for item in figures + tables:
        item.setdefault("name", Path(item["file"]).stem)
        item["caption"] = item.get("caption") or ""
        # the copies for a paper (PDF, SVG, LaTeX) present beside it, whatever the manifest lists
        item["exports"] = [f"{item['name']}.{ext}" for ext in EXPORT_SUFFIXES
                           if (folder / f"{item['name']}.{ext}").is_file()]
    for t in tables:
        rows = read_csv(folder / t["file"])
        t["columns"] = list(dict.fromkeys(k for r in rows for k in r if k is not None))
        t["rows"] = ([{c: r.get(c) or "" for c in t["columns"]} for r in rows]
                     if len(rows) <= _INLINE_TABLE_ROWS else [])
        t["too_long"] = len(rows) if len(rows) > _INLINE_TABLE_ROWS else 0
    return figures, tables


_SHADE = {"within": "var(--within)", "consistent": "var(--within)", "loose": "var(--loose)", "miss": "var(--miss)",
          "inconsistent": "var(--miss)"}          # site.css's verdict colours


def verdict_shares(counter: Counter) -> str:
    """A CSS background for a cell counting within / loose / miss: a bar whose bands are each verdict's share of the
    rows (120 within and 15 missed is mostly green, not red); '' for no rows."""
    parts = [(v, counter[v]) for v in ("within", "consistent", "loose", "miss", "inconsistent") if counter[v]]
    total = sum(n for _, n in parts)
    if not total:
        return ""
    stops, at = [], 0.0
    for v, n in parts:
        end = at + 100.0 * n / total
        stops.append(f"{_SHADE[v]} {at:.1f}% {end:.1f}%")
        at = end
    return f"background: linear-gradient(to right, {', '.join(stops)})"


def experiment_line(e) -> dict:
    rows = e["numbers"]
    rep = Counter(r["verdict"] for r in rows if r["kind"] == "reproduction" and not r.get("same_as"))
    cal = Counter(r["verdict"] for r in rows if r["kind"] == "calibrated" and not r.get("same_as"))
    fmt = lambda c: f"{c['within']} / {c['loose']} / {c['miss']}" if sum(c.values()) else "-"
    return {"reproductions within / loose / miss": fmt(rep), "calibrated within / loose / miss": fmt(cal),
            "other rows": sum(1 for r in rows if r["kind"] not in ("reproduction", "calibrated") or r.get("same_as"))}


def index_entry(report_dir: Path, e) -> dict:
    exp, last, present = e["exp"], e["last"], e["present"]
    folder = report_dir / exp.id
    state = last.get("status") or ("ok" if present else "not run")
    if not present and state in ("ok", "cached"):
        state = "not run"                      # recorded as run, but its folder is gone
    flagged = state in ("failed", "interrupted")
    seconds = finite_float(last.get("seconds")) if state in ("ok", "failed", "interrupted") else None
    if not seconds and present:
        seconds = finite_float(e["report"].get("seconds")) or finite_float(e["run"].get("seconds"))
    links = []
    if present:
        for label, names in (("report", ("report.html",)), ("notebook", (f"{exp.id}.html", f"{exp.id}.ipynb")),
                             ("summary", ("summary.md",)), ("numbers", ("numbers.csv",))):
            name = first_file(folder, *names)
            if name:
                links.append((label, f"{exp.id}/{name}"))
    if state == "failed":
        name = first_file(report_dir / ".failed" / exp.id, f"{exp.id}.html", f"{exp.id}.ipynb")
        if name:
            links.append(("failed notebook", f".failed/{exp.id}/{name}"))
    rows = e["numbers"]
    counts = scoreboard_counts(rows)
    line = experiment_line(e)
    doc = exp.document
    return {"id": exp.id, "title": exp.title, "section": exp.section, "doc_key": doc.key,
            "doc_authors": doc.authors, "doc_year": doc.year, "profile": e["report"].get("profile", ""),
            "page": f"{exp.id}/report.html" if present and (folder / "report.html").is_file() else None,
            "reproductions": line["reproductions within / loose / miss"],
            "rep_shares": verdict_shares(counts.get("reproduction", Counter())),
            "calibrated": line["calibrated within / loose / miss"],
            "cal_shares": verdict_shares(counts.get("calibrated", Counter())),
            "other": line["other rows"], "chips": verdict_chips(rows), "bracket_chips": bracket_chips(rows),
            "state": state, "flagged": flagged, "shown_last_good": flagged and present,
            "error": last.get("error", ""), "time": f"{float(seconds):.1f} s" if seconds else "-",
            "stamp": e["report"].get("locbook", ""), "links": links}


def verdict_chips(rows) -> list[tuple[str, int]]:
    c = Counter(verdict_column(r) for r in rows)
    return [(v, c[v]) for v in VERDICT_COLUMNS if c[v]]


def bracket_chips(rows) -> list[tuple[str, int]]:
    """Bracket verdict counts of an experiment's rows (none when it was not bracketed)."""
    c = Counter(r.get("bracket", "") for r in rows)
    return [(b, c[b]) for b in BRACKETS if c[b]]
