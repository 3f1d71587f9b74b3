"""The compiled EKF kernels (numba), module-level functions compiled on first call (numba caches the machine code on
disk). Imported only by :func:`locbook.tracking._compiled._compiled_ekf` when the compiled path runs, so that
``import locbook`` never loads numba. Without numba they are plain Python (the same arithmetic, slowly: the tests
run them that way). Each kernel works on ``W`` runs at once on the innermost axis (the last axis of its arrays):
``_LANES`` runs, or all of them when there are fewer (a small batch pays for its own runs only)."""
from __future__ import annotations

import numpy as np

from .._numba import jit as _jit
from ._vecmath import _log_positive

_LANES = 64     # runs per block of the compiled EKF: the innermost axis, long enough for LLVM to vectorise it
_LOG_2PI = float(np.log(2.0 * np.pi))
_INERTIAL = 4   # the inertial stream's kind (= _compiled._INERTIAL); 0-3: linear and RSS, parallel and serial


@_jit
def _nb_predict(Fi, Fj, Fv, Q, x, P, xt, T1):
    """x = F x, P = (F P) F^T + Q in place for the lanes (last axis), F given by its nonzero entries (rows Fi,
    columns Fj, values Fv), Q per lane ``(n, n, W)``; P symmetric in, symmetric out (the upper triangle is computed and
    mirrored)."""
    n, W = x.shape
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
        for c in range(i + 1):
            for w in range(W):
                P[c, i, w] = 0.0
    for e in range(Fi.shape[0]):                          # (F P) F^T, upper triangle: P[a, i] for a <= i
        i, j, v = Fi[e], Fj[e], Fv[e]
        for a in range(i + 1):
            for w in range(W):
                P[a, i, w] += v * T1[a, j, w]
    for a in range(n):
        for c in range(a, n):
            for w in range(W):
                P[a, c, w] += Q[a, c, w]
                P[c, a, w] = P[a, c, w]


@_jit
def _nb_update(x, P, c, nz, nnz, H, nu, R, HP, HPH, S, L, KT, PH, D, t, u, Y, nis, hld):
    """Kalman update in place, lane by lane (last axis), with the rows ``H[:c]`` (nonzero only in the columns
    ``nz[:nnz]``), innovations ``nu[:c]`` and noise ``R[:c, :c]``; a missing reading is a zero row with zero
    innovation and unit decoupled noise (its gain column is then exactly zero). K = P H^T S^{-1} (Cholesky of
    S = H P H^T + R), x += K nu, and the Joseph form (I - K H) P (I - K H)^T + K R K^T written as
    P - K (H P) + (K S - P H^T) K^T (equal for any K), its upper triangle computed and mirrored (exactly symmetric).
    Adds each lane's NIS nu^T S^{-1} nu = |L^{-1} nu|^2 to ``nis`` and half its log-determinant, sum log L_jj, to
    ``hld`` (a missing row adds 0 to both). False when some S is not positive definite or some state not finite.
    ``u`` is scratch space the caller provides (unused since the update computes one triangle)."""
    n, W = x.shape
    for r in range(c):                                    # HP = H P, PH = P H^T
        for j in range(n):
            for w in range(W):
                HP[r, j, w] = 0.0
                PH[j, r, w] = 0.0
        for e in range(nnz):
            i = nz[e]
            for j in range(n):
                for w in range(W):
                    HP[r, j, w] += H[r, i, w] * P[i, j, w]
                    PH[j, r, w] += P[j, i, w] * H[r, i, w]
    for r in range(c):                                    # S = H P H^T + R
        for q in range(c):
            for w in range(W):
                HPH[r, q, w] = 0.0
            for e in range(nnz):
                j = nz[e]
                for w in range(W):
                    HPH[r, q, w] += HP[r, j, w] * H[q, j, w]
            for w in range(W):
                S[r, q, w] = HPH[r, q, w] + R[r, q, w]
    for j in range(c):                                    # S = L L^T
        for w in range(W):
            t[w] = S[j, j, w]
        for i in range(j):
            for w in range(W):
                t[w] -= L[j, i, w] * L[j, i, w]
        good = True
        for w in range(W):
            good &= t[w] > 0.0
        if not good:
            return False
        for w in range(W):                                # L_jj > 0 and normal (t > 0): the vectorised log's domain,
            L[j, j, w] = np.sqrt(t[w])                   # but for an infinite one (lane by lane: a select)
            hld[w] += _log_positive(L[j, j, w]) if L[j, j, w] < np.inf else np.inf
        for i in range(j + 1, c):
            for w in range(W):
                t[w] = S[i, j, w]
            for q in range(j):
                for w in range(W):
                    t[w] -= L[i, q, w] * L[j, q, w]
            for w in range(W):
                L[i, j, w] = t[w] / L[j, j, w]
    for i in range(c):                                    # NIS = |Y|^2, L Y = nu (forward substitution)
        for w in range(W):
            Y[i, w] = nu[i, w]
        for q in range(i):
            for w in range(W):
                Y[i, w] -= L[i, q, w] * Y[q, w]
        for w in range(W):
            Y[i, w] /= L[i, i, w]
            nis[w] += Y[i, w] * Y[i, w]
    for j in range(n):                                    # K^T = S^{-1} H P
        for i in range(c):
            for w in range(W):
                KT[i, j, w] = HP[i, j, w]
            for q in range(i):
                for w in range(W):
                    KT[i, j, w] -= L[i, q, w] * KT[q, j, w]
            for w in range(W):
                KT[i, j, w] /= L[i, i, w]
        for i in range(c - 1, -1, -1):
            for q in range(i + 1, c):
                for w in range(W):
                    KT[i, j, w] -= L[q, i, w] * KT[q, j, w]
            for w in range(W):
                KT[i, j, w] /= L[i, i, w]
    good = True
    for i in range(n):                                    # x += K nu
        for w in range(W):
            t[w] = 0.0
        for r in range(c):
            for w in range(W):
                t[w] += KT[r, i, w] * nu[r, w]
        for w in range(W):
            x[i, w] += t[w]
            good &= x[i, w] - x[i, w] == 0.0
    if not good:
        return False
    for i in range(n):                                    # D = K S - P H^T
        for r in range(c):
            for w in range(W):
                D[i, r, w] = -PH[i, r, w]
            for q in range(c):
                for w in range(W):
                    D[i, r, w] += KT[q, i, w] * S[q, r, w]
    for i in range(n):                                    # P - K (H P) + D K^T: the upper triangle, mirrored
        for j in range(i, n):
            for w in range(W):
                t[w] = P[i, j, w]
            for r in range(c):
                for w in range(W):
                    t[w] += D[i, r, w] * KT[r, j, w] - KT[r, i, w] * HP[r, j, w]
            for w in range(W):
                P[i, j, w] = t[w]
                P[j, i, w] = t[w]
    return True


