"""Nonparametric Bayes filters for RSSI tracking: grid-based Bayes (Markov localization) and particle filters.

Both run the recursion of Ozkaya (2011), Eqs. (4.1)-(4.5),

    p(L_t | s_1:t)  ~  p(s_t | L_t)  integral p(L_t | L_t-1) p(L_t-1 | s_1:t-1) dL_t-1,

with the RSS likelihood of independent readers (Sec. 5, Eq. (5.11) sign corrected; note 004, section 3.1)

    p(s | L) = prod_j N(s_j; alpha_j - 10 n_j log10(d_j(L)/d0) - nW_j(L) WAF, sigma^2),

and the process model ``L_t = L_t-1 + v_t + N(0, D^2 I)`` (Eq. (4.2); ``v`` a known velocity, D = inf a
uniform transition). Everything is vectorized over a leading Monte-Carlo axis ``R`` (runs) and over cells or
particles; the only Python loop is over time steps.

Conventions: ``rss_dbm`` has shape ``(R, T, m)``. At step 0 the prior is uniform over the region (or
concentrated at a known initial location) and no prediction is made; from step 1 on each step predicts,
then updates. Estimates: MMSE (posterior mean, Eq. (4.8)) and MAP (Eq. (4.9): the most probable cell, or
the highest-weight particle, since a particle set has no density).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from .._validate import as_array, check_choice, check_scalar
from ..models.channel import log_distance_mean_dbm, pairwise_distance_m, wall_crossings
from ..models.motion import reflect_into_box

__all__ = [
    "RssMeasurementModel", "GridFilterResult", "grid_bayes_filter", "grid_transition_matrix",
    "ParticleFilterResult", "particle_filter", "systematic_resample", "effective_sample_size",
    "RESAMPLING_CDFS", "WEIGHT_SMOOTHINGS", "GRID_TRANSITIONS",
]

RESAMPLING_CDFS = ("standard", "literal_004")
WEIGHT_SMOOTHINGS = ("none", "sqrt", "sqrt_corrected")


@dataclass(frozen=True)
class RssMeasurementModel:
    """Log-distance RSS likelihood with walls, per-reader and optionally per-run-and-step parameters.

    ``ref_power_dbm`` (alpha) and ``path_loss_exp`` (n) are scalars, per-reader arrays ``(m,)``, or
    ``(R, T, m)`` arrays (online calibration gives new values every step). ``sigma_db`` is a scalar, per-reader
    ``(m,)`` (a per-anchor fit), or ``(R, T)`` (the pooled online sigma of Eq. (6.7)). ``walls_m`` are wall segments ``(W, 2, 2)``.
    Distances below ``min_distance_m`` are clipped so that log10(0) never occurs (note 004, section 4.3).
    ``tag_height_m``: the readers are ``(m, 3)`` (x, y, height), the tag moves in the plane ``z = tag_height_m``
    and distances are 3-D (positions, cells, particles and walls stay 2-D).
    """

    readers_m: np.ndarray
    ref_power_dbm: float | np.ndarray
    path_loss_exp: float | np.ndarray
    sigma_db: float | np.ndarray
    wall_attenuation_db: float = 0.0
    walls_m: np.ndarray | None = None
    ref_distance_m: float = 1.0
    min_distance_m: float = 0.1
    tag_height_m: float | None = None

    def __post_init__(self):
        if self.tag_height_m is not None:
            check_scalar("tag_height_m", self.tag_height_m)
        readers = as_array("readers_m", self.readers_m, ndim=2,
                           trailing=(None, 2 if self.tag_height_m is None else 3))
        m = readers.shape[0]
        for name in ("ref_power_dbm", "path_loss_exp"):      # NaN parameters are errors, never "not heard"
            value = as_array(name, getattr(self, name))
            if value.ndim not in (0, 1, 3) or (value.ndim and value.shape[-1] != m):
                raise ValueError(f"{name} must be a scalar, ({m},) or (R, T, {m}), got shape {value.shape}")
        sigma = as_array("sigma_db", self.sigma_db)
        if sigma.ndim not in (0, 1, 2) or (sigma.ndim == 1 and sigma.shape != (m,)) or np.any(sigma < 0):
            raise ValueError(f"sigma_db must be a non-negative scalar, ({m},) (one per reader) or (R, T) array, "
                             f"got {self.sigma_db!r}")
        if np.any(np.asarray(self.path_loss_exp) <= 0):
            raise ValueError(f"path_loss_exp must be positive, got {self.path_loss_exp!r}")
        check_scalar("wall_attenuation_db", self.wall_attenuation_db)
        check_scalar("ref_distance_m", self.ref_distance_m, gt=0)
        check_scalar("min_distance_m", self.min_distance_m, gt=0)
        if self.walls_m is not None:
            as_array("walls_m", np.reshape(self.walls_m, (-1, 2, 2)))

    def _check_step(self, step) -> None:
        """``step`` must index the per-step parameters ``(R, T, m)`` / ``(R, T)`` (no negative wrap-around)."""
        n_steps = [np.shape(v)[1] for v in (self.ref_power_dbm, self.path_loss_exp) if np.ndim(v) == 3]
        n_steps += [np.shape(self.sigma_db)[1]] if np.ndim(self.sigma_db) == 2 else []
        if isinstance(step, (bool, np.bool_)) or not isinstance(step, (int, np.integer)) or step < 0 or (
                n_steps and step >= min(n_steps)):
            raise ValueError(f"step must be an integer in [0, {min(n_steps) if n_steps else 'inf'}), got {step!r}")

    def _runs(self):
        """The number of runs of per-run-and-step parameters (None when every parameter is shared)."""
        runs = {np.shape(v)[0] for v in (self.ref_power_dbm, self.path_loss_exp) if np.ndim(v) == 3}
        runs |= {np.shape(self.sigma_db)[0]} if np.ndim(self.sigma_db) == 2 else set()
        if len(runs) > 1:
            raise ValueError(f"per-run parameters disagree on the number of runs: {sorted(runs)}")
        return runs.pop() if runs else None

    @staticmethod
    def _per_step(value, step: int, per_reader: bool):
        value = np.asarray(value, dtype=float)
        if per_reader:
            return value[:, step, None, :] if value.ndim == 3 else value          # (R, 1, m) or (m,)
        return value[:, step, None] if value.ndim == 2 else value                   # (R, 1) or scalar

    def mean_rss_dbm(self, positions_m, step: int = 0):
        """Mean RSS at positions ``(P, 2)`` or ``(R, P, 2)`` -> ``(R or 1, P, m)``."""
        positions_m = as_array("positions_m", positions_m, trailing=(None, 2))
        if positions_m.ndim not in (2, 3):
            raise ValueError(f"positions_m must have shape (P, 2) or (R, P, 2), got {positions_m.shape}")
        self._check_step(step)
        plan = np.asarray(self.readers_m, dtype=float)[:, :2]
        distance = pairwise_distance_m(positions_m, plan)
        if self.tag_height_m is not None:
            vertical = np.asarray(self.readers_m, dtype=float)[:, 2] - self.tag_height_m
            distance = np.sqrt(distance**2 + vertical**2)
        mean = log_distance_mean_dbm(distance,
                                     self._per_step(self.ref_power_dbm, step, True),
                                     self._per_step(self.path_loss_exp, step, True),
                                     ref_distance_m=self.ref_distance_m, min_distance_m=self.min_distance_m)
        if self.walls_m is not None and self.wall_attenuation_db != 0.0:
            mean = mean - self.wall_attenuation_db * wall_crossings(positions_m, plan, self.walls_m)
        return mean if mean.ndim == 3 else mean[None]

    def log_likelihood(self, rss_dbm, positions_m, step: int = 0):
        """``log p(s | L)`` up to a constant per run, ``rss_dbm (R, m)``, positions ``(P, 2)`` or ``(R, P, 2)``
        -> ``(R, P)``. Readers with a NaN RSS (no packet: not heard) are left out of the product; a run where no
        reader heard anything gets a flat likelihood (that step is a prediction only). The model's parameters
        are checked finite at construction, so only readings can be missing."""
        m = np.shape(self.readers_m)[0]
        rss = as_array("rss_dbm", rss_dbm, ndim=2, trailing=(m,), nan_ok=True)
        if np.ndim(positions_m) == 3 and np.shape(positions_m)[0] != rss.shape[0]:
            raise ValueError(f"positions_m per run {np.shape(positions_m)} must have the {rss.shape[0]} runs of rss_dbm "
                             f"{rss.shape} on its first axis (no silent broadcasting)")
        runs = self._runs()
        if runs is not None and runs != rss.shape[0]:
            raise ValueError(f"the model's per-run parameters have {runs} runs, rss_dbm has {rss.shape[0]} "
                             f"(shape {rss.shape})")
        resid = rss[:, None, :] - self.mean_rss_dbm(positions_m, step)
        resid = np.where(np.isnan(rss)[:, None, :], 0.0, resid)
        sigma = self._per_step(self.sigma_db, step, False)
        if np.any(np.asarray(sigma) <= 0):     # a model with sigma 0 can give mean RSS, not a likelihood
            raise ValueError(f"the likelihood needs sigma_db > 0, got {self.sigma_db!r} at step {step}")
        if np.ndim(sigma) == 1:                # one sigma per reader
            resid = resid / sigma
            return -0.5 * np.einsum("rpm,rpm->rp", resid, resid)
        return -0.5 * np.einsum("rpm,rpm->rp", resid, resid) / np.square(sigma)


def _check_inputs(rss_dbm, model: RssMeasurementModel, *, cells_m=None):
    """``rss_dbm (R, T, m)`` against the model's ``m`` readers (NaN = not heard); cells ``(C, 2)``."""
    if not isinstance(model, RssMeasurementModel):
        raise ValueError(f"model must be an RssMeasurementModel, got {type(model).__name__}")
    m = np.shape(model.readers_m)[0]
    rss_dbm = as_array("rss_dbm", rss_dbm, ndim=3, nan_ok=True)
    if rss_dbm.shape[-1] != m:
        raise ValueError(f"rss_dbm must have shape (runs, steps, {m}) for the model's {m} readers, got {rss_dbm.shape}")
    if cells_m is not None:
        cells_m = as_array("cells_m", cells_m, ndim=2, trailing=(None, 2))
    runs = model._runs()
    if runs is not None and runs != rss_dbm.shape[0]:
        raise ValueError(f"the model's per-run parameters have {runs} runs, rss_dbm has {rss_dbm.shape[0]}")
    if rss_dbm.shape[1]:
        model._check_step(rss_dbm.shape[1] - 1)     # per-step parameters must cover every step
    return rss_dbm, cells_m


