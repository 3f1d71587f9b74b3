"""The compiled UKF (locbook/tracking/_ukf_kernels.py) gives the numbers of the numpy UKF and of filterpy.

The compiled path runs when numba is enabled and the problem is large enough (``_NUMBA_MIN_WORK`` run-steps); here the
threshold is set to 0 and ``_NUMBA_ENABLED`` switched to compare the two paths on every option the kernel covers
(LinearMeasurement, RssMeasurement and inertial streams, parallel and serial, missing readings, the three sigma-point
sets, blocks of runs), on Gudipati's U-path (the benchmark's setting) against filterpy's UnscentedKalmanFilter, and
where it cannot update (the numpy loop's errors, unchanged).
"""
import sys
import warnings

import numpy as np
import pytest

import locbook as lb
from builders import REPO_ROOT
from locbook.tracking import _compiled as K
from locbook.tracking import unscented as U

sys.path.insert(0, str(REPO_ROOT / "benchmarks"))
import bench_ukf_speed as bu  # noqa: E402

pytestmark = pytest.mark.compiled

numba = pytest.importorskip("numba")

TOL = 1e-9


def _both(F, Q, x0, P0, streams, **kw):
    """(numpy result, compiled result, whether the compiled path gave the second)."""
    calls = []
    original = U._compiled_ukf
    saved = K._NUMBA_ENABLED, K._NUMBA_MIN_WORK
    try:
        K._NUMBA_ENABLED = False
        a = lb.unscented_kalman_filter(F, Q, x0, P0, streams, **kw)
        K._NUMBA_ENABLED, K._NUMBA_MIN_WORK = True, 0
        U._compiled_ukf = lambda *args: calls.append(original(*args)) or calls[-1]
        b = lb.unscented_kalman_filter(F, Q, x0, P0, streams, **kw)
    finally:
        U._compiled_ukf = original
        K._NUMBA_ENABLED, K._NUMBA_MIN_WORK = saved
    return a, b, bool(calls) and calls[-1] is not None


def _assert_same(a, b, tol=TOL):
    np.testing.assert_allclose(b.mean, a.mean, rtol=0, atol=tol)
    np.testing.assert_allclose(b.cov, a.cov, rtol=0, atol=tol)
    np.testing.assert_allclose(b.nis, a.nis, rtol=0, atol=tol * 100)       # NaN where no update, in both
    np.testing.assert_allclose(b.log_likelihood, a.log_likelihood, rtol=0, atol=tol * 100)
    np.testing.assert_array_equal(b.nis_dof, a.nis_dof)
    np.testing.assert_array_equal(b.steps, a.steps)
    assert b.floored_updates == a.floored_updates
    np.testing.assert_array_equal(b.diverged, a.diverged)


ANCHORS = np.array([[0.0, 0.0], [12.0, 0.0], [12.0, 9.0], [0.0, 9.0], [6.0, 4.5]])


