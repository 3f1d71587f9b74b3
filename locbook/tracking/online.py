"""Online use of the Kalman family: one step of readings at a time, for many runs at once.

:class:`OnlineFilter` holds the posterior of every run (``batch + (n,)``, ``batch + (n, n)``) and, at each call of
:meth:`OnlineFilter.step`, predicts and updates with that step's readings by running the batch filter it wraps
(:func:`locbook.kalman_filter`, :func:`locbook.extended_kalman_filter` or :func:`locbook.unscented_kalman_filter`) on a
one-step problem from the held posterior. The arithmetic is therefore the batch filter's, step for step: a sequence of
calls gives the numbers of one batch call on the whole sequence (to round-off where the batch call picks its shared-
covariance or compiled path; a tested invariant).

The consistency guard of :mod:`locbook.tracking.results` runs online as well: the rule of
:func:`locbook.nis_divergence` on the NIS of every step so far, so ``diverged`` and ``diverged_step`` are those the
batch call would report.
"""
from __future__ import annotations

import inspect
from dataclasses import replace

import numpy as np

from .._validate import as_array
from .kalman import extended_kalman_filter, kalman_filter
from .results import DIVERGENCE_PROBABILITY, DIVERGENCE_WINDOW, KalmanResult, _check_guard, nis_divergence
from .streams import Stream
from .transition import MotionModel, PerStep
from .unscented import unscented_kalman_filter

__all__ = ["OnlineFilter", "KALMAN_FILTERS"]

#: the Kalman-family filters by kind
KALMAN_FILTERS = {"kf": kalman_filter, "ekf": extended_kalman_filter, "ukf": unscented_kalman_filter}


