"""Document 000 (Dogan 2015), Ch. 3 fusion: the readings of the filter's Q and P_0, the default printed as constants
(Q = 0.000023 I_6 per step, P_0,acc = 0.00023, Eqs. (3.20), (3.24); the node starting from rest) and the alternative
fitted to Table 3.9 (Q = sigma_ACC^2 / 10 I_6, P_0,acc = sigma_ACC^2), checked against the printed constants and
against an independent filterpy implementation written here from the thesis's equations (Tables 3.1-3.5,
Eqs. (3.18)-(3.24)), without calling locbook's filters; and which rows each reading makes calibrations."""
import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter

import locbook as lb
from locbook.scenarios import dogan as dg

P = lb.printed("dogan2015")


def test_printed_constants_are_the_sigma_acc_reading_at_table_3_6():
    """Eq. (3.24)'s Q and Eq. (3.20)'s acceleration variance are sigma_ACC^2 / 10 and sigma_ACC^2 at Table 3.6's
    sigma_ACC, to the printed digits (half a unit in the last printed digit)."""
    sigma = P.get("Table 3.6", "standard deviation of acceleration sigma_ACC")
    q = P.get("Eq. (3.24)", "process noise covariance Q", "per-step variance (Q = value x I_6)")
    p0 = P.get("Eq. (3.20)", "P_0|0", "acceleration variance")
    assert abs(sigma.value**2 / 10 - q.value) <= q.rounding
    assert abs(sigma.value**2 - p0.value) <= p0.rounding
    # and the process-noise standard deviation printed in Sec. 4.1.2 is sqrt(Q)
    sd = P.get("Sec. 4.1.2 text", "process noise", "standard deviation")
    assert abs(np.sqrt(q.value) - sd.value) <= sd.rounding
    # the reading itself
    assert dg.filter_noise("sigma_acc", None) == pytest.approx((sigma.value**2 / 10, sigma.value**2), rel=1e-12)
    assert dg.filter_noise("sigma_acc", 0.0015) == pytest.approx((0.0015**2 / 10, 0.0015**2), rel=1e-12)
    assert dg.filter_noise("printed", 0.0015) == (q.value, p0.value)
    with pytest.raises(lb.ParameterError):
        dg.filter_noise("guessed", 0.01)


