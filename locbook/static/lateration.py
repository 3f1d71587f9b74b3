"""Linearized lateration from ranges: the system, its least squares and weighted least squares.

- :func:`lateration_ls`: linearized least squares, Eq. (8) of George and Vadivukkarasi:
  subtracting the circle of a reference anchor r from circle i gives the linear system
  ``2 (a_r - a_i)^T p = d_i^2 - d_r^2 - |a_i|^2 + |a_r|^2``. With ``pairs`` (Palvai 2008, Eqs. (2.27)-(2.29)):
  the anchors may differ per problem (receivers ``(..., N, dim)`` at random positions) and the sphere equations
  are differenced in pairs ``(i, j)``, consecutive or against the first or the last anchor,
  ``2 (s_j - s_i)^T X = d_i^2 - d_j^2 - |s_i|^2 + |s_j|^2`` (corrected: the printed rows, Eqs. (2.18), (2.20) and
  (2.27), lack the factor 2 and Eq. (2.18)'s right-hand side the full norms; ``variant="literal_palvai2008"`` keeps the
  printed rows without the 2, flagged: it returns twice the coordinates). :func:`lateration_system` builds either
  system;
  :func:`locbook.static.least_squares.recursive_least_squares` is the recursive form of the same rows.
- :func:`lateration_wls`: the same system with weights.
- The same objective in a box: :func:`locbook.static.box_ls.lateration_box_ls`.

Shapes, statuses and failures: :mod:`locbook.static.result`; missing readings: :mod:`locbook.static.missing`; anchor
heights: :mod:`locbook.static.checks`.
"""
from __future__ import annotations

import numpy as np

from .._validate import as_array, check_choice
from ..errors import DegenerateGeometryError, ParameterError
from .checks import check_anchor_geometry, plan_anchors
from .missing import (
    by_heard_anchors,
    check_min_anchors,
    checked_readings,
    given_readings,
    has_missing,
    ref_in_subset,
    solve_where,
)
from .result import LocalizationResult, status_array

# lateration_by_heard serves the box LS too
__all__ = ["lateration_system", "lateration_ls", "lateration_wls", "LATERATION_PAIRS", "LATERATION_VARIANTS"]

#: values of ``pairs`` in :func:`lateration_system` and :func:`lateration_ls`: which sphere equations are differenced
#: (Palvai 2008): each anchor against the next, or every anchor against the first or the last one
LATERATION_PAIRS = ("consecutive", "first", "last")

#: values of ``variant``: the rows with the factor 2 of the differenced sphere equations, or Palvai's printed rows
#: without it (Palvai 2008, Eqs. (2.20), (2.27); they give twice the coordinates)
LATERATION_VARIANTS = ("corrected", "literal_palvai2008")


def lateration_by_heard(anchors_m, distance_m, ref_index: int, min_anchors: int, solve, method: str,
                         tag_height_m=None):
    """:func:`~locbook.static.missing.by_heard_anchors` for the linearized systems: ``solve(anchors, distances,
    ref_index)`` on each group's heard anchors, the reference kept if heard (geometry judged on the plan positions
    with a known tag height)."""
    anchors_m, distance_m = np.asarray(anchors_m, float), np.asarray(distance_m, float)
    m = anchors_m.shape[0]
    flat = distance_m.reshape(-1, m)
    return by_heard_anchors(
        plan_anchors(anchors_m, tag_height_m)[0], distance_m, min_anchors,
        lambda heard, sel: solve(anchors_m[heard], flat[np.ix_(sel, heard)], ref_in_subset(ref_index % m, heard)),
        method)


