"""The long format's rules on hostile files: every malformed row is refused with a
message naming file, line and column (or field count, or byte), ids are text, sentinel values are declared
not heard, and a recording with a clock jump is refused before anything large is allocated."""
import re
import warnings

import numpy as np
import pandas as pd
import pytest

from locbook.data.dataset import load_dataset
from locbook.data.measured import (
    DataFormatError,
    Epochs,
    MeasuredDataWarning,
    epochs,
    read_anchors,
    read_readings,
    regular_epochs,
)
from locbook.errors import ParameterError

HEADER = "time_s,transmitter,receiver,rssi_dbm\n"


def write(tmp_path, text, name="readings.csv"):
    path = tmp_path / name
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8")
    return path


def refused(path, *fragments, reader=read_readings, **kw):
    with pytest.raises(DataFormatError) as info:
        reader(path, **kw)
    message = str(info.value)
    assert str(path) in message, message
    for fragment in fragments:
        assert fragment in message, message
    return message


# -- field counts --------------------------------------------------------------------------------------------
def test_short_row_is_an_error_naming_the_missing_column(tmp_path):
    path = write(tmp_path, HEADER + "0,t,A1,-60\n0,t,A2\n")
    refused(path, "line 3", "'rssi_dbm'", "3 field(s)", "4")


def test_short_row_missing_several_columns(tmp_path):
    path = write(tmp_path, HEADER + "0,t,A1,-60\n0.5,t\n")
    refused(path, "line 3", "'receiver'", "'rssi_dbm'")


def test_empty_rssi_field_stays_not_heard(tmp_path):
    """The documented rule (module docstring, docs/filters.md): an empty rssi_dbm, or NaN, is "not heard"."""
    table = read_readings(write(tmp_path, HEADER + "0,t,A1,-60\n0,t,A2,\n0,t,A3,NaN\n"))
    assert table["rssi_dbm"].iloc[0] == -60.0 and table["rssi_dbm"].iloc[1:].isna().all()


@pytest.mark.parametrize("row,line", [(2, 2), (3, 3)])
def test_extra_field_is_an_error_naming_expected_and_found(tmp_path, row, line):
    rows = ["0,t,A1,-60", "0,t,A2,-61"]
    rows[row - 2] += ",5"
    path = write(tmp_path, HEADER + "\n".join(rows) + "\n")
    message = refused(path, f"line {line}")
    assert re.search(r"4 field", message) and re.search(r"5 field|found 5|has 5", message), message


def test_extra_field_on_every_row_is_not_taken_for_an_index(tmp_path):
    """pandas turns a first column without header name into the index, shifting every column by one."""
    path = write(tmp_path, HEADER + "7,0,t,A1,-60\n8,0.5,t,A2,-61\n")
    refused(path, "line 2", "4 field")


def test_blank_lines_do_not_shift_line_numbers(tmp_path):
    path = write(tmp_path, HEADER + "0,t,A1,-60\n\n  \r\n0.5,t,A2,-61x\n")
    refused(path, "line 5", "'rssi_dbm'", "'-61x'")


def test_quoted_field_over_two_lines_counts_both(tmp_path):
    path = write(tmp_path, HEADER.rstrip() + ",note\n0,t,A1,-60,\"a, b\nc\"\n0.5,t,A2,-61x,\n")
    refused(path, "line 4", "'rssi_dbm'", "'-61x'")
    assert read_readings(write(tmp_path, HEADER.rstrip() + ",note\n0,t,A1,-60,\"a, b\nc\"\n", "ok.csv"))[
        "note"].tolist() == ["a, b\nc"]


# -- encoding ------------------------------------------------------------------------------------------------
def test_non_utf8_bytes_are_refused_with_line_and_byte(tmp_path):
    text = HEADER + "0,t,A1,-60\n0,t\xe9,A2,-61\n"
    data = text.encode("cp1252")
    path = write(tmp_path, data)
    offset = data.index(b"\xe9")                                # independent of the reader: where the byte is
    line = data[:offset].count(b"\n") + 1
    column = offset - data[:offset].rfind(b"\n")               # 1-based byte of the line
    assert (line, column) == (3, 4)
    message = refused(path, f"line {line}", "0xe9", "UTF-8")
    assert f"byte {column}" in message or f"column {column}" in message, message


def test_utf8_with_bom_reads(tmp_path):
    path = write(tmp_path, ("\ufeff" + HEADER + "0,t\u00e9,A1,-60\n").encode("utf-8"))
    table = read_readings(path)
    assert list(table.columns[:4]) == ["time_s", "transmitter", "receiver", "rssi_dbm"]
    assert table["transmitter"].iloc[0] == "t\u00e9"


