"""A commander's commands over the mesh (docs/console.md 1): A2's EA peer on the small
scenario fed by one source up to H+16:40, loopback, free ports, every child reaped;
commands given with the CLI (`python -m saim_mesh ack|set|...`) and answered on
cmdlog/A2 while the peer lingers after its source's end. Waits are on what the processes
print or write, bounded, never sleeps for synchronisation."""
from __future__ import annotations

import json
import queue
import subprocess
import time
import uuid

import msgspec
import pytest
import zenoh

from dissemination.keyspace import KeySpace
from saim_mesh.authority import commands as C
from saim_mesh import scenario as S
from saim_mesh.protocol import wire as W
from saim_mesh.launch.proc import Proc, clean_env, py
from saim_mesh.launch.zenoh_config import config, free_port

from .conftest import ROOT, SMALL

pytestmark = pytest.mark.timeout(240)
SC = str(SMALL)
UNTIL = 1000.0   # the source's stream ends here; the peer lingers, taking commands


def wait_until(fn, timeout: float = 60.0, what: str = ""):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = fn()
        if v:
            return v
        time.sleep(0.05)
    raise TimeoutError(f"no {what} within {timeout} s")


def alerts_in(path):
    try:
        return [json.loads(x) for x in open(path) if x.strip()]
    except FileNotFoundError:
        return []


def reap(procs):
    for p in procs:
        p.stop()
    assert all(p.p.poll() is not None for p in procs)


def cli(kind, ep, root, *args, timeout=10.0, unit="A2"):
    """Run `python -m saim_mesh KIND ...`: (exit code, the printed CmdResult)."""
    r = subprocess.run([*py(), kind, "--scenario", SC, "--unit", unit, "--connect", ep, "--root", root,
                        "--timeout", str(timeout), *args],
                       capture_output=True, text=True, cwd=ROOT, timeout=60 + timeout, env=clean_env())
    assert r.stdout.strip(), r.stderr
    return r.returncode, json.loads(r.stdout.strip().splitlines()[-1])


def test_authority_follows_the_task_organization():
    to = S.load(SMALL, events=False).taskorg.copy()
    assert C.authority(to, "A", "R") is None and C.authority(to, "BN", "R") is None
    assert C.authority(to, "R", "R") is None and "does not command A" in C.authority(to, "A2", "A")
    to.resubordinate("R", "BN")   # the small plan's reorganization at 600 s
    assert C.authority(to, "A", "R") == "the console of A does not command R (its chain of command is now BN/R)"
    assert C.authority(to, "BN", "R") is None
    assert "not a unit above it" in C.authority(to, "ZZ", "R") and "not a unit" in C.authority(None, "A", "R")
    assert C.by_of("console.A", "R") == "A" and C.by_of("console", "R") == "R" and C.by_of("ea.C", "A2") == "A2"


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    """A2's EA peer (listening) and one source of everything up to UNTIL; the peer has
    ended its stream and lingers. Yields (endpoint, root, peer, A2's alert log)."""
    tmp = tmp_path_factory.mktemp("cmd")
    ep, root = f"tcp/127.0.0.1:{free_port()}", f"test/{uuid.uuid4().hex[:8]}"
    out = tmp / "A2.jsonl"
    peer = Proc("peer-A2", [*py(), "peer", "--scenario", SC, "--unit", "A2", "--listen", ep, "--root", root,
                            "--sources", "cp.all", "--out", str(out), "--linger", "600"], env=clean_env(), log_dir=tmp)
    procs = [peer]
    try:
        peer.wait_for("ready A2", 60)
        procs.append(Proc("source-cp.all", [*py(), "source", SC, "--name", "cp.all", "--connect", ep, "--root", root,
                                            "--tracks", "--speed", "max", "--until", str(UNTIL), "--linger", "600"],
                          env=clean_env(), log_dir=tmp))
        peer.wait_for("end {", 120)   # its source ended: the EA finished, the peer lingers
        wait_until(lambda: alerts_in(out), 60, "first alert")
        yield ep, root, peer, out
    finally:
        reap(procs)


def first(out) -> str:
    """The id of the first alert A2's EA raised."""
    return alerts_in(out)[0]["details"]["id"]


