"""Property-based fuzzing of the declarations a user writes: studies (``[[study]]`` TOML) and reading brackets
(readings CSV files) (the house style of tests/static/test_static_fuzz.py).

Inputs: study tables with every key of the schema, each given a value of a plausible or a wrong type (numbers,
NaN, +-inf, 10^9 and 2^70 sizes, strings, booleans, arrays, tables, empty ones), unknown keys and samplers, grids,
paired lists and drawn ranges of any length; the same declarations as bytes damaged at random (a byte flipped to
0xff, cut short, a NUL or a non-UTF-8 byte inserted, a line doubled); readings files with every column given a
plausible or a garbled cell (TOML and non-TOML values, quotes, commas, NUL, huge fields, ranges inside out), and
damaged bytes. The rule every call must keep:

- it loads, and then the expansion is consistent: a study's tasks number exactly :func:`study_size` (experiments x
  the product of the block sizes x replicates, computed from the declaration) and have distinct folder keys, the
  swept values of each task are the declared ones; a bracket's points have distinct keys, the first is the
  default point and every other changes at least one parameter; or
- it is refused with the project's error: a :class:`~locbook.suite.spec.SuiteError` or
  :class:`~locbook.reproduce.interpretations.InterpretationsError` of ONE line that starts with the file's path (for a
  bracket's values, that names the interpretation); never a raw exception from tomllib, csv, pydantic or numpy
  (UnicodeDecodeError, ``_csv.Error``, ValidationError, TypeError, KeyError, MemoryError ...).

Example counts are bounded (``max_examples``) so that the module runs in well under a minute.
"""
import itertools
import math

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from builders import toml_key
from builders import toml_value as toml
from locbook.reproduce.interpretations import INTERPRETATION_COLUMNS, InterpretationsError, load_interpretation_file
from locbook.suite import SuiteError, load_suite
from locbook.suite import study as study_module
from locbook.suite.bracket import bracket_points, experiment_interpretations, find_experiment
from locbook.suite.study import expand_study, load_studies
from toy_suite import _notebook, experiment_toml, suite_toml

pytestmark = pytest.mark.fuzz

FUZZ = settings(max_examples=300, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much,
                                       HealthCheck.function_scoped_fixture])

#: the toy notebook's parameters (their types are what the declarations are checked against)
PARAMS = ('seed: int = 1  # seed\na: float = 1.0  # slope input\nb: float = 0.0  # offset\n'
          'tag: str = "x"  # a label\nn: int = 3  # a count\nweights: list[float] = [1.0]  # a list\n')
SUITE = "\n" + suite_toml(
    experiment_toml("george-fuzz", "fuzz.ipynb", title="fuzz", section="Table 9",
                    rules={"a": {"ge": 0, "le": 5}, "n": {"ge": 1, "le": 10}}, quick={"seed": 3}),
    experiment_toml("george-other", "fuzz.ipynb", title="other", section="Table 9"))


@pytest.fixture(scope="module")
def repo(tmp_path_factory):
    root = tmp_path_factory.mktemp("fuzz-declarations")
    (root / "notebooks").mkdir()
    _notebook(root / "notebooks" / "fuzz.ipynb", PARAMS, body="x = 1\n")
    (root / "notebooks" / "experiments.toml").write_text(SUITE)
    return root


@pytest.fixture(scope="module")
def suite(repo):
    return load_suite(repo / "notebooks" / "experiments.toml")


NUMBERS = st.one_of(st.integers(-3, 12), st.sampled_from([0.5, 1.5, 2.5, 4.9, 5.0, 6.0, -1.0, 1e-3, 1e300,
                                                          float("nan"), float("inf"), float("-inf"),
                                                          10 ** 9, 2 ** 70]))
SCALARS = st.one_of(NUMBERS, st.booleans(), st.sampled_from(["", "x", "p", "george-fuzz", "a", "seed", "<b>"]))
VALUES = st.recursive(SCALARS, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                       st.dictionaries(st.sampled_from(["low", "high", "log", "q"]),
                                                                       inner, max_size=3)), max_leaves=6)
PARAMETER_NAMES = st.sampled_from(["a", "b", "tag", "n", "seed", "weights", "nope"])


