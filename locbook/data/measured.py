"""Measured RSSI data: one documented long format, its validation, and the adapters that read public data sets.

Bringing a new data set into locbook is a file conversion, not code. Three files describe it:

**Readings** (CSV, one row per received packet or per averaged epoch; the *long format*)

============== ======== ========================================================================================
column         required meaning
============== ======== ========================================================================================
``time_s``     yes      time of the reading in seconds (any origin); non-decreasing within a transmitter
``transmitter``yes      id of the moving tag, any text (see "Link direction" below)
``receiver``   yes      id of the fixed device of the link: an ``id`` of the anchors file
``rssi_dbm``   yes      received power in dBm; empty or ``NaN`` = the receiver heard no packet (not heard)
``x_m``        no       true position of the transmitter (m), where known; empty = unknown
``y_m``        no       (``x_m`` and ``y_m`` are given together or not at all, row by row)
``z_m``        no       true height of the transmitter (m), where known
``heading_rad``no       true heading of the transmitter (rad), where known
``device``     no       the hardware that measured the tag's side of the link (a phone model, a tag type), text;
                        default: the transmitter id. Devices differ by a receiver offset (dB); see
                        :func:`locbook.static.calibration.calibrate_path_loss_devices`
============== ======== ========================================================================================

**Link direction.** The anchor, the fixed device, always goes in ``receiver`` and the moving tag in
``transmitter``, whichever end physically transmits: a phone scanning fixed beacons writes the beacon's id in
``receiver`` and the phone's in ``transmitter``. The channel is the same either way (the path loss is
reciprocal), and the estimators only need to know which end is fixed. A readings file whose ``receiver`` ids are not
anchors while its ``transmitter`` ids are is refused with this rule in the message.

Other columns are kept (an epoch keeps those with one value within it, e.g. a point id). Every row has exactly the
header's number of fields: an empty value is an empty field (``0.5,tag,A,`` = not heard), while a row with a field
missing (``0.5,tag,A``) or one too many is refused. In the number columns an empty field, ``NaN``, ``NA`` or
``N/A`` is missing; ids are text, so ``NA`` is an id and only an empty field is no id. ``time_s`` is in seconds: a
magnitude of :data:`MAX_TIME_S` (1e11 s) or more is milli-, micro- or nanoseconds since 1970 and is refused (as
64-bit floats such values also lose the differences between readings). A reading must lie in ``valid_range_dbm``
(default :data:`RSSI_RANGE_DBM`, ``[-150, 20]`` dBm: outside it is a unit or sign error, never a reading); infinite
values are errors anywhere. Values a data set writes for "invalid reading" (e.g. 0, 2, 4 dBm) are declared with
``invalid_values_dbm`` and become NaN (not heard); readings at or above 0 dBm with no sentinel declared and the
default range load with one :class:`MeasuredDataWarning` (implausible beyond a few centimetres from an antenna).
The sentinels are numbers (text such as ``"0"`` and bools are refused) and the range two finite numbers within
:data:`RSSI_LIMITS_DBM`. The same (time, transmitter, receiver) may appear once only; ``sort=True`` reorders a file
by time (stably) before the checks. Files are UTF-8 (a byte-order mark is allowed). True positions, like every
coordinate, are less than :data:`MAX_COORDINATE_M` (1e7 m) in magnitude.

Sizes are checked before a file is read, each limit a module constant: a line of at most :data:`MAX_LINE_BYTES`
(128 KiB); a readings file of at most :data:`MAX_READINGS_FILE_BYTES` (1 GiB, about 3 x 10^7 readings); files of
one record per line (LF or CRLF line ends, no blank line, no quoted line break; quoted fields are fine) go through
pandas' C reader at about 7 bytes of memory per byte of file, any other file through the exact reader, at about
24 bytes per byte, which takes files of at most :data:`MAX_EXACT_READ_BYTES` (64 MiB) and refuses a larger one
naming the line that needs it. Messages quote at most :data:`MAX_QUOTED_CHARS` characters of a file.

**Anchors** (CSV): ``id, x, y, z`` in metres (``z`` is the anchor height: ranges are three-dimensional, the tag at
its known height), or ``id, x, y`` with no ``z`` column for a 2-D problem (anchors and tag in one plane, ranges in
the plane). A ``z`` column gives every anchor's height: one left empty is refused naming its line. Ids are unique;
coordinates finite and less than :data:`MAX_COORDINATE_M` in magnitude; no two anchors within
:data:`ANCHOR_MIN_SEPARATION_M` (1 mm) of each other. Optional columns ``floor`` (each anchor's floor) and ``used``
(false: a placeholder, which may share a point; the separation rule holds among used anchors of one floor):
:mod:`locbook.data.floors`.

**Floor outline** (CSV, optional): ``x, y`` vertices of a closed polygon in metres (at least 3 vertices, the
closing vertex may repeat the first).

Every rule failure raises :class:`DataFormatError` naming the file, the line (as a text editor counts it, the
header being line 1, blank lines included) and the column (or the byte, for a file that is not UTF-8).
:func:`epochs` turns a validated recording into the arrays the estimators take: one row per epoch (a distinct
(time, transmitter), or a window of raw packets), one column per anchor, NaN where the anchor heard nothing (the
library's one rule for missing readings, docs/filters.md). :func:`regular_epochs` puts one transmitter on a fixed clock,
refusing a clock jump that would need more than ``max_epochs`` ticks.

A data set (:mod:`locbook.data.dataset`) is a folder of such files with a manifest (``dataset.toml``) that says
their units, sentinels, epoch rule, tag height, outline and roles; :func:`locbook.data.dataset.load_dataset` reads
one, and the data sets shipped with locbook (``locbook/data/datasets/``) are read the same way.

The code lives along the format's seams, and every name above is importable from here: :mod:`locbook.data.csvfile`
(CSV text, size limits, :class:`DataFormatError`), :mod:`locbook.data.long_format` (the columns and
:func:`validate_readings`), :mod:`locbook.data.readings_file` (:func:`read_readings`), :mod:`locbook.data.epoching`
(:class:`Epochs`, :func:`epochs`); the anchors, outline and path files are read here.
"""
from __future__ import annotations

