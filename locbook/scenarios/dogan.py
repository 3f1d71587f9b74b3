"""Document 000: Dogan (2015), "Indoor Localization and Tracking Based on RSSI and Accelerometer
Measurements", M.Sc. thesis, METU.

One blindfolded node tracked from RSS at four corner anchors with a nearly-constant-acceleration model:
static MLE, a KF on the MLE fixes ("KF (MLE)"), parallel and serial EKFs on the raw RSS, each fused with a
20 Hz accelerometer used as a linear measurement of the acceleration states (Table 3.5), and the posterior
CRLB (Ch. 4).

The thesis prints neither the room of Ch. 3, nor the trajectory, nor the time step. Every such value is a
named default here, with its reason from ``shared/notes/000_dogan.md`` (sections 3.1, 5 and 7):
the room is the test-bed room 7.6 m x 9.2 m (A1, inferred), the trajectory a 24 m polyline walked at
0.3 m/s in 80 s (A1), one 20 Hz grid for every filter with RSS at every 10th step (A2), the per-step
Q = 2.3e-5 I (Eq. (3.24), A3), and the MLE an unconstrained grid + Levenberg-Marquardt search (A8).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..models.channel import PathLossModel, pairwise_distance_m
from ..data.printed_values import printed
from ..errors import ParameterError
from ..tracking.kalman import LinearMeasurement, RssMeasurement, TrackResult, extended_kalman_filter
from ..static.localization import grid_ml_position, rss_ml_position
from ..models.motion import KinematicModel, constant_acceleration, simulate_states
from ..bounds.pcrlb import linear_measurement_information, position_bound_m, posterior_crlb, rss_state_information

__all__ = [
    "ROOM_M", "ANCHORS_M", "REF_POWER_DBM", "PATH_LOSS_EXP", "SIGMA_RSS_DB", "SIGMA_ACC_MPS2", "Q_PER_STEP",
    "DT_S", "RSS_EVERY", "P00_VEL_VAR", "P00_ACC_VAR", "WAYPOINTS_M", "SPEED_MPS", "MC_RUNS", "START_MODES",
    "FILTERS", "Trajectory", "polyline_trajectory", "motion_model", "simulate_rss", "simulate_acceleration",
    "mle_positions", "mle_cost_eq24", "initial_state", "run_filter", "ChannelRun", "run_channel", "printed_tables",
    "TABLE_SETTINGS", "Setting", "table_channels", "record_tables", "bound_rows", "STATIC_TOLERANCE", "FILTER_TOLERANCE",
    "fusion_reduction_rows", "ordering_rows", "table_view", "miss_table", "BOUND_KINDS", "pcrlb_m", "smc_trajectories", "smc_trajectory", "CHANNELS", "run_tables", "table_rows",
]

#: Room of Ch. 3, inferred to be the test-bed room of Sec. 5.4 (note 000 s.3.1: the Fig 3.1 axes, "the same
#: trajectory", and only this room reproduces the MLE column of Tables 3.7/3.11).
ROOM_M = (7.6, 9.2)
#: Anchors A1-A4 at the corners (Sec. 5.4).
ANCHORS_M = np.array([[0.0, 0.0], [7.6, 0.0], [7.6, 9.2], [0.0, 9.2]])
#: Table 3.6: first-meter power P0 (dBm), path-loss exponent alpha, sigma_RSS (dB), sigma_ACC (m/s^2).
REF_POWER_DBM = -48.0
PATH_LOSS_EXP = 3.0
SIGMA_RSS_DB = 6.0
SIGMA_ACC_MPS2 = 0.0152
#: Eq. (3.24): Q = 0.000023 I_6 per step, full rank, not scaled with T ("standard deviation of the process
#: noise is 0.0048", Sec. 4.1.2).
Q_PER_STEP = 2.3e-5
#: Step of the common grid (A2): the accelerometer rate, 20 Hz. Not printed.
DT_S = 0.05
#: RSS at 2 Hz ("2 RSS measurements are taken each second"): every 10th step of the 20 Hz grid.
RSS_EVERY = 10
#: Eq. (3.20): initial velocity and acceleration variances of P_{0|0}.
P00_VEL_VAR = 0.0065
P00_ACC_VAR = 0.00023
#: Default trajectory (A1; not printed): a 24 m polyline with sharp 90-degree turns inside the room.
WAYPOINTS_M = ((1.0, 1.0), (1.0, 8.2), (6.6, 8.2), (6.6, 1.0), (2.6, 1.0))
#: Walking speed (A1): 24 m in 80 s; Fig 3.2's "24 meter after 80 seconds" ONLY-ACC drift is what an
#: unobserved initial speed of 0.3 m/s gives (note 000 s.7).
SPEED_MPS = 0.3
#: Monte-Carlo runs (Sec. 3.5).
MC_RUNS = 500
#: ``"moving"``: the node walks at SPEED_MPS from t = 0 (A1 default); ``"rest"``: it starts from rest and
#: accelerates uniformly over ``ramp_s`` (A1 variant; the fusion results depend on it, note 000 s.7).
START_MODES = ("moving", "rest")
#: Filter columns of Tables 3.7-3.12.
FILTERS = ("parallel_ekf", "serial_ekf", "kalman_filter")
#: MLE search grid (A8): the room +- 3 m at 0.5 m, then Levenberg-Marquardt, unconstrained.
MLE_GRID_STEP_M = 0.5
MLE_GRID_MARGIN_M = 3.0



@dataclass(frozen=True)
class Trajectory:
    """A true trajectory on the filter grid: ``state`` ``(T, 6)`` in the thesis's per-axis layout
    ``[x, vx, ax, y, vy, ay]`` (Eq. (3.10)), or ``(N, T, 6)`` for one trajectory per Monte-Carlo run;
    ``time_s`` ``(T,)`` and the RSS epochs ``rss_steps``."""

    time_s: np.ndarray
    state: np.ndarray
    rss_steps: np.ndarray
    waypoints_m: tuple
    start: str

    @property
    def position_m(self) -> np.ndarray:
        return self.state[..., [0, 3]]

    @property
    def acceleration_mps2(self) -> np.ndarray:
        return self.state[..., [2, 5]]


def polyline_trajectory(waypoints_m=WAYPOINTS_M, speed_mps: float = SPEED_MPS, dt_s: float = DT_S, *,
                        start: str = "moving", ramp_s: float = 2.0, rss_every: int = RSS_EVERY) -> Trajectory:
    """Walk the polyline at constant speed, sampled every ``dt_s`` (note 000, A1).

    The velocity turns within one step at each corner, so the true acceleration (what a bias-free, perfectly
    oriented accelerometer reads, Eq. (3.17)) is the backward difference ``(v_k - v_{k-1}) / dt``: zero on the
    straight segments and an impulse at the turns (and during the ramp for ``start="rest"``).
    """
    if start not in START_MODES:
        raise ParameterError(f"start must be one of {START_MODES}, got {start!r}")
    if speed_mps <= 0 or dt_s <= 0 or rss_every < 1:
        raise ParameterError("speed_mps and dt_s must be positive and rss_every at least 1")
    pts = np.asarray(waypoints_m, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2:
        raise ParameterError(f"waypoints_m must be at least two (x, y) points, got shape {pts.shape}")
    seg = np.diff(pts, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    if np.any(seg_len == 0):
        raise ParameterError("waypoints_m has repeated consecutive points")
    length = seg_len.sum()
    ramp = ramp_s if start == "rest" else 0.0
    accel = speed_mps / ramp if ramp > 0 else 0.0
    duration = length / speed_mps + 0.5 * ramp
    n = int(round(duration / dt_s))
    t = np.arange(n) * dt_s
    # arc length and speed as functions of time
    s = np.where(t < ramp, 0.5 * accel * t**2, 0.5 * accel * ramp**2 + speed_mps * (t - ramp))
    speed = np.where(t < ramp, accel * t, speed_mps)
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    i = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
    direction = seg[i] / seg_len[i, None]
    pos = pts[i] + direction * (s - cum[i])[:, None]
    vel = direction * speed[:, None]
    acc = np.zeros_like(vel)
    acc[1:] = np.diff(vel, axis=0) / dt_s
    state = np.stack([pos[:, 0], vel[:, 0], acc[:, 0], pos[:, 1], vel[:, 1], acc[:, 1]], axis=1)
    return Trajectory(t, state, np.arange(0, n, rss_every), tuple(map(tuple, pts.tolist())), start)


def motion_model(dt_s: float = DT_S, q_per_step: float = Q_PER_STEP) -> KinematicModel:
    """The CA model of Eq. (3.11) in the thesis's layout with Q = q I (Eq. (3.24))."""
    return constant_acceleration(dt_s, q_per_step, layout="axis_major", noise="isotropic")