def _case(kind, rng, B=5, T=50):
    """A small problem exercising one option of the compiled UKF (a constant-velocity walk among five anchors)."""
    model = lb.constant_velocity(0.5, 0.05)
    truth = np.cumsum(rng.normal(0, 0.3, (B, T, 2)), axis=1) + [6.0, 4.5]
    ch = lb.PathLossModel(-40.0, 2.5, 3.0, min_distance_m=0.1)
    power = ch.sample_rss_dbm(lb.pairwise_distance_m(truth, ANCHORS), rng=rng)
    power[rng.random(power.shape) < 0.2] = np.nan
    power[:, 5] = np.nan                                           # a step without any RSS reading
    x0 = np.concatenate([truth[:, 0] + rng.normal(0, 0.5, (B, 2)), np.zeros((B, 2))], axis=1)
    P0 = np.diag([1.0, 1.0, 0.3, 0.3])
    fixes = truth + rng.normal(0, 1.0, truth.shape)
    fixes[rng.random(fixes.shape) < 0.3] = np.nan
    H = model.position_measurement_matrix()
    kw = dict(alpha=0.5)
    rss = lambda **k: lb.RssMeasurement(power, ANCHORS, k.pop("channel", ch), model.position_index, **k)
    if kind == "rss_parallel":
        streams = [rss()]
    elif kind == "rss_serial_descending":
        streams = [rss(mode="serial")]
    elif kind == "rss_serial_given_with_fixes":
        streams = [lb.LinearMeasurement(fixes, H, np.diag([1.0, 1.5])), rss(mode="serial", order="given")]
    elif kind == "linear_parallel_correlated_R":
        streams = [lb.LinearMeasurement(fixes, H, np.array([[1.0, 0.3], [0.3, 1.5]]))]
    elif kind == "linear_serial_batched_R":
        R = np.stack([np.diag([1.0 + b, 0.5 + b]) for b in range(B)])
        streams = [lb.LinearMeasurement(fixes, H, R, mode="serial")]
    elif kind == "per_anchor_channel_and_anchor_sigma":
        ch2 = lb.PathLossModel(np.array([-40.0, -42.0, -38.0, -41.0, -39.0]), np.array([2.0, 2.5, 3.0, 2.2, 2.7]),
                               np.array([2.0, 3.0, 4.0, 2.5, 3.5]), min_distance_m=0.5)
        streams = [rss(channel=ch2, anchor_sigma_m=0.3), rss(channel=ch2, mode="serial", anchor_sigma_m=0.3)]
    elif kind == "batched_channel_no_clamp":
        ch3 = lb.PathLossModel(np.linspace(-42, -38, B)[:, None], np.linspace(2, 3, B)[:, None], 3.0)
        streams = [rss(channel=ch3)]
    elif kind == "tag_height":
        a3 = np.concatenate([ANCHORS, np.full((5, 1), 2.5)], axis=1)
        streams = [lb.RssMeasurement(power, a3, ch, model.position_index, tag_height_m=1.0),
                   lb.RssMeasurement(power, a3, ch, model.position_index, mode="serial", tag_height_m=1.0)]
    elif kind == "moving_receivers":
        moving = ANCHORS + rng.normal(0, 0.2, (B, T, 5, 2))
        streams = [lb.RssMeasurement(power, lb.per_step(moving), ch, model.position_index, anchor_sigma_m=0.2),
                   lb.RssMeasurement(power, lb.per_step(moving), ch, model.position_index, mode="serial")]
    elif kind == "record_and_no_predict_first":
        streams = [lb.LinearMeasurement(fixes, H, np.eye(2)), rss()]
        kw.update(record=[0, 7, 30, T - 1], predict_first=False)
    elif kind == "batched_P0_multidim_batch":
        streams = [lb.RssMeasurement(power.reshape(1, B, T, 5), ANCHORS, ch, model.position_index, mode="serial")]
        x0 = np.broadcast_to(x0, (2, B, 4))
        P0 = np.stack([P0 * (1 + b) for b in range(B)])
    elif kind in ("julier", "cubature"):
        streams = [rss(), lb.LinearMeasurement(fixes, H, np.eye(2))]
        kw.update(points=kind, kappa=1.0 if kind == "julier" else 0.0)
        del kw["alpha"]                                     # julier and cubature take no alpha (refused if given)
    elif kind == "printed_weights_of_eq_3_22":                   # the flagged variant: mean weights sum to 2n / c
        streams = [lb.LinearMeasurement(fixes, H, np.diag([1.0, 1.5])), rss(mode="serial", order="given")]
        kw.update(variant="literal_gudipati2017")
    elif kind == "alpha_1_beta_0_kappa_1":
        streams = [rss(mode="serial")]
        kw.update(alpha=1.0, beta=0.0, kappa=1.0)
    elif kind == "per_step_H_and_R":                               # R per step and run; H per step
        Rs = np.diag([1.0, 1.5]) * rng.uniform(0.5, 2.0, (B, T, 1, 1))
        Hs = H * rng.choice([0.5, 1.0], T)[:, None, None]
        streams = [lb.LinearMeasurement(fixes, lb.per_step(Hs), lb.per_step(Rs)), rss()]
    elif kind == "inertial_world_frame":                          # the readings read the velocity as "acceleration"
        acc = np.concatenate([np.diff(truth, axis=1, prepend=truth[:, :1]) / 0.5, rng.normal(0, 0.1, (B, T, 1))], -1)
        imu = lb.InertialMeasurement(np.diag([0.5, 0.5, 1.0]), n_state=model.F.shape[0], frame="world",
                                     acceleration_index=(2, 3), heading_index=0, yaw_rate_index=1,
                                     name="velocity + noise")
        streams = [lb.Stream(acc, imu), rss()]
    else:
        raise ValueError(kind)
    return model.F, model.Q, x0, P0, streams, kw


