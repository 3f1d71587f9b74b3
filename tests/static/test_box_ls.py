"""Exact solvers for the small bounded least-squares problems.

- :func:`lb.lateration_box_ls` (``solver="exact"``, the default): KKT active-set enumeration, vectorized over
  problems, 2-D and 3-D;
- :func:`lb.fit_path_loss` with bounds (``solver="auto"``/``"exact"``): the two-parameter box QP in closed form.

Independent oracles: cvxpy (Clarabel, each problem solved alone at tight tolerances, so the stacked sum does not
loosen them), scipy's ``lsq_linear`` (bounded-variable least squares, an active-set method of its own), the KKT
conditions checked directly on the answer (a certificate of optimality for a convex QP), and brute force.
"""
import warnings

import cvxpy as cp
import numpy as np
import pytest
from scipy.optimize import lsq_linear

import locbook as lb
from locbook.static import box_ls, calibration
from locbook.static.calibration import path_loss_design_matrix

# Clarabel for one small problem at a time: tight enough for 1e-6 m (the library's stacked solve is looser)
TIGHT = {"tol_gap_abs": 1e-12, "tol_gap_rel": 1e-12, "tol_feas": 1e-12, "tol_ktratio": 1e-10}

ROOMS = {2: (np.array([0.0, 0.0]), np.array([10.0, 8.0])),
         3: (np.array([0.0, 0.0, 0.0]), np.array([10.0, 8.0, 3.0]))}


def _anchors(dim, rng):
    lo, hi = ROOMS[dim]
    corners = np.array(np.meshgrid(*[[a, b] for a, b in zip(lo, hi)], indexing="ij")).reshape(dim, -1).T
    return np.concatenate([corners, rng.uniform(lo, hi, (2, dim))]) + rng.normal(0, 0.3, (corners.shape[0] + 2, dim))


def _problems(dim, k, seed):
    """Anchors around the room, tags in and far outside it (up to three room sizes away), ranges with 30 %
    errors: boxes that bind on 0 .. dim coordinates, and fixes far outside."""
    rng = np.random.default_rng(seed)
    lo, hi = ROOMS[dim]
    anchors = _anchors(dim, rng)
    size = hi - lo
    truth = np.where(rng.random((k, 1)) < 0.7, rng.uniform(lo, hi, (k, dim)),
                     rng.uniform(lo - 3 * size, hi + 3 * size, (k, dim)))
    d = lb.pairwise_distance_m(truth, anchors) * rng.uniform(0.7, 1.3, (k, anchors.shape[0]))
    return anchors, d, lo, hi


def _cvxpy_each(a_mat, b, lo, hi):
    """One DPP problem, re-solved per right-hand side: positions and statuses."""
    p, b_par = cp.Variable(a_mat.shape[1]), cp.Parameter(a_mat.shape[0])
    problem = cp.Problem(cp.Minimize(cp.sum_squares(a_mat @ p - b_par)), [p >= lo, p <= hi])
    out, status = np.full((b.shape[0], a_mat.shape[1]), np.nan), []
    for i in range(b.shape[0]):
        b_par.value = b[i]
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                problem.solve(solver=cp.CLARABEL, **TIGHT)
        except cp.error.SolverError:
            status.append("solver_error")
            continue
        if p.value is not None:
            out[i] = p.value
        status.append(problem.status)
    return out, np.array(status)


def _objective(a_mat, b, p):
    return np.sum((p @ a_mat.T - b) ** 2, axis=-1)


def _n_active(p, lo, hi):
    return np.sum((np.abs(p - lo) < 1e-9) | (np.abs(p - hi) < 1e-9), axis=-1)