def lateration_system(anchors_m, distance_m, ref_index: int = 0, *, pairs: str | None = None,
                      variant: str = "corrected", tag_height_m: float | None = None):
    """Matrices of the linearized lateration system ``A p = b`` (Eq. (8) of George and Vadivukkarasi).

    Returns ``A`` of shape ``(m-1, dim)`` (``2 (a_r - a_i)``, rows for i != r) and ``b`` of shape
    ``(..., m-1)`` (``d_i^2 - d_r^2 - |a_i|^2 + |a_r|^2``). A NaN distance (not heard) gives NaN in the rows
    that use it: its own row, or every row of its problem if it is the reference's.
    With ``tag_height_m`` (anchors ``(m, 3)``) the system is the plan one, exact: ``d^2`` becomes
    ``d^2 - (a_z - h)^2`` and ``a`` the anchors' ``(x, y)`` (:mod:`locbook.static.checks`).

    With ``pairs`` (one of :data:`LATERATION_PAIRS`; Palvai 2008, Eqs. (2.27)-(2.28)) the anchors are
    ``(..., N, dim)`` per problem or ``(N, dim)`` shared, and the rows are ``2 (s_j - s_i)`` ``(..., N - 1, dim)``
    and ``d_i^2 - d_j^2 - |s_i|^2 + |s_j|^2`` ``(..., N - 1)`` over the pairs ``(i, j)`` (NaN where a reading is
    missing); no geometry check (the anchors differ per problem: :func:`lateration_ls` judges each system's rank).
    ``variant="literal_palvai2008"`` drops the factor 2 of ``A`` (:data:`LATERATION_VARIANTS`).
    """
    check_choice("variant", variant, LATERATION_VARIANTS)
    factor = 2.0 if variant == "corrected" else 1.0
    if pairs is not None:
        if tag_height_m is not None or ref_index != 0:
            raise ParameterError("pairs: differenced pairs take neither ref_index nor tag_height_m (the pairs name "
                                 "every reference; anchor heights are not supported there)")
        return _pair_rows(anchors_m, distance_m, pairs, factor)
    plan, vertical = plan_anchors(anchors_m, tag_height_m)
    anchors_m = check_anchor_geometry(plan)
    m = anchors_m.shape[0]
    distance_m = checked_readings("distance_m", distance_m, m)
    if np.any(distance_m < 0):
        raise ValueError(f"distance_m must be non-negative (NaN = not heard), got "
                         f"{float(distance_m[distance_m < 0][0])!r}")
    if (isinstance(ref_index, (bool, np.bool_)) or not isinstance(ref_index, (int, np.integer))
            or not -m <= ref_index < m):
        raise ValueError(f"ref_index must be an anchor index in [-{m}, {m - 1}], got {ref_index!r}")
    ref_index %= m
    others = np.array([i for i in range(m) if i != ref_index])
    a_r = anchors_m[ref_index]
    a_mat = factor * (a_r - anchors_m[others])
    norms = np.sum(anchors_m**2, axis=1)
    if vertical is not None:
        norms = norms + vertical**2           # |p - a_xy|^2 = d^2 - v^2: the known height joins the anchor terms
    b = (distance_m[..., others] ** 2 - distance_m[..., [ref_index]] ** 2
         - norms[others] + norms[ref_index])
    return a_mat, b


def _pair_indices(n: int, pairs: str):
    if pairs == "consecutive":
        return np.arange(n - 1), np.arange(1, n)
    if pairs == "first":
        return np.zeros(n - 1, int), np.arange(1, n)
    return np.arange(n - 1), np.full(n - 1, n - 1)


def _pair_rows(anchors_m, distance_m, pairs: str, factor: float):
    """The rows of :func:`lateration_system` with ``pairs``."""
    check_choice("pairs", pairs, LATERATION_PAIRS)
    s = as_array("anchors_m", anchors_m, min_ndim=2)
    d = as_array("distance_m", distance_m, min_ndim=1, nan_ok=True)
    n = s.shape[-2]
    if d.shape[-1] != n:
        raise ValueError(f"distance_m has {d.shape[-1]} readings on its last axis, anchors_m has {n} positions")
    if n < 2:
        raise ValueError(f"anchors_m must hold at least two anchor positions (axis -2), got shape {s.shape}")
    if np.any(d < 0):
        raise ValueError(f"distance_m must be non-negative (NaN = not heard); it holds {float(np.nanmin(d)):.6g} at "
                         f"index {tuple(int(i) for i in np.argwhere(d < 0)[0])}")
    i, j = _pair_indices(n, pairs)
    H = factor * (s[..., j, :] - s[..., i, :])
    norms = np.einsum("...k,...k->...", s, s)
    Y = d[..., i] ** 2 - d[..., j] ** 2 - norms[..., i] + norms[..., j]
    return H, Y


