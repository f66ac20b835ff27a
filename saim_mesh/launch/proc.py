"""A child process whose output goes to a log file (always drained, whatever it
writes), and whose lines we scan for what it says: `ready`, `summary`, ...

A child is part of whoever started it: on Linux it is sent SIGTERM when its parent dies
(`prctl(PR_SET_PDEATHSIG)`, set in the child before it becomes the command), so a
supervisor killed outright (kill -9) leaves nothing running headless; each child stops
as the supervisor would have stopped it. The kernel ties this to the *thread* that
started the child: start and restart children from one long-lived thread (the
supervisor's loop)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def py() -> list[str]:
    return [sys.executable, "-m", "saim_mesh"]


class Proc:
    def __init__(self, name: str, args: list[str], env=None, log_dir: str | Path | None = None, spawner=None):
        self.name, self.args, self.env = name, list(args), env
        self.spawner = spawner   # (args, log path, env) -> a Popen-like child (zygote.py), else a subprocess
        self.log_dir = Path(log_dir) if log_dir else Path(tempfile.mkdtemp(prefix="saim-"))
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.log_path = self.log_dir / f"{name}.log"
        self.starts = 0
        self.lines: list[str] = []
        self._log = None
        self.start()

    def start(self) -> None:
        """(Re)start: output is appended to the same log; lines are those of this run."""
        self.starts += 1
        if self._log is not None:
            self._log.close()
        self._log = open(self.log_path, "ab")
        self._pos = self._log.tell()
        self._partial = b""
        self.lines = []
        if self.spawner is not None:
            self.p = self.spawner(self.args, self.log_path, self.env)
            return
        self.p = subprocess.Popen(self.args, stdout=self._log, stderr=subprocess.STDOUT, env=self.env,
                                  stdin=subprocess.DEVNULL, preexec_fn=die_with_parent_hook())

    def poll_lines(self) -> list[str]:
        with open(self.log_path, "rb") as f:
            f.seek(self._pos)
            chunk = f.read()
        if not chunk:
            return []
        self._pos += len(chunk)
        parts = (self._partial + chunk).split(b"\n")
        self._partial = parts.pop()
        new = [x.decode("utf-8", "replace") for x in parts]
        self.lines += new
        return new

    def tail(self, n: int = 8) -> list[str]:
        self.poll_lines()
        return self.lines[-n:]

    def find(self, prefix: str) -> str | None:
        self.poll_lines()
        return next((x for x in self.lines if x.startswith(prefix)), None)

    def wait_for(self, prefix: str, timeout: float) -> str:
        end = time.monotonic() + timeout
        seen = 0
        while time.monotonic() < end:
            exited = self.p.poll() is not None   # checked first: then every line it wrote is readable
            self.poll_lines()
            for line in self.lines[seen:]:
                if line.startswith(prefix):
                    return line
            seen = len(self.lines)
            if exited:
                raise RuntimeError(f"{self.name} exited ({self.p.returncode}) before '{prefix}': "
                                   + " | ".join(self.lines[-10:]))
            time.sleep(0.01)
        raise TimeoutError(f"{self.name}: no '{prefix}' within {timeout} s")

    def stop(self, timeout: float = 5.0) -> None:
        """SIGTERM, `timeout` seconds to exit (a supervisor stopping its children needs more), then SIGKILL."""
        if self.p.poll() is None:
            self.p.terminate()
            try:
                self.p.wait(timeout)
            except subprocess.TimeoutExpired:
                self.p.kill()
                self.p.wait()
        self._log.close()

    def __enter__(self) -> "Proc":
        return self

    def __exit__(self, *exc) -> None:
        self.stop()   # reaped even when the block failed

    @property
    def pid(self) -> int:
        return self.p.pid

    def exited(self) -> int | None:
        return self.p.poll()


PR_SET_PDEATHSIG = 1


def wait_line(log: Path, proc, prefix: str, timeout: float) -> str:
    """The first line of `log` that starts with `prefix`, waited for: a process that is
    not a `Proc` (one started in a namespaced host, its output appended to a file).
    RuntimeError, with the log's last lines, when it exits first or `timeout` passes."""
    end = time.monotonic() + timeout

    def lines() -> list[str]:
        """Whole lines only: a line still being written would match its prefix cut short."""
        text = log.read_text(errors="replace") if log.exists() else ""
        return text[:text.rfind("\n") + 1].splitlines()

    def first() -> str | None:
        return next((x for x in lines() if x.startswith(prefix)), None)
    while (got := first()) is None:
        if proc.poll() is not None:
            if (got := first()) is not None:   # it printed, then exited, between the two looks
                return got
            raise RuntimeError(f"exited {proc.returncode} before '{prefix}': {lines()[-10:]}")
        if time.monotonic() > end:
            raise RuntimeError(f"within {timeout} s: no '{prefix}' in {log}: {lines()[-10:]}")
        time.sleep(0.01)
    return got


def _prctl():
    """libc's prctl (Linux), or None."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        import ctypes
        return ctypes.CDLL(None, use_errno=True).prctl
    except (OSError, AttributeError):
        return None


def die_with_parent(parent: int, sig: int = signal.SIGTERM, prctl=None) -> None:
    """In a child, before it becomes its command: `sig` when `parent` (the process that
    forked it) dies; if it died already (before this call), exit now. Nothing on other
    systems (there, whoever stops the supervisor reaps its children)."""
    prctl = prctl or _prctl()
    if prctl is None:
        return
    prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0)
    if os.getppid() != parent:   # orphaned between the fork and the prctl: the signal would never come
        os._exit(128 + int(sig))


def die_with_parent_hook(sig: int = signal.SIGTERM):
    """A `preexec_fn` for subprocess.Popen doing `die_with_parent` (prctl resolved here,
    before the fork: the child only makes the call), or None where there is no prctl."""
    prctl = _prctl()
    if prctl is None:
        return None
    parent = os.getpid()
    return lambda: die_with_parent(parent, sig, prctl)


def clean_env(base: dict | None = None) -> dict:
    """`base` (the environment by default) with what every mesh process wants set."""
    env = dict(os.environ if base is None else base)
    env.setdefault("PYTHONUNBUFFERED", "1")
    # dozens of small processes per machine: two malloc arenas each, not one per thread
    # (zenoh's threads would otherwise each grow their own and keep them)
    env.setdefault("MALLOC_ARENA_MAX", "2")
    return env


# one worker thread for Zenoh's receive runtime where the default is two (the other
# runtimes run one already): a leaf has a link or two, and on a shared machine a second
# receive worker only wakes the first (fewer context switches: bench_mesh measures the
# peer's CPU against the in-process EA's). Routers keep two.
LEAF_RUNTIME = "(rx:(worker_threads:1))"


def leaf_env() -> dict:
    """`clean_env` for a leaf (an EA peer, a source): one receive worker in Zenoh,
    unless ZENOH_RUNTIME is set already."""
    env = clean_env()
    if not env.get("ZENOH_RUNTIME"):   # an empty value makes Zenoh panic: unset counts as unset
        env["ZENOH_RUNTIME"] = LEAF_RUNTIME
    return env
