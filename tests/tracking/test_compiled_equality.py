"""The fast filters give the numbers of a per-run filterpy loop (not a timing test).

On small instances of the two benchmark settings, the Dogan (2015) fusion setting (benchmarks/bench_dogan_filters.py:
KF (MLE), parallel and serial EKF) and Gudipati's UKF U-path (benchmarks/bench_ukf_speed.py), locbook's batched output
equals the benchmarks' filterpy loops to 1e-9 on every path (numpy; the compiled EKF when numba is installed). The
KF's one-covariance path (the same components missing in every run) equals the batched path and filterpy, and the
compiled EKF equals the numpy EKF on every stream option it supports (and gives way to numpy, with its errors, where it
cannot update).
"""
import sys
import warnings

import numpy as np
import pytest

import locbook as lb
from builders import REPO_ROOT
from locbook.tracking import _compiled as K
from locbook.tracking import _loop
from oracles import filterpy_kalman

sys.path.insert(0, str(REPO_ROOT / "benchmarks"))
import bench_dogan_filters as bd  # noqa: E402
import bench_ukf_speed as bu  # noqa: E402

pytestmark = pytest.mark.compiled

try:
    import numba  # noqa: F401
    HAVE_NUMBA = True
except ImportError:
    HAVE_NUMBA = False

PATHS = ["numpy"] + (["numba"] if HAVE_NUMBA else [])
TOL = 1e-9


@pytest.fixture
def path(request, monkeypatch):
    """Run the EKF on the named path whatever the problem size."""
    monkeypatch.setattr(K, "_NUMBA_ENABLED", request.param == "numba")
    monkeypatch.setattr(K, "_NUMBA_MIN_WORK", 0)
    return request.param


@pytest.fixture(scope="module")
def dogan():
    return bd.setting(20, steps=200)


@pytest.mark.parametrize("path", PATHS, indirect=True)
@pytest.mark.parametrize("name", bd.FILTERS)
def test_dogan_filters_equal_filterpy(dogan, name, path):
    ours = bd.locbook_filter(name, dogan)
    ref_x, ref_P = bd.filterpy_filter(name, dogan, 20)
    dx, dP = bd.max_difference(dogan, ours, ref_x, ref_P)
    assert ours.mean.shape == (20, dogan["tr"].rss_steps.size, 6)
    assert dx < TOL and dP < TOL, (dx, dP)


@pytest.mark.parametrize("path", PATHS, indirect=True)
def test_compiled_path_is_taken_for_the_ekfs(dogan, path):
    calls = []
    original = K._compiled_ekf
    try:
        K._compiled_ekf = lambda *a: calls.append(original(*a)) or calls[-1]
        bd.locbook_filter("serial_ekf", dogan)
        bd.locbook_filter("kalman_filter", dogan)
    finally:
        K._compiled_ekf = original
    assert (calls[0] is not None) == (path == "numba")
    # KF (MLE), one covariance for all runs: at 20 runs (one block of lanes) compiled too; numpy turns it off
    assert len(calls) == (2 if path == "numba" else 1) and (calls[-1] is not None) == (path == "numba")


@pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed")
def test_a_covariance_shared_by_many_runs_stays_in_numpy(monkeypatch):
    """More runs than one block of lanes with one covariance for all: the numpy loop updates it once per step (the
    kernel is not called), and gives the kernel's numbers."""
    monkeypatch.setattr(K, "_NUMBA_ENABLED", True)
    monkeypatch.setattr(K, "_NUMBA_MIN_WORK", 0)
    s = bd.setting(65, steps=60)
    calls = []
    original = K._compiled_ekf
    monkeypatch.setattr(K, "_compiled_ekf", lambda *a: calls.append(original(*a)) or calls[-1])
    shared = bd.locbook_filter("kalman_filter", s)
    assert calls == []
    small = {k: (v[:64] if isinstance(v, np.ndarray) and v.ndim >= 2 and v.shape[0] == 65 else v) for k, v in s.items()}
    compiled = bd.locbook_filter("kalman_filter", small)
    assert len(calls) == 1 and calls[0] is not None
    np.testing.assert_allclose(compiled.mean, shared.mean[:64], rtol=0, atol=1e-10)
    np.testing.assert_allclose(compiled.cov, shared.cov[:64], rtol=0, atol=1e-12)


