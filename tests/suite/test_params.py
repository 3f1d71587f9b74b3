"""Notebook parameters checked by pydantic against their annotation and their rule (locbook/suite/params.py).

No notebook is executed: these check the types and rules directly, and read parameters cells written here.
"""
import math
import operator

import nbformat
import pytest
from nbformat.v4 import new_code_cell, new_notebook
from papermill.translators import PythonTranslator

from locbook.errors import ParameterError
from locbook.suite.params import (
    NotebookParameter,
    ParameterRule,
    check_value,
    is_numeric_annotation,
    parse_cli_value,
    read_parameters,
    resolve_parameters,
)


def param(annotation, name="x"):
    return NotebookParameter(name, annotation, None, "")


@pytest.mark.parametrize("annotation, value", [
    ("int", 3), ("int", -2), ("float", 2.5), ("float", 3), ("bool", True), ("str", "a"), ("str", ""),
    ("list[float]", []), ("list[float]", [1, 2.5]), ("list[int]", [1, 2]), ("list[list[float]]", [[1], [2, 3.0]]),
    ("float | None", None), ("list[float] | None", None), ("Literal['a', 'b']", "b"), ("tuple[float, ...]", [1, 2]),
])
def test_values_of_the_declared_type_are_accepted(annotation, value):
    out = check_value(param(annotation), value)
    assert out == (list(value) if isinstance(value, tuple) else value)


@pytest.mark.parametrize("annotation, value", [
    ("int", True), ("int", 2.0), ("int", "2"), ("int", None), ("float", False), ("float", "2.5"), ("bool", 1),
    ("bool", "true"), ("str", 3), ("list[float]", "0.1,0.2"), ("list[float]", [1, "a"]), ("list[int]", [1.5]),
    ("list[list[float]]", [1, 2]), ("float | None", "none"), ("Literal['a', 'b']", "c"), ("tuple[float, ...]", 1.0),
])
def test_values_of_another_type_are_refused_naming_the_parameter_and_its_type(annotation, value):
    with pytest.raises(ParameterError) as exc:
        check_value(param(annotation, "sigma_db"), value)
    assert str(exc.value).startswith(f"parameter 'sigma_db' expects {annotation}, got {value!r}")


def test_ints_become_floats_where_floats_are_declared_also_inside_lists():
    assert type(check_value(param("float"), 3)) is float
    assert [type(v) for v in check_value(param("list[float]"), [1, 2.5])] == [float, float]
    assert [type(v) for row in check_value(param("list[list[float]]"), [[1], [2]]) for v in row] == [float, float]
    assert type(check_value(param("float | None"), 2)) is float
    assert type(check_value(param("list[int]"), [2])[0]) is int


def test_a_tuple_parameter_reaches_papermill_as_a_list():
    # papermill writes a Python tuple into the notebook as a quoted string; a list as a list literal
    out = check_value(param("tuple[float, ...]"), [1, 2])
    assert PythonTranslator.translate(out) == "[1.0, 2.0]"


@pytest.mark.parametrize("rule, good, bad, why", [
    (ParameterRule(ge=1), 1, 0, "must be >= 1"),
    (ParameterRule(gt=0), 1e-300, 0.0, "must be > 0"),
    (ParameterRule(le=31), 31, 32, "must be <= 31"),
    (ParameterRule(lt=1.5), 1.4999, 1.5, "must be < 1.5"),
])
def test_bounds_are_inclusive_or_strict_as_named(rule, good, bad, why):
    assert check_value(param("float"), good, rule) == good
    with pytest.raises(ParameterError, match=f"parameter 'x' = {bad!r} is not allowed: {why} "):
        check_value(param("float"), bad, rule)


def test_nan_is_never_a_value_and_infinity_only_where_the_rule_allows_it():
    for rule in (None, ParameterRule(), ParameterRule(allow_inf=True), ParameterRule(ge=0, allow_inf=True)):
        with pytest.raises(ParameterError, match="NaN is not a value"):
            check_value(param("float"), math.nan, rule)
        with pytest.raises(ParameterError, match="item nan: NaN is not a value"):
            check_value(param("list[float]"), [1.0, math.nan], rule)
    with pytest.raises(ParameterError, match="= inf is not allowed: must be finite"):
        check_value(param("float"), math.inf)
    with pytest.raises(ParameterError, match="= -inf is not allowed: must be finite"):
        check_value(param("float | None"), -math.inf, ParameterRule(ge=0))
    assert check_value(param("float"), math.inf, ParameterRule(ge=0, allow_inf=True)) == math.inf
    with pytest.raises(ParameterError, match="must be >= 0"):
        check_value(param("float"), -math.inf, ParameterRule(ge=0, allow_inf=True))


