"""Routers and topologies: files checked before anything starts, the derived topology,
and the mesh through routers joined by emulated radio links (multi-process, loopback,
bounded)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
import uuid

import pytest

from ea_agent.core.plan import TaskOrg, Unit
from saim_mesh import scenario as S
from saim_mesh.net import topology as T
from saim_mesh.live.up import up
from saim_mesh.launch.proc import Proc
from saim_mesh.inprocess.runner import run
from saim_mesh.security.acl import access_control, identities
from saim_mesh.launch.zenoh_config import config, free_port

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
    assert "saim/x/src/**/@adv/**" in relay["key_exprs"] and {"query", "reply"} <= set(relay["messages"])


# -- the mesh through routers -------------------------------------------------------------

def plan_key(a):
    """An alert as the in-process run raises it (a late one carries when it fell due and,
    on a cut, where it was cut off)."""
    d = {k: v for k, v in a["details"].items() if k not in ("late", "cut_off", "due_from")}
    return (a["t"], a["type"], a["subjects"], a["message"], a["priority"], json.dumps(d, sort_keys=True))


@pytest.fixture(scope="module")
def inproc():
    return {ea.owner: [plan_key(json.loads(json.dumps(a.to_json_dict()))) for a in ea.alerts]
            for ea in run(S.load(SMALL), UNITS)}


def mesh_alerts(out, unit):
    return [json.loads(line) for line in open(out / f"{unit}.jsonl")]


@pytest.mark.timeout(500)
def test_the_mesh_through_routers_over_lossy_links_with_a_router_killed_equals_the_in_process_run(tmp_path, inproc):
    """`mesh up --topology` on the small scenario: 3 routers, two 50 ms / 1 % radio links,
    a source per command post attached to its own router; r-A (A's and A1's router, one
    end of a link) is killed with SIGKILL once the sources run. The supervisor restarts
    it on the same endpoint, the leaves and the link reattach by themselves, each link
    carried traffic both ways with some of it lost, and every peer's alerts equal the
    in-process run's (one shared mesh for both: these runs are slow)."""
    out = tmp_path / "mesh"
    killed: dict = {}

    def kill_r_a(sup, _t0) -> None:
        killed["pid"] = sup.procs["r-A"].pid
        os.kill(killed["pid"], signal.SIGKILL)
    res = up(SC, UNITS, out, "max", topology=str(topo_file(tmp_path, SMALL_TOPO)),
             link={"delay_ms": 50.0, "loss": 0.01}, echo=lambda *a, **k: None, show=False, timeout=420,
             on_started=kill_r_a)
    assert sorted(res["peers"]) == UNITS and not res["given_up"]
    for u in UNITS:
        got = [plan_key(a) for a in mesh_alerts(out, u) if a["category"] != "system-problem"]
        assert got == inproc[u], u
    assert killed and json.loads((out / "pids.json").read_text())["r-A"] != killed["pid"]   # a new r-A served
    assert any(e["process"] == "r-A" and "exit_code" in e for e in res["events"])        # its death was seen
    assert any(e["process"] == "r-A" and e.get("restarted") == 1 for e in res["events"])  # and it came back once
    assert set(res["links"]) == {"r-A->r-BN", "r-B->r-BN"}
    for name, st in res["links"].items():   # each router link carried traffic both ways, some of it lost
        assert st["up"]["bytes"] > 0 and st["down"]["bytes"] > 0, name
        assert st["up"]["lost"] + st["down"]["lost"] > 0, name


def test_a_leaf_whose_router_is_down_at_start_says_so_and_exits(tmp_path):
    port = free_port()   # nobody listens there
    p = subprocess.run([sys.executable, "-m", "saim_mesh", "peer", "--scenario", SC, "--unit", "A", "--sources", "cp.A",
                        "--mode", "client", "--connect", f"tcp/127.0.0.1:{port}", "--root", "t/x"],
                       capture_output=True, text=True, timeout=60)
    assert p.returncode == 4
    assert f"cannot join the mesh at tcp/127.0.0.1:{port}" in p.stderr


def test_each_unit_on_its_command_posts_router_is_well_placed_and_another_router_is_named(tmp_path):
    org = S.load(SMALL, events=False).taskorg
    topo = T.load(topo_file(tmp_path, SMALL_TOPO), org)
    eps = {n: f"tcp/127.0.0.1:{7400 + i}" for i, n in enumerate(topo.routers)}
    for u in org.units:
        assert topo.misplaced(u, org, eps, [eps[topo.router_of(u, org)]]) is None, u
    why = topo.misplaced("A", org, eps, [eps["r-BN"]])
    assert "attached to r-BN, not to its command post's router r-A" in why
    assert "no router of the topology" in topo.misplaced("A", org, eps, ["tcp/127.0.0.1:1"])


@pytest.mark.timeout(120)
def test_a_live_peer_on_the_wrong_router_raises_a_system_problem(tmp_path):
    """A's EA attached to the battalion's router instead of its company's: it works (it is
    told so once it is on the mesh, one system problem), and it still ends cleanly."""
    topo = T.load(topo_file(tmp_path, SMALL_TOPO), S.load(SMALL, events=False).taskorg)
    eps = {n: f"tcp/127.0.0.1:{free_port()}" for n in topo.routers}
    T.resolve(topo, eps, tmp_path / "resolved.json")
    root = f"t/{uuid.uuid4().hex[:8]}"
    with Proc("r-BN", [sys.executable, "-m", "saim_mesh", "router", "--scenario", SC, "--name", "r-BN", "--root",
                       root, "--listen", eps["r-BN"], "--topology", str(tmp_path / "resolved.json")],
              log_dir=tmp_path) as router:
        router.wait_for("router ready", 60)
        with Proc("A", [sys.executable, "-m", "saim_mesh", "peer", "--scenario", SC, "--unit", "A", "--sources", "cp.A",
                        "--mode", "client", "--connect", eps["r-BN"], "--topology", str(tmp_path / "resolved.json"),
                        "--root", root, "--out", str(tmp_path / "A.jsonl"), "--deadline", "3"],
                  log_dir=tmp_path) as peer:
            assert peer.p.wait(60) == 0, peer.tail()
    alerts = [json.loads(x) for x in open(tmp_path / "A.jsonl")]
    wrong = [a for a in alerts if a["details"].get("event") == "wrong-router"]
    assert len(wrong) == 1 and wrong[0]["category"] == "system-problem" and wrong[0]["priority"] == "priority"
    assert "attached to r-BN, not to its command post's router r-A" in wrong[0]["message"]


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
