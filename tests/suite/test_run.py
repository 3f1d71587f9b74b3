"""The notebook suite: parameter checks, caching, failure isolation and reproducibility.

A small throw-away suite of toy notebooks keeps these tests fast; tests/project/test_notebooks.py runs the real one.
"""
import csv
import hashlib
import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from locbook.errors import ParameterError
from locbook.suite import SuiteError, load_suite, read_parameters, run_suite
from locbook.suite.cli import main
from locbook.suite.runner import _validate_report
from toy_suite import GOOD, PARAMS, _notebook, alive, cli, processes_mentioning, run, set_profile, wait_for

pytestmark = pytest.mark.notebooks   # these tests execute (toy) notebooks with papermill


def test_parameters_are_read_with_types(toy):
    params = read_parameters(toy / "notebooks" / "one.ipynb")
    assert {p: params[p].annotation for p in params} == {"seed": "int", "n": "int", "fail": "bool",
                                                         "mode": "Literal['a', 'b']", "sleep_s": "float",
                                                         "kill_worker": "bool", "read_data": "bool",
                                                         "weights": "list[float]"}
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
    ("n=0", "parameter 'n' = 0 is not allowed: must be >= 1"),
    ("n=-5", "parameter 'n' = -5 is not allowed: must be >= 1"),
    ("sleep_s=nan", "parameter 'sleep_s' = nan is not allowed: NaN is not a value"),
    ("sleep_s=inf", "parameter 'sleep_s' = inf is not allowed: must be finite"),
    ("n", "-p expects NAME=VALUE"),
    ("weights=0.1,0.2", "parameter 'weights' expects list[float], got '0.1,0.2'"),
    ("weights=[]", None),   # allowed: no rule on the length
])
def test_bad_parameter_stops_before_execution(toy, capsys, override, message):
    assert run(toy, "george-one") == 0
    report = toy / "reports" / "quick" / "george-one" / "george-one.ipynb"
    before = report.read_bytes()
    if message is None:
        assert run(toy, "george-one", "-p", override) == 0
    else:
        assert run(toy, "george-one", "-p", override) == 2
        assert message in capsys.readouterr().err
    assert report.read_bytes() == before               # the existing report is untouched


def test_a_parameter_on_several_experiments_goes_to_those_that_declare_it(toy, capsys):
    """`locbook run george -p NAME=VALUE` where only some of the selected experiments declare NAME runs
    those with it and says which were left out; a name none declares is refused before anything runs."""
    nb = toy / "notebooks" / "two.ipynb"
    _notebook(nb, PARAMS.replace("weights: list[float] = [1.0]  # a list\n", ""))     # george-two: no `weights`
    assert run(toy, "george", "-p", "weights=[2.0]") == 0
    out = capsys.readouterr().out
    assert "-p weights: 1 of 2 selected experiments declare it and run (george-one); left out: george-two" in out
    assert "1 executed" in out
    assert run(toy, "george", "-p", "n=3") == 0                      # declared by both: both run
    assert "2 executed" in capsys.readouterr().out
    assert run(toy, "george", "-p", "no_such=1") == 2
    assert "unknown parameter 'no_such': none of the 2 selected experiments declares it" in capsys.readouterr().err
    assert run(toy, "george-two", "-p", "weights=[2.0]") == 2        # one experiment: its own parameters only
    assert "unknown parameter 'weights'" in capsys.readouterr().err


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
    assert rows[0]["where"] == "Table 1, mean" and rows[0]["verdict"] in ("within", "loose")


def test_unknown_experiment_is_an_error(toy, capsys):
    assert run(toy, "george-nope") == 2
    assert "unknown experiment" in capsys.readouterr().err


def test_cli_values_are_toml(toy):
    exp = load_suite(toy / "notebooks" / "experiments.toml").experiments[0]
    values = exp.parameters("quick", {"weights": "[0.1, 2]", "sleep_s": "3", "mode": "b", "fail": "true"})
    assert values == {"n": 5, "weights": [0.1, 2.0], "sleep_s": 3.0, "mode": "b", "fail": True}
    assert type(values["sleep_s"]) is float and type(values["weights"][1]) is float


def test_concurrent_runs_leave_every_report_complete(toy):
    first = cli(toy, "--force")
    assert wait_for(lambda: (toy / "reports" / "quick" / ".lock").exists(), 30)
    second = cli(toy, "--force")
    out1, err1 = first.communicate(timeout=300)
    out2, err2 = second.communicate(timeout=300)
    assert first.returncode == 0 and second.returncode == 0, (err1, err2)
    assert "waiting for it to finish" in out2
    folder = toy / "reports" / "quick"
    for eid in ("george-one", "george-two"):
        assert _validate_report(folder / eid, eid) == ""
        assert json.loads((folder / eid / "run.json").read_text())["status"] == "ok"
    rows = list(csv.DictReader((folder / "numbers.csv").read_text().splitlines()))
    assert [r["experiment"] for r in rows] == ["george-one", "george-two"]
    assert not list((folder / ".staging").glob("*/*"))


