"""The committed scoreboard (reports/full) follows the rules of locbook/reproduce/scoring.py."""
import csv
import json

import pytest

import locbook as lb
from builders import REPO_ROOT
from locbook.reproduce.scoring import JUDGED_KINDS, KINDS, WITHIN_LIMIT
from locbook.suite import load_suite
from locbook.suite.bracket import BRACKETS, SITE_NUMBER_COLUMNS, load_bracket
from locbook.suite.site import double_counted

FULL = REPO_ROOT / "reports" / "full"


@pytest.fixture(scope="module")
def rows():
    with open(FULL / "numbers.csv", newline="") as fh:
        reader = csv.DictReader(fh)
        # an experiment's columns, then each row's reading bracket (locbook bracket)
        assert tuple(reader.fieldnames) == SITE_NUMBER_COLUMNS
        return list(reader)


def test_every_row_has_a_kind_and_calibrated_rows_name_their_input(rows):
    assert rows
    for r in rows:
        assert r["kind"] in KINDS, r
        if r["kind"] == "calibrated":
            assert r["calibrated_from"].strip(), r
        if r["verdict"] in ("within", "loose", "miss"):
            assert r["kind"] in JUDGED_KINDS, r


def test_printed_values_appear_exactly_as_printed(rows):
    for r in rows:
        p = lb.printed(r["document"]).get(*r["printed_id"].split(" | "))
        assert r["printed"] == p.text and r["where"] == p.where, r


def test_no_within_window_is_wider_than_a_quarter_of_the_printed_value(rows):
    for r in rows:
        if r["verdict"] == "within" and r["kind"] != "claim":
            value = lb.printed(r["document"]).get(*r["printed_id"].split(" | ")).value
            # window_low may be clipped at 0 for errors in metres: use the upper half-width
            half = float(r["window_high"]) - value
            assert half <= WITHIN_LIMIT * abs(value) * (1 + 1e-9), r


def test_each_printed_quantity_is_counted_once_and_links_resolve(rows):
    assert double_counted(rows) == []
    judged = {(r["document"], r["printed_id"]) for r in rows if r["verdict"] and not r["same_as"]}
    for r in rows:
        if r["same_as"]:
            assert (r["document"], r["same_as"]) in judged, r


def test_every_miss_and_loose_row_has_a_note(rows):
    for r in rows:
        if r["verdict"] in ("miss", "loose", "inconsistent"):
            assert r["note"].strip(), r


def test_committed_reports_are_stamped_with_a_commit_and_never_from_a_dirty_tree():
    suite = load_suite()
    for exp in suite.experiments:
        stamp = json.loads((FULL / exp.id / "report.json").read_text())["locbook"]
        assert "(source " in stamp and "uncommitted" not in stamp, (exp.id, stamp)


def test_every_miss_and_loose_reproduction_or_calibrated_row_has_a_bracket_verdict(rows):
    """The committed brackets (reports/brackets) cover every reproduction or calibrated row that is not
    within, each verdict naming its evidence; a within row is 'default' wherever a bracket covers it."""
    for r in rows:
        if r["kind"] in ("reproduction", "calibrated") and r["verdict"] in ("miss", "loose") and not r["same_as"]:
            assert r["bracket"] in BRACKETS and r["bracket"] != "default", r
            assert r["bracket_interpretations"].strip(), r
        if r["bracket"] == "default":
            assert r["verdict"] == "within", r


def test_the_committed_brackets_are_complete_and_from_committed_code():
    folder = FULL.parent / "brackets"
    for points_csv in sorted(folder.glob("*/points.csv")):
        # bracket.csv beside it, readable (header only for an experiment without scored rows)
        from locbook.suite.bracket_table import BRACKET_COLUMNS, read_table
        assert read_table(points_csv.parent / "bracket.csv", BRACKET_COLUMNS) is not None, points_csv.parent
        with open(points_csv, newline="") as fh:
            points = list(csv.DictReader(fh))
        assert points and points[0]["status"] in ("ok", "cached"), points_csv        # the default point ran
        assert all(p["generated_by"] and "uncommitted" not in p["generated_by"]
                   for p in points if p["status"] in ("ok", "cached")), points_csv
        assert not any(p["interpretations_file"] for p in points), points_csv     # the packaged readings only
        # every point at the full profile's run count, so a verdict survives its Monte-Carlo error
        assert {b["profile"] for b in load_bracket(points_csv.parent)} <= {"full"}, points_csv
        assert (points_csv.parent / "values.csv").is_file(), points_csv


def test_no_outside_row_rests_on_a_margin_monte_carlo_error_could_close(rows):
    """An outside row names its margin, and the printed value clears it."""
    folder = FULL.parent / "brackets"
    for bracket_csv in sorted(folder.glob("*/bracket.csv")):
        for b in load_bracket(bracket_csv.parent):
            if b["bracket"] == "outside":
                assert "beyond its margin" in b["outside_margin"], b


