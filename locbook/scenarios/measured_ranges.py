"""The range stream in the measured-data battery (:mod:`locbook.scenarios.measured`): what a data set whose recordings
carry ranges (``ranges = "FILE"``, :mod:`locbook.data.ranges`) adds to it, by the same protocol.

- **Static** (measured-localization): ``range_nls``, range-only lateration
  (:func:`locbook.static.ranging.range_nls_position`: weighted NLS from the linearized LS fix, bounded to the floor)
  on every scored epoch, beside the **range CRLB** of the ranges that epoch measured at their sigma
  (:func:`locbook.bounds.crlb.range_crlb_checked_m`). Why not the RSS CRLB: a bound is that of the readings the
  estimator sees; ``range_nls`` sees ranges only, and the RSS bound (metres, at 4 dB) would make a 0.3 m ranging
  fix look ten times "below the bound", a ratio that says nothing about the estimator. Its row names the bound it
  is beside (the ``bound`` column), as every row does.
- **Tracking** (measured-tracking): ``ekf_rss_range`` and ``ukf_rss_range``, the battery's constant-velocity EKF
  and UKF with the RSS stream (the fitted channel, as ``ekf`` and ``ukf``) and a range stream
  (:class:`locbook.models.range.RangeModel`, per-epoch sigma), at the same fitted ``q``, from the same start, beside
  the posterior CRLB of the readings they see: the battery's recursion with the ranges' information added
  (:func:`range_tracking_bound_m`; the RSS-only bound would put them far "below" it, a ratio that says nothing).
- **Sigma** of each epoch's range: the reported std (``range_std_m``; an epoch's range is the mean of its window's
  ranges, with the std of that mean, :func:`locbook.data.ranges.align_ranges`); without a ``range_std_m`` column, the
  rule :func:`range_noise`: the residual standard deviation of the calibration recordings' epoch ranges against the
  true distances (3-D, from the true positions; the channel's own rule: fitted on the calibration recordings,
  never on a scored one). A recording whose ranges have no std and a data set whose calibration recordings have no
  ranges: its range methods have no sigma and are not run (the settings table says so).

A recording without a ranges file (or whose file holds no range on its epochs) gives these methods no range:
``range_nls`` has no fix there (counted as missing); the range trackers do not run on such a track, and their pooled
row pools only groups whose every track has ranges (the rule of the inertial fusion trackers:
:mod:`locbook.scenarios.measured_inertial`). A data set without any ranges gives no
new row and changes no number: every stream is keyed by its method.
"""
from __future__ import annotations

import numpy as np

from ..battery import TRACKER_PRIORS, Method, TrackerSettings, TrackingScenario, tracking_bound_m
from ..bounds.crlb import range_crlb_checked_m, range_position_information
from ..data.dataset import Dataset
from ..data.ranges import align_ranges
from ..models.motion import constant_velocity
from ..models.range import RangeModel
from ..static.ranging import range_nls_position
from ..tracking.divergence import DivergenceFlags
from ..tracking.kalman import extended_kalman_filter
from ..tracking.streams import RssMeasurement, Stream
from ..tracking.unscented import unscented_kalman_filter

__all__ = ["RANGE_STATIC_METHODS", "RANGE_TRACKERS", "RANGE_TRACKER_PRIORS", "RANGE_METHOD_NAMES",
           "RANGE_BOUND_NAME", "RANGE_TRACKING_BOUND_NAME", "range_tracking_bound_m", "range_noise", "recording_ranges",
           "range_choices", "static_range_results",
           "run_range_trackers", "range_tracker_knobs", "ranged", "user_ranges", "track_ranges"]

