"""Claim and ambiguity logic that the notebooks used to define in their cells: the replicate standard error,
Dogan's Ch. 4 bound study and horizon ambiguity, Gudipati's Ch. VI rows and the Ozkaya simulations' assumptions."""
import json

import numpy as np
import pytest

import locbook as lb
from locbook.scenarios import dogan as dg
from locbook.scenarios import gudipati as gu
from locbook.scenarios import ozkaya as oz


@pytest.fixture
def report(tmp_path, monkeypatch):
    monkeypatch.setenv("LOCBOOK_OUTPUT_DIR", str(tmp_path))
    return lb.Report("test")


# -- the replicate standard error ---------------------------------------------------------------------------------
def test_replicate_standard_error_of_a_sample_mean_is_sigma_over_root_n():
    n, k = 25, 400
    se = lb.replicate_standard_error(lambda rng: rng.normal(0.0, 2.0, n).mean(), range(k))
    # the sample variance of k Gaussian replicates has relative standard error sqrt(2 / (k - 1)) (4 of them allowed)
    assert abs(se**2 / (4.0 / n) - 1) < 4 * np.sqrt(2 / (k - 1))


def test_replicate_standard_error_is_the_sample_sd_of_the_replicates_and_needs_two():
    values = {3: 1.0, 7: 2.0, 11: 4.0}
    seeds = iter(values)
    se = lb.replicate_standard_error(lambda rng: values[next(seeds)], values)
    assert se == pytest.approx(np.sqrt(((1 - 7 / 3) ** 2 + (2 - 7 / 3) ** 2 + (4 - 7 / 3) ** 2) / 2))
    with pytest.raises(ValueError, match="seeds"):
        lb.replicate_standard_error(lambda rng: 0.0, [1])


# -- Dogan, Ch. 4 -------------------------------------------------------------------------------------------------
def test_horizon_ambiguity_of_a_linear_curve_is_the_closed_form_change_of_its_average():
    dt, n = 0.05, 1600
    t = np.arange(n) * dt
    amb = dg.horizon_ambiguity(t.copy(), t, 80.0, [20.0, 40.0])
    # the average of t over t < h is (k_h - 1) dt / 2 with k_h = h / dt samples; over the whole curve (n - 1) dt / 2
    expected = max(abs((h / dt - 1) * dt / 2 - (n - 1) * dt / 2) for h in (20.0, 40.0))
    assert amb.size == pytest.approx(expected, rel=1e-12)
    assert "20, 40 s from 80 s" in amb.what and amb.source == dg.HORIZON_SOURCE
    with pytest.raises(lb.ParameterError, match="time_s"):
        dg.horizon_ambiguity(t, t[:-1], 80.0, [20.0])
    with pytest.raises(lb.ParameterError, match="other_horizons_s"):
        dg.horizon_ambiguity(t, t, 80.0, [])


def test_bound_study_starts_at_the_prior_and_reuses_one_seed():
    mse = np.array([2.0, 3.0])
    study = dg.BoundStudy({6.0: mse}, n_steps=30, n_trajectories=20, smc_seed=5, replicate_seeds=(1, 2, 3))
    for kind in ("smc", "linear"):
        b = study.bound_m(kind, False, 6.0)
        # Eq. (4.23) at step 0: J_0 = P_0^-1, whose position block is diag(MSE_MLE) (Eq. (3.20))
        assert b[0] == pytest.approx(np.sqrt(mse.sum()), rel=1e-12)
        assert np.all(np.isfinite(b)) and b.shape == (30,)
    # every SMC curve of the study uses the same trajectories; another generator gives other ones
    assert np.array_equal(study.bound_m("smc", True, 6.0), study.bound_m("smc", True, 6.0))
    other = study.bound_m("smc", True, 6.0, rng=np.random.default_rng(6))
    assert not np.array_equal(other, study.bound_m("smc", True, 6.0))
    assert study.replicate_se(np.min, "linear", True, 6.0) == 0.0          # deterministic
    replicates = [np.min(dg.pcrlb_m("smc", fusion=True, sigma_rss_db=6.0, mse_mle_m2=mse, n_steps=30,
                                    rng=np.random.default_rng(s), n_trajectories=20)) for s in (1, 2, 3)]
    assert study.replicate_se(np.min, "smc", True, 6.0) == pytest.approx(np.std(replicates, ddof=1), rel=1e-12)


# -- Gudipati, Ch. VI ---------------------------------------------------------------------------------------------
def _errors(levels, n_runs=50, n_points=8, turn_excess=None, seed=0):
    """WalkErrors per (path, anchors, method): per-point errors level + N(0, 0.05); at the turn points the method's
    turn_excess is added (U path)."""
    rng = np.random.default_rng(seed)
    near = np.zeros(n_points, bool)
    near[[2, 5]] = True
    out = {}
    for path in gu.PATHS:
        for na in gu.ANCHOR_SETS:
            for m in gu.METHODS:
                pp = levels[(na, m)] + rng.normal(0.0, 0.05, (n_runs, n_points))
                if path == "u" and turn_excess:
                    pp[:, near] += turn_excess.get(m, 0.0)
                out[(path, na, m)] = gu.WalkErrors(pp.mean(axis=1), np.sqrt((pp**2).mean(axis=1)), pp)
    return out, near


