"""The square-root (Cholesky-factor) form of the Kalman and extended Kalman filters, vectorized over leading run axes.

The covariance is carried as a factor ``S`` with ``P = S S^T`` through the whole recursion and never formed inside
it, so the recursion cannot lose symmetry or positive semi-definiteness and works on numbers of half the dynamic range
(the condition number of S is the square root of P's): Kaminski, Bryson and Schmidt, "Discrete square root filtering:
a survey of current techniques", IEEE Trans. Automatic Control 16(6), 1971; Grewal and Andrews, "Kalman Filtering:
Theory and Practice", 2nd ed. 2001, Ch. 6 (triangularization, the Morf-Kailath combined square-root filter); the array
algorithms of Kailath, Sayed and Hassibi, "Linear Estimation", 2000, Ch. 12. Every step is one orthogonal
triangularization of a pre-array, done by a (batched) QR decomposition: if ``A^T = Q R`` then ``A Q = R^T`` is lower
triangular and ``R^T R = A A^T``.

    prediction   [F S, Q^{1/2}] Theta = [S-, 0]                  S- S-^T = F P F^T + Q
                 (NonlinearMotion: x- = f(x), F = J the Jacobian at the posterior, as the EKF)

    update       [R^{1/2}   H S-]  Theta  =  [S_e    0 ]          S_e S_e^T = H P- H^T + R   (innovation covariance)
                 [   0       S- ]            [K_bar  S+]          K_bar = P- H^T S_e^{-T},   S+ S+^T = P+
                 w = S_e^{-1} nu (a triangular solve),  x+ = x- + K_bar w,  NIS = w^T w,  log det S = 2 sum log diag S_e

(the gain ``K = K_bar S_e^{-1}`` is never formed). Each stream is updated with its linearisation at the state so far,
``stream.model.linearized(x, z_k, step=k)`` -> ``(z', H, R)``, the linear model the EKF updates with (exact for a
linear model), so the filter equals :func:`locbook.extended_kalman_filter` (and on linear streams
:func:`locbook.kalman_filter`) to round-off. A serial stream is one scalar array update per reading in the stream's
order, each re-linearised at the state updated so far (Dogan 2015, Table 3.3), as the EKF's serial updates.

Missing readings follow the library's one rule: a NaN reading is left out, per run, exactly as the KF leaves it out
(its row of H and innovation set to zero, its row and column of R to the identity's, so the pre-array's row is a unit
row decoupled from the rest: S_e has a unit row and column there and K_bar a zero column; the other readings update as
they would alone); a run without any reading keeps its prior factor.

Semi-definite covariances (a Q of rank one per axis, as the discrete white-noise models build, a zero P0, an R with a
perfect reading) have no Cholesky factor: where Cholesky fails the factor is the symmetric eigen-square-root
``V diag(sqrt(max(lambda, 0)))`` brought to lower triangular form by the same QR (the negative eigenvalues are the
input checks' round-off, at most 1e-8 of the scale).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .._linalg import _UPDATE_OVERFLOW, _apply, _gaussian_log_likelihood, _mT, _Singular
from ._loop import _check_outputs as _loop_check_outputs
from ._loop import _motion_apply, _motion_jacobian, _run, _setup, _streams
from .functional import _Out
from .results import DIVERGENCE_PROBABILITY, DIVERGENCE_WINDOW, KALMAN_OUTPUTS, KalmanResult, _check_guard, _flag
from .streams import Stream, _Serial, _serial_order, _serial_row

__all__ = ["square_root_kalman_filter", "SquareRootKalmanResult", "SQUARE_ROOT_OUTPUTS"]

#: the optional outputs of :func:`square_root_kalman_filter`: the Kalman family's and the factors themselves
SQUARE_ROOT_OUTPUTS = KALMAN_OUTPUTS + ("P_sqrt", "P_pred_sqrt")


@dataclass(frozen=True)
class SquareRootKalmanResult(KalmanResult):
    """A :class:`~locbook.tracking.results.KalmanResult` (``P = S S^T``, ``P_pred`` likewise) with, when named in
    ``outputs``, the factors the recursion carried: ``P_sqrt`` ``batch + (R, n, n)`` lower triangular with a
    non-negative diagonal, ``P = P_sqrt P_sqrt^T``, and ``P_pred_sqrt`` the prior's."""

    P_sqrt: np.ndarray | None = None
    P_pred_sqrt: np.ndarray | None = None


