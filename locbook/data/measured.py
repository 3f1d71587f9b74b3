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
"""
from __future__ import annotations

import csv
import io
import math
import warnings
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.spatial import cKDTree

from .._text import decode_utf8
from ..errors import LocbookError, ParameterError

__all__ = [
    "DataFormatError", "MeasuredDataWarning", "READING_COLUMNS", "OPTIONAL_READING_COLUMNS", "RSSI_RANGE_DBM",
    "MAX_TIME_S", "ANCHOR_MIN_SEPARATION_M", "MAX_REGULAR_EPOCHS", "AGGREGATES", "Epochs", "RSSI_LIMITS_DBM",
    "MAX_COORDINATE_M", "MAX_LINE_BYTES", "MAX_EXACT_READ_BYTES", "MAX_READINGS_FILE_BYTES", "MAX_MIN_READINGS",
    "MIN_WINDOW_S", "DEVICE_COLUMN", "LINK_DIRECTION_RULE",
    "read_readings", "read_anchors", "read_outline", "read_path_segments", "validate_readings", "epochs",
    "regular_epochs", "scan_interval_s",
]

READING_COLUMNS = ("time_s", "transmitter", "receiver", "rssi_dbm")
OPTIONAL_READING_COLUMNS = ("x_m", "y_m", "z_m", "heading_rad")
#: the optional text column naming the measuring hardware of the tag's side of a link (default: the transmitter id):
#: devices differ by a constant receiver offset in dB, which a calibration can fit per device
DEVICE_COLUMN = "device"
#: which end of a link goes in which column, quoted by the messages a swap of the two columns surfaces as
LINK_DIRECTION_RULE = ("the anchor (the fixed device) always goes in 'receiver' and the moving tag in 'transmitter', "
                       "whichever end physically transmits (a phone scanning fixed beacons: the beacon's id is the "
                       "receiver)")
#: a received power outside this interval (dBm) is a unit or sign error, never a reading
RSSI_RANGE_DBM = (-150.0, 20.0)
#: the widest ``valid_range_dbm`` a caller may declare (dBm): -300 dBm is 1e-33 W, +100 dBm 10 MW; a range beyond
#: (an infinite one) would turn off the unit check
RSSI_LIMITS_DBM = (-300.0, 100.0)
#: a time_s of this magnitude or more (3,169 years) is not seconds: milli-, micro- or nanoseconds since 1970
MAX_TIME_S = 1e11
#: two anchors closer than this (m) are the same point: refused (the geometry would be degenerate)
ANCHOR_MIN_SEPARATION_M = 1e-3
#: the default bound on the ticks :func:`regular_epochs` creates (a clock jump would otherwise fill the memory)
MAX_REGULAR_EPOCHS = 1_000_000
#: anchor, outline, path and true-position coordinates of this magnitude (m) or more are refused: no site is larger
#: (projected map coordinates, e.g. UTM northings, stay below 1e7 m); beyond it is a unit error, and distances
#: of 1e300 overflow (issue 44)
MAX_COORDINATE_M = 1e7
#: a line of a CSV longer than this (bytes) is refused: no row of the long format is that long, it is a file
#: without line ends or not a CSV at all (the csv module's own field limit, ``csv.field_size_limit()``, is 128 KiB)
MAX_LINE_BYTES = 128 << 10
#: the largest file the exact reader (``_read_text_table``) takes: it holds every field as a Python string, about
#: :data:`EXACT_READER_BYTES_PER_BYTE` bytes of memory per byte of file (issue 29: 800 bytes per reading), so
#: 64 MiB of CSV take about 1.5 GiB; larger files must be one record per line (the fast reader) or are refused
MAX_EXACT_READ_BYTES = 64 << 20
#: peak memory of the exact reader per byte of file (measured: 10^6 readings, 30 MiB of CSV, peaked at 0.99 GB;
#: issue 29: 4.1 M readings, about 140 MiB, at 2.84 GB)
EXACT_READER_BYTES_PER_BYTE = 24
#: the largest readings file (bytes) read at all: the fast reader takes about
#: :data:`FAST_READER_BYTES_PER_BYTE` bytes of memory per byte of file (issue 29: 10^7 readings, 336 MiB of CSV,
#: peaked at 2.2 GiB; issue 44: 10^6 readings, 31 MB, 200 MB above the interpreter, 3 x 10^6 623 MB, one quoted field
#: or none), so 1 GiB of CSV (about 3 x 10^7 readings) take about 7 GiB; split larger recordings
MAX_READINGS_FILE_BYTES = 1 << 30
FAST_READER_BYTES_PER_BYTE = 7
#: the shortest epoch window (s) but 0: no radio packet is shorter, and a window of 5e-324 s makes ticks infinite
MIN_WINDOW_S = 1e-6
#: the largest ``min_readings`` of an epoch rule: more readings of one anchor than any window holds (a million
#: packets per anchor per window) would leave every entry not heard
MAX_MIN_READINGS = 1_000_000
#: rows per chunk when a large file's number column holds text that is not a number (to name its line)
_LOCATE_CHUNK_ROWS = 200_000
#: characters of a file's text an error message quotes at most (a field, a header, a line): a message never echoes
#: a file (a symlink to /proc/self/environ, a binary file)
MAX_QUOTED_CHARS = 60
_MISSING_TEXT = {"", "nan", "NaN", "NAN", "NA", "N/A"}

class DataFormatError(LocbookError, ValueError):
    """A measured-data file that breaks a rule of the long format; the message names file, line and column."""


class MeasuredDataWarning(UserWarning):
    """Measured data that loads but looks wrong (e.g. readings at or above 0 dBm with no sentinel declared)."""


# -- reading and checking CSV text ---------------------------------------------------------------------------
def _shown(value) -> str:
    """``repr(value)`` for a message, cut to :data:`MAX_QUOTED_CHARS` characters (with the full length) so that a
    message never echoes a large or binary file."""
    text = value if isinstance(value, str) else str(value)
    if len(text) <= MAX_QUOTED_CHARS:
        return repr(value)
    return f"{text[:MAX_QUOTED_CHARS]!r}... ({len(text):,} characters)"


def _shown_names(names, limit: int = 12) -> str:
    """A list of column names for a message: each cut by :func:`_shown`, at most ``limit`` of them."""
    names = list(names)
    shown = ", ".join(_shown(n) for n in names[:limit])
    return f"[{shown}{f', ... ({len(names)} names)' if len(names) > limit else ''}]"


def _size(n_bytes: float) -> str:
    return f"{n_bytes / (1 << 30):.1f} GiB" if n_bytes >= 1 << 30 else f"{n_bytes / (1 << 20):.1f} MiB"


def _check_line_lengths(data: bytes, path: Path, what: str, first_line: int = 1) -> None:
    """Refuse a line longer than :data:`MAX_LINE_BYTES` (bytes ``data`` start at line ``first_line``)."""
    a = np.frombuffer(data, np.uint8)
    ends = np.flatnonzero(a == 10)
    bounds = np.r_[-1, ends, a.size]
    length = np.diff(bounds) - 1
    long = np.flatnonzero(length > MAX_LINE_BYTES)
    if long.size:
        k = int(long[0])
        raise DataFormatError(f"{what} file {path}, line {first_line + k}: the line is {int(length[k]):,} bytes "
                              f"long, more than the {MAX_LINE_BYTES:,} bytes a line may have (MAX_LINE_BYTES): not "
                              "a row of a CSV (no line ends, or not a text file)")


def _decode_utf8(data: bytes, path: Path, what: str) -> str:
    """The file's text; a byte that is not UTF-8 is an error naming its line and its byte in the line."""
    def fail(line, column, offset, line_bytes):
        line_text = line_bytes[:4 * MAX_QUOTED_CHARS].decode("utf-8", errors="replace")
        raise DataFormatError(
            f"{what} file {path}, line {line}, byte {column} of the "
            f"line (byte {offset + 1} of the file): 0x{data[offset]:02x} is not UTF-8 ({_shown(line_text.rstrip())}); "
            "locbook reads UTF-8 only: re-save the file as UTF-8 (e.g. iconv -f cp1252 -t utf-8)")
    return decode_utf8(data, fail)


