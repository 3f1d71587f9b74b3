"""Fixed-lag smoothing of a Kalman-family run: the state of step k - L given the readings up to step k.

The fixed-lag estimate ``x_{k-L|k}``, ``P_{k-L|k}`` is the Rauch-Tung-Striebel smoother run on the filter's moments of
steps 0 .. k alone: the backward pass of the RTS smoother (S. Sarkka, "Bayesian Filtering and Smoothing", Cambridge
University Press, 2013, Theorem 8.2; Ch. 8 on fixed-lag smoothing) over the window [k - L, k] from ``x_{k|k}``,
``P_{k|k}``. The filter is causal, so the moments of steps 0 .. k do not depend on later readings, and
the RTS gains ``C_j = D_{j+1} P_{j+1|j}^{-1}`` (``D_{j+1} = Cov(x_j, x_{j+1})``, the run's ``P_cross``) depend on the
filter moments only, not on the window: the gains of :func:`locbook.rts_smoother` on the whole run serve every window.
For every window end k the backward recursion (Sarkka 2013, Theorem 8.2; with the sigma points' ``D`` the unscented
RTS smoother, S. Sarkka, IEEE TAC 53(3), 2008)

    ``x_{j|k} = x_j + C_j (x_{j+1|k} - x_{j+1|j})``,
    ``P_{j|k} = P_j + C_j (P_{j+1|k} - P_{j+1|j}) C_j^T``,   j = k - 1, ..., k - L, from ``x_{k|k}``, ``P_{k|k}``,

is applied to all windows at once (a loop over the L lag offsets, vectorized over the windows and the run axes), so
the result is exact: the RTS smoother of the run truncated at step k, to round-off, for the KF, the EKF and the UKF's
unscented RTS smoother alike (the singular-prediction rule of :mod:`locbook.tracking.smoother` included, since the
gains are its). Cost: ``O(L T n^3)`` per run, against ``O(T n^3)`` for the full-interval smoother.

State augmentation (the state stacked with its L past copies and one Kalman filter on it; B. D. O. Anderson and J. B.
Moore, "Optimal Filtering", 1979, Sec. 7.3) gives the same numbers and is the tests' independent oracle.
:class:`OnlineFixedLagSmoother` is the same smoother fed one filter step at a time.
"""
from __future__ import annotations

import numbers
from collections import deque
from dataclasses import dataclass

import numpy as np

from .._validate import as_array, check_scalar
from .results import FilterResult, KalmanResult
from .smoother import check_predictions, rts_smoother
from .transition import PerStep

__all__ = ["FixedLagResult", "fixed_lag_smoother", "OnlineFixedLagSmoother"]


@dataclass(frozen=True)
class FixedLagResult(FilterResult):
    """The fixed-lag estimates of a run with T steps and state size n (``batch``: the run's leading axes).

    - ``mean`` ``batch + (R, n)``, ``cov`` ``batch + (R, n, n)``: row i is the estimate of step ``steps[i]`` given the
      readings of steps 0 .. ``given_to[i]`` (``x`` and ``P``, the earlier names: deprecated aliases);
    - ``steps`` ``(R,)``: the step each row estimates (for :func:`fixed_lag_smoother` every step, ``0 .. T - 1``);
    - ``given_to`` ``(R,)``: the last step whose readings the row uses, ``min(steps + lag, T - 1)``;
    - ``lag``: the lag L asked for (a lag of T - 1 or more gives the full-interval smoother);
    - ``log_likelihood`` ``batch + (T,)``, ``diverged``, ``diverged_step`` ``batch``: the filter run's, carried over
      (as :class:`~locbook.tracking.smoother.SmoothedResult` carries them); None from
      :meth:`OnlineFixedLagSmoother.tail`, which is fed moments only.
    """

    _RENAMED = {"x": "mean", "P": "cov"}

    mean: np.ndarray
    cov: np.ndarray
    lag: int
    steps: np.ndarray
    given_to: np.ndarray
    log_likelihood: np.ndarray | None = None
    diverged: np.ndarray | None = None
    diverged_step: np.ndarray | None = None


