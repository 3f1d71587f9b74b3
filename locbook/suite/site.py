"""The reports a reader opens: per-experiment summary and page, and the suite's index (Markdown and HTML).

- ``<id>/summary.md`` fits on a screen: what the experiment reproduces, its scoreboard (rows by kind, columns
  by verdict) and the reasons behind its misses and loose rows;
- ``<id>/report.md`` (and ``report.html``) is the whole page: every number row with its window and note, the
  parameters, the assumptions, the figures and tables;
- ``index.md`` / ``index.html`` open with a kind-by-verdict table per document and in total, headline the
  independent reproductions only, list the experiments, and gather the reasons behind every miss and loose row;
- a data run's folder (``data-<name>/``, holding ``dataset.json``) gets a page of its own instead
  (:func:`data_index_markdown`, :func:`data_index_html`): the data set's title, attribution and licence from its
  manifest, then every method's errors beside its bound (the ``results.csv`` tables), the figures, the channel fits
  and the bookkeeping, without the scoreboard's vocabulary (a data set has no printed number to compare with).

Printed values are shown exactly as printed (the text of the printed-values file). Every table is built from
``numbers.csv`` rows, so a partial run shows the rows of the folders present.

The HTML pages render from the Jinja2 templates in ``templates/`` (autoescaped; ``base.html`` inlines the one
stylesheet, ``site.css``, so that a page opened from file:// needs nothing beside it). Cells are coloured by
verdict, never by how a run went (the run status is text). A page links only to files present in its folder
(the executed notebook as HTML, else as .ipynb; figures and tables of the manifest), so the site has no broken
link; tests/test_site_browser.py opens it in headless Chromium to check that.
"""
from __future__ import annotations

import functools
import html
import json
import math
import re
from collections import Counter, defaultdict
from pathlib import Path

from ..reproduce.printed_values import printed_number
from ..reproduce.report import Table, markdown_text
from ..reproduce.scoring import (BRACKETS, JUDGED_KINDS, KINDS, SCORED_VERDICTS, VERDICT_COLUMNS,
                                 scoreboard_counts, verdict_column)
from .findings import md_cell
from .spec import finite_float

__all__ = ["VERDICT_COLUMNS", "scoreboard_counts", "summary_markdown", "page_markdown", "page_html",
           "index_markdown", "index_html", "double_counted", "dataset_record", "data_page", "data_index_markdown",
           "data_index_html", "dataset_sections"]

def double_counted(rows) -> list[tuple[str, str, list[str]]]:
    """Printed quantities that carry a verdict in more than one row: ``(document, printed_id, experiments)``.
    Each printed quantity must be compared once (repeats use ``same_as``)."""
    seen = defaultdict(list)
    for r in rows:
        if r.get("verdict") and not r.get("same_as"):
            seen[(r["document"], r["printed_id"])].append(r["experiment"])
    return [(d, p, e) for (d, p), e in seen.items() if len(e) > 1]


def _counts_rows(counts: dict[str, Counter]) -> list[dict]:
    used = [v for v in VERDICT_COLUMNS if any(c[v] for c in counts.values())]
    rows = []
    total = Counter()
    for kind, c in counts.items():
        rows.append({"kind": kind, **{v: c[v] for v in used}, "rows": sum(c.values())})
        total.update(c)
    rows.append({"kind": "all", **{v: total[v] for v in used}, "rows": sum(total.values())})
    return rows


def _headline(rows) -> str:
    rep = Counter(r["verdict"] for r in rows if r.get("kind") == "reproduction" and not r.get("same_as"))
    n = sum(rep.values())
    if not n:
        return "No independent reproduction is scored here."
    return (f"**Independent reproductions: {rep['within']} within, {rep['loose']} loose, {rep['miss']} missed, "
            f"of {n}** (each printed quantity counted once; calibrated rows, arithmetic checks and claims are "
            "counted apart below).")


def _bracket_counts(rows) -> dict | None:
    """The tier tally of the scored rows (:func:`locbook.suite.findings.tier_counts`)."""
    from .findings import tier_counts
    return tier_counts(rows)


def _profile_of(report_dir: Path) -> str:
    """The profile whose reports a folder holds (``reports/quick``; ``reports/full/data-x`` is the full profile's),
    '' for another folder (a ``-p`` run's, ``--out``)."""
    from .spec import PROFILES
    folder = Path(report_dir)
    return next((f.name for f in (folder, folder.parent) if f.name in PROFILES), "")


def _bracket_headline(rows, profile: str = "full") -> str:
    from .findings import bracket_headline
    return bracket_headline(rows, profile)


def _findings(report_dir: Path) -> list[tuple[str, str]]:
    """(document, relative link) of every findings page of this reports folder."""
    from .findings import findings_links
    return findings_links(report_dir)


def _reasons(rows) -> list[dict]:
    """Misses and loose rows grouped by their note (the likely reason)."""
    groups: dict[tuple, list] = defaultdict(list)
    for r in rows:
        if r.get("verdict") in ("miss", "loose", "inconsistent") and not r.get("same_as"):
            groups[(r["experiment"], r["verdict"], r.get("note") or "(no note)")].append(r)
    out = []
    for (exp, verdict, note), members in groups.items():
        where = "; ".join(m["where"] for m in members[:3]) + (f"; and {len(members) - 3} more" if len(members) > 3 else "")
        out.append({"experiment": exp, "verdict": verdict, "rows": len(members), "reason": note, "where": where})
    order = {"miss": 0, "inconsistent": 1, "loose": 2}
    return sorted(out, key=lambda g: (g["experiment"], order[g["verdict"]], -g["rows"]))


def _short(note: str, limit: int = 160) -> str:
    """A note's first sentence (or clause), at most ``limit`` characters."""
    first = re.split(r"(?<=[.;])\s", note.strip(), maxsplit=1)[0].rstrip(".;")
    return first if len(first) <= limit else first[:limit].rsplit(" ", 1)[0] + " ..."


def _plural(n: int, noun: str) -> str:
    return f"{n} {noun}{'' if n == 1 else 's'}"


