"""Reading brackets: how long ``locbook bracket`` takes for every experiment of one document, at the quick profile.

Issue 28's target: a bracket of one document (every experiment of it that declares readings) runs within
10 minutes on 2 cores at the quick profile. Each experiment is bracketed with ``--jobs 2 --force`` into a fresh
temporary reports folder (nothing cached), one after the other, as a user would run them; the row of a document
gives the total wall time, the points run and whether the target is met, and the note the time of each experiment.
Reports measured figures; not a test.

    python benchmarks/bench_bracket.py                  # every document with readings
    python benchmarks/bench_bracket.py --document dogan2015
    python benchmarks/bench_bracket.py --size tiny      # one reading of one fast George experiment
"""
from __future__ import annotations

import argparse
import contextlib
import csv
import io
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402

#: seconds a bracket of one document may take at the quick profile on 2 cores (issue 28)
TARGET_S = 600.0
TINY_READINGS = ("name,experiments,parameter,where,default,alternatives,fitted,low,high,basis,source,reason\n"
                 "shadowing,george-rssi-vs-distance,sigma_indoor_db,,,[3.0],,,,assumed,benchmark,one alternative\n")


def _bracket(experiment: str, reports: Path, readings: Path | None = None) -> tuple[float, int, str]:
    """``(wall seconds, points run, counts line)`` of ``locbook bracket experiment --jobs 2 --force``."""
    from locbook.suite.cli import main

    args = ["bracket", experiment, "--jobs", "2", "--force", "--reports", str(reports), "--progress", "quiet"]
    if readings is not None:
        args += ["--readings", str(readings)]
    out = io.StringIO()
    start = time.perf_counter()
    with contextlib.redirect_stdout(out):
        status = main(args)
    seconds = time.perf_counter() - start
    if status == 2:      # bad input: nothing ran
        raise RuntimeError(f"locbook bracket {experiment} refused its input (exit status 2)")
    points_csv = reports / "brackets" / experiment / "points.csv"
    with open(points_csv, newline="") as fh:
        points = list(csv.DictReader(fh))
    line = next((x for x in out.getvalue().splitlines() if x.startswith("bracket of")), "")
    failed = sum(p["status"] not in ("ok", "cached") for p in points)
    note = line.split(": ", 1)[-1].split(" (")[0] + (f"; {failed} point(s) failed" if failed else "")
    return seconds, len(points), note + ("" if status == 0 else f"; exit status {status}")


def _documents() -> dict[str, list[str]]:
    from locbook.reproduce.readings import readings_for
    from locbook.suite import load_suite

    docs: dict[str, list[str]] = {}
    for exp in load_suite().experiments:
        if readings_for(exp.id):
            docs.setdefault(exp.document.key, []).append(exp.id)
    return docs


def run(size: str = "full", documents: list[str] | None = None) -> list[dict]:
    hx.check_size(size)
    rows = []
    with tempfile.TemporaryDirectory(prefix="locbook-bench-bracket-") as tmp:
        if size == "tiny":
            readings = Path(tmp) / "tiny.csv"
            readings.write_text(TINY_READINGS)
            seconds, points, note = _bracket("george-rssi-vs-distance", Path(tmp) / "r", readings)
            return [hx.row("locbook bracket (quick, --jobs 2)", f"george-rssi-vs-distance, {points} points",
                           seconds, note=note)]
        for document, experiments in _documents().items():
            if documents and document not in documents:
                continue
            total, n_points, parts = 0.0, 0, []
            for exp_id in experiments:
                seconds, points, note = _bracket(exp_id, Path(tmp) / document)
                total += seconds
                n_points += points
                parts.append(f"{exp_id} {seconds:.0f} s / {points} points ({note})")
            verdict = "met" if total <= TARGET_S else "NOT met"
            rows.append(hx.row("locbook bracket (quick, --jobs 2)",
                               f"{document}: {len(experiments)} experiment(s), {n_points} points", total,
                               note=f"target <= {TARGET_S:.0f} s {verdict}; " + "; ".join(parts)))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--size", choices=hx.SIZES, default="full")
    parser.add_argument("--document", action="append", help="only this document (repeatable)")
    args = parser.parse_args()
    for r in run(args.size, args.document):
        print(f"{r['workload']}: {r['locbook_s']:.0f} s. {r['note']}")


if __name__ == "__main__":
    main()
