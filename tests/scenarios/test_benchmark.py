"""The cross-document benchmark and the library pieces it added: the Fisher information of the anchors
heard, the particle filter's Gaussian start, per-reader sigma in the grid/particle likelihood. Checked against
closed forms, scipy and an independent covariance-form Kalman recursion."""
from dataclasses import replace

import numpy as np
import pytest
from scipy.stats import norm

import locbook as lb
from locbook import benchmark as bm
from locbook.scenarios import ozkaya


def test_heard_mask_equals_leaving_the_anchors_out():
    rng = np.random.default_rng(0)
    anchors = rng.uniform(0, 10, (5, 2))
    points = rng.uniform(0, 10, (7, 2))
    n = np.array([2.0, 2.5, 3.0, 1.8, 2.2])
    sigma = np.array([4.0, 5.0, 6.0, 3.0, 7.0])
    heard = rng.random((7, 5)) < 0.6
    def rss(keep=slice(None)):          # the anchors 1.1 m above the tag's plane
        return lb.RssModel(np.column_stack([anchors[keep], np.full(len(anchors[keep]), 1.1)]),
                           lb.PathLossModel(0.0, n[keep], sigma[keep]), tag_height_m=0.0)

    got = lb.rss_position_information(points, rss(), heard=heard)
    for p, h, info in zip(points, heard, got):
        want = lb.rss_position_information(p, rss(h)) if h.any() else np.zeros((2, 2))
        np.testing.assert_allclose(info, want, rtol=1e-12, atol=1e-15)
    state = np.concatenate([points, np.zeros((7, 2))], axis=1)
    full = lb.rss_state_information(state, rss(), [0, 1], heard=heard)
    np.testing.assert_allclose(full[:, :2, :2], got, rtol=1e-12)
    assert np.all(full[:, 2:, :] == 0)
    with pytest.raises(ValueError, match="heard must be booleans"):
        lb.rss_position_information(points, rss(), heard=heard.astype(int))


def test_particle_filter_gaussian_start():
    rng = np.random.default_rng(1)
    model = lb.RssModel(np.array([[0.0, 0.0], [20.0, 0.0], [0.0, 20.0]]),
                        lb.PathLossModel(-40.0, 2.0, 4.0, min_distance_m=0.1))
    runs = 4000
    nothing_heard = np.full((runs, 1, 3), np.nan)                  # flat likelihood: the estimate is the particle
    start = np.array([10.0, 8.0])
    res = lb.particle_filter(nothing_heard, model, rng=rng, n_particles=1, region_m=((0, 0), (20, 20)), spread_m=0.5,
                             initial_position_m=np.tile(start, (runs, 1)), initial_sd_m=1.5)
    draws = res.mean[:, 0]
    se = 1.5 / np.sqrt(runs)
    assert np.all(np.abs(draws.mean(axis=0) - start) < 4 * se)
    assert np.all(np.abs(draws.std(axis=0, ddof=1) - 1.5) < 4 * 1.5 / np.sqrt(2 * runs))
    with pytest.raises(ValueError, match="initial_position_m too"):
        lb.particle_filter(nothing_heard, model, rng=rng, n_particles=1, region_m=((0, 0), (20, 20)), initial_sd_m=1.0)


def test_per_reader_sigma_likelihood_matches_scipy():
    readers = np.array([[0.0, 0.0], [8.0, 0.0], [0.0, 6.0]])
    sigma = np.array([3.0, 5.0, 8.0])
    model = lb.RssModel(readers, lb.PathLossModel(np.array([-40.0, -45.0, -50.0]), np.array([2.0, 2.5, 3.0]), sigma,
                                                  min_distance_m=0.1))
    rss = np.array([[-60.0, np.nan, -70.0]])
    cells = np.array([[1.0, 2.0], [4.0, 4.0], [6.0, 1.0]])
    ll = model.log_likelihood(rss, cells)[0]
    mean = model.mean_rss_dbm(cells)[0]
    heard = ~np.isnan(rss[0])
    want = norm.logpdf(rss[0, heard], mean[:, heard], sigma[heard]).sum(axis=-1)
    np.testing.assert_allclose(ll - ll[0], want - want[0], rtol=1e-12)
    np.testing.assert_allclose(ll, want, rtol=1e-12)
    with pytest.raises(ValueError, match="one per anchor"):
        lb.RssModel(readers, lb.PathLossModel(-40.0, 2.0, np.array([3.0, 4.0])))


@pytest.mark.parametrize("key", list(bm.STATIC_SCENARIOS))
def test_static_bound_is_the_closed_form_crlb(key):
    sc = bm.static_scenario(key)
    want = lb.rss_crlb_m(sc.points_m, lb.RssModel(sc.anchors_m, lb.PathLossModel(0.0, sc.channel.path_loss_exp,
                                                                                  sc.channel.sigma_db)))
    np.testing.assert_allclose(bm.static_bound_m(sc), want, rtol=1e-10)


