"""Palvai 2008 scenario: the corrected Jacobian (4.43) against finite differences (the printed one is not it), the
printed parameters, the EKF's sequential schedule, and the particle filter's schedules."""
import numpy as np
import pytest

from locbook.scenarios import palvai as pv


def test_printed_parameters_are_read_from_the_file():
    assert (pv.SIGMA1_DB, pv.ETA, pv.SIGMA2_M, pv.SIGMA3_M, pv.N_LOCATIONS) == (6.0, 4.0, 1.0, 5.0, 25)


def test_corrected_jacobian_matches_finite_differences_and_the_printed_one_does_not():
    rng = np.random.default_rng(0)
    s = rng.uniform(0, 50, (6, 3))
    x = np.array([20.0, 31.0, 12.0])
    setup = pv.Setup()
    h = lambda p: setup.channel.mean_rss_dbm(np.linalg.norm(p - s, axis=-1))
    fd = np.stack([(h(x + 1e-6 * e) - h(x - 1e-6 * e)) / 2e-6 for e in np.eye(3)], -1)
    np.testing.assert_allclose(pv.corrected_jacobian(x, s, pv.ETA), fd, rtol=1e-6, atol=1e-9)
    assert not np.allclose(pv.printed_jacobian(x, s, pv.ETA), fd, rtol=0.5)


def test_sequential_ekf_equals_a_filterpy_loop_over_the_locations():
    from filterpy.kalman import ExtendedKalmanFilter
    rng = np.random.default_rng(1)
    setup = pv.Setup(receiver_sigma_m=5.0)
    loc = pv.draw_locations(2, 12, 3, rng)
    z = pv.measure(setup, loc, rng)
    x0 = rng.uniform(0, 50, (2, 3))
    ours = pv.ekf_path(setup, loc, z, x0, 100 * np.eye(3))
    for r in range(2):
        f = ExtendedKalmanFilter(3, 1)
        f.x, f.P, f.F, f.Q, f.R = x0[r].copy(), 100 * np.eye(3), np.eye(3), np.eye(3), np.array([[36.0]])
        for k in range(12):
            f.predict()
            s = loc[r, k]
            f.update(np.array([z[r, k]]), HJacobian=lambda p: pv.corrected_jacobian(p, s[None], 4.0),
                     Hx=lambda p: np.array([-20.0 - 40 * np.log10(np.linalg.norm(p - s))]))
            np.testing.assert_allclose(ours[r, k], f.x, atol=1e-8)


@pytest.mark.parametrize("schedule", pv.SCHEDULES)
def test_particle_filter_schedules_run_and_concentrate(schedule):
    rng = np.random.default_rng(2)
    setup = pv.Setup(dim=2, sigma_db=2.0)
    loc = pv.draw_locations(3, 20, 2, rng)
    z = pv.measure(setup, loc, rng)
    res = pv.pf_run(setup, loc, z, rng, n_particles=3000, n_iterations=20, schedule=schedule, true_locations_m=loc)
    assert res.mean.shape == (3, 20, 2)
    assert np.all(pv.errors_m(res.mean[:, -1], setup.target) < 8.0)
    variance = np.trace(res.cov, axis1=-2, axis2=-1)
    assert np.all(variance[:, -1] < variance[:, 0])
    with pytest.raises(ValueError, match="n_iterations <= 20"):
        pv.pf_run(setup, loc, z, rng, n_particles=10, n_iterations=21, schedule="sequential")


# -- the readings opened as notebook parameters ---------------------------------------------------------
def test_area_centre_draws_nothing_and_uniform_per_run_draws_one_target_per_run_inside_the_area():
    setup = pv.Setup(dim=3)
    rng = np.random.default_rng(7)
    assert pv.with_target(setup, "area_centre", 40, rng) is setup
    assert rng.random() == np.random.default_rng(7).random()          # the stream was not advanced
    drawn = pv.with_target(setup, "uniform_per_run", 400, np.random.default_rng(8))
    t = drawn.target
    assert t.shape == (400, 3) and np.all((t >= 0) & (t <= pv.AREA_M))
    # uniform on [0, 50]: mean 25 and variance 50^2 / 12 per axis, within 4 standard errors
    assert np.all(np.abs(t.mean(0) - 25.0) < 4 * 50 / np.sqrt(12 * 400))
    assert np.allclose(t.var(0), 50**2 / 12, rtol=0.25)
    with pytest.raises(ValueError, match="target must be one of"):
        pv.with_target(setup, "corner", 3, rng)


