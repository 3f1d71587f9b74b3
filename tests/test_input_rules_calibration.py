"""Path-loss fitting (closed form by default, cvxpy for bounded and robust fits, status reported),
channel input checks and canonical seeds (issue 12).

Independent oracles: numpy's lstsq, scipy's least_squares with its Huber loss (the same function as cvxpy's
huber: r^2 within delta, 2 delta |r| - delta^2 beyond), closed-form facts about float encodings.
"""
import cvxpy as cp
import numpy as np
import pytest
from scipy.optimize import least_squares

import locbook as lb
from locbook import calibration


def _samples(n=60, seed=2, outliers=0):
    rng = np.random.default_rng(seed)
    d = rng.uniform(1.0, 12.0, n)
    p = -47.0 - 10 * 2.3 * np.log10(d) + rng.normal(scale=2.0, size=n)
    p[:outliers] -= 40.0                                        # blocked links: 40 dB below the model
    return d, p


def test_default_is_the_closed_form_and_equals_lstsq_and_cvxpy():
    d, p = _samples()
    fit = lb.fit_path_loss(d, p)
    assert fit.status == "closed_form" and fit.ok
    design = np.c_[np.ones_like(d), -10 * np.log10(d)]
    ref = np.linalg.lstsq(design, p, rcond=None)[0]
    np.testing.assert_allclose([fit.ref_power_dbm, fit.path_loss_exp], ref, rtol=0, atol=1e-10)
    cvx = lb.fit_path_loss(d, p, solver="cvxpy")
    assert cvx.status == "optimal"
    np.testing.assert_allclose([cvx.ref_power_dbm, cvx.path_loss_exp], ref, rtol=0, atol=1e-6)
    # the covariance is s^2 (M^T M)^-1 of the same regression
    s2 = np.sum((p - design @ ref) ** 2) / (d.size - 2)
    np.testing.assert_allclose(fit.covariance, s2 * np.linalg.inv(design.T @ design), rtol=1e-9)


def test_missing_samples_are_left_out():
    d, p = _samples()
    holed = p.copy()
    holed[[3, 10, 11]] = np.nan
    keep = np.isfinite(holed)
    a, b = lb.fit_path_loss(d, holed), lb.fit_path_loss(d[keep], p[keep])
    np.testing.assert_allclose([a.ref_power_dbm, a.path_loss_exp, a.residual_sigma_db],
                               [b.ref_power_dbm, b.path_loss_exp, b.residual_sigma_db], rtol=1e-12)
    assert a.n_samples == 57


def test_bounds_go_to_cvxpy_and_hold():
    d, p = _samples()
    fit = lb.fit_path_loss(d, p, path_loss_exp_bounds=(1.5, 2.0))
    assert fit.status == "optimal" and fit.path_loss_exp <= 2.0 + 1e-7
    # the exponent bound is active: the fit is the best intercept for n = 2 (a one-parameter closed form)
    np.testing.assert_allclose(fit.ref_power_dbm, np.mean(p + 20 * np.log10(d)), atol=1e-5)
    with pytest.raises(ValueError, match="need solver='cvxpy'"):
        lb.fit_path_loss(d, p, path_loss_exp_bounds=(1.5, 2.0), solver="closed_form")


def test_huber_fit_equals_scipy_and_resists_outliers():
    d, p = _samples(outliers=4)
    huber = lb.fit_path_loss(d, p, loss="huber", huber_delta_db=3.0)
    resid = lambda t: p - (t[0] - 10 * t[1] * np.log10(d))
    ref = least_squares(resid, [-40.0, 2.0], loss="huber", f_scale=3.0, xtol=1e-12, ftol=1e-12, gtol=1e-12).x
    np.testing.assert_allclose([huber.ref_power_dbm, huber.path_loss_exp], ref, rtol=0, atol=1e-4)
    ls = lb.fit_path_loss(d, p)
    assert abs(huber.path_loss_exp - 2.3) < abs(ls.path_loss_exp - 2.3) and abs(huber.ref_power_dbm + 47) < 1.5
    assert np.isnan(huber.covariance).all()            # the LS covariance formula does not apply
    clean_d, clean_p = _samples()
    wide = lb.fit_path_loss(clean_d, clean_p, loss="huber", huber_delta_db=100.0)   # nothing beyond delta: LS
    np.testing.assert_allclose(wide.path_loss_exp, lb.fit_path_loss(clean_d, clean_p).path_loss_exp, atol=1e-6)


