"""The particle filter: bootstrap sampling-importance-resampling (SIR), vectorized over runs and particles, with the
improved SIR of Ozkaya (2011) as options of it.

Palvai (2008), Sec. 5.3.1, and Ozkaya (2011), Tables 4.3-4.4 (after Arulampalam et al. 2002): at every step t

    1. predict: x_t^(i) ~ p(x_t | x_t-1^(i))             (from step 1 on; step 0 updates the prior)
    2. update:  w_t^(i) ~ w_t-1^(i) p(z_t | x_t^(i))       (Eq. (4.34); uniform previous weights after a resampling)
    3. normalise; record the estimates (:class:`ParticleFilterResult`, a
       :class:`~locbook.tracking.bayes.BayesFilterResult` with the final log-weights)
    4. resample (any scheme of :mod:`locbook.tracking.resampling`): at every step (SIR), on a schedule, or where
       N_eff = 1 / sum w^2 falls below a fraction of N (the one ESS convention, as the ``particles`` package has it)

The likelihood is an :class:`~locbook.models.rss.RssModel` with its readings, or any callable
``log_likelihood(particles (R, N, dim), t) -> (R, N)``. The motion model is one of

- the reflected random walk ``x_t = x_t-1 + v_t + N(0, D^2 I)`` (Ozkaya Eq. (4.2); Palvai's sigma_2), the default;
- a linear kinematic model (``motion=``: :func:`~locbook.models.motion.constant_velocity`,
  :func:`~locbook.models.motion.constant_acceleration`, any model with ``F``, ``Q`` and ``position_index``):
  the particles carry the full state and move by ``x_t = F x_t-1 + w_t``, ``w_t ~ N(0, Q)`` (Bar-Shalom et al. 2001,
  Sec. 6.3; the bootstrap proposal of Arulampalam et al. 2002, Sec. V-A). Q is often singular (the discrete
  white-noise Q = q G G^T has rank dim), so w is drawn as ``sqrt(q) G n`` with ``n ~ N(0, I_dim)``, or from an
  eigen-factor of Q (never a Cholesky factor, which does not exist for a singular Q); the RSS likelihood sees the
  positions ``x[..., position_index]``;
- any callable ``transition(particles, t, rng) -> particles``.

One run may be given without the run axis (readings ``(T, m)``, or with a callable likelihood the particles
``(N, dim)`` or the start ``(dim,)``): the callables then see ``(N, dim)`` and return ``(N,)`` / ``(N, dim)``, and
every output of the result loses its leading run axis.

A collapsed run is isolated: where a run's log-likelihood is -inf for every particle (no particle
explains the reading), or NaN or +inf for any particle (garbage), its weights cannot be normalised. That run is
flagged ``diverged`` with the first such step (``diverged_step``, -1 elsewhere), its estimates are NaN from that
step on and its final particles and weights are NaN; the other runs go on as if that run were sane (its particles are
still propagated and resampled with equal weights; every resampling draw is made for every run whether or not it
resamples, so the other runs are bit-identical). -inf for some particles only is a zero weight.
A collapse is never silent: the call emits one ``RuntimeWarning`` with the number of collapsed runs and the first
(run, step); when EVERY run collapses (nothing can be estimated: typically a units bug, or a likelihood that overflows)
it raises a ValueError naming the likelihood and the first step and run instead of returning NaN.

Compiled path: from :data:`_NUMBA_MIN_PARTICLES` particles in all (runs x N) on, with numba installed and
not turned off (``LOCBOOK_NUMBA=0``), the kernels of :mod:`locbook.tracking._particle_kernels` run the hot loop with
no temporaries of the size of the cloud: an RssModel's log-likelihood in one pass over the particles
(:func:`_fused_rss_log_likelihood`, walls included), the default random walk in place, and,
with ``weight_smoothing="none"``, the normalisation, the moments, N_eff and systematic resampling (``"standard"``
cumulative sum; the other schemes draw in numpy). The random stream is the numpy path's draw for draw, and so are the
normalisation's sum (numpy's pairwise sum) and the systematic ancestors given the weights; the likelihood and the
weights differ from numpy's in the last bits (the likelihood's log10 and the normalisation's exp are within 2 ulp of
numpy's, the sum over the anchors is in order), so the weights agree to about 1e-14 relative, the resampling decisions
and particles are the numpy path's unless a sample point falls within that of a cumulative weight, and the estimates
agree to round-off (tests/tracking/test_particle_compiled.py).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .._deprecation import keyword_rng
from .._linalg import psd_root
from .._validate import as_array, check_choice, check_scalar
from ..models.base import LinearMotion, MeasurementModel, MotionModel
from ..models.motion import reflect_into_box
from ..models.rss import RssModel
from . import _compiled
from .bayes import (
    _LIKELIHOOD,
    BayesFilterResult,
    _callable_steps,
    _check_inputs,
    _check_size,
    _collapse_error,
    _normalise_log,
    _reading_detail,
    _velocity_schedule,
    _warn_collapse,
    weighted_moments,
)
from .resampling import RESAMPLING_CDFS, RESAMPLING_METHODS, effective_sample_size, resample, systematic_resample

__all__ = ["particle_filter", "ParticleFilterResult", "kernel_map_estimate", "WEIGHT_SMOOTHINGS"]

WEIGHT_SMOOTHINGS = ("none", "sqrt", "sqrt_corrected")

#: the random walk's step D when ``spread_m`` is not given (m)
DEFAULT_SPREAD_M = 0.5
#: the compiled kernels run from this many particles (runs x N) on; smaller filters stay in numpy (no compilation
#: wait for a few hundred particles). Read at call time (tests set it to 0).
_NUMBA_MIN_PARTICLES = 20000
#: the compiled random walk draws its normals in blocks of runs of about this many values (the same stream as one
#: draw of the whole cloud, in a buffer of 512 KiB)
_NOISE_BLOCK_VALUES = 1 << 16


def _trial():
    """A tiny problem for the particle kernels (compiled or loaded once per session: _compiled._kernel_module)."""
    x, w, z1 = np.zeros((1, 2, 2)), np.full((1, 2), 0.5), np.zeros((1, 2))

    def run(K):
        K._nb_rss_loglik(x, np.arange(2), np.ones((1, 1, 2)), np.zeros((1, 1)), np.zeros((1, 1)), np.zeros((1, 1)),
                         np.ones((1, 1)), np.ones((1, 1)), False, 0.1, 1.0, np.zeros((0, 2, 2)), 0.0, z1.copy())
        K._nb_random_walk(x.copy(), np.zeros(2), np.ones(2), x, True, np.zeros(2), np.ones(2), True)
        K._nb_normalise(z1.copy(), z1.copy(), np.zeros(1, bool), w.copy(), z1.copy(), True, np.zeros(1, bool))
        K._nb_moments(w, x, np.zeros((1, 2)), np.zeros((1, 2, 2)), np.zeros((1, 2)), np.zeros(1))
        K._nb_systematic(w, np.zeros(1), np.ones(1, bool), x, x.copy(), z1.copy())
    return run


def _use_compiled(n_particles: int) -> bool:
    """True when the compiled kernels should run for ``n_particles`` in all (the compiled paths on and the kernels
    working here: :func:`locbook.tracking._compiled._kernel_module`)."""
    return n_particles >= _NUMBA_MIN_PARTICLES and _compiled._kernel_module(
        "locbook.tracking._particle_kernels", _trial, "particle filter", stacklevel=4) is not None


def _fused_rss_log_likelihood(model: RssModel, rss_dbm, particles, step: int, position_index=None, out=None):
    """``model.log_likelihood(rss_dbm, particles[..., position_index], step, constant=False)`` ``(R, N)`` in one
    compiled pass over the particles (:func:`~locbook.tracking._particle_kernels._nb_rss_loglik`: distance, clamp,
    tag height, walls, per-anchor or per-run parameters and anchors, NaN readings left out), with no ``(R, N, m)``
    temporary. ``rss_dbm`` ``(R, m)`` checked readings; ``particles`` ``(R, N, n)`` or shared ``(N, n)``;
    ``position_index`` the position columns (default the first ``model.dim``); ``out`` an ``(R, N)`` buffer.
    None when the wall loss is not one number (the numpy path covers it). Coordinates or distances that are not
    finite are handed to :meth:`~locbook.models.rss.RssModel.log_likelihood`, which raises its error."""
    ch = model.channel
    waf = np.asarray(ch.wall_attenuation_db, dtype=float)
    with_walls = model.walls_m is not None and bool(np.any(waf != 0.0))
    if with_walls and waf.ndim != 0:
        return None
    walls = np.ascontiguousarray(model.walls_m, dtype=float) if with_walls else np.zeros((0, 2, 2))
    from . import _particle_kernels as K  # lazy: numba loads only when the compiled path runs
    sigma = np.asarray(model.sigma_at(step), dtype=float)
    z = np.ascontiguousarray(rss_dbm, dtype=float)
    x = np.asarray(particles, dtype=float)
    x3 = x if x.ndim == 3 else x[None]
    m, dim = model.n_anchors, model.dim
    pidx = np.arange(dim, dtype=np.int64) if position_index is None else np.asarray(position_index, np.int64)
    assert isinstance(model.anchors_m, np.ndarray)  # per-step anchors: refused by the filter's input check
    anchors = model.anchors_m if model.anchors_m.ndim == 3 else model.anchors_m[None]
    plan = np.ascontiguousarray(anchors[..., :dim], dtype=float)
    vert2 = (np.zeros((1, m)) if model.tag_height_m is None
             else np.ascontiguousarray(np.square(anchors[..., -1] - model.tag_height_m)))

    ch_t = model.channel_at(step)

    def per_step(value):                          # (1|R, m) at the step
        value = np.asarray(value, dtype=float)
        return np.ascontiguousarray(value if value.ndim == 2 else np.broadcast_to(value, (m,))[None])

    tenn = 10.0 * np.asarray(ch_t.path_loss_exp, dtype=float)     # numpy's (10 n) log10(d / d0), the same rounding
    per_anchor = sigma.ndim == 1
    sig = (sigma[None] if per_anchor else sigma.reshape(-1, 1)).astype(float)
    R = z.shape[0]
    out = np.empty((R, x3.shape[1])) if out is None else out
    if K._nb_rss_loglik(x3, pidx, plan, vert2, z, per_step(ch_t.ref_power_dbm), per_step(tenn),
                        np.ascontiguousarray(sig), per_anchor, float(ch.min_distance_m), float(ch.ref_distance_m),
                        walls, float(waf) if with_walls else 0.0, out):
        return out
    positions = x if position_index is None else x[..., pidx]
    return model.log_likelihood(z, positions, step, constant=False)


# The compiled likelihoods, a registry keyed by model type (exact type): a model without one is evaluated by its
# own relative_log_likelihood in numpy.
_FUSED_LIKELIHOODS = {RssModel: _fused_rss_log_likelihood}


@dataclass(frozen=True)
class ParticleFilterResult(BayesFilterResult):
    """:class:`~locbook.tracking.bayes.BayesFilterResult` of :func:`particle_filter`, with ``log_weights``
    ``(R, N)``: the final normalised log-weights, computed in the log domain at the last update (``-inf`` = a zero
    weight; ``exp(log_weights)`` equals ``weights`` except below 1e-300, where ``weights`` keeps the filter's floor;
    NaN for a collapsed run). With ``motion=`` the estimates and particles are over the full state ``n`` (``mean``
    ``(R, T, n)``, ``cov`` ``(R, T, n, n)``, ``particles_m`` ``(R, N, n)``: positions in m, velocities in m/s, ...;
    ``position_m(motion.position_index)`` the positions). For a single run (no run axis given) every array lacks the
    leading ``R`` axis (``diverged`` and ``diverged_step`` are 0-d)."""

    log_weights: np.ndarray | None = None


def _check_rng(rng) -> None:
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")


def _region(region_m, dim: int | None):
    if len(region_m) != 2:
        raise ValueError(f"region_m must be (lower, upper) corners, got {region_m!r}")
    trailing = (None,) if dim is None else (dim,)
    lower, upper = (as_array(name, b, ndim=1, trailing=trailing)
                    for name, b in zip(("region_m lower", "region_m upper"), region_m))
    if lower.shape != upper.shape or np.any(upper <= lower):
        raise ValueError(f"region_m needs upper > lower on every axis, got {lower.tolist()} and {upper.tolist()}")
    return lower, upper


def _check_cloud(name: str, shape) -> None:
    """Refuse a particle cloud ``(runs, N, state)`` over :data:`~locbook.tracking.bayes.MAX_ARRAY_BYTES` before it is
    drawn (the filter holds a few: the particles, the moved copy, the resampling target)."""
    R, N, d = shape
    _check_size(name, "a particle cloud (runs x particles x state values)", (R, N, d),
                "use fewer particles, or run the runs in blocks")


class _Motion:
    """The motion given as ``motion=``: any :class:`~locbook.models.base.MotionModel` with ``position_index`` (a
    peer's object with ``F``, ``Q`` and ``position_index`` is taken as the linear model ``LinearMotion(F, Q)``),
    moved by ``x_t = f_t(x) + L_t e``, ``e ~ N(0, I)`` (:meth:`~locbook.models.base.MotionModel.noise_factor`), and
    mirrored at the walls of a region (:meth:`~locbook.models.base.MotionModel.mirrored_index`)."""

    def __init__(self, motion):
        if not isinstance(motion, MotionModel):
            if not all(hasattr(motion, a) for a in ("F", "Q", "position_index")):
                raise ValueError(f"motion must be a motion model (locbook.models.base.MotionModel: a KinematicModel, "
                                 f"constant_velocity, ...) with position_index, or a model with F, Q and "
                                 f"position_index, got {type(motion).__name__}")
            F = as_array("motion.F", motion.F, ndim=2)
            if F.shape != (F.shape[0],) * 2:
                raise ValueError(f"motion.F must be square, got shape {F.shape}")
            Q = as_array("motion.Q", motion.Q, ndim=2)
            if Q.shape != F.shape:
                raise ValueError(f"motion.Q must have the shape {F.shape} of motion.F, got {Q.shape}")
            position_index, motion = motion.position_index, LinearMotion(F, Q, name=type(motion).__name__)
        elif not hasattr(motion, "position_index"):
            raise ValueError(f"motion {motion.label} needs position_index (the state's position components, which the "
                             f"likelihood and region_m read)")
        else:
            position_index = motion.position_index
        self.model = motion
        self.position_index = np.asarray(position_index, dtype=np.int64).ravel()
        n = getattr(motion, "n_state", None)
        self.n_state = int(n) if n is not None else (motion.F.shape[-1] if motion.linear else None)
        mirrored = motion.mirrored_index()
        self.derivatives = None if mirrored is None else np.asarray(mirrored, dtype=np.int64)
        self.root = motion.noise_factor(0)      # refused here when not positive semi-definite
        self._root_step, self._root_Q = 0, np.asarray(motion.covariance(0), dtype=float)

    def state_from_positions(self, positions):
        out = np.zeros(positions.shape[:-1] + (self.n_state,))
        out[..., self.position_index] = positions
        return out

    def mirror(self, x, lower, upper):
        """Fold the positions into the box as :func:`~locbook.models.motion.reflect_into_box` does, and reverse the
        velocity and acceleration on every axis reflected an odd number of times (the mirror image of the motion)."""
        width = upper - lower
        folded = np.mod(x[..., self.position_index] - lower, 2.0 * width)
        back = folded > width
        x[..., self.position_index] = lower + np.where(back, 2.0 * width - folded, folded)
        sign = np.where(back, -1.0, 1.0)
        for idx in self.derivatives:
            x[..., idx] *= sign
        return x

    def _root(self, t: int):
        """The noise factor at step ``t``: the last one again while the model's covariance is the same matrix (the
        factor's eigen-decomposition is done once for a constant Q)."""
        if t != self._root_step:
            Q = np.asarray(self.model.covariance(t), dtype=float)
            if not np.array_equal(Q, self._root_Q):
                self.root, self._root_Q = self.model.noise_factor(t), Q
            self._root_step = t
        return self.root

    def step(self, x, t, rng, bounds):
        x = np.asarray(self.model.apply(x, t), dtype=float)
        root = self._root(t)
        if root is not None:
            x = x + rng.standard_normal(x.shape[:-1] + (root.shape[-1],)) @ root.T
        return x if bounds is None else self.mirror(x, *bounds)


@keyword_rng(2)
def particle_filter(rss_dbm, model, *, rng: np.random.Generator, n_steps: int | None = None,
                    n_particles: int | None = None, region_m=None, initial_particles_m=None, initial_position_m=None,
                    initial_sd_m: float = 0.0, initial_covariance=None, spread_m=None, velocity_m=None,
                    transition=None, motion=None, resampling: str = "systematic",
                    resample_threshold: float | None = None, resample_every: int | None = None,
                    weight_smoothing: str = "none", resampling_cdf: str = "standard",
                    cloud_steps=()) -> ParticleFilterResult:
    """Bootstrap SIR particle filter and Ozkaya's improved SIR (module docstring; Ozkaya 2011, Tables 4.3-4.4,
    Sec. 7.1.4; Palvai 2008, Sec. 5.3.1), over runs ``R`` and steps ``T``.

    Likelihood: ``model`` an :class:`~locbook.models.rss.RssModel` and ``rss_dbm`` its readings ``(R, T, m)`` (NaN =
    not heard), or ``model`` a callable ``log_likelihood(particles (R, N, dim), t) -> (R, N)`` with ``rss_dbm=None``
    and ``n_steps`` given.

    Prior (step 0, no prediction): ``initial_particles_m`` ``(R, N, dim)``; or ``n_particles`` drawn uniform in
    ``region_m = (lower, upper)``; or all at ``initial_position_m`` ``(R, dim)`` (a known start, Table 7.21), drawn
    from ``N(initial_position_m, initial_sd_m^2 I)`` (reflected into ``region_m`` when given) when
    ``initial_sd_m > 0`` (the Gaussian prior the posterior CRLB assumes), or from
    ``N(initial_position_m, initial_covariance)`` (``(dim, dim)`` or ``(R, dim, dim)``, positive semi-definite).

    Proposal = process model (bootstrap, Eq. (4.33)): ``transition(particles, t, rng)``, or by default
    ``x_t = x_t-1 + v_t + N(0, D^2 I)`` with ``D = spread_m`` (a scalar or one per axis, default
    :data:`DEFAULT_SPREAD_M`; 0 draws nothing) and ``v_t = velocity_m`` (``(dim,)`` or ``(T, dim)``), reflected into
    ``region_m`` when given (the room, or the accessible part of it: Table 7.22). ``spread_m = inf`` draws a fresh
    uniform proposal over the region (Tables 7.18-7.19), whose particles start from equal weights (the previous
    weights belonged to the replaced particles).

    ``motion``: a motion model (:class:`~locbook.models.base.MotionModel` with ``position_index``: a
    :class:`~locbook.models.motion.KinematicModel`, a heading model, or one of your own) instead of the random walk:
    the particles are full states ``(R, N, n)`` moved by ``x_t = f_t(x) + w``, ``w ~ N(0, Q_t)`` (drawn through the
    model's :meth:`~locbook.models.base.MotionModel.noise_factor`); an RssModel's likelihood sees
    ``x[..., motion.position_index]``, a callable likelihood the full states. The prior is then over the full state:
    ``initial_particles_m`` ``(R, N, n)``; ``initial_position_m`` a state ``(R, n)`` or, for a model with ``n_state``,
    a position ``(R, dim)`` (at rest: the other components 0), spread over the positions by ``initial_sd_m`` or over
    the state by ``initial_covariance`` ``(n, n)``; or ``n_particles`` uniform over ``region_m``, at rest. With
    ``region_m`` a particle leaving the region is mirrored back and the components the model names in
    :meth:`~locbook.models.base.MotionModel.mirrored_index` (a KinematicModel's velocity and
    acceleration) reversed on that axis. ``motion`` excludes ``transition``, ``spread_m`` and ``velocity_m``.

    Resampling (``resampling``: one of :data:`~locbook.tracking.resampling.RESAMPLING_METHODS`): at every step by
    default (basic SIR, Table 4.4); with ``resample_threshold`` only where ``N_eff < resample_threshold * N`` (the
    thesis's "N_t = 0.5", read as a fraction of N since N_eff >= 1 and a literal N_eff < 0.5 never fires); with
    ``resample_every = k`` at steps ``k - 1, 2k - 1, ...``. The draws are made for every run at every step, so the
    random stream does not depend on which runs resample. ``resampling_cdf``: the systematic scheme's cumulative sum
    (:func:`~locbook.tracking.resampling.systematic_resample`; ``"literal_ozkaya2011"`` is Table 4.2 as printed).

    ``weight_smoothing`` (Ozkaya's improved SIR): ``"sqrt"`` replaces the normalised weights by ``sqrt(w)``
    renormalised before the estimate, the N_eff test and the resampling, and carries them forward (our
    reading of Sec. 7.1.4, which reproduces Tables 7.23 and 7.25; it tempers the likelihood). ``"sqrt_corrected"``
    is the literature's generalised resampling: draw with ``a = sqrt(w)`` and reweight the copies by ``w / a``.

    A single run: readings ``(T, m)``, or with a callable likelihood ``initial_particles_m`` ``(N, dim)`` or
    ``initial_position_m`` ``(dim,)`` (``initial_covariance`` ``(dim, dim)``). The callables then take and return
    arrays without the run axis (``log_likelihood(particles (N, dim), t) -> (N,)``, ``transition(particles (N, dim),
    t, rng) -> (N, dim)``) and so does the result (module docstring). The random stream is that of the same call with
    one run, so the numbers are equal to that call's run 0.

    Returns a :class:`ParticleFilterResult`: the weighted mean (MMSE) and covariance, the highest-weight particle as
    MAP, ``n_eff`` before resampling (of the weights drawn from), ``resampled``, the final particles, normalised
    weights and log-weights, and ``clouds`` at ``cloud_steps``. Collapsed runs: module docstring.

    Examples
    --------
    One run of ten steps, equal powers at two anchors (the tag on their bisector); 1000 particles uniform in the room:

    >>> import numpy as np
    >>> import locbook as lb
    >>> model = lb.RssModel(np.array([[0.0, 0.0], [10.0, 0.0]]), lb.PathLossModel(-40.0, 2.0, sigma_db=3.0))
    >>> result = lb.particle_filter(np.full((1, 10, 2), -60.0), model, rng=np.random.default_rng(0),
    ...                             n_particles=1000, region_m=((0.0, -5.0), (10.0, 5.0)))
    >>> result.mean.shape                                # (runs, T, dim)
    (1, 10, 2)
    >>> bool(abs(result.mean[0, -1, 0] - 5.0) < 1.0)     # x on the bisector
    True
    """
    _check_rng(rng)
    given_transition = transition is not None     # a caller's transition may keep the arrays it returns
    check_choice("resampling", resampling, RESAMPLING_METHODS)
    check_choice("resampling_cdf", resampling_cdf, RESAMPLING_CDFS)
    check_choice("weight_smoothing", weight_smoothing, WEIGHT_SMOOTHINGS)
    if resample_threshold is not None and not 0.0 < resample_threshold <= 1.0:
        raise ValueError(f"resample_threshold is a fraction of N in (0, 1], got {resample_threshold}")
    if resample_every is not None:
        check_scalar("resample_every", resample_every, ge=1, integer=True)
        if resample_threshold is not None:
            raise ValueError("give resample_threshold (N_eff-triggered) or resample_every (scheduled), not both")
    check_scalar("initial_sd_m", initial_sd_m, ge=0)
    if (initial_sd_m > 0 or initial_covariance is not None) and initial_position_m is None:
        raise ValueError("initial_sd_m and initial_covariance spread the particles around initial_position_m; "
                         "give initial_position_m too")
    if initial_sd_m > 0 and initial_covariance is not None:
        raise ValueError("give initial_sd_m (an isotropic spread of the positions) or initial_covariance, not both")
    kin = None
    if motion is not None:
        given = [name for name, value in (("transition", transition), ("spread_m", spread_m),
                                          ("velocity_m", velocity_m)) if value is not None]
        if given:
            raise ValueError(f"motion moves the particles by x = f(x) + w, w ~ N(0, Q) (its own model); it excludes "
                             f"{' and '.join(given)} (got motion={type(motion).__name__} and {', '.join(given)})")
        kin = _Motion(motion)
        if region_m is not None and kin.derivatives is None:
            raise ValueError(f"region_m mirrors the motion at the walls; motion={kin.model.label} does not say what a "
                             f"mirror reverses (its mirrored_index() is None)")

    # -- one run without the run axis ----------------------------------------------------------------
    single = False
    is_model = isinstance(model, MeasurementModel)
    if is_model:
        single = np.ndim(rss_dbm) == 2
    elif callable(model):
        single = (initial_particles_m is not None and np.ndim(initial_particles_m) == 2
                  or initial_particles_m is None and initial_position_m is not None
                  and np.ndim(initial_position_m) == 1)
    if single:
        if is_model:
            rss_dbm = as_array("rss_dbm", rss_dbm, nan_ok=True)[None]   # a masked entry is not heard (NaN)
            for name, value, nd in (("initial_particles_m", initial_particles_m, 2),
                                    ("initial_position_m", initial_position_m, 1)):
                if value is not None and np.ndim(value) != nd:
                    raise ValueError(f"a single run (rss_dbm of shape (steps, m)) takes {name} without the run axis "
                                     f"({'(N, dim)' if nd == 2 else '(dim,)'}), got shape {np.shape(value)}")
        else:
            user_ll = model

            def model(particles, t):
                out = np.asarray(user_ll(particles[0], t), dtype=float)
                if out.shape != particles.shape[1:2]:
                    raise ValueError(f"log_likelihood must return ({particles.shape[1]},) for a single run (particles "
                                     f"{particles.shape[1:]}), got {out.shape}")
                return out[None]
        if transition is not None and callable(transition):
            user_transition = transition

            def transition(particles, t, rng):
                out = np.asarray(user_transition(particles[0], t, rng), dtype=float)
                if out.shape != particles.shape[1:]:
                    raise ValueError(f"transition must return {particles.shape[1:]} for a single run, got {out.shape}")
                return out[None]
        if initial_particles_m is not None:
            initial_particles_m = np.asarray(initial_particles_m)[None]
        if initial_position_m is not None:
            initial_position_m = np.asarray(initial_position_m)[None]

    # -- the likelihood ------------------------------------------------------------------------------
    detail, what = None, "log_likelihood"
    fused = None
    if is_model:
        if rss_dbm is None:
            raise ValueError(f"rss_dbm must be the readings (runs, steps, m) of the {model.label} model")
        rss_dbm = _check_inputs(rss_dbm, model)[0]
        if n_steps is not None and n_steps != rss_dbm.shape[1]:
            raise ValueError(f"n_steps {n_steps} disagrees with the {rss_dbm.shape[1]} steps of rss_dbm")
        n_runs, n_steps = rss_dbm.shape[:2]
        detail, what = _reading_detail(rss_dbm), _LIKELIHOOD
        fused = _FUSED_LIKELIHOODS.get(type(model))
        pidx = None if kin is None else kin.position_index
        # a model of positions sees a state's position components; any other model the full states
        of_positions = pidx is not None and getattr(model, "position_dim", None) is not None

        def log_likelihood(particles, t, out=None):
            if compiled and fused is not None:
                ll = fused(model, rss_dbm[:, t], particles, t, pidx, out)
                if ll is not None:
                    return ll
            return model.relative_log_likelihood(rss_dbm[:, t], particles[..., pidx] if of_positions else particles,
                                                 step=t)
    elif callable(model):
        n_steps, n_runs, log_likelihood = _callable_steps(rss_dbm, n_steps), None, model
    else:
        raise ValueError(f"model must be an RssModel or a callable log_likelihood(particles, t) (or any measurement "
                         f"model, locbook.models.base), got {type(model).__name__}")

    # -- the prior -----------------------------------------------------------------------------------
    # dim: the length of a particle (the state with motion); pos_dim: of its position (what region_m bounds)
    pos_dim: int | None = getattr(model, "position_dim", None) if is_model else None
    if kin is not None:
        if pos_dim is not None and kin.position_index.size != pos_dim:
            raise ValueError(f"motion has {kin.position_index.size} position axes, the {model.label} {pos_dim}")
        pos_dim = kin.position_index.size
    dim = kin.n_state if kin is not None else pos_dim
    bounds = None if region_m is None else _region(region_m, pos_dim)

    def confine(x):
        if bounds is None:
            return x
        return reflect_into_box(x, *bounds) if kin is None else kin.mirror(x, *bounds)

    if initial_particles_m is not None:
        if n_particles is not None or initial_position_m is not None:
            raise ValueError("give initial_particles_m, or n_particles with region_m or initial_position_m, not both")
        if np.ndim(initial_particles_m) == 3:
            _check_cloud("initial_particles_m", np.shape(initial_particles_m))
        particles = as_array("initial_particles_m", initial_particles_m, ndim=3).copy()
        if particles.shape[1] == 0:
            raise ValueError("initial_particles_m must hold at least one particle per run, "
                             f"got shape {particles.shape}")
    else:
        if n_particles is None:
            raise ValueError("give n_particles (with region_m or initial_position_m), or initial_particles_m")
        check_scalar("n_particles", n_particles, ge=1, integer=True)
        if initial_position_m is None:
            if bounds is None:
                raise ValueError("a uniform prior needs region_m (or give initial_position_m or initial_particles_m)")
            if n_runs is None:
                raise ValueError("with a log_likelihood callable give initial_particles_m or initial_position_m "
                                 "(the number of runs)")
            if kin is not None and kin.n_state is None:
                raise ValueError(f"motion {kin.model.label} has no n_state: give initial_particles_m or "
                                 f"initial_position_m as full states")
            shape = (n_runs, int(n_particles), bounds[0].size)
            _check_cloud("n_particles", shape[:2] + ((kin.n_state,) if kin is not None else shape[2:]))
            particles = bounds[0] + (bounds[1] - bounds[0]) * rng.random(shape)
            if kin is not None:                       # uniform positions, at rest
                particles = kin.state_from_positions(particles)
        else:
            start = as_array("initial_position_m", initial_position_m)
            if kin is not None and kin.n_state is not None and start.ndim == 2 and start.shape[-1] == pos_dim:
                start = kin.state_from_positions(start)   # a position: at rest
            want = (n_runs if n_runs is not None else start.shape[0] if start.ndim == 2 else None,
                    dim if dim is not None else start.shape[-1] if start.ndim == 2 else None)
            if start.shape != want:
                axes = (want[1] or "dim") if kin is None else f"{kin.n_state}) or (runs, {pos_dim}"
                raise ValueError(f"initial_position_m must have shape (runs, {axes}) = {want}, got {start.shape}")
            shape = (start.shape[0], int(n_particles), start.shape[1])
            _check_cloud("n_particles", shape)
            particles = np.broadcast_to(start[:, None, :], shape).copy()
            if initial_sd_m > 0:
                if kin is None:
                    particles = particles + initial_sd_m * rng.standard_normal(shape)
                else:
                    assert pos_dim is not None      # the motion's position axes (set with kin above)
                    particles[..., kin.position_index] += initial_sd_m * rng.standard_normal(shape[:2] + (pos_dim,))
                particles = confine(particles)
            elif initial_covariance is not None:
                d = shape[-1]
                cov = as_array("initial_covariance", initial_covariance)
                if cov.shape not in ((d, d), (shape[0], d, d)):
                    raise ValueError(f"initial_covariance must have shape ({d}, {d}) or ({shape[0]}, {d}, {d}), "
                                     f"got {cov.shape}")
                root = psd_root("initial_covariance", cov)
                z = rng.standard_normal(shape[:2] + (root.shape[-1],))
                particles = confine(particles + (z @ root.T if root.ndim == 2 else
                                                 np.einsum("rnk,rdk->rnd", z, root)))
    R: int     # (the shape of an array: ints)
    n: int
    R, n, d = particles.shape
    if n_runs is not None and R != n_runs or dim is not None and d != dim:
        raise ValueError(f"the particles {particles.shape} must be (runs, N, dim) with the {n_runs} runs of rss_dbm "
                         f"and the model's dim {dim}" + ("" if kin is None else " (the state of motion)"))
    if bounds is not None and kin is None and bounds[0].size != d:
        raise ValueError(f"region_m has {bounds[0].size} axes, the particles {d}")

    # -- the motion model ----------------------------------------------------------------------------
    compiled = _use_compiled(R * n)
    if compiled:
        from . import _particle_kernels as K  # lazy: numba loads only when the compiled path runs
        particles = np.ascontiguousarray(particles, dtype=float)
    own_motion = False                        # the compiled random walk moves our own buffer in place
    fresh = False
    if kin is not None:
        def transition(x, t, rng):
            return kin.step(x, t, rng, bounds)
    elif transition is None:
        try:
            spread = np.asarray(DEFAULT_SPREAD_M if spread_m is None else spread_m, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"spread_m must be numeric, got {spread_m!r}") from None
        if spread.ndim > 1 or spread.size not in (1, d) or np.any(np.isnan(spread)) or np.any(spread < 0):
            raise ValueError(f"spread_m must be finite (inf: a fresh uniform proposal) and >= 0, a scalar or one "
                             f"per axis ({d},), got {spread_m!r}")
        fresh = bool(np.any(np.isinf(spread)))
        if fresh and (spread.size != 1 or bounds is None):
            raise ValueError("spread_m = inf (a fresh uniform proposal) must be a scalar and needs region_m")
        velocity = _velocity_schedule(velocity_m, n_steps, d)
        moves = bool(np.any(spread > 0))
        own_motion = compiled and not fresh
        if own_motion:                        # normals drawn in blocks of runs: the same stream, no cloud-sized buffer
            block = max(1, _NOISE_BLOCK_VALUES // max(1, n * d))
            noise = np.empty((max(1, min(block, R)), n, d)) if moves else np.empty((1, 1, d))
            spread_d = np.ascontiguousarray(np.broadcast_to(spread, (d,)), dtype=float)
            velocity_c = np.ascontiguousarray(velocity, dtype=float)
            lower_c, upper_c = (np.zeros(d), np.ones(d)) if bounds is None else bounds

        def transition(x, t, rng):
            if fresh:                         # fresh draws from the uniform proposal over the region
                return bounds[0] + (bounds[1] - bounds[0]) * rng.random(x.shape)
            if own_motion:                    # x + v + D n in place, n drawn as numpy's standard_normal(x.shape)
                for r0 in range(0, R, noise.shape[0] if moves else R):
                    xs = x[r0:r0 + noise.shape[0]] if moves else x
                    if moves:
                        rng.standard_normal(out=noise[:xs.shape[0]])
                    K._nb_random_walk(xs, velocity_c[t], spread_d, noise, moves, lower_c, upper_c, bounds is not None)
                return x
            if moves:
                x = x + velocity[t] + spread * rng.standard_normal(x.shape)
            elif velocity_m is not None:
                x = x + velocity[t]
            return x if bounds is None else reflect_into_box(x, *bounds)
    elif not callable(transition):
        raise ValueError("transition must be a callable transition(particles, t, rng), "
                         f"got {type(transition).__name__}")

    # -- the recursion -------------------------------------------------------------------------------
    _check_size("rss_dbm" if is_model else "n_steps",
                "the covariance output (runs x steps x state x state)", (R, n_steps, d, d),
                "run the runs or the steps in blocks")
    try:
        kept = len({int(t) for t in cloud_steps if 0 <= int(t) < n_steps})
    except (TypeError, ValueError):
        raise ValueError(f"cloud_steps must be a collection of step numbers, got {cloud_steps!r}") from None
    _check_size("cloud_steps", f"the {kept} clouds kept (steps x runs x particles x state values)", (kept, R, n, d),
                "keep fewer steps or fewer particles")
    log_w = np.full((R, n), -np.log(n))
    final_log_w = log_w.copy()                # the normalised log-weights of the last step (exact, for the result)
    mean = np.empty((R, n_steps, d))
    cov = np.empty((R, n_steps, d, d))
    best = np.empty((R, n_steps, d))
    n_eff = np.empty((R, n_steps))
    resampled = np.zeros((R, n_steps), dtype=bool)
    clouds = {}
    dead = np.zeros(R, bool)
    dead_step = np.full(R, -1, np.int64)
    # compiled update (module docstring): buffers reused at every step; the particles are resampled into `spare` and
    # the two swap (a caller's transition keeps its arrays: then a fresh target each step)
    fast = compiled and weight_smoothing == "none"
    if fast:
        w = np.empty((R, n))
        ll_buf = np.empty((R, n)) if fused is not None else None
        spare = np.empty((R, n, d)) if not given_transition else None
    for t in range(n_steps):
        last = t == n_steps - 1
        if t > 0:
            particles = np.asarray(transition(particles, t, rng), dtype=float)
            if particles.shape != (R, n, d):
                raise ValueError(f"transition must return ({R}, {n}, {d}), got {particles.shape}")
            if fresh:                         # the old weights belonged to the old particles
                log_w = np.full((R, n), -np.log(n))
        if fast:
            ll = np.asarray(log_likelihood(particles, t) if ll_buf is None else
                            log_likelihood(particles, t, out=ll_buf), dtype=float)
            if ll.shape != (R, n):
                raise ValueError(f"log_likelihood must return ({R}, {n}), got {ll.shape}")
            if ll is not ll_buf:              # the kernel overwrites it with the logits: never a caller's array
                ll = np.array(ll, dtype=float, order="C")
            collapsed = np.zeros(R, bool)
            K._nb_normalise(log_w, ll, dead, w, final_log_w, last, collapsed)
            dead_step[collapsed] = t
            dead |= collapsed
            if R and dead.all():
                raise _collapse_error(dead_step, what, detail)
            K._nb_moments(w, particles, mean[:, t], cov[:, t], best[:, t], n_eff[:, t])
            if t in cloud_steps:
                clouds[t] = particles.copy()
            draw_w = w
        else:
            ll = np.asarray(log_likelihood(particles, t), dtype=float)
            if ll.shape != (R, n):
                raise ValueError(f"log_likelihood must return ({R}, {n}), got {ll.shape}")
            logits = log_w + ll
            top = logits.max(axis=-1)
            collapsed = ~dead & (np.isnan(top) | np.isinf(top))      # -inf for every particle, or NaN / +inf anywhere
            dead_step[collapsed] = t
            dead |= collapsed
            if R and dead.all():
                raise _collapse_error(dead_step, what, detail)
            if dead.any():              # a collapsed run goes on with equal weights (NaN outputs): others unaffected
                logits[dead] = 0.0
            w = _normalise_log(logits)
            if last:
                final_log_w = _log_normalise(logits)
            if weight_smoothing == "sqrt":
                w = np.sqrt(w)
                w /= w.sum(axis=-1, keepdims=True)
                if last:
                    final_log_w = _log_normalise(0.5 * final_log_w)
            mean[:, t], cov[:, t] = weighted_moments(w, particles)
            best[:, t] = particles[np.arange(R), np.argmax(w, axis=-1)]
            if t in cloud_steps:
                clouds[t] = particles.copy()
            draw_w = w
            if weight_smoothing == "sqrt_corrected":
                draw_w = np.sqrt(w)
                draw_w /= draw_w.sum(axis=-1, keepdims=True)
            n_eff[:, t] = effective_sample_size(draw_w)
        if resample_threshold is not None:
            do = n_eff[:, t] < resample_threshold * n
        else:
            do = np.full(R, resample_every is None or (t + 1) % resample_every == 0)
        resampled[:, t] = do
        # drawn for every run so that the stream does not depend on `do`
        if fast and resampling == "systematic" and resampling_cdf == "standard":
            u = rng.random(R)                 # the same draw; ancestors, copies and log_w in one pass
            target = np.empty((R, n, d)) if spare is None else spare
            K._nb_systematic(w, u, do, particles, target, log_w)
            particles, spare = target, (None if spare is None else particles)
            if last and do.any():
                final_log_w[do] = np.log(1.0 / n)
        else:
            idx: Any        # the ancestors of the runs resampled (None when none is)
            if resampling == "systematic":
                u = rng.random(R)
                idx = systematic_resample(draw_w[do], u[do], resampling_cdf) if do.any() else None
            else:
                idx = resample(draw_w, rng=rng, method=resampling)[do]
            if do.any():
                particles[do] = particles[do][np.arange(idx.shape[0])[:, None], idx]
                if weight_smoothing == "sqrt_corrected":
                    new_w = np.take_along_axis(w[do], idx, -1) / np.take_along_axis(draw_w[do], idx, -1)
                    w[do] = new_w / new_w.sum(axis=-1, keepdims=True)
                else:
                    w[do] = 1.0 / n
                if last:
                    final_log_w[do] = np.log(w[do])
            log_w = np.log(np.maximum(w, 1e-300))
        if dead.any():
            mean[dead, t], cov[dead, t], best[dead, t], n_eff[dead, t] = np.nan, np.nan, np.nan, np.nan
            resampled[dead, t] = False
            if t in cloud_steps:
                clouds[t][dead] = np.nan
    if fast:
        # the loop's buffers go before the result's arrays are made (none is read after this)
        w = ll_buf = spare = None  # type: ignore[assignment]
    weights = np.exp(log_w)
    weights /= weights.sum(axis=-1, keepdims=True)
    if dead.any():
        particles = particles.copy()
        particles[dead], weights[dead], final_log_w[dead] = np.nan, np.nan, np.nan
        _warn_collapse(dead, dead_step, "particle_filter", what, detail)
    out = dict(mean=mean, cov=cov, map_m=best, n_eff=n_eff, resampled=resampled, particles_m=particles,
               weights=weights, diverged=dead, diverged_step=dead_step, log_weights=final_log_w)
    if single:                        # one run given without the run axis: none in the result either
        return ParticleFilterResult(**{k: a[0, ...] for k, a in out.items()},
                                    clouds={t: c[0] for t, c in clouds.items()})
    return ParticleFilterResult(**out, clouds=clouds)


def _log_normalise(logw):
    """``logw - log sum exp(logw)`` along the last axis (normalised log-weights; -inf stays -inf)."""
    top = logw.max(axis=-1, keepdims=True)
    return logw - top - np.log(np.exp(logw - top).sum(axis=-1, keepdims=True))


def kernel_map_estimate(particles_m, weights, *, bandwidth_m=None, n_candidates: int = 256):
    """The mode of a weighted Gaussian kernel density of the particles ``(R, Ns, dim)``: the density is evaluated at
    the ``n_candidates`` highest-weight particles and the best is returned ``(R, dim)``. ``bandwidth_m``: None
    gives Silverman's rule per run from the weighted spread."""
    x = as_array("particles_m", particles_m, ndim=3)
    w = as_array("weights", weights, ndim=2)
    R, n, dim = x.shape
    if n == 0 or w.shape != (R, n):
        raise ValueError(f"particles_m (R, N, dim) must hold at least one particle per run and weights be (R, N); got "
                         f"shapes {x.shape} and {w.shape}")
    check_scalar("n_candidates", n_candidates, ge=1, integer=True)
    k = min(int(n_candidates), n)
    # the density is evaluated in blocks of 2048 particles for every run and candidate at once
    _check_size("particles_m", f"the kernel density's block for n_candidates = {k} (runs x candidates x particles "
                "x dim)", (R, k, min(n, 2048), dim), "run the runs in blocks or lower n_candidates")
    # stable: equal weights (every particle after resampling) rank by index on every machine, not in the order
    # numpy's vector sort (AVX-512 or not) leaves ties
    top = np.argsort(-w, axis=-1, kind="stable")[:, :k]
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