# -- ids are text ----------------------------------------------------------------------------------------------
def test_na_ids_are_ids(tmp_path):
    anchors = write(tmp_path, "id,x,y,z\nNA,0,0,2\nN/A,5,0,2\nnan,0,5,2\n", "anchors.csv")
    table = read_anchors(anchors)
    assert table["id"].tolist() == ["NA", "N/A", "nan"]
    readings = write(tmp_path, HEADER + "0,NA,NA,-60\n0,NA,N/A,\n0,N/A,nan,NA\n")
    out = read_readings(readings, anchor_ids=table["id"])
    assert out["transmitter"].tolist() == ["NA", "NA", "N/A"] and out["receiver"].tolist() == ["NA", "N/A", "nan"]
    assert np.isnan(out["rssi_dbm"].iloc[1]) and np.isnan(out["rssi_dbm"].iloc[2])   # NA in a number = not heard
    ep = epochs(out, table["id"])
    assert ep.rss_dbm.shape == (2, 3) and ep.rss_dbm[0, 0] == -60.0


def test_empty_id_is_still_refused(tmp_path):
    refused(write(tmp_path, HEADER + "0,t,A1,-60\n0, ,A2,-61\n"), "line 3", "'transmitter'", "empty")


# -- times ---------------------------------------------------------------------------------------------------
def test_nanosecond_timestamps_are_diagnosed(tmp_path):
    path = write(tmp_path, HEADER + "1581250000000000000,t,A1,-60\n1581250000000000100,t,A1,-61\n")
    message = refused(path, "line 2", "'time_s'", "nanoseconds")
    assert "repeats" not in message


def test_millisecond_timestamps_are_diagnosed(tmp_path):
    path = write(tmp_path, HEADER + "1581250000000,t,A1,-60\n1581250000100,t,A1,-61\n")
    refused(path, "line 2", "'time_s'", "milliseconds")


def test_times_equal_only_as_floats_say_so(tmp_path):
    """Two different times in the file that round to the same 64-bit float are not called a repeat blindly."""
    a, b = "1581250000.00000001", "1581250000.00000002"
    assert float(a) == float(b)
    path = write(tmp_path, HEADER + f"{a},t,A1,-60\n{b},t,A1,-61\n")
    refused(path, "line 3", a, b, "64-bit")


def test_time_going_back_prints_distinguishable_times(tmp_path):
    path = write(tmp_path, HEADER + "1581250000.5,t,A1,-60\n1581250000.25,t,A1,-61\n")
    refused(path, "line 3", "1581250000.25 s after 1581250000.5 s", "sort=True")


def test_sort_reorders_rows_by_time_stably(tmp_path):
    text = HEADER + "2.0,t,A1,-60\n1.0,t,A2,-61\n1.0,t,A1,-62\n0.5,u,A1,-63\n2.0,u,A2,-64\n"
    path = write(tmp_path, text)
    table = read_readings(path, sort=True)
    raw = pd.read_csv(path)
    expected = raw.iloc[np.argsort(raw["time_s"].to_numpy(), kind="stable")]
    assert table["time_s"].tolist() == expected["time_s"].tolist()
    assert table["receiver"].tolist() == expected["receiver"].tolist()
    assert table["rssi_dbm"].tolist() == expected["rssi_dbm"].tolist()
    # the messages still name the file's lines after sorting
    refused(write(tmp_path, text + "1.0,t,A2,-65\n", "dup.csv"), "line 7", "repeats line 3", sort=True)


# -- values --------------------------------------------------------------------------------------------------
SENTINELS = HEADER + "0,t,A1,0\n0,t,A2,2\n0,t,A3,-70\n0.5,t,A1,4\n0.5,t,A2,-71.5\n"


def test_sentinel_values_are_not_heard(tmp_path):
    table = read_readings(write(tmp_path, SENTINELS), invalid_values_dbm=(0, 2, 4))
    np.testing.assert_array_equal(table["rssi_dbm"].to_numpy(), [np.nan, np.nan, -70.0, np.nan, -71.5])


def test_readings_at_or_above_0_dbm_warn_once_without_sentinels(tmp_path):
    path = write(tmp_path, SENTINELS)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        table = read_readings(path)
    ours = [w for w in caught if "0 dBm" in str(w.message)]
    assert len(ours) == 1, [str(w.message) for w in caught]
    message = str(ours[0].message)
    assert "3" in message and "invalid_values_dbm" in message and str(path) in message
    assert table["rssi_dbm"].tolist()[2] == -70.0           # a warning, not a refusal: the values stay
    with pytest.warns(MeasuredDataWarning):
        read_readings(path, invalid_values_dbm=())             # no sentinel declared: still warned
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_readings(path, invalid_values_dbm=(0, 2, 4))   # declared: silent


