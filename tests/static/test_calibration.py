"""Path-loss fitting (closed form by default, cvxpy for bounded and robust fits, status reported) against the normal
equations, lstsq, scipy's lsq_linear and brute force, channel input checks and canonical seeds.

Independent oracles: numpy's lstsq, scipy's least_squares with its Huber loss (the same function as cvxpy's
huber: r^2 within delta, 2 delta |r| - delta^2 beyond), closed-form facts about float encodings.
"""
import re

import cvxpy as cp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import least_squares, lsq_linear

import locbook as lb
from locbook.static import calibration, reference_tags
from locbook.static.calibration import CALIBRATION_MODES, path_loss_design_matrix


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


def test_bounds_hold_exactly_by_default():
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


def _crashing_solve(problem, what):
    raise cp.error.SolverError("Clarabel crashed")


@pytest.mark.filterwarnings("ignore:Solution may be inaccurate")
@pytest.mark.parametrize("how", ["bare_solve", "library_solve", "crash"])
def test_a_solver_that_stops_early_is_reported_not_raised(monkeypatch, how):
    d, p = _samples()
    if how == "bare_solve":          # the solve returns with a non-optimal status
        monkeypatch.setattr(calibration, "solve", lambda problem, what: problem.solve(solver=cp.CLARABEL, max_iter=1))
    elif how == "library_solve":     # the library's own solve raises ConvergenceError on a non-optimal status
        from locbook import _cvx
        monkeypatch.setitem(_cvx._CLARABEL_TIGHT, "max_iter", 1)
    else:                            # the solver itself fails
        monkeypatch.setattr(calibration, "solve", _crashing_solve)
    fit = lb.fit_path_loss(np.broadcast_to(d, (3, d.size)), np.tile(p, (3, 1)), path_loss_exp_bounds=(1.5, 3.0),
                           solver="cvxpy")
    assert not fit.ok and fit.status not in ("optimal", "closed_form")
    if how == "crash":
        assert fit.status == "solver_error"
    assert np.isnan(fit.ref_power_dbm).all() and np.isnan(fit.path_loss_exp).all()


