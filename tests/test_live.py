"""The live mesh with no centre (issue 31): EA peers with no replay, advancing on the event
time their sources promise. Real processes on loopback, free ports, every child reaped;
waits on printed lines and files, bounded by pytest-timeout.

- one `saim-mesh source` publishing the small scenario's events, one peer (`peer --sources`):
  the peer raises exactly the alerts of an in-process EA fed the same messages;
- two sources (a command post's subtree and the rest): the peer applies facts in
  (event time, source, seq) order: the alerts of an in-process EA fed that merge;
- a source that dies is declared lost within `source_silence_s` (one system-problem alert
  naming it) and monitoring goes on with the other; replaying the EA's input journal gives
  exactly the live run's alerts.
"""
from __future__ import annotations

import json
import subprocess
import uuid

import pytest

from saim_mesh import scenario as S
from saim_mesh.live import play
from saim_mesh.live.journal import replay
from saim_mesh.live.peer import LivePeer
from saim_mesh.launch.proc import Proc, clean_env, py
from saim_mesh.inprocess.runner import config_for, make_ea
from saim_mesh.launch.zenoh_config import config, free_port

from .conftest import SMALL

pytestmark = pytest.mark.timeout(300)
SC = str(SMALL)


@pytest.fixture(scope="module")
def sc():
    return S.load(SMALL)


def plan_alerts(alerts) -> list[tuple]:
    """What alerts say (the plan's, not system problems), comparable across runs."""
    out = []
    for a in alerts:
        d = a if isinstance(a, dict) else a.to_json_dict()
        if d["category"] != "system-problem":
            out.append((d["t"], d["type"], tuple(d["subjects"]), d["message"], d["priority"], d["details"].get("id")))
    return out


def load(path) -> list[dict]:
    return [json.loads(x) for x in open(path) if x.strip()]


def in_process(sc, unit: str, streams: dict[str, list]) -> list:
    """An EA fed the sources' messages merged in (event time, source) order, each source in
    its own order: what a live peer must raise."""
    merged = sorted(((m.t, name, i, m) for name, ms in streams.items() for i, m in enumerate(ms)),
                    key=lambda x: x[:3])
    ea = make_ea(sc, unit, config_for(sc, unit))
    ea.start(0.0)
    for *_, m in merged:
        ea.submit(m)
    ea.finish(sc.duration_s)
    return ea.alerts


def start_source(tmp, name: str, ep: str, root: str, *args: str) -> Proc:
    return Proc(f"source-{name}", [*py(), "source", SC, "--name", name, "--connect", ep, "--root", root,
                                   "--linger", "600", *args], env=clean_env(), log_dir=tmp)


def start_live_peer(tmp, unit: str, ep: str, root: str, sources: list[str]) -> Proc:
    return Proc(f"peer-{unit}", [*py(), "peer", "--scenario", SC, "--unit", unit, "--listen", ep, "--root", root,
                                 "--sources", *sources, "--out", str(tmp / f"{unit}.jsonl")],
                env=clean_env(), log_dir=tmp)


def reap(procs) -> None:
    for p in procs:
        p.stop()
    assert all(p.p.poll() is not None for p in procs)


def test_a_peer_on_one_source_raises_what_its_plan_implies(tmp_path, sc):
    ep, root = f"tcp/127.0.0.1:{free_port()}", f"test/{uuid.uuid4().hex[:8]}"
    procs = []
    try:
        procs.append(start_live_peer(tmp_path, "A2", ep, root, ["cp.all"]))
        procs[0].wait_for("ready A2", 60)
        procs.append(start_source(tmp_path, "cp.all", ep, root, "--tracks", "--speed", "max"))
        procs[1].wait_for("end source cp.all", 120)
        line = procs[0].wait_for("summary ", 120)
    finally:
        reap(procs)
    summary = json.loads(line.split(" ", 1)[1])
    assert summary["lost"] == {} and summary["misses"] == 0 and summary["rejects"] == {}, summary
    want = plan_alerts(in_process(sc, "A2", {"cp.all": list(play.share(sc, None, True))}))
    got = plan_alerts(load(tmp_path / "A2.jsonl"))
    assert len(want) >= 5 and got == want