def test_record_ch6_records_the_headline_means_and_each_claims_smallest_margin(report):
    level = {"rss_only": 3.8, "inertial_only": 6.0, "position_fusion": 2.0, "kf": 1.5, "ekf": 1.0, "ukf": 0.8}
    levels = {(na, m): v + (0.3 if na == 4 else 0.0) for m, v in level.items() for na in gu.ANCHOR_SETS}
    errors, near = _errors(levels, turn_excess={"rss_only": 1.0, "kf": 0.5, "ekf": 0.4, "ukf": 0.3})
    flags = {k: None for k in errors}
    gu.record_ch6(report, errors, flags, headline_anchors=6, shadowing_sigma_db=4.0, calibrated=True, ukf_alpha=1e-3,
                  near_turn=near)
    rows = {r["printed_id"]: r for r in report.numbers}
    linear_rss = rows["Ch. VI text | linear path | without fusion"]
    assert linear_rss["kind"] == "calibrated" and "4.000 dB" in linear_rss["calibrated_from"]
    assert linear_rss["reproduced"] == pytest.approx(errors[("linear", 6, "rss_only")].mean_m.mean())
    assert rows["Abstract | 30m x 10m area | positional accuracy"]["verdict"] == ""      # repeats the fused row
    # Fig. 5.4 caption: the smallest gap of a fusion filter over a sensor alone is RSS only minus the KF (4 anchors)
    fig54 = rows["Fig. 5.4 caption | fusion versus individual sensors | claim"]
    gap = errors[("linear", 4, "rss_only")].mean_m - errors[("linear", 4, "kf")].mean_m
    assert fig54["reproduced"] == pytest.approx(gap.mean()) and fig54["mc_std_error"] == pytest.approx(
        lb.mc_standard_error(gap))
    assert fig54["verdict"] == "within" and fig54["note"] == ""
    # the UKF's closest competitor is the EKF; the UKF is clearly better here, so no note
    ukf = rows["Sec. 5.3 text | Fig. 5.4, UKF | claim"]
    assert "(EKF)" in ukf["quantity"] and ukf["verdict"] == "within" and ukf["note"] == ""
    six = rows["Sec. 5.3 text | Fig. 5.5, six anchor nodes | claim"]
    assert six["reproduced"] == pytest.approx(0.3, abs=0.05) and six["verdict"] == "within"
    turns = rows["Sec. 5.3 text | Fig. 5.7, U-path turns | claim"]
    assert "(UKF)" in turns["quantity"] and turns["reproduced"] == pytest.approx(0.3, abs=0.05)  # turns minus elsewhere
    assert rows["Sec. 5.3 text | Fig. 5.6, inertial sensors alone | claim"]["note"].startswith("'acceptable'")


def test_record_ch6_gives_the_reason_when_a_claim_fails(report):
    level = {"rss_only": 3.8, "inertial_only": 6.0, "position_fusion": 2.0, "kf": 1.5, "ekf": 1.0, "ukf": 1.0}
    levels = {(na, m): v for m, v in level.items() for na in gu.ANCHOR_SETS}    # six anchors no better than four
    errors, near = _errors(levels, turn_excess={"ekf": -0.5})                     # the EKF is better at the turns
    gu.record_ch6(report, errors, {k: None for k in errors}, headline_anchors=4, shadowing_sigma_db=4.0,
                  calibrated=False, ukf_alpha=1e-3, near_turn=near)
    rows = {r["printed_id"]: r for r in report.numbers}
    assert rows["Ch. VI text | linear path | without fusion"]["kind"] == "reproduction"
    turns = rows["Sec. 5.3 text | Fig. 5.7, U-path turns | claim"]
    assert turns["verdict"] == "miss" and turns["note"].startswith("per method: RSS only")
    ukf = rows["Sec. 5.3 text | Fig. 5.4, UKF | claim"]
    assert ukf["verdict"] != "within" and "numerically the EKF's linearisation" in ukf["note"]
    assert rows["Sec. 5.3 text | Fig. 5.5, six anchor nodes | claim"]["verdict"] != "within"


# -- Ozkaya, Sec. 7.2 ---------------------------------------------------------------------------------------------
def test_the_simulations_share_one_assumption_block(report):
    oz.record_simulation_assumptions(report, oz.sim_interpretations())
    recorded = {a["name"]: a["value"] for a in report.assumptions}
    # the shared protocol, then every declared simulation reading (data/readings/ozkaya2011.csv) by its name
    assert set(recorded) == {"room_m", "anchors_m", "target_protocol", "cells", "min_distance_m",
                             "thesis_crlb_average", *oz.sim_interpretations()}
    assert {name: json.loads(recorded[name]) if recorded[name].startswith('"') else recorded[name]
            for name in oz.sim_interpretations()} == oz.sim_interpretations()
    assert np.allclose(json.loads(recorded["anchors_m"]), oz.LAYOUTS["corners3"])
    assert all(a["reason"] for a in report.assumptions)
