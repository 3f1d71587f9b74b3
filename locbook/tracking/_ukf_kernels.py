"""The compiled UKF kernel (numba), compiled on first call (numba caches the machine code on disk). Imported only by
:func:`locbook.tracking.unscented._compiled_ukf` when the compiled path runs, so that ``import locbook`` never loads
numba. Without numba the functions are plain Python (the same arithmetic, slowly).

The recursion is the numpy UKF's (:func:`locbook.tracking.unscented._ukf_update`; Gudipati 2017, Sec. 3.6, Eqs.
(3.18)-(3.30) corrected, with the Joseph-form covariance update of that module's docstring), run on blocks of ``W``
runs side by side on the innermost axis of every buffer (the lanes: LLVM vectorises the loops over them), like the
compiled EKF of :mod:`locbook.tracking._kernels`. Two savings that do not change a single bit of the result:

- the sigma points are ``x +- (column i of L)`` with ``L`` lower triangular, so column ``i`` is zero above row
  ``i``: a measurement that reads only state components ``<= u`` takes the same value at the points ``i > u`` as at
  the centre (an RSS stream reading x and y: 5 distinct points of 17 at n = 8), and it is evaluated once;
- the cross-covariance ``P_xz = sum_i W_c^i (X^i - x)(Y^i - z^)^T`` is ``L D`` with ``D_i = W_c^1 (dv^i - dv^{n+i})``
  (the numpy UKF's ``_pair_differences``).
"""
from __future__ import annotations

import numpy as np

from .._numba import jit as _jit
from ._kernels import _descending_order

_LOG_2PI = float(np.log(2.0 * np.pi))
_EPS = float(np.finfo(float).eps)
_TEN_OVER_LN10 = 10.0 / float(np.log(10.0))
#: statuses besides 0 (done): the numpy UKF redoes the filter and raises the library's error, or applies the guard
FAIL_P, FAIL_S, FAIL_STATE, FAIL_GUARD, FAIL_ANCHOR = 1, 2, 3, 4, 5
_LINEAR_PARALLEL, _LINEAR_SERIAL, _RSS_PARALLEL, _RSS_SERIAL, _INERTIAL = 0, 1, 2, 3, 4


@_jit
def _nb_chol(A, L, m, W, t):
    """Cholesky ``A = L L^T`` of the ``m x m`` lower triangles of ``A`` lane by lane (``L`` lower, its upper
    triangle zeroed); False when some lane's ``A`` is not positive definite (or not finite)."""
    for j in range(m):
        for w in range(W):
            t[w] = A[j, j, w]
        for k in range(j):
            for w in range(W):
                t[w] -= L[j, k, w] * L[j, k, w]
        bad = 0
        for w in range(W):
            bad += 0 if t[w] > 0.0 else 1
        if bad:
            return False
        for w in range(W):
            L[j, j, w] = np.sqrt(t[w])
        for i in range(j + 1, m):
            for w in range(W):
                t[w] = A[i, j, w]
            for k in range(j):
                for w in range(W):
                    t[w] -= L[i, k, w] * L[j, k, w]
            for w in range(W):
                L[i, j, w] = t[w] / L[j, j, w]
                L[j, i, w] = 0.0
    return True


@_jit
def _nb_clearly_well_conditioned(S, m, rel, A, L, W, t):
    """The numpy UKF's ``_clearly_well_conditioned``: ``S - rel * bound * I`` has a Cholesky factor in every lane
    (``bound`` the largest absolute row sum of ``S``)."""
    for w in range(W):
        t[w] = 0.0
    for r in range(m):
        for w in range(W):
            A[r, 0, w] = 0.0           # row sum (column 0 is overwritten below, after its use)
        for q in range(m):
            for w in range(W):
                A[r, 0, w] += abs(S[r, q, w])
        for w in range(W):
            t[w] = max(t[w], A[r, 0, w])
    for w in range(W):
        t[w] = rel * t[w]
    for r in range(m):
        for q in range(r + 1):
            for w in range(W):
                A[r, q, w] = S[r, q, w] - (t[w] if r == q else 0.0)
    return _nb_chol(A, L, m, W, t)


