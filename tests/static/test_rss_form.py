"""Stage 2: the static RSS estimators take the readings first, then the one RSS model (:class:`locbook.RssModel`:
anchors, channel, tag height, walls), then keyword-only options. The forms before it (anchors, readings, a
PathLossModel, ``tag_height_m=``; ``grid_m=``) stay one release: one DeprecationWarning each, naming the new call and
attributed to the caller's line, and the same numbers bit for bit. What an estimator cannot honour in a model is refused
by name."""
import re
import warnings

import numpy as np
import pytest

import locbook as lb

ANCHORS_3D = np.array([[5.48, 2.41, 2.08], [0.79, 6.75, 2.62], [3.03, 0.14, 2.38], [3.79, 7.06, 1.85],
                       [5.99, 0.43, 2.31], [8.66, 6.59, 2.41]])       # the Kolakowski (2021) anchors, with heights
H = 1.3
CHANNEL = lb.PathLossModel(np.array([-55.0, -53.0, -56.0, -54.0, -55.5, -52.0]), 2.2, 3.0, min_distance_m=0.1)
CELLS = np.stack(np.meshgrid(np.arange(0.0, 9.1, 0.25), np.arange(0.0, 7.1, 0.25)), -1).reshape(-1, 2)
SQUARE = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])
WALLS = np.array([[[5.0, -1.0], [5.0, 11.0]]])


def _readings():
    """Readings with shadowing, an anchor not heard and an implausible power: every branch of the estimators."""
    rng = np.random.default_rng(47)
    truth = rng.uniform([0.5, 0.5], [8.5, 6.5], (40, 2))
    model = lb.RssModel(ANCHORS_3D, CHANNEL, tag_height_m=H)
    rss = model.mean_rss_dbm(truth)[0] + rng.normal(0.0, 3.0, (40, 6))
    rss[3, 2] = rss[7, [0, 5]] = np.nan
    rss[11, 1] = 500.0
    return rss, model


