"""The cross-document benchmark: every static method on every document's static scenario and on the measured data,
every tracker on every tracking scenario, each beside its bound.

Scenarios are declared in registries here (:data:`STATIC_SCENARIOS`, :data:`TRACKING_SCENARIOS`), methods once in
:mod:`locbook.battery` (:data:`STATIC_METHODS`, :data:`TRACKERS`): adding an entry adds a column or a row of the
table and the heat map.
No source printed these numbers; nothing here is scored against a printed value.

One protocol for every cell (each choice a named setting, reported with the cell):

- Synthetic scenarios take each document's geometry and channel (the values its own experiment uses, or our
  stated default where it prints none, cited per setting) with i.i.d. log-normal shadowing, the model both
  bounds assume. The estimators know the true channel, so a cell measures the method and the geometry, not a
  calibration. All methods of a scenario see the same draws (common random numbers).
- A data set's column (the notebook's ``data`` parameter lists them) is not computed here: it is the ``pooled`` rows
  of the measured-data protocol (:func:`locbook.scenarios.measured.static_results`,
  :func:`~locbook.scenarios.measured.tracking_results`, :func:`~locbook.scenarios.measured.benchmark_rows`), the
  same calls as the data set's own reports (its settings from the data, its trackers started from the first fix,
  its bound without the epochs where it is undefined).
- Static bound: the CRLB ``sqrt(tr J^-1)`` at each true position; the cell's ratio is the RMSE over all fixes
  divided by the RMS of the bound over the positions. Methods that know the room (box-LS, grid ML, grid MMSE,
  k-NN) use information the CRLB does not have and may fall below it.
- Tracking bound: the posterior CRLB (Tichavsky recursion, :func:`locbook.bounds.pcrlb.posterior_crlb`) of the
  constant-velocity model the Kalman trackers use (white-acceleration variance ``q``), with the prior ``N(x_0, P_0)``
  every tracker starts from, evaluated along the true path (Dogan's truth-conditioned bound). The paths are the
  documents' deterministic ones, not draws of that model, so the bound is the reference of the filters' own model
  and a ratio below 1 is possible.
- Every tracker of a synthetic scenario starts from the same prior: the true initial state plus a draw of
  ``N(0, P_0)`` per run (the Kalman filters' mean; the particles drawn around it; the grid's belief the same
  Gaussian).
"""
from __future__ import annotations

import numpy as np

from .battery import (
    STATIC_METHODS,
    TRACKER_PRIORS,
    TRACKERS,
    ProtocolChoice,
    StaticScenario,
    TrackerSettings,
    TrackingScenario,
    channel_settings,
    initial_states,
    run_trackers,
    static_bound_m,
    static_fixes,
    tracking_bound_m,
)
from .geometry import box_outline
from .metrics import accuracy_metrics, position_error_m, rmse_standard_error_m
from .models.channel import PathLossModel
from .montecarlo import seed_from_values
from .scenarios import dogan, george, gudipati, ozkaya, palvai
from .scenarios.measured import measured_static_scenario, measured_tracking_scenario

__all__ = ["ProtocolChoice", "StaticScenario", "TrackingScenario", "STATIC_SCENARIOS", "TRACKING_SCENARIOS",
           "measured_static_scenario", "measured_tracking_scenario",
           "STATIC_METHODS", "TRACKERS", "NOT_APPLICABLE", "TrackerSettings", "static_scenario", "tracking_scenario",
           "static_fixes", "static_bound_m", "run_trackers", "tracking_bound_m", "initial_states", "score",
           "scenario_rng", "static_cells", "tracking_cells", "settings_rows", "TRACKER_PRIORS"]


# ---------------------------------------------------------------------------------------------------- scenarios

def _george_static() -> StaticScenario:
    model = PathLossModel(-45.0, george.PRINTED_N.value, 1.83)
    src = "george-tracking defaults: A = -45 dBm (not printed; raw RSSI 0 at 1 m by Eq. (3)), n = the printed " \
          "calibrated n (Sec. 6), sigma 1.83 dB (not printed; chosen to match the printed C_raw: a calibration)"
    w, h = george.CORRIDOR_SIZE_M
    return StaticScenario(
        "george-corridor", "george", "2.1 x 7.8 m corridor, 4 corner anchors", george.ANCHORS_M, model,
        box_outline((0, 0), (w, h)), george.trajectory_m("centerline"), 0.05,
        (ProtocolChoice("anchors", "4 corners (0,0) (2.1,0) (0,7.8) (2.1,7.8)", "Sec. 5"),
         *channel_settings(model, src),
         ProtocolChoice("positions", "the 25 marked points on the centre line, y 0.3-7.5 m",
                        "not printed; our default"),
         ProtocolChoice("grid pitch", "0.05 m", "benchmark: fine against the corridor's 2.1 m width")))


