"""Range streams: the ranges file of a recording (reader, checks, alignment on the RSS epochs), the range
measurement model on the protocol (hand distances, finite differences, filterpy's EKF and UKF), range-only lateration
and its CRLB (noiseless truth, a Monte-Carlo at high SNR, the outline), and the range methods in the measured battery
on the example data set with ranges (known truth), which leave every other number as it was."""
import hashlib
import textwrap

import numpy as np
import pandas as pd
import pytest

import locbook as lb
from locbook.data.example import write_example_dataset
from locbook.data.measured import DataFormatError
from locbook.scenarios import measured as me
from locbook.scenarios import measured_ranges as mr

filterpy_kalman = pytest.importorskip("filterpy.kalman")

ANCHORS_3D = np.array([[0.0, 0.0, 2.5], [10.0, 0.0, 2.8], [10.0, 8.0, 2.6], [0.0, 8.0, 3.0]])
TAG_M = 1.2


# -- the ranges file ----------------------------------------------------------------------------------------------

def _tiny(folder, ranges_text: str, *, window: str = "1.0", units: str = "", readings: str | None = None,
          point: bool = False):
    """A data set of one calibration recording (4 anchors, one tag) with a ranges file."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "anchors.csv").write_text("id,x,y,z\nA,0,0,2.5\nB,10,0,2.8\nC,10,8,2.6\nD,0,8,3.0\n")
    if readings is None:
        rows = ["time_s,transmitter,receiver,rssi_dbm,x_m,y_m" + (",point" if point else "")]
        for k in range(6):
            for j, a in enumerate("ABCD"):
                t = 0.1 + k + 0.05 * j
                rows.append(f"{t:g},tag,{a},{-50 - 3 * j - k},{2 + 0.5 * k:g},3" + (f",P{k // 3}" if point else ""))
        readings = "\n".join(rows) + "\n"
    (folder / "walk.csv").write_text(readings)
    (folder / "walk_ranges.csv").write_text(textwrap.dedent(ranges_text).lstrip())
    (folder / "dataset.toml").write_text(textwrap.dedent(f"""
        name = "tiny"
        title = "t"
        license = "CC0 1.0"
        attribution = "a"
        {units}
        [geometry]
        anchors = "anchors.csv"
        tag_height_m = 1.2
        [epochs]
        window_s = {window}
        [[recording]]
        name = "walk"
        file = "walk.csv"
        role = "calibration"
        ranges = "walk_ranges.csv"
        """ + ('point_column = "point"\n' if point else "")))
    return folder


GOOD = """
    time_s,transmitter,receiver,range_m,range_std_m
    0.0,tag,A,3.1,0.2
    0.4,tag,A,3.3,0.4
    0.6,tag,B,8.0,0.3
    1.2,tag,C,,0.3
    1.59,tag,C,9.5,0.1
    1.61,tag,C,9.7,0.2
    3.3,tag,D,4.4,0.5
    9.0,tag,D,4.0,0.5
    """


def test_a_good_ranges_file_loads_and_joins_the_data_sets_files(tmp_path):
    ds = lb.load_dataset(_tiny(tmp_path / "d", GOOD))
    rec = ds.recording("walk")
    assert list(rec.ranges.columns[:5]) == ["time_s", "transmitter", "receiver", "range_m", "range_std_m"]
    assert np.isnan(rec.ranges["range_m"].iloc[3]) and rec.ranges["range_m"].iloc[4] == 9.5
    assert rec.ranges_file in ds.files and ds.has_ranges("walk")
    ranges, std = ds.ranges("walk")
    assert ranges.shape == std.shape == (len(ds.epochs("walk")), 4)
    assert "ranges walk" in ds.notes and "1 range(s)" in ds.notes["ranges walk"]      # 9.0 s: after the last epoch


@pytest.mark.parametrize("row, line, column, needle", [
    ("0.5,tag,A,-0.2,0.3", 3, "range_m", "is negative"),
    ("0.5,tag,A,inf,0.3", 3, "range_m", "not a finite number"),
    ("0.5,tag,Z,3.0,0.3", 3, "receiver", "not an anchor id"),
    ("0.5,tag,A,3.0,0", 3, "range_std_m", "not a standard deviation"),
    ("0.5,tag,A,3.0,", 3, "range_std_m", "missing while range_m is given"),
    ("0.5,other,A,3.0,0.3", 3, "transmitter", "has no readings"),
    ("0.0,tag,A,3.0,0.3", 3, "time_s','transmitter','receiver", "repeats line 2"),
    ("abc,tag,A,3.0,0.3", 3, "time_s", "not a finite number"),
    ("0.5,tag,A,1e8,0.3", 3, "range_m", "MAX_COORDINATE_M"),
])
def test_a_bad_range_is_one_line_naming_file_line_and_column(tmp_path, row, line, column, needle):
    text = "time_s,transmitter,receiver,range_m,range_std_m\n0.0,tag,A,3.1,0.2\n" + row + "\n"
    with pytest.raises(DataFormatError) as err:
        lb.load_dataset(_tiny(tmp_path / "d", text))
    message = str(err.value)
    assert "\n" not in message and "walk_ranges.csv" in message and f"line {line}" in message
    assert (f"column {column!r}" in message or f"columns '{column}'" in message) and needle in message


def test_a_missing_column_and_an_unknown_manifest_value_are_refused(tmp_path):
    with pytest.raises(DataFormatError, match=r"missing column\(s\) \['range_m'\]"):
        lb.load_dataset(_tiny(tmp_path / "a", "time_s,transmitter,receiver,distance\n0,tag,A,1\n"))
    folder = _tiny(tmp_path / "b", GOOD)
    (folder / "walk_ranges.csv").unlink()
    with pytest.raises(DataFormatError, match="ranges: file 'walk_ranges.csv' does not exist"):
        lb.load_dataset(folder)


def _independent_alignment(readings: pd.DataFrame, ranges: pd.DataFrame, window_s: float, anchors):
    """The window rule written again with pandas: tick k of [t0 + (k - 1/2) w, t0 + (k + 1/2) w) from the
    transmitter's first reading; per (tick, anchor) the mean range and sqrt(sum std^2) / n."""
    t0 = readings["time_s"].min()
    r = ranges.dropna(subset=["range_m"]).copy()
    r["tick"] = np.floor((r["time_s"] - t0) / window_s + 0.5 + 1e-9).astype(int)
    g = r.groupby(["tick", "receiver"])
    mean = g["range_m"].mean().unstack().reindex(columns=anchors)
    std = (np.sqrt(g["range_std_m"].apply(lambda s: (s ** 2).sum())) / g.size()).unstack().reindex(columns=anchors)
    return t0, mean, std


