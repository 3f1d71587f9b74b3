"""A general sampling-importance-resampling (bootstrap) particle filter, vectorized over runs and particles.

Palvai (2008), Sec. 5.3.1 (after Arulampalam et al. 2002): at every step k

    1. draw x_k^(i) ~ p(x_k | x_{k-1}^(i))                 (the transition prior: here a Gaussian random walk)
    2. w_k^(i) ∝ w_{k-1}^(i) p(z_k | x_k^(i))              (uniform previous weights after a resampling)
    3. normalise; record the estimates
    4. resample: at every step (SIR), or where N_eff = 1 / sum w^2 falls below a threshold

The measurement model enters only through ``log_likelihood(particles, k)``, so one filter serves any schedule of
measurements (one receiver per step, all receivers every step, cycling through them; fresh or frozen shadowing):
the caller decides what step k observes. :func:`rss_log_likelihood` is the log-distance RSS likelihood with
missing readings (NaN = not heard) left out.

Estimates per step: the weighted mean (MMSE) and variance, the highest-weight particle; at the end, a kernel
density MAP (:func:`kernel_map_estimate`).

A collapsed run is isolated (issue 26): where a run's log-likelihood is -inf for every particle (no particle
explains the reading), or NaN or +inf for any particle (garbage), its weights cannot be normalised. That run is
flagged ``degenerate`` with the first such step (``degenerate_step``, -1 elsewhere), its estimates are NaN from that
step on and its final particles and weights are NaN; the other runs go on as if that run were sane (its particles are
still propagated and resampled with equal weights, so with systematic or stratified resampling, whose random draws
do not depend on the weights, the other runs are bit-identical). -inf for some particles only is a zero weight.
A collapse is never silent: the call emits one ``RuntimeWarning`` with the number of collapsed runs and the first
(run, step); when EVERY run collapses (nothing can be estimated: typically a units bug, or a likelihood that overflows)
it raises a ValueError naming ``log_likelihood`` and the first step and run instead of returning NaN.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._validate import as_array, check_scalar
from ..models.channel import PathLossModel
from .bayes import _collapse_error, _warn_collapse
from .resampling import RESAMPLING_METHODS, resample

__all__ = ["SirResult", "sir_particle_filter", "rss_log_likelihood", "kernel_map_estimate"]


@dataclass(frozen=True)
class SirResult:
    """Per run and step: ``mean`` and ``variance`` ``(R, K, dim)`` of the weighted particles, ``max_weight``
    ``(R, K, dim)`` the highest-weight particle, ``n_eff`` ``(R, K)`` before resampling and ``resampled``
    ``(R, K)``; the final ``particles`` ``(R, Ns, dim)`` and ``weights`` ``(R, Ns)``; ``clouds``: the particles
    (after the update, before resampling) at the steps asked for, ``{k: (R, Ns, dim)}``; ``degenerate`` ``(R,)`` and
    ``degenerate_step`` ``(R,)``: runs whose likelihood collapsed, and the step (module docstring)."""

    mean: np.ndarray
    variance: np.ndarray
    max_weight: np.ndarray
    n_eff: np.ndarray
    resampled: np.ndarray
    particles: np.ndarray
    weights: np.ndarray
    clouds: dict
    degenerate: np.ndarray = None
    degenerate_step: np.ndarray = None

    @property
    def n_degenerate(self) -> int:
        """The number of runs whose likelihood collapsed (module docstring)."""
        return 0 if self.degenerate is None else int(np.count_nonzero(self.degenerate))


def rss_log_likelihood(particles_m, receivers_m, power_dbm, channel: PathLossModel, *, min_distance_m: float = 1e-3):
    """``log p(z | x)`` up to a constant for every particle: ``-sum_j (z_j - h_j(x))^2 / (2 sigma^2)`` over the heard
    readings ``j`` (NaN = not heard, left out), ``h_j`` the log-distance mean power from receiver ``j``.

    ``particles_m`` ``(R, Ns, dim)``; ``receivers_m`` ``(m, dim)`` or per run ``(R, m, dim)``; ``power_dbm``
    ``(R, m)``. Accumulated one receiver at a time, so memory stays ``O(R Ns)``."""
    x = np.asarray(particles_m, dtype=float)
    s = np.asarray(receivers_m, dtype=float)
    z = np.asarray(power_dbm, dtype=float)
    m = z.shape[-1]
    if s.shape[-2] != m:
        raise ValueError(f"receivers_m has {s.shape[-2]} receivers, power_dbm {m} readings")
    p0 = np.broadcast_to(np.asarray(channel.ref_power_dbm, float), (m,))
    ple = np.broadcast_to(np.asarray(channel.path_loss_exp, float), (m,))
    var = np.broadcast_to(np.asarray(channel.sigma_db, float) ** 2, (m,))
    if np.any(var <= 0):
        raise ValueError("the likelihood needs sigma_db > 0 (a zero-noise likelihood is a delta)")
    out = np.zeros(x.shape[:-1])
    for j in range(m):
        zj = z[..., j]
        heard = np.isfinite(zj)
        if not heard.any():
            continue
        sj = s[..., j, :] if s.ndim == 2 else s[:, j, :]
        diff = x - (sj if s.ndim == 2 else sj[:, None, :])
        d2 = np.einsum("...i,...i->...", diff, diff)
        # the log-distance mean from d^2 (log10 d = log10(d^2) / 2; the same clamp), without a square root
        d2 = np.maximum(d2, min_distance_m**2) if min_distance_m > 0 else d2
        resid = np.where(heard, zj - p0[j] - 10 * ple[j] * np.log10(channel.ref_distance_m), 0.0)[:, None] \
            + 5.0 * ple[j] * np.log10(d2)
        out -= np.where(heard[:, None], resid**2, 0.0) / (2 * var[j])
    return out


def kernel_map_estimate(particles_m, weights, *, bandwidth_m=None, n_candidates: int = 256):
    """The mode of a weighted Gaussian kernel density of the particles ``(R, Ns, dim)``: the density is evaluated at
    the ``n_candidates`` highest-weight particles and the best is returned ``(R, dim)``. ``bandwidth_m``: None
    gives Silverman's rule per run from the weighted spread."""
    x = as_array("particles_m", particles_m, ndim=3)
    w = as_array("weights", weights, ndim=2)
    R, n, dim = x.shape
    k = min(int(n_candidates), n)
    top = np.argsort(-w, axis=-1)[:, :k]
    cand = np.take_along_axis(x, top[..., None], axis=1)                        # (R, k, dim)
    if bandwidth_m is None:
        mean = np.einsum("rn,rnd->rd", w, x)
        spread = np.sqrt(np.einsum("rn,rnd->rd", w, (x - mean[:, None]) ** 2).mean(axis=-1))
        n_eff = 1.0 / np.einsum("rn,rn->r", w, w)
        h = 1.06 * spread * n_eff ** (-1.0 / (dim + 4))
    else:
        h = np.broadcast_to(check_scalar("bandwidth_m", bandwidth_m, gt=0), (R,))
    h = np.maximum(h, 1e-12)
    dens = np.zeros((R, k))
    for start in range(0, n, 2048):                                             # chunks keep memory O(R k 2048)
        xs, ws = x[:, start:start + 2048], w[:, start:start + 2048]
        d2 = np.sum((cand[:, :, None, :] - xs[:, None, :, :]) ** 2, axis=-1)
        dens += np.einsum("rkn,rn->rk", np.exp(-0.5 * d2 / h[:, None, None] ** 2), ws)
    return np.take_along_axis(cand, np.argmax(dens, axis=-1)[:, None, None], axis=1)[:, 0]


