"""A measurement model is one class: models defined in this module alone (ranges to anchors, a barometer) run through
the KF, the EKF, the UKF, the particle and the grid filter, and give what independent implementations of the same
model give (filterpy's filters, a Bayes rule written here, the library's own models)."""
import numpy as np
import pytest
from filterpy.kalman import ExtendedKalmanFilter, KalmanFilter, MerweScaledSigmaPoints, UnscentedKalmanFilter

import locbook as lb
from builders import REPO_ROOT
from locbook.models.base import MeasurementModel

ANCHORS = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 8.0]])
SIGMA_M = 0.3


class Ranges(MeasurementModel):
    """Ranges from the position (state components 0 and 1) to fixed anchors, ``z_j = |p - a_j| + v_j``."""

    name = "ranges"

    def __init__(self, anchors_m, sigma_m):
        self.anchors_m, self.sigma_m = np.asarray(anchors_m, float), float(sigma_m)

    @property
    def n_readings(self):
        return len(self.anchors_m)

    def mean(self, x, *, step=0):
        return np.linalg.norm(x[..., None, :2] - self.anchors_m, axis=-1)

    def jacobian(self, x, *, step=0):
        diff = x[..., None, :2] - self.anchors_m
        J = np.zeros(x.shape[:-1] + (self.n_readings, x.shape[-1]))
        J[..., :2] = diff / np.linalg.norm(diff, axis=-1, keepdims=True)
        return J

    def covariance(self, x, *, step=0):
        return self.sigma_m**2 * np.eye(self.n_readings)

    def independent_readings(self):
        return True


class Barometer(MeasurementModel):
    """A barometric altitude ``z = h + b + v`` of the state's height (component 0) with a known bias ``b``: linear,
    so the Kalman filter takes it."""

    name = "barometer"
    linear = True

    def __init__(self, bias_m, sigma_m):
        self.bias_m, self.sigma_m = bias_m, sigma_m

    @property
    def n_readings(self):
        return 1

    def mean(self, x, *, step=0):
        return x[..., :1] + self.bias_m

    def jacobian(self, x, *, step=0):
        return np.broadcast_to(np.eye(1, x.shape[-1]), x.shape[:-1] + (1, x.shape[-1]))

    def covariance(self, x, *, step=0):
        return np.array([[self.sigma_m**2]])


def _track(runs=3, steps=25, seed=0):
    model = lb.constant_velocity(1.0, 0.05)
    rng = np.random.default_rng(seed)
    x = np.zeros((runs, steps, 4))
    x[:, 0] = [3.0, 2.0, 0.3, 0.2]
    for k in range(1, steps):
        x[:, k] = x[:, k - 1] @ model.F.T + rng.multivariate_normal(np.zeros(4), model.Q, runs)
    z = np.linalg.norm(x[..., None, :2] - ANCHORS, axis=-1) + rng.normal(0, SIGMA_M, (runs, steps, 3))
    z[0, min(5, steps - 1), 1] = np.nan                                  # a missing range
    z[min(2, runs - 1), 3:5, :] = np.nan                                 # two steps that heard nothing
    return model, x, z


def _filterpy_ekf(model, z, x0, P0):
    f = ExtendedKalmanFilter(4, 3)
    f.x, f.P, f.F, f.Q, f.R = x0.copy(), P0.copy(), model.F, model.Q, SIGMA_M**2 * np.eye(3)
    ranges = Ranges(ANCHORS, SIGMA_M)
    out = []
    for zk in z:
        f.predict()
        present = np.isfinite(zk)
        if present.any():
            f.update(zk[present], lambda x: ranges.jacobian(x[None])[0][present],
                     lambda x: ranges.mean(x[None])[0][present], R=SIGMA_M**2 * np.eye(int(present.sum())))
        out.append(f.x.copy())
    return np.array(out)


def test_a_new_model_runs_in_the_ekf_and_equals_filterpy():
    model, _, z = _track()
    x0, P0 = np.array([3.0, 2.0, 0.0, 0.0]), np.diag([1.0, 1.0, 0.5, 0.5])
    stream = lb.Stream(z, Ranges(ANCHORS, SIGMA_M))
    ours = lb.extended_kalman_filter(model.F, model.Q, x0, P0, stream)
    for r in range(z.shape[0]):
        np.testing.assert_allclose(ours.mean[r], _filterpy_ekf(model, z[r], x0, P0), rtol=0, atol=1e-9)
    serial = lb.extended_kalman_filter(model.F, model.Q, x0, P0, lb.Stream(z, Ranges(ANCHORS, SIGMA_M), mode="serial"))
    assert np.all(np.isfinite(serial.mean)) and np.abs(serial.mean - ours.mean).max() < 0.5    # re-linearised per range
    assert not np.allclose(serial.mean, ours.mean, atol=1e-6)