def simulate_rss(trajectory: Trajectory, channel: PathLossModel, n_runs: int, rng: np.random.Generator,
                 anchors_m=ANCHORS_M) -> np.ndarray:
    """RSS ``(n_runs, E, m)`` at the RSS epochs from Eq. (2.2), i.i.d. N(0, sigma^2) across anchors, time
    and runs (note 000 s.2.2)."""
    d = pairwise_distance_m(trajectory.position_m[..., trajectory.rss_steps, :], anchors_m)
    noise = rng.standard_normal(np.broadcast_shapes((n_runs,) + d.shape[-2:], d.shape))
    return channel.mean_power_dbm(d) + np.asarray(channel.sigma_db) * noise


def simulate_acceleration(trajectory: Trajectory, sigma_acc_mps2: float, n_runs: int,
                          rng: np.random.Generator) -> np.ndarray:
    """Accelerometer readings ``(n_runs, T, 2)``: true world-frame acceleration plus white noise, Eq. (3.17)
    (no bias, perfect orientation)."""
    a = trajectory.acceleration_mps2
    return a + sigma_acc_mps2 * rng.standard_normal(np.broadcast_shapes((n_runs,) + a.shape[-2:], a.shape))


def mle_positions(rss_dbm, channel: PathLossModel, anchors_m=ANCHORS_M, *, room_m=ROOM_M,
                  grid_step_m: float = MLE_GRID_STEP_M, margin_m: float = MLE_GRID_MARGIN_M):
    """Static MLE (Eq. (2.4)) of every RSS vector ``(..., m)``: the best point of a grid over the room +- margin,
    refined by Levenberg-Marquardt without bounds (note 000, A8). Returns a LocalizationResult."""
    xs = np.arange(-margin_m, room_m[0] + margin_m + 1e-9, grid_step_m)
    ys = np.arange(-margin_m, room_m[1] + margin_m + 1e-9, grid_step_m)
    grid = np.stack(np.meshgrid(xs, ys, indexing="ij"), axis=-1).reshape(-1, 2)
    start = grid_ml_position(anchors_m, rss_dbm, channel, grid).position_m
    return rss_ml_position(anchors_m, rss_dbm, channel, start)


