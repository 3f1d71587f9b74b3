"""Any measured data set (:mod:`locbook.data.dataset`) run through locbook's battery (:mod:`locbook.battery`): the one
protocol of the ``measured-*`` experiments and of a data set's columns in the cross-document benchmark. Every page
calls the functions below, so one method name gives the same numbers on every page of one run.

Protocol (every choice a named constant or argument, with its reason; nothing here depends on which data set):

- the channel is fitted on the data set's calibration recordings only, and every method is scored on its static and
  track recordings, which the fit never sees; distances are 3-D with the tag at the data set's known height
  (``tag_height_m``), or in the plane for a 2-D data set (anchors without ``z``);
- missing readings (not heard) follow the library's one rule (NaN), in the fit, the estimators and the filters; the
  radio map of k-NN needs a value for each (point, anchor): a reading an anchor did not hear at a calibration epoch is
  filled with the fitted channel's mean there (:func:`radio_map`), stated;
- settings come from the data by stated rules, the same for every method, and the reports name each and how it was
  obtained (:class:`Protocol`): the grid pitch (:func:`grid_pitch_m`), k-NN's k by leave-one-point-out
  cross-validation on the calibration map (:func:`choose_knn_k`), every tracker's motion from the track's own
  readings (:func:`fit_motion`: the white-acceleration variance ``q`` (m^2/s^4) by maximum likelihood of the EKF's
  innovations, the random walk of the particle and grid filters by maximum likelihood of its innovations on the
  fixes ``kf_on_ml`` filters); a value
  given by the user (``-p``) replaces the rule and is named as given;
- every tracker starts from the same state: the first ``rss_ml`` fix of the track, at rest, with
  the calibrated covariance of such fixes as the position block of P_0 and :data:`START_VELOCITY_SD_M_S`;
- bounds are per epoch: the CRLB of the fitted channel at the truth from the anchors each epoch heard (static), the
  posterior CRLB of the trackers' constant-velocity model at the fitted ``q`` from that start (tracking); an epoch
  whose bound is undefined or near-singular is left out of the bound's summary and counted
  (:mod:`locbook.bounds.summary`), and no ratio is drawn from a degenerate bound;
- intervals: the circular block bootstrap over each recording's epochs in time order, blocks of ``block_s``
  seconds (neighbouring epochs share their shadowing); too few blocks and the interval is reported as not
  estimable (:func:`locbook.accuracy_metrics`).

The problems (calibration, radio map, settings rules, motion fits, scenarios) are
:mod:`locbook.scenarios.measured_setup`'s; this module holds the protocol that gathers them (:func:`protocol`), the
results rows and the user methods' runs, and re-exports the setup's public names.
"""
from __future__ import annotations

from copy import deepcopy
from dataclasses import dataclass, field

import numpy as np

from ..battery import STATIC_METHODS as BATTERY_STATIC
from ..battery import (
    TRACKER_PRIORS,
    StaticScenario,
    TrackerSettings,
    TrackingScenario,
    initial_states,
    run_trackers,
    static_bound_checked,
    tracking_bound_m,
)
from ..battery import static_fixes as battery_static_fixes
from ..bounds.summary import error_bound_ratio, summarize_bound
from ..data.dataset import Dataset
from ..inertial_trackers import FUSION_PRIORS, FUSION_TRACKERS, run_fusion
from ..metrics import accuracy_metrics
from ..models.channel import PathLossModel
from ..models.rss import RssModel
from ..user_methods import MethodFailure, MethodInput, UserMethod, frozen, registered_methods, run_method
from . import measured_ranges as ranging
from .measured_inertial import fusion_choices, fusion_inputs, fusion_knobs, inertial_tracks
from .measured_setup import (
    GRID_SPACING_M,
    HUBER_DELTA_DB,
    KNN_CANDIDATES,
    KNN_CV_CELL_M,
    MAX_GRID_CELLS,
    NEAR_FIELD_M,
    PATH_LOSS_EXP_BOUNDS,
    Q_START,
    REF_POWER_BOUNDS_DBM,
    SPREAD_START_M,
    START_VELOCITY_SD_M_S,
    STATIC_METHODS,
    TRACKERS,
    TestEpochs,
    bayes_measurement_model,
    calibrate,
    calibration_block_bootstrap,
    calibration_set,
    channel,
    choose_knn_k,
    crlb_m,
    device_corrected,
    device_offsets_db,
    epoch_s,
    fit_motion,
    fix_covariance_from_calibration,
    geometry_text,
    grid_pitch_m,
    keyed_stream,
    load,
    outside_fraction,
    radio_map,
    ranging_errors,
    record_dataset,
    scored_recordings,
    static_scenario,
    track_epochs,
    tracker_settings,
    tracking_scenario,
)

