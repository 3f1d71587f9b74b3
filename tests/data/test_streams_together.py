"""Range and inertial streams on one data set, and what a building (floors) does with streams: the three features of
of the streams work that touch one recording, checked together (each alone: tests/data/test_ranges.py,
tests/data/test_inertial.py, tests/data/test_floors.py).

Truth is the generated data set's: ranges of 0.3 m against 4 dB shadowing, a 50 Hz IMU against 1 s RSS epochs."""
from __future__ import annotations

import numpy as np
import pytest

from locbook.data.dataset import load_dataset
from locbook.data.example import write_example_dataset
from locbook.data.measured import DataFormatError
from locbook.errors import ParameterError
from locbook.scenarios import measured as me


@pytest.fixture(scope="module")
def both(tmp_path_factory):
    folder = write_example_dataset(tmp_path_factory.mktemp("both") / "set", np.random.default_rng(2), walk_s=60.0,
                                   ranges=True, inertial=True)
    ds = load_dataset(folder)
    model = me.channel(me.calibrate(ds))
    proto = me.protocol(ds, model)
    st = me.static_results(ds, model, proto, seed=1, n_bootstrap=20, block_s=10.0)
    tr = me.tracking_results(ds, model, proto, seed=1, n_particles=200, particle_runs=2, n_bootstrap=20, block_s=10.0)
    return ds, st, tr


def _pooled(res) -> dict:
    return {r["method"]: r for r in res["rows"] if r["recording"] == me.POOLED}


def test_a_recording_with_ranges_and_inertial_samples_loads_both_on_its_own_clock(both):
    ds, _, _ = both
    for name in ds.recordings_with("track"):
        rec = ds.recording(name)
        assert rec.ranges is not None and rec.inertial is not None
        range_m, _std = ds.ranges(name)
        assert range_m.shape == ds.epochs(name).rss_dbm.shape
        # both streams start within a second of the RSS (the example writes them from t = 0 on the readings' clock)
        assert abs(float(np.nanmin(rec.inertial.time_s)) - float(ds.epochs(name).time_s.min())) < 1.0


def test_every_stream_method_runs_beside_the_rss_battery_and_beats_it_where_its_readings_are_better(both):
    _, st, tr = both
    static, track = _pooled(st), _pooled(tr)
    # 0.3 m ranges against 4 dB RSS: range lateration is several times better than the best RSS method
    best_rss = min(static[m]["mean_m"] for m in ("rss_ml", "grid_ml", "grid_mmse", "knn"))
    assert static["range_nls"]["mean_m"] < 0.3 * best_rss
    for fused in ("ekf_rss_range", "ukf_rss_range", "kf_acc", "ekf_rss_acc", "ekf_rss_imu", "ukf_rss_imu"):
        assert fused in track, fused
        assert track[fused]["mean_m"] < track["ekf"]["mean_m"], fused
    # the range fusion, whose readings are the best, is the best of all
    assert track["ekf_rss_range"]["mean_m"] < min(track[t]["mean_m"] for t in ("ekf_rss_imu", "ukf_rss_imu"))
    assert set(tr["fusion"]) == {"kf_acc", "ekf_rss_acc", "ekf_rss_imu", "ukf_rss_imu"}
    assert {"ekf_rss_range", "ukf_rss_range", *tr["fusion"]} <= set(tr["battery"])


def test_a_building_refuses_streams_in_one_line_naming_the_recording_and_key(tmp_path):
    with pytest.raises(ParameterError, match="floors: a building's example writes RSS readings only"):
        write_example_dataset(tmp_path / "b0", np.random.default_rng(1), floors=2, ranges=True)
    folder = write_example_dataset(tmp_path / "b1", np.random.default_rng(1), walk_s=20.0, floors=2)
    manifest = folder / "dataset.toml"
    text = manifest.read_text()
    head, sep, rest = text.partition('name = "survey"\n')
    assert sep, "the building's manifest names its survey"
    manifest.write_text(head + sep + 'ranges = "survey_ranges.csv"\n' + rest)
    with pytest.raises(DataFormatError) as err:
        load_dataset(folder, floor="F1")
    message = str(err.value)
    assert "\n" not in message and "'survey'" in message and "ranges" in message and "floors" in message


def test_an_anchor_subset_of_a_ranged_data_set_equals_the_data_set_written_with_those_anchors_only(tmp_path):
    import pandas as pd

    from locbook.data.selection import select
    folder = write_example_dataset(tmp_path / "full", np.random.default_rng(4), walk_s=20.0, ranges=True)
    keep = ["A1", "A2", "A4", "A6", "A7"]
    sub = select(load_dataset(folder), anchors=",".join(keep))
    # the independent construction: every file filtered by pandas to the kept anchors, loaded afresh
    cut = tmp_path / "cut"
    cut.mkdir()
    for path in folder.iterdir():
        if path.suffix == ".csv" and path.name != "outline.csv":
            table = pd.read_csv(path, dtype=str, keep_default_na=False)
            column = "id" if path.name == "anchors.csv" else "receiver"
            table[table[column].isin(keep)].to_csv(cut / path.name, index=False)
        else:
            (cut / path.name).write_bytes(path.read_bytes())
    alone = load_dataset(cut)
    assert sub.anchor_ids == alone.anchor_ids == tuple(keep)
    for name in sub.recordings:
        np.testing.assert_array_equal(sub.epochs(name).rss_dbm, alone.epochs(name).rss_dbm)
        for a, b in zip(sub.ranges(name), alone.ranges(name)):
            np.testing.assert_array_equal(a, b)
