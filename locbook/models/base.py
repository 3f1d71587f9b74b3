"""The measurement-model protocol every filter is written against (after Stone Soup's ``MeasurementModel`` and the
Feynman-Kac models of ``particles``): a model says what a reading is, a filter says how to update on it.

A measurement model of ``m`` readings per step, ``z_k = h(x_k) + v_k``, ``v_k ~ N(0, R(x_k))``, has

- :attr:`~MeasurementModel.n_readings` ``m`` and a :attr:`~MeasurementModel.name` (named in every error);
- :meth:`~MeasurementModel.mean` ``h(x)`` (required), :meth:`~MeasurementModel.jacobian` ``dh/dx`` (the EKF's;
  the UKF, the particle and the grid filters do without), :meth:`~MeasurementModel.covariance` ``R(x)``;
- :meth:`~MeasurementModel.log_likelihood` of readings, Gaussian from the three by default (the particle and grid
  filters' weights);
- optionally :meth:`~MeasurementModel.residual` ``a - b`` of readings and :meth:`~MeasurementModel.mean_of` (the
  UKF's weighted mean of predicted readings), for readings on a circle (a bearing);
- :meth:`~MeasurementModel.linearized`: the linear-Gaussian model the EKF updates with at a state, derived from the
  above unless a model knows better (a linear model is its own linearisation, exactly).

Shapes ("points form"): every method takes states ``x`` of shape ``batch + (K, n)``, ``K`` points per run (the
EKF's one state, the UKF's ``2n + 1`` sigma points, ``N`` particles, the cells of a grid), ``batch`` the run axes,
against which the model's own run axes (e.g. a per-run ``H`` ``batch + (m, n)``) broadcast. They return readings
``batch + (K, m)``, Jacobians ``batch + (K, m, n)``, covariances broadcasting to ``batch + (K, m, m)`` and
log-likelihoods ``batch + (K,)``; ``step`` is the time step (for models whose parameters change with it). NaN in a
reading means "not heard": the filters leave it out, and :meth:`~MeasurementModel.log_likelihood` counts only the
readings present.

A new sensor (a range, a barometer, a bearing) is one subclass defining :attr:`n_readings`, :meth:`mean`, and
:meth:`covariance` (plus :meth:`jacobian` for the EKF): every filter then takes it, on its numpy path (the compiled
kernels know the library's own models only, :mod:`locbook.tracking._compiled`).

A leading time axis is marked by :func:`per_step` (run axes are leading axes too: an unmarked ``(T, m, n)`` array is
``T`` runs of one constant matrix each).
"""
from __future__ import annotations

import numpy as np

from .._linalg import _LOG_2PI, _covariance, _refuse_not_finite, psd_root
from .._validate import as_array, call_user, function_output

__all__ = ["MeasurementModel", "LinearGaussian", "FunctionMeasurement", "MotionModel", "LinearMotion", "PerStep",
           "per_step", "step_matrix", "per_state"]


class PerStep:
    """An array whose axis ``-3`` is time: a matrix per step ``batch + (T, r, c)`` (made by :func:`per_step`)."""

    __slots__ = ("value",)
    value: np.ndarray

    def __init__(self, value, name: str = "per_step value"):
        value = as_array(name, value.value if isinstance(value, PerStep) else value)
        if value.ndim < 3:
            raise ValueError(f"{name} must have shape batch + (T, rows, cols) (a matrix per step), got {value.shape}")
        self.value = value

    @property
    def shape(self) -> tuple:
        return self.value.shape

    def at(self, step: int) -> np.ndarray:
        """The matrix of ``step``: ``batch + (r, c)`` (:func:`step_matrix`)."""
        return step_matrix(self.value, step)

    def __repr__(self) -> str:
        return f"per_step(array of shape {self.value.shape})"


def step_matrix(value: np.ndarray, step: int) -> np.ndarray:
    """The matrix of ``step`` from a per-step array ``batch + (T, r, c)``; a time axis of length 1 holds one matrix
    for every step."""
    return value[..., min(step, value.shape[-3] - 1), :, :]


def per_step(value) -> PerStep:
    """Mark ``value`` ``batch + (T, r, c)`` as one matrix per time step (F, Q, B, or a linear model's H and R)."""
    return PerStep(value)


def at_points(value, tail: int):
    """A points-form output (``batch + (K,) + tail``, ``tail`` its last ``tail`` axes) at the single point ``K = 1``:
    the point axis dropped; an output without it (a constant, ``tail`` axes only) kept as it is."""
    value = np.asarray(value)
    return value[(Ellipsis, 0) + (slice(None),) * tail] if value.ndim > tail else value