__all__ = ["PATH_LOSS_EXP_BOUNDS", "REF_POWER_BOUNDS_DBM", "HUBER_DELTA_DB", "NEAR_FIELD_M", "STATIC_METHODS",
           "TRACKERS", "GRID_SPACING_M", "MAX_GRID_CELLS", "KNN_CANDIDATES", "KNN_CV_CELL_M", "Q_START",
           "START_VELOCITY_SD_M_S", "SPREAD_START_M", "load", "calibration_set", "calibrate", "channel",
           "ranging_errors", "radio_map", "scored_recordings", "TestEpochs", "crlb_m", "epoch_s", "grid_pitch_m",
           "choose_knn_k", "fit_motion", "Protocol", "protocol", "static_scenario", "tracking_scenario",
           "static_results", "tracking_results", "RESULT_COLUMNS", "result_row", "bayes_measurement_model",
           "fix_covariance_from_calibration", "outside_fraction", "calibration_block_bootstrap", "record_dataset",
           "geometry_text", "measured_static_scenario", "measured_tracking_scenario", "benchmark_rows",
           "device_offsets_db", "device_corrected", "keyed_stream", "POOLED", "FAILURE_COLUMN", "USER_PRIOR",
           "user_methods", "method_input", "failed_row", "user_method_rows", "user_settings_rows", "scored_methods",
           "tracker_settings"]



@dataclass(frozen=True)
class Protocol:
    """Every setting of the battery on one data set, each with how it was obtained (:func:`protocol`)."""

    fit: str
    grid_spacing_m: float
    knn_k: int
    motion: dict = field(default_factory=dict)      # recording -> fit_motion's dict (or the given values)
    choices: tuple = ()                              # ({method, setting, value, how}, ...)
    knn_table: tuple = ()
    #: track -> the fusion trackers' inputs (locbook.inertial_trackers.FusionInputs), tracks with inertial streams only
    inertial: dict = field(default_factory=dict)

    def rows(self) -> list[dict]:
        return [dict(c) for c in self.choices]


def protocol(data: Dataset, model: PathLossModel, *, fit: str = "closed_form", grid_spacing_m: float | None = None,
             knn_k: int | None = None, q: float | None = None, spread_m: float | None = None,
             tracks: bool = True) -> Protocol:
    """The settings of every method on ``data`` by the module's rules (its docstring); a value given replaces its
    rule and is named as given. ``tracks=False`` skips the trackers' motion fits (a static report)."""
    pitch, pitch_how = grid_pitch_m(data, grid_spacing_m)
    k, k_how, table = choose_knn_k(data, model, knn_k)
    choices = [{"method": "every method", "setting": "channel", "value": f"per-anchor {fit} fit",
                "how": f"fitted on the calibration recordings ({', '.join(data.recordings_with('calibration'))})"},
               {"method": "every method", "setting": "geometry", "value": geometry_text(data), "how": "the manifest"},
               {"method": "grid_ml, grid_mmse, grid_bayes, rss_ml start", "setting": "grid pitch (m)",
                "value": f"{pitch:g}", "how": pitch_how},
               {"method": "knn", "setting": "k", "value": str(k), "how": k_how}]
    motion, inertial = {}, {}
    if tracks and data.recordings_with("track"):
        fix_cov = fix_covariance_from_calibration(data, model, grid_spacing_m=pitch)
        sd = np.sqrt(np.diag(fix_cov))
        for name in data.recordings_with("track"):
            if q is None or spread_m is None:
                m = fit_motion(data, model, name, grid_spacing_m=pitch, fix_cov_m2=fix_cov)
            else:
                m = {}
            m = {**m, **({"q": float(q)} if q is not None else {}),
                 **({"spread_m": float(spread_m)} if spread_m is not None else {})}
            motion[name] = m
            q_how = "given (-p q)" if q is not None else (
                f"rule: maximum likelihood of the EKF's innovations on this track's readings (log-likelihood +"
                f"{m['log_likelihood_gain']:.1f} over q = {Q_START:g}{'; at the fit bound' if m['at_bound'] else ''})")
            s_how = "given (-p spread_m)" if spread_m is not None else (
                "rule: maximum likelihood of the random walk's innovations on this track's rss_ml fixes "
                f"(log-likelihood +{m['spread_log_likelihood_gain']:.1f} over {SPREAD_START_M:g} m"
                f"{'; at the fit bound' if m.get('spread_at_bound') else ''}"
                f"{'; raised to half the grid pitch' if m.get('spread_floor') else ''})")
            choices += [{"method": "kf_on_ml, ekf, ekf_serial, ukf, imm (its quiet mode)",
                         "setting": f"q (m^2/s^4), {name}",
                         "value": f"{m['q']:.3g}", "how": q_how},
                        {"method": "particle, grid_bayes", "setting": f"random walk (m per epoch), {name}",
                         "value": f"{m['spread_m']:.3g}", "how": s_how}]
        if motion:
            ts0 = TrackerSettings()
            choices.append({"method": "imm", "setting": "manoeuvre mode, switching",
                            "value": f"{ts0.imm_q_ratio:g} q, {ts0.imm_switch_probability:g} per step",
                            "how": "assumed: locbook's choice (a second constant-velocity mode an order of magnitude "
                                   "noisier; a mode lasts 20 epochs on average), not fitted"})
            choices.append({"method": "every tracker", "setting": "start",
                            "value": f"the first rss_ml fix, sd {sd[0]:.2f} m / {sd[1]:.2f} m (x / y), at rest (sd "
                                     f"{START_VELOCITY_SD_M_S:g} m/s)",
                            "how": "rule: the calibrated covariance of rss_ml fixes (the first epoch's readings also "
                                   "update it: a small double use, stated)"})
        for name in inertial_tracks(data):      # tracks with an inertial stream: the fusion trackers' settings
            fus = fusion_inputs(data, model, name, grid_spacing_m=pitch, fix_cov_m2=fix_cov, q=motion[name]["q"])
            choices += fusion_choices(name, fus, first=not inertial)
            if fus is not None:
                inertial[name] = fus
    choices += ranging.range_choices(data)        # the range stream's sigma (none without ranges)
    return Protocol(fit, pitch, k, motion, tuple(choices), tuple(table), inertial)


