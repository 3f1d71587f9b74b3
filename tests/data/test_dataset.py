"""Data sets: the manifest (dataset.toml) and its rules, raw packets -> epochs, the shipped data sets, the synthetic
example, and the whole battery on a new data set with one command."""
import csv

import numpy as np
import pandas as pd
import pytest

import locbook as lb
from builders import ANCHORS, MANIFEST, REPO_ROOT, TRACK, calibration_csv
from locbook.data.dataset import datasets_dir, load_dataset, shipped_datasets
from locbook.data.example import EXAMPLE_SITE, write_example_dataset
from locbook.data.measured import DataFormatError, epochs, validate_readings
from locbook.errors import ParameterError
from locbook.scenarios import measured as me

CAL = calibration_csv()


def folder(tmp_path, name):
    path = tmp_path / name
    path.mkdir()
    return path


def make(tmp_path, manifest=MANIFEST, cal=CAL, track=TRACK, anchors=ANCHORS):
    for name, text in (("dataset.toml", manifest), ("cal.csv", cal), ("walk.csv", track), ("anchors.csv", anchors)):
        (tmp_path / name).write_text(text)
    return tmp_path


def refused(tmp_path, *needles, **files):
    make(tmp_path, **files)
    with pytest.raises(DataFormatError) as info:
        load_dataset(tmp_path)
    for needle in needles:
        assert needle in str(info.value), str(info.value)
    return str(info.value)


# -- the manifest ---------------------------------------------------------------------------------------------
def test_a_minimal_data_set_loads(tmp_path):
    ds = load_dataset(make(tmp_path))
    assert ds.name == "tiny" and ds.anchor_ids == ("A", "B", "C", "D") and ds.tag_height_m == 1.0
    assert ds.recordings_with("track") == ["walk"] and len(ds.epochs("cal")) == 4
    # no outline: the box around anchors and truth with a 0.5 m margin, said in the notes
    np.testing.assert_array_equal(ds.outline_m.min(axis=0), [-0.5, -0.5])
    np.testing.assert_array_equal(ds.outline_m.max(axis=0), [6.5, 6.5])
    assert "outline" in ds.notes
    # a true position without a height is at the tag's height
    assert np.all(ds.epochs("cal").position_m[:, 2] == 1.0)


@pytest.mark.parametrize("edit,needles", [
    (lambda m: m.replace('name = "tiny"', 'name = "Tiny Set"'), ["name 'Tiny Set'", "[a-z0-9-]"]),
    (lambda m: m.replace('license = "CC0 1.0"\n', ""), ["'license' is required"]),
    (lambda m: m + "colour = 3\n", ["unknown key(s) ['colour']"]),
    (lambda m: m.replace('role = "track"', 'role = "walking"'), ["role must be one of", "'walking'"]),
    (lambda m: m.replace('file = "walk.csv"', 'file = "../walk.csv"'), ["inside the data set's folder"]),
    (lambda m: m.replace('file = "walk.csv"', 'file = "nowhere.csv"'), ["'nowhere.csv' does not exist"]),
    # a track without a window is native scans (tests/data/test_data_format.py); too long a window refused
    (lambda m: m.replace("window_s = 0.5", "window_s = 10"), ["a track needs at least 2 epochs", "window_s = 10 s"]),
    (lambda m: m.replace("[geometry]", '[units]\ntime = "min"\n[geometry]'), ["[units] time must be one of"]),
    (lambda m: m.replace("[geometry]", '[units]\nrssi = "mW"\n[geometry]'), ["rssi must be 'dBm'"]),
    (lambda m: m.replace("tag_height_m = 1.0\n", ""), ["tag_height_m is required"]),
    (lambda m: m.replace('role = "calibration"', 'role = "static"'), ["no recording has role 'calibration'"]),
    (lambda m: m + '[readings]\nbackward_time = "maybe"\n', ["backward_time must be 'refuse' or 'sort'"]),
    (lambda m: m.replace("window_s = 0.5", "window_s = -1"), ["'window_s' must be >= 0"]),
])
def test_manifest_rules_name_the_problem(tmp_path, edit, needles):
    message = refused(tmp_path, *needles, manifest=edit(MANIFEST))
    assert "dataset.toml" in message


