"""The compiled grid Bayes filter kernels (numba), compiled on first call (numba caches the machine code on disk).
Imported only by :func:`locbook.tracking.bayes.grid_bayes_filter` when the compiled path runs, so that ``import
locbook`` never loads numba. Without numba they are plain Python (the same arithmetic, slowly).

Two kernels, both run by run over the leading run axis (the runs are independent: a run's numbers do not depend on
the others):

- :func:`_nb_predict`: the prediction ``sum_l' K(c_l - c_l' - v) b(l') / Z_l'`` as a banded correlation along each
  axis of the regular lattice (``locbook.tracking.bayes._BandedLattice`` explains the truncation and the
  buffers); the normalisers ``Z`` are the same passes with the taps reversed, applied to the lattice's mask;
- :func:`_nb_update`: per run, the log-likelihood (from the fixed cell-by-anchor mean table and the step's readings,
  NaN = not heard, or given), the collapse test of the numpy loop, the posterior ``max(pred, 1e-300) exp(ll -
  max ll)`` (the log-domain form of the numpy loop where that under- or overflows), its normalisation, mean,
  centred covariance, MAP cell and ``n_eff``.

The exponential of the update is :func:`locbook.tracking._vecmath._exp_nonpositive` (within 2 ulp of ``exp``), which
LLVM vectorises; the library ``exp`` is a scalar call per cell and was most of the update's time.
"""
from __future__ import annotations

import numpy as np

from .._numba import jit
from ._vecmath import _exp_nonpositive  # noqa: F401 - the tests reach it here too

_FLOOR = 1e-300                     # the numpy loop's floor on the predicted belief (its log(max(b, 1e-300)))
_BLOCK = 1024                       # cells per block of the reductions (:func:`_reduction`)



def _jit(fn):
    """``fn`` compiled as every kernel (:func:`locbook._numba.jit`), with fused multiply-adds allowed (``contract``:
    one rounding instead of two; it halves the work of the polynomial and the correlations)."""
    return jit(fn, contract=True)


@_jit
def _shift_pass(src, b, taps, dst, n):
    """``dst[i] = sum_k taps[k] src[b + i - k]`` for ``i < n`` (a correlation along a contiguous row; ``src`` padded
    so that every index is inside; ``len(taps)`` a multiple of 8, zero-padded), eight taps per sweep."""
    for i in range(n):
        dst[i] = 0.0
    for k in range(0, taps.shape[0], 8):
        c = b - k
        s0, s1, s2, s3 = src[c:c + n], src[c - 1:c - 1 + n], src[c - 2:c - 2 + n], src[c - 3:c - 3 + n]
        s4, s5, s6, s7 = src[c - 4:c - 4 + n], src[c - 5:c - 5 + n], src[c - 6:c - 6 + n], src[c - 7:c - 7 + n]
        w0, w1, w2, w3 = taps[k], taps[k + 1], taps[k + 2], taps[k + 3]
        w4, w5, w6, w7 = taps[k + 4], taps[k + 5], taps[k + 6], taps[k + 7]
        for i in range(n):
            dst[i] += ((w0 * s0[i] + w1 * s1[i]) + (w2 * s2[i] + w3 * s3[i])) + \
                ((w4 * s4[i] + w5 * s5[i]) + (w6 * s6[i] + w7 * s7[i]))


@_jit
def _rows_pass(src, m, b, taps, dst, j):
    """``dst[x] = sum_k taps[k] src[(b + j - k) m + x]`` for ``x < m``: a correlation across rows of length ``m`` of
    the flat buffer ``src`` (vectorised along the rows), eight taps per sweep."""
    for x in range(m):
        dst[x] = 0.0
    for k in range(0, taps.shape[0], 8):
        c = (b + j - k) * m
        s0, s1, s2, s3 = src[c:c + m], src[c - m:c], src[c - 2 * m:c - m], src[c - 3 * m:c - 2 * m]
        s4, s5, s6, s7 = src[c - 4 * m:c - 3 * m], src[c - 5 * m:c - 4 * m], src[c - 6 * m:c - 5 * m], \
            src[c - 7 * m:c - 6 * m]
        w0, w1, w2, w3 = taps[k], taps[k + 1], taps[k + 2], taps[k + 3]
        w4, w5, w6, w7 = taps[k + 4], taps[k + 5], taps[k + 6], taps[k + 7]
        for x in range(m):
            dst[x] += ((w0 * s0[x] + w1 * s1[x]) + (w2 * s2[x] + w3 * s3[x])) + \
                ((w4 * s4[x] + w5 * s5[x]) + (w6 * s6[x] + w7 * s7[x]))


