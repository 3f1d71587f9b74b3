"""Start-up: what ``import locbook`` adds to ``import numpy, scipy``, and how fast the CLI answers.

The target: ``import locbook`` takes less than 0.3 s more than ``import numpy, scipy`` on the same machine, and
``locbook --version``, ``locbook list`` and ``locbook show ID`` answer in under a second. Every figure is the median
over fresh interpreters (each import is timed once per process: a second import in the same process is a
dictionary look-up). Reports measured figures; not a test.

- ``import locbook`` against ``import numpy, scipy``: both timed inside the same fresh interpreter, one after the
  other (wall: ``perf_counter``; CPU: ``process_time``; memory: the interpreter's resident-set high-water mark
  ``ru_maxrss`` before and after each), so every interpreter gives one pair;
- ``locbook --version``, ``locbook list`` and ``locbook show george-tracking``: ``python -m locbook ...`` from the
  repository root alternated with ``python -c pass`` (the interpreter's own start, the reference): wall time, and
  CPU time (user + system) of the child from ``RUSAGE_CHILDREN``, which hardly depends on what else the machine
  runs.

The harness's ``compare`` times calls inside this process (its CPU clock does not see a child process), so the
pairs are measured here and handed to ``hx.row`` as an ``hx.Measurement`` (medians, spread, load, like ``compare``).

    python benchmarks/bench_startup.py [full|tiny] [--repeat N]
"""
from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: the added start-up the goal allows ``import locbook`` over ``import numpy, scipy``
IMPORT_BUDGET_S = 0.3
_IMPORTS = ("import resource, time\n"
            "def rss(): return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss\n"
            "m0 = rss(); t0, c0 = time.perf_counter(), time.process_time()\n"
            "import numpy, scipy\n"
            "t1, c1 = time.perf_counter(), time.process_time(); m1 = rss()\n"
            "import locbook\n"
            "t2, c2 = time.perf_counter(), time.process_time(); m2 = rss()\n"
            "print(t1 - t0, c1 - c0, (m1 - m0) / 1024, t2 - t1, c2 - c1, (m2 - m1) / 1024)")


def _load() -> float | None:
    try:
        return os.getloadavg()[0]
    except OSError:
        return None


def _child_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _child(args: list[str]) -> tuple[float, float]:
    """``(wall, CPU)`` seconds of one fresh ``python args`` from the repository root (its output discarded)."""
    cpu, start = _child_cpu_s(), time.perf_counter()
    subprocess.run([sys.executable, *args], cwd=ROOT, check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    return time.perf_counter() - start, _child_cpu_s() - cpu


def _measurement(ours: list[tuple], ref: list[tuple], load, agreement: str = "") -> hx.Measurement:
    """Medians of ``(wall, CPU[, peak MiB])`` pairs as the harness reports them."""
    med = lambda xs, i: float(statistics.median(x[i] for x in xs))                     # noqa: E731
    walls = [x[0] for x in ours]
    peak = max(x[2] for x in ours) if len(ours[0]) > 2 else None
    ref_peak = max(x[2] for x in ref) if len(ref[0]) > 2 else None
    return hx.Measurement(med(ours, 0), med(ours, 1), (min(walls), max(walls)), len(ours), peak, med(ref, 0),
                          med(ref, 1), ref_peak, 1.0, agreement, load)


def _imports(repeat: int) -> tuple[hx.Measurement, list[float]]:
    """``import locbook`` (ours) and ``import numpy, scipy`` (reference), one pair per fresh interpreter."""
    load0, ours, ref = _load(), [], []
    for _ in range(repeat):
        out = subprocess.run([sys.executable, "-c", _IMPORTS], cwd=ROOT, check=True, capture_output=True, text=True)
        bw, bc, bm, lw, lc, lm = map(float, out.stdout.split())
        ours.append((lw, lc, lm))
        ref.append((bw, bc, bm))
    return _measurement(ours, ref, (load0, _load())), [x[0] for x in ours]


def _cli(args: list[str], repeat: int) -> hx.Measurement:
    """``python args`` against ``python -c pass``, alternated L R R L L R ... like ``hx.compare``."""
    load0, ours, ref = _load(), [], []
    for i in range(repeat):
        for mine in ((True, False) if i % 2 == 0 else (False, True)):
            (ours if mine else ref).append(_child(args if mine else ["-c", "pass"]))
    return _measurement(ours, ref, (load0, _load()))


#: the CLI's answers that must come in under a second
CLI_BUDGET_S = 1.0


def measure(repeat: int = hx.MIN_REPEATS, cli=("--version", "list", "show george-tracking")):
    repeat = max(hx.MIN_REPEATS, repeat)
    runs = f"median of {repeat} fresh interpreters"
    m, _ = _imports(repeat)
    verdict = "within" if m.locbook_wall_s < IMPORT_BUDGET_S else "OVER"
    yield hx.row("import locbook", f"after import numpy, scipy; {runs}", m, "import numpy, scipy (same interpreter)",
                 note=f"{verdict} the {IMPORT_BUDGET_S} s budget over numpy and scipy; peak = the "
                      "interpreter's ru_maxrss increase")
    for command in cli:
        name, args = f"locbook {command}", ["-m", "locbook", *command.split()]
        m = _cli(args, repeat)
        verdict = "within" if m.locbook_wall_s < CLI_BUDGET_S else "OVER"
        yield hx.row(name, f"python {' '.join(args)}, from the repository root; {runs}", m, "python -c pass",
                     note=f"{verdict} the {CLI_BUDGET_S:g} s budget; the interpreter's start included; CPU = the "
                          "child's user + system time")


def run(size: str = "full"):
    """The benchmark protocol (benchmarks/run_all.py): the median of 5 interpreters per figure (65 interpreters,
    about 30 s); tiny: ``locbook --version`` only (25)."""
    return measure(cli=("--version",) if hx.check_size(size) == "tiny" else ("--version", "list",
                                                                             "show george-tracking"))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("size", nargs="?", choices=hx.SIZES, default=None, help="the run(size) preset")
    ap.add_argument("--repeat", type=int, default=hx.MIN_REPEATS,
                    help="fresh interpreters per figure (the median is shown)")
    args = ap.parse_args()
    hx.print_rows(run(args.size) if args.size else measure(args.repeat))


if __name__ == "__main__":
    main()
