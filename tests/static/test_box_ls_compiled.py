"""The compiled box-LS search (the aim: box-LS within 2x of the closed-form linear LS).

:func:`locbook.static._box_kernels._nb_box_ls` runs the KKT active-set search of
:func:`locbook.static.box_ls._box_active_set_search` problem by problem in numba. It must give the numpy
search's answers to 1e-12 (same sets, order, acceptance rule, tie-breaking and fallback), keep ``p*`` bit for bit
inside the box, keep the missing-reading and overflow rules, and be switched off by ``_NUMBA_ENABLED``.
Independent oracles: scipy's ``lsq_linear`` (BVLS) and the KKT conditions checked on the answer.
"""

import numpy as np
import pytest
from scipy.optimize import lsq_linear

import locbook as lb
from locbook.static import box_ls
from locbook.tracking import _compiled

pytestmark = pytest.mark.compiled

pytest.importorskip("numba")

ROOMS = {2: (np.array([0.0, 0.0]), np.array([2.1, 7.8])),
         3: (np.array([0.0, 0.0, 0.0]), np.array([10.0, 8.0, 3.0]))}


def _problems(dim, k, seed):
    """Anchors around the room, tags in it and up to three room sizes outside, ranges with 25 % errors."""
    rng = np.random.default_rng(seed)
    lo, hi = ROOMS[dim]
    size = hi - lo
    corners = np.array(np.meshgrid(*[[a, b] for a, b in zip(lo, hi)], indexing="ij")).reshape(dim, -1).T
    anchors = np.concatenate([corners, rng.uniform(lo, hi, (2, dim))]) + rng.normal(0, 0.3, (corners.shape[0] + 2, dim))
    truth = np.where(rng.random((k, 1)) < 0.6, rng.uniform(lo, hi, (k, dim)),
                     rng.uniform(lo - 3 * size, hi + 3 * size, (k, dim)))
    d = lb.pairwise_distance_m(truth, anchors) * rng.uniform(0.75, 1.25, (k, anchors.shape[0]))
    return anchors, d, lo, hi


def _both(monkeypatch, fn):
    """``fn()`` with the compiled search (forced: no minimum size, the numpy search must not run) and with numpy."""
    monkeypatch.setattr(box_ls, "_BOX_NUMBA_MIN_PROBLEMS", 0)
    numpy_search = box_ls._box_active_set_search

    def must_not_run(*args):
        raise AssertionError("the numpy search ran on the compiled path")

    monkeypatch.setattr(_compiled, "_NUMBA_ENABLED", True)
    monkeypatch.setattr(box_ls, "_box_active_set_search", must_not_run)
    compiled = fn()
    monkeypatch.setattr(box_ls, "_box_active_set_search", numpy_search)
    monkeypatch.setattr(_compiled, "_NUMBA_ENABLED", False)
    return compiled, fn()


def _exact(a_mat, b, lo, hi):
    return box_ls._box_ls_exact(a_mat, b, tuple(map(float, lo)), tuple(map(float, hi)))


def _kkt_holds(a_mat, b, p, lo, hi, tol=1e-7):
    """The KKT certificate of ``min |A p - b|^2`` over the box: within the box, the gradient ``A^T (A p - b)``
    (scaled by ``max |A^T A|``) zero on free coordinates, >= 0 at a lower and <= 0 at an upper bound."""
    g = ((p @ a_mat.T - b) @ a_mat) / np.abs(a_mat.T @ a_mat).max()
    scale = 1 + np.abs(b).max(axis=-1, keepdims=True)
    at_lo, at_hi = np.abs(p - lo) < 1e-9, np.abs(p - hi) < 1e-9
    free = ~at_lo & ~at_hi
    return (np.all((p >= lo - 1e-12) & (p <= hi + 1e-12))
            and np.all(np.abs(g[free]) <= tol * np.broadcast_to(scale, g.shape)[free])
            and np.all(g[at_lo & ~at_hi] >= -tol * np.broadcast_to(scale, g.shape)[at_lo & ~at_hi])
            and np.all(g[at_hi & ~at_lo] <= tol * np.broadcast_to(scale, g.shape)[at_hi & ~at_lo]))