def test_calibration_needs_truth_and_missing_manifest_is_named(tmp_path):
    no_truth = "time_s,transmitter,receiver,rssi_dbm\n" + "".join(f"{t},tag,A,-{50 + t}\n" for t in range(4))
    refused(tmp_path, "calibration recording needs true positions", cal=no_truth)
    with pytest.raises(ParameterError, match="dataset.toml"):
        load_dataset(tmp_path / "elsewhere")
    with pytest.raises(ParameterError, match="shipped"):
        load_dataset("no-such-set")


def test_backward_time_is_refused_or_sorted_with_a_count(tmp_path):
    lines = TRACK.splitlines()
    lines[5], lines[9] = lines[9], lines[5]          # (1.0, A) logged before the four readings of t = 0.5
    track = "\n".join(lines) + "\n"
    refused(tmp_path, "walk.csv, line", "time goes back", track=track)
    ds = load_dataset(make(tmp_path, manifest=MANIFEST + '[readings]\nbackward_time = "sort"\n', track=track))
    assert ds.recording("walk").sorted_rows == 4 and "sorted walk" in ds.notes     # the four t = 0.5 rows
    clean = load_dataset(make(folder(tmp_path, "clean")))
    np.testing.assert_array_equal(ds.epochs("walk").rss_dbm, clean.epochs("walk").rss_dbm)


def test_units_are_converted_to_seconds_and_metres(tmp_path):
    base = load_dataset(make(folder(tmp_path, "si")))
    cm = "id,x,y,z\nA,0,0,250\nB,600,0,250\nC,0,600,250\nD,600,600,250\n"
    ms = lambda text: "\n".join([text.splitlines()[0]] + [
        ",".join([str(1000 * float(f[0]) + 5000), *f[1:4], str(100 * float(f[4])), str(100 * float(f[5]))])
        for f in (line.split(",") for line in text.splitlines()[1:])]) + "\n"
    manifest = MANIFEST.replace("[geometry]", '[units]\ntime = "ms"\nlength = "cm"\n[geometry]')
    other = load_dataset(make(folder(tmp_path, "ms"), manifest=manifest,
                              cal=ms(CAL), track=ms(TRACK), anchors=cm))
    np.testing.assert_allclose(other.anchors_m, base.anchors_m)
    for name in ("cal", "walk"):
        a, b = base.epochs(name), other.epochs(name)
        np.testing.assert_allclose(b.time_s - b.time_s[0], a.time_s - a.time_s[0], atol=1e-9)
        np.testing.assert_allclose(b.position_m, a.position_m, atol=1e-12)
        np.testing.assert_array_equal(b.rss_dbm, a.rss_dbm)


def test_sentinels_become_not_heard_and_the_range_refuses(tmp_path):
    track = TRACK.replace(",-55,", ",4,", 1)
    manifest = MANIFEST + "[readings]\ninvalid_values_dbm = [4]\nvalid_range_dbm = [-100, -30]\n"
    ds = load_dataset(make(tmp_path, manifest=manifest, track=track))
    assert np.isnan(ds.epochs("walk").rss_dbm[0, 0]) and "invalid readings" in ds.notes
    refused(tmp_path, "walk.csv, line 2", "outside [-100, -30]", manifest=manifest,
            track=track.replace(",4,", ",-20,", 1))


# -- raw packets -> epochs ------------------------------------------------------------------------------------
def _raw(rows, extra=None):
    table = pd.DataFrame(rows, columns=["time_s", "transmitter", "receiver", "rssi_dbm", "x_m", "y_m"])
    for k, v in (extra or {}).items():
        table[k] = v
    return validate_readings(table, source="test", sort=True)


