"""The measured-data protocol (locbook.scenarios.measured): one definition per method on every page, settings from the
data by stated rules, bounds that cannot lie."""
from dataclasses import replace

import numpy as np
import pytest

import locbook as lb
from builders import REPO_ROOT
from locbook import battery
from locbook.data.example import write_example_dataset
from locbook.scenarios import measured as me
from locbook.scenarios import measured_setup


@pytest.fixture(scope="module")
def example(tmp_path_factory):
    folder = tmp_path_factory.mktemp("protocol") / "example"
    write_example_dataset(folder, np.random.default_rng(5), walk_s=40.0)
    ds = me.load(folder)
    return ds, me.channel(me.calibrate(ds))


def _knn_by_hand(query, fingerprints, cells, k):
    """Weighted k-NN written out (inverse-square weights of the RSS distance over the anchors heard)."""
    out = np.full((len(query), 2), np.nan)
    for i, q in enumerate(query):
        heard = ~np.isnan(q)
        if heard.sum() < min(3, len(q)):
            continue
        d2 = np.sum((fingerprints[:, heard] - q[heard]) ** 2, axis=1)
        near = np.argsort(d2, kind="stable")[:k]
        w = 1.0 / np.maximum(d2[near], 1e-12)
        out[i] = (w[:, None] * cells[near]).sum(axis=0) / w.sum()
    return out


def test_knn_k_is_the_leave_one_point_out_minimum(example):
    ds, model = example
    k, how, table = me.choose_knn_k(ds, model)
    xy, fingerprints, _ = me.radio_map(ds, model)
    _, _, rss = me.calibration_set(ds)
    groups = measured_setup._cv_groups(ds, xy)
    means = {}
    for cand in (1, 3, k):
        err = []
        for g in np.unique(groups):
            out = groups == g
            est = _knn_by_hand(rss[out], fingerprints[~out], xy[~out], cand)
            err.append(np.linalg.norm(est - xy[out], axis=1))
        means[cand] = np.nanmean(np.concatenate(err))
    by_k = {row["k"]: row["mean error (m), leave-one-point-out"] for row in table}
    for cand, value in means.items():
        assert by_k[cand] == pytest.approx(value, abs=2e-3)
    assert by_k[k] == min(by_k.values()) and "leave-one-point-out" in how
    assert me.choose_knn_k(ds, model, 3)[:2] == (3, "given (-p knn_k)")


def test_grid_pitch_is_coarsened_only_past_the_cell_limit(example, monkeypatch):
    ds, _ = example
    assert me.grid_pitch_m(ds) == (me.GRID_SPACING_M, f"rule: {me.GRID_SPACING_M:g} m")
    monkeypatch.setattr(measured_setup, "MAX_GRID_CELLS", 1000)            # the hall's 240 m^2 at 0.1 m is 24,000 cells
    pitch, how = me.grid_pitch_m(ds)
    assert pitch > me.GRID_SPACING_M and "coarsened" in how
    assert lb.grid_in_outline(ds.outline_m, pitch).shape[0] <= 1000 * 1.1


def test_static_results_pooled_rows_are_the_recordings_together(example):
    ds, model = example
    proto = me.protocol(ds, model, tracks=False)
    res = me.static_results(ds, model, proto, seed=3, n_bootstrap=50, block_s=5.0)
    rows = {(r["recording"], r["method"]): r for r in res["rows"]}
    assert [r["recording"] for r in res["rows"][:len(me.STATIC_METHODS)]] == ["pooled"] * len(me.STATIC_METHODS)
    for method in me.STATIC_METHODS:
        e = np.concatenate([res["errors"][n][method] for n in res["recordings"]])
        ok = np.isfinite(e)
        assert rows["pooled", method]["mean_m"] == pytest.approx(np.mean(e[ok]), abs=5e-4)
        assert rows["pooled", method]["rmse_m"] == pytest.approx(np.sqrt(np.mean(e[ok] ** 2)), abs=5e-4)
        assert rows["pooled", method]["epochs"] == e.size
        assert tuple(rows["pooled", method]) == me.RESULT_COLUMNS
    # every fix of one method equals the battery's fix of the same epoch computed on its own recording
    name = res["recordings"][0]
    sc = me.static_scenario(ds, model, [name], grid_spacing_m=proto.grid_spacing_m)
    alone = battery.static_fixes(sc, sc.measured_rss_dbm[None], knn_k=proto.knn_k, methods=["lls", "grid_ml", "knn"])
    for method, fix in alone.items():
        np.testing.assert_allclose(fix[0], res["fixes"][name][method], atol=1e-9)


