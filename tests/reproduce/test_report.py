"""Report.number decides a row's note from the scoring rules' closed form: the miss note appears exactly
when our value lies outside printed +- (rounding + 2 SE + ambiguity) or a claim fails; the loose note exactly when the
value is inside a window wider than +-25 % of the printed value, or a claim holds but not beyond 2 SE."""
import math
from pathlib import Path

import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import locbook as lb

MISS = "the likely reason"
LOOSE = "why agreement says little here"


@pytest.fixture
def report(tmp_path, monkeypatch):
    monkeypatch.setenv("LOCBOOK_OUTPUT_DIR", str(tmp_path))
    monkeypatch.setenv("LOCBOOK_EXPERIMENT", "ozkaya2011-testbed")
    return lb.Report()


def _quantity():
    return lb.printed("ozkaya2011").get("Table 7.1", "28", "rmse_m")      # printed in metres, two decimals


@settings(max_examples=200, deadline=None)
@given(offset=st.floats(-3.0, 3.0), se=st.floats(0.0, 0.3), amb=st.floats(0.0, 0.5))
def test_miss_note_appears_exactly_outside_rounding_plus_two_se_plus_ambiguity(tmp_path_factory, offset, se, amb):
    import os
    os.environ["LOCBOOK_OUTPUT_DIR"] = str(tmp_path_factory.mktemp("r"))
    try:
        report = lb.Report("ozkaya2011-testbed")
    finally:
        del os.environ["LOCBOOK_OUTPUT_DIR"]
    p = _quantity()
    half = p.rounding + 2 * se + amb                # the window's closed form (scoring module docstring)
    assume(abs(abs(offset) - half) > 1e-9)          # not on the boundary
    ambiguity = lb.Ambiguity(amb, "cell layout", "Ozkaya 2011 Sec. 7.2.1") if amb > 0 else None
    row = report.number("rmse", p, p.value + offset, kind="reproduction", mc_std_error=se, ambiguity=ambiguity,
                        miss_note=MISS, loose_note=LOOSE)
    outside = abs(offset) > half
    wide = half / p.value > lb.reproduce.WITHIN_LIMIT
    assert (row["verdict"] == "miss") == outside
    assert (MISS in row["note"]) == outside
    assert (LOOSE in row["note"]) == (not outside and wide)
    if outside:
        assert row["note"] == MISS                  # nothing else to say about a miss
    elif wide:                                      # why it is loose comes first
        assert row["verdict"] == "loose" and row["note"].startswith("the window is") and row["note"].endswith(LOOSE)
    else:
        assert row["verdict"] == "within" and row["note"] == ""


def test_miss_note_comes_before_the_note_and_after_nothing_when_within(report):
    p = _quantity()
    row = report.number("rmse", p, p.value + 1.0, kind="reproduction", miss_note=MISS, loose_note=LOOSE,
                        note="3 runs flagged")
    assert row["verdict"] == "miss" and row["note"] == f"{MISS}; 3 runs flagged"
    row = report.number("rmse", p, p.value, kind="reproduction", miss_note=MISS, loose_note=LOOSE,
                        note="3 runs flagged")
    assert row["verdict"] == "within" and row["note"] == "3 runs flagged"


@pytest.mark.parametrize("relation", [">", ">=", "<", "<="])
@pytest.mark.parametrize("offset_in_se", [-3.0, -1.0, 1.0, 3.0])
def test_a_claims_notes_follow_whether_it_holds_and_whether_beyond_two_standard_errors(report, relation, offset_in_se):
    p = lb.printed("gudipati2017").get("Fig. 5.4 caption", "fusion versus individual sensors", "claim")
    se = 0.1
    ours = offset_in_se * se                         # against the threshold 0
    above = relation.startswith(">")
    holds = ours > 0 if above else ours < 0
    held_with_margin = (ours - 2 * se > 0) if above else (ours + 2 * se < 0)
    row = report.number("gain", p, ours, kind="claim", relation=relation, threshold=0.0, mc_std_error=se,
                        miss_note=MISS, loose_note=LOOSE)
    assert (MISS in row["note"]) == (not holds)
    assert (LOOSE in row["note"]) == (holds and not held_with_margin)
    assert (row["verdict"] == "within") == held_with_margin and (row["verdict"] == "miss") == (not holds)
    if row["verdict"] == "loose":                   # why it is loose comes first
        assert row["note"] == f"the claim holds for our estimate but not beyond 2 Monte-Carlo standard errors; {LOOSE}"