def _read_text_table(path, required: tuple[str, ...], what: str, why: str = "") -> tuple[pd.DataFrame, np.ndarray]:
    """The CSV as text (nothing converted yet), with every required column present, and each row's line in the
    file (as an editor counts it: blank lines count, a quoted field over several lines gives its first line).

    Every row must have exactly as many fields as the header: a missing field is never read as empty (an empty
    field is written ``,,``) and an extra one never shifts the columns. A file over :data:`MAX_EXACT_READ_BYTES`
    is refused before it is read (``why``: the reason it came here, for the message)."""
    path = Path(path)
    if not path.is_file():
        raise DataFormatError(f"{what} file {path} does not exist")
    size = path.stat().st_size
    if size > MAX_EXACT_READ_BYTES:
        raise DataFormatError(
            f"{what} file {path}{': ' + why if why else ''}: such a file is read by the exact reader, which would "
            f"take about {_size(size * EXACT_READER_BYTES_PER_BYTE)} for its {_size(size)}; it reads files up to "
            f"{_size(MAX_EXACT_READ_BYTES)} (MAX_EXACT_READ_BYTES): write one record per line (LF or CRLF line "
            "ends, no blank lines, no quoted line breaks) or split the file")
    data = path.read_bytes()
    _check_line_lengths(data, path, what)
    text = _decode_utf8(data, path, what)
    reader = csv.reader(io.StringIO(text, newline=""), skipinitialspace=True, strict=True)
    rows, lines, header, header_line, end, wrong = [], [], None, 0, 0, None
    try:
        for row in reader:
            first, end = end + 1, reader.line_num
            if not row or (len(row) == 1 and not row[0].strip()):   # a blank (or whitespace) line
                continue
            if header is None:
                header, header_line = [c.strip() for c in row], first
                continue
            if len(row) != len(header) and wrong is None:
                wrong = (first, row)                             # reported after the header's own checks
            rows.append(row)
            lines.append(first)
    except csv.Error as exc:
        raise DataFormatError(f"{what} file {path}, line {reader.line_num}: not a readable CSV row ({exc})") from None
    if header is None:
        raise DataFormatError(f"{what} file {path} is empty (no header line)")
    duplicated = sorted({c for c in header if header.count(c) > 1})
    if duplicated:
        raise DataFormatError(f"{what} file {path}: column(s) {_shown_names(duplicated)} appear more than once in "
                              "the header")
    missing = [c for c in required if c not in header]
    if missing:
        raise DataFormatError(f"{what} file {path}: missing column(s) {missing}; the header has {_shown_names(header)} "
                              f"(required: {list(required)})")
    if wrong is not None:
        _wrong_field_count(path, what, *wrong, header, header_line)
    names = [c if c else f"Unnamed: {j}" for j, c in enumerate(header)]     # pandas' name for a blank header
    table = pd.DataFrame(rows, columns=names, dtype=object) if rows else pd.DataFrame(
        {c: pd.Series([], dtype=object) for c in names})
    return table, np.asarray(lines, dtype=int)


def _wrong_field_count(path, what: str, line: int, row: list[str], header: list[str], header_line: int):
    named = len(header)
    while named and not header[named - 1]:          # empty names at the end of the header
        named -= 1
    if named < len(header) and len(row) == named:   # rows without them: the header alone has trailing commas
        raise DataFormatError(f"{what} file {path}, line {header_line}: the header ends with an empty column name "
                              f"(a trailing comma?): it has {len(header)} names, {_shown_names(header)}, but line "
                              f"{line} has "
                              f"{len(row)} field(s); remove the trailing comma from the header")
    if len(row) < len(header):
        absent = header[len(row):]
        raise DataFormatError(f"{what} file {path}, line {line}, column(s) {_shown_names(absent)}: the row has "
                              f"{len(row)} field(s), "
                              f"the header {len(header)}: {'it is' if len(absent) == 1 else 'they are'} missing "
                              "(an empty value is written as an empty field, e.g. '0.5,tag,A,' for not heard)")
    raise DataFormatError(f"{what} file {path}, line {line}: the row has {len(row)} fields, the header {len(header)} "
                          f"fields ({_shown_names(header)}); a value with a comma must be quoted, and an extra column "
                          "needs a "
                          "name in the header")


def _numeric(table: pd.DataFrame, column: str, source: str, lines, *, missing_ok: bool,
             coordinate: bool = False) -> np.ndarray:
    """A text column as floats; empty / NaN text is missing (allowed only where ``missing_ok``); anything else
    that is not a finite number is an error naming the line. A ``coordinate`` of magnitude
    :data:`MAX_COORDINATE_M` or more is refused too."""
    raw = table[column]
    if pd.api.types.is_numeric_dtype(raw) and not pd.api.types.is_bool_dtype(raw):
        values = raw.to_numpy(dtype=float, na_value=np.nan)
        missing = np.isnan(values)
    else:
        text = raw.astype(object).where(raw.notna(), "").astype(str).str.strip()
        missing = text.isin(_MISSING_TEXT).to_numpy()
        values = pd.to_numeric(text.where(~missing, None), errors="coerce").to_numpy(dtype=float)
    bad = ~missing & ~np.isfinite(values)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise DataFormatError(f"{source}, line {lines[i]}, column {column!r}: {_shown(table[column].iloc[i])} is "
                              "not a finite "
                              f"number ({int(bad.sum())} such value(s) in the column)")
    if missing.any() and not missing_ok:
        i = int(np.flatnonzero(missing)[0])
        raise DataFormatError(f"{source}, line {lines[i]}, column {column!r}: value is missing ({int(missing.sum())} "
                              "missing value(s) in the column; it must be given on every row)")
    if coordinate:
        far = np.abs(values) >= MAX_COORDINATE_M          # NaN compares False
        if far.any():
            i = int(np.flatnonzero(far)[0])
            raise DataFormatError(f"{source}, line {lines[i]}, column {column!r}: {values[i]:g} is not a coordinate of "
                                  f"a site (coordinates are less than {MAX_COORDINATE_M:g} in magnitude, "
                                  f"MAX_COORDINATE_M; {int(far.sum())} such value(s)): a unit error?")
    return values


def _file_lines(n_rows: int) -> np.ndarray:
    return np.arange(n_rows) + 2            # the header is line 1


# -- the long format ----------------------------------------------------------------------------------------
def _seconds(value) -> str:
    """A time with every digit it has (``repr``): ``1581250000.25 s``, never ``1.58125e+09 s``."""
    return f"{float(value)!r} s"