def _pair_least_squares(anchors_m, distance_m, pairs: str, variant: str) -> LocalizationResult:
    """:func:`lateration_ls` with ``pairs``: per problem the normal equations ``(H^T H) X = H^T Y`` (``dim x dim``,
    Palvai 2008 Eq. (2.29)) of the rows that are heard; a problem with fewer than ``dim`` rows, or a rank-deficient
    ``H^T H`` (smallest singular value below 1e-10 of the largest), gets NaN and its status."""
    H, Y = lateration_system(anchors_m, distance_m, pairs=pairs, variant=variant)
    H, Y = np.broadcast_arrays(H, Y[..., None])
    Y = Y[..., 0]
    ok_row = np.isfinite(Y)
    Hm = np.where(ok_row[..., None], H, 0.0)
    Ym = np.where(ok_row, Y, 0.0)
    A = np.einsum("...ki,...kj->...ij", Hm, Hm)
    b = np.einsum("...ki,...k->...i", Hm, Ym)
    dim = H.shape[-1]
    enough = ok_row.sum(axis=-1) >= dim
    sv = np.linalg.svd(A, compute_uv=False) if A.size else np.zeros(A.shape[:-1])
    full = enough & (sv[..., -1] > 1e-10 * np.maximum(sv[..., 0], 1e-300))
    safe = np.where(full[..., None, None], A, np.eye(dim))
    pos = np.linalg.solve(safe, b[..., None])[..., 0]
    pos = np.where(full[..., None], pos, np.nan)
    status = np.where(full, "ok", np.where(enough, "degenerate_geometry", "too_few_anchors")).astype("<U19")
    return LocalizationResult(pos, full, None, 0, f"lateration_ls(pairs={pairs}, {variant})", status)


def _shared_pair_least_squares(anchors_m, distance_m, pairs: str, variant: str) -> LocalizationResult:
    """:func:`_pair_least_squares` for anchors ``(n, dim)`` shared by every problem and ``pairs`` "first" or "last",
    the conventions of the reference-anchor path: the shared layout is judged once
    (:func:`~locbook.static.checks.check_anchor_geometry` raises :class:`DegenerateGeometryError`), and a problem that
    did not hear the pair reference (anchor 0, or n - 1) takes the first (last) anchor it heard instead, as
    :func:`~locbook.static.missing.ref_in_subset` does, rather than losing every row. Problems that heard the
    reference are solved exactly as before; the others are solved on their anchors with the new reference swapped
    into the reference's place (a per-problem layout; a heard subset too small or collinear gets its status)."""
    check_anchor_geometry(anchors_m)
    res = _pair_least_squares(anchors_m, distance_m, pairs, variant)
    d = as_array("distance_m", distance_m, min_ndim=1, nan_ok=True)
    n = anchors_m.shape[0]
    heard = ~np.isnan(d)
    ref = 0 if pairs == "first" else n - 1
    lost = ~heard[..., ref] & heard.any(axis=-1)
    if not lost.any():
        return res
    h = heard[lost]                                                     # (k, n)
    new_ref = np.argmax(h, axis=-1) if pairs == "first" else n - 1 - np.argmax(h[:, ::-1], axis=-1)
    order = np.broadcast_to(np.arange(n), h.shape).copy()
    rows = np.arange(h.shape[0])
    order[rows, ref], order[rows, new_ref] = new_ref, ref               # swap the heard reference into place
    sub = _pair_least_squares(anchors_m[order], np.take_along_axis(d[lost], order, axis=-1), pairs, variant)
    pos, converged, status = (np.array(v) for v in (res.position_m, res.converged, res.status))   # 0-d for one problem
    pos[lost], converged[lost], status[lost] = sub.position_m, sub.converged, sub.status
    return LocalizationResult(pos, converged, None, 0, res.method, status)


