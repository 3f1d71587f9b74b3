"""One experiment in its own process: ``python -m locbook.suite.worker TASK.json``.

The runner starts one worker per notebook, each in its own session, so a worker that dies (SIGKILL, out of
memory) fails only its experiment. The worker executes the notebook with papermill into the task's staging
folder and writes ``result.json`` there; it never touches the report itself.

Clean-up guarantees: if the runner dies (even by SIGKILL) the worker gets SIGTERM from the kernel
(``PR_SET_PDEATHSIG`` on Linux; a parent watch elsewhere); on SIGTERM the worker kills its Jupyter kernel and
exits. A kernel whose worker vanished exits by itself (ipykernel's parent poller, ``JPY_PARENT_PID``).

A full disk (or quota) is not a kernel failure: the worker records ``disk_full`` (the path that could not be
written) in its result, or, when even the result cannot be written, exits with :data:`EXIT_DISK_FULL`; the
runner then stops the run instead of retrying.
"""
from __future__ import annotations

import errno
import json
import math
import os
import re
import signal
import stat
import sys
import threading
import time
from pathlib import Path

import psutil  # at import, not in the SIGTERM handler: an import there could wait on the import lock
from threadpoolctl import threadpool_limits

from .files import machine_label, write_text_atomic

#: one BLAS/OpenMP thread per worker: set before the kernel starts, so its numpy loads BLAS with one thread (``--jobs
#: N`` workers then use N cores, not N x cores: 2 workers x 2 OpenBLAS threads on 2 cores cost the grid filter 4x its
#: CPU time); the worker's own libraries are limited through threadpoolctl (_run)
SINGLE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
                 "BLIS_NUM_THREADS": "1", "VECLIB_MAXIMUM_THREADS": "1", "NUMEXPR_NUM_THREADS": "1"}
#: failures worth one more attempt: the kernel died or never answered (the papermill/ipykernel port race)
KERNEL_FAILURES = ("DeadKernelError", "ZMQError", "Kernel died", "kernel_info", "Kernel didn't respond")
#: rw-rw-rw- before the umask: the mode open() gives new files
_FILE_MODE = stat.S_IRUSR | stat.S_IWUSR | stat.S_IRGRP | stat.S_IWGRP | stat.S_IROTH | stat.S_IWOTH
#: no space left on the device, or the disk quota exceeded
DISK_FULL_ERRNOS = (errno.ENOSPC, errno.EDQUOT)
#: exit status of a worker that could not even write its result for lack of space (28 = ENOSPC on Linux)
EXIT_DISK_FULL = 28
_DISK_FULL_TEXT = re.compile(r"\[Errno (?:%s)\][^:']*(?::\s*'([^']*)')?" % "|".join(map(str, DISK_FULL_ERRNOS)))


