"""A commander's commands over the mesh (docs/console.md 1): a replay and A2's EA peer on
the small scenario, loopback, free ports, every child reaped; commands given with the CLI
(`python -m saim_mesh ack|set|...`) and answered on cmdlog/A2. In secure mode, access
control lets `console.<U>` command the EAs of U's subtree and nobody else. Waits are on
what the processes print or write, bounded, never sleeps for synchronisation."""
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
from saim_mesh import scenario as S
from saim_mesh import wire as W
from saim_mesh.mesh import start_peer
from saim_mesh.proc import Proc, clean_env, py
from saim_mesh.security import endpoint_tls, make_pki, names_for
from saim_mesh.zconf import config, free_port

from .conftest import ROOT, SMALL

pytestmark = pytest.mark.timeout(240)
SC = str(SMALL)
UNTIL = 1000.0   # the replay stops here: the peer waits at its last tick, taking commands


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


def start(tmp, pki=None):
    """A replay up to UNTIL and A2's peer; returns (endpoint, root, procs, alert log)."""
    ep = endpoint_tls(free_port()) if pki else f"tcp/127.0.0.1:{free_port()}"
    root = f"test/{uuid.uuid4().hex[:8]}"
    sec = ["--pki", str(pki)] if pki else []
    replay = Proc("replay", [*py(), "replay", SC, "--listen", ep, "--root", root, "--speed", "max",
                             "--until", str(UNTIL), "--linger", "600", *sec, "--wait-peers", "A2"],
                  env=clean_env(), log_dir=tmp)
    procs = [replay]
    try:
        replay.wait_for("ready", 60)
        out = tmp / "A2.jsonl"
        procs.append(start_peer(SC, "A2", ep, root, out, pki=pki, log_dir=tmp))
        replay.wait_for("end ", 120)
        wait_until(lambda: any(a["details"].get("id") == "A2/1" for a in alerts_in(out)), 60, "first alert")
    except BaseException:
        reap(procs)
        raise
    return ep, root, procs, out


def reap(procs):
    for p in procs:
        p.stop()
    assert all(p.p.poll() is not None for p in procs)


def cli(kind, ep, root, *args, pki=None, timeout=10.0):
    """Run `python -m saim_mesh KIND ...`: (exit code, the printed CmdResult)."""
    sec = ["--pki", str(pki)] if pki else []
    r = subprocess.run([*py(), kind, "--scenario", SC, "--unit", "A2", "--connect", ep, "--root", root,
                        "--timeout", str(timeout), *sec, *args],
                       capture_output=True, text=True, cwd=ROOT, timeout=60 + timeout, env=clean_env())
    assert r.stdout.strip(), r.stderr
    return r.returncode, json.loads(r.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def plain(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cmd")
    ep, root, procs, out = start(tmp)
    yield ep, root, procs, out
    reap(procs)


def test_ack_and_set_through_the_cli(plain):
    ep, root, procs, out = plain
    peer = procs[1]
    code, res = cli("ack", ep, root, "--alert", "A2/1", "--by", "test")
    assert code == 0 and res["ok"] and res["kind"] == "ack" and res["error"] == ""
    assert 942.0 <= res["t"] <= UNTIL
    assert peer.wait_for(f"cmd ack req={res['req']} ok=True", 10)
    assert any(a["details"]["id"] == "A2/1" for a in alerts_in(out))   # the alert acknowledged is A2's
    code, res = cli("ack", ep, root, "--alert", "A2/999")
    assert code == 2 and not res["ok"] and "unknown alert" in res["error"]
    code, res = cli("set", ep, root, "--key", "voi.out_of_position_m", "--value", "1000000")
    assert code == 0 and res["ok"] and res["kind"] == "set"
    code, res = cli("set", ep, root, "--key", "voi.out_of_position_m", "--value", "-3")
    assert code == 2 and "must be > 0" in res["error"]
    code, res = cli("set", ep, root, "--key", "mesh.fsync", "--value", "1")
    assert code == 2 and "unknown key" in res["error"]
    code, res = cli("silence", ep, root, "--id", "s1", "--types", "contact", "--until", "5000")
    assert code == 0 and res["ok"] and res["kind"] == "silence"
    code, res = cli("silence", ep, root, "--id", "s1", "--lift")
    assert code == 0 and res["kind"] == "unsilence"
    code, res = cli("confirm", ep, root, "--mission", "no-such-mission", "--phase", "start")
    assert code == 2 and "unknown mission" in res["error"]
    code, res = cli("cff", ep, root, "--cff", "no-such-cff", "--action", "confirm")
    assert code == 2 and "unknown call for fire" in res["error"]
    assert peer.p.poll() is None


def test_malformed_commands_are_counted_and_answered(plain):
    ep, root, procs, _ = plain
    ks = KeySpace(root)
    answers: queue.Queue = queue.Queue()
    with zenoh.open(config(connect=[ep])) as s:
        sub = s.declare_subscriber(ks.cmdlog("A2"), lambda smp: answers.put(smp.payload.to_bytes()))
        pub = s.declare_publisher(ks.cmd("A2", "ack"))
        changes: queue.Queue = queue.Queue()
        with pub.declare_matching_listener(lambda st: changes.put(st.matching)):
            if not pub.matching_status.matching:
                while not changes.get(timeout=10):
                    pass
        pub.put(msgspec.msgpack.encode({"v": 1, "req": "bad-1", "alert": 5}))    # wrong type
        pub.put(b"\xc1 not msgpack")                                               # no req to answer
        pub.put(msgspec.msgpack.encode({"v": 2, "req": "bad-2", "alert": "A2/1"}))  # wrong version
        got = {}
        while len(got) < 2:
            r = msgspec.msgpack.decode(answers.get(timeout=10), type=W.CmdResult)
            got[r.req] = r
        sub.undeclare()
    assert not got["bad-1"].ok and "alert" in got["bad-1"].error and got["bad-1"].kind == "ack"
    assert not got["bad-2"].ok
    assert procs[1].p.poll() is None   # the peer keeps working
    code, res = cli("ack", ep, root, "--alert", "A2/1")
    assert code == 0 and res["ok"]


def test_access_control_limits_commands_to_the_subtree(tmp_path):
    sc = S.load(SMALL, events=False)
    pki = tmp_path / "pki"
    make_pki(pki, names_for(sc, consoles=True))
    ep, root, procs, _ = start(tmp_path, pki)
    try:
        for who in ("console.C", "ea.C", "ea.A2"):   # outside A's subtree, or not a console
            code, res = cli("ack", ep, root, "--alert", "A2/1", "--as", who, pki=pki, timeout=4.0)
            assert code == 2 and not res["ok"] and "no answer" in res["error"], who
        for who in ("console.A2", "console.A", "console.BN"):
            code, res = cli("ack", ep, root, "--alert", "A2/1", "--as", who, pki=pki)
            assert code == 0 and res["ok"], (who, res)
        code, res = cli("ack", ep, root, "--alert", "A2/1", pki=pki)   # default identity: console.A2
        assert code == 0 and res["ok"]
        procs[1].wait_for("cmd ack", 10)
        answered = [ln for ln in procs[1].tail(10_000) if ln.startswith("cmd ")]
        assert len(answered) == 4 and all("ok=True" in ln for ln in answered)   # refused ones never arrived
    finally:
        reap(procs)
