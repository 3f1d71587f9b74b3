"""Splits and anchor subsets: -p calibration (which recordings the channel is fitted on), -p anchors and the
manifest's [run] anchors (a subset of the anchors), leave-one-recording-out (--split loro) and the anchor-density
study. The fast tests call the library on the generated example data set and check against independent constructions
(a fit done directly by locbook.static.calibration, CSV files filtered with pandas, numpy's statistics); the slow one
runs both commands end to end."""
import itertools
import math
import re
import shutil
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from builders import REPO_ROOT
from locbook.data.dataset import load_dataset
from locbook.data.example import write_example_dataset
from locbook.data.measured import DataFormatError
from locbook.data.selection import MIN_SUBSET_ANCHORS, select, with_anchors, with_calibration
from locbook.errors import ParameterError
from locbook.scenarios import measured as me
from locbook.static.calibration import calibrate_path_loss
from locbook.suite import splits
from locbook.suite.cli import main
from locbook.suite.runner import Outcome

SUITE = REPO_ROOT / "notebooks" / "experiments.toml"
WALK_S = 40.0              # short walks: every fast test here runs the static battery in seconds


@pytest.fixture(scope="module")
def example(tmp_path_factory) -> Path:
    return write_example_dataset(tmp_path_factory.mktemp("ex") / "example", np.random.default_rng(5), walk_s=WALK_S)


def _static_rows(ds):
    model = me.channel(me.calibrate(ds))
    proto = me.protocol(ds, model, tracks=False)
    return me.static_results(ds, model, proto, seed=11, n_bootstrap=20, block_s=10.0)


# -------------------------------------------------------------------------------------------- calibration split

def test_split_changes_which_recordings_are_fitted_and_scored(example):
    ds = load_dataset(example)
    split = with_calibration(ds, "points,walk_b")
    assert {n: r.role for n, r in split.recordings.items()} == {
        "survey": "static", "points": "calibration", "walk_a": "track", "walk_b": "calibration"}
    assert me.scored_recordings(split) == ["survey", "walk_a"]
    assert split.recordings_with("track") == ["walk_a"]
    assert {n: r.role for n, r in ds.recordings.items()}["survey"] == "calibration"     # the input is unchanged
    # the fitted channel equals a closed-form fit done directly on the chosen recordings' epochs
    pos, rss = [], []
    for name in ("points", "walk_b"):
        ep = ds.epochs(name)
        known = np.isfinite(ep.position_m[:, :2]).all(axis=1)
        p = ep.position_m[known].copy()
        p[:, 2] = np.where(np.isfinite(p[:, 2]), p[:, 2], ds.tag_height_m)
        pos.append(p)
        rss.append(ep.rss_dbm[known])
    pos, rss = np.concatenate(pos), np.concatenate(rss)
    distance = np.sqrt(((pos[:, None, :] - ds.anchors_m[None]) ** 2).sum(axis=-1))
    direct = calibrate_path_loss(distance, rss, "per_anchor", solver="closed_form")
    fitted = me.calibrate(split)
    np.testing.assert_allclose(fitted.ref_power_dbm, direct.ref_power_dbm, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fitted.path_loss_exp, direct.path_loss_exp, rtol=0, atol=1e-12)
    assert not np.allclose(fitted.path_loss_exp, me.calibrate(ds).path_loss_exp)      # another fit than the default
    # the scored epochs are the survey's and walk_a's, each with its truth
    res = _static_rows(split)
    assert res["recordings"] == ["survey", "walk_a"]
    n_survey = int(np.isfinite(ds.epochs("survey").position_m[:, 0]).sum())
    assert len(res["tests"]["survey"].truth_m) == n_survey
    assert "calibration split" in split.notes and "survey (calibration in the manifest)" in split.notes[
        "calibration split"]


