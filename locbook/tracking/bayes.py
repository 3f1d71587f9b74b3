"""Nonparametric Bayes filters for RSSI tracking: the grid-based Bayes filter (Markov localization) here, the
particle filter in :mod:`locbook.tracking.particle`, and the result both return.

Both run the recursion of Ozkaya (2011), Eqs. (4.1)-(4.5),

    p(L_t | s_1:t)  ~  p(s_t | L_t)  integral p(L_t | L_t-1) p(L_t-1 | s_1:t-1) dL_t-1,

with the RSS likelihood of independent readers (Ch. 5, Eq. (5.11), whose wall term has the wrong sign in
the print, corrected) given by
the one RSS model, :class:`locbook.models.rss.RssModel`,

    p(s | L) = prod_j N(s_j; alpha_j - 10 n_j log10(d_j(L)/d0) - nW_j(L) WAF, sigma^2),

or by any callable ``log_likelihood(points, t)`` (a Gaussian position fix, a range, a fused model),

and the process model ``L_t = L_t-1 + v_t + N(0, D^2 I)`` (Eq. (4.2); ``v`` a known velocity, D = inf a
uniform transition). Everything is vectorized over a leading Monte-Carlo axis ``R`` (runs) and over cells or
particles; the only Python loop is over time steps.

Conventions: ``rss_dbm`` has shape ``(R, T, m)``. At step 0 the prior is uniform over the region (or
concentrated at a known initial location) and no prediction is made; from step 1 on each step predicts,
then updates. Estimates (:class:`BayesFilterResult`): the posterior mean (MMSE, Eq. (4.8)) and covariance, and the
MAP (Eq. (4.9): the most probable cell, or the highest-weight particle, since a particle set has no density).
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from .._deprecation import old_form, past_wrappers
from .._validate import as_array, check_choice, check_scalar
from ..models.base import MeasurementModel
from ..models.rss import RssModel
from . import _compiled
from .resampling import effective_sample_size
from .results import FilterResult

__all__ = ["BayesFilterResult", "grid_bayes_filter", "grid_transition_matrix", "GRID_TRANSITIONS", "MAX_ARRAY_BYTES"]

#: the largest array (bytes) one grid or particle filter call may allocate, checked from the arguments before anything
#: is allocated (which arrays, and the repository's largest: docs/filters.md, "Size guards"). Read at call time: raise
#: it on a machine with more memory.
MAX_ARRAY_BYTES = 2 * 2**30


def _check_size(name: str, what: str, dims, hint: str) -> None:
    """Refuse an array of ``dims`` float64 values over :data:`MAX_ARRAY_BYTES` before it is allocated, naming the
    argument ``name`` that sets it, what it is, the size it would take and the limit (Python integers: no overflow)."""
    dims = [int(v) for v in dims]
    nbytes = 8 * int(np.prod(dims, dtype=object)) if dims else 8
    if nbytes > MAX_ARRAY_BYTES:
        raise ValueError(f"{name}: {what}, {' x '.join(f'{v:,}' for v in dims)} float64 values, would take "
                         f"{_gib(nbytes)}, over the limit of one array (locbook.tracking.bayes.MAX_ARRAY_BYTES = "
                         f"{_gib(MAX_ARRAY_BYTES)}); {hint}, or raise that limit if the machine has the memory")


def _gib(nbytes: int) -> str:
    return f"{nbytes / 2**30:.3g} GiB"


@dataclass(frozen=True)
class BayesFilterResult(FilterResult):
    """The posterior of a particle or grid filter, per run ``R`` and step ``T``, in the vocabulary of every filter
    result (:class:`~locbook.tracking.results.FilterResult`).

    ``mean`` ``(R, T, dim)``: the posterior mean (MMSE, Ozkaya Eq. (4.8)); ``cov`` ``(R, T, dim, dim)``: the
    weighted covariance of the particles or cells about it (positions in m, covariances in m^2; with the particle
    filter's ``motion=`` the full state); ``steps``: every step, ``arange(T)``; ``log_likelihood``: None (the filters
    weigh by the likelihood up to a constant per run, and the compiled paths keep no normaliser: no exact predictive
    log-likelihood to give); ``diverged`` and ``diverged_step`` ``(R,)`` (-1 where not): filter divergence here is
    the collapse of the likelihood (-inf, NaN or +inf on every particle or cell), its runs NaN from that step on.
    The extras: ``map_m`` ``(R, T, dim)``: the highest-weight particle or the most probable cell (Eq. (4.9));
    ``n_eff`` ``(R, T)``: ``1 / sum w^2`` of the weights before any resampling (Eq. (4.28); for the grid, of the cell
    probabilities); ``resampled`` ``(R, T)`` (always False for the grid); ``particles_m`` ``(R, N, dim)`` and
    ``weights`` ``(R, N)``: the final posterior as weighted points (the particles, or the cells and their belief);
    ``clouds``: the particles after the update, before resampling, at the steps asked for, ``{t: (R, N, dim)}``.
    ``mean_m``, ``covariance_m2``, ``degenerate``, ``degenerate_step`` and ``n_degenerate`` (the earlier names) are
    deprecated aliases of ``mean``, ``cov``, ``diverged``, ``diverged_step`` and ``n_diverged``."""

    _RENAMED = {"mean_m": "mean", "covariance_m2": "cov", "degenerate": "diverged",
                "degenerate_step": "diverged_step", "n_degenerate": "n_diverged"}
    _WHOLE_MEAN_IS_POSITION = True

    mean: np.ndarray
    cov: np.ndarray
    map_m: np.ndarray
    n_eff: np.ndarray
    resampled: np.ndarray
    particles_m: np.ndarray
    weights: np.ndarray
    diverged: np.ndarray
    diverged_step: np.ndarray
    clouds: dict = field(default_factory=dict)
    log_likelihood: np.ndarray | None = None

    @property
    def steps(self) -> np.ndarray:
        """The recorded step indices: every step, ``arange(T)``."""
        return np.arange(np.shape(self.mean)[-2])


def weighted_moments(weights, points_m):
    """Mean ``(R, dim)`` and covariance ``(R, dim, dim)`` of points ``(R, N, dim)`` (or shared ``(N, dim)``) under
    normalised weights ``(R, N)``."""
    mean = weights @ points_m if np.ndim(points_m) == 2 else np.einsum("rn,rnd->rd", weights, points_m)
    dev = points_m - mean[:, None, :]
    return mean, np.einsum("rn,rni,rnj->rij", weights, dev, dev)


def _check_inputs(rss_dbm, model: MeasurementModel, *, cells_m=None):
    """``rss_dbm (R, T, m)`` against the model's ``m`` readings (NaN = not heard); cells ``(C, dim)`` in the model's
    position space (a model of positions) or of any dimension."""
    if not isinstance(model, MeasurementModel):
        raise ValueError(f"model must be a measurement model (e.g. an RssModel), got {type(model).__name__}")
    rss_dbm = as_array("rss_dbm", rss_dbm, ndim=3, nan_ok=True)
    model.check_readings(rss_dbm, None)
    if rss_dbm.shape[-1] != model.n_readings:
        raise ValueError(f"rss_dbm must have shape (runs, steps, {model.n_readings}) for the model's "
                         f"{model.n_readings} readings, got {rss_dbm.shape}")
    if cells_m is not None:
        dim = getattr(model, "position_dim", None)
        cells_m = as_array("cells_m", cells_m, ndim=2, trailing=(None, dim) if dim is not None else None)
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
                  f"{step}{extra}); those runs are NaN from their step on (see diverged, diverged_step), the "
                  "others are unaffected", RuntimeWarning, stacklevel=past_wrappers(3))


def _reading_detail(rss_dbm):
    """``detail(run, step)`` for the collapse messages: that run's readings at that step."""
    return lambda run, step: (f"; rss_dbm[{run}, {step}] = ["
                              + ", ".join(f"{v:.4g}" for v in np.asarray(rss_dbm[run, step], float)) + "]")


