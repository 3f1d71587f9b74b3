"""Failures that adversarial use of the suite found: relative report paths, corrupt cached reports,
a lost Dask scheduler, a full disk, raw parameter values in report.md and file modes. Runs on the toy suite of
tests/suite/test_run.py."""
import csv
import errno
import json
import os
import stat
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from locbook.suite import executors, load_suite, run_suite
from locbook.suite.cli import main
from toy_suite import GOOD, PARAMS, _notebook, alive, processes_mentioning, run, set_profile, wait_for

pytestmark = pytest.mark.notebooks


@pytest.fixture(autouse=True)
def fixed_source(monkeypatch):
    """Other work may edit locbook's source while these tests run; the cache key's source part is held fixed
    so that 'cached' depends on what each test does only."""
    monkeypatch.setattr("locbook.suite.cachekey.runner_fingerprint", lambda: "fixed source")


def _suite_args(toy):
    return ["--suite", str(toy / "notebooks" / "experiments.toml")]


# -- relative --reports / --out ---------------------------------------------------------------------

def test_relative_reports_and_out_folders_work_from_any_cwd(toy, tmp_path, monkeypatch, capsys):
    work = tmp_path / "elsewhere"
    work.mkdir()
    monkeypatch.chdir(work)
    assert main([*_suite_args(toy), "run", "george-one", "--reports", "rel-reports"]) == 0, capsys.readouterr()
    folder = work / "rel-reports" / "quick" / "george-one"
    assert (folder / "report.md").is_file() and (folder / "numbers.csv").is_file()
    assert main([*_suite_args(toy), "run", "george-two", "--out", "rel-out"]) == 0, capsys.readouterr()
    assert (work / "rel-out" / "george-two" / "report.md").is_file()
    # nothing was written relative to the notebooks' folder, where the kernels run
    assert not list((toy / "notebooks").glob("rel-*"))
    # the API resolves too: run_suite with a relative report_root
    suite = load_suite(toy / "notebooks" / "experiments.toml")
    result = run_suite(suite, suite.experiments[:1], "quick", report_root="api-reports", progress="quiet",
                       force=True)
    assert result.report_dir.is_absolute() and result.count("ok") == 1, result.outcomes


# -- corrupt cached reports are not cached ----------------------------------------------------------

def test_non_utf8_numbers_csv_is_not_served_and_does_not_crash_the_run(toy, capsys):
    assert run(toy) == 0
    folder = toy / "reports" / "quick"
    numbers = folder / "george-one" / "numbers.csv"
    numbers.write_bytes(numbers.read_bytes() + b"\xff\xfe garbage \x80\n")
    capsys.readouterr()
    assert run(toy) == 0
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    assert "george-one: ok" in out and "george-two: cached" in out
    assert sum("george-one" in line and "numbers.csv" in line and "not UTF-8" in line
               for line in out.splitlines()) == 1, out
    numbers.read_bytes().decode("utf-8")          # replaced by a fresh, valid report
    # an experiment NOT selected with a corrupt numbers.csv: the suite files are still rebuilt
    other = folder / "george-two" / "numbers.csv"
    other.write_bytes(b"\xff" * 20)
    assert run(toy, "george-one", "--force") == 0
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    rows = list(csv.DictReader((folder / "numbers.csv").read_text(encoding="utf-8").splitlines()))
    assert [r["experiment"] for r in rows] == ["george-one"]
    assert main([*_suite_args(toy), "list", "--reports", str(toy / "reports")]) == 0
    assert main([*_suite_args(toy), "show", "george-two", "--reports", str(toy / "reports")]) == 0


@pytest.mark.parametrize("damage", [b"{ not json", b"[1, 2]", b'{"experiment": "george-two"}', b"\xff\xfe"])
def test_a_corrupt_report_json_is_not_served_as_cached(toy, capsys, damage):
    assert run(toy) == 0
    (toy / "reports" / "quick" / "george-one" / "report.json").write_bytes(damage)
    capsys.readouterr()
    assert run(toy) == 0
    out, err = capsys.readouterr()
    assert "Traceback" not in out + err
    assert "george-one: ok" in out and "george-two: cached" in out
    assert sum("george-one" in line and "report.json" in line for line in out.splitlines()) == 1, out
    record = json.loads((toy / "reports" / "quick" / "george-one" / "report.json").read_text())
    assert record["experiment"] == "george-one"


