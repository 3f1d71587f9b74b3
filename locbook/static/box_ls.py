"""Box-constrained linearized lateration, :func:`lateration_box_ls`: the objective of
:func:`locbook.static.lateration.lateration_ls` with a box constraint, solved exactly by enumerating the KKT active
sets, vectorized over problems (compiled from 256 problems on: :mod:`locbook.static._box_kernels`), cvxpy kept as the
reference (``solver="cvxpy"``).
"""
from __future__ import annotations

from functools import lru_cache
from itertools import product

import numpy as np

from .._cvx import cp, solve
from .._validate import as_array, check_choice
from ..errors import ConvergenceError
from ..tracking import _compiled
from .lateration import lateration_by_heard, lateration_system
from .missing import check_min_anchors, given_readings, has_missing, solve_where
from .result import LocalizationResult, status_array

__all__ = ["lateration_box_ls", "BOX_LS_SOLVERS"]

#: values of ``solver`` in :func:`lateration_box_ls`
BOX_LS_SOLVERS = ("exact", "cvxpy")


@lru_cache(maxsize=16)
def _box_problem(n_problems, a_key, lower, upper):
    a_mat = np.array(a_key)
    b = cp.Parameter((n_problems, a_mat.shape[0]), name="b")
    p = cp.Variable((n_problems, a_mat.shape[1]), name="position_m")
    constraints = [p >= np.array(lower), p <= np.array(upper)]
    problem = cp.Problem(cp.Minimize(cp.sum_squares(p @ a_mat.T - b)), constraints)
    return problem, b, p


def _solve_box_batch(a_mat, b, lower, upper):
    """Box-constrained LS of every row of ``b`` ``(k, rows)`` in one stacked QP. If that solve fails, the
    batch is halved and each half solved again, so a problem the solver cannot handle is marked alone
    (NaN, not converged) and never costs its batch. Returns positions ``(k, dim)`` and success flags."""
    k, dim = b.shape[0], a_mat.shape[1]
    if k == 0:
        return np.empty((0, dim)), np.ones(0, bool)
    problem, b_par, p_var = _box_problem(k, tuple(map(tuple, a_mat.tolist())), lower, upper)
    b_par.value = b
    try:
        solve(problem, "box-constrained lateration")
        return p_var.value, np.ones(k, bool)
    except (ConvergenceError, cp.error.SolverError):
        if k == 1:
            return np.full((1, dim), np.nan), np.zeros(1, bool)
    half = k // 2
    (p1, ok1), (p2, ok2) = (_solve_box_batch(a_mat, part, lower, upper) for part in (b[:half], b[half:]))
    return np.concatenate([p1, p2]), np.concatenate([ok1, ok2])