def findings_summary(entries, rows) -> list[dict]:
    """A few sentences per document, generated from its rows (issue 32): what is reproduced, what is only
    calibrated, what misses and the likely reasons of the most missed rows (their notes, the most frequent first).
    ``[{"key", "authors", "year", "text"}]`` for the documents with scored rows."""
    out = []
    for key, doc, doc_rows in _by_document(entries, rows):
        counts = scoreboard_counts(doc_rows)             # per kind; repeats of another row in their own column
        rep, cal, claims = (counts.get(k, Counter()) for k in ("reproduction", "calibrated", "claim"))
        n_rep, n_cal, n_claims = (sum(v for c, v in k.items() if c != "linked") for k in (rep, cal, claims))
        if not (n_rep or n_cal or n_claims):
            continue
        parts = []
        if n_rep:
            parts.append(f"Of {_plural(n_rep, 'printed number')} reproduced independently, {rep['within']} "
                         f"{'is' if rep['within'] == 1 else 'are'} within {'its' if n_rep == 1 else 'their'} window, "
                         f"{rep['loose']} loose (a window too wide to decide) and {rep['miss']} missed.")
        if n_cal:
            parts.append(f"{n_cal}{' more' if n_rep else ''} {'is' if n_cal == 1 else 'are'} calibrated (an input "
                         f"chosen from a printed number, so agreement shows consistency only): {cal['within']} "
                         f"within, {cal['loose']} loose, {cal['miss']} missed.")
        if n_claims:
            parts.append(f"Of {_plural(n_claims, 'printed claim')}, {claims['within']} "
                         f"{'holds' if claims['within'] == 1 else 'hold'} beyond two standard errors, "
                         f"{claims['loose']} only for our estimate and {claims['miss']} "
                         f"{'does' if claims['miss'] == 1 else 'do'} not.")
        missed = Counter(_short(r.get("note") or "") for r in doc_rows if not r.get("same_as")
                         if r.get("verdict") == "miss" and r.get("kind") in ("reproduction", "calibrated", "claim")
                         and (r.get("note") or "").strip())
        if missed:
            reasons = [f"{why} ({_plural(n, 'row')})" for why, n in missed.most_common(2)]
            parts.append("The likely reasons of most misses: " + "; ".join(reasons) + ".")
        out.append({"key": key, "authors": doc.authors, "year": doc.year, "text": " ".join(parts)})
    return out


# -- one experiment ------------------------------------------------------------------------------------------

def _header(exp, profile: str, stamp: str, dataset: dict | None = None) -> list[str]:
    doc = exp.document
    if dataset:         # a data run: the data set's own title and attribution, not the document's
        about = (f"Experiment `{exp.id}` on the data set *{md_cell(dataset_title(dataset))}*: {md_cell(exp.section)}. "
                 f"{md_cell(dataset_credit(dataset))}")
    else:
        about = f"Experiment `{exp.id}`, reproducing **{exp.section}** of {doc.authors}, *{doc.title}* ({doc.year})."
    return [f"# {exp.title}", "", about, "",
            f"Profile `{profile}`; generated by locbook {stamp}. Notebook: `notebooks/"
            f"{exp.notebook.relative_to(exp.notebook.parents[1]).as_posix()}`.", ""]


def summary_markdown(exp, profile: str, numbers: list[dict], stamp: str, dataset: dict | None = None) -> str:
    """``<id>/summary.md``. ``dataset``: the record of the data set a data run's folder holds
    (:func:`dataset_record`), whose title and attribution the page names; None for the suite's own reports."""
    lines = _header(exp, profile, stamp, dataset)
    if dataset and not numbers:
        lines += ["Results, parameters, settings, figures and tables: [report.md](report.md); every method on this "
                  "data set: [the data set's page](../index.md).", ""]
        return "\n".join(lines)
    if numbers:
        lines += ["## Scoreboard", "", _headline(numbers), "",
                  Table(_counts_rows(scoreboard_counts(numbers))).to_markdown(), ""]
        reasons = _reasons(numbers)
        if reasons:
            lines += ["## Misses and loose rows, by reason", "",
                      Table([{k: g[k] for k in ("verdict", "rows", "reason", "where")} for g in reasons]).to_markdown(), ""]
    else:
        lines += ["The source prints no number for this experiment; its figures are qualitative.", ""]
    lines += ["Every row with its window and note, the parameters, assumptions and figures: [report.md](report.md).", ""]
    return "\n".join(lines)


_PAGE_COLUMNS = ("quantity", "where", "unit", "kind", "printed", "reproduced", "window_low", "window_high", "verdict",
                 "ambiguity_basis", "calibrated_from", "same_as", "note")


def _page_columns(numbers: list[dict]) -> tuple[str, ...]:
    """The page's columns: the bracket verdict and its readings after the verdict when a bracket was run."""
    if not any(r.get("bracket") for r in numbers):
        return _PAGE_COLUMNS
    at = _PAGE_COLUMNS.index("verdict") + 1
    return (*_PAGE_COLUMNS[:at], "bracket", "bracket_readings", *_PAGE_COLUMNS[at:])


def _set_by(exp, name: str, params: dict, dataset: dict | None) -> str:
    """Who set a parameter, for a page's parameters table: the notebook's default, a data run (``data`` from
    ``--data``; a value of ``[experiment.data_run] parameters``, unless ``-p`` gave another), or the profile / ``-p``."""
    if name not in params:
        return "notebook default"
    if dataset:
        run = exp.data_run.parameters if exp.data_run is not None else {}
        if name == "data":
            return "--data"
        if name in ("methods", "trackers"):
            return "--method" if name == "methods" else "--tracker"
        if name in run and params[name] == run[name]:
            return "data run ([experiment.data_run])"
    return "profile / -p"


def _page_parts(exp, params: dict, folder: Path, numbers: list[dict], dataset: dict | None = None):
    manifest = _read_json(folder / "manifest.json", {"figures": [], "tables": []})
    assumptions = _read_csv(folder / "assumptions.csv")
    declared = exp.declared_parameters()
    parameters = [{"name": name, "value": json.dumps(params.get(name, p.default)),
                   "set by": _set_by(exp, name, params, dataset), "meaning": p.help}
                  for name, p in declared.items()]
    shown = [{c: r.get(c, "") for c in _page_columns(numbers)} for r in numbers]
    for row in shown:
        if row["reproduced"] not in ("", None):
            row["reproduced"] = f"{float(row['reproduced']):.4g}"
    return shown, parameters, assumptions, manifest


def _caption_md(text: str) -> str:
    """A caption on one line of Markdown (a newline would end the image or the list item), HTML shown as text."""
    return markdown_text(" ".join(str(text).split("\n")))


