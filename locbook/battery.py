"""The battery: every method locbook runs on a localization or tracking problem, defined once.

A problem is a :class:`StaticScenario` (readings at test positions) or a :class:`TrackingScenario` (readings on a
fixed clock along a path): the anchors, the channel the estimators know, the floor outline, the tag's height (3-D
anchors) or none (a 2-D problem), and for measured data the recorded readings. Every static method
(:data:`STATIC_METHODS`) and every tracker (:data:`TRACKERS`) is one entry with what it is, its settings, and why it
may fall below the Cramer-Rao bound (the prior it uses that the bound does not have); :func:`static_fixes` and
:func:`run_trackers` run them. The cross-document benchmark (:mod:`locbook.benchmark`) and the measured-data
protocol (:mod:`locbook.scenarios.measured`) both call these, so one name is one estimator on every page.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import numpy as np

from .bounds.crlb import check_position_information, rss_position_information
from .bounds.pcrlb import position_bound_m, posterior_crlb, rss_state_information
from .errors import ParameterError
from .geometry import grid_in_outline, outline_box
from .models.channel import PathLossModel
from .models.motion import constant_velocity
from .models.rss import RssModel
from .static.calibration import fix_error_covariance
from .static.fingerprint import knn_position, model_fingerprints
from .static.localization import grid_ml_position, lateration_box_ls, lateration_ls, lateration_wls, rss_ml_position
from .tracking.bayes import grid_bayes_filter
from .tracking.divergence import DivergenceFlags
from .tracking.imm import imm_filter
from .tracking.kalman import extended_kalman_filter
from .tracking.particle import particle_filter
from .tracking.streams import LinearMeasurement, RssMeasurement
from .tracking.unscented import unscented_kalman_filter

__all__ = ["ProtocolChoice", "StaticScenario", "TrackingScenario", "Method", "STATIC_METHODS", "TRACKERS",
           "TrackerSettings", "static_fixes", "static_bound_m", "static_bound_checked", "run_trackers",
           "tracking_bound_m", "initial_states", "channel_settings", "TRACKER_PRIORS", "KF_FIX_MIN_ANCHORS"]


@dataclass(frozen=True)
class ProtocolChoice:
    """One named choice of a scenario or a method: its value and where it comes from."""

    name: str
    value: str
    source: str


@dataclass(frozen=True)
class _AnchorReadings:
    """What the static and tracking scenarios share: their name, document and title, the anchors, channel and floor,
    the anchor distances of plan positions and channel draws at them, whether the readings are measured, and the
    floor's bounding box (the scenario adds ``tag_height_m`` and ``measured_rss_dbm``)."""

    key: str
    document: str
    title: str
    anchors_m: np.ndarray
    channel: PathLossModel
    outline_m: np.ndarray

    @property
    def measured(self) -> bool:
        return self.measured_rss_dbm is not None

    @property
    def box_m(self):
        return outline_box(self.outline_m)

    def grid_m(self, spacing_m: float | None = None) -> np.ndarray:
        """The grid methods' candidates: a grid inside the floor outline at the scenario's pitch (or ``spacing_m``)."""
        return grid_in_outline(self.outline_m, self.grid_spacing_m if spacing_m is None else spacing_m)

    def distances_m(self, points_m) -> np.ndarray:
        """Anchor distances ``(..., m)`` (3-D when the anchors carry heights: the tag at ``tag_height_m``)."""
        p = np.asarray(points_m, float)
        if self.tag_height_m is not None:
            p = np.concatenate([p, np.full(p.shape[:-1] + (1,), self.tag_height_m)], axis=-1)
        return np.linalg.norm(p[..., None, :] - self.anchors_m, axis=-1)

    def _sample_rss_dbm(self, points_m, n_runs: int, rng: np.random.Generator) -> np.ndarray:
        """``n_runs`` independent channel draws at ``points_m``: ``(n_runs, ..., m)``."""
        d = self.distances_m(points_m)
        return self.channel.sample_rss_dbm(np.broadcast_to(d, (n_runs,) + d.shape), rng=rng)