# -- report.md escapes parameter values; kernel-stderr.log is not executable ----------------------

STRING_PARAM = 'label: str = "plain"  # free text\n'


def test_string_parameters_are_escaped_in_report_md(toy):
    _notebook(toy / "notebooks" / "one.ipynb", PARAMS + STRING_PARAM)
    payload = "<script>alert(1)</script><img src=x onerror=alert(2)>&amp;"
    assert run(toy, "george-one", "-p", f"label={json.dumps(payload)}") == 0
    made = next(p for p in (toy / "reports").iterdir() if p.name.startswith("quick-label-"))
    page = (made / "george-one" / "report.md").read_text(encoding="utf-8")
    assert "<script>" not in page and "<img" not in page and "&amp;amp;" in page
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in page
    html = (made / "george-one" / "report.html").read_text(encoding="utf-8")
    assert "<script>alert" not in html


def test_kernel_stderr_log_has_the_mode_of_the_other_report_files(toy):
    old = os.umask(0o022)
    try:
        assert run(toy, "george-one") == 0
    finally:
        os.umask(old)
    folder = toy / "reports" / "quick" / "george-one"
    mode = lambda name: stat.S_IMODE((folder / name).stat().st_mode)
    assert mode("kernel-stderr.log") == mode("numbers.csv") == mode("report.md") == 0o644


# -- a lost Dask scheduler stops the experiments' workers and kernels -------------------------------

