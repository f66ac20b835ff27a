"""A live peer killed with SIGKILL and started again stands where it stood (issue 32.6,
"an alert once due is never lost and never raised twice"): it replays its own input
journal first (the alerts its log holds are not given again), then takes what its
source sent while it was down (the source's cache is small: most of it from the
source's durable journal), marking what fell due meanwhile late. Its final log equals
the in-process run's alerts, each once."""
from __future__ import annotations

import json
import os
import signal
import time
import uuid
from collections import Counter

import pytest

from saim_mesh import scenario as S
from saim_mesh.launch.proc import Proc, clean_env, py
from saim_mesh.inprocess.runner import run
from saim_mesh.launch.zenoh_config import free_port

from .conftest import SMALL
from .test_live import load, plan_alerts, reap

pytestmark = pytest.mark.timeout(300)
SC = str(SMALL)


def peer(tmp, ep: str, root: str, n: int) -> Proc:
    return Proc(f"peer-A{n}", [*py(), "peer", "--scenario", SC, "--unit", "A", "--connect", ep, "--mode", "client",
                               "--root", root, "--sources", "cp.all", "--out", str(tmp / "A.jsonl")],
                env=clean_env(), log_dir=tmp)


def lines(path) -> int:
    try:
        return sum(1 for x in open(path) if x.endswith("\n"))
    except FileNotFoundError:
        return 0


