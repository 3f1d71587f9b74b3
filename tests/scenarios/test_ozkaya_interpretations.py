"""The Ozkaya (2011) simulation readings (locbook/data/readings/ozkaya2011.csv) as library options: each alternative
checked against what it means (an independent computation or an invariant). Every default is the reading the
text supports best (the readings file quotes it); only the values no text supports and that were chosen because they fit
(the CRLB columns' n = 2 and mean over the cells) are ``fitted``, and only rows computed under them are calibrated."""
from dataclasses import replace

import numpy as np
import pytest

import locbook as lb
from locbook.errors import ParameterError
from locbook.reproduce.interpretations import interpretations
from locbook.scenarios import ozkaya as oz
from locbook.scenarios import ozkaya_simulation as ozs


@pytest.fixture
def per_step():
    """Hand-built per-step errors (runs x recursions), skewed like filter errors, with distinct runs."""
    rng = np.random.default_rng(11)
    return rng.gamma(2.0, 0.5, size=(40, 6)) + np.linspace(1.0, 0.0, 6)


def test_default_convention_equals_the_last_recursion_vector(per_step):
    """Passing the per-step errors under the defaults is the old one-error-per-run summary, standard errors too."""
    a = oz.summarize(per_step, np.random.default_rng(3))
    b = oz.summarize(per_step[:, -1].copy(), np.random.default_rng(3))
    assert a == b
    assert a["p90_m"] == np.percentile(per_step[:, -1], 90) and a["median_m"] == np.median(per_step[:, -1])


def _numpy_statistics(sample):
    """Sec. 7.2.1's five statistics of one sample of errors, by numpy alone."""
    return {"rmse_m": np.sqrt(np.mean(sample**2)), "mean_m": np.mean(sample), "median_m": np.median(sample),
            "p90_m": np.percentile(sample, 90), "std_m": np.std(sample)}


def test_all_five_statistics_come_from_one_population_under_each_protocol(per_step):
    """The text computes every statistic 'from total estimation error data'. The fixture's recursions
    differ (the error falls by 1 m over the run), so the errors at rt and those of every recursion give different
    statistics: each protocol must take all five from its own sample."""
    at_rt, every = per_step[:, -1], per_step.ravel()
    assert abs(np.median(at_rt) - np.median(every)) > 0.2 and abs(np.mean(at_rt) - np.mean(every)) > 0.2
    for over, sample in ((False, at_rt), (True, every)):
        got = oz.summarize(per_step, np.random.default_rng(2), over_recursions=over)
        want = _numpy_statistics(sample)
        for k, v in want.items():
            assert got[k] == pytest.approx(v, rel=1e-12), (over, k)


def test_the_per_run_percentile_conventions_use_the_same_recursions(per_step):
    run_rmse = np.sqrt((per_step**2).mean(axis=1))
    got = oz.summarize(per_step, percentile_convention="over_run_rmses", over_recursions=True)
    assert got["median_m"] == pytest.approx(np.percentile(run_rmse, 50), rel=1e-12)
    assert got["p90_m"] == pytest.approx(np.percentile(run_rmse, 90), rel=1e-12)
    assert got["rmse_m"] == pytest.approx(np.sqrt(np.mean(per_step**2)), rel=1e-12)
    averaged = oz.summarize(per_step, percentile_convention="per_run_then_averaged", over_recursions=True)
    assert averaged["median_m"] == pytest.approx(np.mean(np.median(per_step, axis=1)), rel=1e-12)
    assert averaged["p90_m"] == pytest.approx(np.mean(np.percentile(per_step, 90, axis=1)), rel=1e-12)
    # at recursion rt alone a run has one error: its RMSE is that error (the pooled percentiles), its percentile too
    # (the averaged percentiles are the mean error)
    at_rt = oz.summarize(per_step, percentile_convention="over_run_rmses")
    assert at_rt["p90_m"] == pytest.approx(np.percentile(per_step[:, -1], 90), rel=1e-12)
    one = oz.summarize(per_step, percentile_convention="per_run_then_averaged")
    assert one["median_m"] == pytest.approx(one["mean_m"]) and one["p90_m"] == pytest.approx(one["mean_m"])
    assert one["rmse_m"] == pytest.approx(np.sqrt(np.mean(per_step[:, -1] ** 2)), rel=1e-12)


