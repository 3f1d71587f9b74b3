"""The interacting multiple model (IMM) estimator: r motion models switching as a Markov chain, one mode-matched
(extended) Kalman filter per model, vectorized over leading run axes.

A target that walks straight and then turns is followed by no single motion model well: a constant-velocity model
with a small process noise lags in the turn, one with a large noise is noisy on the straight (Dogan 2015 and Gudipati
2017 both report the lag of their single models in turns). The IMM (H. A. P. Blom and Y. Bar-Shalom, "The interacting
multiple model algorithm for systems with Markovian switching coefficients", IEEE Trans. Automatic Control 33(8),
780-783, 1988; Y. Bar-Shalom, X. R. Li and T. Kirubarajan, "Estimation with Applications to Tracking and Navigation",
Wiley, 2001, Sec. 11.6.6) keeps r filters, one per mode, on one state vector, and at every step k

1. mixing probabilities (the mode at k-1 given the mode at k), with ``p_ij = transition[i, j]`` = P(mode j at k |
   mode i at k-1) and ``mu_i`` the mode probabilities at k-1:

       c_j = sum_i p_ij mu_i                     mu_{i|j} = p_ij mu_i / c_j

2. mixed initial conditions of each mode-matched filter (moment matching of the mixture):

       x0_j = sum_i mu_{i|j} x_i                 P0_j = sum_i mu_{i|j} (P_i + (x_i - x0_j)(x_i - x0_j)^T)

3. mode-matched filtering: the prediction with mode j's motion from (x0_j, P0_j), then the measurement streams'
   (extended) Kalman updates in order (:func:`locbook.tracking.streams._ekf_update`, the one EKF update of the
   library), and the mode-conditioned likelihood ``Lambda_j = N(nu_j; 0, S_j)`` of the step's readings (the product
   over the step's updates: the prediction-error decomposition, :mod:`locbook.tracking.results`);
4. mode probabilities ``mu_j = Lambda_j c_j / c``, ``c = sum_j Lambda_j c_j``, computed in log space (log-sum-exp),
   so that likelihoods of 1e-300 and below neither underflow nor divide 0 by 0; ``log c`` is the step's predictive
   log-likelihood of the readings under the mixture (what :attr:`ImmResult.log_likelihood` holds). A step without
   readings has ``Lambda_j = 1``: the probabilities move through the Markov chain alone, ``mu_j = c_j``;
5. the combined estimate (for output only; the recursion goes on with the modes' own estimates):

       x = sum_j mu_j x_j                        P = sum_j mu_j (P_j + (x_j - x)(x_j - x)^T)

Modes and state. All modes share one state vector of size n. A smaller model sits inside a larger state through
:func:`embed`, which sets the states outside it to zero at each of its predictions (mean and variance): e.g. a
constant-velocity mode in a constant-acceleration state, whose acceleration it keeps at 0. A coordinated turn with
the turn rate as a state (X. R. Li and V. P. Jilkov, "Survey of maneuvering target tracking. Part I: Dynamic models",
IEEE Trans. Aerospace and Electronic Systems 39(4), 2003, the coordinated-turn model with unknown turn rate) is a
:class:`~locbook.tracking.transition.NonlinearMotion` with its Jacobian; the constant-velocity mode beside it embeds
the 4-state model and keeps the turn rate at 0 (tests/tracking/test_imm.py builds the pair).

Vectorization. The modes are a leading axis of the filters' arrays (``(r,) + batch + (n,)`` inside; the results put
them after the run axes), so every update is one call for all runs and modes, and the measurement models' own run axes
(per-run H, anchors) broadcast against them unchanged. The linear motions are one stacked product; a loop over the
modes runs only for the NonlinearMotion ones (different functions).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._linalg import _check_state, _covariance, _mT, _raise_singular, _Singular
from .._validate import as_array
from ._loop import _check_outputs as _loop_check_outputs
from ._loop import _motion_apply, _motion_jacobian, _setup, _streams
from .results import FilterResult
from .streams import _ekf_update
from .transition import MotionModel, PerStep

__all__ = ["imm_filter", "ImmResult", "embed", "IMM_OUTPUTS"]

#: the optional outputs of :func:`imm_filter`: the mode-matched posteriors at the recorded steps
IMM_OUTPUTS = ("mode_x", "mode_P")

_NO_MODE = ("the readings at step {step} have likelihood 0 under every mode (their innovations overflow the "
            "Gaussian log-likelihood): the mode probabilities are undefined; readings far outside float64 range or a "
            "lost track")

#: tolerance on a probability vector's sum (rows of the transition matrix, the initial mode probabilities)
_SUM_TOL = 1e-9


@dataclass(frozen=True)
class ImmResult(FilterResult):
    """What :func:`imm_filter` returns (``batch`` the run axes, ``R`` the recorded steps, ``r`` the modes), in the
    vocabulary of every filter result (:class:`~locbook.tracking.results.FilterResult`):

    - ``mean`` ``batch + (R, n)``, ``cov`` ``batch + (R, n, n)``: the combined estimate (module docstring, step 5);
    - ``mode_probabilities`` ``batch + (R, r)``: the posterior mode probabilities ``mu_j`` at those steps;
    - ``log_likelihood`` ``batch + (T,)``: the step's predictive log-likelihood of its readings under the mixture,
      ``log sum_j c_j Lambda_j`` (NaN at a step without readings in that run);
    - ``steps`` ``(R,)``: the recorded step indices;
    - ``mode_x`` ``batch + (R, r, n)``, ``mode_P`` ``batch + (R, r, n, n)``: the mode-matched posteriors, when asked
      for in ``outputs`` (else None).
    """

    mean: np.ndarray
    cov: np.ndarray
    mode_probabilities: np.ndarray
    log_likelihood: np.ndarray
    steps: np.ndarray
    mode_x: np.ndarray | None = None
    mode_P: np.ndarray | None = None
    #: no consistency guard runs on the mixture (its innovations are not one Gaussian): never flagged
    diverged: np.ndarray | None = None
    diverged_step: np.ndarray | None = None

    @property
    def total_log_likelihood(self) -> np.ndarray:
        """``batch``: the log-likelihood of all the readings under the IMM's approximation (steps without readings add
        nothing)."""
        return np.nansum(self.log_likelihood, axis=-1)


def embed(motion, index, n_state: int):
    """A motion model of ``len(index)`` states placed inside a state of ``n_state``: ``(F, Q)`` ``(n_state,
    n_state)`` with the model's F and Q on the rows and columns ``index`` and zeros elsewhere, so that the states
    outside ``index`` are set to 0 (mean and variance) by this mode's prediction. ``motion``: a pair ``(F, Q)`` or a
    model with ``.F`` and ``.Q`` (e.g. :func:`locbook.constant_velocity`).

    Example: a constant-velocity mode inside a constant-acceleration state (both derivative-major, so the CA state is
    ``[x, y, vx, vy, ax, ay]`` and the CV state its first four components)::

        ca = locbook.constant_acceleration(dt_s, q_ca, layout="derivative_major")
        cv = locbook.constant_velocity(dt_s, q_cv)
        modes = [embed(cv, np.concatenate([ca.position_index, ca.velocity_index]), ca.n_state), ca]
    """
    F, Q = _pair(motion, "motion")
    if _nonlinear(F):
        raise ValueError("embed takes a linear motion (F a matrix); wrap a NonlinearMotion's f instead")
    F = as_array("motion F", F, ndim=2)
    m = F.shape[0]
    if F.shape != (m, m):
        raise ValueError(f"motion F must be square (m, m), got {F.shape}")
    Q = _covariance("motion Q", Q, m)
    if Q.ndim != 2:
        raise ValueError(f"motion Q must be ({m}, {m}), got {Q.shape}")
    if isinstance(n_state, (bool, np.bool_)) or not isinstance(n_state, (int, np.integer)) or n_state < m:
        raise ValueError(f"n_state must be an integer of at least {m} (the motion's states), got {n_state!r}")
    idx = np.asarray(index)
    if idx.shape != (m,) or not np.issubdtype(idx.dtype, np.integer) or idx.min(initial=0) < 0 \
            or idx.max(initial=0) >= n_state or np.unique(idx).size != m:
        raise ValueError(f"index must be {m} distinct state components in 0..{n_state - 1} (one per state of the "
                         f"motion), got {index!r}")
    F_full, Q_full = np.zeros((n_state, n_state)), np.zeros((n_state, n_state))
    F_full[np.ix_(idx, idx)] = F
    Q_full[np.ix_(idx, idx)] = Q
    return F_full, Q_full


def _nonlinear(F) -> bool:
    """A motion model that is not linear (its f through the protocol: apply, jacobian_at)."""
    return isinstance(F, MotionModel) and not F.linear


def _pair(motion, name: str):
    """``(F, Q)`` of a motion given as a pair, as a model with ``.F`` and ``.Q``, or as a nonlinear motion model with
    its own covariance (``(model, model.covariance(0))``: a constant Q)."""
    if hasattr(motion, "F") and hasattr(motion, "Q"):
        return motion.F, motion.Q
    if _nonlinear(motion):
        return motion, motion.covariance(0)
    if isinstance(motion, (tuple, list)) and len(motion) == 2:
        return motion[0], motion[1]
    raise ValueError(f"{name} must be a pair (F, Q) or a model with .F and .Q (e.g. locbook.constant_velocity(...)), "
                     f"got {type(motion).__name__}" + (" (for one mode pass [(F, Q)])"
                                                       if isinstance(motion, np.ndarray) else ""))


def _motions(motions):
    """The checked modes: ``[(F or NonlinearMotion, Q), ...]`` and their state size (None if all are nonlinear)."""
    if isinstance(motions, np.ndarray) or not isinstance(motions, (list, tuple)):
        raise ValueError("motions must be a list of motion models, each a pair (F, Q) or a model with .F and .Q, "
                         f"got {type(motions).__name__}")
    if len(motions) == 0:
        raise ValueError("motions must hold at least one motion model")
    out, sizes = [], []
    for i, motion in enumerate(motions):
        F, Q = _pair(motion, f"motions[{i}]")
        if isinstance(F, PerStep):
            raise ValueError(f"motions[{i}]: F must be a constant matrix (n, n) or a NonlinearMotion (per_step is not "
                             "taken by imm_filter)")
        if not _nonlinear(F):
            F = as_array(f"motions[{i}] F", F)
            if F.ndim != 2 or F.shape[0] != F.shape[1]:
                raise ValueError(f"motions[{i}]: F must be a square matrix (n, n) without run axes or a "
                                 f"NonlinearMotion, got shape {F.shape}")
            sizes.append(F.shape[0])
        Q = as_array(f"motions[{i}] Q", Q)
        if Q.ndim != 2 or Q.shape[0] != Q.shape[1]:
            raise ValueError(f"motions[{i}]: Q must be a square covariance (n, n) without run axes, got shape "
                             f"{Q.shape}")
        sizes.append(Q.shape[0])
        out.append((F, Q))
    if len(set(sizes)) > 1:
        per_mode = ", ".join(f"F {F.shape[0] if isinstance(F, np.ndarray) else 'f(x)'} / Q {Q.shape[0]}"
                             for F, Q in out)
        raise ValueError(f"motions must share one state size (embed a smaller model: locbook.tracking.imm.embed), "
                         f"got state sizes {per_mode}")
    for i, (F, Q) in enumerate(out):
        _covariance(f"motions[{i}] Q", Q, Q.shape[0])
    return out


def _transition(transition, r: int) -> np.ndarray:
    """The checked Markov matrix ``(r, r)``: non-negative, rows summing to 1."""
    T = as_array("transition", transition)
    if T.shape != (r, r):
        raise ValueError(f"transition must be a square (r, r) = ({r}, {r}) matrix for {r} motions, got shape "
                         f"{T.shape}")
    if (T < 0).any():
        i, j = (int(v) for v in np.argwhere(T < 0)[0])
        raise ValueError(f"transition must hold probabilities (non-negative), got transition[{i}, {j}] = {T[i, j]:g}")
    sums = T.sum(axis=1)
    off = np.abs(sums - 1.0) > _SUM_TOL
    if off.any():
        i = int(np.argmax(off))
        raise ValueError(f"transition rows must sum to 1 (transition[i, j] = P(mode j at k | mode i at k-1)), row {i} "
                         f"sums to {sums[i]:.12g}")
    return T


def _initial_probabilities(mode_probabilities, r: int, batch: tuple) -> np.ndarray:
    """The initial mode probabilities ``(r,) + batch`` (mode axis first), checked: ``(r,)`` or ``batch + (r,)``,
    non-negative, summing to 1."""
    if mode_probabilities is None:
        return np.full((r,) + batch, 1.0 / r)
    mu = as_array("mode_probabilities", mode_probabilities, min_ndim=1)
    if mu.shape[-1] != r:
        raise ValueError(f"mode_probabilities must end in ({r},) (one per motion), got shape {mu.shape}")
    if (mu < 0).any():
        raise ValueError("mode_probabilities must be non-negative (probabilities), got a value of "
                         f"{float(mu.min()):g}")
    sums = mu.sum(axis=-1)
    if (np.abs(sums - 1.0) > _SUM_TOL).any():
        raise ValueError(f"mode_probabilities must sum to 1 over the modes, got a sum of "
                         f"{float(sums.flat[np.argmax(np.abs(sums - 1.0))]):.12g}")
    try:
        full = np.broadcast_shapes(mu.shape[:-1], batch)
    except ValueError:
        full = None
    if full != batch:
        raise ValueError(f"mode_probabilities' run axes {mu.shape[:-1]} must broadcast to the runs {batch} of the "
                         "readings, x0 and P0")
    return np.moveaxis(np.broadcast_to(mu, batch + (r,)), -1, 0).copy()


def _check_outputs(outputs) -> frozenset:
    """The optional outputs asked for: names among IMM_OUTPUTS."""
    return _loop_check_outputs(outputs, IMM_OUTPUTS)


def _runs_mask(bad, shape: tuple) -> np.ndarray:
    """A failure mask over ``(r,) + batch`` reduced to the runs (a run fails if any of its modes does)."""
    bad = np.asarray(bad, bool)
    try:
        bad = np.broadcast_to(bad, shape)
    except ValueError:
        return bad
    return bad.any(axis=0)


def imm_filter(motions, transition, x0, P0, measurements, *, mode_probabilities=None, record=None,
               predict_first: bool = True, outputs=()) -> ImmResult:
    """The IMM estimator (Blom and Bar-Shalom 1988; Bar-Shalom, Li and Kirubarajan 2001, Sec. 11.6.6; the cycle of
    the module docstring), each mode-matched filter the EKF of :func:`locbook.extended_kalman_filter` (the KF for
    linear streams), vectorized over leading run axes.

    Parameters
    ----------
    motions : r motion models on one state vector of size n, each a pair ``(F, Q)`` (F a matrix ``(n, n)`` or a
        :class:`~locbook.NonlinearMotion` with its jacobian, Q ``(n, n)``; neither with run axes) or a model with
        ``.F`` and ``.Q`` (:func:`locbook.constant_velocity`, :class:`locbook.KinematicModel`). A smaller model goes
        inside the state through :func:`embed`.
    transition : ``(r, r)`` Markov matrix, ``transition[i, j]`` = P(mode j at step k | mode i at step k-1); rows sum
        to 1 (filterpy's ``IMMEstimator`` ``M`` in its code's use: ``cbar = mu @ M``).
    x0, P0 : the prior ``batch + (n,)``, ``batch + (n, n)``, the same for every mode; with ``predict_first`` (filterpy's
        convention) the posterior one step before step 0, so step 0 mixes and predicts; with ``predict_first=False``
        the prior at step 0 (step 0 neither mixes nor predicts, and its mode update starts from
        ``mode_probabilities``).
    measurements : the streams on one time grid, exactly as :func:`locbook.extended_kalman_filter` takes them
        (LinearMeasurement, RssMeasurement, NonlinearMeasurement, any :class:`~locbook.Stream`; NaN = not heard).
    mode_probabilities : ``(r,)`` or ``batch + (r,)``, the mode probabilities of x0 (default uniform).
    record : step indices to keep (default all); ``outputs``: among ``("mode_x", "mode_P")``.

    Returns an :class:`ImmResult`. Errors: a bad transition matrix, motions of different state sizes and the
    other inputs of the EKF are refused in one line each; a singular innovation covariance or an overflow is the
    EKF's SingularCovarianceError naming the step and the run.
    """
    modes = _motions(motions)
    r = len(modes)
    P_mat = _transition(transition, r)
    want = _check_outputs(outputs)
    measurements = _streams(measurements)
    F0, Q0 = next(((F, Q) for F, Q in modes if not _nonlinear(F)), modes[0])
    setup = _setup(F0, Q0, x0, P0, measurements, record, "imm_filter")
    batch, n, T = setup.batch, setup.n, setup.T
    for i, (F, Q) in enumerate(modes):
        if Q.shape[0] != n:
            raise ValueError(f"motions[{i}] has a state of {Q.shape[0]}, x0 of {n}")
        if _nonlinear(F) and getattr(F, "jacobian", True) is None:
            raise ValueError(f"motions[{i}] ({F.name}): the IMM's mode-matched EKF needs the motion's jacobian")
    mu = _initial_probabilities(mode_probabilities, r, batch)
    lin = [j for j, (F, _) in enumerate(modes) if not _nonlinear(F)]
    nonlin = [j for j in range(r) if j not in lin]
    expand = (slice(None),) + (None,) * len(batch)           # (r_lin, n, n) -> (r_lin, 1, ..., 1, n, n)
    F_lin = np.stack([modes[j][0] for j in lin])[expand] if lin else None
    Q_lin = np.stack([modes[j][1] for j in lin])[expand] if lin else None
    all_lin = len(lin) == r

    shape = (r,) + batch
    X = np.broadcast_to(setup.x, shape + (n,)).copy()
    P = np.broadcast_to(setup.P, shape + (n, n)).copy()
    steps, slot = setup.steps, setup.slot
    R = steps.size
    out_x, out_P = np.empty(batch + (R, n)), np.empty(batch + (R, n, n))
    out_mu = np.empty(batch + (R, r))
    out_mx = np.empty(batch + (R, r, n)) if "mode_x" in want else None
    out_mP = np.empty(batch + (R, r, n, n)) if "mode_P" in want else None
    out_ll = np.full(batch + (T,), np.nan)
    pair = P_mat[(slice(None), slice(None)) + (None,) * len(batch)]     # p_ij over (i, j) + batch
    own = np.eye(r)[(slice(None), slice(None)) + (None,) * len(batch)]

    for k in range(T):
        if predict_first or k > 0:
            c = np.einsum("ij,i...->j...", P_mat, mu)          # predicted mode probabilities c_j
            # mixing weights mu_{i|j}; a mode of zero predicted probability (0/0) keeps its own estimate, the limit
            # of mu_{i|j} without switching (its probability stays 0, so it adds nothing to the estimate)
            safe = np.where(c > 0, c, 1.0)
            w = np.where(c[None] > 0, pair * mu[:, None] / safe[None], own)
            x_mix = np.einsum("ij...,i...n->j...n", w, X)
            d = X[:, None] - x_mix[None]                          # x_i - x0_j over (i, j) + batch + (n,)
            P_mix = (np.einsum("ij...,i...ab->j...ab", w, P)
                     + np.einsum("ij...,ij...a,ij...b->j...ab", w, d, d))
            X, P = _predict(modes, lin, nonlin, all_lin, F_lin, Q_lin, x_mix, P_mix, k, len(batch))
        else:
            c = mu
        with np.errstate(divide="ignore"):                        # log 0 = -inf: a mode ruled out
            log_c = np.log(c)
        _check_state(k, X.sum(axis=0), P.sum(axis=0))   # a mode's overflow (the sum keeps NaN/inf), named per run
        ll = np.zeros(shape)
        dof = np.zeros(batch, np.int64)
        for meas, z, act in zip(measurements, setup.zs, setup.active):
            if not act[k]:
                continue
            z_k = np.broadcast_to(z[..., k, :], shape + z.shape[-1:])
            try:
                out = _ekf_update(X, P, z_k, meas, k)
            except _Singular as exc:
                _raise_singular(k, _runs_mask(exc.bad, shape), f"innovation covariance of the {meas.name} update",
                                exc.message)
            X, P = out.x, out.P
            ll = ll + out.ll
            dof = dof + np.broadcast_to(out.dof, shape)[0]
        _check_state(k, X.sum(axis=0), P.sum(axis=0))
        # mode probabilities mu_j = c_j Lambda_j / sum_j c_j Lambda_j, in log space (log-sum-exp)
        a = log_c + ll
        top = a.max(axis=0)
        if not np.isfinite(top).all():          # every mode gives the readings likelihood 0: no mode to keep
            _raise_singular(k, ~np.isfinite(top), message=_NO_MODE)
        log_total = top + np.log(np.exp(a - top).sum(axis=0))
        mu = np.exp(a - log_total)
        out_ll[..., k] = np.where(dof > 0, log_total, np.nan)
        s = slot[k]
        if s >= 0:
            x = np.einsum("j...,j...n->...n", mu, X)
            e = X - x
            out_x[..., s, :] = x
            out_P[..., s, :, :] = np.einsum("j...,j...ab->...ab", mu, P + e[..., :, None] * e[..., None, :])
            out_mu[..., s, :] = np.moveaxis(mu, 0, -1)
            if out_mx is not None:
                out_mx[..., s, :, :] = np.moveaxis(X, 0, -2)
            if out_mP is not None:
                out_mP[..., s, :, :, :] = np.moveaxis(P, 0, -3)
    return ImmResult(out_x, out_P, out_mu, out_ll, steps, out_mx, out_mP)


def _predict(modes, lin, nonlin, all_lin, F_lin, Q_lin, x_mix, P_mix, k: int, batch_ndim: int):
    """Each mode's prediction from its mixed initial condition (``(r,) + batch`` leading): the linear modes in one
    stacked product ``F x``, ``F P F^T + Q``, the NonlinearMotion ones one by one (``f(x)``, ``J P J^T + Q``;
    :mod:`locbook.tracking.transition`)."""
    if all_lin:
        return (F_lin @ x_mix[..., None])[..., 0], F_lin @ P_mix @ _mT(F_lin) + Q_lin
    X, P = np.empty_like(x_mix), np.empty_like(P_mix)
    if lin:
        X[lin] = (F_lin @ x_mix[lin][..., None])[..., 0]
        P[lin] = F_lin @ P_mix[lin] @ _mT(F_lin) + Q_lin
    for j in nonlin:
        motion, Q = modes[j]
        J = _motion_jacobian(motion, x_mix[j], k)
        X[j] = _motion_apply(motion, x_mix[j], k, batch_ndim)
        JP = J @ P_mix[j]
        P[j] = JP @ _mT(J) + Q
    return X, P