def _cli(toy, *args):
    return subprocess.Popen([sys.executable, "-m", "locbook.suite.cli", *_suite_args(toy), "run", "--reports",
                             str(toy / "reports"), "--progress", "plain", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _close_within(cluster, timeout_s: float) -> None:
    try:
        cluster.close(timeout=timeout_s)
    except TimeoutError:        # its worker process is killed all the same (the test checks none is left)
        pass


def test_a_lost_dask_scheduler_leaves_no_worker_or_kernel_running(toy, request):
    distributed = pytest.importorskip("distributed")
    import logging
    # a cluster like a real one: the scheduler here, the Dask worker in its own process
    cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=True, dashboard_address=None,
                                       silence_logs=logging.CRITICAL)
    # the scheduler is closed below: closing the cluster then waits on it for distributed's default 30 s
    request.addfinalizer(lambda: _close_within(cluster, 5.0))
    set_profile(toy, "george-one", "sleep_s = 120.0")
    proc = _cli(toy, "george-one", "--executor", "dask", "--scheduler", cluster.scheduler_address)
    request.addfinalizer(proc.kill)
    assert wait_for(lambda: any("ipykernel" in c for c in processes_mentioning(str(toy)).values()), 120)
    started = processes_mentioning(str(toy))          # runner, the experiment's worker and its kernel
    assert len(started) == 3, started
    cluster.sync(cluster.scheduler.close)             # the scheduler dies mid-run
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 1, out + err
    assert "Traceback" not in out + err
    assert "scheduler" in err and "george-one" in err
    assert wait_for(lambda: not alive(started), 5), [started[p] for p in alive(started)]
    folder = toy / "reports" / "quick"
    assert not list((folder / ".staging").glob("*")) and not (folder / "george-one").exists()
    # nothing keeps writing into the report folder after locbook exited
    before = sorted(str(p) for p in folder.rglob("*"))
    import time
    time.sleep(3)
    assert sorted(str(p) for p in folder.rglob("*")) == before


class _CancelledFuture:
    """A Dask future the client lost with its scheduler: cancelled, its result never comes."""
    status = "cancelled"

    def __init__(self, task_path):
        self.staging = Path(task_path).parent

    def done(self):
        return True

    def result(self, timeout=None):
        raise RuntimeError("cancelled")

    def cancel(self):
        pass


class _LostTask(_CancelledFuture):
    """A lost future whose task still runs where it was sent: told to stop (``.stop``), it meets a kernel that is
    still starting, which makes its runtime folder again (as ipykernel makes its connection file's parents) before
    the worker kills it, and then ends as run_worker_process does."""
    started: list = []

    def __init__(self, task_path):
        import threading
        super().__init__(task_path)
        self.thread = threading.Thread(target=self._task, daemon=True)
        self.thread.start()
        _LostTask.started.append(self.thread)

    def _task(self):
        import time

        from locbook.suite.executors import _mark_ended
        deadline = time.monotonic() + 30
        while not (self.staging / ".stop").exists() and self.staging.exists() and time.monotonic() < deadline:
            time.sleep(0.01)
        time.sleep(0.5)                                                  # the worker takes a moment to stop
        (self.staging / ".runtime").mkdir(parents=True, exist_ok=True)   # the starting kernel's last act
        _mark_ended(self.staging)


class _LostCluster(executors.DaskExecutor):
    """A Dask executor whose client lost its scheduler (no cluster is started): each task submitted becomes a
    ``future`` (a :class:`_CancelledFuture` class)."""
    future = _CancelledFuture

    def __init__(self, jobs, scheduler=None):
        self.cluster, self.scheduler, self.capacity = None, "tcp://gone:8786", 1 << 30
        self.client = SimpleNamespace(status="closed", close=lambda: None)

    def submit(self, eid, task_path):
        return self.future(task_path)


class _ClosedClientFuture(_CancelledFuture):
    """A future of a client that gave up reconnecting and closed (a scheduler killed with SIGKILL): asking it anything
    that needs the scheduler raises distributed's ClosedClientError, cancel() included."""

    def _closed(self, *args, **kwargs):
        from distributed.client import ClosedClientError
        raise ClosedClientError("Trying to run a coroutine on a closed client")

    result = cancel = exception = _closed


class _FinishedOnAClosedClient(_ClosedClientFuture):
    """A task that finished on the cluster just as the client closed: its exit status can no longer be fetched."""
    status = "finished"


class _ClosedClient(_LostCluster):
    future = _ClosedClientFuture
    stop_grace_s = 0.5          # no task ever ran: nothing will write .ended


def _run_on(cluster, monkeypatch, toy, experiments):
    monkeypatch.setattr("locbook.suite.runner.make_executor", lambda kind, jobs, scheduler=None: cluster(jobs))
    suite = load_suite(toy / "notebooks" / "experiments.toml")
    return run_suite(suite, suite.experiments[:experiments], "quick", report_root=toy / "reports", progress="quiet",
                     executor="dask")


def test_a_lost_task_still_stopping_leaves_no_staging_behind(toy, monkeypatch):
    """The runner removes a lost task's staging only after the task ended (its .ended): removed earlier, a kernel
    still starting makes its folder again (CI, stop 43: test_a_lost_dask_scheduler... found it left behind)."""
    class StillStopping(_LostCluster):
        future = _LostTask

    monkeypatch.setattr(_LostTask, "started", [])
    result = _run_on(StillStopping, monkeypatch, toy, 1)
    assert result.count("failed") == 1 and "lost the Dask scheduler" in result.outcomes[0].error, result.outcomes
    for thread in _LostTask.started:
        thread.join()             # the task has ended on its worker: nothing writes any more
    folder = toy / "reports" / "quick"
    assert not list((folder / ".staging").glob("*")), list((folder / ".staging").rglob("*"))


@pytest.mark.parametrize("future", [_ClosedClientFuture, _FinishedOnAClosedClient])
def test_a_closed_dask_client_ends_the_run_with_the_scoreboard_and_no_traceback(toy, monkeypatch, capsys, future):
    """The client of a scheduler killed with SIGKILL closes, and from then on cancel() and result()
    raise ClosedClientError. The run still ends as for any lost cluster: the scoreboard, one line naming the
    scheduler, the lost experiments failed as lost (status.json updated), exit status 1, no staging left."""
    pytest.importorskip("distributed")
    cluster = type("Closed", (_ClosedClient,), {"future": future})
    monkeypatch.setattr("locbook.suite.runner.make_executor", lambda kind, jobs, scheduler=None: cluster(jobs))
    code = run(toy, "--executor", "dask", "--progress", "plain")
    out, err = capsys.readouterr()
    assert code == 1, out + err
    assert "Traceback" not in out + err and "ClosedClientError" not in err
    lines = out.splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("experiment"))       # the scoreboard
    assert {line.split()[0] for line in lines[head + 2:head + 4]} == {"george-one", "george-two"}
    assert [line for line in err.splitlines() if line.startswith("locbook: error:")] == [
        "locbook: error: lost the Dask scheduler tcp://gone:8786 (client closed); the run stopped, and its "
        "experiments on the cluster were asked to stop"]
    folder = toy / "reports" / "quick"
    status = json.loads((folder / "status.json").read_text())
    # every experiment is submitted at once (the cluster's capacity), so both were lost
    assert {eid: (r["status"], r["error"]) for eid, r in status.items()} == {
        eid: ("failed", "Dask task lost: lost the Dask scheduler tcp://gone:8786 (client closed)")
        for eid in ("george-one", "george-two")}
    assert not list((folder / ".staging").glob("*")) and not (folder / "george-one").exists()


