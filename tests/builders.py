"""What several test modules build: TOML text from Python values (tomllib only reads) and the tiny measured data set
(four anchors on a 6 m square, a calibration walk, a track), and where the repository lies. Imported by name
(``from builders import ...``): pyproject's ``pythonpath`` puts this folder on ``sys.path`` for every test module,
whichever subfolder it lives in."""
import math
import re
from pathlib import Path

import numpy as np

#: the repository's root (the clone), whatever folder pytest runs from and however deep a test module lives
REPO_ROOT = Path(__file__).resolve().parents[1]
#: this folder: the test modules' helper files (user_method_examples.py) live here
TESTS_DIR = Path(__file__).resolve().parent

# -- TOML text ------------------------------------------------------------------------------------------------------


def toml_string(text: str) -> str:
    """A basic TOML string: quotes, backslashes and control characters escaped."""
    return '"' + "".join(c if c not in '"\\' and ord(c) >= 0x20 and ord(c) != 0x7f else
                         ("\\" + c if c in '"\\' else f"\\u{ord(c):04x}") for c in text) + '"'


def toml_key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else toml_string(key)


def toml_value(value) -> str:
    """A TOML value: booleans, integers, floats (nan, inf), strings, arrays and inline tables."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return "nan" if math.isnan(value) else ("inf" if value > 0 else "-inf") if math.isinf(value) else repr(value)
    if isinstance(value, str):
        return toml_string(value)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{toml_key(k)} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"no TOML value for {type(value).__name__}")


def toml_document(raw: dict) -> str:
    """A TOML document: top-level values, then tables, then arrays of tables."""
    tables = {k: v for k, v in raw.items() if isinstance(v, dict)}
    arrays = {k: v for k, v in raw.items() if isinstance(v, list) and v and all(isinstance(e, dict) for e in v)}
    lines = [f"{toml_key(k)} = {toml_value(v)}" for k, v in raw.items() if k not in tables and k not in arrays]
    for k, table in tables.items():
        lines += [f"[{toml_key(k)}]"] + [f"{toml_key(a)} = {toml_value(b)}" for a, b in table.items()]
    for k, array in arrays.items():
        for table in array:
            lines += [f"[[{toml_key(k)}]]"] + [f"{toml_key(a)} = {toml_value(b)}" for a, b in table.items()]
    return "\n".join(lines) + "\n"


# -- the tiny measured data set -------------------------------------------------------------------------------------
ANCHORS = "id,x,y,z\nA,0,0,2.5\nB,6,0,2.5\nC,0,6,2.5\nD,6,6,2.5\n"
ANCHOR_XYZ_M = {"A": (0, 0, 2.5), "B": (6, 0, 2.5), "C": (0, 6, 2.5), "D": (6, 6, 2.5)}


def calibration_csv(points: bool = False) -> str:
    """A calibration walk at (1 + t, 2), t = 0..3, the tag 1 m high: readings of -40 - 20 log10 d in whole dBm
    (d the 3-D distance to each anchor); with ``points`` a ``point`` column P0..P3."""
    head = "time_s,transmitter,receiver,rssi_dbm,x_m,y_m" + (",point" if points else "") + "\n"
    return head + "".join(
        f"{t},tag,{a},"
        f"{round(-40 - 20 * np.log10(np.hypot(np.hypot(1 + t - ANCHOR_XYZ_M[a][0], 2 - ANCHOR_XYZ_M[a][1]), 1.5)))},"
        f"{1 + t},2" + (f",P{t}" if points else "") + "\n" for t in range(4) for a in "ABCD")


#: a track along y = 3, one epoch every 0.5 s, made-up powers -55 .. -58 dBm
TRACK = ("time_s,transmitter,receiver,rssi_dbm,x_m,y_m\n"
         + "".join(f"{0.5 * t},tag,{a},-{55 + j},{t},3\n" for t in range(6) for j, a in enumerate("ABCD")))
MANIFEST = """name = "tiny"
title = "tiny test set"
license = "CC0 1.0"
attribution = "test"
[geometry]
anchors = "anchors.csv"
tag_height_m = 1.0
[epochs]
window_s = 0.5
[[recording]]
name = "cal"
file = "cal.csv"
role = "calibration"
window_s = 0
[[recording]]
name = "walk"
file = "walk.csv"
role = "track"
"""


# -- masked readings ------------------------------------------------------------------------------------------------

#: five anchors around a 20 m square: the masked-reading tests' layout (any four heard ones fix a position exactly)
MASKED_ANCHORS = np.array([[0.0, 0.0], [20.0, 0.0], [0.0, 20.0], [20.0, 20.0], [10.0, -5.0]])


def exact_distances(seed=3, problems=6):
    """Random true positions inside the square and their exact distances to :data:`MASKED_ANCHORS`."""
    truth = np.random.default_rng(seed).uniform(2, 18, (problems, 2))
    return truth, np.linalg.norm(truth[:, None] - MASKED_ANCHORS, axis=-1)


def masked(z, where):
    """``z`` masked at ``where``, with garbage under the mask (it must never be used)."""
    data = np.where(where, 1e3, z)
    return np.ma.array(data, mask=where)