def test_two_sources_merge_in_event_time_order(tmp_path, sc):
    """cp.A publishes A's subtree, cp.rest the rest and the tracks: A2's EA applies them in
    (event time, source) order whatever their interleaving on the wire, and its input
    journal replays to the same alerts."""
    ep, root = f"tcp/127.0.0.1:{free_port()}", f"test/{uuid.uuid4().hex[:8]}"
    procs = []
    try:
        procs.append(start_live_peer(tmp_path, "A2", ep, root, ["cp.A", "cp.rest"]))
        procs[0].wait_for("ready A2", 60)
        procs.append(start_source(tmp_path, "cp.A", ep, root, "--units", "A", "--speed", "max"))
        procs.append(start_source(tmp_path, "cp.rest", ep, root, "--but", "A", "--tracks", "--speed", "max"))
        procs[1].wait_for("end source cp.A", 120)
        procs[2].wait_for("end source cp.rest", 120)
        line = procs[0].wait_for("summary ", 120)
    finally:
        reap(procs)
    summary = json.loads(line.split(" ", 1)[1])
    assert summary["lost"] == {}, summary
    streams = {"cp.A": list(play.share(sc, ["A"], False)), "cp.rest": list(play.share(sc, None, True, ["A"]))}
    assert streams["cp.A"] and streams["cp.rest"]
    got = plan_alerts(load(tmp_path / "A2.jsonl"))
    assert got == plan_alerts(in_process(sc, "A2", streams))
    # the EA's input journal replays to the same alerts
    peer = LivePeer(sc, "A2", config(["tcp/127.0.0.1:0"], None), root, ["cp.A", "cp.rest"])
    assert plan_alerts(replay(peer, tmp_path / "A2.input")) == got


def test_a_source_that_dies_is_declared_lost_and_monitoring_goes_on(tmp_path, sc):
    """cp.rest is killed (SIGKILL: no end-of-stream) after 1,200 s of its battle: A2's EA
    declares it lost within `source_silence_s` (one system-problem alert naming it and what
    is degraded), goes on with cp.A to the end, and its input journal, which holds that
    decision, replays to exactly the live run's alerts."""
    ep, root = f"tcp/127.0.0.1:{free_port()}", f"test/{uuid.uuid4().hex[:8]}"
    cfg = tmp_path / "ea.toml"
    cfg.write_text("[mesh]\nsource_silence_s = 5.0\nsource_end_wait_s = 3.0\n")   # it does not come back
    procs = []
    try:
        procs.append(Proc("peer-A2", [*py(), "peer", "--scenario", SC, "--unit", "A2", "--listen", ep, "--root",
                                      root, "--sources", "cp.A", "cp.rest", "--out", str(tmp_path / "A2.jsonl"),
                                      "--config", str(cfg)], env=clean_env(), log_dir=tmp_path))
        procs[0].wait_for("ready A2", 60)
        procs.append(start_source(tmp_path, "cp.rest", ep, root, "--but", "A", "--tracks", "--speed", "60"))
        procs.append(start_source(tmp_path, "cp.A", ep, root, "--units", "A", "--speed", "200"))
        procs[1].wait_for("source cp.rest t=1200", 120)
        procs[1].p.kill()
        lost = procs[0].wait_for("system cp.rest", 60)
        line = procs[0].wait_for("summary ", 120)
    finally:
        reap(procs)
    import re
    since = re.search(r"not received since H\+00:(\d\d):(\d\d)", lost)
    assert since and 1150 <= int(since[1]) * 60 + int(since[2]) <= 1320 and "silent for" in lost, lost
    assert re.search(r"monitoring of B\d?.* degraded", lost), lost
    summary = json.loads(line.split(" ", 1)[1])
    assert list(summary["lost"]) == ["cp.rest"], summary
    alerts = load(tmp_path / "A2.jsonl")
    system = [a for a in alerts if a["category"] == "system-problem"]
    assert len(system) == 1 and system[0]["subjects"] == ["cp.rest"] and system[0]["priority"] == "immediate"
    assert max(a["t"] for a in alerts) > 1200.0   # monitoring went on past the loss
    peer = LivePeer(sc, "A2", config(["tcp/127.0.0.1:0"], None), root, ["cp.A", "cp.rest"])
    again = [a.to_json_dict() for a in replay(peer, tmp_path / "A2.input")]
    key = lambda d: (d["t"], d["type"], tuple(d["subjects"]), d["message"], d["priority"])   # noqa: E731
    assert [key(a) for a in again] == [key(a) for a in alerts]