def _lower_triangular(A):
    """The lower-triangular ``L`` ``batch + (r, r)`` with a non-negative diagonal and ``L L^T = A A^T``, for a
    pre-array ``A`` ``batch + (r, c)``, ``c >= r``: from the QR decomposition ``A^T = Q R``, ``L = R^T`` (the
    orthogonal triangularization of the module docstring; the columns' signs set so that the diagonal is >= 0)."""
    L = _mT(np.linalg.qr(_mT(A), mode="r"))
    d = np.diagonal(L, axis1=-2, axis2=-1)
    return L * np.where(d < 0, -1.0, 1.0)[..., None, :]


def _factor(A):
    """A lower-triangular factor ``L`` of symmetric positive semi-definite matrices ``A`` ``batch + (r, r)``,
    ``L L^T = A``: Cholesky, or where it fails (a semi-definite A) the eigen-square-root triangularized (module
    docstring)."""
    A = np.asarray(A, dtype=float)
    if A.shape[-1] == 0:
        return A.copy()
    try:
        return np.linalg.cholesky(A)
    except np.linalg.LinAlgError:
        pass
    sym = 0.5 * (A + _mT(A))
    lam, V = np.linalg.eigh(sym)
    return _lower_triangular(V * np.sqrt(np.maximum(lam, 0.0))[..., None, :])


def _forward(L, b):
    """``L^{-1} b`` for lower-triangular ``L`` ``batch + (m, m)`` with a positive diagonal and ``b`` ``batch + (m,)``
    (forward substitution, a loop over the m rows: numpy has no batched triangular solve)."""
    L, b = np.broadcast_arrays(L, b[..., None])
    b = b[..., 0]
    w = np.empty(b.shape)
    for i in range(b.shape[-1]):
        w[..., i] = (b[..., i] - np.einsum("...j,...j->...", L[..., i, :i], w[..., :i])) / L[..., i, i]
    return w


def _array_update(x, S, z, H, R, want: bool) -> _Out:
    """The measurement update in array form (module docstring) of the linear model ``z = H x + v``, ``v ~ N(0, R)``
    on the prior ``x`` ``batch + (n,)``, ``P = S S^T``; NaN readings of ``z`` ``batch + (m,)`` left out (module
    docstring). Returns the posterior mean and factor with the NIS, dof and Gaussian log-likelihood of the readings
    present, and with ``want`` their innovation and S (NaN at the missing ones)."""
    valid = np.isfinite(z)
    dof = valid.sum(axis=-1)
    m, n = z.shape[-1], x.shape[-1]
    batch = np.broadcast_shapes(x.shape[:-1], z.shape[:-1], np.shape(H)[:-2], np.shape(R)[:-2], S.shape[:-2])
    if not valid.any():
        zero = np.zeros(batch)
        nan = (np.full(batch + (m,), np.nan), np.full(batch + (m, m), np.nan)) if want else (None, None)
        return _Out(x, S, zero, dof, zero, *nan)
    H = np.where(valid[..., :, None], H, 0.0)
    R = np.where(valid[..., :, None] & valid[..., None, :], R, np.eye(m))
    nu = np.where(valid, np.where(valid, z, 0.0) - _apply(H, x), 0.0)
    HS = H @ S
    pre = np.zeros(batch + (m + n, m + n))
    pre[..., :m, :m] = _factor(R)
    pre[..., :m, m:] = HS
    pre[..., m:, m:] = S
    post = _lower_triangular(pre)
    S_e, K_bar, S_new = post[..., :m, :m], post[..., m:, :m], post[..., m:, m:]
    diag = np.diagonal(S_e, axis1=-2, axis2=-1)
    bad = np.any(valid & ~(diag > 0), axis=-1) | ~np.all(np.isfinite(post), axis=(-2, -1))
    if bad.any():                   # H P- H^T + R singular where a reading is present (or not finite)
        raise _Singular(bad)
    w = _forward(S_e, nu)
    x_new = x + (K_bar @ w[..., None])[..., 0]
    if not np.isfinite(x_new).all():
        raise _Singular(~np.all(np.isfinite(x_new), axis=-1), _UPDATE_OVERFLOW)
    nis = np.einsum("...i,...i->...", w, w)
    # a missing reading's row of S_e is the unit row: log 1 = 0, and w = 0 there
    ll = _gaussian_log_likelihood(nis, 2.0 * np.log(diag).sum(axis=-1), dof)
    some = valid.any(axis=-1)
    S_new = np.where(some[..., None, None], S_new, S)       # a run without a reading keeps its prior factor
    if not want:
        return _Out(x_new, S_new, nis, dof, ll)
    cov = S_e @ _mT(S_e)
    return _Out(x_new, S_new, nis, dof, ll, np.where(valid, nu, np.nan),
                np.where(valid[..., :, None] & valid[..., None, :], cov, np.nan))