def _kf_reference(z, F, H, Q, R, x0, P0):
    """filterpy's KalmanFilter per run, updating with the components present (reduced H and R)."""
    return filterpy_kalman(F, Q, H, R, z, x0, P0, per_run=("x0",), components=True)


@pytest.mark.parametrize("uniform", [True, False])
def test_kalman_filter_on_dogan_fixes_equals_filterpy(dogan, uniform):
    """lb.kalman_filter on the MLE fixes (R = diag(MSE)): with the same fixes missing in every run the covariance is
    computed once per step (shared path); a fix missing in one run only sends it through the batched path."""
    s = dogan
    model, tr = s["model"], s["tr"]
    z = np.full((20, tr.time_s.size, 2), np.nan)
    z[:, tr.rss_steps] = s["fix"]
    if not uniform:
        z[3, tr.rss_steps[4]] = np.nan
        z[5, tr.rss_steps[6], 1] = np.nan
    assert (_loop._shared_pattern(z) is not None) == uniform
    x0, P0 = bd.dg.initial_state(s["fix"][:, 0], s["mse"], acc_var=s["p0_acc"])
    R = np.diag(s["mse"])
    H = model.position_measurement_matrix()
    res = lb.kalman_filter(model.F, model.Q, x0, P0, lb.LinearMeasurement(z, H, R), outputs=("innovation",))
    ref_x, ref_P = _kf_reference(z, model.F, H, model.Q, R, x0, P0)
    np.testing.assert_allclose(res.mean, ref_x, rtol=0, atol=TOL)
    np.testing.assert_allclose(res.cov, ref_P, rtol=0, atol=TOL)
    for b in (0, 3):                  # batched = one run at a time
        one = lb.kalman_filter(model.F, model.Q, x0[b], P0, lb.LinearMeasurement(z[b], H, R),
                               outputs=("innovation",))
        np.testing.assert_allclose(res.mean[b], one.mean, rtol=0, atol=1e-12)
        np.testing.assert_allclose(res.innovation[b], one.innovation, rtol=0, atol=1e-12)


@pytest.fixture(scope="module")
def upath():
    return bu.setting(20, steps=200)


@pytest.mark.parametrize("alpha, runs, tol", [
    (0.5, 20, TOL),
    (1.0, 20, TOL),
    # Gudipati's alpha = 1e-3: weights -1e6 and 6e4, so round-off (about 1e-16 relative) is amplified some 1e6 times in
    # the sigma-point sums; two correct implementations then differ by about 1e-8 (the pre-issue-18 code differed from
    # filterpy by 1.5e-8 on this instance too)
    (1e-3, 5, 1e-7),
])
@pytest.mark.slow
def test_ukf_on_the_u_path_equals_filterpy(upath, alpha, runs, tol):
    ours = bu.locbook_ukf(upath, alpha)
    ref_x, ref_P = bu.filterpy_ukf(upath, runs, alpha)
    assert np.isnan(np.asarray(upath["rss"].rss_dbm)[:runs]).any()        # some steps with an anchor not heard
    np.testing.assert_allclose(ours.mean[:runs], ref_x, rtol=0, atol=tol)
    np.testing.assert_allclose(ours.cov[:runs], ref_P, rtol=0, atol=tol)
    assert ours.floored_updates == 0


# ------------------------------------------------------------------------------------------------------------------
# The compiled EKF equals the numpy EKF on every option it supports
# ------------------------------------------------------------------------------------------------------------------

def _both(F, Q, x0, P0, streams, **kw):
    """(numpy result, compiled result, whether the compiled path ran)."""
    saved = K._NUMBA_ENABLED, K._NUMBA_MIN_WORK
    try:
        K._NUMBA_ENABLED = False
        a = lb.extended_kalman_filter(F, Q, x0, P0, streams, **kw)
        K._NUMBA_ENABLED, K._NUMBA_MIN_WORK = True, 0
        setup = _loop._setup(F, Q, x0, P0, streams, kw.get("record"), "extended_kalman_filter")
        compiled = K._compiled_ekf(setup, streams, kw.get("predict_first", True))
        b = lb.extended_kalman_filter(F, Q, x0, P0, streams, **kw)
    finally:
        K._NUMBA_ENABLED, K._NUMBA_MIN_WORK = saved
    return a, b, compiled is not None


