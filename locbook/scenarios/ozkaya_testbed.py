"""Document 004 (Ozkaya 2011), Chapter 7 experiments (Sec. 7.3) on a synthetic two-room test bed.

The thesis measured one home (two rooms, 3 m x 4 m and 6 m x 4 m, a brick wall between them, three readers,
four reference tags) and prints no raw RSSI and no coordinates. This module builds a synthetic stand-in
with every unprinted quantity a named, documented assumption (note 004 sections 6 and 9):

* the layout of note 004 s.6.1 (``TESTBED_*`` constants of :mod:`locbook.scenarios.ozkaya`, plus the test
  points, pattern locations and paths below);
* a channel (:class:`TestbedChannel`) whose mean is the offline calibration of Table 6.1 with WAF = 2 dB, and
  whose randomness is the sum of a static, spatially correlated shadowing field per reader (it is what makes
  pattern maps and reference-tag smoothing work), a per-visit tag-orientation offset, i.i.d. dynamic noise per
  reading (people moving), and reader-wide attenuation bursts (a person near a reader); the components add up
  to the printed sigma of 5.2 dB; 1 dB reader resolution and the -90 dBm sensitivity floor;
* "realizations": independent test beds (shadowing fields). The thesis measured one, so every statistic is
  computed per realization and averaged, and the spread across realizations says how far a single test bed
  could fall from that average.

Methods (Sec. 7.3.1.3) are in :data:`METHODS`; experiments (fixed target, mobile target, dynamic noise,
obstructed readers, monopole reader antennas) in :data:`EXPERIMENTS`. Every printed cell of Tables 7.26-7.44
is mapped to (experiment, method, statistic) by :data:`TABLE_CELLS`, and the thesis's rankings of methods by
:data:`RANKINGS`.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..tracking.bayes import RssMeasurementModel, grid_bayes_filter, particle_filter
from ..models.channel import PathLossModel, correlated_shadowing_db, pairwise_distance_m, quantize_db
from ..static.fingerprint import knn_position, model_fingerprints
from ..metrics import position_error_m
from ..static.reference_tags import calibrate_from_reference_tags, smooth_rssi
from . import ozkaya as oz

__all__ = [
    "TestbedChannel", "MethodSettings", "Method", "METHODS", "EXPERIMENTS", "TABLE_CELLS", "RANKINGS",
    "TESTBED_CELLS_M", "FIXED_POINTS_M", "PATTERN_EXCLUDED_CELLS_M", "PATTERN_LOCATIONS_M", "MOBILE_PATHS_M",
    "DYNAMIC_POINTS_M", "OBSTRUCTION_POINTS_M", "NEAR_TAG_RADIUS_M", "MONOPOLE_NOISE_SCALE",
    "Testbed", "draw_testbed", "measure_sessions", "measure_pattern_map", "ExperimentResult", "run_testbed",
    "per_realization_statistics", "table_rows", "ranking_rows", "TESTBED_TOLERANCE_BASIS", "miss_note", "ranking_note",
    "near_tag_mask", "METHOD_LABELS", "MOBILE_VELOCITY_M",
]

#: 36 cells of 1 m (k_CELL = 36, Sec. 7.3.1): centres (i + 0.5, j + 0.5), i = 0..8, j = 0..3.
TESTBED_CELLS_M = oz.cell_centres(oz.TESTBED_SIZE_M, 9, 4, margin_m=0.0)
#: 25 fixed test points "starting 1 m from the surrounding walls" (Fig. 7.21, not printed): ASSUMED 5 x 5 lattice
#: x in {1, 2.75, 4.5, 6.25, 8}, y in {1, 1.5, 2, 2.5, 3}.
FIXED_POINTS_M = np.stack(np.meshgrid(np.linspace(1.0, 8.0, 5), np.linspace(1.0, 3.0, 5), indexing="ij"), -1).reshape(-1, 2)
#: The pattern map has 32 "furniture-dependent" locations about 1 m apart (Sec. 6.3): ASSUMED the 36 cell
#: centres less four furniture-occupied cells spread over both rooms.
PATTERN_EXCLUDED_CELLS_M = ((0.5, 3.5), (2.5, 0.5), (5.5, 3.5), (8.5, 1.5))
PATTERN_LOCATIONS_M = np.array([c for c in TESTBED_CELLS_M.tolist()
                                if tuple(c) not in set(PATTERN_EXCLUDED_CELLS_M)])
#: Constant-velocity paths of Fig. 7.22: +0.5 m per recursion along y, small room y 0 -> 3.5, large room
#: y 0 -> 4 (Sec. 7.3.1). The x of each path is not printed: ASSUMED the middle of each room.
MOBILE_PATHS_M = {
    "small room": np.stack([np.full(8, 1.5), np.arange(8) * 0.5], -1),
    "large room": np.stack([np.full(9, 6.0), np.arange(9) * 0.5], -1),
}
MOBILE_VELOCITY_M = (0.0, 0.5)
#: Dynamic-noise experiment: 3 "central" locations (not printed; ASSUMED one in the small room, two in the large).
DYNAMIC_POINTS_M = ((1.5, 2.0), (4.5, 2.5), (6.5, 2.0))
#: Obstructed-reader experiment: 3 locations, two of them next to reference tags (Sec. 7.3.2.3); ASSUMED
#: 0.5 m from T1 and from T4, and one far from every tag.
OBSTRUCTION_POINTS_M = ((1.5, 2.0), (5.0, 2.5), (7.5, 2.0))
#: Table 7.36: test points "within 1.5 m" of a reference tag.
NEAR_TAG_RADIUS_M = 1.5
#: Monopole reader antennas: the auto-calibrated sigma averaged 7.5 dB against 5.3 dB (Table 6.2) with the patch
#: (Sec. 7.3.2.6); both are the same estimator (Eq. (6.7)), so the random components are scaled by their ratio.
MONOPOLE_NOISE_SCALE = 7.5 / 5.3


@dataclass(frozen=True)
class TestbedChannel:
    """The synthetic test bed's RSSI (dBm) for reader j at position p, step t (all values ASSUMED unless noted).

    ``RSSI = alpha_j - 10 n_j log10(d) - n_W WAF + S_j(p) + O_j + e_jt + b_jt - L_j``, quantised to
    ``resolution_db`` (None: not quantised) and floored at ``floor_dbm`` (Sec. 6.2: 1 dB resolution, -90 dBm sensitivity), where

    * ``alpha_j, n_j, WAF``: Table 6.1 (offline calibration; the most careful measurement in the thesis);
    * ``S_j(p)``: static shadowing, a Gaussian field per reader with exponential correlation
      (``static_sigma_db``, ``decorrelation_m``; note 004 s.9 suggests about 4 dB and 1-2 m);
    * ``O_j``: tag orientation, drawn once per visit of a point or pass of a path (the tag is re-oriented
      between visits, Sec. 7.3.1; calibrated to be nearly omnidirectional, hence small);
    * ``e_jt``: dynamic noise, i.i.d. per reading (``dynamic_sigma_db``; note 004 s.9: about 3 dB, the
      figure the thesis quotes for a home [14]);
    * ``b_jt``: a burst loss common to every tag seen by reader j (a person next to the reader), with
      probability ``burst_probability`` per step and a loss uniform in ``burst_loss_db``;
    * ``L_j``: an extra obstruction loss (obstructed-reader experiment only).

    With the defaults ``sqrt(4^2 + 1.5^2 + 3^2) = 5.2 dB``: the printed sigma of Table 6.1.
    ``noise_scale`` multiplies S, O and e (monopole reader antennas).
    """

    ref_power_dbm: tuple = oz.OFFLINE_PARAMETERS["alpha_dbm"]
    path_loss_exp: tuple = oz.OFFLINE_PARAMETERS["path_loss_exp"]
    waf_db: float = oz.WAF_DB
    static_sigma_db: float = 4.0
    decorrelation_m: float = 1.5
    orientation_sigma_db: float = 1.5
    dynamic_sigma_db: float = 3.0
    burst_probability: float = 0.05
    burst_loss_db: tuple = (5.0, 10.0)
    noise_scale: float = 1.0
    resolution_db: float | None = 1.0
    floor_dbm: float = oz.READER_SENSITIVITY_DBM

    def __post_init__(self):
        for name in ("static_sigma_db", "orientation_sigma_db", "dynamic_sigma_db", "noise_scale", "decorrelation_m"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be non-negative, got {getattr(self, name)}")
        if not 0.0 <= self.burst_probability <= 1.0:
            raise ValueError(f"burst_probability must be in [0, 1], got {self.burst_probability}")
        if len(self.ref_power_dbm) != len(oz.TESTBED_READERS_M) or len(self.path_loss_exp) != len(oz.TESTBED_READERS_M):
            raise ValueError("ref_power_dbm and path_loss_exp need one value per test-bed reader (3)")

    @property
    def total_sigma_db(self) -> float:
        """Standard deviation of a reading about the mean model, bursts excluded."""
        return self.noise_scale * float(np.sqrt(self.static_sigma_db**2 + self.orientation_sigma_db**2
                                                + self.dynamic_sigma_db**2))

    def mean_rss_dbm(self, points_m):
        """Mean RSSI ``(P, m)`` at points ``(P, 2)``: Eq. (6.3)/(6.4) with the wall at x = 3 m."""
        model = PathLossModel(np.asarray(self.ref_power_dbm, float), np.asarray(self.path_loss_exp, float),
                              wall_attenuation_db=self.waf_db)
        return model_fingerprints(points_m, oz.TESTBED_READERS_M, model, oz.TESTBED_WALLS_M)


@dataclass(frozen=True)
class Testbed:
    """``n_realizations`` independent test beds: the static field ``field_db (Z, P, m)`` at ``points_m (P, 2)``
    (every location any experiment uses) and the reference tags' orientation offsets ``(Z, K, m)``."""

    channel: TestbedChannel
    points_m: np.ndarray
    field_db: np.ndarray
    tag_orientation_db: np.ndarray

    def index(self, positions_m) -> np.ndarray:
        """Indices into ``points_m`` of positions ``(..., 2)`` (which must be among them)."""
        positions_m = np.asarray(positions_m, float)
        d = np.abs(positions_m[..., None, :] - self.points_m).max(-1)
        idx = d.argmin(-1)
        if np.any(np.take_along_axis(d, idx[..., None], -1) > 1e-9):
            raise ValueError("a measured position is not one of the test bed's points; add it to draw_testbed")
        return idx


