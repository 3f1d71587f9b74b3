"""Floors (zones, scenes) of one data set, placeholder anchors, and the floor-plan image under the maps.

**Floors.** An optional ``floor`` column in the anchors file names each anchor's floor, and the same column in every
readings file names the floor the tag is on at each row (its truth floor, known like its true position). A zone or
a scene of one building is the same concept and uses the same column. Labels are text (``F1``, ``1``, ``basement``):
letters, digits, ``_`` and ``-``, from a letter or digit, at most :data:`MAX_FLOOR_LABEL_CHARS` characters; compared
as written (``01`` is not ``1``). The column is all or none: an anchors file with it gives every anchor's floor,
and then every readings file has it on every row (a row without one is refused naming its line); a readings file
with it beside an anchors file without it is refused, and so is a label no anchor has.

**One floor is one data set** (:func:`locbook.data.dataset.load_dataset` with ``floor=``, or the selector
``DIR@F1``): that floor's anchors, each recording's rows whose truth floor is that floor (a recording spanning floors
is split, counted in the notes; one with no row on it is left out, noted), that floor's outline and plan, and the
channel fitted on that floor's calibration rows alone. Its name is the manifest's with the floor's slug
(:func:`floor_slug`: ``example-f1``), so its reports are a data run of their own, ``data-example-f1/``, and
``locbook run --data DIR`` runs every floor in turn. Readings of a floor's tag by another floor's anchors are
ignored on every floor and counted (no floor detection: the floor is known from the truth column; a method that
infers it is out of scope). The whole building (no floor selected) loads for ``locbook data check`` (every floor is
loaded and checked too, their notes collected), but is not run: :func:`require_one_floor` refuses it.

**Placeholder anchors.** An optional ``used`` column in the anchors file (``true``/``false``, also ``1``/``0``,
``yes``/``no``; every row) declares anchors unused: a placeholder is not an anchor of any method, may share its
point with another anchor (the 1 mm separation rule applies to used anchors, per floor), and every reading it
logged is ignored and counted.

**The floor plan** (``[geometry] floor_plan = "plan.png"`` with ``floor_plan_extent_m = [x0, x1, y0, y1]``, or tables
keyed by floor label): a PNG inside the folder that matplotlib reads, drawn under every map and track figure of the
measured experiments (:func:`locbook.plotting.draw_floor`) with matplotlib's ``imshow`` extent: the image's left
edge at ``x0``, right at ``x1``, its bottom row at ``y0`` and its top row at ``y1`` (metres, SI like every value
of the manifest; ``[units] length`` is the files'). ``outline`` and ``tag_height_m`` may be such tables too; a
floor a table leaves out has none (the default outline, no plan; the median true height).
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pandas as pd

from ..errors import ParameterError
from .csvfile import MAX_COORDINATE_M, DataFormatError, shown, shown_names

__all__ = ["FLOOR_COLUMN", "USED_COLUMN", "FLOOR_SELECTOR", "MAX_FLOOR_LABEL_CHARS", "MAX_FLOOR_PLAN_BYTES",
           "PNG_SIGNATURE", "floor_slug", "split_floor_selector", "anchor_columns", "check_readings_floors",
           "select_rows", "per_floor", "read_floor_plan", "floor_plan_extent", "require_one_floor", "floor_runs"]

#: the column of anchors and readings naming the floor (zone, scene)
FLOOR_COLUMN = "floor"
#: the anchors' column declaring an anchor used (true) or a placeholder (false)
USED_COLUMN = "used"
#: ``DIR@F1``: the data set in DIR, floor F1 (a floor label holds no "@", so the last one separates)
FLOOR_SELECTOR = "@"
#: a floor label names a reports folder (``data-<name>-<slug>``): short, and a file name's characters only
MAX_FLOOR_LABEL_CHARS = 32
_LABEL = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]*")
#: the largest floor-plan file read (bytes): a plan drawn under a map needs no more (a 4000 x 4000 RGBA PNG is
#: about 64 MB decoded, beyond any figure's pixels)
MAX_FLOOR_PLAN_BYTES = 16 << 20
#: the eight bytes every PNG starts with (PNG specification, 5.2)
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_TRUE, _FALSE = {"true", "1", "yes"}, {"false", "0", "no"}


def _text(column: pd.Series) -> pd.Series:
    """A column as stripped text, ``""`` where missing (categories and objects alike)."""
    return column.astype(object).where(column.notna(), "").astype(str).str.strip()


def floor_slug(label: str) -> str:
    """The floor label as it names a data set and its reports folder: lower case, ``_`` as ``-``, hyphens single
    (``F_1`` -> ``f-1``)."""
    return re.sub("-+", "-", label.lower().replace("_", "-")).strip("-")


def split_floor_selector(path):
    """``(data set, floor or None)`` of a ``--data`` value: a path that exists (or a shipped name) is the data set
    itself; else ``DIR@F1`` selects floor ``F1`` of ``DIR`` (split at the last ``@``)."""
    text = str(path)
    if FLOOR_SELECTOR not in text or Path(text).expanduser().exists():
        return path, None
    base, _, floor = text.rpartition(FLOOR_SELECTOR)
    return (type(path)(base) if isinstance(path, Path) else base), floor


def anchor_columns(table: pd.DataFrame, lines, source: str):
    """``(floor labels (m,) or None, used (m,) bool)`` of an anchors table (:func:`locbook.data.measured.
    read_anchors`): the ``floor`` column, every row labelled (module docstring), and the ``used`` column (default
    every anchor used). Raises DataFormatError naming the line and column."""
    floors = None
    if FLOOR_COLUMN in table.columns:
        text = _text(table[FLOOR_COLUMN])
        _check_labels(text.to_numpy(), lines, source, "an anchors file with a floor column gives every anchor's floor")
        floors = text.to_numpy(object)
    used = np.ones(len(table), dtype=bool)
    if USED_COLUMN in table.columns:
        text = _text(table[USED_COLUMN]).str.lower()
        bad = ~text.isin(_TRUE | _FALSE).to_numpy()
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise DataFormatError(f"{source}, line {lines[i]}, column {USED_COLUMN!r}: "
                                  f"{shown(table[USED_COLUMN].iloc[i])} is not true or false (a placeholder anchor "
                                  "is 'false'; every row says which)")
        used = text.isin(_TRUE).to_numpy()
        if not used.any():
            raise DataFormatError(f"{source}, column {USED_COLUMN!r}: every anchor is a placeholder (used = false); "
                                  "a data set needs anchors")
    return floors, used


def _check_labels(labels, lines, source: str, rule: str) -> None:
    empty = labels == ""
    if empty.any():
        i = int(np.flatnonzero(empty)[0])
        raise DataFormatError(f"{source}, line {lines[i]}, column {FLOOR_COLUMN!r}: the floor is empty "
                              f"({int(empty.sum()):,} of the {len(labels):,} rows have none): {rule}")
    for value in pd.unique(labels):
        if not _LABEL.fullmatch(value) or len(value) > MAX_FLOOR_LABEL_CHARS:
            i = int(np.flatnonzero(labels == value)[0])
            raise DataFormatError(f"{source}, line {lines[i]}, column {FLOOR_COLUMN!r}: floor {shown(value)} must be "
                                  f"letters, digits, '_' and '-', from a letter or digit, at most "
                                  f"{MAX_FLOOR_LABEL_CHARS} characters (MAX_FLOOR_LABEL_CHARS): it names a reports "
                                  "folder")


def check_floor_labels(floors, source: str) -> tuple[str, ...]:
    """The floors of the anchors (labels in file order), refusing two labels of one slug (one reports folder)."""
    labels = tuple(dict.fromkeys(floors))
    slugs: dict[str, str] = {}
    for label in labels:
        other = slugs.setdefault(floor_slug(label), label)
        if other != label:
            raise DataFormatError(f"{source}, column {FLOOR_COLUMN!r}: floors {other!r} and {label!r} name one reports "
                                  f"folder ({floor_slug(label)!r}); give them labels that differ beyond case and '_'")
    return labels


def check_readings_floors(table: pd.DataFrame, lines, path: Path, floors) -> None:
    """The ``floor`` column of a readings table (from :func:`read_readings_table`, lines as in the file): present
    exactly when the anchors have floors (``floors``: their labels, or None), on every row, naming a known floor."""
    source = f"readings file {path}"
    if FLOOR_COLUMN not in table.columns:
        if floors:
            raise DataFormatError(f"{source}: no {FLOOR_COLUMN!r} column, but the anchors have floors "
                                  f"({shown_names(floors)}): every readings file names the tag's floor on each row")
        return
    if not floors:
        raise DataFormatError(f"{source}: a {FLOOR_COLUMN!r} column, but the anchors file has none: give each "
                              "anchor its floor (or drop the column, or rename it to keep it as an extra column)")
    text = _text(table[FLOOR_COLUMN]).to_numpy(object)
    _check_labels(text, lines, source, "a readings file with a floor column names the tag's floor on every row")
    unknown = ~np.isin(text, np.asarray(floors, dtype=object))
    if unknown.any():
        i = int(np.flatnonzero(unknown)[0])
        raise DataFormatError(f"{source}, line {lines[i]}, column {FLOOR_COLUMN!r}: floor {shown(text[i])} has no "
                              f"anchor (the anchors' floors are {shown_names(floors)})")


def select_rows(readings: pd.DataFrame, anchors: pd.DataFrame, floor: str | None) -> tuple[pd.DataFrame, dict]:
    """A validated recording's rows for one floor's battery: the rows whose receiver is a used anchor (placeholders'
    rows dropped) and, with ``floor``, whose truth floor is ``floor`` and whose receiver is on it. Returns the rows
    (index renumbered) and the counts ``{"rows", "placeholder", "other floors", "cross-floor"}``: the rows read,
    the placeholders' rows dropped, the rows of the tag on other floors, and the rows of the tag on ``floor`` heard
    by other floors' anchors (ignored)."""
    ids = anchors["id"].astype(str)
    placeholder_ids = set(ids[~anchors[USED_COLUMN]]) if USED_COLUMN in anchors.columns else set()
    counts = {"rows": len(readings), "placeholder": 0, "other floors": 0, "cross-floor": 0}
    if not placeholder_ids and floor is None:       # a data set without floors or placeholders: as it was read
        return readings, counts
    receiver = readings["receiver"]                 # ids as text (categories or objects): compared, never copied
    placeholder = receiver.isin(placeholder_ids).to_numpy()
    keep = ~placeholder
    counts["placeholder"] = int(placeholder.sum())
    if floor is not None:
        on_floor = (_text(readings[FLOOR_COLUMN]) == floor).to_numpy()
        floor_of = dict(zip(ids, anchors[FLOOR_COLUMN]))
        heard_here = (receiver.map(floor_of).astype(object) == floor).to_numpy()
        counts["other floors"] = int((~on_floor & keep).sum())
        counts["cross-floor"] = int((on_floor & ~heard_here & keep).sum())
        keep &= on_floor & heard_here
    if keep.all():
        return readings, counts
    return readings[keep].reset_index(drop=True), counts


