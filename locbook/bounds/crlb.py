"""Cramer-Rao lower bound for static RSS localization.

With received powers ``P_j ~ N(P_0 - 10 n log10 d_j, sigma^2)``, independent across anchors, the Fisher
information of the position p is (Patwari et al. 2003, Eq. (5); Ozkaya 2011, Appendix A, corrected)

    J(p) = (10 n / (sigma ln 10))^2  sum_j (p - a_j)(p - a_j)^T / d_j^4,

and any unbiased estimator has ``E|p_hat - p|^2 >= tr J^{-1}`` (Ozkaya Eq. (A.5): (F_xx + F_yy) / det F).

Every bound takes the one RSS measurement model, :class:`locbook.models.rss.RssModel` (the points first, then the
model, then keyword-only options): its anchors, its channel's exponent ``n``, sigma and near-field clamp
``min_distance_m``, and with ``tag_height_m`` the anchors' heights above the tag (3-D distances, plan positions).
What a bound of one reading per anchor cannot honour is refused by name: walls (``walls_m``) and per-run or
per-step anchors or parameters.

Ozkaya's Appendix A prints ``d_j^2`` in the denominators (Eqs. (A.10)-(A.12)), which makes the bound
dimensionless and scale-invariant; it is kept as ``variant="literal_ozkaya2011"`` (flagged) because, with
n = 2, it reproduces the thesis's CRLB numbers (our finding; the simulations themselves use n = 2.3). It uses the
same model's n, sigma and clamp.

Ranges (RTT / ToA, :class:`locbook.models.range.RangeModel`, ``z_j = d_j + v_j``, ``v_j ~ N(0, sigma_j^2)``) have
the information ``J = sum_j u_j u_j^T / sigma_j^2`` with ``u_j`` the unit vector from anchor ``j`` to the position
(:func:`range_position_information`, :func:`range_crlb_m`, :func:`range_crlb_checked_m`).

On measured data each epoch hears its own anchors: :func:`rss_crlb_checked_m` gives the bound where it means something
and NaN with a reason elsewhere (fewer than :data:`MIN_ANCHORS_FOR_BOUND` anchors heard, or a condition number above
:data:`MAX_BOUND_CONDITION`), so that no near-singular epoch (a bound of 1e8 m) swamps an RMS over a recording.

The earlier call forms (``rss_crlb_m(position_m, anchors_m, path_loss_exp, sigma_db, form="correct", ...)``,
told apart by an array in the second place) still work for one release, with a ``DeprecationWarning`` naming the new
call; so do the old ``form=`` values ``"correct"`` and ``"ozkaya_printed"`` given as ``variant=``.
"""
from __future__ import annotations

import functools
import inspect

import numpy as np

from .._deprecation import RENAMED_CRLB_FORMS, check_variant, renamed_constants, warn_deprecated
from .._linalg import _location_information
from .._validate import as_array, check_choice, check_scalar
from ..errors import DegenerateGeometryError, ParameterError
from ..models.channel import PathLossModel
from ..models.rss import RssModel
from ..static.localization import check_anchor_geometry

__all__ = ["rss_fisher_information", "rss_position_information", "rss_crlb_m", "crlb_rms_over_area_m", "CRLB_VARIANTS",
           "MIN_ANCHORS_FOR_BOUND", "MAX_BOUND_CONDITION", "check_position_information", "rss_crlb_checked_m",
           "range_position_information", "range_crlb_m", "range_crlb_checked_m"]

#: the bound's forms: the corrected Fisher information (1/d^4) and Ozkaya's printed one (1/d^2, flagged)
CRLB_VARIANTS = ("corrected", "literal_ozkaya2011")
#: the old name and spellings (``form=``), one release
__getattr__ = renamed_constants(__name__, {"CRLB_FORMS": ("CRLB_VARIANTS", tuple(RENAMED_CRLB_FORMS))})


