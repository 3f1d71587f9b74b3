"""Checked per-epoch bounds, their summary over a recording, the error / bound ratio and the heat map's n/a cell.

Every number is checked against the closed-form 2x2 Fisher information of RSS ranging written here in numpy,
``J = (10 n / (sigma ln 10))^2 sum_j u_j u_j^T / d_j^2`` (``u_j`` the unit vector from anchor j, Patwari et al.
2003, Eq. (5)), against numpy statistics of hand lists, or against sums written out pair by pair.
"""
import re

import numpy as np
import pytest

from locbook.bounds import (
    MAX_BOUND_CONDITION,
    MIN_ANCHORS_FOR_BOUND,
    TRIM_FRACTION,
    BoundSummary,
    check_position_information,
    error_bound_ratio,
    rss_crlb_checked_m,
    summarize_bound,
)
from locbook.bounds.crlb import rss_crlb_m
from locbook.errors import ParameterError
from locbook.models.channel import PathLossModel
from locbook.models.rss import RssModel

N_EXP, SIGMA_DB = 2.2, 4.0
SQUARE_M = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])


def rss(anchors_m, tag_height_m=None):
    """The bounds' RSS model of these anchors (n = N_EXP, sigma = SIGMA_DB)."""
    return RssModel(anchors_m, PathLossModel(0.0, N_EXP, SIGMA_DB), tag_height_m=tag_height_m)


def closed_form_information(position_m, anchors_m, heard, n=N_EXP, sigma_db=SIGMA_DB, height_m=None):
    """``beta^2 sum_heard u u^T / d^2`` per position, one position at a time (the test's own implementation);
    ``height_m``: each anchor's height above the tag (3-D distance, plan direction)."""
    beta2 = (10.0 * n / (sigma_db * np.log(10.0))) ** 2
    out = []
    for p, h in zip(position_m, heard):
        J = np.zeros((2, 2))
        for a, (j, on) in zip(anchors_m, enumerate(h)):
            if not on:
                continue
            v = p - a[:2]
            d2 = v @ v + (0.0 if height_m is None else height_m[j] ** 2)
            u = v / np.sqrt(d2)             # plan part of the 3-D unit vector
            J += beta2 * np.outer(u, u) / d2
        out.append(J)
    return np.array(out)


def closed_form_bound_m(J):
    return np.sqrt(np.trace(np.linalg.inv(J), axis1=-2, axis2=-1))


def test_epochs_that_heard_two_anchors_have_no_bound_and_the_summary_leaves_them_out():
    rng = np.random.default_rng(7)
    positions = rng.uniform(1.0, 9.0, size=(30, 2))
    heard = np.ones((30, 4), dtype=bool)
    heard[:8, 2:] = False                   # 8 epochs heard anchors 0 and 1 only
    heard[8:10, 1:] = False                 # 2 epochs heard anchor 0 only
    heard[10:14, 3] = False                 # 4 epochs heard three anchors: still a fix
    bound, reason = rss_crlb_checked_m(positions, rss(SQUARE_M), heard=heard)

    assert bound.shape == reason.shape == (30,)
    assert list(reason[:10]) == ["heard 2 anchors, a plan fix needs 3"] * 8 + ["heard 1 anchor, a plan fix needs 3"] * 2
    assert np.isnan(bound[:10]).all()
    assert (reason[10:] == "").all()
    expected = closed_form_bound_m(closed_form_information(positions[10:], SQUARE_M, heard[10:]))
    np.testing.assert_allclose(bound[10:], expected, rtol=1e-12)

    summary = summarize_bound(bound, reason)
    assert isinstance(summary, BoundSummary)
    assert (summary.n_epochs, summary.n_valid) == (30, 20)
    assert summary.excluded == {"too few anchors": 10}
    assert summary.valid.tolist() == [False] * 10 + [True] * 20
    assert not summary.degenerate and summary.degenerate_reason == ""
    np.testing.assert_allclose(summary.rms_m, np.sqrt(np.mean(expected**2)), rtol=1e-12)
    np.testing.assert_allclose(summary.median_m, np.median(expected), rtol=1e-12)
    row = summary.row()
    assert row["bound_epochs"] == 20 and row["bound_excluded"] == 10
    assert row["bound_excluded_why"] == "10 heard fewer than 3 anchors"
    np.testing.assert_allclose(row["bound_rms_m"], np.sqrt(np.mean(expected**2)), rtol=1e-12)
    assert set(summary.row("crlb_")) == {"crlb_median_m", "crlb_rms_m", "crlb_trimmed_rms_m", "crlb_epochs",
                                         "crlb_excluded", "crlb_excluded_why"}


