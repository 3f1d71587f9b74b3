"""The call forms before the readings-first argument convention (``rng`` positional; the grid filter's cells before its
model) work for one release: one DeprecationWarning line naming the new call, attributed to the caller's line, then
the same numbers as the new form. One test per deprecated form; and a wrapped public function's own warnings (the
collapse of some runs) still point at the caller."""
import dataclasses
import warnings

import numpy as np
import pytest

import locbook as lb
from locbook.models.channel import attenuation_bursts_db

ANCHORS = np.array([[0.0, 0.0], [8.0, 0.0], [8.0, 6.0], [0.0, 6.0]])
MODEL = lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.5, 3.0, min_distance_m=0.1))
CELLS = np.stack(np.meshgrid(np.arange(0.0, 8.01, 0.5), np.arange(0.0, 6.01, 0.5)), -1).reshape(-1, 2)
CV = lb.constant_velocity(dt_s=1.0, q=0.1)


def _rss(seed=0, runs=2, steps=4):
    truth = np.array([3.0, 2.0]) + np.cumsum(np.full((runs, steps, 2), 0.3), axis=1)
    return MODEL.mean_rss_dbm(truth) + np.random.default_rng(seed).normal(0.0, 3.0, (runs, steps, len(ANCHORS)))


def _ll(cells, t):
    """A callable log-likelihood for the grid filter: a Gaussian fix at (4, 3) for 2 runs."""
    return np.tile(-0.5 * np.sum((cells - [4.0, 3.0]) ** 2, axis=-1), (2, 1))


W = np.random.default_rng(3).random((3, 12))
ERRORS = np.abs(np.random.default_rng(4).normal(1.0, 0.5, 40))
PF = dict(n_particles=200, region_m=((0.0, 0.0), (8.0, 6.0)))
G = np.random.default_rng

# (name, the old call, the same call in the new form, the new form the warning names); each builds its own generator
CASES = [
    ("correlated_shadowing_db",
     lambda: lb.correlated_shadowing_db(CELLS[:5], 4.0, 3.0, G(1), (2,)),
     lambda: lb.correlated_shadowing_db(CELLS[:5], 4.0, 3.0, rng=G(1), size=(2,)),
     "correlated_shadowing_db(points_m, sigma_db, decorrelation_m, rng=rng, size=size)"),
    ("small_scale_fading_db",
     lambda: lb.small_scale_fading_db(np.linspace(0, 1, 9), 0.33, G(1), k_factor=2.0),
     lambda: lb.small_scale_fading_db(np.linspace(0, 1, 9), 0.33, rng=G(1), k_factor=2.0),
     "small_scale_fading_db(distance_m, wavelength_m, rng=rng)"),
    ("attenuation_bursts_db",
     lambda: attenuation_bursts_db((3, 4), 0.3, (2.0, 6.0), G(1)),
     lambda: attenuation_bursts_db((3, 4), 0.3, (2.0, 6.0), rng=G(1)),
     "attenuation_bursts_db(shape, probability, loss_range_db, rng=rng)"),
    ("PathLossModel.sample_rss_dbm",
     lambda: MODEL.channel.sample_rss_dbm(np.array([1.0, 2.0, 5.0]), G(1), 1),
     lambda: MODEL.channel.sample_rss_dbm(np.array([1.0, 2.0, 5.0]), rng=G(1), n_walls=1),
     "PathLossModel.sample_rss_dbm(distance_m, rng=rng, n_walls=n_walls)"),
    ("simulate_states",
     lambda: lb.simulate_states(CV.F, CV.Q, np.zeros((2, 4)), 5, G(1)),
     lambda: lb.simulate_states(CV.F, CV.Q, np.zeros((2, 4)), 5, rng=G(1)),
     "simulate_states(F, Q, initial_state, n_steps, rng=rng)"),
    ("particle_filter",
     lambda: lb.particle_filter(_rss(), MODEL, G(1), **PF),
     lambda: lb.particle_filter(_rss(), MODEL, rng=G(1), **PF),
     "particle_filter(rss_dbm, model, rng=rng)"),
    ("resample",
     lambda: lb.resample(W, G(1), "residual", n_out=20),
     lambda: lb.resample(W, rng=G(1), method="residual", n_out=20),
     "resample(weights, rng=rng, method=method)"),
    ("resample_where",
     lambda: lb.resample_where(W, G(1), "stratified", threshold=8.0),
     lambda: lb.resample_where(W, rng=G(1), method="stratified", threshold=8.0),
     "resample_where(weights, rng=rng, method=method)"),
    ("accuracy_metrics",
     lambda: lb.accuracy_metrics(ERRORS, G(1), n_bootstrap=50),
     lambda: lb.accuracy_metrics(ERRORS, rng=G(1), n_bootstrap=50),
     "accuracy_metrics(error_m, rng=rng)"),
    ("bootstrap_standard_error",
     lambda: lb.bootstrap_standard_error(ERRORS, np.median, G(1), 50),
     lambda: lb.bootstrap_standard_error(ERRORS, np.median, rng=G(1), n_resamples=50),
     "bootstrap_standard_error(samples, statistic, rng=rng, n_resamples=n_resamples)"),
    ("moving_block_indices",
     lambda: lb.moving_block_indices(20, 4, 6, G(1)),
     lambda: lb.moving_block_indices(20, 4, 6, rng=G(1)),
     "moving_block_indices(n, block_length, n_resamples, rng=rng)"),
    ("circular_block_indices",
     lambda: lb.circular_block_indices(20, 4, 6, G(1)),
     lambda: lb.circular_block_indices(20, 4, 6, rng=G(1)),
     "circular_block_indices(n, block_length, n_resamples, rng=rng)"),
    ("grid_bayes_filter",
     lambda: (lb.grid_bayes_filter(_rss(), CELLS, MODEL, 0.7),
              lb.grid_bayes_filter(None, CELLS, _ll, n_steps=3),
              lb.grid_bayes_filter(_rss(), CELLS, model=MODEL)),
     lambda: (lb.grid_bayes_filter(_rss(), MODEL, CELLS, 0.7),
              lb.grid_bayes_filter(None, _ll, CELLS, n_steps=3),
              lb.grid_bayes_filter(_rss(), MODEL, CELLS)),
     "grid_bayes_filter(rss_dbm, model, cells_m, ...)"),
]


