"""The grid Bayes filter checked from outside: against an independent dense implementation of the
recursion, against closed forms of its transition kernel, and against the exact (Kalman) posterior of a
linear-Gaussian model.

Why the grid converges to the Kalman posterior exponentially fast, not as O(h^2). On a lattice of spacing ``h``
every quantity the filter sums is a sampled Gaussian, and by Poisson summation

    h sum_k N(kh + c; mu, s^2) = 1 + 2 sum_{n>=1} exp(-2 pi^2 s^2 n^2 / h^2) cos(2 pi n (mu - c) / h),

so a sum over the lattice equals the integral up to ``theta(s) = 2 sum_n exp(-2 pi^2 s^2 n^2 / h^2)``
(the trapezoidal rule on R is spectrally accurate for smooth, fast-decaying integrands). The update multiplies
sampled Gaussians, which is exact. The prediction ``sum_j K(x - x_j) b(x_j)`` sums, over ``x_j``, a Gaussian of
variance ``s_t^2 = P_t-1 q / (P_t-1 + q)`` (the previous posterior P times the kernel q), so it multiplies the exact
predicted density by a factor within ``1 +- theta(s_t)``; the kernel normaliser ``Z`` is the same for every
interior column (the lattice is shift-invariant) and cancels. Factors of ``(1 + theta)/(1 - theta)`` accumulate
over steps. The moments of a sampled Gaussian carry their own Poisson terms. :func:`_kf_error_bound` adds these
up; the leading term is ``exp(-2 pi^2 s^2 / h^2)``, so halving ``h`` raises it to the 4th power. A midpoint-rule
O(h^2) term would appear only with a box (cell-integrated) kernel or near the edges, and the tests here keep the
belief tens of standard deviations from the edges.
"""
import warnings

import numpy as np
import pytest
from scipy.stats import norm

import locbook as lb
from locbook.tracking.bayes import grid_bayes_filter, grid_transition_matrix


# -- an independent dense implementation ---------------------------------------------------------------
def _dense_reference(cells, log_lik, spread_m, velocity, prior):
    """``b_t ~ L_t * (A^T b_t-1)`` with ``A[j, i]`` = P(move from cell j to cell i), a Gaussian of std ``spread_m``
    about ``c_j + v_t`` (scipy's pdf, one factor per axis) normalised over the cells; written without
    grid_transition_matrix. ``log_lik`` ``(R, T, C)``, ``prior`` ``(R, C)``. Returns mean, covariance (numpy's
    weighted cov), the belief at each step (for the MAP) and n_eff."""
    R, T, C = log_lik.shape
    b = prior / prior.sum(axis=1, keepdims=True)
    means, covs, beliefs, n_effs = [], [], [], []
    for t in range(T):
        if t:
            if np.isinf(spread_m):
                A = np.full((C, C), 1.0 / C)
            else:
                target = cells + velocity[t]
                A = np.prod(norm.pdf(cells[None, :, :] - target[:, None, :], scale=spread_m), axis=-1)
                A /= A.sum(axis=1, keepdims=True)
            b = b @ A
        b = b * np.exp(log_lik[:, t] - log_lik[:, t].max(axis=1, keepdims=True))
        b /= b.sum(axis=1, keepdims=True)
        means.append([np.average(cells, axis=0, weights=w) for w in b])
        covs.append([np.atleast_2d(np.cov(cells.T, aweights=w, bias=True)) for w in b])
        beliefs.append(b)
        n_effs.append(1.0 / np.sum(b**2, axis=1))
    return np.stack(means, 1), np.stack(covs, 1), np.stack(beliefs, 1), np.stack(n_effs, 1)