@pytest.mark.slow
@pytest.mark.parametrize("dim", [2, 3])
def test_exact_box_ls_equals_cvxpy(dim):
    anchors, d, lo, hi = _problems(dim, 1500, seed=dim)
    res = lb.lateration_box_ls(anchors, d, lo, hi)
    assert res.converged.all() and set(res.status.tolist()) == {"ok"} and res.method == "lateration_box_ls"
    a_mat, b = lb.lateration_system(anchors, d)
    ref, status = _cvxpy_each(a_mat, b, lo, hi)
    optimal = status == "optimal"
    assert optimal.mean() > 0.99                         # Clarabel stops short on a handful at these tolerances
    np.testing.assert_allclose(res.position_m[optimal], ref[optimal], rtol=0, atol=1e-6)
    # everywhere (also where cvxpy stopped short) the exact answer is feasible and never worse than cvxpy's
    assert np.all(res.position_m >= lo) and np.all(res.position_m <= hi)
    f_exact, f_cvx = _objective(a_mat, b, res.position_m), _objective(a_mat, b, np.where(np.isnan(ref), lo, ref))
    assert np.all(f_exact <= f_cvx * (1 + 1e-9) + 1e-9)
    # the workload covers what it should: the box binding on every number of coordinates, fixes far outside
    active = _n_active(res.position_m, lo, hi)
    assert np.all(np.bincount(active, minlength=dim + 1) >= 20), np.bincount(active)
    unconstrained = lb.lateration_ls(anchors, d).position_m
    assert np.max(np.maximum(lo - unconstrained, unconstrained - hi)) > 10.0


@pytest.mark.parametrize("dim", [2, 3])
def test_exact_box_ls_meets_the_kkt_conditions_and_equals_lsq_linear(dim):
    """A certificate that needs no other solver: feasible, gradient A^T (A p - b) zero on free coordinates,
    >= 0 at a lower bound, <= 0 at an upper bound (sufficient for a convex QP)."""
    anchors, d, lo, hi = _problems(dim, 10_000, seed=10 + dim)
    p = lb.lateration_box_ls(anchors, d, lo, hi).position_m
    a_mat, b = lb.lateration_system(anchors, d)
    grad = (p @ a_mat.T - b) @ a_mat
    tol = 1e-9 * (np.abs(b) @ np.abs(a_mat) + 1.0)
    at_lo, at_hi = p == lo, p == hi
    assert np.all(p >= lo) and np.all(p <= hi)
    assert np.all(np.abs(np.where(at_lo | at_hi, 0.0, grad)) <= tol)
    assert np.all(np.where(at_lo, grad, 0.0) >= -tol) and np.all(np.where(at_hi, grad, 0.0) <= tol)
    for i in range(0, 10_000, 50):
        ref = lsq_linear(a_mat, b[i], bounds=(lo, hi), method="bvls", tol=1e-14).x
        np.testing.assert_allclose(p[i], ref, rtol=0, atol=1e-9)


@pytest.mark.parametrize("dim", [2, 3])
def test_stacked_cvxpy_path_is_kept_as_the_reference(dim):
    anchors, d, lo, hi = _problems(dim, 40, seed=20 + dim)
    exact = lb.lateration_box_ls(anchors, d, lo, hi)
    cvx = lb.lateration_box_ls(anchors, d, lo, hi, solver="cvxpy")
    assert cvx.method == exact.method and cvx.status.tolist() == exact.status.tolist()
    # the stacked solve's tolerance is relative to the summed objective: looser than one problem's
    np.testing.assert_allclose(exact.position_m, cvx.position_m, rtol=0, atol=1e-4)
    a_mat, b = lb.lateration_system(anchors, d)
    assert np.all(_objective(a_mat, b, exact.position_m) <= _objective(a_mat, b, cvx.position_m) + 1e-9)
    with pytest.raises(ValueError, match="solver must be one of"):
        lb.lateration_box_ls(anchors, d, lo, hi, solver="clarabel")


@pytest.mark.parametrize("dim", [2, 3])
def test_inside_the_box_the_answer_is_lateration_ls(dim):
    anchors, d, lo, hi = _problems(dim, 3000, seed=30 + dim)
    ls = lb.lateration_ls(anchors, d).position_m
    inside = np.all((ls > lo) & (ls < hi), axis=-1)
    assert 100 < inside.sum() < 3000
    box = lb.lateration_box_ls(anchors, d, lo, hi).position_m
    np.testing.assert_array_equal(box[inside], ls[inside])            # the same arithmetic: bit-identical
    assert np.abs(box[~inside] - ls[~inside]).max() > 1.0
    huge = lb.lateration_box_ls(anchors, d, -1e4, 1e4).position_m      # a box that never binds: plain LS
    np.testing.assert_allclose(huge, ls, rtol=0, atol=1e-9)


