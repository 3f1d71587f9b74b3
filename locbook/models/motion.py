"""Kinematic motion models: nearly constant velocity (CV) and nearly constant acceleration (CA).

Per axis, a chain of ``order + 1`` derivatives (position, velocity[, acceleration]) propagates with
``F_axis = expm(dt * shift)`` and is driven by white noise on the next derivative, piecewise constant
over a step (the "discrete white noise" model, Bar-Shalom et al. 2001, Sec. 6.3.2):

    x_k = F x_{k-1} + G w_k,   w_k ~ N(0, q I_dim),   Q = q G G^T.

``noise="wiener"`` drives the highest derivative itself with white increments of variance ``q`` per step
(the "discrete Wiener process acceleration" model, Bar-Shalom et al. 2001, Sec. 6.3.3): ``G_axis = [dt^2/2, dt,
1]^T`` for CA, exactly the Q printed as Eq. (3.3) in Gudipati (2017).

``noise="isotropic"`` instead gives the full-rank per-step ``Q = q I`` that Dogan (2015) actually uses
(Eq. (3.24), q = 2.3e-5), which the Tichavsky form of the posterior CRLB needs (its Q must be invertible).
Any other Q can be passed to the filters directly.

For CV, ``G_axis = [dt^2/2, dt]^T``: the two-axis generalisation of B_KF in Eq. (9) of George and
Vadivukkarasi, whose Q is not printed (only tuned to minimise C) and whose B_KF drives both axes with one
scalar acceleration; the per-axis G is our choice. ``noise="continuous"`` gives the integrated
continuous white-noise form instead (``q`` then is a power spectral density).

State layout is explicit, because the sources differ:
- ``"derivative_major"``: ``[x, y, vx, vy]`` (document 003, Eq. (9));
- ``"axis_major"``: ``[x, vx, y, vy]`` or ``[x, vx, ax, y, vy, ay]`` (Dogan 2015, Eqs. (3.8), (3.10)).
"""
from __future__ import annotations

from dataclasses import dataclass
from math import factorial
from typing import TYPE_CHECKING

import numpy as np

from .._deprecation import keyword_rng
from .._validate import as_array, check_choice, check_scalar
from .base import MotionModel

__all__ = ["KinematicModel", "constant_velocity", "constant_acceleration", "STATE_LAYOUTS", "NOISE_MODELS",
           "reflect_into_box", "simulate_states", "HeadingKinematicModel", "HEADING_MODELS"]

STATE_LAYOUTS = ("derivative_major", "axis_major")
NOISE_MODELS = ("discrete", "continuous", "isotropic", "wiener")


class _LinearKinematics(MotionModel):
    """The motion-model protocol (:mod:`locbook.models.base`) of a model with constant matrices ``F`` and ``Q``."""

    linear = True
    checks_own_output = True
    if TYPE_CHECKING:   # each subclass computes its own
        @property
        def F(self) -> np.ndarray: ...
        @property
        def Q(self) -> np.ndarray: ...

    def apply(self, x, step: int = 0):
        return np.asarray(x, dtype=float) @ self.F.T

    def jacobian_at(self, x, step: int = 0):
        return self.F

    def covariance(self, step: int = 0):
        return self.Q


