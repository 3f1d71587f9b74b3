"""The range measurement model (RTT / ToA ranges) on the measurement-model protocol (:mod:`locbook.models.base`).

Anchor ``j`` at ``a_j`` measures its distance to the tag at ``p`` (the ranges helper's reading kind,
:mod:`locbook.data.ranges`):

    z_j = || [p, h] - a_j || + v_j,   v_j ~ N(0, sigma_j^2),   independently across anchors,

with ``h`` the tag's known height for anchors ``(m, 3)`` (x, y, height; the tag in the plane ``z = h``), or the
distance in the plane for anchors ``(m, 2)`` (a 2-D problem; anchors ``(m, dim)`` without a height give the distance
in the positions' own space). Its Jacobian is the unit vector ``dz_j/dp = (p - a_j)_plan / d_j`` (0 at ``d_j = 0``,
where the distance has no derivative: a subgradient), and its Fisher information of the position ``J = sum_j u_j u_j^T
/ sigma_j^2`` (:func:`locbook.bounds.crlb.range_crlb_m`).

``sigma_m``: a scalar, per anchor ``(m,)``, per run ``batch + (1 or m,)``, or with ``per_step_sigma=True`` per step
``batch + (T, 1 or m)`` (the reported std of each epoch's range, e.g. :meth:`locbook.data.dataset.Dataset.ranges`; a
time axis of length 1 holds for every step). Every sigma is finite and positive (a missing range is a NaN reading,
whose sigma is not used: give any positive value there).

Shapes (points form, :mod:`locbook.models.base`): states ``batch + (K, n)``; ``position_index`` names their position
components (the Kalman family's states), None for a model of positions (the states are the positions: the particle
and grid filters). Every filter takes it with no switch on its type: the EKF through :meth:`RangeModel.innovation`,
the UKF through :meth:`~RangeModel.mean` and :meth:`~RangeModel.covariance`, the particle and grid filters through
:meth:`~RangeModel.log_likelihood` (their numpy paths; the compiled kernels know the RSS and inertial models only).
"""
from __future__ import annotations

import numpy as np

from .._linalg import _LOG_2PI
from .._validate import as_array, check_scalar
from .base import MeasurementModel

__all__ = ["RangeModel"]


