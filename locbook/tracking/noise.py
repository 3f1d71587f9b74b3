"""Noise levels from the readings: maximum likelihood (any Kalman-family filter) and EM (the linear model).

Every source document tunes its process and measurement noise by hand (Dogan 2015 sets q = 2.3e-5 for readings
simulated at sigma = 6 dB; Gudipati 2017 picks Q and R by trial). The innovations of a Kalman-family filter give the
log-likelihood of the readings under the model (the prediction-error decomposition, :mod:`locbook.tracking.results`):

    log p(z_1..z_T | theta) = sum_k log N(nu_k; 0, S_k(theta)),

exact for a linear-Gaussian model and to first order for the EKF's and UKF's linearisations. Two estimators:

- :func:`fit_noise_ml` maximises it over the noise, on log variance multipliers. ``"scale"`` fits one multiplier of a
  given covariance (Q -> e^a Q, R -> e^b R, an RSS stream's sigma_db^2 -> e^b sigma_db^2); ``"diagonal"`` one per
  component (Q -> D Q D with D = diag(e^{a_i / 2}): each variance scaled, the correlations of the given matrix kept,
  e.g. the position-velocity coupling of a white-noise CV model; an RSS stream: one sigma_db per anchor); a list of
  index groups one per group (e.g. the translational and the angular blocks of Q, the accelerometer and the gyroscope
  rows of R). Pooled over runs (one estimate): scipy.optimize's L-BFGS-B with central-difference gradients, the ``2p +
  1`` candidates of a gradient on a leading axis of one batched filter call. Per run (``per_run=True``): damped Newton
  steps on every run at once, gradient and Hessian by central differences, all the candidates of all runs in one
  filter call per iteration (a joint L-BFGS over the runs' separable objectives converges slowly: its line search is
  shared).
- :func:`fit_noise_em` is the expectation-maximisation of Shumway and Stoffer (1982) for a linear-Gaussian model with
  one LinearMeasurement stream: the RTS smoother's moments and lag-one cross-covariances give the M-step in closed form
  (full Q and R; pykalman's ``em`` with ``em_vars=['transition_covariance', 'observation_covariance']``). Each iteration
  never lowers the likelihood. A step with a missing component is treated as missing as a whole, in the filter and
  smoother of the E-step and in the M-step (pykalman's rule; the likelihood is then that of the complete steps).
"""
from __future__ import annotations

import inspect
from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from .._validate import check_choice, check_scalar
from ..errors import ConvergenceError
from ..models.base import LinearGaussian
from ._loop import _streams
from .kalman import kalman_filter
from .online import KALMAN_FILTERS
from .smoother import rts_smoother
from .streams import Stream
from .transition import MotionModel, PerStep, _control_drift

__all__ = ["NoiseFit", "fit_noise_ml", "fit_noise_em", "NOISE_FORMS"]

NOISE_FORMS = ("scale", "diagonal")


@dataclass(frozen=True)
class NoiseFit:
    """Fitted noise (``batch`` the runs' axes with ``per_run``, else none).

    - ``Q`` ``batch + (n, n)``; ``R``: per stream its fitted ``R`` ``batch + (m, m)`` (an RSS stream: its ``sigma_db``
      ``batch + (1 or m,)``), None for a stream not fitted;
    - ``q_scale`` ``batch + (p_q,)`` and ``r_scale`` (per stream, ``batch + (p_r,)`` or None): the variance multipliers
      of the given Q and R (1 = as given);
    - ``log_likelihood`` ``batch``: at the estimate; ``initial_log_likelihood``: at the given Q and R;
    - ``at_bound`` ``batch + (p,)``: each multiplier (``q_scale``'s, then each stream's ``r_scale``, in order) ended at
      its bound (the likelihood wants it beyond: widen ``scale_bounds`` or suspect the model); ``history`` (EM) ``batch
      + (iterations + 1,)``: the log-likelihood before each iteration and at the end; ``iterations``, ``method``
      (``"ml"`` or ``"em"``);
    - ``flat`` (ML) ``batch + (p,)``, in ``at_bound``'s order: the log-likelihood does not depend on that multiplier
      (every reading of its stream, or of that run, is missing; a zero Q): it is not fitted, its ``q_scale`` /
      ``r_scale`` and the nonzero entries of ``Q`` / ``R`` it scales are NaN (never the start passed off as a fit).
      Readings with no value at all are refused (a ValueError: nothing to fit from).
    """

    Q: np.ndarray
    R: tuple
    q_scale: np.ndarray | None
    r_scale: tuple
    log_likelihood: np.ndarray
    initial_log_likelihood: np.ndarray
    at_bound: np.ndarray
    iterations: int
    method: str
    history: np.ndarray | None = None
    flat: np.ndarray | None = None


def _per_reading(meas) -> bool:
    """True when the stream's model gives its noise as per-reading variances (an RSS stream's sigma_db^2), not a
    covariance."""
    return meas.model.noise()[0] == "variances"