#: the static method the ranges add (:class:`locbook.battery.Method`: what, settings, prior)
RANGE_STATIC_METHODS = {
    "range_nls": Method(None, "range-only lateration: weighted nonlinear least squares of the epoch's ranges (1/sigma "
                              "weights) from the linearized LS fix, in the floor's bounding box, a point outside a "
                              "non-rectangular outline moved to its nearest point",
                        "box = the floor's bounding box; start: linearized LS of the ranges",
                        "its fixes lie in the floor outline (the range CRLB knows no floor)"),
}
#: the trackers the ranges add, what each is
RANGE_TRACKERS = {
    "ekf_rss_range": "constant-velocity EKF on the raw RSS and the ranges (two streams, parallel updates)",
    "ukf_rss_range": "constant-velocity UKF on the raw RSS and the ranges (two streams)",
}
#: why each may fall below its bound, the posterior CRLB of RSS and ranges (:func:`range_tracking_bound_m`)
RANGE_TRACKER_PRIORS = {name: TRACKER_PRIORS["ekf"] for name in RANGE_TRACKERS}
#: the bound the range trackers' rows are beside
RANGE_TRACKING_BOUND_NAME = "PCRLB (constant velocity at the fitted q, from the trackers' start; RSS + ranges)"
RANGE_METHOD_NAMES = (*RANGE_STATIC_METHODS, *RANGE_TRACKERS)
RANGE_BOUND_NAME = "range CRLB (sigma of each epoch's ranges, anchors ranged)"
#: the sigma (m) a missing range carries in the models (never used: a missing range is a NaN reading, left out)
_UNUSED_SIGMA_M = 1.0


def _truth_distances(data: Dataset, position_m) -> np.ndarray:
    """True distances ``(E, m)`` of epochs' true positions ``(E, 3)`` (3-D: the true height where recorded, else the
    tag's known height; in the plane for a 2-D data set)."""
    if data.dimension == 2:
        return np.linalg.norm(position_m[:, None, :2] - data.anchors_m, axis=-1)
    pos = position_m.copy()
    pos[:, 2] = np.where(np.isfinite(pos[:, 2]), pos[:, 2], data.tag_height_m)
    return np.linalg.norm(pos[:, None, :] - data.anchors_m, axis=-1)


def range_noise(data: Dataset) -> dict:
    """The range sigma rule for ranges without a reported std (module docstring): ``{"sigma_m", "bias_m", "n"}``,
    the residual std (``ddof = 1``) and mean of the calibration recordings' epoch ranges minus the true distances over
    ``n`` (epoch, anchor) ranges (the mean is reported, not removed); ``sigma_m`` None when no calibration recording
    has ranges (or fewer than 2 with truth)."""
    if ("range_noise",) not in data._cache:
        residuals = []
        for name in data.recordings_with("calibration"):
            if not data.has_ranges(name):
                continue
            ep, (ranges, _) = data.epochs(name), data.ranges(name)
            known = np.isfinite(ep.position_m[:, :2]).all(axis=1)
            e = ranges[known] - _truth_distances(data, ep.position_m[known])
            residuals.append(e[np.isfinite(e)])
        e = np.concatenate(residuals) if residuals else np.zeros(0)
        data._cache[("range_noise",)] = {"sigma_m": float(np.std(e, ddof=1)) if e.size >= 2 else None,
                                         "bias_m": float(np.mean(e)) if e.size else None, "n": int(e.size)}
    return data._cache[("range_noise",)]


def _sigma_source(data: Dataset, name: str) -> str | None:
    """``"reported"``, ``"fitted"`` or None (no sigma: the recording's ranges are not used) of a recording's ranges."""
    if data.ranges(name)[1] is not None:
        return "reported"
    return "fitted" if range_noise(data)["sigma_m"] is not None else None


def _usable(data: Dataset, name: str) -> bool:
    """Whether a recording's ranges can be used: a ranges file with at least one range on its epochs, and a sigma
    (a file without one range, or of none that falls on an epoch, is a recording without ranges)."""
    return (data.has_ranges(name) and bool(np.isfinite(data.ranges(name)[0]).any())
            and _sigma_source(data, name) is not None)


def recording_ranges(data: Dataset, name: str, ep=None, *, window_s: float | None = None):
    """``(range_m (E, m), sigma_m (E, m))`` of a recording's epochs (``ep``: other epochs of its readings, made with
    the window ``window_s``, e.g. a track's native scans put in windows of its clock, aligned by
    :func:`locbook.data.ranges.align_ranges` by that window; default :meth:`Dataset.epochs`): NaN ranges where none
    (everywhere without a usable ranges file), the sigma of each (reported, else the fitted rule;
    :data:`_UNUSED_SIGMA_M` where there is no range)."""
    rows = len(data.epochs(name)) if ep is None else len(ep)
    m = len(data.anchor_ids)
    if not _usable(data, name):
        return np.full((rows, m), np.nan), np.full((rows, m), _UNUSED_SIGMA_M)
    if ep is None:
        ranges, std = data.ranges(name)
    else:
        rec = data.recording(name)
        ranges, std = align_ranges(ep, rec.readings, rec.ranges, window_s=window_s or rec.epoch_rule.window_s or None,
                                   group_by=() if rec.point_column is None else (rec.point_column,),
                                   source=f"ranges file {rec.ranges_file}")
    if std is None:
        std = np.full(ranges.shape, range_noise(data)["sigma_m"])
    return ranges, np.where(np.isfinite(ranges), std, _UNUSED_SIGMA_M)


