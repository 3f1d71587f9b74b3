"""The missing-reading rule and input checks of the static estimators.

Independent facts used: a problem with a missing anchor equals the same estimator run on the heard anchors
only; problems of a batch are independent, so a NaN in one (or a failure in one) leaves the others bit-identical;
a zero weight removes its equation; the CRLB is the trace of the inverse of the numerical Fisher information;
noiseless ranges give the true position; a pattern-map entry is the plain mean of the samples heard.
"""
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

import locbook as lb
from builders import MASKED_ANCHORS, exact_distances, masked
from locbook.static import box_ls, checks, grid_ml, result, rss_ml
from locbook.static.result import LOCALIZATION_STATUSES

ANCHORS = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 8.0], [0.0, 8.0], [5.0, 12.0]])
MODEL = lb.PathLossModel(-45.0, 2.5, 4.0)
RSS_MODEL = lb.RssModel(ANCHORS, MODEL)
BOX = ([-1.0, -1.0], [11.0, 13.0])


def _batch(n=40, seed=3):
    rng = np.random.default_rng(seed)
    truth = rng.uniform([0, 0], [10, 12], (n, 2))
    power = MODEL.sample_rss_dbm(lb.pairwise_distance_m(truth, ANCHORS), rng=rng)
    return truth, power


