"""Motion models and the Kalman filter against filterpy, scipy and closed forms."""
import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy.linalg import expm, solve_discrete_are

import locbook as lb
from locbook.scenarios import george
from oracles import filterpy_kalman


def test_transition_is_matrix_exponential_of_the_derivative_chain():
    for model in (lb.constant_velocity(0.7, 1.0, layout="axis_major"), lb.constant_acceleration(0.05, 1.0)):
        k = model.order + 1
        shift = np.kron(np.eye(model.dim), np.eye(k, k, 1))
        np.testing.assert_allclose(model.F, expm(shift * model.dt_s), atol=1e-14)


def test_continuous_q_equals_van_loan():
    model = lb.constant_velocity(0.4, 2.5, layout="axis_major", noise="continuous")
    a = np.kron(np.eye(2), np.eye(2, 2, 1))
    g = np.kron(np.eye(2), np.array([[0.0], [1.0]]))            # the noise input matrix
    n = a.shape[0]
    big = np.zeros((2 * n, 2 * n))
    big[:n, :n], big[:n, n:], big[n:, n:] = -a, g @ g.T * 2.5, a.T
    e = expm(big * 0.4)
    np.testing.assert_allclose(model.Q, e[n:, n:].T @ e[:n, n:], atol=1e-12)   # Van Loan (1978)


def test_layouts_are_permutations_and_document_003_matrices():
    dm = lb.constant_velocity(1.0, 0.3)
    am = lb.constant_velocity(1.0, 0.3, layout="axis_major")
    perm = [0, 2, 1, 3]   # [x, y, vx, vy] from [x, vx, y, vy]
    np.testing.assert_allclose(dm.F, am.F[np.ix_(perm, perm)])
    np.testing.assert_allclose(dm.Q, am.Q[np.ix_(perm, perm)])
    np.testing.assert_allclose(dm.F, [[1, 0, 1, 0], [0, 1, 0, 1], [0, 0, 1, 0], [0, 0, 0, 1]])   # Eq. (9), doc 003
    np.testing.assert_allclose(dm.G, [[0.5, 0], [0, 0.5], [1, 0], [0, 1]])
    np.testing.assert_allclose(dm.position_measurement_matrix(), [[1, 0, 0, 0], [0, 1, 0, 0]])
    ca = lb.constant_acceleration(0.05, 1.0)
    np.testing.assert_array_equal(ca.index(2), [2, 5])   # Dogan's per-axis ordering


def _scenario(batch=3, steps=30, seed=0):
    model = lb.constant_velocity(1.0, 0.01)
    rng = np.random.default_rng(seed)
    z = rng.normal(size=(batch, steps, 2)) + np.arange(steps)[:, None] * [0.1, 0.3]
    R = np.diag([8.6, 0.66])
    return model, model.position_measurement_matrix(), z, R, np.zeros(4), np.diag([8.6, 0.66, 1, 1])


@pytest.mark.parametrize("joseph", [True, False])
def test_kalman_equals_filterpy(joseph):
    model, H, z, R, x0, P0 = _scenario()
    res = lb.kalman_filter(model.F, model.Q, x0, P0, lb.LinearMeasurement(z, H, R), joseph=joseph)
    xs, ps = filterpy_kalman(model.F, model.Q, H, R, z, x0, P0)
    for b in range(z.shape[0]):
        np.testing.assert_allclose(res.mean[b], xs[b], atol=1e-10)
        np.testing.assert_allclose(res.cov[b], ps[b], atol=1e-10)


def test_batched_per_run_R_equals_loop():
    model, H, z, _, x0, _ = _scenario(batch=4)
    Rs = np.array([np.diag([a, b]) for a, b in [(1, 2), (3, 0.5), (8.6, 0.66), (0.1, 0.1)]])
    P0 = np.eye(4)
    batched = lb.kalman_filter(model.F, model.Q, x0, P0, lb.LinearMeasurement(z, H, Rs)).mean
    for b in range(4):
        np.testing.assert_allclose(batched[b],
                                   lb.kalman_filter(model.F, model.Q, x0, P0,
                                                    lb.LinearMeasurement(z[b], H, Rs[b])).mean, atol=1e-13)