def _all_points():
    sets = [FIXED_POINTS_M, oz.REFERENCE_TAGS_M, PATTERN_LOCATIONS_M, DYNAMIC_POINTS_M, OBSTRUCTION_POINTS_M,
            *MOBILE_PATHS_M.values()]
    # duplicates would make the field's covariance singular
    return np.unique(np.round(np.concatenate([np.asarray(s, float) for s in sets]), 9), axis=0)


def draw_testbed(channel: TestbedChannel, n_realizations: int, rng: np.random.Generator) -> Testbed:
    """Draw the static shadowing field (independent per reader and realization) and the reference tags'
    orientation offsets."""
    if n_realizations < 1:
        raise ValueError(f"n_realizations must be positive, got {n_realizations}")
    points = _all_points()
    m = len(oz.TESTBED_READERS_M)
    field_db = correlated_shadowing_db(points, channel.noise_scale * channel.static_sigma_db, channel.decorrelation_m,
                                       rng, size=(n_realizations, m))                     # (Z, m, P)
    tag_o = channel.noise_scale * channel.orientation_sigma_db * rng.standard_normal(
        (n_realizations, len(oz.REFERENCE_TAGS_M), m))
    return Testbed(channel, points, np.swapaxes(field_db, -1, -2), tag_o)


def _bursts(channel, shape, rng, probability):
    lo, hi = channel.burst_loss_db
    hit = rng.random(shape) < probability
    return -np.where(hit, lo + (hi - lo) * rng.random(shape), 0.0)