def test_a_rule_applies_to_every_number_inside_lists_and_its_length_to_the_list():
    rule = ParameterRule(ge=0, le=31, min_items=1, max_items=3)
    assert check_value(param("list[int]"), [0, 31], rule) == [0, 31]
    with pytest.raises(ParameterError, match=r"= \[3, 32\] is not allowed: item 32: must be <= 31"):
        check_value(param("list[int]"), [3, 32], rule)
    with pytest.raises(ParameterError, match=r"item -1: must be >= 0"):
        check_value(param("list[list[float]]"), [[1.0], [2.0, -1]], ParameterRule(ge=0, min_items=1))
    with pytest.raises(ParameterError, match=r"needs at least 1 item\(s\), got 0"):
        check_value(param("list[int]"), [], rule)
    with pytest.raises(ParameterError, match=r"allows at most 3 item\(s\), got 4"):
        check_value(param("list[int] | None"), [1, 2, 3, 4], rule)
    assert check_value(param("list[int] | None"), None, rule) is None
    # the message says everything that is allowed
    with pytest.raises(ParameterError, match=r"\(allowed: list\[int\], >= 0, <= 31, at least 1 item\(s\), at most "
                                             r"3 item\(s\), finite\)"):
        check_value(param("list[int]"), [-1], rule)


def test_an_int_with_a_fractional_bound_is_held_to_the_whole_numbers_the_bound_admits():
    # pydantic refuses a fractional bound on an int; the rule means n >= ceil(ge), n > floor(gt), n <= floor(le),
    # n < ceil(lt), checked here against every integer near the bounds (and inside lists)
    rules = [ParameterRule(ge=0.5, le=2.5), ParameterRule(gt=0.5, lt=2.5), ParameterRule(ge=-1.5, lt=-0.5),
             ParameterRule(gt=-1.5, le=1.0)]
    for rule in rules:
        for n in range(-4, 6):
            holds = all(op(n, b) for op, b in ((operator.ge, rule.ge), (operator.gt, rule.gt), (operator.le, rule.le),
                                               (operator.lt, rule.lt)) if b is not None)
            if holds:
                assert check_value(param("int"), n, rule) == n
                assert check_value(param("list[int]"), [n, n], rule) == [n, n]
            else:
                with pytest.raises(ParameterError, match=rf"'x' = {n} is not allowed: must be "):
                    check_value(param("int"), n, rule)
    with pytest.raises(ParameterError, match=r"'x' = 3 is not allowed: must be <= 2.5 \(allowed: int, >= 0.5, <= 2.5"):
        check_value(param("int"), 3, ParameterRule(ge=0.5, le=2.5))
    # an infinite bound: no constraint where every int meets it, refused (naming it) where none does
    assert check_value(param("int"), -7, ParameterRule(ge=-math.inf, le=math.inf)) == -7
    assert check_value(param("float"), 0.25, ParameterRule(ge=0.5 - 0.25)) == 0.25       # floats keep the bound
    with pytest.raises(ParameterError, match=r"the rule ge = inf admits no whole number"):
        check_value(param("int"), 3, ParameterRule(ge=math.inf))


def test_unsupported_annotations_are_refused():
    for annotation in ("dict[str, float]", "numpy.ndarray", "set[int]", "Path", "1 + 2", "list", "tuple"):
        with pytest.raises(ParameterError, match="unsupported parameter annotation"):
            check_value(param(annotation), 1)


def test_rules_from_toml_are_checked_and_named():
    where = "experiments.toml: [parameter_rules]"
    assert ParameterRule.from_toml("n", {"ge": 1, "min_items": 2}, where) == ParameterRule(ge=1, min_items=2)
    with pytest.raises(ParameterError, match=r"the rule for 'n' has unknown key\(s\) \['minimum'\]; allowed: ge, gt"):
        ParameterRule.from_toml("n", {"minimum": 1}, where)
    with pytest.raises(ParameterError, match="the rule for 'n' needs ge to be a number, got '1'"):
        ParameterRule.from_toml("n", {"ge": "1"}, where)
    with pytest.raises(ParameterError, match="the rule for 'n' needs allow_inf to be true or false, got 1"):
        ParameterRule.from_toml("n", {"allow_inf": 1}, where)
    with pytest.raises(ParameterError, match="the rule for 'n' needs min_items to be a whole number, got 1.5"):
        ParameterRule.from_toml("n", {"min_items": 1.5}, where)
    with pytest.raises(ParameterError, match="the rule for 'n' must be a table"):
        ParameterRule.from_toml("n", 3, where)