def _case(kind, rng, B=5):
    """A small multi-stream problem of ``B`` runs exercising one option of the compiled EKF."""
    model = lb.constant_velocity(0.5, 0.05)
    T = 60
    anchors = np.array([[0.0, 0.0], [12.0, 0.0], [12.0, 9.0], [0.0, 9.0], [6.0, 4.5]])
    truth = np.cumsum(rng.normal(0, 0.3, (B, T, 2)), axis=1) + [6.0, 4.5]
    ch = lb.PathLossModel(-40.0, 2.5, 3.0)
    power = ch.sample_rss_dbm(lb.pairwise_distance_m(truth, anchors), rng=rng)
    power[rng.random(power.shape) < 0.2] = np.nan
    x0 = np.concatenate([truth[:, 0] + rng.normal(0, 0.5, (B, 2)), np.zeros((B, 2))], axis=1)
    P0 = np.diag([1.0, 1.0, 0.3, 0.3])
    fixes = truth + rng.normal(0, 1.0, truth.shape)
    fixes[rng.random(fixes.shape) < 0.3] = np.nan
    H = model.position_measurement_matrix()
    kw = {}
    if kind == "parallel":
        streams = [lb.RssMeasurement(power, anchors, ch, model.position_index)]
    elif kind == "serial_descending":
        streams = [lb.RssMeasurement(power, anchors, ch, model.position_index, mode="serial")]
    elif kind == "serial_given_with_fixes":
        streams = [lb.LinearMeasurement(fixes, H, np.diag([1.0, 1.5])),
                   lb.RssMeasurement(power, anchors, ch, model.position_index, mode="serial", order="given")]
    elif kind == "linear_serial_batched_R":
        R = np.stack([np.diag([1.0 + b, 0.5 + b]) for b in range(B)])
        streams = [lb.LinearMeasurement(fixes, H, R, mode="serial")]
    elif kind == "linear_nonuniform_missing":
        streams = [lb.LinearMeasurement(fixes, H, np.array([[1.0, 0.3], [0.3, 1.5]]))]
    elif kind == "per_anchor_channel_and_anchor_sigma":
        ch2 = lb.PathLossModel(np.array([-40.0, -42.0, -38.0, -41.0, -39.0]), np.array([2.0, 2.5, 3.0, 2.2, 2.7]),
                               np.array([2.0, 3.0, 4.0, 2.5, 3.5]), min_distance_m=0.5)
        streams = [lb.RssMeasurement(power, anchors, ch2, model.position_index, anchor_sigma_m=0.3),
                   lb.RssMeasurement(power, anchors, ch2, model.position_index, mode="serial", anchor_sigma_m=0.3)]
    elif kind == "batched_channel":
        ch3 = lb.PathLossModel(np.linspace(-42, -38, B)[:, None], np.linspace(2, 3, B)[:, None], 3.0)
        streams = [lb.RssMeasurement(power, anchors, ch3, model.position_index)]
    elif kind == "tag_height":
        a3 = np.concatenate([anchors, np.full((5, 1), 2.5)], axis=1)
        streams = [lb.RssMeasurement(power, a3, ch, model.position_index, tag_height_m=1.0),
                   lb.RssMeasurement(power, a3, ch, model.position_index, mode="serial", tag_height_m=1.0)]
    elif kind == "moving_receivers":
        moving = anchors + rng.normal(0, 0.2, (B, T, 5, 2))
        streams = [lb.RssMeasurement(power, lb.per_step(moving), ch, model.position_index, anchor_sigma_m=0.2),
                   lb.RssMeasurement(power, lb.per_step(moving), ch, model.position_index, mode="serial")]
    elif kind == "record_and_no_predict_first":
        streams = [lb.LinearMeasurement(fixes, H, np.eye(2)),
                   lb.RssMeasurement(power, anchors, ch, model.position_index)]
        kw = dict(record=[0, 7, 30, 59], predict_first=False)
    elif kind == "batched_P0_multidim_batch":
        streams = [lb.RssMeasurement(power.reshape(1, B, T, 5), anchors, ch, model.position_index, mode="serial")]
        x0 = np.broadcast_to(x0, (2, B, 4))
        P0 = np.stack([P0 * (1 + b) for b in range(B)])
    elif kind == "per_step_H_and_R":                 # R per step and run, H per step; one of each for all steps
        Rs = np.diag([1.0, 1.5]) * rng.uniform(0.5, 2.0, (B, T, 1, 1))
        Hs = H * rng.choice([0.5, 1.0], T)[:, None, None]
        streams = [lb.LinearMeasurement(fixes, lb.per_step(Hs), lb.per_step(Rs)),
                   lb.LinearMeasurement(fixes, lb.per_step(Hs[:1]), lb.per_step(Rs[0]), mode="serial"),
                   lb.RssMeasurement(power, anchors, ch, model.position_index)]
    elif kind == "one_state_column":                 # rows that read one state component (one nonzero in all)
        streams = [lb.LinearMeasurement(fixes[..., :1], H[:1], np.array([[1.2]])),
                   lb.LinearMeasurement(fixes[..., 1:], H[1:], np.array([[0.8]]), mode="serial")]
    elif kind == "three_rows_three_columns":         # the general loops: 3 rows, 3 nonzero columns
        H3 = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 0.0], [1.0, 0.0, 0.5, 0.0]])
        z3 = np.concatenate([fixes, fixes[..., :1] + rng.normal(0, 0.5, (B, T, 1))], axis=-1)
        streams = [lb.LinearMeasurement(z3, H3, np.diag([1.0, 1.5, 2.0]))]
    else:
        raise ValueError(kind)
    return model.F, model.Q, x0, P0, streams, kw


