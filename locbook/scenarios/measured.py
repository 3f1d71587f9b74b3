"""Any measured data set (:mod:`locbook.data.dataset`) run through locbook's battery (:mod:`locbook.battery`): the one
protocol of the ``measured-*`` experiments and of a data set's columns in the cross-document benchmark. Every page
calls the functions below, so one method name gives the same numbers on every page of one run.

Protocol (every choice a named constant or argument, with its reason; nothing here depends on which data set):

- the channel is fitted on the data set's calibration recordings only, and every method is scored on its static and
  track recordings, which the fit never sees; distances are 3-D with the tag at the data set's known height
  (``tag_height_m``), or in the plane for a 2-D data set (anchors without ``z``);
- missing readings (not heard) follow the library's one rule (NaN), in the fit, the estimators and the filters; the
  radio map of k-NN needs a value for each (point, anchor): a reading an anchor did not hear at a calibration epoch is
  filled with the fitted channel's mean there (:func:`radio_map`), stated;
- settings come from the data by stated rules, the same for every method, and the reports name each and how it was
  obtained (:class:`Protocol`): the grid pitch (:func:`grid_pitch_m`), k-NN's k by leave-one-point-out
  cross-validation on the calibration map (:func:`choose_knn_k`), every tracker's motion from the track's own
  readings (:func:`fit_motion`: the white-acceleration variance ``q`` (m^2/s^4) by maximum likelihood of the EKF's
  innovations, the random walk of the particle and grid filters by maximum likelihood of its innovations on the
  fixes ``kf_on_ml`` filters); a value
  given by the user (``-p``) replaces the rule and is named as given;
- every tracker starts from the same state: the first ``rss_ml`` fix of the track, at rest, with
  the calibrated covariance of such fixes as the position block of P_0 and :data:`START_VELOCITY_SD_M_S`;
- bounds are per epoch: the CRLB of the fitted channel at the truth from the anchors each epoch heard (static), the
  posterior CRLB of the trackers' constant-velocity model at the fitted ``q`` from that start (tracking); an epoch
  whose bound is undefined or near-singular is left out of the bound's summary and counted
  (:mod:`locbook.bounds.summary`), and no ratio is drawn from a degenerate bound;
- intervals: the circular block bootstrap over each recording's epochs in time order, blocks of ``block_s``
  seconds (neighbouring epochs share their shadowing); too few blocks and the interval is reported as not
  estimable (:func:`locbook.accuracy_metrics`).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..battery import (STATIC_METHODS as BATTERY_STATIC, TRACKER_PRIORS, TRACKERS as BATTERY_TRACKERS,
                       ProtocolChoice, StaticScenario, TrackerSettings, TrackingScenario, channel_settings,
                       run_trackers, static_bound_checked, static_fixes as battery_static_fixes, tracking_bound_m,
                       initial_states,
                       KF_FIX_MIN_ANCHORS, _ml_fixes)
from ..bounds.crlb import rss_crlb_m
from ..bounds.summary import error_bound_ratio, summarize_bound
from ..data.dataset import Dataset, load_dataset
from ..data.measured import regular_epochs
from ..errors import ConvergenceError, ParameterError
from ..geometry import inside_outline, outline_box
from ..metrics import accuracy_metrics
from ..models.channel import PathLossModel
from ..models.motion import constant_velocity
from ..models.rss import RssModel
from ..montecarlo import seed_from_values
from ..static.calibration import PathLossFit, calibrate_path_loss, fix_error_covariance
from ..static.fingerprint import knn_position
from ..user_methods import MethodFailure, MethodInput, UserMethod, frozen, registered_methods, run_method
from . import measured_ranges as ranging

__all__ = ["PATH_LOSS_EXP_BOUNDS", "REF_POWER_BOUNDS_DBM", "HUBER_DELTA_DB", "NEAR_FIELD_M", "STATIC_METHODS",
           "TRACKERS", "GRID_SPACING_M", "MAX_GRID_CELLS", "KNN_CANDIDATES", "KNN_CV_CELL_M", "Q_START",
           "START_VELOCITY_SD_M_S", "SPREAD_START_M", "load", "calibration_set", "calibrate", "channel",
           "ranging_errors", "radio_map", "scored_recordings", "TestEpochs", "crlb_m", "epoch_s",
           "grid_pitch_m", "choose_knn_k", "fit_motion", "Protocol", "protocol", "static_scenario",
           "tracking_scenario", "static_results", "tracking_results", "RESULT_COLUMNS", "result_row",
           "bayes_measurement_model", "fix_covariance_from_calibration", "outside_fraction",
           "calibration_block_bootstrap", "record_dataset", "geometry_text", "measured_static_scenario",
           "measured_tracking_scenario", "benchmark_rows", "device_offsets_db", "device_corrected", "keyed_stream", "POOLED",
           "FAILURE_COLUMN", "USER_PRIOR", "user_methods", "method_input", "failed_row", "user_method_rows",
           "user_settings_rows", "scored_methods"]

#: bounded fit: exponents and 1-m powers a radio link can physically have (free space n = 2; indoor 1.5-6,
#: Rappaport, Wireless Communications, Table 4.2); wide enough never to bind on data that follow the model
PATH_LOSS_EXP_BOUNDS = (1.0, 6.0)
REF_POWER_BOUNDS_DBM = (-90.0, -20.0)
#: robust fit: residuals beyond 6 dB (about one shadowing sigma indoors) count linearly
HUBER_DELTA_DB = 6.0
#: near-field clamp of the fitted channel (m): below any anchor-to-tag distance of a room-scale deployment
NEAR_FIELD_M = 0.1
#: the battery's methods run on a data set (every one of :mod:`locbook.battery`)
STATIC_METHODS = tuple(BATTERY_STATIC)
TRACKERS = tuple(BATTERY_TRACKERS)
#: grid pitch of grid ML, grid MMSE and grid Bayes (m): a tenth of a metre, far below any method's error indoors...
GRID_SPACING_M = 0.1
#: ...unless the floor needs more cells than this at that pitch; then the pitch that gives this many (memory and
#: time grow with the cells; 250,000 cells is a 50 m x 50 m floor at 0.1 m)
MAX_GRID_CELLS = 250_000
#: k-NN's candidate k, chosen by leave-one-point-out cross-validation on the calibration map (:func:`choose_knn_k`);
#: a map holds many epochs per point (about 20 on danis2022), so k runs to a few points' worth of epochs
KNN_CANDIDATES = (*range(1, 11), 12, 15, 20, 25, 30, 40, 50, 60, 80, 100, 150, 200)
#: without a point column, the calibration epochs are grouped for the cross-validation by the square of this side
#: (m) they lie in: neighbouring epochs of a walked calibration share their place and would make k = 1 look perfect
KNN_CV_CELL_M = 1.0
#: the constant-velocity intensity (m^2/s^4) the maximum-likelihood fit of :func:`fit_motion` starts from (a
#: walking-pace prior; the fit moves it by a factor within 1e-4..1e4)
Q_START = 0.05
#: every tracker's start: the first rss_ml fix with the calibrated covariance of such fixes (the position block of
#: P_0: :func:`fix_covariance_from_calibration`), at rest with this velocity standard deviation (m/s; walkers and
#: robots move at up to ~1.5 m/s)
START_VELOCITY_SD_M_S = 1.0


def load(data, *, calibration="", anchors="") -> Dataset:
    """A data set: a :class:`Dataset` as it is, else a shipped name or a folder (:func:`load_dataset`), on the
    recordings and anchors a run uses (:func:`locbook.data.selection.select`: ``calibration``, the recordings the
    channel is fitted on, and ``anchors``, a subset, each a comma list; empty: the manifest's roles and its ``[run]
    anchors``, else every anchor). The selection applies to a Dataset given too when a value is given."""
    from ..data.selection import select
    if isinstance(data, Dataset) and not (calibration or anchors):
        return data
    return select(data if isinstance(data, Dataset) else load_dataset(data), calibration=calibration, anchors=anchors)


def geometry_text(data: Dataset) -> str:
    """One sentence on the problem's geometry for every report (:attr:`Dataset.geometry_text`)."""
    return data.geometry_text


