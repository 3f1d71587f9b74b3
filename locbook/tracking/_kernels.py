"""The compiled EKF kernels (numba), module-level functions compiled on first call (numba caches the machine code on
disk), with the serial RSS order the UKF kernels share. Imported only when a compiled path
runs (:func:`locbook.tracking._compiled._compiled_ekf`, the UKF kernels), so that ``import locbook`` never loads
numba. Without numba they are plain Python (the same arithmetic, slowly: the tests run them that way). Each kernel
works on ``W`` runs at once on the innermost axis (the last axis of its arrays): blocks of equal width up to 256 runs
(:func:`locbook.tracking._compiled._block_width`), or all of them when there are fewer (a small batch pays for its own
runs only)."""
from __future__ import annotations

import numpy as np

from .._numba import jit as _jit
from ._vecmath import _log10_block, _log_positive

# the filter's arithmetic may fuse a * b + c into one multiply-add (one rounding instead of two: the results agree
# with the numpy loop's to round-off, as before), faster where the CPU has FMA (docs/speed.md; a no-op without)
_jit_fma = _jit(contract=True)
_LOG_2PI = float(np.log(2.0 * np.pi))
_LN_10 = float(np.log(10.0))
_INERTIAL = 4   # the inertial stream's kind (= _compiled._INERTIAL); 0-3: linear and RSS, parallel and serial


@_jit_fma
def _nb_predict(Fi, Fj, Fv, row, Q, Qw, x, P, xt, T1):
    """x = F x, P = (F P) F^T + Q in place for the lanes (last axis), F given by its nonzero entries (rows Fi,
    columns Fj, values Fv, row by row as ``np.nonzero`` gives them; ``row[i]`` True where row i has one), Q
    ``(n, n)`` the same for every lane when ``Qw`` is empty, else ``Qw`` per lane ``(n, n, W)``; P symmetric in,
    symmetric out (the upper triangle is computed and mirrored)."""
    n, W = x.shape
    # each sum over a row of F starts from its first term (F's entries come row by row, np.nonzero's order), so that
    # no array is zeroed first: numba turns a zeroing loop into a call to memset, a fixed cost per row of lanes
    for e in range(Fi.shape[0]):                          # xt = F x, T1 = F P
        i, j, v = Fi[e], Fj[e], Fv[e]
        if e == 0 or Fi[e - 1] != i:
            for w in range(W):
                xt[i, w] = v * x[j, w]
            for c in range(n):
                for w in range(W):
                    T1[i, c, w] = v * P[j, c, w]
            continue
        for w in range(W):
            xt[i, w] += v * x[j, w]
        for c in range(n):
            for w in range(W):
                T1[i, c, w] += v * P[j, c, w]
    for i in range(n):                                    # a row of F without a nonzero: zeros (F P's row i is read
        if not row[i]:                                    # below for every column of F after it)
            for w in range(W):
                xt[i, w] = 0.0
            for c in range(n):
                for w in range(W):
                    T1[i, c, w] = 0.0
    for e in range(Fi.shape[0]):                          # (F P) F^T, upper triangle: P[a, i] for a <= i
        i, j, v = Fi[e], Fj[e], Fv[e]
        if e == 0 or Fi[e - 1] != i:
            for a in range(i + 1):
                for w in range(W):
                    P[a, i, w] = v * T1[a, j, w]
            continue
        for a in range(i + 1):
            for w in range(W):
                P[a, i, w] += v * T1[a, j, w]
    for i in range(n):
        if not row[i]:                                    # its column of (F P) F^T: zeros
            for a in range(i + 1):
                for w in range(W):
                    P[a, i, w] = 0.0
        for w in range(W):
            x[i, w] = xt[i, w]
    for a in range(n):
        for c in range(a, n):
            if Qw.shape[2] == 0:
                q = Q[a, c]
                for w in range(W):
                    P[a, c, w] += q
                    P[c, a, w] = P[a, c, w]
                continue
            for w in range(W):
                P[a, c, w] += Qw[a, c, w]
                P[c, a, w] = P[a, c, w]