def test_mean_over_recursions_takes_rmse_mean_and_std_over_every_recursion(per_step):
    got = oz.summarize(per_step, np.random.default_rng(1), over_recursions=True)
    assert got["rmse_m"] == pytest.approx(np.sqrt(np.mean(per_step**2)), rel=1e-12)
    assert got["mean_m"] == pytest.approx(per_step.mean(), rel=1e-12)
    assert got["std_m"] == pytest.approx(per_step.std(), rel=1e-12)
    # its RMSE standard error is the delta method over the runs' mean squares (runs independent, steps not)
    ms = (per_step**2).mean(axis=1)
    assert got["rmse_m_se"] == pytest.approx(ms.std(ddof=1) / np.sqrt(40) / (2 * np.sqrt(ms.mean())), rel=1e-12)
    assert all(got[k + "_se"] > 0 for k in oz.STATISTICS)


def test_unknown_readings_are_refused_naming_them():
    with pytest.raises(ParameterError, match="percentile_convention"):
        oz.summarize(np.ones(5), percentile_convention="pooled_last_recursion")
    with pytest.raises(ParameterError, match="no_such_reading"):
        oz.sim_interpretations(no_such_reading="x")
    with pytest.raises(ParameterError, match="reader_noise"):
        oz.simulate_truth_and_rss(oz.SimCase("nn", reader_noise="shared"), 3, np.random.default_rng(0))


def test_common_mode_noise_leaves_the_reader_differences_noise_free():
    """Sec. 7.2.1's noise on the transmit power: one draw shared by every reader, so the differences between
    readers are those of the mean RSSI, while each reader's own noise still has sigma_0."""
    case = oz.SimCase("grid", "mobile", sigma0_db=5.2, rt=4, reader_noise="common_mode")
    truth, rss = oz.simulate_truth_and_rss(case, 4000, np.random.default_rng(2))
    mean = lb.RssModel(oz.readers_for("corners3"), lb.PathLossModel(oz.ALPHA_DBM, oz.PATH_LOSS_EXP,
                                                                    min_distance_m=0.1)).mean_rss_dbm(truth)
    noise = rss - mean
    np.testing.assert_allclose(np.diff(noise, axis=-1), 0.0, atol=1e-9)
    assert np.std(noise[..., 0]) == pytest.approx(5.2, rel=0.03)
    # the targets are those of the independent-noise reading (the same stream: the truth is drawn first)
    truth_iid, _ = oz.simulate_truth_and_rss(replace(case, reader_noise="independent_per_reader"), 4000,
                                             np.random.default_rng(2))
    np.testing.assert_array_equal(truth, truth_iid)


def test_fixed_target_noise_frozen_or_fresh():
    frozen = oz.SimCase("grid", "fixed", rt=5, fixed_target_noise="frozen_per_run")
    _, rss = oz.simulate_truth_and_rss(frozen, 50, np.random.default_rng(4))
    assert np.all(rss == rss[:, :1])                                     # the same vector at every recursion
    truth, rss = oz.simulate_truth_and_rss(replace(frozen, fixed_target_noise="fresh_per_step"), 50,
                                           np.random.default_rng(4))
    assert np.all(truth == truth[:, :1])                                 # still a fixed target
    assert not np.any(rss[:, 1:] == rss[:, :1])                          # a new noise draw each recursion


def test_cell_cores_sampling_stays_in_the_area_the_cells_tile():
    case = oz.with_interpretations(oz.SimCase("nn"), {"target_sampling": "cell_cores"})
    truth, _ = oz.simulate_truth_and_rss(case, 5000, np.random.default_rng(5))
    xy = truth[:, 0]
    cells = oz.cell_centres(oz.ROOM_M, 4, 7)
    half = np.array([(oz.ROOM_M[0] - 1) / 8, (oz.ROOM_M[1] - 1) / 14])      # half a cell's sides
    assert np.all(xy >= cells.min(0) - half) and np.all(xy <= cells.max(0) + half)
    assert np.allclose(xy.min(0), 0.5, atol=0.01) and np.allclose(xy.max(0), np.array(oz.ROOM_M) - 0.5, atol=0.01)
    # a region the thesis prints for a row (Table 7.22: 1 m from the walls) is kept under any sampling
    assert oz.with_interpretations(oz.SimCase("sir", target_region="inner"), {"target_sampling": "cell_cores"}) \
        .target_region == "inner"