def _rss_log_lik(rss, cells, anchors, p0_dbm, n_exp, sigma_db, d_min_m):
    """``sum_j log N(s_j; P0 - 10 n log10(max(d_j, d_min) / 1 m), sigma^2)`` over the heard readings, written from
    the model's formula (not through RssModel): ``(R, T, C)``."""
    d = np.linalg.norm(cells[:, None, :] - anchors[None, :, :], axis=-1)                    # (C, m)
    mean = p0_dbm - 10 * n_exp * np.log10(np.maximum(d, d_min_m))
    ll = norm.logpdf(rss[:, :, None, :], mean[None, None], sigma_db)                        # (R, T, C, m)
    return np.where(np.isnan(rss)[:, :, None, :], 0.0, ll).sum(axis=-1)


def _assert_matches(res, ref, cells):
    mean, cov, belief, n_eff = ref
    np.testing.assert_allclose(res.mean, mean, rtol=0, atol=1e-12)
    np.testing.assert_allclose(res.cov, cov, rtol=0, atol=1e-12)
    np.testing.assert_allclose(res.n_eff, n_eff, rtol=1e-12)
    np.testing.assert_allclose(res.weights, belief[:, -1], rtol=0, atol=1e-12)
    # the MAP is a cell of the reference's largest belief (any of them where the belief ties, e.g. uniform)
    index = np.argmin(np.abs(res.map_m[:, :, None, :] - cells).sum(axis=-1), axis=-1)       # (R, T)
    np.testing.assert_array_equal(cells[index], res.map_m)
    at_map = np.take_along_axis(belief, index[..., None], axis=-1)[..., 0]
    np.testing.assert_allclose(at_map, belief.max(axis=-1), rtol=1e-12)
    unique = np.sort(belief, axis=-1)[..., -2] < belief.max(axis=-1) * (1 - 1e-9)
    np.testing.assert_array_equal(index[unique], np.argmax(belief, axis=-1)[unique])


def _l_shaped_grid(spacing):
    xs, ys = np.arange(0, 5.0 + 1e-9, spacing), np.arange(0, 4.0 + 1e-9, spacing)
    grid = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    return grid[~((grid[:, 0] > 3.0) & (grid[:, 1] > 2.5))]


ANCHORS = np.array([[0.0, 0.0], [5.0, 0.0], [0.0, 4.0], [5.0, 4.0]])
CHANNEL = dict(p0_dbm=-40.0, n_exp=2.5, sigma_db=3.0, d_min_m=0.1)


@pytest.mark.parametrize("cells_kind", ["l_shaped", "irregular"])
@pytest.mark.parametrize("spread_m", [0.6, np.inf])
@pytest.mark.parametrize("transition", ["auto", "dense", "separable"])
def test_rss_grid_filter_equals_an_independent_dense_recursion(cells_kind, spread_m, transition):
    rng = np.random.default_rng(30)
    cells = _l_shaped_grid(0.5) if cells_kind == "l_shaped" else rng.uniform(0, 5, (45, 2))
    R, T = 3, 8
    rss = rng.normal(-60, 5, (R, T, 4))
    rss[0, 3, 1] = np.nan                                   # one anchor not heard
    rss[2, 5] = np.nan                                      # a step with nothing heard: prediction only
    velocity = rng.normal(0, 0.3, (T, 2))
    prior = rng.dirichlet(np.ones(len(cells)), R)
    model = lb.RssModel(ANCHORS, lb.PathLossModel(ref_power_dbm=CHANNEL["p0_dbm"], path_loss_exp=CHANNEL["n_exp"],
                                                  sigma_db=CHANNEL["sigma_db"], min_distance_m=CHANNEL["d_min_m"]))
    res = grid_bayes_filter(rss, model, cells, spread_m, velocity_m=velocity, initial_belief=prior,
                            transition=transition)
    ref = _dense_reference(cells, _rss_log_lik(rss, cells, ANCHORS, **CHANNEL), spread_m, velocity, prior)
    _assert_matches(res, ref, cells)