def test_an_inconsistent_arithmetic_row_takes_the_miss_note_and_a_linked_row_never_does(report):
    p = _quantity()
    row = report.number("mean", p, p.value + 2 * p.rounding, kind="arithmetic", miss_note=MISS, loose_note=LOOSE)
    assert row["verdict"] == "inconsistent" and row["note"] == MISS
    row = report.number("mean", p, p.value + 0.5 * p.rounding, kind="arithmetic", miss_note=MISS, loose_note=LOOSE)
    assert row["verdict"] == "consistent" and row["note"] == ""
    again = lb.printed("ozkaya2011").get("Table 7.5", "Default (5 m, 8 m)", "rmse_m")
    row = report.number("rmse", again, again.value + 5.0, kind="reproduction", same_as=p, miss_note=MISS,
                        loose_note=LOOSE)
    assert row["verdict"] == "" and row["note"] == f"the source prints this quantity again at {p.where}; compared there"
    assert math.isnan(row["window_high"])


def test_report_never_makes_the_runners_output_folder_again(tmp_path, monkeypatch):
    """Under locbook run the output folder is the run's staging, made by the runner and removed when it stops; a
    kernel that starts late must fail there, not make the folder (and the run's staging) again."""
    gone = tmp_path / "staging" / "george-one-1"
    monkeypatch.setenv("LOCBOOK_OUTPUT_DIR", str(gone))
    with pytest.raises(FileNotFoundError, match="not an existing folder"):
        lb.Report("toy")
    assert not (tmp_path / "staging").exists()


def test_an_interactive_session_writes_to_its_own_scratch_folder(tmp_path, monkeypatch):
    """Without LOCBOOK_OUTPUT_DIR (a notebook run in Jupyter) a Report writes under the system's temporary folder, in
    a folder of this session: two experiments of one session share it, another process (a second kernel) gets its
    own, and neither is under reports/."""
    import subprocess
    import sys
    import tempfile

    import locbook.reproduce.report as report_module
    monkeypatch.delenv("LOCBOOK_OUTPUT_DIR", raising=False)
    monkeypatch.delenv("LOCBOOK_EXPERIMENT", raising=False)
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr(tempfile, "tempdir", None)          # gettempdir() reads TMPDIR again
    monkeypatch.setattr(report_module, "_SESSION_DIR", None)
    a, b = lb.Report("exp-a"), lb.Report("exp-b")
    assert a.output_dir.parent == b.output_dir.parent and a.output_dir.name == "exp-a"
    session = a.output_dir.parent
    assert session.parent.parent == tmp_path and session.parent.name.startswith("locbook-interactive-")
    assert session.name.startswith("session-") and (a.output_dir / "manifest.json").is_file()
    other = subprocess.run([sys.executable, "-c", "import locbook as lb; print(lb.Report('exp-a').output_dir)"],
                           capture_output=True, text=True, check=True).stdout.strip()
    assert Path(other).parent.parent == session.parent and Path(other).parent != session


_SHOW_CODE = """
import json, os, sys
import matplotlib.pyplot as plt
import IPython.display
shown = []
IPython.display.display = lambda *objs, **kw: shown.extend(objs)
import locbook as lb
report = lb.Report("figure-check")
fig, ax = plt.subplots(figsize=(4, 3))
ax.plot([0, 1], [1, 0])
path = report.figure(fig, "line", "a line", dpi=110)
png = path.read_bytes()
print(json.dumps({"shown": [(type(o).__name__, o.data == png, o.width) for o in shown],
                  "open": plt.get_fignums(), "png_width": int.from_bytes(png[16:20], "big"),
                  "fig_dpi": fig.dpi, "backend": plt.get_backend()}))
"""


