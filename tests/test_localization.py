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
    np.testing.assert_allclose(a_mat, [[-4.2, 0.0], [0.0, -15.6], [-4.2, -15.6]])      # note 003, sec. 2.5
    np.testing.assert_allclose(b, [-4.41, -60.84, -65.25])
    np.testing.assert_allclose(np.linalg.pinv(a_mat), [[-0.15873, 0.07937, -0.07937], [0.02137, -0.04274, -0.02137]], atol=1e-5)


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
    for i in range(0, 50, 7):
        ref = lsq_linear(a_mat, b[i], bounds=([0, 0], [2.1, 7.8]), tol=1e-12).x
        np.testing.assert_allclose(box[i], ref, atol=1e-5)


def test_rss_ml_noiseless_and_against_scipy(points):
    model = lb.PathLossModel(-45.0, 2.1843, 3.0)
    d = lb.pairwise_distance_m(points, ANCHORS)
    exact = lb.rss_ml_position(ANCHORS, model.mean_power_dbm(d), model)
    np.testing.assert_allclose(exact.position_m, points, atol=1e-6)
    power = model.sample_power_dbm(d, np.random.default_rng(4))
    ml = lb.rss_ml_position(ANCHORS, power, model)
    assert ml.converged.all()
    for i in range(0, 50, 5):
        ref = least_squares(lambda p: power[i] - model.mean_power_dbm(lb.pairwise_distance_m(p, ANCHORS)),
                            ml.position_m[i] + 0.05, xtol=1e-12, ftol=1e-12)
        # same local minimum, and scipy cannot improve on locbook's cost
        np.testing.assert_allclose(ml.position_m[i], ref.x, atol=1e-4)
        assert ml.cost[i] <= 2 * ref.cost + 1e-9


def test_grid_ml_noiseless_picks_true_grid_point():
    model = lb.PathLossModel(-45.0, 2.0)
    grid = np.stack(np.meshgrid(np.arange(0.05, 2.1, 0.1), np.arange(0.05, 7.8, 0.1)), -1).reshape(-1, 2)
    truth = grid[[10, 200, 777]]
    res = lb.grid_ml_position(ANCHORS, model.mean_power_dbm(lb.pairwise_distance_m(truth, ANCHORS)), model, grid, chunk=2)
    np.testing.assert_allclose(res.position_m, truth)


@pytest.mark.parametrize("anchors, message", [([[0, 0], [1, 1], [2, 2], [3, 3]], "collinear"),
                                              ([[0, 0], [1, 0]], "at least 3 anchors")])
def test_degenerate_anchor_geometry_raises(anchors, message):
    anchors = np.asarray(anchors, float)
    with pytest.raises(lb.DegenerateGeometryError, match=message):
        lb.lateration_ls(anchors, np.ones(len(anchors)))
    with pytest.raises(lb.DegenerateGeometryError, match=message):
        lb.rss_ml_position(anchors, np.full(len(anchors), -60.0), lb.PathLossModel())


def test_wrong_number_of_ranges_raises():
    with pytest.raises(ValueError, match="anchors"):
        lb.lateration_ls(ANCHORS, np.ones(3))
