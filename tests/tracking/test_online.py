"""Online filtering, NEES and noise estimation.

- OnlineFilter, fed one step at a time, gives the batch filter's numbers (KF with a time-varying model and a control
  input, the RSS EKF and UKF, the EKF and UKF with a step-aware nonlinear motion) and the batch call's divergence flags;
- NEES: the closed form on one sample, and its chi-square mean over Monte-Carlo runs of a consistent KF;
- EM: pykalman's robot data, the log-likelihoods its data set records for the first five EM iterations and pykalman's
  own EM estimates; ML: at the estimate, pykalman's independent log-likelihood equals ours and every nearby setting
  scores lower; per-run estimates equal separate fits and recover the simulated noise levels."""
import numpy as np
import pytest

import locbook as lb

pykalman = pytest.importorskip("pykalman")


def _cv_runs(rng, runs, T, q=0.05, r=0.5, missing=True):
    model = lb.constant_velocity(1.0, q, dim=2)
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    truth = np.empty((runs, T, 4))
    x = np.zeros((runs, 4))
    G = model.G
    for k in range(T):
        x = x @ model.F.T + rng.normal(0, np.sqrt(q), (runs, 2)) @ G.T
        truth[:, k] = x
    z = truth[..., :2] + rng.normal(0, np.sqrt(r), (runs, T, 2))
    if missing:
        z[:, 5:8] = np.nan
    return model, H, r * np.eye(2), truth, z


def test_online_filter_equals_the_batch_call():
    rng = np.random.default_rng(5)
    model, H, R, truth, z = _cv_runs(rng, runs=4, T=30)
    T = z.shape[1]
    Fs = np.broadcast_to(model.F, (T, 4, 4)) * (1 + 0.01 * rng.normal(size=(T, 1, 1)))
    B, u = np.vstack([np.zeros((2, 2)), np.eye(2)]), 0.01 * rng.normal(size=(4, T, 2))
    x0, P0 = np.zeros(4), np.eye(4)
    batch = lb.kalman_filter(lb.per_step(Fs), model.Q, np.broadcast_to(x0, (4, 4)), P0,
                             lb.LinearMeasurement(z, H, R), B=B, u=u)
    online = lb.OnlineFilter("kf", lb.per_step(Fs), model.Q, np.broadcast_to(x0, (4, 4)), P0, B=B)
    for k in range(T):
        step = online.step(lb.LinearMeasurement(z[:, k:k + 1], H, R), u=u[:, k])
        np.testing.assert_allclose(step.mean[:, 0], batch.mean[:, k], atol=1e-12)
        np.testing.assert_allclose(step.cov[:, 0], batch.cov[:, k], atol=1e-12)
    np.testing.assert_allclose(online.log_likelihood, batch.total_log_likelihood, atol=1e-9)


def test_online_ekf_and_ukf_equal_batch_and_flag_the_same_divergence():
    rng = np.random.default_rng(6)
    channel = lb.PathLossModel(ref_power_dbm=-40.0, path_loss_exp=2.5, sigma_db=0.5, min_distance_m=1e-3)
    anchors = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    model, _, _, truth, _ = _cv_runs(rng, runs=3, T=40, missing=False)
    truth[..., :2] += 5.0
    d = np.linalg.norm(truth[..., None, :2] - anchors, axis=-1)
    rss = channel.mean_rss_dbm(d) + rng.normal(0, 3.0, d.shape)       # noise 6x the model's: inconsistent innovations
    meas = lambda r: lb.RssMeasurement(r, anchors, channel, position_index=np.array([0, 1]))
    x0, P0 = np.broadcast_to([5.0, 5.0, 0, 0], (3, 4)), np.diag([4.0, 4.0, 1.0, 1.0])
    for kind, fn in (("ekf", lb.extended_kalman_filter), ("ukf", lb.unscented_kalman_filter)):
        batch = fn(model.F, model.Q, x0, P0, meas(rss), divergence_window=5)
        online = lb.OnlineFilter(kind, model.F, model.Q, x0, P0, divergence_window=5)
        for k in range(rss.shape[1]):
            step = online.step(meas(rss[:, k:k + 1]))
            np.testing.assert_allclose(step.mean[:, 0], batch.mean[:, k], atol=1e-10)
        assert batch.diverged.any()                         # the case exercises the guard
        np.testing.assert_array_equal(step.diverged, batch.diverged)
        np.testing.assert_array_equal(step.diverged_step, batch.diverged_step)


