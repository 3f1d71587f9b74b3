"""The error metrics (locbook.metrics) by hand and against closed forms, masked errors, and the bootstrap intervals of
:func:`locbook.accuracy_metrics`: the circular block bootstrap weights every epoch equally, too few blocks give no
interval, an interval that excludes its estimate says so, and the i.i.d. bootstrap keeps its numbers."""
import warnings

import numpy as np
import pytest
from scipy.signal import lfilter
from scipy.stats import norm

import locbook as lb
import locbook.metrics as metrics
from locbook.metrics import ACCURACY_STATISTICS, MIN_BLOCKS, accuracy_metrics
from locbook.montecarlo import circular_block_indices, moving_block_indices


class _EveryStart(np.random.Generator):
    """A generator whose ``integers`` enumerates every start: resample ``r`` has all its blocks start at
    ``low + r``, so ``high - low`` resamples visit each possible start once. It records the range asked for."""

    def integers(self, low, high=None, size=None, **kwargs):
        self.asked = (low, high, size)
        assert size[0] == high - low, "call with one resample per possible start"
        return np.broadcast_to(np.arange(low, high)[:, None], size).copy()


@pytest.mark.parametrize("n, block", [(10, 3), (12, 5), (7, 7), (5, 1), (9, 20)])
def test_circular_blocks_hold_every_epoch_once_per_position_over_all_starts(n, block):
    """Over all n starts, every position of a resample holds each epoch exactly once ((s + j) mod n is a bijection),
    so each epoch is equally likely: the count of every epoch is n, exactly."""
    g = _EveryStart(np.random.PCG64(0))
    idx = circular_block_indices(n, block, n, rng=g)
    assert g.asked[:2] == (0, n)                                   # starts anywhere on the circle
    assert idx.shape == (n, n)
    for j in range(n):
        np.testing.assert_array_equal(np.sort(idx[:, j]), np.arange(n))
    np.testing.assert_array_equal(np.bincount(idx.ravel(), minlength=n), np.full(n, n))


def test_moving_blocks_over_all_starts_under_weight_the_ends():
    """The contrast (and the moving-block bootstrap's documented bias): over its n - L + 1 starts, epoch i lies in
    min(i + 1, L, n - i, n - L + 1) blocks, so the ends are covered less often than the middle."""
    n, block = 12, 4
    g = _EveryStart(np.random.PCG64(0))
    idx = moving_block_indices(n, block, n - block + 1, rng=g)
    assert g.asked[:2] == (0, n - block + 1)
    # the blocks of each start (one resample per start; its first block is that start's block)
    first = idx[:, :block]
    i = np.arange(n)
    np.testing.assert_array_equal(np.bincount(first.ravel(), minlength=n),
                                  np.minimum.reduce([i + 1, np.full(n, block), n - i, np.full(n, n - block + 1)]))


def test_the_bootstrap_mean_of_resampled_means_is_the_sample_mean():
    """A trending series (the ends far from the middle): the circular resamples' mean is the sample mean within four
    Monte-Carlo standard errors of the resamples' own spread; the moving-block resamples miss it by far more."""
    rng = np.random.default_rng(5)
    n, block, reps = 200, 20, 20000
    x = np.linspace(0.0, 10.0, n) ** 2 + rng.normal(0.0, 1.0, n)
    means = x[circular_block_indices(n, block, reps, rng=np.random.default_rng(6))].mean(axis=1)
    se = means.std(ddof=1) / np.sqrt(reps)
    assert abs(means.mean() - x.mean()) < 4 * se
    moving = x[moving_block_indices(n, block, reps, rng=np.random.default_rng(6))].mean(axis=1)
    assert abs(moving.mean() - x.mean()) > 10 * moving.std(ddof=1) / np.sqrt(reps)


def test_too_few_blocks_give_no_interval_and_say_why():
    """24 epochs in blocks of 10 are 2.4 blocks: every interval NaN, the statistics still computed, one note."""
    e = np.abs(np.random.default_rng(1).normal(size=24))
    m = accuracy_metrics(e, rng=np.random.default_rng(2), block_length=10)
    assert m["n_blocks"] == pytest.approx(2.4)
    assert m["interval_note"] == "not estimable: 24 epochs hold 2.4 blocks of 10; the rule needs at least 10 blocks"
    assert m["interval"] == "circular block bootstrap, blocks of 10 epochs (1000 resamples)"
    for s in ACCURACY_STATISTICS:
        assert np.isnan(m[s + "_low"]) and np.isnan(m[s + "_high"]) and m[s + "_note"] == ""
    assert m["mean_m"] == pytest.approx(e.mean()) and m["max_m"] == e.max()