_LIKELIHOOD = "the likelihood of rss_dbm"


def _callable_steps(rss_dbm, n_steps) -> int:
    """The number of steps of a filter whose likelihood is a callable (it reads its own data): ``n_steps``, checked,
    with ``rss_dbm`` None (particle and grid filters alike)."""
    if rss_dbm is not None:
        raise ValueError("rss_dbm goes with an RssModel; a log_likelihood callable reads its own data "
                         "(give rss_dbm=None and n_steps)")
    if n_steps is None:
        raise ValueError("n_steps must be given with a log_likelihood callable")
    check_scalar("n_steps", n_steps, ge=1, integer=True)
    return int(n_steps)


def _normalise_log(logw):
    """Weights proportional to ``exp(logw)`` along the last axis, computed without overflow."""
    w = np.exp(logw - logw.max(axis=-1, keepdims=True))
    return w / w.sum(axis=-1, keepdims=True)


def _velocity_schedule(velocity_m, n_steps, dim: int = 2):
    v = np.zeros(dim) if velocity_m is None else as_array("velocity_m", velocity_m)
    if v.shape not in ((dim,), (n_steps, dim)):
        raise ValueError(f"velocity_m must have shape ({dim},) or (steps, {dim}) = ({n_steps}, {dim}), got {v.shape}")
    return np.broadcast_to(v, (n_steps, dim)) if v.ndim == 1 else v