import math

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from ..errors import ParameterError
from .csvfile import (
    EXACT_READER_BYTES_PER_BYTE,
    MAX_COORDINATE_M,
    MAX_EXACT_READ_BYTES,
    MAX_LINE_BYTES,
    MAX_QUOTED_CHARS,
    DataFormatError,
    numeric_column,
    read_text_table,
    shown,
)
from .epoching import (
    AGGREGATES,
    MAX_MIN_READINGS,
    MAX_REGULAR_EPOCHS,
    MIN_WINDOW_S,
    Epochs,
    epochs,
    regular_epochs,
    scan_interval_s,
)
from .long_format import (
    DEVICE_COLUMN,
    LINK_DIRECTION_RULE,
    MAX_TIME_S,
    OPTIONAL_READING_COLUMNS,
    READING_COLUMNS,
    RSSI_LIMITS_DBM,
    RSSI_RANGE_DBM,
    MeasuredDataWarning,
    file_time_origin,
    shifted_seconds,
    validate_readings,
)
from .readings_file import (
    FAST_READER_BYTES_PER_BYTE,
    MAX_READINGS_FILE_BYTES,
    read_readings,
    read_readings_table,
    validate_readings_file,
)

__all__ = [
    "DataFormatError", "MeasuredDataWarning", "READING_COLUMNS", "OPTIONAL_READING_COLUMNS", "RSSI_RANGE_DBM",
    "MAX_TIME_S", "ANCHOR_MIN_SEPARATION_M", "MAX_REGULAR_EPOCHS", "AGGREGATES", "Epochs", "RSSI_LIMITS_DBM",
    "MAX_COORDINATE_M", "MAX_LINE_BYTES", "MAX_EXACT_READ_BYTES", "MAX_READINGS_FILE_BYTES", "MAX_MIN_READINGS",
    "MIN_WINDOW_S", "DEVICE_COLUMN", "LINK_DIRECTION_RULE",
    "read_readings", "read_anchors", "read_outline", "read_path_segments", "validate_readings", "epochs",
    "regular_epochs", "scan_interval_s",
]

__all__ += ["EXACT_READER_BYTES_PER_BYTE", "MAX_QUOTED_CHARS", "FAST_READER_BYTES_PER_BYTE", "file_time_origin",
            "shifted_seconds", "read_readings_table", "validate_readings_file"]     # importable here as before

#: two anchors closer than this (m) are the same point: refused (the geometry would be degenerate)
ANCHOR_MIN_SEPARATION_M = 1e-3


