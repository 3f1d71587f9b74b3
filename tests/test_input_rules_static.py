"""The missing-reading rule and input checks of the static estimators (issue 12).

Independent facts used: a problem with a missing anchor equals the same estimator run on the heard anchors
only; problems of a batch are independent, so a NaN in one leaves the others bit-identical.
"""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import locbook as lb
from locbook import localization

ANCHORS = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 8.0], [0.0, 8.0], [5.0, 12.0]])
MODEL = lb.PathLossModel(-45.0, 2.5, 4.0)
BOX = ([-1.0, -1.0], [11.0, 13.0])


def _batch(n=40, seed=3):
    rng = np.random.default_rng(seed)
    truth = rng.uniform([0, 0], [10, 12], (n, 2))
    power = MODEL.sample_power_dbm(lb.pairwise_distance_m(truth, ANCHORS), rng)
    return truth, power


ESTIMATORS = {
    "ls": lambda a, p, **kw: lb.lateration_ls(a, MODEL.range_m(p), **kw),
    "wls": lambda a, p, **kw: lb.lateration_wls(a, MODEL.range_m(p), np.arange(1.0, a.shape[0]), **kw),
    "box": lambda a, p, **kw: lb.lateration_box_ls(a, MODEL.range_m(p), *BOX, **kw),
    "ml": lambda a, p, **kw: lb.rss_ml_position(a, p, MODEL, **kw),
    "grid": lambda a, p, **kw: lb.grid_ml_position(a, p, MODEL, np.stack(np.meshgrid(np.arange(0, 10.5, 0.5),
                                                                                 np.arange(0, 12.5, 0.5)), -1).reshape(-1, 2), **kw),
}


@pytest.mark.parametrize("name", ["ls", "box", "ml", "grid"])
def test_missing_anchor_equals_the_heard_subset_and_leaves_the_batch_alone(name):
    est = ESTIMATORS[name]
    _, power = _batch()
    full = est(ANCHORS, power)
    holed = power.copy()
    holed[5, 2] = np.nan                         # anchor 2 not heard in problem 5
    holed[9, [0, 1, 3]] = np.nan                 # problem 9 heard only two anchors
    res = est(ANCHORS, holed)
    keep = np.setdiff1d(np.arange(len(power)), [5, 9])
    if name == "box":    # one stacked QP: the batch's composition moves the answer within the solver tolerance
        np.testing.assert_allclose(res.position_m[keep], full.position_m[keep], rtol=0, atol=1e-6)
    else:                # closed forms and per-problem iterations: bit-identical
        np.testing.assert_array_equal(res.position_m[keep], full.position_m[keep])
    assert res.converged[keep].all() and set(res.status[keep]) == {"ok"}
    heard = np.array([0, 1, 3, 4])
    sub = est(ANCHORS[heard], power[5:6, heard])
    np.testing.assert_allclose(res.position_m[5], sub.position_m[0], rtol=0, atol=1e-6 if name == "box" else 1e-9)
    assert res.converged[5] and res.status[5] == "ok"
    assert np.isnan(res.position_m[9]).all() and not res.converged[9] and res.status[9] == "too_few_anchors"


def test_grid_ml_ignores_a_missing_anchor_instead_of_returning_cell_zero():
    truth = np.array([[7.0, 9.0]])
    power = MODEL.mean_power_dbm(lb.pairwise_distance_m(truth, ANCHORS))
    power[0, 1] = np.nan
    grid = np.stack(np.meshgrid(np.arange(0, 10.5, 0.5), np.arange(0, 12.5, 0.5)), -1).reshape(-1, 2)
    res = lb.grid_ml_position(ANCHORS, power, MODEL, grid)
    np.testing.assert_array_equal(res.position_m[0], truth[0])                  # noiseless: the true cell


def test_rss_ml_with_a_silent_anchor_is_not_a_confident_answer():
    power = np.full((1, 5), np.nan)
    power[0, :2] = [-60.0, -62.0]
    res = lb.rss_ml_position(ANCHORS, power, MODEL)
    assert np.isnan(res.position_m).all() and not res.converged[0] and res.status[0] == "too_few_anchors"
    with pytest.raises(lb.ConvergenceError, match="too_few_anchors"):
        lb.rss_ml_position(ANCHORS, power, MODEL, raise_on_failure=True)


