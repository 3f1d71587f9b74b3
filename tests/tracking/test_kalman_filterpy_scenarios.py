"""filterpy's own Kalman-family test scenarios, run through locbook's public API.

Each test builds the model and data of one scenario of rlabbe/filterpy's test suite (filterpy/kalman/tests/, master
3b51149; the data drawn from ``np.random.default_rng(seed)`` instead of the global RNG, several runs at once), runs
filterpy 2.0 exactly as its test does (the oracle, one run at a time), runs locbook on all the runs in one call
(``import locbook as lb`` only) and asserts the means and covariances (and, where filterpy gives them, the predictions,
Mahalanobis distances and log-likelihoods) equal. Tolerance: absolute 1e-9 on every mean and covariance (the gaps
measured are 0 to 6e-11, the largest on the radar UKF with P of 1e4 and ranges of 1e3), except
test_steadystate_standard_half (1e-9 of the largest entry; its docstring says why); Mahalanobis distances and
log-likelihoods relative 1e-9 or tighter.

Two behaviours of filterpy decide what locbook is given (each test's docstring): a scalar ``Q`` is added to every
entry of P by ``KalmanFilter.predict()`` and ``rts_smoother`` but is ``q I`` in ``batch_filter`` (test_noisy_1d,
test_kf_rts); the CubatureKalmanFilter updates with the points it propagated, without Q (test_ckf_1d).

Ported (filterpy test function -> test here):

- test_kf.py: test_noisy_1d and test_noisy_11d (update-then-predict loop, batch_filter, Mahalanobis, log-likelihood)
  -> test_noisy_1d; test_sequential_3d (update_sequential in four splits) -> test_sequential_3d; test_batch_filter
  (a missing first reading, both update orders) -> test_batch_filter_both_orders; test_univariate (with and without
  the control input it declares) -> test_univariate; test_procedure_form (the procedural predict/update, 2000 steps)
  -> test_procedure_form; test_procedural_batch_filter (lists of F, Q, H, R; missing readings) ->
  test_procedural_batch_filter; test_functions (predict with a control input, update, then pure predictions) ->
  test_functions; test_steadystate (order-5 kinematic filter of 42 states; its standard half, the first 40 steps,
  where float64 still resolves its covariance; docstring) -> test_steadystate_standard_half.
- test_ekf.py: test_ekf (radar range to an aircraft, update before predict, R a function of the state) ->
  test_ekf_radar.
- test_rts.py: test_rts (KF and its RTS smoother) -> test_kf_rts.
- test_ukf.py: test_radar (Julier points) -> test_ukf_radar; test_linear_2d_merwe and its rts_smoother ->
  test_ukf_linear_2d_merwe; test_linear_2d_simplex -> test_ukf_linear_2d_simplex (locbook has no simplex points: the
  model is linear, so every sigma-point set gives the Kalman filter; docstring); test_ukf_ekf_comparison and
  test_vhartman -> test_ukf_ekf_comparison_vhartman; test_linear_1d -> test_ukf_linear_1d; test_batch_missing_data ->
  test_ukf_batch_missing_data; test_rts and the full-run half of test_fixed_lag (unscented RTS, Julier kappa 1 and 0)
  -> test_ukf_rts; the window smoother of test_fixed_lag -> test_ukf_fixed_lag_window; test_circle (UKF
  and a 6-state KF on a circular track) -> test_ukf_circle; kf_circle and two_radar (filtering scenarios filterpy does
  not collect) -> test_kf_circle_polar, test_ukf_two_radar; test_linear_rts (KF against UKF, both smoothers) ->
  test_linear_rts; _test_log_likelihood (disabled in filterpy by its underscore; per-step log-likelihood) ->
  test_ukf_log_likelihood; test_julier_sigma_points_1D -> test_julier_sigma_points_1d (1e-12).
- test_ckf.py: test_1d -> test_ckf_1d (cubature points; equal to filterpy's CKF, whose update leaves Q out, because
  the scenario's Q does not reach the reading; a variant where it does is compared with filterpy's UKF with cubature
  points; docstring).
- test_sensor_fusion.py: test_fusion (one sensor, then two fused) and its __main__ variant (a GPS of noise 4e100) ->
  test_sensor_fusion.

Not ported: test_sigma_plot, test_scaled_weights (weights and a plot; the Merwe weights are checked against filterpy in
tests/tracking/test_unscented.py), test_simplex_sigma_points_1D/2D (locbook has no simplex sigma points), test_1d_vel (a
hand-written recursion that zeroes the covariance's off-diagonal before the gain: not a Kalman filter and not
filterpy's), test_z_dim, test_z_checks, test_default_dims (filterpy's handling of input shapes), test_update_correlated
(correlated process and measurement noise: locbook's filters take no cross-covariance M) and the steady-state half of
test_steadystate (a fixed gain: locbook's filters have no fixed-gain mode).
"""
import numpy as np
import pytest

import locbook as lb

filterpy_kalman = pytest.importorskip("filterpy.kalman")
filterpy_common = pytest.importorskip("filterpy.common")

ATOL = 1e-9


def _close(actual, desired):
    """Equal to 1e-9, absolute."""
    np.testing.assert_allclose(actual, desired, rtol=0.0, atol=ATOL)


def _cv(dt):
    return np.array([[1.0, dt], [0.0, 1.0]])


H_POS = np.array([[1.0, 0.0]])


# ---------------------------------------------------------------------------------------------------- test_kf.py

@pytest.mark.parametrize("column", [True, False])
def test_noisy_1d(column):
    """test_noisy_1d (``column``: x a column, as filterpy's test_noisy_1d) and test_noisy_11d (x flat).

    filterpy's test sets ``f.Q = 0.0001`` and ``f.R = 5``, scalars. filterpy reads a scalar Q two ways: ``predict()``
    adds it to *every* entry of P (the process covariance of the loop is ``1e-4 [[1, 1], [1, 1]]``, rank one), while
    ``batch_filter`` passes it to ``predict(Q=q)``, which makes it ``q I``; locbook is given each matrix. The loop
    updates before it predicts: locbook's ``predict_first=False`` run, whose ``x_pred`` of step k + 1 is filterpy's
    state after the predict of step k. Then filterpy's batch_filter (predict, then update) from P = 100 I:
    ``predict_first=True`` with Q = 1e-4 I."""
    rng = np.random.default_rng(101)
    runs, T = 4, 100
    zs = np.arange(T) + 20.0 * rng.standard_normal((runs, T))
    F, Q, R = _cv(1.0), 1e-4 * np.ones((2, 2)), np.array([[5.0]])
    x0 = np.broadcast_to([2.0, 0.0], (runs, 2))
    loop = lb.kalman_filter(F, Q, x0, 1000.0 * np.eye(2), lb.LinearMeasurement(zs[..., None], H_POS, R),
                            predict_first=False, outputs=("x_pred", "P_pred"))
    batch = lb.kalman_filter(F, 1e-4 * np.eye(2), x0, 100.0 * np.eye(2), lb.LinearMeasurement(zs[..., None], H_POS, R),
                             outputs=("x_pred", "P_pred"))
    for r in range(runs):
        f = filterpy_kalman.KalmanFilter(dim_x=2, dim_z=1)
        f.x = np.array([[2.0], [0.0]]) if column else np.array([2.0, 0.0])
        f.F, f.H = F.copy(), H_POS.copy()
        f.P *= 1000.0
        f.R, f.Q = 5, 0.0001
        for t in range(T):
            f.update(zs[r, t])
            _close(loop.mean[r, t], np.ravel(f.x))
            _close(loop.cov[r, t], f.P)
            assert np.sqrt(loop.nis[r, t]) == pytest.approx(f.mahalanobis, rel=1e-12)
            assert loop.log_likelihood[r, t] == pytest.approx(f.log_likelihood, rel=1e-12)
            f.predict()
            if t + 1 < T:
                _close(loop.x_pred[r, t + 1], np.ravel(f.x))
                _close(loop.P_pred[r, t + 1], f.P)
        f.x = np.array([[2.0, 0]]).T
        f.P = np.eye(2) * 100.0
        m, c, mp, cp = f.batch_filter(list(zs[r]), update_first=False)
        _close(batch.mean[r], np.reshape(m, (T, 2)))
        _close(batch.cov[r], c)
        _close(batch.x_pred[r], np.reshape(mp, (T, 2)))
        _close(batch.P_pred[r], cp)


