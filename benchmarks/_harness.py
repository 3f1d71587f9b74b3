"""The one benchmark harness: paired, alternated repeats; CPU and wall time; memory; load; agreement.

Every ``bench_*.py`` exposes ``run(size="full")`` (``size`` is ``"full"`` or ``"tiny"``; tiny runs in seconds and is
what the smoke test uses), a generator (or a function returning a list) of rows made by :func:`row`. ``run_all.py``
writes each row as soon as it is yielded.

How a ratio is measured (:func:`compare`): the locbook call and the reference call alternate in one process,
``L R R L L R ...`` (the order flips every pair, so a slow drift of the machine falls on both), at least
:data:`MIN_REPEATS` times each. Each call's wall time (``perf_counter``), CPU time (``process_time``: every thread of
the process) and peak memory are recorded; the row gives the medians and the ratio of medians, for wall and CPU time
both, and the spread (min-max) of the locbook calls. The two results are compared in the same run (``agree``) and the
figure goes into the row. A reference too slow to repeat on the whole workload (a per-run Python loop) runs on a
subset of the runs and is scaled by ``reference_scale`` (stated in the row); the locbook call always does the whole
workload. The largest workloads use :func:`once`: one call, timed and measured at the same time.

Memory: the increase of the process's peak resident set (``VmHWM`` of ``/proc/self/status``, reset before the call
through ``/proc/self/clear_refs``) over its resident set before the call: numpy's arrays and a compiled kernel's
buffers alike. It is measured in one more call of each side after the timed ones (:func:`compare`, :func:`repeat`),
before which the free memory ``malloc`` keeps is returned to the system (``malloc_trim``), so that the call's arrays
are counted even where they would reuse memory a previous call freed. The timed calls run as a user's repeated calls
do, with ``malloc``'s default reuse of freed memory. (Until stop 44 every timed call followed a ``malloc_trim`` too:
each call then faulted its arrays in afresh, a cold start. For the EKF at 500 runs, which allocates about 120 MiB,
that added 5-20 ms to a call of about 90 ms here, more right after the filterpy loop, when the kernel sometimes
compacts memory for transparent huge pages.) :func:`once` times and measures the same call. Where ``/proc`` is
unavailable the row has no memory figure (``tracemalloc_peak_mb`` measures numpy's arrays in a separate call).

The garbage collector runs once before a measurement (and the objects alive then are frozen out of later
collections), not before every call; only the last result of each side is kept.

The load average (1 min) is recorded before and after each measurement and shown in its row.
"""
from __future__ import annotations

import ctypes
import gc
import math
import os
import statistics
import time
import tracemalloc
from dataclasses import dataclass, field

import numpy as np

SIZES = ("full", "tiny")
MIN_REPEATS = 5
KEYS = ("method", "workload", "locbook_s", "locbook_cpu_s", "reference", "reference_s", "reference_cpu_s", "ratio",
        "ratio_cpu", "repeats", "peak_mb", "reference_peak_mb", "agreement", "goal", "load", "note")
_STATUS = "/proc/self/status"
_CLEAR_REFS = "/proc/self/clear_refs"
_LIBC = {}


def aligned(array) -> np.ndarray:
    """A copy of ``array`` (float) whose first element is on a 64-byte boundary. The floors' rate kernels use it: on
    this machine (AVX-512) their 6 x 6 products ran at 18.3 Gop/s on aligned arrays and 11.1 Gop/s at any other
    offset, so the attainable rate depends on where numpy happened to place the arrays unless it is fixed."""
    array = np.asarray(array, dtype=float)
    buf = np.empty(array.size + 8)
    start = (-buf.ctypes.data % 64) // 8
    out = buf[start:start + array.size].reshape(array.shape)
    out[...] = array
    assert out.ctypes.data % 64 == 0
    return out


#: lane widths (runs side by side) at which the floors' rate kernels are measured; the floor takes the best
LANE_WIDTHS = (64, 128, 256, 512)


def best_lane_width(rate_of, widths=LANE_WIDTHS) -> tuple[int, dict]:
    """``(width, rates)``: the lane width at which ``rate_of(width)`` (a floor's rate kernel, operations per second) is
    highest, and the rate at every width. A floor is the operation count at the machine's best rate for the loop
    shape: the compiled filters run blocks of up to 256 lanes, and here the 6 x 6 product kernel ran at 18.0, 21.1,
    24.6 and 18.2 Gop/s at 64, 128, 256 and 512 lanes (the floors of stops 41-43 were taken at 64)."""
    rates = {w: rate_of(w) for w in widths}
    return max(rates, key=rates.get), rates


def check_size(size: str) -> str:
    if size not in SIZES:
        raise ValueError(f"size must be one of {SIZES}, got {size!r}")
    return size


def _status_kib(field_name: str) -> int | None:
    try:
        with open(_STATUS) as f:
            for line in f:
                if line.startswith(field_name + ":"):
                    return int(line.split()[1])
    except OSError:
        return None
    return None