def test_a_peer_killed_and_restarted_raises_each_alert_once_and_what_fell_due_late(tmp_path):
    sc = S.load(SMALL)
    want = plan_alerts(next(ea for ea in run(sc, ["A"]) if ea.owner == "A").alerts)
    assert len(want) >= 6
    ep, root = f"tcp/127.0.0.1:{free_port()}", f"test/{uuid.uuid4().hex[:8]}"
    router = Proc("router", [*py(), "router", "--scenario", SC, "--name", "hub", "--listen", ep, "--root", root],
                  env=clean_env(), log_dir=tmp_path)
    procs = [router]
    try:
        router.wait_for("router ready", 60)
        first = peer(tmp_path, ep, root, 1)
        procs.append(first)
        first.wait_for("ready A", 60)
        src = Proc("source", [*py(), "source", SC, "--name", "cp.all", "--tracks", "--speed", "150", "--cache", "20",
                              "--state", str(tmp_path / "state"), "--linger", "120", "--connect", ep, "--mode",
                              "client", "--root", root], env=clean_env(), log_dir=tmp_path)
        procs.append(src)
        end = time.monotonic() + 120
        while lines(tmp_path / "A.jsonl") < 3 and time.monotonic() < end:   # a few alerts told
            first.poll_lines()
            time.sleep(0.05)
        assert lines(tmp_path / "A.jsonl") >= 3, first.tail()
        os.kill(first.p.pid, signal.SIGKILL)   # the host dies: no goodbye, no flush beyond what was written
        first.p.wait(10)
        before = lines(tmp_path / "A.jsonl")
        # stay down until an alert falls due: the source's clock passes the next one the EA owes
        told = plan_alerts(load(tmp_path / "A.jsonl"))
        owed = [w for w in want if w not in told]
        assert owed, "the EA told everything before it was killed: kill it earlier"
        due = 600 * (int(owed[0][0]) // 600 + 1)   # the source says its clock every 600 s of event time
        if due < sc.duration_s:
            src.wait_for(f"source cp.all t={due} ", 120)
        again = peer(tmp_path, ep, root, 2)
        procs.append(again)
        restart = again.wait_for("restart: ", 60)
        summary = json.loads(again.wait_for("summary ", 240).split(" ", 1)[1])
    finally:
        reap(procs)
    assert "input records replayed" in restart and summary["restored"] > 0, restart
    logged = load(tmp_path / "A.jsonl")
    got = plan_alerts(logged)
    assert Counter(got) == Counter(want) and len(got) == len(want), "each alert once, none lost"
    assert sorted(got) == sorted(want)
    late = [a for a in logged[before:] if a["details"].get("late")]
    told_after = [a for a in logged[before:] if a["category"] != "system-problem"]
    assert told_after and late, "what fell due while the peer was down is raised after the restart, marked late"
    assert summary["fetched"] > 0 or summary["frames"] > 0


def test_a_superior_says_when_a_subordinates_ea_dies_and_comes_back_and_not_when_it_ends(tmp_path):
    ep, root = f"tcp/127.0.0.1:{free_port()}", f"test/{uuid.uuid4().hex[:8]}"
    router = Proc("router", [*py(), "router", "--scenario", SC, "--name", "hub", "--listen", ep, "--root", root],
                  env=clean_env(), log_dir=tmp_path)
    procs = [router]

    def start(unit: str, n: int) -> Proc:
        p = Proc(f"peer-{unit}-{n}", [*py(), "peer", "--scenario", SC, "--unit", unit, "--connect", ep, "--mode",
                                      "client", "--root", root, "--sources", "cp.all", "--out",
                                      str(tmp_path / f"{unit}.jsonl")], env=clean_env(), log_dir=tmp_path)
        procs.append(p)
        p.wait_for(f"ready {unit}", 60)
        return p
    try:
        router.wait_for("router ready", 60)
        a = start("A", 1)
        a1 = start("A1", 1)
        procs.append(Proc("source", [*py(), "source", SC, "--name", "cp.all", "--tracks", "--speed", "150", "--state",
                                     str(tmp_path / "state"), "--linger", "120", "--connect", ep, "--mode", "client",
                                     "--root", root], env=clean_env(), log_dir=tmp_path))
        end = time.monotonic() + 120
        while lines(tmp_path / "A1.jsonl") < 1 and time.monotonic() < end:
            time.sleep(0.05)
        os.kill(a1.p.pid, signal.SIGKILL)
        a1.p.wait(10)
        left = a.wait_for("system A1: ", 60)
        start("A1", 2)
        summary = json.loads(a.wait_for("summary ", 240).split(" ", 1)[1])
    finally:
        reap(procs)
    assert "left the mesh without a goodbye" in left, left
    events = Counter(x["details"].get("event") for x in load(tmp_path / "A.jsonl")
                     if x["category"] == "system-problem" and x["subjects"] == ["A1"])
    assert events == Counter({"peer-lost": 1, "peer-back": 1}), events   # A1's clean end: no alarm
    assert summary["lost"] == {}


def test_a_source_killed_and_restarted_resumes_after_what_it_published(tmp_path):
    """The source (a command post's share of the battle) dies with SIGKILL and starts again
    on the same state folder: a new epoch that resumes after the messages the old one
    published (none twice, none skipped), so the EA's alerts equal the in-process run's."""
    sc = S.load(SMALL)
    want = plan_alerts(next(ea for ea in run(sc, ["A"]) if ea.owner == "A").alerts)
    ep, root = f"tcp/127.0.0.1:{free_port()}", f"test/{uuid.uuid4().hex[:8]}"
    router = Proc("router", [*py(), "router", "--scenario", SC, "--name", "hub", "--listen", ep, "--root", root],
                  env=clean_env(), log_dir=tmp_path)
    procs = [router]

    def source(n: int) -> Proc:
        p = Proc(f"source-{n}", [*py(), "source", SC, "--name", "cp.all", "--tracks", "--speed", "150", "--state",
                                 str(tmp_path / "state"), "--linger", "120", "--connect", ep, "--mode", "client",
                                 "--root", root], env=clean_env(), log_dir=tmp_path)
        procs.append(p)
        return p
    try:
        router.wait_for("router ready", 60)
        a = peer(tmp_path, ep, root, 1)
        procs.append(a)
        a.wait_for("ready A", 60)
        first = source(1)
        end = time.monotonic() + 120
        while lines(tmp_path / "A.jsonl") < 2 and time.monotonic() < end:
            time.sleep(0.05)
        os.kill(first.p.pid, signal.SIGKILL)
        first.p.wait(10)
        resumed = source(2).wait_for("source cp.all: resumed after the ", 60)
        summary = json.loads(a.wait_for("summary ", 240).split(" ", 1)[1])
    finally:
        reap(procs)
    assert "epoch 1 published" in resumed, resumed
    assert plan_alerts(load(tmp_path / "A.jsonl")) == want
    assert summary["lost"] == {} and summary["late_alerts"] == 0, summary
