"""A fork server for the EA peers: it imports the heavy modules once (numpy, shapely,
pyproj, zenoh, the EA and its domains: each peer would otherwise hold its own private
copy of all of them), warms a live peer up on a small scenario with no Zenoh session so
that what the code builds on first use exists too (`live.warm`: codecs, specialised
bytecode, the EA's detectors), freezes it all out of the garbage collector's reach, and
forks each peer from itself, so the peers of a host share those pages copy-on-write
instead of each holding a copy.

Zenoh is imported but never opened here (a fork after `zenoh.open` hangs); each
child opens its own session. The launcher talks to the zygote over its stdin and
stdout (JSON lines); a forked child is handled through `Forked`, which answers like
a `subprocess.Popen` (pid, poll, wait, signals), its exit status reported by the
zygote that reaps it. `SAIM_ZYGOTE=0` turns it off (plain subprocesses)."""
from __future__ import annotations

import atexit
import contextlib
import gc
import importlib
import json
import os
import select
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

from .proc import clean_env, die_with_parent

PRELOAD = ("numpy", "shapely", "shapely.geometry", "pyproj", "zenoh", "zenoh.ext", "msgspec", "msgpack",
           "saim_mesh.cli", "saim_mesh.launch.zenoh_config", "saim_mesh.live.peer", "saim_mesh.live.serve",
           "ea_agent.domains.suo.domain", "ea_agent.domains.uv.domain")
WARM_SCENARIO = Path(__file__).resolve().parents[2] / "scenarios" / "small"


