"""A commander's commands over the mesh (docs/console.md 1): a replay and A2's EA peer on
the small scenario, loopback, free ports, every child reaped; commands given with the CLI
(`python -m saim_mesh ack|set|...`) and answered on cmdlog/A2. In secure mode, access
control lets `console.<U>` send only as U, and each EA takes commands from the consoles of
its own unit and the units above it as organized now (reorganizations included). Waits are on
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
from saim_mesh import commands as C
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


def start(tmp, pki=None, more=()):
    """A replay up to UNTIL, A2's peer and the peers of units MORE; returns (endpoint,
    root, procs, A2's alert log)."""
    ep = endpoint_tls(free_port()) if pki else f"tcp/127.0.0.1:{free_port()}"
    root = f"test/{uuid.uuid4().hex[:8]}"
    sec = ["--pki", str(pki)] if pki else []
    replay = Proc("replay", [*py(), "replay", SC, "--listen", ep, "--root", root, "--speed", "max",
                             "--until", str(UNTIL), "--linger", "600", *sec, "--wait-peers", "A2", *more],
                  env=clean_env(), log_dir=tmp)
    procs = [replay]
    try:
        replay.wait_for("ready", 60)
        out = tmp / "A2.jsonl"
        procs.append(start_peer(SC, "A2", ep, root, out, pki=pki, log_dir=tmp))
        procs += [start_peer(SC, u, ep, root, tmp / f"{u}.jsonl", pki=pki, log_dir=tmp) for u in more]
        replay.wait_for("end ", 120)
        wait_until(lambda: alerts_in(out), 60, "first alert")
    except BaseException:
        reap(procs)
        raise
    return ep, root, procs, out


def first(out) -> str:
    """The id of the first alert A2's EA raised."""
    return alerts_in(out)[0]["details"]["id"]


def reap(procs):
    for p in procs:
        p.stop()
    assert all(p.p.poll() is not None for p in procs)


def cli(kind, ep, root, *args, pki=None, timeout=10.0, unit="A2"):
    """Run `python -m saim_mesh KIND ...`: (exit code, the printed CmdResult)."""
    sec = ["--pki", str(pki)] if pki else []
    r = subprocess.run([*py(), kind, "--scenario", SC, "--unit", unit, "--connect", ep, "--root", root,
                        "--timeout", str(timeout), *sec, *args],
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
    tmp = tmp_path_factory.mktemp("cmd")
    ep, root, procs, out = start(tmp)
    yield ep, root, procs, out
    reap(procs)


def test_ack_and_set_through_the_cli(plain):
    ep, root, procs, out = plain
    peer = procs[1]
    aid = first(out)
    code, res = cli("ack", ep, root, "--alert", aid, "--by", "test")
    assert code == 0 and res["ok"] and res["kind"] == "ack" and res["error"] == ""
    assert 942.0 <= res["t"] <= UNTIL
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
    code, res = cli("silence", ep, root, "--id", "s1", "--types", "contact", "--until", "5000")
    assert code == 0 and res["ok"] and res["kind"] == "silence"
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
    from saim_mesh import cmdlog
    rule = [c.cmd for c in cmdlog.read([out.with_name("A2.cmdlog")]) if type(c.cmd) is W.InhibitCmd]
    assert rule and rule[0].source.types == ["contact"]   # replayable by run --commands
    code, res = cli("confirm", ep, root, "--mission", "no-such-mission", "--phase", "start")
    assert code == 2 and "unknown mission" in res["error"]
    code, res = cli("cff", ep, root, "--cff", "no-such-cff", "--action", "confirm")
    assert code == 2 and "unknown call for fire" in res["error"]
    assert peer.p.poll() is None


def test_malformed_commands_are_counted_and_answered(plain):
    ep, root, procs, out = plain
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
    assert procs[1].p.poll() is None   # the peer keeps working
    code, res = cli("ack", ep, root, "--alert", aid)
    assert code == 0 and res["ok"]


def test_access_control_limits_commands_to_the_subtree(tmp_path):
    sc = S.load(SMALL, events=False)
    pki = tmp_path / "pki"
    make_pki(pki, names_for(sc, consoles=True))
    ep, root, procs, out = start(tmp_path, pki, more=["R"])
    aid = first(out)
    try:
        # R went from A to BN at 600 s; the peers are at 1000 s: R's EA refuses A's console
        # and says why, and takes BN's; no console can claim another unit in the key
        code, res = cli("set", ep, root, "--key", "voi.out_of_position_m", "--value", "400", "--as", "console.A",
                        pki=pki, unit="R")
        assert code == 2 and res["error"] == "the console of A does not command R (its chain of command is now BN/R)"
        assert 600 < res["t"] <= UNTIL
        for who in ("console.BN", "console.R"):
            code, res = cli("set", ep, root, "--key", "voi.out_of_position_m", "--value", "400", "--as", who,
                            pki=pki, unit="R")
            assert code == 0 and res["ok"], (who, res)
        assert forged(ep, root, pki, "console.A", C.make("ack", alert="R/1"), "R", by="BN") is None
        for who in ("ea.C", "ea.A2"):   # not a console: access control drops it
            code, res = cli("ack", ep, root, "--alert", aid, "--as", who, pki=pki, timeout=4.0)
            assert code == 2 and not res["ok"] and "no answer" in res["error"], who
        code, res = cli("ack", ep, root, "--alert", aid, "--as", "console.C", pki=pki)   # not above A2
        assert code == 2 and res["error"] == "the console of C does not command A2 (its chain of command is now BN/A/A2)"
        for who in ("console.A2", "console.A", "console.BN"):
            code, res = cli("ack", ep, root, "--alert", aid, "--as", who, pki=pki)
            assert code == 0 and res["ok"], (who, res)
        code, res = cli("ack", ep, root, "--alert", aid, pki=pki)   # default identity: console.A2
        assert code == 0 and res["ok"]
        procs[1].wait_for("cmd ack", 10)
        answered = [ln for ln in procs[1].tail(10_000) if ln.startswith("cmd ")]
        assert len(answered) == 5 and sum("ok=True" in ln for ln in answered) == 4   # ea.* never arrived
        by_r = [ln for ln in procs[2].tail(10_000) if ln.startswith("cmd ")]
        assert len(by_r) == 3 and sum("ok=True" in ln for ln in by_r) == 2   # the forged one never arrived
    finally:
        reap(procs)


def forged(ep, root, pki, who, cmd, unit, by, wait=4.0):
    """Publish `cmd` to `unit` as identity `who` under a key naming `by`'s console; the
    EA's answer, or None when none came (access control dropped it)."""
    sc = S.load(SMALL, events=False)
    ks = KeySpace(root)
    answers: queue.Queue = queue.Queue()
    with zenoh.open(config(None, [ep], None, False, pki, who, sc, root)) as s:
        sub = s.declare_subscriber(ks.cmdlog(unit), lambda smp: answers.put(smp.payload.to_bytes()))
        s.put(ks.cmd(unit, "ack", by), W.encode(cmd))
        end = time.monotonic() + wait
        try:
            while (left := end - time.monotonic()) > 0:
                r = msgspec.msgpack.decode(answers.get(timeout=left), type=W.CmdResult)
                if r.req == cmd.req:
                    return r
        except queue.Empty:
            return None
        finally:
            sub.undeclare()
    return None
