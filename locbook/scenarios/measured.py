"""Any measured data set (:mod:`locbook.data.dataset`) run through locbook's methods: the protocol of the
``measured-*`` experiments and of the measured columns of the cross-document benchmark.

Protocol (every choice a named constant or argument, with its reason; nothing here depends on which data set):

- the channel is fitted on the data set's calibration recordings only, and every method is scored on its static and
  track recordings, which the fit never sees; distances are 3-D, the tag at the data set's known height
  (``tag_height_m`` of the manifest);
- missing readings (not heard) follow the library's one rule (NaN), in the fit, the estimators and the filters; the
  radio map of k-NN needs a value for each (point, anchor): a reading an anchor did not hear at a calibration epoch is
  filled with the fitted channel's mean there (:func:`radio_map`), stated;
- positions stay inside the floor outline where the method allows it: grid ML, grid Bayes and k-NN work on points
  inside it, box-LS and RSS ML on its bounding box (RSS ML started from the grid-ML fix; ``rss_ml_free`` is the same
  without the box, to show what the bound does); the fraction of fixes outside the outline is reported for every
  method;
- trackers run on the recording's epoch clock (the manifest's ``window_s``); a tick without an epoch is all NaN and
  the filters predict through it;
- the bound is the CRLB of the fitted per-anchor log-normal channel at each true position (3-D distances, the tag's
  height known: the 2-D bound of the plan position).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..bounds.crlb import rss_crlb_m
from ..data.dataset import Dataset, load_dataset
from ..data.measured import regular_epochs
from ..errors import ConvergenceError, ParameterError
from ..geometry import grid_in_outline, inside_outline, outline_box
from ..models.channel import PathLossModel
from ..models.motion import constant_velocity
from ..models.rss import RssModel
from ..montecarlo import moving_block_indices
from ..static.calibration import PathLossFit, calibrate_path_loss, fix_error_covariance
from ..static.fingerprint import knn_position
from ..static.localization import (grid_ml_position, lateration_box_ls, lateration_ls, lateration_wls,
                                   rss_ml_position)
from ..tracking.bayes import grid_bayes_filter
from ..tracking.divergence import DivergenceFlags
from ..tracking.kalman import extended_kalman_filter
from ..tracking.particle import particle_filter
from ..tracking.streams import LinearMeasurement, RssMeasurement
from ..tracking.unscented import unscented_kalman_filter

__all__ = ["PATH_LOSS_EXP_BOUNDS", "REF_POWER_BOUNDS_DBM", "HUBER_DELTA_DB", "NEAR_FIELD_M", "STATIC_METHODS",
           "TRACKERS", "load", "calibration_set", "calibrate", "channel", "ranging_errors", "radio_map",
           "scored_recordings", "TestEpochs", "static_fixes", "crlb_m", "epoch_s", "tracks", "noise_fit",
           "bayes_measurement_model", "fix_covariance_from_calibration", "outside_fraction",
           "calibration_block_bootstrap", "record_dataset"]

#: bounded fit: exponents and 1-m powers a radio link can physically have (free space n = 2; indoor 1.5-6,
#: Rappaport, Wireless Communications, Table 4.2); wide enough never to bind on data that follow the model
PATH_LOSS_EXP_BOUNDS = (1.0, 6.0)
REF_POWER_BOUNDS_DBM = (-90.0, -20.0)
#: robust fit: residuals beyond 6 dB (about one shadowing sigma indoors) count linearly
HUBER_DELTA_DB = 6.0
#: near-field clamp of the fitted channel (m): below any anchor-to-tag distance of a room-scale deployment
NEAR_FIELD_M = 0.1
STATIC_METHODS = ("lls", "wls", "box_ls", "rss_ml", "rss_ml_free", "grid_ml", "knn", "grid_bayes")
TRACKERS = ("kf_on_ml", "ekf", "ukf", "particle", "grid_bayes")


def load(data) -> Dataset:
    """A data set: a :class:`Dataset` as it is, else a shipped name or a folder (:func:`load_dataset`)."""
    return data if isinstance(data, Dataset) else load_dataset(data)


def calibration_set(data: Dataset):
    """``(positions (L, 2), 3-D distances (L, m), RSSI (L, m) with NaN = not heard)`` of the calibration epochs
    (every calibration recording, in manifest order); epochs without a true position are left out."""
    ep = data.epochs_of("calibration")
    known = np.isfinite(ep.position_m[:, :2]).all(axis=1)
    if not known.any():
        raise ParameterError(f"data set {data.name!r}: no calibration epoch has a true position (x_m, y_m)")
    pos = ep.position_m[known]
    distance = np.linalg.norm(pos[:, None, :] - data.anchors_m, axis=-1)
    return pos[:, :2], distance, ep.rss_dbm[known]


def calibrate(data: Dataset, *, mode: str = "per_anchor", fit: str = "closed_form") -> PathLossFit:
    """Path-loss fit on the calibration epochs: ``mode`` ``"per_anchor"`` (one ``(P_0, n)`` per anchor) or
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
        raise ConvergenceError(f"the {fit} {mode} path-loss fit on {data.name!r} failed (solver status "
                               f"{result.status}); not fitted: {failed}")
    exponents = np.atleast_1d(result.path_loss_exp)
    if np.any(exponents <= 0):
        names = list(data.anchor_ids) if exponents.size == len(data.anchor_ids) else ["all"]
        bad = ", ".join(f"{a}: n = {v:.3g}" for a, v in zip(names, exponents) if v <= 0)
        raise ConvergenceError(f"the {fit} {mode} path-loss fit on {data.name!r} gives a path-loss exponent <= 0 "
                               f"({bad}): the anchor's readings do not fall with distance on the calibration "
                               "recordings (a mislabelled anchor or wrong coordinates?); check it, or fit with "
                               "fit='bounded' (exponents in PATH_LOSS_EXP_BOUNDS)")
    return result


