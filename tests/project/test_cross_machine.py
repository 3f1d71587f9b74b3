"""Results that must not depend on the machine's vector code (docs/reports.md, "Across machines").

Two causes made committed numbers move between machines of one kind: iterations stopped midway by a cap (where a
walk stops depends on the last bits of every step) and choices among exact ties (``np.argpartition`` returns ties in
an order that depends on AVX-512). Each test states the machine-independent answer from first principles.
"""
import numpy as np
import pytest

import locbook as lb
from locbook.scenarios import george


def _reference_knn(query, fingerprints, cells, k):
    """Inverse-square weighted k-NN with ties at the k-th distance broken by the lowest cell index, in plain
    Python (distances of half-integer differences are exact in floating point)."""
    d2 = [float(np.sum((f - query) ** 2)) for f in fingerprints]      # exact: sums of quarters
    order = sorted(range(len(d2)), key=lambda c: (d2[c], c))[:k]
    if min(d2[c] for c in order) == 0:
        exact = [c for c in order if d2[c] == 0]
        return cells[exact].mean(axis=0)
    w = np.array([1.0 / d2[c] for c in order])
    return (w[:, None] * cells[order]).sum(axis=0) / w.sum()


def test_knn_breaks_exact_ties_by_cell_index_whatever_the_selection_algorithm():
    rng = np.random.default_rng(4)
    # integer RSSI fingerprints of a few levels: many cells lie at exactly the same distance from a query
    fingerprints = rng.integers(-70, -66, size=(300, 3)).astype(float)
    cells = rng.uniform(0, 10, size=(300, 2))
    queries = rng.integers(-70, -66, size=(200, 3)).astype(float) + 0.5
    for k in (1, 4, 14):
        got = lb.knn_position(queries, fingerprints, cells, k)
        want = np.array([_reference_knn(q, fingerprints, cells, k) for q in queries])
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12)


def test_knn_neighbours_do_not_depend_on_the_order_of_tied_cells_in_a_block():
    # two levels per reader: most cells tie; exact matches (a query equal to fingerprints) take all the weight.
    # Blocks of one query and one block of all give the same answer, the reference's
    rng = np.random.default_rng(5)
    fingerprints = rng.integers(-60, -58, size=(64, 2)).astype(float)
    cells = rng.uniform(0, 5, size=(64, 2))
    queries = np.array([[-59.5, -59.5], [-60.0, -58.0], [-58.5, -60.0]])
    a = lb.knn_position(queries, fingerprints, cells, 5, chunk=1)
    b = lb.knn_position(queries, fingerprints, cells, 5)
    np.testing.assert_array_equal(a, b)
    want = np.array([_reference_knn(q, fingerprints, cells, 5) for q in queries])
    np.testing.assert_allclose(b, want, rtol=1e-12, atol=1e-12)


def _cost_gradient(p, anchors, power, p0_dbm, n):
    """Gradient of sum_j (P_j - P0 + 10 n log10 |p - a_j|)^2 (Dogan Eq. (2.4) up to a constant), by hand."""
    diff = p[..., None, :] - anchors
    d2 = np.sum(diff ** 2, axis=-1)
    resid = power - p0_dbm + 10 * n * np.log10(np.sqrt(d2))
    return np.sum(2 * resid[..., None] * (10 * n / np.log(10)) * diff / d2[..., None], axis=-2)


def test_rss_ml_runs_to_a_stationary_point_where_a_cap_of_100_would_stop_problems_midway():
    truth_m = george.trajectory_m("centerline")
    model = lb.PathLossModel(-45.0, george.PRINTED_N.value, 6.0)
    power = model.sample_rss_dbm(
        np.broadcast_to(lb.pairwise_distance_m(truth_m, george.ANCHORS_M), (400, 25, 4)), rng=np.random.default_rng(5))
    capped = lb.rss_ml_position(power, lb.RssModel(george.ANCHORS_M, model), max_iter=100)
    assert not capped.converged.all()                  # the workload needs more than 100 steps for some problems
    res = lb.rss_ml_position(power, lb.RssModel(george.ANCHORS_M, model))
    assert res.converged.all()
    grad = _cost_gradient(res.position_m, george.ANCHORS_M, power, -45.0, george.PRINTED_N.value)
    # at a local minimum the gradient vanishes; scale: 10 n / ln 10 dB per unit log-distance, ~ 10 dB^2 per metre
    slow = ~capped.converged
    assert np.max(np.linalg.norm(grad[slow], axis=-1)) < 1e-3
    assert np.max(np.linalg.norm(grad, axis=-1)) < 1e-3


