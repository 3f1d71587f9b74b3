"""Maximum likelihood in the RSS domain, :func:`rss_ml_position` (Gaussian shadowing): Eq. (2.4) of Dogan (2015),
solved by batched Levenberg-Marquardt from a convex (linear LS) initialiser.

Shapes, statuses and failures: :mod:`locbook.static.result`; missing readings: :mod:`locbook.static.missing`; anchor
heights: :mod:`locbook.static.checks`.
"""
from __future__ import annotations

import numpy as np

from .._validate import as_array, check_scalar
from ..errors import ConvergenceError
from ..models.channel import PathLossModel
from ..models.rss import RssModel, rss_mean_jacobian
from .checks import check_anchor_geometry, check_channel, goodness_of_fit, implausible_powers, plan_anchors
from .lateration import lateration_ls
from .missing import by_heard_anchors, channel_subset, check_min_anchors, checked_readings, solve_where
from .result import LocalizationResult
from .rss_form import accepts_old_form, old_estimator_call, rss_model_parts

__all__ = ["rss_ml_position"]


def _rss_ml_position_v1(anchors_m, rss_dbm, model, initial_m=None, *, max_iter=None, tol_m=None, min_distance_m=None,
                        raise_on_failure=None, min_anchors=None, tag_height_m=None, region_m=None):
    """The earlier signature of :func:`rss_ml_position`, the anchors first (deprecated calls are bound to it)."""


def _raise_if_failed(res: LocalizationResult, raise_on_failure: bool) -> LocalizationResult:
    if raise_on_failure and not np.all(res.converged):
        failed = sorted(set(np.asarray(res.status).ravel().tolist()) - {'ok'})
        raise ConvergenceError(f"RSS maximum likelihood: {int(np.sum(~res.converged))} of {res.converged.size} "
                               f"problems did not converge (statuses: {failed})")
    return res


def _lift(positions_m, vertical_m):
    """Offsets ``p - a`` ``(..., m, 3)`` of plan positions ``(..., 2)`` from anchors at heights ``-vertical``
    (the z component is the constant ``-(a_z - h)``)."""
    return None if vertical_m is None else np.broadcast_to(-vertical_m, positions_m.shape[:-1] + vertical_m.shape)


def _default_start(anchors_m, rss_dbm, model: PathLossModel, tag_height_m=None) -> np.ndarray:
    """The convex start of :func:`rss_ml_position`: the linearized LS fix on the model's ranges. A problem
    whose ranges overflow (infinite) has no such fix: NaN."""
    with np.errstate(over="ignore"):
        ranges = model.range_m(rss_dbm)
    if np.all(np.isfinite(ranges)):
        return lateration_ls(anchors_m, ranges, tag_height_m=tag_height_m).position_m
    with np.errstate(over="ignore", invalid="ignore"):
        return lateration_ls(anchors_m, np.where(np.isinf(ranges).any(axis=-1, keepdims=True), np.nan, ranges),
                             tag_height_m=tag_height_m).position_m


def _rss_residual_jacobian(pos, anchors, power, model: PathLossModel, clamp_m, vertical_m=None):
    """Residuals, their Jacobian w.r.t. the position and the squared distances (not clamped) of the one RSS model
    (:func:`locbook.models.rss.rss_mean_jacobian`) with the near-field clamp ``clamp_m``; with ``vertical_m`` (anchor
    heights above the tag's plane) the distances are 3-D and the Jacobian keeps the plan columns."""
    diff = pos[..., None, :] - anchors  # (..., m, dim)
    if vertical_m is not None:
        diff = np.concatenate([diff, _lift(pos, vertical_m)[..., None]], axis=-1)
    # the model without its input checks: a distance that overflowed to inf is a valid state here
    mean, grad, d2 = rss_mean_jacobian(diff, np.asarray(model.ref_power_dbm), np.asarray(model.path_loss_exp),
                                       ref_distance_m=model.ref_distance_m, min_distance_m=clamp_m)
    return power - mean, -grad[..., :anchors.shape[-1]], d2    # d resid / d p = - d mean / d p


