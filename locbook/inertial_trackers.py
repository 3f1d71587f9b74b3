"""The battery's RSS + inertial fusion trackers: Dogan's accelerometer EKF and Gudipati's accelerometer + gyroscope
EKF and UKF on a track with an inertial stream (:mod:`locbook.data.inertial`), built from the library's filters and
models as :mod:`locbook.scenarios.dogan` and :mod:`locbook.scenarios.gudipati` build them.

Every tracker steps on the sub-step grid of the track's epoch clock (:func:`locbook.data.inertial.align`: ``n_sub``
sub-steps of ``dt_f`` per epoch, the inertial window means at every sub-step, the RSS at every ``n_sub``-th) from the
RSS trackers' start (the first ``rss_ml`` fix at rest, its calibrated covariance), and is recorded at the RSS epochs,
so its positions ``(R, T, 2)`` are on the same clock as every other tracker's.

- ``ekf_rss_acc`` (Dogan 2015, Sec. 3.5, Table 3.5): the 6-state nearly-constant-acceleration model ``[x, y, vx, vy,
  ax, ay]`` (:class:`~locbook.models.motion.KinematicModel`, order 2) with Dogan's full-rank per-step ``Q = q I``
  (Eq. (3.24), ``noise="isotropic"``), the thesis's own form (the velocity and position get noise of their own; on
  the example, seed 1, walk_a, whose first fix is 4.5 m off: 0.78 m mean error, the Wiener form of the 8-state model
  0.59 m, both with the serial RSS update; with one stacked update 2.24 m and 6.71 m), the accelerometer a linear
  measurement of the acceleration states
  (``LinearMeasurement``, R = the stationary noise variance over the samples per sub-step), rotated to the world
  frame by the heading ``psi_0 + integral of the gyroscope`` where the track has one, else taken as world-frame
  readings (:data:`NO_GYRO_FRAME`, the literal reading of Dogan's and Gudipati's texts, flagged in the settings);
  the RSS of every epoch (``RssMeasurement``, the calibrated channel, serial updates: :data:`RSS_UPDATE`).
- ``kf_acc`` (Dogan 2015's "KF (MLE)" fused with the accelerometer, Eq. (3.21)): ``ekf_rss_acc``'s model, Q and
  accelerometer, the ``rss_ml`` fixes that ``kf_on_ml`` filters (epochs that heard at least 3 anchors) as linear
  position measurements with their calibrated covariance in place of the raw RSS (Dogan uses one Q for every filter).
- ``ekf_rss_imu`` / ``ukf_rss_imu`` (Gudipati 2017, Secs. 3.2-3.6): the 8-state
  :class:`~locbook.models.motion.HeadingKinematicModel` (heading and yaw rate), the body-frame accelerometer and the
  gyroscope through :class:`~locbook.models.imu.InertialMeasurement` (``frame="body"``), the RSS as above; only on a
  track with a gyroscope.

The settings (:func:`fit_fusion`), each by a stated rule: the sensors' bias and noise variance from the calibration
recordings' samples while the tag dwells at a point (Gudipati 2017, Sec. 3.3,
:func:`locbook.models.imu.stationary_bias`;
:func:`stationary_noise`), else locbook's assumed MEMS noise (:func:`default_noise`) with no bias removed;
the initial heading ``psi_0`` (unknown to a method: the truth's heading is never used) by maximum likelihood of
``ekf_rss_acc``'s innovations over :data:`HEADING_CANDIDATES_DEG` then :data:`HEADING_REFINE_DEG` around the best;
``q`` (and ``q_angular``) by maximum likelihood of the fusion EKF's innovations (:func:`locbook.fit_noise_ml`, the
rule of the RSS trackers' ``q``, :func:`locbook.scenarios.measured.fit_motion`), on the readings of the track, no
truth: the RSS trackers' constant-velocity ``q`` is no substitute, it drives another state (the velocity's increments
per epoch, not the acceleration's per sub-step), and the accelerometer measures the acceleration states directly, so
its innovations hold the information about ``q``. The 8-state UKF takes the 8-state EKF's ``q`` (the same model).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .battery import ml_fixes
from .data.inertial import InertialGrid
from .errors import ParameterError
from .models.imu import (
    MEMS_ACCEL_SIGMA_M_S2,
    MEMS_GYRO_SIGMA_RAD_S,
    InertialMeasurement,
    body_to_world,
    stationary_bias,
)
from .models.motion import HeadingKinematicModel, KinematicModel
from .tracking.divergence import DivergenceFlags
from .tracking.kalman import extended_kalman_filter
from .tracking.noise import fit_noise_ml
from .tracking.streams import LinearMeasurement, RssMeasurement, Stream
from .tracking.unscented import unscented_kalman_filter

__all__ = ["FUSION_TRACKERS", "FUSION_PRIORS", "NO_GYRO_FRAME", "HEADING_CANDIDATES_DEG", "HEADING_REFINE_DEG",
           "Q_ACC_START", "Q_IMU_START", "Q_ANGULAR_START", "START_ACCELERATION_SD_M_S2", "START_YAW_RATE_SD_RAD_S",
           "HEADING_START_SD_RAD", "RSS_UPDATE", "STATIONARY_MARGIN_S", "MIN_STATIONARY_SAMPLES", "ImuNoise",
           "FusionInputs", "stationary_noise", "default_noise", "fit_fusion", "run_fusion", "needs_gyro"]

FUSION_TRACKERS = {
    "kf_acc": "accelerometer KF on the rss_ml fixes (Dogan 2015's KF (MLE) with the accelerometer): the model and the "
              "accelerometer of ekf_rss_acc, the fixes kf_on_ml filters as linear position measurements (R: their "
              "calibrated covariance)",
    "ekf_rss_acc": "RSS + accelerometer EKF (Dogan 2015): constant-acceleration model on the inertial sub-step grid, "
                   "the accelerometer a linear measurement of the acceleration (rotated by the gyro-integrated "
                   "heading, "
                   "or taken as world-frame without a gyroscope), RSS at every epoch",
    "ekf_rss_imu": "RSS + accelerometer + gyroscope EKF (Gudipati 2017): 8-state heading model, body-frame inertial "
                   "measurement, RSS at every epoch, on the inertial sub-step grid",
    "ukf_rss_imu": "RSS + accelerometer + gyroscope UKF (Gudipati 2017): the 8-state heading model of ekf_rss_imu, "
                   "unscented",
}
_IMU_PRIOR = ("it fuses inertial readings the bound does not have (the bound is the RSS-only constant-velocity "
              "PCRLB); a path smoother than the model lets it beat it too")
#: why each fusion tracker may fall below the posterior CRLB of the rows (the RSS trackers' bound)
FUSION_PRIORS = {name: _IMU_PRIOR for name in FUSION_TRACKERS}
FUSION_PRIORS["kf_acc"] = _IMU_PRIOR + "; its fixes lie in the floor's bounding box"
#: the trackers that need a gyroscope (the others run with an accelerometer alone)
needs_gyro = ("ekf_rss_imu", "ukf_rss_imu")
#: without a gyroscope the heading is unknown: ekf_rss_acc takes the accelerometer's readings as world-frame
#: accelerations (the literal reading of Dogan 2015, Table 3.5, and of Gudipati 2017, Sec. 3.3; imu.py's
#: ``frame="world"``): right for a tag that keeps its orientation, wrong for one that turns (a phone in a hand)
NO_GYRO_FRAME = "world"
#: the fusion trackers' RSS update: serial scalar updates in descending RSS, each re-linearised at the state updated so
#: far (Dogan 2015, Table 3.3; the battery's ekf_serial). A fusion model is confident about its velocity (the
#: accelerometer pins the acceleration), and from a start metres off one stacked update linearised at the start sends
#: it away: on the example (seed 1, 120 s, walk_a's first fix 4.5 m off) the parallel update gave 2.2 m (ekf_rss_acc)
#: and 5.7 m (ekf_rss_imu) mean errors, the serial 0.78 m and 0.64 m (the RSS-only ekf 1.64 m, ekf_serial 1.21 m)
RSS_UPDATE = "serial"
#: the initial heading's candidates (deg) for its maximum-likelihood choice, then a refinement around the best
HEADING_CANDIDATES_DEG = tuple(range(0, 360, 10))
HEADING_REFINE_DEG = tuple(range(-5, 6))
#: the start of the fusion trackers beyond the RSS trackers' (position and velocity): at rest, acceleration sd
#: (m/s^2; a walker accelerates by up to about 1 m/s^2), yaw rate sd (rad/s; a walker turns at up to ~1 rad/s) and the
#: heading's sd about its maximum-likelihood value (rad: the candidates' spacing)
START_ACCELERATION_SD_M_S2 = 1.0
START_YAW_RATE_SD_RAD_S = 1.0
HEADING_START_SD_RAD = float(np.deg2rad(10.0))
#: the maximum-likelihood fits of q start here: ekf_rss_acc's per-step variance of every state (Dogan's Q = q I;
#: Dogan prints 2.3e-5 per 0.05 s step for simulated walks), the 8-state model's acceleration increment variance per
#: sub-step ((m/s^2)^2: a walker's acceleration changes by ~0.1 m/s^2 per 0.1 s) and its yaw rate's ((rad/s)^2,
#: Gudipati's WalkSettings); the fits move them by a factor within 1e-4..1e4
Q_ACC_START = 1e-3
Q_IMU_START = 0.01
Q_ANGULAR_START = 0.01
#: samples within this time (s) of a dwell's first and last reading are not used as stationary (the tag arrives and
#: leaves), and a stationary calibration needs at least MIN_STATIONARY_SAMPLES samples, else the defaults
STATIONARY_MARGIN_S = 0.5
MIN_STATIONARY_SAMPLES = 50


@dataclass(frozen=True)
class ImuNoise:
    """The inertial sensors' calibration: bias (the stationary mean, subtracted: Gudipati 2017, Sec. 3.3) and white
    noise variance per sample of the accelerometer ``(2,)`` (m/s^2, m^2/s^4) and the gyroscope (rad/s, rad^2/s^2;
    None without one); ``n_samples`` stationary samples it was estimated from (0: defaults), ``source`` the rule."""

    acc_bias_m_s2: np.ndarray
    acc_var_m2_s4: np.ndarray
    gyro_bias_rad_s: float | None
    gyro_var_rad2_s2: float | None
    n_samples: int
    source: str


def default_noise(with_gyro: bool) -> ImuNoise:
    """No stationary samples: locbook's assumption of a MEMS IMU's noise per sample
    (:data:`locbook.models.imu.MEMS_ACCEL_SIGMA_M_S2`, :data:`~locbook.models.imu.MEMS_GYRO_SIGMA_RAD_S`), no bias
    removed."""
    acc_sd, gyro_sd = MEMS_ACCEL_SIGMA_M_S2, MEMS_GYRO_SIGMA_RAD_S
    return ImuNoise(np.zeros(2), np.full(2, acc_sd**2), 0.0 if with_gyro else None,
                    gyro_sd**2 if with_gyro else None, 0,
                    f"default: no calibration recording has inertial samples at rest; accelerometer sd "
                    f"{acc_sd:g} m/s^2, gyroscope sd {gyro_sd:.3g} rad/s per sample "
                    "(locbook.models.imu.MEMS_ACCEL_SIGMA_M_S2 and MEMS_GYRO_SIGMA_RAD_S, locbook's assumption), "
                    "no bias removed")


def stationary_noise(recordings, *, with_gyro: bool) -> ImuNoise:
    """Bias and noise variance from inertial samples at rest (Gudipati 2017, Sec. 3.3): ``recordings`` are
    ``(readings, samples)`` pairs of calibration recordings. A dwell is a run of consecutive readings (in time order)
    with one true position; its samples more than :data:`STATIONARY_MARGIN_S` from its first and last reading are at
    rest. The bias is the mean of every such sample (:func:`locbook.models.imu.stationary_bias`), the variance the
    pooled within-dwell variance (each dwell's own mean removed: ``sum (s - mean_dwell)^2 / (N - dwells)``, so a
    tilt that differs between dwells is not counted as noise). Fewer than :data:`MIN_STATIONARY_SAMPLES`:
    :func:`default_noise`."""
    values, groups, names = [], [], []
    g0 = 0
    for readings, samples in recordings:
        r = readings.sort_values("time_s", kind="stable")
        xy = r[["x_m", "y_m"]].to_numpy(float)
        t = r["time_s"].to_numpy(float)
        known = np.isfinite(xy).all(axis=1)
        xy, t = xy[known], t[known]
        if not len(t):
            continue
        change = np.r_[True, (xy[1:] != xy[:-1]).any(axis=1)]
        run = np.cumsum(change) - 1
        first = np.full(run[-1] + 1, np.inf)
        last = np.full(run[-1] + 1, -np.inf)
        np.minimum.at(first, run, t)
        np.maximum.at(last, run, t)
        lo, hi = first + STATIONARY_MARGIN_S, last - STATIONARY_MARGIN_S
        k = np.searchsorted(lo, samples.time_s, side="right") - 1      # the dwell that starts before each sample
        ok = (k >= 0)
        ok[ok] = samples.time_s[ok] <= hi[k[ok]]
        cols = [samples.acc_m_s2[ok]]
        if with_gyro:
            gyro = samples.gyro_rad_s if samples.gyro_rad_s is not None else np.full(len(samples), np.nan)
            cols.append(gyro[ok, None])
        v = np.concatenate(cols, axis=1)
        fine = np.isfinite(v).all(axis=1)
        values.append(v[fine])
        groups.append(k[ok][fine] + g0)
        g0 += run[-1] + 1
        names.append(samples.file.name)
    v = np.concatenate(values) if values else np.zeros((0, 3 if with_gyro else 2))
    if len(v) < MIN_STATIONARY_SAMPLES:
        return default_noise(with_gyro)
    g = np.concatenate(groups)
    _, g = np.unique(g, return_inverse=True)
    n_groups = int(g.max()) + 1
    mean = np.stack([np.bincount(g, weights=v[:, c], minlength=n_groups) for c in range(v.shape[1])], axis=1)
    mean /= np.bincount(g, minlength=n_groups)[:, None]
    var = ((v - mean[g]) ** 2).sum(axis=0) / max(len(v) - n_groups, 1)
    bias = stationary_bias(v, axis=0)[0]
    return ImuNoise(bias[:2], var[:2], float(bias[2]) if with_gyro else None, float(var[2]) if with_gyro else None,
                    len(v), f"rule: stationary calibration (Gudipati 2017, Sec. 3.3) on {len(v):,} samples at rest in "
                            f"{n_groups} dwells of {', '.join(names)}: bias = their mean, variance = the pooled "
                            f"within-dwell variance")


@dataclass(frozen=True)
class FusionInputs:
    """What the fusion trackers of one track need (:func:`fit_fusion`): the inertial readings on the sub-step grid,
    the calibration (bias removed from ``acc_m_s2`` / ``gyro_rad_s``), the heading start ``heading_rad`` (at the
    grid's start; None without a gyroscope), ``q_acc`` (ekf_rss_acc), ``q_imu = (q, q_angular)`` (ekf_rss_imu,
    ukf_rss_imu; None without a gyroscope) and the fits' records."""

    grid: InertialGrid = field(repr=False)
    noise: ImuNoise
    heading_rad: float | None
    q_acc: float
    q_imu: tuple | None
    fits: dict = field(default_factory=dict)

    @property
    def has_gyro(self) -> bool:
        return self.grid.gyro_rad_s is not None

    @property
    def trackers(self) -> tuple[str, ...]:
        return tuple(n for n in FUSION_TRACKERS if self.has_gyro or n not in needs_gyro)

    @property
    def acc_m_s2(self) -> np.ndarray:
        return self.grid.acc_m_s2 - self.noise.acc_bias_m_s2

    @property
    def gyro_rad_s(self) -> np.ndarray | None:
        return None if self.grid.gyro_rad_s is None else self.grid.gyro_rad_s - self.noise.gyro_bias_rad_s

    @property
    def samples_per_step(self) -> float:
        c = self.grid.counts[self.grid.counts > 0]
        return float(np.median(c)) if c.size else 1.0