def per_state(fn):
    """A function of one state ``(n,)`` (filterpy's ``hx(x)``, ``fx(x)``) made a function of states ``(..., n)`` over
    any leading axes, as every locbook filter calls it (all runs, sigma points or particles at once): ``fn`` applied
    to each state in turn (a Python loop: slow for many runs; write ``fn`` over leading axes where speed matters)."""
    def over_states(x, *args):
        x = np.asarray(x, dtype=float)
        lead = x.shape[:-1]
        flat = x.reshape((-1, x.shape[-1]))
        out = [np.asarray(fn(state, *args), dtype=float) for state in flat]
        tail = out[0].shape if out else ()
        return np.stack(out).reshape(lead + tail) if out else np.zeros(lead + tail)
    over_states.__name__ = getattr(fn, "__name__", "per_state")
    return over_states


def per_state_hint(name: str, fn, x, args=(), tail=None) -> str | None:
    """When ``fn`` failed on states ``x`` ``(..., n)`` with leading axes: the one-line refusal saying so if ``fn``
    works on one state (a per-state function, filterpy's form: an output of shape ``tail``, or at least one axis),
    else None (its own error stands)."""
    x = np.asarray(x)
    if x.ndim < 2:
        return None
    try:
        out = np.asarray(fn(x[(0,) * (x.ndim - 1)], *args), dtype=float)
    except Exception:                       # noqa: BLE001 - not a per-state function either: its own error stands
        return None
    if out.ndim == 0 or (tail is not None and out.shape != tuple(tail)) or not np.all(np.isfinite(out)):
        return None
    return (f"{name} works on one state (n,) but not on states of shape {x.shape}: locbook calls it with every run "
            "(and the UKF's sigma points) at once, states (..., n); write it over leading axes (x[..., 0] for x[0], "
            "H @ x[..., None] for H @ x) or wrap it with locbook.per_state")


