"""A synthetic data set in the form a real one arrives in: raw packets in the long format with a manifest.

:func:`write_example_dataset` writes a folder that ``locbook data check`` and ``locbook run --data`` read like any
measured data set (docs/data-format.md), with the faults real data bring: packets not heard (absent
rows, and a few rows with an empty reading), an invalid-reading sentinel (0 dBm), a point id column, and a track
logged with some timestamps out of order. Its truth is known exactly, so the battery's estimates can be checked
against it. ``locbook data example DIR`` calls it.

The site (every value a named constant): a 20 m x 12 m hall, 8 anchors 2.5-3.0 m high, a tag at 1.2 m, a
log-distance channel per anchor (``P_0`` -45 +- 3 dBm, ``n`` 2.0-2.6, i.i.d. shadowing 4 dB per packet), packets
below -95 dBm lost and 10 % of the others dropped at random. Recordings: a calibration survey on a 2 m grid (5 s at
each point), 12 static test points (10 s each), and two walks around the hall at 1 m/s.

Variants (keyword options of :func:`write_example_dataset`; the defaults write the set above): the walkers' speed
(``speed_m_s``), which recordings are written (``roles``: a static-only, a track-only or a calibration-only set),
a 2-D site (``two_d``: anchors without z, distances in the plane, no tag height) and tracks logged as native scans
(``native_scans``: one row per anchor per scan, every anchor of a scan at one time, 1 Hz, ``window_s = 0``).

``inertial=True`` adds an inertial file per recording (``<recording>_imu.csv``, manifest key ``inertial``;
:mod:`locbook.data.inertial`): a 50 Hz accelerometer and gyroscope in the tag's body frame (x forward = the walking
direction, y left), reading ``true + bias + noise`` with white noise N(0, 0.05 m/s^2) per axis and N(0, 0.005
rad/s), and a constant bias (0.03, -0.02) m/s^2 and 0.002 rad/s (``EXAMPLE_SITE["imu"]``), drawn from a generator
seeded from ``rng`` after every other draw (so the other files' draws are those of the same variant without it).
The walks then go round rectangles with corners rounded to ``EXAMPLE_SITE["imu"]["corner_radius_m"]`` (2 m) at a
constant speed, so the true acceleration is finite: zero on the straights, ``v^2 / r`` to the left on the arcs
(a step at each arc's ends, not an impulse), and the yaw rate ``v / r`` there; the walks' positions, and so their
readings, differ from the sharp-cornered default's (a variant of its own). The survey and the static points are
stationary while the tag dwells at a point (true acceleration and rate 0); their files hold samples only during
the dwells (the 2 s between points are gaps, which the loader counts).

A building (``floors=2``): the same hall on each floor (``F1``, ``F2``, ...; :data:`FLOOR_HEIGHT_M` apart), 8
anchors per floor at that floor's heights (``A1``-``A8`` on F1, ``B1``-``B8`` on F2), a ``floor`` column in the
anchors and the readings (the tag's floor on every row, its true height in ``z_m``). Every anchor of every floor
hears the tag, :data:`FLOOR_ATTENUATION_DB` weaker per floor between them (the cross-floor readings a floor's
battery ignores). The survey and the static points visit every floor in turn (recordings spanning floors, split by
the loader); ``walk_a`` walks F1 and ``walk_b`` the top floor. ``floor_plan=True`` adds ``plan.png``, a plan of the
hall drawn by matplotlib (walls as lines over a floor tint), with its extent in the manifest.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

__all__ = ["write_example_dataset", "EXAMPLE_SITE", "EXAMPLE_ROLES", "FLOOR_ATTENUATION_DB", "FLOOR_HEIGHT_M",
           "MAX_EXAMPLE_FLOORS", "PLAN_MARGIN_M", "PLAN_FLOOR_RGB", "PLAN_WALL_RGB", "write_floor_plan"]

#: the example site's constants (all SI): hall size, anchors, tag height, channel, packet rate and losses
EXAMPLE_SITE = {
    "hall_m": (20.0, 12.0),
    "anchors_m": np.array([[0.5, 0.5, 2.8], [10.0, 0.3, 2.5], [19.5, 0.5, 3.0], [19.7, 6.0, 2.6],
                           [19.5, 11.5, 2.8], [10.0, 11.7, 2.5], [0.5, 11.5, 3.0], [0.3, 6.0, 2.6]]),
    "tag_height_m": 1.2,
    "ref_power_dbm": np.array([-45.0, -43.0, -47.0, -44.0, -48.0, -42.0, -46.0, -45.0]),
    "path_loss_exp": np.array([2.2, 2.0, 2.4, 2.6, 2.1, 2.3, 2.5, 2.2]),
    "sigma_db": 4.0,
    "sensitivity_dbm": -95.0,
    "drop_fraction": 0.10,
    "empty_fraction": 0.02,          # rows logged with an empty reading (not heard)
    "sentinel_fraction": 0.01,       # rows logged with the invalid-reading value
    "sentinel_dbm": 0.0,
    "packet_rate_hz": 4.0,
    "walk_speed_m_s": 1.0,
    "scan_rate_hz": 1.0,             # native scans (native_scans=True): a phone's BLE scan results, about 1 Hz
    # ranges (ranges=True): RTT-like ranging rounds to every anchor, the true 3-D distance plus N(0, sigma^2): 0.3 m is
    # the order of Wi-Fi RTT's (IEEE 802.11mc) spread with a clear line of sight; the device reports that std
    "range_sigma_m": 0.3,
    "range_rate_hz": 2.0,            # ranging rounds per second (native scans: one per scan, at the scan's time)
    "range_missing_fraction": 0.05,  # ranges logged empty (the round failed for that anchor)
    # inertial=True: the tag's IMU (body frame, reading = true + bias + white noise; a phone-grade MEMS unit's
    # order of magnitude: 0.05 m/s^2 and 0.005 rad/s per sample at 50 Hz, Gudipati 2017's WalkSettings scale)
    "imu": {"rate_hz": 50.0, "acc_sigma_m_s2": 0.05, "gyro_sigma_rad_s": 0.005,
            "acc_bias_m_s2": (0.03, -0.02), "gyro_bias_rad_s": 0.002, "corner_radius_m": 2.0},
}
#: extra path loss (dB) per floor between the tag and an anchor: the floor penetration loss of ITU-R P.1238 (Table
#: 3, offices at 1.8-2 GHz: L_f = 15 + 4 (n - 1) dB for n floors; its one-floor value, taken per floor crossed)
FLOOR_ATTENUATION_DB = 15.0
#: storey height (m): floor k's anchors and tag are k x this above floor 0's
FLOOR_HEIGHT_M = 3.0
#: the most floors the example writes (anchor ids A1..A8, B1..B8, ...)
MAX_EXAMPLE_FLOORS = 4
#: the plan image covers the hall and this margin (m) around it: its extent is [-m, w + m, -m, h + m]
PLAN_MARGIN_M = 1.0
#: the plan's colours (RGB in [0, 1]): the hall's floor tint and its walls (a pixel test looks for them)
PLAN_FLOOR_RGB = (0.96, 0.90, 0.78)
PLAN_WALL_RGB = (0.45, 0.30, 0.15)
#: the plan's resolution (pixels per metre)
PLAN_PX_PER_M = 20
#: the recordings of the example by role (``roles`` of :func:`write_example_dataset` picks among them)
EXAMPLE_ROLES = ("calibration", "static", "track")

_MANIFEST = '''# A synthetic example data set written by locbook.data.example (locbook data example DIR):
# raw BLE packets from a log-distance channel with known truth, in the long format, with the faults real data bring.
name = {name}
title = "Synthetic example: 20 m x 12 m hall, 8 anchors, raw packets at 4 Hz (locbook.data.example)"
license = "CC0 1.0"
attribution = {attribution}

[units]
time = "s"
length = "m"
rssi = "dBm"

[readings]
invalid_values_dbm = [0.0]      # the receivers log 0 for a packet they could not decode
backward_time = "sort"          # walk_b was logged with some rows out of time order

[geometry]
anchors = "anchors.csv"
outline = "outline.csv"
tag_height_m = 1.2

[epochs]
window_s = 1.0                  # raw packets -> one epoch per second
aggregate = "mean"
min_readings = 1
'''
#: the [[recording]] blocks of the manifest, by role, in the manifest's order
_RECORDINGS = {
    "calibration": ['\n[[recording]]\nname = "survey"\nfile = "survey.csv"\nrole = "calibration"\n'
                    'point_column = "point"\n'],
    "static": ['\n[[recording]]\nname = "points"\nfile = "points.csv"\nrole = "static"\npoint_column = "point"\n'],
    "track": ['\n[[recording]]\nname = "walk_a"\nfile = "walk_a.csv"\nrole = "track"\n',
              '\n[[recording]]\nname = "walk_b"\nfile = "walk_b.csv"\nrole = "track"\n'],
}
_NATIVE_WINDOW = "window_s = 0                    # native scans: each row time is one scan, already an epoch\n"


def _toml_string(text: str) -> str:
    """``text`` as a TOML basic string: quotes, backslashes and control characters escaped (TOML 1.0, "String"),
    so no value can end the string and add keys."""
    escaped = "".join(c if c not in '"\\' and ord(c) >= 0x20 and ord(c) != 0x7f else
                      ("\\" + c if c in '"\\' else f"\\u{ord(c):04x}") for c in text)
    return f'"{escaped}"'


def _packets(positions_m, time_s, rng, site, *, two_d: bool = False, scans: bool = False) -> pd.DataFrame:
    """Packets of a tag at ``positions_m (T, 2)`` at ``time_s (T,)`` heard by every anchor, with the losses.
    ``two_d``: distances in the plane (no heights); ``scans``: every anchor's reading of one time at that time (a
    scan's rows), not at each anchor's own phase."""
    anchors = site["anchors_m"]
    m = len(anchors)
    if two_d:
        d = np.maximum(np.linalg.norm(positions_m[:, None, :] - anchors[:, :2], axis=-1), 0.1)
    else:
        pos3 = np.column_stack([positions_m, np.full(len(positions_m), site["tag_height_m"])])
        d = np.maximum(np.linalg.norm(pos3[:, None, :] - anchors, axis=-1), 0.1)
    mean = site["ref_power_dbm"] - 10.0 * site["path_loss_exp"] * np.log10(d)
    rss = np.round(mean + site["sigma_db"] * rng.standard_normal(mean.shape))    # receivers report whole dBm
    # each anchor samples at its own phase within the packet interval (a scan: all at the scan's time)
    t = np.repeat(time_s[:, None], m, axis=1) if scans else \
        time_s[:, None] + rng.uniform(0, 1.0 / site["packet_rate_hz"], size=(1, m))
    kept = (rss >= site["sensitivity_dbm"]) & (rng.random(rss.shape) >= site["drop_fraction"])
    row, col = np.nonzero(kept)
    out = pd.DataFrame({"time_s": np.round(t[row, col], 4), "transmitter": "tag1",
                        "receiver": np.array([f"A{j + 1}" for j in range(m)])[col], "rssi_dbm": rss[row, col],
                        "x_m": np.round(positions_m[row, 0], 3), "y_m": np.round(positions_m[row, 1], 3)})
    u = rng.random(len(out))
    out["rssi_dbm"] = out["rssi_dbm"].astype(object)
    out.loc[u < site["empty_fraction"], "rssi_dbm"] = ""
    sentinel = (u >= site["empty_fraction"]) & (u < site["empty_fraction"] + site["sentinel_fraction"])
    out.loc[sentinel, "rssi_dbm"] = site["sentinel_dbm"]
    return out.sort_values("time_s", kind="stable").reset_index(drop=True)


def _dwell(points_m, ids, seconds: float, t0: float, rng, site, *, two_d: bool = False):
    """Packets of a tag standing ``seconds`` at each point in turn (2 s walking between points)."""
    per = int(round(seconds * site["packet_rate_hz"]))
    pos = np.repeat(points_m, per, axis=0)
    start = t0 + np.arange(len(points_m)) * (seconds + 2.0)
    t = (start[:, None] + np.arange(per) / site["packet_rate_hz"]).reshape(-1)
    out = _packets(pos, t, rng, site, two_d=two_d)
    which = np.minimum(((out["time_s"].to_numpy() - t0) // (seconds + 2.0)).astype(int), len(ids) - 1)
    out.insert(6, "point", np.asarray(ids, dtype=object)[which])
    return out


def _rounded_loop(s_m, offset_m: float, radius_m: float, site):
    """Position ``(N, 2)``, heading ``(N,)`` (rad) and curvature ``(N,)`` (1/m, left positive) at arc lengths
    ``s_m`` along the rectangle ``offset_m`` inside the hall's walls with corners rounded to ``radius_m``, walked
    counter-clockwise from ``(offset_m + radius_m, offset_m)`` heading along +x."""
    w, h = site["hall_m"]
    lo, hi = np.array([offset_m, offset_m]), np.array([w - offset_m, h - offset_m])
    r = radius_m
    sides = np.array([hi[0] - lo[0] - 2 * r, hi[1] - lo[1] - 2 * r] * 2)
    arc = 0.5 * np.pi * r
    pieces = np.ravel(np.column_stack([sides, np.full(4, arc)]))        # side, arc, side, arc, ...
    cum = np.r_[0.0, np.cumsum(pieces)]
    s = np.mod(np.asarray(s_m, float), cum[-1])
    k = np.minimum(np.searchsorted(cum, s, side="right") - 1, 7)
    u = s - cum[k]
    side = k // 2
    start = np.array([[lo[0] + r, lo[1]], [hi[0], lo[1] + r], [hi[0] - r, hi[1]], [lo[0], hi[1] - r]])
    centre = np.array([[hi[0] - r, lo[1] + r], [hi[0] - r, hi[1] - r], [lo[0] + r, hi[1] - r], [lo[0] + r, lo[1] + r]])
    heading0 = side * 0.5 * np.pi
    straight = k % 2 == 0
    along = np.column_stack([np.cos(heading0), np.sin(heading0)])
    pos_straight = start[side] + u[:, None] * along
    phi = heading0 - 0.5 * np.pi + u / r                                # the angle seen from the centre
    pos_arc = centre[side] + r * np.column_stack([np.cos(phi), np.sin(phi)])
    pos = np.where(straight[:, None], pos_straight, pos_arc)
    heading = np.where(straight, heading0, heading0 + u / r)
    return pos, heading, np.where(straight, 0.0, 1.0 / r)


def _loop_positions(time_s, offset_m: float, site, t0: float = 0.0, corner_radius_m: float = 0.0) -> np.ndarray:
    """Positions ``(T, 2)`` at ``time_s`` of a tag walking a rectangle ``offset_m`` inside the hall's walls at the
    site's walking speed, from its corner at ``t0`` (``corner_radius_m > 0``: corners rounded,
    :func:`_rounded_loop`)."""
    if corner_radius_m > 0:
        return _rounded_loop(site["walk_speed_m_s"] * (time_s - t0), offset_m, corner_radius_m, site)[0]
    w, h = site["hall_m"]
    corners = np.array([[offset_m, offset_m], [w - offset_m, offset_m], [w - offset_m, h - offset_m],
                        [offset_m, h - offset_m], [offset_m, offset_m]])
    seg = np.linalg.norm(np.diff(corners, axis=0), axis=1)
    cum = np.r_[0.0, np.cumsum(seg)]
    s = (site["walk_speed_m_s"] * (time_s - t0)) % cum[-1]
    return np.column_stack([np.interp(s, cum, corners[:, k]) for k in range(2)])


def _loop_times(duration_s: float, rate_hz: float, t0: float = 0.0) -> np.ndarray:
    return t0 + np.arange(int(duration_s * rate_hz)) / rate_hz


def _loop(duration_s: float, offset_m: float, rng, site, t0: float = 0.0, *, two_d: bool = False,
          scans: bool = False, corner_radius_m: float = 0.0):
    """Packets of a tag walking a rectangle ``offset_m`` inside the hall's walls at the site's walking speed
    (``scans``: as scans at the site's scan rate; ``corner_radius_m > 0``: corners rounded,
    :func:`_rounded_loop`)."""
    t = _loop_times(duration_s, site["scan_rate_hz"] if scans else site["packet_rate_hz"], t0)
    return _packets(_loop_positions(t, offset_m, site, t0, corner_radius_m), t, rng, site, two_d=two_d, scans=scans)


def _ranges(positions_m, time_s, rng, site, *, two_d: bool = False, extra=None) -> pd.DataFrame:
    """A ranging round to every anchor at each of ``time_s (T,)`` from the tag at ``positions_m (T, 2)``: the true
    distance (3-D, the tag at the site's height; in the plane for ``two_d``) plus ``N(0, range_sigma_m^2)``, clipped
    at 0 m (a device reports no negative distance; at these 1.3 m+ distances and 0.3 m it never binds) and logged in
    mm, with its reported std; ``range_missing_fraction`` of them empty (not measured). ``extra``: columns per time
    (a point id)."""
    anchors = site["anchors_m"]
    m = len(anchors)
    if two_d:
        d = np.linalg.norm(positions_m[:, None, :] - anchors[:, :2], axis=-1)
    else:
        pos3 = np.column_stack([positions_m, np.full(len(positions_m), site["tag_height_m"])])
        d = np.linalg.norm(pos3[:, None, :] - anchors, axis=-1)
    value = np.maximum(d + site["range_sigma_m"] * rng.standard_normal(d.shape), 0.0).round(3)
    out = pd.DataFrame({"time_s": np.round(np.repeat(time_s, m), 4), "transmitter": "tag1",
                        "receiver": np.tile([f"A{j + 1}" for j in range(m)], len(time_s)),
                        "range_m": value.reshape(-1).astype(object), "range_std_m": site["range_sigma_m"]})
    out.loc[rng.random(len(out)) < site["range_missing_fraction"], "range_m"] = ""
    for name, values in (extra or {}).items():
        out[name] = np.repeat(np.asarray(values, dtype=object), m)
    return out


def _dwell_ranges(points_m, ids, seconds: float, t0: float, rng, site, *, two_d: bool = False) -> pd.DataFrame:
    """The ranges of :func:`_dwell`'s tag: rounds at the site's ranging rate while it stands at each point."""
    per = int(round(seconds * site["range_rate_hz"]))
    start = t0 + np.arange(len(points_m)) * (seconds + 2.0)
    t = (start[:, None] + np.arange(per) / site["range_rate_hz"]).reshape(-1)
    return _ranges(np.repeat(points_m, per, axis=0), t, rng, site, two_d=two_d,
                   extra={"point": np.repeat(np.asarray(ids, dtype=object), per)})


def _imu_frame(time_s, acc_body_m_s2, rate_rad_s, rng, site) -> pd.DataFrame:
    """An inertial file's rows: ``true + bias + white noise`` (``site["imu"]``) at ``time_s``."""
    imu = site["imu"]
    n = len(time_s)
    acc = acc_body_m_s2 + np.asarray(imu["acc_bias_m_s2"]) + imu["acc_sigma_m_s2"] * rng.standard_normal((n, 2))
    gyro = rate_rad_s + imu["gyro_bias_rad_s"] + imu["gyro_sigma_rad_s"] * rng.standard_normal(n)
    return pd.DataFrame({"time_s": np.round(time_s, 4), "acc_x": np.round(acc[:, 0], 5),
                         "acc_y": np.round(acc[:, 1], 5), "gyro_z": np.round(gyro, 6)})


def _walk_imu(duration_s: float, offset_m: float, rng, site) -> pd.DataFrame:
    """The IMU of a walk of :func:`_loop` with rounded corners: body-frame acceleration (0, v^2 kappa) and yaw rate
    v kappa at the site's IMU rate, from a phase of half a sample."""
    imu = site["imu"]
    t = (np.arange(int(duration_s * imu["rate_hz"])) + 0.5) / imu["rate_hz"]
    v = site["walk_speed_m_s"]
    kappa = _rounded_loop(v * t, offset_m, imu["corner_radius_m"], site)[2]
    return _imu_frame(t, np.column_stack([np.zeros_like(t), v * v * kappa]), v * kappa, rng, site)


def _dwell_imu(n_points: int, seconds: float, t0: float, rng, site) -> pd.DataFrame:
    """The IMU of :func:`_dwell`'s tag: at rest during each dwell, no samples between points."""
    imu = site["imu"]
    per = int(round(seconds * imu["rate_hz"]))
    start = t0 + np.arange(n_points) * (seconds + 2.0)
    t = (start[:, None] + (np.arange(per) + 0.5) / imu["rate_hz"]).reshape(-1)
    return _imu_frame(t, np.zeros((len(t), 2)), np.zeros(len(t)), rng, site)


def write_floor_plan(path, hall_m, *, margin_m: float = PLAN_MARGIN_M) -> tuple[float, float, float, float]:
    """Draw a plan of the hall ``(w, h)`` with matplotlib and save it as a PNG at ``path``: the floor tinted
    :data:`PLAN_FLOOR_RGB`, the outer walls and two inner walls with door gaps as lines of :data:`PLAN_WALL_RGB`,
    white outside; the image covers ``[-margin, w + margin] x [-margin, h + margin]`` exactly (returned, the
    manifest's ``floor_plan_extent_m``). Deterministic bytes (no metadata that changes)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Rectangle
    w, h = hall_m
    extent = (-margin_m, w + margin_m, -margin_m, h + margin_m)
    dpi = 100
    fig = Figure(figsize=((w + 2 * margin_m) * PLAN_PX_PER_M / dpi, (h + 2 * margin_m) * PLAN_PX_PER_M / dpi),
                 dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_axes((0.0, 0.0, 1.0, 1.0))
    ax.set_axis_off()
    ax.add_patch(Rectangle((0.0, 0.0), w, h, facecolor=PLAN_FLOOR_RGB, edgecolor="none"))
    wall = {"color": PLAN_WALL_RGB, "lw": 3, "solid_capstyle": "butt"}
    ax.plot([0, w, w, 0, 0], [0, 0, h, h, 0], **wall)
    ax.plot([0.4 * w, 0.4 * w], [0.0, 0.3 * h], **wall)          # inner walls, each with a door gap
    ax.plot([0.4 * w, 0.4 * w], [0.6 * h, h], **wall)
    ax.plot([0.4 * w, 0.55 * w], [0.5 * h, 0.5 * h], **wall)
    ax.plot([0.7 * w, w], [0.5 * h, 0.5 * h], **wall)
    ax.set_xlim(extent[0], extent[1])
    ax.set_ylim(extent[2], extent[3])
    fig.savefig(path, dpi=dpi, metadata={"Software": None})
    return extent


def _floor_site(site, k: int, n_floors: int) -> dict:
    """The site as heard by a tag on floor ``k`` of ``n_floors``: every floor's anchors (floor j's at j storeys
    up), each reading :data:`FLOOR_ATTENUATION_DB` weaker per floor between, the tag's height on floor k."""
    anchors = np.vstack([site["anchors_m"] + [0.0, 0.0, j * FLOOR_HEIGHT_M] for j in range(n_floors)])
    between = np.repeat(np.abs(np.arange(n_floors) - k), len(site["anchors_m"]))
    return {**site, "anchors_m": anchors, "path_loss_exp": np.tile(site["path_loss_exp"], n_floors),
            "ref_power_dbm": np.tile(site["ref_power_dbm"], n_floors) - FLOOR_ATTENUATION_DB * between,
            "tag_height_m": site["tag_height_m"] + k * FLOOR_HEIGHT_M}