def test_mesh_up_with_a_source_per_command_post_gives_the_in_process_alerts(tmp_path, sc):
    """`mesh up`: a Zenoh router, a source per command post (each company's
    subtree, the battalion's own share with the tracks), EA peers as its clients, no replay:
    every peer's alerts equal the in-process run's (the same EA on the same facts)."""
    from saim_mesh.inprocess.runner import run
    units = ["BN", "A", "A2"]
    out = tmp_path / "mesh"
    r = Proc("mesh-up", [*py(), "mesh", "up", SC, "--units", *units, "--out-dir", str(out)],
             env=clean_env(), log_dir=tmp_path)
    try:
        r.wait_for("3 of 3 EA peers done", 240)
        assert r.p.wait(60) == 0
    finally:
        r.stop()
    table = [x for x in r.lines if x.startswith("total ")]
    assert table, r.tail()
    eas = run(sc, units)
    for ea in eas:
        assert plan_alerts(load(out / f"{ea.owner}.jsonl")) == plan_alerts(ea.alerts), ea.owner


def test_bad_input_to_a_source_or_a_live_peer_is_one_line_counted_never_fatal(sc, tmp_path):
    """A NaN coordinate or a time before the watermark is refused by the source with one
    line naming it (the rest is published); a peer counts a junk frame, a frame on another
    source's key and a frame carrying a message of the wrong kind, and goes on."""
    import zenoh

    from dissemination.keyspace import KeySpace
    from saim_mesh.protocol import messages as M
    from saim_mesh.live import frames as F
    from saim_mesh.live.source import LiveSource
    root = f"test/{uuid.uuid4().hex[:8]}"
    ks = KeySpace.of(sc, root)
    said: list[str] = []
    with zenoh.open(config(["tcp/127.0.0.1:0"], None)) as s:
        src = LiveSource(s, ks, "cp.test", tmp_path)
        assert src.epoch == 1 and LiveSource(s, ks, "cp.test", tmp_path).epoch == 2   # bumped at each start
        good = [e for e in sc.events if type(e) is M.LocationReport][:5]
        bad = [M.LocationReport(good[2].t, good[2].entity, float("nan"), good[2].lat)]
        n = play.publish(src, [*good[:3], *bad, *good[3:]], log=lambda *a, **k: said.append(a[0]))
        assert n == 5 and len(said) == 1 and "field 'lon': not a finite number" in said[0]
        src.watermark(100.0)
        with pytest.raises(ValueError, match="not after its watermark 100.0"):
            src.put(replace_t(good[0], 50.0))
        src.close()
    peer = LivePeer(sc, "A2", config(["tcp/127.0.0.1:0"], None), root, ["cp.x"])
    peer.ea.start(0.0)
    frame = lambda **kw: F.encode(F.Frame(**{"v": 1, "source": "cp.x", "epoch": 1, "seq": 1, "wm": 10.0,  # noqa: E731
                                             "msgs": [M.encode(good[0])], **kw}))
    peer.take(b"\xc1junk", ks.src("cp.x"))
    peer.take(frame(), ks.src("cp.y"))                                    # another source's key
    peer.take(frame(msgs=[M.encode(M.Alert(1.0, "A", "contact", "adversarial-activity", "flash", ("A1",), "x"))]),
              ks.src("cp.x"))                                             # not a fact a source may publish
    peer.take(frame(source="cp.other"), ks.src("cp.other"))               # a source we do not depend on: ignored
    assert sum(peer.gate.rejects.by_kind.values()) == 3, peer.gate.rejects.by_kind
    peer.take(frame(seq=2), ks.src("cp.x"))
    assert peer.ea.n_in == 1 and peer.order.released == 10.0