def _ozkaya_static() -> StaticScenario:
    model = PathLossModel(ozkaya.ALPHA_DBM, ozkaya.PATH_LOSS_EXP, ozkaya.SIGMA_DB)
    return StaticScenario(
        "ozkaya2011-room", "ozkaya2011", "5 x 8 m room, 3 corner readers", ozkaya.readers_for("corners3"), model,
        box_outline((0, 0), ozkaya.ROOM_M), ozkaya.cell_centres(ozkaya.ROOM_M, *ozkaya.CELL_PATTERNS[28]), 0.1,
        (ProtocolChoice("readers", "3 corners (layout corners3)", "Sec. 7.2.1 (which three: not printed)"),
         *channel_settings(model, "Table 6.1, Reader 2 (the simulation channel, Sec. 7.2.1)"),
         ProtocolChoice("positions", "the 28 cell centres (x 1-4 m, y 1-7 m)", "Fig. 7.2"),
         ProtocolChoice("grid pitch", "0.1 m", "benchmark")))


def _dogan_static() -> StaticScenario:
    model = PathLossModel(dogan.REF_POWER_DBM, dogan.PATH_LOSS_EXP, dogan.SIGMA_RSS_DB)
    walk = dogan.walk_trajectory()
    return StaticScenario(
        "dogan2015-room", "dogan2015", "7.6 x 9.2 m room, 4 corner anchors", dogan.ANCHORS_M, model,
        box_outline((0, 0), dogan.ROOM_M), walk.position_m[walk.rss_steps], 0.1,
        (ProtocolChoice("anchors", "4 corners", "Sec. 5.4"), *channel_settings(model, "Table 3.6"),
         ProtocolChoice("positions", f"the walk's {len(walk.rss_steps)} RSS epochs (0.3 m/s polyline, 2 Hz)",
                 "path not printed (our default); where the thesis's MLE is computed"),
         ProtocolChoice("grid pitch", "0.1 m", "benchmark")))


#: Gudipati's readings: shadowing 3 dB plus 1 dB per-packet noise (our defaults), as one i.i.d. term of the same
#: variance
GUDIPATI_SIGMA_DB = float(np.hypot(gudipati.WalkSettings().shadowing_sigma_db, gudipati.WalkSettings().fast_sigma_db))


def _gudipati_model() -> PathLossModel:
    return gudipati.channel_model(gudipati.ANCHOR_SETS[6], GUDIPATI_SIGMA_DB)


def _u_path_points(spacing_m: float, dt_s: float):
    """Positions along the U-path every ``spacing_m`` of arc length (static) or every ``dt_s`` (tracking)."""
    tr = gudipati.path_trajectory("u", gudipati.WalkSettings(dt_s=dt_s))
    pos = tr.position_m
    return pos, np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pos, axis=0), axis=1))])


def _gudipati_static() -> StaticScenario:
    model = _gudipati_model()
    pos, arc = _u_path_points(gudipati.REPORT_SPACING_M, 0.1)
    marks = np.searchsorted(arc, np.arange(0.0, arc[-1], gudipati.REPORT_SPACING_M))
    return StaticScenario(
        "gudipati2017-hall", "gudipati2017", "30 x 10 m hall, 6 anchors", gudipati.anchors_m(gudipati.ANCHOR_SETS[6]),
        model, box_outline((0, 0), gudipati.ROOM_M), pos[marks], 0.2,
        (ProtocolChoice("anchors", "12-15 at the corners, 16-17 mid long walls", "Sec. 5.1 (which ID where: ours)"),
         *channel_settings(model, "Table 5.2 (S, C per anchor); sigma: 3 dB shadowing and 1 dB per packet "
                                   "(our defaults) as one i.i.d. term (the bounds' model; the thesis's walk has "
                                   "correlated shadowing)"),
         ProtocolChoice("positions", f"the U-path's report points every {gudipati.REPORT_SPACING_M:g} m ({len(marks)})",
                 "Sec. 5.3; path geometry not printed (ours)"),
         ProtocolChoice("grid pitch", "0.2 m", "benchmark")))


#: Palvai: the 25 measurement locations are drawn once, in the plane, from this seed (the thesis redraws them per
#: run; one fixed geometry makes its CRLB one number)
PALVAI_GEOMETRY_SEED = 2008


