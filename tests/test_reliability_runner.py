"""Issue 44 (reliability, round 4), the runner's part: a Dask scheduler killed with SIGKILL mid-run, data files edited
or re-pointed while their experiment runs, a plain file where a report folder should be. Runs on the toy suite of
tests/test_suite.py (the tests that execute notebooks are marked so)."""
import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from test_suite import alive, cli, processes_mentioning, run, set_profile, toy, wait_for  # noqa: F401 (toy: fixture)


@pytest.fixture(autouse=True)
def fixed_source(monkeypatch):
    """Other work may edit locbook's source while these tests run: the cache key's source part is held fixed."""
    monkeypatch.setattr("locbook.suite.runner._runner_fingerprint", lambda: "fixed source")


def _sha256(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


# -- item 2: an external scheduler killed with SIGKILL ---------------------------------------------------------

@pytest.mark.slow
@pytest.mark.notebooks
def test_a_scheduler_killed_with_sigkill_ends_the_run_with_its_scoreboard(toy, tmp_path, request):
    """The reproduction of the issue: a scheduler and a worker in their own processes, the scheduler SIGKILLed once
    the kernel runs. The client gives up reconnecting and closes; the run must still end with the scoreboard, one
    line naming the scheduler, exit status 1, the experiment marked, no staging and no process left."""
    pytest.importorskip("distributed")
    scheduler_file = tmp_path / "scheduler.json"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL}
    scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--port", "0",
                                  "--no-dashboard", "--scheduler-file", str(scheduler_file)], **quiet)
    request.addfinalizer(scheduler.kill)
    assert wait_for(scheduler_file.exists, 60)
    worker = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", "--scheduler-file",
                               str(scheduler_file), "--nthreads", "1", "--nworkers", "1", "--no-dashboard"], **quiet)
    request.addfinalizer(worker.kill)
    set_profile(toy, "george-one", "sleep_s = 120.0")
    # both experiments: one runs on the single worker thread, the other waits for it on the scheduler (it never
    # starts, so nothing ends it: the stop waits for it its whole grace period, by when the client has closed)
    proc = cli(toy, "--executor", "dask", "--scheduler", str(scheduler_file), "--progress", "plain")
    request.addfinalizer(proc.kill)
    assert wait_for(lambda: any("ipykernel" in c for c in processes_mentioning(str(toy)).values()), 120)
    started = {p: c for p, c in processes_mentioning(str(toy)).items() if p != proc.pid}   # the worker and its kernel
    time.sleep(10)                                      # as in the issue: about 10 s after the kernel started
    scheduler.send_signal(signal.SIGKILL)
    out, err = proc.communicate(timeout=180)
    assert proc.returncode == 1, out + err
    assert "Traceback" not in out + err and "ClosedClientError" not in out + err
    assert any(line.startswith("experiment") for line in out.splitlines()), out       # the scoreboard
    assert "lost the Dask scheduler" in err and "george-one" in err, err
    folder = toy / "reports" / "quick"
    status = json.loads((folder / "status.json").read_text())
    assert {eid: r["status"] for eid, r in status.items()} == {"george-one": "failed", "george-two": "failed"}, status
    assert all("lost the Dask scheduler" in r["error"] for r in status.values()), status
    assert not list((folder / ".staging").glob("*")), list((folder / ".staging").rglob("*"))
    assert wait_for(lambda: not alive(started), 15), [started[p] for p in alive(started)]


# -- item 12: a plain file where a report folder should be -----------------------------------------------------

def _report(folder: Path, text="new") -> Path:
    folder.mkdir(parents=True)
    (folder / "report.md").write_text(text)
    return folder


@pytest.mark.parametrize("where", ["file", "dangling link", "file and an old file"])
def test_promotion_replaces_what_is_not_a_report_folder_and_leaves_nothing_behind(tmp_path, where):
    from locbook.suite.runner import _replace_dir
    final, old = tmp_path / "reports" / "george-one", tmp_path / "reports" / ".old-george-one"
    final.parent.mkdir()
    if where == "dangling link":
        final.symlink_to(tmp_path / "nowhere")
    else:
        final.write_text("not a report")
    if where == "file and an old file":
        old.write_text("left by an earlier run")
    _replace_dir(_report(tmp_path / "staging" / "george-one"), final)
    assert final.is_dir() and not final.is_symlink() and (final / "report.md").read_text() == "new"
    assert sorted(p.name for p in final.parent.iterdir()) == ["george-one"]
    assert (tmp_path / "nowhere").exists() is False


def test_recovery_removes_a_plain_old_file_and_a_plain_staging_file(tmp_path):
    from locbook.suite.runner import _recover
    good = _report(tmp_path / "george-one", "good")
    (tmp_path / ".old-george-one").write_text("left by an earlier run")
    (tmp_path / ".old-george-two").symlink_to(tmp_path / "nowhere")
    (tmp_path / "george-two").mkdir()
    (tmp_path / ".staging").write_text("a file where the run's staging folder goes")
    _recover(tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["george-one", "george-two"]
    assert (good / "report.md").read_text() == "good"


@pytest.mark.notebooks
def test_a_plain_file_where_a_report_folder_should_be_is_replaced_by_the_report(toy, capsys):
    folder = toy / "reports" / "quick"
    assert run(toy) == 0
    good_two = (folder / "george-two" / "report.md").read_bytes()
    import shutil
    shutil.rmtree(folder / "george-one")
    (folder / "george-one").write_text("a file where the report folder was")
    capsys.readouterr()
    assert run(toy) == 0
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err and "failed" not in err
    assert [line for line in out.splitlines() if "not a report folder" in line] == [
        f"george-one: {folder / 'george-one'} was a file, not a report folder; replaced by the new report"]
    assert "george-one: ok" in out and "george-two: cached" in out
    assert (folder / "george-one" / "report.md").is_file()
    assert (folder / "george-two" / "report.md").read_bytes() == good_two
    assert not list(folder.glob(".old-*")) and not (folder / ".failed").exists()
