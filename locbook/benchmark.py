"""The cross-document benchmark: every static method on every document's static scenario and on the measured data,
every tracker on every tracking scenario, each beside its bound.

Scenarios and methods are declared in registries (:data:`STATIC_SCENARIOS`, :data:`TRACKING_SCENARIOS`,
:data:`STATIC_METHODS`, :data:`TRACKERS`): adding an entry adds a column or a row of the table and the heat map.
No source printed these numbers; nothing here is scored against a printed value.

One protocol for every cell (each choice a named setting, reported with the cell):

- Synthetic scenarios take each document's geometry and channel (the values its own experiment uses, or our
  stated default where it prints none, cited per setting) with i.i.d. log-normal shadowing, the model both
  bounds assume. The estimators know the true channel, so a cell measures the method and the geometry, not a
  calibration. All methods of a scenario see the same draws (common random numbers).
- A measured scenario is built from any data set (:func:`measured_static_scenario`, :func:`measured_tracking_scenario`;
  the notebook's ``data`` parameter lists them): the channel fitted on its calibration recordings
  (:mod:`locbook.scenarios.measured`), scored on its other recordings; its bound uses only the anchors heard at
  each epoch.
- Static bound: the CRLB ``sqrt(tr J^-1)`` at each true position; the cell's ratio is the RMSE over all fixes
  divided by the RMS of the bound over the positions. Methods that know the room (box-LS, grid ML, grid MMSE,
  k-NN) use information the CRLB does not have and may fall below it.
- Tracking bound: the posterior CRLB (Tichavsky recursion, :func:`locbook.bounds.pcrlb.posterior_crlb`) of the
  constant-velocity model the Kalman trackers use (white-acceleration intensity ``q``), with the prior ``N(x_0, P_0)``
  every tracker starts from, evaluated along the true path (Dogan's truth-conditioned bound). The paths are the
  documents' deterministic ones, not draws of that model, so the bound is the reference of the filters' own model
  and a ratio below 1 is possible.
- Every tracker starts from the same prior: the true initial state plus a draw of ``N(0, P_0)`` per run (the Kalman
  filters' mean; the particles drawn around it; the grid's belief the same Gaussian).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .bounds.crlb import rss_position_information
from .bounds.pcrlb import posterior_crlb, position_bound_m, rss_state_information
from .data.measured import regular_epochs
from .geometry import box_outline, grid_in_outline, outline_box
from .metrics import accuracy_metrics, position_error_m, rmse_standard_error_m
from .montecarlo import seed_from_values
from .models.channel import PathLossModel
from .models.motion import constant_velocity
from .static.calibration import fix_error_covariance
from .static.fingerprint import knn_position, model_fingerprints
from .static.localization import (grid_ml_position, lateration_box_ls, lateration_ls, lateration_wls,
                                   rss_ml_position)
from .models.rss import RssModel
from .tracking.bayes import grid_bayes_filter
from .tracking.particle import particle_filter
from .tracking.kalman import extended_kalman_filter
from .tracking.streams import LinearMeasurement, RssMeasurement
from .tracking.unscented import unscented_kalman_filter
from .scenarios import dogan, george, gudipati, measured, ozkaya, palvai
from .tracking.divergence import DivergenceFlags

__all__ = ["ProtocolChoice", "StaticScenario", "TrackingScenario", "STATIC_SCENARIOS", "TRACKING_SCENARIOS",
           "measured_static_scenario", "measured_tracking_scenario",
           "STATIC_METHODS", "TRACKERS", "NOT_APPLICABLE", "TrackerSettings", "static_scenario", "tracking_scenario",
           "static_fixes", "static_bound_m", "run_trackers", "tracking_bound_m", "initial_states", "score",
           "scenario_rng", "static_cells", "tracking_cells", "settings_rows"]


@dataclass(frozen=True)
class ProtocolChoice:
    """One named choice of a scenario or a method: its value and where it comes from."""

    name: str
    value: str
    source: str


@dataclass(frozen=True)
class _AnchorReadings:
    """What the static and tracking scenarios share: their name, document and title, the anchors, channel and floor,
    the anchor distances of plan positions and channel draws at them, whether the readings are measured, and the
    floor's bounding box (the scenario adds ``tag_height_m`` and ``measured_rss_dbm``)."""

    key: str
    document: str
    title: str
    anchors_m: np.ndarray
    channel: PathLossModel
    outline_m: np.ndarray

    @property
    def measured(self) -> bool:
        return self.measured_rss_dbm is not None

    @property
    def box_m(self):
        return outline_box(self.outline_m)

    def distances_m(self, points_m) -> np.ndarray:
        """Anchor distances ``(..., m)`` (3-D when the anchors carry heights: the tag at ``tag_height_m``)."""
        p = np.asarray(points_m, float)
        if self.tag_height_m is not None:
            p = np.concatenate([p, np.full(p.shape[:-1] + (1,), self.tag_height_m)], axis=-1)
        return np.linalg.norm(p[..., None, :] - self.anchors_m, axis=-1)

    def _sample_rss_dbm(self, points_m, n_runs: int, rng: np.random.Generator) -> np.ndarray:
        """``n_runs`` independent channel draws at ``points_m``: ``(n_runs, ..., m)``."""
        d = self.distances_m(points_m)
        return self.channel.sample_rss_dbm(np.broadcast_to(d, (n_runs,) + d.shape), rng)