# ----------------------------------------------------------------------------------------------------- results

#: the results tables' name for every scored recording together (a name the loader reserves)
POOLED = "pooled"
#: the columns of a results table (``results.csv`` of measured-localization and measured-tracking; the benchmark's
#: data columns are the ``pooled`` rows)
RESULT_COLUMNS = ("kind", "recording", "method", "settings", "epochs", "runs", "coverage", "mean_m", "median_m",
                  "p90_m", "ce95_m", "rmse_m", "mean_low_m", "mean_high_m", "rmse_low_m", "rmse_high_m", "interval",
                  "interval_note", "bound", "bound_median_m", "bound_rms_m", "bound_trimmed_rms_m", "bound_excluded",
                  "bound_excluded_why", "ratio", "ratio_note", "outside_outline")
_NO_PRIOR = ("below the bound without a prior: the bound holds for unbiased estimators and for readings that follow "
             "the fitted model; a biased estimator (pulled toward the anchors' centre) or readings less noisy than "
             "the fitted sigma can beat it")
#: a row of a user method that gave no positions (it raised, or returned what
#: :func:`locbook.user_methods.check_output` refuses) says why in this column, after :data:`RESULT_COLUMNS`; the
#: column is there only in a run with user methods ("" on every row that ran), so a run without one writes the
#: columns it always did
FAILURE_COLUMN = "failure"
#: why a user method may fall below the bound (the ratio note of a ratio below 1): locbook cannot know its prior
USER_PRIOR = ("a user method: the bound holds for unbiased estimators that know only the readings and the fitted "
              "channel; whatever else the method uses (the floor, a map, a motion model, a bias toward the room's "
              "centre) can take it below")


def _r(v):
    return None if v is None or not np.isfinite(v) else round(float(v), 3)


def _block(time_s, block_s: float, point=None) -> int:
    """Bootstrap block (epochs): ``block_s`` at the median epoch spacing, and at least the median number of epochs a
    static point holds (epochs at one point share their place and their shadowing: the point is the unit that is
    independent, not the epoch)."""
    t = np.asarray(time_s, float)
    step = float(np.median(np.diff(t))) if t.size > 1 else 1.0
    block = max(1, int(round(block_s / step))) if step > 0 else 1
    if point is not None and len(point):
        changes = np.flatnonzero(np.asarray(point[1:], dtype=object) != np.asarray(point[:-1], dtype=object))
        dwell = np.diff(np.r_[0, changes + 1, len(point)])
        block = max(block, int(np.median(dwell)))
    return block


