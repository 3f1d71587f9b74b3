"""The worker process (locbook.suite.worker): what it keeps of the kernel's stderr."""
import os

from locbook.suite.worker import _drop_kernel_chatter


def test_the_kernel_log_drops_papermill_and_ipykernel_chatter_and_keeps_everything_else(tmp_path):
    """papermill's notes on the annotated parameter lines and on parameters the notebook does not declare, and
    ipykernel's note on its TCP transport, say nothing about the notebook: left out. Warnings, errors and a
    KeyboardInterrupt stay, in order, and the file descriptor keeps writing after them (the worker's stderr)."""
    log = tmp_path / "kernel-stderr.log"
    fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
    try:
        os.write(fd, b"Unable to parse line 3 'seed: int = 1  # root of the streams'.\n"
                     b"/x/notebook.py:4: RuntimeWarning: divide by zero encountered in log10\n"
                     b"Passed unknown parameter: n_particles\n"
                     b"[IPKernelApp] WARNING | Kernel is running over TCP without encryption. All communication ...\n"
                     b"[IPKernelApp] ERROR | KeyboardInterrupt caught in kernel.\n"
                     b"Unable to parse the line\n")
        _drop_kernel_chatter(log, fd)
        os.write(fd, b"written after\n")
    finally:
        os.close(fd)
    assert log.read_text().splitlines() == [
        "/x/notebook.py:4: RuntimeWarning: divide by zero encountered in log10",
        "[IPKernelApp] ERROR | KeyboardInterrupt caught in kernel.",
        "Unable to parse the line",
        "written after"]