def test_online_nonlinear_motion_with_the_step_equals_batch():
    """A unicycle whose time step varies by step (f(x, k)): the online filter passes its step counter."""
    rng = np.random.default_rng(10)
    dts = 0.2 + 0.1 * rng.random(30)

    def f(x, k):
        out = np.array(x, dtype=float, copy=True)
        out[..., 0] += dts[k] * x[..., 3] * np.cos(x[..., 2])
        out[..., 1] += dts[k] * x[..., 3] * np.sin(x[..., 2])
        return out

    def jac(x, k):
        J = np.broadcast_to(np.eye(4), x.shape[:-1] + (4, 4)).copy()
        J[..., 0, 2], J[..., 0, 3] = -dts[k] * x[..., 3] * np.sin(x[..., 2]), dts[k] * np.cos(x[..., 2])
        J[..., 1, 2], J[..., 1, 3] = dts[k] * x[..., 3] * np.cos(x[..., 2]), dts[k] * np.sin(x[..., 2])
        return J
    motion = lb.NonlinearMotion(f, jac, uses_step=True)
    z = rng.normal(size=(2, 30, 2)) + np.linspace(0, 3, 30)[:, None]
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    x0, P0, Q = np.broadcast_to([0.0, 0.0, 0.5, 1.0], (2, 4)), np.eye(4), 0.01 * np.eye(4)
    for kind, fn in (("ekf", lb.extended_kalman_filter), ("ukf", lb.unscented_kalman_filter)):
        batch = fn(motion, Q, x0, P0, lb.LinearMeasurement(z, H, np.eye(2)))
        online = lb.OnlineFilter(kind, motion, Q, x0, P0)
        for k in range(30):
            step = online.step(lb.LinearMeasurement(z[:, k:k + 1], H, np.eye(2)))
            np.testing.assert_allclose(step.mean[:, 0], batch.mean[:, k], atol=1e-12)


def test_online_filter_refuses_what_the_batch_call_refuses():
    online = lb.OnlineFilter("kf", np.eye(2), np.eye(2), np.zeros(2), np.eye(2))
    with pytest.raises(ValueError, match="one step of readings"):
        online.step(lb.LinearMeasurement(np.zeros((3, 2)), np.eye(2), np.eye(2)))
    with pytest.raises(ValueError, match="unknown option"):
        lb.OnlineFilter("kf", np.eye(2), np.eye(2), np.zeros(2), np.eye(2), josep=False)
    short = lb.OnlineFilter("kf", lb.per_step(np.broadcast_to(np.eye(2), (2, 2, 2))), np.eye(2), np.zeros(2), np.eye(2))
    for _ in range(2):
        short.step(lb.LinearMeasurement(np.zeros((1, 2)), np.eye(2), np.eye(2)))
    with pytest.raises(ValueError, match="past its end"):
        short.step(lb.LinearMeasurement(np.zeros((1, 2)), np.eye(2), np.eye(2)))