@_jit_fma
def _nb_update(x, P, c, nz, nnz, H, nu, R, HP, S, L, Li, KT, D, t, Y, nis, hld):
    """Kalman update in place, lane by lane (last axis), with the rows ``H[:c]`` (nonzero only in the columns
    ``nz[:nnz]``), innovations ``nu[:c]`` and noise ``R[:c, :c]``; a missing reading is a zero row with zero
    innovation and unit decoupled noise (its gain column is then exactly zero). K = P H^T S^{-1} (Cholesky of
    S = H P H^T + R), x += K nu, and the Joseph form (I - K H) P (I - K H)^T + K R K^T written as
    P - K (H P) + (K S - P H^T) K^T (equal for any K), its upper triangle computed and mirrored (exactly symmetric).
    Adds each lane's NIS nu^T S^{-1} nu = |L^{-1} nu|^2 to ``nis`` and half its log-determinant, sum log L_jj, to
    ``hld`` (a missing row adds 0 to both). False when some S is not positive definite or some state not finite."""
    n, W = x.shape
    # one or two rows (and one or two nonzeros per row) are the common updates: their sums are written out in one
    # loop over the lanes, with the same operations in the same order as the general loops below them (which a
    # small batch pays for: a loop over few lanes costs about its fixed overhead)
    for r in range(c):                                    # HP = H P (= (P H^T)^T: P is exactly symmetric)
        if nnz == 1 or nnz == 2:
            i0, i1 = nz[0], nz[nnz - 1]
            for j in range(n):
                if nnz == 1:
                    for w in range(W):
                        HP[r, j, w] = H[r, i0, w] * P[i0, j, w]
                    continue
                for w in range(W):
                    HP[r, j, w] = H[r, i0, w] * P[i0, j, w] + H[r, i1, w] * P[i1, j, w]
            continue
        for j in range(n):
            for w in range(W):
                HP[r, j, w] = 0.0
        for e in range(nnz):
            i = nz[e]
            for j in range(n):
                for w in range(W):
                    HP[r, j, w] += H[r, i, w] * P[i, j, w]
    for r in range(c):                                    # S = H P H^T + R
        for q in range(c):
            for w in range(W):
                S[r, q, w] = 0.0
            for e in range(nnz):
                j = nz[e]
                for w in range(W):
                    S[r, q, w] += HP[r, j, w] * H[q, j, w]
            for w in range(W):
                S[r, q, w] += R[r, q, w]
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
            Li[j, w] = 1.0 / L[j, j, w]                 # one division per row; the solves multiply by it
        for i in range(j + 1, c):
            for w in range(W):
                t[w] = S[i, j, w]
            for q in range(j):
                for w in range(W):
                    t[w] -= L[i, q, w] * L[j, q, w]
            for w in range(W):
                L[i, j, w] = t[w] * Li[j, w]
    for i in range(c):                                    # NIS = |Y|^2, L Y = nu (forward substitution)
        for w in range(W):
            Y[i, w] = nu[i, w]
        for q in range(i):
            for w in range(W):
                Y[i, w] -= L[i, q, w] * Y[q, w]
        for w in range(W):
            Y[i, w] *= Li[i, w]
            nis[w] += Y[i, w] * Y[i, w]
    for j in range(n):                                    # K^T = S^{-1} H P
        if c == 1:
            for w in range(W):
                KT[0, j, w] = HP[0, j, w] * Li[0, w] * Li[0, w]
            continue
        if c == 2:
            for w in range(W):
                k0 = HP[0, j, w] * Li[0, w]
                k1 = (HP[1, j, w] - L[1, 0, w] * k0) * Li[1, w]
                k1 = k1 * Li[1, w]
                KT[1, j, w] = k1
                KT[0, j, w] = (k0 - L[1, 0, w] * k1) * Li[0, w]
            continue
        for i in range(c):
            for w in range(W):
                KT[i, j, w] = HP[i, j, w]
            for q in range(i):
                for w in range(W):
                    KT[i, j, w] -= L[i, q, w] * KT[q, j, w]
            for w in range(W):
                KT[i, j, w] *= Li[i, w]
        for i in range(c - 1, -1, -1):
            for q in range(i + 1, c):
                for w in range(W):
                    KT[i, j, w] -= L[q, i, w] * KT[q, j, w]
            for w in range(W):
                KT[i, j, w] *= Li[i, w]
    good = True
    for i in range(n):                                    # x += K nu
        if c == 1 or c == 2:
            for w in range(W):
                v = KT[0, i, w] * nu[0, w]
                if c == 2:
                    v = v + KT[1, i, w] * nu[1, w]
                x[i, w] += v
                good &= x[i, w] - x[i, w] == 0.0
            continue
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
        if c == 1:
            for w in range(W):
                D[i, 0, w] = -HP[0, i, w] + KT[0, i, w] * S[0, 0, w]
            continue
        if c == 2:
            for w in range(W):
                D[i, 0, w] = -HP[0, i, w] + KT[0, i, w] * S[0, 0, w] + KT[1, i, w] * S[1, 0, w]
                D[i, 1, w] = -HP[1, i, w] + KT[0, i, w] * S[0, 1, w] + KT[1, i, w] * S[1, 1, w]
            continue
        for r in range(c):
            for w in range(W):
                D[i, r, w] = -HP[r, i, w]
            for q in range(c):
                for w in range(W):
                    D[i, r, w] += KT[q, i, w] * S[q, r, w]
    for i in range(n):                                    # P - K (H P) + D K^T: the upper triangle, mirrored
        for j in range(i, n):
            if c == 1 or c == 2:
                for w in range(W):
                    v = P[i, j, w] + (D[i, 0, w] * KT[0, j, w] - KT[0, i, w] * HP[0, j, w])
                    if c == 2:
                        v = v + (D[i, 1, w] * KT[1, j, w] - KT[1, i, w] * HP[1, j, w])
                    P[i, j, w] = v
                    P[j, i, w] = v
                continue
            for w in range(W):
                t[w] = P[i, j, w]
            for r in range(c):
                for w in range(W):
                    t[w] += D[i, r, w] * KT[r, j, w] - KT[r, i, w] * HP[r, j, w]
            for w in range(W):
                P[i, j, w] = t[w]
                P[j, i, w] = t[w]
    return True


