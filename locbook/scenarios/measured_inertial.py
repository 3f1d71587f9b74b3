"""The measured-data protocol's inertial part: a track's inertial stream on its sub-step grid and the fusion
trackers' settings from the data (:mod:`locbook.inertial_trackers`), for :func:`locbook.scenarios.measured.protocol`
and :func:`~locbook.scenarios.measured.tracking_results`. A data set without inertial files gets nothing from here:
no setting, no row, no number changes."""
from __future__ import annotations

import numpy as np

from ..data.dataset import Dataset
from ..data.inertial import MAX_SUB_STEPS, align
from ..inertial_trackers import (
    FUSION_TRACKERS,
    HEADING_CANDIDATES_DEG,
    HEADING_REFINE_DEG,
    HEADING_START_SD_RAD,
    NO_GYRO_FRAME,
    Q_ACC_START,
    Q_ANGULAR_START,
    Q_IMU_START,
    START_ACCELERATION_SD_M_S2,
    FusionInputs,
    ImuNoise,
    fit_fusion,
    stationary_noise,
)
from ..models.channel import PathLossModel
from .measured_setup import tracker_settings, tracking_scenario

__all__ = ["inertial_tracks", "imu_noise", "inertial_grid", "fusion_inputs", "fusion_choices", "fusion_knobs"]


def inertial_tracks(data: Dataset) -> list[str]:
    """The track recordings with an inertial stream, in manifest order."""
    return [n for n in data.recordings_with("track") if data.recording(n).inertial is not None]


def imu_noise(data: Dataset) -> ImuNoise:
    """The inertial sensors' calibration of the data set (cached): the stationary calibration on the calibration
    recordings' inertial samples (:func:`locbook.inertial_trackers.stationary_noise`), else the stated defaults.
    The gyroscope's part where some track has a gyroscope."""
    key = ("inertial", "noise")
    if key not in data._cache:
        with_gyro = any(data.recording(n).inertial.gyro_rad_s is not None for n in inertial_tracks(data))
        pairs = [(data.recording(n).readings, data.recording(n).inertial) for n in data.recordings_with("calibration")
                 if data.recording(n).inertial is not None
                 and (not with_gyro or data.recording(n).inertial.gyro_rad_s is not None)]
        data._cache[key] = stationary_noise(pairs, with_gyro=with_gyro)
    return data._cache[key]


def inertial_grid(data: Dataset, recording: str, time_s, dt_s: float):
    """The recording's inertial samples on the sub-step grid of its epoch clock (``time_s``, ``dt_s``: the tracking
    scenario's; :func:`locbook.data.inertial.align`), cached by ``("inertial", recording)``."""
    key = ("inertial", recording, float(dt_s), float(time_s[0]), len(time_s))
    if key not in data._cache:
        data._cache[key] = align(data.recording(recording).inertial, time_s, dt_s)
    return data._cache[key]


def fusion_inputs(data: Dataset, model: PathLossModel, recording: str, *, grid_spacing_m: float, fix_cov_m2,
                  q: float) -> FusionInputs | None:
    """The fusion trackers' inputs and settings on one track with an inertial stream
    (:func:`locbook.inertial_trackers.fit_fusion`: heading start and q by maximum likelihood, the calibration of
    :func:`imu_noise`), from the RSS trackers' start and its covariance (``q``: the RSS trackers', for their P_0).
    None when no accelerometer sample falls within the track's epochs (the files do not overlap in time: no fusion)."""
    sc = tracking_scenario(data, model, recording, grid_spacing_m=grid_spacing_m, q=q, spread_m=1.0)
    grid = inertial_grid(data, recording, sc.time_s, sc.dt_s)
    if not grid.counts.any():
        return None
    return fit_fusion(sc, grid, imu_noise(data), tracker_settings(q, 1, 1.0, fix_cov_m2).P0)