def _heading(fus: FusionInputs, heading0) -> np.ndarray:
    """Heading ``(K, S)`` at each sub-step's middle: ``psi_0`` plus the integrated calibrated gyroscope (a window
    without a sample adds no turn)."""
    w = np.nan_to_num(fus.gyro_rad_s, nan=0.0) * fus.grid.dt_s
    mid = np.cumsum(w) - 0.5 * w
    return np.asarray(heading0, float).reshape(-1, 1) + mid


def _acc_world(fus: FusionInputs, heading0) -> np.ndarray:
    """The accelerometer's window means in the world frame ``(K, S, 2)`` (``heading0 (K,)``), or as world-frame
    readings without a gyroscope (:data:`NO_GYRO_FRAME`)."""
    acc = fus.acc_m_s2
    if not fus.has_gyro:
        return acc[None]
    return body_to_world(acc[None], _heading(fus, heading0))


def _start(x0, P0, n_state):
    """The RSS trackers' start ``x0 (R, 4)``, ``P0 (4, 4)`` extended to the fusion model's state (at rest)."""
    x0 = np.asarray(x0, float)
    out = np.zeros(x0.shape[:-1] + (n_state,))
    out[..., :4] = x0
    P = np.zeros((n_state, n_state))
    P[:4, :4] = P0
    P[4, 4] = P[5, 5] = START_ACCELERATION_SD_M_S2**2
    if n_state == 8:
        P[6, 6], P[7, 7] = HEADING_START_SD_RAD**2, START_YAW_RATE_SD_RAD_S**2
    return out, np.broadcast_to(P, x0.shape[:-1] + (n_state, n_state))