class MeasurementModel:
    """The protocol of a measurement model (module docstring). Subclasses define :attr:`n_readings` and
    :meth:`mean`, and :meth:`covariance` unless they override :meth:`log_likelihood` and are used by the particle and
    grid filters only; the rest has defaults."""

    #: the model's name in errors (a subclass may set it per instance)
    name: str = ""

    @property
    def label(self) -> str:
        """The name errors use: :attr:`name`, or the class name."""
        return self.name or type(self).__name__

    @property
    def n_readings(self) -> int:
        """``m``, the readings per step."""
        raise NotImplementedError(f"{type(self).__name__} must define n_readings (the readings per step)")

    def mean(self, x, *, step: int = 0):
        """``h(x)`` ``batch + (K, m)`` at states ``batch + (K, n)``."""
        raise NotImplementedError(f"{type(self).__name__} must define mean(x, *, step)")

    def jacobian(self, x, *, step: int = 0):
        """``dh/dx`` ``batch + (K, m, n)`` (the EKF's)."""
        raise ValueError(f"{self.label}: the EKF needs the model's jacobian (the UKF, particle and grid filters do "
                         "not)")

    def covariance(self, x, *, step: int = 0):
        """``R(x)``, broadcasting to ``batch + (K, m, m)``."""
        raise NotImplementedError(f"{type(self).__name__} must define covariance(x, *, step)")

    def covariance_at(self, x, *, step: int = 0):
        """``R`` at states ``x`` ``batch + (n,)`` (one point per run; the UKF's R at its predicted mean), broadcasting
        to ``batch + (m, m)``."""
        X = x[..., None, :]
        return at_points(self._checked_covariance(self.covariance(X, step=step), X, step), 2)

    def _checked_covariance(self, value, x, step: int):
        """A user model's covariance at points ``x``, checked (:func:`check_covariance`); the library's as given."""
        return value if self.checks_own_output else check_covariance(self, value, x, step)

    def residual(self, a, b):
        """``a - b`` of readings (override for readings on a circle)."""
        return a - b

    def mean_of(self, values, weights):
        """The UKF's weighted mean of predicted readings ``(..., N, m)`` with weights ``(N,)`` (override for a circular
        mean)."""
        return weights @ values

    @property
    def linear_residual(self) -> bool:
        """True when :meth:`residual` and :meth:`mean_of` are the linear forms (the filters then skip calling them)."""
        cls = type(self)
        return cls.residual is MeasurementModel.residual and cls.mean_of is MeasurementModel.mean_of

    def log_likelihood(self, z, x, *, step: int = 0):
        """``log N(z; h(x), R(x))`` ``batch + (K,)`` of readings ``z`` ``batch + (m,)`` at states ``batch + (K, n)``,
        over the readings present (NaN = not heard: left out; no reading present gives 0)."""
        z = np.asarray(z, dtype=float)[..., None, :]
        valid_any = np.isfinite(z)
        h = np.asarray(self.mean(x, step=step), dtype=float)
        if not self.checks_own_output:
            h = check_output(self, "mean", h, x, (self.n_readings,), valid_any, step)
        R = np.asarray(self._checked_covariance(self.covariance(x, step=step), x, step), dtype=float)
        valid = np.isfinite(z)
        nu = np.where(valid, self.residual(np.where(valid, z, h), h), 0.0)
        m = nu.shape[-1]
        pair = valid[..., :, None] & valid[..., None, :]
        R = np.where(pair, np.broadcast_to(R, nu.shape[:-1] + (m, m)), np.eye(m))
        L = np.linalg.cholesky(R)
        w = np.linalg.solve(L, nu[..., None])[..., 0]
        logdet = 2.0 * np.log(np.diagonal(L, axis1=-2, axis2=-1)).sum(axis=-1)
        dof = valid.sum(axis=-1)
        return -0.5 * (np.einsum("...i,...i->...", w, w) + logdet + dof * _LOG_2PI)

    def relative_log_likelihood(self, z, x, *, step: int = 0):
        """:meth:`log_likelihood` up to a constant per run (what the particle and grid filters' normalised weights
        need; a model may leave out the terms that do not depend on the state)."""
        return self.log_likelihood(z, x, step=step)

    #: the dimension of the positions the model reads (the filters hand it a state's position components), or None
    #: for a model of full states
    position_dim = None

    def innovation(self, x, z, *, step: int = 0):
        """The EKF's linearisation at states ``x`` ``batch + (n,)`` for readings ``z`` ``batch + (m,)``: the
        innovation ``nu = z - h(x)`` (the model's residual; NaN where a reading is missing), ``H = dh/dx`` ``batch +
        (m, n)`` and ``R`` (broadcasting to ``batch + (m, m)``), from :meth:`mean`, :meth:`jacobian` and
        :meth:`covariance` at the one point ``x``, checked (:func:`check_output`)."""
        X = x[..., None, :]
        valid = np.isfinite(z)
        H = check_output(self, "jacobian", self.jacobian(X, step=step), X, (self.n_readings, x.shape[-1]),
                         valid[..., None, :, None], step)[..., 0, :, :]
        h = check_output(self, "mean", self.mean(X, step=step), X, (self.n_readings,), valid[..., None, :],
                         step)[..., 0, :]
        if self.linear_residual:
            nu = np.where(valid, z, h) - h
        else:
            nu = check_output(self, "residual", self.residual(np.where(valid, z, h), h), x, (self.n_readings,),
                              valid, step, points=False)
        return nu, H, at_points(self._checked_covariance(self.covariance(X, step=step), X, step), 2)

    def linearized(self, x, z, *, step: int = 0):
        """The linear-Gaussian model ``z' = H x + v``, ``v ~ N(0, R)``, the (parallel) EKF update uses at ``x``:
        ``(z', H, R)`` with ``z' = nu + H x`` (:meth:`innovation`), so that its innovation ``z' - H x`` is ``nu``;
        NaN where ``z`` is."""
        nu, H, R = self.innovation(x, z, step=step)
        return np.where(np.isfinite(z), nu + (H @ x[..., None])[..., 0], np.nan), H, R

    def constant_terms(self, step: int = 0):
        """``(H, R)`` without run axes when the model is linear with the same H and R in every run (the filters then
        keep one covariance for all runs while the missing readings agree), else None."""
        return None

    #: True for a linear-Gaussian model (what the Kalman filter takes; its linearisation is itself)
    linear: bool = False

    #: True for the library's own models, which check their outputs themselves (the filters check a user model's)
    checks_own_output: bool = False

    def independent_readings(self) -> bool:
        """True when the readings of a step are independent given the state (a diagonal R): the condition of serial
        updates (one scalar update per reading). Default: False (unknown)."""
        return False

    def prepare_readings(self, z):
        """The readings the updates use, computed once before the time loop (a linear model takes its offset off)."""
        return z

    def noise(self):
        """What a noise fit scales (:func:`locbook.fit_noise_ml`): ``("covariance", R)`` (``batch + (m, m)``) or
        ``("variances", v)`` (per-reading variances ``batch + (1 or m,)``); a model whose noise cannot be fitted
        raises a ValueError saying so."""
        raise ValueError(f"{self.label}: this model's noise cannot be fitted; give fit_R=None for this stream")

    def with_noise(self, value) -> "MeasurementModel":
        """The model with its noise (:meth:`noise`'s form) replaced by ``value`` (derived from a checked one: not
        re-checked)."""
        raise ValueError(f"{self.label}: this model's noise cannot be fitted; give fit_R=None for this stream")

    def listed_matrices(self) -> list:
        """``[(name, value), ...]``: the model's matrices as given, for the refusal of a peer's list of per-step
        matrices taken for run axes (:func:`locbook.tracking._loop._setup`)."""
        return []

    def function_name(self, what: str) -> str:
        """The name errors give the model's function ``what`` (``"mean"``, ``"jacobian"``, ``"residual"``,
        ``"mean_of"``)."""
        return what

    def user_function(self, what: str):
        """The user's function behind ``what`` (a model given by functions), else None."""
        return None

    def run_shapes(self) -> list:
        """The run axes the model's own parameters carry, named: ``[(name, shape), ...]`` (default none)."""
        return []

    def check_readings(self, z, n_state: int | None) -> None:
        """Refuse readings ``batch + (T, m)`` (or a state size; None: the particle and grid filters, whose particle
        size the model does not fix) the model cannot take, in one line."""
        if np.shape(z)[-1] != self.n_readings:
            raise ValueError(f"{self.label}: the readings have {np.shape(z)[-1]} components per step on their last "
                             f"axis, the model {self.n_readings}")


