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
link; tests/project/test_site_browser.py opens it in headless Chromium to check that.
"""
from __future__ import annotations

import csv
import html
import io
import json
from collections import Counter, defaultdict
from pathlib import Path

from ..reproduce.printed_values import printed_number
from ..reproduce.report import Table, markdown_text
from ..reproduce.scoring import SCORED_VERDICTS, VERDICT_COLUMNS, scoreboard_counts
from .bracket_table import SITE_NUMBER_COLUMNS, bracket_of_rows, brackets_root, load_bracket
from .cachekey import locbook_version
from .compare import compare_folders, comparison_pages, write_comparison
from .conclusions import CONCLUSIONS_SUFFIX, write_conclusions
from .files import read_csv, read_json, write_text_atomic
from .findings import (
    bracket_headline,
    by_document,
    findings_links,
    first_clause,
    leniency_note,
    md_cell,
    one_screen,
    one_screen_markdown,
    profile_of,
    tier_counts,
    write_findings,
)
from .pages import (
    bracket_chips,
    caption_md,
    experiment_line,
    first_file,
    index_entry,
    number_text,
    page_outputs,
    render,
)
from .site_data import (
    data_index_html,
    data_index_markdown,
    data_page,
    dataset_credit,
    dataset_record,
    dataset_sections,
    dataset_title,
)
from .spec import PROFILES, Suite, finite_float

__all__ = ["write_suite_reports", "write_experiment_pages", "VERDICT_COLUMNS", "scoreboard_counts", "summary_markdown",
           "page_markdown", "page_html",
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
    return tier_counts(rows)


def _bracket_headline(rows, profile: str = "full") -> str:
    return bracket_headline(rows, profile)


def _findings(report_dir: Path) -> list[tuple[str, str]]:
    """(document, relative link) of every findings page of this reports folder."""
    return findings_links(report_dir)


def _reasons(rows) -> list[dict]:
    """Misses and loose rows grouped by their note (the likely reason)."""
    groups: dict[tuple, list] = defaultdict(list)
    for r in rows:
        if r.get("verdict") in ("miss", "loose", "inconsistent") and not r.get("same_as"):
            groups[(r["experiment"], r["verdict"], r.get("note") or "(no note)")].append(r)
    out = []
    for (exp, verdict, note), members in groups.items():
        more = f"; and {len(members) - 3} more" if len(members) > 3 else ""
        where = "; ".join(m["where"] for m in members[:3]) + more
        out.append({"experiment": exp, "verdict": verdict, "rows": len(members), "reason": note, "where": where})
    order = {"miss": 0, "inconsistent": 1, "loose": 2}
    return sorted(out, key=lambda g: (g["experiment"], order[g["verdict"]], -g["rows"]))


def _plural(n: int, noun: str) -> str:
    return f"{n} {noun}{'' if n == 1 else 's'}"


def findings_summary(entries, rows) -> list[dict]:
    """A few sentences per document, generated from its rows: what is reproduced, what is only
    calibrated, what misses and the likely reasons of the most missed rows (their notes, the most frequent first).
    ``[{"key", "authors", "year", "text"}]`` for the documents with scored rows."""
    out = []
    for key, doc, doc_rows in by_document(entries, rows):
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
        missed = Counter(first_clause(r.get("note") or "") for r in doc_rows if not r.get("same_as")
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
                      Table([{k: g[k] for k in ("verdict", "rows", "reason", "where")}
                             for g in reasons]).to_markdown(), ""]
    else:
        lines += ["The source prints no number for this experiment; its figures are qualitative.", ""]
    lines += ["Every row with its window and note, the parameters, assumptions and figures: [report.md](report.md).",
              ""]
    return "\n".join(lines)


_PAGE_COLUMNS = ("quantity", "where", "unit", "kind", "printed", "reproduced", "window_low", "window_high", "verdict",
                 "ambiguity_basis", "calibrated_from", "same_as", "note")


def _page_columns(numbers: list[dict]) -> tuple[str, ...]:
    """The page's columns: the bracket verdict and its interpretations after the verdict when a bracket was run."""
    if not any(r.get("bracket") for r in numbers):
        return _PAGE_COLUMNS
    at = _PAGE_COLUMNS.index("verdict") + 1
    return (*_PAGE_COLUMNS[:at], "bracket", "bracket_interpretations", *_PAGE_COLUMNS[at:])