def _fix_and_range(z_fix, cov_fix, beacon, ranges, sigma_range):
    """A callable likelihood: a Gaussian position fix with a full covariance, and a range to one beacon."""
    inv = np.linalg.inv(cov_fix)

    def log_likelihood(cells, t):
        dev = cells[None, :, :] - z_fix[:, t, None, :]
        fix = -0.5 * np.einsum("rci,ij,rcj->rc", dev, inv, dev)
        rng_m = np.linalg.norm(cells - beacon, axis=-1)
        return fix - 0.5 * ((ranges[:, t, None] - rng_m[None, :]) / sigma_range) ** 2
    return log_likelihood


@pytest.mark.parametrize("transition", ["auto", "dense", "separable"])
def test_callable_grid_filter_equals_an_independent_dense_recursion(transition):
    rng = np.random.default_rng(31)
    cells = _l_shaped_grid(0.4)
    R, T = 4, 7
    truth = rng.uniform(1, 3, (R, T, 2))
    cov_fix = np.array([[0.5, 0.2], [0.2, 0.3]])
    z_fix = truth + rng.multivariate_normal(np.zeros(2), cov_fix, (R, T))
    beacon = np.array([4.5, 0.5])
    ranges = np.linalg.norm(truth - beacon, axis=-1) + rng.normal(0, 0.3, (R, T))
    ll = _fix_and_range(z_fix, cov_fix, beacon, ranges, 0.3)
    velocity = np.array([0.2, -0.1])
    res = grid_bayes_filter(None, ll, cells, 0.5, n_steps=T, velocity_m=velocity, transition=transition)
    log_lik = np.stack([ll(cells, t) for t in range(T)], 1)
    ref = _dense_reference(cells, log_lik, 0.5, np.broadcast_to(velocity, (T, 2)), np.ones((R, len(cells))))
    _assert_matches(res, ref, cells)


@pytest.mark.parametrize("dim", [1, 3])
@pytest.mark.parametrize("transition", ["auto", "dense", "separable"])
def test_callable_grid_filter_in_one_and_three_dimensions(dim, transition):
    rng = np.random.default_rng(32 + dim)
    axes = [np.arange(0, 3.01, 0.5), np.arange(0, 2.01, 0.5), np.arange(0, 1.51, 0.5)][:dim]
    cells = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, dim)
    cells = cells[rng.random(len(cells)) < 0.85]            # a masked lattice
    R, T = 3, 6
    z = rng.uniform(0.5, 1.5, (R, T, dim))

    def ll(c, t):
        return -0.5 * np.sum((c[None] - z[:, t, None, :]) ** 2, axis=-1) / 0.4

    velocity = rng.normal(0, 0.2, (T, dim))
    prior = rng.dirichlet(np.ones(len(cells)), R)
    res = grid_bayes_filter(None, ll, cells, 0.45, n_steps=T, velocity_m=velocity, initial_belief=prior,
                            transition=transition)
    ref = _dense_reference(cells, np.stack([ll(cells, t) for t in range(T)], 1), 0.45, velocity, prior)
    _assert_matches(res, ref, cells)


def test_rss_grid_filter_in_three_dimensions():
    """An RssModel with 3-D anchors on a 3-D grid (cells in the model's position space)."""
    rng = np.random.default_rng(35)
    anchors = np.array([[0, 0, 0], [3, 0, 2], [0, 3, 1], [3, 3, 0.0]])
    model = lb.RssModel(anchors, lb.PathLossModel(ref_power_dbm=-40.0, path_loss_exp=2.0, sigma_db=2.0,
                                                  min_distance_m=0.1))
    axes = [np.arange(0, 3.01, 0.5)] * 2 + [np.arange(0, 2.01, 0.5)]
    cells = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    rss = rng.normal(-55, 4, (2, 5, 4))
    res = grid_bayes_filter(rss, model, cells, 0.6)
    ref = _dense_reference(cells, _rss_log_lik(rss, cells, anchors, -40.0, 2.0, 2.0, 0.1), 0.6, np.zeros((5, 3)),
                           np.ones((2, len(cells))))
    _assert_matches(res, ref, cells)