@dataclass(frozen=True)
class KinematicModel(_LinearKinematics):
    """Linear kinematic model with ``dim`` axes and ``order`` derivatives beyond position.

    Attributes
    ----------
    dt_s : step length (s; or one "step" where a source gives no time base).
    q : process-noise intensity: variance of the white driving noise per step (``noise="discrete"``,
        units m^2/s^(2 order + 2)) or its power spectral density (``noise="continuous"``).
    order : 1 for constant velocity, 2 for constant acceleration.
    dim : number of spatial axes.
    layout : ``"derivative_major"`` or ``"axis_major"`` (see module docstring).
    noise : ``"discrete"`` (Q = q G G^T), ``"wiener"`` (Q = q G G^T with the highest derivative's increment
        white), ``"continuous"`` or ``"isotropic"`` (Q = q I, units per state).
    """

    dt_s: float
    q: float
    order: int = 1
    dim: int = 2
    layout: str = "derivative_major"
    noise: str = "discrete"

    def __post_init__(self):
        check_scalar("dt_s", self.dt_s, gt=0)                    # NaN is rejected too (nan <= 0 is False)
        power = 2 * (self.order + 1)                             # the highest power of dt in F, G and Q
        try:
            big = float(self.dt_s) ** power
        except OverflowError:
            big = np.inf
        if not np.isfinite(big):
            raise ValueError(f"dt_s = {self.dt_s!r} s is too long a step: dt_s**{power} (in Q) overflows float64; a "
                             f"step is at most about {np.finfo(float).max ** (1 / power):.3g} s (an epoch window in "
                             "another time unit?)")
        check_scalar("process noise q", self.q, ge=0)
        if self.order not in (1, 2):
            raise ValueError(f"order must be 1 (constant velocity) or 2 (constant acceleration), got {self.order}")
        check_scalar("dim", self.dim, ge=1, integer=True)
        check_choice("layout", self.layout, STATE_LAYOUTS)
        check_choice("noise", self.noise, NOISE_MODELS)

    @property
    def n_state(self) -> int:
        return self.dim * (self.order + 1)

    def _axis_blocks(self):
        k, dt = self.order + 1, self.dt_s
        f = np.array([[dt ** (j - i) / factorial(j - i) if j >= i else 0.0 for j in range(k)] for i in range(k)])
        g = np.array([[dt ** (k - i) / factorial(k - i)] for i in range(k)])
        if self.noise == "wiener":                # the highest derivative takes white increments
            g = np.array([[dt ** (k - 1 - i) / factorial(k - 1 - i)] for i in range(k)])
        if self.noise in ("discrete", "wiener"):
            q = self.q * (g @ g.T)
        elif self.noise == "isotropic":
            q = self.q * np.eye(k)
        else:
            # integral of F(t) e e^T F(t)^T over one step, e the unit vector of the highest derivative
            q = np.array([[self.q * dt ** (2 * k - 1 - i - j) / ((2 * k - 1 - i - j) * factorial(k - 1 - i)
                                                                * factorial(k - 1 - j))
                           for j in range(k)] for i in range(k)])
        return f, g, q

    def _permutation(self) -> np.ndarray:
        """Index map from axis-major order to this layout: state[layout] = axis_major[perm]."""
        k = self.order + 1
        if self.layout == "axis_major":
            return np.arange(self.n_state)
        return np.array([axis * k + deriv for deriv in range(k) for axis in range(self.dim)])

    def _assemble(self, block):
        """Square per-axis block -> full matrix in this layout."""
        full = np.kron(np.eye(self.dim), block)
        perm = self._permutation()
        return full[np.ix_(perm, perm)]

    @property
    def F(self) -> np.ndarray:
        """Transition matrix (n_state, n_state)."""
        return self._assemble(self._axis_blocks()[0])

    @property
    def G(self) -> np.ndarray:
        """Noise gain (n_state, dim): ``[dt^2/2, dt]`` per axis for CV (``[dt, 1]`` with ``noise="wiener"``)."""
        full = np.kron(np.eye(self.dim), self._axis_blocks()[1])
        return full[self._permutation()]

    @property
    def Q(self) -> np.ndarray:
        """Process-noise covariance (n_state, n_state)."""
        return self._assemble(self._axis_blocks()[2])

    def index(self, derivative: int) -> np.ndarray:
        """State indices of a derivative (0 position, 1 velocity, 2 acceleration), one per axis."""
        if not 0 <= derivative <= self.order:
            raise ValueError(f"derivative {derivative} not in this order-{self.order} model")
        k = self.order + 1
        if self.layout == "axis_major":
            return np.array([axis * k + derivative for axis in range(self.dim)])
        return np.arange(self.dim) + derivative * self.dim

    @property
    def position_index(self) -> np.ndarray:
        return self.index(0)

    def noise_factor(self, step: int = 0):
        """``sqrt(q) G`` for ``noise="discrete"`` or ``"wiener"`` (``Q = q G G^T`` exactly: ``dim`` draws per state);
        the protocol's symmetric root otherwise; None for ``q = 0``."""
        if not np.any(self.Q):
            return None
        return np.sqrt(self.q) * self.G if self.noise in ("discrete", "wiener") else super().noise_factor(step)

    def mirrored_index(self) -> np.ndarray:
        """Velocity (and acceleration) ``(order, dim)``: a mirror reflection of the position reverses them."""
        return np.stack([self.index(k) for k in range(1, self.order + 1)]).astype(np.int64)

    @property
    def velocity_index(self) -> np.ndarray:
        return self.index(1)

    @property
    def acceleration_index(self) -> np.ndarray:
        return self.index(2)

    def derivative_measurement_matrix(self, derivative: int) -> np.ndarray:
        """H picking one derivative on every axis (0: position fixes; 2: an accelerometer as a linear
        measurement of the acceleration states, Dogan Eq. (3.18))."""
        h = np.zeros((self.dim, self.n_state))
        h[np.arange(self.dim), self.index(derivative)] = 1.0
        return h

    def position(self, state):
        """Positions ``(..., dim)`` from states ``(..., n_state)``."""
        return np.asarray(state)[..., self.position_index]

    def position_measurement_matrix(self) -> np.ndarray:
        """H with ``z = position + v`` (George and Vadivukkarasi do not print H; their Z_k is the
        2-D fix of Eq. (8), so H = [[1,0,0,0],[0,1,0,0]])."""
        return self.derivative_measurement_matrix(0)

    def state_from(self, position, velocity=None, acceleration=None):
        """Assemble states ``(..., n_state)`` from per-derivative arrays ``(..., dim)`` (missing = 0)."""
        position = as_array("position", position, min_ndim=1, trailing=(self.dim,))
        if acceleration is not None and self.order < 2:
            raise ValueError("acceleration given to a constant-velocity (order 1) model")
        out = np.zeros(position.shape[:-1] + (self.n_state,))
        for deriv, (name, value) in enumerate((("position", position), ("velocity", velocity),
                                               ("acceleration", acceleration))):
            if value is not None and deriv <= self.order:
                value = as_array(name, value, trailing=(self.dim,))
                if np.broadcast_shapes(value.shape, position.shape) != position.shape:
                    raise ValueError(f"{name} of shape {value.shape} does not fit positions of shape {position.shape}")
                out[..., self.index(deriv)] = value
        return out


