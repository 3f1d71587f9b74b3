"""Convert the Daniş et al. position-annotated BLE RSSI data set from its published log files to locbook's long format.

Provenance of the files beside this script (the source is CC0 1.0, so nothing is required; the changes are listed
anyway): github.com/philotuxo/Position-Annotated-BLE-RSSI-Dataset, commit
77474b69dc7d73fc5b07b74d7b4b65f3235a663e. SOURCE_FOLDER is that repository's top folder (it holds cnf/, hst/,
trk/ and LICENSE.md); only these source files are read, none is changed:

- ``cnf/tetam.dev``: the line ``Dongles:{MAC: [[x, y, z], colour, alias], ...}`` (metres) gives the 12 receivers.
  Each is renamed ``R01``..``R12`` in the order of its alias (``sensor10, 11, 12, 20, 21, 22, 30, 31, 32, 40, 41,
  42``) -> ``anchors.csv`` (``id,x,y,z``; the MACs and aliases are in README.md). Colour and alias are dropped.
- ``cnf/tetam.par``: ``limits`` ``[x0, y0, x1, y1]`` (metres), the rectangle the authors' algorithms work in ->
  ``outline.csv``, its four corners counter-clockwise from (x0, y0). (The occupancy grids ``occ/*.occ`` span the
  same rectangle; their blocked cells are furniture inside it, not a different outline.)
- ``hst/set_1/*.mbd`` (81 points) -> ``calibration.csv`` and ``hst/set_2/*.mbd`` (45 points) -> ``points.csv``. A
  file ``sensorNN_X_Y_Z.mbd`` holds one receiver's readings of the beacon standing still at (X, Y, Z) metres, one
  line ``timestamp,sensorMAC,beaconMAC,RSSI`` per packet (timestamp: seconds since 1970, UTC; RSSI: dBm) for about
  30 minutes. **Cut:** only the lines less than ``CUT_S`` (20 s) after the file's first line are kept (the rest
  of each file, about 99 % of the 5.2 million lines, is dropped: 30 s would make the folder larger than 6 MB). The
  points are named ``S1-01``.. and ``S2-01``.. in the order of their first reading (the ``point`` column); X, Y, Z of
  the file name become ``x_m, y_m, z_m`` (Z is the beacon's height). The file's sensor MAC must be the alias's MAC
  (checked). **Sorted:** a set's rows are put in time order (ties: by receiver id), which also puts them point by point,
  as the points were recorded one after the other (checked: no two points overlap in time).
- ``trk/<track>_all_sensors.mbd`` (9 tracks) -> ``<track>.csv``. Each line is
  ``timestamp,sensorMAC,beaconMAC,RSSI,x,y,z,R11,..,R33``: a packet and the camera rig's pose at that time
  (position in metres, 3x3 orientation matrix). The rows keep the source order (the merge of the 12 receivers'
  logs; 7 files have one row a fraction of a millisecond earlier than the row before it, which the manifest's
  ``backward_time = "sort"`` counts and sorts at load). ``x, y, z`` become ``x_m, y_m, z_m``; **dropped:** the
  orientation matrix (it is the camera's orientation, not the direction the tag is carried in, so no heading is
  derived from it).

Every readings file gets the columns ``time_s`` (seconds since the file's earliest timestamp: ``calibration.csv``
and ``points.csv``, since the set's first reading; a track, since its first row; computed as exact decimal
differences of the source text and written without trailing zeros), ``transmitter`` (the beacon's MAC,
unchanged), ``receiver`` (``R01``..``R12``), ``rssi_dbm`` (the source text, unchanged; impossible values such
as +42 dBm are kept and declared in dataset.toml), ``x_m, y_m, z_m`` and, for the static sets, ``point``.
Coordinates are written with ``repr(float(text))`` (``7.00`` -> ``7.0``: the same value). ``LICENSE.md`` is copied
unchanged. The output is the same on every run (sorted file lists, no clocks, no randomness).

Usage: ``python convert.py SOURCE_FOLDER [DEST_FOLDER]`` (DEST defaults to this script's folder).
"""
from __future__ import annotations

import ast
import csv
import json
import re
import shutil
import sys
from decimal import Decimal
from pathlib import Path

CUT_S = Decimal(20)
SETS = {"set_1": ("calibration.csv", "S1"), "set_2": ("points.csv", "S2")}
TRACKS = ("straight_01", "straight_02", "straight_03", "straight_04", "straight_05", "rectangular_with_rotation",
          "rectangular_without_rotation", "zigzagging_with_rotation", "zigzagging_without_rotation")
POINT_FILE = re.compile(r"^(sensor\d+)_(-?[0-9.]+)_(-?[0-9.]+)_(-?[0-9.]+)\.mbd$")
HEADER = ["time_s", "transmitter", "receiver", "rssi_dbm", "x_m", "y_m", "z_m"]


def _number(text: str) -> str:
    """A coordinate as written: every digit of the value (``repr``)."""
    return repr(float(text))


def _seconds(d: Decimal) -> str:
    """An exact decimal number of seconds without trailing zeros."""
    s = format(d, "f")
    if "." in s:
        s = s.rstrip("0").rstrip(".")
    return "0" if s in ("", "-0") else s


