"""Palvai (2008), "Passive RF Localization Based on RSSI Using Non-linear Bayesian Estimation", M.S.
thesis, George Mason University.

A static emitter is located from RSS recorded by a receiver at N random measurement locations whose positions come
from GPS (sigma_3 = 5 m): linearised least squares (LSF) and its recursive form (RLSF), an EKF with a random-walk
state, and a SIR particle filter. The thesis prints no numeric result, only parameters and claims; every unprinted
choice below is a named argument with its reason. Numbers from our own pilot simulations are orientation, never
scored.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from .._validate import check_choice
from ..models.base import per_step
from ..models.channel import PathLossModel, correct_range_bias, log_distance_gradient
from ..models.rss import RssModel
from ..reproduce.printed_values import printed
from ..static.least_squares import recursive_least_squares
from ..static.localization import lateration_ls, lateration_system
from ..tracking.divergence import DivergenceFlags
from ..tracking.kalman import extended_kalman_filter
from ..tracking.particle import kernel_map_estimate, particle_filter
from ..tracking.streams import NonlinearMeasurement, RssMeasurement

__all__ = [
    "DOCUMENT", "PRINTED", "SIGMA1_DB", "ETA", "SIGMA2_M", "SIGMA3_M", "N_LOCATIONS", "AREA_M", "Setup",
    "TARGETS", "with_target", "draw_locations", "measure", "observed_locations", "lsf_by_count", "rlsf_path",
    "ekf_path", "EKF_VARIANTS", "EKF_SCHEDULES", "SCHEDULES", "SHADOWING", "pf_iterations", "pf_run", "PF_ESTIMATES",
    "pf_estimate_m", "printed_jacobian", "corrected_jacobian", "crlb_m", "errors_m",
]

DOCUMENT = "palvai2008"
#: Everything the thesis prints (locbook/data/printed/palvai2008.csv).
PRINTED = printed(DOCUMENT)
#: Sec. 2.6 / 4.4: shadowing sigma_1, path-loss exponent eta; Sec. 4.4: sigma_2, sigma_3 and 25 locations.
SIGMA1_DB = PRINTED.get("Sec. 4.4 text", "EKF simulation", "shadowing sigma_1").value
ETA = PRINTED.get("Sec. 4.4 text", "EKF simulation", "path loss exponent").value
SIGMA2_M = PRINTED.get("Sec. 4.4 text", "EKF simulation", "process noise sigma_2").value
SIGMA3_M = PRINTED.get("Sec. 4.4 text", "EKF simulation", "location measurement sigma_3").value
N_LOCATIONS = int(PRINTED.get("Sec. 4.4 text", "EKF simulation", "number of locations").value)
#: Sec. 5.4: the particles' prior is "Uniform in [0,50] for three coordinates": the area is taken as that cube.
AREA_M = 50.0


@dataclass(frozen=True)
class Setup:
    """The simulated world: ``dim`` 3 (the thesis's equations) or 2; the target ``target_m`` (not printed: None is
    the area's centre; a point ``(dim,)``, or one target per run ``(R, dim)``, see :func:`with_target`); the link
    budget ``ref_power_dbm`` at ``1 m`` (not printed; K = -20 dBm, ours, known to every estimator); shadowing
    ``sigma_db`` and exponent ``path_loss_exp`` (Secs. 2.6, 4.4); receiver positions observed with GPS noise
    ``receiver_sigma_m`` (sigma_3; 0 = exact, as for the LSF of Sec. 2.6)."""

    dim: int = 3
    target_m: tuple | np.ndarray | None = None
    ref_power_dbm: float = -20.0
    path_loss_exp: float = ETA
    sigma_db: float = SIGMA1_DB
    receiver_sigma_m: float = 0.0

    @property
    def target(self) -> np.ndarray:
        """The target ``(dim,)``, or one per run ``(R, dim)``."""
        return np.full(self.dim, AREA_M / 2) if self.target_m is None else np.asarray(self.target_m, float)

    def run_target(self, run: int = 0) -> np.ndarray:
        """The target ``(dim,)`` of one run (the same for every run unless drawn per run)."""
        t = self.target
        return t if t.ndim == 1 else t[run]

    def target_for(self, x) -> np.ndarray:
        """The target shaped to broadcast against ``x`` ``(R, ..., dim)`` (per-run targets get singleton axes)."""
        return _target_like(self.target, x)

    @property
    def channel(self) -> PathLossModel:
        return PathLossModel(self.ref_power_dbm, self.path_loss_exp, self.sigma_db, min_distance_m=1.0)


def _target_like(target, x) -> np.ndarray:
    t = np.asarray(target, float)
    return t if t.ndim == 1 else t.reshape(t.shape[:1] + (1,) * (np.ndim(x) - 2) + t.shape[1:])


#: Where the static target is (Secs. 2.4, 4.5: "a given target location", not printed): the area's centre, or drawn
#: uniform in the area, one per Monte-Carlo run.
TARGETS = ("area_centre", "uniform_per_run")


def with_target(setup: Setup, target: str, n_runs: int, rng: np.random.Generator) -> Setup:
    """``setup`` with its target read as ``target`` (:data:`TARGETS`) for ``n_runs`` runs: ``"area_centre"``
    returns ``setup`` unchanged and draws nothing (so every other stream is untouched); ``"uniform_per_run"`` draws
    one target per run uniform in the area, ``(n_runs, dim)``."""
    check_choice("target", target, TARGETS)
    if target == "area_centre":
        return setup
    return replace(setup, target_m=rng.uniform(0.0, AREA_M, (int(n_runs), setup.dim)))


def draw_locations(n_runs: int, n_locations: int, dim: int, rng: np.random.Generator) -> np.ndarray:
    """Measurement locations "random selected points within the coverage area" (distribution not stated): uniform
    in the area, redrawn per run, ``(R, N, dim)``."""
    return rng.uniform(0.0, AREA_M, (n_runs, n_locations, dim))


def measure(setup: Setup, locations_m, rng: np.random.Generator) -> np.ndarray:
    """Received powers ``(R, N)`` (Eq. (4.28)): the log-distance mean (distances below 1 m clamped, ours) plus
    shadowing ``N(0, sigma_1^2)``."""
    loc = np.asarray(locations_m)
    d = np.linalg.norm(loc - setup.target_for(loc), axis=-1)
    return setup.channel.sample_rss_dbm(d, rng=rng)


def observed_locations(setup: Setup, locations_m, rng: np.random.Generator) -> np.ndarray:
    """The receiver positions the estimators see: the true ones plus GPS noise ``N(0, sigma_3^2 I)``
    (Sec. 4.4; the thesis does not say which estimators see it)."""
    loc = np.asarray(locations_m, float)
    return loc + setup.receiver_sigma_m * rng.standard_normal(loc.shape) if setup.receiver_sigma_m > 0 else loc


def _ranges(setup: Setup, rss_dbm, bias_correction: str):
    d = setup.channel.range_m(rss_dbm)
    return correct_range_bias(d, setup.sigma_db, setup.path_loss_exp, bias_correction)


def lsf_by_count(setup: Setup, locations_m, rss_dbm, counts, *, reference: str = "consecutive",
                 variant: str = "corrected", bias_correction: str = "median") -> np.ndarray:
    """Batch LSF (Eqs. (2.27)-(2.29), corrected) on the first ``n`` locations for each ``n`` in ``counts``:
    positions ``(R, len(counts), dim)``. ``bias_correction="median"`` is the thesis's plain inversion (2.34);
    ``"squared"`` removes the log-normal bias of ``d^2`` (Eqs. (2.35)-(2.38); an extension)."""
    d = _ranges(setup, rss_dbm, bias_correction)
    out = [lateration_ls(locations_m[:, :n], d[:, :n], pairs=reference, variant=variant).position_m
           for n in counts]
    return np.stack(out, axis=1)


def rlsf_path(setup: Setup, locations_m, rss_dbm, *, bias_correction: str = "median", prior_cov=None):
    """RLSF (Eqs. (2.49)-(2.58), corrected) over the consecutive rows: estimates ``(R, N - 1, dim)`` after locations
    2..N (row i needs locations i and i + 1), prior mean 0 and ``Pi_0 = 1e6 I`` by default (Eq. (2.49) prints no
    Pi_0; ours)."""
    d = _ranges(setup, rss_dbm, bias_correction)
    H, Y = lateration_system(locations_m, d, pairs="consecutive")
    return recursive_least_squares(H, Y, prior_cov=prior_cov).x


EKF_VARIANTS = ("corrected", "literal_palvai2008")


def corrected_jacobian(x, anchors_m, path_loss_exp):
    """``dh_i/dX = (10 eta / ln 10) (s_i - X)^T / d_i^2`` (Eq. (4.43) corrected: the print lacks
    the 1/ln 10 and one 1/d_i): ``(..., N, dim)``."""
    return log_distance_gradient(np.asarray(x, float)[..., None, :] - np.asarray(anchors_m, float), path_loss_exp)


def printed_jacobian(x, anchors_m, path_loss_exp):
    """Eq. (4.43) as printed (flagged): ``10 eta (s_i - X)^T / d_i`` (no 1/ln 10, one factor 1/d_i missing)."""
    diff = np.asarray(anchors_m) - np.asarray(x)[..., None, :]
    return 10 * path_loss_exp * diff / np.linalg.norm(diff, axis=-1)[..., None]


EKF_SCHEDULES = ("sequential", "batch")


def ekf_path(setup: Setup, anchors_m, rss_dbm, x0, P0, *, process_sd_m: float = SIGMA2_M,
             variant: str = "corrected", inflate: bool = False, schedule: str = "sequential",
             with_divergence: bool = False):
    """The EKF of Sec. 4.3 over the sequential schedule (our interpretation of its "time": step k assimilates
    location k): random-walk state ``X_k = X_{k-1} + w``, ``Q = sigma_2^2 I`` (Eq. (4.25); the true target is
    static); measurement (4.28). ``variant="corrected"``: the nonlinear innovation, the corrected Jacobian and
    ``R = sigma_1^2`` (optionally ``inflate``d for the GPS noise sigma_3, an extension); ``"literal_palvai2008"``
    (flagged): the printed Jacobian (4.43) and ``R = I`` as printed.
    ``schedule="batch"``: all N readings in one update (the corrected EKF only). Returns the estimates
    ``(R, N, dim)`` after each location (``(R, 1, dim)`` for the batch schedule); with ``with_divergence``
    ``(estimates, flags)``, the EKF's NIS guard per run (:class:`locbook.tracking.divergence.DivergenceFlags`, step k =
    location k; the batch schedule has one update, fewer than the guard's window, and is never flagged)."""
    if variant not in EKF_VARIANTS:
        raise ValueError(f"variant must be one of {EKF_VARIANTS}, got {variant!r}")
    if schedule not in EKF_SCHEDULES:
        raise ValueError(f"schedule must be one of {EKF_SCHEDULES}, got {schedule!r}")
    s = np.asarray(anchors_m, float)
    R_, N, dim = s.shape
    F, Q = np.eye(dim), process_sd_m**2 * np.eye(dim)
    if schedule == "batch":
        if variant != "corrected":
            raise ValueError("the batch schedule is offered for the corrected EKF only")
        meas = RssMeasurement(np.asarray(rss_dbm)[:, None, :], per_step(s[:, None]), setup.channel, np.arange(dim),
                              anchor_sigma_m=setup.receiver_sigma_m if inflate else 0.0)
        return _with_flags(extended_kalman_filter(F, Q, x0, P0, [meas]), with_divergence)
    if variant == "corrected":
        meas = RssMeasurement(np.asarray(rss_dbm)[..., None], per_step(s[:, :, None, :]), setup.channel, np.arange(dim),
                              anchor_sigma_m=setup.receiver_sigma_m if inflate else 0.0)
        return _with_flags(extended_kalman_filter(F, Q, x0, P0, [meas]), with_divergence)
    # printed form: one location per step through the "diagonal" of an (N, N) stream (NaN off the diagonal)
    z = np.full((R_, N, N), np.nan)
    z[:, np.arange(N), np.arange(N)] = rss_dbm
    ch = setup.channel

    def h(x):
        return ch.mean_rss_dbm(np.linalg.norm(x[..., None, :] - s, axis=-1))

    meas = NonlinearMeasurement(z, h, np.eye(N), jacobian=lambda x: printed_jacobian(x, s, setup.path_loss_exp),
                                name="RSS with the printed Jacobian (4.43) and R = I")
    return _with_flags(extended_kalman_filter(F, Q, x0, P0, [meas]), with_divergence)


def _with_flags(result, with_divergence: bool):
    return (result.mean, DivergenceFlags.of(result)) if with_divergence else result.mean


SCHEDULES = ("all", "sequential", "cyclic")
SHADOWING = ("frozen", "iid")


def pf_iterations(schedule: str, n_iterations: int, n_locations: int) -> int:
    """The iterations ``schedule`` (:data:`SCHEDULES`) runs: the sequential schedule assimilates location k at
    iteration k, so it ends after the ``n_locations`` locations; the others run ``n_iterations``."""
    check_choice("schedule", schedule, SCHEDULES)
    return min(int(n_iterations), int(n_locations)) if schedule == "sequential" else int(n_iterations)


def pf_run(setup: Setup, anchors_m, rss_dbm, rng: np.random.Generator, *, n_particles: int, n_iterations: int,
           schedule: str = "all", shadowing: str = "frozen", true_locations_m=None, process_sd_m: float = SIGMA2_M,
           likelihood_sigma_db: float | None = None, resampling: str = "systematic", cloud_steps=()):
    """The SIR-PF of Sec. 5.3.1 (bootstrap proposal, resampling at every iteration; the scheme is not named),
    particles drawn uniform in the area (Sec. 5.4). ``schedule`` (what an iteration assimilates is not stated):
    ``"all"`` assimilates every location's reading at each iteration, ``"sequential"`` location k at iteration k
    (needs ``n_iterations <= N``), ``"cyclic"`` location ``k mod N``.
    ``shadowing``: ``"frozen"`` reuses the recorded readings (default), ``"iid"`` draws fresh shadowing at
    every iteration at the ``true_locations_m``. ``likelihood_sigma_db``: the filter's sigma (default
    sigma_1; 1 dB suits Fig. 21's noise-free channel)."""
    if schedule not in SCHEDULES:
        raise ValueError(f"schedule must be one of {SCHEDULES}, got {schedule!r}")
    if shadowing not in SHADOWING:
        raise ValueError(f"shadowing must be one of {SHADOWING}, got {shadowing!r}")
    s = np.asarray(anchors_m, float)
    R_, N, dim = s.shape
    if schedule == "sequential" and n_iterations > N:
        raise ValueError(f"the sequential schedule has one iteration per location: n_iterations <= {N}")
    if shadowing == "iid" and true_locations_m is None:
        raise ValueError("fresh shadowing per iteration needs true_locations_m to measure at")
    sigma = setup.sigma_db if likelihood_sigma_db is None else likelihood_sigma_db
    ch = PathLossModel(setup.ref_power_dbm, setup.path_loss_exp, sigma, min_distance_m=1.0)
    data_rng = np.random.default_rng(rng.integers(2**63))
    z0 = np.asarray(rss_dbm, float)
    # the readings each iteration assimilates, (R, iterations, N): every location's, or one location's with the
    # others NaN (not heard: left out of the likelihood); the same readings each time, or fresh shadowing drawn in
    # iteration order. One model over every receiver, so the particle filter runs its RssModel path (compiled for
    # large clouds)
    fresh = [measure(setup, true_locations_m, data_rng) for _ in range(n_iterations)] if shadowing == "iid" else None
    readings = np.stack(fresh, axis=1) if fresh is not None else np.broadcast_to(z0[:, None], (R_, n_iterations, N))
    if schedule != "all":
        k = np.arange(n_iterations)
        heard = np.zeros((n_iterations, N), bool)
        heard[k, k if schedule == "sequential" else k % N] = True
        readings = np.where(heard, readings, np.nan)
    model = RssModel(s, ch)
    init = rng.uniform(0.0, AREA_M, (R_, n_particles, dim))
    if process_sd_m > 0:        # every iteration predicts before its update, the first one too (Sec. 5.3.1)
        init = init + process_sd_m * rng.standard_normal(init.shape)
    return particle_filter(readings, model, rng=rng, initial_particles_m=init, spread_m=process_sd_m,
                           resampling=resampling, cloud_steps=cloud_steps)


#: The SIR-PF's point estimate (Sec. 6.1 does not say which estimate of the cloud it compares: its "ML estimate" is
#: not defined): the weighted mean (MMSE), the highest-weight particle, or the mode of a kernel density of the cloud.
PF_ESTIMATES = ("mean", "highest_weight", "kde_mode")


def pf_estimate_m(result, estimate: str = "mean") -> np.ndarray:
    """The SIR-PF's estimate ``(R, dim)`` after the last iteration of ``result`` (:func:`pf_run`), as ``estimate``
    (:data:`PF_ESTIMATES`): ``"mean"`` the weighted particle mean (MMSE), ``"highest_weight"`` the particle of the
    largest weight (both before the last resampling), ``"kde_mode"`` the mode of a Gaussian kernel density of the
    final cloud, Silverman's bandwidth (:func:`locbook.tracking.particle.kernel_map_estimate`; the SIR resamples at
    every iteration, so the final weights are equal and the density is evaluated at that function's first 256
    particles as candidates, a subsample of the posterior)."""
    check_choice("estimate", estimate, PF_ESTIMATES)
    if estimate == "mean":
        return result.mean[:, -1]
    if estimate == "highest_weight":
        return result.map_m[:, -1]
    return kernel_map_estimate(result.particles_m, result.weights)


def crlb_m(setup: Setup, locations_m) -> np.ndarray:
    """The CRLB ``sqrt(tr J^{-1})`` ``(R,)`` of the static position from the N readings (an extension): ``J =
    sum_i (10 eta / ln 10)^2 u_i u_i^T / (d_i^2 v_i)``, ``v_i = sigma_1^2 + (10 eta / ln 10)^2 sigma_3^2 / d_i^2``
    (the GPS noise propagated to first order, as in the EKF's inflation; ``sigma_3 = 0`` gives the standard bound)."""
    loc = np.asarray(locations_m, float)
    diff = loc - setup.target_for(loc)
    d2 = np.maximum(np.sum(diff**2, axis=-1), 1.0)
    slope2 = (10 * setup.path_loss_exp / np.log(10)) ** 2
    v = setup.sigma_db**2 + slope2 * setup.receiver_sigma_m**2 / d2
    J = np.einsum("rn,rni,rnj->rij", slope2 / (d2**2 * v), diff, diff)
    return np.sqrt(np.trace(np.linalg.inv(J), axis1=-2, axis2=-1))


def errors_m(estimates_m, target_m) -> np.ndarray:
    """Euclidean error ``|X_hat - X|`` (the thesis's "difference between estimated mean and actual location");
    ``target_m`` ``(dim,)`` or one per run ``(R, dim)`` against estimates ``(R, ..., dim)``."""
    est = np.asarray(estimates_m)
    return np.linalg.norm(est - _target_like(target_m, est), axis=-1)