def replace_t(m, t):
    from dataclasses import replace
    return replace(m, t=t)


def forgeries(sc, pki, root: str) -> list[tuple[str, bytes, str]]:
    """What an insider holding console.A's valid certificate forges to A2's EA, as (key,
    payload, the kind its refusal is counted under): commands signed with another console's
    key, an unsigned command, directives whose signature is not theirs."""
    import random

    import msgspec

    from dissemination.keyspace import KeySpace
    from saim_mesh.authority import commands as C
    from saim_mesh.authority import directives
    from saim_mesh.protocol import wire as W
    from saim_mesh.security import sign
    ks, rnd = KeySpace.of(sc, root), random.Random(7)
    other = sign.load_signer(pki, "console.B")   # a console that does not command A2
    out = []
    for i in range(3):
        key = ks.cmd("A2", "ack", "A")
        out.append((key, other.sign(key, W.encode(C.make("ack", alert=f"A2/{900 + i}"))), "signed"))
    out.append((ks.cmd("A2", "ack", "A"), W.encode(C.make("ack", alert="A2/1")), "ackcmd"))
    k_order = directives.key(root, "A", "order")
    mission = next(m.id for m in sc.plan.missions if m.unit == "A2")
    for by in ("console.A", "console.BN"):   # its own name with a made-up signature, and its superior's
        n = 1000 + len(out)
        body = msgspec.msgpack.encode(directives.make("order", req=directives._req(), n=n, at=100.0,
                                                      action="start-mission", mission=mission))
        env = sign.Signed(v=sign.VERSION, by=by, n=n, key=k_order, body=body, sig=bytes(rnd.randbytes(64)))
        out.append((k_order, sign._ENC.encode(msgspec.msgpack.Ext(sign.EXT, sign._ENC.encode(env))), "signed"))
    return out


