"""Property-based fuzzing of the data-set manifest (``dataset.toml``) and the long-format readers.

Inputs: a valid small data set whose manifest gets random edits (any key set to a value of any type: text, huge
integers, 1e300, NaN, infinities, bools, lists, tables; keys deleted; unknown keys), whose files are deleted,
garbled (random bytes, a non-UTF-8 byte, a NUL), replaced by random CSV text or by a link out of the folder; and
random readings and anchors CSVs (random cells: numbers, specials, ``True``, quoted fields, blank and short rows,
CR line ends, byte-order marks). The rule every call must keep:

- it loads, and what it holds is physical: finite anchors within :data:`~locbook.data.measured.MAX_COORDINATE_M`,
  a finite outline and tag height, readings finite or NaN (never infinite) inside the valid range, true positions
  either complete (x, y and z finite) or absent, and calibration epochs with a true position; or
- it raises the project's one-line error (:class:`locbook.LocbookError`: ``DataFormatError`` or
  ``ParameterError``), never another exception type (no KeyError, TypeError, UnicodeDecodeError, csv.Error,
  OverflowError, scipy's ValueError) and never a message over several lines or one that echoes a file;
- the fast reader (pandas' C parser) and the exact reader agree: a file both take gives the same table, and a file
  one refuses the other refuses.

Example counts are bounded (``max_examples``) so that the module runs in well under a minute.
"""
import math
import re
import shutil
import tempfile
import tomllib
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import locbook as lb
import locbook.data.csvfile as csvfile
import locbook.data.measured as measured
import locbook.data.readings_file as fast_reader
from builders import ANCHORS, TRACK, calibration_csv, toml_document
from locbook.data.dataset import load_dataset
from locbook.data.measured import RSSI_RANGE_DBM, read_anchors, read_readings, validate_readings

pytestmark = pytest.mark.fuzz

MAX_COORDINATE_M = getattr(measured, "MAX_COORDINATE_M", 1e7)       # getattr: the module collects on older code

FUZZ = settings(max_examples=150, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                       HealthCheck.function_scoped_fixture])
#: the longest message of a refusal (paths of the temporary folder included): one line, never a file's content
MAX_MESSAGE_CHARS = 1500

CAL = calibration_csv(points=True)
OUTLINE = "x,y\n-1,-1\n7,-1\n7,7\n-1,7\n"
PATH = "x0,y0,x1,y1\n0,3,5,3\n"
FILES = {"anchors.csv": ANCHORS, "cal.csv": CAL, "walk.csv": TRACK, "outline.csv": OUTLINE, "path.csv": PATH}


def manifest() -> dict:
    """The valid manifest the edits start from (every section and most keys present)."""
    return {"name": "fuzz", "title": "fuzzed", "license": "CC0 1.0", "attribution": "test",
            "units": {"time": "s", "length": "m", "rssi": "dBm"},
            "readings": {"valid_range_dbm": [-120.0, 0.0], "backward_time": "refuse"},
            "geometry": {"anchors": "anchors.csv", "outline": "outline.csv", "tag_height_m": 1.0},
            "epochs": {"window_s": 0.5, "aggregate": "mean", "min_readings": 1},
            "recording": [{"name": "cal", "file": "cal.csv", "role": "calibration", "window_s": 0,
                           "point_column": "point"},
                          {"name": "walk", "file": "walk.csv", "role": "track", "reference_path": "path.csv"}]}


# -- the edits ------------------------------------------------------------------------------------------------------
WORDS = ["s", "ms", "ns", "m", "mm", "dBm", "mW", "mean", "max", "sort", "refuse", "calibration", "static", "track",
         "anchors.csv", "cal.csv", "walk.csv", "outline.csv", "path.csv", "../cal.csv", "/etc/hostname", "nowhere.csv",
         "x_m", "time_s", "point", "fuzz", "Fuzz Set", "a" * 300, "", " ", "cal\n", "tag", "0", "True", "-inf"]
SCALARS = st.one_of(st.sampled_from(WORDS), st.text(max_size=8),
                    st.integers(min_value=-2**70, max_value=2**70), st.sampled_from([0, 1, -1, 2, 2**63 - 1]),
                    st.floats(allow_nan=True, allow_infinity=True),
                    st.sampled_from([0.0, 0.5, -1.0, 1e6, -1000.0, 1e300, -1e300, 1e-300, -150.0, 20.0]),
                    st.booleans())
