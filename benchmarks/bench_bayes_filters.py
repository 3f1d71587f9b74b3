"""Time the grid Bayes filter and the SIR particle filter on one Ozkaya (2011) table setting.

    python benchmarks/bench_bayes_filters.py [--runs 1000] [--particles 250] [--steps 10]

One setting = the mobile-target protocol of Table 7.16 (sigma = 5.2 dB, D = 0.5 m, rt = 10): ``runs``
Monte-Carlo runs, each filtered over ``steps`` recursions, all runs in one vectorized call. Prints seconds per
setting (best of 3), the particle-steps (or cell-steps) per second, and for comparison a per-run Python loop of
the same filter on a subset of runs, scaled to the full count.
"""
import argparse
import time

import numpy as np

import locbook as lb
from locbook.scenarios import ozkaya as oz


def timed(fn, repeat=3):
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--particles", type=int, default=250)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--loop-runs", type=int, default=50)
    args = ap.parse_args()
    case = oz.SimCase("sir", "mobile", rt=args.steps, n_particles=args.particles)
    truth, rss = oz.simulate_truth_and_rss(case, args.runs, np.random.default_rng(1))
    readers = oz.readers_for("corners3")
    model = lb.RssMeasurementModel(readers, -52.0, 2.3, 5.2)
    region = (np.zeros(2), np.array(oz.ROOM_M))
    cells = oz.cell_centres(oz.ROOM_M, 4, 7)

    def sir(r):
        return lb.particle_filter(r, model, np.random.default_rng(2), n_particles=args.particles, region_m=region)

    def improved(r):
        return lb.particle_filter(r, model, np.random.default_rng(2), n_particles=args.particles, region_m=region,
                                  resample_threshold=0.5, weight_smoothing="sqrt")

    def grid(r):
        return lb.grid_bayes_filter(r, cells, model, 0.5)

    print(f"one setting: {args.runs} runs x {args.steps} recursions; {args.particles} particles; {len(cells)} cells")
    for name, fn, units in [("grid Bayes (28 cells)", grid, len(cells)), ("SIR", sir, args.particles),
                            ("improved SIR", improved, args.particles)]:
        t = timed(lambda: fn(rss))
        sub = rss[: args.loop_runs]
        t_loop = timed(lambda: [fn(sub[i:i + 1]) for i in range(sub.shape[0])], repeat=1) * args.runs / args.loop_runs
        rate = args.runs * args.steps * units / t
        print(f"{name:22s} vectorized {t:7.3f} s/setting  {rate:11.3e} {'cell' if 'grid' in name else 'particle'}-steps/s"
              f"   per-run loop {t_loop:7.2f} s (extrapolated from {args.loop_runs} runs)  speed-up {t_loop / t:5.1f}x")


if __name__ == "__main__":
    main()
