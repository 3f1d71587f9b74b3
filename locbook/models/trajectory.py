"""Ground-truth trajectories: one :class:`Trajectory` (position, velocity and acceleration sampled in time, one path
or one per Monte-Carlo run) and two ways to make one along a waypoint path.

- :func:`waypoint_trajectory`: straight legs joined by circular arcs, travelled with a trapezoidal speed profile
  (start and stop at rest). Gives every quantity the inertial sensors see: position, velocity, acceleration
  (tangential plus centripetal), heading and yaw rate, in closed form at every sample, so simulated accelerometer
  and gyroscope readings are exact derivatives of the path. Used where a source names a path but never prints it
  (Gudipati 2017's "linear path" and "U-path", Sec. 5.3): the waypoints, turn radius, speed and acceleration
  are then named, documented parameters.
- :func:`polyline_trajectory`: sharp corners walked at constant speed (optionally after a uniform ramp from rest),
  the velocity turning within one step, so the acceleration is the backward difference of the velocity (Dogan 2015's
  walk of Fig. 3.1, whose coordinates are not printed).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .._validate import as_array, check_scalar
from ..errors import ParameterError

__all__ = ["Trajectory", "waypoint_trajectory", "polyline_trajectory", "POLYLINE_STARTS"]

#: How a :func:`polyline_trajectory` starts: ``"rest"`` (a uniform ramp to the speed) or ``"moving"`` (at speed).
POLYLINE_STARTS = ("rest", "moving")


@dataclass(frozen=True)
class Trajectory:
    """True motion at the samples ``time_s`` ``(T,)``: ``position_m``, ``velocity_m_s``, ``acceleration_m_s2``
    ``(..., T, 2)`` in the world frame (a leading axis: one trajectory per Monte-Carlo run).

    Optional, where the maker knows them: ``heading_rad``, ``yaw_rate_rad_s`` ``(T,)`` (heading of the direction of
    travel, unwrapped), the travelled ``arc_length_m`` ``(T,)``; ``rss_steps``, the sample indices at which RSS is
    read when it is read on a slower grid than the motion is sampled; ``waypoints_m`` and ``start`` (how it began,
    e.g. ``"rest"``), as made.
    """

    time_s: np.ndarray
    position_m: np.ndarray
    velocity_m_s: np.ndarray
    acceleration_m_s2: np.ndarray
    heading_rad: np.ndarray | None = None
    yaw_rate_rad_s: np.ndarray | None = None
    arc_length_m: np.ndarray | None = None
    rss_steps: np.ndarray | None = None
    waypoints_m: tuple = ()
    start: str = ""

    @property
    def length_m(self) -> float:
        return float(self._arc_length()[-1])

    def _arc_length(self) -> np.ndarray:
        if self.arc_length_m is None:
            raise ParameterError("this trajectory has no arc_length_m "
                                 "(its maker did not record the travelled distance)")
        return self.arc_length_m

    def indices_every(self, spacing_m: float) -> np.ndarray:
        """Sample indices at the first sample reaching each multiple of ``spacing_m`` of travelled distance (0
        included), e.g. the thesis's report "every 1 m"."""
        check_scalar("spacing_m", spacing_m, gt=0)
        arc = self._arc_length()
        marks = np.arange(0.0, self.length_m + 1e-9, spacing_m)
        return np.unique(np.minimum(np.searchsorted(arc, marks - 1e-9), arc.size - 1))

    def states(self, model) -> np.ndarray:
        """States ``(..., T, n_state)`` in the layout of the kinematic ``model`` (a
        :class:`~locbook.models.motion.KinematicModel`): position, velocity and, for order 2, acceleration."""
        return model.state_from(self.position_m, self.velocity_m_s,
                                self.acceleration_m_s2 if model.order >= 2 else None)

    def head(self, n_steps: int) -> "Trajectory":
        """The first ``n_steps`` samples (and the RSS steps among them)."""
        n = int(check_scalar("n_steps", n_steps, gt=0))
        cut: dict[str, Any] = {name: None if getattr(self, name) is None else getattr(self, name)[..., :n]
               for name in ("time_s", "heading_rad", "yaw_rate_rad_s", "arc_length_m")}
        motion: dict[str, Any] = {name: getattr(self, name)[..., :n, :]
                                  for name in ("position_m", "velocity_m_s", "acceleration_m_s2")}
        rss = None if self.rss_steps is None else self.rss_steps[self.rss_steps < n]
        return replace(self, **cut, **motion, rss_steps=rss)


