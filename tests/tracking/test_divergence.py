"""The consistency guard of every Kalman-family filter.

The normalised innovation squared NIS = nu^T S^{-1} nu is checked against filterpy (its ``mahalanobis`` is
sqrt(NIS)); on a linear-Gaussian model simulated from the filter's own model NIS ~ chi^2(dof) and the false-alarm
fraction stays below the bound (T - w + 1) (1 - p)^w of a window of w consecutive exceedances at probability p; the
UKF scenarios of the issue (sigma = 1e-3 dB, Q = 1e4, alpha = 1; a run that lost track at alpha = 1e-3 with 20 % of
the readings missing) are flagged while the EKF on the same data is not; numpy and the compiled EKF agree on the
flags; the window rule is checked against a plain per-run loop.
"""

import numpy as np
import pytest
from filterpy.kalman import KalmanFilter
from scipy.stats import chi2

import locbook as lb
from builders import REPO_ROOT
from locbook.tracking import _compiled as K

try:
    import numba  # noqa: F401
    HAVE_NUMBA = True
except ImportError:
    HAVE_NUMBA = False

MODEL = lb.constant_velocity(1.0, 0.1)
H = MODEL.position_measurement_matrix()
R = np.array([[0.5, 0.1], [0.1, 0.3]])
ANCHORS = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0]])


def _simulate(runs, steps, seed, missing=0.0, noise=R):
    """States and position fixes drawn from the filter's own model (x0 ~ N(X0, P0), w ~ N(0, Q), v ~ N(0, noise))."""
    rng = np.random.default_rng(seed)
    x0, P0 = np.array([1.0, 2.0, 0.5, -0.3]), np.eye(4)
    x = x0 + rng.multivariate_normal(np.zeros(4), P0, runs)
    xs = np.empty((runs, steps, 4))
    for k in range(steps):
        x = x @ MODEL.F.T + rng.multivariate_normal(np.zeros(4), MODEL.Q, runs)
        xs[:, k] = x
    z = xs @ H.T + rng.multivariate_normal(np.zeros(2), noise, (runs, steps))
    z[rng.random(z.shape) < missing] = np.nan
    return xs, z, x0, P0


def _filterpy_nis(z, x0, P0):
    """filterpy's KalmanFilter per run with the components present: NIS = mahalanobis^2, NaN where no update."""
    nis = np.full(z.shape[:2], np.nan)
    for b in range(z.shape[0]):
        f = KalmanFilter(dim_x=4, dim_z=2)
        f.F, f.Q, f.x, f.P = MODEL.F, MODEL.Q, x0.copy(), P0.copy()
        for k in range(z.shape[1]):
            f.predict()
            keep = np.isfinite(z[b, k])
            if keep.any():
                f.update(z[b, k, keep], R=R[np.ix_(keep, keep)], H=H[keep])
                nis[b, k] = f.mahalanobis ** 2
    return nis


@pytest.fixture
def numba_path(request, monkeypatch):
    monkeypatch.setattr(K, "_NUMBA_ENABLED", request.param == "numba")
    monkeypatch.setattr(K, "_NUMBA_MIN_WORK", 0)
    return request.param


PATHS = ["numpy"] + (["numba"] if HAVE_NUMBA else [])


def _filters(z, x0, P0, **kw):
    """Every Kalman-family filter on the same linear model (serial streams: one scalar update per component)."""
    diag_R = np.diag(np.diag(R))
    return {
        "kalman_filter": lb.kalman_filter(MODEL.F, MODEL.Q, x0, P0, lb.LinearMeasurement(z, H, R), **kw),
        "ekf parallel": lb.extended_kalman_filter(MODEL.F, MODEL.Q, x0, P0, [lb.LinearMeasurement(z, H, R)], **kw),
        "ukf": lb.unscented_kalman_filter(MODEL.F, MODEL.Q, x0, P0, [lb.LinearMeasurement(z, H, R)], alpha=1.0, **kw),
        "ekf serial (diagonal R)": lb.extended_kalman_filter(
            MODEL.F, MODEL.Q, x0, P0, [lb.LinearMeasurement(z, H, diag_R, mode="serial")], **kw),
    }


