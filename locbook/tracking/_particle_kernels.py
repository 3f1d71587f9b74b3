"""The compiled particle-filter kernels (numba): the RSS log-likelihood of every particle in one pass, the random-walk
step, the weight normalisation, the moments and systematic resampling, each a loop over runs and particles with no
temporaries of the size of the cloud. Imported only by :mod:`locbook.tracking.particle` when the compiled path runs, so
that ``import locbook`` never loads numba; without numba they are plain Python (the same arithmetic, slowly).

Each kernel does the arithmetic of the numpy code it replaces, in the same order where that order is numpy's own
documented algorithm (the pairwise sum of ``np.sum``, the sequential ``np.cumsum``, ``np.mod``'s sign rule, the row
offsets of :func:`~locbook.tracking.resampling._search_rows`), so the weights, the resampling decisions and the
particles follow the numpy path's; sums that numpy leaves to its SIMD loops (``einsum``) are summed in order here and
agree to round-off. The likelihood's log10 is :func:`locbook.tracking._vecmath._log10_block`, musl's algorithm written
to vectorise (within 2 ulp of numpy's, which calls the C library's one value at a time: that call was most of the
likelihood's time).
"""
from __future__ import annotations

import math

import numpy as np

from .._numba import jit as _jit
from ._vecmath import _exp_nonpositive, _log10_block  # noqa: F401 - the tests reach _log10_block here too

_PW_BLOCK = 128                     # numpy's pairwise-sum block (PW_BLOCKSIZE in loops_utils.h)


@_jit
def _block_sum(a, lo, n):
    """numpy's pairwise sum of ``a[lo:lo + n]`` for ``n <= 128``: in order below 8, else 8 accumulators."""
    if n < 8:
        res = 0.0
        for i in range(n):
            res += a[lo + i]
        return res
    r0, r1, r2, r3 = a[lo], a[lo + 1], a[lo + 2], a[lo + 3]
    r4, r5, r6, r7 = a[lo + 4], a[lo + 5], a[lo + 6], a[lo + 7]
    i = 8
    stop = n - n % 8
    while i < stop:
        r0 += a[lo + i]
        r1 += a[lo + i + 1]
        r2 += a[lo + i + 2]
        r3 += a[lo + i + 3]
        r4 += a[lo + i + 4]
        r5 += a[lo + i + 5]
        r6 += a[lo + i + 6]
        r7 += a[lo + i + 7]
        i += 8
    res = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while i < n:
        res += a[lo + i]
        i += 1
    return res


@_jit
def _pairwise_sum(a, lo, n):
    """``np.sum(a[lo:lo + n])`` bit for bit: numpy's pairwise summation (blocks of 128 summed by
    :func:`_block_sum`; above, the sum of the two halves split at a multiple of 8), walked with an explicit stack
    (numba's on-disk cache mishandles a recursive kernel)."""
    if n <= _PW_BLOCK:
        return _block_sum(a, lo, n)
    los = np.empty(64, np.int64)
    ns = np.empty(64, np.int64)
    stage = np.zeros(64, np.int64)                     # 0: not split yet; 1: left half pending; 2: right half pending
    left = np.empty(64)
    top = 0
    los[0], ns[0], stage[0] = lo, n, 0
    value, returned = 0.0, False
    while True:
        if returned:
            if top < 0:
                return value
            if stage[top] == 1:                        # the left half is done: keep it, do the right half
                left[top] = value
                stage[top] = 2
                half = ns[top] // 2
                half -= half % 8
                los[top + 1], ns[top + 1], stage[top + 1] = los[top] + half, ns[top] - half, 0
                top += 1
                returned = False
            else:                                      # both halves done
                value = left[top] + value
                top -= 1
        elif ns[top] <= _PW_BLOCK:
            value = _block_sum(a, los[top], ns[top])
            top -= 1
            returned = True
        else:
            stage[top] = 1
            half = ns[top] // 2
            half -= half % 8
            los[top + 1], ns[top + 1], stage[top + 1] = los[top], half, 0
            top += 1


_CHUNK = 512                                    # particles per block of the likelihood kernel (its buffers fit L1)


