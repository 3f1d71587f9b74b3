"""Ozkaya (2011)'s Sec. 7.3 test bed, synthetic: the assumed layout, the channel (:class:`TestbedChannel`), the test
beds drawn from it (:func:`draw_testbed`), the measurement sessions, the methods of Sec. 7.3.1.3 (:data:`METHODS`)
and the experiments run on them (:func:`run_testbed`), with their per-realization statistics and the test bed's
CRLB. The printed tables, rankings and notes are :mod:`locbook.scenarios.ozkaya_testbed`'s, which explains the
assumptions.
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from .._deprecation import RENAMED_CRLB_FORMS, check_variant, renamed_keyword
from ..bounds.crlb import CRLB_VARIANTS, crlb_rms_over_area_m, rss_crlb_m
from ..metrics import error_summary_per_run, position_error_m
from ..models.channel import (
    PathLossModel,
    attenuation_bursts_db,
    correlated_shadowing_db,
    pairwise_distance_m,
    quantize_db,
)
from ..models.rss import RssModel
from ..reproduce.scoring import Ambiguity
from ..static.fingerprint import knn_position, model_fingerprints
from ..static.reference_tags import calibrate_from_reference_tags, smooth_rssi
from ..tracking.bayes import grid_bayes_filter
from ..tracking.particle import particle_filter
from . import ozkaya as oz

#: The statistics of the thesis's test-bed tables (columns of Tables 7.26-7.44).
STATISTICS = ("rmse_m", "mean_m", "median_m", "p90_m", "std_m")
#: Sec. 7.3.1.3: the filters' fixed sigma for the test bed (dB).
TESTBED_SIGMA_DB = oz.PRINTED.get("Sec. 7.3.1.3 text", "test bed methods", "sigma_db").value

#: 36 cells of 1 m (k_CELL = 36, Sec. 7.3.1): centres (i + 0.5, j + 0.5), i = 0..8, j = 0..3.
TESTBED_CELLS_M = oz.cell_centres(oz.TESTBED_SIZE_M, 9, 4, margin_m=0.0)
#: 25 fixed test points "starting 1 m from the surrounding walls" (Fig. 7.21, not printed): ASSUMED 5 x 5 lattice
#: x in {1, 2.75, 4.5, 6.25, 8}, y in {1, 1.5, 2, 2.5, 3}.
FIXED_POINTS_M = np.stack(np.meshgrid(np.linspace(1.0, 8.0, 5), np.linspace(1.0, 3.0, 5), indexing="ij"),
                          -1).reshape(-1, 2)
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
#: Sec. 7.3.2.6: the auto-calibrated sigma averaged this with monopole reader antennas ...
MONOPOLE_SIGMA_PRINTED = oz.PRINTED.get("Sec. 7.3.2.6 text", "monopole reader antennas", "auto_calibrated_sigma_db")
#: ... against Table 6.2's pooled sigma with the patch antennas (Sec. 7.3.2.6 also says "about 5.2" for the patch).
PATCH_SIGMA_PRINTED = oz.PRINTED.get("Table 6.2", "all readers (pooled)", "sigma_db")
PATCH_SIGMA_TEXT_PRINTED = oz.PRINTED.get("Sec. 7.3.2.6 text", "patch reader antennas", "auto_calibrated_sigma_db")
#: Monopole reader antennas: both sigmas are the same estimator (Eq. (6.7)), so the random components of the
#: channel are scaled by their ratio, as Sec. 7.3.2.6 explains the monopole's larger errors ("using monopole antenna
#: ... causes larger RSSI measurement noise"). The ratio is a reading of that text, not a fit: the monopole rows are
#: reproductions (:data:`MONOPOLE_CALIBRATED_FROM` says where the scale comes from).
MONOPOLE_NOISE_SCALE = MONOPOLE_SIGMA_PRINTED.value / PATCH_SIGMA_PRINTED.value
MONOPOLE_CALIBRATED_FROM = (f"reader noise scaled by {MONOPOLE_SIGMA_PRINTED.text} / {PATCH_SIGMA_PRINTED.text}: "
                            "Sec. 7.3.2.6's auto-calibrated sigma over Table 6.2's")

#: The CRLB the thesis quotes for the test bed (Sec. 7.3.1.3; captions of Tables 7.41/7.42).
TESTBED_CRLB_PRINTED = oz.PRINTED.get("Sec. 7.3.1.3 text", "test bed", "crlb_m")
#: n = 2 in the printed-form bound: chosen, with the mean over the cells, to reproduce the simulation CRLB columns
#: (no text supports either; readings testbed_crlb_exponent / testbed_crlb_average): an alternative, not the default
THESIS_CRLB_PATH_LOSS_EXP = 2.0
#: The test bed's own exponents (Table 6.1, per reader): the default exponent of its bound (Appendix A: the bound
#: "depends on ... Signal propagation log-distance path loss parameter n").
TESTBED_CRLB_PATH_LOSS_EXP = tuple(oz.OFFLINE_PARAMETERS["path_loss_exp"])
CRLB_CALIBRATED_FROM = (
    f"printed-form bound (Eqs. A.10-A.12, 1/d^2) with n = {THESIS_CRLB_PATH_LOSS_EXP:g} and the mean over the cells, "
    "both chosen because they reproduce the simulation CRLB columns (e.g. Table 7.2 row 3: "
    f"{oz.PRINTED.get('Table 7.2', '3', 'crlb_m').text}); the test-bed layout is assumed (Sec. 6.1 prints no "
    "coordinates)")

#: The thesis measured ONE test bed; ours is the mean over synthetic ones: the window adds where one test bed falls.
TESTBED_AMBIGUITY_WHAT = "one measured test bed: 2 sd of the statistic between synthetic test beds"
TESTBED_AMBIGUITY_SOURCE = "Ozkaya 2011 Secs. 6.1, 7.3: one test bed measured, its layout not printed"


def testbed_ambiguity(per_testbed) -> Ambiguity:
    """The single-test-bed ambiguity of a statistic: 2 standard deviations (ddof 1) of its values ``(Z,)`` over
    the synthetic test beds (0 for one test bed)."""
    values = np.asarray(per_testbed, float).ravel()
    sd = float(values.std(ddof=1)) if values.size > 1 else 0.0
    return Ambiguity(2.0 * sd, TESTBED_AMBIGUITY_WHAT, TESTBED_AMBIGUITY_SOURCE)


@dataclass(frozen=True)
class TestbedChannel:
    """The synthetic test bed's RSSI (dBm) for reader j at position p, step t (all values ASSUMED unless noted).

    ``RSSI = alpha_j - 10 n_j log10(d) - n_W WAF + S_j(p) + O_j + e_jt + b_jt - L_j``, quantised to
    ``resolution_db`` (None: not quantised) and floored at ``floor_dbm`` (Sec. 6.2: 1 dB resolution, -90 dBm
    sensitivity), where

    * ``alpha_j, n_j, WAF``: Table 6.1 (offline calibration; the most careful measurement in the thesis);
    * ``S_j(p)``: static shadowing, a Gaussian field per reader with exponential correlation
      (``static_sigma_db``, ``decorrelation_m``; our defaults, about 4 dB and 1-2 m);
    * ``O_j``: tag orientation, drawn once per visit of a point or pass of a path (the tag is re-oriented
      between visits, Sec. 7.3.1; calibrated to be nearly omnidirectional, hence small);
    * ``e_jt``: dynamic noise, i.i.d. per reading (``dynamic_sigma_db``; default about 3 dB, the
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
        return model_fingerprints(points_m, RssModel(oz.TESTBED_READERS_M, model, oz.TESTBED_WALLS_M))


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
                                       rng=rng, size=(n_realizations, m))                     # (Z, m, P)
    tag_o = channel.noise_scale * channel.orientation_sigma_db * rng.standard_normal(
        (n_realizations, len(oz.REFERENCE_TAGS_M), m))
    return Testbed(channel, points, np.swapaxes(field_db, -1, -2), tag_o)