@pytest.mark.parametrize("under_runner", [True, False])
def test_under_the_runner_a_figure_is_drawn_once_and_the_cell_shows_the_saved_file(tmp_path, under_runner):
    """With matplotlib's inline backend (a kernel) and LOCBOOK_OUTPUT_DIR set (locbook run), Report.figure shows the
    PNG it saved, bytes for bytes, at the inline backend's displayed size (figure.dpi / dpi of its pixels), and closes
    the figure, so the inline backend draws nothing more; an interactive session keeps its figure open and shows
    nothing itself."""
    import json
    import os
    import subprocess
    import sys
    env = {**os.environ, "MPLBACKEND": "module://matplotlib_inline.backend_inline"}
    env.pop("LOCBOOK_OUTPUT_DIR", None)
    env.pop("LOCBOOK_EXPERIMENT", None)
    env["TMPDIR"] = str(tmp_path)
    if under_runner:
        env["LOCBOOK_OUTPUT_DIR"] = str(tmp_path)
    out = subprocess.run([sys.executable, "-c", _SHOW_CODE], capture_output=True, text=True, env=env, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert "inline" in got["backend"]
    if under_runner:
        assert got["png_width"] > 300
        assert got["shown"] == [["Image", True, round(got["png_width"] * got["fig_dpi"] / 110)]]
        assert got["open"] == []
    else:
        assert got["shown"] == [] and got["open"] == [1]


def _draw_and_save(folder: Path, monkeypatch):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    monkeypatch.setenv("LOCBOOK_OUTPUT_DIR", str(folder))
    report = lb.Report("exports")
    fig, ax = plt.subplots(figsize=(3, 2))
    ax.plot([0, 1, 2], [1, 0, 2], label="a")
    ax.plot([0, 1, 2], [2, 1, 0], label="b")
    ax.legend()
    report.figure(fig, "lines", "two lines")
    report.table("values", [{"name": "x_1", "value_m": 1.5, "note": "50% & $y$ {z} #1 ~ ^ \\"},
                            {"name": "y", "value_m": 2, "note": ""}], "values\nof things")
    plt.close(fig)
    return report


def test_every_figure_is_also_pdf_and_svg_with_the_same_bytes_from_identical_runs(tmp_path, monkeypatch):
    import json
    import xml.etree.ElementTree as ET
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    _draw_and_save(tmp_path / "a", monkeypatch)
    _draw_and_save(tmp_path / "b", monkeypatch)
    for ext in ("png", "pdf", "svg"):
        first, second = (tmp_path / "a" / f"lines.{ext}").read_bytes(), (tmp_path / "b" / f"lines.{ext}").read_bytes()
        assert first == second and len(first) > 500, ext
    pdf = (tmp_path / "a" / "lines.pdf").read_bytes()
    assert pdf.startswith(b"%PDF-") and pdf.rstrip().endswith(b"%%EOF") and b"CreationDate" not in pdf
    root = ET.parse(tmp_path / "a" / "lines.svg").getroot()
    assert root.tag == "{http://www.w3.org/2000/svg}svg"
    manifest = json.loads((tmp_path / "a" / "manifest.json").read_text())
    assert manifest["figures"][0]["exports"] == ["lines.pdf", "lines.svg"]
    assert manifest["tables"][0]["exports"] == ["values.tex"]


def _unlatex(cell: str) -> str:
    """The inverse of LaTeX's escapes of its ten special characters (written out here, not taken from locbook)."""
    for escaped, char in ((r"\textbackslash{}", "\\"), (r"\textasciitilde{}", "~"), (r"\textasciicircum{}", "^"),
                          (r"\&", "&"), (r"\%", "%"), (r"\$", "$"), (r"\#", "#"), (r"\_", "_"), (r"\{", "{"),
                          (r"\}", "}")):
        cell = cell.replace(escaped, char)
    return cell


def test_every_table_is_also_a_booktabs_latex_tabular_holding_the_csv_cells(tmp_path, monkeypatch):
    import csv
    _draw_and_save(tmp_path, monkeypatch)
    lines = (tmp_path / "values.tex").read_text(encoding="utf-8").splitlines()
    assert lines[0] == "% values of things"
    assert lines[1] == r"\begin{tabular}{lrl}"            # the all-number column right-aligned
    assert (lines[2], lines[4], lines[-2], lines[-1]) == (r"\toprule", r"\midrule", r"\bottomrule", r"\end{tabular}")
    body = [line.removesuffix(r" \\") for line in lines[5:-2]]
    # no unescaped special character is left: every &, %, $, #, _, {, } in a cell is preceded by a backslash
    for line in [lines[3], *body]:
        for i, ch in enumerate(line):
            if ch in "%$#_" or (ch == "&" and line[i - 1:i + 2] != " & "):
                assert line[i - 1] == "\\", (line, i)
    with open(tmp_path / "values.csv", newline="", encoding="utf-8") as fh:
        table = list(csv.reader(fh))
    parsed = [[_unlatex(c) for c in row.split(" & ")] for row in [lines[3].removesuffix(r" \\"), *body]]
    assert parsed == table


def test_a_report_draws_in_the_house_style_okabe_ito_palette(tmp_path, monkeypatch):
    import matplotlib
    monkeypatch.setenv("LOCBOOK_OUTPUT_DIR", str(tmp_path))
    lb.Report("style")
    # Okabe & Ito (2008), "Color Universal Design": the eight colours' sRGB values
    okabe_ito = {(0, 114, 178), (213, 94, 0), (0, 158, 115), (204, 121, 167), (230, 159, 0), (86, 180, 233),
                 (0, 0, 0), (240, 228, 66)}
    cycle = [matplotlib.colors.to_rgb(c["color"]) for c in matplotlib.rcParams["axes.prop_cycle"]]
    assert {tuple(round(255 * v) for v in rgb) for rgb in cycle} == okabe_ito and len(cycle) == 8


def test_a_dense_cloud_is_an_image_inside_the_vector_copies_and_a_sparse_one_stays_vector(tmp_path, monkeypatch):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from locbook.reproduce.report import DENSE_VERTICES
    monkeypatch.setenv("LOCBOOK_OUTPUT_DIR", str(tmp_path))
    report = lb.Report("dense")
    for name, n in (("dense", 20 * DENSE_VERTICES), ("sparse", 10)):
        fig, ax = plt.subplots()
        ax.scatter(*np.random.default_rng(0).normal(size=(2, n)), s=2)
        ax.set_xlabel("x (m)")
        report.figure(fig, name)
        plt.close(fig)
    dense, sparse = (tmp_path / "dense.svg").read_text(), (tmp_path / "sparse.svg").read_text()
    assert "<image" in dense and len(dense) < 400_000     # 60,000 markers would take megabytes as paths
    assert "<image" not in sparse
    assert "x (m)" in dense or "<g id=\"text_" in dense   # the axes' text stays vector (glyph paths)
    # a small cloud in each of 16 panels (each under the limit, together over it) is an image too; a short line
    # (200 vertices) beside it stays vector
    fig, axes = plt.subplots(4, 4)
    for ax in axes.flat:
        ax.scatter(*np.random.default_rng(1).normal(size=(2, DENSE_VERTICES // 4)), s=2)
        ax.plot(np.linspace(0, 1, 200), "r-")
    report.figure(fig, "panels")
    plt.close(fig)
    panels = (tmp_path / "panels.svg").read_text()
    assert panels.count("<image") == 16 and len(panels) < 400_000
