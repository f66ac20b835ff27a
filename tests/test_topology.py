"""Routers and topologies: files checked before anything starts, the derived topology,
the clock barrier over the replay's sources, and the mesh through routers joined by
emulated radio links (multi-process, loopback, bounded)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
import uuid
from types import SimpleNamespace

import pytest

from ea_agent.core.plan import TaskOrg, Unit
from saim_mesh import scenario as S
from saim_mesh.net import topology as T
from saim_mesh import wire as W
from saim_mesh.mesh import up
from saim_mesh.proc import Proc
from saim_mesh.peer import Peer
from saim_mesh.runner import run
from saim_mesh.security.acl import access_control, identities
from saim_mesh.zconf import config, free_port

from .conftest import SMALL

SC = str(SMALL)
UNITS = ["A", "A1", "B", "B1", "BN", "C"]
SMALL_TOPO = """
[[router]]
name = "r-BN"
cp = "BN"
[[router]]
name = "r-A"
cp = "A"
links = ["r-BN"]
[[router]]
name = "r-B"
cp = "B"
links = ["r-BN"]
"""


def brigade() -> TaskOrg:
    units = [Unit("BDE", "BDE", "brigade", None), Unit("CAV", "CAV", "company", "BDE")]
    for b in ("1", "2", "3"):
        units += [Unit(f"{b}BN", f"{b}BN", "battalion", "BDE"), Unit(f"{b}A", f"{b}A", "company", f"{b}BN"),
                  Unit(f"{b}A1", f"{b}A1", "platoon", f"{b}A", (f"{b}A1E1",))]
    return TaskOrg(units)


def topo_file(tmp_path, text: str):
    p = tmp_path / "topology.toml"
    p.write_text(text)
    return p


def test_derived_topology_has_a_router_per_battalion_command_post_and_one_at_the_top():
    to = brigade()
    topo = T.derive(to)
    assert sorted(topo.routers) == ["r-1BN", "r-2BN", "r-3BN", "r-BDE"]
    assert topo.top == "r-BDE"
    assert topo.links() == [("r-1BN", "r-BDE"), ("r-2BN", "r-BDE"), ("r-3BN", "r-BDE")]
    assert topo.router_of("2A1", to) == "r-2BN" and topo.router_of("2BN", to) == "r-2BN"
    assert topo.router_of("CAV", to) == "r-BDE" and topo.router_of("BDE", to) == "r-BDE"
    assert topo.side(("r-1BN", "r-BDE")) == {"r-1BN"}


def test_a_written_topology_reads_back_the_same(tmp_path):
    topo = T.derive(brigade())
    T.write(topo, tmp_path / "t.toml")
    back = T.load(tmp_path / "t.toml", brigade())
    assert back.to_dict() == topo.to_dict()


@pytest.mark.parametrize("text, says", [
    ('[[router]]\nname = "r-BDE"\ncp = "NOPE"\n', "'cp' 'NOPE' is not a unit"),
    ('[[router]]\nname = "r-BDE"\ncp = "BDE"\nlinks = ["r-X"]\n', "links to 'r-X': no such router"),
    ('[[router]]\nname = "r-BDE"\ncp = "BDE"\n[[router]]\nname = "r-1"\ncp = "1BN"\n', "unreachable from r-BDE: r-1"),
    ('[[router]]\nname = "r-BDE"\ncp = "BDE"\n[[router]]\nname = "r-1"\ncp = "1BN"\nlinks = ["r-2"]\n'
     '[[router]]\nname = "r-2"\ncp = "2BN"\nlinks = ["r-3"]\n[[router]]\nname = "r-3"\ncp = "3BN"\n'
     'links = ["r-1"]\n', "closes a cycle"),
    ('[[router]]\nname = "r-BDE"\ncp = "BDE"\n[[router]]\nname = "r-1"\ncp = "1BN"\nlinks = ["r-BDE"]\n'
     '[[router]]\nname = "r-2"\ncp = "2BN"\nlinks = ["r-1"]\n[[router]]\nname = "r-1"\ncp = "3BN"\n',
     "router 'r-1' named twice"),
    ('[[router]]\nname = "r-1"\ncp = "1BN"\n', "no router at the top unit's command post"),
    ('[[router]]\nname = "r-BDE"\ncp = "BDE"\n[attach]\n"9Z" = "r-BDE"\n', "'9Z' is neither a unit"),
    ('[[router]]\nname = "r-BDE"\ncp = "BDE"\n[attach]\n"1A" = "r-9"\n', "no such router"),
    ('[[router]]\nname = "r BDE"\ncp = "BDE"\n', "'name' must be"),
    ('[[router]]\nname = "r-BDE"\ncp = "BDE"\nspeed = 3\n', "unknown fields ['speed']"),
    ('[[router]\nname = ', "not valid TOML"),
    ('[routers]\n', "unknown sections"),
])
def test_a_bad_topology_is_refused_naming_what_is_wrong(tmp_path, text, says):
    with pytest.raises(T.TopologyError) as e:
        T.load(topo_file(tmp_path, text), brigade())
    assert says in str(e.value) and "topology.toml" in str(e.value)


def test_a_missing_or_garbled_resolved_topology_is_a_clear_error(tmp_path):
    with pytest.raises(T.TopologyError, match="cannot read"):
        T.read_resolved(tmp_path / "none.json")
    (tmp_path / "bad.json").write_text('{"topology": {"routers": 3}}')
    with pytest.raises(T.TopologyError, match="not a resolved topology"):
        T.read_resolved(tmp_path / "bad.json")
    topo = T.derive(brigade())
    T.resolve(topo, {"r-BDE": "tcp/127.0.0.1:1"}, tmp_path / "r.json")
    with pytest.raises(T.TopologyError, match="no endpoint for routers r-1BN, r-2BN, r-3BN"):
        T.read_resolved(tmp_path / "r.json")


def test_leaves_and_routers_never_scout_and_routers_are_trusted_relays():
    conf = config(None, ["tcp/127.0.0.1:1"], mode="client")
    assert json.loads(conf.get_json("mode")) == "client"
    assert json.loads(conf.get_json("scouting/gossip/enabled")) is False
    assert json.loads(conf.get_json("transport/shared_memory/enabled")) is False
    assert json.loads(conf.get_json("listen/endpoints")) == []
    with pytest.raises(ValueError, match="zenoh mode 'hub'"):
        config(None, None, mode="hub")
    assert "router.r-A" in identities(["A"], [], routers=["r-A"])
    acl = access_control("saim/x", ["A"], [], routers=["r-A"])
    pol = next(p for p in acl["policies"] if p["subjects"] == ["router.r-A"])
    relay = next(r for r in acl["rules"] if r["id"] == "router_relay")
    assert "router_relay" in pol["rules"] and "put" in relay["messages"] and "delete" not in relay["messages"]
    assert "router_relay" not in next(p for p in acl["policies"] if p["subjects"] == ["ea.A"])["rules"]
    # a live source's cache, recovery queries and replies and liveliness live under verbatim
    # `@adv` chunks, which `**` does not reach: a relay must name them or no recovery crosses
    assert "saim/x/src/*/@adv/**" in relay["key_exprs"] and {"query", "reply"} <= set(relay["messages"])


def test_a_tick_is_taken_once_every_source_gave_it():
    stub = SimpleNamespace(tick_parts={})
    tick = lambda n, src, of=2: W.make(W.Tick, t=2.0 * n, n=n, seq=n, src=src, of=of)   # noqa: E731
    assert Peer._whole(stub, tick(1, "r-A", 1))             # one source: at once
    assert not Peer._whole(stub, tick(2, "r-A"))
    assert not Peer._whole(stub, tick(2, "r-A"))            # the same source twice is still one
    assert not Peer._whole(stub, tick(3, "r-A"))
    assert Peer._whole(stub, tick(2, "r-BN"))
    assert list(stub.tick_parts) == [3]                     # tick 2 and older forgotten, 3 still waits
    assert "came only from r-A" in Peer._waiting_for(stub)


# -- the mesh through routers -------------------------------------------------------------

def plan_key(a):
    """An alert as the in-process run raises it (a late one carries where it was cut off)."""
    d = {k: v for k, v in a["details"].items() if k not in ("late", "cut_off")}
    return (a["t"], a["type"], a["subjects"], a["message"], a["priority"], json.dumps(d, sort_keys=True))


@pytest.fixture(scope="module")
def inproc():
    return {ea.owner: [plan_key(json.loads(json.dumps(a.to_json_dict()))) for a in ea.alerts]
            for ea in run(S.load(SMALL), UNITS)}


def mesh_alerts(out, unit):
    return [json.loads(line) for line in open(out / f"{unit}.jsonl")]


@pytest.mark.timeout(400)
def test_the_mesh_through_routers_over_lossy_radio_links_equals_the_in_process_run(tmp_path, inproc):
    out = tmp_path / "mesh"
    res = up(SC, UNITS, out, "max", topology=str(topo_file(tmp_path, SMALL_TOPO)),
             link={"delay_ms": 50.0, "loss": 0.01}, echo=lambda *a, **k: None, timeout=300)
    assert sorted(res["peers"]) == UNITS and not res["given_up"] and res["secure"]
    for u in UNITS:
        got = [plan_key(a) for a in mesh_alerts(out, u) if a["category"] != "system-problem"]
        assert got == inproc[u], u
    for name, st in res["links"].items():   # each router link carried traffic both ways, some of it lost
        assert st["up"]["bytes"] > 0 and st["down"]["bytes"] > 0, name
        assert st["up"]["lost"] + st["down"]["lost"] > 0, name
    assert set(res["links"]) == {"r-A->r-BN", "r-B->r-BN"}


def _wait_line(path, text, timeout):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if path.exists() and text in path.read_text(errors="replace"):
            return
        time.sleep(0.05)
    raise TimeoutError(f"no {text!r} in {path} within {timeout} s")


def _up_in_background(tmp_path, out) -> tuple[threading.Thread, dict]:
    """The small mesh through 3 routers and two 50 ms / 1 % links at 40x, in a thread
    (the test acts on it meanwhile); the dict gets `up`'s result when it ends."""
    res: dict = {}
    t = threading.Thread(target=lambda: res.update(up(
        SC, UNITS, out, "40", topology=str(topo_file(tmp_path, SMALL_TOPO)), link={"delay_ms": 50.0, "loss": 0.01},
        insecure=True, echo=lambda *a, **k: None, timeout=400)), daemon=True)
    t.start()
    return t, res