def _reset_peak() -> bool:
    """Reset the process's peak resident set (Linux); False where that is not possible."""
    try:
        with open(_CLEAR_REFS, "w") as f:
            f.write("5")
        return True
    except OSError:
        return False


def _load() -> float | None:
    try:
        return os.getloadavg()[0]
    except OSError:
        return None


@dataclass
class Call:
    """One timed call: wall and CPU seconds, peak memory increase in MiB (None if unmeasured), the result."""
    wall_s: float
    cpu_s: float
    peak_mb: float | None
    result: object = None


def _malloc_trim() -> None:
    """Return malloc's free memory to the system (glibc), so that the next call's peak counts every page it touches."""
    if _LIBC.get("trim") is None:
        try:
            _LIBC["trim"] = ctypes.CDLL("libc.so.6").malloc_trim
        except (OSError, AttributeError):
            _LIBC["trim"] = False
    if _LIBC["trim"]:
        _LIBC["trim"](0)


def _settle() -> None:
    """Once before a measurement: collect garbage and freeze what is alive (the measurement's collections skip it;
    what an earlier measurement froze is released first, so that its garbage is collected now)."""
    gc.unfreeze()
    gc.collect()
    gc.freeze()


def call(fn, memory: bool = True) -> Call:
    """``fn()`` timed (wall, CPU) and, where the platform allows, its peak memory measured in the same call."""
    if memory:
        _malloc_trim()
    measured = memory and _reset_peak()
    before = _status_kib("VmRSS") if measured else None
    t, c = time.perf_counter(), time.process_time()
    out = fn()
    cpu, wall = time.process_time() - c, time.perf_counter() - t
    peak = None
    if measured and before is not None:
        hwm = _status_kib("VmHWM")
        peak = None if hwm is None else max(0, hwm - before) / 1024
    return Call(wall, cpu, peak, out)


def tracemalloc_peak_mb(fn) -> float:
    """The ``tracemalloc`` peak of one call of ``fn`` in MiB (numpy's arrays; not a compiled kernel's buffers)."""
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


@dataclass
class Measurement:
    """What :func:`compare` or :func:`once` measured (medians over the repeats)."""
    locbook_wall_s: float
    locbook_cpu_s: float
    locbook_spread_s: tuple[float, float]
    repeats: int
    peak_mb: float | None
    reference_wall_s: float | None = None
    reference_cpu_s: float | None = None
    reference_peak_mb: float | None = None
    reference_scale: float = 1.0
    agreement: str = ""
    load: tuple[float | None, float | None] = (None, None)
    results: tuple = field(default=(None, None), repr=False)

    @property
    def ratio(self) -> float | None:
        if self.reference_wall_s is None or not self.locbook_wall_s:
            return None
        return self.reference_wall_s / self.locbook_wall_s

    @property
    def ratio_cpu(self) -> float | None:
        if self.reference_cpu_s is None or not self.locbook_cpu_s:
            return None
        return self.reference_cpu_s / self.locbook_cpu_s


def _median(values):
    return float(statistics.median(values))


def compare(locbook, reference, *, repeats: int = MIN_REPEATS, reference_scale: float = 1.0, agree=None,
            memory: bool = True) -> Measurement:
    """``locbook()`` against ``reference()``, paired and alternated ``repeats`` times each (at least
    :data:`MIN_REPEATS`). ``reference_scale`` multiplies the reference's times (it ran on a subset of the runs: the
    number of runs of the workload over the number it ran); ``agree(locbook_result, reference_result) -> str`` is
    the agreement figure (e.g. ``"max |x - filterpy| 2e-13"``), computed on the results of the last pair; it may
    raise AssertionError when the results disagree beyond the benchmark's stated tolerance (the row then says so)."""
    repeats = max(MIN_REPEATS, int(repeats))
    _settle()
    load0 = _load()
    ours, theirs, last = [], [], [None, None]
    for i in range(repeats):
        order = (True, False) if i % 2 == 0 else (False, True)
        for mine in order:
            c = call(locbook if mine else reference, memory=False)
            last[0 if mine else 1], c.result = c.result, None          # keep only each side's last result
            (ours if mine else theirs).append(c)
    load1 = _load()
    text = _agreement(agree, last[0], last[1])
    peak, ref_peak = (_peak_call(locbook), _peak_call(reference)) if memory else (None, None)
    walls = [c.wall_s for c in ours]
    return Measurement(_median(walls), _median([c.cpu_s for c in ours]), (min(walls), max(walls)), repeats, peak,
                       _median([c.wall_s for c in theirs]) * reference_scale,
                       _median([c.cpu_s for c in theirs]) * reference_scale,
                       ref_peak, reference_scale, text, (load0, load1), tuple(last))


def _peak_call(fn) -> float | None:
    """The peak memory of one more, untimed call of ``fn`` (module docstring)."""
    return call(fn, memory=True).peak_mb


