"""A measured data set: a folder of long-format files (:mod:`locbook.data.measured`) plus a manifest,
``dataset.toml``, that says everything the methods need to know about it. Nothing about a data set lives in code:
the shipped ones (``locbook/data/datasets/<name>/``) and a user's own are read the same way, by
:func:`load_dataset`, and every measured-data experiment takes one (``locbook run --data DIR``).

The manifest (every key below; ``[units]`` describes the files, every other value is SI as its name says)::

    name = "my-lab"                     # [a-z0-9-], at most 64 characters: names the reports folder
                                        # (reports/<profile>/data-<name>/)
    title = "BLE tags in the lab, 2026"
    license = "CC BY 4.0"               # the licence the files are under
    license_file = "LICENSE.md"         # optional: its text, in the folder
    attribution = "A. Author, ..."      # shown with every number computed from the data
    changes = "converted to the long format"   # optional: what differs from the source files (CC BY asks)

    [units]                             # of the files' columns (which keep their names): optional
    time = "s"                          # s | ms | us | ns; not seconds: shifted to the file's first time, scaled
    length = "m"                        # m | cm | mm: anchors, outline, true positions, reference paths
    rssi = "dBm"                        # dBm only
    acceleration = "m/s2"               # m/s2 | g (9.80665 m/s^2): inertial files' acc_x, acc_y (default m/s2)
    angular_rate = "rad/s"              # rad/s | deg/s: inertial files' gyro_z (default rad/s)

    [readings]                          # optional
    valid_range_dbm = [-120.0, -10.0]   # a reading outside is refused (default [-150, 20]; finite, within
                                        # [-300, 100], RSSI_LIMITS_DBM)
    invalid_values_dbm = [0.0, 2.0, 4.0]  # numbers the receivers write for "no reading": NaN (not heard)
    backward_time = "refuse"            # refuse | sort: a file whose time goes back (sort: counted and reported)

    [geometry]
    anchors = "anchors.csv"             # id, x, y, z; or id, x, y (no z column): a 2-D data set, one plane
    outline = "outline.csv"             # optional floor outline (x, y); default: the box around anchors and truth;
                                        # every true position (and reference path vertex) lies inside it or
                                        # within OUTLINE_TOLERANCE_M (0.5 m)
    tag_height_m = 1.3                  # the tag's height, known to the estimators; optional where every true
                                        # position has z_m (then their median); within 100 m of the anchors' heights;
                                        # refused for a 2-D data set (no heights: its z_m are ignored)
    floor_plan = "plan.png"             # optional: a PNG in the folder drawn under the maps and tracks, with...
    floor_plan_extent_m = [-1.0, 21.0, -1.0, 13.0]   # ...its georeference: [x0, x1, y0, y1] m, imshow's extent
                                        # outline, tag_height_m, floor_plan and floor_plan_extent_m may be tables
                                        # keyed by floor ([geometry.outline] F1 = "f1.csv"): locbook.data.floors

    [epochs]                            # raw packets -> epochs (locbook.data.measured.epochs)
    window_s = 1.0                      # 0: each distinct time already is an epoch
    aggregate = "mean"                  # mean | median | max of one anchor's readings in a window
    min_readings = 1                    # fewer readings of an anchor in a window: NaN (not heard); at most 10^6
                                        # and at most the most readings a window of each recording holds

    [run]                               # optional: what a run of the battery uses
    anchors = ["A1", "A2", "A4"]        # a subset of the anchors file's ids (at least 3): the other anchors' readings
                                        # are ignored and counted (locbook.data.selection.with_anchors); default:
                                        # every anchor; ``-p anchors=...`` replaces it for one run

    [[recording]]                       # one per readings file
    name = "survey"                     # [a-z0-9_-], at most 64 characters
    file = "survey.csv"
    role = "calibration"                # calibration (fit the channel, build radio maps) | static (test points) |
                                        # track (a moving tag, on the epoch clock)
    point_column = "point"              # optional: an extra column naming the point; epochs never mix points
    reference_path = "path.csv"         # optional, track: segments x0, y0, x1, y1 the walker followed
    window_s = 0                        # optional: this recording's own epoch window; 0: native scans (each
                                        # distinct time is an epoch; a track's clock is then the median spacing of
                                        # its scan times, Dataset.scan_interval_s). A track needs at least 2 epochs
    ranges = "survey_ranges.csv"        # optional: RTT / ToA ranges of this recording (time_s, transmitter,
                                        # receiver, range_m[, range_std_m]; locbook.data.ranges), aligned with its
                                        # RSS epochs by the same window rule: Dataset.ranges(name)
    inertial = "survey_imu.csv"         # optional: the recording's inertial samples (locbook.data.inertial):
                                        # time_s, acc_x, acc_y[, gyro_z][, mag_x, mag_y], body frame of the tag
                                        # (x forward, y left, yaw rate counter-clockwise positive), time in the
                                        # readings' unit and on their time axis (shifted by the readings' origin)

    [[method]]                          # optional, one per method of your own run beside the battery's
    name = "centroid"                   # its name in every table and figure: letters, digits, '_' and '-', from a
                                        # letter, at most 64 characters; no battery method's (lls, ..., grid_bayes)
    function = "methods.py:centroid"    # package.module:function (importable), or path/to/file.py:function: a
                                        # file relative to this folder, inside it (as every file the manifest names)
    kind = "static"                     # static (each scored epoch on its own) | tracker (each track in time
                                        # order); the signature: locbook.MethodInput

Floors (zones, scenes): a ``floor`` column in the anchors file and in every readings file, and placeholder anchors
(``used = false``), are :mod:`locbook.data.floors`; one floor loads as a data set of its own
(``load_dataset(DIR, floor="F1")`` or ``"DIR@F1"``, named ``<name>-<floor>``).

A data set needs at least one calibration recording; static and track recordings are optional (a calibration-only
data set fits the channel and localizes nothing: the notes say so). Anchors without z make a 2-D data set
(:attr:`Dataset.dimension` 2, :attr:`Dataset.anchors_m` ``(m, 2)``, :attr:`Dataset.tag_height_m` None); with z,
every anchor has one. A ``device`` column in the readings names each row's device (default: the transmitter id); a
track holds one. Calibration recordings holding several devices are noted (``notes["devices"]``: which, with their
epochs), and so is a static or track recording holding a device no calibration recording holds (its receiver offset
is not calibrated: 0 dB is assumed). Every file the
manifest names is a relative path whose target, every symlink resolved, is a regular file inside the data set's
folder: a link out of it is refused before any byte is read, naming the link and its target. A scored recording
(static, or a track with truth) that reads the same file as a calibration recording (the same target or the same
bytes) loads with a note ("in-sample scoring") in :attr:`Dataset.notes`, which ``locbook data check`` prints and
every report lists. Every failure raises :class:`~locbook.data.measured.DataFormatError` naming the manifest (and
key) or the file, line and column; a manifest is UTF-8 and at most :data:`MAX_MANIFEST_BYTES`. A ``[[method]]``
runs its code whenever the data set is run (``locbook run --data``) or checked (``locbook data check`` imports it):
register only code you trust, and run only data sets whose methods you have read (:mod:`locbook.user_methods`).
"""
from __future__ import annotations

import filecmp
import math
import os
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import ParameterError
from .measured import (AGGREGATES, DEVICE_COLUMN, MAX_MIN_READINGS, MIN_WINDOW_S, OPTIONAL_READING_COLUMNS,
                       READING_COLUMNS, DataFormatError, Epochs, _decode_utf8, _reading_options, _shown, _shown_names,
                       epochs, file_time_origin, read_anchors, read_outline, read_path_segments, read_readings_table,
                       scan_interval_s, validate_readings_file)

__all__ = ["Dataset", "Recording", "EpochRule", "load_dataset", "shipped_datasets", "datasets_dir", "name_problem",
           "MAX_NAME_CHARS", "MAX_TAG_HEIGHT_OFFSET_M", "MAX_MANIFEST_BYTES", "OUTLINE_TOLERANCE_M",
           "MANIFEST", "ROLES", "dataset_summary"]