@lru_cache(maxsize=64)
def _box_active_sets(a_key, lower, upper):
    """What the active sets of the box LS ``min |A p - b|^2, lower <= p <= upper`` need, from ``A`` and the box
    alone (computed once per anchors and box, for any number of problems).

    With ``p*`` an unconstrained minimiser and ``d = p - p*``, the objective is ``|A p* - b|^2 + d^T G d``
    (``G = A^T A``; exact, since ``A^T (A p* - b) = 0``) and the half-gradient ``A^T (A p - b)`` is ``G d``. An
    active set holds the coordinates ``F`` at bounds ``v_F`` and leaves ``R`` free; its candidate minimises the
    objective over ``p_R``: ``p_R = p*_R - K (v_F - p*_F)`` with ``K = G_RR^+ G_RF`` (``G_RR^{-1}`` for a
    full-rank ``A``; for a rank-deficient one a minimiser), ``p_F = v_F``. So the candidate is affine in ``p*``,
    ``p = M p* + c``, and so is every quantity its KKT test needs to be non-negative: ``p_j - lower_j`` and
    ``upper_j - p_j`` on the free coordinates (primal feasibility), ``+g_j`` at a lower and ``-g_j`` at an upper
    bound (the dual sign; ``g = G (p - p*)``, divided by ``max |G|`` so that one relative tolerance serves).

    Returns ``(pinv(A)^T, levels)``; ``levels[j-1]`` holds the active sets with ``j`` coordinates at a bound:
    ``(weights, offsets, sets)`` such that ``weights @ p* + offsets``, reshaped ``(sets, 3 dim - j, ...)``, gives
    per set the ``2 dim - j`` KKT quantities followed by the ``dim`` coordinates of the candidate.
    """
    a_mat = np.array(a_key)
    dim = a_mat.shape[1]
    gram = a_mat.T @ a_mat
    g_unit = gram / np.max(np.abs(gram))
    lower, upper = np.array(lower), np.array(upper)
    sets = [[] for _ in range(dim + 1)]
    for kinds in product((0, 1, 2), repeat=dim):        # per coordinate: 0 free, 1 at lower, 2 at upper
        kinds = np.array(kinds)
        free, fixed = np.flatnonzero(kinds == 0), np.flatnonzero(kinds > 0)
        if not fixed.size:
            continue                                    # the unconstrained minimiser p* itself
        v_fixed = np.where(kinds[fixed] == 1, lower[fixed], upper[fixed])
        k_mat = np.linalg.pinv(gram[np.ix_(free, free)]) @ gram[np.ix_(free, fixed)]
        m_mat, c = np.zeros((dim, dim)), np.zeros(dim)
        m_mat[free, free] = 1.0
        m_mat[np.ix_(free, fixed)] = k_mat
        c[free], c[fixed] = -k_mat @ v_fixed, v_fixed
        grad_w, grad_c = g_unit @ (m_mat - np.eye(dim)), g_unit @ c
        sign = np.where(kinds[fixed] == 1, 1.0, -1.0)[:, None]
        # rows: the 2 dim - |F| KKT quantities, then the candidate itself
        weights = np.concatenate([m_mat[free], -m_mat[free], sign * grad_w[fixed], m_mat])
        offsets = np.concatenate([c[free] - lower[free], upper[free] - c[free], sign[:, 0] * grad_c[fixed], c])
        sets[fixed.size].append((weights, offsets))
    levels = [(np.concatenate([s[0] for s in level]), np.concatenate([s[1] for s in level])[:, None], len(level))
              for level in sets[1:]]
    return np.linalg.pinv(a_mat).T, levels


def _box_ls_exact(a_mat, b, lower, upper):
    """Box-constrained LS of every row of ``b`` ``(k, rows)``, exactly, by KKT active-set enumeration.

    The unconstrained minimiser ``p* = pinv(A) b`` (that of :func:`~locbook.static.lateration.lateration_ls`) is the
    answer where it lies in
    the box. For the other problems the set that holds each coordinate outside the box at the bound it crosses is
    tried first (:func:`_box_guided_code`: the answer of most problems); the problems it does not settle visit the
    active sets (:func:`_box_active_sets`) by the number of coordinates held at a bound, 1 to ``dim``, every set of
    a level tested for the problems still open with one matrix product per block of problems (blocks keep the
    temporaries small: on some machines fresh large arrays cost more in page faults than the arithmetic). A
    candidate is a KKT point if it is primal feasible (its free coordinates within the box) and the gradient ``g =
    A^T (A p - b)`` has the sign of its bounds (``g_i >= 0`` at a lower bound, ``g_i <= 0`` at an upper one; zero on
    the free coordinates by construction). A KKT point of a convex QP is a global minimiser, so a problem is settled
    by the first KKT candidate found (any other has the same objective, e.g. when ``A`` is rank-deficient); for a
    strictly convex QP (``A`` of full column rank) it is the unique minimiser, exact up to rounding. The tests allow
    1e-9 relative rounding; should rounding leave a problem with no KKT candidate, the primal-feasible candidate of
    least objective is taken (a corner always is feasible). Returns positions ``(k, dim)`` (clipped into the box)
    and success flags (finite).

    With numba (:func:`_box_kernel_module`: enabled, at least ``_BOX_NUMBA_MIN_PROBLEMS`` problems) the same search
    runs problem by problem in one compiled loop (:func:`locbook.static._box_kernels._nb_box_ls`): the same sets in
    the same order, acceptance rule, tolerance and fallback, so the same answers up to the rounding of the products
    (1e-12, ``tests/static/test_box_ls_compiled.py``); a problem inside the box keeps ``p*`` bit for bit either way.
    """
    key = tuple(map(tuple, a_mat.tolist()))
    pinv_t, levels = _box_active_sets(key, lower, upper)
    lo, hi = np.array(lower), np.array(upper)
    with np.errstate(over="ignore", invalid="ignore"):
        p_star = b @ pinv_t
    kernels = _box_kernel_module(len(b))
    if kernels is not None:     # the same search, problem by problem in one compiled loop (no temporaries per set)
        tables = _box_kernel_tables(key, lower, upper)
        pos, ok = np.empty(p_star.shape), np.empty(len(b), bool)
        kernels._nb_box_ls(np.ascontiguousarray(p_star), lo, hi, float(np.max(np.maximum(np.abs(lo), np.abs(hi)))),
                           *tables, np.ascontiguousarray(a_mat, dtype=float), False, pos, ok)
        return pos, ok
    # per coordinate: numpy reductions over an axis of 2 or 3 are slow
    ok, inside = np.ones(len(b), bool), np.ones(len(b), bool)
    for j in range(len(lo)):
        ok &= np.isfinite(p_star[:, j])
        inside &= (p_star[:, j] >= lo[j]) & (p_star[:, j] <= hi[j])
    pos = np.where(ok[:, None], p_star, np.nan)
    todo = np.flatnonzero(ok & ~inside)
    if todo.size:
        pos[todo] = _box_active_set_search(p_star[todo], lo, hi, levels, a_mat)
    return pos, ok