def test_the_block_count_is_taken_over_the_epochs_with_an_estimate():
    """100 epochs of which 5 have no estimate hold 9.5 blocks of 10 (not estimable); 4 missing leave 9.6; 100
    finite epochs are exactly 10 blocks (estimable). The i.i.d. bootstrap counts single epochs."""
    e = np.linspace(0.1, 3.0, 100)
    missing = e.copy()
    missing[[3, 30, 50, 70, 99]] = np.nan
    m = accuracy_metrics(missing, rng=np.random.default_rng(0), n_bootstrap=200, block_length=10)
    assert m["n_blocks"] == pytest.approx(9.5) and np.isnan(m["mean_m_low"])
    assert m["interval_note"] == ("not estimable: 95 epochs with an estimate hold 9.5 blocks of 10; the rule needs at "
                                  "least 10 blocks")
    full = accuracy_metrics(e, rng=np.random.default_rng(0), n_bootstrap=200, block_length=10)
    assert full["n_blocks"] == MIN_BLOCKS and full["interval_note"] == ""
    assert full["mean_m_low"] <= full["mean_m"] <= full["mean_m_high"]
    short = accuracy_metrics(e[:MIN_BLOCKS - 1], rng=np.random.default_rng(0), n_bootstrap=200)
    assert np.isnan(short["rmse_m_low"]) and short["interval_note"] == (
        f"not estimable: {MIN_BLOCKS - 1} epochs with an estimate; the rule needs at least {MIN_BLOCKS}")
    assert short["interval"] == "bootstrap over epochs (i.i.d., 200 resamples)"
    relaxed = accuracy_metrics(e[:24], rng=np.random.default_rng(0), n_bootstrap=200, block_length=10, min_blocks=2)
    assert relaxed["interval_note"] == "" and np.isfinite(relaxed["mean_m_low"])


def test_no_estimate_at_all_gives_no_interval():
    m = accuracy_metrics(np.full(50, np.nan), rng=np.random.default_rng(0), n_bootstrap=50)
    assert m["coverage"] == 0 and m["n_blocks"] == 0 and np.isnan(m["mean_m"]) and np.isnan(m["mean_m_high"])
    assert m["interval_note"].startswith("not estimable: 0 epochs")


def test_circular_block_interval_of_an_ar1_mean_has_the_width_of_the_theory():
    """An AR(1) series x_t = phi x_{t-1} + w_t (w ~ N(0, 1), phi = 0.5, n = 5000): the sample mean's standard
    deviation is sqrt(var / n ((1 + phi) / (1 - phi) - 2 phi (1 - phi^n) / (n (1 - phi)^2))), var = 1 / (1 - phi^2),
    and the 95 % interval is 2 z_0.975 times it. The circular block bootstrap with blocks of L estimates the
    variance with Bartlett weights, var (1 + 2 sum_{k<L} (1 - k/L) phi^k) / n in expectation (Politis and Romano
    1992), a known shrinkage; around it the width varies by the estimate's own sampling error (relative variance
    (4/3) L / n, Kuensch 1989, halved for a standard deviation) and by the Monte-Carlo error of two percentiles of
    B resamples (variance p (1 - p) / (B phi(z)^2) each). Window: four of those standard deviations. The i.i.d.
    bootstrap's width, sqrt((1 - phi) / (1 + phi)) = 0.58 of it, lies far outside."""
    n, phi, block, reps = 5000, 0.5, 25, 1000
    rng = np.random.default_rng(2024)
    burn = 200                                                       # phi^200: the start forgotten
    x = lfilter([1.0], [1.0, -phi], rng.normal(size=n + burn))[burn:] + 20.0   # shifted to be a distance
    var = 1.0 / (1.0 - phi**2)
    sd_mean = np.sqrt(var / n * ((1 + phi) / (1 - phi) - 2 * phi * (1 - phi**n) / (n * (1 - phi) ** 2)))
    z, p = norm.ppf(0.975), 0.025
    k = np.arange(1, block)
    shrink = np.sqrt((1 + 2 * np.sum((1 - k / block) * phi**k)) / ((1 + phi) / (1 - phi)))
    s_estimate = 0.5 * np.sqrt(4.0 / 3.0 * block / n)
    s_mc = np.sqrt(2 * p * (1 - p) / (reps * norm.pdf(z) ** 2)) / (2 * z)
    window = 4 * np.hypot(s_estimate, s_mc)
    m = accuracy_metrics(x, rng=np.random.default_rng(7), n_bootstrap=reps, block_length=block)
    ratio = (m["mean_m_high"] - m["mean_m_low"]) / (2 * z * sd_mean)
    assert abs(ratio - shrink) < window
    iid = accuracy_metrics(x, rng=np.random.default_rng(7), n_bootstrap=reps)
    assert abs((iid["mean_m_high"] - iid["mean_m_low"]) / (2 * z * sd_mean) - shrink) > window