@pytest.mark.parametrize("key", list(bm.STATIC_SCENARIOS))
def test_noise_free_readings_give_the_truth(key):
    sc = bm.static_scenario(key)
    ch = sc.channel
    sc = replace(sc,
                 channel=lb.PathLossModel(ch.ref_power_dbm, ch.path_loss_exp, 0.0, min_distance_m=ch.min_distance_m))
    rss = sc.rss_dbm(1, np.random.default_rng(2))
    fixes = bm.static_fixes(sc, rss, methods=["lls", "wls", "box_ls", "grid_ml", "rss_ml"])
    for name in ("lls", "wls", "box_ls", "rss_ml"):
        np.testing.assert_allclose(fixes[name][0], sc.points_m, atol=2e-4, err_msg=name)
    # grid ML: the cell whose mean readings are nearest (brute force over every cell), within a pitch of the truth
    cells = sc.grid_m()
    mean = sc.channel.mean_rss_dbm(sc.distances_m(cells))
    cost = np.sum((rss[0][:, None, :] - mean[None]) ** 2, axis=-1)             # (P, C)
    chosen = np.argmin(np.linalg.norm(cells[None] - fixes["grid_ml"][0][:, None], axis=-1), axis=1)
    assert np.allclose(fixes["grid_ml"][0], cells[chosen], atol=1e-12)             # a cell of the grid
    np.testing.assert_allclose(cost[np.arange(len(cells[chosen])), chosen], cost.min(axis=1), atol=1e-9)  # ties allowed
    assert np.all(np.abs(fixes["grid_ml"][0] - sc.points_m) <= sc.grid_spacing_m + 1e-9)


def test_grid_mmse_blocks_equal_one_solve(monkeypatch):
    sc = bm.static_scenario("ozkaya2011-room")
    rss = sc.rss_dbm(5, np.random.default_rng(3))
    whole = bm.static_fixes(sc, rss, methods=["grid_mmse"])["grid_mmse"]
    from locbook import battery
    monkeypatch.setattr(battery, "GRID_BLOCK_VALUES", sc.grid_m().shape[0] * 7)     # blocks of 7 problems
    blocks = bm.static_fixes(sc, rss, methods=["grid_mmse"])["grid_mmse"]
    np.testing.assert_allclose(blocks, whole, rtol=0, atol=1e-12)


def _covariance_form_bound(sc, ts):
    """The PCRLB as the covariance of a Kalman filter linearised at the truth (covariance form, Joseph update), with
    rows only for the anchors heard: an independent recursion from the information form of posterior_crlb."""
    motion = lb.constant_velocity(sc.dt_s, ts.q, dim=2)
    P = ts.P0.copy()
    n = sc.channel.path_loss_exp * np.ones(len(sc.anchors_m))
    sigma = sc.channel.sigma_db * np.ones(len(sc.anchors_m))
    out = []
    for t, p in enumerate(sc.truth_m):
        P = motion.F @ P @ motion.F.T + motion.Q
        heard = np.ones(len(sc.anchors_m), bool) if not sc.measured else ~np.isnan(sc.measured_rss_dbm[t])
        if np.all(np.isfinite(p)) and heard.any():
            a = sc.anchors_m[heard]
            diff = p - a[:, :2]
            d2 = np.sum(diff**2, axis=1) + (0.0 if sc.tag_height_m is None else (a[:, 2] - sc.tag_height_m) ** 2)
            H = np.zeros((heard.sum(), 4))
            H[:, :2] = -(10 * n[heard] / np.log(10))[:, None] * diff / d2[:, None]
            R = np.diag(sigma[heard] ** 2)
            K = P @ H.T @ np.linalg.inv(H @ P @ H.T + R)
            A = np.eye(4) - K @ H
            P = A @ P @ A.T + K @ R @ K.T
        out.append(np.sqrt(P[0, 0] + P[1, 1]))
    return np.array(out)


@pytest.mark.parametrize("key", ["dogan2015-walk", "data-kolakowski2021"])
def test_tracking_bound_is_the_kalman_covariance_linearised_at_the_truth(key):
    sc = (bm.measured_tracking_scenario("kolakowski2021") if key.startswith("data-") else bm.tracking_scenario(key))
    ts = bm.TrackerSettings(q=0.05)
    np.testing.assert_allclose(bm.tracking_bound_m(sc, ts), _covariance_form_bound(sc, ts), rtol=1e-8)


def test_score_interval_is_the_delta_method_over_runs():
    rng = np.random.default_rng(4)
    e = np.abs(rng.normal(0, 2, (50, 1)))
    cell = bm.score(e, np.ones(1), measured=False, rng=rng, n_bootstrap=10)
    se = lb.rmse_standard_error_m(e[:, 0])
    assert cell["rmse_m"] == pytest.approx(lb.rmse_m(e))
    assert cell["rmse_high_m"] - cell["rmse_m"] == pytest.approx(1.96 * se, rel=1e-12)
    assert cell["ratio"] == pytest.approx(cell["rmse_m"])


