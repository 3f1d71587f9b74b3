"""The result vocabulary of every filter, the result of every Kalman-family filter and the consistency guard on its
innovations.

One vocabulary (:class:`FilterResult`). Every filter result (:class:`KalmanResult`, the smoothers'
:class:`~locbook.tracking.smoother.SmoothedResult` and :class:`~locbook.tracking.fixed_lag.FixedLagResult`, the particle
and grid filters' :class:`~locbook.tracking.bayes.BayesFilterResult`) has

- ``mean`` ``batch + (R, n)`` and ``cov`` ``batch + (R, n, n)``: the posterior mean and covariance at ``steps``;
- ``steps`` ``(R,)``: the recorded step indices (every step, ``arange(T)``, for the particle and grid filters);
- ``log_likelihood`` ``batch + (T,)``: the per-step log-likelihood of the readings where the filter gives it exactly
  (the Kalman family; the smoothers carry their filter run's), else None;
- ``diverged`` ``batch`` (bool) and ``diverged_step`` ``batch`` (-1 where not), :attr:`~FilterResult.n_diverged`: filter
  divergence, by each family's own test: the NIS guard for the Kalman family (the smoothers carry their run's),
  the collapse of the likelihood for the particle and grid filters;
- :meth:`~FilterResult.position_m`: the mean's position components.

The old names (``x``, ``P``; ``mean_m``, ``covariance_m2``, ``degenerate``, ``degenerate_step``, ``n_degenerate``)
are kept for one release as read-only aliases that emit a ``DeprecationWarning`` naming the new one; given to a
constructor (or to ``dataclasses.replace``) an old field name is mapped to the new one with the same warning.

The layout of several streams' innovations (``S`` block diagonal over the sequential updates), what is kept in memory,
the guard's rule (NIS above ``chi2.ppf(divergence_probability, dof)`` at ``divergence_window`` consecutive updates) with
its exact false-alarm and detection probabilities, and why a run that overflows stops its whole batch: docs/filters.md,
"Results, innovations and the divergence guard".
"""

from __future__ import annotations

import sys
import warnings
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, TypeVar, cast

import numpy as np

from .._validate import as_array, check_scalar

if TYPE_CHECKING:
    from types import FrameType

__all__ = ["FilterResult", "KalmanResult", "nis_divergence", "nees", "DIVERGENCE_WINDOW", "DIVERGENCE_PROBABILITY",
           "KALMAN_OUTPUTS"]

#: defaults of the consistency guard (module docstring): consecutive updates, and the chi-square probability
DIVERGENCE_WINDOW = 20
DIVERGENCE_PROBABILITY = 0.999

#: the optional per-step outputs a Kalman-family filter records on request (``outputs=``), at its ``record`` steps
KALMAN_OUTPUTS = ("x_pred", "P_pred", "P_cross", "innovation", "S")


def _warn_renamed(what: str, new: str) -> None:
    """The one ``DeprecationWarning`` of an old name, attributed to the first frame outside this module and
    :mod:`dataclasses` (the caller's line, also through ``dataclasses.replace``)."""
    frame: FrameType | None
    level, frame = 2, sys._getframe(1)
    while frame is not None and frame.f_globals.get("__name__") in (__name__, "dataclasses"):
        level, frame = level + 1, frame.f_back
    warnings.warn(f"{what} is deprecated: use {new}", DeprecationWarning, stacklevel=level)


def _renamed_alias(old: str, new: str) -> property:
    def get(self):
        _warn_renamed(f"{type(self).__name__}.{old}", f".{new}")
        return getattr(self, new)
    get.__name__ = old
    get.__doc__ = f"Deprecated alias of :attr:`{new}` (one release): the same object, with a DeprecationWarning."
    return property(get)


