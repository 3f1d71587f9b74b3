"""Box-constrained lateration and bounded path-loss fits: the exact solvers against cvxpy.

    python benchmarks/bench_box_ls.py [full|tiny]

Workloads (full): 10,000 box-LS problems in 2-D (the corridor of document 003, 4 anchors) and in 3-D (a
10 x 8 x 3 m room, 6 anchors), tags in the room and beyond it so that the box binds on 0 .. dim coordinates;
2,000 bounded path-loss fits of 24 samples (Ozkaya's bounds; 5,000 at first, reduced so that the five
stacked cvxpy solves fit the suite's time budget). Every locbook call does the whole workload and
alternates with its reference in one process (``hx.compare``: medians of CPU and wall time, at least 5 pairs):

- a per-problem cvxpy loop: one DPP problem with the right-hand side as a Parameter, re-solved per problem
  (the fastest way to loop with cvxpy), Clarabel at tight tolerances; run on a subset of the problems and scaled
  (the reference text says how many);
- the stacked cvxpy problem of the library (``solver="cvxpy"``);
- the closed-form unconstrained LLS (:func:`locbook.lateration_ls`): the goal asks the exact box solver to stay
  within 2x of it (goal ratio 0.5 on the CPU time).

Agreement, from the results of the same calls, each with its tolerance (a disagreement beyond it is a DISAGREE row):
the position (parameter) difference to cvxpy, over the problems Clarabel solved to "optimal" for the loop, within
the distance its gap and feasibility tolerances allow (`_tolerances.solver_bound`: strong convexity of the objective),
and the exact objective never above cvxpy's; for the closed form, that the box solution equals it bit for bit where the
unconstrained fix is inside the box. The millisecond calls are repeated more (``FAST_REPEATS`` pairs) so that their
medians mean something on a shared machine.
"""
from __future__ import annotations

import gc
import sys
import warnings
from pathlib import Path

import cvxpy as cp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _harness as hx  # noqa: E402
import locbook as lb  # noqa: E402
from _tolerances import LIBRARY_TIGHT, solver_bound  # noqa: E402

TIGHT = {"tol_gap_abs": 1e-12, "tol_gap_rel": 1e-12, "tol_feas": 1e-12, "tol_ktratio": 1e-10}
#: pairs for the millisecond comparisons (exact against the closed form)
FAST_REPEATS = 51
SIZES = {"full": {"n": 10_000, "loop_n": 100, "fits": 2_000, "fit_loop_n": 20, "fast_repeats": FAST_REPEATS},
         "tiny": {"n": 50, "loop_n": 4, "fits": 50, "fit_loop_n": 2, "fast_repeats": hx.MIN_REPEATS}}


def _box_workload(dim, n, rng):
    if dim == 2:
        from locbook.scenarios import george
        anchors = george.ANCHORS_M
        lo, hi = np.array([0.0, 0.0]), np.array([2.1, 7.8])
    else:
        lo, hi = np.array([0.0, 0.0, 0.0]), np.array([10.0, 8.0, 3.0])
        anchors = np.array([[0.2, 0.3, 2.8], [9.8, 0.2, 2.7], [9.7, 7.8, 2.9], [0.3, 7.7, 2.6],
                            [5.0, 4.0, 0.2], [2.0, 6.0, 1.0]])
    size = hi - lo
    truth = np.where(rng.random((n, 1)) < 0.8, rng.uniform(lo, hi, (n, dim)),
                     rng.uniform(lo - size, hi + size, (n, dim)))
    d = lb.pairwise_distance_m(truth, anchors) * rng.uniform(0.75, 1.25, (n, anchors.shape[0]))
    return anchors, d, lo, hi


def _check(text, excess):
    if not excess <= 1:                                              # NaN fails too
        raise AssertionError(f"{text}: beyond the bound")
    return text


def _cvxpy_loop(a_mat, b, lo, hi):
    p, b_par = cp.Variable(a_mat.shape[1]), cp.Parameter(a_mat.shape[0])
    problem = cp.Problem(cp.Minimize(cp.sum_squares(a_mat @ p - b_par)), [p >= lo, p <= hi])
    out, optimal = np.full((b.shape[0], a_mat.shape[1]), np.nan), np.zeros(b.shape[0], bool)
    for i in range(b.shape[0]):
        b_par.value = b[i]
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                problem.solve(solver=cp.CLARABEL, **TIGHT)
        except cp.error.SolverError:
            continue
        optimal[i] = problem.status == cp.OPTIMAL
        if p.value is not None:
            out[i] = p.value
    return out, optimal


