"""Execute the notebook suite with papermill: validation, locking, caching, worker processes, reports.

Layout of a reports folder (``reports/<profile>/``, or its own folder for a run with ``-p`` overrides)::

    index.html, index.md, numbers.csv        the whole suite (numbers.csv: every printed number)
    <id>/<id>.ipynb, <id>.html               the executed notebook and its HTML page
    <id>/summary.md, report.md, *.png, *.csv lightweight results (committed for the full profile)
    <id>/report.html                         the whole page in HTML
    <id>/report.json                         stamp, parameters and run time of the report (committed)
    <id>/run.json                            cache record: key, data files and modules read with their hashes
                                             (taken as the kernel opened them), symbolic links read through, time
    .lock                                    held by the run writing this folder
    .staging/<run>/<id>/                     experiments in progress, one folder per run
    .failed/<id>/                            the last failed attempt, kept for inspection
    status.json                              the last attempt of each experiment
    dataset.json                             a data run's folder only: the data set it holds (identity, title,
                                             attribution, licence, manifest, geometry, the experiments left out)

Guarantees (docs/running.md, "Interrupts, concurrent runs and the cache"):

- one run at a time per folder: a second run waits for the lock and says so;
- each experiment runs in its own worker process; a worker that dies fails only its experiment (retried
  once, as is a kernel that dies on start); every other experiment finishes;
- a finished experiment is validated (notebook readable, every file in its manifest present, numbers.csv
  well formed; a bracket point's figures are captions only) and then promoted by renames; only then is its cache
  record written, so a failed, interrupted or concurrent run never replaces or corrupts a good report;
- SIGINT / SIGTERM: no new experiment starts, running ones are stopped (worker and kernel), finished ones
  are kept, and :class:`SuiteRun` says what ran and what did not;
- a full disk (ENOSPC, or the quota) is not a kernel failure: the run stops as on an interrupt, without
  retrying, its staging removed and every earlier report intact; :attr:`SuiteRun.disk_full` names the path;
- an executor that can run nothing more (a lost Dask scheduler): every running experiment is asked to stop
  (``.stop``), and :attr:`SuiteRun.executor_error` says why; a client that closed meanwhile (its calls raise) ends
  the run the same way, with its outcomes, its status and its staging removed;
- a data file (or module) is recorded with the hash of the content the kernel read, taken as it opened it, and one
  read through a symbolic link with the link and its target: a file edited, or a link re-pointed, while its
  experiment ran leaves a report that is kept, not served as cached (the run says so);
- the suite files (index, numbers.csv) are rebuilt from every experiment folder present, so a partial run
  keeps the other experiments' previous results, each with its own stamp.
"""
from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import subprocess
import threading
import time
import uuid
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

from ..reproduce.report import NUMBER_COLUMNS
from . import cachekey, notebook_html
from .cachekey import (
    cache_key,
    data_hashes,
    data_unchanged,
    dependency_versions,
    links_unchanged,
    locbook_version,
    package_dir,
)
from .executors import make_executor
from .files import machine_label, read_json, write_text_atomic
from .params import read_notebook
from .progress import expected_seconds, make_progress
from .spec import PROFILES, Experiment, Suite, SuiteError
from .worker import disk_full_path

__all__ = ["KERNEL_NAME", "run_tasks", "Task", "cache_key", "Outcome", "SuiteRun", "check_options", "report_cached"]

#: Every notebook runs on this kernel; jupyter_client maps it to the running interpreter.
KERNEL_NAME = "python3"
_WORKER_FILES = (".runtime", ".result.json", ".result.json.tmp", ".task.json", ".data-read.log", ".modules-read.log",
                 ".stop", ".ended")


@dataclass(frozen=True)
class Task:
    """One notebook execution: ``experiment`` with checked ``parameters``, reported in ``<report_dir>/<key>/``.

    ``locbook run`` makes one per experiment (``key`` = the experiment id); a study (:mod:`locbook.suite.study`)
    one per point, so one runner session runs every point of a study. The notebook always runs as its experiment
    (its numbers.csv rows name ``experiment.id``); ``key`` names only the folder, the status and the outcome."""

    key: str
    experiment: Experiment
    parameters: dict = field(hash=False)
    #: False: the notebook's figures are neither drawn nor saved (matplotlib's Agg backend, :meth:`Report.figure`
    #: records the caption only): the points of a bracket, whose numbers are all that is read of them
    figures: bool = True
    #: what a person reads for this task in the live view and the scoreboard (a sweep point by its settings,
    #: ``sigma_db=1.5 rep 0``); empty: the key
    label: str = field(default="", hash=False)
    #: a report folder that may already hold this very run (a sweep point equal to the profile's own report of the
    #: experiment, ``<reports>/<profile>/<experiment>``): when that report is the same run and up to date under its own
    #: record (a report with figures also serves a task without), it is copied in, its pages written for this
    #: folder, instead of executing the notebook again (:meth:`_Scheduler.reuse`)
    reuse: Path | None = field(default=None, hash=False)