def test_default_parameters_change_nothing(example):
    ds = load_dataset(example)
    assert select(ds) is ds and with_calibration(ds, "") is ds and with_anchors(ds, "") is ds
    assert with_calibration(ds, "survey") is ds                          # the manifest's own roles
    assert with_anchors(ds, ",".join(reversed(ds.anchor_ids))) is ds    # every anchor
    loaded = me.load(example)             # what a notebook does with calibration="" and anchors=""
    assert loaded.notes == ds.notes and loaded.anchor_ids == ds.anchor_ids
    assert {n: r.role for n, r in loaded.recordings.items()} == {n: r.role for n, r in ds.recordings.items()}
    assert _static_rows(loaded)["rows"] == _static_rows(ds)["rows"]


# ------------------------------------------------------------------------------------------------ anchor subset

def _filtered_copy(src: Path, dest: Path, keep) -> Path:
    """The example with only the anchors ``keep``: anchors.csv and every readings file filtered with pandas."""
    shutil.copytree(src, dest)
    anchors = pd.read_csv(dest / "anchors.csv")
    anchors[anchors["id"].isin(keep)].to_csv(dest / "anchors.csv", index=False)
    for name in ("survey", "points", "walk_a", "walk_b"):
        table = pd.read_csv(dest / f"{name}.csv", dtype=str, keep_default_na=False)
        table[table["receiver"].isin(keep)].to_csv(dest / f"{name}.csv", index=False)
    return dest


def _ignored_readings(src: Path, dropped) -> int:
    """Readings (heard rows: a number that is not the 0 dBm sentinel) of the ``dropped`` anchors, from the files."""
    total = 0
    for name in ("survey", "points", "walk_a", "walk_b"):
        table = pd.read_csv(src / f"{name}.csv", dtype=str, keep_default_na=False)
        rssi = pd.to_numeric(table["rssi_dbm"], errors="coerce")
        total += int((table["receiver"].isin(dropped) & rssi.notna() & (rssi != 0.0)).sum())
    return total


def test_anchor_subset_equals_a_data_set_of_those_anchors_only(example, tmp_path):
    keep = ["A1", "A2", "A4", "A7", "A8"]
    ds = load_dataset(example)
    subset = with_anchors(ds, ",".join(keep))
    other = load_dataset(_filtered_copy(example, tmp_path / "filtered", keep))
    assert subset.anchor_ids == other.anchor_ids == tuple(keep)
    np.testing.assert_array_equal(subset.anchors_m, other.anchors_m)
    for name in ds.recordings:
        a, b = subset.epochs(name), other.epochs(name)
        np.testing.assert_array_equal(a.time_s, b.time_s)
        np.testing.assert_array_equal(a.rss_dbm, b.rss_dbm)
        np.testing.assert_array_equal(a.position_m, b.position_m)
    mine, theirs = _static_rows(subset), _static_rows(other)
    for name in mine["recordings"]:
        for method, fix in mine["fixes"][name].items():
            np.testing.assert_array_equal(fix, theirs["fixes"][name][method])
    assert mine["rows"] == theirs["rows"]
    dropped = [a for a in ds.anchor_ids if a not in keep]
    n = int(re.search(r"ignored ([\d,]+) readings of (\d+) anchors", subset.notes["anchor subset"]).group(1)
            .replace(",", ""))
    assert n == _ignored_readings(example, dropped) > 0
    assert subset.notes["anchor subset"].endswith(", ".join(dropped))