def test_an_rss_model_as_a_callable_gives_the_same_numbers():
    rng = np.random.default_rng(36)
    cells = _l_shaped_grid(0.25)
    model = lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.5, 3.0, min_distance_m=0.1))
    rss = rng.normal(-60, 5, (3, 6, 4))
    rss[1, 2, 0] = np.nan
    direct = grid_bayes_filter(rss, model, cells, 0.5, velocity_m=(0.1, 0.2))
    wrapped = grid_bayes_filter(None, lambda c, t: model.log_likelihood(rss[:, t], c, t, constant=False), cells,
                                0.5, n_steps=6, velocity_m=(0.1, 0.2))
    for name in ("mean", "cov", "map_m", "n_eff", "weights", "particles_m"):
        np.testing.assert_array_equal(getattr(wrapped, name), getattr(direct, name))


# -- the kernel: closed forms ----------------------------------------------------------------------------
def test_interior_kernel_is_a_sampled_gaussian_with_the_poisson_variance():
    """An interior column of the transition is the Gaussian sampled at the cells (not integrated over them, which
    would add about h^2/12): its variance is the Poisson-summation dual series, here 2.3 % below D^2."""
    h, D = 1.0, 0.6
    cells = np.arange(-30, 30.5, h)[:, None]
    col = grid_transition_matrix(cells, D)[:, 30]             # the source at 0
    assert cells[30, 0] == 0.0
    var = col @ cells[:, 0] ** 2
    n = np.arange(1, 6)
    e = np.exp(-2 * np.pi**2 * D**2 * n**2 / h**2)
    dual = (D**2 + 2 * np.sum((D**2 - 4 * np.pi**2 * D**4 * n**2 / h**2) * e)) / (1 + 2 * np.sum(e))
    assert var == pytest.approx(dual, rel=1e-12)
    assert var / D**2 - 1 == pytest.approx(-0.0233, abs=2e-4)       # the docstring's size of the aliasing
    assert col @ cells[:, 0] == pytest.approx(0.0, abs=1e-15)
    np.testing.assert_allclose(grid_transition_matrix(cells, D).sum(axis=0), 1.0, rtol=1e-14)


def test_edge_truncates_and_renormalises():
    """A source on the edge keeps all its mass on the grid (truncation with renormalisation): the predicted mean is
    the half-normal's, by Euler-Maclaurin on the sampled half line (odd derivatives of the Gaussian vanish at 0),
    (D^2 - h^2/12 - h^4/(240 D^2)) / (D sqrt(pi/2) + h/2) up to O(h^6)."""
    D = 1.0
    for h in (0.2, 0.1):
        cells = np.arange(0, 20 + h / 2, h)[:, None]
        col = grid_transition_matrix(cells, D)[:, 0]
        assert col.sum() == pytest.approx(1.0, rel=1e-14)
        expected = (D**2 - h**2 / 12 - h**4 / (240 * D**2)) / (D * np.sqrt(np.pi / 2) + h / 2)
        assert col @ cells[:, 0] == pytest.approx(expected, abs=h**6)
        assert abs(col @ cells[:, 0] - D * np.sqrt(2 / np.pi)) > 0.1 * h        # an O(h) edge effect, not zero


# -- the exact posterior of a linear-Gaussian model ----------------------------------------------------------
def _theta(s2, h, n_terms=6):
    """``2 sum_n exp(-2 pi^2 s^2 n^2 / h^2)``: the Poisson-summation error of a lattice sum of N(., s^2)."""
    n = np.arange(1, n_terms + 1)
    return 2 * np.sum(np.exp(-2 * np.pi**2 * np.multiply.outer(np.asarray(s2), n**2) / h**2), axis=-1)


