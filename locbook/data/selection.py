"""Splits and anchor subsets of a loaded data set: which recordings the channel is fitted on, and which anchors a run
uses. Each is a pure function of a :class:`~locbook.data.dataset.Dataset` returning a new one (the data set given is
not changed), so every experiment of a run, given the same parameters, sees the same split; the parameters are the
notebooks' (``-p calibration=...``, ``-p anchors=...``), so each split and subset is its own cache entry.

- :func:`with_calibration` (``-p calibration=NAME[,NAME...]``): the named recordings are the calibration recordings
  (the channel and the k-NN radio map are fitted on them, never scored); a recording the manifest calls
  ``calibration`` and the parameter does not name becomes a scored ``static`` recording (a calibration recording
  always has true positions, so it can be scored); a static recording or a track that is named becomes a
  calibration recording and is no longer scored (a track so named is not tracked). The other recordings keep their
  roles. A name that is not a recording, a recording without true positions (the fit needs distances from them) or a
  name given twice is refused, naming the parameter.
- :func:`with_anchors` (``-p anchors=ID[,ID...]``, or the manifest's ``[run] anchors``): the battery runs on those
  anchors only. The readings of the other anchors are dropped before anything is windowed, so the result equals the
  data set whose files hold only the subset's rows and anchors (the clock of a windowed recording starts at its
  first reading among the subset's anchors), and the dropped readings are counted in a note. The floor outline and
  the tag height are the data set's as loaded (the floor does not change when anchors are removed; where the
  manifest gives no outline, the default box was drawn around every anchor). Fewer than :data:`MIN_SUBSET_ANCHORS`
  anchors, an id that is not an anchor, or an id given twice is refused, naming the parameter and listing the ids.
- :func:`select`: both, as a run applies them (the anchors first, then the split); empty values keep the data set as
  it is: the same object, so a run without these parameters gives exactly today's numbers.

Leave-one-recording-out (``locbook run --data DIR --split loro``, :mod:`locbook.suite.splits`) and the
anchor-density study (``locbook study anchor-density --data DIR``) are runs of these parameters.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pandas as pd

from ..bounds.crlb import MIN_ANCHORS_FOR_BOUND
from ..errors import ParameterError

__all__ = ["MIN_SUBSET_ANCHORS", "parse_names", "with_calibration", "with_anchors", "select", "scorable_recordings",
           "check_anchor_ids"]

#: the fewest anchors a subset may hold: a plan fix (x, y) from RSS needs 3 anchors heard (the lateration rows of
#: the reference-anchor LS, the rss_ml fix kf_on_ml filters, KF_FIX_MIN_ANCHORS) and so does a defined CRLB
#: (MIN_ANCHORS_FOR_BOUND); in 2-D and in 3-D with the tag at its known height alike
MIN_SUBSET_ANCHORS = MIN_ANCHORS_FOR_BOUND


def _label(parameter: str) -> str:
    """How a message names the value: a manifest key (``[run] anchors``) as it is, else ``parameter 'NAME'``."""
    return parameter if parameter.startswith("[") else f"parameter {parameter!r}"


def parse_names(value, parameter: str) -> tuple[str, ...]:
    """A comma list (``"a,b"``; spaces around names ignored) or a list of names, as a tuple; ``""``, ``None`` or
    ``[]``: empty. A name given twice, or an empty name between commas, is refused naming ``parameter``."""
    if value is None:
        return ()
    if isinstance(value, str):
        if not value.strip():
            return ()
        names = [v.strip() for v in value.split(",")]
    elif isinstance(value, (list, tuple)) and all(isinstance(v, str) for v in value):
        names = [v.strip() for v in value]
    else:
        raise ParameterError(f"{_label(parameter)} must be a comma list of names, got {value!r}")
    if any(not n for n in names):
        raise ParameterError(f"{_label(parameter)}: an empty name in {value!r} (a comma list: NAME[,NAME...])")
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ParameterError(f"{_label(parameter)}: {', '.join(map(repr, twice))} given twice in {value!r}")
    return tuple(names)


def scorable_recordings(data) -> list[str]:
    """The recordings with true positions (manifest order): those a split can fit the channel on or score."""
    return [name for name, rec in data.recordings.items() if rec.has_truth]


def with_calibration(data, names, *, parameter: str = "calibration"):
    """``data`` with the channel fitted on the recordings ``names`` (module docstring); ``names`` empty, or the
    manifest's own calibration recordings: ``data`` itself."""
    names = parse_names(names, parameter)
    if not names:
        return data
    recordings = list(data.recordings)
    unknown = [n for n in names if n not in data.recordings]
    if unknown:
        raise ParameterError(f"{_label(parameter)}: {', '.join(map(repr, unknown))} is not a recording of data "
                             f"set {data.name!r}; its recordings: {', '.join(recordings)}")
    no_truth = [n for n in names if not data.recordings[n].has_truth]
    if no_truth:
        raise ParameterError(f"{_label(parameter)}: recording {', '.join(map(repr, no_truth))} has no true "
                             "positions (x_m, y_m) and cannot be a calibration recording (the channel is fitted on "
                             "the distances from them); recordings with truth: "
                             f"{', '.join(scorable_recordings(data))}")
    if set(names) == set(data.recordings_with("calibration")):
        return data
    changed, new = [], {}
    for rname, rec in data.recordings.items():
        role = "calibration" if rname in names else ("static" if rec.role == "calibration" else rec.role)
        if role != rec.role:
            why = " (scored)" if role == "static" else " (not tracked, not scored)" if rec.role == "track" else \
                " (not scored)"
            changed.append(f"{rname} ({rec.role} in the manifest) is a {role} recording{why}")
        new[rname] = rec if role == rec.role else replace(rec, role=role)
    notes = {k: v for k, v in data.notes.items()
             if k not in ("in-sample scoring", "devices", "scoring") and not k.startswith("uncalibrated device ")}
    fitted = [n for n in recordings if n in names]
    notes["calibration split"] = (f"-p {parameter}: the channel is fitted on {', '.join(fitted)} (manifest roles "
                                  f"changed: {'; '.join(changed)})")
    out = replace(data, recordings=new, notes=notes, _cache={})
    _renote(out)
    return out