MANIFEST = "dataset.toml"
ROLES = ("calibration", "static", "track")
_TIME_SCALE = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
_LENGTH_SCALE = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
_NAME = re.compile(r"[a-z0-9]+(-[a-z0-9]+)*")            # fullmatch: "$" would let a final newline in
_RECORDING_NAME = re.compile(r"[a-z0-9][a-z0-9_-]*")
#: recording names the reports use for themselves ("pooled": every scored recording together)
RESERVED_RECORDING_NAMES = ("pooled",)
#: margin (m) around anchors and true positions of the default outline, a data set without one
DEFAULT_OUTLINE_MARGIN_M = 0.5
#: how far (m) a true position (or a reference path's vertex) may lie outside the outline: position truth (a camera
#: rig, a robot's odometry, a hand-placed point) and the drawing of the outline both err by centimetres to decimetres;
#: the shipped sets need 0.33 m (danis2022's straight_03, documented in its README) and 0.08 m (kolakowski2021's
#: calibration). Farther out, the outline is not the floor the tag moved on and bounded methods would report the gap
#: as their error
OUTLINE_TOLERANCE_M = 0.5
#: the longest data set or recording name: it names folders and files (255 bytes is a file name's limit)
MAX_NAME_CHARS = 64
#: the tag lies within this height (m) of the anchors' heights (lowest - 100 m .. highest + 100 m): more is a
#: unit or sign error (a height in mm, below ground), and makes every range the height difference
MAX_TAG_HEIGHT_OFFSET_M = 100.0
#: the largest manifest (bytes) read: a dataset.toml is a page of text
MAX_MANIFEST_BYTES = 1 << 20

_TOP = {"name", "title", "license", "license_file", "attribution", "changes", "units", "readings", "geometry",
        "epochs", "recording", "method", "run"}
_SECTIONS = {"units": {"time", "length", "rssi", "acceleration", "angular_rate"},
             "readings": {"valid_range_dbm", "invalid_values_dbm", "backward_time"},
             "geometry": {"anchors", "outline", "tag_height_m", "floor_plan", "floor_plan_extent_m"},
             "epochs": {"window_s", "aggregate", "min_readings"},
             "run": {"anchors"}}
_RECORDING_KEYS = {"name", "file", "role", "point_column", "reference_path", "window_s", "ranges", "inertial"}
_METHOD_KEYS = {"name", "function", "kind"}


def datasets_dir() -> Path:
    """The folder of the data sets shipped with locbook (``locbook/data/datasets``)."""
    return Path(__file__).with_name("datasets")


def shipped_datasets() -> tuple[str, ...]:
    """Names of the data sets shipped with locbook."""
    return tuple(sorted(p.name for p in datasets_dir().iterdir() if (p / MANIFEST).is_file()))


@dataclass(frozen=True)
class EpochRule:
    """How readings become epochs (:func:`locbook.data.measured.epochs`): ``window_s`` (0 = rows are epochs),
    ``aggregate`` and ``min_readings``."""

    window_s: float
    aggregate: str = "mean"
    min_readings: int = 1

    def describe(self) -> str:
        if not self.window_s:
            return ("each distinct time of a transmitter is one epoch (the rows already are epochs; aggregate and "
                    "min_readings do not apply)")
        return (f"{self.window_s:g} s windows, the {self.aggregate} of each anchor's readings, at least "
                f"{self.min_readings} reading(s) per anchor (else not heard)")


@dataclass(frozen=True)
class Recording:
    """One readings file of a data set: its ``role``, validated ``readings`` (long format, SI), epoch rule, the
    optional point column and reference path, and ``sorted_rows``: how many rows went back in time and were put
    in order (``backward_time = "sort"``; 0 otherwise). ``inertial``: the recording's inertial samples
    (:class:`locbook.data.inertial.InertialSamples`, the manifest's ``inertial`` key), None without."""

    name: str
    role: str
    file: Path
    readings: pd.DataFrame = field(repr=False)
    epoch_rule: EpochRule
    point_column: str | None = None
    reference_path_m: np.ndarray | None = None
    sorted_rows: int = 0
    #: the recording's range readings (``ranges = "FILE"``; :func:`locbook.data.ranges.read_ranges`), or None
    ranges: pd.DataFrame | None = field(default=None, repr=False)
    ranges_file: Path | None = None
    inertial: object = field(default=None, repr=False)

    @property
    def has_truth(self) -> bool:
        return bool(np.isfinite(self.readings["x_m"].to_numpy(float)).any())