def lateration_ls(anchors_m, distance_m, ref_index: int = 0, *, pairs: str | None = None, variant: str = "corrected",
                  min_anchors: int | None = None, tag_height_m: float | None = None) -> LocalizationResult:
    """Linearized least-squares position from ranges, batched over problems.

    The one entry point for a linearized lateration fix: ``p = (A^T A)^{-1} A^T b`` of :func:`lateration_system`
    (weights: :func:`lateration_wls`; a box: :func:`locbook.static.box_ls.lateration_box_ls`; recursively:
    :func:`locbook.static.least_squares.recursive_least_squares` of the same rows). Unconstrained: estimates may
    leave the room, as the paper observes ("some of the results go beyond the boundaries"). The result depends
    slightly on ``ref_index`` (anchor 1 in the paper). Shared anchors: ``pinv(A)`` once for the batch.

    Parameters
    ----------
    anchors_m : array_like, shape (m, dim)
        Anchor positions shared by every problem; ``(m, 3)`` (x, y, height) with ``tag_height_m``. With ``pairs``
        also per problem, ``(..., N, dim)``.
    distance_m : array_like, shape (..., m)
        Ranges (m), non-negative; NaN is an anchor not heard (:mod:`locbook.static.missing`).
    ref_index : int, default 0
        The reference anchor whose circle is subtracted from the others (not with ``pairs``).
    pairs : {None, "consecutive", "first", "last"}, optional
        Difference the sphere equations in pairs (:data:`LATERATION_PAIRS`; Palvai 2008): the normal equations per
        problem, the rows with a missing reading left out (``min_anchors`` and ``tag_height_m`` do not apply).
    variant : {"corrected", "literal_palvai2008"}, default "corrected"
        :data:`LATERATION_VARIANTS`: the literal variant drops the factor 2 of the rows (twice the coordinates).
    min_anchors : int, optional
        Heard anchors a problem needs (default ``dim + 1``, at most ``m``).
    tag_height_m : float, optional
        The tag's known height: anchors with heights, plan positions (:mod:`locbook.static.checks`).

    Returns
    -------
    LocalizationResult
        ``position_m`` ``(..., dim)``; ``cost`` None; ``status`` per problem
        (:class:`~locbook.static.result.LocalizationResult`).

    Raises
    ------
    DegenerateGeometryError
        Shared anchors ``(m, dim)`` that are too few, coincident or collinear (``pairs="consecutive"`` excepted: its
        rows are judged per problem).
    ValueError
        Negative or infinite ranges, shapes that do not match, a ``ref_index`` out of range.

    Notes
    -----
    Degenerate geometry and missing readings follow one convention on both paths: a problem whose heard anchors
    are too few or collinear gets NaN and the status ``too_few_anchors`` or ``degenerate_geometry``, as does every
    problem of per-problem anchors. A reference that was not heard is replaced by a heard anchor: the first heard
    for ``ref_index`` and ``pairs="first"``, the last heard for ``pairs="last"``. Remaining difference: per-problem
    anchors are judged by the rank of ``H^T H`` (1e-10), shared ones by
    :func:`~locbook.static.checks.check_anchor_geometry` (1e-6 on the centred anchors).

    References
    ----------
    George and Vadivukkarasi, Eq. (8): ``2 (a_r - a_i)^T p = d_i^2 - d_r^2 - |a_i|^2 + |a_r|^2``, solved by least
    squares. Palvai (2008), Eqs. (2.27)-(2.29): the differenced pairs and their normal equations.

    Examples
    --------
    Noise-free ranges give the true position back:

    >>> import numpy as np
    >>> import locbook as lb
    >>> anchors = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    >>> ranges = lb.pairwise_distance_m(np.array([3.0, 4.0]), anchors)
    >>> fix = lb.lateration_ls(anchors, ranges)
    >>> print(np.round(fix.position_m, 2), fix.status)
    [3. 4.] ok

    Leading axes are problems; a NaN range is an anchor not heard:

    >>> batch = np.array([ranges, ranges])
    >>> batch[1, 2] = np.nan
    >>> print(np.round(lb.lateration_ls(anchors, batch).position_m, 2))
    [[3. 4.]
     [3. 4.]]
    """
    distance_m = given_readings("distance_m", distance_m)
    if pairs is not None:
        if min_anchors is not None or tag_height_m is not None:
            raise ParameterError("pairs: min_anchors and tag_height_m do not apply to differenced pairs")
        check_choice("pairs", pairs, LATERATION_PAIRS)
        shared = as_array("anchors_m", anchors_m, min_ndim=2)
        if shared.ndim == 2 and pairs in ("first", "last"):
            return _shared_pair_least_squares(shared, distance_m, pairs, variant)
        return _pair_least_squares(anchors_m, distance_m, pairs, variant)
    a_mat, b = lateration_system(anchors_m, distance_m, ref_index, variant=variant, tag_height_m=tag_height_m)
    min_anchors = check_min_anchors(min_anchors, a_mat.shape[1], a_mat.shape[0] + 1)
    if has_missing(distance_m):
        return lateration_by_heard(anchors_m, distance_m, ref_index, min_anchors,
                                    lambda a, d, ref: lateration_ls(a, d, ref, variant=variant,
                                                                    tag_height_m=tag_height_m),
                                    f"lateration_ls(ref={ref_index})", tag_height_m)
    with np.errstate(over="ignore", invalid="ignore"):
        pos = b @ np.linalg.pinv(a_mat).T
    ok = np.all(np.isfinite(pos), axis=-1)     # not finite: the squared ranges overflowed
    if not ok.all():                           # a failed problem has no position (not +-inf)
        pos = np.where(ok[..., None], pos, np.nan)
    return LocalizationResult(pos, ok, None, 0, f"lateration_ls(ref={ref_index})", status_array(ok))