VALUES = st.recursive(SCALARS, lambda inner: st.lists(inner, max_size=3)
                      | st.dictionaries(st.sampled_from(["a", "m", "time", "x"]), inner, max_size=2), max_leaves=4)
KEYS = [("name",), ("title",), ("license",), ("license_file",), ("attribution",), ("changes",), ("colour",),
        ("units",), ("units", "time"), ("units", "length"), ("units", "rssi"),
        ("readings",), ("readings", "valid_range_dbm"), ("readings", "invalid_values_dbm"),
        ("readings", "backward_time"), ("geometry",), ("geometry", "anchors"), ("geometry", "outline"),
        ("geometry", "tag_height_m"), ("epochs",), ("epochs", "window_s"), ("epochs", "aggregate"),
        ("epochs", "min_readings"), ("recording",)] + [
    ("recording", i, key) for i in (0, 1) for key in ("name", "file", "role", "point_column", "reference_path",
                                                       "window_s", "colour")]
EDITS = st.lists(st.tuples(st.sampled_from(KEYS), st.one_of(VALUES, st.just(KeyError))), max_size=4)
FILE_EDITS = st.lists(st.tuples(st.sampled_from(sorted(FILES)),
                                st.sampled_from(["delete", "garble", "non-utf8", "nul", "random", "link-out",
                                                 "empty", "directory"]),
                                st.integers(0, 10**6), st.binary(min_size=1, max_size=6)), max_size=3)


def edit(raw: dict, path: tuple, value) -> None:
    """Set ``raw[path] = value`` (``KeyError``: delete it), creating nothing: a path through a value that is not a
    table (an earlier edit) is left alone."""
    node = raw
    for step in path[:-1]:
        if isinstance(node, dict) and isinstance(step, str) and isinstance(node.get(step), (dict, list)):
            node = node[step]
        elif isinstance(node, list) and isinstance(step, int) and step < len(node) and isinstance(node[step], dict):
            node = node[step]
        else:
            return
    if not isinstance(node, dict):
        return
    if value is KeyError:
        node.pop(path[-1], None)
    else:
        node[path[-1]] = value


CELLS = st.one_of(st.sampled_from(["", "NaN", "NA", "N/A", "nan", "inf", "-inf", "True", "false", "1e300", "-1e300",
                                   "0", "-50", "-50.5", " -60", "+5", "1e11", "1_0", "0x10", "é", '"-70"',
                                   '"a,b"', '"x""y"', "tag", "A", "B", " A", "P1"]),
                  st.integers(-200, 50).map(str), st.floats(-1e4, 1e4, allow_nan=False).map(repr))


@st.composite
def csv_texts(draw, header: list[str], ids=("A", "B", "C", "D")):
    """A CSV: ``header`` (sometimes edited), then rows of random cells (sometimes too few or too many), with
    blank lines, CR or CRLF line ends and a byte-order mark now and then."""
    names = list(header)
    if draw(st.integers(0, 9)) == 0:
        names = draw(st.permutations(names))[: draw(st.integers(1, len(names)))]
    if draw(st.integers(0, 14)) == 0:
        names = names + [names[0]]                                 # a duplicated column
    rows = []
    for t in range(draw(st.integers(0, 8))):
        n = len(names) + draw(st.sampled_from([0, 0, 0, 0, 0, 0, -1, 1]))
        cells = [draw(CELLS) for _ in range(max(n, 0))]
        if draw(st.integers(0, 3)) and len(cells) >= 4 and names[:4] == header[:4]:   # a plausible reading
            cells[:4] = [str(t * 0.5), "tag", draw(st.sampled_from(ids)), str(draw(st.integers(-110, -20)))]
            if len(cells) >= 6 and draw(st.booleans()):            # a true position, or none
                cells[4:6] = draw(st.sampled_from([["", ""], ["1.5", "2"], ["0", "-3e2"]]))
        rows.append(",".join(cells))
        if draw(st.integers(0, 12)) == 0:
            rows.append("")
    end = draw(st.sampled_from(["\n", "\n", "\n", "\r\n", "\r"]))
    text = end.join([",".join(names)] + rows) + end
    data = text.encode()
    if draw(st.integers(0, 9)) == 0:
        data = b"\xef\xbb\xbf" + data
    if draw(st.integers(0, 14)) == 0:
        at = draw(st.integers(0, len(data)))
        data = data[:at] + draw(st.sampled_from([b"\xff", b"\x00", b'"', b"\xe9"])) + data[at:]
    return data


