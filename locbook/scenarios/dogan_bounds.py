"""Dogan (2015)'s Ch. 4 bounds: the posterior CRLB of the CA model with RSS (and accelerometer) information
(:func:`pcrlb_m`, Eq. (4.22)), the RMSE / bound table (:func:`bound_rows`) and the horizon study (:class:`BoundStudy`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._deprecation import renamed_keyword
from ..bounds.pcrlb import linear_measurement_information, position_bound_m, posterior_crlb, rss_state_information
from ..errors import ParameterError
from ..metrics import rmse_m
from ..models.channel import PathLossModel
from ..models.motion import KinematicModel, simulate_states
from ..models.rss import RssModel
from ..models.trajectory import Trajectory
from ..montecarlo import replicate_standard_error
from ..reproduce.scoring import Ambiguity
from .dogan_protocol import (
    ANCHORS_M,
    DEFAULT_NOISE_INTERPRETATION,
    DEFAULT_RSS_ONLY_STEP,
    DT_S,
    FILTERS,
    MC_RUNS,
    P00_ACC_VAR,
    P00_VEL_VAR,
    PATH_LOSS_EXP,
    ROOM_M,
    RSS_EVERY,
    SIGMA_ACC_MPS2,
    corner_anchors,
    filter_grid,
    filter_noise,
    initial_state,
    motion_model,
    room_sides_m,
    trajectory_step_s,
)

#: ``"smc"``: Eq. (4.22), the RSS information averaged over simulated CA trajectories (Figs 4.1/4.3);
#: ``"linear"``: MLE fixes as linear measurements with R = diag(MSE_MLE) (Figs 4.2/4.4, trajectory-free);
#: ``"truth"``: the RSS information along one known trajectory (truth-conditioned, Stone Soup's convention),
#: the bound to set beside filters run on that trajectory (an extension: the thesis never overlays them).
BOUND_KINDS = ("smc", "linear", "truth")


def smc_trajectories(n_trajectories: int, n_steps: int, rng: np.random.Generator, *,
                     model: KinematicModel | None = None, room_m=ROOM_M):
    """Sec. 4.1.2: trajectories "that exactly follow the constant acceleration model", each beginning at a point
    "selected arbitrarily in the area": uniform in the room, v_0 ~ N(0, 0.0065 I), a_0 ~ N(0, 0.00023 I) (the
    P_{0|0} blocks; the thesis prints no start distribution), propagated with the per-step Q. Shape
    ``(N, n_steps, 6)``."""
    model = model or motion_model()
    start = model.state_from(rng.uniform((0.0, 0.0), room_sides_m(room_m), (n_trajectories, 2)),
                             np.sqrt(P00_VEL_VAR) * rng.standard_normal((n_trajectories, 2)),
                             np.sqrt(P00_ACC_VAR) * rng.standard_normal((n_trajectories, 2)))
    return simulate_states(model.F, model.Q, start, n_steps - 1, rng=rng)


def smc_trajectory(states, rss_every: int = RSS_EVERY, dt_s: float = DT_S) -> Trajectory:
    """Wrap simulated states ``(N, T, 6)`` (e.g. :func:`smc_trajectories`) as one trajectory per run, so the
    filters can be run on the bound's own scenario."""
    states = np.asarray(states, dtype=float)
    n = states.shape[-2]
    model = motion_model(dt_s)
    return Trajectory(np.arange(n) * dt_s, states[..., model.position_index], states[..., model.velocity_index],
                      states[..., model.acceleration_index], rss_steps=np.arange(0, n, rss_every), start="smc")