def read_anchors(path, *, min_separation_m: float = ANCHOR_MIN_SEPARATION_M) -> pd.DataFrame:
    """Read and check an anchors CSV: ``id, x, y, z`` (metres) for a 3-D data set, ``id, x, y`` (no ``z`` column)
    for a 2-D one (anchors and tag in one plane). Ids are unique (text: ``NA`` is an id), coordinates finite, no
    two anchors closer than ``min_separation_m`` (default 1 mm: two ids at one point are a copy-paste error, and
    would make the geometry degenerate). A ``z`` column holds a height on every line: one left empty while others
    are given is refused naming its line (a 2-D file has no ``z`` column at all). Optional columns
    (:mod:`locbook.data.floors`): ``floor`` (every anchor's floor) and ``used`` (false: a placeholder, which may share
    a point; the separation rule applies to used anchors of one floor). Returns columns ``id, x, y`` and, for 3-D,
    ``z``, then ``floor`` and ``used`` where the file has them."""
    if not (isinstance(min_separation_m, (int, float)) and math.isfinite(min_separation_m) and min_separation_m >= 0):
        raise ParameterError(f"min_separation_m must be a finite number of metres >= 0, got {min_separation_m!r}")
    table, lines = read_text_table(path, ("id", "x", "y"), "anchors")
    source = f"anchors file {path}"
    if len(table) == 0:
        raise DataFormatError(f"{source}: no anchors")
    ids = table["id"].astype(str).str.strip()
    for i in np.flatnonzero((ids == "").to_numpy())[:1]:
        raise DataFormatError(f"{source}, line {lines[i]}, column 'id': the id is empty")
    dup = ids.duplicated().to_numpy()
    if dup.any():
        i = int(np.flatnonzero(dup)[0])
        raise DataFormatError(f"{source}, line {lines[i]}, column 'id': anchor id {shown(ids.iloc[i])} appears twice")
    axes = ("x", "y", "z") if "z" in table.columns else ("x", "y")
    out = pd.DataFrame({"id": ids.to_numpy()})
    for col in ("x", "y"):
        out[col] = numeric_column(table, col, source, lines, missing_ok=False, coordinate=True)
    if "z" in axes:
        z = numeric_column(table, "z", source, lines, missing_ok=True, coordinate=True)
        empty = np.isnan(z)
        if empty.any():
            i = int(np.flatnonzero(empty)[0])
            raise DataFormatError(
                f"{source}, line {lines[i]}, column 'z': the height is empty ({int(empty.sum())} of the {len(z)} "
                f"anchors have none): a 3-D data set gives every anchor's z; a 2-D one (anchors and tag in one "
                "plane) has no z column at all")
        out["z"] = z
    from .floors import FLOOR_COLUMN, USED_COLUMN, anchor_columns, check_floor_labels
    floors, used = anchor_columns(table, lines, source)       # optional floor and used (placeholder) columns
    if floors is not None:
        out[FLOOR_COLUMN] = floors
        check_floor_labels(floors[used], source)
    if USED_COLUMN in table.columns:
        out[USED_COLUMN] = used
    pos = out[list(axes)].to_numpy(float)
    # the separation rule among used anchors of one floor: placeholders may share a point, floors a plan position
    group = np.where(used, 0 if floors is None else pd.factorize(floors)[0], -1)
    pairs = np.zeros((0, 2), dtype=int)
    for g in np.unique(group[group >= 0]):
        members = np.flatnonzero(group == g)
        if len(members) > 1:
            found = cKDTree(pos[members]).query_pairs(min_separation_m, output_type="ndarray")
            pairs = np.concatenate([pairs, members[found].reshape(-1, 2)])
    if len(pairs):
        pairs = np.sort(pairs, axis=1)
        i, j = (int(v) for v in pairs[np.lexsort((pairs[:, 0], pairs[:, 1]))[0]])   # the first in file order
        raise DataFormatError(
            f"{source}, lines {lines[i]} and {lines[j]}, columns {','.join(repr(a) for a in axes)}: anchors "
            f"{shown(ids.iloc[i])} and "
            f"{shown(ids.iloc[j])} are at the same position ({', '.join(f'{v:g}' for v in pos[i])}) m (within "
            f"{min_separation_m:g} m; {len(pairs)} such pair(s)); two receivers at one point are a copy error or one "
            "device: fix the coordinates or keep one id")
    return out


def read_outline(path) -> np.ndarray:
    """Read and check a floor outline CSV (``x, y`` vertices of a closed polygon, metres) -> ``(V, 2)``,
    without a repeated closing vertex."""
    table, lines = read_text_table(path, ("x", "y"), "outline")
    source = f"outline file {path}"
    xy = np.column_stack([numeric_column(table, c, source, lines, missing_ok=False, coordinate=True)
                          for c in ("x", "y")])
    if len(xy) > 1 and np.array_equal(xy[0], xy[-1]):
        xy = xy[:-1]
    if len(xy) < 3:
        raise DataFormatError(f"{source}: an outline needs at least 3 distinct vertices, got {len(xy)}")
    twice = (xy[:, 0] * np.roll(xy[:, 1], -1) - np.roll(xy[:, 0], -1) * xy[:, 1]).sum()
    if abs(twice) < 1e-12:
        raise DataFormatError(f"{source}: the outline encloses no area (its vertices are collinear)")
    return xy


def read_path_segments(path) -> np.ndarray:
    """Read a reference path: ``x0, y0, x1, y1`` per straight segment (metres) -> ``(S, 2, 2)``."""
    table, lines = read_text_table(path, ("x0", "y0", "x1", "y1"), "path")
    source = f"path file {path}"
    cols = [numeric_column(table, c, source, lines, missing_ok=False, coordinate=True)
            for c in ("x0", "y0", "x1", "y1")]
    if len(table) == 0:
        raise DataFormatError(f"{source}: no segments")
    return np.stack(cols, axis=-1).reshape(-1, 2, 2)