@dataclass
class Outcome:
    id: str
    status: str  # "ok", "cached", "failed", "interrupted" or "not run"
    seconds: float
    error: str = ""
    attempts: int = 0


@dataclass
class SuiteRun:
    """What a run did: one :class:`Outcome` per selected experiment, the folder written, and the signal that
    stopped the run (``None`` if it ran to the end)."""

    outcomes: list[Outcome]
    report_dir: Path
    interrupted_by: int | None = None
    #: the path a write failed on for lack of space (disk or quota full); the run stopped there
    disk_full: str | None = None
    #: why the executor could run nothing more (a lost Dask scheduler); the run stopped there
    executor_error: str = ""
    #: a data run: the selected experiments left out because the data set does not meet their
    #: ``[experiment.data_run] needs``, each with why (:func:`locbook.suite.run.select_for_data`); they are no
    #: outcome of the run
    left_out: dict[str, str] = field(default_factory=dict)
    #: key -> the task's label (:attr:`Task.label`), where it has one
    labels: dict[str, str] = field(default_factory=dict)

    def count(self, status: str) -> int:
        return sum(o.status == status for o in self.outcomes)

    def name(self, key: str) -> str:
        """What a person reads for the task of ``key``: its label, else the key."""
        return self.labels.get(key) or key


def _git_state(root: Path | None) -> tuple[str, str]:
    """``(short commit, uncommitted changes under locbook/ and notebooks/)`` of a locbook clone; ``("", "")``
    outside git or for an installed package (whose folder may sit inside someone else's repository)."""
    if root is None:
        return "", ""

    def git(*args):
        return subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True,
                              timeout=10).stdout.rstrip()     # porcelain lines start with a status column
    try:
        rev = git("rev-parse", "--short", "HEAD").strip()
        dirty = git("status", "--porcelain", "--", "locbook", "notebooks") if rev else ""
    except (OSError, subprocess.SubprocessError):
        return "", ""
    return rev, dirty


def _committed_reports(root: Path, report_dir: Path) -> bool:
    """True when git tracks files in ``report_dir`` (the committed ``reports/full``)."""
    try:
        out = subprocess.run(["git", "-C", str(root), "ls-files", "--", str(report_dir.resolve())],
                             capture_output=True, text=True, timeout=10).stdout
    except (OSError, subprocess.SubprocessError):
        return False
    return bool(out.strip())


# ---------------------------------------------------------------------------------------------------
# small file helpers: every suite-level file is written to a temporary name, then renamed

def _is_folder(path: Path) -> bool:
    """``path`` is a real folder (not a file, nor a symbolic link, even one to a folder)."""
    return path.is_dir() and not path.is_symlink()


def _remove(path: Path, ignore_errors: bool = False) -> None:
    """Remove ``path`` whatever it is: a folder tree, or a file or symbolic link (which ``rmtree`` refuses)."""
    try:
        if _is_folder(path):
            shutil.rmtree(path, ignore_errors=ignore_errors)
        elif os.path.lexists(path):
            path.unlink()
    except OSError:
        if not ignore_errors:
            raise


def _replace_dir(new: Path, final: Path):
    """Swap ``new`` into place of ``final``: ``final -> .old-<name>``, ``new -> final``, remove the old copy.
    A crash between the two renames leaves ``.old-<name>``, which :func:`_recover` puts back. ``final`` (or a left
    ``.old-<name>``) that is a plain file or a symbolic link is no report: it is moved aside and removed the same
    way (lexists: a dangling link, which ``exists`` does not see, would make the second rename fail)."""
    old = final.with_name(f".old-{final.name}")
    _remove(old)
    if os.path.lexists(final):
        final.rename(old)
    new.rename(final)
    _remove(old)


def _recover(report_dir: Path) -> None:
    """Undo what an interrupted run left (called under the lock, so no other run is using these)."""
    for old in report_dir.glob(".old-*"):
        final = report_dir / old.name[len(".old-"):]
        if os.path.lexists(final):
            _remove(old, ignore_errors=True)
        else:
            old.rename(final)
    _remove(report_dir / ".staging", ignore_errors=True)     # a file of that name too: the run makes a folder there
    for tmp in report_dir.glob(".*.tmp"):
        tmp.unlink(missing_ok=True)