@pytest.mark.parametrize("call, message", [
    (lambda: lb.fit_path_loss(np.ones(5), np.ones(4)), r"distance_m \(5,\) must have the shape of rss_dbm"),
    (lambda: lb.fit_path_loss([1.0, 2.0, np.nan], [1.0, 2.0, 3.0]), "distance_m is NaN where rss_dbm holds a reading"),
    (lambda: lb.fit_path_loss([1.0, 2.0, 3.0], [1.0, np.inf, 3.0]), "rss_dbm must be finite"),
    (lambda: lb.fit_path_loss([1.0, 2.0], [1.0, 2.0], solver="magic"), "solver must be one of"),
    (lambda: lb.fit_path_loss([1.0, 2.0], [1.0, 2.0], path_loss_exp_bounds=(3.0, 1.0)), "lower <= upper"),
    (lambda: lb.fit_path_loss([1.0, 2.0], [1.0, 2.0], loss="huber", huber_delta_db=0.0), "huber_delta_db must be > 0"),
    (lambda: lb.PathLossModel(ref_power_dbm=np.nan, path_loss_exp=2.0), "ref_power_dbm must be finite"),
    (lambda: lb.PathLossModel(-40.0, path_loss_exp=[2.0, np.nan]), "path_loss_exp must be finite"),
    (lambda: lb.PathLossModel(-40.0, 2.0, sigma_db=float("inf")), "sigma_db must be finite"),
    (lambda: lb.PathLossModel(-40.0, 2.0).mean_rss_dbm([1.0, np.nan]), "distance_m must be finite"),
    (lambda: lb.quantize_db([1.0], step_db=float("nan")), "step_db must be finite"),
    (lambda: lb.pairwise_distance_m(np.zeros((2, 3)), np.zeros((4, 2))), "points_m have dimension 3"),
    (lambda: lb.smooth_rssi(np.zeros(3), np.zeros((4, 2)), np.zeros((4, 2))), r"ref_rss_dbm must have shape"),
    (lambda: lb.smooth_rssi(np.zeros(2), np.zeros((4, 2)), np.zeros((3, 2))),
     r"ref_expected_dbm must have shape \(\.\.\., 4, 2\), got \(3, 2\)"),
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
    with pytest.raises(ValueError, match="n must be >= 0"):
        lb.spawn_generators(1, -2)


# --- channel: the exponent divides in Eq. (7); walls, fading and register conversions are checked --------------

@pytest.mark.parametrize("exponent", [0.0, -1.5, [2.0, 0.0]])
def test_ranging_needs_a_positive_exponent(exponent):
    model = lb.PathLossModel(-45.0, exponent, sigma_db=2.0)
    with pytest.raises(ValueError, match="divides by path_loss_exp, which must be > 0"):
        model.range_m([-60.0, -65.0])
    with pytest.raises(ValueError, match="range_bias_factor divides by path_loss_exp"):
        model.range_bias_factor()
    # the forward model has no division: a zero exponent is a flat channel, P = P0
    if np.ndim(exponent) == 0 and exponent == 0.0:
        np.testing.assert_array_equal(model.mean_rss_dbm([2.0, 7.0]), [-45.0, -45.0])


def test_wall_counts_are_checked():
    with pytest.raises(ValueError, match="n_walls must be non-negative"):
        lb.PathLossModel(-45.0, 2.0).mean_rss_dbm([2.0], n_walls=-1)
    with pytest.raises(ValueError, match="n_walls must be finite"):
        lb.PathLossModel(-45.0, 2.0, wall_attenuation_db=3.0).range_m([-60.0], n_walls=np.nan)


def test_wall_crossings_shapes_and_counts():
    wall = [[3.0, -1.0], [3.0, 5.0]]                                 # the line x = 3
    anchors = [[0.0, 0.0], [6.0, 0.0]]
    points = [[1.0, 1.0], [5.0, 2.0]]
    # independent fact: a path crosses x = 3 iff its ends lie on opposite sides
    expected = [[0, 1], [1, 0]]
    np.testing.assert_array_equal(lb.wall_crossings(points, anchors, [wall]), expected)
    np.testing.assert_array_equal(lb.wall_crossings(points, anchors, wall), expected)          # one wall (2, 2)
    np.testing.assert_array_equal(lb.wall_crossings(points, anchors, [wall, wall]), 2 * np.array(expected))
    np.testing.assert_array_equal(lb.wall_crossings(points, anchors, np.zeros((0, 2, 2))), np.zeros((2, 2)))
    np.testing.assert_array_equal(lb.wall_crossings(points, anchors, []), np.zeros((2, 2)))              # no walls
    with pytest.raises(ValueError, match=r"walls_m must have shape \(W, 2, 2\).*got \(1, 4\)"):
        lb.wall_crossings(points, anchors, [[3.0, -1.0, 3.0, 5.0]])
    with pytest.raises(ValueError, match=r"points_m must have shape \(\.\.\., 2\), got \(2, 3\)"):
        lb.wall_crossings(np.zeros((2, 3)), anchors, [wall])
    with pytest.raises(ValueError, match="anchors_m must be finite"):
        lb.wall_crossings(points, [[0.0, np.nan], [6.0, 0.0]], [wall])


@pytest.mark.parametrize("kwargs, message", [
    (dict(wavelength_m=0.0), "wavelength_m must be > 0"),
    (dict(n_paths=0), "n_paths must be >= 1"),
    (dict(n_paths=2.5), "n_paths must be an integer"),
    (dict(k_factor=-1.0), "k_factor must be >= 0"),
])
def test_fading_arguments_are_checked(kwargs, message):
    args = dict(wavelength_m=0.33) | kwargs
    with pytest.raises(ValueError, match=message):
        lb.small_scale_fading_db(np.linspace(0, 1, 5), args.pop("wavelength_m"), rng=np.random.default_rng(0), **args)


def test_register_conversions_keep_missing_readings():
    np.testing.assert_array_equal(lb.register_to_dbm([-20.0, np.nan]), [-65.0, np.nan])
    np.testing.assert_array_equal(lb.dbm_to_register([-65.0, np.nan]), [-20.0, np.nan])
    np.testing.assert_array_equal(lb.quantize_db([-65.4, np.nan], 1.0, -90.0), [-65.0, np.nan])   # NaN not floored
    with pytest.raises(ValueError, match="register must be finite"):
        lb.register_to_dbm([np.inf])
    with pytest.raises(ValueError, match="floor_dbm must be finite"):
        lb.quantize_db([-65.0], 1.0, np.nan)


# --- metrics ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("call, message", [
    (lambda: lb.rmse_m([1.0, np.inf]), "error_m must be finit"),
    (lambda: lb.mean_error_m([]), r"error_m must hold at least 1 value\(s\), got shape \(0,\)"),
    (lambda: lb.percentile_error_m([1.0, 2.0], q=101), "q must be <= 100"),
    (lambda: lb.error_std_m([1.0, 2.0], ddof=-1), "ddof must be >= 0"),
    (lambda: lb.rmse_standard_error_m([1.0]), "at least two errors"),
    (lambda: lb.reduction_pct([1.0, 2.0], [1.0, 2.0, 3.0]), r"before \(2,\) and after \(3,\) must have the same shape"),
    (lambda: lb.reduction_pct(0.0, 1.0), "before must be non-zero"),
    (lambda: lb.position_error_m([[1.0, 2.0]], [[0.0, 0.0, 0.0]]), "must end in the same dimension"),
    (lambda: lb.position_error_m(np.zeros((3, 2)), np.zeros((4, 2))),
     r"estimate_m \(3, 2\) and truth_m \(4, 2\) do not pair up"),
    (lambda: lb.position_error_m([[np.inf, 0.0]], [[0.0, 0.0]]), "estimate_m must be finite"),
])
def test_metric_inputs_are_checked(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_a_missing_estimate_is_a_missing_error():
    e = lb.position_error_m([[3.0, 4.0], [np.nan, np.nan]], [0.0, 0.0])       # truth shared by both estimates
    assert e[0] == 5.0 and np.isnan(e[1])
    assert np.isnan(lb.rmse_m(e))                                              # never silently over fewer problems


# --- reference tags: NaN readings are not heard ----------------------------------------------------------------

def test_pooled_sigma_leaves_out_readings_not_heard():
    r = np.array([[1.0, -2.0, np.nan], [2.0, np.nan, 1.0]])
    # Eq. (6.7) over the four heard residuals: sqrt((1 + 4 + 4 + 1) / 4), and with ddof = 1: / 3
    assert reference_tags.pooled_sigma_db(r) == pytest.approx(np.sqrt(10 / 4), rel=1e-15)
    assert reference_tags.pooled_sigma_db(r, ddof=1) == pytest.approx(np.sqrt(10 / 3), rel=1e-15)
    rows = reference_tags.pooled_sigma_db(r, axis=-1, ddof=2)
    assert np.isnan(rows).all()                                    # two heard, two fitted: no degrees of freedom
    with pytest.raises(ValueError, match="ddof must be an integer"):
        reference_tags.pooled_sigma_db(r, ddof=0.5)


def test_reference_tag_calibration_with_a_tag_not_heard():
    tags = np.array([[1.0, 1.0], [4.0, 1.0], [1.0, 6.0], [5.0, 5.0]])
    readers = np.array([[0.0, 0.0], [6.0, 0.0], [0.0, 8.0]])
    rss = lb.model_fingerprints(tags, lb.RssModel(readers, lb.PathLossModel(-45.0, 2.2))) \
        + np.random.default_rng(4).normal(0.0, 2.0, (2, 4, 3))
    rss[1, 2, 0] = np.nan                                                # step 1: reader 0 did not hear tag 2
    cal = lb.calibrate_from_reference_tags(rss, tags, readers, ref_power_bounds_dbm=None, path_loss_exp_bounds=None)
    d = lb.pairwise_distance_m(tags, readers)
    heard = [0, 1, 3]
    design = np.c_[np.ones(3), -10 * np.log10(d[heard, 0])]
    ref = np.linalg.lstsq(design, rss[1, heard, 0], rcond=None)[0]       # the fit over the three tags it heard
    np.testing.assert_allclose([cal.ref_power_dbm[1, 0], cal.path_loss_exp[1, 0]], ref, rtol=0, atol=1e-9)
    resid = rss[1] - cal.expected_dbm[1]
    assert cal.sigma_db[1] == pytest.approx(np.sqrt(np.nansum(resid**2) / 11), rel=1e-12)   # 11 heard readings
    assert np.isfinite(cal.sigma_db).all()


def test_smoothing_a_target_that_missed_a_reader_uses_the_others():
    rng = np.random.default_rng(8)
    ref_rss = rng.normal(-60.0, 6.0, (4, 3))
    expected = ref_rss + rng.normal(0.0, 2.0, (4, 3))
    target = ref_rss[2] + rng.normal(0.0, 0.5, 3)                        # close to tag 2 in RSSI space
    holed = target.copy()
    holed[1] = np.nan
    got, nearest, applied = lb.smooth_rssi(holed, ref_rss, expected)
    # the same smoothing on readers 0 and 2 only (a common factor m / 2 on every E_k^2 leaves the weights alone)
    keep = [0, 2]
    want, want_nearest, want_applied = lb.smooth_rssi(target[keep], ref_rss[:, keep], expected[:, keep])
    assert nearest == want_nearest == 2 and applied == want_applied
    np.testing.assert_allclose(got[keep], want, rtol=0, atol=1e-12)
    assert np.isnan(got[1])
    # a fifth tag that heard only reader 1 (which the target missed) shares nothing with the target: no weight
    extra = np.vstack([ref_rss, [np.nan, -50.0, np.nan]])
    got5, nearest5, applied5 = lb.smooth_rssi(holed, extra, np.vstack([expected, [0.0, -52.0, 0.0]]))
    assert nearest5 == 2 and applied5
    np.testing.assert_allclose(got5, got, rtol=0, atol=1e-12)
    # a tag that heard no reader the target heard carries no weight; with none in common nothing is applied
    lonely = ref_rss.copy()
    lonely[:, [0, 2]] = np.nan
    out, _, none = lb.smooth_rssi(holed, lonely, expected)
    assert not none and np.array_equal(out, holed, equal_nan=True)


def test_smoothing_distances_over_fewer_readers_are_rescaled():
    # target (0, 0); tag 0 heard both readers at (3, 4): E^2 = 25; tag 1 heard reader 0 only at 4: 16 over one of
    # two readers, rescaled to 32. Weights (1/25, 1/32) / (1/25 + 1/32) = (32, 25) / 57: tag 0 is nearest.
    target = np.array([0.0, 0.0])
    ref_rss = np.array([[3.0, 4.0], [4.0, np.nan]])
    expected = np.array([[2.0, 2.0], [0.0, 0.0]])                          # tag 0's errors (1, 2)
    got, nearest, applied = lb.smooth_rssi(target, ref_rss, expected, threshold=0.5)
    assert nearest == 0 and applied
    np.testing.assert_allclose(got, target - 32 / 57 * np.array([1.0, 2.0]), rtol=1e-14)
    # the nearest tag missed reader 1, which the target heard: that component is left as it is. Tag 0 (1, -, 1):
    # E^2 = 2 * 3 / 2 = 3; tag 1 (5, 5, 5): E^2 = 75; weights (25, 1) / 26; tag 0's errors (1, -, 1)
    got, nearest, applied = lb.smooth_rssi(np.zeros(3), np.array([[1.0, np.nan, 1.0], [5.0, 5.0, 5.0]]),
                                           np.zeros((2, 3)))
    assert nearest == 0 and applied
    np.testing.assert_allclose(got, [-25 / 26, 0.0, -25 / 26], rtol=1e-14)


# --- Hypothesis: random missing masks in a path-loss fit -------------------------------------------------------

@settings(max_examples=60, deadline=None, derandomize=True)
@given(st.lists(st.booleans(), min_size=40, max_size=40))
def test_any_missing_mask_fits_the_heard_samples(heard):
    d, p = _samples(n=40, seed=11)
    heard = np.array(heard)
    heard[:2] = True                                         # two samples at distinct distances always heard
    holed = np.where(heard, p, np.nan)
    fit = lb.fit_path_loss(d, holed)
    design = np.c_[np.ones(heard.sum()), -10 * np.log10(d[heard])]
    ref = np.linalg.lstsq(design, p[heard], rcond=None)[0]
    np.testing.assert_allclose([fit.ref_power_dbm, fit.path_loss_exp], ref, rtol=0, atol=1e-8)
    assert fit.n_samples == heard.sum()


@settings(max_examples=40, deadline=None, derandomize=True)
@given(st.sampled_from(["distance_m", "rss_dbm"]), st.integers(0, 2), st.integers(1, 4))
def test_wrong_shapes_name_the_argument(which, axis, size):
    good = np.ones((2, 3, 5))
    shape = list(good.shape)
    shape[axis] = shape[axis] + size
    bad = np.ones(shape)
    args = {"distance_m": good, "rss_dbm": good} | {which: bad}
    got = re.escape(f"got {args['distance_m'].shape} and {args['rss_dbm'].shape}")
    with pytest.raises(ValueError, match=r"distance_m and rss_dbm must both have shape .*" + got):
        lb.calibrate_path_loss(args["distance_m"], args["rss_dbm"], mode="pooled")


def test_ozkaya_setting_streams_are_keyed_by_values_not_their_spelling():
    from dataclasses import replace

    from locbook.scenarios import ozkaya as oz
    from locbook.scenarios import ozkaya_simulation as ozs
    case = next(row[-1] for row in oz.simulation_cases() if row[-1].method != "nn")
    entropy = lambda c: oz.case_seed_sequence(2011, c).entropy
    base = replace(case, sigma0_db=0.30000000000000004)
    assert entropy(replace(case, sigma0_db=0.1 + 0.2)) == entropy(base) != entropy(replace(case, sigma0_db=0.3))
    assert entropy(replace(base, motion_m=np.float64(base.motion_m))) == entropy(base)
    assert entropy(replace(base, rt=float(base.rt))) == entropy(base)                       # 10 and 10.0: one value
    assert entropy(replace(base, k_nn=base.k_nn + 1)) == entropy(base)     # estimator only: common random numbers
    assert entropy(replace(base, rt=base.rt + 1)) != entropy(base)         # more steps: another stream
    assert entropy(base) == [2011,
                             lb.seed_from_values({f: getattr(base, f) for f in ozs._TRUTH_FIELDS} | {"steps": base.rt})]


# --- a fit's batch is isolated; an empty batch is an empty answer in every mode ---------
FIT_MODES = {
    "closed_form": {},
    "exact": {"path_loss_exp_bounds": (1.5, 2.2)},
    "cvxpy": {"solver": "cvxpy"},
    "huber": {"loss": "huber", "huber_delta_db": 3.0},
}


def _isolated_batch():
    d, p = _samples(n=30, seed=5)
    powers = np.stack([p, p + 1.5, p - 2.0, p + 0.5])
    powers[1] = np.nan                                      # heard nothing
    powers[3, 1:] = np.nan                                  # heard one sample: one distance
    return d, powers


@pytest.mark.parametrize("mode", list(FIT_MODES))
def test_a_problem_that_heard_too_little_fails_alone(mode):
    """Before, one all-NaN problem raised DegenerateGeometryError for its whole batch; the static estimators give
    NaN and a status for that problem alone, and so does the fit now. The others equal fitting them alone (bit for
    bit: per-problem closed forms, and cvxpy is given the same stacked problem)."""
    d, powers = _isolated_batch()
    with np.errstate(invalid="ignore", divide="ignore"):
        fit = lb.fit_path_loss(d, powers, **FIT_MODES[mode])
    alone = lb.fit_path_loss(d, powers[[0, 2]], **FIT_MODES[mode])
    assert fit.problem_status.tolist() == ["ok", "too_few_distances", "ok", "too_few_distances"]
    assert fit.problem_ok.tolist() == [True, False, True, False] and not fit.ok and alone.ok
    for name in ("ref_power_dbm", "path_loss_exp", "residual_sigma_db"):
        got = getattr(fit, name)
        np.testing.assert_array_equal(got[[0, 2]], getattr(alone, name))
        assert np.isnan(got[[1, 3]]).all(), name
    assert np.isnan(fit.covariance[[1, 3]]).all()
    np.testing.assert_array_equal(fit.covariance[[0, 2]], alone.covariance)
    assert fit.n_samples.tolist() == [30, 0, 30, 1]
    # the closed forms against numpy's lstsq, the problem heard at one distance is not fitted on its one sample
    if mode == "closed_form":
        design = np.c_[np.ones_like(d), -10 * np.log10(d)]
        np.testing.assert_allclose([fit.ref_power_dbm[2], fit.path_loss_exp[2]],
                                   np.linalg.lstsq(design, powers[2], rcond=None)[0], rtol=0, atol=1e-10)


def test_a_design_that_cannot_identify_the_exponent_still_raises():
    """Missing readings are data (a status); the distances are the design: all equal, no batch can use them."""
    with pytest.raises(lb.DegenerateGeometryError, match="distinct distances"):
        lb.fit_path_loss(np.full((2, 4), 3.0), np.full((2, 4), -60.0))
    with pytest.raises(lb.DegenerateGeometryError, match=r"distance_m and rss_dbm must hold at least two"):
        lb.fit_path_loss(np.ones((3, 1)), np.ones((3, 1)))


def test_per_location_mean_carries_a_failed_location_to_its_calibration_alone():
    rng = np.random.default_rng(3)
    dist = rng.uniform(1.0, 9.0, (2, 5, 4))                 # 2 calibrations, 5 locations, 4 anchors
    power = -45.0 - 22.0 * np.log10(dist) + rng.normal(0, 2, dist.shape)
    holed = power.copy()
    holed[1, 2] = np.nan                                    # calibration 1: location 2 heard nothing
    cal = lb.calibrate_path_loss(dist, holed)
    alone = lb.calibrate_path_loss(dist[:1], power[:1])
    assert cal.problem_status.tolist() == ["ok", "too_few_distances"] and not cal.ok
    np.testing.assert_array_equal(cal.ref_power_dbm[:1], alone.ref_power_dbm)
    np.testing.assert_array_equal(cal.path_loss_exp[:1], alone.path_loss_exp)
    assert np.isnan([cal.ref_power_dbm[1], cal.path_loss_exp[1]]).all()


@pytest.mark.parametrize("value", [1e300, -1e300])
def test_powers_whose_sums_overflow_fail_their_problem_alone(value):
    """Finite powers of 1e300 dBm overflow the normal equations' sums; before, the fit returned inf or NaN
    parameters with status closed_form and ok True."""
    d, p = _samples(n=20, seed=6)
    powers = np.stack([p, np.full_like(p, value), p - 1.0])
    with np.errstate(over="ignore", invalid="ignore"):
        fit = lb.fit_path_loss(d, powers)
    assert fit.problem_status.tolist() == ["ok", "not_finite", "ok"] and not fit.ok
    assert np.isnan([fit.ref_power_dbm[1], fit.path_loss_exp[1], fit.residual_sigma_db[1]]).all()
    alone = lb.fit_path_loss(d, powers[[0, 2]])
    np.testing.assert_array_equal(fit.path_loss_exp[[0, 2]], alone.path_loss_exp)


@pytest.mark.parametrize("mode", list(FIT_MODES))
def test_an_empty_batch_is_an_empty_fit_in_every_mode(mode):
    """Before, the Huber fit of an empty batch raised cvxpy's 'Cannot combine empty list of tensors', while the
    closed form and the exact fit returned empty results."""
    fit = lb.fit_path_loss(np.ones((0, 3)), np.zeros((0, 3)), **FIT_MODES[mode])
    assert fit.ref_power_dbm.shape == fit.path_loss_exp.shape == fit.problem_status.shape == (0,)
    assert fit.covariance.shape == (0, 2, 2) and fit.ok
    assert fit.status == ("closed_form" if mode == "closed_form" else "optimal")


def test_reference_tags_a_reader_that_heard_one_tag_is_named():
    """The reference-tag calibration still refuses a step at which a reader heard fewer than two tags (its fit has
    no parameters, and the maps built from it would have none), naming the step and the reader."""
    tags = np.array([[1.0, 1.0], [4.0, 1.0], [1.0, 6.0], [5.0, 5.0]])
    readers = np.array([[0.0, 0.0], [6.0, 0.0], [0.0, 8.0]])
    rss = np.broadcast_to(lb.model_fingerprints(tags, lb.RssModel(readers, lb.PathLossModel(-45.0, 2.2))),
                          (3, 4, 3)).copy()
    rss[2, 1:, 1] = np.nan                                   # step 2: reader 1 heard tag 0 only
    with pytest.raises(lb.DegenerateGeometryError, match=r"ref_rss_dbm.*step \(2,\).*reader 1.*fewer than two"):
        lb.calibrate_from_reference_tags(rss, tags, readers)
    with pytest.raises(ValueError, match=r"ref_rss_dbm.*step \(1,\).*reader 0.*not finite"):
        big = rss.copy()
        big[2, 1:, 1] = -50.0
        big[1, :, 0] = 1e300
        with np.errstate(over="ignore", invalid="ignore"):
            lb.calibrate_from_reference_tags(big, tags, readers, ref_power_bounds_dbm=None, path_loss_exp_bounds=None)


@pytest.mark.parametrize("mode", CALIBRATION_MODES)
def test_calibrating_an_empty_batch_is_an_empty_calibration(mode):
    """Found by tests/static/test_static_fuzz.py: the pooled mode reshaped an empty batch with -1 (numpy: 'cannot
    reshape array of size 0 into shape (0,newaxis)')."""
    cal = lb.calibrate_path_loss(np.ones((0, 3, 4)), np.zeros((0, 3, 4)), mode)
    assert cal.ref_power_dbm.shape == ((0, 4) if mode == "per_anchor" else (0,)) and cal.ok


@pytest.mark.parametrize("mode", ["cvxpy", "huber"])
@pytest.mark.parametrize("value", [-1e300, 1e150])
def test_a_problem_the_solver_cannot_handle_fails_alone_in_a_stacked_fit(mode, value):
    """Found by tests/static/test_static_fuzz.py: one problem with powers of -1e300 dBm made the stacked cvxpy solve
    fail and every problem of the batch came back NaN with status solver_failed. Now a problem whose data overflow the
    objective is not_finite before the solve, and a failed stacked solve is halved until the failing problems are
    alone (as the box-constrained lateration does); the others are their own fits."""
    d, p = _samples(n=12, seed=7)
    powers = np.stack([p, p + 1.0, np.full_like(p, value), p - 1.0])
    with np.errstate(over="ignore", invalid="ignore"):
        fit = lb.fit_path_loss(d, powers, **FIT_MODES[mode])
    assert fit.problem_ok.tolist() == [True, True, False, True]
    assert fit.problem_status[2] in ("not_finite", "solver_failed") and np.isnan(fit.path_loss_exp[2])
    for i in (0, 1, 3):
        alone = lb.fit_path_loss(d, powers[i], **FIT_MODES[mode])
        np.testing.assert_allclose([fit.ref_power_dbm[i], fit.path_loss_exp[i]],
                                   [alone.ref_power_dbm, alone.path_loss_exp], rtol=0, atol=1e-5)


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