def test_ack_and_set_through_the_cli(plain):
    ep, root, peer, out = plain
    aid = first(out)
    code, res = cli("ack", ep, root, "--alert", aid, "--by", "test")
    assert code == 0 and res["ok"] and res["kind"] == "ack" and res["error"] == ""
    assert res["t"] >= 942.0
    assert peer.wait_for(f"cmd ack req={res['req']} ok=True", 10)
    assert aid.startswith("A2/")   # the alert acknowledged is A2's
    code, res = cli("ack", ep, root, "--alert", "A2/999")
    assert code == 2 and not res["ok"] and "unknown alert" in res["error"]
    code, res = cli("set", ep, root, "--key", "voi.out_of_position_m", "--value", "1000000")
    assert code == 0 and res["ok"] and res["kind"] == "set"
    code, res = cli("set", ep, root, "--key", "voi.out_of_position_m", "--value", "-3")
    assert code == 2 and "must be > 0" in res["error"]
    code, res = cli("set", ep, root, "--key", "mesh.fsync", "--value", "1")
    assert code == 2 and "unknown key" in res["error"]
    until = S.load(SMALL, events=False).duration_s + 3600.0   # the EA finished: later than its end
    code, res = cli("silence", ep, root, "--id", "s1", "--types", "contact", "--until", str(until))
    assert code == 0 and res["ok"] and res["kind"] == "silence", res
    code, res = cli("silence", ep, root, "--id", "s1", "--lift")
    assert code == 0 and res["kind"] == "unsilence"
    code, res = cli("inhibit", ep, root, "--id", "r1", "--source-types", "contact", "--target-types", "distance",
                    "strength", "--equal", "subjects")
    assert code == 0 and res["ok"] and res["kind"] == "inhibit" and res["ref"] == "r1"
    code, res = cli("inhibit", ep, root, "--id", "r1", "--lift")
    assert code == 0 and res["ok"] and res["kind"] == "uninhibit"
    code, res = cli("inhibit", ep, root, "--id", "r1", "--lift")
    assert code == 2 and "unknown rule 'r1'" in res["error"]
    logged = [json.loads(x) for x in open(out.with_name("A2.cmdlog"))]
    assert [(x["kind"], x["ok"]) for x in logged][-3:] == [("inhibit", True), ("uninhibit", True),
                                                          ("uninhibit", False)]
    from saim_mesh.logs import cmdlog
    rule = [c.cmd for c in cmdlog.read([out.with_name("A2.cmdlog")]) if type(c.cmd) is W.InhibitCmd]
    assert rule and rule[0].source.types == ["contact"]   # replayable by run --commands
    code, res = cli("confirm", ep, root, "--mission", "no-such-mission", "--phase", "start")
    assert code == 2 and "unknown mission" in res["error"]
    code, res = cli("cff", ep, root, "--cff", "no-such-cff", "--action", "confirm")
    assert code == 2 and "unknown call for fire" in res["error"]
    assert peer.p.poll() is None


def test_malformed_commands_are_counted_and_answered(plain):
    ep, root, peer, out = plain
    aid = first(out)
    ks = KeySpace(root)
    answers: queue.Queue = queue.Queue()
    with zenoh.open(config(connect=[ep])) as s:
        sub = s.declare_subscriber(ks.cmdlog("A2"), lambda smp: answers.put(smp.payload.to_bytes()))
        pub = s.declare_publisher(ks.cmd("A2", "ack", "A2"))
        changes: queue.Queue = queue.Queue()
        with pub.declare_matching_listener(lambda st: changes.put(st.matching)):
            if not pub.matching_status.matching:
                while not changes.get(timeout=10):
                    pass
        pub.put(msgspec.msgpack.encode({"v": 1, "req": "bad-1", "alert": 5}))    # wrong type
        pub.put(b"\xc1 not msgpack")                                               # no req to answer
        pub.put(msgspec.msgpack.encode({"v": 2, "req": "bad-2", "alert": aid}))  # wrong version
        got = {}
        while len(got) < 2:
            r = msgspec.msgpack.decode(answers.get(timeout=10), type=W.CmdResult)
            got[r.req] = r
        sub.undeclare()
    assert not got["bad-1"].ok and "alert" in got["bad-1"].error and got["bad-1"].kind == "ack"
    assert not got["bad-2"].ok
    assert peer.p.poll() is None   # the peer keeps working
    code, res = cli("ack", ep, root, "--alert", aid)
    assert code == 0 and res["ok"]


def test_a_command_given_mode_and_routers_opens_its_session_with_them(monkeypatch):
    """`ack --mode client --routers r0` (a mesh launched by hand through a router): the
    session is opened as a client that accepts router.r0 as a relay, not in peer mode."""
    from saim_mesh.cli import main
    from saim_mesh.launch import zenoh_config
    seen: list[dict] = []

    def config_seen(*args, **kw):
        seen.append(kw)
        raise ConnectionError("stop here: no session in this test")
    monkeypatch.setattr(zenoh_config, "config", config_seen)
    code = main(["ack", "--scenario", SC, "--unit", "A2", "--alert", "A2/1", "--connect", "tcp/127.0.0.1:9",
                 "--mode", "client", "--routers", "r0"])
    assert code == 2 and seen == [{"mode": "client", "routers": ["r0"]}]