def _groups(name: str, form, size: int, free=None) -> np.ndarray:
    """The variance groups of a fitted covariance as a ``(g, size)`` 0/1 matrix: ``"scale"`` one group of every
    component, ``"diagonal"`` one per component (those with a positive variance in ``free``), or a sequence of index
    groups (each group's variances scaled together; the components in no group are kept)."""
    if isinstance(form, str):
        check_choice(name, form, NOISE_FORMS)
        if form == "scale":
            return np.ones((1, size))
        keep = np.ones(size, bool) if free is None else np.asarray(free, bool)
        return np.eye(size)[keep]
    try:
        groups = [np.asarray(g, dtype=int).ravel() for g in form]
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be 'scale', 'diagonal', None or a list of index groups, got {form!r}") from None
    flat = np.concatenate(groups) if groups else np.array([], int)
    if not groups or any(g.size == 0 for g in groups) or flat.min() < 0 or flat.max() >= size \
            or np.unique(flat).size != flat.size:
        raise ValueError(f"{name}: index groups must be non-empty, disjoint and within 0..{size - 1}, got {form!r}")
    M = np.zeros((len(groups), size))
    for i, g in enumerate(groups):
        M[i, g] = 1.0
    return M


class _Parameters:
    """The map from log multipliers ``theta (..., p)`` to Q and the streams' noise (module docstring): each fitted
    covariance ``C`` becomes ``D C D`` with ``D = diag(exp(theta @ M / 2))``, ``M`` its groups (:func:`_groups`), so a
    group's variances are scaled together and the correlations kept; an RSS stream's sigma_db^2 per anchor likewise."""

    def __init__(self, Q, streams, fit_Q, fit_R):
        self.Q0 = np.asarray(Q, dtype=float)
        n = self.Q0.shape[-1]
        self.blocks = []                 # (target, groups M, base): target -1 = Q, i = stream i
        if fit_Q is not None:
            free = np.diagonal(self.Q0, axis1=-2, axis2=-1).reshape(-1, n).max(axis=0) > 0
            self.blocks.append((-1, _groups("fit_Q", fit_Q, n, free), self.Q0))
        for i, (meas, form) in enumerate(zip(streams, fit_R)):
            if form is None:
                continue
            kind, base = meas.model.noise()
            base = np.asarray(base, dtype=float)
            if kind == "variances":
                base = base.reshape(base.shape + (1,)) if base.ndim == 0 else base
                m = np.shape(meas.z)[-1]
                M = _groups(f"fit_R[{i}]", form, m)
                if M.shape[0] > 1 or M.shape[1] != base.shape[-1]:
                    base = np.broadcast_to(base, base.shape[:-1] + (m,))     # one sigma per anchor
            else:
                M = _groups(f"fit_R[{i}]", form, base.shape[-1])
            self.blocks.append((i, M, base))
        self.size = sum(b[1].shape[0] for b in self.blocks)
        if self.size == 0:
            raise ValueError("nothing to fit: give fit_Q and/or fit_R")
        self.streams = streams

    def apply(self, theta):
        """``(Q, streams)`` for log multipliers ``theta (..., p)`` (the leading axes become run axes)."""
        Q, streams = self.Q0, list(self.streams)
        c = 0
        for target, M, base in self.blocks:
            a = theta[..., c:c + M.shape[0]]
            c += M.shape[0]
            log_var = a @ M                                       # (..., size): each component's log multiplier
            if target == -1:
                d = np.exp(0.5 * log_var)
                Q = d[..., :, None] * base * d[..., None, :]
                continue
            meas = streams[target]
            if _per_reading(meas):
                sigma2 = np.exp(log_var if base.shape[-1] > 1 else log_var[..., :1]) * base
                streams[target] = meas.replace(model=meas.model.with_noise(sigma2))
                continue
            d = np.exp(0.5 * log_var)
            # a congruence of a checked covariance: a covariance again
            streams[target] = meas.replace(model=meas.model.with_noise(d[..., :, None] * base * d[..., None, :]))
        return Q, streams

    def unpack(self, theta):
        """``(Q multipliers or None, per-stream multipliers or None)`` of ``theta``, one per group."""
        q, r = None, [None] * len(self.streams)
        c = 0
        for target, M, _ in self.blocks:
            k = M.shape[0]
            if target == -1:
                q = np.exp(theta[..., c:c + k])
            else:
                r[target] = np.exp(theta[..., c:c + k])
            c += k
        return q, tuple(r)


