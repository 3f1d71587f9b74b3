"""Your own data, judged fairly: the data format without guesses. 2-D data sets (anchors without z),
native scans (window_s = 0) and their clock, the truth a windowed epoch gets, the link direction named when the
columns are swapped, devices (a device column, the notes, the joint per-device offset fit), calibration-only data
sets and the example generator's variants. Every fixture is written in tmp_path; expected numbers come from the
fixture's own construction or an independent numpy computation in the test."""
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from builders import REPO_ROOT
from locbook.data.dataset import load_dataset
from locbook.data.example import EXAMPLE_ROLES, EXAMPLE_SITE, write_example_dataset
from locbook.data.measured import (
    LINK_DIRECTION_RULE,
    DataFormatError,
    Epochs,
    epochs,
    read_anchors,
    scan_interval_s,
    validate_readings,
)
from locbook.errors import DegenerateGeometryError, ParameterError
from locbook.static.calibration import calibrate_path_loss, calibrate_path_loss_devices

ANCHORS_XY = {"A": (0.0, 0.0), "B": (6.0, 0.0), "C": (0.0, 6.0), "D": (6.0, 6.0)}
ANCHORS_2D = "id,x,y\n" + "".join(f"{a},{x:g},{y:g}\n" for a, (x, y) in ANCHORS_XY.items())
ANCHORS_3D = "id,x,y,z\nA,0,0,2.1\nB,6,0,2.5\nC,0,6,2.3\nD,6,6,2.4\n"
HEAD = "time_s,transmitter,receiver,rssi_dbm,x_m,y_m"


def rss_2d(x, y, anchor):
    """-40 - 20 log10 d in whole dBm, d in the plane."""
    ax, ay = ANCHORS_XY[anchor]
    return round(-40 - 20 * np.log10(max(np.hypot(x - ax, y - ay), 0.1)))


def cal_rows(points, *, t0=0.0, tx="tag", device=None, z=None):
    """One row per anchor at each point, one point per second."""
    out = []
    for k, (x, y) in enumerate(points):
        for a in ANCHORS_XY:
            row = f"{t0 + k:g},{tx},{a},{rss_2d(x, y, a)},{x:g},{y:g}"
            row += "" if z is None else f",{z:g}"
            row += "" if device is None else f",{device}"
            out.append(row + "\n")
    return "".join(out)


CAL_POINTS = [(1.0, 1.0), (2.0, 4.0), (4.0, 2.0), (5.0, 5.0), (3.0, 3.0)]


def manifest(recordings, *, window="1.0", geometry_extra="", name="fmt46"):
    text = (f'name = "{name}"\ntitle = "format test set"\nlicense = "CC0 1.0"\nattribution = "test"\n'
            f'[geometry]\nanchors = "anchors.csv"\n{geometry_extra}[epochs]\nwindow_s = {window}\n')
    for rname, (role, _, extra) in recordings.items():
        text += f'[[recording]]\nname = "{rname}"\nfile = "{rname}.csv"\nrole = "{role}"\n{extra}'
    return text


