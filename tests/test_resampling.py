"""Resampling schemes: unbiased offspring counts (E[count_j] = N w_j), the residual scheme's closed-form count
distribution, and systematic / stratified / multinomial against filterpy's implementations in distribution (filterpy's
uniforms come from a seeded Generator injected in its module, never from the global RNG)."""
import numpy as np
import pytest
import filterpy.monte_carlo.resampling as fp_resampling

import locbook as lb

W = np.array([0.02, 0.33, 0.05, 0.25, 0.01, 0.17, 0.12, 0.05])
N = W.size
DRAWS = 20000


def _counts(indices):
    return np.apply_along_axis(np.bincount, -1, indices, minlength=N)


@pytest.mark.parametrize("method", lb.RESAMPLING_METHODS)
def test_each_scheme_is_unbiased(method):
    rng = np.random.default_rng(1)
    idx = lb.resample(np.broadcast_to(W, (DRAWS, N)), rng, method)
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
    counts = _counts(lb.resample(np.broadcast_to(W, (DRAWS, N)), rng, "residual"))
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
    ours = _counts(lb.resample(np.broadcast_to(W, (DRAWS // 4, N)), np.random.default_rng(4), method))
    se = np.sqrt((ref.var(axis=0, ddof=1) + ours.var(axis=0, ddof=1)) / ref.shape[0])
    assert np.all(np.abs(ours.mean(axis=0) - ref.mean(axis=0)) <= 4 * se + 1e-12)
    # the spread of each particle's count is the scheme's signature (systematic: count in {floor, ceil})
    np.testing.assert_allclose(ours.var(axis=0), ref.var(axis=0), rtol=0.15, atol=0.01)
    if method == "systematic":
        assert np.all((ours >= np.floor(N * W)) & (ours <= np.ceil(N * W)))


def test_neff_triggered_resampling_keeps_rows_above_the_threshold():
    w = np.stack([np.full(N, 1 / N), W])
    idx, done = lb.resample_where(w, np.random.default_rng(0), threshold=5.0)   # N_eff of W is 4.54
    assert done.tolist() == [False, True]
    np.testing.assert_array_equal(idx[0], np.arange(N))
    with pytest.raises(ValueError, match="non-negative"):
        lb.resample(np.array([0.5, -0.1, 0.6]), np.random.default_rng(0))