def _validate_report(folder: Path, exp_id: str, figures: bool = True) -> str:
    """'' if ``folder`` holds a complete report of ``exp_id``, else what is wrong. ``figures``: the run was asked
    for its figures (a report without them is then incomplete)."""
    try:
        read_notebook(folder / f"{exp_id}.ipynb")
    except Exception as exc:
        return f"executed notebook unreadable ({exc})"
    manifest = read_json(folder / "manifest.json", None)
    if not isinstance(manifest, dict):
        return "manifest.json missing or malformed (the notebook did not create a locbook Report)"
    unsaved = manifest.get("figures_saved") is False      # a bracket point's figures were not drawn
    if unsaved and figures:
        return "its figures were not saved (LOCBOOK_FIGURES=off), but this run asked for them"
    drawn = [f for f in manifest.get("figures", []) if not (unsaved and f.get("file") == "")]
    for item in drawn + manifest.get("tables", []):
        for name in [item["file"], *item.get("exports", [])]:       # the PDF, SVG and LaTeX copies too
            if not (folder / name).is_file():
                return f"{name} is listed in the manifest but missing"
    numbers = folder / "numbers.csv"
    if numbers.exists():
        try:
            with open(numbers, newline="", encoding="utf-8") as fh:
                reader = csv.DictReader(fh)
                if tuple(reader.fieldnames or ()) != NUMBER_COLUMNS:
                    return f"numbers.csv has columns {reader.fieldnames}, expected {list(NUMBER_COLUMNS)}"
                rows = list(reader)
        except UnicodeDecodeError as exc:
            return f"numbers.csv is not UTF-8 text (byte {exc.start}: {exc.reason})"
        except csv.Error as exc:
            return f"numbers.csv is not well-formed CSV ({exc})"
        except OSError as exc:
            return f"numbers.csv unreadable ({exc.strerror or exc})"
        if len(rows) != manifest.get("n_numbers", len(rows)):
            return f"numbers.csv has {len(rows)} rows, the manifest says {manifest.get('n_numbers')}"
        if any(r["experiment"] != exp_id for r in rows):
            return "numbers.csv holds rows of another experiment"
    return ""


def _validate_promoted(folder: Path, exp_id: str, figures: bool = True) -> str:
    """'' if ``folder`` holds a complete promoted report of ``exp_id`` (:func:`_validate_report` plus the files
    :func:`_promote` writes), else what is wrong."""
    why = _validate_report(folder, exp_id, figures)
    if why:
        return why
    try:
        record = json.loads((folder / "report.json").read_text(encoding="utf-8"))
    except UnicodeDecodeError as exc:
        return f"report.json is not UTF-8 text (byte {exc.start})"
    except ValueError as exc:
        return f"report.json is not JSON ({exc})"
    except OSError as exc:
        return f"report.json unreadable ({exc.strerror or exc})"
    if not isinstance(record, dict) or record.get("experiment") != exp_id:
        return f"report.json does not describe {exp_id}"
    for name in ("summary.md", "report.md", "report.html"):
        try:
            (folder / name).read_text(encoding="utf-8")
        except UnicodeDecodeError as exc:
            return f"{name} is not UTF-8 text (byte {exc.start})"
        except OSError as exc:
            return f"{name} unreadable ({exc.strerror or exc})"
    return ""


def _same_run(exp: Experiment, a: dict, b: dict) -> bool:
    """``a`` and ``b`` (checked parameters of ``exp``) run the notebook alike: every declared parameter, absent ones
    at the notebook's default, equal in value and type (an explicit ``a = 1.0`` is the default ``a: float = 1.0``)."""
    declared = exp.declared_parameters()
    if set(a) - set(declared) or set(b) - set(declared):
        return False
    return all(_same_value(a.get(name, p.default), b.get(name, p.default)) for name, p in declared.items())


def _same_value(x, y) -> bool:
    """Equal in value and in type at every level (a default ``[0, 5]`` of a ``list[float]`` is not ``[0.0, 5.0]``)."""
    if type(x) is not type(y):
        return False
    if isinstance(x, (list, tuple)):
        return len(x) == len(y) and all(map(_same_value, x, y))
    if isinstance(x, dict):
        return x.keys() == y.keys() and all(_same_value(x[k], y[k]) for k in x)
    return bool(x == y)


def report_cached(folder: Path, exp: Experiment, key: str, figures: bool = True) -> tuple[bool, str]:
    """``(True, "")`` when the report in ``folder`` is up to date and intact; ``(False, why)`` when it
    would be up to date but is damaged (``why`` says what is wrong), ``(False, "")`` when it is stale or absent.
    A damaged report is never served: it is executed again."""
    run = read_json(folder / "run.json", {})
    data, modules, links = run.get("data", {}), run.get("modules"), run.get("links", {})
    if not (run.get("cache_key") == key and run.get("status") == "ok" and isinstance(data, dict)
            and isinstance(modules, dict) and isinstance(links, dict) and data_unchanged(data)
            and data_unchanged(modules) and links_unchanged(links)):
        return False, ""
    why = _validate_promoted(folder, exp.id, figures)
    return not why, why