def _first_collapse(dead_step) -> tuple[int, int]:
    """(run, step) of the earliest collapse (the lowest run among those of the earliest step)."""
    steps = np.where(dead_step >= 0, dead_step, np.iinfo(np.int64).max)
    run = int(np.argmin(steps))
    return run, int(dead_step[run])


def _collapse_error(dead_step, what: str, detail=None) -> ValueError:
    """The error when every run collapsed: ``what`` names the likelihood or readings (the argument), ``detail(run,
    step)`` may describe that run's input at that step."""
    run, step = _first_collapse(dead_step)
    extra = detail(run, step) if detail is not None else ""
    return ValueError(f"{what} collapsed in every run ({dead_step.size} of {dead_step.size}): -inf for every particle "
                      f"(or cell), or NaN or +inf, so no weight can be normalised; first at step {step} (run {run})"
                      f"{extra}. Nothing can be estimated: check the units and the model (a reading of 1e300 dBm, "
                      "or mW given as dBm, overflows the Gaussian likelihood)")


def _warn_collapse(dead, dead_step, function: str, what: str, detail=None) -> None:
    """One RuntimeWarning when some runs (not all) collapsed: their number and the first (run, step)."""
    run, step = _first_collapse(dead_step)
    extra = detail(run, step) if detail is not None else ""
    warnings.warn(f"{function}: {what} collapsed in {int(dead.sum())} of {dead.size} runs (first: run {run}, step "
                  f"{step}{extra}); those runs are NaN from their step on (see degenerate, degenerate_step), the "
                  "others are unaffected", RuntimeWarning, stacklevel=3)