def channel(fit: PathLossFit) -> PathLossModel:
    """The fitted channel as a model for the estimators (per-anchor or pooled parameters; shadowing sigma = the
    fit's residual spread; near-field clamp :data:`NEAR_FIELD_M`)."""
    return fit.model(min_distance_m=NEAR_FIELD_M)


def ranging_errors(model: PathLossModel, distance_m, rss_dbm):
    """Range from each reading by the inverted channel minus the true 3-D distance (NaN where not heard)."""
    return model.range_m(rss_dbm) - distance_m


def radio_map(data: Dataset, model: PathLossModel):
    """The k-NN radio map from the calibration epochs: one fingerprint per epoch (positions ``(L, 2)`` and
    readings ``(L, m)``), a reading an anchor did not hear filled with the fitted channel's mean there (the map
    must be complete; the fill is stated in the report). Returns ``(cells, map, filled_fraction)``."""
    xy, distance, rss = calibration_set(data)
    missing = np.isnan(rss)
    filled = np.where(missing, model.mean_rss_dbm(distance), rss)
    return xy, filled, float(missing.mean())


def scored_recordings(data: Dataset) -> list[str]:
    """The recordings the static methods are scored on: the static ones and the tracks with a true position per
    epoch (manifest order)."""
    return [name for name, rec in data.recordings.items()
            if rec.role == "static" or (rec.role == "track" and rec.has_truth)]


@dataclass(frozen=True)
class TestEpochs:
    """The scored epochs of one recording: RSSI ``(T, m)``, true plan positions ``(T, 2)``, times ``(T,)`` and
    the point id of each epoch (``None`` without a point column). Epochs without a true position are left out."""

    rss_dbm: np.ndarray
    truth_m: np.ndarray
    time_s: np.ndarray
    point: np.ndarray | None = None

    __test__ = False      # not a pytest class

    @classmethod
    def of(cls, data: Dataset, recording: str) -> "TestEpochs":
        ep = data.epochs(recording)
        known = np.isfinite(ep.position_m[:, :2]).all(axis=1)
        column = data.recording(recording).point_column
        point = None if column is None else ep.extra[column][known]
        return cls(ep.rss_dbm[known], ep.position_m[known, :2], ep.time_s[known], point)