def test_alignment_equals_an_independent_groupby_on_the_same_windows(tmp_path):
    ds = lb.load_dataset(_tiny(tmp_path / "d", GOOD))
    ep = ds.epochs("walk")
    ranges, std = ds.ranges("walk")
    raw = pd.read_csv(tmp_path / "d" / "walk_ranges.csv")
    t0, mean, sd = _independent_alignment(pd.read_csv(tmp_path / "d" / "walk.csv"), raw, 1.0, list("ABCD"))
    for e, t in enumerate(ep.time_s):
        k = int(round((t - t0) / 1.0))
        want = mean.loc[k].to_numpy(float) if k in mean.index else np.full(4, np.nan)
        want_sd = sd.loc[k].to_numpy(float) if k in sd.index else np.full(4, np.nan)
        np.testing.assert_allclose(ranges[e], want, rtol=0, atol=1e-12)
        np.testing.assert_allclose(std[e], want_sd, rtol=0, atol=1e-12)
    # by hand: tick 0 holds 0.0 and 0.4 s of A (mean 3.2, sqrt(0.2^2 + 0.4^2) / 2) and 0.6 s of B (the window of
    # tick 1 starts at 0.1 + 0.5 = 0.6 s: half-open, so 0.6 s is tick 1's); 1.59 and 1.61 s of C split at 1.6 s
    assert ranges[0, 0] == pytest.approx(3.2) and std[0, 0] == pytest.approx(np.sqrt(0.2**2 + 0.4**2) / 2)
    assert ranges[1, 1] == 8.0 and ranges[1, 2] == 9.5 and ranges[2, 2] == 9.7 and ranges[3, 3] == 4.4
    assert np.isnan(ranges[0, 1]) and np.isnan(ranges[4:]).all()