@dataclass(frozen=True)
class StaticScenario(_AnchorReadings):
    """A static localization problem: anchors ``(m, 2)`` (or ``(m, 3)`` with ``tag_height_m``), the channel (the
    truth and what the estimators know), the floor (``outline_m``; the region of box-LS is its bounding box),
    evaluation positions ``points_m (P, 2)``, the pitch of the grid methods' grid; for measured data the readings
    ``measured_rss_dbm (P, m)`` (NaN = not heard) and the k-NN radio map ``(cells, fingerprints)``."""

    points_m: np.ndarray
    grid_spacing_m: float
    settings: tuple[ProtocolChoice, ...]
    tag_height_m: float | None = None
    measured_rss_dbm: np.ndarray | None = None
    radio_map: tuple | None = field(default=None, repr=False)

    def grid_m(self, spacing_m: float | None = None) -> np.ndarray:
        return grid_in_outline(self.outline_m, self.grid_spacing_m if spacing_m is None else spacing_m)

    def rss_dbm(self, n_runs: int, rng: np.random.Generator) -> np.ndarray:
        """Readings ``(R, P, m)``: the measured ones (``R = 1``), or ``n_runs`` draws of the channel."""
        if self.measured:
            return self.measured_rss_dbm[None]
        return self._sample_rss_dbm(self.points_m, n_runs, rng)


@dataclass(frozen=True)
class TrackingScenario(_AnchorReadings):
    """A tracking problem on a fixed clock ``dt_s``: true plan positions ``truth_m (T, 2)`` at every tick (NaN where
    the truth is unknown), the ticks that are scored (``scored (T,)``), the anchors and channel, the floor, and for
    measured data the readings ``measured_rss_dbm (T, m)`` on the clock (a tick without readings is all NaN)."""

    truth_m: np.ndarray
    dt_s: float
    spread_m: float
    grid_spacing_m: float
    settings: tuple[ProtocolChoice, ...]
    tag_height_m: float | None = None
    measured_rss_dbm: np.ndarray | None = None
    scored: np.ndarray | None = None
    fix_cov_m2: np.ndarray | None = None

    @property
    def scored_steps(self) -> np.ndarray:
        return np.arange(len(self.truth_m)) if self.scored is None else np.flatnonzero(self.scored)

    def initial_state(self) -> np.ndarray:
        """True ``[x, y, vx, vy]`` at the first tick (velocity from the first scored displacement)."""
        steps = self.scored_steps
        a, b = steps[0], steps[1]
        return np.r_[self.truth_m[a], (self.truth_m[b] - self.truth_m[a]) / ((b - a) * self.dt_s)]

    def rss_dbm(self, n_runs: int, rng: np.random.Generator) -> np.ndarray:
        """Readings ``(R, T, m)``: the measured ones repeated ``n_runs`` times, or ``n_runs`` draws of the channel."""
        if self.measured:
            return np.broadcast_to(self.measured_rss_dbm, (n_runs,) + self.measured_rss_dbm.shape)
        return self._sample_rss_dbm(self.truth_m, n_runs, rng)


def _fmt(values) -> str:
    a = np.atleast_1d(np.asarray(values, float))
    return f"{a[0]:g}" if a.size == 1 or np.all(a == a[0]) else "[" + ", ".join(f"{v:g}" for v in a) + "]"