def test_a_ratio_below_one_says_why_and_no_ratio_comes_from_a_degenerate_bound(example):
    ds, model = example
    proto = me.protocol(ds, model, tracks=False)
    res = me.static_results(ds, model, proto, seed=3, n_bootstrap=50, block_s=5.0)
    for r in res["rows"]:
        if r["ratio"] is not None and r["ratio"] < 1:
            assert r["ratio_note"].startswith("below 1")
    # epochs that heard two anchors only: their bound is excluded and counted, never summarised as a number
    t = res["tests"][res["recordings"][0]]
    rss = t.rss_dbm.copy()
    rss[:, 2:] = np.nan
    sc = me.static_scenario(ds, model, [res["recordings"][0]], grid_spacing_m=proto.grid_spacing_m)
    bound, reason = battery.static_bound_checked(replace(sc, measured_rss_dbm=rss))
    assert np.isnan(bound).all() and all(reason)
    row = me.result_row("static", "two anchors", "lls", np.ones(len(bound)), bound, reason, np.random.default_rng(0),
                        n_bootstrap=20, block=1, settings="", prior="", bound_name="CRLB", outside=0.0)
    assert row["ratio"] is None and row["ratio_note"].startswith("n/a")
    assert row["bound_excluded"] == len(bound)


def test_every_tracker_starts_at_the_first_fix_and_the_benchmark_cells_are_the_pooled_rows(example):
    ds, model = example
    proto = me.protocol(ds, model)
    assert set(proto.motion) == set(ds.recordings_with("track"))
    static = me.static_results(ds, model, proto, seed=4, n_bootstrap=30, block_s=5.0)
    tracking = me.tracking_results(ds, model, proto, seed=4, n_particles=200, particle_runs=2, n_bootstrap=30,
                                   block_s=5.0)
    for name, (sc, est, flags, bound) in tracking["tracks"].items():
        first = np.flatnonzero(~np.isnan(sc.measured_rss_dbm).all(axis=1))
        assert set(est) == set(me.TRACKERS) and est["particle"].shape[0] == 2
        assert est["ekf"].shape == (1, len(sc.truth_m), 2)
        assert np.isfinite(sc.start_state[:2]).all() and np.all(sc.start_state[2:] == 0)
        assert first.size
    cells = me.benchmark_rows(ds, static, tracking)
    pooled = {(r["kind"], r["method"]): r for r in static["rows"] + tracking["rows"] if r["recording"] == "pooled"}
    assert len(cells) == len(pooled)
    for c in cells:
        r = pooled[c["kind"], c["method"]]
        assert (c["rmse_m"], c["mean_m"], c["median_m"], c["p90_m"], c["ratio"]) == \
               (r["rmse_m"], r["mean_m"], r["median_m"], r["p90_m"], r["ratio"])


def test_the_same_parameters_give_the_same_rows(example):
    ds, model = example
    proto = me.protocol(ds, model, q=0.1, spread_m=0.5)
    assert all(m == {"q": 0.1, "spread_m": 0.5} for m in proto.motion.values())
    a = me.tracking_results(ds, model, proto, seed=9, n_particles=100, particle_runs=2, n_bootstrap=20, block_s=5.0)
    b = me.tracking_results(ds, model, proto, seed=9, n_particles=100, particle_runs=2, n_bootstrap=20, block_s=5.0)
    assert a["rows"] == b["rows"]


