"""The manifest of a measured data set, ``dataset.toml`` (:func:`locbook.data.dataset.load_dataset` reads it):
its schema, and the rules for the names and files it gives.

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

Every key is checked by the schema, the pydantic models below (:class:`Manifest`; unknown keys, types,
ranges), and a broken rule raises :class:`~locbook.data.measured.DataFormatError` in one line naming the
manifest, the key and the value.
"""
from __future__ import annotations

import math
import os
import re
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

from pydantic import AfterValidator, BaseModel, ConfigDict, Field, ValidationError, model_validator
from pydantic_core import PydanticCustomError

from ..errors import ParameterError
from .csvfile import DataFormatError, decode_file_text, shown, shown_names
from .epoching import AGGREGATES, MAX_MIN_READINGS, MIN_WINDOW_S
from .inertial import ACCELERATION_UNITS, ANGULAR_RATE_UNITS
from .long_format import reading_options

__all__ = ["MANIFEST", "ROLES", "TIME_SCALES", "LENGTH_SCALES", "RESERVED_RECORDING_NAMES", "MAX_NAME_CHARS",
           "MAX_MANIFEST_BYTES", "EpochRule", "datasets_dir", "shipped_datasets", "name_problem", "fail",
           "manifest_string", "manifest_number", "manifest_file", "resolve_dataset", "run_anchors",
           "manifest_methods", "Manifest", "read_manifest"]

MANIFEST = "dataset.toml"
ROLES = ("calibration", "static", "track")
TIME_SCALES = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "ns": 1e-9}
LENGTH_SCALES = {"m": 1.0, "cm": 1e-2, "mm": 1e-3}
NAME_PATTERN = re.compile(r"[a-z0-9]+(-[a-z0-9]+)*")            # fullmatch: "$" would let a final newline in
RECORDING_NAME_PATTERN = re.compile(r"[a-z0-9][a-z0-9_-]*")
#: recording names the reports use for themselves ("pooled": every scored recording together)
RESERVED_RECORDING_NAMES = ("pooled",)
#: the longest data set or recording name: it names folders and files (255 bytes is a file name's limit)
MAX_NAME_CHARS = 64
#: the largest manifest (bytes) read: a dataset.toml is a page of text
MAX_MANIFEST_BYTES = 1 << 20


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


def name_problem(name) -> str:
    """``""`` if ``name`` is a valid data set name (the manifest's ``name``; it names the reports folder), else
    what is wrong with it, for a message."""
    if isinstance(name, str) and NAME_PATTERN.fullmatch(name) and len(name) <= MAX_NAME_CHARS:
        return ""
    return (f"name {shown(name)} must be lower-case letters, digits and single hyphens ([a-z0-9-]), at most "
            f"{MAX_NAME_CHARS} characters (MAX_NAME_CHARS); it names the reports folder")


def fail(manifest: Path, message: str):
    raise DataFormatError(f"{manifest}: {message}")


def manifest_string(manifest, raw: dict, key: str, where: str, *, required: bool = True, default: str = "") -> str:
    """``raw[key]`` as a non-empty string, stripped: a value the schema cannot type before the anchors file is read
    (a floor's entry of a table keyed by floor, :func:`locbook.data.floors.per_floor`)."""
    value = raw.get(key, None)
    if value is None:
        if required:
            fail(manifest, f"{where}{key!r} is required")
        return default
    if not isinstance(value, str) or not value.strip():
        fail(manifest, f"{where}{key!r} must be a non-empty string, got {shown(value)}")
    return value.strip()


