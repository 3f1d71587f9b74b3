"""Interpretation brackets: how long ``locbook bracket`` takes for every experiment of one document, at the quick
profile.

The target: a bracket of one document (every experiment of it that declares interpretations) runs within
10 minutes on 2 cores at the quick profile. Each experiment is bracketed with ``--jobs 2 --force`` into a fresh
temporary reports folder (nothing cached), one after the other, as a user would run them; the row of a document
gives the total wall time (and the CPU time of the process and its workers), the points run and whether the target
is met, and the note the time of each experiment. Each bracket runs once (minutes of work: never repeated).
Reports measured figures; not a test.

    python benchmarks/bench_bracket.py                      # full: every interpretation of one small experiment
    python benchmarks/bench_bracket.py --document dogan2015 # one document's figure ('all': every one)
    python benchmarks/bench_bracket.py tiny                 # one interpretation of one fast George experiment
"""
from __future__ import annotations

import argparse
import contextlib
import csv
import io
import os
import resource
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402

#: seconds a bracket of one document may take at the quick profile on 2 cores (the goal)
TARGET_S = 600.0
#: the full size's experiment: two interpretations, about 16 s (a document's bracket takes minutes: ``--document``)
FULL_EXPERIMENT = "dogan2015-models"
TINY_INTERPRETATIONS = (
    "name,experiments,parameter,where,default,alternatives,fitted,low,high,basis,source,reason\n"
    "shadowing,george-rssi-vs-distance,sigma_indoor_db,,,[3.0],,,,assumed,benchmark,one alternative\n")


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _bracket(experiment: str, reports: Path, interpretations: Path | None = None) -> tuple[hx.Measurement, int, str]:
    """``(measurement, points run, counts line)`` of ``locbook bracket experiment --jobs 2 --force``, run once: wall
    time, CPU time of this process and of its workers (``RUSAGE_CHILDREN``), peak resident memory of this process
    (``hx.call``; the workers' memory is not in it)."""
    from locbook.suite.cli import main

    args = ["bracket", experiment, "--jobs", "2", "--force", "--reports", str(reports), "--progress", "quiet"]
    if interpretations is not None:
        args += ["--interpretations", str(interpretations)]
    out = io.StringIO()
    load0, children = _load(), _children_cpu_s()
    with contextlib.redirect_stdout(out):
        c = hx.call(lambda: main(args))
    m = hx.Measurement(c.wall_s, c.cpu_s + _children_cpu_s() - children, (c.wall_s, c.wall_s), 1, c.peak_mb,
                       load=(load0, _load()))
    status = c.result
    if status == 2:      # bad input: nothing ran
        raise RuntimeError(f"locbook bracket {experiment} refused its input (exit status 2)")
    points_csv = reports / "brackets" / experiment / "points.csv"
    with open(points_csv, newline="") as fh:
        points = list(csv.DictReader(fh))
    line = next((x for x in out.getvalue().splitlines() if x.startswith("bracket of")), "")
    failed = sum(p["status"] not in ("ok", "cached") for p in points)
    note = line.split(": ", 1)[-1].split(" (")[0] + (f"; {failed} point(s) failed" if failed else "")
    return m, len(points), note + ("" if status == 0 else f"; exit status {status}")


def _load() -> float | None:
    try:
        return os.getloadavg()[0]
    except OSError:
        return None


def _documents() -> dict[str, list[str]]:
    from locbook.reproduce.interpretations import interpretations_for
    from locbook.suite import load_suite

    docs: dict[str, list[str]] = {}
    for exp in load_suite().experiments:
        if interpretations_for(exp.id):
            docs.setdefault(exp.document.key, []).append(exp.id)
    return docs


def _sum(parts: list[hx.Measurement]) -> hx.Measurement:
    wall = sum(m.locbook_wall_s for m in parts)
    peaks = [m.peak_mb for m in parts if m.peak_mb is not None]
    return hx.Measurement(wall, sum(m.locbook_cpu_s for m in parts), (wall, wall), 1, max(peaks) if peaks else None,
                          load=(parts[0].load[0], parts[-1].load[1]))


def run(size: str = "full", documents: list[str] | None = None):
    """tiny: one interpretation of george-rssi-vs-distance; full: every interpretation of ``FULL_EXPERIMENT`` (the
    suite's time budget holds one small experiment, not a document); ``documents``: a figure per document, every
    experiment of each document named (``"all"``: every document with interpretations), one row per document."""
    hx.check_size(size)
    with tempfile.TemporaryDirectory(prefix="locbook-bench-bracket-") as tmp:
        if size == "tiny" and not documents:
            interpretations = Path(tmp) / "tiny.csv"
            interpretations.write_text(TINY_INTERPRETATIONS)
            m, points, note = _bracket("george-rssi-vs-distance", Path(tmp) / "r", interpretations)
            yield hx.row("locbook bracket (quick, --jobs 2)", f"george-rssi-vs-distance, {points} points", m,
                         note=note + "; CPU includes the workers")
            return
        if not documents:
            m, points, note = _bracket(FULL_EXPERIMENT, Path(tmp) / "r")
            what = f"{FULL_EXPERIMENT}: every interpretation, {points} points"
            yield hx.row("locbook bracket (quick, --jobs 2)", what, m,
                         note=note + "; CPU includes the workers; a whole document's bracket (goal: <= "
                                     f"{TARGET_S:.0f} s) is `bench_bracket.py --document NAME`")
            return
        for document, experiments in _documents().items():
            if "all" not in documents and document not in documents:
                continue
            parts, n_points, notes = [], 0, []
            for exp_id in experiments:
                m, points, note = _bracket(exp_id, Path(tmp) / document)
                parts.append(m)
                n_points += points
                notes.append(f"{exp_id} {m.locbook_wall_s:.0f} s / {points} points ({note})")
            total = _sum(parts)
            verdict = "met" if total.locbook_wall_s <= TARGET_S else "NOT met"
            yield hx.row("locbook bracket (quick, --jobs 2)",
                         f"{document}: {len(experiments)} experiment(s), {n_points} points", total,
                         note=f"target <= {TARGET_S:.0f} s {verdict}; " + "; ".join(notes))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("size", nargs="?", choices=hx.SIZES, default="full")
    parser.add_argument("--document", action="append",
                        help="every experiment of this document (repeatable; 'all': every document with "
                             "interpretations)")
    args = parser.parse_args()
    hx.print_rows(run(args.size, args.document))


if __name__ == "__main__":
    main()