def test_manifest_run_anchors_and_the_parameter(example, tmp_path):
    folder = shutil.copytree(example, tmp_path / "run-anchors")
    manifest = folder / "dataset.toml"
    text = manifest.read_text(encoding="utf-8")
    manifest.write_text(text.replace("[epochs]", '[run]\nanchors = ["A1", "A3", "A5", "A6"]\n\n[epochs]'),
                        encoding="utf-8")
    ds = load_dataset(folder)
    assert ds.run_anchors == ("A1", "A3", "A5", "A6") and len(ds.anchor_ids) == 8      # the loader keeps them all
    run = me.load(folder)
    assert run.anchor_ids == ("A1", "A3", "A5", "A6")
    assert run.notes["anchor subset"].startswith("[run] anchors of the manifest")
    assert me.load(folder, anchors="A2,A4,A8").anchor_ids == ("A2", "A4", "A8")          # -p anchors replaces it
    for bad, why in (('["A1", "A9", "A3"]', "'A9' is not an anchor id"), ('["A1", "A3"]', "at least 3"),
                     ('"A1,A2,A3"', "must be a non-empty list"), ('["A1", "A1", "A2"]', "given twice")):
        manifest.write_text(text.replace("[epochs]", f"[run]\nanchors = {bad}\n\n[epochs]"), encoding="utf-8")
        with pytest.raises(DataFormatError, match=re.escape("[run] anchors") + ".*" + re.escape(why)):
            load_dataset(folder)


def test_bad_values_are_refused_naming_the_parameter(example):
    ds = load_dataset(example)
    with pytest.raises(ParameterError, match=r"parameter 'calibration': 'nope' is not a recording of data set "
                                             r"'example'; its recordings: survey, points, walk_a, walk_b"):
        with_calibration(ds, "points,nope")
    with pytest.raises(ParameterError, match="parameter 'calibration': 'points' given twice"):
        with_calibration(ds, "points,points")
    with pytest.raises(ParameterError, match=r"parameter 'anchors': 'B5' is not an anchor id; the anchors: A1, A2"):
        with_anchors(ds, "A1,A2,B5")
    with pytest.raises(ParameterError, match=rf"parameter 'anchors': 2 anchor\(s\).*at least {MIN_SUBSET_ANCHORS}"):
        with_anchors(ds, "A1,A2")
    assert MIN_SUBSET_ANCHORS == 3


@pytest.mark.parametrize("args, words", [
    (["-p", "calibration=survey,nope"], ["parameter 'calibration'", "'nope'", "survey, points, walk_a, walk_b"]),
    (["-p", "anchors=A1,A2"], ["parameter 'anchors'", "at least 3"]),
    (["-p", "anchors=A1,A2,Z9"], ["parameter 'anchors'", "'Z9'", "A1, A2, A3"]),
    (["--split", "loro", "-p", "calibration=points"], ["--split loro", "-p calibration"]),
])
def test_bad_values_through_the_cli_exit_2_in_one_line(example, tmp_path, capsys, args, words):
    status = main(["run", "--data", str(example), *args, "--suite", str(SUITE), "--reports", str(tmp_path)])
    err = capsys.readouterr().err.strip()
    assert status == 2 and len(err.splitlines()) == 1, err
    assert all(w in err for w in words), err
    assert not any(tmp_path.iterdir())          # refused before anything ran or was written


def test_split_and_study_options_need_a_data_set(tmp_path, capsys):
    assert main(["run", "--split", "loro", "--suite", str(SUITE), "--reports", str(tmp_path)]) == 2
    assert "--data" in capsys.readouterr().err
    assert main(["run", "measured-localization", "-p", "calibration=survey", "--suite", str(SUITE),
                 "--reports", str(tmp_path)]) == 2
    assert "give it with --data" in capsys.readouterr().err
    assert main(["study", "anchor-density", "--suite", str(SUITE), "--reports", str(tmp_path)]) == 2
    assert "--data" in capsys.readouterr().err


# --------------------------------------------------------------------------------------- leave one recording out

