"""Cramer-Rao lower bound for static RSS localization.

With received powers ``P_j ~ N(P_0 - 10 n log10 d_j, sigma^2)``, independent across anchors, the Fisher
information of the position p is (Patwari et al. 2003, Eq. (5); Ozkaya 2011, Appendix A, corrected)

    J(p) = (10 n / (sigma ln 10))^2  sum_j (p - a_j)(p - a_j)^T / d_j^4,

and any unbiased estimator has ``E|p_hat - p|^2 >= tr J^{-1}`` (Ozkaya Eq. (A.5): (F_xx + F_yy) / det F).

Ozkaya's Appendix A prints ``d_j^2`` in the denominators (Eqs. (A.10)-(A.12)), which makes the bound
dimensionless and scale-invariant; it is kept as ``form="ozkaya_printed"`` (flagged) because, with
n = 2, it reproduces the thesis's CRLB numbers (our finding; the simulations themselves use n = 2.3).
"""
from __future__ import annotations

import numpy as np

from ..errors import DegenerateGeometryError
from .._validate import as_array, check_choice, check_scalar
from ..models.channel import PathLossModel
from ..models.rss import RssModel
from ..static.localization import check_anchor_geometry

__all__ = ["rss_fisher_information", "rss_position_information", "rss_crlb_m", "crlb_rms_over_area_m", "CRLB_FORMS"]

CRLB_FORMS = ("correct", "ozkaya_printed")


def rss_fisher_information(position_m, anchors_m, path_loss_exp, sigma_db, form: str = "correct", *,
                           min_distance_m: float = 0.0, height_offset_m: float = 0.0):
    """Fisher information ``(..., 2, 2)`` of the position from RSS at ``position_m`` ``(..., 2)``.

    ``path_loss_exp`` and ``sigma_db`` may be scalars or per-anchor arrays ``(m,)``. The anchors must resolve a
    position on their own (at least 3, not collinear); :func:`rss_position_information` is the same formula
    without that check, for bounds where a prior or a motion model supplies the rest (the posterior CRLB).
    """
    return rss_position_information(position_m, check_anchor_geometry(anchors_m), path_loss_exp, sigma_db, form,
                                    min_distance_m=min_distance_m, height_offset_m=height_offset_m)


def rss_position_information(position_m, anchors_m, path_loss_exp, sigma_db, form: str = "correct", *,
                             min_distance_m: float = 0.0, height_offset_m: float = 0.0, heard=None):
    """``beta^2 sum_j (p - a_j)(p - a_j)^T / d_j^4``, ``beta = 10 n / (sigma ln 10)``, for any anchors ``(m, 2)``.

    ``E[1/d^2]`` diverges for position densities positive at an anchor (so the sample average of Dogan 2015,
    Eq. (4.22), has infinite variance), so two regularisations
    are offered: ``height_offset_m`` (antenna height difference, a scalar or one per anchor,
    ``d^2 = |p - a|^2 + h^2``, the exact information of that model, e.g. anchors near the ceiling and a tag at a
    known height) and ``min_distance_m`` (the near-field clamp of the model, ``max(d, d_min)`` in the law: its mean
    is flat within ``d_min`` of an anchor, so a reading there carries no information and its term is 0). The
    information is :meth:`locbook.models.rss.RssModel.fisher_information` of that model (``form="correct"``);
    ``form="ozkaya_printed"`` uses ``d^2`` in the denominator (flagged, see module docstring; within the clamp
    ``d_min^2``).
    ``heard``: booleans broadcastable to ``(..., m)``, False where an anchor gave no reading (NaN = not heard, the
    library's rule): a reading that is not there carries no information, so its term is left out.
    """
    check_choice("form", form, CRLB_FORMS)
    anchors_m = as_array("anchors_m", anchors_m, ndim=2)
    m = anchors_m.shape[0]
    position_m = as_array("position_m", position_m, min_ndim=1, trailing=(anchors_m.shape[1],))
    for name, value in (("path_loss_exp", path_loss_exp), ("sigma_db", sigma_db)):
        value = as_array(name, value)
        if value.ndim > 1 or value.size not in (1, m) or np.any(value <= 0):
            raise ValueError(f"{name} must be a positive scalar or ({m},) array (one per anchor), got {value.tolist()}")
    check_scalar("min_distance_m", min_distance_m, ge=0)
    height = as_array("height_offset_m", height_offset_m)
    if height.ndim > 1 or height.size not in (1, m):
        raise ValueError(f"height_offset_m must be a scalar or ({m},) array (one per anchor: anchor height minus tag "
                         f"height), got shape {height.shape}")
    diff = position_m[..., None, :] - anchors_m  # (..., m, 2)
    d2 = np.einsum("...i,...i->...", diff, diff) + height**2
    if min_distance_m == 0 and np.any(d2 == 0):
        where = tuple(int(i) for i in np.argwhere(d2 == 0)[0])
        raise DegenerateGeometryError(f"the RSS Fisher information is undefined at an anchor position (d = 0): "
                                      f"position_m{list(where[:-1])} = {position_m[where[:-1]].tolist()} is anchor "
                                      f"{where[-1]}; give height_offset_m (antenna height difference) or "
                                      f"min_distance_m (the near-field clamp)")
    if heard is not None:
        heard = np.asarray(heard)
        if heard.dtype != bool:
            raise ValueError(f"heard must be booleans (False = not heard), got dtype {heard.dtype}")
        try:
            heard = np.broadcast_to(heard, d2.shape)
        except ValueError:
            raise ValueError(f"heard must broadcast to (..., {m}) = {d2.shape}, got shape {heard.shape}") from None
    if form == "ozkaya_printed":    # a flagged variant of the bound, not of the model: d^2 where the model has d^4
        gain = (10.0 * np.asarray(path_loss_exp, float) / (np.asarray(sigma_db, float) * np.log(10.0))) ** 2
        gain = np.broadcast_to(gain, d2.shape) if heard is None else gain * heard
        return np.einsum("...j,...ji,...jk->...ik", gain / np.maximum(d2, min_distance_m**2), diff, diff)
    # the one RSS model's information (its Jacobian, exactly 0 within the clamp, where the clamped mean is flat)
    channel = PathLossModel(0.0, np.asarray(path_loss_exp, float), np.asarray(sigma_db, float),
                            min_distance_m=float(min_distance_m))
    if np.any(height != 0):         # the anchors' heights above the tag's plane z = 0
        if anchors_m.shape[1] != 2:
            raise ValueError(f"height_offset_m needs plan anchors (m, 2) (the tag in a plane), got {anchors_m.shape}")
        model = RssModel(np.column_stack([anchors_m, np.broadcast_to(height, (m,))]), channel, tag_height_m=0.0)
    else:
        model = RssModel(anchors_m, channel)
    batch = position_m.shape[:-1]
    flat = position_m.reshape(-1, anchors_m.shape[1])
    info = model.fisher_information(flat, heard=None if heard is None else heard.reshape(1, -1, m))
    return info.reshape(batch + info.shape[-2:])