def device_offsets_db(data: Dataset) -> dict[str, float]:
    """Each device's receiver offset (dB; a device that reads 3 dB strong has +3), fitted jointly with the
    per-anchor channel on the calibration epochs (:func:`locbook.static.calibration.calibrate_path_loss_devices`)
    when the calibration recordings hold more than one device (the readings' ``device`` column, else each
    transmitter); ``{}`` with one device. Every reading of a device is corrected by its offset before any method
    sees it (:func:`device_corrected`); a device the calibration never saw keeps 0 dB (the data set's notes say so)."""
    if "device_offsets_db" not in data._cache:
        ep = data.epochs_of("calibration")
        known = np.isfinite(ep.position_m[:, :2]).all(axis=1)
        devices = np.asarray(ep.device, dtype=object)[known]
        offsets = {}
        if len(set(devices.tolist())) > 1:
            from ..static.calibration import calibrate_path_loss_devices
            _, distance, rss = _calibration_arrays(data, ep, known)
            offsets = {str(k): float(v) for k, v in calibrate_path_loss_devices(distance, rss, devices)[1].items()}
        data._cache["device_offsets_db"] = offsets
    return data._cache["device_offsets_db"]


def device_corrected(data: Dataset, ep):
    """The epochs ``ep`` with each reading corrected by its device's offset (:func:`device_offsets_db`): the
    readings of the reference device, which the channel fit describes. Unchanged with one device."""
    offsets = device_offsets_db(data)
    if not offsets:
        return ep
    shift = np.array([offsets.get(str(d), 0.0) for d in np.asarray(ep.device, dtype=object)], float)
    return replace(ep, rss_dbm=ep.rss_dbm - shift[:, None])


def _calibration_arrays(data: Dataset, ep, known):
    pos = ep.position_m[known]
    if data.anchors_m.shape[1] == 2:
        distance = np.linalg.norm(pos[:, None, :2] - data.anchors_m, axis=-1)
    else:
        pos = pos.copy()
        pos[:, 2] = np.where(np.isfinite(pos[:, 2]), pos[:, 2], data.tag_height_m)
        distance = np.linalg.norm(pos[:, None, :] - data.anchors_m, axis=-1)
    return pos[:, :2], distance, ep.rss_dbm[known]


def calibration_set(data: Dataset):
    """``(positions (L, 2), distances (L, m), RSSI (L, m) with NaN = not heard)`` of the calibration epochs (every
    calibration recording, in manifest order); epochs without a true position are left out. Distances are 3-D from
    each epoch's true position (its true height where recorded, else the tag's known height), in the plane for a
    2-D data set. A whole building with floors is refused (one floor at a time: :mod:`locbook.data.floors`)."""
    from ..data.floors import require_one_floor
    require_one_floor(data)
    ep = data.epochs_of("calibration")
    known = np.isfinite(ep.position_m[:, :2]).all(axis=1)
    if not known.any():
        raise ParameterError(f"data set {data.name!r}: no calibration epoch has a true position (x_m, y_m)")
    return _calibration_arrays(data, device_corrected(data, ep), known)


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
        ep = device_corrected(data, data.epochs(recording))
        known = np.isfinite(ep.position_m[:, :2]).all(axis=1)
        column = data.recording(recording).point_column
        point = None if column is None else ep.extra[column][known]
        return cls(ep.rss_dbm[known], ep.position_m[known, :2], ep.time_s[known], point)


def crlb_m(data: Dataset, model: PathLossModel, positions_m, rss_dbm=None):
    """``sqrt(trace(J^-1))`` of the plan position for the fitted per-anchor channel at plan positions ``(..., 2)``,
    the tag at the data set's known height (3-D distances; the 2-D bound of :func:`locbook.rss_crlb_m`). With the
    epochs' readings ``rss_dbm (..., m)`` the information of each epoch is that of the anchors it heard (an anchor
    not heard tells nothing), and an epoch with too few of them for a fix has NaN (no bound)."""
    heard = None if rss_dbm is None else ~np.isnan(np.asarray(rss_dbm, float))
    bound = rss_crlb_m(positions_m, RssModel(data.anchors_m, PathLossModel(0.0, model.path_loss_exp, model.sigma_db),
                                             tag_height_m=data.tag_height_m), heard=heard)
    return bound if heard is None else np.where(np.isfinite(bound), bound, np.nan)


def epoch_s(data: Dataset, recording: str) -> float:
    """The epoch clock of a recording (s), the filters' time step: its window, or for native scans (``window_s =
    0``: each scan time is an epoch) the median spacing of its epochs (:meth:`Dataset.scan_interval_s`)."""
    return data.scan_interval_s(recording)


def bayes_measurement_model(data: Dataset, model: PathLossModel) -> RssModel:
    """The fitted channel as the likelihood of the particle and grid Bayes filters (per-anchor sigma, 3-D distances,
    the near-field clamp :data:`NEAR_FIELD_M`)."""
    return RssModel(data.anchors_m, PathLossModel(np.asarray(model.ref_power_dbm, float),
                                                  np.asarray(model.path_loss_exp, float),
                                                  np.asarray(model.sigma_db, float), model.ref_distance_m,
                                                  model.wall_attenuation_db, min_distance_m=NEAR_FIELD_M),
                    tag_height_m=data.tag_height_m)


def outside_fraction(data: Dataset, positions_m) -> float:
    """Fraction of the estimates (finite ones) that lie outside the floor outline."""
    p = np.asarray(positions_m, float).reshape(-1, 2)
    ok = np.isfinite(p).all(axis=1)
    return float(np.mean(~inside_outline(p[ok], data.outline_m))) if ok.any() else float("nan")


def calibration_block_bootstrap(data: Dataset, rng: np.random.Generator, *, n_bootstrap: int, block_s: float,
                                mode: str = "per_anchor"):
    """The per-anchor closed-form fit refitted on ``n_bootstrap`` circular block resamples
    (:func:`locbook.montecarlo.circular_block_indices`) of the calibration epochs in time order (blocks of ``block_s``
    seconds' worth of epochs at the median spacing): neighbouring epochs share their shadowing, so resampling single
    epochs (``block_s`` below one spacing) understates the spread. Returns ``(fits of the resamples (a batch
    PathLossFit), block length in epochs, note)``: ``note`` is "" or, when the epochs hold fewer than
    :data:`locbook.metrics.MIN_BLOCKS` blocks, why the spread is not estimable (the fits are then all NaN)."""
    from ..metrics import MIN_BLOCKS
    from ..montecarlo import circular_block_indices
    ep = data.epochs_of("calibration")
    _, distance, rss = calibration_set(data)
    time_s = ep.time_s[np.isfinite(ep.position_m[:, :2]).all(axis=1)]
    spacing = float(np.median(np.diff(time_s))) if time_s.size > 1 else 1.0
    block = max(1, int(round(block_s / spacing))) if spacing > 0 else 1
    idx = circular_block_indices(len(time_s), block, n_bootstrap, rng=rng)
    fits = calibrate_path_loss(distance[idx], rss[idx], mode)
    blocks = len(time_s) / block
    if blocks >= MIN_BLOCKS:
        return fits, block, ""
    note = (f"not estimable: {len(time_s)} calibration epochs hold {blocks:.1f} blocks of {block}; the rule needs at "
            f"least {MIN_BLOCKS:g} blocks")
    nan = np.full_like(np.asarray(fits.path_loss_exp, float), np.nan)
    return replace(fits, ref_power_dbm=nan, path_loss_exp=nan.copy()), block, note


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
    report.assumption("geometry", geometry_text(data), where)
    if "tag_height_m" not in data.notes and data.tag_height_m is not None:
        report.assumption("tag height", f"{data.tag_height_m:g} m", where)
    for name, rec in data.recordings.items():
        report.assumption(f"epochs of {name}", rec.epoch_rule.describe(), where)
    return dataset_summary(data)


