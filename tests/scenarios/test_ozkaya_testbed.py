"""The synthetic test bed of Ozkaya (2011) Sec. 7.3: the channel's noise structure, the reference-tag wiring,
the mapping of printed cells and how they go on the scoreboard, checked against the model's definition,
least-squares theory, the printed-values file and the thesis's text."""
from dataclasses import replace

import numpy as np
import pytest

import locbook as lb
from locbook.scenarios import ozkaya as oz
from locbook.scenarios import ozkaya_testbed as tb

QUIET = tb.TestbedChannel(static_sigma_db=0.0, orientation_sigma_db=0.0, dynamic_sigma_db=0.0, burst_probability=0.0,
                          resolution_db=None, floor_dbm=-np.inf)


def test_pooled_sigma_eq_6_7_is_half_the_variance_and_the_dof_variant_is_unbiased():
    # linear LS theory: E[SSR] = sigma^2 (N - p). Four tags, three readers, two parameters per reader:
    # Eq. (6.7) (divide by 12) estimates sigma^2 / 2; dividing by 12 - 6 is unbiased.
    rng = np.random.default_rng(3)
    sigma, steps = 3.0, 5000
    tags, readers = np.asarray(oz.REFERENCE_TAGS_M), np.asarray(oz.TESTBED_READERS_M)
    mean = lb.model_fingerprints(tags, lb.RssModel(readers, lb.PathLossModel(-45.0, 2.3)))
    obs = mean + sigma * rng.standard_normal((steps,) + mean.shape)
    kw = dict(ref_power_bounds_dbm=None, path_loss_exp_bounds=None)
    printed = lb.calibrate_from_reference_tags(obs, tags, readers, **kw).sigma_db ** 2
    corrected = lb.calibrate_from_reference_tags(obs, tags, readers, sigma_ddof=6, **kw).sigma_db ** 2
    se = sigma**2 * np.sqrt(2 / 6) / np.sqrt(steps)          # sigma_hat^2 ~ sigma^2 chi2_6 / 6
    assert abs(corrected.mean() - sigma**2) < 4 * se
    assert abs(printed.mean() - sigma**2 / 2) < 4 * se / 2
    with pytest.raises(ValueError, match="degrees of freedom"):
        lb.pooled_sigma_db(np.zeros((4, 3)), ddof=12)


def test_channel_variance_components_match_the_model():
    # static field shared by visits of the same point, orientation per visit, dynamic per reading
    ch = replace(QUIET, static_sigma_db=4.0, orientation_sigma_db=1.5, dynamic_sigma_db=3.0)
    z, t = 3000, 6
    bed = tb.draw_testbed(ch, z, np.random.default_rng(1))
    a, b = (1.0, 1.0), (2.75, 1.0)                            # two fixed points 1.75 m apart
    positions = np.repeat(np.array([a, a, b])[:, None, :], t, axis=1)     # visits: a twice, then b
    target, tags = tb.measure_sessions(bed, positions, np.random.default_rng(2))
    resid = target - ch.mean_rss_dbm(positions.reshape(-1, 2)).reshape(3, t, 3)
    within = resid.var(axis=2, ddof=1).mean()
    assert within == pytest.approx(9.0, rel=0.03)                         # dynamic^2
    visit_mean = resid.mean(axis=2)                                       # (Z, 3 visits, m)
    cov = lambda u, v: np.mean((u - u.mean(0)) * (v - v.mean(0)))
    var_visit = 16.0 + 1.5**2 + 9.0 / t
    assert visit_mean[:, 0].var() == pytest.approx(var_visit, rel=0.05)
    assert cov(visit_mean[:, 0], visit_mean[:, 1]) == pytest.approx(16.0, rel=0.08)                 # same point
    assert cov(visit_mean[:, 0], visit_mean[:, 2]) == pytest.approx(16.0 * np.exp(-1.75 / 1.5), rel=0.15)
    tag_resid = tags - ch.mean_rss_dbm(oz.REFERENCE_TAGS_M)
    assert tag_resid.var() == pytest.approx(ch.total_sigma_db**2, rel=0.05)
    assert ch.total_sigma_db == pytest.approx(np.sqrt(16 + 2.25 + 9))