def _check_lag(lag) -> int:
    """``lag`` a non-negative integer (an integral float is accepted, as elsewhere in locbook), else one line."""
    if isinstance(lag, (bool, np.bool_)) or not isinstance(lag, (numbers.Integral, float, np.floating)):
        raise ValueError(f"lag must be a non-negative integer (a number of steps), got {lag!r}")
    check_scalar("lag", lag, ge=0, integer=True)
    return int(lag)


def _rts(result, F, residual, caller: str):
    """:func:`rts_smoother` of ``result``; its own refusals of a broken result re-worded for ``caller``."""
    try:
        return rts_smoother(result, F, residual=residual)
    except ValueError as exc:
        text = str(exc)
        if not text.startswith("rts_smoother"):
            raise                   # a refusal naming an argument (F, residual) or the user's residual's own error
        raise ValueError(caller + text[len("rts_smoother"):]) from None


def _differ(residual):
    """``a - b`` of states, or the caller's ``residual(a, b)`` checked to keep the states' shape."""
    if residual is None:
        return lambda a, b: a - b

    def diff(a, b):
        out = np.asarray(residual(a, b), dtype=float)
        if out.shape != a.shape:
            raise ValueError(f"residual(a, b) must return the states' shape {a.shape}, got {out.shape}")
        return out
    return diff


def fixed_lag_smoother(result: KalmanResult, lag: int, *, F=None, residual=None) -> FixedLagResult:
    """Fixed-lag smoother of a filter run (module docstring): every step's state given the readings up to ``lag``
    steps later.

    Convention: the result has a row for every step j = 0 .. T - 1 (``steps = arange(T)``). Row j is the estimate of
    step j given the readings of steps 0 .. ``given_to[j] = min(j + lag, T - 1)``: for ``j < T - lag`` the fixed-lag
    estimate ``x_{j|j+L}``, ``P_{j|j+L}`` (what an online smoother reports at step j + L), for the last ``lag`` steps
    the estimates given all the readings (there is no later reading to wait for; they equal the full-interval RTS
    smoother's). So ``lag=0`` gives the filter's ``mean``, ``cov`` and ``lag >= T - 1`` gives
    :func:`locbook.rts_smoother` on the whole run. Row j equals ``rts_smoother`` of the run truncated at step
    ``given_to[j]``, its row j.

    ``result``, ``F``, ``residual``: as :func:`locbook.rts_smoother` takes them (a standard run that recorded every
    step with ``outputs=("x_pred", "P_pred", "P_cross")``, or without ``P_cross`` its linear motion ``F``;
    ``residual(a, b)`` the difference of states, called with arrays ``batch + (W, n)`` of several windows at once).
    ``lag``: a non-negative integer. Vectorized over the run axes and the windows (the loop runs over the lag
    offsets)."""
    L = _check_lag(lag)
    if isinstance(result, KalmanResult):
        check_predictions(result, "fixed_lag_smoother needs")
    # rts_smoother checks the run (shapes, every step recorded, finite covariances, F) and gives the gains C_j, the
    # same for every window, and the last rows (given all the readings)
    full = _rts(result, F, residual, "fixed_lag_smoother")
    x, P = np.asarray(result.mean, float), np.asarray(result.cov, float)
    T = x.shape[-2]
    steps = np.arange(T)
    given_to = np.minimum(steps + min(L, T), T - 1) if T else steps
    carried = (full.log_likelihood, full.diverged, full.diverged_step)      # the run's (rts_smoother carries them)
    if L >= T - 1 or x.size == 0:          # no window ends before the last step: the full-interval smoother
        return FixedLagResult(full.mean, full.cov, L, steps, given_to, *carried)
    x_pred, P_pred = np.asarray(result.x_pred, float), np.asarray(result.P_pred, float)
    gain = full.gain
    diff = _differ(residual)
    W = T - L                               # windows ending at e = L .. T - 1, each giving the row of step e - L
    xs = x[..., L:, :]
    for i in range(1, L + 1):               # offset i: step j = e - i of every window
        j, j1 = slice(L - i, T - i), slice(L - i + 1, T - i + 1)
        xs = x[..., j, :] + np.einsum("...ij,...j->...i", gain[..., j, :, :], diff(xs, x_pred[..., j1, :]))
    Ps = P[..., L:, :, :]
    for i in range(1, L + 1):
        j, j1 = slice(L - i, T - i), slice(L - i + 1, T - i + 1)
        C = gain[..., j, :, :]
        Pj = P[..., j, :, :] + C @ (Ps - P_pred[..., j1, :, :]) @ np.swapaxes(C, -1, -2)
        Ps = 0.5 * (Pj + np.swapaxes(Pj, -1, -2))       # symmetric, as the RTS smoother keeps it
    x_out = np.concatenate([xs, full.mean[..., W:, :]], axis=-2)
    P_out = np.concatenate([Ps, full.cov[..., W:, :, :]], axis=-3)
    return FixedLagResult(x_out, P_out, L, steps, given_to, *carried)