@pytest.mark.parametrize("numba_path", PATHS, indirect=True)
@pytest.mark.parametrize("missing", [0.0, 0.3])
def test_nis_equals_filterpy_mahalanobis_squared(numba_path, missing):
    _, z, x0, P0 = _simulate(6, 40, 1, missing)
    z[2, 5] = np.nan                                    # a step without any update: NaN NIS and dof 0
    ref = _filterpy_nis(z, x0, P0)
    for name, res in _filters(z, x0, P0).items():
        if name.startswith("ekf serial"):
            continue                                    # another R: checked below
        np.testing.assert_allclose(res.nis, ref, rtol=1e-9, atol=1e-12, err_msg=name)
        np.testing.assert_array_equal(res.nis_dof, np.isfinite(z).sum(-1), err_msg=name)
        assert np.isnan(res.nis[2, 5]) and res.nis_dof[2, 5] == 0
    # serial scalar updates of one step: their NIS add up to the stacked update's (a diagonal R, exact)
    diag = np.diag(np.diag(R))
    par = lb.extended_kalman_filter(MODEL.F, MODEL.Q, x0, P0, [lb.LinearMeasurement(z, H, diag)])
    ser = lb.extended_kalman_filter(MODEL.F, MODEL.Q, x0, P0, [lb.LinearMeasurement(z, H, diag, mode="serial")])
    np.testing.assert_allclose(ser.nis, par.nis, rtol=1e-9, atol=1e-12)


def test_nis_of_the_rss_ekf_numpy_and_compiled_agree_with_a_direct_computation(monkeypatch):
    """The RSS EKF (parallel and serial): the NIS from the numpy loop and the compiled kernel equal
    nu^T S^{-1} nu computed from the filter's own prior (x, P) at each step (one step, independently)."""
    rng = np.random.default_rng(3)
    ch = lb.PathLossModel(-40.0, 2.2, 2.0)
    model = lb.constant_velocity(1.0, 0.05)
    pos = 5 + np.cumsum(0.1 * rng.standard_normal((30, 12, 2)), axis=1)
    z = ch.sample_rss_dbm(np.linalg.norm(pos[:, :, None] - ANCHORS, axis=-1), rng=rng)
    z[rng.random(z.shape) < 0.2] = np.nan
    x0, P0 = model.state_from(np.array([5.0, 5.0])), np.eye(4)
    monkeypatch.setattr(K, "_NUMBA_MIN_WORK", 0)
    for mode in ("parallel", "serial"):
        meas = lb.RssMeasurement(z, ANCHORS, ch, model.position_index, mode=mode, order="given")
        out = {}
        for path in PATHS:
            monkeypatch.setattr(K, "_NUMBA_ENABLED", path == "numba")
            out[path] = lb.extended_kalman_filter(model.F, model.Q, x0, P0, [meas])
        res = out["numpy"]
        k = 7                                               # step k from the posterior of step k - 1
        x, P = res.mean[:, k - 1] @ model.F.T, model.F @ res.cov[:, k - 1] @ model.F.T + model.Q
        for b in range(z.shape[0]):
            heard = np.isfinite(z[b, k])
            if mode == "parallel":
                d = np.linalg.norm(x[b, :2] - ANCHORS[heard], axis=-1)
                Hb = np.zeros((heard.sum(), 4))
                Hb[:, :2] = -(10 * 2.2 / np.log(10)) * (x[b, :2] - ANCHORS[heard]) / d[:, None] ** 2
                nu = z[b, k, heard] - ch.mean_rss_dbm(d)
                S = Hb @ P[b] @ Hb.T + 4.0 * np.eye(heard.sum())
                expected = nu @ np.linalg.solve(S, nu)
            else:                                           # scalar updates, each at the state updated so far
                xb, Pb, expected = x[b].copy(), P[b].copy(), 0.0
                for j in np.flatnonzero(heard):
                    d = np.linalg.norm(xb[:2] - ANCHORS[j])
                    h = np.zeros(4)
                    h[:2] = -(10 * 2.2 / np.log(10)) * (xb[:2] - ANCHORS[j]) / d**2
                    nu, s = z[b, k, j] - ch.mean_rss_dbm(d), h @ Pb @ h + 4.0
                    expected += nu**2 / s
                    gain = Pb @ h / s
                    xb, Pb = xb + gain * nu, Pb - np.outer(gain, gain) * s
            assert res.nis[b, k] == pytest.approx(expected, rel=1e-9), (mode, b)
        for path in PATHS[1:]:
            np.testing.assert_allclose(out[path].nis, res.nis, rtol=1e-9, equal_nan=True)
            np.testing.assert_array_equal(out[path].nis_dof, res.nis_dof)