def _lines(path: Path) -> list[list[str]]:
    with open(path, newline="") as fh:
        return [row for row in csv.reader(fh) if row]


def receivers(source: Path) -> list[tuple[str, str, str, list[str]]]:
    """``(id, MAC, alias, [x, y, z] text)`` of the receivers, in alias order."""
    for line in (source / "cnf" / "tetam.dev").read_text().splitlines():
        if line.startswith("Dongles:"):
            devices = json.loads(line.split(":", 1)[1], parse_float=str, parse_int=str)
            break
    else:
        raise SystemExit("cnf/tetam.dev has no 'Dongles:' line")
    rows = sorted((value[2], mac, value[0]) for mac, value in devices.items())
    return [(f"R{i + 1:02d}", mac, alias, xyz) for i, (alias, mac, xyz) in enumerate(rows)]


def convert_set(folder: Path, dest: Path, prefix: str, by_alias: dict, by_mac: dict) -> tuple[int, int, int]:
    files = sorted(folder.glob("*.mbd"))
    kept = {}             # (X, Y, Z) text -> list of (time Decimal, receiver id, beacon, rssi text)
    total = 0
    for path in files:
        m = POINT_FILE.match(path.name)
        if not m:
            raise SystemExit(f"unexpected file name {path}")
        alias, x, y, z = m.groups()
        rid, mac = by_alias[alias]
        lines = _lines(path)
        total += len(lines)
        t0 = Decimal(lines[0][0])
        for t, sensor, beacon, rssi in lines:
            if sensor != mac:
                raise SystemExit(f"{path}: sensor {sensor} is not {alias}'s MAC {mac}")
            if Decimal(t) - t0 < CUT_S:
                kept.setdefault((x, y, z), []).append((Decimal(t), rid, beacon, rssi))
    starts = sorted((min(r[0] for r in rows), key) for key, rows in kept.items())
    spans = [(min(r[0] for r in kept[k]), max(r[0] for r in kept[k])) for _, k in starts]
    if any(b[0] <= a[1] for a, b in zip(spans, spans[1:])):
        raise SystemExit(f"{folder}: two points overlap in time; the time order would mix them")
    origin = starts[0][0]
    out_rows = []
    for i, (_, key) in enumerate(starts):
        x, y, z = (_number(v) for v in key)
        for t, rid, beacon, rssi in kept[key]:
            out_rows.append((t, rid, [_seconds(t - origin), beacon, rid, rssi, x, y, z, f"{prefix}-{i + 1:02d}"]))
    out_rows.sort(key=lambda r: (r[0], r[1]))
    with open(dest, "w", newline="") as fh:
        out = csv.writer(fh, lineterminator="\n")
        out.writerow(HEADER + ["point"])
        out.writerows(r[2] for r in out_rows)
    return len(starts), total, len(out_rows)


def convert_track(path: Path, dest: Path, by_mac: dict) -> int:
    lines = _lines(path)
    origin = min(Decimal(row[0]) for row in lines)
    with open(dest, "w", newline="") as fh:
        out = csv.writer(fh, lineterminator="\n")
        out.writerow(HEADER)
        for row in lines:
            if len(row) != 16:
                raise SystemExit(f"{path}: a line with {len(row)} fields, not 16")
            t, sensor, beacon, rssi, x, y, z = row[:7]
            out.writerow([_seconds(Decimal(t) - origin), beacon, by_mac[sensor], rssi,
                          _number(x), _number(y), _number(z)])
    return len(lines)


def convert(source: Path, dest: Path) -> None:
    recs = receivers(source)
    by_alias = {alias: (rid, mac) for rid, mac, alias, _ in recs}
    by_mac = {mac: rid for rid, mac, _, _ in recs}
    with open(dest / "anchors.csv", "w", newline="") as fh:
        out = csv.writer(fh, lineterminator="\n")
        out.writerow(["id", "x", "y", "z"])
        for rid, _, _, xyz in recs:
            out.writerow([rid] + [_number(v) for v in xyz])
    par = ast.literal_eval((source / "cnf" / "tetam.par").read_text().strip())
    x0, y0, x1, y1 = (repr(float(v)) for v in par["limits"])
    with open(dest / "outline.csv", "w", newline="") as fh:
        out = csv.writer(fh, lineterminator="\n")
        out.writerow(["x", "y"])
        out.writerows([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])
    print(f"anchors.csv: {len(recs)} receivers; outline.csv: {x0}..{x1} x {y0}..{y1} m")
    for name, (file, prefix) in SETS.items():
        points, total, rows = convert_set(source / "hst" / name, dest / file, prefix, by_alias, by_mac)
        print(f"hst/{name}: {points} points, {total} lines -> {file}: {rows} rows (first {CUT_S} s of each file)")
    for track in TRACKS:
        n = convert_track(source / "trk" / f"{track}_all_sensors.mbd", dest / f"{track}.csv", by_mac)
        print(f"trk/{track}_all_sensors.mbd -> {track}.csv: {n} rows")
    shutil.copyfile(source / "LICENSE.md", dest / "LICENSE.md")


if __name__ == "__main__":
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    convert(Path(sys.argv[1]), Path(sys.argv[2]) if len(sys.argv) == 3 else Path(__file__).parent)
