"""The one RssModel read by the Kalman family: channel parameters with run axes stay per run (a 2-D batch of runs is
each run's own filter), per-step anchors are marked, the factory's old keyword form still works, and a channel given
where the model goes is refused by name."""
import numpy as np
import pytest

import locbook as lb

ANCHORS = np.array([[0.0, 0.0], [12.0, 0.0], [12.0, 9.0], [0.0, 9.0]])
CV = lb.constant_velocity(0.5, 0.05)


def test_per_run_channel_parameters_on_a_two_axis_batch_are_each_runs_own():
    B = T = 6                                   # a second run axis as long as the time axis: must not be read as steps
    z = np.random.default_rng(0).normal(-60.0, 3.0, (1, B, T, 4))
    x0 = np.tile([6.0, 4.5, 0.0, 0.0], (1, B, 1))
    ref = np.linspace(-44.0, -36.0, B).reshape(1, B, 1)
    batch = lb.extended_kalman_filter(CV.F, CV.Q, x0, np.eye(4),
                                      [lb.RssMeasurement(z, ANCHORS, lb.PathLossModel(ref, 2.5, 3.0), [0, 1])])
    for b in range(B):
        one = lb.extended_kalman_filter(CV.F, CV.Q, x0[0, b], np.eye(4),
                                        [lb.RssMeasurement(z[0, b], ANCHORS, lb.PathLossModel(ref[0, b, 0], 2.5, 3.0),
                                                           [0, 1])])
        np.testing.assert_allclose(batch.mean[0, b], one.mean, rtol=0, atol=1e-12)


def test_per_step_anchors_marked_equal_the_old_unmarked_form_and_one_step_at_a_time():
    rng = np.random.default_rng(1)
    T = 5
    moving = ANCHORS + rng.uniform(-0.5, 0.5, (T, 4, 2))            # a receiver layout per step
    z = rng.normal(-60.0, 3.0, (3, T, 4))
    x0 = np.tile([6.0, 4.5, 0.0, 0.0], (3, 1))
    channel = lb.PathLossModel(-40.0, 2.5, 3.0, min_distance_m=0.1)
    marked = lb.extended_kalman_filter(CV.F, CV.Q, x0, np.eye(4),
                                       [lb.RssMeasurement(z, lb.per_step(moving), channel, [0, 1])])
    with pytest.warns(DeprecationWarning, match=r"mark them per_step\(anchors_m\)"):
        old = lb.RssMeasurement(z, moving, channel, [0, 1])
    np.testing.assert_array_equal(marked.mean, lb.extended_kalman_filter(CV.F, CV.Q, x0, np.eye(4), [old]).mean)
    # step k reads layout k: the same as filtering with the layout of each step given as a fixed model, step by step
    x, P = x0, np.broadcast_to(np.eye(4), (3, 4, 4))
    for k in range(T):
        x, P = x @ CV.F.T, CV.F @ P @ CV.F.T + CV.Q                 # the filter predicts before every update
        model = lb.RssModel(moving[k], channel, position_index=[0, 1])
        nu, H, R = model.innovation(x, z[:, k])
        S = H @ P @ np.swapaxes(H, -1, -2) + R
        K = P @ np.swapaxes(H, -1, -2) @ np.linalg.inv(S)
        x = x + (K @ nu[..., None])[..., 0]
        P = P - K @ H @ P
        np.testing.assert_allclose(x, marked.mean[:, k], rtol=0, atol=1e-9)


def test_the_factorys_forms():
    z = np.random.default_rng(2).normal(-60.0, 3.0, (2, 4, 4))
    channel = lb.PathLossModel(-40.0, 2.5, 3.0)
    by_model = lb.RssMeasurement(z, lb.RssModel(ANCHORS, channel, position_index=[0, 1]))
    by_keywords = lb.RssMeasurement(z, anchors_m=ANCHORS, channel=channel, position_index=[0, 1])
    x0 = np.tile([6.0, 4.5, 0.0, 0.0], (2, 1))
    np.testing.assert_array_equal(lb.extended_kalman_filter(CV.F, CV.Q, x0, np.eye(4), [by_model]).mean,
                                  lb.extended_kalman_filter(CV.F, CV.Q, x0, np.eye(4), [by_keywords]).mean)
    with pytest.raises(ValueError, match=r"RssMeasurement takes \(rss_dbm, model\) with model an RssModel .* got "
                                         r"PathLossModel as the model$"):
        lb.RssMeasurement(z, channel, position_index=[0, 1])
    with pytest.raises(ValueError,
                       match=r"a Kalman-family stream reads the state.s position components: give position_index"):
        lb.RssMeasurement(z, lb.RssModel(ANCHORS, channel))
