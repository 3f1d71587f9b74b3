"""Convert the Kolakowski (2021) BLE RSS data set from its published wide CSV files to locbook's long format.

Provenance of the files beside this script (CC BY 4.0 asks that changes be indicated): the source files
(github.com/marckolak/ble-rss-fingerprints-calib2021, commit 0a69aaa7006909d3f8f9f3a14fcba9405d404fa5; Zenodo
doi:10.5281/zenodo.5457591) have one row per epoch with columns ``ts`` (ns since 1970), ``x``, ``heading``, ``y`` and
``rssi_1..rssi_6``. Each row becomes six rows (one per anchor) of ``time_s`` (seconds since the file's first row,
``(ts - ts_0) * 1e-9``), ``transmitter`` (``tag``), ``receiver`` (the anchor id), ``rssi_dbm`` (the value, empty =
not heard), and the truth ``x_m``, ``y_m``, ``heading_rad`` where the file has it. No value is changed: every
number is written with all its digits (``repr``). ``anchors.csv``, ``outline.csv`` (the source's ``layout.csv``) and
``path_reference.csv`` are copied unchanged.

Usage: ``python convert.py SOURCE_FOLDER [DEST_FOLDER]`` (DEST defaults to this script's folder).
"""
from __future__ import annotations

import csv
import shutil
import sys
from pathlib import Path

FILES = {"calibration_df.csv": "calibration.csv", "test_robot_df.csv": "robot.csv", "test_walk_df.csv": "walk.csv"}
COPIED = {"anchors.csv": "anchors.csv", "layout.csv": "outline.csv", "path_reference.csv": "path_reference.csv",
          "LICENSE.md": "LICENSE.md"}


def _number(text: str) -> str:
    """A source cell as the long format writes it: empty stays empty, a number keeps every digit."""
    text = text.strip()
    return "" if text == "" else repr(float(text))


def convert_file(source: Path, dest: Path, anchor_ids: list[str]) -> int:
    with open(source, newline="") as fh:
        rows = list(csv.DictReader(fh))
    truth = "x" in rows[0]
    t0 = float(rows[0]["ts"])
    header = ["time_s", "transmitter", "receiver", "rssi_dbm"] + (["x_m", "y_m", "heading_rad"] if truth else [])
    with open(dest, "w", newline="") as fh:
        out = csv.writer(fh, lineterminator="\n")
        out.writerow(header)
        for row in rows:
            time_s = repr((float(row["ts"]) - t0) * 1e-9)
            extra = [_number(row["x"]), _number(row["y"]), _number(row["heading"])] if truth else []
            for a in anchor_ids:
                out.writerow([time_s, "tag", a, _number(row[f"rssi_{a}"])] + extra)
    return len(rows)


def convert(source: Path, dest: Path) -> None:
    with open(source / "anchors.csv", newline="") as fh:
        anchor_ids = [r["id"].strip() for r in csv.DictReader(fh)]
    for src, dst in COPIED.items():
        shutil.copyfile(source / src, dest / dst)
    for src, dst in FILES.items():
        n = convert_file(source / src, dest / dst, anchor_ids)
        print(f"{src}: {n} rows -> {dst}: {n * len(anchor_ids)} readings")


if __name__ == "__main__":
    if len(sys.argv) not in (2, 3):
        sys.exit(__doc__)
    convert(Path(sys.argv[1]), Path(sys.argv[2]) if len(sys.argv) == 3 else Path(__file__).parent)