def _streak_probabilities(steps, window, q):
    """``out[t]``: the exact probability of at least ``window`` consecutive exceedances among ``t`` independent
    updates that each exceed with probability ``q``, for t = 0 .. steps (a dynamic programme over the length of the
    current streak, 0 .. window - 1; a completed streak is absorbed into ``out``)."""
    state = np.zeros(window)
    state[0] = 1.0
    out = np.zeros(steps + 1)
    for t in range(1, steps + 1):
        out[t] = out[t - 1] + q * state[-1]
        state = np.concatenate([[(1 - q) * state.sum()], q * state[:-1]])
    return out


def test_the_streak_probability_equals_enumeration():
    """The dynamic programme against every one of the 2^12 exceedance patterns of 12 updates."""
    q, steps = 0.3, 12
    patterns = (np.arange(2 ** steps)[:, None] >> np.arange(steps)) & 1
    prob = np.prod(np.where(patterns == 1, q, 1 - q), axis=1)
    for window in (1, 2, 3, 5, 12):
        longest = np.zeros(patterns.shape[0], int)
        streak = np.zeros(patterns.shape[0], int)
        for k in range(steps):
            streak = np.where(patterns[:, k] == 1, streak + 1, 0)
            longest = np.maximum(longest, streak)
        assert _streak_probabilities(steps, window, q)[-1] == pytest.approx(prob[longest >= window].sum(), rel=1e-12)


def test_false_alarms_on_the_filters_own_model_match_the_exact_streak_probability():
    """Simulated from the filter's own model, NIS ~ chi^2(dof) independently over updates, so each update exceeds the
    bound with probability exactly 1 - p and a run of T updates is flagged with the exact probability of a streak of
    w exceedances among T Bernoulli(1 - p) trials. At the defaults that is below 1e-55 (no flag); at a loose setting
    (w = 2, p = 0.9, about 0.6 per run) the fraction flagged must equal the mean of the runs' exact probabilities
    within 4 binomial standard errors (the flags of different runs are independent). The serial EKF gets readings
    drawn with its diagonal R (its own model)."""
    runs, steps = 400, 100
    _, z, x0, P0 = _simulate(runs, steps, 2, missing=0.1)
    _, z_diag, _, _ = _simulate(runs, steps, 12, missing=0.1, noise=np.diag(np.diag(R)))
    results = {name: res for name, res in _filters(z, x0, P0).items() if not name.startswith("ekf serial")}
    results["ekf serial (diagonal R)"] = _filters(z_diag, x0, P0)["ekf serial (diagonal R)"]
    assert _streak_probabilities(steps, DEFAULT_WINDOW, 1 - DEFAULT_PROBABILITY)[-1] < 1e-55
    for name, res in results.items():
        assert res.n_diverged == 0, name
        assert np.all(res.diverged_step == -1)
        # the NIS is chi-square: mean = dof, and the tail beyond the 0.999 quantile is rare
        nis, dof = res.nis[res.nis_dof == 2], 2
        assert abs(nis.mean() - dof) < 4 * np.sqrt(2 * dof / nis.size), name
        assert (nis > chi2.ppf(0.999, dof)).mean() < 0.003, name
    w, p = 2, 0.9
    hits = _streak_probabilities(steps, w, 1 - p)
    for name, res in results.items():
        readings = z_diag if name.startswith("ekf serial") else z
        updates = np.isfinite(readings).any(axis=-1).sum(axis=-1)          # steps without any reading are skipped
        prob = hits[updates]
        expected, se = prob.mean(), np.sqrt(np.sum(prob * (1 - prob))) / runs
        flagged = lb.tracking.results.nis_divergence(res.nis, res.nis_dof, w, p)[0]
        assert abs(flagged.mean() - expected) <= 4 * se, (name, flagged.mean(), expected, se)
        loose = _filters(readings, x0, P0, divergence_window=w, divergence_probability=p)[name]
        np.testing.assert_array_equal(loose.diverged, flagged, err_msg=name)