@_jit
def _nb_rss_row(x, w, pidx, npos, tag_h, anchor, p0, ple, sigma, ref_d, clamp, anchor_sigma, z):
    """One RSS reading of lane ``w`` linearised at its state: (innovation z - h(x), variance, the Jacobian's entries
    at the ``npos`` position indices). The one RSS model's formula (:func:`locbook.models.rss.rss_mean_jacobian`, as
    :func:`locbook.tracking.streams._rss_parallel_update` and ``_rss_serial_update`` evaluate it), compiled:
    ``h = P_0 - 10 n log10(max(d, clamp) / d0)``, ``dh/dp = -(10 n / ln 10) (p - a) / d^2`` outside the clamp and 0
    within it (``d^2 < clamp^2``, where h is flat), variance ``sigma^2 + anchor_sigma^2 |dh/dp|^2``
    (:meth:`locbook.tracking.streams.RssMeasurement.variance_db2`); ``clamp`` the stream's ``clamp_m``."""
    d2 = 0.0
    for i in range(anchor.shape[0]):
        u = (x[pidx[i], w] if i < npos else tag_h) - anchor[i]
        d2 += u * u
    slope = 10.0 * ple / np.log(10.0)
    inside = d2 < clamp * clamp
    g0 = 0.0 if inside else -(slope / d2) * (x[pidx[0], w] - anchor[0])
    g1 = -(slope / d2) * (x[pidx[1], w] - anchor[1]) if npos > 1 and not inside else 0.0
    g2 = -(slope / d2) * (x[pidx[2], w] - anchor[2]) if npos > 2 and not inside else 0.0
    d = np.sqrt(d2)
    dh = d if d > clamp else clamp
    h = p0 - 10.0 * ple * np.log10(dh / ref_d)
    var = sigma * sigma
    if anchor_sigma > 0.0 and not inside:
        u = slope * anchor_sigma / d
        var += u * u
    return z - h, var, g0, g1, g2


