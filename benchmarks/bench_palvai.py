"""Speed of Palvai 2008's estimators in locbook.

    python benchmarks/bench_palvai.py [full|tiny]
    python benchmarks/bench_palvai.py [--runs 10000] [--pf-runs 12] [--particles 10000] [--iterations 100]

1. Batch LS and RLS over ``runs`` Monte-Carlo problems (50 locations in 3-D) in one vectorized call, against a per-run
   loop (numpy lstsq per run; a Python RLS loop per run on a subset, scaled), alternated in one process
   (``hx.compare``); the differences come from the same calls.
2. The SIR particle filter, ``pf-runs`` runs x ``particles`` particles x ``iterations`` iterations at 25 locations
   (schedule 'all'), timed once (``hx.once``: time and peak resident memory of the same call). Palvai runs 100;
   the full size runs 12 (the time is linear in the runs; 100 took 50 s, over the suite's budget, and 25 took
   62 s with run_all's fixed malloc mmap threshold).
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
from locbook.scenarios import palvai as pv  # noqa: E402


def _rls_loop(H, Y, runs):
    """Palvai's RLS (Eqs. (2.49)-(2.58)) one run at a time in Python, from x = 0 and P = 1e6 I: the final estimates."""
    out = np.empty((runs, H.shape[-1]))
    for r in range(runs):
        x, P = np.zeros(3), 1e6 * np.eye(3)
        for k in range(H.shape[1]):
            h = H[r, k]
            ph = P @ h
            g = ph / (1 + h @ ph)
            x = x + g * (Y[r, k] - h @ x)
            P = P - np.outer(g, ph)
        out[r] = x
    return out


def measure(runs: int = 10_000, pf_runs: int = 12, particles: int = 10_000, iterations: int = 100,
            rls_loop_runs: int = 500, repeats: int = hx.MIN_REPEATS):
    """Rows as each measurement finishes: LS and RLS against their per-run loops (alternated, ``hx.compare``), the
    particle filter timed once (``hx.once``)."""
    rng = np.random.default_rng(0)
    setup = pv.Setup()
    loc = pv.draw_locations(runs, 50, 3, rng)
    d = setup.channel.range_m(pv.measure(setup, loc, rng))
    H, Y = lb.lateration_system(loc, d, pairs="consecutive")
    gc.collect()
    gc.freeze()     # the imported modules' objects out of the collector: the harness collects before every call
    workload = f"{runs:,} problems, 50 locations, 3-D"
    m = hx.compare(lambda: lb.lateration_ls(loc, d, pairs="consecutive").position_m,
                   lambda: np.stack([np.linalg.lstsq(H[r], Y[r], rcond=None)[0] for r in range(runs)]),
                   repeats=repeats,
                   agree=lambda ours, ref: f"max difference {np.nanmax(np.abs(ours - ref)):.1e} m")
    yield hx.row("batch LS (Palvai)", workload, m, "numpy lstsq per-run loop")
    batch = m.results[0]
    sub = min(runs, rls_loop_runs)

    def rls_agree(ours, ref):
        return (f"max difference to the Python RLS loop {np.nanmax(np.abs(ours[:sub] - ref)):.1e} m (its prior "
                f"P0 = 1e6 I), to batch LS {np.nanmax(np.abs(ours - batch)):.1e} m")

    m = hx.compare(lambda: lb.recursive_least_squares(H, Y).x[:, -1], lambda: _rls_loop(H, Y, sub), repeats=repeats,
                   reference_scale=runs / sub, agree=rls_agree)
    yield hx.row("RLS (Palvai)", workload, m,
                 "Python RLS per-run loop" + (f" ({sub:,} of {runs:,} runs, scaled)" if sub < runs else ""))

    s25 = pv.Setup(receiver_sigma_m=pv.SIGMA3_M)
    loc = pv.draw_locations(pf_runs, 25, 3, rng)
    z = pv.measure(s25, loc, rng)
    observed = pv.observed_locations(s25, loc, rng)

    def pf():
        return pv.pf_run(s25, observed, z, np.random.default_rng(5), n_particles=particles,
                         n_iterations=iterations).mean_m[:, -1]

    # compiled kernels (numba) compiled or loaded from their cache before the timed call
    pv.pf_run(s25, observed[:1], z[:1], np.random.default_rng(5), n_particles=100, n_iterations=2)

    m = hx.once(pf, agree=lambda mean: f"mean error {pv.errors_m(mean, s25.target).mean():.2f} m")
    yield hx.row("SIR particle filter (Palvai)",
                 f"{pf_runs} runs x {particles:,} particles x {iterations} iterations, 25 locations", m,
                 note="no reference" + (f"; {pf_runs} of Palvai's 100 runs, to fit the suite's time budget (the time "
                                        "is linear in the runs)" if pf_runs < 100 else ""))


def run(size: str = "full"):
    """The benchmark protocol (benchmarks/run_all.py): full = 10,000 problems and a 12 x 10,000 x 100 particle filter
    (timed once); tiny = 300 problems and 2 x 500 x 5."""
    if hx.check_size(size) == "tiny":
        return measure(runs=300, pf_runs=2, particles=500, iterations=5, rls_loop_runs=50)
    return measure()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("size", nargs="?", choices=hx.SIZES, default=None, help="the run(size) preset")
    ap.add_argument("--runs", type=int, default=10_000)
    ap.add_argument("--pf-runs", type=int, default=12)
    ap.add_argument("--particles", type=int, default=10_000)
    ap.add_argument("--iterations", type=int, default=100)
    args = ap.parse_args()
    hx.print_rows(run(args.size) if args.size else measure(args.runs, args.pf_runs, args.particles, args.iterations))


if __name__ == "__main__":
    main()