def test_every_declared_method_gives_a_cell_and_a_new_scenario_a_column(monkeypatch):
    base = bm.static_scenario("ozkaya2011-room")
    extra = replace(base, key="test-room-4", anchors_m=ozkaya.readers_for("corners4"))
    monkeypatch.setitem(bm.STATIC_SCENARIOS, "test-room-4", lambda: extra)
    rows = []
    for key in ("ozkaya2011-room", "test-room-4"):
        sc = bm.static_scenario(key)
        rows += bm.static_cells(sc, 3, bm.scenario_rng(0, "static", key), knn_k=4, knn_map_spacing_m=0.5,
                                n_bootstrap=10)
    assert [(r["scenario"], r["method"]) for r in rows] == [(k, m) for k in ("ozkaya2011-room", "test-room-4")
                                                            for m in bm.STATIC_METHODS]
    assert all(r["settings"] and np.isfinite(r["ratio"]) for r in rows)
    # a fourth reader adds information: the bound falls
    assert rows[-1]["bound_rms_m"] < rows[0]["bound_rms_m"]


def test_box_outline_is_the_rectangle_outline_box_reads_back():
    from locbook.geometry import box_outline, inside_outline, outline_box
    outline = box_outline((1.0, -2.0), (4.0, 3.0))
    lower, upper = outline_box(outline)
    np.testing.assert_array_equal(lower, [1.0, -2.0])
    np.testing.assert_array_equal(upper, [4.0, 3.0])
    # shoelace area of a counter-clockwise polygon is +width * height
    x, y = outline.T
    assert 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) == 15.0
    assert inside_outline(np.array([[2.5, 0.5], [4.5, 0.5]]), outline).tolist() == [True, False]
    with pytest.raises(ValueError, match="upper_m"):
        box_outline((0.0, 0.0), (1.0, 0.0))
    with pytest.raises(ValueError, match="lower_m"):
        box_outline((0.0, 0.0, 0.0), (1.0, 1.0))


def test_heat_map_colours_log2_of_the_ratio_and_hatches_what_does_not_apply():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    from locbook.plotting import heat_map
    rows = [{"kind": "static", "method": "a", "scenario": "s", "ratio": 2.0},
            {"kind": "static", "method": "b", "scenario": "s", "ratio": 0.5},
            {"kind": "static", "method": "a", "scenario": "t", "ratio": 100.0},
            {"kind": "tracking", "method": "b", "scenario": "t", "ratio": 4.0}]     # another kind: left out
    fig, ax = plt.subplots()
    image = heat_map(ax, rows, "static", ["a", "b"], ["s", "t", "u"], {"u": "no moving tag"}, vmax_log2=3.0)
    shown = np.ma.filled(image.get_array().astype(float), np.nan)
    np.testing.assert_array_equal(shown[:, 0], [1.0, -1.0])          # log2(2), log2(0.5)
    assert shown[0, 1] == 3.0 and np.isnan(shown[1, 1]) and np.isnan(shown[:, 2]).all()   # clipped; no row
    assert [t.get_text() for t in ax.texts] == ["2.00", "100.00", "0.50", "n/a"]
    assert sum(isinstance(p, Rectangle) and p.get_hatch() == "//" for p in ax.patches) == 1
    plt.close(fig)


def test_ml_fixes_kept_from_an_earlier_call_equal_a_fresh_solve_and_follow_every_input(monkeypatch):
    """battery.ml_fixes keeps its latest results: a repeated call equals a solve with the memo emptied (bit for bit),
    hands out a copy (changing it changes nothing kept), and readings or a channel that differ are solved again."""
    import locbook.battery as battery
    sc = bm.tracking_scenario(next(iter(bm.TRACKING_SCENARIOS)))
    rss = sc.rss_dbm(2, np.random.default_rng(3))
    monkeypatch.setattr(battery, "_ML_FIXES_MEMO", {})
    first = battery.ml_fixes(sc, rss)
    first[...] = 0.0                                            # the caller's copy
    again = battery.ml_fixes(sc, rss)
    monkeypatch.setattr(battery, "_ML_FIXES_MEMO", {})
    np.testing.assert_array_equal(again, battery.ml_fixes(sc, rss))
    assert np.isfinite(again).any() and not (again == 0.0).all()
    other = replace(sc, channel=replace(sc.channel, path_loss_exp=np.asarray(sc.channel.path_loss_exp) + 0.5))
    monkeypatch.setattr(battery, "_ML_FIXES_MEMO", {})
    fresh_other = battery.ml_fixes(other, rss)
    monkeypatch.setattr(battery, "_ML_FIXES_MEMO", {})
    battery.ml_fixes(sc, rss)
    np.testing.assert_array_equal(battery.ml_fixes(other, rss), fresh_other)
    assert not np.array_equal(fresh_other, again, equal_nan=True)