def test_valid_range_refuses_with_line(tmp_path):
    path = write(tmp_path, HEADER + "0,t,A1,-60\n0,t,A2,-140\n")
    read_readings(path)                                      # inside the default range
    refused(path, "line 3", "'rssi_dbm'", "-140", "[-130, 30]", valid_range_dbm=(-130, 30))


def test_bad_options_are_refused(tmp_path):
    path = write(tmp_path, SENTINELS)
    with pytest.raises(ParameterError, match="valid_range_dbm"):
        read_readings(path, valid_range_dbm=(10, -10))
    with pytest.raises(ParameterError, match="invalid_values_dbm"):
        read_readings(path, invalid_values_dbm=(np.nan,))


def test_a_manifest_passes_the_reading_options(tmp_path):
    write(tmp_path, "id,x,y,z\nA1,0,0,2\nA2,5,0,2\nA3,0,5,2\n", "anchors.csv")
    write(tmp_path, SENTINELS, "track.csv")
    write(tmp_path, "time_s,transmitter,receiver,rssi_dbm,x_m,y_m\n0,t,A1,-50,1,1\n", "cal.csv")
    write(tmp_path, """name = "s"\ntitle = "t"\nlicense = "CC0"\nattribution = "test"\ntag_height_m = 1.0
[readings]\ninvalid_values_dbm = [0, 2, 4]\n[geometry]\nanchors = "anchors.csv"\ntag_height_m = 1.0
[epochs]\nwindow_s = 0.5\n[[recording]]\nname = "cal"\nfile = "cal.csv"\nrole = "calibration"
[[recording]]\nname = "r"\nfile = "track.csv"\nrole = "track"\n""".replace('tag_height_m = 1.0\n[readings]',
'[readings]'),
          "dataset.toml")
    data = load_dataset(tmp_path)
    assert np.isnan(data.epochs("r").rss_dbm).sum() == 6 - 2


# -- anchors -------------------------------------------------------------------------------------------------
def test_coincident_anchors_are_refused_naming_both(tmp_path):
    path = write(tmp_path, "id,x,y,z\nA,0,0,2\nB,5,0,2\nC,0.0,0,2.0\n", "anchors.csv")
    refused(path, "'A'", "'C'", "lines 2 and 4", reader=read_anchors)


def test_anchors_above_one_another_are_distinct(tmp_path):
    table = read_anchors(write(tmp_path, "id,x,y,z\nA,0,0,2\nB,0,0,3\nC,5,0,2\n", "anchors.csv"))
    assert len(table) == 3


# -- regular epochs ------------------------------------------------------------------------------------------
def _epochs(time_s, m=2):
    n = len(time_s)
    return Epochs(np.asarray(time_s, float), np.full((n, m), -60.0), np.full((n, 3), np.nan), np.full(n, np.nan),
                  np.full(n, "t", dtype=object), tuple(f"A{j}" for j in range(m)))


def test_regular_epochs_refuses_a_clock_jump_before_allocating():
    ep = _epochs([0.0, 0.1, 0.2, 1e9, 1e9 + 0.1])
    with pytest.raises(ValueError) as info:
        regular_epochs(ep, 0.1)
    message = str(info.value)
    assert "0.2 s" in message and "1000000000.0 s" in message        # where the gap is
    assert "10,000,000,002" in message                               # how many epochs it would take
    assert "max_epochs" in message and "split" in message


def test_regular_epochs_max_epochs_bounds_and_allows():
    ep = _epochs([0.0, 0.1, 100.0])
    reg, tick = regular_epochs(ep, 0.1)
    assert len(reg) == 1001 and tick.tolist() == [0, 1, 1000]
    with pytest.raises(ValueError, match="1,001"):
        regular_epochs(ep, 0.1, max_epochs=1000)
    assert len(regular_epochs(ep, 0.1, max_epochs=1001)[0]) == 1001


def test_regular_epochs_of_nothing_is_nothing(tmp_path):
    """Consistent with epochs() of no readings: an empty result, not an IndexError."""
    table = read_readings(write(tmp_path, HEADER))
    empty = epochs(table, ["A1", "A2"])
    assert len(empty) == 0 and empty.rss_dbm.shape == (0, 2)
    reg, tick = regular_epochs(empty, 0.1)
    assert len(reg) == 0 and reg.rss_dbm.shape == (0, 2) and reg.position_m.shape == (0, 3)
    assert tick.shape == (0,) and tick.dtype.kind == "i"