def page_markdown(exp, profile: str, params: dict, folder: Path, numbers: list[dict], stamp: str,
                  dataset: dict | None = None) -> str:
    """``<id>/report.md``; ``dataset`` as for :func:`summary_markdown` (a data run's page compares no printed
    number: that section is left out when it has none)."""
    shown, parameters, assumptions, manifest = _page_parts(exp, params, folder, numbers, dataset)
    lines = _header(exp, profile, stamp, dataset) + ["[Summary](summary.md).", ""]
    if shown or not dataset:
        lines += ["## Reproduced versus printed", ""]
        lines += [Table(shown).to_markdown() if shown else "No printed number is compared here.", ""]
    # a -p value is any text the user typed: escaped, so a Markdown viewer shows it instead of rendering it as HTML
    escaped = [{**p, "value": html.escape(p["value"], quote=False)} for p in parameters]
    lines += ["## Parameters", "", Table(escaped).to_markdown(), ""]
    if assumptions:
        lines += ["## Assumptions", "", Table(assumptions).to_markdown(), ""]
    # captions are the notebook's text, often built from -p strings: shown as text, never rendered as HTML
    if manifest.get("figures"):
        lines += ["## Figures", ""]
        for fig in manifest["figures"]:
            caption = _caption_md(fig.get("caption") or "")
            if not fig.get("file"):     # a bracket point: figures are not drawn
                lines += [f"*{caption or _caption_md(fig['name'])}* (not drawn: a bracket point)", ""]
                continue
            lines += [f"![{caption or fig['name']}]({fig['file']})", "", f"*{caption}*", ""]
    if manifest.get("tables"):
        lines += ["## Tables", ""]
        lines += [f"- [{t['file']}]({t['file']}): {_caption_md(t.get('caption') or '')}" for t in manifest["tables"]]
        lines.append("")
    return "\n".join(lines)


# -- HTML: rendered from the Jinja2 templates in templates/ (one stylesheet, site.css, inlined in every page so
# that each page works on its own from file://); every href and src names a file that exists ----------------

_TEMPLATES = Path(__file__).with_name("templates")
#: verdicts whose cells are coloured (site.css, ``.v-<verdict>``); "no verdict" and "linked" stay plain
_COLORED = ("within", "loose", "miss", "consistent", "inconsistent", "default", "other_reading", "fitted_only",
            "between", "open", "outside")
#: a table a notebook saved is shown inline up to this many rows (longer ones: the link to the CSV file)
_INLINE_TABLE_ROWS = 200


@functools.lru_cache(maxsize=1)
def _environment():
    from jinja2 import Environment, FileSystemLoader, StrictUndefined
    env = Environment(loader=FileSystemLoader(str(_TEMPLATES)), autoescape=True, undefined=StrictUndefined,
                      trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True)
    env.globals["colored"] = _COLORED
    return env


def _render(template: str, **context) -> str:
    return _environment().get_template(template).render(**context)


def _counts_table(counts: dict[str, Counter]) -> dict:
    """A kind-by-verdict table for the ``counts_table`` macro: its verdict columns and its rows."""
    rows = _counts_rows(counts)
    return {"columns": [c for c in rows[0] if c not in ("kind", "rows")], "rows": rows}


def _headline_counts(rows) -> dict:
    rep = Counter(r["verdict"] for r in rows if r.get("kind") == "reproduction" and not r.get("same_as"))
    return {"within": rep["within"], "loose": rep["loose"], "miss": rep["miss"], "n": sum(rep.values())}


_SHADE = {"within": "var(--within)", "consistent": "var(--within)", "loose": "var(--loose)", "miss": "var(--miss)",
          "inconsistent": "var(--miss)"}          # site.css's verdict colours


def _shares(counter: Counter) -> str:
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


def _chips(rows) -> list[tuple[str, int]]:
    c = Counter(verdict_column(r) for r in rows)
    return [(v, c[v]) for v in VERDICT_COLUMNS if c[v]]


def _bracket_chips(rows) -> list[tuple[str, int]]:
    """Bracket verdict counts of an experiment's rows (none when it was not bracketed)."""
    c = Counter(r.get("bracket", "") for r in rows)
    return [(b, c[b]) for b in BRACKETS if c[b]]


def _number(value, digits: int) -> str:
    try:
        x = float(value)
    except (TypeError, ValueError):
        return "" if value is None else str(value)
    return f"{x:.{digits}g}" if math.isfinite(x) else str(value)


def _rel(folder: Path, *names: str) -> str | None:
    """The first of ``names`` (paths relative to ``folder``) that is a file, as a link; ``None`` if none is."""
    return next((name for name in names if (folder / name).is_file()), None)


def _md_captions(folder: Path) -> dict[str, str]:
    """Captions of figures and tables as report.md states them (for a folder without its manifest)."""
    try:
        text = (folder / "report.md").read_text(encoding="utf-8")
    except OSError:
        return {}
    out = {f: c for c, f in re.findall(r"^!\[(.*)\]\(([^)\s]+)\)\s*$", text, re.M)}
    out.update({f: c for f, c in re.findall(r"^- \[[^\]]*\]\(([^)\s]+)\): (.*)$", text, re.M)})
    # report.md writes "<" as "&lt;" where it could open HTML (markdown_text); the HTML page escapes it itself
    return {f: c.replace("&lt;", "<") for f, c in out.items()}


def _page_outputs(folder: Path, manifest: dict) -> tuple[list[dict], list[dict]]:
    """Figures and tables of the page, each a file present in ``folder``. From manifest.json; a folder
    without one (committed reports: the manifest is not committed) shows the PNG and CSV files it holds."""
    if (folder / "manifest.json").is_file():
        figures = [dict(f) for f in manifest.get("figures", [])]
        tables = [dict(t) for t in manifest.get("tables", [])]
    else:
        captions = _md_captions(folder)
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
    for t in tables:
        rows = _read_csv(folder / t["file"])
        t["columns"] = list(dict.fromkeys(k for r in rows for k in r if k is not None))
        t["rows"] = ([{c: r.get(c) or "" for c in t["columns"]} for r in rows]
                     if len(rows) <= _INLINE_TABLE_ROWS else [])
        t["too_long"] = len(rows) if len(rows) > _INLINE_TABLE_ROWS else 0
    return figures, tables


def _scored_point(row: dict):
    """(printed, ours, window low, window high) of a scored row (a reproduction or calibration with a verdict; not a
    repeat of another row), the printed number read as the scorer reads it (:func:`printed_number`), else None."""
    if (row.get("kind") not in ("reproduction", "calibrated") or row.get("same_as")
            or row.get("verdict") not in SCORED_VERDICTS):
        return None
    try:
        printed = printed_number(row.get("printed", ""))
    except ValueError:
        return None
    values = [finite_float(row.get(k)) for k in ("reproduced", "window_low", "window_high")]
    return None if any(v is None for v in values) else (printed, *values)


