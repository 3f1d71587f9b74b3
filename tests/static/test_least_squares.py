"""Lateration from per-problem receivers (2-D and 3-D) against cvxpy, RLS against batch LS, and the log-normal
range moments against Monte Carlo and closed forms (Palvai 2008, Eqs. (2.27)-(2.58))."""
import cvxpy as cp
import numpy as np
import pytest

import locbook as lb
from locbook.static.lateration import LATERATION_PAIRS


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("reference", LATERATION_PAIRS)
def test_least_squares_equals_cvxpy_and_is_exact_without_noise(dim, reference):
    rng = np.random.default_rng(dim)
    s = rng.uniform(0, 50, (4, 12, dim))
    target = rng.uniform(0, 50, (4, dim))
    d_true = np.linalg.norm(s - target[:, None], axis=-1)
    exact = lb.lateration_ls(s, d_true, pairs=reference)
    np.testing.assert_allclose(exact.position_m, target, atol=1e-7)
    d = d_true * np.exp(0.2 * rng.standard_normal(d_true.shape))
    ours = lb.lateration_ls(s, d, pairs=reference).position_m
    H, Y = lb.lateration_system(s, d, pairs=reference)
    for r in range(4):
        x = cp.Variable(dim)
        cp.Problem(cp.Minimize(cp.sum_squares(H[r] @ x - Y[r]))).solve()
        np.testing.assert_allclose(ours[r], x.value, atol=1e-5)


def test_printed_rows_without_the_factor_2_double_the_coordinates():
    rng = np.random.default_rng(0)
    s = rng.uniform(0, 50, (10, 3))
    target = np.array([20.0, 30.0, 25.0])
    d = np.linalg.norm(s - target, axis=-1)
    lit = lb.lateration_ls(s, d, pairs="consecutive", variant="literal_palvai2008").position_m
    np.testing.assert_allclose(lit, 2 * target, rtol=1e-9)


def test_missing_readings_drop_their_rows_and_too_few_rows_give_nan():
    rng = np.random.default_rng(1)
    s = rng.uniform(0, 50, (6, 3))
    target = np.array([10.0, 20.0, 30.0])
    d = np.linalg.norm(s - target, axis=-1)
    d2 = d.copy()
    d2[2] = np.nan                                  # rows (1,2) and (2,3) go
    res = lb.lateration_ls(np.stack([s, s]), np.stack([d2, np.r_[d[:3], np.nan, np.nan, np.nan]]),
                          pairs="consecutive")
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
    Hl, Yl = lb.lateration_system(s, d, pairs="consecutive")
    np.testing.assert_allclose(lb.recursive_least_squares(Hl, Yl).x[:, -1],      # the thesis's Pi_0 = 1e6 I
                               lb.lateration_ls(s, d, pairs="consecutive").position_m, atol=1e-4)


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
    """Found by tests/static/test_static_fuzz.py: the message said "lateration needs at least two receiver positions"
    without naming the argument or its shape."""
    with pytest.raises(ValueError, match=rf"anchors_m must hold at least two anchor positions.*\(3, {n}, 2\)"):
        lb.lateration_ls(np.zeros((3, n, 2)), np.ones((3, n)), pairs="consecutive")


def test_reference_anchor_and_first_pairs_are_one_system():
    """Every anchor against anchor 0 (George's Eq. (8)) and every anchor against the first (Palvai's pairs) difference
    the same sphere equations, with opposite signs: one system, so one least-squares fix."""
    rng = np.random.default_rng(4)
    anchors = rng.uniform(0, 20, (6, 2))
    d = np.linalg.norm(anchors - [7.0, 9.0], axis=-1) * np.exp(0.1 * rng.standard_normal((5, 6)))
    A, b = lb.lateration_system(anchors, d, 0)
    H, Y = lb.lateration_system(anchors, d, pairs="first")
    np.testing.assert_array_equal(H, -A)
    np.testing.assert_allclose(Y, -b, rtol=1e-12)
    np.testing.assert_allclose(lb.lateration_ls(anchors, d, pairs="first").position_m,
                               lb.lateration_ls(anchors, d, 0).position_m, rtol=1e-9)
    # the printed rows without the factor 2 halve A and double the fix on either form
    np.testing.assert_array_equal(lb.lateration_system(anchors, d, 0, variant="literal_palvai2008")[0], A / 2)
    np.testing.assert_allclose(lb.lateration_ls(anchors, d, 0, variant="literal_palvai2008").position_m,
                               2 * lb.lateration_ls(anchors, d, 0).position_m, rtol=1e-9)
    with pytest.raises(lb.ParameterError, match="pairs"):
        lb.lateration_ls(anchors, d, pairs="first", min_anchors=3)
    with pytest.raises(ValueError, match="pairs"):
        lb.lateration_system(anchors, d, pairs="every")


