"""What a loaded data set holds, in words and tables: the per-recording summary (:func:`dataset_summary`, what
``locbook data check`` prints and every report's first table shows), and the notes on devices and in-sample
scoring that :func:`locbook.data.dataset.load_dataset` and :mod:`locbook.data.selection` add."""
from __future__ import annotations

import filecmp
import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .csvfile import shown

if TYPE_CHECKING:
    from .dataset import Dataset

__all__ = ["dataset_summary", "device_notes", "in_sample_note", "shared_files"]


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


def device_notes(data: Dataset) -> None:
    """Notes on the devices (``device`` column, default the transmitter id): calibration recordings that hold more
    than one (which, and how many epochs each: a pooled fit mixes their receiver offsets), and a scored recording
    holding a device that no calibration recording holds (its offset is not calibrated: 0 dB is assumed). Warnings,
    never refusals: the methods run, the reports say it."""
    calibration = [data.epochs(n).device for n in data.recordings_with("calibration")]
    names, counts = np.unique(np.concatenate(calibration).astype(str), return_counts=True)
    if len(names) > 1:
        each = ", ".join(f"{shown(str(d))} ({int(c):,} epochs)" for d, c in zip(names, counts))
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
                f"recording {rname!r} holds device(s) {', '.join(map(shown, new))}, which no calibration recording "
                "holds: its receiver offset is not calibrated: assumed 0 dB")


def in_sample_note(recordings: dict) -> str:
    """The note "in-sample scoring" (:func:`shared_files`), or "" when no scored recording shares a file."""
    shared = shared_files(recordings)
    if not shared:
        return ""
    return ("; ".join(f"{s} (scored) reads the same file as calibration recording {c} ({f})" for s, c, f in shared)
            + ": the channel is fitted on the epochs these recordings are scored on, so their errors are in-sample "
              "(optimistic); give the scored recordings files of their own")


def shared_files(recordings: dict) -> list[tuple[str, str, str]]:
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


