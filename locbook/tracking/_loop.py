"""The time loop every Kalman-family filter runs (internal): the checked inputs (:func:`_setup`), then at every step the
prediction (:func:`_predictor`: linear, per-step or nonlinear motion with the control input, or the filter's own, e.g.
the UKF's unscented prediction) and the streams' updates in the given order, each from the previous one's posterior,
with the outputs of :class:`locbook.tracking.results.KalmanResult` recorded as asked.

Speed. While the covariance recursion is the same in every run (P0, F and Q without batch axes, linear
streams whose H and R have none and whose missing components are the same in every run) the covariance is kept
unbatched and updated once per step; the first update that differs between runs broadcasts it and continues batched.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._linalg import (
    _apply,
    _batch_shape,
    _check_state,
    _covariance,
    _mT,
    _raise_singular,
    _refuse_not_finite,
    _Singular,
)
from .._validate import as_array, function_output
from ..models.base import step_matrix
from .functional import _linear_update_shared, _Out
from .results import KALMAN_OUTPUTS, KalmanResult
from .streams import Stream
from .transition import MotionModel, PerStep, _control_drift, _matrix_arg


@dataclass
class _Setup:
    """The checked inputs of a recursive filter: ``x`` ``batch + (n,)`` (a copy), ``P`` as given (possibly without
    the batch axes), the streams' measurements ``zs`` broadcast to the batch, the steps with any reading
    ``active`` per stream, the recorded ``steps`` with their output ``slot`` per step (-1: not recorded), and the
    streams' first ``cols`` on the axis of a step's readings (``cols[-1]`` = M, module docstring of results)."""

    F: np.ndarray | None
    Q: np.ndarray
    x: np.ndarray
    P: np.ndarray
    batch: tuple
    T: int
    steps: np.ndarray
    slot: np.ndarray
    zs: list
    active: list
    cols: np.ndarray
    n: int = 0
    F_steps: bool = False          # F is batch + (T, n, n): one matrix per step
    Q_steps: bool = False
    drift: np.ndarray | None = None     # the control input B_k u_k, batch + (T or 1, n)
    motion: MotionModel | None = None   # nonlinear motion (F is then None)

    @property
    def plain_motion(self) -> bool:
        """One constant linear F and Q, no control input: the compiled kernel's and the shared paths' motion."""
        return self.motion is None and not self.F_steps and not self.Q_steps and self.drift is None

    def F_at(self, k: int):
        return step_matrix(self.F, k) if self.F_steps else self.F

    def Q_at(self, k: int):
        return step_matrix(self.Q, k) if self.Q_steps else self.Q

    def drift_at(self, k: int):
        return None if self.drift is None else self.drift[..., min(k, self.drift.shape[-2] - 1), :]


def _streams(measurements) -> list:
    """The streams as a list: one stream, or a sequence of them."""
    if isinstance(measurements, Stream):
        return [measurements]
    try:
        streams = list(measurements)
    except TypeError:
        raise ValueError(f"measurements must be a measurement stream or a list of them, got "
                         f"{type(measurements).__name__}") from None
    if not all(isinstance(m, Stream) for m in streams):
        raise ValueError("measurements must be measurement streams (Stream, LinearMeasurement, RssMeasurement, "
                         f"NonlinearMeasurement), got {[type(m).__name__ for m in streams]}")
    return streams


def _check_outputs(outputs, allowed=KALMAN_OUTPUTS) -> frozenset:
    """The optional outputs asked for: names among ``allowed`` (a filter's outputs; default KALMAN_OUTPUTS)."""
    if isinstance(outputs, str):
        outputs = (outputs,)
    try:
        names = frozenset(outputs or ())
    except TypeError:
        raise ValueError(f"outputs must be a sequence of names among {allowed}, got {outputs!r}") from None
    unknown = sorted(str(v) for v in names - set(allowed))
    if unknown:
        raise ValueError(f"outputs must name fields among {allowed}, got {unknown}")
    return names


def _setup(F, Q, x0, P0, measurements, record, filter_name, B=None, u=None) -> _Setup:
    """The input checks of every Kalman-family filter (once, before the time loop). ``F`` a matrix, ``per_step``
    matrices or a NonlinearMotion; ``Q`` a covariance or ``per_step`` covariances; ``B``, ``u`` the control input
    (:mod:`locbook.tracking.transition`)."""
    if isinstance(P0, PerStep) or isinstance(x0, PerStep):
        raise ValueError("x0 and P0 are the prior of one step: they have no time axis (per_step is for F, Q, B and a "
                         "LinearMeasurement's H and R)")
    if isinstance(F, MotionModel) and F.linear:        # its matrices, as a matrix argument (the compiled paths')
        F, Q = F.F, (F.Q if Q is None else Q)
    motion = F if isinstance(F, MotionModel) else None
    if motion is not None:
        x = as_array("x0", x0)
        if x.ndim < 1:
            raise ValueError(f"x0 must end in (n,), got {x.shape}")
        n = x.shape[-1]
    else:
        shape = F.shape if isinstance(F, PerStep) else np.shape(F)
        if len(shape) < 2 or shape[-1] != shape[-2]:
            raise ValueError("F must be square (n, n) or batch + (n, n), per_step(batch + (T, n, n)) "
                             f"or a motion model (a NonlinearMotion, a KinematicModel), got shape {shape}")
        n = shape[-1]
    measurements = _streams(measurements)
    for meas in measurements:
        meas.model.check_readings(meas.z, n)
    streams = [m.z for m in measurements]
    if not streams:
        raise ValueError(f"{filter_name} needs at least one measurement stream")
    T = {np.shape(s)[-2] for s in streams}
    if len(T) != 1:
        raise ValueError(f"measurement streams must share one time grid, got lengths {sorted(T)}")
    T = T.pop()
    F_steps = False
    F_batch = ()
    if motion is None:
        F, F_steps, F_batch = _matrix_arg("F", F, n, n, T)
    else:
        F = None
    if motion is not None and Q is None:       # the model's own covariance, step by step (one matrix if constant)
        Qs = [np.asarray(motion.covariance(k), dtype=float) for k in range(max(T, 1))]
        same = all(q.shape == Qs[0].shape and np.array_equal(q, Qs[0]) for q in Qs[1:])
        Q = Qs[0] if same else PerStep(np.stack(np.broadcast_arrays(*Qs), axis=-3), f"{motion.label}: covariance")
    Q_given, Q_steps = Q, isinstance(Q, PerStep)
    if Q_steps:
        Q = _covariance("Q (per step)", Q.value, n)
        if Q.ndim < 3 or Q.shape[-3] not in (1, T):
            raise ValueError(f"Q per step must have shape batch + ({T}, {n}, {n}), got {Q.shape}")
    else:
        Q = _covariance("Q", Q, n)
    Q_batch = Q.shape[:-3] if Q_steps else Q.shape[:-2]
    drift, drift_batch = _control_drift(B, u, n, T)
    x = as_array("x0", x0)
    if x.ndim < 1 or x.shape[-1] != n:
        raise ValueError(f"x0 must end in ({n},); got {x.shape}")
    P = _covariance("P0", P0, n)
    _refuse_ambiguous_stacks(measurements, streams, T, x, P, F_batch, Q_given, Q_batch, B)
    # every argument with run axes sets the batch (a batched Q alone runs one filter per Q)
    batch = _batch_shape(*(named for m, s in zip(measurements, streams) for named in _stream_batch_shapes(m, s)),
                         ("x0", x.shape[:-1]), ("P0", P.shape[:-2]), ("F", F_batch), ("Q", Q_batch),
                         ("B u", drift_batch))
    x = np.broadcast_to(x, batch + (n,)).copy()
    steps = np.arange(T) if record is None else np.asarray(record)
    if record is not None and (steps.ndim != 1 or not np.issubdtype(steps.dtype, np.integer)
                               or np.any(steps < 0) or np.any(steps >= T) or np.unique(steps).size != steps.size):
        raise ValueError(f"record must be distinct integer step indices in [0, {T}), got {record!r}")
    slot = np.full(T, -1)
    slot[steps] = np.arange(steps.size)
    zs = [np.broadcast_to(np.asarray(m.model.prepare_readings(s), dtype=float), batch + np.shape(s)[-2:])
          for m, s in zip(measurements, streams)]
    active = [_steps_with_readings(z) for z in zs]
    cols = np.concatenate([[0], np.cumsum([z.shape[-1] for z in zs])]).astype(np.int64)
    return _Setup(F, Q, x, P, batch, T, steps, slot, zs, active, cols, n=n, F_steps=F_steps, Q_steps=Q_steps,
                  drift=drift, motion=motion)


def _refuse_ambiguous_stacks(measurements, streams, T: int, x, P, F_batch, Q_given, Q_batch, B) -> None:
    """Refuse the shapes a peer's call (filterpy's ``batch_filter(zs, Fs=..., Qs=...)``, column readings) gives to mean
    something else than locbook reads (run axes are leading axes; module docstring of
    :mod:`locbook.tracking.transition`), when nothing else in the call says there are runs (readings, x0 and P0
    without run axes):

    - a stack of T matrices F, B or a stream's H (T the number of steps), which would be T runs of one constant
      matrix each, not one matrix per step; of the covariances Q and R only a list or tuple (filterpy's ``Qs``,
      ``Rs``): an array of covariances is a documented run axis (a sweep of noise levels, as
      :func:`locbook.fit_noise_ml` evaluates its candidates);
    - readings ``(T, 1, 1)`` (T columns of one reading), which would be T runs of one step."""
    if x.ndim > 1 or P.ndim > 2:
        return                      # the call has runs: the run axes are what they say
    for meas, z in zip(measurements, streams):
        if T == 1 and np.ndim(z) == 3 and np.shape(z)[-2:] == (1, 1) and np.shape(z)[0] > 1:
            name, k = f"{meas.name}.z", np.shape(z)[0]
            raise ValueError(f"{name} has shape {np.shape(z)}, {k} runs of one step with one reading each; for one "
                             f"reading at each of {k} steps (filterpy's column z) pass shape ({k}, 1), e.g. z[..., 0]; "
                             f"for {k} runs of one step give x0 its run axis")
    if T < 2 or any(np.ndim(z) > 2 for z in streams):
        return
    listed = lambda value: isinstance(value, (list, tuple))
    named = [("F", F_batch)] + ([("Q", Q_batch)] if listed(Q_given) else [])
    if B is not None and not isinstance(B, PerStep):
        named.append(("B", np.shape(B)[:-2]))
    for meas in measurements:
        for name, value, matrix in meas.model.listed_matrices():
            if (matrix and not isinstance(value, PerStep)) or listed(value):
                named.append((name, np.shape(value)[:-2]))
    for name, run_axes in named:
        if run_axes and run_axes[-1] == T:
            raise ValueError(f"{name} has {T} matrices on its leading axis, as many as the readings' steps: an "
                             f"unmarked stack is {T} runs of one constant matrix each; for one matrix per step pass "
                             f"per_step({name.rsplit('.', 1)[-1]}) (filterpy's list of per-step matrices), for {T} "
                             "runs give the readings (or x0) their run axis")


def _stream_batch_shapes(meas, z):
    """The run axes that a stream's arrays carry, named: its readings ``batch + (T, m)`` and its model's parameters."""
    return [(f"{meas.name}.z", np.shape(z)[:-2])] + meas.model.run_shapes()


def _steps_with_readings(z):
    """``(T,)``: the steps at which ``z`` ``batch + (T, m)`` has a reading in some run (batch axes reduced first:
    one pass over contiguous memory)."""
    if z.size == 0:
        return np.zeros(z.shape[-2], bool)
    finite = np.isfinite(z).reshape(-1, z.shape[-2] * z.shape[-1])
    return finite.any(axis=0).reshape(z.shape[-2:]).any(axis=-1)


def _shared_pattern(z):
    """The missing-component pattern ``(T, m)`` of measurements ``batch + (T, m)`` when it is the same in every run
    (then a linear filter's covariance recursion is the same in every run too), else None."""
    if z.size == 0:
        return None
    finite = np.isfinite(z)
    flat = finite.reshape((-1,) + finite.shape[-2:])
    if flat.shape[0] == 0 or not (flat == flat[0]).all():
        return None
    return flat[0]


def _covariance_shared_throughout(setup: _Setup, measurements) -> bool:
    """True when the covariance recursion is the same in every run at every step (a linear filter with P0, F, Q, H
    and R without batch axes and the same components missing in every run): the numpy loop then updates one
    covariance per step, which beats running the runs one by one."""
    if not _motion_shared(setup) or setup.P.ndim != 2:
        return False
    if not all(_shared_terms(meas) for meas in measurements):
        return False                # (before the readings' pass below, which reads every reading)
    return all(_shared_pattern(z) is not None for z in setup.zs)


def _shared_terms(meas) -> bool:
    """A stream whose model is linear with H and R without run axes (:meth:`constant_terms`; at step 0: a model's
    per-step H and R carry their run axes at every step)."""
    return meas.model.constant_terms(0) is not None


def _motion_shared(setup: _Setup) -> bool:
    """Linear motion whose F and Q have no run axes (a control input moves the means only)."""
    return (setup.motion is None and setup.F.ndim == 2 + setup.F_steps and setup.Q.ndim == 2 + setup.Q_steps)


def _shared_linear_update(x, P, z, meas, step: int, joseph: bool = True, want: bool = False):
    """The update of a linear stream (:meth:`constant_terms`) on an unbatched covariance ``P (n, n)`` when H and R have
    no run axes and the same components are present in every run; else None (the caller goes batched)."""
    terms = meas.model.constant_terms(step)
    if terms is None:
        return None
    H, R = (np.asarray(v, float) for v in terms)
    finite = np.isfinite(z)
    m = finite.shape[-1]
    flat = finite.reshape(-1, m)
    if flat.shape[0] == 0 or not (flat == flat[0]).all():
        return None
    present = flat[0]
    if meas.mode == "parallel" or meas.order != "given":
        if meas.mode == "serial":
            return None             # a per-run order: batched
        return _linear_update_shared(x, P, z, present, H, R, joseph=joseph, want=want)
    return _serial_shared(x, P, m, lambda x, P, j: _linear_update_shared(
        x, P, z[..., j:j + 1], present[j:j + 1], H[j:j + 1], R[j:j + 1, j:j + 1], joseph=joseph, want=want), want)


def _serial_shared(x, P, m: int, update, want: bool) -> _Out:
    """Scalar updates ``update(x, P, j)`` of the components ``j = 0 .. m-1`` in order on the shared covariance (a
    diagonal R), each from the previous one's posterior; NIS, dof and log-likelihood summed, innovations side by
    side, S diagonal."""
    nis = ll = 0.0
    dof = 0
    nus, var = [], []
    for j in range(m):
        o = update(x, P, j)
        x, P, nis, dof, ll = o.x, o.P, nis + o.nis, dof + o.dof, ll + o.ll
        if want:
            nus.append(o.nu[..., 0])
            var.append(o.S[..., 0, 0])
    if not want:
        return _Out(x, P, nis, dof, ll)
    nu = np.stack(np.broadcast_arrays(*nus), axis=-1)
    v = np.stack(np.broadcast_arrays(*var), axis=-1)
    S = np.where(np.eye(m, dtype=bool), v[..., :, None], 0.0)
    S = np.where(np.isnan(v)[..., :, None] | np.isnan(v)[..., None, :], np.nan, S)
    return _Out(x, P, nis, dof, ll, nu, S)


_MOTION_FINITE = "for a finite state: f (and its jacobian) must return finite values"


def _motion_apply(motion: MotionModel, x, k: int, batch_ndim: int) -> np.ndarray:
    """``f(x)`` of any motion model, checked for a user's model (:func:`locbook._validate.function_output`; finite:
    a NaN from f is named, not taken for an overflow of the filter). ``batch_ndim``: the run axes of ``x`` (the rest:
    a sigma point's, the state's)."""
    out = motion.apply(x, k)
    if motion.checks_own_output:
        return out
    out = function_output(f"{motion.label}: f", out, np.shape(x), 1, np.shape(x))
    _refuse_not_finite(f"{motion.label}: f", out, ~np.isfinite(out), batch_ndim, k, _MOTION_FINITE)
    return out


def _motion_jacobian(motion: MotionModel, x, k: int) -> np.ndarray:
    """The EKF's ``df/dx`` ``(..., n, n)`` at ``x`` ``batch + (n,)``, checked for a user's model (unbatched ``(n, n)``
    kept as given)."""
    J = motion.jacobian_at(x, k)
    if motion.checks_own_output:
        return J
    n = np.shape(x)[-1]
    J = function_output(f"{motion.label}: jacobian", J, np.shape(x)[:-1] + (n, n), 2, np.shape(x), broadcast=False)
    _refuse_not_finite(f"{motion.label}: jacobian", J, np.broadcast_to(~np.isfinite(J), np.shape(x)[:-1] + (n, n)),
                       np.ndim(x) - 1, k, _MOTION_FINITE)
    return J


def _predictor(setup: _Setup):
    """The prediction of the KF and the EKF (:mod:`locbook.tracking.transition`): ``predict(x, P, k, cross)`` ->
    ``(x-, P-, C)`` with the cross-covariance ``C = P F^T`` (``P J^T`` for nonlinear motion) when ``cross``."""
    motion = setup.motion
    if motion is not None:
        def predict(x, P, k, cross):
            J = _motion_jacobian(motion, x, k)
            x_pred = _motion_apply(motion, x, k, x.ndim - 1)
            d = setup.drift_at(k)
            if d is not None:
                x_pred = x_pred + d
            JP = J @ P
            return x_pred, JP @ _mT(J) + setup.Q_at(k), (_mT(JP) if cross else None)
        return predict
    Ft_const = None if setup.F_steps else np.ascontiguousarray(_mT(setup.F))

    def predict(x, P, k, cross):
        F = setup.F_at(k)
        Ft = Ft_const if Ft_const is not None else _mT(F)
        FP = F @ P
        x_pred = x @ Ft if F.ndim == 2 else _apply(F, x)
        d = setup.drift_at(k)
        if d is not None:
            x_pred = x_pred + d
        return x_pred, FP @ Ft + setup.Q_at(k), (_mT(FP) if cross else None)
    return predict


def _run(setup: _Setup, measurements, update, predict_first: bool, *, shared: bool = False, literal: bool = False,
         joseph: bool = True, outputs=frozenset(), predict=None) -> KalmanResult:
    """The time loop: at every step predict (unless ``predict_first`` is False at step 0), then apply the streams
    present at that step in order with ``update(x, P, z_k, stream, k, want)`` (each from the previous one's
    posterior; it returns a :class:`locbook.tracking.functional._Out`). ``shared``: keep the covariance unbatched
    while it is the same in every run (module docstring; the linear streams' update in the Joseph form or, with
    ``joseph=False``, the short form). ``literal``: the updates start from the previous
    posterior instead of the prediction, and a run without a reading takes the prediction (document 003's printed
    update, :func:`locbook.kalman_filter`). ``outputs``: the optional fields to record (results.KALMAN_OUTPUTS).
    ``predict``: the prediction ``(x, P, k, cross) -> (x-, P-, C)`` (default :func:`_predictor`'s)."""
    x, batch, n = setup.x, setup.batch, setup.n
    predict = predict or _predictor(setup)
    shared = shared and _motion_shared(setup) and setup.P.ndim == 2
    P = setup.P.copy() if shared else np.broadcast_to(setup.P, batch + (n, n)).copy()
    steps, slot, T, cols = setup.steps, setup.slot, setup.T, setup.cols
    R, M = steps.size, int(cols[-1])
    out_x = np.empty(batch + (R, n))
    out_P = _CovarianceRecord(batch, R, n, shared)
    out_nis = np.full(batch + (T,), np.nan)
    out_ll = np.full(batch + (T,), np.nan)
    out_dof = np.zeros(batch + (T,), np.int64)
    out_xp = np.empty(batch + (R, n)) if "x_pred" in outputs else None
    out_Pp = _CovarianceRecord(batch, R, n, shared) if "P_pred" in outputs else None
    out_Pc = _CovarianceRecord(batch, R, n, shared, np.nan) if "P_cross" in outputs else None
    out_nu = np.full(batch + (R, M), np.nan) if "innovation" in outputs else None
    out_S = np.full(batch + (R, M, M), np.nan) if "S" in outputs else None
    want = out_nu is not None or out_S is not None
    if out_S is not None:           # the streams' blocks of a step's S (its updates' innovations are independent)
        block = np.zeros((M, M), bool)
        for c0, c1 in zip(cols[:-1], cols[1:]):
            block[c0:c1, c0:c1] = True
    for k in range(T):
        s = slot[k]
        if predict_first or k > 0:
            try:
                x_pred, P_pred, cross = predict(x, P, k, out_Pc is not None and s >= 0)
            except _Singular as exc:
                _raise_singular(k, exc.bad, "state covariance", exc.message)
            _check_state(k, x_pred, P_pred)          # an overflow in the prediction is named as such
            if cross is not None:
                out_Pc.put(s, cross)
        else:
            x_pred, P_pred = x, P
        # document 003's printed update starts from the previous posterior, not the prediction
        x, P = (x, P) if literal else (x_pred, P_pred)
        if s >= 0 and out_xp is not None:
            out_xp[..., s, :] = x
        if s >= 0 and out_Pp is not None:
            out_Pp.put(s, P)
        nis, dof, ll = 0.0, 0, 0.0
        for i, (meas, z, act) in enumerate(zip(measurements, setup.zs, setup.active)):
            if not act[k]:
                continue
            try:
                out = None
                if shared:
                    out = _shared_linear_update(x, P, z[..., k, :], meas, k, joseph, want)
                    if out is None:
                        shared = False
                        P = np.broadcast_to(P, batch + (n, n)).copy()
                        if literal:
                            P_pred = np.broadcast_to(P_pred, batch + (n, n))
                if out is None:
                    out = update(x, P, z[..., k, :], meas, k, want)
            except _Singular as exc:
                _raise_singular(k, exc.bad, f"innovation covariance of the {meas.name} update", exc.message)
            x, P = out.x, out.P
            nis, dof, ll = nis + out.nis, dof + out.dof, ll + out.ll
            if want and s >= 0:
                c0, c1 = cols[i], cols[i + 1]
                if out_nu is not None:
                    out_nu[..., s, c0:c1] = out.nu
                if out_S is not None:
                    out_S[..., s, c0:c1, c0:c1] = out.S
        if literal:                               # a run without a reading at this step takes the prediction
            updated = np.asarray(dof) > 0
            if shared:
                if not updated:
                    x, P = x_pred, P_pred
            elif not updated.all():
                x = np.where(updated[..., None], x, x_pred)
                P = np.where(updated[..., None, None], P, P_pred)
        _check_state(k, x, P)
        if out_S is not None and s >= 0:          # zero off the blocks, NaN in the rows and columns of missing readings
            v = np.concatenate([np.isfinite(z[..., k, :]) for z in setup.zs], axis=-1)
            out_S[..., s, :, :] = np.where(v[..., :, None] & v[..., None, :],
                                           np.where(block, out_S[..., s, :, :], 0.0), np.nan)
        has = np.asarray(dof) > 0
        out_nis[..., k] = np.where(has, nis, np.nan)
        out_ll[..., k] = np.where(has, ll, np.nan)
        out_dof[..., k] = dof
        if s >= 0:
            out_x[..., s, :] = x
            out_P.put(s, P)
    covariance = lambda record: None if record is None else record.array()
    return KalmanResult(out_x, out_P.array(), steps, out_xp, covariance(out_Pp), out_nu, out_S, out_ll, out_nis,
                        out_dof, P_cross=covariance(out_Pc), variant="literal_george" if literal else "corrected")


class _CovarianceRecord:
    """A recorded covariance output ``batch + (R, n, n)``, kept as one ``(R, n, n)`` array while the covariance is
    the same in every run (the shared path: writing it into every run at every step costs more than the recursion)
    and spread over the runs when a batched value first arrives, or at the end."""

    def __init__(self, batch, R: int, n: int, shared: bool, fill=None):
        self.batch = batch
        empty = (lambda shape: np.full(shape, fill)) if fill is not None else np.empty
        self.small = empty((R, n, n)) if shared else None
        self.big = None if shared else empty(batch + (R, n, n))

    def put(self, slot: int, value) -> None:
        if self.big is None:
            if np.ndim(value) == 2:
                self.small[slot] = value
                return
            self.big = np.broadcast_to(self.small, self.batch + self.small.shape).copy()
        self.big[..., slot, :, :] = value

    def array(self) -> np.ndarray:
        return self.big if self.big is not None else np.broadcast_to(self.small, self.batch + self.small.shape).copy()
