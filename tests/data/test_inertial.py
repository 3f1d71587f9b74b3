"""Inertial streams of a measured data set: the file and its units, the shared time origin, the sub-step
alignment, the fusion trackers on generated data with known truth, and a data set without inertial files unchanged."""
import hashlib
import math
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import locbook as lb
from locbook.data.example import EXAMPLE_SITE, write_example_dataset
from locbook.data.inertial import STANDARD_GRAVITY_M_S2, InertialSamples, align, read_inertial, sub_steps
from locbook.data.measured import DataFormatError
from locbook.scenarios import measured as me


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


# ------------------------------------------------------------------------------------------------------ the reader
def test_reader_converts_g_and_deg_s(tmp_path):
    f = _write(tmp_path / "imu.csv", "time_s,acc_x,acc_y,gyro_z,mag_x,mag_y\n0.0,0.5,-0.25,90,20,-3\n"
                                     "0.02,0.1,,,21,-3\n0.04,1.0,2.0,-45,,\n")
    with pytest.raises(DataFormatError, match=r"line 3, column 'acc_y': missing while 'acc_x' is given"):
        read_inertial(f, acceleration="g", angular_rate="deg/s")
    f = _write(tmp_path / "imu.csv", "time_s,acc_x,acc_y,gyro_z,mag_x,mag_y\n0.0,0.5,-0.25,90,20,-3\n"
                                     "0.02,,,,21,-3\n0.04,1.0,2.0,-45,,\n")
    s = read_inertial(f, acceleration="g", angular_rate="deg/s")
    assert s.acc_m_s2[0] == pytest.approx([0.5 * 9.80665, -0.25 * 9.80665])
    assert s.acc_m_s2[2] == pytest.approx([9.80665, 19.6133])
    assert np.isnan(s.acc_m_s2[1]).all()                          # an empty field: no sample (NaN)
    assert s.gyro_rad_s[[0, 2]] == pytest.approx([math.pi / 2, -math.pi / 4])
    assert s.mag[0].tolist() == [20.0, -3.0] and np.isnan(s.mag[2]).all()
    assert s.interval_s == pytest.approx(0.02) and s.gaps == 0


@pytest.mark.parametrize("text, message", [
    ("time_s,acc_x\n0,1\n1,2\n", r"missing column\(s\) \['acc_y'\]"),
    ("time_s,acc_x,acc_y\n0,1,2\n0.1,x,2\n", r"line 3, column 'acc_x': 'x' is not a finite number"),
    ("time_s,acc_x,acc_y\n0,1,2\n0.2,1,2\n0.1,1,2\n", r"line 4, column 'time_s': the time 0.1 s goes back"),
    ("time_s,acc_x,acc_y\n0,1,2\n0,1,2\n", r"line 3, column 'time_s': the time 0.0 s repeats"),
    ("time_s,acc_x,acc_y,gyro_z\n0,1,2,0\n0.1,1,2,90\n", r"line 3, column 'gyro_z': '90' is 90 rad/s"),
    ("time_s,acc_x,acc_y\n0,1,2\n0.1,1,200\n", r"line 3, column 'acc_y': '200' is 200 m/s\^2"),
    ("time_s,acc_x,acc_y,mag_x\n0,1,2,3\n0.1,1,2,3\n", r"column 'mag_x' without its pair"),
    ("time_s,acc_x,acc_y\n0,1,2\n", r"1 sample\(s\); an inertial stream has at least 2"),
])
def test_reader_refuses_bad_input_in_one_line(tmp_path, text, message):
    f = _write(tmp_path / "imu.csv", text)
    with pytest.raises(DataFormatError, match=message) as err:
        read_inertial(f)
    assert "\n" not in str(err.value) and str(f) in str(err.value)


def test_reader_sorts_under_the_sort_rule(tmp_path):
    f = _write(tmp_path / "imu.csv", "time_s,acc_x,acc_y\n0,1,2\n0.2,3,4\n0.1,5,6\n0.3,7,8\n")
    s = read_inertial(f, sort=True)
    assert s.time_s.tolist() == [0.0, 0.1, 0.2, 0.3] and s.acc_m_s2[:, 0].tolist() == [1, 5, 3, 7]
    assert s.sorted_rows == 1


