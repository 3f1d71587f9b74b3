"""What the interpretation brackets found, counted once: the tier tally, the findings page of each document, the
one-screen answer at the top of an index.

Everything here is computed from the rows of a reports folder's ``numbers.csv`` (the experiments' rows with the
``bracket`` and ``bracket_interpretations`` columns :func:`locbook.suite.bracket.bracket_of_rows` gave them), so the
index, the findings pages and numbers.csv give the same counts by construction (``tests/suite/test_findings.py``
reads all three back and compares them). The tiers are :data:`locbook.reproduce.scoring.BRACKETS`.
"""
from __future__ import annotations

import re
from collections import Counter, defaultdict
from pathlib import Path

from ..reproduce.report import markdown_text
from ..reproduce.scoring import BRACKETS, JUDGED_KINDS
from .bracket_table import four_digits
from .spec import PROFILES

__all__ = ["scored_rows", "tier_counts", "TIER_WORDS", "bracket_headline", "leniency_note", "findings_markdown",
           "write_findings", "findings_links", "md_cell", "one_screen", "one_screen_markdown", "FINDINGS_SUFFIX"]

FINDINGS_SUFFIX = "-findings.md"

#: How the headline and the pages name each tier (:data:`~locbook.reproduce.scoring.BRACKETS`).
TIER_WORDS = {
    "default": "reproduced under the default interpretation",
    "other_interpretation": "reproduced only under another textual (or assumed) interpretation",
    "fitted_only": "reached only under an interpretation fitted to printed output (a calibration, not a reproduction)",
    "between": "between interpretations (the printed value inside the band of our values, no single interpretation "
               "within)",
    "outside": "outside every declared interpretation (beyond the band by more than both Monte-Carlo errors)",
    "open": "open (a setting that could matter is not swept, a point did not run, or Monte-Carlo error could "
            "close the gap)",
    "loose": "loose under every interpretation (a window too wide to decide)",
}
_SHORT = {"default": "default", "other_interpretation": "other interpretation", "fitted_only": "fitted only",
          "between": "between", "outside": "outside", "open": "open", "loose": "loose"}


def _tiers() -> tuple[str, ...]:
    return BRACKETS


def scored_rows(rows) -> list[dict]:
    """The rows a bracket judges: reproduction, calibrated and claim rows with a within / loose / miss verdict,
    each printed quantity once (rows linked to another by ``same_as`` left out)."""
    return [r for r in rows if r.get("kind") in JUDGED_KINDS and not r.get("same_as")
            and r.get("verdict") in ("within", "loose", "miss")]


def tier_counts(rows) -> dict | None:
    """``{"n": scored rows, <tier>: rows, ..., "none": rows not bracketed}`` over :func:`scored_rows`, or None
    when no row has a bracket verdict."""
    scored = scored_rows(rows)
    # a tier name that is not today's (a copied older numbers.csv) is no verdict: counted as not bracketed, so the
    # parts always add up to the scored rows
    c = Counter(r.get("bracket", "") if r.get("bracket", "") in _tiers() else "" for r in scored)
    if not any(c[t] for t in _tiers()):
        return None
    return {"n": len(scored), **{t: c[t] for t in _tiers()}, "none": c[""]}


def leniency_note(profile: str) -> str:
    """What a profile's verdicts mean beside the judged full profile's ('' for the full profile)."""
    if profile == "full" or profile not in PROFILES:
        return ""
    return (f"**This is the `{profile}` profile: it runs fewer Monte-Carlo runs than the judged `full` profile, so "
            "its windows (2 standard errors each) are wider and more rows fall within them.** Its verdicts are a "
            "check that everything runs, not findings to cite: cite `reports/full`.")


def bracket_headline(rows, profile: str = "full") -> str:
    """The tier tally of ``rows`` as one Markdown paragraph ('' when nothing is bracketed)."""
    b = tier_counts(rows)
    if b is None:
        return ""
    parts = [f"{b[t]} {TIER_WORDS[t]}" for t in _tiers()]
    return (f"**Interpretation brackets of the {b['n']} scored rows" + (f" (`{profile}` profile)" if profile else "")
            + ": " + "; ".join(parts)
            + f"; {b['none']} not bracketed.** Each interpretation is judged by its own run (`locbook bracket`), named "
            "in the `bracket_interpretations` column of numbers.csv; the findings page of each document lists the rows "
            "of every tier.")


def md_cell(text) -> str:
    """Text in one Markdown table cell or heading: HTML shown as text (a claims or interpretations file may be
    anyone's), on one line, "|" escaped."""
    return markdown_text(str(text)).replace("\r", " ").replace("\n", " ").replace("|", "\\|")


