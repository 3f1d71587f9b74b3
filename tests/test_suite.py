"""The notebook suite: parameter checks, caching, failure isolation and reproducibility.

A small throw-away suite of toy notebooks keeps these tests fast; tests/test_notebooks.py runs the real one.
"""
import csv
import json
import textwrap

import nbformat
import pytest
from nbformat.v4 import new_code_cell, new_notebook

from locbook.cli import main
from locbook.errors import ParameterError
from locbook.suite import load_suite, read_parameters

GOOD = """\
import numpy as np
import locbook as lb
report = lb.Report("toy")
x = lb.streams(seed, "a")["a"].normal(size=n)
report.number("mean", "Table 1", 0.0, float(x.mean()), tolerance=1.0, tolerance_basis="test")
if fail:
    raise RuntimeError("deliberate failure")
"""


def _notebook(path, params_src, body=GOOD):
    nb = new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    params = new_code_cell(params_src)
    params.metadata["tags"] = ["parameters"]
    nb.cells = [new_code_cell("from typing import Literal"), params, new_code_cell(body)]
    nbformat.write(nb, str(path))


@pytest.fixture
def toy(tmp_path):
    nbdir = tmp_path / "notebooks"
    nbdir.mkdir()
    params = 'seed: int = 1  # seed\nn: int = 10  # samples\nfail: bool = False  # raise\nmode: Literal["a", "b"] = "a"  # a mode\n'
    _notebook(nbdir / "one.ipynb", params)
    _notebook(nbdir / "two.ipynb", params)
    (nbdir / "experiments.toml").write_text(textwrap.dedent("""
        [documents.george]
        title = "t"
        authors = "a"
        year = "2015"
        source = "s"
        note = "n"
        [[experiment]]
        id = "george-one"
        document = "george"
        title = "one"
        section = "Table 1"
        notebook = "one.ipynb"
        [experiment.profiles.quick]
        n = 5
        [experiment.profiles.full]
        n = 50
        [[experiment]]
        id = "george-two"
        document = "george"
        title = "two"
        section = "Table 2"
        notebook = "two.ipynb"
        [experiment.profiles.quick]
        [experiment.profiles.full]
        """))
    return tmp_path


def run(toy, *args):
    return main(["--suite", str(toy / "notebooks" / "experiments.toml"), "run", "--reports", str(toy / "reports"), *args])


def test_parameters_are_read_with_types(toy):
    params = read_parameters(toy / "notebooks" / "one.ipynb")
    assert {p: params[p].annotation for p in params} == {"seed": "int", "n": "int", "fail": "bool",
                                                         "mode": "Literal['a', 'b']"}
    assert params["n"].help == "samples"


def test_unannotated_parameter_is_rejected(tmp_path):
    _notebook(tmp_path / "bad.ipynb", "seed = 1\n")
    with pytest.raises(ParameterError, match="no type annotation"):
        read_parameters(tmp_path / "bad.ipynb")


@pytest.mark.parametrize("override, message", [
    ("no_such_param=1", "unknown parameter 'no_such_param'"),
    ("n=abc", "parameter 'n' expects int"),
    ("mode=c", "parameter 'mode' expects Literal"),
    ("fail=maybe", "parameter 'fail' expects bool"),
])
def test_bad_parameter_stops_before_execution(toy, capsys, override, message):
    assert run(toy, "george-one") == 0
    report = toy / "reports" / "quick" / "george-one" / "george-one.ipynb"
    before = report.read_bytes()
    assert run(toy, "george-one", "-p", override) == 2
    assert message in capsys.readouterr().err
    assert report.read_bytes() == before               # the existing report is untouched


def test_profile_value_of_wrong_type_is_rejected(toy):
    toml = toy / "notebooks" / "experiments.toml"
    toml.write_text(toml.read_text().replace("n = 5\n", 'n = "five"\n'))
    with pytest.raises(ParameterError, match="parameter 'n' expects int"):
        load_suite(toml).experiments[0].parameters("quick")


def test_cache_hit_then_force(toy, capsys):
    assert run(toy) == 0
    first = json.loads((toy / "reports" / "quick" / "status.json").read_text())
    assert {v["status"] for v in first.values()} == {"ok"}
    capsys.readouterr()
    assert run(toy) == 0
    assert "0 executed, 2 cached" in capsys.readouterr().out
    assert run(toy, "george-one", "-p", "n=7") == 0        # a changed parameter re-executes
    assert "1 executed, 0 cached" in capsys.readouterr().out
    assert run(toy, "--force", "george-two") == 0
    assert "1 executed" in capsys.readouterr().out


def test_failure_is_isolated_and_keeps_last_good_report(toy, capsys):
    assert run(toy) == 0
    good = (toy / "reports" / "quick" / "george-one" / "numbers.csv").read_text()
    toml = toy / "notebooks" / "experiments.toml"
    toml.write_text(toml.read_text().replace("n = 5\n", "n = 6\nfail = true\n"))   # only george-one fails
    assert run(toy, "--force", "--jobs", "2") == 1
    captured = capsys.readouterr()
    assert "failed: george-one (RuntimeError: deliberate failure)" in captured.err
    assert "george-two" not in captured.err
    assert (toy / "reports" / "quick" / "george-one" / "numbers.csv").read_text() == good
    assert (toy / "reports" / "quick" / ".failed" / "george-one" / "george-one.ipynb").exists()
    status = json.loads((toy / "reports" / "quick" / "status.json").read_text())
    assert status["george-one"]["status"] == "failed" and status["george-two"]["status"] == "ok"
    assert "showing the last good report" in (toy / "reports" / "quick" / "index.html").read_text()


def test_forced_runs_give_identical_numbers(toy):
    assert run(toy, "--force") == 0
    first = (toy / "reports" / "quick" / "numbers.csv").read_text()
    assert run(toy, "--force") == 0
    assert (toy / "reports" / "quick" / "numbers.csv").read_text() == first
    rows = list(csv.DictReader(first.splitlines()))
    assert [r["experiment"] for r in rows] == ["george-one", "george-two"]
    assert rows[0]["where"] == "Table 1" and rows[0]["within_tolerance"] == "True"


def test_unknown_experiment_is_an_error(toy, capsys):
    assert run(toy, "george-nope") == 2
    assert "unknown experiment" in capsys.readouterr().err