def test_sequential_3d():
    """test_sequential_3d: three position readings of a 3-D constant-velocity target, applied at once (update), one at
    a time, and split 1 + 2 and 2 + 1 (update_sequential). locbook: one parallel stream, one serial stream, and two
    streams in the same splits; each equals its filterpy counterpart and all equal the parallel update."""
    from scipy.linalg import block_diag
    rng = np.random.default_rng(102)
    runs, N, dt = 3, 100, 0.02
    F1 = _cv(dt)
    F, H = block_diag(F1, F1, F1), block_diag(H_POS, H_POS, H_POS)
    q = filterpy_common.Q_discrete_white_noise(dim=2, dt=dt, var=0.0001)
    Q, R, P0 = block_diag(q, q, q), np.eye(3), np.eye(6)
    v = np.array([3.0, 4.0, 5.0])
    z = v * np.arange(N)[:, None] + 20.0 * rng.standard_normal((runs, N, 3))
    x0 = np.zeros((runs, 6))

    def run(streams):
        return lb.kalman_filter(F, Q, x0, P0, streams)

    def split(cut):                                  # two streams: readings [0, cut) then [cut, 3)
        return [lb.LinearMeasurement(z[..., a:b], H[a:b], R[a:b, a:b]) for a, b in ((0, cut), (cut, 3))]
    ours = {"a": run(lb.LinearMeasurement(z, H, R)), "b": run(lb.LinearMeasurement(z, H, R, mode="serial")),
            "c": run(split(1)), "d": run(split(2))}
    steps = {"a": None, "b": ((0, 1), (1, 2), (2, 3)), "c": ((0, 1), (1, 3)), "d": ((0, 2), (2, 3))}
    for r in range(runs):
        filters = {}
        for key in steps:
            f = filterpy_kalman.KalmanFilter(dim_x=6, dim_z=3)
            f.x, f.P, f.F, f.H, f.R, f.Q = np.zeros([6, 1]), P0.copy(), F, H, R, Q
            filters[key] = f
        for t in range(N):
            zt = z[r, t][:, None]
            for key, f in filters.items():
                f.predict()
                if steps[key] is None:
                    f.update(zt)
                else:
                    for a, b in steps[key]:
                        f.update_sequential(a, zt[a:b] if b - a > 1 else zt[a])
                _close(ours[key].mean[r, t], f.x[:, 0])
                _close(ours[key].cov[r, t], f.P)
                _close(ours[key].mean[r, t], ours["a"].mean[r, t])


def test_batch_filter_both_orders():
    """test_batch_filter: readings [None, 1, 2] (the first missing: NaN), batch_filter predicting first, then, from
    where that left the filter, updating first. Run 0 is the scenario's readings, the others random (the first
    missing as well). ``f.Q = 0.0001``, which batch_filter makes 1e-4 I (test_noisy_1d)."""
    rng = np.random.default_rng(103)
    runs = 3
    zs = np.vstack([[np.nan, 1.0, 2.0], np.hstack([np.full((runs - 1, 1), np.nan),
                                                   rng.normal(0, 3, (runs - 1, 2))])])
    F, Q, R = _cv(1.0), 1e-4 * np.eye(2), np.array([[5.0]])
    meas = lb.LinearMeasurement(zs[..., None], H_POS, R)
    first = lb.kalman_filter(F, Q, np.broadcast_to([2.0, 0.0], (runs, 2)), 1000.0 * np.eye(2), meas,
                             outputs=("x_pred", "P_pred"))
    second = lb.kalman_filter(F, Q, first.mean[:, -1], first.cov[:, -1], meas, predict_first=False,
                              outputs=("x_pred", "P_pred"))
    for r in range(runs):
        f = filterpy_kalman.KalmanFilter(dim_x=2, dim_z=1)
        f.x, f.F, f.H = np.array([2.0, 0]), F.copy(), H_POS.copy()
        f.P *= 1000.0
        f.R, f.Q = 5, 0.0001
        z = [None if np.isnan(v) else v for v in zs[r]]
        m, c, mp, cp = f.batch_filter(z, update_first=False)
        _close(first.mean[r], m)
        _close(first.cov[r], c)
        _close(first.x_pred[r], mp)
        _close(first.P_pred[r], cp)
        m, c, mp, cp = f.batch_filter(z, update_first=True)
        _close(second.mean[r], m)
        _close(second.cov[r], c)
        # updating first, filterpy's predictions are those after each step's update: locbook's of the next step
        _close(second.x_pred[r, 1:], mp[:-1])
        _close(second.P_pred[r, 1:], cp[:-1])


def test_univariate():
    """test_univariate: a 1-D random walk read directly, P = 50, Q = 0.02, R = 0.1, readings 0, 1, ..., 49. filterpy's
    test declares a control input (dim_u = 1, B = 1) but calls predict() without one (run 0); runs 1-2 give it a
    control ``u_k`` (filterpy's ``predict(u=u_k)``; locbook's ``B=``, ``u=``)."""
    rng = np.random.default_rng(104)
    runs, T = 3, 50
    u = np.vstack([np.zeros((1, T)), rng.normal(0, 1, (runs - 1, T))])[..., None]
    z = np.broadcast_to(np.arange(T, dtype=float)[:, None], (runs, T, 1))
    res = lb.kalman_filter([[1.0]], [[0.02]], np.zeros((runs, 1)), [[50.0]],
                           lb.LinearMeasurement(z, [[1.0]], [[0.1]]), B=[[1.0]], u=u)
    for r in range(runs):
        f = filterpy_kalman.KalmanFilter(dim_x=1, dim_z=1, dim_u=1)
        f.x = np.array([[0]])
        f.P *= 50
        f.H, f.F, f.B = np.array([[1.0]]), np.array([[1.0]]), np.array([[1.0]])
        f.Q = 0.02
        f.R *= 0.1
        for i in range(T):
            if r == 0:
                f.predict()                         # as filterpy's test: no control given
            else:
                f.predict(u=u[r, i])
            f.update(i)
            _close(res.mean[r, i], f.x[:, 0])
            _close(res.cov[r, i], f.P)


@pytest.mark.slow
def test_procedure_form():
    """test_procedure_form: a target moving 100 m per step read with noise 10.1 m for 2000 steps (positions to 2e5 m),
    filtered by filterpy's procedural predict/update (which its test checks against its class). The
    model is locbook's own constant-velocity model, whose F and Q are checked against filterpy's
    Q_discrete_white_noise first. Batched over runs, and, for the first 500 steps, one step at a time for all of them
    (lb.OnlineFilter)."""
    rng = np.random.default_rng(105)
    runs, T, std_z = 2, 2000, 10.1
    model = lb.constant_velocity(1.0, 5.1, dim=1)
    np.testing.assert_allclose(model.F, _cv(1.0), atol=1e-15)
    np.testing.assert_allclose(model.Q, filterpy_common.Q_discrete_white_noise(2, 1.0, 5.1), atol=1e-15)
    z = 100.0 * np.arange(T) + std_z * rng.standard_normal((runs, T))
    R = np.eye(1) * std_z**2
    x0 = np.zeros((runs, 2))
    res = lb.kalman_filter(model.F, model.Q, x0, np.eye(2), lb.LinearMeasurement(z[..., None], H_POS, R))
    online = lb.OnlineFilter("kf", model.F, model.Q, x0, np.eye(2))
    steps = [online.step(lb.LinearMeasurement(z[:, k:k + 1, None], H_POS, R)) for k in range(500)]
    _close(np.concatenate([s.mean for s in steps], axis=1), res.mean[:, :500])
    _close(np.concatenate([s.cov for s in steps], axis=1), res.cov[:, :500])
    for r in range(runs):
        x, P = np.array([[0.0], [0.0]]), np.eye(2)
        xs, Ps = [], []
        for t in range(T):
            x, P = filterpy_kalman.predict(x, P, model.F, model.Q)
            x, P, _, _, _, _ = filterpy_kalman.update(x, P, z[r, t], R, H_POS, True)
            xs.append(x[:, 0])
            Ps.append(P)
        _close(res.mean[r], xs)
        _close(res.cov[r], Ps)


def test_procedural_batch_filter():
    """test_procedural_batch_filter: readings [13, None, 1, 2] * 10 (run 0; runs 1-2 random with the same gaps),
    filterpy's class batch_filter and its procedural batch_filter with lists [F] * n, [Q] * n, [H] * n, [R] * n;
    locbook with constant matrices and with the same matrices per step (lb.per_step)."""
    rng = np.random.default_rng(106)
    runs = 3
    base = np.array([13.0, np.nan, 1.0, 2.0] * 10)
    zs = np.vstack([base, base + rng.normal(0, 2, (runs - 1, base.size))])
    n = base.size
    F, H, R = _cv(1.0), H_POS, np.eye(1) * 5
    Q = filterpy_common.Q_discrete_white_noise(2, 1.0, 0.0001)
    x0, P0 = np.broadcast_to([2.0, 0.0], (runs, 2)), np.eye(2) * 1000.0
    const = lb.kalman_filter(F, Q, x0, P0, lb.LinearMeasurement(zs[..., None], H, R))
    steps = lb.kalman_filter(lb.per_step(np.broadcast_to(F, (n, 2, 2))), lb.per_step(np.broadcast_to(Q, (n, 2, 2))),
                             x0, P0, lb.LinearMeasurement(zs[..., None], lb.per_step(np.broadcast_to(H, (n, 1, 2))),
                                                          lb.per_step(np.broadcast_to(R, (n, 1, 1)))))
    for r in range(runs):
        z = [None if np.isnan(v) else v for v in zs[r]]
        f = filterpy_kalman.KalmanFilter(dim_x=2, dim_z=1)
        f.x, f.F, f.H, f.P, f.R, f.Q = np.array([2.0, 0]), F, H, P0.copy(), R, Q
        m, c, _, _ = f.batch_filter(z, update_first=False)
        mp, cp, _, _ = filterpy_kalman.batch_filter(np.array([2.0, 0]), P0.copy(), z, [F] * n, [Q] * n, [H] * n,
                                                    [R] * n)
        for res in (const, steps):
            _close(res.mean[r], m)
            _close(res.cov[r], c)
            _close(res.mean[r], mp)
            _close(res.cov[r], cp)


