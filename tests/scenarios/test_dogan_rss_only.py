"""The ONLY-RSS filters' step (the reading ``rss_only_step`` of locbook/data/readings/dogan2015.csv): under
``"rss_rate"`` they predict once per RSS period with Q of Eq. (3.24), under ``"imu_rate"`` ten times on the 20 Hz grid.
Checked against closed forms: the KF's covariance after one RSS period, and the PCRLB's information over the steps
without RSS; the fused filters do not depend on the reading."""
import numpy as np
import pytest

import locbook as lb
from locbook.bounds.pcrlb import linear_measurement_information, position_bound_m, posterior_crlb
from locbook.reproduce.interpretations import interpretations
from locbook.scenarios import dogan as dg


def _walk():
    return dg.walk_trajectory(((1.0, 1.0), (1.0, 4.0)), 0.3, dg.DT_S, start="rest")


def test_the_declared_reading_is_the_library_default_and_its_values_run():
    reading = {r.name: r for r in interpretations("dogan2015")}["rss_only_step"]
    assert reading.default == dg.DEFAULT_RSS_ONLY_STEP and set(reading.values) == set(dg.RSS_ONLY_STEPS)
    assert reading.basis == "textual" and not reading.fitted
    with pytest.raises(lb.ParameterError, match="rss_only_step"):
        dg.filter_grid(_walk(), False, "accelerometer")


def test_rss_grid_keeps_the_epochs_and_steps_at_the_rss_period():
    walk = _walk()
    grid = dg.rss_grid(walk)
    np.testing.assert_array_equal(grid.position_m, walk.position_m[walk.rss_steps])
    np.testing.assert_array_equal(grid.rss_steps, np.arange(walk.rss_steps.size))
    np.testing.assert_allclose(np.diff(grid.time_s), dg.RSS_EVERY * dg.DT_S)          # 0.5 s at Sec. 3.5's rates
    assert dg.filter_grid(walk, True, "rss_rate") is walk            # a fused filter keeps Table 3.5's grid
    assert dg.filter_grid(walk, False, "imu_rate") is walk


@pytest.mark.parametrize("step", dg.RSS_ONLY_STEPS)
def test_kf_covariance_after_one_rss_period_is_the_closed_form(step):
    """KF (MLE) from P_0 (Eq. (3.20)) to the first update: predicted P = F^n P_0 F^n' + sum_i F^i Q F^i' over the n
    predictions of one RSS period (n = 10 at 'imu_rate' with F of 0.05 s, n = 1 at 'rss_rate' with F of 0.5 s), then
    the linear update with H of the position and R = diag(MSE) (Eq. (3.21))."""
    walk = _walk()
    mse = np.array([2.0, 3.0])
    channel = lb.PathLossModel(dg.REF_POWER_DBM, dg.PATH_LOSS_EXP, dg.SIGMA_RSS_DB)
    rss = dg.simulate_rss(walk, channel, 1, np.random.default_rng(3))
    fix = walk.position_m[walk.rss_steps][None] + 0.5
    grid = dg.filter_grid(walk, False, step)
    dt_s, n = (dg.DT_S, dg.RSS_EVERY) if step == "imu_rate" else (dg.DT_S * dg.RSS_EVERY, 1)
    model = dg.motion_model(float(grid.time_s[1] - grid.time_s[0]), dg.Q_PER_STEP)
    track = dg.run_filter("kalman_filter", grid, rss, fix, mse, channel, model=model)
    F = dg.motion_model(dt_s).F
    _, P0 = dg.initial_state(np.zeros(2), mse)
    powers = [np.linalg.matrix_power(F, i) for i in range(n + 1)]
    predicted = powers[n] @ P0 @ powers[n].T + sum(p @ (dg.Q_PER_STEP * np.eye(6)) @ p.T for p in powers[:n])
    H = model.position_measurement_matrix()
    expected = np.linalg.inv(np.linalg.inv(predicted) + H.T @ np.diag(1 / mse) @ H)
    np.testing.assert_allclose(track.cov[0, 1], expected, rtol=1e-9, atol=1e-12)


def test_the_two_steps_differ_by_the_process_noise_of_the_skipped_predictions():
    """Ten predictions with Q add sum_i F^i Q F^i' (0.05 s) per RSS period, one adds Q: the 20 Hz reading carries
    more position uncertainty into each update (Q per step, Eq. (3.24))."""
    F = dg.motion_model(dg.DT_S).F
    q10 = sum(np.linalg.matrix_power(F, i) @ np.linalg.matrix_power(F, i).T
              for i in range(dg.RSS_EVERY)) * dg.Q_PER_STEP
    assert q10[0, 0] > 10 * dg.Q_PER_STEP and np.all(np.diag(q10) >= 10 * dg.Q_PER_STEP - 1e-15)


def test_the_only_rss_bound_over_the_steps_without_rss_is_one_step_with_the_summed_noise():
    """The reason of reading pcrlb_grid: for the linear motion model the 20 Hz recursion with D22 = Q^-1 between RSS
    epochs (Table 4.1 without the accelerometer) gives at the RSS epochs the recursion of one 0.5 s step whose process
    noise is sum_i F^i Q F^i' (0.05 s), so the ONLY-RSS bound of given trajectories does not depend on a filter's
    step."""
    mse = np.array([2.0, 3.0])
    n_steps = 4 * dg.RSS_EVERY + 1
    fine = dg.pcrlb_m("linear", fusion=False, sigma_rss_db=6.0, mse_mle_m2=mse, n_steps=n_steps)[::dg.RSS_EVERY]
    F = dg.motion_model(dg.DT_S).F
    q_sum = sum(np.linalg.matrix_power(F, i) @ np.linalg.matrix_power(F, i).T
                for i in range(dg.RSS_EVERY)) * dg.Q_PER_STEP
    coarse_model = dg.motion_model(dg.DT_S * dg.RSS_EVERY)
    _, P0 = dg.initial_state(np.zeros(2), mse)
    jz = np.broadcast_to(linear_measurement_information(coarse_model.position_measurement_matrix(), np.diag(mse)),
                         (4, 6, 6))
    coarse = position_bound_m(posterior_crlb(np.linalg.inv(P0), coarse_model.F, q_sum, jz),
                              coarse_model.position_index)
    np.testing.assert_allclose(fine, coarse, rtol=1e-6)


def test_the_fused_filters_do_not_depend_on_the_only_rss_step():
    walk = _walk()
    runs = {step: dg.run_channel(walk, 6.0, 3.0, 4, np.random.default_rng(11), sigma_acc_values=(dg.SIGMA_ACC_MPS2,),
                                 mle_grid_step_m=1.0, rss_only_step=step, rmse_epochs="every_step")
            for step in dg.RSS_ONLY_STEPS}
    for name in dg.FILTERS:
        fused = (name, dg.SIGMA_ACC_MPS2)
        np.testing.assert_array_equal(runs["rss_rate"].errors[fused], runs["imu_rate"].errors[fused])
        # the ONLY-RSS filter at the RSS rate has estimates at the RSS epochs only
        assert runs["rss_rate"].errors[("every_step", name, None)].shape == runs["rss_rate"].errors[(name, None)].shape
        assert runs["imu_rate"].errors[("every_step", name, None)].shape[-1] == walk.time_s.size
    np.testing.assert_array_equal(runs["rss_rate"].errors["static_mle"], runs["imu_rate"].errors["static_mle"])