@_jit
def _nb_inertial_row(x, w, j, spec, z, Hrow):
    """Reading ``j`` of the inertial stream for lane ``w``: writes the Jacobian's row into ``Hrow[:, w]`` (its four
    columns; the caller zeroed them) and returns the innovation ``z - h_j(x)``. The model of
    :func:`locbook.models.imu.inertial_measurement_function` and its Jacobian
    :func:`locbook.models.imu.inertial_measurement_jacobian`: body-frame acceleration ``R(psi)^T a`` (``spec[0]`` 1) or
    ``a`` (world frame), then the yaw rate; ``spec`` = (body, acceleration indices, heading, yaw rate)."""
    a0i, a1i, hd, yr = spec[1], spec[2], spec[3], spec[4]
    if j == 2:
        Hrow[yr, w] = 1.0
        return z - x[yr, w]
    a0, a1 = x[a0i, w], x[a1i, w]
    if spec[0] == 0:
        Hrow[a0i if j == 0 else a1i, w] = 1.0
        return z - (a0 if j == 0 else a1)
    c, sn = np.cos(x[hd, w]), np.sin(x[hd, w])
    if j == 0:                                            # [c s; -s c] a, and d/dpsi
        Hrow[a0i, w], Hrow[a1i, w], Hrow[hd, w] = c, sn, -sn * a0 + c * a1
        return z - (c * a0 + sn * a1)
    Hrow[a0i, w], Hrow[a1i, w], Hrow[hd, w] = -sn, c, -c * a0 - sn * a1
    return z - (-sn * a0 + c * a1)