def result_row(kind: str, recording: str, method: str, errors_m, bound_m, reason, rng: np.random.Generator, *,
               n_bootstrap: int, block: int, settings: str, prior: str, bound_name: str, outside: float) -> dict:
    """One row of :data:`RESULT_COLUMNS`: the errors ``(E, R)`` of ``R`` runs at ``E`` epochs in time order (one run
    for a deterministic method) scored by :func:`locbook.accuracy_metrics` (statistics over every run and epoch;
    the circular block bootstrap over blocks of ``block`` epochs, each epoch with all its runs), beside the bound
    ``(E,)`` summarised without its undefined epochs (``reason``; :func:`locbook.bounds.summary.summarize_bound`)
    and the ratio RMSE / RMS bound over the epochs where the bound is defined (n/a with the reason when it is
    degenerate). A ratio below 1 carries why it can be (``prior``: what the method knows that the bound does not)."""
    e = np.asarray(errors_m, float)
    e = e[:, None] if e.ndim == 1 else e
    m = accuracy_metrics(e.ravel(), rng=rng, n_bootstrap=n_bootstrap, block_length=block, values_per_epoch=e.shape[1])
    summary = summarize_bound(bound_m, reason)
    ratio, note = error_bound_ratio(e.T, summary)
    if not note and np.isfinite(ratio) and ratio < 1:
        note = f"below 1: {prior}" if prior else _NO_PRIOR
    notes = [m.get("interval_note", "")] + [m.get(f"{s}_note", "") for s in ("mean_m", "rmse_m")]
    row = {"kind": kind, "recording": recording, "method": method, "settings": settings, "epochs": int(e.shape[0]),
            "runs": int(e.shape[1]), "coverage": _r(m["coverage"]), "mean_m": _r(m["mean_m"]),
            "median_m": _r(m["median_m"]), "p90_m": _r(m["p90_m"]), "ce95_m": _r(m["ce95_m"]),
            "rmse_m": _r(m["rmse_m"]),
            "mean_low_m": _r(m["mean_m_low"]), "mean_high_m": _r(m["mean_m_high"]), "rmse_low_m": _r(m["rmse_m_low"]),
            "rmse_high_m": _r(m["rmse_m_high"]), "interval": m.get("interval", ""),
            "interval_note": "; ".join(dict.fromkeys(n for n in notes if n)), "bound": bound_name,
            **{k: (_r(v) if isinstance(v, float) else v) for k, v in summary.row().items()},
            "ratio": _r(ratio), "ratio_note": note, "outside_outline": _r(outside)}
    return {k: row[k] for k in RESULT_COLUMNS}


def failed_row(kind: str, recording: str, method: str, n_epochs: int, bound_m, reason, *, settings: str,
               bound_name: str, failure: str) -> dict:
    """The row of :data:`RESULT_COLUMNS` of a user method that failed (:class:`locbook.user_methods.MethodFailure`):
    no statistic, the bound's summary as every other method's row has it, and its one-line error in
    :data:`FAILURE_COLUMN`."""
    summary = summarize_bound(bound_m, reason)
    row = {c: None for c in RESULT_COLUMNS}
    row.update(kind=kind, recording=recording, method=method, settings=settings, epochs=int(n_epochs), runs=0,
               interval="", interval_note="", bound=bound_name, ratio_note="",
               **{k: (_r(v) if isinstance(v, float) else v) for k, v in summary.row().items() if k in row})
    return {**{k: row[k] for k in RESULT_COLUMNS}, FAILURE_COLUMN: f"failed: {failure}"}


def user_methods(data: Dataset, *, methods=(), trackers=()) -> tuple[UserMethod, ...]:
    """The user methods of a run on ``data``: its manifest's ``[[method]]`` tables, then the command line's static
    ``methods`` and ``trackers`` (``NAME=SPEC``; :func:`locbook.user_methods.registered_methods`)."""
    return registered_methods(data, methods=methods, trackers=trackers)


def method_input(data: Dataset, model: PathLossModel, recording: str, rss_dbm, time_s,
                 rng: np.random.Generator | None, ranges=None) -> MethodInput:
    """What a user method is called with on one recording's epochs (:class:`locbook.MethodInput`): read-only
    copies of the readings, times, anchors and outline, and a copy of the fitted channel with the one
    :class:`RssModel` built from it, so that no method can change what the next one sees. ``ranges``: ``(range_m,
    range_std_m)`` on the same epochs, or None (:mod:`locbook.scenarios.measured_ranges`)."""
    channel_copy = deepcopy(model)
    return MethodInput(rss_dbm=frozen(rss_dbm), time_s=frozen(time_s), recording=recording,
                       kind=data.recording(recording).role, tag_height_m=data.tag_height_m,
                       anchors_m=frozen(data.anchors_m), channel=channel_copy,
                       model=RssModel(frozen(data.anchors_m), channel_copy, tag_height_m=data.tag_height_m),
                       outline_m=frozen(data.outline_m), rng=rng,
                       range_m=None if ranges is None else frozen(ranges[0]),
                       range_std_m=None if ranges is None else frozen(ranges[1]))


def _run_user(methods, kind: str, inputs_of) -> tuple[dict, dict, dict]:
    """``(positions {method: {recording: (E, 2)}}, covariances {method: {recording: (E, 2, 2) or None}},
    failures {method: MethodFailure})`` of the user methods of ``kind``; ``inputs_of(method)`` gives its
    ``{recording: MethodInput}``."""
    positions, covariances, failures = {}, {}, {}
    for m in methods:
        if m.kind != kind:
            continue
        got = run_method(m, inputs_of(m))
        if isinstance(got, MethodFailure):
            failures[m.name] = got
            continue
        positions[m.name] = {n: v[0] for n, v in got.items()}
        covariances[m.name] = {n: v[1] for n, v in got.items()}
    return positions, covariances, failures