class RangeModel(MeasurementModel):
    """Ranges ``z_j = |[p, h] - a_j| + v_j``, ``v_j ~ N(0, sigma_j^2)`` (module docstring).

    ``anchors_m``: ``(m, dim)``, or ``(m, 3)`` with ``tag_height_m`` (then positions are 2-D and distances 3-D).
    ``sigma_m``: scalar, ``(m,)``, ``batch + (1 or m,)``, or per step ``batch + (T, 1 or m)`` with
    ``per_step_sigma=True``. ``position_index``: the states' position components (``dim`` indices; None: the states
    are the positions)."""

    checks_own_output = True

    def __init__(self, anchors_m, sigma_m, *, tag_height_m: float | None = None, position_index=None,
                 per_step_sigma: bool = False, name: str = "range"):
        self.name = name
        anchors = as_array(f"{name}: anchors_m", anchors_m, ndim=2)
        if tag_height_m is not None:
            check_scalar("tag_height_m", tag_height_m)
            if anchors.shape[1] != 3:
                raise ValueError(f"{name}: anchors_m must be (m, 3) (x, y, height) with tag_height_m (the tag moves in "
                                 f"the plane z = tag_height_m), got {anchors.shape}")
        if anchors.shape[0] < 1 or anchors.shape[1] < 1:
            raise ValueError(f"{name}: anchors_m must have shape (m, dim), got {anchors.shape}")
        self.anchors_m, self.tag_height_m = anchors, None if tag_height_m is None else float(tag_height_m)
        if not isinstance(per_step_sigma, (bool, np.bool_)):
            raise ValueError(f"{name}: per_step_sigma must be True or False, got {per_step_sigma!r}")
        self.per_step_sigma = bool(per_step_sigma)
        sigma = as_array(f"{name}: sigma_m", sigma_m, min_ndim=2 if per_step_sigma else 0)
        if sigma.ndim and sigma.shape[-1] not in (1, self.n_anchors):
            raise ValueError(f"{name}: sigma_m must be a scalar or end in (1,) or ({self.n_anchors},) "
                             f"(one per anchor), got shape {sigma.shape}")
        if not np.all(sigma > 0):
            raise ValueError(f"{name}: sigma_m must be positive (m): a range's standard deviation; "
                             "a missing range is a NaN reading, whose sigma is not used "
                             "(give any positive value there)")
        self.sigma_m = sigma
        if position_index is not None:
            idx = np.asarray(position_index)
            if (idx.dtype == object or (idx.size and not np.issubdtype(idx.dtype, np.integer))
                    or idx.shape != (self.dim,)):
                raise ValueError(f"{name}: position_index must hold {self.dim} integer state indices (one per axis of "
                                 f"the positions), got {position_index!r}")
            position_index = idx
        self.position_index = position_index

    # -- shapes ------------------------------------------------------------------------------------------
    @property
    def n_anchors(self) -> int:
        return self.anchors_m.shape[0]

    @property
    def n_readings(self) -> int:
        return self.n_anchors

    @property
    def dim(self) -> int:
        """The dimension of the positions (the anchors' minus the height column)."""
        return self.anchors_m.shape[1] - (self.tag_height_m is not None)

    @property   # the base's class default None, a read-only property here: the model is of positions
    def position_dim(self) -> int:  # type: ignore[override]
        return self.dim

    @property
    def state_position_index(self) -> np.ndarray:
        return np.arange(self.dim) if self.position_index is None else self.position_index

    @property
    def steps(self) -> int | None:
        """The steps a per-step sigma holds (None: one sigma for every step)."""
        if not self.per_step_sigma or self.sigma_m.shape[-2] == 1:
            return None
        return self.sigma_m.shape[-2]

    def sigma_at(self, step: int = 0) -> np.ndarray:
        """sigma at ``step``: a scalar, ``(1 or m,)`` or ``batch + (1 or m,)``."""
        if isinstance(step, (bool, np.bool_)) or not isinstance(step, (int, np.integer)) or step < 0 or (
                self.steps is not None and step >= self.steps):
            raise ValueError(f"{self.name}: step must be an integer in [0, {self.steps or 'inf'}), got {step!r}")
        s = self.sigma_m
        return s[..., min(step, s.shape[-2] - 1), :] if self.per_step_sigma else s

    def _sigma_points(self, step: int):
        """sigma at ``step`` broadcasting against points-form readings ``batch + (K, m)``."""
        s = self.sigma_at(step)
        return s[..., None, :] if s.ndim >= 2 else s

    # -- the model --------------------------------------------------------------------------------------
    def position_offsets(self, positions_m):
        """``(p - a_j)`` ``(..., m, k)`` of positions ``(..., dim)`` (the tag height appended with 3-D anchors)."""
        p = np.asarray(positions_m, dtype=float)
        if self.tag_height_m is not None:
            p = np.concatenate([p, np.full(p.shape[:-1] + (1,), self.tag_height_m)], axis=-1)
        return p[..., None, :] - self.anchors_m

    def unit_vectors(self, positions_m):
        """``(distances (..., m), u_j (..., m, dim))`` at positions ``(..., dim)``: ``u_j = (p - a_j)_plan / d_j``,
        the gradient of each distance (0 where ``d_j = 0``)."""
        diff = self.position_offsets(positions_m)
        d = np.sqrt(np.einsum("...i,...i->...", diff, diff))
        with np.errstate(invalid="ignore", divide="ignore"):
            unit = np.where(d[..., None] > 0, diff / np.where(d > 0, d, 1.0)[..., None], 0.0)
        return d, unit[..., :self.dim]

    def _distance_gradient(self, x):
        return self.unit_vectors(np.asarray(x, dtype=float)[..., self.state_position_index])

    def mean(self, x, *, step: int = 0):
        """``h(x) = |[p, h] - a_j|`` ``batch + (K, m)`` at states ``batch + (K, n)`` (any leading axes)."""
        return self._distance_gradient(x)[0]

    def jacobian(self, x, *, step: int = 0):
        """``dh_j/dx`` ``batch + (K, m, n)``: the unit vector ``(p - a_j)_plan / d_j`` in the position components, 0
        elsewhere (and at ``d_j = 0``)."""
        x = np.asarray(x, dtype=float)
        unit = self._distance_gradient(x)[1]
        H = np.zeros(unit.shape[:-1] + (x.shape[-1],))
        H[..., self.state_position_index] = unit
        return H

    def covariance(self, x, *, step: int = 0):
        """``diag(sigma_j^2)`` broadcasting to ``batch + (K, m, m)``."""
        var = np.broadcast_to(np.square(self._sigma_points(step)),
                              np.broadcast_shapes(np.shape(self._sigma_points(step)), (self.n_anchors,)))
        return var[..., :, None] * np.eye(self.n_anchors)

    def innovation(self, x, z, *, step: int = 0):
        """The EKF's linearisation at states ``x`` ``batch + (n,)``: ``z - h(x)`` (0 where a range is missing), the
        Jacobian ``batch + (m, n)`` and ``R = diag(sigma^2)``."""
        x = np.asarray(x, dtype=float)
        d, unit = self._distance_gradient(x)
        H = np.zeros(unit.shape[:-1] + (x.shape[-1],))
        H[..., self.state_position_index] = unit
        valid = np.isfinite(z)
        var = np.broadcast_to(np.square(self.sigma_at(step)), z.shape)
        return np.where(valid, z, d) - d, H, var[..., :, None] * np.eye(self.n_anchors)

    def log_likelihood(self, z, x, *, step: int = 0):
        """``sum_j log N(z_j; h_j(x), sigma_j^2)`` over the ranges present ``batch + (K,)`` (readings ``batch + (m,)``,
        NaN = not measured, left out; none present gives 0)."""
        return self._log_likelihood(z, x, step, constant=True)

    def relative_log_likelihood(self, z, x, *, step: int = 0):
        """:meth:`log_likelihood` without its state-free constant (the particle and grid filters' weights)."""
        return self._log_likelihood(z, x, step, constant=False)

    def _log_likelihood(self, z, x, step: int, constant: bool):
        z = np.asarray(z, dtype=float)[..., None, :]
        valid = np.isfinite(z)
        sigma = self._sigma_points(step)
        w = np.where(valid, (np.where(valid, z, 0.0) - self.mean(x, step=step)) / sigma, 0.0)
        out = -0.5 * np.einsum("...m,...m->...", w, w)
        if constant:
            log_norm = np.broadcast_to(np.log(sigma) + 0.5 * _LOG_2PI, np.broadcast_shapes(np.shape(sigma), w.shape))
            out = out - np.where(valid, log_norm, 0.0).sum(axis=-1)
        return out

    def independent_readings(self) -> bool:
        return True

    def noise(self):
        if self.per_step_sigma:
            raise ValueError(f"{self.name}: a per-step sigma is not fitted; give fit_R=None for this stream")
        return "variances", np.square(self.sigma_m)

    def with_noise(self, value) -> "RangeModel":
        out = object.__new__(RangeModel)
        out.__dict__.update(self.__dict__)
        out.sigma_m = np.sqrt(np.asarray(value, dtype=float))
        return out

    def run_shapes(self) -> list:
        core = 1 + self.per_step_sigma
        shape = self.sigma_m.shape
        return [(f"{self.name}.sigma_m", shape[:-core] if len(shape) >= core else ())]

    def check_readings(self, z, n_state=None) -> None:
        super().check_readings(z, n_state)
        if self.per_step_sigma and self.sigma_m.shape[-2] not in (1, np.shape(z)[-2]):
            raise ValueError(f"{self.name}: sigma_m per step must have shape batch + (T, 1 or m) with T = "
                             f"{np.shape(z)[-2]} steps (or 1), got {self.sigma_m.shape}")
        if n_state is not None:
            if self.position_index is None:
                raise ValueError(f"{self.name} in a Kalman-family stream is a model of states: give "
                                 f"RangeModel(..., position_index=...) "
                                 f"({self.dim} state indices of the {n_state}-state)")
            if np.max(self.position_index) >= n_state:
                raise ValueError(f"{self.name}: position_index {self.position_index} is outside the {n_state}-state")

    def __repr__(self) -> str:
        return (f"RangeModel({self.n_anchors} anchors of dim {self.anchors_m.shape[1]}, sigma_m of shape "
                f"{self.sigma_m.shape}{', per step' if self.per_step_sigma else ''}, tag_height_m={self.tag_height_m})")
