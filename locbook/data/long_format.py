"""The long format of readings (:mod:`locbook.data.measured` documents it): its columns, the rules a readings
table obeys (:func:`validate_readings`), and the time rule a recording's other files share with its readings
(:func:`file_time_origin`, :func:`shifted_seconds`)."""
from __future__ import annotations

import warnings
from datetime import datetime, timezone

import numpy as np
import pandas as pd

from ..errors import ParameterError
from .csvfile import DataFormatError, file_lines, numeric_column, seconds_text, shown, shown_names

__all__ = ["READING_COLUMNS", "OPTIONAL_READING_COLUMNS", "DEVICE_COLUMN", "LINK_DIRECTION_RULE", "RSSI_RANGE_DBM",
           "RSSI_LIMITS_DBM", "MAX_TIME_S", "MeasuredDataWarning", "reading_options", "check_time_unit",
           "file_time_origin", "shifted_seconds", "validate_readings", "id_column", "check_receivers",
           "link_direction_hint", "text_ids"]

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


class MeasuredDataWarning(UserWarning):
    """Measured data that loads but looks wrong (e.g. readings at or above 0 dBm with no sentinel declared)."""



def _is_real(value) -> bool:
    """A real number that is not a bool (``True`` is 1 to numpy, never a reading) nor text."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def reading_options(invalid_values_dbm, valid_range_dbm):
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
                             f"{shown(invalid_values_dbm)}")
    sentinels = np.asarray(values, dtype=float).reshape(-1)
    if not np.isfinite(sentinels).all():
        raise ParameterError(f"invalid_values_dbm must hold finite numbers (dBm), got {shown(invalid_values_dbm)}")
    rng = RSSI_RANGE_DBM if valid_range_dbm is None else valid_range_dbm
    if isinstance(rng, np.ndarray):
        rng = rng.tolist()
    if not isinstance(rng, (list, tuple)) or len(rng) != 2 or not all(_is_real(v) for v in rng):
        raise ParameterError(f"valid_range_dbm must be a pair (low, high) of numbers (dBm), got {shown(rng)}")
    low, high = (float(v) for v in rng)
    lo_limit, hi_limit = RSSI_LIMITS_DBM
    if not (lo_limit <= low < high <= hi_limit):      # NaN and infinities fail too
        raise ParameterError(f"valid_range_dbm must be (low, high) with {lo_limit:g} <= low < high <= {hi_limit:g} "
                             f"(dBm, RSSI_LIMITS_DBM: no receiver reports outside), got {shown(rng)}")
    return sentinels, (low, high)


def check_time_unit(time_s: np.ndarray, raw: pd.Series, source: str, lines) -> None:
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
    raise DataFormatError(f"{source}, line {lines[i]}, column 'time_s': {shown(str(raw.iloc[i]).strip())} is not a "
                          "time in "
                          f"seconds ({abs(t) / 3.15576e7:.3g} years; time_s is at most {MAX_TIME_S:.0e} s in "
                          f"magnitude){guess} ({int(huge.sum())} such value(s) in the column)")


def file_time_origin(raw_time):
    """The origin a readings file's times are shifted by when ``[units] time`` is not seconds (the loader shifts the
    readings by it, see :func:`shifted_seconds`), from its time column as written: the smallest time, an ``int`` where
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
        t = numeric_column(table, "time_s", source, lines, missing_ok=False)
        check_time_unit(t, raw, source, lines)
        return t * time_scale
    text = raw.astype(object).where(raw.notna(), "").astype(str).str.strip()
    if isinstance(origin, int) and len(text) and text.str.fullmatch(r"[+-]?\d{1,19}").all():
        try:
            return (text.astype(np.int64).to_numpy() - origin).astype(float) * time_scale
        except (OverflowError, ValueError):
            pass
    return (numeric_column(table, "time_s", source, lines, missing_ok=False) - float(origin)) * time_scale


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
    sentinels, (low, high) = reading_options(invalid_values_dbm, valid_range_dbm)
    lines = file_lines(len(table)) if lines is None else np.asarray(lines)
    if lines.shape != (len(table),):
        raise ParameterError(f"lines must give one line number per row of the table ({len(table)}), "
                             f"got shape {lines.shape}")
    missing_cols = [c for c in READING_COLUMNS if c not in table.columns]
    if missing_cols:
        raise DataFormatError(f"{source}: missing column(s) {missing_cols}; it has {list(table.columns)} "
                              f"(required: {list(READING_COLUMNS)})")
    time_s = numeric_column(table, "time_s", source, lines, missing_ok=False)
    check_time_unit(time_s, table["time_s"], source, lines)
    if sort:
        order = np.argsort(time_s, kind="stable")
        table, lines, time_s = table.iloc[order], lines[order], time_s[order]
    text = table.reset_index(drop=True)
    out = pd.DataFrame(index=text.index)
    out["time_s"] = time_s
    for col in ("transmitter", "receiver"):
        out[col] = id_column(text, col, source, lines).array
    rssi = numeric_column(text, "rssi_dbm", source, lines, missing_ok=True)
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
        out[col] = (numeric_column(text, col, source, lines, missing_ok=True, coordinate=col != "heading_rad")
                    if col in text.columns
                    else np.full(len(text), np.nan))
    if DEVICE_COLUMN in text.columns:
        devices = text_ids(text[DEVICE_COLUMN])
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
        check_receivers(out, anchor_ids, source, lines)
    key = out[["time_s", "transmitter", "receiver"]]
    dup = key.duplicated(keep="first").to_numpy()
    if dup.any():
        i = int(np.flatnonzero(dup)[0])
        first = int(np.flatnonzero((key == key.iloc[i]).all(axis=1).to_numpy())[0])
        written = [str(text["time_s"].iloc[k]).strip() for k in (first, i)]
        note = ("" if written[0] == written[1] else
                f" (the source has times {shown(written[0])} and {shown(written[1])}: equal as 64-bit floats, which "
                "hold about "
                "16 significant digits; give times from a nearer origin, e.g. seconds since the first reading)")
        raise DataFormatError(f"{source}, line {lines[i]}, columns 'time_s','transmitter','receiver': the reading "
                              f"({seconds_text(out['time_s'].iloc[i])}, {shown(out['transmitter'].iloc[i])}, "
                              f"{shown(out['receiver'].iloc[i])}) repeats line {lines[first]}{note}")
    # time non-decreasing within each transmitter: group the rows by transmitter (stable), compare neighbours
    codes = pd.factorize(out["transmitter"])[0]
    by_tx = np.argsort(codes, kind="stable")
    back = (np.diff(time_s[by_tx]) < 0) & (np.diff(codes[by_tx]) == 0)
    if back.any():
        k = np.flatnonzero(back)
        i = int(by_tx[k + 1].min())                                        # the first such row of the source
        prev = int(by_tx[k[by_tx[k + 1] == i][0]])
        raise DataFormatError(f"{source}, line {lines[i]}, column 'time_s': time goes back for transmitter "
                              f"{shown(out['transmitter'].iloc[i])} ({seconds_text(time_s[i])} after "
                              f"{seconds_text(time_s[prev])} "
                              f"on line {lines[prev]}); sort the file by time, or read it with sort=True (rows "
                              "reordered by time, stably)")
    extra = [c for c in text.columns if c not in out.columns]
    for col in extra:
        out[col] = text[col].array
    return out