def _bound_model(model, who: str = "the bound") -> RssModel:
    """``model`` if it is an :class:`~locbook.models.rss.RssModel` a bound can use, else one ValueError line naming
    what to pass: an RssModel without walls, with one set of anchors and parameters (no run or step axes)."""
    if not isinstance(model, RssModel):
        got = type(model).__name__
        hint = (" (give it to RssModel(anchors_m, channel, tag_height_m=...))" if isinstance(model, PathLossModel)
                else "")
        raise ValueError(f"{who} takes model = RssModel(anchors_m, channel) (the anchors and a PathLossModel with the "
                         f"exponent, sigma and clamp), got {got}{hint}")
    if model.walls_m is not None and model.channel.wall_attenuation_db != 0.0:
        raise ValueError(f"{who} cannot honour the model's walls (walls_m): the bound is that of the log-distance mean "
                         "alone; pass dataclasses.replace(model, walls_m=None)")
    per_run = [f"{name} {shape} per run or step" for name, shape in model.per_run_or_step().items()]
    if per_run:
        raise ValueError(f"{who} takes one set of anchors and parameters, the model has {', '.join(per_run)}: pass "
                         "one run's and step's model (e.g. model.select_runs(r) for run r)")
    return model


def _variant(variant, who: str) -> str:
    return check_variant(variant, CRLB_VARIANTS, where=who, renamed=RENAMED_CRLB_FORMS)


def _old_form(old):
    """Decorator: a call whose second argument is an array (the anchors: the earlier, deprecated form) goes to ``old``,
    which warns and calls the new form; an RssModel (or anything else, refused by :func:`_bound_model`) to the new."""
    old_signature = inspect.signature(old)

    def wrap(new):
        @functools.wraps(new)
        def call(*args, **kwargs):
            second = args[1] if len(args) > 1 else kwargs.get("anchors_m")
            if isinstance(second, (np.ndarray, list, tuple)):
                try:
                    old_signature.bind(*args, **kwargs)
                except TypeError:   # neither form: an array where the model goes
                    _bound_model(second, new.__name__)
                return old(*args, **kwargs)
            return new(*args, **kwargs)
        return call
    return wrap


def _old_model(anchors_m, path_loss_exp, sigma_db, *, min_distance_m=0.0, height_offset_m=0.0,
               tag_height_m=None) -> RssModel:
    """The RssModel of an old-form call, with the old form's checks (the same model, so the same bits, as before)."""
    anchors_m = as_array("anchors_m", anchors_m, ndim=2)
    m = anchors_m.shape[0]
    for name, value in (("path_loss_exp", path_loss_exp), ("sigma_db", sigma_db)):
        value = as_array(name, value)
        if value.ndim > 1 or value.size not in (1, m) or np.any(value <= 0):
            raise ValueError(f"{name} must be a positive scalar or ({m},) array (one per anchor), got {value.tolist()}")
    check_scalar("min_distance_m", min_distance_m, ge=0)
    channel = PathLossModel(0.0, np.asarray(path_loss_exp, float), np.asarray(sigma_db, float),
                            min_distance_m=float(min_distance_m))
    if tag_height_m is not None:
        if anchors_m.shape[1] != 3:
            raise ValueError(f"tag_height_m needs 3-D anchors (m, 3) with their heights, got shape {anchors_m.shape}")
        check_scalar("tag_height_m", tag_height_m)
        return RssModel(anchors_m, channel, tag_height_m=tag_height_m)
    height = as_array("height_offset_m", height_offset_m)
    if height.ndim > 1 or height.size not in (1, m):
        raise ValueError(f"height_offset_m must be a scalar or ({m},) array (one per anchor: anchor height minus tag "
                         f"height), got shape {height.shape}")
    if np.any(height != 0):         # the anchors' heights above the tag's plane z = 0
        if anchors_m.shape[1] != 2:
            raise ValueError(f"height_offset_m needs plan anchors (m, 2) (the tag in a plane), got {anchors_m.shape}")
        return RssModel(np.column_stack([anchors_m, np.broadcast_to(height, (m,))]), channel, tag_height_m=0.0)
    return RssModel(anchors_m, channel)


def _old_variant(form) -> str:
    check_choice("form", form, tuple(RENAMED_CRLB_FORMS) + CRLB_VARIANTS)
    return RENAMED_CRLB_FORMS.get(form, form)


def _warn_old(name: str, old: str, new: str) -> None:
    warn_deprecated(f"{name}({old})", f"{name}({new})", skip=(__name__,))