# -------------------------------------------------------------------------------------------- settings from data

def keyed_stream(seed: int, *key) -> np.random.Generator:
    """A stream keyed by its use (data set, kind, recording, method): every page that computes one number draws it
    from the same stream, whatever else it computes."""
    return np.random.default_rng(np.random.SeedSequence([int(seed), seed_from_values(*key)]))


def grid_pitch_m(data: Dataset, requested: float | None = None) -> tuple[float, str]:
    """``(pitch (m), how it was obtained)`` of the grid methods: ``requested`` if given, else
    :data:`GRID_SPACING_M`, coarsened to give at most :data:`MAX_GRID_CELLS` cells over the outline's box."""
    if requested is not None:
        return float(requested), "given (-p grid_spacing_m)"
    lower, upper = outline_box(data.outline_m)
    area = float(np.prod(np.asarray(upper) - np.asarray(lower)))
    pitch = max(GRID_SPACING_M, float(np.ceil(np.sqrt(area / MAX_GRID_CELLS) * 100) / 100))
    how = (f"rule: {GRID_SPACING_M:g} m" if pitch == GRID_SPACING_M else
           f"rule: {GRID_SPACING_M:g} m coarsened to {pitch:g} m to keep at most {MAX_GRID_CELLS:,} cells")
    return pitch, how


def _cv_groups(data: Dataset, xy) -> np.ndarray:
    """The calibration epochs' groups for leave-one-out: the point column where every calibration recording has
    one, else the :data:`KNN_CV_CELL_M` square each epoch lies in."""
    names = data.recordings_with("calibration")
    columns = [data.recording(n).point_column for n in names]
    if all(c is not None for c in columns):
        ep = data.epochs_of("calibration")
        known = np.isfinite(ep.position_m[:, :2]).all(axis=1)
        labels = np.concatenate([np.asarray(data.epochs(n).extra[c], dtype=object)
                                 for n, c in zip(names, columns)])
        recs = np.concatenate([np.full(len(data.epochs(n)), i) for i, n in enumerate(names)])
        keys = [f"{r}/{v}" for r, v in zip(recs[known], labels[known])]
        return np.unique(keys, return_inverse=True)[1]
    cells = np.floor(np.asarray(xy) / KNN_CV_CELL_M).astype(np.int64)
    return np.unique(cells, axis=0, return_inverse=True)[1].ravel()


def choose_knn_k(data: Dataset, model: PathLossModel, requested: int | None = None):
    """``(k, how it was obtained, table)``: k-NN's k by leave-one-point-out cross-validation on the calibration map
    (each group of :func:`_cv_groups` located by the map without it; the k of :data:`KNN_CANDIDATES` with the
    smallest mean error, the smaller on a tie); ``requested`` if given. ``table``: ``[{k, mean error}]``."""
    if requested is not None:
        return int(requested), "given (-p knn_k)", []
    xy, fingerprints, _ = radio_map(data, model)
    _, _, rss = calibration_set(data)
    groups = _cv_groups(data, xy)
    n_groups = int(groups.max()) + 1 if groups.size else 0
    candidates = [k for k in KNN_CANDIDATES if k < len(xy)]
    if n_groups < 2 or not candidates:
        k = min(KNN_CANDIDATES[-1], max(1, len(xy) - 1))
        return k, f"fallback k = {k}: the calibration map has fewer than 2 groups to cross-validate", []
    errors = np.full((len(candidates), len(xy)), np.nan)
    for g in range(n_groups):
        out = groups == g
        keep = ~out
        if keep.sum() < max(candidates):
            continue
        for i, k in enumerate(candidates):
            est = knn_position(rss[out], fingerprints[keep], xy[keep], k)
            errors[i, out] = np.linalg.norm(est - xy[out], axis=-1)
    mean = np.nanmean(errors, axis=1)
    best = int(np.nanargmin(mean))
    table = [{"k": k, "mean error (m), leave-one-point-out": round(float(m), 3)} for k, m in zip(candidates, mean)]
    how = (f"rule: leave-one-point-out cross-validation on the calibration map ({n_groups} groups), k = 1-"
           f"{candidates[-1]}: mean error {mean[best]:.2f} m" + (" (the largest candidate)" if best == len(candidates) - 1
                                                                   else ""))
    return candidates[best], how, table


def _start(data: Dataset, recording: str, first_fix) -> np.ndarray:
    fixed = np.flatnonzero(np.isfinite(first_fix).all(axis=1))
    if fixed.size == 0:
        raise ParameterError(f"recording {recording!r} of {data.name!r}: no epoch heard the {KF_FIX_MIN_ANCHORS} anchors "
                             "an rss_ml fix to start the trackers from needs")
    return np.r_[first_fix[fixed[0]], 0.0, 0.0]


#: the random walk's standard deviation per epoch (m) its maximum-likelihood fit starts from (the fit moves its
#: variance by a factor within 1e-4..1e4)
SPREAD_START_M = 0.3


def fit_motion(data: Dataset, model: PathLossModel, recording: str, *, grid_spacing_m: float, fix_cov_m2,
               q_start: float = Q_START) -> dict:
    """Every tracker's motion setting from the track's own readings, by one rule: the maximum-likelihood value of the
    motion model's innovations (:func:`locbook.fit_noise_ml`; no truth is used).

    - ``q`` (m^2/s^4), the white-acceleration variance per step of the Kalman-family trackers: the EKF on the raw readings,
      the channel (sigma per anchor) kept as calibrated, a multiplier of ``q_start``'s Q fitted;
    - ``spread_m`` (m per epoch), the random walk ``L_t = L_t-1 + N(0, s^2 I)`` of the particle and grid Bayes
      filters: the same walk as a Kalman filter (F = I) on the fixes ``kf_on_ml`` filters (``rss_ml``, epochs that heard
      at least 3 anchors) with their calibrated covariance ``fix_cov_m2``, a multiplier of :data:`SPREAD_START_M`'s
      variance fitted (the particle and grid filters' own likelihood of the raw readings has no closed form; the walk
      is the same), and at least half the grid pitch (a narrower walk cannot move on the grid).
    Returns ``{q, spread_m, log_likelihood_gain, spread_log_likelihood_gain, at_bound, spread_at_bound,
    spread_floor}`` (``at_bound``: a multiplier ended at its limit; ``spread_floor``: the half-pitch floor decided)."""
    from ..tracking.noise import fit_noise_ml
    from ..tracking.streams import LinearMeasurement, RssMeasurement
    sc = tracking_scenario(data, model, recording, grid_spacing_m=grid_spacing_m, q=q_start, spread_m=1.0)
    rss = sc.measured_rss_dbm
    motion = constant_velocity(sc.dt_s, q_start, dim=2)
    P0 = _settings(q_start, 1, 1.0, fix_cov_m2).P0
    stream = RssMeasurement(rss, data.anchors_m, model, np.array([0, 1]), tag_height_m=data.tag_height_m)
    fit = fit_noise_ml(motion.F, motion.Q, sc.start_state, P0, stream, kind="ekf", fit_Q="scale", fit_R=None,
                       per_run=False)
    fixes = _ml_fixes(sc, rss)
    walk = fit_noise_ml(np.eye(2), SPREAD_START_M**2 * np.eye(2), sc.start_state[:2], P0[:2, :2],
                        LinearMeasurement(fixes, np.eye(2), np.asarray(fix_cov_m2, float)), kind="kf", fit_Q="scale",
                        fit_R=None, per_run=False)
    spread = max(0.5 * grid_spacing_m, SPREAD_START_M * float(np.sqrt(walk.q_scale[0])))
    return {"q": float(q_start * fit.q_scale[0]), "spread_m": spread,
            "log_likelihood_gain": float(fit.log_likelihood - fit.initial_log_likelihood),
            "spread_log_likelihood_gain": float(walk.log_likelihood - walk.initial_log_likelihood),
            "at_bound": bool(np.any(fit.at_bound)), "spread_at_bound": bool(np.any(walk.at_bound)),
            "spread_floor": bool(spread == 0.5 * grid_spacing_m)}


