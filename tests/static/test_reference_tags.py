"""Reference-tag calibration and RSSI smoothing (locbook.static.reference_tags, Ozkaya 2011): the online
calibration against a brute-force grid search and the closed form, the smoothing by hand."""
import numpy as np

import locbook as lb

TAGS = np.array([[1.5, 1.5], [2.0, 3.0], [4.5, 1.5], [5.0, 3.0]])
TB_READERS = np.array([[0.0, 0.0], [9.0, 4.0], [9.0, 0.0]])
WALL = [[[3.0, 0.0], [3.0, 4.0]]]


def test_online_calibration_equals_brute_force_grid_search():
    rng = np.random.default_rng(10)
    d = lb.pairwise_distance_m(TAGS, TB_READERS)
    nw = lb.wall_crossings(TAGS, TB_READERS, WALL)
    truth = np.array([-45.0, -49.0, -42.0]) - 10 * np.array([2.3, 2.7, 2.5]) * np.log10(d) - 2.0 * nw
    obs = np.round(truth + rng.normal(0, 5.2, (3,) + truth.shape))              # 3 steps, 1 dB readers
    cal = lb.calibrate_from_reference_tags(obs, TAGS, TB_READERS, walls_m=WALL, wall_attenuation_db=2.0)
    alpha, n = np.meshgrid(np.arange(-55, -40 + 1e-9, 0.01), np.arange(1.5, 3 + 1e-9, 0.001), indexing="ij")
    for s in range(3):
        for j in range(3):
            y = obs[s, :, j] + 2.0 * nw[:, j]
            cost = ((y[None, None, :] - (alpha[..., None] - 10 * n[..., None] * np.log10(d[:, j]))) ** 2).sum(-1)
            best = np.unravel_index(np.argmin(cost), cost.shape)
            ours = ((y - (cal.ref_power_dbm[s, j] - 10 * cal.path_loss_exp[s, j] * np.log10(d[:, j]))) ** 2).sum()
            assert ours <= cost[best] + 1e-6                                 # never worse than the grid
            assert abs(cal.ref_power_dbm[s, j] - alpha[best]) <= 0.02
            assert abs(cal.path_loss_exp[s, j] - n[best]) <= 0.002
            assert (-55 - 1e-7 <= cal.ref_power_dbm[s, j] <= -40 + 1e-7
                    and 1.5 - 1e-7 <= cal.path_loss_exp[s, j] <= 3 + 1e-7)
    resid = obs - cal.expected_dbm
    np.testing.assert_allclose(cal.sigma_db, np.sqrt((resid**2).sum(axis=(-2, -1)) / 12))   # Eq. (6.7)


def test_unbounded_online_calibration_is_the_closed_form():
    d = lb.pairwise_distance_m(TAGS, TB_READERS)
    obs = -50.0 - 22.0 * np.log10(d) + np.random.default_rng(11).normal(0, 3.0, d.shape)
    cal = lb.calibrate_from_reference_tags(obs, TAGS, TB_READERS, ref_power_bounds_dbm=None, path_loss_exp_bounds=None)
    cf = lb.fit_path_loss_closed_form(d.T, obs.T)
    np.testing.assert_allclose(cal.ref_power_dbm, cf.ref_power_dbm, atol=1e-6)
    np.testing.assert_allclose(cal.path_loss_exp, cf.path_loss_exp, atol=1e-6)


def test_smooth_rssi_by_hand():
    s = np.array([-60.0, -70.0, -65.0])
    refs = np.array([[-60.0, -71.0, -65.0], [-80.0, -50.0, -70.0], [-75.0, -75.0, -75.0]])
    expected = refs - np.array([[2.0, -1.0, 0.5], [0.0, 0.0, 0.0], [1.0, 1.0, 1.0]])
    inv = 1.0 / np.array([1.0, 400 + 400 + 25, 225 + 25 + 100])
    w = inv / inv.sum()
    out, nearest, applied = lb.smooth_rssi(s, refs, expected)
    assert nearest == 0 and applied
    np.testing.assert_allclose(out, s - w[0] * np.array([2.0, -1.0, 0.5]))
    same, _, applied = lb.smooth_rssi(s, refs, expected, threshold=0.999)
    assert not applied
    np.testing.assert_array_equal(same, s)