@pytest.mark.parametrize("k", [3, 7])
def test_knn_with_distinct_distances_is_unchanged_by_the_tie_rule(k):
    # no ties (continuous fingerprints): the k nearest are the k smallest distances, as a full sort gives them
    rng = np.random.default_rng(6)
    fingerprints = rng.normal(-60, 5, size=(80, 4))
    cells = rng.uniform(0, 8, size=(80, 2))
    queries = rng.normal(-60, 5, size=(50, 4))
    d2 = np.sum((fingerprints[None] - queries[:, None]) ** 2, axis=-1)
    idx = np.argsort(d2, axis=-1, kind="stable")[:, :k]
    w = 1.0 / np.take_along_axis(d2, idx, axis=-1)
    want = np.einsum("qk,qkd->qd", w / w.sum(axis=-1, keepdims=True), cells[idx])
    np.testing.assert_allclose(lb.knn_position(queries, fingerprints, cells, k), want, rtol=1e-12, atol=1e-12)


def test_a_bracket_made_on_another_machine_of_the_same_kind_is_not_called_stale():
    """dogan2015-tracking's serial EKF RMSE was 2.833613392 here and 2.833613412 with AVX-512 off (7e-9 relative):
    the same result, so the bracket's verdict stands; a value 1e-4 away is another result (a stale bracket)."""
    from locbook.suite.bracket import bracket_of_rows

    b = {"printed_id": "p", "quantity": "q", "where": "w", "bracket": "other_interpretation", "reached_by": "r: x=1",
         "open_interpretations": "", "band_low": "1", "band_high": "2", "points": "3", "profile": "full",
         "ours": "2.833613392"}
    row = {"printed_id": "p", "quantity": "q", "where": "w", "kind": "reproduction", "verdict": "miss"}
    other_machine, stale = bracket_of_rows([{**row, "reproduced": "2.833613412"},
                                            {**row, "reproduced": "2.833896753"}], [b], "full")
    assert other_machine["bracket"] == "other_interpretation"
    assert stale["bracket"] == "open" and "disagree" in stale["bracket_interpretations"]


def test_the_kernel_map_candidates_of_tied_weights_are_taken_by_particle_index():
    """After resampling, weights take a few values, each shared by many particles (all 1/N right after it): the
    n_candidates highest-weight particles include a tie, and a non-stable sort returns tied particles in an order
    that depends on the processor. Tied candidates are now taken by index, so the estimate is the best, under the
    kernel density (computed here by hand), of the highest weights with ties broken by particle index."""
    from locbook.tracking.particle import kernel_map_estimate

    rng = np.random.default_rng(8)
    x = rng.normal(0.0, 1.0, size=(3, 500, 2))
    w = rng.integers(1, 4, size=(3, 500)).astype(float)
    w /= w.sum(axis=-1, keepdims=True)
    order = [sorted(range(500), key=lambda i: (-w[r, i], i))[:16] for r in range(3)]
    got = kernel_map_estimate(x, w, bandwidth_m=0.3, n_candidates=16)
    cand = np.stack([x[r, order[r]] for r in range(3)])
    d2 = np.sum((cand[:, :, None] - x[:, None]) ** 2, axis=-1)
    dens = np.einsum("rkn,rn->rk", np.exp(-0.5 * d2 / 0.3 ** 2), w)
    np.testing.assert_array_equal(got, cand[np.arange(3), np.argmax(dens, axis=-1)])