def test_collinear_heard_anchors_are_marked_degenerate():
    anchors = np.array([[0.0, 0.0], [5.0, 0.0], [10.0, 0.0], [5.0, 8.0]])
    d = lb.pairwise_distance_m(np.array([[4.0, 3.0], [6.0, 2.0]]), anchors)
    d[1, 3] = np.nan                              # the three heard anchors lie on one line
    res = lb.lateration_ls(anchors, d)
    np.testing.assert_allclose(res.position_m[0], [4.0, 3.0], atol=1e-9)
    assert res.status.tolist() == ["ok", "degenerate_geometry"] and np.isnan(res.position_m[1]).all()


def test_reference_anchor_missing_uses_the_first_heard():
    d = lb.pairwise_distance_m(np.array([[3.0, 4.0]]), ANCHORS) + np.array([0.1, -0.2, 0.3, 0.05, -0.1])
    holed = d.copy()
    holed[0, 0] = np.nan
    res = lb.lateration_ls(ANCHORS, holed, ref_index=0)
    np.testing.assert_allclose(res.position_m, lb.lateration_ls(ANCHORS[1:], d[:, 1:], ref_index=0).position_m,
                               atol=1e-12)


def test_wls_keeps_the_weights_of_the_heard_anchors():
    d = lb.pairwise_distance_m(np.array([[3.0, 4.0]]), ANCHORS) + np.array([0.1, -0.2, 0.3, 0.05, -0.1])
    w = np.array([1.0, 2.0, 3.0, 4.0])            # rows of anchors 1..4 (reference 0)
    holed = d.copy()
    holed[0, 2] = np.nan
    res = lb.lateration_wls(ANCHORS, holed, w)
    heard = [0, 1, 3, 4]
    np.testing.assert_allclose(res.position_m, lb.lateration_wls(ANCHORS[heard], d[:, heard], [1.0, 3.0, 4.0]).position_m,
                               atol=1e-12)


def test_one_failing_box_problem_does_not_cost_its_batch(monkeypatch):
    _, power = _batch(8)
    ranges = MODEL.range_m(power)
    good = lb.lateration_box_ls(ANCHORS, ranges, *BOX)
    real_solve = localization.solve

    def flaky(problem, what):                     # the solver fails on any batch holding problem 3's data
        b = [p for p in problem.parameters() if p.name() == "b"][0].value
        if np.any(np.all(np.isclose(b, lb.lateration_system(ANCHORS, ranges[3])[1]), axis=1)):
            raise lb.ConvergenceError("deliberate")
        real_solve(problem, what)

    monkeypatch.setattr(localization, "solve", flaky)
    res = lb.lateration_box_ls(ANCHORS, ranges, *BOX)
    others = np.setdiff1d(np.arange(8), [3])
    np.testing.assert_allclose(res.position_m[others], good.position_m[others], atol=1e-6)
    assert res.status[3] == "solver_failed" and not res.converged[3] and np.isnan(res.position_m[3]).all()
    assert res.converged[others].all()


