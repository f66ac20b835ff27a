"""`proc.wait_line`: a line waited for in the log of a process that is not a `Proc` (one
started in a namespaced host): found once written, and an early exit or the timeout said
with the log's last lines rather than waited out."""
from __future__ import annotations

import subprocess
import sys
from contextlib import contextmanager

import pytest

from saim_mesh.launch.proc import wait_line

pytestmark = pytest.mark.timeout(60)


def spawn(tmp_path, code: str):
    log = tmp_path / "child.log"
    with open(log, "ab") as f:
        return log, subprocess.Popen([sys.executable, "-c", code], stdout=f, stderr=subprocess.STDOUT)


@contextmanager
def running(tmp_path, code: str):
    """A child running `code` (its log and process), killed and reaped however the test ends."""
    log, p = spawn(tmp_path, code)
    try:
        yield log, p
    finally:
        p.kill()
        p.wait()


def test_the_line_written_is_found(tmp_path):
    with running(tmp_path, "import sys, time; print('starting'); sys.stdout.flush(); time.sleep(0.3); "
                           "print('ready at 7', flush=True); time.sleep(30)") as (log, p):
        assert wait_line(log, p, "ready", 20) == "ready at 7"


def test_an_exit_before_the_line_is_said_with_its_code_and_last_lines(tmp_path):
    log, p = spawn(tmp_path, "print('no route to 198.18.0.9', flush=True); raise SystemExit(4)")
    with pytest.raises(RuntimeError, match=r"exited 4 before 'ready'.*no route to 198.18.0.9"):
        wait_line(log, p, "ready", 20)


def test_the_timeout_is_said_not_waited_past(tmp_path):
    with running(tmp_path, "import time; print('still starting', flush=True); time.sleep(30)") as (log, p):
        with pytest.raises(RuntimeError, match=r"within 0.5 s: no 'ready'.*still starting"):
            wait_line(log, p, "ready", 0.5)


def test_a_line_still_being_written_is_read_only_once_whole(tmp_path):
    """The child writes the line's start, waits, then its end: the line returned is whole
    (a read of the unfinished line gave 'received 150000' without its duration)."""
    code = ("import sys, time; sys.stdout.write('received 150000'); sys.stdout.flush(); time.sleep(0.5); "
            "print(' 3.1', flush=True); time.sleep(30)")
    with running(tmp_path, code) as (log, p):
        assert wait_line(log, p, "received", 20) == "received 150000 3.1"


def test_a_line_printed_just_before_exit_is_found_not_called_an_early_exit(tmp_path):
    log, p = spawn(tmp_path, "print('received 5 0.1', flush=True)")
    p.wait()
    assert wait_line(log, p, "received", 20) == "received 5 0.1"
