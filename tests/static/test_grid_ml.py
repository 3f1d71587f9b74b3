"""Grid ML (locbook.static.grid_ml): the result does not depend on how the grid is split into blocks, and a grid
whose smallest block is over the memory limit is refused before anything is allocated."""
import numpy as np
import pytest

import locbook as lb
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