_PRESENT = ("for a reading that is present: it must be finite wherever z has a reading (a missing reading is a NaN "
            "in z, not in the model's output)")


def check_output(model, what: str, value, x, tail: tuple, present, step: int, *, points: bool = True):
    """A model's output ``what`` (``"mean"``, ``"jacobian"``, ``"residual"``) at states ``x``, checked: real, ending
    in ``tail`` (after the point axis when ``points``), finite wherever a reading is ``present`` (broadcasting to
    it). One ValueError line naming the model, the function and the step otherwise."""
    x_shape = np.shape(x)
    name = f"{model.label}: {model.function_name(what)}"
    try:
        out = function_output(name, value, x_shape[:-1] + tail, len(tail), x_shape)
    except ValueError as exc:
        fn = model.user_function(what)
        why = None if fn is None or what == "residual" else per_state_hint(name, fn, x, tail=tail)
        if why is None:
            raise
        raise ValueError(f"{why} ({exc})") from None
    _refuse_not_finite(name, out, present & ~np.isfinite(out), len(x_shape) - 1 - points, step, _PRESENT)
    return out


def check_covariance(model, value, x, step: int):
    """A model's covariance at points ``x`` ``batch + (K, n)``, checked: real, ending in ``(m, m)`` with leading
    axes that broadcast to ``batch + (K,)`` (a per-run R is ``batch + (1, m, m)`` in points form: a ``batch + (m,
    m)`` one would be read as K points), finite, with no negative variance. One ValueError line naming the model and
    the step otherwise."""
    m = model.n_readings
    x_shape = np.shape(x)
    name = f"{model.label}: covariance"
    out = function_output(name, value, x_shape[:-1] + (m, m), 2, x_shape, broadcast=False)
    _refuse_not_finite(name, out, ~np.isfinite(out), max(len(x_shape) - 2, 0), step,
                       "(a covariance must be finite)")
    if np.any(np.diagonal(out, axis1=-2, axis2=-1) < 0):
        raise ValueError(f"{name} returned a negative variance at step {step}: a covariance has a non-negative "
                         "diagonal")
    return out


def with_covariance(model, R):
    """A copy of a model that keeps its covariance in ``R`` (and ``_given_R``) with ``R`` replaced, not checked again
    (a noise fit's candidate: a congruence of a checked covariance)."""
    out = object.__new__(type(model))
    out.__dict__.update(model.__dict__)
    out.R = out._given_R = R
    return out