def _kf_error_bound(P, q, h):
    """Bounds on |grid mean - KF mean| and |grid var - KF var| at each step, 1-D, from the module docstring.

    ``P`` the KF posterior variances ``(T,)``. Step t's prediction multiplies the exact density by a factor within
    ``1 +- theta(s_t)``, ``s_t^2 = P_t-1 q / (P_t-1 + q)``; after t steps the ratio of the grid belief to the sampled
    exact posterior spans at most ``rho_t = prod (1 + theta) / (1 - theta)``. For weights within a ratio ``rho`` of
    g's, ``|E_b f - E_g f| <= (rho - 1)(E_g |f| + |E_g f|)``. The sampled posterior N(m, P) has lattice mean within
    ``dm = sum_n (4 pi P n / h) e_n / (1 - theta)`` of m and second moment about m within
    ``dM = sum_n 8 pi^2 P^2 n^2 / h^2 e_n / (1 - theta)`` of P (``e_n = exp(-2 pi^2 P n^2 / h^2)``)."""
    s2 = P[:-1] * q / (P[:-1] + q)
    th = _theta(s2, h)
    rho = np.concatenate([[1.0], np.cumprod((1 + th) / (1 - th))])
    n = np.arange(1, 7)
    e = np.exp(-2 * np.pi**2 * np.multiply.outer(P, n**2) / h**2)
    dm = np.sum(4 * np.pi * P[:, None] * n / h * e, axis=-1) / (1 - _theta(P, h))
    dM = np.sum(8 * np.pi**2 * P[:, None] ** 2 * n**2 / h**2 * e, axis=-1) / (1 - _theta(P, h))
    M2 = P + dM
    mean_bound = (rho - 1) * (np.sqrt(M2) + dm) + dm
    var_bound = (rho - 1) * (M2 + dm**2) + dM + mean_bound**2 + 2 * dm * mean_bound
    return mean_bound, var_bound


Q1, R1, M0, P0_1, T1, RUNS1 = 1.0, 0.25, 0.3, 4.0, 15, 40


def _random_walk_1d():
    """x_t = x_t-1 + N(0, q), z_t = x_t + N(0, r), prior N(m0, P0), and the KF's exact posterior."""
    rng = np.random.default_rng(37)
    x0 = M0 + np.sqrt(P0_1) * rng.standard_normal(RUNS1)
    x = np.cumsum(np.concatenate([x0[:, None], np.sqrt(Q1) * rng.standard_normal((RUNS1, T1 - 1))], 1), 1)
    z = x + np.sqrt(R1) * rng.standard_normal((RUNS1, T1))
    kf = lb.kalman_filter(np.eye(1), Q1 * np.eye(1), np.full((RUNS1, 1), M0), P0_1 * np.eye(1),
                          lb.LinearMeasurement(z[..., None], np.eye(1), R1 * np.eye(1)), predict_first=False)
    return z, kf


def _grid_1d(z, h, half_width_m=60.0):
    cells = np.arange(-half_width_m, half_width_m + h / 2, h)[:, None]
    prior = np.exp(-0.5 * (cells[:, 0] - M0) ** 2 / P0_1)      # the KF's prior, sampled
    return grid_bayes_filter(None, lambda c, t: -0.5 * (z[:, t, None] - c[None, :, 0]) ** 2 / R1, cells,
                             np.sqrt(Q1), n_steps=T1, initial_belief=prior)


def _errors(grid, kf):
    return (np.abs(grid.mean[..., 0] - kf.mean[..., 0]), np.abs(grid.cov[..., 0, 0] - kf.cov[..., 0, 0]))


def test_grid_posterior_equals_the_kalman_posterior_on_a_fine_grid():
    """h = 0.25 m against posterior std 0.455 m and s = 0.414 m: the aliasing bound is 2e-23, far below round-off,
    so the tolerance is round-off (1e-12 on values of order 10 m). The grid spans +-60 m, the estimates stay within
    +-20 m: the belief at the edges is exp(-40^2 / (2 * 1.21)) = 1e-287 of its peak (edges play no part)."""
    z, kf = _random_walk_1d()
    P = kf.cov[0, :, 0, 0]
    assert np.abs(kf.mean).max() < 20.0
    mean_bound, var_bound = _kf_error_bound(P, Q1, 0.25)
    assert mean_bound.max() < 1e-20 and var_bound.max() < 1e-20
    e_mean, e_var = _errors(_grid_1d(z, 0.25), kf)
    assert e_mean.max() < 1e-12 and e_var.max() < 1e-12