def test_uniform_nn_weights_over_every_cell_give_the_cells_centroid():
    """With k = every cell and plain averaging, the estimate is the centroid of the 28 cells whatever the RSSI, so
    the error is the distance from the target to (2.5, 4)."""
    case = oz.with_interpretations(oz.SimCase("nn", k_nn=28), {"nn_weights": "uniform"})
    last, _, truth, estimate = oz.run_case(case, 30, 7, return_all=True)
    np.testing.assert_allclose(estimate[:, 0], np.broadcast_to([2.5, 4.0], (30, 2)), atol=1e-12)
    np.testing.assert_allclose(last, np.linalg.norm(truth[:, 0] - [2.5, 4.0], axis=-1), atol=1e-12)
    # the corrected weights put more weight on the near cells: not the centroid
    default = oz.run_case(oz.SimCase("nn", k_nn=28), 30, 7, return_all=True)[3]
    assert np.abs(default[:, 0] - [2.5, 4.0]).max() > 0.1


def test_absolute_resample_threshold_never_resamples():
    """Table 7.24's N_eff < 0.5 read literally: N_eff >= 1 always, so the filter never resamples, while 0.5 N does."""
    base = oz.SimCase("sir", "mobile", resample_threshold=0.5, n_particles=200, rt=6)
    absolute = replace(base, resample_threshold_unit="absolute")
    assert oz.resample_fraction(base) == 0.5
    assert oz.resample_fraction(absolute) * absolute.n_particles == pytest.approx(0.5)
    assert oz.resample_fraction(replace(absolute, resample_threshold=None)) is None
    truth, rss = oz.simulate_truth_and_rss(base, 20, np.random.default_rng(8))
    model = lb.RssModel(oz.readers_for("corners3"), lb.PathLossModel(oz.ALPHA_DBM, oz.PATH_LOSS_EXP, oz.SIGMA_DB,
                                                                     min_distance_m=0.1))
    region = (np.zeros(2), np.array(oz.ROOM_M))
    results = {c.resample_threshold_unit: lb.particle_filter(rss, model, rng=np.random.default_rng(9), n_particles=200,
                                                             region_m=region,
                                                             resample_threshold=oz.resample_fraction(c))
               for c in (base, absolute)}
    assert results["fraction_of_n"].resampled.any() and not results["absolute"].resampled.any()
    assert np.all(results["absolute"].n_eff >= 1 - 1e-9)


def test_run_tables_defaults_equal_explicit_default_readings():
    a = oz.run_tables(["7.2"], 30, 3)
    b = oz.run_tables(["7.2"], 30, 3, interpretations=oz.sim_interpretations())
    assert [r["reproduced"] for r in a] == [r["reproduced"] for r in b]
    c = oz.run_tables(["7.2"], 30, 3, interpretations={"reader_noise": "common_mode"})
    assert [r["reproduced"] for r in a if r["column"] == "rmse_m"] != \
        [r["reproduced"] for r in c if r["column"] == "rmse_m"]


def test_every_simulation_reading_is_declared_with_the_librarys_values():
    declared = {r.name: r for r in interpretations("ozkaya2011")}
    for name, values in oz.SIM_INTERPRETATIONS.items():
        r = declared[name]
        # every declared value is one the library knows; library options the text does not support (the per-run
        # percentile conventions, 1 m in from the walls outside Table 7.22) are not declared
        assert r.parameter == name and r.default == values[0] and set(r.values) <= set(values)
        assert set(r.values) == set(values) or name in ("percentile_convention", "target_sampling")
    assert declared["percentile_convention"].values == ("pooled",)
    assert declared["target_sampling"].values == ("room", "cell_cores")
    assert set(declared["crlb_average"].values) == {"cells_mean", "area_rms"}


