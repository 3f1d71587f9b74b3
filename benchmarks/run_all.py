"""Run every benchmark and write one Markdown table.

    python benchmarks/run_all.py [--size full|tiny] [--out benchmarks/RESULTS.md] [--only NAME ...]

Imports every ``benchmarks/bench_*.py`` (discovered, so a new one is picked up), calls its ``run(size)`` (the
protocol of ``benchmarks/_harness.py``: rows made by ``_harness.row``, yielded as each measurement finishes) and writes
the rows as a table, with the machine facts (CPU, Python, numpy, numba, date, git commit), to ``--out``. Each row is
printed when it arrives and the table so far is written to ``<out>.partial`` after every row; ``--out`` itself is
replaced (atomically) only when every module has run, so an interrupted run leaves the last complete table intact
and the rows it measured in the partial file. A benchmark that raises, or yields something that is not a row, becomes
an error row; the others still run. Text below the line ``<!-- notes: kept by run_all.py -->`` in an existing output
file (the hand-written analysis) is carried over unchanged.

The process runs with BLAS pinned to one thread: ``threadpoolctl`` in the process, and the ``*_NUM_THREADS``
variables for the processes it starts (``main`` re-executes itself once with them set, so that they also hold from
the start).
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
if str(HERE) not in sys.path:
    sys.path.insert(0, str(HERE))
import _harness  # noqa: E402

#: set before numpy loads (main re-executes itself with them): one BLAS thread
RUN_ENV = {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}
KEYS = _harness.KEYS
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
    out = dict.fromkeys(KEYS)
    out.update(method=f"{name}: ERROR", workload="", locbook_s=seconds, note=message, benchmark=name, error=True)
    return out


def row_problems(i: int, r) -> list[str]:
    """What is wrong with one row ([] if nothing)."""
    if not isinstance(r, dict):
        return [f"row {i} is a {type(r).__name__}"]
    problems = []
    missing = [k for k in KEYS if k not in r]
    if missing:
        problems.append(f"row {i} lacks {missing}")
    t = r.get("locbook_s")
    if not (isinstance(t, (int, float)) and math.isfinite(t) and t > 0):
        problems.append(f"row {i} ({r.get('method')}) has locbook_s = {t!r}")
    return problems


def check_rows(rows) -> list[str]:
    """What is wrong with a module's rows ([] if nothing)."""
    if not isinstance(rows, list) or not rows:
        return [f"run() returned {type(rows).__name__}, not a non-empty list of rows"]
    return [p for i, r in enumerate(rows) for p in row_problems(i, r)]


def iter_module(path: Path, size: str):
    """The rows of one benchmark as they finish, each tagged with its module; an error row where it fails (a bad
    row, or an exception: the rows before it are kept)."""
    name = path.stem
    start = time.perf_counter()
    n = 0
    try:
        rows = load(path).run(size)
        if isinstance(rows, dict) or not hasattr(rows, "__iter__"):
            raise TypeError(f"run() returned {type(rows).__name__}, not rows")
        for r in rows:
            problems = row_problems(n, r)
            n += 1
            if problems:
                yield _error_row(name, "; ".join(problems), time.perf_counter() - start)
            else:                   # results that disagree with the reference beyond the stated tolerance fail the run
                yield dict(r, benchmark=name, error=str(r.get("agreement") or "").startswith("DISAGREE"))
    except Exception as exc:                                  # noqa: BLE001 - reported as a row, never a crash
        tb = traceback.format_exception_only(type(exc), exc)[-1].strip()
        yield _error_row(name, tb, time.perf_counter() - start)
        return
    if n == 0:
        yield _error_row(name, "run() gave no rows", time.perf_counter() - start)


def run_module(path: Path, size: str) -> list[dict]:
    """The rows of one benchmark, each tagged with its module; an error row if it fails."""
    return list(iter_module(path, size))


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
    from locbook.suite.catalog import machine_label  # the CPU as report.json and `locbook list` name it
    commit = _git("rev-parse", "--short", "HEAD") or "unknown"
    dirty = _git("--no-optional-locks", "status", "--porcelain", "--untracked-files=no")   # read-only
    try:
        load = "%.2f %.2f %.2f" % os.getloadavg()
    except OSError:
        load = "n/a"
    return {"date": datetime.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z"),
            "git commit": commit + (" (working tree modified)" if dirty else ""),
            "CPU": machine_label(), "load average (1, 5, 15 min) at the end": load,
            "platform": platform.platform(), "python": sys.version.split()[0], "numpy": numpy.__version__,
            "scipy": scipy.__version__, "numba": numba_version,
            "LOCBOOK_NUMBA": os.environ.get("LOCBOOK_NUMBA", "(unset: compiled kernels on)"),
            "BLAS threads": _blas_threads()}


def _blas_threads() -> str:
    try:
        from threadpoolctl import threadpool_info
        return ", ".join(f"{p['internal_api']} {p['num_threads']}" for p in threadpool_info()) or "none loaded"
    except ImportError:
        return "unknown (threadpoolctl not installed)"


def _cell(value, kind: str = "") -> str:
    if value is None or value == "":
        return ""
    if kind == "s":
        return f"{value:.3g}" if value < 100 else f"{value:.0f}"
    if kind == "ratio":
        return f"{value:.3g}x" if value < 100 else f"{value:.0f}x"
    if kind == "mb":
        return f"{value:.3g}" if value < 1000 else f"{value:.0f}"
    return str(value).replace("|", "\\|").replace("\n", " ")