@pytest.mark.timeout(500)
def test_a_cut_radio_link_is_noticed_on_both_sides_and_no_alert_is_lost(tmp_path, inproc):
    """A 60 s cut of r-A's link: peers on both sides say their picture stopped; after the
    heal they catch up from the stores and raise what fell due meanwhile, marked late."""
    out = tmp_path / "mesh"
    t, res = _up_in_background(tmp_path, out)
    _wait_line(out / "logs" / "replay.log", "t=1200", 120)
    link_pid = json.loads((out / "pids.json").read_text())["link-r-A-r-BN"]
    os.kill(link_pid, signal.SIGUSR1)
    cut_at = time.monotonic()
    _wait_line(out / "logs" / "A.log", "source-silent", 60)    # behind the cut link
    _wait_line(out / "logs" / "BN.log", "source-silent", 60)   # on the other side
    time.sleep(max(0.0, 60.0 - (time.monotonic() - cut_at)))   # the cut lasts 60 s (the stimulus, not a sync)
    os.kill(link_pid, signal.SIGUSR2)
    t.join(420)
    assert not t.is_alive() and sorted(res["peers"]) == UNITS and not res["given_up"]
    late = 0
    for u in UNITS:
        alerts = mesh_alerts(out, u)
        assert [plan_key(a) for a in alerts if a["category"] != "system-problem"] == inproc[u], u
        late += sum(1 for a in alerts if a["details"].get("late"))
    assert late > 0   # some fell due during the cut: raised after it, marked
    for u in ("A", "BN"):
        silent = [a for a in mesh_alerts(out, u) if a["details"].get("event") == "source-silent"]
        assert silent and "a router link may be down" in silent[0]["message"], u
    assert res["peers"]["A"]["gaps"] >= 1 or res["peers"]["BN"]["gaps"] >= 1
    assert res["links"]["r-A->r-BN"]["cuts"] == 1