def _settings(q: float, n_particles: int, ukf_alpha: float, fix_cov_m2) -> TrackerSettings:
    """The trackers' settings on a track: the start's position covariance is the calibrated fix covariance."""
    cov = np.asarray(fix_cov_m2, float)
    return TrackerSettings(q=q, initial_position_sd_m=float(np.sqrt(np.trace(cov) / 2.0)),
                           initial_velocity_sd_m_s=START_VELOCITY_SD_M_S, n_particles=n_particles,
                           ukf_alpha=ukf_alpha, initial_position_cov_m2=cov)


@dataclass(frozen=True)
class Protocol:
    """Every setting of the battery on one data set, each with how it was obtained (:func:`protocol`)."""

    fit: str
    grid_spacing_m: float
    knn_k: int
    motion: dict = field(default_factory=dict)      # recording -> fit_motion's dict (or the given values)
    choices: tuple = ()                              # ({method, setting, value, how}, ...)
    knn_table: tuple = ()
    #: track -> the fusion trackers' inputs (locbook.inertial_trackers.FusionInputs), tracks with inertial streams only
    inertial: dict = field(default_factory=dict)

    def rows(self) -> list[dict]:
        return [dict(c) for c in self.choices]


def protocol(data: Dataset, model: PathLossModel, *, fit: str = "closed_form", grid_spacing_m: float | None = None,
             knn_k: int | None = None, q: float | None = None, spread_m: float | None = None,
             tracks: bool = True) -> Protocol:
    """The settings of every method on ``data`` by the module's rules (its docstring); a value given replaces its
    rule and is named as given. ``tracks=False`` skips the trackers' motion fits (a static report)."""
    pitch, pitch_how = grid_pitch_m(data, grid_spacing_m)
    k, k_how, table = choose_knn_k(data, model, knn_k)
    choices = [{"method": "every method", "setting": "channel", "value": f"per-anchor {fit} fit",
                "how": f"fitted on the calibration recordings ({', '.join(data.recordings_with('calibration'))})"},
               {"method": "every method", "setting": "geometry", "value": geometry_text(data), "how": "the manifest"},
               {"method": "grid_ml, grid_mmse, grid_bayes, rss_ml start", "setting": "grid pitch (m)",
                "value": f"{pitch:g}", "how": pitch_how},
               {"method": "knn", "setting": "k", "value": str(k), "how": k_how}]
    motion, inertial = {}, {}
    if tracks and data.recordings_with("track"):
        fix_cov = fix_covariance_from_calibration(data, model, grid_spacing_m=pitch)
        sd = np.sqrt(np.diag(fix_cov))
        for name in data.recordings_with("track"):
            if q is None or spread_m is None:
                m = fit_motion(data, model, name, grid_spacing_m=pitch, fix_cov_m2=fix_cov)
            else:
                m = {}
            m = {**m, **({"q": float(q)} if q is not None else {}),
                 **({"spread_m": float(spread_m)} if spread_m is not None else {})}
            motion[name] = m
            q_how = "given (-p q)" if q is not None else (
                f"rule: maximum likelihood of the EKF's innovations on this track's readings (log-likelihood +"
                f"{m['log_likelihood_gain']:.1f} over q = {Q_START:g}{'; at the fit bound' if m['at_bound'] else ''})")
            s_how = "given (-p spread_m)" if spread_m is not None else (
                "rule: maximum likelihood of the random walk's innovations on this track's rss_ml fixes (log-likelihood "
                f"+{m['spread_log_likelihood_gain']:.1f} over {SPREAD_START_M:g} m"
                f"{'; at the fit bound' if m.get('spread_at_bound') else ''}"
                f"{'; raised to half the grid pitch' if m.get('spread_floor') else ''})")
            choices += [{"method": "kf_on_ml, ekf, ekf_serial, ukf, imm (its quiet mode)",
                         "setting": f"q (m^2/s^4), {name}",
                         "value": f"{m['q']:.3g}", "how": q_how},
                        {"method": "particle, grid_bayes", "setting": f"random walk (m per epoch), {name}",
                         "value": f"{m['spread_m']:.3g}", "how": s_how}]
        if motion:
            ts0 = TrackerSettings()
            choices.append({"method": "imm", "setting": "manoeuvre mode, switching",
                            "value": f"{ts0.imm_q_ratio:g} q, {ts0.imm_switch_probability:g} per step",
                            "how": "assumed: locbook's choice (a second constant-velocity mode an order of magnitude "
                                   "noisier; a mode lasts 20 epochs on average), not fitted"})
            choices.append({"method": "every tracker", "setting": "start",
                            "value": f"the first rss_ml fix, sd {sd[0]:.2f} m / {sd[1]:.2f} m (x / y), at rest (sd "
                                     f"{START_VELOCITY_SD_M_S:g} m/s)",
                            "how": "rule: the calibrated covariance of rss_ml fixes (the first epoch's readings also "
                                   "update it: a small double use, stated)"})
        from .measured_inertial import fusion_choices, fusion_inputs, inertial_tracks
        for name in inertial_tracks(data):      # tracks with an inertial stream: the fusion trackers' settings
            fus = fusion_inputs(data, model, name, grid_spacing_m=pitch, fix_cov_m2=fix_cov, q=motion[name]["q"])
            choices += fusion_choices(name, fus, first=not inertial)
            if fus is not None:
                inertial[name] = fus
    choices += ranging.range_choices(data)        # the range stream's sigma (none without ranges)
    return Protocol(fit, pitch, k, motion, tuple(choices), tuple(table), inertial)


# ---------------------------------------------------------------------------------------------------- problems

def _channel_choices(data: Dataset, model: PathLossModel, fit: str) -> tuple[ProtocolChoice, ...]:
    return (ProtocolChoice("data", f"{data.title}; {data.license}", f"{data.root.name}/dataset.toml"),
            ProtocolChoice("geometry", geometry_text(data), "the data set's manifest"),
            ProtocolChoice("channel", f"per-anchor {fit} fit on the calibration recordings "
                                      f"({', '.join(data.recordings_with('calibration'))}; never a scored one)",
                           "measured-calibration"),
            *channel_settings(model, "the fit (sigma = residual spread per anchor)"))


def static_scenario(data: Dataset, model: PathLossModel, recordings=None, *, grid_spacing_m: float,
                    fit: str = "closed_form") -> StaticScenario | None:
    """The static problem of ``recordings`` (default: every scored recording, :func:`scored_recordings`): every epoch
    with a true position is a test point with its measured readings; k-NN's radio map is the calibration epochs.
    None when there is nothing to score."""
    names = scored_recordings(data) if recordings is None else list(recordings)
    if not names:
        return None
    tests = [TestEpochs.of(data, n) for n in names]
    truth = np.concatenate([t.truth_m for t in tests])
    rss = np.concatenate([t.rss_dbm for t in tests])
    cells, fingerprints, filled = radio_map(data, model)
    return StaticScenario(
        f"data-{data.name}", data.name, f"measured: {data.name}, {len(data.anchor_ids)} anchors", data.anchors_m,
        model, np.asarray(data.outline_m, float), truth, grid_spacing_m,
        (*_channel_choices(data, model, fit),
         ProtocolChoice("positions", f"the {len(truth)} epochs with a true position of {', '.join(names)}",
                        "the data set"),
         ProtocolChoice("k-NN map", f"the calibration epochs; {100 * filled:.1f} % of readings not heard, filled with "
                                    "the fitted mean", "measured.radio_map"),
         ProtocolChoice("grid pitch", f"{grid_spacing_m:g} m inside the floor outline", "measured.grid_pitch_m")),
        tag_height_m=data.tag_height_m, measured_rss_dbm=rss, radio_map=(cells, fingerprints))