class _Renames(type):
    """The metaclass of the results: a class's ``_RENAMED`` (old name -> new name) become read-only aliases that
    warn, and old field names given to the constructor (directly or through ``dataclasses.replace``, which passes
    every field's current value too) are mapped to the new ones, the old keyword winning, with the same warning."""

    def __new__(mcls, name, bases, namespace):
        cls = super().__new__(mcls, name, bases, namespace)
        for old, new in namespace.get("_RENAMED", {}).items():
            setattr(cls, old, _renamed_alias(old, new))
        return cls

    def __call__(cls, *args, **kwargs):
        if kwargs:
            fields = getattr(cls, "__dataclass_fields__", {})
            for base in cls.__mro__:
                for old, new in vars(base).get("_RENAMED", {}).items():
                    if old in kwargs and old not in fields:
                        _warn_renamed(f"{cls.__name__}({old}=...)", f"{new}=")
                        kwargs[new] = kwargs.pop(old)
        return super().__call__(*args, **kwargs)


class FilterResult(metaclass=_Renames):
    """The vocabulary every filter result shares (module docstring): ``mean``, ``cov``, ``steps``,
    ``log_likelihood``, ``diverged``, ``diverged_step`` (attributes of each result class), and here
    :attr:`n_diverged` and :meth:`position_m`."""

    #: position_m without an index: the whole mean (a filter whose state is a position) or an error (a state of
    #: several physical quantities, e.g. position and velocity: the index is the caller's to say)
    _WHOLE_MEAN_IS_POSITION = False

    if TYPE_CHECKING:   # every result class declares these two among its dataclass fields
        mean: np.ndarray
        diverged: np.ndarray | None

    @property
    def n_diverged(self) -> int:
        """The number of runs flagged ``diverged``."""
        return 0 if self.diverged is None else int(np.count_nonzero(self.diverged))

    def position_m(self, index=None) -> np.ndarray:
        """The position estimates ``batch + (R, d)``: the mean's components ``index`` (e.g. a motion model's
        ``position_index``). A Kalman-family or smoother result needs ``index`` (its state is whatever the model
        made it); a particle or grid result gives its whole mean by default (its state is the position, unless
        filtered with ``motion=``: then give the motion's ``position_index``)."""
        mean = self.mean
        n = np.shape(mean)[-1]
        if index is None:
            if self._WHOLE_MEAN_IS_POSITION:
                return mean
            raise ValueError(f"index must give the position components of the {type(self).__name__}'s state "
                             f"(0..{n - 1}; e.g. the motion model's position_index)")
        idx = np.atleast_1d(np.asarray(index))
        if idx.ndim != 1 or idx.size == 0 or not np.issubdtype(idx.dtype, np.integer) or idx.min() < 0 \
                or idx.max() >= n:
            raise ValueError(f"index must be state components in 0..{n - 1}, got {index!r}")
        return mean[..., idx]


@dataclass(frozen=True)
class KalmanResult(FilterResult):
    """Output of every Kalman-family filter (module docstring); ``batch`` the runs' axes, ``R`` recorded steps.

    - ``mean`` ``batch + (R, n)``, ``cov`` ``batch + (R, n, n)``: posterior means and covariances at ``steps``
      ``(R,)`` (``x`` and ``P``, the earlier names: deprecated aliases);
    - ``x_pred``, ``P_pred``: the prior each step's update starts from (the one-step prediction; for the KF's
      ``literal_george`` variant the previous posterior, which the printed update uses); ``innovation``
      ``batch + (R, M)`` and ``S`` ``batch + (R, M, M)``: the readings' innovations and their covariance, block
      diagonal over a step's sequential updates (module docstring); ``P_cross`` ``batch + (R, n, n)``: the
      cross-covariance ``Cov(x_{k-1}, x_k)`` of the previous posterior and the prediction (``P F^T``, ``P J^T`` or the
      sigma points'; NaN at a step not predicted), what :func:`locbook.rts_smoother` needs. None unless named in the
      filter's ``outputs``;
    - ``log_likelihood`` ``batch + (T,)``: ``log N(innovation; 0, S)`` of each step's present readings (NaN where a
      step has no update), :attr:`total_log_likelihood` their sum;
    - ``nis``, ``nis_dof``, ``diverged``, ``diverged_step``: the consistency guard (module docstring);
    - ``floored_updates``: the unscented filter's count of covariance updates its guard floored (0 for KF and EKF);
    - ``variant``: the update form that produced the run (``"corrected"``, or the KF's flagged ``"literal_george"``,
      whose ``x_pred``/``P_pred`` are the previous posterior: no smoother applies to it).
    """

    _RENAMED = {"x": "mean", "P": "cov"}

    mean: np.ndarray
    cov: np.ndarray
    steps: np.ndarray
    x_pred: np.ndarray | None = None
    P_pred: np.ndarray | None = None
    innovation: np.ndarray | None = None
    S: np.ndarray | None = None
    log_likelihood: np.ndarray | None = None
    nis: np.ndarray | None = None
    nis_dof: np.ndarray | None = None
    diverged: np.ndarray | None = None
    diverged_step: np.ndarray | None = None
    floored_updates: int = 0
    P_cross: np.ndarray | None = None
    variant: str = "corrected"

    @property
    def total_log_likelihood(self) -> np.ndarray:
        """``batch``: the log-likelihood of all the readings, the sum over the steps (those without an update add
        nothing)."""
        # every filter records it; None only in a result built by hand without it, which numpy then refuses
        return np.nansum(cast(np.ndarray, self.log_likelihood), axis=-1)