# ---------------------------------------------------------------------------------------------------
# reports


# ---------------------------------------------------------------------------------------------------
# the run

class _Stop:
    """SIGINT / SIGTERM while the suite runs: remember the first signal; the loop stops at its next turn."""

    def __init__(self):
        self.signum: int | None = None
        self._previous = {}

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signum, _frame):
        if self.signum is None:
            self.signum = signum

    def __exit__(self, *exc):
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        return False


def _check_kernel(kernel_name: str) -> None:
    from jupyter_client.kernelspec import KernelSpecManager, NoSuchKernel
    try:
        KernelSpecManager().get_kernel_spec(kernel_name)
    except NoSuchKernel:
        raise SuiteError(f"no Jupyter kernel named {kernel_name!r} is installed; install ipykernel in this "
                         "environment (pip install ipykernel)") from None


def _acquire(lock, report_dir: Path, stop: _Stop, progress) -> bool:
    from filelock import Timeout
    try:
        lock.acquire(timeout=0)
        return True
    except Timeout:
        progress.message(f"another locbook run is writing {report_dir}; waiting for it to finish (Ctrl-C to give up)")
    while stop.signum is None:
        try:
            lock.acquire(timeout=0.5)
            return True
        except Timeout:
            continue
    return False


def check_options(timeout_s: float, jobs: int, executor: str, scheduler: str | None) -> None:
    if not timeout_s > 0:
        raise SuiteError(f"the timeout must be a positive number of seconds, got {timeout_s}")
    if jobs < 1:
        raise SuiteError(f"jobs must be at least 1, got {jobs}")
    if executor not in ("local", "dask"):
        raise SuiteError(f"executor must be 'local' or 'dask', got {executor!r}")
    if scheduler and executor != "dask":
        raise SuiteError("a scheduler address needs --executor dask")


def run_tasks(suite: Suite, tasks: list[Task], profile: str, report_dir: Path, *, write_reports, write_pages,
              jobs: int = 1,
              force: bool = False, timeout_s: float = 1800, retries: int = 1, kernel_name: str = KERNEL_NAME,
              progress="plain", executor: str = "local", scheduler: str | None = None,
              data_roots: list[str] | None = None) -> SuiteRun:
    """Run ``tasks`` (checked parameters; distinct keys) into ``report_dir`` (an absolute path) under its lock,
    with every guarantee of the module docstring, then call ``write_reports(report_dir, outcomes)`` (also after
    an interrupt; one :class:`Outcome` per task) to rebuild the folder's aggregate files. ``write_pages(exp,
    profile, params, staging, folder, stamp)`` writes one report's pages into its validated staging folder
    (:func:`locbook.suite.site.write_experiment_pages`): the pages are the site's, passed in, so that the runner
    imports no page code. :func:`locbook.suite.run.run_suite` and
    ``locbook study`` (:func:`locbook.suite.study.run_study`) both run here."""
    from filelock import FileLock

    check_options(timeout_s, jobs, executor, scheduler)
    if len({t.key for t in tasks}) != len(tasks):
        raise SuiteError("every task of a run needs its own key (it names the task's folder)")
    if isinstance(progress, str):
        progress = make_progress(progress)
    rev, dirty = _git_state(suite.repository)
    if dirty and _committed_reports(suite.repository, report_dir):
        changed = ", ".join(line[3:] for line in dirty.splitlines()[:5])
        raise SuiteError(f"{report_dir} holds committed reports, which are stamped with the commit that produced "
                         f"them; commit (or set aside) the changes under locbook/ and notebooks/ first ({changed})")
    _check_kernel(kernel_name)
    try:
        report_dir.mkdir(parents=True, exist_ok=True)
        probe = report_dir / f".write-test-{os.getpid()}"
        probe.write_text("")
        probe.unlink()
    except OSError as exc:
        if disk_full_path(exc, str(report_dir)) is not None:
            raise          # not bad input: the CLI says which path, with the full-disk exit status
        raise SuiteError(f"cannot write to the reports folder {report_dir}: {exc.strerror}") from None
    # data files read under these folders are hashed into the cache record (a changed file reruns the report)
    data_roots = [str(package_dir()), str(suite.root.parent / "shared"), *(data_roots or [])]
    run = SuiteRun([], report_dir, labels={t.key: t.label for t in tasks if t.label})
    with _Stop() as stop:
        lock = FileLock(str(report_dir / ".lock"))
        if not _acquire(lock, report_dir, stop, progress):
            run.interrupted_by = stop.signum
            run.outcomes = [Outcome(t.key, "not run", 0.0) for t in tasks]
            return run
        try:
            _recover(report_dir)
            keys = [t.key for t in tasks]
            progress.labels = dict(run.labels)      # the views name a sweep's points by their settings
            progress.begin(keys, expected_seconds(report_dir, keys))
            try:
                with make_executor(executor, jobs, scheduler) as pool:
                    _run_locked(suite, tasks, profile, report_dir, data_roots, force, timeout_s, retries,
                                kernel_name, write_reports, write_pages, stop, run, progress, pool)
            finally:
                progress.end(run)
        finally:
            lock.release()
    run.interrupted_by = stop.signum
    order = {t.key: i for i, t in enumerate(tasks)}
    run.outcomes.sort(key=lambda o: order[o.id])
    return run


