"""Run every benchmark and write one Markdown table.

    python benchmarks/run_all.py [--size full|tiny] [--out benchmarks/RESULTS.md] [--only NAME ...]

Imports every ``benchmarks/bench_*.py`` (discovered, so a new one is picked up), calls its ``run(size)`` (the
protocol of ``benchmarks/_harness.py``: a list of rows with method, workload, locbook_s, reference, reference_s,
ratio, peak_mb, note) and writes the rows as a table, with the machine facts (CPUs, Python, numpy, numba, date, git
commit), to ``--out``. A benchmark that raises, or returns something that is not a list of such rows, becomes an
error row; the others still run. Text below the line ``<!-- notes: kept by run_all.py -->`` in an existing output file
(the hand-written analysis) is carried over unchanged.
"""
from __future__ import annotations

import argparse
import datetime
import importlib.util
import math
import os
import platform
import subprocess
import sys
import time
import traceback
from pathlib import Path

HERE = Path(__file__).resolve().parent
KEYS = ("method", "workload", "locbook_s", "reference", "reference_s", "ratio", "peak_mb", "note")
NOTES_MARKER = "<!-- notes: kept by run_all.py -->"


def discover(folder: Path = HERE) -> list[Path]:
    """The benchmark modules: ``bench_*.py`` in ``folder``, sorted by name."""
    return sorted(folder.glob("bench_*.py"))


