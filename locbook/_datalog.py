"""Which data files an experiment reads, so that editing one re-runs exactly the experiments that read it.

Under ``locbook run`` the worker sets ``LOCBOOK_DATA_LOG`` (a file) and ``LOCBOOK_DATA_ROOTS`` (folders,
``os.pathsep``-separated: the runner's package and ``../shared``). Importing locbook then installs an audit hook
(PEP 578) that appends the path of every file opened for reading under those roots and under the folder of the
locbook being imported, except Python sources, to the log. The kernel's locbook need not be the runner's (a
kernel started in the notebook's folder imports the installed package while the runner may run from a source
tree), and its own data files are what the notebook reads.

Each file is hashed (SHA-256) when it is opened, not when the report is promoted: a file edited while the experiment
runs is recorded with the content the kernel read, so the runner sees that it changed since (its report is then
not cacheable, and the next run executes it again). A file opened through a symbolic link (the file itself or a
folder on its path) is logged with the path as opened and its target, so re-pointing the link invalidates the report
too. One JSON object a line: ``{"path": target, "sha256": hex, "link": path as opened}`` (``link`` only when it
differs); the runner also reads the plain path lines of an older locbook. The hash is taken just before the kernel's
own open (the audit event precedes it), through an ``open`` the hook ignores (its thread is marked busy), so an edit
after it is seen as a change. A cached report is reused only while every file it read is unchanged.

The hook sees every read (``open``, numpy, pandas, csv alike), so no data access has to remember to register itself;
the one exception is a method of your own (:mod:`locbook.user_methods`): its Python source is code the hook skips and
may lie under no data root, so its loader logs the file with the hash of the bytes it ran (:func:`record_read`).
Files under ``__pycache__`` (byte code, numba's caches) are build artefacts, not data. Outside ``locbook run``
nothing is installed.

With ``LOCBOOK_MODULE_LOG`` (a file) the hook also logs the source of every locbook module the kernel imports (the
import opens its ``.py`` or cached ``.pyc``; the modules imported before the hook, ``locbook/__init__.py`` and its
helpers, are logged at installation), so a report depends on the library code its notebook ran, not on every
module of the package: editing the particle filter does not re-run an experiment that never imported it.
"""
from __future__ import annotations

import os
import sys

_installed = False


def install_from_environment() -> None:
    global _installed
    log_path = os.environ.get("LOCBOOK_DATA_LOG")
    module_log_path = os.environ.get("LOCBOOK_MODULE_LOG")
    roots = [os.path.realpath(r) for r in os.environ.get("LOCBOOK_DATA_ROOTS", "").split(os.pathsep) if r]
    if _installed or not log_path or not roots:
        return
    # imported here, once: the hook itself must not import (an import opens files, which calls the hook)
    import hashlib
    import json
    import stat
    import threading
    from importlib.util import source_from_cache

    package = os.path.realpath(os.path.dirname(os.path.abspath(__file__)))
    roots.append(package)                                                          # this locbook's own data
    _installed = True
    log = open(log_path, "a", encoding="utf-8")   # opened once: the hook writes through these, never opens a log
    module_log = open(module_log_path, "a", encoding="utf-8") if module_log_path else None
    seen: set = set()
    busy: set[int] = set()          # threads hashing a file now: the hash's own open is not a read of the notebook's
    prefixes = tuple(r.rstrip(os.sep) + os.sep for r in roots)
    in_package = package + os.sep
    cache_dir = os.sep + "__pycache__" + os.sep

    def sha256(path: str) -> str | None:
        """The content's hash now (just before the kernel's open), or None for no regular file (a folder, a FIFO
        that hashing would block on, a file that does not exist: the kernel's own open then fails)."""
        me = threading.get_ident()
        busy.add(me)
        try:
            if not stat.S_ISREG(os.stat(path).st_mode):
                return None
            h = hashlib.sha256()
            with open(path, "rb") as fh:
                for block in iter(lambda: fh.read(1 << 20), b""):
                    h.update(block)
            return h.hexdigest()
        except OSError:
            return None
        finally:
            busy.discard(me)

    def append(to, path: str, link: str | None = None) -> None:
        if (path, link) in seen:
            return
        digest = sha256(path)
        if digest is None:        # not there (yet): a later open that finds it is logged then
            return
        seen.add((path, link))
        to.write(json.dumps({"path": path, "sha256": digest, **({"link": link} if link else {})}) + "\n")
        to.flush()

    def log_module(path: str) -> None:
        if path.endswith(".pyc"):
            try:
                path = source_from_cache(path)
            except ValueError:                    # not a PEP 3147 cache name: no source to key on
                return
        append(module_log, path)

    if module_log is not None:
        for name, module in list(sys.modules.items()):
            file = getattr(module, "__file__", None)
            if (name == "locbook" or name.startswith("locbook.")) and file:
                log_module(os.path.realpath(file))

    def hook(event, args):
        if event != "open" or not args or not isinstance(args[0], (str, bytes, os.PathLike)):
            return
        if busy and threading.get_ident() in busy:
            return
        mode = args[1] if len(args) > 1 and isinstance(args[1], str) else "r"
        if any(c in mode for c in "wax+"):
            return
        try:
            given = os.fsdecode(args[0])
            opened = given if os.path.isabs(given) else os.path.join(os.getcwd(), given)
            path = os.path.realpath(opened)
        except (TypeError, ValueError, OSError):
            return
        if path.endswith((".py", ".pyc")):
            if module_log is not None and path.startswith(in_package):
                log_module(path)
            return
        if cache_dir in path:
            return
        plain = os.path.normpath(opened)
        if not (path.startswith(prefixes) or plain.startswith(prefixes)):   # a link under a root is its data too
            return
        # a symbolic link on the way: its path is part of the record (normalised, unless ".." after a link makes
        # the normalised path name another file)
        link = None if plain == path else (plain if os.path.realpath(plain) == path else opened)
        append(log, path, link)

    sys.addaudithook(hook)


def record_read(path: str, sha256: str) -> None:
    """Log a file the kernel ran or read that the audit hook does not log (a user method's Python source: the hook
    skips ``.py`` files, and a command line's file lies under no data root) with the hash of the content used, so
    that it joins the report's cache record (``run.json`` "data"): editing it reruns the report. A no-op outside
    ``locbook run`` (no ``LOCBOOK_DATA_LOG``)."""
    log_path = os.environ.get("LOCBOOK_DATA_LOG")
    if not log_path:
        return
    import json
    with open(log_path, "a", encoding="utf-8") as fh:       # an append: the hook ignores it
        fh.write(json.dumps({"path": os.path.realpath(path), "sha256": sha256}) + "\n")