def test_nees_closed_form_and_chi_square_mean_over_runs():
    from scipy.stats import chi2
    x = np.array([1.0, 2.0])
    P = np.array([[2.0, 0.5], [0.5, 1.0]])
    assert lb.nees(np.zeros(2), x, P) == pytest.approx(x @ np.linalg.solve(P, x), rel=1e-14)
    rng = np.random.default_rng(7)
    M = 400
    model, H, R, truth, z = _cv_runs(rng, runs=M, T=25, missing=False)
    run = lb.kalman_filter(model.F, model.Q, np.zeros((M, 4)), 1e-9 * np.eye(4), lb.LinearMeasurement(z, H, R))
    e = lb.nees(truth, run.mean, run.cov)
    assert e.shape == (M, 25)
    # the filter is the exact posterior of the simulated model: the mean NEES over runs is chi^2(4 M) / M
    lo, hi = chi2.ppf([1e-4, 1 - 1e-4], 4 * M) / M
    mean = e[:, -1].mean()
    assert lo < mean < hi
    pos = lb.nees(truth, run.mean, run.cov, index=[0, 1])[:, -1].mean()
    lo2, hi2 = chi2.ppf([1e-4, 1 - 1e-4], 2 * M) / M
    assert lo2 < pos < hi2
    assert np.isnan(lb.nees(np.full(2, np.nan), x, P))
    with pytest.raises(ValueError, match="index must be distinct state components"):
        lb.nees(np.zeros(2), x, P, index=[0, 2])
    with pytest.raises(ValueError, match="singular"):
        lb.nees(np.zeros(2), x, np.zeros((2, 2)))


def _robot():
    from pykalman.datasets import load_robot
    d = load_robot()
    z = np.ma.filled(np.ma.asarray(d.observations, dtype=float), np.nan)
    T, n = z.shape[0], 5
    u = np.zeros((T, n))
    u[1:] = d.transition_offsets[:T - 1]
    return d, z, u


@pytest.mark.slow
def test_em_equals_pykalman_on_its_robot_data():
    d, z, u = _robot()
    meas = lb.LinearMeasurement(z, d.observation_matrix, d.initial_observation_covariance,
                                offset=d.observation_offset)
    fit = lb.fit_noise_em(d.transition_matrix, d.initial_transition_covariance, d.initial_state_mean,
                          d.initial_state_covariance, meas, B=np.eye(5), u=u, n_iter=4)
    # the data set's log-likelihoods before each of the first five EM iterations (a MATLAB implementation)
    np.testing.assert_allclose(fit.history, d.loglikelihoods[:5], atol=1e-8)
    assert np.all(np.diff(fit.history) > 0)
    kf = pykalman.KalmanFilter(d.transition_matrix, d.observation_matrix, d.initial_transition_covariance,
                               d.initial_observation_covariance, d.transition_offsets, d.observation_offset,
                               d.initial_state_mean, d.initial_state_covariance,
                               em_vars=["transition_covariance", "observation_covariance"])
    kf.em(np.ma.masked_invalid(z), n_iter=4)
    np.testing.assert_allclose(fit.Q, kf.transition_covariance, atol=1e-9)
    np.testing.assert_allclose(fit.R[0], kf.observation_covariance, atol=1e-9)


def test_em_with_partly_missing_readings_equals_pykalman_and_never_lowers_the_likelihood():
    """A step with one component missing is missing as a whole (pykalman's rule, in its filter too)."""
    rng = np.random.default_rng(12)
    model, H, R, truth, z = _cv_runs(rng, runs=1, T=200, missing=False)
    z = z[0]
    z[rng.random(200) < 0.4, 1] = np.nan                    # component 1 missing at 40 % of the steps
    z[:30, 0] += rng.normal(0, 5.0, 30)                      # and noisy readings where it is
    x0, P0 = np.zeros(4), np.eye(4)
    fit = lb.fit_noise_em(model.F, model.Q, x0, P0, lb.LinearMeasurement(z, H, R), n_iter=8)
    assert np.all(np.diff(fit.history) > -1e-9 * np.abs(fit.history[1:]))
    kf = pykalman.KalmanFilter(model.F, H, model.Q, R, initial_state_mean=x0, initial_state_covariance=P0,
                               em_vars=["transition_covariance", "observation_covariance"])
    kf.em(np.ma.masked_invalid(z), n_iter=8)
    np.testing.assert_allclose(fit.Q, kf.transition_covariance, atol=1e-9)
    np.testing.assert_allclose(fit.R[0], kf.observation_covariance, atol=1e-9)


