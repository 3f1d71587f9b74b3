"""The reports a reader opens: per-experiment summary and page, and the suite's index (Markdown and HTML).

- ``<id>/summary.md`` fits on a screen: what the experiment reproduces, its scoreboard (rows by kind, columns
  by verdict) and the reasons behind its misses and loose rows;
- ``<id>/report.md`` (and ``report.html``) is the whole page: every number row with its window and note, the
  parameters, the assumptions, the figures and tables;
- ``index.md`` / ``index.html`` open with a kind-by-verdict table per document and in total, headline the
  independent reproductions only, list the experiments, and gather the reasons behind every miss and loose row.

Printed values are shown exactly as printed (the text of the printed-values file). Every table is built from
``numbers.csv`` rows, so a partial run shows the rows of the folders present.
"""
from __future__ import annotations

import json
from collections import Counter, defaultdict
from html import escape
from pathlib import Path

from .report import Table
from .scoring import KINDS

__all__ = ["VERDICT_COLUMNS", "scoreboard_counts", "summary_markdown", "page_markdown", "page_html",
           "index_markdown", "index_html", "double_counted"]

#: verdict columns of the kind-by-verdict tables ("linked": repeats of a quantity compared elsewhere)
VERDICT_COLUMNS = ("within", "loose", "miss", "consistent", "inconsistent", "no verdict", "linked")
_COLORS = {"within": "#d8f0d8", "loose": "#fff1c2", "miss": "#f8d0d0", "consistent": "#d8f0d8",
           "inconsistent": "#f8d0d0"}
_STYLE = ("body{font-family:sans-serif;margin:2em;max-width:90em}table{border-collapse:collapse;margin:0.5em 0}"
          "td,th{border:1px solid #ccc;padding:3px 7px;vertical-align:top}td.n{text-align:right}"
          + "".join(f".v-{v}{{background:{c}}}" for v, c in _COLORS.items())
          + ".err{font-family:monospace;font-size:small;color:#900}.failed,.interrupted{background:#fdd}")


def _column(row: dict) -> str:
    if row.get("same_as"):
        return "linked"
    return row.get("verdict") or "no verdict"


def scoreboard_counts(rows) -> dict[str, Counter]:
    """``{kind: Counter(verdict column -> rows)}`` over ``numbers.csv`` rows (kinds in :data:`KINDS` order)."""
    counts = {k: Counter() for k in KINDS}
    for r in rows:
        counts.setdefault(r.get("kind", ""), Counter())[_column(r)] += 1
    return {k: c for k, c in counts.items() if c}


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


# -- one experiment ------------------------------------------------------------------------------------------

def _header(exp, profile: str, stamp: str) -> list[str]:
    doc = exp.document
    return [f"# {exp.title}", "",
            f"Experiment `{exp.id}`, reproducing **{exp.section}** of {doc.authors}, *{doc.title}* ({doc.year}).", "",
            f"Profile `{profile}`; generated by locbook {stamp}. Notebook: `notebooks/"
            f"{exp.notebook.relative_to(exp.notebook.parents[1]).as_posix()}`.", ""]


def summary_markdown(exp, profile: str, numbers: list[dict], stamp: str) -> str:
    lines = _header(exp, profile, stamp)
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


def _page_parts(exp, params: dict, folder: Path, numbers: list[dict]):
    manifest = _read_json(folder / "manifest.json", {"figures": [], "tables": []})
    assumptions = _read_csv(folder / "assumptions.csv")
    declared = exp.declared_parameters()
    parameters = [{"name": name, "value": json.dumps(params.get(name, p.default)),
                   "set by": "profile / -p" if name in params else "notebook default", "meaning": p.help}
                  for name, p in declared.items()]
    shown = [{c: r.get(c, "") for c in _PAGE_COLUMNS} for r in numbers]
    for row in shown:
        if row["reproduced"] not in ("", None):
            row["reproduced"] = f"{float(row['reproduced']):.4g}"
    return shown, parameters, assumptions, manifest