def fit_noise_ml(F, Q, x0, P0, measurements, *, kind: str = "kf", fit_Q: str | None = "scale",
                 fit_R="scale", per_run: bool = True, scale_bounds=(1e-4, 1e4), max_iter: int = 200,
                 tol: float = 1e-10, **options) -> NoiseFit:
    """Maximum-likelihood noise levels of a Kalman-family model (module docstring).

    ``F, Q, x0, P0, measurements`` and ``options`` (``B``, ``u``, ``predict_first``, ``alpha``, ``points``, ...) as
    the filter ``kind`` (``"kf"``, ``"ekf"``, ``"ukf"``) takes them; ``Q`` and the streams' R (or sigma_db) are the
    starting point and the shape of what is fitted. ``fit_Q``: ``"scale"``, ``"diagonal"``, a list of index groups
    (module docstring) or None (kept); ``fit_R``: ``"scale"``, ``"diagonal"`` or None for every stream, or a list
    with exactly one entry per stream (a form, a list of index groups, or None: ``[[[0, 1], [2]], "scale"]`` fits
    two groups of the first stream's R and one scale of the second's). ``per_run``: every run (the leading axes
    of the readings) gets its own estimate; False pools the runs (one estimate, the sum of their log-likelihoods).
    ``scale_bounds``: the range of every variance multiplier. ``max_iter``: the iteration limit (of L-BFGS-B pooled,
    of the damped Newton steps per run); ``tol``: the tolerance on the relative change of the objective (L-BFGS-B's;
    a run's Newton steps stop when one raises its log-likelihood by no more than that, or changes no multiplier by
    more than 1e-6, relative).

    Raises ConvergenceError when the optimiser stops without meeting its criteria, ValueError when no step holds a
    reading; a multiplier that ends at its bound is reported in ``at_bound`` (not an error: the likelihood may be flat
    or want more), one the likelihood does not depend on in ``flat`` (NaN estimates; :class:`NoiseFit`).

    Examples
    --------
    Readings of 50 simulated constant-velocity runs with R = 0.25, fitted from a guess R = 1 (one scale, pooled):

    >>> import numpy as np
    >>> import locbook as lb
    >>> cv = lb.constant_velocity(1.0, 0.01, dim=1)
    >>> rng = np.random.default_rng(0)
    >>> states = lb.simulate_states(cv.F, cv.Q, np.zeros((50, 2)), 100, rng=rng)[:, 1:]       # (runs, T, n)
    >>> z = states[..., :1] + rng.normal(0, 0.5, (50, 100, 1))
    >>> fit = lb.fit_noise_ml(cv.F, cv.Q, np.zeros((50, 2)), np.eye(2),
    ...                       lb.LinearMeasurement(z, [[1.0, 0.0]], [[1.0]]), per_run=False)
    >>> print(np.round(fit.r_scale[0], 2), np.round(fit.q_scale, 2))   # R x 0.25, Q x 0.93 (true: 0.25, 1)
    [0.25] [0.93]
    """
    check_choice("kind", kind, tuple(KALMAN_FILTERS))
    streams = _streams(measurements)
    fit_R = [fit_R] * len(streams) if fit_R is None or isinstance(fit_R, str) else list(fit_R)
    if len(fit_R) != len(streams):
        raise ValueError(f"fit_R must be 'scale', 'diagonal' or None for every stream, or a list with one entry per "
                         f"stream ({len(streams)}; index groups of one stream go in its entry, e.g. [[[0, 1], [2]]]), "
                         f"got {len(fit_R)} entries")
    if isinstance(Q, PerStep):
        raise ValueError("fit_noise_ml fits a constant Q (a per-step Q has no one scale); give Q (n, n)")
    check_scalar("max_iter", max_iter, ge=1, integer=True)
    lo, hi = (float(v) for v in scale_bounds)
    if not 0 < lo <= 1 <= hi:
        raise ValueError(f"scale_bounds must be (low, high) with 0 < low <= 1 <= high, got {scale_bounds!r}")
    if Q is None and isinstance(F, MotionModel):    # the motion's own Q, the starting point of the fit
        # a linear motion model holds constant F and Q (the protocol's `linear`)
        Q = cast(Any, F).Q if F.linear else F.covariance(0)
    if Q is None:
        raise ValueError("fit_noise_ml needs Q (n, n): the starting point and the shape of what is fitted")
    params = _Parameters(Q, streams, fit_Q, fit_R)
    p = params.size
    filt = KALMAN_FILTERS[kind]
    _check_options(kind, options)
    options = {**options, "divergence_window": 0, "record": [0]}

    def run(theta):
        Qt, st = params.apply(theta)
        return filt(F, Qt, x0, P0, st, **options)

    def log_likelihood(theta):
        """The runs' total log-likelihood at log multipliers ``theta`` (leading axes: candidates, then runs)."""
        return run(theta).total_log_likelihood

    start = run(np.zeros(p))
    ll0 = start.total_log_likelihood
    runs = np.shape(ll0)
    if not np.isfinite(start.log_likelihood).any():
        why = f"the runs' axes {runs} hold no run" if 0 in runs else "every reading is missing"
        raise ValueError(f"fit_noise_ml: no step of the {len(streams)} stream(s) holds a reading ({why}): there are no "
                         "readings to fit from")
    bad = ~np.isfinite(ll0)
    if np.any(bad):               # -inf: a reading the model gives no probability (no multiplier in range helps)
        at = tuple(int(i) for i in np.argwhere(bad)[0]) if np.ndim(bad) else ()
        raise ValueError(f"fit_noise_ml: the log-likelihood of the readings at the given noise is "
                         f"{float(np.asarray(ll0)[at]):g}{f' in run {at}' if at else ''}: the readings are impossible "
                         "under the model (a reading of 1e300?); check their units and the model's scales")
    flat = _flat(log_likelihood, runs, p, per_run)
    if per_run:
        theta, iterations = _newton_per_run(log_likelihood, runs, p, np.log(lo), np.log(hi), int(max_iter), tol)
    else:
        theta, iterations = _lbfgs_pooled(log_likelihood, runs, p, np.log(lo), np.log(hi), int(max_iter), tol,
                                          abs(float(np.sum(ll0))))
    Qf, st = params.apply(theta)       # pooled: one Q and R for every run
    q, r = params.unpack(np.where(flat, np.nan, theta))
    at_bound = ((theta <= np.log(lo) + 1e-6) | (theta >= np.log(hi) - 1e-6)) & ~flat
    R = [(np.sqrt(s.model.noise()[1]) if _per_reading(s) else s.model.noise()[1]) if form is not None else None
         for s, form in zip(st, fit_R)]
    if flat.any():                      # an undetermined multiplier: NaN in what it scales (the status is `flat`)
        Qf, R = _blank_flat(params, flat, Qf, R)
    ll = log_likelihood(theta)
    return NoiseFit(Qf, tuple(R), q, r, ll if per_run else np.sum(ll), ll0 if per_run else np.sum(ll0), at_bound,
                    iterations, "ml", flat=flat)