def _read(channel, rss_dbm):
    """What the reader reports: ``resolution_db`` steps (None: no quantisation) and the sensitivity floor."""
    if channel.resolution_db is None:
        return np.maximum(rss_dbm, channel.floor_dbm)
    return quantize_db(rss_dbm, channel.resolution_db, channel.floor_dbm)


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
    common = attenuation_bursts_db((z, n_sessions, n_steps, m), p, ch.burst_loss_db, rng=rng)
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
               + attenuation_bursts_db(shape, ch.burst_probability, ch.burst_loss_db, rng=rng))
    return _read(ch, samples).mean(axis=-2)


# -- methods of Sec. 7.3.1.3 ------------------------------------------------------------------------------
@dataclass(frozen=True)
class MethodSettings:
    """Sec. 7.3.1.3 defaults: k_NN = k_CELL = 36, sigma = 5.2 dB, N = 10000, N_t = 0.5, D = 0.5 m (D_0 = 0.5 m
    with the known velocity of the mobile test), smoothing threshold 0.4 (Sec. 7.1.5.3)."""

    k_nn: int = 36
    sigma_db: float = TESTBED_SIGMA_DB
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
    per_step = method.online_sigma or method.parameters != "offline"           # the online calibration's (R, T) axes
    if method.estimator == "nn":
        fp = model_fingerprints(TESTBED_CELLS_M,
                                RssModel(readers, PathLossModel(alpha, n, wall_attenuation_db=oz.WAF_DB), walls,
                                         per_step_channel=per_step))
        return knn_position(rss, fp, TESTBED_CELLS_M, min(k, TESTBED_CELLS_M.shape[0]))
    sigma = calibration.sigma_db[..., None] if method.online_sigma else settings.sigma_db          # (R, T, 1): pooled
    model = RssModel(readers, PathLossModel(alpha, n, sigma, wall_attenuation_db=oz.WAF_DB, min_distance_m=0.1), walls,
                     per_step_channel=per_step)
    if method.estimator == "grid":
        return grid_bayes_filter(rss, model, TESTBED_CELLS_M, settings.spread_m, velocity_m=velocity_m).mean
    if method.estimator != "sir":
        raise ValueError(f"unknown estimator {method.estimator!r}")
    n_runs = rss.shape[0]
    block = max(1, settings.max_particle_runs // settings.n_particles)
    starts = range(0, n_runs, block)
    out = []
    for start, child in zip(starts, seed_sequence.spawn(len(starts))):
        sl = slice(start, start + block)
        block_model = model.select_runs(sl)
        res = particle_filter(rss[sl], block_model, rng=np.random.default_rng(child), n_particles=settings.n_particles,
                              region_m=((0.0, 0.0), oz.TESTBED_SIZE_M), spread_m=settings.spread_m,
                              velocity_m=velocity_m, resample_threshold=settings.resample_threshold,
                              weight_smoothing="sqrt")
        out.append(res.mean)
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
      thesis); filters restart at every point (not stated in the thesis).
    * mobile: each path of :data:`MOBILE_PATHS_M` walked ``mobile_passes`` times (the count is not printed),
      one estimate per step, velocity known to the filters (Sec. 7.3.1.3).
    * dynamic: :data:`DYNAMIC_POINTS_M` x ``fixed_steps`` with people moving around target and readers:
      reader bursts with probability ``dynamic_burst_probability`` per step (ASSUMED).
    * obstructed: :data:`OBSTRUCTION_POINTS_M` x ``fixed_steps``; metal objects in front of every reader add a loss
      uniform in ``obstruction_loss_db`` per reader (default 5-10 dB, ours), to target and tags alike.
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
    arrays of :data:`STATISTICS` (:func:`locbook.metrics.error_summary_per_run`). ``mask (S,)`` keeps some
    sessions (the points near the reference tags of Table 7.36)."""
    e = np.asarray(errors_m, float)
    if mask is not None:
        e = e[:, np.asarray(mask, bool)]
    return error_summary_per_run(e)


def online_sigma_per_testbed(result: "ExperimentResult") -> np.ndarray:
    """The online sigma of Eq. (6.7) averaged over every step of an experiment, per test bed ``(Z,)`` (dB)."""
    s = np.asarray(result.online_sigma_db, float)
    return s.reshape(s.shape[0], -1).mean(-1)


def near_tag_mask(points_m=FIXED_POINTS_M, radius_m: float = NEAR_TAG_RADIUS_M):
    """Test points within ``radius_m`` of a reference tag (Table 7.36)."""
    return pairwise_distance_m(np.asarray(points_m, float), np.asarray(oz.REFERENCE_TAGS_M)).min(-1) <= radius_m


@renamed_keyword("form", "variant", RENAMED_CRLB_FORMS)
def testbed_crlb_m(path_loss_exp=TESTBED_CRLB_PATH_LOSS_EXP, sigma_db: float = TESTBED_SIGMA_DB,
                   variant: str = "literal_ozkaya2011", average: str = "area_rms") -> float:
    """The bound of the test bed for the assumed reader layout (:data:`~locbook.scenarios.ozkaya.TESTBED_READERS_M`),
    by default in the printed form (Eqs. A.10-A.13, 1/d^2) with the test bed's exponents of Table 6.1 (one per reader)
    and sigma = 5.2 dB (Sec. 7.3.1.3), as the RMS over the area ("Square root of (A.13) is used in the thesis to
    compare with RMS error", Appendix A): ``average="area_rms"`` over a 5 cm lattice of the 9 m x 4 m plan, or
    ``"cells_mean"``, the mean of the per-cell bound over the 36 cells (with n = 2: the readings fitted to the
    simulation CRLB columns). ``variant="corrected"`` gives the correct bound (1/d^4) (the earlier ``form=``:
    deprecated)."""
    variant = check_variant(variant, CRLB_VARIANTS, where="testbed_crlb_m", renamed=RENAMED_CRLB_FORMS)
    model = RssModel(oz.TESTBED_READERS_M, PathLossModel(0.0, path_loss_exp, sigma_db))
    if average == "cells_mean":
        return float(np.mean(rss_crlb_m(TESTBED_CELLS_M, model, variant=variant)))
    if average == "area_rms":
        step = 0.05
        xs, ys = (np.arange(step / 2, size, step) for size in oz.TESTBED_SIZE_M)
        points = np.stack(np.meshgrid(xs, ys, indexing="ij"), -1).reshape(-1, 2)
        return crlb_rms_over_area_m(points, model, variant=variant)
    raise ValueError(f"average must be 'area_rms' or 'cells_mean', got {average!r}")