def test_native_scans_align_at_equal_times_and_units_shift_with_the_readings_clock(tmp_path):
    ds = lb.load_dataset(_tiny(tmp_path / "n", GOOD, window="0"))
    _, (ranges, _) = ds.epochs("walk"), ds.ranges("walk")
    assert np.isnan(ranges).all() and ds.ranges("walk").unaligned == 7          # no range at a scan's time
    scans = "time_s,transmitter,receiver,range_m\n0.1,tag,A,3.0\n1.1,tag,B,7.0\n1.15,tag,B,7.5\n"
    ds = lb.load_dataset(_tiny(tmp_path / "m", scans, window="0"))
    ranges, std = ds.ranges("walk")
    e = {float(t): i for i, t in enumerate(ds.epochs("walk").time_s)}
    # each distinct time is a scan (the tiny readings' anchors log at 0.05 s steps): 1.15 s is one too
    assert std is None and ranges[e[0.1], 0] == 3.0 and ranges[e[1.1], 1] == 7.0 and ranges[e[1.15], 1] == 7.5
    assert np.isfinite(ranges).sum() == 3 and ds.ranges("walk").unaligned == 0
    # the same set in ms and cm, times from 1e6 ms: aligned on the same epochs with the same values
    ms = "time_s,transmitter,receiver,range_m,range_std_m\n" + "".join(
        f"{1_000_000 + round(1000 * t)},{tx},{rx},{'' if r != r else round(100 * r)},{round(100 * s)}\n"
        for t, tx, rx, r, s in pd.read_csv(tmp_path / "n" / "walk_ranges.csv").itertuples(index=False))
    readings = pd.read_csv(tmp_path / "n" / "walk.csv")
    readings["time_s"] = (1_000_000 + (1000 * readings["time_s"]).round()).astype(int)
    readings[["x_m", "y_m"]] *= 100
    seconds = lb.load_dataset(_tiny(tmp_path / "s", GOOD))
    scaled = lb.load_dataset(_tiny(tmp_path / "u", ms, units='[units]\ntime = "ms"\nlength = "cm"',
                                   readings=readings.to_csv(index=False)))
    shift = seconds.recording("walk").readings["time_s"].min()
    np.testing.assert_allclose(scaled.epochs("walk").time_s + shift, seconds.epochs("walk").time_s, atol=1e-9)
    for got, want in zip(scaled.ranges("walk"), seconds.ranges("walk")):
        np.testing.assert_allclose(got, want, atol=1e-9)


def test_a_window_of_two_points_needs_the_point_column(tmp_path):
    readings = ("time_s,transmitter,receiver,rssi_dbm,x_m,y_m,point\n0.0,tag,A,-50,1,1,P1\n0.2,tag,A,-51,1,1,P1\n"
                "0.4,tag,A,-60,5,5,P2\n1.0,tag,A,-61,5,5,P2\n")
    text = "time_s,transmitter,receiver,range_m\n0.1,tag,A,2.0\n"
    with pytest.raises(DataFormatError, match=r"line 2: .* several epochs of it .*'point'"):
        lb.load_dataset(_tiny(tmp_path / "a", text, readings=readings, point=True))
    ds = lb.load_dataset(_tiny(tmp_path / "b", text.replace("range_m\n", "range_m,point\n").replace("2.0", "2.0,P1"),
                               readings=readings, point=True))
    ep, (ranges, _) = ds.epochs("walk"), ds.ranges("walk")
    at = [i for i, p in enumerate(ep.extra["point"]) if p == "P1"]
    assert ranges[at[0], 0] == 2.0 and np.isfinite(ranges).sum() == 1


# -- the range measurement model ----------------------------------------------------------------------------------

def test_the_model_mean_is_the_distance_by_hand_in_3d_and_in_the_plane():
    p = np.array([[3.0, 4.0], [7.5, 1.0]])
    m3 = lb.RangeModel(ANCHORS_3D, 0.3, tag_height_m=TAG_M)
    hand = [[np.sqrt((x - a[0]) ** 2 + (y - a[1]) ** 2 + (a[2] - TAG_M) ** 2) for a in ANCHORS_3D] for x, y in p]
    np.testing.assert_allclose(m3.mean(p[:, None, :])[:, 0], hand, rtol=1e-15)
    m2 = lb.RangeModel(ANCHORS_3D[:, :2], 0.3)
    hand = [[np.hypot(x - a[0], y - a[1]) for a in ANCHORS_3D] for x, y in p]
    np.testing.assert_allclose(m2.mean(p[:, None, :])[:, 0], hand, rtol=1e-15)
    with pytest.raises(ValueError, match="sigma_m must be positive"):
        lb.RangeModel(ANCHORS_3D, [0.3, 0.0, 0.3, 0.3], tag_height_m=TAG_M)
    with pytest.raises(ValueError, match=r"\(m, 3\)"):
        lb.RangeModel(ANCHORS_3D[:, :2], 0.3, tag_height_m=TAG_M)


def test_the_jacobian_equals_finite_differences_in_a_state():
    model = lb.RangeModel(ANCHORS_3D, 0.3, tag_height_m=TAG_M, position_index=[0, 2])
    x = np.array([[[3.0, -1.0, 4.0, 0.5], [8.2, 0.3, 6.9, -0.2]]])           # (1, K = 2, n = 4): x at 0, y at 2
    H = model.jacobian(x)
    step = 1e-6
    for i in range(4):
        dx = np.zeros(4)
        dx[i] = step
        numeric = (model.mean(x + dx) - model.mean(x - dx)) / (2 * step)
        np.testing.assert_allclose(H[..., i], numeric, atol=1e-8)
    assert np.all(H[..., [1, 3]] == 0)