def test_editing_a_data_file_reruns_exactly_its_readers(toy, capsys):
    set_profile(toy, "george-one", "read_data = true")
    assert run(toy) == 0
    record = json.loads((toy / "reports" / "quick" / "george-one" / "run.json").read_text())
    assert list(record["data"]) == [str((toy.parent / "shared" / "data" / "offset.csv").resolve())]
    assert json.loads((toy / "reports" / "quick" / "george-two" / "run.json").read_text())["data"] == {}
    capsys.readouterr()
    assert run(toy) == 0
    assert "0 executed, 2 cached" in capsys.readouterr().out
    (toy.parent / "shared" / "data" / "offset.csv").write_text("offset\n0.5\n")
    assert run(toy) == 0
    out = capsys.readouterr().out
    assert "george-one: ok" in out and "george-two: cached" in out and "1 executed, 1 cached" in out
    row = next(csv.DictReader((toy / "reports" / "quick" / "george-one" / "numbers.csv").read_text().splitlines()))
    assert row["printed"] == "0.5"


def test_the_cache_follows_the_library_modules_each_notebook_imported(toy, capsys):
    import locbook
    package = Path(locbook.__file__).resolve().parent
    assert run(toy) == 0
    record_path = toy / "reports" / "quick" / "george-one" / "run.json"
    record = json.loads(record_path.read_text())
    modules = record["modules"]
    # what the toy notebook ran (Report, Printed, streams) is recorded with its hash; what it never imported is not
    for used in ("__init__.py", "reproduce/report.py", "montecarlo.py"):
        path = str(package / used)
        assert modules[path] == hashlib.sha256((package / used).read_bytes()).hexdigest()
    assert not any("/tracking/" in m or m.endswith("particle.py") for m in modules)
    assert not any("__pycache__" in p for p in [*modules, *record["data"]])
    # a changed module (here: its recorded hash no longer matching) re-runs exactly the experiments that imported it
    modules[str(package / "reproduce" / "report.py")] = "0" * 64
    record_path.write_text(json.dumps(record))
    capsys.readouterr()
    assert run(toy) == 0
    out = capsys.readouterr().out
    assert "george-one: ok" in out and "george-two: cached" in out and "1 executed, 1 cached" in out


def test_a_killed_worker_fails_only_its_experiment(toy, capsys):
    assert run(toy) == 0
    good = (toy / "reports" / "quick" / "george-one" / "numbers.csv").read_bytes()
    set_profile(toy, "george-one", "kill_worker = true")
    assert run(toy, "--jobs", "2") == 1
    captured = capsys.readouterr()
    assert "george-one: worker process died (SIGKILL); retrying once" in captured.out
    assert "failed: george-one (worker process died (SIGKILL))" in captured.err
    assert "george-two" not in captured.err
    assert (toy / "reports" / "quick" / "george-one" / "numbers.csv").read_bytes() == good
    status = json.loads((toy / "reports" / "quick" / "status.json").read_text())
    assert status["george-one"]["status"] == "failed" and status["george-two"]["status"] == "cached"
    assert wait_for(lambda: not processes_mentioning(str(toy)), 5), processes_mentioning(str(toy))


@pytest.mark.parametrize("sig, code", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_interrupt_stops_the_run_cleanly_and_keeps_finished_reports(toy, request, sig, code):
    set_profile(toy, "george-two", "sleep_s = 120.0")
    proc = cli(toy, "--jobs", "2")
    request.addfinalizer(proc.kill)
    assert wait_for(lambda: (toy / "reports" / "quick" / "george-one" / "summary.md").exists(), 120)
    assert wait_for(lambda: any("ipykernel" in c for c in processes_mentioning(str(toy)).values()), 60)
    started = processes_mentioning(str(toy))          # runner, workers and kernels
    sent = time.monotonic()
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=30)
    assert time.monotonic() - sent < 10
    assert proc.returncode == code
    assert "Traceback" not in err and "Traceback" not in out
    assert f"interrupted by {sig.name}" in err and "interrupted: george-two" in err
    assert (toy / "reports" / "quick" / "george-one" / "summary.md").exists()
    assert not (toy / "reports" / "quick" / "george-two").exists()
    assert wait_for(lambda: not alive(started), 3), [started[p] for p in alive(started)]
    status = json.loads((toy / "reports" / "quick" / "status.json").read_text())
    assert status["george-two"]["status"] == "interrupted"


