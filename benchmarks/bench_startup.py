"""Start-up: what ``import locbook`` adds to ``import numpy, scipy``, and how fast the CLI answers.

Issue 27's target: ``import locbook`` takes less than 0.3 s more than ``import numpy, scipy`` on the same machine,
and ``locbook --version`` / ``locbook list`` answer in well under a second. Every figure is the median over fresh
interpreters (each import is timed once per process: a second import in the same process is a dictionary
look-up). Reports measured figures; not a test.

- ``import numpy, scipy``: timed inside a fresh interpreter;
- ``import locbook`` on top of it: timed in the same interpreter, right after;
- ``locbook --version`` and ``locbook list``: wall time of ``python -m locbook ...`` from the repository root,
  against ``python -c pass`` (the interpreter's own start) as the reference.

    python benchmarks/bench_startup.py [--size tiny] [--repeat N]
"""
from __future__ import annotations

import argparse
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
#: the added start-up issue 27 allows ``import locbook`` over ``import numpy, scipy``
IMPORT_BUDGET_S = 0.3
_IMPORTS = ("import time\nt0 = time.perf_counter()\nimport numpy, scipy\nt1 = time.perf_counter()\n"
            "import locbook\nt2 = time.perf_counter()\nprint(t1 - t0, t2 - t1)")


def _child_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _wall_s(args: list[str]) -> tuple[float, float]:
    """``(wall, CPU)`` seconds of one fresh ``python args`` from the repository root (its output discarded).
    The CPU time (user + system) hardly depends on what else the machine runs; the wall time does."""
    cpu, start = _child_cpu_s(), time.perf_counter()
    subprocess.run([sys.executable, *args], cwd=ROOT, check=True, stdout=subprocess.DEVNULL,
                   stderr=subprocess.DEVNULL)
    return time.perf_counter() - start, _child_cpu_s() - cpu


def _medians(args: list[str], repeat: int) -> tuple[float, float]:
    runs = [_wall_s(args) for _ in range(repeat)]
    return statistics.median(w for w, _ in runs), statistics.median(c for _, c in runs)


def _import_s() -> tuple[float, float]:
    """``(import numpy, scipy; import locbook after it)`` in seconds, timed inside one fresh interpreter."""
    out = subprocess.run([sys.executable, "-c", _IMPORTS], cwd=ROOT, check=True, capture_output=True, text=True)
    base, extra = map(float, out.stdout.split())
    return base, extra


def measure(repeat: int = 9) -> list[dict]:
    imports = [_import_s() for _ in range(repeat)]
    base_s = statistics.median(b for b, _ in imports)
    extra_s = statistics.median(e for _, e in imports)
    python_s, python_cpu = _medians(["-c", "pass"], repeat)
    version_s, version_cpu = _medians(["-m", "locbook", "--version"], repeat)
    list_s, list_cpu = _medians(["-m", "locbook", "list"], repeat)
    runs = f"median of {repeat} fresh interpreters"
    verdict = "within" if extra_s < IMPORT_BUDGET_S else "OVER"
    return [
        hx.row("import numpy, scipy", runs, base_s, note="the baseline import locbook is compared with"),
        hx.row("import locbook", f"after import numpy, scipy; {runs}", extra_s, reference="import numpy, scipy",
               reference_s=base_s, note=f"{verdict} the {IMPORT_BUDGET_S} s budget over numpy and scipy (issue 27)"),
        hx.row("locbook --version", f"python -m locbook --version, wall; {runs}", version_s,
               reference="python -c pass", reference_s=python_s,
               note=f"the interpreter's start included; CPU {version_cpu:.3f} s against {python_cpu:.3f} s"),
        hx.row("locbook list", f"python -m locbook list, wall; {runs}", list_s,
               reference="python -c pass", reference_s=python_s,
               note=f"the interpreter's start included; CPU {list_cpu:.3f} s against {python_cpu:.3f} s"),
    ]


def run(size: str = "full") -> list[dict]:
    """The benchmark protocol (benchmarks/run_all.py): full = median of 9 interpreters, tiny = of 3."""
    return measure(3 if hx.check_size(size) == "tiny" else 9)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=9, help="fresh interpreters per figure (the median is shown)")
    ap.add_argument("--size", choices=hx.SIZES, default=None, help="the run(size) preset instead of --repeat")
    args = ap.parse_args()
    hx.print_rows(run(args.size) if args.size else measure(args.repeat))


if __name__ == "__main__":
    main()