def test_near_collinear_geometry_is_near_singular_and_an_unknown_position_has_no_truth():
    anchors = np.array([[0.0, 0.0], [5.0, 0.0], [10.0, 0.0]])     # collinear
    positions = np.array([[3.0, 1e-3], [3.0, 0.0], [3.0, 2.0], [np.nan, np.nan]])
    bound, reason = rss_crlb_checked_m(positions, rss(anchors))

    J = closed_form_information(positions[:1], anchors, [[True] * 3])[0]
    eig = np.linalg.eigvalsh(J)
    assert eig[1] / eig[0] > MAX_BOUND_CONDITION
    assert reason[0] == f"near-singular information (condition {eig[1] / eig[0]:.1e})"
    assert re.fullmatch(r"near-singular information \(condition \d\.\de\+\d\d\)", reason[0])
    assert reason[1] == "singular information (rank below 2)"          # on the line: rank 1 exactly
    assert reason[2] == "" and reason[3] == "no true position"
    assert np.isnan(bound[[0, 1, 3]]).all()
    J2 = closed_form_information(positions[2:3], anchors, [[True] * 3])
    np.testing.assert_allclose(bound[2], closed_form_bound_m(J2)[0], rtol=1e-12)

    # the same epoch is defined without the condition check: it is the check, not the formula, that refuses it
    lax, why = rss_crlb_checked_m(positions[:1], rss(anchors), max_condition=np.inf)
    assert why[0] == ""
    np.testing.assert_allclose(lax[0], closed_form_bound_m(J[None])[0], rtol=1e-6)

    summary = summarize_bound(bound, reason)
    assert summary.excluded == {"no truth": 1, "near-singular": 2}
    assert summary.row()["bound_excluded_why"] == "1 without a true position; 2 near-singular"


def test_general_information_check_names_condition_and_anchor_count():
    info = np.array([np.diag([4.0, 1.0]), np.diag([1.0, 1e-7]), np.diag([4.0, 1.0])])
    bound, reason = check_position_information(info, np.array([3, 5, 2]))
    np.testing.assert_allclose(bound[0], np.sqrt(1 / 4 + 1 / 1), rtol=1e-15)    # sqrt(tr J^-1)
    assert reason.tolist() == ["", "near-singular information (condition 1.0e+07)",
                               "heard 2 anchors, a plan fix needs 3"]
    assert np.isnan(bound[1:]).all() and MIN_ANCHORS_FOR_BOUND == 3
    # no count: a posterior information whose prior supplies the rest is checked by its condition alone
    b, r = check_position_information(info[2])
    assert r == "" and b == pytest.approx(np.sqrt(1.25), rel=1e-15)
    with pytest.raises(ParameterError, match="information must be symmetric"):
        check_position_information(np.array([[1.0, 0.5], [0.0, 1.0]]))
    with pytest.raises(ParameterError, match="n_heard"):
        check_position_information(info, np.array([3.0, 3.0, 3.0]))


def test_anchors_with_heights_and_a_known_tag_height_match_the_unchecked_bound():
    anchors = np.column_stack([SQUARE_M, [2.8, 2.5, 2.9, 2.6]])
    tag_height_m = 1.1
    rng = np.random.default_rng(3)
    positions = rng.uniform(0.5, 9.5, size=(12, 2))
    heard = np.ones((12, 4), dtype=bool)
    heard[:3, :2] = False                   # two anchors heard
    heard[3:6, 0] = False                   # three heard
    bound, reason = rss_crlb_checked_m(positions, rss(anchors, tag_height_m), heard=heard)
    assert (reason[:3] == "heard 2 anchors, a plan fix needs 3").all() and np.isnan(bound[:3]).all()
    assert (reason[3:] == "").all()
    unchecked = rss_crlb_m(positions[3:], rss(anchors, tag_height_m), heard=heard[3:])
    np.testing.assert_allclose(bound[3:], unchecked, rtol=1e-12)
    own = closed_form_bound_m(closed_form_information(positions[3:], anchors, heard[3:],
                                                      height_m=anchors[:, 2] - tag_height_m))
    np.testing.assert_allclose(bound[3:], own, rtol=1e-12)
    everyone, why = rss_crlb_checked_m(positions, rss(anchors, tag_height_m))
    assert (why == "").all()
    np.testing.assert_allclose(everyone, rss_crlb_m(positions, rss(anchors, tag_height_m)), rtol=1e-12)
    with pytest.raises(ParameterError, match="must read 2-D positions"):
        rss_crlb_checked_m(positions, rss(anchors))     # 3-D anchors need the tag's height


def test_trimmed_rms_drops_the_largest_five_percent():
    values = np.arange(1.0, 41.0)[::-1].copy()      # 40 bounds, order does not matter
    summary = summarize_bound(values)
    assert TRIM_FRACTION == 0.05
    kept = np.arange(1.0, 39.0)                      # floor(0.05 * 40) = 2 largest (39, 40) left out
    np.testing.assert_allclose(summary.trimmed_rms_m, np.sqrt(np.mean(kept**2)), rtol=1e-15)
    np.testing.assert_allclose(summary.rms_m, np.sqrt(np.mean(values**2)), rtol=1e-15)
    assert summary.median_m == 20.5
    few = summarize_bound(np.array([1.0, 2.0, 3.0, 100.0]))     # floor(0.05 * 4) = 0: nothing trimmed
    assert few.trimmed_rms_m == few.rms_m == pytest.approx(np.sqrt((1 + 4 + 9 + 1e4) / 4), rel=1e-15)