def test_static_model_filter_is_recursive_least_squares():
    # F = I, Q = 0, flat prior: the filtered state is the batch least-squares mean of all measurements
    z = np.random.default_rng(3).normal(size=(40, 2))
    res = lb.kalman_filter(np.eye(2), np.zeros((2, 2)), np.zeros(2), 1e12 * np.eye(2),
                           lb.LinearMeasurement(z, np.eye(2), np.eye(2)), predict_first=False)
    np.testing.assert_allclose(res.mean, np.cumsum(z, 0) / np.arange(1, 41)[:, None], atol=1e-9)
    np.testing.assert_allclose(res.cov[-1], np.eye(2) / 40, atol=1e-12)


def test_covariance_converges_to_riccati_solution():
    model = lb.constant_velocity(1.0, 0.05)
    H, R = model.position_measurement_matrix(), np.diag([2.0, 0.5])
    res = lb.kalman_filter(model.F, model.Q, np.zeros(4), np.eye(4), lb.LinearMeasurement(np.zeros((300, 2)), H, R),
                           outputs=("P_pred",))
    p_pred = solve_discrete_are(model.F.T, H.T, model.Q, R)     # steady-state prediction covariance
    np.testing.assert_allclose(res.P_pred[-1], p_pred, rtol=1e-8)


def test_gain_limits():
    model, H, z, _, x0, P0 = _scenario(batch=1)
    follow = lb.kalman_filter(model.F, model.Q, x0, P0, lb.LinearMeasurement(z, H, 1e-12 * np.eye(2)))
    np.testing.assert_allclose(model.position(follow.mean), z, atol=1e-6)      # R -> 0 follows the fixes
    keep = lb.kalman_filter(model.F, model.Q, x0, P0, lb.LinearMeasurement(z, H, 1e12 * np.eye(2)))
    np.testing.assert_allclose(keep.mean, 0.0, atol=1e-6)                       # R -> inf keeps the prediction


def test_missing_measurements_predict_only():
    model, H, z, R, x0, P0 = _scenario(batch=1, steps=5)
    z = z.copy()
    z[0, 2] = np.nan
    res = lb.kalman_filter(model.F, model.Q, x0, P0, lb.LinearMeasurement(z, H, R))
    np.testing.assert_allclose(res.mean[0, 2], model.F @ res.mean[0, 1])
    np.testing.assert_allclose(res.cov[0, 2], model.F @ res.cov[0, 1] @ model.F.T + model.Q, rtol=1e-12)   # no update


def test_literal_george_variant_is_running_average():
    # Eqs. (11)-(13) as printed drop the prediction: P shrinks as 1/k and x is the running mean
    z = np.random.default_rng(7).normal(size=(20, 2)) + 5.0
    model = lb.constant_velocity(1.0, 1.0)
    res = lb.kalman_filter(model.F,
                           model.Q,
                           np.r_[z[0], 0, 0],
                           np.diag([1.0, 1.0, 1.0, 1.0]),
                           lb.LinearMeasurement(z, model.position_measurement_matrix(), np.eye(2)),
                           variant="literal_george")
    k = np.arange(2, 22)[:, None]
    np.testing.assert_allclose(res.mean[:, :2], (z[0] + np.cumsum(z, 0)) / k, atol=1e-12)


def test_corridor_kf_first_fix_start():
    fixes = np.random.default_rng(1).normal(size=(2, 25, 2))
    truth = george.trajectory_m()
    out = george.track_with_kalman(fixes, truth, q=1e-3)
    np.testing.assert_array_equal(out[:, 0], fixes[:, 0])
    assert out.shape == fixes.shape


def _corridor_filterpy(fixes, truth, q, R, start, update_first):
    """Document 003's KF written out in filterpy: state [x, y, vx, vy], dt = 1 s, F of Eq. (9),
    Q = q G G^T with G = [[1/2, 0], [0, 1/2], [1, 0], [0, 1]], P0 = diag(R_xx, R_yy, 1, 1)."""
    g = np.array([[0.5, 0.0], [0.0, 0.5], [1.0, 0.0], [0.0, 1.0]])
    kf = KalmanFilter(dim_x=4, dim_z=2)
    kf.F = np.array([[1.0, 0, 1, 0], [0, 1, 0, 1], [0, 0, 1, 0], [0, 0, 0, 1]])
    kf.H = np.array([[1.0, 0, 0, 0], [0, 1, 0, 0]])
    kf.Q, kf.R = q * g @ g.T, R
    kf.x, kf.P = np.r_[start, 0.0, 0.0], np.diag([R[0, 0], R[1, 1], 1.0, 1.0])
    out = []
    for t, z in enumerate(fixes):
        if t or not update_first:
            kf.predict()
        kf.update(z)
        out.append(kf.x[:2].copy())
    return np.array(out)