@dataclass(frozen=True)
class StaticScenario(_AnchorReadings):
    """A static localization problem: anchors ``(m, 2)`` (or ``(m, 3)`` with ``tag_height_m``), the channel (the
    truth and what the estimators know), the floor (``outline_m``; the region of box-LS is its bounding box),
    evaluation positions ``points_m (P, 2)``, the pitch of the grid methods' grid; for measured data the readings
    ``measured_rss_dbm (P, m)`` (NaN = not heard) and the k-NN radio map ``(cells, fingerprints)``."""

    points_m: np.ndarray
    grid_spacing_m: float
    settings: tuple[ProtocolChoice, ...]
    tag_height_m: float | None = None
    measured_rss_dbm: np.ndarray | None = None
    radio_map: tuple | None = field(default=None, repr=False)

    def rss_dbm(self, n_runs: int, rng: np.random.Generator) -> np.ndarray:
        """Readings ``(R, P, m)``: the measured ones (``R = 1``), or ``n_runs`` draws of the channel."""
        if self.measured:
            return self.measured_rss_dbm[None]
        return self._sample_rss_dbm(self.points_m, n_runs, rng)


@dataclass(frozen=True)
class TrackingScenario(_AnchorReadings):
    """A tracking problem on a fixed clock ``dt_s``: true plan positions ``truth_m (T, 2)`` at every tick (NaN where
    the truth is unknown), the ticks that are scored (``scored (T,)``), the anchors and channel, the floor, and for
    measured data the readings ``measured_rss_dbm (T, m)`` on the clock (a tick without readings is all NaN)."""

    truth_m: np.ndarray
    dt_s: float
    spread_m: float
    grid_spacing_m: float
    settings: tuple[ProtocolChoice, ...]
    tag_height_m: float | None = None
    measured_rss_dbm: np.ndarray | None = None
    scored: np.ndarray | None = None
    fix_cov_m2: np.ndarray | None = None
    #: measured data: the state every tracker starts from ``[x, y, vx, vy]`` (the first ``rss_ml`` fix, at rest),
    #: with the settings' P_0; None (synthetic): the true initial state plus a draw of ``N(0, P_0)`` per run
    start_state: np.ndarray | None = None
    #: measured data: the time of every tick ``(T,)`` (s; the first epoch's time plus ``k dt_s``); None (synthetic)
    time_s: np.ndarray | None = None
    #: a track with an inertial stream: what the fusion trackers need (:class:`locbook.inertial_trackers.FusionInputs`:
    #: the readings on the sub-step grid, their calibration, heading start and q); None: no fusion tracker runs
    inertial: object | None = field(default=None, repr=False)

    @property
    def scored_steps(self) -> np.ndarray:
        return np.arange(len(self.truth_m)) if self.scored is None else np.flatnonzero(self.scored)

    def initial_state(self) -> np.ndarray:
        """True ``[x, y, vx, vy]`` at the first tick (velocity from the first scored displacement)."""
        steps = self.scored_steps
        a, b = steps[0], steps[1]
        return np.r_[self.truth_m[a], (self.truth_m[b] - self.truth_m[a]) / ((b - a) * self.dt_s)]

    def rss_dbm(self, n_runs: int, rng: np.random.Generator) -> np.ndarray:
        """Readings ``(R, T, m)``: the measured ones repeated ``n_runs`` times, or ``n_runs`` draws of the channel."""
        if self.measured:
            return np.broadcast_to(self.measured_rss_dbm, (n_runs,) + self.measured_rss_dbm.shape)
        return self._sample_rss_dbm(self.truth_m, n_runs, rng)


def _fmt(values) -> str:
    a = np.atleast_1d(np.asarray(values, float))
    return f"{a[0]:g}" if a.size == 1 or np.all(a == a[0]) else "[" + ", ".join(f"{v:g}" for v in a) + "]"


def channel_settings(model: PathLossModel, source: str) -> tuple[ProtocolChoice, ...]:
    return (ProtocolChoice("P0 (dBm at 1 m)", _fmt(model.ref_power_dbm), source),
            ProtocolChoice("path-loss exponent", _fmt(model.path_loss_exp), source),
            ProtocolChoice("shadowing sigma (dB)", _fmt(model.sigma_db), source))



# ------------------------------------------------------------------------------------------------ static methods

def _flat(rss):
    return rss.reshape(-1, rss.shape[-1])


def _lls(sc, rss, opts):
    return lateration_ls(sc.anchors_m, sc.channel.range_m(_flat(rss)), tag_height_m=sc.tag_height_m).position_m