def test_a_degenerate_bound_gives_no_ratio_and_says_why():
    bound = np.array([1.0, 2.0, 1.5, 2.5] + [np.nan] * 6)
    reason = np.array([""] * 4 + ["heard 2 anchors, a plan fix needs 3"] * 6, dtype=object)
    summary = summarize_bound(bound, reason)
    assert summary.degenerate and summary.n_valid == 4
    assert summary.degenerate_reason == "the bound is undefined at 60 % of epochs (heard fewer than 3 anchors)"
    assert np.isnan([summary.rms_m, summary.median_m, summary.trimmed_rms_m]).all()
    ratio, note = error_bound_ratio(np.ones(10), summary)
    assert np.isnan(ratio)
    assert note == "n/a: the bound is undefined at 60 % of epochs (heard fewer than 3 anchors)"
    # NaN without a reason counts as undefined, inf (an unchecked singular bound) as near-singular
    s = summarize_bound(np.array([1.0, np.nan, np.inf, 2.0, 3.0]))
    assert s.excluded == {"near-singular": 1, "undefined": 1} and not s.degenerate
    one = summarize_bound(np.array([2.0]))
    assert one.degenerate and one.degenerate_reason == "the bound is defined at only 1 epoch, a summary needs 2"
    assert np.isnan(error_bound_ratio([1.0], one)[0])
    with pytest.raises(ParameterError, match="reason"):
        summarize_bound(bound, reason[:3])
    with pytest.raises(ParameterError, match="error_m"):
        error_bound_ratio(np.ones(9), summary)


def test_ratio_is_the_rmse_over_the_rms_bound_on_the_same_epochs_runs_pooled():
    rng = np.random.default_rng(11)
    bound = rng.uniform(0.5, 2.0, size=8)
    reason = np.array([""] * 8, dtype=object)
    bound[2], reason[2] = np.nan, "heard 2 anchors, a plan fix needs 3"
    bound[5], reason[5] = 1e8, "near-singular information (condition 3.2e+09)"   # a reason wins over a number
    errors = rng.uniform(0.0, 3.0, size=(3, 8))
    errors[0, 1] = errors[2, 6] = np.nan        # no estimate in those runs
    summary = summarize_bound(bound, reason)
    ratio, note = error_bound_ratio(errors, summary)
    assert note == ""
    se2 = sb2 = n = 0
    for r in range(3):
        for e in range(8):
            if e in (2, 5) or np.isnan(errors[r, e]):
                continue
            se2, sb2, n = se2 + errors[r, e] ** 2, sb2 + bound[e] ** 2, n + 1
    assert ratio == pytest.approx(np.sqrt(se2 / n) / np.sqrt(sb2 / n), rel=1e-12)
    one_run, _ = error_bound_ratio(errors[1], summary)
    keep = [0, 1, 3, 4, 6, 7]
    assert one_run == pytest.approx(np.sqrt(np.mean(errors[1, keep] ** 2) / np.mean(bound[keep] ** 2)), rel=1e-12)


def test_heat_map_draws_an_na_cell_without_a_number_and_the_caption_gets_its_note():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    from locbook.plotting import heat_map, heat_map_notes
    note = "n/a: the bound is undefined at 60 % of epochs (heard fewer than 3 anchors)"
    rows = [{"kind": "static", "method": "a", "scenario": "s", "ratio": 1.5, "ratio_note": ""},
            {"kind": "static", "method": "b", "scenario": "s", "ratio": float("nan"), "ratio_note": note},
            {"kind": "static", "method": "a", "scenario": "t", "ratio": None, "ratio_note": note},
            {"kind": "static", "method": "b", "scenario": "t", "ratio": float("nan"), "ratio_note": ""},  # blank
            {"kind": "tracking", "method": "a", "scenario": "s", "ratio": float("nan"), "ratio_note": "other"}]
    fig, ax = plt.subplots()
    image = heat_map(ax, rows, "static", ["a", "b"], ["s", "t"])
    shown = np.ma.filled(image.get_array().astype(float), np.nan)
    assert shown[0, 0] == pytest.approx(np.log2(1.5)) and np.isnan(shown[[1, 0, 1], [0, 1, 1]]).all()
    texts = {(t.get_position(), t.get_text()) for t in ax.texts}
    assert texts == {((0, 0), "1.50"), ((0, 1), "n/a"), ((1, 0), "n/a")}     # (column, row): no number in n/a
    na = [p for p in ax.patches if isinstance(p, Rectangle) and p.get_hatch() == "xx"]
    assert sorted(p.get_xy() for p in na) == [(-0.5, 0.5), (0.5, -0.5)]
    assert all(p.get_width() == p.get_height() == 1 for p in na)
    r, g, b, _ = na[0].get_facecolor()
    assert r == g == b                              # grey, not a colour of the scale
    plt.close(fig)
    assert heat_map_notes(rows, "static") == [f"s / b: {note}", f"t / a: {note}"]
    assert heat_map_notes(rows, "tracking") == ["s / a: other"]
    shared = [dict(r, scenario="s") for r in rows[1:3]]
    assert heat_map_notes(shared, "static") == [f"s / b, a: {note}"]