def test_time_going_back_is_checked_per_transmitter(tmp_path):
    """Interleaved transmitters: each one's own times must not go back; the other's rows do not count."""
    ok = HEADER + "0,t,A1,-60\n0.5,u,A1,-61\n0.2,t,A1,-62\n0.6,u,A1,-63\n"
    assert len(read_readings(write(tmp_path, ok))) == 4
    bad = HEADER + "0,t,A1,-60\n0.5,u,A1,-61\n0.7,t,A1,-62\n0.25,u,A1,-63\n0.1,t,A1,-64\n"
    refused(write(tmp_path, bad, "bad.csv"), "line 5", "transmitter 'u'", "0.25 s after 0.5 s on line 3")


# -- clear messages for a header's trailing comma, CR-only files, huge tick counts -----------
def test_a_trailing_comma_on_the_header_only_is_named(tmp_path):
    """'...,rssi_dbm,' over 4-field rows was refused as "column(s) ['']: ... missing", naming a column nobody wrote."""
    path = write(tmp_path, HEADER.rstrip("\n") + ",\n0,t,A1,-60\n0.5,t,A2,-61\n")
    message = refused(path, "line 1", "the header ends with an empty column name (a trailing comma?)")
    assert "['']" not in message, message
    refused(write(tmp_path, "\n" + HEADER.rstrip("\n") + ",\n0,t,A1,-60\n", "blank_first.csv"), "line 2: the header")
    # a trailing comma on every line is consistent: it loads, the empty column is an extra one
    table = read_readings(write(tmp_path, HEADER.rstrip("\n") + ",\n0,t,A1,-60,\n0.5,t,A2,-61,\n", "every.csv"))
    assert table["rssi_dbm"].tolist() == [-60.0, -61.0]


@pytest.mark.parametrize("newline", ["\r", "\r\n", "\n"])
def test_non_utf8_line_number_counts_lines_as_the_csv_reader_does(tmp_path, newline):
    """A CR-only file (old Mac export) has no '\\n' at all: the message said line 1 for a byte on line 4. The line is
    the one Python's csv reader reports for the row holding the byte (it ends lines at CR, LF and CRLF)."""
    import csv
    import io
    text = newline.join([HEADER.rstrip("\n"), "0,t,A1,-60", "", "0,t\xe9,A2,-61", "0.5,t,A1,-62"]) + newline
    data = text.encode("cp1252")
    reader = csv.reader(io.StringIO(text, newline=""))
    line = next(reader.line_num for row in reader if any("\xe9" in f for f in row))     # independent: csv's count
    assert line == 4
    message = refused(write(tmp_path, data), f"line {line},", "0xe9", "byte 4 of the line")
    assert "'0,t\\ufffd,A2,-61'" in message or "0,t\ufffd,A2,-61'" in message, message   # just that line's text


def test_regular_epochs_prints_a_huge_tick_count_briefly():
    """A time of 1e300 s made the message print the tick count with about 300 digits ({:,.0f})."""
    ep = _epochs([0.0, 0.1, 1e300])
    with pytest.raises(ValueError) as info:
        regular_epochs(ep, 0.1)
    message = str(info.value)
    assert not re.search(r"\d[\d,]{40,}", message), message
    assert "1e+301 epochs" in message and "1e+301 empty ticks" in message, message
    assert len(message) < 800, len(message)


def test_the_fast_reader_and_the_exact_reader_agree(tmp_path):
    """A logger's file (one record per line, quoted fields allowed) goes through pandas' C reader; the same rows
    with a blank line go through the exact reader. All give the same checked table, ids, missing values and extra
    columns included."""
    from locbook.data.measured import read_readings_table
    body = ("time_s,transmitter,receiver,rssi_dbm,x_m,y_m,point\n0.25,tag, A1,-60.5,1.0,2.0,P1\n"
            "0.25,tag,A2,,1.0,2.0,P1\n"
            "0.5,NA,A1,NaN,N/A,,P2\n0.75,tag,A3,-70,3,4, P2\n")
    fast_path = write(tmp_path, body, "fast.csv")
    quoted_path = write(tmp_path, body.replace(",P1\n0.25", ',"P1"\n0.25', 1), "quoted.csv")
    exact_path = write(tmp_path, body.replace("\n0.5", "\n\n0.5", 1), "exact.csv")
    assert read_readings_table(fast_path)[0].attrs.get("parsed") and read_readings_table(quoted_path)[0].attrs
    assert not read_readings_table(exact_path)[0].attrs
    a = read_readings(fast_path)
    for other in (quoted_path, exact_path):
        b = read_readings(other)
        for col in a.columns:
            left, right = a[col].astype(object).to_numpy(), b[col].astype(object).to_numpy()
            assert [str(v).strip() for v in left] == [str(v).strip() for v in right], col
    assert list(a["transmitter"]) == ["tag", "tag", "NA", "tag"] and list(a["receiver"]) == ["A1", "A2", "A1", "A3"]
