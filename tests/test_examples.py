"""The examples under examples/ run, against a live EA peer with no replay (issue 31):
one publishes a platoon's reports as a source, one follows that platoon's alerts, one
acknowledges the first. Processes on loopback, free ports, reaped; waits on printed lines."""
from __future__ import annotations

import json
import subprocess
import sys
import uuid

import pytest

from saim_mesh.launch.proc import Proc, clean_env, py
from saim_mesh.launch.zenoh_config import free_port

from .conftest import ROOT, SMALL

pytestmark = pytest.mark.timeout(240)
EX = ROOT / "examples"


def _peer_a2(tmp_path, linger: int) -> tuple[Proc, list[str]]:
    """An EA peer for A2 listening on a fresh loopback port, its source the examples'
    reporter; and the arguments that point an example at it."""
    ep, root = f"tcp/127.0.0.1:{free_port()}", f"test/{uuid.uuid4().hex[:8]}"
    peer = Proc("peer-A2", [*py(), "peer", "--scenario", str(SMALL), "--unit", "A2", "--listen", ep, "--root", root,
                            "--sources", "reporter", "--out", str(tmp_path / "A2.jsonl"), "--linger", str(linger)],
                env=clean_env(), log_dir=tmp_path)
    return peer, ["--scenario", str(SMALL), "--connect", ep, "--root", root]


def _publish_reports(common: list[str]) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(EX / "publish_reports.py"), *common, "--name", "reporter"],
                          capture_output=True, text=True, timeout=120, env=clean_env(), cwd=ROOT)


def test_the_examples_publish_follow_and_acknowledge(tmp_path):
    peer, common = _peer_a2(tmp_path, 120)
    follow = None
    try:
        peer.wait_for("ready A2", 60)
        follow = Proc("follow", [sys.executable, str(EX / "follow_alerts.py"), *common, "--count", "2"],
                      env=clean_env(), log_dir=tmp_path)
        follow.wait_for("following", 60)
        pub = _publish_reports(common)
        assert pub.returncode == 0 and "published" in pub.stdout, pub.stderr
        first = follow.wait_for("A2/", 60)   # the first alert's line: its id (whatever its form), t, ...
        aid = first.split()[0]
        assert follow.p.wait(60) == 0
        peer.wait_for("end ", 60)
        logged = [json.loads(x) for x in open(tmp_path / "A2.jsonl")]
        assert logged[0]["details"]["id"] == aid and logged[0]["message"] in first
        ack = subprocess.run([sys.executable, str(EX / "acknowledge.py"), *common, "--alert", aid],
                             capture_output=True, text=True, timeout=60, env=clean_env(), cwd=ROOT)
        assert ack.returncode == 0, (ack.stdout, ack.stderr)
        answer = json.loads(ack.stdout.strip().splitlines()[-1])
        assert answer["ok"] and answer["kind"] == "ack" and answer["ref"] == aid
        bad = subprocess.run([sys.executable, str(EX / "acknowledge.py"), *common, "--alert", "A2/no-such-alert"],
                             capture_output=True, text=True, timeout=60, env=clean_env(), cwd=ROOT)
        assert bad.returncode == 2 and "unknown alert" in bad.stdout
    finally:
        for p in (follow, peer):
            if p is not None:
                p.stop()


def test_the_order_example_reaches_the_subtree_at_its_event_time(tmp_path):
    """A's commander orders abort-plan at event time 600; A2's EA (A's subordinate) takes it
    when its source's watermark passes 600 and answers; its command log says when."""
    peer, common = _peer_a2(tmp_path, 60)
    order = None
    try:
        peer.wait_for("ready A2", 60)
        order = Proc("order", [sys.executable, str(EX / "order_subtree.py"), *common, "--unit", "A", "--action",
                               "abort-plan", "--at", "600", "--expect", "A2"], env=clean_env(), log_dir=tmp_path)
        order.wait_for("ordered", 60)
        pub = _publish_reports(common)
        assert pub.returncode == 0, pub.stderr
        answer = json.loads(order.wait_for('{"unit": "A2"', 90))
        assert order.p.wait(60) == 0
        assert answer["ok"] and answer["kind"] == "order" and answer["t"] == 600.0, answer
        peer.wait_for("end ", 60)
    finally:
        for p in (order, peer):
            if p is not None:
                p.stop()
    rows = [json.loads(x) for x in open(tmp_path / "A2.cmdlog")]
    assert [(r["kind"], r["by"], r["t"], r["ok"]) for r in rows] == [("dir.order", "A", 600.0, True)]