_NEW_MODEL = "RssModel(anchors_m, PathLossModel(0.0, path_loss_exp, sigma_db, min_distance_m=...){})"


def _old_fisher_information(position_m, anchors_m, path_loss_exp, sigma_db, form: str = "correct", *,
                            min_distance_m: float = 0.0, height_offset_m: float = 0.0):
    _warn_old("rss_fisher_information", "position_m, anchors_m, path_loss_exp, sigma_db, form, ...",
              "position_m, " + _NEW_MODEL.format("") + ", variant=...")
    variant = _old_variant(form)
    check_anchor_geometry(anchors_m)
    return rss_fisher_information(position_m, _old_model(anchors_m, path_loss_exp, sigma_db,
                                                         min_distance_m=min_distance_m,
                                                         height_offset_m=height_offset_m), variant=variant)


def _old_position_information(position_m, anchors_m, path_loss_exp, sigma_db, form: str = "correct", *,
                              min_distance_m: float = 0.0, height_offset_m: float = 0.0, heard=None):
    _warn_old("rss_position_information", "position_m, anchors_m, path_loss_exp, sigma_db, form, ...",
              "position_m, " + _NEW_MODEL.format("") + ", variant=..., heard=...")
    variant = _old_variant(form)
    return rss_position_information(position_m, _old_model(anchors_m, path_loss_exp, sigma_db,
                                                           min_distance_m=min_distance_m,
                                                           height_offset_m=height_offset_m),
                                    variant=variant, heard=heard)


def _old_crlb_m(position_m, anchors_m, path_loss_exp, sigma_db, form: str = "correct", *,
                tag_height_m: float | None = None, heard=None):
    _warn_old("rss_crlb_m", "position_m, anchors_m, path_loss_exp, sigma_db, form, tag_height_m=...",
              "position_m, " + _NEW_MODEL.format(", tag_height_m=...") + ", variant=..., heard=...")
    variant = _old_variant(form)
    return rss_crlb_m(position_m, _old_model(anchors_m, path_loss_exp, sigma_db, tag_height_m=tag_height_m),
                      variant=variant, heard=heard)


def _old_rms_over_area_m(points_m, anchors_m, path_loss_exp, sigma_db, form: str = "correct", *,
                         tag_height_m: float | None = None):
    _warn_old("crlb_rms_over_area_m", "points_m, anchors_m, path_loss_exp, sigma_db, form, tag_height_m=...",
              "points_m, " + _NEW_MODEL.format(", tag_height_m=...") + ", variant=...")
    variant = _old_variant(form)
    return crlb_rms_over_area_m(points_m, _old_model(anchors_m, path_loss_exp, sigma_db, tag_height_m=tag_height_m),
                                variant=variant)


@_old_form(_old_fisher_information)
def rss_fisher_information(position_m, model, *, variant: str = "corrected"):
    """Fisher information ``(..., dim, dim)`` of the position from RSS at ``position_m`` ``(..., dim)``, for the RSS
    model ``model`` (:class:`~locbook.models.rss.RssModel`; the channel's ``path_loss_exp`` and ``sigma_db`` scalars
    or per anchor ``(m,)``). The anchors must resolve a position on their own (at least ``dim + 1``, not collinear);
    :func:`rss_position_information` is the same formula without that check, for bounds where a prior or a motion
    model supplies the rest (the posterior CRLB).
    """
    model = _bound_model(model, "rss_fisher_information")
    variant = _variant(variant, "rss_fisher_information")
    check_anchor_geometry(model.anchors_m[:, :model.dim])
    return rss_position_information(position_m, model, variant=variant)