class OnlineFilter:
    """A Kalman-family filter fed one step at a time (module docstring).

    ``kind``: ``"kf"``, ``"ekf"`` or ``"ukf"``. ``F``, ``Q``, ``B``: the motion as the batch filters take it (a
    ``per_step`` matrix is indexed by the step counter, and stepping past its last step is an error, as in the batch
    call; a :class:`~locbook.tracking.transition.NonlinearMotion` with ``uses_step`` sees the step counter too). ``x0``,
    ``P0``: as the batch filters' (``predict_first``: the first step predicts from them, else they are the prior of the
    first step). ``options``: the filter's other keywords (``joseph``, ``alpha``, ``points``, ``divergence_window``,
    ...; ``record`` and ``outputs`` are per step: every step's result holds its one step).

    :meth:`step` takes that step's measurement streams, their readings ``batch + (1, m)`` (one step), and optionally
    this step's ``F``, ``Q``, ``B``, ``u`` (``batch + (p,)``) in place of the constructor's (this step's matrices: a
    ``per_step`` array is refused there; a step-aware NonlinearMotion sees the step counter); it returns the step's
    :class:`~locbook.tracking.results.KalmanResult` and keeps the posterior. Its ``diverged`` and ``diverged_step`` are
    the guard's verdict on every step so far (:func:`locbook.nis_divergence` on the NIS history), as the batch call on
    the same steps would give.

    Examples
    --------
    The example of :func:`locbook.kalman_filter`, one step at a time (readings ``(1, m)`` per step):

    >>> import numpy as np
    >>> import locbook as lb
    >>> online = lb.OnlineFilter("kf", [[1.0]], [[0.0]], [0.0], [[1.0]])
    >>> for z in (2.0, 2.0):
    ...     step = online.step(lb.LinearMeasurement([[z]], [[1.0]], [[1.0]]))
    ...     print(round(float(step.mean[0, 0]), 4))
    1.0
    1.3333
    """

    def __init__(self, kind: str, F, Q, x0, P0, *, B=None, predict_first: bool = True, outputs=(),
                 divergence_window: int | None = DIVERGENCE_WINDOW,
                 divergence_probability: float = DIVERGENCE_PROBABILITY, **options):
        if kind not in KALMAN_FILTERS:
            raise ValueError(f"kind must be one of {sorted(KALMAN_FILTERS)}, got {kind!r}")
        for name in ("record", "u"):
            if name in options:
                raise ValueError(f"{name} is not an option of OnlineFilter: " + (
                    "every step's result holds that step" if name == "record" else "u goes to step(), one step at a "
                    "time"))
        try:                        # a misspelt option is named now, not at the first step
            inspect.signature(KALMAN_FILTERS[kind]).bind_partial(**options)
        except TypeError:
            known = set(inspect.signature(KALMAN_FILTERS[kind]).parameters)
            raise ValueError(f"unknown option(s) of the {kind} filter: {sorted(set(options) - known)}") from None
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
        self._nis: list[np.ndarray] = []
        self._dof: list[np.ndarray] = []

    def _at(self, value, k: int, name: str):
        """A constructor argument at step ``k``: a per-step matrix sliced to its step (kept per step), a step-aware
        motion shifted to the step counter."""
        if isinstance(value, PerStep):
            v = value.value
            if k >= v.shape[-3] and v.shape[-3] != 1:
                raise ValueError(f"{name} per step has {v.shape[-3]} steps; step {k} is past its end")
            return PerStep(v[..., min(k, v.shape[-3] - 1), None, :, :])
        return _shifted(value, k)

    def step(self, measurements, *, F=None, Q=None, B=None, u=None) -> KalmanResult:
        """Predict and update every run with one step's readings (class docstring); returns that step's result."""
        k = self.step_index
        streams = [measurements] if not isinstance(measurements, (list, tuple)) else list(measurements)
        streams = [_one_step(s) for s in streams]
        for name, value in (("F", F), ("Q", Q), ("B", B)):
            if isinstance(value, PerStep):
                raise ValueError(f"step()'s {name} is this step's matrix; a per_step array goes to the constructor")
        F = self._at(self.F, k, "F") if F is None else _shifted(F, k)
        Q = self._at(self.Q, k, "Q") if Q is None else Q
        B = self._at(self.B, k, "B") if B is None else B
        if u is not None:
            u = as_array("u", u, min_ndim=1)[..., None, :]
        res = KALMAN_FILTERS[self.kind](F, Q, self._prior_for(streams), self.P, streams,
                                        B=B if u is not None else None, u=u,
                                        predict_first=self._predict_next, outputs=self._outputs, divergence_window=0,
                                        **self._options)
        # every Kalman-family filter records these three (None only in a result built by hand)
        assert res.log_likelihood is not None and res.nis is not None and res.nis_dof is not None
        self.x, self.P = res.mean[..., -1, :], res.cov[..., -1, :, :]
        self._predict_next = True
        self.step_index += 1
        self.log_likelihood = self.log_likelihood + np.nan_to_num(res.log_likelihood[..., -1])
        self._nis.append(res.nis[..., -1])
        self._dof.append(res.nis_dof[..., -1])
        diverged, step = nis_divergence(np.stack(self._nis, axis=-1), np.stack(self._dof, axis=-1), self._window,
                                        self._probability)
        return replace(res, diverged=diverged, diverged_step=step)

    def _prior_for(self, streams):
        """The posterior so far with the readings' run axes: a step's readings are ``batch + (1, m)`` by this class's
        rule, so runs of one reading each are runs (the batch filters refuse ``(B, 1, 1)`` readings with a prior
        without run axes as ambiguous with a column of B readings; here it is not)."""
        try:
            batch = np.broadcast_shapes(*(np.shape(s.z)[:-2] for s in streams), self.x.shape[:-1])
        except ValueError:
            return self.x           # the filter names the axes that do not broadcast
        return np.broadcast_to(self.x, batch + self.x.shape[-1:])


def _shifted(motion, k: int):
    """A motion model whose step is counted from ``k`` (a one-step call sees step 0:
    :meth:`~locbook.models.base.MotionModel.shifted`); matrices as they are."""
    return motion.shifted(k) if isinstance(motion, MotionModel) and not motion.linear else motion


def _one_step(stream):
    """A stream of one step: readings ``batch + (1, m)`` (the step axis is required: ``(1, m)`` alone would be
    ambiguous between one run and one step)."""
    if not isinstance(stream, Stream):
        raise ValueError(f"measurements must be measurement streams, got {type(stream).__name__}")
    z = np.shape(stream.z)
    if z[-2] != 1:
        raise ValueError(f"OnlineFilter.step takes one step of readings, batch + (1, m); got shape {z}")
    return stream
