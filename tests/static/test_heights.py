"""Anchors with heights and a tag at a known height: every estimator solves for (x, y) with 3-D distances.
Checked against closed forms, an independent scipy solve, and the equivalent 3-D problems."""
import numpy as np
import pytest
from scipy.optimize import least_squares

from locbook import (
    PathLossModel,
    RssMeasurement,
    RssModel,
    constant_velocity,
    extended_kalman_filter,
    grid_ml_position,
    lateration_box_ls,
    lateration_ls,
    lateration_wls,
    rss_ml_position,
    rss_position_information,
)

ANCHORS = np.array([[5.48, 2.41, 2.08], [0.79, 6.75, 2.62], [3.03, 0.14, 2.38], [3.79, 7.06, 1.85],
                    [5.99, 0.43, 2.31], [8.66, 6.59, 2.41]])       # the Kolakowski (2021) anchors
H = 1.3
MODEL = PathLossModel(-55.0, 2.2, 3.0)


def ranges_3d(points_xy):
    lifted = np.concatenate([points_xy, np.full(points_xy.shape[:-1] + (1,), H)], -1)
    return np.linalg.norm(lifted[..., None, :] - ANCHORS, axis=-1)


def test_lateration_with_known_height_is_exact_on_exact_ranges():
    rng = np.random.default_rng(0)
    truth = rng.uniform([0.5, 0.5], [8.5, 6.5], (50, 2))
    d = ranges_3d(truth)
    for res in (lateration_ls(ANCHORS, d, tag_height_m=H),
                lateration_wls(ANCHORS, d, np.ones(5), tag_height_m=H),
                lateration_box_ls(ANCHORS, d, [0, 0], [9.07, 7.1], tag_height_m=H)):
        assert res.position_m.shape == (50, 2)
        np.testing.assert_allclose(res.position_m, truth, atol=1e-5 if "box" in res.method else 1e-9)
    # the 3-D ranges taken as plan ranges (heights ignored) shift every fix by the same few centimetres
    shift = lateration_ls(ANCHORS[:, :2], d).position_m - truth
    assert np.abs(shift).max() > 0.01 and np.ptp(shift, axis=0).max() < 1e-9


def test_lateration_with_height_handles_not_heard_anchors():
    truth = np.array([[2.0, 3.0], [6.0, 5.0]])
    d = ranges_3d(truth)
    d[0, 1] = np.nan
    res = lateration_ls(ANCHORS, d, tag_height_m=H)
    np.testing.assert_allclose(res.position_m, truth, atol=1e-9)
    assert res.status.tolist() == ["ok", "ok"]


def test_anchors_at_the_tag_height_reduce_to_the_plan_problem():
    flat = ANCHORS.copy()
    flat[:, 2] = H
    rng = np.random.default_rng(1)
    power = rng.normal(-70, 6, (20, 6))
    a = rss_ml_position(power, RssModel(flat, MODEL, tag_height_m=H))
    b = rss_ml_position(power, RssModel(flat[:, :2], MODEL))
    np.testing.assert_allclose(a.position_m, b.position_m, atol=1e-9)


def test_rss_ml_with_height_matches_an_independent_scipy_solve():
    rng = np.random.default_rng(2)
    truth = rng.uniform([0.5, 0.5], [8.5, 6.5], (25, 2))
    power = MODEL.mean_rss_dbm(ranges_3d(truth)) + rng.normal(0, 3.0, (25, 6))
    res = rss_ml_position(power, RssModel(ANCHORS, MODEL, tag_height_m=H))
    assert res.converged.all()
    for k in range(25):
        def resid(p, k=k):
            d = np.linalg.norm(np.r_[p, H] - ANCHORS, axis=-1)
            return power[k] - MODEL.mean_rss_dbm(d)
        ref = least_squares(resid, res.position_m[k] + 0.3, xtol=1e-14, ftol=1e-14, gtol=1e-14)
        if np.sum(ref.fun**2) <= np.sum(resid(res.position_m[k])**2) + 1e-9:   # same basin: same minimum
            np.testing.assert_allclose(res.position_m[k], ref.x, atol=1e-6)
        # a stationary point of the 3-D cost: scipy started there does not move
        again = least_squares(resid, res.position_m[k], xtol=1e-15, ftol=1e-15, gtol=1e-15)
        np.testing.assert_allclose(again.x, res.position_m[k], atol=1e-6)


