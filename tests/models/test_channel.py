"""Channel model and path-loss calibration against closed forms and an independent solver (scipy)."""
import numpy as np
import pytest
from scipy.optimize import lsq_linear

import locbook as lb
from locbook.models.channel import AT86RF230_ED_OFFSET_DB
from locbook.static.calibration import CALIBRATION_MODES, path_loss_design_matrix


def test_mean_power_and_range_inversion():
    model = lb.PathLossModel(-45.0, 2.1843, 0.0)
    d = np.array([1.0, 2.0, 10.0])
    # 10 n log10(10) = 21.843 dB below the 1 m power
    np.testing.assert_allclose(model.mean_rss_dbm(d), [-45.0, -45.0 - 21.843 * np.log10(2), -66.843], atol=1e-12)
    np.testing.assert_allclose(model.range_m(model.mean_rss_dbm(d)), d, rtol=1e-12)


def test_per_anchor_parameters_broadcast_on_last_axis():
    model = lb.PathLossModel(np.array([-40.0, -50.0]), np.array([2.0, 3.0]))
    p = model.mean_rss_dbm(np.full((3, 2), 10.0))
    np.testing.assert_allclose(p, np.tile([-60.0, -80.0], (3, 1)))


def test_range_bias_factor_matches_lognormal_mean():
    model = lb.PathLossModel(-52.0, 1.8, 6.0)
    rng = np.random.default_rng(1)
    d_hat = model.range_m(model.sample_rss_dbm(np.full(400_000, 3.0), rng=rng))
    ratio = d_hat / 3.0
    se = ratio.std() / np.sqrt(ratio.size)
    assert abs(ratio.mean() - model.range_bias_factor()) < 4 * se
    assert model.range_bias_factor() == pytest.approx(1.34, abs=0.01)  # Dogan 2015's testbed, alpha 1.8, 6 dB
    # lognormal mean: d_hat / d = 10^(-e / (10 n)) = exp(-e ln10 / (10 n)) with e ~ N(0, 6^2): exp(s^2 / 2)
    s = 6.0 * np.log(10.0) / 18.0
    assert model.range_bias_factor() == pytest.approx(np.exp(s**2 / 2), rel=1e-14)


def test_register_conversions_and_quantisation():
    assert lb.register_to_dbm(0) == -45.0                      # Eq. (3), document 003
    assert lb.register_to_dbm(40, AT86RF230_ED_OFFSET_DB) == -51.0
    np.testing.assert_allclose(lb.dbm_to_register(lb.register_to_dbm([-3.0, 7.0])), [-3.0, 7.0])
    np.testing.assert_array_equal(lb.quantize_db([-60.4, -60.6, -95.2], floor_dbm=-90.0), [-60.0, -61.0, -90.0])


def test_correlated_shadowing_covariance():
    pts = np.array([[0.0, 0.0], [1.0, 0.0], [3.0, 0.0]])
    draws = lb.correlated_shadowing_db(pts, 4.0, 2.0, rng=np.random.default_rng(3), size=(200_000,))
    expected = 16.0 * np.exp(-lb.pairwise_distance_m(pts, pts) / 2.0)
    np.testing.assert_allclose(np.cov(draws.T), expected, atol=0.25)  # MC s.e. of a covariance ~ 16*sqrt(2/N) = 0.05


@pytest.fixture
def cal_data():
    rng = np.random.default_rng(0)
    d = rng.uniform(1.0, 8.0, (6, 4))
    p = -45.0 - 21.843 * np.log10(d) + rng.normal(0.0, 2.0, d.shape)
    return d, p


def test_cvxpy_fit_equals_normal_equations_and_lstsq(cal_data):
    d, p = cal_data
    fit = lb.fit_path_loss(d, p, solver="cvxpy")          # the stacked convex problem, not the default closed form
    closed = lb.fit_path_loss_closed_form(d, p)
    for i in range(d.shape[0]):
        m = path_loss_design_matrix(d[i])
        t = np.linalg.lstsq(m, p[i], rcond=None)[0]     # independent: LAPACK least squares
        np.testing.assert_allclose([closed.ref_power_dbm[i], closed.path_loss_exp[i]], t, atol=1e-10)
        np.testing.assert_allclose([fit.ref_power_dbm[i], fit.path_loss_exp[i]], t, atol=1e-6)
        # LS covariance s^2 (M^T M)^-1 with s^2 = SSR / (N - 2)
        s2 = np.sum((p[i] - m @ t) ** 2) / (d.shape[1] - 2)
        np.testing.assert_allclose(closed.covariance[i], s2 * np.linalg.inv(m.T @ m), rtol=1e-10)