def _range_track(rng, T=40):
    cv = lb.constant_velocity(0.5, 0.05, dim=2)
    truth = np.empty((T, 4))
    x = np.array([2.0, 2.0, 0.4, 0.25])
    for k in range(T):
        x = cv.F @ x
        truth[k] = x
    sigma = 0.3 * rng.uniform(0.7, 1.3, (T, 4))                  # a reported std per step and anchor
    distance = np.linalg.norm(np.column_stack([truth[:, :2], np.full(T, TAG_M)])[:, None] - ANCHORS_3D, axis=-1)
    return cv, truth, sigma, distance + sigma * rng.standard_normal((T, 4))


def _hx(x):
    return np.linalg.norm(np.r_[x[:2], TAG_M] - ANCHORS_3D, axis=-1)


def _Hx(x):
    d = np.r_[x[:2], TAG_M] - ANCHORS_3D
    H = np.zeros((4, 4))
    H[:, :2] = d[:, :2] / np.linalg.norm(d, axis=-1)[:, None]
    return H


X0, P0 = np.array([2.5, 1.5, 0.0, 0.0]), np.diag([1.0, 1.0, 0.5, 0.5])


def test_the_ekf_with_a_range_stream_equals_filterpys():
    cv, truth, sigma, z = _range_track(np.random.default_rng(5))
    z[7, 1] = np.nan                                             # a range not measured
    model = lb.RangeModel(ANCHORS_3D, sigma, tag_height_m=TAG_M, position_index=[0, 1], per_step_sigma=True)
    run = lb.extended_kalman_filter(cv.F, cv.Q, X0[None], P0, [lb.Stream(z[None], model)])
    ekf = filterpy_kalman.ExtendedKalmanFilter(4, 4)
    ekf.x, ekf.P, ekf.F, ekf.Q = X0[:, None].copy(), P0.copy(), cv.F, cv.Q
    for k in range(len(z)):
        ekf.predict()
        ok = np.isfinite(z[k])
        ekf.update(z[k, ok][:, None], lambda x: _Hx(x[:, 0])[ok], lambda x: _hx(x[:, 0])[ok][:, None],
                   R=np.diag(sigma[k, ok] ** 2))
        np.testing.assert_allclose(run.mean[0, k], ekf.x[:, 0], atol=1e-9)
        np.testing.assert_allclose(run.cov[0, k], ekf.P, atol=1e-9)
    assert np.sqrt(np.mean(np.sum((run.mean[0, :, :2] - truth[:, :2]) ** 2, -1))) < 0.5


def test_the_ukf_with_a_range_stream_equals_filterpys():
    cv, truth, sigma, z = _range_track(np.random.default_rng(6))
    model = lb.RangeModel(ANCHORS_3D, sigma, tag_height_m=TAG_M, position_index=[0, 1], per_step_sigma=True)
    run = lb.unscented_kalman_filter(cv.F, cv.Q, X0[None], P0, [lb.Stream(z[None], model)], alpha=0.5)
    ukf = filterpy_kalman.UnscentedKalmanFilter(4, 4, 0.5, _hx, lambda x, dt: cv.F @ x,
                                                filterpy_kalman.MerweScaledSigmaPoints(4, 0.5, 2.0, 0.0))
    ukf.x, ukf.P, ukf.Q = X0.copy(), P0.copy(), cv.Q
    for k in range(len(z)):
        ukf.predict()
        ukf.update(z[k], R=np.diag(sigma[k] ** 2))
        np.testing.assert_allclose(run.mean[0, k], ukf.x, atol=1e-9)
        np.testing.assert_allclose(run.cov[0, k], ukf.P, atol=1e-9)