@_jit
def _crossings(pos, nc, ax, ay, walls, out):
    """``out[i]`` = the walls crossed by the path from the particle ``pos[:, i]`` to the anchor ``(ax, ay)``:
    :func:`~locbook.models.channel.wall_crossings` with its expressions in its order (a proper intersection of the
    two segments by orientation tests), so the counts are numpy's."""
    for i in range(nc):
        out[i] = 0.0
    for q in range(walls.shape[0]):
        w0x, w0y, w1x, w1y = walls[q, 0, 0], walls[q, 0, 1], walls[q, 1, 0], walls[q, 1, 1]
        ex, ey = w1x - w0x, w1y - w0y
        side_a = ex * (ay - w0y) - ey * (ax - w0x)           # which side of the wall line the anchor is on
        c0, a0x, a0y = ax * w0y - ay * w0x, ax - w0x, ay - w0y
        c1, a1x, a1y = ax * w1y - ay * w1x, ax - w1x, ay - w1y
        for i in range(nc):
            px, py = pos[0, i], pos[1, i]
            side_p = ex * (py - w0y) - ey * (px - w0x)
            s0 = (c0 + px * a0y) - py * a0x                  # which side of the path line each wall end is on
            s1 = (c1 + px * a1y) - py * a1x
            if s0 * s1 < 0.0 and side_p * side_a < 0.0:
                out[i] += 1.0


@_jit
def _nb_rss_loglik(x, pidx, plan, vert2, z, p0, tenn, sigma, per_anchor, d_min, d_ref, walls, waf, out):
    """``out[r, i] = -0.5 sum_j ((z_rj - h_j(x_ri)) / sigma_j)^2`` over the heard anchors (``z`` not NaN), with
    ``h_j(p) = P0_j - 10 n_j log10(max(d_j, d_min) / d0)`` and ``d_j^2 = |p - a_j|^2 + vert2_j`` (Ozkaya 2011,
    Eq. (6.3); :meth:`~locbook.models.rss.RssModel.log_likelihood` with ``constant=False``).

    ``x`` ``(1|R, N, n)`` (positions at the columns ``pidx``), ``plan`` ``(1|R, m, dim)``, ``vert2`` ``(1|R, m)``,
    ``z`` ``(R, m)``, ``p0`` and ``tenn = 10 n`` ``(1|R, m)``, ``sigma`` ``(1|R, m)`` (``per_anchor``: each residual
    divided by its sigma, as numpy does for sigma ``(m,)``) or ``(1|R, 1)`` (the sum divided by sigma^2 at the end).
    ``walls`` ``(W, 2, 2)`` (2-D positions; W may be 0) with the loss ``waf`` per wall crossed:
    :func:`~locbook.models.channel.wall_crossings` evaluated with the same expressions, ``h_j - waf nW_j``.
    Blocks of :data:`_CHUNK` particles, one anchor at a time (the sum over the anchors in their order). Returns False
    when a coordinate or a distance is not finite (the numpy path then raises its error)."""
    R, N = out.shape
    m = plan.shape[1]
    dim = pidx.shape[0]
    pos = np.empty((dim, _CHUNK))
    d2 = np.empty(_CHUNK)
    dist = np.empty(_CHUNK)
    lg = np.empty(_CHUNK)
    work = np.empty(_CHUNK)
    acc = np.empty(_CHUNK)
    crossed = np.zeros(_CHUNK)
    n_walls = walls.shape[0]
    for r in range(R):
        rx = r if x.shape[0] > 1 else 0
        ra = r if plan.shape[0] > 1 else 0
        rv = r if vert2.shape[0] > 1 else 0
        rp = r if p0.shape[0] > 1 else 0
        rs = r if sigma.shape[0] > 1 else 0
        for i0 in range(0, N, _CHUNK):
            nc = min(_CHUNK, N - i0)
            for k in range(dim):
                col = pidx[k]
                for i in range(nc):
                    pos[k, i] = x[rx, i0 + i, col]
            for i in range(nc):
                acc[i] = 0.0
            for j in range(m):
                for i in range(nc):
                    d2[i] = 0.0
                for k in range(dim):
                    a = plan[ra, j, k]
                    for i in range(nc):
                        diff = pos[k, i] - a
                        d2[i] += diff * diff
                v2 = vert2[rv, j]
                for i in range(nc):
                    d2[i] = d2[i] + v2
                unbounded = 0                    # an integer reduction (vectorised), not an exit per particle
                for i in range(nc):
                    unbounded |= not d2[i] < np.inf
                if unbounded:
                    return False
                zj = z[r, j]
                if zj != zj:                     # not heard: left out
                    continue
                for i in range(nc):
                    d = math.sqrt(d2[i])
                    if d_min > 0.0 and d < d_min:
                        d = d_min
                    dist[i] = d
                if d_ref != 1.0:                 # d / 1 is d exactly: the division only where it changes a value
                    for i in range(nc):
                        dist[i] = dist[i] / d_ref
                _log10_block(dist, lg, work, nc)
                if n_walls > 0:                  # without walls crossed stays 0: h - 0 is h exactly
                    _crossings(pos, nc, plan[ra, j, 0], plan[ra, j, 1], walls, crossed)
                p0j, tj = p0[rp, j], tenn[rp, j]
                if per_anchor:
                    sj = sigma[rs, j]
                    for i in range(nc):
                        resid = (zj - ((p0j - tj * lg[i]) - waf * crossed[i])) / sj
                        acc[i] += resid * resid
                else:
                    for i in range(nc):
                        resid = zj - ((p0j - tj * lg[i]) - waf * crossed[i])
                        acc[i] += resid * resid
            if per_anchor:
                for i in range(nc):
                    out[r, i0 + i] = -0.5 * acc[i]
            else:
                s = sigma[rs, 0]
                s2 = s * s
                for i in range(nc):
                    out[r, i0 + i] = -0.5 * acc[i] / s2
    return True


