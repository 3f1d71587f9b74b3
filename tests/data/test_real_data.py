"""Measured data end to end: the NaN rules hold on the real Kolakowski (2021) readings (the shipped data set), the floor
geometry and the accuracy table agree with independent computations."""
import numpy as np
import pytest

import locbook as lb
from locbook.scenarios import measured as ko


@pytest.fixture(scope="module")
def real():
    data = ko.load("kolakowski2021")
    model = ko.channel(ko.calibrate(data))
    return data, model


def test_static_methods_use_the_heard_anchors_of_each_real_epoch(real):
    data, model = real
    _, distance, rss = ko.calibration_set(data)
    heard = (~np.isnan(rss)).sum(axis=1)
    pick = np.r_[np.flatnonzero(heard == 6)[:20], np.flatnonzero(heard == 4)[:20], np.flatnonzero(heard == 2)[:5]]
    grid = lb.grid_in_outline(data.outline_m, 0.25)
    res = lb.grid_ml_position(rss[pick], lb.RssModel(data.anchors_m, model, tag_height_m=data.tag_height_m), grid)
    assert np.isnan(res.position_m[heard[pick] < 3]).all()
    assert set(res.status[heard[pick] < 3]) == {"too_few_anchors"}
    assert np.isfinite(res.position_m[heard[pick] >= 3]).all()
    # an epoch with missing anchors gets exactly the fix of the problem without those anchors
    for k in np.flatnonzero(heard[pick] == 4)[:5]:
        row = rss[pick[k]]
        keep = ~np.isnan(row)
        sub = lb.PathLossModel(model.ref_power_dbm[keep], model.path_loss_exp[keep], model.sigma_db[keep],
                               min_distance_m=model.min_distance_m)
        alone = lb.grid_ml_position(row[keep], lb.RssModel(data.anchors_m[keep], sub, tag_height_m=data.tag_height_m),
                                    grid)
        np.testing.assert_array_equal(res.position_m[k], alone.position_m)
    knn = lb.knn_position(rss[pick], ko.radio_map(data, model)[1], ko.radio_map(data, model)[0], 5)
    assert np.isnan(knn[heard[pick] < 3]).all() and np.isfinite(knn[heard[pick] >= 3]).all()


def test_filters_predict_through_the_real_gaps(real):
    data, model = real
    dt = ko.epoch_s(data, "robot")
    reg, ticks = lb.regular_epochs(data.epochs("robot"), dt, tolerance_s=0.1 * dt)
    silent = np.isnan(reg.rss_dbm).all(axis=1)
    assert silent.sum() == len(reg.time_s) - len(ticks) > 300            # the drive's pauses: 338 empty ticks
    motion = lb.constant_velocity(dt, 0.05)
    stream = lb.RssMeasurement(reg.rss_dbm, data.anchors_m, model, np.array([0, 1]), tag_height_m=data.tag_height_m)
    res = lb.extended_kalman_filter(motion.F, motion.Q, np.r_[4.0, 3.0, 0, 0], np.diag([4.0, 4, 1, 1]), [stream])
    assert np.isfinite(res.mean).all()
    # through a silent stretch the filter only predicts: position variance grows, the velocity is carried
    run = np.flatnonzero(silent[1:] & silent[:-1])[0] + 1
    assert res.cov[run, 0, 0] > res.cov[run - 1, 0, 0]
    np.testing.assert_allclose(res.mean[run, :2], res.mean[run - 1, :2] + dt * res.mean[run - 1, 2:], rtol=1e-12)


def _ray_casting(point, polygon):
    """Independent point-in-polygon test (even-odd rule)."""
    x, y = point
    inside = False
    for (x0, y0), (x1, y1) in zip(polygon, np.roll(polygon, -1, axis=0)):
        if (y0 > y) != (y1 > y) and x < x0 + (y - y0) * (x1 - x0) / (y1 - y0):
            inside = not inside
    return inside


