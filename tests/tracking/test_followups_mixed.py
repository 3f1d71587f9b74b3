"""Follow-ups of the reliability work: grid ML's memory guard, masked arrays in the metrics, peer-style calls of
the nonlinear stream and of fit_noise_ml, and the smoother on a run of no steps."""
import numpy as np
import pytest

import locbook as lb
from locbook import metrics
from locbook.static import grid_ml


def _grid_problem(n_problems=41, n_cells=301, seed=3):
    rng = np.random.default_rng(seed)
    anchors = np.array([[0.0, 0.0], [20.0, 0.0], [0.0, 20.0], [20.0, 20.0]])
    model = lb.PathLossModel(ref_power_dbm=-40.0, path_loss_exp=2.5, sigma_db=4.0)
    grid = rng.uniform(0, 20, (n_cells, 2))
    targets = rng.uniform(1, 19, (n_problems, 2))
    d = np.linalg.norm(targets[:, None] - anchors, axis=-1)
    return anchors, -40.0 - 25.0 * np.log10(d) + rng.normal(0, 4, d.shape), model, grid


def test_grid_ml_result_does_not_depend_on_chunk_or_the_block_limit(monkeypatch):
    anchors, rss, model, grid = _grid_problem()
    ref = lb.grid_ml_position(rss, lb.RssModel(anchors, model), grid)
    for chunk in (1, 2, 3, 4, 7, 40, 41, 5000):
        got = lb.grid_ml_position(rss, lb.RssModel(anchors, model), grid, chunk=chunk)
        assert np.array_equal(got.position_m, ref.position_m) and np.array_equal(got.cost, ref.cost), chunk
    # brute force, one problem at a time (closed form: the grid point of least squared residual)
    mean = -40.0 - 25.0 * np.log10(np.linalg.norm(grid[:, None] - anchors, axis=-1))
    brute = np.argmin(((rss[:, None, :] - mean) ** 2).sum(-1), axis=1)
    assert np.array_equal(ref.position_m, grid[brute])
    monkeypatch.setattr(grid_ml, "GRID_ML_BLOCK_BYTES", 8 * grid.shape[0] * 3)   # blocks of 3 problems
    got = lb.grid_ml_position(rss, lb.RssModel(anchors, model), grid)
    assert np.array_equal(got.position_m, ref.position_m) and np.array_equal(got.cost, ref.cost)


def test_grid_ml_refuses_a_grid_whose_smallest_block_is_over_the_limit_before_allocating(monkeypatch):
    anchors, rss, model, grid = _grid_problem()
    monkeypatch.setattr(grid_ml, "GRID_ML_BLOCK_BYTES", 8 * grid.shape[0] * 2 - 1)
    with pytest.raises(ValueError, match=r"^cells_m has 301 cells: .* MiB, over the limit GRID_ML_BLOCK_BYTES") as e:
        lb.grid_ml_position(rss, lb.RssModel(anchors, model), grid)
    assert "\n" not in str(e.value)
    one = lb.grid_ml_position(rss[:1], lb.RssModel(anchors, model), grid)      # one problem: one row fits
    assert np.isfinite(one.cost).all()
    # the block size is decided from the sizes alone: 10^4 problems on 10^7 cells fit 3 problems in 256 MiB
    monkeypatch.setattr(grid_ml, "GRID_ML_BLOCK_BYTES", 256 * 2**20)
    assert grid_ml._grid_ml_block(None, 10**4, 10**7) == 3
    assert grid_ml._grid_ml_block(2048, 10**4, 10**7) == 3


MASKED = np.ma.array([1.0, 2.0, 3.0, 1000.0], mask=[0, 0, 0, 1])


@pytest.mark.parametrize("fn", [metrics.mean_error_m, metrics.rmse_m, metrics.median_error_m, metrics.error_std_m,
                                metrics.percentile_error_m, metrics.rmse_standard_error_m, lb.mc_standard_error])