@pytest.mark.parametrize("dim", [2, 3])
def test_compiled_search_equals_numpy_search_and_bvls(monkeypatch, dim):
    anchors, d, lo, hi = _problems(dim, 3000, seed=10 + dim)
    a_mat, b = lb.lateration_system(anchors, d)
    (pos_c, ok_c), (pos_n, ok_n) = _both(monkeypatch, lambda: _exact(a_mat, b, lo, hi))
    assert ok_c.all() and ok_n.all()
    np.testing.assert_allclose(pos_c, pos_n, rtol=0, atol=1e-12)
    p_star = b @ np.linalg.pinv(a_mat).T
    inside = np.all((p_star >= lo) & (p_star <= hi), axis=-1)
    assert 0.2 < inside.mean() < 0.8
    np.testing.assert_array_equal(pos_c[inside], lb.lateration_ls(anchors, d).position_m[inside])   # bit for bit
    n_bound = np.sum((pos_c == lo) | (pos_c == hi), axis=-1)
    assert set(np.unique(n_bound).tolist()) == set(range(dim + 1))      # every number of active bounds occurs
    assert _kkt_holds(a_mat, b, pos_c, lo, hi)
    for i in np.flatnonzero(~inside)[::40]:                            # an independent active-set method
        ref = lsq_linear(a_mat, b[i], bounds=(lo, hi), method="bvls", tol=1e-14).x
        np.testing.assert_allclose(pos_c[i], ref, rtol=0, atol=1e-9)


@pytest.mark.parametrize("dim", [2, 3])
def test_corners_edges_and_faces(monkeypatch, dim):
    """Unconstrained minimisers exactly on the box's corners, edges and faces, a rounding step outside them, and
    along the diagonals far away: the two searches agree and the answer is the projection-free BVLS one."""
    anchors, _, lo, hi = _problems(dim, 1, seed=20 + dim)
    a_mat, _ = lb.lateration_system(anchors, np.ones(anchors.shape[0]))
    levels = [np.array([lo[j], (lo[j] + hi[j]) / 2, hi[j]]) for j in range(dim)]
    grid = np.array(np.meshgrid(*levels, indexing="ij")).reshape(dim, -1).T          # corners, edge/face midpoints
    size = hi - lo
    targets = np.concatenate([grid, np.nextafter(grid, grid + np.sign(grid - (lo + hi) / 2) + (grid == (lo + hi) / 2)),
                              grid + 1e-9 * size, grid - 1e-9 * size,
                              (lo + hi) / 2 + np.outer(np.linspace(-50, 50, 41), size)])
    # b with the unconstrained minimiser at the target, plus a residual orthogonal to A's columns
    rng = np.random.default_rng(dim)
    q, _ = np.linalg.qr(a_mat, mode="complete")
    b = targets @ a_mat.T + rng.normal(0, 3.0, (len(targets), a_mat.shape[0] - dim)) @ q[:, dim:].T
    (pos_c, ok_c), (pos_n, ok_n) = _both(monkeypatch, lambda: _exact(a_mat, b, lo, hi))
    assert ok_c.all() and ok_n.all()
    np.testing.assert_allclose(pos_c, pos_n, rtol=0, atol=1e-12)
    assert np.all((pos_c >= lo) & (pos_c <= hi))
    for i in range(len(targets)):
        ref = lsq_linear(a_mat, b[i], bounds=(lo, hi), method="bvls", tol=1e-14).x
        # 1e-7: a minimiser 1e-9 room sizes outside a face is within the search's relative tolerance (1e-9) of it
        np.testing.assert_allclose(pos_c[i], ref, rtol=0, atol=1e-7)


