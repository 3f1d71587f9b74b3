"""The fast grid Bayes filter computes the previous arithmetic: the dense transition matrix of
grid_transition_matrix and RssModel.log_likelihood at every step, recursed here in plain numpy in the log domain
(the filter's rule: log(max(b, 1e-300)) + ll, normalised). The fixed-cell likelihood table, the banded separable
prediction and the compiled update (numba on, and numba off) must give the same posterior means and covariances to
1e-12 on masked, uneven, 1-D and 3-D grids, with velocities per step, missing readings, walls, per-run anchors and
per-step parameters, and a run that collapses."""

import numpy as np
import pytest

import locbook as lb
from locbook.models.rss import _table_log_likelihood
from locbook.tracking import _compiled, bayes
from locbook.tracking.bayes import _BandedLattice, grid_bayes_filter, grid_transition_matrix

pytestmark = pytest.mark.compiled

ANCHORS = np.array([[0.0, 0.0], [5.0, 0.0], [0.0, 4.0], [5.0, 4.0]])
CHANNEL = lb.PathLossModel(-40.0, 2.5, 3.0, min_distance_m=0.1)
TOL = 1e-12


@pytest.fixture(params=["numba", "numpy"])
def path(request, monkeypatch):
    """The compiled kernels on every problem size (threshold 0), or off (the numpy path)."""
    monkeypatch.setattr(bayes, "_GRID_MIN_WORK", 0)
    monkeypatch.setattr(_compiled, "_NUMBA_ENABLED", request.param == "numba")
    return request.param


def _reference(log_lik, cells, spread_m, velocity, prior):
    """The previous arithmetic, written out: ``b_t ~ exp(log(max(A_t b_t-1, 1e-300)) + ll_t)`` with ``A_t`` the
    dense matrix. ``log_lik(t) -> (R, C)``. Returns means, covariances (numpy's weighted cov) and final beliefs."""
    b = prior / prior.sum(axis=1, keepdims=True)
    means, covs = [], []
    for t in range(velocity.shape[0]):
        if t:
            b = b @ grid_transition_matrix(cells, spread_m, velocity[t]).T
        lp = np.log(np.maximum(b, 1e-300)) + log_lik(t)
        w = np.exp(lp - lp.max(axis=1, keepdims=True))
        b = w / w.sum(axis=1, keepdims=True)
        means.append(b @ cells)
        covs.append([np.atleast_2d(np.cov(cells.T, aweights=w_r, bias=True)) for w_r in b])
    return np.stack(means, 1), np.stack(covs, 1), b


def _assert_same(res, ref, runs=slice(None)):
    mean, cov, belief = ref
    np.testing.assert_allclose(res.mean[runs], mean, rtol=0, atol=TOL)
    np.testing.assert_allclose(res.cov[runs], cov, rtol=0, atol=TOL)
    np.testing.assert_allclose(res.weights[runs], belief, rtol=0, atol=TOL)


def _l_shaped(spacing):
    xs, ys = np.arange(0, 5.0 + 1e-9, spacing), np.arange(0, 4.0 + 1e-9, spacing)
    grid = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    return grid[~((grid[:, 0] > 3.0) & (grid[:, 1] > 2.5))]


def _rss(rng, runs, steps, model=None, velocity=None, spread_m=0.5, low=(1.0, 1.0), high=(2.5, 3.0)):
    """Readings of a target moving as the filter's process model says (a start in [low, high], steps of
    ``velocity + N(0, spread_m^2)``), with one anchor not heard once and a step where nothing was heard. (Readings
    that contradict the motion by more than about 8 spread_m put the posterior in the far tail of the prediction,
    where the banded kernel's truncation shows: bayes._BandedLattice.)"""
    model = lb.RssModel(ANCHORS, CHANNEL) if model is None else model
    dim = model.dim
    velocity = np.zeros((steps, dim)) if velocity is None else np.broadcast_to(velocity, (steps, dim))
    pos = rng.uniform(low[:dim] if dim < 3 else 0.5, high[:dim] if dim < 3 else 1.5, (runs, dim))
    track = np.empty((runs, steps, dim))
    for t in range(steps):
        if t:
            pos = pos + velocity[t] + rng.normal(0, spread_m, (runs, dim))
        track[:, t] = pos
    if model.anchors_m.ndim == 3:
        mean = np.stack([model.select_runs([r]).mean_rss_dbm(track[r], 0)[0] for r in range(runs)])
    else:
        mean = model.mean_rss_dbm(track.reshape(-1, dim), 0)[0].reshape(runs, steps, -1)
    rss = mean + rng.normal(0, 2.0, mean.shape)
    rss[0, min(3, steps - 1), 1] = np.nan                   # one anchor not heard
    rss[-1, min(2, steps - 1)] = np.nan                     # a step where nothing was heard
    return rss