def _set_by(exp, name: str, params: dict, dataset: dict | None) -> str:
    """Who set a parameter, for a page's parameters table: the notebook's default, a data run (``data`` from
    ``--data``; a value of ``[experiment.data_run] parameters``, unless ``-p`` gave another), or the profile /
    ``-p``."""
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
    manifest = read_json(folder / "manifest.json", {"figures": [], "tables": []})
    assumptions = read_csv(folder / "assumptions.csv")
    declared = exp.declared_parameters()
    parameters = [{"name": name, "value": json.dumps(params.get(name, p.default)),
                   "set by": _set_by(exp, name, params, dataset), "meaning": p.help}
                  for name, p in declared.items()]
    shown = [{c: r.get(c, "") for c in _page_columns(numbers)} for r in numbers]
    for row in shown:
        if row["reproduced"] not in ("", None):
            row["reproduced"] = f"{float(row['reproduced']):.4g}"
    return shown, parameters, assumptions, manifest


def page_markdown(exp, profile: str, params: dict, folder: Path, numbers: list[dict], stamp: str,
                  dataset: dict | None = None) -> str:
    """``<id>/report.md``; ``dataset`` as for :func:`summary_markdown` (a data run's page compares no printed
    number: that section is left out when it has none)."""
    shown, parameters, assumptions, manifest = _page_parts(exp, params, folder, numbers, dataset)
    lines = _header(exp, profile, stamp, dataset) + ["[Summary](summary.md).", ""]
    if shown or not dataset:
        lines += ["## Reproduced versus printed", ""]
        plots = [(PVO_FILE.format(i), p["title"]) for i, p in enumerate(printed_versus_ours(numbers), start=1)]
        for name, title in plots:
            if (Path(folder) / name).is_file():
                lines += [f"![{caption_md(title)}: ours against printed]({name})", ""]
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
            caption = caption_md(fig.get("caption") or "")
            if not fig.get("file"):     # a bracket point: figures are not drawn
                lines += [f"*{caption or caption_md(fig['name'])}* (not drawn: a bracket point)", ""]
                continue
            copies = ", ".join(f"[{e.rsplit('.', 1)[1].upper()}]({e})" for e in fig.get("exports", []))
            lines += [f"![{caption or fig['name']}]({fig['file']})", "",
                      f"*{caption}*" + (f" ({copies})" if copies else ""), ""]
    if manifest.get("tables"):
        lines += ["## Tables", ""]
        lines += [f"- [{t['file']}]({t['file']})" + "".join(f" ([LaTeX]({e}))" for e in t.get("exports", []))
                  + f": {caption_md(t.get('caption') or '')}" for t in manifest["tables"]]
        lines.append("")
    return "\n".join(lines)


# -- HTML: rendered from the Jinja2 templates in templates/ (one stylesheet, site.css, inlined in every page so
# that each page works on its own from file://); every href and src names a file that exists ----------------


def _counts_table(counts: dict[str, Counter]) -> dict:
    """A kind-by-verdict table for the ``counts_table`` macro: its verdict columns and its rows."""
    rows = _counts_rows(counts)
    return {"columns": [c for c in rows[0] if c not in ("kind", "rows")], "rows": rows}


def _headline_counts(rows) -> dict:
    rep = Counter(r["verdict"] for r in rows if r.get("kind") == "reproduction" and not r.get("same_as"))
    return {"within": rep["within"], "loose": rep["loose"], "miss": rep["miss"], "n": sum(rep.values())}


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


#: the printed-versus-ours plots as files beside report.md (which embeds them: the committed reports show them)
PVO_FILE = "printed-versus-ours-{}.svg"