@_jit
def _nb_predict(Fi, Fj, Fv, Q, x, P, xt, T1, n, W):
    """x = F x, P = (F P) F^T + Q for the lanes, F by its nonzero entries (rows Fi, columns Fj, values Fv), Q per lane
    ``(n, n, W)``; the lower triangle is computed and mirrored. (The EKF kernel's prediction computes the upper
    one. It is not imported from there on purpose: numba's disk cache of this module would not notice a change in
    another file and could keep running the old code.)"""
    for i in range(n):
        for w in range(W):
            xt[i, w] = 0.0
        for c in range(n):
            for w in range(W):
                T1[i, c, w] = 0.0
    for e in range(Fi.shape[0]):
        i, j, v = Fi[e], Fj[e], Fv[e]
        for w in range(W):
            xt[i, w] += v * x[j, w]
        for c in range(n):
            for w in range(W):
                T1[i, c, w] += v * P[j, c, w]
    for i in range(n):
        for w in range(W):
            x[i, w] = xt[i, w]
        for c in range(n):
            for w in range(W):
                P[i, c, w] = 0.0
    for e in range(Fi.shape[0]):                          # (F P) F^T: P[a, i] += T1[a, j] F[i, j], a >= i
        i, j, v = Fi[e], Fj[e], Fv[e]
        for a in range(i, n):
            for w in range(W):
                P[a, i, w] += v * T1[a, j, w]
    for a in range(n):
        for c in range(a + 1):
            for w in range(W):
                P[a, c, w] += Q[a, c, w]
                P[c, a, w] = P[a, c, w]


@_jit
def _nb_h(kd, rows, Xp, Yi, used, nused, Hr, ar, dim, pidx, npos, tag_h, p0r, pler, ref_d, clamp, ib, cs, sn,
          trig, W, lin, rss, ine):
    """The stream's readings ``Yi[:rows]`` at the point ``Xp`` (only its ``used`` components are read). Linear: the
    rows ``Hr`` (their entries at the used components); RSS: the one RSS model's mean,
    :func:`locbook.models.channel.log_distance_mean_dbm` with the clamp (its log10 through ln), at the anchors ``ar``
    (``p0r``, ``pler`` per row and lane); inertial:
    :func:`locbook.models.imu.inertial_measurement_function` (``ib``: body frame, acceleration indices, heading, yaw
    rate), with the heading's cosine and sine in ``cs``, ``sn`` (computed here when ``trig``). False when a point
    lies on an anchor of a channel without a clamp (the mean is infinite there). A kind whose flag (``lin``, ``rss``,
    ``ine``) is None is left out of the compiled code."""
    if lin is not None and kd <= 1:
        for r in range(rows):
            for w in range(W):
                Yi[r, w] = 0.0
            for e in range(nused):
                u = used[e]
                for w in range(W):
                    Yi[r, w] += Hr[r, e, w] * Xp[u, w]
        return True
    if rss is not None and kd <= 3:
        on = 0
        for r in range(rows):
            for w in range(W):
                Yi[r, w] = 0.0                            # the squared distance first
            for a in range(dim):
                if a < npos:
                    pa = pidx[a]
                    for w in range(W):
                        v = Xp[pa, w] - ar[r, a, w]
                        Yi[r, w] += v * v
                else:                                     # the known tag height
                    for w in range(W):
                        v = tag_h - ar[r, a, w]
                        Yi[r, w] += v * v
            if clamp == 0.0:
                for w in range(W):
                    on += 1 if Yi[r, w] == 0.0 else 0
            for w in range(W):
                d = np.sqrt(Yi[r, w])
                if clamp > 0.0:
                    d = max(d, clamp)
                # 10 log10(v) as (10 / ln 10) ln(v): libm's log is twice as fast as its log10 (round-off: an ulp)
                Yi[r, w] = p0r[r, w] - pler[r, w] * (_TEN_OVER_LN10 * np.log(d / ref_d))
        return on == 0
    if ine is None:
        return True
    if ib[0]:
        if trig:
            for w in range(W):
                cs[w] = np.cos(Xp[ib[3], w])
                sn[w] = np.sin(Xp[ib[3], w])
        for w in range(W):
            ax, ay = Xp[ib[1], w], Xp[ib[2], w]
            Yi[0, w] = cs[w] * ax + sn[w] * ay
            Yi[1, w] = -sn[w] * ax + cs[w] * ay
            Yi[2, w] = Xp[ib[4], w]
    else:
        for w in range(W):
            Yi[0, w] = Xp[ib[1], w]
            Yi[1, w] = Xp[ib[2], w]
            Yi[2, w] = Xp[ib[4], w]
    return True


