"""The fixed-lag smoother against the RTS smoother of truncated runs, the state-augmentation Kalman filter (an
independent oracle written here) and filterpy's FixedLagSmoother; its conventions, online form and input rules."""
import numpy as np
import pytest

import locbook as lb
from locbook.tracking.fixed_lag import OnlineFixedLagSmoother, fixed_lag_smoother

filterpy_kalman = pytest.importorskip("filterpy.kalman")

OUT = ("x_pred", "P_pred", "P_cross")


def _cv_case(seed, T=40, runs=3, missing=True):
    """A 2-D constant-velocity target, position readings with whole steps and single components missing, and
    a different start per run (so the runs' means differ)."""
    rng = np.random.default_rng(seed)
    model = lb.constant_velocity(0.5, 0.3, dim=2)
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    R = np.array([[0.8, 0.2], [0.2, 1.3]])
    truth = np.cumsum(rng.normal(0, 0.3, (runs, T, 2)), axis=1)
    z = truth + rng.normal(0, 1.0, (runs, T, 2))
    if missing:
        z[:, 7:10] = np.nan                         # three steps without a reading
        z[0, 4, 1] = np.nan                         # one component missing in one run
        z[1, 11, 0] = np.nan
    x0 = rng.normal(0, 1.0, (runs, 4))
    P0 = np.diag([4.0, 4.0, 1.0, 1.0])
    return model.F, model.Q, H, R, z, x0, P0


def _kf(F, Q, H, R, z, x0, P0):
    return lb.kalman_filter(F, Q, x0, P0, lb.LinearMeasurement(z, H, R), outputs=OUT)


def _augmented_oracle(F, Q, H, R, z, x0, P0, L):
    """x_{k-i|k} for i = 0..L at every k, by a plain Kalman filter on the state stacked with its L past copies
    (Anderson and Moore 1979, Sec. 7.3), one run at a time: block i of the augmented state at step k is x_{k-i} (x_0
    for k - i < 0: the start's copies, perfectly correlated). Predict first (filterpy's order), then update with the
    present components. Returns means (runs, T, L + 1, n) and covariances (runs, T, L + 1, n, n)."""
    runs, T, _ = z.shape
    n, A = F.shape[0], (L + 1) * F.shape[0]
    Fa = np.zeros((A, A))
    Fa[:n, :n] = F
    for i in range(1, L + 1):
        Fa[i * n:(i + 1) * n, (i - 1) * n:i * n] = np.eye(n)
    Qa = np.zeros((A, A))
    Qa[:n, :n] = Q
    Ha = np.hstack([H, np.zeros((H.shape[0], A - n))])
    means = np.empty((runs, T, L + 1, n))
    covs = np.empty((runs, T, L + 1, n, n))
    for r in range(runs):
        # step 0's prediction from (x0, P0); its copies start as that predicted state
        x1, P1 = F @ x0[r], F @ P0 @ F.T + Q
        xa, Pa = np.tile(x1, L + 1), np.tile(P1, (L + 1, L + 1))
        for k in range(T):
            if k > 0:
                xa, Pa = Fa @ xa, Fa @ Pa @ Fa.T + Qa
            ok = ~np.isnan(z[r, k])
            if ok.any():
                Hk, Rk = Ha[ok], R[np.ix_(ok, ok)]
                S = Hk @ Pa @ Hk.T + Rk
                K = np.linalg.solve(S, Hk @ Pa).T
                xa = xa + K @ (z[r, k, ok] - Hk @ xa)
                IKH = np.eye(A) - K @ Hk
                Pa = IKH @ Pa @ IKH.T + K @ Rk @ K.T
            means[r, k] = xa.reshape(L + 1, n)
            covs[r, k] = np.stack([Pa[i * n:(i + 1) * n, i * n:(i + 1) * n] for i in range(L + 1)])
    return means, covs