def test_windows_aggregate_each_anchors_readings():
    rows = [(0.00, "t", "A", -60, 0.0, 0.0), (0.30, "t", "A", -70, 1.0, 0.0), (0.40, "t", "A", -62, 2.0, 0.0),
            (0.10, "t", "B", -80, 0.0, 0.0), (1.05, "t", "A", -50, 3.0, 0.0), (1.10, "t", "B", np.nan, 3.0, 0.0)]
    table = _raw(rows)
    by = {agg: epochs(table, ["A", "B"], window_s=1.0, aggregate=agg) for agg in ("mean", "median", "max")}
    ep = by["mean"]
    np.testing.assert_array_equal(ep.time_s, [0.0, 1.0])              # ticks of the window clock
    np.testing.assert_allclose(ep.rss_dbm, [[-64.0, -80.0], [-50.0, np.nan]])
    np.testing.assert_allclose(by["median"].rss_dbm[0], [-62.0, -80.0])
    np.testing.assert_allclose(by["max"].rss_dbm[0], [-60.0, -80.0])
    np.testing.assert_array_equal(ep.n_readings, [[3, 1], [1, 0]])
    np.testing.assert_allclose(ep.position_m[:, 0], [0.75, 3.0])      # a moving tag: the window's mean
    two = epochs(table, ["A", "B"], window_s=1.0, min_readings=2)
    np.testing.assert_allclose(two.rss_dbm, [[-64.0, np.nan], [np.nan, np.nan]])


def test_a_point_column_keeps_points_apart_and_is_kept():
    rows = [(0.0, "t", "A", -60, 1.0, 1.0), (0.1, "t", "A", -62, 1.0, 1.0), (0.2, "t", "A", -70, 5.0, 5.0),
            (0.3, "t", "B", -71, 5.0, 5.0)]
    table = _raw(rows, {"point": ["P1", "P1", "P2", "P2"], "note": ["a", "b", "c", "c"]})
    mixed = epochs(table, ["A", "B"], window_s=1.0)
    assert len(mixed) == 1 and "point" not in mixed.extra              # the point varies inside the window
    ep = epochs(table, ["A", "B"], window_s=1.0, group_by="point")
    assert len(ep) == 2 and list(ep.extra["point"]) == ["P1", "P2"]
    np.testing.assert_allclose(ep.rss_dbm, [[-61.0, np.nan], [-70.0, -71.0]])
    assert "note" not in ep.extra                                      # varies within P1's epoch: not kept
    np.testing.assert_array_equal(ep.select([1]).extra["point"], ["P2"])
    with pytest.raises(ParameterError, match="group_by column 'room'"):
        epochs(table, ["A", "B"], window_s=1.0, group_by="room")


def test_rows_already_on_the_clock_are_one_epoch_each():
    rows = [(k / 3, "t", a, -60.0 - k - j, k * 0.1, 0.0) for k in range(9) for j, a in enumerate("AB")]
    table = _raw(rows)
    plain, windowed = epochs(table, ["A", "B"]), epochs(table, ["A", "B"], window_s=1 / 3)
    np.testing.assert_array_equal(plain.rss_dbm, windowed.rss_dbm)
    np.testing.assert_array_equal(plain.position_m, windowed.position_m)
    np.testing.assert_allclose(plain.time_s, windowed.time_s, atol=1e-12)


# -- the shipped data sets ------------------------------------------------------------------------------------
@pytest.mark.installed
def test_every_shipped_data_set_loads_with_its_licence():
    assert "kolakowski2021" in shipped_datasets()
    for name in shipped_datasets():
        ds = load_dataset(name)
        assert ds.name == name and ds.license_file is not None and ds.license_file.is_file()
        assert ds.recordings_with("calibration") and me.scored_recordings(ds)


