"""Bad input the removed replay mesh's attack tests covered, on the live mesh (issue 51.5):
data dated far past the battle's end on a source's own stream, and a goodbye forged by an
insider with a valid certificate. A real EA process on loopback; the faulty source and the
forger are sessions of the test, every child reaped; waits on printed lines, bounded."""
from __future__ import annotations

import json
import os
import signal
import uuid
from dataclasses import replace

import pytest
import zenoh

from dissemination.keyspace import KeySpace
from saim_mesh.protocol import messages as M
from saim_mesh import scenario as S
from saim_mesh.protocol import wire as W
from saim_mesh.live import play
from saim_mesh.live.source import LiveSource
from saim_mesh.launch.proc import Proc, clean_env, py
from saim_mesh.launch.zenoh_config import config, free_port

from .conftest import SMALL
from .test_live import in_process, load, plan_alerts, reap, start_live_peer

SC = str(SMALL)
YEAR_S = 365 * 86400.0


@pytest.fixture(scope="module")
def sc():
    return S.load(SMALL)


@pytest.mark.timeout(200)
def test_far_ahead_data_on_a_sources_stream_is_refused_counted_said_once_and_changes_nothing(tmp_path, sc):
    """A faulty source (in this test's session, as cp.all) slips three location reports dated
    a year past the battle's end into its frames, among the battle's own messages: A2's EA
    refuses each (counted), says it once, and raises exactly the alerts of the clean stream."""
    ep, root = f"tcp/127.0.0.1:{free_port()}", f"test/{uuid.uuid4().hex[:8]}"
    msgs = list(play.share(sc, None, True))
    reports = [i for i, m in enumerate(msgs) if type(m) is M.LocationReport]
    at = {reports[len(reports) * k // 4]: replace(msgs[reports[len(reports) * k // 4]], t=sc.duration_s + YEAR_S * k)
          for k in (1, 2, 3)}
    peer = start_live_peer(tmp_path, "A2", ep, root, ["cp.all"])
    try:
        peer.wait_for("ready A2", 60)
        with zenoh.open(config(["tcp/127.0.0.1:0"], [ep])) as s:
            src = LiveSource(s, KeySpace.of(sc, root), "cp.all", tmp_path / "state")

            def stream():
                for i, m in enumerate(msgs):
                    if i in at:
                        src.put(at[i])   # not after its watermark: the source's own check lets it by
                    yield m
            assert play.publish(src, stream(), log=lambda *a, **k: None) == len(msgs)
            src.close()
            line = peer.wait_for("summary ", 150)   # the session (its cache) stays for the EA to finish
            src.stop()
    finally:
        reap([peer])
    summary = json.loads(line.split(" ", 1)[1])
    assert sum(summary["rejects"].values()) == 3 and len(summary["rejects"]) == 1, summary
    assert summary["lost"] == {} and summary["messages"] == len(msgs), summary
    said = [x for x in peer.lines if "after the scenario's end" in x]
    assert len(said) == 1 and said[0].startswith("reject "), said
    want = plan_alerts(in_process(sc, "A2", {"cp.all": msgs}))
    assert len(want) >= 5 and plan_alerts(load(tmp_path / "A2.jsonl")) == want


def insider(pki, name: str, connect: str):
    """A session over mutual TLS with `name`'s valid certificate and none of the mesh's
    access-control rules of its own: an insider's modified process."""
    from saim_mesh.security.acl import tls_config
    conf = config(["tls/127.0.0.1:0"], [connect])
    link = tls_config(pki, name)
    conf.insert_json5("transport/link/protocols", json.dumps(link["protocols"]))
    for k, v in link["tls"].items():
        conf.insert_json5(f"transport/link/tls/{k}", json.dumps(v))
    return conf


@pytest.mark.timeout(200)
def test_a_bye_forged_with_another_eas_certificate_is_dropped_and_the_loss_is_still_said(tmp_path, sc):
    """Secure mode: ea.C (a valid certificate) puts a goodbye on bye/A2 (only ea.A2 may);
    access control drops it, so when A2's EA then dies without one (SIGKILL), A, its
    superior, still says A2 left the mesh without a goodbye. (Taken, the forged goodbye
    would have made that loss a clean end: nothing said.)"""
    from saim_mesh.security import endpoint_tls, make_pki, names_for
    pki = tmp_path / "pki"
    make_pki(pki, names_for(sc))
    ep, root = endpoint_tls(free_port()), f"test/{uuid.uuid4().hex[:8]}"
    sec = ["--pki", str(pki)]

    def peer(unit: str, *where: str) -> Proc:
        return Proc(f"peer-{unit}", [*py(), "peer", "--scenario", SC, "--unit", unit, *where, "--root", root,
                                     "--sources", "cp.BN", "--out", str(tmp_path / f"{unit}.jsonl"), *sec],
                    env=clean_env(), log_dir=tmp_path)
    procs = [peer("A", "--listen", ep)]
    try:
        procs[0].wait_for("ready A", 60)
        procs.append(peer("A2", "--connect", ep, "--listen", "tls/127.0.0.1:0"))
        procs[1].wait_for("ready A2", 60)
        with zenoh.open(insider(pki, "ea.C", ep)) as s:
            ks = KeySpace.of(sc, root)
            s.put(ks.bye("A2"), W.encode(W.make(W.Bye, unit="A2")))
            # A answers a late joiner's question after what came before it on this link: the
            # goodbye, had A taken it, was taken before this answer ends
            list(s.get(f"{root}/dirj/A", timeout=10.0))
        os.kill(procs[1].pid, signal.SIGKILL)
        procs[1].p.wait(10)
        left = procs[0].wait_for("system A2: ", 60)
    finally:
        reap(procs)
    assert "left the mesh without a goodbye" in left, left
    system = [a for a in load(tmp_path / "A.jsonl") if a["category"] == "system-problem" and a["subjects"] == ["A2"]]
    assert [a["details"].get("event") for a in system] == ["peer-lost"], system