def test_bursts_hit_every_tag_of_a_reader_at_once():
    ch = replace(QUIET, burst_probability=0.5)
    bed = tb.draw_testbed(ch, 50, np.random.default_rng(4))
    positions = np.repeat(np.asarray(tb.FIXED_POINTS_M)[:, None, :], 4, axis=1)
    target, tags = tb.measure_sessions(bed, positions, np.random.default_rng(5))
    loss = target - ch.mean_rss_dbm(positions.reshape(-1, 2)).reshape(positions.shape[:2] + (3,))
    tag_loss = tags - ch.mean_rss_dbm(oz.REFERENCE_TAGS_M)
    np.testing.assert_allclose(tag_loss, np.broadcast_to(loss[..., None, :], tag_loss.shape), atol=1e-9)
    hit = loss < 0
    assert 0.45 < hit.mean() < 0.55
    assert np.all((loss[hit] <= -5.0) & (loss[hit] >= -10.0))


def test_noise_free_online_calibration_recovers_the_channel_and_absorbs_an_obstruction():
    bed = tb.draw_testbed(QUIET, 2, np.random.default_rng(0))
    positions = np.repeat(np.array([[4.5, 2.5]])[:, None, :], 3, axis=1)
    extra = np.array([[3.0, 0.0, 1.0], [0.0, 2.0, 0.0]])
    _, tags = tb.measure_sessions(bed, positions, np.random.default_rng(1), extra_loss_db=extra)
    cal = lb.calibrate_from_reference_tags(tags, oz.REFERENCE_TAGS_M, oz.TESTBED_READERS_M,
                                           walls_m=oz.TESTBED_WALLS_M, wall_attenuation_db=oz.WAF_DB)
    alpha = np.asarray(oz.OFFLINE_PARAMETERS["alpha_dbm"]) - extra                # still inside [-55, -40]
    np.testing.assert_allclose(cal.ref_power_dbm, np.broadcast_to(alpha[:, None, None], cal.ref_power_dbm.shape),
                               atol=1e-4)
    np.testing.assert_allclose(cal.path_loss_exp, np.broadcast_to(oz.OFFLINE_PARAMETERS["path_loss_exp"],
                                                                  cal.path_loss_exp.shape), atol=1e-5)
    np.testing.assert_allclose(cal.sigma_db, 0.0, atol=1e-4)
    # without noise the online map is the offline map, so online NN = offline NN
    res = tb.run_testbed(2, 7, channel=QUIET, experiments=["fixed"], methods=["offline_nn", "online_nn"], fixed_steps=2)
    np.testing.assert_allclose(res["fixed"].estimates["online_nn"], res["fixed"].estimates["offline_nn"], atol=1e-4)


def test_every_printed_cell_maps_to_a_method_the_experiment_runs():
    printed = [r for r in oz.printed_tables() if len(r["table"]) == 4 and "7.26" <= r["table"] <= "7.44"]
    # counted from Tables 7.26-7.44: 10+15+14+15+15+3+10+10+2+10+2+10+2+15+49 (7.40 lacks one std)+35+35+6+4
    assert len(tb.TABLE_CELLS) == len(printed) == 262
    for (table, row, column), (experiment, method, stat) in tb.TABLE_CELLS.items():
        base = "fixed" if experiment == "fixed_near_tags" else experiment
        assert method in tb.EXPERIMENTS[base], (table, row)
        assert stat == column
    assert tb.TABLE_CELLS[("7.40", "monopole / Grid Bayes", "rmse_m")] == ("monopole", "grid", "rmse_m")
    assert tb.TABLE_CELLS[("7.28", "Offline NN obstructed readers", "mean_m")] == ("obstructed", "offline_nn", "mean_m")


def test_every_ranking_is_what_its_table_prints():
    # each claim "better beats worse" names a table; both methods must have a printed cell of that statistic in
    # that table (found through the printed rows, not through the ranking code), and the printed value of the
    # worse method must exceed the better one's: a swapped pair, a wrong table or statistic fails here
    printed = {(r["table"], r["row"], r["column"]): r["value"] for r in oz.printed_tables()}
    assert len(tb.RANKINGS) == 27
    for where, better, worse, experiment, stat in tb.RANKINGS:
        assert better != worse and stat in tb.STATISTICS
        table, _, qualifier = where.removeprefix("Table ").partition(" ")
        # the label's qualifier names the experiment or, for "(90 %)", the statistic
        if qualifier == "(90 %)":
            assert stat == "p90_m", where
        elif qualifier:
            assert experiment == qualifier.strip("()"), where
        value = {}
        for method in (better, worse):
            cells = [key for key, cell in tb.TABLE_CELLS.items()
                     if key[0] == table and cell == (experiment, method, stat)]
            assert len(cells) == 1, (where, method, cells)
            value[method] = printed[cells[0]]
        assert value[worse] > value[better], (where, better, worse, value)