def _min_eigenvalue(a):
    """Smallest eigenvalue of symmetric ``(..., k, k)`` matrices (closed form for 2 x 2, which is
    an order of magnitude faster than batched LAPACK on tiny matrices)."""
    if a.shape[-1] == 2:
        half_tr = 0.5 * (a[..., 0, 0] + a[..., 1, 1])
        half_diff = 0.5 * (a[..., 0, 0] - a[..., 1, 1])
        return half_tr - np.sqrt(half_diff**2 + a[..., 0, 1] ** 2)
    return np.linalg.eigvalsh(a)[..., 0]


def _solve_small(a, b):
    """Solve ``a x = b`` for ``(..., k, k)`` and ``(..., k)`` (Cramer's rule for 2 x 2)."""
    if a.shape[-1] == 2:
        det = a[..., 0, 0] * a[..., 1, 1] - a[..., 0, 1] * a[..., 1, 0]
        x0 = (a[..., 1, 1] * b[..., 0] - a[..., 0, 1] * b[..., 1]) / det
        x1 = (a[..., 0, 0] * b[..., 1] - a[..., 1, 0] * b[..., 0]) / det
        return np.stack([x0, x1], axis=-1)
    return np.linalg.solve(a, b[..., None])[..., 0]


def _newton_matrix(resid, jac, d2, pos, anchors, model, clamp_m, held=None):
    """Hessian of 0.5 |r|^2: J^T J + sum_j r_j grad^2 r_j, with
    grad^2 r_j = c (I / d_j^2 - 2 (p - a_j)(p - a_j)^T / d_j^4), c = 10 n / ln 10 (the derivative of the one model's
    Jacobian, :func:`locbook.models.rss.rss_mean_jacobian`; 0 within the clamp ``clamp_m``, where the mean is flat).
    Falls back to the Gauss-Newton matrix J^T J where the full Hessian is not positive definite. The second-order
    term matters: shadowing leaves large residuals, where Gauss-Newton converges only linearly. ``held (..., dim)``:
    coordinates held on a bound (projected Newton): their rows and columns are replaced by the identity before the
    test, so the choice is made on the free block, the matrix the step actually uses."""
    jtj = np.einsum("...ki,...kj->...ij", jac, jac)
    diff = pos[..., None, :] - anchors
    c = np.broadcast_to(10.0 * np.asarray(model.path_loss_exp) / np.log(10.0), d2.shape)
    eye = np.eye(pos.shape[-1])
    inside = d2 < clamp_m**2
    d2 = np.maximum(d2, clamp_m**2)            # no value changes outside the clamp; inside the term is 0 below
    hr = c[..., None, None] * (eye / d2[..., None, None]
                                - 2.0 * diff[..., :, None] * diff[..., None, :] / (d2**2)[..., None, None])
    hr = np.where(inside[..., None, None], 0.0, hr)
    full = jtj + np.einsum("...k,...kij->...ij", resid, hr)
    if held is not None and held.any():
        keep = ~(held[..., :, None] | held[..., None, :])
        ident = held[..., :, None] * eye
        full = np.where(keep, full, 0.0) + ident
        jtj = np.where(keep, jtj, 0.0) + ident
    eig_min = _min_eigenvalue(full)
    return np.where((eig_min > 1e-9 * np.trace(jtj, axis1=-2, axis2=-1))[..., None, None], full, jtj)


