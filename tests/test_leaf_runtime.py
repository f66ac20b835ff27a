"""A leaf's Zenoh runs one receive worker (`proc.leaf_env`): Zenoh accepts the setting,
a leaf still talks over a link with it, and its threads are what the setting says."""
from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from saim_mesh.launch.proc import LEAF_RUNTIME, leaf_env

LEAF = r"""
import collections, json, os, sys, threading
import zenoh
from saim_mesh.launch.zenoh_config import free_port
ep = f"tcp/127.0.0.1:{free_port()}"
def conf(**kw):
    c = zenoh.Config()
    c.insert_json5("scouting/multicast/enabled", "false")
    for k, v in kw.items():
        c.insert_json5(k, json.dumps(v))
    return c
with zenoh.open(conf(**{"listen/endpoints": [ep]})) as a, zenoh.open(conf(**{"connect/endpoints": [ep]})) as b:
    got, came = [], threading.Event()
    sub = a.declare_subscriber("leaf/x", lambda s: (got.append(s.payload.to_bytes().decode()), came.set()))
    for _ in range(100):   # until the link is up and the subscription routed
        b.put("leaf/x", b"hello")
        if came.wait(0.1):
            break
    names = collections.Counter(open(f"/proc/self/task/{t}/comm").read().strip().split("-")[0]
                                for t in os.listdir("/proc/self/task"))
    print(json.dumps({"got": got[0] if got else None, "threads": names}))
"""


def _run(env: dict) -> dict:
    out = subprocess.run([sys.executable, "-c", LEAF], env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="thread names from /proc")
@pytest.mark.timeout(120)
def test_a_leaf_runs_one_zenoh_receive_worker_and_still_talks():
    env = leaf_env()
    assert env["ZENOH_RUNTIME"] == LEAF_RUNTIME
    res = _run(env)
    assert res["got"] == "hello"
    assert res["threads"].get("rx") == 1, res["threads"]
    base = _run({k: v for k, v in os.environ.items() if k != "ZENOH_RUNTIME"})
    assert base["got"] == "hello"
    assert base["threads"].get("rx", 0) > 1, base["threads"]   # Zenoh's default: the setting is not a no-op


def test_a_runtime_set_by_the_operator_is_kept(monkeypatch):
    monkeypatch.setenv("ZENOH_RUNTIME", "(rx:(worker_threads:2))")
    assert leaf_env()["ZENOH_RUNTIME"] == "(rx:(worker_threads:2))"
    monkeypatch.setenv("ZENOH_RUNTIME", "")   # empty: Zenoh would panic on it
    assert leaf_env()["ZENOH_RUNTIME"] == LEAF_RUNTIME
