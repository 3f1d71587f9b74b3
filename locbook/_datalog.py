"""Which data files an experiment reads, so that editing one re-runs exactly the experiments that read it.

Under ``locbook run`` the worker sets ``LOCBOOK_DATA_LOG`` (a file) and ``LOCBOOK_DATA_ROOTS`` (folders,
``os.pathsep``-separated: the runner's package and ``../shared``). Importing locbook then installs an audit hook
(PEP 578) that appends the path of every file opened for reading under those roots and under the folder of the
locbook being imported, except Python sources, to the log. The kernel's locbook need not be the runner's (a
kernel started in the notebook's folder imports the installed package while the runner may run from a source
tree), and its own data files are what the notebook reads. The runner stores each logged file's SHA-256 with the report; a cached report is reused only
while every file it read is unchanged. The hook sees every read (``open``, numpy, pandas, csv alike), so no
data access has to remember to register itself. Files under ``__pycache__`` (byte code, numba's caches) are build
artefacts, not data. Outside ``locbook run`` nothing is installed.

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
    from importlib.util import source_from_cache     # imported here: the hook must not import

    package = os.path.realpath(os.path.dirname(os.path.abspath(__file__)))
    roots.append(package)                                                          # this locbook's own data
    _installed = True
    log = open(log_path, "a", encoding="utf-8")   # opened once: the hook itself never opens a file
    module_log = open(module_log_path, "a", encoding="utf-8") if module_log_path else None
    seen: set[str] = set()
    prefixes = tuple(r.rstrip(os.sep) + os.sep for r in roots)
    in_package = package + os.sep
    cache_dir = os.sep + "__pycache__" + os.sep

    def append(to, path: str) -> None:
        if path not in seen:
            seen.add(path)
            to.write(path + "\n")
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
        mode = args[1] if len(args) > 1 and isinstance(args[1], str) else "r"
        if any(c in mode for c in "wax+"):
            return
        try:
            path = os.path.realpath(os.fsdecode(args[0]))
        except (TypeError, ValueError):
            return
        if path in seen or not path.startswith(prefixes):
            return
        if path.endswith((".py", ".pyc")):
            if module_log is not None and path.startswith(in_package):
                log_module(path)
            return
        if cache_dir not in path:
            append(log, path)

    sys.addaudithook(hook)