def _channel_settings(model: PathLossModel, source: str) -> tuple[ProtocolChoice, ...]:
    return (ProtocolChoice("P0 (dBm at 1 m)", _fmt(model.ref_power_dbm), source),
            ProtocolChoice("path-loss exponent", _fmt(model.path_loss_exp), source),
            ProtocolChoice("shadowing sigma (dB)", _fmt(model.sigma_db), source))


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
         *_channel_settings(model, src),
         ProtocolChoice("positions", "the 25 marked points on the centre line, y 0.3-7.5 m", "not printed; our default"),
         ProtocolChoice("grid pitch", "0.05 m", "benchmark: fine against the corridor's 2.1 m width")))


def _ozkaya_static() -> StaticScenario:
    model = PathLossModel(ozkaya.ALPHA_DBM, ozkaya.PATH_LOSS_EXP, ozkaya.SIGMA_DB)
    return StaticScenario(
        "ozkaya2011-room", "ozkaya2011", "5 x 8 m room, 3 corner readers", ozkaya.readers_for("corners3"), model,
        box_outline((0, 0), ozkaya.ROOM_M), ozkaya.cell_centres(ozkaya.ROOM_M, *ozkaya.CELL_PATTERNS[28]), 0.1,
        (ProtocolChoice("readers", "3 corners (layout corners3)", "Sec. 7.2.1 (which three: not printed)"),
         *_channel_settings(model, "Table 6.1, Reader 2 (the simulation channel, Sec. 7.2.1)"),
         ProtocolChoice("positions", "the 28 cell centres (x 1-4 m, y 1-7 m)", "Fig. 7.2"),
         ProtocolChoice("grid pitch", "0.1 m", "benchmark")))


def _dogan_static() -> StaticScenario:
    model = PathLossModel(dogan.REF_POWER_DBM, dogan.PATH_LOSS_EXP, dogan.SIGMA_RSS_DB)
    walk = dogan.walk_trajectory()
    return StaticScenario(
        "dogan2015-room", "dogan2015", "7.6 x 9.2 m room, 4 corner anchors", dogan.ANCHORS_M, model,
        box_outline((0, 0), dogan.ROOM_M), walk.position_m[walk.rss_steps], 0.1,
        (ProtocolChoice("anchors", "4 corners", "Sec. 5.4"), *_channel_settings(model, "Table 3.6"),
         ProtocolChoice("positions", f"the walk's {len(walk.rss_steps)} RSS epochs (0.3 m/s polyline, 2 Hz)",
                 "path not printed (our default); where the thesis's MLE is computed"),
         ProtocolChoice("grid pitch", "0.1 m", "benchmark")))


#: Gudipati's readings: shadowing 3 dB plus 1 dB per-packet noise (our defaults), as one i.i.d. term of the same variance
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
         *_channel_settings(model, "Table 5.2 (S, C per anchor); sigma: 3 dB shadowing and 1 dB per packet "
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
         *_channel_settings(model, "Secs. 2.6, 4.4 (sigma_1, eta); K = -20 dBm at 1 m (not printed; ours)"),
         ProtocolChoice("positions", "the emitter at the area's centre (25, 25)", "not printed (ours)"),
         ProtocolChoice("plane", "2-D (the thesis's equations are 3-D)", "ours (Sec. 5.4 reads its clouds in 2-D)"),
         ProtocolChoice("grid pitch", "0.25 m", "benchmark: 40,000 cells over the area")))


def _measured_parts(data, fit: str = "closed_form"):
    ds = measured.load(data)
    return ds, measured.channel(measured.calibrate(ds, fit=fit))


def _measured_settings(ds, model: PathLossModel, fit: str) -> tuple[ProtocolChoice, ...]:
    heights = ds.anchors_m[:, 2]
    return (ProtocolChoice("data", f"{ds.title}; {ds.license}", f"{ds.root.name}/dataset.toml"),
            ProtocolChoice("anchors", f"{len(heights)}, at {heights.min():g}-{heights.max():g} m height; tag at "
                                      f"{ds.tag_height_m:g} m (3-D distances)", "the data set's manifest"),
            ProtocolChoice("channel", f"per-anchor {fit} fit on the calibration recordings "
                                      f"({', '.join(ds.recordings_with('calibration'))}; never a scored one)",
                           "measured-calibration"),
            *_channel_settings(model, "the fit (sigma = residual spread per anchor)"))