@dataclass(frozen=True)
class Dataset:
    """A measured data set read from its folder (module docstring). ``epochs(name)`` gives a recording's epochs
    by the data set's rule; ``ranges(name)`` its ranges on those epochs (a recording with ``ranges = "FILE"``;
    ``has_ranges(name)``); ``recordings_with(role)`` lists recordings by role and ``has_role(role)`` says whether
    there is one; ``devices(name)`` the devices of a recording; ``scan_interval_s(name)`` its epoch clock.
    ``dimension`` is 2 for anchors without z (then ``anchors_m`` is ``(m, 2)`` and ``tag_height_m`` None), else 3;
    ``geometry_text`` says which, in one sentence for the reports."""

    name: str
    title: str
    root: Path
    license: str
    attribution: str
    anchors: pd.DataFrame = field(repr=False)
    outline_m: np.ndarray = field(repr=False)
    #: the tag's known height (m); None for a 2-D data set (anchors without z)
    tag_height_m: float | None
    recordings: dict[str, Recording] = field(repr=False)
    changes: str = ""
    license_file: Path | None = None
    #: how each value the methods need was obtained, when the manifest did not give it directly
    notes: dict[str, str] = field(default_factory=dict)
    #: every file the manifest names (itself included): what a report computed from the data set depends on
    files: tuple[Path, ...] = ()
    #: where the tag height came from: "manifest" ([geometry] tag_height_m), "median of the true z", or "" (2-D)
    tag_height_source: str = ""
    #: the manifest's methods of your own (``[[method]]``, :class:`locbook.user_methods.UserMethod`), in its order
    methods: tuple = ()
    #: the floors of the building (anchors' ``floor`` column, :mod:`locbook.data.floors`), () without one
    floors: tuple[str, ...] = ()
    #: the floor this data set is (its anchors and rows), None for a data set without floors or a whole building
    floor: str | None = None
    #: the manifest's ``name`` (a floor's :attr:`name` adds the floor's slug)
    manifest_name: str = ""
    #: the floor plan drawn under the maps (a PNG in the folder) and its imshow extent [x0, x1, y0, y1] (m)
    floor_plan: Path | None = None
    floor_plan_extent_m: tuple | None = None
    #: the manifest's ``[run] anchors``: the subset of :attr:`anchor_ids` a run uses (empty: every anchor); applied by
    #: :func:`locbook.data.selection.select`, not here, so the data set holds every anchor as recorded
    run_anchors: tuple[str, ...] = ()
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    @property
    def anchor_ids(self) -> tuple[str, ...]:
        return tuple(self.anchors["id"])

    @property
    def dimension(self) -> int:
        """3 where the anchors carry heights (z), 2 for a 2-D data set (anchors.csv without z: one plane)."""
        return 3 if "z" in self.anchors.columns else 2

    @property
    def anchors_m(self) -> np.ndarray:
        """Anchor positions ``(m, 3)`` (``(m, 2)`` for a 2-D data set) in the order of :attr:`anchor_ids` (metres)."""
        return self.anchors[["x", "y", "z"][:self.dimension]].to_numpy(float)

    @property
    def geometry_text(self) -> str:
        """One sentence on the problem's geometry, for every report: 2-D (distances in the plane), or 3-D distances
        with the anchors' heights and the tag's known height and where it came from."""
        if self.dimension == 2:
            return "2-D: anchors and tag in one plane (the anchors file has no z); distances in the plane"
        z = self.anchors["z"].to_numpy(float)
        heights = f"{z.min():g} m" if z.min() == z.max() else f"{z.min():g}-{z.max():g} m"
        source = {"manifest": " ([geometry] tag_height_m)", "median of the true z": " (median of the true z)"}.get(
            self.tag_height_source, "")
        return f"3-D distances: anchors at {heights}, the tag at its known height {self.tag_height_m:g} m{source}"

    @property
    def selector(self) -> str:
        """``"@F1"`` for floor F1 of a data set with floors (``DIR@F1`` loads it), else ``""``."""
        from .floors import FLOOR_SELECTOR
        return f"{FLOOR_SELECTOR}{self.floor}" if self.floor is not None else ""

    def has_role(self, role: str) -> bool:
        """Whether some recording has ``role`` (one of :data:`ROLES`)."""
        return bool(self.recordings_with(role))

    def recordings_with(self, role: str) -> list[str]:
        if role not in ROLES:
            raise ParameterError(f"role must be one of {ROLES}, got {role!r}")
        return [name for name, rec in self.recordings.items() if rec.role == role]

    def devices(self, recording: str) -> tuple[str, ...]:
        """The devices of a recording's epochs, sorted: its ``device`` column's values, or (without one) its
        transmitter ids."""
        return tuple(sorted(set(self.epochs(recording).device.tolist())))

    def scan_interval_s(self, recording: str) -> float:
        """The epoch clock (s) of a recording of native scans (``window_s = 0``): the median spacing of its epoch
        times (:func:`locbook.data.measured.scan_interval_s`); a recording with a window has that window."""
        window = self.recording(recording).epoch_rule.window_s
        return float(window) if window else scan_interval_s(self.epochs(recording), name=recording)

    def recording(self, name: str) -> Recording:
        if name not in self.recordings:
            raise ParameterError(f"data set {self.name!r} has no recording {name!r}; it has {sorted(self.recordings)}")
        return self.recordings[name]

    def epochs(self, name: str) -> Epochs:
        """The recording's epochs by the data set's epoch rule (cached: the arrays are shared, do not modify).

        A windowed epoch's true position is the mean of the true positions on the window's rows, coordinate by
        coordinate (a coordinate equal on all of them kept exactly), NaN where no row has one; a native scan's
        (``window_s = 0``) is its rows' (:func:`locbook.data.measured.epochs`). A 2-D data set's epochs have NaN
        heights (its z_m is ignored); a 3-D one's heights are the rows' z_m, the tag's known height where a row has
        a position but no z_m."""
        if name not in self._cache:
            rec = self.recording(name)
            rule = rec.epoch_rule
            self._cache[name] = epochs(rec.readings, self.anchor_ids, window_s=rule.window_s or None,
                                       aggregate=rule.aggregate, min_readings=rule.min_readings,
                                       group_by=() if rec.point_column is None else (rec.point_column,))
        return self._cache[name]

    def ranges(self, name: str):
        """The recording's ranges on the rows of :meth:`epochs` (cached): ``(range_m (E, m), range_std_m (E, m) or
        None)``, NaN where an anchor has no range in the epoch's window; the mean of the window's ranges and the std of
        that mean (:func:`locbook.data.ranges.align_ranges`). A recording without a ranges file is refused."""
        key = ("ranges", name)
        if key not in self._cache:
            rec = self.recording(name)
            if rec.ranges is None:
                raise ParameterError(f"recording {name!r} of data set {self.name!r} has no ranges file (its "
                                     "[[recording]] has no ranges = \"FILE\")")
            from .ranges import align_ranges
            rule = rec.epoch_rule
            self._cache[key] = align_ranges(self.epochs(name), rec.readings, rec.ranges, window_s=rule.window_s or None,
                                            group_by=() if rec.point_column is None else (rec.point_column,),
                                            source=f"ranges file {rec.ranges_file}")
        return self._cache[key]

    def has_ranges(self, name: str) -> bool:
        """Whether the recording has a ranges file."""
        return self.recording(name).ranges is not None

    def epochs_of(self, role: str) -> Epochs:
        """The epochs of every recording of ``role``, one after the other (in manifest order)."""
        parts = [self.epochs(n) for n in self.recordings_with(role)]
        if not parts:
            raise ParameterError(f"data set {self.name!r} has no {role} recording")
        if len(parts) == 1:
            return parts[0]
        keys = set.intersection(*(set(p.extra) for p in parts))
        return Epochs(np.concatenate([p.time_s for p in parts]), np.concatenate([p.rss_dbm for p in parts]),
                      np.concatenate([p.position_m for p in parts]), np.concatenate([p.heading_rad for p in parts]),
                      np.concatenate([p.transmitter for p in parts]), self.anchor_ids,
                      np.concatenate([p.n_readings for p in parts]),
                      {k: np.concatenate([p.extra[k] for p in parts]) for k in sorted(keys)},
                      np.concatenate([p.device for p in parts]))


# -- reading the manifest --------------------------------------------------------------------------------------
def name_problem(name) -> str:
    """``""`` if ``name`` is a valid data set name (the manifest's ``name``; it names the reports folder), else
    what is wrong with it, for a message."""
    if isinstance(name, str) and _NAME.fullmatch(name) and len(name) <= MAX_NAME_CHARS:
        return ""
    return (f"name {_shown(name)} must be lower-case letters, digits and single hyphens ([a-z0-9-]), at most "
            f"{MAX_NAME_CHARS} characters (MAX_NAME_CHARS); it names the reports folder")


def _fail(manifest: Path, message: str):
    raise DataFormatError(f"{manifest}: {message}")


def _string(manifest, raw: dict, key: str, where: str, *, required: bool = True, default: str = "") -> str:
    value = raw.get(key, None)
    if value is None:
        if required:
            _fail(manifest, f"{where}{key!r} is required")
        return default
    if not isinstance(value, str) or not value.strip():
        _fail(manifest, f"{where}{key!r} must be a non-empty string, got {_shown(value)}")
    return value.strip()