@st.composite
def samplers(draw):
    """One parameter's sampler table: mostly well formed, sometimes not."""
    kind = draw(st.sampled_from(["grid", "list", "random", "lhs", "other", "two", "value"]))
    if kind in ("grid", "list"):
        return {kind: draw(st.one_of(st.lists(SCALARS, max_size=4), st.lists(st.lists(NUMBERS, max_size=2),
                                                                             max_size=2), VALUES))}
    if kind in ("random", "lhs"):
        table = {"low": draw(NUMBERS), "high": draw(NUMBERS)}
        if draw(st.booleans()):
            table["log"] = draw(st.one_of(st.booleans(), SCALARS))
        return {kind: draw(st.one_of(st.just(table), VALUES))}
    if kind == "other":
        return {"sweep": draw(VALUES)}
    if kind == "two":
        return {"grid": [1.0], "list": [1.0]}
    return draw(VALUES)


@st.composite
def studies(draw):
    """A ``[[study]]`` table: well formed in every key, then (mostly) one key given a value of any type, dropped, or
    a stray key added."""
    parameters = draw(st.dictionaries(PARAMETER_NAMES, samplers(), max_size=3))
    table = {"name": draw(st.sampled_from(["s", "fuzz-study", "s2"])),
             "experiments": draw(st.lists(st.sampled_from(["george-fuzz", "george-other"]), min_size=1, max_size=2,
                                          unique=True)),
             "profile": draw(st.sampled_from(["quick", "full"])), "replicates": draw(st.integers(1, 3)),
             "seed_parameter": draw(st.sampled_from(["seed", "n"])), "sample_seed": draw(st.integers(0, 3)),
             "collect": draw(st.lists(st.sampled_from(["value", "x"]), max_size=2)), "parameters": parameters}
    if any(isinstance(v, dict) and set(v) & {"random", "lhs"} for v in parameters.values()):
        table["samples"] = draw(st.integers(1, 4))
    keys = sorted(table) + ["samples", "stray"]
    for _ in range(draw(st.sampled_from([0, 1, 1, 1, 2]))):
        key, how = draw(st.sampled_from(keys)), draw(st.sampled_from(["value", "value", "drop"]))
        if how == "drop":
            table.pop(key, None)
        else:
            table[key] = draw(st.one_of(NUMBERS, SCALARS, VALUES))
    return table


def study_text(table: dict) -> str:
    lines = ["[[study]]"]
    for key, value in table.items():
        if key != "parameters" or not isinstance(value, dict):
            lines.append(f"{toml_key(key)} = {toml(value)}")
    if isinstance(table.get("parameters"), dict):
        lines.append("[study.parameters]")
        lines += [f"{toml_key(k)} = {toml(v)}" for k, v in table["parameters"].items()]
    return "\n".join(lines) + "\n"


@st.composite
def damaged(draw, text: str) -> bytes:
    """``text`` as bytes, damaged in one of a few ways (or not at all)."""
    data = text.encode()
    how = draw(st.sampled_from(["none"] * 5 + ["flip", "cut", "insert", "double"]))
    if not data or how == "none":
        return data
    i = draw(st.integers(0, len(data) - 1))
    if how == "flip":
        return data[:i] + bytes([draw(st.sampled_from([0xff, 0xe9, 0x00, 0x22, 0x5b, 0x2c, 0x0a]))]) + data[i + 1:]
    if how == "cut":
        return data[:i]
    if how == "insert":
        return data[:i] + draw(st.sampled_from([b"\xc3", b"\x00", b'"', b"\n[", b"\r", b"\xef\xbb\xbf"])) + data[i:]
    lines = data.splitlines(keepends=True)
    j = draw(st.integers(0, len(lines) - 1))
    return b"".join(lines[:j + 1] + lines[j:])


def refused(exc: Exception, path) -> str:
    """The project's one-line error naming ``path``; anything else fails the test."""
    message = str(exc)
    assert isinstance(exc, (SuiteError, InterpretationsError)), f"a raw {type(exc).__name__} escaped: {exc!r}"
    assert "\n" not in message and message.startswith(str(path)), f"not one line naming the file: {message!r}"
    return message


def _grid_values(study):
    return {p: v for p, (s, v) in study.parameters.items() if s == "grid"}