def _box_rows(dim, cfg, rng):
    n, loop_n = cfg["n"], cfg["loop_n"]
    anchors, d, lo, hi = _box_workload(dim, n, rng)
    a_mat, b = lb.lateration_system(anchors, d)
    workload = f"box LS {dim}-D, {n:,} problems, {anchors.shape[0]} anchors"
    method = "lateration_box_ls (exact, KKT active sets)"

    def exact():
        return lb.lateration_box_ls(anchors, d, lo, hi).position_m

    pos = exact()                                             # warm the per-(anchors, box) cache
    active = np.bincount(np.sum((pos == lo) | (pos == hi), axis=-1), minlength=dim + 1).tolist()
    f = lambda q: np.sum((q @ a_mat.T - b[:loop_n]) ** 2, axis=-1)

    lam_min = float(np.linalg.eigvalsh(a_mat.T @ a_mat)[0])
    scale = np.abs(b).max(axis=-1) + max(np.abs(lo).max(), np.abs(hi).max())

    def vs_loop(ours, ref):
        # ours is exact: never above cvxpy's objective (beyond its tolerances), and within solver_bound of its point
        loop_pos, optimal = ref
        diff = np.linalg.norm(ours[:loop_n][optimal] - loop_pos[optimal], axis=-1)
        excess = np.max(diff / solver_bound(lam_min, f(loop_pos[optimal]), TIGHT, scale[:loop_n][optimal]),
                        initial=0.0)
        worse = int(np.sum(f(ours[:loop_n]) > f(np.where(np.isnan(loop_pos), lo, loop_pos)) * (1 + 1e-9) + 1e-9))
        text = (f"max |dp| vs cvxpy {diff.max(initial=0.0):.1e} m over {int(optimal.sum())}/{loop_n} solved "
                f"'optimal' (at most {excess:.2g} of the bound from Clarabel's tolerances); exact objective worse "
                f"than cvxpy's on {worse}")
        return _check(text, excess if worse == 0 else np.inf)

    m = hx.compare(exact, lambda: _cvxpy_loop(a_mat, b[:loop_n], lo, hi), reference_scale=n / loop_n, agree=vs_loop)
    yield hx.row(method, workload, m,
                 f"cvxpy per-problem loop (DPP Parameter, Clarabel tol 1e-12; {loop_n} of {n:,} problems, scaled)",
                 note=f"coordinates at a bound per problem (0..{dim}): {active}")

    def vs_stacked(ours, ref):
        # one solve of all the problems: its gap is relative to the summed objective, which bounds each problem's
        total = float(np.sum(np.sum((ref @ a_mat.T - b) ** 2, axis=-1)))
        diff = np.linalg.norm(ours - ref, axis=-1)
        excess = np.max(diff / solver_bound(lam_min, total, LIBRARY_TIGHT, scale))
        return _check(f"max |dp| vs stacked cvxpy {diff.max():.1e} m (at most {excess:.2g} of the bound from its "
                      "tolerances, relative to the summed objective)", excess)

    m = hx.compare(exact, lambda: lb.lateration_box_ls(anchors, d, lo, hi, solver="cvxpy").position_m,
                   agree=vs_stacked)
    yield hx.row(method, workload, m, "cvxpy stacked (lateration_box_ls solver='cvxpy')")

    def vs_closed(ours, ref):
        inside = np.all((ref >= lo) & (ref <= hi), axis=-1)
        same = int(np.sum(np.all(ours[inside] == ref[inside], axis=-1)))
        text = (f"equal bit for bit to the closed form on {same}/{int(inside.sum())} problems whose unconstrained fix "
                f"is inside the box; {n - int(inside.sum())} outside it")
        return _check(text, 0.0 if same == int(inside.sum()) else np.inf)   # the same arithmetic where no bound binds

    m = hx.compare(exact, lambda: lb.lateration_ls(anchors, d).position_m, repeats=cfg["fast_repeats"],
                   agree=vs_closed)
    yield hx.row(method + " vs closed-form LLS", workload, m, "closed-form LLS (lateration_ls, unconstrained)",
                 goal=0.5, note="goal: box-LS within 2x of the closed-form linear LS")