DEFAULT_WINDOW, DEFAULT_PROBABILITY = lb.tracking.results.DIVERGENCE_WINDOW, lb.tracking.results.DIVERGENCE_PROBABILITY


def _documented_table():
    """The table of docs/filters.md ("What the guard flags"): {row label: [values per dof]} and the dofs."""
    page = REPO_ROOT / "docs" / "filters.md"
    if not page.exists():
        pytest.skip("the docs are not beside the tests (an installed package)")
    doc = page.read_text(encoding="utf-8")
    lines = [line.strip() for line in doc.splitlines()]
    start = next(i for i, line in enumerate(lines) if line.startswith("dof "))
    dofs = [int(v) for v in lines[start].split()[1:]]
    rows = {}
    for line in lines[start + 1:start + 4]:
        label, values = line.split(":")
        rows[label.strip()] = [float(v) for v in values.split()]
    return dofs, rows


def test_the_documented_flag_probabilities_of_a_mis_specified_noise_level_are_exact():
    """The documented table: sigma underestimated by half with R dominating S makes the NIS 4 chi^2(dof), so each
    update exceeds the bound with q = chi2.sf(chi2.ppf(p, dof) / 4, dof); each entry (2 significant digits) must be
    the exact streak probability at the defaults."""
    dofs, rows = _documented_table()
    assert set(rows) == {"q per update", "flagged, T = 1e3", "flagged, T = 1e4"}
    for i, dof in enumerate(dofs):
        q = chi2.sf(chi2.ppf(DEFAULT_PROBABILITY, dof) / 4, dof)
        assert rows["q per update"][i] == float(f"{q:.2g}"), dof
        hits = _streak_probabilities(10_000, DEFAULT_WINDOW, q)
        assert rows["flagged, T = 1e3"][i] == float(f"{hits[1000]:.2g}"), dof
        assert rows["flagged, T = 1e4"][i] == float(f"{hits[10_000]:.2g}"), dof
    assert max(rows["flagged, T = 1e4"]) > 0.5 and min(rows["flagged, T = 1e4"]) < 1e-9


@pytest.mark.parametrize("dof", [4, 8, 10])
def test_the_guard_flags_a_noise_level_underestimated_by_half_as_often_as_documented(dof):
    """NIS = 4 chi^2(dof) (sigma underestimated by half, R dominating S), 1,000 updates per run: the fraction of runs
    flagged at the defaults equals the exact streak probability within 4 binomial standard errors (at dof 4 none of
    the runs, at dof 10 about one in six)."""
    rng = np.random.default_rng(dof)
    runs, steps = 2000, 1000
    nis = 4 * rng.chisquare(dof, (runs, steps))
    flagged, first = lb.tracking.results.nis_divergence(nis, np.full((runs, steps), dof))
    q = chi2.sf(chi2.ppf(DEFAULT_PROBABILITY, dof) / 4, dof)
    prob = _streak_probabilities(steps, DEFAULT_WINDOW, q)[-1]
    se = np.sqrt(prob * (1 - prob) / runs)
    assert abs(flagged.mean() - prob) <= 4 * se + 1e-12, (flagged.mean(), prob, se)
    assert np.all((first >= 0) == flagged)


def test_integral_float_dof_are_accepted_and_others_named():
    """nis_divergence(np.ones(30) * 100, np.full(30, 2.0), 5) ended in numpy's 'arrays used as indices must be of
    integer type'. A float dof with integral values equals the integer dof; a fractional, negative or NaN dof is an
    error naming nis_dof."""
    nis = np.ones(30) * 100
    got = lb.tracking.results.nis_divergence(nis, np.full(30, 2.0), 5)
    assert got[0] and got[1] == 0
    rng = np.random.default_rng(4)
    dof = rng.integers(0, 4, (3, 40))
    nis = np.where(dof > 0, 30.0 * rng.random(dof.shape), np.nan)
    for as_float in (dof.astype(float), dof.astype(np.float32), dof.astype(np.uint8)):
        for a, b in zip(lb.tracking.results.nis_divergence(nis, as_float, 2, 0.9),
                        lb.tracking.results.nis_divergence(nis, dof, 2, 0.9)):
            np.testing.assert_array_equal(a, b)
    for bad in (np.full(30, 2.5), np.full(30, -1.0), np.full(30, -1), np.r_[np.full(29, 2.0), np.nan],
                np.full(30, np.inf)):
        with pytest.raises(ValueError, match="nis_dof"):
            lb.tracking.results.nis_divergence(np.ones(30) * 100, bad, 5)


