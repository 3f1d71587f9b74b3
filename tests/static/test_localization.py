"""Static localization: exact recovery, agreement with scipy on the same inputs, geometry errors."""
import numpy as np
import pytest
from scipy.optimize import least_squares, lsq_linear

import locbook as lb
from locbook.scenarios import george

ANCHORS = george.ANCHORS_M


@pytest.fixture
def points():
    return np.random.default_rng(2).uniform([0, 0], [2.1, 7.8], (50, 2))


@pytest.mark.parametrize("ref", [0, 1, 2, 3])
def test_lateration_exact_ranges(points, ref):
    d = lb.pairwise_distance_m(points, ANCHORS)
    np.testing.assert_allclose(lb.lateration_ls(ANCHORS, d, ref_index=ref).position_m, points, atol=1e-9)


def test_lateration_system_matches_paper_numbers():
    a_mat, b = lb.lateration_system(ANCHORS, np.zeros(4))
    np.testing.assert_allclose(a_mat, [[-4.2, 0.0], [0.0, -15.6], [-4.2, -15.6]])      # Eq. (8), 2 (x_1 - x_i)
    np.testing.assert_allclose(b, [-4.41, -60.84, -65.25])
    np.testing.assert_allclose(np.linalg.pinv(a_mat), [[-0.15873, 0.07937, -0.07937], [0.02137, -0.04274, -0.02137]],
                               atol=1e-5)


def test_wls_unit_weights_is_ls_and_weights_match_lstsq(points):
    d = lb.pairwise_distance_m(points, ANCHORS) * np.random.default_rng(0).uniform(0.8, 1.2, (50, 4))
    np.testing.assert_allclose(lb.lateration_wls(ANCHORS, d, np.ones(3)).position_m,
                               lb.lateration_ls(ANCHORS, d).position_m, atol=1e-10)
    w = np.array([1.0, 4.0, 0.25])
    a_mat, b = lb.lateration_system(ANCHORS, d)
    ref = np.linalg.lstsq(np.sqrt(w)[:, None] * a_mat, (np.sqrt(w) * b[0]), rcond=None)[0]
    np.testing.assert_allclose(lb.lateration_wls(ANCHORS, d, w).position_m[0], ref, atol=1e-10)


def test_box_ls_equals_scipy_lsq_linear(points):
    d = lb.pairwise_distance_m(points, ANCHORS) * np.random.default_rng(1).uniform(0.6, 1.6, (50, 4))
    box = lb.lateration_box_ls(ANCHORS, d, [0, 0], [2.1, 7.8]).position_m
    a_mat, b = lb.lateration_system(ANCHORS, d)
    active = 0
    for i in range(0, 50, 7):
        ref = lsq_linear(a_mat, b[i], bounds=([0, 0], [2.1, 7.8]), tol=1e-12).x
        np.testing.assert_allclose(box[i], ref, atol=1e-5)
        active += bool(np.any(np.isclose(ref, [0, 0]) | np.isclose(ref, [2.1, 7.8])))
    assert active >= 2                  # the box binds on some of the compared problems (else this is plain LS)


ML_MODEL = lb.PathLossModel(-45.0, 2.1843, 3.0)


@pytest.fixture(scope="module")
def ml_problems():
    """50 noisy RSS problems and their global minima found without locbook: a brute-force grid of the cost over
    the corridor and 3 m around it, then scipy's least_squares from the true position and the 3 best grid points."""
    points = np.random.default_rng(2).uniform([0, 0], [2.1, 7.8], (50, 2))
    power = ML_MODEL.sample_rss_dbm(lb.pairwise_distance_m(points, ANCHORS), rng=np.random.default_rng(4))
    xs, ys = np.meshgrid(np.arange(-2.95, 5.1, 0.3), np.arange(-2.95, 10.8, 0.3))    # never on an anchor
    grid = np.stack([xs.ravel(), ys.ravel()], -1)
    grid_mean = ML_MODEL.mean_rss_dbm(lb.pairwise_distance_m(grid, ANCHORS))
    best_cells = np.argsort(np.sum((power[:, None, :] - grid_mean[None]) ** 2, -1), axis=1)[:, :3]
    best_x, best_cost = np.empty((50, 2)), np.empty(50)
    for i in range(50):
        resid = lambda p: power[i] - ML_MODEL.mean_rss_dbm(lb.pairwise_distance_m(p, ANCHORS))
        runs = [least_squares(resid, start, xtol=1e-12, ftol=1e-12, gtol=1e-12)
                for start in [points[i], *grid[best_cells[i]]]]
        best = min(runs, key=lambda r: r.cost)
        best_x[i], best_cost[i] = best.x, 2 * best.cost          # scipy's cost is half the sum of squares
    return dict(points=points, power=power, grid_start=grid[best_cells[:, 0]], best_x=best_x, best_cost=best_cost)


