"""Fixed-interval smoothing of a Kalman-family run: every step's state given all the readings, past and future.

:func:`rts_smoother` is the Rauch-Tung-Striebel smoother (H. E. Rauch, F. Tung and C. T. Striebel, "Maximum
likelihood estimates of linear dynamic systems", AIAA Journal 3(8), 1965) on the filtered and predicted moments a
:func:`~locbook.tracking.kalman.kalman_filter` or :func:`~locbook.tracking.kalman.extended_kalman_filter` run records,
vectorized over the run's leading Monte-Carlo axes (the backward pass loops over time only).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_array
from .results import KalmanResult

__all__ = ["SmoothedResult", "rts_smoother"]


@dataclass(frozen=True)
class SmoothedResult:
    """``x`` ``batch + (T, n)`` and ``P`` ``batch + (T, n, n)``: the smoothed means and covariances at every step;
    ``gain`` ``batch + (T - 1, n, n)``: the smoother gains ``C_k = P_k F^T P_{k+1|k}^{-1}``."""

    x: np.ndarray
    P: np.ndarray
    gain: np.ndarray


def rts_smoother(result: KalmanResult, F) -> SmoothedResult:
    """Rauch-Tung-Striebel smoother of a filter run with motion ``x_{k+1} = F x_k + w_k``:

    ``C_k = P_k F^T P_{k+1|k}^{-1}``, ``x^s_k = x_k + C_k (x^s_{k+1} - x_{k+1|k})``,
    ``P^s_k = P_k + C_k (P^s_{k+1} - P_{k+1|k}) C_k^T``, from ``x^s_{T-1} = x_{T-1}``, ``P^s_{T-1} = P_{T-1}``.

    ``result``: a run that recorded every step and its predictions, ``outputs=("x_pred", "P_pred")`` with
    ``record=None`` and ``predict_first=True`` (the prior of step ``k + 1`` is ``F`` applied to step ``k``'s
    posterior); its ``x_pred``/``P_pred`` are used as recorded, so the filter's own ``Q`` is in them. ``F``: the
    motion matrix ``(n, n)``, or with the run's leading axes ``batch + (n, n)``; for an EKF, its motion Jacobian.
    A step without readings is smoothed like any other (its posterior is its prediction)."""
    if not isinstance(result, KalmanResult):
        raise TypeError(f"result must be a KalmanResult, got {type(result).__name__}")
    if result.x_pred is None or result.P_pred is None:
        raise ValueError("rts_smoother needs the run's predictions: filter with outputs=('x_pred', 'P_pred')")
    x, P = np.asarray(result.x, float), np.asarray(result.P, float)
    T, n = x.shape[-2], x.shape[-1]
    steps = np.asarray(result.steps)
    if not np.array_equal(steps, np.arange(T)) or T == 0:
        raise ValueError("rts_smoother needs every step recorded (record=None), from step 0 on; got steps "
                         f"{steps[:5].tolist()}{'...' if steps.size > 5 else ''} of a run")
    F = as_array("F", F, min_ndim=2)
    if F.shape[-2:] != (n, n):
        raise ValueError(f"F must be ({n}, {n}) (the state's size), with optional run axes; got shape {F.shape}")
    batch = x.shape[:-2]
    try:
        F = np.broadcast_to(F, batch + (n, n))
    except ValueError:
        raise ValueError(f"F's run axes {F.shape[:-2]} do not match the run's {batch}") from None
    x_pred, P_pred = np.asarray(result.x_pred, float), np.asarray(result.P_pred, float)
    xs, Ps = x.copy(), P.copy()
    gain = np.empty(batch + (max(T - 1, 0), n, n))
    for k in range(T - 2, -1, -1):
        # C = P_k F^T P_pred^{-1}, solved as (P_pred^{-1} F P_k)^T (P_pred and P_k symmetric)
        C = np.swapaxes(np.linalg.solve(P_pred[..., k + 1, :, :], F @ P[..., k, :, :]), -1, -2)
        gain[..., k, :, :] = C
        xs[..., k, :] = x[..., k, :] + np.einsum("...ij,...j->...i", C, xs[..., k + 1, :] - x_pred[..., k + 1, :])
        Pk = P[..., k, :, :] + C @ (Ps[..., k + 1, :, :] - P_pred[..., k + 1, :, :]) @ np.swapaxes(C, -1, -2)
        Ps[..., k, :, :] = 0.5 * (Pk + np.swapaxes(Pk, -1, -2))
    return SmoothedResult(xs, Ps, gain)