def lateration_wls(anchors_m, distance_m, weights, ref_index: int = 0, *,
                   min_anchors: int | None = None, tag_height_m: float | None = None) -> LocalizationResult:
    """Weighted linearized least squares ``p = (A^T W A)^{-1} A^T W b`` with diagonal weights
    ``(..., m-1)`` (one per differenced equation, i.e. per non-reference anchor in anchor order), batched.

    ``weights`` has shape ``(m-1,)`` (shared) or ``(..., m-1)`` with batch axes that broadcast to those of
    ``distance_m`` (a scalar is not accepted); finite and non-negative. A zero weight removes its equation: a
    problem whose positively weighted anchors (with the reference) are too few or collinear gets NaN and
    ``status="degenerate_geometry"``. NaN distances are anchors not heard; a problem then keeps the weights of
    its heard anchors (if the reference was not heard, the first heard anchor's weight is unused).
    ``tag_height_m``: anchors with heights (:mod:`locbook.static.checks`)."""
    distance_m = given_readings("distance_m", distance_m)
    a_mat, b = lateration_system(anchors_m, distance_m, ref_index, tag_height_m=tag_height_m)
    min_anchors = check_min_anchors(min_anchors, a_mat.shape[1], a_mat.shape[0] + 1)
    weights = as_array("weights", weights)
    batch = b.shape[:-1]
    try:
        fits = weights.ndim >= 1 and weights.shape[-1] == b.shape[-1] and \
            np.broadcast_shapes(weights.shape[:-1], batch) == batch
    except ValueError:
        fits = False
    if not fits:
        raise ValueError(f"weights must have shape (..., {b.shape[-1]}) (one per non-reference anchor) with batch "
                         f"axes that broadcast to the distances' batch {batch}; got shape {weights.shape}")
    w = np.broadcast_to(weights, b.shape)
    if np.any(w < 0):
        raise ValueError(f"weights must be non-negative, got {float(w[w < 0][0])!r}")
    if has_missing(distance_m):
        anchors_m, distance_m = np.asarray(anchors_m, float), np.asarray(distance_m, float)
        m = anchors_m.shape[0]
        ref = ref_index % m
        flat = distance_m.reshape(-1, m)
        per_anchor = np.zeros((flat.shape[0], m))
        per_anchor[:, [i for i in range(m) if i != ref]] = w.reshape(-1, m - 1)

        def solve_subset(heard, sel):
            sub_ref = ref_in_subset(ref, heard)
            rows = np.delete(heard, sub_ref)
            return lateration_wls(anchors_m[heard], flat[np.ix_(sel, heard)], per_anchor[np.ix_(sel, rows)], sub_ref,
                                  tag_height_m=tag_height_m)

        return by_heard_anchors(plan_anchors(anchors_m, tag_height_m)[0], distance_m, min_anchors,
                                 solve_subset, "lateration_wls")
    if not np.all(w > 0):     # zero weights: the equations left may not fix a position
        degenerate = _zero_weights_degenerate(np.asarray(plan_anchors(anchors_m, tag_height_m)[0], float), ref_index, w)
        if degenerate.any():
            m = a_mat.shape[0] + 1
            flat_d, flat_w = np.asarray(distance_m, float).reshape(-1, m), w.reshape(-1, m - 1)
            return solve_where(~degenerate, batch, a_mat.shape[1],
                                lambda sel: lateration_wls(anchors_m, flat_d[sel], flat_w[sel], ref_index,
                                                           tag_height_m=tag_height_m),
                                "lateration_wls", "degenerate_geometry")
    ata = np.einsum("ki,...k,kj->...ij", a_mat, w, a_mat)
    atb = np.einsum("ki,...k,...k->...i", a_mat, w, b)
    pos = np.linalg.solve(ata, atb[..., None])[..., 0]
    ok = np.all(np.isfinite(pos), axis=-1)
    if not ok.all():                           # a failed problem has no position (not +-inf)
        pos = np.where(ok[..., None], pos, np.nan)
    return LocalizationResult(pos, ok, None, 0, "lateration_wls", status_array(ok))


def _zero_weights_degenerate(anchors_m, ref_index: int, w) -> np.ndarray:
    """Per problem (flattened): whether the reference and the anchors with a positive weight fail
    :func:`~locbook.static.checks.check_anchor_geometry` (too few, coincident or collinear)."""
    m = anchors_m.shape[0]
    ref = ref_index % m
    others = np.array([i for i in range(m) if i != ref])
    patterns, inverse = np.unique(w.reshape(-1, m - 1) > 0, axis=0, return_inverse=True)
    bad = np.zeros(len(patterns), bool)
    for g, pattern in enumerate(patterns):
        try:
            check_anchor_geometry(anchors_m[np.r_[ref, others[pattern]]])
        except DegenerateGeometryError:
            bad[g] = True
    return bad[inverse.reshape(-1)]