# -- the executed notebook's HTML page, written by the runner ----------------------------------------------

def test_the_runner_writes_the_page_and_an_export_failure_fails_the_experiment_keeping_its_notebook(toy,
                                                                                                   monkeypatch):
    import locbook.suite.notebook_html as nh
    suite = load_suite(toy / "notebooks" / "experiments.toml")
    folder = toy / "reports" / "quick"
    assert run_suite(suite, suite.experiments[:1], "quick", report_root=toy / "reports", progress="quiet").count("ok")
    page = (folder / "george-one" / "george-one.html").read_text(encoding="utf-8")
    assert "<html" in page and "deliberate failure" in page                      # the notebook's code, rendered
    good = (folder / "george-one" / "report.md").read_bytes()

    def broken(path):
        raise ValueError("no template")
    monkeypatch.setattr(nh, "export_html", broken)
    run = run_suite(suite, suite.experiments[:1], "quick", report_root=toy / "reports", progress="quiet", force=True)
    (outcome,) = run.outcomes
    assert outcome.status == "failed" and outcome.error == "HTML export failed: ValueError: no template"
    assert (folder / ".failed" / "george-one" / "george-one.ipynb").is_file()        # kept for inspection
    assert (folder / "george-one" / "report.md").read_bytes() == good                # the good report stays


def test_a_full_disk_while_the_runner_writes_a_page_stops_the_run_and_names_the_path(toy, monkeypatch):
    import locbook.suite.notebook_html as nh

    def full(path):
        raise OSError(errno.ENOSPC, "No space left on device", str(Path(path).with_suffix(".html")))
    monkeypatch.setattr(nh, "export_html", full)
    suite = load_suite(toy / "notebooks" / "experiments.toml")
    run = run_suite(suite, suite.experiments, "quick", report_root=toy / "reports", progress="quiet", jobs=1)
    assert run.disk_full is not None and run.disk_full.endswith("george-one.html"), run.outcomes
    assert run.count("ok") == 0
    assert _leftovers(toy / "reports" / "quick") == []


def test_a_stopping_dask_run_waits_for_its_lost_tasks_within_one_budget(toy, monkeypatch):
    """Every lost task is waited for (its .ended) until one deadline shared by the whole stop, not a grace period
    each in turn (with every experiment submitted at once, a lost cluster used to cost 5 s per task)."""
    deadlines = []

    class NeverStarted(_LostCluster):
        stop_grace_s = 0.5

        def wait_or_kill(self, future, staging, timeout_s):
            import time
            start = time.perf_counter()
            super().wait_or_kill(future, staging, timeout_s)
            deadlines.append((start + timeout_s, start, time.perf_counter()))

    run = _run_on(NeverStarted, monkeypatch, toy, 2)
    assert run.count("failed") == 2 and len(deadlines) == 2, run.outcomes
    ends = [d[0] for d in deadlines]
    assert max(ends) - min(ends) < 0.05                          # one deadline for both
    # and nothing waited beyond it (each task 5 s more before)
    assert deadlines[-1][2] - deadlines[0][1] < 0.5 + 0.5
    assert not list((toy / "reports" / "quick" / ".staging").glob("*"))