def scored_methods(res: dict | None) -> list[str]:
    """The methods of a :func:`static_results` or :func:`tracking_results` that gave positions, in table order:
    the battery's, then the user methods that ran (a failed one has rows, no figure)."""
    if res is None:
        return []
    return [*res["battery"], *(m.name for m in res["user"] if m.name not in res["failures"])]


def user_method_rows(*results) -> list[dict]:
    """One row per user method of the ``results`` (:func:`static_results`, :func:`tracking_results`; None skipped):
    name, kind, function (``user method <spec>``), where it was registered, ``ok`` or ``failed``, its one-line
    error and its own traceback. The table the command line reads to say which user method failed."""
    rows = []
    for res in results:
        if res is None:
            continue
        for m in res["user"]:
            f = res["failures"].get(m.name)
            rows.append({"method": m.name, "kind": m.kind, "function": res["described"][m.name],
                         "registered": "[[method]] of the manifest" if m.source == "manifest" else
                         ("--method" if m.kind == "static" else "--tracker") + " on the command line",
                         "status": "failed" if f else "ok", "recording": f.recording if f else "",
                         "error": f.error if f else "", "traceback": f.traceback if f else ""})
    return rows


def user_settings_rows(methods, kind: str | None = None) -> list[dict]:
    """The settings table's rows of the user methods (of ``kind``, default every one): ``user method <spec>``."""
    sees = {"static": "static: every scored epoch on its own", "tracker": "tracker: each track in time order"}
    return [{"method": m.name, "setting": "function", "value": m.described,
             "how": ("the manifest's [[method]] table" if m.source == "manifest" else
                     f"{'--method' if m.kind == 'static' else '--tracker'} on the command line") + f" ({sees[m.kind]})"}
            for m in methods if kind is None or m.kind == kind]


def _static_settings(name: str, proto: Protocol) -> str:
    extra = {"knn": f"k = {proto.knn_k} (calibration map)", "grid_ml": f"pitch {proto.grid_spacing_m:g} m",
             "grid_mmse": f"pitch {proto.grid_spacing_m:g} m",
             "rss_ml": f"grid ML at {proto.grid_spacing_m:g} m", "rss_ml_free": f"grid ML at {proto.grid_spacing_m:g} m"
             }.get(name, "")
    return "; ".join(x for x in (BATTERY_STATIC[name].settings, extra) if x)