def test_per_run_targets_are_measured_and_scored_run_by_run():
    rng = np.random.default_rng(3)
    setup = pv.with_target(pv.Setup(dim=2, sigma_db=0.0), "uniform_per_run", 3, rng)
    loc = pv.draw_locations(3, 6, 2, rng)
    z = pv.measure(setup, loc, rng)
    for r in range(3):                       # the noise-free reading is the path loss to that run's own target
        d = np.linalg.norm(loc[r] - setup.run_target(r), axis=-1)
        np.testing.assert_allclose(z[r], -20.0 - 10 * pv.ETA * np.log10(np.maximum(d, 1.0)))
        one = pv.Setup(dim=2, sigma_db=6.0, receiver_sigma_m=5.0, target_m=tuple(setup.run_target(r)))
        many = pv.Setup(dim=2, sigma_db=6.0, receiver_sigma_m=5.0, target_m=setup.target_m)
        assert pv.crlb_m(many, loc)[r] == pytest.approx(pv.crlb_m(one, loc[r:r + 1])[0], rel=1e-12)
    est = rng.uniform(0, 50, (3, 4, 2))
    np.testing.assert_allclose(pv.errors_m(est, setup.target),
                               [[np.hypot(*(est[r, k] - setup.run_target(r))) for k in range(4)] for r in range(3)])
    # noise-free readings and exact positions: the LSF recovers each run's own target
    np.testing.assert_allclose(pv.lsf_by_count(setup, loc, z, [6])[:, 0], setup.target, atol=1e-8)


def test_the_link_budget_cancels_from_every_estimator():
    rng = np.random.default_rng(4)
    loc = pv.draw_locations(4, 12, 3, rng)
    shadow = 6.0 * rng.standard_normal((4, 12))
    base, other = pv.Setup(receiver_sigma_m=5.0), pv.Setup(receiver_sigma_m=5.0, ref_power_dbm=-35.0)
    z = {s: s.channel.mean_rss_dbm(np.linalg.norm(loc - s.target, axis=-1)) + shadow for s in (base, other)}
    x0 = rng.uniform(0, 50, (4, 3))
    for f in (lambda s: pv.lsf_by_count(s, loc, z[s], [5, 12]), lambda s: pv.rlsf_path(s, loc, z[s]),
              lambda s: pv.ekf_path(s, loc, z[s], x0, 100 * np.eye(3))):
        np.testing.assert_allclose(f(other), f(base), rtol=1e-9, atol=1e-9)


def _replayed_prior(seed, runs, n, dim):
    rng = np.random.default_rng(seed)
    rng.integers(2**63)                              # pf_run's data stream is drawn first
    return rng.uniform(0.0, pv.AREA_M, (runs, n, dim))


def test_pf_mean_and_highest_weight_are_the_weighted_mean_and_argmax_of_the_likelihood():
    setup = pv.Setup(dim=2, sigma_db=4.0)
    rng = np.random.default_rng(5)
    loc = pv.draw_locations(2, 5, 2, rng)
    z = pv.measure(setup, loc, rng)
    res = pv.pf_run(setup, loc, z, np.random.default_rng(11), n_particles=400, n_iterations=1, process_sd_m=0.0)
    x = _replayed_prior(11, 2, 400, 2)
    d = np.maximum(np.linalg.norm(x[:, :, None, :] - loc[:, None], axis=-1), 1.0)
    loglik = -0.5 * np.sum((z[:, None, :] - (-20.0 - 10 * pv.ETA * np.log10(d))) ** 2, axis=-1) / 4.0**2
    w = np.exp(loglik - loglik.max(-1, keepdims=True))
    w /= w.sum(-1, keepdims=True)
    np.testing.assert_allclose(pv.pf_estimate_m(res, "mean"), np.einsum("rn,rnd->rd", w, x), rtol=1e-10)
    np.testing.assert_array_equal(pv.pf_estimate_m(res, "highest_weight"), x[np.arange(2), w.argmax(-1)])
    with pytest.raises(ValueError, match="estimate must be one of"):
        pv.pf_estimate_m(res, "median")