def _tiny_dataset(folder: Path, *, readings_t0_ms: int, imu_t0_ms: int, extra_units: str = "",
                  imu_file: str = "survey_imu.csv") -> Path:
    """A three-anchor data set in milliseconds whose survey starts at ``readings_t0_ms`` and its inertial file at
    ``imu_t0_ms`` (integer times since 1970, as loggers write them)."""
    folder.mkdir()
    _write(folder / "anchors.csv", "id,x,y,z\nA1,0,0,2\nA2,10,0,2\nA3,0,10,2\n")
    rows = ["time_s,transmitter,receiver,rssi_dbm,x_m,y_m"]
    for k in range(40):
        for j, a in enumerate(("A1", "A2", "A3")):
            rows.append(f"{readings_t0_ms + 250 * k + j},tag,{a},{-50 - 3 * j - (k % 4)},{2 + k // 20},3")
    _write(folder / "survey.csv", "\n".join(rows) + "\n")
    _write(folder / imu_file, "time_s,acc_x,acc_y,gyro_z\n"
           + "".join(f"{imu_t0_ms + 20 * i},0.01,-0.02,0.001\n" for i in range(100)))
    _write(folder / "dataset.toml", f'''name = "tiny"
title = "t"
license = "CC0 1.0"
attribution = "test"
[units]
time = "ms"
{extra_units}
[geometry]
anchors = "anchors.csv"
tag_height_m = 1.0
[epochs]
window_s = 1.0
[[recording]]
name = "survey"
file = "survey.csv"
role = "calibration"
inertial = "{imu_file}"
''')
    return folder


def test_inertial_times_share_the_readings_origin(tmp_path):
    """[units] time = "ms": both files are shifted by the readings file's first time, so an IMU file that starts
    2.5 s after the readings keeps its 2.5 s (its own first time is not its origin)."""
    t0 = 1_717_000_000_123                                    # ms since 1970
    ds = lb.load_dataset(_tiny_dataset(tmp_path / "d", readings_t0_ms=t0, imu_t0_ms=t0 + 2_500,
                                       extra_units='acceleration = "g"\nangular_rate = "deg/s"'))
    rec = ds.recording("survey")
    assert rec.readings["time_s"].min() == 0.0
    assert rec.inertial.time_s[0] == pytest.approx(2.5, abs=1e-12)
    assert rec.inertial.time_s[-1] == pytest.approx(2.5 + 99 * 0.02, abs=1e-12)
    assert rec.inertial.acc_m_s2[0] == pytest.approx([0.01 * STANDARD_GRAVITY_M_S2, -0.02 * STANDARD_GRAVITY_M_S2])
    assert rec.inertial.gyro_rad_s[0] == pytest.approx(np.deg2rad(0.001))
    assert rec.inertial.file in ds.files and "inertial survey" in ds.notes
    early = lb.load_dataset(_tiny_dataset(tmp_path / "e", readings_t0_ms=t0, imu_t0_ms=t0 - 1_000))
    assert early.recording("survey").inertial.time_s[0] == pytest.approx(-1.0, abs=1e-12)


def test_manifest_refuses_a_bad_unit_and_a_file_outside(tmp_path):
    folder = _tiny_dataset(tmp_path / "d", readings_t0_ms=0, imu_t0_ms=0, extra_units='acceleration = "mg"')
    with pytest.raises(DataFormatError, match=r"\[units\] acceleration must be one of \['g', 'm/s2'\], got 'mg'"):
        lb.load_dataset(folder)
    folder = _tiny_dataset(tmp_path / "e", readings_t0_ms=0, imu_t0_ms=0, imu_file="../imu.csv")
    with pytest.raises(DataFormatError, match=r"\[\[recording\]\] 'survey': inertial: '../imu.csv' must be a file "
                                              r"inside the data set's folder"):
        lb.load_dataset(folder)


# --------------------------------------------------------------------------------------------------- alignment
def test_alignment_equals_a_pandas_resample():
    rng = np.random.default_rng(3)
    t = np.sort(rng.uniform(-1.2, 4.9, 400))
    t = t[np.abs(((t + 1.0) / 0.1) - np.round((t + 1.0) / 0.1)) > 1e-6]      # none on a window's edge
    acc = rng.normal(size=(len(t), 2))
    acc[rng.random(len(t)) < 0.1] = np.nan
    gyro = rng.normal(size=len(t))
    samples = InertialSamples(Path("x.csv"), t, acc, gyro, None, 0.015)
    ticks = np.arange(0.0, 5.0, 1.0)              # epochs at 0..4 s, 1 s apart: the grid starts at -1 s
    grid = align(samples, ticks, 1.0, n_sub=10)
    frame = pd.DataFrame({"ax": acc[:, 0], "ay": acc[:, 1], "g": gyro},
                         index=pd.Timestamp(0) + pd.to_timedelta(t - (-1.0), unit="s"))
    frame = frame[frame.index >= pd.Timestamp(0)]
    want = frame.resample("100ms", origin=pd.Timestamp(0), closed="left", label="left").mean()
    want = want.reindex(pd.Timestamp(0) + pd.to_timedelta(np.arange(50) * 0.1, unit="s"))
    np.testing.assert_allclose(grid.acc_m_s2, want[["ax", "ay"]].to_numpy(), equal_nan=True, rtol=1e-12)
    np.testing.assert_allclose(grid.gyro_rad_s, want["g"].to_numpy(), equal_nan=True, rtol=1e-12)
    assert grid.rss_steps.tolist() == [9, 19, 29, 39, 49]
    np.testing.assert_allclose(grid.time_s[grid.rss_steps], ticks)   # an epoch ends its last sub-step's window
    assert sub_steps(1.0, 0.02) == 10 and sub_steps(1.0, 0.25) == 4
    assert sub_steps(0.5, 2.0) == 1