class LinearGaussian(MeasurementModel):
    """``z_k = H_k x_k + d_k + v_k``, ``v_k ~ N(0, R_k)`` (the Kalman filter's model).

    ``H``: ``(m, n)``, with run axes ``batch + (m, n)``, or one per step ``per_step(batch + (T, m, n))``; ``R``:
    ``(m, m)``, ``batch + (m, m)`` or ``per_step(batch + (T, m, m))`` (checked: a covariance). ``offset``: ``d``
    (pykalman's observation offset), ``(m,)`` or per step ``batch + (T, m)``: the filters update with ``z - d``.
    """

    def __init__(self, H, R, offset=None, *, name: str = ""):
        self.name = name
        self._given_R = R
        Hv = H.value if isinstance(H, PerStep) else as_array(f"{self.label}.H", H)
        if Hv.ndim < 2:
            raise ValueError(f"{self.label}: H must be (m, n) or batch + (m, n), got shape {Hv.shape}")
        m = Hv.shape[-2]
        _covariance(f"{self.label}.R", R.value if isinstance(R, PerStep) else R, m)
        self.H, self.R = H if isinstance(H, PerStep) else Hv, R if isinstance(R, PerStep) else np.asarray(R, float)
        self.offset = None if offset is None else as_array(f"{self.label}.offset", offset, min_ndim=1)
        if self.offset is not None and self.offset.shape[-1] != m:
            raise ValueError(f"{self.label}: offset must have shape ({m},) or batch + (T, {m}), "
                             f"got {self.offset.shape}")

    @property
    def n_readings(self) -> int:
        return np.shape(self.H)[-2]

    @property
    def n_state(self) -> int:
        return np.shape(self.H)[-1]

    def H_at(self, step: int) -> np.ndarray:
        return self.H.at(step) if isinstance(self.H, PerStep) else self.H

    def R_at(self, step: int) -> np.ndarray:
        return self.R.at(step) if isinstance(self.R, PerStep) else self.R

    def mean(self, x, *, step: int = 0):
        H = self.H_at(step)
        return x @ H.T if H.ndim == 2 else np.einsum("...mn,...kn->...km", H, x)

    def jacobian(self, x, *, step: int = 0):
        H = self.H_at(step)
        return H if H.ndim == 2 else H[..., None, :, :]

    def covariance(self, x, *, step: int = 0):
        R = self.R_at(step)
        return R if R.ndim == 2 else R[..., None, :, :]

    def innovation(self, x, z, *, step: int = 0):
        H = self.H_at(step)
        return z - (x @ H.T if H.ndim == 2 else (H @ x[..., None])[..., 0]), H, self.R_at(step)

    def linearized(self, x, z, *, step: int = 0):
        """Exactly itself: ``(z, H, R)`` (the offset is taken off the readings once, before the time loop)."""
        return z, self.H_at(step), self.R_at(step)

    def constant_terms(self, step: int = 0):
        H, R = self.H_at(step), self.R_at(step)
        return (H, R) if H.ndim == 2 and R.ndim == 2 else None

    def per_step_fields(self) -> bool:
        return isinstance(self.H, PerStep) or isinstance(self.R, PerStep)

    def run_shapes(self) -> list:
        axes = lambda v: v.shape[:-3] if isinstance(v, PerStep) else np.shape(v)[:-2]
        shapes = [(f"{self.label}.H", axes(self.H)), (f"{self.label}.R", axes(self.R))]
        if self.offset is not None and self.offset.ndim > 1:
            shapes.append((f"{self.label}.offset", self.offset.shape[:-2]))
        return shapes

    def check_readings(self, z, n_state: int | None) -> None:
        T, m = np.shape(z)[-2:]
        if np.ndim(z) >= 3 and m == 1 and np.shape(z)[-2] == self.n_readings != 1:
            raise ValueError(f"{self.label}.z has shape {np.shape(z)}, a column of {self.n_readings} readings per step "
                             f"(filterpy's (m, 1) z); pass batch + (T, m), e.g. z[..., 0] of shape {np.shape(z)[:-1]}")
        if m != self.n_readings:
            raise ValueError(f"{self.label}.H must have {m} rows (one per component of z), "
                             f"got shape {np.shape(self.H)}")
        if n_state is not None and self.n_state != n_state:
            raise ValueError(f"{self.label}.H must have shape (m, {n_state}) or batch + (m, {n_state}) (one column per "
                             f"state component), got {np.shape(self.H)}")
        for field in ("H", "R"):
            value = getattr(self, field)
            if isinstance(value, PerStep) and value.value.shape[-3] not in (1, T):
                raise ValueError(f"{self.label}.{field} per step must have {T} steps on axis -3 (one per reading "
                                 f"step), got shape {value.value.shape}")
        if self.offset is not None and self.offset.ndim > 1 and self.offset.shape[-2] not in (1, T):
            raise ValueError(f"{self.label}.offset must have shape ({m},) or batch + ({T}, {m}) like z, got "
                             f"{self.offset.shape}")

    checks_own_output = True
    linear = True

    def independent_readings(self) -> bool:
        R = self.R.value if isinstance(self.R, PerStep) else self.R
        return not np.any(R - R * np.eye(R.shape[-1]))

    def prepare_readings(self, z):
        return z if self.offset is None else z - self.offset

    def listed_matrices(self) -> list:
        return [(f"{self.label}.H", self.H, True), (f"{self.label}.R", self._given_R, False)]

    def noise(self):
        if isinstance(self.R, PerStep):
            raise ValueError("a LinearMeasurement with R per step cannot be fitted; give fit_R=None for this stream")
        return "covariance", self.R

    def with_noise(self, value) -> "LinearGaussian":
        return with_covariance(self, value)