def test_a_solver_that_stops_early_is_reported_not_raised(monkeypatch):
    d, p = _samples()
    monkeypatch.setattr(calibration, "solve", lambda problem, what: problem.solve(solver=cp.CLARABEL, max_iter=1))
    fit = lb.fit_path_loss(np.broadcast_to(d, (3, d.size)), np.tile(p, (3, 1)), path_loss_exp_bounds=(1.5, 3.0))
    assert not fit.ok and fit.status not in ("optimal", "closed_form")
    assert np.isnan(fit.ref_power_dbm).all() and np.isnan(fit.path_loss_exp).all()


@pytest.mark.parametrize("call, message", [
    (lambda: lb.fit_path_loss(np.ones(5), np.ones(4)), r"distance_m \(5,\) must have the shape of power_dbm"),
    (lambda: lb.fit_path_loss([1.0, 2.0, np.nan], [1.0, 2.0, 3.0]), "distance_m must be finite"),
    (lambda: lb.fit_path_loss([1.0, 2.0, 3.0], [1.0, np.inf, 3.0]), "power_dbm must be finite"),
    (lambda: lb.fit_path_loss([1.0, 2.0], [1.0, 2.0], solver="magic"), "solver must be one of"),
    (lambda: lb.fit_path_loss([1.0, 2.0], [1.0, 2.0], path_loss_exp_bounds=(3.0, 1.0)), "lower <= upper"),
    (lambda: lb.fit_path_loss([1.0, 2.0], [1.0, 2.0], loss="huber", huber_delta_db=0.0), "huber_delta_db must be > 0"),
    (lambda: lb.PathLossModel(ref_power_dbm=np.nan), "ref_power_dbm must be finite"),
    (lambda: lb.PathLossModel(path_loss_exp=[2.0, np.nan]), "path_loss_exp must be finite"),
    (lambda: lb.PathLossModel(sigma_db=float("inf")), "sigma_db must be finite"),
    (lambda: lb.PathLossModel().mean_power_dbm([1.0, np.nan]), "distance_m must be finite"),
    (lambda: lb.quantize_db([1.0], step_db=float("nan")), "step_db must be finite"),
    (lambda: lb.pairwise_distance_m(np.zeros((2, 3)), np.zeros((4, 2))), "points have dimension 3"),
    (lambda: lb.smooth_rssi(np.zeros(3), np.zeros((4, 2)), np.zeros((4, 2))), r"ref_rss_dbm must have shape"),
])
def test_bad_input_names_the_argument(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_range_of_a_missing_reading_stays_missing():
    r = lb.PathLossModel(-45.0, 2.0).range_m([-65.0, np.nan])
    assert r[0] == pytest.approx(10.0) and np.isnan(r[1])


def test_seeds_come_from_a_canonical_encoding():
    assert lb.seed_from_values(1) == lb.seed_from_values(1.0) == lb.seed_from_values(np.float64(1.0)) \
        == lb.seed_from_values(np.int64(1))
    assert lb.seed_from_values(0.1 + 0.2) == lb.seed_from_values(0.30000000000000004) != lb.seed_from_values(0.3)
    assert lb.seed_from_values({"b": 2, "a": (1, "x")}) == lb.seed_from_values({"a": [1.0, "x"], "b": 2.0})
    assert lb.seed_from_values(True) != lb.seed_from_values(1)
    assert lb.seed_from_values(2**60 + 1) != lb.seed_from_values(2**60)           # beyond 2**53: still exact
    # the encoding is the float's exact binary value, not Python's shortest repr
    assert (0.1).hex().encode() in lb.canonical_encoding(0.1)
    with pytest.raises(ValueError, match="NaN"):
        lb.seed_from_values(float("nan"))