def constant_velocity(dt_s: float, q: float, dim: int = 2, layout: str = "derivative_major",
                      noise: str = "discrete") -> KinematicModel:
    """Nearly constant velocity model (document 003 Eq. (9); Dogan Eq. (3.9)).

    Examples
    --------
    >>> import numpy as np
    >>> import locbook as lb
    >>> cv = lb.constant_velocity(0.5, 0.1, dim=1)          # dt = 0.5 s; state (position, velocity)
    >>> print(cv.F)
    [[1.  0.5]
     [0.  1. ]]
    >>> print(cv.Q)                                          # q G G^T, G = [dt^2/2, dt] (noise="discrete")
    [[0.0015625 0.00625  ]
     [0.00625   0.025    ]]
    """
    return KinematicModel(dt_s, q, order=1, dim=dim, layout=layout, noise=noise)


def constant_acceleration(dt_s: float, q: float, dim: int = 2, layout: str = "axis_major",
                          noise: str = "discrete") -> KinematicModel:
    """Nearly constant acceleration model (Dogan Eq. (3.11), Gudipati Sec. 3.2)."""
    return KinematicModel(dt_s, q, order=2, dim=dim, layout=layout, noise=noise)


HEADING_MODELS = ("yaw_rate", "literal_gudipati2017")


@dataclass(frozen=True)
class HeadingKinematicModel(_LinearKinematics):
    """Planar nearly-constant-acceleration motion with two angular states (Gudipati 2017, Sec. 3.2).

    The thesis prints an 8-D state ``[x, y, vx, vy, ax, ay, theta_x, theta_y]`` but 6 x 6 matrices A (3.2) and
    Q (3.3) (Sec. 3.2). The 6-D block is :class:`KinematicModel` (order 2, derivative-major as
    printed, ``noise="wiener"``: ``Q = q G G^T`` with ``G = [dt^2/2, dt, 1]`` per axis, Eq. (3.3); ``q`` is the
    variance of the acceleration increment per step, (m/s^2)^2). The angular block is

    - ``heading="yaw_rate"`` (default): heading ``psi`` and yaw rate ``omega``, ``psi_k = psi_{k-1} + omega dt``,
      ``omega`` a random walk with increments of variance ``q_angular`` (rad/s)^2 per step (the same form:
      ``Q = q_angular g g^T``, ``g = [dt, 1]``). Planar motion has one rotation axis; the gyroscope measures
      ``omega`` and the heading rotates body-frame accelerations into the world frame.
    - ``heading="literal_gudipati2017"`` (flagged): ``theta_x``, ``theta_y`` "angular velocities along x and y" as
      printed, each a random walk (A block ``I_2``, Q block ``q_angular dt I_2``).

    State indices: position 0-1, velocity 2-3, acceleration 4-5, angular 6-7 (``heading_index``,
    ``yaw_rate_index`` for ``"yaw_rate"``).
    """

    dt_s: float
    q: float
    q_angular: float
    heading: str = "yaw_rate"

    def __post_init__(self):
        check_scalar("q_angular", self.q_angular, ge=0)
        check_choice("heading", self.heading, HEADING_MODELS)
        KinematicModel(self.dt_s, self.q, order=2, dim=2)           # checks dt_s and q

    @property
    def translation(self) -> KinematicModel:
        """The 6-D constant-acceleration block of Eqs. (3.2)-(3.3)."""
        return KinematicModel(self.dt_s, self.q, order=2, dim=2, layout="derivative_major", noise="wiener")

    n_state = 8
    position_index = np.array([0, 1])
    velocity_index = np.array([2, 3])
    acceleration_index = np.array([4, 5])
    angular_index = np.array([6, 7])
    heading_index = 6
    yaw_rate_index = 7

    def _angular_blocks(self):
        dt = self.dt_s
        if self.heading == "yaw_rate":
            g = np.array([[dt], [1.0]])
            return np.array([[1.0, dt], [0.0, 1.0]]), self.q_angular * (g @ g.T)
        return np.eye(2), self.q_angular * dt * np.eye(2)

    @property
    def F(self) -> np.ndarray:
        out = np.zeros((8, 8))
        out[:6, :6] = self.translation.F
        out[6:, 6:] = self._angular_blocks()[0]
        return out

    @property
    def Q(self) -> np.ndarray:
        out = np.zeros((8, 8))
        out[:6, :6] = self.translation.Q
        out[6:, 6:] = self._angular_blocks()[1]
        return out

    def position(self, state):
        return np.asarray(state)[..., self.position_index]

    def position_measurement_matrix(self) -> np.ndarray:
        """H = [I_2 0] (a position fix as the measurement: our reading of the
        thesis's "linear Kalman filter", whose measurement model Sec. 5.3 does not state)."""
        h = np.zeros((2, 8))
        h[[0, 1], [0, 1]] = 1.0
        return h

    def state_from(self, position, velocity=None, acceleration=None, angular=None):
        """States ``(..., 8)`` from ``(..., 2)`` arrays (missing = 0); ``angular`` is ``(psi, omega)`` or
        ``(theta_x, theta_y)``."""
        position = as_array("position", position, min_ndim=1, trailing=(2,))
        out = np.zeros(position.shape[:-1] + (8,))
        out[..., :2] = position
        for idx, name, value in ((self.velocity_index, "velocity", velocity),
                                 (self.acceleration_index, "acceleration", acceleration),
                                 (self.angular_index, "angular", angular)):
            if value is not None:
                out[..., idx] = as_array(name, value, trailing=(2,))
        return out