_BOX_BLOCK_VALUES = 32_768     # values of the largest temporary per block of problems (256 kB)
#: problems from which :func:`_box_ls_exact` runs the compiled search (fewer: numpy, without loading numba)
_BOX_NUMBA_MIN_PROBLEMS = 256


def _box_trial():
    """A tiny problem for the box-LS kernel (compiled or loaded once per session: _compiled._kernel_module)."""
    a_mat = np.array([[1.0, 0.0], [0.0, 1.0]])
    tables = _box_kernel_tables(((1.0, 0.0), (0.0, 1.0)), (0.0, 0.0), (1.0, 1.0))
    pos, ok = np.empty((1, 2)), np.empty(1, bool)

    def run(kernels):
        kernels._nb_box_ls(np.array([[2.0, 0.5]]), np.zeros(2), np.ones(2), 1.0, *tables, a_mat, False, pos, ok)
    return run


def _box_kernel_module(n_problems: int):
    """:mod:`locbook.static._box_kernels` when the compiled search applies (at least ``_BOX_NUMBA_MIN_PROBLEMS``
    problems, the compiled paths on and the kernel working here:
    :func:`locbook.tracking._compiled._kernel_module`), else None (the numpy search)."""
    if n_problems < _BOX_NUMBA_MIN_PROBLEMS:
        return None
    return _compiled._kernel_module("locbook.static._box_kernels", _box_trial, "box LS", stacklevel=5)


def _box_flat_tables(levels, dim: int):
    """The active sets of ``levels`` (:func:`_box_active_sets`) for the compiled search, in the numpy search's order:
    ``weights (rows, dim)`` and ``offsets (rows,)`` of every set one after the other, and per set its first row
    ``start`` and its number of KKT quantities ``n_kkt`` (``2 dim - j`` for ``j`` coordinates at a bound; the
    ``dim`` rows of its candidate follow them)."""
    start, n_kkt, first = [], [], 0
    for j, (weights, _, n_sets) in enumerate(levels, start=1):
        per_set = weights.shape[0] // n_sets
        start += [first + s * per_set for s in range(n_sets)]
        n_kkt += [2 * dim - j] * n_sets
        first += weights.shape[0]
    return (np.ascontiguousarray(np.concatenate([lv[0] for lv in levels]), dtype=float),
            np.ascontiguousarray(np.concatenate([lv[1][:, 0] for lv in levels]), dtype=float),
            np.array(start, np.int64), np.array(n_kkt, np.int64), _box_guided_sets(dim))


