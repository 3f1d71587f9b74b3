"""Dogan (2015), "Indoor Localization and Tracking Based on RSSI and Accelerometer
Measurements", M.Sc. thesis, METU.

One blindfolded node tracked from RSS at four corner anchors with a nearly-constant-acceleration model:
static MLE, a KF on the MLE fixes ("KF (MLE)"), parallel and serial EKFs on the raw RSS, each fused with a
20 Hz accelerometer used as a linear measurement of the acceleration states (Table 3.5), and the posterior
CRLB (Ch. 4).

Every printed value used here is read from ``locbook/data/printed/dogan2015.csv`` (Table 3.6, Eqs. (3.20) and
(3.24), the Sec. 3.5 rates, the Sec. 5.4 area). The thesis prints neither the room of Ch. 3, nor the trajectory,
nor the time step. Every such value is a named default here, with its reason beside it: the room is the test-bed room
7.6 m x 9.2 m (inferred), the trajectory a 24 m polyline walked at 0.3 m/s in 80 s (our choice), a 20 Hz grid
for the fused filters with RSS at every 10th step (Table 3.5), the ONLY-RSS filters stepping once per RSS epoch
(:data:`RSS_ONLY_STEPS`; the 20 Hz grid is the declared alternative), and the MLE an unconstrained grid +
Levenberg-Marquardt search (the thesis names no solver).

The fusion reading (how the filter's Q and P_0 relate to sigma_ACC, and how the node starts) is a named option,
:data:`NOISE_READINGS` and :data:`START_MODES`. The defaults follow the printed text (issue 28's rule): Q and
P_0,acc as the constants of Eqs. (3.20), (3.24) and a node starting from rest, as the thesis's own x_0. A reading
chosen because it fits printed output (Q scaled with sigma_ACC, fitted to Table 3.9; the moving start with its
walking speed, fitted to Fig. 3.2) is a named alternative, and every row computed under it is ``calibrated`` and names
it (:func:`fitted_readings`).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..models.channel import PathLossModel, pairwise_distance_m
from ..reproduce.printed_values import printed
from ..reproduce.scoring import Ambiguity
from ..metrics import rmse_m
from ..montecarlo import jackknife_standard_error, replicate_standard_error
from ..errors import ParameterError
from ..tracking.kalman import extended_kalman_filter
from ..tracking.results import KalmanResult
from ..tracking.streams import LinearMeasurement, RssMeasurement
from ..tracking.transition import per_step
from ..static.localization import grid_ml_position, rss_ml_position
from ..models.motion import KinematicModel, constant_acceleration, simulate_states
from ..models.rss import RssModel
from ..models.trajectory import POLYLINE_STARTS, Trajectory, polyline_trajectory
from ..bounds.pcrlb import linear_measurement_information, position_bound_m, posterior_crlb, rss_state_information
from ..tracking.divergence import DivergenceFlags, divergence_note, divergence_rows

__all__ = [
    "PRINTED", "ROOM_M", "ANCHORS_M", "corner_anchors", "STATE_LAYOUT", "REF_POWER_DBM",
    "PATH_LOSS_EXP", "SIGMA_RSS_DB", "SIGMA_ACC_MPS2", "Q_PER_STEP", "DT_S", "RSS_EVERY", "P00_VEL_VAR",
    "P00_ACC_VAR", "WAYPOINTS_M", "SPEED_MPS", "SPEED_CALIBRATED_FROM", "SPEED_ASSUMED", "MC_RUNS", "START_MODES",
    "DEFAULT_START", "NOISE_READINGS", "DEFAULT_NOISE_READING", "NOISE_CALIBRATED_FROM", "Q_PER_ACC_VARIANCE",
    "filter_noise", "fitted_readings", "speed_reason", "FILTERS",
    "walk_trajectory", "motion_model", "simulate_rss", "simulate_acceleration", "mle_positions", "mle_cost_eq24",
    "initial_state", "filter_inputs", "run_filter", "ChannelRun", "run_channel", "noise_fit", "printed_tables", "TABLE_SETTINGS", "TableSetting",
    "table_channels", "record_tables", "bound_rows", "thesis_repeat_error", "tail_rows",
    "fusion_reduction_rows", "ordering_rows", "table_view", "BOUND_KINDS", "pcrlb_m",
    "smc_trajectories", "smc_trajectory", "CHANNELS", "run_tables", "table_rows", "only_acc_errors",
    "fusion_gain_pct", "mean_rmse_m", "printed_fusion_gains_pct", "REPEATED_ROWS", "readings_summary",
    "RMSE_TABLES", "TABLE_SIGMA_ACC_MPS2", "TABLE_36_CHANNEL", "SIGMA_ACC_SWEEP_CHANNELS", "MLE_R_READINGS",
    "divergence_table", "MLE_BOUNDS", "RMSE_EPOCHS", "PCRLB_MSE_MLE", "room_waypoints", "scored_errors",
    "RSS_ONLY_STEPS", "DEFAULT_RSS_ONLY_STEP", "rss_grid", "filter_grid", "MOVING_START_FITTED",
]

#: Everything the thesis prints (locbook/data/printed/dogan2015.csv).
PRINTED = printed("dogan2015")


def _value(location: str, item: str, statistic: str = "") -> float:
    return PRINTED.get(location, item, statistic).value


#: Room of Ch. 3, inferred to be the test-bed area of Sec. 5.4 ("a 7.6 m x 9.2 m area"; inferred from
#: the Fig 3.1 axes and Sec. 5.4's "the same trajectory", and of the rooms we tried only this one reproduces the
#: MLE column of Tables 3.7/3.11).
ROOM_M = (_value("Sec. 5.4", "area", "width"), _value("Sec. 5.4", "area", "length"))


def _room(room_m) -> tuple[float, float]:
    room = np.asarray(room_m, dtype=float)
    if room.shape != (2,) or not np.all(np.isfinite(room)) or not np.all(room > 0):
        raise ParameterError(f"room_m must be two positive finite sides (width, length) in m, got {room_m!r}")
    return float(room[0]), float(room[1])


def corner_anchors(room_m=ROOM_M) -> np.ndarray:
    """Anchors A1-A4 at the corners of the room, in the order of Sec. 5.4: (0, 0), (w, 0), (w, l), (0, l)."""
    w, length = _room(room_m)
    return np.array([[0.0, 0.0], [w, 0.0], [w, length], [0.0, length]])


#: The four anchors of Sec. 5.4 ("anchor 1 at the point (0,0), anchor 2 at (7.6,0), ..."), the layout of every
#: simulation of Ch. 3-4 ("4 anchors at the corners of the room"). Passed as ``anchors_m`` to every function.
ANCHORS_M = corner_anchors(ROOM_M)
#: The state layout of Eq. (3.10), per axis: ``[x, vx, ax, y, vy, ay]``; the positions sit at indices 0 and 3.
STATE_LAYOUT = ("x", "vx", "ax", "y", "vy", "ay")
#: Table 3.6: first-meter power P0 (dBm), path-loss exponent alpha, sigma_RSS (dB), sigma_ACC (m/s^2).
REF_POWER_DBM = _value("Table 3.6", "first meter power of RSS P0")
PATH_LOSS_EXP = _value("Table 3.6", "path loss exponent alpha")
SIGMA_RSS_DB = _value("Table 3.6", "standard deviation of RSS sigma_RSS")
SIGMA_ACC_MPS2 = _value("Table 3.6", "standard deviation of acceleration sigma_ACC")
#: Eq. (3.24): Q = 0.000023 I_6 per step, full rank, not scaled with T ("standard deviation of the process
#: noise is 0.0048", Sec. 4.1.2).
Q_PER_STEP = _value("Eq. (3.24)", "process noise covariance Q", "per-step variance (Q = value x I_6)")
#: Sec. 3.5: 20 Hz accelerometer, "2 RSS measurements are taken each second". One common grid at the
#: accelerometer rate (the step is not printed) with the RSS at every 10th step.
_ACC_HZ = _value("Sec. 3.5 text", "acceleration measurements", "rate")
_RSS_HZ = _value("Sec. 3.5 text", "RSS measurements", "rate")
DT_S = 1.0 / _ACC_HZ
RSS_EVERY = int(round(_ACC_HZ / _RSS_HZ))
#: Eq. (3.20): initial velocity and acceleration variances of P_{0|0}.
P00_VEL_VAR = _value("Eq. (3.20)", "P_0|0", "velocity variance")
P00_ACC_VAR = _value("Eq. (3.20)", "P_0|0", "acceleration variance")
#: Default trajectory (not printed): a 24 m polyline with sharp 90-degree turns inside the room.
WAYPOINTS_M = ((1.0, 1.0), (1.0, 8.2), (6.6, 8.2), (6.6, 1.0), (2.6, 1.0))
#: Walking speed (not printed): 24 m in 80 s. Under the ``"moving"`` start it is the speed whose unobserved initial
#: velocity gives Fig 3.2's "24 meter after 80 seconds" ONLY-ACC drift (our simulation), i.e. a calibration of that
#: start: rows run there are ``calibrated`` (:data:`SPEED_CALIBRATED_FROM`). Under the default ``"rest"`` start no
#: printed number fixes it (the ONLY-ACC drift from rest is the integrated accelerometer noise, about 1.75 m at 80 s
#: whatever the speed), so it is an open assumption there (:data:`SPEED_ASSUMED`).
SPEED_MPS = 0.3
SPEED_CALIBRATED_FROM = ("walking speed 0.3 m/s (24 m polyline in 80 s) chosen so that an unobserved initial "
                         "velocity gives the ONLY-ACC drift 'reaches to 24 meter after 80 seconds' (Fig. 3.2 text)")
SPEED_ASSUMED = ("not printed: an open assumption under the start from rest (no printed number fixes it there: from "
                 "rest the ONLY-ACC drift of Fig. 3.2 is the integrated accelerometer noise whatever the speed); "
                 "0.3 m/s keeps our 24 m polyline at Fig. 3.2's 80 s; plausible walking range 0.2-1.5 m/s")
#: Monte-Carlo runs (Sec. 3.5).
MC_RUNS = int(_value("Sec. 3.5 text", "Monte Carlo runs"))
#: The true node's initial motion (not printed).
#: ``"rest"``: it starts from rest and accelerates uniformly to SPEED_MPS over ``ramp_s``: the reading of the
#: thesis's own initialisation, Eqs. (3.19)-(3.20), x_0 with zero velocity and velocity variance 0.0065 (sd
#: 0.08 m/s), which a node walking at 0.3 m/s would violate by 3.7 sd. Default.
#: ``"moving"``: it walks at SPEED_MPS from t = 0 (a labelled alternative): the start under which SPEED_MPS was
#: calibrated from Fig. 3.2's 24 m ONLY-ACC drift, but which leaves the fused EKFs an unobserved 0.3 m/s velocity
#: error from which 4-6 % of runs diverge beyond 4 m at 6 dB (the thesis saw "4 m errors" at worst, Fig. 3.10 text).
START_MODES = POLYLINE_STARTS
DEFAULT_START = "rest"
#: How the filter's process noise and the acceleration variance of P_{0|0} relate to sigma_ACC.
#: ``"printed"``: Q = 0.000023 I_6 per step and P_{0|0,acc} = 0.00023 whatever sigma_ACC: Eqs. (3.20), (3.24) as
#: the text prints them, constants, and Sec. 4.1.2's "the standard deviation of the process noise is 0.0048 in our
#: system" (0.0048^2 = 2.3e-5) while sigma_ACC is swept. Default (issue 28: the default reading is what the text
#: prints).
#: ``"sigma_acc"``: Q = sigma_ACC^2 / 10 I_6 per step and P_{0|0,acc} = sigma_ACC^2, for the sigma_ACC of the row
#: (Table 3.6's 0.0152 for ONLY RSS); a labelled alternative fitted to output (:data:`NOISE_CALIBRATED_FROM`). The
#: printed constants are exactly these at Table 3.6's sigma_ACC (Eq. (3.24)'s 0.000023 = 0.0152^2 / 10, Eq. (3.20)'s
#: 0.00023 = 0.0152^2, tested), and the printed KF (MLE), a linear filter that never diverges, falls 1.34 -> 1.02 ->
#: 0.98 -> 0.96 m with sigma_ACC in Table 3.9, which no fixed-Q filter does (the isotropic Q adds about 40x more
#: velocity uncertainty per step than the accelerometer noise). Measured trade-off (dogan2015-tracking,
#: readings_summary): it brings KF (MLE) to within about 1-2 % of the printed sigma_ACC <= 0.0075 cells, but with Q
#: this small a few EKF runs lock onto a wrong position, which inflates the EKFs' RMSE.
MOVING_START_FITTED = ("start 'moving' (the node walks from t = 0) chosen because, at the walking speed 0.3 m/s, its "
                       "unobserved initial velocity gives Fig. 3.2's 'reaches to 24 meter after 80 seconds'; no text "
                       "supports a moving start (Eqs. (3.19)-(3.20) start the filter at zero velocity, and Fig. 3.2's text "
                       "blames 'the error of the acceleration')")
NOISE_READINGS = ("printed", "sigma_acc")
DEFAULT_NOISE_READING = "printed"
NOISE_CALIBRATED_FROM = ("noise reading 'sigma_acc' (Q = sigma_ACC^2/10 I_6, P_0,acc = sigma_ACC^2 per row) chosen "
                         "because it fits the printed KF (MLE) fall with sigma_ACC of Table 3.9 (the text prints Q and "
                         "P_0,acc as constants, Eqs. (3.20), (3.24))")
#: Q per step over sigma_ACC^2 in the ``"sigma_acc"`` reading (0.000023 / 0.0152^2 = 0.0996).
Q_PER_ACC_VARIANCE = 0.1
#: KF (MLE)'s R = diag(MSE_MLE) (Eq. (3.21); constant or per epoch is not stated): ``"constant"``, the MSE per
#: axis averaged over runs and epochs ("averaging Mean Squared Error (MSE) of static localization over 500 Monte
#: Carlo runs", Sec. 3.5; default), or ``"per_epoch"``, averaged over runs at each epoch (Table 4.1 indexes R_{RSS-MLE,k+1} by time; variant).
MLE_R_READINGS = ("constant", "per_epoch")
#: Filter columns of Tables 3.7-3.12.
FILTERS = ("parallel_ekf", "serial_ekf", "kalman_filter")
#: MLE search grid (the thesis names no solver): the room +- 3 m at 0.5 m, then Levenberg-Marquardt, unconstrained.
MLE_GRID_STEP_M = 0.5
MLE_GRID_MARGIN_M = 3.0
#: The MLE's domain (Sec. 2.3.1 names no solver, start or bounds): ``"unconstrained"`` (default), or ``"room"``: the
#: unconstrained fix projected onto the room inset by :data:`MLE_ROOM_INSET_M` (each coordinate clipped), the simplest
#: reading of a fix known to lie in the room (not the box-constrained minimiser of Eq. (2.4)).
MLE_BOUNDS = ("unconstrained", "room")
#: Inset of the ``"room"`` bound from the walls: a fix clipped into a corner would sit on an anchor, where the RSS
#: model (Eq. (2.2)) is singular and an EKF started there cannot linearise; 0.1 m keeps it off (our choice).
MLE_ROOM_INSET_M = 0.1
#: The steps of the tables' RMSE (Tables 3.7-3.12 do not define it): ``"rss_epochs"`` (default: every filter where
#: the MLE exists) or ``"every_step"``: the filters at every step of the 20 Hz grid from the first RSS epoch (the MLE
#: column stays at the RSS epochs, where it exists).
RMSE_EPOCHS = ("rss_epochs", "every_step")
#: How the PCRLB uses the MLE's per-axis MSE (Eq. (3.20), Sec. 4.1.2; not stated): ``"runs_and_epochs"`` (default:
#: one MSE per axis averaged over runs and epochs, for P_0 and every epoch's R of the linear bound) or
#: ``"per_epoch"``: averaged over runs at each epoch, P_0 from the first epoch's, the linear bound's R_k per epoch.
PCRLB_MSE_MLE = ("runs_and_epochs", "per_epoch")
#: The step of the ONLY-RSS filters (KF (MLE), parallel and serial EKF without the accelerometer; not printed, and Q of
#: Eq. (3.24) is per step, so the step sets their process noise): ``"rss_rate"`` (default), one prediction and one
#: update per RSS epoch (0.5 s at Sec. 3.5's 2 Hz, 2 s on the test bed's packet period): the recursion of Eqs.
#: (3.3)-(3.5) and Tables 3.1-3.4, each k a prediction and a measurement update, "the filtering process is repeated
#: when a new measurement is available" (Sec. 3.3), and only the RSS feeds them; ``"imu_rate"``: the grid of the
#: fused filters (Table 3.5, 20 Hz "In RSS/IMU fusion case"), predicting 9 times between RSS epochs with Q each
#: time (the same per-step Q and the same grid for every filter of the ONLY RSS / RSS-IMU comparisons). The fused
#: filters always step on the trajectory's grid (Table 3.5).
RSS_ONLY_STEPS = ("rss_rate", "imu_rate")
DEFAULT_RSS_ONLY_STEP = "rss_rate"


def filter_noise(reading: str, sigma_acc_mps2: float | None) -> tuple[float, float]:
    """``(q_per_step, p0_acc_var)`` of the filter under a :data:`NOISE_READINGS` reading.

    ``"sigma_acc"``: ``(Q_PER_ACC_VARIANCE sigma^2, sigma^2)`` with sigma the row's sigma_ACC, or Table 3.6's
    sigma_ACC for ONLY RSS (``None``); ``"printed"``: Eq. (3.24)'s Q and Eq. (3.20)'s acceleration variance."""
    if reading not in NOISE_READINGS:
        raise ParameterError(f"noise reading must be one of {NOISE_READINGS}, got {reading!r}")
    if reading == "printed":
        return Q_PER_STEP, P00_ACC_VAR
    sigma = SIGMA_ACC_MPS2 if sigma_acc_mps2 is None else float(sigma_acc_mps2)
    if not sigma > 0:
        raise ParameterError(f"sigma_acc_mps2 must be positive, got {sigma_acc_mps2!r}")
    return Q_PER_ACC_VARIANCE * sigma**2, sigma**2


def fitted_readings(start: str = DEFAULT_START, noise_reading: str = DEFAULT_NOISE_READING, *,
                    speed_mps: float = SPEED_MPS) -> str:
    """The readings fitted to printed output that a row computed under ``start`` and ``noise_reading`` used, as the
    row's ``calibrated_from`` text, ``"; "``-joined; ``""`` when none (the row is then a ``reproduction``).

    Issue 45's rule (fitted: no text supports it and it was chosen because it fits): the ``"moving"`` start
    (:data:`MOVING_START_FITTED`), with the walking speed :data:`SPEED_MPS` fitted to Fig. 3.2's drift under it
    (:data:`SPEED_CALIBRATED_FROM`), and the ``"sigma_acc"`` noise reading fitted to Table 3.9
    (:data:`NOISE_CALIBRATED_FROM`); the ``"rest"`` start and the ``"printed"`` reading are the text's own
    (Eqs. (3.19)-(3.20), (3.24)). The ONLY-RSS step (:data:`RSS_ONLY_STEPS`) is textual either way."""
    if start not in START_MODES:
        raise ParameterError(f"start must be one of {START_MODES}, got {start!r}")
    if noise_reading not in NOISE_READINGS:
        raise ParameterError(f"noise_reading must be one of {NOISE_READINGS}, got {noise_reading!r}")
    used = []
    if start == "moving":               # issue 45: no text supports it; it was declared for Fig. 3.2's drift
        used.append(MOVING_START_FITTED)
        if float(speed_mps) == SPEED_MPS:
            used.append(SPEED_CALIBRATED_FROM)
    if noise_reading == "sigma_acc":
        used.append(NOISE_CALIBRATED_FROM)
    return "; ".join(used)


def speed_reason(start: str = DEFAULT_START, speed_mps: float = SPEED_MPS) -> str:
    """Why the walking speed has its value under ``start``: calibrated from Fig. 3.2 (the ``"moving"`` start at
    :data:`SPEED_MPS`), or an open assumption (:data:`SPEED_ASSUMED` from rest)."""
    if start == "moving":
        return (SPEED_CALIBRATED_FROM if float(speed_mps) == SPEED_MPS else
                f"not printed: our choice; under the moving start Fig. 3.2's 24 m drift calls for {SPEED_MPS:g} m/s")
    return SPEED_ASSUMED



def room_waypoints(waypoints_m=WAYPOINTS_M, room_m=ROOM_M):
    """Fig. 3.1's path, drawn in the frame of the default room :data:`ROOM_M`, read in a room of sides ``room_m``:
    every coordinate scaled by the ratio of the rooms' sides (Fig. 3.1 draws the path relative to the room, with no
    coordinates). The default room returns ``waypoints_m`` itself."""
    scale = np.asarray(_room(room_m)) / np.asarray(ROOM_M, dtype=float)
    if np.all(scale == 1.0):
        return waypoints_m
    return (np.asarray(waypoints_m, dtype=float) * scale).tolist()


def walk_trajectory(waypoints_m=WAYPOINTS_M, speed_m_s: float = SPEED_MPS, dt_s: float = DT_S, *,
                    start: str = DEFAULT_START, ramp_s: float = 2.0, rss_every: int = RSS_EVERY) -> Trajectory:
    """The default walk for Fig. 3.1's unprinted path (:func:`~locbook.models.trajectory.polyline_trajectory`): the
    polyline at constant speed, sampled at the accelerometer's rate, RSS every ``rss_every``-th sample (Sec. 3.5)."""
    return polyline_trajectory(waypoints_m, speed_m_s=speed_m_s, dt_s=dt_s, start=start, ramp_s=ramp_s,
                               rss_every=rss_every)


