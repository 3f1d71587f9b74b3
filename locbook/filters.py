"""Linear Kalman filter, vectorized over leading Monte-Carlo axes.

Standard recursion (filterpy / Dogan 2015, Table 3.1 notation):

    x_{k|k-1} = F x_{k-1|k-1}                      P_{k|k-1} = F P_{k-1|k-1} F^T + Q
    S_k = H P_{k|k-1} H^T + R                      K_k = P_{k|k-1} H^T S_k^{-1}
    x_{k|k} = x_{k|k-1} + K_k (z_k - H x_{k|k-1})
    P_{k|k} = (I - K_k H) P_{k|k-1} (I - K_k H)^T + K_k R K_k^T     (Joseph form)

Document 003 (George and Vadivukkarasi, Eqs. (9)-(13)) prints the update with ``X_{k-1}`` and
``P_{k-1}`` in place of the predicted quantities, so the prediction of Eqs. (9)-(10) is computed and
then discarded. That literal form is available as ``variant="literal_003"`` (flagged; note 003,
section 2.6 point 1): it reduces to a running average of the measurements.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["KalmanResult", "kalman_filter", "KF_VARIANTS"]

KF_VARIANTS = ("standard", "literal_003")


@dataclass(frozen=True)
class KalmanResult:
    """Filter output; shapes ``batch + (T, n)`` and ``batch + (T, n, n)``.

    ``x_pred``/``P_pred`` are the one-step predictions used at each update (for ``literal_003`` the
    quantities that the printed update actually uses, i.e. the previous posterior).
    """

    x: np.ndarray
    P: np.ndarray
    x_pred: np.ndarray
    P_pred: np.ndarray
    innovation: np.ndarray
    variant: str


def _mT(a):
    return np.swapaxes(a, -1, -2)


def kalman_filter(z, F, H, Q, R, x0, P0, *, predict_first: bool = True,
                  variant: str = "standard", joseph: bool = True) -> KalmanResult:
    """Run a linear Kalman filter over measurements ``z`` of shape ``batch + (T, m)``.

    Parameters
    ----------
    z : measurements; a time step whose entries are all NaN is skipped (prediction only).
    F, H, Q : model matrices ``(n, n)``, ``(m, n)``, ``(n, n)``; may carry batch axes.
    R : measurement covariance ``(m, m)`` or ``batch + (m, m)`` (e.g. an empirical R per run).
    x0, P0 : initial state ``batch + (n,)`` and covariance.
        With ``predict_first=True`` they are the posterior one step *before* ``z[..., 0, :]``
        (filterpy's convention: predict, then update, at every step). With ``predict_first=False``
        they are the prior at the time of ``z[..., 0, :]``, which is used without a prediction.
    variant : ``"standard"`` or ``"literal_003"`` (Eqs. (11)-(13) of document 003 as printed).
    joseph : use the Joseph-form covariance update (keeps P symmetric positive definite).
    """
    if variant not in KF_VARIANTS:
        raise ValueError(f"variant must be one of {KF_VARIANTS}, got {variant!r}")
    z = np.asarray(z, dtype=float)
    F, H, Q, R = (np.asarray(a, dtype=float) for a in (F, H, Q, R))
    x = np.asarray(x0, dtype=float)
    P = np.asarray(P0, dtype=float)
    n, m = F.shape[-1], H.shape[-2]
    if z.shape[-1] != m:
        raise ValueError(f"measurements have dimension {z.shape[-1]} but H has {m} rows")
    if x.shape[-1] != n or P.shape[-2:] != (n, n):
        raise ValueError(f"x0 must end in ({n},) and P0 in ({n}, {n}); got {x.shape} and {P.shape}")
    batch = np.broadcast_shapes(z.shape[:-2], x.shape[:-1], P.shape[:-2], F.shape[:-2], H.shape[:-2],
                                Q.shape[:-2], R.shape[:-2])
    T = z.shape[-2]
    x = np.broadcast_to(x, batch + (n,)).copy()
    P = np.broadcast_to(P, batch + (n, n)).copy()
    z = np.broadcast_to(z, batch + (T, m))
    eye = np.eye(n)
    out_x = np.empty(batch + (T, n))
    out_P = np.empty(batch + (T, n, n))
    out_xp = np.empty(batch + (T, n))
    out_Pp = np.empty(batch + (T, n, n))
    out_nu = np.full(batch + (T, m), np.nan)
    for k in range(T):
        if predict_first or k > 0:
            x_pred = x @ _mT(F)                      # x- = F x
            P_pred = F @ P @ _mT(F) + Q              # P- = F P F' + Q
        else:
            x_pred, P_pred = x, P
        # the printed update of document 003 uses the previous posterior, not the prediction
        x_use, P_use = (x, P) if variant == "literal_003" else (x_pred, P_pred)
        zk = z[..., k, :]
        valid = np.all(np.isfinite(zk), axis=-1)
        zk = np.where(valid[..., None], zk, 0.0)
        S = H @ P_use @ _mT(H) + R                   # S = H P H' + R
        K = np.linalg.solve(S, H @ P_use)            # K' = S^{-1} H P  (S, P symmetric)
        K = _mT(K)
        nu = zk - x_use @ _mT(H)                     # innovation z - H x
        x_new = x_use + (K @ nu[..., None])[..., 0]
        IKH = eye - K @ H
        if joseph:
            P_new = IKH @ P_use @ _mT(IKH) + K @ R @ _mT(K)   # P = (I-KH)P(I-KH)' + KRK'
        else:
            P_new = IKH @ P_use                                # P = (I-KH)P
        P_new = 0.5 * (P_new + _mT(P_new))
        x = np.where(valid[..., None], x_new, x_pred)
        P = np.where(valid[..., None, None], P_new, P_pred)
        out_x[..., k, :], out_P[..., k, :, :] = x, P
        out_xp[..., k, :], out_Pp[..., k, :, :] = x_use, P_use
        out_nu[..., k, :] = np.where(valid[..., None], nu, np.nan)
    return KalmanResult(out_x, out_P, out_xp, out_Pp, out_nu, variant)
