"""One tally everywhere: the findings pages, numbers.csv and the index of a reports folder give the same
tier counts, read back from the files themselves."""
import csv
import re
from collections import Counter

import pytest

from builders import REPO_ROOT
from locbook.suite.bracket import BRACKETS
from locbook.suite.findings import (
    TIER_WORDS,
    bracket_headline,
    findings_markdown,
    leniency_note,
    scored_rows,
    tier_counts,
)

FULL = REPO_ROOT / "reports" / "full"
SHORT = {"default": "default", "other_interpretation": "other interpretation", "fitted_only": "fitted only",
         "between": "between",
         "outside": "outside", "open": "open", "loose": "loose"}


def _counter(rows):
    """The tiers of the scored rows, counted by hand from the columns (not through locbook.suite.findings)."""
    return Counter(r["bracket"] for r in rows if r["kind"] in ("reproduction", "calibrated", "claim")
                   and not r["same_as"] and r["verdict"] in ("within", "loose", "miss"))


def _headline_counts(text: str) -> dict:
    line = next(s for s in text.splitlines() if s.startswith("**Interpretation brackets of the"))
    out = {"n": int(re.search(r"of the (\d+) scored rows", line).group(1))}
    for tier in BRACKETS:
        out[tier] = int(re.search(r"(\d+) " + re.escape(TIER_WORDS[tier]), line).group(1))
    out["none"] = int(re.search(r"(\d+) not bracketed", line).group(1))
    return out


def _page_counts(text: str) -> dict:
    line = next(s for s in text.splitlines() if "Scored rows:" in s)
    out = {"n": int(re.search(r"Scored rows: (\d+)", line).group(1))}
    for tier in BRACKETS:
        out[tier] = int(re.search(re.escape(SHORT[tier]) + r" (\d+)", line).group(1))
    return out


def _rows(n_each=2):
    rows = []
    for i, tier in enumerate(BRACKETS + ("",)):
        for k in range(n_each + i % 2):
            rows.append({"experiment": "doc-x", "document": "doc", "printed_id": f"T | {tier} | {k}", "kind":
                         "reproduction", "same_as": "", "verdict": "within" if tier == "default" else "miss",
                         "bracket": tier, "bracket_interpretations": f"at full: r{k}: p={k}" if tier else "",
                         "printed": "1.0", "reproduced": "1.5", "note": ""})
    # not scored: a linked repeat and an arithmetic row
    rows.append({**rows[0], "same_as": "T | default | 0", "verdict": ""})
    rows.append({**rows[0], "kind": "arithmetic", "verdict": "consistent"})
    return rows


def test_the_headline_and_the_findings_page_count_the_same_rows():
    rows = _rows()
    hand = _counter(rows)
    want = {"n": sum(hand.values()), **{t: hand[t] for t in BRACKETS}, "none": hand[""]}
    assert tier_counts(rows) == want and len(scored_rows(rows)) == want["n"]
    assert sum(want[t] for t in BRACKETS) + want["none"] == want["n"]
    # a retired tier name (an older numbers.csv) counts as not bracketed: the parts still add up
    old = [{**r, "bracket": "reachable"} if r["bracket"] == "other_interpretation" else r for r in rows]
    got = tier_counts(old)
    assert got["other_interpretation"] == 0 and got["none"] == want["none"] + want["other_interpretation"]
    assert sum(got[t] for t in BRACKETS) + got["none"] == got["n"]
    assert _headline_counts(bracket_headline(rows, "full")) == want
    page = findings_markdown("doc", "A. Author", 2011, rows, "full")
    assert _page_counts(page) == {k: v for k, v in want.items() if k != "none"}
    # every tier but default has its section, headed by its count
    for tier in BRACKETS[1:]:
        assert f"## {SHORT[tier].capitalize()} ({hand[tier]})" in page


def test_only_the_quick_profile_is_called_lenient():
    assert "wider" in leniency_note("quick") and leniency_note("full") == "" and leniency_note("") == ""


@pytest.mark.skipif(not (FULL / "numbers.csv").is_file(), reason="no committed reports/full")
def test_the_committed_index_findings_and_numbers_agree():
    with open(FULL / "numbers.csv", newline="", encoding="utf-8") as fh:
        rows = list(csv.DictReader(fh))
    hand = _counter(rows)
    index = (FULL / "index.md").read_text(encoding="utf-8")
    got = _headline_counts(index)
    assert got == {"n": sum(hand.values()), **{t: hand[t] for t in BRACKETS}, "none": hand[""]}
    assert sum(got[t] for t in BRACKETS) + got["none"] == got["n"]
    pages = sorted(FULL.glob("*-findings.md"))
    assert pages
    # the pages add up to the index: a document without a page has no bracketed row
    with_page = {p.name[:-len("-findings.md")] for p in pages}
    unpaged = sum(_counter([r for r in rows if r["document"] not in with_page]).values())
    assert sum(_page_counts(p.read_text(encoding="utf-8"))["n"] for p in pages) + unpaged == got["n"]
    assert not any(_counter([r for r in rows if r["document"] not in with_page])[t] for t in BRACKETS)
    for page in pages:
        document = page.name[:-len("-findings.md")]
        mine = _counter([r for r in rows if r["document"] == document])
        assert _page_counts(page.read_text(encoding="utf-8")) == \
            {"n": sum(mine.values()), **{t: mine[t] for t in BRACKETS}}, document
        # the one-screen answer's table row of the document
        row = next(s for s in index.splitlines() if s.startswith(f"| `{document}` |"))
        cells = [c.strip() for c in row.strip("|").split("|")]
        assert [int(c) for c in cells[1:]] == [sum(mine.values())] + [mine[t] for t in BRACKETS], document