def mle_cost_eq24(points_m, rss_dbm, channel: PathLossModel, anchors_m=ANCHORS_M):
    """The MLE cost of Eq. (2.4) as printed, ``sum_j (log10 d_hat_j - log10 d_j(p))^2`` with ``d_hat`` from Eq. (2.3),
    for every candidate ``points_m`` ``(G, 2)`` and RSS vector ``rss_dbm`` ``(..., m)``: shape ``(..., G)``.

    It equals ``(10 alpha)^-2 sum_j (P_j - P(d_j))^2``, the Gaussian RSS-domain likelihood that
    :func:`locbook.rss_ml_position` minimises (note 000 s.2.3, derived), so both have the same minimiser."""
    log_d = np.log10(np.maximum(pairwise_distance_m(np.asarray(points_m, float), anchors_m), 1e-9))   # (G, m)
    log_d_hat = np.log10(channel.range_m(np.asarray(rss_dbm, float)))                                  # (..., m)
    return np.sum((log_d_hat[..., None, :] - log_d) ** 2, axis=-1)


def initial_state(first_fix_m, mse_mle_m2):
    """Eqs. (3.19)-(3.20): ``x_0 = [x_MLE, 0, 0, y_MLE, 0, 0]`` and
    ``P_0 = diag(MSE_x, 0.0065, 0.00023, MSE_y, 0.0065, 0.00023)``."""
    first_fix_m = np.asarray(first_fix_m, dtype=float)
    x0 = np.zeros(first_fix_m.shape[:-1] + (6,))
    x0[..., 0], x0[..., 3] = first_fix_m[..., 0], first_fix_m[..., 1]
    mse = np.asarray(mse_mle_m2, dtype=float)
    diag = np.stack([mse[..., 0], np.full(mse.shape[:-1], P00_VEL_VAR), np.full(mse.shape[:-1], P00_ACC_VAR),
                     mse[..., 1], np.full(mse.shape[:-1], P00_VEL_VAR), np.full(mse.shape[:-1], P00_ACC_VAR)], -1)
    return x0, diag[..., :, None] * np.eye(6)


