"""Each document's conclusions page: every claim it states (``locbook/data/claims/<document>.csv``,
:mod:`locbook.reproduce.claims`) judged from the rows of a reports folder.

Per claim: does the source's own printed table support it; does it hold, fail or stay undecidable on our values
under the default interpretation; and does that verdict hold under every other interpretation its brackets ran (each
point's values from ``<reports>/brackets/<experiment>/values.csv``), naming the interpretations that change it.
Ambiguous wording (with the test under the other interpretation) and the source's own inconsistencies are shown beside
the claim.
"""
from __future__ import annotations

from collections import defaultdict
from pathlib import Path

from ..reproduce.claims import Claim, ClaimsError, Value, claims, evaluate, outcome_word
from ..reproduce.printed_values import printed_number
from .bracket_table import brackets_root, load_values, same_number
from .findings import by_document, md_cell, profile_of
from .spec import finite_float

__all__ = ["judge_claim", "conclusions_markdown", "write_conclusions", "CONCLUSIONS_SUFFIX"]

CONCLUSIONS_SUFFIX = "-conclusions.md"


def _rows_by_id(rows) -> dict[tuple[str, str], dict]:
    return {(r.get("experiment", ""), r.get("printed_id", "")): r for r in rows}


def _ours(row: dict) -> Value | None:
    v = finite_float(row.get("reproduced", ""))
    if v is None and row.get("kind") != "claim":
        return None
    se = finite_float(row.get("mc_std_error", "")) or 0.0
    return Value(v if v is not None else float("nan"), se, row.get("verdict", ""))


def _printed(row: dict) -> Value | None:
    try:
        return Value(printed_number(row.get("printed", "")))
    except ValueError:
        return None


def _env(claim: Claim, by_id: dict, pick) -> dict | str:
    """Evidence name -> Value under ``pick`` (a row -> Value or None), or the reason it cannot be built."""
    env = {}
    for name, key in claim.evidence.items():
        row = by_id.get(key)
        if row is None:
            return f"row {key[0]} | {key[1]} is not in this folder's numbers.csv"
        value = pick(row)
        if value is None:
            return f"row {key[0]} | {key[1]} has no value"
        env[name] = value
    return env


def _outcome(test: str, env):
    if isinstance(env, str) or not test:
        return None
    try:
        return evaluate(test, env)
    except (ClaimsError, ArithmeticError, ValueError):     # (a test is type-checked when its file loads)
        return None


def _primary(rows) -> dict[tuple[str, str], tuple[str, str]]:
    """(document, printed_id) -> (experiment, printed_id) of the row where each printed quantity is compared (not a
    linked repeat)."""
    return {(r.get("document", ""), r.get("printed_id", "")): (r.get("experiment", ""), r.get("printed_id", ""))
            for r in rows if not r.get("same_as")}


def judge_claim(claim: Claim, by_id: dict, values_by_experiment: dict[str, list[dict]],
                primary: dict | None = None) -> dict:
    """The verdicts of one claim: ``printed`` and ``ours`` (True / False / None), ``why`` (when it cannot be
    judged), ``alt`` (ours under the other interpretation of ambiguous wording), ``interpretations`` (how many other
    bracket points were judged) and ``changed_by`` (the points whose verdict differs from the default's, with their
    basis)."""
    out = {"claim": claim, "printed": None, "ours": None, "why": "", "alt": None, "interpretations": 0,
           "changed_by": [], "printed_na": False, "not_judged": []}
    if not claim.testable:
        out["why"] = claim.note or "no row measures it"
        return out
    ours_env = _env(claim, by_id, _ours)
    printed_env = _env(claim, by_id, _printed)
    out["printed_na"] = isinstance(printed_env, str)     # a claim row, or a printed text without one number
    out["printed"] = _outcome(claim.test, printed_env)
    out["ours"] = _outcome(claim.test, ours_env)
    out["alt"] = _outcome(claim.alt_test, ours_env) if claim.alt_test else None
    if isinstance(ours_env, str):
        out["why"] = ours_env
        return out
    # under each other interpretation: the evidence rows take the point's values, a linked row (same_as) its master's,
    # wherever the master was compared (another experiment of the document); a point that lacks one of the rows
    # does not judge the claim
    primary = primary if primary is not None else _primary(by_id.values())

    def master(row):
        if row.get("same_as"):
            return primary.get((row.get("document", ""), row["same_as"]), (row.get("experiment", ""), row["same_as"]))
        return (row.get("experiment", ""), row.get("printed_id", ""))
    rows = [by_id[key] for key in claim.evidence.values()]
    masters = {master(row) for row in rows}
    for exp in sorted({key[0] for key in masters}):
        mine = [row for row in rows if master(row)[0] == exp]
        default = {(exp, v["printed_id"]): v for v in values_by_experiment.get(exp, []) if v["basis"] == "default"}
        if not default:
            continue
        # the bracket's default run must be this report's: else it was made at another profile or by other code
        if any(master(row) in default and not same_number(default[master(row)]["ours"], row.get("reproduced"))
               for row in mine):
            out["not_judged"].append(f"{exp}: its bracket's default run differs from this report (another profile "
                                     "or other code), so the other interpretations are not judged here")
            continue
        points = defaultdict(dict)
        labels = {}
        for v in values_by_experiment.get(exp, []):
            if v["basis"] == "default":
                continue
            points[v["point"]][(exp, v["printed_id"])] = v
            labels[v["point"]] = (v["interpretation"], v["basis"])
        for point, table in points.items():
            if any(master(row) not in table for row in mine):
                continue

            def pick(row, table=table):
                alt = table.get(master(row))
                if alt is None:          # a row of another experiment: its default value
                    return _ours(row)
                return _ours({"reproduced": alt["ours"], "mc_std_error": alt["mc_std_error"],
                              "verdict": alt["verdict"], "kind": row.get("kind", "")})
            outcome = _outcome(claim.test, _env(claim, by_id, pick))
            out["interpretations"] += 1
            if outcome != out["ours"]:
                label, basis = labels[point]
                out["changed_by"].append(f"{exp}, {label} [{basis}]: {outcome_word(outcome)}")
    return out


