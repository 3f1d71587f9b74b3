"""The motion side of the Kalman family: constant, time-varying and nonlinear transitions, with a control input.

Every Kalman-family filter (:func:`locbook.kalman_filter`, :func:`locbook.extended_kalman_filter`,
:func:`locbook.unscented_kalman_filter`) predicts step ``k`` from the posterior of step ``k - 1`` with

    x_{k|k-1} = F_k x_{k-1|k-1} + B_k u_k            P_{k|k-1} = F_k P_{k-1|k-1} F_k^T + Q_k        (linear)
    x_{k|k-1} = f(x_{k-1|k-1}) + B_k u_k             P_{k|k-1} = J P J^T + Q_k,  J = df/dx           (EKF)
    x_{k|k-1} = sum_i W_m^i f(X^i) + B_k u_k          P_{k|k-1} = sum_i W_c^i (Y^i - x)(Y^i - x)^T + Q_k (UKF)

(filterpy's convention: the matrices and control of index ``k`` act in the prediction *to* step ``k``; with
``predict_first=False`` step 0 is not predicted and index 0 is unused, pykalman's convention, whose offset ``b_{t-1}``
moves ``t - 1`` to ``t``, is then ``u_k = b_{k-1}`` with ``B = I``).

- ``F`` is a matrix ``(n, n)`` (or with run axes ``batch + (n, n)``), a matrix per step ``per_step(batch + (T, n, n))``
  or a :class:`NonlinearMotion` (``f`` with its Jacobian for the EKF, ``f`` alone for the UKF).
- ``Q`` is a covariance ``(n, n)`` / ``batch + (n, n)`` or ``per_step(batch + (T, n, n))``.
- The control input: ``u`` ``batch + (T, p)`` and ``B`` ``(n, p)`` / ``batch + (n, p)`` / ``per_step(batch + (T, n,
  p))``; ``B u`` is formed once for all steps.

A leading time axis is marked by :func:`per_step` because run axes are leading axes too: an array ``(T, n, n)``
without the mark is ``T`` runs of one constant matrix each.

Besides the posterior, a prediction gives the cross-covariance of the previous posterior and the prediction,
``C_k = Cov(x_{k-1}, x_k | z_1..z_{k-1})`` (``P F^T``, ``P J^T`` or the sigma points' ``sum W_c (X - x)(Y - x)^T``),
recorded on request as ``P_cross``: the one quantity a Rauch-Tung-Striebel smoother needs beyond the filter's moments,
so one smoother (:func:`locbook.rts_smoother`) serves the KF, the EKF and the UKF (the unscented RTS smoother).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .._validate import as_array, call_user, function_output
from ..models.base import LinearMotion, MotionModel, PerStep, per_state_hint, per_step

__all__ = ["PerStep", "per_step", "NonlinearMotion", "LinearMotion", "MotionModel"]


@dataclass(frozen=True)
class NonlinearMotion(MotionModel):
    """A nonlinear motion model ``x_k = f(x_{k-1}) + B u_k + w_k``, ``w_k ~ N(0, Q_k)`` (module docstring).

    ``f``: maps states ``(..., n)`` to ``(..., n)`` over any leading axes (the EKF calls it with the runs'
    posteriors ``batch + (n,)``, the UKF with their sigma points ``batch + (N, n)``). ``jacobian``: states ``(..., n)``
    to ``(..., n, n)``; the EKF needs it, the UKF does not. With ``uses_step=True`` both are called as ``f(x, k)``
    (``k`` the step predicted to), for a model whose time step varies.

    For states on a circle (a heading): ``residual(a, b)`` is the difference ``a - b`` of states (e.g. wrapped to
    ``(-pi, pi]``), used wherever the UKF subtracts states; ``mean(points, weights)`` the weighted mean of points
    ``(..., N, n)`` with weights ``(N,)`` (e.g. a circular mean); both default to the linear forms. ``name`` names the
    model in errors.
    """

    f: object
    jacobian: object = None
    residual: object = None
    mean: object = None
    uses_step: bool = False
    name: str = "motion"

    def __post_init__(self):
        for field in ("f", "jacobian", "residual", "mean"):
            value = getattr(self, field)
            if (value is not None or field == "f") and not callable(value):
                raise ValueError(f"{self.name}: {field} must be a function, got {type(value).__name__}")

    def _call(self, field: str, x, step: int):
        """The model's ``f`` or ``jacobian`` at ``x`` (``f(x)``, or ``f(x, k)`` with ``uses_step``); a function whose
        signature does not take those arguments (filterpy's ``fx(x, dt)``) is a one-line error saying what to pass."""
        form = f"{field}(x, k)" if self.uses_step else f"{field}(x)"
        hint = ("uses_step=False for f(x)" if self.uses_step else
                "bind the time step, e.g. NonlinearMotion(lambda x: fx(x, dt)), or uses_step=True for f(x, k) "
                "with k the step predicted to")
        args = (x, step) if self.uses_step else (x,)
        try:
            return call_user(getattr(self, field), args,
                             lambda exc: f"{self.name}: {field} cannot be called as {form} (states (..., n)"
                                         f"{', k the step' if self.uses_step else ''}): {exc}; {hint}")
        except Exception as exc:
            n = np.shape(x)[-1:]
            why = per_state_hint(f"{self.name}: {field}", getattr(self, field), x, args[1:],
                                 n if field == "f" else n * 2)
            if why is None:
                raise
            raise ValueError(f"{why} (it raised {type(exc).__name__}: {exc})") from None

    def apply(self, x, step: int = 0):
        """``f(x)`` (or ``f(x, step)``), checked to keep the state's shape and to be real (a complex output is
        refused, not cut to its real part)."""
        out = self._call("f", x, step)
        try:
            return np.asarray(function_output(f"{self.name}: f", out, np.shape(x), 1, np.shape(x)))
        except ValueError as exc:
            why = per_state_hint(f"{self.name}: f", self.f, x, (step,) if self.uses_step else (), np.shape(x)[-1:])
            if why is None:
                raise
            raise ValueError(f"{why} ({exc})") from None

    def jacobian_at(self, x, step: int = 0):
        """The Jacobian ``df/dx`` ``(..., n, n)`` at ``x`` (the EKF's), checked (an unbatched ``(n, n)`` kept as
        given)."""
        if self.jacobian is None:
            raise ValueError(f"{self.name}: the EKF needs the motion's jacobian (the UKF does not)")
        n = np.shape(x)[-1]
        return function_output(f"{self.name}: jacobian", self._call("jacobian", x, step), np.shape(x)[:-1] + (n, n), 2,
                               np.shape(x), broadcast=False)

    def difference(self, a, b):
        """``a - b`` of states, through ``residual`` when given."""
        return self.residual(a, b) if self.residual is not None else a - b

    def mean_of(self, points, weights):
        """The weighted mean of points, through ``mean`` when given."""
        return self.mean(points, weights) if self.mean is not None else weights @ points

    @property
    def linear_differences(self) -> bool:
        return self.residual is None and self.mean is None

    def shifted(self, k: int) -> "NonlinearMotion":
        """A step-aware motion whose step is counted from ``k`` (a one-step call sees step 0)."""
        if not self.uses_step:
            return self
        shift = lambda fn: None if fn is None else (lambda x, step: fn(x, step + k))
        return replace(self, f=shift(self.f), jacobian=shift(self.jacobian))


def _matrix_arg(name: str, value, rows: int, cols: int, T: int):
    """A matrix argument that may be constant (``batch + (rows, cols)``) or per step (``PerStep``, ``batch + (T, rows,
    cols)``): ``(array, per_step flag, run axes)``."""
    if isinstance(value, PerStep):
        arr = value.value
        if arr.shape[-2:] != (rows, cols) or arr.shape[-3] not in (1, T):
            raise ValueError(f"{name} per step must have shape batch + ({T}, {rows}, {cols}), got {arr.shape}")
        return arr, True, arr.shape[:-3]
    arr = as_array(name, value)
    if arr.ndim < 2 or arr.shape[-2:] != (rows, cols):
        raise ValueError(f"{name} must have shape ({rows}, {cols}) or batch + ({rows}, {cols}) (per_step(...) for a "
                         f"matrix per step), got {arr.shape}")
    return arr, False, arr.shape[:-2]


def _control_drift(B, u, n: int, T: int):
    """``B_k u_k`` ``batch + (T, n)`` for the control input (module docstring), or None without one; and its run
    axes."""
    if B is None and u is None:
        return None, ()
    if B is None or u is None:
        raise ValueError("a control input needs both B (n, p) and u batch + (T, p)")
    u = as_array("u", u, min_ndim=2)
    if u.shape[-2] not in (1, T):
        raise ValueError(f"u must have shape batch + ({T}, p) (one control vector per step), got {u.shape}")
    p = u.shape[-1]
    B, steps, _ = _matrix_arg("B", B, n, p, T)
    drift = np.einsum("...np,...p->...n", B if steps else B[..., None, :, :], u)
    return drift, drift.shape[:-2]