# -- the rule for a reading's basis ----------------------------------------------------------------------
def test_no_default_is_fitted_and_fitted_values_are_the_library_s():
    declared = {r.name: r for r in interpretations("ozkaya2011")}
    assert not any(r.is_calibration for r in declared.values())           # no default may be fitted
    fitted = {(r.name, v) for r in declared.values() for v in r.fitted}
    assert fitted == {(n, v) for n, v in oz.FITTED_VALUES.items()} | {("testbed_crlb_exponent", 2.0),
                                                                      ("testbed_crlb_average", "cells_mean")}
    for name, value in oz.FITTED_VALUES.items():
        assert value in declared[name].alternatives and declared[name].alternative_basis(value) == "fitted"
    # the three re-judged simulation readings: textual defaults with a textual alternative, none fitted
    for name, default, other in (("reader_noise", "independent_per_reader", "common_mode"),
                                 ("fixed_target_noise", "frozen_per_run", "fresh_per_step"),
                                 ("mobile_protocol", "reflect_error_at_rt", "mean_over_recursions")):
        r = declared[name]
        assert (r.default, r.basis, r.alternatives, r.fitted) == (default, "textual", (other,), ())
        assert r.alternative_basis(other) == "textual" and name not in oz.FITTED_VALUES


def test_the_quotes_are_the_thesis_s_words_at_the_lines_they_name():
    """Each quoted passage of the re-judged readings is in the thesis text at the line given (the words checked here
    are copied from the thesis, Secs. 7.2.1-7.2.2.3 and Appendix A)."""
    declared = {r.name: r for r in interpretations("ozkaya2011")}
    for name, line, words in (
            ("reader_noise", 1137, "zero mean Gaussian noise added"),
            ("reader_noise", 1309, "added on the transmit power"),
            ("fixed_target_noise", 1323, "worst case scenario"), ("fixed_target_noise", 1415, "drastically increases"),
            ("fixed_target_noise", 1543, "if the measurement is erroneous"),
            ("mobile_protocol", 1373, "wait for a sufficient recursion time for the filter to settle"),
            ("mobile_protocol", 1137, "estimation will be done for every step if the target is mobile"),
            ("crlb_average", 2286, "Square root of (A.13) is used in the thesis to compare with RMS error")):
        quotes = declared[name].quotes
        assert f"line {line}" in quotes and words in quotes, (name, line)


def test_library_defaults_equal_the_declared_defaults():
    """Every Ozkaya reading the library holds has the readings CSV's default: the simulation readings (their first
    value, sim_interpretations(), the SimCase fields they set), the CRLB readings (thesis_crlb_m's defaults) and the
    record_crlb defaults."""
    import inspect
    declared = {r.name: r for r in interpretations("ozkaya2011")}
    defaults = oz.sim_interpretations()
    for name, values in oz.SIM_INTERPRETATIONS.items():
        assert values[0] == defaults[name] == declared[name].default, name
    case = oz.SimCase("grid")
    assert case.reader_noise == declared["reader_noise"].default
    assert case.fixed_target_noise == declared["fixed_target_noise"].default
    assert case.nn_weights == declared["nn_weights"].default
    assert case.resample_threshold_unit == declared["resample_threshold"].default
    assert case.target_region == declared["target_sampling"].default
    assert case.wall_handling == declared["wall_handling"].default
    assert case.initial_location == declared["known_initial_location"].default
    for function in (oz.thesis_crlb_m, oz.record_crlb):
        params = inspect.signature(function).parameters
        assert params["path_loss_exp"].default == declared["crlb_exponent"].default
        assert params["average"].default == declared["crlb_average"].default
    assert inspect.signature(oz.record_crlb).parameters["half_separation_layout"].default == \
        declared["half_separation_layout"].default
    assert declared["crlb_exponent"].default == oz.PATH_LOSS_EXP          # the simulations' n of Sec. 7.2.1
    assert oz.fitted_interpretations(defaults) == ()
    # under the defaults a mobile run's statistics are those of recursion rt (run_summary passes no over_recursions)
    mobile = oz.SimCase("grid", "mobile", rt=4)
    last, per_step, _, _ = oz.run_case(mobile, 20, 3, return_all=True)
    assert oz.run_summary(mobile, 20, 3)["rmse_m"] == pytest.approx(np.sqrt(np.mean(last**2)), rel=1e-12)
    pooled = oz.run_summary(mobile, 20, 3, {"mobile_protocol": "mean_over_recursions"})
    assert pooled["rmse_m"] == pytest.approx(np.sqrt(np.mean(per_step**2)), rel=1e-12)


