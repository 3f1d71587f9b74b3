"""Time and peak memory of every method on the measured data of Kolakowski (2021) (CC BY 4.0, shipped with
locbook; attribution in locbook/data/datasets/kolakowski2021/README.md).

    python benchmarks/bench_real_data.py [--spacing 0.1] [--particles 5000] [--knn-queries 100000] [--dense-check]
                                         [--size tiny]

Each method runs once on the real inputs (the calibration set for the fits, the 719-epoch robot drive for the
estimators, the drive on its 1/3 s clock for the trackers). Peak memory is the largest block of memory the call
held at once, measured by ``tracemalloc`` (numpy's arrays are included) in a second call. The grid Bayes filter is
shown on the flat at ``--spacing`` with the separable transition; ``--dense-check`` also runs the dense C x C
transition (its matrix alone is 8 C^2 bytes) for comparison. The k-NN radio map is the 4,104 calibration points;
``--knn-queries`` repeats the drive's queries to show that its memory stays bounded (64 MiB blocks) whatever the batch.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402

import locbook as lb  # noqa: E402
from locbook.scenarios import measured as ko  # noqa: E402


def measure(spacing: float = 0.1, particles: int = 5000, knn_queries: int = 100_000, dense_check: bool = False,
            cvxpy_fits: bool = True) -> list[dict]:
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
    fix_cov = ko.fix_covariance_from_calibration(data, model)
    motion = lb.constant_velocity(epoch_s, 0.05)
    x0, P0 = np.r_[truth[0], 0.0, 0.0], np.diag([4.0, 4.0, 1.0, 1.0])
    stream = lb.RssMeasurement(reg.rss_dbm, anchors, model, np.array([0, 1]), tag_height_m=h)
    queries = np.resize(rss, (knn_queries, rss.shape[1]))
    ml_fixes = np.full((len(reg.time_s), 2), np.nan)             # the KF's input: RSS-ML fixes on the clock
    ml_fixes[ticks] = lb.rss_ml_position(anchors, rss, model, lb.grid_ml_position(anchors, rss, model, grid,
                                                                                   tag_height_m=h).position_m,
                                         tag_height_m=h).position_m

    cases = [("fit per anchor (closed form)", "4,104 points x 6 anchors", lambda: ko.calibrate(data), None)]
    if cvxpy_fits:
        cases += [("fit per anchor (bounded, cvxpy)", "4,104 points x 6 anchors", lambda: ko.calibrate(data, fit="bounded"),
                   None),
                  ("fit per anchor (Huber, cvxpy)", "4,104 points x 6 anchors", lambda: ko.calibrate(data, fit="huber"),
                   None)]
    cases += [
        ("LLS", "719 epochs", lambda: lb.lateration_ls(anchors, ranges, tag_height_m=h).position_m, "fix"),
        ("box-LS", "719 epochs", lambda: lb.lateration_box_ls(anchors, ranges, lower, upper,
                                                                                tag_height_m=h).position_m, "fix"),
        (f"grid ML ({spacing} m)", f"719 epochs x {len(grid)} cells",
         lambda: lb.grid_ml_position(anchors, rss, model, grid, tag_height_m=h).position_m, "fix"),
        ("RSS ML (LM from grid ML)", "719 epochs",
         lambda: lb.rss_ml_position(anchors, rss, model, lb.grid_ml_position(anchors, rss, model, grid, tag_height_m=h)
                                    .position_m, tag_height_m=h).position_m, "fix"),
        ("k-NN (k = 5)", f"719 epochs x {len(cells)} map points", lambda: lb.knn_position(rss, fingerprints, cells, 5), "fix"),
        ("k-NN (k = 5), many queries", f"{knn_queries:,} queries x {len(cells)} map points",
         lambda: lb.knn_position(queries, fingerprints, cells, 5), None),
        ("KF on ML fixes", f"{len(reg.time_s)} ticks",
         lambda: lb.extended_kalman_filter(motion.F, motion.Q, x0, P0, [lb.LinearMeasurement(
             ml_fixes, np.hstack([np.eye(2), np.zeros((2, 2))]), fix_cov)]).x[ticks, :2], "fix"),
        ("EKF (parallel RSS update)", f"{len(reg.time_s)} ticks",
         lambda: lb.extended_kalman_filter(motion.F, motion.Q, x0, P0, [stream]).x[ticks, :2], "fix"),
        ("UKF", f"{len(reg.time_s)} ticks",
         lambda: lb.unscented_kalman_filter(motion.F, motion.Q, x0, P0, [stream], alpha=0.5).x[ticks, :2], "fix"),
        (f"particle filter ({particles} particles)", f"{len(reg.time_s)} ticks, 1 run",
         lambda: lb.particle_filter(reg.rss_dbm[None], bayes_model, np.random.default_rng(1), n_particles=particles,
                                    region_m=(lower, upper), spread_m=0.3, resample_threshold=0.5).mean_m[0, ticks], "fix"),
        (f"grid Bayes, separable ({spacing} m)", f"{len(reg.time_s)} ticks x {len(grid)} cells",
         lambda: lb.grid_bayes_filter(reg.rss_dbm[None], grid, bayes_model, 0.3).mean_m[0, ticks], "fix"),
    ]
    if dense_check:
        cases.append((f"grid Bayes, dense ({spacing} m)", f"{len(reg.time_s)} ticks x {len(grid)} cells",
                      lambda: lb.grid_bayes_filter(reg.rss_dbm[None], grid, bayes_model, 0.3,
                                                   transition="dense").mean_m[0, ticks], "fix"))
    rows = []
    for name, workload, fn, kind in cases:
        seconds, _, out = hx.timed(fn)
        err = f"mean error {np.nanmean(np.linalg.norm(out - truth, axis=-1)):.2f} m; " if kind == "fix" else ""
        rows.append(hx.row(name, f"Kolakowski 2021, {workload}", seconds, peak=hx.peak_mb(fn),
                           note=f"{err}no reference"))
    return rows


def run(size: str = "full") -> list[dict]:
    """The benchmark protocol (benchmarks/run_all.py): full = 0.1 m grid, 5,000 particles, 100,000 k-NN queries;
    tiny = 0.5 m grid, 300 particles, 2,000 queries, without the cvxpy fits."""
    if hx.check_size(size) == "tiny":
        return measure(spacing=0.5, particles=300, knn_queries=2_000, cvxpy_fits=False)
    return measure()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--spacing", type=float, default=0.1)
    ap.add_argument("--particles", type=int, default=5000)
    ap.add_argument("--knn-queries", type=int, default=100_000)
    ap.add_argument("--dense-check", action="store_true")
    ap.add_argument("--size", choices=hx.SIZES, default=None, help="the run(size) preset instead of the options")
    args = ap.parse_args()
    hx.print_rows(run(args.size) if args.size else measure(args.spacing, args.particles, args.knn_queries,
                                                           args.dense_check))


if __name__ == "__main__":
    main()