def _acc_setup(sc, fus: FusionInputs, rss, x0, P0, q: float, heading0):
    """``(model, x0, P0, streams)`` of ekf_rss_acc: runs ``R`` of readings ``rss (R, T, m)`` (and of ``heading0``)."""
    model = KinematicModel(fus.grid.dt_s, q, order=2, dim=2, layout="derivative_major", noise="isotropic")
    acc = _acc_world(fus, heading0)
    runs = max(rss.shape[0], acc.shape[0])
    acc = np.broadcast_to(acc, (runs,) + acc.shape[1:])
    z = np.broadcast_to(fus.grid.on_grid(rss), (runs,) + (fus.grid.n_steps, rss.shape[-1]))
    x, P = _start(np.broadcast_to(x0, (runs, 4)), P0, 6)
    r_acc = np.diag(fus.noise.acc_var_m2_s4) / fus.samples_per_step
    streams = [LinearMeasurement(acc, model.derivative_measurement_matrix(2), r_acc),
               RssMeasurement(z, sc.anchors_m, sc.channel, np.array([0, 1]), mode=RSS_UPDATE,
                              tag_height_m=sc.tag_height_m)]
    return model, x, P, streams


def _imu_setup(sc, fus: FusionInputs, rss, x0, P0, q: tuple):
    """``(model, x0, P0, streams)`` of ekf_rss_imu / ukf_rss_imu."""
    model = HeadingKinematicModel(fus.grid.dt_s, q[0], q[1], heading="yaw_rate")
    runs = rss.shape[0]
    z_imu = np.concatenate([fus.acc_m_s2, fus.gyro_rad_s[:, None]], axis=1)
    z_imu = np.broadcast_to(z_imu, (runs,) + z_imu.shape)
    z = fus.grid.on_grid(rss)
    x, P = _start(x0, P0, 8)
    x = x.copy()
    x[..., 6] = fus.heading_rad
    n = fus.samples_per_step
    R = np.diag([*(fus.noise.acc_var_m2_s4 / n), fus.noise.gyro_var_rad2_s2 / n])
    streams = [Stream(z_imu, InertialMeasurement(R, n_state=8, frame="body", name="accelerometer + gyroscope")),
               RssMeasurement(z, sc.anchors_m, sc.channel, np.array([0, 1]), mode=RSS_UPDATE,
                              tag_height_m=sc.tag_height_m)]
    return model, x, P, streams