# -- a full disk --------------------------------------------------------------------------------------

DISK_FULL_EXIT = 3


def _leftovers(folder):
    """Staging folders and temporary files a run must never leave behind."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*")
                  if p.name.endswith(".tmp") or (p.parent.name == ".staging"))


def _assert_disk_full_run(out, err, code, folder, good, path_part):
    assert code == DISK_FULL_EXIT, out + err
    assert "Traceback" not in out + err
    lines = [line for line in err.splitlines() if line.startswith("locbook: error: no space left on device")]
    assert len(lines) == 1 and path_part in lines[0], err
    assert "retrying" not in out                           # a full disk is not a kernel failure
    assert "experiment" in out and "status" in out           # the scoreboard is printed
    assert _leftovers(folder) == []
    for eid, files in good.items():                          # earlier reports intact, byte for byte
        assert {n: (folder / eid / n).read_bytes() for n in files} == files


def _report_files(folder, eid):
    return {p.name: p.read_bytes() for p in (folder / eid).iterdir() if p.is_file()}


def test_disk_full_while_promoting_stops_the_run_with_its_own_status(toy, monkeypatch, capsys):
    assert run(toy) == 0
    folder = toy / "reports" / "quick"
    good = {eid: _report_files(folder, eid) for eid in ("george-one", "george-two")}
    import locbook.suite.runner as runner
    calls = []

    def full(exp, profile, params, staging, *rest):
        calls.append(exp.id)
        raise OSError(errno.ENOSPC, "No space left on device", str(staging / "report.html"))

    monkeypatch.setattr(runner, "_promote", full)
    capsys.readouterr()
    code = run(toy, "--force", "--jobs", "1")
    out, err = capsys.readouterr()
    _assert_disk_full_run(out, err, code, folder, good, "/.staging/")
    # The launch order follows the last run's times (longest first), which for two toy notebooks is a coin toss;
    # what matters is that the run stopped at the first promotion and the other never started.
    assert len(calls) == 1, calls
    status = json.loads((folder / "status.json").read_text())
    assert status[calls[0]]["status"] == "failed" and "no space left" in status[calls[0]]["error"]
    other, = {"george-one", "george-two"} - set(calls)
    assert status[other]["status"] == "ok"                  # its earlier good run stands
    assert not (folder / ".failed").exists()


def test_a_kernel_that_meets_a_full_disk_is_not_retried(toy, capsys):
    """ENOSPC raised inside the kernel (a write to /dev/full, which always fails that way)."""
    assert run(toy) == 0
    folder = toy / "reports" / "quick"
    good = {eid: _report_files(folder, eid) for eid in ("george-one", "george-two")}
    _notebook(toy / "notebooks" / "one.ipynb", PARAMS,
              body=GOOD + "with open('/dev/full', 'w') as fh:\n    fh.write('x' * 100000)\n")
    capsys.readouterr()
    code = run(toy, "--force", "--jobs", "1", "george-one")
    out, err = capsys.readouterr()
    _assert_disk_full_run(out, err, code, folder, good, str(folder / ".staging"))


def _mount_tmpfs(path, size):
    path.mkdir()
    if not hasattr(os, "geteuid") or os.geteuid() != 0:
        pytest.skip("mounting a small tmpfs needs root; the injected-ENOSPC tests cover the same paths")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f"mounting a tmpfs is not permitted here ({done.stderr.strip()}); the injected-ENOSPC tests "
                    "cover the same paths")
    return lambda: subprocess.run(["umount", "-l", str(path)], capture_output=True)


def _fill(disk, leave_bytes):
    """Fill the file system of ``disk`` until at most ``leave_bytes`` are free."""
    filler = disk / "filler"
    with open(filler, "wb") as fh:
        try:
            while True:
                free = os.statvfs(disk).f_bavail * os.statvfs(disk).f_frsize
                if free <= leave_bytes:
                    break
                fh.write(b"\0" * min(1 << 20, max(4096, free - leave_bytes)))
                fh.flush()
        except OSError as exc:
            assert exc.errno == errno.ENOSPC


@pytest.mark.parametrize("leave_kb", [0, 96])
def test_a_real_full_disk(toy, tmp_path, request, capsys, leave_kb):
    """A 6 MB tmpfs holds the reports: one good run, then the disk is filled (to nothing left, or to a little
    room, so that the worker's or the kernel's writes fail rather than the runner's) and the run forced."""
    disk = tmp_path / "disk"
    request.addfinalizer(_mount_tmpfs(disk, "6m"))
    reports = disk / "reports"
    args = [*_suite_args(toy), "run", "--reports", str(reports), "--jobs", "1", "--progress", "plain"]
    assert main(args) == 0, capsys.readouterr()
    folder = reports / "quick"
    good = {eid: _report_files(folder, eid) for eid in ("george-one", "george-two")}
    index = (folder / "index.html").read_bytes()
    _fill(disk, leave_kb * 1024)
    capsys.readouterr()
    code = main([*args, "--force"])
    out, err = capsys.readouterr()
    _assert_disk_full_run(out, err, code, folder, good, str(disk))
    assert (folder / "index.html").read_bytes() == index
    assert wait_for(lambda: not processes_mentioning(str(disk)), 5), processes_mentioning(str(disk))
    # once there is room again the same command runs, and nothing of the failed run is in its way
    (disk / "filler").unlink()
    assert main([*args, "--force"]) == 0, capsys.readouterr()


def test_report_files_are_utf8_whatever_the_kernels_locale(tmp_path):
    """A kernel in an ASCII locale (C, without UTF-8 mode) writes numbers.csv and assumptions.csv as UTF-8, which
    is how the runner reads them."""
    code = ("import locbook as lb\n"
            "r = lb.Report('toy')\n"
            "p = lb.Printed('george', 'Table 1', 'mean', '', 'dB', '1.0')\n"
            "r.number('mean \\u03c3', p, 1.0, kind='reproduction', note='\\u00b1 one \\u03c3')\n"
            "r.assumption('\\u03c3', 1.0, 'a \\u00b5 reason')\n")
    env = {**os.environ, "LC_ALL": "C", "LANG": "C", "PYTHONCOERCECLOCALE": "0", "PYTHONUTF8": "0",
           "LOCBOOK_OUTPUT_DIR": str(tmp_path), "LOCBOOK_EXPERIMENT": "george-one"}
    env.pop("PYTHONIOENCODING", None)
    done = subprocess.run([sys.executable, "-c", "import locale; print(locale.getpreferredencoding(False))"],
                          env=env, capture_output=True, text=True)
    if done.stdout.strip().lower() in ("utf-8", "utf8"):
        pytest.skip("this Python uses UTF-8 even in the C locale")
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    row = next(csv.DictReader((tmp_path / "numbers.csv").read_text(encoding="utf-8").splitlines()))
    assert row["quantity"] == "mean \u03c3" and row["note"] == "\u00b1 one \u03c3"
    assert "a \u00b5 reason" in (tmp_path / "assumptions.csv").read_text(encoding="utf-8")


def test_a_staging_folder_a_straggler_writes_in_is_removed_on_a_second_pass(tmp_path, monkeypatch):
    """The end of a run removes its staging folder even when a worker that was told to stop writes a last file while
    the folder is being removed (the removal of the folder then fails once: here simulated)."""
    import shutil

    import locbook.suite.runner as runner
    real_rmtree = shutil.rmtree
    staging = tmp_path / ".staging" / "123-abcdef00"
    (staging / "george-one-1").mkdir(parents=True)
    (staging / "george-one-1" / "kernel-stderr.log").write_text("x")
    calls = []

    def racing_rmtree(path, ignore_errors=False):
        calls.append(path)
        real_rmtree(path, ignore_errors=ignore_errors)
        if len(calls) == 1:                       # a straggler's file landed while the tree was walked
            (Path(path) / "george-one-1").mkdir(parents=True)
            (Path(path) / "george-one-1" / ".result.json").write_text("{}")

    monkeypatch.setattr(runner.shutil, "rmtree", racing_rmtree)
    runner._remove_staging(staging)
    assert not staging.exists() and len(calls) == 2