def run_filter(name: str, trajectory: Trajectory, rss_dbm, mle_fix_m, mse_mle_m2, channel: PathLossModel, *,
               acc_mps2=None, sigma_acc_mps2: float | None = None, model: KinematicModel | None = None,
               serial_order: str = "descending", anchors_m=ANCHORS_M) -> TrackResult:
    """One filter of Tables 3.7-3.12 on all runs at once, recorded at the RSS epochs.

    ``rss_dbm`` ``(..., E, m)`` and ``mle_fix_m`` ``(..., E, 2)`` are at ``trajectory.rss_steps``; the filter starts
    at the first epoch from the MLE fix (Eqs. (3.19)-(3.20)) and runs on the 20 Hz grid. ``"kalman_filter"`` is
    KF (MLE): the fixes as linear position measurements with R = diag(MSE_MLE) (Eq. (3.21)); ``"parallel_ekf"``
    and ``"serial_ekf"`` use the raw RSS with R = sigma^2 I (Eq. (3.22)). With ``acc_mps2`` ``(..., T, 2)`` the
    accelerometer updates every step before the RSS (Table 3.5, R_acc = sigma_acc^2 I, Eq. (3.23)).
    """
    if name not in FILTERS:
        raise ParameterError(f"filter must be one of {FILTERS}, got {name!r}")
    model = model or motion_model()
    steps = trajectory.rss_steps
    n_steps = trajectory.time_s.size
    rss_dbm = np.asarray(rss_dbm, dtype=float)
    batch = rss_dbm.shape[:-2]
    x0, P0 = initial_state(np.asarray(mle_fix_m)[..., 0, :], np.asarray(mse_mle_m2))
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
        mse = np.asarray(mse_mle_m2, dtype=float)
        measurements.append(LinearMeasurement(z, model.position_measurement_matrix(), mse[..., :, None] * np.eye(2)))
    else:
        z = np.full(grid_shape + (rss_dbm.shape[-1],), np.nan)
        z[..., at, :] = rss_dbm[..., 1:, :]
        mode = "parallel" if name == "parallel_ekf" else "serial"
        measurements.append(RssMeasurement(z, anchors_m, channel, model.position_index, mode=mode,
                                           order=serial_order))
    track = extended_kalman_filter(model.F, model.Q, x0, P0, measurements, record=at)
    x = np.concatenate([np.broadcast_to(x0[..., None, :], track.x.shape[:-2] + (1, 6)), track.x], axis=-2)
    P = np.concatenate([np.broadcast_to(P0[..., None, :, :], track.P.shape[:-3] + (1, 6, 6)), track.P], axis=-3)
    return TrackResult(x, P, steps)


@dataclass
class ChannelRun:
    """All filters for one channel setting (sigma_RSS, alpha): errors ``(runs, E)`` at the RSS epochs, keyed
    ``"static_mle"`` and ``(filter, sigma_acc or None)``; ``mse_mle_m2`` the per-axis MSE used for R and P_0."""

    sigma_rss_db: float
    path_loss_exp: float
    mse_mle_m2: np.ndarray
    errors: dict = field(default_factory=dict)
    converged_fraction: float = 1.0