def test_an_interval_that_excludes_its_estimate_is_flagged(monkeypatch):
    """The largest error at the last of 1000 epochs, blocks of 100 drawn as the moving-block bootstrap draws them:
    a block holds the last epoch once in 901 starts, so about 1 % of resamples hold it and the maximum's 97.5 %
    point falls below the maximum. The interval is kept as computed and flagged; the circular bootstrap, where that
    epoch is as likely as any, gives an interval that reaches the maximum and no note."""
    e = np.random.default_rng(3).uniform(0.0, 1.0, 1000)
    e[-1] = 5.0
    fine = accuracy_metrics(e, rng=np.random.default_rng(4), n_bootstrap=2000, block_length=100)
    assert fine["max_m_high"] == 5.0 and fine["max_m_note"] == ""
    monkeypatch.setattr(metrics, "circular_block_indices", moving_block_indices)
    m = accuracy_metrics(e, rng=np.random.default_rng(4), n_bootstrap=2000, block_length=100)
    low, high = m["max_m_low"], m["max_m_high"]
    assert high < 1.0 and m["max_m"] == 5.0                          # not widened
    assert m["max_m_note"].startswith(f"the interval excludes the estimate (5.00 outside [{low:.2f}, {high:.2f}]): "
                                      "the maximum is a skewed statistic at the edge of its bootstrap distribution")
    idx = moving_block_indices(1000, 100, 2000, rng=np.random.default_rng(4))
    share = 100 * np.mean(~(idx == 999).any(axis=1))                 # resamples without the last epoch
    assert m["max_m_note"].endswith(f"; {share:.1f} % of the resamples fall below it")
    for s in ACCURACY_STATISTICS:                                    # every other interval holds its estimate
        held = m[s + "_low"] <= m[s] <= m[s + "_high"]
        assert (m[s + "_note"] == "") == held


def test_the_moving_block_bias_is_flagged_and_the_circular_bootstrap_has_none(monkeypatch):
    """The reported moving-block bias in miniature: errors of 5 m in the first and last 50 of 1000 epochs, 1 m between
    (mean exactly 1.4 m), 10 blocks of 100. The moving-block resamples under-weight both ends, so their means fall
    below 1.4 and the interval misses it: flagged, with the block count named. The circular resamples hold it."""
    e = np.ones(1000)
    e[:50] = e[-50:] = 5.0
    fine = accuracy_metrics(e, rng=np.random.default_rng(4), n_bootstrap=2000, block_length=100)
    assert fine["mean_m_low"] <= 1.4 <= fine["mean_m_high"]
    assert all(fine[s + "_note"] == "" for s in ACCURACY_STATISTICS)
    monkeypatch.setattr(metrics, "circular_block_indices", moving_block_indices)
    m = accuracy_metrics(e, rng=np.random.default_rng(4), n_bootstrap=2000, block_length=100)
    assert m["mean_m"] == pytest.approx(1.4) and m["mean_m_high"] < 1.4
    assert m["mean_m_note"].startswith(f"the interval excludes the estimate (1.40 outside [{m['mean_m_low']:.2f}, "
                                       f"{m['mean_m_high']:.2f}]): few blocks for the mean (10 blocks of 100 epochs), "
                                       "so the resampled statistic takes few distinct values; ")


