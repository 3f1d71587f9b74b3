"""Grid Bayes and particle filters (document 004) against closed forms, independent loops and filterpy's resampler.
Fingerprinting and the reference tags: tests/static/test_fingerprint.py, tests/static/test_reference_tags.py."""
import numpy as np
import pytest
from scipy.stats import norm

import locbook as lb

READERS = np.array([[0.0, 0.0], [5.0, 0.0], [0.0, 8.0]])
ROOM = (np.zeros(2), np.array([5.0, 8.0]))


def _cells(step):
    xs, ys = np.arange(step / 2, 5.0, step), np.arange(step / 2, 8.0, step)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    return np.column_stack([gx.ravel(), gy.ravel()])


# -- grid Bayes ----------------------------------------------------------------------------------------
def _model(ref_power_dbm, path_loss_exp, sigma_db):
    """The filters' RSS model over READERS with the 0.1 m near-field clamp."""
    return lb.RssModel(READERS, lb.PathLossModel(ref_power_dbm, path_loss_exp, sigma_db, min_distance_m=0.1))


def _independent_likelihood(rss, cells, sigma):
    d = np.maximum(np.linalg.norm(cells[:, None, :] - READERS[None], axis=-1), 0.1)
    mean = -52.0 - 23.0 * np.log10(d)
    return np.prod(norm.pdf(rss[None, :], mean, sigma), axis=-1)


def test_grid_filter_with_uniform_transition_is_the_normalised_likelihood():
    cells = _cells(1.0)
    model = _model(-52.0, 2.3, 5.2)
    rss = np.random.default_rng(3).normal(-70.0, 4.0, (2, 4, 3))
    res = lb.grid_bayes_filter(rss, model, cells, spread_m=np.inf)
    for r in range(2):
        lik = _independent_likelihood(rss[r, -1], cells, 5.2)
        np.testing.assert_allclose(res.weights[r], lik / lik.sum(), rtol=1e-10)
        np.testing.assert_allclose(res.mean[r, -1], (lik / lik.sum()) @ cells, rtol=1e-10)


def test_log_likelihood_is_the_gaussian_log_density_up_to_a_constant_per_run():
    # per-reader alpha and n, per-run-and-step alpha and sigma, a wall with its attenuation, a cell on a reader
    # (distance clipped at 0.1 m), positions per run, and a NaN (reader 2 not heard in run 1)
    walls = np.array([[[2.5, -1.0], [2.5, 9.0]]])                          # x = 2.5, longer than the room
    rng = np.random.default_rng(13)
    R, T, P = 2, 3, 40
    alpha = rng.uniform(-55.0, -40.0, (R, T, 3))
    sigma = rng.uniform(3.0, 7.0, (R, T, 1))                                # pooled per run and step
    n = np.array([2.1, 2.6, 1.9])
    model = lb.RssModel(READERS, lb.PathLossModel(alpha, n, sigma, wall_attenuation_db=3.5, min_distance_m=0.1),
                        walls_m=walls,
                        per_step_channel=True)
    pos = rng.uniform([0.0, 0.0], [5.0, 8.0], (R, P, 2))
    pos[0, 0] = READERS[0] + [0.03, 0.04]                                   # 0.05 m from reader 0
    rss = rng.normal(-65.0, 6.0, (R, 3))
    rss[1, 2] = np.nan
    for step in range(T):
        ll = model.log_likelihood(rss, pos, step)
        assert ll.shape == (R, P)
        for r in range(R):
            d = np.maximum(np.hypot(*(pos[r][:, None, :] - READERS[None]).transpose(2, 0, 1)), 0.1)   # (P, m)
            crosses = (pos[r][:, 0] < 2.5)[:, None] != (READERS[:, 0] < 2.5)[None]        # opposite sides of x = 2.5
            mean = alpha[r, step] - 10 * n * np.log10(d) - 3.5 * crosses
            heard = ~np.isnan(rss[r])
            ref = norm.logpdf(rss[r][heard], mean[:, heard], sigma[r, step]).sum(-1)
            gap = ll[r] - ref
            np.testing.assert_allclose(gap, gap[0], rtol=0, atol=1e-9 * np.abs(ref).max())    # one constant per run
            np.testing.assert_allclose(ll[r], ref, rtol=1e-12)                  # the normalised density itself
            kernel = model.log_likelihood(rss, pos, step, constant=False)[r]   # the filters' form: a constant less
            np.testing.assert_allclose(kernel - ref, (kernel - ref)[0], rtol=0, atol=1e-9 * np.abs(ref).max())
    # the likelihood ratio between two positions is what enters the filters: pin one by hand
    one = _model(-50.0, 2.0, 4.0)
    a, b = np.array([[1.0, 0.0]]), np.array([[0.0, 2.0]])                 # distances (1, 4, sqrt 65), (2, sqrt 29, 6)
    s = np.array([[-52.0, -62.0, -66.0]])
    ma = -50.0 - 20 * np.log10([1.0, 4.0, np.sqrt(65.0)])
    mb = -50.0 - 20 * np.log10([2.0, np.sqrt(29.0), 6.0])
    expected = (np.sum((s[0] - mb) ** 2) - np.sum((s[0] - ma) ** 2)) / (2 * 16.0)
    assert (one.log_likelihood(s, a) - one.log_likelihood(s, b))[0, 0] == pytest.approx(expected, rel=1e-12)