def _robust(j: dict) -> str:
    if j["ours"] is None and not j["interpretations"]:
        return "-"
    if not j["interpretations"]:
        return "no bracket ran"
    textual = [c for c in j["changed_by"] if "[fitted]" not in c]
    if not textual:
        return f"same under all {j['interpretations']} other interpretations" + (
            "" if not j["changed_by"] else f" but {len(j['changed_by'])} fitted")
    return "changes under " + "; ".join(textual)


def conclusions_markdown(document: str, authors: str, year, judged: list[dict], profile: str) -> str:
    """The conclusions page of one document from its judged claims (:func:`judge_claim`)."""
    holds = sum(j["ours"] is True for j in judged)
    fails = sum(j["ours"] is False for j in judged)
    lines = [f"# Conclusions: {md_cell(authors)} ({year}), `{document}`", "",
             (f"Profile `{profile}`. " if profile else "")
             + f"{len(judged)} claims and conclusions of the source, each judged from the rows of numbers.csv: "
             f"{holds} hold, {fails} fail and {len(judged) - holds - fails} are undecidable under the default "
             "interpretation (a comparison is decided only beyond two standard errors of the difference of our values; "
             "the printed column applies the same test to the source's own printed numbers). The last column says "
             "whether the verdict survives every other interpretation the brackets ran.", "",
             "| claim | where | kind | printed numbers | ours (default) | under the other interpretations | notes |",
             "|---|---|---|---|---|---|---|"]
    for j in judged:
        c = j["claim"]
        notes = []
        if c.ambiguity:
            notes.append(f"**ambiguous**: {c.ambiguity} (other interpretation: {outcome_word(j['alt'])})")
        if c.inconsistency:
            notes.append(f"**source inconsistent**: {c.inconsistency}")
        if j["why"]:
            notes.append(j["why"])
        notes += j.get("not_judged", [])
        if c.note and c.note != j["why"]:
            notes.append(c.note)
        evidence = ", ".join(f"{name}: {exp} | {pid}" for name, (exp, pid) in c.evidence.items())
        lines.append(f"| `{c.id}`: {md_cell(c.claim)} | {md_cell(c.location)} | {c.kind} | "
                     f"{'-' if not c.testable or j.get('printed_na') else outcome_word(j['printed'])} | "
                     f"{outcome_word(j['ours']) if c.testable else 'untested'} | {md_cell(_robust(j))} | "
                     f"{md_cell('; '.join(notes))}" + (f" (rows: {md_cell(evidence)})" if evidence else "") + " |")
    return "\n".join(lines) + "\n"


def write_conclusions(report_dir: Path, suite, entries, rows, write) -> dict:
    """Write ``<report_dir>/<document>-conclusions.md`` for every document with declared claims (``write(path,
    text)`` writes atomically); returns document -> {"holds", "fails" (claim texts), "undecidable" (count)} for
    the one-screen answer."""
    by_id = _rows_by_id(rows)
    out = {}
    for key, doc, _doc_rows in by_document(entries, rows):
        declared = claims(key)
        if not declared:
            continue
        primary = _primary(rows)
        values = {exp.id: load_values(brackets_root(report_dir) / exp.id) for exp in suite.experiments
                  if exp.document.key == key}
        judged = [judge_claim(c, by_id, values, primary) for c in declared]
        write(Path(report_dir) / f"{key}{CONCLUSIONS_SUFFIX}",
              conclusions_markdown(key, doc.authors, doc.year, judged, profile_of(report_dir)))
        out[key] = {"holds": [j["claim"].id for j in judged if j["ours"] is True],
                    "fails": [j["claim"].id for j in judged if j["ours"] is False],
                    "undecidable": sum(j["ours"] is None for j in judged)}
    return out
