"""The checks every static estimator shares: the anchors' geometry, implausible powers, the goodness of fit, the
channel's parameters and the anchors' heights.

Anchor heights (measured data, e.g. anchors near the ceiling and a tag carried at 1.3 m): every estimator takes
``tag_height_m`` (the RSS estimators read it from the model, ``model.tag_height_m``). Then ``anchors_m`` is
``(m, 3)`` (x, y, height), the tag moves in the plane ``z = tag_height_m``, positions are ``(..., 2)`` and every
range and power is that of the 3-D distance ``sqrt(|p - a_xy|^2 + (a_z - tag_height_m)^2)``. The linearized systems
stay exact (the known height moves to the right-hand side: ``|p - a_xy|^2 = d^2 - (a_z - h)^2``); the geometry checks
apply to the anchors' plan positions (:func:`plan_anchors`).
Without ``tag_height_m`` the anchors' dimension is the position's (2-D or 3-D alike).
"""
from __future__ import annotations

import numpy as np

from .._validate import as_array, check_scalar
from ..errors import DegenerateGeometryError
from ..models.channel import PathLossModel, log_distance_mean_dbm, pairwise_distance_m, require_path_loss_model

# the public API (locbook._API); goodness_of_fit, check_channel and plan_anchors serve the estimators
__all__ = ["check_anchor_geometry", "ANCHOR_CONDITION_RTOL", "implausible_powers", "IMPLAUSIBLE_SIGMAS",
           "GOODNESS_OF_FIT_ALPHA"]

#: A heard power more than this many shadowing sigmas above the model's mean at the estimator's near-field clamp
#: is not a reading of that channel (``status="implausible_reading"``: :func:`implausible_powers`); why 10 and
#: what it refuses: docs/architecture.md, "Static localization: thresholds".
IMPLAUSIBLE_SIGMAS = 10.0

#: False-alarm probability of the ML estimators' goodness-of-fit test (``status="poor_fit"``: the minimised cost
#: over sigma^2 beyond ``chi2.ppf(1 - GOODNESS_OF_FIT_ALPHA, m_heard - dim)``); why so small: docs/architecture.md,
#: "Static localization: thresholds".
GOODNESS_OF_FIT_ALPHA = 1e-9


#: Anchors whose centred coordinates have a smallest singular value below this fraction of the largest are
#: collinear (coplanar in 3-D): :func:`check_anchor_geometry`; why 1e-6: docs/architecture.md, "Static
#: localization: thresholds".
ANCHOR_CONDITION_RTOL = 1e-6


def check_anchor_geometry(anchors_m) -> np.ndarray:
    """Validate anchors ``(m, dim)``: finite, at least ``dim + 1`` anchors, no two at one point (closer than
    1 nm), not on one line (plane), nor nearly so: the smallest singular value of the centred anchor matrix must
    exceed :data:`ANCHOR_CONDITION_RTOL` (1e-6) times the largest (a scale-invariant conditioning criterion;
    docs/architecture.md says why 1e-6).

    Raises :class:`DegenerateGeometryError` naming the problem (``ValueError`` for a wrong shape or a
    non-finite coordinate).
    """
    anchors_m = as_array("anchors_m", anchors_m, ndim=2)
    m, dim = anchors_m.shape
    if dim < 1:
        raise ValueError(f"anchors_m must have shape (m, dim) with dim >= 1, got {anchors_m.shape}")
    if m < dim + 1:
        raise DegenerateGeometryError(
            f"{dim}-D localization needs at least {dim + 1} anchors, got {m}"
        )
    gaps = np.where(np.eye(m, dtype=bool), np.inf, pairwise_distance_m(anchors_m, anchors_m))
    if np.any(gaps <= 1e-9):
        i, j = np.argwhere(gaps <= 1e-9)[0]
        raise DegenerateGeometryError(f"anchors {i} and {j} coincide at {anchors_m[i].tolist()}: "
                                      "two anchors at one point are one anchor")
    centred = anchors_m - anchors_m.mean(axis=0)
    # the ratio is scale-invariant: normalise first, so coordinates near 1e300 do not overflow inside the SVD
    sv = np.linalg.svd(centred / np.max(np.abs(centred)), compute_uv=False)
    ratio = sv[dim - 1] / sv[0]
    if not ratio > ANCHOR_CONDITION_RTOL:
        rank = int(np.sum(sv > ANCHOR_CONDITION_RTOL * sv[0]))
        flat, across = ("coplanar", "across the plane they lie in") if dim == 3 else \
            ("collinear", "across the line they lie on")
        raise DegenerateGeometryError(
            f"the {m} anchors are {flat} or nearly so: the smallest singular value of the centred anchors is "
            f"{ratio:.3g} of the largest (numerical rank {rank} < {dim}; the bound is {ANCHOR_CONDITION_RTOL:g}), "
            f"so a position {across} cannot be resolved"
        )
    return anchors_m


