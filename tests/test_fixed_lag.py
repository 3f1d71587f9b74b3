"""The fixed-lag smoother against the RTS smoother of truncated runs, the state-augmentation Kalman filter (an
independent oracle written here) and filterpy's FixedLagSmoother; its conventions, online form and input rules."""
import numpy as np
import pytest

import locbook as lb
from locbook.tracking.fixed_lag import FixedLagResult, OnlineFixedLagSmoother, fixed_lag_smoother

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
        z[0, 15, 1] = np.nan                        # one component missing in one run
        z[1, 17, 0] = np.nan
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
        np.testing.assert_allclose(fl.x[:, k - lag], short.x[:, k - lag], rtol=0, atol=1e-10)
        np.testing.assert_allclose(fl.P[:, k - lag], short.P[:, k - lag], rtol=0, atol=1e-10)
    # the last `lag` rows are given every reading: the full-interval smoother's
    full = lb.rts_smoother(_kf(F, Q, H, R, z, x0, P0))
    np.testing.assert_allclose(fl.x[:, T - lag:], full.x[:, T - lag:], rtol=0, atol=1e-10)
    np.testing.assert_allclose(fl.P[:, T - lag:], full.P[:, T - lag:], rtol=0, atol=1e-10)


def test_lag_zero_is_the_filter_and_a_long_lag_the_full_smoother():
    F, Q, H, R, z, x0, P0 = _cv_case(2, T=25)
    run = _kf(F, Q, H, R, z, x0, P0)
    zero = fixed_lag_smoother(run, 0)
    np.testing.assert_array_equal(zero.x, run.x)
    np.testing.assert_array_equal(zero.P, run.P)
    np.testing.assert_array_equal(zero.given_to, np.arange(25))
    full = lb.rts_smoother(run)
    for lag in (24, 25, 10 ** 6):
        fl = fixed_lag_smoother(run, lag)
        np.testing.assert_allclose(fl.x, full.x, rtol=0, atol=1e-12)
        np.testing.assert_allclose(fl.P, full.P, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(fl.given_to, np.full(25, 24))
        assert fl.lag == lag
    # one step short of the whole run: only row 0 lacks the last reading, and it differs from the full smoother's
    fl = fixed_lag_smoother(run, 23)
    np.testing.assert_allclose(fl.x[:, 1:], full.x[:, 1:], rtol=0, atol=1e-12)
    assert np.abs(fl.x[:, 0] - full.x[:, 0]).max() > 1e-6


@pytest.mark.parametrize("lag", [2, 5])
def test_equals_the_state_augmentation_kalman_filter(lag):
    F, Q, H, R, z, x0, P0 = _cv_case(3, T=30)
    fl = fixed_lag_smoother(_kf(F, Q, H, R, z, x0, P0), lag, )
    means, covs = _augmented_oracle(F, Q, H, R, z, x0, P0, lag)
    T = z.shape[1]
    # rows j < T - lag: block `lag` of the augmented state at step j + lag
    np.testing.assert_allclose(fl.x[:, :T - lag], means[:, lag:, lag], rtol=0, atol=1e-8)
    np.testing.assert_allclose(fl.P[:, :T - lag], covs[:, lag:, lag], rtol=0, atol=1e-8)
    # the last rows: block i at the last step is x_{T-1-i|T-1}
    for i in range(lag):
        np.testing.assert_allclose(fl.x[:, T - 1 - i], means[:, T - 1, i], rtol=0, atol=1e-8)
        np.testing.assert_allclose(fl.P[:, T - 1 - i], covs[:, T - 1, i], rtol=0, atol=1e-8)


def test_without_p_cross_the_motion_f_gives_the_same_rows():
    F, Q, H, R, z, x0, P0 = _cv_case(4, T=20)
    run = lb.kalman_filter(F, Q, x0, P0, lb.LinearMeasurement(z, H, R), outputs=("x_pred", "P_pred"))
    a = fixed_lag_smoother(run, 3, F=F)
    b = fixed_lag_smoother(_kf(F, Q, H, R, z, x0, P0), 3)
    np.testing.assert_allclose(a.x, b.x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(a.P, b.P, rtol=0, atol=1e-12)


def test_filterpy_fixed_lag_smoother_is_not_exact_where_ours_matches_the_oracle():
    """filterpy's FixedLagSmoother(N) on one run with every reading (it takes no missing one): its filter equals
    ours; its xSmooth[j] is meant to be x_{j|j+N-1} (it applies the readings of steps j .. j + N - 1), i.e. our lag
    N - 1. Past its start-up (rows j > N) it stays far from the exact answer, which the augmented oracle confirms."""
    lag, T = 4, 60
    F, Q, H, R, z, x0, P0 = _cv_case(5, T=T, runs=1, missing=False)
    run = _kf(F, Q, H, R, z, x0, P0)
    ours = fixed_lag_smoother(run, lag).x[0]
    oracle = _augmented_oracle(F, Q, H, R, z, x0, P0, lag)[0][0, lag:, lag]
    np.testing.assert_allclose(ours[:T - lag], oracle, rtol=0, atol=1e-8)
    fls = filterpy_kalman.FixedLagSmoother(dim_x=4, dim_z=2, N=lag + 1)
    fls.x, fls.P, fls.F, fls.Q, fls.H, fls.R = x0[0].copy(), P0.copy(), F, Q, H, R
    theirs, filtered = fls.smooth_batch(list(z[0]), N=lag + 1)
    np.testing.assert_allclose(filtered, run.x[0], rtol=0, atol=1e-9)
    rows = slice(lag + 2, T - lag)
    gap = np.abs(theirs[rows] - ours[rows]).max()
    gap_oracle = np.abs(theirs[rows] - oracle[rows]).max()
    print(f"filterpy FixedLagSmoother(N={lag + 1}) vs exact x_(j|j+{lag}): max |difference| {gap:.3g} "
          f"(vs the augmented oracle {gap_oracle:.3g}); the filter itself is {np.abs(run.x[0] - ours)[rows].max():.3g} "
          "from the exact answer")
    assert gap > 0.1 and gap_oracle > 0.1