def test_stacked_fit_drops_missing_samples():
    # NaN powers are left out of their own problem only: each problem equals LAPACK on its observed samples
    rng = np.random.default_rng(5)
    d = rng.uniform(1.0, 8.0, (3, 5))
    p = -48.0 - 22.0 * np.log10(d) + rng.normal(0.0, 2.0, d.shape)
    p[0, 1] = p[2, 4] = np.nan
    for solver in ("cvxpy", "closed_form"):                # both paths; the default (auto) is the closed form
        fit = lb.fit_path_loss(d, p, solver=solver)
        for i in range(3):
            keep = np.isfinite(p[i])
            t = np.linalg.lstsq(path_loss_design_matrix(d[i, keep]), p[i, keep], rcond=None)[0]
            np.testing.assert_allclose([fit.ref_power_dbm[i], fit.path_loss_exp[i]], t, atol=1e-6)
        assert fit.n_samples.tolist() == [4, 5, 4]


def test_noiseless_recovery_every_mode():
    d = np.array([[1.0, 2.0, 4.0, 8.0], [1.5, 3.0, 5.0, 6.0]])
    p = -50.0 - 23.0 * np.log10(d)
    assert {"per_location_mean", "pooled", "per_anchor"} <= set(CALIBRATION_MODES)
    for mode in CALIBRATION_MODES:
        fit = lb.calibrate_path_loss(d, p, mode=mode)
        np.testing.assert_allclose(fit.path_loss_exp, 2.3, atol=1e-6)
        np.testing.assert_allclose(fit.ref_power_dbm, -50.0, atol=1e-5)


def test_bounded_fit_equals_scipy_lsq_linear(cal_data):
    d, p = cal_data
    bounds = ((-55.0, -46.0), (1.5, 2.0))   # tight enough that some fits are active at a bound
    fit = lb.fit_path_loss(d, p, ref_power_bounds_dbm=bounds[0], path_loss_exp_bounds=bounds[1])
    for i in range(d.shape[0]):
        ref = lsq_linear(path_loss_design_matrix(d[i]), p[i], bounds=([bounds[0][0], bounds[1][0]],
                                                                       [bounds[0][1], bounds[1][1]]), tol=1e-12)
        np.testing.assert_allclose([fit.ref_power_dbm[i], fit.path_loss_exp[i]], ref.x, atol=1e-5)


def test_bounded_fit_equals_brute_force_grid():
    rng = np.random.default_rng(5)
    d = np.array([1.0, 2.5, 4.0, 6.0])
    p = -47.0 - 26.0 * np.log10(d) + rng.normal(0, 3.0, 4)
    fit = lb.fit_path_loss(d, p, ref_power_bounds_dbm=(-55, -40), path_loss_exp_bounds=(1.5, 3.0))
    a, n = np.meshgrid(np.linspace(-55, -40, 1501), np.linspace(1.5, 3.0, 1501), indexing="ij")
    cost = ((p - (a[..., None] - 10 * n[..., None] * np.log10(d))) ** 2).sum(-1)
    i, j = np.unravel_index(np.argmin(cost), cost.shape)
    assert abs(fit.ref_power_dbm - a[i, j]) <= 0.011 and abs(fit.path_loss_exp - n[i, j]) <= 0.0011


def test_per_location_mean_is_mean_of_fits(cal_data):
    d, p = cal_data
    fit = lb.calibrate_path_loss(d, p, mode="per_location_mean", solver="closed_form")
    single = [lb.fit_path_loss_closed_form(d[i], p[i]).path_loss_exp for i in range(d.shape[0])]
    assert fit.path_loss_exp == pytest.approx(np.mean(single), abs=1e-12)
    # independently: LAPACK least squares at each location, then the mean of the 6 estimates
    each = np.array([np.linalg.lstsq(path_loss_design_matrix(d[i]), p[i], rcond=None)[0] for i in range(d.shape[0])])
    assert fit.ref_power_dbm == pytest.approx(each[:, 0].mean(), abs=1e-10)
    assert fit.path_loss_exp == pytest.approx(each[:, 1].mean(), abs=1e-10)
    # pooled: one LAPACK fit over all 24 links; per anchor: one fit per column
    pooled = lb.calibrate_path_loss(d, p, mode="pooled")
    t = np.linalg.lstsq(path_loss_design_matrix(d.ravel()), p.ravel(), rcond=None)[0]
    np.testing.assert_allclose([pooled.ref_power_dbm, pooled.path_loss_exp], t, atol=1e-10)
    per_anchor = lb.calibrate_path_loss(d, p, mode="per_anchor")
    for j in range(d.shape[1]):
        t = np.linalg.lstsq(path_loss_design_matrix(d[:, j]), p[:, j], rcond=None)[0]
        np.testing.assert_allclose([per_anchor.ref_power_dbm[j], per_anchor.path_loss_exp[j]], t, atol=1e-10)