def test_a_new_model_runs_in_the_ukf_and_equals_filterpy():
    model, _, z = _track(runs=2)
    x0, P0 = np.array([3.0, 2.0, 0.0, 0.0]), np.diag([1.0, 1.0, 0.5, 0.5])
    ours = lb.unscented_kalman_filter(model.F, model.Q, x0, P0, lb.Stream(z, Ranges(ANCHORS, SIGMA_M)), alpha=0.5)
    ranges = Ranges(ANCHORS, SIGMA_M)
    for r in range(z.shape[0]):
        pts = MerweScaledSigmaPoints(4, alpha=0.5, beta=2.0, kappa=0.0)
        f = UnscentedKalmanFilter(4, 3, 1.0, hx=lambda x: ranges.mean(x[None])[0], fx=lambda x, dt: model.F @ x,
                                  points=pts)
        f.x, f.P, f.Q, f.R = x0.copy(), P0.copy(), model.Q, SIGMA_M**2 * np.eye(3)
        for k, zk in enumerate(z[r]):
            f.predict()
            present = np.isfinite(zk)
            if present.all():
                f.update(zk)
                np.testing.assert_allclose(ours.mean[r, k], f.x, rtol=0, atol=1e-8)
            elif not present.any():
                np.testing.assert_allclose(ours.mean[r, k], f.x, rtol=0, atol=1e-8)
            else:                            # a partial step: filterpy has no missing component; stop comparing
                break


def test_a_new_linear_model_runs_in_the_kalman_filter_and_equals_filterpy():
    rng = np.random.default_rng(1)
    F, Q = np.array([[1.0, 1.0], [0.0, 1.0]]), np.diag([0.01, 0.02])
    height = np.cumsum(rng.normal(0, 0.3, (2, 40)), axis=1)
    z = (height + 4.0 + rng.normal(0, 0.5, height.shape))[..., None]
    z[1, 10:12] = np.nan
    x0, P0 = np.zeros(2), np.eye(2)
    ours = lb.kalman_filter(F, Q, x0, P0, lb.Stream(z, Barometer(4.0, 0.5)))
    for r in range(2):
        f = KalmanFilter(2, 1)
        f.x, f.P, f.F, f.Q, f.H, f.R = x0[:, None].copy(), P0.copy(), F, Q, np.eye(1, 2), np.array([[0.25]])
        for k in range(40):
            f.predict()
            if np.isfinite(z[r, k, 0]):
                f.update(z[r, k] - 4.0)
            np.testing.assert_allclose(ours.mean[r, k], f.x[:, 0], rtol=0, atol=1e-10)


def test_a_new_model_runs_in_the_grid_filter_as_its_own_likelihood_written_out():
    _, x, z = _track(runs=2, steps=6)
    xs, ys = np.meshgrid(np.linspace(0, 10, 41), np.linspace(0, 8, 33))
    cells = np.column_stack([xs.ravel(), ys.ravel()])
    ranges = Ranges(ANCHORS, SIGMA_M)
    ours = lb.grid_bayes_filter(z, ranges, cells, spread_m=0.5)

    def written_out(c, t):                 # the Gaussian range likelihood by hand, missing ranges left out
        d = np.linalg.norm(c[:, None, :] - ANCHORS, axis=-1)
        r = np.where(np.isfinite(z[:, t, None, :]), z[:, t, None, :] - d, 0.0)
        return -0.5 * np.sum(r * r, axis=-1) / SIGMA_M**2
    ref = lb.grid_bayes_filter(None, written_out, cells, spread_m=0.5, n_steps=z.shape[1])
    np.testing.assert_allclose(ours.mean, ref.mean, rtol=0, atol=1e-9)
    np.testing.assert_allclose(ours.weights, ref.weights, rtol=0, atol=1e-12)