def _fit_rows(cfg, rng):
    k, n_samples, loop_n = cfg["fits"], 24, cfg["fit_loop_n"]
    d = rng.uniform(1.0, 15.0, (k, n_samples))
    ref = rng.uniform(-62.0, -33.0, k)
    exp = rng.uniform(1.0, 3.6, k)
    p = ref[:, None] - 10 * exp[:, None] * np.log10(d) + rng.normal(0.0, 4.0, (k, n_samples))
    p[rng.random((k, n_samples)) < 0.05] = np.nan
    bounds = dict(ref_power_bounds_dbm=(-55.0, -40.0), path_loss_exp_bounds=(1.5, 3.0))
    workload = f"bounded path-loss fit, {k:,} fits x {n_samples} samples"
    method = "fit_path_loss (exact bounded closed form)"

    def params(fit):
        return np.stack([fit.ref_power_dbm, fit.path_loss_exp], -1)

    def exact():
        return params(lb.fit_path_loss(d, p, **bounds))

    got = exact()
    n_active = int(np.sum(np.any(got != params(lb.fit_path_loss_closed_form(d, p)), axis=-1)))
    # each fit is a box LS in (P0, n) over its heard samples: design rows [1, -10 log10 d]
    heard = ~np.isnan(p)
    x = -10 * np.log10(d)
    gram = np.stack([np.stack([heard.sum(-1), np.where(heard, x, 0).sum(-1)], -1),
                     np.stack([np.where(heard, x, 0).sum(-1), np.where(heard, x * x, 0).sum(-1)], -1)], -2)
    lam_fit = np.linalg.eigvalsh(gram)[:, 0]
    scale_fit = np.nanmax(np.abs(p), axis=-1) + 55.0                  # the data's and the bounds' largest values

    def objective(q):                                                  # of the first len(q) fits
        k = q.shape[0]
        return np.nansum((p[:k] - (q[:, :1] + q[:, 1:] * x[:k])) ** 2, axis=-1)

    def vs_fits(ours, ref, total):
        diff = np.linalg.norm(ours[:ref.shape[0]] - ref, axis=-1)
        f_ref = np.sum(objective(ref)) if total else objective(ref)
        excess = np.max(diff / solver_bound(lam_fit[:ref.shape[0]], f_ref, LIBRARY_TIGHT, scale_fit[:ref.shape[0]]))
        return _check(f"max |d param| vs {'stacked ' if total else ''}cvxpy {diff.max():.1e} (at most {excess:.2g} "
                      "of the bound from its tolerances" + (", relative to the summed objective)" if total else ")"),
                      excess)

    m = hx.compare(exact, lambda: params(lb.fit_path_loss(d, p, **bounds, solver="cvxpy")),
                   agree=lambda ours, ref: vs_fits(ours, ref, True))
    yield hx.row(method, workload, m, "cvxpy stacked (fit_path_loss solver='cvxpy')",
                 note=f"bounds active on {n_active}/{k} fits")

    def one_by_one():
        return np.array([[f.ref_power_dbm, f.path_loss_exp] for f in
                         (lb.fit_path_loss(d[i], p[i], **bounds, solver="cvxpy") for i in range(loop_n))])

    m = hx.compare(exact, one_by_one, reference_scale=k / loop_n,
                   agree=lambda ours, ref: vs_fits(ours, ref, False))
    yield hx.row(method, workload, m, f"cvxpy one fit per solve (fit_path_loss solver='cvxpy'; {loop_n} of {k:,} "
                                      "fits, scaled)")


def run(size: str = "full"):
    """Benchmark rows (module docstring), yielded as each comparison finishes; ``size`` is ``"full"`` or ``"tiny"``
    (50 problems, a few seconds)."""
    if size not in SIZES:
        raise ValueError(f"size must be one of {tuple(SIZES)}, got {size!r}")
    cfg = SIZES[size]
    rng = np.random.default_rng(0)
    gc.collect()
    gc.freeze()     # the imported modules' objects out of the collector: the harness collects before every call
    yield from _box_rows(2, cfg, rng)
    yield from _box_rows(3, cfg, rng)
    yield from _fit_rows(cfg, rng)


if __name__ == "__main__":
    hx.print_rows(run(sys.argv[1] if len(sys.argv) > 1 else "full"))
