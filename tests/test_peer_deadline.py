"""A live EA peer whose source never comes (no router, no source: only the peer on
loopback): the source is declared lost after `[mesh] source_join_s`, one system-problem
alert naming it, and the peer ends cleanly with its summary; with a longer join limit,
`--deadline` ends it first, again cleanly. Bounded, every child reaped."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from saim_mesh.launch.proc import clean_env
from saim_mesh.launch.zenoh_config import free_port

from .conftest import ROOT, SMALL

pytestmark = pytest.mark.timeout(120)


def peer(tmp_path, join_s: float, deadline: float) -> tuple[subprocess.CompletedProcess, list[dict]]:
    cfg = tmp_path / f"join-{join_s}.toml"
    cfg.write_text(f"[mesh]\nsource_join_s = {join_s}\nsource_silence_s = {join_s}\n")
    out = tmp_path / f"A2-{join_s}.jsonl"
    r = subprocess.run([sys.executable, "-m", "saim_mesh", "peer", "--scenario", str(SMALL), "--unit", "A2",
                        "--sources", "cp.A", "--listen", f"tcp/127.0.0.1:{free_port()}", "--root", "t/deadline",
                        "--config", str(cfg), "--deadline", str(deadline), "--out", str(out)],
                       capture_output=True, text=True, timeout=90, env=clean_env(), cwd=ROOT)
    return r, [json.loads(x) for x in open(out)] if out.exists() else []


def summary(r) -> dict:
    return json.loads(next(x for x in r.stdout.splitlines() if x.startswith("summary "))[len("summary "):])


def test_a_source_never_heard_is_one_alert_and_the_peer_ends_cleanly(tmp_path):
    r, alerts = peer(tmp_path, 1.0, 10.0)   # lost after 1 s; the deadline then ends it
    assert r.returncode == 0, r.stderr[-2000:]
    lost = [a for a in alerts if a["details"].get("event") == "source-lost"]
    assert len(lost) == 1 and lost[0]["details"]["source"] == "cp.A" and lost[0]["category"] == "system-problem"
    assert summary(r)["lost"] == {"cp.A": "never heard in 1 s"}


def test_the_deadline_ends_a_peer_that_still_waits_for_its_source(tmp_path):
    r, alerts = peer(tmp_path, 60.0, 3.0)
    assert r.returncode == 0, r.stderr[-2000:]
    assert summary(r)["lost"] == {}   # still waiting for cp.A when the deadline passed
    assert not [a for a in alerts if a["details"].get("event") == "source-lost"]
