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
from saim_mesh.proc import Proc, clean_env, py
from saim_mesh.runner import run
from saim_mesh.zconf import free_port

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
        src = Proc("source", [*py(), "source", SC, "--name", "cp.all", "--tracks", "--speed", "60", "--cache", "20",
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