def per_floor(manifest: Path, section: dict, key: str, floors, floor: str | None, where: str = "[geometry] "):
    """The value of ``section[key]`` for ``floor``: the value itself (every floor), or, for a table keyed by floor
    label (``[geometry.outline] F1 = "f1.csv"``), the floor's entry (None where it names none; every key a known
    floor). ``floor`` None (the whole building) returns the table's values as a list. Absent: None."""
    from .manifest import fail
    if key not in section:
        return None
    value = section[key]
    if not isinstance(value, dict):
        return value
    if not floors:
        fail(manifest, f"{where}{key} is a table keyed by floor, but the anchors have no floor column")
    unknown = [k for k in value if k not in floors]
    if unknown:
        fail(manifest, f"{where}{key}: floor(s) {shown_names(unknown)} have no anchor (the floors are "
                       f"{shown_names(floors)})")
    return list(value.values()) if floor is None else value.get(floor)


def read_floor_plan(manifest: Path, root: Path, value, where: str) -> Path:
    """The floor-plan file: a relative path inside the folder (:func:`locbook.data.manifest.manifest_file`), a PNG (its
    signature) of at most :data:`MAX_FLOOR_PLAN_BYTES` that matplotlib reads. Raises DataFormatError in one line."""
    from .manifest import fail, manifest_file, manifest_string
    name = manifest_string(manifest, {"floor_plan": value}, "floor_plan", where)
    path = manifest_file(manifest, root, name, where + "floor_plan: ")
    size = path.stat().st_size
    if size > MAX_FLOOR_PLAN_BYTES:
        fail(manifest, f"{where}floor_plan {path.name}: {size:,} bytes; a floor plan is at most "
                       f"{MAX_FLOOR_PLAN_BYTES:,} (MAX_FLOOR_PLAN_BYTES)")
    with open(path, "rb") as fh:
        head = fh.read(len(PNG_SIGNATURE))
    if head != PNG_SIGNATURE:
        fail(manifest, f"{where}floor_plan {path.name} is not a PNG (it does not start with the PNG signature); "
                       "save the plan as PNG")
    try:
        image = plan_image(path)
    except Exception as exc:        # a truncated or corrupt PNG: whatever the decoder raises, one line
        fail(manifest, f"{where}floor_plan {path.name}: matplotlib cannot read it ({type(exc).__name__}: "
                       f"{' '.join(str(exc).split())[:120]})")
    if image.ndim not in (2, 3) or min(image.shape[:2]) < 1:
        fail(manifest, f"{where}floor_plan {path.name}: not an image (shape {image.shape})")
    return path