def fix_covariance_from_calibration(data: Dataset, model: PathLossModel, *, grid_spacing_m: float):
    """``R`` of ``kf_on_ml``: the covariance of the errors of the fixes it filters (the ``rss_ml`` method, epochs
    that heard at least 3 anchors) over the calibration epochs (the set the channel was fitted on, never a scored
    recording)."""
    xy, _, rss = calibration_set(data)
    sc = StaticScenario("calibration", data.name, "calibration", data.anchors_m, model, np.asarray(data.outline_m, float),
                        xy, grid_spacing_m, (), tag_height_m=data.tag_height_m, measured_rss_dbm=rss)
    fixes = _ml_fixes(sc, rss)
    ok = np.isfinite(fixes).all(axis=1)
    return fix_error_covariance(fixes[ok], xy[ok])


def track_epochs(data: Dataset, recording: str):
    """``(epochs, epochs on the clock, tick of each epoch)`` of a track (:func:`tracking_scenario`): its epochs
    (device-corrected) put on its epoch clock (:func:`epoch_s`) by :func:`locbook.data.measured.regular_epochs`;
    native scans are first put in windows of the clock's period (the mean of an anchor's scans in a window, as a
    windowed recording's epochs), since jittered scan times can put two scans on one tick."""
    dt = epoch_s(data, recording)
    rec = data.recording(recording)
    if rec.epoch_rule.window_s:
        ep = device_corrected(data, data.epochs(recording))
        reg, ticks = regular_epochs(ep, dt, tolerance_s=0.1 * dt)
    else:
        from ..data.measured import epochs as make_epochs
        ep = device_corrected(data, make_epochs(rec.readings, data.anchor_ids, window_s=dt, aggregate="mean"))
        reg, ticks = regular_epochs(ep, dt, tolerance_s=0.5 * dt)
    return ep, reg, ticks


def tracking_scenario(data: Dataset, model: PathLossModel, recording: str, *, grid_spacing_m: float, q: float,
                      spread_m: float, fix_cov_m2=None, fit: str = "closed_form", inertial=None) -> TrackingScenario:
    """One track on its epoch clock (:func:`epoch_s`; a tick without an epoch is all NaN and unscored; native scans
    are put in windows of the clock's period, so scans with jittered times never share a tick), truth at the ticks of
    the epochs with a true position, and the start every tracker takes (the first rss_ml fix, at rest). ``inertial``:
    the fusion trackers' inputs of the track (:attr:`Protocol.inertial`), None without."""
    dt = epoch_s(data, recording)
    ep, reg, ticks = track_epochs(data, recording)
    truth = np.full((reg.rss_dbm.shape[0], 2), np.nan)
    known = np.isfinite(ep.position_m[:, :2]).all(axis=1)
    truth[ticks[known]] = ep.position_m[known, :2]
    scored = np.isfinite(truth).all(axis=1)
    base = StaticScenario(recording, data.name, recording, data.anchors_m, model, np.asarray(data.outline_m, float),
                          np.zeros((0, 2)), grid_spacing_m, (), tag_height_m=data.tag_height_m)
    start = _start(data, recording, _ml_fixes(base, reg.rss_dbm))
    return TrackingScenario(
        f"data-{data.name}", data.name, f"measured: {data.name}, track {recording}, {dt:g} s epochs", data.anchors_m,
        model, np.asarray(data.outline_m, float), truth, dt, spread_m, grid_spacing_m,
        (*_channel_choices(data, model, fit),
         ProtocolChoice("path", f"the track {recording!r} on a {dt:g} s clock ({int(scored.sum())} epochs with truth)",
                        "the data set")),
        tag_height_m=data.tag_height_m, measured_rss_dbm=reg.rss_dbm, scored=scored,
        fix_cov_m2=fix_cov_m2, start_state=start, time_s=reg.time_s, inertial=inertial)


# ----------------------------------------------------------------------------------------------------- results

#: the results tables' name for every scored recording together (a name the loader reserves)
POOLED = "pooled"
#: the columns of a results table (``results.csv`` of measured-localization and measured-tracking; the benchmark's
#: data columns are the ``pooled`` rows)
RESULT_COLUMNS = ("kind", "recording", "method", "settings", "epochs", "runs", "coverage", "mean_m", "median_m",
                  "p90_m", "ce95_m", "rmse_m", "mean_low_m", "mean_high_m", "rmse_low_m", "rmse_high_m", "interval",
                  "interval_note", "bound", "bound_median_m", "bound_rms_m", "bound_trimmed_rms_m", "bound_excluded",
                  "bound_excluded_why", "ratio", "ratio_note", "outside_outline")
_NO_PRIOR = ("below the bound without a prior: the bound holds for unbiased estimators and for readings that follow "
             "the fitted model; a biased estimator (pulled toward the anchors' centre) or readings less noisy than "
             "the fitted sigma can beat it")
#: a row of a user method that gave no positions (it raised, or returned what
#: :func:`locbook.user_methods.check_output` refuses) says why in this column, after :data:`RESULT_COLUMNS`; the
#: column is there only in a run with user methods ("" on every row that ran), so a run without one writes the
#: columns it always did
FAILURE_COLUMN = "failure"
#: why a user method may fall below the bound (the ratio note of a ratio below 1): locbook cannot know its prior
USER_PRIOR = ("a user method: the bound holds for unbiased estimators that know only the readings and the fitted "
              "channel; whatever else the method uses (the floor, a map, a motion model, a bias toward the room's "
              "centre) can take it below")


def _r(v):
    return None if v is None or not np.isfinite(v) else round(float(v), 3)


def _block(time_s, block_s: float, point=None) -> int:
    """Bootstrap block (epochs): ``block_s`` at the median epoch spacing, and at least the median number of epochs a
    static point holds (epochs at one point share their place and their shadowing: the point is the unit that is
    independent, not the epoch)."""
    t = np.asarray(time_s, float)
    step = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    block = max(1, int(round(block_s / step))) if step > 0 else 1
    if point is not None and len(point):
        changes = np.flatnonzero(np.asarray(point[1:], dtype=object) != np.asarray(point[:-1], dtype=object))
        dwell = np.diff(np.r_[0, changes + 1, len(point)])
        block = max(block, int(np.median(dwell)))
    return block


def result_row(kind: str, recording: str, method: str, errors_m, bound_m, reason, rng: np.random.Generator, *,
               n_bootstrap: int, block: int, settings: str, prior: str, bound_name: str, outside: float) -> dict:
    """One row of :data:`RESULT_COLUMNS`: the errors ``(E, R)`` of ``R`` runs at ``E`` epochs in time order (one run
    for a deterministic method) scored by :func:`locbook.accuracy_metrics` (statistics over every run and epoch;
    the circular block bootstrap over blocks of ``block`` epochs, each epoch with all its runs), beside the bound
    ``(E,)`` summarised without its undefined epochs (``reason``; :func:`locbook.bounds.summary.summarize_bound`)
    and the ratio RMSE / RMS bound over the epochs where the bound is defined (n/a with the reason when it is
    degenerate). A ratio below 1 carries why it can be (``prior``: what the method knows that the bound does not)."""
    e = np.asarray(errors_m, float)
    e = e[:, None] if e.ndim == 1 else e
    m = accuracy_metrics(e.ravel(), rng=rng, n_bootstrap=n_bootstrap, block_length=block, values_per_epoch=e.shape[1])
    summary = summarize_bound(bound_m, reason)
    ratio, note = error_bound_ratio(e.T, summary)
    if not note and np.isfinite(ratio) and ratio < 1:
        note = f"below 1: {prior}" if prior else _NO_PRIOR
    notes = [m.get("interval_note", "")] + [m.get(f"{s}_note", "") for s in ("mean_m", "rmse_m")]
    row = {"kind": kind, "recording": recording, "method": method, "settings": settings, "epochs": int(e.shape[0]),
            "runs": int(e.shape[1]), "coverage": _r(m["coverage"]), "mean_m": _r(m["mean_m"]),
            "median_m": _r(m["median_m"]), "p90_m": _r(m["p90_m"]), "ce95_m": _r(m["ce95_m"]), "rmse_m": _r(m["rmse_m"]),
            "mean_low_m": _r(m["mean_m_low"]), "mean_high_m": _r(m["mean_m_high"]), "rmse_low_m": _r(m["rmse_m_low"]),
            "rmse_high_m": _r(m["rmse_m_high"]), "interval": m.get("interval", ""),
            "interval_note": "; ".join(dict.fromkeys(n for n in notes if n)), "bound": bound_name,
            **{k: (_r(v) if isinstance(v, float) else v) for k, v in summary.row().items()},
            "ratio": _r(ratio), "ratio_note": note, "outside_outline": _r(outside)}
    return {k: row[k] for k in RESULT_COLUMNS}