def static_fixes(data: Dataset, model: PathLossModel, rss_dbm, *, grid_spacing_m: float = 0.1, knn_k: int = 5,
                 chunk: int = 4096) -> dict[str, np.ndarray]:
    """Every static estimator on the readings ``(T, m)`` (one fix per epoch, NaN where a method has none):
    linearized LS, weighted LS (weights ``1 / d_i^4`` of the inverted ranges: the squared-range equations'
    variance grows as ``d^4`` under log-normal shadowing), box-LS on the outline's bounding box, RSS ML started
    at the grid-ML fix on the outline's bounding box (``rss_ml``) and on the whole plane (``rss_ml_free``), grid ML
    on a grid inside the outline, and k-NN on :func:`radio_map`."""
    anchors, height = data.anchors_m, data.tag_height_m
    ranges = model.range_m(rss_dbm)
    lower, upper = outline_box(data.outline_m)
    grid = grid_in_outline(data.outline_m, grid_spacing_m)
    out = {"lls": lateration_ls(anchors, ranges, tag_height_m=height).position_m}
    w = 1.0 / np.where(np.isnan(ranges[:, 1:]), 1.0, ranges[:, 1:]) ** 4
    out["wls"] = lateration_wls(anchors, ranges, w / np.max(w, axis=-1, keepdims=True), tag_height_m=height).position_m
    out["box_ls"] = lateration_box_ls(anchors, ranges, lower, upper, tag_height_m=height).position_m
    grid_fix = grid_ml_position(anchors, rss_dbm, model, grid, chunk=chunk, tag_height_m=height).position_m
    out["grid_ml"] = grid_fix
    out["rss_ml"] = rss_ml_position(anchors, rss_dbm, model, grid_fix, tag_height_m=height,
                                    region_m=(lower, upper)).position_m
    out["rss_ml_free"] = rss_ml_position(anchors, rss_dbm, model, grid_fix, tag_height_m=height).position_m
    cells, fingerprints, _ = radio_map(data, model)
    out["knn"] = knn_position(rss_dbm, fingerprints, cells, knn_k)
    return out


def crlb_m(data: Dataset, model: PathLossModel, positions_m, rss_dbm=None):
    """``sqrt(trace(J^-1))`` of the plan position for the fitted per-anchor channel at plan positions ``(..., 2)``,
    the tag at the data set's known height (3-D distances; the 2-D bound of :func:`locbook.rss_crlb_m`). With the
    epochs' readings ``rss_dbm (..., m)`` the information of each epoch is that of the anchors it heard (an anchor
    not heard tells nothing), and an epoch with too few of them for a fix has NaN (no bound)."""
    heard = None if rss_dbm is None else ~np.isnan(np.asarray(rss_dbm, float))
    bound = rss_crlb_m(positions_m, data.anchors_m, model.path_loss_exp, model.sigma_db,
                       tag_height_m=data.tag_height_m, heard=heard)
    return bound if heard is None else np.where(np.isfinite(bound), bound, np.nan)


def epoch_s(data: Dataset, recording: str) -> float:
    """The epoch clock of a recording (its window, s): the filters' time step."""
    window = data.recording(recording).epoch_rule.window_s
    if not window:
        raise ParameterError(f"recording {recording!r} of {data.name!r} has no epoch window (window_s = 0: its rows "
                             "are epochs at their own times); a tracker needs a clock: give the recording a window_s")
    return float(window)


def _ml_fixes(data: Dataset, model: PathLossModel, rss, grid):
    """RSS-ML fixes ``(E, 2)`` on the outline's bounding box, started at the best point of ``grid`` (NaN where an epoch
    heard no anchor)."""
    lower, upper = outline_box(data.outline_m)
    heard = ~np.isnan(rss).all(axis=-1)
    ml = np.full((rss.shape[0], 2), np.nan)
    grid_fix = grid_ml_position(data.anchors_m, rss[heard], model, grid, tag_height_m=data.tag_height_m).position_m
    ml[heard] = rss_ml_position(data.anchors_m, rss[heard], model, grid_fix, tag_height_m=data.tag_height_m,
                                region_m=(lower, upper)).position_m
    return ml


def _kalman_start(data: Dataset, recording: str, ml):
    """The Kalman filters' start (:func:`tracks`): the first RSS-ML fix with a 2 m standard deviation, at rest."""
    fixed = np.flatnonzero(np.isfinite(ml).all(axis=1))
    if fixed.size == 0:
        raise ParameterError(f"recording {recording!r} of {data.name!r}: no epoch gives an RSS-ML fix to start from")
    return np.r_[ml[fixed[0]], 0.0, 0.0], np.diag([4.0, 4.0, 1.0, 1.0])