def test_ranking_rows_on_hand_made_errors():
    # per-realization errors constant over sessions and steps: every statistic but std equals that constant,
    # so the reproduced differences are known by hand
    from locbook.scenarios.ozkaya_testbed import ExperimentResult
    level = {"offline_nn": (2.0, 2.2), "online_nn": (1.5, 1.9), "grid": (1.2, 1.0), "grid_sigma": (1.1, 1.3),
             "grid_smoothing": (1.3, 1.3), "sir": (1.0, 1.4), "sir_sigma_smoothing": (0.9, 1.3)}     # 2 realizations
    res = ExperimentResult("mobile", np.zeros((1, 5, 2)))
    for method, (z0, z1) in level.items():
        res.errors[method] = np.stack([np.full((1, 5), z0), np.full((1, 5), z1)])             # (Z=2, S=1, T=5)
    rows = tb.ranking_rows({"mobile": res})
    expected = [r for r in tb.RANKINGS if r[3] == "mobile"]
    assert len(rows) == len(expected) == 7
    printed = {(r["table"], r["row"], r["column"]): r["value"] for r in oz.printed_tables()}
    for row, (where, better, worse, experiment, stat) in zip(rows, expected, strict=True):
        assert row["where"] == where and row["statistic"] == stat == "rmse_m"
        diff = np.subtract(level[worse], level[better])
        assert row["reproduced_difference_m"] == pytest.approx(diff.mean(), abs=1e-12)
        assert row["se_m"] == pytest.approx(abs(diff[0] - diff[1]) / 2, abs=1e-12)    # sd(ddof 1) / sqrt(2)
        assert row["holds"] == (diff.mean() > 0)
        table = where.split()[1]
        cell = lambda m: next(k for k, c in tb.TABLE_CELLS.items() if k[0] == table and c == (experiment, m, stat))
        assert row["printed_difference_m"] == pytest.approx(printed[cell(worse)] - printed[cell(better)], abs=1e-4)
    holds = {(r[1], r[2]): row["holds"] for r, row in zip(expected, rows)}
    assert holds[("sir", "grid")] is False and holds[("grid", "online_nn")] is True     # 1.1 - 1.2 < 0; 1.7 - 1.1 > 0


def test_near_tag_points_by_hand():
    mask = tb.near_tag_mask(np.array([[1.5, 2.9], [3.0, 3.0], [8.0, 1.0], [6.25, 1.0]]))
    # (1.5, 2.9): 0.64 m from T2; (3, 3): 1 m from T2; (8, 1): 3.5 m from T3; (6.25, 1): 1.82 m from T3
    assert mask.tolist() == [True, True, False, False]