def test_a_secure_source_reaches_its_ea_and_a_forged_one_does_not(tmp_path, sc):
    """mTLS and access control: cp.BN (identity source.cp.BN) publishes the battle to A2's EA;
    an insider with a valid certificate (observer) puts a forged frame on cp.BN's key that
    would end its stream at once: access control drops it, and A2 raises the in-process alerts.
    Another insider (console.A's certificate) forges commands and directives to A2: each is
    refused and counted exactly once, by kind, and changes nothing. After R's reorganization
    (from A to BN), the CLI's command to R's EA as A's console is refused, saying why."""
    import time
    from collections import Counter

    import zenoh

    from dissemination.keyspace import KeySpace
    from saim_mesh.live import frames as F
    from saim_mesh.security import endpoint_tls, make_pki, names_for
    pki = tmp_path / "pki"
    make_pki(pki, names_for(sc, consoles=True))
    ep, root = endpoint_tls(free_port()), f"test/{uuid.uuid4().hex[:8]}"
    sec = ["--pki", str(pki)]
    procs = []
    try:
        procs.append(Proc("peer-A2", [*py(), "peer", "--scenario", SC, "--unit", "A2", "--listen", ep, "--root", root,
                                      "--sources", "cp.BN", "--out", str(tmp_path / "A2.jsonl"), *sec],
                          env=clean_env(), log_dir=tmp_path))
        procs[0].wait_for("ready A2", 60)
        conf = config(["tls/127.0.0.1:0"], [ep], pki=pki, name="observer", sc=sc, root=root)
        with zenoh.open(conf) as s:
            forged = F.encode(F.Frame(v=1, source="cp.BN", epoch=2**40, seq=1, wm=1e6, msgs=[], end=True))
            pub = s.declare_publisher(KeySpace.of(sc, root).src("cp.BN"))
            pub.put(forged)
            pub.undeclare()
        forged = forgeries(sc, pki, root)
        insider = zenoh.open(config(["tls/127.0.0.1:0"], [ep], pki=pki, name="console.A", sc=sc, root=root))
        try:
            for key, payload, _ in forged:
                pub = insider.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
                end = time.monotonic() + 30
                while not pub.matching_status.matching:   # A2's EA subscribes to it: sent, never dropped
                    assert time.monotonic() < end, f"A2's EA never subscribed to {key}"
                    time.sleep(0.02)
                pub.put(payload)
                pub.undeclare()
            ep_r = endpoint_tls(free_port())   # R's EA, beside: the CLI's commands after R's reorganization
            procs.append(Proc("peer-R", [*py(), "peer", "--scenario", SC, "--unit", "R", "--listen", ep_r, "--root",
                                         root, "--sources", "cp.BN", "--out", str(tmp_path / "R.jsonl"), "--linger",
                                         "120", *sec], env=clean_env(), log_dir=tmp_path))
            procs[-1].wait_for("ready R", 60)
            procs.append(Proc("source-cp.BN", [*py(), "source", SC, "--name", "cp.BN", "--connect", ep, ep_r, "--root",
                                               root, "--linger", "600", "--tracks", "--speed", "max", "--by-group",
                                               "--state", str(tmp_path / "state"),   # a group frame missed: from here
                                               *sec, "--listen", "tls/127.0.0.1:0"], env=clean_env(), log_dir=tmp_path))
            line = procs[0].wait_for("summary ", 120)
        finally:
            insider.close()
        procs[1].wait_for("end ", 120)   # R's EA is past the battle's end, answering commands

        def ack_r(as_: str) -> tuple[int, dict]:
            r = subprocess.run([*py(), "ack", "--scenario", SC, "--unit", "R", "--alert", "R/999", "--as", as_,
                                "--connect", ep_r, "--root", root, "--timeout", "20", *sec],
                               capture_output=True, text=True, timeout=90, env=clean_env())
            assert r.stdout.strip(), r.stderr
            return r.returncode, json.loads(r.stdout.strip().splitlines()[-1])
        # R moved from A to BN at 600 (the plan's reorganization): A's console commands it no more
        code, res = ack_r("console.A")
        assert code == 2 and res["ok"] is False and res["error"] == "the console of A does not command R (its chain of command is now BN/R)", res
        code, res = ack_r("console.BN")
        assert code == 2 and "unknown alert" in res["error"], res   # its new superior's: through to the EA
    finally:
        reap(procs)
    summary = json.loads(line.split(" ", 1)[1])
    assert summary["rejects"] == dict(Counter(kind for *_, kind in forged)), summary["rejects"]
    from .heard import by_live_groups
    msgs = list(play.share(sc, None, True))
    heard = by_live_groups(sc, msgs, "A2")   # cp.BN publishes by key group: A2 takes the groups of its interest
    assert summary["lost"] == {} and summary["messages"] == len(heard) < len(msgs), summary
    want = plan_alerts(in_process(sc, "A2", {"cp.BN": msgs}))
    assert plan_alerts(load(tmp_path / "A2.jsonl")) == want