def _check_options(kind: str, options: dict) -> None:
    """A keyword the filter ``kind`` does not take is one line naming it and the kinds that take it (e.g. the UKF's
    ``alpha`` given with ``kind="kf"``), not the filter's TypeError at the first evaluation."""
    takes = {k: set(inspect.signature(f).parameters) for k, f in KALMAN_FILTERS.items()}
    for name in options:
        if name not in takes[kind]:
            others = [k for k in KALMAN_FILTERS if name in takes[k]]
            where = (f"only kind={' or kind='.join(repr(k) for k in others)} takes it" if others else
                     "no filter kind takes it (a misspelt option?)")
            raise ValueError(f"fit_noise_ml: the {kind!r} filter has no option {name!r}: {where}")


def _flat(log_likelihood, runs, p: int, per_run: bool) -> np.ndarray:
    """``batch + (p,)`` (pooled: ``(p,)``): the log-likelihood at the start does not move, to a few ulp, when a log
    multiplier moves by :data:`_H` either way: nothing in the readings depends on it (every reading of that stream
    missing, a run with no reading)."""
    steps = np.concatenate([np.zeros((1, p)), _H * np.eye(p), -_H * np.eye(p)])
    f = log_likelihood(steps.reshape((2 * p + 1,) + (1,) * len(runs) + (p,)))
    if not per_run:
        f = f.reshape(2 * p + 1, -1).sum(axis=-1)
    f0, fp, fm = f[0], f[1:p + 1], f[p + 1:]
    tol = 8 * np.finfo(float).eps * np.abs(f0)
    flat = (np.abs(fp - f0) <= tol) & (np.abs(fm - f0) <= tol)
    return np.moveaxis(flat, 0, -1)


def _blank_flat(params, flat, Q, R: list):
    """NaN in the entries of the fitted ``Q`` and ``R`` (per stream) that a flat multiplier scales (an entry that is 0
    in the given matrix stays 0: any multiplier gives it)."""
    c = 0
    for target, M, base in params.blocks:
        hit = (flat[..., c:c + M.shape[0]].astype(float) @ M) > 0            # (..., size): components scaled
        c += M.shape[0]
        if not hit.any():
            continue
        value = np.array(Q if target == -1 else R[target], dtype=float)
        if target != -1 and _per_reading(params.streams[target]):
            hit = np.broadcast_to(hit.any(axis=-1, keepdims=True) if value.shape[-1:] == (1,) else hit,
                                  np.broadcast_shapes(hit.shape[:-1] + value.shape[-1:], value.shape))
            value = np.where(hit, np.nan, value)
        else:
            value = np.where((hit[..., :, None] | hit[..., None, :]) & (base != 0), np.nan, value)
        if target == -1:
            Q = value
        else:
            R[target] = value
    return Q, R


_H = 1e-4          # finite-difference step in log multipliers (a relative change of 1e-4)
_DAMPING_FLOOR = 1e-10      # the per-run Newton's smallest damping (relative to the Hessian's largest diagonal entry)
_EXPAND = 2.0 ** np.arange(8)   # the per-run Newton tries its step times each of these


