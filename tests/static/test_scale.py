"""Bounded memory at any size: the chunked k-NN equals the unchunked one, and the separable grid transition
equals the dense C x C matrix, on small problems where the dense forms fit."""
import numpy as np
import pytest

from locbook import PathLossModel, RssModel, grid_bayes_filter, grid_transition_matrix, knn_position


@pytest.mark.parametrize("weighting", ["inverse_square", "uniform", "literal_ozkaya2011"])
def test_chunked_knn_equals_unchunked(weighting):
    rng = np.random.default_rng(7)
    cells = rng.uniform(0, 8, (150, 2))
    fingerprints = rng.normal(-65, 8, (150, 5))
    queries = rng.normal(-65, 8, (4, 9, 5))
    queries[0, 0, 2] = np.nan                              # one reader not heard
    queries[1, 3, [0, 4]] = np.nan
    whole = knn_position(queries, fingerprints, cells, 4, weighting, chunk=10**6)
    for chunk in (1, 7, 36):
        np.testing.assert_array_equal(knn_position(queries, fingerprints, cells, 4, weighting, chunk=chunk), whole)
    np.testing.assert_array_equal(knn_position(queries, fingerprints, cells, 4, weighting), whole)


def test_chunked_knn_with_a_map_per_query_equals_unchunked():
    rng = np.random.default_rng(8)
    cells = rng.uniform(0, 8, (40, 2))
    maps = rng.normal(-65, 8, (6, 40, 4))
    queries = rng.normal(-65, 8, (6, 4))
    whole = knn_position(queries, maps, cells, 3, chunk=6)
    np.testing.assert_array_equal(knn_position(queries, maps, cells, 3, chunk=1), whole)
    # and each query against its own map, one at a time, by the unbatched call
    for q in range(6):
        np.testing.assert_array_equal(knn_position(queries[q], maps[q], cells, 3), whole[q])


def test_knn_chunk_must_be_a_positive_integer():
    with pytest.raises(ValueError, match="chunk"):
        knn_position(np.zeros(3), np.zeros((4, 3)), np.zeros((4, 2)), 2, chunk=0)


def _masked_grid(spacing):
    xs, ys = np.arange(0, 5.0 + 1e-9, spacing), np.arange(0, 4.0 + 1e-9, spacing)
    grid = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    return grid[~((grid[:, 0] > 3.0) & (grid[:, 1] > 2.5))]        # an L-shaped floor


@pytest.mark.parametrize("spread_m", [0.1, 0.6, np.inf])
@pytest.mark.parametrize("velocity_m", [None, (0.3, -0.1)])
def test_separable_grid_transition_equals_dense(spread_m, velocity_m):
    rng = np.random.default_rng(3)
    cells = _masked_grid(0.25)
    model = RssModel(np.array([[0, 0], [5, 0], [0, 4], [5, 4.0]]), PathLossModel(-40.0, 2.5, 3.0, min_distance_m=0.1))
    rss = rng.normal(-60, 5, (3, 15, 4))
    rss[0, 3, 1] = np.nan
    rss[2, 5] = np.nan                                      # a step where nothing was heard
    dense = grid_bayes_filter(rss, model, cells, spread_m, velocity_m=velocity_m, transition="dense")
    separable = grid_bayes_filter(rss, model, cells, spread_m, velocity_m=velocity_m, transition="separable")
    np.testing.assert_allclose(separable.weights, dense.weights, rtol=1e-9, atol=1e-14)
    np.testing.assert_allclose(separable.mean, dense.mean, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(separable.map_m, dense.map_m)


def test_separable_prediction_is_the_dense_matrix_product():
    """One prediction step against the matrix of grid_transition_matrix, on irregular (not equally spaced)
    lattice coordinates."""
    from locbook.tracking.bayes import _SeparableTransition
    rng = np.random.default_rng(4)
    xs, ys = np.sort(rng.uniform(0, 4, 9)), np.sort(rng.uniform(0, 3, 7))
    cells = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)[rng.random(63) < 0.7]
    belief = rng.dirichlet(np.ones(cells.shape[0]), size=2)
    for v in ((0.0, 0.0), (0.4, 0.2)):
        expected = belief @ grid_transition_matrix(cells, 0.5, v).T
        got = _SeparableTransition(cells, 0.5).predict(belief, v)
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-16)
        np.testing.assert_allclose(got.sum(axis=-1), 1.0, rtol=1e-12)


def test_auto_transition_never_builds_the_dense_matrix_on_a_grid(monkeypatch):
    import locbook.tracking.bayes as bayes
    cells = _masked_grid(0.5)

    def refuse(*args, **kwargs):
        raise AssertionError("the dense transition was built")

    monkeypatch.setattr(bayes, "grid_transition_matrix", refuse)
    model = RssModel(np.array([[0, 0], [5, 0], [0, 4.0]]), PathLossModel(-40.0, 2.5, 3.0, min_distance_m=0.1))
    res = grid_bayes_filter(np.full((1, 4, 3), -60.0), model, cells, 0.5)
    assert np.isfinite(res.mean).all()