def test_clipping_the_unconstrained_fix_is_not_the_answer():
    """Projecting the unconstrained LS fix onto the box is a different (worse) estimator; a solver returning it
    fails this test. With correlated coordinates (a long corridor of anchors) clipping one coordinate moves the
    best value of the other."""
    anchors = np.array([[0.0, 0.0], [2.0, 1.0], [20.0, 9.0], [22.0, 11.0]])     # along a diagonal corridor
    truth = np.array([[25.0, 4.0], [-3.0, 6.0], [12.0, -4.0]])
    d = lb.pairwise_distance_m(truth, anchors)
    lo, hi = np.array([0.0, 0.0]), np.array([20.0, 10.0])
    a_mat, b = lb.lateration_system(anchors, d)
    clipped = np.clip(lb.lateration_ls(anchors, d).position_m, lo, hi)
    box = lb.lateration_box_ls(anchors, d, lo, hi).position_m
    assert np.all(np.abs(box - clipped).max(axis=-1) > 0.1)
    assert np.all(_objective(a_mat, b, box) < _objective(a_mat, b, clipped) - 1.0)
    for i in range(len(truth)):
        ref = lsq_linear(a_mat, b[i], bounds=(lo, hi), method="bvls", tol=1e-14).x
        np.testing.assert_allclose(box[i], ref, rtol=0, atol=1e-9)
    # on the random workload too, clipping differs from the answer on many problems
    anchors, d, lo, hi = _problems(2, 2000, seed=40)
    clipped = np.clip(lb.lateration_ls(anchors, d).position_m, lo, hi)
    box = lb.lateration_box_ls(anchors, d, lo, hi).position_m
    assert np.sum(np.abs(box - clipped).max(axis=-1) > 1e-3) > 100


def test_rank_deficient_matrix_gives_a_least_objective_kkt_point():
    """Not reachable through the lateration API (collinear anchors are rejected) but handled: the objective is
    cvxpy's and the box holds."""
    a_mat = np.array([[1.0, 2.0], [2.0, 4.0], [-1.0, -2.0]])       # rank 1: only x + 2 y is determined
    rng = np.random.default_rng(7)
    b = rng.normal(0.0, 20.0, (300, 3))
    lo, hi = (0.0, -1.0), (3.0, 2.0)
    pos, ok = box_ls._box_ls_exact(a_mat, b, lo, hi)
    assert ok.all() and np.all(pos >= lo) and np.all(pos <= hi)
    ref, status = _cvxpy_each(a_mat, b, np.array(lo), np.array(hi))
    good = status == "optimal"
    assert good.mean() > 0.95
    np.testing.assert_allclose(_objective(a_mat, b, pos)[good], _objective(a_mat, b, ref)[good], rtol=1e-7, atol=1e-6)


@pytest.mark.parametrize("dim", [2, 3])
def test_fallback_least_feasible_candidate_is_exact_too(dim):
    """Should rounding leave a problem with no KKT candidate, the least objective among the feasible candidates
    is taken. Forced here for every problem (the KKT quantities pushed negative), it still equals BVLS."""
    anchors, d, lo, hi = _problems(dim, 400, seed=45 + dim)
    a_mat, b = lb.lateration_system(anchors, d)
    pinv_t, levels = box_ls._box_active_sets(tuple(map(tuple, a_mat.tolist())), tuple(lo), tuple(hi))
    spoiled = []
    for weights, offsets, n_sets in levels:
        per_set = weights.shape[0] // n_sets
        kkt_row = (np.arange(weights.shape[0]) % per_set) < per_set - dim
        spoiled.append((weights, offsets - 1e6 * kkt_row[:, None], n_sets))
    p_star = b @ pinv_t
    outside = np.any((p_star < lo) | (p_star > hi), axis=-1)
    got = box_ls._box_active_set_search(p_star[outside], lo, hi, spoiled, a_mat)
    for i, row in zip(np.flatnonzero(outside)[::5], got[::5]):
        ref = lsq_linear(a_mat, b[i], bounds=(lo, hi), method="bvls", tol=1e-14).x
        np.testing.assert_allclose(row, ref, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got, lb.lateration_box_ls(anchors, d, lo, hi).position_m[outside], rtol=0, atol=1e-9)