def _box_guided_sets(dim: int) -> np.ndarray:
    """``guided[code]``: the index (in :func:`_box_flat_tables`' order) of the active set that holds coordinate ``j``
    free (``kind 0``), at its lower (1) or at its upper bound (2), ``code = sum_j kind_j 3^(dim - 1 - j)``; -1 for
    all free. The sets are ordered by the number of bounds held, then in ``itertools.product`` order (as
    :func:`_box_active_sets` builds them)."""
    patterns = list(product((0, 1, 2), repeat=dim))
    order = sorted(range(1, len(patterns)), key=lambda c: (sum(k > 0 for k in patterns[c]), c))
    guided = np.full(len(patterns), -1, np.int64)
    guided[order] = np.arange(len(order))
    return guided


def _box_guided_code(p_star, lo, hi) -> np.ndarray:
    """The code (:func:`_box_guided_sets`) of the active set that holds each coordinate of ``p_star (n, dim)``
    outside the box at the bound it crosses: the KKT set of most problems (those whose coordinates do not pull one
    another across the bounds: most problems outside the box, docs/speed.md)."""
    code = np.zeros(len(p_star), np.int64)
    for j in range(p_star.shape[1]):
        code = 3 * code + np.where(p_star[:, j] < lo[j], 1, np.where(p_star[:, j] > hi[j], 2, 0))
    return code


@lru_cache(maxsize=64)
def _box_kernel_tables(a_key, lower, upper):
    """:func:`_box_flat_tables` of :func:`_box_active_sets` (once per anchors and box)."""
    return _box_flat_tables(_box_active_sets(a_key, lower, upper)[1], len(lower))


