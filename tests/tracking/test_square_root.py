"""The square-root (Cholesky-factor) Kalman / extended Kalman filter: equal to the covariance-form KF and EKF
(x, P, log-likelihood, NIS, the optional outputs) on linear streams with missing components, the RSS EKF (parallel
and serial), nonlinear and time-varying motion and batched runs with per-run priors; equal to filterpy's
SquareRootKalmanFilter run by run; and the point of the form, the ill-conditioned measurement of Grewal and Andrews'
implementation chapter (P0 = I, H = [[1, 1, 1], [1, 1, 1 + d]], R = d^2 I with d^2 at the round-off of 1), where the
conventional update loses positive definiteness while the square-root form matches the exact rational posterior."""
from fractions import Fraction

import numpy as np
import pytest
from filterpy.kalman import SquareRootKalmanFilter

import locbook as lb
from locbook.errors import SingularCovarianceError
from locbook.tracking.square_root import SquareRootKalmanResult, square_root_kalman_filter

MODEL = lb.constant_velocity(1.0, 0.05)
H_POS = MODEL.position_measurement_matrix()
ANCHORS = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
OUTPUTS = ("x_pred", "P_pred", "P_cross", "innovation", "S")
FIELDS = ("mean", "cov", "log_likelihood", "nis") + OUTPUTS


def _equal(a, b, fields=FIELDS, tol=1e-9):
    """Fields of two results equal to ``tol`` (relative to each field's scale), NaN in the same places."""
    for f in fields:
        u, v = getattr(a, f), getattr(b, f)
        assert u.shape == v.shape, f
        np.testing.assert_array_equal(np.isnan(u), np.isnan(v), err_msg=f)
        scale = max(1.0, float(np.nanmax(np.abs(u))))
        np.testing.assert_allclose(np.nan_to_num(v), np.nan_to_num(u), rtol=tol, atol=tol * scale, err_msg=f)
    np.testing.assert_array_equal(a.nis_dof, b.nis_dof)


def _per_run_P0(runs, n, rng):
    A = rng.normal(size=(runs, n, n))
    return A @ np.swapaxes(A, -1, -2) + np.eye(n)


def test_constant_velocity_with_missing_components_equals_kalman_filter():
    """Position fixes with a correlated R, 30 % of the components missing (some steps with no reading in some runs),
    per-run P0: every field and output of kalman_filter to 1e-9."""
    rng = np.random.default_rng(0)
    runs, T = 6, 40
    z = rng.normal(size=(runs, T, 2)) * 2.0 + np.arange(T)[:, None] * [0.3, -0.2]
    z[rng.random(z.shape) < 0.3] = np.nan
    z[1, 5:9] = np.nan                                      # a run without readings for four steps
    assert np.isnan(z).all(axis=-1).any() and not np.isnan(z).all(axis=(0, -1)).any()
    meas = lb.LinearMeasurement(z, H_POS, np.array([[2.0, 0.3], [0.3, 0.7]]))
    x0, P0 = rng.normal(size=(runs, 4)), _per_run_P0(runs, 4, rng)
    ref = lb.kalman_filter(MODEL.F, MODEL.Q, x0, P0, meas, outputs=OUTPUTS)
    res = square_root_kalman_filter(MODEL.F, MODEL.Q, x0, P0, meas, outputs=OUTPUTS)
    assert isinstance(res, SquareRootKalmanResult) and isinstance(res, lb.KalmanResult)
    _equal(ref, res)
    np.testing.assert_array_equal(ref.diverged, res.diverged)


@pytest.mark.parametrize("mode,order", [("parallel", "given"), ("serial", "given"), ("serial", "descending")])
def test_rss_ekf_equals_extended_kalman_filter(mode, order):
    """The RSS EKF on four anchors, 20 % of the readings missing, per-run P0: parallel (one stacked update) and serial
    (one scalar update per reading, re-linearised, in the given or the per-run descending order)."""
    rng = np.random.default_rng(3)
    ch = lb.PathLossModel(-40.0, 2.2, 2.0)
    runs, T = 8, 30
    pos = 5 + np.cumsum(0.1 * rng.standard_normal((runs, T, 2)), axis=1)
    z = ch.sample_rss_dbm(np.linalg.norm(pos[:, :, None] - ANCHORS, axis=-1), rng=rng)
    z[rng.random(z.shape) < 0.2] = np.nan
    meas = lb.RssMeasurement(z, ANCHORS, ch, MODEL.position_index, mode=mode, order=order)
    x0, P0 = MODEL.state_from(np.array([5.0, 5.0])), _per_run_P0(runs, 4, rng)
    ref = lb.extended_kalman_filter(MODEL.F, MODEL.Q, x0, P0, meas, outputs=OUTPUTS)
    _equal(ref, square_root_kalman_filter(MODEL.F, MODEL.Q, x0, P0, meas, outputs=OUTPUTS))


