"""Time batched static localization against a per-problem loop, for N problems (default 10,000).

    python benchmarks/bench_static_localization.py [full|tiny]
    python benchmarks/bench_static_localization.py --n 10000 [--loop-n N]

Each batched call alternates with its per-problem loop in one process (``hx.compare``: medians of CPU and wall time,
at least 5 pairs); the differences to the loop come from the same calls. The cvxpy loop builds one parameterized
problem (DPP) and re-solves it per problem, the fastest way to loop with cvxpy; the loops run on a subset of the
problems and are scaled to N (the reference text says how many).

Tolerances, per problem (beyond one the row is a disagreement): linearized LS against numpy's lstsq, the round-off
bound of least squares (`_tolerances.ls_round_off_m`); box-constrained LS against cvxpy, the distance Clarabel's default
tolerances allow (duality gap 1e-8 through the objective's curvature, plus its feasibility tolerance); RSS maximum
likelihood against scipy's LM from the same start, the two solvers' stopping rules (scipy's default ftol and xtol,
locbook's tol_m), or else locbook's fix must be another local minimum of the cost (positive definite Hessian, Newton
step within its tol_m): the cost is not convex and the two may stop in different basins.
"""
from __future__ import annotations

import argparse
import gc
import sys
from pathlib import Path

import cvxpy as cp
import numpy as np
from scipy.optimize import least_squares

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402
import locbook as lb  # noqa: E402
from _tolerances import CLARABEL_DEFAULT, ls_round_off_m, solver_bound  # noqa: E402
from locbook.scenarios import george  # noqa: E402

#: scipy least_squares' default ftol and xtol; rss_ml_position's default tol_m
SCIPY_FTOL, SCIPY_XTOL, ML_TOL_M = 1e-8, 1e-8, 1e-7
#: the corridor of document 003 (m): the box of the constrained fits
BOX_LO, BOX_HI = [0.0, 0.0], [2.1, 7.8]


def _rss_cost_terms(q, anchors, power, model):
    """The residuals ``P - P0 + 10 n log10(d / d0)`` at positions ``q`` ``(k, 2)``, the gradient and the exact Hessian
    of their sum of squares."""
    diff = q[:, None, :] - anchors                                             # (k, m, 2)
    d2 = np.sum(diff**2, axis=-1)
    r = power - (model.ref_power_dbm - 10.0 * model.path_loss_exp * np.log10(np.sqrt(d2) / model.ref_distance_m))
    c = 10.0 * model.path_loss_exp / np.log(10.0)
    jac = c * diff / d2[..., None]                                             # d r / d q
    outer = diff[..., :, None] * diff[..., None, :]
    second = c * (np.eye(2) / d2[..., None, None] - 2 * outer / d2[..., None, None] ** 2)   # d^2 r / d q^2
    grad = 2 * np.einsum("km,kmi->ki", r, jac)
    hess = 2 * (np.einsum("kmi,kmj->kij", jac, jac) + np.einsum("km,kmij->kij", r, second))
    return r, jac, grad, hess