CASES = ["parallel", "serial_descending", "serial_given_with_fixes", "linear_serial_batched_R",
         "linear_nonuniform_missing", "per_anchor_channel_and_anchor_sigma", "batched_channel", "tag_height",
         "moving_receivers", "record_and_no_predict_first", "batched_P0_multidim_batch", "per_step_H_and_R",
         "one_state_column", "three_rows_three_columns"]


@pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed: only the numpy path exists")
@pytest.mark.parametrize("kind", CASES)
def test_compiled_ekf_equals_numpy_ekf(kind):
    F, Q, x0, P0, streams, kw = _case(kind, np.random.default_rng(CASES.index(kind)))
    a, b, compiled = _both(F, Q, x0, P0, streams, **kw)
    assert compiled
    assert a.mean.shape == b.mean.shape and a.cov.shape == b.cov.shape
    np.testing.assert_array_equal(a.steps, b.steps)
    np.testing.assert_allclose(b.mean, a.mean, rtol=0, atol=TOL)
    np.testing.assert_allclose(b.cov, a.cov, rtol=0, atol=TOL)
    # the guard's inputs too: NIS and the log-likelihood (log det S through the kernels' own log)
    np.testing.assert_array_equal(b.nis_dof, a.nis_dof)
    np.testing.assert_allclose(b.nis, a.nis, rtol=1e-9, atol=TOL)
    np.testing.assert_allclose(b.log_likelihood, a.log_likelihood, rtol=1e-9, atol=TOL)


@pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed: only the numpy path exists")
@pytest.mark.parametrize("kind", ["parallel", "serial_descending"])
def test_compiled_ekf_over_several_blocks_equals_numpy_ekf(kind, monkeypatch):
    """70 runs in blocks of at most 32 lanes: three blocks of 24, the last padded with two copies of the last run,
    equal the numpy EKF run by run (so do the padded lanes' runs: they are not written twice)."""
    monkeypatch.setattr(K, "_BLOCK_LANES", 32)
    assert K._block_width(70) == 24 and K._block_width(500) == 32 and K._block_width(64) == 32
    F, Q, x0, P0, streams, kw = _case(kind, np.random.default_rng(11), B=70)
    a, b, compiled = _both(F, Q, x0, P0, streams, **kw)
    assert compiled and b.mean.shape[0] == 70
    np.testing.assert_allclose(b.mean, a.mean, rtol=0, atol=TOL)
    np.testing.assert_allclose(b.cov, a.cov, rtol=0, atol=TOL)
    np.testing.assert_array_equal(b.nis_dof, a.nis_dof)
    np.testing.assert_allclose(b.nis, a.nis, rtol=1e-9, atol=TOL)