def test_grid_filter_recursion_equals_explicit_loop():
    cells = _cells(1.0)
    model = _model(-52.0, 2.3, 4.0)
    rss = np.random.default_rng(4).normal(-68.0, 5.0, (1, 5, 3))
    v = np.array([0.0, 0.5])
    res = lb.grid_bayes_filter(rss, model, cells, spread_m=0.7, velocity_m=v)
    bel = np.full(len(cells), 1.0 / len(cells))
    for t in range(5):
        if t:
            new = np.zeros_like(bel)
            for j, cj in enumerate(cells):                    # from cell j
                k = norm.pdf(cells[:, 0], cj[0] + v[0], 0.7) * norm.pdf(cells[:, 1], cj[1] + v[1], 0.7)
                new += bel[j] * k / k.sum()
            bel = new
        bel = bel * _independent_likelihood(rss[0, t], cells, 4.0)
        bel /= bel.sum()
    np.testing.assert_allclose(res.weights[0], bel, rtol=1e-9)
    np.testing.assert_allclose(res.map_m[0, -1], cells[np.argmax(bel)])


# -- resampling and particle filters --------------------------------------------------------------------
def test_systematic_resample_matches_table_4_2_loop_and_filterpy(monkeypatch):
    from filterpy.monte_carlo import resampling
    rng = np.random.default_rng(5)
    for _ in range(20):
        n = int(rng.integers(2, 40))
        w = rng.random(n) ** 3
        w /= w.sum()
        u = rng.random()
        ours = lb.systematic_resample(w, u)
        c, j, loop = np.cumsum(w), 0, []
        for i in range(n):                                   # Table 4.2 with the standard CDF
            ui = (u + i) / n
            while ui > c[j]:
                j += 1
            loop.append(j)
        np.testing.assert_array_equal(ours, loop)
        monkeypatch.setattr(resampling, "random", lambda: u)
        np.testing.assert_array_equal(ours, resampling.systematic_resample(w))


def test_systematic_resample_rows_are_independent_and_literal_cdf_is_shifted():
    w = np.array([[0.5, 0.25, 0.25], [0.1, 0.1, 0.8]])
    np.testing.assert_array_equal(lb.systematic_resample(w, [0.0, 0.5]),
                                  [[0, 0, 1], [1, 2, 2]])   # u = 1/6, 1/2, 5/6 against c = .1, .2, 1
    # printed CDF: c = (0, 0.25, 0.5): u = 0, 1/3, 2/3 -> first c_j >= u_i: 0, 2, past the end (clipped)
    np.testing.assert_array_equal(lb.systematic_resample(w[0], 0.0, cdf="literal_ozkaya2011"), [0, 2, 2])