def run_channel(trajectory: Trajectory, sigma_rss_db: float, path_loss_exp: float, n_runs: int,
                rng: np.random.Generator, *, sigma_acc_values=(), only_rss: bool = True, filters=FILTERS,
                ref_power_dbm: float = REF_POWER_DBM, serial_order: str = "descending",
                model: KinematicModel | None = None, keep_estimates: bool = False) -> ChannelRun:
    """Simulate one channel setting and run the MLE and the requested filters, ONLY RSS and/or fused with an
    accelerometer of each ``sigma_acc_values``; all cases share the same RSS draws (common random numbers, so
    the fusion gain is measured on identical RSS). The MLE's per-axis MSE sets R and P_0 of KF (MLE) and
    P_0 of every filter (Eqs. (3.20), (3.21), A6)."""
    channel = PathLossModel(ref_power_dbm, path_loss_exp, sigma_rss_db)
    truth = trajectory.position_m[..., trajectory.rss_steps, :]
    rss = simulate_rss(trajectory, channel, n_runs, rng)
    mle = mle_positions(rss, channel)
    fix = mle.position_m
    mse = np.mean((fix - truth) ** 2, axis=(0, 1))
    out = ChannelRun(sigma_rss_db, path_loss_exp, mse, converged_fraction=float(np.mean(mle.converged)))
    out.errors["static_mle"] = np.linalg.norm(fix - truth, axis=-1)
    if keep_estimates:
        out.errors[("estimates", "static_mle")] = fix
    # one accelerometer noise draw, scaled for each sigma_ACC (common random numbers across the sweep)
    unit_noise = rng.standard_normal((n_runs,) + trajectory.acceleration_mps2.shape[-2:])
    cases = ([None] if only_rss else []) + list(sigma_acc_values)
    for sigma_acc in cases:
        acc = None if sigma_acc is None else trajectory.acceleration_mps2 + sigma_acc * unit_noise
        for name in filters:
            track = run_filter(name, trajectory, rss, fix, mse, channel, acc_mps2=acc, sigma_acc_mps2=sigma_acc,
                               model=model, serial_order=serial_order)
            pos = track.x[..., [0, 3]]
            out.errors[(name, sigma_acc)] = np.linalg.norm(pos - truth, axis=-1)
            if keep_estimates:
                out.errors[("estimates", name, sigma_acc)] = pos
    return out


@dataclass(frozen=True)
class Setting:
    """One printed cell's setting: channel (sigma_RSS, alpha) and accelerometer (None for ONLY RSS)."""

    sigma_rss_db: float
    path_loss_exp: float
    sigma_acc_mps2: float | None


def _table_settings():
    """Printed row -> setting for Tables 3.7-3.12 (captions, note 000 s.3.3). sigma_ACC in the tables is
    written 0.015 (Table 3.6: 0.0152)."""
    out = {}
    for s in (6, 5, 4, 3):
        out[("3.7", f"sigma_rss_db={s}")] = Setting(s, 3.0, None)
        out[("3.8", f"sigma_rss_db={s}")] = Setting(s, 3.0, 0.015)
    for a in ("0.015", "0.0075", "0.0015", "0.00075"):
        out[("3.9", f"sigma_acc={a}")] = Setting(6, 3.0, float(a))
    for a in ("0.0075", "0.0015"):
        out[("3.10", f"sigma_acc={a}")] = Setting(3, 3.0, float(a))
    for p in ("4", "3.5", "3", "2.5", "2", "1.5"):
        out[("3.11", f"ple={p}")] = Setting(6, float(p), None)
        out[("3.12", f"ple={p}")] = Setting(6, float(p), 0.015)
    return out


TABLE_SETTINGS = _table_settings()


def printed_tables() -> tuple[dict, ...]:
    """Printed cells of Tables 3.7-3.12 (locbook/data/printed/dogan2015.csv): dicts with table, row, column,
    value (float) and the :class:`~locbook.data.Printed` itself (``printed``)."""
    return tuple({"table": p.location.removeprefix("Table "), "row": p.item, "column": p.statistic,
                  "value": p.value, "printed": p}
                 for p in printed("dogan2015") if p.location.startswith("Table 3."))


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
               serial_order: str = "descending", model: KinematicModel | None = None) -> dict:
    """Every channel setting of Tables 3.7-3.12 (or the ``channels`` subset of :data:`CHANNELS`), each with its
    own random stream spawned from ``seed``; returns ``{(sigma_RSS, alpha): ChannelRun}``."""
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
                               filters=filters, serial_order=serial_order, model=model)
    return out


