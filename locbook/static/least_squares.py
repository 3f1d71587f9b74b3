"""Linearised lateration from receivers that differ per problem (2-D or 3-D), batch and recursive least squares.

Palvai (2008) locates a static emitter from ranges measured at N receiver positions (random per Monte-Carlo run).
Differencing the sphere equations ``|X - s_i|^2 = d_i^2`` of two positions removes ``|X|^2``:

    2 (s_j - s_i)^T X = d_i^2 - d_j^2 - |s_i|^2 + |s_j|^2,

with ``(i, j)`` consecutive pairs ``(i, i + 1)`` (Eqs. (2.27)-(2.28), corrected: the printed rows lack the factor 2
and Eq. (2.18)'s right-hand side the full norms, note 002 s.2.4-2.6), or every position against the first or the
last one. ``variant="literal_002"`` keeps the printed rows without the 2 (flagged: it returns twice the
coordinates). The batch solution is ``(H^T H)^{-1} H^T Y`` (Eq. (2.29)); :func:`recursive_least_squares` is the
RLSF of Eqs. (2.49)-(2.58), which equals it as the prior information goes to zero.

Missing readings (NaN distance = not heard) drop every row that uses them; a problem left with fewer than ``dim``
independent rows gets a NaN position and status ``too_few_anchors`` or ``degenerate_geometry``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_array, check_choice
from .localization import LocalizationResult

__all__ = ["LATERATION_REFERENCES", "LATERATION_VARIANTS", "lateration_rows", "least_squares_position",
           "RlsResult", "recursive_least_squares"]

LATERATION_REFERENCES = ("consecutive", "first", "last")
LATERATION_VARIANTS = ("corrected", "literal_002")


def _pairs(n: int, reference: str):
    if reference == "consecutive":
        return np.arange(n - 1), np.arange(1, n)
    if reference == "first":
        return np.zeros(n - 1, int), np.arange(1, n)
    return np.arange(n - 1), np.full(n - 1, n - 1)


def lateration_rows(receivers_m, distance_m, *, reference: str = "consecutive", variant: str = "corrected"):
    """The differenced system ``H X = Y``: ``H`` ``(..., N - 1, dim)`` with rows ``2 (s_j - s_i)`` and ``Y``
    ``(..., N - 1)`` with ``d_i^2 - d_j^2 - |s_i|^2 + |s_j|^2`` for the pairs of ``reference``. ``receivers_m``
    ``(..., N, dim)`` (per problem) or ``(N, dim)`` (shared); ``distance_m`` ``(..., N)``, NaN = not heard (its rows
    are NaN)."""
    check_choice("reference", reference, LATERATION_REFERENCES)
    check_choice("variant", variant, LATERATION_VARIANTS)
    s = as_array("receivers_m", receivers_m, min_ndim=2)
    d = as_array("distance_m", distance_m, min_ndim=1, nan_ok=True)
    n = s.shape[-2]
    if d.shape[-1] != n:
        raise ValueError(f"distance_m has {d.shape[-1]} readings on its last axis, receivers_m has {n} positions")
    if n < 2:
        raise ValueError(f"receivers_m must hold at least two receiver positions (axis -2), got shape {s.shape}")
    if np.any(d < 0):
        raise ValueError(f"distance_m must be non-negative (NaN = not heard); it holds {float(np.nanmin(d)):.6g} at "
                         f"index {tuple(int(i) for i in np.argwhere(d < 0)[0])}")
    i, j = _pairs(n, reference)
    factor = 2.0 if variant == "corrected" else 1.0
    H = factor * (s[..., j, :] - s[..., i, :])
    norms = np.einsum("...k,...k->...", s, s)
    Y = d[..., i] ** 2 - d[..., j] ** 2 - norms[..., i] + norms[..., j]
    return H, Y


def least_squares_position(receivers_m, distance_m, *, reference: str = "consecutive",
                           variant: str = "corrected") -> LocalizationResult:
    """Batch least squares ``(H^T H)^{-1} H^T Y`` of :func:`lateration_rows` for every problem (Palvai 2008,
    Eq. (2.29)), by the normal equations (``dim x dim``); rows with a missing reading are left out."""
    H, Y = lateration_rows(receivers_m, distance_m, reference=reference, variant=variant)
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
    return LocalizationResult(pos, full, None, 0, f"least_squares_position({reference}, {variant})", status)


@dataclass(frozen=True)
class RlsResult:
    """Estimates ``x`` ``(..., K, n)`` and covariances (information inverses) ``P`` ``(..., K, n, n)`` after each
    of the K rows."""

    x: np.ndarray
    P: np.ndarray


def recursive_least_squares(H, y, *, x0=None, prior_cov=None) -> RlsResult:
    """Recursive least squares over the rows of ``H`` ``(..., K, n)`` and ``y`` ``(..., K)``, vectorized over the
    leading axes (Palvai 2008, RLSF, Eqs. (2.49)-(2.58), corrected: the prior mean enters as ``Pi_0^{-1} x0``
    and the innovation is ``y_k - h_k x``)::

        K_k = P h_k^T / (1 + h_k P h_k^T),   x <- x + K_k (y_k - h_k x),   P <- (I - K_k h_k) P

    (``P`` updated in the equivalent Joseph form.)

    Each estimate equals the regularised batch solution ``(Pi_0^{-1} + H_k^T H_k)^{-1} (Pi_0^{-1} x0 + H_k^T Y_k)``
    of the rows so far, and batch least squares as ``prior_cov -> inf``. Defaults: ``x0 = 0``,
    ``prior_cov = 1e6 I`` (note 002 s.2.8). A NaN row (a missing reading) is skipped."""
    H = as_array("H", H, min_ndim=2, nan_ok=True)
    y = as_array("y", y, min_ndim=1, nan_ok=True)
    n = H.shape[-1]
    K = H.shape[-2]
    if y.shape[-1] != K:
        raise ValueError(f"y has {y.shape[-1]} rows on its last axis, H has {K}")
    batch = np.broadcast_shapes(H.shape[:-2], y.shape[:-1])
    x = np.broadcast_to(np.zeros(n) if x0 is None else as_array("x0", x0, trailing=(n,)), batch + (n,)).copy()
    P0 = 1e6 * np.eye(n) if prior_cov is None else as_array("prior_cov", prior_cov, trailing=(n, n))
    P = np.broadcast_to(P0, batch + (n, n)).copy()
    H = np.broadcast_to(H, batch + (K, n))
    y = np.broadcast_to(y, batch + (K,))
    out_x = np.empty(batch + (K, n))
    out_P = np.empty(batch + (K, n, n))
    for k in range(K):
        h = H[..., k, :]
        yk = y[..., k]
        ok = np.isfinite(yk) & np.all(np.isfinite(h), axis=-1)
        h = np.where(ok[..., None], h, 0.0)
        ph = np.einsum("...ij,...j->...i", P, h)                      # P h^T
        gain = ph / (1.0 + np.einsum("...i,...i->...", h, ph))[..., None]
        innov = np.where(ok, yk - np.einsum("...i,...i->...", h, x), 0.0)
        x = x + gain * innov[..., None]
        # Joseph form of P <- (I - K h) P (unit row noise): stays symmetric positive definite under round-off
        ikh = np.eye(n) - gain[..., :, None] * h[..., None, :]
        P = ikh @ P @ np.swapaxes(ikh, -1, -2) + gain[..., :, None] * gain[..., None, :]
        P = 0.5 * (P + np.swapaxes(P, -1, -2))
        out_x[..., k, :] = x
        out_P[..., k, :, :] = P
    return RlsResult(out_x, out_P)