@_jit
def _rows_pass2(src, m, b, taps, dst0, dst1, j):
    """:func:`_rows_pass` for the rows ``j`` (into ``dst0``) and ``j + 1`` (into ``dst1``) at once: nine source
    rows per sweep of eight taps serve both (fewer loads per multiply-add)."""
    for x in range(m):
        dst0[x] = 0.0
        dst1[x] = 0.0
    for k in range(0, taps.shape[0], 8):
        c = (b + j - k) * m
        r8 = src[c + m:c + 2 * m]
        s0, s1, s2, s3 = src[c:c + m], src[c - m:c], src[c - 2 * m:c - m], src[c - 3 * m:c - 2 * m]
        s4, s5, s6, s7 = src[c - 4 * m:c - 3 * m], src[c - 5 * m:c - 4 * m], src[c - 6 * m:c - 5 * m], \
            src[c - 7 * m:c - 6 * m]
        w0, w1, w2, w3 = taps[k], taps[k + 1], taps[k + 2], taps[k + 3]
        w4, w5, w6, w7 = taps[k + 4], taps[k + 5], taps[k + 6], taps[k + 7]
        for x in range(m):
            a0, a1, a2, a3, a4, a5, a6, a7 = s0[x], s1[x], s2[x], s3[x], s4[x], s5[x], s6[x], s7[x]
            dst0[x] += ((w0 * a0 + w1 * a1) + (w2 * a2 + w3 * a3)) + ((w4 * a4 + w5 * a5) + (w6 * a6 + w7 * a7))
            dst1[x] += ((w0 * r8[x] + w1 * a0) + (w2 * a1 + w3 * a2)) + ((w4 * a3 + w5 * a4) + (w6 * a5 + w7 * a6))