def test_two_streams_nonlinear_motion_and_time_varying_motion_equal_the_ekf():
    """A pendulum (NonlinearMotion, the EKF's Jacobian at the posterior) with a nonlinear reading sin(theta) and a
    linear rate reading, both predict_first conventions, recorded steps; then per-step F and Q with a control input and
    a zero P0 (semi-definite: the eigen factor)."""
    rng = np.random.default_rng(2)
    dt, T = 0.1, 30

    def f(x):
        return np.stack([x[..., 0] + dt * x[..., 1], x[..., 1] - dt * 9.81 * np.sin(x[..., 0])], axis=-1)

    def jac(x):
        J = np.zeros(x.shape + (2,))
        J[..., 0, 0], J[..., 0, 1], J[..., 1, 1] = 1.0, dt, 1.0
        J[..., 1, 0] = -dt * 9.81 * np.cos(x[..., 0])
        return J

    z = np.sin(0.3 * np.arange(T))[None, :, None] + 0.1 * rng.normal(size=(3, T, 1))
    z[:, ::4] = np.nan
    rate = rng.normal(size=(3, T, 1))
    rate[rng.random(rate.shape) < 0.5] = np.nan
    h_jac = lambda X: np.stack([np.cos(X[..., 0]), 0 * X[..., 0]], -1)[..., None, :]
    streams = [lb.NonlinearMeasurement(z, lambda X: np.sin(X[..., :1]), np.array([[0.01]]), jacobian=h_jac),
               lb.LinearMeasurement(rate, np.array([[0.0, 1.0]]), np.array([[0.5]]))]
    motion, Q = lb.NonlinearMotion(f, jac), np.diag([1e-4, 1e-3])
    for first in (True, False):
        args = (motion, Q, np.array([[0.1, 0.0]]), 0.1 * np.eye(2), streams)
        kw = dict(predict_first=first, record=[0, 5, T - 1], outputs=OUTPUTS)
        _equal(lb.extended_kalman_filter(*args, **kw), square_root_kalman_filter(*args, **kw))
    Fs = lb.per_step(np.stack([MODEL.F * (1 + 0.01 * k) for k in range(T)]))
    Qs = lb.per_step(np.stack([MODEL.Q * (1 + k) for k in range(T)]))
    u, B = rng.normal(size=(4, T, 2)), np.vstack([np.zeros((2, 2)), np.eye(2)])
    zz = rng.normal(size=(4, T, 2))
    zz[rng.random(zz.shape) < 0.3] = np.nan
    args = (Fs, Qs, np.zeros(4), np.zeros((4, 4)), lb.LinearMeasurement(zz, H_POS, np.eye(2)))
    kw = dict(B=B, u=u, outputs=OUTPUTS)
    _equal(lb.kalman_filter(*args, **kw), square_root_kalman_filter(*args, **kw))


def test_semi_definite_covariances_are_factored():
    """Q of the discrete white-noise model (rank 2 of 4), P0 = 0 (a known start) and an R with a perfect reading
    (variance 0) have no Cholesky factor; the filter factors them through the eigen-decomposition and equals the KF."""
    with pytest.raises(np.linalg.LinAlgError):
        np.linalg.cholesky(MODEL.Q)
    rng = np.random.default_rng(5)
    z = rng.normal(size=(3, 25, 2))
    z[rng.random(z.shape) < 0.2] = np.nan
    meas = lb.LinearMeasurement(z, H_POS, np.diag([0.0, 1.0]))
    args = (MODEL.F, MODEL.Q, rng.normal(size=(3, 4)), np.zeros((4, 4)), meas)
    _equal(lb.kalman_filter(*args, outputs=OUTPUTS), square_root_kalman_filter(*args, outputs=OUTPUTS))


def test_factor_output_is_a_triangular_square_root_of_P():
    rng = np.random.default_rng(7)
    z = rng.normal(size=(5, 20, 2))
    z[rng.random(z.shape) < 0.3] = np.nan
    res = square_root_kalman_filter(MODEL.F, MODEL.Q, np.zeros(4), 10 * np.eye(4),
                                    lb.LinearMeasurement(z, H_POS, np.eye(2)), outputs=("P_sqrt", "P_pred_sqrt"))
    assert res.P_pred is None and res.x_pred is None          # the prior's factor only, as asked
    for S, P in ((res.P_sqrt, res.cov), (res.P_pred_sqrt, None)):
        assert S.shape == (5, 20, 4, 4)
        np.testing.assert_array_equal(np.triu(S, 1), 0.0)
        assert (np.diagonal(S, axis1=-2, axis2=-1) > 0).all()
        if P is not None:
            np.testing.assert_array_equal(P, np.swapaxes(P, -1, -2))
            np.testing.assert_allclose(S @ np.swapaxes(S, -1, -2), P, rtol=1e-12, atol=1e-14)
    plain = square_root_kalman_filter(MODEL.F, MODEL.Q, np.zeros(4), 10 * np.eye(4),
                                      lb.LinearMeasurement(z, H_POS, np.eye(2)))
    assert plain.P_sqrt is None and plain.P_pred_sqrt is None