@_jit
def _nb_random_walk(x, velocity, spread, noise, moves, lower, upper, bounded):
    """The random walk ``x = x + v + D n`` in place (``n`` the standard normals drawn by numpy; ``D`` per axis), then
    folded into ``[lower, upper]`` by mirror reflection as :func:`~locbook.models.motion.reflect_into_box` does
    (``bounded``)."""
    R, N, d = x.shape
    for r in range(R):
        for i in range(N):
            for k in range(d):
                v = x[r, i, k]
                if moves:
                    v = (v + velocity[k]) + spread[k] * noise[r, i, k]
                else:
                    v = v + velocity[k]
                if bounded:
                    width = upper[k] - lower[k]
                    period = 2.0 * width
                    shifted = v - lower[k]
                    if 0.0 <= shifted < period:     # np.mod(a, b) = a here and a + b just below 0 (fmod is a)
                        folded = shifted
                    elif -period <= shifted < 0.0:
                        folded = shifted + period
                    else:                           # Python's float % is np.mod's rule
                        folded = shifted % period
                    v = lower[k] + (period - folded if folded > width else folded)
                x[r, i, k] = v


@_jit
def _nb_normalise(log_w, logits, dead, w, final, want_final, collapsed):
    """The weight update in place: ``logits = log_w + ll`` (``logits`` holds ``ll`` on entry), its maximum, and
    ``w = exp(logits - max) / sum`` (numpy's ``_normalise_log`` with its pairwise sum). A run whose maximum is NaN
    or infinite and that was not ``dead`` is flagged in ``collapsed``; a dead or collapsed run gets logits 0 (equal
    weights). ``want_final``: ``final = logits - max - log(sum)`` too (the normalised log-weights)."""
    R, N = logits.shape
    for r in range(R):
        top = -np.inf
        bad = False
        for i in range(N):
            v = log_w[r, i] + logits[r, i]
            logits[r, i] = v
            if v != v:
                bad = True
            elif v > top:
                top = v
        if not dead[r] and (bad or math.isinf(top)):
            collapsed[r] = True
        if dead[r] or collapsed[r]:
            for i in range(N):
                logits[r, i] = 0.0
            top = 0.0
        for i in range(N):                # logits - top <= 0 here (NaN and infinite maxima were zeroed above)
            w[r, i] = _exp_nonpositive(logits[r, i] - top)
        total = _pairwise_sum(w[r], 0, N)
        for i in range(N):
            w[r, i] = w[r, i] / total
        if want_final:
            log_total = np.log(total)
            for i in range(N):
                final[r, i] = logits[r, i] - top - log_total


