"""The runner (locbook.suite.runner) under adversity: a Dask scheduler killed with SIGKILL mid-run, data files edited
or re-pointed while their experiment runs, a plain file where a report folder should be. Runs on the toy suite
(tests/toy_suite.py; the tests that execute notebooks are marked so)."""
import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from toy_suite import alive, cli, processes_mentioning, run, set_profile, wait_for


@pytest.fixture(autouse=True)
def fixed_source(monkeypatch):
    """Other work may edit locbook's source while these tests run: the cache key's source part is held fixed."""
    monkeypatch.setattr("locbook.suite.cachekey.runner_fingerprint", lambda: "fixed source")


def _sha256(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


# -- an external scheduler killed with SIGKILL ---------------------------------------------------------

@pytest.mark.slow
@pytest.mark.notebooks
def test_a_scheduler_killed_with_sigkill_ends_the_run_with_its_scoreboard(toy, tmp_path, request):
    """The reproduction of the issue: a scheduler and a worker in their own processes, the scheduler SIGKILLed once
    the kernel runs. The client gives up reconnecting and closes; the run must still end with the scoreboard, one
    line naming the scheduler, exit status 1, the experiment marked, no staging and no process left. Whether the
    client has closed before the runner's last call on it depends on timing (here it is usually still reconnecting,
    and the old code passed too): the closed client itself is test_suite_failures.py's
    test_a_closed_dask_client_ends_the_run_with_the_scoreboard_and_no_traceback."""
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
    set_profile(toy, "george-two", "sleep_s = 120.0")
    # both experiments: one runs on the single worker thread, the other waits for it on the scheduler (it never
    # starts, so nothing ends it: the stop waits for it its whole grace period, by when the client has closed).
    # Both sleep: the scheduler may hand either one to the thread first, and a short one finished before the kill
    # (george-two "ok" in 0.7 s, in 2 of 3 fresh-clone runs)
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


# -- a plain file where a report folder should be -----------------------------------------------------

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


# -- files are hashed as the kernel reads them; a symbolic link's target is part of the record ----------

_READ_THEN_EDIT = """
import os, sys
import locbook
with open(sys.argv[1]) as fh:                    # the kernel reads the file ...
    fh.read()
with open(sys.argv[2], "w") as fh:               # ... which is edited while the experiment still runs
    fh.write("edited after it was read\\n")
open(sys.argv[1]).read()                         # a second read logs nothing more
"""


def _read_log(tmp_path, script, *args):
    log = tmp_path / "read.log"
    env = {**os.environ, "LOCBOOK_DATA_LOG": str(log), "LOCBOOK_DATA_ROOTS": str(tmp_path / "data")}
    subprocess.run([sys.executable, "-c", script, *map(str, args)], cwd=tmp_path, env=env, check=True)
    return [json.loads(line) for line in log.read_text(encoding="utf-8").splitlines()]


def test_the_data_log_records_the_content_the_kernel_read_not_the_content_at_promotion(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    (data / "walk.csv").write_text("content read\n")
    read = hashlib.sha256(b"content read\n").hexdigest()
    entries = _read_log(tmp_path, _READ_THEN_EDIT, "data/walk.csv", data / "walk.csv")
    assert entries == [{"path": str((data / "walk.csv").resolve()), "sha256": read}]
    assert _sha256(data / "walk.csv") != read                         # what is there now is not what was read


_OPEN_MISSING_THEN_CREATE = """
import pathlib, sys, locbook
late = pathlib.Path(sys.argv[1])
try:
    open(late).read()
except FileNotFoundError:
    pass
late.write_text("made later")
open(late).read()
"""


def test_a_file_first_opened_while_missing_is_logged_when_it_is_read(tmp_path):
    # the first open finds nothing to hash; the file made afterwards and read is what the report depends on
    (tmp_path / "data").mkdir()
    entries = _read_log(tmp_path, _OPEN_MISSING_THEN_CREATE, "data/late.csv")
    assert entries == [{"path": str((tmp_path / "data" / "late.csv").resolve()),
                        "sha256": hashlib.sha256(b"made later").hexdigest()}]


def test_a_file_read_through_a_symbolic_link_is_logged_with_the_link_and_its_target(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    (data / "a.csv").write_text("a\n")
    (data / "walk.csv").symlink_to("a.csv")
    entries = _read_log(tmp_path, "import sys, locbook; open(sys.argv[1]).read()", "data/walk.csv")
    assert entries == [{"path": str((data / "a.csv").resolve()), "sha256": _sha256(data / "a.csv"),
                        "link": str(tmp_path.resolve() / "data" / "walk.csv")}]


def test_the_runner_keeps_what_was_read_and_names_what_changed_since(tmp_path):
    from locbook.suite.cachekey import data_hashes, links_unchanged
    data = tmp_path / "data"
    data.mkdir()
    for name in ("a.csv", "b.csv", "same.csv"):
        (data / name).write_text(name)
    (data / "walk.csv").symlink_to("a.csv")
    read = {name: _sha256(data / name) for name in ("a.csv", "same.csv")}
    log = [{"path": str(data / "a.csv"), "sha256": read["a.csv"], "link": str(data / "walk.csv")},
           {"path": str(data / "same.csv"), "sha256": read["same.csv"]}]
    (tmp_path / ".data-read.log").write_text("".join(json.dumps(e) + "\n" for e in log) + '{"path": "/cut')
    (data / "a.csv").write_text("edited while the experiment ran")
    (data / "walk.csv").unlink()
    (data / "walk.csv").symlink_to("b.csv")                           # ... and re-pointed
    hashes, links, changed = data_hashes(tmp_path)
    assert hashes == {str(data / "a.csv"): read["a.csv"], str(data / "same.csv"): read["same.csv"]}
    assert links == {str(data / "walk.csv"): str(data / "a.csv")}
    assert changed == sorted([str(data / "a.csv"), str(data / "walk.csv")])
    assert not links_unchanged(links) and links_unchanged({str(data / "walk.csv"): str(data / "b.csv")})


@pytest.mark.notebooks
def test_a_data_file_edited_while_its_experiment_runs_is_not_served_as_cached(toy):
    offset = toy.parent / "shared" / "data" / "offset.csv"
    set_profile(toy, "george-one", "read_data = true\nsleep_s = 4.0")
    proc = cli(toy, "george-one", "--progress", "plain")

    def kernel_read_it():
        return any("offset.csv" in log.read_text() for log in toy.glob("reports/quick/.staging/*/*/.data-read.log"))
    try:
        assert wait_for(kernel_read_it, 120)
        time.sleep(1.0)                                  # the kernel's own read follows the hook's at once
        offset.write_text("offset\n0.5\n")
        out, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 0, out + err
    folder = toy / "reports" / "quick" / "george-one"
    assert _printed(folder) == "0.0"                       # computed from what it read
    record = json.loads((folder / "run.json").read_text())
    again = cli(toy, "george-one", "--progress", "plain")
    out2, err2 = again.communicate(timeout=120)
    # the next run executes it again (it used to say cached, serving 0.0 computed from the old content)
    assert again.returncode == 0 and "george-one: ok" in out2 and "done: 1 executed, 0 cached" in out2, out2 + err2
    assert _printed(folder) == "0.5"
    assert f"george-one: {offset.resolve()} changed while it ran, after its kernel read it; the report is kept, " \
           "and the next run executes it again" in out
    assert record["data"] == {str(offset.resolve()): hashlib.sha256(b"offset\n0.0\n").hexdigest()}


def _printed(folder):
    import csv
    return next(csv.DictReader((folder / "numbers.csv").read_text().splitlines()))["printed"]


@pytest.mark.notebooks
def test_re_pointing_a_symlinked_data_file_invalidates_the_report(toy, capsys):
    data = toy.parent / "shared" / "data"
    (data / "a.csv").write_text("offset\n0.0\n")
    (data / "b.csv").write_text("offset\n0.0\n")         # the same content: the link's target alone changed
    (data / "offset.csv").unlink()
    (data / "offset.csv").symlink_to("a.csv")
    set_profile(toy, "george-one", "read_data = true")
    assert run(toy) == 0
    record = json.loads((toy / "reports" / "quick" / "george-one" / "run.json").read_text())
    capsys.readouterr()
    assert run(toy) == 0 and "0 executed, 2 cached" in capsys.readouterr().out
    (data / "offset.csv").unlink()
    (data / "offset.csv").symlink_to("b.csv")
    assert run(toy) == 0
    out = capsys.readouterr().out
    assert "george-one: ok" in out and "george-two: cached" in out         # it used to say cached
    assert record["links"] == {str(data.resolve() / "offset.csv"): str((data / "a.csv").resolve())}
    record = json.loads((toy / "reports" / "quick" / "george-one" / "run.json").read_text())
    assert record["links"] == {str(data.resolve() / "offset.csv"): str((data / "b.csv").resolve())}


def test_a_reused_report_must_match_in_value_and_type_at_every_level():
    from locbook.suite.runner import _same_value
    assert _same_value([0.0, 5.0], [0.0, 5.0]) and _same_value({"a": [1]}, {"a": [1]}) and _same_value(None, None)
    # a float list's default written [0, 5] runs the notebook with ints: not the run of [0.0, 5.0]
    assert not _same_value([0, 5], [0.0, 5.0]) and not _same_value(1, 1.0) and not _same_value(True, 1)
    assert not _same_value([1.0], [1.0, 2.0]) and not _same_value((1.0,), [1.0])
    assert not _same_value(float("nan"), float("nan"))          # never assumed equal
