"""A measured data set: a folder of long-format files (:mod:`locbook.data.measured`) plus a manifest,
``dataset.toml``, that says everything the methods need to know about it. Nothing about a data set lives in code:
the shipped ones (``locbook/data/datasets/<name>/``) and a user's own are read the same way, by
:func:`load_dataset`, and every measured-data experiment takes one (``locbook run --data DIR``).

The manifest, ``dataset.toml``, is :mod:`locbook.data.manifest` (every key, its schema).

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

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import ParameterError
from .csvfile import DataFormatError, shown, shown_names
from .epoching import Epochs, epochs, scan_interval_s
from .long_format import DEVICE_COLUMN, OPTIONAL_READING_COLUMNS, READING_COLUMNS, file_time_origin
from .manifest import (
    LENGTH_SCALES,
    MANIFEST,
    MAX_MANIFEST_BYTES,
    MAX_NAME_CHARS,
    ROLES,
    TIME_SCALES,
    EpochRule,
    datasets_dir,
    fail,
    manifest_file,
    manifest_methods,
    manifest_number,
    manifest_string,
    name_problem,
    read_manifest,
    resolve_dataset,
    shipped_datasets,
)
from .manifest import run_anchors as check_run_anchors
from .measured import read_anchors, read_outline, read_path_segments
from .readings_file import read_readings_table, validate_readings_file
from .summary import dataset_summary, device_notes, in_sample_note

__all__ = ["Dataset", "Recording", "EpochRule", "load_dataset", "shipped_datasets", "datasets_dir", "name_problem",
           "MAX_NAME_CHARS", "MAX_TAG_HEIGHT_OFFSET_M", "MAX_MANIFEST_BYTES", "OUTLINE_TOLERANCE_M",
           "MANIFEST", "ROLES", "dataset_summary"]

#: margin (m) around anchors and true positions of the default outline, a data set without one
DEFAULT_OUTLINE_MARGIN_M = 0.5
#: how far (m) a true position (or a reference path's vertex) may lie outside the outline: position truth (a camera
#: rig, a robot's odometry, a hand-placed point) and the drawing of the outline both err by centimetres to decimetres;
#: the shipped sets need 0.33 m (danis2022's straight_03, documented in its README) and 0.08 m (kolakowski2021's
#: calibration). Farther out, the outline is not the floor the tag moved on and bounded methods would report the gap
#: as their error
OUTLINE_TOLERANCE_M = 0.5
#: the tag lies within this height (m) of the anchors' heights (lowest - 100 m .. highest + 100 m): more is a
#: unit or sign error (a height in mm, below ground), and makes every range the height difference
MAX_TAG_HEIGHT_OFFSET_M = 100.0


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




def _convert(table: pd.DataFrame, time_scale: float, length_scale: float) -> pd.DataFrame:
    """The readings table with times in seconds and lengths in metres. Times not in seconds are shifted by the
    file's origin, :func:`~locbook.data.long_format.file_time_origin` (the one rule the recording's ranges and
    inertial files are shifted by, :func:`~locbook.data.long_format.shifted_seconds`): integer times, such as
    nanoseconds since 1970, are shifted as integers, so no digit is lost. A cell that is not a number is left as
    written, for the long format's checks to name."""
    if time_scale == 1.0 and length_scale == 1.0:
        return table
    out = table.copy()

    def scaled(column: str, scale: float, origin):      # origin None: not shifted
        raw = out[column]
        if pd.api.types.is_numeric_dtype(raw) and not isinstance(raw.dtype, pd.CategoricalDtype):
            v = raw.to_numpy(float)
            out[column] = (v - origin if origin is not None else v) * scale
            return
        text = raw.astype(object).where(raw.notna(), "").astype(str).str.strip()
        if isinstance(origin, int):                     # every field an integer (file_time_origin's int case)
            out[column] = (text.astype(np.int64).to_numpy() - origin).astype(float) * scale
            return
        v = pd.to_numeric(text, errors="coerce").to_numpy(float)
        finite = np.isfinite(v)
        if origin is not None:
            v = v - origin
        out[column] = np.where(finite, v * scale, text.to_numpy(object)).astype(object)

    if time_scale != 1.0:
        scaled("time_s", time_scale, file_time_origin(out["time_s"]))
    if length_scale != 1.0:
        for col in ("x_m", "y_m", "z_m"):
            if col in out.columns:
                scaled(col, length_scale, None)
    return out


