"""Which data files an experiment reads, so that editing one re-runs exactly the experiments that read it.

Under ``locbook run`` the worker sets ``LOCBOOK_DATA_LOG`` (a file) and ``LOCBOOK_DATA_ROOTS`` (folders,
``os.pathsep``-separated: the runner's package and ``../shared``). Importing locbook then installs an audit hook
(PEP 578) that appends the path of every file opened for reading under those roots and under the folder of the
locbook being imported, except Python sources, to the log. The kernel's locbook need not be the runner's (a
kernel started in the notebook's folder imports the installed package while the runner may run from a source
tree), and its own data files are what the notebook reads. The runner stores each logged file's SHA-256 with the report; a cached report is reused only
while every file it read is unchanged. The hook sees every read (``open``, numpy, pandas, csv alike), so no
data access has to remember to register itself. Outside ``locbook run`` nothing is installed.
"""
from __future__ import annotations

import os
import sys

_installed = False


def install_from_environment() -> None:
    global _installed
    log_path = os.environ.get("LOCBOOK_DATA_LOG")
    roots = [os.path.realpath(r) for r in os.environ.get("LOCBOOK_DATA_ROOTS", "").split(os.pathsep) if r]
    if _installed or not log_path or not roots:
        return
    roots.append(os.path.realpath(os.path.dirname(os.path.abspath(__file__))))   # this locbook's own data
    _installed = True
    log = open(log_path, "a", encoding="utf-8")   # opened once: the hook itself never opens a file
    seen: set[str] = set()
    prefixes = tuple(r.rstrip(os.sep) + os.sep for r in roots)

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
        if path in seen or not path.startswith(prefixes) or path.endswith((".py", ".pyc")):
            return
        seen.add(path)
        log.write(path + "\n")
        log.flush()

    sys.addaudithook(hook)