@pytest.mark.slow
def test_ml_is_a_maximum_of_pykalmans_independent_likelihood():
    d, z, u = _robot()
    meas = lb.LinearMeasurement(z, d.observation_matrix, d.initial_observation_covariance,
                                offset=d.observation_offset)
    fit = lb.fit_noise_ml(d.transition_matrix, d.initial_transition_covariance, d.initial_state_mean,
                          d.initial_state_covariance, meas, B=np.eye(5), u=u, predict_first=False)
    masked = np.ma.masked_invalid(z)

    def pk(Q, R):
        return pykalman.KalmanFilter(d.transition_matrix, d.observation_matrix, Q, R, d.transition_offsets,
                                     d.observation_offset, d.initial_state_mean,
                                     d.initial_state_covariance).loglikelihood(masked)
    best = pk(fit.Q, fit.R[0])
    assert best == pytest.approx(float(fit.log_likelihood), abs=1e-8)
    assert best > float(fit.initial_log_likelihood) + 100
    for dq in (0.98, 1.0, 1.02):
        for dr in (0.98, 1.0, 1.02):
            if (dq, dr) != (1.0, 1.0):
                assert pk(dq * fit.Q, dr * fit.R[0]) < best


@pytest.mark.slow
def test_per_run_ml_equals_separate_fits_and_recovers_the_simulated_noise():
    rng = np.random.default_rng(8)
    q, r = 0.05, 0.5
    model, H, _, truth, z = _cv_runs(rng, runs=24, T=150, q=q, r=r)
    x0, P0 = np.zeros((24, 4)), np.eye(4)
    # start from wrong levels: Q 10x too small, R 4x too large
    meas = lb.LinearMeasurement(z, H, 4 * r * np.eye(2))
    fit = lb.fit_noise_ml(model.F, 0.1 * model.Q, x0, P0, meas)
    assert fit.q_scale.shape == (24, 1) and not fit.at_bound.any()
    for i in (0, 7):
        alone = lb.fit_noise_ml(model.F, 0.1 * model.Q, x0[i], P0, lb.LinearMeasurement(z[i], H, 4 * r * np.eye(2)))
        np.testing.assert_allclose(fit.q_scale[i], alone.q_scale, rtol=1e-4)
        np.testing.assert_allclose(fit.r_scale[0][i], alone.r_scale[0], rtol=1e-4)
    # the runs' log estimates scatter around the truth (multipliers 10 and 1/4): within 4 standard errors
    for est, true in ((np.log(fit.q_scale[:, 0]), np.log(10.0)), (np.log(fit.r_scale[0][:, 0]), np.log(0.25))):
        assert abs(est.mean() - true) < 4 * est.std(ddof=1) / np.sqrt(est.size)
    pooled = lb.fit_noise_ml(model.F, 0.1 * model.Q, x0, P0, meas, per_run=False)
    assert pooled.q_scale.shape == (1,)
    assert (abs(np.log(pooled.q_scale[0]) - np.log(10.0)) < 0.2
            and abs(np.log(pooled.r_scale[0][0]) - np.log(0.25)) < 0.1)


@pytest.mark.slow
def test_ml_diagonal_form_and_rss_sigma():
    rng = np.random.default_rng(9)
    channel = lb.PathLossModel(ref_power_dbm=-40.0, path_loss_exp=2.5, sigma_db=2.0, min_distance_m=1e-3)
    anchors = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    model, _, _, truth, _ = _cv_runs(rng, runs=2, T=200, q=0.01, missing=False)
    truth[..., :2] += 5.0
    d = np.linalg.norm(truth[..., None, :2] - anchors, axis=-1)
    sigma_true = np.array([1.0, 2.0, 3.0, 4.0])
    rss = channel.mean_rss_dbm(d) + rng.normal(0, 1.0, d.shape) * sigma_true
    meas = lb.RssMeasurement(rss, anchors, channel, position_index=np.array([0, 1]))
    fit = lb.fit_noise_ml(model.F, model.Q, np.broadcast_to([5.0, 5, 0, 0], (2, 4)), np.diag([1.0, 1, 0.1, 0.1]),
                          meas, kind="ekf", fit_Q=None, fit_R="diagonal", per_run=False)
    sigma = np.broadcast_to(fit.R[0], (4,))
    assert fit.q_scale is None
    # each anchor's sigma recovered within 15% (400 readings per anchor: the standard error of a sigma is ~3.5%)
    np.testing.assert_allclose(sigma, sigma_true, rtol=0.15)
    with pytest.raises(ValueError, match="one entry per stream"):
        lb.fit_noise_ml(model.F, model.Q, np.zeros(4), np.eye(4), meas, kind="ekf", fit_R=[[0, 1], [2, 3]])
    with pytest.raises(ValueError, match="nothing to fit"):
        lb.fit_noise_ml(model.F, model.Q, np.zeros(4), np.eye(4), meas, kind="ekf", fit_Q=None, fit_R=None)