def _reason_of(row: dict) -> str:
    """The text a row's tier rests on, without the run profile prefix (rows sharing it are listed together)."""
    text = row.get("bracket_interpretations", "") or "(no interpretation named)"
    return re.sub(r"^at [a-z]+: ", "", text)


def findings_markdown(document: str, authors: str, year, doc_rows: list[dict], profile: str) -> str:
    """The findings page of ``document`` from its rows of a reports folder: the tally (the same as numbers.csv's
    and the index's), then each tier but ``default``, its rows grouped by the reason they share (written once)."""
    b = tier_counts(doc_rows) or {"n": 0, **{t: 0 for t in _tiers()}, "none": 0}
    scored = scored_rows(doc_rows)
    lines = [f"# Findings: {md_cell(authors)} ({year}), `{document}`", "",
             (f"Profile `{profile}`. " if profile else "") + f"Scored rows: {b['n']}: "
             + "; ".join(f"{_SHORT[t]} {b[t]}" for t in _tiers())
             + f"; not bracketed {b['none']}. These counts are those of numbers.csv and of the index (one table).",
             ""]
    if leniency_note(profile):
        lines += [leniency_note(profile), ""]
    lines += ["| tier | rows | meaning |", "|---|---|---|"]
    lines += [f"| {_SHORT[t]} | {b[t]} | {TIER_WORDS[t]} |" for t in _tiers()]
    lines.append("")
    for tier in _tiers():
        if tier == "default":
            continue
        chosen = [r for r in scored if r.get("bracket") == tier]     # (tier_counts' count of the tier)
        lines += [f"## {_SHORT[tier].capitalize()} ({len(chosen)})", "", TIER_WORDS[tier].capitalize() + ".", ""]
        if not chosen:
            lines += ["None.", ""]
            continue
        groups: dict[str, list[dict]] = defaultdict(list)
        for r in chosen:
            groups[_reason_of(r)].append(r)
        for reason, members in sorted(groups.items(), key=lambda g: (-len(g[1]), g[0])):
            lines += [f"**{md_cell(reason)}** ({len(members)} row{'s' if len(members) != 1 else ''})", ""]
            table = ["| experiment | printed quantity | printed | ours (default) | verdict |", "|---|---|---|---|---|"]
            table += [f"| {md_cell(r['experiment'])} | {md_cell(r['printed_id'])} | {md_cell(r['printed'])} | "
                      f"{md_cell(_short(r.get('reproduced', '')))} | {md_cell(r['verdict'])} |" for r in members]
            if len(members) > 6:      # a long list folds (GitHub renders <details>)
                lines += ["<details><summary>the rows</summary>", ""] + table + ["", "</details>", ""]
            else:
                lines += table + [""]
    return "\n".join(lines) + "\n"


def write_findings(report_dir: Path, entries, rows, profile: str, write) -> list[tuple[str, str]]:
    """Write ``<report_dir>/<document>-findings.md`` for every document with bracketed rows (``write(path, text)``
    writes atomically) and remove the pages of documents no longer bracketed; returns (document, file name)."""
    out = []
    for key, doc, doc_rows in by_document(entries, rows):
        path = Path(report_dir) / f"{key}{FINDINGS_SUFFIX}"
        if tier_counts(doc_rows) is None:
            if path.is_file():
                path.unlink()
            continue
        write(path, findings_markdown(key, doc.authors, doc.year, doc_rows, profile))
        out.append((key, path.name))
    return out


def findings_links(report_dir: Path) -> list[tuple[str, str]]:
    """(document, file name) of the findings pages in a reports folder."""
    return [(p.name[:-len(FINDINGS_SUFFIX)], p.name) for p in sorted(Path(report_dir).glob(f"*{FINDINGS_SUFFIX}"))]


def _interpretation_names(text: str) -> list[str]:
    """The interpretations a ``bracket_interpretations`` text of a reached row names, each as ``parameter=value`` (a
    joint point as its label)."""
    text = re.sub(r"^at [a-z]+: ", "", text or "")
    names = []
    for part in text.split("; "):
        head, _, value = part.partition(": ")
        names.append(part.strip() if head.endswith("together") or head.endswith("together [fitted]")
                     else (value.strip() or head.strip()))
    return [n for n in names if n]


def _short(text) -> str:
    return four_digits(str(text))


def first_clause(note: str, limit: int = 160) -> str:
    """A note's first sentence (or clause), at most ``limit`` characters."""
    first = re.split(r"(?<=[.;])\s", note.strip(), maxsplit=1)[0].rstrip(".;")
    return first if len(first) <= limit else first[:limit].rsplit(" ", 1)[0] + " ..."