def _wls(sc, rss, opts):
    ranges = sc.channel.range_m(_flat(rss))
    w = 1.0 / np.where(np.isnan(ranges[:, 1:]), 1.0, ranges[:, 1:]) ** 4
    return lateration_wls(sc.anchors_m, ranges, w / np.max(w, axis=-1, keepdims=True),
                          tag_height_m=sc.tag_height_m).position_m


def _box_ls(sc, rss, opts):
    lower, upper = sc.box_m
    return lateration_box_ls(sc.anchors_m, sc.channel.range_m(_flat(rss)), lower, upper,
                             tag_height_m=sc.tag_height_m).position_m


def _grid_ml(sc, rss, opts):
    return grid_ml_position(_flat(rss), RssModel(sc.anchors_m, sc.channel, tag_height_m=sc.tag_height_m),
                            sc.grid_m()).position_m


def _grid_start(sc, rss, opts):
    start = opts.get("grid_ml")
    return _grid_ml(sc, rss, opts) if start is None else start


def _rss_ml(sc, rss, opts):
    return rss_ml_position(_flat(rss), RssModel(sc.anchors_m, sc.channel, tag_height_m=sc.tag_height_m),
                           _grid_start(sc, rss, opts), region_m=sc.box_m).position_m


def _rss_ml_free(sc, rss, opts):
    return rss_ml_position(_flat(rss), RssModel(sc.anchors_m, sc.channel, tag_height_m=sc.tag_height_m),
                           _grid_start(sc, rss, opts)).position_m


def _bayes_model(sc) -> RssModel:
    m = sc.channel
    return RssModel(sc.anchors_m, PathLossModel(np.asarray(m.ref_power_dbm, float), np.asarray(m.path_loss_exp, float),
                                                np.asarray(m.sigma_db, float), m.ref_distance_m, m.wall_attenuation_db,
                                                float(m.min_distance_m) if m.min_distance_m > 0 else 0.1),
                    tag_height_m=sc.tag_height_m)


#: problems per block of the grid posterior: beliefs of about 32 MiB at a time
GRID_BLOCK_VALUES = 1 << 22