def test_a_second_device_in_the_calibration_gets_its_offset_and_every_reading_is_corrected(tmp_path):
    """Half the survey's points measured by a phone that reads 4 dB strong: the joint fit finds +4 dB (to the
    shadowing's error), and after the correction the channel fit equals the one of the survey without the shift."""
    import pandas as pd
    folder = write_example_dataset(tmp_path / "two", np.random.default_rng(8), walk_s=20.0,
                                   roles=("calibration", "static"))
    plain = me.load(folder)
    base = me.channel(me.calibrate(plain))
    survey = folder / "survey.csv"
    table = pd.read_csv(survey)
    phone = table["point"].astype("category").cat.codes % 2 == 1
    table["device"] = np.where(phone, "phone", "tag")
    table.loc[phone & (table["rssi_dbm"] != 0.0), "rssi_dbm"] += 4.0      # not the 0 dBm "no reading" sentinel
    table.to_csv(survey, index=False)
    ds = me.load(folder)
    offsets = me.device_offsets_db(ds)
    assert set(offsets) == {"phone", "tag"} and 0.0 in offsets.values()          # one reference device
    assert offsets["phone"] - offsets["tag"] == pytest.approx(4.0, abs=0.5)
    fitted = me.channel(me.calibrate(ds))
    ref = "tag" if offsets["tag"] == 0.0 else "phone"
    shift = 0.0 if ref == "tag" else 4.0
    np.testing.assert_allclose(np.asarray(fitted.path_loss_exp), np.asarray(base.path_loss_exp), atol=0.15)
    np.testing.assert_allclose(np.asarray(fitted.ref_power_dbm) - shift, np.asarray(base.ref_power_dbm), atol=1.0)


@pytest.mark.parametrize("variant", ["two_d", "native_scans"])
def test_a_2d_set_and_native_scans_run_the_whole_battery(tmp_path, variant):
    folder = write_example_dataset(tmp_path / variant.replace("_", "-"), np.random.default_rng(6), walk_s=30.0,
                                   **{variant: True})
    ds = me.load(folder)
    model = me.channel(me.calibrate(ds))
    proto = me.protocol(ds, model)
    static = me.static_results(ds, model, proto, seed=1, n_bootstrap=20, block_s=5.0)
    tracking = me.tracking_results(ds, model, proto, seed=1, n_particles=100, particle_runs=2, n_bootstrap=20,
                                   block_s=5.0)
    assert static["rows"] and tracking["rows"]
    sc = static["scenario"]
    if variant == "two_d":
        assert ds.anchors_m.shape[1] == 2 and sc.tag_height_m is None
        assert "2-D" in me.geometry_text(ds)
        # distances in the plane: the channel's mean at a true position uses the plan distance
        np.testing.assert_allclose(sc.distances_m(sc.points_m[:3]),
                                   np.linalg.norm(sc.points_m[:3, None] - ds.anchors_m, axis=-1))
    else:
        name = ds.recordings_with("track")[0]
        t = np.unique(ds.epochs(name).time_s)
        assert me.epoch_s(ds, name) == pytest.approx(np.median(np.diff(t)))
    for name, (tsc, est, flags, bound) in tracking["tracks"].items():
        assert np.isfinite(est["ekf"][0, tsc.scored_steps]).all()


def _reports_with_benchmark():
    root = REPO_ROOT / "reports"
    return sorted(p.parent.parent for p in root.glob("*/benchmark-cross-document/benchmark.csv")) + \
        sorted(p.parent.parent for p in root.glob("*/data-*/benchmark-cross-document/benchmark.csv"))


def _data_set_of(report_dir, experiment):
    """The data set an experiment's report was computed from: its recorded parameter, else the notebook's default."""
    import json

    from locbook.suite import load_suite
    params = json.loads((report_dir / experiment / "report.json").read_text())["parameters"]
    if "data" in params:
        return me.load(params["data"]).name
    exp = next(e for e in load_suite().experiments if e.id == experiment)
    return me.load(exp.declared_parameters()["data"].default).name


@pytest.mark.parametrize("report_dir", _reports_with_benchmark(), ids=lambda p: p.name)
def test_every_method_name_gives_the_same_numbers_on_every_page_of_a_run(report_dir):
    """The committed reports of one run: a data set's column of the benchmark (its `pooled` cells) holds the numbers
    of the data set's own measured-localization and measured-tracking results, method by method."""
    import pandas as pd
    bench = pd.read_csv(report_dir / "benchmark-cross-document" / "benchmark.csv")
    pages = {}
    for folder in [report_dir, *report_dir.glob("data-*")]:
        for experiment, kind in (("measured-localization", "static"), ("measured-tracking", "tracking")):
            if (folder / experiment / "results.csv").is_file():
                pages[_data_set_of(folder, experiment), kind] = pd.read_csv(folder / experiment / "results.csv")
    compared = 0
    for (name, kind), results in pages.items():
        cells = bench[(bench["scenario"] == f"data-{name}") & (bench["kind"] == kind)]
        if cells.empty:
            continue
        pooled = results[results["recording"] == "pooled"].set_index("method")
        assert set(cells["method"]) == set(pooled.index)
        for _, c in cells.iterrows():
            for col in ("rmse_m", "mean_m", "median_m", "p90_m", "ratio"):
                a, b = c[col], pooled.loc[c["method"], col]
                assert (pd.isna(a) and pd.isna(b)) or a == pytest.approx(b, abs=1e-9), (name, kind, c["method"], col)
            compared += 1
    if not compared:
        pytest.skip(f"{report_dir}: no data set's own reports beside its benchmark column")