def test_a_new_model_runs_in_the_particle_filter_as_its_own_likelihood_written_out():
    _, x, z = _track(runs=3, steps=10)
    ranges = Ranges(ANCHORS, SIGMA_M)
    start = np.random.default_rng(4).uniform((0.0, 0.0), (10.0, 8.0), (3, 2000, 2))
    kw = dict(initial_particles_m=start, region_m=((0.0, 0.0), (10.0, 8.0)), spread_m=0.4)
    ours = lb.particle_filter(z, ranges, rng=np.random.default_rng(5), **kw)

    def written_out(p, t):
        d = np.linalg.norm(p[..., None, :] - ANCHORS, axis=-1)
        r = np.where(np.isfinite(z[:, t, None, :]), z[:, t, None, :] - d, 0.0)
        dof = np.isfinite(z[:, t]).sum(-1)[:, None]
        return -0.5 * np.sum(r * r, axis=-1) / SIGMA_M**2 - dof * (np.log(SIGMA_M) + 0.5 * np.log(2 * np.pi))
    ref = lb.particle_filter(None, written_out, rng=np.random.default_rng(5), n_steps=z.shape[1], **kw)
    np.testing.assert_allclose(ours.mean, ref.mean, rtol=0, atol=1e-9)
    error = np.linalg.norm(ours.mean[:, 5:] - x[:, 5:, :2], axis=-1)
    prior = np.linalg.norm(np.array([5.0, 4.0]) - x[:, 5:, :2], axis=-1)          # the uniform prior's mean
    assert np.sqrt(np.mean(error**2)) < 0.4 * np.sqrt(np.mean(prior**2))     # and it tracks (measured: 0.62 m vs 2.6 m)


def test_the_rss_models_are_models_of_the_protocol_in_every_filter():
    """The library's own models are of the same protocol: the grid filter's RSS likelihood through the generic
    Gaussian log-likelihood of the protocol equals its table fast path."""
    channel = lb.PathLossModel(-40.0, 2.2, 3.0, min_distance_m=0.1)
    model = lb.RssModel(ANCHORS, channel)
    assert isinstance(model, MeasurementModel) and isinstance(lb.RssMeasurement(np.zeros((2, 3)), ANCHORS, channel,
                                                                                [0, 1]).model, MeasurementModel)
    cells = np.random.default_rng(2).uniform(0, 8, (50, 2))
    rss = np.random.default_rng(3).normal(-60, 4, (4, 3))
    rss[1, 2] = np.nan
    generic = MeasurementModel.log_likelihood(model, rss, cells, step=0)
    np.testing.assert_allclose(generic, model.log_likelihood(rss, cells, 0), rtol=1e-12)


def test_a_model_that_is_not_a_model_is_refused_by_name():
    with pytest.raises(ValueError, match="a Stream's model must be a MeasurementModel"):
        lb.Stream(np.zeros((3, 2)), object())
    with pytest.raises(ValueError, match="serial updates need independent readings"):
        lb.Stream(np.zeros((3, 1)), Barometer(0.0, 1.0), mode="serial")
    with pytest.raises(ValueError, match="kalman_filter takes LinearMeasurement streams"):
        lb.kalman_filter(np.eye(4), np.eye(4), np.zeros(4), np.eye(4), lb.Stream(np.zeros((3, 3)),
                                                                                 Ranges(ANCHORS, SIGMA_M)))


class NoJacobian(Ranges):
    jacobian = MeasurementModel.jacobian


def test_a_model_without_a_jacobian_runs_in_the_ukf_and_is_refused_by_the_ekf_by_name():
    model, _, z = _track(runs=1, steps=5)
    stream = lb.Stream(z, NoJacobian(ANCHORS, SIGMA_M))
    x0, P0 = np.array([3.0, 2.0, 0.0, 0.0]), np.eye(4)
    assert np.isfinite(lb.unscented_kalman_filter(model.F, model.Q, x0, P0, stream).mean).all()
    with pytest.raises(ValueError, match="ranges: the EKF needs the model's jacobian"):
        lb.extended_kalman_filter(model.F, model.Q, x0, P0, stream)


def test_the_architecture_pages_sensor_example_runs():
    """docs/architecture.md's 'Adding a sensor' example, executed (skipped where the docs are not beside the tests)."""
    page = REPO_ROOT / "docs" / "architecture.md"
    if not page.exists():
        pytest.skip("docs/architecture.md is not beside the tests")
    text = page.read_text()
    start = text.index("```python\n", text.index("## Adding a sensor")) + len("```python\n")
    code = text[start:text.index("\n```", start)]
    names = {}                                   # the example makes its own walk, readings and prior
    exec(compile(code, str(page), "exec"), names)
    walk_m = names["walk_m"]
    assert np.linalg.norm(names["track"].mean[..., -1, :2] - walk_m[-1], axis=-1).max() < 1.5
    assert names["cloud"].mean.shape == walk_m.shape