def test_rss_ml_noiseless_and_against_scipy(points, ml_problems):
    model = ML_MODEL
    d = lb.pairwise_distance_m(points, ANCHORS)
    exact = lb.rss_ml_position(model.mean_rss_dbm(d), lb.RssModel(ANCHORS, model))
    np.testing.assert_allclose(exact.position_m, points, atol=1e-6)
    power = model.sample_rss_dbm(d, rng=np.random.default_rng(4))
    np.testing.assert_array_equal(power, ml_problems["power"])
    ml = lb.rss_ml_position(power, lb.RssModel(ANCHORS, model))
    assert ml.converged.all()
    for i in range(0, 50, 5):
        ref = least_squares(lambda p: power[i] - model.mean_rss_dbm(lb.pairwise_distance_m(p, ANCHORS)),
                            ml.position_m[i] + 0.05, xtol=1e-12, ftol=1e-12)
        # same local minimum, and scipy cannot improve on locbook's cost
        np.testing.assert_allclose(ml.position_m[i], ref.x, atol=1e-4)
        assert ml.cost[i] <= 2 * ref.cost + 1e-9
    # locbook's cost is the sum of squared residuals at its position, recomputed here
    resid = power - model.mean_rss_dbm(lb.pairwise_distance_m(ml.position_m[:, None, :], ANCHORS)[:, 0])
    np.testing.assert_allclose(ml.cost, np.sum(resid**2, -1), rtol=1e-9)
    # started in the global basin (the best brute-force grid point, not locbook's answer), locbook's iteration
    # reaches the global minimum that scipy found from independent starts, for every problem
    best_x, best_cost = ml_problems["best_x"], ml_problems["best_cost"]
    from_grid = lb.rss_ml_position(power, lb.RssModel(ANCHORS, model), initial_m=ml_problems["grid_start"])
    assert from_grid.converged.all()
    assert np.all(from_grid.cost <= best_cost * (1 + 1e-9) + 1e-9)
    np.testing.assert_allclose(from_grid.position_m, best_x, atol=1e-4)


def test_rss_ml_converged_means_a_stationary_point_of_the_cost(ml_problems):
    """The estimator is local, as its docstring says: from the default convex (linearized-LS) start it may stop in
    a local minimum (here some problems do: their cost exceeds the global one scipy finds from independent
    starts). What ``converged`` promises is a local minimum: the cost's gradient, taken here by central
    differences (independent of locbook's Jacobian), vanishes, and no nearby point is lower."""
    power = ml_problems["power"]
    ml = lb.rss_ml_position(power, lb.RssModel(ANCHORS, ML_MODEL))
    assert ml.converged.all()
    cost = lambda p: np.sum((power - ML_MODEL.mean_rss_dbm(lb.pairwise_distance_m(p[:, None, :], ANCHORS)[:, 0])) ** 2,
                            -1)
    h = 1e-6
    for axis in (0, 1):
        step = np.zeros(2)
        step[axis] = h
        grad = (cost(ml.position_m + step) - cost(ml.position_m - step)) / (2 * h)
        assert np.all(np.abs(grad) <= 1e-4 * (1 + ml.cost)), np.abs(grad).max()
    for angle in np.linspace(0, 2 * np.pi, 8, endpoint=False):
        assert np.all(cost(ml.position_m + 1e-3 * np.array([np.cos(angle), np.sin(angle)])) >= ml.cost - 1e-12)
    local = ml.cost > ml_problems["best_cost"] * (1 + 1e-9) + 1e-9
    assert local.any()          # the fixture holds problems where the convex start is not in the global basin


def test_grid_ml_noiseless_picks_true_grid_point():
    model = lb.PathLossModel(-45.0, 2.0)
    grid = np.stack(np.meshgrid(np.arange(0.05, 2.1, 0.1), np.arange(0.05, 7.8, 0.1)), -1).reshape(-1, 2)
    truth = grid[[10, 200, 777]]
    res = lb.grid_ml_position(model.mean_rss_dbm(lb.pairwise_distance_m(truth, ANCHORS)), lb.RssModel(ANCHORS, model),
                              grid, chunk=2)
    np.testing.assert_allclose(res.position_m, truth)