def test_the_particle_and_grid_filters_take_the_model_as_any_model():
    cv, truth, sigma, z = _range_track(np.random.default_rng(7))
    model = lb.RangeModel(ANCHORS_3D, 0.3, tag_height_m=TAG_M)
    box = (np.zeros(2), np.array([10.0, 8.0]))
    pf = lb.particle_filter(z[None], model, rng=np.random.default_rng(1), n_particles=500, region_m=box,
                            spread_m=0.4, initial_position_m=X0[None, :2], initial_sd_m=1.0)
    cells = lb.grid_in_outline(lb.box_outline(*box), 0.1)
    gb = lb.grid_bayes_filter(z[None], model, cells, 0.4)
    # the likelihood by hand at a cell: a sum of Gaussian log-densities of the ranges
    x = cells[:3][None]
    want = -0.5 * np.sum(((z[0] - np.linalg.norm(np.column_stack([cells[:3], np.full(3, TAG_M)])[:, None]
                                                 - ANCHORS_3D, axis=-1)) / 0.3) ** 2, -1) \
        - 4 * (np.log(0.3) + 0.5 * np.log(2 * np.pi))
    np.testing.assert_allclose(model.log_likelihood(z[:1], x)[0], want, rtol=1e-12)
    for est in (pf.mean[0], gb.mean[0]):
        assert np.sqrt(np.mean(np.sum((est - truth[:, :2]) ** 2, -1))) < 0.5


# -- range-only lateration and its bound --------------------------------------------------------------------------

def test_range_nls_recovers_the_truth_from_noiseless_ranges_and_counts_too_few():
    rng = np.random.default_rng(8)
    truth = rng.uniform([0.5, 0.5], [9.5, 7.5], (50, 2))
    d = lb.RangeModel(ANCHORS_3D, 0.3, tag_height_m=TAG_M).mean(truth[:, None, :])[:, 0]
    d[3, 0] = np.nan                                        # three ranges: still a fix
    d[4, :2] = np.nan                                       # two: none
    res = lb.range_nls_position(d, ANCHORS_3D, tag_height_m=TAG_M, outline_m=lb.box_outline([0, 0], [10, 8]))
    ok = res.status == "ok"
    assert res.status[4] == "too_few_anchors" and np.isnan(res.position_m[4]).all() and ok.sum() == 49
    np.testing.assert_allclose(res.position_m[ok], truth[ok], atol=1e-7)
    flat = lb.range_nls_position(np.linalg.norm(truth[:, None] - ANCHORS_3D[:, :2], axis=-1), ANCHORS_3D[:, :2])
    np.testing.assert_allclose(flat.position_m, truth, atol=1e-7)                   # 2-D, unbounded


def test_range_nls_is_efficient_at_high_snr_its_rmse_over_the_crlb_is_one_within_the_monte_carlo_error():
    rng = np.random.default_rng(9)
    point, sigma, n = np.array([3.0, 5.0]), np.array([0.02, 0.03, 0.025, 0.04]), 2000
    model = lb.RangeModel(ANCHORS_3D, sigma, tag_height_m=TAG_M)
    z = model.mean(point[None, None])[0, 0] + sigma * rng.standard_normal((n, 4))
    res = lb.range_nls_position(z, ANCHORS_3D, tag_height_m=TAG_M, range_std_m=sigma)
    e2 = np.sum((res.position_m - point) ** 2, -1)
    bound = lb.range_crlb_m(point, model)
    ratio = np.sqrt(e2.mean()) / bound
    se = 0.5 * ratio * e2.std(ddof=1) / np.sqrt(n) / e2.mean()          # the delta method on sqrt(mean)
    assert abs(ratio - 1) < 3 * se, (ratio, se)
    # the bound's closed form by hand: sqrt(tr J^-1), J = sum u u^T / sigma^2 from the plan unit vectors
    diff = np.column_stack([point - ANCHORS_3D[:, :2], TAG_M - ANCHORS_3D[:, 2]])
    u = diff[:, :2] / np.linalg.norm(diff, axis=-1)[:, None]
    J = np.einsum("j,ji,jk->ik", 1 / sigma**2, u, u)
    assert bound == pytest.approx(np.sqrt(np.trace(np.linalg.inv(J))), rel=1e-12)


def test_a_fix_outside_a_non_rectangular_outline_moves_to_its_nearest_point():
    outline = np.array([[0, 0], [10, 0], [10, 4], [4, 4], [4, 8], [0, 8]], float)    # an L: the notch is x > 4, y > 4
    outside = np.array([[7.0, 6.0], [6.0, 4.5]])
    d = np.linalg.norm(np.column_stack([outside, np.full(2, TAG_M)])[:, None] - ANCHORS_3D, axis=-1)
    res = lb.range_nls_position(d, ANCHORS_3D, tag_height_m=TAG_M, outline_m=outline)
    assert lb.inside_outline(res.position_m, outline, tolerance_m=1e-9).all()
    np.testing.assert_allclose(res.position_m, [[7.0, 4.0], [6.0, 4.0]], atol=1e-9)     # the nearest edge, y = 4
    boxed = lb.range_nls_position(d + 30.0, ANCHORS_3D, tag_height_m=TAG_M, outline_m=outline)
    assert (lb.inside_outline(boxed.position_m, outline)).all()