def test_sir_converges_to_the_grid_posterior_mean():
    # one update from a uniform prior: the grid posterior on a fine grid is the continuous one
    model = _model(-52.0, 2.3, 5.2)
    rss = np.array([[[-66.0, -70.0, -72.0]]])
    grid = lb.grid_bayes_filter(rss, model, _cells(0.02), spread_m=np.inf)
    pf = lb.particle_filter(np.repeat(rss, 20, axis=0), model, rng=np.random.default_rng(6),
                            n_particles=50_000, region_m=ROOM)
    spread = np.sqrt(grid.weights[0] @ np.sum((_cells(0.02) - grid.mean[0, 0]) ** 2, axis=-1))
    se = spread / np.sqrt(50_000 * 20)
    np.testing.assert_allclose(pf.mean[:, 0].mean(axis=0), grid.mean[0, 0], atol=6 * se + 2e-3)


def test_sir_with_gaussian_prior_converges_to_the_grid_filter_over_steps():
    # target mid-room with small noise: the posterior stays far from the walls, where reflection (PF) and
    # truncation (grid) differ; a 0.1 m grid keeps discretisation (about 0.1^2/12 in variance) below the MC error
    model = _model(-52.0, 2.3, 2.0)
    truth = np.array([2.5, 4.0])
    mean = model.mean_rss_dbm(truth[None])[0, 0]
    rss = (mean + np.random.default_rng(7).normal(0, 2.0, (4, 3)))[None]
    grid = lb.grid_bayes_filter(rss, model, _cells(0.1), spread_m=0.3)
    pf = lb.particle_filter(np.repeat(rss, 40, axis=0), model, rng=np.random.default_rng(8), n_particles=20_000,
                            region_m=ROOM, spread_m=0.3, resample_threshold=0.5)
    np.testing.assert_allclose(pf.mean[:, -1].mean(axis=0), grid.mean[0, -1], atol=0.01)   # D = 0.6 is 0.06 off


def test_particle_filter_options_and_invariants():
    model = _model(-52.0, 2.3, 5.2)
    rss = np.random.default_rng(9).normal(-68.0, 5.0, (30, 6, 3))
    kw = dict(n_particles=200, region_m=ROOM)
    basic = lb.particle_filter(rss, model, rng=np.random.default_rng(1), **kw)
    assert basic.resampled.all()
    again = lb.particle_filter(rss, model, rng=np.random.default_rng(1), **kw)
    np.testing.assert_array_equal(basic.mean, again.mean)        # same stream, same numbers
    improved = lb.particle_filter(rss, model, rng=np.random.default_rng(1), resample_threshold=0.5,
                                  weight_smoothing="sqrt", **kw)
    np.testing.assert_allclose(improved.weights.sum(-1), 1.0)
    assert (improved.n_eff[improved.resampled] < 100).all() and (improved.n_eff[~improved.resampled] >= 100).all()
    assert improved.resampled.any() and not improved.resampled.all()          # both branches above are exercised
    inner = (np.ones(2), np.array([4.0, 7.0]))
    con = lb.particle_filter(rss, model, rng=np.random.default_rng(1), n_particles=200, region_m=inner)
    assert (con.particles_m >= 1.0).all() and (con.particles_m[..., 0] <= 4.0).all()
    assert (con.particles_m[..., 1] <= 7.0).all() and (con.mean >= 1.0).all() and (con.mean <= [4.0, 7.0]).all()
    start = np.tile([2.0, 3.0], (30, 1))
    known = lb.particle_filter(rss[:, :1], model, rng=np.random.default_rng(1), initial_position_m=start, **kw)
    np.testing.assert_allclose(known.mean[:, 0], start)
    with pytest.raises(ValueError, match="fraction of N"):
        lb.particle_filter(rss, model, rng=np.random.default_rng(1), resample_threshold=5.0, **kw)