def test_loro_splits_hold_out_each_recording_with_truth(example):
    ds = load_dataset(example)
    with_truth = [n for n in ("survey", "points", "walk_a", "walk_b")
                  if pd.read_csv(example / f"{n}.csv")["x_m"].notna().any()]
    found = splits.loro_splits(ds)
    assert [held for held, _ in found] == with_truth and len(found) == 4
    for held, calibration in found:
        assert set(calibration) == set(with_truth) - {held}
        split = me.load(ds, calibration=",".join(calibration))
        assert set(split.recordings_with("calibration")) == set(calibration)
        assert me.scored_recordings(split) == [held]                   # exactly the held-out one is scored
    one = with_calibration(ds, "survey,points,walk_a")             # walk_b then holds the only truth left out
    assert splits.loro_splits(with_calibration(ds, "survey")) == found
    assert len(one.recordings_with("calibration")) == 3


def test_loro_needs_two_recordings_with_truth(tmp_path):
    only = write_example_dataset(tmp_path / "cal", np.random.default_rng(2), walk_s=WALK_S, roles=("calibration",))
    with pytest.raises(ParameterError, match="--split loro.*1 recording"):
        splits.loro_splits(load_dataset(only))


def _results(folder: Path, rows) -> None:
    folder.mkdir(parents=True)
    pd.DataFrame(rows, columns=["kind", "recording", "method", "epochs", "mean_m", "median_m", "rmse_m"]).to_csv(
        folder / "results.csv", index=False)


def test_loro_table_is_numpy_statistics_of_the_splits(example, tmp_path):
    ds = load_dataset(example)
    rng = np.random.default_rng(0)
    means = {}
    fake = []
    for held, calibration in splits.loro_splits(ds):
        folder = tmp_path / held
        errors = {"lls": rng.uniform(2, 9), "grid_ml": rng.uniform(0.5, 3)}
        means[held] = errors
        rows = [("static", r, m, 10, e + (5 if r != held else 0), e, e) for r in ("pooled", held, "other")
                for m, e in errors.items()]
        _results(folder / "measured-localization", rows)
        if held.startswith("walk"):
            _results(folder / "measured-tracking", [("tracking", held, "ekf", 10, errors["grid_ml"] / 2, 0, 0)])
        outcomes = [Outcome("measured-localization", "ok", 1.0), Outcome("measured-tracking", "cached", 1.0)]
        fake.append((held, calibration, SimpleNamespace(outcomes=outcomes, report_dir=folder), ""))
    table, per_split = splits.loro_tables(ds, fake)
    assert len(per_split) == 4 * 2 + 2
    by = {(r["kind"], r["method"]): r for r in table}
    for method in ("lls", "grid_ml"):
        v = np.array([means[h][method] for h in means])
        row = by[("static", method)]
        assert row["splits"] == 4
        assert row["mean_m"] == pytest.approx(v.mean(), abs=1e-4)
        assert row["std_m"] == pytest.approx(v.std(ddof=1), abs=1e-4)
        assert (row["min_m"], row["max_m"]) == (pytest.approx(v.min(), abs=1e-4), pytest.approx(v.max(), abs=1e-4))
        for h in means:
            assert row[f"mean_m {h}"] == pytest.approx(means[h][method], abs=1e-12)
    ekf = by[("tracking", "ekf")]
    v = np.array([means[h]["grid_ml"] / 2 for h in ("walk_a", "walk_b")])
    assert ekf["splits"] == 2 and ekf["std_m"] == pytest.approx(v.std(ddof=1), abs=1e-4)
    assert splits.spread([1.0])["std_m"] is None and splits.spread([])["n"] == 0


# -------------------------------------------------------------------------------------------------- anchor density

def test_density_sizes_rule():
    assert splits.density_sizes(4) == (3, 4) and splits.density_sizes(6) == (3, 4, 5, 6)
    assert splits.density_sizes(8) == (3, 5, 6, 8) and splits.density_sizes(12) == (3, 6, 9, 12)
    assert splits.density_sizes(8, (6, 3)) == (3, 6)
    for bad in ((2,), (3, 9), (3, 3)):
        with pytest.raises(ParameterError, match="--sizes"):
            splits.density_sizes(8, bad)