@_jit_fma
def _nb_rss_rows(x, r, run, jrow, k, ta, c0, Z, A, P0c, PLE, SIG, pidx, npos, tag_h, dims, ref_d, clamp, anchor_sigma,
                 Hr, nu, var, valid, dof, zb, d2, dh, lg, work):
    """Row ``r`` of an RSS update for every lane ``w`` at once: reading ``jrow[w]`` of run ``run[w]`` (readings ``Z``
    from column ``c0``, anchors ``A``, channel ``P0c``/``PLE``/``SIG`` per run or shared, as packed by
    :func:`locbook.tracking._compiled._pack_streams`) linearised at the lane's state. Writes the innovation
    ``nu[r] = z - h(x)``, the variance ``var[r]``, the Jacobian's entries ``Hr[r, pidx[:npos]]`` and ``valid[r]``, and
    adds 1 to ``dof`` where there is a reading; a missing reading (not finite) gets 0, 1, zeros and False. Returns the
    number of lanes with a reading.

    The one RSS model's formula (:func:`locbook.models.rss.rss_mean_jacobian`, as
    :meth:`locbook.models.rss.RssModel.innovation` evaluates it), compiled:
    ``h = P_0 - 10 n log10(max(d, clamp) / d0)``, ``dh/dp = -(10 n / ln 10) (p - a) / d^2`` outside the clamp and 0
    within it (``d^2 < clamp^2``, where h is flat), variance ``sigma^2 + anchor_sigma^2 |dh/dp|^2``
    (:meth:`locbook.models.rss.RssModel.variance_db2`); ``clamp`` the model's ``clamp_m``, ``tag_h`` the
    height of a tag whose state has fewer position components than the anchors. No branch depends on a lane: the
    loops vectorise, and the logarithm is :func:`locbook.tracking._vecmath._log10_block` over the lanes (``zb``,
    ``d2``, ``dh``, ``lg``, ``work``: scratch of one value per lane)."""
    W = x.shape[1]
    BA, BC = A.shape[0], P0c.shape[0]
    p0i, p1i, p2i = pidx[0], pidx[1], pidx[2]
    for w in range(W):                                    # the distance to the anchor
        b, j = run[w], jrow[w]
        ab = min(b, BA - 1)
        zb[w] = Z[b, k, c0 + j]
        u = x[p0i, w] - A[ab, ta, c0 + j, 0]
        s2 = u * u
        if dims > 1:
            u = (x[p1i, w] if npos > 1 else tag_h) - A[ab, ta, c0 + j, 1]
            s2 += u * u
        if dims > 2:
            u = (x[p2i, w] if npos > 2 else tag_h) - A[ab, ta, c0 + j, 2]
            s2 += u * u
        d2[w] = s2
        d = np.sqrt(s2)
        dh[w] = (d if d > clamp else clamp) / ref_d
    _log10_block(dh, lg, work, W)
    count = 0
    for w in range(W):
        b, j = run[w], jrow[w]
        ab, bc = min(b, BA - 1), min(b, BC - 1)
        ple = PLE[bc, c0 + j]
        slope = 10.0 * ple / _LN_10
        inside = d2[w] < clamp * clamp
        coef = slope / d2[w]
        ok = zb[w] - zb[w] == 0.0                       # finite
        g = 0.0 if inside else -coef * (x[p0i, w] - A[ab, ta, c0 + j, 0])
        Hr[r, p0i, w] = g if ok else 0.0
        if npos > 1:
            g = 0.0 if inside else -coef * (x[p1i, w] - A[ab, ta, c0 + j, 1])
            Hr[r, p1i, w] = g if ok else 0.0
        if npos > 2:
            g = 0.0 if inside else -coef * (x[p2i, w] - A[ab, ta, c0 + j, 2])
            Hr[r, p2i, w] = g if ok else 0.0
        sigma = SIG[bc, c0 + j]
        v = sigma * sigma
        if anchor_sigma > 0.0:
            u = slope * anchor_sigma / np.sqrt(d2[w])
            v = v if inside else v + u * u
        h = P0c[bc, c0 + j] - 10.0 * ple * lg[w]
        nu[r, w] = zb[w] - h if ok else 0.0
        var[r, w] = v if ok else 1.0
        valid[r, w] = ok
        dof[w] += ok
        count += ok
    return count