def test_kolakowski_long_files_keep_every_empty_cell_as_not_heard():
    """The shipped long files read with the csv module (independent of the loader): every empty cell is NaN."""
    ds = load_dataset("kolakowski2021")
    for name, rows in (("calibration", 4104), ("robot", 719), ("walk", 876)):
        with open(ds.recording(name).file, newline="") as fh:
            cells = [r["rssi_dbm"] for r in csv.DictReader(fh)]
        grid = np.array([float(c) if c else np.nan for c in cells]).reshape(rows, 6)
        np.testing.assert_array_equal(ds.epochs(name).rss_dbm, grid)
    robot = ds.epochs("robot")
    assert np.isclose(robot.time_s[-1] - robot.time_s[0], 352.0, atol=0.5)     # the data set's README
    assert np.all(robot.position_m[:, 2] == 1.3)


SOURCE = REPO_ROOT.parent / "shared" / "data" / "kolakowski2021"


@pytest.mark.skipif(not (SOURCE / "calibration_df.csv").is_file(), reason="the published source files are not here")
def test_kolakowski_conversion_reproduces_the_shipped_files(tmp_path):
    """convert.py applied to the published wide files gives the shipped long files byte for byte."""
    import importlib.util
    spec = importlib.util.spec_from_file_location("convert", datasets_dir() / "kolakowski2021" / "convert.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.convert(SOURCE, tmp_path)
    for name in ("calibration.csv", "robot.csv", "walk.csv", "anchors.csv", "outline.csv", "path_reference.csv"):
        assert (tmp_path / name).read_bytes() == (datasets_dir() / "kolakowski2021" / name).read_bytes(), name


# -- the example data set -------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def example(tmp_path_factory):
    return write_example_dataset(tmp_path_factory.mktemp("example"), np.random.default_rng(5), walk_s=60.0)


def test_the_example_has_the_faults_it_promises(example):
    ds = load_dataset(example)
    assert ds.recording("walk_b").sorted_rows > 0
    survey = pd.read_csv(example / "survey.csv", dtype={"rssi_dbm": str})
    assert (survey["rssi_dbm"] == "0.0").any() and survey["rssi_dbm"].isna().any()
    assert not np.any(ds.recording("survey").readings["rssi_dbm"] >= 0)      # the sentinel is not a reading
    assert set(ds.epochs("points").extra["point"]) == {f"T{k:02d}" for k in range(1, 13)}


def test_the_example_calibration_recovers_its_channel(example):
    """The closed-form fit on the survey's 1 s epoch means recovers the generator's channel (4 dB per packet)."""
    fit = me.calibrate(load_dataset(example))
    np.testing.assert_allclose(fit.path_loss_exp, EXAMPLE_SITE["path_loss_exp"], atol=0.2)
    np.testing.assert_allclose(fit.ref_power_dbm, EXAMPLE_SITE["ref_power_dbm"], atol=2.0)


@pytest.mark.notebooks
def test_one_command_runs_the_whole_battery_on_a_new_data_set(tmp_path):
    """The issue's test: a data set written to a folder (log-distance packets, NaN readings, a point id column, an
    invalid sentinel, backward timestamps in one track), its manifest, and `locbook run --data DIR`."""
    from locbook.suite.cli import main
    folder = write_example_dataset(tmp_path / "mine", np.random.default_rng(7), name="mine", walk_s=60.0)
    assert main(["data", "check", str(folder)]) == 0
    assert main(["run", "--data", str(folder), "--reports", str(tmp_path / "reports"), "--quiet"]) == 0
    out = tmp_path / "reports" / "quick" / "data-mine"
    for exp in ("measured-calibration", "measured-localization", "measured-tracking", "benchmark-cross-document"):
        assert (out / exp / "summary.md").is_file() and list((out / exp).glob("*.png")), exp
    results = pd.read_csv(out / "measured-localization" / "results.csv").set_index(["recording", "method"])
    at, bound = results["mean_m"], results["bound_median_m"]
    assert at[("points", "grid_ml")] < 2 * bound[("points", "grid_ml")]
    assert at[("walk_a", "grid_ml")] < 2 * bound[("walk_a", "grid_ml")]
    # the trackers whose settings come from the data by the stated rule do better than the fixes of one epoch
    tracking = pd.read_csv(out / "measured-tracking" / "results.csv").set_index(["recording", "method"])["mean_m"]
    for tracker in ("kf_on_ml", "particle", "grid_bayes"):
        assert tracking[("pooled", tracker)] < 0.5 * (results["mean_m"][("walk_a", "rss_ml")] +
                                                      results["mean_m"][("walk_b", "rss_ml")]), tracker
    assert (pd.read_csv(out / "measured-calibration" / "fits.csv").query("fit == 'closed_form' and mode == "
            "'per_anchor'")["n"].sub(EXAMPLE_SITE["path_loss_exp"]).abs() < 0.3).all()
    bench = pd.read_csv(out / "benchmark-cross-document" / "benchmark.csv")
    assert set(bench.loc[bench["scenario"] == "data-mine", "kind"]) == {"static", "tracking"}


def test_run_with_data_refuses_bad_input_before_running(tmp_path, capsys):
    from locbook.suite.cli import EXIT_BAD_INPUT, main
    good = make(folder(tmp_path, "good"))
    assert main(["run", "george-tracking", "--data", str(good), "--reports", str(tmp_path / "r")]) == EXIT_BAD_INPUT
    assert "takes no data set" in capsys.readouterr().err
    assert main(["run", "--data", str(tmp_path / "missing"), "--reports", str(tmp_path / "r")]) == EXIT_BAD_INPUT
    assert "no data set at" in capsys.readouterr().err
    bad = make(folder(tmp_path, "bad"), manifest=MANIFEST.replace('role = "track"', 'role = "walking"'))
    assert main(["run", "--data", str(bad), "--reports", str(tmp_path / "r")]) == EXIT_BAD_INPUT
    assert "dataset.toml" in capsys.readouterr().err and not (tmp_path / "r").exists()
    assert main(["data", "check", str(bad)]) == EXIT_BAD_INPUT
    assert main(["data", "check", str(good)]) == 0 and "data set 'tiny'" in capsys.readouterr().out


# -- what the review of the first version found ---------------------------------------------------------------
def test_windows_are_half_open_so_a_regular_clock_gives_even_counts():
    """2 Hz packets with 1 s windows: two readings in every window (round-half-to-even gave 2, 1, 3, 1, 3, ...)."""
    rows = [(0.5 * k, "t", "A", -60.0 - k, 0.0, 0.0) for k in range(12)]
    ep = epochs(_raw(rows), ["A"], window_s=1.0)
    np.testing.assert_array_equal(ep.n_readings[:, 0], [1] + [2] * 5 + [1])     # [-0.5, 0.5), [0.5, 1.5), ...
    rows = [(0.1 * k, "t", "A", -60.0, 0.0, 0.0) for k in range(20)]           # a decimal clock
    np.testing.assert_array_equal(epochs(_raw(rows), ["A"], window_s=0.5).n_readings[:, 0], [3, 5, 5, 5, 2])


def test_undeclared_readings_at_0_dbm_warn_through_a_manifest(tmp_path):
    from locbook.data.measured import MeasuredDataWarning
    with pytest.warns(MeasuredDataWarning, match="at or above 0 dBm"):
        load_dataset(make(tmp_path, track=TRACK.replace(",-55,", ",0,")))


def test_a_track_with_two_transmitters_or_a_point_column_is_refused(tmp_path):
    two = TRACK + "".join(f"{0.5 * t},other,A,-60,{t},3\n" for t in range(3))
    refused(tmp_path, "walk.csv holds 2 transmitters", "their own file", track=two)
    refused(tmp_path, "point_column belongs to calibration and static",
            manifest=MANIFEST.replace('role = "track"', 'role = "track"\npoint_column = "x_m"'))


def test_empty_point_ids_are_refused_naming_the_line(tmp_path):
    cal = CAL.replace("x_m,y_m\n", "x_m,y_m,point\n", 1)
    cal = "\n".join(line + ("" if i == 0 else (",P1" if i < 9 else ("," if i == 9 else ",P2")))
                    for i, line in enumerate(cal.splitlines())) + "\n"
    manifest = MANIFEST.replace('role = "calibration"', 'role = "calibration"\npoint_column = "point"')
    refused(tmp_path, "cal.csv, line 10, column 'point'", "the point id is empty", manifest=manifest, cal=cal)


def test_nanoseconds_since_1970_keep_every_digit(tmp_path):
    base = 1_700_000_000_000_000_000
    ns = "time_s,transmitter,receiver,rssi_dbm,x_m,y_m\n" + "".join(
        f"{base + 250_000_000 * t + 7},tag,{a},-{55 + j},{t},3\n" for t in range(6) for j, a in enumerate("ABCD"))
    manifest = MANIFEST.replace("[geometry]", '[units]\ntime = "ns"\n[geometry]')
    ds = load_dataset(make(tmp_path, manifest=manifest, track=ns,
                           cal=CAL.replace("\n0,", "\n1700000000000000000,").replace("\n1,", "\n1700000000000000001,")
                           .replace("\n2,", "\n1700000000000000002,").replace("\n3,", "\n1700000000000000003,")))
    np.testing.assert_array_equal(ds.recording("walk").readings["time_s"].unique(), 0.25 * np.arange(6))
    assert len(ds.epochs("cal")) == 4                 # 1 ns apart, still four distinct epochs


def test_a_data_set_without_per_epoch_truth_has_no_static_scenario(tmp_path):
    from locbook import benchmark as bm
    track = "time_s,transmitter,receiver,rssi_dbm\n" + "".join(
        f"{0.5 * t},tag,{a},-{55 + j}\n" for t in range(6) for j, a in enumerate("ABCD"))
    ds = load_dataset(make(tmp_path, track=track))
    assert "scoring" in ds.notes and me.scored_recordings(ds) == []
    assert bm.measured_static_scenario(ds) is None and bm.measured_tracking_scenario(ds) is None


def test_the_measured_bound_uses_the_anchors_each_epoch_heard():
    """An epoch that did not hear some anchors: its bound is the closed-form CRLB of the anchors it heard."""
    ds = load_dataset("kolakowski2021")
    model = me.channel(me.calibrate(ds))
    t = me.TestEpochs.of(ds, "robot")
    rss = t.rss_dbm[:3].copy()
    rss[1, [0, 4]] = np.nan
    rss[2, [0, 1, 2, 3, 4]] = np.nan                     # one anchor: no fix, no bound
    got = me.crlb_m(ds, model, t.truth_m[:3], rss)
    np.testing.assert_allclose(got[0], me.crlb_m(ds, model, t.truth_m[:1])[0], rtol=1e-12)
    keep = [1, 2, 3, 5]
    alone = lb.rss_crlb_m(t.truth_m[1], lb.RssModel(ds.anchors_m[keep], lb.PathLossModel(
        0.0, model.path_loss_exp[keep], model.sigma_db[keep]), tag_height_m=ds.tag_height_m))
    np.testing.assert_allclose(got[1], alone, rtol=1e-10)
    assert np.isnan(got[2])


def test_data_sets_of_one_name_never_share_a_reports_folder(tmp_path):
    from locbook.suite import load_suite, run_suite
    from locbook.suite.spec import SuiteError
    suite = load_suite()
    exp = [e for e in suite.experiments if e.id == "measured-calibration"]
    first, second = make(folder(tmp_path, "one")), make(folder(tmp_path, "two"))
    from locbook.suite.run import _dataset_argument, claim_dataset_folder
    name, _, roots, identity = _dataset_argument(str(first))
    assert str(first) in roots and identity == str(first)
    claim_dataset_folder(tmp_path / "r" / "quick" / "data-tiny", name, identity)
    with pytest.raises(SuiteError, match="another data set named 'tiny'"):
        run_suite(suite, exp, "quick", report_root=tmp_path / "r", overrides={"data": str(second)},
                  out_dir=None, progress="quiet")
    with pytest.raises(ParameterError, match="not an empty folder"):
        write_example_dataset(first, np.random.default_rng(1))


@pytest.mark.installed
def test_danis2022_facts():
    """The second shipped data set as its README describes it."""
    ds = load_dataset("danis2022")
    assert len(ds.anchor_ids) == 12 and sorted(set(ds.anchors_m[:, 2])) == [1.22, 2.3]
    assert len(set(ds.epochs("calibration").extra["point"])) == 81
    assert len(set(ds.epochs("points").extra["point"])) == 45
    assert len(ds.recordings_with("track")) == 9 and all(ds.recording(n).has_truth for n in ds.recordings_with("track"))
    assert ds.tag_height_m == pytest.approx(1.85) and "median" in ds.notes["tag_height_m"]
    assert "CC0" in ds.license and ds.license_file.is_file()


def test_motion_fit_is_the_maximum_likelihood_of_each_motion_model_and_starts_where_the_trackers_start():
    """measured.fit_motion: q maximises the EKF's log-likelihood of the track's readings (an EKF rerun at the fitted q
    gives at least the likelihood at the start value, and nearby q give less), from the state every tracker starts
    at (the first rss_ml fix, at rest); the random walk maximises a KF (F = I) on the rss_ml fixes likewise."""
    from locbook.battery import ml_fixes
    ds = me.load("danis2022")
    model = me.channel(me.calibrate(ds))
    name = "straight_01"
    fix_cov = me.fix_covariance_from_calibration(ds, model, grid_spacing_m=0.1)
    fit = me.fit_motion(ds, model, name, grid_spacing_m=0.1, fix_cov_m2=fix_cov)
    sc = me.tracking_scenario(ds, model, name, grid_spacing_m=0.1, q=fit["q"], spread_m=fit["spread_m"])
    fixes = ml_fixes(sc, sc.measured_rss_dbm)
    first = np.flatnonzero(np.isfinite(fixes).all(axis=1))[0]
    np.testing.assert_array_equal(sc.start_state, np.r_[fixes[first], 0.0, 0.0])
    P0 = np.zeros((4, 4))
    P0[:2, :2], P0[2:, 2:] = fix_cov, me.START_VELOCITY_SD_M_S**2 * np.eye(2)       # the calibrated fix covariance
    stream = lb.RssMeasurement(sc.measured_rss_dbm, ds.anchors_m, model, np.array([0, 1]), tag_height_m=ds.tag_height_m)

    def ekf_ll(q):
        m = lb.constant_velocity(sc.dt_s, q, dim=2)
        return float(lb.extended_kalman_filter(m.F, m.Q, sc.start_state, P0, [stream]).total_log_likelihood)

    best = ekf_ll(fit["q"])
    assert best >= ekf_ll(me.Q_START) - 1e-9
    assert best >= ekf_ll(fit["q"] * 1.3) and best >= ekf_ll(fit["q"] / 1.3)

    def walk_ll(s):
        return float(lb.kalman_filter(np.eye(2), s**2 * np.eye(2), sc.start_state[:2], P0[:2, :2],
                                      [lb.LinearMeasurement(fixes, np.eye(2), fix_cov)]).total_log_likelihood)

    s = fit["spread_m"]
    assert walk_ll(s) >= walk_ll(me.SPREAD_START_M) - 1e-9
    assert walk_ll(s) >= walk_ll(s * 1.15) and walk_ll(s) >= walk_ll(s / 1.15)
