"""Where the experiments' worker processes run: on this machine, or as tasks on a Dask cluster.

Both executors start the same worker (``python -m locbook.suite.worker TASK.json``) on the same task file in
the run's staging folder, and the runner reads the same ``.result.json`` back, so the caching, locking,
validation, promotion and retries of :mod:`locbook.suite.runner` do not depend on the executor, and neither do
the numbers. On a cluster the reports folder must be on a file system the workers share (the usual home or
project file system of an HPC cluster), and every worker needs locbook installed.

The Dask executor runs one experiment per task: the task starts the worker process, waits for it, and stops
it (worker and kernel) when the runner writes ``.stop`` into the staging folder (an interrupt of the run, or a
task the runner gave up on), when the task file disappears (the runner removed or moved the staging folder), or
when the Dask worker running the task stops running (it lost its scheduler), so no experiment outlives the run.
The task then writes ``.ended``; a runner that can no longer hear from the cluster waits for it before it removes
the staging folder.
"""
from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from .spec import SuiteError
from .worker import EXIT_DISK_FULL

__all__ = ["LocalExecutor", "DaskExecutor", "make_executor", "run_worker_process"]

_STOP_GRACE_S = 5.0
#: how long to try reaching a scheduler (a cluster being brought up by a batch system may need a few seconds)
_CONNECT_TIMEOUT = "10s"


def _worker_command(task_path: Path | str, parent: int | None = None) -> list[str]:
    cmd = [sys.executable, "-m", "locbook.suite.worker", str(task_path)]
    return cmd + [str(parent)] if parent is not None else cmd


def _no_result(code: int | None, staging: Path) -> dict:
    """What the runner records for a worker that left no result, by its exit status: a worker killed from
    outside, or one that exited without a result, is worth one more attempt (``kernel_failure``); one that
    could not write for lack of space (:data:`~locbook.suite.worker.EXIT_DISK_FULL`) is not."""
    if code == EXIT_DISK_FULL:
        return {"error": f"no space left on device writing {staging}", "kernel_failure": False,
                "disk_full": str(staging)}
    if code is not None and code < 0:
        return {"error": f"worker process died ({signal.Signals(-code).name})", "kernel_failure": True}
    return {"error": f"worker process exited with status {code} without a result", "kernel_failure": True}


def _spawn(task_path, parent=None) -> subprocess.Popen:
    # own session: a terminal's Ctrl-C reaches the runner only, which decides what it means
    return subprocess.Popen(_worker_command(task_path, parent), start_new_session=True, stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def _wait_or_kill(proc: subprocess.Popen, timeout_s: float) -> int:
    try:
        return proc.wait(timeout_s)
    except subprocess.TimeoutExpired:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except OSError:
            pass
        return proc.wait()


class LocalExecutor:
    """Worker processes on this machine, ``jobs`` at a time."""

    is_local = True

    def __init__(self, jobs: int):
        self.capacity = jobs

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return False

    def submit(self, eid: str, task_path: Path) -> subprocess.Popen:
        return _spawn(task_path)

    def done(self, proc) -> bool:
        return proc.poll() is not None

    def no_result(self, proc, staging: Path) -> dict:
        return _no_result(proc.returncode, staging)

    def broken(self) -> str:
        """Why no further experiment can run here ('' while they can)."""
        return ""

    def stop(self, proc, staging: Path) -> None:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)

    #: how long a stopping run waits for its workers before it kills them
    stop_grace_s = _STOP_GRACE_S

    def wait_or_kill(self, proc, staging: Path, timeout_s: float) -> None:
        _wait_or_kill(proc, timeout_s)      # the worker kills its kernel before it exits


def _running_dask_worker():
    """The Dask worker running the calling task, or None outside a Dask task."""
    try:
        from distributed import get_worker
        return get_worker()
    except (ImportError, ValueError):
        return None


