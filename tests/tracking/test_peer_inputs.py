"""What a filterpy user passes first is either taken as filterpy means it or refused with a line saying what locbook
expects: None for a step without a reading, a function of one state, a list of per-step matrices, column readings."""
import numpy as np
import pytest
from filterpy.kalman import KalmanFilter

import locbook as lb

F = np.array([[1.0, 1.0], [0.0, 1.0]])
Q = np.diag([0.01, 0.05])
H = np.array([[1.0, 0.0]])


def test_a_none_step_is_a_step_without_a_reading_as_in_filterpy():
    zs = [[1.0], [2.1], None, [3.9], None, [6.2]]
    ours = lb.kalman_filter(F, Q, np.zeros(2), np.eye(2), lb.LinearMeasurement(zs, H, np.eye(1)))
    f = KalmanFilter(2, 1)
    f.x, f.P, f.F, f.Q, f.H, f.R = np.zeros((2, 1)), np.eye(2), F, Q, H, np.eye(1)
    for k, z in enumerate(zs):
        f.predict()
        f.update(None if z is None else np.array(z))          # filterpy: update(None) keeps the prior
        np.testing.assert_allclose(ours.mean[k], f.x[:, 0], rtol=0, atol=1e-12)
    assert ours.nis_dof.tolist() == [1, 1, 0, 1, 0, 1]


def _per_state_h(x):                                  # filterpy's hx: one state (n,) -> (m,)
    return H @ x


def test_a_function_of_one_state_is_refused_by_name_and_per_state_makes_it_one_of_states():
    z = np.random.default_rng(0).normal(size=(3, 8, 1))
    x0 = np.zeros((3, 2))
    jac = lambda x: np.broadcast_to(H, x.shape[:-1] + (1, 2))          # noqa: E731
    with pytest.raises(ValueError, match=r"nonlinear measurement: h works on one state \(n,\) but not on states"):
        lb.extended_kalman_filter(F, Q, x0, np.eye(2),
                                  lb.NonlinearMeasurement(z, _per_state_h, np.eye(1), jacobian=jac))
    with pytest.raises(ValueError, match="wrap it with locbook.per_state"):
        lb.unscented_kalman_filter(F, Q, x0, np.eye(2), lb.NonlinearMeasurement(z, _per_state_h, np.eye(1)))
    wrapped = lb.extended_kalman_filter(F, Q, x0, np.eye(2), lb.NonlinearMeasurement(
        z, lb.per_state(_per_state_h), np.eye(1), jacobian=jac))
    linear = lb.kalman_filter(F, Q, x0, np.eye(2), lb.LinearMeasurement(z, H, np.eye(1)))
    np.testing.assert_allclose(wrapped.mean, linear.mean, rtol=0, atol=1e-12)


def test_a_motion_of_one_state_is_refused_by_name():
    fx = lambda x: np.array([x[0] + x[1], x[1]])                         # noqa: E731 - indexes the first axis
    z = np.zeros((3, 5, 1))
    with pytest.raises(ValueError, match=r"motion: f works on one state \(n,\)"):
        lb.unscented_kalman_filter(lb.NonlinearMotion(fx), Q, np.zeros((3, 2)), np.eye(2),
                                   lb.LinearMeasurement(z, H, np.eye(1)))
    ok = lb.unscented_kalman_filter(lb.NonlinearMotion(lb.per_state(fx)), Q, np.zeros((3, 2)), np.eye(2),
                                    lb.LinearMeasurement(z, H, np.eye(1)))
    ref = lb.kalman_filter(F, Q, np.zeros((3, 2)), np.eye(2), lb.LinearMeasurement(z, H, np.eye(1)))
    np.testing.assert_allclose(ok.mean, ref.mean, rtol=0, atol=1e-9)


def test_filterpy_list_of_matrices_and_column_readings_are_refused_with_the_form_to_pass():
    z = np.random.default_rng(1).normal(size=(6, 1))
    with pytest.raises(ValueError, match="per_step"):
        lb.kalman_filter([F] * 6, Q, np.zeros(2), np.eye(2), lb.LinearMeasurement(z, H, np.eye(1)))
    with pytest.raises(ValueError, match=r"column of 2 readings per step"):
        lb.LinearMeasurement(np.zeros((6, 2, 1)), np.eye(2), np.eye(2))
    with pytest.raises(ValueError, match=r"filterpy's fx\(x, dt\)|bind the time step"):
        lb.extended_kalman_filter(lb.NonlinearMotion(lambda x, dt: F @ x, lambda x, dt: F), Q, np.zeros(2), np.eye(2),
                                  lb.LinearMeasurement(z, H, np.eye(1)))