def profile_of(report_dir: Path) -> str:
    """The profile whose reports a folder holds (``reports/quick``; ``reports/full/data-x`` is the full profile's),
    '' for another folder (a ``-p`` run's, ``--out``)."""
    folder = Path(report_dir)
    return next((f.name for f in (folder, folder.parent) if f.name in PROFILES), "")


def by_document(entries, rows):
    """(document key, document, its rows) per document of ``entries``, in the order they first appear."""
    docs = {}
    for e in entries:
        docs.setdefault(e["exp"].document.key, e["exp"].document)
    return [(key, doc, [r for r in rows if r.get("document") == key]) for key, doc in docs.items()]


def one_screen(entries, rows, conclusions: dict | None = None) -> list[dict]:
    """Per document with scored rows: ``{"key", "authors", "year", "counts" (tier -> rows), "sentences"}``: how
    many printed numbers are reproduced by tier, which conclusions hold and fail (``conclusions``: document ->
    {"holds": [...], "fails": [...], "undecidable": n}), and the one reason that explains most of the rest."""
    out = []
    for key, doc, doc_rows in by_document(entries, rows):
        scored = scored_rows(doc_rows)
        if not scored:
            continue
        b = tier_counts(doc_rows)
        counts = {t: (b or {}).get(t, 0) for t in _tiers()}
        n = len(scored)
        sentences = []
        if b is None:
            within = sum(r["verdict"] == "within" for r in scored)
            sentences.append(f"{within} of {n} scored printed numbers are within their window (no bracket ran).")
        else:
            sentences.append(f"Of {n} scored printed numbers, {counts['default']} are reproduced under the default "
                             f"interpretation and {counts['other_interpretation']} more under another textual (or "
                             f"assumed) interpretation; {counts['fitted_only']} only under a fitted one, "
                             f"{counts['between']} lie between interpretations, {counts['outside']} outside every "
                             f"interpretation, {counts['open']} are open, {counts['loose']} loose and {b['none']} not "
                             "bracketed.")
        rest = [r for r in scored if r.get("bracket") not in ("default", "")] if b else \
            [r for r in scored if r["verdict"] != "within"]
        reached = Counter(name for r in rest if r.get("bracket") in ("other_interpretation", "fitted_only")
                          for name in dict.fromkeys(_interpretation_names(r.get("bracket_interpretations", ""))))
        notes = Counter(first_clause(r.get("note", ""), 140) for r in rest if (r.get("note") or "").strip())
        if reached and reached.most_common(1)[0][1] >= max(notes.most_common(1)[0][1] if notes else 0, 1):
            name, k = reached.most_common(1)[0]
            sentences.append(f"The interpretation that reaches the most of the rest: {name} ({k} of the {len(rest)} "
                             "rows not reproduced by default).")
        elif notes:
            why, k = notes.most_common(1)[0]
            sentences.append(f"The reason given most often for the rest ({k} of {len(rest)} rows): {why}.")
        c = (conclusions or {}).get(key)
        if c:
            sentences.append(f"Conclusions (claims of the source judged from our rows): {len(c['holds'])} hold, "
                             f"{len(c['fails'])} fail, {c['undecidable']} cannot be decided"
                             + (f"; holding, e.g.: {', '.join(c['holds'][:3])}" if c["holds"] else "")
                             + (f"; failing, e.g.: {', '.join(c['fails'][:3])}" if c["fails"] else "")
                             + f" (the {key} conclusions page lists every one).")
        out.append({"key": key, "authors": doc.authors, "year": doc.year, "counts": counts, "n": n,
                    "sentences": sentences})
    return out


def one_screen_markdown(answers: list[dict], profile: str) -> list[str]:
    """The one-screen answer as Markdown lines (a paragraph per document, then one small table)."""
    if not answers:
        return []
    lines = ["## The answer, per document", ""]
    if leniency_note(profile):
        lines += [leniency_note(profile), ""]
    for a in answers:
        lines += [f"- **{md_cell(a['authors'])} ({a['year']})**, `{a['key']}`: "
                  + markdown_text(" ".join(a["sentences"]))]
    lines += ["", "| document | scored | " + " | ".join(_SHORT[t] for t in _tiers()) + " |",
              "|---|---|" + "---|" * len(_tiers())]
    lines += [f"| `{a['key']}` | {a['n']} | " + " | ".join(str(a["counts"][t]) for t in _tiers()) + " |"
              for a in answers]
    return lines + [""]