# ---- the per-run damped Newton of fit_noise_ml on functions with a known answer -----------------------------------

def _newton(f, runs, p, **kw):
    from locbook.tracking.noise import _newton_per_run
    args = dict(lo=np.log(1e-4), hi=np.log(1e4), max_iter=200, tol=1e-10) | kw
    return _newton_per_run(f, runs, p, args["lo"], args["hi"], args["max_iter"], args["tol"])


def test_per_run_newton_finds_each_runs_interior_maximum():
    """Concave quadratics, one per run, with correlated axes: the maximiser solves the linear system exactly."""
    centre = np.array([[0.5, -1.0], [2.0, 0.3], [-3.0, 1.5]])
    C = np.array([[2.0, 0.8], [0.8, 1.0]])

    def f(theta):
        d = theta - centre
        return -0.5 * np.einsum("...i,ij,...j->...", d, C, d)
    theta, _ = _newton(f, (3,), 2)
    np.testing.assert_allclose(theta, centre, atol=1e-5)


def test_per_run_newton_climbs_a_flat_ridge_to_its_bound_and_stops_on_a_flat_top(monkeypatch):
    """Not concave: along the first axis the likelihood rises ever more slowly towards the upper bound (-exp(-theta),
    its maximum over the box is at the bound); along the second, log cosh has a flat-bottomed valley turned upside
    down (a smooth top). Each run must end at the bound and at its centre (scipy's bounded L-BFGS-B on the same
    function, run by run, is the reference), in fewer iterations than the damped step alone takes (the doubled steps
    cross the ridge)."""
    from scipy.optimize import minimize
    lo, hi = np.log(1e-4), np.log(1e4)
    centre = np.array([0.3, -2.0, 4.0, 1.0])

    def f(theta):
        return -np.exp(-theta[..., 0]) - np.log(np.cosh(theta[..., 1] - centre))
    theta, iterations = _newton(f, (4,), 2)
    for r in range(4):
        ref = minimize(lambda t: np.exp(-t[0]) + np.log(np.cosh(t[1] - centre[r])), np.zeros(2), method="L-BFGS-B",
                       bounds=[(lo, hi)] * 2, options={"ftol": 1e-15, "gtol": 1e-12})
        assert theta[r, 0] == pytest.approx(hi) and ref.x[0] == pytest.approx(hi)
        assert abs(theta[r, 1] - centre[r]) < 1e-4 and abs(ref.x[1] - centre[r]) < 1e-4
    from locbook.tracking import noise
    monkeypatch.setattr(noise, "_EXPAND", np.array([1.0]))               # the damped Newton step alone
    plain, plain_iterations = _newton(f, (4,), 2)
    np.testing.assert_allclose(plain, theta, atol=1e-4)
    assert iterations < plain_iterations


