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
from saim_mesh import zygote
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