def ranged(data: Dataset, names) -> list[str]:
    """The recordings of ``names`` whose ranges the methods can use: ``range_nls`` runs when a scored one has them,
    the range trackers run on each track that has them (and on no other)."""
    return [n for n in names if _usable(data, n)]


def range_choices(data: Dataset) -> list[dict]:
    """The settings table's rows of the range methods (none without ranges): where each recording's range sigma
    comes from."""
    with_ranges = [n for n in data.recordings if data.has_ranges(n) and data.recording(n).role != "calibration"]
    if not with_ranges:
        return []
    noise = range_noise(data)
    rows = []
    for name in with_ranges:
        source = _sigma_source(data, name)
        if source == "reported":
            std = data.ranges(name)[1]
            value = (f"reported, median {float(np.nanmedian(std)):.3g} m per epoch" if np.isfinite(std).any()
                     else "reported")
            how = ("the ranges file's range_std_m; an epoch's range is the mean of its window's ranges, its std "
                   "sqrt(mean(std^2) / n)")
        elif source == "fitted":
            value = f"{noise['sigma_m']:.3g}"
            how = (f"rule: residual std of the calibration recordings' epoch ranges against the true distances "
                   f"({noise['n']:,} ranges; mean residual {noise['bias_m']:+.3g} m, not removed)")
        else:
            value, how = "none: not used", ("the ranges file has no range_std_m and no calibration recording has "
                                            "ranges to fit a sigma on")
        rows.append({"method": ", ".join(RANGE_METHOD_NAMES), "setting": f"range sigma (m), {name}", "value": value,
                     "how": how})
    return rows


def static_range_results(data: Dataset, names) -> dict | None:
    """``range_nls`` on the scored epochs (those with a true position) of each recording ``names``, and its bound:
    ``{"fixes": {recording: (E, 2)}, "bounds": {recording: (bound (E,), reason (E,))}, "status": {recording: (E,)}}``;
    None when no recording has usable ranges."""
    if not ranged(data, names):
        return None
    fixes, bounds, status = {}, {}, {}
    tag = data.tag_height_m
    for name in names:
        ep = data.epochs(name)
        known = np.isfinite(ep.position_m[:, :2]).all(axis=1)
        ranges, sigma = (v[known] for v in recording_ranges(data, name))
        res = range_nls_position(ranges, data.anchors_m, outline_m=data.outline_m, tag_height_m=tag,
                                 range_std_m=np.where(np.isfinite(ranges), sigma, np.nan))
        fixes[name], status[name] = res.position_m, res.status
        bounds[name] = range_crlb_checked_m(ep.position_m[known, :2],
                                            RangeModel(data.anchors_m, sigma, tag_height_m=tag),
                                            heard=np.isfinite(ranges))
    return {"fixes": fixes, "bounds": bounds, "status": status}


def track_ranges(data: Dataset, name: str, ep, ticks, n_ticks: int):
    """A track's ranges on its clock: ``(range_m (T, m), sigma_m (T, m))`` from its epochs ``ep`` and their ticks
    (:func:`locbook.scenarios.measured.track_epochs`); NaN (and the unused sigma) at a tick without a range."""
    # native scans were put in windows of the clock's period (track_epochs): the ranges go to those windows
    native = not data.recording(name).epoch_rule.window_s
    ranges, sigma = recording_ranges(data, name, ep if native else None,
                                     window_s=data.scan_interval_s(name) if native else None)
    m = ranges.shape[1]
    z, s = np.full((n_ticks, m), np.nan), np.full((n_ticks, m), _UNUSED_SIGMA_M)
    z[ticks], s[ticks] = ranges, sigma
    return z, s