@_jit_fma
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
def _descending_order(Z, run, k, c0, m, sel, key):
    """``sel[:m, w]``: the readings ``c0 .. c0 + m - 1`` of run ``run[w]`` at step ``k`` (``Z`` ``(B, T, M)``) in the
    order of descending value, for every lane ``w``; stable (ties, and the missing readings, last, keep their order).
    ``key``: scratch ``(m, W)``. The serial RSS update's order in the EKF and UKF kernels."""
    for w in range(sel.shape[1]):
        for j in range(m):
            sel[j, w] = j
            zj = Z[run[w], k, c0 + j]
            key[j, w] = zj if np.isfinite(zj) else -np.inf
        for j in range(1, m):
            i = j
            while i > 0 and key[sel[i - 1, w], w] < key[sel[i, w], w]:
                sel[i - 1, w], sel[i, w] = sel[i, w], sel[i - 1, w]
                i -= 1


@_jit_fma
def _nb_ekf(Fi, Fj, Fv, Q, x0, P0, predict_first, slot, active, kind, col, nz, nnz, Z, H, R, A, P0c, PLE, SIG, dims,
            ref_d, clamp, anchor_sigma, tag_h, pidx, npos, descending, iner, out_x, out_P, out_nis, out_dof,
            out_ll, W, lin, rss, ine):
    """The EKF time loop of :func:`locbook.tracking._loop._run` with :func:`locbook.tracking.streams._ekf_update`, over
    blocks of ``W`` runs (the last block padded with copies of the last run), with each run's NIS, its dof and
    log-likelihood at every step (``out_nis``, ``out_dof``, ``out_ll`` ``(B, T)``; NaN, 0 and NaN where no update).
    Stream kinds: 0/1 linear parallel/serial, 2/3 RSS parallel/serial, 4 inertial (parallel, :func:`_nb_inertial_row`
    with the parameters ``iner[s]``). Returns 0, or 1 + a run whose update failed (the caller then redoes the filter in
    numpy, which raises the library's error). ``lin``, ``rss``, ``ine``: 1 where the call has streams of that kind,
    None where not (:func:`locbook.tracking._compiled._present`): numba prunes a None kind's branch, so a kernel
    compiles only the kinds it is called with (a KF's first call skips the RSS rows' compile)."""
    B, T, n, ns = Z.shape[0], Z.shape[1], x0.shape[1], kind.shape[0]
    mmax = 1
    for s in range(ns):
        mmax = max(mmax, col[s + 1] - col[s])
    x, xt = np.empty((n, W)), np.empty((n, W))
    P, T1 = np.empty((n, n, W)), np.empty((n, n, W))
    Hr, HP, KT = np.zeros((mmax, n, W)), np.empty((mmax, n, W)), np.empty((mmax, n, W))
    nu, var, key = np.empty((mmax, W)), np.empty((mmax, W)), np.empty((mmax, W))
    Rr, S, L = np.zeros((mmax, mmax, W)), np.empty((mmax, mmax, W)), np.zeros((mmax, mmax, W))
    D = np.empty((n, mmax, W))
    t = np.empty(W)
    Y, Li, nis, dof = np.empty((mmax, W)), np.empty((mmax, W)), np.zeros(W), np.zeros(W, np.int64)
    hld = np.zeros(W)
    valid = np.zeros((mmax, W), np.bool_)
    sel = np.empty((mmax, W), np.int64)
    run = np.empty(W, np.int64)
    Qw = np.empty((n, n, W if Q.shape[0] > 1 else 0))    # Q per lane, or none when every run has the same
    qacc = np.empty((mmax, W))
    jrow = np.empty(W, np.int64)
    frow = np.zeros(n, np.bool_)                          # the rows of F with a nonzero
    for e in range(Fi.shape[0]):
        frow[Fi[e]] = True
    zb, d2b, dhb, lgb, wkb = np.empty(W), np.empty(W), np.empty(W), np.empty(W), np.empty(W)
    for b0 in range(0, B, W):
        for w in range(W):
            b = min(b0 + w, B - 1)
            run[w] = b
            for i in range(n):
                x[i, w] = x0[b, i]
                for j in range(n):
                    P[i, j, w] = P0[min(b, P0.shape[0] - 1), i, j]
                    if Q.shape[0] > 1:
                        Qw[i, j, w] = Q[b, i, j]
        for k in range(T):
            if predict_first or k > 0:
                _nb_predict(Fi, Fj, Fv, frow, Q[0], Qw, x, P, xt, T1)
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
                sort = kd == 3 and descending[s]          # the update order: as given, or by descending RSS
                if sort:
                    _descending_order(Z, run, k, c0, m, sel, key)
                for u in range(m if serial else 1):       # serial: one scalar update per reading
                    rows = 1 if serial else m
                    present = False
                    if lin is not None and kd <= 1:       # linear rows: no branch per lane (selects vectorise)
                        th, hb = min(k, H.shape[1] - 1), H.shape[0]
                        for r in range(rows):
                            j = u if serial else r
                            for w in range(W):
                                qacc[r, w] = 0.0
                            for e in range(nnz[s]):
                                col_e = nz[s, e]
                                if hb == 1:                       # one H for every run: a constant over the lanes
                                    h = H[0, th, c0 + j, col_e]
                                    for w in range(W):
                                        Hr[r, col_e, w] = h
                                        qacc[r, w] += h * x[col_e, w]
                                    continue
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
                    elif ine is not None and kd == _INERTIAL:     # inertial rows, lane by lane
                        for r in range(rows):
                            for w in range(W):
                                zj = Z[run[w], k, c0 + r]
                                valid[r, w] = np.isfinite(zj)
                                for e in range(nnz[s]):
                                    Hr[r, nz[s, e], w] = 0.0
                                nu[r, w] = 0.0
                                var[r, w] = 1.0
                                if not valid[r, w]:
                                    continue
                                present = True
                                dof[w] += 1
                                nu[r, w] = _nb_inertial_row(x, w, r, iner[s], zj, Hr[r])
                    elif rss is not None:                 # RSS rows, every lane at once
                        for r in range(rows):
                            for w in range(W):
                                jrow[w] = (sel[u, w] if sort else u) if serial else r
                            got = _nb_rss_rows(x, r, run, jrow, k, ta, c0, Z, A, P0c, PLE, SIG, pidx[s], npos[s],
                                               tag_h[s], dims[s], ref_d[s], clamp[s], anchor_sigma[s], Hr, nu, var,
                                               valid, dof, zb, d2b, dhb, lgb, wkb)
                            present |= got > 0
                    if not present:
                        continue
                    for r in range(rows):                 # R of the readings present, unit decoupled noise elsewhere
                        for q in range(rows):
                            if kd <= 1 or kd == _INERTIAL:    # (the order is the given one: sel is the identity)
                                jr, jq = (u, u) if serial else (r, q)
                                tr, rb = min(k, R.shape[1] - 1), R.shape[0]
                                other = 1.0 if r == q else 0.0
                                if rb == 1:                       # one R for every run
                                    rv = R[0, tr, c0 + jr, c0 + jq]
                                    for w in range(W):
                                        Rr[r, q, w] = rv if valid[r, w] and valid[q, w] else other
                                    continue
                                for w in range(W):
                                    Rr[r, q, w] = R[min(run[w], rb - 1), tr, c0 + jr, c0 + jq] \
                                        if valid[r, w] and valid[q, w] else other
                                continue
                            for w in range(W):                # RSS: var is 1 where a reading is missing
                                Rr[r, q, w] = var[r, w] if r == q else 0.0
                    if not _nb_update(x, P, rows, nz[s], nnz[s], Hr, nu, Rr, HP, S, L, Li, KT, D, t, Y, nis, hld):
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