def _is_real(value) -> bool:
    """A real number that is not a bool (``True`` is 1 to numpy, never a reading) nor text."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def _reading_options(invalid_values_dbm, valid_range_dbm):
    """The checked sentinel values (a float array) and range ``(low, high)`` of :func:`validate_readings`.

    Sentinels: a number or a sequence of numbers (not text, not bools: ``"0"`` or ``[True]`` are refused, not read
    as 0 and 1 dBm). The range: two finite numbers within :data:`RSSI_LIMITS_DBM` (an infinite bound would turn off
    the unit check the range exists for)."""
    values = () if invalid_values_dbm is None else invalid_values_dbm
    if _is_real(values):
        values = (values,)
    if isinstance(values, np.ndarray):
        values = values.reshape(-1).tolist() if values.dtype.kind in "iuf" else list(values.reshape(-1))
    if not isinstance(values, (list, tuple)) or not all(_is_real(v) for v in values):
        raise ParameterError("invalid_values_dbm must be a sequence of numbers (dBm), got "
                             f"{_shown(invalid_values_dbm)}")
    sentinels = np.asarray(values, dtype=float).reshape(-1)
    if not np.isfinite(sentinels).all():
        raise ParameterError(f"invalid_values_dbm must hold finite numbers (dBm), got {_shown(invalid_values_dbm)}")
    rng = RSSI_RANGE_DBM if valid_range_dbm is None else valid_range_dbm
    if isinstance(rng, np.ndarray):
        rng = rng.tolist()
    if not isinstance(rng, (list, tuple)) or len(rng) != 2 or not all(_is_real(v) for v in rng):
        raise ParameterError(f"valid_range_dbm must be a pair (low, high) of numbers (dBm), got {_shown(rng)}")
    low, high = (float(v) for v in rng)
    lo_limit, hi_limit = RSSI_LIMITS_DBM
    if not (lo_limit <= low < high <= hi_limit):      # NaN and infinities fail too
        raise ParameterError(f"valid_range_dbm must be (low, high) with {lo_limit:g} <= low < high <= {hi_limit:g} "
                             f"(dBm, RSSI_LIMITS_DBM: no receiver reports outside), got {_shown(rng)}")
    return sentinels, (low, high)


def _check_time_unit(time_s: np.ndarray, raw: pd.Series, source: str, lines) -> None:
    """Refuse times that are not seconds: beyond :data:`MAX_TIME_S` they are milli-, micro- or nanoseconds (a
    common export), which as 64-bit floats also lose their differences (1.6e18 ns are 256 ns apart at best) and
    would surface as "repeats line ..."."""
    huge = np.abs(time_s) >= MAX_TIME_S
    if not huge.any():
        return
    i = int(np.flatnonzero(huge)[0])
    t = float(time_s[i])
    guess = ""
    for scale, unit, short in ((1e3, "milliseconds", "ms"), (1e6, "microseconds", "us"), (1e9, "nanoseconds", "ns")):
        if 1e8 <= abs(t) / scale < MAX_TIME_S:   # 1973 .. 5138 as seconds since 1970
            when = datetime.fromtimestamp(t / scale, tz=timezone.utc).isoformat(timespec="seconds")
            guess = (f"; it looks like {unit} since 1970 ({t / scale!r} s = {when}): in a data set, declare "
                     f"[units] time = \"{short}\" in dataset.toml; else convert the column to seconds (divide by "
                     f"{scale:.0e}, after subtracting the first time to keep the small differences)")
            break
    raise DataFormatError(f"{source}, line {lines[i]}, column 'time_s': {_shown(str(raw.iloc[i]).strip())} is not a "
                          "time in "
                          f"seconds ({abs(t) / 3.15576e7:.3g} years; time_s is at most {MAX_TIME_S:.0e} s in "
                          f"magnitude){guess} ({int(huge.sum())} such value(s) in the column)")


def file_time_origin(raw_time):
    """The origin a readings file's times are shifted by when ``[units] time`` is not seconds (the rule of
    :func:`locbook.data.dataset._convert`), from its time column as written: the smallest time, an ``int`` where
    every field is an integer (so that nanoseconds since 1970 keep every digit), else a float; None where no time is
    a number. A recording's other files (ranges, inertial samples) are shifted by the same origin, so they stay on
    its readings' clock."""
    raw = pd.Series(raw_time)
    if pd.api.types.is_numeric_dtype(raw) and not isinstance(raw.dtype, pd.CategoricalDtype):
        v = raw.to_numpy(float)
        return float(np.nanmin(v)) if np.isfinite(v).any() else None
    text = raw.astype(object).where(raw.notna(), "").astype(str).str.strip()
    if len(text) and text.str.fullmatch(r"[+-]?\d{1,19}").all():
        try:
            return int(text.astype(np.int64).min())
        except (OverflowError, ValueError):
            pass
    v = pd.to_numeric(text, errors="coerce").to_numpy(float)
    return float(np.min(v[np.isfinite(v)])) if np.isfinite(v).any() else None


def shifted_seconds(table: pd.DataFrame, source: str, lines, time_scale: float, origin) -> np.ndarray:
    """A recording's other file's ``time_s`` in seconds on its readings' clock: as written (``time_scale`` 1, or no
    ``origin``; refused beyond :data:`MAX_TIME_S` as the readings are), else ``(t - origin) * time_scale`` with
    ``origin`` the readings file's :func:`file_time_origin` (integers shifted as integers)."""
    raw = table["time_s"]
    if time_scale == 1.0 or origin is None:
        t = _numeric(table, "time_s", source, lines, missing_ok=False)
        _check_time_unit(t, raw, source, lines)
        return t * time_scale
    text = raw.astype(object).where(raw.notna(), "").astype(str).str.strip()
    if isinstance(origin, int) and len(text) and text.str.fullmatch(r"[+-]?\d{1,19}").all():
        try:
            return (text.astype(np.int64).to_numpy() - origin).astype(float) * time_scale
        except (OverflowError, ValueError):
            pass
    return (_numeric(table, "time_s", source, lines, missing_ok=False) - float(origin)) * time_scale