def _backward_rows(time_s: np.ndarray, transmitter) -> int:
    """Rows that came after a later reading of the same transmitter (file order): the rows sorting moves back."""
    frame = pd.DataFrame({"t": time_s, "tx": pd.factorize(transmitter)[0]})
    latest = frame.groupby("tx")["t"].cummax()
    earlier = latest.groupby(frame["tx"]).shift(1)
    return int((frame["t"] < earlier).sum())


def load_dataset(path, *, floor: str | None = None) -> Dataset:
    """Read and check a data set: a shipped name (``"kolakowski2021"``), its folder, or its ``dataset.toml``.

    Every file is read and validated here (the manifest's schema, :class:`locbook.data.manifest.Manifest`; long
    format rules, the manifest's sentinels, range, units and clock handling), so a data set that loads is one every
    experiment can run on.

    Parameters
    ----------
    path : str or path-like
        A shipped data set's name (:func:`shipped_datasets`), a folder holding a ``dataset.toml``, or the manifest
        itself; ``DIR@F1`` selects floor ``F1``.
    floor : str, optional
        One floor of a data set with floors, loaded as a data set of its own (:mod:`locbook.data.floors`); without
        it a data set with floors loads as the whole building, every floor checked, for ``locbook data check``.

    Returns
    -------
    Dataset
        The anchors (metres), the outline, the tag height and every recording's validated readings;
        :meth:`Dataset.epochs` gives a recording's epochs by the manifest's rule.

    Raises
    ------
    DataFormatError
        A file or manifest that breaks a rule, in one line naming the file (and key, or line and column).
    ParameterError
        ``path`` names no data set, or ``floor`` no floor of it.

    Examples
    --------
    >>> from locbook.data.dataset import load_dataset
    >>> data = load_dataset("danis2022")
    >>> data.dimension, len(data.anchor_ids), data.tag_height_m
    (3, 12, 1.85)
    >>> data.recordings_with("calibration"), data.recordings_with("static")
    (['calibration'], ['points'])
    >>> data.epochs("calibration").rss_dbm.shape          # (epochs, anchors), NaN where not heard
    (1718, 12)
    """
    from . import floors as fl
    if floor is None:
        path, floor = fl.split_floor_selector(path)
    root, manifest = resolve_dataset(path)
    spec = read_manifest(manifest)                   # every key, type and value: the schema's
    name, title, license_, attribution, changes = spec.name, spec.title, spec.license, spec.attribution, spec.changes
    license_file = None
    if spec.license_file is not None:
        license_file = manifest_file(manifest, root, spec.license_file, "license_file: ")
    units, opts = spec.units, spec.readings
    time_scale, length_scale = TIME_SCALES[units.time], LENGTH_SCALES[units.length]
    sentinels, backward = opts.sentinels, opts.backward_time

    geometry = spec.geometry.given()
    anchors = read_anchors(manifest_file(manifest, root, spec.geometry.anchors, "[geometry] anchors: "))
    used = anchors[fl.USED_COLUMN].to_numpy(bool) if fl.USED_COLUMN in anchors.columns else np.ones(len(anchors), bool)
    floors = (tuple(dict.fromkeys(anchors[fl.FLOOR_COLUMN][used])) if fl.FLOOR_COLUMN in anchors.columns else ())
    if floor is not None and floor not in floors:
        raise ParameterError(f"data set {name!r} ({root}) has no floor {floor!r}" + (
            f"; its floors are {', '.join(floors)}" if floors else ": its anchors file has no floor column"))
    axes = [c for c in ("x", "y", "z") if c in anchors.columns]     # no z: a 2-D data set
    run_anchors = check_run_anchors(manifest, spec.run.anchors, tuple(anchors["id"]))
    if length_scale != 1.0:
        anchors[axes] *= length_scale

    recordings: dict[str, Recording] = {}
    invalid_found: dict[str, int] = {}
    dropped: dict[str, dict] = {}
    left_out: list[str] = []
    for rec in spec.recording:
        rname, role, point_column = rec.name, rec.role, rec.point_column
        where = f"[[recording]] {rname!r}: "
        path = manifest_file(manifest, root, rec.file, where)
        rule = spec.epochs.rule(rec.window_s)
        table, lines = read_readings_table(path, time_as_text=time_scale != 1.0)
        fl.check_readings_floors(table, lines, path, floors)
        if point_column is not None:
            _check_point_column(table, lines, point_column, path, manifest, where)
        readings = validate_readings_file(path, table, lines, lambda t: _convert(t, time_scale, length_scale),
                                          anchor_ids=anchors["id"], invalid_values_dbm=sentinels,
                                          # None when not declared: readings >= 0 dBm then warn
                                          valid_range_dbm=opts.valid_range_dbm, sort=backward == "sort")
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
                    fail(manifest, f"{where}{path.name} holds {len(senders)} {what} "
                                   f"({', '.join(map(shown, senders[:5]))}"
                                   f"{', ...' if len(senders) > 5 else ''}); a track follows one tag: give each "
                                   f"{what[:-1]}'s rows their own file and [[recording]]")
        reference = None
        if rec.reference_path is not None:
            reference = read_path_segments(manifest_file(manifest, root, rec.reference_path,
                                                         where + "reference_path: ")) * length_scale
        if floors and (rec.ranges is not None or rec.inertial is not None):
            fail(manifest, f"{where}{'ranges' if rec.ranges is not None else 'inertial'}: a data set with floors takes "
                           "RSS readings only (its streams are not split by floor yet); give each floor a data set "
                           "of its own to use its ranges or inertial samples")
        ranges, ranges_file = None, None
        origin = file_time_origin(table["time_s"]) if time_scale != 1.0 else None
        if rec.ranges is not None:
            from .ranges import read_ranges
            ranges_file = manifest_file(manifest, root, rec.ranges, where + "ranges: ")
            ranges = read_ranges(ranges_file, anchor_ids=anchors["id"], transmitters=readings["transmitter"].unique(),
                                 time_scale=time_scale, length_scale=length_scale, time_origin_raw=origin)
        inertial = None
        if rec.inertial is not None:
            from .inertial import read_inertial
            inertial = read_inertial(manifest_file(manifest, root, rec.inertial, where + "inertial: "),
                                     time_scale=time_scale, time_origin=origin, acceleration=units.acceleration,
                                     angular_rate=units.angular_rate, sort=backward == "sort")
        recordings[rname] = Recording(rname, role, path, readings, rule, point_column, reference, sorted_rows,
                                      ranges, ranges_file, inertial)
    anchors = anchors[used & ((anchors[fl.FLOOR_COLUMN] == floor).to_numpy() if floor is not None else True)]
    anchors = anchors.drop(columns=[fl.USED_COLUMN], errors="ignore").reset_index(drop=True)
    roles = {r.role for r in recordings.values()}
    if "calibration" not in roles:
        fail(manifest, ("no recording has role 'calibration'" if floor is None else
                         f"floor {floor!r}: no calibration recording has a row on this floor")
              + ": the channel is fitted on it (and never on the recordings it is scored on)")

    for rec in recordings.values():
        if rec.role == "calibration" and not rec.has_truth:
            fail(manifest, f"[[recording]] {rec.name!r}: a calibration recording needs true positions (x_m, y_m): "
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
            fail(manifest, "[geometry] tag_height_m: anchors have no z: a 2-D data set has no tag height (give the "
                           "anchors' z in the anchors file for 3-D distances, or drop tag_height_m)")
        with_z = [r.name for r in recordings.values() if r.readings["z_m"].notna().any()]
        if with_z:
            notes["z_m"] = (f"the anchors have no z (a 2-D data set): the true heights (z_m) of "
                            f"{', '.join(map(repr, with_z))} are ignored; distances are in the plane")
        for rec in recordings.values():
            rec.readings["z_m"] = np.nan
    elif height_value is not None:
        tag_height = manifest_number(manifest, {"tag_height_m": height_value}, "tag_height_m", "[geometry] ")
        notes["tag_height_m"] = f"{tag_height:g} m (manifest)"
        source, height_source = "[geometry] tag_height_m", "manifest"
    elif with_xy.any() and np.isfinite(truth_z[with_xy]).all():
        tag_height = float(np.median(truth_z[with_xy]))
        notes["tag_height_m"] = f"{tag_height:g} m: the median of the recorded true heights (z_m)"
        source, height_source = "the tag's height (the median of the recordings' z_m)", "median of the true z"
    else:
        fail(manifest, "[geometry] tag_height_m is required: the estimators need the tag's height, and not every "
                       "true position has a z_m (a 2-D data set has no z column in its anchors file)")
    if tag_height is not None:
        z = anchors["z"].to_numpy(float)
        low, high = z.min() - MAX_TAG_HEIGHT_OFFSET_M, z.max() + MAX_TAG_HEIGHT_OFFSET_M
        if not low <= tag_height <= high:
            fail(manifest, f"{source} = {tag_height:g} m is not within {MAX_TAG_HEIGHT_OFFSET_M:g} m of the "
                           f"anchors' heights ({z.min():g} to {z.max():g} m; allowed {low:g} to {high:g} m, "
                           "MAX_TAG_HEIGHT_OFFSET_M): a unit or sign error? (the manifest's values are in metres)")
        for rec in recordings.values():     # a true position without a height is at the tag's known height
            r = rec.readings
            r.loc[r["x_m"].notna() & r["z_m"].isna(), "z_m"] = tag_height
    outline_value = fl.per_floor(manifest, geometry, "outline", floors, floor)
    if isinstance(outline_value, list):      # a whole building of outlines per floor: the box around them all
        parts = [read_outline(manifest_file(manifest, root, manifest_string(manifest, {"outline": v}, "outline",
                                                                            "[geometry] "),
                                            "[geometry] outline: ")) * length_scale for v in outline_value]
        lo, hi = np.vstack(parts).min(axis=0), np.vstack(parts).max(axis=0)
        outline = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
    elif outline_value is not None:
        value = manifest_string(manifest, {"outline": outline_value}, "outline", "[geometry] ")
        outline = read_outline(manifest_file(manifest, root, value, "[geometry] outline: ")) * length_scale
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
    in_sample = in_sample_note(recordings)
    if in_sample:
        notes["in-sample scoring"] = in_sample
    if not roles & {"static", "track"}:
        notes["scoring"] = ("calibration only: no static or track recording, so nothing is localized or scored; "
                            "the channel is fitted on the calibration recordings")
    elif not any(r.role == "static" or (r.role == "track" and r.has_truth) for r in recordings.values()):
        notes["scoring"] = ("no static or track recording has a true position per epoch: the static methods are "
                            "not scored (tracks with a reference path are scored by their distance to it)")
    methods = manifest_methods(manifest, root, spec.method)
    files = [manifest, root / spec.geometry.anchors]
    for key in ("outline", "floor_plan"):
        value = geometry.get(key)
        files += [root / v for v in (value.values() if isinstance(value, dict) else [value] if value else [])
                  if isinstance(v, str)]
    files += [license_file] if license_file else []
    for rec in spec.recording:
        files += [root / f for f in (rec.file, rec.reference_path, rec.ranges, rec.inertial) if f is not None]
    files += [m.path for m in methods if m.path is not None]
    _floor_notes(notes, dropped, floor, left_out, recordings)
    data = Dataset(name if floor is None else f"{name}-{fl.floor_slug(floor)}", title if floor is None else
                   f"{title} (floor {floor})", root, license_, attribution, anchors, outline, tag_height, recordings,
                   changes, license_file, notes, tuple(files), height_source, methods=methods, floors=floors,
                   floor=floor, manifest_name=name, floor_plan=plan, floor_plan_extent_m=extent,
                   run_anchors=run_anchors)
    if floor is not None and name_problem(data.name):
        fail(manifest, f"floor {floor!r}: the floor's data set name {data.name!r} (the manifest's name and the "
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
    device_notes(data)
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
        fail(manifest, f"[geometry] {given} needs {absent} too: a plan is drawn at its georeference, "
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
            fail(manifest, f"{where}floor_plan_extent_m without a floor_plan for this floor")
        return None, None
    if extent is None:
        fail(manifest, f"{where}a floor_plan needs its floor_plan_extent_m (the table names none for this floor)")
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
        notes["split recordings"] = ("recordings spanning floors, split by floor: " + "; ".join(
            f"{r}: {c['rows'] - c['other floors'] - c['placeholder']:,} of its {c['rows']:,} rows on floor {floor}"
            for r, c in split.items()))
    cross = {r: c["cross-floor"] for r, c in dropped.items() if c["cross-floor"]}
    if cross:
        notes["cross-floor readings"] = (f"readings of the tag on floor {floor} by other floors' anchors, ignored (a "
                                         "floor's battery uses its own anchors; floor detection is out of scope): "
                                         + ", ".join(f"{n:,} in {r}" for r, n in cross.items()))
    if left_out:
        notes["left out"] = f"recordings with no row on floor {floor}: {', '.join(left_out)}"



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
            fail(manifest, f"{where}a track needs at least 2 epochs, {rec.file.name} makes {len(ep)} at window_s = "
                           f"{rule.window_s:g} s ({span}): the window is longer than the recording, or [units] time "
                           "is not the file's unit")
        fail(manifest, f"{where}a track needs at least 2 epochs, {rec.file.name} makes {len(ep)} as native scans "
                       f"(window_s = 0: one epoch per distinct time; {span}): the trackers step on the scans' clock, "
                       "which takes 2 scan times or more")
    if rule.window_s and rule.min_readings > 1 and not np.isfinite(ep.rss_dbm).any():
        every = epochs(rec.readings, data.anchor_ids, window_s=rule.window_s, aggregate=rule.aggregate,
                       group_by=() if rec.point_column is None else (rec.point_column,))
        most = int(every.n_readings.max()) if every.n_readings is not None and every.n_readings.size else 0
        if most < rule.min_readings:
            fail(manifest, f"[epochs] min_readings = {rule.min_readings:,} leaves no entry of recording {rname!r} "
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
                fail(manifest, f"[geometry] outline: {int(far.sum()):,} of the {len(xy):,} {what} of recording "
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
    fail(manifest, f"[geometry] outline (x {lo[0]:g}..{hi[0]:g}, y {lo[1]:g}..{hi[1]:g} m) contains none of the "
                   f"{len(anchors_xy)} anchors and none of the {len(truth_xy)} true positions: it is not this "
                   "site's floor (another unit, another file?)")



def _check_point_column(table: pd.DataFrame, lines, column: str, path: Path, manifest: Path, where: str) -> None:
    """The point column is an extra column of the file, and every row names its point (an empty id would make one
    'point' of rows in transit)."""
    reserved = READING_COLUMNS + OPTIONAL_READING_COLUMNS + (DEVICE_COLUMN,)
    if column in reserved or column not in table.columns:
        extra = [c for c in table.columns if c not in reserved]
        raise DataFormatError(f"{manifest}: {where}point_column {shown(column)} must name an extra column of "
                              f"{path.name} (not one of the long format's); its extra columns are "
                              f"{shown_names(extra)}")
    ids = table[column]
    text = ids.astype(object).where(ids.notna(), "").astype(str).str.strip()
    empty = (text == "").to_numpy()
    if empty.any():
        i = int(np.flatnonzero(empty)[0])
        raise DataFormatError(f"readings file {path}, line {lines[i]}, column {column!r}: the point id is empty "
                              f"({int(empty.sum())} such row(s)); every row of a point column ({manifest.name}, "
                              f"{where.rstrip(': ')}) names its point: drop rows taken between points, or label them")