def printed_versus_ours(numbers: list[dict]) -> list[dict]:
    """One inline SVG per printed table (the rows' ``location``, and unit): each scored number a point at (printed,
    ours) with its window as a vertical bar, in its verdict's class (a ring marks a row whose bracket reached it
    under another reading), and the line ours = printed. Rows without a verdict are left out; a table with none gets
    no figure. Returns ``[{"title", "svg", "n"}]`` in the order the tables first appear."""
    groups: dict[tuple, list] = {}
    for r in numbers:
        point = _scored_point(r)
        if point is not None:
            location = (r.get("printed_id") or "").split(" | ")[0]
            groups.setdefault((location, r.get("unit") or ""), []).append((point, r))
    size, pad = 300, 40
    inner, top = size - 52, pad - 28                    # the plot square; its top edge (room below for the labels)
    out = []
    for (location, unit), items in groups.items():
        values = [v for point, _ in items for v in point]
        data_lo, data_hi = min(values), max(values)
        span = data_hi - data_lo if data_hi > data_lo else max(abs(data_hi), 1.0)
        lo, hi = data_lo - 0.06 * span, data_hi + 0.06 * span          # a margin around the data

        def x(v):
            return round(pad + (v - lo) / (hi - lo) * inner, 1)

        def y(v):
            return round(top + (hi - v) / (hi - lo) * inner, 1)
        parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{size}" height="{size}" viewBox="0 0 {size} {size}" '
                 f'role="img" class="pvo"><title>{html.escape(location)}: ours against printed</title>',
                 f'<rect x="{pad}" y="{top}" width="{inner}" height="{inner}" class="frame"/>',
                 f'<line x1="{x(lo)}" y1="{y(lo)}" x2="{x(hi)}" y2="{y(hi)}" class="diagonal"/>']
        for v in (data_lo, data_hi):                                         # the data's ends as tick labels
            parts.append(f'<text x="{x(v)}" y="{size - 2}" font-size="10" text-anchor="middle">{v:.3g}</text>')
            parts.append(f'<text x="{pad - 3}" y="{y(v) + 3}" font-size="10" text-anchor="end">{v:.3g}</text>')
        parts.append(f'<text x="{pad + inner / 2}" y="{size - 14}" font-size="11" text-anchor="middle">printed'
                     f'{" (" + html.escape(unit) + ")" if unit else ""}</text>')
        parts.append(f'<text x="10" y="{top + inner / 2}" font-size="11" text-anchor="middle" '
                     f'transform="rotate(-90 10 {top + inner / 2})">ours</text>')
        for (printed, ours, low, high), r in items:
            verdict = r["verdict"]
            label = html.escape(f'{r.get("printed_id")}: printed {r.get("printed")}, ours {ours:.4g}, window '
                                f'[{low:.4g}, {high:.4g}], {verdict}'
                                + (f', bracket {r["bracket"]}' if r.get("bracket") else ""))
            parts.append(f'<g class="v-{verdict}"><title>{label}</title><line x1="{x(printed)}" y1="{y(low)}" '
                         f'x2="{x(printed)}" y2="{y(high)}" class="window"/>'
                         f'<circle cx="{x(printed)}" cy="{y(ours)}" r="3.5" class="ours"/>'
                         + (f'<circle cx="{x(printed)}" cy="{y(ours)}" r="6" class="reached"/>'
                            if r.get("bracket") in ("other_reading", "fitted_only") else "") + '</g>')
        parts.append("</svg>")
        out.append({"title": location + (f" ({unit})" if unit else ""), "svg": "".join(parts), "n": len(items)})
    return out


#: the page's columns whose long texts repeat from row to row: shown once, below the table, as numbered notes
_FOOTNOTE_COLUMNS = ("ambiguity_basis", "calibrated_from", "bracket_readings", "note")
_FOLD_CHARS = 240          # a note longer than this is folded (<details>), its first sentence shown


def _footnotes(shown: list[dict]) -> list[dict]:
    """Each distinct text of :data:`_FOOTNOTE_COLUMNS` numbered once, in order of first use; the cells become links to
    it (``[3]``). Returns the notes ``[{"n", "text", "head"}]`` (``head``: the first sentence of a folded one)."""
    from markupsafe import Markup, escape
    numbered: dict[str, int] = {}
    for row in shown:
        for c in _FOOTNOTE_COLUMNS:
            text = str(row.get(c) or "").strip()
            if text:
                n = numbered.setdefault(text, len(numbered) + 1)
                row[c] = Markup(f'<a class="fn" href="#fn-{n}" title="{escape(_short(text, 200))}">[{n}]</a>')
    return [{"n": n, "text": t, "head": _short(t, 160) if len(t) > _FOLD_CHARS else ""} for t, n in numbered.items()]


def page_html(exp, profile: str, params: dict, folder: Path, numbers: list[dict], stamp: str,
              dataset: dict | None = None) -> str:
    """``<id>/report.html``, rendered in ``folder`` (the staging folder, before it is promoted): links to the
    files present there and to ``../index.html``, which every run (re)writes. ``dataset`` as for
    :func:`summary_markdown`."""
    folder = Path(folder)
    shown, parameters, assumptions, manifest = _page_parts(exp, params, folder, numbers, dataset)
    for row in shown:
        for c in ("window_low", "window_high"):
            row[c] = _number(row[c], 6)
        for c in _page_columns(numbers):
            row[c] = "" if row[c] is None else row[c]
    footnotes = _footnotes(shown)
    figures, tables = _page_outputs(folder, manifest)
    links = []
    notebook = _rel(folder, f"{exp.id}.html", f"{exp.id}.ipynb")
    if notebook:
        links.append(("executed notebook" + (" (.ipynb)" if notebook.endswith(".ipynb") else ""), notebook))
        if notebook.endswith(".html") and _rel(folder, f"{exp.id}.ipynb"):
            links.append(("notebook file (.ipynb)", f"{exp.id}.ipynb"))
    for label, name in (("summary (Markdown)", "summary.md"), ("this page in Markdown", "report.md"),
                        ("numbers.csv", "numbers.csv"), ("assumptions.csv", "assumptions.csv")):
        if _rel(folder, name):
            links.append((label, name))
    assumption_columns = list(dict.fromkeys(k for r in assumptions for k in r if k is not None))
    return _render(
        "report.html", version=stamp, exp=exp, doc=exp.document, profile=profile, stamp=stamp,
        notebook=f"notebooks/{exp.notebook.relative_to(exp.notebook.parents[1]).as_posix()}", links=links,
        headline=_headline_counts(numbers),
        counts=_counts_table(scoreboard_counts(numbers)) if numbers else None,
        reasons=[{k: g[k] for k in ("verdict", "rows", "reason", "where")} for g in _reasons(numbers)],
        numbers=shown, page_columns=_page_columns(numbers), plots=printed_versus_ours(numbers), footnotes=footnotes,
        parameters=parameters,
        assumptions=[{c: r.get(c) or "" for c in assumption_columns} for r in assumptions],
        assumption_columns=assumption_columns, figures=figures, tables=tables,
        dataset=({"title": dataset_title(dataset), "credit": dataset_credit(dataset)} if dataset else None))