def test_pf_kde_mode_is_scipy_gaussian_kde_argmax_over_the_particles():
    from scipy.stats import gaussian_kde
    rng = np.random.default_rng(6)
    raw = np.concatenate([rng.normal(0.0, 1.0, (2, 150, 3)), rng.normal(3.0, 2.0, (2, 90, 3))], axis=1)
    w = rng.uniform(0.2, 1.0, (2, 240))
    w /= w.sum(-1, keepdims=True)
    x = np.empty_like(raw)
    for r in range(2):      # whiten so that the weighted (biased) covariance is I: the kernel is then isotropic
        m = w[r] @ raw[r]
        c = np.einsum("n,ni,nj->ij", w[r], raw[r] - m, raw[r] - m)
        x[r] = np.linalg.solve(np.linalg.cholesky(c), (raw[r] - m).T).T
    res = type("Result", (), {"particles_m": x, "weights": w})()
    ours = pv.pf_estimate_m(res, "kde_mode")
    for r in range(2):
        n_eff = 1 / np.sum(w[r] ** 2)
        h = 1.06 * n_eff ** (-1 / 7)                  # Silverman's rule with unit spread, dim 3
        # scipy's kernel covariance is factor^2 times the unbiased weighted covariance I / (1 - sum w^2)
        kde = gaussian_kde(x[r].T, bw_method=h * np.sqrt(1 - np.sum(w[r] ** 2)), weights=w[r])
        np.testing.assert_allclose(kde.covariance, h**2 * np.eye(3), atol=1e-10)
        np.testing.assert_array_equal(ours[r], x[r, np.argmax(kde(x[r].T))])


def test_the_sequential_schedule_runs_one_iteration_per_location_and_the_others_as_asked():
    assert pv.pf_iterations("sequential", 250, 10) == 10 and pv.pf_iterations("sequential", 5, 10) == 5
    assert pv.pf_iterations("all", 250, 10) == 250 and pv.pf_iterations("cyclic", 250, 10) == 250
    rng = np.random.default_rng(9)
    setup = pv.Setup(dim=2)
    loc = pv.draw_locations(2, 4, 2, rng)
    z = pv.measure(setup, loc, rng)
    res = pv.pf_run(setup, loc, z, rng, n_particles=50, n_iterations=pv.pf_iterations("sequential", 30, 4),
                    schedule="sequential")
    assert res.mean.shape == (2, 4, 2)
    with pytest.raises(ValueError, match="schedule must be one of"):
        pv.pf_iterations("random", 3, 4)


def test_fig7_default_exact_locations_without_shadowing_give_the_exact_batch_fix():
    # Fig. 7 is Fig. 8 without shadowing, with the locations known exactly (Sec. 2.6): the differenced
    # system of Eqs. (2.27)-(2.29) is then consistent and its least-squares solution is the target itself
    rng = np.random.default_rng(3)
    setup = pv.Setup(dim=3, sigma_db=0.0, receiver_sigma_m=0.0)
    loc = pv.draw_locations(4, 20, 3, rng)
    z = pv.measure(setup, loc, rng)
    seen = pv.observed_locations(setup, loc, rng)
    np.testing.assert_array_equal(seen, loc)
    est = pv.lsf_by_count(setup, seen, z, [5, 10, 20])
    assert pv.errors_m(est, setup.target).max() < 1e-6
    from locbook.reproduce.interpretations import interpretations
    fig7 = {r.name: r for r in interpretations("palvai2008")}["fig7_gps_noise"]
    assert fig7.default == 0.0 and pv.SIGMA3_M in fig7.alternatives
