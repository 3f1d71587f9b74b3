"""Speed of Palvai 2008's estimators in locbook.

    python benchmarks/bench_palvai.py [--runs 10000] [--pf-runs 100] [--particles 10000] [--iterations 100] [--size tiny]

1. Batch LS and RLS over ``runs`` Monte-Carlo problems (50 locations in 3-D) in one vectorized call, against a per-run
   loop (numpy lstsq per run; a Python RLS loop per run on a subset, scaled): times and ratios.
2. The SIR particle filter, ``pf-runs`` runs x ``particles`` particles x ``iterations`` iterations at 25 locations
   (schedule 'all'): time and peak memory (tracemalloc).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402

import locbook as lb  # noqa: E402
from locbook.scenarios import palvai as pv  # noqa: E402


def _rls_loop(H, Y, runs):
    for r in range(runs):
        x, P = np.zeros(3), 1e6 * np.eye(3)
        for k in range(H.shape[1]):
            h = H[r, k]
            ph = P @ h
            g = ph / (1 + h @ ph)
            x = x + g * (Y[r, k] - h @ x)
            P = P - np.outer(g, ph)


def measure(runs: int = 10_000, pf_runs: int = 100, particles: int = 10_000, iterations: int = 100,
            repeat: int = 3) -> list[dict]:
    rng = np.random.default_rng(0)
    setup = pv.Setup()
    loc = pv.draw_locations(runs, 50, 3, rng)
    d = setup.channel.range_m(pv.measure(setup, loc, rng))
    rows = []
    workload = f"{runs:,} problems, 50 locations, 3-D"
    t_batch, _, batch = hx.timed(lambda: lb.lateration_ls(loc, d, pairs="consecutive").position_m, repeat)
    H, Y = lb.lateration_system(loc, d, pairs="consecutive")
    t_loop, _, loop = hx.timed(lambda: np.stack([np.linalg.lstsq(H[r], Y[r], rcond=None)[0] for r in range(runs)]))
    rows.append(hx.row("batch LS (Palvai)", workload, t_batch, "numpy lstsq per-run loop", t_loop,
                       hx.peak_mb(lambda: lb.lateration_ls(loc, d, pairs="consecutive")),
                       f"max difference {np.nanmax(np.abs(batch - loop)):.1e} m"))
    t_rls, _, rls = hx.timed(lambda: lb.recursive_least_squares(H, Y).x[:, -1], repeat)
    sub = min(runs, 500)
    t0 = time.perf_counter()
    _rls_loop(H, Y, sub)
    t_rls_loop = (time.perf_counter() - t0) * runs / sub
    rows.append(hx.row("RLS (Palvai)", workload, t_rls, "Python RLS per-run loop" + (f" ({sub} runs, scaled)"
                                                                                    if sub < runs else ""),
                       t_rls_loop, hx.peak_mb(lambda: lb.recursive_least_squares(H, Y)),
                       f"max difference to batch LS {np.nanmax(np.abs(rls - batch)):.1e} m"))
    s25 = pv.Setup(receiver_sigma_m=pv.SIGMA3_M)
    loc = pv.draw_locations(pf_runs, 25, 3, rng)
    z = pv.measure(s25, loc, rng)
    observed = pv.observed_locations(s25, loc, rng)

    def pf():
        return pv.pf_run(s25, observed, z, np.random.default_rng(5), n_particles=particles, n_iterations=iterations)

    t_pf, _, res = hx.timed(pf)
    rows.append(hx.row("SIR particle filter (Palvai)",
                       f"{pf_runs} runs x {particles:,} particles x {iterations} iterations, 25 locations", t_pf,
                       peak=hx.peak_mb(pf),
                       note=f"mean error {pv.errors_m(res.mean_m[:, -1], s25.target).mean():.2f} m; no reference"))
    return rows


def run(size: str = "full") -> list[dict]:
    """The benchmark protocol (benchmarks/run_all.py): full = 10,000 problems and a 100 x 10,000 x 100 particle filter;
    tiny = 300 problems and 2 x 500 x 5."""
    if hx.check_size(size) == "tiny":
        return measure(runs=300, pf_runs=2, particles=500, iterations=5, repeat=1)
    return measure()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=10_000)
    ap.add_argument("--pf-runs", type=int, default=100)
    ap.add_argument("--particles", type=int, default=10_000)
    ap.add_argument("--iterations", type=int, default=100)
    ap.add_argument("--size", choices=hx.SIZES, default=None, help="the run(size) preset instead of the options")
    args = ap.parse_args()
    rows = run(args.size) if args.size else measure(args.runs, args.pf_runs, args.particles, args.iterations)
    hx.print_rows(rows)


if __name__ == "__main__":
    main()