# -- the suite -----------------------------------------------------------------------------------------------

def _by_document(entries, rows):
    docs = {}
    for e in entries:
        docs.setdefault(e["exp"].document.key, e["exp"].document)
    return [(key, doc, [r for r in rows if r.get("document") == key]) for key, doc in docs.items()]


def _experiment_line(e) -> dict:
    rows = e["numbers"]
    rep = Counter(r["verdict"] for r in rows if r["kind"] == "reproduction" and not r.get("same_as"))
    cal = Counter(r["verdict"] for r in rows if r["kind"] == "calibrated" and not r.get("same_as"))
    fmt = lambda c: f"{c['within']} / {c['loose']} / {c['miss']}" if sum(c.values()) else "-"
    return {"reproductions within / loose / miss": fmt(rep), "calibrated within / loose / miss": fmt(cal),
            "other rows": sum(1 for r in rows if r["kind"] not in ("reproduction", "calibrated") or r.get("same_as"))}


def _datasets(report_dir: Path, page: str = "index.html") -> list[tuple[str, str]]:
    """``(data set, link)`` of the reports of other data sets kept in this folder (``data-<name>/``): a link to its
    ``page`` (``index.html`` or ``index.md``), else to the other one; a folder with neither is not listed. Read from
    disk, whatever run wrote this index: committed reports hold index.md only (the HTML is not committed), and a
    partial run never drops a data set it did not touch."""
    other = "index.md" if page == "index.html" else "index.html"
    out = []
    for d in sorted(Path(report_dir).glob("data-*")):
        name = _rel(d, page, other)
        if d.is_dir() and name:
            out.append((d.name[len("data-"):], f"{d.name}/{name}"))
    return out


def index_markdown(report_dir: Path, entries, rows, conclusions: dict | None = None) -> str:
    from .findings import leniency_note, one_screen, one_screen_markdown
    profile = _profile_of(report_dir)
    lines = [f"# locbook reports, `{report_dir.name}`", ""]
    lines += one_screen_markdown(one_screen(entries, rows, conclusions), profile)
    if not lines[2:] and leniency_note(profile):
        lines += [leniency_note(profile), ""]
    lines += [
             "Every printed number beside ours: [numbers.csv](numbers.csv). A row's kind says what agreement "
             "means: `reproduction` (our own simulation or analysis, no input chosen from the printed number), "
             "`calibrated` (an input was chosen from a printed number; the row names it), `arithmetic` (the "
             "source's own arithmetic), `claim` (a printed statement, checked as stated), `shown` (transcribed, "
             "nothing to compare). Verdicts: `within` (inside a window no wider than +-25 %: printed rounding + "
             "2 Monte-Carlo standard errors + a named ambiguity), `loose` (inside a wider window), `miss`.", "",
             _headline(rows), ""]
    if _bracket_headline(rows, profile):
        lines += [_bracket_headline(rows, profile), ""]
        if _findings(report_dir):
            lines += ["Findings per document: " + ", ".join(f"[{doc}]({link})" for doc, link in _findings(report_dir)),
                      ""]
    if _conclusion_pages(report_dir):
        lines += ["Conclusions per document (each claim of the source judged from the rows): " + ", ".join(
            f"[{doc}]({link})" for doc, link in _conclusion_pages(report_dir)), ""]
    sections = dataset_sections(report_dir, "index.md")
    if sections:            # each data set by its own manifest (title, attribution), its answer first
        lines += ["The measured-data experiments on other data sets (`locbook run --data`):", ""]
        lines += [f"- [{d['name']}]({d['link']}): " + " ".join(md_cell(x) for x in (
            d["answer"], f"*{d['title']}*.", d["credit"]) if x.strip("*.")) for d in sections] + [""]
    twice = double_counted(rows)
    if twice:
        lines += ["**Counted more than once** (fix the notebooks): " + "; ".join(
            f"{d} {p} in {', '.join(e)}" for d, p, e in twice), ""]
    findings = findings_summary(entries, rows)
    if findings:
        lines += ["## Findings", ""] + [f"- **{f['authors']} ({f['year']})**, `{f['key']}`: {markdown_text(f['text'])}"
                                        for f in findings] + [""]
    lines += ["## By document", ""]
    for key, doc, doc_rows in _by_document(entries, rows):
        if doc_rows:
            lines += [f"### {doc.authors} ({doc.year}), `{key}`", "",
                      Table(_counts_rows(scoreboard_counts(doc_rows))).to_markdown(), ""]
    if rows:
        lines += ["### All documents", "", Table(_counts_rows(scoreboard_counts(rows))).to_markdown(), ""]
    lines += ["## Experiments", ""]
    table = []
    for e in entries:
        exp = e["exp"]
        table.append({"experiment": f"`{exp.id}`", "reproduces": exp.section, **_experiment_line(e),
                      "brackets": ", ".join(f"{n} {b}" for b, n in _bracket_chips(e["numbers"])) or "-",
                      "report": f"[summary]({exp.id}/summary.md)" if e["present"] else "not run",
                      "generated by": e["report"].get("locbook", "")})
    lines += [Table(table).to_markdown(), ""]
    reasons = _reasons(rows)
    if reasons:       # long: folded (GitHub renders <details>); each reason once per experiment and verdict
        lines += ["## Misses and loose rows, by reason", "", "<details><summary>" + _plural(len(reasons), "reason")
                  + f" over {sum(g['rows'] for g in reasons)} rows</summary>", "", Table(reasons).to_markdown(), "",
                  "</details>", ""]
    return "\n".join(lines)