def write_pvo_files(numbers: list[dict], folder: Path) -> list[tuple[str, str]]:
    """Each printed-versus-ours plot (:func:`printed_versus_ours`) as a standalone SVG file in ``folder``, its
    style (site.css's ``.pvo`` rules) and a white ground inside it; returns ``(file name, title)`` per plot."""
    from .pages import _TEMPLATES
    css = " ".join(line for line in (_TEMPLATES / "site.css").read_text(encoding="utf-8").splitlines()
                   if line.startswith(".pvo"))
    css += " .pvo text { font-family: sans-serif; fill: #1d232a; }"
    out = []
    for i, plot in enumerate(printed_versus_ours(numbers), start=1):
        head, sep, rest = plot["svg"].partition('class="pvo">')
        svg = head + sep + f'<style>{css}</style><rect width="100%" height="100%" fill="#fff"/>' + rest
        name = PVO_FILE.format(i)
        (Path(folder) / name).write_text(svg + "\n", encoding="utf-8")
        out.append((name, plot["title"]))
    return out


#: a printed-versus-ours plot of at most this many points labels each beside it
_LABELLED_POINTS = 3


def _short_quantity(row: dict) -> str:
    text = str(row.get("quantity") or row.get("printed_id") or "")
    return text if len(text) <= 28 else text[:27] + "\u2026"


def nice_ticks(lo: float, hi: float, most: int = 5) -> list[float]:
    """Round tick values inside ``[lo, hi]``: multiples of 1, 2, 2.5 or 5 times a power of ten, at most ``most``
    of them and at least two (the ends, when the span is too narrow for a round step)."""
    import math
    span = hi - lo
    if not span > 0 or not math.isfinite(span):
        return [lo]
    raw = span / (most - 1)
    power = 10 ** math.floor(math.log10(raw))
    step = next(m * power for m in (1, 2, 2.5, 5, 10) if m * power >= raw)
    first = math.ceil(lo / step) * step
    ticks = [round(first + i * step, 12) for i in range(int((hi - first) / step + 1e-9) + 1)]
    return ticks if len(ticks) >= 2 else [lo, hi]


def printed_versus_ours(numbers: list[dict]) -> list[dict]:
    """One inline SVG per printed table (the rows' ``location``, and unit): each scored number a point at (printed,
    ours) with its window as a vertical bar, in its verdict's class (a ring marks a row whose bracket reached it
    under another interpretation), and the line ours = printed. Rows without a verdict are left out; a table with none
    gets no figure. Returns ``[{"title", "svg", "n"}]`` in the order the tables first appear."""
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
        for v in nice_ticks(lo, hi):                       # round ticks on both axes, with their marks
            parts.append(f'<line x1="{x(v)}" y1="{top + inner}" x2="{x(v)}" y2="{top + inner + 4}" class="frame"/>'
                         f'<line x1="{pad - 4}" y1="{y(v)}" x2="{pad}" y2="{y(v)}" class="frame"/>')
            parts.append(f'<text x="{x(v)}" y="{size - 2}" font-size="10" text-anchor="middle">{v:.3g}</text>')
            parts.append(f'<text x="{pad - 6}" y="{y(v) + 3}" font-size="10" text-anchor="end">{v:.3g}</text>')
        parts.append(f'<text x="{pad + inner / 2}" y="{size - 14}" font-size="11" text-anchor="middle">printed'
                     f'{" (" + html.escape(unit) + ")" if unit else ""}</text>')
        parts.append(f'<text x="10" y="{top + inner / 2}" font-size="11" text-anchor="middle" '
                     f'transform="rotate(-90 10 {top + inner / 2})">ours</text>')
        for (printed, ours, low, high), r in items:
            verdict = r["verdict"]
            label = html.escape(f'{r.get("printed_id")}: printed {r.get("printed")}, ours {ours:.4g}, window '
                                f'[{low:.4g}, {high:.4g}], {verdict}'
                                + (f', bracket {r["bracket"]}' if r.get("bracket") else ""))
            # a small table's points say what they are beside them too (not only on hover)
            visible = (f'<text x="{min(x(printed) + 7, size - 4)}" y="{y(ours) - 6}" font-size="10" '
                       f'text-anchor="{"start" if x(printed) < pad + inner * 0.6 else "end"}" class="point-label">'
                       f'{html.escape(_short_quantity(r))}: {verdict}</text>' if len(items) <= _LABELLED_POINTS else "")
            parts.append(f'<g class="v-{verdict}"><title>{label}</title><line x1="{x(printed)}" y1="{y(low)}" '
                         f'x2="{x(printed)}" y2="{y(high)}" class="window"/>'
                         f'<circle cx="{x(printed)}" cy="{y(ours)}" r="3.5" class="ours"/>'
                         + (f'<circle cx="{x(printed)}" cy="{y(ours)}" r="6" class="reached"/>'
                            if r.get("bracket") in ("other_interpretation", "fitted_only") else "")
                         + visible + '</g>')
        parts.append("</svg>")
        out.append({"title": location + (f" ({unit})" if unit else ""), "svg": "".join(parts), "n": len(items)})
    return out