@pytest.mark.parametrize("r_mode", ["empirical", "isotropic"])
def test_corridor_kf_equals_filterpy(r_mode):
    # fixes scattered about the centreline with a different spread per axis, so R is not isotropic
    truth = george.trajectory_m()
    rng = np.random.default_rng(1)
    fixes = truth + rng.normal(size=(3, 25, 2)) * [0.8, 1.5] + [0.2, -0.1]
    q = 0.05
    first = george.track_with_kalman(fixes, truth, q=q, r_mode=r_mode)
    true_start = george.track_with_kalman(fixes, truth, q=q, r_mode=r_mode, init="true_start")
    for b in range(fixes.shape[0]):
        # R "obtained from experiments": the sample covariance (ddof 1) of fix - truth over the 25 points
        R = np.cov((fixes[b] - truth).T) if r_mode == "empirical" else 3.3 * np.eye(2)
        # first-fix start: the first output is the first fix, then predict + update on fixes 2..25
        ref = _corridor_filterpy(fixes[b, 1:], truth, q, R, fixes[b, 0], update_first=False)
        np.testing.assert_array_equal(first[b, 0], fixes[b, 0])
        np.testing.assert_allclose(first[b, 1:], ref, atol=1e-10)
        # true start: update with fix 1 at the true start (no prediction first), then predict + update
        ref = _corridor_filterpy(fixes[b], truth, q, R, truth[0], update_first=True)
        np.testing.assert_allclose(true_start[b], ref, atol=1e-10)
    # the filter smooths: its error is well below that of the fixes it filters
    err = lambda p: np.sqrt(np.mean(np.sum((p - truth) ** 2, -1)))
    assert err(first) < 0.8 * err(fixes)


def test_batched_process_noise_equals_loop():
    # one q per leading index (e.g. a q grid): F/H/Q batch axes broadcast like the measurements'
    model, H, z, R, x0, P0 = _scenario(batch=1)
    qs = [1e-4, 1e-2, 1.0]
    Qs = np.stack([lb.constant_velocity(1.0, q).Q for q in qs])
    batched = lb.kalman_filter(model.F, Qs, x0, P0, lb.LinearMeasurement(z[0], H, R)).mean
    assert batched.shape == (3, z.shape[1], 4)
    for i, Q in enumerate(Qs):
        np.testing.assert_allclose(batched[i],
                                   lb.kalman_filter(model.F, Q, x0, P0, lb.LinearMeasurement(z[0], H, R)).mean,
                                   atol=1e-13)


def test_a_motion_whose_f_or_jacobian_is_complex_is_refused_by_its_own_methods():
    motion = lb.NonlinearMotion(lambda x: x * (1 + 1j), lambda x: np.eye(2) * (1 + 0j), name="spin")
    with pytest.raises(ValueError, match="spin: f returned complex values"):
        motion.apply(np.zeros((3, 2)), 0)
    with pytest.raises(ValueError, match="spin: jacobian returned complex values"):
        motion.jacobian_at(np.zeros((3, 2)), 0)
    plain = lb.NonlinearMotion(lambda x: 2 * x, lambda x: 2 * np.eye(2))
    np.testing.assert_array_equal(plain.apply(np.ones((3, 2)), 0), 2 * np.ones((3, 2)))
    np.testing.assert_array_equal(plain.jacobian_at(np.ones((3, 2)), 0), 2 * np.eye(2))


def test_reflect_into_box_folds_long_steps():
    lo, hi = np.zeros(2), np.array([5.0, 8.0])
    p = np.array([[-1.0, 9.0], [11.5, -17.0], [2.0, 3.0]])
    # -1 -> 1; 9 -> 7; 11.5 -> 10 - 11.5 = -1.5 -> 1.5; -17 -> 17 - 16 = 1 (period 16)
    np.testing.assert_allclose(lb.reflect_into_box(p, lo, hi), [[1.0, 7.0], [1.5, 1.0], [2.0, 3.0]])