class OnlineFixedLagSmoother:
    """:func:`fixed_lag_smoother` fed one filter step at a time, for all runs at once.

    ``lag``: L, a non-negative integer. ``F`` (``(n, n)``, optional run axes): the linear motion, used for the
    cross-covariance ``D_k = P_{k-1} F^T`` of a step fed without ``P_cross`` (one F for every step; a per-step motion
    passes each step's ``P_cross``). ``residual(a, b)``: the difference of states, as :func:`locbook.rts_smoother`.

    :meth:`update` takes the new step's filter moments (``x`` ``batch + (n,)``, ``P``, ``x_pred``, ``P_pred``,
    ``P_cross`` ``batch + (n, n)``: a :class:`~locbook.tracking.results.KalmanResult`'s ``mean``, ``cov``, ``x_pred``,
    ``P_pred``, ``P_cross`` at that step;
    :meth:`step` takes a one-step KalmanResult, e.g. from :meth:`locbook.OnlineFilter.step` with ``outputs=("x_pred",
    "P_pred", "P_cross")``). It keeps the last L + 1 steps and, from the (L + 1)-th step k = L on, returns ``(x, P)``
    of step k - L given the readings to step k, the RTS smoother of the buffered window (module docstring); before
    that it returns None. :meth:`tail` gives the steps not yet returned, given every step fed so far. A sequence of
    T updates therefore returns rows 0 .. T - L - 1 of :func:`fixed_lag_smoother` of the batch run, and ``tail()``
    its last rows (to round-off). Cost per step: one RTS pass over L + 1 steps."""

    def __init__(self, lag: int, *, F=None, residual=None):
        self.lag = _check_lag(lag)
        if isinstance(F, PerStep):
            raise ValueError("F of OnlineFixedLagSmoother is one (n, n) matrix (optional run axes); for a per-step "
                             "motion pass each step's P_cross to update()")
        self._F = None if F is None else as_array("F", F, min_ndim=2)
        if self._F is not None and self._F.shape[-1] != self._F.shape[-2]:
            raise ValueError(f"F must be square (n, n) with optional run axes, got shape {self._F.shape}")
        if residual is not None and not callable(residual):
            raise ValueError(f"residual must be a callable residual(a, b) -> a - b of states, got "
                             f"{type(residual).__name__}")
        self._residual = residual
        self._buffer: deque = deque(maxlen=self.lag + 1)
        self._shapes = None
        self.count = 0                      # steps fed so far

    def update(self, x, P, x_pred, P_pred, P_cross=None):
        """Feed step k = :attr:`count` (its moments, class docstring); return ``(x_{k-L|k}, P_{k-L|k})``
        (``batch + (n,)``, ``batch + (n, n)``) once k >= L, else None. ``P_cross`` (``Cov(x_{k-1}, x_k)``) may be
        None with the constructor's ``F``, and is not used at the first step (NaN there: not predicted)."""
        first = self.count == 0
        x = as_array("x", x, min_ndim=1, nan_ok=True)       # a NaN mean is carried as NaN (rts_smoother)
        n = x.shape[-1]
        P = as_array("P", P, min_ndim=2)
        x_pred = as_array("x_pred", x_pred, min_ndim=1, nan_ok=True)
        P_pred = as_array("P_pred", P_pred, min_ndim=2)
        square = x.shape + (n,)
        for name, a, want in (("P", P, square), ("x_pred", x_pred, x.shape), ("P_pred", P_pred, square)):
            if a.shape != want:
                raise ValueError(f"{name} must have shape {want} (x is {x.shape}), got {a.shape}")
        if self._shapes is not None and x.shape != self._shapes:
            raise ValueError(f"x must keep the shape {self._shapes} of the steps fed before, got {x.shape}")
        if P_cross is not None:
            P_cross = as_array("P_cross", P_cross, nan_ok=first)
            if P_cross.shape != P.shape:
                raise ValueError(f"P_cross must have shape {P.shape} (that of P), got {P_cross.shape}")
        elif first:
            P_cross = np.full(P.shape, np.nan)
        elif self._F is None:
            raise ValueError("P_cross is needed at every step after the first (filter with outputs=('x_pred', "
                             "'P_pred', 'P_cross')), or give OnlineFixedLagSmoother its linear motion F")
        else:
            if self._F.shape[-1] != n:
                raise ValueError(f"F must be ({n}, {n}) (the state's size), got shape {self._F.shape}")
            try:        # D_k = P_{k-1} F^T (the linear model's cross-covariance, Sarkka 2013, Theorem 8.2)
                P_cross = np.broadcast_to(self._buffer[-1][1] @ np.swapaxes(self._F, -1, -2), P.shape).copy()
            except ValueError:
                raise ValueError(f"F's run axes {self._F.shape[:-2]} do not match the runs' {x.shape[:-1]}") from None
        self._shapes = x.shape
        self._buffer.append((x, P, x_pred, P_pred, P_cross))
        self.count += 1
        if self.count <= self.lag:
            return None
        smooth = self._window()
        return smooth.mean[..., 0, :], smooth.cov[..., 0, :, :]

    def step(self, result: KalmanResult):
        """:meth:`update` with the moments of a one-step :class:`~locbook.tracking.results.KalmanResult` that
        recorded ``x_pred``, ``P_pred`` (and ``P_cross``, or the constructor's ``F``)."""
        check_predictions(result, "OnlineFixedLagSmoother.step needs")
        if np.shape(result.mean)[-2:-1] != (1,):
            raise ValueError(f"result must hold one step, got a mean of shape {np.shape(result.mean)}")
        cross = None if result.P_cross is None else np.asarray(result.P_cross)[..., 0, :, :]
        return self.update(np.asarray(result.mean)[..., 0, :], np.asarray(result.cov)[..., 0, :, :],
                           np.asarray(result.x_pred)[..., 0, :], np.asarray(result.P_pred)[..., 0, :, :], cross)

    def tail(self) -> FixedLagResult:
        """The steps fed but not yet returned (the last ``min(lag, count)``), each given every step fed so far: the
        last rows of :func:`fixed_lag_smoother` on the run fed so far. ``steps`` and ``given_to`` as there."""
        m = min(self.lag, self.count)
        steps = np.arange(self.count - m, self.count)
        given_to = np.full(m, self.count - 1)
        if not self._buffer:
            return FixedLagResult(np.zeros((0, 0)), np.zeros((0, 0, 0)), self.lag, steps, given_to)
        smooth = self._window()
        first = smooth.mean.shape[-2] - m
        return FixedLagResult(smooth.mean[..., first:, :], smooth.cov[..., first:, :, :], self.lag, steps, given_to)

    def _window(self):
        """:func:`rts_smoother` of the buffered steps (its first step's P_cross, outside the window, is not used)."""
        x, P, x_pred, P_pred, cross = (np.stack(a, axis=-2 if i in (0, 2) else -3)
                                       for i, a in enumerate(zip(*self._buffer)))
        w = x.shape[-2]
        run = KalmanResult(x, P, np.arange(w), x_pred, P_pred, P_cross=cross)
        return _rts(run, None, self._residual, "OnlineFixedLagSmoother")