def _pieces(waypoints, radius):
    """Lines and arcs: ('line', start, unit, length) and ('arc', centre, r, angle0, sweep)."""
    d = np.diff(waypoints, axis=0)
    lengths = np.linalg.norm(d, axis=1)
    if np.any(lengths <= 0):
        raise ValueError("consecutive waypoints must differ")
    u = d / lengths[:, None]
    cut = np.zeros(len(waypoints))                      # tangent length cut at each interior waypoint
    turns = []
    for i in range(1, len(waypoints) - 1):
        cross = u[i - 1, 0] * u[i, 1] - u[i - 1, 1] * u[i, 0]
        angle = np.arctan2(cross, np.dot(u[i - 1], u[i]))
        if abs(abs(angle) - np.pi) < 1e-9:
            raise ValueError(f"the path reverses at waypoint {i}; a turn needs an angle below 180 degrees")
        cut[i] = radius * np.tan(abs(angle) / 2)
        turns.append(angle)
    for i in range(len(lengths)):
        if cut[i] + cut[i + 1] > lengths[i] + 1e-9:
            raise ValueError(f"turn_radius_m = {radius} is too large for leg {i} ({lengths[i]:.3g} m long): the "
                             "arcs at its ends would overlap")
    pieces = []
    for i in range(len(lengths)):
        start = waypoints[i] + cut[i] * u[i]
        pieces.append(("line", start, u[i], lengths[i] - cut[i] - cut[i + 1]))
        if i < len(turns):
            angle = turns[i]
            if angle == 0 or radius == 0:
                continue
            sign = np.sign(angle)
            normal = sign * np.array([-u[i, 1], u[i, 0]])
            tangent_point = waypoints[i + 1] - cut[i + 1] * u[i]
            centre = tangent_point + radius * normal
            a0 = np.arctan2(*(tangent_point - centre)[::-1])
            pieces.append(("arc", centre, radius, a0, angle))
    return pieces


def _speed_profile(t, length, speed, accel):
    """Arc length, speed and tangential acceleration at times ``t`` for a trapezoidal (or triangular) profile."""
    t_ramp = speed / accel
    if accel * t_ramp**2 > length:                      # triangle: never reaches the cruise speed
        t_ramp = np.sqrt(length / accel)
        speed = accel * t_ramp
        t_cruise = 0.0
    else:
        t_cruise = (length - accel * t_ramp**2) / speed
    total = 2 * t_ramp + t_cruise
    t = np.clip(t, 0.0, total)
    up, cruise = t < t_ramp, t < t_ramp + t_cruise
    td = t - t_ramp - t_cruise
    s = np.where(up, 0.5 * accel * t**2,
                 np.where(cruise, 0.5 * accel * t_ramp**2 + speed * (t - t_ramp),
                          0.5 * accel * t_ramp**2 + speed * t_cruise + speed * td - 0.5 * accel * td**2))
    v = np.where(up, accel * t, np.where(cruise, speed, speed - accel * td))
    a = np.where(up, accel, np.where(cruise, 0.0, -accel))
    a = np.where(t >= total, 0.0, a)
    return s, np.maximum(v, 0.0), a, total


def waypoint_trajectory(waypoints_m, *, speed_m_s: float, accel_m_s2: float, dt_s: float,
                        turn_radius_m: float = 0.0) -> Trajectory:
    """Travel the polyline ``waypoints_m`` ``(K, 2)`` from rest to rest: corners rounded by arcs of
    ``turn_radius_m`` (0: sharp corners, only for straight paths, since a sharp turn needs infinite yaw rate),
    speed rising at ``accel_m_s2`` to ``speed_m_s`` and falling at the end, sampled every ``dt_s`` from 0 to the
    stop (the last sample is the stop)."""
    wp = as_array("waypoints_m", waypoints_m, ndim=2, trailing=(2,))
    if wp.shape[0] < 2:
        raise ValueError("a path needs at least two waypoints")
    speed = check_scalar("speed_m_s", speed_m_s, gt=0)
    accel = check_scalar("accel_m_s2", accel_m_s2, gt=0)
    dt = check_scalar("dt_s", dt_s, gt=0)
    radius = check_scalar("turn_radius_m", turn_radius_m, ge=0)
    pieces = _pieces(wp, radius)
    if radius == 0 and wp.shape[0] > 2:
        d = np.diff(wp, axis=0)
        cross = d[:-1, 0] * d[1:, 1] - d[:-1, 1] * d[1:, 0]
        if np.any(np.abs(cross) > 1e-12):
            raise ValueError("a path with turns needs turn_radius_m > 0 (a sharp corner has no finite yaw rate)")
    lengths = np.array([p[3] if p[0] == "line" else p[2] * abs(p[4]) for p in pieces])
    bounds = np.concatenate([[0.0], np.cumsum(lengths)])
    total_length = bounds[-1]
    _, _, _, total_time = _speed_profile(np.array([0.0]), total_length, speed, accel)
    n = int(np.floor(total_time / dt + 1e-9)) + 1
    t = np.arange(n) * dt
    if t[-1] < total_time - 1e-9:
        t = np.append(t, total_time)
    s, v, a_t, _ = _speed_profile(t, total_length, speed, accel)
    which = np.clip(np.searchsorted(bounds, s, side="right") - 1, 0, len(pieces) - 1)
    pos, tangent, curvature = np.empty((t.size, 2)), np.empty((t.size, 2)), np.zeros(t.size)
    for j, piece in enumerate(pieces):
        sel = which == j
        ds = s[sel] - bounds[j]
        if piece[0] == "line":
            _, start, u, _ = piece
            pos[sel] = start + ds[:, None] * u
            tangent[sel] = u
        else:
            _, centre, r, a0, sweep = piece
            sign = np.sign(sweep)
            ang = a0 + sign * ds / r
            pos[sel] = centre + r * np.stack([np.cos(ang), np.sin(ang)], -1)
            tangent[sel] = sign * np.stack([-np.sin(ang), np.cos(ang)], -1)
            curvature[sel] = sign / r
    normal = np.stack([-tangent[:, 1], tangent[:, 0]], -1)
    velocity = v[:, None] * tangent
    acceleration = a_t[:, None] * tangent + (v**2 * curvature)[:, None] * normal
    heading = np.unwrap(np.arctan2(tangent[:, 1], tangent[:, 0]))
    return Trajectory(t, pos, velocity, acceleration, heading, v * curvature, s,
                      waypoints_m=tuple(map(tuple, wp.tolist())), start="rest")


