"""Ozkaya (2011)'s Sec. 7.2 simulation protocol: the rooms, reader layouts and cells, one printed setting as a
:class:`SimCase`, its truth and RSS draws, the NN / grid Bayes / SIR estimates (:func:`run_case`), the error
statistics of a case (:func:`summarize`) and the CRLB of a layout (Appendix A: the thesis's form and the correct one).
:mod:`locbook.scenarios.ozkaya` gathers this and the other Ozkaya modules.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .._deprecation import renamed_names
from ..bounds.crlb import crlb_rms_over_area_m, rss_crlb_m
from ..errors import ParameterError
from ..metrics import (
    error_std_m,
    mean_error_m,
    median_error_m,
    percentile_error_m,
    position_error_m,
    rmse_m,
    rmse_standard_error_m,
)
from ..models.channel import PathLossModel
from ..models.motion import reflect_into_box
from ..models.rss import RssModel
from ..montecarlo import bootstrap_standard_error, seed_from_values
from ..reproduce.printed_values import printed
from ..static.fingerprint import knn_position, model_fingerprints
from ..tracking.bayes import grid_bayes_filter
from ..tracking.particle import particle_filter

PRINTED = printed("ozkaya2011")


ROOM_M = (5.0, 8.0)
LARGE_ROOM_M = (10.0, 16.0)
#: Simulation channel, Sec. 7.2.1: Reader 2's offline values (Table 6.1) for every reader.
ALPHA_DBM, PATH_LOSS_EXP, SIGMA_DB = (PRINTED.get("Table 6.1", "Reader 2", s).value
                                      for s in ("alpha_dbm", "path_loss_exp", "sigma_db"))
STATISTICS = ("rmse_m", "mean_m", "median_m", "p90_m", "std_m")

#: Reader layouts. Corners: Sec. 7.2.1's separations of 5 m and 8 m (which three corners is not printed; any
#: three are equivalent by symmetry).
#: "half3": the half-separation layout of Fig. 7.6 (separations 2.5 m and 4 m, "to inner region of the
#: environment", Sec. 7.2.2.1 E); its positions are not printed: the corner triangle scaled by 1/2 about the room's
#: centre. "half3_centroid": the same triangle moved so that its centroid is the room's centre
#: (:data:`HALF_SEPARATION_LAYOUTS`, the interpretation ``half_separation_layout``).
#: "large3"/"large4": the 10 m x 16 m room's corners (separations "twice of the default", Sec. 7.2.2.1 F).
LAYOUTS = {
    "corners3": ((0.0, 0.0), (5.0, 0.0), (0.0, 8.0)),
    "corners4": ((0.0, 0.0), (5.0, 0.0), (0.0, 8.0), (5.0, 8.0)),
    "half3": ((1.25, 2.0), (3.75, 2.0), (1.25, 6.0)),
    "half3_centroid": ((5.0 / 3.0, 8.0 / 3.0), (25.0 / 6.0, 8.0 / 3.0), (5.0 / 3.0, 20.0 / 3.0)),
    "large3": ((0.0, 0.0), (10.0, 0.0), (0.0, 16.0)),
    "large4": ((0.0, 0.0), (10.0, 0.0), (0.0, 16.0), (10.0, 16.0)),
}

#: k_CELL -> (nx, ny) lattice patterns (ours for 6, 16, 56, 98, which are not specified in the
#: thesis; 8, 28, 112 are: 2 m, 1 m and 0.5 m spacing). 135 is the 10 x 16 m room.
CELL_PATTERNS = {6: (2, 3), 8: (2, 4), 16: (4, 4), 28: (4, 7), 56: (7, 8), 98: (7, 14), 112: (8, 14), 135: (9, 15)}
#: The cells tile the room shrunk by this margin on every side (Fig. 7.2: 28 cells at x 1..4, y 1..7).
CELL_MARGIN_M = 0.5
#: The interpretation ``half_separation_layout`` -> the layout of :data:`LAYOUTS` it places Table 7.5's half-separation
#: readers at.
HALF_SEPARATION_LAYOUTS = {"scaled_about_centre": "half3", "centroid_at_centre": "half3_centroid"}
#: How a mobile target's Gaussian step that would leave the room is handled (not printed): mirrored at the wall,
#: stopped at the wall, or drawn again until it lands inside.
WALL_HANDLINGS = ("reflect", "clip", "redraw")

#: The contested interpretations of the Sec. 7.2 simulations (locbook/data/interpretations/ozkaya2011.csv):
#: interpretation name -> its values, the first being the default. Each is a notebook parameter of the same name.
SIM_INTERPRETATIONS = {
    # how the median and 90th percentile are taken: from the same errors as the RMSE, mean and std (Sec. 7.2.1,
    # 'From total estimation error data ... using CDF plot'), or two per-run summaries the text does not describe
    "percentile_convention": ("pooled", "per_run_then_averaged", "over_run_rmses"),
    # where a target 'placed at random in the room' (Sec. 7.2.1) is drawn: the room, 1 m in, or the cells' area
    "target_sampling": ("room", "inner", "cell_cores"),
    # the k-NN weights of Eq. (3.3): corrected, as printed, or plain averaging
    "nn_weights": ("inverse_square", "literal_ozkaya2011", "uniform"),
    # noise independent per reader (Eq. (A.6)'s product of one Gaussian per reader, the model the filters and the
    # CRLB use), or one draw 'added on the transmit power' shared by every reader (Secs. 7.2.2.2, 7.2.2.3)
    "reader_noise": ("independent_per_reader", "common_mode"),
    # a fixed target's noise: drawn once per run (one erroneous measurement at a location, 'a worst case scenario'),
    # or afresh with every measurement
    "fixed_target_noise": ("frozen_per_run", "fresh_per_step"),
    # a mobile target's statistics: of the error at recursion rt (after the wait 'for the filter to settle'), or of
    # the errors of every recursion ('estimation will be done for every step', Sec. 7.2.1)
    "mobile_protocol": ("reflect_error_at_rt", "mean_over_recursions"),
    # a mobile target's step that would leave the room: mirrored, stopped at the wall, or drawn again (not printed)
    "wall_handling": WALL_HANDLINGS,
    # where Table 7.5's half-separation readers stand (Fig. 7.6, not printed): HALF_SEPARATION_LAYOUTS
    "half_separation_layout": tuple(HALF_SEPARATION_LAYOUTS),
    # Table 7.21's 'known initial location': every particle / all the belief at the true start, or spread about it
    # with the filter's D (a Gaussian prior on the initial state)
    "known_initial_location": ("exact", "gaussian_d"),
    # Table 7.24's N_t = 0.5: a fraction of N, or N_eff < 0.5 particles as printed (never true: N_eff >= 1)
    "resample_threshold": ("fraction_of_n", "absolute"),
}


def room_for(layout: str):
    return LARGE_ROOM_M if layout.startswith("large") else ROOM_M


def readers_for(layout: str) -> np.ndarray:
    if layout not in LAYOUTS:
        raise ValueError(f"unknown reader layout {layout!r}; choose from {sorted(LAYOUTS)}")
    return np.array(LAYOUTS[layout])


def cell_centres(room_m, nx: int, ny: int, margin_m: float = 0.5) -> np.ndarray:
    """Centres of an ``nx x ny`` partition of the room shrunk by ``margin_m`` on every side.

    With the default margin this gives the thesis's 28 cells at x in {1..4}, y in {1..7} (Fig. 7.2), the
    112 cells at 0.5 m spacing and the 135 cells of the 10 x 16 m room (Tables 7.1, 7.6).
    """
    w, h = room_m[0] - 2 * margin_m, room_m[1] - 2 * margin_m
    xs = margin_m + w * (np.arange(nx) + 0.5) / nx
    ys = margin_m + h * (np.arange(ny) + 0.5) / ny
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    return np.column_stack([gx.ravel(), gy.ravel()])


def printed_tables() -> list[dict]:
    """Every printed number of Tables 7.1-7.46 (locbook/data/printed/ozkaya2011.csv): dicts with
    ``table, row, column, value`` (float) and the :class:`~locbook.reproduce.Printed` itself (``printed``)."""
    return [{"table": p.location.removeprefix("Table "), "row": p.item, "column": p.statistic, "value": p.value,
             "printed": p} for p in printed("ozkaya2011") if p.location.startswith("Table 7.")]


def printed_cell(table: str, row: str, column: str):
    """The :class:`~locbook.reproduce.Printed` of a cell of Tables 7.1-7.46, or None where the thesis prints none."""
    return printed("ozkaya2011").find(f"Table {table}", row, column)


def printed_value(table: str, row: str, column: str) -> float | None:
    cell = printed_cell(table, row, column)
    return None if cell is None else cell.value


@dataclass(frozen=True)
class SimCase:
    """One simulated setting. Defaults are the thesis's stated controls (Sec. 7.2.1-7.2.2).

    method: ``"nn"`` (parameter-based NN, offline parameters), ``"grid"`` or ``"sir"``.
    target: ``"fixed"`` (a uniform position), ``"mobile"`` (Gaussian steps of ``motion_m``, fresh noise; a step leaving
        the room handled per ``wall_handling``: ``"reflect"``, ``"clip"`` or ``"redraw"``, :data:`WALL_HANDLINGS`),
        ``"const_velocity"`` (Table 7.20: +0.5 m in y per recursion from y = 1, random x, fresh noise).
    sigma0_db / sigma_db: simulated noise / the filter's model. spread_m: the filter's D (inf = uniform).
    filter_region / target_region: ``"room"``, ``"inner"`` (1 m from the walls, Table 7.22) or ``"cell_cores"``
        (the area the cells tile, :data:`CELL_MARGIN_M` in; target regions only).
    resample_threshold: None = every step (basic SIR); else the N_eff threshold, read per ``resample_threshold_unit``:
        ``"fraction_of_n"`` (N_eff < threshold N) or ``"absolute"`` (N_eff < threshold, as Table 7.24 prints it).
    nn_weights: the k-NN weighting of Eq. (3.3) (:data:`~locbook.static.fingerprint.KNN_WEIGHTINGS`).
    reader_noise: ``"independent_per_reader"`` (i.i.d. per reader, Eq. (A.6)) or ``"common_mode"`` (one draw per
        run and step shared by every reader: noise "added on the transmit power", Secs. 7.2.2.2-7.2.2.3).
    fixed_target_noise: ``"frozen_per_run"`` (a fixed target's noise drawn once per run) or ``"fresh_per_step"`` (a new
        draw with every measurement).
    known_initial / initial_location: Table 7.21's known start: ``"exact"`` (every particle, or all the grid belief,
        at the true start) or ``"gaussian_d"`` (spread about it with the filter's D).
    """

    method: str
    target: str = "fixed"
    layout: str = "corners3"
    k_cell: int = 28
    k_nn: int = 4
    sigma0_db: float = SIGMA_DB
    sigma_db: float = SIGMA_DB
    spread_m: float = 0.5
    motion_m: float = 0.5
    rt: int = 10
    estimator: str = "mmse"
    known_velocity: bool = False
    known_initial: bool = False
    filter_region: str = "room"
    target_region: str = "room"
    n_particles: int = 250
    resample_threshold: float | None = None
    weight_smoothing: str = "none"
    velocity_m: float = 0.5
    alpha_dbm: float = ALPHA_DBM
    path_loss_exp: float = PATH_LOSS_EXP
    nn_weights: str = "inverse_square"
    reader_noise: str = "independent_per_reader"
    fixed_target_noise: str = "frozen_per_run"
    resample_threshold_unit: str = "fraction_of_n"
    wall_handling: str = "reflect"
    initial_location: str = "exact"

    def describe(self) -> str:
        base = SimCase(self.method)
        return ", ".join(f"{k}={v}" for k, v in asdict(self).items() if k == "method" or v != getattr(base, k))


def _region(kind: str, room_m):
    if kind == "room":
        return np.zeros(2), np.asarray(room_m, float)
    if kind == "inner":
        return np.ones(2), np.asarray(room_m, float) - 1.0
    if kind == "cell_cores":
        return np.full(2, CELL_MARGIN_M), np.asarray(room_m, float) - CELL_MARGIN_M
    raise ValueError(f"region must be 'room', 'inner' or 'cell_cores', got {kind!r}")


_TRUTH_FIELDS = ("target", "layout", "sigma0_db", "motion_m", "target_region", "velocity_m", "alpha_dbm",
                 "path_loss_exp")


def case_seed_sequence(seed: int, case: SimCase) -> np.random.SeedSequence:
    """The stream of a setting, keyed by what draws the truth and the RSSI (target protocol, layout, noise,
    steps). Settings that differ only in the estimator (k_NN, cells, D, N, resampling, weights) therefore see
    the same targets and noise: common random numbers, so a sweep's rows differ by the method alone, as the
    thesis's repeated rows do. Adding a setting never shifts another's numbers. The noise interpretations
    (``reader_noise``, ``fixed_target_noise``) and the wall handling are left out of the key on purpose: the targets'
    steps are drawn before the noise, so a setting under another noise interpretation sees the same targets, and one
    under another wall handling the same steps (``"redraw"`` then draws more)."""
    key = {f: getattr(case, f) for f in _TRUTH_FIELDS}
    key["steps"] = 1 if case.method == "nn" else case.rt
    return np.random.SeedSequence([seed, seed_from_values(key)])


def simulate_truth_and_rss(case: SimCase, n_runs: int, rng: np.random.Generator):
    """Target positions ``(R, T, 2)`` and RSSI ``(R, T, m)`` for the case's target protocol (Sec. 7.2.1).

    Noise: ``N(0, sigma0^2)`` per run, step and reader; ``reader_noise="common_mode"`` draws one value per run and
    step for every reader (noise on the target's transmit power), ``fixed_target_noise="frozen_per_run"`` one per
    run for a fixed target (the same vector at every recursion)."""
    check_interpretation("reader_noise", case.reader_noise)
    check_interpretation("fixed_target_noise", case.fixed_target_noise)
    check_interpretation("wall_handling", case.wall_handling)
    room = room_for(case.layout)
    readers = readers_for(case.layout)
    lo, hi = _region(case.target_region, room)
    steps = 1 if case.method == "nn" else case.rt
    if case.target == "const_velocity":
        start = np.column_stack([lo[0] + (hi[0] - lo[0]) * rng.random(n_runs), np.ones(n_runs)])
        truth = start[:, None, :] + case.velocity_m * np.arange(1, steps + 1)[None, :, None] * np.array([0.0, 1.0])
    else:
        start = lo + (hi - lo) * rng.random((n_runs, 2))
        if case.target == "mobile":
            moves = case.motion_m * rng.standard_normal((n_runs, steps, 2))
            moves[:, 0] = 0.0
            truth = np.empty((n_runs, steps, 2))
            truth[:, 0] = start
            for t in range(1, steps):
                truth[:, t] = _step_inside(truth[:, t - 1], moves[:, t], lo, hi, case, rng)
        elif case.target == "fixed":
            truth = np.broadcast_to(start[:, None, :], (n_runs, steps, 2))
        else:
            raise ValueError(f"unknown target protocol {case.target!r}")
    model = RssModel(readers, PathLossModel(case.alpha_dbm, case.path_loss_exp, case.sigma0_db, min_distance_m=0.1))
    mean = model.mean_rss_dbm(truth)                                    # (R, T, m): steps as positions
    frozen = case.target == "fixed" and case.fixed_target_noise == "frozen_per_run"
    noise_shape = (n_runs, 1 if frozen else steps, 1 if case.reader_noise == "common_mode" else readers.shape[0])
    rss = mean + case.sigma0_db * rng.standard_normal(noise_shape)
    return np.asarray(truth), rss


def _step_inside(previous_m, move_m, lo, hi, case: SimCase, rng: np.random.Generator, max_redraws: int = 1000):
    """One mobile step ``previous + move`` kept in the box ``[lo, hi]`` per ``case.wall_handling``: mirrored at the
    walls (``"reflect"``), stopped at the wall it crosses (``"clip"``), or the step drawn again from
    ``N(0, motion_m^2 I)`` until it lands inside (``"redraw"``, a truncated Gaussian step)."""
    moved = previous_m + move_m
    if case.wall_handling == "reflect":
        return reflect_into_box(moved, lo, hi)
    if case.wall_handling == "clip":
        return np.clip(moved, lo, hi)
    for _ in range(max_redraws):
        outside = np.any((moved < lo) | (moved > hi), axis=-1)
        if not outside.any():
            return moved
        moved[outside] = previous_m[outside] + case.motion_m * rng.standard_normal((int(outside.sum()), 2))
    return np.clip(moved, lo, hi)          # a step that never lands inside (a tiny box): stop at the wall


def resample_fraction(case: SimCase) -> float | None:
    """The SIR's N_eff threshold as the fraction of N that :func:`~locbook.tracking.particle.particle_filter` takes:
    ``resample_threshold`` itself under ``"fraction_of_n"``, ``resample_threshold / N`` under ``"absolute"`` (Table
    7.24's ``N_eff < 0.5`` read literally: since N_eff >= 1 it never resamples); None (every step) stays None."""
    check_interpretation("resample_threshold", case.resample_threshold_unit)
    if case.resample_threshold is None or case.resample_threshold_unit == "fraction_of_n":
        return case.resample_threshold
    return case.resample_threshold / case.n_particles


def run_case(case: SimCase, n_runs: int, seed: int, *, return_all: bool = False):
    """Errors (m) at the last recursion, one per run; with ``return_all`` also the per-step errors
    ``(R, T)``, the truth and the estimates."""
    rng = np.random.default_rng(case_seed_sequence(seed, case))
    truth, rss = simulate_truth_and_rss(case, n_runs, rng)
    room = room_for(case.layout)
    readers = readers_for(case.layout)
    filter_model = RssModel(readers, PathLossModel(case.alpha_dbm, case.path_loss_exp, case.sigma_db,
                                                   min_distance_m=0.1))
    if case.method in ("nn", "grid"):
        cells = cell_centres(room, *CELL_PATTERNS[case.k_cell])
    if case.method == "nn":
        fp = model_fingerprints(cells, RssModel(readers, PathLossModel(case.alpha_dbm, case.path_loss_exp)))
        estimate = knn_position(rss, fp, cells, case.k_nn, case.nn_weights)
    elif case.method == "grid":
        velocity = (0.0, case.velocity_m) if case.known_velocity else None
        initial = None
        if case.known_initial:
            check_interpretation("known_initial_location", case.initial_location)
            if case.initial_location == "exact":
                initial = np.zeros((n_runs, cells.shape[0]))
                initial[np.arange(n_runs), np.argmin(np.sum((cells[None] - truth[:, :1]) ** 2, -1), -1)] = 1.0
            else:                                           # Gaussian about the start with the filter's D
                d2 = np.sum((cells[None] - truth[:, :1]) ** 2, -1)
                initial = np.exp(-(d2 - d2.min(-1, keepdims=True)) / (2.0 * case.spread_m ** 2))
                initial /= initial.sum(-1, keepdims=True)
        res = grid_bayes_filter(rss, filter_model, cells, case.spread_m, velocity_m=velocity, initial_belief=initial)
        estimate = res.mean if case.estimator == "mmse" else res.map_m
    elif case.method == "sir":
        res = particle_filter(
            rss, filter_model, rng=rng, n_particles=case.n_particles, region_m=_region(case.filter_region, room),
            spread_m=case.spread_m, velocity_m=(0.0, case.velocity_m) if case.known_velocity else None,
            initial_position_m=truth[:, 0] if case.known_initial else None,
            initial_sd_m=_initial_sd_m(case),
            resample_threshold=resample_fraction(case), weight_smoothing=case.weight_smoothing)
        estimate = res.mean if case.estimator == "mmse" else res.map_m
    else:
        raise ValueError(f"unknown method {case.method!r}")
    errors = position_error_m(estimate, truth)
    if return_all:
        return errors[:, -1], errors, truth, estimate
    return errors[:, -1]


def _initial_sd_m(case: SimCase) -> float:
    """The spread of the SIR's particles about a known start (Table 7.21): 0 (every particle at it) under
    ``initial_location="exact"``, the filter's D under ``"gaussian_d"``; 0 when the start is not known."""
    if not case.known_initial:
        return 0.0
    check_interpretation("known_initial_location", case.initial_location)
    return float(case.spread_m) if case.initial_location == "gaussian_d" and np.isfinite(case.spread_m) else 0.0


_STATISTIC_FUNCTIONS = {"rmse_m": rmse_m, "mean_m": mean_error_m, "median_m": median_error_m,
                        "p90_m": percentile_error_m, "std_m": error_std_m}
_PERCENTILES = {"median_m": 50.0, "p90_m": 90.0}


def _sample(errors_m, over_recursions: bool):
    """The errors every statistic of a table is taken from (one population for all): of every recursion of every
    run ``(..., R*T)`` when ``over_recursions``, else of recursion rt of every run ``(..., R)``; ``errors_m`` is
    ``(..., R, T)``."""
    if over_recursions:
        return errors_m.reshape(errors_m.shape[:-2] + (-1,))
    return errors_m[..., -1]


def _percentile_over_runs(errors_m, q: float, convention: str, over_recursions: bool = False):
    """The ``q``-th percentile of per-step errors ``(..., R, T)`` under a percentile convention, one per leading
    index, always over the recursions the other statistics use (:func:`_sample`): ``pooled``, the percentile of
    those errors themselves (the CDF of 'total estimation error data', Sec. 7.2.1); ``per_run_then_averaged``, the
    mean over runs of each run's percentile over its recursions (recursion rt alone: its error); ``over_run_rmses``,
    the percentile over runs of each run's RMSE over its recursions (recursion rt alone: its error)."""
    if convention == "pooled":
        return np.percentile(_sample(errors_m, over_recursions), q, axis=-1)
    per_run = errors_m if over_recursions else errors_m[..., -1:]
    if convention == "per_run_then_averaged":
        return np.mean(np.percentile(per_run, q, axis=-1), axis=-1)
    return np.percentile(np.sqrt(np.mean(np.square(per_run), axis=-1)), q, axis=-1)      # over_run_rmses


def summarize(errors, rng: np.random.Generator | None = None, *,
              percentile_convention: str = "pooled", over_recursions: bool = False) -> dict:
    """The printed statistics (Sec. 7.2.1: RMSE, mean, median, 90th percentile, std) of the errors, and with ``rng``
    their Monte-Carlo standard errors (``<statistic>_se``).

    ``errors``: one last-recursion error per run ``(R,)``, or the per-step errors ``(R, T)`` (the last column being
    recursion rt). All five statistics come from the same errors (Sec. 7.2.1: 'From total estimation error data we
    calculate the mean ..., RMSE, and std. ... using CDF plot we give median ... and 90 percentile error'): recursion
    rt of every run, or with ``over_recursions`` every recursion of every run (the ``"mean_over_recursions"``
    mobile protocol). ``percentile_convention`` (:data:`SIM_INTERPRETATIONS`, :func:`_percentile_over_runs`) is
    ``"pooled"`` by default; its two per-run alternatives are kept for exploration, not declared as interpretations.

    Standard errors: the delta method for the RMSE (over the runs' mean squared errors) and the bootstrap over
    whole runs for the rest (a run's recursions are not independent).
    """
    check_interpretation("percentile_convention", percentile_convention)
    errors = np.asarray(errors, float)
    if errors.ndim not in (1, 2):
        raise ParameterError(f"errors must be (runs,) or (runs, recursions), got shape {errors.shape}")
    per_step = errors if errors.ndim == 2 else errors[:, None]
    if percentile_convention == "pooled" and not over_recursions:
        last = per_step[:, -1]
        out = {k: float(f(last)) for k, f in _STATISTIC_FUNCTIONS.items()}
        out["rmse_se_m"] = float(rmse_standard_error_m(last))
        if rng is not None:
            for k, f in _STATISTIC_FUNCTIONS.items():
                out[k + "_se"] = out["rmse_se_m"] if k == "rmse_m" else bootstrap_standard_error(last, f, rng=rng)
        return out

    def statistics(e):            # (..., R, T) -> {statistic: (...)}
        sample = _sample(e, over_recursions)
        got = {k: _STATISTIC_FUNCTIONS[k](sample, axis=-1) for k in ("rmse_m", "mean_m", "std_m")}
        got.update({k: _percentile_over_runs(e, q, percentile_convention, over_recursions)
                    for k, q in _PERCENTILES.items()})
        return got

    got = statistics(per_step)
    out = {k: float(got[k]) for k in _STATISTIC_FUNCTIONS}
    n_runs = per_step.shape[0]
    if n_runs < 2:
        raise ParameterError(f"errors: a standard error needs at least two Monte-Carlo runs, got {n_runs}")
    # delta method over the runs' mean squared errors (independent across runs, unlike a run's recursions)
    run_ms = np.mean(np.square(per_step), axis=1) if over_recursions else np.square(per_step[:, -1])
    out["rmse_se_m"] = float(np.std(run_ms, ddof=1) / np.sqrt(n_runs) / (2.0 * np.sqrt(np.mean(run_ms))))
    if rng is not None:
        resampled = statistics(per_step[rng.integers(0, n_runs, size=(200, n_runs))])
        for k in _STATISTIC_FUNCTIONS:
            out[k + "_se"] = out["rmse_se_m"] if k == "rmse_m" else float(np.std(resampled[k], ddof=1))
    return out


# -- bounds ------------------------------------------------------------------------------------------
def _area_points(room_m, step_m: float = 0.05):
    xs = np.arange(step_m / 2, room_m[0], step_m)
    ys = np.arange(step_m / 2, room_m[1], step_m)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    return np.column_stack([gx.ravel(), gy.ravel()])


def thesis_crlb_m(layout: str, sigma_db: float, path_loss_exp: float = PATH_LOSS_EXP,
                  average: str = "area_rms") -> float:
    """The thesis's CRLB columns: Eqs. (A.10)-(A.13) as printed (1/d^2, flagged ``variant="literal_ozkaya2011"``), by
    default with the simulations' n = 2.3 (Sec. 7.2.1) and as the RMS over the room ("Square root of (A.13) is used in
    the thesis to compare with RMS error", Appendix A): 0.711 / 0.557 m for 3 / 4 corner readers at 5.2 dB.

    Which exponent and which averaging over target positions gave the printed CRLB columns is not stated. The
    interpretations fitted to them (:data:`FITTED_VALUES`, named alternatives) are n = 2 and ``"cells_mean"``, the mean
    of the per-position bound over the 1 m grid cells of the layout's room (28 cells in 5 x 8 m): 0.7999 / 0.6392 m at
    5.2 dB and 0.1538 m per dB, i.e. every printed value 0.15 / 0.46 / 0.80 / 1.08 / 1.38 / 1.70. The printed
    bound is proportional to sigma / n (Eqs. A.10-A.12 scale as (n / sigma)^2).
    """
    room = room_for(layout)
    model = RssModel(readers_for(layout), PathLossModel(0.0, path_loss_exp, sigma_db))
    if average == "cells_mean":
        points = cell_centres(room, int(room[0]) - 1, int(room[1]) - 1)
        return float(np.mean(rss_crlb_m(points, model, variant="literal_ozkaya2011")))
    if average == "area_rms":
        return crlb_rms_over_area_m(_area_points(room), model, variant="literal_ozkaya2011")
    raise ValueError(f"average must be 'cells_mean' or 'area_rms', got {average!r}")


def correct_crlb_m(layout: str, sigma_db: float, path_loss_exp: float = PATH_LOSS_EXP) -> float:
    """The correct RSS CRLB (1/d^4, Patwari et al. 2003) with the simulation's n, RMS over the room."""
    room = room_for(layout)
    return crlb_rms_over_area_m(_area_points(room), RssModel(readers_for(layout), PathLossModel(0.0, path_loss_exp,
                                                                                              sigma_db)))


def check_interpretation(name: str, value) -> None:
    if value not in SIM_INTERPRETATIONS[name]:
        raise ParameterError(f"{name} must be one of {SIM_INTERPRETATIONS[name]}, got {value!r}")


# the names before "reading" meant only a sensor measurement (deprecated for one release)
__getattr__ = renamed_names(__name__, {
    "SIM_READINGS": "SIM_INTERPRETATIONS",
    "check_reading": "check_interpretation",
})