def test_run_testbed_is_reproducible_and_subsets_do_not_change_numbers():
    settings = tb.MethodSettings(n_particles=200)
    kw = dict(settings=settings, fixed_steps=4, mobile_passes=2, pattern_samples=5)
    full = tb.run_testbed(2, 11, **kw)
    again = tb.run_testbed(2, 11, **kw)
    part = tb.run_testbed(2, 11, experiments=["mobile", "obstructed"], methods=["sir", "grid"], **kw)
    # the loops below must not run over empty collections
    assert set(full) == set(again) == set(tb.EXPERIMENTS) and set(part) == {"mobile", "obstructed"}
    for name, res in full.items():
        assert set(res.estimates) == set(res.errors) == set(tb.EXPERIMENTS[name])
        for key, est in res.estimates.items():
            np.testing.assert_array_equal(est, again[name].estimates[key])
    for name in ("mobile", "obstructed"):
        assert set(part[name].estimates) == {"sir", "grid"} & set(tb.EXPERIMENTS[name])
        for key, est in part[name].estimates.items():
            np.testing.assert_array_equal(est, full[name].estimates[key])
    rows = tb.table_rows(full)
    assert {r["table"] for r in rows} == {t for t, _, _ in tb.TABLE_CELLS}
    assert all(np.isfinite(r["reproduced"]) and r["spread_m"] > 0 for r in rows)
    # every row recomputed from the estimates: Euclidean error, the statistic per realization (near-tag
    # rows keep the fixed points within 1.5 m of a tag, by distance), their mean, sd and sd / sqrt(Z)
    printed = {(r["table"], r["row"], r["column"]): r["printed"] for r in oz.printed_tables()}
    tags = np.asarray(oz.REFERENCE_TAGS_M)
    points = np.asarray(tb.FIXED_POINTS_M)
    near = np.min(np.linalg.norm(points[:, None] - tags[None], axis=-1), axis=1) <= tb.NEAR_TAG_RADIUS_M
    assert 0 < near.sum() < near.size
    stat = {"rmse_m": lambda e: np.sqrt(np.mean(e**2, 1)), "mean_m": lambda e: e.mean(1),
            "median_m": lambda e: np.median(e, 1), "p90_m": lambda e: np.quantile(e, 0.9, axis=1),
            "std_m": lambda e: np.sqrt(np.mean((e - e.mean(1, keepdims=True)) ** 2, 1))}
    assert len(rows) == len(tb.TABLE_CELLS)
    for r in rows:
        base = "fixed" if r["experiment"] == "fixed_near_tags" else r["experiment"]
        res = full[base]
        err = np.linalg.norm(res.estimates[r["method"]] - res.truth_m, axis=-1)               # (Z, S, T)
        if r["experiment"] == "fixed_near_tags":
            err = err[:, near]
        values = stat[r["column"]](err.reshape(err.shape[0], -1))
        spread = np.std(values, ddof=1)
        assert r["printed"] == printed[(r["table"], r["row"], r["column"])]
        assert r["reproduced"] == pytest.approx(values.mean(), rel=1e-12, abs=1e-12)
        assert r["spread_m"] == pytest.approx(spread, rel=1e-9)
        assert r["mc_se_m"] == pytest.approx(spread / np.sqrt(values.size), rel=1e-9)
        assert tb.testbed_ambiguity(r["per_testbed"]).size == pytest.approx(2 * spread, rel=1e-9)
    with pytest.raises(ValueError, match="unknown experiments"):
        tb.run_testbed(1, 0, experiments=["fixd"])


def test_printed_inputs_are_read_from_the_printed_file():
    # the printed-values file itself (not the scenario's constants): Sec. 7.3.2.6's 7.5 dB over Table 6.2's 5.3 dB,
    # Sec. 7.3.1.3's sigma = 5.2 and CRLB = 0.76
    P = lb.printed("ozkaya2011")
    mono = P.get("Sec. 7.3.2.6 text", "monopole reader antennas", "auto_calibrated_sigma_db")
    patch = P.get("Table 6.2", "all readers (pooled)", "sigma_db")
    assert (mono.text, patch.text) == ("7.5", "5.3")
    assert tb.MONOPOLE_NOISE_SCALE == pytest.approx(mono.value / patch.value, rel=1e-15)
    assert mono.text in tb.MONOPOLE_CALIBRATED_FROM and patch.text in tb.MONOPOLE_CALIBRATED_FROM
    assert tb.MethodSettings().sigma_db == P.get("Sec. 7.3.1.3 text", "test bed methods", "sigma_db").value == 5.2
    assert tb.TESTBED_CRLB_PRINTED.text == "0.76"
    assert tb.run_testbed.__kwdefaults__["monopole_noise_scale"] == tb.MONOPOLE_NOISE_SCALE


def _printed_form_bounds(points, n, sigma):
    """The printed-form bound (1/d^2 Fisher information, Ozkaya A.10-A.12) written out by hand; ``n`` one per reader."""
    readers = np.asarray(oz.TESTBED_READERS_M)
    b = (10 * np.asarray(n, float) / (sigma * np.log(10))) ** 2 * np.ones(len(readers))
    bounds = []
    for p in points:
        diff = p - readers
        d2 = np.sum(diff**2, -1)
        fxx = np.sum(b * diff[:, 0] ** 2 / d2)          # printed form: d^2 where d^4 belongs (Eqs. (A.10)-(A.12))
        fyy = np.sum(b * diff[:, 1] ** 2 / d2)
        fxy = np.sum(b * diff[:, 0] * diff[:, 1] / d2)
        bounds.append(np.sqrt((fxx + fyy) / (fxx * fyy - fxy**2)))
    return np.array(bounds)