def load(path: Path):
    """Import a benchmark module from its file (its folder on sys.path, as when it runs as a script)."""
    if str(path.parent) not in sys.path:
        sys.path.insert(0, str(path.parent))
    spec = importlib.util.spec_from_file_location(f"locbook_benchmarks.{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _error_row(name: str, message: str, seconds: float | None = None) -> dict:
    return {"method": f"{name}: ERROR", "workload": "", "locbook_s": seconds, "reference": None, "reference_s": None,
            "ratio": None, "peak_mb": None, "note": message, "benchmark": name, "error": True}


def check_rows(rows) -> list[str]:
    """What is wrong with a module's rows ([] if nothing)."""
    if not isinstance(rows, list) or not rows:
        return [f"run() returned {type(rows).__name__}, not a non-empty list of rows"]
    problems = []
    for i, r in enumerate(rows):
        if not isinstance(r, dict):
            problems.append(f"row {i} is a {type(r).__name__}")
            continue
        missing = [k for k in KEYS if k not in r]
        if missing:
            problems.append(f"row {i} lacks {missing}")
        t = r.get("locbook_s")
        if not (isinstance(t, (int, float)) and math.isfinite(t) and t > 0):
            problems.append(f"row {i} ({r.get('method')}) has locbook_s = {t!r}")
    return problems


def run_module(path: Path, size: str) -> list[dict]:
    """The rows of one benchmark, each tagged with its module; an error row if it fails."""
    name = path.stem
    start = time.perf_counter()
    try:
        rows = load(path).run(size)
    except Exception as exc:                                  # noqa: BLE001 - reported as a row, never a crash
        tb = traceback.format_exception_only(type(exc), exc)[-1].strip()
        return [_error_row(name, tb, time.perf_counter() - start)]
    problems = check_rows(rows)
    if problems:
        return [_error_row(name, "; ".join(problems), time.perf_counter() - start)]
    return [dict(r, benchmark=name, error=False) for r in rows]


def _git(*args) -> str:
    try:
        return subprocess.run(["git", *args], cwd=HERE, capture_output=True, text=True, timeout=20).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


def machine_facts() -> dict:
    import numpy
    import scipy
    try:
        import numba
        numba_version = numba.__version__
    except ImportError:
        numba_version = "not installed"
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    commit = _git("rev-parse", "--short", "HEAD") or "unknown"
    dirty = _git("--no-optional-locks", "status", "--porcelain", "--untracked-files=no")   # read-only
    try:
        load = "%.2f %.2f %.2f" % os.getloadavg()
    except OSError:
        load = "n/a"
    return {"date": datetime.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z"),
            "git commit": commit + (" (working tree modified)" if dirty else ""),
            "CPU": f"{cpu}, {os.cpu_count()} logical CPUs", "load average (1, 5, 15 min) at the end": load,
            "platform": platform.platform(), "python": sys.version.split()[0], "numpy": numpy.__version__,
            "scipy": scipy.__version__, "numba": numba_version,
            "LOCBOOK_NUMBA": os.environ.get("LOCBOOK_NUMBA", "(unset: compiled EKF on when numba is installed)")}


def _cell(value, kind: str = "") -> str:
    if value is None:
        return ""
    if kind == "s":
        return f"{value:.3g}" if value < 100 else f"{value:.0f}"
    if kind == "ratio":
        return f"{value:.3g}x" if value < 100 else f"{value:.0f}x"
    if kind == "mb":
        return f"{value:.3g}" if value < 1000 else f"{value:.0f}"
    return str(value).replace("|", "\\|").replace("\n", " ")


def markdown(rows: list[dict], size: str, facts: dict, seconds: float, notes: str = "") -> str:
    lines = [f"# Benchmark results ({size})", "",
             f"Written by `python benchmarks/run_all.py --size {size}` in {seconds:.0f} s. Times are wall-clock seconds "
             "(best of a few repeats for the cheap locbook calls); a reference marked \"scaled\" was timed on a subset "
             "of the runs and scaled to the full count; ratio = reference / locbook; peak memory is the tracemalloc "
             "peak of the locbook call in MiB (numpy arrays included, numba kernel buffers not).", "",
             "| machine | |", "|---|---|"]
    lines += [f"| {k} | {_cell(v)} |" for k, v in facts.items()]
    lines += ["", "| benchmark | method | workload | locbook (s) | reference | reference (s) | ratio | peak (MiB) | note |",
              "|---|---|---|---:|---|---:|---:|---:|---|"]
    for r in rows:
        lines.append("| " + " | ".join([
            _cell(r.get("benchmark")), ("**" + _cell(r["method"]) + "**") if r.get("error") else _cell(r["method"]),
            _cell(r["workload"]), _cell(r["locbook_s"], "s"), _cell(r["reference"]), _cell(r["reference_s"], "s"),
            _cell(r["ratio"], "ratio"), _cell(r["peak_mb"], "mb"), _cell(r["note"])]) + " |")
    errors = sum(bool(r.get("error")) for r in rows)
    lines += ["", f"{len(rows)} rows, {errors} error(s)."]
    text = "\n".join(lines) + "\n"
    if notes:
        text += "\n" + NOTES_MARKER + "\n" + notes.lstrip("\n")
    return text


def kept_notes(out: Path) -> str:
    """The hand-written text below the notes marker of an existing output file ('' if none)."""
    try:
        text = out.read_text()
    except OSError:
        return ""
    return text.split(NOTES_MARKER, 1)[1] if NOTES_MARKER in text else ""


def run_all(size: str = "full", out: Path | str = HERE / "RESULTS.md", only=None, folder: Path = HERE,
            verbose: bool = True) -> list[dict]:
    """Run the benchmarks (all, or those whose module name contains one of ``only``) and write ``out``."""
    if size not in ("full", "tiny"):
        raise ValueError(f"size must be 'full' or 'tiny', got {size!r}")
    start = time.perf_counter()
    rows = []
    for path in discover(folder):
        if only and not any(o in path.stem for o in only):
            continue
        if verbose:
            print(f"[run_all] {path.stem} ({size}) ...", flush=True)
        t = time.perf_counter()
        new = run_module(path, size)
        rows += new
        if verbose:
            status = "ERROR " + new[0]["note"] if new[0].get("error") else f"{len(new)} rows"
            print(f"[run_all] {path.stem}: {status} in {time.perf_counter() - t:.1f} s", flush=True)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    text = markdown(rows, size, machine_facts(), time.perf_counter() - start, kept_notes(out))
    out.write_text(text)
    if verbose:
        print(f"[run_all] wrote {out}")
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", choices=("full", "tiny"), default="full")
    ap.add_argument("--out", default=str(HERE / "RESULTS.md"))
    ap.add_argument("--only", nargs="*", default=None, help="run only the benchmarks whose name contains one of these")
    args = ap.parse_args()
    rows = run_all(args.size, args.out, args.only)
    sys.exit(1 if any(r.get("error") for r in rows) else 0)


if __name__ == "__main__":
    main()
