"""Measurement streams of the Kalman family and the updates written once against the measurement-model protocol
(:mod:`locbook.models.base`).

A :class:`Stream` is readings plus their model: ``z`` ``batch + (T, m)`` (NaN = not heard), a
:class:`~locbook.models.base.MeasurementModel`, and the update ``mode``: ``"parallel"`` (one stacked update per step)
or ``"serial"`` (one scalar update per reading, each re-linearised at the state updated so far, in the ``order``
``"given"`` or ``"descending"`` reading; needs independent readings). :func:`LinearMeasurement`,
:func:`RssMeasurement` and :func:`NonlinearMeasurement` build the streams of the library's three models.

:func:`_ekf_update` is the one EKF update (the KF's too: a linear model is its own linearisation), from the model's
:meth:`~locbook.models.base.MeasurementModel.linearized` (parallel) or
:meth:`~locbook.models.base.MeasurementModel.innovation` row by row (serial); it returns the posterior with the NIS,
dof and Gaussian log-likelihood of the readings present, and on request their innovations and innovation covariance
(block diagonal over serial updates; :mod:`locbook.tracking.results`).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np

from .._linalg import _LOG_2PI, _UPDATE_OVERFLOW, _joseph, _Singular
from .._validate import as_array, check_choice
from ..models.base import FunctionMeasurement, LinearGaussian, MeasurementModel, PerStep
from ..models.channel import PathLossModel
from ..models.rss import RssModel
from .functional import _linear_update, _Out

__all__ = ["Stream", "LinearMeasurement", "RssMeasurement", "NonlinearMeasurement", "RSS_UPDATE_MODES",
           "SERIAL_ORDERS"]

RSS_UPDATE_MODES = ("parallel", "serial")
SERIAL_ORDERS = ("descending", "given")


@dataclass(frozen=True)
class Stream:
    """Readings ``z`` ``batch + (T, m)`` of one sensor and their :class:`~locbook.models.base.MeasurementModel`
    (module docstring). ``z``: NaN (or a masked entry of a numpy masked array, pykalman's convention) = a missing
    reading, left out of the update; a step without any reading is prediction only. ``mode``: ``"parallel"`` or
    ``"serial"``; ``order``: the serial updates' order, ``"given"`` or ``"descending"`` reading (strongest first,
    missing last; Dogan 2015, Table 3.3). The model's attributes are readable on the stream (``stream.H``)."""

    z: np.ndarray
    model: MeasurementModel
    mode: str = "parallel"
    order: str = "given"

    def __post_init__(self):
        model = self.model
        if not isinstance(model, MeasurementModel):
            raise ValueError(f"a Stream's model must be a MeasurementModel (locbook.models.base), got "
                             f"{type(model).__name__}")
        check_choice("mode", self.mode, RSS_UPDATE_MODES)
        check_choice("order", self.order, SERIAL_ORDERS)
        object.__setattr__(self, "z", as_array(f"{model.label}.z", self.z, min_ndim=2, nan_ok=True))
        if self.mode == "serial" and not model.independent_readings():
            raise ValueError(f"{model.label}: serial updates need independent readings (a diagonal R); use "
                             "mode='parallel'")

    def __getattr__(self, name):
        if name.startswith("__") or name in ("z", "model", "mode", "order"):
            raise AttributeError(name)
        try:
            return getattr(object.__getattribute__(self, "model"), name)
        except AttributeError:
            raise AttributeError(f"{type(self).__name__} (model {type(self.model).__name__}) has no attribute "
                                 f"{name!r}") from None

    @property
    def name(self) -> str:
        return self.model.label

    @property
    def rss_dbm(self) -> np.ndarray:
        """The readings (the name of an RSS stream's)."""
        return self.z

    def replace(self, *, z=None, model=None, mode=None, order=None) -> "Stream":
        """The stream with the given fields changed (checked again; only a new model alone is taken as given: a
        filter's derived model, e.g. a noise fit's candidate, must not re-read every reading)."""
        if z is None and mode is None and order is None and model is not None:
            out = object.__new__(Stream)
            for name, value in (("z", self.z), ("model", model), ("mode", self.mode), ("order", self.order)):
                object.__setattr__(out, name, value)
            return out
        return Stream(self.z if z is None else z, self.model if model is None else model,
                      mode or self.mode, order or self.order)

    def __repr__(self) -> str:
        return f"Stream(z of shape {self.z.shape}, {type(self.model).__name__} {self.name!r}, mode={self.mode!r})"

    # readings are arrays: a stream is not hashable (mypy types object's __hash__ as a method, never None)
    __hash__ = None  # type: ignore[assignment]


