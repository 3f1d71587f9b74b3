"""Time the grid Bayes filter and the SIR particle filter on one Ozkaya (2011) table setting.

    python benchmarks/bench_bayes_filters.py [--runs 1000] [--particles 250] [--steps 10] [--loop-runs 50]
    python benchmarks/bench_bayes_filters.py full|tiny

One setting = the mobile-target protocol of Table 7.16 (sigma = 5.2 dB, D = 0.5 m, rt = 10): ``runs``
Monte-Carlo runs, each filtered over ``steps`` recursions, all runs in one vectorized call, against a per-run Python
loop of the same filter on a subset of runs (scaled to the full count), the two alternated in one process
(``hx.compare``: medians of CPU and wall time); the particle-steps (or cell-steps) per CPU second are in the note.
Agreement: the grid filter's posterior means equal the loop's to round-off (1e-9 of the largest coordinate); the
particle filters draw their own random streams, so the mean errors against the truth on the loop's runs must differ
by at most 4 standard errors of the paired per-run difference (at the tiny size's 4 runs, a t-distribution with 3
degrees of freedom: about 3 % of seeds would cross that by chance). Each run of the loop draws from a stream of its
own (``SeedSequence.spawn``), so the per-run differences are independent as the standard error assumes (a shared
seed made it too small: 3.9 standard errors on 400 runs instead of -0.45). Beyond either tolerance the row is a
disagreement.
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
from locbook.scenarios import ozkaya as oz  # noqa: E402


def measure(runs: int = 1000, particles: int = 250, steps: int = 10, loop_runs: int = 50,
            repeats: int = hx.MIN_REPEATS):
    """Rows as each filter finishes: the vectorized call on every run against a per-run loop of the same call on
    the first ``loop_runs`` runs (scaled), alternated. Agreement from the same calls: the grid filter is
    deterministic, so the largest difference of the posterior means (tolerance: round-off, 1e-9 of the largest
    coordinate); the particle filters draw differently per run, so the mean error against the truth of both on the
    loop's runs (tolerance: their paired difference within 4 standard errors, from the loop's runs)."""
    case = oz.SimCase("sir", "mobile", rt=steps, n_particles=particles)
    truth, rss = oz.simulate_truth_and_rss(case, runs, np.random.default_rng(1))
    readers = oz.readers_for("corners3")
    model = lb.RssModel(readers, lb.PathLossModel(-52.0, 2.3, 5.2, min_distance_m=0.1))
    region = (np.zeros(2), np.array(oz.ROOM_M))
    cells = oz.cell_centres(oz.ROOM_M, 4, 7)

    def sir(r, rng):
        return lb.particle_filter(r, model, rng=rng, n_particles=particles, region_m=region).mean

    def improved(r, rng):
        return lb.particle_filter(r, model, rng=rng, n_particles=particles, region_m=region,
                                  resample_threshold=0.5, weight_smoothing="sqrt").mean

    def grid(r, rng):
        return lb.grid_bayes_filter(r, model, cells, 0.5).mean

    n = min(loop_runs, runs)
    sub = rss[:n]
    gc.collect()
    gc.freeze()     # the imported modules' objects out of the collector: the harness collects before every call

    def error_m(mean):
        return float(np.mean(np.linalg.norm(mean - truth[:mean.shape[0]], axis=-1)))

    def same(ours, loop):
        # the same arithmetic on one run or many: round-off, 1e-9 of the largest coordinate (at least 1 m)
        d, tol = float(np.max(np.abs(ours[:n] - loop))), 1e-9 * max(1.0, float(np.max(np.abs(loop))))
        if not d <= tol:
            raise AssertionError(f"max |mean - per-run loop| {d:.1e} m > {tol:.1e} m (round-off)")
        return f"max |mean - per-run loop| {d:.1e} m (tolerance {tol:.0e} m)"

    def accuracy(ours, loop):
        # own random streams: the per-run differences of the mean error on the loop's runs (paired on the same
        # readings) are Monte-Carlo noise; their mean must stay within 4 standard errors (from these n differences)
        # plus a round-off floor (every run of the loop has its own stream, so the differences are independent)
        diff = (np.linalg.norm(ours[:n] - truth[:n], axis=-1).mean(-1)
                - np.linalg.norm(loop - truth[:n], axis=-1).mean(-1))
        se = float(diff.std(ddof=1) / np.sqrt(n))
        text = (f"mean error {error_m(ours):.3f} m over {runs} runs, {error_m(ours[:n]):.3f} m on the loop's {n} "
                f"runs, per-run loop {error_m(loop):.3f} m (own random streams): difference {diff.mean():+.3f} m, "
                f"standard error {se:.3f} m")
        if not abs(diff.mean()) <= 4 * se + 1e-9:
            raise AssertionError(f"{text}: beyond 4 standard errors")
        return text

    for name, fn, units, unit, agree in [
            (f"grid Bayes filter ({len(cells)} cells)", grid, len(cells), "cell", same),
            (f"SIR particle filter ({particles} particles)", sir, particles, "particle", accuracy),
            (f"improved SIR ({particles} particles)", improved, particles, "particle", accuracy)]:
        fn(rss[:2], np.random.default_rng(0))     # compiled kernels compiled or loaded before the timed calls
        # the vectorized call draws one stream for all runs; the loop gives each run a stream of its own
        m = hx.compare(lambda: fn(rss, np.random.default_rng(2)),
                       lambda: np.concatenate([fn(sub[i:i + 1], np.random.default_rng(seed)) for i, seed in
                                               enumerate(np.random.SeedSequence(3).spawn(n))]),
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