COLUMNS = ("benchmark", "method", "workload", "locbook CPU (s)", "locbook wall (s)", "reference", "reference CPU (s)",
           "ratio (CPU)", "ratio (wall)", "goal", "peak (MiB)", "reference peak (MiB)", "agreement", "load (1 min)",
           "note")


def _table_row(r: dict) -> str:
    method = ("**" + _cell(r["method"]) + "**") if r.get("error") else _cell(r["method"])
    return "| " + " | ".join([
        _cell(r.get("benchmark")), method, _cell(r["workload"]), _cell(r.get("locbook_cpu_s"), "s"),
        _cell(r["locbook_s"], "s"), _cell(r["reference"]), _cell(r.get("reference_cpu_s"), "s"),
        _cell(r.get("ratio_cpu"), "ratio"), _cell(r["ratio"], "ratio"), _cell(r.get("goal")),
        _cell(r["peak_mb"], "mb"), _cell(r.get("reference_peak_mb"), "mb"), _cell(r.get("agreement")),
        _cell(r.get("load")), _cell(r["note"])]) + " |"


def markdown(rows: list[dict], size: str, facts: dict, seconds: float, notes: str = "",
             module_seconds: dict | None = None, complete: bool = True) -> str:
    state = "" if complete else " (IN PROGRESS: the run has not finished; the rows so far)"
    lines = [f"# Benchmark results ({size}){state}", "",
             f"Written by `python benchmarks/run_all.py --size {size}` in {seconds:.0f} s. Each ratio is reference / "
             "locbook of the medians of paired, alternated calls in one process (at least 5 of each; "
             "`benchmarks/_harness.py`), in CPU time and in wall time; a reference marked \"scaled\" ran on a "
             "subset of the runs and its times were scaled to the whole workload (locbook always runs the whole "
             "workload). Peak memory is the increase of the process's peak resident set during one more call of "
             "each side after the timed ones, with malloc's free memory returned to the system first (numpy "
             "arrays and compiled kernels' buffers alike), in MiB; a workload timed once is timed and measured "
             "in the same call. The agreement column compares the two results "
             "of the same run; the load column is the 1-minute load average before and after the measurement. "
             "BLAS runs on one thread.", "", "| machine | |", "|---|---|"]
    lines += [f"| {k} | {_cell(v)} |" for k, v in facts.items()]
    lines += ["", "| " + " | ".join(COLUMNS) + " |",
              "|" + "|".join("---:" if c.endswith(("(s)", "(CPU)", "(wall)", "(MiB)")) else "---" for c in COLUMNS)
              + "|"]
    lines += [_table_row(r) for r in rows]
    errors = sum(bool(r.get("error")) for r in rows)
    lines += ["", f"{len(rows)} rows, {errors} error(s)."]
    if module_seconds:
        lines += ["", "| module | wall time (s) |", "|---|---:|"]
        lines += [f"| {k} | {v:.1f} |" for k, v in module_seconds.items()]
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


def _write(path: Path, text: str) -> None:
    """Write ``path`` atomically (a temporary file renamed over it)."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def run_all(size: str = "full", out: Path | str = HERE / "RESULTS.md", only=None, folder: Path = HERE,
            verbose: bool = True) -> list[dict]:
    """Run the benchmarks (all, or those whose module name contains one of ``only``) and write ``out`` (module
    docstring: rows printed and written to ``<out>.partial`` as they finish, ``out`` replaced at the end)."""
    if size not in ("full", "tiny"):
        raise ValueError(f"size must be 'full' or 'tiny', got {size!r}")
    from threadpoolctl import threadpool_limits
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    partial = out.with_name(out.name + ".partial")
    notes = kept_notes(out)
    start = time.perf_counter()
    rows, module_seconds = [], {}
    with threadpool_limits(limits=1, user_api="blas"):
        for path in discover(folder):
            if only and not any(o in path.stem for o in only):
                continue
            if verbose:
                print(f"[run_all] {path.stem} ({size}) ...", flush=True)
            t = time.perf_counter()
            for r in iter_module(path, size):
                rows.append(r)
                if verbose:
                    print("  " + ("ERROR " + r["note"] if r.get("error") else _harness.format_row(r)), flush=True)
                _write(partial, markdown(rows, size, machine_facts(), time.perf_counter() - start, notes,
                                         module_seconds, complete=False))
            module_seconds[path.stem] = time.perf_counter() - t
            if verbose:
                print(f"[run_all] {path.stem}: {module_seconds[path.stem]:.1f} s", flush=True)
    _write(out, markdown(rows, size, machine_facts(), time.perf_counter() - start, notes, module_seconds))
    partial.unlink(missing_ok=True)
    if verbose:
        print(f"[run_all] wrote {out} in {time.perf_counter() - start:.0f} s")
    return rows


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--size", choices=("full", "tiny"), default="full")
    ap.add_argument("--out", default=str(HERE / "RESULTS.md"))
    ap.add_argument("--only", nargs="*", default=None, help="run only the benchmarks whose name contains one of these")
    args = ap.parse_args()
    if args.only and Path(args.out).resolve() == (HERE / "RESULTS.md").resolve():
        ap.error("--only writes a table of the selected benchmarks alone: give --out another file (the full table "
                 "in benchmarks/RESULTS.md is written by a run of all of them)")
    if any(os.environ.get(k) != v for k, v in RUN_ENV.items()):       # once: before numpy and malloc start
        os.execve(sys.executable, [sys.executable, *sys.argv], {**os.environ, **RUN_ENV})
    rows = run_all(args.size, args.out, args.only)
    sys.exit(1 if any(r.get("error") for r in rows) else 0)


if __name__ == "__main__":
    main()