def _reading_detail(rss_dbm):
    """``detail(run, step)`` for the collapse messages: that run's readings at that step."""
    return lambda run, step: (f"; rss_dbm[{run}, {step}] = ["
                              + ", ".join(f"{v:.4g}" for v in np.asarray(rss_dbm[run, step], float)) + "]")


_LIKELIHOOD = "the likelihood of rss_dbm"


def _normalise_log(logw):
    """Weights proportional to ``exp(logw)`` along the last axis, computed without overflow."""
    w = np.exp(logw - logw.max(axis=-1, keepdims=True))
    return w / w.sum(axis=-1, keepdims=True)


def _velocity_schedule(velocity_m, n_steps):
    v = np.zeros(2) if velocity_m is None else as_array("velocity_m", velocity_m)
    if v.shape not in ((2,), (n_steps, 2)):
        raise ValueError(f"velocity_m must have shape (2,) or (steps, 2) = ({n_steps}, 2), got {v.shape}")
    return np.broadcast_to(v, (n_steps, 2)) if v.ndim == 1 else v


# -- grid-based Bayes --------------------------------------------------------------------------------
def grid_transition_matrix(cells_m, spread_m: float, velocity_m=(0.0, 0.0)):
    """Transition ``T[l, l'] = P(L_t = c_l | L_t-1 = c_l')``: a Gaussian of std ``spread_m`` (D) centred on
    ``c_l' + v``, normalised over the grid for each ``l'`` (note 004, section 3.7). ``spread_m = inf``
    gives the uniform transition (no motion prior)."""
    cells_m = as_array("cells_m", cells_m, ndim=2, trailing=(None, 2))
    n = cells_m.shape[0]
    check_scalar("spread_m", spread_m, gt=0, allow_inf=True)
    as_array("velocity_m", velocity_m, trailing=(2,))
    if np.isinf(spread_m):
        return np.full((n, n), 1.0 / n)
    diff = cells_m[:, None, :] - cells_m[None, :, :] - np.asarray(velocity_m, dtype=float)
    log_t = -0.5 * np.einsum("abi,abi->ab", diff, diff) / spread_m**2
    t = np.exp(log_t - log_t.max(axis=0, keepdims=True))
    return t / t.sum(axis=0, keepdims=True)


