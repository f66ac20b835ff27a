"""The live mesh by key group (issue 50), real processes on loopback: sources publish each
flush as per-group frames and a progress frame; several EA peers (`saim-mesh peer`) assemble
the flushes of the groups they hear and raise exactly the in-process run's alerts; the
input journal replays to them."""
from __future__ import annotations

import json
import sys
import uuid

import pytest

from saim_mesh import scenario as S
from saim_mesh.live import play
from saim_mesh.live.journal import replay
from saim_mesh.live.peer import LivePeer
from saim_mesh.proc import Proc, clean_env
from saim_mesh.zconf import config, free_port

from .conftest import SMALL
from .test_live import in_process, load, plan_alerts, reap, start_live_peer

pytestmark = pytest.mark.timeout(420)
SC = str(SMALL)


@pytest.fixture(scope="module")
def sc():
    return S.load(SMALL)


def start_group_source(tmp, name: str, root: str, *args: str) -> Proc:
    return Proc(f"source-{name}", [sys.executable, "-m", "saim_mesh.live.groupsource", SC, "--name", name,
                                   "--root", root, "--linger", "600", *args],
                env=clean_env(), log_dir=tmp)


def test_peers_on_key_groups_raise_the_in_process_alerts(tmp_path, sc):
    root = f"test/{uuid.uuid4().hex[:8]}"
    units = ["A2", "C"]
    names = ["cp.A", "cp.rest"]
    eps = [f"tcp/127.0.0.1:{free_port()}" for _ in units]   # each peer listens; the sources connect to all
    procs = []
    try:
        for u, ep in zip(units, eps):
            procs.append(start_live_peer(tmp_path, u, ep, root, names))
            procs[-1].wait_for(f"ready {u}", 60)
        conn = [x for ep in eps for x in ("--connect", ep)]
        procs.append(start_group_source(tmp_path, "cp.A", root, *conn, "--units", "A", "--state", str(tmp_path / "s")))
        procs.append(start_group_source(tmp_path, "cp.rest", root, *conn, "--but", "A", "--tracks",
                                        "--state", str(tmp_path / "s")))
        for p, n in zip(procs[len(units):], names):
            line = p.wait_for(f"end source {n}", 180)
            assert int(line.rsplit("groups=", 1)[1]) > 1   # published on several groups
        lines = [p.wait_for("summary ", 240) for p in procs[:len(units)]]
    finally:
        reap(procs)
    streams = {"cp.A": list(play.share(sc, ["A"], False)), "cp.rest": list(play.share(sc, None, True, ["A"]))}
    for u, line in zip(units, lines):
        summary = json.loads(line.split(" ", 1)[1])
        assert summary["lost"] == {} and summary["rejects"] == {} and summary["gaps"] == 0, summary
        offered = sum(len(streams[n]) for n in summary["depends"])
        assert summary["messages"] < 0.9 * offered, (u, summary["messages"], offered)   # only its interest's groups
        got = plan_alerts(load(tmp_path / f"{u}.jsonl"))
        want = plan_alerts(in_process(sc, u, streams))
        assert len(want) >= 3 and got == want, u
        peer = LivePeer(sc, u, config(["tcp/127.0.0.1:0"], None), root, names)
        assert plan_alerts(replay(peer, tmp_path / f"{u}.input")) == got, u