class FunctionMeasurement(MeasurementModel):
    """A model given by functions: ``z_k = h(x_k) + v_k``, ``v_k ~ N(0, R)`` (e.g. a body-frame accelerometer, whose
    reading depends on the heading state, Gudipati 2017, Eqs. (3.9), (3.11); a bearing and range).

    ``h``: maps states ``(..., n)`` to ``(..., m)`` over any leading axes (the filters call it in points form,
    module docstring). ``jacobian``: states ``(..., n)`` to ``(..., m, n)``; the EKF needs it. ``R``: ``(m, m)`` or
    ``batch + (m, m)``, or a function of the state ``x`` ``(..., n)`` returning them (a noise that depends on the
    state; evaluated where the update linearises). ``m``: the readings per step (default: from ``R`` when it is a
    matrix). ``residual(a, b)`` and ``mean(values, weights)``: for readings on a circle (module docstring).

    What the functions return is checked (real, of the shape the model needs, finite wherever a reading is present):
    anything else is one ValueError line naming the model's function and the step; an exception raised inside a
    function reaches the caller unchanged.
    """

    def __init__(self, h, R, jacobian=None, *, m: int | None = None, name: str = "nonlinear measurement",
                 residual=None, mean=None):
        self.name = name
        if not callable(h):
            raise ValueError(f"{name}: h must be a function of the state, got {type(h).__name__}")
        for field, value in (("jacobian", jacobian), ("residual", residual), ("mean", mean)):
            if value is not None and not callable(value):
                raise ValueError(f"{name}: {field} must be a function or None, got {type(value).__name__}")
        if isinstance(R, PerStep):
            raise ValueError(f"{name}: a NonlinearMeasurement's R is one covariance or a function of the state "
                             "(per_step R is for a LinearMeasurement)")
        if m is None:
            if callable(R):
                raise ValueError(f"{name}: give m (the readings per step) when R is a function of the state")
            m = np.shape(R)[-1] if np.ndim(R) else 1
        self._m = int(m)
        self._given_R = R
        if not callable(R):
            _covariance(f"{name}: R", R, self._m)
            R = np.asarray(R, dtype=float)
        self.h, self.R, self.jacobian_fn, self.residual_fn, self.mean_fn = h, R, jacobian, residual, mean

    @property
    def n_readings(self) -> int:
        return self._m

    @property
    def linear_residual(self) -> bool:
        return self.residual_fn is None and self.mean_fn is None

    def function_name(self, what: str) -> str:
        return {"mean": "h", "mean_of": "mean"}.get(what, what)

    def user_function(self, what: str):
        return {"mean": self.h, "jacobian": self.jacobian_fn}.get(what)

    def _call(self, field: str, fn, *args):
        """``fn(*args)``; a signature that does not take them (filterpy's ``h(x, *hx_args)``) is one line saying what
        to pass."""
        form = {"h": "h(x)", "jacobian": "jacobian(x)", "residual": "residual(a, b)",
                "mean": "mean(values, weights)", "R": "R(x)"}[field]
        hint = {"h": "bind its other arguments: write lambda x: h(x, arg)",
                "jacobian": "bind its other arguments: write jacobian=lambda x: H(x, arg)"}.get(
                    field, f"give a function called as {form}")
        try:
            return call_user(fn, args, lambda exc: f"{self.name}: {field} cannot be called as {form}: {exc}; {hint}")
        except Exception as exc:
            tail = {"h": (self._m,), "R": (self._m, self._m)}.get(field)
            why = per_state_hint(f"{self.name}: {field}", fn, args[0], args[1:], tail) \
                if field in ("h", "jacobian", "R") else None
            if why is None:
                raise
            raise ValueError(f"{why} (it raised {type(exc).__name__}: {exc})") from None

    def mean(self, x, *, step: int = 0):
        return self._call("h", self.h, x)

    def jacobian(self, x, *, step: int = 0):
        if self.jacobian_fn is None:
            raise ValueError(f"{self.name}: the EKF needs its jacobian (the UKF does not)")
        return self._call("jacobian", self.jacobian_fn, x)

    def covariance(self, x, *, step: int = 0):
        if not callable(self.R):
            return self.R if self.R.ndim == 2 else self.R[..., None, :, :]
        return self._noise_at(x)

    def covariance_at(self, x, *, step: int = 0):
        return self._noise_at(x)

    def residual(self, a, b):
        return a - b if self.residual_fn is None else self._call("residual", self.residual_fn, a, b)

    def relative_log_likelihood(self, z, x, *, step: int = 0):
        """:meth:`log_likelihood` up to a constant per run (what the particle and grid filters' normalised weights
        need; a model may leave out the terms that do not depend on the state)."""
        return self.log_likelihood(z, x, step=step)

    #: the dimension of the positions the model reads (the filters hand it a state's position components), or None
    #: for a model of full states
    position_dim = None

    def innovation(self, x, z, *, step: int = 0):
        """The EKF's linearisation at ``x`` ``batch + (n,)``: ``h`` and its Jacobian called with the states as they are
        (the functions map states ``(..., n)`` over any leading axes), their outputs checked."""
        valid = np.isfinite(z)
        m, n = self._m, np.shape(x)[-1]
        H = check_output(self, "jacobian", self.jacobian(x, step=step), x, (m, n), valid[..., :, None], step,
                         points=False)
        h = check_output(self, "mean", self.mean(x, step=step), x, (m,), valid, step, points=False)
        a = np.where(valid, z, h)
        nu = a - h if self.residual_fn is None else check_output(self, "residual", self.residual(a, h), x, (m,), valid,
                                                                 step, points=False)
        return nu, H, self._noise_at(x)

    def _noise_at(self, x):
        """R at the states ``x`` ``batch + (n,)``: the fixed R, or the callback's (checked: a covariance)."""
        if not callable(self.R):
            return self.R
        m = self._m
        R = _covariance(f"{self.name}: R(x)", self._call("R", self.R, x), m)
        try:
            np.broadcast_shapes(R.shape[:-2], np.shape(x)[:-1])
        except ValueError:
            raise ValueError(f"{self.name}: R(x) returned shape {R.shape}, which does not broadcast to the runs' "
                             f"{np.shape(x)[:-1] + (m, m)}") from None
        return R

    def mean_of(self, values, weights):
        return weights @ values if self.mean_fn is None else self._call("mean", self.mean_fn, values, weights)

    def independent_readings(self) -> bool:
        return not callable(self.R) and not np.any(self.R - self.R * np.eye(self._m))

    def listed_matrices(self) -> list:
        return [] if callable(self.R) else [(f"{self.name}.R", self._given_R, False)]

    def noise(self):
        if callable(self.R):
            raise ValueError(f"{self.name}: a noise given by a function of the state cannot be fitted; give "
                             "fit_R=None for this stream")
        return "covariance", self.R

    def with_noise(self, value) -> "FunctionMeasurement":
        return with_covariance(self, value)

    def run_shapes(self) -> list:
        return [] if callable(self.R) else [(f"{self.name}.R", np.shape(self.R)[:-2])]

    def check_readings(self, z, n_state: int | None) -> None:
        if not callable(self.R):
            R = np.shape(self.R)
            if np.shape(z)[-1] == 1 and np.ndim(z) >= 3 and R[-1] == np.shape(z)[-2] != 1:
                raise ValueError(f"{self.name}: z has shape {np.shape(z)}, a column of {R[-1]} readings per step "
                                 f"(filterpy's (m, 1) z); pass batch + (T, m), e.g. z[..., 0] of shape "
                                 f"{np.shape(z)[:-1]}")
        super().check_readings(z, n_state)