def static_results(data: Dataset, model: PathLossModel, proto: Protocol, *, seed: int, n_bootstrap: int,
                   block_s: float, user_methods=()) -> dict | None:
    """Every static method on every scored recording (one problem: each epoch is located on its own), scored per
    recording and pooled (:func:`result_row`; the CRLB from the anchors each epoch heard). None when nothing is
    scored. Returns ``{"recordings", "tests", "fixes", "errors", "bounds", "rows"}`` (per recording: fixes and errors
    ``{method: (E, 2) / (E,)}``, bounds ``(bound, reason)``).

    ``user_methods``: :class:`locbook.user_methods.UserMethod` (its static ones run; a tracker is left to
    :func:`tracking_results`), each called once per scored recording (:func:`method_input`) after the battery and
    scored the same way, its rows after the battery's in each group and its bootstrap stream keyed by its name, so
    no battery number changes. One that fails has rows saying so (:func:`failed_row`) and no fixes. The result also
    holds ``"battery"`` (the battery's names), ``"user"`` (the static user methods), ``"described"`` (``user method
    <spec>`` of each), ``"covariances"`` (``{recording: {method: (E, 2, 2) or None}}``) and ``"failures"``
    (``{method: MethodFailure}``)."""
    names = scored_recordings(data)
    sc = static_scenario(data, model, names, grid_spacing_m=proto.grid_spacing_m, fit=proto.fit)
    if sc is None:
        return None
    tests = {n: TestEpochs.of(data, n) for n in names}
    pooled = battery_static_fixes(sc, sc.measured_rss_dbm[None], knn_k=proto.knn_k)
    cuts = np.cumsum([0] + [len(t.truth_m) for t in tests.values()])
    pooled_bound = static_bound_checked(sc)          # the anchors each epoch heard
    fixes, errors, bounds, rows = {}, {}, {}, []
    for i, n in enumerate(names):
        fixes[n] = {k: v[0, cuts[i]:cuts[i + 1]] for k, v in pooled.items()}
        errors[n] = {k: np.linalg.norm(v - tests[n].truth_m, axis=-1) for k, v in fixes[n].items()}
        bounds[n] = tuple(v[cuts[i]:cuts[i + 1]] for v in pooled_bound)
    ranged = ranging.static_range_results(data, names)     # range_nls where the recordings have ranges
    stream = list(ranging.RANGE_STATIC_METHODS) if ranged is not None else []
    for method in stream:
        for n in names:
            fixes[n][method] = ranged["fixes"][n]
            errors[n][method] = np.linalg.norm(ranged["fixes"][n] - tests[n].truth_m, axis=-1)
    user = tuple(m for m in user_methods if m.kind == "static")
    described = {m.name: m.described for m in user}
    got, covariances, failures = _run_user(user, "static", lambda m: {
        n: method_input(data, model, n, tests[n].rss_dbm, tests[n].time_s,
                        keyed_stream(seed, data.name, "user", "static", n, m.name),
                        ranging.user_ranges(data, n)) for n in names})
    for name, per_recording in got.items():
        for n in names:
            fixes[n][name] = per_recording[n]
            errors[n][name] = np.linalg.norm(per_recording[n] - tests[n].truth_m, axis=-1)
    bound_name = "CRLB (fitted channel, anchors heard)"
    groups = [(POOLED, names)] + [(n, [n]) for n in names]
    for label, members in groups:
        # the largest member's block: a pooled row is never resampled in finer units than one of its recordings
        block = max(_block(tests[n].time_s, block_s, tests[n].point) for n in members)
        bound = np.concatenate([bounds[n][0] for n in members])
        reason = np.concatenate([bounds[n][1] for n in members])
        for method in [*pooled, *stream, *described]:
            if method in failures:
                rows.append(failed_row("static", label, method, len(bound), bound, reason,
                                       settings=described[method], bound_name=bound_name,
                                       failure=failures[method].error))
                continue
            e = np.concatenate([errors[n][method] for n in members])
            f = np.concatenate([fixes[n][method] for n in members])
            own = ranging.RANGE_STATIC_METHODS.get(method)      # a range method: beside the range CRLB
            row = result_row("static", label, method, e,
                             np.concatenate([ranged["bounds"][n][0] for n in members]) if own else bound,
                             np.concatenate([ranged["bounds"][n][1] for n in members]) if own else reason,
                             keyed_stream(seed, data.name, "static", members[0] if len(members) == 1 else label,
                                          method), n_bootstrap=n_bootstrap,
                             block=block, settings=described.get(method) or (own.settings if own else
                                                                             _static_settings(method, proto)),
                             prior=BATTERY_STATIC[method].prior if method in BATTERY_STATIC else
                             own.prior if own else USER_PRIOR,
                             bound_name=ranging.RANGE_BOUND_NAME if own else bound_name,
                             outside=outside_fraction(data, f))
            rows.append(row if method in BATTERY_STATIC or own else {**row, FAILURE_COLUMN: ""})
    return {"recordings": names, "tests": tests, "fixes": fixes, "errors": errors, "bounds": bounds, "rows": rows,
            "scenario": sc, "battery": [*pooled, *stream], "user": user, "described": described, "failures": failures,
            "covariances": {n: {k: v[n] for k, v in covariances.items()} for n in names}}


_KALMAN = ("kf_on_ml", "ekf", "ekf_serial", "ukf")