# ----------------------------------------------------------------------------------- the battery on known truth
@pytest.fixture(scope="module")
def fused(tmp_path_factory):
    folder = tmp_path_factory.mktemp("inertial") / "example"
    write_example_dataset(folder, np.random.default_rng(5), walk_s=60.0, inertial=True)
    ds = me.load(folder)
    model = me.channel(me.calibrate(ds))
    proto = me.protocol(ds, model)
    res = me.tracking_results(ds, model, proto, seed=11, n_particles=200, particle_runs=2, n_bootstrap=50,
                              block_s=10.0)
    return folder, ds, model, proto, res


def test_stationary_noise_recovers_the_generator(fused):
    folder, ds, model, proto, res = fused
    imu = EXAMPLE_SITE["imu"]
    noise = proto.inertial["walk_a"].noise
    n = noise.n_samples
    assert n > 5000
    # the mean's and the sd's Monte-Carlo errors: sigma / sqrt(n), sigma / sqrt(2 n); within 4 of them
    np.testing.assert_allclose(noise.acc_bias_m_s2, imu["acc_bias_m_s2"], atol=4 * imu["acc_sigma_m_s2"] / np.sqrt(n))
    np.testing.assert_allclose(np.sqrt(noise.acc_var_m2_s4), imu["acc_sigma_m_s2"],
                               atol=4 * imu["acc_sigma_m_s2"] / np.sqrt(2 * n))
    assert noise.gyro_bias_rad_s == pytest.approx(imu["gyro_bias_rad_s"], abs=4 * imu["gyro_sigma_rad_s"] / np.sqrt(n))
    assert np.sqrt(noise.gyro_var_rad2_s2) == pytest.approx(imu["gyro_sigma_rad_s"],
                                                            abs=4 * imu["gyro_sigma_rad_s"] / np.sqrt(2 * n))


def test_heading_start_is_found_without_truth(fused):
    """Both walks start heading along +x (the loops go counter-clockwise from their lower-left straight): the
    maximum-likelihood heading lies within the coarse candidates' spacing (10 deg, the 8-state filters' start sd);
    the heading is seen only in the turns (a straight at constant speed has no acceleration)."""
    folder, ds, model, proto, res = fused
    for name in ("walk_a", "walk_b"):
        assert abs(np.rad2deg(proto.inertial[name].heading_rad)) < 10.0
        assert proto.inertial[name].grid.n_sub == 10               # 1 s epochs, 50 Hz: capped at 10


def test_fusion_beats_rss_alone_and_stays_near_the_bound(fused):
    folder, ds, model, proto, res = fused
    rows = {(r["recording"], r["method"]): r for r in res["rows"]}
    assert res["fusion"] == ["kf_acc", "ekf_rss_acc", "ekf_rss_imu", "ukf_rss_imu"]
    ekf = rows[("pooled", "ekf")]
    for name in res["fusion"]:
        row = rows[("pooled", name)]
        assert row["mean_m"] < ekf["mean_m"], (name, row["mean_m"], ekf["mean_m"])
        assert row["bound"] == ekf["bound"] and row["epochs"] == ekf["epochs"]
        assert 0.3 < row["ratio"] < 3.0
        # the truth, independently: the rounded loop's positions at the epochs' times
        sc, est, flags, bound = res["tracks"]["walk_a"]
        steps = sc.scored_steps
        err = np.linalg.norm(est[name][0, steps] - sc.truth_m[steps], axis=-1)
        assert np.mean(err) < 2.0
    assert 0.3 < ekf["ratio"] < 3.0
    bench = me.benchmark_rows(ds, None, res)
    assert set(res["fusion"]) <= {r["method"] for r in bench}


