"""The TAK gateway on the live mesh (issue 31.4): no replay, a Zenoh router, one source
for the small scenario, A's and A2's EAs; the gateway (`tak`) draws the picture
from the source's frames, its clock from their watermarks, and sends every alert the EAs
raise as CoT to a TAK server (a TCP receiver built with pytak), with the units and tracks."""
from __future__ import annotations

import json
import sys
import uuid

import pytest

from saim_mesh.launch.proc import Proc, clean_env, py
from saim_mesh.tak import cot as C
from saim_mesh.launch.zenoh_config import free_port

from .conftest import SMALL
from .test_tak_gateway import GROUP, Receivers, every_ea_alert_on_tak

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
        gw = Proc("tak", [sys.executable, "-m", "saim_mesh", "tak", sc, *client,
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
        every_ea_alert_on_tak(rx, [tmp_path / f"{u}.jsonl" for u in units])
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


@pytest.mark.timeout(240)
def test_pli_on_the_live_mesh_reach_an_ea_as_the_tak_source(tmp_path):
    """`tak --live`: an ATAK user's PLI go out as the live source `tak` at the wall
    clock's event time; A2's EA, live on the same clock with `--sources tak`, takes them."""
    import asyncio
    import threading
    from datetime import datetime, timezone

    from .test_tak_gateway import _cfg, pli, pytak
    sc, root = str(SMALL), f"test/{uuid.uuid4().hex[:8]}"
    ep, lport = f"tcp/127.0.0.1:{free_port()}", free_port()
    client = ["--connect", ep, "--mode", "client", "--root", root]
    start = ["--live", "--start", datetime.now(timezone.utc).isoformat()]
    procs: list[Proc] = []
    try:
        procs.append(Proc("router", [*py(), "router", "--scenario", sc, "--name", "hub", "--listen", ep, "--root", root],
                          env=clean_env(), log_dir=tmp_path))
        procs[-1].wait_for("router ready", 60)
        peer = Proc("A2", [*py(), "peer", "--scenario", sc, "--unit", "A2", *client, "--sources", "tak", *start,
                           "--out", str(tmp_path / "A2.jsonl")], env=clean_env(), log_dir=tmp_path)
        procs.append(peer)
        peer.wait_for("ready A2", 60)
        gw = Proc("tak", [sys.executable, "-m", "saim_mesh", "tak", sc, *client, *start,
                          "--cot-url", f"udp://{GROUP}:{free_port()}", "--mcast-if", "127.0.0.1", "--mcast-ttl", "0",
                          "--listen-cot", f"tcp://127.0.0.1:{lport}",
                          "--uid-rule", "regex:^ATAK-(?P<entity>\\w+)$", "--no-overlay", "--linger", "600"],
                  env=clean_env(), log_dir=tmp_path)
        procs.append(gw)
        gw.wait_for("tak ready", 60)

        async def send():
            tx = await pytak.txworker_factory(asyncio.Queue(), _cfg(COT_URL=f"tcp://127.0.0.1:{lport}", TAK_PROTO=0))
            for k in range(5):
                await tx.send_data(pli("ATAK-A2S1E01", -116.9 + k * 1e-4, 35.45, "ALPHA"))
            await tx.writer.drain()
            tx.writer.close()
        threading.Thread(target=lambda: asyncio.run(send()), daemon=True).start()
        # the EA's input journal holds what it took: wait (bounded) for the five reports there
        import time as _t

        from saim_mesh.live import frames as F
        from saim_mesh.live.journal import records

        def taken() -> int:
            try:
                return sum(len(F.decode(r[1], 1 << 20).msgs) for r in records(tmp_path / "A2.input") if r[0] == "frame")
            except FileNotFoundError:
                return 0
        deadline = _t.monotonic() + 60
        while taken() < 5 and _t.monotonic() < deadline:
            _t.sleep(0.2)   # polling the journal file, bounded by the deadline
        gw.stop()   # its stream ends: the EA finishes
        summary = json.loads(peer.wait_for("summary ", 60).split(" ", 1)[1])
        done = gw.wait_for("tak done", 60)
    finally:
        for p in procs:
            p.stop()
    assert "pli=5" in done, done
    assert summary["messages"] == 5 and summary["depends"] == ["tak"] and summary["rejects"] == {}, summary