def measured_static_scenario(data, fit: str = "closed_form") -> StaticScenario | None:
    """The static scenario of a data set (a :class:`~locbook.data.dataset.Dataset`, a shipped name or a folder):
    every epoch with a true position of its scored recordings (:func:`locbook.scenarios.measured.scored_recordings`)
    is a test point with its measured readings; k-NN's radio map is the calibration epochs. None when no recording
    has a true position per epoch (nothing to score)."""
    ds, model = _measured_parts(data, fit)
    names = measured.scored_recordings(ds)
    if not names:
        return None
    tests = [measured.TestEpochs.of(ds, n) for n in names]
    truth = np.concatenate([t.truth_m for t in tests])
    rss = np.concatenate([t.rss_dbm for t in tests])
    cells, fingerprints, filled = measured.radio_map(ds, model)
    return StaticScenario(
        f"data-{ds.name}", ds.name, f"measured: {ds.name}, {len(ds.anchor_ids)} anchors", ds.anchors_m, model,
        np.asarray(ds.outline_m, float), truth, 0.1,
        (*_measured_settings(ds, model, fit),
         ProtocolChoice("positions", f"the {len(truth)} epochs with a true position of {', '.join(names)}",
                        "the data set"),
         ProtocolChoice("k-NN map", f"the calibration epochs; {100 * filled:.1f} % of readings not heard, filled with "
                                    "the fitted mean", "measured-localization"),
         ProtocolChoice("grid pitch", "0.1 m inside the floor outline", "measured-localization")),
        tag_height_m=ds.tag_height_m, measured_rss_dbm=rss, radio_map=(cells, fingerprints))


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
        (*st.settings[:4], ProtocolChoice("path", "the U-path (2 m from the walls) at 0.5 m/s with 0.25 m/s^2 ramps and 1 m "
                                           "turn radius; a step every 0.5 s (the thesis: 0.1 s); RSS only",
                                   "path and timing not printed (ours); GUDIPATI_TRACKING_DT_S")))


def measured_tracking_scenario(data, fit: str = "closed_form") -> TrackingScenario | None:
    """The tracking scenario of a data set: its first track with a true position per epoch, on its epoch clock
    (a tick without readings is all NaN and unscored); None when no track has per-epoch truth."""
    ds, model = _measured_parts(data, fit)
    names = [n for n in ds.recordings_with("track") if ds.recording(n).has_truth]
    if not names:
        return None
    name = names[0]
    dt = measured.epoch_s(ds, name)
    ep = ds.epochs(name)
    reg, ticks = regular_epochs(ep, dt, tolerance_s=0.1 * dt)
    truth = np.full((reg.rss_dbm.shape[0], 2), np.nan)
    truth[ticks] = ep.position_m[:, :2]
    scored = np.isfinite(truth).all(axis=1)
    return TrackingScenario(
        f"data-{ds.name}", ds.name, f"measured: {ds.name}, track {name}, {dt:g} s epochs", ds.anchors_m, model,
        np.asarray(ds.outline_m, float), truth, dt, 0.3, 0.1,
        (*_measured_settings(ds, model, fit),
         ProtocolChoice("path", f"the track {name!r} on a {dt:g} s clock ({int(scored.sum())} epochs scored against "
                                "its truth)", "the data set; measured-tracking"),
         ProtocolChoice("KF-on-ML R", "covariance of RSS-ML fix errors on the calibration epochs",
                        "measured.fix_covariance_from_calibration")),
        tag_height_m=ds.tag_height_m, measured_rss_dbm=reg.rss_dbm, scored=scored,
        fix_cov_m2=measured.fix_covariance_from_calibration(ds, model))


TRACKING_SCENARIOS = {"george-walk": _george_tracking, "ozkaya2011-constant-velocity": _ozkaya_tracking,
                      "dogan2015-walk": _dogan_tracking, "gudipati2017-u-path": _gudipati_tracking}

#: documents with no scenario of a kind, and why (shown as a blank column with the reason)
NOT_APPLICABLE = {("tracking", "palvai2008"): "a static emitter seen from a moving receiver: there is no moving tag "
                                              "for the trackers (its EKF and particle filter are in palvai2008-*)"}


def tracking_scenario(key: str, **kwargs) -> TrackingScenario:
    if key not in TRACKING_SCENARIOS:
        raise ValueError(f"unknown tracking scenario {key!r}; declared: {sorted(TRACKING_SCENARIOS)}")
    return TRACKING_SCENARIOS[key](**kwargs)


