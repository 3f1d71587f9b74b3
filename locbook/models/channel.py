"""Radio channel models: log-distance path loss, log-normal shadowing, register conversions.

The log-distance path-loss model (LDPM) in the dB domain, with reference distance d0,

    P_r(d) = P_0 - 10 n log10(d / d0) - n_W * WAF + w,     w ~ N(0, sigma^2)  [dB]

is Eq. (5) of George and Vadivukkarasi, Eq. (2.2) of Dogan (2015, where the
exponent is called alpha), and Eq. (6.3) of Ozkaya (2011, where the reference power is called
alpha and walls attenuate by WAF each). Names in code are explicit to avoid that clash:
``ref_power_dbm`` (P_0), ``path_loss_exp`` (n), ``ref_distance_m`` (d0).

Every anchor may have its own reference power and exponent: parameters broadcast against the
last (anchor) axis of a distance array.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._deprecation import keyword_rng
from .._validate import as_array, check_scalar

__all__ = [
    "PathLossModel",
    "log_distance_mean_dbm",
    "log_distance_gradient",
    "log_distance_regressor_db",
    "CC2420_RSSI_OFFSET_DB",
    "AT86RF230_ED_OFFSET_DB",
    "register_to_dbm",
    "dbm_to_register",
    "quantize_db",
    "pairwise_distance_m",
    "wall_crossings",
    "correlated_shadowing_db",
    "attenuation_bursts_db",
    "small_scale_fading_db",
    "RANGE_BIAS_TARGETS",
    "log_normal_range_moments",
    "correct_range_bias",
]

#: CC2420 RSSI register offset: P = RSSI_VAL - 45 dBm (Eq. (3) in George and Vadivukkarasi,
#: from the CC2420 datasheet rev 1.3).
CC2420_RSSI_OFFSET_DB = -45.0
#: AT86RF230 energy-detect offset: P = ED - 91 dBm (Gudipati 2017, Sec. 3.3, after the datasheet).
AT86RF230_ED_OFFSET_DB = -91.0


def register_to_dbm(register, offset_db: float = CC2420_RSSI_OFFSET_DB):
    """Received power in dBm from a radio's RSSI register value: ``P = register + offset``.

    Eq. (3) in George and Vadivukkarasi (``P_r = RSSI - 45``) with the CC2420 default; pass
    ``AT86RF230_ED_OFFSET_DB`` for the AT86RF230 energy-detect value used by Gudipati (2017).
    A NaN register value (no packet) stays NaN.
    """
    check_scalar("offset_db", offset_db)
    return as_array("register", register, nan_ok=True) + offset_db


def dbm_to_register(rss_dbm, offset_db: float = CC2420_RSSI_OFFSET_DB):
    """Inverse of :func:`register_to_dbm` (no rounding; see :func:`quantize_db`). NaN (not heard) stays NaN."""
    check_scalar("offset_db", offset_db)
    return as_array("rss_dbm", rss_dbm, nan_ok=True) - offset_db


def quantize_db(rss_dbm, step_db: float = 1.0, floor_dbm: float | None = None):
    """Round powers to the radio's resolution (1 dB for CC2420, AT86RF230 ED and the
    Ozkaya readers) and optionally clip at a sensitivity floor (e.g. -90 dBm in Ozkaya 2011).
    A NaN power (not heard) stays NaN; it is not clipped to the floor.
    """
    check_scalar("step_db", step_db, gt=0)
    if floor_dbm is not None:
        check_scalar("floor_dbm", floor_dbm)
    q = np.round(as_array("rss_dbm", rss_dbm, nan_ok=True) / step_db) * step_db
    if floor_dbm is not None:
        q = np.maximum(q, floor_dbm)
    return q


def pairwise_distance_m(points_m, anchors_m, *, names: tuple[str, str] = ("points_m", "anchors_m")):
    """Euclidean distances between points ``(..., dim)`` and anchors ``(m, dim)`` -> ``(..., m)``.

    ``names``: the caller's names of the two arguments, used in the error raised when finite coordinates are so
    large (about 1e154 m) that their distances overflow."""
    points_m = as_array(names[0], points_m, min_ndim=1)
    anchors_m = as_array(names[1], anchors_m, ndim=2)
    if points_m.shape[-1] != anchors_m.shape[-1]:
        raise ValueError(
            f"{names[0]} have dimension {points_m.shape[-1]} but {names[1]} have {anchors_m.shape[-1]}"
        )
    diff = points_m[..., None, :] - anchors_m
    with np.errstate(over="ignore", invalid="ignore"):
        distance = np.sqrt(np.einsum("...i,...i->...", diff, diff))
    if not np.all(np.isfinite(distance)):          # the inputs are finite (as_array): this is overflow
        raise ValueError(f"the distances between {names[0]} and {names[1]} overflow: their coordinates reach "
                         f"{max(np.abs(points_m).max(initial=0), np.abs(anchors_m).max(initial=0)):.3g} m")
    return distance


def log_distance_mean_dbm(distance_m, ref_power_dbm, path_loss_exp, *, ref_distance_m: float = 1.0,
                          min_distance_m: float = 0.0, n_walls=0, wall_attenuation_db: float = 0.0):
    """The log-distance mean power, ``P_0 - 10 n log10(max(d, d_min) / d0) - n_W WAF`` (dBm): the one place
    the model is written (Eq. (5) in George and Vadivukkarasi, Eq. (2.2) in Dogan 2015, Eqs. (6.3)-(6.4) in
    Ozkaya 2011). Every estimator, filter and fingerprint map of locbook calls it.

    ``min_distance_m`` is the near-field clamp: the far-field model is not meant to hold within about a
    wavelength of the antenna (0.125 m at 2.4 GHz), and ``log10(0)`` must never occur; 0 means no clamp.
    Parameters broadcast against ``distance_m``; no input checks (callers check once, outside hot loops)."""
    d = np.maximum(distance_m, min_distance_m) if min_distance_m > 0 else distance_m
    mean = ref_power_dbm - 10.0 * path_loss_exp * np.log10(d / ref_distance_m)
    if wall_attenuation_db != 0.0:
        mean = mean - n_walls * wall_attenuation_db
    return mean


def log_distance_gradient(offset_m, path_loss_exp, *, min_distance_m: float = 0.0, d2_m2=None):
    """Gradient of :func:`log_distance_mean_dbm` w.r.t. the position, ``-(10 n / ln 10) (p - a) / d^2``
    ``(..., m, dim)``, from the offsets ``p - a`` ``(..., m, dim)`` (the EKF Jacobian of Dogan 2015, Table 3.2, which
    the thesis does not print); ``d2_m2`` ``(..., m)``: the squared distances when the caller has them (e.g. 3-D
    with a height column).

    Within the near-field clamp (``d < min_distance_m``) the mean is ``P_0 - 10 n log10(d_min / d0)``, a constant,
    so its gradient is exactly 0 there (the reading carries no information about the position): filters and Newton
    steps stay finite at an anchor and the Fisher information of a reading inside the clamp is 0. At ``d = d_min``
    the one-sided derivative from outside is used. No input checks (callers check once)."""
    offset_m = np.asarray(offset_m, dtype=float)
    d2 = np.einsum("...i,...i->...", offset_m, offset_m) if d2_m2 is None else d2_m2
    slope = 10.0 * np.asarray(path_loss_exp) / np.log(10.0)
    if min_distance_m > 0:
        inside = d2 < min_distance_m**2
        # max() changes no value outside the clamp; inside it only avoids 0/0 before the exact 0 is put in
        return np.where(inside[..., None], 0.0, -(slope / np.maximum(d2, min_distance_m**2))[..., None] * offset_m)
    return -(slope / d2)[..., None] * offset_m


def log_distance_regressor_db(distance_m, ref_distance_m: float = 1.0):
    """``10 log10(d / d0)``: the regressor of the log-distance law, linear in ``(P_0, n)``
    (``P = P_0 - n * 10 log10(d/d0)``), for the calibrations that fit the law (Gudipati 2017, Eqs. (3.7), (6);
    Dogan 2015, Eq. (5.1)). No input checks."""
    return 10.0 * np.log10(np.asarray(distance_m, dtype=float) / ref_distance_m)


@dataclass(frozen=True)
class PathLossModel:
    """Log-distance path loss with i.i.d. log-normal shadowing.

    Fields broadcast against the anchor axis: a scalar means one value shared by all anchors,
    an array of length m gives each anchor its own value (per-anchor calibration).

    Attributes
    ----------
    ref_power_dbm : float or array (m,)
        Mean received power at the reference distance, P_0 (dBm). Called A in document 003,
        P0 in 000, alpha in 004.
    path_loss_exp : float or array (m,)
        Path-loss exponent n (alpha in document 000).
    sigma_db : float or array (m,)
        Standard deviation of the shadowing term w (dB).
    ref_distance_m : float
        Reference distance d0 (1 m in every source document).
    wall_attenuation_db : float
        Attenuation per wall (WAF, Ozkaya Eq. (6.3)); multiplied by a wall count.
    min_distance_m : float
        Near-field clamp of :func:`log_distance_mean_dbm` (0: none, and distances must be positive).

    No field has a default taken from one document: the reference power and the exponent are always given.

    Examples
    --------
    >>> import numpy as np
    >>> import locbook as lb
    >>> channel = lb.PathLossModel(ref_power_dbm=-40.0, path_loss_exp=2.0, sigma_db=3.0)
    >>> print(channel.mean_rss_dbm(np.array([1.0, 10.0, 100.0])))      # P0 - 10 n log10(d / d0)
    [-40. -60. -80.]
    >>> print(channel.range_m(np.array([-60.0])))                       # the inverse, in metres
    [10.]
    """

    ref_power_dbm: float | np.ndarray
    path_loss_exp: float | np.ndarray
    sigma_db: float | np.ndarray = 0.0
    ref_distance_m: float = 1.0
    wall_attenuation_db: float = 0.0
    min_distance_m: float = 0.0

    def __post_init__(self):
        check_scalar("ref_distance_m", self.ref_distance_m, gt=0)
        check_scalar("wall_attenuation_db", self.wall_attenuation_db)
        check_scalar("min_distance_m", self.min_distance_m, ge=0)
        for name in ("ref_power_dbm", "path_loss_exp", "sigma_db"):
            as_array(name, getattr(self, name))                 # NaN or infinite parameters are errors
        if np.any(np.asarray(self.sigma_db) < 0):
            raise ValueError(f"sigma_db must be non-negative, got {self.sigma_db}")

    def _positive_exponent(self, where: str) -> None:
        """``path_loss_exp`` divides in Eq. (7); a non-positive exponent has no inverse."""
        if np.any(np.asarray(self.path_loss_exp) <= 0):
            raise ValueError(f"{where} divides by path_loss_exp, which must be > 0; got {self.path_loss_exp}")

    def mean_rss_dbm(self, distance_m, n_walls=0):
        """Mean received power, ``P_0 - 10 n log10(d/d0) - n_W WAF`` (Eq. (5) in document 003,
        Eq. (6.4) in Ozkaya 2011)."""
        distance_m = as_array("distance_m", distance_m)
        if np.any(distance_m < 0) or (self.min_distance_m == 0 and np.any(distance_m == 0)):
            raise ValueError("distances must be positive for the log-distance model (or give min_distance_m)")
        _check_walls_count(n_walls)
        return log_distance_mean_dbm(distance_m, np.asarray(self.ref_power_dbm), np.asarray(self.path_loss_exp),
                                     ref_distance_m=self.ref_distance_m, min_distance_m=self.min_distance_m,
                                     n_walls=np.asarray(n_walls), wall_attenuation_db=self.wall_attenuation_db)

    @keyword_rng(2, "n_walls")
    def sample_rss_dbm(self, distance_m, *, rng: np.random.Generator, n_walls=0):
        """Mean power plus i.i.d. Gaussian shadowing ``w ~ N(0, sigma_db^2)``, one draw per entry (``rng`` and
        ``n_walls`` keyword-only; the positional form ``sample_rss_dbm(distance_m, rng, n_walls)`` is deprecated)."""
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        mean = self.mean_rss_dbm(distance_m, n_walls)
        return mean + np.asarray(self.sigma_db) * rng.standard_normal(mean.shape)

    def range_m(self, rss_dbm, n_walls=0):
        """Invert the mean model: ``d = d0 10^((P_0 - P_r - n_W WAF) / (10 n))``.

        Eq. (7) in George and Vadivukkarasi; Eq. (2.3) in Dogan (2015). The estimate is median
        unbiased but mean biased by ``exp((sigma ln10 / (10 n))^2 / 2)`` under shadowing.
        A NaN power (not heard) gives a NaN range (still not heard).
        """
        rss_dbm = as_array("rss_dbm", rss_dbm, nan_ok=True)
        self._positive_exponent("range_m")
        _check_walls_count(n_walls)
        exponent = (
            np.asarray(self.ref_power_dbm) - rss_dbm - np.asarray(n_walls) * self.wall_attenuation_db
        ) / (10.0 * np.asarray(self.path_loss_exp))
        return self.ref_distance_m * 10.0**exponent

    def range_bias_factor(self):
        """Mean bias of :meth:`range_m` under shadowing: ``E[d_hat]/d = exp((sigma ln10/(10 n))^2/2)``
        (the range of Dogan 2015, Eq. (2.3), is log-normal)."""
        self._positive_exponent("range_bias_factor")
        s = np.asarray(self.sigma_db) * np.log(10.0) / (10.0 * np.asarray(self.path_loss_exp))
        return np.exp(0.5 * s**2)


RANGE_BIAS_TARGETS = ("median", "mean", "squared")


def log_normal_range_moments(sigma_db, path_loss_exp) -> dict:
    """Moments of the range inverted from a log-normally shadowed power, ``d = d_0 exp(k)``, ``k ~ N(0, sigma_k^2)``,
    ``sigma_k = ln(10) sigma / (10 n)`` (Palvai 2008, Eqs. (2.35)-(2.38)): ``sigma_k``,
    ``mean_ratio`` ``E[d]/d_0 = exp(sigma_k^2 / 2)``, ``mean_square_ratio`` ``E[d^2]/d_0^2 = exp(2 sigma_k^2)`` and
    ``sd_ratio`` ``sd(d)/d_0 = sqrt(exp(2 sigma_k^2) - exp(sigma_k^2))``. Arrays broadcast."""
    sigma = as_array("sigma_db", sigma_db)
    n = as_array("path_loss_exp", path_loss_exp)
    if np.any(sigma < 0) or np.any(n <= 0):
        raise ValueError("sigma_db must be >= 0 and path_loss_exp > 0")
    sk = np.log(10.0) * sigma / (10.0 * n)
    return {"sigma_k": sk, "mean_ratio": np.exp(sk**2 / 2), "mean_square_ratio": np.exp(2 * sk**2),
            "sd_ratio": np.sqrt(np.exp(2 * sk**2) - np.exp(sk**2))}


def correct_range_bias(distance_m, sigma_db, path_loss_exp, target: str = "mean"):
    """Ranges inverted from shadowed powers, corrected for the log-normal bias (Palvai 2008,
    Eqs. (2.35)-(2.38); the thesis does not correct it, an extension): ``"median"``
    leaves them (already median-unbiased), ``"mean"`` divides by ``exp(sigma_k^2 / 2)`` (mean-unbiased ``d``),
    ``"squared"`` divides by ``exp(sigma_k^2)`` so that ``d^2`` is mean-unbiased (what linearised lateration
    uses). NaN (not heard) stays NaN."""
    if target not in RANGE_BIAS_TARGETS:
        raise ValueError(f"target must be one of {RANGE_BIAS_TARGETS}, got {target!r}")
    d = as_array("distance_m", distance_m, nan_ok=True)
    sk2 = log_normal_range_moments(sigma_db, path_loss_exp)["sigma_k"] ** 2
    return d * {"median": 1.0, "mean": np.exp(-sk2 / 2), "squared": np.exp(-sk2)}[target]


def _check_walls_count(n_walls) -> None:
    """Wall counts ``n_W`` (Eq. (6.3), Ozkaya 2011) are finite and non-negative."""
    counts = as_array("n_walls", n_walls)
    if np.any(counts < 0):
        raise ValueError(f"n_walls must be non-negative wall counts, got a minimum of {counts.min()}")


@keyword_rng(3, "size")
def correlated_shadowing_db(points_m, sigma_db: float, decorrelation_m: float, *,
                            rng: np.random.Generator, size: tuple[int, ...] = ()):
    """Spatially correlated log-normal shadowing at fixed points (Gudmundson model).

    Covariance ``sigma^2 exp(-|p_i - p_j| / d_c)`` between points ``(P, dim)``; returns draws of
    shape ``size + (P,)``. Used where a source needs shadowing that averaging over packets does not
    remove (our synthetic stand-ins for Gudipati 2017's Fig. 5.1 calibration walk and for
    Ozkaya 2011's test bed, Sec. 7.3). ``decorrelation_m = 0`` gives i.i.d. draws. ``rng`` and ``size`` are
    keyword-only (the positional form ``(points_m, sigma_db, decorrelation_m, rng, size)`` is deprecated).
    """
    points_m = np.atleast_2d(as_array("points_m", points_m))
    check_scalar("sigma_db", sigma_db, ge=0)
    check_scalar("decorrelation_m", decorrelation_m, ge=0)
    n_points = points_m.shape[0]
    z = rng.standard_normal(size + (n_points,))
    if decorrelation_m <= 0 or sigma_db == 0:
        return sigma_db * z
    dist = pairwise_distance_m(points_m, points_m)
    cov = np.exp(-dist / decorrelation_m)
    # small jitter: the exponential kernel is positive definite, but near-duplicate points are not
    chol = np.linalg.cholesky(cov + 1e-12 * np.eye(n_points))
    return sigma_db * z @ chol.T


@keyword_rng(3)
def attenuation_bursts_db(shape, probability: float, loss_range_db: tuple[float, float], *, rng: np.random.Generator):
    """Intermittent attenuation bursts (dB, <= 0): at each entry, with probability ``probability``, a loss drawn
    uniformly from ``loss_range_db = (low, high)`` (both >= 0), else no loss.

    A burst drawn per (receiver, step) and added to every transmitter that receiver hears at that step models a
    body or object next to the receiver shading it as a whole ("reader-wide" attenuation: our synthetic stand-in for
    the obstructed readers of Ozkaya 2011, Sec. 7.3, Tables 7.38 and 7.44); the caller broadcasts the ``shape``
    draw over the transmitters. Returns an array of ``shape``: ``-U(low, high)`` where a burst occurs, ``0``
    elsewhere. The expected value is ``-probability (low + high) / 2``. ``rng`` is keyword-only (the positional
    form ``(shape, probability, loss_range_db, rng)`` is deprecated).
    """
    check_scalar("probability", probability, ge=0, le=1)
    if len(loss_range_db) != 2:
        raise ValueError(f"loss_range_db must be (low, high), got {loss_range_db!r}")
    low, high = (float(v) for v in loss_range_db)
    check_scalar("loss_range_db low", low, ge=0)
    check_scalar("loss_range_db high", high, ge=low)
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    hit = rng.random(shape) < probability
    return -np.where(hit, low + (high - low) * rng.random(shape), 0.0)


def wall_crossings(points_m, anchors_m, walls_m):
    """Number of walls crossed by the straight path from each point to each anchor (``n_W`` in
    Ozkaya 2011, Eq. (6.3)): ``points (..., 2)``, anchors ``(m, 2)``, walls ``(W, 2, 2)`` as segments
    ``[[x1, y1], [x2, y2]]`` -> integer counts ``(..., m)``.

    A path crosses a wall when the two segments properly intersect (orientation test); a path that only
    touches a wall's end point or runs along it is not counted.
    """
    points_m = as_array("points_m", points_m, min_ndim=1, trailing=(2,))
    anchors_m = as_array("anchors_m", anchors_m, ndim=2, trailing=(None, 2))
    walls_m = as_array("walls_m", walls_m)
    if walls_m.shape == (2, 2):                                   # one wall
        walls_m = walls_m[None]
    elif walls_m.size == 0:                                       # no walls
        walls_m = walls_m.reshape(0, 2, 2)
    if walls_m.ndim != 3 or walls_m.shape[1:] != (2, 2):
        raise ValueError(f"walls_m must have shape (W, 2, 2) (segments [[x1, y1], [x2, y2]]) or (2, 2) for one "
                         f"wall, got {walls_m.shape}")
    count = np.zeros(points_m.shape[:-1] + (anchors_m.shape[0],), dtype=int)

    def cross(o, a, b):   # z of (a - o) x (b - o)
        return (a[..., 0] - o[..., 0]) * (b[..., 1] - o[..., 1]) - (a[..., 1] - o[..., 1]) * (b[..., 0] - o[..., 0])

    px, py = points_m[..., 0, None], points_m[..., 1, None]      # (..., 1)
    for w0, w1 in walls_m:
        side_p, side_a = cross(w0, w1, points_m)[..., None], cross(w0, w1, anchors_m)   # which side of the wall line
        # which side of the path line each wall end lies on: (a - p) x (w - p) = a x w + p x (a - w), linear in p
        sides = []
        for w in (w0, w1):
            aw = anchors_m - w
            sides.append((anchors_m[:, 0] * w[1] - anchors_m[:, 1] * w[0]) + px * aw[:, 1] - py * aw[:, 0])
        count += (sides[0] * sides[1] < 0) & (side_p * side_a < 0)
    return count


@keyword_rng(2)
def small_scale_fading_db(distance_m, wavelength_m: float, *, rng: np.random.Generator, n_paths: int = 64,
                          k_factor: float = 0.0):
    """Multipath envelope (dB, relative to the mean power) along a line, by a sum of plane waves.

    ``n_paths`` scattered waves with uniform arrival angles and phases and equal power, plus (``k_factor`` > 0)
    a line-of-sight wave carrying ``K`` times the scattered power: Rayleigh fading for ``K = 0``, Rician
    otherwise (Ozkaya 2011, Sec. 5.1.1; Rappaport 2002, Ch. 5). Fades of 20-40 dB within a fraction of a
    wavelength are what the thesis illustrates at 910 MHz (lambda about 33 cm). ``rng`` is keyword-only (the
    positional form ``(distance_m, wavelength_m, rng)`` is deprecated).
    """
    x = as_array("distance_m", distance_m)
    check_scalar("wavelength_m", wavelength_m, gt=0)
    check_scalar("n_paths", n_paths, ge=1, integer=True)
    check_scalar("k_factor", k_factor, ge=0)
    k = 2.0 * np.pi / wavelength_m
    angles = rng.uniform(0.0, 2.0 * np.pi, n_paths)
    phases = rng.uniform(0.0, 2.0 * np.pi, n_paths)
    scattered = np.exp(1j * (k * x[..., None] * np.cos(angles) + phases)).sum(axis=-1) / np.sqrt(n_paths)
    field = np.sqrt(1.0 / (1.0 + k_factor)) * scattered + np.sqrt(k_factor / (1.0 + k_factor)) * np.exp(1j * k * x)
    return 20.0 * np.log10(np.abs(field))


def require_path_loss_model(value, name: str = "model") -> None:
    """Raise a ValueError naming ``name`` unless ``value`` is a :class:`PathLossModel` (a path-loss fit says how
    it becomes one)."""
    if not isinstance(value, PathLossModel):
        hint = "; a path-loss fit becomes one with fit.model()" if type(value).__name__ == "PathLossFit" else ""
        raise ValueError(f"{name} must be a PathLossModel, got {type(value).__name__}{hint}")