def _agreement(agree, *results) -> str:
    """``agree(*results)``, the row's agreement figure; an AssertionError (a disagreement beyond the benchmark's stated
    tolerance) becomes ``"DISAGREE: ..."``, which run_all.py reports as an error."""
    if agree is None:
        return ""
    try:
        return agree(*results)
    except AssertionError as exc:
        return f"DISAGREE: {exc}"


def repeat(locbook, *, repeats: int = MIN_REPEATS, agree=None, memory: bool = True) -> Measurement:
    """``locbook()`` alone (no reference), ``repeats`` times; ``agree(result) -> str`` an accuracy figure (it may raise
    AssertionError beyond a stated tolerance, as :func:`compare`'s)."""
    repeats = max(MIN_REPEATS, int(repeats))
    _settle()
    load0 = _load()
    ours, result = [], None
    for _ in range(repeats):
        c = call(locbook, memory=False)
        result, c.result = c.result, None
        ours.append(c)
    load1 = _load()
    text = _agreement(agree, result)
    walls = [c.wall_s for c in ours]
    return Measurement(_median(walls), _median([c.cpu_s for c in ours]), (min(walls), max(walls)), repeats,
                       _peak_call(locbook) if memory else None, agreement=text, load=(load0, load1),
                       results=(result, None))


def once(locbook, *, agree=None) -> Measurement:
    """One call of a workload too large to repeat: timed and its memory measured in the same call."""
    _settle()
    load0 = _load()
    c = call(locbook, True)
    load1 = _load()
    text = _agreement(agree, c.result)
    return Measurement(c.wall_s, c.cpu_s, (c.wall_s, c.wall_s), 1, c.peak_mb, agreement=text, load=(load0, load1),
                       results=(c.result, None))


def _fmt_load(load) -> str:
    a, b = load
    return "" if a is None else f"{a:.2f}->{b:.2f}"


def row(method: str, workload: str, m: Measurement, reference: str | None = None, *, goal: float | None = None,
        note: str = "") -> dict:
    """A row of RESULTS.md from a measurement. ``reference`` names the reference (and the subset it ran on, when
    scaled); ``goal``: the ratio the issue asks for (the row says met or MISSED, on the CPU-time ratio)."""
    ratio, ratio_cpu = m.ratio, m.ratio_cpu
    verdict = None
    if goal is not None:
        verdict = (f">= {goal:g}x: " + ("met" if ratio_cpu is not None and ratio_cpu >= goal else "MISSED")
                   if goal >= 1 else f">= {goal:g}x (within {1 / goal:g}x): "
                   + ("met" if ratio_cpu is not None and ratio_cpu >= goal else "MISSED"))
    lo, hi = m.locbook_spread_s
    spread = f"locbook {lo:.3g}-{hi:.3g} s over {m.repeats} calls" if m.repeats > 1 else "timed once"
    if m.reference_scale != 1.0:
        spread += f"; reference times scaled x{m.reference_scale:g}"
    return {"method": method, "workload": workload, "locbook_s": float(m.locbook_wall_s),
            "locbook_cpu_s": float(m.locbook_cpu_s), "reference": reference if m.reference_wall_s is not None else None,
            "reference_s": m.reference_wall_s, "reference_cpu_s": m.reference_cpu_s, "ratio": ratio,
            "ratio_cpu": ratio_cpu, "repeats": m.repeats, "peak_mb": m.peak_mb,
            "reference_peak_mb": m.reference_peak_mb, "agreement": m.agreement, "goal": verdict,
            "load": _fmt_load(m.load), "note": "; ".join(x for x in (note, spread) if x)}


def _fmt(value, digits=3):
    if value is None:
        return ""
    if isinstance(value, float):
        if not math.isfinite(value):
            return str(value)
        return f"{value:.{digits}g}" if abs(value) < 1000 else f"{value:.0f}"
    return str(value)


def format_row(r: dict) -> str:
    """One row as a line of plain text (the modules' command lines, run_all's progress)."""
    ratio = f" x{r['ratio_cpu']:.1f} CPU, x{r['ratio']:.1f} wall" if r.get("ratio") is not None else ""
    ref = f"; {r['reference']}: {_fmt(r['reference_cpu_s'])} s CPU{ratio}" if r.get("reference") else ""
    peak = f"; peak +{_fmt(r['peak_mb'])} MiB" if r.get("peak_mb") is not None else ""
    agree = f"; {r['agreement']}" if r.get("agreement") else ""
    goal = f"; goal {r['goal']}" if r.get("goal") else ""
    note = f"  [{r['note']}]" if r.get("note") else ""
    return (f"{r['method']} ({r['workload']}): locbook {_fmt(r['locbook_cpu_s'])} s CPU, {_fmt(r['locbook_s'])} s "
            f"wall{ref}{peak}{agree}{goal}{note}")


def print_rows(rows) -> list[dict]:
    """Print each row as it comes (``rows`` may be a generator); return them as a list."""
    out = []
    for r in rows:
        print(format_row(r), flush=True)
        out.append(r)
    return out