def test_no_simulation_reading_makes_a_row_calibrated():
    every = [dict(zip(oz.SIM_INTERPRETATIONS, values)) for values in
             [tuple(v[i % len(v)] for v in oz.SIM_INTERPRETATIONS.values()) for i in range(3)]]
    for chosen in every:
        for case in (oz.SimCase("nn"), oz.SimCase("grid", "fixed"), oz.SimCase("sir", "mobile")):
            assert oz.fitted_interpretations(chosen, case) == () and oz.fitted_calibrated_from(chosen, case) == ""
    assert oz.fitted_interpretations({"crlb_exponent": 2.0, "crlb_average": "area_rms"}) == ("crlb_exponent",)
    assert "crlb_average = 'cells_mean'" in oz.fitted_calibrated_from({"crlb_average": "cells_mean"})


def test_the_readings_a_miss_note_names_are_those_that_can_move_the_case():
    text = oz.sim_interpretations()
    assert oz.unfitted_interpretations(text, oz.SimCase("nn")) == ("reader_noise",)   # one shot, no recursions
    assert oz.unfitted_interpretations(text, oz.SimCase("grid", "fixed")) == ("reader_noise", "fixed_target_noise")
    assert oz.unfitted_interpretations(text, oz.SimCase("sir", "mobile")) == ("reader_noise", "mobile_protocol")
    assert oz.unfitted_interpretations(text, oz.SimCase("grid", "fixed", sigma0_db=0.0)) == ()   # no noise to read


def test_text_reading_note_names_the_readings_the_side_and_the_bracket():
    text = oz.sim_interpretations()
    note = oz.text_interpretation_note(text, oz.SimCase("nn"), "ozkaya2011-nn-sim", 1.5, 1.95)
    assert note.startswith("under the interpretations run (noise independent per reader) ours is below")
    assert ("the other textual interpretation (common-mode noise on the transmit power) is an alternative: "
            "locbook bracket ozkaya2011-nn-sim runs it") in note
    both = oz.text_interpretation_note(text, oz.SimCase("sir", "mobile"), "ozkaya2011-sir-sim", 1.3, 1.14)
    assert "ours is above" in both and "at recursion rt" in both and "over every recursion" in both
    assert "other textual interpretations" in both and "are alternatives" in both and "runs them" in both
    # under the alternative the default is named as the other reading; nothing to say where no reading moves the case
    alt = oz.text_interpretation_note({**text, "reader_noise": "common_mode"}, oz.SimCase("nn"), "x", 1.0, 2.0)
    assert "(common-mode noise on the transmit power) ours" in alt and "(noise independent per reader) is" in alt
    assert oz.text_interpretation_note(text, oz.SimCase("grid", "fixed", sigma0_db=0.0), "x", 1.0, 2.0) == ""


def test_rows_under_the_default_readings_are_reproductions_and_misses_name_the_alternative(tmp_path, monkeypatch):
    monkeypatch.setenv("LOCBOOK_OUTPUT_DIR", str(tmp_path))
    monkeypatch.setenv("LOCBOOK_EXPERIMENT", "ozkaya2011-nn-sim")
    report = lb.Report()
    rows = oz.run_tables(["7.2", "7.3"], 60, 5, interpretations={"reader_noise": "common_mode"})
    oz.record_tables(report, rows, 60)
    assert report.numbers and all(r["kind"] == "reproduction" and not r["calibrated_from"] for r in report.numbers)
    misses = [r for r in report.numbers if r["verdict"] in ("miss", "loose")]
    assert misses and all("locbook bracket ozkaya2011-nn-sim" in r["note"] for r in misses)