def pcrlb_m(kind: str, *, fusion: bool, sigma_rss_db: float, mse_mle_m2, n_steps: int,
            path_loss_exp: float = PATH_LOSS_EXP, sigma_acc_mps2: float = SIGMA_ACC_MPS2,
            rng: np.random.Generator | None = None, n_trajectories: int = MC_RUNS, trajectory: Trajectory | None = None,
            acc_at_rss_epochs: bool = False, min_distance_m: float = 0.0, height_offset_m: float = 0.0,
            rss_every: int = RSS_EVERY, model: KinematicModel | None = None, p0_acc_var: float = P00_ACC_VAR,
            anchors_m=ANCHORS_M, room_m=ROOM_M) -> np.ndarray:
    """Position PCRLB (Eq. (4.23), m) at steps ``0 .. n_steps - 1`` of the 20 Hz grid, by Table 4.1.

    J_0 = P_{0|0}^{-1} (Eqs. (3.20), (4.11)); the Tichavsky recursion (4.7) with D22 = Q^{-1} + J_z, where J_z at
    RSS epochs (every ``rss_every``-th step) is the RSS information of ``kind`` (see :data:`BOUND_KINDS`), and for
    ``fusion`` the accelerometer's ``H_acc^T R_acc^{-1} H_acc`` at the other steps. Table 4.1 leaves the
    acceleration out at RSS epochs although the fusion filter uses it there; ``acc_at_rss_epochs=True`` adds it
    (our correction, off by default). ``min_distance_m`` / ``height_offset_m`` regularise the near-anchor 1/d^2
    singularity of E[J_z] (which gives the average of Eq. (4.22) an infinite variance); the thesis uses neither.
    ``mse_mle_m2`` is ``(2,)`` (one MSE per axis over runs and epochs) or ``(E, 2)`` per RSS epoch
    (:data:`PCRLB_MSE_MLE`): P_0 from epoch 0's, and the linear bound's R at the k-th RSS epoch from epoch k's (Table
    4.1's R_{k+1}). The SMC trajectories start in ``room_m``; ``anchors_m`` are the anchors.
    """
    if kind not in BOUND_KINDS:
        raise ParameterError(f"kind must be one of {BOUND_KINDS}, got {kind!r}")
    model = model or motion_model()
    idx = model.position_index
    mse = np.asarray(mse_mle_m2, dtype=float)
    per_epoch = mse.ndim == 2
    rss_steps = np.arange(rss_every, n_steps, rss_every)
    if per_epoch and (mse.shape[-1] != 2 or mse.shape[0] < rss_steps.size + 1):
        raise ParameterError(f"a per-epoch mse_mle_m2 must be (epochs, 2) with at least {rss_steps.size + 1} epochs "
                             f"for {n_steps} steps, got shape {mse.shape}")
    _, P0 = initial_state(np.zeros(2), mse[0] if per_epoch else mse, acc_var=p0_acc_var)
    jz = np.zeros((n_steps - 1, 6, 6))
    if fusion:
        acc_info = linear_measurement_information(model.derivative_measurement_matrix(2),
                                                  sigma_acc_mps2**2 * np.eye(2))
        jz[:] = acc_info
        if not acc_at_rss_epochs:
            jz[rss_steps - 1] = 0.0
    def rss_model():       # the RSS model of the bound: the anchors height_offset_m above the tag, the clamp
        anchors, height = np.asarray(anchors_m, float), np.asarray(height_offset_m, float)
        channel = PathLossModel(0.0, path_loss_exp, sigma_rss_db, min_distance_m=min_distance_m)
        if np.any(height != 0):
            return RssModel(np.column_stack([anchors, np.broadcast_to(height, anchors.shape[:1])]), channel,
                            tag_height_m=0.0)
        return RssModel(anchors, channel)
    if kind == "linear" and per_epoch:        # R_k per epoch (Table 4.1's R_{k+1}); epoch 0 is P_0's
        H = model.position_measurement_matrix()
        rss_info = np.stack([linear_measurement_information(H, np.diag(m)) for m in mse[1:rss_steps.size + 1]])
    elif kind == "linear":
        rss_info = linear_measurement_information(model.position_measurement_matrix(), np.diag(mse))
    elif kind == "truth":
        if trajectory is None or trajectory.time_s.size < n_steps:
            raise ParameterError("the truth-conditioned bound needs a trajectory of at least n_steps steps")
        rss_info = rss_state_information(trajectory.states(model)[rss_steps], rss_model(), idx)
    else:
        if rng is None:
            raise ParameterError("the Monte-Carlo (smc) bound needs rng")
        states = smc_trajectories(n_trajectories, n_steps, rng, model=model, room_m=room_m)
        rss_info = rss_state_information(states[:, rss_steps], rss_model(), idx).mean(axis=0)    # Eq. (4.22)
    jz[rss_steps - 1] += rss_info
    info = posterior_crlb(np.linalg.inv(P0), model.F, model.Q, jz)
    return position_bound_m(info, idx)


@renamed_keyword("noise_reading", "noise_interpretation")
def bound_rows(runs: dict, trajectory: Trajectory, *, noise_interpretation: str = DEFAULT_NOISE_INTERPRETATION,
               anchors_m=ANCHORS_M, rss_only_step: str = DEFAULT_RSS_ONLY_STEP) -> list[dict]:
    """Every filter's RMSE beside the truth-conditioned PCRLB of its own information (ONLY RSS or fused, same
    trajectory, Q, R and P_0 as the filter under ``noise_interpretation``), both as the RMS over the RSS epochs; KF
    (MLE) also beside the linear bound. An ONLY-RSS filter's bound uses its own grid and Q per step
    (:func:`filter_grid` of ``rss_only_step``)."""
    out = []
    for (sigma, ple), run in runs.items():
        for key, err in run.errors.items():
            if not (isinstance(key, tuple) and key[0] in FILTERS):
                continue
            name, sigma_acc = key
            q, p0_acc = filter_noise(noise_interpretation, sigma_acc)
            grid = filter_grid(trajectory, sigma_acc is not None, rss_only_step)
            common = dict(fusion=sigma_acc is not None, sigma_rss_db=sigma, path_loss_exp=ple,
                          sigma_acc_mps2=sigma_acc or SIGMA_ACC_MPS2, mse_mle_m2=run.mse_mle_m2,
                          n_steps=grid.time_s.size,
                          model=motion_model(trajectory_step_s(grid), q), p0_acc_var=p0_acc,
                          rss_every=int(np.diff(grid.rss_steps[:2])[0]), anchors_m=anchors_m)
            bound = pcrlb_m("truth", trajectory=grid, **common)[grid.rss_steps]
            row = dict(sigma_rss_db=sigma, ple=ple, sigma_acc=sigma_acc, filter=name, rmse_m=float(rmse_m(err)),
                       pcrlb_m=float(np.sqrt(np.mean(bound**2))))
            if key in run.divergence:
                row["runs flagged diverged"] = run.divergence[key].n_diverged
            if name == "kalman_filter":
                lin = pcrlb_m("linear", **common)[grid.rss_steps]
                row["linear_pcrlb_m"] = float(np.sqrt(np.mean(lin**2)))
            row["ratio"] = row["rmse_m"] / row["pcrlb_m"]
            out.append(row)
    return out