def test_anchor_subsets_distinct_sized_and_reproducible():
    ids = [f"A{i}" for i in range(1, 9)]
    drawn = splits.anchor_subsets(ids, (3, 5, 8), 5, rng=np.random.default_rng(7))
    again = splits.anchor_subsets(ids, (3, 5, 8), 5, rng=np.random.default_rng(7))
    other = splits.anchor_subsets(ids, (3, 5, 8), 5, rng=np.random.default_rng(8))
    assert drawn == again and drawn != other
    assert [len(s) for s in drawn] == [3] * 5 + [5] * 5 + [8]            # C(8, 8) = 1 < 5: every subset
    assert len(set(drawn)) == len(drawn)
    assert all(list(s) == sorted(s, key=ids.index) and set(s) <= set(ids) for s in drawn)
    every = splits.anchor_subsets(ids[:4], (3,), 5, rng=np.random.default_rng(0))      # C(4, 3) = 4 <= 5
    assert every == [tuple(c) for c in itertools.combinations(ids[:4], 3)]
    with pytest.raises(TypeError):
        splits.anchor_subsets(ids, (3,), 5, rng=7)


def test_density_study_points_and_table(example, tmp_path):
    from locbook.suite.spec import load_suite
    suite = load_suite(SUITE)
    study, ds, drawn = splits.anchor_density_study(suite, str(example), subsets=2, sizes=(3, 4), sample_seed=3)
    assert drawn == splits.anchor_subsets(ds.anchor_ids, (3, 4), 2, rng=np.random.default_rng(3))
    from locbook.suite.study import expand_study
    points = expand_study(study)
    assert [p.values["anchors"] for p in points] == [",".join(s) for s in drawn]
    assert len({p.key for p in points}) == 4 and all(p.experiment.id == "measured-localization" for p in points)
    assert all(p.parameters["data"] == str(example.resolve()) for p in points)
    # the table: one row per (k, method), numpy's statistics of the subsets' pooled rows
    rng = np.random.default_rng(1)
    values = {}
    for p in points:
        values[p.key] = {m: rng.uniform(1, 5) for m in ("lls", "knn")}
        _results(tmp_path / p.key, [("static", "pooled", m, 9, e, e, e) for m, e in values[p.key].items()]
                 + [("static", "points", m, 3, 99.0, 0, 0) for m in values[p.key]])
    table, rows = splits.density_tables(points, tmp_path, {p.key for p in points}, ds.anchor_ids)
    assert [(r["k"], r["method"]) for r in table] == [(3, "lls"), (3, "knn"), (4, "lls"), (4, "knn")]
    for r in table:
        v = np.array([values[p.key][r["method"]] for p in points if len(p.values["anchors"].split(",")) == r["k"]])
        assert r["subsets"] == 2 and r["mean_m"] == pytest.approx(v.mean(), abs=1e-4)
        assert r["std_m"] == pytest.approx(v.std(ddof=1), abs=1e-4) and r["max_m"] == pytest.approx(v.max(), abs=1e-4)
    assert len(rows) == 8


# ------------------------------------------------------------------------------------------------------ end to end