CASES = ["rss_parallel", "rss_serial_descending", "rss_serial_given_with_fixes", "linear_parallel_correlated_R",
         "linear_serial_batched_R", "per_anchor_channel_and_anchor_sigma", "batched_channel_no_clamp", "tag_height",
         "moving_receivers", "record_and_no_predict_first", "batched_P0_multidim_batch", "julier", "cubature",
         "printed_weights_of_eq_3_22", "alpha_1_beta_0_kappa_1", "inertial_world_frame", "per_step_H_and_R"]


@pytest.mark.parametrize("kind", CASES)
def test_compiled_ukf_equals_numpy_ukf(kind):
    a, b, compiled = _both(*_case(kind, np.random.default_rng(CASES.index(kind)))[:5],
                           **_case(kind, np.random.default_rng(CASES.index(kind)))[5])
    assert compiled, "the compiled path did not run"
    assert np.isfinite(a.mean).all() and (a.nis_dof > 0).any() and len(np.unique(a.nis_dof)) > 1    # some missing
    # the printed weights do not sum to 1 (2n / c): every step scales the round-off of the two summation orders, and
    # with numpy 2.4 the state (about 100) differs by 2e-9 after 48 steps; 1e-8 still catches a wrong formula
    _assert_same(a, b, tol=1e-8 if kind == "printed_weights_of_eq_3_22" else TOL)


@pytest.mark.parametrize("B, most_lanes", [(1, None), (70, None), (70, 32)])
def test_blocks_of_runs_and_a_single_run(B, most_lanes, monkeypatch):
    """70 runs: one block of 70 lanes, or with blocks of at most 32 lanes three blocks of 24 (the last padded with two
    copies of the last run); 1 run: one lane. Each run equals the same run filtered alone (numpy)."""
    from locbook.tracking import _compiled
    if most_lanes:
        monkeypatch.setattr(_compiled, "_BLOCK_LANES", most_lanes)
        assert _compiled._block_width(B) == 24
    F, Q, x0, P0, streams, kw = _case("rss_serial_given_with_fixes", np.random.default_rng(3), B=B, T=30)
    a, b, compiled = _both(F, Q, x0, P0, streams, **kw)
    assert compiled
    _assert_same(a, b)
    r = B - 1
    alone = lb.unscented_kalman_filter(F, Q, x0[r], P0, [lb.LinearMeasurement(streams[0].z[r], streams[0].H,
                                                                              streams[0].R),
                                                         lb.RssMeasurement(streams[1].rss_dbm[r], ANCHORS,
                                                                           streams[1].channel, [0, 1], mode="serial",
                                                                           order="given")], **kw)
    np.testing.assert_allclose(b.mean[r], alone.mean, rtol=0, atol=TOL)


@pytest.fixture(scope="module")
def upath():
    return bu.setting(12, steps=150)


@pytest.mark.parametrize("alpha", [0.5, 1.0])
def test_compiled_ukf_on_the_u_path_equals_numpy_and_filterpy(upath, alpha):
    """The benchmark's setting (body-frame inertial stream, then six anchors' RSS with some missing): the compiled path
    equals the numpy path and filterpy's UnscentedKalmanFilter run by run."""
    m = upath["model"]
    a, b, compiled = _both(m.F, m.Q, upath["x0"], upath["P0"], [upath["imu"], upath["rss"]], alpha=alpha, beta=2.0,
                           kappa=0.0)
    assert compiled
    _assert_same(a, b)
    ref_x, ref_P = bu.filterpy_ukf(upath, 3, alpha)
    np.testing.assert_allclose(b.mean[:3], ref_x, rtol=0, atol=TOL)
    np.testing.assert_allclose(b.cov[:3], ref_P, rtol=0, atol=TOL)