# ------------------------------------------------------------------------------------------------ static methods

def _flat(rss):
    return rss.reshape(-1, rss.shape[-1])


def _lls(sc, rss, opts):
    return lateration_ls(sc.anchors_m, sc.channel.range_m(_flat(rss)), tag_height_m=sc.tag_height_m).position_m


def _wls(sc, rss, opts):
    ranges = sc.channel.range_m(_flat(rss))
    w = 1.0 / np.where(np.isnan(ranges[:, 1:]), 1.0, ranges[:, 1:]) ** 4
    return lateration_wls(sc.anchors_m, ranges, w / np.max(w, axis=-1, keepdims=True),
                          tag_height_m=sc.tag_height_m).position_m


def _box_ls(sc, rss, opts):
    lower, upper = sc.box_m
    return lateration_box_ls(sc.anchors_m, sc.channel.range_m(_flat(rss)), lower, upper,
                             tag_height_m=sc.tag_height_m).position_m


def _grid_ml(sc, rss, opts):
    return grid_ml_position(sc.anchors_m, _flat(rss), sc.channel, sc.grid_m(), tag_height_m=sc.tag_height_m).position_m


def _rss_ml(sc, rss, opts):
    start = opts.get("grid_ml")
    if start is None:
        start = _grid_ml(sc, rss, opts)
    return rss_ml_position(sc.anchors_m, _flat(rss), sc.channel, start, tag_height_m=sc.tag_height_m).position_m


def _bayes_model(sc) -> RssModel:
    m = sc.channel
    return RssModel(sc.anchors_m, PathLossModel(np.asarray(m.ref_power_dbm, float), np.asarray(m.path_loss_exp, float),
                                                np.asarray(m.sigma_db, float), m.ref_distance_m, m.wall_attenuation_db,
                                                float(m.min_distance_m) if m.min_distance_m > 0 else 0.1),
                    tag_height_m=sc.tag_height_m)


#: problems per block of the grid posterior: beliefs of about 32 MiB at a time
GRID_BLOCK_VALUES = 1 << 22