@_jit
def _nb_predict(belief, zinv, dead, scatter, gather, dims, xb, lx, tx, bx, yb, ly, py, ty, by, zb, pz, tz, bz, out,
                pred):
    """``pred[r] = (K (belief[r] * zinv))`` at the cells, for the runs not ``dead``: the belief over ``Z`` scattered
    into the padded lattice ``xb`` (rows of length ``lx``; masked points and pads stay 0), correlated along x into
    ``yb`` (``(n0, ly, n2)``, rows ``py..`` of each plane), along y into ``zb`` (3-D: planes ``pz..``) or ``out``,
    along z into ``out``, and gathered. ``dims = (n0, n1, n2, dim)``; ``t*``, ``b*``: each axis's taps and read
    offset (:func:`_shift_pass`, :func:`_rows_pass`)."""
    n0, n1, n2, dim = dims[0], dims[1], dims[2], dims[3]
    n_runs, n_cells = belief.shape
    for r in range(n_runs):
        if dead[r]:
            continue
        for c in range(n_cells):
            xb[scatter[c]] = belief[r, c] * zinv[c]
        for q in range(n0 * n1):
            if dim == 1:
                dst = out[0:n2]
            else:
                o = ((q // n1) * ly + py + q % n1) * n2
                dst = yb[o:o + n2]
            _shift_pass(xb[q * lx:(q + 1) * lx], bx, tx, dst, n2)
        if dim >= 2:
            for a in range(n0):
                src = yb[a * ly * n2:(a + 1) * ly * n2]
                target = out if dim == 2 else zb
                for j in range(0, n1, 2):
                    o = (a * n1 + j) * n2 if dim == 2 else ((pz + a) * n1 + j) * n2
                    if j + 1 < n1:
                        _rows_pass2(src, n2, by, ty, target[o:o + n2], target[o + n2:o + 2 * n2], j)
                    else:
                        _rows_pass(src, n2, by, ty, target[o:o + n2], j)
        if dim == 3:
            m = n1 * n2
            for a in range(0, n0, 2):
                if a + 1 < n0:
                    _rows_pass2(zb, m, bz, tz, out[a * m:(a + 1) * m], out[(a + 1) * m:(a + 2) * m], a)
                else:
                    _rows_pass(zb, m, bz, tz, out[a * m:(a + 1) * m], a)
        for c in range(n_cells):
            pred[r, c] = out[gather[c]]


def _reduction(fn):
    """A reduction loop of the update: reassociation allowed (:func:`locbook._numba.jit`), so that LLVM accumulates it
    in vector registers side by side (faster than four scalar partial sums: docs/speed.md). Each sum runs in blocks of
    ``_BLOCK`` cells whose partial results are added in order, which bounds the error by that of ``_BLOCK`` / (the
    partial sums of a block) plus ``C / _BLOCK`` additions."""
    return jit(fn, contract=True, reassoc=True)


@_reduction
def _sum(a, n):
    """``sum(a[:n])`` in blocks of ``_BLOCK``."""
    total = 0.0
    for start in range(0, n, _BLOCK):
        s = 0.0
        ab = a[start:min(start + _BLOCK, n)]        # a view: its index starts at 0, which LLVM vectorises
        for i in range(ab.size):
            s += ab[i]
        total += s
    return total


@_reduction
def _dot(a, b, n):
    """``sum(a[:n] * b[:n])`` in blocks, as :func:`_sum`."""
    total = 0.0
    for start in range(0, n, _BLOCK):
        s = 0.0
        stop = min(start + _BLOCK, n)
        ab, bb = a[start:stop], b[start:stop]
        for i in range(ab.size):
            s += ab[i] * bb[i]
        total += s
    return total


@_reduction
def _centred(w, x, mx, y, my, n):
    """``sum(w (x - mx) (y - my))`` over ``n`` cells, in blocks, as :func:`_sum`."""
    total = 0.0
    for start in range(0, n, _BLOCK):
        s = 0.0
        stop = min(start + _BLOCK, n)
        wb, xb, yb = w[start:stop], x[start:stop], y[start:stop]
        for i in range(wb.size):
            s += wb[i] * (xb[i] - mx) * (yb[i] - my)
        total += s
    return total


@_jit
def _top(ll, n):
    """``(max ll[:n], any NaN)``, four partial maxima."""
    t0 = t1 = t2 = t3 = -np.inf
    nan = 0
    i = 0
    while i + 4 <= n:
        a, b, c, d = ll[i], ll[i + 1], ll[i + 2], ll[i + 3]
        nan |= (a != a) | (b != b) | (c != c) | (d != d)
        t0 = a if a > t0 else t0
        t1 = b if b > t1 else t1
        t2 = c if c > t2 else t2
        t3 = d if d > t3 else t3
        i += 4
    while i < n:
        a = ll[i]
        nan |= a != a
        t0 = a if a > t0 else t0
        i += 1
    return max(max(t0, t1), max(t2, t3)), nan != 0


@_reduction
def _moments2(w, x, y, n):
    """``(sum w^2, sum w x, sum w y)`` over ``n`` cells, in blocks, as :func:`_sum`."""
    sq = mx = my = 0.0
    for start in range(0, n, _BLOCK):
        q = a = b = 0.0
        stop = min(start + _BLOCK, n)
        wb, xb, yb = w[start:stop], x[start:stop], y[start:stop]
        for i in range(wb.size):
            q += wb[i] * wb[i]
            a += wb[i] * xb[i]
            b += wb[i] * yb[i]
        sq += q
        mx += a
        my += b
    return sq, mx, my


@_reduction
def _cov2(w, x, mx, y, my, n):
    """``sum w (x - mx)^2, sum w (x - mx)(y - my), sum w (y - my)^2`` over ``n`` cells, in blocks, as :func:`_sum`."""
    sxx = sxy = syy = 0.0
    for start in range(0, n, _BLOCK):
        a = b = c = 0.0
        stop = min(start + _BLOCK, n)
        wb, xb, yb = w[start:stop], x[start:stop], y[start:stop]
        for i in range(wb.size):
            u, v = xb[i] - mx, yb[i] - my
            p = wb[i] * u
            a += p * u
            b += p * v
            c += wb[i] * v * v
        sxx += a
        sxy += b
        syy += c
    return sxx, sxy, syy


@_jit
def _nb_update(belief, ll_given, use_table, table, rss, inv_sigma, dead, points, llb, wb, mean, cov, best, n_eff,
               collapsed):
    """The update of the runs not ``dead``, in place: ``belief (R, C)`` holds the predicted belief (or the prior) on
    entry and the posterior on exit. The log-likelihood is ``ll_given[r]`` or, with ``use_table``, ``-0.5 sum_j
    ((rss[r, j] - table[r or 0, j, c]) inv_sigma[j])^2`` over the heard readings (NaN = not heard, left out: the
    rule of :meth:`RssModel.log_likelihood`). A run whose ``max ll`` is NaN or infinite, or with a NaN ``ll``, is
    flagged in ``collapsed`` and left alone (the numpy loop's test: its ``max(log b + ll)`` is then not finite).
    Otherwise ``w = max(pred, 1e-300) exp(ll - max ll)``, in the log domain where its largest value is below 1e-250
    or its sum overflows; the posterior ``w / sum w``; its mean ``(R, dim)`` and centred covariance written at the
    step's slot; ``best`` the first cell of the largest posterior; ``n_eff = 1 / sum b^2``. ``points``: ``(dim,
    C)``; ``llb``, ``wb``: scratch ``(C,)``."""
    n_runs, n_cells = belief.shape
    dim = points.shape[0]
    n_anchors = rss.shape[1]
    for r in range(n_runs):
        if dead[r]:
            continue
        if use_table:
            tr = table[r if table.shape[0] > 1 else 0]
            first = True
            for j in range(n_anchors):
                v = rss[r, j]
                if v != v:                              # not heard
                    continue
                s = inv_sigma[j]
                row = tr[j]
                if first:
                    for c in range(n_cells):
                        d = (v - row[c]) * s
                        llb[c] = d * d
                    first = False
                else:
                    for c in range(n_cells):
                        d = (v - row[c]) * s
                        llb[c] += d * d
            if first:                                   # nothing heard
                for c in range(n_cells):
                    llb[c] = 0.0
            else:
                for c in range(n_cells):
                    llb[c] *= -0.5
            ll = llb
        else:
            ll = ll_given[r]
        top, bad = _top(ll, n_cells)
        if bad or top == np.inf or top == -np.inf:
            collapsed[r] = True
            continue
        pr = belief[r]
        for c in range(n_cells):
            p = pr[c]
            if p < _FLOOR:
                p = _FLOOR
            wb[c] = p * _exp_nonpositive(ll[c] - top)
        s = _sum(wb, n_cells)
        if not (s >= 1e-240 and s < np.inf):          # the posterior under- or overflows: the log domain
            top = -np.inf
            for c in range(n_cells):
                wb[c] = np.log(max(pr[c], _FLOOR)) + ll[c]
                if wb[c] > top:
                    top = wb[c]
            if not (top > -np.inf and top < np.inf):
                collapsed[r] = True
                continue
            for c in range(n_cells):
                wb[c] = np.exp(wb[c] - top)
            s = _sum(wb, n_cells)
        for c in range(n_cells):
            pr[c] = wb[c] / s
        at = 0
        big = pr[0]
        for c in range(n_cells):
            if pr[c] > big:
                at, big = c, pr[c]
        best[r] = at
        if dim == 2:
            sq, mx, my = _moments2(pr, points[0], points[1], n_cells)
            n_eff[r] = 1.0 / sq
            mean[r, 0], mean[r, 1] = mx, my
            cxx, cxy, cyy = _cov2(pr, points[0], mx, points[1], my, n_cells)
            cov[r, 0, 0], cov[r, 0, 1], cov[r, 1, 0], cov[r, 1, 1] = cxx, cxy, cxy, cyy
            continue
        n_eff[r] = 1.0 / _dot(pr, pr, n_cells)
        for d in range(dim):
            mean[r, d] = _dot(pr, points[d], n_cells)
        for d in range(dim):
            for e in range(d + 1):
                cov[r, d, e] = _centred(pr, points[d], mean[r, d], points[e], mean[r, e], n_cells)
                cov[r, e, d] = cov[r, d, e]
