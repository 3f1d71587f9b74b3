"""Batched functional Kalman prediction and update, the steps every Kalman-family filter is written on.

As filterpy offers ``predict`` and ``update`` beside its classes, :func:`predict` and :func:`update` are the two halves
of one recursion (filterpy / Dogan 2015, Table 3.1 notation), vectorized over leading run axes:

    x- = F x                                    P- = F P F^T + Q                                   (predict)
    nu = z - H x-      S = H P- H^T + R         K = P- H^T S^{-1}
    x+ = x- + K nu     P+ = (I - K H) P- (I - K H)^T + K R K^T       (Joseph form; ``joseph=False``: (I - K H) P-)
    log-likelihood = log N(nu; 0, S) = -(nu^T S^{-1} nu + log det S + m log 2 pi) / 2                (update)

Missing readings follow the library's rule: a NaN component of ``z`` is left out of the update (a zero row of H, a
zero innovation and unit decoupled noise, so its gain column is exactly zero and the other components update as they
would alone); its innovation is NaN and so are its row and column of S; the NIS, the log-likelihood and the degrees of
freedom are those of the components present (a run without any reading keeps its prior, with NIS and log-likelihood 0
and dof 0).

The filters (:func:`locbook.kalman_filter`, :func:`locbook.extended_kalman_filter`) call the unchecked cores
``_predict`` and ``_linear_update`` of these functions at every step; the public forms check their inputs first.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from .._linalg import (
    _UPDATE_OVERFLOW,
    _apply,
    _batch_shape,
    _covariance,
    _first_bad,
    _gaussian_log_likelihood,
    _inv_small,
    _joseph,
    _logdet,
    _matrix,
    _mT,
    _not_positive_definite,
    _Singular,
    _solve_active,
)
from .._validate import as_array
from ..errors import SingularCovarianceError

__all__ = ["predict", "update", "KalmanUpdate"]


@dataclass(frozen=True)
class KalmanUpdate:
    """What one Kalman update produces, per run (``batch`` the run axes): the posterior ``x`` ``batch + (n,)`` and
    ``P`` ``batch + (n, n)``, the ``innovation`` ``z - H x-`` ``batch + (m,)`` and its covariance ``S``
    ``batch + (m, m)`` (NaN at missing components), the normalised innovation squared ``nis`` ``nu^T S^{-1} nu``,
    its degrees of freedom ``dof`` (the components present) and the Gaussian ``log_likelihood`` ``log N(nu; 0, S)``
    (module docstring)."""

    x: np.ndarray
    P: np.ndarray
    innovation: np.ndarray
    S: np.ndarray
    nis: np.ndarray
    dof: np.ndarray
    log_likelihood: np.ndarray


class _Out(NamedTuple):
    """An update inside a filter: the posterior, the NIS, dof and log-likelihood of the components present, and (when
    asked for) the innovation and S with NaN at missing components (None otherwise)."""

    x: np.ndarray
    P: np.ndarray
    nis: np.ndarray
    dof: np.ndarray | int
    ll: np.ndarray
    # arrays when the caller asked for them (its ``want``), else None: Any, as only that flag tells which
    nu: Any = None
    S: Any = None


def _square(name: str, value) -> np.ndarray:
    value = as_array(name, value)
    if value.ndim < 2 or value.shape[-1] != value.shape[-2]:
        raise ValueError(f"{name} must be square (n, n) or batch + (n, n), got {value.shape}")
    return value


def _state(x, P):
    """The checked state ``x`` ``batch + (n,)`` and covariance ``P``."""
    x = as_array("x", x, min_ndim=1)
    n = x.shape[-1]
    return x, _covariance("P", P, n)


def predict(x, P, F, Q):
    """The Kalman prediction ``x- = F x``, ``P- = F P F^T + Q`` (module docstring), batched: ``x`` ``batch + (n,)``,
    ``P``, ``F``, ``Q`` ``(n, n)`` or ``batch + (n, n)`` (P and Q symmetric positive semi-definite, checked). Returns
    ``(x-, P-)`` broadcast over the run axes of all four."""
    x, P = _state(x, P)
    n = x.shape[-1]
    F = _square("F", F)
    if F.shape[-1] != n:
        raise ValueError(f"F must have shape ({n}, {n}) or batch + ({n}, {n}) for a state of {n}, got {F.shape}")
    Q = _covariance("Q", Q, n)
    batch = _batch_shape(("x", x.shape[:-1]), ("P", P.shape[:-2]), ("F", F.shape[:-2]), ("Q", Q.shape[:-2]))
    x_pred, P_pred = _predict(np.broadcast_to(x, batch + (n,)), P, F, Q, np.ascontiguousarray(_mT(F)))
    return x_pred, np.broadcast_to(P_pred, batch + (n, n)).copy()


def _predict(x, P, F, Q, Ft):
    """:func:`predict` without the checks (the filters' loop), with ``Ft`` the contiguous ``F^T`` computed once."""
    return (x @ Ft if F.ndim == 2 else _apply(F, x)), F @ P @ Ft + Q


def update(x, P, z, H, R, *, joseph: bool = True) -> KalmanUpdate:
    """One Kalman update (module docstring), batched over leading run axes: ``x`` ``batch + (n,)``, ``P``
    ``(n, n)`` or ``batch + (n, n)``, readings ``z`` ``batch + (m,)`` (NaN: missing, left out), ``H`` ``(m, n)`` and
    ``R`` ``(m, m)`` or with run axes (P and R symmetric positive semi-definite, checked). ``joseph=False``: the short
    covariance form ``(I - K H) P`` (symmetrised). Returns a :class:`KalmanUpdate`. An innovation covariance that is
    not positive definite (or a posterior that overflows) raises a SingularCovarianceError naming the first such run."""
    x, P = _state(x, P)
    n = x.shape[-1]
    z = as_array("z", z, min_ndim=1, nan_ok=True)
    m = z.shape[-1]
    H = _matrix("H", H, m, n)
    R = _covariance("R", R, m)
    batch = _batch_shape(("x", x.shape[:-1]), ("P", P.shape[:-2]), ("z", z.shape[:-1]), ("H", H.shape[:-2]),
                         ("R", R.shape[:-2]))
    x = np.broadcast_to(x, batch + (n,))
    z = np.broadcast_to(z, batch + (m,))
    try:
        out = _linear_update(x, P, z, H, R, joseph=joseph, want=True)
    except _Singular as exc:
        if exc.message:
            raise SingularCovarianceError(exc.message.replace(" at step {step}", "") + _first_bad(exc.bad)) from None
        raise SingularCovarianceError("the innovation covariance S = H P H^T + R is singular, not positive definite "
                                      f"or not finite{_first_bad(exc.bad)}; R must be positive where P gives no "
                                      "spread, and the readings and covariances finite") from None
    full = lambda v, tail: np.broadcast_to(v, batch + tail).copy()
    return KalmanUpdate(full(out.x, (n,)), full(out.P, (n, n)), full(out.nu, (m,)), full(out.S, (m, m)),
                        full(out.nis, ()), full(out.dof, ()).astype(np.int64), full(out.ll, ()))


def _missing_as_nan(nu, S, valid):
    """The innovation and S of an update with NaN at the missing components (their rows and columns of S)."""
    if valid.all():
        return nu, S
    return np.where(valid, nu, np.nan), np.where(valid[..., :, None] & valid[..., None, :], S, np.nan)


def _linear_update(x, P, z, H, R, *, joseph: bool = True, want: bool = False) -> _Out:
    """:func:`update` without the checks (the filters' inner step). A NaN component gets a zero row in H, a zero
    innovation and a unit decoupled noise, so its gain column is exactly zero and the other rows update as usual.
    ``want``: also return the innovation and S (NaN at missing components)."""
    valid = np.isfinite(z)
    dof = valid.sum(axis=-1)
    if not valid.any():
        zero = np.zeros(np.broadcast_shapes(x.shape[:-1], z.shape[:-1]))
        if not want:
            return _Out(x, P, zero, dof, zero)
        m = z.shape[-1]
        return _Out(x, P, zero, dof, zero, np.full(z.shape, np.nan), np.full(z.shape + (m,), np.nan))
    if not valid.all():
        H = np.where(valid[..., :, None], H, 0.0)
        pair = valid[..., :, None] & valid[..., None, :]
        R = np.where(pair, R, np.eye(z.shape[-1]))
    Ht = np.ascontiguousarray(H.T) if H.ndim == 2 else _mT(H)     # one H for all runs: a contiguous H^T
    if valid.all():
        nu = z - (x @ Ht if H.ndim == 2 else (H @ x[..., None])[..., 0])
    else:
        nu = np.where(valid, np.where(valid, z, 0.0) - (H @ x[..., None])[..., 0], 0.0)
    HP = H @ P
    S = HP @ Ht + R
    bad = valid.any(axis=-1) & _not_positive_definite(S)
    if bad.any():
        raise _Singular(bad)
    if S.shape[-1] <= 2:                                      # K = P H^T S^{-1}, closed-form inverse
        S_inv = _inv_small(S)
        K = _mT(HP) @ S_inv
        nis = np.einsum("...i,...i->...", nu, (S_inv @ nu[..., None])[..., 0])
    else:                                                     # K' = S^{-1} H P and S^{-1} nu from one solve
        n = P.shape[-1]
        both = np.broadcast_shapes(nu.shape[:-1], HP.shape[:-2])
        rhs = np.concatenate([np.broadcast_to(HP, both + HP.shape[-2:]),
                              np.broadcast_to(nu, both + nu.shape[-1:])[..., None]], axis=-1)
        sol = _solve_active(S, rhs, valid.any(axis=-1))
        K = _mT(sol[..., :n])
        nis = np.einsum("...i,...i->...", nu, sol[..., n])
    # a run without readings has S = I (zero H, unit noise): log det 0, NIS 0, dof 0, log-likelihood 0
    return _finish(x + (K @ nu[..., None])[..., 0], P, K, H, R, nu, S, nis, dof, valid, joseph=joseph, want=want)


def _linear_update_shared(x, P, z, present, H, R, *, joseph: bool = True, want: bool = False) -> _Out:
    """:func:`_linear_update` with one covariance ``P (n, n)`` and one ``H``, ``R`` for every run, the components
    ``present (m,)`` the same in every run; ``x`` and ``z`` batched. P, S and the dof are unbatched."""
    m = present.size
    if not present.any():
        zero = np.zeros(x.shape[:-1])
        return _Out(x, P, zero, 0, zero, np.full(z.shape, np.nan) if want else None,
                    np.full((m, m), np.nan) if want else None)
    if not present.all():
        H = np.where(present[:, None], H, 0.0)
        R = np.where(present[:, None] & present[None, :], R, np.eye(m))
    nu = z - x @ H.T if present.all() else np.where(present, np.where(present, z, 0.0) - x @ H.T, 0.0)
    HP = H @ P
    S = HP @ H.T + R
    everyone = np.ones(x.shape[:-1], bool)
    if _not_positive_definite(S):
        raise _Singular(everyone)
    flat = nu.reshape(-1, m)
    if m <= 2:
        S_inv = _inv_small(S)
        K = HP.T @ S_inv
        nis = np.einsum("bi,bi->b", flat @ S_inv, flat)
    else:
        try:                                    # K' = S^{-1} H P and S^{-1} nu^T in one solve
            sol = np.linalg.solve(S, np.concatenate([HP, flat.T], axis=-1))
        except np.linalg.LinAlgError:
            raise _Singular(everyone) from None
        K = sol[:, :P.shape[-1]].T
        nis = np.einsum("bi,ib->b", flat, sol[:, P.shape[-1]:])
    nis, dof = nis.reshape(x.shape[:-1]), int(present.sum())
    return _finish(x + nu @ K.T, P, K, H, R, nu, S, nis, dof, present, joseph=joseph, want=want)


def _finish(x_new, P, K, H, R, nu, S, nis, dof, valid, *, joseph: bool, want: bool) -> _Out:
    """The tail both linear updates share: refuse a non-finite state (a larger S that is not positive definite),
    the Gaussian log-likelihood of the innovation, the posterior covariance (Joseph form, or the short form
    ``(I - K H) P`` symmetrised) and the outputs (innovation and S with NaN at missing components if ``want``)."""
    if not np.isfinite(x_new).all():
        raise _Singular(~np.all(np.isfinite(x_new), axis=-1), _UPDATE_OVERFLOW)
    ll = _gaussian_log_likelihood(nis, _logdet(S), dof)
    if joseph:
        P_new = _joseph(P, K, H, R)
    else:
        short = (np.eye(P.shape[-1]) - K @ H) @ P
        P_new = 0.5 * (short + _mT(short))
    if not want:
        return _Out(x_new, P_new, nis, dof, ll)
    nu_out, S_out = _missing_as_nan(nu, S, valid)
    return _Out(x_new, P_new, nis, dof, ll, nu_out, S_out)