def test_the_checked_bound_says_why_where_it_is_undefined():
    model = lb.RangeModel(ANCHORS_3D, np.full((3, 4), 0.3), tag_height_m=TAG_M)
    heard = np.array([[True] * 4, [True, True, False, False], [True] * 4])
    bound, reason = lb.bounds.crlb.range_crlb_checked_m(np.array([[3.0, 4.0], [3.0, 4.0], [np.nan, np.nan]]), model,
                                                        heard=heard)
    assert bound[0] == pytest.approx(lb.range_crlb_m(np.array([3.0, 4.0]), lb.RangeModel(ANCHORS_3D, 0.3,
                                                                                         tag_height_m=TAG_M)))
    assert np.isnan(bound[1:]).all() and reason[1] == "heard 2 anchors, a plan fix needs 3"
    assert reason[2] == "no true position"


# -- the battery on generated data with known truth ----------------------------------------------------------------

RUN = dict(seed=11, n_bootstrap=30, block_s=10.0)
TRACK_RUN = dict(seed=11, n_particles=100, particle_runs=2, n_bootstrap=30, block_s=10.0)


def _digest(folder, names=None) -> str:
    h = hashlib.sha256()
    for p in sorted(folder.iterdir()):
        if names is None or p.name in names:
            h.update(p.name.encode() + b"\0" + p.read_bytes())
    return h.hexdigest()


def test_the_default_example_is_byte_for_byte_what_it_was(tmp_path):
    plain = write_example_dataset(tmp_path / "plain", np.random.default_rng(1), seed_note=1)
    ranged = write_example_dataset(tmp_path / "ranged", np.random.default_rng(1), seed_note=1, ranges=True)
    # the digest of `locbook data example DIR` (seed 1) as main wrote it before the range streams
    assert _digest(plain) == "586f73adc36fecef29afcfa62b0caf1925efd9dc86d7fc9c301cf4528f3aa617"
    names = [p.name for p in plain.iterdir()]
    for name in names:
        if name != "dataset.toml":
            assert (ranged / name).read_bytes() == (plain / name).read_bytes(), name
    assert sorted(p.name for p in ranged.iterdir()) == sorted(names + [f"{n}_ranges.csv" for n in
                                                                       ("survey", "points", "walk_a", "walk_b")])
    text = (ranged / "dataset.toml").read_text()
    stripped = "".join(line for line in text.splitlines(keepends=True) if not line.startswith("ranges = "))
    assert (text.count("ranges = ") == 4
            and stripped.replace(", ranges (0.3 m)", "") == (plain / "dataset.toml").read_text())


def test_the_examples_ranges_are_the_true_distance_plus_the_stated_noise(tmp_path):
    folder = write_example_dataset(tmp_path / "r", np.random.default_rng(2), walk_s=60.0, ranges=True)
    site = lb.data.example.EXAMPLE_SITE
    for name in ("survey", "walk_a"):
        ranges = pd.read_csv(folder / f"{name}_ranges.csv")
        assert (ranges["range_std_m"] == site["range_sigma_m"]).all()
        assert ranges["range_m"].isna().mean() == pytest.approx(site["range_missing_fraction"], abs=0.02)
    # the survey stands at its points: each range against the distance from its point (the readings' truth)
    ranges, readings = pd.read_csv(folder / "survey_ranges.csv"), pd.read_csv(folder / "survey.csv")
    where = readings.groupby("point")[["x_m", "y_m"]].first()
    xy = where.loc[ranges["point"]].to_numpy()
    anchors = pd.read_csv(folder / "anchors.csv").set_index("id").loc[ranges["receiver"]].to_numpy()
    d = np.linalg.norm(np.column_stack([xy, np.full(len(xy), site["tag_height_m"])]) - anchors, axis=-1)
    e = (ranges["range_m"] - d).dropna()
    assert abs(e.mean()) < 3 * 0.3 / np.sqrt(len(e)) + 1e-3 and e.std() == pytest.approx(0.3, rel=0.05)


@pytest.fixture(scope="module")
def ranged(tmp_path_factory):
    """The example with ranges, the same without (its manifest's ranges keys removed), each run through the battery
    at given settings."""
    base = tmp_path_factory.mktemp("ranged")
    folder = write_example_dataset(base / "with", np.random.default_rng(4), walk_s=60.0, ranges=True)
    plain = base / "without"
    plain.mkdir()
    for p in folder.iterdir():
        text = p.read_bytes()
        if p.name == "dataset.toml":
            text = b"\n".join(line for line in text.split(b"\n") if not line.startswith(b"ranges = "))
        (plain / p.name).write_bytes(text)
    out = {}
    for key, where in (("with", folder), ("without", plain)):
        ds = me.load(where)
        model = me.channel(me.calibrate(ds))
        proto = me.protocol(ds, model, grid_spacing_m=0.4, knn_k=4, q=0.05, spread_m=0.4)
        out[key] = (ds, proto, me.static_results(ds, model, proto, **RUN), me.tracking_results(ds, model, proto,
                                                                                               **TRACK_RUN))
    return out


