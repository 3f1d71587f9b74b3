"""Lateration from per-problem receivers (2-D and 3-D) against cvxpy, RLS against batch LS, and the log-normal
range moments against Monte Carlo and closed forms (Palvai 2008, note 002 s.2.4-2.8)."""
import cvxpy as cp
import numpy as np
import pytest

import locbook as lb


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("reference", lb.LATERATION_REFERENCES)
def test_least_squares_equals_cvxpy_and_is_exact_without_noise(dim, reference):
    rng = np.random.default_rng(dim)
    s = rng.uniform(0, 50, (4, 12, dim))
    target = rng.uniform(0, 50, (4, dim))
    d_true = np.linalg.norm(s - target[:, None], axis=-1)
    exact = lb.least_squares_position(s, d_true, reference=reference)
    np.testing.assert_allclose(exact.position_m, target, atol=1e-7)
    d = d_true * np.exp(0.2 * rng.standard_normal(d_true.shape))
    ours = lb.least_squares_position(s, d, reference=reference).position_m
    H, Y = lb.lateration_rows(s, d, reference=reference)
    for r in range(4):
        x = cp.Variable(dim)
        cp.Problem(cp.Minimize(cp.sum_squares(H[r] @ x - Y[r]))).solve()
        np.testing.assert_allclose(ours[r], x.value, atol=1e-5)


def test_printed_rows_without_the_factor_2_double_the_coordinates():
    rng = np.random.default_rng(0)
    s = rng.uniform(0, 50, (10, 3))
    target = np.array([20.0, 30.0, 25.0])
    d = np.linalg.norm(s - target, axis=-1)
    lit = lb.least_squares_position(s, d, variant="literal_002").position_m
    np.testing.assert_allclose(lit, 2 * target, rtol=1e-9)


def test_missing_readings_drop_their_rows_and_too_few_rows_give_nan():
    rng = np.random.default_rng(1)
    s = rng.uniform(0, 50, (6, 3))
    target = np.array([10.0, 20.0, 30.0])
    d = np.linalg.norm(s - target, axis=-1)
    d2 = d.copy()
    d2[2] = np.nan                                  # rows (1,2) and (2,3) go
    res = lb.least_squares_position(np.stack([s, s]), np.stack([d2, np.r_[d[:3], np.nan, np.nan, np.nan]]))
    np.testing.assert_allclose(res.position_m[0], target, atol=1e-7)
    assert res.status.tolist() == ["ok", "too_few_anchors"] and np.all(np.isnan(res.position_m[1]))


def test_rls_equals_the_regularised_batch_solution_and_batch_ls_as_the_prior_vanishes():
    rng = np.random.default_rng(2)
    H = rng.standard_normal((5, 30, 3))
    y = rng.standard_normal((5, 30))
    x0 = np.array([1.0, -2.0, 0.5])
    prior = np.diag([4.0, 9.0, 1.0])
    rls = lb.recursive_least_squares(H, y, x0=x0, prior_cov=prior)
    for k in (0, 4, 29):
        Hk, yk = H[:, :k + 1], y[:, :k + 1]
        info = np.linalg.inv(prior) + np.einsum("rki,rkj->rij", Hk, Hk)
        rhs = np.linalg.solve(prior, x0) + np.einsum("rki,rk->ri", Hk, yk)
        np.testing.assert_allclose(rls.x[:, k], np.linalg.solve(info, rhs[..., None])[..., 0], atol=1e-9)
        np.testing.assert_allclose(rls.P[:, k], np.linalg.inv(info), atol=1e-9)
    vague = lb.recursive_least_squares(H, y, prior_cov=1e10 * np.eye(3))
    batch = np.linalg.lstsq(H[0], y[0], rcond=None)[0]
    np.testing.assert_allclose(vague.x[0, -1], batch, atol=1e-6)
    # RLSF on the lateration rows = LSF (the thesis: "identical error performance")
    s = rng.uniform(0, 50, (3, 20, 3))
    d = np.linalg.norm(s - 25.0, axis=-1) * np.exp(0.3 * rng.standard_normal((3, 20)))
    Hl, Yl = lb.lateration_rows(s, d)
    np.testing.assert_allclose(lb.recursive_least_squares(Hl, Yl).x[:, -1],      # the thesis's Pi_0 = 1e6 I
                               lb.least_squares_position(s, d).position_m, atol=1e-4)


def test_log_normal_range_moments_against_monte_carlo_and_the_note():
    m = lb.log_normal_range_moments(6.0, 4.0)
    assert m["sigma_k"] == pytest.approx(np.log(10) * 6 / 40)
    rng = np.random.default_rng(3)
    ratio = 10 ** (6.0 * rng.standard_normal(400_000) / 40)       # d / d_0 with sigma = 6 dB, n = 4
    se = ratio.std() / np.sqrt(ratio.size)
    assert abs(ratio.mean() - m["mean_ratio"]) < 4 * se
    assert abs((ratio**2).mean() - m["mean_square_ratio"]) < 4 * (ratio**2).std() / np.sqrt(ratio.size)
    assert ratio.std() == pytest.approx(m["sd_ratio"], rel=0.01)
    assert np.median(lb.correct_range_bias(ratio, 6.0, 4.0, "median")) == pytest.approx(1.0, abs=0.01)
    assert lb.correct_range_bias(ratio, 6.0, 4.0, "mean").mean() == pytest.approx(1.0, abs=4 * se)
    assert (lb.correct_range_bias(ratio, 6.0, 4.0, "squared") ** 2).mean() == pytest.approx(1.0, abs=0.01)


@pytest.mark.parametrize("n", [0, 1])
def test_too_few_receivers_names_the_argument(n):
    """Found by tests/test_fuzz_static.py: the message said "lateration needs at least two receiver positions"
    without naming receivers_m or its shape."""
    with pytest.raises(ValueError, match=rf"receivers_m must hold at least two receiver positions.*\(3, {n}, 2\)"):
        lb.least_squares_position(np.zeros((3, n, 2)), np.ones((3, n)))