def _old_call(function, *args, **kwargs):
    """``function(*args, **kwargs)`` and the one DeprecationWarning it gave (attributed to this file)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out = function(*args, **kwargs)
    assert [w.category for w in caught] == [DeprecationWarning], [str(w.message) for w in caught]
    assert caught[0].filename == __file__                     # the caller's line
    return out, str(caught[0].message)


def _same(a: lb.LocalizationResult, b: lb.LocalizationResult):
    for name in ("position_m", "converged", "cost", "status"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert (a.n_iter, a.method) == (b.n_iter, b.method)


def test_rss_ml_position_old_form_warns_and_gives_the_same_numbers():
    rss, model = _readings()
    start = lb.grid_ml_position(rss, model, CELLS).position_m
    new = lb.rss_ml_position(rss, model, start, region_m=((0.0, 0.0), (9.0, 7.0)), tol_m=1e-9)
    old, message = _old_call(lb.rss_ml_position, ANCHORS_3D, rss, CHANNEL, initial_m=start, tag_height_m=H,
                             region_m=((0.0, 0.0), (9.0, 7.0)), tol_m=1e-9)
    assert message == ("rss_ml_position(anchors_m, rss_dbm, channel, ...) is deprecated: use "
                       "rss_ml_position(rss_dbm, RssModel(anchors_m, channel, tag_height_m=...), ...)")
    assert set(new.status.tolist()) >= {"ok", "implausible_reading"}
    _same(old, new)


def test_grid_ml_position_old_form_warns_and_gives_the_same_numbers():
    rss, model = _readings()
    new = lb.grid_ml_position(rss, model, CELLS, chunk=7)
    old, message = _old_call(lb.grid_ml_position, ANCHORS_3D, rss, CHANNEL, CELLS, chunk=7, tag_height_m=H)
    assert message == ("grid_ml_position(anchors_m, rss_dbm, channel, ...) is deprecated: use "
                       "grid_ml_position(rss_dbm, RssModel(anchors_m, channel, tag_height_m=...), ...)")
    _same(old, new)


def test_grid_ml_position_grid_m_keyword_warns_and_gives_the_same_numbers():
    rss, model = _readings()
    old, message = _old_call(lb.grid_ml_position, rss, model, grid_m=CELLS)
    assert message == "grid_ml_position(..., grid_m=...) is deprecated: use grid_ml_position(..., cells_m=...)"
    _same(old, lb.grid_ml_position(rss, model, cells_m=CELLS))


def test_model_fingerprints_old_form_warns_and_gives_the_same_numbers():
    channel = lb.PathLossModel(np.array([-42.0, -52.0, -45.0, -47.0]), np.array([2.3, 2.3, 2.5, 2.0]),
                               wall_attenuation_db=2.0)
    old, message = _old_call(lb.model_fingerprints, CELLS, SQUARE, channel, WALLS, min_distance_m=0.2)
    assert message == ("model_fingerprints(cells_m, anchors_m, channel, walls_m, ...) is deprecated: use "
                       "model_fingerprints(cells_m, RssModel(anchors_m, channel, walls_m), ...)")
    np.testing.assert_array_equal(old, lb.model_fingerprints(CELLS, lb.RssModel(SQUARE, channel, WALLS),
                                                             min_distance_m=0.2))


def test_new_forms_compute_what_the_model_says():
    """The estimators read the anchors, the channel and the tag height from the model: grid ML is the cell of least
    squared residual against the model's own mean, the map is the model's mean at the cells (walls included), and
    per-run and per-step parameters give one map per run and step."""
    rss, model = _readings()
    keep = ~np.isnan(rss).any(axis=1) & (np.nanmax(rss, axis=1) < 100)
    fix = lb.grid_ml_position(rss[keep], model, CELLS)
    brute = np.argmin(((rss[keep][:, None, :] - model.mean_rss_dbm(CELLS)[0]) ** 2).sum(-1), axis=1)
    np.testing.assert_array_equal(fix.position_m, CELLS[brute])
    channel = lb.PathLossModel(-45.0, 2.2, wall_attenuation_db=3.0, min_distance_m=0.1)   # the map's clamp
    walled = lb.RssModel(SQUARE, channel, WALLS)
    np.testing.assert_allclose(lb.model_fingerprints(CELLS, walled), walled.mean_rss_dbm(CELLS)[0], rtol=0,
                               atol=1e-12)
    per_step = np.random.default_rng(1).uniform(-50.0, -40.0, (2, 3, 4))
    maps = lb.model_fingerprints(CELLS, lb.RssModel(SQUARE, lb.PathLossModel(per_step, 2.2), per_step_channel=True))
    assert maps.shape == (2, 3, len(CELLS), 4)
    np.testing.assert_array_equal(maps[1, 2], lb.model_fingerprints(CELLS, lb.RssModel(SQUARE, lb.PathLossModel(
        per_step[1, 2], 2.2))))
    # walls that attenuate nothing are no walls: the ML estimators take them
    quiet = lb.RssModel(SQUARE, lb.PathLossModel(-45.0, 2.2, 2.0), WALLS)
    power = quiet.mean_rss_dbm(np.array([[3.0, 4.0]]))[0]
    _same(lb.rss_ml_position(power, quiet), lb.rss_ml_position(power, lb.RssModel(SQUARE, quiet.channel)))


PER_RUN = lb.RssModel(np.broadcast_to(SQUARE, (2, 4, 2)), lb.PathLossModel(-45.0, 2.2, 2.0))
PER_STEP = lb.RssModel(SQUARE, lb.PathLossModel(np.full((2, 5, 4), -45.0), 2.2, 2.0), per_step_channel=True)
PER_STEP_SIGMA = lb.RssModel(SQUARE, lb.PathLossModel(-45.0, 2.2, np.full((2, 5, 1), 2.0)), per_step_channel=True)
WALLED = lb.RssModel(SQUARE, lb.PathLossModel(-45.0, 2.2, 2.0, wall_attenuation_db=3.0), WALLS)
HEIGHTS = lb.RssModel(ANCHORS_3D, CHANNEL, tag_height_m=H)
POWER = np.full(4, -60.0)


@pytest.mark.parametrize("call, message", [
    (lambda: lb.rss_ml_position(POWER, lb.PathLossModel(-45.0, 2.2)),
     r"^rss_ml_position: model must be an RssModel .* got PathLossModel: pass rss_ml_position\(rss_dbm, "
     r"RssModel\(anchors_m, channel, tag_height_m=\.\.\.\), \.\.\.\)$"),
    (lambda: lb.grid_ml_position(POWER, lb.PathLossModel(-45.0, 2.2), CELLS),
     r"^grid_ml_position: model must be an RssModel .* got PathLossModel: pass grid_ml_position\(rss_dbm, RssModel"),
    (lambda: lb.model_fingerprints(CELLS, lb.PathLossModel(-45.0, 2.2)),
     r"^model_fingerprints: model must be an RssModel .* got PathLossModel: pass model_fingerprints\(cells_m, "
     r"RssModel\(anchors_m, channel, walls_m\)\)$"),
    (lambda: lb.rss_ml_position(POWER, SQUARE), r"model must be an RssModel .* got ndarray"),
    (lambda: lb.rss_ml_position(np.full((2, 4), -60.0), PER_RUN),
     r"rss_ml_position: model.anchors_m is per run or per step, shape"),
    (lambda: lb.model_fingerprints(CELLS, PER_RUN), r"model_fingerprints: model.anchors_m is per run or per step"),
    (lambda: lb.grid_ml_position(POWER, PER_STEP, CELLS),
     r"grid_ml_position: model.channel.ref_power_dbm is per run or per step, shape \(2, 5, 4\)"),
    (lambda: lb.rss_ml_position(POWER, PER_STEP_SIGMA),
     r"rss_ml_position: model.channel.sigma_db is per run or per step"),
    (lambda: lb.rss_ml_position(POWER, WALLED),
     r"rss_ml_position: model.walls_m \(1 wall\(s\), 3 dB each\) is not modelled"),
    (lambda: lb.grid_ml_position(POWER, WALLED, CELLS), r"grid_ml_position: model.walls_m .* is not modelled"),
    (lambda: lb.model_fingerprints(CELLS, HEIGHTS), r"model_fingerprints: model.tag_height_m is not supported"),
    (lambda: lb.rss_ml_position(np.full(6, -60.0), HEIGHTS, tag_height_m=H), r"tag_height_m is the model's: pass Rss"),
    (lambda: lb.model_fingerprints(CELLS, WALLED, walls_m=WALLS), r"walls_m is the model's: pass RssModel"),
])
def test_what_an_estimator_cannot_honour_is_refused_by_name(call, message):
    with pytest.raises(ValueError, match=message) as info:
        call()
    assert "\n" not in str(info.value)


def test_the_new_forms_never_warn_and_a_doubled_cells_m_is_an_error():
    rss, model = _readings()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        lb.rss_ml_position(rss[:3], model=model)
        lb.grid_ml_position(rss[:3], model, cells_m=CELLS)
        lb.model_fingerprints(CELLS, lb.RssModel(SQUARE, lb.PathLossModel(-45.0, 2.2)))
    with pytest.raises(TypeError, match=re.escape("got cells_m and grid_m")):
        lb.grid_ml_position(rss, model, CELLS, grid_m=CELLS)