@pytest.mark.slow
def test_loro_and_density_end_to_end(tmp_path):
    data = write_example_dataset(tmp_path / "example", np.random.default_rng(4), walk_s=30.0)
    reports = tmp_path / "reports"
    common = ["--suite", str(SUITE), "--reports", str(reports), "--profile", "quick", "--progress", "quiet"]
    assert main(["run", "--data", str(data), "--split", "loro", *common]) == 0
    loro = reports / "quick" / "data-example" / "loro"
    table = pd.read_csv(loro / "loro.csv")
    per_split = pd.read_csv(loro / "splits.csv")
    assert (loro / "loro.png").stat().st_size > 10_000 and "Leave-one-recording-out" in (loro / "loro.md").read_text()
    assert set(per_split["split"]) == {"survey", "points", "walk_a", "walk_b"}
    static = table[table["kind"] == "static"].set_index("method")
    assert static.loc["grid_ml", "splits"] == 4
    v = per_split[(per_split["kind"] == "static") & (per_split["method"] == "grid_ml")]["mean_m"].to_numpy()
    assert static.loc["grid_ml", "std_m"] == pytest.approx(np.std(v, ddof=1), abs=1e-3)
    tracking = table[table["kind"] == "tracking"].set_index("method")
    assert set(tracking["splits"]) == {2}                      # the two walks, each tracked when held out
    # a split's report is the cached report of its calibration parameter
    walk_a = per_split[per_split["split"] == "walk_a"]["report"].iloc[0]
    assert "calibration" in Path(walk_a).parent.parent.name
    # the errors of the generated data against its truth: grid ML within a few metres of the truth in every split
    assert 0 < static.loc["grid_ml", "max_m"] < 4.0
    assert main(["study", "anchor-density", "--data", str(data), "--sizes", "3,8", "--subsets", "2",
                 "--suite", str(SUITE), "--reports", str(reports), "--progress", "quiet"]) == 0
    density = reports / "quick" / "data-example" / "anchor-density"
    rows = pd.read_csv(density / "density.csv")
    assert set(rows["k"]) == {3, 8} and (density / "density.png").stat().st_size > 10_000
    assert len(rows) == 2 * rows["method"].nunique()
    assert set(rows[rows["k"] == 3]["subsets"]) == {2} and set(rows[rows["k"] == 8]["subsets"]) == {1}
    grid = rows[rows["method"] == "grid_ml"].set_index("k")["mean_m"]
    assert grid[8] < grid[3]                                   # more anchors, smaller error (generated truth)
    assert math.isfinite(grid[8])


def test_a_stopped_loro_run_keeps_the_earlier_table_and_never_shrinks_it(example, tmp_path, monkeypatch):
    """An interrupt after the first split leaves the complete table of an earlier run as it was (bytes)."""
    from locbook.suite import load_suite

    suite = load_suite()
    rng = np.random.default_rng(1)
    calls, runs = [], iter(range(1000))

    def fake_run_suite(suite_, experiments, profile, *, overrides, report_root, data, **_kw):
        held = next(n for n in ("survey", "points", "walk_a", "walk_b")
                    if n not in overrides["calibration"].split(","))
        folder = tmp_path / "runs" / f"{next(runs)}-{held}"
        _results(folder / "measured-localization", [("static", held, "lls", 10, rng.uniform(1, 5), 0, 0)])
        calls.append(held)
        stop = interrupt_after is not None and len(calls) > interrupt_after
        return SimpleNamespace(outcomes=[Outcome("measured-localization", "ok", 1.0)], report_dir=folder,
                               interrupted_by="SIGINT" if stop else None, disk_full=None, executor_error=None)

    monkeypatch.setattr(splits, "run_suite", fake_run_suite)
    interrupt_after = None
    whole = splits.run_loro(suite, None, "quick", data=str(example), report_root=tmp_path / "reports",
                            progress="quiet")
    assert whole.written and not whole.stopped and len(calls) == 4
    table = whole.folder / "loro.csv"
    before = table.read_bytes()
    assert len(pd.read_csv(table)) == 1 and pd.read_csv(table)["splits"].item() == 4
    calls.clear()
    interrupt_after = 1
    stopped = splits.run_loro(suite, None, "quick", data=str(example), report_root=tmp_path / "reports",
                              progress="quiet")
    assert stopped.stopped and stopped.kept and not stopped.written and len(calls) == 2
    assert table.read_bytes() == before
    # with no earlier table, a stopped run writes the splits it has (nothing to shrink)
    shutil.rmtree(whole.folder)
    calls.clear()
    first = splits.run_loro(suite, None, "quick", data=str(example), report_root=tmp_path / "reports",
                            progress="quiet")
    assert first.stopped and first.written and pd.read_csv(first.folder / "loro.csv")["splits"].item() == 2
