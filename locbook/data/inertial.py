"""Inertial streams of a measured data set: the file, its validation, and its alignment with the RSS epochs.

**The file** (CSV, named per recording by the manifest's ``inertial = "FILE"``; one row per sample):

============== ======== ========================================================================================
column         required meaning
============== ======== ========================================================================================
``time_s``     yes      time of the sample, in the unit and on the time axis of the recording's readings file
``acc_x``      yes      acceleration along the tag's forward axis (body frame), ``[units] acceleration``
``acc_y``      yes      acceleration along the tag's left axis (``acc_x`` and ``acc_y`` given together or not at all)
``gyro_z``     no       yaw rate about the tag's up axis, counter-clockwise positive, ``[units] angular_rate``
``mag_x``      no       magnetic field along the forward and left axes (any unit; ``mag_x`` and ``mag_y``
``mag_y``      no       together): read, validated and kept, unused by the methods (no heading measurement yet)
============== ======== ========================================================================================

The body frame is the tag's: x forward, y left, z up (a right-handed frame; a level sensor's horizontal axes, so
gravity is on z and not in the file's columns). Units: ``[units] acceleration`` is ``m/s2`` (default) or ``g``
(:data:`STANDARD_GRAVITY_M_S2` = 9.80665 m/s^2 exactly, the CGPM's standard acceleration of gravity) and
``[units] angular_rate`` ``rad/s`` (default) or ``deg/s``. An empty field (or ``NaN``) is no sample (the library's
one rule for missing readings: NaN); other columns are ignored.

**Time.** The time column has the readings' unit (``[units] time``) and their time axis: a unit that is not seconds
is shifted by the origin of the recording's readings file (its first time,
:func:`~locbook.data.measured.file_time_origin`), never by the inertial file's own first time, so that the two streams
keep their offset (integer times are shifted as integers, as the readings' are, so no digit of a nanosecond clock is
lost). The times are strictly increasing after the data set's ``backward_time`` rule (``refuse``: a time that does not
increase is refused naming its line; ``sort``: the rows are sorted, stably, counted and noted, and a time that still
repeats is refused). The sampling interval is the median spacing of the times; a spacing of more than
:data:`GAP_INTERVALS` intervals is a gap, counted and noted (the sub-steps it covers have no reading: the filters
predict through them).

**Limits.** Values beyond :data:`MAX_ACCELERATION_M_S2` (16 g, the largest full scale of a MEMS accelerometer in a
phone or tag) or :data:`MAX_ANGULAR_RATE_RAD_S` (2000 deg/s, a MEMS gyroscope's largest full scale) are unit errors
(deg/s declared as rad/s, mg as g) and refused. A file has at least 2 samples and is read by the exact reader (at
most 64 MiB, :data:`locbook.data.measured.MAX_EXACT_READ_BYTES`: about 10^6 samples, 5 h at 50 Hz).

**Alignment** (:func:`align`): the fusion filters step on a grid of ``n_sub`` sub-steps per epoch of the track's
clock, ``dt_f = epoch_s / n_sub`` with ``n_sub = clip(round(epoch_s / interval_s), 1, MAX_SUB_STEPS)``: the
sub-step is the IMU's interval where the epoch holds at most :data:`MAX_SUB_STEPS` of them, else a tenth of the
epoch (Dogan 2015's scheme, Sec. 3.5 / Table 3.5: a 20 Hz accelerometer with the RSS at every 10th step). Sub-step
``j`` covers ``[t_0 - epoch_s + j dt_f, t_0 - epoch_s + (j + 1) dt_f)``, ``t_0`` the time of the track's first
epoch: the filters start one epoch before it, as the RSS-only trackers do (they predict before each step), so the
RSS epoch ``k`` falls on sub-step ``(k + 1) n_sub - 1``. Each sub-step's reading is the mean of the samples in its
window, per column (NaN where it holds none).

Every failure raises :class:`~locbook.data.measured.DataFormatError` naming the file, line and column.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import ParameterError
from .csvfile import DataFormatError, numeric_column, read_text_table, seconds_text, shown
from .long_format import check_time_unit, shifted_seconds

__all__ = ["InertialSamples", "InertialGrid", "read_inertial", "align", "INERTIAL_COLUMNS",
           "OPTIONAL_INERTIAL_COLUMNS", "ACCELERATION_UNITS", "ANGULAR_RATE_UNITS", "STANDARD_GRAVITY_M_S2",
           "GAP_INTERVALS", "MAX_SUB_STEPS", "MAX_ACCELERATION_M_S2", "MAX_ANGULAR_RATE_RAD_S", "sub_steps"]

INERTIAL_COLUMNS = ("time_s", "acc_x", "acc_y")
OPTIONAL_INERTIAL_COLUMNS = ("gyro_z", "mag_x", "mag_y")
#: the standard acceleration of gravity (m/s^2; exact, 3rd CGPM 1901): ``[units] acceleration = "g"``
STANDARD_GRAVITY_M_S2 = 9.80665
ACCELERATION_UNITS = {"m/s2": 1.0, "g": STANDARD_GRAVITY_M_S2}
ANGULAR_RATE_UNITS = {"rad/s": 1.0, "deg/s": math.pi / 180.0}
#: a spacing of more than this many sampling intervals is a gap (counted and noted): a logger's pause, not jitter
GAP_INTERVALS = 5
#: the most fusion sub-steps per RSS epoch (Dogan 2015: RSS at every 10th step of the 20 Hz accelerometer grid);
#: more would cost filter steps without adding information the mean of the window does not carry
MAX_SUB_STEPS = 10
#: 16 g (m/s^2): the largest full scale of the MEMS accelerometers of phones and tags; beyond it is a unit error
MAX_ACCELERATION_M_S2 = 16 * STANDARD_GRAVITY_M_S2
#: 2000 deg/s (rad/s): the largest full scale of a MEMS gyroscope; beyond it is a unit error (deg/s as rad/s)
MAX_ANGULAR_RATE_RAD_S = 2000 * math.pi / 180.0


@dataclass(frozen=True)
class InertialSamples:
    """One recording's inertial file, validated and in SI: ``time_s (N,)`` (s, strictly increasing, on the
    readings' time axis), ``acc_m_s2 (N, 2)`` (body frame: forward, left), ``gyro_rad_s (N,)`` (counter-clockwise
    positive) or None, ``mag (N, 2)`` (as written) or None; ``interval_s`` the median spacing, ``gaps`` the
    spacings of more than :data:`GAP_INTERVALS` intervals, ``largest_gap_s``, ``sorted_rows`` rows put in time order
    (``backward_time = "sort"``)."""

    file: Path
    time_s: np.ndarray = field(repr=False)
    acc_m_s2: np.ndarray = field(repr=False)
    gyro_rad_s: np.ndarray | None = field(default=None, repr=False)
    mag: np.ndarray | None = field(default=None, repr=False)
    interval_s: float = 0.0
    gaps: int = 0
    largest_gap_s: float = 0.0
    sorted_rows: int = 0

    def __len__(self) -> int:
        return self.time_s.shape[0]

    @property
    def rate_hz(self) -> float:
        return 1.0 / self.interval_s

    def describe(self) -> str:
        """One line for the notes: samples, rate, channels, gaps."""
        what = "accelerometer" + (", gyroscope" if self.gyro_rad_s is not None else "") + (
            ", magnetometer (kept, unused)" if self.mag is not None else "")
        gaps = (f"; {self.gaps} gap(s) of more than {GAP_INTERVALS} intervals, the largest {self.largest_gap_s:.3g} s"
                if self.gaps else "")
        order = f"; {self.sorted_rows} row(s) put in time order" if self.sorted_rows else ""
        return (f"{self.file.name}: {len(self):,} samples at {self.rate_hz:.4g} Hz (median interval "
                f"{self.interval_s:.4g} s), {what}{gaps}{order}")


def _pair(table, names, source, lines, scale: float, limit: float, unit: str):
    """Columns ``names`` as floats times ``scale``, given together (both or neither per row) and within
    ``limit`` in magnitude (SI)."""
    cols = [numeric_column(table, c, source, lines, missing_ok=True) * scale for c in names]
    if len(cols) == 2:
        half = np.isnan(cols[0]) != np.isnan(cols[1])
        if half.any():
            i = int(np.flatnonzero(half)[0])
            given, absent = (names[0], names[1]) if np.isfinite(cols[0][i]) else (names[1], names[0])
            raise DataFormatError(f"{source}, line {lines[i]}, column {absent!r}: missing while {given!r} is given "
                                  f"(the two axes are given together or not at all)")
    if limit is not None:
        for c, v in zip(names, cols):
            far = np.abs(v) > limit                   # NaN compares False
            if far.any():
                i = int(np.flatnonzero(far)[0])
                raise DataFormatError(f"{source}, line {lines[i]}, column {c!r}: {shown(table[c].iloc[i])} is "
                                      f"{abs(v[i]):.4g} {unit} in magnitude, beyond the {limit:.4g} {unit} a MEMS "
                                      f"sensor measures ({int(far.sum())} such value(s)): a unit error? (declare "
                                      "[units] acceleration / angular_rate)")
    return np.column_stack(cols) if len(cols) == 2 else cols[0]


def read_inertial(path, *, time_scale: float = 1.0, time_origin=None, acceleration: str = "m/s2",
                  angular_rate: str = "rad/s", sort: bool = False) -> InertialSamples:
    """Read and check an inertial file (module docstring) -> :class:`InertialSamples` in SI.

    ``time_scale``: seconds per unit of the time column (``[units] time``); with a unit that is not seconds,
    ``time_origin`` is the origin of the recording's readings file
    (:func:`~locbook.data.measured.file_time_origin` of its raw time column), the times being shifted by it.
    ``acceleration`` and ``angular_rate``: the ``[units]`` of the columns. ``sort``: the data set's ``backward_time =
    "sort"``."""
    if acceleration not in ACCELERATION_UNITS:
        raise ParameterError(f"acceleration unit must be one of {sorted(ACCELERATION_UNITS)}, got {acceleration!r}")
    if angular_rate not in ANGULAR_RATE_UNITS:
        raise ParameterError(f"angular_rate unit must be one of {sorted(ANGULAR_RATE_UNITS)}, got {angular_rate!r}")
    path = Path(path)
    table, lines = read_text_table(path, INERTIAL_COLUMNS, "inertial")
    source = f"inertial file {path}"
    if len(table) < 2:
        raise DataFormatError(f"{source}: {len(table)} sample(s); an inertial stream has at least 2 (its sampling "
                              "interval is the median spacing of the times)")
    if ("mag_x" in table.columns) != ("mag_y" in table.columns):
        have = "mag_x" if "mag_x" in table.columns else "mag_y"
        raise DataFormatError(f"{source}: column {have!r} without its pair; the magnetometer is mag_x and mag_y "
                              "together (or neither)")
    if time_scale == 1.0:
        time_s = numeric_column(table, "time_s", source, lines, missing_ok=False)
        check_time_unit(time_s, table["time_s"], source, lines)
    else:
        if time_origin is None:
            raise ParameterError("time_origin is required for a time unit that is not seconds: the origin of the "
                                 "recording's readings file (locbook.data.measured.file_time_origin)")
        time_s = shifted_seconds(table, source, lines, time_scale, time_origin)
    sorted_rows = 0
    if sort:
        order = np.argsort(time_s, kind="stable")
        sorted_rows = int((time_s < np.maximum.accumulate(time_s)).sum())
        table, lines, time_s = table.iloc[order].reset_index(drop=True), lines[order], time_s[order]
    step = np.diff(time_s)
    bad = np.flatnonzero(step <= 0)
    if bad.size:
        k = int(bad[0])
        how = "repeats" if step[k] == 0 else "goes back from"
        raise DataFormatError(f"{source}, line {lines[k + 1]}, column 'time_s': the time {seconds_text(time_s[k + 1])} "
                              f"{how} {seconds_text(time_s[k])} on line {lines[k]} ({bad.size} such row(s)); inertial "
                              "times are strictly increasing"
                              + ("" if sort else " (a data set with backward_time = 'sort' sorts them first)"))
    acc = _pair(table, ("acc_x", "acc_y"), source, lines, ACCELERATION_UNITS[acceleration], MAX_ACCELERATION_M_S2,
                "m/s^2")
    gyro = (_pair(table, ("gyro_z",), source, lines, ANGULAR_RATE_UNITS[angular_rate], MAX_ANGULAR_RATE_RAD_S,
                  "rad/s") if "gyro_z" in table.columns else None)
    mag = _pair(table, ("mag_x", "mag_y"), source, lines, 1.0, None, "") if "mag_x" in table.columns else None
    if not np.isfinite(acc).any():
        raise DataFormatError(f"{source}, column 'acc_x': no sample holds an acceleration (every acc_x, acc_y empty)")
    interval = float(np.median(step))
    gap = step > GAP_INTERVALS * interval
    return InertialSamples(path, time_s, acc, gyro, mag, interval, int(gap.sum()),
                           float(step[gap].max()) if gap.any() else 0.0, sorted_rows)


def sub_steps(epoch_s: float, interval_s: float, max_sub_steps: int = MAX_SUB_STEPS) -> int:
    """Fusion sub-steps per epoch: ``clip(round(epoch_s / interval_s), 1, max_sub_steps)`` (module docstring)."""
    if not (isinstance(epoch_s, (int, float)) and math.isfinite(epoch_s) and epoch_s > 0):
        raise ParameterError(f"epoch_s must be a positive number of seconds, got {epoch_s!r}")
    if not (isinstance(interval_s, (int, float)) and math.isfinite(interval_s) and interval_s > 0):
        raise ParameterError(f"interval_s must be a positive number of seconds, got {interval_s!r}")
    if isinstance(max_sub_steps, bool) or not isinstance(max_sub_steps, (int, np.integer)) or max_sub_steps < 1:
        raise ParameterError(f"max_sub_steps must be a positive integer, got {max_sub_steps!r}")
    return int(min(max(round(epoch_s / interval_s), 1), max_sub_steps))


@dataclass(frozen=True)
class InertialGrid:
    """Inertial readings on the fusion filters' sub-step grid of one track (:func:`align`): ``n_sub`` sub-steps of
    ``dt_s`` per epoch, ``time_s (S,)`` each sub-step's window end (``S = T n_sub``), the window means ``acc_m_s2 (S,
    2)`` and ``gyro_rad_s (S,)`` (or None), ``counts (S,)`` the samples of each window, and ``rss_steps (T,)`` the
    sub-step of each epoch."""

    n_sub: int
    dt_s: float
    time_s: np.ndarray = field(repr=False)
    acc_m_s2: np.ndarray = field(repr=False)
    gyro_rad_s: np.ndarray | None = field(repr=False)
    counts: np.ndarray = field(repr=False)
    rss_steps: np.ndarray = field(repr=False)

    @property
    def n_steps(self) -> int:
        return self.time_s.shape[0]

    def on_grid(self, epoch_values, fill=np.nan) -> np.ndarray:
        """Values ``(..., T, k)`` of the epochs spread on the sub-step grid ``(..., S, k)`` (``fill`` elsewhere)."""
        v = np.asarray(epoch_values, float)
        out = np.full(v.shape[:-2] + (self.n_steps,) + v.shape[-1:], fill)
        out[..., self.rss_steps, :] = v
        return out


def align(samples: InertialSamples, epoch_time_s, epoch_s: float, *, max_sub_steps: int = MAX_SUB_STEPS,
          n_sub: int | None = None) -> InertialGrid:
    """The inertial ``samples`` on the sub-step grid of a track's epoch clock (module docstring, "Alignment"):
    ``epoch_time_s (T,)`` the ticks of the regular clock of period ``epoch_s`` (the tracking scenario's
    ``time_s``). ``n_sub`` overrides the rule (:func:`sub_steps`). Samples outside the grid are not used."""
    ticks = np.asarray(epoch_time_s, float)
    if ticks.ndim != 1 or ticks.size < 1 or not np.isfinite(ticks).all():
        raise ParameterError("epoch_time_s must be the finite times (T,) of the track's epoch clock")
    n_sub = sub_steps(epoch_s, samples.interval_s, max_sub_steps) if n_sub is None else int(n_sub)
    dt = epoch_s / n_sub
    n = ticks.size * n_sub
    start = ticks[0] - epoch_s
    # window index of each sample; a relative 1e-9 keeps a sample written at a window's start in that window
    j = np.floor((samples.time_s - start) / dt + 1e-9).astype(np.int64)
    inside = (j >= 0) & (j < n)

    def means(values):
        v = np.asarray(values, float).reshape(len(samples), -1)
        out = np.full((n, v.shape[1]), np.nan)
        for c in range(v.shape[1]):
            ok = inside & np.isfinite(v[:, c])
            count = np.bincount(j[ok], minlength=n)
            total = np.bincount(j[ok], weights=v[ok, c], minlength=n)
            with np.errstate(invalid="ignore", divide="ignore"):
                out[:, c] = np.where(count > 0, total / np.maximum(count, 1), np.nan)
        return out

    ok = inside & np.isfinite(samples.acc_m_s2).all(axis=1)
    counts = np.bincount(j[ok], minlength=n)
    acc = means(samples.acc_m_s2)
    gyro = None if samples.gyro_rad_s is None else means(samples.gyro_rad_s)[:, 0]
    return InertialGrid(n_sub, dt, start + (np.arange(n) + 1) * dt, acc, gyro, counts,
                        (np.arange(ticks.size) + 1) * n_sub - 1)
