"""Unscented Kalman filter (scaled unscented transform), vectorized over leading Monte-Carlo axes.

Gudipati 2017, Sec. 3.6, Eqs. (3.18)-(3.30), with the print's errors corrected (marked in brackets below):

    lambda = alpha^2 (n + kappa) - n
    X^0 = x-,  X^i = x- + (sqrt((n + lambda) P-))_i,  X^{n+i} = x- - (sqrt((n + lambda) P-))_i     (3.18)-(3.20)
    W_m^0 = lambda / (n + lambda)        [printed n / (n + lambda), Eq. (3.22)]
    W_c^0 = W_m^0 + 1 - alpha^2 + beta,  W_m^i = W_c^i = 1 / (2 (n + lambda))                          (3.23)
    gamma^i = h(X^i), i = 0..2n          [printed i = 1..2n, Eq. (3.24)]
    z^ = sum W_m^i gamma^i,   P_zz = sum W_c^i (gamma^i - z^)(gamma^i - z^)^T + R   [printed without R, (3.26)]
    P_xz = sum W_c^i (X^i - x-)(gamma^i - z^)^T,  K = P_xz P_zz^{-1},  x+ = x- + K (z - z^)
    P+ = P- - K P_zz K^T                 [printed P- - K P_xz K^T, dimensionally impossible, Eq. (3.30)]

The motion model is linear (Eqs. (3.1), (3.16)), so the prediction is the Kalman one; sigma points are drawn
around the predicted state at every update (Eq. (3.18)), as the thesis does.

Numerical guard. At the thesis's alpha = 1e-3 the weights are about -1e6 and 6e4 (n = 8), and
``P- - K P_zz K^T`` is a difference of nearly equal matrices. The covariance update is therefore written in the
equivalent Joseph form with the statistically linearised measurement matrix ``H~ = P_xz^T P-^{-1}`` and noise
``R~ = P_zz - H~ P- H~^T``:

    P+ = (I - K H~) P- (I - K H~)^T + K R~ K^T,

which equals ``P- - K P_zz K^T`` in exact arithmetic (``K P_zz K^T = K P_xz^T``) and is symmetric positive
semi-definite whenever ``R~`` is. ``R~`` is symmetrised and its eigenvalues floored at 0 (the guard); the number
of floored updates is returned, so a run can show it is rarely or never needed.

The thesis-literal forms are flagged variants: ``variant="literal_gudipati2017"`` (Eq. (3.22) as printed; the weights
then sum to ``2n / (n + lambda)``; the filter's earlier ``weights=``, deprecated) and ``innovation_noise=False``
(Eq. (3.26) without R). Eq. (3.30) as printed cannot
be evaluated (an ``n x m`` times ``n x m`` product) and has no variant.

Missing readings follow the library's rule: a NaN component is left out of the update (zero gain column).

Speed. With numba installed and enabled (``LOCBOOK_NUMBA``, :mod:`locbook.tracking._compiled`), linear
motion (F without run axes; Q may differ per run) and streams of the library's linear, RSS and inertial models
(:class:`~locbook.models.imu.InertialMeasurement`; the compiled registry, :mod:`locbook.tracking._compiled`), the same
recursion runs compiled on blocks of runs
(:mod:`locbook.tracking._ukf_kernels`); anything it cannot do (a covariance that is not positive definite, the
eigenvalue guard on a multi-reading update, a state that overflows) sends the problem back to the numpy loop, which
raises the library's error or applies the guard. Both paths give the same numbers to round-off
(tests/tracking/test_unscented_compiled.py).
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .._deprecation import old_keyword, renamed_constants
from .._linalg import (
    _UPDATE_OVERFLOW,
    _gaussian_log_likelihood,
    _inv_small,
    _logdet,
    _mT,
    _not_positive_definite,
    _refuse_not_finite,
    _Singular,
    _singular_runs,
)
from .._validate import check_choice, check_scalar, function_output
from ..models.base import check_output
from ._loop import _check_outputs, _motion_apply, _run, _setup, _streams
from .functional import _missing_as_nan, _Out
from .results import DIVERGENCE_PROBABILITY, DIVERGENCE_WINDOW, KalmanResult, _check_guard, _flag
from .streams import _diagonal_entry, _row, _Serial, _serial_order

__all__ = ["UKF_VARIANTS", "SIGMA_POINT_SETS", "UnscentedWeights", "unscented_weights", "sigma_points",
           "unscented_transform", "unscented_kalman_filter"]

#: the weights' forms: corrected (they sum to 1) and Gudipati's printed W_m^0 (Eq. (3.22), flagged)
UKF_VARIANTS = ("corrected", "literal_gudipati2017")
#: the old name (``weights=``), one release
__getattr__ = renamed_constants(__name__, {"UKF_WEIGHTS": ("UKF_VARIANTS", UKF_VARIANTS)})
#: the sigma-point sets of :func:`unscented_weights`
SIGMA_POINT_SETS = ("merwe", "julier", "cubature")


@dataclass(frozen=True)
class UnscentedWeights:
    """Mean and covariance weights ``(2n + 1,)`` and the scaling ``lam`` of the scaled unscented transform."""

    mean: np.ndarray
    cov: np.ndarray
    lam: float

    @property
    def n(self) -> int:
        return (self.mean.size - 1) // 2


_DEFAULT_ALPHA, _DEFAULT_BETA = 1e-3, 2.0


def unscented_weights(n: int, alpha: float = _DEFAULT_ALPHA, beta: float = _DEFAULT_BETA, kappa: float = 0.0,
                      variant: str = "corrected", points: str = "merwe") -> UnscentedWeights:
    """Weights of a symmetric sigma-point set: ``X^0 = x``, ``X^{i, n+i} = x +- (sqrt((n + lambda) P))_i``.

    ``points="merwe"``: van der Merwe's scaled set, Eqs. (3.21)-(3.23) in Gudipati 2017 (``lambda = alpha^2 (n +
    kappa) - n``, ``W_m^i = W_c^i = 1 / (2 (n + lambda))``, ``W_c^0 = W_m^0 + 1 - alpha^2 + beta``).
    ``variant="corrected"``: ``W_m^0 = lambda / (n + lambda)`` (the weights sum to 1). ``"literal_gudipati2017"``: the
    printed ``W_m^0 = n / (n + lambda)`` (flagged: the mean weights then sum to ``2n / (n + lambda)``, about 2e6
    at the thesis's alpha = 1e-3 and n = 8). ``n + lambda = alpha^2 (n + kappa)`` must be positive.

    ``points="julier"``: Julier and Uhlmann's set (S. J. Julier and J. K. Uhlmann, "A new extension of the Kalman
    filter to nonlinear systems", 1997): ``lambda = kappa``, ``W^0 = kappa / (n + kappa)``, ``W^i = 1 / (2 (n +
    kappa))``, the same weights for mean and covariance (filterpy's JulierSigmaPoints). ``points="cubature"``: the
    third-degree spherical-radial cubature rule (I. Arasaratnam and S. Haykin, "Cubature Kalman filters", IEEE TAC
    54(6), 2009): ``2n`` points ``x +- sqrt(n) (sqrt P)_i`` of weight ``1 / (2n)`` (here with a centre point of weight
    0). Both are the scaled set's algebra at ``alpha = 1``, ``beta = 0`` (Julier's with its kappa, the cubature rule
    with kappa = 0); ``alpha`` and ``beta`` are not used by them (nor ``kappa`` by the cubature rule), so a value
    other than their default is refused with a line saying which parameter the set takes, rather than ignored."""
    check_scalar("n", n, ge=1, integer=True)
    check_scalar("alpha", alpha, gt=0)
    check_scalar("beta", beta)
    check_scalar("kappa", kappa)
    check_choice("variant", variant, UKF_VARIANTS)
    check_choice("points", points, SIGMA_POINT_SETS)
    if points != "merwe" and variant != "corrected":
        raise ValueError(f"variant={variant!r} is a variant of the printed scaled (merwe) weights; points={points!r} "
                         "has none")
    scaled = ("julier", "cubature")              # the sets without alpha and beta (cubature: without kappa too)
    ignored = [f"{name}={value!r}" for name, value, default, sets in
               (("alpha", alpha, _DEFAULT_ALPHA, scaled), ("beta", beta, _DEFAULT_BETA, scaled),
                ("kappa", kappa, 0.0, ("cubature",))) if points in sets and value != default]
    if ignored:
        takes = ("kappa (lambda = kappa)" if points == "julier" else
                 "no parameter (x +- sqrt(n) columns, weights 1 / (2n))")
        raise ValueError(f"points={points!r} does not use {', '.join(ignored)}: its set takes {takes}; alpha and beta "
                         "scale points='merwe' only")
    n = int(n)
    if points == "cubature":
        alpha, beta, kappa = 1.0, 0.0, 0.0
    elif points == "julier":
        alpha, beta = 1.0, 0.0
    c = alpha**2 * (n + kappa)           # n + lambda, computed directly (lambda = c - n cancels at small alpha)
    if not c > 0:
        raise ValueError(f"n + lambda = alpha^2 (n + kappa) must be positive, got {c} (n = {n}, kappa = {kappa})")
    lam = c - n
    w_i = 1.0 / (2.0 * c)
    w_m0 = 1.0 - n / c if variant == "corrected" else n / c      # lambda / (n + lambda) = 1 - n / (n + lambda)
    mean = np.full(2 * n + 1, w_i)
    cov = mean.copy()
    mean[0] = w_m0
    cov[0] = w_m0 + 1.0 - alpha**2 + beta
    return UnscentedWeights(mean, cov, float(lam))


_SIGMA_OVERFLOW = ("the state overflowed at step {step}: the readings predicted at its sigma points, or their "
                   "covariance, are not finite (the state was driven far out by a reading too large for float64 "
                   "arithmetic, e.g. 1.5e308 dBm or m, or by a huge F, Q or P0)")

_P_NOT_PD = ("the state covariance P is not positive definite at step {step}, so its Cholesky factor (the "
             "sigma-point spread of Eqs. (3.19)-(3.20)) does not exist; check P0, Q and the measurement noise")


def sigma_points(x, P, lam: float):
    """Sigma points ``batch + (2n + 1, n)`` around ``x`` ``batch + (n,)``: ``x``, ``x +- columns of
    chol((n + lam) P)`` (Eqs. (3.18)-(3.20) with the column index the print leaves out)."""
    return _sigma_points(x, P, lam)[0]


def _sigma_points(x, P, lam: float):
    """:func:`sigma_points` and the Cholesky factor ``L`` of ``(n + lam) P`` whose columns spread them."""
    n = x.shape[-1]
    try:
        L = np.linalg.cholesky((n + lam) * P)
    except np.linalg.LinAlgError:
        eig = np.linalg.eigvalsh(np.where(np.isfinite(P), P, 0.0))
        raise _Singular(~(eig[..., 0] > 0), _P_NOT_PD) from None
    cols = _mT(L)                                    # row i = column i of L
    X = np.empty(np.broadcast_shapes(x.shape[:-1], L.shape[:-2]) + (2 * n + 1, n))
    X[..., 0, :] = x
    np.add(x[..., None, :], cols, out=X[..., 1:n + 1, :])
    np.subtract(x[..., None, :], cols, out=X[..., n + 1:, :])
    return X, L


def _pair_differences(values, weights: UnscentedWeights):
    """``D`` with ``sum_i W_c^i (X^i - x)(v^i)^T = L D`` for a symmetric sigma-point set and values ``(..., 2n + 1,
    m)``: ``X^i - x = +-(column i of L)`` (zero for the centre) and ``W_c^i`` is the same for ``i >= 1``, so row i of
    D is ``W_c^1 (v^i - v^{n+i})``."""
    n = weights.n
    return weights.cov[1] * (values[..., 1:n + 1, :] - values[..., n + 1:, :])


def unscented_transform(points, values, weights: UnscentedWeights):
    """Weighted mean ``(..., m)``, covariance ``(..., m, m)`` of ``values`` ``(..., 2n+1, m)`` and the
    cross-covariance ``(..., n, m)`` with ``points`` ``(..., 2n+1, n)`` (Eqs. (3.25)-(3.27), without R)."""
    mean = weights.mean @ values                     # sum_k W_m^k values^k (matmul, not einsum: BLAS over the batch)
    dv = values - mean[..., None, :]
    dx = points - points[..., :1, :]                 # X^0 is the mean of the sigma points
    wdv = _mT(weights.cov[:, None] * dv)             # (..., m, 2n+1): W_c^k (values^k - mean)
    cov = wdv @ dv
    cross = _mT(dx) @ _mT(wdv)
    return mean, 0.5 * (cov + _mT(cov)), cross


def _ukf_update(x, P, z, h, R, weights: UnscentedWeights, innovation_noise: bool, guard: list,
                want: bool = False, model=None, step: int = 0) -> _Out:
    """One unscented update with measurement function ``h`` (sigma points -> values); NaN rows of ``z`` are left
    out. ``guard[0]`` counts the updates whose ``R~`` needed flooring. Returns the posterior with the NIS
    ``nu^T S^{-1} nu`` of the components present (from the inverse that gives the gain), their number and the
    Gaussian log-likelihood ``log N(nu; 0, S)``; ``want``: also the innovation ``z - z^`` and ``S`` (NaN where
    missing). ``model``: a measurement model whose ``residual`` and ``mean_of`` replace the linear forms (their outputs
    checked for a user's model; ``step`` names the step), or None for the linear forms."""
    valid = np.isfinite(z)
    dof = valid.sum(axis=-1)
    if not valid.any():
        zero = np.zeros(x.shape[:-1])
        if not want:
            return _Out(x, P, zero, dof, zero)
        return _Out(x, P, zero, dof, zero, np.full(z.shape, np.nan), np.full(z.shape + (z.shape[-1],), np.nan))
    X, L = _sigma_points(x, P, weights.lam)
    nb = X.ndim - 2                                  # the run axes
    Y = h(X, valid[..., None, :])
    n, m = x.shape[-1], z.shape[-1]
    c = n + weights.lam                              # L L^T = c P
    meas = model if model is not None and not model.linear_residual else None
    if meas is not None:                             # its mean, e.g. a circular mean of bearings, or Eq. (3.25)
        z_hat = _checked(meas, "mean_of", meas.mean_of(Y, weights.mean), Y.shape[:-2] + Y.shape[-1:], valid, step, nb)
    else:
        z_hat = weights.mean @ Y                     # Eq. (3.25)
    dv = Y - z_hat[..., None, :] if meas is None else _checked(
        meas, "residual", meas.residual(Y, z_hat[..., None, :]), Y.shape, valid[..., None, :], step, nb)
    Pzz = _mT(weights.cov[:, None] * dv) @ dv        # Eq. (3.26) without R
    Pzz = 0.5 * (Pzz + _mT(Pzz))
    # P_xz = sum_i W_c^i (X^i - x-)(gamma^i - z^)^T (Eq. (3.27)) = L D, D = L^{-1} P_xz
    D = _pair_differences(dv, weights)
    S = Pzz + R if innovation_noise else Pzz
    S = np.broadcast_to(S, x.shape[:-1] + (m, m))
    row_ok = valid.any(axis=-1)
    if not valid.all():
        D = np.where(valid[..., None, :], D, 0.0)
        pair = valid[..., :, None] & valid[..., None, :]
        S = np.where(pair, S, np.eye(m))
    Pxz = L @ D
    bad = row_ok & _not_positive_definite(S)
    if m > 2 and not _clearly_well_conditioned(S, 2e3 * m * np.finfo(float).eps):
        # larger S: a tiny eigenvalue (e.g. P_zz without R, Eq. (3.26) as printed) would give a huge gain
        eig = np.linalg.eigvalsh(S)
        bad = bad | row_ok & ~(eig[..., 0] > 1e3 * m * np.finfo(float).eps * np.abs(eig[..., -1]))
    if bad.any():
        # sigma points far out (a state driven there by an overflowing reading): their readings or S overflow
        over = bad & ~(np.all(np.isfinite(Y), axis=(-2, -1)) & np.all(np.isfinite(S), axis=(-2, -1)))
        raise _Singular(over, _SIGMA_OVERFLOW) if over.any() else _Singular(bad)
    nu = np.where(valid, (z - z_hat) if meas is None else
                  _checked(meas, "residual", meas.residual(np.where(valid, z, z_hat), z_hat), z_hat.shape, valid,
                           step, nb), 0.0)
    S_use = S if row_ok.all() else np.where(row_ok[..., None, None], S, np.eye(m))
    S_inv = _inverse(S_use, row_ok)
    K = Pxz @ S_inv                                  # K = P_xz S^{-1}
    nis = np.where(row_ok, np.einsum("...i,...i->...", nu, (S_inv @ nu[..., None])[..., 0]), 0.0)
    ll = np.where(row_ok, _gaussian_log_likelihood(nis, _logdet(S_use), dof), 0.0)
    x_new = x + (K @ nu[..., None])[..., 0]
    if not np.all(np.isfinite(x_new)):
        raise _Singular(~np.all(np.isfinite(x_new), axis=-1), _UPDATE_OVERFLOW)
    # Joseph form with the statistically linearised H~ = P_xz^T P^{-1} and R~ = S - H~ P H~^T (module docstring),
    # through L: H~ P H~^T = c D^T D and (I - K H~) P (I - K H~)^T = M M^T / c with M = (I - K H~) L = L - c K D^T
    Rt = S - c * (_mT(D) @ D)
    Rt = 0.5 * (Rt + _mT(Rt))
    if not _clearly_well_conditioned(Rt, 1e3 * m * np.finfo(float).eps):
        # R~ may have a negative eigenvalue: the guard (eigen-decomposition, floored at 0)
        w, v = np.linalg.eigh(Rt)
        floor = w < 0
        if floor.any():
            guard[0] += int(np.any(floor, axis=-1).sum())
            Rt = (v * np.maximum(w, 0.0)[..., None, :]) @ _mT(v)
    M = L - c * (K @ _mT(D))
    P_new = (M @ _mT(M)) / c + K @ Rt @ _mT(K)
    P_new = 0.5 * (P_new + _mT(P_new))
    keep = ~row_ok
    if keep.any():
        x_new = np.where(keep[..., None], x, x_new)
        P_new = np.where(keep[..., None, None], P, P_new)
    if not want:
        return _Out(x_new, P_new, nis, dof, ll)
    nu_out, S_out = _missing_as_nan(nu, S, valid)
    return _Out(x_new, P_new, nis, dof, ll, nu_out, S_out)


def _inverse(A, active):
    """Inverse of a batch of small matrices (closed form for 1 x 1 and 2 x 2, else LAPACK's inv, which is faster than
    its batched solve on such matrices); a singular one raises _Singular naming the ``active`` runs concerned."""
    if A.shape[-1] <= 2:
        return _inv_small(A)
    try:
        return np.linalg.inv(A)
    except np.linalg.LinAlgError:
        raise _Singular(_singular_runs(A, active)) from None


def _clearly_well_conditioned(A, rel):
    """True when ``A - rel * bound * I`` has a Cholesky factor for every symmetric matrix of the batch ``A`` (``bound``
    its largest absolute row sum, at least its largest |eigenvalue|): then every smallest eigenvalue is above about
    ``rel`` times the largest. A cheap sufficient test that lets the common case skip an eigen-decomposition; False
    means "compute the eigenvalues" (the callers' margins are twice the round-off of either computation)."""
    bound = np.abs(A).sum(axis=-1).max(axis=-1)
    try:
        np.linalg.cholesky(A - (rel * bound)[..., None, None] * np.eye(A.shape[-1]))
    except np.linalg.LinAlgError:
        return False
    return True


def _checked(model, what: str, value, shape, present, step: int, batch_ndim: int):
    """A model's ``residual`` or ``mean_of`` output, checked for a user's model (real, of ``shape``, finite where a
    reading is ``present``)."""
    if model.checks_own_output:
        return value
    name = f"{model.label}: {model.function_name(what)}"
    out = function_output(name, value, shape, 1, np.shape(value))
    _refuse_not_finite(name, out, present & ~np.isfinite(out), batch_ndim, step, _PRESENT)
    return out


_PRESENT = ("for a reading that is present: it must be finite wherever z has a reading (a missing reading is a NaN "
            "in z, not in the model's output)")


def _model_function(model, step: int, row=None):
    """``h`` over sigma points ``batch + (N, n)`` from the model's mean (checked for a user's model), all readings or
    the one reading ``row`` (an int or per-run indices ``batch``) of a serial update."""
    m = model.n_readings

    def h(X, present):
        Y = model.mean(X, step=step)
        if not model.checks_own_output:
            Y = check_output(model, "mean", Y, X, (m,), present if row is None else True, step)
        return Y if row is None else _row(Y, row if isinstance(row, int) else row[..., None], -1)[..., None]
    return h


def _model_noise(model, x, step: int):
    """``R`` at the predicted mean ``x`` ``batch + (n,)`` (the model's covariance at the one point)."""
    return model.covariance_at(x, step=step)


def _unscented_stream_update(x, P, z, stream, step: int, want: bool, weights, innovation_noise: bool, guard: list):
    """The UKF update of one stream: one unscented update of all its readings, or (serial) one per reading in the
    stream's order, each with fresh sigma points (Gudipati 2017, Sec. 3.6, corrected)."""
    model = stream.model
    if stream.mode == "parallel":
        return _ukf_update(x, P, z, _model_function(model, step), _model_noise(model, x, step), weights,
                           innovation_noise, guard, want, model, step)
    m = z.shape[-1]
    order = _serial_order(z, stream.order)
    a: Any      # reading j, or per run an array of indices when the stream has an order
    dof: np.ndarray | int
    acc, dof = _Serial(x.shape[:-1], m, want), 0
    for j in range(m):
        a = j if order is None else order[..., j]
        zj = z[..., j:j + 1] if order is None else np.take_along_axis(z, a[..., None], -1)
        R = np.asarray(_model_noise(model, x, step), dtype=float)
        Rj = R[..., j:j + 1, j:j + 1] if order is None else _diagonal_entry(R, a)[..., None, None]
        o = _ukf_update(x, P, zj, _model_function(model, step, a), Rj, weights, innovation_noise, guard, want, model,
                        step)
        x, P, dof = o.x, o.P, dof + o.dof
        acc.add(o.nu[..., 0] if want else None, o.S[..., 0, 0] if want else None, np.isfinite(zj[..., 0]), a,
                nis=o.nis, ll=o.ll)
    return acc.out(x, P, dof)


def _checked_motion(motion, field: str, value, shape, batch_ndim: int, step: int) -> np.ndarray:
    """The output of a motion model's ``mean`` or ``residual``, checked: real, of ``shape``, finite."""
    name = f"{motion.label}: {field}"
    out = function_output(name, value, shape, 1)
    _refuse_not_finite(name, out, ~np.isfinite(out), batch_ndim, step,
                       "for finite states: it must return finite values")
    return out


def _unscented_predictor(setup, weights: UnscentedWeights):
    """The unscented prediction through a NonlinearMotion (:mod:`locbook.tracking.transition`): sigma points ``X`` of
    the posterior, ``Y = f(X) + B u``, ``x- = sum W_m Y`` (or the motion's mean), ``P- = sum W_c (Y - x-)(Y - x-)^T +
    Q`` and the cross-covariance ``sum W_c (X - x)(Y - x-)^T`` (differences through the motion's residual)."""
    motion = setup.motion

    def predict(x, P, k, cross):
        X, L = _sigma_points(x, P, weights.lam)
        nb = X.ndim - 2                              # the run axes
        Y = _motion_apply(motion, X, k, nb)
        d = setup.drift_at(k)
        if d is not None:
            Y = Y + d[..., None, :]
        linear = motion.linear_differences
        if not linear:
            x_pred = _checked_motion(motion, "mean", motion.mean_of(Y, weights.mean), Y.shape[:-2] + Y.shape[-1:], nb,
                                     k)
        else:
            x_pred = weights.mean @ Y
        dY = Y - x_pred[..., None, :] if linear else _checked_motion(
            motion, "residual", motion.difference(Y, x_pred[..., None, :]), Y.shape, nb, k)
        wdY = weights.cov[:, None] * dY
        P_pred = _mT(dY) @ wdY
        P_pred = 0.5 * (P_pred + _mT(P_pred)) + setup.Q_at(k)
        C = L @ _pair_differences(dY, weights) if cross else None          # sum W_c (X - x)(Y - x-)^T
        return x_pred, P_pred, C
    return predict


def unscented_kalman_filter(F, Q, x0, P0, measurements, *, B=None, u=None, alpha: float = 1e-3, beta: float = 2.0,
                            kappa: float = 0.0, variant: str = "corrected", points: str = "merwe",
                            innovation_noise: bool = True, record=None, predict_first: bool = True, outputs=(),
                            divergence_window: int | None = DIVERGENCE_WINDOW,
                            divergence_probability: float = DIVERGENCE_PROBABILITY,
                            weights: str | None = None) -> KalmanResult:
    """Unscented Kalman filter, vectorized over leading Monte-Carlo axes (Gudipati 2017, Sec. 3.6, corrected; see the
    module docstring for the printed errors and the covariance guard).

    Motion: a linear ``F`` (constant, with run axes or ``per_step``) is predicted exactly (the Kalman prediction, as
    the thesis's linear model has it); a :class:`~locbook.tracking.transition.NonlinearMotion` by the unscented
    transform of the posterior's sigma points through ``f`` (its ``mean`` and ``residual`` for states on a circle),
    ``P- = sum W_c (Y - x-)(Y - x-)^T + Q``; the control input ``B u`` is added to the prediction. ``points``: the
    sigma-point set (:func:`unscented_weights`: ``"merwe"``, ``"julier"``, ``"cubature"``).

    Same arguments, time loop and result (:class:`~locbook.tracking.results.KalmanResult`, whose
    ``floored_updates`` counts the (run, update) pairs whose ``R~`` had a negative eigenvalue floored by the guard of
    the module docstring) as :func:`locbook.extended_kalman_filter`. :class:`RssMeasurement` and
    :class:`NonlinearMeasurement` streams are updated by the unscented transform (serial RSS streams one anchor
    at a time, each with fresh sigma points); :class:`LinearMeasurement` streams go through the unscented
    transform too, which is exact for them (so the UKF equals the KF on a linear model, a tested invariant).

    ``alpha``, ``beta``, ``kappa``: sigma-point spread; defaults are the thesis's (alpha = 1e-3, beta = 2,
    kappa = 0). ``variant``: ``"corrected"`` or the flagged ``"literal_gudipati2017"`` (Eq. (3.22) as printed; the
    earlier keyword ``weights=`` is accepted for one release with a DeprecationWarning).
    ``innovation_noise=False``: Eq. (3.26) as printed, without R (flagged: with more measurements than the
    state's spread can explain, P_zz is singular and the update stops with a clear error).

    ``divergence_window``, ``divergence_probability``: the consistency guard of :mod:`locbook.tracking.results` (its
    module docstring). The UKF can lose track while its covariance stays symmetric positive definite (a sigma-point
    spread far beyond the measurement's linear range, e.g. sigma = 1e-3 dB with Q = 1e4 at alpha = 1; or the
    round-off of alpha = 1e-3 over 1e5 steps): its error then grows far beyond the reported covariance, the NIS
    exceeds the chi-square bound at every update and the run is flagged ``diverged`` (with ``diverged_step``).

    Speed: with numba installed, linear motion (F without run axes, Q per run or shared, no control input), streams of
    the library's linear, RSS and inertial (:class:`~locbook.models.imu.InertialMeasurement`) models and no ``outputs``,
    compiled loops run blocks of runs (:mod:`locbook.tracking._ukf_kernels`; ``LOCBOOK_NUMBA=0`` turns them off), else
    the numpy loop; both give the same numbers to round-off (amplified some 1e6 times at alpha = 1e-3).

    Examples
    --------
    On a linear model the UKF is the Kalman filter (the example of :func:`locbook.kalman_filter`):

    >>> import numpy as np
    >>> import locbook as lb
    >>> run = lb.unscented_kalman_filter([[1.0]], [[0.0]], [0.0], [[1.0]],
    ...                                  lb.LinearMeasurement([[2.0], [2.0]], [[1.0]], [[1.0]]))
    >>> print(np.round(run.mean[:, 0], 4))
    [1.     1.3333]
    """
    variant = old_keyword("unscented_kalman_filter", "weights", weights, "variant", variant, "corrected")
    check_choice("variant", variant, UKF_VARIANTS)
    window, probability = _check_guard(divergence_window, divergence_probability)
    outputs = _check_outputs(outputs)
    measurements = _streams(measurements)
    setup = _setup(F, Q, x0, P0, measurements, record, "unscented_kalman_filter", B, u)
    w = unscented_weights(setup.n, alpha, beta, kappa, variant, points)
    guard = [0]

    def update(x, P, z, meas, step, want):
        try:
            return _update(x, P, z, meas, step, want)
        except _Singular as exc:
            if exc.message:                  # the state covariance: already says what failed
                raise
            name = meas.name
            form = "P_zz + R" if innovation_noise else "P_zz without R (Eq. (3.26) as printed)"
            printed_weights = " with the printed weights of Eq. (3.22)" if variant == "literal_gudipati2017" else ""
            raise _Singular(exc.bad, f"the unscented innovation covariance S = {form} of the {name} update"
                                     f"{printed_weights} is singular, not positive definite or not finite at step "
                                     "{step}") from None

    def _update(x, P, z, meas, step, want):
        return _unscented_stream_update(x, P, z, meas, step, want, w, innovation_noise, guard)

    if not outputs:
        compiled = _compiled_ukf(setup, measurements, predict_first, w, innovation_noise)
        if compiled is not None:
            return _flag(compiled, window, probability)
    predict = _unscented_predictor(setup, w) if setup.motion is not None else None
    res = _run(setup, measurements, update, predict_first, outputs=outputs, predict=predict)
    return _flag(replace(res, floored_updates=guard[0]), window, probability)


def _compiled_ukf(setup, measurements, predict_first: bool, weights: UnscentedWeights, innovation_noise: bool):
    """The UKF by the compiled kernel (:mod:`locbook.tracking._ukf_kernels`) when it applies (numba installed and
    enabled, F without run axes (Q may have them) and no control input, LinearMeasurement, RssMeasurement and inertial
    streams, at least ``_NUMBA_MIN_WORK`` run-steps, the EKF's threshold), else None: the numpy loop then runs. Also
    None when an update fails or needs the eigenvalue guard on more than one reading (status of the kernel): the numpy
    loop then redoes the filter and raises the library's error or applies the guard."""
    from . import _compiled
    F, Q, batch, T = setup.F, setup.Q, setup.batch, setup.T
    B = int(np.prod(batch, dtype=np.int64))
    if not _compiled._NUMBA_ENABLED or not setup.plain_motion:
        return None                 # nonlinear or time-varying motion, a control input: numpy
    if F.ndim != 2 or B * T < _compiled._NUMBA_MIN_WORK or B == 0 or T == 0:
        return None
    if not (np.array_equal(Q, _mT(Q)) and np.array_equal(setup.P, _mT(setup.P))):
        return None                 # the kernel keeps P exactly symmetric
    n = setup.n
    if not _compiled._numba_ready():
        return None
    packing = _compiled._pack_streams(setup, measurements, B)
    if packing is None:
        return None
    packed, iner = packing
    nz, nnz = packed[2], packed[3]
    umax = np.array([nz[s, :nnz[s]].max() if nnz[s] else -1 for s in range(len(measurements))], dtype=np.int64)
    S = setup.steps.size
    Fi, Fj = np.nonzero(F)
    P0 = setup.P[None] if setup.P.ndim == 2 else np.broadcast_to(setup.P, batch + (n, n)).reshape(B, n, n)
    lanes = _compiled._block_width(B)
    out_x, out_P = np.empty((B, S, n)), np.empty((B, S, n, n))
    out_nis, out_dof, out_ll = np.empty((B, T)), np.empty((B, T), np.int64), np.empty((B, T))
    out_floored = np.zeros(B, np.int64)
    args = (Fi.astype(np.int64), Fj.astype(np.int64), np.ascontiguousarray(F[Fi, Fj]),
            _compiled._leading(Q, batch, B, (n, n)), np.ascontiguousarray(setup.x.reshape(B, n)),
            np.ascontiguousarray(P0), bool(predict_first),
            setup.slot.astype(np.int64), np.array(setup.active, dtype=np.bool_).reshape(-1, T), *packed, iner, umax,
            np.ascontiguousarray(weights.mean, dtype=float), np.ascontiguousarray(weights.cov, dtype=float),
            float(n + weights.lam), bool(innovation_noise),
            lanes, out_x, out_P, out_nis, out_dof, out_ll, out_floored, *_compiled._present(packed[0]))
    from . import _ukf_kernels  # lazy: numba loads only when the compiled path runs
    done = _compiled._call_kernel(_ukf_kernels._nb_ukf, args, "UKF")
    if done is None or done[0]:     # (status, block): a failed update, the numpy loop redoes the filter
        return None
    return KalmanResult(out_x.reshape(batch + (S, n)), out_P.reshape(batch + (S, n, n)), setup.steps,
                        log_likelihood=out_ll.reshape(batch + (T,)), nis=out_nis.reshape(batch + (T,)),
                        nis_dof=out_dof.reshape(batch + (T,)), floored_updates=int(out_floored.sum()))