#: the page's columns whose long texts repeat from row to row: shown once, below the table, as numbered notes
_FOOTNOTE_COLUMNS = ("ambiguity_basis", "calibrated_from", "bracket_interpretations", "note")
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
                row[c] = Markup(f'<a class="fn" href="#fn-{n}" title="{escape(first_clause(text, 200))}">[{n}]</a>')
    return [{"n": n, "text": t, "head": first_clause(t, 160) if len(t) > _FOLD_CHARS else ""}
            for t, n in numbered.items()]


def page_html(exp, profile: str, params: dict, folder: Path, numbers: list[dict], stamp: str,
              dataset: dict | None = None, bracket_page: str | None = None) -> str:
    """``<id>/report.html``, rendered in ``folder`` (the staging folder, before it is promoted): links to the
    files present there and to ``../index.html``, which every run (re)writes. ``dataset`` as for
    :func:`summary_markdown`; ``bracket_page``: the link to the experiment's bracket page, where one exists."""
    folder = Path(folder)
    shown, parameters, assumptions, manifest = _page_parts(exp, params, folder, numbers, dataset)
    for row in shown:
        for c in ("window_low", "window_high"):
            row[c] = number_text(row[c], 4)            # the digits of `reproduced` beside them
        for c in _page_columns(numbers):
            row[c] = "" if row[c] is None else row[c]
    footnotes = _footnotes(shown)
    figures, tables = page_outputs(folder, manifest)
    links = []
    notebook = first_file(folder, f"{exp.id}.html", f"{exp.id}.ipynb")
    if notebook:
        links.append(("executed notebook" + (" (.ipynb)" if notebook.endswith(".ipynb") else ""), notebook))
        if notebook.endswith(".html") and first_file(folder, f"{exp.id}.ipynb"):
            links.append(("notebook file (.ipynb)", f"{exp.id}.ipynb"))
    for label, name in (("summary (Markdown)", "summary.md"), ("this page in Markdown", "report.md"),
                        ("numbers.csv", "numbers.csv"), ("numbers in LaTeX", "numbers.tex"),
                        ("assumptions.csv", "assumptions.csv")):
        if first_file(folder, name):
            links.append((label, name))
    if bracket_page:
        links.append(("interpretation bracket (strip charts)", bracket_page))
    assumption_columns = list(dict.fromkeys(k for r in assumptions for k in r if k is not None))
    return render(
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


def index_markdown(report_dir: Path, entries, rows, conclusions: dict | None = None) -> str:
    profile = profile_of(report_dir)
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
    if comparison_pages(report_dir):
        lines += ["Compared with: " + ", ".join(f"[{base}]({link})" for base, link in comparison_pages(report_dir))
                  + " (every printed number in both runs, the difference and its standard error).", ""]
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
    for key, doc, doc_rows in by_document(entries, rows):
        if doc_rows:
            lines += [f"### {doc.authors} ({doc.year}), `{key}`", "",
                      Table(_counts_rows(scoreboard_counts(doc_rows))).to_markdown(), ""]
    if rows:
        lines += ["### All documents", "", Table(_counts_rows(scoreboard_counts(rows))).to_markdown(), ""]
    lines += ["## Experiments", ""]
    table = []
    for e in entries:
        exp = e["exp"]
        table.append({"experiment": f"`{exp.id}`", "reproduces": exp.section, **experiment_line(e),
                      "brackets": ", ".join(f"{n} {b}" for b, n in bracket_chips(e["numbers"])) or "-",
                      "report": f"[summary]({exp.id}/summary.md)" if e["present"] else "not run",
                      "generated by": e["report"].get("locbook", "")})
    lines += [Table(table).to_markdown(), ""]
    reasons = _reasons(rows)
    if reasons:       # long: folded (GitHub renders <details>); each reason once per experiment and verdict
        lines += ["## Misses and loose rows, by reason", "", "<details><summary>" + _plural(len(reasons), "reason")
                  + f" over {sum(g['rows'] for g in reasons)} rows</summary>", "", Table(reasons).to_markdown(), "",
                  "</details>", ""]
    return "\n".join(lines)


def index_html(report_dir: Path, entries, rows, version: str, conclusions: dict | None = None) -> str:
    """``index.html`` of a reports folder: links only to the files present in it."""
    report_dir = Path(report_dir)
    experiments = [index_entry(report_dir, e) for e in entries]
    pages = {x["id"]: x["page"] for x in experiments}
    reasons = [{**g, "page": pages.get(g["experiment"])} for g in _reasons(rows)]
    documents = [{"key": key, "authors": doc.authors, "year": doc.year, "title": doc.title,
                  "table": _counts_table(scoreboard_counts(doc_rows))}
                 for key, doc, doc_rows in by_document(entries, rows) if doc_rows]
    return render(
        "index.html", version=version, folder=report_dir.name, numbers_csv=(report_dir / "numbers.csv").is_file(),
        headline=_headline_counts(rows), brackets=_bracket_counts(rows), findings=_findings(report_dir),
        bracket_headline=_bracket_headline(rows, profile_of(report_dir)),
        answers=_one_screen(entries, rows, conclusions), leniency=_leniency(report_dir),
        conclusion_pages=_conclusion_pages(report_dir), comparisons=comparison_pages(report_dir),
        twice=double_counted(rows), datasets=dataset_sections(report_dir),
        total=_counts_table(scoreboard_counts(rows)) if rows else None, documents=documents,
        experiments=experiments, n_present=sum(1 for e in entries if e["present"]), reasons=reasons,
        summary=findings_summary(entries, rows))


def _conclusion_pages(report_dir: Path) -> list[tuple[str, str]]:
    """(document, file name) of the conclusions pages in a reports folder."""
    return [(p.name[:-len(CONCLUSIONS_SUFFIX)], p.name)
            for p in sorted(Path(report_dir).glob(f"*{CONCLUSIONS_SUFFIX}"))]


def _one_screen(entries, rows, conclusions):
    return one_screen(entries, rows, conclusions)


def _leniency(report_dir: Path) -> str:
    return leniency_note(profile_of(report_dir)).replace("**", "")


#: numbers.tex's columns (from numbers.csv): what a paper's table of printed against reproduced values needs
PAPER_COLUMNS = ("quantity", "where", "unit", "kind", "printed", "reproduced", "window_low", "window_high", "verdict")


def numbers_for_paper(numbers: list[dict]) -> list[dict]:
    """numbers.csv's rows cut to :data:`PAPER_COLUMNS`, each number at 4 significant digits (the pages' digits)."""
    def four(text):
        value = finite_float(text)
        return text if value is None else f"{value:.4g}"
    return [{c: (four(r.get(c, "")) if c in ("reproduced", "window_low", "window_high") else r.get(c, ""))
             for c in PAPER_COLUMNS} for r in numbers]


def write_experiment_pages(exp, profile: str, params: dict, staging: Path, folder: Path, stamp: str) -> None:
    """``summary.md``, ``report.md`` and ``report.html`` of one validated report in ``staging`` (to become
    ``folder``), from its numbers.csv: the runner's ``write_pages`` (:func:`locbook.suite.runner.run_tasks`)."""
    numbers = read_csv(staging / "numbers.csv")
    # the pages show each row's interpretation bracket when the experiment was bracketed (<reports>/brackets/<id>/)
    bracket = load_bracket(brackets_root(folder.parent) / exp.id) if folder.parent.name in PROFILES else []
    if bracket:
        numbers = bracket_of_rows(numbers, bracket, profile)
    dataset = dataset_record(folder.parent)       # a data run's pages name the data set, not the document
    if numbers:           # the printed numbers beside ours, for a paper (booktabs LaTeX); before the pages link it
        Table(numbers_for_paper(numbers)).write_latex(staging / "numbers.tex")
    assumptions = read_csv(staging / "assumptions.csv")
    if assumptions:
        Table(assumptions).write_latex(staging / "assumptions.tex")
    write_pvo_files(numbers, staging)           # before report.md, which embeds them
    (staging / "summary.md").write_text(summary_markdown(exp, profile, numbers, stamp, dataset),
                                        encoding="utf-8")
    (staging / "report.md").write_text(page_markdown(exp, profile, params, staging, numbers, stamp, dataset),
                                       encoding="utf-8")
    page = brackets_root(folder.parent) / exp.id / "index.html"
    (staging / "report.html").write_text(page_html(exp, profile, params, staging, numbers, stamp, dataset,
                                                   f"../../brackets/{exp.id}/index.html" if bracket and page.is_file()
                                                   else None), encoding="utf-8")


def write_suite_reports(suite: Suite, report_dir: Path, *, list_all: bool = True,
                        compare_with: Path | None = None) -> None:
    """Rebuild ``numbers.csv``, ``index.html`` and ``index.md`` from the experiment folders present (and the
    interpretation brackets in ``<reports>/brackets/``: :mod:`locbook.suite.bracket`); in a profile's folder also each
    document's findings page (:mod:`locbook.suite.findings`) and conclusions page (:mod:`locbook.suite.conclusions`),
    from the same rows.

    An experiment's rows come from its own folder, whatever run wrote it, so a partial run leaves the
    others' results as they were. ``list_all=False`` (folders of ``-p`` runs) lists only the experiments
    present. ``compare_with``: the base run of a ``-p`` (or ``--out``) run, the profile's own folder: when it holds
    reports, the comparison with it (:mod:`locbook.suite.compare`) is written beside the index, which links it."""
    status = read_json(report_dir / "status.json", {})
    dataset = dataset_record(report_dir)       # a data run's folder: the data set's page, not the scoreboard
    rows, entries = [], []
    for exp in suite.experiments:
        folder = report_dir / exp.id
        present = (folder / "summary.md").is_file()
        # a data set's page names every experiment that takes a data set: those run, those failed, those left out
        listed = present or list_all or (dataset is not None and (exp.data_run is not None or exp.id in status))
        if not listed:
            continue
        numbers = read_csv(folder / "numbers.csv") if present else []
        # each row's interpretation bracket, from <reports>/brackets/<id>/bracket.csv when one was run (else empty); not
        # for a -p run's folder, whose rows were computed under other interpretations than the bracket's default
        bracket = load_bracket(brackets_root(report_dir) / exp.id) if report_dir.name in PROFILES else []
        numbers = bracket_of_rows(numbers, bracket, read_json(folder / "report.json", {}).get("profile"))
        rows += numbers
        entries.append({"exp": exp, "present": present, "report": read_json(folder / "report.json", {}),
                        "run": read_json(folder / "run.json", {}), "last": status.get(exp.id, {}),
                        "numbers": numbers})
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=SITE_NUMBER_COLUMNS)
    writer.writeheader()
    for r in rows:
        writer.writerow({c: r.get(c, "") for c in SITE_NUMBER_COLUMNS})
    write_text_atomic(report_dir / "numbers.csv", out.getvalue())
    if compare_with is not None and Path(compare_with) != Path(report_dir) and (compare_with / "numbers.csv").is_file():
        write_comparison(compare_folders(compare_with, report_dir, suite))
    if dataset is not None:
        write_text_atomic(report_dir / "index.html", data_index_html(report_dir, entries, dataset, locbook_version()))
        write_text_atomic(report_dir / "index.md", data_index_markdown(report_dir, entries, dataset))
        return
    # the findings pages, the conclusions pages and the index from the same rows as numbers.csv (one tally)
    profile = profile_of(report_dir)
    if report_dir.name in PROFILES:
        write_findings(report_dir, entries, rows, profile, lambda path, text: write_text_atomic(path, text))
    conclusions = (write_conclusions(report_dir, suite, entries, rows, lambda path, text: write_text_atomic(path, text))
                   if report_dir.name in PROFILES else {})
    write_text_atomic(report_dir / "index.html", index_html(report_dir, entries, rows, locbook_version(),
                                                             conclusions))
    write_text_atomic(report_dir / "index.md", index_markdown(report_dir, entries, rows, conclusions))
