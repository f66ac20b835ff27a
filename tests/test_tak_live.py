"""The TAK gateway on the live mesh (issue 31.4): no replay, a Zenoh router, one source
for the small scenario, A's and A2's EAs; the gateway (`tak --sources`) draws the picture
from the source's frames, its clock from their watermarks, and sends every alert the EAs
raise as CoT to a TAK server (a TCP receiver built with pytak), with the units and tracks."""
from __future__ import annotations

import json
import sys
import uuid

import pytest

from saim_mesh.proc import Proc, clean_env, py
from saim_mesh.tak import cot as C
from saim_mesh.zconf import free_port

from .conftest import SMALL
from .test_tak_gateway import GROUP, Receivers, cot_alert, ea_alert

pytestmark = pytest.mark.timeout(300)


def test_live_mesh_alerts_arrive_as_cot(tmp_path):
    sc, root = str(SMALL), f"test/{uuid.uuid4().hex[:8]}"
    ep = f"tcp/127.0.0.1:{free_port()}"
    tport = free_port()
    rx = Receivers(tport, GROUP, free_port())
    client = ["--connect", ep, "--mode", "client", "--root", root]
    units = ["A", "A2"]
    procs: list[Proc] = []
    try:
        procs.append(Proc("router", [*py(), "router", "--scenario", sc, "--name", "hub", "--listen", ep, "--root", root],
                          env=clean_env(), log_dir=tmp_path))
        procs[-1].wait_for("router ready", 60)
        gw = Proc("tak", [sys.executable, "-m", "saim_mesh", "tak", sc, *client, "--sources",
                          "--epoch", "2026-05-01T06:00:00Z", "--cot-url", f"tcp://127.0.0.1:{tport}",
                          "--period", "60", "--linger", "120"], env=clean_env(), log_dir=tmp_path)
        procs.append(gw)
        gw.wait_for("tak ready", 60)
        for u in units:
            procs.append(Proc(u, [*py(), "peer", "--scenario", sc, "--unit", u, *client, "--sources", "cp.all",
                                  "--out", str(tmp_path / f"{u}.jsonl")], env=clean_env(), log_dir=tmp_path))
            procs[-1].wait_for(f"ready {u}", 60)
        procs.append(Proc("source", [*py(), "source", sc, "--name", "cp.all", "--tracks", *client, "--speed", "max",
                                     "--linger", "30"], env=clean_env(), log_dir=tmp_path))
        for p in procs[2:4]:   # the EAs finish after the source has ended: the gateway lingers for them
            p.wait_for("summary ", 200)
        want = sorted((ea_alert(json.loads(x)) for u in units for x in open(tmp_path / f"{u}.jsonl")
                       if json.loads(x)["category"] != "system-problem"), key=json.dumps)
        assert len(want) >= 5

        def alerts():
            return sorted((a for s, d in rx.got if s == "tcp" for a in [cot_alert(d)] if a is not None
                           and a["id"] and "/w" not in a["id"]), key=json.dumps)
        assert rx.wait(lambda g: len(alerts()) >= len(want), 30), (len(alerts()), len(want))
        assert alerts() == want
        kinds = {C.parse(d).detail.get("__saim", {}).get("kind") for _, d in rx.got}
        assert {"unit", "track", "alert"} <= kinds
        gw.stop()   # SIGTERM: it says what it did
        done = gw.wait_for("tak done", 60)
        assert "rejects=0" in done, done
    finally:
        for p in procs:
            p.stop()
        rx.close()
    assert all(p.p.poll() is not None for p in procs)