@pytest.mark.parametrize("compiled", [True, False] if HAVE_NUMBA else [False])
def test_the_kernels_prediction_is_F_x_and_F_P_F_T_plus_Q_for_every_pattern_of_empty_rows(compiled):
    """The kernel's prediction, called directly with its scratch filled with NaN (so that a read of something never
    written shows), against F x and F P F^T + Q: every pattern of rows of F without entries for n = 5 (none, first,
    middle, last, all), with Q shared and Q per lane; compiled and as plain Python."""
    from locbook.tracking import _kernels
    predict = _kernels._nb_predict if compiled else _kernels._nb_predict.py_func
    rng = np.random.default_rng(3)
    n, W = 5, 6
    F0 = rng.normal(size=(n, n))
    A = rng.normal(size=(W, n, n))
    P_lanes = A @ np.swapaxes(A, -1, -2) + np.eye(n)                  # (W, n, n), symmetric positive definite
    B = rng.normal(size=(W, n, n))
    Q_lanes = B @ np.swapaxes(B, -1, -2)
    x_lanes = rng.normal(size=(W, n))
    for pattern in range(2**n):
        empty = [(pattern >> i) & 1 == 1 for i in range(n)]
        F = F0 * ~np.array(empty)[:, None]
        Fi, Fj = np.nonzero(F)
        row = np.zeros(n, np.bool_)
        row[Fi] = True
        for shared in (True, False):
            Q = Q_lanes[0] if shared else Q_lanes
            Qw = np.empty((n, n, 0)) if shared else np.ascontiguousarray(np.moveaxis(Q_lanes, 0, -1))
            x = np.ascontiguousarray(x_lanes.T)
            P = np.ascontiguousarray(np.moveaxis(P_lanes, 0, -1))
            xt, T1 = np.full((n, W), np.nan), np.full((n, n, W), np.nan)
            predict(Fi.astype(np.int64), Fj.astype(np.int64), np.ascontiguousarray(F[Fi, Fj]), row,
                    np.ascontiguousarray(Q_lanes[0]), Qw, x, P, xt, T1)
            want_P = F @ P_lanes @ F.T + Q
            np.testing.assert_allclose(x.T, x_lanes @ F.T, rtol=1e-12, atol=1e-12, err_msg=f"empty rows {empty}")
            np.testing.assert_allclose(np.moveaxis(P, -1, 0), want_P, rtol=1e-12, atol=1e-12,
                                       err_msg=f"empty rows {empty}, Q shared {shared}")


@pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed: only the numpy path exists")
def test_rows_of_F_without_entries_before_others():
    """State (vx, vy, x, y) whose velocity is drawn afresh each step: F's first two rows are zero. The kernel's F P
    skips rows without entries, and (F P) F^T reads them for the rows after: they must be zeros, not what the scratch
    held (a filter with the full F runs first on the same shapes, leaving its F P in the freed memory)."""
    dt = 0.5
    F_empty = np.array([[0, 0, 0, 0], [0, 0, 0, 0], [dt, 0, 1, 0], [0, dt, 0, 1.0]])
    F_full = F_empty + np.diag([1.0, 1.0, 0.0, 0.0])
    Q = np.diag([0.2, 0.2, 0.01, 0.01])
    rng = np.random.default_rng(0)
    B, T = 16, 20
    fixes, x0, P0 = rng.normal(0, 1, (B, T, 2)), rng.normal(0, 1, (B, 4)), np.diag([0.3, 0.3, 1.0, 1.0])
    streams = [lb.LinearMeasurement(fixes, np.eye(2, 4, 2), 0.25 * np.eye(2))]
    for _ in range(3):
        _both(F_full, Q, x0, P0, streams)
        a, b, compiled = _both(F_empty, Q, x0, P0, streams)
        assert compiled
        np.testing.assert_allclose(b.mean, a.mean, rtol=0, atol=TOL)
        np.testing.assert_allclose(b.cov, a.cov, rtol=0, atol=TOL)


@pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed: only the numpy path exists")
def test_compiled_ekf_gives_way_to_numpy_errors():
    """A zero-noise reading with no prior spread: the kernel cannot update, the numpy loop raises the library's error
    naming the step and run."""
    model = lb.constant_velocity(1.0, 0.05)
    anchors = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]])
    power = np.full((2, 5, 3), -60.0)
    power[:, 0] = np.nan
    for mode in ("parallel", "serial"):
        meas = lb.RssMeasurement(power, anchors, lb.PathLossModel(-40.0, 2.0, 0.0), model.position_index, mode=mode)
        setup = _loop._setup(model.F, np.zeros((4, 4)), np.zeros((2, 4)) + 3.0, np.zeros((4, 4)), [meas], None, "ekf")
        saved = K._NUMBA_ENABLED, K._NUMBA_MIN_WORK
        try:
            K._NUMBA_ENABLED, K._NUMBA_MIN_WORK = True, 0
            assert K._compiled_ekf(setup, [meas], True) is None
            with pytest.raises(lb.SingularCovarianceError, match=r"at step 1 \(run index \(0,\)\)"):
                lb.extended_kalman_filter(model.F, np.zeros((4, 4)), np.zeros((2, 4)) + 3.0, np.zeros((4, 4)), [meas])
        finally:
            K._NUMBA_ENABLED, K._NUMBA_MIN_WORK = saved