def test_functions():
    """test_functions: filterpy's procedural predict with a control input (x = 10, P = 3, u = 1, Q = 4, B = 1), an
    update (z = 12, R = 12.25), then a 2-D state read once and predicted with F = I and then with a constant-velocity F
    after its velocity is set to 1 (the filterpy test's asserted values [1, 0], [2, 1], [3, 1] among them)."""
    x, P = filterpy_kalman.predict(x=10.0, P=3.0, u=1.0, Q=2.0**2)
    x, P = filterpy_kalman.update(x=x, P=P, z=12.0, R=3.5**2)
    res = lb.kalman_filter([[1.0]], [[4.0]], [10.0], [[3.0]], lb.LinearMeasurement([[12.0]], [[1.0]], [[12.25]]),
                           B=[[1.0]], u=[[1.0]])
    _close(res.mean[0], np.ravel(x))
    _close(res.cov[0], np.reshape(P, (1, 1)))
    assert res.mean[0, 0] == pytest.approx(11.0 + 7.0 / 19.25, abs=1e-12)      # the closed form: K = 7 / (7 + 12.25)

    H, Q0 = np.array([[1.0, 0]]), np.zeros((2, 2))
    x, P = filterpy_kalman.predict(x=np.array([1.0, 0]), P=np.eye(2), Q=Q0)
    x, P = filterpy_kalman.update(x, P, z=[1], R=np.array([[1.0]]), H=H)
    x1, P1 = filterpy_kalman.predict(x=x, P=P, Q=Q0)
    first = lb.kalman_filter(np.eye(2), Q0, [1.0, 0], np.eye(2), lb.LinearMeasurement([[1.0], [np.nan]], H, [[1.0]]))
    _close(first.mean[0], x)
    _close(first.cov[0], P)
    _close(first.mean[1], x1)
    _close(first.cov[1], P1)
    np.testing.assert_array_equal(first.mean, [[1.0, 0.0], [1.0, 0.0]])
    x1 = x1.copy()
    x1[1] = 1.0
    F = _cv(1.0)
    x2, P2 = filterpy_kalman.predict(x=x1, F=F, P=P1, Q=Q0)
    x3, P3 = filterpy_kalman.predict(x=x2, F=F, P=P2, Q=Q0)
    moving = lb.kalman_filter(F, Q0, x1, first.cov[1], lb.LinearMeasurement(np.full((2, 1), np.nan), H, [[1.0]]))
    _close(moving.mean, [x2, x3])
    _close(moving.cov, [P2, P3])
    np.testing.assert_array_equal(moving.mean, [[2.0, 1.0], [3.0, 1.0]])


def test_steadystate_standard_half():
    """test_steadystate, first half: filterpy's kinematic_kf(dim=7, order=5), a 42-state filter (seven axes of order
    5, Q = I, R = 1) reading the sum of the seven positions, velocity 1 on the first axis, readings 0, 1, 2, ...

    The model is numerically ill-posed: only the sum of the positions is observed, so P grows like k^11 on the
    unobservable combinations (1e12 at step 40, 2e16 at step 90) while the innovation variance S = H P H^T + R stays
    near 320, a difference of terms 1e14 times larger. From about step 50 both filters compute S from round-off:
    filterpy's P gets negative eigenvalues before step 100 (and with some numpy builds its S falls below 0, a negative
    variance), locbook stops with a SingularCovarianceError naming the step (asserted). So the first 40 steps are
    compared, x and P each to 1e-9 of its largest entry (x about 40, P 1e12; measured: 7e-11 and 1e-14 of it at step 40,
    the gap growing with the conditioning). The second half (predict_steadystate / update_steadystate, a frozen gain)
    has no counterpart in locbook, whose filters always compute the gain from P."""
    cv = filterpy_common.kinematic_kf(dim=7, order=5)
    cv.x[1] = 1.0
    x0, F, H, Q, R, P0 = cv.x[:, 0].copy(), cv.F.copy(), cv.H.copy(), cv.Q.copy(), cv.R.copy(), cv.P.copy()
    T, compared = 100, 40
    res = lb.kalman_filter(F, Q, x0, P0, lb.LinearMeasurement(np.arange(compared, dtype=float)[:, None], H, R))
    S, low = [], []
    for i in range(T):
        cv.predict()
        cv.update([i])
        S.append(cv.S[0, 0])
        low.append(np.linalg.eigvalsh(0.5 * (cv.P + cv.P.T)).min())
        if i < compared:
            np.testing.assert_allclose(res.mean[i], cv.x[:, 0], rtol=0, atol=ATOL * np.abs(cv.x).max())
            np.testing.assert_allclose(res.cov[i], cv.P, rtol=0, atol=ATOL * np.abs(cv.P).max())
    assert np.abs(res.cov[-1]).max() > 1e12                  # the unobservable combinations did grow
    # filterpy's covariance from round-off: negative eigenvalues (and, with some numpy builds, a negative S)
    assert min(low) < 0 or min(S) < 0
    with pytest.raises(lb.SingularCovarianceError, match="at step"):
        lb.kalman_filter(F, Q, x0, P0, lb.LinearMeasurement(np.arange(T, dtype=float)[:, None], H, R))


# ---------------------------------------------------------------------------------------------------- test_ekf.py

def _radar_ranges(rng, runs, T, dt, process_err_pct=0.05):
    """filterpy's RadarSim (filterpy.examples and test_ukf.py): an aircraft at 1000 m altitude flying at 100 m/s, speed
    and altitude jittered by 5 and 10 at each call, the slant range read with an error of 5 % of the position."""
    vel = 100.0 + 5.0 * rng.standard_normal((runs, T))
    alt = 1000.0 + 10.0 * rng.standard_normal((runs, T))
    pos = np.cumsum(vel * dt, axis=-1)
    return np.sqrt(pos**2 + alt**2) + pos * process_err_pct * rng.standard_normal((runs, T))


def _slant_range(x):
    return np.sqrt(x[..., 0:1] ** 2 + x[..., 2:3] ** 2)


def _slant_range_jacobian(x):
    d = _slant_range(x)[..., 0]
    H = np.zeros(x.shape[:-1] + (1, 3))
    H[..., 0, 0], H[..., 0, 2] = x[..., 0] / d, x[..., 2] / d
    return H


@pytest.mark.slow
def test_ekf_radar():
    """test_ekf: horizontal distance, speed and altitude of an aircraft from its slant range, 400 steps of 0.05 s. The
    loop updates before it predicts, with ``R = 0.05 h(x)`` at the state it updates (a noise growing with the range):
    locbook's ``predict_first=False`` run with R a function of the state; filterpy's state after each predict is
    locbook's ``x_pred`` of the next step."""
    rng = np.random.default_rng(201)
    runs, dt, err = 3, 0.05, 0.05
    T = int(20 / dt)
    z = _radar_ranges(rng, runs, T, dt)
    F = np.eye(3) + np.array([[0, 1, 0], [0, 0, 0], [0, 0, 0]]) * dt
    Q = np.array([[0, 0, 0], [0, 1, 0], [0, 0, 1]]) * 0.001
    x0 = np.array([-10.0, 90.0, 1100.0])
    meas = lb.NonlinearMeasurement(z[..., None], _slant_range, lambda x: (err * _slant_range(x))[..., None],
                                   _slant_range_jacobian, name="slant range")
    res = lb.extended_kalman_filter(F, Q, np.broadcast_to(x0, (runs, 3)), 50.0 * np.eye(3), meas,
                                    predict_first=False, outputs=("x_pred", "P_pred"))

    def H_of(x):
        denom = np.sqrt(x[0] ** 2 + x[2] ** 2)
        return np.array([[x[0] / denom, 0.0, x[2] / denom]])

    def hx(x):
        return np.sqrt(x[0] ** 2 + x[2] ** 2)

    for r in range(runs):
        rk = filterpy_kalman.ExtendedKalmanFilter(dim_x=3, dim_z=1)
        rk.F, rk.x, rk.Q = F.copy(), x0.copy(), Q.copy()
        rk.R *= 10
        rk.P *= 50
        for i in range(T):
            rk.update(np.asarray([z[r, i]]), H_of, hx, R=hx(rk.x) * err)
            _close(res.mean[r, i], rk.x)
            _close(res.cov[r, i], rk.P)
            assert np.sqrt(res.nis[r, i]) == pytest.approx(rk.mahalanobis, rel=1e-9)
            assert res.log_likelihood[r, i] == pytest.approx(rk.log_likelihood, rel=1e-9)
            rk.predict()
            if i + 1 < T:
                _close(res.x_pred[r, i + 1], rk.x)
                _close(res.P_pred[r, i + 1], rk.P)