def test_a_nan_nis_at_an_update_neither_counts_nor_breaks_the_streak():
    """A NaN NIS where dof > 0 (e.g. a foreign update function that returns x and P only) carries no evidence either
    way: it is skipped like a step without an update. It used to reset the streak."""
    nis, dof = np.full(21, 100.0), np.full(21, 2)
    nis[10] = np.nan
    diverged, first = lb.tracking.results.nis_divergence(nis, dof, 20)
    assert diverged and first == 0                     # 20 exceedances around the NaN
    diverged, _ = lb.tracking.results.nis_divergence(nis[:20], dof[:20], 20)
    assert not diverged                                 # 19 exceedances: the NaN does not count
    nis = np.r_[np.full(5, 100.0), np.nan, np.full(5, 100.0)]
    diverged, first = lb.tracking.results.nis_divergence(nis, np.full(11, 2), 6)
    assert diverged and first == 0


def _ukf_scenario_1(runs=6, steps=60, seed=0):
    """Sigma = 1e-3 dB, a random walk with Q = 1e4 I, 4 anchors; the UKF at alpha = 1."""
    rng = np.random.default_rng(seed)
    ch = lb.PathLossModel(-40.0, 2.0, 1e-3)
    pos = 5 + np.cumsum(0.05 * rng.standard_normal((runs, steps, 2)), axis=1)
    z = ch.sample_rss_dbm(np.linalg.norm(pos[:, :, None] - ANCHORS, axis=-1), rng=rng)
    return pos, lb.RssMeasurement(z, ANCHORS, ch, [0, 1]), np.eye(2), 1e4 * np.eye(2)


def test_ukf_that_loses_track_at_alpha_1_is_flagged_and_the_ekf_is_not():
    pos, meas, F, Q = _ukf_scenario_1()
    x0, P0 = np.array([5.0, 5.0]), np.eye(2)
    ukf = lb.unscented_kalman_filter(F, Q, x0, P0, [meas], alpha=1.0)
    ekf = lb.extended_kalman_filter(F, Q, x0, P0, [meas])
    err_u = np.linalg.norm(ukf.mean - pos, axis=-1)
    err_e = np.linalg.norm(ekf.mean - pos, axis=-1)
    sd_u = np.sqrt(np.trace(ukf.cov, axis1=-2, axis2=-1))
    assert err_u.max(axis=-1).min() > 1e4 * sd_u.min()             # every run lost, far beyond its covariance
    assert np.all(ukf.diverged) and ukf.n_diverged == 6
    assert np.all((ukf.diverged_step >= 0) & (ukf.diverged_step < 10))
    assert err_e.max() < 0.05 and ekf.n_diverged == 0
    # the guard off: nothing flagged, the same estimates
    off = lb.unscented_kalman_filter(F, Q, x0, P0, [meas], alpha=1.0, divergence_window=0)
    assert off.n_diverged == 0 and np.all(off.diverged_step == -1)
    np.testing.assert_array_equal(off.mean, ukf.mean)