def _number(manifest, raw: dict, key: str, where: str, *, ge: float | None = None, gt: float | None = None):
    value = raw[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        _fail(manifest, f"{where}{key!r} must be a finite number, got {_shown(value)}")
    if (ge is not None and value < ge) or (gt is not None and value <= gt):
        _fail(manifest, f"{where}{key!r} must be {'>= ' + str(ge) if ge is not None else '> ' + str(gt)}, "
                        f"got {value!r}")
    return float(value)


def _unknown_keys(manifest, raw: dict, allowed: set, where: str):
    unknown = sorted(set(raw) - allowed)
    if unknown:
        _fail(manifest, f"{where}unknown key(s) {_shown_names(unknown)}; allowed: {sorted(allowed)}")


def _file(manifest: Path, root: Path, value: str, where: str) -> Path:
    """The file the manifest names, checked before any byte of it is read: a relative path whose target (every
    symlink resolved) is a regular file inside the data set's folder. A link out of the folder is refused, naming
    the link and its target (a data set from elsewhere must not make locbook read, and quote, e.g.
    /proc/self/environ)."""
    try:
        path = root / value
        if Path(value).is_absolute() or ".." in Path(value).parts:
            _fail(manifest, f"{where}{_shown(value)} must be a file inside the data set's folder (a relative path)")
        target = Path(os.path.realpath(path))
        if not target.is_relative_to(Path(os.path.realpath(root))):
            _fail(manifest, f"{where}{_shown(value)} is a link to {str(target)!r}, outside the data set's folder "
                            f"{root}; a data set's files lie inside its folder: copy the file in")
        if not target.is_file():
            _fail(manifest, f"{where}file {_shown(value)} does not exist in {root}" if not target.exists() else
                  f"{where}{_shown(value)} is not a regular file")
    except (OSError, ValueError) as exc:       # a NUL byte, a name too long, a link loop
        if isinstance(exc, DataFormatError):
            raise
        _fail(manifest, f"{where}{_shown(value)} is not a usable file name ({exc.__class__.__name__}: {exc})")
    return path


def _resolve(path) -> tuple[Path, Path]:
    """``(folder, manifest)`` of a data set given as a shipped name, a folder or its ``dataset.toml``."""
    text = str(path)
    if isinstance(path, str) and _NAME.fullmatch(text) and not Path(text).exists():
        folder = datasets_dir() / text
        if not (folder / MANIFEST).is_file():
            raise ParameterError(f"{text!r} is neither a folder nor a data set shipped with locbook "
                                 f"(shipped: {', '.join(shipped_datasets())}); give the folder holding {MANIFEST}")
        return folder, folder / MANIFEST
    p = Path(path).expanduser()
    if p.is_dir():
        p = p / MANIFEST
    if not p.is_file():
        raise ParameterError(f"no data set at {path}: {p} does not exist (a data set is a folder with a {MANIFEST}; "
                             "docs/data-format.md)")
    return p.parent.resolve(), p.resolve()


def _convert(table: pd.DataFrame, time_scale: float, length_scale: float) -> pd.DataFrame:
    """The readings table with times in seconds (shifted to the file's first time when not seconds; integer times,
    such as nanoseconds since 1970, are shifted as integers, so no digit is lost) and lengths in metres. A cell that
    is not a number is left as written, for the long format's checks to name."""
    if time_scale == 1.0 and length_scale == 1.0:
        return table
    out = table.copy()

    def scaled(column: str, scale: float, shift: bool):
        raw = out[column]
        if pd.api.types.is_numeric_dtype(raw) and not isinstance(raw.dtype, pd.CategoricalDtype):
            v = raw.to_numpy(float)
            out[column] = (v - np.nanmin(v) if shift and np.isfinite(v).any() else v) * scale
            return
        text = raw.astype(object).where(raw.notna(), "").astype(str).str.strip()
        if shift and len(text) and text.str.fullmatch(r"[+-]?\d{1,19}").all():
            try:
                v = text.astype(np.int64).to_numpy()        # integers up to 9.2e18 (ns since 1970: year 2262)
            except (OverflowError, ValueError):
                v = None
            if v is not None:
                out[column] = (v - v.min()).astype(float) * scale
                return
        v = pd.to_numeric(text, errors="coerce").to_numpy(float)
        finite = np.isfinite(v)
        if shift and finite.any():
            v = v - np.min(v[finite])
        out[column] = np.where(finite, v * scale, text.to_numpy(object)).astype(object)

    if time_scale != 1.0:
        scaled("time_s", time_scale, shift=True)
    if length_scale != 1.0:
        for col in ("x_m", "y_m", "z_m"):
            if col in out.columns:
                scaled(col, length_scale, shift=False)
    return out


def _backward_rows(time_s: np.ndarray, transmitter) -> int:
    """Rows that came after a later reading of the same transmitter (file order): the rows sorting moves back."""
    frame = pd.DataFrame({"t": time_s, "tx": pd.factorize(transmitter)[0]})
    latest = frame.groupby("tx")["t"].cummax()
    earlier = latest.groupby(frame["tx"]).shift(1)
    return int((frame["t"] < earlier).sum())


def load_dataset(path, *, floor: str | None = None) -> Dataset:
    """Read and check a data set: a shipped name (``"kolakowski2021"``), its folder, or its ``dataset.toml``.

    Every file is read and validated here (long format rules, the manifest's sentinels, range, units and clock
    handling), so a data set that loads is one every experiment can run on. ``floor`` (or ``path`` written
    ``DIR@F1``): one floor of a data set with floors, a data set of its own (:mod:`locbook.data.floors`); without
    it a data set with floors loads as the whole building, every floor checked, for ``locbook data check``."""
    from . import floors as fl
    if floor is None:
        path, floor = fl.split_floor_selector(path)
    root, manifest = _resolve(path)
    size = manifest.stat().st_size
    if size > MAX_MANIFEST_BYTES:
        _fail(manifest, f"the manifest is {size:,} bytes; a {MANIFEST} is at most {MAX_MANIFEST_BYTES:,} "
                        "(MAX_MANIFEST_BYTES)")
    text = _decode_utf8(manifest.read_bytes(), manifest, "manifest")
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise DataFormatError(f"{manifest}: not valid TOML ({exc})") from None
    _unknown_keys(manifest, raw, _TOP, "")
    for section, allowed in _SECTIONS.items():
        if not isinstance(raw.get(section, {}), dict):
            _fail(manifest, f"[{section}] must be a table")
        _unknown_keys(manifest, raw.get(section, {}), allowed, f"[{section}] ")
    name = _string(manifest, raw, "name", "")
    problem = name_problem(name)
    if problem:
        _fail(manifest, problem)
    title = _string(manifest, raw, "title", "")
    license_ = _string(manifest, raw, "license", "")
    attribution = _string(manifest, raw, "attribution", "")
    changes = _string(manifest, raw, "changes", "", required=False)
    license_file = None
    if "license_file" in raw:
        license_file = _file(manifest, root, _string(manifest, raw, "license_file", ""), "license_file: ")

    units = raw.get("units", {})
    time_unit, length_unit = units.get("time", "s"), units.get("length", "m")
    if not isinstance(time_unit, str) or time_unit not in _TIME_SCALE:
        _fail(manifest, f"[units] time must be one of {sorted(_TIME_SCALE)}, got {_shown(time_unit)}")
    if not isinstance(length_unit, str) or length_unit not in _LENGTH_SCALE:
        _fail(manifest, f"[units] length must be one of {sorted(_LENGTH_SCALE)}, got {_shown(length_unit)}")
    if units.get("rssi", "dBm") != "dBm":
        _fail(manifest, f"[units] rssi must be 'dBm' (convert the readings to dBm), got {_shown(units.get('rssi'))}")
    time_scale, length_scale = _TIME_SCALE[time_unit], _LENGTH_SCALE[length_unit]
    from .inertial import ACCELERATION_UNITS, ANGULAR_RATE_UNITS
    acc_unit, rate_unit = units.get("acceleration", "m/s2"), units.get("angular_rate", "rad/s")
    if not isinstance(acc_unit, str) or acc_unit not in ACCELERATION_UNITS:
        _fail(manifest, f"[units] acceleration must be one of {sorted(ACCELERATION_UNITS)}, got {_shown(acc_unit)}")
    if not isinstance(rate_unit, str) or rate_unit not in ANGULAR_RATE_UNITS:
        _fail(manifest, f"[units] angular_rate must be one of {sorted(ANGULAR_RATE_UNITS)}, got {_shown(rate_unit)}")

    opts = raw.get("readings", {})
    try:
        sentinels, valid_range = _reading_options(opts.get("invalid_values_dbm"), opts.get("valid_range_dbm"))
    except ParameterError as exc:
        raise DataFormatError(f"{manifest}: [readings] {exc}") from None
    backward = opts.get("backward_time", "refuse")
    if backward not in ("refuse", "sort"):
        _fail(manifest, f"[readings] backward_time must be 'refuse' or 'sort', got {_shown(backward)}")

    geometry = raw.get("geometry", {})
    anchors = read_anchors(_file(manifest, root, _string(manifest, geometry, "anchors", "[geometry] "),
                                 "[geometry] anchors: "))
    used = anchors[fl.USED_COLUMN].to_numpy(bool) if fl.USED_COLUMN in anchors.columns else np.ones(len(anchors), bool)
    floors = (tuple(dict.fromkeys(anchors[fl.FLOOR_COLUMN][used])) if fl.FLOOR_COLUMN in anchors.columns else ())
    if floor is not None and floor not in floors:
        raise ParameterError(f"data set {name!r} ({root}) has no floor {floor!r}" + (
            f"; its floors are {', '.join(floors)}" if floors else ": its anchors file has no floor column"))
    axes = [c for c in ("x", "y", "z") if c in anchors.columns]     # no z: a 2-D data set
    run_anchors = _run_anchors(manifest, raw.get("run", {}), tuple(anchors["id"]))
    if length_scale != 1.0:
        anchors[axes] *= length_scale

    rule_raw = raw.get("epochs", {})
    default_rule = _epoch_rule(manifest, rule_raw, "[epochs] ", None)

    records = raw.get("recording", [])
    if not isinstance(records, list) or not records:
        _fail(manifest, "no [[recording]]: a data set lists its readings files, each with a role "
                        f"({', '.join(ROLES)})")
    recordings: dict[str, Recording] = {}
    invalid_found: dict[str, int] = {}
    dropped: dict[str, dict] = {}
    left_out: list[str] = []
    for i, rec in enumerate(records):
        where = f"[[recording]] {i + 1}: "
        if not isinstance(rec, dict):
            _fail(manifest, f"{where}must be a table")
        _unknown_keys(manifest, rec, _RECORDING_KEYS, where)
        rname = _string(manifest, rec, "name", where)
        where = f"[[recording]] {rname!r}: "
        if not _RECORDING_NAME.fullmatch(rname) or len(rname) > MAX_NAME_CHARS:
            _fail(manifest, f"[[recording]] {i + 1}: name {_shown(rname)} must be lower-case letters, digits, '_' "
                            f"and '-', at most {MAX_NAME_CHARS} characters (MAX_NAME_CHARS)")
        if rname in recordings:
            _fail(manifest, f"{where}the name appears twice")
        if rname in RESERVED_RECORDING_NAMES:
            _fail(manifest, f"{where}the name is reserved: the results tables name every scored recording together "
                            f"{rname!r}; rename the recording")
        role = _string(manifest, rec, "role", where)
        if role not in ROLES:
            _fail(manifest, f"{where}role must be one of {ROLES}, got {_shown(role)}")
        path = _file(manifest, root, _string(manifest, rec, "file", where), where)
        point_column = _string(manifest, rec, "point_column", where, required=False) or None
        rule = _epoch_rule(manifest, {**rule_raw, **({"window_s": rec["window_s"]} if "window_s" in rec else {})},
                           where, default_rule)
        if role == "track" and point_column is not None:
            _fail(manifest, f"{where}point_column belongs to calibration and static recordings (a tag standing at "
                            "named points); a track moves")
        table, lines = read_readings_table(path, time_as_text=time_scale != 1.0)
        fl.check_readings_floors(table, lines, path, floors)
        if point_column is not None:
            _check_point_column(table, lines, point_column, path, manifest, where)
        readings = validate_readings_file(path, table, lines, lambda t: _convert(t, time_scale, length_scale),
                                          anchor_ids=anchors["id"], invalid_values_dbm=sentinels,
                                          # None when not declared: readings >= 0 dBm then warn
                                          valid_range_dbm=opts.get("valid_range_dbm"), sort=backward == "sort")
        readings, dropped[rname] = fl.select_rows(readings, anchors, floor)
        if floor is not None and not len(readings):
            left_out.append(rname)          # no row on this floor: not one of its recordings
            continue
        sorted_rows = 0
        if backward == "sort":     # counted on the file's order (validate_readings has sorted its copy)
            t = _convert(table, time_scale, length_scale)["time_s"]
            sorted_rows = _backward_rows(pd.to_numeric(pd.Series(t), errors="coerce").to_numpy(float),
                                         table["transmitter"])
        if sentinels.size:
            raw_rssi = pd.to_numeric(pd.Series(table["rssi_dbm"]).astype(object), errors="coerce").to_numpy(float)
            invalid_found[rname] = int(np.isin(raw_rssi, sentinels).sum())
        if role == "track":
            for column, what in (("transmitter", "transmitters"), (DEVICE_COLUMN, "devices")):
                senders = readings[column].unique() if column in readings.columns else ()
                if len(senders) > 1:
                    _fail(manifest, f"{where}{path.name} holds {len(senders)} {what} "
                                    f"({', '.join(map(_shown, senders[:5]))}"
                                    f"{', ...' if len(senders) > 5 else ''}); a track follows one tag: give each "
                                    f"{what[:-1]}'s rows their own file and [[recording]]")
        reference = None
        if "reference_path" in rec:
            if role != "track":
                _fail(manifest, f"{where}reference_path belongs to a track, not a {role} recording")
            reference = read_path_segments(_file(manifest, root, _string(manifest, rec, "reference_path", where),
                                                 where + "reference_path: ")) * length_scale
        if floors and ("ranges" in rec or "inertial" in rec):
            _fail(manifest, f"{where}{'ranges' if 'ranges' in rec else 'inertial'}: a data set with floors takes "
                            "RSS readings only (its streams are not split by floor yet); give each floor a data set "
                            "of its own to use its ranges or inertial samples")
        ranges, ranges_file = None, None
        origin = file_time_origin(table["time_s"]) if time_scale != 1.0 else None
        if "ranges" in rec:
            from .ranges import read_ranges
            ranges_file = _file(manifest, root, _string(manifest, rec, "ranges", where), where + "ranges: ")
            ranges = read_ranges(ranges_file, anchor_ids=anchors["id"], transmitters=readings["transmitter"].unique(),
                                 time_scale=time_scale, length_scale=length_scale, time_origin_raw=origin)
        inertial = None
        if "inertial" in rec:
            from .inertial import read_inertial
            inertial = read_inertial(_file(manifest, root, _string(manifest, rec, "inertial", where),
                                           where + "inertial: "),
                                     time_scale=time_scale, time_origin=origin,
                                     acceleration=acc_unit, angular_rate=rate_unit, sort=backward == "sort")
        recordings[rname] = Recording(rname, role, path, readings, rule, point_column, reference, sorted_rows,
                                      ranges, ranges_file, inertial)
    anchors = anchors[used & ((anchors[fl.FLOOR_COLUMN] == floor).to_numpy() if floor is not None else True)]
    anchors = anchors.drop(columns=[fl.USED_COLUMN], errors="ignore").reset_index(drop=True)
    roles = {r.role for r in recordings.values()}
    if "calibration" not in roles:
        _fail(manifest, ("no recording has role 'calibration'" if floor is None else
                         f"floor {floor!r}: no calibration recording has a row on this floor")
              + ": the channel is fitted on it (and never on the recordings it is scored on)")

    for rec in recordings.values():
        if rec.role == "calibration" and not rec.has_truth:
            _fail(manifest, f"[[recording]] {rec.name!r}: a calibration recording needs true positions (x_m, y_m): "
                            "the channel is fitted on the distances from them to the anchors")
    notes = {}
    truth_z = np.concatenate([r.readings["z_m"].to_numpy(float) for r in recordings.values()])
    truth_xy = np.concatenate([r.readings[["x_m", "y_m"]].to_numpy(float) for r in recordings.values()])
    with_xy = np.isfinite(truth_xy).all(axis=1)
    tag_height, height_source = None, ""
    height_value = fl.per_floor(manifest, geometry, "tag_height_m", floors, floor)
    if isinstance(height_value, list):      # the whole building, heights per floor: their median, for the check only
        finite = [v for v in height_value if isinstance(v, (int, float)) and not isinstance(v, bool)]
        height_value = float(np.median(finite)) if len(finite) == len(height_value) else height_value[0]
    if "z" not in anchors.columns:          # 2-D: one plane, no heights anywhere
        if "tag_height_m" in geometry:
            _fail(manifest, "[geometry] tag_height_m: anchors have no z: a 2-D data set has no tag height (give the "
                            "anchors' z in the anchors file for 3-D distances, or drop tag_height_m)")
        with_z = [r.name for r in recordings.values() if r.readings["z_m"].notna().any()]
        if with_z:
            notes["z_m"] = (f"the anchors have no z (a 2-D data set): the true heights (z_m) of "
                            f"{', '.join(map(repr, with_z))} are ignored; distances are in the plane")
        for rec in recordings.values():
            rec.readings["z_m"] = np.nan
    elif height_value is not None:
        tag_height = _number(manifest, {"tag_height_m": height_value}, "tag_height_m", "[geometry] ")
        notes["tag_height_m"] = f"{tag_height:g} m (manifest)"
        source, height_source = "[geometry] tag_height_m", "manifest"
    elif with_xy.any() and np.isfinite(truth_z[with_xy]).all():
        tag_height = float(np.median(truth_z[with_xy]))
        notes["tag_height_m"] = f"{tag_height:g} m: the median of the recorded true heights (z_m)"
        source, height_source = "the tag's height (the median of the recordings' z_m)", "median of the true z"
    else:
        _fail(manifest, "[geometry] tag_height_m is required: the estimators need the tag's height, and not every "
                        "true position has a z_m (a 2-D data set has no z column in its anchors file)")
    if tag_height is not None:
        z = anchors["z"].to_numpy(float)
        low, high = z.min() - MAX_TAG_HEIGHT_OFFSET_M, z.max() + MAX_TAG_HEIGHT_OFFSET_M
        if not low <= tag_height <= high:
            _fail(manifest, f"{source} = {tag_height:g} m is not within {MAX_TAG_HEIGHT_OFFSET_M:g} m of the "
                            f"anchors' heights ({z.min():g} to {z.max():g} m; allowed {low:g} to {high:g} m, "
                            "MAX_TAG_HEIGHT_OFFSET_M): a unit or sign error? (the manifest's values are in metres)")
        for rec in recordings.values():     # a true position without a height is at the tag's known height
            r = rec.readings
            r.loc[r["x_m"].notna() & r["z_m"].isna(), "z_m"] = tag_height
    outline_value = fl.per_floor(manifest, geometry, "outline", floors, floor)
    if isinstance(outline_value, list):      # a whole building of outlines per floor: the box around them all
        parts = [read_outline(_file(manifest, root, _string(manifest, {"outline": v}, "outline", "[geometry] "),
                                    "[geometry] outline: ")) * length_scale for v in outline_value]
        lo, hi = np.vstack(parts).min(axis=0), np.vstack(parts).max(axis=0)
        outline = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
    elif outline_value is not None:
        outline = read_outline(_file(manifest, root, _string(manifest, {"outline": outline_value}, "outline",
                                                             "[geometry] "), "[geometry] outline: ")) * length_scale
    else:
        paths = [r.reference_path_m.reshape(-1, 2) for r in recordings.values() if r.reference_path_m is not None]
        pts = np.vstack([anchors[["x", "y"]].to_numpy(float), truth_xy[with_xy], *paths])
        lo, hi = pts.min(axis=0) - DEFAULT_OUTLINE_MARGIN_M, pts.max(axis=0) + DEFAULT_OUTLINE_MARGIN_M
        outline = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
        notes["outline"] = (f"none given: the box around the anchors and the true positions with a "
                            f"{DEFAULT_OUTLINE_MARGIN_M:g} m margin")
    _check_outline(manifest, outline, anchors[["x", "y"]].to_numpy(float), truth_xy[with_xy])
    if outline_value is not None:
        _check_truth_in_outline(manifest, outline, recordings)
    plan, extent = _floor_plan(manifest, root, geometry, floors, floor)
    for rec in recordings.values():
        if rec.sorted_rows:
            notes[f"sorted {rec.name}"] = (f"{rec.sorted_rows} row(s) of {rec.file.name} went back in time and were "
                                           "put in time order (backward_time = 'sort')")
    for rec in recordings.values():
        if rec.inertial is not None:
            notes[f"inertial {rec.name}"] = rec.inertial.describe()
    if sentinels.size:
        values = ", ".join(f"{v:g}" for v in sentinels)
        found = ", ".join(f"{n} in {k}" for k, n in invalid_found.items() if n) or "none found"
        notes["invalid readings"] = f"values {values} dBm are 'no reading' and load as NaN (not heard): {found}"
    in_sample = _in_sample_note(recordings)
    if in_sample:
        notes["in-sample scoring"] = in_sample
    if not roles & {"static", "track"}:
        notes["scoring"] = ("calibration only: no static or track recording, so nothing is localized or scored; "
                            "the channel is fitted on the calibration recordings")
    elif not any(r.role == "static" or (r.role == "track" and r.has_truth) for r in recordings.values()):
        notes["scoring"] = ("no static or track recording has a true position per epoch: the static methods are "
                            "not scored (tracks with a reference path are scored by their distance to it)")
    methods = _methods(manifest, root, raw.get("method", []))
    files = [manifest, root / _string(manifest, geometry, "anchors", "[geometry] ")]
    for key in ("outline", "floor_plan"):
        value = geometry.get(key)
        files += [root / v for v in (value.values() if isinstance(value, dict) else [value] if value else [])
                  if isinstance(v, str)]
    files += [license_file] if license_file else []
    for rec in records:
        files += [root / rec["file"]] + ([root / rec["reference_path"]] if "reference_path" in rec else [])
        files += [root / rec["ranges"]] if "ranges" in rec else []
        files += [root / rec["inertial"]] if "inertial" in rec else []
    files += [m.path for m in methods if m.path is not None]
    _floor_notes(notes, dropped, floor, left_out, recordings)
    data = Dataset(name if floor is None else f"{name}-{fl.floor_slug(floor)}", title if floor is None else
                   f"{title} (floor {floor})", root, license_, attribution, anchors, outline, tag_height, recordings,
                   changes, license_file, notes, tuple(files), height_source, methods=methods, floors=floors,
                   floor=floor, manifest_name=name, floor_plan=plan, floor_plan_extent_m=extent,
                   run_anchors=run_anchors)
    if floor is not None and name_problem(data.name):
        _fail(manifest, f"floor {floor!r}: the floor's data set name {data.name!r} (the manifest's name and the "
                        f"floor's slug) is not a data set name: {name_problem(data.name)}")
    for rname, rec in recordings.items():    # every recording's epochs now: a problem is named with its file
        try:
            data.epochs(rname)
        except DataFormatError as exc:
            raise DataFormatError(f"readings file {rec.file} (recording {rname!r}): {exc}") from None
        _check_epochs_kept(manifest, data, rname)
        if rec.ranges is not None:
            aligned = data.ranges(rname)
            said = []
            if aligned.unaligned:
                said.append(f"{aligned.unaligned:,} range(s) of {rec.ranges_file.name} fall on no epoch of recording "
                            f"{rname!r} (before the transmitter's first reading, in a window without RSS rows, or at a "
                            "time no scan has): not used")
            if aligned.ignored:
                said.append(f"{aligned.ignored:,} range(s) of {rec.ranges_file.name} are of anchors that are not "
                            "anchors of this data set (placeholders, used = false): ignored")
            if said:
                data.notes[f"ranges {rname}"] = "; ".join(said)
    _device_notes(data)
    if floors and floor is None:      # the whole building: every floor loads as a data set of its own
        for f in floors:
            try:
                part = load_dataset(root, floor=f)
            except DataFormatError as exc:
                raise DataFormatError(f"floor {f!r}: {exc}") from None
            notes[f"floor {f}"] = (f"data set {part.name!r}: {len(part.anchor_ids)} anchors, recordings "
                                   + ", ".join(part.recordings) + "; " + "; ".join(
                                       f"{k}: {v}" for k, v in part.notes.items() if k.startswith(("split", "cross",
                                                                                                  "left out"))))
    return data


def _floor_plan(manifest: Path, root: Path, geometry: dict, floors, floor):
    """``(plan path, extent)`` of this data set (or floor): :func:`locbook.data.floors.read_floor_plan` and
    :func:`~locbook.data.floors.floor_plan_extent`, both given or neither; a whole building with plans per floor
    checks each and draws none."""
    from . import floors as fl
    plan = fl.per_floor(manifest, geometry, "floor_plan", floors, floor)
    extent = fl.per_floor(manifest, geometry, "floor_plan_extent_m", floors, floor)
    if "floor_plan" not in geometry and "floor_plan_extent_m" not in geometry:
        return None, None
    if ("floor_plan" in geometry) != ("floor_plan_extent_m" in geometry):
        given, absent = ("floor_plan", "floor_plan_extent_m") if "floor_plan" in geometry else (
            "floor_plan_extent_m", "floor_plan")
        _fail(manifest, f"[geometry] {given} needs {absent} too: a plan is drawn at its georeference, "
                        "floor_plan_extent_m = [x0, x1, y0, y1] (m)")
    if floor is None and any(isinstance(geometry[k], dict) for k in ("floor_plan", "floor_plan_extent_m")):
        # the whole building with plans per floor: check every floor's, draw none
        for f in floors:
            _one_plan(manifest, root, geometry, fl.per_floor(manifest, geometry, "floor_plan", floors, f),
                      fl.per_floor(manifest, geometry, "floor_plan_extent_m", floors, f), f"[geometry] floor {f!r}: ")
        return None, None
    return _one_plan(manifest, root, geometry, plan, extent,
                     "[geometry] " if floor is None else f"[geometry] floor {floor!r}: ")


def _one_plan(manifest: Path, root: Path, geometry: dict, plan, extent, where: str):
    """One floor's ``(plan, extent)``: none where a plan table leaves the floor out (an extent table naming it is
    then refused), else both checked."""
    from . import floors as fl
    if plan is None:
        if extent is not None and isinstance(geometry["floor_plan_extent_m"], dict):
            _fail(manifest, f"{where}floor_plan_extent_m without a floor_plan for this floor")
        return None, None
    if extent is None:
        _fail(manifest, f"{where}a floor_plan needs its floor_plan_extent_m (the table names none for this floor)")
    return fl.read_floor_plan(manifest, root, plan, where), fl.floor_plan_extent(manifest, extent, where)


def _floor_notes(notes: dict, dropped: dict, floor, left_out, recordings) -> None:
    """Notes on the rows a floor's (or a data set's) battery ignores: placeholders' readings, the rows of a
    recording on other floors (split), other floors' anchors hearing this floor's tag (cross-floor)."""
    placeholder = {r: c["placeholder"] for r, c in dropped.items() if c["placeholder"]}
    if placeholder:
        notes["placeholder anchors"] = ("readings logged by placeholder anchors (used = false) are ignored: "
                                        + ", ".join(f"{n:,} in {r}" for r, n in placeholder.items()))
    if floor is None:
        return
    split = {r: c for r, c in dropped.items() if c["other floors"] and r in recordings}
    if split:
        notes["split recordings"] = (f"recordings spanning floors, split by floor: " + "; ".join(
            f"{r}: {c['rows'] - c['other floors'] - c['placeholder']:,} of its {c['rows']:,} rows on floor {floor}"
            for r, c in split.items()))
    cross = {r: c["cross-floor"] for r, c in dropped.items() if c["cross-floor"]}
    if cross:
        notes["cross-floor readings"] = (f"readings of the tag on floor {floor} by other floors' anchors, ignored (a "
                                         "floor's battery uses its own anchors; floor detection is out of scope): "
                                         + ", ".join(f"{n:,} in {r}" for r, n in cross.items()))
    if left_out:
        notes["left out"] = f"recordings with no row on floor {floor}: {', '.join(left_out)}"


def _run_anchors(manifest: Path, run: dict, known: tuple) -> tuple[str, ...]:
    """``[run] anchors``: a list of anchor ids, checked by the rule of ``-p anchors``
    (:func:`locbook.data.selection.check_anchor_ids`: each an anchor, none twice, at least 3)."""
    if "anchors" not in run:
        return ()
    from .selection import check_anchor_ids
    value = run["anchors"]
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        _fail(manifest, f"[run] anchors must be a non-empty list of anchor ids (strings), got {_shown(value)}")
    try:
        return check_anchor_ids(value, known, "[run] anchors")
    except ParameterError as exc:
        raise DataFormatError(f"{manifest}: {exc}") from None


def _methods(manifest: Path, root: Path, raw) -> tuple:
    """The ``[[method]]`` tables: each with ``name``, ``function`` and ``kind`` (no other key), checked as the
    command line's are (:meth:`locbook.user_methods.UserMethod.parse`; a file through :func:`_file`: relative, inside
    the folder), no name twice. Nothing is imported here: ``locbook data check`` says whether each imports."""
    from ..user_methods import METHOD_KINDS, UserMethod
    if not isinstance(raw, list):
        _fail(manifest, "[[method]] must be an array of tables ([[method]] with name, function and kind)")
    out, seen = [], {}
    for i, rec in enumerate(raw):
        where = f"[[method]] {i + 1}: "
        if not isinstance(rec, dict):
            _fail(manifest, f"{where}must be a table")
        name = rec.get("name")
        if isinstance(name, str) and name.strip():
            where = f"[[method]] {_shown(name.strip())}: "
        _unknown_keys(manifest, rec, _METHOD_KEYS, where)
        for key in ("name", "function", "kind"):
            value = rec.get(key)
            if not isinstance(value, str) or not value.strip():
                _fail(manifest, f"{where}{key!r} is required, a non-empty string" if value is None else
                      f"{where}{key!r} must be a non-empty string, got {_shown(value)}")
        kind, function = rec["kind"].strip(), rec["function"].strip()
        if kind not in METHOD_KINDS:
            _fail(manifest, f"{where}kind must be one of {METHOD_KINDS}, got {_shown(kind)}")
        target = function.rpartition(":")[0]
        if target.endswith(".py"):
            _file(manifest, root, target, f"{where}function: ")
        try:
            method = UserMethod.parse(rec["name"].strip(), function, kind, base=root, source="manifest")
        except ParameterError as exc:
            _fail(manifest, f"{where}{exc}")
        if method.name.lower() in seen:
            _fail(manifest, f"{where}the name appears twice")
        seen[method.name.lower()] = method
        out.append(method)
    return tuple(out)


def _device_notes(data: Dataset) -> None:
    """Notes on the devices (``device`` column, default the transmitter id): calibration recordings that hold more
    than one (which, and how many epochs each: a pooled fit mixes their receiver offsets), and a scored recording
    holding a device that no calibration recording holds (its offset is not calibrated: 0 dB is assumed). Warnings,
    never refusals: the methods run, the reports say it."""
    calibration = [data.epochs(n).device for n in data.recordings_with("calibration")]
    names, counts = np.unique(np.concatenate(calibration).astype(str), return_counts=True)
    if len(names) > 1:
        each = ", ".join(f"{_shown(str(d))} ({int(c):,} epochs)" for d, c in zip(names, counts))
        data.notes["devices"] = (f"the calibration recordings hold {len(names)} devices: {each}; their receiver "
                                 "offsets (dB) differ, which a fit per device (calibrate_path_loss_devices) "
                                 "separates and a pooled fit mixes")
    known = set(names.tolist())
    for rname, rec in data.recordings.items():
        if rec.role == "calibration":
            continue
        new = [d for d in data.devices(rname) if d not in known]
        if new:
            data.notes[f"uncalibrated device {rname}"] = (
                f"recording {rname!r} holds device(s) {', '.join(map(_shown, new))}, which no calibration recording "
                "holds: its receiver offset is not calibrated: assumed 0 dB")


def _check_epochs_kept(manifest: Path, data: Dataset, rname: str) -> None:
    """Refuse a recording its epoch rule leaves useless: a track of fewer than 2 epochs (the trackers step on its
    clock: a window longer than the recording, or times in another unit than [units] time says), and a recording
    where ``min_readings`` leaves no entry heard (more readings than any window holds: every epoch not heard)."""
    rec, ep = data.recording(rname), data.epochs(rname)
    rule, where = rec.epoch_rule, f"[[recording]] {rname!r}: "
    if rec.role == "track" and len(ep) < 2:
        t = rec.readings["time_s"].to_numpy(float)
        span = f"its times span {float(np.ptp(t)) if len(t) else 0.0:g} s"
        if rule.window_s:
            _fail(manifest, f"{where}a track needs at least 2 epochs, {rec.file.name} makes {len(ep)} at window_s = "
                            f"{rule.window_s:g} s ({span}): the window is longer than the recording, or [units] time "
                            "is not the file's unit")
        _fail(manifest, f"{where}a track needs at least 2 epochs, {rec.file.name} makes {len(ep)} as native scans "
                        f"(window_s = 0: one epoch per distinct time; {span}): the trackers step on the scans' clock, "
                        "which takes 2 scan times or more")
    if rule.window_s and rule.min_readings > 1 and not np.isfinite(ep.rss_dbm).any():
        every = epochs(rec.readings, data.anchor_ids, window_s=rule.window_s, aggregate=rule.aggregate,
                       group_by=() if rec.point_column is None else (rec.point_column,))
        most = int(every.n_readings.max()) if every.n_readings is not None and every.n_readings.size else 0
        if most < rule.min_readings:
            _fail(manifest, f"[epochs] min_readings = {rule.min_readings:,} leaves no entry of recording {rname!r} "
                            f"({rec.file.name}) heard: "
                            f"the most readings of one anchor in one {rule.window_s:g} s window is {most:,}; "
                            f"min_readings must be at most {most:,} (or the window longer)")


def _check_truth_in_outline(manifest: Path, outline: np.ndarray, recordings: dict) -> None:
    """Refuse an outline that leaves out true positions: every true position of every recording (and every vertex
    of a reference path) lies inside the outline or within OUTLINE_TOLERANCE_M of it. Else the bounded methods
    search a floor the tag was not on and report errors of the outline's offset as ok."""
    from ..geometry import distance_to_segments, inside_outline
    edges = np.stack([outline, np.roll(outline, -1, axis=0)], axis=1)            # (V, 2, 2)
    chunk = max(1, (1 << 20) // len(edges))
    for rec in recordings.values():
        parts = [("rows with a true position", rec.readings[["x_m", "y_m"]].to_numpy(float))]
        if rec.reference_path_m is not None:
            parts.append(("reference path vertices", rec.reference_path_m.reshape(-1, 2)))
        for what, xy in parts:
            xy = xy[np.isfinite(xy).all(axis=1)]
            out = xy[~inside_outline(xy, outline)] if len(xy) else xy
            if not len(out):
                continue
            gap = np.concatenate([distance_to_segments(out[i:i + chunk], edges) for i in range(0, len(out), chunk)])
            far = gap > OUTLINE_TOLERANCE_M
            if far.any():
                i = int(np.flatnonzero(far)[0])
                _fail(manifest, f"[geometry] outline: {int(far.sum()):,} of the {len(xy):,} {what} of recording "
                                f"{rec.name!r} lie more than {OUTLINE_TOLERANCE_M:g} m (OUTLINE_TOLERANCE_M) outside "
                                f"it, the first ({out[i, 0]:g}, {out[i, 1]:g}) m, {gap[i]:.3g} m out: every true "
                                "position lies inside the outline (a unit error, another site's outline?)")


def _check_outline(manifest: Path, outline: np.ndarray, anchors_xy: np.ndarray, truth_xy: np.ndarray) -> None:
    """Refuse an outline that contains none of the anchors and none of the true positions: the bounded methods
    would search a floor elsewhere and report errors of the outline's offset as ok (a unit error, another site's
    file)."""
    from ..geometry import inside_outline
    if inside_outline(anchors_xy, outline).any() or (len(truth_xy) and inside_outline(truth_xy, outline).any()):
        return
    lo, hi = outline.min(axis=0), outline.max(axis=0)
    _fail(manifest, f"[geometry] outline (x {lo[0]:g}..{hi[0]:g}, y {lo[1]:g}..{hi[1]:g} m) contains none of the "
                    f"{len(anchors_xy)} anchors and none of the {len(truth_xy)} true positions: it is not this "
                    "site's floor (another unit, another file?)")


def _in_sample_note(recordings: dict) -> str:
    """The note "in-sample scoring" (:func:`_shared_files`), or "" when no scored recording shares a file."""
    shared = _shared_files(recordings)
    if not shared:
        return ""
    return ("; ".join(f"{s} (scored) reads the same file as calibration recording {c} ({f})" for s, c, f in shared)
            + ": the channel is fitted on the epochs these recordings are scored on, so their errors are in-sample "
              "(optimistic); give the scored recordings files of their own")


def _shared_files(recordings: dict) -> list[tuple[str, str, str]]:
    """``(scored recording, calibration recording, file name)`` for each scored recording (static, or a track with
    truth) that reads the same file (by its target, or the same bytes) as a calibration recording."""
    def same(a: Path, b: Path) -> bool:
        try:
            return os.path.samefile(a, b) or filecmp.cmp(a, b, shallow=False)
        except OSError:
            return False
    calibration = [r for r in recordings.values() if r.role == "calibration"]
    out = []
    for rec in recordings.values():
        if rec.role == "static" or (rec.role == "track" and rec.has_truth):
            out += [(repr(rec.name), repr(c.name), rec.file.name) for c in calibration if same(rec.file, c.file)]
    return out


def _check_point_column(table: pd.DataFrame, lines, column: str, path: Path, manifest: Path, where: str) -> None:
    """The point column is an extra column of the file, and every row names its point (an empty id would make one
    'point' of rows in transit)."""
    reserved = READING_COLUMNS + OPTIONAL_READING_COLUMNS + (DEVICE_COLUMN,)
    if column in reserved or column not in table.columns:
        extra = [c for c in table.columns if c not in reserved]
        raise DataFormatError(f"{manifest}: {where}point_column {_shown(column)} must name an extra column of "
                              f"{path.name} (not one of the long format's); its extra columns are "
                              f"{_shown_names(extra)}")
    ids = table[column]
    text = ids.astype(object).where(ids.notna(), "").astype(str).str.strip()
    empty = (text == "").to_numpy()
    if empty.any():
        i = int(np.flatnonzero(empty)[0])
        raise DataFormatError(f"readings file {path}, line {lines[i]}, column {column!r}: the point id is empty "
                              f"({int(empty.sum())} such row(s)); every row of a point column ({manifest.name}, "
                              f"{where.rstrip(': ')}) names its point: drop rows taken between points, or label them")


def _epoch_rule(manifest, raw: dict, where: str, default: EpochRule | None) -> EpochRule:
    window = _number(manifest, raw, "window_s", where, ge=0) if "window_s" in raw else (
        default.window_s if default else 0.0)
    if 0 < window < MIN_WINDOW_S:
        _fail(manifest, f"{where}'window_s' must be 0 or at least {MIN_WINDOW_S:g} s (MIN_WINDOW_S: shorter windows "
                        f"overflow the tick count), got {window!r}")
    aggregate = raw.get("aggregate", "mean")
    if aggregate not in AGGREGATES:
        _fail(manifest, f"{where}aggregate must be one of {AGGREGATES}, got {_shown(aggregate)}")
    min_readings = raw.get("min_readings", 1)
    if isinstance(min_readings, bool) or not isinstance(min_readings, int) or not 1 <= min_readings <= MAX_MIN_READINGS:
        _fail(manifest, f"{where}min_readings must be an integer from 1 to {MAX_MIN_READINGS:,} (MAX_MIN_READINGS: "
                        f"more readings than a window holds leave every entry not heard), got {_shown(min_readings)}")
    return EpochRule(window, aggregate, min_readings)


def dataset_summary(data: Dataset) -> list[dict]:
    """One row per recording: role, readings, epochs, share of (epoch, anchor) entries heard, readings per heard
    entry, duration, truth, rows sorted (and, in a data set with ranges, the (epoch, anchor) entries with a range);
    what ``locbook data check`` prints and every report's first table shows."""
    rows = []
    for name, rec in data.recordings.items():
        ep = data.epochs(name)
        heard = np.isfinite(ep.rss_dbm)
        finite_rows = int(np.isfinite(rec.readings["rssi_dbm"].to_numpy(float)).sum())
        rows.append({
            "recording": name, "role": rec.role, "file": rec.file.name, "readings": finite_rows,
            "rows not heard": int(len(rec.readings) - finite_rows), "epochs": len(ep),
            "heard (%)": round(100 * float(heard.mean()), 1) if heard.size else 0.0,
            "readings per heard entry": round(float(ep.n_readings[heard].mean()), 2) if heard.any() else 0.0,
            "duration (s)": round(float(ep.time_s.max() - ep.time_s.min()), 1) if len(ep) else 0.0,
            "truth": ("per epoch" if np.isfinite(ep.position_m[:, 0]).any()
                      else "reference path" if rec.reference_path_m is not None else "none"),
            "points": (len(set(ep.extra[rec.point_column].tolist())) if rec.point_column else ""),
            "rows sorted": rec.sorted_rows,
        })
    if any(rec.ranges is not None for rec in data.recordings.values()):   # a column only where there are ranges
        for row in rows:
            rec = data.recording(row["recording"])
            row["ranges (epoch, anchor)"] = (int(np.isfinite(data.ranges(rec.name)[0]).sum())
                                             if rec.ranges is not None else "")
    return rows