def tracking_results(data: Dataset, model: PathLossModel, proto: Protocol, *, seed: int, n_particles: int,
                     particle_runs: int, n_bootstrap: int, block_s: float, ukf_alpha: float = 0.5,
                     recordings=None, user_methods=()) -> dict | None:
    """Every tracker on every track (:func:`tracking_scenario`, the motion of :class:`Protocol`), scored per track
    with a true position and pooled over them (:func:`result_row`; the posterior CRLB of the constant-velocity model
    at the track's fitted ``q`` from the trackers' start). The Kalman-family trackers and grid Bayes are
    deterministic (one run); the particle filter runs ``particle_runs`` times on independent streams and is scored
    over all its runs. ``recordings``: the tracks to run (default every one). None without a track. Returns ``{"tracks":
    {name: (scenario, {tracker: (R, T, 2)}, flags, bound (T,))}, "rows"}``.

    ``user_methods``: as for :func:`static_results`; its trackers run once on each track (every tick of its clock,
    in time order: :func:`method_input`), one run, no NIS guard, after the battery, with the same bound and rows
    (``"battery"``, ``"user"``, ``"described"``, ``"covariances"`` ``{track: {tracker: (T, 2, 2) or None}}`` and
    ``"failures"`` as there)."""
    names = data.recordings_with("track") if recordings is None else list(recordings)
    if not names:
        return None
    fix_cov = fix_covariance_from_calibration(data, model, grid_spacing_m=proto.grid_spacing_m)
    ranged = ranging.ranged(data, names)
    stream = list(ranging.RANGE_TRACKERS) if ranged else []
    out, per = {}, {}
    for name in names:
        motion = proto.motion[name]
        fus = proto.inertial.get(name)
        sc = tracking_scenario(data, model, name, grid_spacing_m=proto.grid_spacing_m, q=motion["q"],
                               spread_m=motion["spread_m"], fix_cov_m2=fix_cov, fit=proto.fit, inertial=fus)
        ts = tracker_settings(motion["q"], n_particles, ukf_alpha, fix_cov)
        rss = sc.measured_rss_dbm
        x0 = initial_states(sc, ts, 1, None)
        est, flags = run_trackers(sc, rss[None], x0, ts, keyed_stream(seed, data.name, "tracking", name, "kalman"),
                                  trackers=[t for t in TRACKERS if t != "particle"], with_divergence=True)
        fused = {}
        if fus is not None:      # the fusion trackers (deterministic: one run), after the battery's draws
            for t in fus.trackers:
                fused[t], flags[t] = run_fusion(sc, t, np.asarray(rss[None], float), x0, ts.P0, ukf_alpha=ts.ukf_alpha)
        runs = np.broadcast_to(rss, (particle_runs,) + rss.shape)
        est["particle"] = run_trackers(sc, runs, np.repeat(x0, particle_runs, axis=0), ts,
                                       keyed_stream(seed, data.name, "tracking", name, "particle"),
                                       trackers=["particle"])["particle"]
        est = {**{t: est[t] for t in TRACKERS}, **fused}
        range_bound = None
        if name in ranged:      # the range trackers: the RSS stream and the track's ranges
            ep, _, ticks = track_epochs(data, name)
            more, more_flags = ranging.run_range_trackers(data, name, sc, ep, ticks, x0, ts)
            est.update(more)
            flags.update(more_flags)
            range_bound = ranging.range_tracking_bound_m(data, name, sc, ep, ticks, ts)
        bound = tracking_bound_m(sc, ts)
        out[name] = (sc, est, flags, bound)
        if sc.scored is not None and sc.scored.any():
            steps = sc.scored_steps
            per[name] = {"steps": steps, "block": _block(steps * sc.dt_s, block_s), "bound": bound[steps],
                         "range_bound": None if range_bound is None else range_bound[steps],
                         "errors": {t: np.linalg.norm(v[:, steps] - sc.truth_m[steps], axis=-1).T
                                    for t, v in est.items()},
                         "est": {t: v[:, steps] for t, v in est.items()},
                         "knobs": {**_tracker_knobs(proto, name, ts, sc),
                                   **(fusion_knobs(fus, ukf_alpha) if fus is not None else {})}}
            if name in ranged:
                per[name]["knobs"].update(ranging.range_tracker_knobs(data, name, per[name]["knobs"]["ekf"], ts))
    user = tuple(m for m in user_methods if m.kind == "tracker")
    described = {m.name: m.described for m in user}
    got, covariances, failures = _run_user(user, "tracker", lambda m: {
        n: method_input(data, model, n, out[n][0].measured_rss_dbm, out[n][0].time_s,
                        keyed_stream(seed, data.name, "user", "tracking", n, m.name),
                        ranging.user_ranges(data, n, track_epochs(data, n), len(out[n][0].time_s))
                        if data.has_ranges(n) else None)
        for n in names})
    for tracker, per_track in got.items():
        for n in names:
            out[n][1][tracker] = per_track[n][None]           # one run: (1, T, 2), as every tracker's (R, T, 2)
            if n in per:
                steps = per[n]["steps"]
                per[n]["errors"][tracker] = np.linalg.norm(per_track[n][None][:, steps] - out[n][0].truth_m[steps],
                                                           axis=-1).T
                per[n]["est"][tracker] = per_track[n][None][:, steps]
    rows = []
    bound_name = "PCRLB (constant velocity at the fitted q, from the trackers' start)"
    groups = ([(POOLED, list(per))] if per else []) + [(n, [n]) for n in per]
    # the fusion trackers that ran on some track; a row of one pools only groups whose every track has it
    fusion = [t for t in FUSION_TRACKERS if any(t in out[n][1] for n in names)]
    for label, members in groups:
        block = max(per[n]["block"] for n in members)
        bound = np.concatenate([per[n]["bound"] for n in members])
        # a stream's tracker pools only groups whose every track has its stream
        for tracker in [*TRACKERS, *(t for t in [*stream, *fusion] if all(t in per[n]["errors"] for n in members)),
                        *described]:
            if tracker in failures:
                rows.append(failed_row("tracking", label, tracker, len(bound), bound, None,
                                       settings=described[tracker], bound_name=bound_name,
                                       failure=failures[tracker].error))
                continue
            e = np.concatenate([per[n]["errors"][tracker] for n in members])
            # the range trackers are beside the bound of the readings they see: RSS and ranges
            ranged_row = tracker in ranging.RANGE_TRACKERS
            row_bound = np.concatenate([per[n]["range_bound"] for n in members]) if ranged_row else bound
            settings = described.get(tracker) or (per[members[0]]["knobs"][tracker] if len(members) == 1 else
                                                  "motion per track (see each track's row)")
            row = result_row("tracking", label, tracker, e, row_bound, None,
                             keyed_stream(seed, data.name, "tracking", members[0] if len(members) == 1 else label,
                                          tracker, "bootstrap"),
                             n_bootstrap=n_bootstrap, block=block, settings=settings,
                             prior=TRACKER_PRIORS.get(tracker, ranging.RANGE_TRACKER_PRIORS.get(
                                 tracker, FUSION_PRIORS.get(tracker, USER_PRIOR))),
                             bound_name=ranging.RANGE_TRACKING_BOUND_NAME if ranged_row else bound_name,
                             outside=outside_fraction(data, np.concatenate([per[n]["est"][tracker].reshape(-1, 2)
                                                                            for n in members])))
            rows.append(row if tracker in TRACKER_PRIORS or tracker in ranging.RANGE_TRACKERS
                        or tracker in FUSION_PRIORS else {**row, FAILURE_COLUMN: ""})
    return {"tracks": out, "rows": rows, "battery": [*TRACKERS, *stream, *fusion], "fusion": fusion, "user": user,
            "described": described,
            "failures": failures, "covariances": {n: {k: v[n] for k, v in covariances.items()} for n in names}}