def test_missing_anchors_and_overflow_keep_their_rules_with_the_exact_solver():
    anchors, d, lo, hi = _problems(3, 30, seed=50)
    holed = d.copy()
    holed[4, 1] = np.nan                           # one anchor not heard
    holed[7, :-2] = np.nan                         # two heard: too few
    with np.errstate(over="ignore", invalid="ignore"):
        holed[9, 0] = 1e200                        # squares to infinity
        res = lb.lateration_box_ls(anchors, holed, lo, hi)
    full = lb.lateration_box_ls(anchors, d, lo, hi)
    keep = np.setdiff1d(np.arange(30), [4, 7, 9])
    np.testing.assert_array_equal(res.position_m[keep], full.position_m[keep])    # no solver tolerance now
    heard = np.setdiff1d(np.arange(anchors.shape[0]), [1])
    np.testing.assert_array_equal(res.position_m[4],
                                  lb.lateration_box_ls(anchors[heard], d[4:5, heard], lo, hi).position_m[0])
    assert res.status[7] == "too_few_anchors" and res.status[9] == "solver_failed"
    assert np.isnan(res.position_m[[7, 9]]).all() and not res.converged[[7, 9]].any()


@pytest.mark.filterwarnings("ignore:Solution may be inaccurate")
def test_cvxpy_box_path_still_isolates_a_failing_problem(monkeypatch):
    """The stacked cvxpy path's halving (kept for solver="cvxpy"): one problem the solver fails on fails alone."""
    anchors, d, lo, hi = _problems(2, 8, seed=60)
    good = lb.lateration_box_ls(anchors, d, lo, hi, solver="cvxpy")
    real_solve = box_ls.solve
    poison = lb.lateration_system(anchors, d[3])[1]

    def flaky(problem, what):
        b = [p for p in problem.parameters() if p.name() == "b"][0].value
        if np.any(np.all(np.isclose(b, poison), axis=1)):
            raise lb.ConvergenceError("deliberate")
        real_solve(problem, what)

    monkeypatch.setattr(box_ls, "solve", flaky)
    res = lb.lateration_box_ls(anchors, d, lo, hi, solver="cvxpy")
    others = np.setdiff1d(np.arange(8), [3])
    np.testing.assert_allclose(res.position_m[others], good.position_m[others], atol=1e-6)
    assert res.status[3] == "solver_failed" and np.isnan(res.position_m[3]).all() and res.converged[others].all()
    exact = lb.lateration_box_ls(anchors, d, lo, hi)             # the exact solver never calls cvxpy
    assert exact.converged.all()


# -- bounded path-loss fit ---------------------------------------------------------------------------
def _fits(k=400, n=20, seed=70):
    rng = np.random.default_rng(seed)
    d = rng.uniform(1.0, 15.0, (k, n))
    ref = rng.uniform(-62.0, -33.0, k)
    exp = rng.uniform(1.0, 3.6, k)
    p = ref[:, None] - 10 * exp[:, None] * np.log10(d) + rng.normal(0.0, 4.0, (k, n))
    p[rng.random((k, n)) < 0.1] = np.nan                            # not heard
    return d, p


BOUNDS = {
    "both": ((-55.0, -40.0), (1.5, 3.0)),
    "exponent only": (None, (1.5, 3.0)),
    "ref power only": ((-55.0, -40.0), None),
    "inactive": ((-200.0, 100.0), (-10.0, 20.0)),
}


def _params(fit):
    return np.stack([fit.ref_power_dbm, fit.path_loss_exp], -1)