@_old_form(_old_position_information)
def rss_position_information(position_m, model, *, variant: str = "corrected", heard=None):
    """``beta^2 sum_j (p - a_j)(p - a_j)^T / d_j^4``, ``beta = 10 n / (sigma ln 10)``, for any anchors of ``model``.

    ``E[1/d^2]`` diverges for position densities positive at an anchor (so the sample average of Dogan 2015,
    Eq. (4.22), has infinite variance), so the model's two regularisations apply: anchors with heights
    (``tag_height_m`` and anchors ``(m, 3)``: ``d^2 = |p - a|^2 + (z_j - h)^2``, the exact information of that model,
    e.g. anchors near the ceiling and a tag at a known height) and the channel's ``min_distance_m`` (the near-field
    clamp of the model, ``max(d, d_min)`` in the law: its mean is flat within ``d_min`` of an anchor, so a reading
    there carries no information and its term is 0). The information is
    :meth:`locbook.models.rss.RssModel.fisher_information` of that model (``variant="corrected"``);
    ``variant="literal_ozkaya2011"`` uses ``d^2`` in the denominator (flagged, see module docstring; within the clamp
    ``d_min^2``).
    ``heard``: booleans broadcastable to ``(..., m)``, False where an anchor gave no reading (NaN = not heard, the
    library's rule): a reading that is not there carries no information, so its term is left out.
    """
    model = _bound_model(model, "rss_position_information")
    variant = _variant(variant, "rss_position_information")
    m, dim = model.n_anchors, model.dim
    position_m = as_array("position_m", position_m, min_ndim=1, trailing=(dim,))
    ch = model.channel
    min_distance_m = ch.min_distance_m
    anchors = model.anchors_m
    diff = position_m[..., None, :] - anchors[:, :dim]  # (..., m, dim)
    vertical = 0.0 if model.tag_height_m is None else anchors[:, -1] - model.tag_height_m
    d2 = np.einsum("...i,...i->...", diff, diff) + vertical**2
    if min_distance_m == 0 and np.any(d2 == 0):
        where = tuple(int(i) for i in np.argwhere(d2 == 0)[0])
        raise DegenerateGeometryError(f"the RSS Fisher information is undefined at an anchor position (d = 0): "
                                      f"position_m{list(where[:-1])} = {position_m[where[:-1]].tolist()} is anchor "
                                      f"{where[-1]}; give the model anchor heights (anchors (m, 3) with "
                                      f"tag_height_m) or the channel a min_distance_m (the near-field clamp)")
    if heard is not None:
        heard = np.asarray(heard)
        if heard.dtype != bool:
            raise ValueError(f"heard must be booleans (False = not heard), got dtype {heard.dtype}")
        try:
            heard = np.broadcast_to(heard, d2.shape)
        except ValueError:
            raise ValueError(f"heard must broadcast to (..., {m}) = {d2.shape}, got shape {heard.shape}") from None
    if variant == "literal_ozkaya2011":    # a flagged variant of the bound, not of the model: d^2 where it has d^4
        sigma = np.asarray(ch.sigma_db, float)
        if np.any(sigma <= 0):
            raise ValueError(f"the Fisher information needs sigma_db > 0 (channel.sigma_db), got {ch.sigma_db!r}")
        gain = (10.0 * np.asarray(ch.path_loss_exp, float) / (sigma * np.log(10.0))) ** 2
        gain = np.broadcast_to(gain, d2.shape) if heard is None else gain * heard
        return np.einsum("...j,...ji,...jk->...ik", gain / np.maximum(d2, float(min_distance_m)**2), diff, diff)
    # the one RSS model's information (its Jacobian, exactly 0 within the clamp, where the clamped mean is flat)
    batch = position_m.shape[:-1]
    flat = position_m.reshape(-1, dim)
    info = model.fisher_information(flat, heard=None if heard is None else heard.reshape(1, -1, m))
    return info.reshape(batch + info.shape[-2:])