def test_a_masked_error_is_a_nan_in_every_metric(fn):
    assert np.isnan(fn(MASKED))
    assert np.isnan(fn(np.array([1.0, 2.0, 3.0, np.nan])))
    full = fn(np.ma.array([1.0, 2.0, 3.0, 4.0], mask=False))     # nothing masked: the plain array's value
    assert full == fn(np.array([1.0, 2.0, 3.0, 4.0]))


def test_masked_errors_in_summaries_and_the_cdf():
    s = metrics.error_summary(MASKED)                            # was numpy's "output array is read-only"
    assert s["n"] == 4 and all(np.isnan(s[k]) for k in ("mean_m", "rmse_m", "median_m", "p90_m", "std_m"))
    x, p = metrics.empirical_cdf(MASKED)
    assert not np.ma.isMaskedArray(x) and np.isnan(x[-1]) and np.array_equal(x[:3], [1, 2, 3])
    assert np.array_equal(p, [0.25, 0.5, 0.75, 1.0])
    per_run = metrics.error_summary_per_run(np.ma.array([[1.0, 2.0], [3.0, 4.0]], mask=[[0, 1], [0, 0]]))
    assert np.isnan(per_run["rmse_m"][0]) and per_run["rmse_m"][1] == np.sqrt(12.5)
    r = metrics.reduction_pct(np.ma.array([2.0, 4.0], mask=[0, 1]), 1.0)
    assert r[0] == 50.0 and np.isnan(r[1])
    assert lb.mc_standard_error([1.0, 3.0]) == 1.0                 # std(ddof=1) sqrt(2) / sqrt(2)


def test_a_column_z_of_a_nonlinear_stream_gets_the_column_hint():
    z = np.zeros((12, 2, 1))
    with pytest.raises(ValueError, match=r"column of 2 readings per step .*z\[\.\.\., 0\] of shape \(12, 2\)"):
        lb.NonlinearMeasurement(z, lambda x: x, np.eye(2))


def _ekf(h):
    z = np.ones((5, 2))
    jac = lambda x: np.broadcast_to(np.eye(2), np.shape(x)[:-1] + (2, 2))
    meas = lb.NonlinearMeasurement(z, h, np.eye(2), jacobian=jac)
    return lb.extended_kalman_filter(np.eye(2), 0.01 * np.eye(2), np.zeros(2), np.eye(2), [meas])


def test_a_filterpy_style_h_with_a_second_argument_gets_a_hint_not_a_bare_type_error():
    with pytest.raises(ValueError, match=r"h cannot be called as h\(x\).*write lambda x: h\(x, arg\)") as e:
        _ekf(lambda x, arg: x)
    assert "\n" not in str(e.value)

    def broken(x):                      # a TypeError raised inside a correct function is its own
        return len(3)
    with pytest.raises(TypeError, match="has no len"):
        _ekf(broken)
    assert np.allclose(_ekf(lambda x: x).mean[-1], 1.0, atol=0.5)


def test_fit_noise_ml_names_an_option_its_filter_kind_does_not_take():
    meas = lb.LinearMeasurement(np.ones((6, 2)), np.eye(2), np.eye(2))
    args = (np.eye(2), 0.01 * np.eye(2), np.zeros(2), np.eye(2), [meas])
    with pytest.raises(ValueError, match=r"^fit_noise_ml: the 'kf' filter has no option 'alpha': only kind='ukf'"):
        lb.fit_noise_ml(*args, kind="kf", alpha=0.5)
    with pytest.raises(ValueError, match=r"no option 'alpah': no filter kind takes it"):
        lb.fit_noise_ml(*args, kind="ukf", alpah=0.5)


def test_rts_smoother_of_a_run_with_no_steps_is_empty():
    meas = lb.LinearMeasurement(np.zeros((0, 2)), np.eye(2), np.eye(2))
    run = lb.kalman_filter(np.eye(2), 0.01 * np.eye(2), np.zeros(2), np.eye(2), [meas],
                           outputs=("x_pred", "P_pred", "P_cross"))
    s = lb.rts_smoother(run)
    assert s.mean.shape == (0, 2) and s.cov.shape == (0, 2, 2) and s.gain.shape == (0, 2, 2)