def rss_grid(trajectory: Trajectory) -> Trajectory:
    """``trajectory`` sampled at its RSS epochs only (``rss_steps`` then ``0 .. E - 1``): the grid of an ONLY-RSS filter
    stepping at the RSS rate (:data:`RSS_ONLY_STEPS`). The epochs must be evenly spaced (one step)."""
    steps = np.asarray(trajectory.rss_steps)
    spacing = np.diff(steps)
    if steps.size < 2 or np.any(spacing != spacing[0]):
        raise ParameterError("the RSS-rate grid needs at least two evenly spaced RSS epochs")

    def at(a, axis):
        return None if a is None else np.take(a, steps, axis=axis)
    return replace(trajectory, time_s=trajectory.time_s[steps], position_m=at(trajectory.position_m, -2),
                   velocity_m_s=at(trajectory.velocity_m_s, -2), acceleration_m_s2=at(trajectory.acceleration_m_s2, -2),
                   heading_rad=at(trajectory.heading_rad, -1), yaw_rate_rad_s=at(trajectory.yaw_rate_rad_s, -1),
                   arc_length_m=at(trajectory.arc_length_m, -1), rss_steps=np.arange(steps.size))


def filter_grid(trajectory: Trajectory, fusion: bool, rss_only_step: str = DEFAULT_RSS_ONLY_STEP) -> Trajectory:
    """The grid a filter of Tables 3.7-3.12 steps on: the trajectory's for a fused filter (Table 3.5: a prediction at
    every accelerometer sample) and for an ONLY-RSS filter under ``"imu_rate"``; its RSS epochs (:func:`rss_grid`) for
    an ONLY-RSS filter under ``"rss_rate"`` (:data:`RSS_ONLY_STEPS`)."""
    if rss_only_step not in RSS_ONLY_STEPS:
        raise ParameterError(f"rss_only_step must be one of {RSS_ONLY_STEPS}, got {rss_only_step!r}")
    return trajectory if fusion or rss_only_step == "imu_rate" else rss_grid(trajectory)


