"""Time batched static localization against a per-problem loop, for N problems (default 10,000).

    python benchmarks/bench_static_localization.py [--n 10000] [--loop-n N] [--size tiny]

Reports seconds per method. The cvxpy loop builds one parameterized problem (DPP) and re-solves it per problem, the
fastest way to loop with cvxpy; with ``--loop-n`` smaller than ``--n`` the loops are timed on a subset and scaled to N
(marked "scaled").
"""
from __future__ import annotations

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


def measure(n: int = 10_000, loop_n: int | None = None, repeat: int = 3) -> list[dict]:
    loop_n = min(loop_n or n, n)
    anchors = george.ANCHORS_M
    rng = np.random.default_rng(0)
    truth = rng.uniform([0, 0], [2.1, 7.8], (n, 2))
    model = lb.PathLossModel(-45.0, 2.1843, 1.83)
    power = model.sample_rss_dbm(lb.pairwise_distance_m(truth, anchors), rng)
    ranges = model.range_m(power)
    a_mat, b = lb.lateration_system(anchors, ranges)
    workload = f"{n:,} problems, 4 anchors (corridor of document 003)"
    scaled = "" if loop_n == n else f" ({loop_n} problems, scaled)"
    rows = []

    t_batch, _, est = hx.timed(lambda: lb.lateration_ls(anchors, ranges).position_m, repeat)
    t_loop, _, loop_est = hx.timed(lambda: np.array([np.linalg.lstsq(a_mat, b[i], rcond=None)[0] for i in range(loop_n)]))
    rows.append(hx.row("linearized LS", workload, t_batch, "numpy lstsq per-problem loop" + scaled, t_loop * n / loop_n,
                       hx.peak_mb(lambda: lb.lateration_ls(anchors, ranges)),
                       f"max difference {np.abs(est[:loop_n] - loop_est).max():.1e} m"))

    t_batch, _, box = hx.timed(lambda: lb.lateration_box_ls(anchors, ranges, [0, 0], [2.1, 7.8]).position_m)
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

    t_loop, _, loop_box = hx.timed(cvx_loop)
    rows.append(hx.row("box-constrained LS (batched)", workload, t_batch,
                       "cvxpy DPP per-problem loop" + scaled, t_loop * n / loop_n,
                       hx.peak_mb(lambda: lb.lateration_box_ls(anchors, ranges, [0, 0], [2.1, 7.8])),
                       f"max difference {np.abs(box[:loop_n] - loop_box).max():.1e} m"))

    t_batch, _, ml = hx.timed(lambda: lb.rss_ml_position(anchors, power, model))

    def scipy_loop():
        return np.array([least_squares(lambda q, i=i: power[i] - model.mean_rss_dbm(lb.pairwise_distance_m(q, anchors)),
                                       est[i], method="lm").x for i in range(loop_n)])

    t_loop, _, _ = hx.timed(scipy_loop)
    rows.append(hx.row("RSS maximum likelihood", workload, t_batch, "scipy least_squares per-problem loop" + scaled,
                       t_loop * n / loop_n, hx.peak_mb(lambda: lb.rss_ml_position(anchors, power, model)),
                       f"converged for {ml.converged.mean():.2%} of problems"))
    return rows


def run(size: str = "full") -> list[dict]:
    """The benchmark protocol (benchmarks/run_all.py): full = 10,000 problems (loops on 2,000, scaled), tiny = 100."""
    if hx.check_size(size) == "tiny":
        return measure(100, 20, repeat=1)
    return measure(10_000, 2_000)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--loop-n", type=int, default=None, help="problems timed in the per-problem loops")
    ap.add_argument("--size", choices=hx.SIZES, default=None, help="the run(size) preset instead of the options")
    args = ap.parse_args()
    hx.print_rows(run(args.size) if args.size else measure(args.n, args.loop_n))


if __name__ == "__main__":
    main()