def plan_image(path) -> np.ndarray:
    """The plan's pixels as matplotlib reads them (``matplotlib.image.imread``: floats in [0, 1], ``(H, W[, C])``)."""
    import matplotlib.image as mpimg
    return mpimg.imread(str(path))


def floor_plan_extent(manifest: Path, value, where: str) -> tuple[float, float, float, float]:
    """``floor_plan_extent_m = [x0, x1, y0, y1]``: four finite numbers (metres), ``x0 < x1``, ``y0 < y1``, each less
    than MAX_COORDINATE_M in magnitude."""
    from .manifest import fail
    ok = (isinstance(value, list) and len(value) == 4
          and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in value))
    if not ok:
        fail(manifest, f"{where}floor_plan_extent_m must be four finite numbers [x0, x1, y0, y1] (metres), got "
                       f"{shown(value)}")
    x0, x1, y0, y1 = (float(v) for v in value)
    if not (x0 < x1 and y0 < y1):
        fail(manifest, f"{where}floor_plan_extent_m = {value}: needs x0 < x1 and y0 < y1 (the plan's left, right, "
                       "bottom and top edges, as matplotlib's imshow extent)")
    if max(abs(v) for v in (x0, x1, y0, y1)) >= MAX_COORDINATE_M:
        fail(manifest, f"{where}floor_plan_extent_m = {value}: coordinates are less than {MAX_COORDINATE_M:g} m "
                       "(MAX_COORDINATE_M)")
    return (x0, x1, y0, y1)


