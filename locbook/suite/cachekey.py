"""What decides whether a report is up to date: the cache key of an experiment run (its notebook, parameters,
profile, the runner's locbook source and the dependency versions) and the hashes of the data files and library
modules a kernel read (recorded in ``run.json``, checked again before a report is served from the cache).

Below the runner (:mod:`locbook.suite.runner`) and the sweeps (:mod:`locbook.suite.study`), which key their points
with it.
"""
from __future__ import annotations

import hashlib
import json
import os
import sys
from importlib import metadata
from pathlib import Path

from .. import __version__
from .params import read_notebook
from .spec import Experiment

__all__ = ["locbook_version", "package_dir", "runner_fingerprint", "dependency_versions", "notebook_fingerprint",
           "cache_key", "sha256_file", "data_hashes", "data_unchanged", "links_unchanged"]


_DEPENDENCIES = ("numpy", "scipy", "cvxpy", "clarabel", "osqp", "scs", "matplotlib", "papermill",
                 "nbclient", "nbconvert", "nbformat", "ipykernel", "numba")


def locbook_version() -> str:
    return __version__


def package_dir() -> Path:
    return Path(__file__).resolve().parents[1]


#: the runner process's locbook code (package-relative patterns): the suite, the reproduction layer it imports, the
#: package's own start-up modules and errors, and the templates of the report pages
_RUNNER_SOURCES = ("suite/*.py", "suite/templates/**/*", "reproduce/*.py", "__init__.py", "_lazy.py", "_datalog.py",
                   "errors.py")


def runner_fingerprint() -> str:
    """The runner's side of a report: the sources of the suite (which writes the pages) and of what it imports from
    locbook (:data:`_RUNNER_SOURCES`), and the report site's templates. A fixed set, so a run from the command line
    and one from Python share their cache. The kernel's side, the library code the notebook ran, is recorded per
    experiment (``run.json`` "modules", like its data files)."""
    package = package_dir()
    files = {path for pattern in _RUNNER_SOURCES for path in package.glob(pattern) if path.is_file()}
    h = hashlib.sha256()
    for path in sorted(files):
        h.update(str(path.relative_to(package)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def dependency_versions() -> dict[str, str]:
    versions = {"python": sys.version.split()[0]}
    for name in _DEPENDENCIES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "absent"
    return versions


def notebook_fingerprint(path: Path) -> str:
    nb = read_notebook(path)
    h = hashlib.sha256()
    for cell in nb.cells:  # sources and tags only: outputs and execution counts do not matter
        h.update(cell.cell_type.encode())
        h.update(cell.source.encode())
        h.update(json.dumps(cell.get("metadata", {}).get("tags", [])).encode())
    return h.hexdigest()


def cache_key(exp: Experiment, profile: str, params: dict, *, source: str | None = None,
              versions: dict | None = None, figures: bool = True) -> str:
    """Hash of notebook, parameters, profile, the runner's locbook source (:func:`runner_fingerprint`) and
    dependency versions. The data files an experiment reads and the library modules its kernel imports are checked
    separately, by their hashes recorded in ``run.json``."""
    payload = {
        "experiment": exp.id, "profile": profile, "parameters": params,
        "notebook": notebook_fingerprint(exp.notebook),
        "locbook": source or runner_fingerprint(),
        "versions": versions or dependency_versions(),
        **({} if figures else {"figures": False}),      # the keys of runs with figures are unchanged
    }
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


def sha256_file(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def data_hashes(staging: Path, log: str = ".data-read.log") -> tuple[dict[str, str], dict[str, str], list[str]]:
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
            now = sha256_file(Path(path)) if Path(path).is_file() else None
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


def data_unchanged(recorded: dict[str, str]) -> bool:
    for path, digest in recorded.items():
        try:
            if sha256_file(Path(path)) != digest:
                return False
        except (OSError, TypeError, ValueError):     # gone, unreadable, or a damaged record
            return False
    return True


def links_unchanged(recorded: dict[str, str]) -> bool:
    """Every symbolic link a report read through still points where it did (re-pointed: another file was read)."""
    try:
        return all(os.path.realpath(link) == target for link, target in recorded.items())
    except (OSError, TypeError, ValueError):         # a damaged record
        return False