#: how :func:`grid_bayes_filter` applies the transition
GRID_TRANSITIONS = ("auto", "dense", "separable")


class _SeparableTransition:
    """The transition of :func:`grid_transition_matrix` applied without the ``C x C`` matrix.

    The cells are a subset of the lattice ``xs x ys`` of their distinct coordinates. The Gaussian kernel factors,
    ``K(c_l - c_l' - v) = Kx(x_l - x_l' - v_x) Ky(y_l - y_l' - v_y)``, so with the normaliser
    ``Z_l' = sum_l K(...)`` over the cells (the lattice's other points weigh 0)

        (T b)(l) = sum_l' K(c_l - c_l' - v) b(l') / Z_l' = [Ky (B / Z) Kx^T](l),

    with ``B`` the belief placed on the lattice: memory ``O(lattice + nx^2 + ny^2)`` instead of ``O(C^2)`` and the
    same numbers up to rounding (no truncation of the kernel). Each column of ``Kx`` and ``Ky`` is scaled by its
    largest entry before use (a factor that cancels between numerator and ``Z``), as the dense matrix subtracts
    its column maxima, so that a narrow kernel does not underflow."""

    def __init__(self, cells_m: np.ndarray, spread_m: float):
        self.xs, self.ix = np.unique(cells_m[:, 0], return_inverse=True)
        self.ys, self.iy = np.unique(cells_m[:, 1], return_inverse=True)
        self.spread_m = spread_m
        self.n_cells = cells_m.shape[0]
        self.mask = np.zeros((self.ys.size, self.xs.size))
        self.mask[self.iy, self.ix] = 1.0
        self._v, self._kx, self._ky, self._z = None, None, None, None

    @staticmethod
    def lattice_size(cells_m: np.ndarray) -> int:
        return int(np.unique(cells_m[:, 0]).size) * int(np.unique(cells_m[:, 1]).size)

    def _kernel(self, coords, shift):
        """``K[i, j] = exp(-(c_i - c_j - shift)^2 / (2 D^2))`` scaled so that each column's maximum is 1."""
        log_k = -0.5 * np.square(coords[:, None] - coords[None, :] - shift) / self.spread_m**2
        return np.exp(log_k - log_k.max(axis=0, keepdims=True))

    def _prepare(self, velocity_m) -> bool:
        v = np.asarray(velocity_m, dtype=float)
        if self._v is None or not np.array_equal(v, self._v):
            self._kx, self._ky = self._kernel(self.xs, v[0]), self._kernel(self.ys, v[1])
            self._z = (self._ky.T @ self.mask @ self._kx)[self.iy, self.ix]      # Z_l' at each cell
            self._v = v
        return bool(np.all(self._z > 0))

    def predict(self, belief: np.ndarray, velocity_m) -> np.ndarray | None:
        """``belief (R, C)`` -> predicted belief, or None where the kernel underflowed on every cell of some column
        (the caller then uses the dense matrix, which handles it)."""
        if np.isinf(self.spread_m):
            return np.broadcast_to(belief.sum(axis=-1, keepdims=True) / self.n_cells, belief.shape).copy()
        if not self._prepare(velocity_m):
            return None
        lattice = np.zeros((belief.shape[0],) + self.mask.shape)
        lattice[:, self.iy, self.ix] = belief / self._z
        return np.matmul(np.matmul(self._ky, lattice), self._kx.T)[:, self.iy, self.ix]