@pytest.mark.skipif(not HAVE_NUMBA, reason="numba is not installed: only the numpy path exists")
@pytest.mark.parametrize("frame", ["body", "world"])
def test_compiled_ekf_with_the_inertial_stream_equals_numpy(upath, frame):
    """Gudipati's fused EKF (the inertial stream of locbook.models.imu with its Jacobian, then six anchors' RSS with
    some missing; 20 walks, 200 steps): the kernel evaluates h and its Jacobian itself and equals the numpy loop,
    which calls the two functions; a missing inertial component is left out of the update in both."""
    m, imu = upath["model"], upath["imu"]
    z = np.array(imu.z)
    z[np.random.default_rng(1).random(z.shape) < 0.1] = np.nan
    imu = lb.Stream(z, lb.InertialMeasurement(imu.R, n_state=8, frame=frame))
    a, b, compiled = _both(m.F, m.Q, upath["x0"], upath["P0"], [imu, upath["rss"]])
    assert compiled
    assert (a.nis_dof > 0).all() and len(np.unique(a.nis_dof)) > 2          # some readings missing
    np.testing.assert_allclose(b.mean, a.mean, rtol=0, atol=TOL)
    np.testing.assert_allclose(b.cov, a.cov, rtol=0, atol=TOL)
    np.testing.assert_allclose(b.nis, a.nis, rtol=0, atol=TOL * 100)
    np.testing.assert_allclose(b.log_likelihood, a.log_likelihood, rtol=0, atol=TOL * 100)
    np.testing.assert_array_equal(b.nis_dof, a.nis_dof)


@pytest.mark.parametrize("why", ["function_model", "index_from_the_end"])
def test_inertial_streams_the_kernel_cannot_take_stay_in_numpy(monkeypatch, why):
    """The compiled backend knows models by type (its registry): the inertial model runs compiled, the same functions
    given as a user's function model (NonlinearMeasurement) run in numpy, and so does an inertial model with a numpy
    index from the end (the kernels count from 0); each gives the numpy loop's numbers."""
    monkeypatch.setattr(K, "_NUMBA_MIN_WORK", 0)
    n = 8
    z = np.random.default_rng(3).normal(0.0, 0.3, (2, 5, 3))
    R = 0.1 * np.eye(3)
    if why == "function_model":
        meas = lb.NonlinearMeasurement(z, lb.inertial_measurement_function("body"), R,
                                       jacobian=lb.inertial_measurement_jacobian(n, "body"))
    else:
        meas = lb.Stream(z, lb.InertialMeasurement(R, n_state=n, heading_index=-2))
    F, Q, x0, P0 = np.eye(n), 0.01 * np.eye(n), np.zeros(n), np.eye(n)
    setup = _loop._setup(F, Q, x0, P0, [meas], None, "ekf")
    assert K._compiled_ekf(setup, [meas], True) is None
    good = lb.Stream(z, lb.InertialMeasurement(R, n_state=n))
    if HAVE_NUMBA:
        assert K._compiled_ekf(setup, [good], True) is not None
    if why == "function_model":          # the same model either way: the same numbers
        np.testing.assert_allclose(lb.extended_kalman_filter(F, Q, x0, P0, [meas]).mean,
                                   lb.extended_kalman_filter(F, Q, x0, P0, [good]).mean, rtol=0, atol=1e-12)


