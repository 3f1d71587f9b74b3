"""Time batched static localization against a per-problem loop, for N problems (default 10,000).

    python benchmarks/bench_static_localization.py [--n 10000] [--loop-n N]

Prints seconds per method. The cvxpy loop builds one parameterized problem (DPP) and re-solves it per
problem, the fastest way to loop with cvxpy; with ``--loop-n`` smaller than ``--n`` the loop is timed
on a subset and scaled to N (marked "extrapolated").
"""
import argparse
import time

import cvxpy as cp
import numpy as np
from scipy.optimize import least_squares

import locbook as lb
from locbook.scenarios import george


def timed(fn, repeat=3):
    best = np.inf
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=10_000)
    ap.add_argument("--loop-n", type=int, default=None, help="problems timed in the per-problem loops")
    args = ap.parse_args()
    n, loop_n = args.n, args.loop_n or args.n
    anchors = george.ANCHORS_M
    rng = np.random.default_rng(0)
    truth = rng.uniform([0, 0], [2.1, 7.8], (n, 2))
    model = lb.PathLossModel(-45.0, 2.1843, 1.83)
    power = model.sample_power_dbm(lb.pairwise_distance_m(truth, anchors), rng)
    ranges = model.range_m(power)
    a_mat, b = lb.lateration_system(anchors, ranges)
    rows = []

    t_batch, est = timed(lambda: lb.lateration_ls(anchors, ranges).position_m)
    t_loop, loop_est = timed(lambda: np.array([np.linalg.lstsq(a_mat, b[i], rcond=None)[0] for i in range(loop_n)]), 1)
    assert np.allclose(est[:loop_n], loop_est)
    rows.append(("linearized LS, numpy", t_batch, t_loop * n / loop_n, loop_n < n))

    t_batch, box = timed(lambda: lb.lateration_box_ls(anchors, ranges, [0, 0], [2.1, 7.8]).position_m, 1)
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

    t_loop, loop_box = timed(cvx_loop, 1)
    rows.append(("box-constrained LS, cvxpy", t_batch, t_loop * n / loop_n, loop_n < n))
    max_diff = np.abs(box[:loop_n] - loop_box).max()

    t_batch, ml = timed(lambda: lb.rss_ml_position(anchors, power, model), 1)
    init = est

    def scipy_loop():
        return np.array([least_squares(lambda q, i=i: power[i] - model.mean_power_dbm(lb.pairwise_distance_m(q, anchors)),
                                       init[i], method="lm").x for i in range(loop_n)])

    t_loop, _ = timed(scipy_loop, 1)
    rows.append(("RSS maximum likelihood (vs scipy least_squares loop)", t_batch, t_loop * n / loop_n, loop_n < n))

    print(f"{n} static localization problems, 4 anchors (corridor of document 003), 2 cores")
    print(f"{'method':55s} {'batched (s)':>12s} {'loop (s)':>12s} {'speed-up':>9s}")
    for name, tb, tl, extra in rows:
        print(f"{name:55s} {tb:12.4f} {tl:12.4f}{'*' if extra else ' '} {tl / tb:8.0f}x")
    print(f"box LS: batched and looped cvxpy solutions differ by at most {max_diff:.1e} m; "
          f"ML converged for {ml.converged.mean():.2%} of problems")
    if loop_n < n:
        print(f"* loop timed on {loop_n} problems and scaled to {n} (extrapolated)")


if __name__ == "__main__":
    main()
