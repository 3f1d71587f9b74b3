"""``locbook study``: the declaration's checks, the expansion of points and seeds, and study runs of a toy notebook
whose arithmetic is known (value = 10 a + b + seed), through the same runner as ``locbook run``."""
import csv
import json
import math
import re
import signal
import subprocess
import sys
import textwrap
from dataclasses import replace

import numpy as np
import pytest

from locbook.suite import SuiteError, load_suite
from locbook.suite.cli import main
from locbook.suite.study import _draw, expand_study, load_studies, load_study
from toy_suite import set_profile, wait_for


def _suite(toy):
    return load_suite(toy / "notebooks" / "experiments.toml")


def _study_file(tmp_path, text):
    path = tmp_path / "study.toml"
    path.write_text(textwrap.dedent(text))
    return path


# -- the declaration --------------------------------------------------------------------------------------------

@pytest.mark.parametrize("body, message", [
    ('name = "Bad Name"\nexperiments = ["george-study"]', "study name 'Bad Name' must be lower-case"),
    ('name = "s"\nexperiments = ["george-nope"]', "unknown experiment(s) george-nope"),
    ('name = "s"\nexperiments = []', "experiments must be a non-empty list"),
    ('name = "s"\nexperiments = ["george-study"]\ncolour = 1', "unknown key(s) ['colour']"),
    ('name = "s"\nexperiments = ["george-study"]\nprofile = "huge"', "profile 'huge' is not a profile"),
    ('name = "s"\nexperiments = ["george-study"]\n[study.parameters]\nzz = { grid = [1.0] }',
     "experiment 'george-study' has no parameter 'zz'"),
    ('name = "s"\nexperiments = ["george-study", "george-one"]\n[study.parameters]\na = { grid = [1.0] }',
     "experiment 'george-one' has no parameter 'a'"),
    ('name = "s"\nexperiments = ["george-study"]\n[study.parameters]\na = { sobol = [1.0] }',
     "parameter 'a' needs exactly one sampler of grid, list, random, lhs"),
    ('name = "s"\nexperiments = ["george-study"]\n[study.parameters]\na = { grid = [] }',
     "parameter 'a': grid needs a non-empty list"),
    ('name = "s"\nexperiments = ["george-study"]\nsamples = 3\n[study.parameters]\n'
     'a = { random = { low = 2, high = 1 } }',
     "parameter 'a': random needs low < high"),
    ('name = "s"\nexperiments = ["george-study"]\nsamples = 3\n[study.parameters]\n'
     'a = { lhs = { low = 0, high = 1, log = true } }',
     "log = true needs low > 0"),
    ('name = "s"\nexperiments = ["george-study"]\n[study.parameters]\na = { random = { low = 0, high = 1 } }',
     "random / lhs parameters (a) need samples >= 1"),
    ('name = "s"\nexperiments = ["george-study"]\nsamples = 2\n[study.parameters]\n'
     'seed = { lhs = { low = 0, high = 9 } }',
     "parameter 'seed' of 'george-study' is int; only float parameters can be drawn"),
    ('name = "s"\nexperiments = ["george-study"]\n[study.parameters]\nb = { list = [1.0] }\n'
     'tag = { list = ["p", "q"] }',
     "list parameters are paired element-wise and need equal lengths"),
    ('name = "s"\nexperiments = ["george-study"]\nreplicates = 0', "replicates must be a whole number >= 1"),
    ('name = "s"\nexperiments = ["george-study"]\nreplicates = 2\n[study.parameters]\nseed = { grid = [1, 2] }',
     "'seed' is swept and also set by the replicates"),
    ('name = "s"\nexperiments = ["george-study"]\nreplicates = 2\nseed_parameter = "a"',
     "replicates need an int parameter 'a'"),
])
def test_a_bad_declaration_is_refused_before_anything_runs(stoy, tmp_path, body, message):
    path = _study_file(tmp_path, "[[study]]\n" + body + "\n")
    with pytest.raises(SuiteError, match="^" + str(path).replace(".", r"\.") + ": ") as info:
        load_study(_suite(stoy), path)
    assert message in str(info.value)