@accepts_old_form(lambda args, kwargs: old_estimator_call(args, kwargs, "rss_ml_position", _rss_ml_position_v1))
def rss_ml_position(rss_dbm, model: RssModel, initial_m=None, *,
                    max_iter: int = 10_000, tol_m: float = 1e-7, min_distance_m: float = 1e-3,
                    raise_on_failure: bool = False, min_anchors: int | None = None,
                    region_m=None) -> LocalizationResult:
    """Maximum-likelihood position from received powers under Gaussian shadowing, batched over problems.

    Minimises ``sum_j (P_j - P_0 + 10 n log10 |p - a_j|)^2`` for the RSS model ``model``: a non-convex problem,
    every problem started from ``initial_m`` or, by default, the linearized LS fix on the model's ranges (the convex
    initialiser), and refined by damped Newton steps (Levenberg-Marquardt with the exact Hessian where it is
    positive definite), vectorized over the batch; each iteration works only on the problems that have not
    converged yet, so the converged ones cost nothing more.

    Parameters
    ----------
    rss_dbm : array_like, shape (..., m)
        Received powers (dBm); NaN is an anchor not heard (:mod:`locbook.static.missing`): the problem is solved on
        the anchors it heard.
    model : RssModel
        The one RSS measurement model: anchors ``(m, dim)`` shared by every problem, the channel (scalars or
        per-anchor ``(m,)`` parameters) and ``model.tag_height_m`` (anchors ``(m, 3)`` with heights and plan
        positions, :mod:`locbook.static.checks`). A model with per-run anchors, per-run or per-step parameters, or
        walls that attenuate (``walls_m`` with a non-zero ``wall_attenuation_db``) is refused by name.
    initial_m : array_like, shape (dim,) or (..., dim), optional
        The start, broadcasting to the batch; a row that is all NaN means "no start given" and gets the default
        start (so a grid fix that was NaN for too few heard anchors can be passed on as it is).
    max_iter : int, default 10000
        Iteration cap. High on purpose: far from the anchors the cost is flat and a problem can need a thousand
        steps or more (George's corridor at 6 dB: up to about 1,500), and a walk stopped midway ends wherever its
        last step left it, which depends on the last bits of every step (numpy's vector ``log10`` differs between
        AVX-512 and AVX2): with a cap of 100, such problems moved an RMSE by per cent across machines.
    tol_m : float, default 1e-7
        Relative step size (m) below which an accepted step ends the iterations.
    min_distance_m : float, default 1e-3
        The estimator's near-field clamp (m), at least the channel's ``min_distance_m``.
    raise_on_failure : bool, default False
        Raise :class:`ConvergenceError` if any problem of the batch did not converge, whatever the reason.
    min_anchors : int, optional
        Heard anchors a problem needs (default ``dim + 1``).
    region_m : (lower, upper), optional
        The maximum likelihood over that box (a room's bounding box, e.g. :func:`locbook.geometry.outline_box`)
        instead of the whole plane: the start is clipped into it and every step is projected onto it (projected
        Levenberg-Marquardt), so no fix leaves the box; a fix on its boundary is the constrained optimum, where the
        unconstrained one lies outside. Without it a fix can land far outside the room when the readings point
        there (deep fades, a biased channel). The boxed cost is not convex either.

    Returns
    -------
    LocalizationResult
        ``position_m`` ``(..., dim)``, ``cost`` (the minimised sum of squares, dB^2), ``n_iter``, ``status``.
        ``converged`` (status ``"ok"``) means a local minimum of the cost was reached, not necessarily the global
        one: from the default convex start a problem can stop in another basin (Dogan's initialiser study,
        ``dogan2015-models``: about 3 % of draws). For the global minimum start from a grid
        (``initial_m=grid_ml_position(rss_dbm, model, cells_m).position_m``), as the Dogan scenarios do. A
        problem without a finite start (its ranges overflow, e.g. for a tiny exponent) gets NaN and
        ``status="solver_failed"`` alone; one that does not converge in ``max_iter`` steps ``"not_converged"``.

    Raises
    ------
    ConvergenceError
        With ``raise_on_failure=True``, if a problem did not converge.
    DegenerateGeometryError
        Anchors that are too few, coincident or collinear.
    ValueError
        A model the estimator cannot honour (named), infinite readings, shapes that do not match.

    Notes
    -----
    Garbage never gives a confident answer: a problem with an implausible power (more than
    :data:`~locbook.static.checks.IMPLAUSIBLE_SIGMAS` sigma above the model's mean at
    ``max(min_distance_m, channel.min_distance_m)``, e.g. +500 dBm; the assumption: a reading implying a tag
    closer than 1 mm, the default clamp, to an anchor's antenna is not a reading of this channel) gets NaN and
    ``status="implausible_reading"`` before any iteration, and a problem whose cost is infinite or NaN (at the
    start or at the end) gets NaN and ``status="solver_failed"``, never ``converged``. Readings that are each
    possible but impossible together get ``status="poor_fit"`` (position and ``converged`` kept): a converged
    problem whose cost over ``sigma^2`` exceeds ``chi2.ppf(1 - alpha, m_heard - dim)``,
    :data:`~locbook.static.checks.GOODNESS_OF_FIT_ALPHA` (model with ``sigma_db > 0`` only).

    The earlier form, ``rss_ml_position(anchors_m, rss_dbm, channel, initial_m, ..., tag_height_m=...)`` (a
    :class:`~locbook.PathLossModel` third), is deprecated: it warns and builds the :class:`~locbook.RssModel`.

    References
    ----------
    Dogan (2015), Eq. (2.4): the MLE cost, which the cost above equals up to the factor ``(10 n)^{-2}`` (by
    Eq. (2.3), ``log10 d_hat_j - log10 d_j = -(P_j - P(d_j)) / (10 n)``).

    Examples
    --------
    Noise-free powers give the true position back:

    >>> import numpy as np
    >>> import locbook as lb
    >>> anchors = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    >>> channel = lb.PathLossModel(-40.0, 2.5)
    >>> power = channel.mean_rss_dbm(lb.pairwise_distance_m(np.array([3.0, 4.0]), anchors))
    >>> fix = lb.rss_ml_position(power, lb.RssModel(anchors, channel))
    >>> print(np.round(fix.position_m, 2), fix.status)
    [3. 4.] ok
    """
    anchors_m, channel, tag_height_m = rss_model_parts(model, "rss_ml_position")
    return _rss_ml(anchors_m, rss_dbm, channel, initial_m, max_iter=max_iter, tol_m=tol_m,
                   min_distance_m=min_distance_m, raise_on_failure=raise_on_failure, min_anchors=min_anchors,
                   tag_height_m=tag_height_m, region_m=region_m)