@pytest.mark.slow
@pytest.mark.parametrize("speed_mps, start", [(1.5, "rest"), (0.3, "moving")])
def test_per_run_noise_fit_converges_under_the_dogan_readings_that_broke_it(speed_mps, start, monkeypatch):
    """Dogan's per-run ML noise fit (100 runs) under two readings of the bracket: at 1.5 m/s the damping reached
    round-off (mu = -lambda_min exactly: 'Singular matrix'); from a moving start two runs crawled along a flat ridge
    and one oscillated by round-off on a flat top (ConvergenceError after 200 iterations). Every run now ends at a
    finite multiplier with a likelihood at least the hand-set one's (the steps only ever climb)."""
    from locbook.scenarios import dogan as dg
    room = [7.6, 9.2]
    path = dg.room_waypoints([[1.0, 1.0], [1.0, 8.2], [6.6, 8.2], [6.6, 1.0], [2.6, 1.0]], room)
    tr = dg.walk_trajectory(path, speed_mps, 0.05, start=start)
    from locbook.scenarios import dogan_protocol
    fits = []
    original = dogan_protocol.fit_noise_ml

    def keep(*a, **k):
        fits.append(original(*a, **k))
        return fits[-1]
    monkeypatch.setattr(dogan_protocol, "fit_noise_ml", keep)   # where noise_fit looks the name up
    ml = dg.noise_fit(tr, dg.SIGMA_RSS_DB, dg.PATH_LOSS_EXP, 100, lb.streams(2015, "noise_fit")["noise_fit"],
                      anchors_m=dg.corner_anchors(room), room_m=room)
    per_run = fits[-1]
    assert np.all(np.isfinite(ml["q_ml_runs"])) and np.asarray(ml["q_ml_runs"]).size == 100
    assert np.all(per_run.log_likelihood
                  >= per_run.initial_log_likelihood - 1e-9 * np.abs(per_run.initial_log_likelihood))


def test_a_pooled_fit_whose_line_search_ends_abnormal_at_the_optimum_is_accepted_and_a_real_failure_is_not(monkeypatch):
    """L-BFGS-B can end 'ABNORMAL' at the optimum (the central-difference gradient's round-off; the compiled and the
    numpy summation orders flip the flag at one point): one restart that cannot lower the objective confirms it and
    the fit equals the unforced one; a restart that keeps moving and fails is the error."""
    import scipy.optimize

    from locbook.errors import ConvergenceError
    rng = np.random.default_rng(8)
    model, H, _, truth, z = _cv_runs(rng, runs=4, T=80, q=0.05, r=0.5)
    meas = lb.LinearMeasurement(z, H, 2.0 * np.eye(2))
    args = (model.F, 0.1 * model.Q, np.zeros((4, 4)), np.eye(4), meas)
    plain = lb.fit_noise_ml(*args, per_run=False)
    real = scipy.optimize.minimize
    calls = []

    def abnormal_first(*a, **k):
        res = real(*a, **k)
        calls.append(res.fun)
        if len(calls) == 1:
            res.success, res.message = False, "ABNORMAL: "
        return res

    monkeypatch.setattr(scipy.optimize, "minimize", abnormal_first)
    fit = lb.fit_noise_ml(*args, per_run=False)
    assert len(calls) == 2
    np.testing.assert_allclose(fit.q_scale, plain.q_scale, rtol=1e-6)

    def always_abnormal_and_far(*a, **k):
        res = real(*a, **k)
        res.success, res.message = False, "ABNORMAL: "
        res.fun = res.fun - 1e3 if len(calls) % 2 else res.fun          # the restart still lowers it a lot
        calls.append(res.fun)
        return res

    calls.clear()
    monkeypatch.setattr(scipy.optimize, "minimize", always_abnormal_and_far)
    with pytest.raises(ConvergenceError, match="L-BFGS-B"):
        lb.fit_noise_ml(*args, per_run=False)


def test_fit_noise_ml_names_an_option_its_filter_kind_does_not_take():
    meas = lb.LinearMeasurement(np.ones((6, 2)), np.eye(2), np.eye(2))
    args = (np.eye(2), 0.01 * np.eye(2), np.zeros(2), np.eye(2), [meas])
    with pytest.raises(ValueError, match=r"^fit_noise_ml: the 'kf' filter has no option 'alpha': only kind='ukf'"):
        lb.fit_noise_ml(*args, kind="kf", alpha=0.5)
    with pytest.raises(ValueError, match=r"no option 'alpah': no filter kind takes it"):
        lb.fit_noise_ml(*args, kind="ukf", alpah=0.5)