def validate_readings(table: pd.DataFrame, *, source: str, lines=None, anchor_ids=None, invalid_values_dbm=None,
                      valid_range_dbm=None, sort: bool = False) -> pd.DataFrame:
    """Check a readings table of the long format (module docstring) and return it typed: ``time_s``,
    ``rssi_dbm`` and the optional position columns as floats (NaN = missing), ids as text.

    ``table`` holds text or numbers; ``source`` names it in messages and ``lines`` gives each row's line in that
    source (default: row ``i`` is line ``i + 2``). With ``anchor_ids`` every receiver must be one of them.

    ``invalid_values_dbm``: values a data set writes for "no valid reading" (e.g. ``(0, 2, 4)``); they become
    NaN (not heard) before any other check. ``valid_range_dbm``: the plausible interval of a reading (default
    :data:`RSSI_RANGE_DBM`); a value outside it is refused. With no sentinel declared and the default range,
    readings at or above 0 dBm (not plausible beyond a few centimetres from the antenna) load but raise one
    :class:`MeasuredDataWarning` with their count. ``sort=True`` reorders the rows by time (stable: rows of
    equal time keep their order) before the checks, so a file that is not in time order loads; messages still
    name the source's lines."""
    sentinels, (low, high) = _reading_options(invalid_values_dbm, valid_range_dbm)
    lines = _file_lines(len(table)) if lines is None else np.asarray(lines)
    if lines.shape != (len(table),):
        raise ParameterError(f"lines must give one line number per row of the table ({len(table)}), "
                             f"got shape {lines.shape}")
    missing_cols = [c for c in READING_COLUMNS if c not in table.columns]
    if missing_cols:
        raise DataFormatError(f"{source}: missing column(s) {missing_cols}; it has {list(table.columns)} "
                              f"(required: {list(READING_COLUMNS)})")
    time_s = _numeric(table, "time_s", source, lines, missing_ok=False)
    _check_time_unit(time_s, table["time_s"], source, lines)
    if sort:
        order = np.argsort(time_s, kind="stable")
        table, lines, time_s = table.iloc[order], lines[order], time_s[order]
    text = table.reset_index(drop=True)
    out = pd.DataFrame(index=text.index)
    out["time_s"] = time_s
    for col in ("transmitter", "receiver"):
        out[col] = _id_column(text, col, source, lines).array
    rssi = _numeric(text, "rssi_dbm", source, lines, missing_ok=True)
    rssi = np.where(np.isin(rssi, sentinels), np.nan, rssi)     # declared sentinels: not heard
    outside = np.isfinite(rssi) & ((rssi < low) | (rssi > high))
    if outside.any():
        i = int(np.flatnonzero(outside)[0])
        raise DataFormatError(f"{source}, line {lines[i]}, column 'rssi_dbm': {rssi[i]:g} dBm is outside "
                              f"[{low:g}, {high:g}] dBm (a unit or sign error, not a reading; empty = not heard; "
                              f"{int(outside.sum())} such value(s))")
    if sentinels.size == 0 and valid_range_dbm is None:
        high_power = np.flatnonzero(rssi >= 0.0)          # NaN compares False
        if high_power.size:
            values = ", ".join(f"{v:g}" for v in np.unique(rssi[high_power])[:6])
            warnings.warn(f"{source}: {high_power.size} reading(s) at or above 0 dBm (values {values}; the first on "
                          f"line {lines[high_power[0]]}), implausible beyond a few centimetres from an antenna. If the "
                          "data set writes such values for invalid readings, declare them: invalid_values_dbm=(...) "
                          "makes them NaN (not heard); to keep them as readings, give valid_range_dbm explicitly",
                          MeasuredDataWarning, stacklevel=3)
    out["rssi_dbm"] = rssi
    for col in OPTIONAL_READING_COLUMNS:
        out[col] = (_numeric(text, col, source, lines, missing_ok=True, coordinate=col != "heading_rad")
                    if col in text.columns
                    else np.full(len(text), np.nan))
    if DEVICE_COLUMN in text.columns:
        devices = _ids(text[DEVICE_COLUMN])
        empty = devices.isna().to_numpy()
        if empty.any():
            i = int(np.flatnonzero(empty)[0])
            raise DataFormatError(f"{source}, line {lines[i]}, column {DEVICE_COLUMN!r}: the device is empty "
                                  f"({int(empty.sum())} such row(s)); a device column names the device on every row "
                                  "(without the column, each transmitter id is its own device)")
        out[DEVICE_COLUMN] = devices.array
    half = np.isnan(out["x_m"].to_numpy()) != np.isnan(out["y_m"].to_numpy())
    if half.any():
        i = int(np.flatnonzero(half)[0])
        given, absent = ("x_m", "y_m") if np.isfinite(out["x_m"].iloc[i]) else ("y_m", "x_m")
        raise DataFormatError(f"{source}, line {lines[i]}, column {absent!r}: missing while {given!r} is given "
                              "(a true position has both coordinates or neither)")
    if anchor_ids is not None:
        _check_receivers(out, anchor_ids, source, lines)
    key = out[["time_s", "transmitter", "receiver"]]
    dup = key.duplicated(keep="first").to_numpy()
    if dup.any():
        i = int(np.flatnonzero(dup)[0])
        first = int(np.flatnonzero((key == key.iloc[i]).all(axis=1).to_numpy())[0])
        written = [str(text["time_s"].iloc[k]).strip() for k in (first, i)]
        note = ("" if written[0] == written[1] else
                f" (the source has times {_shown(written[0])} and {_shown(written[1])}: equal as 64-bit floats, which "
                "hold about "
                "16 significant digits; give times from a nearer origin, e.g. seconds since the first reading)")
        raise DataFormatError(f"{source}, line {lines[i]}, columns 'time_s','transmitter','receiver': the reading "
                              f"({_seconds(out['time_s'].iloc[i])}, {_shown(out['transmitter'].iloc[i])}, "
                              f"{_shown(out['receiver'].iloc[i])}) repeats line {lines[first]}{note}")
    # time non-decreasing within each transmitter: group the rows by transmitter (stable), compare neighbours
    codes = pd.factorize(out["transmitter"])[0]
    by_tx = np.argsort(codes, kind="stable")
    back = (np.diff(time_s[by_tx]) < 0) & (np.diff(codes[by_tx]) == 0)
    if back.any():
        k = np.flatnonzero(back)
        i = int(by_tx[k + 1].min())                                        # the first such row of the source
        prev = int(by_tx[k[by_tx[k + 1] == i][0]])
        raise DataFormatError(f"{source}, line {lines[i]}, column 'time_s': time goes back for transmitter "
                              f"{_shown(out['transmitter'].iloc[i])} ({_seconds(time_s[i])} after "
                              f"{_seconds(time_s[prev])} "
                              f"on line {lines[prev]}); sort the file by time, or read it with sort=True (rows "
                              "reordered by time, stably)")
    extra = [c for c in text.columns if c not in out.columns]
    for col in extra:
        out[col] = text[col].array
    return out


def _id_column(table: pd.DataFrame, column: str, source: str, lines) -> pd.Series:
    """A column of ids (:func:`_ids`), a row without one refused naming its line: ids are text, so "NA", "N/A" or
    "nan" are ids, and only an empty field is no id."""
    ids = _ids(table[column])
    empty = ids.isna().to_numpy()
    if empty.any():
        i = int(np.flatnonzero(empty)[0])
        raise DataFormatError(f"{source}, line {lines[i]}, column {column!r}: the id is empty")
    return ids


def _check_receivers(table: pd.DataFrame, anchor_ids, source: str, lines) -> None:
    """Refuse a row whose ``receiver`` is not an anchor id (the readings' and the ranges' one rule), naming its
    line, with the link-direction hint where the transmitters are the anchors."""
    known = {str(a) for a in anchor_ids}
    unknown = ~table["receiver"].isin(known).to_numpy()
    if unknown.any():
        i = int(np.flatnonzero(unknown)[0])
        raise DataFormatError(f"{source}, line {lines[i]}, column 'receiver': {_shown(table['receiver'].iloc[i])} is "
                              f"not an anchor id (the anchors are {_shown_names(sorted(known))})"
                              f"{_link_direction_hint(table['transmitter'], known)}")


def _link_direction_hint(transmitters: pd.Series, anchor_ids) -> str:
    """The end of the message for a receiver that is not an anchor: the link-direction rule, and whether the
    transmitter column holds anchor ids (the two columns swapped: a phone log of the beacons it heard)."""
    known = {str(a) for a in anchor_ids}
    sent = pd.Series(pd.Series(transmitters).unique()).astype(str)
    swapped = sent[sent.isin(known)]
    if len(swapped):
        return (f"; the transmitter column holds anchor ids ({_shown_names(swapped.tolist(), limit=4)}): the two "
                f"columns are swapped? {LINK_DIRECTION_RULE[0].upper()}{LINK_DIRECTION_RULE[1:]}")
    return f"; {LINK_DIRECTION_RULE}"


def _ids(column: pd.Series) -> pd.Series:
    """Text ids, stripped, as categories (one string per distinct id, whatever the number of rows); an empty or
    absent field is missing (NaN)."""
    if not isinstance(column.dtype, pd.CategoricalDtype):
        column = column.astype(object).where(column.notna(), "").astype(str).astype("category")
    cats = column.cat.categories.astype(str).str.strip()
    uniq, inverse = np.unique(cats.to_numpy(object), return_inverse=True)
    codes = column.cat.codes.to_numpy()
    new = np.where(codes < 0, -1, inverse[np.maximum(codes, 0)])
    empty = np.flatnonzero(uniq == "")
    if empty.size:
        new = np.where(new == empty[0], -1, new - (new > empty[0]))
        uniq = np.delete(uniq, empty[0])
    return pd.Series(pd.Categorical.from_codes(new, pd.Index(uniq, dtype=object)), index=column.index)


#: bytes per block of the field-count scan of :func:`read_readings_table` (its scratch memory is ~4x this)
_SCAN_BLOCK = 1 << 25