def failed_row(kind: str, recording: str, method: str, n_epochs: int, bound_m, reason, *, settings: str,
               bound_name: str, failure: str) -> dict:
    """The row of :data:`RESULT_COLUMNS` of a user method that failed (:class:`locbook.user_methods.MethodFailure`):
    no statistic, the bound's summary as every other method's row has it, and its one-line error in
    :data:`FAILURE_COLUMN`."""
    summary = summarize_bound(bound_m, reason)
    row = {c: None for c in RESULT_COLUMNS}
    row.update(kind=kind, recording=recording, method=method, settings=settings, epochs=int(n_epochs), runs=0,
               interval="", interval_note="", bound=bound_name, ratio_note="",
               **{k: (_r(v) if isinstance(v, float) else v) for k, v in summary.row().items() if k in row})
    return {**{k: row[k] for k in RESULT_COLUMNS}, FAILURE_COLUMN: f"failed: {failure}"}


def user_methods(data: Dataset, *, methods=(), trackers=()) -> tuple[UserMethod, ...]:
    """The user methods of a run on ``data``: its manifest's ``[[method]]`` tables, then the command line's static
    ``methods`` and ``trackers`` (``NAME=SPEC``; :func:`locbook.user_methods.registered_methods`)."""
    return registered_methods(data, methods=methods, trackers=trackers)


def method_input(data: Dataset, model: PathLossModel, recording: str, rss_dbm, time_s,
                 rng: np.random.Generator | None, ranges=None) -> MethodInput:
    """What a user method is called with on one recording's epochs (:class:`locbook.MethodInput`): read-only
    copies of the readings, times, anchors and outline, and a copy of the fitted channel with the one
    :class:`RssModel` built from it, so that no method can change what the next one sees. ``ranges``: ``(range_m,
    range_std_m)`` on the same epochs, or None (:mod:`locbook.scenarios.measured_ranges`)."""
    from copy import deepcopy
    channel_copy = deepcopy(model)
    return MethodInput(rss_dbm=frozen(rss_dbm), time_s=frozen(time_s), recording=recording,
                       kind=data.recording(recording).role, tag_height_m=data.tag_height_m,
                       anchors_m=frozen(data.anchors_m), channel=channel_copy,
                       model=RssModel(frozen(data.anchors_m), channel_copy, tag_height_m=data.tag_height_m),
                       outline_m=frozen(data.outline_m), rng=rng,
                       range_m=None if ranges is None else frozen(ranges[0]),
                       range_std_m=None if ranges is None else frozen(ranges[1]))


def _run_user(methods, kind: str, inputs_of) -> tuple[dict, dict, dict]:
    """``(positions {method: {recording: (E, 2)}}, covariances {method: {recording: (E, 2, 2) or None}},
    failures {method: MethodFailure})`` of the user methods of ``kind``; ``inputs_of(method)`` gives its
    ``{recording: MethodInput}``."""
    positions, covariances, failures = {}, {}, {}
    for m in methods:
        if m.kind != kind:
            continue
        got = run_method(m, inputs_of(m))
        if isinstance(got, MethodFailure):
            failures[m.name] = got
            continue
        positions[m.name] = {n: v[0] for n, v in got.items()}
        covariances[m.name] = {n: v[1] for n, v in got.items()}
    return positions, covariances, failures


def scored_methods(res: dict | None) -> list[str]:
    """The methods of a :func:`static_results` or :func:`tracking_results` that gave positions, in table order:
    the battery's, then the user methods that ran (a failed one has rows, no figure)."""
    if res is None:
        return []
    return [*res["battery"], *(m.name for m in res["user"] if m.name not in res["failures"])]


def user_method_rows(*results) -> list[dict]:
    """One row per user method of the ``results`` (:func:`static_results`, :func:`tracking_results`; None skipped):
    name, kind, function (``user method <spec>``), where it was registered, ``ok`` or ``failed``, its one-line
    error and its own traceback. The table the command line reads to say which user method failed."""
    rows = []
    for res in results:
        if res is None:
            continue
        for m in res["user"]:
            f = res["failures"].get(m.name)
            rows.append({"method": m.name, "kind": m.kind, "function": res["described"][m.name],
                         "registered": "[[method]] of the manifest" if m.source == "manifest" else
                         ("--method" if m.kind == "static" else "--tracker") + " on the command line",
                         "status": "failed" if f else "ok", "recording": f.recording if f else "",
                         "error": f.error if f else "", "traceback": f.traceback if f else ""})
    return rows


def user_settings_rows(methods, kind: str | None = None) -> list[dict]:
    """The settings table's rows of the user methods (of ``kind``, default every one): ``user method <spec>``."""
    sees = {"static": "static: every scored epoch on its own", "tracker": "tracker: each track in time order"}
    return [{"method": m.name, "setting": "function", "value": m.described,
             "how": ("the manifest's [[method]] table" if m.source == "manifest" else
                     f"{'--method' if m.kind == 'static' else '--tracker'} on the command line") + f" ({sees[m.kind]})"}
            for m in methods if kind is None or m.kind == kind]


def _static_settings(name: str, proto: Protocol) -> str:
    extra = {"knn": f"k = {proto.knn_k} (calibration map)", "grid_ml": f"pitch {proto.grid_spacing_m:g} m",
             "grid_mmse": f"pitch {proto.grid_spacing_m:g} m",
             "rss_ml": f"grid ML at {proto.grid_spacing_m:g} m", "rss_ml_free": f"grid ML at {proto.grid_spacing_m:g} m"
             }.get(name, "")
    return "; ".join(x for x in (BATTERY_STATIC[name].settings, extra) if x)


