"""The run's views (live, plain, quiet; the end scoreboard) and the Dask executor, on the toy suite of
tests/suite/test_run.py."""
import csv
import io
import json

import pytest

from locbook.suite import load_suite, run_suite
from locbook.suite.progress import LiveProgress, make_progress
from toy_suite import run, set_profile

pytestmark = pytest.mark.notebooks


def _folder(toy, name="quick"):
    return toy / "reports" / name


def test_plain_view_has_no_control_characters_and_ends_with_the_scoreboard(toy, capsys):
    assert run(toy, "--jobs", "2") == 0
    out = capsys.readouterr().out          # captured: not a terminal, so "auto" is plain
    assert "\x1b" not in out and "\r" not in out
    lines = out.splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("experiment"))
    assert lines[head].split() == ["experiment", "status", "time", "reproduction"]
    board = {line.split()[0]: line for line in lines[head + 2:head + 4]}
    assert set(board) == {"george-one", "george-two"}
    # each toy notebook scores one reproduction row: its verdict is counted in the scoreboard
    verdicts = [r["verdict"] for r in csv.DictReader((_folder(toy) / "numbers.csv").read_text().splitlines())]
    for eid, verdict in zip(("george-one", "george-two"), verdicts):
        assert f"1 {verdict}" in board[eid] and " ok " in board[eid]
    assert lines[-1].startswith("done: 2 executed")


def test_a_second_run_shows_the_expected_time_from_the_last_report(toy, capsys):
    assert run(toy, "george-one") == 0
    seconds = json.loads((_folder(toy) / "george-one" / "report.json").read_text())["seconds"]
    capsys.readouterr()
    assert run(toy, "george-one", "--force") == 0
    assert f"running george-one (last run {seconds:.0f} s) ..." in capsys.readouterr().out


def test_quiet_prints_only_the_end(toy, capsys):
    assert run(toy, "--quiet") == 0
    out = capsys.readouterr().out
    assert "running" not in out and "[1/2]" not in out
    assert "george-one" in out and out.splitlines()[-1].startswith("done: 2 executed")


def test_live_view_draws_every_experiment_and_its_final_state(toy):
    suite = load_suite(toy / "notebooks" / "experiments.toml")
    stream = io.StringIO()
    view = LiveProgress(stream)
    result = run_suite(suite, suite.experiments, "quick", report_root=toy / "reports", progress=view)
    assert result.count("ok") == 2
    text = stream.getvalue()
    assert "george-one" in text and "george-two" in text and "2/2 finished" in text
    with pytest.raises(ValueError, match="progress mode must be one of"):
        make_progress("loud")


def test_a_scheduler_needs_the_dask_executor(toy, capsys):
    assert run(toy, "--scheduler", "tcp://127.0.0.1:1") == 2
    assert "needs --executor dask" in capsys.readouterr().err


def test_dask_run_on_two_workers_equals_the_local_run(toy, capsys):
    pytest.importorskip("distributed")
    set_profile(toy, "george-two", "seed = 7")
    assert run(toy, "--out", str(toy / "reports" / "local"), "--jobs", "2") == 0
    assert run(toy, "--out", str(toy / "reports" / "dask"), "--executor", "dask", "--jobs", "2") == 0
    out = capsys.readouterr().out
    assert "2 executed" in out
    local, dask = _folder(toy, "local"), _folder(toy, "dask")
    assert (dask / "numbers.csv").read_bytes() == (local / "numbers.csv").read_bytes()
    for eid in ("george-one", "george-two"):
        assert (dask / eid / "numbers.csv").read_bytes() == (local / eid / "numbers.csv").read_bytes()
        a, b = (json.loads((f / eid / "report.json").read_text()) for f in (local, dask))
        assert a["parameters"] == b["parameters"]
    # the same cache: a local run over the Dask run's folder finds both reports up to date, and vice versa
    assert run(toy, "--out", str(dask)) == 0
    assert "0 executed, 2 cached" in capsys.readouterr().out
    assert run(toy, "--out", str(local), "--executor", "dask", "--jobs", "1") == 0
    assert "0 executed, 2 cached" in capsys.readouterr().out


def test_a_failing_notebook_on_dask_fails_alone(toy, capsys):
    pytest.importorskip("distributed")
    set_profile(toy, "george-one", "fail = true")
    assert run(toy, "--executor", "dask", "--jobs", "2") == 1
    captured = capsys.readouterr()
    assert "failed: george-one (RuntimeError: deliberate failure)" in captured.err
    status = json.loads((_folder(toy) / "status.json").read_text())
    assert status["george-one"]["status"] == "failed" and status["george-two"]["status"] == "ok"