def test_nonlinear_streams_stay_in_numpy(monkeypatch):
    monkeypatch.setattr(K, "_NUMBA_MIN_WORK", 0)
    model = lb.constant_velocity(1.0, 0.05)
    z = np.random.default_rng(0).normal(size=(3, 10, 2))
    meas = lb.NonlinearMeasurement(z, lambda x: x[..., :2], np.eye(2),
                                   jacobian=lambda x: np.broadcast_to(np.eye(2, 4), x.shape[:-1] + (2, 4)))
    setup = _loop._setup(model.F, model.Q, np.zeros(4), np.eye(4), [meas], None, "ekf")
    assert K._compiled_ekf(setup, [meas], True) is None
    lin = lb.extended_kalman_filter(model.F, model.Q, np.zeros(4), np.eye(4), [lb.LinearMeasurement(z, np.eye(2, 4),
                                                                                                    np.eye(2))])
    non = lb.extended_kalman_filter(model.F, model.Q, np.zeros(4), np.eye(4), [meas])
    np.testing.assert_allclose(non.mean, lin.mean, rtol=0, atol=1e-12)


@pytest.mark.parametrize("kernel", ["numba" if HAVE_NUMBA else "plain Python"])
def test_zero_steps_do_not_turn_the_compiled_ekf_off(monkeypatch, kernel):
    """Zero steps reached the kernel's argument packing inside the guard that turns the compiled EKF off for the whole
    session on any exception ('cannot reshape array of size 0', with a RuntimeWarning), so every later EKF ran in
    numpy. (The fuzz module restores _NUMBA_ENABLED and ignores RuntimeWarning, so it could not see this.) Without
    numba installed the same wrapper runs with the kernel as plain Python (the kernels are plain functions until
    numba compiles them)."""
    monkeypatch.setattr(K, "_NUMBA_ENABLED", True)
    monkeypatch.setattr(K, "_NUMBA_MIN_WORK", 0)
    if not HAVE_NUMBA:
        monkeypatch.setitem(K._NUMBA_STATE, "ready", True)
    model = lb.constant_velocity(1.0, 0.05)
    H = model.position_measurement_matrix()
    R = np.diag([0.5, 0.8])
    x0, P0 = np.zeros(4), np.eye(4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")                        # no "the compiled EKF failed" warning
        for z in (np.empty((3, 0, 2)), np.empty((0, 5, 2)), np.empty((0, 0, 2))):
            res = lb.extended_kalman_filter(model.F, model.Q, x0, P0, [lb.LinearMeasurement(z, H, R)])
            assert res.mean.shape == z.shape[:-1] + (4,)
    assert K._NUMBA_ENABLED is True
    # and the compiled path is still taken: a batch whose missing components differ between runs
    z = np.random.default_rng(0).normal(size=(2, 3, 2))
    z[0, 1, 0] = np.nan
    calls = []
    original = K._compiled_ekf
    monkeypatch.setattr(K, "_compiled_ekf", lambda *a: calls.append(original(*a)) or calls[-1])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = lb.extended_kalman_filter(model.F, model.Q, x0, P0, [lb.LinearMeasurement(z, H, R)])
    assert len(calls) == 1 and calls[0] is not None
    monkeypatch.setattr(K, "_NUMBA_ENABLED", False)
    ref = lb.extended_kalman_filter(model.F, model.Q, x0, P0, [lb.LinearMeasurement(z, H, R)])
    np.testing.assert_allclose(res.mean, ref.mean, rtol=0, atol=TOL)


@pytest.mark.parametrize("widths", [(2, 4), (1, 3, 2), (2, 2), (3, 0, 1), (0, 0)])
def test_streams_side_by_side_equal_numpys_concatenation(widths):
    """The kernels' readings array, copied step by step as blocks of bytes, is np.concatenate's on the last axis for
    contiguous streams, slices of longer ones (the scenario's accelerometer), broadcast runs, reversed columns (numpy's
    own copy) and float32; NaN readings are kept bit for bit."""
    rng = np.random.default_rng(7)
    zs = [rng.normal(size=(5, 9, m)) for m in widths]
    if widths[0]:
        zs[0][2, 3, 0] = np.nan
    cases = [zs, [z[:, 1:] for z in zs], [np.broadcast_to(z[:1], z.shape) for z in zs], [z[..., ::-1] for z in zs],
             [z.astype(np.float32) for z in zs], [np.asfortranarray(z) for z in zs]]
    for streams in cases:
        got = K._side_by_side(streams)
        want = np.concatenate([np.asarray(z, float) for z in streams], axis=-1)
        assert got.dtype == np.float64 and got.flags.c_contiguous and got.shape == want.shape
        assert np.array_equal(got.view(np.int64), want.view(np.int64))