def test_the_grid_filter_takes_the_rss_models_mean_table_once(monkeypatch):
    """The RSS model's fast path (its cell-by-anchor mean table, which the compiled grid kernels read) is asked for
    once per call and used, not bypassed by the protocol's generic per-step likelihood."""
    from locbook.models.rss import RssModel
    calls = []
    original = RssModel.mean_table
    monkeypatch.setattr(RssModel, "mean_table", lambda self, *a: calls.append(1) or original(self, *a))
    monkeypatch.setattr(RssModel, "log_likelihood", lambda *a, **k: pytest.fail("per-step likelihood used"))
    model = RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.2, 3.0, min_distance_m=0.1))
    cells = np.random.default_rng(0).uniform(0, 8, (60, 2))
    rss = np.random.default_rng(1).normal(-60, 4, (3, 4, 3))
    res = lb.grid_bayes_filter(rss, model, cells, spread_m=0.5)
    assert np.isfinite(res.mean).all() and len(calls) == 1


@pytest.mark.compiled
def test_the_particle_filter_takes_the_rss_models_compiled_likelihood(monkeypatch):
    """The RSS model's compiled likelihood (a registry keyed by model type) is what the particle filter calls when
    the compiled path is on, not the protocol's generic likelihood."""
    from locbook.tracking import _compiled, particle
    if not (_compiled._NUMBA_ENABLED and _compiled._numba_ready()):
        pytest.skip("the compiled paths are off")
    calls = []
    fused = particle._FUSED_LIKELIHOODS[lb.RssModel]
    monkeypatch.setitem(particle._FUSED_LIKELIHOODS, lb.RssModel, lambda *a, **k: calls.append(1) or fused(*a, **k))
    model = lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.2, 3.0, min_distance_m=0.1))
    rss = np.random.default_rng(1).normal(-60, 4, (2, 3, 3))
    n = max(particle._NUMBA_MIN_PARTICLES, 100)
    lb.particle_filter(rss, model, rng=np.random.default_rng(2), n_particles=n, region_m=((0, 0), (8, 8)))
    assert len(calls) == 3                      # one per step


class GrowingNoise(lb.MotionModel):
    """A user motion model: constant velocity whose process noise grows with the step (a step-dependent Q)."""
    name = "growing"

    def __init__(self):
        self.cv = lb.constant_velocity(1.0, 0.05)

    def apply(self, x, step=0):
        return x @ self.cv.F.T

    def jacobian_at(self, x, step=0):
        return self.cv.F

    def covariance(self, step=0):
        return self.cv.Q * (1.0 + step)


def test_a_user_motion_model_brings_its_step_dependent_covariance_and_the_online_filter_counts_its_steps():
    model, _, z = _track(runs=2, steps=12)
    stream = lb.Stream(z, Ranges(ANCHORS, SIGMA_M))
    x0, P0 = np.array([3.0, 2.0, 0.0, 0.0]), np.eye(4)
    motion = GrowingNoise()
    ours = lb.extended_kalman_filter(motion, None, x0, P0, stream)
    Qs = lb.per_step(np.stack([motion.covariance(k) for k in range(12)]))
    ref = lb.extended_kalman_filter(motion.cv.F, Qs, x0, P0, stream)
    np.testing.assert_allclose(ours.mean, ref.mean, rtol=0, atol=1e-12)
    online = lb.OnlineFilter("ekf", motion, None, np.broadcast_to(x0, (2, 4)), P0)
    steps = [online.step(lb.Stream(z[:, k:k + 1], Ranges(ANCHORS, SIGMA_M))).mean[:, -1] for k in range(12)]
    np.testing.assert_allclose(np.stack(steps, axis=1), ref.mean, rtol=0, atol=1e-10)