# ---------------------------------------------------------------------------------------------------- test_rts.py

def test_kf_rts():
    """test_rts (test_rts.py): x0 = (-1, 1), ``fk.P = .01``, ``fk.Q = 0.001``, ``fk.R = 5``, 40 readings t + 4 N(0, 1);
    batch_filter then rts_smoother (means, covariances, gains and predicted covariances).

    The scalars: ``F P F^T`` with the scalar P is 0.01 F F^T, i.e. P0 = 0.01 I; batch_filter makes the scalar Q 0.001 I
    (test_noisy_1d), but filterpy's rts_smoother adds it to every entry of ``F P F^T`` (its ``Pp``), i.e. smooths with
    Q = 0.001 [[1, 1], [1, 1]], not the filter's Q. locbook's smoother uses the run's own predictions, so it is
    compared with filterpy's rts_smoother given the filter's Q (``Qs=[0.001 I] * n``); filterpy's default call is
    checked to differ (the smoother of another model)."""
    rng = np.random.default_rng(301)
    runs, T = 4, 40
    zs = np.arange(T) + 4.0 * rng.standard_normal((runs, T))
    F, Q = _cv(1.0), 0.001 * np.eye(2)
    res = lb.kalman_filter(F, Q, np.broadcast_to([-1.0, 1.0], (runs, 2)), 0.01 * np.eye(2),
                           lb.LinearMeasurement(zs[..., None], H_POS, [[5.0]]), outputs=("x_pred", "P_pred", "P_cross"))
    smooth = lb.rts_smoother(res)
    for r in range(runs):
        fk = filterpy_kalman.KalmanFilter(dim_x=2, dim_z=1)
        fk.x, fk.F, fk.H = np.array([-1.0, 1.0]), F.copy(), H_POS.copy()
        fk.P, fk.R, fk.Q = 0.01, 5, 0.001
        mu, cov, _, _ = fk.batch_filter(list(zs[r]))
        M, P, K, Pp = fk.rts_smoother(mu, cov, Qs=[Q] * T)
        assert np.abs(fk.rts_smoother(mu, cov)[0] - M).max() > 1e-3      # the scalar Q read as 0.001 [[1, 1], [1, 1]]
        _close(res.mean[r], mu)
        _close(res.cov[r], cov)
        _close(smooth.mean[r], M)
        _close(smooth.cov[r], P)
        _close(smooth.gain[r], K[:-1])
        _close(res.P_pred[r, 1:], Pp[:-1])


# ---------------------------------------------------------------------------------------------------- test_ukf.py

RADAR_F = np.eye(3) + 0.05 * np.array([[0, 1, 0], [0, 0, 0], [0, 0, 0]])


def _radar_motion():
    return lb.NonlinearMotion(lambda x: x @ RADAR_F.T, name="radar motion")


@pytest.mark.slow
def test_ukf_radar():
    """test_radar (test_ukf.py): the radar scenario through the UKF with Julier's points, kappa = 0, 401 steps,
    predict then update; Q = 0.01 I, R = 10, x0 = (0, 90, 1100), P0 = 100 I; the Mahalanobis distance of each update.
    Motion by sigma points through fx (lb.NonlinearMotion) and by the linear F (exact): both equal filterpy."""
    rng = np.random.default_rng(401)
    runs, dt = 3, 0.05
    T = len(np.arange(0, 20 + dt, dt))
    z = _radar_ranges(rng, runs, T, dt)
    x0, P0, Q = np.broadcast_to([0.0, 90.0, 1100.0], (runs, 3)), 100.0 * np.eye(3), 0.01 * np.eye(3)
    meas = lb.NonlinearMeasurement(z[..., None], _slant_range, [[10.0]], name="slant range")
    sigma = lb.unscented_kalman_filter(_radar_motion(), Q, x0, P0, meas, points="julier", kappa=0.0)
    linear = lb.unscented_kalman_filter(RADAR_F, Q, x0, P0, meas, points="julier", kappa=0.0)
    for r in range(runs):
        sp = filterpy_kalman.JulierSigmaPoints(n=3, kappa=0.0)
        kf = filterpy_kalman.UnscentedKalmanFilter(3, 1, dt, fx=lambda x, dt: RADAR_F.dot(x),
                                                   hx=lambda x: [np.sqrt(x[0] ** 2 + x[2] ** 2)], points=sp)
        kf.Q *= 0.01
        kf.R = 10
        kf.x = np.array([0.0, 90.0, 1100.0])
        kf.P *= 100.0
        for i in range(T):
            kf.predict()
            kf.update(z=[z[r, i]])
            for res in (sigma, linear):
                _close(res.mean[r, i], kf.x)
                _close(res.cov[r, i], kf.P)
            assert np.sqrt(sigma.nis[r, i]) == pytest.approx(kf.mahalanobis, rel=1e-9)


def _cv2d(dt):
    return np.array([[1, dt, 0, 0], [0, 1, 0, 0], [0, 0, 1, dt], [0, 0, 0, 1]], dtype=float)


H_2D = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])


def _fp_ukf_2d(dt, points, x0, P0):
    kf = filterpy_kalman.UnscentedKalmanFilter(dim_x=4, dim_z=2, dt=dt, fx=lambda x, dt: _cv2d(dt) @ x,
                                               hx=lambda x: np.array([x[0], x[2]]), points=points)
    kf.x, kf.P = np.array(x0, dtype=float), np.array(P0, dtype=float)
    return kf


def test_ukf_linear_2d_merwe():
    """test_linear_2d_merwe: a 2-D constant-velocity target read in position, 20 steps of 0.1, Merwe points (0.1, 2,
    -1), x0 = (-1, 1, -1, 1), P0 = 1.1 I, Q = R = I (filterpy's defaults); batch_filter and the unscented
    rts_smoother. locbook: the UKF with fx as an lb.NonlinearMotion and a nonlinear reading h, and lb.rts_smoother."""
    rng = np.random.default_rng(402)
    runs, T, dt = 3, 20, 0.1
    zs = np.arange(T)[:, None] + 0.1 * rng.standard_normal((runs, T, 2))
    F = _cv2d(dt)
    x0 = np.broadcast_to([-1.0, 1, -1, 1], (runs, 4))
    res = lb.unscented_kalman_filter(lb.NonlinearMotion(lambda x: x @ F.T), np.eye(4), x0, 1.1 * np.eye(4),
                                     lb.NonlinearMeasurement(zs, lambda x: x[..., [0, 2]], np.eye(2)),
                                     alpha=0.1, beta=2.0, kappa=-1.0, outputs=("x_pred", "P_pred", "P_cross"))
    smooth = lb.rts_smoother(res)
    for r in range(runs):
        kf = _fp_ukf_2d(dt, filterpy_kalman.MerweScaledSigmaPoints(4, 0.1, 2.0, -1), [-1.0, 1, -1, 1], np.eye(4) * 1.1)
        Ms, Ps = kf.batch_filter(list(zs[r]))
        smooth_x, smooth_P, _ = kf.rts_smoother(Ms, Ps, dts=dt)
        _close(res.mean[r], Ms)
        _close(res.cov[r], Ps)
        _close(smooth.mean[r], smooth_x)
        _close(smooth.cov[r], smooth_P)


