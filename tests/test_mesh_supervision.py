"""Processes die and the mesh goes on: kill -9 of the replay, a fusion node and a peer
under a supervised, secure `mesh up`; a lost source is an alert and then a clean exit;
a peer with nobody to talk to says so. Multi-process, loopback, bounded, reaped."""
from __future__ import annotations

import json
import os
import signal
import uuid

import pytest

from saim_mesh import scenario as S
from saim_mesh.mesh import start_peer, start_replay
from saim_mesh.proc import Proc, clean_env, py
from saim_mesh.runner import run
from saim_mesh.zconf import free_port

from .conftest import ROOT, SMALL

pytestmark = pytest.mark.timeout(300)
SENSORS = ROOT / "scenarios" / "small-sensors"


def key(a):
    return (a["t"], a["type"], tuple(a["subjects"]), a["message"], a["priority"])


def plan(alerts):
    return [a for a in alerts if a["category"] != "system-problem"]


def load(path):
    return [json.loads(x) for x in open(path)]


@pytest.fixture(scope="module")
def inproc_sensors():
    return {ea.owner: [key(a.to_json_dict()) for a in ea.alerts]
            for ea in run(S.load(SENSORS), ["A", "A2"])}


def _pid(out, name):
    return json.loads((out / "pids.json").read_text())[name]


def test_kill_9_of_replay_fusion_node_and_peer_under_mesh_up(tmp_path, inproc_sensors):
    """One supervised, secure run; the replay, a fusion node and the A2 peer are each
    killed with SIGKILL mid-run. Each is reported and restarted; A's alerts equal the
    fault-free run's, and so do A2's: what fell while it was down is raised late."""
    out = tmp_path / "mesh"
    mesh = Proc("mesh", [*py(), "mesh", "up", str(SENSORS), "--replay", "--units", "A", "A2", "--out-dir", str(out),
                         "--speed", "250"], env=clean_env(), log_dir=tmp_path)
    logs = out / "logs"
    try:
        replay = _follow(logs / "replay.log")
        replay.wait_for("t=1000", 120)
        os.kill(_pid(out, "replay"), signal.SIGKILL)
        mesh.wait_for("supervisor: restarted replay", 60)
        replay = _follow(logs / "replay.log", skip=replay.size())
        replay.wait_for("start resumed", 60)
        replay.wait_for("t=2000", 120)
        os.kill(_pid(out, "fusion-F"), signal.SIGKILL)
        mesh.wait_for("supervisor: restarted fusion-F", 60)
        # down across its flash call for fire (t=3900): a restart now takes a zygote's fork and
        # the 0.5 s backoff (125 s of scenario at 250x), so the kill comes at 3800
        replay.wait_for("t=3800", 120)
        os.kill(_pid(out, "A2"), signal.SIGKILL)
        mesh.wait_for("supervisor: restarted A2", 60)
        mesh.wait_for("2 peers", 240)
        assert mesh.p.wait(60) == 0
    finally:
        mesh.stop()
    summary = json.loads((out / "summary.json").read_text())
    crashed = sorted(e["process"] for e in summary["events"] if "exit_code" in e)
    assert crashed == ["A2", "fusion-F", "replay"] and all(e["exit_code"] == -9 for e in summary["events"]
                                                           if "exit_code" in e)
    assert summary["secure"] and not summary["given_up"]
    a = load(out / "A.jsonl")
    assert [key(x) for x in plan(a)] == inproc_sensors["A"]
    notes = [(x["subjects"][0], x["details"]["event"]) for x in a if x["category"] == "system-problem"]
    assert ("A2", "left") in notes and ("A2", "back") in notes
    assert ("fusion-F", "left") in notes and ("fusion-F", "back") in notes
    a2 = load(out / "A2.jsonl")
    assert [key(x) for x in plan(a2)] == inproc_sensors["A2"]   # nothing lost, nothing twice
    s2 = summary["peers"]["A2"]
    assert s2["restarted"] and s2["joined_t"] >= 3800
    late = [x for x in plan(a2) if x["details"].get("late")]
    want_late = [k for k in inproc_sensors["A2"] if 3800 + 22 <= k[0] <= s2["joined_t"]]
    assert want_late and set(want_late) <= {key(x) for x in late}        # e.g. the flash call for fire
    assert all(x["t"] <= s2["joined_t"] == x["details"]["raised_at_t"] for x in late)
    assert s2["late_alerts"] == len(late)


class _follow:
    """Lines of a log file another process writes (the mesh's children)."""

    def __init__(self, path, skip: int = 0):
        self.path, self.pos, self.lines = path, skip, []

    def size(self) -> int:
        return self.path.stat().st_size if self.path.exists() else 0

    def wait_for(self, text: str, timeout: float) -> str:
        import time
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if self.path.exists():
                with open(self.path, "rb") as f:
                    f.seek(self.pos)
                    chunk = f.read()
                cut = chunk.rfind(b"\n") + 1
                self.pos += cut
                self.lines += chunk[:cut].decode("utf-8", "replace").splitlines()
                for line in self.lines:
                    if line.startswith(text):
                        return line
            time.sleep(0.02)
        raise TimeoutError(f"{self.path.name}: no {text!r} within {timeout} s")


def test_lost_source_is_an_alert_then_a_clean_exit_at_the_deadline(tmp_path):
    """The replay dies and nothing restarts it: the peer raises a system-problem alert
    after `clock_silence_s` and exits with one clear line when `--deadline` passes."""
    cfg = tmp_path / "ea.toml"
    cfg.write_text("[mesh]\nclock_silence_s = 1.0\n")
    ep, root = f"tcp/127.0.0.1:{free_port()}", f"test/{uuid.uuid4().hex[:8]}"
    replay = start_replay(str(SMALL), ep, root, ["A2"], "50", log_dir=tmp_path)
    procs = [replay]
    try:
        replay.wait_for("ready", 60)
        peer = start_peer(str(SMALL), "A2", ep, root, tmp_path / "A2.jsonl", log_dir=tmp_path,
                          extra=["--config", str(cfg), "--deadline", "4"])
        procs.append(peer)
        replay.wait_for("t=200", 60)
        replay.p.kill()
        replay.p.wait(10)
        peer.wait_for("presence SAIM source-silent", 30)
        assert peer.p.wait(30) == 3
        assert any("no clock from the source for 4 s: giving up" in x for x in peer.tail(5))
    finally:
        for p in procs:
            p.stop()
    notes = [a for a in load(tmp_path / "A2.jsonl") if a["category"] == "system-problem"]
    assert [(a["subjects"], a["priority"], a["details"]["event"]) for a in notes] == \
        [(["SAIM"], "immediate", "source-silent")]


def test_peer_with_nothing_to_connect_to_says_so(tmp_path):
    ep = f"tcp/127.0.0.1:{free_port()}"   # nothing listens here
    peer = start_peer(str(SMALL), "A2", ep, "test/nobody", tmp_path / "A2.jsonl", log_dir=tmp_path,
                      extra=["--deadline", "3"])
    try:
        line = peer.wait_for("not connected", 30)
        assert ep in line
        assert peer.p.wait(30) == 3
    finally:
        peer.stop()