def _scan_records(path: Path, n_fields: int) -> str:
    """``""`` when the file after its header line is UTF-8 text with LF or CRLF line ends whose every line is one
    record of ``n_fields`` fields (a quoted field, with commas or doubled quotes in it, may appear; a quoted line
    break may not) and none is blank: then data row ``i`` is line ``i + 2`` and no row is short or long. Else the
    first reason it is not, naming the line. A line over :data:`MAX_LINE_BYTES` is refused here. Read in blocks of
    :data:`_SCAN_BLOCK` bytes (never the whole file at once); only lines holding a quote go through the csv
    module."""
    want = n_fields - 1
    with open(path, "rb") as fh:
        fh.readline(MAX_LINE_BYTES + 2)                    # the header (checked by the caller)
        line, rest = 2, b""                                # the line number of the block's first line
        while True:
            chunk = fh.read(_SCAN_BLOCK)
            if not chunk and not rest:
                return ""
            block = rest + chunk
            if chunk:                                      # cut at the last line end; the rest joins the next block
                cut = block.rfind(b"\n") + 1
                if cut == 0:
                    if len(block) > MAX_LINE_BYTES:
                        _check_line_lengths(block, path, "readings", line)
                    rest = block
                    continue
                block, rest = block[:cut], block[cut:]
            else:
                rest = b""
            _check_line_lengths(block, path, "readings", line)
            a = np.frombuffer(block, np.uint8)
            ends = np.flatnonzero(a == 10)
            if a[-1] != 10:
                ends = np.r_[ends, a.size - 1]             # the last line without a line end
            cr = np.flatnonzero(a == 13)
            lone = cr[(cr + 1 >= a.size) | (a[np.minimum(cr + 1, a.size - 1)] != 10)]
            if lone.size:
                return f"line {line + int(np.searchsorted(ends, lone[0]))} ends with a CR alone (not LF or CRLF)"
            try:
                block.decode("utf-8")
            except UnicodeDecodeError as exc:
                return f"line {line + int(np.searchsorted(ends, exc.start))} is not UTF-8"
            per_line = np.diff(np.searchsorted(np.flatnonzero(a == 44), ends, side="right"), prepend=0)
            quoted = np.unique(np.searchsorted(ends, np.flatnonzero(a == 34)))
            if quoted.size:                                # those lines: fields as the csv module splits them
                starts = np.r_[0, ends[:-1] + 1]
                texts = [block[starts[k]:ends[k] + 1].decode("utf-8").rstrip("\r\n") for k in quoted]
                reader = csv.reader(texts, skipinitialspace=True, strict=True)
                try:
                    for j, row in enumerate(reader):
                        if reader.line_num != j + 1:
                            return f"line {line + int(quoted[j])} has a quoted field that goes on over a line break"
                        per_line[quoted[j]] = len(row) - 1
                except csv.Error as exc:
                    k = int(quoted[min(reader.line_num, len(quoted)) - 1])
                    return f"line {line + k} is not a readable CSV row ({exc})"
            bad = np.flatnonzero(per_line != want)
            if bad.size:
                k = int(bad[0])
                blank = not block[(0 if k == 0 else ends[k - 1] + 1):ends[k] + 1].strip()
                return (f"line {line + k} is blank" if blank else
                        f"line {line + k} has {int(per_line[k]) + 1} field(s), the header {n_fields}")
            line += ends.size


def _header(first: bytes) -> list[str] | None:
    """The header's column names (stripped), or None if the line is not a readable CSV row."""
    if first.startswith(b"\xef\xbb\xbf"):
        first = first[3:]
    text = first.decode("utf-8", "replace").rstrip("\r\n")
    if '"' not in text:
        return [c.strip() for c in text.split(",")]
    try:
        rows = list(csv.reader([text], skipinitialspace=True, strict=True))
    except csv.Error:
        return None
    return [c.strip() for c in rows[0]] if len(rows) == 1 else None


def _locate_bad_number(path: Path, header: list[str], numeric: list[str], error: Exception):
    """Name the line and column of the first number column's field the fast reader could not parse (a file too
    large for the exact reader): read it again in chunks of :data:`_LOCATE_CHUNK_ROWS` rows as text (one record
    per line, as checked) and run the long format's number check on each."""
    source = f"readings file {path}"
    try:
        offset = 0
        for chunk in pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True, engine="c",
                                 encoding="utf-8-sig", chunksize=_LOCATE_CHUNK_ROWS):
            chunk.columns = header
            lines = _file_lines(len(chunk)) + offset
            for column in numeric:
                _numeric(chunk, column, source, lines, missing_ok=column != "time_s")
            offset += len(chunk)
    except DataFormatError:
        raise
    except (ValueError, UnicodeDecodeError, pd.errors.ParserError) as exc:     # pandas' tokenizer, once more
        error = exc
    raise DataFormatError(f"{source}: pandas' reader refused it ({_shown(str(error))}), and at "
                          f"{_size(path.stat().st_size)} "
                          f"it is too large for the exact reader (MAX_EXACT_READ_BYTES = "
                          f"{_size(MAX_EXACT_READ_BYTES)}), which would name the line")


def _text_categories(path: Path, j: int, n_rows: int) -> pd.Series:
    """Column ``j`` of the file as categories of its text. pandas' C reader turns categories that all look like
    numbers or bools into numbers or bools (``01`` -> 1, ``1.50`` and ``1.5`` -> one point, ``true`` -> True), which
    would change ids; the column is read again as text, in chunks of :data:`_LOCATE_CHUNK_ROWS` rows (each chunk's
    strings are categories before the next is read)."""
    from pandas.api.types import union_categoricals
    parts = [chunk.iloc[:, 0].astype("category") for chunk in
             pd.read_csv(path, usecols=[j], dtype=str, keep_default_na=False, skipinitialspace=True, engine="c",
                         encoding="utf-8-sig", chunksize=_LOCATE_CHUNK_ROWS)]
    values = union_categoricals(parts) if parts else pd.Categorical([])
    if len(values) != n_rows:           # cannot happen for a file the scan passed; never a silent shift
        raise DataFormatError(f"readings file {path}: column {j + 1} read again as text has {len(values)} rows, "
                              f"not {n_rows}")
    return pd.Series(values)


def read_readings_table(path, *, time_as_text: bool = False) -> tuple[pd.DataFrame, np.ndarray]:
    """A readings CSV as :func:`validate_readings` takes it, and each row's line: the number columns as floats
    (empty, ``NaN``, ``NA``, ``N/A`` missing), the ids and other columns as categories (text, stripped later).

    Files of one record per line (every logger's output; quoted fields allowed, quoted line breaks not) are parsed
    by pandas' C reader, at a few bytes per field; any other file, or one that reader refuses, goes through the
    exact reader (``_read_text_table``), whose messages name the line and column of the problem. Sizes are checked
    before anything is read: a file over :data:`MAX_READINGS_FILE_BYTES`, a line over :data:`MAX_LINE_BYTES`, and a
    file over :data:`MAX_EXACT_READ_BYTES` that needs the exact reader are refused, naming the limit.
    ``time_as_text`` keeps ``time_s`` as written (integer nanoseconds since 1970 lose their last digits as
    floats)."""
    path = Path(path)
    if not path.is_file():
        raise DataFormatError(f"readings file {path} does not exist")
    size = path.stat().st_size
    if size > MAX_READINGS_FILE_BYTES:
        raise DataFormatError(f"readings file {path} is {_size(size)}: reading it would take about "
                              f"{_size(size * FAST_READER_BYTES_PER_BYTE)}, and a readings file is at most "
                              f"{_size(MAX_READINGS_FILE_BYTES)} (MAX_READINGS_FILE_BYTES): split the recording "
                              "into several files, one [[recording]] each")
    with open(path, "rb") as fh:
        first = fh.readline(MAX_LINE_BYTES + 2)
    _check_line_lengths(first.rstrip(b"\r\n"), path, "readings")
    header = _header(first)
    header_ok = (header is not None and all(c in header for c in READING_COLUMNS)
                 and len(set(header)) == len(header) and all(header))
    if not header_ok and size > MAX_EXACT_READ_BYTES:
        raise DataFormatError(f"readings file {path}, line 1: the header "
                              f"{'is not a readable CSV row' if header is None else _shown_names(header)}; it names "
                              f"the columns {list(READING_COLUMNS)} (and optional ones), each once, none empty")
    numeric = [c for c in ("time_s", "rssi_dbm", *OPTIONAL_READING_COLUMNS)
               if header_ok and c in header and not (time_as_text and c == "time_s")]
    why = _scan_records(path, len(header)) if header_ok else "the header is not the long format's"
    if not why:
        try:
            kinds = {c: (float if c in numeric else str if c == "time_s" else "category") for c in header}
            table = pd.read_csv(path, dtype=kinds, keep_default_na=False,
                                na_values={c: sorted(_MISSING_TEXT) for c in numeric}, skipinitialspace=True,
                                engine="c", encoding="utf-8-sig")
        except (ValueError, UnicodeDecodeError, pd.errors.ParserError) as exc:
            if size > MAX_EXACT_READ_BYTES:                # too large to read again as text: locate it in chunks
                _locate_bad_number(path, header, numeric, exc)
            why = "the fast reader refused it"             # the exact reader says what and where
    if not why and len(table.columns) != len(header):   # e.g. lines ended by a bare CR: the header read differs
        why = "the fast reader split the lines otherwise than the header line"
    if why:
        return _read_text_table(path, READING_COLUMNS, "readings", why=why)
    table.columns = header
    for j, column in enumerate(header):
        if kinds[column] == "category" and table[column].cat.categories.dtype.kind not in "OUT":
            table[column] = _text_categories(path, j, len(table))
    table.attrs["parsed"] = True       # numbers already parsed: see validate_readings_file
    return table, _file_lines(len(table))