@pytest.mark.timeout(500)
def test_a_killed_router_is_restarted_its_leaves_reattach_and_no_alert_is_lost(tmp_path, inproc):
    """kill -9 of r-A (A's and A1's router, one end of a radio link) mid-run: the
    supervisor restarts it on the same endpoint; the leaves, the link and the replay
    reattach by themselves, and every peer's alerts still equal the in-process run's."""
    out = tmp_path / "mesh"
    t, res = _up_in_background(tmp_path, out)
    _wait_line(out / "logs" / "replay.log", "t=1200", 120)
    first = json.loads((out / "pids.json").read_text())["r-A"]
    os.kill(first, signal.SIGKILL)
    t.join(420)
    assert not t.is_alive() and sorted(res["peers"]) == UNITS and not res["given_up"]
    assert json.loads((out / "pids.json").read_text())["r-A"] != first   # a new r-A process served the rest
    assert any(e["process"] == "r-A" and "exit_code" in e for e in res["events"])        # its death was seen
    assert any(e["process"] == "r-A" and e.get("restarted") == 1 for e in res["events"])  # and it came back once
    for u in UNITS:
        got = [plan_key(a) for a in mesh_alerts(out, u) if a["category"] != "system-problem"]
        assert got == inproc[u], u


def test_a_leaf_whose_router_is_down_at_start_says_so_and_exits(tmp_path):
    port = free_port()   # nobody listens there
    p = subprocess.run([sys.executable, "-m", "saim_mesh", "peer", "--scenario", SC, "--unit", "A", "--mode", "client",
                        "--connect", f"tcp/127.0.0.1:{port}", "--root", "t/x"], capture_output=True, text=True,
                       timeout=60)
    assert p.returncode == 4
    assert f"cannot join the mesh at tcp/127.0.0.1:{port}" in p.stderr