def _old_accuracy_metrics(e, rng, n_bootstrap, level):
    """The i.i.d. bootstrap as it was before the block bootstrap (block_length 1): indices rng.integers(0, n, (B, n)),
    NaN-aware statistics, percentile interval."""
    n = e.size
    idx = rng.integers(0, n, size=(n_bootstrap, n))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        stats = lambda a, axis=None: {
            "mean_m": np.nanmean(a, axis=axis), "median_m": np.nanmedian(a, axis=axis),
            "rmse_m": np.sqrt(np.nanmean(a**2, axis=axis)), "p75_m": np.nanpercentile(a, 75, axis=axis),
            "p90_m": np.nanpercentile(a, 90, axis=axis), "ce95_m": np.nanpercentile(a, 95, axis=axis),
            "max_m": np.nanmax(a, axis=axis)}
        point, boot = stats(e), stats(e[idx], axis=-1)
    tail = 50.0 * (1.0 - level)
    out = {}
    for s in point:
        out[s] = float(point[s])
        out[s + "_low"], out[s + "_high"] = (float(v) for v in np.nanpercentile(boot[s], [tail, 100.0 - tail]))
    return out


@pytest.mark.parametrize("level", [0.95, 0.8])
def test_iid_bootstrap_numbers_are_unchanged(level):
    """block_length 1: every statistic and bound equal, bit for bit, to the pre-issue-46 formula, and the stream
    advanced by the same draws."""
    e = np.abs(np.random.default_rng(8).normal(0.0, 2.0, 300))
    e[[4, 40, 200]] = np.nan
    ours, theirs = np.random.default_rng(9), np.random.default_rng(9)
    m = accuracy_metrics(e, rng=ours, n_bootstrap=400, level=level)
    old = _old_accuracy_metrics(e, theirs, 400, level)
    for key, value in old.items():
        assert m[key] == value, key
    assert ours.integers(0, 2**62) == theirs.integers(0, 2**62)
    assert m["interval"] == "bootstrap over epochs (i.i.d., 400 resamples)" and m["interval_note"] == ""
    assert m["n_blocks"] == 297.0 and m["n"] == 300 and m["coverage"] == pytest.approx(297 / 300)