def _grid_mmse(sc, rss, opts):
    # one step of the grid Bayes filter from a uniform belief (no transition at the first step): the posterior mean
    flat = _flat(rss)
    cells, model = sc.grid_m(), _bayes_model(sc)
    block = max(1, GRID_BLOCK_VALUES // cells.shape[0])
    return np.concatenate([grid_bayes_filter(flat[i:i + block, None, :], model, cells, 1.0).mean[:, 0]
                           for i in range(0, flat.shape[0], block)])


def _knn(sc, rss, opts):
    if sc.radio_map is not None:
        cells, fingerprints = sc.radio_map
    else:
        cells = sc.grid_m(opts["knn_map_spacing_m"])
        fingerprints = model_fingerprints(cells, RssModel(sc.anchors_m, PathLossModel(sc.channel.ref_power_dbm,
                                                                                      sc.channel.path_loss_exp)))
    return knn_position(_flat(rss), fingerprints, cells, opts["knn_k"], chunk=4096)


@dataclass(frozen=True)
class Method:
    """One method of the battery: its function (static methods; None for a tracker, run by :func:`run_trackers`),
    what it is, its settings, and ``prior``: what it knows that the Cramer-Rao bound does not (the floor, a radio
    map, a motion model), i.e. why its error may fall below the bound; "" for a method with no such prior."""

    fn: object
    what: str
    settings: str
    prior: str = ""

    def __iter__(self):          # (fn, what, settings): the registry's old tuple form
        return iter((self.fn, self.what, self.settings))

    def __getitem__(self, i):
        return (self.fn, self.what, self.settings)[i]


#: the static methods, in table order
STATIC_METHODS = {
    "lls": Method(_lls, "linearized LS on the inverted ranges (reference anchor 0)", "no region"),
    "wls": Method(_wls, "weighted linearized LS, weights 1/d^4 of the inverted ranges", "no region"),
    "box_ls": Method(_box_ls, "box-constrained LS (exact active set)", "box = the floor's bounding box",
                     "its fixes lie in the floor's bounding box"),
    "rss_ml": Method(_rss_ml, "RSS maximum likelihood (damped Gauss-Newton) from the grid-ML fix, in the floor's "
                              "bounding box", "box = the floor's bounding box; start: grid ML",
                     "its fixes lie in the floor's bounding box and start at the grid-ML fix inside the floor"),
    "rss_ml_free": Method(_rss_ml_free, "RSS maximum likelihood (damped Gauss-Newton) from the grid-ML fix, "
                                        "unconstrained", "no region after the start",
                          "it starts at the grid-ML fix inside the floor"),
    "grid_ml": Method(_grid_ml, "grid maximum likelihood", "grid inside the floor at the scenario's pitch",
                      "it searches only inside the floor outline"),
    "grid_mmse": Method(_grid_mmse, "grid posterior mean, uniform prior over the floor", "grid inside the floor",
                        "its prior is uniform over the floor outline"),
    "knn": Method(_knn, "weighted k-NN fingerprinting (inverse-square weights)",
                  "map: the channel's mean on a lattice (synthetic), the calibration set (measured)",
                  "its radio map holds positions inside the floor (measured data: recorded in the same room, "
                  "possibly on the same lines as the scored epochs)"),
}


def static_fixes(sc: StaticScenario, rss_dbm, *, knn_k: int = 4, knn_map_spacing_m: float = 0.5,
                 methods=None) -> dict[str, np.ndarray]:
    """Every declared static method on readings ``(R, P, m)`` -> fixes ``(R, P, 2)`` (NaN where it has none)."""
    rss = np.asarray(rss_dbm, float)
    opts = {"knn_k": knn_k, "knn_map_spacing_m": knn_map_spacing_m}
    chosen = tuple(STATIC_METHODS if methods is None else methods)
    out = {}
    # grid ML first: it is the start of both RSS-ML methods (computed once)
    for name in sorted(chosen, key=lambda n: n != "grid_ml"):
        out[name] = np.asarray(STATIC_METHODS[name].fn(sc, rss, opts), float).reshape(rss.shape[:-1] + (2,))
        if name == "grid_ml":
            opts["grid_ml"] = out[name].reshape(-1, 2)
    return {name: out[name] for name in chosen}


def _information(sc, positions_m, heard=None):
    ch = sc.channel
    # the bound's model: anchors (heights over the tag), n, sigma, clamp
    model = RssModel(sc.anchors_m, PathLossModel(0.0, ch.path_loss_exp, ch.sigma_db, min_distance_m=ch.min_distance_m),
                     tag_height_m=sc.tag_height_m)
    return rss_position_information(positions_m, model, heard=heard)


def static_bound_m(sc: StaticScenario) -> np.ndarray:
    """CRLB ``sqrt(tr J^-1)`` at each evaluation position ``(P,)``; for measured data from the anchors heard at that
    epoch, NaN where that bound is undefined or near-singular (:func:`static_bound_checked`)."""
    return static_bound_checked(sc)[0]


def static_bound_checked(sc: StaticScenario):
    """``(bound (P,), reason (P,))``: the static CRLB at each evaluation position, NaN with the reason where it is
    undefined (fewer than 3 anchors heard) or near-singular (:func:`locbook.bounds.crlb.check_position_information`);
    every anchor counts as heard in a synthetic scenario."""
    heard = np.ones((len(sc.points_m), len(sc.anchors_m)), bool) if not sc.measured else ~np.isnan(sc.measured_rss_dbm)
    return check_position_information(_information(sc, sc.points_m, heard if sc.measured else None), heard.sum(-1))


# ------------------------------------------------------------------------------------------------------ trackers

@dataclass(frozen=True)
class TrackerSettings:
    """The trackers' shared settings: ``q`` the constant-velocity model's white-acceleration variance per step
    (m^2/s^4; the discrete form, Q = q G G^T with G = [dt^2/2, dt]),
    the prior ``P_0 = diag(sd_p^2, sd_p^2, sd_v^2, sd_v^2)``, particles and the UKF's alpha."""

    q: float = 0.05
    initial_position_sd_m: float = 1.0
    initial_velocity_sd_m_s: float = 0.5
    n_particles: int = 1000
    ukf_alpha: float = 0.5
    #: the IMM's manoeuvre mode: a constant-velocity model with this many times q (locbook's choice, not a source's:
    #: a mode an order of magnitude noisier for turns and stops beside the quiet one of the single-model filters)
    imm_q_ratio: float = 10.0
    #: the IMM's probability per step of leaving a mode (locbook's choice: a mode lasts 20 steps on average)
    imm_switch_probability: float = 0.05
    #: a full position covariance of the start (m^2, (2, 2)) in place of ``initial_position_sd_m^2 I`` (measured
    #: data: the calibrated covariance of the fix the trackers start from); the particles then start with the
    #: isotropic ``sqrt(tr / 2)``
    initial_position_cov_m2: np.ndarray | None = None

    @property
    def P0(self) -> np.ndarray:
        P = np.diag([self.initial_position_sd_m**2] * 2 + [self.initial_velocity_sd_m_s**2] * 2)
        if self.initial_position_cov_m2 is not None:
            P[:2, :2] = np.asarray(self.initial_position_cov_m2, float)
        return P

    @property
    def particle_start_sd_m(self) -> float:
        """The particles' isotropic start spread (m): the position block's ``sqrt(trace / 2)``."""
        return float(np.sqrt(np.trace(self.P0[:2, :2]) / 2.0))


def initial_states(sc: TrackingScenario, ts: TrackerSettings, n_runs: int, rng: np.random.Generator) -> np.ndarray:
    """``x_0`` per run ``(R, 4)``: the scenario's ``start_state`` (measured data; no draw), else the true initial
    state plus a draw of ``N(0, P_0)`` (the prior of the bound)."""
    if sc.start_state is not None:
        return np.broadcast_to(np.asarray(sc.start_state, float), (n_runs, 4)).copy()
    return sc.initial_state() + rng.standard_normal((n_runs, 4)) @ np.linalg.cholesky(ts.P0).T


#: the KF on ML fixes uses a fix only where the epoch heard at least this many anchors (fewer leave a two-fold or
#: worse ambiguity that the fix covariance R, calibrated on well-heard epochs, does not describe: the filter predicts)
KF_FIX_MIN_ANCHORS = 3


#: the fixes of the latest :func:`ml_fixes` calls, by a digest of everything they depend on: one track's fixes are
#: asked for by the motion fit, the tracker start, the KF on fixes and the fusion trackers, and solving them is the
#: dearest step of a measured battery
_ML_FIXES_MEMO: dict[bytes, np.ndarray] = {}
_ML_FIXES_MEMO_SIZE = 16


def _ml_fixes_key(sc, flat: np.ndarray) -> bytes:
    """A digest of ``rss_ml``'s inputs: the readings, anchors, channel, tag height, the floor's box and grid."""
    digest = hashlib.blake2b(digest_size=20)
    ch = sc.channel
    parts = (flat, sc.anchors_m, sc.box_m[0], sc.box_m[1], sc.grid_m(), ch.ref_power_dbm, ch.path_loss_exp,
             ch.sigma_db, ch.ref_distance_m, ch.wall_attenuation_db, ch.min_distance_m,
             np.nan if sc.tag_height_m is None else sc.tag_height_m)
    for part in parts:
        a = np.ascontiguousarray(part, dtype=float)
        digest.update(repr(a.shape).encode())
        digest.update(a.tobytes())
    return digest.digest()


def ml_fixes(sc, rss, ts=None):
    """The ``rss_ml`` method's fixes ``(..., 2)`` (grid-ML start at the scenario's pitch, the floor's box), NaN where
    an epoch heard fewer than :data:`KF_FIX_MIN_ANCHORS` anchors: what ``kf_on_ml`` filters. The latest calls' fixes
    are kept (by a digest of every input) and handed out again as copies: the same bits, solved once."""
    flat = _flat(rss)
    key = _ml_fixes_key(sc, flat)
    if key not in _ML_FIXES_MEMO:
        heard = (~np.isnan(flat)).sum(axis=-1) >= KF_FIX_MIN_ANCHORS
        out = np.full((flat.shape[0], 2), np.nan)
        if heard.any():
            out[heard] = _rss_ml(sc, flat[heard], {})
        while len(_ML_FIXES_MEMO) >= _ML_FIXES_MEMO_SIZE:
            _ML_FIXES_MEMO.pop(next(iter(_ML_FIXES_MEMO)))
        _ML_FIXES_MEMO[key] = out
    return _ML_FIXES_MEMO[key].reshape(np.shape(rss)[:-1] + (2,)).copy()


def _fix_cov(sc, ts, rng):
    """``R`` of the KF on ML fixes: given (measured data: from the calibration set), else the covariance of RSS-ML fix
    errors along the path over 200 independent draws (a calibration stream, never the scored runs)."""
    if sc.fix_cov_m2 is not None:
        return np.asarray(sc.fix_cov_m2, float)
    rss = sc.rss_dbm(200, rng)
    fixes = ml_fixes(sc, rss, ts)
    ok = np.isfinite(fixes).all(axis=-1)
    return fix_error_covariance(fixes[ok], np.broadcast_to(sc.truth_m, fixes.shape)[ok])


def _gaussian_belief(cells, x0, P0_pos):
    inv = np.linalg.inv(P0_pos)
    d = cells[None] - x0[:, None, :2]
    logp = -0.5 * np.einsum("rci,ij,rcj->rc", d, inv, d)
    p = np.exp(logp - logp.max(axis=-1, keepdims=True))
    return p / p.sum(axis=-1, keepdims=True)


TRACKERS = {
    "kf_on_ml": "constant-velocity KF on the rss_ml fixes of epochs that heard at least 3 anchors (R: fix-error "
                "covariance from a calibration stream)",
    "ekf": "constant-velocity EKF on the raw RSS, parallel (stacked) update",
    "ekf_serial": "constant-velocity EKF on the raw RSS, serial scalar updates (descending RSS)",
    "ukf": "constant-velocity UKF on the raw RSS",
    "imm": "IMM of two constant-velocity modes (q and imm_q_ratio x q, switching with imm_switch_probability per "
           "step), an EKF per mode on the raw RSS, parallel update",
    "particle": "SIR particle filter, random walk (spread per step) reflected into the floor's box, resampled at "
                "N_eff < N/2",
    "grid_bayes": "grid Bayes filter, the same random walk on a grid inside the floor (separable transition)",
}


_KALMAN_PRIOR = ("the posterior bound is that of the filter's own constant-velocity model; a path smoother than the "
                 "model (straight lines at a steady pace) lets a filter beat it")
_WALK_PRIOR = "its random walk stays inside the floor (the posterior bound knows no floor)"
#: why each tracker may fall below the posterior CRLB (Method.prior of the static methods)
TRACKER_PRIORS = {"kf_on_ml": _KALMAN_PRIOR + "; its fixes lie in the floor's bounding box", "ekf": _KALMAN_PRIOR,
                  "ekf_serial": _KALMAN_PRIOR, "ukf": _KALMAN_PRIOR,
                  "imm": "the posterior bound is that of one constant-velocity model (the quiet mode's)",
                  "particle": _WALK_PRIOR,
                  "grid_bayes": _WALK_PRIOR}


def run_trackers(sc: TrackingScenario, rss_dbm, x0, ts: TrackerSettings, rng: np.random.Generator, *,
                 trackers=None, with_divergence: bool = False):
    """Every declared tracker on readings ``(R, T, m)`` from initial states ``(R, 4)`` -> positions ``(R, T, 2)``.
    ``with_divergence=True`` returns ``(positions, {tracker: flags})``, the NIS guard per run of each Kalman-family
    tracker (:class:`locbook.tracking.divergence.DivergenceFlags`, steps of the scenario's clock). ``trackers``: names
    of :data:`TRACKERS` (default: all of them); the fusion trackers of a track with an inertial stream are run by
    :func:`locbook.inertial_trackers.run_fusion`, which builds on this module."""
    rss = np.asarray(rss_dbm, float)
    rng_cov, rng_pf = rng.spawn(2)
    chosen = tuple(TRACKERS if trackers is None else trackers)
    unknown = [t for t in chosen if t not in TRACKERS]
    if unknown:
        raise ParameterError(f"run_trackers runs the battery's trackers {TRACKERS}, got {unknown}; the fusion "
                             "trackers are locbook.inertial_trackers.run_fusion's")
    motion = constant_velocity(sc.dt_s, ts.q, dim=2)
    P0 = np.broadcast_to(ts.P0, (len(x0), 4, 4))
    idx = np.array([0, 1])
    out, flags = {}, {}
    if "kf_on_ml" in chosen:
        H = np.hstack([np.eye(2), np.zeros((2, 2))])
        fixes = ml_fixes(sc, rss, ts)
        res = extended_kalman_filter(motion.F, motion.Q, x0, P0,
                                     [LinearMeasurement(fixes, H, _fix_cov(sc, ts, rng_cov))])
        out["kf_on_ml"], flags["kf_on_ml"] = res.position_m([0, 1]), DivergenceFlags.of(res)
    for name, mode in (("ekf", "parallel"), ("ekf_serial", "serial")):
        if name in chosen:
            stream = RssMeasurement(rss, sc.anchors_m, sc.channel, idx, mode=mode, tag_height_m=sc.tag_height_m)
            res = extended_kalman_filter(motion.F, motion.Q, x0, P0, [stream])
            out[name], flags[name] = res.position_m([0, 1]), DivergenceFlags.of(res)
    if "ukf" in chosen:
        stream = RssMeasurement(rss, sc.anchors_m, sc.channel, idx, tag_height_m=sc.tag_height_m)
        res = unscented_kalman_filter(motion.F, motion.Q, x0, P0, [stream], alpha=ts.ukf_alpha)
        out["ukf"], flags["ukf"] = res.position_m([0, 1]), DivergenceFlags.of(res)
    if "imm" in chosen:
        stream = RssMeasurement(rss, sc.anchors_m, sc.channel, idx, tag_height_m=sc.tag_height_m)
        agile = constant_velocity(sc.dt_s, ts.q * ts.imm_q_ratio, dim=2)
        p = ts.imm_switch_probability
        res = imm_filter([motion, agile], [[1.0 - p, p], [p, 1.0 - p]], x0, P0, [stream])
        out["imm"] = res.position_m([0, 1])
    model = _bayes_model(sc)
    if "particle" in chosen:
        out["particle"] = particle_filter(rss, model, rng=rng_pf, n_particles=ts.n_particles, region_m=sc.box_m,
                                          spread_m=sc.spread_m, initial_position_m=x0[:, :2],
                                          initial_sd_m=ts.particle_start_sd_m, resample_threshold=0.5).mean
    if "grid_bayes" in chosen:
        cells = grid_in_outline(sc.outline_m, sc.grid_spacing_m)
        out["grid_bayes"] = grid_bayes_filter(rss, model, cells, sc.spread_m,
                                              initial_belief=_gaussian_belief(cells, x0, ts.P0[:2, :2])).mean
    out = {k: out[k] for k in chosen}
    return (out, flags) if with_divergence else out


def tracking_bound_m(sc: TrackingScenario, ts: TrackerSettings, *, extra_position_information=None) -> np.ndarray:
    """Position PCRLB ``(T,)`` at every tick: the Tichavsky recursion of the constant-velocity model (``ts.q``) from
    ``J_0 = P_0^-1``, with the RSS information at the true positions (only the anchors heard, for measured data; a
    tick with no truth or no reading adds none). Tick ``k`` is ``J_{k+1}`` (the filters predict before each step).
    ``extra_position_information`` ``(T, 2, 2)``: the information of another stream about the position at each
    tick (independent of the RSS: the information matrices add), e.g. the ranges'
    (:func:`locbook.bounds.crlb.range_position_information`)."""
    motion = constant_velocity(sc.dt_s, ts.q, dim=2)
    truth = np.where(np.isfinite(sc.truth_m), sc.truth_m, 0.0)
    states = np.concatenate([truth, np.zeros_like(truth)], axis=-1)
    heard = np.isfinite(sc.truth_m).all(axis=-1)[:, None]
    if sc.measured:
        heard = heard & ~np.isnan(sc.measured_rss_dbm)
    ch = sc.channel
    model = RssModel(sc.anchors_m, PathLossModel(0.0, ch.path_loss_exp, ch.sigma_db, min_distance_m=ch.min_distance_m),
                     tag_height_m=sc.tag_height_m)
    jz = rss_state_information(states, model, [0, 1], heard=heard)
    if extra_position_information is not None:
        jz = jz.copy()
        jz[..., :2, :2] += np.asarray(extra_position_information, float)
    info = posterior_crlb(np.linalg.inv(ts.P0), motion.F, motion.Q, jz, form="riccati")
    return position_bound_m(info[1:], [0, 1])