@pytest.mark.parametrize("parameters, message", [
    ("a = { grid = [1.0, 6.0] }", "point 2 of 'george-study': parameter 'a' = 6.0 is not allowed: must be <= 5"),
    ("a = { grid = [1, \"x\"] }", "point 2 of 'george-study': parameter 'a' expects float"),
    ("b = { grid = [1.0, nan] }", "parameter 'b' = nan is not allowed: NaN is not a value"),
    ("b = { list = [1.0, 1.0] }", "point 2 of 'george-study' repeats point 1"),
])
def test_every_value_of_every_point_is_checked_against_its_rule(stoy, tmp_path, parameters, message):
    path = _study_file(tmp_path, f'[[study]]\nname = "s"\nexperiments = ["george-study"]\n[study.parameters]\n'
                                 f'{parameters}\n')
    with pytest.raises(SuiteError) as info:
        expand_study(load_study(_suite(stoy), path))
    assert message in str(info.value)


def test_a_drawn_range_outside_the_rule_is_refused(stoy, tmp_path):
    path = _study_file(tmp_path, '[[study]]\nname = "s"\nexperiments = ["george-study"]\nsamples = 50\n'
                                 '[study.parameters]\na = { random = { low = 4.0, high = 9.0 } }\n')
    with pytest.raises(SuiteError, match="parameter 'a' = .* is not allowed: must be <= 5"):
        expand_study(load_study(_suite(stoy), path))


def test_unknown_study_names_the_declared_ones(stoy, tmp_path):
    with pytest.raises(SuiteError, match=r"no study 'nope'.*\(declared: toy\)"):
        load_study(_suite(stoy), "nope")
    two = _study_file(tmp_path, '[[study]]\nname = "a"\nexperiments = ["george-study"]\n'
                                '[[study]]\nname = "b"\nexperiments = ["george-study"]\n')
    with pytest.raises(SuiteError, match=r"exactly one \[\[study\]\], found 2 \(a, b\)"):
        load_study(_suite(stoy), two)


# -- the expansion --------------------------------------------------------------------------------------------

def test_grid_crosses_paired_lists_and_replicates_take_consecutive_seeds(stoy):
    points = expand_study(load_study(_suite(stoy), "toy"))
    # 2 grid values x 2 paired list rows = 4 points, x 2 replicates; seeds from the profile's seed 3
    got = [(p.point, p.replicate, p.replicate_seed, p.values["a"], p.values["b"], p.values["tag"]) for p in points]
    assert got == [(1, 0, 3, 1.0, 0.25, "p"), (1, 1, 4, 1.0, 0.25, "p"), (2, 0, 3, 1.0, 0.5, "q"),
                   (2, 1, 4, 1.0, 0.5, "q"), (3, 0, 3, 1.5, 0.25, "p"), (3, 1, 4, 1.5, 0.25, "p"),
                   (4, 0, 3, 1.5, 0.5, "q"), (4, 1, 4, 1.5, 0.5, "q")]
    assert all(p.parameters["seed"] == p.replicate_seed for p in points)
    assert len({p.key for p in points}) == len(points)
    # one replicate keeps replicate 0's folder (the seed is always explicit): its cache carries over
    one = replace(load_studies(_suite(stoy))["toy"], replicates=1)
    assert [p.key for p in expand_study(one)] == [p.key for p in points if p.replicate == 0]


def test_random_and_latin_hypercube_draws(stoy, tmp_path):
    n = 40
    path = _study_file(tmp_path, f'[[study]]\nname = "s"\nexperiments = ["george-study"]\nsamples = {n}\n'
                                 'sample_seed = 7\n[study.parameters]\n'
                                 'a = {{ lhs = {{ low = 0.5, high = 4.5 }} }}\n'
                                 'b = {{ random = {{ low = 1e-3, high = 10.0, log = true }} }}\n'.replace("{{", "{")
                                 .replace("}}", "}"))
    study = load_study(_suite(stoy), path)
    points = expand_study(study)
    a = np.array([p.values["a"] for p in points])
    b = np.array([p.values["b"] for p in points])
    # Latin hypercube: exactly one sample in each of the n equal strata of [low, high)
    strata = np.floor((a - 0.5) / 4.0 * n).astype(int)
    assert sorted(strata) == list(range(n))
    assert np.all((b >= 1e-3) & (b < 10.0))
    # log-uniform: log b is uniform on [log 1e-3, log 10): its mean is near the middle (4 sd of n uniforms)
    u = (np.log(b) - math.log(1e-3)) / (math.log(10.0) - math.log(1e-3))
    assert abs(u.mean() - 0.5) < 4 * math.sqrt(1 / 12 / n)
    # the same study gives the same points; another sample seed other ones
    assert [p.values for p in expand_study(load_study(_suite(stoy), path))] == [p.values for p in points]
    other = replace(study, sample_seed=8)
    assert _draw(other)["a"] != _draw(study)["a"]