def implausible_powers(rss_dbm, model: PathLossModel, clamp_m: float) -> np.ndarray:
    """Per problem ``(...)``: whether some heard power of ``rss_dbm (..., m)`` exceeds the model's mean at the
    near-field clamp ``clamp_m`` (a positive finite distance), ``P_0 - 10 n log10(clamp_m / d0)`` (walls and
    antenna heights only lower it), by more than :data:`IMPLAUSIBLE_SIGMAS` times the anchor's shadowing sigma.

    The physical assumption: a reading that implies a tag closer than ``clamp_m`` to an anchor's antenna (closer
    than 1 mm at the RSS ML's default clamp) is implausible, a unit error, a sentinel or an overflow rather than a
    tag touching the antenna. A real reading of a tag that close IS refused (with ``sigma_db = 0``, any power above
    the clamp mean); for a tag at least ``clamp_m`` away the model gives such a reading probability below 1e-23.
    NaN (not heard) is never implausible."""
    check_scalar("clamp_m", clamp_m, gt=0)     # 0 would give an infinite bound (nothing refused), NaN no bound
    top = (log_distance_mean_dbm(clamp_m, np.asarray(model.ref_power_dbm, float),
                                 np.asarray(model.path_loss_exp, float), ref_distance_m=model.ref_distance_m)
           + IMPLAUSIBLE_SIGMAS * np.asarray(model.sigma_db, float))
    return np.any(rss_dbm > top, axis=-1)


def goodness_of_fit(status: np.ndarray, cost: np.ndarray, model: PathLossModel, m: int, dim: int) -> np.ndarray:
    """``status`` with ``"ok"`` turned into ``"poor_fit"`` where ``cost / sigma^2`` exceeds the chi-square
    quantile ``chi2.ppf(1 - GOODNESS_OF_FIT_ALPHA, m - dim)`` (:data:`GOODNESS_OF_FIT_ALPHA`; ``m`` heard anchors).

    ``cost`` is the unweighted ``sum_j r_j^2`` (dB^2) the estimators minimise. With one sigma it is divided by
    ``sigma^2``: the ML residual statistic, chi-square with ``m - dim`` degrees of freedom under the model
    (linearised). With per-anchor sigma it is divided by the largest ``sigma_j^2``: then
    ``min_p sum r_j^2 / max sigma^2 <= min_p sum (r_j / sigma_j)^2``, the weighted ML residual statistic, so the
    test never flags more often than ``alpha`` (it is conservative). No test without shadowing (all sigma 0) or
    without redundancy (``m <= dim``)."""
    sigma_max = float(np.max(np.asarray(model.sigma_db, float)))
    dof = m - dim
    if not sigma_max > 0 or dof <= 0:
        return status
    from scipy.special import chdtri  # lazy: keeps `import locbook` fast
    bound = chdtri(dof, GOODNESS_OF_FIT_ALPHA)  # upper quantile: P(chi2_dof > bound) = alpha
    with np.errstate(over="ignore"):            # a huge finite cost over a tiny sigma is inf: still beyond the bound
        poor = (status == "ok") & (np.asarray(cost) / sigma_max**2 > bound)
    return np.where(poor, "poor_fit", status).astype("<U19")


def plan_anchors(anchors_m, tag_height_m):
    """``(anchors the positions live with, vertical offsets a_z - h (m,) or None)``: with a known tag height the
    anchors must be ``(m, 3)`` and the estimators work on their plan positions ``(m, 2)``."""
    if tag_height_m is None:
        return anchors_m, None
    check_scalar("tag_height_m", tag_height_m)
    anchors = as_array("anchors_m", anchors_m, ndim=2)
    if anchors.shape[1] != 3:
        raise ValueError(f"with tag_height_m the anchors must be (m, 3) (x, y, height), got shape {anchors.shape}")
    return anchors[:, :2], anchors[:, 2] - float(tag_height_m)


def check_channel(model, m: int) -> None:
    """The channel's parameters are scalars or per-anchor ``(m,)`` arrays, finite."""
    require_path_loss_model(model)
    for name in ("ref_power_dbm", "path_loss_exp", "sigma_db"):
        value = as_array(f"model.{name}", getattr(model, name))
        if value.ndim > 1 or value.size not in (1, m):
            raise ValueError(f"model.{name} must be a scalar or have shape ({m},) (one per anchor), "
                             f"got shape {value.shape}")
    if np.any(np.asarray(model.path_loss_exp) <= 0):
        raise ValueError(f"model.path_loss_exp must be positive, got {model.path_loss_exp!r}")