def _on_floor(frame: pd.DataFrame, k: int, n_anchors: int) -> pd.DataFrame:
    """Packets of a tag on floor ``k`` (from a :func:`_floor_site`): anchors renamed by floor (A1..A8, B1..B8),
    the tag's true height and floor on every row."""
    index = frame["receiver"].str[1:].astype(int) - 1
    frame["receiver"] = [f"{chr(ord('A') + i // n_anchors)}{i % n_anchors + 1}" for i in index]
    at = list(frame.columns).index("y_m") + 1
    frame.insert(at, "z_m", round(EXAMPLE_SITE["tag_height_m"] + k * FLOOR_HEIGHT_M, 3))
    frame.insert(at + 1, "floor", f"F{k + 1}")
    return frame


def _write_floors(folder: Path, rng, site, n_floors: int, walk_s: float, roles) -> None:
    """The building's files (module docstring): anchors with floors, recordings spanning floors and walks."""
    m = len(site["anchors_m"])
    anchors = pd.DataFrame({
        "id": [f"{chr(ord('A') + j)}{i + 1}" for j in range(n_floors) for i in range(m)],
        "x": np.tile(site["anchors_m"][:, 0], n_floors), "y": np.tile(site["anchors_m"][:, 1], n_floors),
        "z": np.concatenate([site["anchors_m"][:, 2] + j * FLOOR_HEIGHT_M for j in range(n_floors)]),
        "floor": [f"F{j + 1}" for j in range(n_floors) for _ in range(m)]})
    anchors.to_csv(folder / "anchors.csv", index=False)
    w, h = site["hall_m"]
    gx, gy = np.meshgrid(np.arange(1.0, w, 2.0), np.arange(1.0, h, 2.0))
    grid = np.column_stack([gx.ravel(), gy.ravel()])

    def visits(points, prefix, seconds):
        """The tag standing at ``points`` on every floor in turn (one file spanning the floors)."""
        parts, t0 = [], 0.0
        for k in range(n_floors):
            ids = [f"F{k + 1}-{prefix}{i + 1:03d}" for i in range(len(points))]
            parts.append(_on_floor(_dwell(points, ids, seconds, t0, rng, _floor_site(site, k, n_floors)), k, m))
            t0 += len(points) * (seconds + 2.0) + 10.0
        return pd.concat(parts, ignore_index=True)

    visits(grid, "C", 5.0).to_csv(folder / "survey.csv", index=False)
    if "static" in roles:
        tests = np.column_stack([rng.uniform(2.0, w - 2.0, 12), rng.uniform(2.0, h - 2.0, 12)]).round(2)
        visits(tests, "T", 10.0).to_csv(folder / "points.csv", index=False)
    if "track" in roles:
        _on_floor(_loop(walk_s, 2.0, rng, _floor_site(site, 0, n_floors)), 0, m).to_csv(folder / "walk_a.csv",
                                                                                        index=False)
        top = n_floors - 1
        walk_b = _on_floor(_loop(walk_s, 3.0, rng, _floor_site(site, top, n_floors)), top, m)
        swap = rng.choice(np.arange(1, len(walk_b) - 1, 2), size=max(1, len(walk_b) // 500), replace=False)
        order = np.arange(len(walk_b))
        order[swap], order[swap + 1] = swap + 1, swap
        walk_b.iloc[order].to_csv(folder / "walk_b.csv", index=False)


def _check_floor_options(floors, floor_plan, two_d: bool, native_scans: bool) -> None:
    from ..errors import ParameterError
    if isinstance(floors, bool) or not isinstance(floors, int) or not 1 <= floors <= MAX_EXAMPLE_FLOORS:
        raise ParameterError(f"floors must be an integer from 1 to {MAX_EXAMPLE_FLOORS} (MAX_EXAMPLE_FLOORS), got "
                             f"{floors!r}")
    if not isinstance(floor_plan, bool):
        raise ParameterError(f"floor_plan must be True or False, got {floor_plan!r}")
    if floors > 1 and (two_d or native_scans):
        raise ParameterError("floors: a building of several floors is written in 3-D with raw packets (not with "
                             "two_d or native_scans)")


def _with_floor_plan(folder: Path, site, text: str) -> str:
    """The manifest ``text`` with the plan (written to ``plan.png``, :func:`write_floor_plan`) and its extent."""
    extent = write_floor_plan(folder / "plan.png", site["hall_m"])
    return text.replace('outline = "outline.csv"\n', 'outline = "outline.csv"\nfloor_plan = "plan.png"\n'
                        f"floor_plan_extent_m = [{', '.join(f'{v:g}' for v in extent)}]\n")


def _write_building(folder: Path, rng, site, n_floors: int, walk_s: float, roles, name: str, seed_note,
                    floor_plan: bool) -> Path:
    """The example building (module docstring): its files (:func:`_write_floors`) and manifest, the one-floor
    example's with each floor's tag height from its rows' z_m."""
    w, h = site["hall_m"]
    pd.DataFrame({"x": [0.0, w, w, 0.0], "y": [0.0, 0.0, h, h]}).to_csv(folder / "outline.csv", index=False)
    _write_floors(folder, rng, site, n_floors, walk_s, roles)
    attribution = f"Synthetic data generated by locbook (locbook.data.example.write_example_dataset, seed {seed_note})"
    text = _MANIFEST.format(name=_toml_string(name), attribution=_toml_string(attribution))
    text = text.replace("tag_height_m = 1.2\n", "")       # each floor's: the median of its rows' z_m
    text = text.replace("Synthetic example: 20 m x 12 m hall, 8 anchors,",
                        f"Synthetic example: {n_floors} floors of a 20 m x 12 m hall, 8 anchors each,")
    if floor_plan:
        text = _with_floor_plan(folder, site, text)
    text += "".join(block for role in EXAMPLE_ROLES if role in roles for block in _RECORDINGS[role])
    (folder / "dataset.toml").write_text(text, encoding="utf-8")
    return folder


def write_example_dataset(folder, rng: np.random.Generator, *, name: str = "example", walk_s: float = 120.0,
                          seed_note: int | str = "given", force: bool = False, speed_m_s: float | None = None,
                          roles=EXAMPLE_ROLES, two_d: bool = False, native_scans: bool = False,
                          ranges: bool = False, inertial: bool = False, floors: int = 1,
                          floor_plan: bool = False) -> Path:
    """Write the example data set (module docstring) to ``folder`` (created; a folder that holds files is refused
    unless ``force``, so a typo never overwrites a data set) and return it. ``walk_s``: length of each walk (s): 120 s
    gives about 30,000 readings in all; the loader benchmark scales it up. ``name``: the manifest's name (it names
    the reports folder).

    Variants (the defaults write today's set, byte for byte): ``speed_m_s``, the walkers' speed (default
    ``EXAMPLE_SITE["walk_speed_m_s"]``, 1 m/s); ``roles``, the recordings written, a subset of
    :data:`EXAMPLE_ROLES` holding ``"calibration"`` (e.g. ``("calibration", "static")`` for a static-only set,
    ``("calibration", "track")`` for a track-only one); ``two_d``, anchors without z (a 2-D site: readings from
    distances in the plane, no ``tag_height_m``); ``native_scans``, the tracks written as scans (every anchor of a
    scan at one time, ``EXAMPLE_SITE["scan_rate_hz"]``) with ``window_s = 0``; ``ranges``, a ranges file per
    recording (``<name>_ranges.csv``, :mod:`locbook.data.ranges`): RTT-like ranges to every anchor at
    ``EXAMPLE_SITE["range_rate_hz"]`` (the tracks' native scans: at each scan), the true 3-D distance plus
    ``N(0, range_sigma_m^2)`` (0.3 m) with that std reported, ``range_missing_fraction`` (5 %) empty, drawn from a
    generator seeded by one draw of ``rng`` after every other draw, so the other files are those written without
    it, byte for byte; ``inertial``, an inertial file per recording and walks with rounded corners (module
    docstring), from a generator of its own drawn after the ranges' (the same rule); ``floors``, the floors of a
    building (1 to :data:`MAX_EXAMPLE_FLOORS`; 2 or more: module docstring; not with ``two_d``, ``native_scans``,
    ``ranges`` or ``inertial``);
    ``floor_plan``, a plan image (:func:`write_floor_plan`) and its extent in the manifest."""
    from ..errors import ParameterError
    from .dataset import name_problem
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    problem = name_problem(name)          # the manifest's own rule, checked before anything is written
    if problem:
        raise ParameterError(f"name (--name): {problem}")
    site = EXAMPLE_SITE
    if speed_m_s is not None:
        if isinstance(speed_m_s, bool) or not isinstance(speed_m_s, (int, float)) or not 0 < speed_m_s < np.inf:
            raise ParameterError(f"speed_m_s must be a positive finite speed (m/s), got {speed_m_s!r}")
        site = {**site, "walk_speed_m_s": float(speed_m_s)}
    roles = (roles,) if isinstance(roles, str) else tuple(roles)
    unknown = [r for r in roles if r not in EXAMPLE_ROLES]
    if unknown or "calibration" not in roles:
        raise ParameterError(f"roles must be some of {EXAMPLE_ROLES}, 'calibration' among them (a data set needs a "
                             f"calibration recording), got {roles!r}")
    for key, value in (("two_d", two_d), ("native_scans", native_scans), ("ranges", ranges), ("inertial", inertial)):
        if not isinstance(value, bool):
            raise ParameterError(f"{key} must be True or False, got {value!r}")
    _check_floor_options(floors, floor_plan, two_d, native_scans)
    if floors != 1 and (ranges or inertial):
        raise ParameterError("floors: a building's example writes RSS readings only (a data set with floors takes no "
                             "ranges or inertial streams yet); leave out ranges / inertial, or floors")
    folder = Path(folder)
    if folder.exists() and (not folder.is_dir() or (any(folder.iterdir()) and not force)):
        raise ParameterError(f"{folder} exists and is not an empty folder; the example is written to a new or empty "
                             "folder (force=True, `--force`, to overwrite its files)")
    folder.mkdir(parents=True, exist_ok=True)
    if floors > 1:                  # a building: its own files and draws (the one-floor example below is untouched)
        return _write_building(folder, rng, site, floors, walk_s, roles, name, seed_note, floor_plan)
    w, h = site["hall_m"]
    columns = {"id": [f"A{j + 1}" for j in range(len(site["anchors_m"]))], "x": site["anchors_m"][:, 0],
               "y": site["anchors_m"][:, 1]}
    if not two_d:
        columns["z"] = site["anchors_m"][:, 2]
    pd.DataFrame(columns).to_csv(folder / "anchors.csv", index=False)
    pd.DataFrame({"x": [0.0, w, w, 0.0], "y": [0.0, 0.0, h, h]}).to_csv(folder / "outline.csv", index=False)
    gx, gy = np.meshgrid(np.arange(1.0, w, 2.0), np.arange(1.0, h, 2.0))
    grid = np.column_stack([gx.ravel(), gy.ravel()])
    grid_ids = [f"C{k + 1:03d}" for k in range(len(grid))]
    _dwell(grid, grid_ids, 5.0, 0.0, rng, site, two_d=two_d).to_csv(folder / "survey.csv", index=False)
    if "static" in roles:
        tests = np.column_stack([rng.uniform(2.0, w - 2.0, 12), rng.uniform(2.0, h - 2.0, 12)]).round(2)
        test_ids = [f"T{k + 1:02d}" for k in range(len(tests))]
        _dwell(tests, test_ids, 10.0, 0.0, rng, site, two_d=two_d).to_csv(folder / "points.csv", index=False)
    radius = site["imu"]["corner_radius_m"] if inertial else 0.0
    if "track" in roles:
        _loop(walk_s, 2.0, rng, site, two_d=two_d, scans=native_scans, corner_radius_m=radius).to_csv(
            folder / "walk_a.csv", index=False)
        walk_b = _loop(walk_s, 3.0, rng, site, two_d=two_d, scans=native_scans, corner_radius_m=radius)
        # logged out of order: a few pairs of neighbouring rows swapped (a buffered receiver flushing late)
        swap = rng.choice(np.arange(1, len(walk_b) - 1, 2), size=max(1, len(walk_b) // 500), replace=False)
        order = np.arange(len(walk_b))
        order[swap], order[swap + 1] = swap + 1, swap
        walk_b = walk_b.iloc[order]
        walk_b.to_csv(folder / "walk_b.csv", index=False)
    if ranges:      # after every other draw, from a stream of its own: the files above are unchanged
        range_rng = np.random.default_rng(rng.integers(2**63))
        _dwell_ranges(grid, grid_ids, 5.0, 0.0, range_rng, site, two_d=two_d).to_csv(
            folder / "survey_ranges.csv", index=False)
        if "static" in roles:
            _dwell_ranges(tests, test_ids, 10.0, 0.0, range_rng, site, two_d=two_d).to_csv(
                folder / "points_ranges.csv", index=False)
        if "track" in roles:
            for walk, offset in (("walk_a", 2.0), ("walk_b", 3.0)):
                # rounds centred on the 1 s windows (k - 1/4, k + 1/4 s: their mean time is the window's tick); as
                # scans, at each scan's time (the epoch of a native scan)
                t = (_loop_times(walk_s, site["scan_rate_hz"]) if native_scans else
                     _loop_times(walk_s, site["range_rate_hz"]) + 0.5 / site["range_rate_hz"])
                _ranges(_loop_positions(t, offset, site, corner_radius_m=radius), t, range_rng, site,
                        two_d=two_d).to_csv(folder / f"{walk}_ranges.csv", index=False)
    imu_files = {}
    if inertial:        # after every other draw: the other files are those of the variant without it
        imu_rng = np.random.default_rng(rng.integers(2**63))
        imu_files["survey"] = _dwell_imu(len(grid), 5.0, 0.0, imu_rng, site)
        if "static" in roles:
            imu_files["points"] = _dwell_imu(12, 10.0, 0.0, imu_rng, site)
        if "track" in roles:
            imu_files["walk_a"] = _walk_imu(walk_s, 2.0, imu_rng, site)
            imu_files["walk_b"] = _walk_imu(walk_s, 3.0, imu_rng, site)
        for rec, frame in imu_files.items():
            frame.to_csv(folder / f"{rec}_imu.csv", index=False)
    attribution = f"Synthetic data generated by locbook (locbook.data.example.write_example_dataset, seed {seed_note})"
    text = _MANIFEST.format(name=_toml_string(name), attribution=_toml_string(attribution))
    if two_d:
        text = text.replace("tag_height_m = 1.2\n", "")
        text = text.replace("8 anchors, raw packets", "8 anchors in one plane (2-D), raw packets")
    if native_scans and "track" in roles:
        text = text.replace(", raw packets at 4 Hz",
                            f", raw packets at 4 Hz, walks as {site['scan_rate_hz']:g} Hz scans")
    if ranges:
        text = text.replace(", raw packets at 4 Hz", f", raw packets at 4 Hz, ranges ({site['range_sigma_m']:g} m)", 1)
    if inertial:
        text = text.replace('rssi = "dBm"\n', 'rssi = "dBm"\nacceleration = "m/s2"            # the inertial files\n'
                                              'angular_rate = "rad/s"\n')
        text = text.replace(", raw packets at 4 Hz", ", raw packets at 4 Hz, 50 Hz IMU files (rounded corners)")
    for role in EXAMPLE_ROLES:
        if role in roles:
            text += "".join(block + (_NATIVE_WINDOW if native_scans and role == "track" else "")
                            + (f'ranges = "{block.split(chr(34))[1]}_ranges.csv"\n' if ranges else "")
                            + (f'inertial = "{block.split(chr(34))[1]}_imu.csv"\n' if inertial else "")
                            for block in _RECORDINGS[role])
    if floor_plan:
        text = _with_floor_plan(folder, site, text)
    (folder / "dataset.toml").write_text(text, encoding="utf-8")
    return folder
