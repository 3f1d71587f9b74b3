"""A measured data set as the battery's problems (the protocol of :mod:`locbook.scenarios.measured`): loading, the
channel fitted on the calibration recordings (:func:`calibrate`), the radio map, the grid pitch and k-NN's k by their
rules, each track's motion by maximum likelihood (:func:`fit_motion`), the trackers' settings
(:func:`tracker_settings`) and the static and tracking scenarios (:func:`static_scenario`,
:func:`tracking_scenario`).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..battery import (
    KF_FIX_MIN_ANCHORS,
    ProtocolChoice,
    StaticScenario,
    TrackerSettings,
    TrackingScenario,
    channel_settings,
    ml_fixes,
)
from ..battery import STATIC_METHODS as BATTERY_STATIC
from ..battery import TRACKERS as BATTERY_TRACKERS
from ..bounds.crlb import rss_crlb_m
from ..data.dataset import Dataset, dataset_summary, load_dataset
from ..data.floors import require_one_floor
from ..data.measured import epochs as make_epochs
from ..data.measured import regular_epochs
from ..data.selection import select
from ..errors import ConvergenceError, ParameterError
from ..geometry import inside_outline, outline_box
from ..metrics import MIN_BLOCKS
from ..models.channel import PathLossModel
from ..models.motion import constant_velocity
from ..models.rss import RssModel
from ..montecarlo import circular_block_indices, seed_from_values
from ..static.calibration import PathLossFit, calibrate_path_loss, calibrate_path_loss_devices, fix_error_covariance
from ..static.fingerprint import knn_position_per_k
from ..tracking.noise import fit_noise_ml
from ..tracking.streams import LinearMeasurement, RssMeasurement

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


def crlb_m(data: Dataset, model: PathLossModel, positions_m, rss_dbm=None) -> np.ndarray:
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
        est = knn_position_per_k(rss[out], fingerprints[keep], xy[keep], candidates)    # (k, points, 2)
        errors[:, out] = np.linalg.norm(est - xy[out], axis=-1)
    mean = np.nanmean(errors, axis=1)
    best = int(np.nanargmin(mean))
    table = [{"k": k, "mean error (m), leave-one-point-out": round(float(m), 3)} for k, m in zip(candidates, mean)]
    how = (f"rule: leave-one-point-out cross-validation on the calibration map ({n_groups} groups), k = 1-"
           f"{candidates[-1]}: mean error {mean[best]:.2f} m" +
           (" (the largest candidate)" if best == len(candidates) - 1 else ""))
    return candidates[best], how, table


def _start(data: Dataset, recording: str, first_fix) -> np.ndarray:
    fixed = np.flatnonzero(np.isfinite(first_fix).all(axis=1))
    if fixed.size == 0:
        raise ParameterError(f"recording {recording!r} of {data.name!r}: no epoch heard the {KF_FIX_MIN_ANCHORS} "
                             "anchors an rss_ml fix to start the trackers from needs")
    return np.r_[first_fix[fixed[0]], 0.0, 0.0]


#: the random walk's standard deviation per epoch (m) its maximum-likelihood fit starts from (the fit moves its
#: variance by a factor within 1e-4..1e4)
SPREAD_START_M = 0.3


def fit_motion(data: Dataset, model: PathLossModel, recording: str, *, grid_spacing_m: float, fix_cov_m2,
               q_start: float = Q_START) -> dict:
    """Every tracker's motion setting from the track's own readings, by one rule: the maximum-likelihood value of the
    motion model's innovations (:func:`locbook.fit_noise_ml`; no truth is used).

    - ``q`` (m^2/s^4), the white-acceleration variance per step of the Kalman-family trackers: the EKF on the raw
      readings, the channel (sigma per anchor) kept as calibrated, a multiplier of ``q_start``'s Q fitted;
    - ``spread_m`` (m per epoch), the random walk ``L_t = L_t-1 + N(0, s^2 I)`` of the particle and grid Bayes
      filters: the same walk as a Kalman filter (F = I) on the fixes ``kf_on_ml`` filters (``rss_ml``, epochs that heard
      at least 3 anchors) with their calibrated covariance ``fix_cov_m2``, a multiplier of :data:`SPREAD_START_M`'s
      variance fitted (the particle and grid filters' own likelihood of the raw readings has no closed form; the walk
      is the same), and at least half the grid pitch (a narrower walk cannot move on the grid).
    Returns ``{q, spread_m, log_likelihood_gain, spread_log_likelihood_gain, at_bound, spread_at_bound,
    spread_floor}`` (``at_bound``: a multiplier ended at its limit; ``spread_floor``: the half-pitch floor decided)."""
    sc = tracking_scenario(data, model, recording, grid_spacing_m=grid_spacing_m, q=q_start, spread_m=1.0)
    rss = sc.measured_rss_dbm
    motion = constant_velocity(sc.dt_s, q_start, dim=2)
    P0 = tracker_settings(q_start, 1, 1.0, fix_cov_m2).P0
    stream = RssMeasurement(rss, data.anchors_m, model, np.array([0, 1]), tag_height_m=data.tag_height_m)
    fit = fit_noise_ml(motion.F, motion.Q, sc.start_state, P0, stream, kind="ekf", fit_Q="scale", fit_R=None,
                       per_run=False)
    fixes = ml_fixes(sc, rss)
    walk = fit_noise_ml(np.eye(2), SPREAD_START_M**2 * np.eye(2), sc.start_state[:2], P0[:2, :2],
                        LinearMeasurement(fixes, np.eye(2), np.asarray(fix_cov_m2, float)), kind="kf", fit_Q="scale",
                        fit_R=None, per_run=False)
    spread = max(0.5 * grid_spacing_m, SPREAD_START_M * float(np.sqrt(walk.q_scale[0])))
    return {"q": float(q_start * fit.q_scale[0]), "spread_m": spread,
            "log_likelihood_gain": float(fit.log_likelihood - fit.initial_log_likelihood),
            "spread_log_likelihood_gain": float(walk.log_likelihood - walk.initial_log_likelihood),
            "at_bound": bool(np.any(fit.at_bound)), "spread_at_bound": bool(np.any(walk.at_bound)),
            "spread_floor": bool(spread == 0.5 * grid_spacing_m)}


def tracker_settings(q: float, n_particles: int, ukf_alpha: float, fix_cov_m2) -> TrackerSettings:
    """The trackers' settings on a track: the start's position covariance is the calibrated fix covariance."""
    cov = np.asarray(fix_cov_m2, float)
    return TrackerSettings(q=q, initial_position_sd_m=float(np.sqrt(np.trace(cov) / 2.0)),
                           initial_velocity_sd_m_s=START_VELOCITY_SD_M_S, n_particles=n_particles,
                           ukf_alpha=ukf_alpha, initial_position_cov_m2=cov)


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
    sc = StaticScenario("calibration", data.name, "calibration", data.anchors_m, model,
                        np.asarray(data.outline_m, float), xy, grid_spacing_m, (), tag_height_m=data.tag_height_m,
                        measured_rss_dbm=rss)
    fixes = ml_fixes(sc, rss)
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
    start = _start(data, recording, ml_fixes(base, reg.rss_dbm))
    return TrackingScenario(
        f"data-{data.name}", data.name, f"measured: {data.name}, track {recording}, {dt:g} s epochs", data.anchors_m,
        model, np.asarray(data.outline_m, float), truth, dt, spread_m, grid_spacing_m,
        (*_channel_choices(data, model, fit),
         ProtocolChoice("path", f"the track {recording!r} on a {dt:g} s clock ({int(scored.sum())} epochs with truth)",
                        "the data set")),
        tag_height_m=data.tag_height_m, measured_rss_dbm=reg.rss_dbm, scored=scored,
        fix_cov_m2=fix_cov_m2, start_state=start, time_s=reg.time_s, inertial=inertial)
