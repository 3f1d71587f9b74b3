"""The channel model (locbook.models.channel) against closed forms: mean power and range inversion, per-anchor
parameters, the range bias, register conversions, correlated shadowing, walls and small-scale fading. Its
calibration: tests/static/test_calibration.py."""
import numpy as np
import pytest

import locbook as lb
from locbook.models.channel import AT86RF230_ED_OFFSET_DB


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