@dataclass(frozen=True)
class GridFilterResult:
    """``mmse_m``, ``map_m``: ``(R, T, 2)``; ``belief``: final posterior ``(R, C)``; ``degenerate`` ``(R,)`` and
    ``degenerate_step`` ``(R,)`` (-1 where not): runs whose likelihood collapsed (:func:`grid_bayes_filter`)."""

    mmse_m: np.ndarray
    map_m: np.ndarray
    belief: np.ndarray
    degenerate: np.ndarray = None
    degenerate_step: np.ndarray = None

    @property
    def n_degenerate(self) -> int:
        """The number of runs whose likelihood collapsed."""
        return 0 if self.degenerate is None else int(np.count_nonzero(self.degenerate))


def grid_bayes_filter(rss_dbm, cells_m, model: RssMeasurementModel, spread_m: float = 0.5, *,
                      velocity_m=None, initial_belief=None, transition: str = "auto") -> GridFilterResult:
    """Grid-based Bayes filter (Ozkaya 2011, Eqs. (4.10)-(4.15)) over runs ``R`` and steps ``T``.

    ``Bel_t(l) ~ p(s_t | c_l) sum_l' T[l, l'] Bel_t-1(l')`` with :func:`grid_transition_matrix`.
    ``velocity_m``: a known displacement per step, ``(2,)`` or ``(T, 2)`` (the mean of the process model
    in the thesis's constant-velocity experiment). ``initial_belief``: ``(C,)`` or ``(R, C)``; uniform if None.

    ``transition``: ``"dense"`` builds the ``C x C`` matrix (memory quadratic in the cells: 2 GB at 16,000
    cells); ``"separable"`` applies the same transition as two small matrix products on the lattice of the cells'
    distinct x and y coordinates (memory linear in the cells for a grid, possibly masked by a floor outline;
    equal to the dense one up to rounding); ``"auto"`` (default) takes the separable form when that lattice
    has at most 4 points per cell, which every regular grid has.

    A run whose posterior collapses at a step (the likelihood is -inf, or NaN, on every cell the belief allows, e.g.
    a reading of 1e300 dBm) is flagged ``degenerate`` with that ``degenerate_step``; its estimates and final belief
    are NaN from that step on, and the other runs are unaffected. The call then emits one ``RuntimeWarning`` (the
    number of such runs, the first run and step, its readings); when every run collapses it raises a ValueError
    naming ``rss_dbm`` and the first step instead (nothing can be estimated: a units bug, not a result).
    """
    rss_dbm, cells_m = _check_inputs(rss_dbm, model, cells_m=cells_m)
    check_scalar("spread_m", spread_m, gt=0, allow_inf=True)
    check_choice("transition", transition, GRID_TRANSITIONS)
    n_runs, n_steps, _ = rss_dbm.shape
    n_cells = cells_m.shape[0]
    velocity = _velocity_schedule(velocity_m, n_steps)
    if initial_belief is not None:
        initial_belief = as_array("initial_belief", initial_belief)
        if initial_belief.shape not in ((n_cells,), (n_runs, n_cells)):
            raise ValueError(f"initial_belief must have shape ({n_cells},) or ({n_runs}, {n_cells}), "
                             f"got {initial_belief.shape}")
        if np.any(initial_belief < 0) or np.any(initial_belief.sum(axis=-1) <= 0):
            raise ValueError("initial_belief must be non-negative with a positive sum over the cells")
    belief = (np.full((n_runs, n_cells), 1.0 / n_cells) if initial_belief is None
              else np.broadcast_to(np.asarray(initial_belief, float), (n_runs, n_cells)).copy())
    mmse = np.empty((n_runs, n_steps, 2))
    best = np.empty((n_runs, n_steps, 2))
    separable = None
    if transition == "separable" or (
            transition == "auto" and _SeparableTransition.lattice_size(cells_m) <= 4 * n_cells):
        separable = _SeparableTransition(cells_m, spread_m)
    dense, last_v = None, None
    dead = np.zeros(n_runs, bool)
    dead_step = np.full(n_runs, -1, np.int64)
    for t in range(n_steps):
        if t > 0:
            predicted = None if separable is None else separable.predict(belief, velocity[t])
            if predicted is None:
                if dense is None or not np.array_equal(velocity[t], last_v):
                    dense, last_v = grid_transition_matrix(cells_m, spread_m, velocity[t]), velocity[t]
                predicted = belief @ dense.T
            belief = predicted
        log_post = np.log(np.maximum(belief, 1e-300)) + model.log_likelihood(rss_dbm[:, t], cells_m, t)
        top = log_post.max(axis=-1)
        collapsed = ~dead & (np.isnan(top) | np.isinf(top))
        dead_step[collapsed] = t
        dead |= collapsed
        if n_runs and dead.all():
            raise _collapse_error(dead_step, _LIKELIHOOD, _reading_detail(rss_dbm))
        if dead.any():              # a collapsed run goes on with a uniform belief (NaN outputs): others unaffected
            log_post[dead] = 0.0
        belief = _normalise_log(log_post)
        mmse[:, t] = belief @ cells_m
        best[:, t] = cells_m[np.argmax(belief, axis=-1)]
        if dead.any():
            mmse[dead, t], best[dead, t] = np.nan, np.nan
    if dead.any():
        belief = belief.copy()
        belief[dead] = np.nan
        _warn_collapse(dead, dead_step, "grid_bayes_filter", _LIKELIHOOD, _reading_detail(rss_dbm))
    return GridFilterResult(mmse, best, belief, dead, dead_step)