@pytest.mark.parametrize("anchors, message", [([[0, 0], [1, 1], [2, 2], [3, 3]], "collinear"),
                                              ([[0, 0], [1, 0]], "at least 3 anchors")])
def test_degenerate_anchor_geometry_raises(anchors, message):
    anchors = np.asarray(anchors, float)
    with pytest.raises(lb.DegenerateGeometryError, match=message):
        lb.lateration_ls(anchors, np.ones(len(anchors)))
    with pytest.raises(lb.DegenerateGeometryError, match=message):
        lb.rss_ml_position(np.full(len(anchors), -60.0), lb.RssModel(anchors, lb.PathLossModel(-40.0, 2.0)))


def test_wrong_number_of_ranges_raises():
    with pytest.raises(ValueError, match="anchors"):
        lb.lateration_ls(ANCHORS, np.ones(3))


def test_rss_ml_on_a_box_is_the_bounded_optimum_of_scipy():
    """region_m: the projected LM equals scipy's L-BFGS-B on the same cost with the same bounds where the free
    optimum lies outside the box, and changes nothing where it lies inside."""
    from scipy.optimize import minimize
    anchors = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    model = lb.PathLossModel(-40.0, 2.5, 4.0)
    rng = np.random.default_rng(3)
    box = ([1.0, 1.0], [9.0, 9.0])                   # the anchors outside it: no distance is ever 0
    for true in ([12.0, 5.0], [4.0, -3.0], [11.5, 11.0], [3.0, 7.0]):
        rss = model.mean_rss_dbm(np.linalg.norm(np.array(true) - anchors, axis=1)) + rng.normal(0, 1.0, 4)
        cost = lambda p: np.sum((rss - model.mean_rss_dbm(np.linalg.norm(p - anchors, axis=1))) ** 2)
        ref = minimize(cost, [5.0, 5.0], method="L-BFGS-B", bounds=[(1, 9), (1, 9)],
                       options=dict(ftol=1e-15, gtol=1e-10))
        got = lb.rss_ml_position(rss, lb.RssModel(anchors, model), np.array([5.0, 5.0]), region_m=box)
        assert got.status == "ok"
        np.testing.assert_allclose(got.position_m, ref.x, atol=1e-4)
        free = lb.rss_ml_position(rss, lb.RssModel(anchors, model), np.array([5.0, 5.0]))
        inside = np.all((free.position_m >= 1) & (free.position_m <= 9))
        assert inside == (true == [3.0, 7.0])
        if inside:
            np.testing.assert_allclose(got.position_m, free.position_m, atol=1e-9)
    with pytest.raises(ValueError, match="lower < upper"):
        lb.rss_ml_position(rss, lb.RssModel(anchors, model), region_m=([1.0, 1.0], [1.0, 9.0]))


def test_rss_ml_on_a_box_converges_to_points_where_the_projected_gradient_vanishes():
    """500 random boxed problems (true positions inside and outside the box, 6 dB shadowing): every one converges,
    stays in the box, and ends where the cost's projected gradient (central differences) is zero."""
    rng = np.random.default_rng(0)
    anchors = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    model = lb.PathLossModel(-40.0, 2.5, 6.0)
    true = rng.uniform(-6, 16, (500, 2))
    rss = model.mean_rss_dbm(np.linalg.norm(true[:, None] - anchors, axis=-1)) + rng.normal(0, 6, (500, 4))
    lower, upper = np.array([1.0, 1.0]), np.array([9.0, 9.0])
    res = lb.rss_ml_position(rss, lb.RssModel(anchors, model), np.full((500, 2), 5.0), region_m=(lower, upper))
    assert np.all(res.converged)            # (a few are "poor_fit": converged on readings 6 dB noise rarely gives)
    p = res.position_m
    assert np.all((p >= lower) & (p <= upper))
    cost = lambda q: np.sum((rss - model.mean_rss_dbm(np.linalg.norm(q[:, None] - anchors, axis=-1))) ** 2, axis=-1)
    h = 1e-6
    grad = np.stack([(cost(p + h * e) - cost(p - h * e)) / (2 * h) for e in np.eye(2)], axis=-1)
    # on a bound the gradient may point out of the box (the constraint holds it); elsewhere it must vanish
    out = ((p <= lower) & (grad > 0)) | ((p >= upper) & (grad < 0))
    assert np.max(np.abs(np.where(out, 0.0, grad))) < 1e-3