def _step_s(trajectory: Trajectory) -> float:
    return float(trajectory.time_s[1] - trajectory.time_s[0])


def motion_model(dt_s: float = DT_S, q_per_step: float = Q_PER_STEP) -> KinematicModel:
    """The CA model of Eq. (3.11) in the thesis's layout (Eq. (3.10)) with Q = q I (Eq. (3.24))."""
    return constant_acceleration(dt_s, q_per_step, layout="axis_major", noise="isotropic")


def simulate_rss(trajectory: Trajectory, channel: PathLossModel, n_runs: int, rng: np.random.Generator,
                 anchors_m=ANCHORS_M) -> np.ndarray:
    """RSS ``(n_runs, E, m)`` at the RSS epochs from Eq. (2.2), i.i.d. N(0, sigma^2) across anchors, time
    and runs (Eq. (2.2); the thesis models no correlation)."""
    d = pairwise_distance_m(trajectory.position_m[..., trajectory.rss_steps, :], anchors_m)
    noise = rng.standard_normal(np.broadcast_shapes((n_runs,) + d.shape[-2:], d.shape))
    return channel.mean_rss_dbm(d) + np.asarray(channel.sigma_db) * noise


def simulate_acceleration(trajectory: Trajectory, sigma_acc_mps2: float, n_runs: int,
                          rng: np.random.Generator) -> np.ndarray:
    """Accelerometer readings ``(n_runs, T, 2)``: true world-frame acceleration plus white noise, Eq. (3.17)
    (no bias, perfect orientation)."""
    a = trajectory.acceleration_m_s2
    return a + sigma_acc_mps2 * rng.standard_normal(np.broadcast_shapes((n_runs,) + a.shape[-2:], a.shape))


def mle_positions(rss_dbm, channel: PathLossModel, anchors_m=ANCHORS_M, *, room_m=ROOM_M,
                  grid_step_m: float = MLE_GRID_STEP_M, margin_m: float = MLE_GRID_MARGIN_M,
                  bounds: str = "unconstrained"):
    """Static MLE (Eq. (2.4)) of every RSS vector ``(..., m)``: the best point of a grid of ``grid_step_m`` over the
    room +- margin, refined by Levenberg-Marquardt without bounds (the thesis names no solver, start or bounds); with
    ``bounds="room"`` (:data:`MLE_BOUNDS`) the fix is then projected onto the room inset by :data:`MLE_ROOM_INSET_M`.
    Returns a LocalizationResult."""
    if bounds not in MLE_BOUNDS:
        raise ParameterError(f"bounds must be one of {MLE_BOUNDS}, got {bounds!r}")
    if not (np.isfinite(grid_step_m) and grid_step_m > 0):
        raise ParameterError(f"grid_step_m must be a positive finite step in m, got {grid_step_m!r}")
    room_m = _room(room_m)
    xs = np.arange(-margin_m, room_m[0] + margin_m + 1e-9, grid_step_m)
    ys = np.arange(-margin_m, room_m[1] + margin_m + 1e-9, grid_step_m)
    grid = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)
    model = RssModel(anchors_m, channel)
    start = grid_ml_position(rss_dbm, model, grid).position_m
    fix = rss_ml_position(rss_dbm, model, start)
    if bounds == "room":
        inset = MLE_ROOM_INSET_M
        fix = replace(fix, position_m=np.clip(fix.position_m, inset, np.asarray(room_m) - inset))
    return fix


def mle_cost_eq24(points_m, rss_dbm, channel: PathLossModel, anchors_m=ANCHORS_M):
    """The MLE cost of Eq. (2.4) as printed, ``sum_j (log10 d_hat_j - log10 d_j(p))^2`` with ``d_hat`` from Eq. (2.3),
    for every candidate ``points_m`` ``(G, 2)`` and RSS vector ``rss_dbm`` ``(..., m)``: shape ``(..., G)``.

    It equals ``(10 alpha)^-2 sum_j (P_j - P(d_j))^2``, the Gaussian RSS-domain likelihood that
    :func:`locbook.rss_ml_position` minimises (derived from Eq. (2.3)), so both have the same minimiser."""
    # log ranges compared as Eq. (2.4) prints them (the range domain, not the power-domain law)
    log_d = np.log10(np.maximum(pairwise_distance_m(np.asarray(points_m, float), anchors_m), 1e-9))   # (G, m)
    log_d_hat = np.log10(channel.range_m(np.asarray(rss_dbm, float)))                                  # (..., m)
    return np.sum((log_d_hat[..., None, :] - log_d) ** 2, axis=-1)


def initial_state(first_fix_m, mse_mle_m2, *, vel_var: float = P00_VEL_VAR, acc_var: float = P00_ACC_VAR):
    """Eqs. (3.19)-(3.20): ``x_0 = [x_MLE, 0, 0, y_MLE, 0, 0]`` and
    ``P_0 = diag(MSE_x, vel_var, acc_var, MSE_y, vel_var, acc_var)`` (printed: 0.0065 and 0.00023; the
    ``"sigma_acc"`` reading sets ``acc_var = sigma_ACC^2``, :func:`filter_noise`)."""
    first_fix_m = np.asarray(first_fix_m, dtype=float)
    x0 = np.zeros(first_fix_m.shape[:-1] + (6,))
    x0[..., 0], x0[..., 3] = first_fix_m[..., 0], first_fix_m[..., 1]
    mse = np.asarray(mse_mle_m2, dtype=float)
    vel, acc = np.full(mse.shape[:-1], float(vel_var)), np.full(mse.shape[:-1], float(acc_var))
    diag = np.stack([mse[..., 0], vel, acc, mse[..., 1], vel, acc], -1)
    return x0, diag[..., :, None] * np.eye(6)


def filter_inputs(name: str, trajectory: Trajectory, rss_dbm, mle_fix_m, mse_mle_m2, channel: PathLossModel, *,
                  acc_mps2=None, sigma_acc_mps2: float | None = None, model: KinematicModel | None = None,
                  p0_acc_var: float = P00_ACC_VAR, serial_order: str = "descending", anchors_m=ANCHORS_M):
    """The inputs of one filter of Tables 3.7-3.12 (:func:`run_filter`): ``(x0, P0, measurements, at)`` for
    :func:`locbook.extended_kalman_filter` on the grid after the first RSS epoch (``at``: the later RSS epochs on it);
    with a per-epoch MSE (KF (MLE)) also the fixes ``z`` on the grid, ``(x0, P0, measurements, at, z)``."""
    model = model or motion_model()
    steps = trajectory.rss_steps
    n_steps = trajectory.time_s.size
    rss_dbm = np.asarray(rss_dbm, dtype=float)
    batch = rss_dbm.shape[:-2]
    mse = np.asarray(mse_mle_m2, dtype=float)
    per_epoch = mse.ndim == 2
    x0, P0 = initial_state(np.asarray(mle_fix_m)[..., 0, :], mse[0] if per_epoch else mse, acc_var=p0_acc_var)
    measurements = []
    if acc_mps2 is not None:
        if sigma_acc_mps2 is None:
            raise ParameterError("fusion needs sigma_acc_mps2 for R_acc")
        acc = np.asarray(acc_mps2, dtype=float)[..., steps[0] + 1:, :]
        measurements.append(LinearMeasurement(acc, model.derivative_measurement_matrix(2),
                                              np.asarray(sigma_acc_mps2, float)[..., None, None] ** 2 * np.eye(2)))
    grid_shape = batch + (n_steps - steps[0] - 1,)
    at = steps[1:] - steps[0] - 1                  # RSS epochs after the first, on the grid after step 0
    if name == "kalman_filter":
        z = np.full(grid_shape + (2,), np.nan)
        z[..., at, :] = np.asarray(mle_fix_m)[..., 1:, :]
        if per_epoch:
            return x0, P0, measurements, at, z
        measurements.append(LinearMeasurement(z, model.position_measurement_matrix(), mse[..., :, None] * np.eye(2)))
    else:
        z = np.full(grid_shape + (rss_dbm.shape[-1],), np.nan)
        z[..., at, :] = rss_dbm[..., 1:, :]
        mode = "parallel" if name == "parallel_ekf" else "serial"
        measurements.append(RssMeasurement(z, anchors_m, channel, model.position_index, mode=mode,
                                           order=serial_order))
    return x0, P0, measurements, at