def manifest_number(manifest, raw: dict, key: str, where: str, *, ge: float | None = None, gt: float | None = None):
    """``raw[key]`` as a finite float (``ge``/``gt``: its bound), for per-floor values as :func:`manifest_string`."""
    value = raw[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        fail(manifest, f"{where}{key!r} must be a finite number, got {shown(value)}")
    if (ge is not None and value < ge) or (gt is not None and value <= gt):
        fail(manifest, f"{where}{key!r} must be {'>= ' + str(ge) if ge is not None else '> ' + str(gt)}, "
                       f"got {value!r}")
    return float(value)


def manifest_file(manifest: Path, root: Path, value: str, where: str) -> Path:
    """The file the manifest names, checked before any byte of it is read: a relative path whose target (every
    symlink resolved) is a regular file inside the data set's folder. A link out of the folder is refused, naming
    the link and its target (a data set from elsewhere must not make locbook read, and quote, e.g.
    /proc/self/environ)."""
    try:
        path = root / value
        if Path(value).is_absolute() or ".." in Path(value).parts:
            fail(manifest, f"{where}{shown(value)} must be a file inside the data set's folder (a relative path)")
        target = Path(os.path.realpath(path))
        if not target.is_relative_to(Path(os.path.realpath(root))):
            fail(manifest, f"{where}{shown(value)} is a link to {str(target)!r}, outside the data set's folder "
                           f"{root}; a data set's files lie inside its folder: copy the file in")
        if not target.is_file():
            fail(manifest, f"{where}file {shown(value)} does not exist in {root}" if not target.exists() else
                 f"{where}{shown(value)} is not a regular file")
    except (OSError, ValueError) as exc:       # a NUL byte, a name too long, a link loop
        if isinstance(exc, DataFormatError):
            raise
        fail(manifest, f"{where}{shown(value)} is not a usable file name ({exc.__class__.__name__}: {exc})")
    return path


def resolve_dataset(path) -> tuple[Path, Path]:
    """``(folder, manifest)`` of a data set given as a shipped name, a folder or its ``dataset.toml``."""
    text = str(path)
    if isinstance(path, str) and NAME_PATTERN.fullmatch(text) and not Path(text).exists():
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


# -- the schema: pydantic models of the manifest's tables -------------------------------------------------------
def _refuse(message: str):
    """A rule's refusal inside a model: ``message`` is the manifest's one line after its ``where`` (:func:`_one_line`
    puts the file and the place in front)."""
    raise PydanticCustomError("manifest", "{text}", {"text": message})


def _text(value: str) -> str:
    """A non-empty string, stripped (the manifest's strings: names, files, ids)."""
    if not value.strip():
        raise PydanticCustomError("empty_text", "empty")
    return value.strip()


Text = Annotated[str, AfterValidator(_text)]


def _choice(key: str, choices, why: str = ""):
    """A validator: the value is one of ``choices``, else "KEY must be one of CHOICES, got VALUE"."""
    listed = sorted(choices) if isinstance(choices, dict) else choices

    def check(value):
        if not isinstance(value, str) or value not in choices:
            _refuse(f"{key} must be {why or f'one of {listed}'}, got {shown(value)}")
        return value
    return AfterValidator(check)


def _window(value):
    """``window_s``: a finite number >= 0, and 0 or at least :data:`MIN_WINDOW_S` (epoch rule)."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        _refuse(f"'window_s' must be a finite number, got {shown(value)}")
    if value < 0:
        _refuse(f"'window_s' must be >= 0, got {value!r}")
    window = float(value)
    if 0 < window < MIN_WINDOW_S:
        _refuse(f"'window_s' must be 0 or at least {MIN_WINDOW_S:g} s (MIN_WINDOW_S: shorter windows overflow the "
                f"tick count), got {window!r}")
    return window


def _min_readings(value):
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_MIN_READINGS:
        _refuse(f"min_readings must be an integer from 1 to {MAX_MIN_READINGS:,} (MAX_MIN_READINGS: more readings "
                f"than a window holds leave every entry not heard), got {shown(value)}")
    return value


def _anchor_list(value):
    if not isinstance(value, list) or not value or not all(isinstance(v, str) for v in value):
        _refuse(f"anchors must be a non-empty list of anchor ids (strings), got {shown(value)}")
    return value


class _Table(BaseModel):
    """A table of the manifest: no key but its fields (extra="forbid"), TOML's types as they are (strict)."""
    model_config = ConfigDict(extra="forbid", strict=True)

    def given(self) -> dict:
        """The keys the manifest gave, with their values (what a per-floor table lookup reads)."""
        return {k: getattr(self, k) for k in self.model_fields_set}


class Units(_Table):
    """``[units]``: the files' units (converted to SI on reading)."""
    time: Annotated[Any, _choice("time", TIME_SCALES)] = "s"
    length: Annotated[Any, _choice("length", LENGTH_SCALES)] = "m"
    rssi: Annotated[Any, _choice("rssi", ("dBm",), "'dBm' (convert the readings to dBm)")] = "dBm"
    acceleration: Annotated[Any, _choice("acceleration", ACCELERATION_UNITS)] = "m/s2"
    angular_rate: Annotated[Any, _choice("angular_rate", ANGULAR_RATE_UNITS)] = "rad/s"


class ReadingsOptions(_Table):
    """``[readings]``: sentinels and plausible range (:func:`locbook.data.long_format.reading_options`), clock rule."""
    valid_range_dbm: Any = None
    invalid_values_dbm: Any = None
    backward_time: Annotated[Any, _choice("backward_time", ("refuse", "sort"), "'refuse' or 'sort'")] = "refuse"

    @model_validator(mode="after")
    def _options(self):
        try:
            reading_options(self.invalid_values_dbm, self.valid_range_dbm)
        except ParameterError as exc:
            _refuse(str(exc))
        return self

    @property
    def sentinels(self):
        """The declared "no reading" values (dBm), a float array (:func:`~locbook.data.long_format.reading_options`)."""
        return reading_options(self.invalid_values_dbm, self.valid_range_dbm)[0]


class Geometry(_Table):
    """``[geometry]``; outline, tag height and floor plan may be tables keyed by floor (:func:`locbook.data.floors.
    per_floor` checks them against the anchors' floors)."""
    anchors: Text
    outline: Any = None
    tag_height_m: Any = None
    floor_plan: Any = None
    floor_plan_extent_m: Any = None


class EpochsSection(_Table):
    """``[epochs]``: the data set's epoch rule (:class:`EpochRule`)."""
    window_s: Annotated[Any, AfterValidator(_window)] = None
    aggregate: Annotated[Any, _choice("aggregate", AGGREGATES, f"one of {AGGREGATES}")] = "mean"
    min_readings: Annotated[Any, AfterValidator(_min_readings)] = 1

    def rule(self, window_s: float | None = None) -> EpochRule:
        """The rule, with a recording's own ``window_s`` where it gives one."""
        window = window_s if window_s is not None else self.window_s
        return EpochRule(0.0 if window is None else window, self.aggregate, self.min_readings)


class Run(_Table):
    """``[run]``: what a run of the battery uses (its anchors: checked against the anchors file by the loader)."""
    anchors: Annotated[Any, AfterValidator(_anchor_list)] = None


class RecordingEntry(_Table):
    """One ``[[recording]]`` (the field order is the order the rules are checked in)."""
    name: Annotated[Text, AfterValidator(lambda v: _recording_name(v))]
    role: Annotated[Text, _choice("role", ROLES, f"one of {ROLES}")]
    file: Text
    point_column: Text = None       # type: ignore[assignment]  (absent: None; TOML has no null)
    window_s: Annotated[Any, AfterValidator(_window)] = None
    reference_path: Text = None     # type: ignore[assignment]
    ranges: Text = None             # type: ignore[assignment]
    inertial: Text = None           # type: ignore[assignment]

    @model_validator(mode="after")
    def _by_role(self):
        if self.role == "track" and self.point_column is not None:
            _refuse("point_column belongs to calibration and static recordings (a tag standing at named points); a "
                    "track moves")
        if self.reference_path is not None and self.role != "track":
            _refuse(f"reference_path belongs to a track, not a {self.role} recording")
        return self


def _recording_name(name: str) -> str:
    if not RECORDING_NAME_PATTERN.fullmatch(name) or len(name) > MAX_NAME_CHARS:
        raise PydanticCustomError("manifest_indexed", "{text}", {"text": (
            f"name {shown(name)} must be lower-case letters, digits, '_' and '-', at most {MAX_NAME_CHARS} "
            "characters (MAX_NAME_CHARS)")})
    if name in RESERVED_RECORDING_NAMES:
        _refuse(f"the name is reserved: the results tables name every scored recording together {name!r}; rename "
                "the recording")
    return name


def _method_kind(value: str) -> str:
    from ..user_methods import METHOD_KINDS
    if value not in METHOD_KINDS:
        _refuse(f"kind must be one of {METHOD_KINDS}, got {shown(value)}")
    return value


class MethodEntry(_Table):
    """One ``[[method]]``: a method of your own (:class:`locbook.user_methods.UserMethod`)."""
    name: Text
    function: Text
    kind: Annotated[Text, AfterValidator(_method_kind)]


def _dataset_name(name: str) -> str:
    problem = name_problem(name)
    if problem:
        _refuse(problem)
    return name


class Manifest(_Table):
    """The whole ``dataset.toml`` (module docstring): :func:`read_manifest` validates one."""
    name: Annotated[Text, AfterValidator(_dataset_name)]
    title: Text
    license: Text
    attribution: Text
    changes: Text = ""
    license_file: Text = None       # type: ignore[assignment]
    units: Units = Units()
    readings: ReadingsOptions = ReadingsOptions()
    geometry: Geometry
    epochs: EpochsSection = EpochsSection()
    run: Run = Run()
    recording: Annotated[list[RecordingEntry], Field(min_length=1)]
    method: list[MethodEntry] = []

    @model_validator(mode="after")
    def _names_once(self):
        seen = set()
        for rec in self.recording:
            if rec.name in seen:
                _refuse(f"[[recording]] {rec.name!r}: the name appears twice")
            seen.add(rec.name)
        return self


#: the sections (tables) of the manifest, in the order their keys are checked; the order their values are
_SECTIONS = ("units", "readings", "geometry", "epochs", "run")
_VALUES = ("units", "readings", "geometry", "run", "epochs")
_TOP_FIELDS = ("name", "title", "license", "attribution", "changes", "license_file")
_NOT_A_TABLE = {"model_type", "model_attributes_type", "dict_type"}


def _rank(error: dict) -> tuple:
    """The order the rules are checked in (the first broken one is reported): keys before values, the manifest's
    own keys, then each section's, then each recording's in turn, then the methods'."""
    loc, kind = error["loc"], error["type"]
    if not loc:
        return (9,)
    head, extra = loc[0], kind == "extra_forbidden"
    if extra and len(loc) == 1:
        return (0,)
    if head in _SECTIONS:
        if len(loc) == 1 and kind in _NOT_A_TABLE:
            return (1, _SECTIONS.index(head), 0)
        if extra:
            return (1, _SECTIONS.index(head), 1)
        fields = list(Manifest.model_fields[head].annotation.model_fields)
        return (3, _VALUES.index(head), fields.index(loc[1]) if len(loc) > 1 else 99)   # 99: the whole table's
    if head in _TOP_FIELDS:
        return (2, _TOP_FIELDS.index(head))
    model = RecordingEntry if head == "recording" else MethodEntry
    group = 4 if head == "recording" else 5
    if len(loc) == 1:
        return (group, -1)
    if len(loc) == 2:
        return (group, loc[1], 0 if kind in _NOT_A_TABLE else 99)
    return (group, loc[1], 1 if extra else 2 + list(model.model_fields).index(loc[2]))


def _where(loc: tuple, kind: str, raw: dict) -> str:
    """The place a message names: ``[units] ``, ``[[recording]] 'walk': `` (by its index where the name is the
    problem or not yet read), ``[[method]] 'centroid': ``, or ``""`` for the manifest's own keys."""
    if not loc:
        return ""
    head = loc[0]
    if head in _SECTIONS:
        return f"[{head}] "
    if head not in ("recording", "method") or len(loc) == 1:
        return ""
    i, entry = loc[1], raw[head][loc[1]]
    name = entry.get("name") if isinstance(entry, dict) else None
    named = isinstance(name, str) and name.strip()
    if head == "method":
        return f"[[method]] {shown(name.strip())}: " if named else f"[[method]] {i + 1}: "
    by_index = (kind in _NOT_A_TABLE | {"extra_forbidden", "manifest_indexed"}
                or (len(loc) > 2 and loc[2] == "name" and kind != "manifest"))
    return f"[[recording]] {i + 1}: " if by_index or not named else f"[[recording]] {name.strip()!r}: "


def _one_line(exc, raw: dict) -> str:
    """The first broken rule of a pydantic ``ValidationError`` (:func:`_rank`), in the manifest's words."""
    errors = exc.errors()
    error = min(errors, key=_rank)
    loc, kind, value = error["loc"], error["type"], error.get("input")
    where = _where(loc, kind, raw)
    key = loc[-1] if loc else ""
    if kind in ("manifest", "manifest_indexed"):
        return where + error["ctx"]["text"]
    if kind == "extra_forbidden":
        unknown = sorted(e["loc"][-1] for e in errors if e["type"] == kind and e["loc"][:-1] == loc[:-1])
        model = {1: Manifest, 2: Manifest.model_fields[loc[0]].annotation if loc[0] in _SECTIONS else None,
                 3: RecordingEntry if loc[0] == "recording" else MethodEntry}[len(loc)]
        return f"{where}unknown key(s) {shown_names(unknown)}; allowed: {sorted(model.model_fields)}"
    if loc == ("geometry",) and kind == "missing":      # no [geometry] at all: its one required key is missing
        return "[geometry] 'anchors' is required"
    if loc[0] == "recording" and len(loc) == 1:
        return f"no [[recording]]: a data set lists its readings files, each with a role ({', '.join(ROLES)})"
    if loc[0] == "method" and len(loc) == 1:
        return "[[method]] must be an array of tables ([[method]] with name, function and kind)"
    if kind in _NOT_A_TABLE:
        return f"[{loc[0]}] must be a table" if len(loc) == 1 else f"{where}must be a table"
    if kind == "missing":
        return f"{where}{key!r} is required" + (", a non-empty string" if loc[0] == "method" else "")
    return f"{where}{key!r} must be a non-empty string, got {shown(value)}"   # string_type, empty_text


def read_manifest(manifest: Path) -> Manifest:
    """The validated manifest: at most :data:`MAX_MANIFEST_BYTES`, UTF-8, TOML, and every
    key, type and value by the schema (:class:`Manifest`); a broken rule raises :class:`DataFormatError` in one line
    naming the manifest, the place and the value."""
    size = manifest.stat().st_size
    if size > MAX_MANIFEST_BYTES:
        fail(manifest, f"the manifest is {size:,} bytes; a {MANIFEST} is at most {MAX_MANIFEST_BYTES:,} "
                       "(MAX_MANIFEST_BYTES)")
    text = decode_file_text(manifest.read_bytes(), manifest, "manifest")
    try:
        raw = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise DataFormatError(f"{manifest}: not valid TOML ({exc})") from None
    try:
        return Manifest.model_validate(raw)
    except ValidationError as exc:
        raise DataFormatError(f"{manifest}: {_one_line(exc, raw)}") from None


def run_anchors(manifest: Path, value, known: tuple) -> tuple[str, ...]:
    """``[run] anchors`` (a list of strings, :class:`Run`), checked by the rule of ``-p anchors``
    (:func:`locbook.data.selection.check_anchor_ids`: each an anchor, none twice, at least 3)."""
    if value is None:
        return ()
    from .selection import check_anchor_ids
    try:
        return check_anchor_ids(value, known, "[run] anchors")
    except ParameterError as exc:
        raise DataFormatError(f"{manifest}: {exc}") from None


def manifest_methods(manifest: Path, root: Path, entries) -> tuple:
    """The ``[[method]]`` tables (:class:`MethodEntry`) as methods, checked as the command line's are
    (:meth:`locbook.user_methods.UserMethod.parse`; a file through :func:`manifest_file`: relative, inside the
    folder), no name twice. Nothing is imported here: ``locbook data check`` says whether each imports."""
    from ..user_methods import UserMethod
    out, seen = [], {}
    for entry in entries:
        where = f"[[method]] {shown(entry.name)}: "
        target = entry.function.rpartition(":")[0]
        if target.endswith(".py"):
            manifest_file(manifest, root, target, f"{where}function: ")
        try:
            method = UserMethod.parse(entry.name, entry.function, entry.kind, base=root, source="manifest")
        except ParameterError as exc:
            fail(manifest, f"{where}{exc}")
        if method.name.lower() in seen:
            fail(manifest, f"{where}the name appears twice")
        seen[method.name.lower()] = method
        out.append(method)
    return tuple(out)
