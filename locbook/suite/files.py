"""The suite's file helpers: reading the CSV and JSON files locbook writes, the one atomic write, a point's key text
and the machine label.

The leaf of :mod:`locbook.suite`: it imports no other suite module, so every layer above (runner, sweeps, site,
CLI) can use it. A damaged file reads as an absent one (the runner's validation says what is wrong with it); every
suite-level file is written to a temporary name, then renamed, so a reader never sees half a file.
"""
from __future__ import annotations

import csv
import functools
import hashlib
import json
import os
from collections.abc import Callable
from pathlib import Path

__all__ = ["read_json", "read_csv", "atomic_write", "write_text_atomic", "point_text", "point_key", "value_text",
           "machine_label"]


def read_json(path: Path, default):
    """The JSON in ``path``, or ``default`` when the file is missing, unreadable, not UTF-8, not JSON, or (for a
    dict or list ``default``) JSON of another type: a damaged file reads as an absent one, never as a crash."""
    try:
        value = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):      # UnicodeDecodeError is a ValueError
        return default
    if isinstance(default, (dict, list)) and not isinstance(value, type(default)):
        return default
    return value


def read_csv(path: Path) -> list[dict]:
    """Rows of a CSV file written by locbook (UTF-8); ``[]`` when it is missing or damaged (not UTF-8, NUL
    bytes): the runner's validation says what is wrong with it, the pages show what can be read."""
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            return list(csv.DictReader(fh))
    except (OSError, ValueError, csv.Error):
        return []


def atomic_write(path: Path, write: Callable[[Path], object], tmp: Path | None = None) -> None:
    """``write(tmp)`` then rename ``tmp`` to ``path`` (``tmp``: default ``.<name>.<pid>.tmp`` beside it). On any
    exception (a full disk, an interrupt) the temporary file is removed and ``path`` keeps what it held."""
    if tmp is None:
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_text_atomic(path: Path, text: str, tmp: Path | None = None) -> None:
    """:func:`atomic_write` of ``text`` as UTF-8."""
    atomic_write(path, lambda t: t.write_text(text, encoding="utf-8"), tmp)


def point_text(values: dict) -> str:
    """The checked values of a point as one text (what makes two points the same point; hashed into its key)."""
    return json.dumps(values, sort_keys=True)


def point_key(experiment_id: str, values: dict, digits: int = 64, taken: dict[str, str] | None = None) -> str:
    """The report folder of a sweep point: the experiment id and the first ``digits`` hex digits of the SHA-256 of
    :func:`point_text`, or all 64 when that shorter key is already ``taken`` (key -> point text) by other values.
    A study keys by all 64 (a 40-bit prefix made points collide from about 10^6 points on); a bracket, a few dozen
    points, by 10 (as committed in points.csv)."""
    text = point_text(values)
    digest = hashlib.sha256(text.encode()).hexdigest()
    key = f"{experiment_id}-{digest[:digits]}"
    return key if (taken or {}).get(key, text) == text else f"{experiment_id}-{digest}"


def value_text(value) -> str:
    """A parameter value as a person reads it in a point's name: ``'zigzag'``, ``true``, ``1.5``, ``[0.1, 0.2]``."""
    if isinstance(value, str):
        return f"'{value}'"
    if isinstance(value, bool):
        return str(value).lower()
    return repr(value)


@functools.lru_cache(maxsize=1)
def machine_label() -> str:
    """The machine a run time was measured on, as ``locbook list`` shows it: the CPU model and the logical CPUs
    (``AMD EPYC 9B14, 2 CPUs``); no host name."""
    import platform
    cpu = platform.processor() or platform.machine() or "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8", errors="replace").splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count() or '?'} CPUs"