def disk_full_path(exc: BaseException, default: str) -> str | None:
    """The path ``exc`` (or an exception it was raised from) could not write for lack of space: its file
    name, or ``default`` when it names none; ``None`` when ``exc`` is not a full disk or quota."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, OSError) and exc.errno in DISK_FULL_ERRNOS:
            return os.fsdecode(exc.filename) if exc.filename else default
        exc = exc.__cause__ or exc.__context__
    return None


def _disk_full_in_text(text: str, default: str) -> str:
    """The same for an error raised inside the kernel, known by its text (``[Errno 28] ...: 'path'``)."""
    match = _DISK_FULL_TEXT.search(text)
    return (match.group(1) or default) if match else ""


def _kill_kernels_and_exit(signum=signal.SIGTERM, _frame=None):
    try:
        descendants = psutil.Process().children(recursive=True)   # the kernel and anything it started
    except psutil.Error:
        descendants = []
    for child in descendants:
        try:
            os.killpg(child.pid, signal.SIGKILL)      # the kernel leads its own session
        except OSError:
            try:
                child.kill()
            except psutil.Error:
                pass
    os._exit(128 + int(signum))


def _die_with_parent(parent: int):
    try:  # Linux: the kernel signals us the moment the runner dies
        import ctypes
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)   # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent:                    # the runner died before prctl took effect
        _kill_kernels_and_exit()

    def watch():
        while True:
            if os.getppid() != parent:
                _kill_kernels_and_exit()
            time.sleep(0.5)

    threading.Thread(target=watch, daemon=True).start()


def execute(task: dict) -> dict:
    """Run the notebook; return ``{"error", "kernel_failure", "disk_full", "seconds"}``; never raises.
    ``disk_full``: the path that could not be written for lack of space ('' otherwise)."""
    import papermill as pm

    staging = Path(task["staging"])
    out_nb = staging / f"{task['id']}.ipynb"
    start = time.perf_counter()
    error, kernel_failure, disk_full = "", False, ""
    try:
        pm.execute_notebook(task["notebook"], str(out_nb), parameters=task["parameters"],
                            kernel_name=task["kernel"], cwd=str(Path(task["notebook"]).parent),
                            # nbclient wants whole seconds
                            progress_bar=False, log_output=False, execution_timeout=math.ceil(task["timeout"]))
    except pm.PapermillExecutionError as exc:
        error = f"{exc.ename}: {exc.evalue}"
        disk_full = _disk_full_in_text(error, str(staging))
    except Exception as exc:  # kernel death, timeout, missing kernel, I/O: the run fails, the suite goes on
        error = f"{type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc).strip() else ''}"
        disk_full = disk_full_path(exc, str(staging)) or ""
        kernel_failure = not disk_full and any(k in error for k in KERNEL_FAILURES)
    seconds = time.perf_counter() - start
    # the notebook's HTML page is the runner's to write (locbook.suite.runner._export_page): once per run, not once
    # per experiment, does it pay nbconvert's start
    if disk_full:
        error = f"no space left on device writing {disk_full}"
    # "machine": where the seconds were measured, this worker's machine (on a cluster, not the runner's)
    return {"error": error, "kernel_failure": kernel_failure, "disk_full": disk_full, "seconds": seconds,
            "machine": machine_label()}


def main(task_path: str, parent: int | None = None) -> int:
    """``parent``: the process that started this worker (the runner, or a Dask task on a cluster node)."""
    from .._lazy import skip_iri_format_checker
    skip_iri_format_checker()      # before papermill imports nbformat (and jsonschema)
    task = json.loads(Path(task_path).read_text())
    _die_with_parent(parent if parent is not None else task["runner_pid"])
    signal.signal(signal.SIGTERM, _kill_kernels_and_exit)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the runner decides what an interrupt means
    staging = Path(task["staging"])
    try:
        return _run(task, staging)
    except OSError as exc:
        path = disk_full_path(exc, str(staging))
        if path is None:
            raise
        try:   # a result names the path; if even that cannot be written, the exit status says it
            _write_result(staging, {"error": f"no space left on device writing {path}", "kernel_failure": False,
                                    "disk_full": path, "seconds": 0.0})
        except OSError:
            pass
        return EXIT_DISK_FULL


def _write_result(staging: Path, result: dict) -> None:
    # the temporary name is fixed: the runner strips it with the other worker files
    write_text_atomic(staging / ".result.json", json.dumps(result), tmp=staging / ".result.json.tmp")


def _run(task: dict, staging: Path) -> int:
    runtime = staging / ".runtime"     # own folder for the kernel's connection file and temporary files
    runtime.mkdir(exist_ok=True)
    os.environ.update(SINGLE_THREAD)
    threadpool_limits(limits=1)         # libraries this process has already loaded (the variables act at load)
    os.environ.update({"LOCBOOK_OUTPUT_DIR": str(staging), "LOCBOOK_EXPERIMENT": task["id"],
                       "LOCBOOK_DATA_LOG": str(staging / ".data-read.log"),
                       "LOCBOOK_MODULE_LOG": str(staging / ".modules-read.log"),
                       "LOCBOOK_DATA_ROOTS": os.pathsep.join(task["data_roots"]),
                       "JUPYTER_RUNTIME_DIR": str(runtime), "TMPDIR": str(runtime),
                       "PYDEVD_DISABLE_FILE_VALIDATION": "1"})
    os.environ.pop("LOCBOOK_FIGURES", None)     # never inherited: only the task decides
    if not task.get("figures", True):     # a bracket point: Agg draws nothing until saved, and Report saves nothing
        quiet = "ignore:FigureCanvasAgg is non-interactive:UserWarning"     # plt.show() under Agg
        os.environ.update({"MPLBACKEND": "Agg", "LOCBOOK_FIGURES": "off",
                           "PYTHONWARNINGS": ",".join(filter(None, [os.environ.get("PYTHONWARNINGS", ""), quiet]))})
    # the kernel inherits stderr: keep its chatter in a log beside the report
    # read-write for all before the umask, as open() creates every other report file (os.open's default
    # also sets the execute bits)
    log = staging / "kernel-stderr.log"
    log_fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, _FILE_MODE)
    os.dup2(log_fd, 2)
    os.close(log_fd)
    result = execute(task)
    _drop_kernel_chatter(log)
    _write_result(staging, result)
    return EXIT_DISK_FULL if result["disk_full"] else 0


#: lines of kernel-stderr.log that say nothing about the notebook: papermill's parser of the parameters cell, which
#: reads no annotated line (``seed: int = 1``; locbook reads the cell itself); papermill on a value the notebook
#: does not declare (locbook checks every -p against the declared parameters first); ipykernel's note on the
#: local TCP transport of every kernel
KERNEL_CHATTER = (re.compile(r"Unable to parse line \d+ "), re.compile(r"Passed unknown parameter: "),
                  re.compile(r"\[IPKernelApp\] WARNING \| Kernel is running over TCP without encryption\."))


def _drop_kernel_chatter(log: Path, fd: int = 2) -> None:
    """Rewrite ``log`` (open as ``fd``: this process's stderr) without the :data:`KERNEL_CHATTER` lines, in place:
    ``fd`` stays on the same file for anything written later. A log that cannot be read is left as it is."""
    try:
        lines = log.read_text(encoding="utf-8", errors="replace").splitlines(keepends=True)
    except OSError:
        return
    kept = [line for line in lines if not any(p.match(line) for p in KERNEL_CHATTER)]
    if len(kept) == len(lines):
        return
    try:
        if fd == 2:
            sys.stderr.flush()
        os.lseek(fd, 0, os.SEEK_SET)
        os.ftruncate(fd, 0)
        with open(fd, "wb", closefd=False) as fh:
            fh.write("".join(kept).encode("utf-8"))
    except OSError:                 # a full disk: the report's own files say so; the log is only for diagnosis
        pass


if __name__ == "__main__":
    sys.exit(main(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else None))