READINGS_HEADER = ["time_s", "transmitter", "receiver", "rssi_dbm", "x_m", "y_m", "point"]


def apply_file_edit(root: Path, outside: Path, name: str, kind: str, where: int, junk: bytes, text: bytes | None):
    path = root / name
    data = path.read_bytes() if path.is_file() and not path.is_symlink() else FILES[name].encode()
    if path.is_symlink() or path.is_file():
        path.unlink()
    elif path.is_dir():
        shutil.rmtree(path)
    at = where % (len(data) + 1)
    if kind == "delete":
        return
    if kind == "link-out":
        path.symlink_to(outside)
    elif kind == "directory":
        path.mkdir()
    else:
        new = {"garble": data[:at] + junk + data[at:], "non-utf8": data[:at] + b"\xfc" + data[at:],
               "nul": data[:at] + b"\x00" + data[at:], "random": text or b"", "empty": b""}[kind]
        path.write_bytes(new)


def assert_one_line(exc: BaseException, secret: str = "") -> str:
    message = str(exc)
    assert message, f"{type(exc).__name__} without a message"
    assert "\n" not in message and "\r" not in message, f"a message over several lines: {message!r}"
    assert len(message) <= MAX_MESSAGE_CHARS, f"a message of {len(message)} characters: {message[:300]!r}..."
    assert not secret or secret not in message, f"the message echoes a file outside the folder: {message!r}"
    return message


def refusal_or(fn, *args, secret: str = "", **kwargs):
    """``fn(...)``, or None if it raised the project's one-line error; any other exception fails the test."""
    try:
        with np.errstate(all="ignore"), warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return fn(*args, **kwargs)
    except lb.LocbookError as exc:
        event(f"{fn.__name__} refused: {re.sub(r'/[^ ]*', '<path>', str(exc))[:50]}")
        assert_one_line(exc, secret)
        return None


def assert_physical(ds) -> None:
    """What a loaded data set may hold (module docstring)."""
    anchors = ds.anchors_m
    assert np.isfinite(anchors).all() and (np.abs(anchors) < MAX_COORDINATE_M).all()
    assert np.isfinite(ds.outline_m).all() and ds.outline_m.shape[1] == 2 and len(ds.outline_m) >= 3
    assert math.isfinite(ds.tag_height_m)
    for name, rec in ds.recordings.items():
        r = rec.readings
        rss = r["rssi_dbm"].to_numpy(float)
        assert not np.isinf(rss).any()
        heard = rss[np.isfinite(rss)]
        assert ((heard >= -300) & (heard <= 100)).all()
        assert np.isfinite(r["time_s"].to_numpy(float)).all()
        ep = ds.epochs(name)
        xy_known = np.isfinite(ep.position_m[:, :2])
        assert (xy_known[:, 0] == xy_known[:, 1]).all(), f"{name}: half a true position"
        assert np.isfinite(ep.position_m[xy_known[:, 0]]).all(), f"{name}: a true position without a finite height"
        assert not np.isinf(ep.rss_dbm).any()
        if rec.role == "calibration":
            assert xy_known.any(), f"{name}: a calibration recording without truth loaded"


# -- the properties ------------------------------------------------------------------------------------------------
@pytest.fixture
def scratch():
    base = Path(tempfile.mkdtemp(prefix="fuzz-manifest-"))
    yield base
    shutil.rmtree(base, ignore_errors=True)


def test_the_unedited_data_set_loads(scratch):
    root = scratch / "set"
    root.mkdir()
    for name, text in FILES.items():
        (root / name).write_text(text)
    (root / "dataset.toml").write_text(toml_document(manifest()))
    assert tomllib.loads(toml_document(manifest())) == manifest()
    assert_physical(load_dataset(root))