# -- grid-based Bayes --------------------------------------------------------------------------------
def grid_transition_matrix(cells_m, spread_m: float, velocity_m=None):
    """Transition ``T[l, l'] = P(L_t = c_l | L_t-1 = c_l')`` on cells ``(C, dim)``: the process model
    ``L_t = L_t-1 + v + N(0, D^2 I)`` of Ozkaya (2011), Eq. (4.2), with ``D = spread_m`` (Eqs. (4.10)-(4.15) state
    the Gaussian model of std D; its discretisation on the grid is ours)::

        T[l, l'] = K(c_l - c_l' - v) / sum_k K(c_k - c_l' - v),   K(u) = exp(-|u|^2 / (2 D^2)),

    the Gaussian density *sampled* at the cells (not integrated over the cells' areas) and normalised over the grid
    for each source cell ``l'``. Edges therefore truncate and renormalise: the mass the continuous Gaussian would
    carry outside the grid (or outside a masked floor outline) goes to the cells inside in proportion to the kernel,
    none is lost, and near an edge the prediction is pulled inwards (the particle filter reflects instead). Far from
    the edges of a regular lattice of spacing ``h`` the sampled kernel's mean is ``v`` and its variance ``D^2`` per
    axis up to aliasing terms (Poisson summation) of relative size about ``8 pi^2 (D/h)^2 exp(-2 pi^2 D^2 / h^2)``
    in the variance (2e-7 at D = h, 0.14 at D = h/2); for ``D`` well below ``h`` it is no longer Gaussian (nearly
    all the mass stays on the cell nearest ``c_l' + v``, so a velocity below h/2 per step is rounded away). Each
    column is computed relative to its largest entry, so a column whose kernel underflows everywhere (a target far
    outside the grid) gives its mass to the cells nearest ``c_l' + v``. ``spread_m = inf`` gives the uniform
    transition (no motion prior). ``velocity_m``: ``(dim,)``; zero if None."""
    cells_m = as_array("cells_m", cells_m, ndim=2)
    n, dim = cells_m.shape
    if n == 0:
        raise ValueError(f"cells_m must hold at least one cell, got shape {cells_m.shape}")
    check_scalar("spread_m", spread_m, gt=0, allow_inf=True)
    velocity = np.zeros(dim) if velocity_m is None else as_array("velocity_m", velocity_m, trailing=(dim,))
    # the construction's largest array is the C x C x dim difference (then three C x C ones)
    _check_size("cells_m", "the dense transition (cells x cells" + (")" if np.isinf(spread_m) else " x dim to build)"),
                (n, n) if np.isinf(spread_m) else (n, n, max(dim, 1)), _DENSE_HINT)
    if np.isinf(spread_m):
        return np.full((n, n), 1.0 / n)
    diff = cells_m[:, None, :] - cells_m[None, :, :] - velocity
    log_t = -0.5 * np.einsum("abi,abi->ab", diff, diff) / spread_m**2
    t = np.exp(log_t - log_t.max(axis=0, keepdims=True))
    return t / t.sum(axis=0, keepdims=True)


#: how :func:`grid_bayes_filter` applies the transition
GRID_TRANSITIONS = ("auto", "dense", "separable")
_DENSE_HINT = ("use fewer cells, or cells on a regular grid (possibly masked: the separable transition is linear in "
               "them)")


def _along_axes(kernels, lattice):
    """``kernels[a]`` applied along the lattice axis of coordinate ``a`` (the lattice's axes run from the last
    coordinate to the first, after any run axis), for any dimension."""
    for a in reversed(range(len(kernels))):
        axis = lattice.ndim - 1 - a
        lattice = np.moveaxis(np.tensordot(kernels[a], lattice, axes=([1], [axis])), 0, axis)
    return lattice


class _SeparableTransition:
    """The transition of :func:`grid_transition_matrix` applied without the ``C x C`` matrix.

    The cells are a subset of the lattice ``xs x ys (x ...)`` of their distinct coordinates. The Gaussian kernel
    factors, ``K(c_l - c_l' - v) = Kx(x_l - x_l' - v_x) Ky(y_l - y_l' - v_y)``, so with the normaliser
    ``Z_l' = sum_l K(...)`` over the cells (the lattice's other points weigh 0)

        (T b)(l) = sum_l' K(c_l - c_l' - v) b(l') / Z_l' = [Ky (B / Z) Kx^T](l),

    with ``B`` the belief placed on the lattice (rows y, columns x; in other dimensions one kernel per axis):
    memory ``O(lattice + nx^2 + ny^2)`` instead of ``O(C^2)`` and the same numbers up to rounding (no truncation of
    the kernel). Each column of ``Kx`` and ``Ky`` is scaled by its largest entry before use (a factor that cancels
    between numerator and ``Z``), as the dense matrix subtracts its column maxima, so that a narrow kernel does not
    underflow."""

    _v: np.ndarray | None       # the velocity the kernels _k and normaliser _z are for (None: not prepared)
    _k: list[np.ndarray]
    _z: np.ndarray

    def __init__(self, cells_m: np.ndarray, spread_m: float):
        self.dim = cells_m.shape[1]
        axes = [np.unique(cells_m[:, a], return_inverse=True) for a in range(self.dim)]
        self.coords = [values for values, _ in axes]
        self.index = tuple(inverse for _, inverse in reversed(axes))        # (iy, ix) in the plane
        self.spread_m = spread_m
        self.n_cells = cells_m.shape[0]
        self.mask = np.zeros(tuple(values.size for values in reversed(self.coords)))
        self.mask[self.index] = 1.0
        # None until _prepare, which every reader of _k and _z calls first
        self._v, self._k, self._z = None, None, None  # type: ignore[assignment]

    @staticmethod
    def lattice_size(cells_m: np.ndarray) -> int:
        return int(np.prod([np.unique(cells_m[:, a]).size for a in range(cells_m.shape[1])], dtype=object))

    def _kernel(self, coords, shift):
        """``K[i, j] = exp(-(c_i - c_j - shift)^2 / (2 D^2))`` scaled so that each column's maximum is 1."""
        log_k = -0.5 * np.square(coords[:, None] - coords[None, :] - shift) / self.spread_m**2
        return np.exp(log_k - log_k.max(axis=0, keepdims=True))

    def _prepare(self, velocity_m) -> bool:
        v = np.asarray(velocity_m, dtype=float)
        if self._v is None or not np.array_equal(v, self._v):
            self._k = [self._kernel(c, v[a]) for a, c in enumerate(self.coords)]
            if self.dim == 2:
                kx, ky = self._k
                self._z = (ky.T @ self.mask @ kx)[self.index]                      # Z_l' at each cell
            else:
                self._z = _along_axes([k.T for k in self._k], self.mask)[self.index]
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
        lattice[(slice(None),) + self.index] = belief / self._z
        if self.dim == 2:
            kx, ky = self._k
            return np.matmul(np.matmul(ky, lattice), kx.T)[(slice(None),) + self.index]
        return _along_axes(self._k, lattice)[(slice(None),) + self.index]


