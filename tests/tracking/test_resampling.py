"""Resampling schemes: unbiased offspring counts (E[count_j] = N w_j), the residual scheme's closed-form count
distribution, and systematic / stratified / multinomial against filterpy's implementations in distribution (filterpy's
uniforms come from a seeded Generator injected in its module, never from the global RNG)."""
import filterpy.monte_carlo.resampling as fp_resampling
import numpy as np
import pytest

import locbook as lb
from locbook.tracking.resampling import RESAMPLING_METHODS

W = np.array([0.02, 0.33, 0.05, 0.25, 0.01, 0.17, 0.12, 0.05])
N = W.size
DRAWS = 20000


def _counts(indices):
    return np.apply_along_axis(np.bincount, -1, indices, minlength=N)


@pytest.mark.parametrize("method", RESAMPLING_METHODS)
def test_each_scheme_is_unbiased(method):
    rng = np.random.default_rng(1)
    idx = lb.resample(np.broadcast_to(W, (DRAWS, N)), rng=rng, method=method)
    counts = _counts(idx)
    assert np.all(counts.sum(axis=1) == N)
    se = counts.std(axis=0, ddof=1) / np.sqrt(DRAWS)
    assert np.all(np.abs(counts.mean(axis=0) - N * W) <= 4 * se + 1e-12)
    # no scheme beats nothing: multinomial has the binomial variance, the others at most that
    var = counts.var(axis=0, ddof=1)
    assert np.all(var <= N * W * (1 - W) * 1.1 + 1e-12)
    if method == "multinomial":
        np.testing.assert_allclose(var, N * W * (1 - W), rtol=0.06)


def test_residual_counts_are_the_floor_plus_a_multinomial_of_the_rest():
    rng = np.random.default_rng(2)
    counts = _counts(lb.resample(np.broadcast_to(W, (DRAWS, N)), rng=rng, method="residual"))
    floor = np.floor(N * W)
    assert np.all(counts >= floor)
    rest = N - floor.sum()
    r = (N * W - floor) / rest
    np.testing.assert_allclose(counts.var(axis=0, ddof=1), rest * r * (1 - r), rtol=0.06, atol=1e-3)


@pytest.mark.parametrize("method, theirs", [("systematic", fp_resampling.systematic_resample),
                                            ("stratified", fp_resampling.stratified_resample),
                                            ("multinomial", fp_resampling.multinomial_resample)])
def test_matches_filterpy_in_distribution(method, theirs, monkeypatch):
    gen = np.random.default_rng(3)
    monkeypatch.setattr(fp_resampling, "random", lambda size=None: gen.random(size))
    ref = np.array([np.bincount(theirs(W), minlength=N) for _ in range(DRAWS // 4)])
    ours = _counts(lb.resample(np.broadcast_to(W, (DRAWS // 4, N)), rng=np.random.default_rng(4), method=method))
    se = np.sqrt((ref.var(axis=0, ddof=1) + ours.var(axis=0, ddof=1)) / ref.shape[0])
    assert np.all(np.abs(ours.mean(axis=0) - ref.mean(axis=0)) <= 4 * se + 1e-12)
    # the spread of each particle's count is the scheme's signature (systematic: count in {floor, ceil})
    np.testing.assert_allclose(ours.var(axis=0), ref.var(axis=0), rtol=0.15, atol=0.01)
    if method == "systematic":
        assert np.all((ours >= np.floor(N * W)) & (ours <= np.ceil(N * W)))


def test_neff_triggered_resampling_keeps_rows_above_the_threshold():
    w = np.stack([np.full(N, 1 / N), W])
    idx, done = lb.resample_where(w, rng=np.random.default_rng(0), threshold=5.0)   # N_eff of W is 4.54
    assert done.tolist() == [False, True]
    np.testing.assert_array_equal(idx[0], np.arange(N))
    with pytest.raises(ValueError, match="non-negative"):
        lb.resample(np.array([0.5, -0.1, 0.6]), rng=np.random.default_rng(0))


SIZES = sorted(set(range(1, 300)) | {20, 49, 500, 999, 1000, 1024, 2000, 4096, 10000})


def test_residual_resampling_of_uniform_weights_is_deterministic_like_filterpy(monkeypatch):
    """With equal weights every particle gets exactly floor(N w) = 1 copy and nothing is drawn.
    N w computed in floating point can land one ulp under 1 (N = 20, 49, 1000, ...), which made the scheme draw at
    random; filterpy's residual_resample (given weights that do sum to 1) and Stone Soup copy each particle once."""
    gen = np.random.default_rng(5)
    monkeypatch.setattr(fp_resampling, "random", lambda size=None: gen.random(size))
    for n in SIZES:
        expected = np.arange(n)
        ones = np.ones(n)
        if n * (1.0 / n) == 1.0:      # weights summing to 1 whose N w is exactly 1: filterpy copies each particle once
            with np.errstate(invalid="ignore", divide="ignore"):
                np.testing.assert_array_equal(fp_resampling.residual_resample(np.full(n, 1.0 / n)), expected)
        for weights in (ones, np.full(n, 1.0 / n), np.full((3, n), 7.3)):
            for seed in (0, 1):
                idx = lb.resample(weights, rng=np.random.default_rng(seed), method="residual")
                np.testing.assert_array_equal(idx, np.broadcast_to(expected, np.shape(weights)), err_msg=f"N = {n}")


def test_residual_resampling_counts_never_exceed_n_near_integers():
    """The tolerance that rounds N w up to an integer must not create more than N offspring: weights just above and
    below k / N in alternation still give exactly N particles, each at least floor(N w) - 0 and within one of N w."""
    rng = np.random.default_rng(6)
    for n in (2, 3, 20, 49, 1000):
        eps = np.finfo(float).eps
        w = np.full(n, 1.0 / n) * (1 + eps * np.where(np.arange(n) % 2, -4, 4))
        idx = lb.resample(w, rng=rng, method="residual")
        counts = np.bincount(idx, minlength=n)
        assert counts.sum() == n
        assert np.all(np.abs(counts - n * w / w.sum()) < 1 + 1e-9)


def test_the_effective_sample_size_of_no_weights_is_refused():
    """1 / sum(w^2) over no weights is 1 / 0 = inf: a confident number from empty input."""
    from locbook.tracking.resampling import effective_sample_size
    with pytest.raises(ValueError, match=r"^weights must hold at least one weight along the last axis"):
        effective_sample_size(np.zeros((3, 0)))
    np.testing.assert_allclose(effective_sample_size(np.full((2, 4), 0.25)), [4.0, 4.0])