def fit_fusion(sc, grid: InertialGrid, noise: ImuNoise, P0) -> FusionInputs:
    """The fusion trackers' settings on one track (module docstring): the heading start by maximum likelihood of
    ekf_rss_acc over the candidates (a gyroscope only), then ``q_acc`` and, with a gyroscope, ``(q, q_angular)``
    by :func:`locbook.fit_noise_ml` of ekf_rss_acc's and ekf_rss_imu's innovations on the track's readings (the
    scenario ``sc``: its measured readings and start state; ``P0`` the RSS trackers' (4, 4) start covariance)."""
    rss = np.asarray(sc.measured_rss_dbm, float)[None]
    x0 = np.asarray(sc.start_state, float)[None]
    fus = FusionInputs(grid, noise, None, Q_ACC_START, None)
    fits = {}
    heading = None

    def fit_q(heading):
        model, x, P, streams = _acc_setup(sc, fus, rss, x0, P0, Q_ACC_START, heading if heading is not None else 0.0)
        return fit_noise_ml(model.F, model.Q, x, P, streams, kind="ekf", fit_Q="scale", fit_R=None, per_run=False)

    q_acc = Q_ACC_START
    if grid.gyro_rad_s is not None:
        def best(candidates_rad):
            model, x, P, streams = _acc_setup(sc, fus, rss, x0, P0, q_acc, candidates_rad)
            ll = extended_kalman_filter(model.F, model.Q, x, P, streams, record=[0],
                                        divergence_window=0).total_log_likelihood
            return float(candidates_rad[int(np.nanargmax(ll))]), ll
        # the heading at the start value of q, then again at the q fitted there (one alternation: the likelihood's
        # heading optimum moves with q)
        for _ in range(2):
            coarse, _ll = best(np.deg2rad(np.asarray(HEADING_CANDIDATES_DEG, float)))
            heading, ll = best(coarse + np.deg2rad(np.asarray(HEADING_REFINE_DEG, float)))
            heading = float(np.angle(np.exp(1j * heading)))
            fit = fit_q(heading)
            q_acc = float(Q_ACC_START * fit.q_scale[0])
        fits["heading_log_likelihood_spread"] = float(np.nanmax(ll) - np.nanmin(ll))
    else:
        fit = fit_q(None)
    q_acc = float(Q_ACC_START * fit.q_scale[0])
    fits["acc"] = {"gain": float(fit.log_likelihood - fit.initial_log_likelihood),
                   "at_bound": bool(np.any(fit.at_bound))}
    q_imu = None
    if grid.gyro_rad_s is not None:
        fus = FusionInputs(grid, noise, heading, q_acc, (Q_IMU_START, Q_ANGULAR_START))
        model, x, P, streams = _imu_setup(sc, fus, rss, x0, P0, (Q_IMU_START, Q_ANGULAR_START))
        fit = fit_noise_ml(model.F, model.Q, x, P, streams, kind="ekf",
                           fit_Q=[[0, 1, 2, 3, 4, 5], [6, 7]], fit_R=None, per_run=False)
        q_imu = (float(Q_IMU_START * fit.q_scale[0]), float(Q_ANGULAR_START * fit.q_scale[1]))
        fits["imu"] = {"gain": float(fit.log_likelihood - fit.initial_log_likelihood),
                       "at_bound": bool(np.any(fit.at_bound))}
    return FusionInputs(grid, noise, heading, q_acc, q_imu, fits)