@_jit
def _nb_moments(w, x, mean, cov, best, n_eff):
    """Per run: the weighted mean ``(R, d)`` and covariance ``(R, d, d)`` of the particles (as
    :func:`~locbook.tracking.bayes.weighted_moments`), the highest-weight particle ``(R, d)`` (the first on ties, as
    ``argmax``) and ``N_eff = 1 / sum w^2`` (Arulampalam et al. 2002, Eq. (51)). Positions in the plane (d = 2) take
    a loop with the sums in registers."""
    R, N, d = x.shape
    for r in range(R):
        sq = 0.0
        top = -1.0
        arg = 0
        for i in range(N):
            wi = w[r, i]
            sq += wi * wi
            if wi > top:
                top = wi
                arg = i
        n_eff[r] = 1.0 / sq
        for k in range(d):
            best[r, k] = x[r, arg, k]
        if d == 2:
            m0 = 0.0
            m1 = 0.0
            for i in range(N):
                m0 += w[r, i] * x[r, i, 0]
                m1 += w[r, i] * x[r, i, 1]
            c00 = 0.0
            c01 = 0.0
            c11 = 0.0
            for i in range(N):
                d0 = x[r, i, 0] - m0
                d1 = x[r, i, 1] - m1
                c00 += w[r, i] * d0 * d0
                c01 += w[r, i] * d0 * d1
                c11 += w[r, i] * d1 * d1
            mean[r, 0], mean[r, 1] = m0, m1
            cov[r, 0, 0], cov[r, 0, 1], cov[r, 1, 0], cov[r, 1, 1] = c00, c01, c01, c11
            continue
        for k in range(d):
            mean[r, k] = 0.0
        for i in range(N):
            wi = w[r, i]
            for k in range(d):
                mean[r, k] += wi * x[r, i, k]
        for k in range(d):
            for c in range(d):
                cov[r, k, c] = 0.0
        for i in range(N):
            wi = w[r, i]
            for k in range(d):
                dk = x[r, i, k] - mean[r, k]
                for c in range(k + 1):
                    cov[r, k, c] += wi * dk * (x[r, i, c] - mean[r, c])
        for k in range(d):
            for c in range(k):
                cov[r, c, k] = cov[r, k, c]


@_jit
def _nb_systematic(w, u, do, x, x_out, log_w):
    """Systematic resampling (Arulampalam et al. 2002, Alg. 2) of the runs ``do`` into ``x_out`` (the others are
    copied), then ``log_w = log(max(w, 1e-300))`` with ``w = 1 / N`` where resampled.

    The ancestors are those of :func:`~locbook.tracking.resampling.systematic_resample` (``cdf="standard"``) bit for
    bit: its cumulative sum normalised by its last entry (set to 1), the points ``p_i = (u + i) / N``, both shifted by
    ``2 k`` for the k-th resampled run (its one-call search), and for each point the first ``j`` with ``c_j >= p_i``,
    clipped to ``N - 1``. That ancestor is the number of ``j <= N - 2`` with ``c_j < p_i``, i.e. with ``n_j <= i``
    where ``n_j`` is the number of points ``<= c_j`` (the points increase with ``i``). Each ``n_j`` is found from its
    estimate ``floor(N c_j - u) + 1`` and corrected by comparing the exact points (rarely more than one step), and the
    ancestors are the running sum of a histogram of the ``n_j``: no branch depends on the weights, where a merge of
    the two sorted lists mispredicts about once per particle (3x slower on uneven weights)."""
    R, N, d = x.shape
    k_row = 0
    uniform_log = np.log(max(1.0 / N, 1e-300))
    cdf = np.empty(N)
    points = np.empty(N + 1)
    count = np.empty(N + 1, np.int64)
    for r in range(R):
        if not do[r]:
            for i in range(N):
                for k in range(d):
                    x_out[r, i, k] = x[r, i, k]
                log_w[r, i] = np.log(max(w[r, i], 1e-300))
            continue
        cum = 0.0
        for j in range(N):
            cum += w[r, j]
            cdf[j] = cum
        offset = 2.0 * k_row
        k_row += 1
        for j in range(N - 1):
            cdf[j] = cdf[j] / cum + offset
        cdf[N - 1] = 1.0 + offset
        ur = u[r]
        for i in range(N):
            points[i] = (ur + i) / N + offset
        points[N] = np.inf                              # a sentinel: no count exceeds N
        for i in range(N + 1):
            count[i] = 0
        for j in range(N - 1):                          # the last entry is the largest value: never passed
            c = cdf[j]
            n_j = int((c - offset) * N - ur) + 1
            n_j = min(max(n_j, 0), N)
            while points[n_j] <= c:
                n_j += 1
            while n_j > 0 and points[n_j - 1] > c:
                n_j -= 1
            count[n_j] += 1
        ancestor = 0
        for i in range(N):
            ancestor += count[i]
            for k in range(d):
                x_out[r, i, k] = x[r, ancestor, k]
            log_w[r, i] = uniform_log