@pytest.mark.parametrize("h", [1.0, 0.8, 0.6, 0.5, 0.4])
def test_grid_error_is_within_the_poisson_summation_bound(h):
    """At spacings where the discretisation error is well above round-off (1e-6 to 6e-2), it stays within the
    bound derived in the module docstring (not fitted to the data) at every run and step."""
    z, kf = _random_walk_1d()
    mean_bound, var_bound = _kf_error_bound(kf.cov[0, :, 0, 0], Q1, h)
    e_mean, e_var = _errors(_grid_1d(z, h), kf)
    assert np.all(e_mean <= mean_bound + 1e-13)
    assert np.all(e_var <= var_bound + 1e-13)
    assert e_mean.max() > 1e-3 * mean_bound.max()              # the bound is a bound on this error, not vacuous


@pytest.mark.parametrize("h", [1.0, 0.9, 0.8])
def test_grid_error_shrinks_exponentially_when_the_spacing_halves(h):
    """The leading error is exp(-2 pi^2 s^2 / h^2) with s^2 = P q / (P + q) at the KF's steady state, so from h to
    h/2 the log of the largest error falls by 6 pi^2 s^2 / h^2 (10.2 to 15.9 here). The prefactor is a slowly
    varying function of h, allowed 20 % of that log; an O(h^2) error would fall by log 4 = 1.4."""
    z, kf = _random_walk_1d()
    P = kf.cov[0, -1, 0, 0]
    s2 = P * Q1 / (P + Q1)
    coarse, fine = _errors(_grid_1d(z, h), kf), _errors(_grid_1d(z, h / 2), kf)
    predicted = 6 * np.pi**2 * s2 / h**2
    for e_h, e_h2 in zip(coarse, fine):
        measured = np.log(e_h.max() / e_h2.max())
        assert measured == pytest.approx(predicted, rel=0.2)
        assert measured > 5 * np.log(4.0)


def test_grid_posterior_equals_the_kalman_posterior_in_two_dimensions():
    """A 2-D random walk with a known velocity (KF: control input B u = v) and correlated position readings
    (the likelihood is not separable; the transition is). h = 0.2 m does not divide the velocity (the kernel sits
    off the lattice; its normaliser is still the same for every interior column). The aliasing bound
    (theta at the smallest eigenvalue of P Q / (P + Q)) is below 1e-20: the tolerance is round-off."""
    rng = np.random.default_rng(38)
    q, R_cov, v, T, runs, h = 1.0, np.array([[0.3, 0.1], [0.1, 0.2]]), np.array([0.5, -0.25]), 10, 5, 0.2
    m0, P0 = np.array([0.5, -0.3]), np.diag([2.0, 1.5])
    x = [rng.multivariate_normal(m0, P0, runs)]
    for _ in range(T - 1):
        x.append(x[-1] + v + np.sqrt(q) * rng.standard_normal((runs, 2)))
    x = np.stack(x, 1)
    z = x + rng.multivariate_normal(np.zeros(2), R_cov, (runs, T))
    kf = lb.kalman_filter(np.eye(2), q * np.eye(2), np.broadcast_to(m0, (runs, 2)), P0,
                          lb.LinearMeasurement(z, np.eye(2), R_cov), B=np.eye(2),
                          u=np.broadcast_to(v, (runs, T, 2)), predict_first=False)
    lam = np.linalg.eigvalsh(kf.cov[0]).min(axis=-1)                                # (T,)
    s2 = lam[:-1] * q / (lam[:-1] + q)
    assert np.all(np.exp(-2 * np.pi**2 * np.minimum(s2, lam[1:]) / h**2) < 1e-20)
    assert np.abs(kf.mean - m0).max() < 12.0                    # 13 m or more from the +-25 m edges
    axis = np.arange(-25.0, 25.0 + h / 2, h)
    cells = np.stack(np.meshgrid(axis, axis), -1).reshape(-1, 2)
    inv_p0, inv_r = np.linalg.inv(P0), np.linalg.inv(R_cov)
    prior = np.exp(-0.5 * np.einsum("ci,ij,cj->c", cells - m0, inv_p0, cells - m0))

    def ll(c, t):
        dev = c[None] - z[:, t, None, :]
        return -0.5 * np.einsum("rci,ij,rcj->rc", dev, inv_r, dev)

    grid = grid_bayes_filter(None, ll, cells, np.sqrt(q), n_steps=T, velocity_m=v, initial_belief=prior)
    np.testing.assert_allclose(grid.mean, kf.mean, rtol=0, atol=1e-12)
    np.testing.assert_allclose(grid.cov, kf.cov, rtol=0, atol=1e-12)