def write_set(folder: Path, recordings, *, anchors=ANCHORS_2D, **kw) -> Path:
    """recordings: name -> (role, csv text, extra manifest lines)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "anchors.csv").write_text(anchors)
    for rname, (_, text, _) in recordings.items():
        (folder / f"{rname}.csv").write_text(text)
    (folder / "dataset.toml").write_text(manifest(recordings, **kw))
    return folder


def refused(folder, recordings, *needles, **kw):
    with pytest.raises(DataFormatError) as info:
        load_dataset(write_set(folder, recordings, **kw))
    for needle in needles:
        assert needle in str(info.value), str(info.value)
    return str(info.value)


TRACK_2D = HEAD + "\n" + "".join(f"{0.5 * k:g},tag,{a},{rss_2d(1 + k, 3, a)},{1 + k:g},3\n"
                                 for k in range(5) for a in ANCHORS_XY)


# -- 1. 2-D data sets ------------------------------------------------------------------------------------------
def test_a_2d_data_set_has_plane_anchors_no_tag_height_and_ignores_true_heights(tmp_path):
    cal = HEAD + ",z_m\n" + cal_rows(CAL_POINTS, z=1.7)
    ds = load_dataset(write_set(tmp_path, {"cal": ("calibration", cal, ""), "walk": ("track", TRACK_2D, "")},
                                window="0.5"))
    assert ds.dimension == 2 and ds.tag_height_m is None
    np.testing.assert_array_equal(ds.anchors_m, np.array(list(ANCHORS_XY.values())))
    assert ds.geometry_text.startswith("2-D") and "in the plane" in ds.geometry_text
    ep = ds.epochs("cal")
    assert np.isnan(ep.position_m[:, 2]).all()                       # z_m ignored, not the tag's height
    np.testing.assert_array_equal(ep.position_m[:, :2], np.array(CAL_POINTS))
    assert "z_m" in ds.notes and "'cal'" in ds.notes["z_m"] and "ignored" in ds.notes["z_m"]
    assert "tag_height_m" not in ds.notes


def test_a_2d_data_set_scales_its_plane_coordinates(tmp_path):
    cm = "id,x,y\n" + "".join(f"{a},{100 * x:g},{100 * y:g}\n" for a, (x, y) in ANCHORS_XY.items())
    def to_cm(line):
        *head, x, y = line.split(",")
        return ",".join([*head, f"{100 * float(x):g}", f"{100 * float(y):g}"]) + "\n"

    cal = HEAD + "\n" + "".join(to_cm(line) for line in cal_rows(CAL_POINTS).splitlines())
    folder = write_set(tmp_path, {"cal": ("calibration", cal, "")}, anchors=cm)
    text = (folder / "dataset.toml").read_text().replace("[geometry]", '[units]\nlength = "cm"\n[geometry]')
    (folder / "dataset.toml").write_text(text)
    ds = load_dataset(folder)
    assert ds.anchors_m.shape == (4, 2)
    np.testing.assert_allclose(ds.anchors_m, np.array(list(ANCHORS_XY.values())))
    np.testing.assert_allclose(ds.epochs("cal").position_m[:, :2], np.array(CAL_POINTS))


def test_a_tag_height_in_a_2d_manifest_is_refused_in_one_line(tmp_path):
    message = refused(tmp_path, {"cal": ("calibration", HEAD + "\n" + cal_rows(CAL_POINTS), "")},
                      "[geometry] tag_height_m", "anchors have no z: a 2-D data set has no tag height",
                      geometry_extra="tag_height_m = 1.2\n")
    assert "\n" not in message


def test_anchors_with_some_heights_missing_are_refused_naming_the_line(tmp_path):
    mixed = "id,x,y,z\nA,0,0,2.5\nB,6,0,2.5\nC,0,6,\nD,6,6,\n"
    refused(tmp_path, {"cal": ("calibration", HEAD + "\n" + cal_rows(CAL_POINTS), "")}, "anchors file",
            "line 4", "'z'", "2 of the 4 anchors have none", "no z column", anchors=mixed)
    path = tmp_path / "a.csv"
    path.write_text(ANCHORS_2D)
    table = read_anchors(path)
    assert list(table.columns) == ["id", "x", "y"]
    path.write_text("id,x,y\nA,0,0\nB,0.0,0.0005\nC,5,0\n")            # separation is checked in the plane
    with pytest.raises(DataFormatError, match="columns 'x','y': anchors 'A' and 'B'"):
        read_anchors(path)


def test_a_3d_geometry_text_names_the_anchor_heights_and_the_tag_height_source(tmp_path):
    cal = HEAD + ",z_m\n" + cal_rows(CAL_POINTS[:3], z=1.8) + cal_rows(CAL_POINTS[3:], t0=10, z=1.9)
    ds = load_dataset(write_set(tmp_path / "median", {"cal": ("calibration", cal, "")}, anchors=ANCHORS_3D))
    z = np.array([2.1, 2.5, 2.3, 2.4])
    heights = np.r_[np.full(12, 1.8), np.full(8, 1.9)]
    assert ds.dimension == 3 and ds.anchors_m.shape == (4, 3) and ds.tag_height_m == np.median(heights)
    assert ds.geometry_text == (f"3-D distances: anchors at {z.min():g}-{z.max():g} m, the tag at its known height "
                                f"{np.median(heights):g} m (median of the true z)")
    given = load_dataset(write_set(tmp_path / "given", {"cal": ("calibration", cal, "")}, anchors=ANCHORS_3D,
                                   geometry_extra="tag_height_m = 1.25\n"))
    assert given.geometry_text.endswith("the tag at its known height 1.25 m ([geometry] tag_height_m)")


# -- 2. native scans ---------------------------------------------------------------------------------------------
SCAN_TIMES = [0.0, 1.0, 2.1, 3.0, 7.5, 8.4, 9.5]          # irregular, with one long pause: median != mean


def scan_track(times, *, tx="tag"):
    return HEAD + "\n" + "".join(f"{t:g},{tx},{a},{rss_2d(1 + 0.5 * k, 3, a)},{1 + 0.5 * k:g},3\n"
                                 for k, t in enumerate(times) for a in ANCHORS_XY)


@pytest.mark.parametrize("where", ["global", "recording"])
def test_a_track_of_native_scans_loads_with_one_epoch_per_scan_time(tmp_path, where):
    recs = {"cal": ("calibration", HEAD + "\n" + cal_rows(CAL_POINTS), ""),
            "walk": ("track", scan_track(SCAN_TIMES), "window_s = 0\n" if where == "recording" else "")}
    ds = load_dataset(write_set(tmp_path, recs, window="0" if where == "global" else "1.0"))
    ep = ds.epochs("walk")
    np.testing.assert_array_equal(ep.time_s, SCAN_TIMES)
    rows = pd.read_csv(tmp_path / "walk.csv")
    expected = rows.pivot(index="time_s", columns="receiver", values="rssi_dbm")[list(ANCHORS_XY)].to_numpy(float)
    np.testing.assert_array_equal(ep.rss_dbm, expected)
    assert ds.scan_interval_s("walk") == np.median(np.diff(np.unique(rows["time_s"])))
    assert ds.scan_interval_s("cal") == (1.0 if where == "recording" else np.median(np.diff(np.arange(5.0))))


def test_scan_interval_is_the_median_spacing_and_refuses_what_has_no_clock(tmp_path):
    recs = {"cal": ("calibration", HEAD + "\n" + cal_rows(CAL_POINTS), ""),
            "walk": ("track", scan_track(SCAN_TIMES), "")}
    ds = load_dataset(write_set(tmp_path, recs, window="0"))
    ep = ds.epochs("walk")
    assert scan_interval_s(ep) == np.median(np.diff(np.sort(np.asarray(SCAN_TIMES))))
    assert scan_interval_s(ep) != np.mean(np.diff(SCAN_TIMES))
    with pytest.raises(ParameterError, match="recording 'walk': 1 epoch"):
        scan_interval_s(ep.select(slice(0, 1)), name="walk")
    same = Epochs(np.zeros(3), np.full((3, 4), -60.0), np.full((3, 3), np.nan), np.full(3, np.nan),
                  np.array(["tag"] * 3, dtype=object), tuple(ANCHORS_XY))
    with pytest.raises(ParameterError, match="recording 'x': the median spacing .* is 0 s"):
        scan_interval_s(same, name="x")
    two = Epochs(np.arange(4.0), np.full((4, 4), -60.0), np.full((4, 3), np.nan), np.full(4, np.nan),
                 np.array(["a", "b", "a", "b"], dtype=object), tuple(ANCHORS_XY))
    with pytest.raises(ParameterError, match="2 transmitter"):
        scan_interval_s(two, name="y")


def test_a_native_scan_track_with_one_scan_time_is_refused_at_load(tmp_path):
    recs = {"cal": ("calibration", HEAD + "\n" + cal_rows(CAL_POINTS), ""),
            "walk": ("track", scan_track([4.0]), "window_s = 0\n")}
    refused(tmp_path, recs, "[[recording]] 'walk'", "at least 2 epochs", "makes 1 as native scans", "window_s = 0")


# -- 3. the truth of a windowed epoch ----------------------------------------------------------------------------
def test_a_windowed_epoch_gets_the_mean_of_its_rows_true_positions_and_nan_without_any():
    rng = np.random.default_rng(46)
    t = np.sort(np.r_[0.0, rng.uniform(0.0, 4.4, 39)])     # the clock starts at the first reading, t = 0
    x, y = 0.7 * t + rng.normal(0, 0.01, 40), np.full(40, 2.0)
    known = np.ones(40, bool)
    known[(t >= 2.5) & (t < 3.5)] = False                 # the window of tick 3 has no truth at all
    table = pd.DataFrame({"time_s": t, "transmitter": "tag", "receiver": rng.choice(list("AB"), 40),
                          "rssi_dbm": -60.0, "x_m": np.where(known, x, np.nan), "y_m": np.where(known, y, np.nan)})
    table = table.drop_duplicates(["time_s", "transmitter", "receiver"])
    ep = epochs(validate_readings(table, source="test"), ["A", "B"], window_s=1.0)
    tick = np.floor(table["time_s"].to_numpy() / 1.0 + 0.5)            # the windows [k - 1/2, k + 1/2)
    for k, time in enumerate(ep.time_s):
        rows = table[(tick == time) & table["x_m"].notna().to_numpy()]
        if len(rows):
            assert ep.position_m[k, 0] == pytest.approx(rows["x_m"].mean(), abs=1e-12)
            assert ep.position_m[k, 1] == 2.0                          # constant within the window: kept exactly
        else:
            assert time == 3.0 and np.isnan(ep.position_m[k]).all()
    assert 3.0 in ep.time_s and len(ep) == 5


# -- 4. link direction -------------------------------------------------------------------------------------------
def test_swapped_link_columns_name_the_rule(tmp_path):
    cal = HEAD + "\n" + cal_rows(CAL_POINTS)
    swapped = "\n".join([HEAD] + [",".join([f[0], f[2], f[1], *f[3:]]) for f in
                                  (line.split(",") for line in cal.splitlines()[1:])]) + "\n"
    message = refused(tmp_path, {"cal": ("calibration", swapped, "")}, "column 'receiver'", "'tag' is not an anchor id",
                      "swapped", "always goes in 'receiver'", "whichever end physically transmits")
    assert "\n" not in message
    # not swapped, just unknown: the rule is still said
    unknown = cal.replace(",tag,D,", ",tag,E,", 1)
    refused(tmp_path / "u", {"cal": ("calibration", unknown, "")}, "'E' is not an anchor id", LINK_DIRECTION_RULE)
    table = validate_readings(pd.read_csv(tmp_path / "cal.csv"), source="t")
    with pytest.raises(DataFormatError, match="swapped"):
        epochs(table, list(ANCHORS_XY))


# -- 5. devices --------------------------------------------------------------------------------------------------
def test_epochs_carry_their_device_and_default_to_the_transmitter(tmp_path):
    two = (HEAD + ",device\n" + cal_rows(CAL_POINTS, device="phone-a")
           + cal_rows(CAL_POINTS[:3], t0=20, device="phone-b"))
    track = TRACK_2D.replace("\n", ",phone-c\n").replace("y_m,phone-c", "y_m,device", 1)
    ds = load_dataset(write_set(tmp_path, {"cal": ("calibration", two, ""), "walk": ("track", track, "")},
                                window="0.5"))
    ep = ds.epochs("cal")
    assert ep.device.dtype == object and ep.device.shape == (len(ep),)
    assert ds.devices("cal") == ("phone-a", "phone-b") and ds.devices("walk") == ("phone-c",)
    assert "device" not in ep.extra
    assert "phone-a (5 epochs)" in ds.notes["devices"].replace("'", "") and \
        "phone-b (3 epochs)" in ds.notes["devices"].replace("'", "")
    note = ds.notes["uncalibrated device walk"]
    assert "'walk'" in note and "'phone-c'" in note and "its receiver offset is not calibrated: assumed 0 dB" in note
    plain = load_dataset(write_set(tmp_path / "plain", {"cal": ("calibration", HEAD + "\n" + cal_rows(CAL_POINTS), ""),
                                                        "walk": ("track", TRACK_2D, "")}, window="0.5"))
    np.testing.assert_array_equal(plain.epochs("walk").device, plain.epochs("walk").transmitter)
    assert "devices" not in plain.notes and not any(k.startswith("uncalibrated") for k in plain.notes)
    # a window never mixes two devices: both phones at the same times and place give two epochs each second
    both = HEAD + ",device\n" + cal_rows(CAL_POINTS, device="p1") + cal_rows(CAL_POINTS, tx="tag2", device="p2")
    same_tx = both.replace(",tag2,", ",tag,")
    rows = pd.read_csv(pd.io.common.StringIO(same_tx))
    rows["time_s"] = rows["time_s"] + np.where(rows["device"] == "p2", 0.25, 0.0)   # no repeated (t, tx, rx)
    ep2 = epochs(validate_readings(rows, source="t", sort=True), list(ANCHORS_XY), window_s=1.0)
    assert len(ep2) == 2 * len(CAL_POINTS) and sorted(set(ep2.device)) == ["p1", "p2"]


def test_a_track_with_two_devices_or_an_empty_device_is_refused(tmp_path):
    cal = HEAD + "\n" + cal_rows(CAL_POINTS)
    lines = TRACK_2D.splitlines()
    two = "\n".join([lines[0] + ",device"] + [f"{r},{'a' if i < 8 else 'b'}" for i, r in enumerate(lines[1:])]) + "\n"
    refused(tmp_path, {"cal": ("calibration", cal, ""), "walk": ("track", two, "")}, "holds 2 devices",
            "a track follows one tag", window="0.5")
    empty = two.replace(",b\n", ",\n", 1)
    refused(tmp_path / "e", {"cal": ("calibration", cal, ""), "walk": ("track", empty, "")}, "line 10",
            "column 'device'", "the device is empty", window="0.5")


def _channel(rng, n_loc=60, m=5):
    distance = rng.uniform(0.8, 20.0, (n_loc, m))
    ref = rng.uniform(-50, -38, m)
    exp = rng.uniform(1.6, 3.2, m)
    return distance, ref, exp


def _joint_design(distance, rss, device, names, ref_distance_m=1.0):
    """The full design of rss = P0_a - n_a L + o_d (columns P0_1..m, n_1..m, o of names[1:]) over finite readings,
    built independently of the library."""
    n_loc, m = rss.shape
    rows, y, anchor = [], [], []
    for i in range(n_loc):
        for a in range(m):
            if np.isfinite(rss[i, a]):
                row = np.zeros(2 * m + len(names) - 1)
                row[a] = 1.0
                row[m + a] = -10.0 * np.log10(distance[i, a] / ref_distance_m)
                if device[i] != names[0]:
                    row[2 * m + names.index(device[i]) - 1] = 1.0
                rows.append(row), y.append(rss[i, a]), anchor.append(a)
    return np.array(rows), np.array(y), np.array(anchor)


def test_the_joint_fit_recovers_known_device_offsets_from_noiseless_readings():
    rng = np.random.default_rng(7)
    distance, ref, exp = _channel(rng)
    truth = {"pixel": 0.0, "iphone": -4.5, "galaxy": 2.25}
    device = rng.choice(list(truth), len(distance))
    rss = ref - 10 * exp * np.log10(distance) + np.array([truth[d] for d in device])[:, None]
    rss[rng.random(rss.shape) < 0.15] = np.nan
    fit, offsets = calibrate_path_loss_devices(distance, rss, device, reference="pixel")
    assert offsets.keys() == truth.keys()
    for d in truth:
        assert offsets[d] == pytest.approx(truth[d], abs=1e-9)
    np.testing.assert_allclose(fit.ref_power_dbm, ref, atol=1e-9)
    np.testing.assert_allclose(fit.path_loss_exp, exp, atol=1e-10)
    np.testing.assert_allclose(fit.residual_sigma_db, 0.0, atol=1e-9)
    np.testing.assert_array_equal(fit.n_samples, np.isfinite(rss).sum(axis=0))
    assert fit.ok and fit.status == "closed_form"
    # the default reference is the device with most finite readings; offsets move with it
    counts = {d: int(np.isfinite(rss[device == d]).sum()) for d in truth}
    default = max(sorted(counts), key=lambda d: counts[d])
    _, shifted = calibrate_path_loss_devices(distance, rss, device)
    for d in truth:
        assert shifted[d] == pytest.approx(truth[d] - truth[default], abs=1e-9)
    assert shifted[default] == 0.0


def test_the_joint_fit_is_the_least_squares_solution_of_the_full_design_with_its_covariance():
    rng = np.random.default_rng(8)
    distance, ref, exp = _channel(rng, n_loc=80, m=4)
    names = ["a", "b", "c"]
    device = rng.choice(names, len(distance), p=[0.5, 0.3, 0.2])
    sigma = np.array([2.0, 4.0, 3.0, 5.0])
    rss = (ref - 10 * exp * np.log10(distance) + np.array([{"a": 0, "b": 3, "c": -2}[d] for d in device])[:, None]
           + sigma * rng.standard_normal(distance.shape))
    rss[rng.random(rss.shape) < 0.2] = np.nan
    fit, offsets = calibrate_path_loss_devices(distance, rss, device, reference="a", ref_distance_m=2.0)
    X, y, anchor = _joint_design(distance, rss, device, names, ref_distance_m=2.0)
    theta = np.linalg.lstsq(X, y, rcond=None)[0]
    m = 4
    np.testing.assert_allclose(fit.ref_power_dbm, theta[:m], rtol=0, atol=1e-9)
    np.testing.assert_allclose(fit.path_loss_exp, theta[m:2 * m], rtol=0, atol=1e-9)
    np.testing.assert_allclose([offsets["b"], offsets["c"]], theta[2 * m:], rtol=0, atol=1e-9)
    assert offsets["a"] == 0.0
    # residual sigma: SSR per anchor over its share of the degrees of freedom (k = 2 offsets)
    resid = y - X @ theta
    n_a = np.bincount(anchor, minlength=m)
    ssr = np.bincount(anchor, weights=resid**2, minlength=m)
    s2 = ssr / (n_a - 2 - 2 * n_a / len(y))
    np.testing.assert_allclose(fit.residual_sigma_db, np.sqrt(s2), rtol=1e-10)
    # covariance: the OLS sandwich under per-anchor noise, its (P0_a, n_a) blocks
    inv = np.linalg.inv(X.T @ X)
    full = inv @ (X.T * s2[anchor]) @ X @ inv
    for a in range(m):
        block = full[np.ix_([a, m + a], [a, m + a])]
        np.testing.assert_allclose(fit.covariance[a], block, rtol=1e-8, atol=1e-12)


def test_with_one_device_the_joint_fit_is_the_per_anchor_closed_form():
    rng = np.random.default_rng(9)
    distance, ref, exp = _channel(rng)
    rss = ref - 10 * exp * np.log10(distance) + 3.0 * rng.standard_normal(distance.shape)
    rss[rng.random(rss.shape) < 0.25] = np.nan
    fit, offsets = calibrate_path_loss_devices(distance, rss, np.full(len(distance), "only"))
    plain = calibrate_path_loss(distance, rss, "per_anchor", solver="closed_form")
    assert offsets == {"only": 0.0}
    for field in ("ref_power_dbm", "path_loss_exp", "residual_sigma_db", "covariance", "n_samples"):
        np.testing.assert_allclose(getattr(fit, field), getattr(plain, field), rtol=1e-9, atol=1e-12)
    assert fit.status == plain.status and (fit.problem_status == plain.problem_status).all()
    assert type(fit) is type(plain) and fit.ref_power_dbm.shape == plain.ref_power_dbm.shape


def test_the_joint_fit_refuses_what_cannot_be_fitted():
    rng = np.random.default_rng(10)
    distance, ref, exp = _channel(rng, n_loc=12, m=3)
    rss = ref - 10 * exp * np.log10(distance)
    device = np.array(["a"] * 6 + ["b"] * 6)
    silent = rss.copy()
    silent[6:] = np.nan
    with pytest.raises(DegenerateGeometryError, match="device 'b' has no finite reading"):
        calibrate_path_loss_devices(distance, silent, device)
    one_distance = rss.copy()
    one_distance[1:, 2] = np.nan                       # anchor 2 heard at one distance only
    with pytest.raises(DegenerateGeometryError, match=r"anchor\(s\) \[2\].*fewer than two distinct distances"):
        calibrate_path_loss_devices(distance, one_distance, device)
    apart = rss.copy()
    apart[:6, 2], apart[6:, :2] = np.nan, np.nan       # device b hears only anchor 2, which device a never hears
    with pytest.raises(DegenerateGeometryError, match=r"device\(s\) \['b'\] share no anchor"):
        calibrate_path_loss_devices(distance, apart, device, reference="a")
    with pytest.raises(ParameterError, match="reference 'z' is not one of the devices"):
        calibrate_path_loss_devices(distance, rss, device, reference="z")
    with pytest.raises(ParameterError, match=r"device must give one device per location, shape \(12,\)"):
        calibrate_path_loss_devices(distance, rss, device[:5])
    with pytest.raises(ParameterError, match="empty or missing device name"):
        calibrate_path_loss_devices(distance, rss, np.r_[device[:11], [""]])


# -- 6. calibration-only data sets -------------------------------------------------------------------------------
def test_a_calibration_only_data_set_loads(tmp_path):
    ds = load_dataset(write_set(tmp_path, {"cal": ("calibration", HEAD + "\n" + cal_rows(CAL_POINTS), "")}))
    assert ds.has_role("calibration") and not ds.has_role("static") and not ds.has_role("track")
    assert len(ds.epochs("cal")) == len(CAL_POINTS) and "calibration only" in ds.notes["scoring"]
    with pytest.raises(ParameterError, match="role must be one of"):
        ds.has_role("walk")
    refused(tmp_path / "none", {"pts": ("static", HEAD + "\n" + cal_rows(CAL_POINTS), "")},
            "no recording has role 'calibration'")


# -- 7. the example generator's variants -------------------------------------------------------------------------
def test_the_example_defaults_are_todays_options(tmp_path):
    a = write_example_dataset(tmp_path / "a", np.random.default_rng(2), walk_s=10.0)
    b = write_example_dataset(tmp_path / "b", np.random.default_rng(2), walk_s=10.0,
                              speed_m_s=EXAMPLE_SITE["walk_speed_m_s"], roles=("calibration", "static", "track"),
                              two_d=False, native_scans=False)
    files = sorted(p.name for p in a.iterdir())
    assert files == sorted(p.name for p in b.iterdir())
    assert all((a / f).read_bytes() == (b / f).read_bytes() for f in files)
    assert files == ["anchors.csv", "dataset.toml", "outline.csv", "points.csv", "survey.csv", "walk_a.csv",
                     "walk_b.csv"]


def test_a_2d_example_has_plane_anchors_and_no_tag_height(tmp_path):
    ds = load_dataset(write_example_dataset(tmp_path / "e", np.random.default_rng(3), walk_s=10.0, two_d=True))
    assert ds.dimension == 2 and ds.anchors_m.shape == (len(EXAMPLE_SITE["anchors_m"]), 2) and ds.tag_height_m is None
    np.testing.assert_array_equal(ds.anchors_m, EXAMPLE_SITE["anchors_m"][:, :2])
    assert (tmp_path / "e" / "anchors.csv").read_text().splitlines()[0] == "id,x,y"


def test_a_native_scan_example_writes_scans_on_the_scan_clock(tmp_path):
    walk_s = 12.0
    ds = load_dataset(write_example_dataset(tmp_path / "e", np.random.default_rng(4), walk_s=walk_s,
                                            native_scans=True))
    rate = EXAMPLE_SITE["scan_rate_hz"]
    for name in ("walk_a", "walk_b"):
        assert ds.recording(name).epoch_rule.window_s == 0
        rows = pd.read_csv(tmp_path / "e" / f"{name}.csv")
        times = np.unique(rows["time_s"])
        assert len(ds.epochs(name)) == len(times) and len(times) <= int(walk_s * rate)
        assert ds.scan_interval_s(name) == pytest.approx(np.median(np.diff(times)))
        assert ds.scan_interval_s(name) == pytest.approx(1.0 / rate)
    assert ds.recording("survey").epoch_rule.window_s == 1.0            # the other recordings keep their window


@pytest.mark.parametrize("roles,names", [(("calibration", "static"), {"survey", "points"}),
                                         (("calibration", "track"), {"survey", "walk_a", "walk_b"}),
                                         (("calibration",), {"survey"})])
def test_an_example_of_some_roles_writes_those_recordings(tmp_path, roles, names):
    ds = load_dataset(write_example_dataset(tmp_path / "e", np.random.default_rng(5), walk_s=10.0, roles=roles))
    assert set(ds.recordings) == names
    assert {p.stem for p in (tmp_path / "e").glob("*.csv")} == names | {"anchors", "outline"}
    for role in EXAMPLE_ROLES:
        assert ds.has_role(role) == (role in roles)


def test_the_example_walker_moves_at_the_given_speed(tmp_path):
    speed = 0.6
    folder = write_example_dataset(tmp_path / "e", np.random.default_rng(6), walk_s=20.0, speed_m_s=speed,
                                   roles=("calibration", "track"))
    rows = pd.read_csv(folder / "walk_a.csv").drop_duplicates("time_s").sort_values("time_s")
    # the packets' times carry each anchor's phase; the positions are those of the packet clock's ticks
    xy = rows[["x_m", "y_m"]].drop_duplicates().to_numpy()
    step = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    assert np.median(step) == pytest.approx(speed / EXAMPLE_SITE["packet_rate_hz"], abs=2e-3)   # 3-decimal truth


def test_the_example_refuses_bad_variants(tmp_path):
    with pytest.raises(ParameterError, match="'calibration' among them"):
        write_example_dataset(tmp_path / "a", np.random.default_rng(0), roles=("static",))
    with pytest.raises(ParameterError, match="roles must be some of"):
        write_example_dataset(tmp_path / "b", np.random.default_rng(0), roles=("calibration", "walk"))
    with pytest.raises(ParameterError, match="speed_m_s must be a positive finite speed"):
        write_example_dataset(tmp_path / "c", np.random.default_rng(0), speed_m_s=0.0)
    with pytest.raises(ParameterError, match="two_d must be True or False"):
        write_example_dataset(tmp_path / "d", np.random.default_rng(0), two_d="yes")
    assert not any((tmp_path / n).exists() for n in "abcd")


# -- 8. the documented 2-D example loads ---------------------------------------------------------------------------
def test_the_documented_2d_example_loads(tmp_path):
    doc = REPO_ROOT / "docs" / "data-format.md"
    if not doc.exists():
        pytest.skip("the docs are not beside the tests (an installed package)")
    section = doc.read_text(encoding="utf-8").split("## 2-D data sets", 1)[1].split("\n## ", 1)[0]
    toml = re.search(r"```toml\n(.*?)```", section, re.S)[1]
    anchors = re.search(r"```csv\n(.*?)```", section, re.S)[1]
    (tmp_path / "dataset.toml").write_text(toml)
    (tmp_path / "anchors.csv").write_text(anchors)
    table = pd.read_csv(pd.io.common.StringIO(anchors))
    beacons = dict(zip(table["id"], zip(table["x"], table["y"])))

    def power(x, y, b):
        return round(-40 - 20 * np.log10(max(np.hypot(x - beacons[b][0], y - beacons[b][1]), 0.1)))

    survey = [(1, 1), (2, 4), (6, 2), (7, 5)]
    (tmp_path / "survey.csv").write_text(HEAD + ",point\n" + "".join(
        f"{k},phone,{b},{power(x, y, b)},{x},{y},P{k}\n" for k, (x, y) in enumerate(survey) for b in beacons))
    (tmp_path / "walk.csv").write_text(HEAD + "\n" + "".join(
        f"{k},phone,{b},{power(1 + k, 3, b)},{1 + k},3\n" for k in range(5) for b in beacons))
    ds = load_dataset(tmp_path)
    assert ds.dimension == 2 and ds.tag_height_m is None and ds.anchors_m.shape == (len(beacons), 2)
    assert ds.has_role("track") and len(ds.epochs("walk")) == 5
