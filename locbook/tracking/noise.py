"""Noise levels from the readings: maximum likelihood (any Kalman-family filter) and EM (the linear model).

Every source document tunes its process and measurement noise by hand (Dogan 2015 sets q = 2.3e-5 and sigma = 3.5 dB;
Gudipati 2017 picks Q and R by trial). The innovations of a Kalman-family filter give the log-likelihood of the
readings under the model (the prediction-error decomposition, :mod:`locbook.tracking.results`):

    log p(z_1..z_T | theta) = sum_k log N(nu_k; 0, S_k(theta)),

exact for a linear-Gaussian model and to first order for the EKF's and UKF's linearisations. Two estimators:

- :func:`fit_noise_ml` maximises it over the noise (scipy.optimize L-BFGS-B on log multipliers, central-difference
  gradients). ``"scale"`` fits one multiplier of a given covariance (Q -> e^a Q, R -> e^b R, an RSS stream's sigma_db^2
  -> e^b sigma_db^2); ``"diagonal"`` one per component (Q -> D Q D with D = diag(e^{a_i / 2}): each variance scaled,
  the correlations of the given matrix kept, e.g. the position-velocity coupling of a white-noise CV model; an RSS
  stream: one sigma_db per anchor). Batched over runs: with ``per_run=True`` every run gets its own estimate, found by
  one optimisation of the sum of the runs' (independent) objectives, whose gradient is separable, so each gradient costs
  ``2p + 1`` batched filter calls whatever the number of runs (the candidates ride on a leading axis of one call).
- :func:`fit_noise_em` is the expectation-maximisation of Shumway and Stoffer (1982) for a linear-Gaussian model with
  one LinearMeasurement stream: the RTS smoother's moments and lag-one cross-covariances give the M-step in closed form
  (full Q and R; pykalman's ``em`` with ``em_vars=['transition_covariance', 'observation_covariance']``). Each iteration
  never lowers the likelihood. Readings with a missing component leave their step out of the R update (pykalman's
  rule).
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .._validate import check_choice, check_scalar
from ..errors import ConvergenceError
from .kalman import extended_kalman_filter, kalman_filter
from .smoother import rts_smoother
from .streams import LinearMeasurement, NonlinearMeasurement, RssMeasurement
from .transition import PerStep, _control_drift
from .unscented import unscented_kalman_filter

__all__ = ["NoiseFit", "fit_noise_ml", "fit_noise_em", "NOISE_FORMS"]

NOISE_FORMS = ("scale", "diagonal")
_FILTERS = {"kf": kalman_filter, "ekf": extended_kalman_filter, "ukf": unscented_kalman_filter}


@dataclass(frozen=True)
class NoiseFit:
    """Fitted noise (``batch`` the runs' axes with ``per_run``, else none).

    - ``Q`` ``batch + (n, n)``; ``R``: per stream its fitted ``R`` ``batch + (m, m)`` (an RSS stream: its ``sigma_db``
      ``batch + (1 or m,)``), None for a stream not fitted;
    - ``q_scale`` ``batch + (p_q,)`` and ``r_scale`` (per stream, ``batch + (p_r,)`` or None): the variance multipliers
      of the given Q and R (1 = as given);
    - ``log_likelihood`` ``batch``: at the estimate; ``initial_log_likelihood``: at the given Q and R;
    - ``at_bound`` ``batch``: a multiplier ended at its bound (the likelihood wants it beyond: widen ``scale_bounds``
      or suspect the model); ``history`` (EM) ``batch + (iterations + 1,)``: the log-likelihood before each iteration
      and at the end; ``iterations``, ``method`` (``"ml"`` or ``"em"``).
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


def _stream_noise(meas):
    """A stream's noise as a variance-like array: R ``(.., m, m)`` or an RSS stream's sigma_db^2 ``(.., 1 or m)``."""
    if isinstance(meas, RssMeasurement):
        return np.asarray(meas.channel.sigma_db, dtype=float) ** 2
    if callable(meas.R):
        raise ValueError(f"{getattr(meas, 'name', type(meas).__name__)}: a noise given by a function of the state "
                         "cannot be fitted; give fit_R=None for this stream")
    if isinstance(meas.R, PerStep):
        raise ValueError("a LinearMeasurement with R per step cannot be fitted; give fit_R=None for this stream")
    return np.asarray(meas.R, dtype=float)


class _Parameters:
    """The map from log multipliers ``theta (..., p)`` to Q and the streams' noise (module docstring)."""

    def __init__(self, Q, streams, fit_Q, fit_R):
        self.Q0 = np.asarray(Q, dtype=float)
        n = self.Q0.shape[-1]
        self.blocks = []                 # (target, form, size, base): target -1 = Q, i = stream i
        if fit_Q is not None:
            check_choice("fit_Q", fit_Q, NOISE_FORMS)
            if fit_Q == "diagonal":
                free = np.diagonal(self.Q0, axis1=-2, axis2=-1).reshape(-1, n).max(axis=0) > 0
            self.blocks.append((-1, fit_Q, 1 if fit_Q == "scale" else n, None if fit_Q == "scale" else free))
        for i, (meas, form) in enumerate(zip(streams, fit_R)):
            if form is None:
                continue
            check_choice(f"fit_R[{i}]", form, NOISE_FORMS)
            base = _stream_noise(meas)
            if isinstance(meas, RssMeasurement):
                m = np.shape(meas.rss_dbm)[-1]
                size = 1 if form == "scale" else m
            else:
                m = base.shape[-1]
                size = 1 if form == "scale" else m
            self.blocks.append((i, form, size, base))
        self.size = sum(b[2] for b in self.blocks)
        if self.size == 0:
            raise ValueError("nothing to fit: give fit_Q and/or fit_R")
        self.streams = streams

    def apply(self, theta):
        """``(Q, streams)`` for log multipliers ``theta (..., p)`` (the leading axes become run axes)."""
        Q, streams = self.Q0, list(self.streams)
        c = 0
        for target, form, size, extra in self.blocks:
            a = theta[..., c:c + size]
            c += size
            if target == -1:
                if form == "scale":
                    Q = np.exp(a)[..., None] * self.Q0
                else:
                    d = np.exp(0.5 * np.where(extra, a, 0.0))
                    Q = d[..., :, None] * self.Q0 * d[..., None, :]
                continue
            meas = streams[target]
            if isinstance(meas, RssMeasurement):
                sigma2 = np.exp(a) * extra                 # (..., 1 or m): the channel's sigma_db per anchor
                streams[target] = replace(meas, channel=replace(meas.channel, sigma_db=np.sqrt(sigma2)))
                continue
            if form == "scale":
                R = np.exp(a)[..., None] * extra
            else:
                d = np.exp(0.5 * a)
                R = d[..., :, None] * extra * d[..., None, :]
            streams[target] = _with_R(meas, R)
        return Q, streams

    def unpack(self, theta):
        """``(Q multipliers or None, per-stream multipliers or None)`` of ``theta``."""
        q, r = None, [None] * len(self.streams)
        c = 0
        for target, _, size, _ in self.blocks:
            if target == -1:
                q = np.exp(theta[..., c:c + size])
            else:
                r[target] = np.exp(theta[..., c:c + size])
            c += size
        return q, tuple(r)


def _with_R(meas, R):
    """The stream with noise R (built without re-checking: R is a congruence of a checked covariance)."""
    view = object.__new__(type(meas))
    for field in meas.__dataclass_fields__:
        object.__setattr__(view, field, getattr(meas, field))
    object.__setattr__(view, "R", R)
    return view


def _as_list(streams):
    if isinstance(streams, (LinearMeasurement, RssMeasurement, NonlinearMeasurement)):
        return [streams]
    return list(streams)


def fit_noise_ml(F, Q, x0, P0, measurements, *, kind: str = "kf", fit_Q: str | None = "scale",
                 fit_R="scale", per_run: bool = True, scale_bounds=(1e-4, 1e4), max_iter: int = 200,
                 tol: float = 1e-10, **options) -> NoiseFit:
    """Maximum-likelihood noise levels of a Kalman-family model (module docstring).

    ``F, Q, x0, P0, measurements`` and ``options`` (``B``, ``u``, ``predict_first``, ``alpha``, ``points``, ...) as
    the filter ``kind`` (``"kf"``, ``"ekf"``, ``"ukf"``) takes them; ``Q`` and the streams' R (or sigma_db) are the
    starting point and the shape of what is fitted. ``fit_Q``: ``"scale"``, ``"diagonal"`` or None (kept);
    ``fit_R``: one of those for every stream, or a list with one per stream. ``per_run``: every run (the leading axes
    of the readings) gets its own estimate; False pools the runs (one estimate, the sum of their log-likelihoods).
    ``scale_bounds``: the range of every variance multiplier. ``max_iter``, ``tol``: L-BFGS-B's iteration limit and
    its tolerance on the relative change of the objective.

    Raises ConvergenceError when the optimiser stops without meeting its criteria; a multiplier that ends at its bound
    is reported in ``at_bound`` (not an error: the likelihood may be flat or want more)."""
    from scipy.optimize import minimize           # lazy: keeps `import locbook` fast
    check_choice("kind", kind, tuple(_FILTERS))
    streams = _as_list(measurements)
    fit_R = [fit_R] * len(streams) if fit_R is None or isinstance(fit_R, str) else list(fit_R)
    if len(fit_R) != len(streams):
        raise ValueError(f"fit_R must be one form or one per stream ({len(streams)}), got {len(fit_R)}")
    if isinstance(Q, PerStep):
        raise ValueError("fit_noise_ml fits a constant Q (a per-step Q has no one scale); give Q (n, n)")
    check_scalar("max_iter", max_iter, ge=1, integer=True)
    lo, hi = (float(v) for v in scale_bounds)
    if not 0 < lo <= 1 <= hi:
        raise ValueError(f"scale_bounds must be (low, high) with 0 < low <= 1 <= high, got {scale_bounds!r}")
    params = _Parameters(Q, streams, fit_Q, fit_R)
    p = params.size
    filt = _FILTERS[kind]
    options = {**options, "divergence_window": 0, "record": [0]}

    def log_likelihood(theta):
        """The runs' total log-likelihood at log multipliers ``theta`` (leading axes: candidates, then runs)."""
        Qt, st = params.apply(theta)
        return filt(F, Qt, x0, P0, st, **options).total_log_likelihood

    ll0 = log_likelihood(np.zeros(p))
    runs = np.shape(ll0)
    batch = runs if per_run else ()
    h = 1e-5
    steps = np.concatenate([np.zeros((1, p)), h * np.eye(p), -h * np.eye(p)])     # centre, +h e_j, -h e_j

    def objective(flat):
        theta = flat.reshape(batch + (p,))
        if not per_run:             # one theta for every run: the candidates' axis in front of the runs'
            theta = theta.reshape((1,) * len(runs) + (p,))
        cand = theta + steps.reshape((2 * p + 1,) + (1,) * len(runs) + (p,))      # (2p + 1,) + runs + (p,)
        ll = log_likelihood(cand)
        if not per_run:
            ll = ll.reshape(2 * p + 1, -1).sum(axis=-1)
        grad = (ll[1:p + 1] - ll[p + 1:]) / (2 * h)                                # (p,) + batch
        value = -float(np.sum(ll[0]))
        if not np.isfinite(value):
            return np.inf, np.zeros(flat.size)
        return value, -np.moveaxis(grad, 0, -1).ravel()

    bounds = [(np.log(lo), np.log(hi))] * (int(np.prod(batch, dtype=np.int64)) * p)
    scale = max(1.0, abs(float(np.sum(ll0))))
    res = minimize(objective, np.zeros(len(bounds)), jac=True, method="L-BFGS-B", bounds=bounds,
                   options={"maxiter": int(max_iter), "ftol": tol, "gtol": 1e-6 * scale / max(len(bounds), 1)})
    if not res.success:
        raise ConvergenceError(f"fit_noise_ml: L-BFGS-B stopped without converging after {res.nit} iterations "
                               f"({res.message}); raise max_iter or check the model")
    theta = res.x.reshape(batch + (p,))
    Qf, st = params.apply(theta)       # pooled: one Q and R for every run
    q, r = params.unpack(theta)
    at_bound = np.any((theta <= np.log(lo) + 1e-6) | (theta >= np.log(hi) - 1e-6), axis=-1)
    R = tuple((s.channel.sigma_db if isinstance(s, RssMeasurement) else s.R) if form is not None else None
              for s, form in zip(st, fit_R))
    ll = log_likelihood(theta)
    return NoiseFit(Qf, R, q, r, ll if per_run else np.sum(ll), ll0 if per_run else np.sum(ll0), at_bound,
                    int(res.nit), "ml")


def fit_noise_em(F, Q, x0, P0, measurement: LinearMeasurement, *, B=None, u=None, n_iter: int = 10,
                 fit=("Q", "R"), per_run: bool = True) -> NoiseFit:
    """Expectation-maximisation of the full Q and R of a linear-Gaussian model (module docstring; Shumway and Stoffer
    1982), ``x_k = F_k x_{k-1} + B_k u_k + w_k``, ``z_k = H x_k + d + v_k``, the prior ``x0, P0`` at step 0
    (``predict_first=False``: pykalman's convention; the step that moves the prior is not part of the model).

    E-step: :func:`locbook.kalman_filter` and :func:`locbook.rts_smoother` give the smoothed means ``m_k``,
    covariances ``V_k`` and lag-one cross-covariances ``V_{k+1,k} = V_{k+1} G_k^T`` (G the smoother gains). M-step:

        Q = 1/(T-1) sum_k [e_k e_k^T + F V_k F^T + V_{k+1} - V_{k+1,k} F^T - F V_{k+1,k}^T],
            e_k = m_{k+1} - F m_k - B u_{k+1}      (F = F_{k+1})
        R = 1/|K| sum_{k in K} [r_k r_k^T + H V_k H^T],   r_k = z_k - H m_k - d,  K the steps with every component.

    ``fit``: which of ``"Q"``, ``"R"`` to update. ``per_run``: one estimate per run (the leading axes of the readings),
    else the runs' statistics are pooled. ``history``: the log-likelihood before each iteration and at the end (it never
    decreases, up to round-off)."""
    check_scalar("n_iter", n_iter, ge=1, integer=True)
    if not isinstance(measurement, LinearMeasurement) or isinstance(measurement.H, PerStep) \
            or isinstance(measurement.R, PerStep) or measurement.mode != "parallel":
        raise ValueError("fit_noise_em takes one parallel LinearMeasurement with a constant H and R")
    unknown = set(fit) - {"Q", "R"}
    if unknown or not fit:
        raise ValueError(f"fit must name 'Q' and/or 'R', got {fit!r}")
    Q = np.asarray(Q, dtype=float)
    R = np.asarray(measurement.R, dtype=float)
    H = np.asarray(measurement.H, dtype=float)
    z = np.asarray(measurement.z, dtype=float)
    if measurement.offset is not None:
        z = z - np.asarray(measurement.offset, dtype=float)
    T, n = z.shape[-2], H.shape[-1]
    if T < 2:
        raise ValueError("fit_noise_em needs at least two steps")
    Fs = F.value if isinstance(F, PerStep) else np.asarray(F, dtype=float)[..., None, :, :]
    drift, _ = _control_drift(B, u, n, T)
    history = []

    for it in range(n_iter + 1):
        run = kalman_filter(F, Q, x0, P0, replace(measurement, R=R), B=B, u=u, predict_first=False,
                            outputs=("x_pred", "P_pred", "P_cross"), divergence_window=0)
        history.append(run.total_log_likelihood)
        if it == n_iter:
            break
        sm = rts_smoother(run)
        m, V, G = sm.x, sm.P, sm.gain
        batch = m.shape[:-2]
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
            Q = 0.5 * (Q + np.swapaxes(Q, -1, -2))
        if "R" in fit:
            full = np.all(np.isfinite(z), axis=-1)                       # batch + (T,)
            full = np.broadcast_to(full, batch + (T,))
            r = np.where(full[..., None], np.broadcast_to(z, batch + z.shape[-2:]) - m @ H.T, 0.0)
            terms = r[..., :, None] * r[..., None, :] + H @ V @ H.T
            terms = np.where(full[..., None, None], terms, 0.0)
            if per_run:
                count = full.sum(axis=-1)
                if np.any(count == 0):
                    raise ValueError("fit_noise_em: a run has no step with every reading present (R cannot be fitted)")
                R = terms.sum(axis=-3) / count[..., None, None]
            else:
                R = terms.reshape((-1,) + R.shape[-2:]).sum(axis=0) / max(int(full.sum()), 1)
            R = 0.5 * (R + np.swapaxes(R, -1, -2))
    history = np.stack([np.asarray(h) for h in history], axis=-1)
    if not per_run:
        history = history.reshape(-1, n_iter + 1).sum(axis=0)
    final = history[..., -1]
    return NoiseFit(Q, (R,), None, (None,), final, history[..., 0], np.zeros(np.shape(final), bool), int(n_iter),
                    "em", history)
