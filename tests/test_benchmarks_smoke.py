"""Every benchmark module keeps working (issue 18): each ``benchmarks/bench_*.py`` (discovered, so none rots) runs its
``run("tiny")`` and returns rows of the benchmark protocol with finite positive times, and ``benchmarks/run_all.py``
writes the Markdown table, reporting a failing benchmark as an error row instead of stopping."""
import math
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"
sys.path.insert(0, str(BENCH))
import run_all  # noqa: E402

MODULES = run_all.discover(BENCH)


def test_the_benchmarks_are_discovered():
    names = {p.stem for p in MODULES}
    assert {"bench_dogan_filters", "bench_ukf_speed", "bench_bayes_filters", "bench_palvai", "bench_path_loss_fit",
            "bench_real_data", "bench_static_localization", "bench_ukf_stability", "bench_startup"} <= names


def _positive(value):
    return isinstance(value, (int, float)) and math.isfinite(value) and value > 0


@pytest.mark.parametrize("path", MODULES, ids=[p.stem for p in MODULES])
def test_tiny_run_gives_protocol_rows(path):
    module = run_all.load(path)
    rows = module.run("tiny")
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
        assert r["peak_mb"] is None or (math.isfinite(r["peak_mb"]) and r["peak_mb"] >= 0)
        assert isinstance(r["note"], str)


def test_run_all_writes_a_table_and_reports_a_failing_benchmark(tmp_path):
    folder = tmp_path / "benchmarks"
    folder.mkdir()
    (folder / "bench_fine.py").write_text(
        "def run(size='full'):\n"
        "    return [dict(method='sum', workload='3 numbers', locbook_s=0.5, reference='by hand', reference_s=2.0,\n"
        "                 ratio=4.0, peak_mb=0.1, note='a | b')]\n")
    (folder / "bench_broken.py").write_text("def run(size='full'):\n    raise RuntimeError('no data here')\n")
    (folder / "bench_bad_rows.py").write_text("def run(size='full'):\n    return [dict(method='x', locbook_s=-1.0)]\n")
    out = tmp_path / "RESULTS.md"
    out.write_text("old table\n" + run_all.NOTES_MARKER + "\nhand-written notes\n")
    rows = run_all.run_all("tiny", out, folder=folder, verbose=False)
    assert [r["benchmark"] for r in rows] == ["bench_bad_rows", "bench_broken", "bench_fine"]
    assert [r["error"] for r in rows] == [True, True, False]
    text = out.read_text()
    assert "| benchmark | method | workload | locbook (s) | reference | reference (s) | ratio | peak (MiB) | note |" in text
    assert "| bench_fine | sum | 3 numbers | 0.5 | by hand | 2 | 4x | 0.1 | a \\| b |" in text
    assert "RuntimeError: no data here" in text and "lacks" in text
    assert "| numpy |" in text and "| git commit |" in text and "| python |" in text
    assert text.rstrip().endswith("hand-written notes") and "old table" not in text


def test_run_all_on_the_real_benchmarks(tmp_path):
    out = tmp_path / "results.md"
    rows = run_all.run_all("tiny", out, only=["bench_path_loss_fit"], verbose=False)
    assert len(rows) == 1 and not rows[0]["error"]
    assert "closed-form path-loss fit" in out.read_text()
