"""Online use of the Kalman family: one step of readings at a time, for many runs at once.

:class:`OnlineFilter` holds the posterior of every run (``batch + (n,)``, ``batch + (n, n)``) and, at each call of
:meth:`OnlineFilter.step`, predicts and updates with that step's readings by running the batch filter it wraps
(:func:`locbook.kalman_filter`, :func:`locbook.extended_kalman_filter` or :func:`locbook.unscented_kalman_filter`) on a
one-step problem from the held posterior. The arithmetic is therefore the batch filter's, step for step: a sequence of
calls gives the numbers of one batch call on the whole sequence (to round-off where the batch call picks its shared-
covariance or compiled path; a tested invariant).

The consistency guard of :mod:`locbook.tracking.results` runs online as well: each run's streak of NIS exceedances is
carried from step to step, so ``diverged`` and ``diverged_step`` are those the batch call would report.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .._validate import as_array
from .kalman import extended_kalman_filter, kalman_filter
from .results import DIVERGENCE_PROBABILITY, DIVERGENCE_WINDOW, KalmanResult, _check_guard
from .transition import NonlinearMotion, PerStep
from .unscented import unscented_kalman_filter

__all__ = ["OnlineFilter"]

_FILTERS = {"kf": kalman_filter, "ekf": extended_kalman_filter, "ukf": unscented_kalman_filter}


class OnlineFilter:
    """A Kalman-family filter fed one step at a time (module docstring).

    ``kind``: ``"kf"``, ``"ekf"`` or ``"ukf"``. ``F``, ``Q``, ``B``: the motion as the batch filters take it (a
    ``per_step`` matrix is indexed by the step counter; a :class:`~locbook.tracking.transition.NonlinearMotion` with
    ``uses_step`` sees the step counter too). ``x0``, ``P0``: as the batch filters' (``predict_first``: the first
    step predicts from them, else they are the prior of the first step). ``options``: the filter's other keywords
    (``joseph``, ``alpha``, ``points``, ``divergence_window``, ...; ``record`` and ``outputs`` are per step: every
    step's result holds its one step).

    :meth:`step` takes that step's measurement streams, their readings ``batch + (1, m)`` (one step), and optionally this step's ``F``, ``Q``, ``B``, ``u`` (``batch + (p,)``) in place of
    the constructor's; it returns the step's :class:`~locbook.tracking.results.KalmanResult` and keeps the posterior.
    """

    def __init__(self, kind: str, F, Q, x0, P0, *, B=None, predict_first: bool = True, outputs=(),
                 divergence_window: int | None = DIVERGENCE_WINDOW,
                 divergence_probability: float = DIVERGENCE_PROBABILITY, **options):
        if kind not in _FILTERS:
            raise ValueError(f"kind must be one of {sorted(_FILTERS)}, got {kind!r}")
        if "record" in options:
            raise ValueError("record has no meaning online: every step's result holds that step")
        self.kind = kind
        self.F, self.Q, self.B = F, Q, B
        self.x = np.array(as_array("x0", x0), dtype=float)
        self.P = np.array(as_array("P0", P0), dtype=float)
        self.step_index = 0
        self._predict_next = bool(predict_first)
        self._outputs = outputs
        self._options = options
        self._window, self._probability = _check_guard(divergence_window, divergence_probability)
        self.log_likelihood = 0.0
        self._streak = self._start = self.diverged = self.diverged_step = None

    def _at(self, value, k: int):
        """A constructor argument at step ``k``: a per-step matrix sliced to its step (kept per step), a step-aware
        motion shifted to the step counter."""
        if isinstance(value, PerStep):
            v = value.value
            return PerStep(v[..., min(k, v.shape[-3] - 1):min(k, v.shape[-3] - 1) + 1, :, :])
        if isinstance(value, NonlinearMotion) and value.uses_step:
            shift = lambda fn: None if fn is None else (lambda x, step: fn(x, step + k))
            return replace(value, f=shift(value.f), jacobian=shift(value.jacobian))
        return value

    def step(self, measurements, *, F=None, Q=None, B=None, u=None) -> KalmanResult:
        """Predict and update every run with one step's readings (class docstring); returns that step's result."""
        k = self.step_index
        streams = [measurements] if not isinstance(measurements, (list, tuple)) else list(measurements)
        streams = [_one_step(s) for s in streams]
        F = self._at(self.F, k) if F is None else F
        Q = self._at(self.Q, k) if Q is None else Q
        B = self._at(self.B, k) if B is None else B
        if u is not None:
            u = as_array("u", u, min_ndim=1)[..., None, :]
        res = _FILTERS[self.kind](F, Q, self.x, self.P, streams, B=B if u is not None else None, u=u,
                                  predict_first=self._predict_next, outputs=self._outputs, divergence_window=0,
                                  **self._options)
        self.x, self.P = res.x[..., -1, :], res.P[..., -1, :, :]
        self._predict_next = True
        self.step_index += 1
        self.log_likelihood = self.log_likelihood + np.nan_to_num(res.log_likelihood[..., -1])
        res = self._guard(res)
        return res

    def _guard(self, res: KalmanResult) -> KalmanResult:
        """Carry each run's streak of NIS exceedances (the rule of :func:`locbook.nis_divergence`) one step on."""
        nis, dof = res.nis[..., -1], res.nis_dof[..., -1]
        if self._streak is None:
            self._streak = np.zeros(nis.shape, np.int64)
            self._start = np.full(nis.shape, -1, np.int64)
            self.diverged = np.zeros(nis.shape, bool)
            self.diverged_step = np.full(nis.shape, -1, np.int64)
        if self._window:
            from scipy.special import chdtri          # lazy, as in results.py
            updated = (dof > 0) & ~np.isnan(nis)
            bound = np.where(updated, chdtri(np.maximum(dof, 1).astype(float), 1.0 - self._probability), np.inf)
            exceed = updated & (nis > bound)
            k = self.step_index - 1
            self._start = np.where(exceed & (self._streak == 0), k, self._start)
            self._streak = np.where(exceed, self._streak + 1, np.where(updated, 0, self._streak))
            newly = ~self.diverged & (self._streak >= self._window)
            self.diverged_step = np.where(newly, self._start, self.diverged_step)
            self.diverged = self.diverged | newly
        return replace(res, diverged=self.diverged.copy(), diverged_step=self.diverged_step.copy())


def _one_step(stream):
    """A stream of one step: readings ``batch + (1, m)`` (the step axis is required: ``(1, m)`` alone would be
    ambiguous between one run and one step)."""
    from .streams import LinearMeasurement, NonlinearMeasurement, RssMeasurement
    if not isinstance(stream, (LinearMeasurement, NonlinearMeasurement, RssMeasurement)):
        raise ValueError(f"measurements must be measurement streams, got {type(stream).__name__}")
    z = np.shape(stream.rss_dbm if isinstance(stream, RssMeasurement) else stream.z)
    if z[-2] != 1:
        raise ValueError(f"OnlineFilter.step takes one step of readings, batch + (1, m); got shape {z}")
    return stream