def test_grid_ml_with_height_equals_the_3d_grid_at_that_height():
    rng = np.random.default_rng(3)
    grid = np.stack(np.meshgrid(np.arange(0, 9.1, 0.25), np.arange(0, 7.1, 0.25)), -1).reshape(-1, 2)
    power = rng.normal(-70, 6, (30, 6))
    power[3, 2] = np.nan
    a = grid_ml_position(power, RssModel(ANCHORS, MODEL, tag_height_m=H), grid)
    grid3 = np.column_stack([grid, np.full(len(grid), H)])
    b = grid_ml_position(power, RssModel(ANCHORS, MODEL), grid3)
    np.testing.assert_array_equal(a.position_m, b.position_m[:, :2])


def test_bayes_model_with_height_uses_3d_distances():
    model = RssModel(ANCHORS, PathLossModel(-55.0, 2.2, 3.0, min_distance_m=0.1), tag_height_m=H)
    cells = np.array([[1.0, 1.0], [4.0, 3.0]])
    expected = -55.0 - 22.0 * np.log10(ranges_3d(cells))
    np.testing.assert_allclose(model.mean_rss_dbm(cells)[0], expected, rtol=1e-13)
    with pytest.raises(ValueError, match="anchors_m"):
        RssModel(ANCHORS[:, :2], PathLossModel(-55.0, 2.2, 3.0), tag_height_m=H)


def test_crlb_height_offsets_per_anchor():
    p = np.array([3.0, 4.0])
    info = rss_position_information(p, RssModel(ANCHORS, MODEL, tag_height_m=H))
    diff = p - ANCHORS[:, :2]
    d2 = ranges_3d(p) ** 2
    beta2 = (22.0 / (3.0 * np.log(10))) ** 2
    np.testing.assert_allclose(info, beta2 * np.einsum("j,ji,jk->ik", 1 / d2**2, diff, diff), rtol=1e-13)


def test_ekf_with_known_height_equals_a_3d_state_with_a_frozen_height():
    """Tag height known == a 3-D state whose height has zero variance and zero process noise."""
    rng = np.random.default_rng(4)
    steps = 40
    truth = np.cumsum(rng.normal(0, 0.1, (steps, 2)), axis=0) + [4.0, 3.0]
    power = MODEL.mean_rss_dbm(ranges_3d(truth)) + rng.normal(0, 3.0, (steps, 6))
    power[5, [0, 3]] = np.nan
    dt = 1 / 3
    for mode in ("parallel", "serial"):
        plan = constant_velocity(dt, 0.05, dim=2)              # state [x, y, vx, vy]
        x0 = np.array([4.0, 3.0, 0.0, 0.0])
        P0 = np.diag([4.0, 4.0, 1.0, 1.0])
        a = extended_kalman_filter(plan.F, plan.Q, x0, P0, [RssMeasurement(power, ANCHORS, MODEL, np.array([0, 1]),
                                                                           mode=mode, tag_height_m=H)])
        space = constant_velocity(dt, 0.05, dim=3)             # state [x, y, z, vx, vy, vz]
        keep = np.array([0, 1, 3, 4])
        Q = np.zeros((6, 6))
        Q[np.ix_(keep, keep)] = plan.Q
        x03 = np.array([4.0, 3.0, H, 0.0, 0.0, 0.0])
        P03 = np.zeros((6, 6))
        P03[np.ix_(keep, keep)] = P0
        b = extended_kalman_filter(space.F, Q, x03, P03, [RssMeasurement(power, ANCHORS, MODEL, np.array([0, 1, 2]),
                                                                         mode=mode)])
        np.testing.assert_allclose(a.mean[..., [0, 1]], b.mean[..., [0, 1]], atol=1e-10)
        np.testing.assert_allclose(b.mean[..., 2], H, atol=1e-12)