def _palvai_static() -> StaticScenario:
    setup = palvai.Setup(dim=2)
    receivers = palvai.draw_locations(1, palvai.N_LOCATIONS, 2, np.random.default_rng(PALVAI_GEOMETRY_SEED))[0]
    model = setup.channel
    return StaticScenario(
        "palvai2008-area", "palvai2008", "50 x 50 m area, emitter seen from 25 receiver positions", receivers, model,
        box_outline((0, 0), (palvai.AREA_M, palvai.AREA_M)), setup.target[None], 0.25,
        (ProtocolChoice("receivers", f"{palvai.N_LOCATIONS} positions uniform in the area, drawn once (seed "
                              f"{PALVAI_GEOMETRY_SEED}), exactly known", "Sec. 4.4 (N = 25; law ours); sigma_3 = 0"),
         *channel_settings(model, "Secs. 2.6, 4.4 (sigma_1, eta); K = -20 dBm at 1 m (not printed; ours)"),
         ProtocolChoice("positions", "the emitter at the area's centre (25, 25)", "not printed (ours)"),
         ProtocolChoice("plane", "2-D (the thesis's equations are 3-D)", "ours (Sec. 5.4 reads its clouds in 2-D)"),
         ProtocolChoice("grid pitch", "0.25 m", "benchmark: 40,000 cells over the area")))


STATIC_SCENARIOS = {"george-corridor": _george_static, "ozkaya2011-room": _ozkaya_static,
                    "dogan2015-room": _dogan_static, "gudipati2017-hall": _gudipati_static,
                    "palvai2008-area": _palvai_static}


def static_scenario(key: str, **kwargs) -> StaticScenario:
    if key not in STATIC_SCENARIOS:
        raise ValueError(f"unknown static scenario {key!r}; declared: {sorted(STATIC_SCENARIOS)}")
    return STATIC_SCENARIOS[key](**kwargs)


def _george_tracking() -> TrackingScenario:
    st = _george_static()
    return TrackingScenario(
        "george-walk", "george", "corridor centre line, 25 points at 1 s", st.anchors_m, st.channel, st.outline_m,
        george.trajectory_m("centerline"), 1.0, 0.3, 0.05,
        (*st.settings[:4], ProtocolChoice("path", "centre line, y 0.3 -> 7.5 m, one point per second (0.3 m/s)",
                                   "not printed (our default); dt: george-tracking dt_s")))


def _ozkaya_tracking() -> TrackingScenario:
    st = _ozkaya_static()
    steps = np.arange(1, 11)
    truth = np.column_stack([np.full(steps.size, 2.5), 1.0 + 0.5 * steps])
    return TrackingScenario(
        "ozkaya2011-constant-velocity", "ozkaya2011", "+0.5 m in y per recursion, 10 recursions", st.anchors_m,
        st.channel, st.outline_m, truth, 1.0, 0.5, 0.1,
        (*st.settings[:4], ProtocolChoice("path", "x = 2.5 m, y = 1 + 0.5 k m, k = 1..10 (one recursion = 1 s)",
                                   "Table 7.20 protocol (x drawn at random there; the room's middle here)")))


def _dogan_tracking() -> TrackingScenario:
    st = _dogan_static()
    walk = dogan.walk_trajectory()
    return TrackingScenario(
        "dogan2015-walk", "dogan2015", "0.3 m/s polyline, RSS at 2 Hz", st.anchors_m, st.channel, st.outline_m,
        walk.position_m[walk.rss_steps], dogan.DT_S * dogan.RSS_EVERY, 0.15, 0.1,
        (*st.settings[:4], ProtocolChoice("path", "the 24 m polyline at 0.3 m/s from rest, at its RSS epochs (0.5 s); "
                                           "RSS only (the accelerometer is not used here)",
                                   "path not printed (our default); Sec. 3.5")))


#: Gudipati's filters step at every 0.1 s packet; the benchmark steps at 0.5 s (one reading per anchor per step),
#: so that a 0.2 m grid can follow the 0.25 m per-step random walk (at 0.1 s the walk's 0.05 m would need a grid
#: finer than 0.05 m over 300 m^2)
GUDIPATI_TRACKING_DT_S = 0.5


def _gudipati_tracking() -> TrackingScenario:
    st = _gudipati_static()
    pos, _ = _u_path_points(1.0, GUDIPATI_TRACKING_DT_S)
    return TrackingScenario(
        "gudipati2017-u-path", "gudipati2017", "U-path at 0.5 m/s, RSS every 0.5 s", st.anchors_m, st.channel,
        st.outline_m, pos, GUDIPATI_TRACKING_DT_S, 0.25, 0.2,
        (*st.settings[:4], ProtocolChoice("path",
                                          "the U-path (2 m from the walls) at 0.5 m/s with 0.25 m/s^2 ramps and 1 m "
                                          "turn radius; a step every 0.5 s (the thesis: 0.1 s); RSS only",
                                          "path and timing not printed (ours); GUDIPATI_TRACKING_DT_S")))