def test_sigkill_of_the_runner_leaves_no_worker_or_kernel(toy, request):
    set_profile(toy, "george-one", "sleep_s = 120.0")
    proc = cli(toy, "george-one")
    request.addfinalizer(proc.kill)
    assert wait_for(lambda: any("ipykernel" in c for c in processes_mentioning(str(toy)).values()), 60)
    started = processes_mentioning(str(toy))
    assert len(started) == 3                            # runner, worker, kernel
    proc.kill()
    proc.communicate()
    assert wait_for(lambda: not alive(started), 5), [started[p] for p in alive(started)]
    # the next run recovers the folder (the lock died with its holder; the stale staging is removed)
    assert run(toy, "george-two") == 0
    assert not list((toy / "reports" / "quick" / ".staging").glob("*"))


def test_partial_run_keeps_the_other_experiments_rows(toy):
    assert run(toy) == 0
    folder = toy / "reports" / "quick"
    before = [r for r in csv.DictReader((folder / "numbers.csv").read_text().splitlines())]
    (folder / "george-two" / "run.json").unlink()           # as in a fresh clone: run.json is not committed
    set_profile(toy, "george-one", "seed = 5")
    assert run(toy, "george-one") == 0
    after = [r for r in csv.DictReader((folder / "numbers.csv").read_text().splitlines())]
    assert ([r for r in after if r["experiment"] == "george-two"]
            == [r for r in before if r["experiment"] == "george-two"])
    assert ([r for r in after if r["experiment"] == "george-one"]
            != [r for r in before if r["experiment"] == "george-one"])
    index = (folder / "index.md").read_text()
    assert "not run" not in index and "[summary](george-two/summary.md)" in index