def _read(channel, power_dbm):
    """What the reader reports: ``resolution_db`` steps (None: no quantisation) and the sensitivity floor."""
    if channel.resolution_db is None:
        return np.maximum(power_dbm, channel.floor_dbm)
    return quantize_db(power_dbm, channel.resolution_db, channel.floor_dbm)


def measure_sessions(testbed: Testbed, positions_m, rng: np.random.Generator, *,
                     burst_probability: float | None = None, extra_loss_db=None):
    """RSSI of the target and of the four reference tags over sessions.

    ``positions_m (S, T, 2)``: the target's position at each step of each session (a visit of a fixed point,
    or a pass along a path). The reference tags are read at the same steps and share the reader-wide terms
    (bursts, obstruction). ``extra_loss_db (Z, m)``: obstruction loss per realization and reader.
    Returns ``target (Z, S, T, m)`` and ``tags (Z, S, T, K, m)``, quantised and floored.
    """
    ch = testbed.channel
    p = ch.burst_probability if burst_probability is None else burst_probability
    positions_m = np.asarray(positions_m, float)
    n_sessions, n_steps = positions_m.shape[:2]
    z, _, m = testbed.field_db.shape
    idx = testbed.index(positions_m)                                                   # (S, T)
    tag_idx = testbed.index(oz.REFERENCE_TAGS_M)                                       # (K,)
    k = tag_idx.size
    scale = ch.noise_scale
    common = _bursts(ch, (z, n_sessions, n_steps, m), rng, p)
    if extra_loss_db is not None:
        common = common - np.asarray(extra_loss_db, float)[:, None, None, :]
    orient = scale * ch.orientation_sigma_db * rng.standard_normal((z, n_sessions, 1, m))
    target = (ch.mean_rss_dbm(positions_m.reshape(-1, 2)).reshape(n_sessions, n_steps, m)
              + testbed.field_db[:, idx] + orient + common
              + scale * ch.dynamic_sigma_db * rng.standard_normal((z, n_sessions, n_steps, m)))
    tag_static = ch.mean_rss_dbm(oz.REFERENCE_TAGS_M) + testbed.field_db[:, tag_idx] + testbed.tag_orientation_db
    tags = (tag_static[:, None, None] + common[..., None, :]
            + scale * ch.dynamic_sigma_db * rng.standard_normal((z, n_sessions, n_steps, k, m)))
    return _read(ch, target), _read(ch, tags)


def measure_pattern_map(testbed: Testbed, rng: np.random.Generator, n_samples: int = 40):
    """Pattern (RADAR) map of Sec. 6.3: at each of :data:`PATTERN_LOCATIONS_M`, ``n_samples`` readings with the tag
    re-oriented each time (fresh orientation, dynamic noise and bursts), quantised; only the mean vector is kept.
    The 20 cm x 20 cm patch is far below the field's correlation length, so the static field is the
    location's. Returns ``(Z, C, m)``."""
    ch = testbed.channel
    z, _, m = testbed.field_db.shape
    idx = testbed.index(PATTERN_LOCATIONS_M)
    shape = (z, idx.size, n_samples, m)
    samples = (ch.mean_rss_dbm(PATTERN_LOCATIONS_M)[:, None, :] + testbed.field_db[:, idx, None, :]
               + ch.noise_scale * (ch.orientation_sigma_db * rng.standard_normal(shape)
                                   + ch.dynamic_sigma_db * rng.standard_normal(shape))
               + _bursts(ch, shape, rng, ch.burst_probability))
    return _read(ch, samples).mean(axis=-2)


# -- methods of Sec. 7.3.1.3 ------------------------------------------------------------------------------
@dataclass(frozen=True)
class MethodSettings:
    """Sec. 7.3.1.3 defaults: k_NN = k_CELL = 36, sigma = 5.2 dB, N = 10000, N_t = 0.5, D = 0.5 m (D_0 = 0.5 m
    with the known velocity of the mobile test), smoothing threshold 0.4 (Sec. 7.1.5.3)."""

    k_nn: int = 36
    sigma_db: float = 5.2
    spread_m: float = 0.5
    n_particles: int = 10000
    resample_threshold: float = 0.5
    smoothing_threshold: float = 0.4
    #: 0: the pooled sigma of Eq. (6.7) as printed; 6 (= 2 parameters x 3 readers): degrees-of-freedom corrected
    sigma_ddof: int = 0
    #: particle filters run in blocks of at most this many (run x particle) pairs, to bound memory
    max_particle_runs: int = 2_000_000


@dataclass(frozen=True)
class Method:
    """One localization method of Sec. 7.3.1.3: ``estimator`` nn | grid | sir; ``parameters`` pattern |
    offline (Table 6.1) | online (reference tags, every step); ``online_sigma`` uses the pooled sigma of
    Eq. (6.7) instead of the fixed 5.2 dB; ``smoothing`` applies the RSSI smoothing of Sec. 7.1.5.3;
    ``k_nn`` overrides the settings' k_NN."""

    estimator: str
    parameters: str = "online"
    online_sigma: bool = False
    smoothing: bool = False
    k_nn: int | None = None