@pytest.mark.parametrize("cells_kind", ["masked", "uneven"])
def test_rss_filter_equals_the_dense_recursion(path, cells_kind):
    rng = np.random.default_rng(310)
    if cells_kind == "masked":
        cells = _l_shaped(0.2)
    else:                                                   # distinct coordinates not evenly spaced: no banding
        xs, ys = np.sort(rng.uniform(0, 5, 14)), np.sort(rng.uniform(0, 4, 11))
        cells = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    R, T = 3, 7
    velocity = rng.normal(0, 0.2, (T, 2))
    model = lb.RssModel(ANCHORS, CHANNEL)
    rss = _rss(rng, R, T, model, velocity)
    prior = rng.dirichlet(np.ones(len(cells)), R)
    res = grid_bayes_filter(rss, model, cells, 0.5, velocity_m=velocity, initial_belief=prior)
    ref = _reference(lambda t: model.log_likelihood(rss[:, t], cells, t, constant=False), cells, 0.5, velocity, prior)
    _assert_same(res, ref)


@pytest.mark.parametrize("dim", [1, 3])
def test_callable_filter_in_one_and_three_dimensions(path, dim):
    rng = np.random.default_rng(311 + dim)
    axes = [np.arange(0, 3.01, 0.25), np.arange(0, 2.01, 0.25), np.arange(0, 1.51, 0.25)][:dim]
    cells = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, dim)
    cells = cells[rng.random(len(cells)) < 0.85]            # a masked lattice
    R, T = 3, 6
    z = rng.uniform(0.5, 1.5, (R, T, dim))

    def ll(c, t):
        return -0.5 * np.sum((c[None] - z[:, t, None, :]) ** 2, axis=-1) / 0.2

    velocity = rng.normal(0, 0.2, (T, dim))
    res = grid_bayes_filter(None, ll, cells, 0.4, n_steps=T, velocity_m=velocity)
    ref = _reference(lambda t: ll(cells, t), cells, 0.4, velocity, np.ones((R, len(cells))))
    _assert_same(res, ref)


def test_rss_filter_in_three_dimensions(path):
    rng = np.random.default_rng(314)
    anchors = np.array([[0, 0, 0], [3, 0, 2], [0, 3, 1], [3, 3, 0.0]])
    model = lb.RssModel(anchors, lb.PathLossModel(-40.0, 2.0, 2.0, min_distance_m=0.1))
    axes = [np.arange(0, 3.01, 0.3)] * 2 + [np.arange(0, 2.01, 0.4)]
    cells = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    rss = _rss(rng, 2, 5, model, (0.1, -0.2, 0.05), 0.6)
    res = grid_bayes_filter(rss, model, cells, 0.6, velocity_m=(0.1, -0.2, 0.05))
    ref = _reference(lambda t: model.log_likelihood(rss[:, t], cells, t, constant=False), cells, 0.6,
                     np.tile([0.1, -0.2, 0.05], (5, 1)), np.ones((2, len(cells))))
    _assert_same(res, ref)


@pytest.mark.parametrize("kind", ["walls", "per_run_anchors", "per_step_parameters", "per_anchor_sigma"])
def test_rss_model_variants(path, kind):
    rng = np.random.default_rng(315)
    cells = _l_shaped(0.25)
    R, T = 3, 6
    if kind == "walls":
        model = lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.5, 3.0, wall_attenuation_db=4.0, min_distance_m=0.1),
                            walls_m=np.array([[[2.4, -1.0], [2.4, 2.1]], [[-1.0, 3.1], [3.5, 3.1]]]))
    elif kind == "per_run_anchors":
        model = lb.RssModel(ANCHORS + rng.normal(0, 0.3, (R, 4, 2)), CHANNEL)
    elif kind == "per_step_parameters":
        model = lb.RssModel(ANCHORS, lb.PathLossModel(rng.normal(-40, 1, (R, T, 4)), 2.5, rng.uniform(2, 4, (R, T, 1)),
                                                      min_distance_m=0.1), per_step_channel=True)
    else:
        model = lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.5, np.array([2.0, 3.0, 4.0, 2.5]), min_distance_m=0.1))
    velocity = rng.normal(0, 0.2, (T, 2))
    rss = _rss(rng, R, T, None if kind == "per_step_parameters" else model, velocity)
    res = grid_bayes_filter(rss, model, cells, 0.5, velocity_m=velocity)
    ref = _reference(lambda t: model.log_likelihood(rss[:, t], cells, t, constant=False), cells, 0.5, velocity,
                     np.ones((R, len(cells))))
    _assert_same(res, ref)