@_jit
def _nb_ukf_update(x, P, n, rows, kd, used, nused, umax, Hr, ar, dim, pidx, npos, tag_h, p0r, pler, ref_d, clamp, ib,
                   zr, valid, Rr, Wm, Wc, c, innovation_noise, buf, Lp, Xp, Y, zh, Pzz, D, S, LS, A2, Pxz, KT, nu, Yn,
                   Mm, Rt, t, t2, cs, sn, nis, hld, floored, W, lin, rss, ine):
    """One unscented update of the lanes in place (the numpy UKF's ``_ukf_update``): sigma points from the Cholesky
    factor of ``c P`` (``c = n + lambda``), readings ``Y`` at them, ``z^ = sum W_m Y``, ``S = sum W_c dv dv^T (+ R)``,
    ``P_xz = L D``, ``K = P_xz S^{-1}`` (Cholesky of S), ``x += K nu``, and the Joseph form ``P = M M^T / c + K R~ K^T``
    with ``M = L - c K D^T``, ``R~ = S - c D^T D``. A missing reading (``valid`` False) has a zero column of D and a
    unit decoupled row of S, so its gain column is zero; a lane without any reading keeps x and P. Adds the NIS
    ``|L_S^{-1} nu|^2`` and half the log-determinant to ``nis``, ``hld``. Returns 0 or a FAIL_ status."""
    m = rows
    N = 2 * n + 1
    for i in range(n):                                    # L L^T = c P
        for j in range(i + 1):
            for w in range(W):
                buf[i, j, w] = c * P[i, j, w]
    if not _nb_chol(buf, Lp, n, W, t):
        return FAIL_P
    for e in range(nused):                                # the centre
        u = used[e]
        for w in range(W):
            Xp[u, w] = x[u, w]
    centre = W > 0                                       # True, typed bool (a literal True would compile _nb_h twice)
    if not _nb_h(kd, m, Xp, Y[0], used, nused, Hr, ar, dim, pidx, npos, tag_h, p0r, pler, ref_d, clamp, ib, cs, sn,
                 centre, W, lin, rss, ine):
        return FAIL_ANCHOR
    hd = ib[3]
    for i in range(n - 1, -1, -1):                        # the pairs x +- column i of L (last first: see trig)
        if i > umax:                                      # column i is zero on every component read
            for r in range(m):
                for w in range(W):
                    Y[1 + i, r, w] = Y[0, r, w]
                    Y[1 + n + i, r, w] = Y[0, r, w]
            continue
        # column i > heading index: the heading is the centre's, whose cos and sin are still in cs, sn
        trig = kd != _INERTIAL or i <= hd
        for sgn in range(2):
            k = 1 + i + sgn * n
            for e in range(nused):
                u = used[e]
                if sgn == 0:
                    for w in range(W):
                        Xp[u, w] = x[u, w] + Lp[u, i, w]
                else:
                    for w in range(W):
                        Xp[u, w] = x[u, w] - Lp[u, i, w]
            if not _nb_h(kd, m, Xp, Y[k], used, nused, Hr, ar, dim, pidx, npos, tag_h, p0r, pler, ref_d, clamp, ib,
                         cs, sn, trig, W, lin, rss, ine):
                return FAIL_ANCHOR
    for r in range(m):                                    # z^ = sum W_m Y (Eq. (3.25)), dv = Y - z^
        for w in range(W):
            zh[r, w] = 0.0
        for k in range(N):
            for w in range(W):
                zh[r, w] += Wm[k] * Y[k, r, w]
        for k in range(N):
            for w in range(W):
                Y[k, r, w] -= zh[r, w]
    for r in range(m):                                    # P_zz = sum W_c dv dv^T (Eq. (3.26)), lower triangle
        for q in range(r + 1):
            for w in range(W):
                Pzz[r, q, w] = 0.0
            for k in range(N):
                for w in range(W):
                    Pzz[r, q, w] += Wc[k] * Y[k, r, w] * Y[k, q, w]
    w1 = Wc[1]
    for w in range(W):
        t2[w] = 0.0                                       # 1 where the lane has a reading
    for r in range(m):
        for w in range(W):
            if valid[r, w]:
                t2[w] = 1.0
    for i in range(n):                                    # D (the pair differences), zero columns where missing
        for r in range(m):
            for w in range(W):
                D[i, r, w] = w1 * (Y[1 + i, r, w] - Y[1 + n + i, r, w]) if valid[r, w] else 0.0
    for r in range(m):                                    # S = P_zz + R; unit decoupled rows where missing
        for q in range(r + 1):
            for w in range(W):
                if valid[r, w] and valid[q, w]:
                    v = Pzz[r, q, w] + (Rr[r, q, w] if innovation_noise else 0.0)
                else:
                    v = 1.0 if r == q else 0.0
                S[r, q, w] = v
                S[q, r, w] = v
    if m > 2 and not _nb_clearly_well_conditioned(S, m, 2e3 * m * _EPS, A2, LS, W, t):
        return FAIL_S                                     # numpy decides with the eigenvalues
    for r in range(m):
        for q in range(r + 1):
            for w in range(W):
                A2[r, q, w] = S[r, q, w]
    if not _nb_chol(A2, LS, m, W, t):
        return FAIL_S
    for a in range(n):                                    # P_xz = L D
        for r in range(m):
            for w in range(W):
                Pxz[a, r, w] = 0.0
            for b in range(a + 1):
                for w in range(W):
                    Pxz[a, r, w] += Lp[a, b, w] * D[b, r, w]
    for r in range(m):                                    # innovation, and the NIS |L_S^{-1} nu|^2
        for w in range(W):
            nu[r, w] = zr[r, w] - zh[r, w] if valid[r, w] else 0.0
    for r in range(m):
        for w in range(W):
            Yn[r, w] = nu[r, w]
        for q in range(r):
            for w in range(W):
                Yn[r, w] -= LS[r, q, w] * Yn[q, w]
        for w in range(W):
            Yn[r, w] /= LS[r, r, w]
            if t2[w] > 0.0:
                nis[w] += Yn[r, w] * Yn[r, w]
                hld[w] += np.log(LS[r, r, w])
    for a in range(n):                                    # K^T = S^{-1} P_xz^T (column a of K^T)
        for r in range(m):
            for w in range(W):
                KT[r, a, w] = Pxz[a, r, w]
            for q in range(r):
                for w in range(W):
                    KT[r, a, w] -= LS[r, q, w] * KT[q, a, w]
            for w in range(W):
                KT[r, a, w] /= LS[r, r, w]
        for r in range(m - 1, -1, -1):
            for q in range(r + 1, m):
                for w in range(W):
                    KT[r, a, w] -= LS[q, r, w] * KT[q, a, w]
            for w in range(W):
                KT[r, a, w] /= LS[r, r, w]
    bad = 0
    for a in range(n):                                    # x+ = x + K nu (kept where no reading)
        for w in range(W):
            t[w] = 0.0
        for r in range(m):
            for w in range(W):
                t[w] += KT[r, a, w] * nu[r, w]
        for w in range(W):
            v = x[a, w] + t[w]
            bad += 0 if np.isfinite(v) else 1
            if t2[w] > 0.0:
                x[a, w] = v
    if bad:
        return FAIL_STATE
    for r in range(m):                                    # R~ = S - c D^T D, lower triangle
        for q in range(r + 1):
            for w in range(W):
                t[w] = 0.0
            for i in range(n):
                for w in range(W):
                    t[w] += D[i, r, w] * D[i, q, w]
            for w in range(W):
                v = S[r, q, w] - c * t[w]
                Rt[r, q, w] = v
                Rt[q, r, w] = v
    if m == 1:                                            # the guard: R~ floored at 0
        for w in range(W):
            if Rt[0, 0, w] < 0.0 or not np.isfinite(Rt[0, 0, w]):
                if not Rt[0, 0, w] < 0.0:
                    return FAIL_GUARD
                Rt[0, 0, w] = 0.0
                if t2[w] > 0.0:
                    floored[w] += 1
    elif not _nb_clearly_well_conditioned(Rt, m, 1e3 * m * _EPS, A2, LS, W, t):
        return FAIL_GUARD                                 # numpy floors its eigenvalues
    for a in range(n):                                    # M = L - c K D^T
        for b in range(n):
            for w in range(W):
                t[w] = 0.0
            for r in range(m):
                for w in range(W):
                    t[w] += KT[r, a, w] * D[b, r, w]
            for w in range(W):
                Mm[a, b, w] = (Lp[a, b, w] if b <= a else 0.0) - c * t[w]
    for a in range(n):                                    # G = R~ K^T (into buf rows 0..m-1)
        for r in range(m):
            for w in range(W):
                buf[r, a, w] = 0.0
            for q in range(m):
                for w in range(W):
                    buf[r, a, w] += Rt[r, q, w] * KT[q, a, w]
    for a in range(n):                                    # P+ = M M^T / c + K R~ K^T, lower triangle mirrored
        for b in range(a + 1):
            for w in range(W):
                t[w] = 0.0
            for e in range(n):
                for w in range(W):
                    t[w] += Mm[a, e, w] * Mm[b, e, w]
            for w in range(W):
                t[w] /= c
            for r in range(m):
                for w in range(W):
                    t[w] += KT[r, a, w] * buf[r, b, w]
            for w in range(W):
                if t2[w] > 0.0:
                    P[a, b, w] = t[w]
                    P[b, a, w] = t[w]
    return 0


