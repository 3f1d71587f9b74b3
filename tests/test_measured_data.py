"""The long format of measured data: every rule refuses a malformed file with a message naming file, line and
column (one test per rule), and the Kolakowski (2021) adapter keeps every empty cell as NaN (not heard)."""
import csv
import re

import numpy as np
import pandas as pd
import pytest

from locbook.data.measured import (DataFormatError, MeasuredData, epochs, kolakowski2021, measured_data_dir,
                                   read_anchors, read_outline, read_path_segments, read_readings, regular_epochs)

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
    refuses(tmp_path, ANCHORS.replace(",z", ""), "missing column(s) ['z']", reader=read_anchors)
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


# -- the Kolakowski (2021) adapter ---------------------------------------------------------------------------
def _source_cells(name):
    """The source file read with the csv module (independent of the adapter): RSSI cells per row, as text."""
    with open(measured_data_dir("kolakowski2021") / name, newline="") as fh:
        reader = csv.DictReader(fh)
        return [[row[f"rssi_{a}"] for a in range(1, 7)] for row in reader]


@pytest.fixture(scope="module")
def kolakowski():
    return kolakowski2021()


@pytest.mark.parametrize("recording,name", [("calibration", "calibration_df.csv"), ("robot", "test_robot_df.csv"),
                                            ("walk", "test_walk_df.csv")])
def test_kolakowski_empty_cells_are_not_heard(kolakowski, recording, name):
    cells = _source_cells(name)
    ep = kolakowski.epochs(recording)
    assert ep.rss_dbm.shape == (len(cells), 6)
    empty = np.array([[c.strip() == "" for c in row] for row in cells])
    np.testing.assert_array_equal(np.isnan(ep.rss_dbm), empty)
    heard = np.array([[float(c) if c.strip() else np.nan for c in row] for row in cells])
    np.testing.assert_array_equal(ep.rss_dbm, heard)


def test_kolakowski_facts(kolakowski):
    cal, robot, walk = (kolakowski.epochs(k) for k in ("calibration", "robot", "walk"))
    assert (len(cal), len(robot), len(walk)) == (4104, 719, 876)       # the data set's README
    assert np.isclose(robot.time_s[-1] - robot.time_s[0], 352.0, atol=0.5)
    assert np.all(robot.position_m[:, 2] == 1.3) and np.isnan(walk.position_m).all()
    assert kolakowski.anchors_m.shape == (6, 3) and kolakowski.outline_m.shape[1] == 2
    assert "CC BY 4.0" in kolakowski.attribution and "10.3390/s21186270" in kolakowski.attribution


def test_kolakowski_round_trip_through_the_long_format(kolakowski, tmp_path):
    """Written out in the long format and read back by the generic reader, the robot drive is unchanged."""
    path = tmp_path / "robot_long.csv"
    kolakowski.recordings["robot"].to_csv(path, index=False, float_format="%.17g")
    anchors = tmp_path / "anchors.csv"
    kolakowski.anchors.to_csv(anchors, index=False)
    again = MeasuredData.from_files("copy", anchors, {"robot": path}, attribution=kolakowski.attribution)
    a, b = kolakowski.epochs("robot"), again.epochs("robot")
    np.testing.assert_array_equal(a.rss_dbm, b.rss_dbm)
    np.testing.assert_array_equal(a.position_m, b.position_m)


def test_kolakowski_malformed_wide_cell_names_the_source_column(tmp_path):
    src = measured_data_dir("kolakowski2021")
    for name in ("anchors.csv", "layout.csv", "path_reference.csv", "test_robot_df.csv", "test_walk_df.csv"):
        (tmp_path / name).write_bytes((src / name).read_bytes())
    lines = (src / "calibration_df.csv").read_text().splitlines()
    fields = lines[9].split(",")
    fields[7] = "-5x"                                 # rssi_3 of the 9th data row (line 10)
    lines[9] = ",".join(fields)
    (tmp_path / "calibration_df.csv").write_text("\n".join(lines) + "\n")
    with pytest.raises(DataFormatError) as info:
        kolakowski2021(tmp_path)
    assert re.search(r"calibration_df\.csv, line 10, column 'rssi_3': '-5x' is not a finite number", str(info.value))
