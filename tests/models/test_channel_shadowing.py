"""General test-bed tools moved out of the Ozkaya scenario: the spatially correlated shadowing field, attenuation
bursts (locbook.models.channel) and per-run error statistics (locbook.metrics), each checked against an
independent fact: the field's correlation against exp(-L / d_c), the bursts against the binomial and uniform laws,
the statistics against numpy."""
import numpy as np
import pytest

import locbook as lb
from locbook.metrics import error_summary_per_run
from locbook.models.channel import attenuation_bursts_db


def test_shadowing_field_correlation_at_each_lag_is_exponential():
    # points on a line 0.5 m apart: the empirical correlation between points L apart equals exp(-L / d_c)
    decorrelation, n = 1.5, 40_000
    x = np.arange(0.0, 4.01, 0.5)
    pts = np.stack([x, np.zeros_like(x)], -1)
    field = lb.correlated_shadowing_db(pts, 4.0, decorrelation, rng=np.random.default_rng(11), size=(n,))
    assert field.shape == (n, x.size)
    assert field.std() == pytest.approx(4.0, rel=0.02)
    corr = np.corrcoef(field.T)
    for lag in (1, 2, 3, 6):
        rho = np.exp(-0.5 * lag / decorrelation)
        empirical = np.diag(corr, k=lag)
        se = (1 - rho**2) / np.sqrt(n)                      # large-sample s.e. of a correlation coefficient
        assert np.all(np.abs(empirical - rho) < 5 * se), (lag, empirical, rho)
    # no correlation length: independent draws
    iid = lb.correlated_shadowing_db(pts, 4.0, 0.0, rng=np.random.default_rng(12), size=(n,))
    assert np.all(np.abs(np.corrcoef(iid.T)[np.triu_indices(x.size, 1)]) < 5 / np.sqrt(n))


def test_attenuation_bursts_follow_the_binomial_and_uniform_laws():
    p, (lo, hi), shape = 0.3, (5.0, 10.0), (200, 500)
    loss = attenuation_bursts_db(shape, p, (lo, hi), rng=np.random.default_rng(3))
    assert loss.shape == shape and np.all(loss <= 0)
    hit = loss < 0
    n = hit.size
    assert abs(hit.mean() - p) < 4 * np.sqrt(p * (1 - p) / n)
    depth = -loss[hit]
    assert depth.min() >= lo and depth.max() <= hi
    # uniform on [lo, hi]: mean (lo + hi) / 2, variance (hi - lo)^2 / 12
    assert abs(depth.mean() - (lo + hi) / 2) < 4 * (hi - lo) / np.sqrt(12 * depth.size)
    assert depth.var() == pytest.approx((hi - lo) ** 2 / 12, rel=0.05)
    assert loss.mean() == pytest.approx(-p * (lo + hi) / 2, rel=0.03)
    assert np.all(attenuation_bursts_db(shape, 0.0, (lo, hi), rng=np.random.default_rng(4)) == 0)
    assert np.all(attenuation_bursts_db(shape, 1.0, (lo, lo), rng=np.random.default_rng(5)) == -lo)


@pytest.mark.parametrize("kwargs", [dict(probability=1.5), dict(probability=-0.1), dict(loss_range_db=(10.0, 5.0)),
                                    dict(loss_range_db=(-1.0, 5.0)), dict(loss_range_db=(5.0,))])
def test_attenuation_bursts_refuse_bad_arguments(kwargs):
    args = dict(probability=0.1, loss_range_db=(5.0, 10.0)) | kwargs
    with pytest.raises(ValueError):
        attenuation_bursts_db((3,), args["probability"], args["loss_range_db"], rng=np.random.default_rng(0))


def test_error_summary_per_run_equals_numpy_row_by_row():
    rng = np.random.default_rng(7)
    errors = rng.gamma(2.0, 0.6, size=(5, 25, 30))           # (runs, points, steps)
    stats = error_summary_per_run(errors)
    flat = errors.reshape(5, -1)
    np.testing.assert_allclose(stats["rmse_m"], np.sqrt((flat**2).mean(1)), rtol=1e-12)
    np.testing.assert_allclose(stats["mean_m"], flat.mean(1), rtol=1e-12)
    np.testing.assert_allclose(stats["median_m"], np.median(flat, 1), rtol=1e-12)
    np.testing.assert_allclose(stats["p90_m"], np.percentile(flat, 90, axis=1), rtol=1e-12)
    np.testing.assert_allclose(stats["std_m"], flat.std(1), rtol=1e-12)
    # RMSE^2 = mean^2 + std^2 (population std)
    np.testing.assert_allclose(stats["rmse_m"] ** 2, stats["mean_m"] ** 2 + stats["std_m"] ** 2, rtol=1e-12)
    # and each run's statistics are error_summary's over that run alone
    for i in range(5):
        one = lb.error_summary(errors[i])
        for key, values in stats.items():
            assert values[i] == pytest.approx(one[key], rel=1e-12)
    with pytest.raises(ValueError):
        error_summary_per_run(np.ones(4))                      # no estimates axis
    with pytest.raises(ValueError):
        error_summary_per_run(np.array([[1.0, np.inf]]))