@pytest.mark.parametrize("case", list(BOUNDS))
def test_bounded_path_loss_fit_equals_cvxpy_and_lsq_linear(case):
    ref_b, exp_b = BOUNDS[case]
    d, p = _fits()
    fit = lb.fit_path_loss(d, p, ref_power_bounds_dbm=ref_b, path_loss_exp_bounds=exp_b)
    assert fit.status == "optimal" and fit.ok
    assert np.array_equal(_params(fit), _params(lb.fit_path_loss(d, p, ref_power_bounds_dbm=ref_b,
                                                                 path_loss_exp_bounds=exp_b, solver="exact")))
    lo = [-np.inf if ref_b is None else ref_b[0], -np.inf if exp_b is None else exp_b[0]]
    hi = [np.inf if ref_b is None else ref_b[1], np.inf if exp_b is None else exp_b[1]]
    got = _params(fit)
    assert np.all(got >= lo) and np.all(got <= hi)
    closed = _params(lb.fit_path_loss_closed_form(d, p))
    active = np.any(closed < lo, axis=-1) | np.any(closed > hi, axis=-1)
    if case == "inactive":
        assert not active.any()
        np.testing.assert_array_equal(got, closed)                   # the closed form itself
    else:
        assert 40 < active.sum() < len(d) - 40                        # bounds active on many fits, not all
        np.testing.assert_array_equal(got[~active], closed[~active])
    for i in range(len(d)):                                           # scipy's active-set solver (BVLS), every fit
        keep = np.isfinite(p[i])
        ref = lsq_linear(path_loss_design_matrix(d[i, keep]), p[i, keep], bounds=(lo, hi), method="bvls", tol=1e-14).x
        np.testing.assert_allclose(got[i], ref, rtol=0, atol=1e-9)
    for i in range(0, len(d), 8):                                    # cvxpy, one fit per solve (stays tight)
        cvx = lb.fit_path_loss(d[i], p[i], ref_power_bounds_dbm=ref_b, path_loss_exp_bounds=exp_b, solver="cvxpy")
        assert cvx.status == "optimal"
        np.testing.assert_allclose(got[i], _params(cvx), rtol=0, atol=1e-6)
    # the rest of the result (residual sigma, covariance, counts) is computed as for the cvxpy fit
    cvx = lb.fit_path_loss(d[:5], p[:5], ref_power_bounds_dbm=ref_b, path_loss_exp_bounds=exp_b, solver="cvxpy")
    np.testing.assert_allclose(fit.residual_sigma_db[:5], cvx.residual_sigma_db, rtol=1e-6)
    np.testing.assert_array_equal(fit.n_samples[:5], cvx.n_samples)


def test_bounded_path_loss_fit_equals_brute_force_on_edges_and_corners():
    rng = np.random.default_rng(5)
    d = np.array([1.0, 2.5, 4.0, 6.0, 9.0])
    a, n = np.meshgrid(np.linspace(-55, -40, 1501), np.linspace(1.5, 3.0, 1501), indexing="ij")
    where = []
    for ref, exp in [(-30, 4.0), (-65, 1.0), (-30, 1.0), (-65, 4.0), (-35, 0.5), (-47, 2.2)]:   # beyond the bounds
        p = ref - 10 * exp * np.log10(d) + rng.normal(0, 1.0, 5)
        fit = lb.fit_path_loss(d, p, ref_power_bounds_dbm=(-55, -40), path_loss_exp_bounds=(1.5, 3.0))
        cost = ((p - (a[..., None] - 10 * n[..., None] * np.log10(d))) ** 2).sum(-1)
        i, j = np.unravel_index(np.argmin(cost), cost.shape)
        assert abs(fit.ref_power_dbm - a[i, j]) <= 0.0101 and abs(fit.path_loss_exp - n[i, j]) <= 0.00101
        where.append(int(fit.ref_power_dbm in (-55, -40)) + int(fit.path_loss_exp in (1.5, 3.0)))
    assert set(where) == {0, 1, 2}             # inside, on an edge, at a corner


def test_huber_stays_on_cvxpy_and_solver_choices():
    d, p = _fits(k=1)
    with pytest.raises(ValueError, match="needs solver='cvxpy'"):
        lb.fit_path_loss(d, p, loss="huber", solver="exact")
    assert lb.fit_path_loss(d, p, loss="huber", path_loss_exp_bounds=(1.5, 3.0)).status == "optimal"   # via cvxpy
    assert lb.fit_path_loss(d, p, solver="exact").status == "closed_form"         # no bounds: the closed form
    assert "exact" in calibration.CALIBRATION_SOLVERS


@pytest.mark.filterwarnings("ignore:Solution may be inaccurate")
def test_cvxpy_fit_failure_is_still_reported_not_raised(monkeypatch):
    """The oracle path keeps its failure reporting; the exact default never calls cvxpy."""
    d, p = _fits(k=3)

    def crash(problem, what):
        raise cp.error.SolverError("Clarabel crashed")

    monkeypatch.setattr(calibration, "solve", crash)
    fit = lb.fit_path_loss(d, p, path_loss_exp_bounds=(1.5, 3.0), solver="cvxpy")
    assert not fit.ok and fit.status == "solver_error" and np.isnan(fit.ref_power_dbm).all()
    assert lb.fit_path_loss(d, p, path_loss_exp_bounds=(1.5, 3.0)).ok