def _lbfgs_pooled(log_likelihood, runs, p: int, lo: float, hi: float, max_iter: int, tol: float, scale: float):
    """One multiplier vector for all runs: scipy's L-BFGS-B on the summed log-likelihood, its central-difference
    gradient from one filter call with the ``2p + 1`` candidates on a leading axis."""
    from scipy.optimize import minimize  # lazy: keeps `import locbook` fast
    steps = np.concatenate([np.zeros((1, p)), _H * np.eye(p), -_H * np.eye(p)])     # centre, +h e_j, -h e_j

    def objective(theta):
        cand = theta.reshape((1,) * len(runs) + (p,)) + steps.reshape((2 * p + 1,) + (1,) * len(runs) + (p,))
        ll = log_likelihood(cand).reshape(2 * p + 1, -1).sum(axis=-1)
        value = -float(ll[0])
        if not np.isfinite(value):
            return np.inf, np.zeros(p)
        return value, -(ll[1:p + 1] - ll[p + 1:]) / (2 * _H)

    # (scipy-stubs types options as a TypedDict of float | numpy floating entries; this dict, built once for both
    # calls, is inferred dict[str, float], which no overload takes: the ignores below)
    options = {"maxiter": max_iter, "ftol": tol, "gtol": 1e-7 * max(scale, 1.0)}
    res = minimize(objective, np.zeros(p), jac=True, method="L-BFGS-B",  # type: ignore[call-overload]
                   bounds=[(lo, hi)] * p, options=options)
    if not res.success and "ABNORMAL" in str(res.message):
        # the line search failed: near the optimum the central-difference gradient of a large summed log-likelihood
        # carries round-off that can contradict the step (the same point ends "converged" or "abnormal" with the
        # compiled kernels' or numpy's summation order). Restart once from there with a fresh curvature memory: a
        # restart that cannot lower the objective either confirms the point is as converged as the objective's
        # precision allows; one that moves it continues from there
        again = minimize(objective, res.x, jac=True, method="L-BFGS-B",  # type: ignore[call-overload]
                         bounds=[(lo, hi)] * p, options=options)
        if again.success:
            res = again
        elif again.fun >= res.fun - tol * max(abs(res.fun), 1.0):
            return res.x, int(res.nit)
    if not res.success:
        raise ConvergenceError(f"fit_noise_ml: L-BFGS-B stopped without converging after {res.nit} iterations "
                               f"({res.message}); raise max_iter or check the model")
    return res.x, int(res.nit)


def _newton_per_run(log_likelihood, runs, p: int, lo: float, hi: float, max_iter: int, tol: float):
    """A multiplier vector per run: damped Newton steps on every run at once (Levenberg-Marquardt damping, projected
    onto the bounds), the gradient and Hessian by central differences from one filter call with the ``1 + 2p +
    p(p-1)/2`` candidates on a leading axis, the step and its doublings (:data:`_EXPAND`) from a second, the step
    doubled as long as the likelihood keeps rising. A run stops when its accepted step changes no multiplier by more
    than 1e-6 (relative) or raises its log-likelihood by no more than ``tol`` (relative)."""
    pairs = [(i, j) for i in range(p) for j in range(i + 1, p)]
    stencil: Any = [np.zeros(p)] + [s * _H * np.eye(p)[i] for s in (1, -1) for i in range(p)] + \
        [_H * (np.eye(p)[i] + np.eye(p)[j]) for i, j in pairs]
    stencil = np.array(stencil).reshape((len(stencil),) + (1,) * len(runs) + (p,))
    theta = np.zeros(runs + (p,))
    damping = np.full(runs, 1e-3)
    done = np.zeros(runs, bool)
    for it in range(1, max_iter + 1):
        f = log_likelihood(theta + stencil)                      # (E,) + runs
        f0, fp, fm = f[0], f[1:p + 1], f[p + 1:2 * p + 1]
        g = np.moveaxis((fp - fm) / (2 * _H), 0, -1)             # runs + (p,)
        H = np.zeros(runs + (p, p))
        diag = np.moveaxis((fp - 2 * f0 + fm) / _H**2, 0, -1)
        H[..., np.arange(p), np.arange(p)] = diag
        for (i, j), fij in zip(pairs, f[2 * p + 1:]):
            H[..., i, j] = H[..., j, i] = (fij - fp[i] - fp[j] + f0) / _H**2
        # ascent on f: solve (-H + mu I) step = g, mu lifting -H to positive definite and damping the step
        A = -0.5 * (H + np.swapaxes(H, -1, -2))
        low = np.linalg.eigvalsh(A)[..., 0]
        size = np.maximum(np.abs(diag).max(axis=-1), 1e-12)
        mu = np.maximum(0.0, -low) + damping * size
        step = np.linalg.solve(A + mu[..., None, None] * np.eye(p), g[..., None])[..., 0]
        # where the likelihood is not concave (a flat ridge towards a bound) the shifted Newton step alone crawls:
        # the step and its multiples up to 2^7 in one call, doubled as long as the likelihood keeps rising
        trials = np.clip(theta + _EXPAND.reshape((-1,) + (1,) * (len(runs) + 1)) * step, lo, hi)
        trials = np.where(done[..., None], theta, trials)
        f_trials = log_likelihood(trials)
        f_trials = np.where(np.isfinite(f_trials), f_trials, -np.inf)
        best = np.cumprod(f_trials[1:] > f_trials[:-1], axis=0).sum(axis=0)     # the last of the rising multiples
        f_trial = np.take_along_axis(f_trials, best[None], 0)[0]
        step = np.take_along_axis(trials, best[None, ..., None], 0)[0] - theta
        better = np.isfinite(f_trial) & (f_trial >= f0 - 1e-12 * np.abs(f0))
        theta = np.where(better[..., None], theta + step, theta)
        # the damping keeps a floor: below it, mu would equal -low to round-off and A + mu I be singular
        damping = np.where(better, np.maximum(damping / 10.0, _DAMPING_FLOOR), damping * 10.0)
        small = np.abs(step).max(axis=-1) < 1e-6
        flat = f_trial - f0 <= tol * np.abs(f0)        # on a flat top, round-off moves the step back and forth
        done = done | (better & (small | flat))
        if done.all():
            return theta, it
    raise ConvergenceError(f"fit_noise_ml: {int(np.count_nonzero(~done))} of {done.size} runs did not converge in "
                           f"{max_iter} damped Newton iterations; raise max_iter or check the model")