@_jit
def _nb_ukf(Fi, Fj, Fv, Q, x0, P0, predict_first, slot, active, kind, col, nz, nnz, Z, H, R, A, P0c, PLE, SIG, dims,
            ref_d, clamp, anchor_sigma, tag_h, pidx, npos, descending, iner, umax, Wm, Wc, c, innovation_noise, W,
            out_x, out_P, out_nis, out_dof, out_ll, out_floored, lin, rss, ine):
    """The UKF time loop of :func:`locbook.tracking._loop._run` with the numpy UKF's updates (serial streams one
    reading at a time, each with fresh sigma points; serial RSS in descending order of RSS when asked), over blocks of
    ``W`` runs (the last block padded with copies of the last run); each run's NIS, dof and log-likelihood at every
    step and its number of floored updates. Returns ``(status, block start)``: status 0, or a FAIL_ code (the caller
    then redoes the filter in numpy, which raises the library's error or applies the eigenvalue guard). ``lin``,
    ``rss``, ``ine``: the kinds present, as for :func:`locbook.tracking._kernels._nb_ekf`."""
    B, T, n, ns = Z.shape[0], Z.shape[1], x0.shape[1], kind.shape[0]
    N = 2 * n + 1
    mmax = 1
    for s in range(ns):
        mmax = max(mmax, col[s + 1] - col[s])
    x, xt = np.empty((n, W)), np.empty((n, W))
    P, T1 = np.empty((n, n, W)), np.empty((n, n, W))
    buf, Lp, Mm = np.zeros((max(n, mmax), n, W)), np.zeros((n, n, W)), np.empty((n, n, W))
    Xp, Y = np.zeros((n, W)), np.empty((N, mmax, W))
    zh, nu, Yn, zr = np.empty((mmax, W)), np.empty((mmax, W)), np.empty((mmax, W)), np.empty((mmax, W))
    Pzz, S, LS = np.empty((mmax, mmax, W)), np.empty((mmax, mmax, W)), np.zeros((mmax, mmax, W))
    A2, Rt, Rr = np.zeros((mmax, mmax, W)), np.empty((mmax, mmax, W)), np.zeros((mmax, mmax, W))
    D, Pxz, KT = np.empty((n, mmax, W)), np.empty((n, mmax, W)), np.empty((mmax, n, W))
    Hr, ar = np.zeros((mmax, n, W)), np.zeros((mmax, 3, W))
    p0r, pler, var, key = np.zeros((mmax, W)), np.zeros((mmax, W)), np.ones((mmax, W)), np.empty((mmax, W))
    t, t2, cs, sn = np.empty(W), np.empty(W), np.empty(W), np.empty(W)
    nis, hld, floored = np.zeros(W), np.zeros(W), np.zeros(W, np.int64)
    dof = np.zeros(W, np.int64)
    valid = np.zeros((mmax, W), np.bool_)
    sel = np.empty((mmax, W), np.int64)
    run = np.empty(W, np.int64)
    Qw = np.empty((n, n, W))
    for b0 in range(0, B, W):
        for w in range(W):
            b = min(b0 + w, B - 1)
            run[w] = b
            floored[w] = 0
            for i in range(n):
                x[i, w] = x0[b, i]
                for j in range(n):
                    P[i, j, w] = P0[min(b, P0.shape[0] - 1), i, j]
                    Qw[i, j, w] = Q[min(b, Q.shape[0] - 1), i, j]
        for k in range(T):
            if predict_first or k > 0:
                _nb_predict(Fi, Fj, Fv, Qw, x, P, xt, T1, n, W)
            for w in range(W):
                nis[w] = 0.0
                hld[w] = 0.0
                dof[w] = 0
            ta = min(k, A.shape[1] - 1)
            for s in range(ns):
                if not active[s, k]:                      # no reading of this stream at this step in any run
                    continue
                c0, m, kd = col[s], col[s + 1] - col[s], kind[s]
                serial = kd == _LINEAR_SERIAL or kd == _RSS_SERIAL
                if kd == _RSS_SERIAL and descending[s]:   # the update order: by descending RSS, or as given
                    _descending_order(Z, run, k, c0, m, sel, key)
                else:
                    for w in range(W):
                        for j in range(m):
                            sel[j, w] = j
                for u in range(m if serial else 1):       # serial: one scalar update per reading
                    rows = 1 if serial else m
                    present = 0
                    for r in range(rows):
                        for w in range(W):
                            b = run[w]
                            j = sel[u, w] if serial else r
                            zj = Z[b, k, c0 + j]
                            valid[r, w] = np.isfinite(zj)
                            zr[r, w] = zj
                            if valid[r, w]:
                                present += 1
                                dof[w] += 1
                            if kd <= _LINEAR_SERIAL or kd == _INERTIAL:
                                bh, th = min(b, H.shape[0] - 1), min(k, H.shape[1] - 1)
                                for e in range(nnz[s]):
                                    Hr[r, e, w] = H[bh, th, c0 + j, nz[s, e]]
                            else:
                                bc = min(b, P0c.shape[0] - 1)
                                ba = min(b, A.shape[0] - 1)
                                for a in range(dims[s]):
                                    ar[r, a, w] = A[ba, ta, c0 + j, a]
                                p0r[r, w] = P0c[bc, c0 + j]
                                pler[r, w] = PLE[bc, c0 + j]
                                # the variance at the state updated so far (the numpy UKF's _rss_noise)
                                sg = SIG[bc, c0 + j]
                                v = sg * sg
                                if anchor_sigma[s] > 0.0:
                                    d2 = 0.0
                                    for a in range(dims[s]):
                                        q = (x[pidx[s, a], w] if a < npos[s] else tag_h[s]) - ar[r, a, w]
                                        d2 += q * q
                                    d = np.sqrt(d2)
                                    if not d < clamp[s]:
                                        g = 10.0 * pler[r, w] / np.log(10.0) * anchor_sigma[s] / max(d, clamp[s])
                                        v += g * g
                                var[r, w] = v
                    if present == 0:
                        continue
                    for r in range(rows):                 # R of the readings (only the present ones are read)
                        for q in range(rows):
                            for w in range(W):
                                if kd <= _LINEAR_SERIAL or kd == _INERTIAL:
                                    jr = sel[u, w] if serial else r
                                    jq = sel[u, w] if serial else q
                                    Rr[r, q, w] = R[min(run[w], R.shape[0] - 1), min(k, R.shape[1] - 1), c0 + jr,
                                                    c0 + jq]
                                else:
                                    Rr[r, q, w] = var[r, w] if r == q else 0.0
                    status = _nb_ukf_update(x, P, n, rows, kd, nz[s], nnz[s], umax[s], Hr, ar, dims[s], pidx[s],
                                            npos[s], tag_h[s], p0r, pler, ref_d[s], clamp[s], iner[s], zr, valid, Rr,
                                            Wm, Wc, c, innovation_noise, buf, Lp, Xp, Y, zh, Pzz, D, S, LS, A2, Pxz,
                                            KT, nu, Yn, Mm, Rt, t, t2, cs, sn, nis, hld, floored, W, lin, rss, ine)
                    if status:
                        return status, b0
            for w in range(W):                            # a state or covariance that overflowed: numpy names it
                t[w] = 0.0                                # (v - v is NaN exactly when v is not finite)
            for i in range(n):
                for w in range(W):
                    t[w] += x[i, w] - x[i, w]
                for j in range(i, n):
                    for w in range(W):
                        t[w] += P[i, j, w] - P[i, j, w]
            for w in range(W):
                if not t[w] == 0.0:
                    return FAIL_STATE, b0
            for w in range(min(W, B - b0)):
                out_nis[b0 + w, k] = nis[w] if dof[w] > 0 else np.nan
                # log N(nu; 0, S) summed over the step's updates: -(NIS + log det S + dof log 2 pi) / 2
                out_ll[b0 + w, k] = -0.5 * (nis[w] + 2.0 * hld[w] + dof[w] * _LOG_2PI) if dof[w] > 0 else np.nan
                out_dof[b0 + w, k] = dof[w]
            if slot[k] >= 0:
                for w in range(min(W, B - b0)):
                    for i in range(n):
                        out_x[b0 + w, slot[k], i] = x[i, w]
                        for j in range(n):
                            out_P[b0 + w, slot[k], i, j] = P[i, j, w]
        for w in range(min(W, B - b0)):
            out_floored[b0 + w] = floored[w]
    return 0, 0
