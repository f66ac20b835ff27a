"""What only the removed replay mesh's tests covered, on the live mesh (issue 51.5): two EAs of
one unit on the same sources, and a frozen EA noticed by its superior (a peer's --deadline:
tests/test_peer_deadline.py). Real processes on loopback, free ports, every child reaped; waits
on printed lines and files, bounded by pytest-timeout.

One mesh (a router, one source, the EAs of A, A1 and twice B1) serves the tests that only
read what it did: each mesh costs a minute of this machine."""
from __future__ import annotations

import json
import os
import signal
import time
import uuid
from collections import Counter

import pytest

from saim_mesh.launch.proc import Proc, clean_env, py
from saim_mesh.launch.zenoh_config import free_port

from .conftest import SMALL
from .test_live import load, reap

SC = str(SMALL)


def lines(path) -> int:
    try:
        return sum(1 for x in open(path) if x.endswith("\n"))
    except FileNotFoundError:
        return 0


@pytest.fixture(scope="module")
def mesh(tmp_path_factory):
    """A router, the EAs of A, A1 and two of B1 (its own two EAs, as a hot standby), then
    cp.all (the small battle, at 100x). Once A1 told an alert it is frozen (SIGSTOP) until A
    says it left, then thawed (SIGCONT) until A says it is back; every EA runs to its end."""
    tmp = tmp_path_factory.mktemp("coverage-mesh")
    ep, root = f"tcp/127.0.0.1:{free_port()}", f"test/{uuid.uuid4().hex[:8]}"
    procs: list[Proc] = []
    said: dict[str, str] = {}
    summaries: dict[str, dict] = {}

    def peer(name: str, unit: str) -> Proc:
        p = Proc(f"peer-{name}", [*py(), "peer", "--scenario", SC, "--unit", unit, "--connect", ep, "--mode",
                                  "client", "--root", root, "--sources", "cp.all", "--out",
                                  str(tmp / f"{name}.jsonl")], env=clean_env(), log_dir=tmp)
        procs.append(p)
        return p
    try:
        router = Proc("router", [*py(), "router", "--scenario", SC, "--name", "hub", "--listen", ep, "--root", root],
                      env=clean_env(), log_dir=tmp)
        procs.append(router)
        router.wait_for("router ready", 60)
        eas = {"A": peer("A", "A"), "A1": peer("A1", "A1"), "B1a": peer("B1a", "B1"), "B1b": peer("B1b", "B1")}
        for name, p in eas.items():
            p.wait_for(f"ready {name[:2] if name.startswith('B1') else name}", 60)
        procs.append(Proc("source", [*py(), "source", SC, "--name", "cp.all", "--tracks", "--speed", "100", "--state",
                                     str(tmp / "state"), "--linger", "120", "--connect", ep, "--mode", "client",
                                     "--root", root], env=clean_env(), log_dir=tmp))
        end = time.monotonic() + 120
        while lines(tmp / "A1.jsonl") < 1 and time.monotonic() < end:   # A1 under way
            time.sleep(0.05)
        assert lines(tmp / "A1.jsonl") >= 1, eas["A1"].tail()
        os.kill(eas["A1"].pid, signal.SIGSTOP)
        try:
            said["left"] = eas["A"].wait_for("system A1: ", 60)
        finally:
            os.kill(eas["A1"].pid, signal.SIGCONT)
        n = len(eas["A"].lines)
        said["back"] = _next(eas["A"], "system A1: ", n, 60)
        for name, p in eas.items():
            summaries[name] = json.loads(p.wait_for("summary ", 300).split(" ", 1)[1])
    finally:
        reap(procs)
    return {"dir": tmp, "said": said, "summary": summaries}


def _next(p: Proc, prefix: str, after: int, timeout: float) -> str:
    """The first line starting with `prefix` among those `p` says after its first `after` lines."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        p.poll_lines()
        got = next((x for x in p.lines[after:] if x.startswith(prefix)), None)
        if got is not None:
            return got
        if p.exited() is not None:
            p.poll_lines()
            break
        time.sleep(0.01)
    got = next((x for x in p.lines[after:] if x.startswith(prefix)), None)
    if got is None:
        raise AssertionError(f"{p.name}: no second '{prefix}' within {timeout} s: {p.tail()}")
    return got


@pytest.mark.timeout(600)
def test_two_peers_of_one_unit_on_the_same_sources_raise_identical_alerts(mesh):
    """Determinism on the mesh: two EAs of B1, the same sources, the same alerts (ids and
    content), each in the same order."""
    a, b = load(mesh["dir"] / "B1a.jsonl"), load(mesh["dir"] / "B1b.jsonl")
    assert len(a) >= 3, a
    assert [x["details"].get("id") for x in a] == [x["details"].get("id") for x in b]
    assert a == b
    sa, sb = mesh["summary"]["B1a"], mesh["summary"]["B1b"]
    assert sa["lost"] == sb["lost"] == {} and sa["messages"] == sb["messages"] > 0


@pytest.mark.timeout(600)
def test_a_frozen_peer_is_noticed_by_its_superiors_lease_and_noted_when_it_thaws(mesh):
    """A1's EA frozen (SIGSTOP: its host hangs, its socket stays open): once its liveliness
    lease runs out, A (its superior) raises one system problem naming A1; thawed (SIGCONT),
    A notes it is back; A1's clean end at the finish raises nothing."""
    assert "left the mesh without a goodbye" in mesh["said"]["left"], mesh["said"]
    assert "back" in mesh["said"]["back"].lower(), mesh["said"]
    events = Counter(x["details"].get("event") for x in load(mesh["dir"] / "A.jsonl")
                     if x["category"] == "system-problem" and x["subjects"] == ["A1"])
    assert events == Counter({"peer-lost": 1, "peer-back": 1}), events
    assert mesh["summary"]["A"]["lost"] == {}