# -- the callable's contract -------------------------------------------------------------------------------
def test_callable_collapse_is_isolated_and_named():
    cells = _l_shaped_grid(0.5)
    rng = np.random.default_rng(39)
    z = rng.uniform(1, 3, (3, 5, 2))

    def ll(c, t):
        out = -0.5 * np.sum((c[None] - z[:, t, None, :]) ** 2, axis=-1)
        if t == 2:
            out[1] = -np.inf                                  # run 1: nothing explains its reading at step 2
        return out

    with pytest.warns(RuntimeWarning, match=r"log_likelihood collapsed in 1 of 3 runs \(first: run 1, step 2"):
        res = grid_bayes_filter(None, ll, cells, 0.5, n_steps=5)
    assert res.diverged.tolist() == [False, True, False] and res.diverged_step.tolist() == [-1, 2, -1]
    assert np.isnan(res.mean[1, 2:]).all() and np.isfinite(res.mean[1, :2]).all()
    alone = grid_bayes_filter(None, lambda c, t: -0.5 * np.sum((c[None] - z[::2, t, None, :]) ** 2, -1), cells,
                              0.5, n_steps=5)
    np.testing.assert_array_equal(res.mean[::2], alone.mean)
    with pytest.raises(ValueError, match="log_likelihood collapsed in every run"):
        grid_bayes_filter(None, lambda c, t: np.full((2, len(c)), np.nan), cells, 0.5, n_steps=3)


@pytest.mark.parametrize("kwargs, message", [
    (dict(rss_dbm=np.zeros((1, 2, 4))), "rss_dbm goes with an RssModel"),
    (dict(n_steps=None), "n_steps must be given"),
    (dict(n_steps=0), "n_steps must be"),
    (dict(ll=lambda c, t: np.zeros(len(c))), r"log_likelihood must return \(runs, C\)"),
    (dict(ll=lambda c, t: np.zeros((2 + t, len(c)))), r"got \(3, 12\) at step 1"),
    (dict(initial_belief=np.ones((3, 12))), r"initial_belief must have shape \(12,\) or \(2, 12\)"),
    (dict(velocity_m=(0.1, 0.2, 0.3)), r"velocity_m must have shape \(2,\) or \(steps, 2\)"),
    (dict(ll="not callable"), "model must be an RssModel or a callable"),
])
def test_callable_bad_input_names_the_argument(kwargs, message):
    cells = np.stack(np.meshgrid(np.arange(4.0), np.arange(3.0)), -1).reshape(-1, 2)         # 12 cells
    call = dict(rss_dbm=None, ll=lambda c, t: np.zeros((2, len(c))), n_steps=3) | kwargs
    rss, ll, n_steps = call.pop("rss_dbm"), call.pop("ll"), call.pop("n_steps")
    with pytest.raises(ValueError, match=message):
        grid_bayes_filter(rss, ll, cells, 0.5, n_steps=n_steps, **call)