# -- particle filters -------------------------------------------------------------------------------
def effective_sample_size(weights):
    """``N_eff = 1 / sum_j w_j^2`` of normalised weights along the last axis (Ozkaya 2011, Eq. (4.28))."""
    weights = as_array("weights", weights, min_ndim=1)
    return 1.0 / np.einsum("...n,...n->...", weights, weights)


def systematic_resample(weights, uniforms, cdf: str = "standard"):
    """Systematic resampling (Ozkaya 2011, Table 4.2) of every row of ``weights (..., N)``.

    ``uniforms (...)`` are the single draws ``u_1 ~ U[0, 1)``, scaled here to ``U[0, 1/N)``; the sample
    points are ``u_i = (u_1 + i - 1) / N`` and particle ``j`` is copied for each ``u_i`` with
    ``c_j-1 < u_i <= c_j``. ``cdf="standard"`` uses ``c_j = w_1 + ... + w_j``. The table prints ``c_1 = 0``,
    ``c_j = c_j-1 + w_j``, which drops ``w_1`` and shifts every particle's interval; that is kept as the
    flagged ``"literal_004"`` (indices beyond the last particle are clipped to it).
    Returns integer indices ``(..., N)``.
    """
    if cdf not in RESAMPLING_CDFS:
        raise ValueError(f"cdf must be one of {RESAMPLING_CDFS}, got {cdf!r}")
    weights = as_array("weights", weights, min_ndim=1)
    batch, n = weights.shape[:-1], weights.shape[-1]
    if n == 0 or np.any(weights < 0) or np.any(weights.sum(axis=-1) <= 0):
        raise ValueError(f"weights must be non-negative with a positive sum in every row, got shape {weights.shape}")
    uniforms_arr = as_array("uniforms", uniforms)
    if uniforms_arr.shape != batch or np.any(uniforms_arr < 0) or np.any(uniforms_arr >= 1):
        raise ValueError(f"uniforms must be draws in [0, 1) of shape {batch} (one per row of weights), "
                         f"got shape {uniforms_arr.shape}")
    w = weights.reshape(-1, n)
    c = np.cumsum(w, axis=-1)
    c /= c[:, -1:]
    if cdf == "literal_004":
        c = np.concatenate([np.zeros((c.shape[0], 1)), c[:, 1:] - c[:, :1]], axis=-1)
    else:
        c[:, -1] = 1.0                                     # guard against round-off below the last u_i
    u = (np.asarray(uniforms, dtype=float).reshape(-1, 1) + np.arange(n)) / n
    # one searchsorted over all rows: offset row r by 2r so the rows' CDFs do not overlap
    offset = 2.0 * np.arange(c.shape[0])[:, None]
    idx = np.searchsorted((c + offset).ravel(), (u + offset).ravel(), side="left").reshape(c.shape)
    idx = np.minimum(idx - n * np.arange(c.shape[0])[:, None], n - 1)
    return idx.reshape(batch + (n,))


