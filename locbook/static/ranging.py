"""Range-only lateration: the position from measured ranges (RTT / ToA) by weighted nonlinear least squares.

:func:`range_nls_position` minimises, per problem (an epoch's ranges ``r_j`` to the anchors it ranged),

    sum_j ((|[p, h] - a_j| - r_j) / sigma_j)^2,

the maximum-likelihood position of the range model :class:`locbook.models.range.RangeModel` (independent Gaussian
range errors of std ``sigma_j``), by :func:`scipy.optimize.least_squares` (trust-region reflective, analytic Jacobian)
started from the linearized least-squares fix of the same ranges (:func:`locbook.static.lateration.lateration_ls`,
the closed form; a problem it cannot solve starts at the centroid of its anchors) and bounded to the outline's
bounding box. A non-rectangular outline is then honoured by moving a solution that lies outside it to the nearest
point of its boundary (the nearest floor point: the projection, not the constrained minimiser, which for a convex
outline and a locally quadratic cost lies on the same edge; stated so, never hidden). Without an outline the
problem is unbounded.

Missing ranges (NaN, not measured) are left out; a problem with fewer than ``dim + 1`` ranges (3 for a plan
position) gets a NaN position and ``status="too_few_anchors"`` (two ranges meet in two points), counted by the
result's status. One scipy solve per problem (scipy's least squares is not batched; a problem is 2 unknowns and up
to ``m`` residuals, about a millisecond).
"""
from __future__ import annotations

from typing import Any

import numpy as np
from scipy.optimize import least_squares

from .._validate import as_array, check_scalar
from ..geometry import inside_outline, nearest_on_outline, outline_box
from .checks import check_anchor_geometry, plan_anchors
from .lateration import lateration_ls
from .result import LocalizationResult

__all__ = ["range_nls_position", "RANGE_NLS_TOLERANCE"]

#: scipy's ``xtol``, ``ftol`` and ``gtol`` of the solve: far below any ranging error, so that noiseless ranges give
#: the true position to about 1e-9 m
RANGE_NLS_TOLERANCE = 1e-12