def validate_readings_file(path, table: pd.DataFrame, lines, prepare=lambda t: t, **options) -> pd.DataFrame:
    """:func:`validate_readings` of a table from :func:`read_readings_table` (after ``prepare``, e.g. a unit
    conversion). Where the fast reader parsed the numbers and the table breaks a rule, the file is read again as
    text and checked again, so that the message quotes the file's own text (two times equal only as floats); a
    file too large for the exact reader (:data:`MAX_EXACT_READ_BYTES`) keeps the message of the parsed table."""
    source = f"readings file {path}"
    try:
        return validate_readings(prepare(table), source=source, lines=lines, **options)
    except DataFormatError:
        if not table.attrs.get("parsed") or Path(path).stat().st_size > MAX_EXACT_READ_BYTES:
            raise
    exact, lines = _read_text_table(path, READING_COLUMNS, "readings")
    return validate_readings(prepare(exact), source=source, lines=lines, **options)


def read_readings(path, *, anchor_ids=None, invalid_values_dbm=None, valid_range_dbm=None,
                  sort: bool = False) -> pd.DataFrame:
    """Read and check a readings CSV of the long format (module docstring); the options are those of
    :func:`validate_readings` (sentinel values, plausible range, sorting by time)."""
    table, lines = read_readings_table(path)
    return validate_readings_file(path, table, lines, anchor_ids=anchor_ids, invalid_values_dbm=invalid_values_dbm,
                                  valid_range_dbm=valid_range_dbm, sort=sort)


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
    table, lines = _read_text_table(path, ("id", "x", "y"), "anchors")
    source = f"anchors file {path}"
    if len(table) == 0:
        raise DataFormatError(f"{source}: no anchors")
    ids = table["id"].astype(str).str.strip()
    for i in np.flatnonzero((ids == "").to_numpy())[:1]:
        raise DataFormatError(f"{source}, line {lines[i]}, column 'id': the id is empty")
    dup = ids.duplicated().to_numpy()
    if dup.any():
        i = int(np.flatnonzero(dup)[0])
        raise DataFormatError(f"{source}, line {lines[i]}, column 'id': anchor id {_shown(ids.iloc[i])} appears twice")
    axes = ("x", "y", "z") if "z" in table.columns else ("x", "y")
    out = pd.DataFrame({"id": ids.to_numpy()})
    for col in ("x", "y"):
        out[col] = _numeric(table, col, source, lines, missing_ok=False, coordinate=True)
    if "z" in axes:
        z = _numeric(table, "z", source, lines, missing_ok=True, coordinate=True)
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
            f"{_shown(ids.iloc[i])} and "
            f"{_shown(ids.iloc[j])} are at the same position ({', '.join(f'{v:g}' for v in pos[i])}) m (within "
            f"{min_separation_m:g} m; {len(pairs)} such pair(s)); two receivers at one point are a copy error or one "
            "device: fix the coordinates or keep one id")
    return out


def read_outline(path) -> np.ndarray:
    """Read and check a floor outline CSV (``x, y`` vertices of a closed polygon, metres) -> ``(V, 2)``,
    without a repeated closing vertex."""
    table, lines = _read_text_table(path, ("x", "y"), "outline")
    source = f"outline file {path}"
    xy = np.column_stack([_numeric(table, c, source, lines, missing_ok=False, coordinate=True) for c in ("x", "y")])
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
    table, lines = _read_text_table(path, ("x0", "y0", "x1", "y1"), "path")
    source = f"path file {path}"
    cols = [_numeric(table, c, source, lines, missing_ok=False, coordinate=True) for c in ("x0", "y0", "x1", "y1")]
    if len(table) == 0:
        raise DataFormatError(f"{source}: no segments")
    return np.stack(cols, axis=-1).reshape(-1, 2, 2)


# -- from readings to estimator inputs ---------------------------------------------------------------------
#: how the readings of one anchor within one epoch window become the epoch's reading
AGGREGATES = ("mean", "median", "max")


@dataclass(frozen=True)
class Epochs:
    """One recording as the estimators take it: ``rss_dbm (T, m)`` per epoch and anchor (NaN = not heard),
    ``time_s (T,)``, the true position ``position_m (T, 3)`` and heading ``heading_rad (T,)`` (NaN where unknown),
    the ``transmitter`` of each epoch and the anchor ids of the columns. ``n_readings (T, m)``: how many readings
    made each entry (0 where not heard). ``extra``: the readings file's other columns (a point id, a label) that
    hold one value within every epoch, one value per epoch (a column that varies within an epoch is not kept:
    name it in ``group_by`` to split epochs by it). ``device (T,)``: the device of each epoch (the readings'
    ``device`` column; default, and where not given, the transmitter id)."""

    time_s: np.ndarray
    rss_dbm: np.ndarray
    position_m: np.ndarray
    heading_rad: np.ndarray
    transmitter: np.ndarray
    anchor_ids: tuple[str, ...]
    n_readings: np.ndarray | None = None
    extra: dict = field(default_factory=dict)
    device: np.ndarray | None = None

    def __post_init__(self):
        if self.device is None:          # the default: each transmitter is its own device
            object.__setattr__(self, "device", np.asarray(self.transmitter, dtype=object).copy())

    def __len__(self) -> int:
        return self.time_s.shape[0]

    def select(self, mask) -> "Epochs":
        """The epochs where ``mask`` holds (or at the given indices)."""
        return Epochs(self.time_s[mask], self.rss_dbm[mask], self.position_m[mask], self.heading_rad[mask],
                      self.transmitter[mask], self.anchor_ids,
                      None if self.n_readings is None else self.n_readings[mask],
                      {k: v[mask] for k, v in self.extra.items()}, self.device[mask])


def _check_epoch_rule(window_s, aggregate: str, min_readings: int, group_by, readings: pd.DataFrame):
    if window_s is not None and not (isinstance(window_s, (int, float)) and not isinstance(window_s, bool)
                                     and math.isfinite(window_s) and (window_s == 0 or window_s >= MIN_WINDOW_S)):
        raise ParameterError(f"window_s must be None, 0 or a finite number of seconds >= {MIN_WINDOW_S:g} "
                             f"(MIN_WINDOW_S: shorter windows overflow the tick count), got {_shown(window_s)}")
    if aggregate not in AGGREGATES:
        raise ParameterError(f"aggregate must be one of {AGGREGATES}, got {_shown(aggregate)}")
    if not (isinstance(min_readings, (int, np.integer)) and not isinstance(min_readings, bool)
            and 1 <= min_readings <= MAX_MIN_READINGS):
        raise ParameterError(f"min_readings must be an integer from 1 to {MAX_MIN_READINGS:,} (MAX_MIN_READINGS), "
                             f"got {_shown(min_readings)}")
    group_by = (group_by,) if isinstance(group_by, str) else tuple(group_by)
    reserved = set(READING_COLUMNS) | set(OPTIONAL_READING_COLUMNS) | {DEVICE_COLUMN}
    for col in group_by:
        if col in reserved:
            raise ParameterError(f"group_by names extra columns of the readings (e.g. a point id), not {col!r}")
        if col not in readings.columns:
            raise ParameterError(f"group_by column {col!r} is not a column of the readings "
                                 f"(extra columns: {[c for c in readings.columns if c not in reserved]})")
    return group_by