@dataclass(frozen=True)
class ParticleFilterResult:
    """``mmse_m``, ``map_m`` (highest-weight particle): ``(R, T, 2)``; ``n_eff``: ``(R, T)`` before any
    resampling; ``resampled``: ``(R, T)`` bool; ``particles_m (R, N, 2)`` and ``weights (R, N)`` at the end;
    ``degenerate`` ``(R,)`` and ``degenerate_step`` ``(R,)`` (-1 where not): the runs whose likelihood collapsed
    (:func:`particle_filter`), NaN from that step on."""

    mmse_m: np.ndarray
    map_m: np.ndarray
    n_eff: np.ndarray
    resampled: np.ndarray
    particles_m: np.ndarray
    weights: np.ndarray
    degenerate: np.ndarray = None
    degenerate_step: np.ndarray = None

    @property
    def n_degenerate(self) -> int:
        """The number of runs whose likelihood collapsed."""
        return 0 if self.degenerate is None else int(np.count_nonzero(self.degenerate))


def particle_filter(rss_dbm, model: RssMeasurementModel, rng: np.random.Generator, *, n_particles: int,
                    region_m, spread_m: float = 0.5, velocity_m=None, initial_position_m=None, initial_sd_m: float = 0.0,
                    resample_threshold: float | None = None, weight_smoothing: str = "none",
                    resampling_cdf: str = "standard") -> ParticleFilterResult:
    """SIR particle filter and the thesis's improved SIR (Ozkaya 2011, Tables 4.3-4.4, Sec. 7.1.4).

    Proposal = process model (bootstrap, Eq. (4.33)): ``L_t = L_t-1 + v_t + N(0, D^2 I)``, reflected into
    ``region_m = (lower, upper)`` (the room, or the accessible part of it: Table 7.22); ``spread_m = inf``
    draws a fresh uniform proposal over the region (Tables 7.18-7.19), whose particles start from equal
    weights (the previous weights belonged to the particles that were replaced). Weights ``w_t ~ w_t-1 p(s_t | L_t)``
    (Eq. (4.34)). Particles start uniform in the region, or all at ``initial_position_m (R, 2)`` when the
    initial location is known (Table 7.21); with ``initial_sd_m > 0`` they are drawn from
    ``N(initial_position_m, initial_sd_m^2 I)`` reflected into the region (a Gaussian prior on the start, the one
    the posterior CRLB assumes).

    Resampling (systematic, :func:`systematic_resample`): every step when ``resample_threshold`` is None
    (basic SIR, Table 4.4); otherwise only when ``N_eff < resample_threshold * N`` (the thesis's "N_t = 0.5",
    read as a fraction of N since N_eff >= 1; note 004, section 11.6).

    ``weight_smoothing``: ``"sqrt"`` replaces the normalised weights by ``sqrt(w)`` renormalised before the
    estimate, the N_eff test and the resampling, and carries them forward (the interpretation validated in
    note 004, section 3.7; it tempers the likelihood). ``"sqrt_corrected"`` is the literature's generalised
    resampling: draw with ``a = sqrt(w)`` and reweight the copies by ``w / a``. Both estimates use the
    current weights (MMSE = weighted mean; MAP = the highest-weight particle).

    A run whose likelihood collapses at a step (every particle's log-likelihood -inf, e.g. a reading of 1e300 dBm
    that overflows the Gaussian, or NaN) is isolated: it is flagged ``degenerate`` with that ``degenerate_step``,
    its estimates are NaN from that step on and its final particles and weights NaN; it goes on internally with
    equal weights, so the other runs' random draws, and hence their results, are those of a batch without the fault.
    The call then emits one ``RuntimeWarning`` (the number of such runs, the first run and step, its readings); when
    every run collapses it raises a ValueError naming ``rss_dbm`` and the first step instead.
    """
    check_choice("weight_smoothing", weight_smoothing, WEIGHT_SMOOTHINGS)
    check_scalar("n_particles", n_particles, ge=1, integer=True)
    check_scalar("spread_m", spread_m, gt=0, allow_inf=True)
    check_scalar("initial_sd_m", initial_sd_m, ge=0)
    if initial_sd_m > 0 and initial_position_m is None:
        raise ValueError("initial_sd_m spreads the particles around initial_position_m; give initial_position_m too")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    if resample_threshold is not None and not 0.0 < resample_threshold <= 1.0:
        raise ValueError(f"resample_threshold is a fraction of N in (0, 1], got {resample_threshold}")
    rss_dbm, _ = _check_inputs(rss_dbm, model)
    n_runs, n_steps, _ = rss_dbm.shape
    if len(region_m) != 2:
        raise ValueError(f"region_m must be (lower, upper) corners, got {region_m!r}")
    lower, upper = (as_array(name, b, trailing=(2,)) for name, b in zip(("region lower", "region upper"), region_m))
    if np.any(upper <= lower):
        raise ValueError(f"region_m needs upper > lower on both axes, got {lower.tolist()} and {upper.tolist()}")
    velocity = _velocity_schedule(velocity_m, n_steps)
    shape = (n_runs, n_particles, 2)

    def uniform():
        return lower + (upper - lower) * rng.random(shape)

    if initial_position_m is None:
        particles = uniform()
    else:
        initial_position_m = as_array("initial_position_m", initial_position_m)
        if initial_position_m.shape != (n_runs, 2):
            raise ValueError(f"initial_position_m must have shape (runs, 2) = ({n_runs}, 2), "
                             f"got {initial_position_m.shape}")
        particles = np.broadcast_to(np.asarray(initial_position_m, float)[:, None, :], shape).copy()
        if initial_sd_m > 0:
            particles = reflect_into_box(particles + initial_sd_m * rng.standard_normal(shape), lower, upper)
    log_w = np.full((n_runs, n_particles), -np.log(n_particles))
    mmse = np.empty((n_runs, n_steps, 2))
    best = np.empty((n_runs, n_steps, 2))
    n_eff = np.empty((n_runs, n_steps))
    resampled = np.zeros((n_runs, n_steps), dtype=bool)
    dead = np.zeros(n_runs, bool)
    dead_step = np.full(n_runs, -1, np.int64)
    for t in range(n_steps):
        if t > 0:
            if np.isinf(spread_m):
                # fresh draws from the uniform proposal: the old weights belonged to the old particles
                particles = uniform()
                log_w = np.full((n_runs, n_particles), -np.log(n_particles))
            else:
                particles = reflect_into_box(particles + velocity[t] + spread_m * rng.standard_normal(shape),
                                             lower, upper)
        logits = log_w + model.log_likelihood(rss_dbm[:, t], particles, t)
        top = logits.max(axis=-1)
        collapsed = ~dead & (np.isnan(top) | np.isinf(top))     # -inf for every particle, or NaN / +inf anywhere
        dead_step[collapsed] = t
        dead |= collapsed
        if n_runs and dead.all():
            raise _collapse_error(dead_step, _LIKELIHOOD, _reading_detail(rss_dbm))
        if dead.any():              # a collapsed run goes on with equal weights (NaN outputs): others unaffected
            logits[dead] = 0.0
        w = _normalise_log(logits)
        if weight_smoothing == "sqrt":
            w = np.sqrt(w)
            w /= w.sum(axis=-1, keepdims=True)
        mmse[:, t] = np.einsum("rn,rnd->rd", w, particles)
        best[:, t] = particles[np.arange(n_runs), np.argmax(w, axis=-1)]
        draw_w = w
        if weight_smoothing == "sqrt_corrected":
            draw_w = np.sqrt(w)
            draw_w /= draw_w.sum(axis=-1, keepdims=True)
        n_eff[:, t] = effective_sample_size(draw_w)
        do = (np.ones(n_runs, dtype=bool) if resample_threshold is None
              else n_eff[:, t] < resample_threshold * n_particles)
        resampled[:, t] = do
        u = rng.random(n_runs)              # drawn for every run so the stream does not depend on `do`
        if np.any(do):
            idx = systematic_resample(draw_w[do], u[do], resampling_cdf)
            particles[do] = particles[do][np.arange(idx.shape[0])[:, None], idx]
            if weight_smoothing == "sqrt_corrected":
                new_w = np.take_along_axis(w[do], idx, -1) / np.take_along_axis(draw_w[do], idx, -1)
                w[do] = new_w / new_w.sum(axis=-1, keepdims=True)
            else:
                w[do] = 1.0 / n_particles
        log_w = np.log(np.maximum(w, 1e-300))
        if dead.any():
            mmse[dead, t], best[dead, t], n_eff[dead, t] = np.nan, np.nan, np.nan
            resampled[dead, t] = False
    weights = np.exp(log_w)
    if dead.any():
        particles, weights = particles.copy(), weights.copy()
        particles[dead], weights[dead] = np.nan, np.nan
        _warn_collapse(dead, dead_step, "particle_filter", _LIKELIHOOD, _reading_detail(rss_dbm))
    return ParticleFilterResult(mmse, best, n_eff, resampled, particles, weights, dead, dead_step)