HORIZON_SOURCE = "Dogan 2015 Sec. 4.1.2"


@dataclass(frozen=True)
class BoundStudy:
    """The Ch. 4 bounds of one run of the study (Figs. 4.1-4.4): every SMC curve from one seed, as one figure of
    the thesis would draw them, and independent replicate seeds for the Monte-Carlo standard error of a statistic
    of an SMC curve. ``mse_mle_m2`` maps sigma_RSS (dB) to the per-axis MSE of the Ch. 3 MLE (P_0, and R of the
    linear bound), per axis ``(2,)`` or per epoch ``(E, 2)``; ``room_m`` the room, its corners the anchors; the other
    fields are those of :func:`pcrlb_m`."""

    mse_mle_m2: dict
    n_steps: int
    n_trajectories: int
    smc_seed: int
    replicate_seeds: tuple
    acc_at_rss_epochs: bool = False
    min_distance_m: float = 0.0
    height_offset_m: float = 0.0
    room_m: tuple = ROOM_M

    def bound_m(self, kind: str, fusion: bool, sigma_rss_db: float, sigma_acc_mps2: float = SIGMA_ACC_MPS2, *,
                rng: np.random.Generator | None = None) -> np.ndarray:
        """Position PCRLB (Eq. (4.23), m) per step; an SMC bound draws its trajectories from ``rng`` (default: a
        generator of the study's one seed, so that every curve uses the same trajectories); a linear bound is
        deterministic."""
        if kind == "smc" and rng is None:
            rng = np.random.default_rng(self.smc_seed)
        elif kind != "smc":
            rng = None
        return pcrlb_m(kind, fusion=fusion, sigma_rss_db=sigma_rss_db, mse_mle_m2=self.mse_mle_m2[sigma_rss_db],
                       n_steps=self.n_steps, sigma_acc_mps2=sigma_acc_mps2, rng=rng, n_trajectories=self.n_trajectories,
                       acc_at_rss_epochs=self.acc_at_rss_epochs, min_distance_m=self.min_distance_m,
                       height_offset_m=self.height_offset_m, room_m=self.room_m, anchors_m=corner_anchors(self.room_m))

    def replicate_se(self, statistic, kind: str, fusion: bool, sigma_rss_db: float,
                     sigma_acc_mps2: float = SIGMA_ACC_MPS2) -> float:
        """Monte-Carlo standard error of ``statistic(bound)``: the standard deviation of independent SMC replicates
        of the same size (:func:`locbook.montecarlo.replicate_standard_error`); 0 for the deterministic linear
        bound."""
        if kind != "smc":
            return 0.0
        return replicate_standard_error(
            lambda rng: statistic(self.bound_m(kind, fusion, sigma_rss_db, sigma_acc_mps2, rng=rng)),
            self.replicate_seeds)


def horizon_ambiguity(bound_m, time_s, horizon_s: float, other_horizons_s) -> Ambiguity:
    """The averaging horizon of Figs. 4.3-4.4's time averages is not printed: the ambiguity is the
    largest change of the average of ``bound_m`` over ``time_s < h`` for the other plausible horizons ``h``, from
    its average over the whole curve (``horizon_s``)."""
    bound_m, time_s = np.asarray(bound_m, float), np.asarray(time_s, float)
    if bound_m.shape != time_s.shape:
        raise ParameterError(f"bound_m and time_s must have one shape, got {bound_m.shape} and {time_s.shape}")
    if not len(other_horizons_s):
        raise ParameterError("other_horizons_s must name at least one other plausible horizon")
    size = max(abs(float(bound_m[time_s < h].mean()) - float(bound_m.mean())) for h in other_horizons_s)
    what = (f"the averaging horizon is not printed: the largest change of the average over "
            f"{', '.join(f'{h:g}' for h in other_horizons_s)} s from {horizon_s:g} s")
    return Ambiguity(size, what, HORIZON_SOURCE)