def _index_entry(report_dir: Path, e) -> dict:
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
            name = _rel(folder, *names)
            if name:
                links.append((label, f"{exp.id}/{name}"))
    if state == "failed":
        name = _rel(report_dir / ".failed" / exp.id, f"{exp.id}.html", f"{exp.id}.ipynb")
        if name:
            links.append(("failed notebook", f".failed/{exp.id}/{name}"))
    rows = e["numbers"]
    counts = scoreboard_counts(rows)
    line = _experiment_line(e)
    doc = exp.document
    return {"id": exp.id, "title": exp.title, "section": exp.section, "doc_key": doc.key,
            "doc_authors": doc.authors, "doc_year": doc.year, "profile": e["report"].get("profile", ""),
            "page": f"{exp.id}/report.html" if present and (folder / "report.html").is_file() else None,
            "reproductions": line["reproductions within / loose / miss"],
            "rep_shares": _shares(counts.get("reproduction", Counter())),
            "calibrated": line["calibrated within / loose / miss"],
            "cal_shares": _shares(counts.get("calibrated", Counter())),
            "other": line["other rows"], "chips": _chips(rows), "bracket_chips": _bracket_chips(rows),
            "state": state, "flagged": flagged, "shown_last_good": flagged and present,
            "error": last.get("error", ""), "time": f"{float(seconds):.1f} s" if seconds else "-",
            "stamp": e["report"].get("locbook", ""), "links": links}


def index_html(report_dir: Path, entries, rows, version: str, conclusions: dict | None = None) -> str:
    """``index.html`` of a reports folder: links only to the files present in it."""
    report_dir = Path(report_dir)
    experiments = [_index_entry(report_dir, e) for e in entries]
    pages = {x["id"]: x["page"] for x in experiments}
    reasons = [{**g, "page": pages.get(g["experiment"])} for g in _reasons(rows)]
    documents = [{"key": key, "authors": doc.authors, "year": doc.year, "title": doc.title,
                  "table": _counts_table(scoreboard_counts(doc_rows))}
                 for key, doc, doc_rows in _by_document(entries, rows) if doc_rows]
    return _render(
        "index.html", version=version, folder=report_dir.name, numbers_csv=(report_dir / "numbers.csv").is_file(),
        headline=_headline_counts(rows), brackets=_bracket_counts(rows), findings=_findings(report_dir),
        bracket_headline=_bracket_headline(rows, _profile_of(report_dir)),
        answers=_one_screen(entries, rows, conclusions), leniency=_leniency(report_dir),
        conclusion_pages=_conclusion_pages(report_dir),
        twice=double_counted(rows), datasets=dataset_sections(report_dir),
        total=_counts_table(scoreboard_counts(rows)) if rows else None, documents=documents,
        experiments=experiments, n_present=sum(1 for e in entries if e["present"]), reasons=reasons,
        summary=findings_summary(entries, rows))


def _conclusion_pages(report_dir: Path) -> list[tuple[str, str]]:
    """(document, file name) of the conclusions pages in a reports folder."""
    from .conclusions import CONCLUSIONS_SUFFIX
    return [(p.name[:-len(CONCLUSIONS_SUFFIX)], p.name)
            for p in sorted(Path(report_dir).glob(f"*{CONCLUSIONS_SUFFIX}"))]


def _one_screen(entries, rows, conclusions):
    from .findings import one_screen
    return one_screen(entries, rows, conclusions)


def _leniency(report_dir: Path) -> str:
    from .findings import leniency_note
    return leniency_note(_profile_of(report_dir)).replace("**", "")


def _read_json(path: Path, default):
    """The JSON in ``path``, or ``default`` when the file is missing, unreadable, not UTF-8, not JSON, or (for a
    dict or list ``default``) JSON of another type: a damaged file reads as an absent one, never as a crash."""
    try:
        value = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):      # UnicodeDecodeError is a ValueError
        return default
    if isinstance(default, (dict, list)) and not isinstance(value, type(default)):
        return default
    return value


def _read_csv(path: Path) -> list[dict]:
    """Rows of a CSV file written by locbook (UTF-8); ``[]`` when it is missing or damaged (not UTF-8, NUL
    bytes): the runner's validation says what is wrong with it, the pages show what can be read."""
    import csv
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            return list(csv.DictReader(fh))
    except (OSError, ValueError, csv.Error):
        return []


# -- a data set's reports (``locbook run --data``: a folder holding dataset.json) -----------------------------
# Its page opens with the answer: the data set's own title and attribution, then every method's errors beside its
# bound, then the channel fits, then the bookkeeping. It uses none of the reproduction vocabulary of the suite's
# own pages: a data set has no printed number to compare with.

#: the results tables of a data set's page: (experiment, the kind of its ``results.csv`` rows, heading); the columns
#: are those of :data:`locbook.scenarios.measured.RESULT_COLUMNS`
DATA_RESULTS = (("measured-localization", "static", "Static localization"),
                ("measured-tracking", "tracking", "Tracking"))
#: the figures shown inline below the results: (experiment, file)
DATA_FIGURES = (("measured-localization", "cdf.png"), ("measured-localization", "maps.png"),
                ("measured-tracking", "tracks.png"))
#: the channel fits shown after the results: (experiment, file)
DATA_FITS = ("measured-calibration", "fits.csv")
#: the results row that holds every scored recording together (``recording`` column)
POOLED = "pooled"
#: columns of a results table on the page: (shown name, results.csv column)
_RESULT_CELLS = (("method", "method"), ("recording", "recording"), ("epochs", "epochs"), ("coverage", "coverage"),
                 ("mean (m)", "mean_m"), ("mean interval (m)", ""), ("median (m)", "median_m"),
                 ("p90 (m)", "p90_m"), ("CE95 (m)", "ce95_m"), ("bound median (m)", "bound_median_m"),
                 ("ratio", "ratio"), ("ratio note", "ratio_note"), ("settings", "settings"))
#: columns of the fits table on the page (the measured-calibration notebook's fits.csv)
_FIT_CELLS = ("mode", "fit", "anchor", "P_0 (dBm)", "n", "residual sigma (dB)", "samples", "status")


def dataset_record(report_dir: Path) -> dict | None:
    """The record of the data set a reports folder holds (its ``dataset.json``, written by the runner when a data run
    claims the folder: name, identity, title, attribution, licence, manifest, geometry, the experiments left out and
    why), or None for a folder of the suite's own reports."""
    record = _read_json(Path(report_dir) / "dataset.json", {})
    return record if isinstance(record.get("data set"), str) and record.get("data set") else None


def dataset_title(record: dict) -> str:
    return str(record.get("title") or record.get("name") or "a data set")


def dataset_credit(record: dict) -> str:
    """The manifest's attribution and licence in one sentence ('' when the record has neither)."""
    parts = []
    if record.get("attribution"):
        parts.append(f"Attribution: {str(record['attribution']).rstrip('.')}.")
    if record.get("licence"):
        parts.append(f"Licence: {str(record['licence']).rstrip('.')}.")
    return " ".join(parts)


