"""Speed of Palvai 2008's estimators in locbook.

    python benchmarks/bench_palvai.py [full|tiny]
    python benchmarks/bench_palvai.py [--runs 10000] [--pf-runs 12] [--particles 10000] [--iterations 100]

1. Batch LS and RLS over ``runs`` Monte-Carlo problems (50 locations in 3-D) in one vectorized call, against a per-run
   loop (numpy lstsq per run; a Python RLS loop per run on a subset, scaled), alternated in one process
   (``hx.compare``); the differences come from the same calls. Tolerances, per problem: batch LS against lstsq,
   the round-off bound of least squares (``_tolerances.ls_round_off_m``: Golub & Van Loan's
   perturbation bound at a backward error m n eps, and the normal equations' kappa^2); RLS against the loop, the
   round-off of the recursion for each (:func:`rls_round_off_m`: eps times the cancellation 1 + P0 |h|^2 of an
   update, P0 = 1e6, times the largest estimate along the way); RLS against batch LS, the prior's effect (closed
   form) plus both round-offs. Beyond a bound the row is a disagreement.
2. The SIR particle filter, ``pf-runs`` runs x ``particles`` particles x ``iterations`` iterations at 25 locations
   (schedule 'all'), timed once (``hx.once``: time and peak resident memory of the same call). Palvai runs 100;
   the full size runs 12 (the time is linear in the runs; 100 took 50 s, over the suite's budget, and 25 took
   62 s with run_all's fixed malloc mmap threshold). Its mean error against the target is reported without a
   tolerance: no reference runs, Palvai prints no figure, and nothing bounds this filter's error independently (the
   CRLB bounds an unbiased estimator from below; the filter's own covariance is not calibrated, as it re-assimilates
   the same readings at every iteration).
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
from _tolerances import EPS, ls_round_off_m  # noqa: E402
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


def rls_round_off_m(H, Y, prior_cov: float = 1e6):
    """A first-order bound on the round-off of the RLS recursion from ``x = 0``, ``P = prior_cov I`` (per problem):
    an update cancels ``1 + h P h^T <= 1 + prior_cov |h|^2`` in ``P`` (``P`` only shrinks), so it loses up to that
    factor times ``eps`` of the largest estimate along the way, the regularised batch solutions of the rows so far
    (closed form, the identity of :func:`locbook.recursive_least_squares`). Also returns the last of those
    solutions."""
    n = H.shape[-1]
    info = np.cumsum(np.einsum("...ki,...kj->...kij", H, H), axis=-3) + np.eye(n) / prior_cov
    path = np.linalg.solve(info, np.cumsum(H * Y[..., None], axis=-2)[..., None])[..., 0]
    amplification = 1 + prior_cov * np.max(np.sum(H**2, axis=-1), axis=-1)
    return EPS * amplification * np.max(np.abs(path), axis=(-2, -1)), path[..., -1, :]


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

    def ls_agree(ours, ref):
        # two solvers of the same least-squares problems (normal equations, lstsq): within the sum of their
        # round-off bounds (ls_round_off_m), per problem
        diff = np.linalg.norm(ours - ref, axis=-1)
        excess = np.max(diff / (2 * ls_round_off_m(H, Y, ref)))
        text = f"max difference {np.max(diff):.1e} m, at most {excess:.2g} of the round-off bound"
        if not excess <= 1:                                         # NaN (a position missing) fails too
            raise AssertionError(f"{text}, beyond it")
        return text

    m = hx.compare(lambda: lb.lateration_ls(loc, d, pairs="consecutive").position_m,
                   lambda: np.stack([np.linalg.lstsq(H[r], Y[r], rcond=None)[0] for r in range(runs)]),
                   repeats=repeats, agree=ls_agree)
    yield hx.row("batch LS (Palvai)", workload, m, "numpy lstsq per-run loop")
    batch = m.results[0]
    sub = min(runs, rls_loop_runs)

    def rls_agree(ours, ref):
        # the two RLS recursions (Joseph form; P - g (P h)^T) round off up to rls_round_off_m each; batch LS
        # differs from RLS by the prior's effect (regularised minus plain batch solution, closed form) and the
        # round-offs of both
        bound, regularised = rls_round_off_m(H, Y)
        to_loop = np.linalg.norm(ours[:sub] - ref, axis=-1)
        to_batch = np.linalg.norm(ours - batch, axis=-1)
        prior = np.linalg.norm(regularised - batch, axis=-1)
        excess = (np.max(to_loop / (2 * bound[:sub])),
                  np.max(to_batch / (prior + bound + ls_round_off_m(H, Y, batch))))
        text = (f"max difference to the Python RLS loop {np.max(to_loop):.1e} m (its prior P0 = 1e6 I), to batch LS "
                f"{np.max(to_batch):.1e} m: at most {excess[0]:.2g} and {excess[1]:.2g} of their bounds (round-off, "
                "and the prior's effect for batch LS)")
        if not (excess[0] <= 1 and excess[1] <= 1):
            raise AssertionError(f"{text}, beyond them")
        return text

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
                         n_iterations=iterations).mean[:, -1]

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