# -- runs ---------------------------------------------------------------------------------------------------------

def study(toy, *args, reports="reports"):
    return main(["--suite", str(toy / "notebooks" / "experiments.toml"), "study", "toy", "--reports",
                 str(toy / reports), "--progress", "plain", *args])


def _rows(toy, reports="reports"):
    with open(toy / reports / "studies" / "toy" / "study.csv", newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.mark.notebooks
def test_a_toy_study_writes_the_expected_rows_then_is_cached(stoy, capsys):
    assert study(stoy, "--jobs", "2") == 0
    out = capsys.readouterr().out
    assert "8 executed, 0 cached, 0 failed" in out
    # points named by their settings in the live lines and the scoreboard (a = 1.0 / 1.5 crossed with the paired
    # b and tag lists, 2 replicates), never by their folders' hashes
    assert re.findall(r"george-study-[0-9a-f]{6,}", out) == []
    for a in ("1.0", "1.5"):
        for b, tag in (("0.25", "p"), ("0.5", "q")):
            for rep in (0, 1):
                label = f"a={a}, b={b}, tag='{tag}' rep {rep}"
                assert f"running {label} ..." in out and re.search(rf"^{re.escape(label)}\s+ok\b", out, re.M), label
    rows = _rows(stoy)
    assert len(rows) == 8 and {r["quantity"] for r in rows} == {"value"}     # collect keeps "value" only
    assert list(rows[0])[:8] == ["study", "experiment", "point", "replicate", "replicate_seed", "a", "b", "tag"]
    for r in rows:
        a, b, seed = float(r["a"]), float(r["b"]), int(r["replicate_seed"])
        assert seed == 3 + int(r["replicate"])
        assert float(r["ours"]) == pytest.approx(10 * a + b + seed, rel=1e-9)
        assert float(r["mc_std_error"]) == pytest.approx(0.125 * seed, rel=1e-9)
        assert r["printed"] == "16.0" and float(r["rounding"]) == pytest.approx(0.05)
        assert r["experiment"] == "george-study" and r["study"] == "toy"
    folder = stoy / "reports" / "studies" / "toy"
    # each point's own report: the rows of its numbers.csv name the experiment, not the point
    with open(folder / rows[0]["folder"] / "numbers.csv", newline="") as fh:
        assert {r["experiment"] for r in csv.DictReader(fh)} == {"george-study"}
    # one plot per (printed quantity, numeric swept parameter): a and b; tag is text
    assert sorted(p.name.rsplit("-", 1)[-1] for p in (folder / "plots").glob("*.png")) == ["a.png", "b.png"]
    before = (folder / "study.csv").read_bytes()
    assert study(stoy) == 0
    assert "0 executed, 8 cached" in capsys.readouterr().out
    assert (folder / "study.csv").read_bytes() == before


@pytest.mark.notebooks
def test_a_point_equal_to_the_profiles_own_report_is_reused_not_executed(stoy, tmp_path, capsys):
    """Replicate 0 of the profile's own values (a = 1.0 is the default, seed 3 the quick profile's) is the quick
    report of the experiment: copied from reports/quick, not executed again; the other points run."""
    path = _study_file(tmp_path, """
        [[study]]
        name = "own"
        experiments = ["george-study"]
        replicates = 2
        [study.parameters]
        a = { grid = [1.0, 1.5] }
        """)
    toml = str(stoy / "notebooks" / "experiments.toml")
    assert main(["--suite", toml, "run", "george-study", "--reports", str(stoy / "reports"),
                 "--progress", "plain"]) == 0
    quick = stoy / "reports" / "quick" / "george-study"
    assert main(["--suite", toml, "study", str(path), "--reports", str(stoy / "reports"), "--progress", "plain"]) == 0
    out = capsys.readouterr().out
    assert "3 executed, 1 cached, 0 failed" in out, out
    assert "a=1.0 rep 0: the same run as" in out
    folder = stoy / "reports" / "studies" / "own"
    rows = {(r["a"], r["replicate"]): r for r in csv.DictReader(open(folder / "study.csv", newline=""))
            if r["quantity"] == "value"}
    own = rows[("1.0", "0")]
    # the reused report is the quick one (the executed notebook itself, 10 a + b + seed = 13), recorded with this
    # point's parameters
    assert float(own["ours"]) == pytest.approx(13.0, rel=1e-12)
    assert (folder / own["folder"] / "george-study.ipynb").read_bytes() == (quick / "george-study.ipynb").read_bytes()
    assert json.loads((folder / own["folder"] / "report.json").read_text())["parameters"] == {"a": 1.0, "seed": 3}
    assert float(rows[("1.5", "0")]["ours"]) == pytest.approx(18.0, rel=1e-12)
    assert float(rows[("1.0", "1")]["ours"]) == pytest.approx(14.0, rel=1e-12)
    # a second study run serves all four from its own folder
    assert main(["--suite", toml, "study", str(path), "--reports", str(stoy / "reports"), "--progress", "plain"]) == 0
    assert "0 executed, 4 cached" in capsys.readouterr().out
    # with --force nothing is reused: every point is executed
    assert main(["--suite", toml, "study", str(path), "--reports", str(stoy / "reports"), "--progress", "plain",
                 "--force"]) == 0
    assert "4 executed, 0 cached" in capsys.readouterr().out


def study_cli(toy, reports, *args):
    """``locbook study toy`` in its own process (the runner's cache key includes the locbook modules its process
    loaded, so runs meant to share a cache run as the same command)."""
    return subprocess.Popen([sys.executable, "-m", "locbook.suite.cli", "--suite",
                             str(toy / "notebooks" / "experiments.toml"), "study", "toy", "--reports",
                             str(toy / reports), "--jobs", "2", "--progress", "plain", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


@pytest.mark.notebooks
def test_a_study_interrupted_by_sigint_resumes_and_equals_an_uninterrupted_one(stoy, request):
    set_profile(stoy, "george-study", "sleep_s = 2.0")
    proc = study_cli(stoy, "cut")
    request.addfinalizer(proc.kill)
    folder = stoy / "cut" / "studies" / "toy"
    assert wait_for(lambda: any(folder.glob("george-study-*/summary.md")), 120)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 130 and "Traceback" not in err
    finished = len(list(folder.glob("george-study-*/summary.md")))
    assert 1 <= finished < 8
    out, err = study_cli(stoy, "cut").communicate(timeout=300)
    assert f"{8 - finished} executed, {finished} cached" in out, out + err     # the finished points are kept
    out, err = study_cli(stoy, "whole").communicate(timeout=300)
    assert "8 executed" in out, out + err
    assert len(list(folder.glob("george-study-*/summary.md"))) == 8
    assert (folder / "study.csv").read_bytes() == (stoy / "whole" / "studies" / "toy" / "study.csv").read_bytes()


@pytest.mark.notebooks
def test_a_study_on_dask_equals_the_local_one(stoy, capsys):
    pytest.importorskip("distributed")
    assert study(stoy, "--jobs", "2", reports="local") == 0
    assert study(stoy, "--jobs", "2", "--executor", "dask", reports="dask") == 0
    assert "8 executed" in capsys.readouterr().out
    assert (stoy / "dask" / "studies" / "toy" / "study.csv").read_bytes() == \
        (stoy / "local" / "studies" / "toy" / "study.csv").read_bytes()


def test_the_studies_of_the_experiment_list_are_valid():
    suite = load_suite()
    for declared in load_studies(suite).values():
        assert expand_study(declared)


def test_a_bad_study_is_one_line_and_exit_status_2(stoy, tmp_path, capsys):
    path = _study_file(tmp_path, '[[study]]\nname = "s"\nexperiments = ["george-study"]\n[study.parameters]\n'
                                 'a = { grid = [9.0] }\n')
    for name in ("nope", str(path)):
        assert main(["--suite", str(stoy / "notebooks" / "experiments.toml"), "study", name, "--reports",
                     str(tmp_path / "r")]) == 2
        err = capsys.readouterr().err
        assert err.startswith("locbook: error: ") and len(err.splitlines()) == 1 and "Traceback" not in err
    assert "parameter 'a' = 9.0 is not allowed: must be <= 5" in err
    assert not (tmp_path / "r").exists()          # nothing ran, nothing was written