def polyline_trajectory(waypoints_m, *, speed_m_s: float, dt_s: float, start: str = "moving", ramp_s: float = 2.0,
                        rss_every: int = 1) -> Trajectory:
    """Walk the polyline ``waypoints_m`` ``(K, 2)`` at constant speed ``speed_m_s``, sampled every ``dt_s`` (Dogan
    2015, Fig. 3.1, path not printed), RSS read every ``rss_every``-th sample.

    ``start="rest"``: the speed ramps up uniformly over ``ramp_s``; ``"moving"``: at speed from t = 0. The walk lasts
    ``length / speed + ramp_s / 2`` (rounded to whole samples) and does not stop at the end. The velocity turns
    within one step at each corner, so the true acceleration (what a bias-free, perfectly oriented accelerometer
    reads, Dogan Eq. (3.17)) is the backward difference ``(v_k - v_{k-1}) / dt``: zero on the straight segments and
    an impulse at the turns (and during the ramp). No yaw rate: a sharp corner has none that is finite.
    """
    if start not in POLYLINE_STARTS:
        raise ParameterError(f"start must be one of {POLYLINE_STARTS}, got {start!r}")
    if speed_m_s <= 0 or dt_s <= 0 or rss_every < 1:
        raise ParameterError("speed_m_s and dt_s must be positive and rss_every at least 1")
    pts = np.asarray(waypoints_m, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2:
        raise ParameterError(f"waypoints_m must be at least two (x, y) points, got shape {pts.shape}")
    seg = np.diff(pts, axis=0)
    seg_len = np.linalg.norm(seg, axis=1)
    if np.any(seg_len == 0):
        raise ParameterError("waypoints_m has repeated consecutive points")
    length = seg_len.sum()
    ramp = ramp_s if start == "rest" else 0.0
    accel = speed_m_s / ramp if ramp > 0 else 0.0
    duration = length / speed_m_s + 0.5 * ramp
    n = int(round(duration / dt_s))
    t = np.arange(n) * dt_s
    # arc length and speed as functions of time
    s = np.where(t < ramp, 0.5 * accel * t**2, 0.5 * accel * ramp**2 + speed_m_s * (t - ramp))
    speed = np.where(t < ramp, accel * t, speed_m_s)
    cum = np.concatenate([[0.0], np.cumsum(seg_len)])
    i = np.clip(np.searchsorted(cum, s, side="right") - 1, 0, len(seg) - 1)
    direction = seg[i] / seg_len[i, None]
    pos = pts[i] + direction * (s - cum[i])[:, None]
    vel = direction * speed[:, None]
    acc = np.zeros_like(vel)
    acc[1:] = np.diff(vel, axis=0) / dt_s
    heading = np.unwrap(np.arctan2(direction[:, 1], direction[:, 0]))
    return Trajectory(t, pos, vel, acc, heading_rad=heading, arc_length_m=s, rss_steps=np.arange(0, n, rss_every),
                      waypoints_m=tuple(map(tuple, pts.tolist())), start=start)