def test_suite_option_after_the_command_and_a_malformed_scheduler(toy, capsys):
    from locbook.suite.cli import main
    suite = str(toy / "notebooks" / "experiments.toml")
    assert main(["run", "george-two", "--suite", suite, "--reports", str(toy / "reports"), "--quiet"]) == 0
    assert "done: 1 executed" in capsys.readouterr().out
    assert main(["list", "--suite", suite]) == 0 and "george-one" in capsys.readouterr().out
    pytest.importorskip("distributed")
    assert run(toy, "--executor", "dask", "--scheduler", "bogus:addr") == 2
    err = capsys.readouterr().err
    assert "neither a scheduler address (tcp://HOST:PORT) nor an existing scheduler file" in err
    assert "Traceback" not in err


def test_the_live_view_shows_the_outcomes_time(monkeypatch):
    """One clock: a finished row shows the runner's time of the outcome (the scoreboard's), whatever its own clock
    said while it ran."""
    import locbook.suite.progress as progress
    from locbook.suite.runner import Outcome
    clock = [100.0]
    monkeypatch.setattr(progress.time, "perf_counter", lambda: clock[0])
    view = LiveProgress(io.StringIO())
    view.state = {"a": {"status": "queued", "since": None, "seconds": None, "attempt": 1}}
    view.start, view.total, view.done = 100.0, 1, 0
    view.started("a", 1)
    clock[0] = 135.0
    view.finished(Outcome("a", "ok", 34.5))
    assert view.state["a"]["seconds"] == 34.5
    view.finished(Outcome("b", "cached", 0.0))                       # a cached one shows no time
    assert view.state["b"]["seconds"] is None


def test_the_outcomes_time_runs_from_start_to_finish_and_the_scoreboard_shows_it(toy, capsys):
    """The outcome's seconds (the live view's and the scoreboard's) count the worker's and kernel's start and the
    export too: at least the notebook's own execution time in report.json, and at least its 1.5 s sleep."""
    from locbook.suite.progress import scoreboard_rows
    set_profile(toy, "george-one", "sleep_s = 1.5")
    suite = load_suite(toy / "notebooks" / "experiments.toml")
    done = run_suite(suite, [e for e in suite.experiments if e.id == "george-one"], "quick",
                     report_root=toy / "reports", progress="quiet")
    outcome, = done.outcomes
    notebook_s = json.loads((_folder(toy) / "george-one" / "report.json").read_text())["seconds"]
    assert outcome.seconds >= notebook_s >= 1.5
    assert scoreboard_rows(done)[0]["time"] == f"{outcome.seconds:.0f} s"


@pytest.mark.parametrize("name", ["ozkaya2011-comparison-sim", "an-experiment-id-of-sixty-characters-" + "x" * 23])
def test_the_plain_scoreboard_fits_100_columns_and_keeps_every_count(tmp_path, name):
    """A suite whose rows count many kinds and verdicts: every line at most 100 characters, and every count a row
    holds is still there, in the fixed verdict order."""
    from locbook.reproduce.report import NUMBER_COLUMNS
    from locbook.suite.progress import scoreboard_rows, scoreboard_text
    from locbook.suite.runner import Outcome, SuiteRun
    folder = tmp_path / name
    folder.mkdir()
    (folder / "summary.md").write_text("x")
    rows = [{**{c: "" for c in NUMBER_COLUMNS}, "experiment": name, "printed_id": f"p{i}", "kind": kind,
             "verdict": verdict}
            for i, (kind, verdict) in enumerate([(k, v) for k in ("reproduction", "calibrated", "claim")
                                                 for v in ("within", "loose", "miss") for _ in range(12)]
                                                + [("arithmetic", "consistent"), ("arithmetic", "inconsistent")])]
    with open(folder / "numbers.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=NUMBER_COLUMNS)
        writer.writeheader()
        writer.writerows(rows)
    run = SuiteRun([Outcome(name, "ok", 12.0)], tmp_path)
    text = scoreboard_text(run)
    assert max(len(line) for line in text.splitlines()) <= 100, text
    flat = " ".join(text.split())
    for kind, counts in scoreboard_rows(run)[0].items():
        if kind not in ("experiment", "status", "time") and counts:
            assert " ".join(counts.split()) in flat, (kind, counts)
    assert "12 within, 12 loose, 12 miss" in flat
