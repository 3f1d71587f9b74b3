"""The declared readings (locbook/data/readings/*.csv): every row loads, every notebook parameter it names
exists in each listed experiment with the declared default (so the declaration cannot drift from the notebooks), every
alternative and range end is a value that parameter accepts, every module attribute it names exists (and holds the
declared default when it is a plain value), and the loader refuses each kind of broken row naming file, line and
problem."""
import fnmatch
import importlib
import re
import tomllib

import numpy as np
import pytest

from builders import REPO_ROOT
from locbook.reproduce.interpretations import (
    BASES,
    INTERPRETATION_COLUMNS,
    INTERPRETATIONS_DIR,
    Interpretation,
    InterpretationsError,
    interpretations,
    interpretations_for,
    load_interpretation_file,
)
from locbook.suite import load_suite, read_parameters
from locbook.suite.params import check_value

DOCUMENTS = ("dogan2015", "gudipati2017", "palvai2008", "george", "ozkaya2011")
SUITE = load_suite()
EXPERIMENTS = {e.id: e for e in SUITE.experiments}
ALL = [r for d in DOCUMENTS for r in interpretations(d)]
WITH_PARAMETER = [(r, e) for r in ALL if r.parameter for e in r.experiments]
GAPS = [r for r in ALL if r.is_gap]
#: Monte-Carlo counts whose help says "not printed": they set precision, not a reading of the source.
COUNTS = {("george-rssi-vs-distance", "packets_per_point"), ("palvai2008-particle-filter", "n_runs")}


def _id(item):
    r, e = item if isinstance(item, tuple) else (item, "")
    return f"{r.document}:{r.name}" + (f"@{e}" if e else "")


def _plain(value):
    """A module value as TOML would hold it (tuples and arrays as lists, numpy scalars as Python numbers), or None
    if it is not a plain value (a function, class, dict or None)."""
    if isinstance(value, (bool, str)):
        return value
    if isinstance(value, (int, float, np.integer, np.floating)):
        return float(value) if isinstance(value, (float, np.floating)) else int(value)
    if isinstance(value, (tuple, list, np.ndarray)):
        items = [_plain(v) for v in np.asarray(value, dtype=object).tolist()] if isinstance(value, np.ndarray) \
            else [_plain(v) for v in value]
        return None if any(i is None for i in items) else items
    return None


