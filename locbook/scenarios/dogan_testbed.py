"""Dogan (2015), Ch. 5: the thesis's test bed, regenerated from the printed channel fit.

No raw measurement of the thesis was published, so everything here is synthetic data drawn with the printed fit
(Sec. 5.2: P0, alpha and sigma_RSS of the LS fit; the tracking figures use sigma_RSS = 6 dB) in the 7.6 m x 9.2 m
laboratory with corner anchors (Sec. 5.4). Every printed value is read from ``locbook/data/printed/dogan2015.csv``.
Three studies:

- calibration (Eq. (5.1), Figs 5.4-5.5): LS on 24 points x 30 packets x 4 anchors on the assumed Fig 5.4 grid;
- antenna orientation (Sec. 5.3, Fig 5.6): an explicitly illustrative, non-isotropic gain g(theta);
- tracking (Sec. 5.4, Figs 5.7-5.11): the Ch. 3 filters with one packet every 2 s (every 40th step of the 20 Hz
  grid) and a simulated 20 Hz accelerometer, as the thesis did ("real RSS plus simulated acceleration").

The printed test-bed RMSEs come from one measured walk. Our estimate is the mean RMSE of one simulated walk; the
spread of single walks (2 sd) is the named ambiguity of the comparison, not a standard error of a mean.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._deprecation import renamed_keyword
from ..errors import ParameterError
from ..metrics import reduction_pct, rmse_m
from ..models.channel import PathLossModel, pairwise_distance_m, quantize_db
from ..montecarlo import single_run_interval
from ..reproduce.scoring import Ambiguity
from ..static.calibration import PathLossFit, calibrate_path_loss
from ..tracking.divergence import divergence_note
from .dogan import (
    ANCHORS_M,
    DEFAULT_NOISE_INTERPRETATION,
    DEFAULT_START,
    DT_S,
    FILTERS,
    PRINTED,
    SPEED_MPS,
    ChannelRun,
    calibrated_from_text,
    scored_errors,
)

__all__ = [
    "TESTBED_REF_POWER_DBM", "TESTBED_PATH_LOSS_EXP", "TESTBED_FIT_SIGMA_DB", "TESTBED_SIGMA_DB", "TESTBED_RSS_EVERY",
    "CALIBRATION_X_M", "CALIBRATION_Y_M", "CALIBRATION_POINTS", "CALIBRATION_PACKETS", "PRINTED_MEASUREMENT_COUNT",
    "PRINTED_TESTBED_RMSE", "PRINTED_FUSION_REDUCTION", "PRINTED_FUSION_REDUCTION_CH6", "PRINTED_ACCURACY",
    "ANTENNA_SEPARATION_M", "ANTENNA_HEIGHT_M", "ORIENTATION_SAMPLES", "ONE_WALK_SOURCE",
    "calibration_points_m", "simulate_calibration", "fit_calibration", "CalibrationStudy", "calibration_study",
    "orientation_gain_db", "simulate_orientation", "testbed_rows", "printed_reductions_pct", "testbed_flags",
    "record_testbed", "BENIGN_CHANNEL_NOTE",
]

#: Sec. 5.2: the LS fit of Eq. (5.1) to the laboratory measurements.
TESTBED_REF_POWER_DBM = PRINTED.get("Sec. 5.2", "LS fit (Eq. (5.1))", "P0").value
TESTBED_PATH_LOSS_EXP = PRINTED.get("Sec. 5.2", "LS fit (Eq. (5.1))", "alpha").value
TESTBED_FIT_SIGMA_DB = PRINTED.get("Sec. 5.2", "LS fit (Eq. (5.1))", "sigma_RSS").value
#: Figs 5.8-5.9 captions: the tracking uses sigma_RSS = 6 dB (not the fitted 5.8 dB).
TESTBED_SIGMA_DB = PRINTED.get("Fig. 5.8 caption", "tracking channel", "sigma_RSS").value
#: Sec. 5.4: one packet "each 2 seconds": every 40th step of the 20 Hz grid (our time step; the
#: walk's timing is not printed).
TESTBED_RSS_EVERY = int(round(PRINTED.get("Sec. 5.4", "packet period").value / DT_S))
#: Fig 5.4's 24 points; coordinates not printed. Default (ours): a 6 x 4 grid inside the room.
CALIBRATION_X_M = (1.1, 2.2, 3.3, 4.3, 5.4, 6.5)
CALIBRATION_Y_M = (1.5, 3.5, 5.7, 7.7)
#: Sec. 5.2: 24 points, 30 packets per point, every anchor records each.
CALIBRATION_POINTS = int(PRINTED.get("Sec. 5.2", "calibration", "measurement points").value)
CALIBRATION_PACKETS = int(PRINTED.get("Sec. 5.2", "calibration", "packets per point").value)
#: Sec. 5.2: "Total number of the measurements used in parameter estimation is 3360" (but 24 x 30 x 4 = 2880).
PRINTED_MEASUREMENT_COUNT = PRINTED.get("Sec. 5.2", "calibration", "total number of the measurements")
#: Sec. 5.4, Figs 5.8-5.11: RMSE (m) of the single measured walk, ONLY RSS (None) and RSS + simulated
#: acceleration ("fusion"), as :class:`~locbook.reproduce.Printed`.
PRINTED_TESTBED_RMSE = {
    ("static_mle", None): PRINTED.get("Fig. 5.8 text", "STATIC (MLE)", "ONLY RSS"),
    ("serial_ekf", None): PRINTED.get("Fig. 5.9 text", "serial EKF", "ONLY RSS"),
    ("serial_ekf", "fusion"): PRINTED.get("Fig. 5.9 text", "serial EKF", "RSS/IMU"),
    ("parallel_ekf", None): PRINTED.get("Fig. 5.10 text", "parallel EKF", "ONLY RSS"),
    ("parallel_ekf", "fusion"): PRINTED.get("Fig. 5.10 text", "parallel EKF", "RSS/IMU"),
    ("kalman_filter", None): PRINTED.get("Fig. 5.11 text", "KF", "ONLY RSS"),
    ("kalman_filter", "fusion"): PRINTED.get("Fig. 5.11 text", "KF", "RSS/IMU"),
}
#: Sec. 5.4: "sensor fusion decreases the error approximately by 15% experimentally"; Ch. 6 repeats it.
PRINTED_FUSION_REDUCTION = PRINTED.get("Sec. 5.4 text", "fusion error reduction", "experimental")
PRINTED_FUSION_REDUCTION_CH6 = PRINTED.get("Ch. 6", "fusion error reduction", "experimental")
#: Sec. 5.4: "static localization performance can be enhanced the tracking filters to reach accuracy 1 m".
PRINTED_ACCURACY = PRINTED.get("Sec. 5.4 text", "tracking filters", "experimental accuracy")
#: Sec. 5.3: anchor and blindfolded node 1 m above the floor, 2 m apart, 100 measurements per orientation.
ANTENNA_SEPARATION_M = PRINTED.get("Sec. 5.3", "antenna test", "distance").value
ANTENNA_HEIGHT_M = PRINTED.get("Sec. 5.3", "antenna test", "height above the ground").value
ORIENTATION_SAMPLES = int(PRINTED.get("Sec. 5.3", "antenna test", "measurements per orientation").value)
#: Where the thesis says that one walk was measured (the source of the single-walk ambiguity).
ONE_WALK_SOURCE = "Dogan 2015 Sec. 5.4 (one experimental walk; Figs. 5.8-5.11 print its RMSE)"

_FIGURE = {"static_mle": "Fig. 5.8", "serial_ekf": "Fig. 5.9", "parallel_ekf": "Fig. 5.10",
           "kalman_filter": "Fig. 5.11"}


def calibration_points_m(x_m=CALIBRATION_X_M, y_m=CALIBRATION_Y_M) -> np.ndarray:
    """The Fig 5.4 measurement points ``(P, 2)``, row by row (our assumed grid)."""
    xs, ys = np.meshgrid(np.asarray(x_m, float), np.asarray(y_m, float))
    return np.stack([xs.ravel(), ys.ravel()], axis=-1)


def simulate_calibration(points_m, channel: PathLossModel, n_packets: int, rng: np.random.Generator, *,
                         n_runs: int = 1, anchors_m=ANCHORS_M, quantize_step_db: float | None = None):
    """RSS ``(n_runs, P, n_packets, m)`` of every packet at every anchor (Sec. 5.2: each anchor saves the RSS of
    each packet) and the true distances ``(P, m)``. Shadowing is i.i.d. over packets, points and anchors (no
    spatial correlation, the thesis's own model); ``quantize_step_db`` rounds to the radio's resolution."""
    if n_packets < 1 or n_runs < 1:
        raise ParameterError("n_packets and n_runs must be at least 1")
    distance = pairwise_distance_m(np.asarray(points_m, float), anchors_m)
    shape = (n_runs, distance.shape[0], n_packets, distance.shape[1])
    power = channel.sample_rss_dbm(np.broadcast_to(distance[None, :, None, :], shape), rng=rng)
    if quantize_step_db:
        power = quantize_db(power, quantize_step_db)
    return power, distance


@dataclass(frozen=True)
class CalibrationStudy:
    """Eq. (5.1) on many synthetic calibrations: estimates ``(n_runs,)`` of P0, alpha and the residual sigma."""

    ref_power_dbm: np.ndarray
    path_loss_exp: np.ndarray
    residual_sigma_db: np.ndarray
    n_measurements: int

    def summary(self, truth: PathLossModel) -> list[dict]:
        rows = []
        for name, est, true in (("P0 (dBm)", self.ref_power_dbm, truth.ref_power_dbm),
                                ("alpha", self.path_loss_exp, truth.path_loss_exp),
                                ("sigma (dB)", self.residual_sigma_db, truth.sigma_db)):
            rows.append(dict(parameter=name, truth=float(true), mean=float(est.mean()),
                             bias=float(est.mean() - true), std=float(est.std(ddof=1)),
                             rmse=float(rmse_m(est - true))))
        return rows


def calibration_study(points_m, channel: PathLossModel, n_packets: int, n_runs: int, rng: np.random.Generator, *,
                      average_packets: bool = False, quantize_step_db: float | None = None,
                      anchors_m=ANCHORS_M) -> CalibrationStudy:
    """Repeat the calibration ``n_runs`` times: pooled LS (Eq. (5.1)) over every (point, anchor, packet) sample,
    or over the per-(point, anchor) packet means (``average_packets``; the thesis does not say). Uses the
    normal equations, which equal the cvxpy solution (tested)."""
    power, distance = simulate_calibration(points_m, channel, n_packets, rng, n_runs=n_runs, anchors_m=anchors_m,
                                           quantize_step_db=quantize_step_db)
    if average_packets:
        power = power.mean(axis=2, keepdims=True)
    d = np.broadcast_to(distance[None, :, None, :], power.shape)
    fit = calibrate_path_loss(d.reshape(n_runs, -1, d.shape[-1]), power.reshape(n_runs, -1, d.shape[-1]), "pooled",
                              solver="closed_form")
    return CalibrationStudy(fit.ref_power_dbm, fit.path_loss_exp, fit.residual_sigma_db, int(fit.n_samples[0]))


def fit_calibration(rss_dbm, distance_m) -> PathLossFit:
    """One calibration, Eq. (5.1) solved as the convex LS ``min ||P - (P0 - 10 alpha log10 d)||^2`` in cvxpy
    over every packet of ``rss_dbm`` ``(P, packets, m)`` at ``distance_m`` ``(P, m)``."""
    rss_dbm = np.asarray(rss_dbm, float)
    d = np.broadcast_to(np.asarray(distance_m, float)[:, None, :], rss_dbm.shape)
    return calibrate_path_loss(d.reshape(-1, d.shape[-1]), rss_dbm.reshape(-1, d.shape[-1]), "pooled",
                               solver="cvxpy")


def orientation_gain_db(theta_deg, *, quadrupole_db: float = 4.0, dipole_db: float = 3.0,
                        phase_deg: float = 30.0):
    """An **illustrative** non-isotropic antenna gain ``g(theta) = A cos(2 theta + phi) + B cos(theta)`` (dB).

    Sec. 5.3 measured the RSS against the blindfolded node's orientation (Fig 5.6) and printed no value; the shape
    and the 3-5 dB amplitudes are our illustration, not the thesis's chip antenna."""
    t = np.deg2rad(np.asarray(theta_deg, float))
    return quadrupole_db * np.cos(2.0 * t + np.deg2rad(phase_deg)) + dipole_db * np.cos(t)


def simulate_orientation(theta_deg, channel: PathLossModel, rng: np.random.Generator, *,
                         n_samples: int = ORIENTATION_SAMPLES, separation_m: float = ANTENNA_SEPARATION_M,
                         sigma_db: float = 3.0, **gain):
    """RSS ``(n_orientations, n_samples)`` at ``separation_m`` (both antennas at the same height, so the height does
    not enter the distance) for each orientation: the channel mean plus :func:`orientation_gain_db` plus
    N(0, sigma_db^2) sample noise (a static link fluctuates less than the walking channel)."""
    theta = np.atleast_1d(np.asarray(theta_deg, float))
    mean = channel.mean_rss_dbm(separation_m) + orientation_gain_db(theta, **gain)
    return mean[:, None] + sigma_db * rng.standard_normal((theta.size, n_samples))


def _walk_row(values, coverage: float) -> dict:
    values = np.asarray(values, float)
    lo, hi = single_run_interval(values, coverage)
    return dict(mean_single_walk=float(values.mean()), sd_single_walk=float(values.std(ddof=1)),
                mc_se=float(values.std(ddof=1) / np.sqrt(values.size)), median_single_walk=float(np.median(values)),
                lower=lo, upper=hi)


def printed_reductions_pct() -> dict:
    """The fusion reduction of each filter from its printed pair (Figs. 5.9-5.11), in %."""
    return {name: float(reduction_pct(PRINTED_TESTBED_RMSE[(name, None)].value,
                                      PRINTED_TESTBED_RMSE[(name, "fusion")].value)) for name in FILTERS}


def testbed_rows(run: ChannelRun, sigma_acc_mps2: float, *, coverage: float = 0.90,
                 rmse_epochs: str = "rss_epochs") -> list[dict]:
    """Each printed test-bed RMSE beside the simulated walks: the RMSE of one walk (per walk over its epochs) with
    its mean, sd, Monte-Carlo standard error of the mean, median and central ``coverage`` interval, and the pooled
    Monte-Carlo RMSE (``mc_rmse``); then the fusion reduction per filter (printed: derived from the printed pair) and
    the mean of the three per walk, which the thesis summarises as "approximately 15%". ``rmse_epochs``: the filters'
    RMSE over the packet epochs or over every grid step (:func:`~locbook.scenarios.dogan.scored_errors`)."""
    rows = []
    for (name, case), printed in PRINTED_TESTBED_RMSE.items():
        key = "static_mle" if name == "static_mle" else (name, None if case is None else sigma_acc_mps2)
        err = scored_errors(run, key, rmse_epochs)
        rows.append(dict(filter=name, case="ONLY RSS" if case is None else "RSS/IMU", where=printed.location,
                         printed=printed.value, printed_value=printed, mc_rmse=float(rmse_m(err)),
                         **_walk_row(rmse_m(err, axis=1), coverage)))
    per_filter = []
    printed_red = printed_reductions_pct()
    for name in FILTERS:
        only = rmse_m(scored_errors(run, (name, None), rmse_epochs), axis=1)
        fused = rmse_m(scored_errors(run, (name, sigma_acc_mps2), rmse_epochs), axis=1)
        per_filter.append(reduction_pct(only, fused))
        rows.append(dict(filter=name, case="reduction % (derived)", where=PRINTED_TESTBED_RMSE[(name, None)].location,
                         printed=printed_red[name], printed_value=None,
                         mc_rmse=float(reduction_pct(rmse_m(scored_errors(run, (name, None), rmse_epochs)),
                                                     rmse_m(scored_errors(run, (name, sigma_acc_mps2), rmse_epochs)))),
                         **_walk_row(per_filter[-1], coverage)))
    mean_reduction = np.mean(per_filter, axis=0)          # per walk: the mean of the three filters' reductions
    rows.append(dict(filter="mean of the three", case="reduction %", where=PRINTED_FUSION_REDUCTION.location,
                     printed=PRINTED_FUSION_REDUCTION.value, printed_value=PRINTED_FUSION_REDUCTION,
                     mc_rmse=float(np.mean([r["mc_rmse"] for r in rows[-3:]])), **_walk_row(mean_reduction, coverage)))
    return rows


#: Why the synthetic walks miss the measured one.
BENIGN_CHANNEL_NOTE = ("the experiment's MLE is better than i.i.d. 6 dB shadowing at alpha 1.8 allows (static CRLB RMS "
                       "over the room about 5 m); the real errors were smaller or more benign, so the synthetic "
                       "ONLY-RSS walks are worse")
_MISS_NOTES = {"ONLY RSS": BENIGN_CHANNEL_NOTE, "RSS/IMU": "the fused filter misses for the same reason as ONLY RSS"}
_REDUCTION_MISS = ("the simulated walks gain more from fusion than the measured one (the measured channel is more "
                   "benign than i.i.d. 6 dB shadowing)")
_KEPT = "kept in the mean over the simulated walks"


def testbed_flags(row: dict, run: ChannelRun, sigma_acc_mps2: float) -> dict | None:
    """The NIS guard's flags behind one :func:`testbed_rows` row, ``{"<filter> ONLY RSS"/"<filter> RSS/IMU":
    DivergenceFlags}``: its own filter and case; both cases for a reduction; every filter of :data:`FILTERS` for
    the mean of the three. None for the MLE (no guard)."""
    if row["filter"] == "static_mle":
        return None
    cases = {"ONLY RSS": [None], "RSS/IMU": [sigma_acc_mps2]}.get(row["case"], [None, sigma_acc_mps2])
    names = FILTERS if row["filter"] not in FILTERS else [row["filter"]]
    return {f"{n} {'ONLY RSS' if c is None else 'RSS/IMU'}": run.divergence[(n, c)] for n in names for c in cases}


@renamed_keyword("noise_reading", "noise_interpretation")
def record_testbed(report, rows: list[dict], run: ChannelRun, sigma_acc_mps2: float, *, start: str = DEFAULT_START,
                   noise_interpretation: str = DEFAULT_NOISE_INTERPRETATION, speed_mps: float = SPEED_MPS) -> None:
    """Record Sec. 5.4's printed single-walk values (Figs. 5.8-5.11) from :func:`testbed_rows`, then the mean of the
    three printed reductions (arithmetic) and the "accuracy 1 m" claim on the best tracking filter.

    Each printed RMSE (and the 15 % reduction) is one measured walk: our value is the mean over simulated walks of
    one walk's value, its standard error the Monte-Carlo one, and 2 sd of single walks the named ambiguity
    (:data:`ONE_WALK_SOURCE`). The MLE row is a ``reproduction``; the filter rows are ``calibrated`` exactly when
    ``run`` used an interpretation fitted to printed output (``start``, ``noise_interpretation``, ``speed_mps`` as run;
    named by :func:`~locbook.scenarios.dogan.calibrated_from_text`), else ``reproduction``. A miss says why
    (:data:`BENIGN_CHANNEL_NOTE`); every note counts the runs the NIS guard flagged (:func:`testbed_flags`). The
    per-filter reductions derived from printed pairs (``printed_value`` None) are table rows only."""
    fitted = calibrated_from_text(start, noise_interpretation, speed_mps=speed_mps)
    for r in rows:
        p = r["printed_value"]
        if p is None:
            continue
        amb = Ambiguity(2 * r["sd_single_walk"], "one measured walk: 2 sd of the value of one simulated walk",
                        ONE_WALK_SOURCE)
        kind = "calibrated" if fitted and r["filter"] != "static_mle" else "reproduction"
        name = (f"test-bed RMSE {r['filter']} {r['case']}, mean of one walk" if r["case"] != "reduction %" else
                "fusion reduction, mean of the three filters, mean of one walk")
        report.number(name, p, r["mean_single_walk"], kind=kind, mc_std_error=r["mc_se"], ambiguity=amb,
                      calibrated_from=fitted if kind == "calibrated" else "",
                      miss_note=_MISS_NOTES.get(r["case"], _REDUCTION_MISS),
                      note=divergence_note("", testbed_flags(r, run, sigma_acc_mps2), averaged=_KEPT))
    report.number("fusion reduction, mean of the three printed pairs (Figs. 5.9-5.11)", PRINTED_FUSION_REDUCTION_CH6,
                  float(np.mean(list(printed_reductions_pct().values()))), kind="arithmetic")
    best = min((r for r in rows if r["case"] in ("ONLY RSS", "RSS/IMU") and r["filter"] != "static_mle"),
               key=lambda r: r["mean_single_walk"])
    printed_best = min(p.value for (name, _), p in PRINTED_TESTBED_RMSE.items() if name != "static_mle")
    a16 = f"not reached in our walks, nor in the thesis's own: its best printed walk is {printed_best:g} m"
    report.number(f"best tracking filter, mean RMSE of one walk ({best['filter']} {best['case']})", PRINTED_ACCURACY,
                  best["mean_single_walk"], kind="claim", relation="<=", mc_std_error=best["mc_se"],
                  miss_note=a16, loose_note=a16,
                  note=divergence_note("", testbed_flags(best, run, sigma_acc_mps2), averaged=_KEPT))
