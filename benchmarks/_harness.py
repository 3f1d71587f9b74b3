"""Helpers shared by the benchmark modules: the ``run(size) -> list[dict]`` protocol of ``benchmarks/run_all.py``.

Every ``bench_*.py`` exposes ``run(size="full")`` (``size`` is ``"full"`` or ``"tiny"``; tiny runs in a few seconds)
returning rows with the keys of :data:`KEYS`:

- ``method``, ``workload``: what was timed, on what;
- ``locbook_s``: wall-clock seconds of the locbook call (best of a few repeats where it is cheap);
- ``reference``, ``reference_s``: what it is compared with (e.g. a per-run filterpy loop) and its seconds, or None;
- ``ratio``: ``reference_s / locbook_s`` or None;
- ``peak_mb``: the ``tracemalloc`` peak of the locbook call in MiB (numpy's arrays are traced; memory that a numba
  kernel allocates is not), measured in a separate call so that tracing does not slow the timed one; or None;
- ``note``: anything else (differences to the reference, how a reference time was scaled, errors).
"""
from __future__ import annotations

import math
import time
import tracemalloc

SIZES = ("full", "tiny")
KEYS = ("method", "workload", "locbook_s", "reference", "reference_s", "ratio", "peak_mb", "note")


def check_size(size: str) -> str:
    if size not in SIZES:
        raise ValueError(f"size must be one of {SIZES}, got {size!r}")
    return size


def timed(fn, repeat: int = 1):
    """``(best wall-clock seconds over repeat calls, best CPU seconds, the last call's result)``."""
    best, best_cpu, out = math.inf, math.inf, None
    for _ in range(max(1, repeat)):
        t, c = time.perf_counter(), time.process_time()
        out = fn()
        best_cpu = min(best_cpu, time.process_time() - c)
        best = min(best, time.perf_counter() - t)
    return best, best_cpu, out


def peak_mb(fn) -> float:
    """The ``tracemalloc`` peak of one call of ``fn``, in MiB."""
    was_tracing = tracemalloc.is_tracing()
    if not was_tracing:
        tracemalloc.start()
    tracemalloc.reset_peak()
    try:
        fn()
        _, peak = tracemalloc.get_traced_memory()
    finally:
        if not was_tracing:
            tracemalloc.stop()
    return peak / 2**20


def row(method: str, workload: str, locbook_s: float, reference: str | None = None, reference_s: float | None = None,
        peak: float | None = None, note: str = "") -> dict:
    ratio = reference_s / locbook_s if reference_s is not None and locbook_s else None
    return {"method": method, "workload": workload, "locbook_s": float(locbook_s), "reference": reference,
            "reference_s": None if reference_s is None else float(reference_s), "ratio": ratio,
            "peak_mb": None if peak is None else float(peak), "note": note}


def _fmt(value, digits=3):
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.{digits}g}" if abs(value) < 1000 else f"{value:.0f}"
    return str(value)


def print_rows(rows) -> None:
    """The rows as a plain-text table (the modules' command lines)."""
    for r in rows:
        ratio = f"x{r['ratio']:.0f}" if r["ratio"] is not None else ""
        ref = f"; {r['reference']}: {_fmt(r['reference_s'])} s {ratio}" if r["reference"] else ""
        peak = f"; peak {_fmt(r['peak_mb'])} MiB" if r["peak_mb"] is not None else ""
        note = f"  [{r['note']}]" if r["note"] else ""
        print(f"{r['method']} ({r['workload']}): locbook {_fmt(r['locbook_s'])} s{ref}{peak}{note}")