def tracks(data: Dataset, model: PathLossModel, recording: str, rng: np.random.Generator, *, q: float,
           fix_cov_m2, spread_m: float, n_particles: int, particle_runs: int, grid_spacing_m: float = 0.1,
           ukf_alpha: float = 0.5, with_divergence: bool = False):
    """Every tracker on one recording put on its epoch clock (:func:`epoch_s`; a tick without an epoch is all NaN:
    the filters predict through it). Returns ``(regular epochs, ticks of the recording's epochs, {tracker: plan
    positions at every tick (T, 2)})``; the particle filter's entry is ``(particle_runs, T, 2)`` (independent
    streams of ``rng``: the spread over them is the filter's own randomness).

    - ``kf_on_ml``: constant-velocity KF (``q``, m^2/s^3 white-acceleration PSD per axis, discrete form) on the
      RSS-ML fixes (on the outline's bounding box) with ``R = fix_cov_m2`` (calibrated on the calibration epochs,
      not on this recording);
    - ``ekf`` (parallel update) and ``ukf`` (``ukf_alpha``): the same motion model on the raw RSSI, per-anchor
      channel, 3-D distances;
    - ``particle``: SIR, ``L_t = L_t-1 + N(0, spread_m^2 I)`` reflected into the outline's box, resampled when
      ``N_eff < N / 2``;
    - ``grid_bayes``: the same random walk on a grid inside the outline (separable transition).
    The starting state of the Kalman filters is the first RSS-ML fix with a 2 m standard deviation, at rest.

    ``with_divergence=True`` appends ``{tracker: flags}`` for ``kf_on_ml``, ``ekf`` and ``ukf``: the NIS guard of the
    one run on the recording (:class:`locbook.tracking.divergence.DivergenceFlags`, steps of the regular clock)."""
    dt = epoch_s(data, recording)
    reg, ticks = regular_epochs(data.epochs(recording), dt, tolerance_s=0.1 * dt)
    rss = reg.rss_dbm
    anchors, height = data.anchors_m, data.tag_height_m
    lower, upper = outline_box(data.outline_m)
    grid = grid_in_outline(data.outline_m, grid_spacing_m)
    ml = _ml_fixes(data, model, rss, grid)
    motion = constant_velocity(dt, q, dim=2)
    x0, P0 = _kalman_start(data, recording, ml)
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    rss_stream = RssMeasurement(rss, anchors, model, np.array([0, 1]), tag_height_m=height)
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


def noise_fit(data: Dataset, model: PathLossModel, recording: str, *, q: float, grid_spacing_m: float = 0.1) -> dict:
    """Maximum-likelihood noise levels of the EKF of :func:`tracks` on one recording, beside the ones it uses.

    The EKF uses a walking-pace prior ``q`` (not tuned) and the channel's sigma_db fitted on the calibration
    recordings. Here the innovations of this recording's own readings choose a multiplier of each
    (:func:`locbook.fit_noise_ml`: Q -> e^a Q, every anchor's sigma_db^2 -> e^b sigma_db^2, the calibrated ratios
    between anchors kept); no truth is used. The EKF is then rerun at the estimate. Returns a dict: ``q`` and
    ``q_ml``, ``sigma_db`` (the calibration's, mean over anchors) and ``sigma_ml_db``, the log-likelihoods, the
    multipliers at their bound, and ``mean_error_m`` / ``mean_error_ml_m`` where the recording has a true position
    per epoch (else None)."""
    from ..tracking.noise import fit_noise_ml
    dt = epoch_s(data, recording)
    reg, ticks = regular_epochs(data.epochs(recording), dt, tolerance_s=0.1 * dt)
    rss = reg.rss_dbm
    anchors, height = data.anchors_m, data.tag_height_m
    heard = np.flatnonzero(~np.isnan(rss).all(axis=-1))
    # as tracks(): the first RSS-ML fix, at rest (each epoch's fix is its own problem: the first alone suffices)
    ml = _ml_fixes(data, model, rss[heard[:1]], grid_in_outline(data.outline_m, grid_spacing_m))
    x0, P0 = _kalman_start(data, recording, ml)
    motion = constant_velocity(dt, q, dim=2)
    stream = RssMeasurement(rss, anchors, model, np.array([0, 1]), tag_height_m=height)
    fit = fit_noise_ml(motion.F, motion.Q, x0, P0, stream, kind="ekf", fit_Q="scale", fit_R="scale", per_run=False)
    sigma = np.asarray(model.sigma_db, dtype=float)
    out = {"recording": recording, "q": q, "q_ml": float(q * fit.q_scale[0]),
           "sigma_db": float(np.mean(sigma)), "sigma_ml_db": float(np.mean(sigma * np.sqrt(fit.r_scale[0][0]))),
           "log_likelihood": float(fit.initial_log_likelihood), "log_likelihood_ml": float(fit.log_likelihood),
           "at_bound": bool(np.any(fit.at_bound)), "mean_error_m": None, "mean_error_ml_m": None}
    ep = data.epochs(recording)
    known = np.isfinite(ep.position_m[:, :2]).all(axis=1)
    if known.any():
        ml_stream = RssMeasurement(rss, anchors, replace(model, sigma_db=fit.R[0]), np.array([0, 1]),
                                   tag_height_m=height)
        for key, Q, st in (("mean_error_m", motion.Q, stream), ("mean_error_ml_m", fit.Q, ml_stream)):
            x = extended_kalman_filter(motion.F, Q, x0, P0, [st]).x[:, :2]
            out[key] = float(np.mean(np.linalg.norm(x[ticks[known]] - ep.position_m[known, :2], axis=-1)))
    return out