def snapshot(folder):
    return {p.relative_to(folder): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_override_run_writes_its_own_folder(toy, capsys):
    assert run(toy) == 0
    before = snapshot(toy / "reports" / "quick")
    capsys.readouterr()
    assert run(toy, "george-one", "-p", "n=7") == 0
    out = capsys.readouterr().out
    assert snapshot(toy / "reports" / "quick") == before
    made = [p.name for p in (toy / "reports").iterdir() if p.name.startswith("quick-")]
    assert (len(made) == 1 and made[0].startswith("quick-n-7-")
            and f"reports of this run: {toy / 'reports' / made[0]}" in out)
    index = (toy / "reports" / made[0] / "index.md").read_text()
    assert "george-one" in index and "george-two" not in index
    assert run(toy, "george-one", "-p", "n=7", "--out", str(toy / "reports" / "My_Run")) == 2


def test_bad_suite_inputs_get_one_clear_line(toy, capsys):
    toml = toy / "notebooks" / "experiments.toml"
    original = toml.read_text()
    toml.write_text(original.replace('id = "george-one"', 'id = "george-../one"'))
    with pytest.raises(SuiteError, match=r"experiment id 'george-../one' must be lower-case letters"):
        load_suite(toml)
    toml.write_text(original)
    for bad in ("0", "-1", "nan"):
        with pytest.raises(SystemExit) as exc:
            run(toy, "--timeout", bad)
        assert exc.value.code == 2
        assert "--timeout: must be a positive, finite number" in capsys.readouterr().err
    assert run(toy, "george-two") == 0
    good = (toy / "reports" / "quick" / "george-two" / "george-two.ipynb").read_bytes()
    (toy / "notebooks" / "two.ipynb").write_text("{ this is not JSON")
    assert run(toy, "george-two") == 2
    err = capsys.readouterr().err
    assert "two.ipynb: not a readable Jupyter notebook" in err and "Traceback" not in err
    assert (toy / "reports" / "quick" / "george-two" / "george-two.ipynb").read_bytes() == good
    suite = load_suite(toml)
    with pytest.raises(SuiteError, match="no Jupyter kernel named 'no-such-kernel'"):
        run_suite(suite, suite.experiments[:1], "quick", report_root=toy / "reports", kernel_name="no-such-kernel")


def test_unwritable_reports_folder_is_one_clear_line(toy, capsys):
    target = "/sys/fs/locbook-reports"         # sysfs refuses new folders even to root
    if not os.path.isdir("/sys/fs"):
        pytest.skip("needs /sys/fs")
    assert main(["--suite", str(toy / "notebooks" / "experiments.toml"), "run", "--reports", target, "george-one"]) == 2
    err = capsys.readouterr().err
    assert "cannot write to the reports folder /sys/fs/locbook-reports/quick" in err and "Traceback" not in err


def test_the_index_opens_with_the_kind_by_verdict_tables(toy, capsys):
    assert run(toy) == 0
    index = (toy / "reports" / "quick" / "index.md").read_text()
    # printed 0.0 with a +-1 window: wider than +-25 % of the printed value, so loose, never within
    assert "Independent reproductions: 0 within, 2 loose, 0 missed, of 2" in index
    assert "### a (2015), `george`" in index and "| kind | loose | rows |" in index
    assert "| reproduction | 2 | 2 |" in index
    summary = (toy / "reports" / "quick" / "george-one" / "summary.md").read_text()
    assert "| loose | 1 | the window is +-inf% of the printed value" in summary
    page = (toy / "reports" / "quick" / "george-one" / "report.md").read_text()
    assert "| mean | Table 1, mean |" in page and "test window (toy Sec. 1)" in page
    html = (toy / "reports" / "quick" / "index.html").read_text()
    assert "class='n v-loose'" in html


def test_committed_reports_are_never_written_from_a_dirty_tree(toy, capsys):
    git = lambda *a: subprocess.run(["git", "-C", str(toy), *a], check=True, capture_output=True)
    git("init", "-q")
    git("add", "-A")
    git("-c", "user.email=t@t", "-c", "user.name=t", "commit", "-q", "-m", "source")
    assert run(toy) == 0
    git("add", "-A")
    git("-c", "user.email=t@t", "-c", "user.name=t", "commit", "-q", "-m", "reports")
    stamp = json.loads((toy / "reports" / "quick" / "george-one" / "report.json").read_text())["locbook"]
    assert "uncommitted" not in stamp and "(source " in stamp
    before = (toy / "reports" / "quick" / "george-one" / "numbers.csv").read_bytes()
    _notebook(toy / "notebooks" / "one.ipynb", PARAMS.replace("n: int = 10", "n: int = 11"))
    capsys.readouterr()
    assert run(toy, "--force") == 2
    err = capsys.readouterr().err
    assert "holds committed reports" in err and "notebooks/one.ipynb" in err and "Traceback" not in err
    assert (toy / "reports" / "quick" / "george-one" / "numbers.csv").read_bytes() == before
    # an uncommitted folder may be written; its stamp says the source was dirty
    assert run(toy, "--out", str(toy / "scratch")) == 0
    stamp = json.loads((toy / "scratch" / "george-one" / "report.json").read_text())["locbook"]
    assert stamp.endswith("+ uncommitted changes)")


def test_the_kernel_runs_blas_on_one_thread(toy, tmp_path):
    """A worker's kernel loads BLAS with one thread (SINGLE_THREAD set before the kernel starts), so --jobs N
    workers use N cores, whatever the machine's core count (threadpoolctl reads the thread count in the kernel)."""
    record = tmp_path / "blas.json"
    body = GOOD + ("import json\nfrom threadpoolctl import threadpool_info\n"
                   f"open({str(record)!r}, 'w').write(json.dumps([p['num_threads'] for p in threadpool_info()]))\n")
    _notebook(toy / "notebooks" / "one.ipynb", PARAMS, body)
    assert run(toy, "george-one") == 0
    threads = json.loads(record.read_text())
    assert threads and set(threads) == {1}


def test_the_longest_experiments_are_launched_first(tmp_path):
    """Launch order: the last run times in this folder, longest first; an experiment this folder never
    timed takes the other profile's time; one never timed anywhere goes first; ties keep the suite's order."""
    from locbook.suite.runner import _longest_first

    def timed(folder, eid, seconds):
        (folder / eid).mkdir(parents=True)
        (folder / eid / "report.json").write_text(json.dumps({"seconds": seconds}))

    quick, full = tmp_path / "quick", tmp_path / "full"
    timed(quick, "a", 5.0)
    timed(quick, "b", 40.0)
    timed(full, "c", 300.0)           # quick never ran c: full's time ranks it
    timed(full, "b", 900.0)           # quick's own time for b wins
    timed(quick, "e", 5.0)
    ids = ["a", "b", "c", "d", "e"]
    order = sorted([(e, 1) for e in ids], key=_longest_first(quick, "quick", ids))
    assert [e for e, _ in order] == ["d", "c", "b", "a", "e"]
    # a data set's folder (reports/quick/data-x) has no sibling profile: its own times only
    data = quick / "data-x"
    timed(data, "a", 1.0)
    order = sorted([(e, 1) for e in ids], key=_longest_first(data, "quick", ids))
    assert [e for e, _ in order] == ["b", "c", "d", "e", "a"]