def page_markdown(exp, profile: str, params: dict, folder: Path, numbers: list[dict], stamp: str) -> str:
    shown, parameters, assumptions, manifest = _page_parts(exp, params, folder, numbers)
    lines = _header(exp, profile, stamp) + ["[Summary](summary.md).", ""]
    lines += ["## Reproduced versus printed", ""]
    lines.append(Table(shown).to_markdown() if shown else "No printed number is compared here.")
    lines += ["", "## Parameters", "", Table(parameters).to_markdown(), ""]
    if assumptions:
        lines += ["## Assumptions", "", Table(assumptions).to_markdown(), ""]
    if manifest.get("figures"):
        lines += ["## Figures", ""]
        for fig in manifest["figures"]:
            lines += [f"![{fig['caption'] or fig['name']}]({fig['file']})", "", f"*{fig['caption']}*", ""]
    if manifest.get("tables"):
        lines += ["## Tables", ""]
        lines += [f"- [{t['file']}]({t['file']}): {t['caption']}" for t in manifest["tables"]]
        lines.append("")
    return "\n".join(lines)


def _html_table(rows: list[dict], verdict_key: str | None = "verdict") -> str:
    if not rows:
        return ""
    cols = list(dict.fromkeys(k for r in rows for k in r))
    head = "".join(f"<th>{escape(c)}</th>" for c in cols)
    body = []
    for r in rows:
        cls = f" class='v-{escape(str(r.get(verdict_key, '')))}'" if verdict_key and r.get(verdict_key) in _COLORS else ""
        body.append(f"<tr{cls}>" + "".join(f"<td>{escape(str(r.get(c, '')))}</td>" for c in cols) + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def _counts_html(counts: dict[str, Counter]) -> str:
    rows = _counts_rows(counts)
    cols = [c for c in rows[0] if c != "kind"]
    head = "<th>kind</th>" + "".join(f"<th>{escape(c)}</th>" for c in cols)
    body = []
    for r in rows:
        cells = [f"<th>{escape(r['kind'])}</th>"]
        for c in cols:
            cls = f" v-{c}" if c in _COLORS and r[c] else ""
            cells.append(f"<td class='n{cls}'>{r[c]}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"


def page_html(exp, profile: str, params: dict, folder: Path, numbers: list[dict], stamp: str) -> str:
    shown, parameters, assumptions, manifest = _page_parts(exp, params, folder, numbers)
    figs = "".join(f"<figure><img src='{escape(f['file'])}' style='max-width:100%'><figcaption>"
                   f"{escape(f['caption'])}</figcaption></figure>" for f in manifest.get("figures", []))
    tables = "".join(f"<li><a href='{escape(t['file'])}'>{escape(t['file'])}</a>: {escape(t['caption'])}</li>"
                     for t in manifest.get("tables", []))
    doc = exp.document
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>{escape(exp.id)}</title><style>{_STYLE}</style></head>
<body><h1>{escape(exp.title)}</h1><p>Experiment <code>{escape(exp.id)}</code>, reproducing <b>{escape(exp.section)}</b> of
{escape(doc.authors)}, <i>{escape(doc.title)}</i> ({escape(doc.year)}). Profile <code>{escape(profile)}</code>; generated by
locbook {escape(stamp)}. <a href="{escape(exp.id)}.ipynb">Executed notebook</a>.</p>
<h2>Scoreboard</h2><p>{escape(_headline(numbers).replace('**', ''))}</p>{_counts_html(scoreboard_counts(numbers)) if numbers else ''}
<h2>Reproduced versus printed</h2>{_html_table(shown) or '<p>No printed number is compared here.</p>'}
<h2>Parameters</h2>{_html_table(parameters, None)}<h2>Assumptions</h2>{_html_table(assumptions, None)}
<h2>Figures</h2>{figs}<h2>Tables</h2><ul>{tables}</ul></body></html>
"""


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


def index_markdown(report_dir: Path, entries, rows) -> str:
    lines = [f"# locbook reports, `{report_dir.name}`", "",
             "Every printed number beside ours: [numbers.csv](numbers.csv). A row's kind says what agreement "
             "means: `reproduction` (our own simulation or analysis, no input chosen from the printed number), "
             "`calibrated` (an input was chosen from a printed number; the row names it), `arithmetic` (the "
             "source's own arithmetic), `claim` (a printed statement, checked as stated), `shown` (transcribed, "
             "nothing to compare). Verdicts: `within` (inside a window no wider than +-25 %: printed rounding + "
             "2 Monte-Carlo standard errors + a named ambiguity), `loose` (inside a wider window), `miss`.", "",
             _headline(rows), ""]
    twice = double_counted(rows)
    if twice:
        lines += ["**Counted more than once** (fix the notebooks): " + "; ".join(
            f"{d} {p} in {', '.join(e)}" for d, p, e in twice), ""]
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
                      "report": f"[summary]({exp.id}/summary.md)" if e["present"] else "not run",
                      "generated by": e["report"].get("locbook", "")})
    lines += [Table(table).to_markdown(), ""]
    reasons = _reasons(rows)
    if reasons:
        lines += ["## Misses and loose rows, by reason", "", Table(reasons).to_markdown(), ""]
    return "\n".join(lines)


def index_html(report_dir: Path, entries, rows, version: str) -> str:
    docs = "".join(f"<h3>{escape(doc.authors)} ({escape(doc.year)}), <code>{escape(key)}</code></h3>"
                   f"{_counts_html(scoreboard_counts(doc_rows))}"
                   for key, doc, doc_rows in _by_document(entries, rows) if doc_rows)
    total = f"<h3>All documents</h3>{_counts_html(scoreboard_counts(rows))}" if rows else ""
    exp_rows = []
    for e in entries:
        exp, run, last = e["exp"], e["run"], e["last"]
        state = last.get("status", "ok" if e["present"] else "not run")
        links = []
        if e["present"]:
            links += [f'<a href="{exp.id}/report.html">report</a>', f'<a href="{exp.id}/{exp.id}.ipynb">notebook</a>',
                      f'<a href="{exp.id}/summary.md">summary</a>', f'<a href="{exp.id}/numbers.csv">numbers</a>']
        if state == "failed":
            links.append(f'<a href=".failed/{exp.id}/{exp.id}.ipynb">failed notebook</a>')
        err = f'<div class="err">{escape(last.get("error", ""))}</div>' if last.get("error") else ""
        shown = " (showing the last good report)" if state in ("failed", "interrupted") and e["present"] else ""
        seconds = last.get("seconds", run.get("seconds", 0)) or 0
        counts = scoreboard_counts(e["numbers"]).get("reproduction", Counter())
        verdict = "miss" if counts["miss"] else "loose" if counts["loose"] else "within" if counts["within"] else ""
        line = _experiment_line(e)
        exp_rows.append(
            f"<tr><td><code>{escape(exp.id)}</code><br>{escape(exp.title)}</td><td>{escape(exp.section)}</td>"
            f"<td class='n v-{verdict}'>{escape(line['reproductions within / loose / miss'])}</td>"
            f"<td class='n'>{escape(line['calibrated within / loose / miss'])}</td><td class='n'>{line['other rows']}</td>"
            f"<td class='{escape(state.replace(' ', '-'))}'>{escape(state)}{shown}{err}</td><td>{seconds:.1f} s</td>"
            f"<td>{escape(e['report'].get('locbook', ''))}</td><td>{' · '.join(links)}</td></tr>")
    reasons = _html_table(_reasons(rows))
    twice = double_counted(rows)
    warn = ("<p class='err'>Counted more than once: " + escape("; ".join(f"{d} {p} in {', '.join(e)}" for d, p, e in twice))
            + "</p>") if twice else ""
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>locbook reports ({escape(report_dir.name)})</title>
<style>{_STYLE}</style></head>
<body><h1>locbook reports, <code>{escape(report_dir.name)}</code></h1>
<p>locbook {escape(version)}. Every printed number beside ours: <a href="numbers.csv">numbers.csv</a>.</p>
<p>{escape(_headline(rows).replace('**', ''))}</p>{warn}
<h2>By document</h2>{docs}{total}
<h2>Experiments</h2><table><thead><tr><th>experiment</th><th>reproduces</th><th>reproductions within / loose / miss</th>
<th>calibrated within / loose / miss</th><th>other rows</th><th>last run</th><th>time</th><th>generated by</th><th>outputs</th></tr></thead>
<tbody>{''.join(exp_rows)}</tbody></table>
<h2>Misses and loose rows, by reason</h2>{reasons or '<p>None.</p>'}</body></html>
"""


def _read_json(path: Path, default):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return default


def _read_csv(path: Path) -> list[dict]:
    import csv
    if not path.exists():
        return []
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))