def reflect_into_box(position_m, lower_m, upper_m):
    """Fold positions ``(..., dim)`` back into the box ``[lower, upper]`` by mirror reflection at its
    walls (repeatedly, for steps longer than the box). Used for targets and particles confined to a room
    (Ozkaya 2011, Sec. 7.2 simulations: the boundary handling is not stated; reflection is the assumed default of
    the declared reading ``wall_handling``, whose alternatives clip at the wall or redraw the step).
    """
    lower = as_array("lower_m", lower_m)
    width = as_array("upper_m", upper_m) - lower
    if np.any(width <= 0):
        raise ValueError(f"the box needs upper > lower on every axis, got {lower_m} and {upper_m}")
    if lower.shape != width.shape or lower.ndim > 1:
        raise ValueError(f"lower_m and upper_m must be corners of the same dimension, got {lower_m} and {upper_m}")
    position_m = as_array("position_m", position_m, trailing=lower.shape)
    folded = np.mod(position_m - lower, 2.0 * width)
    return lower + np.where(folded > width, 2.0 * width - folded, folded)


@keyword_rng(4)
def simulate_states(F, Q, initial_state, n_steps: int, *, rng: np.random.Generator):
    """Sample trajectories of ``x_k = F x_{k-1} + w_k``, ``w_k ~ N(0, Q)``: ``(..., n_steps + 1, n)`` from initial
    states ``(..., n)`` (the "trajectories that exactly follow the constant acceleration model" of Dogan's
    Sec. 4.1.2). ``Q`` may be singular (it is factored by eigen-decomposition). ``rng`` is keyword-only (the
    positional form ``(F, Q, initial_state, n_steps, rng)`` is deprecated)."""
    F = as_array("F", F, ndim=2)
    n = F.shape[0]
    if F.shape != (n, n):
        raise ValueError(f"F must be square (n, n), got {F.shape}")
    Q = as_array("Q", Q, ndim=2)
    if Q.shape != (n, n):
        raise ValueError(f"Q must have shape ({n}, {n}) like F, got {Q.shape}")
    x = as_array("initial_state", initial_state, trailing=(n,))
    check_scalar("n_steps", n_steps, ge=0, integer=True)
    w, v = np.linalg.eigh(Q)
    if w.min(initial=0.0) < -1e-9 * max(1.0, w.max(initial=0.0)):
        raise ValueError(f"Q must be positive semi-definite, its smallest eigenvalue is {w.min()}")
    root = v * np.sqrt(np.clip(w, 0.0, None))              # Q = root root^T
    noise = rng.standard_normal((n_steps,) + x.shape) @ root.T
    out = np.empty(x.shape[:-1] + (n_steps + 1, x.shape[-1]))
    out[..., 0, :] = x
    for k in range(n_steps):
        x = x @ F.T + noise[k]
        out[..., k + 1, :] = x
    return out