def run_worker_process(task_path: str) -> int:
    """The Dask task: run one experiment's worker process to its end and return its exit status.

    The worker gets SIGTERM (it stops its kernel), and SIGKILL after a grace period, as soon as the run no
    longer wants it: the runner wrote ``.stop`` beside the task file (an interrupt, or a task it gave up on),
    the task file is gone (the runner removed or moved the staging folder: it finished or gave up), or the Dask
    worker running this task stopped running (it lost its scheduler, so no result would reach the runner).
    """
    task = Path(task_path)
    proc = _spawn(task_path, parent=os.getpid())
    stop = task.parent / ".stop"
    dask_worker = _running_dask_worker()
    while True:
        try:
            code = proc.wait(0.2)
            break
        except subprocess.TimeoutExpired:
            pass
        lost = dask_worker is not None and getattr(dask_worker.status, "name", "running") not in ("running", "paused")
        if lost or stop.exists() or not task.exists():
            proc.send_signal(signal.SIGTERM)       # the worker kills its kernel, then exits
            code = _wait_or_kill(proc, _STOP_GRACE_S)
            break
    _mark_ended(task.parent)
    return code


def _mark_ended(staging: Path) -> None:
    """Write ``.ended`` into the staging folder once the worker process is gone (it kills its kernel on SIGTERM; one
    killed after the grace period could not, and its kernel exits when it finds its parent gone: ipykernel polls for
    it, ``JPY_PARENT_PID``): a runner that lost this
    task removes the folder only then, or after a grace period. A kernel still starting up recreates its runtime
    folder (ipykernel makes its connection file's parents), so removing earlier could leave the folder behind.
    Written only into a folder that still exists: opening the file never creates one."""
    try:
        (staging / ".ended").write_text("")
    except OSError:
        pass


