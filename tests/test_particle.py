"""The general SIR particle filter against the Kalman posterior of a linear-Gaussian problem, its RSS likelihood
against a direct computation, the kernel MAP and the N_eff trigger."""
import numpy as np
import pytest

import locbook as lb


@pytest.mark.parametrize("method", lb.RESAMPLING_METHODS)
def test_sir_posterior_of_a_linear_gaussian_problem_equals_the_kalman_posterior(method):
    rng = np.random.default_rng(0)
    R, Ns, K = 4, 40_000, 5
    m0, P0 = np.array([1.0, -2.0]), np.diag([4.0, 1.0])
    r = 0.5
    truth = np.array([2.0, -1.5])
    z = truth + np.sqrt(r) * rng.standard_normal((R, K, 2))
    particles = m0 + rng.standard_normal((R, Ns, 2)) @ np.linalg.cholesky(P0).T

    def loglik(x, k):
        return -0.5 * np.sum((z[:, k, None, :] - x) ** 2, axis=-1) / r

    res = lb.sir_particle_filter(particles, loglik, K, rng, resampling=method)
    # conjugate posterior after all K steps (static state, z_k = x + v)
    info = np.linalg.inv(P0) + K / r * np.eye(2)
    post_P = np.linalg.inv(info)
    post_m = (post_P @ (np.linalg.solve(P0, m0)[:, None] + z.sum(axis=1).T / r)).T
    tol = 5 * np.sqrt(np.diag(post_P) / (Ns / 10))           # resampling leaves ~Ns/10 distinct ancestors
    assert np.all(np.abs(res.mean[:, -1] - post_m) < tol)
    np.testing.assert_allclose(res.variance[:, -1].mean(axis=0), np.diag(post_P), rtol=0.1)
    assert res.resampled.all()


@pytest.mark.parametrize("ref_distance_m", [1.0, 2.0])
def test_rss_log_likelihood_leaves_out_missing_readings(ref_distance_m):
    rng = np.random.default_rng(1)
    ch = lb.PathLossModel(-20.0, 4.0, 6.0, ref_distance_m=ref_distance_m)
    x = rng.uniform(0, 50, (2, 7, 3))
    s = rng.uniform(0, 50, (2, 4, 3))
    z = rng.uniform(-90, -50, (2, 4))
    z[1, 2] = np.nan
    ours = lb.rss_log_likelihood(x, s, z, ch)
    for r in range(2):
        for i in range(7):
            d = np.linalg.norm(x[r, i] - s[r], axis=-1)
            h = -20 - 40 * np.log10(d / ref_distance_m)
            keep = np.isfinite(z[r])
            assert ours[r, i] == pytest.approx(-np.sum((z[r, keep] - h[keep]) ** 2) / 72.0)


def test_kernel_map_finds_the_mode_and_neff_triggers_resampling():
    rng = np.random.default_rng(2)
    x = np.concatenate([rng.normal(3.0, 1.0, (1, 3000, 2)), rng.normal(-6.0, 3.0, (1, 1000, 2))], axis=1)
    w = np.full((1, 4000), 1 / 4000)
    mode = lb.kernel_map_estimate(x, w)
    assert np.linalg.norm(mode[0] - 3.0) < 0.6
    res = lb.sir_particle_filter(rng.normal(0, 1, (3, 500, 1)), lambda p, k: -0.5 * p[..., 0] ** 2 * (k + 1), 4, rng,
                                 resample_threshold=250.0)
    np.testing.assert_array_equal(res.resampled, res.n_eff < 250.0)