def run_filter(name: str, trajectory: Trajectory, rss_dbm, mle_fix_m, mse_mle_m2, channel: PathLossModel, *,
               acc_mps2=None, sigma_acc_mps2: float | None = None, model: KinematicModel | None = None,
               p0_acc_var: float = P00_ACC_VAR, serial_order: str = "descending", anchors_m=ANCHORS_M,
               every_step: bool = False) -> KalmanResult:
    """One filter of Tables 3.7-3.12 on all runs at once, recorded at the RSS epochs.

    ``rss_dbm`` ``(..., E, m)`` and ``mle_fix_m`` ``(..., E, 2)`` are at ``trajectory.rss_steps``; the filter starts
    at the first epoch from the MLE fix (Eqs. (3.19)-(3.20)) and runs on the 20 Hz grid. ``"kalman_filter"`` is
    KF (MLE): the fixes as linear position measurements with R = diag(MSE_MLE) (Eq. (3.21)); ``"parallel_ekf"``
    and ``"serial_ekf"`` use the raw RSS with R = sigma^2 I (Eq. (3.22)). With ``acc_mps2`` ``(..., T, 2)`` the
    accelerometer updates every step before the RSS (Table 3.5, R_acc = sigma_acc^2 I, Eq. (3.23)). ``model``
    carries Q (:func:`motion_model`), ``p0_acc_var`` the acceleration variance of P_0 (:func:`filter_noise`).
    ``mse_mle_m2`` is ``(2,)`` (one MSE per axis, the default reading of Eq. (3.21)) or ``(E, 2)``: one per RSS
    epoch, Table 4.1's R_{k+1} (the other reading; KF (MLE) only, P_0 from the first epoch's).

    With ``every_step`` the estimates are recorded at every grid step from the first RSS epoch (``steps`` of the
    result: ``rss_steps[0] .. T - 1``) instead of at the RSS epochs only (the same recursion).

    The result is the filter's own :class:`~locbook.KalmanResult` with the NIS guard's fields on the trajectory's grid:
    ``nis``/``nis_dof`` ``(..., T)`` (NaN / 0 up to the first epoch, where the filter starts), ``diverged`` and
    ``diverged_step`` (a step of ``trajectory.time_s``); with a per-epoch MSE the segments are judged as one filter
    (:meth:`locbook.tracking.divergence.DivergenceFlags.from_nis` on their concatenated NIS).
    """
    if name not in FILTERS:
        raise ParameterError(f"filter must be one of {FILTERS}, got {name!r}")
    model = model or motion_model()
    steps = trajectory.rss_steps
    n_steps = trajectory.time_s.size
    mse = np.asarray(mse_mle_m2, dtype=float)
    per_epoch = mse.ndim == 2
    if per_epoch and (name != "kalman_filter" or mse.shape != (steps.size, 2)):
        raise ParameterError(f"a per-epoch MSE must be (epochs, 2) = ({steps.size}, 2) and is used by KF (MLE) only, "
                             f"got shape {mse.shape} for {name}")
    inputs = filter_inputs(name, trajectory, rss_dbm, mle_fix_m, mse, channel, acc_mps2=acc_mps2,
                           sigma_acc_mps2=sigma_acc_mps2, model=model, p0_acc_var=p0_acc_var,
                           serial_order=serial_order, anchors_m=anchors_m)
    if per_epoch:
        x0, P0, measurements, at, z = inputs
        return _per_epoch_kf(model, x0, P0, measurements, z, mse, at, steps, n_steps, every_step)
    x0, P0, measurements, at = inputs
    # the guard is judged on the trajectory's grid (_on_trajectory_grid): the filter's own, on its grid, is not needed
    track = extended_kalman_filter(model.F, model.Q, x0, P0, measurements, record=None if every_step else at,
                                   divergence_window=0)
    x = np.concatenate([np.broadcast_to(x0[..., None, :], track.mean.shape[:-2] + (1, 6)), track.mean], axis=-2)
    P = np.concatenate([np.broadcast_to(P0[..., None, :, :], track.cov.shape[:-3] + (1, 6, 6)), track.cov], axis=-3)
    recorded = np.arange(steps[0], n_steps) if every_step else steps
    return _on_trajectory_grid(KalmanResult(x, P, recorded), track.nis, track.nis_dof, n_steps)


def _on_trajectory_grid(result: KalmanResult, nis, nis_dof, n_steps: int) -> KalmanResult:
    """``result`` with the NIS guard of the filter grid after the first RSS epoch (steps ``steps[0] + 1 ..``; NIS
    ``nis``, ``nis_dof``) put on the trajectory's grid of ``n_steps`` steps: no update before the filter starts."""
    offset = n_steps - nis.shape[-1]
    pad = nis.shape[:-1] + (offset,)
    flags = DivergenceFlags.from_nis(nis, nis_dof, step_offset=offset)
    return replace(result, nis=np.concatenate([np.full(pad, np.nan), nis], axis=-1),
                   nis_dof=np.concatenate([np.zeros(pad, np.int64), nis_dof], axis=-1),
                   diverged=flags.diverged, diverged_step=flags.diverged_step)


def _per_epoch_kf(model, x0, P0, acc_streams, z, mse, at, steps, n_steps, every_step=False) -> KalmanResult:
    """KF (MLE) with R = diag(MSE_MLE) of each epoch (Table 4.1's R_{k+1}): the multi-rate filter
    (:func:`locbook.extended_kalman_filter`) with the fixes' R given per step, each inter-epoch segment the R of the
    epoch that ends it (the steps after the last epoch: the last epoch's). The same recursion as running one segment at
    a time from the previous segment's posterior (tests/test_dogan_fusion_reading.py compares the two), in one call;
    the guard judges the whole NIS as one filter's."""
    H = model.position_measurement_matrix()
    grid = z.shape[-2]
    ends = np.append(np.asarray(at, dtype=np.int64), grid - 1)
    segment = np.searchsorted(ends, np.arange(grid))        # a step's segment, 0 up to the first epoch after the start
    r_steps = mse[np.minimum(segment + 1, len(mse) - 1)][:, :, None] * np.eye(2)      # mse[e] for segment e - 1
    track = extended_kalman_filter(model.F, model.Q, x0, P0,
                                   [*acc_streams, LinearMeasurement(z, H, per_step(r_steps))],
                                   record=None if every_step else at, divergence_window=0)
    x = np.concatenate([np.broadcast_to(x0[..., None, :], track.mean.shape[:-2] + (1, 6)), track.mean], axis=-2)
    P = np.concatenate([np.broadcast_to(P0[..., None, :, :], track.cov.shape[:-3] + (1, 6, 6)), track.cov], axis=-3)
    recorded = np.arange(steps[0], n_steps) if every_step else steps
    return _on_trajectory_grid(KalmanResult(x, P, recorded), track.nis, track.nis_dof, n_steps)


@dataclass
class ChannelRun:
    """All filters for one channel setting (sigma_RSS, alpha): errors ``(runs, E)`` at the RSS epochs, keyed
    ``"static_mle"`` and ``(filter, sigma_acc or None)``; ``mse_mle_m2`` the per-axis MSE used for R and P_0;
    ``divergence``: the NIS guard's :class:`~locbook.tracking.divergence.DivergenceFlags` of every filter case, keyed like
    ``errors`` (the errors keep every run: the thesis averaged all its runs); ``mse_mle_epoch_m2`` ``(E, 2)`` the MSE
    per axis and RSS epoch (over runs). With ``rmse_epochs="every_step"`` the filter cases' errors at every grid step
    from the first RSS epoch are kept too, keyed ``("every_step", filter, sigma_acc)`` (:func:`scored_errors`)."""

    sigma_rss_db: float
    path_loss_exp: float
    mse_mle_m2: np.ndarray
    errors: dict = field(default_factory=dict)
    converged_fraction: float = 1.0
    divergence: dict = field(default_factory=dict)
    mse_mle_epoch_m2: np.ndarray | None = None


def scored_errors(run: ChannelRun, key, rmse_epochs: str = "rss_epochs") -> np.ndarray:
    """The errors of ``run`` a table RMSE is taken over (:data:`RMSE_EPOCHS`): ``run.errors[key]`` at the RSS epochs,
    or, for ``"every_step"`` and a filter case ``(filter, sigma_acc)``, its errors at every grid step."""
    if rmse_epochs not in RMSE_EPOCHS:
        raise ParameterError(f"rmse_epochs must be one of {RMSE_EPOCHS}, got {rmse_epochs!r}")
    if rmse_epochs == "every_step" and isinstance(key, tuple) and key[0] in FILTERS:
        return run.errors[("every_step",) + key]
    return run.errors[key]


def _simulate_channel(trajectory: Trajectory, channel: PathLossModel, n_runs: int, rng: np.random.Generator,
                      anchors_m, room_m, mle_grid_step_m: float, mle_bounds: str):
    """The tables' simulation of one channel: the true positions at the RSS epochs, the RSS of ``n_runs`` runs, their
    MLE fixes and its per-axis MSE over runs and epochs (:func:`run_channel`, :func:`noise_fit`)."""
    truth = trajectory.position_m[..., trajectory.rss_steps, :]
    rss = simulate_rss(trajectory, channel, n_runs, rng, anchors_m)
    mle = mle_positions(rss, channel, anchors_m, room_m=room_m, grid_step_m=mle_grid_step_m, bounds=mle_bounds)
    return truth, rss, mle, np.mean((mle.position_m - truth) ** 2, axis=(0, 1))


def run_channel(trajectory: Trajectory, sigma_rss_db: float, path_loss_exp: float, n_runs: int,
                rng: np.random.Generator, *, sigma_acc_values=(), only_rss: bool = True, filters=FILTERS,
                ref_power_dbm: float = REF_POWER_DBM, serial_order: str = "descending",
                noise_reading: str = DEFAULT_NOISE_READING, anchors_m=ANCHORS_M, mle_r: str = "constant",
                keep_estimates: bool = False, room_m=ROOM_M, mle_grid_step_m: float = MLE_GRID_STEP_M,
                mle_bounds: str = "unconstrained", rmse_epochs: str = "rss_epochs",
                rss_only_step: str = DEFAULT_RSS_ONLY_STEP) -> ChannelRun:
    """Simulate one channel setting and run the MLE and the requested filters, ONLY RSS and/or fused with an
    accelerometer of each ``sigma_acc_values``; all cases share the same RSS draws (common random numbers, so
    the fusion gain is measured on identical RSS). The MLE's per-axis MSE sets R and P_0 of KF (MLE) and
    P_0 of every filter (Eqs. (3.20), (3.21)). Each case's Q and P_0 acceleration variance follow
    ``noise_reading`` (:func:`filter_noise`); the filter grid is the trajectory's. ``mle_r`` (:data:`MLE_R_READINGS`):
    KF (MLE)'s R from the MSE per axis over runs and epochs (``"constant"``) or per epoch over runs
    (``"per_epoch"``). The MLE (:func:`mle_positions`) searches ``room_m`` (with ``anchors_m``) at
    ``mle_grid_step_m``, bounded by ``mle_bounds``; ``rmse_epochs="every_step"`` also keeps every filter's errors at
    every grid step (:func:`scored_errors`). The ONLY-RSS filters step on :func:`filter_grid` of ``rss_only_step``
    (:data:`RSS_ONLY_STEPS`): under ``"rss_rate"`` once per RSS epoch, so their "every step" errors are those at the
    RSS epochs, the only steps they have; their NIS guard's steps are mapped back to the trajectory's grid."""
    if rmse_epochs not in RMSE_EPOCHS:
        raise ParameterError(f"rmse_epochs must be one of {RMSE_EPOCHS}, got {rmse_epochs!r}")
    if rss_only_step not in RSS_ONLY_STEPS:
        raise ParameterError(f"rss_only_step must be one of {RSS_ONLY_STEPS}, got {rss_only_step!r}")
    if mle_r not in MLE_R_READINGS:
        raise ParameterError(f"mle_r must be one of {MLE_R_READINGS}, got {mle_r!r}")
    channel = PathLossModel(ref_power_dbm, path_loss_exp, sigma_rss_db)
    truth, rss, mle, mse = _simulate_channel(trajectory, channel, n_runs, rng, anchors_m, room_m, mle_grid_step_m,
                                             mle_bounds)
    fix = mle.position_m
    out = ChannelRun(sigma_rss_db, path_loss_exp, mse, converged_fraction=float(np.mean(mle.converged)),
                     mse_mle_epoch_m2=np.mean((fix - truth) ** 2, axis=0))
    out.errors["static_mle"] = np.linalg.norm(fix - truth, axis=-1)
    if keep_estimates:
        out.errors[("estimates", "static_mle")] = fix
    # one accelerometer noise draw, scaled for each sigma_ACC (common random numbers across the sweep)
    unit_noise = rng.standard_normal((n_runs,) + trajectory.acceleration_m_s2.shape[-2:])
    cases = ([None] if only_rss else []) + list(sigma_acc_values)
    for sigma_acc in cases:
        acc = None if sigma_acc is None else trajectory.acceleration_m_s2 + sigma_acc * unit_noise
        q, p0_acc = filter_noise(noise_reading, sigma_acc)
        grid = filter_grid(trajectory, sigma_acc is not None, rss_only_step)
        model = motion_model(_step_s(grid), q)          # Q of Eq. (3.24) per step of this filter's grid
        for name in filters:
            r_mse = np.mean((fix - truth) ** 2, axis=0) if (mle_r == "per_epoch" and name == "kalman_filter") else mse
            track = run_filter(name, grid, rss, fix, r_mse, channel, acc_mps2=acc, sigma_acc_mps2=sigma_acc,
                               model=model, p0_acc_var=p0_acc, serial_order=serial_order, anchors_m=anchors_m,
                               every_step=rmse_epochs == "every_step")
            pos = track.position_m(model.position_index)
            if rmse_epochs == "every_step":
                every = np.linalg.norm(pos - grid.position_m[..., track.steps, :], axis=-1)
                out.errors[("every_step", name, sigma_acc)] = every
                pos = pos[..., grid.rss_steps - track.steps[0], :]      # the same estimates at the RSS epochs
            out.errors[(name, sigma_acc)] = np.linalg.norm(pos - truth, axis=-1)
            flags = DivergenceFlags.of(track)
            if grid is not trajectory:                   # the RSS-rate grid's step e is the trajectory's rss_steps[e]
                flags = replace(flags, diverged_step=np.where(
                    flags.diverged, trajectory.rss_steps[np.clip(flags.diverged_step, 0, grid.time_s.size - 1)], -1))
            out.divergence[(name, sigma_acc)] = flags
            if keep_estimates:
                out.errors[("estimates", name, sigma_acc)] = pos
    return out