def runs(study) -> int:
    """The number of tasks a study declares, from its declaration (the module docstring of locbook.suite.study):
    experiments x each grid's length x the paired lists' length x samples (if any parameter is drawn) x
    replicates."""
    samplers = [s for s, _v in study.parameters.values()]
    lists = [len(v) for s, v in study.parameters.values() if s == "list"]
    return (len(study.experiments) * math.prod(len(v) for v in _grid_values(study).values())
            * (lists[0] if lists else 1) * (study.samples if {"random",
                                                              "lhs"} & set(samplers) else 1) * study.replicates)


# -- studies ---------------------------------------------------------------------------------------------------

@given(table=studies(), data=st.data())
@FUZZ
def test_a_study_declaration_loads_or_is_one_line_and_expands_consistently(suite, tmp_path_factory, table, data):
    path = tmp_path_factory.mktemp("study") / "study.toml"
    path.write_bytes(data.draw(damaged(study_text(table)), label="bytes"))
    try:
        found = load_studies(suite, path)
    except Exception as exc:   # noqa: BLE001  (the rule says which exceptions are allowed)
        event(f"refused: {refused(exc, path)[len(str(path)):][:40]}")
        return
    for study in found.values():
        n = runs(study)
        assert n == study_module.study_size(study) and n <= study_module.MAX_STUDY_RUNS
        try:
            tasks = expand_study(study)
        except Exception as exc:   # noqa: BLE001
            event("a point refused")
            refused(exc, path)
            continue
        event("expanded")
        assert len(tasks) == n
        assert len({t.key for t in tasks}) == len(tasks)
        assert all(t.key.startswith(t.experiment.id + "-") for t in tasks)
        assert all(set(t.values) == set(study.parameters) for t in tasks)      # the swept ones, each point
        assert {t.replicate for t in tasks} == set(range(study.replicates))
        for pname, values in _grid_values(study).items():      # a grid axis: each of its values as often
            counts = {}
            for t in tasks:
                counts[repr(t.values[pname])] = counts.get(repr(t.values[pname]), 0) + 1
            assert len(counts) == len(values) and len(set(counts.values())) == 1


@given(grids=st.lists(st.integers(1, 4), min_size=0, max_size=3), lists=st.integers(0, 3),
       samples=st.integers(0, 3), replicates=st.integers(1, 3), two=st.booleans())
@FUZZ
def test_the_number_of_points_is_the_product_of_the_blocks(suite, tmp_path_factory, grids, lists, samples,
                                                           replicates, two):
    """Well-formed studies: the tasks are the Cartesian product of the blocks times replicates and experiments."""
    names = iter(["a", "b", "n"])
    parameters = {next(names): {"grid": [0.5 * i for i in range(k)]} for k in grids}
    if "n" in parameters:
        parameters["n"] = {"grid": list(range(1, grids[2] + 1))}
    if lists:
        parameters["tag"] = {"list": [f"t{i}" for i in range(lists)]}
    if samples and "b" not in parameters:
        parameters["b"] = {"lhs": {"low": 0.0, "high": 1.0}}
    else:
        samples = 0
    table = {"name": "s", "experiments": ["george-fuzz", "george-other"] if two else ["george-fuzz"],
             "replicates": replicates, "parameters": parameters, **({"samples": samples} if samples else {})}
    path = tmp_path_factory.mktemp("study") / "study.toml"
    path.write_text(study_text(table))
    (study,) = load_studies(suite, path).values()
    tasks = expand_study(study)
    expected = (2 if two else 1) * math.prod(grids) * (lists or 1) * (samples or 1) * replicates
    assert len(tasks) == runs(study) == study_module.study_size(study) == expected
    assert len({t.key for t in tasks}) == expected
    # the product itself: every combination of the grid values, once per experiment and replicate
    combos = {(t.experiment.id, t.replicate, *(t.values[p] for p in parameters if "grid" in parameters[p]))
              for t in tasks}
    assert len(combos) == (2 if two else 1) * replicates * math.prod(grids)
    assert combos == {(e, r, *c) for e in (["george-fuzz", "george-other"] if two else ["george-fuzz"])
                      for r in range(replicates)
                      for c in itertools.product(*(parameters[p]["grid"] for p in parameters
                                                   if "grid" in parameters[p]))}