def test_a_user_motion_model_runs_in_the_imm():
    model, _, z = _track(runs=2, steps=10)
    stream = lb.Stream(z, Ranges(ANCHORS, SIGMA_M))
    x0, P0 = np.array([3.0, 2.0, 0.0, 0.0]), np.eye(4)
    res = lb.imm_filter([GrowingNoise()], [[1.0]], x0, P0, [stream])
    ref = lb.extended_kalman_filter(GrowingNoise(), None, x0, P0, stream)
    assert res.mean.shape == ref.mean.shape and np.isfinite(res.mean).all()


class PerRunNoise(Ranges):
    def covariance(self, x, *, step=0):                 # per run, without the point axis: ambiguous, refused
        return np.array([1.0, 2.0, 3.0])[:, None, None] * SIGMA_M**2 * np.eye(3)


def test_a_covariance_without_the_point_axis_is_refused_by_name():
    model, _, z = _track(runs=3, steps=5)
    for filt in (lb.extended_kalman_filter, lb.unscented_kalman_filter):
        with pytest.raises(ValueError, match=r"ranges: covariance returned shape \(3, 3, 3\)"):
            filt(model.F, model.Q, np.array([3.0, 2.0, 0.0, 0.0]), np.eye(4), lb.Stream(z, PerRunNoise(ANCHORS, 0.3)))


def test_library_models_cross_filters_or_are_refused_by_name():
    from locbook.models.base import LinearGaussian
    cells = np.random.default_rng(0).uniform(0, 8, (40, 2))
    fixes = np.random.default_rng(1).normal(4, 1, (2, 5, 2))
    assert np.isfinite(lb.grid_bayes_filter(fixes, LinearGaussian(np.eye(2), np.eye(2)), cells).mean).all()
    rss = np.random.default_rng(2).normal(-60, 3, (2, 5, 3))
    channel = lb.PathLossModel(-40.0, 2.2, 3.0)
    # the one RssModel in a Kalman stream: a state of positions as it is, a larger state through position_index
    alone = lb.extended_kalman_filter(np.eye(2), np.eye(2), np.array([3.0, 2.0]), np.eye(2),
                                      lb.Stream(rss, lb.RssModel(ANCHORS, channel, position_index=[0, 1])))
    factory = lb.extended_kalman_filter(np.eye(2), np.eye(2), np.array([3.0, 2.0]), np.eye(2),
                                        lb.RssMeasurement(rss, ANCHORS, channel, [0, 1]))
    np.testing.assert_array_equal(alone.mean, factory.mean)
    with pytest.raises(ValueError, match=r"is a model of states: give RssModel\(\.\.\., position_index=\.\.\.\) "
                                         r"\(2 state indices of the 4-state\)"):
        lb.extended_kalman_filter(np.eye(4), np.eye(4), np.array([3.0, 2.0, 0.0, 0.0]), np.eye(4),
                                  lb.Stream(rss, lb.RssModel(ANCHORS, channel)))


def test_the_noise_fit_takes_a_kinematic_model_with_its_own_q():
    cv = lb.constant_velocity(1.0, 0.05)
    z = np.random.default_rng(3).normal(0, 1, (4, 30, 2)).cumsum(axis=1)
    stream = lb.LinearMeasurement(z, np.eye(2, 4), np.eye(2))
    a = lb.fit_noise_ml(cv, None, np.zeros(4), np.eye(4), stream, per_run=False)
    b = lb.fit_noise_ml(cv.F, cv.Q, np.zeros(4), np.eye(4), stream, per_run=False)
    np.testing.assert_allclose(a.q_scale, b.q_scale, rtol=0, atol=0)


def test_a_serial_linear_stream_in_descending_order_equals_the_parallel_update():
    """One H for every run and a per-run reading order (descending): the serial form of a diagonal-R update is the
    parallel one to round-off, in the KF, the EKF and the square-root form."""
    from locbook.models.base import LinearGaussian
    cv = lb.constant_velocity(1.0, 0.1)
    z = np.random.default_rng(0).normal(size=(3, 10, 2))
    z[0, 2, 0] = np.nan
    model = LinearGaussian(np.eye(2, 4), np.diag([1.0, 2.0]))
    ref = lb.kalman_filter(cv.F, cv.Q, np.zeros(4), np.eye(4), lb.Stream(z, model))
    serial = lb.Stream(z, model, mode="serial", order="descending")
    for filt in (lb.kalman_filter, lb.extended_kalman_filter, lb.square_root_kalman_filter):
        np.testing.assert_allclose(filt(cv.F, cv.Q, np.zeros(4), np.eye(4), serial).mean, ref.mean, rtol=0, atol=1e-12)