def static_results(data: Dataset, model: PathLossModel, proto: Protocol, *, seed: int, n_bootstrap: int,
                   block_s: float, user_methods=()) -> dict | None:
    """Every static method on every scored recording (one problem: each epoch is located on its own), scored per
    recording and pooled (:func:`result_row`; the CRLB from the anchors each epoch heard). None when nothing is
    scored. Returns ``{"recordings", "tests", "fixes", "errors", "bounds", "rows"}`` (per recording: fixes and errors
    ``{method: (E, 2) / (E,)}``, bounds ``(bound, reason)``).

    ``user_methods``: :class:`locbook.user_methods.UserMethod` (its static ones run; a tracker is left to
    :func:`tracking_results`), each called once per scored recording (:func:`method_input`) after the battery and
    scored the same way, its rows after the battery's in each group and its bootstrap stream keyed by its name, so
    no battery number changes. One that fails has rows saying so (:func:`failed_row`) and no fixes. The result also
    holds ``"battery"`` (the battery's names), ``"user"`` (the static user methods), ``"described"`` (``user method
    <spec>`` of each), ``"covariances"`` (``{recording: {method: (E, 2, 2) or None}}``) and ``"failures"``
    (``{method: MethodFailure}``)."""
    names = scored_recordings(data)
    sc = static_scenario(data, model, names, grid_spacing_m=proto.grid_spacing_m, fit=proto.fit)
    if sc is None:
        return None
    tests = {n: TestEpochs.of(data, n) for n in names}
    pooled = battery_static_fixes(sc, sc.measured_rss_dbm[None], knn_k=proto.knn_k)
    cuts = np.cumsum([0] + [len(t.truth_m) for t in tests.values()])
    pooled_bound = static_bound_checked(sc)          # the anchors each epoch heard
    fixes, errors, bounds, rows = {}, {}, {}, []
    for i, n in enumerate(names):
        fixes[n] = {k: v[0, cuts[i]:cuts[i + 1]] for k, v in pooled.items()}
        errors[n] = {k: np.linalg.norm(v - tests[n].truth_m, axis=-1) for k, v in fixes[n].items()}
        bounds[n] = tuple(v[cuts[i]:cuts[i + 1]] for v in pooled_bound)
    ranged = ranging.static_range_results(data, names)     # range_nls where the recordings have ranges
    stream = list(ranging.RANGE_STATIC_METHODS) if ranged is not None else []
    for method in stream:
        for n in names:
            fixes[n][method] = ranged["fixes"][n]
            errors[n][method] = np.linalg.norm(ranged["fixes"][n] - tests[n].truth_m, axis=-1)
    user = tuple(m for m in user_methods if m.kind == "static")
    described = {m.name: m.described for m in user}
    got, covariances, failures = _run_user(user, "static", lambda m: {
        n: method_input(data, model, n, tests[n].rss_dbm, tests[n].time_s,
                        keyed_stream(seed, data.name, "user", "static", n, m.name),
                        ranging.user_ranges(data, n)) for n in names})
    for name, per_recording in got.items():
        for n in names:
            fixes[n][name] = per_recording[n]
            errors[n][name] = np.linalg.norm(per_recording[n] - tests[n].truth_m, axis=-1)
    bound_name = "CRLB (fitted channel, anchors heard)"
    groups = [(POOLED, names)] + [(n, [n]) for n in names]
    for label, members in groups:
        # the largest member's block: a pooled row is never resampled in finer units than one of its recordings
        block = max(_block(tests[n].time_s, block_s, tests[n].point) for n in members)
        bound = np.concatenate([bounds[n][0] for n in members])
        reason = np.concatenate([bounds[n][1] for n in members])
        for method in [*pooled, *stream, *described]:
            if method in failures:
                rows.append(failed_row("static", label, method, len(bound), bound, reason,
                                       settings=described[method], bound_name=bound_name,
                                       failure=failures[method].error))
                continue
            e = np.concatenate([errors[n][method] for n in members])
            f = np.concatenate([fixes[n][method] for n in members])
            own = ranging.RANGE_STATIC_METHODS.get(method)      # a range method: beside the range CRLB
            row = result_row("static", label, method, e,
                             np.concatenate([ranged["bounds"][n][0] for n in members]) if own else bound,
                             np.concatenate([ranged["bounds"][n][1] for n in members]) if own else reason,
                             keyed_stream(seed, data.name, "static", members[0] if len(members) == 1 else label,
                                          method), n_bootstrap=n_bootstrap,
                             block=block, settings=described.get(method) or (own.settings if own else
                                                                             _static_settings(method, proto)),
                             prior=BATTERY_STATIC[method].prior if method in BATTERY_STATIC else
                             own.prior if own else USER_PRIOR,
                             bound_name=ranging.RANGE_BOUND_NAME if own else bound_name,
                             outside=outside_fraction(data, f))
            rows.append(row if method in BATTERY_STATIC or own else {**row, FAILURE_COLUMN: ""})
    return {"recordings": names, "tests": tests, "fixes": fixes, "errors": errors, "bounds": bounds, "rows": rows,
            "scenario": sc, "battery": [*pooled, *stream], "user": user, "described": described, "failures": failures,
            "covariances": {n: {k: v[n] for k, v in covariances.items()} for n in names}}


_KALMAN = ("kf_on_ml", "ekf", "ekf_serial", "ukf")


def tracking_results(data: Dataset, model: PathLossModel, proto: Protocol, *, seed: int, n_particles: int,
                     particle_runs: int, n_bootstrap: int, block_s: float, ukf_alpha: float = 0.5,
                     recordings=None, user_methods=()) -> dict | None:
    """Every tracker on every track (:func:`tracking_scenario`, the motion of :class:`Protocol`), scored per track
    with a true position and pooled over them (:func:`result_row`; the posterior CRLB of the constant-velocity model
    at the track's fitted ``q`` from the trackers' start). The Kalman-family trackers and grid Bayes are
    deterministic (one run); the particle filter runs ``particle_runs`` times on independent streams and is scored
    over all its runs. ``recordings``: the tracks to run (default every one). None without a track. Returns ``{"tracks": {name: (scenario, {tracker: (R, T, 2)}, flags,
    bound (T,))}, "rows"}``.

    ``user_methods``: as for :func:`static_results`; its trackers run once on each track (every tick of its clock,
    in time order: :func:`method_input`), one run, no NIS guard, after the battery, with the same bound and rows
    (``"battery"``, ``"user"``, ``"described"``, ``"covariances"`` ``{track: {tracker: (T, 2, 2) or None}}`` and
    ``"failures"`` as there)."""
    names = data.recordings_with("track") if recordings is None else list(recordings)
    if not names:
        return None
    from .measured_inertial import fusion_knobs
    from ..inertial_trackers import FUSION_PRIORS, FUSION_TRACKERS
    fix_cov = fix_covariance_from_calibration(data, model, grid_spacing_m=proto.grid_spacing_m)
    ranged = ranging.ranged(data, names)
    stream = list(ranging.RANGE_TRACKERS) if ranged else []
    out, per = {}, {}
    for name in names:
        motion = proto.motion[name]
        fus = proto.inertial.get(name)
        sc = tracking_scenario(data, model, name, grid_spacing_m=proto.grid_spacing_m, q=motion["q"],
                               spread_m=motion["spread_m"], fix_cov_m2=fix_cov, fit=proto.fit, inertial=fus)
        ts = _settings(motion["q"], n_particles, ukf_alpha, fix_cov)
        rss = sc.measured_rss_dbm
        x0 = initial_states(sc, ts, 1, None)
        est, flags = run_trackers(sc, rss[None], x0, ts, keyed_stream(seed, data.name, "tracking", name, "kalman"),
                                  trackers=[t for t in TRACKERS if t != "particle"], with_divergence=True)
        fused = {}
        if fus is not None:      # the fusion trackers (deterministic: one run), after the battery's draws
            fused, fused_flags = run_trackers(sc, rss[None], x0, ts,
                                              keyed_stream(seed, data.name, "tracking", name, "fusion"),
                                              trackers=list(fus.trackers),
                                              with_divergence=True)
            flags.update(fused_flags)
        runs = np.broadcast_to(rss, (particle_runs,) + rss.shape)
        est["particle"] = run_trackers(sc, runs, np.repeat(x0, particle_runs, axis=0), ts,
                                       keyed_stream(seed, data.name, "tracking", name, "particle"),
                                       trackers=["particle"])["particle"]
        est = {**{t: est[t] for t in TRACKERS}, **fused}
        range_bound = None
        if name in ranged:      # the range trackers: the RSS stream and the track's ranges
            ep, _, ticks = track_epochs(data, name)
            more, more_flags = ranging.run_range_trackers(data, name, sc, ep, ticks, x0, ts)
            est.update(more)
            flags.update(more_flags)
            range_bound = ranging.range_tracking_bound_m(data, name, sc, ep, ticks, ts)
        bound = tracking_bound_m(sc, ts)
        out[name] = (sc, est, flags, bound)
        if sc.scored is not None and sc.scored.any():
            steps = sc.scored_steps
            per[name] = {"steps": steps, "block": _block(steps * sc.dt_s, block_s), "bound": bound[steps],
                         "range_bound": None if range_bound is None else range_bound[steps],
                         "errors": {t: np.linalg.norm(v[:, steps] - sc.truth_m[steps], axis=-1).T
                                    for t, v in est.items()},
                         "est": {t: v[:, steps] for t, v in est.items()},
                         "knobs": {**_tracker_knobs(proto, name, ts, sc),
                                   **(fusion_knobs(fus, ukf_alpha) if fus is not None else {})}}
            if name in ranged:
                per[name]["knobs"].update(ranging.range_tracker_knobs(data, name, per[name]["knobs"]["ekf"], ts))
    user = tuple(m for m in user_methods if m.kind == "tracker")
    described = {m.name: m.described for m in user}
    got, covariances, failures = _run_user(user, "tracker", lambda m: {
        n: method_input(data, model, n, out[n][0].measured_rss_dbm, out[n][0].time_s,
                        keyed_stream(seed, data.name, "user", "tracking", n, m.name),
                        ranging.user_ranges(data, n, track_epochs(data, n), len(out[n][0].time_s))
                        if data.has_ranges(n) else None)
        for n in names})
    for tracker, per_track in got.items():
        for n in names:
            out[n][1][tracker] = per_track[n][None]           # one run: (1, T, 2), as every tracker's (R, T, 2)
            if n in per:
                steps = per[n]["steps"]
                per[n]["errors"][tracker] = np.linalg.norm(per_track[n][None][:, steps] - out[n][0].truth_m[steps],
                                                           axis=-1).T
                per[n]["est"][tracker] = per_track[n][None][:, steps]
    rows = []
    bound_name = "PCRLB (constant velocity at the fitted q, from the trackers' start)"
    groups = ([(POOLED, list(per))] if per else []) + [(n, [n]) for n in per]
    # the fusion trackers that ran on some track; a row of one pools only groups whose every track has it
    fusion = [t for t in FUSION_TRACKERS if any(t in out[n][1] for n in names)]
    for label, members in groups:
        block = max(per[n]["block"] for n in members)
        bound = np.concatenate([per[n]["bound"] for n in members])
        # a stream's tracker pools only groups whose every track has its stream
        for tracker in [*TRACKERS, *(t for t in [*stream, *fusion] if all(t in per[n]["errors"] for n in members)),
                        *described]:
            if tracker in failures:
                rows.append(failed_row("tracking", label, tracker, len(bound), bound, None,
                                       settings=described[tracker], bound_name=bound_name,
                                       failure=failures[tracker].error))
                continue
            e = np.concatenate([per[n]["errors"][tracker] for n in members])
            # the range trackers are beside the bound of the readings they see: RSS and ranges
            ranged_row = tracker in ranging.RANGE_TRACKERS
            row_bound = np.concatenate([per[n]["range_bound"] for n in members]) if ranged_row else bound
            settings = described.get(tracker) or (per[members[0]]["knobs"][tracker] if len(members) == 1 else
                                                  "motion per track (see each track's row)")
            row = result_row("tracking", label, tracker, e, row_bound, None,
                             keyed_stream(seed, data.name, "tracking", members[0] if len(members) == 1 else label,
                                          tracker, "bootstrap"),
                             n_bootstrap=n_bootstrap, block=block, settings=settings,
                             prior=TRACKER_PRIORS.get(tracker, ranging.RANGE_TRACKER_PRIORS.get(
                                 tracker, FUSION_PRIORS.get(tracker, USER_PRIOR))),
                             bound_name=ranging.RANGE_TRACKING_BOUND_NAME if ranged_row else bound_name,
                             outside=outside_fraction(data, np.concatenate([per[n]["est"][tracker].reshape(-1, 2)
                                                                            for n in members])))
            rows.append(row if tracker in TRACKER_PRIORS or tracker in ranging.RANGE_TRACKERS or tracker in FUSION_PRIORS
                        else {**row, FAILURE_COLUMN: ""})
    return {"tracks": out, "rows": rows, "battery": [*TRACKERS, *stream, *fusion], "fusion": fusion, "user": user,
            "described": described,
            "failures": failures, "covariances": {n: {k: v[n] for k, v in covariances.items()} for n in names}}