def _row(res, method, recording="pooled"):
    return next(r for r in res["rows"] if r["method"] == method and r["recording"] == recording)


def test_range_nls_is_within_its_bounds_scale_and_well_below_the_rss_methods(ranged):
    ds, proto, st, _ = ranged["with"]
    row = _row(st, "range_nls")
    assert row["bound"] == mr.RANGE_BOUND_NAME and row["bound_rms_m"] < 0.25
    assert row["mean_m"] < 2 * row["bound_rms_m"]
    best_rss = min(_row(st, m)["mean_m"] for m in me.STATIC_METHODS)
    assert row["mean_m"] < 0.3 * best_rss
    # the static points (standing: the truth is exact) alone: RMSE / RMS bound near 1
    points = _row(st, "range_nls", "points")
    assert 0.7 < points["ratio"] < 1.4 and points["coverage"] > 0.9
    # its errors are those of range_nls_position on the epochs' ranges, scored against the truth
    ep = ds.epochs("points")
    known = np.isfinite(ep.position_m[:, 0])
    r, s = ds.ranges("points")
    fix = lb.range_nls_position(r[known], ds.anchors_m, outline_m=ds.outline_m, tag_height_m=ds.tag_height_m,
                                range_std_m=s[known]).position_m
    np.testing.assert_array_equal(st["fixes"]["points"]["range_nls"], fix)
    assert "range_nls" in st["battery"] and "range_nls" in st["errors"]["walk_a"]


def test_the_fusion_trackers_beat_the_rss_only_ones_on_every_track(ranged):
    _, proto, _, tr = ranged["with"]
    for track in ("walk_a", "walk_b", "pooled"):
        for fused, alone in (("ekf_rss_range", "ekf"), ("ukf_rss_range", "ukf")):
            f, a = _row(tr, fused, track), _row(tr, alone, track)
            assert f["mean_m"] < 0.5 * a["mean_m"]
            # beside the bound of the readings they see: the ranges' information adds to the RSS', so the bound
            # is lower on every track, and a near-efficient filter's ratio is near 1 against it (RSS alone: ~0.2)
            assert f["bound"] == me.ranging.RANGE_TRACKING_BOUND_NAME != a["bound"]
            assert f["bound_rms_m"] < 0.5 * a["bound_rms_m"]
            assert 0.7 < f["ratio"] < 2.0
    assert {"ekf_rss_range", "ukf_rss_range"} <= set(tr["tracks"]["walk_a"][2])           # the NIS guard's table
    sigma = [c for c in proto.rows() if c["setting"].startswith("range sigma")]
    assert [c["setting"] for c in sigma] == ["range sigma (m), points", "range sigma (m), walk_a",
                                             "range sigma (m), walk_b"]
    assert all(c["value"].startswith("reported") for c in sigma)


def test_without_ranges_no_row_changes_and_none_is_added(ranged):
    _, proto_w, st_w, tr_w = ranged["with"]
    _, proto_o, st_o, tr_o = ranged["without"]
    for w, o in ((st_w, st_o), (tr_w, tr_o)):
        assert [r for r in w["rows"] if r["method"] not in mr.RANGE_METHOD_NAMES] == o["rows"]
        assert not [r for r in o["rows"] if r["method"] in mr.RANGE_METHOD_NAMES]
    assert [c for c in proto_w.rows() if not c["setting"].startswith("range sigma")] == proto_o.rows()
    assert st_o["battery"] == list(me.STATIC_METHODS) and tr_o["battery"] == list(me.TRACKERS)