TRACKING_SCENARIOS = {"george-walk": _george_tracking, "ozkaya2011-constant-velocity": _ozkaya_tracking,
                      "dogan2015-walk": _dogan_tracking, "gudipati2017-u-path": _gudipati_tracking}

#: documents with no scenario of a kind, and why (shown as a blank column with the reason)
NOT_APPLICABLE = {("tracking", "palvai2008"): "a static emitter seen from a moving receiver: there is no moving tag "
                                              "for the trackers (its EKF and particle filter are in palvai2008-*)"}


def tracking_scenario(key: str, **kwargs) -> TrackingScenario:
    if key not in TRACKING_SCENARIOS:
        raise ValueError(f"unknown tracking scenario {key!r}; declared: {sorted(TRACKING_SCENARIOS)}")
    return TRACKING_SCENARIOS[key](**kwargs)



# ------------------------------------------------------------------------------------------------------ scoring

def score(error_m, bound_m, *, measured: bool, rng: np.random.Generator, n_bootstrap: int,
          block_length: int = 1) -> dict:
    """One cell: RMSE and its 95 % interval, mean, median, 90th percentile, the share of missing fixes, the RMS bound
    and the ratio RMSE / RMS bound. ``error_m`` ``(R, P)``. Interval: synthetic data over Monte-Carlo runs (delta
    method on the runs' mean squared errors; a run's points share nothing but the method); measured data by a
    (moving-block) bootstrap over the epochs of the one recording, the runs (filter randomness) averaged first."""
    e = np.asarray(error_m, float)
    finite = np.isfinite(e)
    missing = float(1.0 - finite.mean())
    b = np.asarray(bound_m, float)
    b_rms = float(np.sqrt(np.mean(b[np.isfinite(b)] ** 2))) if np.isfinite(b).any() else float("nan")
    ef = e[finite]
    rmse = float(np.sqrt(np.mean(ef**2))) if ef.size else float("nan")
    if measured or e.shape[0] < 2:
        per_epoch = np.sqrt(np.nanmean(e**2, axis=0))
        # every epoch kept in time order (NaN = no fix): blocks never join epochs across a gap
        m = accuracy_metrics(per_epoch, rng=rng, n_bootstrap=n_bootstrap, block_length=block_length)
        low, high = m["rmse_m_low"], m["rmse_m_high"]
        how = m["interval"] + (f"; {m['interval_note']}" if m["interval_note"] else "")
    else:
        # a run's root-mean-square error: the runs are the independent samples
        se = float(rmse_standard_error_m(np.sqrt(np.nanmean(e**2, axis=1))))
        low, high = rmse - 1.96 * se, rmse + 1.96 * se
        how = f"+/- 1.96 Monte-Carlo SE over {e.shape[0]} runs"
    return {"rmse_m": rmse, "rmse_low_m": float(low), "rmse_high_m": float(high), "interval": how,
            "mean_m": float(np.mean(ef)) if ef.size else float("nan"),
            "median_m": float(np.median(ef)) if ef.size else float("nan"),
            "p90_m": float(np.percentile(ef, 90)) if ef.size else float("nan"),
            "missing": missing, "bound_rms_m": b_rms, "ratio": rmse / b_rms if b_rms > 0 else float("nan")}


# ------------------------------------------------------------------------------------------------ the experiment

def scenario_rng(seed: int, kind: str, key: str) -> np.random.Generator:
    """A scenario's own stream, keyed by its name: adding or removing a scenario never moves another's numbers."""
    return np.random.default_rng(np.random.SeedSequence([seed, seed_from_values(kind, key)]))


def _ratio_note(ratio: float, prior: str) -> str:
    """Why a ratio below 1 can be (the method's prior the bound does not have); "" otherwise."""
    if not (np.isfinite(ratio) and ratio < 1):
        return ""
    return f"below 1: {prior}" if prior else ("below 1 without a prior: the bound holds for unbiased estimators; a "
                                              "biased one (pulled toward the anchors' centre) can beat it")


def _row(kind, sc, method, cell, settings, runs, points, bound_name):
    prior = STATIC_METHODS[method].prior if kind == "static" else TRACKER_PRIORS.get(method, "")
    return {"kind": kind, "scenario": sc.key, "document": sc.document,
            "data": "measured" if sc.measured else "synthetic",
            "method": method, "runs": runs, "points": points, **cell, "ratio_note": _ratio_note(cell["ratio"], prior),
            "bound": bound_name, "settings": settings}