def _longest_first(report_dir: Path, profile: str, ids):
    """The launch order: the longest experiments first (their last run time in this folder, else in the other
    profile's folder beside it, for a first run), so that at the end no worker waits alone on a long one; experiments
    never timed first of all (they may be long), then the suite's order among equals."""
    seconds = expected_seconds(report_dir, ids)
    for other in PROFILES:
        sibling = report_dir.parent / other
        if other != profile and report_dir.name == profile and sibling.is_dir():
            seconds = {**expected_seconds(sibling, [e for e in ids if e not in seconds]), **seconds}
    return lambda item: -seconds.get(item[0], float("inf"))


def _run_locked(suite, tasks, profile, report_dir, data_roots, force, timeout_s, retries, kernel_name,
                write_reports, write_pages, stop, run, progress, pool):
    """Run ``tasks`` with the folder's lock held: :class:`_Scheduler` (its docstring)."""
    _Scheduler(suite, tasks, profile, report_dir, data_roots, force, timeout_s, retries, kernel_name, write_reports,
               write_pages, stop, run, progress, pool).run()


class _Scheduler:
    """One locked session of the runner: the cached tasks finished, the rest queued longest first, launched up to
    the executor's capacity, each result validated and promoted (or retried once, or kept under ``.failed/``), and
    at the end, whatever stopped it, every running task stopped, every task given an outcome, the staging removed
    and the suite files rebuilt. Its state: ``queue`` ((id, attempt) to launch), ``running`` (id -> (executor
    handle, staging, attempt, started or None)), ``abandoned`` ((handle, staging) of lost tasks asked to stop,
    which may still be running), and ``status`` (``status.json``)."""

    def __init__(self, suite, tasks, profile, report_dir, data_roots, force, timeout_s, retries, kernel_name,
                 write_reports, write_pages, stop, run, progress, pool):
        self.profile, self.report_dir, self.data_roots = profile, report_dir, data_roots
        self.timeout_s, self.retries, self.kernel_name = timeout_s, retries, kernel_name
        self.write_reports, self.write_pages = write_reports, write_pages
        self.stop, self.suite_run, self.progress, self.pool = stop, run, progress, pool
        source, versions = cachekey.runner_fingerprint(), dependency_versions()
        rev, dirty = _git_state(suite.repository)
        self.stamp = locbook_version() + (f" (source {rev}{' + uncommitted changes' if dirty else ''})" if rev else "")
        self.status_path = report_dir / "status.json"
        self.status = read_json(self.status_path, {})
        self.by_id = {t.key: t for t in tasks}
        self.keys = {t.key: cache_key(t.experiment, profile, t.parameters, source=source, versions=versions,
                                      figures=t.figures) for t in tasks}
        self.fingerprint = {"source": source, "versions": versions}
        self.staging_root = report_dir / ".staging" / f"{os.getpid()}-{uuid.uuid4().hex[:8]}"
        queue: deque = deque()
        for t in tasks:
            cached, damaged = ((False, "") if force else
                               report_cached(report_dir / t.key, t.experiment, self.keys[t.key], t.figures))
            if cached:
                self.finish(Outcome(t.key, "cached", 0.0))
            elif not force and t.reuse is not None and stop.signum is None and self.reuse(t):
                progress.message(f"{run.name(t.key)}: the same run as {t.reuse}: its report reused")
                self.finish(Outcome(t.key, "cached", 0.0))
            else:
                if damaged:
                    progress.message(f"{t.key}: the cached report is damaged ({damaged}); executing it again")
                queue.append((t.key, 1))
        self.queue = deque(sorted(queue, key=_longest_first(report_dir, profile, [eid for eid, _ in queue])))
        self.running: dict[str, tuple] = {}
        self.abandoned: list[tuple] = []

    def reuse(self, t: Task) -> bool:
        """Serve ``t`` from the report in ``t.reuse`` when that report is the same run (its parameters, every one
        the notebook declares filled in with its default, equal ``t``'s in value and type) and up to date under its
        own record's key (with figures: a report with them serves a task without): copied into staging under that
        folder's lock (not waited for: a folder being written is not read), checked again on the copy, its pages
        written for this folder (a study's page links no bracket) and its records for this task, then promoted like
        a run. False (the task is executed) when there is nothing to reuse or anything fails."""
        from filelock import FileLock, Timeout

        exp = t.experiment
        theirs = read_json(t.reuse / "report.json", {}).get("parameters")
        if not isinstance(theirs, dict) or not _same_run(exp, theirs, t.parameters):
            return False
        source_key = cache_key(exp, self.profile, theirs, **self.fingerprint)
        staging = self.staging_root / f"{t.key}-reused"
        try:
            lock = FileLock(str(t.reuse.parent / ".lock"))
            lock.acquire(timeout=0)
        except (Timeout, OSError):
            return False
        try:
            if not report_cached(t.reuse, exp, source_key)[0]:
                return False
            staging.parent.mkdir(parents=True, exist_ok=True)
            shutil.copytree(t.reuse, staging, symlinks=True)
        except OSError:
            _remove(staging, ignore_errors=True)
            return False
        finally:
            lock.release()
        try:
            if not report_cached(staging, exp, source_key)[0]:
                raise OSError("the copy is not the report it was copied from")
            record = read_json(staging / "report.json", {})
            self.write_pages(exp, self.profile, t.parameters, staging, self.report_dir / t.key,
                             str(record.get("locbook", self.stamp)))
            (staging / "report.json").write_text(json.dumps({**record, "parameters": t.parameters}, indent=1,
                                                            sort_keys=True) + "\n")
            run = read_json(staging / "run.json", {})
            (staging / "run.json").write_text(json.dumps({**run, "cache_key": self.keys[t.key]}, indent=1))
            _replace_dir(staging, self.report_dir / t.key)
        except Exception:       # anything amiss: the notebook is executed instead, as without a report to reuse
            _remove(staging, ignore_errors=True)
            return False
        return True

    def disk_full(self, path) -> None:
        """A write failed for lack of space: the run stops (no retry, no new experiment)."""
        if self.suite_run.disk_full is None:
            self.suite_run.disk_full = str(path)
            self.progress.message(f"no space left on device writing {path}; stopping the run")

    def halted(self) -> bool:
        run = self.suite_run
        return self.stop.signum is not None or run.disk_full is not None or bool(run.executor_error)

    def finish(self, outcome: Outcome):
        self.suite_run.outcomes.append(outcome)
        if outcome.status != "not run":
            self.status[outcome.id] = {"status": outcome.status, "seconds": round(outcome.seconds, 2),
                                       "error": outcome.error}
            try:
                write_text_atomic(self.status_path, json.dumps(self.status, indent=1, sort_keys=True))
            except OSError as exc:
                path = disk_full_path(exc, str(self.status_path))
                if path is None:
                    raise
                self.disk_full(path)    # the record of this attempt is lost; the reports are not
        self.progress.finished(outcome)

    def launch(self, eid: str, attempt: int):
        pool = self.pool
        staging = self.staging_root / f"{eid}-{attempt}"
        exp = self.by_id[eid].experiment
        task = {"id": exp.id, "notebook": str(exp.notebook), "parameters": self.by_id[eid].parameters,
                "staging": str(staging), "timeout": self.timeout_s, "kernel": self.kernel_name,
                "data_roots": self.data_roots, "runner_pid": os.getpid(), "figures": self.by_id[eid].figures}
        writing = staging
        try:
            staging.mkdir(parents=True)
            writing = staging / ".task.json"
            writing.write_text(json.dumps(task))
            handle = pool.submit(eid, staging / ".task.json")
        except Exception as exc:   # a full disk, or an executor that lost its cluster: this one has not started
            self.queue.appendleft((eid, attempt))
            shutil.rmtree(staging, ignore_errors=True)
            path = disk_full_path(exc, str(writing))
            if path is not None:
                self.disk_full(path)
            elif pool.broken():
                self.suite_run.executor_error = pool.broken()
            else:
                raise
            return
        self.running[eid] = (handle, staging, attempt, None)

    def mark_started(self):
        """An experiment is running once its worker has made its runtime folder (on a cluster, a submitted
        task may wait for a free worker); the elapsed time counts from then."""
        running = self.running
        for eid, (handle, staging, attempt, started) in running.items():
            if started is None and (self.pool.is_local or (staging / ".runtime").exists()):
                running[eid] = (handle, staging, attempt, time.perf_counter())
                self.progress.started(eid, attempt)

    def complete(self, eid: str, handle, staging: Path, attempt: int, started: float | None):
        pool, run, progress, by_id, report_dir = self.pool, self.suite_run, self.progress, self.by_id, self.report_dir
        seconds = time.perf_counter() - started if started is not None else 0.0
        result = read_json(staging / ".result.json", None)
        if not isinstance(result, dict):
            result = {"seconds": seconds, **pool.no_result(handle, staging)}
        result.setdefault("seconds", seconds)
        if not result.get("error") and not result.get("lost") and by_id[eid].figures:   # (a bracket point's page:
            result.update(_export_page(staging, by_id[eid].experiment.id))              # its .ipynb is linked)
        if result.get("lost"):
            # the executor gave up on the task, which may still be running where it was sent: ask it to stop,
            # and leave its staging folder in place (removed with the run's) so that nothing writes elsewhere
            pool.stop(handle, staging)
            self.abandoned.append((handle, staging))
            if pool.broken():
                run.executor_error = pool.broken()
        if result.get("disk_full"):
            self.disk_full(result["disk_full"])
        elif (result["error"] and result.get("kernel_failure") and attempt <= self.retries and not self.halted()):
            progress.message(f"{eid}: {result['error']}; retrying once")
            self.queue.appendleft((eid, attempt + 1))
            return
        error = result["error"] or _validate_report(staging, by_id[eid].experiment.id, by_id[eid].figures)
        # the outcome's time is the live view's clock: from the start the row showed to now, the page export and
        # the promotion included (report.json keeps the notebook's own execution time, the next run's estimate)
        wall = time.perf_counter() - started if started is not None else result["seconds"]
        if not error:
            final = report_dir / eid
            if os.path.lexists(final) and not _is_folder(final):     # no report: the new one takes its place
                kind = "a symbolic link" if final.is_symlink() else "a file"
                progress.message(f"{eid}: {final} was {kind}, not a report folder; replaced by the new report")
            try:
                changed = _promote(by_id[eid].experiment, self.profile, by_id[eid].parameters, staging,
                                   report_dir / eid, self.stamp, self.keys[eid], result, self.write_pages)
                if changed:
                    more = f" (and {len(changed) - 1} more)" if len(changed) > 1 else ""
                    progress.message(f"{eid}: {changed[0]}{more} changed while it ran, after its kernel read it; the "
                                     "report is kept, and the next run executes it again")
            except OSError as exc:
                path = disk_full_path(exc, str(staging))
                if path is not None:
                    self.disk_full(path)
                    error = f"no space left on device writing {path}"
                else:
                    error = f"could not write the report: {exc.strerror or exc}"
        if error:
            if not (result.get("lost") or run.disk_full):   # nothing to inspect in an attempt the disk cut short
                try:
                    _keep_failed(staging, report_dir / ".failed" / eid)
                except OSError:
                    pass
            self.finish(Outcome(eid, "failed", wall, error, attempt))
        else:
            self.finish(Outcome(eid, "ok", wall, "", attempt))

    def run(self):
        """Launch, poll and complete until the queue and the running tasks are empty or the run halts; then
        :meth:`shut_down`, whatever happened."""
        pool, run, queue, running = self.pool, self.suite_run, self.queue, self.running
        try:
            while queue or running:
                if self.halted():
                    break
                while queue and len(running) < pool.capacity and not self.halted():
                    self.launch(*queue.popleft())
                self.mark_started()
                time.sleep(0.1)
                for eid in [e for e, (h, *_rest) in running.items() if pool.done(h)]:
                    handle, staging, attempt, started = running.pop(eid)
                    if started is None:
                        self.progress.started(eid, attempt)
                    self.complete(eid, handle, staging, attempt, started)
                if not run.executor_error and pool.broken():
                    run.executor_error = pool.broken()
        finally:
            self.shut_down()

    def shut_down(self):
        """An interrupt, a full disk, a lost cluster (or an unexpected error in :meth:`run`): stop the workers, keep
        everything finished. Each step runs whatever the one before it met (an executor's error is held until the
        end), so every experiment gets its outcome, the staging is always removed and the suite files rebuilt."""
        pool, run, stop, running, report_dir = self.pool, self.suite_run, self.stop, self.running, self.report_dir
        held: list[BaseException] = []

        def guarded(call, *args):
            try:
                call(*args)
            except Exception as exc:
                held.append(exc)

        for eid, (handle, staging, attempt, started) in running.items():
            guarded(pool.stop, handle, staging)
        deadline = time.perf_counter() + pool.stop_grace_s      # one budget for every task of the run
        if stop.signum:
            why = f"stopped by {signal.Signals(stop.signum).name}"
        elif run.disk_full is not None:
            why = "stopped: no space left on device"
        else:
            why = f"stopped: {run.executor_error}" if run.executor_error else "stopped"
        for eid, (handle, staging, attempt, started) in running.items():
            guarded(pool.wait_or_kill, handle, staging, max(0.0, deadline - time.perf_counter()))
            self.finish(Outcome(eid, "interrupted", time.perf_counter() - started if started is not None else 0.0,
                                why, attempt))
        for handle, staging in self.abandoned:     # their staging goes only once they have ended (or their time is up)
            guarded(pool.wait_or_kill, handle, staging, max(0.0, deadline - time.perf_counter()))
        for eid, _attempt in self.queue:
            self.finish(Outcome(eid, "not run", 0.0))
        _remove_staging(self.staging_root)
        try:
            self.write_reports(report_dir, run.outcomes)
        except OSError as exc:
            path = disk_full_path(exc, str(report_dir))
            if path is None:
                raise
            self.disk_full(path)        # the previous index and numbers.csv stay as they were
        if held:
            raise held[0]          # an executor's own error (not a lost cluster: that is guarded there), after clean-up