def test_a_motion_models_sample_draws_its_transition_density():
    """MotionModel.sample: draws of x_k given x_{k-1} have mean F x and covariance Q (a constant-velocity model whose
    Q is singular, so the draw goes through its square root), within the Monte-Carlo error of 200,000 draws."""
    cv = lb.constant_velocity(1.0, 0.2)
    x = np.array([1.0, 2.0, 0.5, -0.3])
    draws = cv.sample(np.broadcast_to(x, (200_000, 4)), step=0, rng=np.random.default_rng(7))
    np.testing.assert_allclose(draws.mean(axis=0), cv.F @ x, rtol=0, atol=5 * np.sqrt(np.diag(cv.Q).max() / 2e5))
    np.testing.assert_allclose(np.cov(draws.T), cv.Q, rtol=0, atol=5 * np.sqrt(2.0 / 2e5) * np.diag(cv.Q).max())


class MyConstantVelocity(lb.MotionModel):
    """A user's constant-velocity model written against the protocol alone (no F or Q attributes)."""

    n_state = 4
    position_index = np.array([0, 1])

    def __init__(self, dt_s, q):
        self.ref = lb.constant_velocity(dt_s, q, noise="continuous")

    def apply(self, x, step=0):
        return np.asarray(x, dtype=float) @ self.ref.F.T

    def covariance(self, step=0):
        return self.ref.Q

    def mirrored_index(self):
        return np.array([[2, 3]])


class Pulsed(lb.MotionModel):
    """Stands still (f = identity); the noise is switched on at even steps only."""

    n_state = 2
    position_index = np.array([0, 1])

    def apply(self, x, step=0):
        return np.asarray(x, dtype=float)

    def covariance(self, step=0):
        return (step % 2 == 0) * 0.25 * np.eye(2)


def test_a_users_motion_model_moves_the_particles_as_the_library_model_with_the_same_matrices():
    rss = np.random.default_rng(4).normal(-60.0, 3.0, (2, 8, 3))
    model = lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.2, 3.0, min_distance_m=0.1))
    box = ([0.0, 0.0], [10.0, 8.0])
    mine = lb.particle_filter(rss, model, rng=np.random.default_rng(1), n_particles=300, region_m=box,
                              motion=MyConstantVelocity(1.0, 0.05))
    ref = lb.particle_filter(rss, model, rng=np.random.default_rng(1), n_particles=300, region_m=box,
                             motion=lb.constant_velocity(1.0, 0.05, noise="continuous"))
    np.testing.assert_array_equal(mine.mean, ref.mean)


def test_a_users_motion_model_draws_its_noise_at_each_step_from_its_own_covariance():
    n = 20_000
    start = np.zeros((1, n, 2))
    res = lb.particle_filter(None, lambda x, t: np.zeros(x.shape[:2]), rng=np.random.default_rng(2), n_steps=4,
                             initial_particles_m=start, motion=Pulsed(), cloud_steps=(1, 2, 3))
    var = [res.clouds[t][0].var(axis=0).mean() for t in (1, 2, 3)]
    # step 1: no noise (odd); step 2: 0.25 added; step 3: no noise. Resampling with equal weights keeps the spread
    # up to its Monte-Carlo error (the variance of a variance over 20,000 draws: about 1 %)
    assert var[0] == 0.0
    assert var[1] == pytest.approx(0.25, rel=0.05) and var[2] == pytest.approx(var[1], rel=0.05)


def test_a_motion_without_position_index_or_a_mirror_is_refused_by_name():
    class Bare(lb.MotionModel):
        def apply(self, x, step=0):
            return x
    model = lb.RssModel(ANCHORS, lb.PathLossModel(-40.0, 2.2, 3.0))
    rss = np.zeros((1, 3, 3))
    with pytest.raises(ValueError, match="motion Bare needs position_index"):
        lb.particle_filter(rss, model, rng=np.random.default_rng(0), n_particles=5, region_m=([0, 0], [9, 9]),
                           motion=Bare())
    with pytest.raises(ValueError, match="region_m mirrors the motion at the walls; motion=Pulsed"):
        lb.particle_filter(rss, model, rng=np.random.default_rng(0), n_particles=5, region_m=([0, 0], [9, 9]),
                           motion=type("Pulsed", (Pulsed,), {"mirrored_index": lambda self: None})())