def noise_fit(trajectory: Trajectory, sigma_rss_db: float, path_loss_exp: float, n_runs: int,
              rng: np.random.Generator, *, name: str = "parallel_ekf", noise_reading: str = DEFAULT_NOISE_READING,
              ref_power_dbm: float = REF_POWER_DBM, anchors_m=ANCHORS_M, room_m=ROOM_M,
              mle_grid_step_m: float = MLE_GRID_STEP_M, mle_bounds: str = "unconstrained",
              rss_only_step: str = DEFAULT_RSS_ONLY_STEP) -> dict:
    """Maximum-likelihood noise levels of an ONLY-RSS filter of Tables 3.7-3.12 beside the thesis's hand-set ones.

    The thesis sets ``Q = q I`` by hand (Eq. (3.24), q = 2.3e-5 per step) and ``R = sigma_RSS^2 I`` at the simulated
    sigma (Eq. (3.22)). On ``n_runs`` simulated runs of one channel (the tables' simulation, :func:`run_channel`), the
    innovations' log-likelihood (:func:`locbook.fit_noise_ml`, EKF) is maximised over a multiplier of Q and one of
    sigma_RSS^2: pooled over the runs (one estimate), and per run (its spread). Then the filter runs at the hand-set
    and at the pooled ML values. The truth has no process noise (a deterministic walk with sharp turns, the assumed
    Fig. 3.1 path): the ML q is the white-noise level that best explains the turns as the filter sees them, not a
    property of the simulation, while the ML sigma_RSS should recover the simulated sigma (a check of the method).

    Returns a dict: ``q_hand``, ``q_ml`` (pooled), ``q_ml_runs`` (per run), ``sigma_hand_db``, ``sigma_ml_db``,
    ``sigma_ml_runs_db``, ``rmse_hand_m``, ``rmse_ml_m`` (over runs and RSS epochs), the pooled log-likelihoods
    ``log_likelihood_hand`` and ``log_likelihood_ml``, and ``at_bound`` (a multiplier at its bound)."""
    from ..tracking.noise import fit_noise_ml
    if name not in ("parallel_ekf", "serial_ekf"):
        raise ParameterError(f"noise_fit fits the RSS EKFs (parallel_ekf, serial_ekf), got {name!r}")
    channel = PathLossModel(ref_power_dbm, path_loss_exp, sigma_rss_db)
    truth, rss, mle, mse = _simulate_channel(trajectory, channel, n_runs, rng, anchors_m, room_m, mle_grid_step_m,
                                             mle_bounds)
    trajectory = filter_grid(trajectory, False, rss_only_step)     # an ONLY-RSS filter's grid (RSS_ONLY_STEPS)
    dt_s = _step_s(trajectory)
    fix = mle.position_m
    q, p0_acc = filter_noise(noise_reading, None)
    model = motion_model(dt_s, q)
    x0, P0, measurements, at = filter_inputs(name, trajectory, rss, fix, mse, channel, model=model,
                                             p0_acc_var=p0_acc, anchors_m=anchors_m)
    pooled = fit_noise_ml(model.F, model.Q, x0, P0, measurements, kind="ekf", per_run=False)
    each = fit_noise_ml(model.F, model.Q, x0, P0, measurements, kind="ekf", per_run=True)

    def rmse(q_scale, r_scale):
        sigma = sigma_rss_db * np.sqrt(r_scale)
        ch = PathLossModel(ref_power_dbm, path_loss_exp, sigma)
        track = run_filter(name, trajectory, rss, fix, mse, ch, model=motion_model(dt_s, q * q_scale),
                           p0_acc_var=p0_acc, anchors_m=anchors_m)
        pos = track.position_m(model.position_index)
        return float(np.sqrt(np.mean(np.sum((pos - truth) ** 2, axis=-1))))

    qs, rs = float(pooled.q_scale[0]), float(pooled.r_scale[0][0])
    return {"q_hand": q, "q_ml": q * qs, "q_ml_runs": q * each.q_scale[..., 0],
            "sigma_hand_db": float(sigma_rss_db), "sigma_ml_db": float(sigma_rss_db * np.sqrt(rs)),
            "sigma_ml_runs_db": sigma_rss_db * np.sqrt(each.r_scale[0][..., 0]),
            "rmse_hand_m": rmse(1.0, 1.0), "rmse_ml_m": rmse(qs, rs),
            "log_likelihood_hand": float(pooled.initial_log_likelihood),
            "log_likelihood_ml": float(pooled.log_likelihood),
            "at_bound": bool(np.any(pooled.at_bound) or np.any(each.at_bound))}   # any multiplier of any fit


@dataclass(frozen=True)
class TableSetting:
    """One printed cell's setting: channel (sigma_RSS, alpha) and accelerometer (None for ONLY RSS)."""

    sigma_rss_db: float
    path_loss_exp: float
    sigma_acc_mps2: float | None


def _table_settings():
    """Printed row -> setting for Tables 3.7-3.12, from the row labels and the captions in dogan2015.csv:
    3.7 sweeps sigma_RSS ONLY RSS at Table 3.6's alpha; 3.8 the same fused at its caption's sigma_ACC
    (0.015, Table 3.6: 0.0152); 3.9 / 3.10 sweep sigma_ACC at their caption's sigma_RSS; 3.11 / 3.12 sweep alpha at
    their caption's sigma_RSS, ONLY RSS and fused at Table 3.12's caption's sigma_ACC."""
    acc = _value("Table 3.8 caption", "sigma_ACC")
    fixed_rss = {t: _value(f"Table {t} caption", "sigma_RSS") for t in ("3.9", "3.10", "3.11", "3.12")}
    acc_312 = _value("Table 3.12 caption", "sigma_ACC")
    out = {}
    for p in PRINTED:
        table = p.location.removeprefix("Table ")
        if p.location not in RMSE_TABLES or (table, p.item) in out:
            continue
        label = float(p.item.partition("=")[2])
        setting = {"3.7": lambda: TableSetting(label, PATH_LOSS_EXP, None),
                   "3.8": lambda: TableSetting(label, PATH_LOSS_EXP, acc),
                   "3.9": lambda: TableSetting(fixed_rss["3.9"], PATH_LOSS_EXP, label),
                   "3.10": lambda: TableSetting(fixed_rss["3.10"], PATH_LOSS_EXP, label),
                   "3.11": lambda: TableSetting(fixed_rss["3.11"], label, None),
                   "3.12": lambda: TableSetting(fixed_rss["3.12"], label, acc_312)}[table]()
        out[(table, p.item)] = setting
    return out


#: The printed RMSE tables of Ch. 3.
RMSE_TABLES = tuple(f"Table 3.{i}" for i in range(7, 13))
TABLE_SETTINGS = _table_settings()
#: The channel (sigma_RSS, alpha) of Table 3.6, and the channels of the sigma_ACC sweeps (Tables 3.9 and 3.10).
TABLE_36_CHANNEL = (SIGMA_RSS_DB, PATH_LOSS_EXP)
SIGMA_ACC_SWEEP_CHANNELS = tuple(dict.fromkeys((st.sigma_rss_db, st.path_loss_exp) for (t, _), st in TABLE_SETTINGS.items()
                                               if t in ("3.9", "3.10")))
#: sigma_ACC of the fused rows of Tables 3.8, 3.11-3.12 as the captions write it (Table 3.6: 0.0152).
TABLE_SIGMA_ACC_MPS2 = TABLE_SETTINGS[("3.8", "sigma_rss_db=6")].sigma_acc_mps2


def printed_tables() -> tuple[dict, ...]:
    """Printed cells of Tables 3.7-3.12 (locbook/data/printed/dogan2015.csv): dicts with table, row, column,
    value (float) and the :class:`~locbook.reproduce.Printed` itself (``printed``)."""
    return tuple({"table": p.location.removeprefix("Table "), "row": p.item, "column": p.statistic,
                  "value": p.value, "printed": p}
                 for p in PRINTED if p.location in RMSE_TABLES)


def table_channels(settings=None) -> dict:
    """Channel settings (sigma_RSS, alpha) needed by the printed cells, each with the sorted sigma_ACC values of
    its fusion rows and whether an ONLY-RSS row uses it."""
    settings = TABLE_SETTINGS if settings is None else settings
    out: dict = {}
    for s in settings.values():
        only, accs = out.get((s.sigma_rss_db, s.path_loss_exp), (False, set()))
        if s.sigma_acc_mps2 is None:
            only = True
        else:
            accs = accs | {s.sigma_acc_mps2}
        out[(s.sigma_rss_db, s.path_loss_exp)] = (only, accs)
    return {k: (v[0], tuple(sorted(v[1], reverse=True))) for k, v in sorted(out.items(), reverse=True)}


#: Canonical channel order; channel i draws from child i of the seed, so any subset gives the same numbers.
CHANNELS = tuple(table_channels())


def run_tables(trajectory: Trajectory, n_runs: int, seed: int, *, channels=None, filters=FILTERS,
               serial_order: str = "descending", noise_reading: str = DEFAULT_NOISE_READING,
               anchors_m=ANCHORS_M, mle_r: str = "constant", **mle_options) -> dict:
    """Every channel setting of Tables 3.7-3.12 (or the ``channels`` subset of :data:`CHANNELS`), each with its
    own random stream spawned from ``seed``; returns ``{(sigma_RSS, alpha): ChannelRun}``. ``mle_options``: ``room_m``,
    ``mle_grid_step_m``, ``mle_bounds``, ``rmse_epochs``, ``rss_only_step`` of :func:`run_channel`."""
    plan = table_channels()
    chosen = CHANNELS if channels is None else tuple(channels)
    unknown = [c for c in chosen if c not in plan]
    if unknown:
        raise ParameterError(f"unknown channel settings {unknown}; known: {list(plan)}")
    children = np.random.SeedSequence(seed).spawn(len(CHANNELS))
    out = {}
    for key in chosen:
        only, accs = plan[key]
        rng = np.random.default_rng(children[CHANNELS.index(key)])
        out[key] = run_channel(trajectory, key[0], key[1], n_runs, rng, sigma_acc_values=accs, only_rss=only,
                               filters=filters, serial_order=serial_order, noise_reading=noise_reading,
                               anchors_m=anchors_m, mle_r=mle_r, **mle_options)
    return out