def _export_page(staging: Path, exp_id: str) -> dict:
    """Write the executed notebook's HTML page (``<id>.html``, :func:`locbook.suite.notebook_html.export_html`) into
    ``staging``; ``{}``, or the result fields of its failure (an export that fails fails the experiment, without hiding
    its notebook, which stays for inspection; a full disk names the path). The runner exports every page itself: a
    worker would pay nbconvert's and mathtext's start (about 1.5 s) once per experiment, the runner once per run.
    A bracket point (no figures: only its numbers are read) gets none; the site links its ``.ipynb``."""
    notebook = staging / f"{exp_id}.ipynb"
    if not notebook.exists():         # nothing to export: the validation says what is missing
        return {}
    page = staging / f"{exp_id}.html"
    try:
        body = notebook_html.export_html(notebook)      # self-contained: the math drawn to SVG, no script from a CDN
        page.write_text(body, encoding="utf-8")
    except Exception as exc:  # an HTML failure must not hide the notebook's own result
        path = disk_full_path(exc, str(page))
        if path is not None:
            return {"error": f"no space left on device writing {path}", "kernel_failure": False, "disk_full": path}
        return {"error": f"HTML export failed: {type(exc).__name__}: {exc}", "kernel_failure": False}
    return {}


def _remove_staging(path: Path, within_s: float = 5.0) -> None:
    """Remove a run's staging folder, called once its workers have ended (their ``.ended``) or their grace
    period is over. A kernel's last writes may still land for a moment, and a file created while ``rmtree`` walks
    the tree makes a folder's removal fail: it is tried again until the folder is gone or ``within_s`` has passed
    (the next run's :func:`_recover` removes what is left, such as the runtime folder a kernel still starting on
    an unreachable node would make again)."""
    deadline = time.perf_counter() + within_s
    while True:
        shutil.rmtree(path, ignore_errors=True)
        if not path.exists() or time.perf_counter() > deadline:
            return
        time.sleep(0.1)