# -- the readings declared with a basis -------------------------------------------------------------------------
def test_frozen_noise_cannot_be_averaged_away_while_fresh_noise_can():
    """Without noise the grid filter settles on a fixed target; with the noise frozen per run its error stays that of
    one noisy measurement, larger than under fresh noise, which the recursions average (the invariant that makes the
    fixed target 'a worst case scenario' under the default)."""
    base = oz.SimCase("grid", "fixed", rt=12)
    frozen = oz.summarize(oz.run_case(base, 300, 2))["rmse_m"]
    fresh = oz.summarize(oz.run_case(replace(base, fixed_target_noise="fresh_per_step"), 300, 2))["rmse_m"]
    assert frozen > fresh


@pytest.mark.parametrize("handling", oz.WALL_HANDLINGS)
def test_every_wall_handling_keeps_a_mobile_target_in_the_room(handling):
    case = oz.SimCase("grid", "mobile", rt=30, motion_m=2.0, wall_handling=handling)
    truth, _ = oz.simulate_truth_and_rss(case, 200, np.random.default_rng(6))
    assert np.all(truth >= 0.0) and np.all(truth <= np.array(oz.ROOM_M))
    steps = np.linalg.norm(np.diff(truth, axis=1), axis=-1)
    if handling == "clip":                                   # a clipped step ends on a wall
        on_wall = np.any(np.isclose(truth[:, 1:], 0.0) | np.isclose(truth[:, 1:], np.array(oz.ROOM_M)), axis=-1)
        assert on_wall.any()
    if handling == "redraw":                                 # steps are drawn whole: never shortened by a wall
        assert steps.max() > 2.0
    # every handling starts from the same uniform draws
    ref, _ = oz.simulate_truth_and_rss(replace(case, wall_handling="reflect"), 200, np.random.default_rng(6))
    np.testing.assert_array_equal(truth[:, 0], ref[:, 0])


def test_clip_stops_a_step_at_the_wall_it_crosses():
    lo, hi = np.zeros(2), np.array([5.0, 8.0])
    case = oz.SimCase("grid", "mobile", wall_handling="clip")
    got = ozs._step_inside(np.array([[4.5, 1.0]]), np.array([[1.0, -2.0]]), lo, hi, case, np.random.default_rng(0))
    np.testing.assert_allclose(got, [[5.0, 0.0]])
    reflected = ozs._step_inside(np.array([[4.5, 1.0]]), np.array([[1.0, -2.0]]), lo, hi,
                                replace(case, wall_handling="reflect"), np.random.default_rng(0))
    np.testing.assert_allclose(reflected, [[4.5, 1.0]])      # 5.5 -> 4.5 and -1 -> 1: mirrored at both walls


def test_half_separation_layouts_have_the_printed_separations_inside_the_room():
    """Table 7.5: separations of 2.5 m and 4 m (Sec. 7.2.2.1 E), readers toward the room's inner region."""
    for reading, key in oz.HALF_SEPARATION_LAYOUTS.items():
        r = oz.readers_for(key)
        assert sorted(np.round([np.linalg.norm(r[1] - r[0]), np.linalg.norm(r[2] - r[0])], 12)) == [2.5, 4.0]
        assert np.all(r > 0) and np.all(r < np.array(oz.ROOM_M))
    np.testing.assert_allclose(oz.readers_for("half3"), (oz.readers_for("corners3") - [2.5, 4.0]) / 2 + [2.5, 4.0])
    np.testing.assert_allclose(oz.readers_for("half3_centroid").mean(0), [2.5, 4.0])
    case = oz.with_interpretations(oz.SimCase("nn", layout="half3"), {"half_separation_layout": "centroid_at_centre"})
    assert case.layout == "half3_centroid"
    centred = oz.with_interpretations(oz.SimCase("nn"), {"half_separation_layout": "centroid_at_centre"})
    assert centred.layout == "corners3"


def test_the_large_room_readers_are_its_corners_with_twice_the_separations():
    for m in (3, 4):
        r = oz.readers_for(f"large{m}")
        np.testing.assert_allclose(r, 2 * oz.readers_for(f"corners{m}"))
    assert oz.cell_centres(oz.LARGE_ROOM_M, *oz.CELL_PATTERNS[135]).shape == (135, 2)