def test_compiled_ukf_at_alpha_1e_3_agrees_to_the_amplified_round_off(upath):
    """At the thesis's alpha = 1e-3 the weights are about -1e6 and 6e4: round-off (1e-16 relative) is amplified some
    1e6 times in the sigma-point sums, so two correct implementations differ by about 1e-8 (filterpy vs numpy: the
    tolerance of tests/tracking/test_compiled_equality.py)."""
    m = upath["model"]
    a, b, compiled = _both(m.F, m.Q, upath["x0"], upath["P0"], [upath["imu"], upath["rss"]], alpha=1e-3)
    assert compiled
    _assert_same(a, b, tol=1e-6)
    ref_x, ref_P = bu.filterpy_ukf(upath, 3, 1e-3)
    np.testing.assert_allclose(b.mean[:3], ref_x, rtol=0, atol=1e-6)


def test_the_compiled_path_keeps_the_numpy_errors(monkeypatch):
    """Where an update fails the kernel gives way and the numpy loop raises its error (the one of
    tests/tracking/test_unscented.py), and the compiled path stays on for the session."""
    rng = np.random.default_rng(4)
    model = lb.constant_velocity(1.0, 0.05)
    ch = lb.PathLossModel(-40.0, 2.5, 3.0)
    z = ch.sample_rss_dbm(lb.pairwise_distance_m(np.array([[5.0, 4.0]] * 10), ANCHORS[:4]), rng=rng)
    start = np.array([5.0, 4.0, 0.0, 0.0])
    meas = lb.RssMeasurement(z, ANCHORS[:4], ch, model.position_index)
    monkeypatch.setattr(K, "_NUMBA_ENABLED", True)
    monkeypatch.setattr(K, "_NUMBA_MIN_WORK", 0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(lb.SingularCovarianceError, match="step 0"):
            lb.unscented_kalman_filter(model.F, model.Q, start, np.diag([2.0, 2.0, 0.5, 0.5]), [meas],
                                       innovation_noise=False)
        with pytest.raises(lb.SingularCovarianceError, match="state covariance P is not positive definite at step 0"):
            lb.unscented_kalman_filter(np.eye(4), np.zeros((4, 4)), start, np.diag([2.0, 0.0, 0.5, 0.5]), [meas])
    # a channel without a clamp and the centre sigma point on an anchor: the numpy loop's error (after numpy's
    # divide-by-zero warning of log10(0))
    on = lb.RssMeasurement(z, ANCHORS[:4], lb.PathLossModel(-40.0, 2.5, 3.0, min_distance_m=0.0),
                           model.position_index)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", "divide by zero", RuntimeWarning)
        with pytest.raises(lb.SingularCovarianceError, match="step 0"):
            lb.unscented_kalman_filter(np.eye(4), np.zeros((4, 4)), np.zeros(4), np.eye(4), [on])
    assert K._NUMBA_ENABLED is True


def test_outputs_and_unsupported_streams_stay_in_numpy(monkeypatch):
    monkeypatch.setattr(K, "_NUMBA_MIN_WORK", 0)
    F, Q, x0, P0, streams, kw = _case("rss_parallel", np.random.default_rng(0))
    setup = U._setup(F, Q, x0, P0, streams, None, "ukf")
    w = U.unscented_weights(4, 0.5)
    assert U._compiled_ukf(setup, streams, True, w, True) is not None
    res = lb.unscented_kalman_filter(F, Q, x0, P0, streams, outputs=("x_pred",), **kw)
    assert res.x_pred is not None                     # the numpy loop recorded it
    generic = [lb.NonlinearMeasurement(streams[0].rss_dbm, lambda X: X[..., :2] @ np.ones((2, 5)), np.eye(5))]
    setup = U._setup(F, Q, x0, P0, generic, None, "ukf")
    assert U._compiled_ukf(setup, generic, True, w, True) is None       # a user's h: numpy
    monkeypatch.setattr(K, "_NUMBA_MIN_WORK", 10**9)
    setup = U._setup(F, Q, x0, P0, streams, None, "ukf")
    assert U._compiled_ukf(setup, streams, True, w, True) is None       # too small: no compilation wait


@pytest.mark.parametrize("heading_index", [6, -2])
def test_inertial_stream_with_an_index_from_the_end_equals_the_numpy_ukf(monkeypatch, heading_index):
    """The inertial h takes numpy indices, -2 included (the heading of an 8-state model); the kernel counts from 0,
    so such a stream stays in numpy (-2), and a positive index is compiled (6): both equal the numpy loop. Q per
    run is compiled too."""
    rng = np.random.default_rng(0)
    n, B, T = 8, 6, 40
    F = np.eye(n)
    F[0, 2] = F[1, 3] = F[2, 4] = F[3, 5] = F[6, 7] = 0.1
    Q = np.stack([np.eye(n) * 0.01 * (1 + i) for i in range(B)])
    x0, P0 = rng.normal(0.0, 1.0, (B, n)), 0.5 * np.eye(n)
    meas = lb.Stream(rng.normal(0.0, 1.0, (B, T, 3)),
                     lb.InertialMeasurement(0.1 * np.eye(3), n_state=n, heading_index=heading_index))
    monkeypatch.setattr(K, "_NUMBA_MIN_WORK", 0)
    monkeypatch.setattr(K, "_NUMBA_ENABLED", False)
    ref = lb.unscented_kalman_filter(F, Q, x0, P0, [meas], alpha=0.5)
    monkeypatch.setattr(K, "_NUMBA_ENABLED", True)
    calls = []
    original = U._compiled_ukf
    monkeypatch.setattr(U, "_compiled_ukf", lambda *a: calls.append(original(*a)) or calls[-1])
    ours = lb.unscented_kalman_filter(F, Q, x0, P0, [meas], alpha=0.5)
    assert (calls[0] is not None) == (heading_index >= 0)
    np.testing.assert_allclose(ours.mean, ref.mean, rtol=0, atol=1e-10)
    np.testing.assert_allclose(ours.cov, ref.cov, rtol=0, atol=1e-10)


@pytest.mark.parametrize("which", ["EKF", "UKF"])
def test_a_kernel_that_cannot_run_warns_once_and_the_numpy_loop_answers(monkeypatch, which):
    """numba failing inside a kernel (here: the kernel raises) gives one RuntimeWarning naming the filter, turns the
    compiled paths off for the session and returns the numpy loop's numbers."""
    from locbook.tracking import _kernels, _ukf_kernels
    F, Q, x0, P0, streams, kw = _case("rss_parallel", np.random.default_rng(0))
    run = lb.extended_kalman_filter if which == "EKF" else lb.unscented_kalman_filter
    kw = {} if which == "EKF" else kw
    monkeypatch.setattr(K, "_NUMBA_ENABLED", False)
    ref = run(F, Q, x0, P0, streams, **kw)

    def broken(*args):
        raise RuntimeError("no LLVM here")

    monkeypatch.setattr(_kernels if which == "EKF" else _ukf_kernels, "_nb_ekf" if which == "EKF" else "_nb_ukf",
                        broken)
    monkeypatch.setattr(K, "_NUMBA_ENABLED", True)
    monkeypatch.setattr(K, "_NUMBA_MIN_WORK", 0)
    failed = f"the compiled {which} failed \\(RuntimeError: no LLVM here\\)"
    with pytest.warns(RuntimeWarning, match=failed) as caught:
        ours = run(F, Q, x0, P0, streams, **kw)
    assert [w.filename for w in caught] == [__file__]                 # once, at the caller's line
    assert K._NUMBA_ENABLED is False
    np.testing.assert_array_equal(ours.mean, ref.mean)
    np.testing.assert_array_equal(ours.cov, ref.cov)