def _check_guard(window, probability):
    """The guard's arguments: ``window`` a non-negative integer (0 or None: off), ``probability`` in (0, 1)."""
    if window is not None:
        check_scalar("divergence_window", window, ge=0, integer=True)
    check_scalar("divergence_probability", probability, gt=0, lt=1)
    return 0 if window is None else int(window), float(probability)


def nis_divergence(nis, nis_dof, window: int | None = DIVERGENCE_WINDOW,
                   probability: float = DIVERGENCE_PROBABILITY):
    """The consistency guard of the module docstring: ``(diverged batch, diverged_step batch)`` from the normalised
    innovation squared ``nis`` ``batch + (T,)`` (NaN: no update) and its degrees of freedom ``nis_dof``.

    A run diverged when ``nis > chi2.ppf(probability, dof)`` at ``window`` consecutive updates (steps with
    ``dof == 0`` are skipped, and so are steps whose NIS is NaN: they carry no evidence either way, e.g. a foreign
    update function that returns no NIS); ``diverged_step`` is the first step of the first such window, -1 where
    none. ``nis_dof``: non-negative integers (an integer or float array with integral values).
    Vectorized over runs (numpy passes over the runs that have at least ``window`` exceedances; the rule's one
    implementation)."""
    window, probability = _check_guard(window, probability)
    nis = np.asarray(nis, dtype=float)
    dof = np.asarray(nis_dof)
    if not np.issubdtype(dof.dtype, np.integer):        # float (or bool) dof: integral values only
        try:
            as_float = dof.astype(float)
        except (TypeError, ValueError):
            raise ValueError(f"nis_dof must hold non-negative integers (degrees of freedom), got dtype {dof.dtype}") \
                from None
        fractional = ~np.isfinite(as_float) | (as_float != np.round(as_float))
        if fractional.any():
            raise ValueError(f"nis_dof must hold non-negative integers (degrees of freedom); got "
                             f"{as_float[fractional].flat[0]!r} at index "
                             f"{tuple(int(i) for i in np.argwhere(fractional)[0])}")
        dof = as_float.astype(np.int64)
    if dof.size and dof.min() < 0:
        raise ValueError(f"nis_dof must hold non-negative integers (degrees of freedom); got {int(dof.min())} at index "
                         f"{tuple(int(i) for i in np.argwhere(dof < 0)[0])}")
    try:
        dof = dof if dof.shape == nis.shape else np.broadcast_to(dof, nis.shape)
    except ValueError:
        raise ValueError(f"nis_dof {dof.shape} must broadcast to the shape of nis {nis.shape}") from None
    batch = nis.shape[:-1]
    if window == 0 or nis.shape[-1] < window or nis.size == 0:
        return np.zeros(batch, bool), np.full(batch, -1, np.int64)
    from scipy.special import chdtri  # lazy: keeps `import locbook` fast
    # the dimensions are small integers: one quantile each, looked up (inf for dof 0: never exceeded)
    table = np.concatenate([[np.inf], chdtri(np.arange(1, max(int(dof.max()), 1) + 1, dtype=float), 1.0 - probability)])
    T = nis.shape[-1]
    nis, dof = nis.reshape(-1, T), dof.reshape(-1, T)
    exceed = nis > np.take(table, dof)          # NaN > bound is False: a skipped step never counts
    diverged, start = np.zeros(nis.shape[0], bool), np.full(nis.shape[0], -1, np.int64)
    # only a run with at least `window` exceedances in all can hold `window` consecutive ones (most runs of a
    # consistent filter have a handful): the streaks are counted on those runs alone
    some = np.flatnonzero(np.count_nonzero(exceed, axis=-1) >= window)
    if some.size:
        exceed, nis, dof = exceed[some], nis[some], dof[some]
        updated = (dof > 0) & ~np.isnan(nis)    # a NaN NIS (no evidence) is skipped: neither counts nor breaks
        # the length of the current streak of exceedances among the updates: count minus the count at the last
        # update that stayed within the bound
        count = np.cumsum(exceed, axis=-1)
        reset = np.maximum.accumulate(np.where(updated & ~exceed, count, 0), axis=-1)
        hit = (count - reset) >= window
        hits = hit.any(axis=-1)
        end = np.argmax(hit, axis=-1)           # the update that completes the first window
        first = np.take_along_axis(count, end[..., None], -1) - window + 1
        diverged[some] = hits
        start[some] = np.where(hits, np.argmax(count >= first, axis=-1), -1)  # the window's first exceedance
    return diverged.reshape(batch), start.reshape(batch)