def test_testbed_crlb_fitted_form_is_the_printed_form_bound_averaged_over_the_cells():
    cells = np.asarray(tb.TESTBED_CELLS_M)
    assert cells.shape == (36, 2)
    bounds = _printed_form_bounds(cells, 2.0, tb.TESTBED_SIGMA_DB)
    assert tb.testbed_crlb_m(2.0, average="cells_mean") == pytest.approx(np.mean(bounds), rel=1e-9)
    # the correct bound (1/d^4) is larger than the printed form wherever every reader is more than 1 m away
    assert tb.testbed_crlb_m(np.asarray(oz.OFFLINE_PARAMETERS["path_loss_exp"]), variant="corrected") > \
        tb.testbed_crlb_m(2.0, average="cells_mean")


def test_testbed_crlb_default_is_the_rms_over_the_area_with_table_6_1_exponents():
    """The default bound is that of 'the experimented system setup' (Table 6.1's n per reader) as the RMS
    over the area (Appendix A compares it with RMS errors), not the readings fitted to the simulation columns."""
    assert tb.TESTBED_CRLB_PATH_LOSS_EXP == tuple(lb.printed("ozkaya2011").get("Table 6.1", f"Reader {j}",
                                                                               "path_loss_exp").value
                                                  for j in (1, 2, 3))
    step = 0.05
    xs, ys = np.arange(step / 2, 9.0, step), np.arange(step / 2, 4.0, step)
    points = np.stack(np.meshgrid(xs, ys, indexing="ij"), -1).reshape(-1, 2)
    bounds = _printed_form_bounds(points, tb.TESTBED_CRLB_PATH_LOSS_EXP, tb.TESTBED_SIGMA_DB)
    assert tb.testbed_crlb_m() == pytest.approx(np.sqrt(np.mean(bounds**2)), rel=1e-9)
    with pytest.raises(ValueError, match="average"):
        tb.testbed_crlb_m(average="median")


def test_first_printings_follow_the_thesis_order():
    P = lb.printed("ozkaya2011")
    for (table, row, column), cell in tb.TABLE_CELLS.items():
        first = tb.first_printing(*cell)
        me = P.get(f"Table {table}", row, column)
        # the first printing is this cell or one in an earlier table of the same experiment, method and statistic
        assert first.location <= me.location
        key = (first.location.removeprefix("Table "), first.item, first.statistic)
        assert tb.TABLE_CELLS[key] == cell
    # the thesis's own cross-references: the summary tables repeat Tables 7.26-7.40 ...
    assert tb.first_printing(*tb.TABLE_CELLS[("7.41", "Pattern-based NN", "rmse_m")]).location == "Table 7.26"
    assert tb.first_printing(*tb.TABLE_CELLS[("7.41", "Grid Bayes", "rmse_m")]).location == "Table 7.29"
    assert tb.first_printing(*tb.TABLE_CELLS[("7.43", "Offline NN", "std_m")]).location == "Table 7.28"
    assert tb.first_printing(*tb.TABLE_CELLS[("7.40", "patch / Grid Bayes", "rmse_m")]).location == "Table 7.30"
    # ... except the offline-NN mobile row, printed only in Table 7.42
    offline_mobile = tb.TABLE_CELLS[("7.42", "Parameter-based offline NN", "rmse_m")]
    assert tb.first_printing(*offline_mobile).location == "Table 7.42"
    # every cell of Table 7.41 (all methods, fixed target) was printed before
    assert all(tb.first_printing(*c).location < "Table 7.41" for k, c in tb.TABLE_CELLS.items() if k[0] == "7.41")


def _hand_made_results(levels: dict, experiments=("fixed", "mobile", "monopole")):
    """Results whose per-test-bed statistics are known by hand: errors constant within a test bed (so rmse = mean =
    median = p90 = that constant, std = 0), one constant per test bed."""
    res = {}
    for name in experiments:
        r = tb.ExperimentResult(name, np.zeros((25, 2, 2)))
        for method in tb.EXPERIMENTS[name]:
            r.errors[method] = np.stack([np.full((25, 2), v) for v in levels[method]])        # (Z, S, T)
        res[name] = r
    return res


