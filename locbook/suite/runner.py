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
  well formed; a bracket point's figures are captions only) and then promoted by renames; only then is its cache record written, so a failed,
  interrupted or concurrent run never replaces or corrupts a good report;
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
import hashlib
import io
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
import uuid
from collections import deque
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path

from . import site
from ..errors import ParameterError
from ..reproduce.report import NUMBER_COLUMNS
from .files import machine_label, read_csv, read_json, write_text_atomic
from .params import read_notebook
from .executors import make_executor
from .worker import disk_full_path
from .progress import expected_seconds, make_progress
from .spec import PROFILES, SAFE_NAME, Experiment, Suite, SuiteError

__all__ = ["KERNEL_NAME", "run_suite", "run_tasks", "Task", "cache_key", "Outcome", "SuiteRun",
           "write_suite_reports", "override_folder_name", "data_kinds", "select_for_data", "user_method_failures",
           "USER_METHODS_TABLE"]

#: Every notebook runs on this kernel; jupyter_client maps it to the running interpreter.
KERNEL_NAME = "python3"
_DEPENDENCIES = ("numpy", "scipy", "cvxpy", "clarabel", "osqp", "scs", "matplotlib", "papermill",
                 "nbclient", "nbconvert", "nbformat", "ipykernel", "numba")
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
    #: ``[experiment.data_run] needs``, each with why (:func:`select_for_data`); they are no outcome of the run
    left_out: dict[str, str] = field(default_factory=dict)

    def count(self, status: str) -> int:
        return sum(o.status == status for o in self.outcomes)


def locbook_version() -> str:
    from .. import __version__
    return __version__


def _package_dir() -> Path:
    return Path(__file__).resolve().parents[1]


#: the runner process's locbook code (package-relative patterns): the suite, the reproduction layer it imports, the
#: package's own start-up modules and errors, and the templates of the report pages
_RUNNER_SOURCES = ("suite/*.py", "suite/templates/**/*", "reproduce/*.py", "__init__.py", "_lazy.py", "_datalog.py",
                   "errors.py")