ESTIMATORS = {
    "ls": lambda a, p, **kw: lb.lateration_ls(a, MODEL.range_m(p), **kw),
    "wls": lambda a, p, **kw: lb.lateration_wls(a, MODEL.range_m(p), np.arange(1.0, a.shape[0]), **kw),
    "box": lambda a, p, **kw: lb.lateration_box_ls(a, MODEL.range_m(p), *BOX, **kw),
    "ml": lambda a, p, **kw: lb.rss_ml_position(p, lb.RssModel(a, MODEL), **kw),
    "grid": lambda a, p, **kw: lb.grid_ml_position(
        p, lb.RssModel(a, MODEL),
        np.stack(np.meshgrid(np.arange(0, 10.5, 0.5), np.arange(0, 12.5, 0.5)), -1).reshape(-1, 2), **kw),
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
    power = MODEL.mean_rss_dbm(lb.pairwise_distance_m(truth, ANCHORS))
    power[0, 1] = np.nan
    grid = np.stack(np.meshgrid(np.arange(0, 10.5, 0.5), np.arange(0, 12.5, 0.5)), -1).reshape(-1, 2)
    res = lb.grid_ml_position(power, RSS_MODEL, grid)
    np.testing.assert_array_equal(res.position_m[0], truth[0])                  # noiseless: the true cell


def test_rss_ml_with_a_silent_anchor_is_not_a_confident_answer():
    power = np.full((1, 5), np.nan)
    power[0, :2] = [-60.0, -62.0]
    res = lb.rss_ml_position(power, RSS_MODEL)
    assert np.isnan(res.position_m).all() and not res.converged[0] and res.status[0] == "too_few_anchors"
    with pytest.raises(lb.ConvergenceError, match="too_few_anchors"):
        lb.rss_ml_position(power, RSS_MODEL, raise_on_failure=True)


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
    np.testing.assert_allclose(res.position_m,
                               lb.lateration_wls(ANCHORS[heard], d[:, heard], [1.0, 3.0, 4.0]).position_m,
                               atol=1e-12)


def test_one_failing_box_problem_does_not_cost_its_batch(monkeypatch):
    _, power = _batch(8)
    ranges = MODEL.range_m(power)
    good = lb.lateration_box_ls(ANCHORS, ranges, *BOX, solver="cvxpy")   # the stacked QP's failure isolation
    real_solve = box_ls.solve

    def flaky(problem, what):                     # the solver fails on any batch holding problem 3's data
        b = [p for p in problem.parameters() if p.name() == "b"][0].value
        if np.any(np.all(np.isclose(b, lb.lateration_system(ANCHORS, ranges[3])[1]), axis=1)):
            raise lb.ConvergenceError("deliberate")
        real_solve(problem, what)

    monkeypatch.setattr(box_ls, "solve", flaky)
    res = lb.lateration_box_ls(ANCHORS, ranges, *BOX, solver="cvxpy")
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
    (lambda: lb.lateration_wls(ANCHORS, np.ones(5), np.ones(3)), r"weights must have shape \(\.\.\., 4\)"),
    (lambda: lb.lateration_wls(ANCHORS, np.ones((2, 5)), 1.0),
     r"weights must have shape \(\.\.\., 4\).*got shape \(\)"),
    (lambda: lb.lateration_wls(ANCHORS, np.ones((2, 5)), np.ones((2, 1))),
     r"weights must have shape.*got shape \(2, 1\)"),
    (lambda: lb.lateration_wls(ANCHORS, np.ones((2, 5)), np.ones((3, 4))),
     r"weights must have shape.*got shape \(3, 4\)"),
    (lambda: lb.lateration_wls(ANCHORS, np.ones(5), [1.0, -1.0, 1.0, 1.0]), "weights must be non-negative, got -1.0"),
    (lambda: lb.lateration_ls(ANCHORS, np.ones(5), min_anchors=6),
     r"min_anchors must be <= the number of anchors \(5\)"),
    (lambda: lb.lateration_box_ls(ANCHORS, np.ones(5), 0.0, 10.0, min_anchors=3.5), "min_anchors must be an integer"),
    (lambda: lb.rss_ml_position(-60 * np.ones((2, 5)), RSS_MODEL, initial_m=[[np.nan, 1.0], [2.0, 2.0]]),
     r"initial_m must be finite, or all NaN.*\[nan, 1.0\]"),
    (lambda: lb.rss_ml_position(-60 * np.ones(5), RSS_MODEL, initial_m=[np.inf, 1.0]), "initial_m must be finite"),
    (lambda: lb.grid_ml_position(-60 * np.ones(5), RSS_MODEL, [[1.0, np.nan]]), "cells_m must be finite"),
    (lambda: lb.knn_position(np.zeros((5, 4)), np.zeros((3, 10, 4)), np.zeros((10, 2)), 2),
     r"batch axes of rss_dbm \(5,\).*fingerprints_dbm \(3,\)"),
    (lambda: lb.knn_position(np.zeros(3), np.zeros((10, 4)), np.zeros((10, 2)), 2),
     r"rss_dbm must have shape \(\.\.\., 4\)"),
    (lambda: lb.knn_position(np.zeros(4), np.zeros((10, 4)), np.zeros((9, 2)), 2),
     "fingerprints_dbm has 10 cells.*cells_m has 9"),
    (lambda: lb.model_fingerprints(np.zeros((5, 3)), RSS_MODEL),
     r"cells_m must have shape \(\.\.\., 2\), got \(5, 3\)"),
    (lambda: lb.model_fingerprints(np.zeros((5, 2)), MODEL), r"model must be an RssModel.*got PathLossModel"),
    (lambda: lb.model_fingerprints(np.zeros((5, 2)), lb.RssModel(ANCHORS, MODEL, np.full((1, 2, 2), np.nan))),
     "walls_m must be finite"),
    (lambda: lb.model_fingerprints(ANCHORS, RSS_MODEL, min_distance_m=0.0), "min_distance_m must be > 0"),
    (lambda: lb.pattern_fingerprints(np.zeros((6, 40, 4)), axis=-1), "axis must be a sample axis"),
    (lambda: lb.pattern_fingerprints(np.full((6, 40, 4), np.inf)), "rss_dbm must be finite"),
    (lambda: lb.rss_crlb_m(np.zeros((4, 3)), lb.RssModel(ANCHORS, MODEL)), r"position_m must have shape \(\.\.\., 2\)"),
    (lambda: lb.rss_crlb_m([1.0, np.nan], lb.RssModel(ANCHORS, MODEL)), "position_m must be finite"),
    (lambda: lb.rss_crlb_m([1.0, 1.0], lb.RssModel(ANCHORS, lb.PathLossModel(0.0, [2.0, 2.0], 4.0))),
     r"channel.path_loss_exp must be a scalar or end in \(1,\) or \(5,\)"),
    (lambda: lb.crlb_rms_over_area_m(np.zeros((0, 2)), lb.RssModel(ANCHORS, MODEL)), "points_m must hold at least one"),
    (lambda: lb.lateration_box_ls(ANCHORS, np.ones(5), [0, 0, 0], [1, 1]),
     r"lower_m must be a scalar or have shape \(2,\)"),
    (lambda: lb.rss_ml_position(np.ones(5), MODEL),
     r"model must be an RssModel.*pass rss_ml_position\(rss_dbm, RssModel"),
    (lambda: lb.grid_ml_position(np.ones(5), MODEL, ANCHORS),
     r"model must be an RssModel.*pass grid_ml_position\(rss_dbm, Rss"),
    (lambda: lb.rss_ml_position(-60 * np.ones(5), RSS_MODEL, initial_m=np.zeros(3)), "initial_m must broadcast"),
    (lambda: lb.grid_ml_position(-60 * np.ones(5), RSS_MODEL, np.zeros((4, 3))), r"cells_m must have shape"),
    (lambda: lb.rss_ml_position(-60 * np.ones(5), RSS_MODEL, min_anchors=2), "min_anchors must be >= 3"),
])
def test_bad_input_names_the_argument(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_target_on_an_anchor_is_found():
    d = lb.pairwise_distance_m(ANCHORS[2], ANCHORS)          # zero distance to anchor 2
    np.testing.assert_allclose(lb.lateration_ls(ANCHORS, d).position_m, ANCHORS[2], atol=1e-9)
    power = MODEL.mean_rss_dbm(np.maximum(d, 1e-3))
    np.testing.assert_allclose(lb.rss_ml_position(power, RSS_MODEL).position_m, ANCHORS[2], atol=1e-3)


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
    np.testing.assert_allclose(lb.knn_position(holed[4], fp, cells, k=4, min_anchors=2),
                               lb.knn_position(query[4, [2, 3]], fp[:, [2, 3]], cells, k=4), rtol=1e-12)
    with pytest.raises(ValueError, match="fingerprints_dbm must be finite"):
        lb.knn_position(query, np.where(fp > -50, np.nan, fp), cells, k=4)


# -- zero weights, overflow, empty batches: failures stay with their problem ------------------------------------
def test_zero_weights_drop_their_equations_and_a_degenerate_problem_fails_alone():
    truth = np.array([[3.0, 4.0], [6.0, 7.0], [2.0, 9.0]])
    d = lb.pairwise_distance_m(truth, ANCHORS) + np.array([0.1, -0.2, 0.3, 0.05, -0.1])
    w = np.array([[1.0, 0.0, 0.0, 0.0],      # reference 0 and anchor 1 only: two anchors, no 2-D fix
                  [2.0, 0.0, 0.0, 5.0],      # anchors 0, 1, 4: two equations, two unknowns
                  [1.0, 1.0, 1.0, 1.0]])     # equal weights: ordinary least squares
    res = lb.lateration_wls(ANCHORS, d, w)
    assert res.status.tolist() == ["degenerate_geometry", "ok", "ok"] and np.isnan(res.position_m[0]).all()
    assert res.converged.tolist() == [False, True, True]
    # independent facts: a zero weight removes its equation; a square system is solved exactly; equal weights = LS
    np.testing.assert_allclose(res.position_m[1], lb.lateration_ls(ANCHORS[[0, 1, 4]], d[1, [0, 1, 4]]).position_m,
                               atol=1e-12)
    np.testing.assert_allclose(res.position_m[2], lb.lateration_ls(ANCHORS, d[2]).position_m, atol=1e-12)
    np.testing.assert_array_equal(res.position_m[1:], lb.lateration_wls(ANCHORS, d[1:], w[1:]).position_m)


def _with_overflow(values, row, cols, value):
    values = values.copy()
    values[row, cols] = value
    return values


@pytest.mark.parametrize("name", ["ls", "wls", "box"])
def test_ranges_that_overflow_fail_their_problem_alone(name):
    """Finite ranges of 1e200 m square to infinity; before, the NaN they made in the linear system was taken for a
    missing reading and the estimator recursed on the same problem without end."""
    est = {"ls": lambda d: lb.lateration_ls(ANCHORS, d),
           "wls": lambda d: lb.lateration_wls(ANCHORS, d, np.arange(1.0, 5.0)),
           "box": lambda d: lb.lateration_box_ls(ANCHORS, d, *BOX)}[name]
    _, power = _batch(6)
    d = _with_overflow(MODEL.range_m(power), 2, [0, 1], 1e200)
    with np.errstate(over="ignore", invalid="ignore"):
        res = est(d)
    keep = [0, 1, 3, 4, 5]
    assert res.status[2] == "solver_failed" and not res.converged[2] and np.isnan(res.position_m[2]).all()
    assert res.converged[keep].all()
    alone = est(d[keep])
    if name == "box":
        np.testing.assert_allclose(res.position_m[keep], alone.position_m, atol=1e-6)
    else:
        np.testing.assert_array_equal(res.position_m[keep], alone.position_m)


def test_rss_ml_without_a_finite_start_fails_alone():
    """A power of -20000 dBm is finite, but its range overflows, so the linearized start does not exist."""
    _, power = _batch(6)
    holed = _with_overflow(power, 1, 0, -20000.0)
    res = lb.rss_ml_position(holed, RSS_MODEL)
    keep = [0, 2, 3, 4, 5]
    assert res.status[1] == "solver_failed" and not res.converged[1] and np.isnan(res.position_m[1]).all()
    np.testing.assert_array_equal(res.position_m[keep], lb.rss_ml_position(power[keep], RSS_MODEL).position_m)
    assert res.converged[keep].all()
    with pytest.raises(lb.ConvergenceError, match="solver_failed"):
        lb.rss_ml_position(holed, RSS_MODEL, raise_on_failure=True)


def test_grid_ml_with_an_overflowing_cost_fails_alone():
    """A power of -1e160 dBm is finite and not implausibly high (a tag very far away), but its square overflows."""
    _, power = _batch(4)
    grid = ANCHORS + 0.5
    holed = _with_overflow(power, 2, 0, -1e160)
    with np.errstate(over="ignore"):
        res = lb.grid_ml_position(holed, RSS_MODEL, grid)
    assert res.status.tolist() == ["ok", "ok", "solver_failed", "ok"] and np.isnan(res.position_m[2]).all()
    np.testing.assert_array_equal(res.position_m[[0, 1, 3]],
                                  lb.grid_ml_position(power[[0, 1, 3]], RSS_MODEL, grid).position_m)


@pytest.mark.parametrize("name", list(ESTIMATORS))
def test_an_empty_batch_gives_an_empty_answer(name):
    res = ESTIMATORS[name](ANCHORS, np.zeros((0, 5)) - 60.0)
    assert res.position_m.shape == (0, 2) and res.converged.shape == (0,) and res.status.shape == (0,)


def test_nan_start_rows_take_the_default_start_so_a_grid_fix_chains():
    """The Dogan recipe, a grid fix refined by ML, with a problem that heard two anchors: the grid gives NaN there,
    which ``rss_ml_position`` takes as "no start" (before, it refused the whole batch)."""
    _, power = _batch(6)
    holed = _with_overflow(power, 3, [0, 1, 2], np.nan)
    grid = np.stack(np.meshgrid(np.arange(-1, 11.5, 0.5), np.arange(-1, 13.5, 0.5)), -1).reshape(-1, 2)
    start = lb.grid_ml_position(holed, RSS_MODEL, grid).position_m
    assert np.isnan(start[3]).all()
    res = lb.rss_ml_position(holed, RSS_MODEL, start)
    keep = [0, 1, 2, 4, 5]
    assert res.status[3] == "too_few_anchors" and res.converged[keep].all()
    np.testing.assert_array_equal(res.position_m[keep],
                                  lb.rss_ml_position(power[keep], RSS_MODEL, start[keep]).position_m)
    # all heard, some rows without a start: those rows equal the default-start answer
    mixed = start.copy()
    mixed[3] = start[0]
    mixed[[0, 4]] = np.nan
    res = lb.rss_ml_position(power, RSS_MODEL, mixed)
    np.testing.assert_allclose(res.position_m[[0, 4]], lb.rss_ml_position(power[[0, 4]], RSS_MODEL).position_m,
                               rtol=0, atol=1e-9)
    np.testing.assert_array_equal(res.position_m[[1, 2, 3, 5]],
                                  lb.rss_ml_position(power[[1, 2, 3, 5]], RSS_MODEL, mixed[[1, 2, 3, 5]]).position_m)


@pytest.mark.parametrize("name", ["ls", "wls", "box", "grid"])
def test_target_on_an_anchor_with_another_anchor_missing(name):
    """Zero distance to anchor 2 (and anchor 4 not heard): the estimate is anchor 2 itself."""
    d = lb.pairwise_distance_m(ANCHORS[2], ANCHORS)[None]
    for holed in (d, _with_overflow(d, 0, 4, np.nan)):
        if name == "grid":    # noiseless powers at the grid's own distance floor (1e-6 m) for the anchor
            power = MODEL.mean_rss_dbm(np.maximum(np.nan_to_num(holed, nan=1.0), 1e-6))
            power[np.isnan(holed)] = np.nan
            grid = np.stack(np.meshgrid(np.arange(0, 10.5, 0.5), np.arange(0, 12.5, 0.5)), -1).reshape(-1, 2)
            res = lb.grid_ml_position(power, RSS_MODEL, grid)
        else:
            res = {"ls": lambda: lb.lateration_ls(ANCHORS, holed),
                   "wls": lambda: lb.lateration_wls(ANCHORS, holed, [1.0, 2.0, 3.0, 4.0]),
                   "box": lambda: lb.lateration_box_ls(ANCHORS, holed, *BOX)}[name]()
        np.testing.assert_allclose(res.position_m[0], ANCHORS[2], atol=1e-6 if name == "box" else 1e-9)
        assert res.converged[0] and res.status[0] == "ok"


# -- k-NN and the maps -------------------------------------------------------------------------------------------
def test_knn_minimum_is_capped_at_the_readers_of_the_map():
    """With a two-reader map a query that heard both readers is always compared (default min_anchors 3), in a batch
    with missing readings too; one reader heard is too few."""
    fp = np.array([[-50.0, -60.0], [-52.0, -60.0], [-50.0, -62.0]])
    cells = np.array([[0.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    res = lb.knn_position(np.array([[-51.6, -60.0], [-50.0, np.nan]]), fp, cells, k=1)
    np.testing.assert_array_equal(res[0], cells[1])              # E^2 = 0.16 to cell 1, 2.56 to cell 0
    assert np.isnan(res[1]).all()


def test_knn_names_the_incomplete_map_entry():
    fp = np.full((5, 3), -60.0)
    fp[3, 1] = np.nan
    with pytest.raises(ValueError, match=r"cell 3, reader 1.*fill"):
        lb.knn_position(np.full(3, -60.0), fp, np.zeros((5, 2)), k=2)


def test_pattern_map_averages_the_heard_samples():
    rng = np.random.default_rng(4)
    samples = rng.normal(-60, 5, (4, 6, 3))
    samples[1, [0, 2], 0] = np.nan                 # two packets missed by reader 0 at location 1
    samples[2, :, 2] = np.nan                      # reader 2 never heard location 2
    fp = lb.pattern_fingerprints(samples)
    for c in range(4):
        for r in range(3):
            heard = [v for v in samples[c, :, r] if not np.isnan(v)]
            if heard:
                assert fp[c, r] == pytest.approx(sum(heard) / len(heard), rel=1e-14)
            else:
                assert np.isnan(fp[c, r])
    np.testing.assert_array_equal(fp[[0, 3]], np.mean(samples[[0, 3]], axis=-2))   # complete locations untouched
    with pytest.raises(ValueError, match="cell 2, reader 2"):
        lb.knn_position(np.full(3, -60.0), fp, np.zeros((4, 2)), k=2)


# -- the CRLB in any dimension -----------------------------------------------------------------------------------
def test_crlb_in_3d_is_the_trace_of_the_inverse_numerical_fisher_information():
    anchors = np.array([[0.0, 0.0, 0.0], [6.0, 0.0, 0.5], [0.0, 5.0, 1.0], [5.0, 5.0, 3.0], [2.0, 1.0, 3.0]])
    model = lb.PathLossModel(-45.0, 2.3, 4.0)
    p = np.array([2.1, 1.7, 0.9])
    eps = 1e-6
    jac = np.stack([(model.mean_rss_dbm(lb.pairwise_distance_m(p + eps * e, anchors))
                     - model.mean_rss_dbm(lb.pairwise_distance_m(p - eps * e, anchors))) / (2 * eps)
                    for e in np.eye(3)], axis=1)
    expected = np.sqrt(np.trace(np.linalg.inv(jac.T @ jac / 16.0)))
    assert lb.rss_crlb_m(p, lb.RssModel(anchors, model)) == pytest.approx(expected, rel=1e-6)


# -- properties: random masks with a minimum, collinear subsets, degenerate anchors ------------------------------
@settings(max_examples=60, deadline=None, derandomize=True)
@given(mask=arrays(bool, (10, 5)), name=st.sampled_from(["ls", "grid", "ml"]), min_anchors=st.sampled_from([4, 5]))
def test_property_random_masks_with_a_minimum(mask, name, min_anchors):
    _, power = _batch(10, seed=5)
    res = ESTIMATORS[name](ANCHORS, np.where(mask, np.nan, power), min_anchors=min_anchors)
    for i in range(10):
        heard = np.flatnonzero(~mask[i])
        if heard.size < min_anchors:
            assert res.status[i] == "too_few_anchors" and not res.converged[i] and np.isnan(res.position_m[i]).all()
        else:
            sub = ESTIMATORS[name](ANCHORS[heard], power[i:i + 1, heard])
            np.testing.assert_allclose(res.position_m[i], sub.position_m[0], atol=1e-9)
            assert res.status[i] == sub.status[0]


COLLINEAR3 = np.array([[0.0, 0.0], [5.0, 0.0], [10.0, 0.0], [5.0, 8.0], [0.0, 8.0]])   # anchors 0, 1, 2 on a line


@settings(max_examples=60, deadline=None, derandomize=True)
@given(mask=arrays(bool, (10, 5)), name=st.sampled_from(["ls", "wls", "grid"]))
def test_property_collinear_heard_subsets_are_degenerate(mask, name):
    truth = np.random.default_rng(2).uniform([1, 1], [9, 7], (10, 2))
    power = MODEL.mean_rss_dbm(lb.pairwise_distance_m(truth, COLLINEAR3))
    res = ESTIMATORS[name](COLLINEAR3, np.where(mask, np.nan, power))
    for i in range(10):
        heard = np.flatnonzero(~mask[i])
        expected = ("too_few_anchors" if heard.size < 3 else
                    "degenerate_geometry" if set(heard) <= {0, 1, 2} else "ok")
        assert res.status[i] == expected
        assert res.converged[i] == (expected == "ok") and np.isnan(res.position_m[i]).all() == (expected != "ok")
        if expected == "ok" and name != "grid":     # noiseless ranges: the exact position
            np.testing.assert_allclose(res.position_m[i], truth[i], atol=1e-8)


@settings(max_examples=80, deadline=None, derandomize=True)
@given(anchors=arrays(float, (4, 2), elements=st.floats(-50, 50)), which=st.integers(0, 3),
       t=arrays(float, 4, elements=st.floats(-20, 20), unique=True), kind=st.sampled_from(["coincident", "collinear"]))
def test_property_degenerate_anchors_are_rejected(anchors, which, t, kind):
    if kind == "coincident":
        bad = np.vstack([anchors, anchors[which]])
        match = "coincide"
    else:    # points a + t u on one line; distinct t, at least 1e-3 apart
        if np.min(np.diff(np.sort(t))) < 1e-3:
            return
        bad = anchors[which] + t[:, None] * np.array([0.6, -0.8])
        match = "collinear"
    with pytest.raises(lb.DegenerateGeometryError, match=match):
        lb.check_anchor_geometry(bad)
    with pytest.raises(lb.DegenerateGeometryError):
        lb.lateration_ls(bad, np.ones(len(bad)))


@settings(max_examples=40, deadline=None, derandomize=True)
@given(mask=arrays(bool, (8, 5)))
def test_property_box_random_masks(mask):
    """Box LS over random masks: each problem is the box LS of its heard anchors (to the solver's tolerance), too few
    heard gives NaN, and the box holds."""
    _, power = _batch(8, seed=6)
    res = ESTIMATORS["box"](ANCHORS, np.where(mask, np.nan, power))
    for i in range(8):
        heard = np.flatnonzero(~mask[i])
        if heard.size < 3:
            assert res.status[i] == "too_few_anchors" and np.isnan(res.position_m[i]).all()
            continue
        sub = ESTIMATORS["box"](ANCHORS[heard], power[i:i + 1, heard])
        np.testing.assert_allclose(res.position_m[i], sub.position_m[0], atol=1e-6)
        assert res.status[i] == "ok" and np.all(res.position_m[i] >= np.array(BOX[0]) - 1e-7) \
            and np.all(res.position_m[i] <= np.array(BOX[1]) + 1e-7)


# -- no confident answer from garbage ----------------------------------------------------------
SQUARE = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
SQUARE_MODEL = lb.PathLossModel(-40.0, 2.0, 4.0)


@pytest.mark.parametrize("value", [1e300, 500.0])
@pytest.mark.parametrize("name", ["ml", "grid"])
def test_physically_impossible_powers_get_their_own_status(name, value):
    """+500 dBm (1e47 W) or 1e300 dBm: no position explains it (the model's mean power never exceeds its value at
    the near-field clamp, here P_0 + 60 n dB at 1 mm, and 10 sigma above that has probability < 1e-23). Before, the
    ML returned the centre of the square with converged=True (cost inf at 1e300) and the grid a grid point."""
    grid = np.stack(np.meshgrid(np.arange(0, 10.5, 0.5), np.arange(0, 10.5, 0.5)), -1).reshape(-1, 2)
    est = {"ml": lambda p: lb.rss_ml_position(p, lb.RssModel(SQUARE, SQUARE_MODEL)),
           "grid": lambda p: lb.grid_ml_position(p, lb.RssModel(SQUARE, SQUARE_MODEL), grid)}[name]
    truth = np.array([[2.0, 3.0], [7.0, 6.0], [4.0, 8.0]])
    power = SQUARE_MODEL.mean_rss_dbm(lb.pairwise_distance_m(truth, SQUARE))
    bad = power.copy()
    bad[1] = value                                   # every reading of problem 1
    bad[2, 3] = value                                # one reading of problem 2
    with np.errstate(over="ignore", invalid="ignore"):
        res = est(bad)
    assert res.status.tolist() == ["ok", "implausible_reading", "implausible_reading"]
    assert res.converged.tolist() == [True, False, False] and np.isnan(res.position_m[1:]).all()
    np.testing.assert_array_equal(res.position_m[0], est(power[:1]).position_m[0])
    # the bound is the model's: just below it a reading is taken (and the estimate is finite)
    clamp = 1e-3 if name == "ml" else 1e-6
    top = SQUARE_MODEL.ref_power_dbm - 10 * SQUARE_MODEL.path_loss_exp * np.log10(clamp) + 10 * SQUARE_MODEL.sigma_db
    edge = np.array([[top - 1e-6, *power[0, 1:]], [top + 1e-6, *power[0, 1:]]])
    res = est(edge)
    assert res.status[1] == "implausible_reading" and res.status[0] != "implausible_reading"
    assert np.isfinite(res.position_m[0]).all()


def test_an_infinite_cost_is_never_converged():
    """A start at 1e300 m: every distance squares to infinity, the cost is infinite and the step NaN; before, the
    damping grew to its cap and the problem was declared converged at the start with cost inf."""
    truth = np.array([[2.0, 3.0], [7.0, 6.0]])
    power = SQUARE_MODEL.mean_rss_dbm(lb.pairwise_distance_m(truth, SQUARE))
    with np.errstate(over="ignore", invalid="ignore"):
        res = lb.rss_ml_position(power, lb.RssModel(SQUARE, SQUARE_MODEL),
                                 initial_m=[[np.nan, np.nan], [1e300, 1e300]])
    assert res.status.tolist() == ["ok", "solver_failed"] and res.converged.tolist() == [True, False]
    assert np.isnan(res.position_m[1]).all()
    np.testing.assert_allclose(res.position_m[0], truth[0], atol=1e-9)
    assert not np.any(res.converged & ~np.isfinite(res.cost))


NEARLY_COLLINEAR = np.array([[0.0, 0.0], [5.0, 1e-7], [10.0, 0.0], [20.0, 0.0]])


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e4])
def test_nearly_collinear_anchors_are_degenerate_at_any_scale(scale):
    """The issue's layout (anchor 1 off the line by 1e-7 m) passed the old check (singular values relative to
    max(largest, 1 m) against 1e-9) and lateration_ls returned -4.55e8 m with status ok. The criterion is now the
    smallest singular value of the centred anchors relative to the largest, against 1e-6: scale-invariant."""
    with pytest.raises(lb.DegenerateGeometryError, match="collinear"):
        lb.check_anchor_geometry(scale * NEARLY_COLLINEAR)
    with pytest.raises(lb.DegenerateGeometryError, match="collinear"):
        lb.lateration_ls(scale * NEARLY_COLLINEAR, scale * np.array([5.0, 1.0, 5.0, 15.0]))
    # a tilted layout with a ratio of about 1e-4 is well within the bound at every scale (and in 3-D)
    tilted = np.array([[0.0, 0.0], [5.0, 1e-3], [10.0, 0.0], [20.0, 0.0]]) @ np.array([[0.6, 0.8], [-0.8, 0.6]])
    lb.check_anchor_geometry(scale * tilted)


def test_nearly_collinear_heard_anchors_fail_their_problem_alone():
    """Four anchors; a problem that did not hear the one off the line keeps three nearly collinear ones."""
    anchors = np.r_[NEARLY_COLLINEAR[:3], [[5.0, 8.0]]]
    truth = np.array([[3.0, 2.0], [6.0, 4.0]])
    d = lb.pairwise_distance_m(truth, anchors)
    holed = d.copy()
    holed[1, 3] = np.nan
    for res in (lb.lateration_ls(anchors, holed), lb.lateration_wls(anchors, holed, [1.0, 1.0, 1.0]),
                lb.lateration_box_ls(anchors, holed, -1.0, 11.0),
                lb.rss_ml_position(np.where(np.isnan(holed), np.nan, SQUARE_MODEL.mean_rss_dbm(d)),
                                   lb.RssModel(anchors, SQUARE_MODEL))):
        assert res.status.tolist() == ["ok", "degenerate_geometry"] and np.isnan(res.position_m[1]).all()
        np.testing.assert_allclose(res.position_m[0], truth[0], atol=1e-6)


def _scenario_layouts() -> dict:
    """Every anchor layout of the scenarios and the shipped data, as plan positions ``(m, 2)`` (the estimators judge
    the geometry of anchors with heights on their plan positions)."""
    from locbook import benchmark
    from locbook.data.dataset import datasets_dir
    from locbook.data.measured import read_anchors
    from locbook.scenarios import dogan, george, gudipati, ozkaya
    layouts = {"george": george.ANCHORS_M, "dogan": dogan.ANCHORS_M,
               "ozkaya testbed": np.array(ozkaya.TESTBED_READERS_M, float),
               "kolakowski2021 shipped anchors": read_anchors(datasets_dir() / "kolakowski2021" / "anchors.csv")[
                   ["x", "y"]].to_numpy(float)}
    layouts |= {f"ozkaya {name}": np.array(readers, float) for name, readers in ozkaya.LAYOUTS.items()}
    layouts |= {f"gudipati {n}": gudipati.anchors_m(ids) for n, ids in gudipati.ANCHOR_SETS.items()}
    for key in benchmark.STATIC_SCENARIOS:
        layouts[f"benchmark {key}"] = np.asarray(benchmark.static_scenario(key).anchors_m, float)[:, :2]
    for key in benchmark.TRACKING_SCENARIOS:
        layouts[f"benchmark tracking {key}"] = np.asarray(benchmark.tracking_scenario(key).anchors_m, float)[:, :2]
    return layouts


def _condition_ratio(anchors) -> float:
    sv = np.linalg.svd(anchors - anchors.mean(0), compute_uv=False)
    return sv[1] / sv[0]


def test_the_notebooks_anchor_layouts_are_far_from_the_conditioning_bound():
    """Every anchor layout of the scenarios (george, dogan, every ozkaya layout and its testbed, every gudipati anchor
    set, every benchmark scenario) and of the shipped data (Kolakowski 2021: the smallest ratio, about 0.022, on a
    subset of three anchors), and each of its subsets of at least three anchors (a problem that missed the others
    keeps them), has a singular-value ratio at least 1000 times the bound, so the check never rejects what the
    notebooks solve; an exactly collinear subset (ratio ~0) is rejected anyway, as before. Palvai's benchmark area
    (25 simulated receivers, every one heard in every problem) is checked whole: no subset of it is ever solved."""
    from itertools import combinations
    least = {}
    for name, layout in _scenario_layouts().items():
        m = len(layout)
        sizes = range(3, m + 1) if m <= 8 else [m]
        ratios = [(_condition_ratio(layout[list(sub)]), sub) for k in sizes for sub in combinations(range(m), k)]
        ratios = [(r, sub) for r, sub in ratios if r > 1e-12]
        least[name] = min(ratios)
        assert least[name][0] >= 1000 * checks.ANCHOR_CONDITION_RTOL, (name, least[name])
        lb.check_anchor_geometry(layout)
    assert least["kolakowski2021 shipped anchors"][0] < 0.03     # the data set's near-line triple is covered
    assert len(least) >= 17, sorted(least)


@pytest.mark.parametrize("name", ["ls", "wls"])
def test_a_single_overflowing_range_gives_nan_not_infinity(name):
    """Found by tests/static/test_static_fuzz.py: one range of 1e300 m squares to inf; the fix came out (inf, -inf) with
    status solver_failed, a failed problem with a position. A failed problem's position is NaN."""
    d = lb.pairwise_distance_m(np.array([3.0, 4.0]), ANCHORS)
    d[1] = 1e300
    with np.errstate(over="ignore", invalid="ignore"):
        res = (lb.lateration_ls(ANCHORS, d) if name == "ls" else lb.lateration_wls(ANCHORS, d, [1.0, 2.0, 3.0, 4.0]))
    assert res.status == "solver_failed" and not res.converged and np.isnan(res.position_m).all()


# -- readings impossible together, a goodness-of-fit status ----------------------------------
SQUARE_GRID = np.stack(np.meshgrid(np.arange(0, 10.25, 0.25), np.arange(0, 10.25, 0.25)), -1).reshape(-1, 2)
ML_ESTIMATORS = {"ml": lambda a, p, model, **kw: lb.rss_ml_position(p, lb.RssModel(a, model), **kw),
                 "grid": lambda a, p, model, **kw: lb.grid_ml_position(p, lb.RssModel(a, model), SQUARE_GRID, **kw)}


@pytest.mark.parametrize("name", ["ml", "grid"])
@pytest.mark.parametrize("power, model", [(100.0, lb.PathLossModel(-45.0, 3.5, 8.0)),
                                          (39.0, lb.PathLossModel(-40.0, 2.0, 2.0))])
def test_readings_impossible_together_are_a_poor_fit(name, power, model):
    """The reviewer's cases: each reading alone is below the implausibility bound (the mean at 1 mm plus 10 sigma),
    but four equal powers that high would need the tag within millimetres of all four corners of a 10 m square at
    once. The ML answer (the centre) leaves about 48 sigma per anchor: sum r^2 / sigma^2 is far beyond
    chi2.ppf(1 - 1e-9, 4 - 2) = 2 ln(1e9) = 41.4 (closed form for 2 degrees of freedom). Before, status ok."""
    from scipy.stats import chi2
    res = ML_ESTIMATORS[name](SQUARE, np.full(4, power), model)
    assert res.status == "poor_fit"
    assert res.cost / model.sigma_db**2 > chi2.ppf(1 - checks.GOODNESS_OF_FIT_ALPHA, 2)
    # the ML answer is kept: position and converged flag as they were (the status says the readings do not fit)
    assert res.converged and np.isfinite(res.position_m).all()
    if name == "ml":     # the reviewer's answer: the centre (the grid's best point is a corner, at the 1 um clamp)
        np.testing.assert_allclose(res.position_m, [5.0, 5.0], atol=1e-6)


@pytest.mark.parametrize("name", ["ml", "grid"])
@pytest.mark.parametrize("sigma_db", [4.0, np.array([2.0, 3.0, 4.0, 6.0])])
def test_model_consistent_readings_are_never_a_poor_fit(name, sigma_db):
    """2,000 problems whose readings are the model's mean plus its own shadowing: the statistic is (about) chi-square
    with m - 2 = 2 degrees of freedom, beyond the bound with probability 1e-9, so none is flagged (and with
    per-anchor sigma the cost divided by the largest sigma^2 is at most the weighted cost's minimum)."""
    model = lb.PathLossModel(-40.0, 2.5, sigma_db)
    rng = np.random.default_rng(26)
    truth = rng.uniform(0.5, 9.5, (2000, 2))
    power = model.sample_rss_dbm(lb.pairwise_distance_m(truth, SQUARE), rng=rng)
    res = ML_ESTIMATORS[name](SQUARE, power, model)
    assert "poor_fit" not in set(res.status.tolist())
    assert res.converged.all()


@pytest.mark.parametrize("name", ["ml", "grid"])
def test_a_poor_fit_is_flagged_alone_in_its_batch(name):
    """A batch of noisy model-consistent problems, one (row 3) that hears -30 dBm at all four corners (the model's
    mean at 0.3 m: no position is that close to all four; at the centre each reading is 27 dB = 6.8 sigma too
    strong, cost / sigma^2 about 180 > 41.4) and one (row 5) that heard only three anchors (1 degree of freedom,
    still testable): only row 3 is flagged, every position equals the problem solved alone, and a sigma of 0 (no
    shadowing model) flags nothing."""
    rng = np.random.default_rng(5)
    truth = rng.uniform(1, 9, (8, 2))
    power = SQUARE_MODEL.sample_rss_dbm(lb.pairwise_distance_m(truth, SQUARE), rng=rng)
    power[3] = -30.0
    power[5, 2] = np.nan
    res = ML_ESTIMATORS[name](SQUARE, power, SQUARE_MODEL)
    assert res.status.tolist() == ["ok"] * 3 + ["poor_fit"] + ["ok"] * 4
    assert res.converged.all()
    for i in range(8):
        np.testing.assert_allclose(res.position_m[i], ML_ESTIMATORS[name](SQUARE, power[i], SQUARE_MODEL).position_m,
                                   rtol=0, atol=1e-9)
    noiseless_model = lb.PathLossModel(SQUARE_MODEL.ref_power_dbm, SQUARE_MODEL.path_loss_exp, 0.0)
    assert set(ML_ESTIMATORS[name](SQUARE, power, noiseless_model).status.tolist()) == {"ok"}


def test_poor_fit_is_a_documented_status():
    assert "poor_fit" in LOCALIZATION_STATUSES and "poor_fit" in lb.LocalizationResult.__doc__
    assert 0 < checks.GOODNESS_OF_FIT_ALPHA <= 1e-6


@pytest.mark.parametrize("clamp_m", [0.0, -1e-3, np.inf, np.nan])
def test_implausible_powers_checks_its_clamp(clamp_m):
    """clamp_m = 0 gave numpy's divide warning and an infinite bound (every reading plausible), NaN a bound that
    refuses nothing silently: the clamp must be a positive finite distance, and the error names it."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(ValueError, match="clamp_m"):
            lb.implausible_powers(np.full(4, -60.0), SQUARE_MODEL, clamp_m)


def test_implausible_reading_states_its_physical_assumption():
    """The rule refuses a power above the mean at the 1 mm clamp (plus 10 sigma), so a REAL noise-free reading of a
    tag 0.5 mm from an anchor of a model without shadowing (sigma 0, min_distance_m 0) is refused: the docstrings
    must say that a reading implying a tag closer than 1 mm to an antenna is taken as implausible, and must not
    claim that no real reading is refused."""
    model = lb.PathLossModel(-40.0, 2.0)                      # sigma_db = 0, min_distance_m = 0 (the defaults)
    truth = np.array([5e-4, 0.0])                             # 0.5 mm from anchor 0
    power = model.mean_rss_dbm(lb.pairwise_distance_m(truth, SQUARE))
    assert lb.rss_ml_position(power, lb.RssModel(SQUARE, model)).status == "implausible_reading"
    far = model.mean_rss_dbm(lb.pairwise_distance_m(np.array([2e-3, 0.0]), SQUARE))   # 2 mm: taken
    assert lb.rss_ml_position(far, lb.RssModel(SQUARE, model)).status != "implausible_reading"
    import inspect
    for module in (checks, result, rss_ml, grid_ml):      # the homes of the estimators and the rule
        assert "no real reading is refused" not in inspect.getsource(module)
    for doc in (lb.implausible_powers.__doc__, lb.rss_ml_position.__doc__, lb.LocalizationResult.__doc__):
        assert "closer than 1 mm" in " ".join(doc.split()), doc


@pytest.mark.parametrize("value", [-1e300, -1e160])
def test_grid_ml_overflow_is_consistent_with_rss_ml_and_silent(value):
    """A reading of -1e300 dBm is finite and not implausibly high, but its square overflows: grid ML leaked
    'RuntimeWarning: overflow encountered in square' and returned cost inf, where rss_ml_position gives NaN with
    solver_failed. Both now give NaN position and cost and status solver_failed, with no warning, the others alone."""
    _, power = _batch(4)
    holed = _with_overflow(power, 2, 0, value)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        grid = lb.grid_ml_position(holed, RSS_MODEL, ANCHORS + 0.5)
        ml = lb.rss_ml_position(holed, RSS_MODEL)
    for res in (grid, ml):
        assert res.status[2] == "solver_failed" and not res.converged[2]
        assert np.isnan(res.position_m[2]).all() and np.isnan(res.cost[2])
        assert res.converged[[0, 1, 3]].all() and np.isfinite(res.cost[[0, 1, 3]]).all()


def test_the_degenerate_geometry_message_says_plane_in_3d():
    """3-D anchors on one plane were described as 'collinear (coplanar) ... across the line they lie on'."""
    coplanar = np.array([[0.0, 0.0, 1.0], [10.0, 0.0, 1.0], [0.0, 10.0, 1.0], [10.0, 10.0, 1.0], [5.0, 3.0, 1.0]])
    with pytest.raises(lb.DegenerateGeometryError) as info:
        lb.check_anchor_geometry(coplanar)
    message = str(info.value)
    assert "coplanar" in message and "plane" in message and "collinear" not in message and "line" not in message
    with pytest.raises(lb.DegenerateGeometryError) as info:
        lb.check_anchor_geometry(np.c_[np.arange(4.0), np.zeros(4)])     # 2-D: on the x axis
    assert "collinear" in str(info.value) and "across the line" in str(info.value)


# -- a masked reading is a reading not heard --------------------------------------------------------------------
@pytest.mark.parametrize("solve", [
    lambda d: lb.lateration_ls(MASKED_ANCHORS, d),
    lambda d: lb.lateration_ls(MASKED_ANCHORS, d, pairs="first"),
    lambda d: lb.lateration_wls(MASKED_ANCHORS, d, np.ones(4)),
    lambda d: lb.lateration_box_ls(MASKED_ANCHORS, d, -100.0, 100.0),
], ids=["ls", "ls_pairs", "wls", "box_ls"])
def test_lateration_with_masked_distances_uses_the_heard_anchors_only(solve):
    # exact distances: any four heard anchors (not collinear) give the true position exactly
    truth, d = exact_distances()
    where = np.zeros(d.shape, bool)
    where[1, 0] = where[2, 3] = where[4, 1] = True
    res = solve(masked(d, where))
    np.testing.assert_allclose(res.position_m, truth, rtol=0, atol=1e-8)
    assert (res.status == "ok").all()


def test_rss_estimators_with_masked_powers_equal_the_nan_readings():
    truth, d = exact_distances(4)
    model = lb.PathLossModel(-40.0, 2.0, 2.0)
    power = -40.0 - 20 * np.log10(d)
    where = np.zeros(d.shape, bool)
    where[0, 2] = where[3, 4] = True
    grid = np.stack(np.meshgrid(np.arange(0.0, 20.5, 0.5), np.arange(0.0, 20.5, 0.5)), -1).reshape(-1, 2)
    for solve in (lambda p: lb.rss_ml_position(p, lb.RssModel(MASKED_ANCHORS, model)),
                  lambda p: lb.grid_ml_position(p, lb.RssModel(MASKED_ANCHORS, model), grid)):
        got = solve(masked(power, where))
        np.testing.assert_array_equal(got.position_m, solve(np.where(where, np.nan, power)).position_m)
    np.testing.assert_allclose(lb.rss_ml_position(masked(power, where), lb.RssModel(MASKED_ANCHORS, model)).position_m,
                               truth, atol=1e-5)