def _same(old, new):
    """Bit-identical results: arrays, numbers, dicts, tuples and filter results (every field)."""
    if dataclasses.is_dataclass(new):
        assert type(old) is type(new)
        for field in dataclasses.fields(new):
            _same(getattr(old, field.name), getattr(new, field.name))
    elif isinstance(new, dict):
        assert old.keys() == new.keys()
        for key in new:
            _same(old[key], new[key])
    elif isinstance(new, tuple):
        assert len(old) == len(new)
        for a, b in zip(old, new):
            _same(a, b)
    elif isinstance(new, str) or new is None:
        assert old == new
    else:
        np.testing.assert_array_equal(old, new)


@pytest.mark.parametrize("name, old, new, use", CASES, ids=[case[0] for case in CASES])
def test_the_old_form_warns_once_at_the_callers_line_and_gives_the_same_numbers(name, old, new, use):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ours = old()
    deprecations = [w for w in caught if issubclass(w.category, DeprecationWarning)]
    calls = 3 if name == "grid_bayes_filter" else 1                   # the grid case makes three old calls
    assert len(deprecations) == calls, [str(w.message) for w in caught]
    for w in deprecations:
        message = str(w.message)
        assert "\n" not in message and message.startswith(f"{name}(") and message.endswith(f"is deprecated: use {use}")
        assert w.filename == __file__                                   # the caller's line, not the library's
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)
        _same(ours, new())


def test_a_positional_value_that_is_no_generator_names_the_keyword_only_form():
    with pytest.raises(TypeError, match=r"resample\(\) takes 1 positional argument \(weights\), got 2: rng and the "
                                        r"options are keyword-only: resample\(weights, rng=\.\.\., method=\.\.\.\)"):
        lb.resample(W, "multinomial")
    with pytest.raises(TypeError, match=r"particle_filter\(\) takes 2 positional arguments \(rss_dbm, model\), got 3"):
        lb.particle_filter(_rss(), MODEL, 7, **PF)
    with pytest.raises(TypeError, match="got multiple values for argument 'rng'"):
        lb.particle_filter(_rss(), MODEL, G(1), rng=G(1), **PF)
    with pytest.raises(TypeError, match="missing 1 required keyword-only argument: 'rng'"):
        lb.accuracy_metrics(ERRORS)


def test_a_path_loss_model_where_the_grid_filter_takes_its_model_is_one_clear_error():
    with pytest.raises(ValueError, match="model must be an RssModel or a callable log_likelihood"):
        lb.grid_bayes_filter(_rss(), MODEL.channel, CELLS)


@pytest.mark.parametrize("which", ["particle", "grid"])
def test_the_collapse_warning_of_a_wrapped_filter_points_at_the_callers_line(which):
    """The decorators of locbook._deprecation add a frame: the filters' own fixed-stacklevel warnings count it out."""
    rss = _rss(runs=3)
    rss[1, 2, 0] = 1e300                                            # overflows run 1's likelihood at step 2
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if which == "particle":
            lb.particle_filter(rss, MODEL, rng=G(1), **PF)
        else:
            lb.grid_bayes_filter(rss, MODEL, CELLS)
    collapsed = [w for w in caught if "collapsed in 1 of 3 runs" in str(w.message)]
    assert len(collapsed) == 1 and collapsed[0].filename == __file__


def test_the_renamed_constants_warn_and_keep_their_values():
    from locbook.bounds import crlb
    from locbook.tracking import unscented
    with pytest.warns(DeprecationWarning, match=r"locbook.bounds.crlb.CRLB_FORMS is deprecated: use "
                                                r"locbook.bounds.crlb.CRLB_VARIANTS"):
        assert crlb.CRLB_FORMS == ("correct", "ozkaya_printed")
    with pytest.warns(DeprecationWarning, match="UKF_WEIGHTS is deprecated"):
        assert unscented.UKF_WEIGHTS == unscented.UKF_VARIANTS
    with pytest.raises(AttributeError, match="has no attribute 'CRLB_FORM'"):
        crlb.CRLB_FORM


def test_a_bound_takes_walls_that_attenuate_nothing_as_no_walls():
    square = np.array([[0.0, 0.0], [8.0, 0.0], [8.0, 6.0], [0.0, 6.0]])
    channel = lb.PathLossModel(-40.0, 2.2, 3.0)
    walls = np.array([[[4.0, -1.0], [4.0, 7.0]]])
    points = np.array([[1.0, 2.0], [6.0, 3.0]])
    np.testing.assert_array_equal(lb.rss_crlb_m(points, lb.RssModel(square, channel, walls)),
                                  lb.rss_crlb_m(points, lb.RssModel(square, channel)))
