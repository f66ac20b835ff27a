"""Multi-process integration tests: real Zenoh peers on loopback, free ports, bounded time,
every child reaped. Synchronisation is on what the processes print, never on sleeps."""
from __future__ import annotations

import json
import uuid

import pytest

from saim_mesh import scenario as S
from saim_mesh.mesh import Proc, start_peer, start_replay
from saim_mesh.runner import run
from saim_mesh.zconf import free_port

from .conftest import SMALL

pytestmark = pytest.mark.timeout(240)
SC = str(SMALL)


def load(path):
    return [json.loads(line) for line in open(path)]


def plan_alerts(alerts):
    """Alerts from the plan and the picture (not the wall-clock-driven presence notes)."""
    return [a for a in alerts if a["category"] != "system-problem"]


def key(a):
    return (a["t"], a["type"], a["subjects"], a["message"], a["priority"])


@pytest.fixture(scope="module")
def inproc():
    eas = run(S.load(SMALL), ["BN", "A", "B", "C", "A2"])
    return {ea.owner: [json.loads(json.dumps(a.to_json_dict())) for ea_ in [ea] for a in ea_.alerts] for ea in eas}


def launch(tmp, peers: list[tuple[str, str]], speed="max"):
    ep = f"tcp/127.0.0.1:{free_port()}"
    root = f"test/{uuid.uuid4().hex[:8]}"
    replay = start_replay(SC, ep, root, sorted(u for u, _ in peers), speed)   # every peer, twins too
    procs: list[Proc] = [replay]
    replay.wait_for("ready", 60)
    for unit, name in peers:
        procs.append(start_peer(SC, unit, ep, root, tmp / f"{name}.jsonl", name))
    return ep, root, procs


def reap(procs):
    for p in procs:
        p.stop()
    assert all(p.p.poll() is not None for p in procs)