def check_anchor_ids(ids, known, parameter: str) -> tuple[str, ...]:
    """``ids`` (a comma list or a list) as a tuple, checked against the anchor ids ``known``: each an anchor, none
    twice, at least :data:`MIN_SUBSET_ANCHORS` of them; else a ParameterError naming ``parameter``."""
    ids = parse_names(ids, parameter)
    known = tuple(known)
    if not ids:
        return ()
    unknown = [a for a in ids if a not in known]
    if unknown:
        raise ParameterError(f"{_label(parameter)}: {', '.join(map(repr, unknown))} is not an anchor id; the "
                             f"anchors: {', '.join(known)}")
    if len(ids) < MIN_SUBSET_ANCHORS:
        raise ParameterError(f"{_label(parameter)}: {len(ids)} anchor(s) ({', '.join(ids)}); a subset needs at "
                             f"least {MIN_SUBSET_ANCHORS} (MIN_SUBSET_ANCHORS: a plan fix and its CRLB need 3 "
                             f"anchors heard); the anchors: {', '.join(known)}")
    return ids


def with_anchors(data, ids, *, parameter: str = "anchors", source: str | None = None):
    """``data`` on the anchors ``ids`` only (module docstring): the anchors file's rows of those ids (in its order)
    and every recording's readings of them; the other anchors' readings are dropped and counted in the note
    ``anchor subset``. ``ids`` empty, or every anchor: ``data`` itself. ``source``: where the subset came from, for
    the note (default ``-p <parameter>``)."""
    ids = check_anchor_ids(ids, data.anchor_ids, parameter)
    if not ids or set(ids) == set(data.anchor_ids):
        return data
    keep = set(ids)
    dropped = [a for a in data.anchor_ids if a not in keep]
    anchors = data.anchors[data.anchors["id"].isin(keep)].reset_index(drop=True)
    recordings, ignored = {}, 0
    for rname, rec in data.recordings.items():
        r = rec.readings
        kept = r["receiver"].astype(str).isin(keep).to_numpy()
        ignored += int(np.isfinite(r["rssi_dbm"].to_numpy(float)[~kept]).sum())     # readings: heard rows
        changes = {"readings": r[kept].reset_index(drop=True)}
        ranges = getattr(rec, "ranges", None)      # range readings (a recording's ``ranges`` file): the same rule
        if isinstance(ranges, pd.DataFrame) and "receiver" in ranges.columns:
            changes["ranges"] = ranges[ranges["receiver"].astype(str).isin(keep)].reset_index(drop=True)
        recordings[rname] = replace(rec, **changes)
    notes = {k: v for k, v in data.notes.items() if k not in ("devices",) and not k.startswith("uncalibrated device ")}
    notes["anchor subset"] = (f"{source or '-p ' + parameter}: the battery runs on {len(ids)} of the "
                              f"{len(data.anchor_ids)} anchors ({', '.join(a for a in data.anchor_ids if a in keep)}); "
                              f"ignored {ignored:,} readings of {len(dropped)} anchors not in the subset: "
                              f"{', '.join(dropped)}")
    out = replace(data, anchors=anchors, recordings=recordings, notes=notes, _cache={})
    _renote(out)
    return out


def select(data, *, calibration="", anchors=""):
    """The data set a run uses: :func:`with_anchors` (``anchors``, else the manifest's ``[run] anchors``), then
    :func:`with_calibration` (``calibration``). Empty values and no ``[run] anchors``: ``data`` itself."""
    manifest = tuple(getattr(data, "run_anchors", ()) or ())
    if parse_names(anchors, "anchors"):
        data = with_anchors(data, anchors)
    elif manifest:
        data = with_anchors(data, manifest, source="[run] anchors of the manifest")
    return with_calibration(data, calibration)


def _renote(data) -> None:
    """The notes that depend on the roles or the anchors, recomputed on a selected data set by the loader's own
    rules (in-sample scoring, devices) and a note when nothing is left to score."""
    from .summary import device_notes, in_sample_note
    in_sample = in_sample_note(data.recordings)
    if in_sample:
        data.notes["in-sample scoring"] = in_sample
    if not any(r.role == "static" or (r.role == "track" and r.has_truth) for r in data.recordings.values()):
        data.notes["scoring"] = ("no static recording and no track with truth is left after the split: nothing is "
                                 "scored (tracks with a reference path are scored by their distance to it)")
    device_notes(data)