def _serial_array_update(x, S, z, stream: Stream, step: int, want: bool) -> _Out:
    """A serial stream: one scalar array update per reading in the stream's order (``streams._serial_order``), each on
    the model's linearisation at the state updated so far (Dogan 2015, Table 3.3), the NIS and log-likelihood summed
    (the scalar innovations of one step are independent under the model)."""
    model = stream.model
    m = z.shape[-1]
    order = _serial_order(z, stream.order)
    acc, dof = _Serial(np.broadcast_shapes(x.shape[:-1], z.shape[:-1]), m, want), np.isfinite(z).sum(axis=-1)
    for j in range(m):
        a = j if order is None else order[..., j]
        row = _serial_row(model, x, z, a, step)
        if row is None:
            continue
        valid, nu, h, var = row
        nu = np.where(valid, nu, np.nan)
        # the linear model of this reading at x: z' = nu + h x, so that its innovation z' - h x is nu
        z_lin = (nu + np.einsum("...i,...i->...", h, x))[..., None]
        o = _array_update(x, S, z_lin, h[..., None, :], np.asarray(var)[..., None, None], True)
        acc.add(np.where(valid, nu, 0.0), o.S[..., 0, 0], valid, a, nis=o.nis, ll=o.ll)
        x, S = o.x, o.P             # (_Out's P slot holds the factor, its S the innovation covariance)
    return acc.out(x, S, dof)


def _update(x, S, z, stream: Stream, step: int, want: bool = False) -> _Out:
    """One stream's update in array form on its linearisation at the state so far (parallel), or its serial form."""
    if stream.mode == "serial":
        return _serial_array_update(x, S, z, stream, step, want)
    z_lin, H, R = stream.model.linearized(x, z, step=step)
    return _array_update(x, S, z_lin, H, np.asarray(R, dtype=float), want)


def _predictor(setup, Q_sqrt):
    """The prediction in array form (module docstring): ``(x, S, k, cross) -> (x-, S-, C)``, ``C = P F^T = S (F S)^T``
    (``P J^T`` for nonlinear motion) the cross-covariance when ``cross``; ``Q_sqrt`` the factors of Q (per step when
    Q is)."""
    motion = setup.motion

    def predict(x, S, k, cross):
        if motion is not None:
            F = _motion_jacobian(motion, x, k)
            x_pred = _motion_apply(motion, x, k, x.ndim - 1)
        else:
            F = setup.F_at(k)
            x_pred = _apply(F, x)
        d = setup.drift_at(k)
        if d is not None:
            x_pred = x_pred + d
        FS = F @ S
        Qs = Q_sqrt[..., min(k, Q_sqrt.shape[-3] - 1), :, :] if setup.Q_steps else Q_sqrt
        shape = np.broadcast_shapes(FS.shape, Qs.shape)
        S_pred = _lower_triangular(np.concatenate([np.broadcast_to(FS, shape), np.broadcast_to(Qs, shape)], axis=-1))
        return x_pred, S_pred, (S @ _mT(FS) if cross else None)
    return predict


