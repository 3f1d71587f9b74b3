"""Recursive least squares over the rows of a linear system: the recursive form of the linearized lateration fix.

Palvai (2008) locates a static emitter from ranges measured at N receiver positions; its LSF is the batch solution
``(H^T H)^{-1} H^T Y`` of the differenced sphere equations (:func:`locbook.static.lateration.lateration_ls` with
``pairs``, rows from :func:`locbook.static.lateration.lateration_system`), and its RLSF, Eqs. (2.49)-(2.58), is
:func:`recursive_least_squares` of the same rows, which equals the batch solution as the prior information goes to
zero. A NaN row (a missing reading) is skipped.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_array

__all__ = ["RlsResult", "recursive_least_squares"]


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
    ``prior_cov = 1e6 I`` (Palvai 2008, Eq. (2.49), prints no value for Pi_0; ours). A NaN row (a missing
    reading) is skipped."""
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