def table_rows(runs: dict) -> list[dict]:
    """Printed cells beside the reproduced RMSE (over runs and RSS epochs, note 000 A7) with its Monte-Carlo
    standard error; cells whose setting was not run are left out."""
    from ..metrics import rmse_m
    rows = []
    for cell in printed_tables():
        s = TABLE_SETTINGS[(cell["table"], cell["row"])]
        run = runs.get((s.sigma_rss_db, s.path_loss_exp))
        key = "static_mle" if cell["column"] == "static_mle" else (cell["column"], s.sigma_acc_mps2)
        if run is None or key not in run.errors:
            continue
        err = run.errors[key]
        per_run = np.mean(err**2, axis=1)          # runs are independent; epochs within a run are not
        value = float(rmse_m(err))
        se = float(np.std(per_run, ddof=1) / np.sqrt(per_run.size) / (2.0 * value))
        rows.append(dict(table=cell["table"], row=cell["row"], column=cell["column"], printed=cell["value"],
                         reproduced=value, mc_se=se))
    return rows


#: ``"smc"``: Eq. (4.22), the RSS information averaged over simulated CA trajectories (Figs 4.1/4.3);
#: ``"linear"``: MLE fixes as linear measurements with R = diag(MSE_MLE) (Figs 4.2/4.4, trajectory-free);
#: ``"truth"``: the RSS information along one known trajectory (truth-conditioned, Stone Soup's convention),
#: the bound to set beside filters run on that trajectory (note 000 X2).
BOUND_KINDS = ("smc", "linear", "truth")


def smc_trajectories(n_trajectories: int, n_steps: int, rng: np.random.Generator, *,
                     model: KinematicModel | None = None, room_m=ROOM_M):
    """Sec. 4.1.2: trajectories "that exactly follow the constant acceleration model", each beginning at a point
    "selected arbitrarily in the area": uniform in the room, v_0 ~ N(0, 0.0065 I), a_0 ~ N(0, 0.00023 I) (the
    P_{0|0} blocks, note 000 A4), propagated with the per-step Q. Shape ``(N, n_steps, 6)``."""
    model = model or motion_model()
    start = model.state_from(rng.uniform((0.0, 0.0), room_m, (n_trajectories, 2)),
                             np.sqrt(P00_VEL_VAR) * rng.standard_normal((n_trajectories, 2)),
                             np.sqrt(P00_ACC_VAR) * rng.standard_normal((n_trajectories, 2)))
    return simulate_states(model.F, model.Q, start, n_steps - 1, rng)


def smc_trajectory(states, rss_every: int = RSS_EVERY, dt_s: float = DT_S) -> Trajectory:
    """Wrap simulated states ``(N, T, 6)`` (e.g. :func:`smc_trajectories`) as one trajectory per run, so the
    filters can be run on the bound's own scenario."""
    states = np.asarray(states, dtype=float)
    n = states.shape[-2]
    return Trajectory(np.arange(n) * dt_s, states, np.arange(0, n, rss_every), (), "smc")