def test_without_inertial_files_nothing_changes(fused, tmp_path):
    """The same data set with its inertial keys removed: the RSS trackers' rows, the settings and the bounds are the
    ones it gives with them, and no fusion row, setting or figure entry is added."""
    folder, ds, model, proto, res = fused
    plain = tmp_path / "plain"
    plain.mkdir()
    for f in folder.iterdir():
        if not f.name.endswith("_imu.csv"):
            (plain / f.name).write_bytes(f.read_bytes())
    text = (plain / "dataset.toml").read_text()
    (plain / "dataset.toml").write_text(re.sub(r'inertial = "[a-z_]+\.csv"\n', "", text))
    ds2 = me.load(plain)
    model2 = me.channel(me.calibrate(ds2))
    proto2 = me.protocol(ds2, model2)
    res2 = me.tracking_results(ds2, model2, proto2, seed=11, n_particles=200, particle_runs=2, n_bootstrap=50,
                               block_s=10.0)
    assert res2["fusion"] == [] and proto2.inertial == {}
    assert res2["rows"] == [r for r in res["rows"] if r["method"] not in res["fusion"]]
    assert proto2.rows() == [r for r in proto.rows() if not any(t in r["method"] for t in res["fusion"])]


# --------------------------------------------------------------------------------------------- the example's bytes
#: SHA-256 of the default example (seed 1, walk_s 20) as written before inertial streams existed (the base of the
#: streams' work)
_DEFAULT_BYTES = {
    "anchors.csv": "d2301b3eec8dc61ad6d5ccc13ee772cc79883ba99755c60ae8f785bd82fa306a",
    "dataset.toml": "9204526f49b710c7f795f9c588fa8982c41215984bfe775e2b1a330de0534425",
    "outline.csv": "28ba9485ad4f0487411e9323274142f127bd23f8eaecec8aadcc2870c84aa67a",
    "points.csv": "4c2f5d4154ea48f64c55f01843f2958de4401875c9d4481af573d605d266d801",
    "survey.csv": "92db1b2fc25190aa9752e361a291f62fe535a9f83ccf20310cd4303575747504",
    "walk_a.csv": "5f548f0072b5607478401bdbd2da4d6624cc4a545f7818abd00e13500c31cc49",
    "walk_b.csv": "c242b5898ee5da1995479ee567b8f57841888fd44a6572dfa8ffb7cb41b706af",
}


def _hashes(folder: Path) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


def test_default_example_bytes_unchanged(tmp_path):
    write_example_dataset(tmp_path / "a", np.random.default_rng(1), walk_s=20.0, seed_note=1)
    assert _hashes(tmp_path / "a") == _DEFAULT_BYTES
    write_example_dataset(tmp_path / "b", np.random.default_rng(1), walk_s=20.0, seed_note=1, inertial=True)
    with_imu = _hashes(tmp_path / "b")
    # the inertial draws come from their own stream: the recordings that do not move are the default's bytes
    for name in ("anchors.csv", "outline.csv", "points.csv", "survey.csv"):
        assert with_imu[name] == _DEFAULT_BYTES[name]
    assert {"survey_imu.csv", "points_imu.csv", "walk_a_imu.csv", "walk_b_imu.csv"} <= set(with_imu)


def test_without_a_gyroscope_only_the_accelerometer_ekf_runs(fused, tmp_path):
    """Walk files without gyro_z: no heading to rotate by, so kf_acc and ekf_rss_acc take the readings as world-frame
    (named in the settings) and the 8-state trackers, which need the gyroscope, do not run."""
    folder, ds, model, proto, res = fused
    bare = tmp_path / "bare"
    bare.mkdir()
    for f in folder.iterdir():
        (bare / f.name).write_bytes(f.read_bytes())
    for name in ("walk_a_imu.csv", "walk_b_imu.csv"):
        frame = pd.read_csv(bare / name)
        frame.drop(columns="gyro_z").to_csv(bare / name, index=False)
    ds2 = me.load(bare)
    assert ds2.recording("walk_a").inertial.gyro_rad_s is None
    model2 = me.channel(me.calibrate(ds2))
    proto2 = me.protocol(ds2, model2)
    assert proto2.inertial["walk_a"].trackers == ("kf_acc", "ekf_rss_acc")
    assert proto2.inertial["walk_a"].heading_rad is None
    frames = [r for r in proto2.rows() if r["setting"].startswith("accelerometer frame")]
    assert len(frames) == 2 and all(r["value"].startswith("world") for r in frames)
    res2 = me.tracking_results(ds2, model2, proto2, seed=11, n_particles=100, particle_runs=1, n_bootstrap=20,
                               block_s=10.0, recordings=["walk_b"])
    assert res2["fusion"] == ["kf_acc", "ekf_rss_acc"]
    assert {r["method"] for r in res2["rows"]} >= {"ekf", "kf_acc", "ekf_rss_acc"}
    assert not {"ekf_rss_imu", "ukf_rss_imu"} & {r["method"] for r in res2["rows"]}