METHODS = {
    "pattern_nn": Method("nn", "pattern"),
    "offline_nn": Method("nn", "offline"),
    "offline_nn_k4": Method("nn", "offline", k_nn=4),
    "offline_nn_k18": Method("nn", "offline", k_nn=18),
    "online_nn": Method("nn", "online"),
    "grid": Method("grid"),
    "grid_sigma": Method("grid", online_sigma=True),
    "grid_smoothing": Method("grid", smoothing=True),
    "sir": Method("sir"),
    "sir_sigma_smoothing": Method("sir", online_sigma=True, smoothing=True),
}
METHOD_LABELS = {
    "pattern_nn": "pattern-based NN", "offline_nn": "offline parameter-based NN", "offline_nn_k4": "offline NN, k = 4",
    "offline_nn_k18": "offline NN, k = 18", "online_nn": "online parameter-based NN", "grid": "grid Bayes",
    "grid_sigma": "grid Bayes + online sigma", "grid_smoothing": "grid Bayes + RSSI smoothing", "sir": "improved SIR",
    "sir_sigma_smoothing": "improved SIR + online sigma + RSSI smoothing",
}

#: Which methods each experiment runs (the union of what Tables 7.26-7.44 print for it).
EXPERIMENTS = {
    "fixed": ("pattern_nn", "offline_nn", "offline_nn_k4", "offline_nn_k18", "online_nn", "grid", "grid_sigma",
              "grid_smoothing", "sir"),
    "mobile": ("offline_nn", "online_nn", "grid", "grid_sigma", "grid_smoothing", "sir", "sir_sigma_smoothing"),
    "dynamic": ("offline_nn", "online_nn", "grid", "grid_sigma", "grid_smoothing", "sir"),
    "obstructed": ("offline_nn", "online_nn", "grid", "grid_smoothing"),
    "monopole": ("online_nn", "grid", "grid_sigma", "sir", "sir_sigma_smoothing"),
}