def sir_particle_filter(initial_particles_m, log_likelihood, n_steps: int, rng: np.random.Generator, *,
                        process_sd_m=0.0, resampling: str = "systematic", resample_threshold=None,
                        cloud_steps=()) -> SirResult:
    """Bootstrap SIR filter (module docstring) from ``initial_particles_m`` ``(R, Ns, dim)`` (equal weights) over
    ``n_steps`` steps. ``log_likelihood(particles (R, Ns, dim), k) -> (R, Ns)``; ``process_sd_m``: the random
    walk's standard deviation per step (scalar or ``(dim,)``; Palvai's sigma_2), drawn before each update;
    ``resampling``: one of :data:`locbook.RESAMPLING_METHODS`; ``resample_threshold``: None resamples at every step
    (SIR), a number resamples where ``N_eff`` is below it (e.g. ``Ns / 3``)."""
    x = as_array("initial_particles_m", initial_particles_m, ndim=3).copy()
    if resampling not in RESAMPLING_METHODS:
        raise ValueError(f"resampling must be one of {RESAMPLING_METHODS}, got {resampling!r}")
    check_scalar("n_steps", n_steps, ge=1, integer=True)
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    R, n, dim = x.shape
    if n == 0:
        raise ValueError(f"initial_particles_m must hold at least one particle per run, got shape {x.shape}")
    sd = np.broadcast_to(as_array("process_sd_m", process_sd_m), (dim,))
    if np.any(sd < 0):
        raise ValueError("process_sd_m must be >= 0")
    logw = np.full((R, n), -np.log(n))
    mean = np.empty((R, n_steps, dim))
    var = np.empty((R, n_steps, dim))
    best = np.empty((R, n_steps, dim))
    n_eff = np.empty((R, n_steps))
    did = np.zeros((R, n_steps), bool)
    clouds = {}
    dead = np.zeros(R, bool)
    dead_step = np.full(R, -1, np.int64)
    for k in range(int(n_steps)):
        if np.any(sd > 0):
            x = x + sd * rng.standard_normal(x.shape)
        ll = np.asarray(log_likelihood(x, k), dtype=float)
        if ll.shape != (R, n):
            raise ValueError(f"log_likelihood must return ({R}, {n}), got {ll.shape}")
        logw = logw + ll
        top = logw.max(axis=-1)
        collapsed = ~dead & (np.isnan(top) | np.isinf(top))      # NaN anywhere, +inf anywhere, or -inf everywhere
        dead_step[collapsed] = k
        dead |= collapsed
        if R and dead.all():
            raise _collapse_error(dead_step, "log_likelihood")
        if dead.any():              # a collapsed run goes on with equal weights (its outputs are NaN): others unaffected
            logw[dead] = 0.0
        logw = logw - logw.max(axis=-1, keepdims=True)
        w = np.exp(logw)
        w /= w.sum(axis=-1, keepdims=True)
        logw = np.log(np.maximum(w, 1e-300))
        mean[:, k] = np.einsum("rn,rnd->rd", w, x)
        var[:, k] = np.einsum("rn,rnd->rd", w, (x - mean[:, k, None]) ** 2)
        best[:, k] = np.take_along_axis(x, np.argmax(w, axis=-1)[:, None, None], axis=1)[:, 0]
        n_eff[:, k] = 1.0 / np.einsum("rn,rn->r", w, w)
        if k in cloud_steps:
            clouds[k] = x.copy()
        do = np.ones(R, bool) if resample_threshold is None else n_eff[:, k] < resample_threshold
        if do.any():
            idx = resample(w, rng, resampling)
            x = np.where(do[:, None, None], np.take_along_axis(x, idx[..., None], axis=1), x)
            logw = np.where(do[:, None], -np.log(n), logw)
        did[:, k] = do & ~dead
        if dead.any():
            for out in (mean, var, best):
                out[dead, k] = np.nan
            n_eff[dead, k] = np.nan
            if k in cloud_steps:
                clouds[k][dead] = np.nan
    w = np.exp(logw)
    w /= w.sum(axis=-1, keepdims=True)
    if dead.any():
        x, w = x.copy(), w.copy()
        x[dead], w[dead] = np.nan, np.nan
        _warn_collapse(dead, dead_step, "sir_particle_filter", "log_likelihood")
    return SirResult(mean, var, best, n_eff, did, x, w, clouds, dead, dead_step)
