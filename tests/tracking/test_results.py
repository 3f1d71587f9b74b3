"""One result vocabulary for every filter: the Kalman family, the smoothers, the particle and grid filters
all return ``mean``, ``cov``, ``steps``, ``log_likelihood``, ``diverged``, ``diverged_step``, ``n_diverged`` and
``position_m``, checked here against written-out closed forms (a 2-D random walk observed directly: one scalar
Kalman filter and RTS smoother per axis; a grid posterior under a uniform transition; the particle filter's first,
prediction-free update); the old names are the same objects behind one DeprecationWarning each."""
import dataclasses
import re
import warnings

import numpy as np
import pytest

import locbook as lb
from locbook.tracking.results import FilterResult

VOCABULARY = ("mean", "cov", "steps", "log_likelihood", "diverged", "diverged_step", "n_diverged", "position_m")
#: the old names of each result class and the new ones they stand for
OLD_KALMAN = {"x": "mean", "P": "cov"}
OLD_BAYES = {"mean_m": "mean", "covariance_m2": "cov", "degenerate": "diverged", "degenerate_step": "diverged_step",
             "n_degenerate": "n_diverged"}

RUNS, T, Q_VAR, R_VAR, P0_VAR = 3, 12, 0.3, 0.8, 2.0


def _walk():
    """A 2-D random walk observed directly (x_k = x_{k-1} + w, z_k = x_k + v), with a step and a reading missing."""
    rng = np.random.default_rng(47)
    truth = np.cumsum(rng.normal(0.0, np.sqrt(Q_VAR), (RUNS, T, 2)), axis=1)
    z = truth + rng.normal(0.0, np.sqrt(R_VAR), (RUNS, T, 2))
    z[:, 4] = np.nan                                 # a step without readings
    z[1, 7, 0] = np.nan                              # one reading not heard
    return z


def _scalar_kf(z):
    """The scalar Kalman filter of one axis (F = H = 1; Kalman 1960, the predict / update pair written out), per run:
    posterior means and variances ``(R, T)``, priors, and the innovations' log-likelihood per step (0 where no
    reading)."""
    x, p = np.zeros(z.shape[0]), np.full(z.shape[0], P0_VAR)
    out = {k: np.empty(z.shape) for k in ("x", "p", "x_pred", "p_pred", "ll")}
    for k in range(z.shape[1]):
        x_pred, p_pred = x, p + Q_VAR
        heard = ~np.isnan(z[:, k])
        s = p_pred + R_VAR
        nu = np.where(heard, z[:, k] - x_pred, 0.0)
        gain = np.where(heard, p_pred / s, 0.0)
        x, p = x_pred + gain * nu, (1 - gain) * p_pred
        out["ll"][:, k] = np.where(heard, -0.5 * (nu**2 / s + np.log(2 * np.pi * s)), 0.0)
        for name, v in (("x", x), ("p", p), ("x_pred", x_pred), ("p_pred", p_pred)):
            out[name][:, k] = v
    return out


def _scalar_rts(f):
    """The scalar RTS smoother (Rauch, Tung and Striebel 1965) of one axis from :func:`_scalar_kf`'s moments."""
    xs, ps = f["x"].copy(), f["p"].copy()
    for k in range(xs.shape[1] - 2, -1, -1):
        c = f["p"][:, k] / f["p_pred"][:, k + 1]
        xs[:, k] = f["x"][:, k] + c * (xs[:, k + 1] - f["x_pred"][:, k + 1])
        ps[:, k] = f["p"][:, k] + c**2 * (ps[:, k + 1] - f["p_pred"][:, k + 1])
    return xs, ps


def _kalman_runs(z):
    F, Q, H, R = np.eye(2), Q_VAR * np.eye(2), np.eye(2), R_VAR * np.eye(2)
    x0, P0 = np.zeros((RUNS, 2)), P0_VAR * np.eye(2)
    meas = lb.LinearMeasurement(z, H, R)
    outputs = ("x_pred", "P_pred", "P_cross")
    return {"kalman_filter": lb.kalman_filter(F, Q, x0, P0, meas, outputs=outputs),
            "extended_kalman_filter": lb.extended_kalman_filter(F, Q, x0, P0, [meas], outputs=outputs),
            "unscented_kalman_filter": lb.unscented_kalman_filter(F, Q, x0, P0, [meas], alpha=1.0, outputs=outputs)}