def _strip_worker_files(staging: Path) -> None:
    for name in _WORKER_FILES:
        path = staging / name
        if path.is_dir():
            shutil.rmtree(path, ignore_errors=True)
        else:
            path.unlink(missing_ok=True)


def _keep_failed(staging: Path, failed: Path) -> None:
    _strip_worker_files(staging)
    failed.parent.mkdir(exist_ok=True)
    _replace_dir(staging, failed)


def _promote(exp, profile, params, staging: Path, folder: Path, stamp: str, key: str, result: dict,
             write_pages) -> list[str]:
    """Write the summary and the records into the validated staging folder, then swap it into place. The cache
    record (run.json) is written before the swap, inside the new folder, so it only ever describes a
    complete report. Returns the files (and links) read that changed while the experiment ran: the record holds
    what the kernel read, so the next run executes this report again."""
    data, links, changed = data_hashes(staging)
    modules, _module_links, changed_modules = data_hashes(staging, ".modules-read.log")
    _strip_worker_files(staging)
    write_pages(exp, profile, params, staging, folder, stamp)
    (staging / "report.json").write_text(json.dumps(
        {"experiment": exp.id, "profile": profile, "parameters": params, "locbook": stamp,
         "seconds": round(result["seconds"], 1), "machine": result.get("machine") or machine_label()}, indent=1,
        sort_keys=True) + "\n")
    (staging / "run.json").write_text(json.dumps({
        "cache_key": key, "status": "ok", "seconds": round(result["seconds"], 2), "data": data, "links": links,
        "modules": modules}, indent=1))
    _replace_dir(staging, folder)
    return changed + changed_modules