def test_literal_sign_returns_minus_n():
    d = np.array([1.0, 2.0, 4.0, 8.0])
    p = -45.0 - 21.843 * np.log10(d)
    t = np.linalg.lstsq(path_loss_design_matrix(d, sign_convention="literal_george"), p, rcond=None)[0]
    assert t[1] == pytest.approx(-2.1843, abs=1e-10)


@pytest.mark.parametrize("distances", [[4.039] * 4, [3.0, 3.0]])
def test_degenerate_calibration_raises(distances):
    with pytest.raises(lb.DegenerateGeometryError, match="distinct distances"):
        lb.fit_path_loss(np.array(distances), np.full(len(distances), -60.0))


def test_corridor_centre_is_degenerate_but_centre_line_is_not():
    from locbook.scenarios import george
    centre = lb.pairwise_distance_m([[1.05, 3.9]], george.ANCHORS_M)
    with pytest.raises(lb.DegenerateGeometryError):
        lb.calibrate_path_loss(centre, -45 - 21.843 * np.log10(centre))
    line = lb.pairwise_distance_m([[1.05, 1.0]], george.ANCHORS_M)
    fit = lb.calibrate_path_loss(line, -45 - 21.843 * np.log10(line))
    assert fit.path_loss_exp == pytest.approx(2.1843, abs=1e-9)


def test_missing_samples_are_ignored(cal_data):
    d, p = cal_data
    p_nan = p.copy()
    p_nan[0, 1] = np.nan
    fit = lb.fit_path_loss(d[0], p_nan[0])
    ref = lb.fit_path_loss_closed_form(np.delete(d[0], 1), np.delete(p[0], 1))
    assert fit.path_loss_exp == pytest.approx(ref.path_loss_exp, abs=1e-6)
    # against LAPACK on the three observed samples (the default fit is the closed form itself), both solvers
    t = np.linalg.lstsq(path_loss_design_matrix(np.delete(d[0], 1)), np.delete(p[0], 1), rcond=None)[0]
    for solver in ("closed_form", "cvxpy"):
        fit = lb.fit_path_loss(d[0], p_nan[0], solver=solver)
        np.testing.assert_allclose([fit.ref_power_dbm, fit.path_loss_exp], t, atol=1e-6)
        assert fit.n_samples == 3


def test_fix_error_covariance_is_numpy_cov_of_the_errors_per_run():
    rng = np.random.default_rng(11)
    truth = rng.uniform(0, 5, size=(40, 2))
    fixes = truth + rng.normal(size=(3, 40, 2)) * [0.5, 2.0] + [1.0, -1.0]     # a bias does not enter
    R = lb.fix_error_covariance(fixes, truth)
    for k in range(3):
        np.testing.assert_allclose(R[k], np.cov((fixes[k] - truth).T), rtol=1e-12)


def test_design_rows_times_the_parameters_are_the_channels_mean():
    """The calibration's regressor is the law's: [1, -10 log10(d/d0)] . (P_0, n) = PathLossModel.mean_rss_dbm(d)."""
    d = np.array([0.5, 1.0, 3.0, 12.5])
    model = lb.PathLossModel(-41.5, 2.7, ref_distance_m=0.5)
    rows = path_loss_design_matrix(d, ref_distance_m=0.5)
    np.testing.assert_allclose(rows @ [-41.5, 2.7], model.mean_rss_dbm(d), rtol=1e-14)