def test_native_scans_with_jittered_times_run_on_their_median_clock(tmp_path):
    """Phone scans are not evenly spaced: two scans closer than half the median spacing share a tick and are
    averaged, never an error; every scan lands on a tick of the clock."""
    import pandas as pd
    folder = write_example_dataset(tmp_path / "scans", np.random.default_rng(4), walk_s=30.0, native_scans=True)
    name = me.load(folder).recordings_with("track")[0]
    path = folder / me.load(folder).recording(name).file.name
    table = pd.read_csv(path)
    times = np.unique(table["time_s"])
    shift = dict(zip(times, times + np.random.default_rng(0).uniform(-0.45, 0.45, times.size)))
    table["time_s"] = table["time_s"].map(shift).clip(lower=0.0)
    table.sort_values("time_s", kind="stable").to_csv(path, index=False)
    ds = me.load(folder)
    model = me.channel(me.calibrate(ds))
    sc = me.tracking_scenario(ds, model, name, grid_spacing_m=0.1, q=0.05, spread_m=1.0)
    t = np.unique(ds.epochs(name).time_s)
    assert sc.dt_s == pytest.approx(np.median(np.diff(t)))
    assert sc.measured_rss_dbm.shape[0] == int(round((t[-1] - t[0]) / sc.dt_s)) + 1
    heard = ~np.isnan(sc.measured_rss_dbm).all(axis=1)
    assert heard.sum() < len(t) and heard.sum() >= len(t) // 2       # some scans shared a tick, none was lost


@pytest.mark.slow
def test_the_python_example_of_docs_your_data_runs():
    """docs/your-data.md's code block, run as written (fewer resamples and particles)."""
    import re
    page = REPO_ROOT / "docs" / "your-data.md"
    if not page.exists():
        pytest.skip("the docs are not beside the tests (an installed package)")
    code = re.findall(r"```python\n(.*?)```", page.read_text(encoding="utf-8"), flags=re.S)[0]
    code = code.replace("n_bootstrap=1000", "n_bootstrap=20").replace("n_particles=1000", "n_particles=100")
    scope = {}
    exec(compile(code, str(page), "exec"), scope)
    rows = scope["rows"]
    assert rows and all(tuple(r) == me.RESULT_COLUMNS for r in rows)
    assert {r["kind"] for r in rows} == {"static", "tracking"}


@pytest.mark.parametrize("profile", ["quick", "full"])
def test_the_pages_of_a_data_run_share_every_setting_they_both_declare(profile):
    """measured-localization, measured-tracking and the benchmark compute a data set's numbers by the same calls; they
    give the same numbers only if every parameter two of them declare resolves to the same value in every profile
    (the particle settings once differed: the benchmark's particle row was not measured-tracking's)."""
    from locbook.suite import load_suite
    suite = load_suite()
    ids = ("measured-localization", "measured-tracking", "benchmark-cross-document")
    resolved = {e.id: {**{k: v.default for k, v in e.declared_parameters().items()},
                       **e.parameters(profile, data_run=True)} for e in suite.experiments if e.id in ids}
    assert set(resolved) == set(ids)
    shared = ("seed", "fit", "n_bootstrap", "block_s", "n_particles", "particle_runs", "ukf_alpha", "grid_spacing_m",
              "knn_k", "q", "spread_m", "calibration", "anchors")
    for name in shared:
        values = {i: p[name] for i, p in resolved.items() if name in p}
        assert len(values) >= 2 and len({repr(v) for v in values.values()}) == 1, (name, values)