def fusion_choices(name: str, fus: FusionInputs | None, *, first: bool = True) -> list[dict]:
    """The settings table's rows of the fusion trackers on track ``name``: each setting, its value and its rule (the
    sensors' calibration, the data set's, with the ``first`` track only); ``fus`` None: one row saying why none ran."""
    if fus is None:
        return [{"method": ", ".join(FUSION_TRACKERS), "setting": f"inertial stream, {name}", "value": "not run",
                 "how": "no accelerometer sample falls within the track's epochs (the inertial file's times do not "
                        "overlap the readings': another time unit or origin?)"}]
    g, noise = fus.grid, fus.noise
    acc_sd = np.sqrt(noise.acc_var_m2_s4)
    rows = [{"method": ", ".join(fus.trackers), "setting": f"sub-step grid, {name}",
             "value": f"{g.n_sub} sub-steps of {g.dt_s:.4g} s per epoch; {fus.samples_per_step:g} samples per sub-step",
             "how": f"rule: the IMU's median interval, at most {MAX_SUB_STEPS} sub-steps per epoch "
                    "(locbook.data.inertial.sub_steps; Dogan 2015: RSS at every 10th accelerometer step)"},
            *([{"method": ", ".join(fus.trackers), "setting": "accelerometer bias, sd per sample (m/s^2)",
                "value": f"bias ({noise.acc_bias_m_s2[0]:.4g}, {noise.acc_bias_m_s2[1]:.4g}), sd ({acc_sd[0]:.4g}, "
                         f"{acc_sd[1]:.4g})", "how": noise.source}] if first else [])]
    if fus.has_gyro and first:
        rows.append({"method": ", ".join(fus.trackers), "setting": "gyroscope bias, sd per sample (rad/s)",
                     "value": f"bias {noise.gyro_bias_rad_s:.4g}, sd {np.sqrt(noise.gyro_var_rad2_s2):.4g}",
                     "how": noise.source})
    if fus.has_gyro:
        rows.append({"method": ", ".join(fus.trackers), "setting": f"initial heading (deg), {name}",
                     "value": f"{np.rad2deg(fus.heading_rad):.1f}",
                     "how": f"rule: maximum likelihood of ekf_rss_acc's innovations over headings every "
                            f"{HEADING_CANDIDATES_DEG[1] - HEADING_CANDIDATES_DEG[0]} deg, then every "
                            f"{HEADING_REFINE_DEG[1] - HEADING_REFINE_DEG[0]} deg around the best (no truth); the "
                            "8-state "
                            f"filters start there with sd {np.rad2deg(HEADING_START_SD_RAD):g} deg"})
    else:
        rows.append({"method": "kf_acc, ekf_rss_acc", "setting": f"accelerometer frame, {name}",
                     "value": f"{NO_GYRO_FRAME}: the readings taken as world-frame accelerations",
                     "how": "assumed: no gyroscope, so no heading to rotate body-frame readings by "
                            "(locbook.inertial_trackers.NO_GYRO_FRAME); wrong for a tag that turns"})
    acc = fus.fits.get("acc", {})
    rows.append({"method": "kf_acc, ekf_rss_acc",
                 "setting": f"q (Q = q I per sub-step, Dogan's Eq. (3.24) form), {name}",
                 "value": f"{fus.q_acc:.3g}",
                 "how": f"rule: maximum likelihood of the fusion EKF's innovations on this track's readings "
                        f"(log-likelihood +{acc.get('gain', 0.0):.1f} over q = {Q_ACC_START:g}"
                        f"{'; at the fit bound' if acc.get('at_bound') else ''}); start at rest, acceleration sd "
                        f"{START_ACCELERATION_SD_M_S2:g} m/s^2; kf_acc takes ekf_rss_acc's (Dogan: one Q for every "
                        "filter)"})
    if fus.q_imu is not None:
        imu = fus.fits.get("imu", {})
        rows.append({"method": "ekf_rss_imu, ukf_rss_imu", "setting": f"q, q_angular (per sub-step), {name}",
                     "value": f"{fus.q_imu[0]:.3g} (m/s^2)^2, {fus.q_imu[1]:.3g} (rad/s)^2",
                     "how": f"rule: maximum likelihood of ekf_rss_imu's innovations, the translational and the "
                            f"angular blocks of Q (log-likelihood +{imu.get('gain', 0.0):.1f} over q = "
                            f"{Q_IMU_START:g}, "
                            f"q_angular = {Q_ANGULAR_START:g}{'; at the fit bound' if imu.get('at_bound') else ''}); "
                            "the UKF takes the EKF's"})
    return rows


def fusion_knobs(fus: FusionInputs, ukf_alpha: float) -> dict:
    """Each fusion tracker's settings in one line (the results rows' ``settings``)."""
    g = fus.grid
    grid = f"{g.n_sub} x {g.dt_s:.3g} s sub-steps per epoch"
    frame = (f"heading start {np.rad2deg(fus.heading_rad):.0f} deg (ML) + gyroscope" if fus.has_gyro
             else f"readings as {NO_GYRO_FRAME}-frame (no gyroscope)")
    out = {"ekf_rss_acc": f"Q = q I, q = {fus.q_acc:.3g} per sub-step (fitted), {grid}, {frame}; start: first "
                          "rss_ml fix at rest"}
    out["kf_acc"] = out["ekf_rss_acc"] + "; R: rss_ml fix errors on the calibration epochs"
    if fus.q_imu is not None:
        common = (f"q = {fus.q_imu[0]:.3g}, q_angular = {fus.q_imu[1]:.3g} per sub-step (fitted), {grid}, heading "
                  "start "
                  f"{np.rad2deg(fus.heading_rad):.0f} deg (ML); start: first rss_ml fix at rest")
        out["ekf_rss_imu"] = common
        out["ukf_rss_imu"] = common + f"; alpha = {ukf_alpha:g}"
    return {k: v for k, v in out.items() if k in FUSION_TRACKERS}
