"""Palvai 2008 scenario: the corrected Jacobian (4.43) against finite differences (the printed one is not it), the
printed parameters, the EKF's sequential schedule, and the particle filter's schedules."""
import numpy as np
import pytest

import locbook as lb
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
    assert res.mean_m.shape == (3, 20, 2)
    assert np.all(pv.errors_m(res.mean_m[:, -1], setup.target) < 8.0)
    variance = np.trace(res.covariance_m2, axis1=-2, axis2=-1)
    assert np.all(variance[:, -1] < variance[:, 0])
    with pytest.raises(ValueError, match="n_iterations <= 20"):
        pv.pf_run(setup, loc, z, rng, n_particles=10, n_iterations=21, schedule="sequential")
