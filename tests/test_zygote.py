"""The zygote the EA peers fork from: a launcher killed outright (no chance to stop its
children) takes the zygote with it, and the zygote its children: no orphan peers."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

LAUNCHER = r"""
import json, sys, time
from saim_mesh.launch import zygote
p = zygote.spawner()(["link", "--listen", "0", "--to", "1"], sys.argv[1], None)
print(json.dumps({"child": p.pid, "zygote": zygote._shared.p.pid}), flush=True)
time.sleep(120)
"""


def _gone(pid: int, timeout: float) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return True
        time.sleep(0.05)
    return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="prctl(PR_SET_PDEATHSIG) is Linux's")
@pytest.mark.timeout(60)
def test_a_killed_launcher_leaves_no_orphan_peers(tmp_path):
    log = tmp_path / "child.log"
    launcher = subprocess.Popen([sys.executable, "-c", LAUNCHER, str(log)], stdout=subprocess.PIPE, text=True)
    pids: dict = {}
    try:
        pids = json.loads(launcher.stdout.readline())
        end = time.monotonic() + 30
        while "link ready" not in (log.read_text() if log.exists() else "") and time.monotonic() < end:
            time.sleep(0.05)
        assert "link ready" in log.read_text()
        launcher.send_signal(signal.SIGKILL)
        launcher.wait(10)
        assert _gone(pids["zygote"], 10) and _gone(pids["child"], 10)
        assert "stats {" in log.read_text()   # the child was told (SIGTERM) and stopped cleanly
    finally:
        if launcher.poll() is None:
            launcher.kill()
            launcher.wait()
        for pid in pids.values():   # a failed run leaves nothing behind either
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


WARM = r"""
import importlib, json, os, sys
from saim_mesh.launch import zygote
from saim_mesh.live import warm
for m in zygote.PRELOAD:
    importlib.import_module(m)
tasks = sorted(os.listdir("/proc/self/task"))
fresh = "ea_agent.domains.suo.needs" in sys.modules
n = warm.warm(zygote.WARM_SCENARIO)
again = warm.warm(zygote.WARM_SCENARIO)
problem = zygote.warm_up()   # what `serve` runs
print(json.dumps({"n": n, "again": again, "problem": problem, "tasks_before": tasks,
                  "tasks_after": sorted(os.listdir("/proc/self/task")), "needs_before": fresh,
                  "needs_after": "ea_agent.domains.suo.needs" in sys.modules, "modules": sorted(sys.modules)}))
"""
@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc/self/task is Linux's")
@pytest.mark.timeout(120)
def test_the_warm_up_runs_a_live_peer_and_leaves_no_thread_to_fork_under():
    """The zygote forks after its warm-up: a thread started there (Zenoh's runtime, a
    pool) would be missing in every child, holding whatever lock it held. The warm-up is
    the live peer's, the same every time."""
    out = subprocess.run([sys.executable, "-c", WARM], capture_output=True, text=True, timeout=100)
    assert out.returncode == 0, out.stderr
    res = json.loads(out.stdout.strip().splitlines()[-1])
    assert res["n"] > 1000 and res["again"] == res["n"]   # the sources' first half hour went through the peer
    assert res["problem"] is None
    assert res["tasks_after"] == res["tasks_before"]
    assert not res["needs_before"] and res["needs_after"]   # code a peer imports on first use is in
    assert "saim_mesh.live.peer" in res["modules"] and "saim_mesh.live.order" in res["modules"]


LIVE_PEER = r"""
import importlib, json, sys
from saim_mesh.launch import zygote
for m in zygote.PRELOAD:
    importlib.import_module(m)
zygote.warm_up()
from saim_mesh.live import serve
serve.serve = lambda peer, *a, **k: {}   # on the mesh: only Zenoh's wiring (imported above)
from saim_mesh.cli import main
code = main(["peer", "--scenario", str(zygote.WARM_SCENARIO), "--unit", "A", "--sources", "cp.A", "cp.BN",
             "--out", sys.argv[1]])
print(json.dumps({"code": code, "modules": sorted(sys.modules)}))
"""


@pytest.mark.timeout(120)
def test_a_live_peer_starts_after_the_zygotes_imports_and_warm_up(tmp_path):
    """What a forked EA peer runs (the zygote's imports and warm-up, then `saim-mesh peer
    --sources`, up to its session) works in a process that went through the warm-up.
    (That none of it imports a removed module: tests/test_layers.py.)"""
    out = subprocess.run([sys.executable, "-c", LIVE_PEER, str(tmp_path / "A.jsonl")], capture_output=True,
                         text=True, timeout=100)
    assert out.returncode == 0, out.stderr
    res = json.loads(out.stdout.strip().splitlines()[-1])
    assert res["code"] == 0
    assert "saim_mesh.live.peer" in res["modules"]


def test_a_warm_up_that_fails_is_named_and_the_zygote_goes_on(tmp_path):
    from saim_mesh.launch import zygote
    bad = tmp_path / "nowhere"
    problem = zygote.warm_up(bad)
    assert problem is not None and str(bad) in problem and problem.startswith("zygote: no warm-up")
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "scenario.json").write_text("{not json")
    problem = zygote.warm_up(broken)   # a scenario that does not load: returned, not raised
    assert problem is not None and str(broken) in problem


@pytest.mark.timeout(60)
def test_a_zygote_that_cannot_warm_up_says_so_and_still_forks(tmp_path, capfd):
    from saim_mesh.launch import zygote
    bad = tmp_path / "nowhere"
    env = dict(os.environ, SAIM_ZYGOTE_WARM=str(bad))
    z = zygote.Zygote(env)
    try:
        log = tmp_path / "child.log"
        p = z.spawn([sys.executable, "-m", "saim_mesh", "link", "--help"], str(log), env)
        assert p.wait(30) == 0
        assert "usage" in log.read_text()
    finally:
        z.close()
    assert f"zygote: no warm-up ({bad}" in capfd.readouterr().err