CELLS = np.stack(np.meshgrid(np.linspace(-3, 3, 13), np.linspace(-2, 2, 9)), -1).reshape(-1, 2)
FIX_SD = 0.7


def _fix_log_likelihood(z):
    """A Gaussian position fix ``z`` ``(R, T, 2)``: ``log_likelihood(points (R, N, 2) or (N, 2), t) -> (R, N)``."""
    def ll(points, t):
        d = np.asarray(points) - z[:, t, None, :]
        return -0.5 * np.sum(d**2, axis=-1) / FIX_SD**2
    return ll


def _all_results():
    """Every filter's result on small problems (DeprecationWarnings of the old names raised: the filters use none)."""
    z = _walk()
    fixes = np.nan_to_num(z, nan=0.0)[..., :T, :] * 0.2
    start = np.random.default_rng(3).normal(0.0, 1.0, (RUNS, 200, 2))
    with warnings.catch_warnings():
        warnings.filterwarnings("error", message=r".* is deprecated: use ", category=DeprecationWarning)
        out = _kalman_runs(z)
        out["rts_smoother"] = lb.rts_smoother(out["kalman_filter"])
        out["fixed_lag_smoother"] = lb.fixed_lag_smoother(out["kalman_filter"], 2)
        out["particle_filter"] = lb.particle_filter(None, _fix_log_likelihood(fixes), rng=np.random.default_rng(5),
                                                    n_steps=T, initial_particles_m=start, spread_m=0.3,
                                                    cloud_steps=(0,))
        out["grid_bayes_filter"] = lb.grid_bayes_filter(None, _fix_log_likelihood(fixes), CELLS, np.inf, n_steps=T)
    return z, fixes, start, out


@pytest.fixture(scope="module")
def results():
    return _all_results()


def test_every_filter_returns_the_same_vocabulary_with_its_shapes(results):
    _, _, _, out = results
    assert set(out) == {"kalman_filter", "extended_kalman_filter", "unscented_kalman_filter", "rts_smoother",
                        "fixed_lag_smoother", "particle_filter", "grid_bayes_filter"}
    for name, res in out.items():
        assert isinstance(res, FilterResult), name
        missing = [a for a in VOCABULARY if not hasattr(res, a)]
        assert missing == [], (name, missing)
        n = 2
        assert res.mean.shape == (RUNS, T, n) and res.cov.shape == (RUNS, T, n, n), name
        np.testing.assert_array_equal(res.steps, np.arange(T), err_msg=name)
        assert res.diverged.shape == (RUNS,) and res.diverged.dtype == bool, name
        assert res.diverged_step.shape == (RUNS,) and np.issubdtype(res.diverged_step.dtype, np.integer), name
        np.testing.assert_array_equal(res.diverged_step[~res.diverged], -1, err_msg=name)
        assert res.n_diverged == int(np.count_nonzero(res.diverged)) == 0, name     # well-posed: none diverged
        # every covariance symmetric positive definite
        np.testing.assert_allclose(res.cov, np.swapaxes(res.cov, -1, -2), rtol=0, atol=1e-12, err_msg=name)
        assert np.linalg.eigvalsh(res.cov).min() > 0, name
        if name in ("particle_filter", "grid_bayes_filter"):
            assert res.log_likelihood is None, name                  # no exact predictive likelihood (documented)
        else:
            assert res.log_likelihood.shape == (RUNS, T), name