def _ca_matrices(dt, q):
    """Eq. (3.11) in the per-axis layout of Eq. (3.10), written out; Q = q I_6 (Eq. (3.24))."""
    block = np.array([[1.0, dt, dt**2 / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
    F = np.zeros((6, 6))
    F[:3, :3] = F[3:, 3:] = block
    return F, q * np.eye(6)


def _filterpy_fusion(name, rss_dbm, fixes_m, mse_m2, acc, sigma_acc, rss_steps, n_steps, dt, anchors, p0_dbm, ple,
                     sigma_rss, q, acc_var):
    """Table 3.5 per run with filterpy: prediction, then the accelerometer (Eq. (3.18), R = sigma_acc^2 I), then at
    RSS epochs KF (MLE) (Eq. (3.21)) or the parallel / serial EKF (Tables 3.3-3.4, Eq. (3.22)). Q = q I_6 and
    P_0 = diag(MSE_x, 0.0065, acc_var, MSE_y, 0.0065, acc_var) (Eqs. (3.19)-(3.20), (3.24)).
    Returns the position estimates at the RSS epochs, (runs, epochs, 2)."""
    vel_var = P.get("Eq. (3.20)", "P_0|0", "velocity variance").value
    F, Q = _ca_matrices(dt, q)
    h_acc = np.zeros((2, 6))
    h_acc[0, 2] = h_acc[1, 5] = 1.0
    h_pos = np.zeros((2, 6))
    h_pos[0, 0] = h_pos[1, 3] = 1.0

    def h(x, j):
        return np.atleast_1d(p0_dbm - 10 * ple * np.log10(np.hypot(x[0] - anchors[j, 0], x[3] - anchors[j, 1])))

    def jac(x, j):
        j = np.atleast_1d(j)
        dx, dy = x[0] - anchors[j, 0], x[3] - anchors[j, 1]
        d2 = dx**2 + dy**2
        out = np.zeros((len(j), 6))
        out[:, 0], out[:, 3] = -10 * ple / np.log(10) * dx / d2, -10 * ple / np.log(10) * dy / d2
        return out

    out = np.empty(fixes_m.shape)
    for b in range(rss_dbm.shape[0]):
        f = ExtendedKalmanFilter(6, 1)
        f.x = np.array([fixes_m[b, 0, 0], 0, 0, fixes_m[b, 0, 1], 0, 0], float)
        f.P = np.diag([mse_m2[0], vel_var, acc_var, mse_m2[1], vel_var, acc_var])
        f.F, f.Q = F, Q
        out[b, 0] = f.x[[0, 3]]
        epoch = 1
        for k in range(rss_steps[0] + 1, n_steps):
            f.predict()
            f.update(acc[b, k], lambda x: h_acc, lambda x: h_acc @ x, R=sigma_acc**2 * np.eye(2))
            if epoch < len(rss_steps) and k == rss_steps[epoch]:
                z = rss_dbm[b, epoch]
                if name == "kalman_filter":
                    f.update(fixes_m[b, epoch], lambda x: h_pos, lambda x: h_pos @ x, R=np.diag(mse_m2))
                elif name == "parallel_ekf":
                    f.update(z, lambda x: jac(x, np.arange(4)), lambda x: np.concatenate([h(x, j) for j in range(4)]),
                             R=sigma_rss**2 * np.eye(4))
                else:
                    for j in np.argsort(-z):                 # Table 3.3: strongest anchor first
                        f.update(z[j:j + 1], lambda x, j=j: jac(x, j), lambda x, j=j: h(x, j),
                                 R=np.array([[sigma_rss**2]]))
                out[b, epoch] = f.x[[0, 3]]
                epoch += 1
    return out


@pytest.mark.parametrize("reading", ["printed", "sigma_acc"])
@pytest.mark.parametrize("name", ["kalman_filter", "parallel_ekf", "serial_ekf"])
def test_each_reading_equals_an_independent_filterpy_implementation(name, reading):
    """run_channel from rest under each noise reading against the filterpy loop above on the same draws: the RSS,
    the MLE fixes and the accelerometer noise are replayed from the same seed in run_channel's order (RSS, then one
    unit accelerometer noise draw scaled per sigma_ACC). Q and P_0,acc come from the printed constants ('printed')
    or from sigma_ACC ('sigma_acc'), written here, not from filter_noise."""
    assert (dg.DEFAULT_START, dg.DEFAULT_NOISE_INTERPRETATION) == ("rest", "printed")
    tr = dg.walk_trajectory(waypoints_m=((1.0, 1.0), (1.0, 4.0), (4.0, 4.0)), speed_m_s=0.5)
    assert tr.start == "rest" and np.all(tr.velocity_m_s[0] == 0.0)
    n_runs, sigmas = 3, (0.0075, 0.0015)
    run = dg.run_channel(tr, 6.0, 3.0, n_runs, np.random.default_rng(11), sigma_acc_values=sigmas, only_rss=False,
                         filters=(name,), keep_estimates=True, noise_interpretation=reading)
    q_printed = P.get("Eq. (3.24)", "process noise covariance Q", "per-step variance (Q = value x I_6)").value
    acc_printed = P.get("Eq. (3.20)", "P_0|0", "acceleration variance").value
    rng = np.random.default_rng(11)
    channel = lb.PathLossModel(dg.REF_POWER_DBM, 3.0, 6.0)
    rss = dg.simulate_rss(tr, channel, n_runs, rng)
    fixes = dg.mle_positions(rss, channel).position_m
    mse = np.mean((fixes - tr.position_m[tr.rss_steps]) ** 2, axis=(0, 1))
    np.testing.assert_allclose(run.mse_mle_m2, mse, rtol=1e-12)
    unit = rng.standard_normal((n_runs,) + tr.acceleration_m_s2.shape)
    for sigma in sigmas:
        q, acc_var = (q_printed, acc_printed) if reading == "printed" else (sigma**2 / 10, sigma**2)
        ref = _filterpy_fusion(name, rss, fixes, mse, tr.acceleration_m_s2 + sigma * unit, sigma, tr.rss_steps,
                               tr.time_s.size, dg.DT_S, dg.ANCHORS_M, dg.REF_POWER_DBM, 3.0, 6.0, q, acc_var)
        np.testing.assert_allclose(run.errors[("estimates", name, sigma)], ref, atol=1e-8)


@pytest.mark.parametrize("sigma_acc", [None, 0.15, 0.015, 0.0152, 0.0075, 0.0015, 1e-6])
def test_the_default_reading_is_eq_3_24s_constant_q_for_any_sigma_acc(sigma_acc):
    """The default (the text's reading) is Q = 0.000023 I_6 per step (Eq. (3.24)) and P_0,acc = 0.00023
    (Eq. (3.20)) whatever sigma_ACC; Sec. 4.1.2's process-noise sd 0.0048 is its square root to the printed digits."""
    q = P.get("Eq. (3.24)", "process noise covariance Q", "per-step variance (Q = value x I_6)")
    p0 = P.get("Eq. (3.20)", "P_0|0", "acceleration variance")
    assert dg.filter_noise(dg.DEFAULT_NOISE_INTERPRETATION, sigma_acc) == (q.value, p0.value) == (0.000023, 0.00023)
    sd = P.get("Sec. 4.1.2 text", "process noise", "standard deviation")
    assert abs(np.sqrt(dg.filter_noise(dg.DEFAULT_NOISE_INTERPRETATION, sigma_acc)[0]) - sd.value) <= sd.rounding


def test_calibrated_from_text_names_exactly_the_readings_fitted_to_output():
    """The basis rule for the four (start, noise reading) pairs: rest + printed is the text's own reading (no
    calibration); the moving start, which no text supports, is fitted with the speed fitted to Fig. 3.2 under it,
    'sigma_acc' the Q fitted to Table 3.9, and both together name both; under another speed the moving start is still
    fitted (the speed itself is then an assumption)."""
    assert dg.calibrated_from_text("rest", "printed") == ""
    moving = dg.calibrated_from_text("moving", "printed")
    assert "Fig. 3.2" in moving and "24 meter" in moving and "Table 3.9" not in moving
    scaled = dg.calibrated_from_text("rest", "sigma_acc")
    assert "Table 3.9" in scaled and "sigma_acc" in scaled and "Fig. 3.2" not in scaled
    both = dg.calibrated_from_text("moving", "sigma_acc")
    assert both == f"{moving}; {scaled}"
    other_speed = dg.calibrated_from_text("moving", "printed", speed_mps=0.5)
    assert (other_speed == dg.MOVING_START_FITTED and "no text" in other_speed
            and dg.SPEED_CALIBRATED_FROM not in other_speed)
    assert dg.calibrated_from_text() == ""                                    # the defaults are the text's readings
    with pytest.raises(lb.ParameterError, match="start"):
        dg.calibrated_from_text("running", "printed")
    with pytest.raises(lb.ParameterError, match="noise_interpretation"):
        dg.calibrated_from_text("rest", "guessed")


def test_the_printed_reading_does_not_see_sigma_acc_in_q():
    """Under the printed constants, the KF (MLE) prediction covariance is the same for every sigma_ACC, so a
    sigma_ACC sweep moves it only through R_acc; under the sigma_ACC reading Q itself scales with sigma_ACC^2."""
    q_printed = {s: dg.filter_noise("printed", s)[0] for s in (0.015, 0.0075, 0.0015)}
    q_scaled = {s: dg.filter_noise("sigma_acc", s)[0] for s in (0.015, 0.0075, 0.0015)}
    assert len(set(q_printed.values())) == 1
    assert (q_scaled[0.015] / q_scaled[0.0075] == pytest.approx(4.0)
            and q_scaled[0.0075] / q_scaled[0.0015] == pytest.approx(25.0))


def test_thesis_repeat_error_from_the_printed_re_runs():
    """The relative standard error of a printed cell from the thesis's re-runs of one setting, recomputed by hand from
    the seven printed pairs (Table 3.11 alpha = 3 vs Table 3.7 6 dB; Table 3.12 alpha = 3 vs Table 3.8 6 dB)."""
    cells = {(p.location, p.item, p.statistic): p.value for p in P}
    pairs = [(("Table 3.11", "ple=3"), ("Table 3.7", "sigma_rss_db=6"), c)
             for c in ("static_mle", "parallel_ekf", "serial_ekf", "kalman_filter")]
    pairs += [(("Table 3.12", "ple=3"), ("Table 3.8", "sigma_rss_db=6"), c)
              for c in ("parallel_ekf", "serial_ekf", "kalman_filter")]
    rel = [(cells[a + (c,)] - cells[b + (c,)]) / ((cells[a + (c,)] + cells[b + (c,)]) / 2) for a, b, c in pairs]
    assert dg.thesis_repeat_error() == pytest.approx(np.sqrt(np.mean(np.square(rel)) / 2), rel=1e-12)
    assert 0.005 < dg.thesis_repeat_error() < 0.02                       # 0.2-2.7 % differences (Tables 3.7-3.12)


def test_fusion_gain_and_mean_level_by_hand():
    """The fusion reduction of pooled RMSEs and the mean level of the three filters, recomputed by hand; the jackknife
    standard error of one pooled RMSE agrees with the delta method, SE(MSE) / (2 RMSE)."""
    rng = np.random.default_rng(5)
    errors = {}
    for f in dg.FILTERS:
        errors[(f, None)] = rng.gamma(2.0, 1.0, (300, 7))
        errors[(f, 0.5)] = 0.7 * errors[(f, None)] * rng.uniform(0.8, 1.2, (300, 7))
    run = dg.ChannelRun(6.0, 3.0, np.zeros(2), errors)
    rmse = {k: np.sqrt(np.mean(v**2)) for k, v in errors.items()}
    gain, gain_se, each = dg.fusion_gain_pct(run, 0.5)
    for f in dg.FILTERS:
        assert each[f] == pytest.approx(100 * (1 - rmse[(f, 0.5)] / rmse[(f, None)]), rel=1e-12)
    assert gain == pytest.approx(np.mean(list(each.values())), rel=1e-12) and 0 < gain_se < 2
    level, _, levels = dg.mean_rmse_m(run, 0.5)
    assert level == pytest.approx(np.mean([rmse[(f, 0.5)] for f in dg.FILTERS]), rel=1e-12)
    one, one_se, _ = dg.mean_rmse_m(run, None, filters=("kalman_filter",))
    per_run = np.mean(errors[("kalman_filter", None)] ** 2, axis=1)
    assert one_se == pytest.approx(per_run.std(ddof=1) / np.sqrt(per_run.size) / (2 * one), rel=0.02)


@pytest.mark.parametrize("fusion", [False, True])
def test_per_epoch_r_equals_the_filter_run_one_segment_at_a_time(fusion):
    """KF (MLE) with a per-epoch R (Table 4.1's R_{k+1}; one filter with R per step) equals the filter run one
    inter-epoch segment at a time, each with its epoch's R and starting from the previous segment's posterior."""
    tr = dg.walk_trajectory(waypoints_m=((1.0, 1.0), (1.0, 4.0), (4.0, 4.0)), speed_m_s=0.5)
    rng = np.random.default_rng(3)
    channel = lb.PathLossModel(dg.REF_POWER_DBM, 3.0, 6.0)
    rss = dg.simulate_rss(tr, channel, 4, rng)
    fix = dg.mle_positions(rss, channel).position_m
    mse = rng.uniform(0.2, 2.0, (tr.rss_steps.size, 2))                    # a different R at every epoch
    acc = dg.simulate_acceleration(tr, 0.0075, 4, rng) if fusion else None
    kw = dict(acc_mps2=acc, sigma_acc_mps2=0.0075 if fusion else None)
    ours = dg.run_filter("kalman_filter", tr, rss, fix, mse, channel, **kw)
    model = dg.motion_model()
    x0, P0, acc_streams, at, z = dg.filter_inputs("kalman_filter", tr, rss, fix, mse, channel, model=model, **kw)
    H = model.position_measurement_matrix()
    x, P, xs, nis, start = x0, np.broadcast_to(P0, x0.shape[:-1] + (6, 6)), [x0], [], 0
    for e, end in enumerate(list(at) + [z.shape[-2] - 1], start=1):
        part = [lb.LinearMeasurement(m.z[..., start:end + 1, :], m.H, m.R) for m in acc_streams]
        part.append(lb.LinearMeasurement(z[..., start:end + 1, :], H, np.diag(mse[min(e, len(mse) - 1)])))
        track = lb.extended_kalman_filter(model.F, model.Q, x, P, part)
        x, P = track.mean[..., -1, :], track.cov[..., -1, :, :]
        xs.append(x)
        nis.append(track.nis)
        start = end + 1
    np.testing.assert_allclose(ours.mean, np.stack(xs[:-1], axis=-2), rtol=0, atol=1e-9)
    np.testing.assert_allclose(ours.nis[..., -z.shape[-2]:], np.concatenate(nis, axis=-1), rtol=1e-9)


@pytest.mark.parametrize("fusion", [False, True])
def test_per_epoch_r_with_equal_epochs_equals_the_constant_r(fusion):
    """KF (MLE) with a per-epoch R (Table 4.1's R_{k+1}, run segment by segment) equals the one-pass filter when every
    epoch has the same R: segmenting the multi-rate filter changes nothing."""
    tr = dg.walk_trajectory(waypoints_m=((1.0, 1.0), (1.0, 4.0), (4.0, 4.0)), speed_m_s=0.5)
    rng = np.random.default_rng(2)
    channel = lb.PathLossModel(dg.REF_POWER_DBM, 3.0, 6.0)
    rss = dg.simulate_rss(tr, channel, 4, rng)
    fix = dg.mle_positions(rss, channel).position_m
    mse = np.mean((fix - tr.position_m[tr.rss_steps]) ** 2, axis=(0, 1))
    acc = dg.simulate_acceleration(tr, 0.0075, 4, rng) if fusion else None
    kw = dict(acc_mps2=acc, sigma_acc_mps2=0.0075 if fusion else None)
    one = dg.run_filter("kalman_filter", tr, rss, fix, mse, channel, **kw)
    seg = dg.run_filter("kalman_filter", tr, rss, fix, np.tile(mse, (tr.rss_steps.size, 1)), channel, **kw)
    np.testing.assert_allclose(seg.mean, one.mean, atol=1e-10)
    np.testing.assert_allclose(seg.cov, np.broadcast_to(one.cov, seg.cov.shape), atol=1e-12)
    with pytest.raises(lb.ParameterError, match="per-epoch"):
        dg.run_filter("serial_ekf", tr, rss, fix, np.tile(mse, (tr.rss_steps.size, 1)), channel)