def test_degenerate_box_and_rank_deficient_matrix(monkeypatch):
    """A box of zero width on one coordinate (lower == upper: both bounds active at once, the first set in order
    wins) and a rank-deficient ``A`` (many minimisers: the first KKT set's one): the two searches agree."""
    rng = np.random.default_rng(3)
    anchors, d, lo, hi = _problems(3, 800, seed=30)
    a_mat, b = lb.lateration_system(anchors, d)
    flat_lo, flat_hi = lo.copy(), hi.copy()
    flat_hi[2] = flat_lo[2] = 1.5
    (pos_c, _), (pos_n, _) = _both(monkeypatch, lambda: _exact(a_mat, b, flat_lo, flat_hi))
    np.testing.assert_allclose(pos_c, pos_n, rtol=0, atol=1e-12)
    assert np.all(pos_c[:, 2] == 1.5)
    rank1 = np.array([[1.0, 2.0], [2.0, 4.0], [-1.0, -2.0]])       # only x + 2 y is determined
    b1 = rng.normal(0.0, 20.0, (500, 3))
    (pos_c, ok_c), (pos_n, ok_n) = _both(monkeypatch, lambda: _exact(rank1, b1, (0.0, -1.0), (3.0, 2.0)))
    assert ok_c.all() and ok_n.all()
    np.testing.assert_allclose(pos_c, pos_n, rtol=0, atol=1e-12)
    # the objective is the least over the box: that of BVLS (its minimiser may differ where A is singular)
    ref = np.array([lsq_linear(rank1, row, bounds=((0.0, -1.0), (3.0, 2.0)), method="bvls", tol=1e-14).x
                    for row in b1[::25]])
    obj = lambda p, bb: np.sum((p @ rank1.T - bb) ** 2, axis=-1)
    np.testing.assert_allclose(obj(pos_c[::25], b1[::25]), obj(ref, b1[::25]), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("dim", [2, 3])
def test_compiled_fallback_is_the_least_feasible_candidate(dim):
    """The fallback (no KKT candidate, forced) in the kernel equals the numpy fallback and BVLS."""
    from locbook.static import _box_kernels
    anchors, d, lo, hi = _problems(dim, 400, seed=40 + dim)
    a_mat, b = lb.lateration_system(anchors, d)
    key = tuple(map(tuple, a_mat.tolist()))
    pinv_t, levels = box_ls._box_active_sets(key, tuple(lo), tuple(hi))
    p_star = b @ pinv_t
    outside = np.any((p_star < lo) | (p_star > hi), axis=-1)
    spoiled = []
    for weights, offsets, n_sets in levels:
        per_set = weights.shape[0] // n_sets
        kkt_row = (np.arange(weights.shape[0]) % per_set) < per_set - dim
        spoiled.append((weights, offsets - 1e6 * kkt_row[:, None], n_sets))
    want = box_ls._box_active_set_search(p_star[outside], lo, hi, spoiled, a_mat)
    pos, ok = np.empty(p_star.shape), np.empty(len(b), bool)
    tables = box_ls._box_kernel_tables(key, tuple(lo), tuple(hi))
    bound = float(np.max(np.maximum(np.abs(lo), np.abs(hi))))
    _box_kernels._nb_box_ls(p_star, lo, hi, bound, *tables, a_mat, True, pos, ok)
    np.testing.assert_allclose(pos[outside], want, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(pos[~outside], p_star[~outside])
    for i in np.flatnonzero(outside)[::10]:
        ref = lsq_linear(a_mat, b[i], bounds=(lo, hi), method="bvls", tol=1e-14).x
        np.testing.assert_allclose(pos[i], ref, rtol=0, atol=1e-9)
    # the kernel's plain-Python source (what runs without numba) does the same arithmetic
    pos_py, ok_py = np.empty((40, dim)), np.empty(40, bool)
    _box_kernels._nb_box_ls.py_func(p_star[:40], lo, hi, bound, *tables, a_mat, False, pos_py, ok_py)
    pos_nb, ok_nb = np.empty((40, dim)), np.empty(40, bool)
    _box_kernels._nb_box_ls(p_star[:40], lo, hi, bound, *tables, a_mat, False, pos_nb, ok_nb)
    np.testing.assert_array_equal(pos_py, pos_nb)
    assert ok_py.all() and ok_nb.all()


def test_missing_readings_and_overflow_through_the_compiled_path(monkeypatch):
    anchors, d, lo, hi = _problems(3, 600, seed=50)
    holed = d.copy()
    rng = np.random.default_rng(5)
    holed[rng.random(holed.shape) < 0.08] = np.nan          # anchors not heard, some problems with too few
    holed[7, :-2] = np.nan
    holed[9, 0] = 1e200                                     # squares to infinity: solver_failed alone
    with np.errstate(over="ignore", invalid="ignore"):
        compiled, numpy_ = _both(monkeypatch, lambda: lb.lateration_box_ls(anchors, holed, lo, hi))
    np.testing.assert_array_equal(compiled.status, numpy_.status)
    np.testing.assert_array_equal(compiled.converged, numpy_.converged)
    np.testing.assert_allclose(compiled.position_m, numpy_.position_m, rtol=0, atol=1e-12)   # NaN where NaN
    assert compiled.status[7] == "too_few_anchors" and compiled.status[9] == "solver_failed"
    assert np.isnan(compiled.position_m[[7, 9]]).all()
    assert np.sum(np.isnan(holed).any(axis=-1)) > 100 and np.sum(compiled.status == "ok") > 400


def test_non_finite_unconstrained_fix_fails_alone(monkeypatch):
    """``p*`` not finite (NaN or infinite) gives NaN and ok False on both paths, the others are untouched."""
    a_mat, b = lb.lateration_system(*_problems(2, 300, seed=60)[:2])
    b[3] = np.inf                                           # p* NaN (inf - inf)
    b[11, 0] = -np.inf                                      # p* infinite
    lo, hi = ROOMS[2]
    with np.errstate(over="ignore", invalid="ignore"):
        (pos_c, ok_c), (pos_n, ok_n) = _both(monkeypatch, lambda: _exact(a_mat, b, lo, hi))
    np.testing.assert_array_equal(ok_c, ok_n)
    assert not ok_c[[3, 11]].any() and ok_c.sum() == 298
    np.testing.assert_allclose(pos_c, pos_n, rtol=0, atol=1e-12)
    assert np.isnan(pos_c[[3, 11]]).all()


def test_switch_and_minimum_size_select_numpy(monkeypatch):
    anchors, d, lo, hi = _problems(2, 300, seed=70)
    calls = []
    numpy_search = box_ls._box_active_set_search
    monkeypatch.setattr(box_ls, "_box_active_set_search", lambda *a: calls.append(1) or numpy_search(*a))
    monkeypatch.setattr(_compiled, "_NUMBA_ENABLED", False)
    lb.lateration_box_ls(anchors, d, lo, hi)
    assert calls == [1]                                             # LOCBOOK_NUMBA=0: numpy
    monkeypatch.setattr(_compiled, "_NUMBA_ENABLED", True)
    monkeypatch.setattr(box_ls, "_BOX_NUMBA_MIN_PROBLEMS", 301)
    lb.lateration_box_ls(anchors, d, lo, hi)
    assert calls == [1, 1]                                          # too few problems: numpy
    monkeypatch.setattr(box_ls, "_BOX_NUMBA_MIN_PROBLEMS", 300)
    lb.lateration_box_ls(anchors, d, lo, hi)
    assert calls == [1, 1]                                          # compiled


@pytest.mark.parametrize("dim", [2, 3])
def test_the_guided_set_of_each_pattern_holds_those_coordinates_at_those_bounds(dim):
    """``_box_guided_sets`` maps every free/lower/upper pattern to the active set whose candidate holds exactly those
    coordinates at those bounds (whatever p*), and ``_box_guided_code`` reads the pattern off p*."""
    from itertools import product
    rng = np.random.default_rng(dim)
    a_mat = rng.normal(size=(dim + 2, dim))
    lo, hi = -rng.uniform(1, 2, dim), rng.uniform(1, 2, dim)
    weights, offsets, start, n_kkt, guided = box_ls._box_kernel_tables(
        tuple(map(tuple, a_mat.tolist())), tuple(lo), tuple(hi))
    assert guided[0] == -1 and sorted(guided[1:]) == list(range(3**dim - 1))
    p = rng.normal(size=dim) * 5
    for code, kinds in enumerate(product((0, 1, 2), repeat=dim)):
        if code == 0:
            continue
        s = guided[code]
        r0 = start[s] + n_kkt[s]
        cand = weights[r0:r0 + dim] @ p + offsets[r0:r0 + dim]
        for j, kind in enumerate(kinds):
            if kind:
                assert cand[j] == (lo[j] if kind == 1 else hi[j])
        assert n_kkt[s] == 2 * dim - sum(k > 0 for k in kinds)
        outside = np.where(np.array(kinds) == 1, lo - 1.0, np.where(np.array(kinds) == 2, hi + 1.0, 0.5 * (lo + hi)))
        assert box_ls._box_guided_code(outside[None], lo, hi)[0] == code