def epochs(readings: pd.DataFrame, anchor_ids, *, window_s: float | None = None, aggregate: str = "mean",
           min_readings: int = 1, group_by=()) -> Epochs:
    """Readings (validated, long format) -> one row per epoch and one column per anchor of ``anchor_ids`` (in
    that order), NaN where the anchor heard nothing (the library's one rule for missing readings). Epochs are in
    time order (ties: the transmitter's first appearance).

    ``window_s=None`` (or 0): the rows already are epochs (native scans: a phone's scan, a logger's averaged
    interval): every distinct (time, transmitter) is one epoch, and its true position must be the same on all of
    its rows (else :class:`DataFormatError`); the epoch's time is that time and its truth that of its rows.

    ``window_s > 0``: raw packets -> epochs. A transmitter's readings go to the window of the nearest tick of a
    clock of period ``window_s`` started at that transmitter's first reading (tick ``k`` holds ``[t0 + (k - 1/2) w,
    t0 + (k + 1/2) w)``, so rows already on such a clock keep one epoch each), and the readings of one anchor in one
    window are combined by ``aggregate`` (``"mean"``, ``"median"`` or ``"max"`` of the dBm values); an anchor with
    fewer than ``min_readings`` readings in the window is NaN (not heard). The epoch's time is its tick.

    The true position of a windowed epoch is the mean, coordinate by coordinate, of the true positions written on
    the window's rows (every row of the epoch that has one, heard or not: one row per reading, so a time logged by
    four anchors counts four times), not the row nearest the tick: the readings were taken along that stretch, so
    the mean is the position their aggregate describes. A coordinate that is the same on every such row (a tag
    standing still, rows already epochs) is kept exactly, not averaged. The heading is the circular mean of the
    rows' headings. NaN where no row of the window has a true position (heading: no row has one). A moving tag's
    first window is only half full (``[t0, t0 + w/2)``), so its mean lies about ``w/4`` of travel after the tick.

    ``group_by``: extra columns (a point id) whose values never share an epoch: epochs are split by them, so a
    window never mixes two static points. Epochs are split by the readings' ``device`` column too (a window never
    mixes two devices); :attr:`Epochs.device` holds it (default: the transmitter id). Extra columns that hold one
    value within every epoch are kept in :attr:`Epochs.extra`."""
    anchor_ids = tuple(str(a) for a in anchor_ids)
    group_by = _check_epoch_rule(window_s, aggregate, min_readings, group_by, readings)
    col = {a: j for j, a in enumerate(anchor_ids)}
    receivers = pd.Series(readings["receiver"].map(col), dtype=float)
    if receivers.isna().any():
        bad = readings["receiver"][receivers.isna().to_numpy()].iloc[0]
        raise DataFormatError(f"receiver {_shown(bad)} is not one of the anchor ids {_shown_names(anchor_ids)}"
                              f"{_link_direction_hint(readings['transmitter'], anchor_ids)}")
    receivers = receivers.to_numpy(int)
    time_s = readings["time_s"].to_numpy(float)
    tx_codes, tx_names = pd.factorize(readings["transmitter"])
    windowed = bool(window_s)
    if windowed:
        first = pd.Series(time_s).groupby(tx_codes).transform("min").to_numpy()
        # half-open windows [t0 + (k - 1/2) w, t0 + (k + 1/2) w): a reading half a window from a tick goes to the later
        # tick (np.rint's round-half-to-even would make windows alternately wider and narrower); the relative epsilon
        # keeps readings on a decimal clock (0.1 s steps) on one side of every boundary
        tick = np.floor((time_s - first) / window_s + 0.5 + 1e-9)
        epoch_time = first + tick * window_s
    else:
        epoch_time = time_s
    has_device = DEVICE_COLUMN in readings.columns
    splits = group_by + ((DEVICE_COLUMN,) if has_device else ())
    keys = [pd.Series(epoch_time), pd.Series(tx_codes)] + [pd.Series(pd.factorize(readings[c])[0]) for c in splits]
    row, uniques = pd.MultiIndex.from_arrays(keys).factorize()
    n, m = len(uniques), len(anchor_ids)
    # epochs in time order, ties by the transmitter's first appearance, then by first appearance of the group
    utime = uniques.get_level_values(0).to_numpy(float)
    utx = uniques.get_level_values(1).to_numpy(int)
    order = np.lexsort((np.arange(n), utx, utime))
    rank = np.empty_like(order)
    rank[order] = np.arange(n)
    row = rank[row]
    rss_in = readings["rssi_dbm"].to_numpy(float)
    heard = np.isfinite(rss_in)
    flat = row * m + receivers
    counts = np.bincount(flat[heard], minlength=n * m).reshape(n, m)
    rss = np.full(n * m, np.nan)
    if windowed:
        grouped = pd.Series(rss_in[heard]).groupby(flat[heard])
        agg = getattr(grouped, aggregate)()
        rss[agg.index.to_numpy()] = agg.to_numpy()
        rss = rss.reshape(n, m)
        rss[counts < min_readings] = np.nan
    else:
        rss[flat] = rss_in
        rss = rss.reshape(n, m)
    truth = readings[["x_m", "y_m", "z_m", "heading_rad"]].to_numpy(float)
    if windowed:
        frame = pd.DataFrame({"x": truth[:, 0], "y": truth[:, 1], "z": truth[:, 2],
                              "c": np.cos(truth[:, 3]), "s": np.sin(truth[:, 3])})
        frame["h"] = truth[:, 3]
        grouped = frame.groupby(row)
        mean, low, high = grouped.mean(), grouped.min(), grouped.max()   # NaN left out
        at = mean.index.to_numpy()
        position = np.full((n, 3), np.nan)
        heading = np.full(n, np.nan)
        # a value constant within the epoch (a static tag, rows already epochs) is kept exactly, not averaged
        position[at] = np.where(low[["x", "y", "z"]] == high[["x", "y", "z"]], low[["x", "y", "z"]],
                                mean[["x", "y", "z"]])
        heading[at] = np.where(low["h"] == high["h"], low["h"],
                               np.arctan2(mean["s"].to_numpy(), mean["c"].to_numpy()))
    else:
        per_epoch = np.full((n, 4), np.nan)
        per_epoch[row] = truth
        # every row of an epoch must give the same truth: the same value on all of them, or none on all
        grouped = pd.DataFrame(truth).groupby(row)
        low, high, count = (grouped.min().to_numpy(), grouped.max().to_numpy(), grouped.count().to_numpy())
        size = grouped.size().to_numpy()[:, None]
        differ = np.full((n, 4), False)
        differ[grouped.min().index.to_numpy()] = (low != high) & (count > 0) | (count > 0) & (count < size)
        if differ.any():
            e = int(np.flatnonzero(differ.any(axis=1))[0])
            raise DataFormatError(f"epoch at {_seconds(utime[order[e]])} of transmitter "
                                  f"{_shown(tx_names[utx[order[e]]])} "
                                  "has different true positions or headings on its rows")
        position, heading = per_epoch[:, :3], per_epoch[:, 3]
    extra = {}
    reserved = set(READING_COLUMNS) | set(OPTIONAL_READING_COLUMNS) | {DEVICE_COLUMN}
    for name in [c for c in readings.columns if c not in reserved]:
        values = readings[name].reset_index(drop=True)
        if name not in group_by and (values.groupby(row).nunique(dropna=False) > 1).any():
            continue                                   # varies within an epoch: not an epoch's property
        kept = np.empty(n, dtype=object)
        kept[row[::-1]] = values.to_numpy(object)[::-1]
        extra[name] = kept
    tx = np.asarray(tx_names, dtype=object)[utx[order]]
    device = None
    if has_device:                                     # one device per epoch: the epochs are split by it
        device = np.empty(n, dtype=object)
        device[row[::-1]] = readings[DEVICE_COLUMN].astype(str).to_numpy(object)[::-1]
    return Epochs(utime[order], rss, position, heading, tx, anchor_ids, counts, extra, device)