def test_a_collapsing_run_is_flagged_and_the_others_unaffected(path):
    rng = np.random.default_rng(316)
    cells = _l_shaped(0.2)
    rss = _rss(rng, 3, 6)
    rss[1, 2, 0] = 1e300                                    # overflows the Gaussian: -inf on every cell
    model = lb.RssModel(ANCHORS, CHANNEL)
    with pytest.warns(RuntimeWarning, match=r"1 of 3 runs \(first: run 1, step 2"):
        res = grid_bayes_filter(rss, model, cells, 0.5)
    assert res.diverged.tolist() == [False, True, False] and res.diverged_step.tolist() == [-1, 2, -1]
    good = [0, 2]
    ref = _reference(lambda t: model.log_likelihood(rss[good, t], cells, t, constant=False), cells, 0.5,
                     np.zeros((6, 2)), np.ones((2, len(cells))))
    _assert_same(res, ref, good)
    assert np.isnan(res.mean[1, 2:]).all() and np.isfinite(res.mean[1, :2]).all()
    assert np.isnan(res.weights[1]).all()
    rss[:, 4, 2] = 1e300                                    # every run: the error names the first step and run
    with pytest.raises(ValueError, match=r"rss_dbm collapsed in every run \(3 of 3\).*step 2 \(run 1\)"):
        grid_bayes_filter(rss, model, cells, 0.5)


def test_posterior_below_the_belief_floor_takes_the_log_domain(path):
    """A prior that is 0 outside a corner and readings that point to the opposite corner: the filter's rule floors
    the belief at 1e-300, so the posterior lies where the likelihood is (exp(ll - max) * 1e-300 underflows the
    fast form: the log-domain fallback)."""
    cells = _l_shaped(0.25)
    prior = np.where((cells[:, 0] < 0.6) & (cells[:, 1] < 0.6), 1.0, 0.0)[None]
    model = lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.5, 0.3, min_distance_m=0.1))
    target = np.array([2.9, 3.9])
    rss = model.mean_rss_dbm(target[None])[0, 0][None, None].repeat(3, axis=1)
    res = grid_bayes_filter(rss, model, cells, 0.1, initial_belief=prior)
    ref = _reference(lambda t: model.log_likelihood(rss[:, t], cells, t, constant=False), cells, 0.1,
                     np.zeros((3, 2)), prior)
    _assert_same(res, ref)
    assert np.linalg.norm(res.mean[0, 0] - target) < 0.3


def test_compiled_path_equals_numpy_path_on_a_large_grid(monkeypatch):
    """Numba on against numba off at the default threshold (a problem large enough for the kernels)."""
    rng = np.random.default_rng(317)
    xs, ys = np.arange(0.05, 8, 0.1), np.arange(0.05, 6, 0.1)
    cells = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    anchors = np.array([[0, 0], [8, 0], [0, 6], [8, 6.0]])
    model = lb.RssModel(anchors, CHANNEL)
    rss = _rss(rng, 6, 8, model, (0.05, 0.1), 0.4, low=(2.0, 2.0), high=(5.0, 4.0))
    assert rss.shape[0] * rss.shape[1] * len(cells) >= bayes._GRID_MIN_WORK
    monkeypatch.setattr(_compiled, "_NUMBA_ENABLED", True)
    fast = grid_bayes_filter(rss, model, cells, 0.4, velocity_m=(0.05, 0.1))
    monkeypatch.setattr(_compiled, "_NUMBA_ENABLED", False)
    slow = grid_bayes_filter(rss, model, cells, 0.4, velocity_m=(0.05, 0.1))
    for name in ("mean", "cov"):
        np.testing.assert_allclose(getattr(fast, name), getattr(slow, name), rtol=0, atol=TOL)
    np.testing.assert_allclose(fast.n_eff, slow.n_eff, rtol=1e-11)
    np.testing.assert_array_equal(fast.map_m, slow.map_m)