def _rss_ml(anchors_m, rss_dbm, model: PathLossModel, initial_m=None, *,
            max_iter: int = 10_000, tol_m: float = 1e-7, min_distance_m: float = 1e-3,
            raise_on_failure: bool = False, min_anchors: int | None = None,
            tag_height_m: float | None = None, region_m=None) -> LocalizationResult:
    """:func:`rss_ml_position` on the model's anchors ``(m, k)``, channel ``model`` and tag height; the problems or
    anchors it sets apart (implausible readings, anchors not heard, no finite start) are solved by calls to itself."""
    plan, vertical = plan_anchors(anchors_m, tag_height_m)
    anchors_full = np.asarray(anchors_m, dtype=float)        # with heights: what recursive calls are given
    anchors_m = check_anchor_geometry(plan)
    m, dim = anchors_m.shape
    lower, upper = _region(region_m, dim)
    rss_dbm = checked_readings("rss_dbm", rss_dbm, m)
    check_channel(model, m)
    check_scalar("max_iter", max_iter, ge=1, integer=True)
    check_scalar("tol_m", tol_m, gt=0)
    check_scalar("min_distance_m", min_distance_m, gt=0)
    min_anchors = check_min_anchors(min_anchors, dim, m)
    if initial_m is not None:
        initial_m = as_array("initial_m", initial_m, min_ndim=1, nan_ok=True)
        try:
            initial_m = np.broadcast_to(initial_m, rss_dbm.shape[:-1] + (dim,))
        except ValueError:
            raise ValueError(f"initial_m must broadcast to {rss_dbm.shape[:-1] + (dim,)}, got shape "
                             f"{initial_m.shape}") from None
        no_start = np.isnan(initial_m)
        partly = no_start.any(axis=-1) & ~no_start.all(axis=-1)
        if np.any(partly):
            raise ValueError("initial_m must be finite, or all NaN in a problem's row (no start: the default), got "
                             f"a partly NaN row {initial_m[partly][0].tolist()}")
    implausible = implausible_powers(rss_dbm, model, max(float(min_distance_m), model.min_distance_m)).reshape(-1)
    if implausible.any():             # those problems fail alone, before any arithmetic on their readings
        flat, batch = rss_dbm.reshape(-1, m), rss_dbm.shape[:-1]
        start = None if initial_m is None else initial_m.reshape(-1, dim)
        res = solve_where(~implausible, batch, dim,
                           lambda sel: _rss_ml(anchors_full, flat[sel], model,
                                               None if start is None else start[sel], max_iter=max_iter,
                                               tol_m=tol_m, min_distance_m=min_distance_m,
                                               min_anchors=min_anchors, tag_height_m=tag_height_m,
                                               region_m=region_m),
                           "rss_ml_lm", "implausible_reading")
        return _raise_if_failed(res, raise_on_failure)
    if np.isnan(rss_dbm).any():
        flat = rss_dbm.reshape(-1, m)
        start = None if initial_m is None else initial_m.reshape(-1, dim)
        res = by_heard_anchors(
            anchors_m, rss_dbm, min_anchors,
            lambda heard, sel: _rss_ml(
                anchors_full[heard], flat[np.ix_(sel, heard)], channel_subset(model, heard, m),
                None if start is None else start[sel], max_iter=max_iter, tol_m=tol_m,
                min_distance_m=min_distance_m, tag_height_m=tag_height_m, region_m=region_m),
            "rss_ml_lm")
        return _raise_if_failed(res, raise_on_failure)
    if initial_m is None:
        initial_m = _default_start(anchors_full, rss_dbm, model, tag_height_m)
    elif np.isnan(initial_m).any():     # rows without a start get the default one
        initial_m = np.array(initial_m)
        no_start = np.isnan(initial_m).all(axis=-1)
        initial_m[no_start] = _default_start(anchors_full, rss_dbm[no_start], model, tag_height_m)
    batch, dim = rss_dbm.shape[:-1], anchors_m.shape[1]
    pos = np.array(np.broadcast_to(initial_m, batch + (dim,)), dtype=float).reshape(-1, dim)
    startable = np.all(np.isfinite(pos), axis=-1)
    if not startable.all():           # no finite start: those problems fail alone
        flat = rss_dbm.reshape(-1, m)
        res = solve_where(startable, batch, dim,
                           lambda sel: _rss_ml(anchors_full, flat[sel], model, pos[sel], max_iter=max_iter,
                                               tol_m=tol_m, min_distance_m=min_distance_m,
                                               tag_height_m=tag_height_m, region_m=region_m),
                           "rss_ml_lm", "solver_failed")
        return _raise_if_failed(res, raise_on_failure)
    if lower is not None:
        pos = np.clip(pos, lower, upper)
    power = rss_dbm.reshape(-1, rss_dbm.shape[-1])
    clamp_m = max(float(min_distance_m), model.min_distance_m)     # the model's near-field clamp
    with np.errstate(over="ignore", invalid="ignore"):     # a start so far away that its distances overflow
        resid, jac, d2 = _rss_residual_jacobian(pos, anchors_m, power, model, clamp_m, vertical)
        cost = np.sum(resid**2, axis=-1)
    lam = np.full(cost.shape, 1e-3)
    converged = np.zeros(cost.shape, bool)
    eye = np.eye(dim)
    active = np.flatnonzero(np.isfinite(cost))   # problems still iterating; an infinite cost has nowhere to go
    it = 0
    for it in range(1, max_iter + 1):
        p_a, r_a, j_a, d2_a, c_a, l_a = (a[active] for a in (pos, resid, jac, d2, cost, lam))
        jtr = np.einsum("...ki,...k->...i", j_a, r_a)
        held = None
        if lower is not None:
            # projected Newton (Bertsekas 1982): a coordinate on a bound whose gradient points out of the box is
            # held (its row and column of the system replaced by the identity, its gradient by 0); the others
            # take the Newton step of the reduced problem, clipped into the box
            held = ((p_a <= lower) & (jtr > 0)) | ((p_a >= upper) & (jtr < 0))
            jtr = np.where(held, 0.0, jtr)
        hess = _newton_matrix(r_a, j_a, d2_a, p_a, anchors_m, model, clamp_m, held)
        # damped step: (H + lam diag(H)) delta = -J^T r
        damp = l_a[:, None, None] * (eye * np.diagonal(hess, axis1=-2, axis2=-1)[:, None, :] + 1e-12 * eye)
        step = -_solve_small(hess + damp, jtr)
        if lower is not None:                 # the step that stays inside the box
            step = np.clip(p_a + step, lower, upper) - p_a
        trial = p_a + step
        r_new, j_new, d2_new = _rss_residual_jacobian(trial, anchors_m, power[active], model, clamp_m, vertical)
        c_new = np.sum(r_new**2, axis=-1)
        better = c_new <= c_a
        step_small = np.linalg.norm(step, axis=-1) <= tol_m * (1.0 + np.linalg.norm(p_a, axis=-1))
        gain_small = (c_a - c_new) <= 1e-12 * (1.0 + c_a)
        acc = active[better]
        pos[acc], resid[acc], jac[acc], d2[acc], cost[acc] = (trial[better], r_new[better], j_new[better],
                                                              d2_new[better], c_new[better])
        l_a = np.clip(np.where(better, l_a * 0.3, l_a * 10.0), 1e-12, 1e16)
        lam[active] = l_a
        # converged: an accepted step that is tiny or gains nothing, or no descent even with a
        # vanishing step (a local minimum)
        done = (better & (step_small | gain_small)) | (l_a >= 1e16)
        converged[active[done]] = True
        active = active[~done]
        if active.size == 0:
            break
    status = np.where(converged, "ok", "not_converged").astype("<U19")
    broken = ~(np.isfinite(cost) & np.all(np.isfinite(pos), axis=-1))   # no minimum: never converged
    converged[broken], status[broken], pos[broken] = False, "solver_failed", np.nan
    status = goodness_of_fit(status, cost, model, m, dim)   # converged on readings no position explains
    if raise_on_failure and not np.all(converged):
        raise ConvergenceError(
            f"RSS maximum likelihood: {int(np.sum(~converged))} of {converged.size} problems did not "
            f"converge in {max_iter} Levenberg-Marquardt iterations (statuses: "
            f"{sorted(set(status.tolist()) - {'ok'})})"
        )
    return LocalizationResult(pos.reshape(batch + (dim,)), converged.reshape(batch), cost.reshape(batch),
                              it, "rss_ml_lm", status.reshape(batch))


def _region(region_m, dim: int):
    """``(lower, upper)`` arrays ``(dim,)`` of a ``region_m`` box, checked (``(None, None)`` without one)."""
    if region_m is None:
        return None, None
    try:
        lower, upper = region_m
    except (TypeError, ValueError):
        raise ValueError(f"region_m must be a pair (lower, upper) of corners, got {region_m!r}") from None
    lower = as_array("region_m lower corner", lower, ndim=1, trailing=(dim,))
    upper = as_array("region_m upper corner", upper, ndim=1, trailing=(dim,))
    if np.any(lower >= upper):
        raise ValueError(f"region_m must have lower < upper in every coordinate, got {lower.tolist()} and "
                         f"{upper.tolist()}")
    return lower, upper