def LinearMeasurement(z, H, R, mode: str = "parallel", offset=None) -> Stream:
    """A linear-Gaussian stream ``z_k = H_k x_k + d_k + v_k``, ``v_k ~ N(0, R_k)``
    (:class:`~locbook.models.base.LinearGaussian`).

    ``z``: ``batch + (T, m)``; a NaN entry is a missing component (that row is left out of the update, the others are
    used), so streams at different rates share one time grid; filterpy's column readings ``(T, m, 1)`` are refused
    with the shape to pass. ``H``: ``(m, n)``, with run axes ``batch + (m, n)``, or one per step ``per_step(batch +
    (T, m, n))``. ``R``: ``(m, m)``, ``batch + (m, m)`` or ``per_step(batch + (T, m, m))``. ``offset``: the
    measurement offset ``d`` (pykalman's observation offset), ``(m,)`` or per step like ``z``. ``mode``:
    ``"parallel"`` (one stacked update) or ``"serial"`` (one scalar update per row in the given order; needs a
    diagonal R, and then equals the parallel update to round-off)."""
    zz = as_array("LinearMeasurement.z", z, min_ndim=2, nan_ok=True)
    shape_H = (H.value if hasattr(H, "value") else as_array("LinearMeasurement.H", H)).shape
    if len(shape_H) >= 2 and zz.shape[-1] != shape_H[-2]:       # z against H first: R is checked against H
        LinearGaussian(np.zeros(shape_H[-2:]), np.eye(shape_H[-2]), name="LinearMeasurement").check_readings(
            zz, shape_H[-1])
    model = LinearGaussian(H, R, offset, name="LinearMeasurement")
    model.check_readings(zz, model.n_state)
    if mode == "serial" and not model.independent_readings():
        raise ValueError("serial linear updates need a diagonal R (independent measurement components)")
    return Stream(zz, model, mode=mode)


def RssMeasurement(rss_dbm, model=None, channel: PathLossModel | None = None, position_index=None,
                   mode: str = "parallel", order: str = "descending", anchor_sigma_m: float = 0.0,
                   tag_height_m: float | None = None, *, anchors_m=None) -> Stream:
    """Received powers for the EKF and the UKF (Dogan 2015, Ch. 3): ``rss_dbm`` ``batch + (T, m)``, NaN where an
    anchor gave no reading, read through ``model``, an :class:`~locbook.models.rss.RssModel` with its
    ``position_index`` (the state's position components). ``mode``: ``"parallel"`` (one stacked update, Table 3.4)
    or ``"serial"`` (scalar updates, each re-linearised at the state updated so far, Table 3.3, in ``order``
    ``"descending"`` RSS as printed or the ``"given"`` anchor order; loop bound j <= N, the print's "for each j < N"
    would skip the last anchor; corrected).

    The model's fields may be given in its place: ``RssMeasurement(rss_dbm, anchors_m, channel, position_index,
    anchor_sigma_m=..., tag_height_m=...)``; there, anchors ``batch + (T, m, dim)`` are per step (the form's old
    reading: a DeprecationWarning asks for ``per_step(anchors_m)``, which means the same). Channel parameters with
    leading axes are per run (``batch + (1 or m,)``) in both forms."""
    check_choice("mode", mode, RSS_UPDATE_MODES)
    check_choice("order", order, SERIAL_ORDERS)
    if isinstance(model, RssModel):
        if channel is not None or anchor_sigma_m != 0.0 or tag_height_m is not None:
            raise ValueError("RssMeasurement(rss_dbm, model): the channel, anchor_sigma_m and tag_height_m are the "
                             "RssModel's own fields; give them there")
        if position_index is not None:
            model = replace(model, position_index=position_index)
    else:
        if anchors_m is not None and model is not None:
            raise ValueError("RssMeasurement: give the model (an RssModel) or anchors_m=, not both")
        anchors_m = model if anchors_m is None else anchors_m
        if isinstance(anchors_m, PathLossModel) or anchors_m is None or channel is None or position_index is None:
            got = "nothing" if anchors_m is None else type(anchors_m).__name__
            raise ValueError(f"RssMeasurement takes (rss_dbm, model) with model an RssModel (with position_index), or "
                             f"(rss_dbm, anchors_m, channel, position_index); got {got} as the model"
                             + ("" if isinstance(anchors_m, PathLossModel) or anchors_m is None else
                                f" without {'channel' if channel is None else 'position_index'}"))
        if not isinstance(anchors_m, PerStep) and np.ndim(anchors_m) > 2:
            warnings.warn("RssMeasurement: anchors_m with more than two axes are per step; mark them "
                          "per_step(anchors_m) (unmarked leading axes are run axes in RssModel)", DeprecationWarning,
                          stacklevel=2)
            anchors_m = PerStep(anchors_m, "RssMeasurement.anchors_m")
        model = RssModel(anchors_m, channel, position_index=position_index, anchor_sigma_m=anchor_sigma_m,
                         tag_height_m=tag_height_m, name="RssMeasurement")
    if model.position_index is None:
        raise ValueError(f"{model.name}: a Kalman-family stream reads the state's position components: give "
                         f"position_index (RssModel(..., position_index=...))")
    z = as_array(f"{model.name}.rss_dbm", rss_dbm, min_ndim=2, nan_ok=True)
    # the stream's own shapes (the filter checks n)
    model.check_readings(z, int(np.max(model.state_position_index)) + 1)
    return Stream(z, model, mode=mode, order=order)


