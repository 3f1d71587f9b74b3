"""Measured RSSI data: one documented long format, its validation, and the adapters that read public data sets.

Bringing a new data set into locbook is a file conversion, not code. Three files describe it:

**Readings** (CSV, one row per received packet or per averaged epoch; the *long format*)

============== ======== ========================================================================================
column         required meaning
============== ======== ========================================================================================
``time_s``     yes      time of the reading in seconds (any origin); non-decreasing within a transmitter
``transmitter``yes      id of the device that sent the packet (the tag), any text
``receiver``   yes      id of the device that measured the RSSI: an ``id`` of the anchors file
``rssi_dbm``   yes      received power in dBm; empty or ``NaN`` = the receiver heard no packet (not heard)
``x_m``        no       true position of the transmitter (m), where known; empty = unknown
``y_m``        no       (``x_m`` and ``y_m`` are given together or not at all, row by row)
``z_m``        no       true height of the transmitter (m), where known
``heading_rad``no       true heading of the transmitter (rad), where known
============== ======== ========================================================================================

Other columns are kept and ignored. A reading must lie in ``[-150, 20]`` dBm (a received power outside it is a
unit or sign error, never a reading); infinite values are errors anywhere. The same (time, transmitter,
receiver) may appear once only.

**Anchors** (CSV): ``id, x, y, z`` in metres (``z`` is the anchor height; required, so that ranges are
three-dimensional). Ids are unique; coordinates finite.

**Floor outline** (CSV, optional): ``x, y`` vertices of a closed polygon in metres (at least 3 vertices, the
closing vertex may repeat the first).

Every rule failure raises :class:`DataFormatError` naming the file, the line (as a text editor counts it, the
header being line 1) and the column. :func:`epochs` turns a validated recording into the arrays the estimators
take: one row per (time, transmitter) epoch, one column per anchor, NaN where the anchor heard nothing
(the library's one rule for missing readings, README).

Adapter: :func:`kolakowski2021` reads the BLE data set of Kolakowski (2021) shipped in
``locbook/data/measured/kolakowski2021`` (CC BY 4.0; attribution in :data:`KOLAKOWSKI2021_ATTRIBUTION` and that
folder's README.md and LICENSE.md) into this format.
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import LocbookError

__all__ = [
    "DataFormatError", "READING_COLUMNS", "OPTIONAL_READING_COLUMNS", "RSSI_RANGE_DBM", "MeasuredData", "Epochs",
    "read_readings", "read_anchors", "read_outline", "read_path_segments", "validate_readings", "epochs",
    "regular_epochs", "kolakowski2021", "KOLAKOWSKI2021_ATTRIBUTION", "KOLAKOWSKI2021_TAG_HEIGHT_M",
    "measured_data_dir",
]

READING_COLUMNS = ("time_s", "transmitter", "receiver", "rssi_dbm")
OPTIONAL_READING_COLUMNS = ("x_m", "y_m", "z_m", "heading_rad")
#: a received power outside this interval (dBm) is a unit or sign error, never a reading
RSSI_RANGE_DBM = (-150.0, 20.0)
_MISSING_TEXT = {"", "nan", "NaN", "NAN", "NA", "N/A"}

KOLAKOWSKI2021_ATTRIBUTION = (
    "Measured data: M. Kolakowski, \"Automated Calibration of RSS Fingerprinting Based Systems Using a Mobile Robot "
    "and Machine Learning\", Sensors 21, 6270 (2021), doi:10.3390/s21186270; data set \"BLE RSS dataset for "
    "fingerprinting radio map calibration\" (github.com/marckolak/ble-rss-fingerprints-calib2021, commit 0a69aaa, "
    "Zenodo doi:10.5281/zenodo.5457591), licensed CC BY 4.0 (creativecommons.org/licenses/by/4.0). Files used "
    "unchanged; locbook converts them to its long format in memory.")
#: The tag's height in the data set's README ("about 1.3 m above the floor"); the data carry no per-sample height.
KOLAKOWSKI2021_TAG_HEIGHT_M = 1.3


class DataFormatError(LocbookError, ValueError):
    """A measured-data file that breaks a rule of the long format; the message names file, line and column."""


def measured_data_dir(name: str) -> Path:
    """The folder of a data set shipped with locbook (``locbook/data/measured/<name>``)."""
    path = Path(__file__).with_name("measured") / name
    if not path.is_dir():
        shipped = sorted(p.name for p in Path(__file__).with_name("measured").iterdir() if p.is_dir())
        raise ValueError(f"no measured data set {name!r} is shipped with locbook; shipped: {shipped}")
    return path


# -- reading and checking CSV text ---------------------------------------------------------------------------
def _read_text_table(path, required: tuple[str, ...], what: str) -> pd.DataFrame:
    """The CSV as text (nothing converted yet), with every required column present."""
    path = Path(path)
    if not path.is_file():
        raise DataFormatError(f"{what} file {path} does not exist")
    try:
        table = pd.read_csv(path, dtype=str, keep_default_na=False, skipinitialspace=True)
    except (pd.errors.ParserError, UnicodeDecodeError, pd.errors.EmptyDataError) as exc:
        raise DataFormatError(f"{what} file {path} is not a readable CSV table: {exc}") from None
    with open(path, newline="", encoding="utf-8", errors="replace") as fh:
        header = [c.strip() for c in next(csv.reader(fh), [])]
    duplicated = sorted({c for c in header if header.count(c) > 1})
    if duplicated:
        raise DataFormatError(f"{what} file {path}: column(s) {duplicated} appear more than once in the header")
    table.columns = [str(c).strip() for c in table.columns]
    missing = [c for c in required if c not in table.columns]
    if missing:
        raise DataFormatError(f"{what} file {path}: missing column(s) {missing}; the header has {list(table.columns)} "
                              f"(required: {list(required)})")
    return table


def _numeric(table: pd.DataFrame, column: str, source: str, lines, *, missing_ok: bool) -> np.ndarray:
    """A text column as floats; empty / NaN text is missing (allowed only where ``missing_ok``); anything else
    that is not a finite number is an error naming the line."""
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
        raise DataFormatError(f"{source}, line {lines[i]}, column {column!r}: {table[column].iloc[i]!r} is not a finite "
                              f"number ({int(bad.sum())} such value(s) in the column)")
    if missing.any() and not missing_ok:
        i = int(np.flatnonzero(missing)[0])
        raise DataFormatError(f"{source}, line {lines[i]}, column {column!r}: value is missing ({int(missing.sum())} "
                              "missing value(s) in the column; it must be given on every row)")
    return values


def _file_lines(n_rows: int) -> np.ndarray:
    return np.arange(n_rows) + 2            # the header is line 1


# -- the long format ----------------------------------------------------------------------------------------
def validate_readings(table: pd.DataFrame, *, source: str, lines=None, anchor_ids=None) -> pd.DataFrame:
    """Check a readings table of the long format (module docstring) and return it typed: ``time_s``,
    ``rssi_dbm`` and the optional position columns as floats (NaN = missing), ids as text.

    ``table`` holds text or numbers; ``source`` names it in messages and ``lines`` gives each row's line in that
    source (default: row ``i`` is line ``i + 2``). With ``anchor_ids`` every receiver must be one of them."""
    lines = _file_lines(len(table)) if lines is None else np.asarray(lines)
    missing_cols = [c for c in READING_COLUMNS if c not in table.columns]
    if missing_cols:
        raise DataFormatError(f"{source}: missing column(s) {missing_cols}; it has {list(table.columns)} "
                              f"(required: {list(READING_COLUMNS)})")
    text = table
    out = pd.DataFrame(index=table.index)
    out["time_s"] = _numeric(text, "time_s", source, lines, missing_ok=False)
    for col in ("transmitter", "receiver"):
        ids = text[col].astype(object).where(text[col].notna(), "").astype(str).str.strip()
        empty = ids.isin(_MISSING_TEXT).to_numpy()
        if empty.any():
            i = int(np.flatnonzero(empty)[0])
            raise DataFormatError(f"{source}, line {lines[i]}, column {col!r}: the id is empty")
        out[col] = ids.to_numpy()
    rssi = _numeric(text, "rssi_dbm", source, lines, missing_ok=True)
    low, high = RSSI_RANGE_DBM
    outside = np.isfinite(rssi) & ((rssi < low) | (rssi > high))
    if outside.any():
        i = int(np.flatnonzero(outside)[0])
        raise DataFormatError(f"{source}, line {lines[i]}, column 'rssi_dbm': {rssi[i]:g} dBm is outside "
                              f"[{low:g}, {high:g}] dBm (a unit or sign error, not a reading; empty = not heard)")
    out["rssi_dbm"] = rssi
    for col in OPTIONAL_READING_COLUMNS:
        out[col] = (_numeric(text, col, source, lines, missing_ok=True) if col in table.columns
                    else np.full(len(table), np.nan))
    half = np.isnan(out["x_m"].to_numpy()) != np.isnan(out["y_m"].to_numpy())
    if half.any():
        i = int(np.flatnonzero(half)[0])
        given, absent = ("x_m", "y_m") if np.isfinite(out["x_m"].iloc[i]) else ("y_m", "x_m")
        raise DataFormatError(f"{source}, line {lines[i]}, column {absent!r}: missing while {given!r} is given "
                              "(a true position has both coordinates or neither)")
    if anchor_ids is not None:
        known = {str(a) for a in anchor_ids}
        unknown = ~out["receiver"].isin(known).to_numpy()
        if unknown.any():
            i = int(np.flatnonzero(unknown)[0])
            raise DataFormatError(f"{source}, line {lines[i]}, column 'receiver': {out['receiver'].iloc[i]!r} is not "
                                  f"an anchor id (the anchors are {sorted(known)})")
    key = out[["time_s", "transmitter", "receiver"]]
    dup = key.duplicated(keep="first").to_numpy()
    if dup.any():
        i = int(np.flatnonzero(dup)[0])
        first = int(np.flatnonzero((key == key.iloc[i]).all(axis=1).to_numpy())[0])
        raise DataFormatError(f"{source}, line {lines[i]}, columns 'time_s','transmitter','receiver': the reading "
                              f"({out['time_s'].iloc[i]:g} s, {out['transmitter'].iloc[i]!r}, "
                              f"{out['receiver'].iloc[i]!r}) repeats line {lines[first]}")
    for tx, rows in out.groupby("transmitter", sort=False).groups.items():
        pos = out.index.get_indexer(rows)
        back = np.flatnonzero(np.diff(out["time_s"].to_numpy()[pos]) < 0)
        if back.size:
            i = pos[back[0] + 1]
            raise DataFormatError(f"{source}, line {lines[i]}, column 'time_s': time goes back for transmitter {tx!r} "
                                  f"({out['time_s'].iloc[i]:g} s after {out['time_s'].iloc[pos[back[0]]]:g} s); "
                                  "sort the file by time")
    extra = [c for c in table.columns if c not in out.columns]
    for col in extra:
        out[col] = table[col].to_numpy()
    return out.reset_index(drop=True)


def read_readings(path, *, anchor_ids=None) -> pd.DataFrame:
    """Read and check a readings CSV of the long format (module docstring)."""
    table = _read_text_table(path, READING_COLUMNS, "readings")
    return validate_readings(table, source=f"readings file {path}", anchor_ids=anchor_ids)


def read_anchors(path) -> pd.DataFrame:
    """Read and check an anchors CSV: ``id, x, y, z`` (metres), ids unique, coordinates finite."""
    table = _read_text_table(path, ("id", "x", "y", "z"), "anchors")
    source, lines = f"anchors file {path}", _file_lines(len(table))
    if len(table) == 0:
        raise DataFormatError(f"{source}: no anchors")
    ids = table["id"].astype(str).str.strip()
    for i in np.flatnonzero(ids.isin(_MISSING_TEXT).to_numpy())[:1]:
        raise DataFormatError(f"{source}, line {lines[i]}, column 'id': the id is empty")
    dup = ids.duplicated().to_numpy()
    if dup.any():
        i = int(np.flatnonzero(dup)[0])
        raise DataFormatError(f"{source}, line {lines[i]}, column 'id': anchor id {ids.iloc[i]!r} appears twice")
    out = pd.DataFrame({"id": ids.to_numpy()})
    for col in ("x", "y", "z"):
        out[col] = _numeric(table, col, source, lines, missing_ok=False)
    return out


def read_outline(path) -> np.ndarray:
    """Read and check a floor outline CSV (``x, y`` vertices of a closed polygon, metres) -> ``(V, 2)``,
    without a repeated closing vertex."""
    table = _read_text_table(path, ("x", "y"), "outline")
    source, lines = f"outline file {path}", _file_lines(len(table))
    xy = np.column_stack([_numeric(table, c, source, lines, missing_ok=False) for c in ("x", "y")])
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
    table = _read_text_table(path, ("x0", "y0", "x1", "y1"), "path")
    source, lines = f"path file {path}", _file_lines(len(table))
    cols = [_numeric(table, c, source, lines, missing_ok=False) for c in ("x0", "y0", "x1", "y1")]
    if len(table) == 0:
        raise DataFormatError(f"{source}: no segments")
    return np.stack(cols, axis=-1).reshape(-1, 2, 2)


# -- from readings to estimator inputs ---------------------------------------------------------------------
@dataclass(frozen=True)
class Epochs:
    """One recording as the estimators take it: ``rss_dbm (T, m)`` per epoch and anchor (NaN = not heard),
    ``time_s (T,)``, the true position ``position_m (T, 3)`` and heading ``heading_rad (T,)`` (NaN where unknown),
    the ``transmitter`` of each epoch and the anchor ids of the columns."""

    time_s: np.ndarray
    rss_dbm: np.ndarray
    position_m: np.ndarray
    heading_rad: np.ndarray
    transmitter: np.ndarray
    anchor_ids: tuple[str, ...]

    def __len__(self) -> int:
        return self.time_s.shape[0]

    def select(self, mask) -> "Epochs":
        """The epochs where ``mask`` holds (or at the given indices)."""
        return Epochs(self.time_s[mask], self.rss_dbm[mask], self.position_m[mask], self.heading_rad[mask],
                      self.transmitter[mask], self.anchor_ids)


def epochs(readings: pd.DataFrame, anchor_ids) -> Epochs:
    """Pivot validated readings to one row per (time, transmitter) epoch and one column per anchor of
    ``anchor_ids`` (in that order). A receiver with no row in an epoch, or an empty reading, is NaN (not heard).
    The true position of an epoch must be the same on all of its rows (else :class:`DataFormatError`)."""
    anchor_ids = tuple(str(a) for a in anchor_ids)
    col = {a: j for j, a in enumerate(anchor_ids)}
    keys = readings[["time_s", "transmitter"]]
    codes, uniques = pd.MultiIndex.from_frame(keys).factorize()
    order = np.lexsort((np.arange(len(uniques)), uniques.get_level_values(0).to_numpy()))
    rank = np.empty_like(order)
    rank[order] = np.arange(order.size)
    row = rank[codes]
    n = len(uniques)
    receivers = readings["receiver"].map(col)
    if receivers.isna().any():
        bad = readings["receiver"][receivers.isna()].iloc[0]
        raise DataFormatError(f"receiver {bad!r} is not one of the anchor ids {list(anchor_ids)}")
    rss = np.full((n, len(anchor_ids)), np.nan)
    rss[row, receivers.to_numpy(int)] = readings["rssi_dbm"].to_numpy(float)
    truth = readings[["x_m", "y_m", "z_m", "heading_rad"]].to_numpy(float)
    per_epoch = np.full((n, 4), np.nan)
    per_epoch[row] = truth
    again = np.full((n, 4), np.nan)
    again[row[::-1]] = truth[::-1]             # the first row of each epoch, to compare with the last
    differ = ~((per_epoch == again) | (np.isnan(per_epoch) & np.isnan(again)))
    if differ.any():
        e = int(np.flatnonzero(differ.any(axis=1))[0])
        raise DataFormatError(f"epoch at {uniques[order[e]][0]:g} s of transmitter {uniques[order[e]][1]!r} has different "
                              "true positions or headings on its rows")
    time_s = uniques.get_level_values(0).to_numpy(float)[order]
    tx = uniques.get_level_values(1).to_numpy(object)[order]
    return Epochs(time_s, rss, per_epoch[:, :3], per_epoch[:, 3], tx, anchor_ids)


def regular_epochs(ep: Epochs, dt_s: float, *, tolerance_s: float | None = None) -> tuple[Epochs, np.ndarray]:
    """Put one transmitter's epochs on a regular clock of period ``dt_s`` for the filters, which step at a fixed
    rate: each epoch goes to the nearest tick (within ``tolerance_s``, default ``dt_s / 2``) and a tick without an
    epoch is all NaN (nothing heard: the filters predict through it, by the library's rule). Returns the regular
    epochs and, per original epoch, its tick index."""
    if not (isinstance(dt_s, (int, float)) and math.isfinite(dt_s) and dt_s > 0):
        raise ValueError(f"dt_s must be a positive finite number of seconds, got {dt_s!r}")
    if len(set(ep.transmitter.tolist())) > 1:
        raise ValueError("regular_epochs takes one transmitter's epochs; select them first")
    tol = 0.5 * dt_s if tolerance_s is None else tolerance_s
    t0 = ep.time_s[0]
    tick = np.rint((ep.time_s - t0) / dt_s).astype(int)
    off = np.abs(ep.time_s - t0 - tick * dt_s)
    if np.any(off > tol + 1e-12 * dt_s):
        i = int(np.argmax(off))
        raise ValueError(f"epoch at {ep.time_s[i]:g} s is {off[i]:g} s off the {dt_s:g} s clock (tolerance {tol:g} s)")
    if np.any(np.diff(tick) <= 0):
        i = int(np.flatnonzero(np.diff(tick) <= 0)[0])
        raise ValueError(f"epochs at {ep.time_s[i]:g} s and {ep.time_s[i + 1]:g} s fall on the same {dt_s:g} s tick")
    n = int(tick[-1]) + 1
    m = ep.rss_dbm.shape[1]

    def spread(values, shape):
        out = np.full(shape, np.nan)
        out[tick] = values
        return out

    tx = np.full(n, ep.transmitter[0], dtype=object)
    reg = Epochs(t0 + np.arange(n) * dt_s, spread(ep.rss_dbm, (n, m)), spread(ep.position_m, (n, 3)),
                 spread(ep.heading_rad, (n,)), tx, ep.anchor_ids)
    return reg, tick


# -- data sets ------------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class MeasuredData:
    """A measured data set in locbook's format: ``anchors`` (id, x, y, z), ``recordings`` by name (long-format
    readings), an optional floor ``outline_m (V, 2)`` and reference ``path_m (S, 2, 2)``, and its attribution
    (to be shown wherever its numbers are)."""

    name: str
    anchors: pd.DataFrame
    recordings: dict[str, pd.DataFrame]
    attribution: str
    outline_m: np.ndarray | None = None
    path_m: np.ndarray | None = None
    notes: dict[str, str] = field(default_factory=dict)

    @property
    def anchor_ids(self) -> tuple[str, ...]:
        return tuple(self.anchors["id"])

    @property
    def anchors_m(self) -> np.ndarray:
        """Anchor positions ``(m, 3)`` in the order of :attr:`anchor_ids`."""
        return self.anchors[["x", "y", "z"]].to_numpy(float)

    def epochs(self, recording: str) -> Epochs:
        if recording not in self.recordings:
            raise ValueError(f"{self.name} has no recording {recording!r}; it has {sorted(self.recordings)}")
        return epochs(self.recordings[recording], self.anchor_ids)

    @classmethod
    def from_files(cls, name: str, anchors, recordings: dict, *, attribution: str, outline=None, path=None):
        """A data set from files of the long format: ``recordings`` maps names to readings CSVs."""
        anchor_table = read_anchors(anchors)
        recs = {k: read_readings(p, anchor_ids=anchor_table["id"]) for k, p in recordings.items()}
        return cls(name, anchor_table, recs, attribution, None if outline is None else read_outline(outline),
                   None if path is None else read_path_segments(path))


def _kolakowski_wide(path: Path, anchor_ids, *, tag_height_m: float, with_truth: bool) -> pd.DataFrame:
    """One Kolakowski (2021) wide file (``ts`` ns, ``x``, ``heading``, ``y``, ``rssi_<id>``) in the long format,
    checked by the long format's rules with messages pointing at the wide file's lines and columns."""
    rssi_cols = [f"rssi_{a}" for a in anchor_ids]
    required = ("ts",) + (("x", "y", "heading") if with_truth else ()) + tuple(rssi_cols)
    table = _read_text_table(path, required, "Kolakowski 2021")
    source, lines = f"Kolakowski 2021 file {path}", _file_lines(len(table))
    ts_ns = _numeric(table, "ts", source, lines, missing_ok=False)
    n, m = len(table), len(anchor_ids)
    rssi = np.column_stack([_numeric(table, c, source, lines, missing_ok=True) for c in rssi_cols])
    low, high = RSSI_RANGE_DBM
    outside = np.isfinite(rssi) & ((rssi < low) | (rssi > high))
    if outside.any():
        i, j = (int(v) for v in np.argwhere(outside)[0])
        raise DataFormatError(f"{source}, line {lines[i]}, column {rssi_cols[j]!r}: {rssi[i, j]:g} dBm is outside "
                              f"[{low:g}, {high:g}] dBm")
    long = pd.DataFrame({
        "time_s": np.repeat((ts_ns - ts_ns[0]) * 1e-9, m) if n else np.zeros(0),
        "transmitter": "tag",
        "receiver": np.tile(np.asarray(anchor_ids, dtype=object), n),
        "rssi_dbm": rssi.reshape(-1),
    })
    if with_truth:
        for col, src in (("x_m", "x"), ("y_m", "y"), ("heading_rad", "heading")):
            long[col] = np.repeat(_numeric(table, src, source, lines, missing_ok=True), m)
        long["z_m"] = np.where(np.isnan(long["x_m"]), np.nan, tag_height_m)
    return validate_readings(long, source=source, lines=np.repeat(lines, m), anchor_ids=anchor_ids)


def kolakowski2021(root=None, *, tag_height_m: float = KOLAKOWSKI2021_TAG_HEIGHT_M) -> MeasuredData:
    """The BLE RSSI data set of Kolakowski (2021), in locbook's long format (CC BY 4.0; see
    :data:`KOLAKOWSKI2021_ATTRIBUTION`).

    Recordings: ``calibration`` (4,104 static robot positions with LiDAR ground truth), ``robot`` (a 352 s robot
    drive with ground truth, 3 epochs per second with one 20 s gap) and ``walk`` (a person walking the reference
    path; no per-sample truth). Each row of the source files is one epoch whose RSSI values are averages over the
    packets of that interval (so many are not integers); an empty cell is "not heard". Times are seconds from the
    first row of each file. The tag's height is not in the files: ``tag_height_m`` (default 1.3 m, from the data
    set's README: "about 1.3 m above the floor") is given to every position with ground truth. ``root``: the
    folder of the unchanged source files (default: the copy shipped with locbook)."""
    root = measured_data_dir("kolakowski2021") if root is None else Path(root)
    if not (isinstance(tag_height_m, (int, float)) and math.isfinite(tag_height_m)):
        raise ValueError(f"tag_height_m must be a finite number of metres, got {tag_height_m!r}")
    anchors = read_anchors(root / "anchors.csv")
    ids = tuple(anchors["id"])
    recordings = {
        "calibration": _kolakowski_wide(root / "calibration_df.csv", ids, tag_height_m=tag_height_m, with_truth=True),
        "robot": _kolakowski_wide(root / "test_robot_df.csv", ids, tag_height_m=tag_height_m, with_truth=True),
        "walk": _kolakowski_wide(root / "test_walk_df.csv", ids, tag_height_m=tag_height_m, with_truth=False),
    }
    notes = {"tag_height_m": f"{tag_height_m:g} m for every position (README of the data set: about 1.3 m)",
             "rssi": "per-epoch averages of the packets received in the interval (dBm); empty = not heard"}
    return MeasuredData("kolakowski2021", anchors, recordings, KOLAKOWSKI2021_ATTRIBUTION,
                        read_outline(root / "layout.csv"), read_path_segments(root / "path_reference.csv"), notes)
