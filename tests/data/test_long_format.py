"""The long format of measured data: every rule refuses a malformed file with a message naming file, line and
column (one test per rule). Data sets and their manifests: tests/data/test_dataset.py."""

import numpy as np
import pytest

from locbook.data.measured import (
    DataFormatError,
    epochs,
    read_anchors,
    read_outline,
    read_path_segments,
    read_readings,
    regular_epochs,
)

GOOD = """time_s,transmitter,receiver,rssi_dbm,x_m,y_m
0.0,tag,A,-60.5,1.0,2.0
0.0,tag,B,,1.0,2.0
0.5,tag,A,-61,1.1,2.0
0.5,tag,B,-70,1.1,2.0
"""
ANCHORS = "id,x,y,z\nA,0,0,2.5\nB,5,0,2.4\nC,0,5,2.3\n"


def write(tmp_path, text, name="readings.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def rows(text, line, new):
    """``text`` with its line number ``line`` (1 = header) replaced by ``new``."""
    lines = text.splitlines()
    lines[line - 1] = new
    return "\n".join(lines) + "\n"


def refuses(tmp_path, text, *fragments, reader=read_readings, **kw):
    path = write(tmp_path, text)
    with pytest.raises(DataFormatError) as info:
        reader(path, **kw)
    message = str(info.value)
    assert str(path) in message
    for fragment in fragments:
        assert fragment in message, message
    return message


def test_good_file_reads_typed_with_missing_as_nan(tmp_path):
    table = read_readings(write(tmp_path, GOOD), anchor_ids=["A", "B", "C"])
    assert table["rssi_dbm"].isna().tolist() == [False, True, False, False]
    assert table["time_s"].dtype == float and np.isnan(table["z_m"]).all()
    ep = epochs(table, ["A", "B", "C"])
    np.testing.assert_array_equal(ep.rss_dbm, [[-60.5, np.nan, np.nan], [-61.0, -70.0, np.nan]])
    np.testing.assert_array_equal(ep.position_m[:, :2], [[1.0, 2.0], [1.1, 2.0]])


def test_missing_file(tmp_path):
    with pytest.raises(DataFormatError, match="does not exist"):
        read_readings(tmp_path / "absent.csv")


def test_missing_required_column(tmp_path):
    refuses(tmp_path, GOOD.replace("rssi_dbm", "rssi"), "missing column(s) ['rssi_dbm']")


def test_duplicated_header_column(tmp_path):
    text = GOOD.replace("x_m,y_m", "x_m,x_m")
    refuses(tmp_path, text, "more than once")


def test_time_not_a_number(tmp_path):
    refuses(tmp_path, rows(GOOD, 4, "zero,tag,A,-61,1.1,2.0"), "line 4", "'time_s'", "'zero' is not a finite number")


def test_time_missing(tmp_path):
    refuses(tmp_path, rows(GOOD, 3, ",tag,B,-70,1.0,2.0"), "line 3", "'time_s'", "missing")


def test_empty_receiver_id(tmp_path):
    refuses(tmp_path, rows(GOOD, 5, "0.5,tag,,-70,1.1,2.0"), "line 5", "'receiver'", "empty")


def test_rssi_outside_plausible_range(tmp_path):
    refuses(tmp_path, rows(GOOD, 2, "0.0,tag,A,60.5,1.0,2.0"), "line 2", "'rssi_dbm'", "outside [-150, 20] dBm")


def test_rssi_infinite(tmp_path):
    refuses(tmp_path, rows(GOOD, 2, "0.0,tag,A,-inf,1.0,2.0"), "line 2", "'rssi_dbm'", "not a finite number")


def test_rssi_text(tmp_path):
    refuses(tmp_path, rows(GOOD, 4, "0.5,tag,A,-61dBm,1.1,2.0"), "line 4", "'rssi_dbm'", "'-61dBm'")


def test_half_a_true_position(tmp_path):
    refuses(tmp_path, rows(GOOD, 4, "0.5,tag,A,-61,1.1,"), "line 4", "'y_m'", "missing while 'x_m' is given")


def test_unknown_receiver(tmp_path):
    refuses(tmp_path, rows(GOOD, 5, "0.5,tag,D,-70,1.1,2.0"), "line 5", "'receiver'", "'D' is not an anchor id",
            anchor_ids=["A", "B", "C"])


def test_repeated_reading(tmp_path):
    refuses(tmp_path, rows(GOOD, 5, "0.5,tag,A,-70,1.1,2.0"), "line 5", "repeats line 4")


def test_time_going_back(tmp_path):
    text = GOOD + "0.2,tag,A,-65,1.2,2.0\n"
    refuses(tmp_path, text, "line 6", "'time_s'", "time goes back")


def test_epoch_with_two_true_positions(tmp_path):
    table = read_readings(write(tmp_path, rows(GOOD, 3, "0.0,tag,B,,1.5,2.0")))
    with pytest.raises(DataFormatError, match="different true positions"):
        epochs(table, ["A", "B"])


def test_anchor_rules(tmp_path):
    # no z column is a 2-D anchors file (tests/data/test_data_format.py); a z column needs every height
    refuses(tmp_path, ANCHORS.replace(",z", ""), "line 2", "4 fields, the header 3", reader=read_anchors)
    refuses(tmp_path, rows(ANCHORS, 3, "B,5,0,"), "line 3", "'z'", "the height is empty", "no z column",
            reader=read_anchors)
    refuses(tmp_path, ANCHORS.replace("y,z", "z,q"), "missing column(s) ['y']", reader=read_anchors)
    refuses(tmp_path, rows(ANCHORS, 4, "A,0,5,2.3"), "line 4", "'id'", "appears twice", reader=read_anchors)
    refuses(tmp_path, rows(ANCHORS, 3, "B,5,,2.4"), "line 3", "'y'", "missing", reader=read_anchors)
    refuses(tmp_path, rows(ANCHORS, 2, "A,0,0,nan2"), "line 2", "'z'", "not a finite number", reader=read_anchors)


def test_outline_rules(tmp_path):
    refuses(tmp_path, "x,y\n0,0\n1,0\n0,0\n", "at least 3 distinct vertices", reader=read_outline)
    refuses(tmp_path, "x,y\n0,0\n1,0\n2,0\n", "encloses no area", reader=read_outline)
    refuses(tmp_path, "x,y\n0,0\n1,0\nx,1\n", "line 4", "'x'", reader=read_outline)
    np.testing.assert_array_equal(read_outline(write(tmp_path, "x,y\n0,0\n1,0\n1,1\n0,0\n")), [[0, 0], [1, 0], [1, 1]])


def test_path_rules(tmp_path):
    refuses(tmp_path, "x0,y0,x1\n0,0,1\n", "missing column(s) ['y1']", reader=read_path_segments)


def test_regular_epochs_inserts_silent_ticks(tmp_path):
    table = read_readings(write(tmp_path, GOOD + "1.5,tag,A,-62,1.3,2.0\n"))
    reg, tick = regular_epochs(epochs(table, ["A", "B"]), 0.5)
    assert tick.tolist() == [0, 1, 3]
    assert np.isnan(reg.rss_dbm[2]).all() and np.isnan(reg.position_m[2]).all()
    with pytest.raises(ValueError, match="0.1 s off the 0.4 s clock"):
        regular_epochs(epochs(table, ["A", "B"]), 0.4, tolerance_s=0.05)