def _tracker_knobs(proto: Protocol, name: str, ts: TrackerSettings, sc: TrackingScenario) -> dict:
    fitted = "log_likelihood_gain" in proto.motion[name]
    common = (f"q = {ts.q:.3g} m^2/s^4 ({'fitted' if fitted else 'given'}), dt = {sc.dt_s:g} s, start: first rss_ml "
              f"fix, calibrated fix covariance, at rest (sd {ts.initial_velocity_sd_m_s:g} m/s)")
    walk = (f"random walk {sc.spread_m:.3g} m/epoch "
            f"({'fitted' if 'spread_log_likelihood_gain' in proto.motion[name] else 'given'})")
    return {"kf_on_ml": common + "; R: rss_ml fix errors on the calibration epochs", "ekf": common,
            "ekf_serial": common, "ukf": common + f"; alpha = {ts.ukf_alpha:g}",
            "imm": common + f"; manoeuvre mode {ts.imm_q_ratio:g} q, switching {ts.imm_switch_probability:g} per step "
                            "(locbook's choice)",
            "particle": f"N = {ts.n_particles}, {walk}", "grid_bayes": f"pitch {sc.grid_spacing_m:g} m, {walk}"}


def benchmark_rows(data: Dataset, static: dict | None, tracking: dict | None) -> list[dict]:
    """A data set's cells of the cross-document benchmark: the ``pooled`` rows of :func:`static_results` and
    :func:`tracking_results`, in the benchmark's columns (the same numbers as the data set's own reports)."""
    rows = []
    for kind, res in (("static", static), ("tracking", tracking)):
        if res is None:
            continue
        for r in res["rows"]:
            if r["recording"] != POOLED:
                continue
            rows.append({"kind": kind, "scenario": f"data-{data.name}", "document": data.name, "data": "measured",
                         "method": r["method"], "runs": r["runs"], "points": r["epochs"], "rmse_m": r["rmse_m"],
                         "rmse_low_m": r["rmse_low_m"], "rmse_high_m": r["rmse_high_m"], "interval": r["interval"],
                         "mean_m": r["mean_m"], "median_m": r["median_m"], "p90_m": r["p90_m"],
                         "missing": _r(1.0 - r["coverage"]) if r["coverage"] is not None else None,
                         "bound_rms_m": r["bound_rms_m"], "bound_median_m": r["bound_median_m"],
                         "bound_excluded": r["bound_excluded"], "ratio": r["ratio"], "ratio_note": r["ratio_note"],
                         "bound": "CRLB" if kind == "static" else "PCRLB", "settings": r["settings"],
                         **({FAILURE_COLUMN: r[FAILURE_COLUMN]} if FAILURE_COLUMN in r else {})})
    return rows


def measured_static_scenario(data, fit: str = "closed_form") -> StaticScenario | None:
    """The static problem of a data set (every scored recording; :func:`static_scenario` at the rule's grid pitch);
    None when nothing is scored."""
    ds = load(data)
    model = channel(calibrate(ds, fit=fit))
    return static_scenario(ds, model, grid_spacing_m=grid_pitch_m(ds)[0], fit=fit)


def measured_tracking_scenario(data, fit: str = "closed_form") -> TrackingScenario | None:
    """The first track with a true position per epoch (:func:`tracking_scenario`, its motion by :func:`fit_motion`);
    None when no track has truth."""
    ds = load(data)
    model = channel(calibrate(ds, fit=fit))
    names = [n for n in ds.recordings_with("track") if ds.recording(n).has_truth]
    if not names:
        return None
    pitch = grid_pitch_m(ds)[0]
    fix_cov = fix_covariance_from_calibration(ds, model, grid_spacing_m=pitch)
    m = fit_motion(ds, model, names[0], grid_spacing_m=pitch, fix_cov_m2=fix_cov)
    return tracking_scenario(ds, model, names[0], grid_spacing_m=pitch, q=m["q"], spread_m=m["spread_m"],
                             fix_cov_m2=fix_cov, fit=fit)