def test_a_known_initial_location_is_exact_or_spread_by_d():
    case = oz.SimCase("grid", "mobile", rt=1, known_initial=True)
    truth, rss = oz.simulate_truth_and_rss(case, 5, np.random.default_rng(3))
    assert ozs._initial_sd_m(case) == 0.0 and ozs._initial_sd_m(replace(case, known_initial=False)) == 0.0
    assert ozs._initial_sd_m(replace(case, initial_location="gaussian_d", spread_m=0.7)) == 0.7
    assert ozs._initial_sd_m(replace(case, initial_location="gaussian_d", spread_m=np.inf)) == 0.0
    with pytest.raises(ParameterError, match="known_initial_location"):
        ozs._initial_sd_m(replace(case, initial_location="roughly"))
    assert oz.with_interpretations(case, {"known_initial_location": "gaussian_d"}).initial_location == "gaussian_d"


def test_crlb_exponent_scales_the_printed_bound_as_one_over_n():
    """Eqs. (A.10)-(A.12): the Fisher information scales as (n / sigma)^2, so the printed-form bound is proportional
    to sigma / n under either averaging."""
    for average in ("area_rms", "cells_mean"):
        ref = oz.thesis_crlb_m("corners3", 5.2, 2.0, average)
        assert oz.thesis_crlb_m("corners3", 5.2, 2.3, average) == pytest.approx(ref * 2.0 / 2.3, rel=1e-12)
        assert oz.thesis_crlb_m("corners3", 10.4, 2.0, average) == pytest.approx(2 * ref, rel=1e-12)


def test_area_rms_is_the_rms_of_the_bound_over_the_room():
    xs, ys = np.arange(0.025, 5.0, 0.05), np.arange(0.025, 8.0, 0.05)
    points = np.stack(np.meshgrid(xs, ys, indexing="ij"), -1).reshape(-1, 2)
    bound = lb.rss_crlb_m(points, lb.RssModel(oz.readers_for("corners3"), lb.PathLossModel(0.0, 2.3, 5.2)),
                          variant="literal_ozkaya2011")
    assert oz.thesis_crlb_m("corners3", 5.2) == pytest.approx(np.sqrt(np.mean(bound**2)), rel=1e-9)
    cells = lb.rss_crlb_m(oz.cell_centres(oz.ROOM_M, 4, 7), lb.RssModel(oz.readers_for("corners3"),
                                                                        lb.PathLossModel(0.0, 2.0, 5.2)),
                          variant="literal_ozkaya2011")
    assert oz.thesis_crlb_m("corners3", 5.2, 2.0, "cells_mean") == pytest.approx(np.mean(cells), rel=1e-12)


def test_record_crlb_calibrated_only_under_a_fitted_reading(tmp_path, monkeypatch):
    monkeypatch.setenv("LOCBOOK_OUTPUT_DIR", str(tmp_path))
    monkeypatch.setenv("LOCBOOK_EXPERIMENT", "ozkaya2011-crlb")
    text, fitted = lb.Report(), lb.Report()
    oz.record_crlb(text)
    oz.record_crlb(fitted, 2.0, "cells_mean")
    assert all(r["kind"] == "reproduction" for r in text.numbers)
    assert all(r["kind"] == "calibrated" and "n = 2 " in r["calibrated_from"] for r in fitted.numbers)
    by_id = {r["printed_id"]: r for r in text.numbers}
    five = next(r for r in text.numbers if r["verdict"] and float(r["printed"]) == 0.80)
    assert float(five["reproduced"]) == pytest.approx(oz.thesis_crlb_m("corners3", 5.2), rel=1e-12)
    assert five["verdict"] == "miss" and "locbook bracket ozkaya2011-crlb" in five["note"]
    assert "fitted to the printed CRLB columns, which no text supports (n = 2 and the mean over the 1 m cells) are " \
        "alternatives" in five["note"]
    # the half-separation bound (Table 7.5) follows the declared placement of its readers
    moved = lb.Report()
    oz.record_crlb(moved, half_separation_layout="centroid_at_centre")
    half = next(r for r in moved.numbers if r["printed_id"].startswith("Table 7.5 | Half"))
    assert float(half["reproduced"]) == pytest.approx(oz.thesis_crlb_m("half3_centroid", 5.2), rel=1e-12)
    assert by_id.keys() == {r["printed_id"] for r in fitted.numbers}
