"""Inertial sensors for planar motion: accelerometer and gyroscope models, stationary bias calibration,
body-to-world rotation and dead reckoning (Gudipati 2017, Secs. 3.3 and 4.1).

Sensor models, as printed (Eqs. (3.4)-(3.6)), for a level sensor (gravity is on the vertical axis, so only the
residual bias of the horizontal axes remains, Sec. 3.3):

    accelerometer:  acc_t = a_t - b_a + v_a,   v_a ~ N(0, sigma_a^2)     (body frame, per axis)
    gyroscope:      y_t = omega_t - b_g + v_g, v_g ~ N(0, sigma_g^2)

Calibration (Sec. 3.3): average samples taken while the node is stationary; during operation subtract that
mean (it estimates ``-b``). The thesis never rotates body-frame readings by the heading (Secs. 3.3,
4.1); locbook rotates by default (``frame="body"``) and keeps the literal reading (``frame="world"``: the readings
are taken as world-frame accelerations) as a flagged option.

Dead reckoning (Sec. 4.1): integrate acceleration to velocity and velocity to position (trapezoid rule by
default), heading from the integrated yaw rate.
"""
from __future__ import annotations

import numpy as np

from .._linalg import _covariance
from .._validate import as_array, check_choice, check_scalar
from .base import MeasurementModel, with_covariance

__all__ = ["InertialMeasurement", "IMU_FRAMES", "INTEGRATION_RULES", "rotation_2d", "world_to_body", "body_to_world",
           "accelerometer_readings", "gyroscope_readings", "stationary_bias", "integrate", "dead_reckon",
           "inertial_measurement_function", "inertial_measurement_jacobian"]

IMU_FRAMES = ("body", "world")
#: locbook's assumption of a MEMS IMU's white noise per sample (about 50 Hz), where nothing measured gives it: the
#: accelerometer's sd (m/s^2) and the gyroscope's (0.2 deg/s, in rad/s); Gudipati 2017 prints neither, so its
#: simulation assumes these too (locbook.scenarios.gudipati.WalkSettings)
MEMS_ACCEL_SIGMA_M_S2 = 0.05
MEMS_GYRO_SIGMA_RAD_S = float(np.deg2rad(0.2))
INTEGRATION_RULES = ("trapezoid", "euler")


def rotation_2d(heading_rad):
    """Rotation matrices ``(..., 2, 2)`` from body to world for headings ``(...)`` (rad, counter-clockwise from x)."""
    c, s = np.cos(heading_rad), np.sin(heading_rad)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


def world_to_body(vector_world, heading_rad):
    """``R(psi)^T v`` for vectors ``(..., 2)`` and headings ``(...)``."""
    return np.einsum("...ji,...j->...i", rotation_2d(heading_rad), vector_world)


def body_to_world(vector_body, heading_rad):
    """``R(psi) v`` for vectors ``(..., 2)`` and headings ``(...)``."""
    return np.einsum("...ij,...j->...i", rotation_2d(heading_rad), vector_body)


def _rng(rng):
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    return rng


def accelerometer_readings(acc_world_m_s2, heading_rad, *, bias_m_s2, sigma_m_s2: float, rng: np.random.Generator,
                           frame: str = "body"):
    """Accelerometer samples ``(..., T, 2)``, Eq. (3.4): ``acc = a - b_a + v_a`` with the true acceleration ``a``
    expressed in the body frame (``frame="body"``, rotated by the true heading ``(..., T)``) or taken as the
    world-frame acceleration (``frame="world"``, the thesis's literal reading). ``bias_m_s2``: ``(2,)`` or
    broadcastable to ``(..., 1, 2)`` (one constant bias per run)."""
    check_choice("frame", frame, IMU_FRAMES)
    check_scalar("sigma_m_s2", sigma_m_s2, ge=0)
    acc = as_array("acc_world_m_s2", acc_world_m_s2, min_ndim=2, trailing=(None, 2))
    a = world_to_body(acc, as_array("heading_rad", heading_rad)) if frame == "body" else acc
    bias = as_array("bias_m_s2", bias_m_s2)
    return a - bias + sigma_m_s2 * _rng(rng).standard_normal(np.broadcast_shapes(a.shape, bias.shape))