def test_without_a_std_column_sigma_is_fitted_on_the_calibration_ranges(tmp_path):
    folder = write_example_dataset(tmp_path / "d", np.random.default_rng(5), walk_s=30.0, ranges=True)
    for name in ("survey", "points", "walk_a", "walk_b"):
        f = folder / f"{name}_ranges.csv"
        pd.read_csv(f, dtype=str, keep_default_na=False).drop(columns="range_std_m").to_csv(f, index=False)
    ds = lb.load_dataset(folder)
    noise = mr.range_noise(ds)
    # independently: the survey's ranges in 1 s windows from each point's first reading, against the true distance
    readings, ranges = pd.read_csv(folder / "survey.csv"), pd.read_csv(folder / "survey_ranges.csv").dropna()
    ep = ds.epochs("survey")
    residuals = []
    e_of = {(p, float(t)): i for i, (p, t) in enumerate(zip(ep.extra["point"], ep.time_s))}
    t0 = readings["time_s"].min()
    ranges["tick"] = t0 + np.floor((ranges["time_s"] - t0) / 1.0 + 0.5 + 1e-9)
    means = ranges.groupby(["point", "tick", "receiver"])["range_m"].mean()
    anchors = pd.read_csv(folder / "anchors.csv").set_index("id")
    for (point, tick, rx), value in means.items():
        i = e_of.get((point, tick))
        if i is None:
            continue
        p = np.r_[ep.position_m[i, :2], 1.2]
        residuals.append(value - np.linalg.norm(p - anchors.loc[rx].to_numpy()))
    assert noise["n"] == len(residuals)
    assert noise["sigma_m"] == pytest.approx(np.std(residuals, ddof=1), rel=1e-9)
    assert noise["sigma_m"] == pytest.approx(0.3 / np.sqrt(2), rel=0.1)      # two ranges per window
    rows = [c for c in mr.range_choices(ds)]
    assert rows and all(c["value"] == f"{noise['sigma_m']:.3g}" and c["how"].startswith("rule: residual std")
                        for c in rows)


def test_the_range_methods_names_are_reserved():
    from locbook.user_methods import method_name_problem
    for name in mr.RANGE_METHOD_NAMES:
        assert "battery method" in method_name_problem(name)


def test_the_command_writes_the_ranges_of_every_variant_and_check_counts_them(tmp_path, capsys):
    from locbook.suite.cli import main
    assert main(["data", "example", str(tmp_path / "cli"), "--ranges", "--two-d", "--native-scans", "--seed", "3",
                 "--roles", "calibration,track"]) == 0
    lib = write_example_dataset(tmp_path / "lib", np.random.default_rng(3), seed_note=3, two_d=True, native_scans=True,
                                roles=("calibration", "track"), ranges=True)
    assert _digest(tmp_path / "cli") == _digest(lib)
    ds = lb.load_dataset(lib)
    assert not ds.notes.get("ranges walk_a") and ds.dimension == 2
    for name in ("walk_a", "walk_b"):            # native scans: a ranging round at each scan, on its epoch
        ranges, std = ds.ranges(name)
        ep = ds.epochs(name)
        assert np.isfinite(ranges).mean() > 0.9 and np.nanmax(np.abs(std - 0.3)) < 1e-12
        d = np.linalg.norm(ep.position_m[:, None, :2] - ds.anchors_m, axis=-1)        # in the plane
        assert np.nanstd(ranges - d) == pytest.approx(0.3, rel=0.1)
    capsys.readouterr()
    assert main(["data", "check", str(lib)]) == 0
    assert "| ranges (epoch, anchor) |" in capsys.readouterr().out


def test_a_method_of_your_own_gets_the_ranges_on_its_epochs(ranged, tmp_path):
    from locbook.user_methods import registered_methods
    code = tmp_path / "tri.py"
    code.write_text("import numpy as np\nimport locbook as lb\n\n\ndef tri(inp):\n"
                    "    if inp.range_m is None:\n        return np.full((inp.n_epochs, 2), np.nan)\n"
                    "    return lb.lateration_ls(inp.anchors_m, inp.range_m,"
                    " tag_height_m=inp.tag_height_m).position_m\n")
    ds, proto, st, tr = ranged["with"]
    model = me.channel(me.calibrate(ds))
    user = registered_methods(methods=[f"tri={code}:tri"], trackers=[f"tri_track={code}:tri"])
    mine = me.static_results(ds, model, proto, user_methods=user, **RUN)
    for name in mine["recordings"]:
        ep = ds.epochs(name)
        known = np.isfinite(ep.position_m[:, 0])
        want = lb.lateration_ls(ds.anchors_m, ds.ranges(name)[0][known], tag_height_m=ds.tag_height_m).position_m
        np.testing.assert_array_equal(mine["fixes"][name]["tri"], want)
    assert [r for r in mine["rows"] if "failure" not in r] == st["rows"]      # every other row as it was
    tracks = me.tracking_results(ds, model, proto, user_methods=user, **TRACK_RUN)["tracks"]
    sc, est, _, _ = tracks["walk_a"]
    assert np.isfinite(est["tri_track"][0]).all(axis=1).mean() > 0.9         # the ranges on the track's clock