@pytest.mark.parametrize("lag", [1, 4])
def test_each_row_is_the_rts_smoother_of_the_run_truncated_at_its_last_reading(lag):
    F, Q, H, R, z, x0, P0 = _cv_case(1)
    T = z.shape[1]
    fl = fixed_lag_smoother(_kf(F, Q, H, R, z, x0, P0), lag)
    np.testing.assert_array_equal(fl.steps, np.arange(T))
    np.testing.assert_array_equal(fl.given_to, np.minimum(np.arange(T) + lag, T - 1))
    for k in (lag, lag + 3, 9, 16, 23, T - 2, T - 1):   # window ends around the missing readings and at the end
        short = lb.rts_smoother(_kf(F, Q, H, R, z[:, :k + 1], x0, P0))
        np.testing.assert_allclose(fl.mean[:, k - lag], short.mean[:, k - lag], rtol=0, atol=1e-10)
        np.testing.assert_allclose(fl.cov[:, k - lag], short.cov[:, k - lag], rtol=0, atol=1e-10)
    # the last `lag` rows are given every reading: the full-interval smoother's
    full = lb.rts_smoother(_kf(F, Q, H, R, z, x0, P0))
    np.testing.assert_allclose(fl.mean[:, T - lag:], full.mean[:, T - lag:], rtol=0, atol=1e-10)
    np.testing.assert_allclose(fl.cov[:, T - lag:], full.cov[:, T - lag:], rtol=0, atol=1e-10)