def fit_noise_em(F, Q, x0, P0, measurement, *, B=None, u=None, n_iter: int = 10,
                 fit=("Q", "R"), per_run: bool = True) -> NoiseFit:
    """Expectation-maximisation of the full Q and R of a linear-Gaussian model (module docstring; Shumway and Stoffer
    1982), ``x_k = F_k x_{k-1} + B_k u_k + w_k``, ``z_k = H x_k + d + v_k``, the prior ``x0, P0`` at step 0
    (``predict_first=False``: pykalman's convention; the step that moves the prior is not part of the model).

    E-step: :func:`locbook.kalman_filter` and :func:`locbook.rts_smoother` give the smoothed means ``m_k``,
    covariances ``V_k`` and lag-one cross-covariances ``V_{k+1,k} = V_{k+1} G_k^T`` (G the smoother gains). M-step::

        Q = 1/(T-1) sum_k [e_k e_k^T + F V_k F^T + V_{k+1} - V_{k+1,k} F^T - F V_{k+1,k}^T],
            e_k = m_{k+1} - F m_k - B u_{k+1}      (F = F_{k+1})
        R = 1/|K| sum_{k in K} [r_k r_k^T + H V_k H^T],   r_k = z_k - H m_k - d,  K the steps with every component
                                                                               (the others are missing as a whole).

    ``fit``: which of ``"Q"``, ``"R"`` to update. ``per_run``: one estimate per run (the leading axes of the readings),
    else the runs' statistics are pooled. ``history``: the log-likelihood before each iteration and at the end (it never
    decreases, up to round-off)."""
    check_scalar("n_iter", n_iter, ge=1, integer=True)
    model: Any = getattr(measurement, "model", None)   # whatever it is: checked by what it has, below
    terms = model.constant_terms(0) if getattr(model, "linear", False) else None
    if terms is None or measurement.mode != "parallel" or getattr(model, "per_step_fields", lambda: False)():
        raise ValueError("fit_noise_em takes one parallel LinearMeasurement with one constant H (m, n) and R")
    if isinstance(F, MotionModel) and F.linear:    # a linear motion model holds constant F and Q
        F, Q = cast(Any, F).F, (cast(Any, F).Q if Q is None else Q)
    if isinstance(F, MotionModel) or isinstance(Q, PerStep) or np.ndim(Q) != 2:
        raise ValueError("fit_noise_em fits the linear model: F a matrix (n, n) or per_step(F), Q one (n, n) "
                         "covariance (a NonlinearMotion or a per-step Q has no closed-form M-step here)")
    unknown = set(fit) - {"Q", "R"}
    if unknown or not fit:
        raise ValueError(f"fit must name 'Q' and/or 'R', got {fit!r}")
    Q = np.asarray(Q, dtype=float)
    H, R = (np.asarray(v, dtype=float) for v in terms)
    z = np.asarray(model.prepare_readings(measurement.z), dtype=float)
    # pykalman's rule: a step with a missing component is missing as a whole, in the E-step and the M-step alike
    # (the R M-step of a partly observed step has no closed form; leaving such steps out of the M-step only would
    # break the monotone likelihood of EM)
    z = np.where(np.all(np.isfinite(z), axis=-1, keepdims=True), z, np.nan)
    measurement = Stream(z, LinearGaussian(H, R, name=measurement.name))
    T, n = z.shape[-2], H.shape[-1]
    if T < 2:
        raise ValueError("fit_noise_em needs at least two steps")
    _check_em_readings(z, per_run)
    Fs = F.value if isinstance(F, PerStep) else np.asarray(F, dtype=float)[..., None, :, :]
    drift, _ = _control_drift(B, u, n, T)
    history: Any = []      # one log-likelihood per iteration; one array at the end

    for it in range(n_iter + 1):
        run = kalman_filter(F, Q, x0, P0, measurement.replace(model=measurement.model.with_noise(R)), B=B, u=u,
                            predict_first=False, outputs=("x_pred", "P_pred", "P_cross"), divergence_window=0)
        history.append(run.total_log_likelihood)
        _check_em_step(history, per_run, it, z)
        if it == n_iter:
            break
        sm = rts_smoother(run)
        m, V, G = sm.mean, sm.cov, sm.gain
        batch = m.shape[:-2]
        # an overflow of the squares is caught by _finite_iterate (one line), not warned about on the way
        with np.errstate(over="ignore", invalid="ignore"):
            if "Q" in fit:
                Fk = np.broadcast_to(Fs, np.broadcast_shapes(Fs.shape[:-3], batch) + (T, n, n))[..., 1:, :, :] \
                    if Fs.shape[-3] > 1 else Fs
                e = m[..., 1:, :] - np.einsum("...ij,...j->...i", Fk, m[..., :-1, :])
                if drift is not None:
                    e = e - np.broadcast_to(drift, batch + (T, n))[..., 1:, :]
                C = V[..., 1:, :, :] @ np.swapaxes(G, -1, -2)                 # Cov(x_{k+1}, x_k | all)
                CF = C @ np.swapaxes(Fk, -1, -2)
                terms = (e[..., :, None] * e[..., None, :] + Fk @ V[..., :-1, :, :] @ np.swapaxes(Fk, -1, -2)
                         + V[..., 1:, :, :] - CF - np.swapaxes(CF, -1, -2))
                Q = terms.mean(axis=-3) if per_run else terms.reshape((-1, n, n)).mean(axis=0)
                parts = (e[..., :, None] * e[..., None, :], V[..., 1:, :, :], CF)
                Q = _psd_iterate("Q", _finite_iterate("Q", 0.5 * (Q + np.swapaxes(Q, -1, -2)), it + 1, z),
                                 _scale(parts, per_run), it + 1)
            if "R" in fit:
                full = np.all(np.isfinite(z), axis=-1)                       # batch + (T,)
                full = np.broadcast_to(full, batch + (T,))
                r = np.where(full[..., None], np.broadcast_to(z, batch + z.shape[-2:]) - m @ H.T, 0.0)
                terms = r[..., :, None] * r[..., None, :] + H @ V @ H.T
                terms = np.where(full[..., None, None], terms, 0.0)
                if per_run:                                                  # every run has a full step (checked)
                    R = terms.sum(axis=-3) / full.sum(axis=-1)[..., None, None]
                else:
                    R = terms.reshape((-1,) + R.shape[-2:]).sum(axis=0) / int(full.sum())
                R = _psd_iterate("R", _finite_iterate("R", 0.5 * (R + np.swapaxes(R, -1, -2)), it + 1, z),
                                 _scale((terms,), per_run), it + 1)
    history = np.stack([np.asarray(h) for h in history], axis=-1)
    if not per_run:
        history = history.reshape(-1, n_iter + 1).sum(axis=0)
    final = history[..., -1]
    return NoiseFit(Q, (R,), None, (None,), final, history[..., 0], np.zeros(np.shape(final) + (0,), bool),
                    int(n_iter), "em", history)