@pytest.mark.parametrize("call, message", [
    (lambda: lb.lateration_ls(ANCHORS, np.ones((3, 4))), r"distance_m must have shape \(\.\.\., 5\)"),
    (lambda: lb.lateration_ls(ANCHORS, [1, 2, np.inf, 1, 1]), "distance_m must be finite"),
    (lambda: lb.lateration_ls(ANCHORS, [1, 2, -1, 1, 1]), "distance_m must be non-negative"),
    (lambda: lb.lateration_ls(ANCHORS, np.ones(5), ref_index=5), "ref_index must be an anchor index"),
    (lambda: lb.lateration_ls(np.r_[ANCHORS, [[np.nan, 1.0]]], np.ones(6)), "anchors_m must be finite"),
    (lambda: lb.lateration_ls(np.r_[ANCHORS, [[10.0, 8.0]]], np.ones(6)), "anchors 2 and 5 coincide"),
    (lambda: lb.lateration_wls(ANCHORS, np.ones(5), np.ones(3)), "weights must broadcast"),
    (lambda: lb.lateration_box_ls(ANCHORS, np.ones(5), [0, 0, 0], [1, 1]), r"lower_m must be a scalar or have shape \(2,\)"),
    (lambda: lb.rss_ml_position(ANCHORS, np.ones(5), lb.PathLossModel(np.zeros(3))), r"model.ref_power_dbm must be a scalar or have shape \(5,\)"),
    (lambda: lb.rss_ml_position(ANCHORS, -60 * np.ones(5), MODEL, initial_m=np.zeros(3)), "initial_m must broadcast"),
    (lambda: lb.grid_ml_position(ANCHORS, -60 * np.ones(5), MODEL, np.zeros((4, 3))), r"grid_m must have shape"),
    (lambda: lb.rss_ml_position(ANCHORS, -60 * np.ones(5), MODEL, min_anchors=2), "min_anchors must be >= 3"),
])
def test_bad_input_names_the_argument(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_target_on_an_anchor_is_found():
    d = lb.pairwise_distance_m(ANCHORS[2], ANCHORS)          # zero distance to anchor 2
    np.testing.assert_allclose(lb.lateration_ls(ANCHORS, d).position_m, ANCHORS[2], atol=1e-9)
    power = MODEL.mean_power_dbm(np.maximum(d, 1e-3))
    np.testing.assert_allclose(lb.rss_ml_position(ANCHORS, power, MODEL).position_m, ANCHORS[2], atol=1e-3)


@settings(max_examples=60, deadline=None, derandomize=True)
@given(mask=arrays(bool, (12, 5)), name=st.sampled_from(["ls", "wls", "ml"]))
def test_property_random_missing_masks(mask, name):
    """Whatever is missing: a problem with >= 3 heard non-collinear anchors equals its heard-subset solution;
    fewer gives NaN and not converged; no NaN ever comes with converged=True."""
    _, power = _batch(12, seed=11)
    holed = np.where(mask, np.nan, power)
    res = ESTIMATORS[name](ANCHORS, holed)
    for i in range(12):
        heard = np.flatnonzero(~mask[i])
        if heard.size < 3:
            assert res.status[i] == "too_few_anchors" and not res.converged[i] and np.isnan(res.position_m[i]).all()
            continue
        if name == "wls":   # weight of each non-reference anchor's row; the first heard anchor is the reference
            weight_of_anchor = np.r_[0.0, np.arange(1.0, 5.0)]
            sub = lb.lateration_wls(ANCHORS[heard], MODEL.range_m(power[i:i + 1, heard]), weight_of_anchor[heard[1:]])
        else:
            sub = ESTIMATORS[name](ANCHORS[heard], power[i:i + 1, heard])
        np.testing.assert_allclose(res.position_m[i], sub.position_m[0], atol=1e-9)
        assert res.converged[i] == sub.converged[0]
    assert not np.any(res.converged & np.isnan(res.position_m).any(-1))


def test_knn_compares_over_the_heard_readers():
    rng = np.random.default_rng(8)
    cells = rng.uniform(0, 10, (30, 2))
    fp = rng.normal(-60, 8, (30, 4))
    query = rng.normal(-60, 8, (6, 4))
    holed = query.copy()
    holed[1, 2] = np.nan
    holed[4, [0, 1]] = np.nan                       # two readers heard: fewer than the default minimum of 3
    res = lb.knn_position(holed, fp, cells, k=4)
    full = lb.knn_position(query, fp, cells, k=4)
    keep = [0, 2, 3, 5]
    np.testing.assert_allclose(res[keep], full[keep], rtol=1e-12)   # einsum may sum another batch size otherwise
    np.testing.assert_allclose(res[1], lb.knn_position(query[1, [0, 1, 3]], fp[:, [0, 1, 3]], cells, k=4), rtol=1e-12)
    assert np.isnan(res[4]).all()
    np.testing.assert_allclose(lb.knn_position(holed[4], fp, cells, k=4, min_readers=2),
                               lb.knn_position(query[4, [2, 3]], fp[:, [2, 3]], cells, k=4), rtol=1e-12)
    with pytest.raises(ValueError, match="fingerprints_dbm must be finite"):
        lb.knn_position(query, np.where(fp > -50, np.nan, fp), cells, k=4)