def user_ranges(data: Dataset, name: str, track=None, n_ticks: int | None = None):
    """``(range_m, range_std_m)`` a user method gets (:class:`locbook.MethodInput`) on a recording: on its scored
    epochs (those with a true position), or on a track's clock (``track``: :func:`locbook.scenarios.measured.
    track_epochs`'s ``(epochs, on the clock, ticks)``, ``n_ticks`` ticks); the std NaN where there is no range.
    None where the recording has no usable ranges."""
    if not _usable(data, name):
        return None
    if track is None:
        ep = data.epochs(name)
        known = np.isfinite(ep.position_m[:, :2]).all(axis=1)
        ranges, sigma = (v[known] for v in recording_ranges(data, name))
    else:
        ranges, sigma = track_ranges(data, name, track[0], track[2], n_ticks)
    return ranges, np.where(np.isfinite(ranges), sigma, np.nan)


def run_range_trackers(data: Dataset, name: str, sc: TrackingScenario, ep, ticks, x0, ts: TrackerSettings):
    """``(positions {tracker: (1, T, 2)}, flags {tracker: DivergenceFlags})`` of the fusion trackers on one track:
    the battery's EKF and UKF (constant velocity at ``ts.q``, from ``x0``, ``ts.P0``) with the RSS stream of ``ekf``
    and the track's range stream (:func:`track_ranges`, a sigma per tick)."""
    rss = sc.measured_rss_dbm[None]
    z, sigma = track_ranges(data, name, ep, ticks, rss.shape[1])
    idx = np.array([0, 1])
    motion = constant_velocity(sc.dt_s, ts.q, dim=2)
    P0 = np.broadcast_to(ts.P0, (len(x0), 4, 4))

    def streams():
        return [RssMeasurement(rss, sc.anchors_m, sc.channel, idx, tag_height_m=sc.tag_height_m),
                Stream(z[None], RangeModel(data.anchors_m, sigma, tag_height_m=data.tag_height_m, position_index=idx,
                                           per_step_sigma=True))]

    out, flags = {}, {}
    res = extended_kalman_filter(motion.F, motion.Q, x0, P0, streams())
    out["ekf_rss_range"], flags["ekf_rss_range"] = res.position_m([0, 1]), DivergenceFlags.of(res)
    res = unscented_kalman_filter(motion.F, motion.Q, x0, P0, streams(), alpha=ts.ukf_alpha)
    out["ukf_rss_range"], flags["ukf_rss_range"] = res.position_m([0, 1]), DivergenceFlags.of(res)
    return out, flags


def range_tracker_knobs(data: Dataset, name: str, common: str, ts: TrackerSettings) -> dict:
    """The settings column of the fusion trackers on track ``name`` (``common``: the Kalman trackers' text)."""
    source = _sigma_source(data, name) if data.has_ranges(name) else None
    ranges = {"reported": "ranges: reported std per epoch",
              "fitted": f"ranges: sigma {range_noise(data)['sigma_m'] or float('nan'):.3g} m (fitted on calibration)",
              None: "no ranges on this track: RSS only"}[source]
    return {"ekf_rss_range": f"{common}; {ranges}", "ukf_rss_range": f"{common}; alpha = {ts.ukf_alpha:g}; {ranges}"}


def range_tracking_bound_m(data: Dataset, name: str, sc: TrackingScenario, ep, ticks, ts: TrackerSettings):
    """The range trackers' bound on track ``name``: the battery's posterior CRLB (:func:`locbook.battery.
    tracking_bound_m`, constant velocity at ``ts.q``) with the ranges' position information added at every tick
    with a true position (:func:`locbook.bounds.crlb.range_position_information` of the ranges that tick measured,
    at their sigma: the readings the range trackers see). ``(T,)`` m."""
    z, sigma = track_ranges(data, name, ep, ticks, len(sc.truth_m))
    known = np.isfinite(sc.truth_m).all(axis=-1)
    truth = np.where(known[:, None], sc.truth_m, 0.0)
    info = range_position_information(truth, RangeModel(data.anchors_m, sigma, tag_height_m=data.tag_height_m),
                                      heard=np.isfinite(z) & known[:, None])
    return tracking_bound_m(sc, ts, extra_position_information=info)