def _check_em_readings(z, per_run: bool) -> None:
    """Refuse readings ``batch + (T, m)`` that leave EM nothing to fit from: no step with every component present
    (pooled: in any run; per run: in some run), zero components, or no run at all. Without them the E-step is the
    prior's prediction and EM would return its start (or R = 0) with a log-likelihood of 0."""
    m = z.shape[-1]
    full = np.all(np.isfinite(z), axis=-1) & (m > 0)                        # batch + (T,)
    if not full.any():
        what = ("no run" if full.size == 0 else "readings of zero components" if m == 0
                else f"no step with all {m} components present (a step with a missing component is missing as a whole)")
        raise ValueError(f"fit_noise_em: measurement.z {z.shape} has {what}: there are no readings to fit from")
    if per_run and z.ndim > 2:
        empty = ~full.any(axis=-1)
        if empty.any():
            run = tuple(int(i) for i in np.argwhere(empty)[0])
            raise ValueError(f"fit_noise_em: run {run} of measurement.z {z.shape} has no step with all {m} components "
                             f"present ({int(empty.sum())} such runs): no readings to fit it from; drop those runs or "
                             "pool the runs (per_run=False)")


#: how far EM's log-likelihood may fall in one iteration, relative to its size, before the fit is an error (EM never
#: lowers it in exact arithmetic; a larger fall is an E-step without precision, e.g. a Q of 1e300 against readings of 1)
_EM_FALL_RTOL = 1e-7


