"""The compiled box-constrained LS kernel (numba) of :func:`locbook.static.box_ls.lateration_box_ls`, compiled
on first call (numba caches the machine code on disk). Imported only by
:func:`locbook.static.box_ls._box_ls_exact` when the compiled path runs, so that ``import locbook`` never loads
numba. Without numba it is plain Python (the same arithmetic, slowly: the tests may run it that way).

The kernel is the KKT active-set enumeration of :func:`locbook.static.box_ls._box_active_set_search` run
problem by problem: the active sets' affine maps ``weights @ p* + offsets`` (:func:`~locbook.static.box_ls.
_box_active_sets`, flattened by :func:`~locbook.static.box_ls._box_kernel_tables`) are evaluated for one
unconstrained minimiser ``p*`` at a time, in the same order (by the number of coordinates at a bound, then
``itertools.product`` order), the first set whose KKT quantities are all ``>= tol`` settling the problem (the numpy
search's ``argmax``); no temporaries per set, and a problem stops at its first KKT set. As in numpy, the set that holds
each coordinate outside the box at the bound it crosses (``guided``) is tried first.
"""
from __future__ import annotations

import numpy as np

from .._numba import jit as _jit


@_jit
def _nb_candidate(weights, offsets, r0, p, cand):
    """``cand = weights[r0:r0 + dim] @ p + offsets[r0:r0 + dim]`` (one active set's candidate)."""
    dim = p.shape[0]
    for c in range(dim):
        acc = 0.0
        for j in range(dim):
            acc += weights[r0 + c, j] * p[j]
        cand[c] = acc + offsets[r0 + c]


@_jit
def _nb_box_ls(p_star, lo, hi, bound, weights, offsets, start, n_kkt, guided, a_mat, force_fallback, pos, ok):
    """Box LS of every unconstrained minimiser ``p_star (n, dim)``, in place into ``pos (n, dim)`` and ``ok (n,)``.

    A problem with a non-finite ``p*`` fails (NaN, ``ok`` False); one inside the box keeps ``p*`` bit for bit; for
    the others the set ``guided[code]`` (:func:`~locbook.static.box_ls._box_guided_sets`: each coordinate outside
    the box held at the bound it crosses) is tried first, then the active sets ``s`` (rows ``start[s]``: ``n_kkt[s]``
    KKT quantities, then the ``dim`` coordinates of the candidate) are visited in order; the first whose quantities
    are all ``>= tol`` (``tol = -1e-9 (1 + bound +
    max_j |p*_j|)``, ``bound`` the box's largest absolute bound) gives the answer. If none does (rounding;
    ``force_fallback`` makes it so for the tests), the primal-feasible candidate (within ``tol``) of least
    ``|A (p - p*)|^2`` is taken, the first of equal ones. The answer is clipped into the box, as in numpy.
    """
    n, dim = p_star.shape
    n_sets = start.shape[0]
    rows = a_mat.shape[0]
    p = np.empty(dim)
    cand = np.empty(dim)
    best = np.empty(dim)
    for i in range(n):
        finite = True
        inside = True
        for j in range(dim):
            v = p_star[i, j]
            p[j] = v
            if not np.isfinite(v):
                finite = False
            if not (v >= lo[j] and v <= hi[j]):
                inside = False
        ok[i] = finite
        if not finite:
            for j in range(dim):
                pos[i, j] = np.nan
            continue
        if inside:
            for j in range(dim):
                pos[i, j] = p[j]
            continue
        size = abs(p[0])
        for j in range(1, dim):
            size = max(size, abs(p[j]))
        tol = -1e-9 * (1.0 + bound + size)
        found = False
        if not force_fallback:
            code = 0
            for j in range(dim):
                code = 3 * code + (1 if p[j] < lo[j] else (2 if p[j] > hi[j] else 0))
            first = guided[code]
            for t in range(-1, n_sets):
                s = first if t < 0 else t
                if s < 0 or (t >= 0 and s == first):      # (the guided set was tried first)
                    continue
                r0 = start[s]
                kkt = True
                for r in range(r0, r0 + n_kkt[s]):
                    acc = 0.0
                    for j in range(dim):
                        acc += weights[r, j] * p[j]
                    if not (acc + offsets[r] >= tol):
                        kkt = False
                        break
                if kkt:
                    _nb_candidate(weights, offsets, r0 + n_kkt[s], p, best)
                    found = True
                    break
        if not found:                   # rounding left no KKT candidate: the least feasible one
            least = np.inf
            for j in range(dim):
                best[j] = np.nan
            for s in range(n_sets):
                _nb_candidate(weights, offsets, start[s] + n_kkt[s], p, cand)
                feasible = True
                for j in range(dim):
                    if not (cand[j] >= lo[j] + tol and cand[j] <= hi[j] - tol):
                        feasible = False
                if not feasible:
                    continue
                excess = 0.0
                for k in range(rows):
                    acc = 0.0
                    for j in range(dim):
                        acc += (cand[j] - p[j]) * a_mat[k, j]
                    excess += acc * acc
                if excess < least:
                    least = excess
                    for j in range(dim):
                        best[j] = cand[j]
        for j in range(dim):
            pos[i, j] = min(max(best[j], lo[j]), hi[j])