def test_a_frame_the_full_order_refuses_is_offered_again_never_dropped(sc):
    """The order holds at most `max_buffered` facts: a frame it refuses as full waits (and its
    source's later frames behind it) until a release makes room; nothing is lost and the
    journal holds frames in the order they were taken."""
    from saim_mesh.protocol import messages as M
    from saim_mesh.live import frames as F
    peer = LivePeer(sc, "A2", config(["tcp/127.0.0.1:0"], None), "t/full", ["cp.a", "cp.b"])
    peer.order.max_buffered = 3
    reps = [e for e in sc.events if type(e) is M.LocationReport][:8]

    def frame(src, seq, wm, ms):
        return F.encode(F.Frame(v=1, source=src, epoch=1, seq=seq, wm=wm, msgs=[M.encode(m) for m in ms]))
    peer.receive(frame("cp.a", 1, reps[1].t, reps[0:2]), "")
    peer.receive(frame("cp.a", 2, reps[3].t, reps[2:4]), "")   # 4 facts would wait: refused as full
    peer.receive(frame("cp.a", 3, reps[5].t, reps[4:6]), "")   # queues behind it
    assert [f.seq for _, _, f in peer.seq.hold.waiting["cp.a"]] == [2, 3] and peer.ea.n_in == 0
    peer.receive(frame("cp.b", 1, 1e5, []), "")                # cp.b's promise releases cp.a's first facts
    peer.seq.retry()
    peer.seq.retry()
    assert not peer.seq.hold.waiting_for("cp.a") and peer.ea.n_in == 6 and peer.frames == 4


def test_a_source_back_after_every_other_ended_does_not_kill_the_peer(sc, tmp_path):
    """A lost source heard again once every other source ended (the order released up to
    +inf) is taken back with one line, not an OverflowError out of the alert's text (a
    brigade peer died so in bench_scale)."""
    from saim_mesh.protocol import messages as M
    from saim_mesh.live import frames as F
    peer = LivePeer(sc, "A2", config(["tcp/127.0.0.1:0"], None), "t/back", ["cp.a", "cp.b"],
                    out_path=str(tmp_path / "A2.jsonl"), log=lambda *a, **k: None)
    peer.ea.start(0.0)
    rep = next(e for e in sc.events if type(e) is M.LocationReport)

    def frame(src, seq, wm, ms, end=False):
        return F.encode(F.Frame(v=1, source=src, epoch=1, seq=seq, wm=wm, msgs=[M.encode(m) for m in ms], end=end))
    peer.receive(frame("cp.a", 1, 2.0, []), "")
    peer.lose("cp.a", "silent for 10 s")
    peer.receive(frame("cp.b", 1, 4.0, [], end=True), "")
    assert peer.order.released == float("inf")
    peer.receive(frame("cp.a", 2, rep.t, [rep]), "")
    back = [a for a in peer.given if a.details.get("event") == "source-back"]
    assert len(back) == 1 and "since the end" in back[0].message, [a.message for a in peer.given]
    assert peer.rebuilds == 1


def test_a_peer_that_joins_after_a_source_with_no_journal_gets_its_frames_from_the_cache(tmp_path, sc):
    """A late joiner (or a restarted EA) of a source that keeps no journal (no --state): the
    publisher's cache is all there is, so the subscriber asks it when declared."""
    ep, root = f"tcp/127.0.0.1:{free_port()}", f"test/{uuid.uuid4().hex[:8]}"
    procs = []
    try:
        src = Proc("source-cp.all", [*py(), "source", SC, "--name", "cp.all", "--listen", ep, "--root", root,
                                     "--linger", "600", "--tracks", "--speed", "max"], env=clean_env(), log_dir=tmp_path)
        procs.append(src)
        src.wait_for("end source cp.all", 120)   # everything published before the peer exists
        procs.append(Proc("peer-A2", [*py(), "peer", "--scenario", SC, "--unit", "A2", "--connect", ep, "--root",
                                      root, "--sources", "cp.all", "--out", str(tmp_path / "A2.jsonl")],
                          env=clean_env(), log_dir=tmp_path))
        line = procs[1].wait_for("summary ", 180)
    finally:
        reap(procs)
    summary = json.loads(line.split(" ", 1)[1])
    assert summary["gaps"] == 0 and summary["lost"] == {}, summary
    want = plan_alerts(in_process(sc, "A2", {"cp.all": list(play.share(sc, None, True))}))
    assert len(want) >= 5 and plan_alerts(load(tmp_path / "A2.jsonl")) == want