def measure(n: int = 10_000, loop_n: int | None = None, scipy_n: int | None = None, repeats: int = hx.MIN_REPEATS):
    """Rows as each comparison finishes: the batched call on all ``n`` problems against a per-problem loop on the
    first ``loop_n`` (``scipy_n`` for the slowest loop, scipy's least_squares), scaled by n / loop_n, alternated in
    one process; the differences come from the same calls."""
    loop_n = min(loop_n or n, n)
    scipy_n = min(scipy_n or loop_n, n)
    anchors = george.ANCHORS_M
    rng = np.random.default_rng(0)
    truth = rng.uniform(BOX_LO, BOX_HI, (n, 2))
    model = lb.PathLossModel(-45.0, 2.1843, 1.83)
    power = model.sample_rss_dbm(lb.pairwise_distance_m(truth, anchors), rng=rng)
    ranges = model.range_m(power)
    a_mat, b = lb.lateration_system(anchors, ranges)
    workload = f"{n:,} problems, 4 anchors (corridor of document 003)"
    gc.collect()
    gc.freeze()     # the imported modules' objects out of the collector: the harness collects before every call

    def scaled(k):
        return "" if k == n else f" ({k:,} of {n:,} problems, scaled)"

    def ls_agree(ours, ref):
        # two solvers of the same least-squares problems (pinv, lstsq): within the sum of their round-off bounds
        diff = np.linalg.norm(ours[:loop_n] - ref, axis=-1)
        excess = np.max(diff / (2 * ls_round_off_m(a_mat, b[:loop_n], ref)))
        text = (f"max difference {np.max(diff):.1e} m on {loop_n:,} problems, at most {excess:.2g} of the round-off "
                "bound")
        if not excess <= 1:                                         # NaN fails too
            raise AssertionError(f"{text}, beyond it")
        return text

    m = hx.compare(lambda: lb.lateration_ls(anchors, ranges).position_m,
                   lambda: np.array([np.linalg.lstsq(a_mat, b[i], rcond=None)[0] for i in range(loop_n)]),
                   repeats=repeats, reference_scale=n / loop_n, agree=ls_agree)
    yield hx.row("linearized LS", workload, m, "numpy lstsq per-problem loop" + scaled(loop_n))
    est = m.results[0]

    p = cp.Variable(2)
    b_par = cp.Parameter(3)
    single = cp.Problem(cp.Minimize(cp.sum_squares(a_mat @ p - b_par)), [p >= BOX_LO, p <= BOX_HI])

    def cvx_loop():
        out = np.empty((loop_n, 2))
        for i in range(loop_n):
            b_par.value = b[i]
            single.solve(solver=cp.CLARABEL)
            out[i] = p.value
        return out

    def box_agree(ours, ref):
        # cvxpy stops at Clarabel's tolerances: objective within the duality gap 1e-8 max(1, f) of the optimum, so
        # (the objective grows as lambda_min(A^T A) |p - p*|^2 from the box's optimum) |p - p*| <= sqrt(gap /
        # lambda_min), plus the feasibility tolerance on the box (1e-8 of the data's scale); ours is exact
        f = np.sum((ref @ a_mat.T - b[:loop_n]) ** 2, axis=-1)
        lam = np.linalg.eigvalsh(a_mat.T @ a_mat)[0]
        bound = solver_bound(lam, f, CLARABEL_DEFAULT, np.abs(b[:loop_n]).max(axis=-1) + max(BOX_HI))
        diff = np.linalg.norm(ours[:loop_n] - ref, axis=-1)
        excess = np.max(diff / bound)
        text = (f"max difference {np.max(diff):.1e} m on {loop_n:,} problems, at most {excess:.2g} of the bound from "
                "Clarabel's tolerances")
        if not excess <= 1:
            raise AssertionError(f"{text}, beyond it")
        return text

    m = hx.compare(lambda: lb.lateration_box_ls(anchors, ranges, BOX_LO, BOX_HI).position_m, cvx_loop,
                   repeats=repeats, reference_scale=n / loop_n, agree=box_agree)
    yield hx.row("box-constrained LS (batched)", workload, m, "cvxpy DPP per-problem loop" + scaled(loop_n))

    p0, ple, d0 = model.ref_power_dbm, model.path_loss_exp, model.ref_distance_m

    def residual(q, i):          # the log-distance mean written out, as a hand-written reference would
        return power[i] - (p0 - 10.0 * ple * np.log10(np.sqrt(np.sum((q - anchors) ** 2, axis=-1)) / d0))

    def scipy_loop():
        return np.array([least_squares(residual, est[i], args=(i,), method="lm").x for i in range(scipy_n)])

    def ml_agree(ours, ref):
        # the same cost from the same start, two local solvers: at one minimum they agree within their stopping
        # rules, scipy's (a step gaining less than ftol of the cost: |dp| <= sqrt(2 ftol C / lambda_min(J^T J)), C
        # = its cost 1/2 |r|^2; or a step below xtol |p|) plus ours (a step below tol_m (1 + |p|)). Beyond that
        # distance the two stopped at different local minima (the cost is not convex): ours must then be one,
        # a positive definite exact Hessian and a Newton step to its stationary point within its tol_m (1 + |p|)
        ok = np.flatnonzero(ours.converged[:scipy_n])
        q, p_ref, pw = ours.position_m[ok], ref[ok], power[ok]
        r_ref, jac_ref, _, _ = _rss_cost_terms(p_ref, anchors, pw, model)
        lam = np.linalg.eigvalsh(np.einsum("kmi,kmj->kij", jac_ref, jac_ref))[:, 0]
        bound = (np.sqrt(2 * SCIPY_FTOL * 0.5 * np.sum(r_ref**2, axis=-1) / lam)
                 + SCIPY_XTOL * np.linalg.norm(p_ref, axis=-1) + ML_TOL_M * (1 + np.linalg.norm(q, axis=-1)))
        diff = np.linalg.norm(q - p_ref, axis=-1)
        other = ~(diff <= bound)
        _, _, grad, hess = _rss_cost_terms(q[other], anchors, pw[other], model)
        minimum = np.all(np.linalg.eigvalsh(hess) > 0, axis=-1)
        safe = np.where(minimum[:, None, None], hess, np.eye(2))          # (not a minimum: fails anyway)
        newton = np.linalg.norm(np.linalg.solve(safe, grad[..., None])[..., 0], axis=-1)
        bad = int(np.sum(~(minimum & (newton <= ML_TOL_M * (1 + np.linalg.norm(q[other], axis=-1))))))
        text = (f"converged for {ours.converged.mean():.2%} of problems; on the {ok.size:,} of {scipy_n:,} that "
                f"converged, median difference to scipy {np.median(diff):.1e} m, max {diff.max():.1e} m; "
                f"{ok.size - int(other.sum())} within the solvers' stopping distance (at most "
                f"{np.max(diff[~other] / bound[~other], initial=0):.2g} of it)"
                + (f", {other.sum() - bad} at another local minimum of the same cost" if other.sum() > bad else ""))
        if bad:
            raise AssertionError(f"{text}; {bad} neither within the stopping distance nor at a local minimum")
        return text

    rss_model = lb.RssModel(anchors, model)
    m = hx.compare(lambda: lb.rss_ml_position(power, rss_model), scipy_loop, repeats=repeats,
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