#: runs x steps x cells from which grid_bayes_filter runs the compiled kernels (smaller problems stay in numpy, with
#: no compilation wait)
_GRID_MIN_WORK = 200_000
_EPS_LOG = 53 * np.log(2.0)                 # -log(2^-53): a tap below exp(-_EPS_LOG) of the largest is rounding


def _even_axis(values: np.ndarray) -> float | None:
    """The spacing of sorted distinct coordinates if they are evenly spaced up to the rounding of ``arange`` or
    ``linspace`` (64 ulp of the largest coordinate), else None; 0 for a single value."""
    if values.size == 1:
        return 0.0
    h = (values[-1] - values[0]) / (values.size - 1)
    tol = 64 * np.finfo(float).eps * max(np.abs(values).max(), h)
    return float(h) if np.all(np.abs(values - (values[0] + h * np.arange(values.size))) <= tol) else None


class _BandedLattice:
    """The transition of :func:`grid_transition_matrix` on a regular lattice (cells evenly spaced per axis, possibly
    masked; up to three axes) as a banded correlation along each axis, by the compiled kernel
    :func:`locbook.tracking._grid_kernels._nb_predict`.

    On a lattice of spacing ``h`` the per-axis kernel of :class:`_SeparableTransition` is Toeplitz,
    ``Kx[i, j] = exp(-((i - j) h - v)^2 / (2 D^2))``, so ``Kx b`` is a 1-D correlation with the taps
    ``t(s) = exp(-(s h - v)^2 / (2 D^2))``, ``s = i - j``. Truncation: a tap is dropped where it is below 2^-53 (the
    rounding of a double) of the largest entry of every column of ``Kx`` (the columns at the lattice's ends, whose
    targets ``x_j + v`` may fall outside it, have the smallest largest entries: the rule takes theirs); with ``v = 0``
    on a long axis this keeps ``|s h| <= sqrt(2 * 53 ln 2) D = 8.57 D``. An entry of the 2-D (3-D) column is a product
    of per-axis entries, so every dropped entry is below 2^-53 of its column's largest entry on the lattice (on a
    masked lattice, of the largest over the lattice's points, which the cells may not all be). Normalisers ``Z_l'``
    (the same correlation, taps reversed, of the mask) are computed with the same truncation, so each column is
    normalised over the cells as before: edges truncate and renormalise. A column whose ``Z`` underflows, or taps
    spanning more than 700 in the exponent (a velocity carrying the targets far outside the lattice), are left to
    :class:`_SeparableTransition` (``prepare`` returns False). The work per run is ``C (K_x + K_y)`` multiply-adds
    (``K`` the number of taps: 85 per axis at ``D = 5 h``) instead of ``C (n_x + n_y)``."""

    _v: np.ndarray | None       # the velocity the plan is for (None: not prepared)
    _plan: dict | None          # None: not applicable at that velocity
    _zinv: np.ndarray | None

    def __init__(self, cells_m: np.ndarray, spread_m: float, spacing):
        self.dim = cells_m.shape[1]
        self.spread_m = float(spread_m)
        axes = [np.unique(cells_m[:, a], return_inverse=True) for a in range(self.dim)]
        self.n = [values.size for values, _ in axes]                # per coordinate axis (x, y, z)
        self.h = list(spacing)
        self.index = [inverse.astype(np.int64) for _, inverse in axes]
        self.n_cells = cells_m.shape[0]
        sizes = self.n + [1] * (3 - self.dim)
        self.shape = (sizes[2], sizes[1], sizes[0])                 # (n0, n1, n2) = (z, y, x) planes, rows, columns
        self._v, self._plan, self._zinv = None, None, None

    @staticmethod
    def build(cells_m: np.ndarray, spread_m: float):
        """The banded transition of ``cells_m``, or None when it does not apply (uneven coordinates, more than three
        axes, an infinite spread)."""
        if not np.isfinite(spread_m) or not 1 <= cells_m.shape[1] <= 3:
            return None
        spacing = [_even_axis(np.unique(cells_m[:, a])) for a in range(cells_m.shape[1])]
        if any(h is None for h in spacing):
            return None
        return _BandedLattice(cells_m, spread_m, spacing)

    def _taps(self, a: int, v: float):
        """The kept taps of axis ``a`` and their first offset ``s_min``, or None (the class docstring)."""
        n, h = self.n[a], self.h[a]
        if n == 1:
            return np.ones(1), 0
        s = np.arange(-(n - 1), n)
        e = np.square(s * h - v) / (2.0 * self.spread_m**2)
        worst = max(e[n - 1:].min(), e[:n].min())                   # the end columns' largest entries
        keep = np.flatnonzero(e <= worst + _EPS_LOG)
        if worst - e.min() > 700.0:
            return None
        return np.exp(-(e[keep[0]:keep[-1] + 1] - e.min())), int(s[keep[0]])

    def _make_plan(self, taps):
        """Buffers and offsets of :func:`_nb_predict` for the per-axis ``(taps, s_min)`` (x, y, z)."""
        n0, n1, n2 = self.shape
        padded = []
        for a in range(3):
            t, smin = taps[a] if a < self.dim else (np.ones(1), 0)
            k = -(-t.size // 8) * 8
            tt = np.zeros(k)
            tt[:t.size] = t
            lead = max(0, k - 1 + smin)                                # pad before the lattice
            length = lead + (n2, n1, n0)[a] + max(0, -smin)
            padded.append((tt, lead - smin, lead, length))
        (tx, bx, px, lx), (ty, by, py, ly), (tz, bz, pz, lz) = padded
        ix = self.index[0]
        iy = self.index[1] if self.dim > 1 else np.zeros_like(ix)
        iz = self.index[2] if self.dim > 2 else np.zeros_like(ix)
        scatter = (iz * n1 + iy) * lx + px + ix
        gather = (iz * n1 + iy) * n2 + ix
        return dict(scatter=scatter, gather=gather, dims=np.array([n0, n1, n2, self.dim], np.int64),
                    xb=np.zeros(n0 * n1 * lx), lx=lx, tx=tx, bx=bx,
                    yb=np.zeros(n0 * ly * n2 if self.dim > 1 else 1), ly=ly, py=py, ty=ty, by=by,
                    zb=np.zeros(lz * n1 * n2 if self.dim > 2 else 1), pz=pz, tz=tz, bz=bz, out=np.zeros(n0 * n1 * n2))

    def _run(self, plan, belief, zinv, dead, kernels):
        pred = np.empty_like(belief)
        kernels._nb_predict(belief, zinv, dead, plan["scatter"], plan["gather"], plan["dims"], plan["xb"],
                            plan["lx"], plan["tx"], plan["bx"], plan["yb"], plan["ly"], plan["py"], plan["ty"],
                            plan["by"], plan["zb"], plan["pz"], plan["tz"], plan["bz"], plan["out"], pred)
        return pred

    def prepare(self, velocity_m, kernels) -> bool:
        v = np.asarray(velocity_m, dtype=float)
        if self._v is not None and np.array_equal(v, self._v):
            return self._plan is not None
        self._v, self._plan = v.copy(), None
        taps = [self._taps(a, v[a]) for a in range(self.dim)]
        if any(t is None for t in taps):
            return False
        flipped = [(t[::-1].copy(), -(smin + t.size - 1)) for t, smin in taps]    # Z: the reversed taps on the mask
        ones = np.ones((1, self.n_cells))
        z = self._run(self._make_plan(flipped), ones, ones[0], np.zeros(1, np.bool_), kernels)[0]
        if not np.all(z > 0):
            return False
        self._plan, self._zinv = self._make_plan(taps), 1.0 / z
        return True

    def predict(self, belief: np.ndarray, velocity_m, dead: np.ndarray, kernels) -> np.ndarray | None:
        """``belief (R, C)`` -> the predicted belief (rows of ``dead`` runs unspecified), or None (not applicable
        at this velocity)."""
        if not self.prepare(velocity_m, kernels):
            return None
        pred = self._run(self._plan, np.ascontiguousarray(belief), self._zinv, dead, kernels)
        pred[dead] = belief[dead]                   # (the kernel skips them)
        return pred


def _grid_trial():
    """A tiny problem for the grid kernels (compiled or loaded once per session: _compiled._kernel_module)."""
    cells = np.array([[0.0, 0.0], [0.5, 0.0], [0.0, 0.5], [0.5, 0.5]])
    lattice = _BandedLattice.build(cells, 0.5)

    def run(kernels):
        belief = lattice.predict(np.full((1, 4), 0.25), np.zeros(2), np.zeros(1, bool), kernels)
        kernels._nb_update(belief, np.zeros((1, 4)), True, np.zeros((1, 1, 4)), np.zeros((1, 1)), np.ones(1),
                           np.zeros(1, bool), np.ascontiguousarray(cells.T), np.empty(4), np.empty(4),
                           np.empty((1, 2)), np.empty((1, 2, 2)), np.zeros(1, np.int64), np.empty(1),
                           np.zeros(1, np.bool_))
    return run


def _grid_kernels():
    """:mod:`locbook.tracking._grid_kernels` when the compiled paths are on and the kernels work here, else None (the
    numpy path): :func:`locbook.tracking._compiled._kernel_module`."""
    return _compiled._kernel_module("locbook.tracking._grid_kernels", _grid_trial, "grid filter", stacklevel=4)


# The models whose likelihood the compiled grid kernels evaluate from a mean table (a registry keyed by model type,
# exact type): ``table(model, cells, n_runs) -> (table (1|R, C, m), sigma) or None``.
_MEAN_TABLES = {RssModel: lambda model, cells, n_runs: model.mean_table(cells, n_runs)}


def _points_log_likelihood(model: MeasurementModel, rss_dbm, cells_m, n_runs: int):
    """``t -> (R, C)``: the model's log-likelihood of step ``t``'s readings on the cells (up to a constant per run),
    through the model's own fixed-points form when it has one (an RssModel's mean table), else its
    :meth:`~locbook.models.base.MeasurementModel.log_likelihood`, checked."""
    if type(model) in _MEAN_TABLES:     # an RssModel (the table's one key)
        return cast(RssModel, model).points_log_likelihood(rss_dbm, cells_m, n_runs)

    def ll(t):
        out = np.asarray(model.log_likelihood(rss_dbm[:, t], cells_m, step=t), dtype=float)
        if out.shape != (n_runs, cells_m.shape[0]):
            out = np.broadcast_to(out, (n_runs, cells_m.shape[0]))
        return out
    return ll


def _is_likelihood(value) -> bool:
    """A measurement model or a callable log-likelihood: what :func:`grid_bayes_filter` takes as ``model``."""
    return isinstance(value, MeasurementModel) or callable(value)


def _old_grid_order(function, args, kwargs):
    """:func:`~locbook._deprecation.old_form`'s detector of :func:`grid_bayes_filter`: the earlier, deprecated
    order, the cells second (an array, not a model or a callable) and the model or callable third (positionally or as
    ``model=``), is swapped into the new one."""
    if len(args) < 2 or _is_likelihood(args[1]):
        return None
    if len(args) > 2 and "model" not in kwargs and _is_likelihood(args[2]):
        args = (args[0], args[2], args[1], *args[3:])
    elif len(args) == 2 and "cells_m" not in kwargs and _is_likelihood(kwargs.get("model")):
        kwargs = dict(kwargs)
        args = (args[0], kwargs.pop("model"), args[1])
    else:
        return None
    return ("grid_bayes_filter(rss_dbm, cells_m, model, ...)", "grid_bayes_filter(rss_dbm, model, cells_m, ...)",
            args, kwargs)


@old_form(_old_grid_order)
def grid_bayes_filter(rss_dbm, model, cells_m, spread_m: float = 0.5, *, n_steps: int | None = None,
                      velocity_m=None, initial_belief=None, transition: str = "auto") -> BayesFilterResult:
    """Grid-based Bayes filter (Ozkaya 2011, Eqs. (4.10)-(4.15)) over runs ``R`` and steps ``T``.

    ``Bel_t(l) ~ p(z_t | c_l) sum_l' T[l, l'] Bel_t-1(l')`` with :func:`grid_transition_matrix` (its docstring: a
    sampled Gaussian normalised over the grid, edges truncated and renormalised) and the likelihood of ``model``.
    Returns a :class:`BayesFilterResult`: the posterior mean, covariance and MAP cell per step, ``n_eff`` the
    effective number of cells ``1 / sum Bel^2``, and the cells with the final belief as ``particles_m``, ``weights``.

    Likelihood: ``model`` an :class:`~locbook.models.rss.RssModel` and ``rss_dbm`` its readings ``(R, T, m)`` (NaN =
    not heard; :meth:`RssModel.log_likelihood <locbook.models.rss.RssModel.log_likelihood>`), the cells in the
    model's position space; or ``model`` a callable ``log_likelihood(cells (C, dim), t) -> (R, C)`` (the log of
    ``p(z_t | c_l)`` up to a constant per run; any model: a Gaussian position fix, ranges, several sensors) with
    ``rss_dbm=None`` and ``n_steps`` given, the cells ``(C, dim)`` of any dimension, the number of runs that of its
    output. ``velocity_m``: a known displacement per step, ``(dim,)`` or ``(T, dim)`` (the mean of the process model
    in the thesis's constant-velocity experiment). ``initial_belief``: ``(C,)`` or ``(R, C)``; uniform if None.
    The model comes second, as in every RSS filter and estimator; the earlier order, ``(rss_dbm, cells_m,
    model, ...)``, is deprecated (one release: a DeprecationWarning, the same result).

    ``transition``: ``"dense"`` builds the ``C x C`` matrix (memory quadratic in the cells: its construction peaks
    at ``8 C^2 (dim + 3)`` bytes, 4 GB at 10,000 cells in 2-D); ``"separable"`` applies the same transition as one
    small matrix product per axis on the lattice of the cells' distinct coordinates (memory linear in the cells for a
    grid, possibly masked by a floor outline; equal to the dense one up to rounding); ``"auto"`` (default) takes the
    separable form when that lattice has at most 4 points per cell, which every regular grid has. Every array of the
    call (the belief, the outputs, the dense construction's ``C x C x dim`` difference, the separable lattice per run)
    is checked against :data:`MAX_ARRAY_BYTES` before it is allocated: beyond it, a ValueError naming ``cells_m`` (or
    the readings).

    Speed. With an :class:`~locbook.models.rss.RssModel` whose mean does not change with the step (no
    per-step ``ref_power_dbm``, ``path_loss_exp`` or ``sigma_db``; walls allowed), the cell-by-anchor mean table is
    computed once per call (per run for per-run anchors, up to :data:`locbook.models.rss.TABLE_MAX_VALUES` values)
    and each step's log-likelihood from it, by the same arithmetic as :meth:`RssModel.log_likelihood
    <locbook.models.rss.RssModel.log_likelihood>` (the same bits). From :data:`_GRID_MIN_WORK` runs x steps x
    cells on, with numba (``LOCBOOK_NUMBA=0`` turns it off), compiled kernels (:mod:`locbook.tracking._grid_kernels`)
    run the update (likelihood, posterior, moments, MAP, ``n_eff`` in a few passes per run) and, on a lattice whose
    distinct coordinates are evenly spaced per axis (up to three axes; possibly masked), the separable prediction as
    a banded correlation truncated where a kernel entry is below 2^-53 of its column's largest (``|u| > 8.57 D`` away
    from the edges; :class:`_BandedLattice`). Their results equal the numpy path's to about 1e-14 (tests/tracking/
    test_bayes_compiled.py), except where the posterior lies in the far tail of the prediction (readings contradicting
    the motion model by more than about 8 D), where the truncated entries, negligible against their columns, are not
    negligible against the tail.

    A run whose posterior collapses at a step (the likelihood is -inf, or NaN, on every cell the belief allows, e.g.
    a reading of 1e300 dBm) is flagged ``diverged`` with that ``diverged_step``; its estimates and final belief
    are NaN from that step on, and the other runs are unaffected. The call then emits one ``RuntimeWarning`` (the
    number of such runs, the first run and step, its readings); when every run collapses it raises a ValueError
    naming ``rss_dbm`` (or ``log_likelihood``) and the first step instead (nothing can be estimated: a units bug,
    not a result).

    Examples
    --------
    The readings of :func:`locbook.particle_filter`'s example on a 0.5 m grid: the posterior mean is on the bisector
    (x = 5 m), and by symmetry at y = 0.

    >>> import numpy as np
    >>> import locbook as lb
    >>> model = lb.RssModel(np.array([[0.0, 0.0], [10.0, 0.0]]), lb.PathLossModel(-40.0, 2.0, sigma_db=3.0))
    >>> x, y = np.meshgrid(np.arange(0.25, 10.0, 0.5), np.arange(-4.75, 5.0, 0.5), indexing="ij")
    >>> result = lb.grid_bayes_filter(np.full((1, 10, 2), -60.0), model, np.stack([x.ravel(), y.ravel()], -1), 0.5)
    >>> print(result.mean.shape, f"{result.mean[0, -1, 0]:.2f} {abs(result.mean[0, -1, 1]):.2f}")
    (1, 10, 2) 5.00 0.00
    """
    first = None                                    # the callable's step-0 output, which gives the number of runs
    is_model = isinstance(model, MeasurementModel)
    if is_model:
        if rss_dbm is None:
            raise ValueError(f"rss_dbm must be the readings (runs, steps, m) of the {model.label} model")
        rss_dbm, cells_m = _check_inputs(rss_dbm, model, cells_m=cells_m)
        if n_steps is not None and n_steps != rss_dbm.shape[1]:
            raise ValueError(f"n_steps {n_steps} disagrees with the {rss_dbm.shape[1]} steps of rss_dbm")
        n_runs, n_steps, _ = rss_dbm.shape
        detail, what = _reading_detail(rss_dbm), _LIKELIHOOD
        fixed = {}                                  # the model's likelihood on the cells, made once

        def log_likelihood(t):
            if "ll" not in fixed:
                fixed["ll"] = _points_log_likelihood(model, rss_dbm, cells_m, n_runs)
            return fixed["ll"](t)
    elif callable(model):
        n_steps = _callable_steps(rss_dbm, n_steps)
        cells_m = as_array("cells_m", cells_m, ndim=2)
        if cells_m.shape[1] < 1:
            raise ValueError(f"cells_m must have shape (C, dim) with dim >= 1, got {cells_m.shape}")
        detail, what, n_runs, fixed = None, "log_likelihood", None, {}

        def log_likelihood(t):
            ll = np.asarray(model(cells_m, t), dtype=float)
            if ll.ndim != 2 or ll.shape[1] != cells_m.shape[0] or n_runs is not None and ll.shape[0] != n_runs:
                raise ValueError(f"log_likelihood must return (runs, C) = ({n_runs or 'runs'}, {cells_m.shape[0]}) "
                                 f"at every step, got {ll.shape} at step {t}")
            return ll
    else:
        raise ValueError(f"model must be an RssModel or a callable log_likelihood(cells, t) (or any measurement "
                         f"model, locbook.models.base), got {type(model).__name__}")
    check_scalar("spread_m", spread_m, gt=0, allow_inf=True)
    check_choice("transition", transition, GRID_TRANSITIONS)
    n_cells, dim = cells_m.shape
    if n_cells == 0:
        raise ValueError(f"cells_m must hold at least one cell, got shape {cells_m.shape}")
    velocity = _velocity_schedule(velocity_m, n_steps, dim)
    if n_runs is None:
        first = log_likelihood(0)
        n_runs = first.shape[0]
    if initial_belief is not None:
        initial_belief = as_array("initial_belief", initial_belief)
        if initial_belief.shape not in ((n_cells,), (n_runs, n_cells)):
            raise ValueError(f"initial_belief must have shape ({n_cells},) or ({n_runs}, {n_cells}), "
                             f"got {initial_belief.shape}")
        if np.any(initial_belief < 0) or np.any(initial_belief.sum(axis=-1) <= 0):
            raise ValueError("initial_belief must be non-negative with a positive sum over the cells")
    # size guards (MAX_ARRAY_BYTES), before anything of the size of the grid is allocated
    runs_name = "rss_dbm" if is_model else "log_likelihood"
    _check_size("cells_m", "the belief (runs x cells)", (n_runs, n_cells), "use fewer cells or run the runs in blocks")
    _check_size(runs_name, "the covariance output (runs x steps x dim x dim)", (n_runs, n_steps, dim, dim),
                "run the runs or the steps in blocks")
    lattice = _SeparableTransition.lattice_size(cells_m)
    use_separable = transition == "separable" or transition == "auto" and lattice <= 4 * n_cells
    if use_separable:                                # its mask, and with a finite spread one lattice per run
        _check_size("cells_m", f"the separable transition's lattice of the cells' distinct coordinates (runs x "
                    f"lattice points, for {n_cells:,} cells)", (1 if np.isinf(spread_m) else max(n_runs, 1), lattice),
                    "cells on a regular grid keep the lattice near the number of cells; scattered cells take "
                    "transition='auto'")
    elif not use_separable and n_steps > 1:
        _check_size("cells_m", "the dense transition (cells x cells" + (")" if np.isinf(spread_m) else
                                                                        " x dim to build)"),
                    (n_cells, n_cells) if np.isinf(spread_m) else (n_cells, n_cells, max(dim, 1)), _DENSE_HINT)
    belief = (np.full((n_runs, n_cells), 1.0 / n_cells) if initial_belief is None
              else np.broadcast_to(np.asarray(initial_belief, float), (n_runs, n_cells)).copy())
    mean = np.empty((n_runs, n_steps, dim))
    cov = np.empty((n_runs, n_steps, dim, dim))
    best = np.empty((n_runs, n_steps, dim))
    n_eff = np.empty((n_runs, n_steps))
    separable = banded = None
    if use_separable:
        separable = _SeparableTransition(cells_m, spread_m)
    if is_model and n_steps:
        table = _MEAN_TABLES.get(type(model))            # a Gaussian model's mean table: the kernels' likelihood
        table = table(model, cells_m, n_runs) if table is not None else None
        if table is not None:
            fixed["table"], fixed["sigma"] = table
            fixed["ll"] = model.points_log_likelihood(rss_dbm, cells_m, n_runs, table=table)
        else:
            fixed["ll"] = _points_log_likelihood(model, rss_dbm, cells_m, n_runs)
    kernels = None
    if n_runs * n_steps * n_cells >= _GRID_MIN_WORK:
        kernels = _grid_kernels()
        if kernels is not None and separable is not None:
            banded = _BandedLattice.build(cells_m, spread_m)
    dense: np.ndarray | None
    last_v: Any        # the velocity dense is for (None: not built yet)
    dense, last_v = None, None
    dead = np.zeros(n_runs, bool)
    dead_step = np.full(n_runs, -1, np.int64)
    if kernels is not None:
        points = np.ascontiguousarray(cells_m.T)
        llb, wb = np.empty(n_cells), np.empty(n_cells)
        step_mean, step_cov = np.empty((n_runs, dim)), np.empty((n_runs, dim, dim))
        step_best, step_n_eff = np.zeros(n_runs, np.int64), np.empty(n_runs)
        use_table = "table" in fixed
        table_t = (np.ascontiguousarray(np.swapaxes(fixed["table"], 1, 2)) if use_table else np.zeros((1, 1, 1)))
        inv_sigma = (np.broadcast_to(1.0 / np.asarray(fixed["sigma"], float), (rss_dbm.shape[2],)).copy()
                     if use_table else np.zeros(1))
    for t in range(n_steps):
        if t > 0:
            predicted = None
            if banded is not None:
                predicted = banded.predict(belief, velocity[t], dead, kernels)
            if predicted is None and separable is not None:
                predicted = separable.predict(belief, velocity[t])
            if predicted is None:
                if dense is None or not np.array_equal(velocity[t], last_v):
                    dense, last_v = grid_transition_matrix(cells_m, spread_m, velocity[t]), velocity[t]
                predicted = belief @ dense.T
            belief = predicted
        if kernels is not None:                     # the fused update (_grid_kernels._nb_update)
            belief = np.ascontiguousarray(belief)
            ll = None if use_table else np.ascontiguousarray(
                first if t == 0 and first is not None else log_likelihood(t), dtype=float)
            hit = np.zeros(n_runs, np.bool_)
            kernels._nb_update(belief, np.zeros((1, 1)) if ll is None else ll, use_table, table_t,
                               np.ascontiguousarray(rss_dbm[:, t]) if use_table else np.zeros((1, 1)), inv_sigma,
                               dead, points, llb, wb, step_mean, step_cov, step_best, step_n_eff, hit)
            collapsed = hit & ~dead
        else:
            log_post = np.log(np.maximum(belief, 1e-300)) + (first if t == 0 and first is not None
                                                             else log_likelihood(t))
            top = log_post.max(axis=-1)
            collapsed = ~dead & (np.isnan(top) | np.isinf(top))
        dead_step[collapsed] = t
        dead |= collapsed
        if n_runs and dead.all():
            raise _collapse_error(dead_step, what, detail)
        if kernels is not None:
            mean[:, t], cov[:, t], best[:, t], n_eff[:, t] = step_mean, step_cov, cells_m[step_best], step_n_eff
        else:
            if dead.any():          # a collapsed run goes on with a uniform belief (NaN outputs): others unaffected
                log_post[dead] = 0.0
            belief = _normalise_log(log_post)
            mean[:, t], cov[:, t] = weighted_moments(belief, cells_m)
            best[:, t] = cells_m[np.argmax(belief, axis=-1)]
            n_eff[:, t] = effective_sample_size(belief)
        if dead.any():
            mean[dead, t], cov[dead, t], best[dead, t], n_eff[dead, t] = np.nan, np.nan, np.nan, np.nan
    if dead.any():
        belief = belief.copy()
        belief[dead] = np.nan
        _warn_collapse(dead, dead_step, "grid_bayes_filter", what, detail)
    return BayesFilterResult(mean, cov, best, n_eff, np.zeros((n_runs, n_steps), bool),
                             np.broadcast_to(cells_m, (n_runs,) + cells_m.shape), belief, dead, dead_step)