@pytest.mark.slow
def test_recorded_rows_have_kinds_links_windows_and_notes(tmp_path, monkeypatch):
    monkeypatch.setenv("LOCBOOK_OUTPUT_DIR", str(tmp_path))
    monkeypatch.setenv("LOCBOOK_EXPERIMENT", "ozkaya2011-testbed")
    report = lb.Report()
    levels = {m: (1.2, 1.5, 1.8) for m in tb.METHODS}                 # Z = 3: mean 1.5, sd 0.3
    rows = tb.table_rows(_hand_made_results(levels))
    recorded = tb.record_table_rows(report, rows)
    assert len(recorded) == len(rows) > 0
    judged = [n["printed_id"] for n in recorded if n["verdict"]]
    assert len(judged) == len(set(judged))                           # each printed quantity judged once
    ids = set(judged)
    for r, n in zip(rows, recorded, strict=True):
        assert n["printed"] == r["printed"].text
        # the monopole scale is the text's own explanation (Sec. 7.3.2.6): reproductions by default
        assert n["kind"] == "reproduction" and not n["calibrated_from"]
        if r["first_printed"].id != r["printed"].id:
            assert n["same_as"] == r["first_printed"].id and n["same_as"] in ids and n["verdict"] == ""
            continue
        assert not n["same_as"]
        # window: rounding + 2 sd / sqrt(3) + 2 sd with sd = 0.3 (std rows: every test bed 0, window = rounding)
        sd = 0.0 if r["column"] == "std_m" else 0.3
        half = r["printed"].rounding + 2 * sd / np.sqrt(3) + 2 * sd
        assert n["window_high"] == pytest.approx(r["printed"].value + half, rel=1e-9)
        assert n["ambiguity"] == pytest.approx(2 * sd, abs=1e-12)
        assert n["ambiguity_basis"].startswith(tb.TESTBED_AMBIGUITY_WHAT)
        if n["verdict"] in ("miss", "loose"):
            assert n["note"].strip()
        if n["verdict"] == "within":
            assert half <= 0.25 * r["printed"].value
    # the window is wide (about 0.9 m): most statistics near 1.5 m are loose, none of them "within"
    assert any(n["verdict"] == "loose" for n in recorded)
    # a monopole scale named as calibrated from a fit makes its rows calibrated
    again = tb.record_table_rows(report, [r for r in rows if r["experiment"] == "monopole"],
                                 monopole_calibrated_from="x")
    assert again and all(n["kind"] == "calibrated" and n["calibrated_from"] == "x" for n in again)


def test_a_repeat_printed_with_another_text_is_compared_and_says_so(tmp_path, monkeypatch):
    monkeypatch.setenv("LOCBOOK_OUTPUT_DIR", str(tmp_path))
    report = lb.Report()
    rows = tb.table_rows(_hand_made_results({m: (1.2, 1.5, 1.8) for m in tb.METHODS}, ("fixed",)))
    first = next(r for r in rows if r["first_printed"].id != r["printed"].id)
    altered = replace(first["printed"], text=first["printed"].text + "1")       # a different printed text
    (n,) = tb.record_table_rows(report, [{**first, "printed": altered}])
    assert n["verdict"] and not n["same_as"]
    assert first["first_printed"].where in n["note"] and "both printed values are compared" in n["note"]


@pytest.mark.parametrize("old, new", [("correct", "corrected"), ("ozkaya_printed", "literal_ozkaya2011")])
def test_testbed_crlb_old_form_keyword_warns_at_the_caller_and_gives_the_same_number(old, new):
    """``form=`` (the earlier keyword) is ``variant=`` for one release, its values mapped."""
    with pytest.warns(DeprecationWarning, match=fr"testbed_crlb_m\(form='{old}'\) is deprecated: use "
                                                fr"testbed_crlb_m\(variant='{new}'\)") as caught:
        got = tb.testbed_crlb_m(2.0, form=old, average="cells_mean")
    assert len(caught) == 1 and caught[0].filename == __file__
    assert got == tb.testbed_crlb_m(2.0, variant=new, average="cells_mean")
