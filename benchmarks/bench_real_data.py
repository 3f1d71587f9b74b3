"""Time and peak memory of every method on the measured data of Kolakowski (2021) (CC BY 4.0, shipped with
locbook; attribution in locbook/data/datasets/kolakowski2021/README.md).

    python benchmarks/bench_real_data.py [full|tiny]
    python benchmarks/bench_real_data.py [--spacing 0.1] [--particles 3000] [--knn-queries 10000] [--dense-check]

Each method runs on the real inputs (the calibration set for the fits, the 719-epoch robot drive for the
estimators, the drive on its 1/3 s clock for the trackers), 5 times (``hx.repeat``: medians of CPU and wall time;
peak resident memory of each call); the many k-NN queries, the Huber fit and the particle filter once
(``hx.once``). No reference: the figure beside the
time is the mean error against the robot's truth, from the timed calls. It has no tolerance: nothing independent
says what error a method must reach on these measurements (the data's authors print no figure for our methods, and
a bound such as the CRLB assumes the model these readings only approximate), so it is shown, not checked. The grid Bayes
filter is shown on the flat at ``--spacing`` with the separable transition; ``--dense-check`` also runs the dense C x C
transition (its matrix alone is 8 C^2 bytes) for comparison. The k-NN radio map is the 4,104 calibration points;
``--knn-queries`` (10,000 at full size: 100,000 took 12 s) repeats the drive's queries to show that its memory stays
bounded (64 MiB blocks) whatever the batch.
"""
from __future__ import annotations

import argparse
import gc
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402
import locbook as lb  # noqa: E402
from locbook.scenarios import measured as ko  # noqa: E402