@_jit
def _nb_ekf(Fi, Fj, Fv, Q, x0, P0, predict_first, slot, active, kind, col, nz, nnz, Z, H, R, A, P0c, PLE, SIG, dims,
            ref_d, clamp, anchor_sigma, tag_h, pidx, npos, descending, iner, out_x, out_P, out_nis, out_dof,
            out_ll):
    """The EKF time loop of :func:`locbook.tracking._loop._run` with :func:`locbook.tracking.streams._ekf_update`, over
    blocks of ``W = min(_LANES, B)`` runs (the last block padded with copies of the last run), with each run's NIS, its dof and
    log-likelihood at every step (``out_nis``, ``out_dof``, ``out_ll`` ``(B, T)``; NaN, 0 and NaN where no update).
    Stream kinds: 0/1 linear parallel/serial, 2/3 RSS parallel/serial, 4 inertial (parallel, :func:`_nb_inertial_row`
    with the parameters ``iner[s]``). Returns 0, or 1 + a run whose update failed (the caller then redoes the filter in
    numpy, which raises the library's error)."""
    B, T, n, ns = Z.shape[0], Z.shape[1], x0.shape[1], kind.shape[0]
    W = min(_LANES, B)
    mmax = 1
    for s in range(ns):
        mmax = max(mmax, col[s + 1] - col[s])
    x, xt = np.empty((n, W)), np.empty((n, W))
    P, T1 = np.empty((n, n, W)), np.empty((n, n, W))
    Hr, HP, KT = np.zeros((mmax, n, W)), np.empty((mmax, n, W)), np.empty((mmax, n, W))
    nu, var, key = np.empty((mmax, W)), np.empty((mmax, W)), np.empty((mmax, W))
    Rr, S, L = np.zeros((mmax, mmax, W)), np.empty((mmax, mmax, W)), np.zeros((mmax, mmax, W))
    HPH, PH, D = np.empty((mmax, mmax, W)), np.empty((n, mmax, W)), np.empty((n, mmax, W))
    t, t2 = np.empty(W), np.empty(W)
    Y, nis, dof = np.empty((mmax, W)), np.zeros(W), np.zeros(W, np.int64)
    hld = np.zeros(W)
    valid = np.zeros((mmax, W), np.bool_)
    sel = np.empty((mmax, W), np.int64)
    run = np.empty(W, np.int64)
    Qw = np.empty((n, n, W))
    qacc = np.empty((mmax, W))
    for b0 in range(0, B, W):
        for w in range(W):
            b = min(b0 + w, B - 1)
            run[w] = b
            for i in range(n):
                x[i, w] = x0[b, i]
                for j in range(n):
                    P[i, j, w] = P0[min(b, P0.shape[0] - 1), i, j]
                    Qw[i, j, w] = Q[min(b, Q.shape[0] - 1), i, j]
        for k in range(T):
            if predict_first or k > 0:
                _nb_predict(Fi, Fj, Fv, Qw, x, P, xt, T1)
            for w in range(W):
                nis[w] = 0.0
                hld[w] = 0.0
                dof[w] = 0
            ta = min(k, A.shape[1] - 1)
            for s in range(ns):
                if not active[s, k]:                      # no reading of this stream at this step in any run
                    continue
                c0, m, kd = col[s], col[s + 1] - col[s], kind[s]
                serial = kd == 1 or kd == 3
                for w in range(W):                   # the update order: as given, or by descending RSS
                    for j in range(m):
                        sel[j, w] = j
                    if kd == 3 and descending[s]:         # stable: ties (and the missing, last) keep their order
                        for j in range(m):
                            zj = Z[run[w], k, c0 + j]
                            key[j, w] = zj if np.isfinite(zj) else -np.inf
                        for j in range(1, m):
                            i = j
                            while i > 0 and key[sel[i - 1, w], w] < key[sel[i, w], w]:
                                sel[i - 1, w], sel[i, w] = sel[i, w], sel[i - 1, w]
                                i -= 1
                for u in range(m if serial else 1):       # serial: one scalar update per reading
                    rows = 1 if serial else m
                    present = False
                    if kd <= 1:                           # linear rows: no branch per lane (selects vectorise)
                        th, hb = min(k, H.shape[1] - 1), H.shape[0]
                        for r in range(rows):
                            j = u if serial else r
                            for w in range(W):
                                qacc[r, w] = 0.0
                            for e in range(nnz[s]):
                                col_e = nz[s, e]
                                for w in range(W):
                                    h = H[min(run[w], hb - 1), th, c0 + j, col_e]
                                    Hr[r, col_e, w] = h
                                    qacc[r, w] += h * x[col_e, w]
                            for w in range(W):
                                zj = Z[run[w], k, c0 + j]
                                ok = zj - zj == 0.0               # finite
                                valid[r, w] = ok
                                nu[r, w] = zj - qacc[r, w] if ok else 0.0
                                var[r, w] = 1.0
                                dof[w] += ok
                                present |= ok
                            for e in range(nnz[s]):
                                col_e = nz[s, e]
                                for w in range(W):
                                    Hr[r, col_e, w] = Hr[r, col_e, w] if valid[r, w] else 0.0
                    for r in range(rows if kd > 1 else 0):   # RSS and inertial rows, lane by lane
                        for w in range(W):
                            b = run[w]
                            j = sel[u, w] if serial else r
                            zj = Z[b, k, c0 + j]
                            valid[r, w] = np.isfinite(zj)
                            for e in range(nnz[s]):
                                Hr[r, nz[s, e], w] = 0.0
                            nu[r, w] = 0.0
                            var[r, w] = 1.0
                            if not valid[r, w]:
                                continue
                            present = True
                            dof[w] += 1
                            if kd == _INERTIAL:
                                nu[r, w] = _nb_inertial_row(x, w, j, iner[s], zj, Hr[r])
                            else:                                 # RSS (linear rows were built above)
                                bc = min(b, P0c.shape[0] - 1)
                                nu[r, w], var[r, w], g0, g1, g2 = _nb_rss_row(
                                    x, w, pidx[s], npos[s], tag_h[s], A[min(b, A.shape[0] - 1), ta, c0 + j, :dims[s]],
                                    P0c[bc, c0 + j], PLE[bc, c0 + j], SIG[bc, c0 + j], ref_d[s], clamp[s],
                                    anchor_sigma[s], zj)
                                Hr[r, pidx[s, 0], w] = g0
                                if npos[s] > 1:
                                    Hr[r, pidx[s, 1], w] = g1
                                if npos[s] > 2:
                                    Hr[r, pidx[s, 2], w] = g2
                    if not present:
                        continue
                    for r in range(rows):                 # R of the readings present, unit decoupled noise elsewhere
                        for q in range(rows):
                            if kd <= 1 or kd == _INERTIAL:    # (the order is the given one: sel is the identity)
                                jr, jq = (u, u) if serial else (r, q)
                                tr, rb = min(k, R.shape[1] - 1), R.shape[0]
                                for w in range(W):
                                    Rr[r, q, w] = R[min(run[w], rb - 1), tr, c0 + jr, c0 + jq] \
                                        if valid[r, w] and valid[q, w] else (1.0 if r == q else 0.0)
                                continue
                            for w in range(W):                # RSS: var is 1 where a reading is missing
                                Rr[r, q, w] = var[r, w] if r == q else 0.0
                    if not _nb_update(x, P, rows, nz[s], nnz[s], Hr, nu, Rr, HP, HPH, S, L, KT, PH, D, t, t2, Y, nis,
                                      hld):
                        return b0 + 1
            for w in range(W):                       # a state or covariance that overflowed: numpy names it
                t[w] = 0.0                                # (v - v is NaN exactly when v is not finite)
            for i in range(n):
                for w in range(W):
                    t[w] += x[i, w] - x[i, w]
                for j in range(i, n):
                    for w in range(W):
                        t[w] += P[i, j, w] - P[i, j, w]
            for w in range(W):
                if not t[w] == 0.0:
                    return b0 + 1
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
    return 0