def nees(x_true, x, P, *, index=None):
    """Normalised estimation error squared ``(x - x_true)^T P^{-1} (x - x_true)`` ``batch + (T,)`` of estimates ``x``
    ``batch + (T, n)`` with covariances ``P`` ``batch + (T, n, n)`` against the truth ``x_true`` (broadcast against
    ``x``; NaN where the truth is missing). ``index``: the state components to score (e.g. the position), with the
    matching block of P. Under a consistent filter NEES ~ chi^2(n) at each step, so its average over M Monte-Carlo
    runs lies in ``chi2.ppf([a, 1 - a], M n) / M`` (Bar-Shalom, Li and Kirubarajan 2001, Sec. 5.4.2)."""
    x = as_array("x", x, min_ndim=1)
    x_true = as_array("x_true", x_true, min_ndim=1, nan_ok=True)
    P = as_array("P", P, min_ndim=2)
    if P.shape[-2:] != (x.shape[-1], x.shape[-1]) or x_true.shape[-1] != x.shape[-1]:
        raise ValueError(f"x {x.shape}, x_true {x_true.shape} and P {P.shape} must share the state size")
    if index is not None:
        idx = np.atleast_1d(np.asarray(index))
        if idx.ndim != 1 or not np.issubdtype(idx.dtype, np.integer) or idx.size == 0 or idx.min() < 0 \
                or idx.max() >= x.shape[-1] or np.unique(idx).size != idx.size:
            raise ValueError(f"index must be distinct state components in 0..{x.shape[-1] - 1}, got {index!r}")
        x, x_true, P = x[..., idx], x_true[..., idx], P[..., idx[:, None], idx[None, :]]
    e = x - x_true
    ok = np.all(np.isfinite(e), axis=-1)
    e = np.where(ok[..., None], e, 0.0)
    try:
        sol = np.linalg.solve(P, e[..., None])[..., 0]
    except np.linalg.LinAlgError:
        raise ValueError("nees needs positive definite covariances P: some P (of the components scored) is "
                         "singular") from None
    return np.where(ok, np.einsum("...i,...i->...", e, sol), np.nan)


_KalmanLike = TypeVar("_KalmanLike", bound="KalmanResult")    # _flag keeps the result's class


def _flag(res: _KalmanLike, window: int, probability: float) -> _KalmanLike:
    """``res`` with the guard's ``diverged`` and ``diverged_step`` (module docstring)."""
    diverged, step = nis_divergence(res.nis, res.nis_dof, window, probability)
    return replace(res, diverged=diverged, diverged_step=step)