def bayes_measurement_model(data: Dataset, model: PathLossModel) -> RssModel:
    """The fitted channel as the likelihood of the particle and grid Bayes filters (per-anchor sigma, 3-D distances,
    the near-field clamp :data:`NEAR_FIELD_M`)."""
    return RssModel(data.anchors_m, PathLossModel(np.asarray(model.ref_power_dbm, float),
                                                  np.asarray(model.path_loss_exp, float),
                                                  np.asarray(model.sigma_db, float), model.ref_distance_m,
                                                  model.wall_attenuation_db, min_distance_m=NEAR_FIELD_M),
                    tag_height_m=data.tag_height_m)


def fix_covariance_from_calibration(data: Dataset, model: PathLossModel, *, grid_spacing_m: float = 0.1):
    """``R`` of the KF on ML fixes: the covariance of RSS-ML fix errors over the calibration epochs (the set the
    channel was fitted on, never a scored recording)."""
    xy, _, rss = calibration_set(data)
    grid = grid_in_outline(data.outline_m, grid_spacing_m)
    grid_fix = grid_ml_position(data.anchors_m, rss, model, grid, tag_height_m=data.tag_height_m).position_m
    fixes = rss_ml_position(data.anchors_m, rss, model, grid_fix, tag_height_m=data.tag_height_m,
                            region_m=outline_box(data.outline_m)).position_m
    ok = np.isfinite(fixes).all(axis=1)
    return fix_error_covariance(fixes[ok], xy[ok])


def outside_fraction(data: Dataset, positions_m) -> float:
    """Fraction of the estimates (finite ones) that lie outside the floor outline."""
    p = np.asarray(positions_m, float).reshape(-1, 2)
    ok = np.isfinite(p).all(axis=1)
    return float(np.mean(~inside_outline(p[ok], data.outline_m))) if ok.any() else float("nan")


def calibration_block_bootstrap(data: Dataset, rng: np.random.Generator, *, n_bootstrap: int, block_s: float,
                                mode: str = "per_anchor"):
    """The per-anchor closed-form fit refitted on ``n_bootstrap`` moving-block resamples of the calibration epochs
    in time order (blocks of ``block_s`` seconds' worth of epochs at the median spacing): neighbouring epochs share
    their shadowing, so resampling single epochs (``block_s`` below one spacing) understates the spread. Returns
    ``(fits of the resamples (a batch PathLossFit), block length in epochs)``."""
    ep = data.epochs_of("calibration")
    _, distance, rss = calibration_set(data)
    time_s = ep.time_s[np.isfinite(ep.position_m[:, :2]).all(axis=1)]
    spacing = float(np.median(np.diff(time_s))) if time_s.size > 1 else 1.0
    block = max(1, int(round(block_s / spacing))) if spacing > 0 else 1
    idx = moving_block_indices(len(time_s), block, n_bootstrap, rng)
    return calibrate_path_loss(distance[idx], rss[idx], mode), block


def record_dataset(report, data: Dataset) -> list[dict]:
    """Put a data set's provenance and assumptions in a report (``report.assumption``: attribution, licence,
    changes, tag height, outline, epoch rule of each recording, the manifest's notes) and return the table of its
    recordings (:func:`locbook.data.dataset.dataset_summary`) for ``report.table``."""
    from ..data.dataset import dataset_summary
    where = f"{data.root.name}/dataset.toml"
    report.assumption("data", f"{data.title}. {data.attribution}", where)
    report.assumption("licence", data.license + (f" ({data.license_file.name})" if data.license_file else ""), where)
    if data.changes:
        report.assumption("changes from the source", data.changes, where)
    for key, note in data.notes.items():
        report.assumption(key.replace("_", " "), note, where)
    if "tag_height_m" not in data.notes:
        report.assumption("tag height", f"{data.tag_height_m:g} m", where)
    for name, rec in data.recordings.items():
        report.assumption(f"epochs of {name}", rec.epoch_rule.describe(), where)
    return dataset_summary(data)