def _runner_fingerprint() -> str:
    """The runner's side of a report: the sources of the suite (which writes the pages) and of what it imports from
    locbook (:data:`_RUNNER_SOURCES`), and the report site's templates. A fixed set, so a run from the command line
    and one from Python share their cache. The kernel's side, the library code the notebook ran, is recorded per
    experiment (``run.json`` "modules", like its data files)."""
    package = _package_dir()
    files = {path for pattern in _RUNNER_SOURCES for path in package.glob(pattern) if path.is_file()}
    h = hashlib.sha256()
    for path in sorted(files):
        h.update(str(path.relative_to(package)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def _dependency_versions() -> dict[str, str]:
    versions = {"python": sys.version.split()[0]}
    for name in _DEPENDENCIES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "absent"
    return versions


def _notebook_fingerprint(path: Path) -> str:
    nb = read_notebook(path)
    h = hashlib.sha256()
    for cell in nb.cells:  # sources and tags only: outputs and execution counts do not matter
        h.update(cell.cell_type.encode())
        h.update(cell.source.encode())
        h.update(json.dumps(cell.get("metadata", {}).get("tags", [])).encode())
    return h.hexdigest()


def cache_key(exp: Experiment, profile: str, params: dict, *, source: str | None = None,
              versions: dict | None = None, figures: bool = True) -> str:
    """Hash of notebook, parameters, profile, the runner's locbook source (:func:`_runner_fingerprint`) and
    dependency versions. The data files an experiment reads and the library modules its kernel imports are checked
    separately, by their hashes recorded in ``run.json``."""
    payload = {
        "experiment": exp.id, "profile": profile, "parameters": params,
        "notebook": _notebook_fingerprint(exp.notebook),
        "locbook": source or _runner_fingerprint(),
        "versions": versions or _dependency_versions(),
        **({} if figures else {"figures": False}),      # the keys of runs with figures are unchanged
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


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


def override_folder_name(profile: str, overrides: dict[str, str]) -> str:
    """Folder of a run with ``-p`` overrides: the profile, the overrides in words, and a hash of them
    (``quick-sigma-db-2-5-a1b2c3d4``), ``[a-z0-9-]`` only."""
    words = "-".join(f"{k}-{overrides[k]}" for k in sorted(overrides))
    slug = re.sub(r"[^a-z0-9]+", "-", words.lower()).strip("-")[:60].strip("-")
    digest = hashlib.sha256(json.dumps(overrides, sort_keys=True).encode()).hexdigest()[:8]
    return "-".join(p for p in (profile, slug, digest) if p)


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
        if not (folder / item["file"]).is_file():
            return f"{item['file']} is listed in the manifest but missing"
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


def _data_hashes(staging: Path, log: str = ".data-read.log") -> tuple[dict[str, str], dict[str, str], list[str]]:
    """``(hashes, links, changed)`` of every data file (or, with ``log=".modules-read.log"``, every locbook module
    source) the kernel logged as read (see locbook._datalog): ``hashes`` maps each file to the SHA-256 of the content
    the kernel read (hashed as it opened it), ``links`` each path opened through a symbolic link to its target then,
    and ``changed`` lists the files that differ now from what the kernel read (edited, removed or, for a link,
    re-pointed while the experiment ran). The record keeps what was read, so such a report is not served as cached:
    the next run sees the change and executes it again. A plain path line (an older kernel's locbook) is hashed
    now, as before."""
    logged = staging / log
    try:
        lines = logged.read_text(encoding="utf-8").splitlines()
    except FileNotFoundError:
        lines = []
    hashes: dict[str, str] = {}
    links: dict[str, str] = {}
    changed: set[str] = set()
    for line in lines:
        entry = _log_entry(line)
        if entry is None:
            continue
        path, digest, link = entry
        try:
            now = _sha256(Path(path)) if Path(path).is_file() else None
        except OSError:
            now = None
        if digest is None:              # no hash from the kernel: what is there now (a file gone is no file read)
            if now is None:
                continue
            digest = now
        first = hashes.setdefault(path, digest)          # a file read twice: the record keeps the first read
        if now != digest or first != digest:
            changed.add(path)
        if link is not None:
            first = links.setdefault(link, path)
            if os.path.realpath(link) != path or first != path:
                changed.add(link)
    return dict(sorted(hashes.items())), dict(sorted(links.items())), sorted(changed)


def _log_entry(line: str) -> tuple[str, str | None, str | None] | None:
    """``(target, sha256 or None, link or None)`` of one line of a read log: a JSON object, or a plain path."""
    if not line.startswith("{"):
        return (line, None, None) if line else None
    try:
        entry = json.loads(line)
        path, digest, link = entry["path"], entry["sha256"], entry.get("link")
    except (ValueError, KeyError, TypeError, AttributeError):     # a line cut short (a worker killed writing it)
        return None
    if not (isinstance(path, str) and isinstance(digest, str) and isinstance(link, (str, type(None)))):
        return None
    return path, digest, link


def _data_unchanged(recorded: dict[str, str]) -> bool:
    for path, digest in recorded.items():
        try:
            if _sha256(Path(path)) != digest:
                return False
        except (OSError, TypeError, ValueError):     # gone, unreadable, or a damaged record
            return False
    return True


def _links_unchanged(recorded: dict[str, str]) -> bool:
    """Every symbolic link a report read through still points where it did (re-pointed: another file was read)."""
    try:
        return all(os.path.realpath(link) == target for link, target in recorded.items())
    except (OSError, TypeError, ValueError):         # a damaged record
        return False


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


def _cached(folder: Path, exp: Experiment, key: str, figures: bool = True) -> tuple[bool, str]:
    """``(True, "")`` when the report in ``folder`` is up to date and intact; ``(False, why)`` when it
    would be up to date but is damaged (``why`` says what is wrong), ``(False, "")`` when it is stale or absent.
    A damaged report is never served: it is executed again."""
    run = read_json(folder / "run.json", {})
    data, modules, links = run.get("data", {}), run.get("modules"), run.get("links", {})
    if not (run.get("cache_key") == key and run.get("status") == "ok" and isinstance(data, dict)
            and isinstance(modules, dict) and isinstance(links, dict) and _data_unchanged(data)
            and _data_unchanged(modules) and _links_unchanged(links)):
        return False, ""
    why = _validate_promoted(folder, exp.id, figures)
    return not why, why


# ---------------------------------------------------------------------------------------------------
# reports

def write_suite_reports(suite: Suite, report_dir: Path, *, list_all: bool = True) -> None:
    """Rebuild ``numbers.csv``, ``index.html`` and ``index.md`` from the experiment folders present (and the
    reading brackets in ``<reports>/brackets/``: :mod:`locbook.suite.bracket`); in a profile's folder also each
    document's findings page (:mod:`locbook.suite.findings`) and conclusions page (:mod:`locbook.suite.conclusions`),
    from the same rows.

    An experiment's rows come from its own folder, whatever run wrote it, so a partial run leaves the
    others' results as they were. ``list_all=False`` (folders of ``-p`` runs) lists only the experiments
    present."""
    from .bracket import SITE_NUMBER_COLUMNS, bracket_of_rows, brackets_root, load_bracket

    status = read_json(report_dir / "status.json", {})
    dataset = site.dataset_record(report_dir)       # a data run's folder: the data set's page, not the scoreboard
    rows, entries = [], []
    for exp in suite.experiments:
        folder = report_dir / exp.id
        present = (folder / "summary.md").is_file()
        # a data set's page names every experiment that takes a data set: those run, those failed, those left out
        listed = present or list_all or (dataset is not None and (exp.data_run is not None or exp.id in status))
        if not listed:
            continue
        numbers = read_csv(folder / "numbers.csv") if present else []
        # each row's reading bracket, from <reports>/brackets/<id>/bracket.csv when one was run (else empty); not
        # for a -p run's folder, whose rows were computed under other readings than the bracket's default
        bracket = load_bracket(brackets_root(report_dir) / exp.id) if report_dir.name in PROFILES else []
        numbers = bracket_of_rows(numbers, bracket, read_json(folder / "report.json", {}).get("profile"))
        rows += numbers
        entries.append({"exp": exp, "present": present, "report": read_json(folder / "report.json", {}),
                        "run": read_json(folder / "run.json", {}), "last": status.get(exp.id, {}),
                        "numbers": numbers})
    out = io.StringIO()
    writer = csv.DictWriter(out, fieldnames=SITE_NUMBER_COLUMNS)
    writer.writeheader()
    for r in rows:
        writer.writerow({c: r.get(c, "") for c in SITE_NUMBER_COLUMNS})
    write_text_atomic(report_dir / "numbers.csv", out.getvalue())
    if dataset is not None:
        write_text_atomic(report_dir / "index.html", site.data_index_html(report_dir, entries, dataset, locbook_version()))
        write_text_atomic(report_dir / "index.md", site.data_index_markdown(report_dir, entries, dataset))
        return
    # the findings pages, the conclusions pages and the index from the same rows as numbers.csv (one tally)
    from .findings import write_findings
    from .conclusions import write_conclusions
    profile = site._profile_of(report_dir)
    if report_dir.name in PROFILES:
        write_findings(report_dir, entries, rows, profile, lambda path, text: write_text_atomic(path, text))
    conclusions = write_conclusions(report_dir, suite, entries, rows,
                                    lambda path, text: write_text_atomic(path, text)) if report_dir.name in PROFILES else {}
    write_text_atomic(report_dir / "index.html", site.index_html(report_dir, entries, rows, locbook_version(),
                                                             conclusions))
    write_text_atomic(report_dir / "index.md", site.index_markdown(report_dir, entries, rows, conclusions))


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


def _absolute(path) -> Path:
    """``path`` (``~`` expanded) as an absolute path, without resolving symbolic links."""
    return Path(os.path.abspath(Path(path).expanduser()))


def split_overrides(experiments: list[Experiment], overrides: dict[str, str]):
    """``-p`` on several experiments: each takes the overrides its notebook declares, and one that declares none of
    them is left out (it would only rerun its defaults). Returns ``(kept experiments, {id: its overrides}, left-out
    ids)``. A name that no selected experiment declares is refused (ParameterError naming the experiments); with one
    experiment every name must be its own (the usual check, in :meth:`Experiment.parameters`)."""
    names = [k for k in overrides if k != "data"]
    if len(experiments) <= 1 or not names:
        return list(experiments), {e.id: dict(overrides) for e in experiments}, []
    declared = {e.id: e.declared_parameters() for e in experiments}
    nobody = [k for k in names if not any(k in d for d in declared.values())]
    if nobody:
        raise ParameterError(f"unknown parameter {', '.join(repr(k) for k in nobody)}: none of the "
                             f"{len(experiments)} selected experiments declares it "
                             f"({', '.join(e.id for e in experiments)}); `locbook show ID` lists an experiment's")
    kept, each, left_out = [], {}, []
    for e in experiments:
        mine = {k: v for k, v in overrides.items() if k in declared[e.id] or k == "data"}
        if any(k in declared[e.id] for k in names):
            kept.append(e)
            each[e.id] = mine
        else:
            left_out.append(e.id)
    return kept, each, left_out


def run_suite(suite: Suite, experiments: list[Experiment], profile: str, *, jobs: int = 1, force: bool = False,
              overrides: dict[str, str] | None = None, report_root: Path | None = None,
              out_dir: Path | None = None, timeout_s: float = 1800, retries: int = 1,
              kernel_name: str = KERNEL_NAME, progress="plain", executor: str = "local",
              scheduler: str | None = None, data: str | None = None, requested=None, methods=(),
              trackers=()) -> SuiteRun:
    """Run experiments and write their reports; see the module docstring for the guarantees.

    ``data``: a data set (a shipped name or a folder with ``dataset.toml``; :func:`locbook.data.dataset.load_dataset`
    checks it first) for every selected experiment, each of which must take one (a ``data`` parameter: the measured-
    data experiments and the cross-document benchmark). Its reports go to ``data-<name>/`` inside the folder the run
    would otherwise write (``<report_root>/<profile>/data-<name>/``), and its files join the cache key. An experiment
    whose ``[experiment.data_run] needs`` the data set does not meet is left out before anything runs (one message
    each; :attr:`SuiteRun.left_out`; recorded for the data set's page), unless its id is in ``requested`` (the ids
    asked for by name; default: every experiment given): that is an error (:func:`select_for_data`). The values of
    ``[experiment.data_run] parameters`` apply to a data run, under ``overrides``.

    ``methods`` / ``trackers``: static methods and trackers of your own (:class:`locbook.user_methods.UserMethod`,
    ``--method`` / ``--tracker``), a data run's only: each experiment that declares a ``methods`` (``trackers``)
    parameter gets them, ``NAME=SPEC`` with a file absolute, so they join its cache key (and the kernel records the
    content of the code it ran, :func:`locbook._datalog.record_read`); the report folder stays the data run's. A
    name the data set's own ``[[method]]`` tables use too is refused before anything runs.

    Parameters of every selected experiment are checked before any executes (raises ParameterError); with several
    experiments, each takes the ``overrides`` it declares and those declaring none are left out
    (:func:`split_overrides`).
    The reports go to ``<report_root>/<profile>/``, or, with ``overrides``, to their own folder
    (:func:`override_folder_name`) so that the profile's default report is never touched; ``out_dir``
    names the folder explicitly. ``retries``: further attempts for an experiment whose worker or kernel died.
    ``progress``: a mode of :func:`locbook.suite.progress.make_progress` ("auto", "live", "plain", "quiet") or
    a view object. ``executor``: "local" (worker processes on this machine, ``jobs`` at a time) or "dask"
    (each experiment a task on dask.distributed: the cluster at ``scheduler``, or a LocalCluster of ``jobs``
    workers); both run the same worker, so caching, locking, retries and numbers are the same.
    """
    overrides = dict(overrides or {})
    _check_options(timeout_s, jobs, executor, scheduler)
    data_roots: list[str] = []
    per_experiment: dict[str, dict] = {}
    dataset_name = identity = None
    facts: dict = {}
    left_out: dict[str, str] = {}
    if "data" in overrides:
        if data is not None:
            raise SuiteError("give the data set once: --data or -p data=..., not both")
        data = overrides.pop("data")          # -p data=X is --data X: checked, hashed, its own folder
    given = [k for k in ("methods", "trackers") if k in overrides]
    if given:
        raise SuiteError(f"-p {given[0]}: give methods of your own with --method NAME=SPEC and --tracker NAME=SPEC "
                         "(a file relative to this folder)")
    methods, trackers = list(methods or ()), list(trackers or ())
    if (methods or trackers) and data is None:
        raise SuiteError("--method and --tracker run on a data set: give one with --data DIR")
    chosen = [k for k in ("calibration", "anchors") if k in overrides]
    if chosen and data is None:
        raise SuiteError(f"-p {chosen[0]} names {'recordings' if chosen[0] == 'calibration' else 'anchors'} of one "
                         "data set: give it with --data DIR (a shipped one by name: --data kolakowski2021)")
    if data is not None:
        ds, dataset_name, value, data_roots, identity = _load_data_argument(data)
        # the split and anchor subset every experiment will see (locbook.data.selection.select): a bad value is one
        # line here, before anything runs, and an experiment the selection leaves nothing to run on is left out
        from ..data.selection import select
        ds = select(ds, calibration=overrides.get("calibration", ""), anchors=overrides.get("anchors", ""))
        from ..user_methods import registered_methods
        registered_methods(ds, methods=methods, trackers=trackers)        # a name given twice: one line, here
        for exp in experiments:
            declared = exp.declared_parameters()
            if "data" not in declared:
                takes = [e.id for e in suite.experiments if "data" in e.declared_parameters()]
                raise SuiteError(f"experiment {exp.id!r} takes no data set; with --data run the experiments that do: "
                                 f"{', '.join(takes)} (`locbook run --data DIR` runs them all)")
            as_list = str(declared["data"].annotation).replace(" ", "").startswith("list")
            # override text as `-p` takes it: a str parameter verbatim, a list as a TOML array
            per_experiment[exp.id] = {"data": json.dumps([value]) if as_list else value}
            for name, mine in (("methods", methods), ("trackers", trackers)):
                if mine and name in declared:
                    per_experiment[exp.id][name] = json.dumps([m.option() for m in mine])
        kinds = data_kinds(ds)
        experiments, left_out = select_for_data(experiments, kinds, requested)
        facts = _dataset_facts(ds, identity, suite, kinds)
    # every user path made absolute here, once: the workers and kernels run in other folders (a kernel runs in
    # its notebook's folder), so a relative staging path would point elsewhere there
    root = _absolute(report_root) if report_root else _absolute(suite.default_reports())
    if out_dir is not None:
        report_dir = _absolute(out_dir)
        if not SAFE_NAME.match(report_dir.name):
            raise SuiteError(f"output folder name {report_dir.name!r} must be lower-case letters, digits and "
                             "hyphens ([a-z0-9-])")
    elif overrides:
        report_dir = root / override_folder_name(profile, overrides)
    else:
        report_dir = root / profile
    if dataset_name is not None and out_dir is None:
        report_dir = report_dir / f"data-{dataset_name}"
    if identity is not None:
        _claim_dataset_folder(report_dir, dataset_name, identity, facts)
    experiments, own, _ = split_overrides(experiments, overrides)
    tasks = [Task(exp.id, exp, exp.parameters(profile, {**own[exp.id], **per_experiment.get(exp.id, {})},
                                              data_run=data is not None))
             for exp in experiments]  # validation first
    custom_folder = bool(overrides) or out_dir is not None or dataset_name is not None
    if isinstance(progress, str):
        progress = make_progress(progress)
    for eid, why in left_out.items():
        progress.message(f"{eid}: left out: {why}")
    for flag, name, mine in (("--method", "methods", methods), ("--tracker", "trackers", trackers)):
        takers = [e.id for e in experiments if name in e.declared_parameters()]
        if mine and not takers:
            every = [e.id for e in suite.experiments if name in e.declared_parameters()]
            progress.message(f"{flag} {', '.join(m.name for m in mine)}: no experiment of this run takes it (those "
                             f"that do: {', '.join(every)})")
        elif mine and name == "trackers" and not ds.has_role("track"):
            progress.message(f"--tracker {', '.join(m.name for m in mine)}: the data set has no track recording, so "
                             "no report runs it")
    run = run_tasks(suite, tasks, profile, report_dir, jobs=jobs, force=force, timeout_s=timeout_s,
                    retries=retries, kernel_name=kernel_name, progress=progress, executor=executor,
                    scheduler=scheduler, data_roots=data_roots,
                    write_reports=lambda folder, _outcomes: _write_reports(suite, folder, custom_folder,
                                                                           dataset_name is not None and out_dir is None))
    run.left_out = dict(left_out)
    return run


#: the table a data run's notebook saves when it runs methods of your own (:func:`locbook.scenarios.measured.
#: user_method_rows`): which ran, which failed and why
USER_METHODS_TABLE = "user_methods.csv"


def user_method_failures(run: SuiteRun) -> list[dict]:
    """The methods of your own that failed in the reports of ``run`` (executed or cached: a cached report's failure
    is still the state of that method), read from each report's :data:`USER_METHODS_TABLE`: one dict per method,
    ``{method, kind, function, error, experiments, page}`` (``page``: the first report that shows its traceback)."""
    out: dict[str, dict] = {}
    for o in run.outcomes:
        if o.status not in ("ok", "cached"):
            continue
        folder = run.report_dir / o.id
        table = folder / USER_METHODS_TABLE
        if not table.is_file():
            continue
        try:
            with open(table, newline="", encoding="utf-8") as fh:
                rows = list(csv.DictReader(fh))
        except (OSError, UnicodeDecodeError, csv.Error):
            continue
        for r in rows:
            if r.get("status") != "failed" or not r.get("method"):
                continue
            f = out.setdefault(r["method"], {"method": r["method"], "kind": r.get("kind", ""),
                                             "function": r.get("function", ""), "error": r.get("error", ""),
                                             "experiments": [], "page": str(folder / "report.html")})
            if o.id not in f["experiments"]:
                f["experiments"].append(o.id)
    return list(out.values())


def data_kinds(ds) -> frozenset[str]:
    """The kinds of :data:`locbook.suite.spec.DATA_KINDS` a loaded data set (:class:`locbook.data.dataset.Dataset`)
    holds: each role with a recording, and "scored" when it has a recording the static methods are scored on
    (:func:`locbook.scenarios.measured.scored_recordings`)."""
    from ..data.dataset import ROLES
    from ..scenarios.measured import scored_recordings
    kinds = {role for role in ROLES if ds.has_role(role)}
    if scored_recordings(ds):
        kinds.add("scored")
    return frozenset(kinds)


def select_for_data(experiments: list[Experiment], kinds, requested=None) -> tuple[list[Experiment], dict[str, str]]:
    """The experiments a data set holding ``kinds`` (:func:`data_kinds`) can run: ``(kept, {id: why left out})``,
    by each one's ``[experiment.data_run] needs`` (one without the table runs on every data set). ``requested``:
    the ids asked for by name (default: all of ``experiments``); one of them that the data set cannot run is an
    error (SuiteError, one line), as is a selection of which none can run."""
    requested = {e.id for e in experiments} if requested is None else set(requested)
    kept, left_out = [], {}
    for exp in experiments:
        why = exp.data_run.missing(kinds) if exp.data_run is not None else ""
        if not why:
            kept.append(exp)
        elif exp.id in requested:
            raise SuiteError(f"{exp.id} cannot run on this data set: {why} (`locbook run --data DIR` without ids "
                             "runs every experiment the data set can run)")
        else:
            left_out[exp.id] = why
    if experiments and not kept:
        raise SuiteError("no selected experiment can run on this data set: " + "; ".join(
            f"{eid}: {why}" for eid, why in left_out.items()))
    return kept, left_out


def _write_reports(suite: Suite, folder: Path, custom_folder: bool, nested: bool) -> None:
    write_suite_reports(suite, folder, list_all=not custom_folder)
    parent = folder.parent
    if nested and (parent / "index.html").is_file():     # the profile's index links its data-<name>/ folders
        from filelock import FileLock, Timeout
        lock = FileLock(str(parent / ".lock"))
        try:
            lock.acquire(timeout=0)       # a run writing that folder rebuilds its index itself, link included
        except Timeout:
            return
        try:
            write_suite_reports(suite, parent, list_all=parent.name in PROFILES)
        finally:
            lock.release()


def _load_data_argument(data: str):
    """``(data set, name, parameter value, data roots, identity)`` of a data set given to ``--data``: checked by
    loading it (a malformed one fails here, before anything runs). A shipped data set is passed by name, any other
    by its absolute folder. The roots hold every file its manifest names (a symbolic link's target folder too), so
    that each file a report read joins its cache record; the identity ("shipped:<name>" or the folder) tells two
    data sets of one name apart."""
    from ..data.dataset import datasets_dir, load_dataset
    from ..data.floors import require_one_floor
    ds = load_dataset(data)
    require_one_floor(ds)                 # a building runs floor by floor (floors.floor_runs: the CLI's loop)
    base = ds.manifest_name or ds.name    # one floor of a data set: DIR@F1, its name the manifest's and the floor's
    shipped = ds.root.resolve() == (datasets_dir() / base).resolve()
    roots = sorted({str(ds.root), *(str(Path(f).resolve().parent) for f in ds.files)})
    return (ds, ds.name, (base if shipped else str(ds.root)) + ds.selector, roots,
            (f"shipped:{base}" if shipped else str(ds.root)) + ds.selector)


def _dataset_argument(data: str) -> tuple[str, str, list[str], str]:
    """``(name, parameter value, data roots, identity)`` of :func:`_load_data_argument`."""
    return _load_data_argument(data)[1:]


def _dataset_facts(ds, identity: str, suite: Suite, kinds) -> dict:
    """What a data set's page says of it, read from the loaded data set (its manifest): title, attribution,
    licence, the manifest's path (a shipped one's inside the package, so that committed reports name no machine's
    folder), the geometry sentence, and every experiment of the suite it cannot run, with why."""
    from ..data.dataset import MANIFEST
    manifest = (f"locbook/data/datasets/{ds.name}/{MANIFEST}" if identity.startswith("shipped:")
                else str(Path(ds.root) / MANIFEST))
    left_out = {e.id: e.data_run.missing(kinds) for e in suite.experiments
                if e.data_run is not None and e.data_run.missing(kinds)}
    return {"title": ds.title, "attribution": ds.attribution, "licence": ds.license, "manifest": manifest,
            "geometry": getattr(ds, "geometry_text", ""), "left out": left_out}


def _claim_dataset_folder(report_dir: Path, name: str, identity: str, facts: dict | None = None) -> None:
    """``data-<name>/`` holds one data set's reports: refuse a different data set of the same name (its reports
    would replace the others'), else record which one it holds and what its page says of it (``dataset.json``:
    name, identity, and ``facts``, :func:`_dataset_facts`), rewritten at every run."""
    record = report_dir / "dataset.json"
    held = read_json(record, {}).get("data set")
    if held and held != identity:
        raise SuiteError(f"{report_dir} holds the reports of another data set named {name!r} ({held}); give yours "
                         "another name in its dataset.toml (name = ...), or remove that folder")
    if not held or facts:
        report_dir.mkdir(parents=True, exist_ok=True)
        write_text_atomic(record, json.dumps({"name": name, "data set": identity, **(facts or {})}, indent=1) + "\n")


def _check_options(timeout_s: float, jobs: int, executor: str, scheduler: str | None) -> None:
    if not timeout_s > 0:
        raise SuiteError(f"the timeout must be a positive number of seconds, got {timeout_s}")
    if jobs < 1:
        raise SuiteError(f"jobs must be at least 1, got {jobs}")
    if executor not in ("local", "dask"):
        raise SuiteError(f"executor must be 'local' or 'dask', got {executor!r}")
    if scheduler and executor != "dask":
        raise SuiteError("a scheduler address needs --executor dask")


def run_tasks(suite: Suite, tasks: list[Task], profile: str, report_dir: Path, *, write_reports, jobs: int = 1,
              force: bool = False, timeout_s: float = 1800, retries: int = 1, kernel_name: str = KERNEL_NAME,
              progress="plain", executor: str = "local", scheduler: str | None = None,
              data_roots: list[str] | None = None) -> SuiteRun:
    """Run ``tasks`` (checked parameters; distinct keys) into ``report_dir`` (an absolute path) under its lock,
    with every guarantee of the module docstring, then call ``write_reports(report_dir, outcomes)`` (also after
    an interrupt; one :class:`Outcome` per task) to rebuild the folder's aggregate files. :func:`run_suite` and
    ``locbook study`` (:func:`locbook.suite.study.run_study`) both run here."""
    from filelock import FileLock

    _check_options(timeout_s, jobs, executor, scheduler)
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
    data_roots = [str(_package_dir()), str(suite.root.parent / "shared"), *(data_roots or [])]
    run = SuiteRun([], report_dir)
    with _Stop() as stop:
        lock = FileLock(str(report_dir / ".lock"))
        if not _acquire(lock, report_dir, stop, progress):
            run.interrupted_by = stop.signum
            run.outcomes = [Outcome(t.key, "not run", 0.0) for t in tasks]
            return run
        try:
            _recover(report_dir)
            keys = [t.key for t in tasks]
            progress.begin(keys, expected_seconds(report_dir, keys))
            try:
                with make_executor(executor, jobs, scheduler) as pool:
                    _run_locked(suite, tasks, profile, report_dir, data_roots, force, timeout_s, retries,
                                kernel_name, write_reports, stop, run, progress, pool)
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
                write_reports, stop, run, progress, pool):
    source, versions = _runner_fingerprint(), _dependency_versions()
    rev, dirty = _git_state(suite.repository)
    stamp = locbook_version() + (f" (source {rev}{' + uncommitted changes' if dirty else ''})" if rev else "")
    status_path = report_dir / "status.json"
    status = read_json(status_path, {})
    by_id = {t.key: t for t in tasks}
    keys = {t.key: cache_key(t.experiment, profile, t.parameters, source=source, versions=versions,
                             figures=t.figures) for t in tasks}

    def disk_full(path) -> None:
        """A write failed for lack of space: the run stops (no retry, no new experiment)."""
        if run.disk_full is None:
            run.disk_full = str(path)
            progress.message(f"no space left on device writing {path}; stopping the run")

    def halted() -> bool:
        return stop.signum is not None or run.disk_full is not None or bool(run.executor_error)

    def finish(outcome: Outcome):
        run.outcomes.append(outcome)
        if outcome.status != "not run":
            status[outcome.id] = {"status": outcome.status, "seconds": round(outcome.seconds, 2),
                                  "error": outcome.error}
            try:
                write_text_atomic(status_path, json.dumps(status, indent=1, sort_keys=True))
            except OSError as exc:
                path = disk_full_path(exc, str(status_path))
                if path is None:
                    raise
                disk_full(path)    # the record of this attempt is lost; the reports are not
        progress.finished(outcome)

    queue: deque = deque()
    for t in tasks:
        cached, damaged = (False, "") if force else _cached(report_dir / t.key, t.experiment, keys[t.key], t.figures)
        if cached:
            finish(Outcome(t.key, "cached", 0.0))
        else:
            if damaged:
                progress.message(f"{t.key}: the cached report is damaged ({damaged}); executing it again")
            queue.append((t.key, 1))
    queue = deque(sorted(queue, key=_longest_first(report_dir, profile, [eid for eid, _ in queue])))
    staging_root = report_dir / ".staging" / f"{os.getpid()}-{uuid.uuid4().hex[:8]}"
    running: dict[str, tuple] = {}     # id -> (executor handle, staging, attempt, started or None)
    abandoned: list[tuple] = []        # (handle, staging) of lost tasks asked to stop, which may still be running

    def launch(eid: str, attempt: int):
        staging = staging_root / f"{eid}-{attempt}"
        exp = by_id[eid].experiment
        task = {"id": exp.id, "notebook": str(exp.notebook), "parameters": by_id[eid].parameters,
                "staging": str(staging), "timeout": timeout_s, "kernel": kernel_name,
                "data_roots": data_roots, "runner_pid": os.getpid(), "figures": by_id[eid].figures}
        writing = staging
        try:
            staging.mkdir(parents=True)
            writing = staging / ".task.json"
            writing.write_text(json.dumps(task))
            handle = pool.submit(eid, staging / ".task.json")
        except Exception as exc:   # a full disk, or an executor that lost its cluster: this one has not started
            queue.appendleft((eid, attempt))
            shutil.rmtree(staging, ignore_errors=True)
            path = disk_full_path(exc, str(writing))
            if path is not None:
                disk_full(path)
            elif pool.broken():
                run.executor_error = pool.broken()
            else:
                raise
            return
        running[eid] = (handle, staging, attempt, None)

    def mark_started():
        """An experiment is running once its worker has made its runtime folder (on a cluster, a submitted
        task may wait for a free worker); the elapsed time counts from then."""
        for eid, (handle, staging, attempt, started) in running.items():
            if started is None and (pool.is_local or (staging / ".runtime").exists()):
                running[eid] = (handle, staging, attempt, time.perf_counter())
                progress.started(eid, attempt)

    def complete(eid: str, handle, staging: Path, attempt: int, started: float | None):
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
            abandoned.append((handle, staging))
            if pool.broken():
                run.executor_error = pool.broken()
        if result.get("disk_full"):
            disk_full(result["disk_full"])
        elif (result["error"] and result.get("kernel_failure") and attempt <= retries and not halted()):
            progress.message(f"{eid}: {result['error']}; retrying once")
            queue.appendleft((eid, attempt + 1))
            return
        error = result["error"] or _validate_report(staging, by_id[eid].experiment.id, by_id[eid].figures)
        if not error:
            final = report_dir / eid
            if os.path.lexists(final) and not _is_folder(final):     # no report: the new one takes its place
                kind = "a symbolic link" if final.is_symlink() else "a file"
                progress.message(f"{eid}: {final} was {kind}, not a report folder; replaced by the new report")
            try:
                changed = _promote(by_id[eid].experiment, profile, by_id[eid].parameters, staging, report_dir / eid,
                                   stamp, keys[eid], result)
                if changed:
                    more = f" (and {len(changed) - 1} more)" if len(changed) > 1 else ""
                    progress.message(f"{eid}: {changed[0]}{more} changed while it ran, after its kernel read it; the "
                                     "report is kept, and the next run executes it again")
            except OSError as exc:
                path = disk_full_path(exc, str(staging))
                if path is not None:
                    disk_full(path)
                    error = f"no space left on device writing {path}"
                else:
                    error = f"could not write the report: {exc.strerror or exc}"
        if error:
            if not (result.get("lost") or run.disk_full):   # nothing to inspect in an attempt the disk cut short
                try:
                    _keep_failed(staging, report_dir / ".failed" / eid)
                except OSError:
                    pass
            finish(Outcome(eid, "failed", result["seconds"], error, attempt))
        else:
            finish(Outcome(eid, "ok", result["seconds"], "", attempt))

    try:
        while queue or running:
            if halted():
                break
            while queue and len(running) < pool.capacity and not halted():
                launch(*queue.popleft())
            mark_started()
            time.sleep(0.1)
            for eid in [e for e, (h, *_rest) in running.items() if pool.done(h)]:
                handle, staging, attempt, started = running.pop(eid)
                if started is None:
                    progress.started(eid, attempt)
                complete(eid, handle, staging, attempt, started)
            if not run.executor_error and pool.broken():
                run.executor_error = pool.broken()
    finally:
        # an interrupt, a full disk, a lost cluster (or an unexpected error here): stop the workers, keep
        # everything finished. Each step runs whatever the one before it met (an executor's error is held until the
        # end), so every experiment gets its outcome, the staging is always removed and the suite files rebuilt.
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
            finish(Outcome(eid, "interrupted", time.perf_counter() - started if started is not None else 0.0,
                           why, attempt))
        for handle, staging in abandoned:     # their staging goes only once they have ended (or their time is up)
            guarded(pool.wait_or_kill, handle, staging, max(0.0, deadline - time.perf_counter()))
        for eid, _attempt in queue:
            finish(Outcome(eid, "not run", 0.0))
        _remove_staging(staging_root)
        try:
            write_reports(report_dir, run.outcomes)
        except OSError as exc:
            path = disk_full_path(exc, str(report_dir))
            if path is None:
                raise
            disk_full(path)        # the previous index and numbers.csv stay as they were
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
    from .notebook_html import export_html
    page = staging / f"{exp_id}.html"
    try:
        body = export_html(notebook)      # self-contained: the math drawn to SVG, no script from a CDN
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


def _promote(exp, profile, params, staging: Path, folder: Path, stamp: str, key: str, result: dict) -> list[str]:
    """Write the summary and the records into the validated staging folder, then swap it into place. The cache
    record (run.json) is written before the swap, inside the new folder, so it only ever describes a
    complete report. Returns the files (and links) read that changed while the experiment ran: the record holds
    what the kernel read, so the next run executes this report again."""
    data, links, changed = _data_hashes(staging)
    modules, _module_links, changed_modules = _data_hashes(staging, ".modules-read.log")
    _strip_worker_files(staging)
    numbers = read_csv(staging / "numbers.csv")
    # the pages show each row's reading bracket when the experiment was bracketed (<reports>/brackets/<id>/)
    from .bracket import bracket_of_rows, brackets_root, load_bracket
    bracket = load_bracket(brackets_root(folder.parent) / exp.id) if folder.parent.name in PROFILES else []
    if bracket:
        numbers = bracket_of_rows(numbers, bracket, profile)
    dataset = site.dataset_record(folder.parent)       # a data run's pages name the data set, not the document
    (staging / "summary.md").write_text(site.summary_markdown(exp, profile, numbers, stamp, dataset),
                                        encoding="utf-8")
    (staging / "report.md").write_text(site.page_markdown(exp, profile, params, staging, numbers, stamp, dataset),
                                       encoding="utf-8")
    (staging / "report.html").write_text(site.page_html(exp, profile, params, staging, numbers, stamp, dataset),
                                         encoding="utf-8")
    (staging / "report.json").write_text(json.dumps(
        {"experiment": exp.id, "profile": profile, "parameters": params, "locbook": stamp,
         "seconds": round(result["seconds"], 1), "machine": result.get("machine") or machine_label()}, indent=1,
        sort_keys=True) + "\n")
    (staging / "run.json").write_text(json.dumps({
        "cache_key": key, "status": "ok", "seconds": round(result["seconds"], 2), "data": data, "links": links,
        "modules": modules}, indent=1))
    _replace_dir(staging, folder)
    return changed + changed_modules