def _result_rows(path: Path, kind: str) -> list[dict]:
    """The rows of ``kind`` of a results.csv, grouped per method (in the file's order), each method's pooled row
    first, then its recordings in the file's order. A method scored on one recording keeps its pooled row only
    (the same epochs), named ``pooled (= <recording>)``."""
    rows = [r for r in _read_csv(path) if (r.get("kind") or kind) == kind and r.get("method")]
    out = []
    for method in dict.fromkeys(r["method"] for r in rows):
        mine = sorted((r for r in rows if r["method"] == method), key=lambda r: r.get("recording") != POOLED)
        if len(mine) == 2 and mine[0].get("recording") == POOLED != mine[1].get("recording"):
            mine = [{**mine[0], "recording": f"{POOLED} (= {mine[1].get('recording')})"}]
        out += mine
    return out


def _interval_cell(row: dict) -> str:
    low, high = finite_float(row.get("mean_low_m")), finite_float(row.get("mean_high_m"))
    if low is not None and high is not None:
        return f"[{row['mean_low_m']}, {row['mean_high_m']}]"
    return (row.get("interval_note") or "").strip() or "n/a"


def _result_table(rows: list[dict]) -> tuple[list[dict], list[dict]]:
    """(cells by shown column, notes): each distinct ratio note numbered once (``[n]``), in order of first use."""
    numbered: dict[str, int] = {}
    out = []
    for r in rows:
        cells = {}
        for shown, column in _RESULT_CELLS:
            if shown == "mean interval (m)":
                cells[shown] = _interval_cell(r)
            elif column == "ratio":
                cells[shown] = r.get("ratio") if finite_float(r.get("ratio")) is not None else "n/a"
            elif column == "ratio_note":
                note = (r.get("ratio_note") or "").strip()
                cells[shown] = f"[{numbered.setdefault(note, len(numbered) + 1)}]" if note else ""
            else:
                cells[shown] = r.get(column) or ""
        if (r.get("failure") or "").strip():         # a method of your own that gave no positions, and why
            cells["mean (m)"], cells["mean interval (m)"] = "failed", r["failure"].strip()
        cells["pooled"] = str(r.get("recording")).startswith(POOLED)
        out.append(cells)
    return out, [{"n": n, "text": t} for t, n in numbered.items()]


def _state_of(eid: str, record: dict, status: dict, folder: Path) -> tuple[str, str]:
    """(state, why) of an experiment of a data set's page: "left out", "failed", "interrupted", "not run", "ok" or
    "cached" (the last run's), with the reason of the first four."""
    left = (record.get("left out") or {}) if isinstance(record.get("left out"), dict) else {}
    if eid in left:
        return "left out", str(left[eid])
    last = status.get(eid) if isinstance(status.get(eid), dict) else {}
    state = last.get("status") or ""
    present = (folder / eid / "summary.md").is_file()
    if state in ("failed", "interrupted"):
        return state, str(last.get("error") or "")
    if not present:
        return "not run", "it has not run on this data set yet"
    return state or "ok", ""


def _missing_line(eid: str, state: str, why: str, what: str) -> str:
    """One line for a result the page cannot show: which experiment, and why."""
    if state == "left out":
        return f"{eid}: left out: {why}."
    if state in ("failed", "interrupted"):
        return f"{eid} {state}: {why or 'no reason recorded'}."
    if state == "not run":
        return f"{eid}: not run: {why}."
    return f"{eid}: its report holds no {what}."


def _best(rows: list[dict]) -> dict | None:
    """The pooled row with the lowest finite mean error (None: no such row)."""
    pooled = [r for r in rows
              if str(r.get("recording")).startswith(POOLED) and finite_float(r.get("mean_m")) is not None]
    return min(pooled, key=lambda r: finite_float(r["mean_m"])) if pooled else None


def _answer_text(parts: list[dict]) -> str:
    """One sentence: per kind, the method with the lowest pooled mean error, beside the median of its bound."""
    said = []
    for p in parts:
        best = _best(p["source_rows"])
        if best is None:
            continue
        bound = (best.get("bound") or "bound").split(" (")[0]
        text = f"{p['heading'].lower()}, {best['method']} {best['mean_m']} m"
        if finite_float(best.get("bound_median_m")) is not None:
            text += f" ({bound} median {best['bound_median_m']} m)"
        if finite_float(best.get("coverage")) is not None and finite_float(best["coverage"]) < 1:
            text += f", an estimate at {best['coverage']} of the epochs"
        said.append(text)
    return ("Lowest mean error over every scored recording together: " + "; ".join(said) + ".") if said else ""


def data_page(report_dir: Path, entries, record: dict) -> dict:
    """What a data set's page shows (:func:`data_index_markdown`, :func:`data_index_html`), read from the folder:
    ``entries`` as :func:`locbook.suite.runner.write_suite_reports` builds them, ``record`` its dataset.json."""
    report_dir = Path(report_dir)
    status = _read_json(report_dir / "status.json", {})
    by_id = {e["exp"].id: e for e in entries}
    results, lines = [], []
    for eid, kind, heading in DATA_RESULTS:
        state, why = _state_of(eid, record, status, report_dir)
        rows = _result_rows(report_dir / eid / "results.csv", kind) if state not in ("left out", "not run") else []
        note = ""
        if state in ("failed", "interrupted") and rows:
            note = f"The last run of {eid} {state} ({why or 'no reason recorded'}); these are its previous results."
        cells, notes = _result_table(rows)
        results.append({"id": eid, "heading": heading, "kind": kind, "rows": cells, "notes": notes,
                        "source_rows": rows, "note": note,
                        "bounds": list(dict.fromkeys(r.get("bound") for r in rows if r.get("bound"))),
                        "missing": "" if rows else _missing_line(eid, state, why, "results table (results.csv)"),
                        "link": _rel(report_dir, f"{eid}/report.html", f"{eid}/report.md")})
    figures = []
    for eid, name in DATA_FIGURES:
        folder = report_dir / eid
        if (folder / name).is_file() and _state_of(eid, record, status, report_dir)[0] != "left out":
            shown, _tables = _page_outputs(folder, _read_json(folder / "manifest.json", {"figures": [], "tables": []}))
            caption = next((f["caption"] for f in shown if f["file"] == name), "")
            figures.append({"file": f"{eid}/{name}", "caption": caption or name, "experiment": eid})
    fit_id, fit_file = DATA_FITS
    state, why = _state_of(fit_id, record, status, report_dir)
    fits = _read_csv(report_dir / fit_id / fit_file) if state not in ("left out", "not run") else []
    used = _fit_used(by_id)
    if fits and used and {"mode", "fit"} <= set(fits[0]):
        shown_fits = [r for r in fits if r.get("mode") != "per_anchor" or r.get("fit") == used]
    else:
        shown_fits = fits
    fit_columns = [c for c in _FIT_CELLS if fits and c in fits[0]] or (list(fits[0]) if fits else [])
    experiments = []
    for e in entries:
        eid = e["exp"].id
        state, why = _state_of(eid, record, status, report_dir)
        entry = _index_entry(report_dir, e) if state != "left out" else None
        experiments.append({"id": eid, "title": e["exp"].title, "state": state, "why": why,
                            "page": entry["page"] if entry else None, "links": entry["links"] if entry else [],
                            "time": entry["time"] if entry else "-", "stamp": entry["stamp"] if entry else "",
                            "profile": e["report"].get("profile", "")})
    return {"title": dataset_title(record), "name": record.get("name", ""), "credit": dataset_credit(record),
            "attribution": record.get("attribution", ""), "licence": record.get("licence", ""),
            "geometry": record.get("geometry", ""), "manifest": record.get("manifest", ""),
            "identity": record.get("data set", ""), "profile": _profile_of(report_dir) or next(
                (x["profile"] for x in experiments if x["profile"]), ""),
            "answer": _answer_text(results), "results": results, "figures": figures,
            "fits": [{c: r.get(c) or "" for c in fit_columns} for r in shown_fits], "fit_columns": fit_columns,
            "fit_used": used if shown_fits is not fits else "", "fits_link": _rel(report_dir, f"{fit_id}/{fit_file}"),
            "fits_missing": "" if fits else _missing_line(fit_id, state, why, "fits table (fits.csv)"),
            "experiments": experiments}