def range_nls_position(range_m, anchors_m, *, outline_m=None, tag_height_m: float | None = None, range_std_m=None,
                       x0=None) -> LocalizationResult:
    """Weighted nonlinear least-squares positions ``(..., 2)`` from measured ranges ``(..., m)``.

    Per problem the minimiser of ``sum_j ((|[p, h] - a_j| - r_j) / sigma_j)^2`` by scipy's trust-region reflective
    least squares, started from the linearized LS fix and bounded to the outline's bounding box; a solution outside
    a non-rectangular outline is moved to the nearest point of its boundary (module docstring).

    Parameters
    ----------
    range_m : array_like, shape (..., m)
        Ranges (m), non-negative; NaN is a range not measured (left out). A problem with fewer than three ranges
        gets a NaN position and ``status="too_few_anchors"``.
    anchors_m : array_like, shape (m, 2) or (m, 3)
        Anchor positions; ``(m, 3)`` with ``tag_height_m`` (3-D distances, plan positions; a 2-D data set's
        anchors have no height and its distances are in the plane).
    outline_m : array_like, shape (V, 2), optional
        The floor: the bounds and the nearest-point rule (without it the problem is unbounded).
    tag_height_m : float, optional
        The tag's known height.
    range_std_m : array_like, optional
        Each range's standard deviation (m), broadcasting to ``range_m`` (None: equal weights); finite and positive
        where a range is given.
    x0 : array_like, shape (..., 2), optional
        The start (default: the linearized LS fix, :func:`locbook.static.lateration.lateration_ls`).

    Returns
    -------
    LocalizationResult
        ``position_m`` ``(..., 2)``, with the cost ``sum_j w_j^2`` (the weighted squared residuals) at the
        solution and a status per problem.

    Raises
    ------
    DegenerateGeometryError
        Anchors that are too few, coincident or collinear.
    ValueError
        Negative ranges, anchors without heights given ``tag_height_m``, shapes that do not match.

    References
    ----------
    The maximum-likelihood position of the range model :class:`locbook.models.range.RangeModel` (independent
    Gaussian range errors of std ``sigma_j``).

    Examples
    --------
    Noise-free ranges give the true position back:

    >>> import numpy as np
    >>> import locbook as lb
    >>> anchors = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    >>> ranges = lb.pairwise_distance_m(np.array([3.0, 4.0]), anchors)
    >>> fix = lb.range_nls_position(ranges, anchors)
    >>> print(np.round(fix.position_m, 2), fix.status)
    [3. 4.] ok
    """
    anchors = as_array("anchors_m", anchors_m, ndim=2)
    if tag_height_m is not None:
        check_scalar("tag_height_m", tag_height_m)
        if anchors.shape[1] != 3:
            raise ValueError(f"anchors_m must be (m, 3) (x, y, height) with tag_height_m, got {anchors.shape}")
    plan, vertical = plan_anchors(anchors, tag_height_m)
    check_anchor_geometry(plan)
    m, dim = plan.shape
    ranges = as_array("range_m", range_m, min_ndim=1, nan_ok=True, trailing=(m,))
    if np.any(ranges < 0):
        raise ValueError(f"range_m must be non-negative (NaN = not measured), got {float(ranges[ranges < 0][0])!r}")
    batch = ranges.shape[:-1]
    flat = ranges.reshape(-1, m)
    if range_std_m is None:
        std = np.ones_like(flat)
    else:
        try:
            std = np.broadcast_to(as_array("range_std_m", range_std_m, nan_ok=True), ranges.shape).reshape(-1, m)
        except ValueError:
            raise ValueError(f"range_std_m must broadcast to range_m {ranges.shape}, got {np.shape(range_std_m)}") \
                from None
        given = np.isfinite(flat)
        if not np.all(std[given] > 0):
            raise ValueError("range_std_m must be finite and positive wherever a range is given")
    lower = upper = None
    if outline_m is not None:
        outline = as_array("outline_m", outline_m, ndim=2, trailing=(None, 2))
        lower, upper = outline_box(outline)
        if dim != 2:
            raise ValueError(f"outline_m bounds plan positions; the anchors give {dim}-D positions")
    heard = np.isfinite(flat)
    n_heard = heard.sum(axis=-1)
    enough = n_heard >= dim + 1
    position = np.full((flat.shape[0], dim), np.nan)
    cost = np.full(flat.shape[0], np.nan)
    status = np.where(enough, "ok", "too_few_anchors").astype("<U19")
    if x0 is None:
        start = np.full_like(position, np.nan)
        if enough.any():
            start[enough] = lateration_ls(anchors, flat[enough], tag_height_m=tag_height_m).position_m
    else:
        start = np.broadcast_to(as_array("x0", x0, nan_ok=True, trailing=(dim,)), batch + (dim,)).reshape(-1, dim)
    v2 = 0.0 if vertical is None else np.square(vertical)
    for i in np.flatnonzero(enough):        # one scipy solve per problem (module docstring)
        a, r, s = plan[heard[i]], flat[i, heard[i]], std[i, heard[i]]
        vz2 = v2 if np.ndim(v2) == 0 else np.asarray(v2)[heard[i]]
        p0 = start[i] if np.isfinite(start[i]).all() else a.mean(axis=0)
        if lower is not None:               # trf starts strictly inside its bounds
            span = upper - lower
            p0 = np.clip(p0, lower + 1e-9 * span, upper - 1e-9 * span)

        def residual(p, a=a, r=r, s=s, vz2=vz2):
            return (np.sqrt(np.sum((p - a) ** 2, axis=-1) + vz2) - r) / s

        def jacobian(p, a=a, s=s, vz2=vz2):
            d = np.sqrt(np.sum((p - a) ** 2, axis=-1) + vz2)
            return (p - a) / np.where(d > 0, d, 1.0)[:, None] / s[:, None]

        # Any: scipy-stubs' bounds type has no member for the (array, array) pair the outline gives
        bounds: Any = (-np.inf, np.inf) if lower is None else (lower, upper)
        try:
            sol = least_squares(residual, p0, jac=jacobian, method="trf", xtol=RANGE_NLS_TOLERANCE,
                                ftol=RANGE_NLS_TOLERANCE, gtol=RANGE_NLS_TOLERANCE, bounds=bounds)
        except (ValueError, np.linalg.LinAlgError):
            status[i] = "solver_failed"
            continue
        if not (sol.success and np.isfinite(sol.x).all()):
            status[i] = "solver_failed"
            continue
        position[i], cost[i] = sol.x, 2.0 * sol.cost
    if outline_m is not None:
        fixed = np.isfinite(position).all(axis=-1)
        outside = fixed & ~inside_outline(position, outline)
        if outside.any():                   # a non-rectangular outline: the nearest point of the floor
            position[outside] = nearest_on_outline(position[outside], outline)
    ok = status == "ok"
    return LocalizationResult(position.reshape(batch + (dim,)), ok.reshape(batch), cost.reshape(batch), 0,
                              "range_nls", status.reshape(batch))