class MotionModel:
    """The protocol of a motion model ``x_k = f_k(x_{k-1}) + w_k``, ``w_k ~ N(0, Q_k)`` (after Stone Soup's
    ``TransitionModel``): :meth:`apply` ``f`` (states ``(..., n)`` over any leading axes: the runs' posteriors, the
    UKF's sigma points, particles), :meth:`jacobian_at` ``df/dx`` (the EKF's), :meth:`covariance` ``Q_k``,
    :meth:`sample` (a draw of ``x_k`` given ``x_{k-1}``), and for states on a circle :meth:`difference` and
    :meth:`mean_of`. A linear model (:attr:`linear`) also has its matrices ``F`` and ``Q`` (constant, with run axes,
    or :func:`per_step`), which the Kalman filter and the compiled paths take as they are."""

    name: str = ""
    #: True for ``x_k = F_k x_{k-1} + w_k`` with the attributes ``F`` and ``Q``
    linear: bool = False
    #: True for the library's own models, which check their outputs themselves (the filters check a user model's)
    checks_own_output: bool = False

    @property
    def label(self) -> str:
        return self.name or type(self).__name__

    def apply(self, x, step: int = 0):
        """``f(x)`` ``(..., n)``."""
        raise NotImplementedError(f"{type(self).__name__} must define apply(x, step)")

    def jacobian_at(self, x, step: int = 0):
        """``df/dx`` ``(..., n, n)`` at ``x`` (the EKF's)."""
        raise ValueError(f"{self.label}: the EKF needs the motion's jacobian (the UKF does not)")

    def covariance(self, step: int = 0):
        """``Q_k`` ``(n, n)`` (or with run axes)."""
        raise ValueError(f"{self.label}: the motion has no covariance of its own; give Q")

    def difference(self, a, b):
        """``a - b`` of states (override for states on a circle)."""
        return a - b

    def mean_of(self, points, weights):
        """The weighted mean of points ``(..., N, n)`` with weights ``(N,)`` (override for a circular mean)."""
        return weights @ points

    @property
    def linear_differences(self) -> bool:
        """True when :meth:`difference` and :meth:`mean_of` are the linear forms."""
        cls = type(self)
        return cls.difference is MotionModel.difference and cls.mean_of is MotionModel.mean_of

    def sample(self, x, *, step: int = 0, rng: np.random.Generator):
        """A draw of ``x_k`` given states ``x`` ``(..., n)``: ``f(x) + L e``, ``e ~ N(0, I)``, with ``Q_k = L L^T``
        from :meth:`noise_factor` (a singular Q draws in its range only; ``Q = 0`` draws nothing)."""
        x_next = np.asarray(self.apply(x, step), dtype=float)
        root = self.noise_factor(step)
        if root is None:
            return x_next
        noise = rng.standard_normal(np.broadcast_shapes(x_next.shape[:-1], root.shape[:-2]) + root.shape[-1:])
        return x_next + np.einsum("...ik,...k->...i", root, noise)

    def noise_factor(self, step: int = 0):
        """``L`` ``(n, k)`` with ``Q_k = L L^T`` (the particle filter draws ``w = L e``, ``e ~ N(0, I_k)``), or None
        when ``Q_k = 0`` (nothing drawn): by default the symmetric root of :meth:`covariance` over its directions of
        positive variance (:func:`locbook._linalg.psd_root`); a model with a known factor (``Q = q G G^T``) gives it."""
        Q = np.asarray(self.covariance(step), dtype=float)
        return None if not np.any(Q) else psd_root(f"{self.label}: covariance at step {step}", Q)

    def mirrored_index(self) -> np.ndarray | None:
        """The state components whose sign a mirror reflection of the position reverses (velocity, acceleration),
        ``(k, dim)``: each row one derivative's components, aligned with the position components (the particle filter
        flips them when it folds a particle back into ``region_m``); an empty ``(0, dim)`` array folds the positions
        alone. None by default: the mirror image of the motion is not defined, and the particle filter refuses
        ``region_m`` with it."""
        return None

    def shifted(self, k: int) -> "MotionModel":
        """The model whose step is counted from ``k`` (the online filter's one-step calls see step 0): a view that adds
        ``k`` to the step of :meth:`apply`, :meth:`jacobian_at` and :meth:`covariance`."""
        return self if k == 0 else _ShiftedMotion(self, k)


