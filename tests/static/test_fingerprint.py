"""Fingerprinting (locbook.static.fingerprint): the k-nearest-neighbour estimate against hand computations, and
model fingerprints against the path-loss model they come from."""
import numpy as np
import pytest

import locbook as lb

#: three readers in a 5 m x 8 m room (those of tests/tracking/test_bayes_particle.py)
READERS = np.array([[0.0, 0.0], [5.0, 0.0], [0.0, 8.0]])


# -- nearest neighbour ---------------------------------------------------------------------------------
def test_knn_inverse_square_weights_by_hand():
    cells = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0], [5.0, 5.0]])
    fp = np.array([[-50.0, -60.0], [-52.0, -60.0], [-50.0, -63.0], [-80.0, -80.0]])
    s = np.array([-51.0, -60.0])
    # E^2 = 1, 1, 10, ...: weights (1, 1, 0.1) / 2.1
    expected = (cells[0] + cells[1] + 0.1 * cells[2]) / 2.1
    np.testing.assert_allclose(lb.knn_position(s, fp, cells, k=3), expected, rtol=1e-12)
    # k = 1 with a tie (E^2 = 1 for cells 0 and 1): exactly one of the tied cells, not a blend or another cell
    assert lb.knn_position(s, fp, cells, k=1).tolist() in (cells[0].tolist(), cells[1].tolist())
    # k = 1 without a tie is the nearest cell itself (E^2 = 2.25, 0.25, 11.25, ...)
    np.testing.assert_array_equal(lb.knn_position(np.array([-51.5, -60.0]), fp, cells, k=1), cells[1])
    np.testing.assert_array_equal(lb.knn_position(np.array([-50.0, -62.0]), fp, cells, k=1), cells[2])
    # k = 2: cells 1 and 0 with weights (1/0.25, 1/2.25) normalised = (0.9, 0.1)
    np.testing.assert_allclose(lb.knn_position(np.array([-51.5, -60.0]), fp, cells, k=2),
                               0.9 * cells[1] + 0.1 * cells[0], rtol=1e-12)
    # literal Eq. (3.3): (1/E^2) / sum E^2 = (1, 1, 0.1) / 12
    np.testing.assert_allclose(lb.knn_position(s, fp, cells, k=3, weighting="literal_ozkaya2011"), 2.1 * expected / 12)


def test_knn_exact_match_and_batched_maps():
    cells = np.array([[0.0, 0.0], [1.0, 2.0], [3.0, 1.0]])
    fp = np.array([[-40.0, -50.0], [-45.0, -55.0], [-60.0, -45.0]])
    np.testing.assert_allclose(lb.knn_position(fp[1], fp, cells, k=3), cells[1])
    maps = np.stack([fp, fp[::-1]])                    # one map per batch entry
    out = lb.knn_position(np.stack([fp[0], fp[0]]), maps, cells, k=1)
    np.testing.assert_allclose(out, [cells[0], cells[2]])
    with pytest.raises(ValueError, match="k must be"):
        lb.knn_position(fp[0], fp, cells, k=4)


def test_model_fingerprints_match_path_loss_model():
    model = lb.PathLossModel(np.array([-42.0, -52.0, -45.0]), np.array([2.3, 2.3, 2.5]), wall_attenuation_db=2.0)
    cells = np.array([[1.0, 1.0], [4.0, 3.0]])
    walls = [[[3.0, -1.0], [3.0, 9.0]]]
    fp = lb.model_fingerprints(cells, lb.RssModel(READERS, model, walls))
    expected = model.mean_rss_dbm(lb.pairwise_distance_m(cells, READERS),
                                    lb.wall_crossings(cells, READERS, walls))
    np.testing.assert_allclose(fp, expected)


def test_knn_for_several_k_at_once_equals_one_call_per_k_bit_for_bit():
    """knn_position_per_k computes the RSSI-space distances once for every k; each of its rows must be the single-k
    knn_position of that k, to the last bit: integer fingerprints (ties at the k-th distance), readers not heard,
    every weighting, blocks of any size."""
    from locbook.static.fingerprint import knn_position_per_k
    rng = np.random.default_rng(1)
    for trial in range(60):
        cells_n, readers, queries = rng.integers(2, 60), rng.integers(3, 7), rng.integers(1, 50)
        fingerprints = np.round(rng.normal(-60.0, 8.0, (cells_n, readers)))
        cells = rng.uniform(0.0, 10.0, (cells_n, 2))
        rss = np.round(rng.normal(-60.0, 8.0, (queries, readers)))
        rss[rng.random(rss.shape) < 0.25] = np.nan
        ks = [k for k in (1, 2, 3, 5, 8, 20, 50) if k <= cells_n]
        for weighting in ("inverse_square", "uniform"):
            every = knn_position_per_k(rss, fingerprints, cells, ks, weighting, chunk=int(rng.integers(1, 20)))
            assert every.shape == (len(ks), queries, 2)
            for row, k in zip(every, ks):
                np.testing.assert_array_equal(row, lb.knn_position(rss, fingerprints, cells, k, weighting))
    with pytest.raises(ValueError, match="k must be between 1 and the number of cells"):
        knn_position_per_k(rss, fingerprints, cells, [1, cells_n + 1])