def NonlinearMeasurement(z, h, R, jacobian=None, name: str = "nonlinear measurement", residual=None,
                         mean=None) -> Stream:
    """A stream ``z_k = h(x_k) + v_k``, ``v_k ~ N(0, R)`` given by functions
    (:class:`~locbook.models.base.FunctionMeasurement`: ``h``, its ``jacobian`` for the EKF, ``R`` fixed or a function
    of the state, ``residual`` and ``mean`` for readings on a circle). ``z``: ``batch + (T, m)``, NaN = missing."""
    zz = as_array(f"{name}: z", z, min_ndim=2, nan_ok=True)
    R_shape: tuple[int, ...] = () if callable(R) else np.shape(R)
    if zz.shape[-1] == 1 and zz.ndim >= 3 and len(R_shape) >= 2 and R_shape[-1] == R_shape[-2] == zz.shape[-2] != 1:
        raise ValueError(f"{name}: z has shape {zz.shape}, a column of {R_shape[-1]} readings per step "
                         f"(filterpy's (m, 1) z); pass batch + (T, m), e.g. z[..., 0] of shape {zz.shape[:-1]}")
    model = FunctionMeasurement(h, R, jacobian, m=zz.shape[-1], name=name, residual=residual, mean=mean)
    model.check_readings(zz, 0)
    return Stream(zz, model)


# -- the one EKF update ----------------------------------------------------------------------------------------


def _serial_order(z, order: str):
    """Reading order of serial updates per run ``batch + (m,)`` (strongest first, missing last), or None for the
    given order."""
    if order == "descending":
        return np.argsort(-np.where(np.isfinite(z), z, -np.inf), axis=-1, kind="stable")
    return None


def _row(values, a, axis: int):
    """Row ``a`` (an int, or per run ``batch`` indices) of ``values`` on ``axis`` (-1 for readings, -2 for a
    Jacobian's rows), the axis dropped; ``values`` without the runs' axes (one H for all runs) are broadcast to them."""
    if isinstance(a, (int, np.integer)):
        return np.take(values, a, axis=axis)
    values = np.asarray(values)
    lead = values.ndim + axis                      # the axes before the row axis
    batch = np.broadcast_shapes(values.shape[:lead], np.shape(a))
    values = np.broadcast_to(values, batch + values.shape[lead:])
    idx = np.asarray(a)[(...,) + (None,) * (-axis)]
    idx = np.broadcast_to(idx, batch + (1,) + values.shape[len(batch) + 1:])
    return np.take_along_axis(values, idx, len(batch)).squeeze(len(batch))


def _diagonal_entry(R, a):
    """``R[..., a, a]`` for ``a`` an int or per-run indices ``batch``."""
    R = np.asarray(R, dtype=float)
    if isinstance(a, (int, np.integer)):
        return R[..., a, a]
    d = np.diagonal(R, axis1=-2, axis2=-1)
    d = np.broadcast_to(d, np.broadcast_shapes(d.shape[:-1], a.shape) + d.shape[-1:])
    return np.take_along_axis(d, a[..., None], -1)[..., 0]