class _ShiftedMotion(MotionModel):
    """:meth:`MotionModel.shifted`'s view: ``model`` with its steps counted from ``k``."""

    def __init__(self, model: MotionModel, k: int):
        self.model, self.k = model, int(k)
        self.name, self.linear, self.checks_own_output = model.label, model.linear, model.checks_own_output

    def apply(self, x, step: int = 0):
        return self.model.apply(x, step + self.k)

    def jacobian_at(self, x, step: int = 0):
        return self.model.jacobian_at(x, step + self.k)

    def covariance(self, step: int = 0):
        return self.model.covariance(step + self.k)

    def difference(self, a, b):
        return self.model.difference(a, b)

    def mean_of(self, points, weights):
        return self.model.mean_of(points, weights)

    @property
    def linear_differences(self) -> bool:
        return self.model.linear_differences

    def shifted(self, k: int) -> MotionModel:
        return self.model.shifted(self.k + k)


class LinearMotion(MotionModel):
    """``x_k = F_k x_{k-1} + w_k``, ``w_k ~ N(0, Q_k)``: ``F`` ``(n, n)``, with run axes ``batch + (n, n)`` or
    :func:`per_step`; ``Q`` likewise (checked: a covariance)."""

    linear = True
    checks_own_output = True

    def __init__(self, F, Q, *, name: str = "linear motion"):
        self.name = name
        Fv = F.value if isinstance(F, PerStep) else as_array(f"{name}: F", F)
        if Fv.ndim < 2 or Fv.shape[-1] != Fv.shape[-2]:
            raise ValueError(f"{name}: F must be square (n, n), batch + (n, n) or per_step(...), got {Fv.shape}")
        _covariance(f"{name}: Q", Q.value if isinstance(Q, PerStep) else Q, Fv.shape[-1])
        self.F, self.Q = F if isinstance(F, PerStep) else Fv, Q if isinstance(Q, PerStep) else np.asarray(Q, float)

    def _at(self, value, step: int):
        return value.at(step) if isinstance(value, PerStep) else value

    def apply(self, x, step: int = 0):
        F = self._at(self.F, step)
        return x @ F.T if F.ndim == 2 else np.einsum("...ij,...j->...i", F, x)

    def jacobian_at(self, x, step: int = 0):
        return self._at(self.F, step)

    def covariance(self, step: int = 0):
        return self._at(self.Q, step)
