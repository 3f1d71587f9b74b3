"""Time the grid Bayes filter and the SIR particle filter on one Ozkaya (2011) table setting.

    python benchmarks/bench_bayes_filters.py [--runs 1000] [--particles 250] [--steps 10] [--loop-runs 50]
    python benchmarks/bench_bayes_filters.py full|tiny

One setting = the mobile-target protocol of Table 7.16 (sigma = 5.2 dB, D = 0.5 m, rt = 10): ``runs``
Monte-Carlo runs, each filtered over ``steps`` recursions, all runs in one vectorized call, against a per-run Python
loop of the same filter on a subset of runs (scaled to the full count), the two alternated in one process
(``hx.compare``: medians of CPU and wall time); the particle-steps (or cell-steps) per CPU second are in the note.
"""
from __future__ import annotations

import gc
import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402

import locbook as lb  # noqa: E402
from locbook.scenarios import ozkaya as oz  # noqa: E402


def measure(runs: int = 1000, particles: int = 250, steps: int = 10, loop_runs: int = 50,
            repeats: int = hx.MIN_REPEATS):
    """Rows as each filter finishes: the vectorized call on every run against a per-run loop of the same call on
    the first ``loop_runs`` runs (scaled), alternated. Agreement from the same calls: the grid filter is
    deterministic, so the largest difference of the posterior means; the particle filters draw differently per run,
    so the mean error against the truth of both on the loop's runs."""
    case = oz.SimCase("sir", "mobile", rt=steps, n_particles=particles)
    truth, rss = oz.simulate_truth_and_rss(case, runs, np.random.default_rng(1))
    readers = oz.readers_for("corners3")
    model = lb.RssModel(readers, lb.PathLossModel(-52.0, 2.3, 5.2, min_distance_m=0.1))
    region = (np.zeros(2), np.array(oz.ROOM_M))
    cells = oz.cell_centres(oz.ROOM_M, 4, 7)

    def sir(r):
        return lb.particle_filter(r, model, np.random.default_rng(2), n_particles=particles, region_m=region).mean_m

    def improved(r):
        return lb.particle_filter(r, model, np.random.default_rng(2), n_particles=particles, region_m=region,
                                  resample_threshold=0.5, weight_smoothing="sqrt").mean_m

    def grid(r):
        return lb.grid_bayes_filter(r, cells, model, 0.5).mean_m

    n = min(loop_runs, runs)
    sub = rss[:n]
    gc.collect()
    gc.freeze()     # the imported modules' objects out of the collector: the harness collects before every call

    def error_m(mean):
        return float(np.mean(np.linalg.norm(mean - truth[:mean.shape[0]], axis=-1)))

    def same(ours, loop):
        return f"max |mean - per-run loop| {np.max(np.abs(ours[:n] - loop)):.1e} m"

    def accuracy(ours, loop):
        return (f"mean error {error_m(ours):.3f} m over {runs} runs, {error_m(ours[:n]):.3f} m on the loop's {n} "
                f"runs, per-run loop {error_m(loop):.3f} m (own random streams)")

    for name, fn, units, unit, agree in [
            (f"grid Bayes filter ({len(cells)} cells)", grid, len(cells), "cell", same),
            (f"SIR particle filter ({particles} particles)", sir, particles, "particle", accuracy),
            (f"improved SIR ({particles} particles)", improved, particles, "particle", accuracy)]:
        fn(rss[:2])     # compiled kernels (numba) compiled or loaded from their cache before the timed calls
        m = hx.compare(lambda: fn(rss), lambda: np.concatenate([fn(sub[i:i + 1]) for i in range(n)]),
                       repeats=repeats, reference_scale=runs / n, agree=agree)
        rate = runs * steps * units / m.locbook_cpu_s
        yield hx.row(name, f"Ozkaya Table 7.16 setting, {runs} runs x {steps} recursions", m,
                     "locbook per-run loop" + ("" if n == runs else f" ({n} of {runs} runs, scaled)"),
                     note=f"{rate:.3g} {unit}-steps per CPU second")


def run(size: str = "full"):
    """The benchmark protocol (benchmarks/run_all.py): full = 1000 runs x 250 particles (loop on 50 runs); tiny =
    20 runs x 50 particles (loop on 4)."""
    if hx.check_size(size) == "tiny":
        return measure(runs=20, particles=50, loop_runs=4)
    return measure()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("size", nargs="?", choices=hx.SIZES, default=None, help="the run(size) preset")
    ap.add_argument("--runs", type=int, default=1000)
    ap.add_argument("--particles", type=int, default=250)
    ap.add_argument("--steps", type=int, default=10)
    ap.add_argument("--loop-runs", type=int, default=50)
    args = ap.parse_args()
    hx.print_rows(run(args.size) if args.size else measure(args.runs, args.particles, args.steps, args.loop_runs))


if __name__ == "__main__":
    main()
