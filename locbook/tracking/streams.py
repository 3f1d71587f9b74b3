"""Measurement streams of the Kalman family and their updates: :class:`LinearMeasurement` (the KF's, also used by
the EKF and UKF), :class:`RssMeasurement` (parallel and serial RSS EKF, Dogan 2015, Ch. 3) and
:class:`NonlinearMeasurement` (an EKF/UKF stream given by its function h).

Each ``*_update`` applies one stream's readings of one step to a batched state (``_ekf_update`` dispatches on the
stream) and returns the posterior with the NIS, dof and Gaussian log-likelihood of the readings present, and on request
their innovations and innovation covariance (block diagonal over serial updates; :mod:`locbook.tracking.results`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_array, call_user, check_choice, check_scalar, function_output
from ..models.channel import PathLossModel
from ..models.rss import rss_mean_jacobian
from ._linalg import (_LOG_2PI, _STATE_NOT_FINITE, _UPDATE_OVERFLOW, _Singular, _covariance, _joseph,
                      _refuse_not_finite)
from .functional import _linear_update, _Out
from .transition import PerStep

__all__ = ["LinearMeasurement", "RssMeasurement", "NonlinearMeasurement", "MEASUREMENT_TYPES",
           "RSS_UPDATE_MODES", "SERIAL_ORDERS"]

RSS_UPDATE_MODES = ("parallel", "serial")
_ON_ANCHOR = ("the state is on an anchor at step {step} and the channel has no near-field clamp (min_distance_m = 0), "
              "where the log-distance mean is infinite: give the channel a min_distance_m (e.g. 1e-3 m)")
SERIAL_ORDERS = ("descending", "given")


def _readings(stream, field: str, name: str) -> np.ndarray:
    """A stream's readings ``batch + (T, m)`` as checked floats, kept on the (frozen) stream in place of what was given,
    so a masked reading is NaN (not heard) wherever the filters read them (a masked array's data is never used)."""
    z = as_array(name, getattr(stream, field), min_ndim=2, nan_ok=True)
    object.__setattr__(stream, field, z)
    return z


@dataclass(frozen=True)
class LinearMeasurement:
    """A linear-Gaussian measurement stream ``z_k = H_k x_k + d_k + v_k``, ``v_k ~ N(0, R_k)``.

    ``z``: ``batch + (T, m)``; a NaN entry is a missing component (that row is left out of the
    update, the others are used), so streams at different rates share one time grid. A masked entry of a numpy masked
    array is missing too (pykalman's convention); filterpy's column readings ``(T, m, 1)`` are refused with the shape
    to pass (as are ``(T, 1, 1)`` readings in a call without run axes elsewhere: T runs or T steps?).
    ``H``: ``(m, n)``, with run axes ``batch + (m, n)``, or one per step ``per_step(batch + (T, m, n))``
    (:func:`locbook.per_step`). ``R``: ``(m, m)``, ``batch + (m, m)`` or ``per_step(batch + (T, m, m))``.
    ``offset``: the measurement offset ``d`` (pykalman's observation offset), ``(m,)`` or per step like ``z``
    (``batch + (T, m)``); the filters update with ``z - d``.
    ``mode``: ``"parallel"`` (one stacked update) or ``"serial"`` (one scalar update per row in the given order;
    needs a diagonal R, and then equals the parallel update exactly; Dogan 2015's serial and parallel RSS EKFs,
    Tables 3.3-3.4, differ only by the re-linearisation between scalar updates).
    """

    z: np.ndarray
    H: np.ndarray
    R: np.ndarray
    mode: str = "parallel"
    offset: np.ndarray | None = None

    def __post_init__(self):
        check_choice("mode", self.mode, RSS_UPDATE_MODES)
        z = _readings(self, "z", "LinearMeasurement.z")
        T, m = z.shape[-2:]
        H = self.H.value if isinstance(self.H, PerStep) else as_array("LinearMeasurement.H", self.H)
        if H.ndim >= 2 and m == 1 and z.ndim >= 3 and z.shape[-2] == H.shape[-2] != 1:
            raise ValueError(f"LinearMeasurement.z has shape {z.shape}, a column of {H.shape[-2]} readings per step "
                             f"(filterpy's (m, 1) z); pass batch + (T, m), e.g. z[..., 0] of shape {z.shape[:-1]}")
        if H.ndim < 2 or H.shape[-2] != m:
            raise ValueError(f"LinearMeasurement.H must have {m} rows (one per component of z), got shape {H.shape}")
        R = _covariance("LinearMeasurement.R", self.R.value if isinstance(self.R, PerStep) else self.R, m)
        for name, value in (("H", self.H), ("R", self.R)):
            if isinstance(value, PerStep) and value.value.shape[-3] not in (1, T):
                raise ValueError(f"LinearMeasurement.{name} per step must have {T} steps on axis -3 (one per "
                                 f"reading step), got shape {value.value.shape}")
        if self.mode == "serial" and np.any(R - R * np.eye(R.shape[-1])):
            raise ValueError("serial linear updates need a diagonal R (independent measurement components)")
        if self.offset is not None:
            d = as_array("LinearMeasurement.offset", self.offset, min_ndim=1)
            if d.shape[-1] != m or d.ndim > 1 and d.shape[-2] not in (1, T):
                raise ValueError(f"LinearMeasurement.offset must have shape ({m},) or batch + ({T}, {m}) like z, got "
                                 f"{d.shape}")


@dataclass(frozen=True)
class RssMeasurement:
    """Received powers from fixed anchors, ``z_kj = h_j(p_k) + e_kj``, ``e ~ N(0, sigma_db^2)`` i.i.d., for the EKF
    and the UKF: ``h`` and its Jacobian are the one RSS model's (:class:`locbook.models.rss.RssModel`, evaluated by
    :func:`locbook.models.rss.rss_mean_jacobian`; Dogan Eq. (2.2)) with the near-field clamp :attr:`clamp_m`.

    ``rss_dbm``: ``batch + (T, m)``, NaN where an anchor gave no reading (a step without any reading is
    prediction only). ``channel``: its ``ref_power_dbm``, ``path_loss_exp`` and ``sigma_db`` may be scalars,
    per-anchor ``(m,)`` arrays, or carry batch axes ``batch + (1,)`` (several settings run as one batch).
    ``mode``: ``"parallel"`` (one stacked update, Table 3.4) or ``"serial"`` (scalar updates, each
    re-linearised at the state updated so far, Table 3.3, in ``order`` ``"descending"`` RSS as printed or
    the ``"given"`` anchor order). The near-field clamp is the channel's ``min_distance_m`` (:attr:`clamp_m`; within
    it the mean is flat and its Jacobian 0), so the stream and :class:`~locbook.models.rss.RssModel` are one model.
    A channel without a clamp (``min_distance_m = 0``) has an infinite mean on an anchor: a state (or sigma point)
    exactly on one raises :class:`~locbook.errors.SingularCovarianceError` naming the step; give the channel a clamp
    (e.g. 1 mm) where the track can pass over an anchor.

    ``anchors_m``: fixed anchors ``(m, dim)``, or receiver positions per step ``batch + (T, m, dim)`` (a moving
    receiver, or measurement locations drawn per Monte-Carlo run: Palvai 2008, Eq. (4.28)). ``anchor_sigma_m``:
    the anchors' positions are known only to this standard deviation (e.g. GPS, Palvai's sigma_3); the
    measurement variance is then inflated to ``sigma^2 + anchor_sigma^2 |dh/dp|^2``, i.e.
    ``sigma^2 + (10 n / ln 10)^2 anchor_sigma^2 / d^2`` (0 added within the clamp), at the linearisation point
    (first-order propagation of the position error; an extension: Palvai 2008, Sec. 4.4, does not say how sigma_3
    enters the EKF).

    ``tag_height_m``: the anchors are ``(m, 3)`` (x, y, height), the tag moves in the plane ``z = tag_height_m``
    and ``position_index`` names the state's x and y only; the distances are 3-D.
    """

    rss_dbm: np.ndarray
    anchors_m: np.ndarray
    channel: PathLossModel
    position_index: np.ndarray
    mode: str = "parallel"
    order: str = "descending"
    anchor_sigma_m: float = 0.0
    tag_height_m: float | None = None

    def lift(self, positions_m):
        """Positions ``(..., k)`` from the state, with the known tag height appended when there is one."""
        if self.tag_height_m is None:
            return positions_m
        return np.concatenate([positions_m, np.full(positions_m.shape[:-1] + (1,), float(self.tag_height_m))], -1)

    def anchors_at(self, step: int) -> np.ndarray:
        """Anchor positions at ``step``: ``(m, dim)`` or ``batch + (m, dim)``."""
        a = np.asarray(self.anchors_m, dtype=float)
        return a if a.ndim == 2 else a[..., min(step, a.shape[-3] - 1), :, :]

    @property
    def clamp_m(self) -> float:
        """The model's near-field clamp: the channel's ``min_distance_m``."""
        return float(self.channel.min_distance_m)

    def variance_db2(self, distance_m, path_loss_exp, sigma_db):
        """Measurement variance per reading: ``sigma^2``, inflated for ``anchor_sigma_m`` (class docstring) by
        ``anchor_sigma^2 |dh/dp|^2``, ``|dh/dp| = 10 n / (d ln 10)`` outside the clamp and 0 inside."""
        var = np.asarray(sigma_db, dtype=float) ** 2
        if self.anchor_sigma_m > 0:
            slope = 10.0 * np.asarray(path_loss_exp, dtype=float) / np.log(10.0)
            clamp = self.clamp_m
            inflation = (slope * self.anchor_sigma_m / np.maximum(distance_m, clamp)) ** 2
            var = var + np.where(np.asarray(distance_m) < clamp, 0.0, inflation)
        return var

    def __post_init__(self):
        check_choice("mode", self.mode, RSS_UPDATE_MODES)
        check_choice("order", self.order, SERIAL_ORDERS)
        power = _readings(self, "rss_dbm", "RssMeasurement.rss_dbm")
        anchors = as_array("RssMeasurement.anchors_m", self.anchors_m, min_ndim=2)
        m, dim = anchors.shape[-2], anchors.shape[-1]
        if power.shape[-1] != m:
            raise ValueError(f"RssMeasurement.rss_dbm has {power.shape[-1]} anchors on its last axis, "
                             f"anchors_m has {m}")
        if anchors.ndim > 2 and anchors.shape[-3] not in (1, power.shape[-2]):
            raise ValueError(f"RssMeasurement.anchors_m per step must have shape batch + (T, m, dim) with T = "
                             f"{power.shape[-2]} steps (or 1), got {anchors.shape}")
        idx = np.asarray(self.position_index)
        if self.tag_height_m is not None:
            check_scalar("tag_height_m", self.tag_height_m)
            if dim != 3:
                raise ValueError(f"RssMeasurement with tag_height_m needs anchors (m, 3) (x, y, height), got {anchors.shape}")
        n_free = dim - (self.tag_height_m is not None)
        if idx.shape != (n_free,):
            raise ValueError(f"RssMeasurement.position_index must hold {n_free} state indices (one per "
                             f"axis of the anchors{', the height known' if n_free < dim else ''}), got "
                             f"{self.position_index!r}")
        check_scalar("anchor_sigma_m", self.anchor_sigma_m, ge=0)
        for name in ("ref_power_dbm", "path_loss_exp", "sigma_db"):
            value = as_array(f"RssMeasurement.channel.{name}", getattr(self.channel, name))
            if value.ndim and value.shape[-1] not in (1, m):
                raise ValueError(f"RssMeasurement.channel.{name} must be a scalar or end in (1,) or ({m},) "
                                 f"(one per anchor), got shape {value.shape}")


@dataclass(frozen=True)
class NonlinearMeasurement:
    """A nonlinear measurement stream ``z_k = h(x_k) + v_k``, ``v_k ~ N(0, R)`` (e.g. a body-frame accelerometer,
    whose reading depends on the heading state; Gudipati 2017, Eqs. (3.9), (3.11); or a bearing and range).

    ``z``: ``batch + (T, m)``, NaN = a missing component (left out of the update). ``h``: maps states
    ``(..., n)`` to ``(..., m)`` over any leading axes: the EKF calls it with ``batch + (n,)``, the UKF with the
    sigma points ``batch + (N, n)``. ``jacobian``: states ``(..., n)`` to ``(..., m, n)``; the EKF needs it,
    the UKF does not. ``R``: ``(m, m)`` or ``batch + (m, m)``, or a function of the state ``x`` ``batch + (n,)``
    returning them (a noise that depends on the state, e.g. on the range; evaluated where the update linearises: the
    EKF's state so far, the UKF's predicted mean). ``name`` names the stream in error messages.

    For readings on a circle (a bearing): ``residual(a, b)`` is the difference ``a - b`` of readings ``(..., m)``
    (e.g. wrapped to ``(-pi, pi]``), used for the innovation and, in the UKF, wherever readings are subtracted;
    ``mean(values, weights)`` the UKF's weighted mean of predicted readings ``(..., N, m)`` (e.g. a circular mean of
    the angle components). Both default to the linear forms.

    The filters check what these functions return (issue 44): real numbers (complex values are refused, never cut to
    their real part) of the shape the stream needs, finite wherever a reading is present (NaN in ``z`` marks a missing
    reading; a NaN from ``h`` is not one). Anything else is a ValueError of one line naming the stream's function
    (``"<name>: h returned shape ..."``, ``"... returned NaN at step k"``); an exception raised inside a function
    reaches the caller unchanged.
    """

    z: np.ndarray
    h: object
    R: np.ndarray
    jacobian: object = None
    name: str = "nonlinear measurement"
    residual: object = None
    mean: object = None

    def __post_init__(self):
        z = _readings(self, "z", f"{self.name}: z")
        if not callable(self.h):
            raise ValueError(f"{self.name}: h must be a function of the state, got {type(self.h).__name__}")
        for field in ("jacobian", "residual", "mean"):
            value = getattr(self, field)
            if value is not None and not callable(value):
                raise ValueError(f"{self.name}: {field} must be a function or None, got {type(value).__name__}")
        if isinstance(self.R, PerStep):
            raise ValueError(f"{self.name}: a NonlinearMeasurement's R is one covariance or a function of the state "
                             "(per_step R is for a LinearMeasurement)")
        if not callable(self.R):
            R = np.shape(self.R)
            if z.shape[-1] == 1 and z.ndim >= 3 and len(R) >= 2 and R[-1] == R[-2] == z.shape[-2] != 1:
                raise ValueError(f"{self.name}: z has shape {z.shape}, a column of {R[-1]} readings per step "
                                 f"(filterpy's (m, 1) z); pass batch + (T, m), e.g. z[..., 0] of shape {z.shape[:-1]}")
            _covariance(f"{self.name}: R", self.R, z.shape[-1])

    def _call(self, field: str, *args):
        """The stream's function ``field`` called with ``args``; one whose signature does not take them (filterpy's
        ``h(x, *hx_args)``) is a one-line error saying what to pass; a TypeError raised inside a function that takes
        them reaches the caller unchanged."""
        form = {"h": "h(x)", "jacobian": "jacobian(x)", "residual": "residual(a, b)",
                "mean": "mean(values, weights)"}[field]
        hint = {"h": "bind its other arguments: write lambda x: h(x, arg)",
                "jacobian": "bind its other arguments: write jacobian=lambda x: H(x, arg)"}.get(
                    field, f"give a function called as {form}")
        return call_user(getattr(self, field), args,
                         lambda exc: f"{self.name}: {field} cannot be called as {form}: {exc}; {hint}")

    def noise_at(self, x) -> np.ndarray:
        """R at the state ``x`` ``batch + (n,)``: the fixed R, or the callback's (checked: a covariance)."""
        if not callable(self.R):
            return np.asarray(self.R, dtype=float)
        m = np.shape(self.z)[-1]
        R = _covariance(f"{self.name}: R(x)", self.R(x), m)
        try:
            np.broadcast_shapes(R.shape[:-2], np.shape(x)[:-1])
        except ValueError:
            raise ValueError(f"{self.name}: R(x) returned shape {R.shape}, which does not broadcast to the runs' "
                             f"{np.shape(x)[:-1] + (m, m)}") from None
        return R

    def difference(self, a, b):
        """``a - b`` of readings, through ``residual`` when given."""
        return np.asarray(self._call("residual", a, b), dtype=float) if self.residual is not None else a - b

    # The filters call h, jacobian, residual and mean through these: each output is checked (real, of the shape the
    # stream needs, finite wherever a reading is present), so a function that fails is an error naming it and the
    # step, never a reading taken as missing (the EKF's linearised reading would be NaN) or an overflow.
    def readings_at(self, x, present, step: int, batch_ndim: int) -> np.ndarray:
        """``h(x)`` ``x.shape[:-1] + (m,)`` (``x``: states or sigma points), checked; ``present`` broadcasts to it."""
        m = np.shape(self.z)[-1]
        out = function_output(f"{self.name}: h", self._call("h", x), np.shape(x)[:-1] + (m,), 1, np.shape(x))
        _refuse_not_finite(f"{self.name}: h", out, present & ~np.isfinite(out), batch_ndim, step, _PRESENT)
        return out

    def jacobian_at(self, x, present, step: int) -> np.ndarray:
        """The EKF's ``dh/dx`` ``batch + (m, n)`` at ``x`` ``batch + (n,)``, checked (rows of present readings
        finite)."""
        if self.jacobian is None:
            raise ValueError(f"{self.name}: the EKF needs its jacobian (the UKF does not)")
        m, n = np.shape(self.z)[-1], np.shape(x)[-1]
        H = function_output(f"{self.name}: jacobian", self._call("jacobian", x), np.shape(x)[:-1] + (m, n), 2, np.shape(x))
        _refuse_not_finite(f"{self.name}: jacobian", H, present[..., :, None] & ~np.isfinite(H), np.ndim(x) - 1, step,
                           _PRESENT)
        return H

    def residual_of(self, a, b, present, step: int, batch_ndim: int) -> np.ndarray:
        """``a - b`` of readings (``residual`` when given), checked: the broadcast shape, finite where ``present``."""
        if self.residual is None:
            return a - b
        shape = np.broadcast_shapes(np.shape(a), np.shape(b))
        out = function_output(f"{self.name}: residual", self._call("residual", a, b), shape, 1, shape)
        _refuse_not_finite(f"{self.name}: residual", out, present & ~np.isfinite(out), batch_ndim, step, _PRESENT)
        return out

    def mean_of(self, values, weights, present, step: int, batch_ndim: int) -> np.ndarray:
        """The UKF's weighted mean of predicted readings ``(..., N, m)`` (``mean`` when given, else the linear one),
        checked: ``(..., m)``, finite where ``present``."""
        if self.mean is None:
            return weights @ values
        out = function_output(f"{self.name}: mean", self._call("mean", values, weights), np.shape(values)[:-2] +
                              np.shape(values)[-1:], 1, np.shape(values))
        _refuse_not_finite(f"{self.name}: mean", out, present & ~np.isfinite(out), batch_ndim, step, _PRESENT)
        return out


_PRESENT = ("for a reading that is present: it must be finite wherever z has a reading (a missing reading is a NaN "
            "in z, not in the function's output)")


MEASUREMENT_TYPES = (LinearMeasurement, RssMeasurement, NonlinearMeasurement)


def _rss_mean_jacobian(meas: RssMeasurement, offset_m, ref_power_dbm, path_loss_exp, batch_ndim: int | None = None):
    """The stream's model at offsets ``p - a_j`` (with the height column when the tag height is known): mean, Jacobian,
    distances (not clamped). Without a clamp, a state on an anchor has no finite mean: a named error (the runs
    ``batch_ndim`` leading axes; the rest are reduced)."""
    mean, grad, d2 = rss_mean_jacobian(offset_m, ref_power_dbm, path_loss_exp, ref_distance_m=meas.channel.ref_distance_m,
                                       min_distance_m=meas.clamp_m)
    _refuse_on_anchor(meas, d2, batch_ndim)
    return mean, grad, np.sqrt(d2)


def _refuse_on_anchor(meas: RssMeasurement, d2, batch_ndim: int | None) -> None:
    """Without a clamp the mean is infinite on an anchor: a named error for the runs (``batch_ndim`` leading axes of
    the squared distances ``d2``; the rest are reduced) whose point lies on one."""
    if meas.clamp_m == 0 and not np.all(d2 != 0):
        on = d2 == 0
        if batch_ndim is not None:
            on = on.reshape(on.shape[:batch_ndim] + (-1,)).any(axis=-1)
        raise _Singular(on, _ON_ANCHOR)


def _rss_parallel_update(x, P, z, meas: RssMeasurement, step: int = 0, want: bool = False) -> _Out:
    """Table 3.4: one update with the stacked Jacobian at the predicted state, R = sigma^2 I (inflated for
    uncertain anchor positions, :class:`RssMeasurement`)."""
    idx = np.asarray(meas.position_index)
    ch = meas.channel
    offset = meas.lift(x[..., idx])[..., None, :] - meas.anchors_at(step)
    h, grad, d = _rss_mean_jacobian(meas, offset, np.asarray(ch.ref_power_dbm), np.asarray(ch.path_loss_exp),
                                    x.ndim - 1)
    m = z.shape[-1]
    H = np.zeros(grad.shape[:-1] + (x.shape[-1],))
    H[..., idx] = grad[..., :idx.size]
    far = ~np.all(np.isfinite(d), axis=-1)
    if far.any():                   # the state ran away (an overflow, e.g. after a reading of 1e300 dBm)
        raise _Singular(far, _STATE_NOT_FINITE)
    sigma2 = np.broadcast_to(meas.variance_db2(d, ch.path_loss_exp, ch.sigma_db), z.shape)
    R = sigma2[..., :, None] * np.eye(m)
    valid = np.isfinite(z)
    # the linear update on the innovation's linearisation: z - h(x) = H (x_true - x) + e; its innovation is z - h(x)
    return _linear_update(x, P, np.where(valid, z - h + (H @ x[..., None])[..., 0], np.nan), H, R, want=want)


def _serial_order(z, order: str):
    """Anchor order of serial updates per run ``batch + (m,)``: strongest reading first (missing last) or as given."""
    if order == "descending":
        return np.argsort(-np.where(np.isfinite(z), z, -np.inf), axis=-1, kind="stable")
    return np.broadcast_to(np.arange(z.shape[-1]), z.shape)


def _pick_anchor(anchors, a):
    """The anchor ``a`` (batch indices) of fixed ``(m, dim)`` or per-run ``batch + (m, dim)`` anchors."""
    if anchors.ndim == 2:
        return anchors[a]
    anchors = np.broadcast_to(anchors, a.shape + anchors.shape[-2:])
    return np.take_along_axis(anchors, a[..., None, None], -2)[..., 0, :]


class _Serial:
    """Accumulates the scalar updates of one serial stream: NIS and log-likelihood summed (the innovations of one
    step's sequential updates are independent under the model), and on request each reading's innovation and variance
    in its own column (``column`` ``batch``: the reading each run updates with), S diagonal."""

    def __init__(self, batch, m, want: bool):
        self.nis, self.ll = np.zeros(batch), np.zeros(batch)
        self.nu = np.full(batch + (m,), np.nan) if want else None
        self.var = np.full(batch + (m,), np.nan) if want else None

    def add(self, nu, s, valid, column):
        """One scalar update per run: innovation ``nu``, variance ``s``, the reading's ``column`` ``batch``
        (``valid``: the reading is present)."""
        safe = np.where(valid, s, 1.0)
        term = np.where(valid, nu * nu / safe, 0.0)
        self.nis = self.nis + term
        self.ll = self.ll + np.where(valid, -0.5 * (term + np.log(safe) + _LOG_2PI), 0.0)
        if self.nu is not None:
            np.put_along_axis(self.nu, column[..., None], np.where(valid, nu, np.nan)[..., None], -1)
            np.put_along_axis(self.var, column[..., None], np.where(valid, s, np.nan)[..., None], -1)

    def out(self, x, P, dof) -> _Out:
        if self.nu is None:
            return _Out(x, P, self.nis, dof, self.ll)
        m = self.nu.shape[-1]
        S = np.where(np.eye(m, dtype=bool), self.var[..., :, None], 0.0)
        S = np.where(np.isnan(self.var)[..., :, None] | np.isnan(self.var)[..., None, :], np.nan, S)
        return _Out(x, P, self.nis, dof, self.ll, self.nu, S)


def _rss_serial_update(x, P, z, meas: RssMeasurement, step: int = 0, want: bool = False) -> _Out:
    """Table 3.3: scalar updates in descending RSS order (strongest anchor first), each re-linearised at the
    state updated so far; loop bound j <= N (the print's "for each j < N" would skip the
    last anchor; corrected)."""
    idx = np.asarray(meas.position_index)
    ch = meas.channel
    m = z.shape[-1]
    anchors = meas.anchors_at(step)
    p0 = np.broadcast_to(np.asarray(ch.ref_power_dbm, dtype=float), z.shape)
    ple = np.broadcast_to(np.asarray(ch.path_loss_exp, dtype=float), z.shape)
    sigma2 = np.broadcast_to(np.asarray(ch.sigma_db, dtype=float) ** 2, z.shape)
    order = _serial_order(z, meas.order)
    # the scalar innovations of one step are independent under the model (each is conditioned on the previous
    # updates), so their NIS add up to a chi-square with one dof per reading (to first order: h is linearised)
    acc, dof = _Serial(x.shape[:-1], m, want), np.isfinite(z).sum(axis=-1)
    for j in range(m):
        a = order[..., j]
        zj = np.take_along_axis(z, a[..., None], -1)[..., 0]
        valid = np.isfinite(zj)
        if not valid.any():
            continue
        pick = lambda arr: np.take_along_axis(arr, a[..., None], -1)[..., 0]
        diff = meas.lift(x[..., idx]) - _pick_anchor(anchors, a)
        hx, grad, d = _rss_mean_jacobian(meas, diff, pick(p0), pick(ple), x.ndim - 1)   # the batch axes in the anchor's place
        h_row = np.zeros(x.shape)
        h_row[..., idx] = grad[..., :idx.size]
        var = meas.variance_db2(d, pick(ple), np.sqrt(pick(sigma2)))
        nu = np.where(valid, zj - hx, 0.0)
        ph = (P @ h_row[..., None])[..., 0]                   # P H^T
        s = np.einsum("...i,...i->...", h_row, ph) + var
        if (valid & ~(s > 0)).any():
            raise _Singular(valid & ~(s > 0))
        K = np.where(valid[..., None], ph / s[..., None], 0.0)
        acc.add(nu, s, valid, np.broadcast_to(a, valid.shape))
        x = x + K * nu[..., None]
        over = ~np.all(np.isfinite(x), axis=-1)
        if over.any():              # named here: the next reading's linearisation would only see NaN
            raise _Singular(over, _UPDATE_OVERFLOW)
        P = _joseph(P, K[..., :, None], h_row[..., None, :], var[..., None, None])
    return acc.out(x, P, dof)


def _nonlinear_ekf_update(x, P, z, meas: NonlinearMeasurement, want: bool = False, step: int = 0) -> _Out:
    """EKF update of a :class:`NonlinearMeasurement`: linearised at the predicted state (h, its Jacobian and the
    residual checked: a NaN from them where a reading is present is an error, not a missing reading)."""
    valid = np.isfinite(z)
    H = meas.jacobian_at(x, valid, step)
    h = meas.readings_at(x, valid, step, x.ndim - 1)
    # the linear update on the linearisation z - h(x) = H (x_true - x) + v, whose innovation is (the residual) z - h(x)
    nu = meas.residual_of(np.where(valid, z, h), h, valid, step, x.ndim - 1)
    return _linear_update(x, P, np.where(valid, nu + (H @ x[..., None])[..., 0], np.nan), H, meas.noise_at(x),
                          want=want)


def _serial_linear(x, P, m: int, update, want: bool) -> _Out:
    """Scalar updates ``update(x, P, j)`` of the components ``j = 0 .. m-1`` in order (a diagonal R), each from the
    previous one's posterior; NIS, dof and log-likelihood summed, innovations side by side, S diagonal."""
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


def _linear_stream_update(x, P, z, meas: LinearMeasurement, joseph: bool = True, want: bool = False) -> _Out:
    H, R = np.asarray(meas.H, float), np.asarray(meas.R, float)
    if meas.mode == "parallel":
        return _linear_update(x, P, z, H, R, joseph=joseph, want=want)
    return _serial_linear(x, P, z.shape[-1], lambda x, P, j: _linear_update(
        x, P, z[..., j:j + 1], H[..., j:j + 1, :], R[..., j:j + 1, j:j + 1], joseph=joseph, want=want), want)


def _ekf_update(x, P, z, meas, step, want: bool = False, joseph: bool = True) -> _Out:
    """One stream's update of the EKF (and the KF): linear streams exactly, RSS and nonlinear ones linearised at the
    state so far."""
    if isinstance(meas, LinearMeasurement):
        return _linear_stream_update(x, P, z, meas, joseph, want)
    if isinstance(meas, NonlinearMeasurement):
        return _nonlinear_ekf_update(x, P, z, meas, want, step)
    if meas.mode == "parallel":
        return _rss_parallel_update(x, P, z, meas, step, want)
    return _rss_serial_update(x, P, z, meas, step, want)


def _per_step_stream(meas) -> bool:
    """True for a linear stream whose H or R is given per step."""
    return isinstance(meas, LinearMeasurement) and (isinstance(meas.H, PerStep) or isinstance(meas.R, PerStep))


def _stream_at(meas: LinearMeasurement, step: int) -> LinearMeasurement:
    """The stream with its per-step H and R of ``step`` (checked at construction; built without re-checking)."""
    return _replace_unchecked(meas, **{field: getattr(meas, field).at(step) for field in ("H", "R")
                                       if isinstance(getattr(meas, field), PerStep)})


def _replace_unchecked(stream, **changes):
    """``dataclasses.replace`` of a frozen stream without running its checks again: for values derived from checked
    ones inside a filter (a per-step matrix's step, a congruence of a checked covariance), where re-checking every
    step would cost more than the update."""
    view = object.__new__(type(stream))
    for field in stream.__dataclass_fields__:
        object.__setattr__(view, field, changes.get(field, getattr(stream, field)))
    return view


def _stream_name(meas) -> str:
    return meas.name if isinstance(meas, NonlinearMeasurement) else type(meas).__name__


def _stream_readings(meas):
    """A stream's readings ``batch + (T, m)``."""
    return meas.rss_dbm if isinstance(meas, RssMeasurement) else meas.z