def test_every_experiment_with_compared_numbers_gets_printed_versus_ours_figures(rows):
    """An experiment page shows, per printed table, ours against printed: one point per scored number (a
    reproduction or calibrated row with a verdict, repeats left out), in its verdict's class; an experiment with such
    rows gets at least one figure, one without gets none. The count is the scoreboard's, not the figure code's."""
    import re
    from collections import Counter

    from locbook.suite.site import printed_versus_ours

    by_experiment = {}
    for r in rows:
        by_experiment.setdefault(r["experiment"], []).append(r)
    for experiment, numbers in by_experiment.items():
        scored = Counter(r["verdict"] for r in numbers if r["kind"] in ("reproduction", "calibrated")
                         and not r["same_as"] and r["verdict"] in ("within", "loose", "miss"))
        plots = printed_versus_ours(numbers)
        dots = Counter(v for p in plots for v in re.findall(r'<g class="v-(\w+)"><title>', p["svg"]))
        assert dots == scored, experiment                                   # every scored row, in its verdict
        assert sum(p["n"] for p in plots) == sum(scored.values()) and bool(plots) == bool(scored), experiment
        for p in plots:
            assert p["svg"].startswith("<svg") and p["svg"].endswith("</svg>")
            assert len(re.findall(r'r="3.5" class="ours"', p["svg"])) == p["n"], (experiment, p["title"])
    table = printed_versus_ours(by_experiment["ozkaya2011-nn-sim"])[0]
    assert table["title"] == "Table 7.1 (m)" and table["n"] == 35


def test_the_index_opens_with_findings_generated_from_the_rows(rows):
    """Per document, a few sentences from its rows: the counts of the scoreboard and the notes of the most
    missed rows."""
    from collections import Counter

    from locbook.suite.site import findings_summary
    suite = load_suite(REPO_ROOT / "notebooks" / "experiments.toml")
    entries = [{"exp": e, "numbers": [r for r in rows if r["experiment"] == e.id]} for e in suite.experiments]
    found = {f["key"]: f["text"] for f in findings_summary(entries, rows)}
    assert set(found) == {"george", "ozkaya2011", "dogan2015", "gudipati2017", "palvai2008"}
    for key, text in found.items():
        counted = [r for r in rows if r["document"] == key and not r["same_as"]]
        rep = Counter(r["verdict"] for r in counted if r["kind"] == "reproduction")
        if rep:
            assert (f"Of {sum(rep.values())} printed numbers reproduced independently, {rep['within']} are within "
                    f"their window, {rep['loose']} loose") in text and f"and {rep['miss']} missed." in text, key
        notes = Counter(r["note"] for r in counted if r["verdict"] == "miss" and r["note"])
        if notes:
            assert "The likely reasons of most misses: " in text, key


def test_a_pages_repeated_notes_are_shown_once_and_every_reference_resolves(rows):
    """The windows' bases and the notes, repeated on every row, are numbered once below the table; each
    cell links to its note, long ones folded."""
    import re

    from locbook.suite import site
    suite = load_suite(REPO_ROOT / "notebooks" / "experiments.toml")
    exp = next(e for e in suite.experiments if e.id == "dogan2015-tracking")
    numbers = [r for r in rows if r["experiment"] == exp.id]
    page = site.page_html(exp, "full", {}, FULL / exp.id, numbers, "test")
    columns = ("ambiguity_basis", "calibrated_from", "bracket_interpretations", "note")
    texts = {r[c].strip() for r in numbers for c in columns if r[c].strip()}
    notes = re.findall(r'<li id="fn-(\d+)" value="\1">', page)
    assert sorted(map(int, notes)) == list(range(1, len(texts) + 1))
    assert set(re.findall(r'href="#fn-(\d+)"', page)) <= set(notes)
    assert len(re.findall(r'class="fn"', page)) == sum(1 for r in numbers for c in columns if r[c].strip())
    assert "<details><summary>" in page                       # the long notes are folded


def test_every_committed_figure_is_png_pdf_and_svg_and_every_table_csv_and_latex():
    """reports/full holds what a paper takes: each figure as PNG, PDF and SVG, each table as CSV and LaTeX (a report
    folder is one holding report.md, also those of the committed data set's experiments)."""
    import xml.etree.ElementTree as ET
    folders = sorted(p.parent for p in FULL.rglob("report.md"))
    assert len(folders) >= len(load_suite(REPO_ROOT / "notebooks" / "experiments.toml").experiments)
    missing, figures, tables = [], 0, 0
    for folder in folders:
        for png in folder.glob("*.png"):
            figures += 1
            missing += [str(png.with_suffix(s).relative_to(FULL)) for s in (".pdf", ".svg")
                        if not png.with_suffix(s).is_file()]
        for table in folder.glob("*.csv"):
            tables += 1
            if not table.with_suffix(".tex").is_file():
                missing.append(str(table.with_suffix(".tex").relative_to(FULL)))
    assert missing == [] and figures >= 80 and tables >= 200, (missing[:10], figures, tables)
    some = next(iter(sorted(FULL.rglob("*.pdf"))))
    assert some.read_bytes().startswith(b"%PDF-")
    assert ET.parse(some.with_suffix(".svg")).getroot().tag == "{http://www.w3.org/2000/svg}svg"
    tex = (FULL / "george-tracking" / "numbers.tex").read_text(encoding="utf-8")
    assert tex.count(r"\toprule") == tex.count(r"\bottomrule") == 1 and "\\begin{tabular}" in tex


def test_the_committed_markdown_pages_show_their_plots(rows):
    """A reader of the repository sees the plots: every image a committed report.md embeds is committed beside it,
    and each experiment with scored rows embeds its printed-versus-ours plots."""
    import re

    from locbook.suite.site import printed_versus_ours
    scored = {e for e in {r["experiment"] for r in rows}
              if printed_versus_ours([r for r in rows if r["experiment"] == e])}      # a number printed as a number
    for page in sorted(FULL.rglob("report.md")):
        images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", page.read_text(encoding="utf-8"))
        assert all((page.parent / name).is_file() for name in images), (page, images)
        if page.parent.name in scored and page.parent.parent == FULL:
            assert "printed-versus-ours-1.svg" in images, page