class DaskExecutor:
    """Each experiment a task on dask.distributed: the scheduler at ``scheduler`` (``tcp://host:8786``, or a
    scheduler file path), or a LocalCluster of ``jobs`` single-threaded workers."""

    is_local = False

    def __init__(self, jobs: int, scheduler: str | None = None):
        try:
            from distributed import Client, LocalCluster
        except ImportError:
            raise SuiteError("--executor dask needs dask.distributed: pip install 'locbook[dask]'") from None
        self.cluster = None
        self.scheduler = scheduler
        try:
            if scheduler:
                if Path(scheduler).is_file():
                    self.client = Client(scheduler_file=scheduler, timeout=_CONNECT_TIMEOUT)
                else:
                    self.client = Client(scheduler, timeout=_CONNECT_TIMEOUT)
            else:
                # In-process workers (one thread each): a task only starts a worker process and waits for it,
                # so nothing is gained by worker processes, and without them a Ctrl-C in the terminal reaches
                # the runner alone, which stops the tasks' workers itself. The scheduler, the workers and the
                # task protocol are those of any dask.distributed cluster.
                self.cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=False,
                                            dashboard_address=None, silence_logs=logging.ERROR)
                self.client = Client(self.cluster)
        except OSError as exc:     # refused, timed out, unknown host
            self.close()
            raise SuiteError(f"cannot reach the Dask scheduler {scheduler or '(local cluster)'}: {exc}") from None
        except (ValueError, TypeError) as exc:
            self.close()
            raise SuiteError(f"--scheduler {scheduler!r} is neither a scheduler address (tcp://HOST:PORT) nor an "
                             f"existing scheduler file ({exc})") from None
        # every queued experiment is submitted at once; the cluster runs as many as it has workers
        self.capacity = 1 << 30

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    def close(self) -> None:
        for thing in (getattr(self, "client", None), self.cluster):
            if thing is not None:
                try:
                    thing.close()
                except Exception:  # closing a cluster that is already gone: nothing left to do
                    pass

    def submit(self, eid: str, task_path: Path):
        # pure=False and a unique key per attempt: an experiment's attempts are never deduplicated or cached
        return self.client.submit(run_worker_process, str(task_path), key=f"locbook-{task_path.parent.name}-"
                                  f"{os.urandom(4).hex()}", pure=False, retries=0)

    # Every call on the client or a future below is guarded: once the scheduler may be gone, the client raises
    # (ClosedClientError, CancelledError, a comm or timeout error) where it used to answer, and a raw traceback from
    # distributed must never replace the run's scoreboard, status update and clean-up.

    def done(self, future) -> bool:
        try:
            return future.done()
        except Exception:      # a future the client can no longer follow is finished for the runner: it is lost
            return True

    def _status(self, future) -> str:
        try:
            return str(future.status)
        except Exception:
            return "lost"

    def no_result(self, future, staging: Path) -> dict:
        """A task that finished without a result file is judged by its worker's exit status. A task the
        cluster lost (cancelled: the client lost its scheduler), one whose exit status can no longer be fetched
        (the client closed meanwhile), or one that failed there (its Dask worker died) may still be running
        somewhere: ``lost`` tells the runner to ask it to stop (``.stop``); a lost task is not retried."""
        status = self._status(future)
        if status == "finished":
            try:
                return _no_result(future.result(timeout=5), staging)
            except Exception as exc:    # finished on the cluster, but its exit status never reached the client
                why = self.broken() or f"its exit status could not be fetched ({type(exc).__name__}: {exc})"
                return {"error": f"Dask task lost: {why}", "kernel_failure": False, "lost": True}
        if status in ("cancelled", "lost"):
            why = self.broken() or "the task was cancelled on the cluster"
            return {"error": f"Dask task lost: {why}", "kernel_failure": False, "lost": True}
        try:
            exc = future.exception(timeout=1)
        except Exception as err:      # the client cannot say any more (it lost its scheduler meanwhile)
            exc = err
        return {"error": f"Dask task failed: {type(exc).__name__}: {exc}", "kernel_failure": True, "lost": True}

    def broken(self) -> str:
        """Why no further experiment can run on the cluster ('' while they can): the client lost its
        scheduler (it is reconnecting, or gave up and closed)."""
        try:
            status = getattr(self.client, "status", "running")
        except Exception:      # a client torn down so far that it cannot say
            status = "unknown"
        if status in ("running", "newly-created"):
            return ""
        # the runner says this in one line; the client's own reconnect errors (tracebacks) would bury it
        for name in [n for n in logging.root.manager.loggerDict if n.split(".")[0] == "distributed"]:
            logging.getLogger(name).setLevel(logging.CRITICAL)   # distributed's config sets some levels itself
        return f"lost the Dask scheduler {self.scheduler or '(local cluster)'} (client {status})"

    def stop(self, future, staging: Path) -> None:
        # written even when the future is done: a task the client saw cancelled may still run on its worker
        try:
            (staging / ".stop").write_text("")
        except OSError:
            pass

    #: how long a stopping run waits for all its tasks: their own grace before they kill a worker, and that again
    stop_grace_s = 2 * _STOP_GRACE_S

    def wait_or_kill(self, future, staging: Path, timeout_s: float) -> None:
        """Wait until the task's worker has ended (its ``.ended``), at most ``timeout_s``: what is left of the
        stopping run's :attr:`stop_grace_s`, one budget for all its tasks. The future alone cannot say so once the
        client lost its scheduler, while the task may still be running on its Dask worker (or start there: a task
        that finds ``.stop`` stops at once, but one that started just before may be making its folders)."""
        deadline = time.perf_counter() + timeout_s
        try:
            future.result(timeout=timeout_s)
        except Exception:  # timed out, cancelled or failed: the run is stopping either way
            pass
        try:
            future.cancel()
        except Exception:  # a closed client (ClosedClientError): the task is the cluster's to drop, .stop stops it
            pass
        while staging.is_dir() and not (staging / ".ended").exists() and time.perf_counter() < deadline:
            time.sleep(0.05)


def make_executor(kind: str, jobs: int, scheduler: str | None = None):
    if kind == "local":
        return LocalExecutor(jobs)
    if kind == "dask":
        return DaskExecutor(jobs, scheduler)
    raise SuiteError(f"executor must be 'local' or 'dask', got {kind!r}")