class _Serial:
    """Accumulates the scalar updates of one serial stream: NIS and log-likelihood summed (the innovations of one
    step's sequential updates are independent under the model), and on request each reading's innovation and variance
    in its own column (``column`` ``batch``: the reading each run updates with), S diagonal."""

    def __init__(self, batch, m, want: bool):
        self.nis, self.ll = np.zeros(batch), np.zeros(batch)
        self.nu = np.full(batch + (m,), np.nan) if want else None
        self.var = np.full(batch + (m,), np.nan) if want else None

    def add(self, nu, s, valid, column, nis=None, ll=None):
        """One scalar update per run: innovation ``nu``, variance ``s``, the reading's ``column`` ``batch``
        (``valid``: the reading is present); ``nis``/``ll``: the update's own, else from ``nu`` and ``s``."""
        if nis is None:
            safe = np.where(valid, s, 1.0)
            nis = np.where(valid, nu * nu / safe, 0.0)
            ll = np.where(valid, -0.5 * (nis + np.log(safe) + _LOG_2PI), 0.0)
        self.nis = self.nis + nis
        self.ll = self.ll + ll
        if self.nu is not None:
            col = np.broadcast_to(column, valid.shape)[..., None]
            np.put_along_axis(self.nu, col, np.broadcast_to(np.where(valid, nu, np.nan), valid.shape)[..., None], -1)
            np.put_along_axis(self.var, col, np.broadcast_to(np.where(valid, s, np.nan), valid.shape)[..., None], -1)

    def out(self, x, P, dof) -> _Out:
        if self.nu is None:
            return _Out(x, P, self.nis, dof, self.ll)
        assert self.var is not None     # made together with nu
        m = self.nu.shape[-1]
        S = np.where(np.eye(m, dtype=bool), self.var[..., :, None], 0.0)
        S = np.where(np.isnan(self.var)[..., :, None] | np.isnan(self.var)[..., None, :], np.nan, S)
        return _Out(x, P, self.nis, dof, self.ll, self.nu, S)


def _serial_row(model: MeasurementModel, x, z, a, step: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """The linearisation of reading ``a`` (an int, or per run ``batch``) at the state so far ``x``: ``(present,
    innovation (NaN where missing), the Jacobian's row batch + (n,), the reading's variance)``, or None when no run
    has that reading (one serial update of :func:`_serial_ekf_update` and the square-root form)."""
    valid = np.isfinite(_row(z, a, -1))
    if not valid.any():
        return None
    nu_all, H, R = model.innovation(x, z, step=step)
    return valid, _row(nu_all, a, -1), np.broadcast_to(_row(H, a, -2), x.shape), _diagonal_entry(R, a)


def _serial_ekf_update(x, P, z, stream: Stream, step: int, want: bool, joseph: bool) -> _Out:
    """Scalar updates, one per reading in the stream's order, each re-linearised at the state updated so far (Dogan
    2015, Table 3.3; for a linear model the exact sequential form of the parallel update)."""
    model = stream.model
    m = z.shape[-1]
    order = _serial_order(z, stream.order)
    # the scalar innovations of one step are independent under the model (each is conditioned on the previous
    # updates), so their NIS add up to a chi-square with one dof per reading (to first order when h is linearised)
    acc, dof = _Serial(x.shape[:-1], m, want), np.isfinite(z).sum(axis=-1)
    for j in range(m):
        a = j if order is None else order[..., j]
        row = _serial_row(model, x, z, a, step)
        if row is None:
            continue
        valid, nu, h_row, var = row
        nu = np.where(valid, nu, 0.0)
        ph = (P @ h_row[..., None])[..., 0]                   # P H^T
        s = np.einsum("...i,...i->...", h_row, ph) + var
        if (valid & ~(s > 0)).any():
            raise _Singular(valid & ~(s > 0))
        K = np.where(valid[..., None], ph / s[..., None], 0.0)
        acc.add(nu, s, valid, a)
        x = x + K * nu[..., None]
        over = ~np.all(np.isfinite(x), axis=-1)
        if over.any():              # named here: the next reading's linearisation would only see NaN
            raise _Singular(over, _UPDATE_OVERFLOW)
        if joseph:
            P = _joseph(P, K[..., :, None], h_row[..., None, :], np.asarray(var)[..., None, None])
        else:
            short = P - K[..., :, None] * ph[..., None, :]
            P = 0.5 * (short + np.swapaxes(short, -1, -2))
    return acc.out(x, P, dof)


def _ekf_update(x, P, z, stream: Stream, step, want: bool = False, joseph: bool = True) -> _Out:
    """One stream's update of the EKF (and the KF): the linear update on the model's linearisation at the state so far
    (exact for a linear model), or its serial form."""
    if stream.mode == "serial":
        return _serial_ekf_update(x, P, z, stream, step, want, joseph)
    z_lin, H, R = stream.model.linearized(x, z, step=step)
    return _linear_update(x, P, z_lin, H, R, joseph=joseph, want=want)