def test_lag_zero_is_the_filter_and_a_long_lag_the_full_smoother():
    F, Q, H, R, z, x0, P0 = _cv_case(2, T=25)
    run = _kf(F, Q, H, R, z, x0, P0)
    zero = fixed_lag_smoother(run, 0)
    np.testing.assert_array_equal(zero.mean, run.mean)
    np.testing.assert_array_equal(zero.cov, run.cov)
    np.testing.assert_array_equal(zero.given_to, np.arange(25))
    full = lb.rts_smoother(run)
    for lag in (24, 25, 10 ** 6):
        fl = fixed_lag_smoother(run, lag)
        np.testing.assert_allclose(fl.mean, full.mean, rtol=0, atol=1e-12)
        np.testing.assert_allclose(fl.cov, full.cov, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(fl.given_to, np.full(25, 24))
        assert fl.lag == lag
    # one step short of the whole run: only row 0 lacks the last reading, and it differs from the full smoother's
    fl = fixed_lag_smoother(run, 23)
    np.testing.assert_allclose(fl.mean[:, 1:], full.mean[:, 1:], rtol=0, atol=1e-12)
    assert np.abs(fl.mean[:, 0] - full.mean[:, 0]).max() > 1e-6


@pytest.mark.parametrize("lag", [2, 5])
def test_equals_the_state_augmentation_kalman_filter(lag):
    F, Q, H, R, z, x0, P0 = _cv_case(3, T=30)
    fl = fixed_lag_smoother(_kf(F, Q, H, R, z, x0, P0), lag, )
    means, covs = _augmented_oracle(F, Q, H, R, z, x0, P0, lag)
    T = z.shape[1]
    # rows j < T - lag: block `lag` of the augmented state at step j + lag
    np.testing.assert_allclose(fl.mean[:, :T - lag], means[:, lag:, lag], rtol=0, atol=1e-8)
    np.testing.assert_allclose(fl.cov[:, :T - lag], covs[:, lag:, lag], rtol=0, atol=1e-8)
    # the last rows: block i at the last step is x_{T-1-i|T-1}
    for i in range(lag):
        np.testing.assert_allclose(fl.mean[:, T - 1 - i], means[:, T - 1, i], rtol=0, atol=1e-8)
        np.testing.assert_allclose(fl.cov[:, T - 1 - i], covs[:, T - 1, i], rtol=0, atol=1e-8)


def test_without_p_cross_the_motion_f_gives_the_same_rows():
    F, Q, H, R, z, x0, P0 = _cv_case(4, T=20)
    run = lb.kalman_filter(F, Q, x0, P0, lb.LinearMeasurement(z, H, R), outputs=("x_pred", "P_pred"))
    a = fixed_lag_smoother(run, 3, F=F)
    b = fixed_lag_smoother(_kf(F, Q, H, R, z, x0, P0), 3)
    np.testing.assert_allclose(a.mean, b.mean, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.cov, b.cov, rtol=0, atol=1e-12)


def test_filterpy_fixed_lag_smoother_is_not_exact_where_ours_matches_the_oracle():
    """filterpy's FixedLagSmoother(N) on one run with every reading (it takes no missing one): its filter equals
    ours; its xSmooth[j] is meant to be x_{j|j+N-1} (it applies the readings of steps j .. j + N - 1), i.e. our lag
    N - 1. Past its start-up (rows j > N) it stays far from the exact answer, which the augmented oracle confirms."""
    lag, T = 4, 60
    F, Q, H, R, z, x0, P0 = _cv_case(5, T=T, runs=1, missing=False)
    run = _kf(F, Q, H, R, z, x0, P0)
    ours = fixed_lag_smoother(run, lag).mean[0]
    oracle = _augmented_oracle(F, Q, H, R, z, x0, P0, lag)[0][0, lag:, lag]
    np.testing.assert_allclose(ours[:T - lag], oracle, rtol=0, atol=1e-8)
    fls = filterpy_kalman.FixedLagSmoother(dim_x=4, dim_z=2, N=lag + 1)
    fls.x, fls.P, fls.F, fls.Q, fls.H, fls.R = x0[0].copy(), P0.copy(), F, Q, H, R
    theirs, filtered = fls.smooth_batch(list(z[0]), N=lag + 1)
    np.testing.assert_allclose(filtered, run.mean[0], rtol=0, atol=1e-9)
    rows = slice(lag + 2, T - lag)
    gap = np.abs(theirs[rows] - ours[rows]).max()
    gap_oracle = np.abs(theirs[rows] - oracle[rows]).max()
    print(f"filterpy FixedLagSmoother(N={lag + 1}) vs exact x_(j|j+{lag}): max |difference| {gap:.3g} "
          f"(vs the augmented oracle {gap_oracle:.3g}); the filter itself is "
          f"{np.abs(run.mean[0] - ours)[rows].max():.3g} "
          "from the exact answer")
    assert gap > 0.1 and gap_oracle > 0.1


def _pendulum_case(seed, T=50, runs=3):
    """Sarkka's (2013) pendulum: state (angle rad, angular rate rad/s), x_k = f(x_{k-1}) + w, reading sin(angle) + v;
    a few readings missing."""
    rng = np.random.default_rng(seed)
    dt, g = 0.05, 9.81
    f = lambda x: np.stack([x[..., 0] + dt * x[..., 1], x[..., 1] - dt * g * np.sin(x[..., 0])], axis=-1)

    def jac(x):
        J = np.zeros(x.shape + (2,))
        J[..., 0, 0], J[..., 0, 1] = 1.0, dt
        J[..., 1, 0], J[..., 1, 1] = -dt * g * np.cos(x[..., 0]), 1.0
        return J
    motion = lb.NonlinearMotion(f, jac)
    q = 0.3
    Q = q * np.array([[dt ** 3 / 3, dt ** 2 / 2], [dt ** 2 / 2, dt]])
    x = np.broadcast_to([1.2, 0.0], (runs, 2)).copy()
    z = np.empty((runs, T, 1))
    for k in range(T):
        x = f(x) + rng.multivariate_normal([0, 0], Q, runs)
        z[:, k, 0] = np.sin(x[:, 0]) + rng.normal(0, 0.3, runs)
    z[:, 20:24] = np.nan
    meas = lambda zz: lb.NonlinearMeasurement(zz, lambda s: np.sin(s[..., :1]), [[0.09]],
                                              lambda s: np.stack([np.cos(s[..., :1]), np.zeros(s.shape[:-1] + (1,))],
                                                                 axis=-1))
    x0 = np.broadcast_to([1.0, 0.0], (runs, 2))
    return motion, Q, x0, np.diag([0.5, 0.5]), z, meas


@pytest.mark.parametrize("kind", ["ekf", "ukf"])
def test_ekf_and_ukf_runs_are_smoothed_exactly(kind):
    motion, Q, x0, P0, z, meas = _pendulum_case(6)
    T = z.shape[1]
    filt = lb.extended_kalman_filter if kind == "ekf" else lb.unscented_kalman_filter
    run = filt(motion, Q, x0, P0, meas(z), outputs=OUT)
    full = lb.rts_smoother(run)
    for lag in (T - 1, T + 3):
        fl = fixed_lag_smoother(run, lag)
        np.testing.assert_allclose(fl.mean, full.mean, rtol=0, atol=1e-12)
        np.testing.assert_allclose(fl.cov, full.cov, rtol=0, atol=1e-12)
    lag = 6
    fl = fixed_lag_smoother(run, lag)
    assert np.isfinite(fl.mean).all() and np.isfinite(fl.cov).all()
    for k in (lag, 22, 27, T - 1):     # windows before, across and after the missing readings
        short = lb.rts_smoother(filt(motion, Q, x0, P0, meas(z[:, :k + 1]), outputs=OUT))
        np.testing.assert_allclose(fl.mean[:, k - lag], short.mean[:, k - lag], rtol=0, atol=1e-10)
        np.testing.assert_allclose(fl.cov[:, k - lag], short.cov[:, k - lag], rtol=0, atol=1e-10)


def test_a_residual_of_states_is_used_as_the_difference():
    F, Q, H, R, z, x0, P0 = _cv_case(7, T=20)
    run = _kf(F, Q, H, R, z, x0, P0)
    plain = fixed_lag_smoother(run, 3)
    calls = []

    def residual(a, b):
        calls.append(a.shape)
        return a - b
    fl = fixed_lag_smoother(run, 3, residual=residual)
    np.testing.assert_allclose(fl.mean, plain.mean, rtol=0, atol=1e-12)
    assert (3, 17, 4) in calls                      # called once per offset on every window of every run
    with pytest.raises(ValueError, match=r"residual\(a, b\) must return the states' shape"):
        fixed_lag_smoother(run, 3, residual=lambda a, b: (a - b)[..., :2])


def test_online_form_equals_the_batch_form():
    F, Q, H, R, z, x0, P0 = _cv_case(8, T=30)
    run = _kf(F, Q, H, R, z, x0, P0)
    lag = 4
    batch = fixed_lag_smoother(run, lag)
    online, rows = OnlineFixedLagSmoother(lag), []
    online_F = OnlineFixedLagSmoother(lag, F=F)     # the cross-covariances from F instead
    for k in range(30):
        out = online.update(run.mean[:, k], run.cov[:, k], run.x_pred[:, k], run.P_pred[:, k], run.P_cross[:, k])
        out_F = online_F.update(run.mean[:, k], run.cov[:, k], run.x_pred[:, k], run.P_pred[:, k])
        if k < lag:
            assert out is None and out_F is None
            continue
        rows.append(out)
        np.testing.assert_allclose(out_F[0], out[0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(np.stack([r[0] for r in rows], axis=-2), batch.mean[:, :30 - lag], rtol=0, atol=1e-10)
    np.testing.assert_allclose(np.stack([r[1] for r in rows], axis=-3), batch.cov[:, :30 - lag], rtol=0, atol=1e-10)
    tail = online.tail()
    np.testing.assert_array_equal(tail.steps, np.arange(30 - lag, 30))
    np.testing.assert_array_equal(tail.given_to, np.full(lag, 29))
    np.testing.assert_allclose(tail.mean, batch.mean[:, 30 - lag:], rtol=0, atol=1e-10)
    np.testing.assert_allclose(tail.cov, batch.cov[:, 30 - lag:], rtol=0, atol=1e-10)


def test_online_smoother_takes_the_online_filter_steps():
    F, Q, H, R, z, x0, P0 = _cv_case(9, T=15)
    batch = fixed_lag_smoother(_kf(F, Q, H, R, z, x0, P0), 2)
    filt = lb.OnlineFilter("kf", F, Q, x0, P0, outputs=OUT)
    online = OnlineFixedLagSmoother(2)
    got = [online.step(filt.step(lb.LinearMeasurement(z[:, k:k + 1], H, R))) for k in range(15)]
    assert got[0] is None and got[1] is None
    np.testing.assert_allclose(np.stack([g[0] for g in got[2:]], axis=-2), batch.mean[:, :13], rtol=0, atol=1e-9)
    # fewer steps than the lag: nothing returned, the tail is the full smoother of what was fed
    run5 = _kf(F, Q, H, R, z[:, :5], x0, P0)
    short = OnlineFixedLagSmoother(10)
    for k in range(5):
        assert short.update(run5.mean[:, k], run5.cov[:, k], run5.x_pred[:, k], run5.P_pred[:, k],
                            run5.P_cross[:, k]) is None
    tail = short.tail()
    np.testing.assert_array_equal(tail.steps, np.arange(5))
    np.testing.assert_allclose(tail.mean, lb.rts_smoother(run5).mean, rtol=0, atol=1e-10)


def test_short_and_empty_runs():
    F, Q, H, R, z, x0, P0 = _cv_case(10, T=12)
    one = _kf(F, Q, H, R, z[:, :1], x0, P0)
    for lag in (0, 3):
        fl = fixed_lag_smoother(one, lag)
        np.testing.assert_array_equal(fl.mean, one.mean)
        np.testing.assert_array_equal(fl.given_to, [0])
    none = _kf(F, Q, H, R, z[:, :0], x0, P0)
    fl = fixed_lag_smoother(none, 2)
    assert fl.mean.shape == (3, 0, 4) and fl.steps.shape == (0,) and fl.given_to.shape == (0,)
    # no run at all: the shapes of the empty batch
    zero = _kf(F, Q, H, R, z[:0], x0[:0], P0)
    assert fixed_lag_smoother(zero, 2).mean.shape == (0, 12, 4)


def test_bad_input_is_one_line_naming_it():
    F, Q, H, R, z, x0, P0 = _cv_case(11, T=12)
    run = _kf(F, Q, H, R, z, x0, P0)
    for lag in (-1, 2.5, "3", True, None, np.nan, np.inf, [2]):
        with pytest.raises(ValueError, match="^lag must") as info:
            fixed_lag_smoother(run, lag)
        assert "\n" not in str(info.value)
        with pytest.raises(ValueError, match="^lag must"):
            OnlineFixedLagSmoother(lag)
    bare = lb.kalman_filter(F, Q, x0, P0, lb.LinearMeasurement(z, H, R))
    with pytest.raises(ValueError, match=r"P_pred.*outputs=\('x_pred', 'P_pred', 'P_cross'\)"):
        fixed_lag_smoother(bare, 2)
    no_cross = lb.kalman_filter(F, Q, x0, P0, lb.LinearMeasurement(z, H, R), outputs=("x_pred", "P_pred"))
    with pytest.raises(ValueError, match="^fixed_lag_smoother needs the cross-covariances"):
        fixed_lag_smoother(no_cross, 2)
    every_other = lb.kalman_filter(F, Q, x0, P0, lb.LinearMeasurement(z, H, R), record=np.arange(0, 12, 2),
                                   outputs=OUT)
    with pytest.raises(ValueError, match="^fixed_lag_smoother needs every step recorded"):
        fixed_lag_smoother(every_other, 2)
    george = lb.kalman_filter(F, Q, x0, P0, lb.LinearMeasurement(z, H, R), variant="literal_george", outputs=OUT)
    with pytest.raises(ValueError, match="run of the corrected update"):
        fixed_lag_smoother(george, 2)
    with pytest.raises(TypeError, match="KalmanResult"):
        fixed_lag_smoother(run.mean, 2)
    online = OnlineFixedLagSmoother(2)
    online.update(run.mean[:, 0], run.cov[:, 0], run.x_pred[:, 0], run.P_pred[:, 0])
    with pytest.raises(ValueError, match="^P_cross is needed"):
        online.update(run.mean[:, 1], run.cov[:, 1], run.x_pred[:, 1], run.P_pred[:, 1])
    with pytest.raises(ValueError, match="^x must keep the shape"):
        online.update(run.mean[0, 1], run.cov[0, 1], run.x_pred[0, 1], run.P_pred[0, 1], run.P_cross[0, 1])
    with pytest.raises(ValueError, match="^P_pred must have shape"):
        online.update(run.mean[:, 1], run.cov[:, 1], run.x_pred[:, 1], run.P_pred[:, 1, :2], run.P_cross[:, 1])
    with pytest.raises(ValueError, match="^P must be finite"):
        online.update(run.mean[:, 1], run.cov[:, 1] * np.nan, run.x_pred[:, 1], run.P_pred[:, 1], run.P_cross[:, 1])