def test_first_and_last_pairs_re_pick_a_reference_that_was_not_heard_as_the_reference_anchor_path_does():
    """Shared anchors, the pair reference (anchor 0 for "first", the last anchor for "last") not heard: the pairs
    take the first (last) heard anchor instead, so the fix is the reference-anchor path's, and exact ranges give the
    tag back; problems that heard the reference are solved as before."""
    rng = np.random.default_rng(11)
    anchors = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0], [4.0, 7.0]])
    tag = np.array([3.0, 4.0])
    exact = np.linalg.norm(anchors - tag, axis=-1)
    for pairs, lost in (("first", 0), ("last", 4)):
        d = exact.copy()
        d[lost] = np.nan
        res = lb.lateration_ls(anchors, d, pairs=pairs)
        assert res.status == "ok" and res.converged
        np.testing.assert_allclose(res.position_m, tag, rtol=0, atol=1e-9)
    noisy = exact * np.exp(0.1 * rng.standard_normal((6, 5)))
    noisy[1:4, 0] = np.nan                                    # three problems without anchor 0
    noisy[3, 1] = np.nan                                      # one of them without anchor 1 too
    noisy[5, :3] = np.nan                                     # two anchors heard: too few for a 2-D fix
    res = lb.lateration_ls(anchors, noisy, pairs="first")
    ref = lb.lateration_ls(anchors, noisy)                    # re-picks the first heard anchor as its reference
    np.testing.assert_array_equal(res.status, ref.status)
    assert list(res.status) == ["ok"] * 5 + ["too_few_anchors"]
    np.testing.assert_allclose(res.position_m[:5], ref.position_m[:5], rtol=1e-9)
    kept = [0, 4]                                             # heard the reference: unchanged by the others
    np.testing.assert_array_equal(res.position_m[kept],
                                  lb.lateration_ls(anchors, noisy[kept], pairs="first").position_m)


def test_degenerate_geometry_is_reported_alike_on_the_reference_and_pair_paths():
    """Shared anchors on one line raise DegenerateGeometryError on both paths; a problem whose heard anchors are
    collinear, or too few, gets NaN and the same status on both."""
    line = np.c_[np.arange(4.0), np.zeros(4)]
    for pairs in (None, "first", "last"):
        with pytest.raises(lb.DegenerateGeometryError, match="collinear"):
            lb.lateration_ls(line, np.ones(4), pairs=pairs)
    anchors = np.array([[0.0, 0.0], [5.0, 0.0], [10.0, 0.0], [5.0, 8.0]])    # the first three on the x axis
    d = np.tile(np.linalg.norm(anchors - [4.0, 3.0], axis=-1), (3, 1))
    d[0, 3] = np.nan                                          # heard only the collinear three
    d[1, [0, 3]] = np.nan                                     # heard two
    for pairs in (None, "first", "last"):
        res = lb.lateration_ls(anchors, d, pairs=pairs)
        assert list(res.status) == ["degenerate_geometry", "too_few_anchors", "ok"], pairs
        assert np.isnan(res.position_m[:2]).all() and not res.converged[:2].any()
        np.testing.assert_allclose(res.position_m[2], [4.0, 3.0], atol=1e-9)


def test_a_list_of_masked_rows_keeps_every_rows_mask():
    # np.asarray of a list of masked arrays drops their masks: the 1e3 under the mask was used (a fix 8 km off)
    anchors = np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0], [10.0, 10.0]])
    d = np.linalg.norm(anchors - [3.0, 4.0], axis=1)
    bad = d.copy()
    bad[1] = 1e3
    rows = [np.ma.array(bad, mask=[0, 1, 0, 0]), np.ma.array(d)]
    for given in (rows, [rows]):
        np.testing.assert_allclose(lb.lateration_ls(anchors, given).position_m.reshape(-1, 2), [[3.0, 4.0]] * 2)
    with pytest.raises(ValueError, match="distance_m must be a rectangular array"):
        lb.lateration_ls(anchors, [rows[0], d[:3]])