@pytest.mark.timeout(120)
def test_a_peer_on_the_wrong_router_raises_a_system_problem(tmp_path):
    topo = T.load(topo_file(tmp_path, SMALL_TOPO), S.load(SMALL, events=False).taskorg)
    eps = {n: f"tcp/127.0.0.1:{free_port()}" for n in topo.routers}
    T.resolve(topo, eps, tmp_path / "resolved.json")
    root = f"t/{uuid.uuid4().hex[:8]}"
    router = Proc("r-BN", [sys.executable, "-m", "saim_mesh", "router", "--scenario", SC, "--name", "r-BN", "--root",
                           root, "--listen", eps["r-BN"], "--topology", str(tmp_path / "resolved.json")],
                  log_dir=tmp_path)
    try:
        router.wait_for("router ready", 60)
        peer = Proc("A", [sys.executable, "-m", "saim_mesh", "peer", "--scenario", SC, "--unit", "A", "--mode",
                          "client", "--connect", eps["r-BN"], "--topology", str(tmp_path / "resolved.json"),
                          "--root", root, "--out", str(tmp_path / "A.jsonl"), "--deadline", "3"], log_dir=tmp_path)
        try:
            peer.wait_for("presence A wrong-router", 60)
        finally:
            peer.stop()
    finally:
        router.stop()
    alerts = [json.loads(x) for x in open(tmp_path / "A.jsonl")]
    wrong = [a for a in alerts if a["details"].get("event") == "wrong-router"]
    assert wrong and "attached to r-BN, not to its command post's router r-A" in wrong[0]["message"]


@pytest.mark.timeout(120)
def test_a_router_enforces_the_role_rules_on_its_own_ingress(tmp_path):
    """Behind a router a receiver's access control sees only the router's certificate: the
    router itself must drop what a sender may not publish. An EA's session forges a
    clock tick and an order of another unit through it; a reader behind the same router
    gets neither, but gets the EA's own alert."""
    from saim_mesh.security.pki import make_pki, names_for
    sc = S.load(SMALL, events=False)
    pki = tmp_path / "pki"
    make_pki(pki, names_for(sc) + ["router.r-BN"])
    root = f"t/{uuid.uuid4().hex[:8]}"
    port = free_port()
    router = Proc("r-BN", [sys.executable, "-m", "saim_mesh", "router", "--scenario", SC, "--name", "r-BN",
                           "--root", root, "--listen", f"tls/127.0.0.1:{port}", "--pki", str(pki)], log_dir=tmp_path)
    try:
        router.wait_for("router ready", 60)
        leaf = lambda name: config(None, [f"tls/127.0.0.1:{port}"], pki=pki, name=name, sc=sc, root=root,  # noqa
                                   mode="client", routers=["r-BN"])
        import zenoh
        got: list[str] = []
        with zenoh.open(leaf("ea.BN")) as reader, zenoh.open(leaf("ea.A")) as forger:
            reader.declare_subscriber(f"{root}/**", lambda smp: got.append(str(smp.key_expr)))
            ok = forger.declare_publisher(f"{root}/alert/A/contact")
            end = time.monotonic() + 20
            while not ok.matching_status.matching and time.monotonic() < end:   # the reader's interest arrived
                time.sleep(0.02)
            forger.put(f"{root}/clock", b"forged tick")
            forger.put(f"{root}/ord/B", b"forged order")
            ok.put(b"a real alert")   # after the forgeries, on the same path: when it is here, they would be
            end = time.monotonic() + 20
            while f"{root}/alert/A/contact" not in got and time.monotonic() < end:
                time.sleep(0.02)
    finally:
        router.stop()
    assert f"{root}/alert/A/contact" in got
    assert f"{root}/clock" not in got and f"{root}/ord/B" not in got