def test_a_fit_becomes_the_model_it_estimates():
    """A noiseless log-distance data set: the fit's model is the generating one (closed form); per anchor, one
    channel per anchor; a fit handed where a model is expected says how to convert it."""
    rng = np.random.default_rng(5)
    d = rng.uniform(1.0, 12.0, size=(30, 3))                       # 30 locations x 3 anchors
    p0, n = np.array([-40.0, -47.0, -52.0]), np.array([1.8, 2.4, 3.1])
    rss = p0 - 10 * n * np.log10(d)
    per_anchor = lb.calibrate_path_loss(d, rss, "per_anchor").model(sigma_db=4.0)
    np.testing.assert_allclose(per_anchor.ref_power_dbm, p0, atol=1e-9)
    np.testing.assert_allclose(per_anchor.path_loss_exp, n, atol=1e-9)
    assert per_anchor.sigma_db == 4.0
    np.testing.assert_allclose(per_anchor.mean_rss_dbm(d), rss, atol=1e-8)
    shared = lb.calibrate_path_loss(d[:, :1], rss[:, :1], "pooled").model(min_distance_m=0.1)
    assert np.isclose(shared.ref_power_dbm, -40.0) and np.isclose(shared.path_loss_exp, 1.8)
    assert np.isclose(shared.sigma_db, 0.0, atol=1e-9) and shared.min_distance_m == 0.1   # residual sigma
    with pytest.raises(ValueError, match=r"a path-loss fit becomes one with fit.model\(\)"):
        lb.rss_ml_position(np.array([-50.0, -60.0, -60.0]),
                           lb.RssModel(np.array([[0.0, 0.0], [10.0, 0.0], [0.0, 10.0]]),
                                       lb.calibrate_path_loss(d, rss, "per_anchor")))


def test_a_fit_of_independent_problems_or_a_failed_fit_is_not_a_model():
    rng = np.random.default_rng(6)
    d = rng.uniform(1.0, 12.0, size=(4, 20, 2))                    # 4 independent calibrations
    batch = lb.fit_path_loss(d, -45.0 - 20 * np.log10(d))
    with pytest.raises(ValueError, match=r"shape \(4, 20\)|select one problem first"):
        batch.model()
    one = lb.fit_path_loss(np.array([2.0, 2.0, 5.0]), np.array([-50.0, np.nan, np.nan]))   # one distance heard
    assert not one.ok
    with pytest.raises(ValueError, match="cannot become a model.*too_few_distances"):
        one.model()


def test_nan_padded_distances_fit_each_ragged_problem_as_its_own_samples():
    """Problems of unequal length padded with NaN (distance and power) give the fits of the unpadded problems;
    a NaN distance beside a reading is refused."""
    d = np.array([[1.0, 2.0, 4.0, np.nan], [1.0, 2.0, 3.0, 5.0]])
    p = np.array([[-40.0, -46.5, -52.0, np.nan], [-40.0, -46.0, -50.5, -54.0]])
    both = lb.fit_path_loss(d, p)
    for k, n in ((0, 3), (1, 4)):
        alone = lb.fit_path_loss(d[k, :n], p[k, :n])
        A = np.column_stack([np.ones(n), -10 * np.log10(d[k, :n])])          # numpy's least squares: the oracle
        ref, exp = np.linalg.lstsq(A, p[k, :n], rcond=None)[0]
        np.testing.assert_allclose([both.ref_power_dbm[k], both.path_loss_exp[k]], [ref, exp], rtol=1e-12)
        np.testing.assert_allclose([alone.ref_power_dbm, alone.path_loss_exp], [ref, exp], rtol=1e-12)
    bad = p.copy()
    bad[0, 3] = -55.0
    with pytest.raises(ValueError, match="NaN where rss_dbm holds a reading"):
        lb.fit_path_loss(d, bad)


# -- walls and small-scale fading ------------------------------------------------------------------------
def test_wall_crossings_counts_a_wall_between_rooms():
    walls = [[[3.0, 0.0], [3.0, 4.0]]]
    readers = np.array([[0.0, 0.0], [9.0, 4.0]])
    pts = np.array([[1.0, 1.0], [5.0, 2.0], [3.0, 5.0]])       # small room, large room, beyond the wall's end
    np.testing.assert_array_equal(lb.wall_crossings(pts, readers, walls), [[0, 1], [1, 0], [0, 0]])


def test_small_scale_fading_has_unit_mean_power_and_deep_fades():
    rng = np.random.default_rng(12)
    x = np.linspace(0, 50, 20000)
    rayleigh = lb.small_scale_fading_db(x, 0.33, rng=rng)
    assert np.mean(10 ** (rayleigh / 10)) == pytest.approx(1.0, abs=0.1)
    assert rayleigh.min() < -20.0                      # Rayleigh: fades beyond 20 dB over many wavelengths
    rician = lb.small_scale_fading_db(x, 0.33, rng=rng, k_factor=10.0)
    assert rician.min() > rayleigh.min()