def _count(value: float) -> str:
    """A count for a message: every digit up to 1e15 (``10,000,000,002``), beyond that 3 significant digits
    (``1e+301``; a bad timestamp can ask for 300-digit tick counts)."""
    return f"{value:,.0f}" if abs(value) < 1e15 else f"{value:.3g}"


def regular_epochs(ep: Epochs, dt_s: float, *, tolerance_s: float | None = None,
                   max_epochs: int = MAX_REGULAR_EPOCHS) -> tuple[Epochs, np.ndarray]:
    """Put one transmitter's epochs on a regular clock of period ``dt_s`` for the filters, which step at a fixed
    rate: each epoch goes to the nearest tick (within ``tolerance_s``, default ``dt_s / 2``) and a tick without an
    epoch is all NaN (nothing heard: the filters predict through it, by the library's rule). Returns the regular
    epochs and, per original epoch, its tick index. No epochs give no ticks (as :func:`epochs` of no readings).

    The clock has ``round((t_last - t_first) / dt_s) + 1`` ticks; more than ``max_epochs`` (default
    :data:`MAX_REGULAR_EPOCHS`, 1,000,000: 28 h at 0.1 s) is refused before anything is allocated, naming the
    largest gap, since it is nearly always a clock jump (one bad timestamp). Split the recording at the gap
    (``ep.select(ep.time_s < t)``, ``ep.select(ep.time_s >= t)``) and regularise each part, or raise
    ``max_epochs`` for a recording that really is that long."""
    if not (isinstance(dt_s, (int, float)) and math.isfinite(dt_s) and dt_s > 0):
        raise ParameterError(f"dt_s must be a positive finite number of seconds, got {dt_s!r}")
    if not (isinstance(max_epochs, (int, np.integer)) and not isinstance(max_epochs, bool) and max_epochs >= 1):
        raise ParameterError(f"max_epochs must be a positive integer, got {max_epochs!r}")
    tol = 0.5 * dt_s if tolerance_s is None else tolerance_s
    if not (isinstance(tol, (int, float)) and math.isfinite(tol) and tol >= 0):
        raise ParameterError(f"tolerance_s must be a finite number of seconds >= 0, got {tolerance_s!r}")
    if len(ep) == 0:
        return ep.select(np.zeros(0, dtype=int)), np.zeros(0, dtype=int)
    if len(set(ep.transmitter.tolist())) > 1:
        raise ParameterError("regular_epochs takes one transmitter's epochs; select them first")
    time_s = np.asarray(ep.time_s, dtype=float)
    if not np.isfinite(time_s).all():
        i = int(np.flatnonzero(~np.isfinite(time_s))[0])
        raise ParameterError(f"epoch {i} has time {time_s[i]!r} s; times must be finite")
    t0 = time_s[0]
    tick_f = np.rint((time_s - t0) / dt_s)        # float: a huge tick count must not overflow an int cast
    n_needed = float(tick_f.max()) + 1.0
    if n_needed > max_epochs:
        gaps = np.diff(time_s)
        i = int(np.argmax(gaps))
        gap, cut = float(gaps[i]), float(time_s[i + 1])
        raise ParameterError(
            f"regular_epochs: the {dt_s:g} s clock would need {_count(n_needed)} epochs, more than max_epochs = "
            f"{max_epochs:,}; the largest gap is {gap!r} s, between the epochs at {_seconds(time_s[i])} and "
            f"{_seconds(time_s[i + 1])} (epochs {i} and {i + 1} of {len(time_s)}), {_count(gap / dt_s)} empty ticks. "
            f"A clock jump? Then split the recording there (ep.select(ep.time_s < {cut!r}) and "
            f"ep.select(ep.time_s >= {cut!r})) and put each part on the clock, or raise max_epochs if "
            "the recording really is that long")
    tick = tick_f.astype(int)
    off = np.abs(time_s - t0 - tick * dt_s)
    if np.any(off > tol + 1e-12 * dt_s):
        i = int(np.argmax(off))
        raise ParameterError(f"epoch at {time_s[i]:g} s is {off[i]:g} s off the {dt_s:g} s clock "
                             f"(tolerance {tol:g} s)")
    if np.any(np.diff(tick) <= 0):
        i = int(np.flatnonzero(np.diff(tick) <= 0)[0])
        raise ParameterError(f"epochs at {_seconds(time_s[i])} and {_seconds(time_s[i + 1])} fall on the same "
                             f"{dt_s:g} s tick or are out of time order")
    n = int(tick[-1]) + 1
    m = ep.rss_dbm.shape[1]

    def spread(values, shape):
        out = np.full(shape, np.nan)
        out[tick] = values
        return out

    tx = np.full(n, ep.transmitter[0], dtype=object)
    counts = None
    if ep.n_readings is not None:
        counts = np.zeros((n, m), dtype=ep.n_readings.dtype)
        counts[tick] = ep.n_readings
    extra = {}
    for name, values in ep.extra.items():
        extra[name] = np.full(n, None, dtype=object)
        extra[name][tick] = values
    reg = Epochs(t0 + np.arange(n) * dt_s, spread(ep.rss_dbm, (n, m)), spread(ep.position_m, (n, 3)),
                 spread(ep.heading_rad, (n,)), tx, ep.anchor_ids, counts, extra,
                 np.full(n, ep.device[0], dtype=object))
    return reg, tick


def scan_interval_s(ep: Epochs, *, name: str | None = None) -> float:
    """The clock of native scans (rows already epochs, ``window_s = 0``): the median spacing (s) of the epoch times
    of one transmitter, ``median(diff(sorted(time_s)))``, the filters' time step for such a recording. The median,
    not the mean: a scanner that pauses (a phone's scan throttling, a logger's gap) leaves a few long spacings that
    would set a clock slower than nearly every scan.

    ``name`` names the recording in messages. Fewer than 2 epochs, epochs of several transmitters or devices, times
    that are not finite, or a median spacing of 0 (most epochs at one time) are refused (:class:`ParameterError`)."""
    what = f"recording {name!r}" if name else "the epochs"
    if not isinstance(ep, Epochs):
        raise ParameterError(f"scan_interval_s takes Epochs, got {type(ep).__name__}")
    time_s = np.asarray(ep.time_s, dtype=float)
    if len(time_s) < 2:
        raise ParameterError(f"{what}: {len(time_s)} epoch(s); the scan interval is the median spacing of at least "
                             "2 epoch times")
    senders = set(ep.transmitter.tolist())
    if len(senders) > 1 or len(set(ep.device.tolist())) > 1:
        raise ParameterError(f"{what}: epochs of {len(senders)} transmitter(s) and {len(set(ep.device.tolist()))} "
                             "device(s); the scan interval is that of one transmitter's scans (select them first)")
    if not np.isfinite(time_s).all():
        i = int(np.flatnonzero(~np.isfinite(time_s))[0])
        raise ParameterError(f"{what}: epoch {i} has time {time_s[i]!r} s; times must be finite")
    spacing = float(np.median(np.diff(np.sort(time_s))))
    if not spacing > 0:
        raise ParameterError(f"{what}: the median spacing of its {len(time_s)} epoch times is 0 s (most epochs share "
                             f"one time, {_seconds(np.median(time_s))}): no scan clock; are the times in the unit "
                             "[units] time says?")
    return spacing
