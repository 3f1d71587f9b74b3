"""George and Vadivukkarasi, "Kalman Filtering For RSSI Based Localization System in
Wireless Sensor Networks" (conference paper, about 2015; venue and year not stated).

Test bed: a 2.1 m x 7.8 m corridor with four TelosB (CC2420) anchors at its corners; a walking target
measured at 25 marked points; LDPM calibration at 5 known points, ranging by Eq. (7), linearized
multilateration by Eq. (8), and a constant-velocity Kalman filter on the position fixes.

The paper prints neither the trajectory, the shadowing level, the calibration points, nor Q, R, P0 or
dt; every such value is an explicit argument here, with its default and the reason for it stated
where it is defined. The pipeline is simulated, so the reproduction is of
the method under those assumptions, not of the authors' measured data.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._deprecation import RENAMED_KF_VARIANTS, check_variant
from ..metrics import mean_error_m, position_error_m
from ..models.channel import PathLossModel, pairwise_distance_m
from ..models.motion import constant_velocity
from ..reproduce.printed_values import printed
from ..static.calibration import calibrate_path_loss, fix_error_covariance
from ..static.localization import lateration_ls
from ..tracking.divergence import DivergenceFlags
from ..tracking.kalman import KF_VARIANTS, kalman_filter
from ..tracking.streams import LinearMeasurement

__all__ = [
    "ANCHORS_M", "CORRIDOR_SIZE_M", "PRINTED", "PRINTED_N", "PRINTED_C_RAW", "PRINTED_C_KF",
    "PRINTED_REDUCTION", "PRINTED_REDUCTION_CLAIM", "N_MARKED_POINTS", "CC2420_PA_LEVEL_DBM",
    "DEFAULT_CALIBRATION_POINTS_M", "SIGMA_FITTED_DB",
    "trajectory_m", "MIN_PLAUSIBLE_PATH_LOSS_EXP", "CorridorRuns", "simulate_corridor", "track_with_kalman",
    "kalman_error_vs_q",
    "TRAJECTORIES", "R_MODES", "INIT_MODES",
]

#: Everything the paper prints (locbook/data/printed/george.csv).
PRINTED = printed("george")
#: The corridor, Sec. 5 ("2.1 m wide and 7.8 m long").
CORRIDOR_SIZE_M = (PRINTED.get("Sec. 5", "corridor", "width").value, PRINTED.get("Sec. 5", "corridor", "length").value)
#: Anchor coordinates, Sec. 5 ("fixed at corners of the corridor with coordinates (0,0),(2.1,0),(0,7.8),(2.1,7.8)"),
#: in the listed order (anchor 1 first).
ANCHORS_M = np.array([[0.0, 0.0], [CORRIDOR_SIZE_M[0], 0.0], [0.0, CORRIDOR_SIZE_M[1]], list(CORRIDOR_SIZE_M)])
#: The printed results compared by the notebooks.
PRINTED_N = PRINTED.get("Sec. 6 text", "path-loss exponent n", "mean of 5 calibration locations")
PRINTED_C_RAW = PRINTED.get("Fig. 5 text", "mean error C without filter", "Eq. (15), 25 points")
PRINTED_C_KF = PRINTED.get("Fig. 6 text", "mean error C with Kalman filter", "Eq. (15), 25 points")
PRINTED_REDUCTION = PRINTED.get("Fig. 6 text", "error reduction", "C without filter to C with Kalman filter")
PRINTED_REDUCTION_CLAIM = PRINTED.get("Abstract", "error reduction", "claim")
#: The marked points of the walk, Fig. 5 ("cross 1-25").
N_MARKED_POINTS = int(PRINTED.get("Fig. 5", "marked trajectory points", "cross 1-25").value)

#: CC2420 PA_LEVEL -> output power (dBm), CC2420 datasheet rev 1.3, Table 9 (external to the paper;
#: the paper names levels 3 to 31 only).
CC2420_PA_LEVEL_DBM = {31: 0.0, 27: -1.0, 23: -3.0, 19: -5.0, 15: -7.0, 11: -10.0, 7: -15.0, 3: -25.0}

#: The shadowing sigma (dB) of a per-point mean power at which C without filter is close to the printed 2.2867 m:
#: FITTED (no sentence of the paper gives a sigma), so rows computed under it are calibrations. The declared default
#: is the assumed 3 dB (locbook/data/interpretations/george.csv).
SIGMA_FITTED_DB = 1.83

#: Five calibration points (not printed). Chosen off the corridor centre, where all four anchor
#: distances are equal and the fit is singular; each gives cond(M) <= 18 (our choice and check).
DEFAULT_CALIBRATION_POINTS_M = ((0.525, 1.95), (1.575, 1.95), (0.525, 5.85), (1.575, 5.85), (1.05, 1.0))

TRAJECTORIES = ("centerline", "zigzag")
R_MODES = ("empirical", "isotropic")
INIT_MODES = ("first_measurement", "true_start")


def trajectory_m(kind: str = "centerline", n_points: int = N_MARKED_POINTS) -> np.ndarray:
    """The marked points (25, "cross 1-25"), whose coordinates the paper does not print.

    ``"centerline"``: x = 1.05 m, y from 0.3 to 7.5 m evenly (0.3 m steps for 25 points);
    ``"zigzag"``: the same y with x alternating 0.5 / 1.6 m (an alternative of ours).
    """
    if n_points < 2:
        raise ValueError(f"n_points must be at least 2, got {n_points}")
    y = np.linspace(0.3, 7.5, n_points)
    if kind == "centerline":
        x = np.full(n_points, 1.05)
    elif kind == "zigzag":
        x = np.where(np.arange(n_points) % 2 == 0, 0.5, 1.6)
    else:
        raise ValueError(f"trajectory must be one of {TRAJECTORIES}, got {kind!r}")
    return np.stack([x, y], axis=-1)


#: A calibration whose fitted exponent falls below this has failed: shadowing swamped the 1-8 m spread of the
#: calibration distances (weaker decay than free space, or an inverted slope), and its ranges overflow. Such a
#: run's fixes are NaN and counted, never averaged in (a 6 dB sweep once averaged fixes of 1e121 m).
MIN_PLAUSIBLE_PATH_LOSS_EXP = 1.0


@dataclass(frozen=True)
class CorridorRuns:
    """Monte-Carlo runs of the paper's pipeline up to the unfiltered fixes (leading axis: runs).

    truth_m (T, 2); calibration_rss_dbm (runs, L, 4); fitted ref_power_dbm, path_loss_exp (runs,);
    rss_dbm (runs, T, 4) the per-point mean received powers; fixes_m (runs, T, 2) from Eq. (8), NaN for a
    run whose calibration failed (``calibration_ok`` False, see :data:`MIN_PLAUSIBLE_PATH_LOSS_EXP`).
    """

    truth_m: np.ndarray
    calibration_points_m: np.ndarray
    calibration_rss_dbm: np.ndarray
    ref_power_dbm: np.ndarray
    path_loss_exp: np.ndarray
    rss_dbm: np.ndarray
    fixes_m: np.ndarray
    calibration_ok: np.ndarray

    @property
    def n_failed_calibrations(self) -> int:
        return int(np.sum(~self.calibration_ok))

    def calibrated(self, per_run, axis: int = 0) -> np.ndarray:
        """The entries of ``per_run`` (one per run along ``axis``) of the runs whose calibration succeeded: the runs a
        statistic of the paper's pipeline averages. A failed run has no fixes, so no C of Eq. (15): it is left out and
        counted (:meth:`failed_calibration_note`), never averaged in as NaN (docs/filters.md, missing readings)."""
        per_run = np.asarray(per_run)
        if per_run.ndim == 0 or per_run.shape[axis] != self.calibration_ok.size:
            raise ValueError(f"per_run must hold one entry per run ({self.calibration_ok.size}) along axis {axis}, "
                             f"got shape {per_run.shape}")
        return np.compress(self.calibration_ok, per_run, axis=axis)

    def failed_calibration_note(self, note: str = "") -> str:
        """``note`` followed by the count of runs left out of every statistic because their calibration failed
        (fitted exponent below :data:`MIN_PLAUSIBLE_PATH_LOSS_EXP` or not finite); ``note`` unchanged when none did."""
        failed = self.n_failed_calibrations
        if failed == 0:
            return note
        clause = (f"{failed} of {self.calibration_ok.size} runs left out: their calibration failed (fitted path-loss "
                  f"exponent below {MIN_PLAUSIBLE_PATH_LOSS_EXP:g}), so Eqs. (7)-(8) give no fixes; the statistic is "
                  f"over the other {self.calibration_ok.size - failed}")
        return f"{note}; {clause}" if note else clause

    @property
    def fix_error_m(self) -> np.ndarray:
        return position_error_m(self.fixes_m, self.truth_m)


def simulate_corridor(n_runs: int, truth_m, true_model: PathLossModel, *, rng_calibration: np.random.Generator,
                      rng_tracking: np.random.Generator, calibration_points_m=DEFAULT_CALIBRATION_POINTS_M,
                      calib_mode: str = "per_location_mean", use_calibrated_model: bool = True,
                      ref_anchor: int = 0, min_path_loss_exp: float = MIN_PLAUSIBLE_PATH_LOSS_EXP) -> CorridorRuns:
    """Simulate ``n_runs`` independent repetitions of the experiment (Secs. 5-6 of the paper).

    1. calibration: mean received power at each calibration point from each anchor, LDPM plus
       Gaussian shadowing ``true_model.sigma_db`` (the sigma of a per-point *mean*, after averaging
       packets), fitted by least squares (Eq. (6), sign corrected) in ``calib_mode``;
    2. tracking: the same channel at each trajectory point, ranging by Eq. (7) with the fitted
       (or, if ``use_calibrated_model=False``, the true) model, then Eq. (8) with anchor ``ref_anchor``
       as the reference row; fixes are not constrained to the corridor, as in the paper.

    A run whose calibrated exponent is below ``min_path_loss_exp`` has failed calibration: its fixes are NaN
    (``calibration_ok`` False). With the calibrated model only; the true model never fails.
    """
    truth_m = np.asarray(truth_m, float)
    cal_pts = np.asarray(calibration_points_m, float)
    cal_dist = pairwise_distance_m(cal_pts, ANCHORS_M)                         # (L, 4)
    cal_power = true_model.sample_rss_dbm(np.broadcast_to(cal_dist, (n_runs,) + cal_dist.shape), rng=rng_calibration)
    fit = calibrate_path_loss(np.broadcast_to(cal_dist, cal_power.shape), cal_power, mode=calib_mode,
                              solver="closed_form")
    if calib_mode == "per_anchor":
        ref, exp = fit.ref_power_dbm[:, None, :], fit.path_loss_exp[:, None, :]   # (runs, 1, 4)
    else:
        ref, exp = fit.ref_power_dbm[:, None, None], fit.path_loss_exp[:, None, None]
    dist = pairwise_distance_m(truth_m, ANCHORS_M)                              # (T, 4)
    power = true_model.sample_rss_dbm(np.broadcast_to(dist, (n_runs,) + dist.shape), rng=rng_tracking)
    ok = np.all(fit.path_loss_exp.reshape(n_runs, -1) >= min_path_loss_exp, axis=-1) if use_calibrated_model \
        else np.ones(n_runs, bool)
    ranging = PathLossModel(ref, np.where(ok.reshape((n_runs,) + (1,) * (exp.ndim - 1)), exp, 1.0)) \
        if use_calibrated_model else true_model
    ranges = np.where(ok[:, None, None], ranging.range_m(power), np.nan)     # a failed run: nothing heard
    fixes = lateration_ls(ANCHORS_M, ranges, ref_index=ref_anchor).position_m
    return CorridorRuns(truth_m, cal_pts, cal_power, fit.ref_power_dbm, fit.path_loss_exp, power, fixes, ok)


def track_with_kalman(fixes_m, truth_m, *, q: float, dt_s: float = 1.0, r_mode: str = "empirical",
                      r_iso_m2: float = 3.3, init: str = "first_measurement", init_velocity_var: float = 1.0,
                      variant: str = "corrected", with_divergence: bool = False):
    """Filter the fixes with the constant-velocity KF of Eqs. (9)-(13); returns positions (runs, T, 2).

    Q = q G G^T (white acceleration; the paper prints no Q, only that it was "tuned" to minimise
    C), H = [I 0], U = 0. R is the empirical fix covariance per run (``"empirical"``) or ``r_iso_m2 * I``
    (``"isotropic"``; 3.3 m^2, our default from a pilot simulation of this corridor: the paper says only that R
    is "obtained from experiments"). Initial state (Sec. 4 steps 5.2-5.3, "set the initial position", "initial
    velocity to zero"): the first fix (``"first_measurement"``) or the true start (``"true_start"``), with
    P0 = diag(R_xx, R_yy, v, v). With the first-fix start the first output is that fix.

    ``variant``: the KF's (:func:`locbook.kalman_filter`): ``"corrected"`` or the printed update
    ``"literal_george"`` (``"standard"``, its earlier name: deprecated).

    ``with_divergence=True`` returns ``(positions, flags)``, ``flags`` the KF's NIS guard per run
    (:class:`locbook.tracking.divergence.DivergenceFlags`, steps indexed by marked point): runs without fixes (failed
    calibration) are not filtered, so neither flagged nor counted.
    """
    variant = check_variant(variant, KF_VARIANTS, where="track_with_kalman", renamed=RENAMED_KF_VARIANTS)
    if r_mode not in R_MODES:
        raise ValueError(f"r_mode must be one of {R_MODES}, got {r_mode!r}")
    if init not in INIT_MODES:
        raise ValueError(f"init must be one of {INIT_MODES}, got {init!r}")
    fixes_m = np.asarray(fixes_m, float)
    usable = np.all(np.isfinite(fixes_m), axis=(-2, -1))
    if not usable.all():          # runs without fixes (failed calibration) stay NaN; the others are filtered
        out = np.full(fixes_m.shape, np.nan)
        flags = DivergenceFlags(np.zeros(0, bool), np.zeros(0, np.int64))
        if usable.any():
            out[usable], flags = track_with_kalman(fixes_m[usable], truth_m, q=q, dt_s=dt_s, r_mode=r_mode,
                                                   r_iso_m2=r_iso_m2, init=init, init_velocity_var=init_velocity_var,
                                                   variant=variant, with_divergence=True)
        return (out, flags.scatter(usable)) if with_divergence else out
    model = constant_velocity(dt_s, q)
    H = model.position_measurement_matrix()
    if r_mode == "empirical":
        R = fix_error_covariance(fixes_m, truth_m)
    else:
        R = np.broadcast_to(r_iso_m2 * np.eye(2), fixes_m.shape[:-2] + (2, 2))
    P0 = np.zeros(R.shape[:-2] + (4, 4))
    P0[..., :2, :2] = np.diagonal(R, axis1=-2, axis2=-1)[..., None, :] * np.eye(2)
    P0[..., 2, 2] = P0[..., 3, 3] = init_velocity_var
    if init == "first_measurement":
        x0 = model.state_from(fixes_m[..., 0, :])
        res = kalman_filter(model.F, model.Q, x0, P0, LinearMeasurement(fixes_m[..., 1:, :], H, R), predict_first=True,
                            variant=variant)
        out = np.concatenate([fixes_m[..., :1, :], model.position(res.mean)], axis=-2)
        # the filter's step k is marked point k + 1 (point 0 is the first fix)
        return (out, DivergenceFlags.of(res, step_offset=1)) if with_divergence else out
    x0 = model.state_from(np.broadcast_to(np.asarray(truth_m, float)[0], fixes_m.shape[:-2] + (2,)))
    res = kalman_filter(model.F, model.Q, x0, P0, LinearMeasurement(fixes_m, H, R), predict_first=False,
                        variant=variant)
    out = model.position(res.mean)
    return (out, DivergenceFlags.of(res)) if with_divergence else out


def kalman_error_vs_q(fixes_m, truth_m, q_grid, **kalman) -> tuple[np.ndarray, list[DivergenceFlags]]:
    """The paper's tuning of Q ("tuned" to minimise C, Sec. 4), as a sweep: for each ``q`` of ``q_grid`` the mean
    error C (Eq. (15)) of every run filtered by :func:`track_with_kalman` (``kalman``: its other keywords), shape
    ``(len(q_grid), runs)`` (NaN for runs without fixes), and the NIS guard's flags per ``q``."""
    truth_m = np.asarray(truth_m, float)
    errors, flags = [], []
    for q in np.asarray(q_grid, float).ravel():
        est, flagged = track_with_kalman(fixes_m, truth_m, q=float(q), with_divergence=True, **kalman)
        errors.append(mean_error_m(position_error_m(est, truth_m), axis=-1))
        flags.append(flagged)
    return np.array(errors), flags