# -- the zygote process ------------------------------------------------------------------
def _child(req: dict) -> None:
    """In the forked child: become the requested command, then exit with its code."""
    code = 1
    try:
        os.setpgid(0, 0)   # its own group: a signal to it is not a signal to its siblings
        for s in (signal.SIGTERM, signal.SIGINT, signal.SIGCHLD):
            signal.signal(s, signal.SIG_DFL)
        die_with_parent(_ZYGOTE_PID)   # the zygote gone (its launcher killed): no orphan peers
        fd = os.open(req["log"], os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
        null = os.open(os.devnull, os.O_RDONLY)
        os.dup2(null, 0)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        os.close(fd)
        os.close(null)
        sys.stdin = open(0, closefd=False)
        sys.stdout = open(1, "w", buffering=1, closefd=False)
        sys.stderr = open(2, "w", buffering=1, closefd=False)
        os.environ.clear()
        os.environ.update(req["env"])
        # the zygote's imports stay frozen: a full collection would write to every one of
        # their headers and copy their pages into this child (what it allocates is collected)
        sys.argv = ["saim-mesh", *req["argv"]]
        from saim_mesh.cli import main
        code = main(req["argv"]) or 0
    except SystemExit as e:
        code = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
    except BaseException:   # noqa: BLE001 -- whatever it was, the child says it and exits
        import traceback
        traceback.print_exc()
    finally:
        try:
            sys.stdout.flush()
            sys.stderr.flush()
        finally:
            os._exit(code)


_ZYGOTE_PID = 0   # set in `serve`: the parent every forked child checks it still has


def _die_with_launcher() -> None:
    """SIGTERM when the launcher dies (Linux prctl PR_SET_PDEATHSIG; the launcher's pid
    comes in SAIM_ZYGOTE_PARENT): a launcher (a host's supervisor) killed outright takes
    the zygote with it, and the zygote its children (`die_with_parent` in `_child`)."""
    launcher = int(os.environ.get("SAIM_ZYGOTE_PARENT") or os.getppid())
    die_with_parent(launcher)


def warm_up(scenario: Path = WARM_SCENARIO) -> str | None:
    """Run a live peer through the first half hour of a small scenario's sources here,
    before any fork (`live.warm`). A problem is returned, not raised: a zygote that could
    not warm up still forks. `SAIM_ZYGOTE_WARM`: 0 for none, or another scenario's directory."""
    choice = os.environ.get("SAIM_ZYGOTE_WARM", "1")
    if choice == "0":
        return None
    if choice not in ("", "1"):
        scenario = Path(choice)
    try:
        from ..live.warm import warm
        with contextlib.redirect_stdout(sys.stderr):   # stdout is the launcher's channel
            warm(scenario)
    except Exception as e:   # noqa: BLE001 -- whatever it was: named, and no warm-up
        return f"zygote: no warm-up ({scenario}: {type(e).__name__}: {e})"
    return None


def serve() -> None:
    """The zygote's loop: fork on request, report every child's pid and exit status.
    It ends when its launcher is gone (stdin closed, or SIGTERM when it died), and its
    children with it: a host's processes never run on without their supervisor."""
    global _ZYGOTE_PID
    _ZYGOTE_PID = os.getpid()
    _die_with_launcher()
    for m in PRELOAD:
        importlib.import_module(m)
    problem = warm_up()
    if problem:
        print(problem, file=sys.stderr, flush=True)
    gc.collect()
    gc.freeze()   # imported objects stay out of the collector's passes: their pages stay shared
    out = sys.stdout
    out.write("ready\n")
    out.flush()
    live: set[int] = set()
    buf = b""
    while True:
        r, _, _ = select.select([0], [], [], 0.05)
        if r:
            data = os.read(0, 65536)
            if not data:   # the launcher is gone: so are we (each child gets SIGTERM as we exit)
                return
            buf += data
            while b"\n" in buf:
                line, buf = buf.split(b"\n", 1)
                req = json.loads(line)
                pid = os.fork()
                if pid == 0:
                    _child(req)
                live.add(pid)
                out.write(json.dumps({"id": req["id"], "pid": pid}) + "\n")
                out.flush()
        for pid in list(live):
            try:
                done, status = os.waitpid(pid, os.WNOHANG)
            except ChildProcessError:
                live.discard(pid)
                continue
            if done:
                live.discard(pid)
                out.write(json.dumps({"exit": pid, "code": os.waitstatus_to_exitcode(status)}) + "\n")
                out.flush()


# -- the launcher's side -------------------------------------------------------------------
class Forked:
    """A child of the zygote, handled like a `subprocess.Popen`."""

    def __init__(self, zygote: "Zygote", pid: int):
        self.z, self.pid = zygote, pid
        self.args: list[str] = []

    @property
    def returncode(self) -> int | None:
        return self.z.codes.get(self.pid)

    def poll(self) -> int | None:
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        end = None if timeout is None else time.monotonic() + timeout
        with self.z.cond:
            while self.pid not in self.z.codes:
                left = None if end is None else end - time.monotonic()
                if left is not None and left <= 0:
                    raise subprocess.TimeoutExpired(self.args, timeout)
                if not self.z.alive():   # no zygote to reap it: ask the kernel whether it is there
                    if not _exists(self.pid):
                        self.z.codes[self.pid] = -9
                        break
                self.z.cond.wait(0.05 if left is None else min(left, 0.05))
        return self.z.codes[self.pid]

    def send_signal(self, sig: int) -> None:
        if self.returncode is None:
            try:
                os.kill(self.pid, sig)
            except ProcessLookupError:
                pass

    def terminate(self) -> None:
        self.send_signal(signal.SIGTERM)

    def kill(self) -> None:
        self.send_signal(signal.SIGKILL)


def _exists(pid: int) -> bool:
    try:
        os.kill(pid, 0)
        return True
    except ProcessLookupError:
        return False
    except PermissionError:
        return True


class Zygote:
    def __init__(self, env: dict | None = None):
        env = dict(env or os.environ)   # as clean_env takes it: none (or empty) is ours
        # glibc reads MALLOC_ARENA_MAX at start: here, for every EA peer. One arena, not two:
        # Zenoh's threads and the EA then share one heap's free memory instead of each arena
        # keeping its own pages (less PSS per peer, and no slower: a brigade live run)
        env.setdefault("MALLOC_ARENA_MAX", "1")
        env = clean_env(env)
        env.setdefault("OPENBLAS_NUM_THREADS", "1")   # no thread pool to fork under
        env["SAIM_ZYGOTE_PARENT"] = str(os.getpid())   # it dies with us (PR_SET_PDEATHSIG, checked)
        self.p = subprocess.Popen([sys.executable, "-m", "saim_mesh.launch.zygote"], stdin=subprocess.PIPE,
                                  stdout=subprocess.PIPE, env=env)
        if self.p.stdout.readline().strip() != b"ready":
            self.p.kill()
            raise RuntimeError("the zygote did not start")
        self.cond = threading.Condition()
        self.codes: dict[int, int] = {}
        self.pids: dict[int, int] = {}
        self.next_id = 0
        self.lock = threading.Lock()
        threading.Thread(target=self._read, name="zygote-reader", daemon=True).start()

    def alive(self) -> bool:
        return self.p.poll() is None

    def _read(self) -> None:
        for line in self.p.stdout:
            msg = json.loads(line)
            with self.cond:
                if "exit" in msg:
                    self.codes[msg["exit"]] = msg["code"]
                else:
                    self.pids[msg["id"]] = msg["pid"]
                self.cond.notify_all()
        with self.cond:
            self.cond.notify_all()

    def spawn(self, args: list[str], log_path: str, env: dict | None) -> Forked:
        """Fork `saim-mesh ARGS...` (args as given to subprocess: `python -m saim_mesh ...`)."""
        argv = args[3:] if args[1:3] == ["-m", "saim_mesh"] else args
        with self.lock:
            self.next_id += 1
            rid = self.next_id
            self.p.stdin.write((json.dumps({"id": rid, "argv": argv, "log": str(log_path),
                                            "env": dict(env or os.environ)}) + "\n").encode())
            self.p.stdin.flush()
        with self.cond:
            if not self.cond.wait_for(lambda: rid in self.pids or not self.alive(), 30):
                raise RuntimeError("the zygote did not fork")
        if rid not in self.pids:
            raise RuntimeError("the zygote died")
        f = Forked(self, self.pids.pop(rid))
        f.args = list(args)
        return f

    def close(self) -> None:
        if self.alive():
            self.p.stdin.close()
            try:
                self.p.wait(5)
            except subprocess.TimeoutExpired:
                self.p.kill()
                self.p.wait()


_shared: Zygote | None = None
_shared_lock = threading.Lock()


def shared() -> Zygote | None:
    """The launcher's zygote, started on first use (None when SAIM_ZYGOTE=0 or it cannot start)."""
    global _shared
    if os.environ.get("SAIM_ZYGOTE", "1") == "0":
        return None
    with _shared_lock:
        if _shared is None or not _shared.alive():
            _shared = Zygote()
            atexit.register(_shared.close)
        return _shared


def spawner():
    """What `Proc(spawner=...)` takes: the shared zygote's `spawn`, or None (plain subprocesses)."""
    z = shared()
    return z.spawn if z is not None else None


if __name__ == "__main__":
    serve()