def _box_active_set_search(p_star, lo, hi, levels, a_mat):
    """The KKT search of :func:`_box_ls_exact` for finite unconstrained minimisers ``p_star (n, dim)`` outside
    the box."""
    n, dim = p_star.shape
    size = np.abs(p_star[:, 0])
    for j in range(1, dim):
        size = np.maximum(size, np.abs(p_star[:, j]))
    tol = -1e-9 * (1.0 + np.max(np.maximum(np.abs(lo), np.abs(hi))) + size)
    out = np.empty((n, dim))
    # first, per problem, the set that holds each coordinate outside the box at the bound it crosses
    flat_w, flat_c, starts, n_kkts, guided = _box_flat_tables(levels, dim)
    sets = guided[_box_guided_code(p_star, lo, hi)]
    still = []
    for s in np.unique(sets):
        idx = np.flatnonzero(sets == s)
        if s < 0:                         # inside the box (not for this function): the search decides
            still.append(idx)
            continue
        r0, k = starts[s], n_kkts[s]
        rows = p_star[idx] @ flat_w[r0:r0 + k + dim].T + flat_c[r0:r0 + k + dim]      # (problems, rows)
        settled = rows[:, :k].min(axis=1) >= tol[idx]
        out[idx[settled]] = rows[settled, k:]
        still.append(idx[~settled])
    open_ = np.concatenate(still) if still else np.arange(0)
    for weights, offsets, n_sets in levels:
        if not open_.size:
            break
        # blocks of problems keep the temporaries small (large fresh arrays cost page faults, not arithmetic)
        block = max(256, _BOX_BLOCK_VALUES // weights.shape[0])
        still = []
        for start in range(0, open_.size, block):
            idx = open_[start:start + block]
            rows = (weights @ p_star[idx].T + offsets).reshape(n_sets, -1, idx.size)  # (sets, rows, problems)
            kkt = rows[:, :-dim].min(axis=1) >= tol[idx]                              # (sets, problems)
            best = np.argmax(kkt, axis=0)
            r = np.arange(idx.size)
            settled = kkt[best, r]
            out[idx[settled]] = rows[best[settled], -dim:, r[settled]]
            still.append(idx[~settled])
        open_ = np.concatenate(still)
        if not open_.size:
            break
    if open_.size:     # rounding left no KKT candidate
        out[open_] = _box_least_feasible(p_star[open_], lo, hi, levels, a_mat, tol[open_])
    return np.clip(out, lo, hi)


def _box_least_feasible(p_star, lo, hi, levels, a_mat, tol):
    """The fallback of :func:`_box_active_set_search`: of every active set's candidate the primal-feasible one
    (a corner always is) of least objective ``|A (p - p*)|^2`` (exact too, but it evaluates every set)."""
    n, dim = p_star.shape
    out, least = np.empty((n, dim)), np.full(n, np.inf)
    for weights, offsets, n_sets in levels:
        rows = (weights @ p_star.T + offsets).reshape(n_sets, -1, n)
        for cand in rows[:, -dim:].transpose(0, 2, 1):                     # each set's candidates (n, dim)
            feasible = np.all((cand >= lo + tol[:, None]) & (cand <= hi - tol[:, None]), axis=-1)
            excess = np.sum(((cand - p_star) @ a_mat.T) ** 2, axis=-1)
            take = feasible & (excess < least)
            out[take], least[take] = cand[take], excess[take]
    return out


def lateration_box_ls(anchors_m, distance_m, lower_m, upper_m, ref_index: int = 0, *,
                      min_anchors: int | None = None, tag_height_m: float | None = None,
                      solver: str = "exact") -> LocalizationResult:
    """Linearized least squares constrained to a box, ``min |A p - b|^2`` over ``lower_m <= p <= upper_m``.

    ``A, b`` are those of :func:`locbook.static.lateration.lateration_system` (2-D or 3-D): a fix kept inside the
    room, an optional extension to George and Vadivukkarasi (which does not constrain its estimates: "some of the
    results go beyond the boundaries"). Where the unconstrained fix is inside the box it is the answer (bit for bit
    that of :func:`~locbook.static.lateration.lateration_ls`); elsewhere the answer is not that fix clipped into the
    box, which is wrong in general (correlated coordinates: holding one at its bound moves the best value of
    another).

    Parameters
    ----------
    anchors_m : array_like, shape (m, dim)
        Anchor positions shared by every problem; ``(m, 3)`` with ``tag_height_m``.
    distance_m : array_like, shape (..., m)
        Ranges (m); NaN is an anchor not heard (:mod:`locbook.static.missing`).
    lower_m, upper_m : float or array_like, shape (dim,)
        The box's corners (a scalar serves every coordinate); ``lower_m <= upper_m``.
    ref_index : int, default 0
        The reference anchor of the linearized system.
    min_anchors : int, optional
        Heard anchors a problem needs (default ``dim + 1``).
    tag_height_m : float, optional
        The tag's known height: anchors with heights, the box on ``(x, y)`` (:mod:`locbook.static.checks`).
    solver : {"exact", "cvxpy"}, default "exact"
        :data:`BOX_LS_SOLVERS`. ``"exact"``: KKT active-set enumeration, exact (no iterations, no solver
        tolerance). ``"cvxpy"``: the reference, one stacked cvxpy QP (Clarabel, tight tolerances).

    Returns
    -------
    LocalizationResult
        ``position_m`` ``(..., dim)`` inside the box; ``cost`` None. A problem the solver fails on (or whose
        arithmetic does not give a finite fix) gets a NaN position and ``status="solver_failed"``, alone.

    Raises
    ------
    DegenerateGeometryError
        Anchors that are too few, coincident or collinear.
    ValueError
        An empty box (``lower_m > upper_m``), a box of the wrong shape, negative or infinite ranges.

    Notes
    -----
    ``solver="exact"``: each of the ``3^dim`` (9 or 27) ways to hold every coordinate free, at its lower or at its
    upper bound gives the reduced unconstrained LS in closed form; its reduced matrices depend only on ``A`` and the
    box, so they are computed once per anchors and box (cached). From 256 problems on, one compiled loop (numba;
    ``LOCBOOK_NUMBA=0`` turns it off) tries the active sets problem by problem, stopping at the first that passes;
    otherwise numpy evaluates them with matrix products over many problems at once (blocks of about a thousand).
    Both give the same answers (to 1e-12; tests/static/test_box_ls_compiled.py). The answer is the candidate that is
    feasible and meets the KKT sign conditions (gradient ``A^T (A p - b)`` >= 0 at a lower bound, <= 0 at an upper
    one, 0 on free coordinates); for this strictly convex QP it is unique (:func:`_box_ls_exact`).

    ``solver="cvxpy"``: all problems are stacked into one QP, built once per (batch size, anchors, box) with the
    right-hand sides as a Parameter and re-solved by setting its value; if the solve fails, the batch is halved
    until the failing problems are alone. It agrees with the exact solver to Clarabel's tolerance, which is
    relative to the stacked objective: about 1e-6 m for a few problems, up to about 1e-3 m for thousands stacked
    (one problem per solve at tighter tolerances agrees to 1e-7 m; ``tests/static/test_box_ls.py``).

    References
    ----------
    George and Vadivukkarasi, Eq. (8): the linearized system; the box and its KKT conditions (Karush-Kuhn-Tucker
    for a convex QP with bound constraints) are this library's extension.

    Examples
    --------
    A tag outside the room: the unconstrained fix leaves the box, the constrained one stays on its wall:

    >>> import numpy as np
    >>> import locbook as lb
    >>> anchors = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    >>> ranges = lb.pairwise_distance_m(np.array([12.0, 4.0]), anchors)
    >>> print(np.round(lb.lateration_ls(anchors, ranges).position_m, 2))
    [12.  4.]
    >>> fix = lb.lateration_box_ls(anchors, ranges, 0.0, 10.0)
    >>> print(np.round(fix.position_m, 2), fix.status)
    [10.  5.] ok
    """
    distance_m = given_readings("distance_m", distance_m)
    check_choice("solver", solver, BOX_LS_SOLVERS)
    a_mat, b = lateration_system(anchors_m, distance_m, ref_index, tag_height_m=tag_height_m)
    dim = a_mat.shape[1]
    min_anchors = check_min_anchors(min_anchors, dim, a_mat.shape[0] + 1)
    bounds = []
    for name, value in (("lower_m", lower_m), ("upper_m", upper_m)):
        value = as_array(name, value)
        if value.ndim > 1 or value.size not in (1, dim):
            raise ValueError(f"{name} must be a scalar or have shape ({dim},), got shape {value.shape}")
        bounds.append(tuple(np.broadcast_to(value, (dim,)).tolist()))
    lower, upper = bounds
    if any(lo > hi for lo, hi in zip(lower, upper)):
        raise ValueError(f"empty box: lower {lower} > upper {upper}")
    if has_missing(distance_m):
        return lateration_by_heard(anchors_m, distance_m, ref_index, min_anchors,
                                    lambda a, d, ref: lateration_box_ls(a, d, lower, upper, ref,
                                                                        tag_height_m=tag_height_m, solver=solver),
                                    "lateration_box_ls", tag_height_m)
    batch = b.shape[:-1]
    flat_b = b.reshape(-1, b.shape[-1])
    finite = np.all(np.isfinite(flat_b), axis=-1)
    if not finite.all():     # squared ranges that overflow: those problems fail alone, the solver never sees them
        flat_d = np.asarray(distance_m, float).reshape(-1, a_mat.shape[0] + 1)
        return solve_where(finite, batch, dim,
                            lambda sel: lateration_box_ls(anchors_m, flat_d[sel], lower, upper, ref_index,
                                                          tag_height_m=tag_height_m, solver=solver),
                            "lateration_box_ls", "solver_failed")
    if solver == "exact":
        pos, ok = _box_ls_exact(a_mat, flat_b, lower, upper)
    else:
        pos, ok = _solve_box_batch(a_mat, flat_b, lower, upper)
    return LocalizationResult(pos.reshape(batch + (dim,)), ok.reshape(batch), None, 0, "lateration_box_ls",
                              status_array(ok).reshape(batch))