def _check_outputs(outputs) -> frozenset:
    """The optional outputs asked for: names among SQUARE_ROOT_OUTPUTS."""
    return _loop_check_outputs(outputs, SQUARE_ROOT_OUTPUTS)


def _product(S):
    """``S S^T``, symmetric to the last bit."""
    P = S @ _mT(S)
    return 0.5 * (P + _mT(P))


def square_root_kalman_filter(F, Q, x0, P0, measurements, *, B=None, u=None, record=None, predict_first: bool = True,
                              outputs=(), divergence_window: int | None = DIVERGENCE_WINDOW,
                              divergence_probability: float = DIVERGENCE_PROBABILITY) -> SquareRootKalmanResult:
    """The (extended) Kalman filter in square-root form (module docstring): the arguments and the result of
    :func:`locbook.extended_kalman_filter`, with the covariance carried as a lower-triangular factor ``S``, ``P = S
    S^T``, through every prediction and update (orthogonal triangularizations by QR, batched over the runs).

    ``F``, ``Q``, ``B``, ``u``: linear motion (run axes or ``per_step``) or a
    :class:`~locbook.tracking.transition.NonlinearMotion` with its Jacobian; ``x0``, ``P0`` the prior (one step
    before step 0 with ``predict_first``, else at step 0); ``measurements``: a stream or a list of them
    (:class:`LinearMeasurement`, :class:`RssMeasurement` parallel or serial, :class:`NonlinearMeasurement`), NaN =
    missing; ``record``, ``outputs`` (among :data:`SQUARE_ROOT_OUTPUTS`: the Kalman family's ``x_pred``, ``P_pred``,
    ``P_cross``, ``innovation``, ``S`` and the factors ``P_sqrt``, ``P_pred_sqrt``), ``divergence_window``,
    ``divergence_probability``: as :func:`locbook.extended_kalman_filter`. The inputs are checked as there (Q, P0
    and R symmetric positive semi-definite; a semi-definite one is factored through its eigen-decomposition).

    Returns a :class:`SquareRootKalmanResult` (a :class:`~locbook.tracking.results.KalmanResult`) whose ``P`` (and
    ``P_pred``) is ``S S^T`` of the carried factor: exactly symmetric, and positive semi-definite up to the round-off
    of forming that product (an eigenvalue below 1e-16 of P's scale can come out as -1e-17; the factor, output
    ``P_sqrt``, is the exact statement), where the conventional update's ``P - K H P`` loses definiteness by far more
    on an ill-conditioned problem (nearly perfect readings: ``P0 = I``, ``H = [[1, 1, 1], [1, 1, 1 + d]]``,
    ``R = d^2 I``, ``d = 1e-8``, serial: the short form's smallest eigenvalue -1.6e-10, this form's P within 4e-9 of the
    exact posterior). The numpy loop only (no compiled path); each step costs a QR of a ``(m + n)``-square array per
    run and stream.
    """
    window, probability = _check_guard(divergence_window, divergence_probability)
    names = _check_outputs(outputs)
    measurements = _streams(measurements)
    setup = _setup(F, Q, x0, P0, measurements, record, "square_root_kalman_filter", B, u)
    n = setup.n
    loop_outputs = (names & set(KALMAN_OUTPUTS)) | ({"P_pred"} if "P_pred_sqrt" in names else set())
    # the loop carries the factor where the other filters carry P (it only records it and checks it is finite)
    factored = replace(setup, P=np.broadcast_to(_factor(setup.P), setup.batch + (n, n)).copy())
    res = _run(factored, measurements, _update, predict_first, outputs=loop_outputs,
               predict=_predictor(setup, _factor(setup.Q)))
    S_pred = res.P_pred
    out = SquareRootKalmanResult(
        **{f: getattr(res, f) for f in KalmanResult.__dataclass_fields__},
        P_sqrt=res.cov if "P_sqrt" in names else None, P_pred_sqrt=S_pred if "P_pred_sqrt" in names else None)
    out = replace(out, cov=_product(res.cov), P_pred=_product(S_pred) if "P_pred" in names else None)
    return _flag(out, window, probability)