def test_command_line_values_are_toml_and_a_bare_word_is_a_string():
    assert parse_cli_value(param("list[float]"), "[0.1, 2]") == [0.1, 2.0]
    assert parse_cli_value(param("bool"), "True") is True
    assert parse_cli_value(param("Literal['zigzag', 'line']"), "zigzag") == "zigzag"
    assert parse_cli_value(param("str"), " two words ") == " two words "
    assert parse_cli_value(param("float | None"), "2") == 2.0
    with pytest.raises(ParameterError, match="parameter 'x' expects int, got 'abc'"):
        parse_cli_value(param("int"), "abc")


def test_unknown_names_are_refused_with_the_notebook_and_the_known_names():
    declared = {"n": param("int", "n"), "seed": param("int", "seed")}
    with pytest.raises(ParameterError, match=r"ctx: unknown parameter 'm' \(not in one.ipynb\); known: n, seed"):
        resolve_parameters("nb/one.ipynb", declared, {}, {"m": "1"}, "ctx")
    assert resolve_parameters("one.ipynb", declared, {"n": 2}, {"seed": "3"}, "ctx", {"n": ParameterRule(ge=1)}) \
        == {"n": 2, "seed": 3}


def _notebook(path, source):
    nb = new_notebook()
    cell = new_code_cell(source)
    cell.metadata["tags"] = ["parameters"]
    nb.cells = [new_code_cell("from typing import Literal"), cell]
    nbformat.write(nb, str(path))
    return path


def test_every_parameter_is_read_including_those_papermill_inspect_misses(tmp_path):
    # a help comment with '=', Literal[...] and '| None' (papermill 2.7's inspect_notebook skips these lines)
    nb = _notebook(tmp_path / "p.ipynb", 'n_particles: int = 250  # particles (Sec. 7.2.1: N = 250)\n'
                                         'start: Literal["rest", "moving"] = "rest"  # from rest\n'
                                         'alpha_dbm: float | None = None  # None = Table 6.1\n'
                                         'grid: list[list[float]] = [[0.0, 1.0]]\n')
    params = read_parameters(nb)
    assert [(p.name, p.annotation, p.default, p.help) for p in params.values()] == [
        ("n_particles", "int", 250, "particles (Sec. 7.2.1: N = 250)"),
        ("start", "Literal['rest', 'moving']", "rest", "from rest"),
        ("alpha_dbm", "float | None", None, "None = Table 6.1"),
        ("grid", "list[list[float]]", [[0.0, 1.0]], ""),
    ]
    assert [is_numeric_annotation(p.annotation) for p in params.values()] == [True, False, True, True]


@pytest.mark.parametrize("source, message", [
    ("seed = 1\n", "parameter 'seed' has no type annotation"),
    ("seed: int = 1\nprint(seed)\nimport os\n", "the parameters cell may only hold annotated assignments"),
    ("seed: int = abs(-1)\n", "parameter 'seed' needs a literal default value"),
    ("seed: int = 1.5\n", "default value: parameter 'seed' expects int, got 1.5"),
    ("x: float = float('nan')\n", "parameter 'x' needs a literal default value"),
    ("table: dict[str, int] = {}\n", "default value: unsupported parameter annotation 'dict[str, int]'"),
    ("seed: int = \n", "the parameters cell is not valid Python"),
])
def test_a_bad_parameters_cell_is_named_with_its_notebook(tmp_path, source, message):
    nb = _notebook(tmp_path / "bad.ipynb", source)
    with pytest.raises(ParameterError) as exc:
        read_parameters(nb)
    assert str(exc.value).startswith(str(nb)) and message in str(exc.value)


def test_the_runners_cache_key_does_not_depend_on_what_else_the_process_imported():
    import subprocess
    import sys
    code = ("import sys\n{}\nfrom locbook.suite import cachekey\nprint(cachekey.runner_fingerprint())")
    plain = subprocess.run([sys.executable, "-c", code.format("")], capture_output=True, text=True, check=True)
    more = subprocess.run([sys.executable, "-c", code.format("import locbook.tracking.unscented, locbook.benchmark")],
                          capture_output=True, text=True, check=True)
    assert plain.stdout == more.stdout and len(plain.stdout.strip()) == 64