def _tracker_knobs(proto: Protocol, name: str, ts: TrackerSettings, sc: TrackingScenario) -> dict:
    fitted = "log_likelihood_gain" in proto.motion[name]
    common = (f"q = {ts.q:.3g} m^2/s^4 ({'fitted' if fitted else 'given'}), dt = {sc.dt_s:g} s, start: first rss_ml "
              f"fix, calibrated fix covariance, at rest (sd {ts.initial_velocity_sd_m_s:g} m/s)")
    walk = (f"random walk {sc.spread_m:.3g} m/epoch "
            f"({'fitted' if 'spread_log_likelihood_gain' in proto.motion[name] else 'given'})")
    return {"kf_on_ml": common + "; R: rss_ml fix errors on the calibration epochs", "ekf": common,
            "ekf_serial": common, "ukf": common + f"; alpha = {ts.ukf_alpha:g}",
            "imm": common + f"; manoeuvre mode {ts.imm_q_ratio:g} q, switching {ts.imm_switch_probability:g} per step "
                            "(locbook's choice)",
            "particle": f"N = {ts.n_particles}, {walk}", "grid_bayes": f"pitch {sc.grid_spacing_m:g} m, {walk}"}


def benchmark_rows(data: Dataset, static: dict | None, tracking: dict | None) -> list[dict]:
    """A data set's cells of the cross-document benchmark: the ``pooled`` rows of :func:`static_results` and
    :func:`tracking_results`, in the benchmark's columns (the same numbers as the data set's own reports)."""
    rows = []
    for kind, res in (("static", static), ("tracking", tracking)):
        if res is None:
            continue
        for r in res["rows"]:
            if r["recording"] != POOLED:
                continue
            rows.append({"kind": kind, "scenario": f"data-{data.name}", "document": data.name, "data": "measured",
                         "method": r["method"], "runs": r["runs"], "points": r["epochs"], "rmse_m": r["rmse_m"],
                         "rmse_low_m": r["rmse_low_m"], "rmse_high_m": r["rmse_high_m"], "interval": r["interval"],
                         "mean_m": r["mean_m"], "median_m": r["median_m"], "p90_m": r["p90_m"],
                         "missing": _r(1.0 - r["coverage"]) if r["coverage"] is not None else None,
                         "bound_rms_m": r["bound_rms_m"], "bound_median_m": r["bound_median_m"],
                         "bound_excluded": r["bound_excluded"], "ratio": r["ratio"], "ratio_note": r["ratio_note"],
                         "bound": "CRLB" if kind == "static" else "PCRLB", "settings": r["settings"],
                         **({FAILURE_COLUMN: r[FAILURE_COLUMN]} if FAILURE_COLUMN in r else {})})
    return rows


def measured_static_scenario(data, fit: str = "closed_form") -> StaticScenario | None:
    """The static problem of a data set (every scored recording; :func:`static_scenario` at the rule's grid pitch);
    None when nothing is scored."""
    ds = load(data)
    model = channel(calibrate(ds, fit=fit))
    return static_scenario(ds, model, grid_spacing_m=grid_pitch_m(ds)[0], fit=fit)


def measured_tracking_scenario(data, fit: str = "closed_form") -> TrackingScenario | None:
    """The first track with a true position per epoch (:func:`tracking_scenario`, its motion by :func:`fit_motion`);
    None when no track has truth."""
    ds = load(data)
    model = channel(calibrate(ds, fit=fit))
    names = [n for n in ds.recordings_with("track") if ds.recording(n).has_truth]
    if not names:
        return None
    pitch = grid_pitch_m(ds)[0]
    fix_cov = fix_covariance_from_calibration(ds, model, grid_spacing_m=pitch)
    m = fit_motion(ds, model, names[0], grid_spacing_m=pitch, fix_cov_m2=fix_cov)
    return tracking_scenario(ds, model, names[0], grid_spacing_m=pitch, q=m["q"], spread_m=m["spread_m"],
                             fix_cov_m2=fix_cov, fit=fit)