def test_ukf_linear_2d_simplex():
    """test_linear_2d_simplex: the same model from P0 = 1e-4 I, readings of a noise-free constant-velocity track
    (x_k = F x_{k-1} from x0) with noise 0.1, filterpy's UKF with simplex points (n + 1 of them) and its smoother.
    locbook has no simplex points; the model is linear, so any sigma-point set that reproduces the mean and covariance
    gives the Kalman filter's numbers (the unscented transform is exact on linear functions), and locbook's UKF (Merwe
    points) and KF with its RTS smoother are compared to filterpy's simplex run on that ground."""
    rng = np.random.default_rng(403)
    runs, T, dt = 3, 20, 0.1
    F = _cv2d(dt)
    x, truth = np.array([-1.0, 1.0, -1.0, 1]), []
    for _ in range(T):
        x = F @ x
        truth.append(x[[0, 2]])
    zs = np.array(truth) + 0.1 * rng.standard_normal((runs, T, 2))
    x0, P0 = np.broadcast_to([-1.0, 1, -1, 1], (runs, 4)), 1e-4 * np.eye(4)
    meas = lb.LinearMeasurement(zs, H_2D, np.eye(2))
    outs = ("x_pred", "P_pred", "P_cross")
    kf_run = lb.kalman_filter(F, np.eye(4), x0, P0, meas, outputs=outs)
    ukf_run = lb.unscented_kalman_filter(lb.NonlinearMotion(lambda x: x @ F.T), np.eye(4), x0, P0, meas, alpha=0.5,
                                         outputs=outs)
    for r in range(runs):
        kf = _fp_ukf_2d(dt, filterpy_kalman.SimplexSigmaPoints(n=4), [-1.0, 1.0, -1.0, 1], np.eye(4) * 0.0001)
        Ms, Ps = kf.batch_filter(list(zs[r]))
        smooth_x, smooth_P, _ = kf.rts_smoother(Ms, Ps, dts=dt)
        for run in (kf_run, ukf_run):
            _close(run.mean[r], Ms)
            _close(run.cov[r], Ps)
            smooth = lb.rts_smoother(run)
            _close(smooth.mean[r], smooth_x)
            _close(smooth.cov[r], smooth_P)


def test_ukf_ekf_comparison_vhartman():
    """test_ukf_ekf_comparison and test_vhartman (filterpy issue 172): a 1-D random walk, P0 = Q = R = 1, 50 readings
    N(0, 1), filterpy's UKF (Merwe points alpha = 1, beta = 2, kappa = 0.1) and EKF, which the tests check against each
    other after every predict and update. locbook's UKF, EKF and KF, each after every step, and the UKF and EKF
    priors."""
    rng = np.random.default_rng(404)
    runs, T = 3, 50
    zs = rng.standard_normal((runs, T, 1))
    x0, outs = np.zeros((runs, 1)), ("x_pred", "P_pred")
    ukf_run = lb.unscented_kalman_filter([[1.0]], [[1.0]], x0, [[1.0]],
                                         lb.NonlinearMeasurement(zs, lambda x: x[..., :1], np.diag([1.0])),
                                         alpha=1.0, beta=2.0, kappa=0.1, outputs=outs)
    ekf_run = lb.extended_kalman_filter([[1.0]], [[1.0]], x0, [[1.0]],
                                        lb.NonlinearMeasurement(zs, lambda x: x[..., :1], np.diag([1.0]),
                                                                lambda x: np.ones(x.shape[:-1] + (1, 1))),
                                        outputs=outs)
    kf_run = lb.kalman_filter([[1.0]], [[1.0]], x0, [[1.0]], lb.LinearMeasurement(zs, [[1.0]], [[1.0]]))
    for r in range(runs):
        points = filterpy_kalman.MerweScaledSigmaPoints(1, alpha=1, beta=2.0, kappa=0.1)
        ukf = filterpy_kalman.UnscentedKalmanFilter(dim_x=1, dim_z=1, dt=1.0, points=points,
                                                    fx=lambda x, dt: np.dot(np.array([[1.0]], dtype=np.float32), x),
                                                    hx=lambda x: np.array([x[0]]))
        ukf.x, ukf.P, ukf.R, ukf.Q = np.array([0.0]), np.array([[1]]), np.diag([1]), np.diag([1])
        ekf = filterpy_kalman.ExtendedKalmanFilter(dim_x=1, dim_z=1)
        ekf.F = np.array([[1]])
        ekf.x, ekf.P, ekf.R, ekf.Q = np.array([0.0]), np.array([[1]]), np.diag([1]), np.diag([1])
        for k in range(T):
            ukf.predict()
            ekf.predict()
            for run in (ukf_run, ekf_run):
                _close(run.x_pred[r, k], ukf.x)
                _close(run.P_pred[r, k], ukf.P)
            _close(ekf_run.P_pred[r, k], ekf.P)
            ukf.update(list(zs[r, k]))
            ekf.update(list(zs[r, k]), lambda x: np.array([[1]]), lambda x: np.array([x[0]]))
            for run in (ukf_run, ekf_run, kf_run):
                _close(run.mean[r, k], ukf.x)
                _close(run.cov[r, k], ukf.P)
                _close(run.mean[r, k], np.ravel(ekf.x))
                _close(run.cov[r, k], ekf.P)


def test_ukf_linear_1d():
    """test_linear_1d: a 1-D constant-velocity target, Merwe points (0.1, 2, -1), x0 = (1, 2), P0 = [[1, 1.1], [1.1,
    3]], R = 0.05, Q = [[0, 0], [0, 0.001]] (singular), one reading 2 then 50 readings i + 0.1 N(0, 1)."""
    rng = np.random.default_rng(405)
    runs, dt = 3, 0.1
    zs = np.concatenate([np.full((runs, 1), 2.0), np.arange(50) + 0.1 * rng.standard_normal((runs, 50))], axis=1)
    F, P0, Q = _cv(dt), np.array([[1, 1.1], [1.1, 3]]), np.array([[0.0, 0], [0.0, 0.001]])
    res = lb.unscented_kalman_filter(lb.NonlinearMotion(lambda x: x @ F.T), Q, np.broadcast_to([1.0, 2.0], (runs, 2)),
                                     P0, lb.NonlinearMeasurement(zs[..., None], lambda x: x[..., :1], [[0.05]]),
                                     alpha=0.1, beta=2.0, kappa=-1.0)
    for r in range(runs):
        kf = filterpy_kalman.UnscentedKalmanFilter(dim_x=2, dim_z=1, dt=dt, fx=lambda x, dt: _cv(dt) @ x,
                                                   hx=lambda x: np.array([x[0]]),
                                                   points=filterpy_kalman.MerweScaledSigmaPoints(2, 0.1, 2.0, -1))
        kf.x, kf.P, kf.Q = np.array([1, 2]), P0.copy(), Q.copy()
        kf.R *= 0.05
        for k in range(zs.shape[1]):
            kf.predict()
            kf.update(np.array([zs[r, k]]))
            _close(res.mean[r, k], kf.x)
            _close(res.cov[r, k], kf.P)


def test_ukf_batch_missing_data():
    """test_batch_missing_data: the 2-D model of test_linear_2d_merwe from P0 = 1e-4 I, 20 readings with the third
    missing (None in filterpy's batch_filter, a NaN step in locbook: prediction only)."""
    rng = np.random.default_rng(406)
    runs, T, dt = 3, 20, 0.1
    zs = np.arange(T)[:, None] + 0.1 * rng.standard_normal((runs, T, 2))
    zs[:, 2] = np.nan
    F = _cv2d(dt)
    res = lb.unscented_kalman_filter(lb.NonlinearMotion(lambda x: x @ F.T), np.eye(4),
                                     np.broadcast_to([-1.0, 1, -1, 1], (runs, 4)), 1e-4 * np.eye(4),
                                     lb.NonlinearMeasurement(zs, lambda x: x[..., [0, 2]], np.eye(2)),
                                     alpha=0.1, beta=2.0, kappa=-1.0)
    for r in range(runs):
        kf = _fp_ukf_2d(dt, filterpy_kalman.MerweScaledSigmaPoints(4, 0.1, 2.0, -1), [-1.0, 1, -1, 1],
                        np.eye(4) * 0.0001)
        Ms, Ps = kf.batch_filter([None if np.isnan(z).any() else z for z in zs[r]])
        _close(res.mean[r], Ms)
        _close(res.cov[r], Ps)