def static_cells(sc: StaticScenario, n_runs: int, rng: np.random.Generator, *, knn_k: int, knn_map_spacing_m: float,
                 n_bootstrap: int) -> list[dict]:
    """Every static method on one scenario: ``n_runs`` draws (one for measured data), scored beside the CRLB."""
    rng_rss, rng_boot = rng.spawn(2)
    rss = sc.rss_dbm(n_runs, rng_rss)
    fixes = static_fixes(sc, rss, knn_k=knn_k, knn_map_spacing_m=knn_map_spacing_m)
    bound = static_bound_m(sc)
    knobs = {"knn": f"k = {knn_k}" + ("" if sc.radio_map is not None else f", map pitch {knn_map_spacing_m:g} m"),
             "grid_ml": f"pitch {sc.grid_spacing_m:g} m", "grid_mmse": f"pitch {sc.grid_spacing_m:g} m",
             "rss_ml": f"start: grid ML at {sc.grid_spacing_m:g} m",
             "rss_ml_free": f"start: grid ML at {sc.grid_spacing_m:g} m"}
    rows = []
    for name, f in fixes.items():
        cell = score(position_error_m(f, sc.points_m), bound, measured=sc.measured, rng=rng_boot,
                     n_bootstrap=n_bootstrap)
        settings = "; ".join(x for x in (STATIC_METHODS[name][2], knobs.get(name, "")) if x)
        rows.append(_row("static", sc, name, cell, settings, rss.shape[0], len(sc.points_m), "CRLB"))
    return rows


def tracking_cells(sc: TrackingScenario, ts: TrackerSettings, n_runs: int, rng: np.random.Generator, *,
                   n_bootstrap: int, block_length: int = 30, with_divergence: bool = False):
    """Every tracker on one scenario: ``n_runs`` runs (fresh readings and prior draws; a measured scenario's one
    recording repeated, the runs differing in the prior draw and the particles: the benchmark's data columns come
    from :func:`locbook.scenarios.measured.tracking_results` instead), scored at the scored ticks beside the PCRLB.
    Returns the rows, the estimates ``{tracker: (R, T, 2)}`` and the bound ``(T,)``; with
    ``with_divergence`` also ``{tracker: flags}`` of the Kalman-family trackers (:func:`run_trackers`). Every cell
    keeps every run."""
    rng_rss, rng_x0, rng_filters, rng_boot = rng.spawn(4)
    rss = sc.rss_dbm(n_runs, rng_rss)
    x0 = initial_states(sc, ts, n_runs, rng_x0)
    est, flags = run_trackers(sc, rss, x0, ts, rng_filters, with_divergence=True)
    bound = tracking_bound_m(sc, ts)
    steps = sc.scored_steps
    common = (f"q = {ts.q:g} m^2/s^4, dt = {sc.dt_s:g} s, "
              f"P0 sd {ts.initial_position_sd_m:g} m / {ts.initial_velocity_sd_m_s:g} m/s")
    knobs = {"kf_on_ml": common + f"; fixes: rss_ml (grid-ML start at {sc.grid_spacing_m:g} m)",
             "ekf": common, "ekf_serial": common, "ukf": common + f"; alpha = {ts.ukf_alpha:g}, beta = 2, kappa = 0",
             "imm": common + f"; manoeuvre mode {ts.imm_q_ratio:g} q, switching {ts.imm_switch_probability:g} per "
                             "step (locbook's choice)",
             "particle": f"N = {ts.n_particles}, random walk {sc.spread_m:g} m/step, start N(x0, P0)",
             "grid_bayes": f"pitch {sc.grid_spacing_m:g} m, random walk {sc.spread_m:g} m/step, start N(x0, P0)"}
    rows = []
    for name, f in est.items():
        cell = score(position_error_m(f[:, steps], sc.truth_m[steps]), bound[steps], measured=sc.measured,
                     rng=rng_boot, n_bootstrap=n_bootstrap, block_length=block_length)
        rows.append(_row("tracking", sc, name, cell, knobs[name], n_runs, len(steps), "PCRLB"))
    return (rows, est, bound, flags) if with_divergence else (rows, est, bound)


def settings_rows(scenarios) -> list[dict]:
    """Every scenario's named settings, one row each."""
    return [{"scenario": sc.key, "document": sc.document, "setting": st.name, "value": st.value, "source": st.source}
            for sc in scenarios for st in sc.settings]