def test_moving_block_indices_keep_their_numbers():
    """The calibration bootstrap's resampler, as it was: starts rng.integers(0, n - L + 1, (B, ceil(n / L)))."""
    n, block, reps = 37, 5, 50
    starts = np.random.default_rng(1).integers(0, n - block + 1, size=(reps, -(-n // block)))
    old = (starts[..., None] + np.arange(block)).reshape(reps, -1)[:, :n]
    np.testing.assert_array_equal(moving_block_indices(n, block, reps, rng=np.random.default_rng(1)), old)


def test_circular_block_one_draws_as_the_ordinary_bootstrap():
    a = circular_block_indices(40, 1, 30, rng=np.random.default_rng(3))
    np.testing.assert_array_equal(a, np.random.default_rng(3).integers(0, 40, size=(30, 40)))
    # a block longer than the series is the series itself, rotated
    r = circular_block_indices(6, 50, 4, rng=np.random.default_rng(3))
    np.testing.assert_array_equal((r - r[:, :1]) % 6, np.tile(np.arange(6), (4, 1)))


@pytest.mark.parametrize("kwargs, match", [({"min_blocks": 0}, "min_blocks"), ({"min_blocks": np.nan}, "min_blocks"),
                                           ({"block_length": 0}, "block_length"),
                                           ({"block_length": 2.5}, "block_length")])
def test_bad_interval_options_name_the_argument(kwargs, match):
    with pytest.raises(ValueError, match=match):
        accuracy_metrics(np.ones(30), rng=np.random.default_rng(0), **kwargs)


def test_circular_indices_refuse_a_seed_for_a_generator():
    from locbook.errors import ParameterError
    with pytest.raises(ParameterError, match="rng must be a numpy.random.Generator"):
        circular_block_indices(10, 2, 5, rng=0)


def test_values_per_epoch_resamples_whole_epochs():
    """k runs per epoch: the bootstrap draws epochs, each with all its runs. With k identical copies of every epoch the
    mean and RMSE and their intervals are those of one copy under the same draws (a second computation), and the
    block count is the epochs'."""
    e = np.abs(np.random.default_rng(3).normal(1.0, 0.5, 60))
    one = accuracy_metrics(e, rng=np.random.default_rng(9), n_bootstrap=300, block_length=3)
    three = accuracy_metrics(np.repeat(e, 3), rng=np.random.default_rng(9), n_bootstrap=300, block_length=3,
                                values_per_epoch=3)
    for key in ("mean_m", "mean_m_low", "mean_m_high", "rmse_m", "rmse_m_low", "rmse_m_high", "n_blocks"):
        assert three[key] == pytest.approx(one[key], rel=1e-12), key
    assert three["n"] == 180
    with pytest.raises(ValueError, match="values_per_epoch"):
        accuracy_metrics(np.ones(7), rng=np.random.default_rng(0), values_per_epoch=3)


MASKED = np.ma.array([1.0, 2.0, 3.0, 1000.0], mask=[0, 0, 0, 1])


@pytest.mark.parametrize("fn", [metrics.mean_error_m, metrics.rmse_m, metrics.median_error_m, metrics.error_std_m,
                                metrics.percentile_error_m, metrics.rmse_standard_error_m, lb.mc_standard_error])
def test_a_masked_error_is_a_nan_in_every_metric(fn):
    assert np.isnan(fn(MASKED))
    assert np.isnan(fn(np.array([1.0, 2.0, 3.0, np.nan])))
    full = fn(np.ma.array([1.0, 2.0, 3.0, 4.0], mask=False))     # nothing masked: the plain array's value
    assert full == fn(np.array([1.0, 2.0, 3.0, 4.0]))


def test_masked_errors_in_summaries_and_the_cdf():
    s = metrics.error_summary(MASKED)                            # was numpy's "output array is read-only"
    assert s["n"] == 4 and all(np.isnan(s[k]) for k in ("mean_m", "rmse_m", "median_m", "p90_m", "std_m"))
    x, p = metrics.empirical_cdf(MASKED)
    assert not np.ma.isMaskedArray(x) and np.isnan(x[-1]) and np.array_equal(x[:3], [1, 2, 3])
    assert np.array_equal(p, [0.25, 0.5, 0.75, 1.0])
    per_run = metrics.error_summary_per_run(np.ma.array([[1.0, 2.0], [3.0, 4.0]], mask=[[0, 1], [0, 0]]))
    assert np.isnan(per_run["rmse_m"][0]) and per_run["rmse_m"][1] == np.sqrt(12.5)
    r = metrics.reduction_pct(np.ma.array([2.0, 4.0], mask=[0, 1]), 1.0)
    assert r[0] == 50.0 and np.isnan(r[1])
    assert lb.mc_standard_error([1.0, 3.0]) == 1.0                 # std(ddof=1) sqrt(2) / sqrt(2)


def test_metrics():
    assert round(float(lb.reduction_pct(2.2867, 1.0378)), 2) == 54.62      # document 003's three numbers agree
    e = np.random.default_rng(0).rayleigh(size=1000)
    assert lb.rmse_m(e) ** 2 == pytest.approx(lb.mean_error_m(e) ** 2 + lb.error_std_m(e) ** 2, rel=1e-12)
    assert lb.mean_error_m(lb.position_error_m([[3.0, 4.0], [0.0, 1.0]], [[0.0, 0.0], [0.0, 0.0]])) == 3.0
    x, f = lb.empirical_cdf([3.0, 1.0, 2.0])
    np.testing.assert_array_equal(x, [1, 2, 3])
    np.testing.assert_allclose(f, [1 / 3, 2 / 3, 1])
    assert lb.percentile_error_m(np.arange(11.0), 90) == 9.0


def test_metrics_by_hand():
    # errors 1, 2, 2, 5 (sum 10, sum of squares 34): every statistic written out, not derived from another one
    e = np.array([1.0, 2.0, 2.0, 5.0])
    assert lb.mean_error_m(e) == 2.5
    assert lb.rmse_m(e) == pytest.approx(np.sqrt(34 / 4), rel=1e-15)
    assert lb.error_std_m(e) == pytest.approx(1.5, rel=1e-15)                        # sqrt(34/4 - 2.5^2)
    assert lb.error_std_m(e, ddof=1) == pytest.approx(np.sqrt(9 / 3), rel=1e-15)      # squared deviations 9 in all
    assert lb.median_error_m(e) == 2.0
    assert lb.percentile_error_m(e, 90) == pytest.approx(4.1, rel=1e-15)            # rank 0.9 * 3 = 2.7: 2 + 0.7 * 3
    assert lb.percentile_error_m(e, 25) == pytest.approx(1.75, rel=1e-15)           # rank 0.75: 1 + 0.75 * 1
    # delta method: squared errors 1, 4, 4, 25 (mean 8.5, sample variance 369 / 3 = 123)
    assert lb.rmse_standard_error_m(e) == pytest.approx(np.sqrt(123 / 4) / (2 * np.sqrt(8.5)), rel=1e-14)
    assert lb.reduction_pct(4.0, 3.0) == 25.0 and lb.reduction_pct(2.0, 3.0) == -50.0
    summary = lb.error_summary(e.reshape(2, 2))
    assert summary == pytest.approx({"mean_m": 2.5, "rmse_m": np.sqrt(8.5), "median_m": 2.0, "p90_m": 4.1,
                                     "std_m": 1.5, "n": 4}, rel=1e-15)
    # axis: one value per row of a (runs, steps) array
    two = np.array([[3.0, 4.0], [0.0, 2.0]])
    np.testing.assert_allclose(lb.rmse_m(two, axis=-1), [np.sqrt(12.5), np.sqrt(2.0)], rtol=1e-15)
    np.testing.assert_allclose(lb.mean_error_m(two, axis=0), [1.5, 3.0], rtol=1e-15)
    np.testing.assert_allclose(lb.error_std_m(two, axis=1), [0.5, 1.0], rtol=1e-15)
    # 3-D Euclidean error, batched: |(1, 2, 2)| = 3, |(2, 3, 6)| = 7
    est, truth = [[1.0, 2.0, 2.0], [3.0, 3.0, 6.0]], [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]
    np.testing.assert_allclose(lb.position_error_m(est, truth), [3.0, 7.0], rtol=1e-15)
    x, f = lb.empirical_cdf(np.array([[2.0, 2.0], [1.0, 4.0]]))
    np.testing.assert_array_equal(x, [1.0, 2.0, 2.0, 4.0])
    np.testing.assert_allclose(f, [0.25, 0.5, 0.75, 1.0])


def test_rmse_standard_error_matches_the_spread_of_the_rmse():
    # the delta-method SE must be the actual Monte-Carlo spread of the RMSE of n errors
    rng = np.random.default_rng(21)
    n = 400
    samples = rng.rayleigh(size=(4000, n))
    spread = np.std(lb.rmse_m(samples, axis=-1), ddof=1)
    se = lb.rmse_standard_error_m(samples, axis=-1)
    assert np.mean(se) == pytest.approx(spread, rel=0.05)       # SE of a sample sd over 4000 repeats is ~1.1 %


def test_single_run_interval_is_the_central_sample_quantile_range():
    from scipy.stats.mstats import mquantiles
    lo, hi = lb.single_run_interval(np.linspace(0, 1, 100001), 0.9)
    assert (lo, hi) == pytest.approx((0.05, 0.95), abs=1e-12)
    x = np.random.default_rng(3).gamma(2.0, size=37)
    # numpy's linear percentile is Hyndman-Fan type 7, scipy's mquantiles with alphap = betap = 1
    np.testing.assert_allclose(lb.single_run_interval(x, 0.8), mquantiles(x, [0.1, 0.9], alphap=1, betap=1),
                               rtol=1e-12)
    with pytest.raises(lb.ParameterError, match="coverage"):
        lb.single_run_interval(x, 1.0)


def test_fix_error_covariance_is_numpy_cov_of_the_errors_per_run():
    rng = np.random.default_rng(11)
    truth = rng.uniform(0, 5, size=(40, 2))
    fixes = truth + rng.normal(size=(3, 40, 2)) * [0.5, 2.0] + [1.0, -1.0]     # a bias does not enter
    R = lb.fix_error_covariance(fixes, truth)
    for k in range(3):
        np.testing.assert_allclose(R[k], np.cov((fixes[k] - truth).T), rtol=1e-12)


def test_the_bootstraps_percentiles_equal_numpys_nanpercentile_bit_for_bit():
    """The resamples' percentiles are taken for all rows at once (metrics._nan_percentiles); numpy's nanpercentile,
    one row at a time, is the oracle: equal to the last bit, with ties, all-NaN rows, one-value rows, q = 0 and 100."""
    rng = np.random.default_rng(7)
    for trial in range(300):
        rows, cols = rng.integers(1, 40), rng.integers(1, 200)
        e = rng.gamma(2.0, 1.0, (rows, cols)) * rng.choice([1e-3, 1.0, 1e3])
        e[rng.random((rows, cols)) < rng.random()] = np.nan
        e[0] = np.nan if trial % 7 == 0 else e[0]
        e = np.round(e, 1) if trial % 5 == 0 else e
        q = [75, 90, 95] if trial % 2 else [0.0, *rng.uniform(0, 100, 3), 50.0, 100.0]
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)       # numpy warns on an all-NaN row
            expected = np.nanpercentile(e, q, axis=-1)
        np.testing.assert_array_equal(metrics._nan_percentiles(e, q), expected)