def test_the_kalman_family_and_smoothers_equal_the_written_out_scalar_recursions(results):
    z, _, _, out = results
    axes = [_scalar_kf(z[..., a]) for a in range(2)]
    ll = axes[0]["ll"] + axes[1]["ll"]
    ll[:, 4] = np.nan                                              # a step without readings: NaN, not 0
    for name in ("kalman_filter", "extended_kalman_filter", "unscented_kalman_filter"):
        res = out[name]
        for a in range(2):
            np.testing.assert_allclose(res.mean[..., a], axes[a]["x"], rtol=0, atol=1e-12, err_msg=name)
            np.testing.assert_allclose(res.cov[..., a, a], axes[a]["p"], rtol=0, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(res.cov[..., 0, 1], 0.0, rtol=0, atol=1e-12, err_msg=name)
        np.testing.assert_allclose(res.log_likelihood, ll, rtol=1e-12, atol=1e-12, err_msg=name)
    smooth, lag = out["rts_smoother"], out["fixed_lag_smoother"]
    for a in range(2):
        xs, ps = _scalar_rts(axes[a])
        np.testing.assert_allclose(smooth.mean[..., a], xs, rtol=0, atol=1e-12)
        np.testing.assert_allclose(smooth.cov[..., a, a], ps, rtol=0, atol=1e-12)
    # the smoothers carry their run's likelihood and flags (smoothing conditions on the same readings)
    kf = out["kalman_filter"]
    for res in (smooth, lag):
        np.testing.assert_array_equal(res.log_likelihood, kf.log_likelihood)
        np.testing.assert_array_equal(res.diverged, kf.diverged)
        np.testing.assert_array_equal(res.diverged_step, kf.diverged_step)
    # the fixed-lag rows given all the readings (the last `lag` steps) are the RTS smoother's
    np.testing.assert_allclose(lag.mean[:, -2:], smooth.mean[:, -2:], rtol=0, atol=1e-12)


def test_the_grid_and_particle_means_are_their_weighted_moments(results):
    _, fixes, start, out = results
    grid = out["grid_bayes_filter"]
    # a uniform transition (spread inf) forgets the past: each step's posterior is its likelihood, normalised
    d2 = np.sum((CELLS[None, None] - fixes[:, :, None, :]) ** 2, axis=-1)
    w = np.exp(-0.5 * d2 / FIX_SD**2)
    w /= w.sum(axis=-1, keepdims=True)
    mean = np.einsum("rtc,cd->rtd", w, CELLS)
    dev = CELLS[None, None] - mean[:, :, None, :]
    np.testing.assert_allclose(grid.mean, mean, rtol=0, atol=1e-12)
    np.testing.assert_allclose(grid.cov, np.einsum("rtc,rtci,rtcj->rtij", w, dev, dev), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(grid.position_m(), grid.mean)    # the state is the position
    pf = out["particle_filter"]
    # step 0 updates the given particles without a prediction (module docstring of locbook.tracking.bayes)
    np.testing.assert_array_equal(pf.clouds[0], start)
    w0 = np.exp(-0.5 * np.sum((start - fixes[:, :1]) ** 2, axis=-1) / FIX_SD**2)
    w0 /= w0.sum(axis=-1, keepdims=True)
    np.testing.assert_allclose(pf.mean[:, 0], np.einsum("rn,rnd->rd", w0, start), rtol=0, atol=1e-12)


@pytest.mark.parametrize("name", ["kalman_filter", "extended_kalman_filter", "unscented_kalman_filter",
                                  "rts_smoother", "fixed_lag_smoother", "particle_filter", "grid_bayes_filter"])
def test_an_old_name_is_the_same_object_with_one_deprecation_warning(results, name):
    res = results[3][name]
    old_names = OLD_BAYES if name in ("particle_filter", "grid_bayes_filter") else OLD_KALMAN
    cls = type(res).__name__
    for old, new in old_names.items():
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            value = getattr(res, old)
        assert [(w.category, str(w.message)) for w in caught] == \
            [(DeprecationWarning, f"{cls}.{old} is deprecated: use .{new}")], (name, old)
        assert caught[0].filename == __file__                         # attributed to the caller's line
        new_value = getattr(res, new)
        assert value is new_value or value == new_value, (name, old)
    for new in set(old_names.values()):
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            getattr(res, new)                                         # the new names never warn


def test_positional_construction_and_replace_keep_working(results):
    kf = results[3]["kalman_filter"]
    assert [f.name for f in dataclasses.fields(lb.KalmanResult)][:3] == ["mean", "cov", "steps"]
    again = lb.KalmanResult(kf.mean, kf.cov, kf.steps, kf.x_pred, kf.P_pred, kf.innovation, kf.S, kf.log_likelihood,
                            kf.nis, kf.nis_dof, kf.diverged, kf.diverged_step)
    assert again.mean is kf.mean and again.cov is kf.cov and again.log_likelihood is kf.log_likelihood
    flags = np.array([True, False, False])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        flagged = dataclasses.replace(kf, diverged=flags, diverged_step=np.array([3, -1, -1]))
    assert flagged.n_diverged == 1 and flagged.mean is kf.mean
    # an old field name given to replace (or the constructor) is mapped to the new one, with the warning
    new_cov = kf.cov * 2.0
    with pytest.warns(DeprecationWarning, match=re.escape("KalmanResult(P=...) is deprecated: use cov=")):
        doubled = dataclasses.replace(kf, P=new_cov)
    assert doubled.cov is new_cov and doubled.mean is kf.mean
    # the smoother carries a flagged run's flags
    smooth = lb.rts_smoother(flagged)
    np.testing.assert_array_equal(smooth.diverged, flags)
    assert smooth.n_diverged == 1 and smooth.diverged_step.tolist() == [3, -1, -1]


def test_position_m_of_kalman_and_bayes_results():
    rng = np.random.default_rng(8)
    cv = lb.constant_velocity(0.5, 0.2)
    z = np.cumsum(rng.normal(0, 0.5, (2, 10, 2)), axis=1)
    H = np.hstack([np.eye(2), np.zeros((2, 2))])
    res = lb.kalman_filter(cv.F, cv.Q, np.zeros(4), np.eye(4), lb.LinearMeasurement(z, H, 0.3 * np.eye(2)))
    idx = np.asarray(cv.position_index)
    np.testing.assert_array_equal(res.position_m(cv.position_index), res.mean[..., idx])
    np.testing.assert_array_equal(res.position_m([1]), res.mean[..., [1]])
    with pytest.raises(ValueError, match="index must give the position components of the KalmanResult's state"):
        res.position_m()                              # a state of position and velocity: the index is the caller's
    for bad in ([4], [-1], [], [0.5], [[0, 1]]):
        with pytest.raises(ValueError, match=r"index must be state components in 0\.\.3"):
            res.position_m(bad)
    # a particle filter with motion=: the state is position and velocity, position_m takes the motion's index
    start = np.concatenate([z[:, :1] + rng.normal(0, 0.5, (2, 300, 2)), np.zeros((2, 300, 2))], axis=-1)
    pf = lb.particle_filter(None, lambda x, t: -0.5 * np.sum((x[..., idx] - z[:, t, None]) ** 2, axis=-1) / 0.3,
                            rng=np.random.default_rng(2), n_steps=10, initial_particles_m=start, motion=cv)
    assert pf.mean.shape == (2, 10, 4)
    np.testing.assert_array_equal(pf.position_m(cv.position_index), pf.mean[..., idx])
    np.testing.assert_array_equal(pf.position_m(), pf.mean)


def test_a_collapsed_particle_or_grid_run_is_diverged_at_its_step():
    z = np.zeros((3, 5, 2))

    def ll(points, t):
        out = -0.5 * np.sum((np.asarray(points) - z[:, t, None]) ** 2, axis=-1)
        if t >= 2:
            out[1] = -np.inf                                              # run 1: no point explains step 2
        return out
    start = np.random.default_rng(0).normal(0, 1, (3, 100, 2))
    with pytest.warns(RuntimeWarning, match=r"1 of 3 runs \(first: run 1, step 2"):
        pf = lb.particle_filter(None, ll, rng=np.random.default_rng(1), n_steps=5, initial_particles_m=start,
                                spread_m=0.1)
    with pytest.warns(RuntimeWarning, match=r"1 of 3 runs \(first: run 1, step 2"):
        grid = lb.grid_bayes_filter(None, ll, CELLS, 0.5, n_steps=5)
    for res in (pf, grid):
        assert res.diverged.tolist() == [False, True, False] and res.diverged_step.tolist() == [-1, 2, -1]
        assert res.n_diverged == 1
        assert np.isnan(res.mean[1, 2:]).all() and np.isfinite(res.mean[[0, 2]]).all()
        assert np.isfinite(res.mean[1, :2]).all()
        with pytest.warns(DeprecationWarning):
            assert res.degenerate is res.diverged and res.degenerate_step is res.diverged_step
        with pytest.warns(DeprecationWarning):
            assert res.n_degenerate == 1