def _fit_used(by_id: dict) -> str:
    """The channel fit the methods ran on: measured-localization's (else measured-tracking's) ``fit`` parameter as
    its report records it, else the notebook's default; '' when neither declares one."""
    for eid in ("measured-localization", "measured-tracking"):
        e = by_id.get(eid)
        if e is None:
            continue
        params = e["report"].get("parameters") if isinstance(e["report"].get("parameters"), dict) else {}
        if params.get("fit"):
            return str(params["fit"])
        declared = e["exp"].declared_parameters()
        if "fit" in declared and declared["fit"].default:
            return str(declared["fit"].default)
    return ""


def _md_results(part: dict) -> list[str]:
    lines = [f"### {part['heading']}", ""]
    if not part["rows"]:
        return lines + [md_cell(part["missing"]), ""]
    if part["note"]:
        lines += [md_cell(part["note"]), ""]
    rows = [{k: (f"**{v}**" if k == "method" and r["pooled"] else md_cell(v)) for k, v in r.items() if k != "pooled"}
            for r in part["rows"]]
    lines += [Table(rows).to_markdown(), ""]
    about = f"From [{part['id']}]({part['id']}/report.md); the bound: {md_cell('; '.join(part['bounds']))}." \
        if part["bounds"] else f"From [{part['id']}]({part['id']}/report.md)."
    lines += [about + " Ratio: RMSE over the RMS bound on the epochs where the bound is defined.", ""]
    if part["notes"]:
        lines += ["Ratio notes:", ""] + [f"{n['n']}. {md_cell(n['text'])}" for n in part["notes"]] + [""]
    return lines


def data_index_markdown(report_dir: Path, entries, record: dict) -> str:
    """``index.md`` of a data set's reports folder: the answer first (title, attribution, licence, geometry; every
    method's errors beside its bound, the figures), then the channel fits, then the bookkeeping."""
    page = data_page(report_dir, entries, record)
    lines = [f"# {md_cell(page['title'])}", ""]
    for text in (page["credit"], page["geometry"] and page["geometry"].rstrip(".") + "."):
        if text:
            lines += [md_cell(text), ""]
    lines += ["## Results", ""]
    if page["answer"]:
        lines += [md_cell(page["answer"]), ""]
    for part in page["results"]:
        lines += _md_results(part)
    for f in page["figures"]:
        lines += [f"![{_caption_md(f['caption'])}]({f['file']})", "", f"*{_caption_md(f['caption'])}*", ""]
    lines += ["## Channel fits", ""]
    if page["fits"]:
        lines += [Table([{c: md_cell(v) for c, v in r.items()} for r in page["fits"]]).to_markdown(), ""]
        lines += [("Pooled fits, and each anchor's fit by the " + page["fit_used"] + " fit the methods ran on; "
                   if page["fit_used"] else "") + f"every fit: [{DATA_FITS[1]}]({page['fits_link']}).", ""]
    else:
        lines += [md_cell(page["fits_missing"]), ""]
    lines += ["## Experiments on this data set", ""]
    table = [{"experiment": f"[`{x['id']}`]({x['id']}/summary.md)" if x["links"] else f"`{x['id']}`",
              "title": md_cell(x["title"]), "last run": md_cell(x["state"] + (f": {x['why']}" if x["why"] else "")),
              "time": x["time"], "generated by": md_cell(x["stamp"])} for x in page["experiments"]]
    if table:
        lines += [Table(table).to_markdown(), ""]
    lines += [f"Data set `{md_cell(page['name'])}`" + (f", manifest `{md_cell(page['manifest'])}`" if page["manifest"]
                                                       else "") + (f"; profile `{page['profile']}`" if page["profile"]
                                                                   else "") + ". A last run `cached` was up to date "
              "and not executed again; `ok` ran in that run.", ""]
    return "\n".join(lines)


def data_index_html(report_dir: Path, entries, record: dict, version: str) -> str:
    """``index.html`` of a data set's reports folder (as :func:`data_index_markdown`)."""
    return _render("data_index.html", version=version, page=data_page(report_dir, entries, record))


def dataset_sections(report_dir: Path, page: str = "index.html") -> list[dict]:
    """The data sets of a profile's folder (``data-<name>/``, :func:`_datasets`), each with its title, attribution
    and the answer sentence of its page: ``[{"name", "link", "title", "credit", "answer"}]``."""
    out = []
    for name, link in _datasets(report_dir, page):
        folder = Path(report_dir) / f"data-{name}"
        record = dataset_record(folder) or {"name": name}
        parts = [{"heading": heading, "source_rows": _result_rows(folder / eid / "results.csv", kind)}
                 for eid, kind, heading in DATA_RESULTS
                 if eid not in (record.get("left out") or {})]
        out.append({"name": name, "link": link, "title": dataset_title(record), "credit": dataset_credit(record),
                    "answer": _answer_text(parts)})
    return out
