"""The RSS measurement model: one object that every RSS filter and estimator asks for the mean reading, its
Jacobian, the log-likelihood of readings and the Fisher information (after Stone Soup's measurement models).

Reader (anchor) ``j`` at ``a_j`` hears a tag at ``p`` with (Ozkaya 2011, Eq. (6.3); Dogan 2015, Eq. (2.2);
George and Vadivukkarasi, Eq. (5))

    s_j = h_j(p) + e_j,   h_j(p) = P_0j - 10 n_j log10(max(d_j, d_min) / d0) - nW_j(p) WAF,   e_j ~ N(0, sigma_j^2),

independently across readers, with the channel's parameters and near-field clamp ``d_min``
(:class:`locbook.models.channel.PathLossModel`, evaluated by :func:`~locbook.models.channel.log_distance_mean_dbm`),
``nW_j`` the walls crossed by the straight path (:func:`~locbook.models.channel.wall_crossings`). ``d_j`` is the
distance in the position's space or, with ``tag_height_m``, the 3-D distance to anchors that carry a height
(``d^2 = |p - a_j|^2 + (z_j - h)^2``, the tag in the plane ``z = h``).

Two readings of one model. A model of positions (no ``position_index``: the particle and grid filters, the static
estimators, the bounds) takes positions ``(P, dim)`` or per run ``(R, P, dim)``; its results carry a run axis ``R``
(1 when nothing is per run) and the position axis ``P``: mean ``(R, P, m)``, Jacobian ``(R, P, m, dim)``, Fisher
information ``(R, P, dim, dim)``, log-likelihood ``(R, P)`` for readings ``(R, m)``. A model of states (with
``position_index``: the Kalman family) takes points-form states ``batch + (K, n)`` (:mod:`locbook.models.base`).
Parameters are scalars, per reader ``(m,)``, per run ``batch + (1 or m,)``, or, with ``per_step_channel=True``, per
step ``batch + (T, 1 or m)`` (e.g. the online calibration of Ozkaya Eqs. (6.5)-(6.7) with its pooled sigma
``(R, T, 1)``). Anchors are ``(m, k)``, per run ``(R, m, k)`` (measurement locations drawn per Monte-Carlo run,
Palvai 2008), or per step ``per_step(batch + (T, m, k))`` (states only). NaN readings mean "not heard" and are left
out. For one release a model of positions still reads unmarked ``(R, T, m)`` parameters and an ``(R, T)`` sigma as per
run and step (deprecated: a DeprecationWarning asks for ``per_step_channel=True`` and sigma ``(R, T, 1)``).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any

import numpy as np

from .._linalg import _STATE_NOT_FINITE, _location_information, _Singular
from .._validate import as_array, check_scalar
from .base import MeasurementModel, PerStep, step_matrix
from .channel import (
    PathLossModel,
    log_distance_gradient,
    log_distance_mean_dbm,
    require_path_loss_model,
    wall_crossings,
)

__all__ = ["RssModel", "RssMeasurementModel", "rss_mean_jacobian", "LIKELIHOOD_BLOCK_VALUES"]

_LOG_2PI = float(np.log(2.0 * np.pi))
#: runs per block of :meth:`RssModel.log_likelihood`: about this many values in each temporary (32 MiB)
LIKELIHOOD_BLOCK_VALUES = 1 << 22
#: the largest per-run mean table (runs x cells x anchors values) :meth:`RssModel.points_log_likelihood` keeps
TABLE_MAX_VALUES = 1 << 24


def _table_log_likelihood(rss, table, sigma, dim: int):
    """:meth:`RssModel.log_likelihood` (``constant=False``) of the readings ``(R, m)`` from the mean table ``(1 or
    R, C, m)``: the same arithmetic on the same blocks of runs, so the same bits."""
    n_runs, n_cells = rss.shape[0], table.shape[1]
    block = max(1, LIKELIHOOD_BLOCK_VALUES // max(1, n_cells * rss.shape[1] * (dim + 1)))
    out = np.empty((n_runs, n_cells))
    for start in range(0, n_runs, block):
        rows = slice(start, start + block)
        r = rss[rows]
        resid = r[:, None, :] - (table[rows] if table.shape[0] > 1 else table)
        resid = np.where(np.isnan(r)[:, None, :], 0.0, resid)
        if np.ndim(sigma) == 1:
            resid = resid / sigma
            out[rows] = -0.5 * np.einsum("rpm,rpm->rp", resid, resid)
        else:
            out[rows] = -0.5 * np.einsum("rpm,rpm->rp", resid, resid) / np.square(sigma)
    return out


def rss_mean_jacobian(offset_m, ref_power_dbm, path_loss_exp, *, ref_distance_m: float = 1.0,
                      min_distance_m: float = 0.0, vertical_m2=None, jacobian: bool = True):
    """The model's arithmetic at offsets ``p - a_j`` ``(..., m, k)``, without input checks (the filters' and
    solvers' inner loops; :class:`RssModel` checks, then calls it): the mean ``h_j`` ``(..., m)`` (module
    docstring, walls left out), its Jacobian ``dh_j/dp = -(10 n_j / ln 10) (p - a_j) / d_j^2`` ``(..., m, k)``
    (``None`` with ``jacobian=False``; exactly 0 within the clamp ``d_j < min_distance_m``, where the clamped mean is
    flat) and the squared distances ``d_j^2`` ``(..., m)`` (not clamped). ``vertical_m2``: squared vertical offsets
    broadcasting to ``(..., m)`` added to ``|p - a_j|^2`` (anchors above the tag's plane; the Jacobian is then the
    plan part). Parameters broadcast against ``(..., m)``. Distances that overflow give an infinite ``d^2`` (callers
    that must refuse it check)."""
    d2 = np.einsum("...i,...i->...", offset_m, offset_m)
    if vertical_m2 is not None:
        d2 = d2 + vertical_m2
    mean = log_distance_mean_dbm(np.sqrt(d2), ref_power_dbm, path_loss_exp, ref_distance_m=ref_distance_m,
                                 min_distance_m=min_distance_m)
    grad = log_distance_gradient(offset_m, path_loss_exp, min_distance_m=min_distance_m, d2_m2=d2) if jacobian else None
    return mean, grad, d2


_ON_ANCHOR = ("the state is on an anchor at step {step} and the channel has no near-field clamp (min_distance_m = 0), "
              "where the log-distance mean is infinite: give the channel a min_distance_m (e.g. 1e-3 m)")
_CHANNEL_FIELDS = ("ref_power_dbm", "path_loss_exp", "sigma_db")


def _anchor_axis(value):
    """A channel parameter (scalar, ``(m,)`` or ``batch + (1 or m,)``) made to broadcast against points-form values
    ``batch + (K, m)``."""
    value = np.asarray(value, dtype=float)
    return value[..., None, :] if value.ndim >= 2 else value


@dataclass(frozen=True)
class RssModel(MeasurementModel):
    """Log-distance RSS readings from ``anchors_m`` through ``channel`` (module docstring): the one RSS model of the
    library. The particle and grid filters, the static estimators and the bounds evaluate it at positions; the Kalman
    family's streams (:func:`locbook.RssMeasurement`, or ``Stream(rss_dbm, model)``) at states, whose position
    components are ``position_index``.

    ``anchors_m``: ``(m, dim)``; per run ``batch + (m, dim)``; per step ``per_step(batch + (T, m, dim))`` (a moving
    receiver, or measurement locations drawn per Monte-Carlo run: Palvai 2008, Eq. (4.28); the Kalman family only).
    With ``tag_height_m`` the anchors are ``(..., m, 3)``, the last coordinate the anchor's height, the positions 2-D
    (the tag moves in the plane ``z = tag_height_m``) and distances 3-D.

    ``channel``: a :class:`PathLossModel`. Its ``ref_power_dbm``, ``path_loss_exp`` and ``sigma_db`` are scalars, per
    anchor ``(m,)``, or with leading run axes ``batch + (1 or m,)``. With ``per_step_channel=True`` every one of them
    with two axes or more carries a step axis before the anchor axis, ``batch + (T, 1 or m)`` (a time axis of length 1
    holds for every step), e.g. the online calibration of Ozkaya 2011, Eqs. (6.5)-(6.7), whose pooled sigma is
    ``(R, T, 1)``. Its ``min_distance_m`` is the near-field clamp (0: none; a position on an anchor then has an
    infinite mean) and its ``wall_attenuation_db`` the loss per wall of ``walls_m`` ``(W, 2, 2)`` (2-D only).

    ``position_index``: the states' position components (the Kalman family; None: the states are the positions).
    ``anchor_sigma_m``: the anchors' positions are known only to this standard deviation (Palvai's sigma_3); the
    Kalman family's variance is then ``sigma^2 + (10 n / ln 10)^2 anchor_sigma^2 / d^2`` (0 added within the clamp) at
    the linearisation point (first-order propagation; an extension: Palvai 2008, Sec. 4.4, does not say how sigma_3
    enters the EKF).

    The evaluation at positions (:meth:`mean_rss_dbm`, :meth:`log_likelihood`, :meth:`fisher_information`, the
    particle and grid filters) takes one run axis: positions ``(P, dim)`` or ``(R, P, dim)``, anchors ``(m, dim)`` or
    ``(R, m, dim)``, parameters per run ``(R, 1 or m)`` or per run and step; a per-anchor sigma per run is not taken
    there (one sigma per run and step, or one per anchor shared by the runs).

    Examples
    --------
    Two anchors 10 m apart; the mean powers at two positions (a run axis of one, then positions, then anchors):

    >>> import numpy as np
    >>> import locbook as lb
    >>> model = lb.RssModel(np.array([[0.0, 0.0], [10.0, 0.0]]), lb.PathLossModel(-40.0, 2.0, sigma_db=3.0))
    >>> print(np.round(model.mean_rss_dbm(np.array([[1.0, 0.0], [5.0, 0.0]])), 2))
    [[[-40.   -59.08]
      [-53.98 -53.98]]]
    """

    anchors_m: np.ndarray | PerStep
    channel: PathLossModel
    walls_m: np.ndarray | None = None
    tag_height_m: float | None = None
    position_index: np.ndarray | None = None
    anchor_sigma_m: float = 0.0
    per_step_channel: bool = False
    name: str = "RssModel"
    checks_own_output = True

    def __post_init__(self):
        require_path_loss_model(self.channel, "channel")
        if self.tag_height_m is not None:
            check_scalar("tag_height_m", self.tag_height_m)
        given = self.anchors_m
        per_step_anchors = isinstance(given, PerStep)
        anchors = as_array("anchors_m", given.value if per_step_anchors else given,
                           min_ndim=3 if per_step_anchors else 2)
        if self.tag_height_m is not None and anchors.shape[-1] != 3:
            raise ValueError(f"anchors_m must end in (m, 3) (x, y, height) with tag_height_m (the tag moves in the "
                             f"plane z = tag_height_m), got {anchors.shape}")
        if anchors.shape[-1] < 1:
            raise ValueError(f"anchors_m must have shape (m, dim) or batch + (m, dim), got {anchors.shape}")
        object.__setattr__(self, "anchors_m", PerStep(anchors, "anchors_m") if per_step_anchors else anchors)
        m = anchors.shape[-2]
        if self.position_index is not None:
            idx = np.asarray(self.position_index)
            if idx.dtype == object or (idx.size and not np.issubdtype(idx.dtype, np.integer)):
                raise ValueError(f"{self.name}.position_index must hold integer state indices, got "
                                 f"{self.position_index!r}")
            if idx.shape != (self.dim,):
                raise ValueError(f"{self.name}.position_index must hold {self.dim} state indices (one per axis of the "
                                 f"anchors{', the height known' if self.tag_height_m is not None else ''}), got "
                                 f"{self.position_index!r}")
            object.__setattr__(self, "position_index", idx)
        check_scalar("anchor_sigma_m", self.anchor_sigma_m, ge=0)
        if not isinstance(self.per_step_channel, (bool, np.bool_)):
            raise ValueError(f"per_step_channel must be True or False, got {self.per_step_channel!r}")
        ch = self.channel
        sigma_shape = np.shape(ch.sigma_db)
        if self.position_index is None and not self.per_step_channel and (
                np.ndim(ch.ref_power_dbm) == 3 or np.ndim(ch.path_loss_exp) == 3 or (
                    len(sigma_shape) == 2 and sigma_shape[-1] != 1)):
            # the old unmarked per-run-and-step form: (R, T, m) parameters, an (R, T) pooled sigma
            warnings.warn("RssModel: channel parameters (R, T, m) and sigma (R, T) per run and step are deprecated "
                          "unmarked; give per_step_channel=True with sigma (R, T, 1)", DeprecationWarning, stacklevel=3)
            if len(sigma_shape) == 2:
                ch = replace(ch, sigma_db=np.asarray(ch.sigma_db, float)[..., None])
            object.__setattr__(self, "channel", ch)
            object.__setattr__(self, "per_step_channel", True)
        for name in _CHANNEL_FIELDS:
            value = np.asarray(getattr(ch, name), float)
            if value.ndim and value.shape[-1] not in (1, m):
                raise ValueError(f"channel.{name} must be a scalar or end in (1,) or ({m},) (one per anchor), "
                                 f"got shape {value.shape}")
        if np.any(np.asarray(ch.path_loss_exp) <= 0):
            raise ValueError(f"channel.path_loss_exp must be positive, got {ch.path_loss_exp!r}")
        if self.walls_m is not None:
            walls = as_array("walls_m", np.reshape(self.walls_m, (-1, 2, 2)))
            if self.dim != 2:
                raise ValueError(f"walls_m needs 2-D positions, the anchors give {self.dim}-D")
            object.__setattr__(self, "walls_m", walls)
        if self.position_index is None:
            _ = self._one_run_axis      # a model of positions: its per-run axes must agree (checked once, here)

    # -- shapes --------------------------------------------------------------------------------------
    @property
    def _anchor_values(self) -> np.ndarray:
        a = self.anchors_m
        return a.value if isinstance(a, PerStep) else a

    @property
    def n_anchors(self) -> int:
        return self._anchor_values.shape[-2]

    @property
    def dim(self) -> int:
        """The dimension of the positions (the anchors' minus the height column)."""
        return self._anchor_values.shape[-1] - (self.tag_height_m is not None)

    @cached_property
    def _one_run_axis(self) -> dict:
        """The parameters in the form the evaluation at positions reads (class docstring): ``ref_power_dbm`` and
        ``path_loss_exp`` a scalar, ``(m,)`` or ``(R or 1, T or 1, 1 or m)``; ``sigma_db`` a scalar, ``(m,)`` or
        ``(R or 1, T or 1)``; with ``"runs"`` (None or R).
        Refused in one line when the model has more than one run axis, per-step anchors or a per-anchor sigma per
        run."""
        if isinstance(self.anchors_m, PerStep):
            raise ValueError(f"{self.name}: per-step anchors (per_step(anchors_m)) are read by the Kalman family only; "
                             f"the particle and grid filters, the estimators and the bounds take (m, dim) or per run "
                             f"(R, m, dim)")
        if self.anchors_m.ndim > 3:
            raise ValueError(f"{self.name}: anchors_m {self.anchors_m.shape} has more than one run axis; the particle "
                             f"and grid filters, the estimators and the bounds take (m, dim) or per run (R, m, dim)")
        out: dict[str, Any]
        runs: set[int]
        out, runs = {}, set()
        if self.anchors_m.ndim == 3:
            runs.add(self.anchors_m.shape[0])
        for name in _CHANNEL_FIELDS:
            value = np.asarray(getattr(self.channel, name), float)
            if value.ndim >= 2:
                if value.ndim > 2 + self.per_step_channel:
                    raise ValueError(
                        f"{self.name}: channel.{name} {value.shape} has more than one run axis"
                        f"{'' if self.per_step_channel else ' (per-step values: give per_step_channel=True)'}; the "
                        f"particle and grid filters, the estimators and the bounds take one")
                if not self.per_step_channel:
                    value = value[:, None, :]                           # (R, one step for all, k)
                elif value.ndim == 2:
                    value = value[None]                                 # (one run for all, T, k)
                if value.shape[0] > 1 or np.ndim(getattr(self.channel, name)) == 2 + self.per_step_channel:
                    runs.add(value.shape[0])
                if name == "sigma_db":
                    if value.shape[-1] != 1:
                        raise ValueError(f"{self.name}: channel.sigma_db {np.shape(self.channel.sigma_db)} gives a "
                                         f"sigma per anchor per run; the particle and grid filters, the estimators and "
                                         f"the bounds take one sigma per run (R, 1) (and step), or per anchor (m,)")
                    value = value[..., 0]
            out[name] = value
        if len(runs) > 1:
            raise ValueError(f"per-run anchors and parameters disagree on the number of runs: {sorted(runs)}")
        out["runs"] = runs.pop() if runs else None
        return out

    @property
    def runs(self) -> int | None:
        """The number of runs of per-run anchors or parameters (None when everything is shared)."""
        return self._one_run_axis["runs"]

    @property
    def steps(self) -> int | None:
        """The number of steps the per-step anchors and parameters hold (None when none is per step, or all hold for
        every step: a time axis of length 1)."""
        lengths = [self.anchors_m.value.shape[-3]] if isinstance(self.anchors_m, PerStep) else []
        if self.per_step_channel:
            lengths += [np.shape(getattr(self.channel, n))[-2] for n in _CHANNEL_FIELDS
                        if np.ndim(getattr(self.channel, n)) >= 2]
        lengths = [t for t in lengths if t > 1]
        return min(lengths) if lengths else None

    def per_run_or_step(self) -> dict:
        """``{field: shape}`` of the anchors and channel parameters that carry a run or step axis (``"anchors_m"``,
        ``"channel.ref_power_dbm"``, ...): what an estimator or a bound of one layout and one channel refuses."""
        a = self.anchors_m
        out = {"anchors_m": a.shape} if isinstance(a, PerStep) or a.ndim > 2 else {}
        out.update({f"channel.{n}": np.shape(getattr(self.channel, n)) for n in _CHANNEL_FIELDS
                    if np.ndim(getattr(self.channel, n)) >= 2})
        return out

    def select_runs(self, runs) -> "RssModel":
        """The model of the runs ``runs`` (a slice or indices) of its per-run anchors and parameters."""
        ch = self.channel
        n_core = 2 if self.per_step_channel else 1

        def part(value, core):
            return np.asarray(value)[runs] if np.ndim(value) > core else value

        channel = replace(ch, **{name: part(getattr(ch, name), n_core) for name in _CHANNEL_FIELDS})
        return replace(self, anchors_m=part(self.anchors_m, 2), channel=channel)

    def check_step(self, step) -> None:
        """``step`` must index the per-step parameters (no negative wrap-around)."""
        n_steps = self.steps
        if isinstance(step, (bool, np.bool_)) or not isinstance(step, (int, np.integer)) or step < 0 or (
                n_steps is not None and step >= n_steps):
            raise ValueError(f"step must be an integer in [0, {'inf' if n_steps is None else n_steps}), got {step!r}")

    def channel_at(self, step: int = 0) -> PathLossModel:
        """The channel at ``step`` in the one-run-axis form: ``ref_power_dbm`` and ``path_loss_exp`` scalars, ``(m,)``
        or per run ``(R, m)``; ``sigma_db`` a scalar, ``(m,)`` or per run ``(R, 1)``."""
        self.check_step(step)
        values = {name: self._per_step(name, step) for name in _CHANNEL_FIELDS}
        for name in ("ref_power_dbm", "path_loss_exp"):
            if values[name].ndim == 3:                                  # (R|1, 1, 1|m) -> (R|1, m)
                values[name] = np.broadcast_to(values[name][:, 0, :], (values[name].shape[0], self.n_anchors))
        return replace(self.channel, **values)

    # -- the measurement-model protocol (locbook.models.base) ---------------------------------------
    @property
    def n_readings(self) -> int:
        return self.n_anchors

    @property   # the base's class default None, a read-only property here: the model is of positions
    def position_dim(self) -> int:  # type: ignore[override]
        """The model reads positions of this dimension (the particle and grid filters hand it a state's position
        components)."""
        return self.dim

    @property
    def state_position_index(self) -> np.ndarray:
        """The states' position components: ``position_index``, or the first ``dim`` (the states are positions)."""
        return np.arange(self.dim) if self.position_index is None else self.position_index

    @property
    def clamp_m(self) -> float:
        """The model's near-field clamp: the channel's ``min_distance_m``."""
        return float(self.channel.min_distance_m)

    def lift(self, positions_m):
        """Positions ``(..., k)`` from the state, with the known tag height appended when there is one."""
        if self.tag_height_m is None:
            return positions_m
        return np.concatenate([positions_m, np.full(positions_m.shape[:-1] + (1,), float(self.tag_height_m))], -1)

    def anchors_at(self, step: int) -> np.ndarray:
        """Anchor positions at ``step``: ``(m, dim)`` or ``batch + (m, dim)``."""
        a = self.anchors_m
        return step_matrix(a.value, step) if isinstance(a, PerStep) else a

    def _param(self, name: str, step: int) -> np.ndarray:
        """A channel parameter at ``step``: a scalar, ``(m,)`` or ``batch + (1 or m,)`` (the Kalman family's form)."""
        value = np.asarray(getattr(self.channel, name), dtype=float)
        if self.per_step_channel and value.ndim >= 2:
            return value[..., min(step, value.shape[-2] - 1), :]
        return value

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

    def _refuse_on_anchor(self, d2, batch_ndim: int | None) -> None:
        """Without a clamp the mean is infinite on an anchor: a named error for the runs (``batch_ndim`` leading axes
        of the squared distances ``d2``; the rest are reduced) whose point lies on one."""
        if self.clamp_m == 0 and not np.all(d2 != 0):
            on = d2 == 0
            if batch_ndim is not None:
                on = on.reshape(on.shape[:batch_ndim] + (-1,)).any(axis=-1)
            raise _Singular(on, _ON_ANCHOR)

    def _points_offsets(self, x, step: int):
        """``p - a_j`` ``batch + (K, m, dim)`` at points-form states ``batch + (K, n)``."""
        a = self.anchors_at(step)
        a = a if a.ndim == 2 else a[..., None, :, :]
        return self.lift(x[..., self.state_position_index])[..., None, :] - a

    def _wall_loss_db(self, x, step: int):
        """The walls' loss ``nW_j(p) WAF`` ``batch + (K, m)`` at points-form states (0 without walls)."""
        if self.walls_m is None or self.channel.wall_attenuation_db == 0.0:
            return 0.0
        plan = self.anchors_at(step)[..., :2]
        if plan.ndim != 2:
            raise ValueError(f"{self.name}: walls with per-run or per-step anchors are not evaluated at states; give "
                             f"(m, 2) anchors")
        pos = np.asarray(x, dtype=float)[..., self.state_position_index]
        crossings = wall_crossings(pos.reshape(-1, 2), plan, self.walls_m).reshape(pos.shape[:-1] + (plan.shape[0],))
        return self.channel.wall_attenuation_db * crossings

    def _at_states(self, x, step: int, jacobian: bool):
        """:func:`rss_mean_jacobian` at points-form states ``batch + (K, n)`` (a model of states): the mean ``batch +
        (K, m)`` (walls left out) and the position gradient (None with ``jacobian=False``); a state on an anchor
        without a clamp is refused."""
        self.check_step(step)
        ch = self.channel
        mean, grad, d2 = rss_mean_jacobian(self._points_offsets(x, step),
                                           _anchor_axis(self._param("ref_power_dbm", step)),
                                           _anchor_axis(self._param("path_loss_exp", step)),
                                           ref_distance_m=ch.ref_distance_m, min_distance_m=self.clamp_m,
                                           jacobian=jacobian)
        self._refuse_on_anchor(d2, np.ndim(x) - 2)
        return mean, grad

    def mean(self, x, step: int = 0):
        """A model of positions: ``h(p)`` ``(R|1, P, m)`` (:meth:`mean_rss_dbm`). A model of states: ``h``
        ``batch + (K, m)`` at points-form states ``batch + (K, n)`` (their ``position_index`` components)."""
        if self.position_index is None:
            return self.mean_rss_dbm(x, step)
        return self._at_states(x, step, jacobian=False)[0] - self._wall_loss_db(x, step)

    def jacobian(self, x, step: int = 0):
        """A model of positions: ``dh_j/dp`` ``(R|1, P, m, dim)`` (:meth:`position_jacobian`). A model of states:
        ``dh_j/dx`` ``batch + (K, m, n)``: ``dh_j/dp = -(10 n_j / ln 10) (p - a_j) / d_j^2`` in the position
        components (the EKF Jacobian of Dogan 2015, Table 3.2, not printed there; ``d_j`` the 3-D distance when the
        anchors have heights), 0 in the others. Walls add a piecewise-constant term (zero derivative almost
        everywhere). Within the near-field clamp (``d_j < d_min``) the mean ``P_0 - 10 n log10(d_min / d0)`` is
        constant, so the derivative is exactly 0 there (:func:`~locbook.models.channel.log_distance_gradient`)."""
        if self.position_index is None:
            return self.position_jacobian(x, step)
        grad = self._at_states(x, step, jacobian=True)[1]
        idx = self.state_position_index
        H = np.zeros(grad.shape[:-1] + (np.shape(x)[-1],))
        H[..., idx] = grad[..., :idx.size]
        return H

    def covariance(self, x, step: int = 0):
        """A model of positions: ``diag(sigma_j^2)`` at the step, broadcasting to ``(R|1, P, m, m)``. A model of
        states: ``diag(sigma^2)`` per reading ``batch + (K, m, m)``, inflated at the points' distances for
        ``anchor_sigma_m``."""
        if self.position_index is None:
            sigma = np.asarray(self._per_step("sigma_db", step), dtype=float)        # (), (m,) or (R, 1)
            var = np.broadcast_to(np.square(sigma), np.broadcast_shapes(sigma.shape, (self.n_anchors,)))
            return var[..., None, :, None] * np.eye(self.n_anchors)
        self.check_step(step)
        diff = self._points_offsets(x, step)
        d = np.sqrt(np.einsum("...i,...i->...", diff, diff))
        var = np.broadcast_to(self.variance_db2(d, _anchor_axis(self._param("path_loss_exp", step)),
                                                _anchor_axis(self._param("sigma_db", step))), d.shape)
        return var[..., :, None] * np.eye(self.n_readings)

    def innovation(self, x, z, *, step: int = 0):
        """Table 3.4's linearisation at the states ``x`` ``batch + (n,)``: ``z - h(x)``, the stacked Jacobian and
        ``R = sigma^2 I`` (inflated for uncertain anchor positions); a model of states only."""
        self.check_step(step)
        idx = self.state_position_index
        ch = self.channel
        path_loss_exp = self._param("path_loss_exp", step)
        offset = self.lift(x[..., idx])[..., None, :] - self.anchors_at(step)
        h, grad, d2 = rss_mean_jacobian(offset, self._param("ref_power_dbm", step), path_loss_exp,
                                        ref_distance_m=ch.ref_distance_m, min_distance_m=self.clamp_m)
        self._refuse_on_anchor(d2, x.ndim - 1)
        d = np.sqrt(d2)
        H = np.zeros(grad.shape[:-1] + (x.shape[-1],))
        H[..., idx] = grad[..., :idx.size]
        far = ~np.all(np.isfinite(d), axis=-1)
        if far.any():                   # the state ran away (an overflow, e.g. after a reading of 1e300 dBm)
            raise _Singular(far, _STATE_NOT_FINITE)
        if self.walls_m is not None and ch.wall_attenuation_db != 0.0:
            h = h - self._wall_loss_db(x[..., None, :], step)[..., 0, :]
        m = z.shape[-1]
        sigma2 = np.broadcast_to(self.variance_db2(d, path_loss_exp, self._param("sigma_db", step)), z.shape)
        return z - h, H, sigma2[..., :, None] * np.eye(m)

    def independent_readings(self) -> bool:
        return True

    def noise(self):
        if self.per_step_channel:
            raise ValueError(f"{self.name}: a per-step channel's noise is not fitted; give fit_R=None for this stream")
        return "variances", np.asarray(self.channel.sigma_db, dtype=float) ** 2

    def with_noise(self, value) -> "RssModel":
        return replace(self, channel=replace(self.channel, sigma_db=np.sqrt(value)))

    def run_shapes(self) -> list:
        a = self.anchors_m
        core = 1 + self.per_step_channel
        shapes = [(f"{self.name}.anchors_m", a.value.shape[:-3] if isinstance(a, PerStep) else a.shape[:-2])]
        for name in _CHANNEL_FIELDS:
            value = np.shape(getattr(self.channel, name))
            shapes.append((f"{self.name}.channel.{name}", value[:-core] if len(value) >= core else ()))
        return shapes

    def relative_log_likelihood(self, z, x, *, step: int = 0):
        """:meth:`log_likelihood` without its position-free constant (``constant=False``)."""
        return self.log_likelihood(z, x, step, constant=False)

    def check_readings(self, z, n_state=None) -> None:
        if n_state is None:             # the particle and grid filters: positions
            self.readings(z, ndim=np.ndim(z) if np.ndim(z) in (2, 3) else 3)
            return
        m = self.n_readings
        if np.shape(z)[-1] != m:
            raise ValueError(f"{self.name}.rss_dbm has {np.shape(z)[-1]} anchors on its last axis, anchors_m has {m}")
        if self.position_index is None:
            raise ValueError(f"{self.name} in a Kalman-family stream is a model of states: give "
                             f"RssModel(..., position_index=...) ({self.dim} state indices of the {n_state}-state)")
        a = self.anchors_m
        if isinstance(a, PerStep) and a.value.shape[-3] not in (1, np.shape(z)[-2]):
            raise ValueError(f"{self.name}.anchors_m per step must have shape batch + (T, m, dim) with T = "
                             f"{np.shape(z)[-2]} steps (or 1), got {a.value.shape}")
        if self.per_step_channel:
            for name in _CHANNEL_FIELDS:
                value = np.shape(getattr(self.channel, name))
                if len(value) >= 2 and value[-2] not in (1, np.shape(z)[-2]):
                    raise ValueError(f"{self.name}.channel.{name} per step must have shape batch + (T, 1 or m) with "
                                     f"T = {np.shape(z)[-2]} steps (or 1), got {value}")
        if np.max(self.state_position_index) >= n_state:
            raise ValueError(f"{self.name}.position_index {self.state_position_index} is outside the {n_state}-state")

    # -- evaluation at positions (one run axis: the particle and grid filters, the estimators, the bounds) ------
    def mean_table(self, points, n_runs: int):
        """``(table, sigma)``: the cell-by-anchor mean ``(1 or R, C, m)`` at fixed ``points`` ``(C, dim)`` and the
        sigma, when the mean does not change with the step (no per-step parameters; walls are fixed per cell too) and a
        per-run table fits in :data:`TABLE_MAX_VALUES`; else None (each step evaluates the model)."""
        runs = self.runs
        if self.steps is not None or (runs is not None and runs * points.shape[0] * self.n_anchors > TABLE_MAX_VALUES):
            return None
        return self.mean_rss_dbm(points, 0), self._sigma(0, "the likelihood")

    def points_log_likelihood(self, rss_dbm, points, n_runs: int, *, table=False):
        """The log-likelihood ``(R, C)`` (up to a constant per run) of each step's readings ``rss_dbm`` ``(R, T, m)``
        at fixed ``points`` ``(C, dim)`` (a grid's cells), as a function of the step: from the mean table
        (:meth:`mean_table`) by the arithmetic of :meth:`log_likelihood` on the same blocks of runs (the same bits),
        or the model at each step. ``table``: the :meth:`mean_table` already computed (None: there is none)."""
        fixed = table if table is not False else (self.mean_table(points, n_runs) if rss_dbm.shape[1] else None)
        if fixed is None:
            return lambda t: self.log_likelihood(rss_dbm[:, t], points, t, constant=False)
        table, sigma = fixed
        return lambda t: _table_log_likelihood(rss_dbm[:, t], table, sigma, self.dim)

    def readings(self, rss_dbm, *, ndim: int) -> np.ndarray:
        """Readings ``(R, m)`` (``ndim=2``) or ``(R, T, m)`` (``ndim=3``) against the model's anchors, runs and
        steps; NaN = not heard."""
        m = self.n_anchors
        rss = as_array("rss_dbm", rss_dbm, ndim=ndim, nan_ok=True, trailing=(m,) if ndim == 2 else None)
        if rss.shape[-1] != m:
            raise ValueError(f"rss_dbm must have shape ({'runs, steps' if ndim == 3 else 'runs'}, {m}) for the model's "
                             f"{m} anchors, got {rss.shape}")
        runs = self.runs
        if runs is not None and runs != rss.shape[0]:
            raise ValueError(f"the model's per-run anchors or parameters have {runs} runs, rss_dbm has {rss.shape[0]} "
                             f"(shape {rss.shape})")
        if ndim == 3 and rss.shape[1]:
            self.check_step(rss.shape[1] - 1)       # per-step parameters must cover every step
        return rss

    def _positions(self, positions_m) -> np.ndarray:
        positions_m = as_array("positions_m", positions_m, trailing=(None, self.dim))
        if positions_m.ndim not in (2, 3):
            raise ValueError(f"positions_m must have shape (P, {self.dim}) or (R, P, {self.dim}), got "
                             f"{positions_m.shape}")
        runs = self.runs
        if positions_m.ndim == 3 and runs is not None and positions_m.shape[0] != runs:
            raise ValueError(f"positions_m per run {positions_m.shape} must have the model's {runs} runs on its "
                             f"first axis (no silent broadcasting)")
        return positions_m

    def _offsets(self, positions_m):
        """``(p - a_j)`` ``(R|1, P, m, dim)`` and the squared vertical offsets (``(R|1, 1, m)`` or 0)."""
        anchors = self.anchors_m
        plan = anchors[..., :self.dim]
        if anchors.ndim == 3:
            diff = (positions_m if positions_m.ndim == 3 else positions_m[None])[:, :, None, :] - plan[:, None]
        else:
            diff = positions_m[..., None, :] - plan
        if self.tag_height_m is None:
            return diff, None
        vertical = anchors[..., -1] - self.tag_height_m
        return diff, np.square(vertical if anchors.ndim == 2 else vertical[:, None, :])

    def _checked_d2(self, d2, positions_m):
        """``d2`` as given, refused when it overflowed (finite inputs are checked: only overflow makes it infinite)."""
        if not np.all(np.isfinite(d2)):
            raise ValueError(f"the distances between positions_m and anchors_m overflow: their coordinates reach "
                             f"{max(np.abs(positions_m).max(initial=0), np.abs(self.anchors_m).max(initial=0)):.3g} m")
        return d2

    def distance_m(self, positions_m) -> np.ndarray:
        """Distances ``(R|1, P, m)`` from the positions to the anchors (3-D with ``tag_height_m``)."""
        positions_m = self._positions(positions_m)
        diff, vertical2 = self._offsets(positions_m)
        with np.errstate(over="ignore", invalid="ignore"):
            d2 = np.einsum("...i,...i->...", diff, diff)
            if vertical2 is not None:
                d2 = d2 + vertical2
        distance = np.sqrt(self._checked_d2(d2, positions_m))
        return distance if distance.ndim == 3 else distance[None]

    def _per_step(self, name: str, step: int):
        """A parameter at ``step`` in the one-run-axis form: ``(R|1, 1, 1|m)`` or a scalar / ``(m,)`` for
        ``ref_power_dbm`` and ``path_loss_exp``; ``(R|1, 1)`` or a scalar / ``(m,)`` for ``sigma_db``."""
        value = self._one_run_axis[name]
        if name != "sigma_db":
            return value[:, min(step, value.shape[1] - 1), None, :] if value.ndim == 3 else value
        return value[:, min(step, value.shape[1] - 1), None] if value.ndim == 2 else value

    def _evaluate(self, positions_m, step: int, jacobian: bool):
        """:func:`rss_mean_jacobian` at checked positions and step: (positions, mean, Jacobian or None), the run
        axis present."""
        positions_m = self._positions(positions_m)
        self.check_step(step)
        ch = self.channel
        diff, vertical2 = self._offsets(positions_m)
        with np.errstate(over="ignore", invalid="ignore"):
            mean, grad, d2 = rss_mean_jacobian(diff, self._per_step("ref_power_dbm", step),
                                               self._per_step("path_loss_exp", step),
                                               ref_distance_m=ch.ref_distance_m, min_distance_m=ch.min_distance_m,
                                               vertical_m2=vertical2, jacobian=jacobian)
        self._checked_d2(d2, positions_m)
        mean = mean if mean.ndim == 3 else mean[None]
        if grad is not None and grad.ndim == 3:
            grad = grad[None]
        return positions_m, mean, grad

    def mean_rss_dbm(self, positions_m, step: int = 0) -> np.ndarray:
        """``h(p)`` ``(R|1, P, m)`` at positions ``(P, dim)`` or ``(R, P, dim)`` (module docstring)."""
        positions_m, mean, _ = self._evaluate(positions_m, step, jacobian=False)
        ch = self.channel
        if self.walls_m is not None and ch.wall_attenuation_db != 0.0:
            assert isinstance(self.anchors_m, np.ndarray)   # _evaluate's _one_run_axis refuses per-step anchors
            plan = self.anchors_m[..., :2]
            if plan.ndim == 3:
                crossings = np.stack([wall_crossings(positions_m[r] if positions_m.ndim == 3 else positions_m,
                                                     plan[r], self.walls_m) for r in range(plan.shape[0])])
            else:
                crossings = wall_crossings(positions_m, plan, self.walls_m)
            mean = mean - ch.wall_attenuation_db * crossings
        return mean

    def position_jacobian(self, positions_m, step: int = 0) -> np.ndarray:
        """``dh_j/dp`` ``(R|1, P, m, dim)`` at positions ``(P, dim)`` or ``(R, P, dim)`` (:meth:`jacobian`'s values
        with the run axis always present)."""
        return self._evaluate(positions_m, step, jacobian=True)[2]

    def sigma_at(self, step: int = 0):
        """``sigma_db`` at ``step``: a scalar, ``(m,)``, or per run ``(R, 1)`` (checked positive)."""
        return self._sigma(step, "the likelihood")

    def _sigma(self, step: int, where: str):
        sigma = self._per_step("sigma_db", step)
        if np.any(np.asarray(sigma) <= 0):     # a model with sigma 0 gives mean readings, not a density
            raise ValueError(f"{where} needs sigma_db > 0 (channel.sigma_db), got {self.channel.sigma_db!r} at step "
                             f"{step}")
        return sigma

    def log_likelihood(self, rss_dbm, positions_m, step: int = 0, *, constant: bool = True) -> np.ndarray:
        """``log p(s | p) = sum_j log N(s_j; h_j(p), sigma_j^2)`` over the heard readings ``(R, m)`` (NaN: not heard,
        left out; a run that heard nothing gets 0) at positions ``(P, dim)`` or ``(R, P, dim)`` -> ``(R, P)``.

        ``constant=False`` leaves out ``-sum_j (log sigma_j + log(2 pi) / 2)``, which does not depend on the
        position: the particle and grid filters normalise their weights per run and use this form. Runs are
        evaluated in blocks of about :data:`LIKELIHOOD_BLOCK_VALUES` temporaries (each run's arithmetic is the same
        in any block)."""
        rss = self.readings(rss_dbm, ndim=2)
        positions_m = self._positions(positions_m)
        if positions_m.ndim == 3 and positions_m.shape[0] != rss.shape[0]:
            raise ValueError(f"positions_m per run {positions_m.shape} must have the {rss.shape[0]} runs of rss_dbm "
                             f"{rss.shape} on its first axis (no silent broadcasting)")
        self.check_step(step)
        sigma = self._sigma(step, "the likelihood")
        n_runs = rss.shape[0]
        block = max(1, LIKELIHOOD_BLOCK_VALUES // max(1, positions_m.shape[-2] * rss.shape[1] * (self.dim + 1)))
        if n_runs <= block:
            return self._log_likelihood(rss, positions_m, step, constant, sigma)
        out = np.empty((n_runs, positions_m.shape[-2]))
        per_run = self.runs is not None
        for start in range(0, n_runs, block):
            rows = slice(start, start + block)
            model = self.select_runs(rows) if per_run else self
            out[rows] = model._log_likelihood(rss[rows], positions_m[rows] if positions_m.ndim == 3 else positions_m,
                                              step, constant, sigma[rows] if np.ndim(sigma) == 2 else sigma)
        return out

    def _log_likelihood(self, rss, positions_m, step, constant, sigma):
        """:meth:`log_likelihood` on checked inputs, one block of runs (``sigma`` at the step)."""
        missing = np.isnan(rss)
        resid = rss[:, None, :] - self.mean_rss_dbm(positions_m, step)
        resid = np.where(missing[:, None, :], 0.0, resid)
        if np.ndim(sigma) == 1:                # one sigma per anchor
            resid = resid / sigma
            out = -0.5 * np.einsum("rpm,rpm->rp", resid, resid)
        else:
            out = -0.5 * np.einsum("rpm,rpm->rp", resid, resid) / np.square(sigma)
        if constant:
            log_norm = np.broadcast_to(np.log(sigma) + 0.5 * _LOG_2PI, rss.shape)       # sigma: (), (m,) or (R, 1)
            out = out - np.where(missing, 0.0, log_norm).sum(axis=-1)[:, None]
        return out

    def fisher_information(self, positions_m, step: int = 0, *, heard=None) -> np.ndarray:
        """``J(p) = sum_j grad h_j grad h_j^T / sigma_j^2`` ``(R|1, P, dim, dim)``, i.e.
        ``(10 n / (sigma ln 10))^2 sum_j (p - a_j)(p - a_j)^T / d_j^4`` (Patwari et al. 2003, Eq. (5); Ozkaya 2011,
        App. A corrected; Dogan 2015, Eq. (4.19)), from :meth:`position_jacobian`. ``heard``: booleans broadcastable
        to ``(R|1, P, m)``, False where an anchor gave no reading (its term is left out)."""
        grad = self.position_jacobian(positions_m, step)
        sigma = self._sigma(step, "the Fisher information")
        gain = 1.0 / np.square(np.asarray(sigma, float))
        gain = gain[..., None] if np.ndim(gain) == 2 else gain                     # (R, 1) -> (R, 1, 1)
        gain = np.broadcast_to(gain, np.broadcast_shapes(np.shape(gain), grad.shape[:-1]))
        return _location_information(gain, grad, heard)


def RssMeasurementModel(anchors_m, channel, position_index, anchor_sigma_m: float = 0.0, tag_height_m=None,
                        name: str = "RssMeasurement") -> RssModel:
    """Deprecated: :class:`RssModel` with ``position_index`` (one RSS model; unmarked anchors ``batch + (T, m, dim)``
    were per step here, now ``per_step(anchors_m)``)."""
    warnings.warn("RssMeasurementModel is deprecated: use RssModel(anchors_m, channel, position_index=..., "
                  "anchor_sigma_m=..., tag_height_m=...) (per-step anchors as per_step(anchors_m))", DeprecationWarning,
                  stacklevel=2)
    if not isinstance(anchors_m, PerStep) and np.ndim(anchors_m) > 2:
        anchors_m = PerStep(anchors_m, "anchors_m")
    return RssModel(anchors_m, channel, position_index=position_index, anchor_sigma_m=anchor_sigma_m,
                    tag_height_m=tag_height_m, name=name)