def gyroscope_readings(yaw_rate_rad_s, *, bias_rad_s, sigma_rad_s: float, rng: np.random.Generator):
    """Gyroscope samples ``(..., T)``, Eqs. (3.5)-(3.6): ``y = omega - b_g + v_g``. ``bias_rad_s``: a scalar or
    broadcastable to ``(..., 1)``."""
    check_scalar("sigma_rad_s", sigma_rad_s, ge=0)
    rate = as_array("yaw_rate_rad_s", yaw_rate_rad_s, min_ndim=1)
    bias = as_array("bias_rad_s", bias_rad_s)
    return rate - bias + sigma_rad_s * _rng(rng).standard_normal(np.broadcast_shapes(rate.shape, bias.shape))


def stationary_bias(stationary_readings, axis: int = -2):
    """The calibration of Sec. 3.3: the mean of readings taken at rest along ``axis`` (time), kept as an axis of
    length 1 so that ``readings - stationary_bias(rest)`` removes it. It estimates ``-b`` in the sign of
    Eqs. (3.4)-(3.5); its error is the sensor noise over ``sqrt(samples)``."""
    r = as_array("stationary_readings", stationary_readings, min_ndim=1)
    if r.shape[axis] < 1:
        raise ValueError("stationary_bias needs at least one reading at rest")
    return r.mean(axis=axis, keepdims=True)


def integrate(rate, dt_s: float, initial=0.0, *, rule: str = "trapezoid", axis: int = -1):
    """Cumulative integral of samples ``rate`` along ``axis`` (same length; the first entry is ``initial``):
    trapezoid rule or forward Euler (``x_k = x_{k-1} + dt r_{k-1}``)."""
    check_scalar("dt_s", dt_s, gt=0)
    check_choice("rule", rule, INTEGRATION_RULES)
    r = np.moveaxis(as_array("rate", rate, min_ndim=1), axis, -1)
    steps = 0.5 * (r[..., 1:] + r[..., :-1]) if rule == "trapezoid" else r[..., :-1]
    out = np.concatenate([np.zeros(r.shape[:-1] + (1,)), np.cumsum(steps * dt_s, axis=-1)], axis=-1)
    out = out + np.asarray(initial, dtype=float)[..., None]
    return np.moveaxis(out, -1, axis)


def dead_reckon(acc_world_m_s2, dt_s: float, *, velocity0_m_s=(0.0, 0.0), position0_m=(0.0, 0.0),
                rule: str = "trapezoid"):
    """Inertial navigation by double integration (Sec. 4.1): world-frame accelerations ``(..., T, 2)`` ->
    velocities and positions ``(..., T, 2)`` starting from ``velocity0_m_s`` and ``position0_m`` ``(..., 2)``.
    Any acceleration error ``e`` grows into a position error of about ``e t^2 / 2``."""
    acc = as_array("acc_world_m_s2", acc_world_m_s2, min_ndim=2, trailing=(None, 2))
    v0 = as_array("velocity0_m_s", velocity0_m_s, trailing=(2,))
    p0 = as_array("position0_m", position0_m, trailing=(2,))
    velocity = integrate(acc, dt_s, v0, rule=rule, axis=-2)
    position = integrate(velocity, dt_s, p0, rule=rule, axis=-2)
    return velocity, position


def inertial_measurement_function(frame: str = "body", *, acceleration_index=(4, 5), heading_index: int = 6,
                                  yaw_rate_index: int = 7):
    """``h(x)`` of the inertial measurement ``z = [acc_1, acc_2, gyro]`` for a state with world-frame
    acceleration, heading and yaw rate (:class:`locbook.HeadingKinematicModel`): the body-frame acceleration
    ``R(psi)^T a`` (``frame="body"``) or ``a`` itself (``"world"``), and the yaw rate. Works over any leading axes
    (EKF states or UKF sigma points). The stationary-calibrated readings are the measurement (bias removed)."""
    check_choice("frame", frame, IMU_FRAMES)
    ia = np.asarray(acceleration_index)

    def h(x):
        a = x[..., ia]
        acc = world_to_body(a, x[..., heading_index]) if frame == "body" else a
        return np.concatenate([acc, x[..., yaw_rate_index:yaw_rate_index + 1]], axis=-1)
    return h