def table_rows(runs: dict, rmse_epochs: str = "rss_epochs") -> list[dict]:
    """Printed cells beside the reproduced RMSE (over runs and RSS epochs: the thesis does not define its table RMSE;
    every run, as the thesis averaged every run) with its Monte-Carlo standard error and, for a filter column, the
    NIS guard's flags of its runs (``divergence``, None for the MLE); cells whose setting was not run are left out.
    ``rmse_epochs="every_step"`` takes the filters' RMSE over every grid step instead (:func:`scored_errors`)."""
    rows = []
    for cell in printed_tables():
        s = TABLE_SETTINGS[(cell["table"], cell["row"])]
        run = runs.get((s.sigma_rss_db, s.path_loss_exp))
        key = "static_mle" if cell["column"] == "static_mle" else (cell["column"], s.sigma_acc_mps2)
        if run is None or key not in run.errors:
            continue
        err = scored_errors(run, key, rmse_epochs)
        per_run = np.mean(err**2, axis=1)          # runs are independent; epochs within a run are not
        value = float(rmse_m(err))
        se = float(np.std(per_run, ddof=1) / np.sqrt(per_run.size) / (2.0 * value))
        rows.append(dict(table=cell["table"], row=cell["row"], column=cell["column"], printed=cell["value"],
                         printed_value=cell["printed"], reproduced=value, mc_se=se,
                         divergence=run.divergence.get(key) if key != "static_mle" else None))
    return rows


#: ``"smc"``: Eq. (4.22), the RSS information averaged over simulated CA trajectories (Figs 4.1/4.3);
#: ``"linear"``: MLE fixes as linear measurements with R = diag(MSE_MLE) (Figs 4.2/4.4, trajectory-free);
#: ``"truth"``: the RSS information along one known trajectory (truth-conditioned, Stone Soup's convention),
#: the bound to set beside filters run on that trajectory (an extension: the thesis never overlays them).
BOUND_KINDS = ("smc", "linear", "truth")


def smc_trajectories(n_trajectories: int, n_steps: int, rng: np.random.Generator, *,
                     model: KinematicModel | None = None, room_m=ROOM_M):
    """Sec. 4.1.2: trajectories "that exactly follow the constant acceleration model", each beginning at a point
    "selected arbitrarily in the area": uniform in the room, v_0 ~ N(0, 0.0065 I), a_0 ~ N(0, 0.00023 I) (the
    P_{0|0} blocks; the thesis prints no start distribution), propagated with the per-step Q. Shape
    ``(N, n_steps, 6)``."""
    model = model or motion_model()
    start = model.state_from(rng.uniform((0.0, 0.0), _room(room_m), (n_trajectories, 2)),
                             np.sqrt(P00_VEL_VAR) * rng.standard_normal((n_trajectories, 2)),
                             np.sqrt(P00_ACC_VAR) * rng.standard_normal((n_trajectories, 2)))
    return simulate_states(model.F, model.Q, start, n_steps - 1, rng=rng)


def smc_trajectory(states, rss_every: int = RSS_EVERY, dt_s: float = DT_S) -> Trajectory:
    """Wrap simulated states ``(N, T, 6)`` (e.g. :func:`smc_trajectories`) as one trajectory per run, so the
    filters can be run on the bound's own scenario."""
    states = np.asarray(states, dtype=float)
    n = states.shape[-2]
    model = motion_model(dt_s)
    return Trajectory(np.arange(n) * dt_s, states[..., model.position_index], states[..., model.velocity_index],
                      states[..., model.acceleration_index], rss_steps=np.arange(0, n, rss_every), start="smc")


def pcrlb_m(kind: str, *, fusion: bool, sigma_rss_db: float, mse_mle_m2, n_steps: int,
            path_loss_exp: float = PATH_LOSS_EXP, sigma_acc_mps2: float = SIGMA_ACC_MPS2,
            rng: np.random.Generator | None = None, n_trajectories: int = MC_RUNS, trajectory: Trajectory | None = None,
            acc_at_rss_epochs: bool = False, min_distance_m: float = 0.0, height_offset_m: float = 0.0,
            rss_every: int = RSS_EVERY, model: KinematicModel | None = None, p0_acc_var: float = P00_ACC_VAR,
            anchors_m=ANCHORS_M, room_m=ROOM_M) -> np.ndarray:
    """Position PCRLB (Eq. (4.23), m) at steps ``0 .. n_steps - 1`` of the 20 Hz grid, by Table 4.1.

    J_0 = P_{0|0}^{-1} (Eqs. (3.20), (4.11)); the Tichavsky recursion (4.7) with D22 = Q^{-1} + J_z, where J_z at
    RSS epochs (every ``rss_every``-th step) is the RSS information of ``kind`` (see :data:`BOUND_KINDS`), and for
    ``fusion`` the accelerometer's ``H_acc^T R_acc^{-1} H_acc`` at the other steps. Table 4.1 leaves the
    acceleration out at RSS epochs although the fusion filter uses it there; ``acc_at_rss_epochs=True`` adds it
    (our correction, off by default). ``min_distance_m`` / ``height_offset_m`` regularise the near-anchor 1/d^2
    singularity of E[J_z] (which gives the average of Eq. (4.22) an infinite variance); the thesis uses neither.
    ``mse_mle_m2`` is ``(2,)`` (one MSE per axis over runs and epochs) or ``(E, 2)`` per RSS epoch
    (:data:`PCRLB_MSE_MLE`): P_0 from epoch 0's, and the linear bound's R at the k-th RSS epoch from epoch k's (Table
    4.1's R_{k+1}). The SMC trajectories start in ``room_m``; ``anchors_m`` are the anchors.
    """
    if kind not in BOUND_KINDS:
        raise ParameterError(f"kind must be one of {BOUND_KINDS}, got {kind!r}")
    model = model or motion_model()
    idx = model.position_index
    mse = np.asarray(mse_mle_m2, dtype=float)
    per_epoch = mse.ndim == 2
    rss_steps = np.arange(rss_every, n_steps, rss_every)
    if per_epoch and (mse.shape[-1] != 2 or mse.shape[0] < rss_steps.size + 1):
        raise ParameterError(f"a per-epoch mse_mle_m2 must be (epochs, 2) with at least {rss_steps.size + 1} epochs for "
                             f"{n_steps} steps, got shape {mse.shape}")
    _, P0 = initial_state(np.zeros(2), mse[0] if per_epoch else mse, acc_var=p0_acc_var)
    jz = np.zeros((n_steps - 1, 6, 6))
    if fusion:
        acc_info = linear_measurement_information(model.derivative_measurement_matrix(2),
                                                  sigma_acc_mps2**2 * np.eye(2))
        jz[:] = acc_info
        if not acc_at_rss_epochs:
            jz[rss_steps - 1] = 0.0
    def rss_model():       # the RSS model of the bound: the anchors height_offset_m above the tag, the clamp
        anchors, height = np.asarray(anchors_m, float), np.asarray(height_offset_m, float)
        channel = PathLossModel(0.0, path_loss_exp, sigma_rss_db, min_distance_m=min_distance_m)
        if np.any(height != 0):
            return RssModel(np.column_stack([anchors, np.broadcast_to(height, anchors.shape[:1])]), channel,
                            tag_height_m=0.0)
        return RssModel(anchors, channel)
    if kind == "linear" and per_epoch:        # R_k per epoch (Table 4.1's R_{k+1}); epoch 0 is P_0's
        H = model.position_measurement_matrix()
        rss_info = np.stack([linear_measurement_information(H, np.diag(m)) for m in mse[1:rss_steps.size + 1]])
    elif kind == "linear":
        rss_info = linear_measurement_information(model.position_measurement_matrix(), np.diag(mse))
    elif kind == "truth":
        if trajectory is None or trajectory.time_s.size < n_steps:
            raise ParameterError("the truth-conditioned bound needs a trajectory of at least n_steps steps")
        rss_info = rss_state_information(trajectory.states(model)[rss_steps], rss_model(), idx)
    else:
        if rng is None:
            raise ParameterError("the Monte-Carlo (smc) bound needs rng")
        states = smc_trajectories(n_trajectories, n_steps, rng, model=model, room_m=room_m)
        rss_info = rss_state_information(states[:, rss_steps], rss_model(), idx).mean(axis=0)    # Eq. (4.22)
    jz[rss_steps - 1] += rss_info
    info = posterior_crlb(np.linalg.inv(P0), model.F, model.Q, jz)
    return position_bound_m(info, idx)


#: Printed rows that repeat one setting: Table 3.9's sigma_ACC = 0.015 row is Table 3.8's 6 dB
#: row (the same run, printed twice); Tables 3.11/3.12's alpha = 3 rows re-run Tables 3.7/3.8's 6 dB rows.
REPEATED_ROWS = {("3.9", "sigma_acc=0.015"): ("3.8", "sigma_rss_db=6"),
                 ("3.11", "ple=3"): ("3.7", "sigma_rss_db=6"),
                 ("3.12", "ple=3"): ("3.8", "sigma_rss_db=6")}


def thesis_repeat_error() -> float:
    """Relative Monte-Carlo standard error of one printed table cell, estimated from the thesis's own re-runs of
    one setting (Table 3.11's alpha = 3 row against Table 3.7's 6 dB row, Table 3.12's against Table 3.8's):
    for two independent estimates of one quantity, ``|a - b| / sqrt(2)`` estimates the standard error of each, so
    this returns ``sqrt(mean(((a - b) / ((a + b) / 2))^2) / 2)`` over the seven cell pairs."""
    cells = {(c["table"], c["row"], c["column"]): c["value"] for c in printed_tables()}
    rel = []
    for (table, row), (t0, r0) in REPEATED_ROWS.items():
        if table == "3.9":                       # the same run printed twice, not a re-run
            continue
        for (t, r, col), value in cells.items():
            if (t, r) == (table, row):
                other = cells[(t0, r0, col)]
                rel.append((value - other) / (0.5 * (value + other)))
    return float(np.sqrt(np.mean(np.square(rel)) / 2.0))