def _resolve(where: str):
    parts = where.split(".")
    for cut in range(len(parts) - 1, 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ModuleNotFoundError:
            continue
        for attr in parts[cut:]:
            obj = getattr(obj, attr)
        return obj
    raise ModuleNotFoundError(where)


@pytest.mark.parametrize("document", DOCUMENTS)
def test_every_document_declares_readings_that_load(document):
    rows = interpretations(document)
    assert rows and all(isinstance(r, Interpretation) and r.document == document for r in rows)
    assert len({r.name for r in rows}) == len(rows)
    assert all(r.basis in BASES for r in rows)
    assert interpretations(document) is rows            # cached


def test_interpretations_ship_as_package_data():
    pyproject = tomllib.loads((REPO_ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    patterns = pyproject["tool"]["setuptools"]["package-data"]["locbook.data"]
    for path in INTERPRETATIONS_DIR.glob("*.csv"):
        assert any(fnmatch.fnmatch(f"interpretations/{path.name}", p) for p in patterns), path
    assert {p.stem for p in INTERPRETATIONS_DIR.glob("*.csv")} == set(DOCUMENTS)


@pytest.mark.parametrize("reading", ALL, ids=_id)
def test_listed_experiments_exist_and_belong_to_the_document(reading):
    for eid in reading.experiments:
        assert eid in EXPERIMENTS, f"{reading.name}: unknown experiment {eid!r}"
        assert EXPERIMENTS[eid].document.key == reading.document


@pytest.mark.parametrize("item", WITH_PARAMETER, ids=_id)
def test_parameter_and_default_match_the_notebook(item):
    reading, eid = item
    exp = EXPERIMENTS[eid]
    declared = read_parameters(exp.notebook)
    assert reading.parameter in declared, f"{eid} has no parameter {reading.parameter!r}"
    param = declared[reading.parameter]
    assert reading.default == param.default, (reading.default, param.default)
    assert type(reading.default) is type(param.default) or isinstance(param.default, float)
    rule = exp.rules.get(reading.parameter)
    for value in reading.alternatives:
        check_value(param, value, rule)
    if reading.low is not None:
        kind = int if type(param.default) is int else float
        for end in (reading.low, reading.high):
            assert kind(end) == end
            check_value(param, kind(end), rule)


@pytest.mark.parametrize("reading", GAPS, ids=_id)
def test_a_gap_names_an_attribute_that_holds_the_default(reading):
    value = _resolve(reading.where)
    plain = _plain(value)
    if plain is not None and not (isinstance(plain, str) != isinstance(reading.default, str)):
        assert plain == reading.default, (reading.where, plain, reading.default)
    else:                              # a function, class or table: the default is a label of how it behaves
        assert isinstance(reading.default, str) and reading.default


def test_every_unprinted_notebook_parameter_is_declared():
    missing = []
    for exp in SUITE.experiments:
        if exp.document.key not in DOCUMENTS:
            continue
        declared = {r.parameter for r in interpretations_for(exp.id)}
        for p in read_parameters(exp.notebook).values():
            if "not printed" in p.help.lower() and p.name not in declared and (exp.id, p.name) not in COUNTS:
                missing.append(f"{exp.id}:{p.name}")
    assert missing == []


def test_interpretations_for_collects_across_files():
    got = interpretations_for("dogan2015-pcrlb")
    assert got and all("dogan2015-pcrlb" in r.experiments for r in got)
    assert {r.name for r in got} == {r.name for r in interpretations("dogan2015") if "dogan2015-pcrlb" in r.experiments}
    assert interpretations_for("no-such-experiment") == ()


def test_the_readings_opened_as_notebook_parameters_are_declared():
    names = {d: {r.name for r in interpretations(d)} for d in DOCUMENTS}
    assert {"noise_interpretation", "start", "walking_speed", "accelerometer_role", "pcrlb_horizon",
            "pcrlb_process_noise", "pcrlb_sigma_acc_values"} <= names["dogan2015"]
    assert {"tracking_shadowing", "process_noise", "report_spacing", "anchor_layout",
            "fusion_interpretation"} <= names["gudipati2017"]
    assert {"percentile_convention", "target_sampling", "nn_weights"} <= names["ozkaya2011"]
    assert {"shadowing", "trajectory", "process_noise", "step"} <= names["george"]


def test_dogan_q_reading_offers_the_printed_constant():
    from locbook.scenarios import dogan
    noise = {r.name: r for r in interpretations("dogan2015")}["noise_interpretation"]
    # the default is the text's constant; the reading fitted to Table 3.9 is a named alternative
    assert not noise.is_calibration and noise.default == "printed" == dogan.DEFAULT_NOISE_INTERPRETATION
    assert "sigma_acc" in noise.alternatives and set(noise.values) <= set(dogan.NOISE_INTERPRETATIONS)
    # the printed reading is Eq. (3.24)'s constant: the same Q whatever sigma_ACC, the square of Sec. 4.1.2's sd
    assert dogan.filter_noise("printed", 0.005) == dogan.filter_noise("printed", 0.15)
    sd = dogan.PRINTED.get("Sec. 4.1.2 text", "process noise", "standard deviation")
    assert dogan.filter_noise("printed", None)[0] == pytest.approx(sd.value ** 2, abs=2 * sd.value * sd.rounding)
    # the fitted reading agrees with it only at Table 3.6's sigma_ACC
    assert dogan.filter_noise("sigma_acc", None)[0] == pytest.approx(dogan.Q_PER_STEP, rel=0.01)
    assert dogan.filter_noise("sigma_acc", 0.005)[0] < dogan.Q_PER_STEP / 5


def test_every_calibration_reading_can_be_swept_away_from_its_fit():
    fitted = [r for r in ALL if r.is_calibration]
    assert all(r.alternatives or r.low is not None for r in fitted)


#: a quoted passage of the source: at least three words between quotation marks ('...', "..." or curly quotes)
_QUOTED = re.compile(r"""(?:'[^']*\w+\W+\w+\W+\w+[^']*'|"[^"]*\w+\W+\w+\W+\w+[^"]*"|“[^”]*\w+\W+\w+\W+\w+[^”]*”)""")
_PLACE = re.compile(r"\b(Sec|Secs|Section|Ch|Chapter|Table|Tables|Eq|Eqs|Fig|Figs|Figure|Appendix|Abstract|Algorithm"
                    r"|line)\b")


@pytest.mark.parametrize("reading", [r for r in ALL if r.basis in ("printed", "textual")], ids=_id)
def test_a_printed_or_textual_reading_quotes_the_text_it_rests_on(reading):
    # the default is the reading the text supports best, argued from quotes (section, and line)
    assert _QUOTED.search(reading.quotes), f"{reading.document}:{reading.name}: quotes holds no quoted passage"
    assert _PLACE.search(reading.quotes), f"{reading.document}:{reading.name}: quotes names no section or table"


@pytest.mark.parametrize("reading", ALL, ids=_id)
def test_every_reading_says_where_the_text_stands_on_it(reading):
    # an assumed reading too says what the text says around the gap (section, line), so a reader can check
    assert reading.quotes.strip() and _PLACE.search(reading.quotes), f"{reading.document}:{reading.name}"


@pytest.mark.parametrize("reading", [r for r in ALL if r.basis == "fitted" or r.fitted], ids=_id)
def test_a_fitted_value_says_why_no_text_supports_it(reading):
    # `fitted` means only that nothing in the text supports it and it was chosen because it fits
    assert re.search(r"no (?:text|word|sentence|passage)|not supported by the text|the text (?:does not|never)",
                     reading.reason), (f"{reading.document}:{reading.name}: the reason does not say why no text "
                                       "supports it")


def test_the_basis_of_each_value():
    r = Interpretation("doc", "x", ("e",), "p", "", "a", ("b", "c"), None, None, "textual", "Sec. 1", "why", ("c",),
                "Sec. 1: 'the words of the text'")
    assert (r.alternative_basis("a"), r.alternative_basis("b"), r.alternative_basis("c")) == \
        ("textual", "textual", "fitted")
    silent = Interpretation("doc", "y", ("e",), "p", "", 1.0, (2.0,), 0.5, 3.0, "assumed", "Sec. 1", "why")
    assert silent.alternative_basis(2) == "assumed" and silent.alternative_basis(1.0) == "assumed"
    fit = Interpretation("doc", "z", ("e",), "p", "", 1.0, (2.0,), None, None, "fitted", "Sec. 1", "why")
    assert fit.alternative_basis(1.0) == "fitted" and fit.alternative_basis(2.0) == "textual"


# -- validation ----------------------------------------------------------------------------------------------------
GOOD = {"name": "speed", "experiments": "x-a x-b", "parameter": "speed_mps", "where": "", "default": "0.3",
        "alternatives": "[0.5]", "low": "0.2", "high": "1.5", "basis": "assumed", "source": "Sec. 1",
        "reason": "not printed"}


def _write(tmp_path, *rows, header=INTERPRETATION_COLUMNS):
    import csv
    path = tmp_path / "doc.csv"
    with open(path, "w", newline="", encoding="utf-8") as fh:
        fh.write("# a comment line\n")
        writer = csv.writer(fh, lineterminator="\n")
        writer.writerow(header)
        for row in rows:
            writer.writerow([row.get(c, "") for c in header])
    return path


def test_a_good_file_loads(tmp_path):
    (r,) = load_interpretation_file(_write(tmp_path, GOOD))
    assert (r.document, r.name, r.experiments, r.default, r.alternatives, r.low, r.high) == \
        ("doc", "speed", ("x-a", "x-b"), 0.3, (0.5,), 0.2, 1.5)
    assert r.values == (0.3, 0.5) and not r.is_gap and not r.is_calibration
    (none,) = load_interpretation_file(_write(tmp_path, {**GOOD, "default": "", "low": "", "high": ""}))
    assert none.default is None
    (fit,) = load_interpretation_file(_write(tmp_path, {**GOOD, "alternatives": "[0.5, 1]", "fitted": "[1.0]"}))
    assert fit.fitted == (1.0,) and fit.is_fitted(1) and not fit.is_fitted(0.5) and not r.is_fitted(0.5)


@pytest.mark.parametrize("change, problem", [
    ({"basis": "guessed"}, "unknown basis 'guessed'"),
    ({"default": "0.5"}, "also among the alternatives"),
    ({"default": "1", "alternatives": "[1.0]", "low": "", "high": ""}, "also among the alternatives"),
    ({"alternatives": "[0.5, 0.5]"}, "alternatives repeat a value"),
    ({"low": "2.0"}, "low 2.0 > high 1.5"),
    ({"default": "2.0"}, "outside [low, high]"),
    ({"low": ""}, "give both low and high"),
    ({"low": "'a'"}, "low must be a finite number"),
    ({"default": "rest", "low": "", "high": ""}, "default 'rest' is not a TOML value"),
    ({"alternatives": "[0.5"}, "alternatives '[0.5' is not a TOML value"),
    ({"alternatives": "0.5"}, "alternatives must be a TOML array"),
    ({"fitted": "[0.7]"}, "fitted names [0.7], which are not among the alternatives"),
    ({"fitted": "0.5"}, "fitted must be a TOML array"),
    ({"default": "'rest'", "alternatives": "['moving']"}, "needs a numeric default"),
    ({"basis": "fitted", "alternatives": "", "low": "", "high": ""}, "needs at least one alternative"),
    ({"parameter": "", "where": ""}, "needs a parameter or"),
    ({"parameter": "", "where": "not a path"}, "must be a dotted path"),
    ({"name": "Speed"}, "must be snake_case"),
    ({"experiments": ""}, "experiments is empty"),
    ({"reason": ""}, "reason is empty"),
])
def test_a_broken_row_is_refused_naming_file_line_and_problem(tmp_path, change, problem):
    path = _write(tmp_path, {**GOOD, "name": "other", "default": "0.4", "alternatives": "", "low": "", "high": ""},
                  {**GOOD, **change})
    with pytest.raises(InterpretationsError) as err:
        load_interpretation_file(path)
    message = str(err.value)
    assert str(path) in message and "line 4" in message     # comment, header, a good row, then the broken one
    assert problem in message


def test_true_and_one_are_different_alternatives(tmp_path):
    (r,) = load_interpretation_file(_write(tmp_path, {**GOOD, "default": "true", "alternatives": "[1]", "low": "",
                                               "high": ""}))
    assert r.default is True and r.alternatives == (1,)


def test_a_duplicate_name_is_refused(tmp_path):
    path = _write(tmp_path, GOOD, {**GOOD, "default": "0.4"})
    with pytest.raises(InterpretationsError, match=r"line 4: duplicate name 'speed' \(first on line 3\)"):
        load_interpretation_file(path)


def test_wrong_columns_are_refused(tmp_path):
    path = _write(tmp_path, GOOD, header=INTERPRETATION_COLUMNS[:-1])
    with pytest.raises(InterpretationsError, match=re.escape(f"{path}, line 2: columns must be")):
        load_interpretation_file(path)


def test_an_unknown_document_names_the_known_ones():
    with pytest.raises(KeyError, match="dogan2015"):
        interpretations("no_such_document")


def test_labelled_function_readings_match_the_functions_defaults():
    import inspect

    from locbook.scenarios import ozkaya
    from locbook.static import fingerprint
    declared = {r.name: r for r in interpretations("ozkaya2011")}
    weights = declared["nn_weights"]
    assert inspect.signature(fingerprint.knn_position).parameters["weighting"].default == weights.default
    assert set(weights.values) == set(fingerprint.KNN_WEIGHTINGS)
    average = declared["crlb_average"]
    assert inspect.signature(ozkaya.thesis_crlb_m).parameters["average"].default == average.default
    for value in average.values:              # every declared averaging is one the function computes
        assert ozkaya.thesis_crlb_m("corners3", 5.2, average=value) > 0


def test_requires_is_an_optional_last_column_of_other_parameters(tmp_path):
    from locbook.reproduce.interpretations import OPTIONAL_INTERPRETATION_COLUMNS
    header = INTERPRETATION_COLUMNS + OPTIONAL_INTERPRETATION_COLUMNS
    (r,) = load_interpretation_file(_write(tmp_path, {**GOOD, "requires": "{ mode = 'iso', k = 2 }"}, header=header))
    assert r.requires == {"mode": "iso", "k": 2}
    (plain,) = load_interpretation_file(_write(tmp_path, GOOD, header=header))      # empty: none
    assert plain.requires == {}
    for bad, problem in [("['mode']", "requires must be a TOML inline table"),
                         ("{ speed_mps = 1.0 }", "requires names the interpretation's own parameter 'speed_mps'")]:
        with pytest.raises(InterpretationsError, match=re.escape(problem)):
            load_interpretation_file(_write(tmp_path, {**GOOD, "requires": bad}, header=header))
    with pytest.raises(InterpretationsError, match="requires needs the interpretation's own parameter"):
        load_interpretation_file(_write(tmp_path, {**GOOD, "parameter": "", "where": "a.b", "requires": "{ m = 1 }"},
                                 header=header))


def test_a_bad_reading_after_a_blank_line_is_named_by_its_own_line(tmp_path):
    from locbook.reproduce.interpretations import INTERPRETATION_COLUMNS, InterpretationsError, load_interpretation_file
    path = tmp_path / "r.csv"
    path.write_text(",".join(INTERPRETATION_COLUMNS) + "\n\n" + "slope,george-study,a,,1.0,[1.0],,,,assumed,s,,r\n")
    with pytest.raises(InterpretationsError, match=r"r\.csv, line 3 \(slope\)"):
        load_interpretation_file(path)