def _check_em_step(history, per_run: bool, it: int, z) -> None:
    """EM's self-checks after the filter of iteration ``it``: a finite log-likelihood (-inf: a reading the model
    cannot produce), and one that did not fall beyond round-off since the previous iteration (pooled: their sum)."""
    h = np.asarray(history[-1], dtype=float)
    if not np.all(np.isfinite(h)):
        at = tuple(int(i) for i in np.argwhere(~np.isfinite(h))[0]) if h.ndim else ()
        top = float(np.nanmax(np.abs(z))) if np.isfinite(z).any() else np.nan
        raise ValueError(f"fit_noise_em: the log-likelihood of measurement.z is {float(h[at]):g}"
                         f"{f' in run {at}' if at else ''} at iteration {it} (the largest |z| is {top:.3g}): the "
                         "readings are impossible under the model; check their units and the model's scales")
    if it == 0:
        return
    new, old = (h, np.asarray(history[-2], dtype=float)) if per_run else (np.sum(h), np.sum(history[-2]))
    fall = old - new > _EM_FALL_RTOL * np.maximum(np.maximum(np.abs(old), np.abs(new)), 1.0)
    if np.any(fall):
        at = tuple(int(i) for i in np.argwhere(fall)[0]) if np.ndim(fall) else ()
        raise ConvergenceError(f"fit_noise_em: the log-likelihood fell from {float(old[at]):.6g} to "
                               f"{float(new[at]):.6g}{f' in run {at}' if at else ''} at iteration {it} (EM never "
                               "lowers it): the filter or smoother lost precision; rescale the model (Q, R and P0 near "
                               "the readings' variance)")


def _finite_iterate(name: str, A, iteration: int, z):
    """An M-step's estimate, refused where it overflowed float64 (it squares the residuals)."""
    if not np.all(np.isfinite(A)):
        top = float(np.nanmax(np.abs(z))) if np.isfinite(z).any() else np.nan
        raise ConvergenceError(f"fit_noise_em: the M-step's {name} of iteration {iteration} overflows float64 (it "
                               f"squares the residuals; the largest |z| is {top:.3g}): rescale the readings")
    return A


#: the round-off an M-step's Q or R may carry below zero, relative to the scale of the terms it sums (the filter's
#: own tolerance on a covariance, locbook.tracking._linalg._SYM_RTOL)
_EM_PSD_RTOL = 1e-8


def _scale(parts, per_run: bool) -> np.ndarray:
    """The largest |entry| of the M-step's summands ``parts`` (each ``batch + (K, a, a)``): per run, or of all runs."""
    axes = (-3, -2, -1)
    top = np.max([np.abs(p).max(axis=axes) if p.size else np.zeros(p.shape[:-3]) for p in parts], axis=0)
    return top if per_run else np.max(top, initial=0.0)


def _psd_iterate(name: str, A, scale, iteration: int):
    """The symmetric M-step estimate ``A`` ``(..., a, a)`` as a covariance: an average of conditional second moments
    is positive semi-definite, so negative eigenvalues within :data:`_EM_PSD_RTOL` times ``scale`` (its summands'
    largest entry) are cancellation round-off (EM started from Q = 0 stays at 0 up to some 1e-17); where there are
    any, the eigenvalues within that band become 0. Beyond it the E-step has lost its precision: ConvergenceError."""
    if A.shape[-1] == 0:
        return A
    w, V = np.linalg.eigh(A)
    low = w[..., 0]
    if not np.any(low < 0):
        return A
    tol = _EM_PSD_RTOL * np.asarray(scale, dtype=float)
    bad = low < -tol
    if np.any(bad):
        at = tuple(int(i) for i in np.argwhere(bad)[0]) if np.ndim(bad) else ()
        raise ConvergenceError(f"fit_noise_em: the M-step's {name} of iteration {iteration}"
                               f"{f' in run {at}' if at else ''} has the eigenvalue {float(low[at]):.3g}, below the "
                               f"round-off {float(np.broadcast_to(tol, np.shape(low))[at]):.3g} of its terms (a "
                               "covariance cannot be negative): the E-step lost its precision; rescale the model")
    fix = low < 0
    w = np.where(np.abs(w) <= tol[..., None] if np.ndim(tol) else np.abs(w) <= tol, 0.0, w)
    clipped = (V * w[..., None, :]) @ np.swapaxes(V, -1, -2)
    clipped = 0.5 * (clipped + np.swapaxes(clipped, -1, -2))
    return np.where(fix[..., None, None], clipped, A) if np.ndim(fix) else clipped
