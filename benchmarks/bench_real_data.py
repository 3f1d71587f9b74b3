"""Time and peak memory of every method on the measured data of Kolakowski (2021) (CC BY 4.0, shipped with
locbook; attribution in locbook/data/measured/kolakowski2021/README.md).

    python benchmarks/bench_real_data.py [--spacing 0.1] [--particles 5000] [--dense-check]

Each method runs once on the real inputs (the calibration set for the fits, the 719-epoch robot drive for the
estimators, the drive on its 1/3 s clock for the trackers). Peak memory is the largest block of memory the call
held at once, measured by ``tracemalloc`` (numpy's arrays are included). The grid Bayes filter is shown on the flat
at ``--spacing`` with the separable transition; ``--dense-check`` also runs the dense C x C transition (its matrix
alone is 8 C^2 bytes) for comparison. The k-NN radio map is the 4,104 calibration points; ``--knn-queries``
repeats the drive's queries to show that its memory stays bounded (64 MiB blocks) whatever the batch.
"""
import argparse
import time
import tracemalloc

import numpy as np

import locbook as lb
from locbook.scenarios import kolakowski as ko


def measure(fn):
    tracemalloc.start()
    t = time.perf_counter()
    out = fn()
    seconds = time.perf_counter() - t
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return out, seconds, peak / 2**20


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--spacing", type=float, default=0.1)
    ap.add_argument("--particles", type=int, default=5000)
    ap.add_argument("--knn-queries", type=int, default=100_000)
    ap.add_argument("--dense-check", action="store_true")
    args = ap.parse_args()
    data = ko.load()
    fit = ko.calibrate(data)
    model = ko.channel(fit)
    drive = ko.Drive.of(data)
    rss, truth = drive.rss_dbm, drive.truth_m
    anchors, h = data.anchors_m, ko.TAG_HEIGHT_M
    grid = lb.grid_in_outline(data.outline_m, args.spacing)
    lower, upper = lb.outline_box(data.outline_m)
    ranges = model.range_m(rss)
    cells, fingerprints, _ = ko.radio_map(data, model)
    reg, ticks = lb.regular_epochs(data.epochs("robot"), ko.EPOCH_S, tolerance_s=0.1 * ko.EPOCH_S)
    bayes_model = ko.bayes_measurement_model(data, model)
    fix_cov = ko.fix_covariance_from_calibration(data, model)
    motion = lb.constant_velocity(ko.EPOCH_S, 0.05)
    x0, P0 = np.r_[truth[0], 0.0, 0.0], np.diag([4.0, 4.0, 1.0, 1.0])
    stream = lb.RssMeasurement(reg.rss_dbm, anchors, model, np.array([0, 1]), tag_height_m=h)
    queries = np.resize(rss, (args.knn_queries, rss.shape[1]))
    ml_fixes = np.full((len(reg.time_s), 2), np.nan)             # the KF's input: RSS-ML fixes on the clock
    ml_fixes[ticks] = lb.rss_ml_position(anchors, rss, model, lb.grid_ml_position(anchors, rss, model, grid,
                                                                                   tag_height_m=h).position_m,
                                         tag_height_m=h).position_m

    cases = [
        ("fit per anchor (closed form)", "4,104 points x 6 anchors", lambda: ko.calibrate(data), None),
        ("fit per anchor (bounded, cvxpy)", "4,104 points x 6 anchors", lambda: ko.calibrate(data, fit="bounded"), None),
        ("fit per anchor (Huber, cvxpy)", "4,104 points x 6 anchors", lambda: ko.calibrate(data, fit="huber"), None),
        ("LLS", "719 epochs", lambda: lb.lateration_ls(anchors, ranges, tag_height_m=h).position_m, "fix"),
        ("box-LS (cvxpy, stacked)", "719 epochs", lambda: lb.lateration_box_ls(anchors, ranges, lower, upper,
                                                                                tag_height_m=h).position_m, "fix"),
        (f"grid ML ({args.spacing} m)", f"719 epochs x {len(grid)} cells",
         lambda: lb.grid_ml_position(anchors, rss, model, grid, tag_height_m=h).position_m, "fix"),
        ("RSS ML (LM from grid ML)", "719 epochs",
         lambda: lb.rss_ml_position(anchors, rss, model, lb.grid_ml_position(anchors, rss, model, grid, tag_height_m=h)
                                    .position_m, tag_height_m=h).position_m, "fix"),
        ("k-NN (k = 5)", f"719 epochs x {len(cells)} map points", lambda: lb.knn_position(rss, fingerprints, cells, 5), "fix"),
        ("k-NN (k = 5), many queries", f"{args.knn_queries:,} queries x {len(cells)} map points",
         lambda: lb.knn_position(queries, fingerprints, cells, 5), None),
        ("KF on ML fixes", f"{len(reg.time_s)} ticks",
         lambda: lb.extended_kalman_filter(motion.F, motion.Q, x0, P0, [lb.LinearMeasurement(
             ml_fixes, np.hstack([np.eye(2), np.zeros((2, 2))]), fix_cov)]).x[ticks, :2], "fix"),
        ("EKF (parallel RSS update)", f"{len(reg.time_s)} ticks",
         lambda: lb.extended_kalman_filter(motion.F, motion.Q, x0, P0, [stream]).x[ticks, :2], "fix"),
        ("UKF", f"{len(reg.time_s)} ticks",
         lambda: lb.unscented_kalman_filter(motion.F, motion.Q, x0, P0, [stream], alpha=0.5).x[ticks, :2], "fix"),
        (f"particle filter ({args.particles} particles)", f"{len(reg.time_s)} ticks, 1 run",
         lambda: lb.particle_filter(reg.rss_dbm[None], bayes_model, np.random.default_rng(1), n_particles=args.particles,
                                    region_m=(lower, upper), spread_m=0.3, resample_threshold=0.5).mmse_m[0, ticks], "fix"),
        (f"grid Bayes, separable ({args.spacing} m)", f"{len(reg.time_s)} ticks x {len(grid)} cells",
         lambda: lb.grid_bayes_filter(reg.rss_dbm[None], grid, bayes_model, 0.3).mmse_m[0, ticks], "fix"),
    ]
    if args.dense_check:
        cases.append((f"grid Bayes, dense ({args.spacing} m)", f"{len(reg.time_s)} ticks x {len(grid)} cells",
                      lambda: lb.grid_bayes_filter(reg.rss_dbm[None], grid, bayes_model, 0.3,
                                                   transition="dense").mmse_m[0, ticks], "fix"))
    print(f"Kolakowski (2021) measured data; grid {args.spacing} m = {len(grid)} cells inside the outline "
          f"(a dense transition would be {8 * len(grid) ** 2 / 2**20:.0f} MiB)")
    print(f"{'method':38s} {'workload':34s} {'time (s)':>9s} {'peak (MiB)':>11s} {'mean error (m)':>15s}")
    for name, workload, fn, kind in cases:
        out, seconds, peak = measure(fn)
        err = f"{np.nanmean(np.linalg.norm(out - truth, axis=-1)):.2f}" if kind == "fix" else ""
        print(f"{name:38s} {workload:34s} {seconds:9.3f} {peak:11.1f} {err:>15s}")


if __name__ == "__main__":
    main()