def _grid_mmse(sc, rss, opts):
    # one step of the grid Bayes filter from a uniform belief (no transition at the first step): the posterior mean
    flat = _flat(rss)
    cells, model = sc.grid_m(), _bayes_model(sc)
    block = max(1, GRID_BLOCK_VALUES // cells.shape[0])
    return np.concatenate([grid_bayes_filter(flat[i:i + block, None, :], cells, model, 1.0).mean_m[:, 0]
                           for i in range(0, flat.shape[0], block)])


def _knn(sc, rss, opts):
    if sc.radio_map is not None:
        cells, fingerprints = sc.radio_map
    else:
        cells = sc.grid_m(opts["knn_map_spacing_m"])
        fingerprints = model_fingerprints(cells, sc.anchors_m, PathLossModel(sc.channel.ref_power_dbm,
                                                                             sc.channel.path_loss_exp))
    return knn_position(_flat(rss), fingerprints, cells, opts["knn_k"], chunk=4096)


#: name -> (function, what it is, its settings)
STATIC_METHODS = {
    "lls": (_lls, "linearized LS on the inverted ranges (reference anchor 0)", "no region"),
    "wls": (_wls, "weighted linearized LS, weights 1/d^4 of the inverted ranges", "no region"),
    "box_ls": (_box_ls, "box-constrained LS (exact active set)", "box = the floor's bounding box"),
    "rss_ml": (_rss_ml, "RSS maximum likelihood (Gauss-Newton) from the grid-ML fix", "unconstrained after the start"),
    "grid_ml": (_grid_ml, "grid maximum likelihood", "grid inside the floor at the scenario's pitch"),
    "grid_mmse": (_grid_mmse, "grid posterior mean, uniform prior over the floor", "grid inside the floor"),
    "knn": (_knn, "weighted k-NN fingerprinting (inverse-square weights)",
            "map: the channel's mean on a lattice (synthetic), the calibration set (measured)"),
}


def static_fixes(sc: StaticScenario, rss_dbm, *, knn_k: int = 4, knn_map_spacing_m: float = 0.5,
                 methods=None) -> dict[str, np.ndarray]:
    """Every declared static method on readings ``(R, P, m)`` -> fixes ``(R, P, 2)`` (NaN where it has none)."""
    rss = np.asarray(rss_dbm, float)
    opts = {"knn_k": knn_k, "knn_map_spacing_m": knn_map_spacing_m}
    out = {}
    for name in (STATIC_METHODS if methods is None else methods):
        fn = STATIC_METHODS[name][0]
        out[name] = np.asarray(fn(sc, rss, opts), float).reshape(rss.shape[:-1] + (2,))
        if name == "grid_ml":
            opts["grid_ml"] = out[name].reshape(-1, 2)
    return out


def _information(sc, positions_m, heard=None):
    anchors = sc.anchors_m
    height = 0.0 if sc.tag_height_m is None else anchors[:, 2] - sc.tag_height_m
    return rss_position_information(positions_m, anchors[:, :2], sc.channel.path_loss_exp, sc.channel.sigma_db,
                                    min_distance_m=float(sc.channel.min_distance_m), height_offset_m=height,
                                    heard=heard)


def _trace_inverse_2d(info):
    det = info[..., 0, 0] * info[..., 1, 1] - info[..., 0, 1] ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(det > 0, (info[..., 0, 0] + info[..., 1, 1]) / np.where(det > 0, det, 1.0), np.inf)


def static_bound_m(sc: StaticScenario) -> np.ndarray:
    """CRLB ``sqrt(tr J^-1)`` at each evaluation position ``(P,)``; for measured data from the anchors heard at that
    epoch (inf where fewer than two are heard: the position is not identifiable from that epoch)."""
    heard = None if not sc.measured else ~np.isnan(sc.measured_rss_dbm)
    return np.sqrt(_trace_inverse_2d(_information(sc, sc.points_m, heard)))


# ------------------------------------------------------------------------------------------------------ trackers

@dataclass(frozen=True)
class TrackerSettings:
    """The trackers' shared settings: ``q`` the constant-velocity model's white-acceleration intensity (m^2/s^3),
    the prior ``P_0 = diag(sd_p^2, sd_p^2, sd_v^2, sd_v^2)``, particles, the UKF's alpha, the ML fixes' start grid."""

    q: float = 0.05
    initial_position_sd_m: float = 1.0
    initial_velocity_sd_m_s: float = 0.5
    n_particles: int = 1000
    ukf_alpha: float = 0.5
    ml_start_spacing_m: float = 0.5

    @property
    def P0(self) -> np.ndarray:
        return np.diag([self.initial_position_sd_m**2] * 2 + [self.initial_velocity_sd_m_s**2] * 2)


def initial_states(sc: TrackingScenario, ts: TrackerSettings, n_runs: int, rng: np.random.Generator) -> np.ndarray:
    """``x_0`` per run ``(R, 4)``: the true initial state plus a draw of ``N(0, P_0)`` (the prior of the bound)."""
    return sc.initial_state() + rng.standard_normal((n_runs, 4)) @ np.linalg.cholesky(ts.P0).T


def _ml_fixes(sc, rss, ts):
    flat = _flat(rss)
    heard = (~np.isnan(flat)).sum(axis=-1) >= 3
    out = np.full((flat.shape[0], 2), np.nan)
    start = grid_ml_position(sc.anchors_m, flat[heard], sc.channel, grid_in_outline(sc.outline_m, ts.ml_start_spacing_m),
                             tag_height_m=sc.tag_height_m).position_m
    out[heard] = rss_ml_position(sc.anchors_m, flat[heard], sc.channel, start, tag_height_m=sc.tag_height_m).position_m
    return out.reshape(rss.shape[:-1] + (2,))


def _fix_cov(sc, ts, rng):
    """``R`` of the KF on ML fixes: given (measured data: from the calibration set), else the covariance of RSS-ML fix
    errors along the path over 200 independent draws (a calibration stream, never the scored runs)."""
    if sc.fix_cov_m2 is not None:
        return np.asarray(sc.fix_cov_m2, float)
    rss = sc.rss_dbm(200, rng)
    fixes = _ml_fixes(sc, rss, ts)
    ok = np.isfinite(fixes).all(axis=-1)
    return fix_error_covariance(fixes[ok], np.broadcast_to(sc.truth_m, fixes.shape)[ok])


def _gaussian_belief(cells, x0, P0_pos):
    inv = np.linalg.inv(P0_pos)
    d = cells[None] - x0[:, None, :2]
    logp = -0.5 * np.einsum("rci,ij,rcj->rc", d, inv, d)
    p = np.exp(logp - logp.max(axis=-1, keepdims=True))
    return p / p.sum(axis=-1, keepdims=True)


TRACKERS = {
    "kf_on_ml": "constant-velocity KF on RSS-ML fixes (R: fix-error covariance from a calibration stream)",
    "ekf": "constant-velocity EKF on the raw RSS, parallel (stacked) update",
    "ekf_serial": "constant-velocity EKF on the raw RSS, serial scalar updates (descending RSS)",
    "ukf": "constant-velocity UKF on the raw RSS",
    "particle": "SIR particle filter, random walk (spread per step) reflected into the floor's box, resampled at "
                "N_eff < N/2",
    "grid_bayes": "grid Bayes filter, the same random walk on a grid inside the floor (separable transition)",
}


def run_trackers(sc: TrackingScenario, rss_dbm, x0, ts: TrackerSettings, rng: np.random.Generator, *,
                 trackers=None, with_divergence: bool = False):
    """Every declared tracker on readings ``(R, T, m)`` from initial states ``(R, 4)`` -> positions ``(R, T, 2)``.
    ``with_divergence=True`` returns ``(positions, {tracker: flags})``, the NIS guard per run of each Kalman-family
    tracker (:class:`locbook.tracking.divergence.DivergenceFlags`, steps of the scenario's clock)."""
    rss = np.asarray(rss_dbm, float)
    rng_cov, rng_pf = rng.spawn(2)
    chosen = tuple(TRACKERS if trackers is None else trackers)
    motion = constant_velocity(sc.dt_s, ts.q, dim=2)
    P0 = np.broadcast_to(ts.P0, (len(x0), 4, 4))
    idx = np.array([0, 1])
    out, flags = {}, {}
    if "kf_on_ml" in chosen:
        H = np.hstack([np.eye(2), np.zeros((2, 2))])
        fixes = _ml_fixes(sc, rss, ts)
        res = extended_kalman_filter(motion.F, motion.Q, x0, P0, [LinearMeasurement(fixes, H, _fix_cov(sc, ts, rng_cov))])
        out["kf_on_ml"], flags["kf_on_ml"] = res.x[..., :2], DivergenceFlags.of(res)
    for name, mode in (("ekf", "parallel"), ("ekf_serial", "serial")):
        if name in chosen:
            stream = RssMeasurement(rss, sc.anchors_m, sc.channel, idx, mode=mode, tag_height_m=sc.tag_height_m)
            res = extended_kalman_filter(motion.F, motion.Q, x0, P0, [stream])
            out[name], flags[name] = res.x[..., :2], DivergenceFlags.of(res)
    if "ukf" in chosen:
        stream = RssMeasurement(rss, sc.anchors_m, sc.channel, idx, tag_height_m=sc.tag_height_m)
        res = unscented_kalman_filter(motion.F, motion.Q, x0, P0, [stream], alpha=ts.ukf_alpha)
        out["ukf"], flags["ukf"] = res.x[..., :2], DivergenceFlags.of(res)
    model = _bayes_model(sc)
    if "particle" in chosen:
        out["particle"] = particle_filter(rss, model, rng_pf, n_particles=ts.n_particles, region_m=sc.box_m,
                                          spread_m=sc.spread_m, initial_position_m=x0[:, :2],
                                          initial_sd_m=ts.initial_position_sd_m, resample_threshold=0.5).mean_m
    if "grid_bayes" in chosen:
        cells = grid_in_outline(sc.outline_m, sc.grid_spacing_m)
        out["grid_bayes"] = grid_bayes_filter(rss, cells, model, sc.spread_m,
                                              initial_belief=_gaussian_belief(cells, x0, ts.P0[:2, :2])).mean_m
    out = {k: out[k] for k in chosen}
    return (out, flags) if with_divergence else out


def tracking_bound_m(sc: TrackingScenario, ts: TrackerSettings) -> np.ndarray:
    """Position PCRLB ``(T,)`` at every tick: the Tichavsky recursion of the constant-velocity model (``ts.q``) from
    ``J_0 = P_0^-1``, with the RSS information at the true positions (only the anchors heard, for measured data; a
    tick with no truth or no reading adds none). Tick ``k`` is ``J_{k+1}`` (the filters predict before each step)."""
    motion = constant_velocity(sc.dt_s, ts.q, dim=2)
    truth = np.where(np.isfinite(sc.truth_m), sc.truth_m, 0.0)
    states = np.concatenate([truth, np.zeros_like(truth)], axis=-1)
    heard = np.isfinite(sc.truth_m).all(axis=-1)[:, None]
    if sc.measured:
        heard = heard & ~np.isnan(sc.measured_rss_dbm)
    anchors = sc.anchors_m
    height = 0.0 if sc.tag_height_m is None else anchors[:, 2] - sc.tag_height_m
    jz = rss_state_information(states, anchors[:, :2], sc.channel.path_loss_exp, sc.channel.sigma_db, [0, 1],
                               min_distance_m=float(sc.channel.min_distance_m), height_offset_m=height, heard=heard)
    info = posterior_crlb(np.linalg.inv(ts.P0), motion.F, motion.Q, jz, form="riccati")
    return position_bound_m(info[1:], [0, 1])


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
        m = accuracy_metrics(per_epoch[np.isfinite(per_epoch)], rng, n_bootstrap=n_bootstrap, block_length=block_length)
        low, high = m["rmse_m_low"], m["rmse_m_high"]
        how = f"bootstrap over epochs (blocks of {block_length})"
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


def _row(kind, sc, method, cell, settings, runs, points, bound_name):
    return {"kind": kind, "scenario": sc.key, "document": sc.document, "data": "measured" if sc.measured else "synthetic",
            "method": method, "runs": runs, "points": points, **cell, "bound": bound_name, "settings": settings}


def static_cells(sc: StaticScenario, n_runs: int, rng: np.random.Generator, *, knn_k: int, knn_map_spacing_m: float,
                 n_bootstrap: int) -> list[dict]:
    """Every static method on one scenario: ``n_runs`` draws (one for measured data), scored beside the CRLB."""
    rng_rss, rng_boot = rng.spawn(2)
    rss = sc.rss_dbm(n_runs, rng_rss)
    fixes = static_fixes(sc, rss, knn_k=knn_k, knn_map_spacing_m=knn_map_spacing_m)
    bound = static_bound_m(sc)
    knobs = {"knn": f"k = {knn_k}" + ("" if sc.radio_map is not None else f", map pitch {knn_map_spacing_m:g} m"),
             "grid_ml": f"pitch {sc.grid_spacing_m:g} m", "grid_mmse": f"pitch {sc.grid_spacing_m:g} m",
             "rss_ml": f"start: grid ML at {sc.grid_spacing_m:g} m"}
    rows = []
    for name, f in fixes.items():
        cell = score(position_error_m(f, sc.points_m), bound, measured=sc.measured, rng=rng_boot,
                     n_bootstrap=n_bootstrap)
        settings = "; ".join(x for x in (STATIC_METHODS[name][2], knobs.get(name, "")) if x)
        rows.append(_row("static", sc, name, cell, settings, rss.shape[0], len(sc.points_m), "CRLB"))
    return rows


def tracking_cells(sc: TrackingScenario, ts: TrackerSettings, n_runs: int, rng: np.random.Generator, *,
                   n_bootstrap: int, block_length: int = 30, with_divergence: bool = False):
    """Every tracker on one scenario: ``n_runs`` runs (fresh readings for synthetic data; for measured data the one
    recording, the runs differing in the prior draw and the particles), scored at the scored ticks beside the
    PCRLB. Returns the rows, the estimates ``{tracker: (R, T, 2)}`` and the bound ``(T,)``; with
    ``with_divergence`` also ``{tracker: flags}`` of the Kalman-family trackers (:func:`run_trackers`). Every cell
    keeps every run."""
    rng_rss, rng_x0, rng_filters, rng_boot = rng.spawn(4)
    rss = sc.rss_dbm(n_runs, rng_rss)
    x0 = initial_states(sc, ts, n_runs, rng_x0)
    est, flags = run_trackers(sc, rss, x0, ts, rng_filters, with_divergence=True)
    bound = tracking_bound_m(sc, ts)
    steps = sc.scored_steps
    common = f"q = {ts.q:g} m^2/s^3, dt = {sc.dt_s:g} s, P0 sd {ts.initial_position_sd_m:g} m / {ts.initial_velocity_sd_m_s:g} m/s"
    knobs = {"kf_on_ml": common + f"; ML start grid {ts.ml_start_spacing_m:g} m",
             "ekf": common, "ekf_serial": common, "ukf": common + f"; alpha = {ts.ukf_alpha:g}, beta = 2, kappa = 0",
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
