"""Time the grid Bayes filter and the SIR particle filter on one Ozkaya (2011) table setting.

    python benchmarks/bench_bayes_filters.py [--runs 1000] [--particles 250] [--steps 10] [--loop-runs 50] [--size tiny]

One setting = the mobile-target protocol of Table 7.16 (sigma = 5.2 dB, D = 0.5 m, rt = 10): ``runs``
Monte-Carlo runs, each filtered over ``steps`` recursions, all runs in one vectorized call. Reports seconds per
setting (best of 3), the particle-steps (or cell-steps) per second, and for comparison a per-run Python loop of
the same filter on a subset of runs, scaled to the full count.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402

import locbook as lb  # noqa: E402
from locbook.scenarios import ozkaya as oz  # noqa: E402


def measure(runs: int = 1000, particles: int = 250, steps: int = 10, loop_runs: int = 50, repeat: int = 3) -> list[dict]:
    case = oz.SimCase("sir", "mobile", rt=steps, n_particles=particles)
    truth, rss = oz.simulate_truth_and_rss(case, runs, np.random.default_rng(1))
    readers = oz.readers_for("corners3")
    model = lb.RssModel(readers, lb.PathLossModel(-52.0, 2.3, 5.2, min_distance_m=0.1))
    region = (np.zeros(2), np.array(oz.ROOM_M))
    cells = oz.cell_centres(oz.ROOM_M, 4, 7)

    def sir(r):
        return lb.particle_filter(r, model, np.random.default_rng(2), n_particles=particles, region_m=region)

    def improved(r):
        return lb.particle_filter(r, model, np.random.default_rng(2), n_particles=particles, region_m=region,
                                  resample_threshold=0.5, weight_smoothing="sqrt")

    def grid(r):
        return lb.grid_bayes_filter(r, cells, model, 0.5)

    n = min(loop_runs, runs)
    sub = rss[:n]
    rows = []
    for name, fn, units, unit in [(f"grid Bayes filter ({len(cells)} cells)", grid, len(cells), "cell"),
                                  (f"SIR particle filter ({particles} particles)", sir, particles, "particle"),
                                  (f"improved SIR ({particles} particles)", improved, particles, "particle")]:
        t, _, _ = hx.timed(lambda: fn(rss), repeat)
        t_loop, _, _ = hx.timed(lambda: [fn(sub[i:i + 1]) for i in range(n)])
        rate = runs * steps * units / t
        rows.append(hx.row(name, f"Ozkaya Table 7.16 setting, {runs} runs x {steps} recursions", t,
                           "locbook per-run loop" + ("" if n == runs else f" ({n} runs, scaled)"), t_loop * runs / n,
                           hx.peak_mb(lambda: fn(rss)), f"{rate:.3g} {unit}-steps/s"))
    return rows


def run(size: str = "full") -> list[dict]:
    """The benchmark protocol (benchmarks/run_all.py): full = 1000 runs x 250 particles; tiny = 20 runs x 50."""
    if hx.check_size(size) == "tiny":
        return measure(runs=20, particles=50, loop_runs=4, repeat=1)
    return measure()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--particles", type=int, default=250)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--loop-runs", type=int, default=50)
    ap.add_argument("--size", choices=hx.SIZES, default=None, help="the run(size) preset instead of the options")
    args = ap.parse_args()
    rows = run(args.size) if args.size else measure(args.runs, args.particles, args.steps, args.loop_runs)
    hx.print_rows(rows)


if __name__ == "__main__":
    main()