def record_tables(report, rows, *, variants: dict | None = None, label: str = "", start: str = DEFAULT_START,
                  noise_reading: str = DEFAULT_NOISE_READING, speed_mps: float = SPEED_MPS) -> dict:
    """Record every printed cell of Tables 3.7-3.12 (one row per distinct printed quantity; the repeats of
    :data:`REPEATED_ROWS` link to the cell they repeat with ``same_as``) and return the verdict counts.

    Kinds: the STATIC (MLE) column is a ``reproduction`` (positions along the assumed path only); a filter column
    is ``calibrated`` exactly when ``rows`` were computed under a reading fitted to printed output (``start``,
    ``noise_reading`` and ``speed_mps`` as run; :func:`fitted_readings` names them in ``calibrated_from``), else a
    ``reproduction``. Window: printed rounding + 2 Monte-Carlo standard errors (from per-run values)
    + the thesis's own Monte-Carlo error (:func:`thesis_repeat_error`, 2 standard errors of the printed cell).
    ``variants`` maps ``(table, row, column)`` to ``{reading: value}``: what the other readings give, quoted in
    the note of every miss (the reading was tested before the miss is attributed). Loose rows keep the automatic
    note (which part of the window is wide). A filter cell whose runs the NIS guard flagged says how many in its note
    (the RMSE keeps them, as the thesis averaged every run)."""
    from ..reproduce.scoring import Ambiguity, score
    rel = thesis_repeat_error()
    fitted = fitted_readings(start, noise_reading, speed_mps=speed_mps)
    by_key = {(r["table"], r["row"], r["column"]): r for r in rows}
    counts: dict = {}
    for r in rows:
        p = r["printed_value"]
        repeat = REPEATED_ROWS.get((r["table"], r["row"]))
        same = by_key.get((repeat[0], repeat[1], r["column"])) if repeat else None
        kind = "calibrated" if fitted and r["column"] != "static_mle" else "reproduction"
        amb = Ambiguity(2.0 * rel * p.value, "the thesis's own Monte-Carlo error: 2 standard errors of a 500-run cell, "
                        f"{100 * rel:.1f} % from its re-runs of one setting",
                        "Dogan 2015 Tables 3.7/3.11 and 3.8/3.12 (alpha = 3 rows repeat the 6 dB rows)")
        verdict = score(kind, p.text, r["reproduced"], mc_std_error=r["mc_se"], ambiguity=amb,
                        linked=same is not None).verdict
        note = (_miss_reason(r, (variants or {}).get((r["table"], r["row"], r["column"]), {}), start=start,
                             noise_reading=noise_reading) if verdict == "miss" else "")
        note = divergence_note(note, r.get("divergence"))
        row = report.number(f"RMSE {r['column']}{label}", p, r["reproduced"], kind=kind, mc_std_error=r["mc_se"],
                            ambiguity=amb, calibrated_from=fitted if kind == "calibrated" else "",
                            same_as=same["printed_value"] if same else None, note=note)
        counts[row["verdict"] or "linked"] = counts.get(row["verdict"] or "linked", 0) + 1
    return counts


def readings_summary(rows, variants: dict, chosen: str, others, *, tolerance: float = 0.2) -> list[dict]:
    """How close each reading comes to the printed fusion cells of the 6 and 3 dB channels (Tables 3.8-3.10, the
    repeats of :data:`REPEATED_ROWS` left out, only cells run under more than one reading): per reading and filter
    family (the EKFs, KF (MLE)), the number of cells, how many lie within ``tolerance`` (relative) of the printed
    value, ``|ours / printed - 1| <= tolerance``, and the median of ``100 |ours / printed - 1|``.

    ``rows``: :func:`table_rows` of the chosen reading (named ``chosen``); ``variants``: ``(table, row, column) ->
    {reading: value}`` as for :func:`record_tables`; ``others``: the names of the other readings to summarise.
    A summary of the readings table, not a scored comparison (no window, no verdict)."""
    if not 0.0 < tolerance < 1.0:
        raise ParameterError(f"tolerance must be a fraction in (0, 1), got {tolerance!r}")
    ours = {(r["table"], r["row"], r["column"]): r["reproduced"] for r in rows}
    printed_of = {(r["table"], r["row"], r["column"]): r["printed"] for r in rows}
    fusion_keys = [k for k in variants if k[0] in ("3.8", "3.9", "3.10") and REPEATED_ROWS.get(k[:2]) is None
                   and len(variants[k]) > 1]
    within = f"within_{100 * tolerance:g}_pct"
    summary = []
    for name in [chosen, *others]:
        values = ours if name == chosen else {k: variants[k][name] for k in fusion_keys}
        for family, cols in [("EKFs", ("parallel_ekf", "serial_ekf")), ("KF (MLE)", ("kalman_filter",))]:
            keys = [k for k in fusion_keys if k[2] in cols]
            deviation = [abs(values[k] / printed_of[k] - 1) for k in keys]
            summary.append({"reading": name, "filters": family, "cells": len(keys),
                            within: sum(d <= tolerance for d in deviation),
                            "median_abs_deviation_pct": float(np.median([100 * d for d in deviation]))})
    return summary


def _miss_reason(row, variants: dict, *, start: str = DEFAULT_START, noise_reading: str = DEFAULT_NOISE_READING) -> str:
    """The likely reason of a missed Table 3.7-3.12 cell computed under ``start`` and ``noise_reading``, with what the
    other readings ``variants`` (``{label: value}``) give for the same cell."""
    s = TABLE_SETTINGS[(row["table"], row["row"])]
    tested = "; ".join(f"{k}: {v:.3f}" for k, v in variants.items())
    tested = (f" Tested readings of the same cell: {tested}." if tested else
              " The other readings were run on the 6 dB and 3 dB channels (the readings table), not on this one.")
    ours, printed_value = row["reproduced"], row["printed"]
    if row["column"] == "static_mle":
        return ("STATIC (MLE): the room is the inferred test-bed room and the MLE an unbounded search (neither is "
                "printed for Ch. 3); the residual gap is the unprinted path, which sets how close the node comes to "
                "the anchors." + tested)
    if s.sigma_acc_mps2 is None:
        if row["column"] == "kalman_filter" and s.path_loss_exp <= 2.5:
            return ("KF (MLE) at low alpha: far-out MLE fixes make R = diag(MSE_MLE) large and our KF beats the "
                    "printed one; R per epoch (Table 4.1's R_k+1, the other reading of Eq. (3.21)) beats it too, and "
                    "any bound on the MLE is not printed." + tested)
        return ("ONLY RSS filters: they depend on the unprinted path, speed and start through how often the "
                "constant-acceleration model meets a turn; the fusion readings barely change ONLY RSS, and for KF "
                "(MLE) R per epoch (Table 4.1's R_k+1) moves it further from the printed value." + tested)
    if s.sigma_acc_mps2 >= TABLE_SIGMA_ACC_MPS2:
        side = "better" if ours < printed_value else "worse"
        return (f"sigma_ACC = 0.015: our fused filter ({start} start) is {side} than printed, and no reading tried "
                "reproduces this row (start from rest or moving, Q printed or from sigma_ACC; at 0.015 both Q readings "
                "coincide): the start, which the thesis does not print, moves it most (the moving start makes the "
                "EKFs diverge in a tail of runs)." + tested)
    if noise_reading == "printed":
        if ours > printed_value:
            return ("fused filter at sigma_ACC below 0.015 with Q printed as a constant (Eq. (3.24)): the process noise, "
                    "not the accelerometer, limits the filter, so our error barely falls with sigma_ACC while the "
                    "printed one does (KF (MLE) 1.34 -> 0.96 m, Table 3.9); only Q scaled with sigma_ACC (the "
                    "'sigma_acc' reading, fitted to that fall) follows it, so the printed tables were likely run with "
                    "a Q other than the one printed." + tested)
        return ("fused filter at sigma_ACC below 0.015 with Q printed as a constant (Eq. (3.24)): our filter is better "
                "than printed; the gap is the unprinted path and start." + tested)
    if row["column"] != "kalman_filter" and ours > printed_value:
        return ("fused EKF at sigma_ACC below 0.015 with Q = sigma_ACC^2/10 (the 'sigma_acc' reading, fitted to "
                "Table 3.9): the typical run improves with sigma_ACC as printed (see the median table), but with so "
                "small a Q a few runs lock onto a wrong position and never recover (fraction beyond 4 m in the tail "
                "table), which the RMSE weighs; the thesis's EKFs show no such tail." + tested)
    return ("fused filter below 0.015 with Q = sigma_ACC^2/10 (the 'sigma_acc' reading, fitted to Table 3.9's KF "
            "(MLE) fall with sigma_ACC): the remaining gap is the unprinted path and start." + tested)


def fusion_reduction_rows(runs: dict) -> list[dict]:
    """Fusion gain at the tables' sigma_ACC for each filter and channel: Table 3.7 -> 3.8 and 3.11 -> 3.12."""
    from ..metrics import reduction_pct, rmse_m
    printed = {(c["table"], c["row"], c["column"]): c["value"] for c in printed_tables()}
    out = []
    for (t_only, t_fus) in (("3.7", "3.8"), ("3.11", "3.12")):
        for row in [r for (t, r) in TABLE_SETTINGS if t == t_only]:
            s = TABLE_SETTINGS[(t_only, row)]
            run = runs.get((s.sigma_rss_db, s.path_loss_exp))
            if run is None:
                continue
            for name in FILTERS:
                ours = reduction_pct(rmse_m(run.errors[(name, None)]), rmse_m(run.errors[(name, TABLE_SIGMA_ACC_MPS2)]))
                theirs = reduction_pct(printed[(t_only, row, name)], printed[(t_fus, row, name)])
                out.append(dict(tables=f"{t_only} -> {t_fus}", row=row, filter=name, printed_pct=theirs,
                                reproduced_pct=float(ours)))
    return out


def fusion_gain_pct(run: ChannelRun, sigma_acc_mps2: float, filters=FILTERS,
                    rmse_epochs: str = "rss_epochs") -> tuple[float, float, dict]:
    """The fusion reduction of the RMSE, ONLY RSS -> RSS/IMU, averaged over ``filters`` (the text's "Sensor fusion
    decreases the error approximately % 30", Figs 3.5-3.7), its jackknife standard error over runs, and the
    reduction of each filter. The RMSE is pooled over runs and epochs (the thesis does not define it)."""
    mse = {(f, c): np.mean(scored_errors(run, (f, c), rmse_epochs) ** 2, axis=1) for f in filters
           for c in (None, sigma_acc_mps2)}

    def mean_gain(*per_run):
        parts = [100.0 * (1.0 - np.sqrt(per_run[2 * i + 1].mean() / per_run[2 * i].mean())) for i in range(len(filters))]
        return float(np.mean(parts))

    arrays = [mse[(f, c)] for f in filters for c in (None, sigma_acc_mps2)]
    each = {f: 100.0 * (1.0 - np.sqrt(mse[(f, sigma_acc_mps2)].mean() / mse[(f, None)].mean())) for f in filters}
    return mean_gain(*arrays), jackknife_standard_error(mean_gain, *arrays), each


def mean_rmse_m(run: ChannelRun, sigma_acc_mps2: float | None, filters=FILTERS,
                rmse_epochs: str = "rss_epochs") -> tuple[float, float, dict]:
    """The mean over ``filters`` of their pooled RMSE in one case (the one level the text reads off three curves,
    "errors are near 1.5 meter", Fig. 3.4), its jackknife standard error over runs (the filters share the runs'
    RSS, so their errors are correlated), and each filter's RMSE."""
    arrays = [np.mean(scored_errors(run, (f, sigma_acc_mps2), rmse_epochs) ** 2, axis=1) for f in filters]

    def level(*per_run):
        return float(np.mean([np.sqrt(a.mean()) for a in per_run]))

    each = {f: float(np.sqrt(a.mean())) for f, a in zip(filters, arrays)}
    return level(*arrays), jackknife_standard_error(level, *arrays), each