@pytest.fixture(scope="module")
def mesh_run(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("mesh")
    _, _, procs = launch(tmp, [("BN", "BN"), ("A", "A"), ("C", "C"), ("A2", "A2a"), ("A2", "A2b")])
    try:
        summaries = {p.name: json.loads(p.wait_for("summary ", 180)[8:]) for p in procs[1:]}
        procs[0].p.wait(60)
    finally:
        reap(procs)
    return {name: load(tmp / f"{name}.jsonl") for name in summaries}, summaries


def test_two_peers_for_one_unit_raise_identical_alerts(mesh_run):
    alerts, _ = mesh_run
    assert plan_alerts(alerts["A2a"]) and plan_alerts(alerts["A2a"]) == plan_alerts(alerts["A2b"])


def test_mesh_peer_equals_in_process_run(mesh_run, inproc):
    alerts, _ = mesh_run
    for name, unit in (("A2a", "A2"), ("A", "A"), ("BN", "BN"), ("C", "C")):
        assert [key(a) for a in plan_alerts(alerts[name])] == [key(a) for a in inproc[unit]], name


def test_the_mission_model_checks_reach_the_mesh(mesh_run):
    """Every check family the mission classes compose (issue 13) is raised by a peer on the
    mesh: each peer subscribes to what its missions need (held areas, supported units,
    checkpoints, orders within its subtree). Equality with the in-process run is above."""
    alerts, _ = mesh_run
    types = {a["type"] for name in ("BN", "A", "C", "A2a") for a in alerts[name]}
    assert {"escape", "end-state", "penetration", "projected-penetration", "friendly-expected", "band",
            "threat-ahead", "checkpoint", "line", "recon-progress"} <= types, types
    # the ON-ORDER march: BN ordered it at 2150, M started at 2200 (50 s later: late)
    late = [a for a in alerts["BN"] if a["type"] == "schedule" and a["details"].get("constraint") == "ON-ORDER"]
    assert [(a["t"], a["details"]["how"]) for a in late] == [(2180.0, "late")]


def test_max_speed_replay_stays_within_its_window_of_the_slowest_peer(mesh_run):
    _, summaries = mesh_run
    # the replay publishes tick t only once every EA peer has done t - 20 s; its events
    # before the next tick (2 s on) are then the furthest a peer can see ahead
    leads = {name: s["max_lead_s"] for name, s in summaries.items()}
    assert all(0 < lead <= 20 + 2 for lead in leads.values()), leads


def test_echelons_share_threat_alerts_and_keep_their_own_plans(mesh_run):
    alerts, summaries = mesh_run
    by = lambda name, typ: [key(a) for a in alerts[name] if a["type"] == typ]
    assert by("BN", "fratricide") and by("BN", "fratricide") == by("A", "fratricide")
    of_c = [key(a) for a in alerts["BN"] if a["type"] == "proximity" and a["details"].get("parent") == "C"]
    assert of_c and of_c == by("C", "proximity")   # BN's about C CO's units are C's own
    missions = lambda name: {a["details"]["mission"] for a in alerts[name] if a["type"] == "contingency"}
    assert missions("BN") == {"BN-branch-disrupt"} and missions("A") == {"A-sequel-suppress"} and not missions("C")
    places = lambda name: {a["details"]["place"] for a in alerts[name] if a["type"] == "ave-of-approach"}
    assert places("BN") == {"AA-DIAMOND"} and places("C") == {"AA-RUBY"} and not places("A")
    assert summaries["A2a"]["subscriptions"] < summaries["BN"]["subscriptions"]   # nobody takes everything


def test_killed_peer_is_noticed_and_recovers_and_late_joiner_catches_up(tmp_path, inproc):
    ep, root, procs = launch(tmp_path, [("A", "A"), ("A2", "A2")], speed="250")
    replay = procs[0]
    try:
        replay.wait_for("t=1500", 120)
        procs[2].p.kill()                                    # the platoon's EA dies
        procs[2].p.wait(10)
        replay.wait_for("t=2000", 120)
        again = start_peer(SC, "A2", ep, root, tmp_path / "A2-again.jsonl", "A2-again")
        late = start_peer(SC, "B", ep, root, tmp_path / "B-late.jsonl", "B-late")
        procs += [again, late]
        s_again = json.loads(again.wait_for("summary ", 180)[8:])
        s_late = json.loads(late.wait_for("summary ", 180)[8:])
        procs[1].wait_for("summary ", 180)
    finally:
        reap(procs)
    assert s_again["joined_t"] >= 2000 and s_late["joined_t"] >= 2000
    a_alerts = load(tmp_path / "A.jsonl")
    left = [a for a in a_alerts if a["category"] == "system-problem" and a["details"]["left"]]
    back = [a for a in a_alerts if a["category"] == "system-problem" and not a["details"]["left"]]
    assert left and left[0]["subjects"] == ["A2"] and 1500 <= left[0]["t"] <= 2000
    assert back and back[0]["t"] >= left[0]["t"]
    assert plan_alerts(a_alerts) == [a for a in plan_alerts(a_alerts)]   # A kept working
    assert [key(a) for a in plan_alerts(a_alerts)] == [key(a) for a in inproc["A"]]
    for name, unit, joined in (("A2-again", "A2", s_again["joined_t"]), ("B-late", "B", s_late["joined_t"])):
        got = [key(a) for a in plan_alerts(load(tmp_path / f"{name}.jsonl"))]
        want = [key(a) for a in inproc[unit] if a["t"] > joined]
        assert got == want and want, name


def test_frozen_peer_is_noticed_by_its_lease_and_noted_when_it_thaws(tmp_path, inproc):
    """A peer that stops reporting (SIGSTOP: no crash, no closed socket) is lost when its
    Zenoh lease (configs/zenoh-peer.json5) runs out; thawed, it reconnects, is back, sees
    the gap in the clock and takes what it missed from the store: its alerts are those
    of a peer that never froze."""
    import signal
    ep, root, procs = launch(tmp_path, [("A", "A"), ("A2", "A2")], speed="200")
    a, a2 = procs[1], procs[2]
    try:
        procs[0].wait_for("t=3300", 120)
        a2.p.send_signal(signal.SIGSTOP)
        left = a.wait_for("presence A2 left", 60)
        procs[0].wait_for("t=4000", 60)   # cut off past A2's call for fire (t=3900): it must catch up
        a2.p.send_signal(signal.SIGCONT)
        back = a.wait_for("presence A2 back", 60)
        a.wait_for("summary ", 180)
        s2 = json.loads(a2.wait_for("summary ", 180)[8:])
    finally:
        for p in procs:
            p.p.send_signal(signal.SIGCONT)
        reap(procs)
    t_left, t_back = int(left.split("t=")[1]), int(back.split("t=")[1])
    assert 3300 <= t_left <= 3300 + 200 * 10 and t_back >= t_left   # lease 2 s of wall time, at speed 200
    notes = [x for x in load(tmp_path / "A.jsonl") if x["category"] == "system-problem"]
    assert [(x["subjects"], x["details"]["left"]) for x in notes] == [(["A2"], True), (["A2"], False)]
    assert s2["gaps"] >= 1
    assert [key(x) for x in plan_alerts(load(tmp_path / "A2.jsonl"))] == [key(x) for x in inproc["A2"]]


def test_malformed_messages_are_counted_and_the_peer_keeps_working(tmp_path, inproc):
    import zenoh

    from saim_mesh.zconf import config
    ep, root, procs = launch(tmp_path, [("A2", "A2")], speed="400")
    try:
        procs[0].wait_for("t=300", 120)
        with zenoh.open(config([], [ep])) as s:
            pub = s.declare_publisher(f"{root}/msn/A2/bogus", congestion_control=zenoh.CongestionControl.BLOCK)
            # A fresh session only routes to subscribers it has heard of: wait for the A2 peer's.
            listener = pub.declare_matching_listener()   # held: dropping it would close its channel
            if not pub.matching_status.matching:
                assert next(st for st in listener if st.matching)
            for payload, att in ((b"\x00garbage", None), (b"\xc1", (10**9).to_bytes(8, "big")),
                                 (__import__("msgpack").packb({"v": 1, "kind": "location", "t": 1.0}), None)):
                pub.put(payload, attachment=att)
            summary = json.loads(procs[1].wait_for("summary ", 180)[8:])   # session open until then
    finally:
        reap(procs)
    assert summary["bad_messages"] == 3
    assert [key(a) for a in plan_alerts(load(tmp_path / "A2.jsonl"))] == [key(a) for a in inproc["A2"]]



def _multicast_works() -> bool:
    """Probe: two sessions with multicast scouting and no endpoints find each other."""
    import threading

    import zenoh

    from saim_mesh.zconf import config
    key, found = f"probe/{uuid.uuid4().hex}", threading.Event()
    with zenoh.open(config(["tcp/127.0.0.1:0"], [], multicast=True)) as a, \
            zenoh.open(config(["tcp/127.0.0.1:0"], [], multicast=True)) as b:
        sub = b.declare_subscriber(key, zenoh.handlers.FifoChannel(1))
        pub = a.declare_publisher(key)
        listener = pub.declare_matching_listener(lambda st: found.set() if st.matching else None)
        ok = pub.matching_status.matching or found.wait(10)
        del sub, listener
        return ok


def test_peers_find_each_other_by_multicast_scouting(tmp_path, inproc):
    """`--multicast`: no endpoint is configured to connect to; the replay and the peer
    discover each other by UDP multicast scouting and the peer alerts as usual."""
    if not _multicast_works():
        pytest.skip("UDP multicast scouting does not work on this host's network")
    from saim_mesh.mesh import py
    root = f"test/{uuid.uuid4().hex[:8]}"
    zargs = ["--listen", "tcp/127.0.0.1:0", "--multicast", "--root", root]
    replay = Proc("replay", [*py(), "replay", SC, "--speed", "max", "--linger", "5", "--wait-peers", "A2", *zargs])
    procs = [replay]
    try:
        replay.wait_for("ready", 60)
        procs.append(Proc("A2", [*py(), "peer", "--scenario", SC, "--unit", "A2", "--out", str(tmp_path / "A2.jsonl"),
                                 *zargs]))
        procs[1].wait_for("summary ", 180)
    finally:
        reap(procs)
    assert [key(a) for a in plan_alerts(load(tmp_path / "A2.jsonl"))] == [key(a) for a in inproc["A2"]]
