"""Every benchmark module keeps working: each ``benchmarks/bench_*.py`` (discovered, so none rots) runs
its ``run("tiny")`` and yields rows of the harness's protocol with finite positive times, and ``benchmarks/run_all.py``
writes the Markdown table, reporting a failing benchmark as an error row instead of stopping, and keeps a complete
table intact while a run is under way. The harness's paired measurement is checked on two calls of known cost."""
import math
import sys

import pytest

from builders import REPO_ROOT

BENCH = REPO_ROOT / "benchmarks"
sys.path.insert(0, str(BENCH))
import _harness as harness  # noqa: E402
import run_all  # noqa: E402

MODULES = run_all.discover(BENCH)


def test_the_benchmarks_are_discovered():
    names = {p.stem for p in MODULES}
    assert {"bench_dogan_filters", "bench_ukf_speed", "bench_bayes_filters", "bench_palvai", "bench_path_loss_fit",
            "bench_real_data", "bench_static_localization", "bench_ukf_stability", "bench_startup"} <= names


def _positive(value):
    return isinstance(value, (int, float)) and math.isfinite(value) and value > 0


@pytest.mark.slow
@pytest.mark.parametrize("path", MODULES, ids=[p.stem for p in MODULES])
def test_tiny_run_gives_protocol_rows(path):
    module = run_all.load(path)
    rows = list(module.run("tiny"))
    assert run_all.check_rows(rows) == []
    for r in rows:
        assert set(run_all.KEYS) <= set(r), r
        assert isinstance(r["method"], str) and r["method"] and isinstance(r["workload"], str)
        assert _positive(r["locbook_s"]), r
        if r["reference_s"] is None:
            assert r["ratio"] is None
        else:
            assert isinstance(r["reference"], str) and r["reference"]
            assert _positive(r["reference_s"]), r
            assert r["ratio"] == pytest.approx(r["reference_s"] / r["locbook_s"])
            assert r["ratio_cpu"] == pytest.approx(r["reference_cpu_s"] / r["locbook_cpu_s"])
            assert r["repeats"] >= harness.MIN_REPEATS        # every ratio from paired, alternated repeats
        assert r["peak_mb"] is None or (math.isfinite(r["peak_mb"]) and r["peak_mb"] >= 0)
        assert isinstance(r["note"], str)
        assert not str(r["agreement"]).startswith("DISAGREE"), r          # the same run's results agree


def test_run_all_writes_a_table_and_reports_a_failing_benchmark(tmp_path):
    folder = tmp_path / "benchmarks"
    folder.mkdir()
    (folder / "bench_fine.py").write_text(
        "import _harness as hx\n"
        "def run(size='full'):\n"
        "    m = hx.Measurement(0.5, 0.4, (0.5, 0.6), 5, 0.1, 2.0, 2.0, None, 1.0, 'max |d| 0', (0.5, 0.5))\n"
        "    yield hx.row('sum', '3 numbers', m, 'by hand', goal=3, note='a | b')\n")
    (folder / "_harness.py").write_text((BENCH / "_harness.py").read_text())
    (folder / "bench_broken.py").write_text("def run(size='full'):\n    raise RuntimeError('no data here')\n")
    (folder / "bench_bad_rows.py").write_text("def run(size='full'):\n    return [dict(method='x', locbook_s=-1.0)]\n")
    out = tmp_path / "RESULTS.md"
    out.write_text("old table\n" + run_all.NOTES_MARKER + "\nhand-written notes\n")
    rows = run_all.run_all("tiny", out, folder=folder, verbose=False)
    assert [r["benchmark"] for r in rows] == ["bench_bad_rows", "bench_broken", "bench_fine"]
    assert [r["error"] for r in rows] == [True, True, False]
    text = out.read_text()
    assert "| " + " | ".join(run_all.COLUMNS) + " |" in text
    assert ("| bench_fine | sum | 3 numbers | 0.4 | 0.5 | by hand | 2 | 5x | 4x | >= 3x: met | 0.1 |  | max \\|d\\| 0 "
            "| 0.50->0.50 | a \\| b; locbook 0.5-0.6 s over 5 calls |") in text
    assert "RuntimeError: no data here" in text and "lacks" in text
    assert "| numpy |" in text and "| git commit |" in text and "| python |" in text
    assert text.rstrip().endswith("hand-written notes") and "old table" not in text


def test_run_all_on_the_real_benchmarks(tmp_path):
    out = tmp_path / "results.md"
    rows = run_all.run_all("tiny", out, only=["bench_path_loss_fit"], verbose=False)
    assert len(rows) == 1 and not rows[0]["error"]
    assert "closed-form path-loss fit" in out.read_text()


def test_an_interrupted_run_keeps_the_complete_table(tmp_path):
    """A benchmark that stops the run (KeyboardInterrupt) leaves the previous RESULTS.md untouched and the rows so
    far in RESULTS.md.partial."""
    folder = tmp_path / "benchmarks"
    folder.mkdir()
    (folder / "_harness.py").write_text((BENCH / "_harness.py").read_text())
    (folder / "bench_a.py").write_text(
        "import _harness as hx\n"
        "def run(size='full'):\n"
        "    yield hx.row('first', 'w', hx.repeat(lambda: sum(range(100))))\n"
        "    raise KeyboardInterrupt\n")
    out = tmp_path / "RESULTS.md"
    out.write_text("the good table\n")
    with pytest.raises(KeyboardInterrupt):
        run_all.run_all("tiny", out, folder=folder, verbose=False)
    assert out.read_text() == "the good table\n"
    partial = (tmp_path / "RESULTS.md.partial").read_text()
    assert "IN PROGRESS" in partial and "| bench_a | first | w |" in partial


def test_compare_alternates_and_measures_both_sides():
    """Paired calls of known relative cost: the reference does 4x the work of the locbook side, so the CPU ratio is
    near 4 (wide bounds: a shared machine), the calls alternate, and the agreement sees the last results."""
    order = []

    def ours():
        order.append("L")
        return sum(range(50_000))

    def theirs():
        order.append("R")
        return sum(range(200_000)) and sum(range(50_000))

    m = harness.compare(ours, theirs, repeats=5, agree=lambda a, b: f"{a == b}")
    # the timed pairs alternate; then one more call of each measures its memory, untimed
    assert order == ["L", "R", "R", "L", "L", "R", "R", "L", "L", "R"] + ["L", "R"]
    assert m.repeats == 5 and m.agreement == "True"
    assert 2.0 < m.ratio_cpu < 8.0
    assert 20.0 < harness.compare(ours, theirs, reference_scale=10.0).ratio_cpu < 80.0


def test_peak_memory_counts_a_large_array():
    """The resident-set peak of a call that holds a 64 MiB array is at least about 64 MiB (where /proc allows)."""
    import numpy as np
    c = harness.call(lambda: np.ones(8 * 2**20).sum())
    if c.peak_mb is None:
        pytest.skip("no /proc/self/clear_refs here")
    assert c.peak_mb > 60
    # compare measures it in its extra, untimed call of each side
    m = harness.compare(lambda: np.ones(8 * 2**20).sum(), lambda: np.ones(2**10).sum())
    assert m.peak_mb > 60 and m.reference_peak_mb < 30