def printed_fusion_gains_pct() -> list[float]:
    """The fusion reduction of every printed ONLY RSS / RSS-IMU cell pair of one setting (Tables 3.7 -> 3.8 and
    3.11 -> 3.12, sigma_ACC = 0.015): the thesis's own numbers behind its "average performance enhancement of
    tracking by sensor fusion is around 30%" (Ch. 6)."""
    cells = {(c["table"], c["row"], c["column"]): c["value"] for c in printed_tables()}
    out = []
    for (t_only, t_fus), (table, row, column) in [((a, b), key) for a, b in (("3.7", "3.8"), ("3.11", "3.12"))
                                                  for key in cells if key[0] == b]:
        out.append(100.0 * (1.0 - cells[(t_fus, row, column)] / cells[(t_only, row, column)]))
    return out


def ordering_rows(rows) -> list[dict]:
    """Per printed row: the filters ranked by RMSE, printed and reproduced (the text's claims: MLE worst, KF (MLE)
    best except at high information, serial EKF a little better than parallel)."""
    out = []
    for key in dict.fromkeys((r["table"], r["row"]) for r in rows):
        cells = [r for r in rows if (r["table"], r["row"]) == key]
        rank = lambda field: " < ".join(c["column"] for c in sorted(cells, key=lambda c: c[field]))
        out.append(dict(table=key[0], row=key[1], printed=rank("printed"), reproduced=rank("reproduced"),
                        same=rank("printed") == rank("reproduced")))
    return out


def bound_rows(runs: dict, trajectory: Trajectory, *, noise_reading: str = DEFAULT_NOISE_READING,
               anchors_m=ANCHORS_M, rss_only_step: str = DEFAULT_RSS_ONLY_STEP) -> list[dict]:
    """Every filter's RMSE beside the truth-conditioned PCRLB of its own information (ONLY RSS or fused, same
    trajectory, Q, R and P_0 as the filter under ``noise_reading``), both as the RMS over the RSS epochs; KF (MLE)
    also beside the linear bound. An ONLY-RSS filter's bound uses its own grid and Q per step (:func:`filter_grid` of
    ``rss_only_step``)."""
    out = []
    for (sigma, ple), run in runs.items():
        for key, err in run.errors.items():
            if not (isinstance(key, tuple) and key[0] in FILTERS):
                continue
            name, sigma_acc = key
            q, p0_acc = filter_noise(noise_reading, sigma_acc)
            grid = filter_grid(trajectory, sigma_acc is not None, rss_only_step)
            common = dict(fusion=sigma_acc is not None, sigma_rss_db=sigma, path_loss_exp=ple,
                          sigma_acc_mps2=sigma_acc or SIGMA_ACC_MPS2, mse_mle_m2=run.mse_mle_m2, n_steps=grid.time_s.size,
                          model=motion_model(_step_s(grid), q), p0_acc_var=p0_acc,
                          rss_every=int(np.diff(grid.rss_steps[:2])[0]), anchors_m=anchors_m)
            bound = pcrlb_m("truth", trajectory=grid, **common)[grid.rss_steps]
            row = dict(sigma_rss_db=sigma, ple=ple, sigma_acc=sigma_acc, filter=name, rmse_m=float(rmse_m(err)),
                       pcrlb_m=float(np.sqrt(np.mean(bound**2))))
            if key in run.divergence:
                row["runs flagged diverged"] = run.divergence[key].n_diverged
            if name == "kalman_filter":
                lin = pcrlb_m("linear", **common)[grid.rss_steps]
                row["linear_pcrlb_m"] = float(np.sqrt(np.mean(lin**2)))
            row["ratio"] = row["rmse_m"] / row["pcrlb_m"]
            out.append(row)
    return out


def tail_rows(runs: dict, threshold_m: float = 4.0) -> list[dict]:
    """For every filter case of every channel: the RMSE, the median (typical-run) and 90th percentile of the
    per-run RMS error (:func:`~locbook.metrics.rmse_m` over epochs), the fraction of runs beyond ``threshold_m``, the worst run, and the
    runs the NIS guard flagged diverged (blank for the MLE)."""
    out = []
    for (sigma, ple), run in runs.items():
        for key, err in run.errors.items():
            if key != "static_mle" and not (isinstance(key, tuple) and key[0] in FILTERS):
                continue
            name, sigma_acc = (key, None) if key == "static_mle" else key
            per = rmse_m(err, axis=-1)
            flags = run.divergence.get(key) if key != "static_mle" else None
            out.append(dict(sigma_rss_db=sigma, ple=ple, filter=name,
                            case="ONLY RSS" if sigma_acc is None else f"RSS/IMU {sigma_acc:g}",
                            rmse_m=float(rmse_m(err)), median_run_m=float(np.median(per)),
                            p90_run_m=float(np.percentile(per, 90)),
                            fraction_beyond=float(np.mean(per > threshold_m)), worst_run_m=float(per.max()),
                            runs=int(per.size), **{"runs flagged diverged": "" if flags is None else flags.n_diverged}))
    return out


def divergence_table(runs: dict, *, dt_s: float = DT_S) -> list[dict]:
    """The NIS guard's count for every filter case of every channel of ``runs`` (``{(sigma_RSS, alpha): ChannelRun}``):
    runs flagged / runs and the median time of the first flagged step (``dt_s`` per step of the trajectory grid)."""
    flags = {}
    for (sigma, ple), run in runs.items():
        for (name, sigma_acc), f in run.divergence.items():
            case = "ONLY RSS" if sigma_acc is None else f"RSS/IMU {sigma_acc:g}"
            flags[(name, f"sigma_RSS {sigma:g} dB, alpha {ple:g}, {case}")] = f
    return divergence_rows(flags, step_s=dt_s)


def only_acc_errors(trajectory: Trajectory, sigma_acc_mps2: float, n_runs: int, rng: np.random.Generator, *,
                    noise_reading: str = DEFAULT_NOISE_READING, with_divergence: bool = False):
    """Fig. 3.2, tracking with ONLY ACC: the KF of Table 3.5 with the accelerometer alone (Eq. (3.18),
    R_acc = sigma_ACC^2 I), started at the true position with zero velocity and acceleration (Eq. (3.19) with a
    perfect position). Returns the position error ``(n_runs, T - 1)`` at steps 1 .. T-1; with ``with_divergence``
    ``(errors, flags)``, the KF's NIS guard per run (:class:`locbook.tracking.divergence.DivergenceFlags`, steps of the
    trajectory's grid). The guard sees the accelerometer's innovations only: the position is not observed, so its
    drift is no inconsistency of the filter."""
    dt_s = float(trajectory.time_s[1] - trajectory.time_s[0])
    q, p0_acc = filter_noise(noise_reading, sigma_acc_mps2)
    model = motion_model(dt_s, q)
    acc = simulate_acceleration(trajectory, sigma_acc_mps2, n_runs, rng)
    x0 = model.state_from(trajectory.position_m[0])
    _, P0 = initial_state(np.zeros(2), np.full(2, 1e-6), acc_var=p0_acc)
    track = extended_kalman_filter(model.F, model.Q, x0, P0, [LinearMeasurement(
        acc[:, 1:], model.derivative_measurement_matrix(2), sigma_acc_mps2**2 * np.eye(2))])
    err = np.linalg.norm(track.position_m(model.position_index) - trajectory.position_m[1:], axis=-1)
    return (err, DivergenceFlags.of(track, step_offset=1)) if with_divergence else err


def table_view(rows, table: str) -> list[dict]:
    """One display row per printed row: ``printed / reproduced`` side by side for each filter column."""
    out: dict = {}
    for r in rows:
        if r["table"] == table:
            out.setdefault(r["row"], {"row": r["row"]})[r["column"]] = f"{r['printed']:.3f} / {r['reproduced']:.3f}"
    return list(out.values())


HORIZON_SOURCE = "Dogan 2015 Sec. 4.1.2"


@dataclass(frozen=True)
class BoundStudy:
    """The Ch. 4 bounds of one run of the study (Figs. 4.1-4.4): every SMC curve from one seed, as one figure of
    the thesis would draw them, and independent replicate seeds for the Monte-Carlo standard error of a statistic
    of an SMC curve. ``mse_mle_m2`` maps sigma_RSS (dB) to the per-axis MSE of the Ch. 3 MLE (P_0, and R of the
    linear bound), per axis ``(2,)`` or per epoch ``(E, 2)``; ``room_m`` the room, its corners the anchors; the other
    fields are those of :func:`pcrlb_m`."""

    mse_mle_m2: dict
    n_steps: int
    n_trajectories: int
    smc_seed: int
    replicate_seeds: tuple
    acc_at_rss_epochs: bool = False
    min_distance_m: float = 0.0
    height_offset_m: float = 0.0
    room_m: tuple = ROOM_M

    def bound_m(self, kind: str, fusion: bool, sigma_rss_db: float, sigma_acc_mps2: float = SIGMA_ACC_MPS2, *,
                rng: np.random.Generator | None = None) -> np.ndarray:
        """Position PCRLB (Eq. (4.23), m) per step; an SMC bound draws its trajectories from ``rng`` (default: a
        generator of the study's one seed, so that every curve uses the same trajectories); a linear bound is
        deterministic."""
        if kind == "smc" and rng is None:
            rng = np.random.default_rng(self.smc_seed)
        elif kind != "smc":
            rng = None
        return pcrlb_m(kind, fusion=fusion, sigma_rss_db=sigma_rss_db, mse_mle_m2=self.mse_mle_m2[sigma_rss_db],
                       n_steps=self.n_steps, sigma_acc_mps2=sigma_acc_mps2, rng=rng, n_trajectories=self.n_trajectories,
                       acc_at_rss_epochs=self.acc_at_rss_epochs, min_distance_m=self.min_distance_m,
                       height_offset_m=self.height_offset_m, room_m=self.room_m, anchors_m=corner_anchors(self.room_m))

    def replicate_se(self, statistic, kind: str, fusion: bool, sigma_rss_db: float,
                     sigma_acc_mps2: float = SIGMA_ACC_MPS2) -> float:
        """Monte-Carlo standard error of ``statistic(bound)``: the standard deviation of independent SMC replicates
        of the same size (:func:`locbook.montecarlo.replicate_standard_error`); 0 for the deterministic linear
        bound."""
        if kind != "smc":
            return 0.0
        return replicate_standard_error(
            lambda rng: statistic(self.bound_m(kind, fusion, sigma_rss_db, sigma_acc_mps2, rng=rng)),
            self.replicate_seeds)


def horizon_ambiguity(bound_m, time_s, horizon_s: float, other_horizons_s) -> Ambiguity:
    """The averaging horizon of Figs. 4.3-4.4's time averages is not printed: the ambiguity is the
    largest change of the average of ``bound_m`` over ``time_s < h`` for the other plausible horizons ``h``, from
    its average over the whole curve (``horizon_s``)."""
    bound_m, time_s = np.asarray(bound_m, float), np.asarray(time_s, float)
    if bound_m.shape != time_s.shape:
        raise ParameterError(f"bound_m and time_s must have one shape, got {bound_m.shape} and {time_s.shape}")
    if not len(other_horizons_s):
        raise ParameterError("other_horizons_s must name at least one other plausible horizon")
    size = max(abs(float(bound_m[time_s < h].mean()) - float(bound_m.mean())) for h in other_horizons_s)
    what = (f"the averaging horizon is not printed: the largest change of the average over "
            f"{', '.join(f'{h:g}' for h in other_horizons_s)} s from {horizon_s:g} s")
    return Ambiguity(size, what, HORIZON_SOURCE)