# -- the pieces ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["scalar", "per_anchor", "per_run"])
def test_table_likelihood_is_the_model_likelihood_bit_for_bit(kind, monkeypatch):
    rng = np.random.default_rng(318)
    cells = _l_shaped(0.25)
    sigma = np.array([2.0, 3.0, 4.0, 2.5]) if kind == "per_anchor" else 3.0
    anchors = ANCHORS + rng.normal(0, 0.3, (5, 4, 2)) if kind == "per_run" else ANCHORS
    model = lb.RssModel(anchors, lb.PathLossModel(-40.0, 2.5, sigma, min_distance_m=0.1))
    rss = rng.normal(-60, 5, (5, 2, 4))
    rss[0, 1, 1] = rss[3, 0] = np.nan
    monkeypatch.setattr(lb.models.rss, "LIKELIHOOD_BLOCK_VALUES", 3000)       # several blocks of runs
    table = model.mean_rss_dbm(cells, 0)
    for t in range(2):
        np.testing.assert_array_equal(_table_log_likelihood(rss[:, t], table, model._sigma(0, "x"), 2),
                                      model.log_likelihood(rss[:, t], cells, t, constant=False))


def test_fast_exponential_is_within_two_ulp_of_numpy():
    from locbook.tracking import _grid_kernels as k
    x = np.concatenate([-np.logspace(-20, np.log10(750), 4000), [0.0, -708.4, -709.0, -744.0, -745.1, -746.0,
                                                                   -1e4, -np.inf]])
    got = np.array([k._exp_nonpositive(v) for v in x])
    want = np.exp(x)
    normal = want >= np.finfo(float).tiny
    assert np.all(np.abs(got[normal] - want[normal]) <= 2 * np.spacing(want[normal]))
    assert np.all(np.abs(got[~normal] - want[~normal]) <= np.spacing(0.0))     # subnormals: one rounding


def test_banded_taps_keep_exactly_what_is_above_double_rounding():
    """v = 0 on a long axis: the kept taps are |s h| <= sqrt(2 * 53 ln 2) D (8.57 D); the first dropped tap is
    below 2^-53 of the peak, the last kept one above it."""
    h, D = 0.1, 0.5
    cells = np.arange(0, 30, h)[:, None]
    lattice = _BandedLattice.build(cells, D)
    taps, smin = lattice._taps(0, 0.0)
    half = int(np.floor(np.sqrt(2 * 53 * np.log(2)) * D / h))
    assert smin == -half and taps.size == 2 * half + 1
    assert taps[0] >= 2.0**-53 > np.exp(-0.5 * ((half + 1) * h / D) ** 2)
    assert _BandedLattice.build(np.array([[0.0], [0.1], [0.25]]), D) is None          # uneven: not banded


@pytest.mark.parametrize("dim", [1, 2, 3])
def test_banded_prediction_is_the_dense_matrix_product(dim):
    """Against ``belief @ grid_transition_matrix(...).T``: to 1e-12 relative at velocities within the grid; at a
    velocity carrying the targets of many cells 1.5 m (5 D) outside the grid, every column still sums to 1 and the
    error is below 1e-15 of the largest predicted value (the truncation is relative to each column's largest entry:
    cells that receive only from such columns' far tails have larger relative errors)."""
    from locbook.tracking import _grid_kernels as kernels
    rng = np.random.default_rng(319)
    axes = [np.arange(0, 2.01, 0.2), np.arange(0, 1.61, 0.2), np.arange(0, 0.81, 0.2)][:dim]
    cells = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, dim)
    if dim > 1:                                            # a masked lattice (each coordinate still present)
        cells = cells[rng.random(len(cells)) < 0.8]
    belief = rng.dirichlet(np.ones(len(cells)), 3)
    lattice = _BandedLattice.build(cells, 0.3)
    assert lattice is not None
    for v in (np.zeros(dim), rng.normal(0, 0.2, dim), np.full(dim, 1.5)):
        got = lattice.predict(belief, v, np.zeros(3, bool), kernels)
        want = belief @ grid_transition_matrix(cells, 0.3, v).T
        if v[0] < 1:
            np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-300)
        else:
            assert np.abs(got - want).max() <= 1e-15 * want.max()
        np.testing.assert_allclose(got.sum(axis=1), 1.0, rtol=1e-13)
        one_hot = lattice.predict(np.eye(len(cells))[:5], v, np.zeros(5, bool), kernels)
        np.testing.assert_allclose(one_hot.sum(axis=1), 1.0, rtol=1e-13)      # each column normalised over the cells
