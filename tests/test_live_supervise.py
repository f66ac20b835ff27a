"""`mesh up --restarts N` on the live mesh (issue 49.6): each process that dies is
restarted up to N times, then given up with one line naming it, and the rest of the
mesh goes on without it. The supervisor's rule on fake children, then one live mesh
whose EA peer is killed twice under `--restarts 1`. Loopback, bounded, reaped."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import time

import pytest

from saim_mesh.launch.supervise import Supervisor
from saim_mesh.launch.proc import clean_env, py, wait_line

from .conftest import SMALL


class Child:
    """A stand-in for a `Proc`: runs until `die(code)`; `start()` is a restart."""

    def __init__(self, name: str, pid: int):
        self.name, self.pid, self.starts, self.code, self.said = name, pid, 1, None, []

    def exited(self):
        return self.code

    def die(self, code: int = -9) -> None:
        self.code = code

    def start(self) -> None:
        self.starts, self.code, self.pid = self.starts + 1, None, self.pid + 1

    def tail(self, n: int = 8):
        return [f"{self.name} was here"]

    def find(self, prefix: str):
        return next((x for x in self.said if x.startswith(prefix)), None)


def supervised(tmp_path, n: int, *names):
    said: list[str] = []
    sup = Supervisor(said.append, n, backoff_s=0.0, pids_path=tmp_path / "pids.json")
    kids = [sup.add(Child(x, 100 * (i + 1))) for i, x in enumerate(names)]
    return sup, said, kids


def test_a_child_is_restarted_n_times_then_given_up_in_one_line_and_the_others_go_on(tmp_path):
    sup, said, (a2, a) = supervised(tmp_path, 2, "A2", "A")
    for restart in (1, 2):
        a2.die()
        sup.check()   # reported, restart due (no backoff here)
        sup.check()   # restarted
        assert a2.exited() is None and a2.starts == restart + 1
        assert said[-1] == f"supervisor: restarted A2 (restart {restart})"
        assert json.loads((tmp_path / "pids.json").read_text())["A2"] == a2.pid
    a2.die()
    sup.check()
    sup.check()
    assert a2.exited() == -9 and a2.starts == 3, "not restarted a third time"
    gave = [x for x in said if "gave up" in x]
    assert gave == ["supervisor: gave up on A2: died 3 times, restarted 2 (--restarts 2); the rest of the mesh "
                    "goes on without it"]
    assert sup.given_up == {"A2"} and json.loads((tmp_path / "given_up.json").read_text()) == {"A2": 3}
    assert [e for e in sup.events if e.get("given_up")] == [{"process": "A2", "exit_code": -9, "start": 3,
                                                               "last_lines": ["A2 was here"], "given_up": True}]
    a.die(1)   # the others keep their own N
    sup.check()
    sup.check()
    assert a.exited() is None and a.starts == 2 and sup.given_up == {"A2"}
    assert sum(1 for e in sup.events if "restarted" in e) == 3


def test_restarts_0_gives_up_at_the_first_death_and_an_end_is_no_death(tmp_path):
    sup, said, (src, peer) = supervised(tmp_path, 0, "cp.A", "A")
    peer.said.append("summary {}")
    peer.die(0)   # said its summary and ended: finished, not dead
    src.die(1)
    sup.check()
    sup.check()
    assert src.starts == 1 and peer.starts == 1 and sup.given_up == {"cp.A"}
    assert [x for x in said if x.startswith("supervisor: gave up")] == [
        "supervisor: gave up on cp.A: died 1 time, restarted 0 (--restarts 0); the rest of the mesh goes on "
        "without it"]
    assert not any(x.startswith("supervisor: A ") for x in said), said


# the live mesh: a router, six command-post sources, two EA peers on 127.0.0.1

def pids(out) -> dict:
    return json.loads((out / "pids.json").read_text())


def until(what, timeout: float, why: str):
    """Poll `what()` until it is true (returned) or `timeout` passes (AssertionError)."""
    end = time.monotonic() + timeout
    while not (got := what()):
        if time.monotonic() > end:
            raise AssertionError(f"within {timeout} s: {why}")
        time.sleep(0.05)
    return got


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    return True


def count(path, prefix: str) -> int:
    try:
        return sum(1 for x in path.read_text(errors="replace").splitlines() if x.startswith(prefix))
    except FileNotFoundError:
        return 0


@pytest.mark.timeout(300)
def test_live_mesh_up_restarts_a_killed_peer_once_then_gives_up_on_it_and_goes_on(tmp_path):
    out, log = tmp_path / "mesh", tmp_path / "mesh.log"
    with open(log, "wb") as f:   # its own process group: every child is reaped below, whatever happens
        mesh = subprocess.Popen([*py(), "mesh", "up", str(SMALL), "--units", "A", "A2", "--speed", "100",
                                 "--restarts", "1", "--insecure", "--out-dir", str(out)],
                                stdout=f, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, env=clean_env(),
                                start_new_session=True)
    seen: set[int] = set()
    try:
        wait_line(log, mesh, "host local: sources ", 180)
        until(lambda: count(out / "A2.jsonl", "{"), 120, "A2 raised no alert")   # it has a journal to restore
        first = pids(out)["A2"]
        seen |= set(pids(out).values())
        os.kill(first, signal.SIGKILL)
        wait_line(log, mesh, "supervisor: restarted A2 (restart 1)", 60)
        second = until(lambda: pids(out)["A2"] != first and pids(out)["A2"], 30, "A2's new pid in pids.json")
        seen.add(second)
        until(lambda: count(out / "logs" / "A2.log", "ready A2") == 2, 60, "the restarted A2 is not ready")
        restored = wait_line(out / "logs" / "A2.log", mesh, "restart: ", 5)
        os.kill(second, signal.SIGKILL)
        gave = wait_line(log, mesh, "supervisor: gave up on ", 60)
        other = pids(out)["A"]
        assert alive(other), "the other EA died with A2"
        assert json.loads((out / "given_up.json").read_text()) == {"A2": 2}
        done = wait_line(log, mesh, "host local: 1 of 2 EA peers done", 200)
        rc = mesh.wait(60)
    finally:
        print("mesh up said:", log.read_text(errors="replace")[-4000:])   # shown when the test fails
        seen |= set(pids(out).values()) if (out / "pids.json").exists() else set()
        if mesh.poll() is None:
            os.killpg(mesh.pid, signal.SIGTERM)   # the launcher stops its children
            try:
                mesh.wait(30)
            except subprocess.TimeoutExpired:
                pass
        try:
            os.killpg(mesh.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        mesh.wait(10)
        for pid in seen:   # zygote-forked peers have their own group (they die with the zygote anyway)
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
    said = log.read_text().splitlines()
    assert "input records replayed" in restored, restored
    assert gave == ("supervisor: gave up on A2: died 2 times, restarted 1 (--restarts 1); the rest of the mesh "
                    "goes on without it"), gave
    assert sum(1 for x in said if x.startswith("supervisor: restarted A2")) == 1
    assert done.endswith("(given up: A2)") and rc == 1, (done, rc)   # a peer short: not a clean run
    summary = json.loads((out / "summary.json").read_text())
    assert summary["given_up"] == ["A2"] and sorted(summary["peers"]) == ["A"], summary["given_up"]
    assert summary["peers"]["A"]["alerts"] > 0
    assert [e["process"] for e in summary["events"] if "exit_code" in e] == ["A2", "A2"]
    assert any("gave up on A2 (--restarts 1)" in x for x in said[-3:]), said[-3:]