def inertial_measurement_jacobian(n_state: int = 8, frame: str = "body", *, acceleration_index=(4, 5),
                                  heading_index: int = 6, yaw_rate_index: int = 7):
    """The Jacobian ``(..., 3, n_state)`` of :func:`inertial_measurement_function` (for the EKF)."""
    check_choice("frame", frame, IMU_FRAMES)
    ia = np.asarray(acceleration_index)

    def jacobian(x):
        H = np.zeros(x.shape[:-1] + (3, n_state))
        psi = x[..., heading_index]
        c, s = np.cos(psi), np.sin(psi)
        if frame == "body":
            ax, ay = x[..., ia[0]], x[..., ia[1]]
            # [c s; -s c] a: rows d/da and d/dpsi
            H[..., 0, ia[0]], H[..., 0, ia[1]] = c, s
            H[..., 1, ia[0]], H[..., 1, ia[1]] = -s, c
            H[..., 0, heading_index] = -s * ax + c * ay
            H[..., 1, heading_index] = -c * ax - s * ay
        else:
            H[..., 0, ia[0]] = H[..., 1, ia[1]] = 1.0
        H[..., 2, yaw_rate_index] = 1.0
        return H
    return jacobian


class InertialMeasurement(MeasurementModel):
    """The inertial measurement model ``z = [acc_1, acc_2, gyro] + v``, ``v ~ N(0, R)``, on the measurement-model
    protocol (:mod:`locbook.models.base`): :func:`inertial_measurement_function` and its Jacobian
    :func:`inertial_measurement_jacobian` for a state of ``n_state`` components with world-frame acceleration,
    heading and yaw rate at the given indices (Gudipati 2017, Eqs. (3.9), (3.11)); ``R`` ``(3, 3)`` or with run axes
    ``batch + (3, 3)``. The compiled EKF and UKF evaluate the same function in their kernels
    (:mod:`locbook.tracking._compiled`)."""

    checks_own_output = True

    def __init__(self, R, *, n_state: int = 8, frame: str = "body", acceleration_index=(4, 5), heading_index: int = 6,
                 yaw_rate_index: int = 7, name: str = "inertial"):
        check_choice("frame", frame, IMU_FRAMES)
        self.name, self.frame, self.n_state = name, frame, int(n_state)
        self.acceleration_index = tuple(int(i) for i in np.asarray(acceleration_index).reshape(-1))
        self.heading_index, self.yaw_rate_index = int(heading_index), int(yaw_rate_index)
        if len(self.acceleration_index) != 2:
            raise ValueError(f"{name}: acceleration_index must hold two state indices, got {acceleration_index!r}")
        index = self.acceleration_index + (self.heading_index, self.yaw_rate_index)
        if min(index) < -self.n_state or max(index) >= self.n_state:
            raise ValueError(f"{name}: the state indices {index} are outside the {self.n_state}-state")
        self._given_R = R
        self.R = _covariance(f"{name}: R", R, 3)
        self._h = inertial_measurement_function(frame, acceleration_index=self.acceleration_index,
                                                heading_index=self.heading_index, yaw_rate_index=self.yaw_rate_index)
        self._jacobian = inertial_measurement_jacobian(self.n_state, frame, acceleration_index=self.acceleration_index,
                                                       heading_index=self.heading_index,
                                                       yaw_rate_index=self.yaw_rate_index)

    @property
    def n_readings(self) -> int:
        return 3

    def mean(self, x, *, step: int = 0):
        return self._h(x)

    def jacobian(self, x, *, step: int = 0):
        return self._jacobian(x)

    def covariance(self, x, *, step: int = 0):
        return self.R if self.R.ndim == 2 else self.R[..., None, :, :]

    def innovation(self, x, z, *, step: int = 0):
        valid = np.isfinite(z)
        h = self._h(x)
        return np.where(valid, z, h) - h, self._jacobian(x), self.R

    def independent_readings(self) -> bool:
        return not np.any(self.R - self.R * np.eye(3))

    def noise(self):
        return "covariance", self.R

    def with_noise(self, value) -> "InertialMeasurement":
        return with_covariance(self, value)

    def listed_matrices(self) -> list:
        return [(f"{self.name}.R", self._given_R, False)]

    def run_shapes(self) -> list:
        return [(f"{self.name}.R", self.R.shape[:-2])]

    def check_readings(self, z, n_state: int | None) -> None:
        super().check_readings(z, n_state)
        if n_state is not None and n_state != self.n_state:
            raise ValueError(f"{self.name}: the model is for a {self.n_state}-state, the filter's state has {n_state}")