def pcrlb_m(kind: str, *, fusion: bool, sigma_rss_db: float, mse_mle_m2, n_steps: int,
            path_loss_exp: float = PATH_LOSS_EXP, sigma_acc_mps2: float = SIGMA_ACC_MPS2,
            rng: np.random.Generator | None = None, n_trajectories: int = MC_RUNS, trajectory: Trajectory | None = None,
            acc_at_rss_epochs: bool = False, min_distance_m: float = 0.0, height_offset_m: float = 0.0,
            rss_every: int = RSS_EVERY, model: KinematicModel | None = None, anchors_m=ANCHORS_M) -> np.ndarray:
    """Position PCRLB (Eq. (4.23), m) at steps ``0 .. n_steps - 1`` of the 20 Hz grid, by Table 4.1.

    J_0 = P_{0|0}^{-1} (Eqs. (3.20), (4.11)); the Tichavsky recursion (4.7) with D22 = Q^{-1} + J_z, where J_z at
    RSS epochs (every ``rss_every``-th step) is the RSS information of ``kind`` (see :data:`BOUND_KINDS`), and for
    ``fusion`` the accelerometer's ``H_acc^T R_acc^{-1} H_acc`` at the other steps. Table 4.1 leaves the
    acceleration out at RSS epochs although the fusion filter uses it there; ``acc_at_rss_epochs=True`` adds it
    (the FIX of note 000 A5). ``min_distance_m`` / ``height_offset_m`` regularise the near-anchor 1/d^2 singularity
    of E[J_z] (note 000 s.2.10); the thesis uses neither.
    """
    if kind not in BOUND_KINDS:
        raise ParameterError(f"kind must be one of {BOUND_KINDS}, got {kind!r}")
    model = model or motion_model()
    idx = model.position_index
    mse = np.asarray(mse_mle_m2, dtype=float)
    _, P0 = initial_state(np.zeros(2), mse)
    rss_steps = np.arange(rss_every, n_steps, rss_every)
    jz = np.zeros((n_steps - 1, 6, 6))
    if fusion:
        acc_info = linear_measurement_information(model.derivative_measurement_matrix(2),
                                                  sigma_acc_mps2**2 * np.eye(2))
        jz[:] = acc_info
        if not acc_at_rss_epochs:
            jz[rss_steps - 1] = 0.0
    regularise = dict(min_distance_m=min_distance_m, height_offset_m=height_offset_m)
    if kind == "linear":
        rss_info = linear_measurement_information(model.position_measurement_matrix(), np.diag(mse))
    elif kind == "truth":
        if trajectory is None or trajectory.time_s.size < n_steps:
            raise ParameterError("the truth-conditioned bound needs a trajectory of at least n_steps steps")
        rss_info = rss_state_information(trajectory.state[rss_steps], anchors_m, path_loss_exp, sigma_rss_db, idx,
                                         **regularise)
    else:
        if rng is None:
            raise ParameterError("the Monte-Carlo (smc) bound needs rng")
        states = smc_trajectories(n_trajectories, n_steps, rng, model=model)
        rss_info = rss_state_information(states[:, rss_steps], anchors_m, path_loss_exp, sigma_rss_db, idx,
                                         **regularise).mean(axis=0)               # Eq. (4.22)
    jz[rss_steps - 1] += rss_info
    info = posterior_crlb(np.linalg.inv(P0), model.F, model.Q, jz)
    return position_bound_m(info, idx)


#: Acceptance windows (relative to the printed value) plus 2 Monte-Carlo standard errors. The MLE depends on the
#: room and the positions only, so 10 %; the filters also depend on the unprinted trajectory, start, time grid
#: and R_MLE (note 000 A1, A2, A6: "expect +-15-30 % at best"), so 20 %. The thesis's own repeat rows differ by
#: up to 2.5 % (its Monte-Carlo repeatability).
STATIC_TOLERANCE = 0.10
FILTER_TOLERANCE = 0.20


def _miss_reason(row) -> str:
    s = TABLE_SETTINGS[(row["table"], row["row"])]
    if s.sigma_acc_mps2 is not None and s.sigma_acc_mps2 < 0.015:
        return ("A10: in this model fusion is insensitive to sigma_ACC below 0.015 (the process noise, std 0.0048 per "
                "step, dominates, as the thesis's own Sec. 4.1.2 says); the printed drop from 0.015 to 0.0075 is "
                "unexplained (a different acceleration truth or R_acc)")
    if s.sigma_acc_mps2 is not None and row["column"] != "kalman_filter":
        if row["reproduced"] > row["printed"]:
            return ("fused EKFs: a tail of runs that diverge for tens of seconds from the unobserved initial velocity "
                    "(truth 0.3 m/s, x_0 at rest, A1); the start-from-rest variant gives errors below the printed "
                    "ones, so the printed value lies between the two unprinted starts")
        return ("fused EKFs below the printed value: fewer diverging runs in this setting; the fused EKFs depend "
                "strongly on the unprinted start (A1), see the start-variant table")
    if s.sigma_acc_mps2 is None and row["column"] == "kalman_filter" and s.path_loss_exp <= 2.5:
        return ("KF (MLE) at low alpha: far-out MLE fixes make R = diag(MSE_MLE) large, and our KF is better than "
                "printed; R's form (constant vs per epoch, A6) and any bound on the MLE (A8) are not printed")
    return "unexplained (unprinted trajectory, start and time grid, A1/A2)"