def test_ukf_at_the_default_alpha_with_missing_readings_is_flagged_once_it_lost_track():
    """The second scenario of the issue (alpha = 1e-3, 20 % of readings missing) after a long run: the estimate is
    1e4 reported standard deviations from the truth while P stays symmetric positive definite. Runs started in that
    state are flagged within the window; runs started consistently are not."""
    rng = np.random.default_rng(5)
    model = lb.constant_velocity(0.1, 0.05)
    ch = lb.PathLossModel(-40.0, 2.0, 2.0)
    runs, steps = 8, 80
    pos = 5 + np.cumsum(0.02 * rng.standard_normal((runs, steps, 2)), axis=1)
    z = ch.sample_rss_dbm(np.linalg.norm(pos[:, :, None] - ANCHORS, axis=-1), rng=rng)
    z[rng.random(z.shape) < 0.2] = np.nan
    x0 = np.zeros((runs, 4))
    x0[:, :2] = 5.0
    lost = np.arange(runs) % 2 == 1
    x0[lost, :2] += 2e3                                             # 1e4 sd of P0 = 0.04 I away
    P0 = np.diag([0.04, 0.04, 0.01, 0.01])
    res = lb.unscented_kalman_filter(model.F, model.Q, x0, P0,
                                     [lb.RssMeasurement(z, ANCHORS, ch, model.position_index)])
    assert np.all(np.linalg.eigvalsh(res.cov)[..., 0] > 0)             # no existing guard notices
    np.testing.assert_array_equal(res.diverged, lost)
    assert np.all(res.diverged_step[lost] == 0)


def test_numpy_and_compiled_ekf_agree_on_the_flags(monkeypatch):
    """Half the runs get readings 30 times noisier than the filter's model (an inconsistent filter): flagged on both
    paths, the same runs and steps."""
    rng = np.random.default_rng(8)
    ch = lb.PathLossModel(-40.0, 2.2, 1.0)
    model = lb.constant_velocity(1.0, 0.05)
    runs, steps = 70, 60
    pos = 5 + np.cumsum(0.05 * rng.standard_normal((runs, steps, 2)), axis=1)
    mean = ch.mean_rss_dbm(np.linalg.norm(pos[:, :, None] - ANCHORS, axis=-1))
    noisy = np.arange(runs) % 2 == 0
    z = mean + np.where(noisy, 30.0, 1.0)[:, None, None] * rng.standard_normal(mean.shape)
    x0, P0 = model.state_from(np.array([5.0, 5.0])), np.eye(4)
    monkeypatch.setattr(K, "_NUMBA_MIN_WORK", 0)
    for mode in ("parallel", "serial"):
        meas = lb.RssMeasurement(z, ANCHORS, ch, model.position_index, mode=mode)
        out = {}
        for path in PATHS:
            monkeypatch.setattr(K, "_NUMBA_ENABLED", path == "numba")
            out[path] = lb.extended_kalman_filter(model.F, model.Q, x0, P0, [meas], divergence_window=5)
        ref = out["numpy"]
        assert ref.diverged[noisy].mean() > 0.9 and not ref.diverged[~noisy].any()
        for path in PATHS[1:]:
            np.testing.assert_array_equal(out[path].diverged, ref.diverged)
            np.testing.assert_array_equal(out[path].diverged_step, ref.diverged_step)


def _reference_flags(nis, dof, window, probability):
    """The window rule as a plain loop over runs and steps (the independent reference)."""
    flat_nis, flat_dof = nis.reshape(-1, nis.shape[-1]), dof.reshape(-1, nis.shape[-1])
    diverged, first = np.zeros(flat_nis.shape[0], bool), np.full(flat_nis.shape[0], -1)
    for b in range(flat_nis.shape[0]):
        streak, start = 0, -1
        for k in range(flat_nis.shape[1]):
            if flat_dof[b, k] == 0 or np.isnan(flat_nis[b, k]):
                continue
            if flat_nis[b, k] > chi2.ppf(probability, flat_dof[b, k]):
                start = k if streak == 0 else start
                streak += 1
                if streak >= window:
                    diverged[b], first[b] = True, start
                    break
            else:
                streak = 0
    return diverged.reshape(nis.shape[:-1]), first.reshape(nis.shape[:-1])


