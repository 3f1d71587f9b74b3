"""Monte-Carlo helpers (locbook.montecarlo): named random streams reproducible, independent and stable under a longer
prefix, and the bootstrap and jackknife standard errors against their closed forms."""
import numpy as np
import pytest

import locbook as lb


def test_streams_are_reproducible_independent_and_prefix_stable():
    a, b = lb.streams(5, "calibration", "tracking"), lb.streams(5, "calibration", "tracking")
    np.testing.assert_array_equal(a["tracking"].normal(size=10), b["tracking"].normal(size=10))
    c = lb.streams(5, "calibration", "tracking")
    assert not np.allclose(c["calibration"].normal(size=10), c["tracking"].normal(size=10))
    small = lb.streams(1, "x")["x"].standard_normal((3, 4))
    big = lb.streams(1, "x")["x"].standard_normal((10, 4))
    np.testing.assert_array_equal(small, big[:3])     # run i's draws do not depend on the number of runs
    assert lb.mc_standard_error(np.array([1.0, 3.0])) == pytest.approx(1.0)


def test_bootstrap_standard_error_matches_closed_forms():
    """Averaged over 20 Gaussian samples, the bootstrap SE of the mean equals sigma / sqrt(n) and that of the
    median the asymptotic sqrt(pi / 2) sigma / sqrt(n) (a single sample's bootstrap SE of a median scatters by
    about 10 %, so one sample is not a test)."""
    n, sigma = 1000, 2.0
    ratios = {np.mean: [], np.median: []}
    closed = {np.mean: sigma / np.sqrt(n), np.median: np.sqrt(np.pi / 2) * sigma / np.sqrt(n)}
    for k in range(20):
        x = np.random.default_rng(k).normal(3.0, sigma, n)
        for stat in ratios:
            se = lb.bootstrap_standard_error(x, stat, rng=np.random.default_rng(1000 + k), n_resamples=400)
            ratios[stat].append(se / closed[stat])
    assert np.mean(ratios[np.mean]) == pytest.approx(1.0, abs=0.04)
    assert np.mean(ratios[np.median]) == pytest.approx(1.0, abs=0.08)
    with pytest.raises(ValueError, match="two"):
        lb.bootstrap_standard_error([1.0], np.mean, rng=np.random.default_rng(0))


def test_jackknife_standard_error_closed_forms():
    """For the mean the delete-one jackknife SE is s / sqrt(n) exactly (Efron and Tibshirani 1993, Sec. 11.2); for a
    difference of means of paired runs it is that of the paired differences."""
    rng = np.random.default_rng(0)
    x, y = rng.normal(size=50), rng.normal(size=50)
    assert lb.jackknife_standard_error(np.mean, x) == pytest.approx(x.std(ddof=1) / np.sqrt(x.size), rel=1e-12)
    d = x - y
    assert lb.jackknife_standard_error(lambda a, b: a.mean() - b.mean(), x, y) == pytest.approx(
        d.std(ddof=1) / np.sqrt(d.size), rel=1e-12)
    with pytest.raises(lb.ParameterError, match="per_run"):
        lb.jackknife_standard_error(np.mean, x, y[:10])
    with pytest.raises(lb.ParameterError, match="per_run"):
        lb.jackknife_standard_error(np.mean, [1.0])