def rss_crlb_m(position_m, anchors_m, path_loss_exp, sigma_db, form: str = "correct", *,
               tag_height_m: float | None = None, heard=None):
    """Position RMSE bound ``sqrt(tr J^{-1})`` (m) at each position ``(..., 2)`` -> ``(...)``.

    In 2-D by Ozkaya's closed form (A.5); for anchors in another dimension ``(m, dim)`` (positions
    ``(..., dim)``) by the trace of the inverse. Positions must be finite and off the anchors.

    With 3-D anchors ``(m, 3)`` the choice is explicit: without ``tag_height_m`` the bound is the 3-D one of a
    position whose height is unknown too (positions ``(..., 3)``; often mostly height error); with
    ``tag_height_m`` it is the 2-D bound of ``(x, y)`` (positions ``(..., 2)``) for a tag at that known height:
    each anchor's height above the tag enters the distance (``rss_fisher_information``'s ``height_offset_m``),
    i.e. the ``(x, y)`` block of the 3-D information, not its Schur complement.

    ``heard`` ``(..., m)`` booleans (measured data: False = the anchor heard nothing at that epoch): the bound of
    the anchors each position heard (2-D positions only); where those cannot fix a position (fewer than two, or
    aligned with it) the bound is ``inf``."""
    # with a heard mask a position may see too few anchors: no up-front geometry check, inf where singular
    information = rss_fisher_information if heard is None else rss_position_information
    extra = {} if heard is None else {"heard": heard}
    if tag_height_m is not None:
        anchors = as_array("anchors_m", anchors_m, ndim=2)
        if anchors.shape[1] != 3:
            raise ValueError(f"tag_height_m needs 3-D anchors (m, 3) with their heights, got shape {anchors.shape}")
        check_scalar("tag_height_m", tag_height_m)
        info = information(position_m, anchors[:, :2], path_loss_exp, sigma_db, form,
                           height_offset_m=anchors[:, 2] - tag_height_m, **extra)
    else:
        info = information(position_m, anchors_m, path_loss_exp, sigma_db, form, **extra)
    if info.shape[-1] != 2:
        if heard is not None:
            raise ValueError("heard= gives the bound of 2-D positions (plan anchors, or 3-D ones with tag_height_m)")
        return np.sqrt(np.trace(np.linalg.inv(info), axis1=-2, axis2=-1))
    det = info[..., 0, 0] * info[..., 1, 1] - info[..., 0, 1] ** 2
    trace = info[..., 0, 0] + info[..., 1, 1]
    if heard is None:
        return np.sqrt(trace / det)   # (F_xx + F_yy) / (F_xx F_yy - F_xy^2)
    ok = det > 1e-12 * trace**2       # rank 2, beyond rounding
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(ok, np.sqrt(trace / np.where(ok, det, 1.0)), np.inf)


def crlb_rms_over_area_m(points_m, anchors_m, path_loss_exp, sigma_db, form: str = "correct", *,
                         tag_height_m: float | None = None):
    """RMS of the bound over target positions ``(P, 2)``: ``sqrt(mean_p tr J(p)^{-1})``, the
    area-average used by Ozkaya (2011) for Fig. 7.1 and the CRLB columns (``tag_height_m``: :func:`rss_crlb_m`)."""
    points_m = as_array("points_m", points_m, min_ndim=1)
    if points_m.size == 0:
        raise ValueError(f"points_m must hold at least one position, got shape {points_m.shape}")
    bound = rss_crlb_m(points_m, anchors_m, path_loss_exp, sigma_db, form, tag_height_m=tag_height_m)
    return float(np.sqrt(np.mean(bound**2)))