@_old_form(_old_crlb_m)
def rss_crlb_m(position_m, model, *, variant: str = "corrected", heard=None):
    """Position RMSE bound ``sqrt(tr J^{-1})`` (m) at each position ``(..., dim)`` -> ``(...)`` for the RSS model
    ``model`` (:class:`~locbook.models.rss.RssModel`).

    In 2-D by Ozkaya's closed form (A.5); for anchors in another dimension ``(m, dim)`` (positions
    ``(..., dim)``) by the trace of the inverse. Positions must be finite and off the anchors.

    With 3-D anchors ``(m, 3)`` the choice is the model's: without ``tag_height_m`` the bound is the 3-D one of a
    position whose height is unknown too (positions ``(..., 3)``; often mostly height error); with
    ``tag_height_m`` it is the 2-D bound of ``(x, y)`` (positions ``(..., 2)``) for a tag at that known height:
    each anchor's height above the tag enters the distance, i.e. the ``(x, y)`` block of the 3-D information, not
    its Schur complement.

    ``heard`` ``(..., m)`` booleans (measured data: False = the anchor heard nothing at that epoch): the bound of
    the anchors each position heard (2-D positions only); where those cannot fix a position (fewer than two, or
    aligned with it) the bound is ``inf``.

    Examples
    --------
    The centre of a 10 m square of anchors, sigma 3 dB, exponent 2:

    >>> import numpy as np
    >>> import locbook as lb
    >>> anchors = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
    >>> model = lb.RssModel(anchors, lb.PathLossModel(-40.0, 2.0, sigma_db=3.0))
    >>> print(np.round(lb.rss_crlb_m(np.array([[5.0, 5.0]]), model), 3))
    [2.442]
    """
    variant = _variant(variant, "rss_crlb_m")
    # with a heard mask a position may see too few anchors: no up-front geometry check, inf where singular
    if heard is None:
        info = rss_fisher_information(position_m, model, variant=variant)
    else:
        info = rss_position_information(position_m, model, variant=variant, heard=heard)
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


@_old_form(_old_rms_over_area_m)
def crlb_rms_over_area_m(points_m, model, *, variant: str = "corrected"):
    """RMS of the bound over target positions ``(P, dim)``: ``sqrt(mean_p tr J(p)^{-1})``, the
    area-average used by Ozkaya (2011) for Fig. 7.1 and the CRLB columns (``model``, ``variant``:
    :func:`rss_crlb_m`)."""
    points_m = as_array("points_m", points_m, min_ndim=1)
    if points_m.size == 0:
        raise ValueError(f"points_m must hold at least one position, got shape {points_m.shape}")
    bound = rss_crlb_m(points_m, model, variant=_variant(variant, "crlb_rms_over_area_m"))
    return float(np.sqrt(np.mean(bound**2)))


# ------------------------------------------------------------------------------------- checked per-epoch bounds

#: Fewest anchors heard for a plan bound. RSS ranges from two anchors meet in two points (a two-fold ambiguity
#: mirrored about their baseline) and their information is near-singular near that line, so the bound of a plan
#: position from RSS alone needs three anchors (a fix), as lateration does.
MIN_ANCHORS_FOR_BOUND = 3

#: Largest condition number ``lambda_max / lambda_min`` of a 2x2 position information accepted for a bound. The
#: bound ``sqrt(tr J^{-1})`` is then dominated by the weak direction, whose standard deviation is
#: ``sqrt(condition)`` times the strong one's: beyond 1e6 (a factor of 1000, e.g. 0.5 m across and 500 m along)
#: the ellipse is a line, not a fix, and its size (far beyond any floor) describes no estimator's error.
MAX_BOUND_CONDITION = 1e6

#: The reason given to an epoch whose true position is unknown (NaN): :mod:`locbook.bounds.summary` counts it as
#: "no truth".
NO_TRUTH_REASON = "no true position"


def _too_few_reason(k: int, needed: int) -> str:
    return f"heard {k} anchor{'' if k == 1 else 's'}, a plan fix needs {needed}"


