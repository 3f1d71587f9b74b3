"""Time batched static localization against a per-problem loop, for N problems (default 10,000).

    python benchmarks/bench_static_localization.py [full|tiny]
    python benchmarks/bench_static_localization.py --n 10000 [--loop-n N]

Each batched call alternates with its per-problem loop in one process (``hx.compare``: medians of CPU and wall time,
at least 5 pairs); the differences to the loop come from the same calls. The cvxpy loop builds one parameterized
problem (DPP) and re-solves it per problem, the fastest way to loop with cvxpy; the loops run on a subset of the
problems and are scaled to N (the reference text says how many).
"""
from __future__ import annotations

import gc
import argparse
import sys
from pathlib import Path

import cvxpy as cp
import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402

import locbook as lb  # noqa: E402
from locbook.scenarios import george  # noqa: E402


def measure(n: int = 10_000, loop_n: int | None = None, scipy_n: int | None = None, repeats: int = hx.MIN_REPEATS):
    """Rows as each comparison finishes: the batched call on all ``n`` problems against a per-problem loop on the
    first ``loop_n`` (``scipy_n`` for the slowest loop, scipy's least_squares), scaled by n / loop_n, alternated in
    one process; the differences come from the same calls."""
    loop_n = min(loop_n or n, n)
    scipy_n = min(scipy_n or loop_n, n)
    anchors = george.ANCHORS_M
    rng = np.random.default_rng(0)
    truth = rng.uniform([0, 0], [2.1, 7.8], (n, 2))
    model = lb.PathLossModel(-45.0, 2.1843, 1.83)
    power = model.sample_rss_dbm(lb.pairwise_distance_m(truth, anchors), rng)
    ranges = model.range_m(power)
    a_mat, b = lb.lateration_system(anchors, ranges)
    workload = f"{n:,} problems, 4 anchors (corridor of document 003)"
    gc.collect()
    gc.freeze()     # the imported modules' objects out of the collector: the harness collects before every call

    def scaled(k):
        return "" if k == n else f" ({k:,} of {n:,} problems, scaled)"

    def max_diff(k):
        return lambda ours, ref: f"max difference {np.abs(ours[:k] - ref).max():.1e} m on {k:,} problems"

    m = hx.compare(lambda: lb.lateration_ls(anchors, ranges).position_m,
                   lambda: np.array([np.linalg.lstsq(a_mat, b[i], rcond=None)[0] for i in range(loop_n)]),
                   repeats=repeats, reference_scale=n / loop_n, agree=max_diff(loop_n))
    yield hx.row("linearized LS", workload, m, "numpy lstsq per-problem loop" + scaled(loop_n))
    est = m.results[0]

    p = cp.Variable(2)
    b_par = cp.Parameter(3)
    single = cp.Problem(cp.Minimize(cp.sum_squares(a_mat @ p - b_par)), [p >= 0, p <= [2.1, 7.8]])

    def cvx_loop():
        out = np.empty((loop_n, 2))
        for i in range(loop_n):
            b_par.value = b[i]
            single.solve(solver=cp.CLARABEL)
            out[i] = p.value
        return out

    m = hx.compare(lambda: lb.lateration_box_ls(anchors, ranges, [0, 0], [2.1, 7.8]).position_m, cvx_loop,
                   repeats=repeats, reference_scale=n / loop_n, agree=max_diff(loop_n))
    yield hx.row("box-constrained LS (batched)", workload, m, "cvxpy DPP per-problem loop" + scaled(loop_n))

    p0, ple, d0 = model.ref_power_dbm, model.path_loss_exp, model.ref_distance_m

    def residual(q, i):          # the log-distance mean written out, as a hand-written reference would
        return power[i] - (p0 - 10.0 * ple * np.log10(np.sqrt(np.sum((q - anchors) ** 2, axis=-1)) / d0))

    def scipy_loop():
        return np.array([least_squares(residual, est[i], args=(i,), method="lm").x for i in range(scipy_n)])

    def ml_agree(ours, ref):
        ok = ours.converged[:scipy_n]
        diff = np.max(np.abs(ours.position_m[:scipy_n][ok] - ref[ok]), axis=-1)
        far = int(np.sum(diff > 1e-3))
        return (f"converged for {ours.converged.mean():.2%} of problems; on the {int(ok.sum()):,} of {scipy_n:,} that "
                f"converged, median difference to scipy {np.median(diff):.1e} m, max {diff.max():.1e} m"
                + (f" ({far} beyond 1 mm: another local optimum of the same cost)" if far else ""))

    m = hx.compare(lambda: lb.rss_ml_position(anchors, power, model), scipy_loop, repeats=repeats,
                   reference_scale=n / scipy_n, agree=ml_agree)
    yield hx.row("RSS maximum likelihood", workload, m, "scipy least_squares (LM) per-problem loop" + scaled(scipy_n))


def run(size: str = "full"):
    """The benchmark protocol (benchmarks/run_all.py): full = 10,000 problems (loops on 300, scipy's on 100,
    scaled), tiny = 100 (loops on 10, scipy's on 5)."""
    if hx.check_size(size) == "tiny":
        return measure(100, 10, 5)
    return measure(10_000, 300, 100)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("size", nargs="?", choices=hx.SIZES, default=None, help="the run(size) preset")
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--loop-n", type=int, default=None, help="problems timed in the per-problem loops")
    args = ap.parse_args()
    hx.print_rows(run(args.size) if args.size else measure(args.n, args.loop_n))


if __name__ == "__main__":
    main()
