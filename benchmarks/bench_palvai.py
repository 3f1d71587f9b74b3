"""Speed of Palvai 2008's estimators in locbook.

    python benchmarks/bench_palvai.py [--runs 10000] [--pf-runs 100] [--particles 10000] [--iterations 100]

1. Batch LS and RLS over ``runs`` Monte-Carlo problems (50 locations in 3-D) in one vectorized call, against a per-run
   loop (numpy lstsq per run; a Python RLS loop per run on a subset, scaled): times and ratios.
2. The SIR particle filter, ``pf-runs`` runs x ``particles`` particles x ``iterations`` iterations at 25 locations
   (schedule 'all'): time and peak memory of the Python process (tracemalloc).
"""
import argparse
import time
import tracemalloc

import numpy as np

import locbook as lb
from locbook.scenarios import palvai as pv


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--runs", type=int, default=10_000)
    ap.add_argument("--pf-runs", type=int, default=100)
    ap.add_argument("--particles", type=int, default=10_000)
    ap.add_argument("--iterations", type=int, default=100)
    args = ap.parse_args()
    rng = np.random.default_rng(0)
    setup = pv.Setup()
    loc = pv.draw_locations(args.runs, 50, 3, rng)
    d = setup.channel.range_m(pv.measure(setup, loc, rng))
    t0 = time.perf_counter()
    batch = lb.least_squares_position(loc, d).position_m
    t_batch = time.perf_counter() - t0
    H, Y = lb.lateration_rows(loc, d)
    t0 = time.perf_counter()
    rls = lb.recursive_least_squares(H, Y).x[:, -1]
    t_rls = time.perf_counter() - t0
    t0 = time.perf_counter()
    loop = np.stack([np.linalg.lstsq(H[r], Y[r], rcond=None)[0] for r in range(args.runs)])
    t_loop = time.perf_counter() - t0
    sub = min(args.runs, 500)
    t0 = time.perf_counter()
    for r in range(sub):
        x, P = np.zeros(3), 1e6 * np.eye(3)
        for k in range(H.shape[1]):
            h = H[r, k]
            ph = P @ h
            g = ph / (1 + h @ ph)
            x = x + g * (Y[r, k] - h @ x)
            P = P - np.outer(g, ph)
    t_rls_loop = (time.perf_counter() - t0) * args.runs / sub
    print(f"{args.runs} problems, 50 locations, 3-D:")
    print(f"  batch LS vectorized {t_batch:.3f} s; per-run lstsq loop {t_loop:.3f} s (x{t_loop / t_batch:.0f}); "
          f"max difference {np.nanmax(np.abs(batch - loop)):.1e} m")
    print(f"  RLS vectorized {t_rls:.3f} s; per-run Python loop {t_rls_loop:.1f} s (scaled from {sub}) (x{t_rls_loop / t_rls:.0f}); "
          f"max difference to batch {np.nanmax(np.abs(rls - batch)):.1e} m")
    s25 = pv.Setup(receiver_sigma_m=pv.SIGMA3_M)
    loc = pv.draw_locations(args.pf_runs, 25, 3, rng)
    z = pv.measure(s25, loc, rng)
    tracemalloc.start()
    t0 = time.perf_counter()
    res = pv.pf_run(s25, pv.observed_locations(s25, loc, rng), z, rng, n_particles=args.particles,
                    n_iterations=args.iterations)
    t_pf = time.perf_counter() - t0
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    print(f"SIR-PF {args.pf_runs} runs x {args.particles} particles x {args.iterations} iterations, 25 locations: "
          f"{t_pf:.1f} s, peak memory {peak / 2**20:.0f} MiB; mean error {pv.errors_m(res.mean[:, -1], s25.target).mean():.2f} m")


if __name__ == "__main__":
    main()