def test_inside_outline_agrees_with_ray_casting(real):
    data, _ = real
    rng = np.random.default_rng(0)
    points = rng.uniform([-1, -1], [10, 8], (2000, 2))
    expected = np.array([_ray_casting(p, data.outline_m) for p in points])
    np.testing.assert_array_equal(lb.inside_outline(points, data.outline_m), expected)
    cells = lb.grid_in_outline(data.outline_m, 0.1)
    assert all(_ray_casting(c, data.outline_m) for c in cells[::50])
    # the flat's area (shoelace) against the cell count of the 0.1 m grid
    o = data.outline_m
    area = 0.5 * abs(np.dot(o[:, 0], np.roll(o[:, 1], -1)) - np.dot(o[:, 1], np.roll(o[:, 0], -1)))
    assert abs(len(cells) * 0.01 - area) < 0.03 * area


def test_distance_to_segments_closed_form():
    segments = np.array([[[0.0, 0.0], [4.0, 0.0]], [[4.0, 0.0], [4.0, 3.0]]])
    points = np.array([[2.0, 1.0], [5.0, 1.5], [-3.0, -4.0], [6.0, 7.0], [np.nan, 0.0]])
    expected = [1.0, 1.0, 5.0, np.hypot(2.0, 4.0), np.nan]
    np.testing.assert_allclose(lb.distance_to_segments(points, segments), expected)


@pytest.mark.slow
def test_accuracy_metrics_against_direct_numpy():
    rng = np.random.default_rng(1)
    e = np.abs(rng.normal(0, 1.0, 4000))
    e[[5, 17]] = np.nan
    m = lb.accuracy_metrics(e, rng=rng, n_bootstrap=2000)
    f = e[np.isfinite(e)]
    assert m["coverage"] == pytest.approx(3998 / 4000) and m["n"] == 4000
    assert m["mean_m"] == pytest.approx(f.mean()) and m["median_m"] == pytest.approx(np.median(f))
    assert m["rmse_m"] == pytest.approx(np.sqrt(np.mean(f**2))) and m["max_m"] == f.max()
    assert m["ce95_m"] == pytest.approx(np.percentile(f, 95)) and m["p75_m"] == pytest.approx(np.percentile(f, 75))
    # the bootstrap interval of the mean against the normal-theory one, mean +- 1.96 s / sqrt(n)
    half = 1.96 * f.std(ddof=1) / np.sqrt(f.size)
    assert m["mean_m_high"] - m["mean_m_low"] == pytest.approx(2 * half, rel=0.1)


def test_block_bootstrap_widens_the_interval_of_correlated_errors():
    """An AR(1) error series: blocks keep the correlation, i.i.d. resampling understates the spread."""
    rng = np.random.default_rng(2)
    n, phi = 5000, 0.95
    x = np.empty(n)
    x[0] = 0.0
    for t in range(1, n):
        x[t] = phi * x[t - 1] + rng.normal()
    e = np.abs(x)
    iid = lb.accuracy_metrics(e, rng=np.random.default_rng(3), n_bootstrap=500)
    blocks = lb.accuracy_metrics(e, rng=np.random.default_rng(3), n_bootstrap=500, block_length=100)
    width = lambda m: m["mean_m_high"] - m["mean_m_low"]
    assert width(blocks) > 2.5 * width(iid)       # variance inflation ~(1 + phi) / (1 - phi) = 39, ratio ~6


def test_a_calibration_that_cannot_fit_an_anchor_names_it(monkeypatch):
    """An anchor that heard nothing on the calibration points is named with its status, not blamed on the solver."""
    from locbook.errors import ConvergenceError
    from locbook.scenarios import measured as k
    from locbook.scenarios import measured_setup
    data = k.load("kolakowski2021")
    xy, distance, rss = k.calibration_set(data)
    rss = rss.copy()
    rss[:, 2] = np.nan
    monkeypatch.setattr(measured_setup, "calibration_set", lambda _data: (xy, distance, rss))   # calibrate's home
    with pytest.raises(ConvergenceError, match=rf"{data.anchor_ids[2]}: too_few_distances"):
        k.calibrate(data)