# -- readings (brackets) -------------------------------------------------------------------------------------------

CELLS = {
    "name": st.sampled_from(["slope", "offset", "slope", "x_1", "slope", "offset", "Bad Name", ""]),
    "experiments": st.sampled_from(["george-fuzz", "george-fuzz george-other", "", "george-fuzz george-fuzz",
                                    "george-nope"]),
    "parameter": st.sampled_from(["a", "b", "n", "tag", "seed", "weights", "", "nope", "1x"]),
    "where": st.sampled_from(["", "locbook.toy.HIDDEN", "not a path"]),
    "default": st.sampled_from(["", "1.0", "0.0", "3", "'x'", "[1.0]", "nan", "inf", "true", "bare word", "1e400",
                                "'<script>'"]),
    "alternatives": st.sampled_from(["", "[]", "[1.3]", "[2, 3]", "['p', 'q']", "[1.0]", "1.3", "[nan]", "[[1.0]]",
                                     "[{ q = 1 }]", "[true]", "[6.0]", "['<b>']"]),
    "fitted": st.sampled_from(["", "[]", "[1.3]", "[2]", "[9.9]", "x"]),
    "low": st.sampled_from(["", "0.0", "1", "-1e300", "nan", "'x'", "5.5"]),
    "high": st.sampled_from(["", "2.0", "4", "1e300", "inf", "0.5"]),
    "basis": st.sampled_from(["printed", "assumed", "fitted", "assumed", "printed", "guessed"]),
    "source": st.sampled_from(["Table 9", "Table 9", "", "a, b", '"quoted, comma"', "T\u00e4ble"]),
    "quotes": st.sampled_from(["", "Sec. 1 (line 3): 'the words of the text'", '"quoted, comma"', "<b>x</b>"]),
    "reason": st.sampled_from(["why", "why", "", "x" * 50]),
    "requires": st.sampled_from(["", "{ b = 0.5 }", "{ a = 1.0 }", "{ tag = 'p' }", "{ nope = 1 }", "x", "[1]"]),
}


def csv_cell(text: str) -> str:
    return f'"{text.replace(chr(34), chr(34) * 2)}"' if any(c in text for c in ',"\n') else text


@st.composite
def readings_files(draw) -> str:
    optional = draw(st.booleans())
    columns = list(INTERPRETATION_COLUMNS) + (["requires"] if optional else [])
    if draw(st.integers(0, 4)) == 0:
        columns.remove("quotes")            # a file of one's own written before the quotes column
    if draw(st.integers(0, 9)) == 0:
        columns = draw(st.permutations(columns))
    lines = [",".join(columns)]
    for _ in range(draw(st.integers(0, 3))):
        row = [draw(CELLS[c]) for c in columns]
        if draw(st.integers(0, 9)) == 0:
            row = row[:-1]                  # a short row
        lines.append(",".join(csv_cell(c) for c in row))
    if draw(st.integers(0, 9)) == 0:
        lines.insert(draw(st.integers(0, len(lines))), "# a comment")
    return "\n".join(lines) + "\n"


@given(text=readings_files(), data=st.data())
@FUZZ
def test_a_readings_file_loads_or_is_one_line_and_its_points_are_consistent(suite, tmp_path_factory, text, data):
    path = tmp_path_factory.mktemp("readings") / "george.csv"
    path.write_bytes(data.draw(damaged(text), label="bytes"))
    try:
        readings = load_interpretation_file(path)
    except Exception as exc:   # noqa: BLE001
        event(f"refused: {refused(exc, path)[len(str(path)):][:40]}")
        return
    exp = find_experiment(suite, "george-fuzz")
    try:
        points = bracket_points(exp, "quick", experiment_interpretations(exp, readings))
    except Exception as exc:   # noqa: BLE001
        assert isinstance(exc, SuiteError), f"a raw {type(exc).__name__} escaped: {exc!r}"
        assert "\n" not in str(exc)
        event("bracket refused")
        return
    event(f"{len(points)} points")
    assert points[0].label == "default" and points[0].parameters["seed"] == 3
    assert len({p.key for p in points}) == len(points)
    assert all(p.parameters != points[0].parameters for p in points[1:])
    assert len({tuple(sorted((k, repr(v)) for k, v in p.parameters.items())) for p in points}) == len(points)
