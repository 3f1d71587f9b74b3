"""Range readings (RTT / ToA): a file of their own per recording, read, checked and aligned with its RSS epochs.

A recording's ``ranges = "FILE"`` (manifest, :mod:`locbook.data.dataset`) names a CSV beside its readings file:

================ ======== ======================================================================================
column           required meaning
================ ======== ======================================================================================
``time_s``       yes      time of the range (s), on the readings file's clock ([units] time applies; a time unit
                          other than seconds is shifted by the readings file's first time, so both stay aligned)
``transmitter``  yes      the moving tag, as in the readings (a transmitter without readings is refused)
``receiver``     yes      the anchor (an ``id`` of the anchors file), as for RSS (link direction rule)
``range_m``      yes      the measured distance tag-anchor (m; [units] length applies); empty or ``NaN`` = not
                          measured (NaN)
``range_std_m``  no       the ranging device's reported standard deviation of that range (m), > 0 wherever a range
                          is given
================ ======== ======================================================================================

Other columns are kept (a point column or ``device`` column, when given, decides which epoch a range belongs to
where a window holds two epochs of one transmitter). Refused, naming file, line and column (one line,
:class:`~locbook.data.measured.DataFormatError`): a negative range, a non-finite value (``inf``), a range of
:data:`~locbook.data.measured.MAX_COORDINATE_M` or more, a receiver that is not an anchor, a std of 0 or less or one
missing where a range is given, a repeated (time, transmitter, receiver), and a time that is not seconds (as in the
readings). The file is read by the exact reader (:data:`~locbook.data.measured.MAX_EXACT_READ_BYTES`, 64 MiB, about
2 x 10^6 ranges).

**Alignment** (:func:`align_ranges`): the ranges go to the recording's epochs by the same window rule as its RSS
readings (:func:`locbook.data.measured.epochs`): with ``window_s > 0`` a range of a transmitter goes to the window of
the nearest tick of the clock started at that transmitter's first RSS reading, ``[t0 + (k - 1/2) w, t0 + (k + 1/2)
w)``, i.e. the same ticks; with ``window_s = 0`` (native scans) to the epoch at the same time. An epoch's range of an
anchor is the mean of the window's ranges of that anchor (every range counts; ``min_readings`` is an RSS rule and
does not apply), and its reported std is that of the mean of independent ranges,
``sqrt(mean(std_i^2) / n)`` over the same ranges. An epoch without a range of an anchor has NaN (not measured). A
range that falls on no epoch (before the transmitter's first reading, in a window with no RSS row, or at a time no
scan has) is not used and counted (the data set's notes say how many).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from .csvfile import DataFormatError, numeric_column, read_text_table, seconds_text, shown, shown_names
from .epoching import Epochs
from .long_format import DEVICE_COLUMN, check_receivers, id_column, shifted_seconds

__all__ = ["RANGE_COLUMNS", "RANGE_STD_COLUMN", "read_ranges", "validate_ranges", "align_ranges", "RangeAlignment"]

RANGE_COLUMNS = ("time_s", "transmitter", "receiver", "range_m")
#: the optional column of the reported standard deviation of each range (m)
RANGE_STD_COLUMN = "range_std_m"


def validate_ranges(table: pd.DataFrame, *, source: str, lines=None, anchor_ids, transmitters=None,
                    time_scale: float = 1.0, length_scale: float = 1.0, time_origin_raw=None) -> pd.DataFrame:
    """Check a ranges table (module docstring) and return it typed: ``time_s``, ``range_m`` (NaN = not measured)
    and ``range_std_m`` (when given) as floats in s and m, ids as text, other columns kept. ``transmitters``: the
    transmitter ids of the recording's readings (a range of another one is refused); ``time_scale`` and
    ``length_scale``: the data set's [units]; ``time_origin_raw``: the readings file's first time as written
    (:func:`locbook.data.measured.file_time_origin`)."""
    lines = np.arange(len(table)) + 2 if lines is None else np.asarray(lines)
    missing = [c for c in RANGE_COLUMNS if c not in table.columns]
    if missing:
        raise DataFormatError(f"{source}: missing column(s) {missing}; it has {shown_names(table.columns)} "
                              f"(required: {list(RANGE_COLUMNS)})")
    text = table.reset_index(drop=True)
    out = pd.DataFrame(index=text.index)
    out["time_s"] = shifted_seconds(text, source, lines, time_scale, time_origin_raw)
    for col in ("transmitter", "receiver"):
        out[col] = id_column(text, col, source, lines).astype(str).to_numpy(object)
    check_receivers(out, anchor_ids, source, lines)
    if transmitters is not None:
        senders = {str(t) for t in transmitters}
        other = ~out["transmitter"].isin(senders).to_numpy()
        if other.any():
            i = int(np.flatnonzero(other)[0])
            raise DataFormatError(f"{source}, line {lines[i]}, column 'transmitter': "
                                  f"{shown(out['transmitter'].iloc[i])}"
                                  f" has no readings in the recording's readings file (its transmitters: "
                                  f"{shown_names(sorted(senders))}); ranges are aligned with a transmitter's RSS "
                                  "epochs")
    rng = numeric_column(text, "range_m", source, lines, missing_ok=True, coordinate=True) * length_scale
    negative = rng < 0                                          # NaN compares False
    if negative.any():
        i = int(np.flatnonzero(negative)[0])
        raise DataFormatError(f"{source}, line {lines[i]}, column 'range_m': "
                              f"{shown(str(text['range_m'].iloc[i]).strip())}"
                              f" is negative ({int(negative.sum())} such value(s)); a range is a distance (>= 0 m): "
                              "a device that reports negative ranges near an anchor needs them clipped, or left empty "
                              "(not measured)")
    out["range_m"] = rng
    if RANGE_STD_COLUMN in text.columns:
        std = numeric_column(text, RANGE_STD_COLUMN, source, lines, missing_ok=True, coordinate=True) * length_scale
        bad = np.isfinite(std) & ~(std > 0)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise DataFormatError(f"{source}, line {lines[i]}, column {RANGE_STD_COLUMN!r}: "
                                  f"{shown(str(text[RANGE_STD_COLUMN].iloc[i]).strip())} is not a standard deviation "
                                  f"(> 0 m; {int(bad.sum())} such value(s))")
        absent = np.isfinite(rng) & np.isnan(std)
        if absent.any():
            i = int(np.flatnonzero(absent)[0])
            raise DataFormatError(f"{source}, line {lines[i]}, column {RANGE_STD_COLUMN!r}: value is missing while "
                                  f"range_m is given ({int(absent.sum())} such row(s)); a {RANGE_STD_COLUMN} column "
                                  "gives the std of every range (drop the column to have sigma fitted on the "
                                  "calibration recordings)")
        out[RANGE_STD_COLUMN] = std
    key = out[["time_s", "transmitter", "receiver"]]
    dup = key.duplicated(keep="first").to_numpy()
    if dup.any():
        i = int(np.flatnonzero(dup)[0])
        first = int(np.flatnonzero((key == key.iloc[i]).all(axis=1).to_numpy())[0])
        raise DataFormatError(f"{source}, line {lines[i]}, columns 'time_s','transmitter','receiver': the range "
                              f"({seconds_text(out['time_s'].iloc[i])}, {shown(out['transmitter'].iloc[i])}, "
                              f"{shown(out['receiver'].iloc[i])}) repeats line {lines[first]}")
    for col in [c for c in text.columns if c not in out.columns]:
        out[col] = text[col].astype(object).where(text[col].notna(), "").astype(str).str.strip().to_numpy(object)
    out.attrs["lines"] = lines
    return out


def read_ranges(path, *, anchor_ids, transmitters=None, time_scale: float = 1.0, length_scale: float = 1.0,
                time_origin_raw=None) -> pd.DataFrame:
    """Read and check a ranges CSV (module docstring; options: :func:`validate_ranges`)."""
    path = Path(path)
    table, lines = read_text_table(path, RANGE_COLUMNS, "ranges")
    return validate_ranges(table, source=f"ranges file {path}", lines=lines, anchor_ids=anchor_ids,
                           transmitters=transmitters, time_scale=time_scale, length_scale=length_scale,
                           time_origin_raw=time_origin_raw)


class RangeAlignment(tuple):
    """``(range_m (E, m), range_std_m (E, m) or None)`` on a recording's epochs (:func:`align_ranges`), with
    ``unaligned``: how many ranges fell on no epoch, ``n_ranges (E, m)``: how many ranges made each entry, and
    ``ignored``: how many were of an anchor the epochs do not hold (a placeholder, an anchor outside a subset)."""

    def __new__(cls, range_m, range_std_m, unaligned: int, n_ranges, ignored: int = 0):
        out = super().__new__(cls, (range_m, range_std_m))
        out.unaligned, out.n_ranges, out.ignored = int(unaligned), n_ranges, int(ignored)
        return out


def align_ranges(ep: Epochs, readings: pd.DataFrame, ranges: pd.DataFrame, *, window_s: float | None,
                 group_by=(), source: str = "ranges") -> RangeAlignment:
    """The ranges on the rows of ``ep``, the epochs of ``readings`` by the window rule ``window_s`` (None or 0:
    native scans) and ``group_by`` (the point column), as :func:`locbook.data.measured.epochs` made them (module
    docstring, "Alignment"). A range whose window holds two epochs of its transmitter (two points, two devices) goes
    to the one whose point (device) the ranges file names; a file without that column is refused, naming the line.
    Returns :class:`RangeAlignment`."""
    anchor_ids = tuple(ep.anchor_ids)
    n, m = len(ep), len(anchor_ids)
    col = {a: j for j, a in enumerate(anchor_ids)}
    time_s = ranges["time_s"].to_numpy(float)
    tx = ranges["transmitter"].astype(str).to_numpy(object)
    if window_s:
        first = pd.Series(readings["time_s"].to_numpy(float)).groupby(
            readings["transmitter"].astype(str).to_numpy(object)).min()
        t0 = first.reindex(tx).to_numpy(float)           # every transmitter has readings (validate_ranges)
        # the ticks of measured.epochs, by the same arithmetic (the same floats): a window's range meets its epoch
        tick = np.floor((time_s - t0) / window_s + 0.5 + 1e-9)
        epoch_time = t0 + tick * window_s
        on_clock = tick >= 0
    else:
        epoch_time, on_clock = time_s, np.ones(len(time_s), bool)
    splits = [c for c in (*group_by, DEVICE_COLUMN) if c in ep.extra or (c == DEVICE_COLUMN and c in readings)]
    keys = pd.DataFrame({"t": ep.time_s, "tx": np.asarray(ep.transmitter, dtype=object).astype(str)})
    ambiguous = keys.duplicated(keep=False).to_numpy()
    use = []
    if ambiguous.any():
        for c in splits:
            values = ep.device if c == DEVICE_COLUMN else ep.extra[c]
            if c in ranges.columns:
                keys[c] = np.asarray(values, dtype=object).astype(str)
                use.append(c)
    keys["row"] = np.arange(n)
    left = pd.DataFrame({"t": epoch_time, "tx": tx})
    for c in use:
        left[c] = ranges[c].astype(str).to_numpy(object)
    on = ["t", "tx", *use]
    unique = keys.drop_duplicates(on, keep=False)
    doubled = keys[keys.duplicated(on, keep=False)].drop_duplicates(on)
    row = left.merge(unique[on + ["row"]], on=on, how="left")["row"].to_numpy(float)
    if len(doubled):
        hit = left.merge(doubled[on].assign(hit=True), on=on, how="left")["hit"].eq(True).to_numpy()
        if hit.any():
            i = int(np.flatnonzero(hit)[0])
            lines = ranges.attrs.get("lines", np.arange(len(ranges)) + 2)
            missing = [c for c in splits if c not in use] or list(group_by) or [DEVICE_COLUMN]
            raise DataFormatError(f"{source}, line {lines[i]}: the range at {seconds_text(time_s[i])} of transmitter "
                                  f"{shown(tx[i])} falls in a window holding several epochs of it (several points or "
                                  f"devices); give the ranges file the column(s) {shown_names(missing)} to say which")
    receivers = ranges["receiver"].map(col).to_numpy(float)
    value = ranges["range_m"].to_numpy(float)
    # a range of an anchor the epochs do not hold (a placeholder, used = false; an anchor left out of a subset) is
    # ignored and counted, as that anchor's RSS readings are
    anchored = np.isfinite(receivers)
    ignored = int((~anchored & np.isfinite(value)).sum())
    ok = np.isfinite(row) & on_clock & np.isfinite(value) & anchored
    unaligned = int((~(np.isfinite(row) & on_clock) & np.isfinite(value) & anchored).sum())
    flat = row[ok].astype(np.int64) * m + receivers[ok].astype(np.int64)
    counts = np.bincount(flat, minlength=n * m).astype(float)
    total = np.bincount(flat, weights=value[ok], minlength=n * m)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(counts > 0, total / np.where(counts > 0, counts, 1.0), np.nan).reshape(n, m)
        std = None
        if RANGE_STD_COLUMN in ranges.columns:
            var = np.bincount(flat, weights=np.square(ranges[RANGE_STD_COLUMN].to_numpy(float)[ok]), minlength=n * m)
            # the std of the mean of n independent ranges: sqrt(mean(std_i^2) / n) = sqrt(sum std_i^2) / n
            std = np.where(counts > 0, np.sqrt(var) / np.where(counts > 0, counts, 1.0), np.nan).reshape(n, m)
    return RangeAlignment(mean, std, unaligned, counts.reshape(n, m).astype(int), ignored)