def test_equals_filterpy_square_root_kalman_filter_run_by_run():
    """filterpy's SquareRootKalmanFilter (it stores P1_2 with P = P1_2 P1_2^T, Q1_2 and R1_2 from Cholesky; predict,
    then update, at every step: our predict_first=True): x, P, the residual y and S = S1_2 S1_2^T at every step."""
    rng = np.random.default_rng(11)
    runs, T = 4, 30
    Q = MODEL.Q + 1e-3 * np.eye(4)                            # filterpy factors Q by Cholesky: positive definite
    R = np.array([[1.5, 0.4], [0.4, 0.8]])
    z = rng.normal(size=(runs, T, 2)) * 2 + np.arange(T)[:, None] * [0.5, 0.1]
    x0, P0 = rng.normal(size=(runs, 4)), _per_run_P0(runs, 4, rng)
    res = square_root_kalman_filter(MODEL.F, Q, x0, P0, lb.LinearMeasurement(z, H_POS, R),
                                    outputs=("innovation", "S"))
    for b in range(runs):
        kf = SquareRootKalmanFilter(dim_x=4, dim_z=2)
        kf.x, kf.F, kf.H = x0[b][:, None].copy(), MODEL.F, H_POS
        kf.P, kf.Q, kf.R = P0[b], Q, R
        for k in range(T):
            kf.predict()
            kf.update(z[b, k][:, None])
            np.testing.assert_allclose(res.mean[b, k], kf.x[:, 0], rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(res.cov[b, k], kf.P, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(res.innovation[b, k], kf.y[:, 0], rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(res.S[b, k], kf.S, rtol=1e-9, atol=1e-9)


# -- the ill-conditioned measurement: exact rational reference --------------------------------------------------------


def _fractions(A):
    return [[Fraction(float(v)) for v in row] for row in np.atleast_2d(A)]


def _mul(A, B):
    return [[sum(A[i][k] * B[k][j] for k in range(len(B))) for j in range(len(B[0]))] for i in range(len(A))]


def _transpose(A):
    return [list(r) for r in zip(*A)]


def _inverse(A):
    """Gauss-Jordan in exact rationals."""
    n = len(A)
    M = [row[:] + [Fraction(int(i == j)) for j in range(n)] for i, row in enumerate(A)]
    for c in range(n):
        p = next(r for r in range(c, n) if M[r][c] != 0)
        M[c], M[p] = M[p], M[c]
        M[c] = [v / M[c][c] for v in M[c]]
        for r in range(n):
            if r != c and M[r][c] != 0:
                M[r] = [a - M[r][c] * b for a, b in zip(M[r], M[c])]
    return [row[n:] for row in M]


def _exact_update(P, z, H, R):
    """The Kalman update of the prior N(0, P) by z = H x + v, v ~ N(0, R), in exact rational arithmetic on the float
    inputs as given: (x+, P+) = (K z, P - K H P), K = P H^T (H P H^T + R)^-1."""
    P, z, H, R = _fractions(P), _fractions(np.reshape(z, (-1, 1))), _fractions(H), _fractions(R)
    S = [[a + b for a, b in zip(r, s)] for r, s in zip(_mul(_mul(H, P), _transpose(H)), R)]
    K = _mul(_mul(P, _transpose(H)), _inverse(S))
    KHP = _mul(_mul(K, H), P)
    return _mul(K, z), [[a - b for a, b in zip(r, s)] for r, s in zip(P, KHP)]


def _det3(P):
    return sum(P[0][j] * (P[1][(j + 1) % 3] * P[2][(j + 2) % 3] - P[1][(j + 2) % 3] * P[2][(j + 1) % 3])
               for j in range(3))


@pytest.mark.parametrize("delta,mode", [(3e-8, "parallel"), (1e-8, "serial"), (1e-8, "parallel")])
def test_ill_conditioned_measurement_keeps_positive_definite_and_exact(delta, mode):
    """P0 = I_3, H = [[1, 1, 1], [1, 1, 1 + d]], R = d^2 I (d^2 of the order of the round-off of 1: 1e-16 rounds
    away, 9e-16 to 4 ulps), one update: the exact
    posterior (rationals) has the smallest leading minor det P+ ~ 1e-16 .. 1e-17.

    The conventional short form (kalman_filter(joseph=False)) returns a P whose smallest eigenvalue has lost every
    digit (-0.19 for d = 3e-8 parallel; +-1.6e-10 for d = 1e-8 serial, its sign round-off, against an exact ~1e-17)
    with the state off by 1 % and 47 % of its size; at d = 1e-8 parallel its S = H P H^T + R is not positive
    definite and it refuses. The square-root form keeps a nonsingular triangular factor S (P = S S^T positive
    definite exactly), det(S)^2 equals the exact det P+ to 1e-7, S S^T (in exact arithmetic) the exact P+ to 1e-8
    and x the exact x+ to 1e-7 of its size (measured: 1.5e-9 .. 3.5e-9 and 1e-8)."""
    H = np.array([[1.0, 1.0, 1.0], [1.0, 1.0, 1.0 + delta]])
    R, z = delta ** 2 * np.eye(2), np.array([[1.0, 2.0]])
    assert (1.0 + delta ** 2) - 1.0 != delta ** 2             # the regime of the example: 1 + d^2 loses d^2's digits
    x_exact, P_exact = _exact_update(np.eye(3), z[0], H, R)
    x_e = np.array([float(v[0]) for v in x_exact])
    det_exact = _det3(P_exact)
    assert 0 < det_exact < 1e-15
    meas = lb.LinearMeasurement(z, H, R, mode=mode)
    args = (np.eye(3), np.zeros((3, 3)), np.zeros(3), np.eye(3), meas)
    res = square_root_kalman_filter(*args, predict_first=False, outputs=("P_sqrt",))
    S = res.P_sqrt[0]
    assert (np.diag(S) > 0).all()
    ratio = float(Fraction(float(np.prod(np.diag(S)))) ** 2 / det_exact)
    assert abs(ratio - 1) < 1e-7
    SS = _mul(_fractions(S), _transpose(_fractions(S)))
    assert max(abs(float(a - b)) for ra, rb in zip(SS, P_exact) for a, b in zip(ra, rb)) < 1e-8
    np.testing.assert_allclose(res.cov[0], [[float(v) for v in r] for r in P_exact], rtol=0, atol=1e-8)
    assert np.abs(res.mean[0] - x_e).max() < 1e-7 * np.abs(x_e).max()
    if delta == 1e-8 and mode == "parallel":
        with pytest.raises(SingularCovarianceError):
            lb.kalman_filter(*args, predict_first=False, joseph=False)
        return
    short = lb.kalman_filter(*args, predict_first=False, joseph=False)
    # the short form loses every digit of the smallest eigenvalue (exact: ~1e-17; its error is ~1e-10, far beyond a
    # round-off of 1e-16): whether it lands below zero (indefinite) is itself round-off, -1.6e-10 on one numpy /
    # numba build and +1.6e-10 on another, so the test asserts the loss, not its sign
    exact_min = np.linalg.eigvalsh(np.array([[float(v) for v in r] for r in P_exact]))[0]
    assert abs(np.linalg.eigvalsh(short.cov[0])[0] - exact_min) > 1e-11
    assert np.abs(short.mean[0] - x_e).max() > 1e-3 * np.abs(x_e).max()


# -- bad input ------------------------------------------------------------------------------------------------------


def _one_line(excinfo):
    text = str(excinfo.value)
    assert "\n" not in text and text
    return text


@pytest.mark.parametrize("change,needle", [
    (dict(P0=-np.eye(4)), "P0 must be positive semi-definite"),
    (dict(Q=np.eye(3)), "Q"),
    (dict(outputs=("P_chol",)), "outputs must name fields among"),
    (dict(x0=np.array([np.nan, 0, 0, 0])), "x0 must be finite"),
    (dict(measurements=[np.zeros((3, 2))]), "measurements must be measurement streams"),
    (dict(divergence_window=-1), "divergence_window"),
    (dict(record=[5]), "record"),
])
def test_bad_inputs_are_one_line_value_errors(change, needle):
    z = np.ones((3, 2))
    kw = dict(F=MODEL.F, Q=MODEL.Q, x0=np.zeros(4), P0=np.eye(4),
              measurements=lb.LinearMeasurement(z, H_POS, np.eye(2)))
    kw.update(change)
    with pytest.raises(ValueError) as excinfo:
        square_root_kalman_filter(**kw)
    assert needle in _one_line(excinfo)


def test_singular_innovation_is_named():
    """A perfect reading of a perfectly known state (P0 = 0, Q = 0, R = 0): H P H^T + R = 0, refused at step 0 as the
    EKF refuses it."""
    meas = lb.LinearMeasurement(np.ones((2, 3, 2)), H_POS, np.zeros((2, 2)))
    with pytest.raises(SingularCovarianceError) as excinfo:
        square_root_kalman_filter(MODEL.F, np.zeros((4, 4)), np.zeros(4), np.zeros((4, 4)), meas)
    assert "at step 0 (run index (0,))" in _one_line(excinfo)