def id_column(table: pd.DataFrame, column: str, source: str, lines) -> pd.Series:
    """A column of ids (:func:`text_ids`), a row without one refused naming its line: ids are text, so "NA", "N/A" or
    "nan" are ids, and only an empty field is no id."""
    ids = text_ids(table[column])
    empty = ids.isna().to_numpy()
    if empty.any():
        i = int(np.flatnonzero(empty)[0])
        raise DataFormatError(f"{source}, line {lines[i]}, column {column!r}: the id is empty")
    return ids


def check_receivers(table: pd.DataFrame, anchor_ids, source: str, lines) -> None:
    """Refuse a row whose ``receiver`` is not an anchor id (the readings' and the ranges' one rule), naming its
    line, with the link-direction hint where the transmitters are the anchors."""
    known = {str(a) for a in anchor_ids}
    unknown = ~table["receiver"].isin(known).to_numpy()
    if unknown.any():
        i = int(np.flatnonzero(unknown)[0])
        raise DataFormatError(f"{source}, line {lines[i]}, column 'receiver': {shown(table['receiver'].iloc[i])} is "
                              f"not an anchor id (the anchors are {shown_names(sorted(known))})"
                              f"{link_direction_hint(table['transmitter'], known)}")


def link_direction_hint(transmitters: pd.Series, anchor_ids) -> str:
    """The end of the message for a receiver that is not an anchor: the link-direction rule, and whether the
    transmitter column holds anchor ids (the two columns swapped: a phone log of the beacons it heard)."""
    known = {str(a) for a in anchor_ids}
    sent = pd.Series(pd.Series(transmitters).unique()).astype(str)
    swapped = sent[sent.isin(known)]
    if len(swapped):
        return (f"; the transmitter column holds anchor ids ({shown_names(swapped.tolist(), limit=4)}): the two "
                f"columns are swapped? {LINK_DIRECTION_RULE[0].upper()}{LINK_DIRECTION_RULE[1:]}")
    return f"; {LINK_DIRECTION_RULE}"


def text_ids(column: pd.Series) -> pd.Series:
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