def test_window_rule_equals_a_per_run_loop():
    rng = np.random.default_rng(11)
    dof = rng.integers(0, 4, (5, 7, 40))
    nis = np.where(dof > 0, rng.chisquare(np.maximum(dof, 1)) * rng.choice([0.5, 40.0], dof.shape, p=[0.5, 0.5]),
                   np.nan)
    nis[rng.random(nis.shape) < 0.05] = np.nan          # NaN at some updates (dof > 0): skipped by both
    for window, p in ((1, 0.99), (3, 0.9), (4, 0.999), (41, 0.5)):
        got = lb.tracking.results.nis_divergence(nis, dof, window, p)
        ref = _reference_flags(nis, dof, window, p)
        np.testing.assert_array_equal(got[0], ref[0])
        np.testing.assert_array_equal(got[1], ref[1])
        if window == 3:
            assert 0 < ref[0].sum() < ref[0].size           # the pattern exercises both outcomes
    off = lb.tracking.results.nis_divergence(nis, dof, 0)
    assert not off[0].any() and np.all(off[1] == -1)
    with pytest.raises(ValueError, match="divergence_probability"):
        lb.tracking.results.nis_divergence(nis, dof, 3, 1.0)
    with pytest.raises(ValueError, match="divergence_window"):
        lb.kalman_filter(MODEL.F, MODEL.Q, np.zeros(4), np.eye(4), lb.LinearMeasurement(np.zeros((3, 2)), H, R),
                         divergence_window=2.5)


def _guard_by_loop(nis, dof, window, probability):
    """The guard's rule step by step (one run): the first step of the first `window` consecutive exceedances among
    the updates (dof > 0 and a number), -1 if none."""
    streak, start = 0, -1
    for k, (v, d) in enumerate(zip(nis, dof)):
        if d == 0 or np.isnan(v):
            continue
        if v > chi2.ppf(probability, d):
            streak, start = streak + 1, start if streak else k
            if streak == window:
                return start
        else:
            streak = 0
    return -1


def test_the_guard_is_its_rule_run_by_run():
    """nis_divergence against the rule written as a loop, on runs built around the threshold: exactly `window`
    exceedances in all (together or split), one short, steps without an update (dof 0 or a NaN NIS) inside a streak,
    and random runs; the batch axes are kept (numpy's passes: the guard has one implementation)."""
    window, probability = 4, 0.99
    rng = np.random.default_rng(11)
    runs, steps = 60, 40
    dof = rng.integers(0, 3, (runs, steps))
    high, low = 1e3, 1e-3
    nis = np.where(rng.random((runs, steps)) < 0.3, high, low)
    nis[:6] = low
    nis[0, 5:9] = high                                  # exactly window, together
    nis[1, [3, 4, 20, 21]] = high                       # exactly window, split: no streak
    nis[2, 10:13] = high                                # one short
    nis[3, [7, 8, 10, 11]] = high                       # a step without an update inside the streak
    dof[3, 9], dof[3, [7, 8, 10, 11]] = 0, 2
    nis[4, 30:35], dof[4, 30:35], nis[4, 32] = high, 1, np.nan
    nis[5, 36:40], dof[5, 36:40] = high, 2              # at the very end
    dof[:6, :][nis[:6] == high] = np.maximum(dof[:6, :][nis[:6] == high], 1)
    nis = np.where((dof == 0) & (rng.random((runs, steps)) < 0.5), np.nan, nis)
    expected = np.array([_guard_by_loop(nis[b], dof[b], window, probability) for b in range(runs)])
    diverged, first = lb.tracking.results.nis_divergence(nis.reshape(6, 10, steps), dof.reshape(6, 10, steps), window,
                                                         probability)
    assert diverged.shape == first.shape == (6, 10)
    np.testing.assert_array_equal(first.ravel(), expected)
    np.testing.assert_array_equal(diverged.ravel(), expected >= 0)
    assert expected[:6].tolist() == [5, -1, -1, 7, 30, 36]
    assert 0 < np.count_nonzero(expected >= 0) < runs  # both kinds among the random runs too


@pytest.mark.compiled
def test_the_guard_never_loads_numba_by_itself():
    """A large NIS judged in a fresh interpreter where no compiled filter ran: numpy's passes answer, and numba stays
    unloaded (loading it for the guard alone would cost more than the pass saves)."""
    import subprocess
    import sys
    code = ("import sys, numpy as np\n"
            "from locbook.tracking.results import nis_divergence\n"
            "nis = np.full((50, 400), 100.0)\n"
            "flags, first = nis_divergence(nis, np.full((50, 400), 2), 5)\n"
            "print(bool(flags.all()), int(first.max()), 'numba' in sys.modules)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["True", "0", "False"], out
