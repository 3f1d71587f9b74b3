"""Fixed-interval smoothing of a Kalman-family run: every step's state given all the readings, past and future.

:func:`rts_smoother` is the Rauch-Tung-Striebel smoother (H. E. Rauch, F. Tung and C. T. Striebel, "Maximum
likelihood estimates of linear dynamic systems", AIAA Journal 3(8), 1965) on the filtered and predicted moments and
cross-covariances a :func:`~locbook.tracking.kalman.kalman_filter`,
:func:`~locbook.tracking.kalman.extended_kalman_filter` or :func:`~locbook.tracking.unscented.unscented_kalman_filter`
run records (for the UKF with nonlinear motion it is the
unscented RTS smoother), vectorized over the run's leading Monte-Carlo axes (the backward pass loops over time only).

A singular predicted covariance (a deterministic state: Q = 0 with a known start, a zero-variance component) has a
well-defined smoother: the gain ``C_k = D_{k+1} P_{k+1|k}^+`` with the Moore-Penrose pseudo-inverse gives the Gaussian
conditional mean for any generalized inverse, because ``D_{k+1}^T`` and ``x_{k+1} - x_{k+1|k}`` lie in the range of
``P_{k+1|k}`` (pykalman's smoother uses ``pinv`` throughout). A step of a run whose ``P_{k+1|k}`` has an eigenvalue at
or below :data:`PINV_RTOL` times its largest takes that pseudo-inverse (eigenvalues below the cut treated as 0); every
other step keeps the LU solve, so a regular run's numbers do not depend on another run being singular.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_array
from .results import FilterResult, KalmanResult
from .transition import PerStep

__all__ = ["SmoothedResult", "rts_smoother", "PINV_RTOL"]

#: a predicted covariance whose smallest eigenvalue is at most this fraction of its largest is singular for the
#: smoother (module docstring): its directions below the cut are deterministic, and their round-off residue (some
#: 1e-16 of the scale) is not inverted
PINV_RTOL = 1e-12


@dataclass(frozen=True)
class SmoothedResult(FilterResult):
    """``mean`` ``batch + (T, n)`` and ``cov`` ``batch + (T, n, n)``: the smoothed means and covariances at every
    step (``x`` and ``P``, earlier names: deprecated aliases); ``gain`` ``batch + (T - 1, n, n)``: the smoother gains
    ``C_k = P_k F^T P_{k+1|k}^{-1}``. The rest of the result vocabulary
    (:class:`~locbook.tracking.results.FilterResult`) is the filter run's, carried over: ``steps`` (every step),
    ``log_likelihood`` (the readings' likelihood is that of the filter: smoothing conditions on the same readings),
    ``diverged`` and ``diverged_step`` (the NIS guard on the filter's innovations); None in a result built without
    them."""

    _RENAMED = {"x": "mean", "P": "cov"}

    mean: np.ndarray
    cov: np.ndarray
    gain: np.ndarray
    steps: np.ndarray | None = None
    log_likelihood: np.ndarray | None = None
    diverged: np.ndarray | None = None
    diverged_step: np.ndarray | None = None


def check_predictions(result, who: str) -> None:
    """Refuse, in one line starting with ``who`` (e.g. ``"rts_smoother needs"``), a result that is not a standard
    Kalman-family run with its predictions (what every smoother of this package starts from)."""
    if not isinstance(result, KalmanResult):
        raise TypeError(f"result must be a KalmanResult, got {type(result).__name__}")
    if result.variant != "corrected":
        raise ValueError(f"{who} a run of the corrected update: the {result.variant!r} variant's x_pred and P_pred are "
                         "the previous posterior, not a prediction")
    if result.x_pred is None or result.P_pred is None:
        raise ValueError(f"{who} the run's predictions (result.x_pred, result.P_pred): filter with "
                         "outputs=('x_pred', 'P_pred', 'P_cross')")


def rts_smoother(result: KalmanResult, F=None, *, residual=None) -> SmoothedResult:
    """Rauch-Tung-Striebel smoother of a filter run (the KF, the EKF, and the UKF's unscented RTS smoother):

    ``C_k = D_{k+1} P_{k+1|k}^{-1}``, ``x^s_k = x_k + C_k (x^s_{k+1} - x_{k+1|k})``,
    ``P^s_k = P_k + C_k (P^s_{k+1} - P_{k+1|k}) C_k^T``, from ``x^s_{T-1} = x_{T-1}``, ``P^s_{T-1} = P_{T-1}``,

    where ``D_{k+1} = Cov(x_k, x_{k+1})`` is the cross-covariance of the posterior of step k and the prediction of step
    k + 1: ``P_k F^T`` for linear motion, ``P_k J^T`` for the EKF's, the sigma points' ``sum W_c (X - x)(Y - x-)^T``
    for the UKF's (S. Sarkka, "Unscented Rauch-Tung-Striebel smoother", IEEE TAC 53(3), 2008; filterpy's
    ``UnscentedKalmanFilter.rts_smoother``).

    ``result``: a run that recorded every step and its predictions, ``outputs=("x_pred", "P_pred", "P_cross")`` with
    ``record=None`` (the filter's own Q, control input and motion are in them). Without ``P_cross``, ``F`` (``(n,
    n)``, with the run's leading axes, or ``per_step(batch + (T, n, n))``, F_k moving step k - 1 to step k) gives
    ``D_{k+1} = P_k F_{k+1}^T``. ``residual(a, b)``: the difference of states (e.g. a wrapped heading; the motion's
    ``residual``). A step without readings is smoothed like any other (its posterior is its prediction). A singular
    ``P_{k+1|k}`` takes the pseudo-inverse (module docstring); a run of zero runs, of no step or of one step is returned
    as it is (no step: empty arrays, no gain);
    covariances that are not finite, or arrays of the wrong shapes (a result built by hand), are refused in one line.

    Examples
    --------
    With no process noise every smoothed step is the last posterior (the example of :func:`locbook.kalman_filter`):

    >>> import numpy as np
    >>> import locbook as lb
    >>> run = lb.kalman_filter([[1.0]], [[0.0]], [0.0], [[1.0]], lb.LinearMeasurement([[2.0], [2.0]], [[1.0]], [[1.0]]),
    ...                        outputs=("x_pred", "P_pred", "P_cross"))
    >>> smooth = lb.rts_smoother(run)
    >>> print(np.round(smooth.mean[:, 0], 4), np.round(smooth.cov[:, 0, 0], 4))
    [1.3333 1.3333] [0.3333 0.3333]
    """
    check_predictions(result, "rts_smoother needs")
    x, P = np.asarray(result.mean, float), np.asarray(result.cov, float)
    if x.ndim < 2 or P.shape != x.shape + x.shape[-1:]:
        raise ValueError(f"rts_smoother: the run's mean must be batch + (T, n) and cov batch + (T, n, n), got shapes "
                         f"{x.shape} and {P.shape}")
    T, n = x.shape[-2], x.shape[-1]
    steps = np.asarray(result.steps)
    if not np.array_equal(steps, np.arange(T)):
        raise ValueError("rts_smoother needs every step recorded (record=None), from step 0 on; got steps "
                         f"{steps[:5].tolist()}{'...' if steps.size > 5 else ''} of a run")
    batch = x.shape[:-2]
    if result.P_cross is not None:
        cross = np.asarray(result.P_cross, float)
    elif F is None:
        raise ValueError("rts_smoother needs the cross-covariances of the run (outputs=('x_pred', 'P_pred', "
                         "'P_cross')) or its linear motion F")
    else:
        cross = _cross_from_F(F, P, batch, T, n)
    x_pred, P_pred = np.asarray(result.x_pred, float), np.asarray(result.P_pred, float)
    for name, a, want in (("x_pred", x_pred, x.shape), ("P_pred", P_pred, P.shape), ("P_cross", cross, P.shape)):
        if a.shape != want:
            raise ValueError(f"rts_smoother: the run's {name} must have the shape {want} of its "
                             f"{'mean' if name == 'x_pred' else 'cov'}, got {a.shape}")
    # the covariances of a filter run are finite; NaN or inf here is a broken result (a NaN mean is carried as NaN)
    for name, a in (("cov", P), ("P_pred", P_pred), ("P_cross", cross[..., 1:, :, :])):
        bad = ~np.isfinite(a)
        if bad.any():
            at = tuple(int(i) for i in np.argwhere(bad)[0])
            step = at[len(batch)] + (name == "P_cross")
            raise ValueError(f"rts_smoother: the run's {name} is not finite at step {step}"
                             f"{f' of run {at[:len(batch)]}' if batch else ''} (entry {at[len(batch) + 1:]}); "
                             "the smoother needs the finite covariances of a filter run")
    if x.size == 0:                  # no run (a zero-length run axis), no step or no state: nothing to smooth
        return SmoothedResult(x.copy(), P.copy(), np.zeros(batch + (max(T - 1, 0), n, n)), *_carried(result))
    if residual is None:
        diff = lambda a, b: a - b
    elif not callable(residual):
        raise ValueError("residual must be a callable residual(a, b) -> a - b of states, "
                         f"got {type(residual).__name__}")
    else:
        def diff(a, b):
            out = np.asarray(residual(a, b), dtype=float)
            if out.shape != a.shape:
                raise ValueError(f"residual(a, b) must return the states' shape {a.shape}, got {out.shape}")
            return out
    if batch and _same_in_every_run(batch, P, P_pred, cross[..., 1:, :, :]):
        # one covariance recursion for every run (a linear filter's shared path): gains and covariances once
        one = (0,) * len(batch)
        gain, Ps = _covariance_pass(P[one], P_pred[one], cross[one])
    else:
        gain, Ps = _covariance_pass(P, P_pred, cross)
    xs = x.copy()
    for k in range(T - 2, -1, -1):
        xs[..., k, :] = x[..., k, :] + np.einsum("...ij,...j->...i", gain[..., k, :, :],
                                                 diff(xs[..., k + 1, :], x_pred[..., k + 1, :]))
    full = lambda a: a if a.shape[:-3] == batch else np.broadcast_to(a, batch + a.shape).copy()
    return SmoothedResult(xs, full(Ps), full(gain), *_carried(result))


def _carried(result: KalmanResult):
    """What a smoothed result carries of its filter run (:class:`SmoothedResult`): steps, log-likelihood, flags."""
    return result.steps, result.log_likelihood, result.diverged, result.diverged_step


def _same_in_every_run(batch, *arrays) -> bool:
    """True when each of ``arrays`` (``batch + (...)``) holds the same values in every run."""
    for a in arrays:
        flat = a.reshape((int(np.prod(batch)),) + a.shape[len(batch):])     # not -1: a may be empty (T = 1)
        if flat.shape[0] > 1 and not np.array_equal(flat, np.broadcast_to(flat[:1], flat.shape)):
            return False
    return True


def _covariance_pass(P, P_pred, cross):
    """The backward covariance recursion over leading run axes: gains ``C_k = D_{k+1} P_{k+1|k}^{-1}`` ``(..., T - 1,
    n, n)`` and smoothed covariances ``(..., T, n, n)`` (the means need the gains only). A singular ``P_{k+1|k}``
    (:func:`_singular`) takes the pseudo-inverse (module docstring), the others the LU solve."""
    T, n = P.shape[-3], P.shape[-1]
    gain, Ps = np.empty(P.shape[:-3] + (max(T - 1, 0), n, n)), P.copy()
    singular = _singular(P_pred[..., 1:, :, :])
    for k in range(T - 2, -1, -1):
        # C = D P_pred^{-1}, solved as (P_pred^{-1} D^T)^T (P_pred symmetric)
        Pp, Dt = P_pred[..., k + 1, :, :], np.swapaxes(cross[..., k + 1, :, :], -1, -2)
        sing = singular[..., k]
        if not sing.any():
            C = np.swapaxes(np.linalg.solve(Pp, Dt), -1, -2)
        else:
            C = np.empty(Pp.shape)
            if sing.ndim == 0:
                C[...] = _pinv_gain(Pp, Dt)
            else:
                C[sing] = _pinv_gain(Pp[sing], Dt[sing])
                if not sing.all():
                    C[~sing] = np.swapaxes(np.linalg.solve(Pp[~sing], Dt[~sing]), -1, -2)
        gain[..., k, :, :] = C
        Pk = P[..., k, :, :] + C @ (Ps[..., k + 1, :, :] - P_pred[..., k + 1, :, :]) @ np.swapaxes(C, -1, -2)
        Ps[..., k, :, :] = 0.5 * (Pk + np.swapaxes(Pk, -1, -2))
    return gain, Ps


def _singular(P_pred) -> np.ndarray:
    """Which of the symmetric ``P_pred`` ``(..., n, n)`` have their smallest eigenvalue at or below :data:`PINV_RTOL`
    times their largest (the mask ``(...)``). The eigenvalues are computed only where a Cholesky factor does not
    prove the matrix regular: for a positive definite ``A``, ``lambda_min >= det A / lambda_max^(n-1)`` and
    ``lambda_max <= tr A``, so ``det A > PINV_RTOL tr(A)^n`` (in logs) is enough; the decision is the eigenvalues'."""
    n = P_pred.shape[-1]
    out = np.zeros(P_pred.shape[:-2], bool)
    if out.size == 0:
        return out
    trace = np.trace(P_pred, axis1=-2, axis2=-1)
    try:
        L = np.linalg.cholesky(P_pred)
        with np.errstate(divide="ignore", invalid="ignore"):
            log_det = 2.0 * np.log(np.diagonal(L, axis1=-2, axis2=-1)).sum(axis=-1)
            sure = (trace > 0) & (log_det > np.log(PINV_RTOL) + n * np.log(trace))
    except np.linalg.LinAlgError:                 # some matrix is not positive definite: decide every one
        sure = np.zeros(out.shape, bool)
    check = ~sure
    if check.any():
        w = np.linalg.eigvalsh(P_pred[check])
        out[check] = w[:, 0] <= PINV_RTOL * w[:, -1]
    return out


def _pinv_gain(P_pred, Dt):
    """``C = D P_pred^+`` ``(..., n, n)`` from ``Dt = D^T``: the pseudo-inverse from the symmetric eigen-decomposition,
    eigenvalues at or below :data:`PINV_RTOL` times the largest (and any negative round-off) treated as 0."""
    w, V = np.linalg.eigh(P_pred)
    keep = w > PINV_RTOL * np.maximum(w[..., -1:], 0.0)
    inv_w = np.where(keep, 1.0 / np.where(keep, w, 1.0), 0.0)
    # C^T = V diag(1/w) V^T D^T
    Ct = V @ (inv_w[..., :, None] * (np.swapaxes(V, -1, -2) @ Dt))
    return np.swapaxes(Ct, -1, -2)


def _cross_from_F(F, P, batch, T: int, n: int):
    """``D_k = P_{k-1} F_k^T`` ``batch + (T, n, n)`` (index 0 unused) for linear motion ``F``."""
    if isinstance(F, PerStep):
        Fs = F.value                                 # checked finite by per_step
        if Fs.shape[-2:] != (n, n) or Fs.shape[-3] not in (1, T):
            raise ValueError(f"F per step must have shape batch + ({T}, {n}, {n}), got {Fs.shape}")
    else:
        Fs = as_array("F", F, min_ndim=2)
        if Fs.shape[-2:] != (n, n):
            raise ValueError(f"F must be ({n}, {n}) (the state's size), with optional run axes; got shape {Fs.shape}")
        Fs = Fs[..., None, :, :]
    try:
        Fs = np.broadcast_to(Fs, batch + (T, n, n))
    except ValueError:
        raise ValueError(f"F's run axes {Fs.shape[:-3]} do not match the run's {batch}") from None
    cross = np.full(batch + (T, n, n), np.nan)
    if T > 1:
        cross[..., 1:, :, :] = P[..., :-1, :, :] @ np.swapaxes(Fs[..., 1:, :, :], -1, -2)
    return cross