def test_rss_model_needs_its_readings():
    model = lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.5, 3.0, min_distance_m=0.1))
    with pytest.raises(ValueError, match="rss_dbm must be the readings"):
        grid_bayes_filter(None, model, _l_shaped_grid(1.0), 0.5, n_steps=3)
    with pytest.raises(ValueError, match="n_steps 4 disagrees"):
        grid_bayes_filter(np.zeros((1, 3, 4)), model, _l_shaped_grid(1.0), 0.5, n_steps=4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        grid_bayes_filter(np.full((1, 3, 4), -60.0), model, _l_shaped_grid(1.0), 0.5, n_steps=3)


# -- size guard ------------------------------------------------------------------------------------
def _guard_model():
    return lb.RssModel(np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]]),
                       lb.PathLossModel(-40.0, 2.0, 4.0, min_distance_m=0.1))


@pytest.mark.parametrize("transition", ["auto", "dense", "separable"])
def test_scattered_cells_beyond_the_limit_are_refused_before_anything_is_allocated(transition):
    import tracemalloc
    cells = np.random.default_rng(0).random((100_000, 2)) * 10.0            # no two cells share a coordinate
    tracemalloc.start()
    try:
        with pytest.raises(ValueError) as exc:
            grid_bayes_filter(np.full((1, 5, 3), -60.0), _guard_model(), cells, 0.5, transition=transition)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    text = str(exc.value)
    assert "\n" not in text and text.startswith("cells_m: ") and "MAX_ARRAY_BYTES = 2 GiB" in text
    if transition == "separable":     # the lattice of the distinct coordinates: 1e5 x 1e5 points
        assert f"1 x 10,000,000,000 float64 values, would take {8e10 / 2**30:.3g} GiB" in text
    else:                             # the dense construction's C x C x dim difference
        assert f"100,000 x 100,000 x 2 float64 values, would take {1.6e11 / 2**30:.3g} GiB" in text
    assert peak < 50 * 2**20


def test_grid_transition_matrix_checks_its_size_first(monkeypatch):
    import locbook.tracking.bayes as bayes
    cells = np.random.default_rng(1).random((300, 2))
    monkeypatch.setattr(bayes, "MAX_ARRAY_BYTES", 8 * 300 * 300 * 2)        # the construction's largest array
    assert grid_transition_matrix(cells, 0.5).shape == (300, 300)
    monkeypatch.setattr(bayes, "MAX_ARRAY_BYTES", 8 * 300 * 300 * 2 - 1)
    with pytest.raises(ValueError, match="^cells_m: the dense transition"):
        grid_transition_matrix(cells, 0.5)
    with pytest.raises(ValueError, match="^cells_m: the dense transition"):
        grid_bayes_filter(np.full((1, 3, 3), -60.0), _guard_model(), cells * 10, 0.5, transition="dense")


def test_the_repositorys_grids_are_inside_the_limit():
    """The largest grids in use (bench_grid's 36,000-cell separable lattice over 12 runs, bench_real_data's 5,111-cell
    dense check, 2-D) stay inside the limit, and so does a 10,000-cell dense transition."""
    from locbook.tracking.bayes import MAX_ARRAY_BYTES
    assert 8 * 12 * 36_000 < MAX_ARRAY_BYTES and 8 * 10_000**2 * 2 < MAX_ARRAY_BYTES
    xs, ys = np.arange(0, 24, 0.1), np.arange(0, 15, 0.1)
    cells = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
    res = grid_bayes_filter(np.full((2, 3, 3), -60.0), _guard_model(), cells, 0.5)
    assert np.isfinite(res.mean).all()


def test_no_cells_is_one_line_not_a_division_by_zero():
    """Before: ZeroDivisionError (the uniform prior 1 / C) and numpy's "zero-size array to reduction"."""
    with pytest.raises(ValueError, match=r"^cells_m must hold at least one cell, got shape \(0, 2\)$"):
        grid_bayes_filter(np.full((2, 3, 3), -60.0), _guard_model(), np.zeros((0, 2)), 0.5)
    with pytest.raises(ValueError, match=r"^cells_m must hold at least one cell"):
        grid_transition_matrix(np.zeros((0, 2)), 0.5)