@pytest.mark.slow
@pytest.mark.parametrize("kappa", [1.0, 0.0])
def test_ukf_rts(kappa):
    """test_rts (test_ukf.py; Julier kappa = 1) and the full-run half of test_fixed_lag (Julier kappa = 0): the radar
    scenario, 401 steps, filterpy's loop (predict, update), its batch_filter (asserted equal to the loop, as its test
    does) and its unscented rts_smoother with ``Qs = [Q] * n``; locbook's UKF with fx as an lb.NonlinearMotion and
    lb.rts_smoother."""
    rng = np.random.default_rng(407 + int(kappa))
    runs, dt = 3, 0.05
    T = len(np.arange(0, 20 + dt, dt))
    z = _radar_ranges(rng, runs, T, dt)
    x0 = np.broadcast_to([0.0, 90.0, 1100.0], (runs, 3))
    res = lb.unscented_kalman_filter(_radar_motion(), 0.01 * np.eye(3), x0, 100.0 * np.eye(3),
                                     lb.NonlinearMeasurement(z[..., None], _slant_range, [[10.0]]), points="julier",
                                     kappa=kappa, outputs=("x_pred", "P_pred", "P_cross"))
    smooth = lb.rts_smoother(res)
    for r in range(runs):
        kf = filterpy_kalman.UnscentedKalmanFilter(3, 1, dt, fx=lambda x, dt: RADAR_F.dot(x),
                                                   hx=lambda x: [np.sqrt(x[0] ** 2 + x[2] ** 2)],
                                                   points=filterpy_kalman.JulierSigmaPoints(n=3, kappa=kappa))
        kf.Q *= 0.01
        kf.R = 10
        kf.x = np.array([0.0, 90.0, 1100.0])
        kf.P *= 100.0
        xs = np.zeros((T, 3))
        for i in range(T):
            kf.predict()
            kf.update(z=[z[r, i]])
            xs[i] = kf.x
        kf.x, kf.P = np.array([0.0, 90.0, 1100.0]), np.eye(3) * 100.0
        M, P = kf.batch_filter(list(z[r]))
        assert np.array_equal(M, xs)
        M2, P2, _ = kf.rts_smoother(Xs=M, Ps=P, Qs=[kf.Q] * T)
        _close(res.mean[r], M)
        _close(res.cov[r], P)
        _close(smooth.mean[r], M2)
        _close(smooth.cov[r], P2)


def test_ukf_fixed_lag_window():
    """test_fixed_lag, its window: the radar UKF (Julier kappa = 0, P0 = I) and, at step 20, filterpy's rts_smoother on
    the last 10 filtered states only. locbook: the filter over the whole track, then the same window filtered from the
    posterior of step 10 (the same numbers as the whole run's) and smoothed by lb.rts_smoother."""
    rng = np.random.default_rng(409)
    runs, dt, N, i_at = 3, 0.05, 10, 20
    T = len(np.arange(0, 20 + dt, dt))
    z = _radar_ranges(rng, runs, T, dt)
    Q, meas = 0.01 * np.eye(3), lambda zz: lb.NonlinearMeasurement(zz[..., None], _slant_range, [[10.0]])
    full = lb.unscented_kalman_filter(_radar_motion(), Q, np.broadcast_to([0.0, 90.0, 1100.0], (runs, 3)), np.eye(3),
                                      meas(z), points="julier", kappa=0.0)
    start = i_at - N                                    # the window is steps start + 1 .. i_at
    window = lb.unscented_kalman_filter(_radar_motion(), Q, full.mean[:, start], full.cov[:, start],
                                        meas(z[:, start + 1:i_at + 1]), points="julier", kappa=0.0,
                                        outputs=("x_pred", "P_pred", "P_cross"))
    _close(window.mean, full.mean[:, start + 1:i_at + 1])
    smooth = lb.rts_smoother(window)
    for r in range(runs):
        kf = filterpy_kalman.UnscentedKalmanFilter(3, 1, dt, fx=lambda x, dt: RADAR_F.dot(x),
                                                   hx=lambda x: [np.sqrt(x[0] ** 2 + x[2] ** 2)],
                                                   points=filterpy_kalman.JulierSigmaPoints(n=3, kappa=0))
        kf.Q *= 0.01
        kf.R = 10
        kf.x = np.array([0.0, 90.0, 1100.0])
        kf.P *= 1.0
        M, P = [], []
        for i in range(i_at + 1):
            kf.predict()
            kf.update(z=[z[r, i]])
            M.append(kf.x)
            P.append(kf.P)
        _close(full.mean[r, :i_at + 1], M)
        M2, P2, _ = kf.rts_smoother(Xs=np.asarray(M)[-N:], Ps=np.asarray(P)[-N:])
        _close(smooth.mean[r], M2)
        _close(smooth.cov[r], P2)


def _polar_to_xy_deg(x):
    """test_circle's hx: (radius, angle in degrees, ...) to (x, y)."""
    a = np.radians(x[..., 1])
    return np.stack([np.cos(a) * x[..., 0], np.sin(a) * x[..., 0]], axis=-1)


@pytest.mark.slow
def test_ukf_circle():
    """test_circle: a target on a circle of radius 50 (1/30 degree per step) read in x, y with noise 0.1, tracked by a
    UKF in polar coordinates (radius, angle, angular rate; Julier kappa = 0; Q = 0.001 on the angle only) and by a
    6-state constant-acceleration KF in x, y. filterpy's 12000 steps are cut to 2000 (a sixth of the time, 67 degrees
    of the circle; each filterpy step is a Python call), over two runs; every 7th step and the last are compared."""
    from math import cos, radians, sin
    rng = np.random.default_rng(410)
    runs, T, std = 2, 2000, 0.1
    a = np.radians(np.arange(T) / 30 + 90)
    zs = np.stack([np.cos(a) * 50.0, np.sin(a) * 50.0], -1) + std * rng.standard_normal((runs, T, 2))
    R = np.eye(2) * std**2
    Qu = np.diag([0.0, 0.001, 0.0])
    Fu = np.array([[1.0, 0, 0], [0, 1, 1], [0, 0, 1]])
    ukf_run = lb.unscented_kalman_filter(lb.NonlinearMotion(lambda x: x @ Fu.T), Qu,
                                         np.broadcast_to([50.0, 90.0, 0.0], (runs, 3)), 100.0 * np.eye(3),
                                         lb.NonlinearMeasurement(zs, _polar_to_xy_deg, R), points="julier", kappa=0.0)
    F1 = np.array([[1.0, 1.0, 0.5], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]])
    from scipy.linalg import block_diag
    F6 = block_diag(F1, F1)
    H6 = np.zeros((2, 6))
    H6[0, 0] = H6[1, 3] = 1.0
    q3 = filterpy_common.Q_discrete_white_noise(3, 1.0, 0.00001)
    Q6 = block_diag(q3, q3)
    kf_run = lb.kalman_filter(F6, Q6, np.broadcast_to([50.0, 0, 0, 0, 0, 0], (runs, 6)), 100.0 * np.eye(6),
                              lb.LinearMeasurement(zs, H6, R))

    def hx(x):
        return np.array([cos(radians(x[1])) * x[0], sin(radians(x[1])) * x[0]])

    for r in range(runs):
        f = filterpy_kalman.UnscentedKalmanFilter(dim_x=3, dim_z=2, dt=0.01, hx=hx,
                                                  fx=lambda x, dt: np.array([x[0], x[1] + x[2], x[2]]),
                                                  points=filterpy_kalman.JulierSigmaPoints(n=3, kappa=0.0))
        f.x = np.array([50.0, 90.0, 0])
        f.P *= 100
        f.R, f.Q = R.copy(), Qu.copy()
        kf = filterpy_kalman.KalmanFilter(dim_x=6, dim_z=2)
        kf.x, kf.F, kf.H, kf.R = np.array([50.0, 0.0, 0, 0, 0.0, 0.0]), F6, H6, R
        kf.P *= 100
        kf.Q[0:3, 0:3] = q3
        kf.Q[3:6, 3:6] = q3
        for t in range(T):
            f.predict()
            f.update(zs[r, t])
            kf.predict()
            kf.update(zs[r, t])
            if t % 7 == 0 or t == T - 1:            # every 7th step compared (all are filtered)
                _close(ukf_run.mean[r, t], f.x)
                _close(ukf_run.cov[r, t], f.P)
                _close(kf_run.mean[r, t], kf.x)
                _close(kf_run.cov[r, t], kf.P)


@pytest.mark.slow
def test_kf_circle_polar():
    """kf_circle (test_ukf.py; a scenario filterpy does not collect, no test_ prefix): the circular track read in x, y,
    converted to (radius, bearing) with atan2 and filtered by a 3-state KF (radius, bearing, bearing rate) with Q = I
    (filterpy's default) for 2000 steps. The bearing is not wrapped (nor is it in filterpy): it jumps by 2 pi at the
    crossing of +-pi, both filters follow the same numbers."""
    rng = np.random.default_rng(411)
    runs, T, std = 2, 2000, 0.1
    a = np.radians(np.arange(T) / 30 + 90)
    xy = np.stack([np.cos(a) * 50.0, np.sin(a) * 50.0], -1) + std * rng.standard_normal((runs, T, 2))
    zs = np.stack([np.hypot(xy[..., 0], xy[..., 1]), np.arctan2(xy[..., 1], xy[..., 0])], -1)
    F = np.array([[1.0, 0, 0.0], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]])
    H = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    R = np.eye(2) * std**2
    res = lb.kalman_filter(F, np.eye(3), np.broadcast_to([50.0, 0.0, 0.0], (runs, 3)), 100.0 * np.eye(3),
                           lb.LinearMeasurement(zs, H, R))
    for r in range(runs):
        kf = filterpy_kalman.KalmanFilter(dim_x=3, dim_z=2)
        kf.x, kf.F, kf.H, kf.R = np.array([50.0, 0.0, 0.0]), F, H, R
        kf.P *= 100
        for t in range(T):
            kf.predict()
            kf.update(zs[r, t])
            _close(res.mean[r, t], kf.x)
            _close(res.cov[r, t], kf.P)


