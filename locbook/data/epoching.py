"""From readings to the estimators' inputs: :class:`Epochs` (one row per epoch, one column per anchor, NaN where not
heard), :func:`epochs` (native scans or windows of raw packets), :func:`regular_epochs` (one transmitter on a fixed
clock) and :func:`scan_interval_s` (the clock of native scans)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from ..errors import ParameterError
from .csvfile import DataFormatError, seconds_text, shown, shown_names
from .long_format import DEVICE_COLUMN, OPTIONAL_READING_COLUMNS, READING_COLUMNS, link_direction_hint

__all__ = ["AGGREGATES", "MIN_WINDOW_S", "MAX_MIN_READINGS", "MAX_REGULAR_EPOCHS", "Epochs", "epochs",
           "regular_epochs", "scan_interval_s"]

#: the default bound on the ticks :func:`regular_epochs` creates (a clock jump would otherwise fill the memory)
MAX_REGULAR_EPOCHS = 1_000_000
#: the shortest epoch window (s) but 0: no radio packet is shorter, and a window of 5e-324 s makes ticks infinite
MIN_WINDOW_S = 1e-6
#: the largest ``min_readings`` of an epoch rule: more readings of one anchor than any window holds (a million
#: packets per anchor per window) would leave every entry not heard
MAX_MIN_READINGS = 1_000_000
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
                             f"(MIN_WINDOW_S: shorter windows overflow the tick count), got {shown(window_s)}")
    if aggregate not in AGGREGATES:
        raise ParameterError(f"aggregate must be one of {AGGREGATES}, got {shown(aggregate)}")
    if not (isinstance(min_readings, (int, np.integer)) and not isinstance(min_readings, bool)
            and 1 <= min_readings <= MAX_MIN_READINGS):
        raise ParameterError(f"min_readings must be an integer from 1 to {MAX_MIN_READINGS:,} (MAX_MIN_READINGS), "
                             f"got {shown(min_readings)}")
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
        raise DataFormatError(f"receiver {shown(bad)} is not one of the anchor ids {shown_names(anchor_ids)}"
                              f"{link_direction_hint(readings['transmitter'], anchor_ids)}")
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
            raise DataFormatError(f"epoch at {seconds_text(utime[order[e]])} of transmitter "
                                  f"{shown(tx_names[utx[order[e]]])} "
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
            f"{max_epochs:,}; the largest gap is {gap!r} s, between the epochs at {seconds_text(time_s[i])} and "
            f"{seconds_text(time_s[i + 1])} (epochs {i} and {i + 1} of {len(time_s)}), {_count(gap / dt_s)} empty "
            "ticks. "
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
        raise ParameterError(f"epochs at {seconds_text(time_s[i])} and {seconds_text(time_s[i + 1])} fall on the same "
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
                             f"one time, {seconds_text(np.median(time_s))}): no scan clock; are the times in the unit "
                             "[units] time says?")
    return spacing