@FUZZ
@given(edits=EDITS, file_edits=FILE_EDITS, text=csv_texts(READINGS_HEADER),
       manifest_junk=st.sampled_from(["none"] * 10 + ["non-utf8", "cut"]))
def test_a_fuzzed_data_set_loads_physically_or_is_refused_in_one_line(scratch, edits, file_edits, text, manifest_junk):
    root = Path(tempfile.mkdtemp(dir=scratch))
    outside = scratch / "environ"
    secret = "SECRET_TOKEN=hunter2"
    outside.write_text(f"{secret}\0HOME=/root\0" * 50)
    for name, content in FILES.items():
        (root / name).write_text(content)
    raw = manifest()
    for path, value in edits:
        edit(raw, path, value)
    document = toml_document(raw).encode()
    if manifest_junk == "non-utf8":
        document = document.replace(b"fuzzed", b"fuzz\xe9d")
    elif manifest_junk == "cut":
        document = document[: len(document) // 2]
    (root / "dataset.toml").write_bytes(document)
    for name, kind, where, junk in file_edits:
        apply_file_edit(root, outside, name, kind, where, junk, text)
    event(f"edits {len(edits)}, file edits {len(file_edits)}")
    ds = refusal_or(load_dataset, root, secret=secret)
    if ds is not None:
        event("loaded")
        assert_physical(ds)
    shutil.rmtree(root)


def _exact(path):
    table, lines = csvfile.read_text_table(path, measured.READING_COLUMNS, "readings")
    return validate_readings(table, source=f"readings file {path}", lines=lines)


@FUZZ
@given(text=csv_texts(READINGS_HEADER))
def test_a_random_readings_file_loads_or_is_refused_and_both_readers_agree(scratch, text):
    path = Path(tempfile.mkdtemp(dir=scratch)) / "r.csv"
    path.write_bytes(text)
    out = refusal_or(read_readings, path)
    exact = refusal_or(_exact, path)
    assert (out is None) == (exact is None), "one reader refused the file, the other took it"
    if out is None:
        with pytest.MonkeyPatch.context() as mp:         # refused as a large file too, in one line
            mp.setattr(csvfile, "MAX_EXACT_READ_BYTES", 0)
            mp.setattr(fast_reader, "_LOCATE_CHUNK_ROWS", 2)
            assert refusal_or(read_readings, path) is None
        return
    event("loaded")
    assert np.isfinite(out["time_s"].to_numpy(float)).all()
    rss = out["rssi_dbm"].to_numpy(float)
    assert not np.isinf(rss).any()
    low, high = RSSI_RANGE_DBM
    assert ((rss[np.isfinite(rss)] >= low) & (rss[np.isfinite(rss)] <= high)).all()
    assert (np.isnan(out["x_m"].to_numpy(float)) == np.isnan(out["y_m"].to_numpy(float))).all()
    assert_same_table(out, exact)
    # as a "large" file (over the exact reader's limit): the same table from the fast reader, or a one-line refusal
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(csvfile, "MAX_EXACT_READ_BYTES", 0)
        mp.setattr(fast_reader, "_LOCATE_CHUNK_ROWS", 2)
        large = refusal_or(read_readings, path)
    if large is not None:
        event("loaded as a large file")
        assert_same_table(large, exact)


def assert_same_table(out, exact):
    assert list(out.columns) == list(exact.columns)
    for column in out.columns:
        a, b = out[column].astype(object).to_numpy(), exact[column].astype(object).to_numpy()
        assert [str(v).strip() for v in a] == [str(v).strip() for v in b], column


COORDINATES = st.one_of(st.floats(-1e3, 1e3, allow_nan=False).map(repr),
                        st.sampled_from(["0", "6", "2.5", "-3", "9999999", "1e-300", "", "nan", "inf", "x", '"1.5"']))


@st.composite
def anchors_texts(draw):
    """An anchors CSV: distinct ids mostly, random coordinates, and now and then one far beyond any site."""
    n = draw(st.integers(0, 5))
    ids = draw(st.sampled_from([["A", "B", "C", "D", "E"], ["A", "B", "A", "C", "D"], ["A", "", "B", "C", "D"]]))
    rows = [[ids[k]] + [draw(COORDINATES) for _ in range(draw(st.sampled_from([3, 3, 3, 3, 2, 4])))]
            for k in range(n)]
    far = draw(st.sampled_from([None, "1e300", "-1e300", "1e7", "1.7e308", "-9999999.9"]))
    if far and rows:
        row = rows[draw(st.integers(0, n - 1))]
        row[draw(st.integers(1, len(row) - 1))] = far
    return ("\n".join(["id,x,y,z"] + [",".join(r) for r in rows]) + "\n").encode()


@FUZZ
@given(text=anchors_texts())
def test_a_random_anchors_file_loads_finite_or_is_refused(scratch, text):
    path = Path(tempfile.mkdtemp(dir=scratch)) / "anchors.csv"
    path.write_bytes(text)
    out = refusal_or(read_anchors, path)
    if out is not None:
        event("loaded")
        xyz = out[["x", "y", "z"]].to_numpy(float)
        assert np.isfinite(xyz).all() and (np.abs(xyz) < MAX_COORDINATE_M).all()
        assert out["id"].is_unique


@FUZZ
@given(invalid=st.one_of(st.none(), VALUES, st.lists(SCALARS, max_size=3)),
       valid=st.one_of(st.none(), VALUES, st.lists(SCALARS, min_size=2, max_size=2)))
def test_readings_options_of_any_type_are_taken_or_refused_by_name(invalid, valid):
    import pandas as pd
    table = pd.DataFrame({"time_s": [0.0, 1.0], "transmitter": ["t", "t"], "receiver": ["A", "A"],
                          "rssi_dbm": [-50.0, 0.0]})
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            out = validate_readings(table, source="t", invalid_values_dbm=invalid, valid_range_dbm=valid)
    except lb.DataFormatError as exc:                   # a reading outside the range declared: the file's fault
        assert_one_line(exc)
        assert "rssi_dbm" in str(exc)
        return
    except lb.ParameterError as exc:
        message = assert_one_line(exc)
        assert "invalid_values_dbm" in message or "valid_range_dbm" in message, message
        return
    event("taken")

    def real(v):
        return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
    # taken: numbers (not text, not bools) and a finite range of two of them
    assert invalid is None or real(invalid) or (isinstance(invalid, list) and all(real(v) for v in invalid)), invalid
    assert valid is None or (isinstance(valid, list) and len(valid) == 2 and all(real(v) for v in valid)), valid
    rss = out["rssi_dbm"].to_numpy(float)
    assert not np.isinf(rss).any()


@FUZZ
@given(base=st.sampled_from(["cal", "walk"]), time_scale=st.sampled_from([1.0, 1e-7, 1e9, 1e-300, 3.3]),
       window=st.sampled_from([None, 0, 0.5, 1.0, 0.25, 2.0, 1e-6, 1e300, 5e-324, 1e-300, -1.0, float("nan"), True,
                               "1", float("inf")]),
       aggregate=st.sampled_from(["mean", "median", "max", "mean", "sum", None, ["mean"]]),
       min_readings=st.sampled_from([1, 2, 3, 1, 0, 2**70, 1.0, True, "1"]),
       group_by=st.sampled_from([(), ("point",), "point", ("x_m",), ("nope",)]))
def test_epochs_of_any_rule_are_finite_or_refused(base, time_scale, window, aggregate, min_readings, group_by):
    import pandas as pd
    text = pd.read_csv(__import__("io").StringIO(CAL if base == "cal" else TRACK), dtype=str, keep_default_na=False)
    text["time_s"] = [repr(float(t) * time_scale) for t in text["time_s"]]
    table = refusal_or(validate_readings, text, source="t")
    if table is None:
        return
    anchors = sorted(set(table["receiver"]))
    ep = refusal_or(lb.epochs, table, anchors, window_s=window, aggregate=aggregate, min_readings=min_readings,
                    group_by=group_by)
    if ep is None:
        return
    event("epochs")
    assert 1 <= len(ep) <= len(table) and np.isfinite(ep.time_s).all() and not np.isinf(ep.rss_dbm).any()
    assert (ep.n_readings >= 0).all() and ep.rss_dbm.shape == (len(ep), len(anchors))
    known = np.isfinite(ep.position_m[:, :2])
    assert (known[:, 0] == known[:, 1]).all()