def test_ukf_two_radar():
    """two_radar (test_ukf.py; "code is not complete", not collected by filterpy, and its constructor call
    ``UnscentedKalmanFilter(..., kappa=0)`` predates filterpy 2's ``points=``: the kappa of filterpy 1's UKF was
    Julier's, so JulierSigmaPoints(kappa=0) here). An aircraft at (100, 100) flying at (0.1, 0.1) per step, read by two
    radar stations at (0, 0) and (200, 0) in range (1 mm) and bearing (1 mrad), 300 steps; batch_filter and the
    unscented rts_smoother."""
    rng = np.random.default_rng(412)
    runs, T, dt, vx, vy = 2, 300, 1.0, 0.1, 0.1
    range_std, bearing_std = 0.001, 1.0 / 1000
    stations = np.array([[0.0, 0.0], [200.0, 0.0]])
    vel = np.array([vx, vy]) + 2e-8 * rng.standard_normal((runs, T, 1))     # ACSim: one jitter for both axes
    track = np.array([100.0, 100.0]) + np.cumsum(vel * dt, axis=1)

    def readings(pos):
        diff = stations - pos[..., None, :]                          # station minus aircraft, as RadarStation
        rng_, brg = np.hypot(diff[..., 0], diff[..., 1]), np.arctan2(diff[..., 1], diff[..., 0])
        return np.stack([rng_[..., 0], brg[..., 0], rng_[..., 1], brg[..., 1]], -1)

    zs = readings(track) + np.array([range_std, bearing_std] * 2) * rng.standard_normal((runs, T, 4))
    Rm = np.diag([range_std**2, bearing_std**2, range_std**2, bearing_std**2])
    q = filterpy_common.Q_discrete_white_noise(2, var=0.0002, dt=dt)
    from scipy.linalg import block_diag
    Q, P0 = block_diag(q, q), np.diag([0.1, 0.01, 0.1, 0.01])
    F = _cv2d(dt)
    res = lb.unscented_kalman_filter(lb.NonlinearMotion(lambda x: x @ F.T), Q,
                                     np.broadcast_to([100.0, vx, 100.0, vy], (runs, 4)), P0,
                                     lb.NonlinearMeasurement(zs, lambda x: readings(x[..., [0, 2]]), Rm),
                                     points="julier", kappa=0.0, outputs=("x_pred", "P_pred", "P_cross"))
    smooth = lb.rts_smoother(res)

    def fx(x, dt):
        x_est = x.copy()
        x_est[0] += x[1] * dt
        x_est[2] += x[3] * dt
        return x_est

    for r in range(runs):
        f = filterpy_kalman.UnscentedKalmanFilter(dim_x=4, dim_z=4, dt=dt, hx=lambda x: readings(x[[0, 2]]), fx=fx,
                                                  points=filterpy_kalman.JulierSigmaPoints(4, kappa=0.0))
        f.x, f.R, f.P = np.array([100, vx, 100, vy]), Rm, P0.copy()
        f.Q[0:2, 0:2] = q
        f.Q[2:4, 2:4] = q
        xs, Ps = f.batch_filter(zs[r])
        ms, mP, _ = f.rts_smoother(xs, Ps)
        _close(res.mean[r], xs)
        _close(res.cov[r], Ps)
        _close(smooth.mean[r], ms)
        _close(smooth.cov[r], mP)
    assert np.sqrt(np.mean((res.mean[..., [0, 2]] - track) ** 2)) < 0.01     # the 1 mm / 1 mrad readings pin it down


def test_linear_rts():
    """test_linear_rts (filterpy issue 97): a constant-velocity track x_k = k + 1 read with noise 1e-4 (R = 1e-8),
    Q = Q_discrete_white_noise(2, 1, 0.01), x0 = (0, 1), P0 = I, 50 steps; filterpy's KF and UKF (Merwe 0.1, 2, 1) and
    both rts_smoothers. locbook's KF equals filterpy's KF, locbook's UKF filterpy's UKF, and, as filterpy's test asserts
    for its own pair, the UKF the KF within 1e-7 (position) and 1e-6 (velocity), filtered and smoothed."""
    rng = np.random.default_rng(413)
    runs, N, dt = 3, 50, 1.0
    sig_t, sig_o = 0.1, 0.0001
    F, H = _cv(dt), H_POS
    X_obs = np.arange(1, N + 1) + rng.normal(scale=sig_o, size=(runs, N))
    oc = np.ones((1, 1)) * sig_o**2
    tc = filterpy_common.Q_discrete_white_noise(dim=2, dt=dt, var=sig_t**2)
    x0, outs = np.broadcast_to([0.0, 1.0], (runs, 2)), ("x_pred", "P_pred", "P_cross")
    kf_run = lb.kalman_filter(F, tc, x0, np.eye(2), lb.LinearMeasurement(X_obs[..., None], H, oc), outputs=outs)
    ukf_run = lb.unscented_kalman_filter(lb.NonlinearMotion(lambda x: x @ F.T), tc, x0, np.eye(2),
                                         lb.NonlinearMeasurement(X_obs[..., None], lambda x: x @ H.T, oc),
                                         alpha=0.1, beta=2.0, kappa=1.0, outputs=outs)
    kf_s, ukf_s = lb.rts_smoother(kf_run), lb.rts_smoother(ukf_run)
    for r in range(runs):
        points = filterpy_kalman.MerweScaledSigmaPoints(n=2, alpha=0.1, beta=2.0, kappa=1)
        ukf = filterpy_kalman.UnscentedKalmanFilter(dim_x=2, dim_z=1, dt=dt, hx=lambda x: np.dot(H, x),
                                                    fx=lambda x, dt: np.dot(_cv(dt), x), points=points)
        ukf.x, ukf.R, ukf.Q = np.array([0.0, 1.0]), np.copy(oc), np.copy(tc)
        kf = filterpy_kalman.KalmanFilter(dim_x=2, dim_z=1)
        kf.x, kf.R, kf.Q, kf.H, kf.F = np.array([[0.0, 1]]).T, np.copy(oc), np.copy(tc), np.copy(H), np.copy(F)
        mu_ukf, cov_ukf = ukf.batch_filter(list(X_obs[r]))
        x_ukf, P_ukf, _ = ukf.rts_smoother(mu_ukf, cov_ukf)
        mu_kf, cov_kf, _, _ = kf.batch_filter(list(X_obs[r]))
        x_kf, P_kf, _, _ = kf.rts_smoother(mu_kf, cov_kf)
        _close(kf_run.mean[r], mu_kf[..., 0])
        _close(kf_run.cov[r], cov_kf)
        _close(kf_s.mean[r], x_kf[..., 0])
        _close(kf_s.cov[r], P_kf)
        _close(ukf_run.mean[r], mu_ukf)
        _close(ukf_run.cov[r], cov_ukf)
        _close(ukf_s.mean[r], x_ukf)
        _close(ukf_s.cov[r], P_ukf)
    for ours, theirs in ((ukf_run.mean, kf_run.mean), (ukf_s.mean, kf_s.mean)):
        np.testing.assert_allclose(ours[..., 0], theirs[..., 0], rtol=0, atol=1e-7)
        np.testing.assert_allclose(ours[..., 1], theirs[..., 1], rtol=0, atol=1e-6)


def test_ukf_log_likelihood():
    """_test_log_likelihood (disabled in filterpy by its leading underscore, a filtering scenario all the same): the 2-D
    model of test_linear_2d_merwe with R = 0.01 I, Q = Q_discrete_white_noise(2, 0.1, 1.21, block_size=2), P0 = I,
    40 readings; after each update filterpy's log_likelihood (log N(y; 0, S)) and Mahalanobis distance."""
    rng = np.random.default_rng(414)
    runs, T, dt, z_std = 3, 40, 0.1, 0.1
    zs = np.arange(T)[:, None] + z_std * rng.standard_normal((runs, T, 2))
    R = np.diag([z_std**2, z_std**2])
    Q = filterpy_common.Q_discrete_white_noise(dim=2, dt=dt, var=1.1**2, block_size=2)
    F = _cv2d(dt)
    res = lb.unscented_kalman_filter(lb.NonlinearMotion(lambda x: x @ F.T), Q,
                                     np.broadcast_to([-1.0, 1, -1, 1], (runs, 4)), np.eye(4),
                                     lb.NonlinearMeasurement(zs, lambda x: x[..., [0, 2]], R),
                                     alpha=0.1, beta=2.0, kappa=-1.0)
    for r in range(runs):
        kf = _fp_ukf_2d(dt, filterpy_kalman.MerweScaledSigmaPoints(4, 0.1, 2.0, -1), [-1.0, 1, -1, 1], np.eye(4))
        kf.R, kf.Q = R, Q
        for k in range(T):
            kf.predict()
            kf.update(zs[r, k])
            _close(res.mean[r, k], kf.x)
            _close(res.cov[r, k], kf.P)
            assert res.log_likelihood[r, k] == pytest.approx(kf.log_likelihood, rel=1e-9)
            assert np.sqrt(res.nis[r, k]) == pytest.approx(kf.mahalanobis, rel=1e-9)
    assert res.total_log_likelihood.shape == (runs,)