def _estimate(method: Method, rss, tags, calibration, settings: MethodSettings, pattern_map, velocity_m,
              seed_sequence: np.random.SeedSequence):
    """Positions ``(R, T, 2)`` from target RSSI ``(R, T, m)`` and tag RSSI ``(R, T, K, m)``."""
    readers = np.asarray(oz.TESTBED_READERS_M)
    walls = np.asarray(oz.TESTBED_WALLS_M)
    k = settings.k_nn if method.k_nn is None else method.k_nn
    if method.smoothing:
        rss, _, _ = smooth_rssi(rss, tags, calibration.expected_dbm, settings.smoothing_threshold)
    if method.parameters == "pattern":
        fp = pattern_map[:, None]                                                  # (R, 1, C, m)
        return knn_position(rss, fp, PATTERN_LOCATIONS_M, min(k, PATTERN_LOCATIONS_M.shape[0]))
    if method.parameters == "offline":
        alpha, n = np.asarray(oz.OFFLINE_PARAMETERS["alpha_dbm"]), np.asarray(oz.OFFLINE_PARAMETERS["path_loss_exp"])
    else:
        alpha, n = calibration.ref_power_dbm, calibration.path_loss_exp                # (R, T, m)
    if method.estimator == "nn":
        fp = model_fingerprints(TESTBED_CELLS_M, readers, PathLossModel(alpha, n, wall_attenuation_db=oz.WAF_DB), walls)
        return knn_position(rss, fp, TESTBED_CELLS_M, min(k, TESTBED_CELLS_M.shape[0]))
    sigma = calibration.sigma_db if method.online_sigma else settings.sigma_db
    model = RssMeasurementModel(readers, alpha, n, sigma, oz.WAF_DB, walls)
    if method.estimator == "grid":
        return grid_bayes_filter(rss, TESTBED_CELLS_M, model, settings.spread_m, velocity_m=velocity_m).mmse_m
    if method.estimator != "sir":
        raise ValueError(f"unknown estimator {method.estimator!r}")
    n_runs = rss.shape[0]
    block = max(1, settings.max_particle_runs // settings.n_particles)
    starts = range(0, n_runs, block)
    out = []
    for start, child in zip(starts, seed_sequence.spawn(len(starts))):
        sl = slice(start, start + block)
        part = lambda v: v[sl] if np.ndim(v) >= 2 else v
        block_model = replace(model, ref_power_dbm=part(alpha), path_loss_exp=part(n), sigma_db=part(sigma))
        res = particle_filter(rss[sl], block_model, np.random.default_rng(child), n_particles=settings.n_particles,
                              region_m=((0.0, 0.0), oz.TESTBED_SIZE_M), spread_m=settings.spread_m,
                              velocity_m=velocity_m, resample_threshold=settings.resample_threshold,
                              weight_smoothing="sqrt")
        out.append(res.mmse_m)
    return np.concatenate(out, axis=0)


@dataclass
class ExperimentResult:
    """``truth_m (S, T, 2)``; ``estimates[method]`` and ``errors[method]``: ``(Z, S, T, 2)`` and ``(Z, S, T)``;
    ``online_sigma_db (Z, S, T)``, ``online_alpha_dbm``/``online_path_loss_exp`` ``(Z, S, T, m)``: the
    per-step reference-tag calibration; ``target_rss_dbm (Z, S, T, m)``."""

    name: str
    truth_m: np.ndarray
    estimates: dict = field(default_factory=dict)
    errors: dict = field(default_factory=dict)
    online_sigma_db: np.ndarray | None = None
    online_alpha_dbm: np.ndarray | None = None
    online_path_loss_exp: np.ndarray | None = None
    target_rss_dbm: np.ndarray | None = None


def _run_experiment(name, testbed, truth_m, methods, settings, pattern_map, rng_ss: np.random.SeedSequence, *,
                    velocity_m=None, burst_probability=None, extra_loss_db=None) -> ExperimentResult:
    # one stream per method name, so running a subset of methods does not change any method's numbers
    meas_ss, *children = rng_ss.spawn(1 + len(METHODS))
    method_ss = dict(zip(METHODS, children))
    target, tags = measure_sessions(testbed, truth_m, np.random.default_rng(meas_ss),
                                    burst_probability=burst_probability, extra_loss_db=extra_loss_db)
    z, s, t, m = target.shape
    rss = target.reshape(z * s, t, m)
    tag_rss = tags.reshape(z * s, t, *tags.shape[-2:])
    cal = calibrate_from_reference_tags(tag_rss, oz.REFERENCE_TAGS_M, oz.TESTBED_READERS_M,
                                        walls_m=oz.TESTBED_WALLS_M, wall_attenuation_db=oz.WAF_DB,
                                        sigma_ddof=settings.sigma_ddof)
    fp = None if pattern_map is None else np.repeat(pattern_map, s, axis=0)              # (Z*S, C, m)
    result = ExperimentResult(name, np.asarray(truth_m, float), online_sigma_db=cal.sigma_db.reshape(z, s, t),
                              online_alpha_dbm=cal.ref_power_dbm.reshape(z, s, t, m),
                              online_path_loss_exp=cal.path_loss_exp.reshape(z, s, t, m), target_rss_dbm=target)
    for key in methods:
        est = _estimate(METHODS[key], rss, tag_rss, cal, settings, fp, velocity_m, method_ss[key]).reshape(z, s, t, 2)
        result.estimates[key] = est
        result.errors[key] = position_error_m(est, result.truth_m)
    return result


def run_testbed(n_realizations: int, seed: int, *, channel: TestbedChannel = TestbedChannel(),
                settings: MethodSettings = MethodSettings(), experiments=tuple(EXPERIMENTS), fixed_steps: int = 30,
                mobile_passes: int = 10, pattern_samples: int = 40, dynamic_burst_probability: float = 0.3,
                obstruction_loss_db=(5.0, 10.0), monopole_noise_scale: float = MONOPOLE_NOISE_SCALE,
                methods=None) -> dict[str, ExperimentResult]:
    """Run the experiments of Sec. 7.3 on ``n_realizations`` independent synthetic test beds.

    * fixed: each of :data:`FIXED_POINTS_M` visited once for ``fixed_steps`` estimates (25 x 30 = 750 in the
      thesis); filters restart at every point (note 004 s.11.14).
    * mobile: each path of :data:`MOBILE_PATHS_M` walked ``mobile_passes`` times (the count is not printed),
      one estimate per step, velocity known to the filters (Sec. 7.3.1.3).
    * dynamic: :data:`DYNAMIC_POINTS_M` x ``fixed_steps`` with people moving around target and readers:
      reader bursts with probability ``dynamic_burst_probability`` per step (ASSUMED).
    * obstructed: :data:`OBSTRUCTION_POINTS_M` x ``fixed_steps``; metal objects in front of every reader add a loss
      uniform in ``obstruction_loss_db`` per reader (note 004 s.9: 5-10 dB), to target and tags alike.
    * monopole: the mobile experiment on a fresh test bed whose random components are scaled by
      ``monopole_noise_scale``; the fixed-sigma filters still assume 5.2 dB (Sec. 7.3.2.6).

    The reference tags are read at every step (Sec. 6.2) and calibrate alpha, n per reader and the pooled sigma.
    ``methods`` restricts the methods run (default: :data:`EXPERIMENTS`). Same arguments, same numbers.
    """
    unknown = set(experiments) - set(EXPERIMENTS)
    if unknown:
        raise ValueError(f"unknown experiments {sorted(unknown)}; choose from {list(EXPERIMENTS)}")
    if methods is not None and set(methods) - set(METHODS):
        raise ValueError(f"unknown methods {sorted(set(methods) - set(METHODS))}; choose from {list(METHODS)}")
    root = np.random.SeedSequence(seed)
    bed_ss, pattern_ss, mono_ss, loss_ss, *exp_ss = root.spawn(4 + len(EXPERIMENTS))
    exp_ss = dict(zip(EXPERIMENTS, exp_ss))       # keyed by name: running a subset does not change the numbers
    testbed = draw_testbed(channel, n_realizations, np.random.default_rng(bed_ss))
    pattern_map = measure_pattern_map(testbed, np.random.default_rng(pattern_ss), pattern_samples)
    lo, hi = obstruction_loss_db
    obstruction = lo + (hi - lo) * np.random.default_rng(loss_ss).random((n_realizations, len(oz.TESTBED_READERS_M)))
    pick = lambda name: tuple(mm for mm in EXPERIMENTS[name] if methods is None or mm in methods)

    def hold(points):
        return np.repeat(np.asarray(points, float)[:, None, :], fixed_steps, axis=1)

    out = {}
    for name in experiments:
        kwargs = {}
        if name in ("mobile", "monopole"):
            bed = testbed if name == "mobile" else draw_testbed(
                replace(channel, noise_scale=channel.noise_scale * monopole_noise_scale), n_realizations,
                np.random.default_rng(mono_ss))
            subs = []
            for path, path_ss in zip(MOBILE_PATHS_M.values(), exp_ss[name].spawn(len(MOBILE_PATHS_M))):
                truth = np.repeat(path[None], mobile_passes, axis=0)
                subs.append(_run_experiment(name, bed, truth, pick(name), settings, None, path_ss,
                                            velocity_m=MOBILE_VELOCITY_M))
            out[name] = _merge_paths(name, subs)
            continue
        if name == "fixed":
            truth = hold(FIXED_POINTS_M)
        elif name == "dynamic":
            truth, kwargs = hold(DYNAMIC_POINTS_M), {"burst_probability": dynamic_burst_probability}
        else:
            truth, kwargs = hold(OBSTRUCTION_POINTS_M), {"extra_loss_db": obstruction}
        out[name] = _run_experiment(name, testbed, truth, pick(name), settings,
                                    pattern_map if name == "fixed" else None, exp_ss[name], **kwargs)
    return out


def _merge_paths(name, subs) -> ExperimentResult:
    """Paths have different lengths: flatten (session, step) into one estimate axis, ``S = 1``."""
    def cat(arrays):
        return np.concatenate([a.reshape(a.shape[0], 1, -1, *a.shape[3:]) for a in arrays], axis=2)
    truth = np.concatenate([s.truth_m.reshape(1, -1, 2) for s in subs], axis=1)
    res = ExperimentResult(name, truth, online_sigma_db=cat([s.online_sigma_db for s in subs]),
                           online_alpha_dbm=cat([s.online_alpha_dbm for s in subs]),
                           online_path_loss_exp=cat([s.online_path_loss_exp for s in subs]),
                           target_rss_dbm=cat([s.target_rss_dbm for s in subs]))
    for key in subs[0].errors:
        res.estimates[key] = cat([s.estimates[key] for s in subs])
        res.errors[key] = cat([s.errors[key] for s in subs])
    return res


# -- statistics, printed tables, rankings -----------------------------------------------------------------
def per_realization_statistics(errors_m, mask=None) -> dict[str, np.ndarray]:
    """Statistics of the thesis's tables over each realization's estimates: ``errors_m (Z, S, T)`` -> ``(Z,)``
    arrays of rmse, mean, median, 90th percentile and std (ddof 0). ``mask (S,)`` keeps some sessions."""
    e = np.asarray(errors_m, float)
    if mask is not None:
        e = e[:, np.asarray(mask, bool)]
    e = e.reshape(e.shape[0], -1)
    return {"rmse_m": np.sqrt(np.mean(e**2, -1)), "mean_m": e.mean(-1), "median_m": np.median(e, -1),
            "p90_m": np.percentile(e, 90, axis=-1), "std_m": e.std(-1)}


def near_tag_mask(points_m=FIXED_POINTS_M, radius_m: float = NEAR_TAG_RADIUS_M):
    """Test points within ``radius_m`` of a reference tag (Table 7.36)."""
    return pairwise_distance_m(np.asarray(points_m, float), np.asarray(oz.REFERENCE_TAGS_M)).min(-1) <= radius_m


_ROW_METHOD = {
    "Pattern-based NN": "pattern_nn", "Offline parameter-based NN": "offline_nn", "Parameter-based offline NN": "offline_nn",
    "Offline NN": "offline_nn", "Online NN": "online_nn", "Parameter-based online NN": "online_nn",
    "Grid-based Bayesian": "grid", "Grid Bayes": "grid", "Improved SIR": "sir", "Grid Bayes + auto σ": "grid_sigma",
    "Grid Bayes + RSSI smoothing": "grid_smoothing", "Grid Bayes + smoothing": "grid_smoothing",
    "Grid Bayes + online σ": "grid_sigma", "Improved SIR + online σ + RSSI smoothing": "sir_sigma_smoothing",
    "Improved SIR + online σ + smoothing": "sir_sigma_smoothing",
}
#: table -> experiment (and the subset of sessions for Table 7.36)
_TABLE_EXPERIMENT = {"7.26": "fixed", "7.27": "fixed", "7.28": "fixed", "7.29": "fixed", "7.30": "mobile",
                     "7.31": "dynamic", "7.32": "fixed", "7.33": "mobile", "7.34": "dynamic", "7.35": "fixed",
                     "7.36": "fixed_near_tags", "7.37": "mobile", "7.38": "obstructed", "7.39": "mobile",
                     "7.40": "mobile", "7.41": "fixed", "7.42": "mobile", "7.43": "dynamic", "7.44": "obstructed"}


def _cell(table: str, row: str, column: str):
    """(experiment, method, statistic) of one printed cell of Tables 7.26-7.44."""
    experiment = _TABLE_EXPERIMENT[table]
    label = row
    if table == "7.27":
        return experiment, {"4": "offline_nn_k4", "18": "offline_nn_k18", "36": "offline_nn"}[row], column
    if table == "7.28" and " " in row and ("dynamic" in row or "obstructed" in row):
        experiment = "dynamic" if "dynamic" in row else "obstructed"
        label = row.split(" dynamic")[0].split(" obstructed")[0]
    if table == "7.40":
        antenna, _, label = row.partition(" / ")
        if "monopole" in antenna:
            experiment = "monopole"
    return experiment, _ROW_METHOD[label], column


def _printed_cells():
    return [(r["table"], r["row"], r["column"], float(r["value"])) for r in oz.printed_tables()
            if "7.26" <= r["table"] <= "7.44" and len(r["table"]) == 4]


#: (table, row, column) -> (experiment, method, statistic) for every printed cell of Tables 7.26-7.44
TABLE_CELLS = {(t, r, c): _cell(t, r, c) for t, r, c, _ in _printed_cells()}

TESTBED_TOLERANCE_BASIS = ("the thesis measured one test bed: 2 x the spread of the statistic across synthetic test-bed "
                           "realizations (with the Monte-Carlo error of their mean), i.e. where one test bed drawn from "
                           "the assumed model falls 95 % of the time")


def _statistics(results, experiment):
    if experiment == "fixed_near_tags":
        res, mask = results["fixed"], near_tag_mask()
    else:
        res, mask = results[experiment], None
    return {key: per_realization_statistics(err, mask) for key, err in res.errors.items()}


def table_rows(results: dict[str, ExperimentResult]) -> list[dict]:
    """Every printed cell of Tables 7.26-7.44 whose experiment was run: printed value, mean over realizations,
    spread (std across realizations), its Monte-Carlo standard error, and the single-test-bed tolerance."""
    cache, rows = {}, []
    for t, r, c, printed in _printed_cells():
        experiment, method, stat = TABLE_CELLS[(t, r, c)]
        base = "fixed" if experiment == "fixed_near_tags" else experiment
        if base not in results or method not in results[base].errors:
            continue
        if experiment not in cache:
            cache[experiment] = _statistics(results, experiment)
        values = cache[experiment][method][stat]
        spread = float(values.std(ddof=1)) if values.size > 1 else float("nan")
        se = spread / np.sqrt(values.size)
        rows.append({"table": t, "row": r, "column": c, "experiment": experiment, "method": method,
                     "printed": printed, "reproduced": float(values.mean()), "spread_m": spread, "mc_se_m": se,
                     "tolerance_m": 2.0 * float(np.hypot(spread, se))})
    return rows


#: The thesis's claims that one method beats another: (where, better, worse, experiment, statistic).
RANKINGS = (
    ("Table 7.26", "pattern_nn", "offline_nn", "fixed", "rmse_m"),
    ("Table 7.27", "offline_nn_k18", "offline_nn_k4", "fixed", "rmse_m"),
    ("Table 7.27", "offline_nn", "offline_nn_k18", "fixed", "rmse_m"),
    ("Table 7.28", "online_nn", "offline_nn", "fixed", "rmse_m"),
    ("Table 7.28 (90 %)", "online_nn", "offline_nn", "fixed", "p90_m"),
    ("Table 7.28 (dynamic)", "online_nn", "offline_nn", "dynamic", "std_m"),
    ("Table 7.28 (obstructed)", "online_nn", "offline_nn", "obstructed", "mean_m"),
    ("Table 7.29", "online_nn", "sir", "fixed", "rmse_m"),
    ("Table 7.29", "sir", "grid", "fixed", "rmse_m"),
    ("Table 7.30", "sir", "grid", "mobile", "rmse_m"),
    ("Table 7.30", "grid", "online_nn", "mobile", "rmse_m"),
    ("Table 7.31", "sir", "grid", "dynamic", "std_m"),
    ("Table 7.31", "grid", "online_nn", "dynamic", "std_m"),
    ("Table 7.32", "grid_sigma", "grid", "fixed", "rmse_m"),
    ("Table 7.33", "grid_sigma", "grid", "mobile", "rmse_m"),
    ("Table 7.34", "grid_sigma", "grid", "dynamic", "std_m"),
    ("Table 7.35", "grid_smoothing", "grid", "fixed", "rmse_m"),
    ("Table 7.36", "grid_smoothing", "grid", "fixed_near_tags", "mean_m"),
    ("Table 7.37", "grid_smoothing", "grid", "mobile", "rmse_m"),
    ("Table 7.38", "grid_smoothing", "grid", "obstructed", "mean_m"),
    ("Table 7.39", "sir_sigma_smoothing", "sir", "mobile", "rmse_m"),
    ("Table 7.40 (monopole)", "grid_sigma", "grid", "monopole", "rmse_m"),
    ("Table 7.40 (monopole)", "sir_sigma_smoothing", "sir", "monopole", "rmse_m"),
    ("Table 7.41", "pattern_nn", "online_nn", "fixed", "rmse_m"),
    ("Table 7.42", "online_nn", "offline_nn", "mobile", "rmse_m"),
    ("Table 7.42", "sir_sigma_smoothing", "grid_smoothing", "mobile", "rmse_m"),
    ("Table 7.43", "grid_smoothing", "grid", "dynamic", "std_m"),
)


def _printed_stat(experiment, method, stat):
    for (t, r, c), cell in TABLE_CELLS.items():
        if cell == (experiment, method, stat):
            return oz.printed_value(t, r, c)
    return None


def ranking_rows(results: dict[str, ExperimentResult]) -> list[dict]:
    """Each printed ranking "better beats worse": the printed difference ``worse - better`` (> 0) beside the
    reproduced one (mean over realizations of the paired per-realization difference) and its standard error.
    ``holds``: the reproduced difference is positive; ``significant``: by more than 2 standard errors. Also the
    patch-versus-monopole claim of Table 7.40 (every method worse with the monopole)."""
    cache, rows = {}, []
    for where, better, worse, experiment, stat in RANKINGS:
        base = "fixed" if experiment == "fixed_near_tags" else experiment
        if base not in results or better not in results[base].errors or worse not in results[base].errors:
            continue
        if experiment not in cache:
            cache[experiment] = _statistics(results, experiment)
        st = cache[experiment]
        diff = st[worse][stat] - st[better][stat]
        printed = _printed_stat(experiment, worse, stat) - _printed_stat(experiment, better, stat)
        rows.append(_ranking_row(where, f"{METHOD_LABELS[better]} < {METHOD_LABELS[worse]}", experiment, stat,
                                 printed, diff))
    if "mobile" in results and "monopole" in results:
        patch, mono = _statistics(results, "mobile"), _statistics(results, "monopole")
        for key in EXPERIMENTS["monopole"]:
            if key in patch and key in mono:
                printed = _printed_stat("monopole", key, "rmse_m") - _printed_stat("mobile", key, "rmse_m")
                # different test beds: unpaired difference
                rows.append(_ranking_row("Table 7.40 (antenna)", f"patch < monopole, {METHOD_LABELS[key]}", "mobile vs monopole",
                                         "rmse_m", printed, mono[key]["rmse_m"][:, None] - patch[key]["rmse_m"][None, :]))
    return rows


def _ranking_row(where, claim, experiment, stat, printed, diff):
    diff = np.asarray(diff, float)
    mean = float(diff.mean())
    if diff.ndim == 2:      # unpaired: SE of a difference of two independent means
        se = float(np.hypot(diff.mean(1).std(ddof=1) / np.sqrt(diff.shape[0]),
                            diff.mean(0).std(ddof=1) / np.sqrt(diff.shape[1])))
    else:
        se = float(diff.std(ddof=1) / np.sqrt(diff.size)) if diff.size > 1 else float("nan")
    return {"where": where, "claim": claim, "experiment": experiment, "statistic": stat,
            "printed_difference_m": round(printed, 4), "reproduced_difference_m": mean, "se_m": se,
            "holds": mean > 0, "significant": bool(abs(mean) > 2 * se)}


# -- why printed numbers and rankings are missed ------------------------------------------------------------
_FILTER_FIXED = ("fixed target: the thesis's Bayesian filters are its worst fixed-target methods (grid Bayes 2.04 m), while "
                 "here they average 30 readings with fresh dynamic noise and beat NN. A real home's static errors are not "
                 "a log-distance mean plus a smooth Gaussian field (furniture, multipath nulls, orientation), so the "
                 "filters' 5.2 dB Gaussian likelihood accumulates evidence for a wrong cell; the synthetic channel has "
                 "no such model error. Whether the thesis restarted the filter at each point is not stated either")
_SMALL_K = ("few neighbours: the thesis's k = 4 and 18 errors have heavy tails (90 % at 3.6 / 2.95 m) that the synthetic "
            "Gaussian-plus-burst noise does not produce; one outlying link moves a few-neighbour estimate to a wrong cell")
_PATTERN = ("pattern NN median 0.9 m against a mean of 1.16 m means many estimates land on a training location; a weighted "
            "centroid over all 32 locations (k_NN = 36 capped at 32) cannot do that. The thesis may have used fewer neighbours "
            "for the pattern method")
_NEAR_TAGS = ("points near the reference tags: the thesis's grid Bayes is worse there (2.13 m) than overall (1.77 m mean), ours "
              "is not; the tag and test-point coordinates are assumed, and the filters' fixed-target gap applies as well")
_MONOPOLE = ("monopole antennas are modelled only by scaling the noise (7.5 / 5.3); the real change (vertical polarisation, "
             "more multipath, different pattern) is not a scaled copy of the patch channel")
_DYNAMIC = ("the dynamic-noise experiment's disturbance (people around target and readers) is modelled as reader-wide "
            "bursts with probability 0.3 per step; its size and kind are assumed")
_SIGMA = ("online sigma of Eq. (6.7) (no degrees-of-freedom correction) is about 3.7 dB here for a true 5.2 dB, so the "
          "online-sigma filters are overconfident; the thesis's online sigma was 5.3 dB (Table 6.2)")


def miss_note(experiment: str, method: str, column: str) -> str:
    """Likely reason a printed cell of Tables 7.26-7.44 falls outside the single-test-bed tolerance."""
    est = METHODS[method].estimator
    if experiment == "fixed_near_tags":
        return _NEAR_TAGS
    if experiment == "monopole":
        return _MONOPOLE
    if experiment == "dynamic":
        return _DYNAMIC
    if method == "pattern_nn":
        return _PATTERN
    if method in ("offline_nn_k4", "offline_nn_k18"):
        return _SMALL_K
    if experiment == "fixed" and est in ("grid", "sir"):
        return _FILTER_FIXED
    if METHODS[method].online_sigma:
        return _SIGMA
    return "unexplained: the synthetic test bed differs from the home in a way this model does not capture"


_RANKING_NOTES = (
    ("Table 7.27", "here the error is lowest near k = 18 (about k_CELL / 2), as in the thesis's own simulations; the "
                   "thesis's test bed found k = 36 better by 0.02 m, and the thesis itself remarks that this contradicts "
                   "its simulation"),
    ("Table 7.28", "the synthetic home's mean channel is Table 6.1 itself, so the offline map is exact and the per-step "
                   "4-tag fits only add noise; online calibration wins where reader-wide offsets occur (dynamic noise, "
                   "obstruction: both hold). The thesis's home differed from its offline calibration (Table 6.2 vs 6.1 "
                   "differ by about 3 dB per reader): see the sensitivity run with the home set to Table 6.2"),
    ("Table 7.29", _FILTER_FIXED),
    ("Table 7.30", "grid Bayes and improved SIR are within a few centimetres here; the thesis's own simulations also rank "
                   "improved SIR behind grid Bayes for a mobile target (1.37 vs 1.22 m, Sec. 7.2.3), so this ranking is "
                   "not reproduced in simulation by the thesis either"),
    ("Table 7.31", "within a few centimetres here (see Table 7.30); " + _DYNAMIC),
    ("Table 7.32", _SIGMA), ("Table 7.33", _SIGMA), ("Table 7.34", _SIGMA), ("Table 7.39", _SIGMA),
    ("Table 7.40 (monopole)", _SIGMA + "; with the monopole the true spread is 7.4 dB, yet Eq. (6.7) gives about 5.5 dB, "
                              "close to the fixed 5.2 dB, so online sigma gains nothing"),
    ("Table 7.42", _SIGMA),
    ("Table 7.35", "smoothing subtracts a nearby tag's error; the error a target shares with a tag here is the static field "
                   "(correlation exp(-d / 1.5 m)) and reader-wide bursts. The thesis's gains (0.17-0.58 m) imply errors "
                   "shared far more strongly near the tags than this model has"),
)


def ranking_note(where: str, claim: str) -> str:
    """Likely reason a printed ranking does not hold on the synthetic test bed."""
    if "smoothing" in claim and "sigma" not in claim:
        return dict(_RANKING_NOTES)["Table 7.35"]
    for prefix, note in _RANKING_NOTES:
        if where.startswith(prefix):
            return note
    return "unexplained"