def measure(spacing: float = 0.1, particles: int = 3000, knn_queries: int = 10_000, dense_check: bool = False,
            cvxpy_fits: bool = True, repeats: int = hx.MIN_REPEATS):
    """Rows as each method finishes: ``hx.repeat`` (``repeats`` calls, medians) for every method, ``hx.once`` for the
    many k-NN queries, the Huber fit and the particle filter (for every method when ``repeats`` is 1); the mean error
    against the robot's truth from the timed calls."""
    data = ko.load("kolakowski2021")
    epoch_s = ko.epoch_s(data, "robot")
    fit = ko.calibrate(data)
    model = ko.channel(fit)
    drive = ko.TestEpochs.of(data, "robot")
    rss, truth = drive.rss_dbm, drive.truth_m
    anchors, h = data.anchors_m, data.tag_height_m
    grid = lb.grid_in_outline(data.outline_m, spacing)
    lower, upper = lb.outline_box(data.outline_m)
    ranges = model.range_m(rss)
    cells, fingerprints, _ = ko.radio_map(data, model)
    reg, ticks = lb.regular_epochs(data.epochs("robot"), epoch_s, tolerance_s=0.1 * epoch_s)
    bayes_model = ko.bayes_measurement_model(data, model)
    fix_cov = ko.fix_covariance_from_calibration(data, model, grid_spacing_m=0.1)
    motion = lb.constant_velocity(epoch_s, 0.05)
    x0, P0 = np.r_[truth[0], 0.0, 0.0], np.diag([4.0, 4.0, 1.0, 1.0])
    stream = lb.RssMeasurement(reg.rss_dbm, anchors, model, np.array([0, 1]), tag_height_m=h)
    queries = np.resize(rss, (knn_queries, rss.shape[1]))
    ml_fixes = np.full((len(reg.time_s), 2), np.nan)             # the KF's input: RSS-ML fixes on the clock
    rss_model = lb.RssModel(anchors, model, tag_height_m=h)      # the static estimators' model
    grid_fixes = lb.grid_ml_position(rss, rss_model, grid).position_m
    ml_fixes[ticks] = lb.rss_ml_position(rss, rss_model, grid_fixes).position_m

    cases = [("fit per anchor (closed form)", "4,104 points x 6 anchors", lambda: ko.calibrate(data), None)]
    if cvxpy_fits:
        cases += [("fit per anchor (bounded, cvxpy)", "4,104 points x 6 anchors",
                   lambda: ko.calibrate(data, fit="bounded"), None),
                  ("fit per anchor (Huber, cvxpy)", "4,104 points x 6 anchors",
                   lambda: ko.calibrate(data, fit="huber"), "once")]
    cases += [
        ("LLS", "719 epochs", lambda: lb.lateration_ls(anchors, ranges, tag_height_m=h).position_m, "fix"),
        ("box-LS", "719 epochs", lambda: lb.lateration_box_ls(anchors, ranges, lower, upper,
                                                                                tag_height_m=h).position_m, "fix"),
        (f"grid ML ({spacing} m)", f"719 epochs x {len(grid)} cells",
         lambda: lb.grid_ml_position(rss, rss_model, grid).position_m, "fix"),
        ("RSS ML (LM from grid ML)", "719 epochs",
         lambda: lb.rss_ml_position(rss, rss_model, lb.grid_ml_position(rss, rss_model, grid).position_m).position_m,
         "fix"),
        ("k-NN (k = 5)", f"719 epochs x {len(cells)} map points",
         lambda: lb.knn_position(rss, fingerprints, cells, 5), "fix"),
        ("k-NN (k = 5), many queries", f"{knn_queries:,} queries x {len(cells)} map points",
         lambda: lb.knn_position(queries, fingerprints, cells, 5), "once"),
        ("KF on ML fixes", f"{len(reg.time_s)} ticks",
         lambda: lb.extended_kalman_filter(motion.F, motion.Q, x0, P0, [lb.LinearMeasurement(
             ml_fixes, np.hstack([np.eye(2), np.zeros((2, 2))]), fix_cov)]).mean[ticks, :2], "fix"),
        ("EKF (parallel RSS update)", f"{len(reg.time_s)} ticks",
         lambda: lb.extended_kalman_filter(motion.F, motion.Q, x0, P0, [stream]).mean[ticks, :2], "fix"),
        ("UKF", f"{len(reg.time_s)} ticks",
         lambda: lb.unscented_kalman_filter(motion.F, motion.Q, x0, P0, [stream], alpha=0.5).mean[ticks, :2], "fix"),
        (f"particle filter ({particles} particles)", f"{len(reg.time_s)} ticks, 1 run",
         lambda: lb.particle_filter(reg.rss_dbm[None], bayes_model, rng=np.random.default_rng(1), n_particles=particles,
                                    region_m=(lower, upper), spread_m=0.3, resample_threshold=0.5).mean[0, ticks],
         "fix once"),
        (f"grid Bayes, separable ({spacing} m)", f"{len(reg.time_s)} ticks x {len(grid)} cells",
         lambda: lb.grid_bayes_filter(reg.rss_dbm[None], bayes_model, grid, 0.3).mean[0, ticks], "fix"),
    ]
    if dense_check:
        cases.append((f"grid Bayes, dense ({spacing} m)", f"{len(reg.time_s)} ticks x {len(grid)} cells",
                      lambda: lb.grid_bayes_filter(reg.rss_dbm[None], bayes_model, grid, 0.3,
                                                   transition="dense").mean[0, ticks], "fix"))
    gc.collect()
    gc.freeze()     # the imported modules' objects out of the collector: the harness collects before every call
    # compiled kernels (numba) compiled or loaded from their cache on 3 ticks, so no timed call (and no peak) holds
    # a compilation
    short = lb.RssMeasurement(reg.rss_dbm[:3], anchors, model, np.array([0, 1]), tag_height_m=h)
    lb.extended_kalman_filter(motion.F, motion.Q, x0, P0, [short])
    lb.unscented_kalman_filter(motion.F, motion.Q, x0, P0, [short], alpha=0.5)
    lb.particle_filter(reg.rss_dbm[None, :3], bayes_model, rng=np.random.default_rng(1), n_particles=50,
                       region_m=(lower, upper), spread_m=0.3, resample_threshold=0.5)
    lb.grid_bayes_filter(reg.rss_dbm[None, :3], bayes_model, grid, 0.3)

    def error(out):
        return f"mean error {np.nanmean(np.linalg.norm(out - truth, axis=-1)):.2f} m"

    for name, workload, fn, kind in cases:
        kind = kind or ""
        agree = error if kind.startswith("fix") else None
        once = kind.endswith("once") or repeats == 1
        m = hx.once(fn, agree=agree) if once else hx.repeat(fn, repeats=repeats, agree=agree)
        yield hx.row(name, f"Kolakowski 2021, {workload}", m, note="no reference")


def run(size: str = "full"):
    """The benchmark protocol (benchmarks/run_all.py): full = 0.1 m grid, 3,000 particles, 10,000 k-NN queries
    (timed once); tiny = 0.5 m grid, 300 particles, 2,000 queries, without the cvxpy fits."""
    if hx.check_size(size) == "tiny":
        return measure(spacing=0.5, particles=300, knn_queries=2_000, cvxpy_fits=False)
    return measure()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("size", nargs="?", choices=hx.SIZES, default=None, help="the run(size) preset")
    ap.add_argument("--spacing", type=float, default=0.1)
    ap.add_argument("--particles", type=int, default=3000)
    ap.add_argument("--knn-queries", type=int, default=10_000)
    ap.add_argument("--dense-check", action="store_true")
    args = ap.parse_args()
    hx.print_rows(run(args.size) if args.size else measure(args.spacing, args.particles, args.knn_queries,
                                                           args.dense_check))


if __name__ == "__main__":
    main()