def require_one_floor(data) -> None:
    """Refuse to run the battery on a whole building: a data set with floors runs one floor at a time (module
    docstring). ParameterError naming the floors and the selector."""
    if data.floors and data.floor is None:
        picks = ", ".join(f"{data.root}{FLOOR_SELECTOR}{f}" for f in data.floors)
        raise ParameterError(f"data set {data.name!r} has floors {', '.join(data.floors)}: the battery runs on one "
                             f"floor at a time (load_dataset(DIR, floor=...), or {picks}); `locbook run --data DIR` "
                             "runs every floor")


def floor_runs(data: str) -> list[str]:
    """The ``--data`` values a data run of ``data`` makes: ``[data]`` for a data set without floors or with a floor
    selected, else one ``DATA@FLOOR`` per floor, in the anchors file's order (each its own reports folder)."""
    import tomllib

    from .manifest import resolve_dataset
    from .measured import read_anchors
    base, floor = split_floor_selector(data)
    if floor is not None:
        return [data]
    try:        # only the manifest and the anchors file: each floor's run loads (and checks) its data set
        root, manifest = resolve_dataset(data)
        anchors = read_anchors(root / tomllib.loads(manifest.read_text(encoding="utf-8"))["geometry"]["anchors"])
    except Exception:           # a malformed data set: the run's own loading names the problem
        return [data]
    if FLOOR_COLUMN not in anchors.columns:
        return [data]
    used = anchors[USED_COLUMN].to_numpy(bool) if USED_COLUMN in anchors.columns else np.ones(len(anchors), bool)
    return [f"{data}{FLOOR_SELECTOR}{f}" for f in dict.fromkeys(anchors[FLOOR_COLUMN][used])]