def check_position_information(information, n_heard=None, *, min_anchors: int = MIN_ANCHORS_FOR_BOUND,
                               max_condition: float = MAX_BOUND_CONDITION):
    """``(bound_m (...), reason (...))``: the bound ``sqrt(tr J^{-1})`` of a plan position from its 2x2 information
    ``J`` ``(..., 2, 2)`` (1/m^2), where it is meaningful, else NaN and one short reason.

    ``sqrt(tr J^{-1}) = sqrt((J_xx + J_yy) / (J_xx J_yy - J_xy^2))`` (Ozkaya 2011, Eq. (A.5)). ``reason`` (an
    object array of str) is ``""`` where the bound is defined, else, first that applies:

    - ``"heard k anchors, a plan fix needs 3"`` where ``n_heard`` (``(...)``, anchors heard at each epoch; ``None``
      skips this check, e.g. for a posterior information where a prior supplies the rest) is below ``min_anchors``
      (:data:`MIN_ANCHORS_FOR_BOUND`);
    - ``"no information (NaN)"`` where ``J`` holds NaN (nothing was computed for that epoch);
    - ``"singular information (rank below 2)"`` where ``det J <= 0`` (after rounding);
    - ``"near-singular information (condition 3.2e+09)"`` where the condition number
      ``lambda_max / lambda_min = lambda_max^2 / det J`` exceeds ``max_condition`` (:data:`MAX_BOUND_CONDITION`).

    Where the reason is not empty the bound is NaN (never inf, never the huge number a near-singular ``J`` gives).
    """
    info = as_array("information", information, min_ndim=2, trailing=(2, 2), nan_ok=True)
    batch = info.shape[:-2]
    min_anchors = int(check_scalar("min_anchors", min_anchors, ge=1, integer=True))
    max_condition = check_scalar("max_condition", max_condition, gt=1, allow_inf=True)
    flat = info.reshape(-1, 2, 2)                       # epochs on one axis (a single epoch is a batch of one)
    a, b, c, d = flat[:, 0, 0], flat[:, 0, 1], flat[:, 1, 0], flat[:, 1, 1]
    missing = np.isnan(flat).any(axis=(-2, -1))
    with np.errstate(invalid="ignore"):
        negative = (a < 0) | (d < 0)
        asym = np.abs(b - c) > 1e-9 * np.maximum(np.abs(a) + np.abs(d), np.finfo(float).tiny)
    for bad, what in ((negative, "positive semi-definite (a negative diagonal)"), (asym & ~missing, "symmetric")):
        if bad.any():
            first = int(np.argmax(bad))
            where = str([int(i) for i in np.unravel_index(first, batch)]) if batch else ""
            raise ParameterError(f"information must be {what}; information{where} = {flat[first].tolist()}")
    reason = np.full(flat.shape[0], "", dtype=object)
    trace = a + d
    det = a * d - b * c                                   # J_xx J_yy - J_xy^2
    # eigenvalues tr/2 +- sqrt(((J_xx - J_yy)/2)^2 + J_xy^2); lambda_min = det / lambda_max avoids cancellation
    with np.errstate(invalid="ignore"):
        lam_max = 0.5 * trace + np.sqrt(0.25 * (a - d) ** 2 + b * c)
    singular = ~missing & ~(det > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        condition = np.where(singular | missing, np.inf, lam_max**2 / np.where(det > 0, det, 1.0))
    near = ~missing & ~singular & (condition > max_condition)
    for i in np.flatnonzero(near):                       # the flagged epochs only: each its own number
        reason[i] = f"near-singular information (condition {condition[i]:.1e})"
    reason[singular] = "singular information (rank below 2)"
    reason[missing] = "no information (NaN)"
    if n_heard is not None:
        heard_n = np.asarray(n_heard)
        if not np.issubdtype(heard_n.dtype, np.integer) or np.any(heard_n < 0):
            raise ParameterError(f"n_heard must be counts of anchors heard (integers >= 0), got {heard_n.dtype} "
                                 f"values")
        try:
            heard_n = np.broadcast_to(heard_n, batch).ravel()
        except ValueError:
            raise ParameterError(f"n_heard must broadcast to the information's batch shape {batch}, got shape "
                                 f"{heard_n.shape}") from None
        few = heard_n < min_anchors
        for k in np.unique(heard_n[few]):           # one reason per count heard (a few values), not per epoch
            reason[few & (heard_n == k)] = _too_few_reason(int(k), min_anchors)
    ok = reason == ""
    with np.errstate(divide="ignore", invalid="ignore"):
        bound = np.where(ok, np.sqrt(trace / np.where(ok, det, 1.0)), np.nan)   # sqrt((J_xx + J_yy) / det J)
    bound, reason = bound.reshape(batch), reason.reshape(batch)
    return bound, reason


def _old_crlb_checked_m(position_m, anchors_m, path_loss_exp, sigma_db, *, tag_height_m: float | None = None,
                        heard=None, min_anchors: int = MIN_ANCHORS_FOR_BOUND,
                        max_condition: float = MAX_BOUND_CONDITION):
    _warn_old("rss_crlb_checked_m", "position_m, anchors_m, path_loss_exp, sigma_db, tag_height_m=...",
              "position_m, " + _NEW_MODEL.format(", tag_height_m=...") + ", heard=...")
    anchors = as_array("anchors_m", anchors_m, ndim=2)
    if tag_height_m is not None and anchors.shape[1] != 3:
        raise ParameterError(f"tag_height_m needs 3-D anchors (m, 3) with their heights, got shape "
                             f"{anchors.shape}")
    if tag_height_m is None and anchors.shape[1] != 2:
        raise ParameterError(f"anchors_m must be plan anchors (m, 2), or (m, 3) with tag_height_m (the bound is "
                             f"that of a plan position), got shape {anchors.shape}")
    return rss_crlb_checked_m(position_m, _old_model(anchors, path_loss_exp, sigma_db, tag_height_m=tag_height_m),
                              heard=heard, min_anchors=min_anchors, max_condition=max_condition)


@_old_form(_old_crlb_checked_m)
def rss_crlb_checked_m(position_m, model, *, heard=None, min_anchors: int = MIN_ANCHORS_FOR_BOUND,
                       max_condition: float = MAX_BOUND_CONDITION):
    """``(bound_m (...), reason (...))``: :func:`rss_crlb_m` (``variant="corrected"``) at plan positions ``(..., 2)``,
    checked epoch by epoch: NaN with a short reason where the bound says nothing (:func:`check_position_information`).

    ``model``: an :class:`~locbook.models.rss.RssModel` of plan positions, anchors ``(m, 2)``, or ``(m, 3)`` with
    ``tag_height_m`` (the tag at that known height: each anchor's height above the tag enters the distance, as in
    :func:`rss_crlb_m`). ``heard`` ``(..., m)`` booleans (False = the anchor heard nothing at that epoch; ``None`` =
    every anchor heard): the information is that of the anchors heard (:func:`rss_position_information`), and an
    epoch that heard fewer than ``min_anchors`` has ``"heard k anchors, a plan fix needs 3"``. A position holding NaN
    (true position unknown) has ``"no true position"``. Where the bound is defined it equals :func:`rss_crlb_m`'s.
    """
    model = _bound_model(model, "rss_crlb_checked_m")
    if model.dim != 2:
        raise ParameterError(f"rss_crlb_checked_m gives the bound of a plan position: the model must read 2-D "
                             f"positions (anchors (m, 2), or (m, 3) with tag_height_m), its anchors "
                             f"{model.anchors_m.shape} give {model.dim}-D")
    m = model.n_anchors
    position = as_array("position_m", position_m, min_ndim=1, trailing=(2,), nan_ok=True)
    batch = position.shape[:-1]
    if heard is None:
        heard_b = np.ones(batch + (m,), dtype=bool)
    else:
        heard_b = np.asarray(heard)
        if heard_b.dtype != bool:
            raise ParameterError(f"heard must be booleans (False = not heard), got dtype {heard_b.dtype}")
        try:
            heard_b = np.broadcast_to(heard_b, batch + (m,))
        except ValueError:
            raise ParameterError(f"heard must broadcast to (..., {m}) = {batch + (m,)}, got shape "
                                 f"{heard_b.shape}") from None
    known = ~np.isnan(position).any(axis=-1)
    info = np.full(batch + (2, 2), np.nan)
    if known.any():     # the information of the epochs with a true position only (NaN is no position)
        info[known] = rss_position_information(position[known], model, heard=heard_b[known])
    bound, reason = check_position_information(info, heard_b.sum(axis=-1), min_anchors=min_anchors,
                                               max_condition=max_condition)
    reason[~known] = NO_TRUTH_REASON
    return bound, reason


# ------------------------------------------------------------------------------------------------ range bounds

def _range_model(model, who: str):
    from ..models.range import RangeModel
    if not isinstance(model, RangeModel):
        raise ValueError(f"{who} takes model = RangeModel(anchors_m, sigma_m, tag_height_m=...), got "
                         f"{type(model).__name__}")
    if model.per_step_sigma:
        raise ValueError(f"{who}: give one sigma per position (sigma_m (m,) or (P, m), per_step_sigma=False)")
    return model


def range_position_information(position_m, model, *, heard=None):
    """The range Fisher information of the position ``J = sum_j u_j u_j^T / sigma_j^2`` ``(..., dim, dim)`` at
    ``position_m`` ``(..., dim)``, ``u_j = (p - a_j)_plan / d_j`` the unit vector from anchor ``j`` (its plan part
    for anchors with heights above a tag at ``tag_height_m``), for the range model ``model``
    (:class:`locbook.models.range.RangeModel`: ``z_j = d_j + v_j``, ``v_j ~ N(0, sigma_j^2)``; the Gaussian location
    information ``dh^T dh / sigma^2``). ``model.sigma_m``: a scalar, ``(m,)`` or per position ``(..., m)`` broadcasting
    against the positions (e.g. each epoch's reported std). ``heard``: booleans broadcastable to ``(..., m)``, False
    where an anchor gave no range (its term is left out)."""
    model = _range_model(model, "range_position_information")
    dim = model.dim
    position_m = as_array("position_m", position_m, min_ndim=1, trailing=(dim,))
    unit = model.unit_vectors(position_m)[1]
    gain = 1.0 / np.square(np.broadcast_to(model.sigma_m, unit.shape[:-1]))
    return _location_information(gain, unit, heard)


def range_crlb_m(position_m, model, *, heard=None):
    """Position RMSE bound ``sqrt(tr J^{-1})`` (m) from ranges at each position ``(..., dim)`` -> ``(...)``
    (:func:`range_position_information`); for plan positions the closed form ``sqrt((J_xx + J_yy) / det J)``
    (Ozkaya 2011, Eq. (A.5), for the range information). Where the ranges heard cannot fix a position (fewer than
    two, or aligned with it) the bound is ``inf``. :func:`range_crlb_checked_m` gives NaN with a reason instead."""
    info = range_position_information(position_m, model, heard=heard)
    if info.shape[-1] != 2:
        return np.sqrt(np.trace(np.linalg.inv(info), axis1=-2, axis2=-1))
    det = info[..., 0, 0] * info[..., 1, 1] - info[..., 0, 1] ** 2
    trace = info[..., 0, 0] + info[..., 1, 1]
    ok = det > 1e-12 * trace**2
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(ok, np.sqrt(trace / np.where(ok, det, 1.0)), np.inf)


def range_crlb_checked_m(position_m, model, *, heard=None, min_anchors: int = MIN_ANCHORS_FOR_BOUND,
                         max_condition: float = MAX_BOUND_CONDITION):
    """``(bound_m (...), reason (...))``: :func:`range_crlb_m` at plan positions ``(..., 2)`` checked epoch by
    epoch as the RSS bound is (:func:`check_position_information`): NaN with a reason where fewer than
    ``min_anchors`` ranges were heard (two ranges meet in two points, as two RSS ranges do), where the information is
    near-singular, or where the true position is unknown (NaN)."""
    model = _range_model(model, "range_crlb_checked_m")
    if model.dim != 2:
        raise ParameterError(f"range_crlb_checked_m gives the bound of a plan position: anchors (m, 2), or (m, 3) "
                             f"with tag_height_m; the model's give {model.dim}-D")
    m = model.n_anchors
    position = as_array("position_m", position_m, min_ndim=1, trailing=(2,), nan_ok=True)
    batch = position.shape[:-1]
    heard_b = np.ones(batch + (m,), bool) if heard is None else np.broadcast_to(np.asarray(heard, bool), batch + (m,))
    known = ~np.isnan(position).any(axis=-1)
    info = np.full(batch + (2, 2), np.nan)
    if known.any():
        sigma = np.broadcast_to(model.sigma_m, batch + (m,)) if np.ndim(model.sigma_m) >= 2 else model.sigma_m
        sub = model if np.ndim(model.sigma_m) < 2 else model.with_noise(np.square(sigma[known]))
        info[known] = range_position_information(position[known], sub, heard=heard_b[known])
    bound, reason = check_position_information(info, heard_b.sum(axis=-1), min_anchors=min_anchors,
                                               max_condition=max_condition)
    reason[~known] = NO_TRUTH_REASON
    return bound, reason
