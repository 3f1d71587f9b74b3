"""Real measured data: the BLE RSSI data set of Kolakowski (2021) run through locbook's methods.

Six BLE anchors at 1.85-2.62 m height in a furnished 9.1 m x 7.1 m flat, a tag at about 1.3 m on a mobile
robot (LiDAR ground truth): 4,104 calibration points, a 352 s robot drive, and a person's walk along known
straight segments (data: CC BY 4.0, :data:`locbook.data.measured.KOLAKOWSKI2021_ATTRIBUTION`).

Protocol (every choice a named constant or argument, with its reason):

- the channel is fitted on the calibration points only, and every method is scored on the robot drive and the
  walk, which the fit never sees; distances are 3-D, the tag at the known height :data:`TAG_HEIGHT_M`;
- missing readings (empty cells: not heard) follow the library's one rule (NaN), in the fit, the estimators and
  the filters; the radio map of k-NN needs a value for each (point, anchor): a reading an anchor did not hear
  at a calibration point is filled with the fitted channel's mean at that point (:func:`radio_map`), stated;
- positions stay inside the floor outline where the method allows it: grid ML, grid Bayes and k-NN work on
  points inside it, box-LS on its bounding box, RSS ML starts from the grid-ML fix; the fraction of fixes
  outside the outline is reported for every method;
- the bound is the CRLB of the fitted per-anchor log-normal channel at each true position (3-D distances).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..bounds.crlb import rss_position_information
from ..errors import ConvergenceError
from ..data.measured import KOLAKOWSKI2021_TAG_HEIGHT_M, MeasuredData, kolakowski2021, regular_epochs
from ..geometry import grid_in_outline, inside_outline, outline_box
from ..models.channel import PathLossModel
from ..models.motion import constant_velocity
from ..static.calibration import PathLossFit, calibrate_path_loss, fix_error_covariance
from ..static.fingerprint import knn_position
from ..static.localization import (grid_ml_position, lateration_box_ls, lateration_ls, lateration_wls,
                                   rss_ml_position)
from ..models.rss import RssModel
from ..tracking.bayes import grid_bayes_filter
from ..tracking.particle import particle_filter
from ..tracking.kalman import extended_kalman_filter
from ..tracking.streams import LinearMeasurement, RssMeasurement
from ..tracking.unscented import unscented_kalman_filter
from ..tracking.divergence import DivergenceFlags

__all__ = ["TAG_HEIGHT_M", "EPOCH_S", "PATH_LOSS_EXP_BOUNDS", "REF_POWER_BOUNDS_DBM", "HUBER_DELTA_DB",
           "STATIC_METHODS", "TRACKERS", "load", "calibration_set", "calibrate", "channel", "ranging_errors",
           "radio_map", "static_fixes", "crlb_m", "tracks", "Drive", "bayes_measurement_model",
           "fix_covariance_from_calibration", "outside_fraction"]

#: the tag's height above the floor (data set README: "about 1.3 m"); not in the files
TAG_HEIGHT_M = KOLAKOWSKI2021_TAG_HEIGHT_M
#: the data's epoch clock: rows 1/3 s apart (median spacing of both test files)
EPOCH_S = 1.0 / 3.0
#: bounded fit: exponents and 1-m powers a BLE link can physically have (free space n = 2; indoor 1.5-6,
#: Rappaport, Wireless Communications, Table 4.2); wide enough never to bind on data that follow the model
PATH_LOSS_EXP_BOUNDS = (1.0, 6.0)
REF_POWER_BOUNDS_DBM = (-90.0, -20.0)
#: robust fit: residuals beyond 6 dB (about one shadowing sigma indoors) count linearly
HUBER_DELTA_DB = 6.0
STATIC_METHODS = ("lls", "wls", "box_ls", "rss_ml", "grid_ml", "knn", "grid_bayes")
TRACKERS = ("kf_on_ml", "ekf", "ukf", "particle", "grid_bayes")


def load() -> MeasuredData:
    """The data set, shipped with locbook, in the long format."""
    return kolakowski2021(tag_height_m=TAG_HEIGHT_M)


def _lifted(points_xy):
    return np.concatenate([points_xy, np.full(points_xy.shape[:-1] + (1,), TAG_HEIGHT_M)], axis=-1)


def calibration_set(data: MeasuredData):
    """``(positions (L, 2), 3-D distances (L, m), RSSI (L, m) with NaN = not heard)`` of the calibration points."""
    ep = data.epochs("calibration")
    xy = ep.position_m[:, :2]
    distance = np.linalg.norm(_lifted(xy)[:, None, :] - data.anchors_m, axis=-1)
    return xy, distance, ep.rss_dbm


def calibrate(data: MeasuredData, *, mode: str = "per_anchor", fit: str = "closed_form") -> PathLossFit:
    """Path-loss fit on the calibration points: ``mode`` ``"per_anchor"`` (one ``(P_0, n)`` per anchor) or
    ``"pooled"``; ``fit`` ``"closed_form"`` (normal equations), ``"bounded"`` (cvxpy, :data:`PATH_LOSS_EXP_BOUNDS`,
    :data:`REF_POWER_BOUNDS_DBM`) or ``"huber"`` (cvxpy, :data:`HUBER_DELTA_DB`). Missing readings are left out."""
    _, distance, rss = calibration_set(data)
    kwargs = {"closed_form": {"solver": "closed_form"},
              "bounded": {"solver": "cvxpy", "ref_power_bounds_dbm": REF_POWER_BOUNDS_DBM,
                          "path_loss_exp_bounds": PATH_LOSS_EXP_BOUNDS},
              "huber": {"solver": "cvxpy", "loss": "huber", "huber_delta_db": HUBER_DELTA_DB}}
    if fit not in kwargs:
        raise ValueError(f"fit must be one of {sorted(kwargs)}, got {fit!r}")
    result = calibrate_path_loss(distance, rss, mode, **kwargs[fit])
    if not result.ok:
        # a fit is not ok when the solver failed or when some anchor's problem could not be fitted (too few
        # distances, non-finite sums): name which, per anchor
        status = np.atleast_1d(result.problem_status)
        names = list(data.anchor_ids) if status.size == len(data.anchor_ids) else [str(i) for i in range(status.size)]
        failed = ", ".join(f"{n}: {s}" for n, s in zip(names, status) if s != "ok") or "none"
        raise ConvergenceError(f"the {fit} {mode} path-loss fit failed (solver status {result.status}); "
                               f"not fitted: {failed}")
    return result


def channel(fit: PathLossFit, *, min_distance_m: float = 0.1) -> PathLossModel:
    """The fitted channel as a model for the estimators (per-anchor or pooled parameters; shadowing sigma = the
    fit's residual spread). ``min_distance_m``: near-field clamp (0.1 m, below any anchor-to-tag distance here)."""
    return PathLossModel(np.asarray(fit.ref_power_dbm, float), np.asarray(fit.path_loss_exp, float),
                         np.asarray(fit.residual_sigma_db, float), min_distance_m=min_distance_m)


def ranging_errors(model: PathLossModel, distance_m, rss_dbm):
    """Range from each reading by the inverted channel minus the true 3-D distance (NaN where not heard)."""
    return model.range_m(rss_dbm) - distance_m


def radio_map(data: MeasuredData, model: PathLossModel):
    """The k-NN radio map from the calibration set: one fingerprint per calibration point (its positions
    ``(L, 2)`` and readings ``(L, m)``), a reading an anchor did not hear filled with the fitted channel's mean
    at that point (the map must be complete; the fill is stated in the report). Returns ``(cells, map,
    filled_fraction)``."""
    xy, distance, rss = calibration_set(data)
    missing = np.isnan(rss)
    filled = np.where(missing, model.mean_rss_dbm(distance), rss)
    return xy, filled, float(missing.mean())


@dataclass(frozen=True)
class Drive:
    """The robot drive: epochs' RSSI ``(T, m)``, true plan positions ``(T, 2)`` and times ``(T,)``."""

    rss_dbm: np.ndarray
    truth_m: np.ndarray
    time_s: np.ndarray

    @classmethod
    def of(cls, data: MeasuredData) -> "Drive":
        ep = data.epochs("robot")
        return cls(ep.rss_dbm, ep.position_m[:, :2], ep.time_s)


def static_fixes(data: MeasuredData, model: PathLossModel, rss_dbm, *, grid_spacing_m: float = 0.1, knn_k: int = 5,
                 chunk: int = 4096) -> dict[str, np.ndarray]:
    """Every static estimator on the readings ``(T, m)`` (one fix per epoch, NaN where a method has none):
    linearized LS, weighted LS (weights ``1 / d_i^4`` of the inverted ranges: the squared-range equations'
    variance grows as ``d^4`` under log-normal shadowing), box-LS on the outline's bounding box, RSS ML started
    at the grid-ML fix, grid ML on a grid inside the outline, and k-NN on :func:`radio_map`."""
    anchors = data.anchors_m
    ranges = model.range_m(rss_dbm)
    lower, upper = outline_box(data.outline_m)
    grid = grid_in_outline(data.outline_m, grid_spacing_m)
    out = {"lls": lateration_ls(anchors, ranges, tag_height_m=TAG_HEIGHT_M).position_m}
    w = 1.0 / np.where(np.isnan(ranges[:, 1:]), 1.0, ranges[:, 1:]) ** 4
    out["wls"] = lateration_wls(anchors, ranges, w / np.max(w, axis=-1, keepdims=True),
                                tag_height_m=TAG_HEIGHT_M).position_m
    out["box_ls"] = lateration_box_ls(anchors, ranges, lower, upper, tag_height_m=TAG_HEIGHT_M).position_m
    grid_fix = grid_ml_position(anchors, rss_dbm, model, grid, chunk=chunk, tag_height_m=TAG_HEIGHT_M).position_m
    out["grid_ml"] = grid_fix
    out["rss_ml"] = rss_ml_position(anchors, rss_dbm, model, grid_fix, tag_height_m=TAG_HEIGHT_M).position_m
    cells, fingerprints, _ = radio_map(data, model)
    out["knn"] = knn_position(rss_dbm, fingerprints, cells, knn_k)
    return out


def crlb_m(data: MeasuredData, model: PathLossModel, positions_m):
    """``sqrt(trace(J^-1))`` of the fitted per-anchor channel at plan positions ``(..., 2)`` (3-D distances)."""
    info = rss_position_information(positions_m, data.anchors_m[:, :2], model.path_loss_exp, model.sigma_db,
                                    height_offset_m=data.anchors_m[:, 2] - TAG_HEIGHT_M)
    return np.sqrt(np.trace(np.linalg.inv(info), axis1=-2, axis2=-1))


def tracks(data: MeasuredData, model: PathLossModel, recording: str, rng: np.random.Generator, *, q: float,
           fix_cov_m2, spread_m: float, n_particles: int, particle_runs: int, grid_spacing_m: float = 0.1,
           ukf_alpha: float = 0.5, with_divergence: bool = False):
    """Every tracker on one recording (``"robot"`` or ``"walk"``) put on the :data:`EPOCH_S` clock (a tick without
    an epoch is all NaN: the filters predict through it). Returns ``(ticks of the recording's epochs, {tracker:
    plan positions at every tick (T, 2)})``; the particle filter's entry is ``(particle_runs, T, 2)`` (independent
    streams of ``rng``: the spread over them is the filter's own randomness).

    - ``kf_on_ml``: constant-velocity KF (``q``, m^2/s^3 white-acceleration PSD per axis, discrete form) on the
      RSS-ML fixes with ``R = fix_cov_m2`` (calibrated on the calibration set, not on this recording);
    - ``ekf`` (parallel update) and ``ukf`` (``ukf_alpha``): the same motion model on the raw RSSI, per-anchor
      channel, 3-D distances;
    - ``particle``: SIR, ``L_t = L_t-1 + N(0, spread_m^2 I)`` reflected into the outline's box, resampled when
      ``N_eff < N / 2``;
    - ``grid_bayes``: the same random walk on a grid inside the outline (separable transition).
    The starting state of the Kalman filters is the first RSS-ML fix with a 2 m standard deviation, at rest.

    ``with_divergence=True`` appends ``{tracker: flags}`` for ``kf_on_ml``, ``ekf`` and ``ukf``: the NIS guard of the
    one run on the recording (:class:`locbook.tracking.divergence.DivergenceFlags`, steps of the regular clock)."""
    ep = data.epochs(recording)
    reg, ticks = regular_epochs(ep, EPOCH_S, tolerance_s=0.1 * EPOCH_S)
    rss = reg.rss_dbm
    anchors = data.anchors_m
    lower, upper = outline_box(data.outline_m)
    grid = grid_in_outline(data.outline_m, grid_spacing_m)
    heard = ~np.isnan(rss).all(axis=-1)
    ml = np.full((rss.shape[0], 2), np.nan)
    grid_fix = grid_ml_position(anchors, rss[heard], model, grid, tag_height_m=TAG_HEIGHT_M).position_m
    ml[heard] = rss_ml_position(anchors, rss[heard], model, grid_fix, tag_height_m=TAG_HEIGHT_M).position_m
    motion = constant_velocity(EPOCH_S, q, dim=2)
    first = ml[np.flatnonzero(np.isfinite(ml).all(axis=1))[0]]
    x0 = np.r_[first, 0.0, 0.0]
    P0 = np.diag([4.0, 4.0, 1.0, 1.0])
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    rss_stream = RssMeasurement(rss, anchors, model, np.array([0, 1]), tag_height_m=TAG_HEIGHT_M)
    kalman = {"kf_on_ml": extended_kalman_filter(motion.F, motion.Q, x0, P0,
                                                 [LinearMeasurement(ml, H, np.asarray(fix_cov_m2, float))]),
              "ekf": extended_kalman_filter(motion.F, motion.Q, x0, P0, [rss_stream]),
              "ukf": unscented_kalman_filter(motion.F, motion.Q, x0, P0, [rss_stream], alpha=ukf_alpha)}
    out = {name: res.x[:, :2] for name, res in kalman.items()}
    bayes_model = bayes_measurement_model(data, model)
    runs = np.broadcast_to(rss, (particle_runs,) + rss.shape)
    out["particle"] = particle_filter(runs, bayes_model, rng, n_particles=n_particles, region_m=(lower, upper),
                                      spread_m=spread_m, resample_threshold=0.5).mean_m
    out["grid_bayes"] = grid_bayes_filter(rss[None], grid, bayes_model, spread_m).mean_m[0]
    out["rss_ml"] = ml
    if with_divergence:
        return reg, ticks, out, {name: DivergenceFlags.of(res) for name, res in kalman.items()}
    return reg, ticks, out


def bayes_measurement_model(data: MeasuredData, model: PathLossModel) -> RssModel:
    """The fitted channel as the likelihood of the particle and grid Bayes filters (per-anchor sigma, 3-D distances,
    the near-field clamp of 0.1 m they have always used)."""
    return RssModel(data.anchors_m, PathLossModel(np.asarray(model.ref_power_dbm, float),
                                                  np.asarray(model.path_loss_exp, float),
                                                  np.asarray(model.sigma_db, float), model.ref_distance_m,
                                                  model.wall_attenuation_db, min_distance_m=0.1),
                    tag_height_m=TAG_HEIGHT_M)


def fix_covariance_from_calibration(data: MeasuredData, model: PathLossModel, *, grid_spacing_m: float = 0.1):
    """``R`` of the KF on ML fixes: the covariance of RSS-ML fix errors over the calibration points (the set the
    channel was fitted on, never the test drive)."""
    xy, _, rss = calibration_set(data)
    grid = grid_in_outline(data.outline_m, grid_spacing_m)
    grid_fix = grid_ml_position(data.anchors_m, rss, model, grid, tag_height_m=TAG_HEIGHT_M).position_m
    fixes = rss_ml_position(data.anchors_m, rss, model, grid_fix, tag_height_m=TAG_HEIGHT_M).position_m
    ok = np.isfinite(fixes).all(axis=1)
    return fix_error_covariance(fixes[ok], xy[ok])


def outside_fraction(data: MeasuredData, positions_m) -> float:
    """Fraction of the estimates (finite ones) that lie outside the floor outline."""
    p = np.asarray(positions_m, float).reshape(-1, 2)
    ok = np.isfinite(p).all(axis=1)
    return float(np.mean(~inside_outline(p[ok], data.outline_m))) if ok.any() else float("nan")