def test_julier_sigma_points_1d():
    """test_julier_sigma_points_1D: Julier's points for n = 1, kappa = 0 (three of them, equal mean and covariance
    weights) reproduce the mean 5 and variance 9 through the unscented transform; locbook's points and weights equal
    filterpy's (1e-12)."""
    w = lb.unscented_weights(1, kappa=0.0, points="julier")
    sp = filterpy_kalman.JulierSigmaPoints(1, 0.0)
    np.testing.assert_allclose(w.mean, sp.Wm, rtol=0, atol=1e-12)
    np.testing.assert_allclose(w.cov, sp.Wc, rtol=0, atol=1e-12)
    X = lb.sigma_points(np.array([5.0]), np.array([[9.0]]), w.lam)
    assert X.shape == (3, 1)
    np.testing.assert_allclose(np.sort(X[:, 0]), np.sort(sp.sigma_points(5, 9)[:, 0]), rtol=0, atol=1e-12)
    mean, cov, _ = lb.unscented_transform(X, X, w)
    assert mean[0] == pytest.approx(5.0, abs=1e-12)
    assert cov[0, 0] == pytest.approx(9.0, abs=1e-12)


# ---------------------------------------------------------------------------------------------------- test_ckf.py

class _CubaturePoints:
    """The cubature rule's points for filterpy's UKF (x +- sqrt(n) columns of chol(P), weights 1 / (2n); Arasaratnam
    and Haykin 2009), in filterpy's sigma-point interface."""

    def __init__(self, n):
        self.n = n
        self.Wm = self.Wc = np.full(2 * n, 1.0 / (2 * n))

    def num_sigmas(self):
        return 2 * self.n

    def sigma_points(self, x, P):
        L = np.linalg.cholesky(self.n * P)
        return np.vstack([x + L.T, x - L.T])


@pytest.mark.parametrize("q_position", [0.0, 0.001])
def test_ckf_1d(q_position):
    """test_1d (test_ckf.py): a 1-D constant-velocity target, x0 = (1, 2), P0 = [[1, 1.1], [1.1, 3]], R = 0.05,
    Q = [[0, 0], [0, 0.001]], 50 readings i + 0.1 N(0, 1); filterpy's CubatureKalmanFilter, and its UKF with Merwe
    points (0.1, 2, -1) that the test compares it with; locbook's UKF with cubature points.

    filterpy's CKF updates with the cubature points it propagated through fx in its predict (``sigmas_f``), whose
    spread is F P F^T without Q, where locbook (and filterpy's UKF) redraws the points around the prediction P- = F P
    F^T + Q. In the scenario Q acts on the velocity alone and the reading is the position (H Q = 0), so the two give
    the same numbers and locbook equals the CKF. With the same noise on the position too (``q_position = 0.001``, a
    variant) the CKF leaves that Q out of S and P_xz and differs (by more than 1e-3, asserted), and locbook is compared
    with filterpy's UKF with cubature points (and Merwe points: the model is linear, any set gives the KF) instead."""
    rng = np.random.default_rng(501)
    runs, T, dt = 3, 50, 0.1
    zs = np.arange(T) + 0.1 * rng.standard_normal((runs, T))
    F, P0, Q = _cv(dt), np.array([[1, 1.1], [1.1, 3]]), np.array([[q_position, 0.0], [0.0, 0.001]])
    res = lb.unscented_kalman_filter(lb.NonlinearMotion(lambda x: x @ F.T), Q, np.broadcast_to([1.0, 2.0], (runs, 2)),
                                     P0, lb.NonlinearMeasurement(zs[..., None], lambda x: x[..., 0:1], [[0.05]]),
                                     points="cubature")
    fx, hx = (lambda x, dt: np.dot(_cv(dt), x)), (lambda x: x[0:1])
    ckf_gap = 0.0
    for r in range(runs):
        ckf = filterpy_kalman.CubatureKalmanFilter(dim_x=2, dim_z=1, dt=dt, hx=hx, fx=fx)
        ckf.x, ckf.P, ckf.R, ckf.Q = np.array([[1.0], [2.0]]), P0.copy(), np.eye(1) * 0.05, Q.copy()
        filters = []
        for points in (filterpy_kalman.MerweScaledSigmaPoints(2, 0.1, 2.0, -1), _CubaturePoints(2)):
            kf = filterpy_kalman.UnscentedKalmanFilter(dim_x=2, dim_z=1, dt=dt, fx=fx, hx=hx, points=points)
            kf.x, kf.P, kf.Q = np.array([1.0, 2.0]), P0.copy(), Q.copy()
            kf.R *= 0.05
            filters.append(kf)
        for i in range(T):
            z = np.array([[zs[r, i]]])
            ckf.predict()
            ckf.update(z)
            for kf in filters:
                kf.predict()
                kf.update(z[0])
                _close(res.mean[r, i], kf.x)
                _close(res.cov[r, i], kf.P)
            if q_position == 0.0:
                _close(res.mean[r, i], ckf.x[:, 0])
                _close(res.cov[r, i], ckf.P)
            ckf_gap = max(ckf_gap, np.abs(res.mean[r, i] - ckf.x[:, 0]).max())
    if q_position > 0:
        assert ckf_gap > 1e-3          # the CKF's update without Q: the documented difference is real


# -------------------------------------------------------------------------------------------- test_sensor_fusion.py

def _fusion_model(dt=0.1):
    return _cv(dt), np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]]) * 0.02


def test_sensor_fusion():
    """test_fusion: a target at position i (i = 1 .. 99, dt = 0.1) read by a wheel sensor (sigma 2) alone, and by the
    wheel and a GPS (sigma 4) fused in one 2-row update; filterpy's test asserts that fusing lowers the spread of the
    position error (here: averaged over the runs). The __main__ variant: a GPS of sigma 4e100 reading -1e40, which the
    fused filter all but ignores (locbook equals filterpy there too)."""
    rng = np.random.default_rng(601)
    runs = 6
    i = np.arange(1, 100, dtype=float)
    F, Q = _fusion_model()
    wheel = i + 2.0 * rng.standard_normal((runs, i.size))
    gps = i + 4.0 * rng.standard_normal((runs, i.size))
    single = lb.kalman_filter(F, Q, np.broadcast_to([0.0, 1.0], (runs, 2)), 100.0 * np.eye(2),
                              lb.LinearMeasurement(wheel[..., None], H_POS, [[4.0]]))
    H2 = np.array([[1.0, 0.0], [1.0, 0.0]])
    fused = {}
    for gps_sigma, g in ((4.0, gps), (4e100, np.full_like(gps, -1e40))):
        fused[gps_sigma] = lb.kalman_filter(F, Q, np.zeros((runs, 2)), 100.0 * np.eye(2),
                                            lb.LinearMeasurement(np.stack([wheel, g], -1), H2,
                                                                 np.diag([4.0, gps_sigma**2])), divergence_window=0)
    for r in range(runs):
        kf1 = filterpy_kalman.KalmanFilter(dim_x=2, dim_z=1)
        kf1.F, kf1.H, kf1.x, kf1.Q = F, H_POS, np.array([[0.0], [1.0]]), Q
        kf1.P *= 100
        kf1.R[0, 0] = 4.0
        kf2 = {}
        for gps_sigma in fused:
            f = filterpy_kalman.KalmanFilter(dim_x=2, dim_z=2)
            f.F, f.H, f.x, f.Q = F, H2, np.array([[0.0], [0.0]]), Q
            f.P *= 100
            f.R[0, 0], f.R[1, 1] = 4.0, gps_sigma**2
            kf2[gps_sigma] = f
        for k in range(i.size):
            kf1.predict()
            kf1.update(np.array([[wheel[r, k]]]))
            _close(single.mean[r, k], kf1.x[:, 0])
            _close(single.cov[r, k], kf1.P)
            for gps_sigma, f in kf2.items():
                m1 = gps[r, k] if gps_sigma == 4.0 else -1e40
                f.predict()
                f.update(np.array([[wheel[r, k]], [m1]]))
                _close(fused[gps_sigma].mean[r, k], f.x[:, 0])
                _close(fused[gps_sigma].cov[r, k], f.P)
    spread = lambda res: np.std(i - res.mean[..., 0], axis=-1).mean()
    assert spread(fused[4.0]) < spread(single)