def record_tables(report, rows, *, label: str = "") -> dict:
    """Record every printed cell (``where`` = table, row, column) with its window; returns the score."""
    within = 0
    for r in rows:
        frac = STATIC_TOLERANCE if r["column"] == "static_mle" else FILTER_TOLERANCE
        tol = frac * r["printed"] + 2.0 * r["mc_se"]
        inside = abs(r["reproduced"] - r["printed"]) <= tol
        within += inside
        report.number(f"RMSE {r['column']}{label}", f"Table {r['table']}, {r['row']}, {r['column']}", r["printed"],
                      r["reproduced"], unit="m", tolerance=tol, mc_std_error=r["mc_se"],
                      tolerance_basis=f"{frac:.0%} of printed (unprinted scenario, note 000 A1/A2/A8) + 2 MC s.e.",
                      note="" if inside else _miss_reason(r))
    return {"cells": len(rows), "within": within}


def fusion_reduction_rows(runs: dict) -> list[dict]:
    """Fusion gain at sigma_ACC = 0.015 for each filter and channel: Table 3.7 -> 3.8 and 3.11 -> 3.12."""
    from ..metrics import reduction_pct, rmse_m
    printed = {(c["table"], c["row"], c["column"]): c["value"] for c in printed_tables()}
    out = []
    for (t_only, t_fus), rows in ((("3.7", "3.8"), [f"sigma_rss_db={s}" for s in (6, 5, 4, 3)]),
                                  (("3.11", "3.12"), [f"ple={p}" for p in ("4", "3.5", "3", "2.5", "2", "1.5")])):
        for row in rows:
            s = TABLE_SETTINGS[(t_only, row)]
            run = runs.get((s.sigma_rss_db, s.path_loss_exp))
            if run is None:
                continue
            for name in FILTERS:
                ours = reduction_pct(rmse_m(run.errors[(name, None)]), rmse_m(run.errors[(name, 0.015)]))
                theirs = reduction_pct(printed[(t_only, row, name)], printed[(t_fus, row, name)])
                out.append(dict(tables=f"{t_only} -> {t_fus}", row=row, filter=name, printed_pct=theirs,
                                reproduced_pct=float(ours)))
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


def bound_rows(runs: dict, trajectory: Trajectory, *, model: KinematicModel | None = None) -> list[dict]:
    """Every filter's RMSE beside the truth-conditioned PCRLB of its own information (ONLY RSS or fused, same
    trajectory, R and P_0), both as the RMS over the RSS epochs; KF (MLE) also beside the linear bound."""
    from ..metrics import rmse_m
    n = trajectory.time_s.size
    out = []
    for (sigma, ple), run in runs.items():
        for key, err in run.errors.items():
            if not (isinstance(key, tuple) and key[0] in FILTERS):
                continue
            name, sigma_acc = key
            common = dict(fusion=sigma_acc is not None, sigma_rss_db=sigma, path_loss_exp=ple,
                          sigma_acc_mps2=sigma_acc or SIGMA_ACC_MPS2, mse_mle_m2=run.mse_mle_m2, n_steps=n, model=model)
            bound = pcrlb_m("truth", trajectory=trajectory, **common)[trajectory.rss_steps]
            row = dict(sigma_rss_db=sigma, ple=ple, sigma_acc=sigma_acc, filter=name, rmse_m=float(rmse_m(err)),
                       pcrlb_m=float(np.sqrt(np.mean(bound**2))))
            if name == "kalman_filter":
                lin = pcrlb_m("linear", **common)[trajectory.rss_steps]
                row["linear_pcrlb_m"] = float(np.sqrt(np.mean(lin**2)))
            row["ratio"] = row["rmse_m"] / row["pcrlb_m"]
            out.append(row)
    return out


def table_view(rows, table: str) -> list[dict]:
    """One display row per printed row: ``printed / reproduced`` side by side for each filter column."""
    out: dict = {}
    for r in rows:
        if r["table"] == table:
            out.setdefault(r["row"], {"row": r["row"]})[r["column"]] = f"{r['printed']:.3f} / {r['reproduced']:.3f}"
    return list(out.values())


def miss_table(report) -> list[dict]:
    """Every recorded number outside its window, with the reason."""
    return [{"where": r["where"], "printed": r["reported"], "reproduced": round(r["reproduced"], 3),
             "reason": r["note"] or "unexplained"} for r in report.numbers if r["within_tolerance"] is False]