def run_fusion(sc, name: str, rss_dbm, x0, P0, *, ukf_alpha: float):
    """Tracker ``name`` of :data:`FUSION_TRACKERS` on readings ``(R, T, m)`` from the RSS trackers' start ``x0 (R,
    4)``, ``P0 (4, 4)`` -> ``(positions (R, T, 2) at the epochs, DivergenceFlags on the epoch clock)``."""
    fus = sc.inertial
    if fus is None:
        raise ParameterError(f"tracker {name!r} needs the track's inertial stream; the track has none")
    if name in needs_gyro and not fus.has_gyro:
        raise ParameterError(f"tracker {name!r} needs a gyroscope (gyro_z); the track's inertial file has none")
    rss = np.asarray(rss_dbm, float)
    record = fus.grid.rss_steps
    if name == "kf_acc":         # Dogan's KF (MLE): the rss_ml fixes in place of the raw RSS, one Q for both
        if sc.fix_cov_m2 is None:
            raise ParameterError("kf_acc needs the scenario's fix covariance (fix_cov_m2): the rss_ml fixes' R")
        model, x, P, streams = _acc_setup(sc, fus, rss, x0, P0, fus.q_acc,
                                          fus.heading_rad if fus.heading_rad is not None else 0.0)
        fixes = fus.grid.on_grid(ml_fixes(sc, rss))
        streams = [streams[0], LinearMeasurement(np.broadcast_to(fixes, (streams[0].z.shape[0],) + fixes.shape[1:]),
                                                 model.position_measurement_matrix(),
                                                 np.asarray(sc.fix_cov_m2, float))]
        res = extended_kalman_filter(model.F, model.Q, x, P, streams, record=record)
    elif name == "ekf_rss_acc":
        model, x, P, streams = _acc_setup(sc, fus, rss, x0, P0, fus.q_acc,
                                          fus.heading_rad if fus.heading_rad is not None else 0.0)
        res = extended_kalman_filter(model.F, model.Q, x, P, streams, record=record)
    else:
        model, x, P, streams = _imu_setup(sc, fus, rss, x0, P0, fus.q_imu)
        if name == "ekf_rss_imu":
            res = extended_kalman_filter(model.F, model.Q, x, P, streams, record=record)
        else:
            res = unscented_kalman_filter(model.F, model.Q, x, P, streams, alpha=ukf_alpha, record=record)
    flags = DivergenceFlags.of(res)
    n_sub = fus.grid.n_sub
    flags = DivergenceFlags(flags.diverged, np.where(flags.diverged, flags.diverged_step // n_sub, -1), flags.window,
                            flags.probability)
    return res.position_m([0, 1]), flags
