"""The commander's console on the live mesh (issue 31.4): `mesh up --sources-per-cp
--console` on the small scenario (a source per command post, no replay, mTLS and access
control). Through the console's own HTTP API, as the page uses it: the clock comes from
the sources' watermarks, positions from their frames, the EAs' alerts arrive, and an
acknowledgement reaches the EA that raised it (its command log says so)."""
from __future__ import annotations

import json
import time
import urllib.request

import pytest

from saim_mesh.proc import Proc, clean_env, py

from .conftest import SMALL

pytestmark = pytest.mark.timeout(420)


def get(url: str) -> dict:
    with urllib.request.urlopen(url, timeout=10) as r:
        return json.loads(r.read())


def post(url: str, body: dict) -> tuple[int, dict]:
    req = urllib.request.Request(url, json.dumps(body).encode(), {"Content-Type": "application/json"})
    try:
        with urllib.request.urlopen(req, timeout=30) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read())


def until(cond, timeout: float, what: str):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        v = cond()
        if v:
            return v
        time.sleep(0.2)   # polling the page's API, as the page would; bounded by the timeout
    raise AssertionError(f"no {what} within {timeout} s")


def test_the_console_draws_the_live_mesh_and_acks_reach_the_ea(tmp_path):
    p = Proc("mesh-up", [*py(), "mesh", "up", str(SMALL), "--sources-per-cp", "--units", "BN", "A", "A2",
                         "--speed", "30", "--out-dir", str(tmp_path), "--console", "0", "--console-linger", "60"],
             env=clean_env(), log_dir=tmp_path)
    try:
        url = p.wait_for("http://127.0.0.1:", 180).split()[0].rstrip("/")
        st = until(lambda: (s := get(f"{url}/api/state"))["t"] > 60 and s["positions"] and s, 120, "clock and positions")
        assert st["unit"] == "BN"
        urgent = until(lambda: [a for a in get(f"{url}/api/state")["alerts"]
                                if a["owner"] == "BN" and a["priority"] in ("flash", "immediate")], 200,
                       "an urgent alert of BN")
        aid = urgent[0]["details"]["id"]
        code, res = post(f"{url}/api/ack", {"unit": "BN", "alert": aid})
        assert code == 200 and res["ok"], res
        logged = until(lambda: [json.loads(x) for x in open(tmp_path / "BN.cmdlog") if '"ack"' in x]
                       if (tmp_path / "BN.cmdlog").exists() else None, 60, "the ack in BN's command log")
        assert any(aid in json.dumps(x) for x in logged), logged
        t_late = get(f"{url}/api/state")["t"]
        assert t_late >= st["t"]   # the clock only moves forward
    finally:
        left = stop_mesh(p, tmp_path)
    assert not left, f"children of mesh up still running (killed now): {left}"


def stop_mesh(p: Proc, out) -> list[str]:
    """SIGTERM to mesh up, time for it to stop its children (more than Proc.stop's 5 s),
    then any child still alive is named and killed: none may outlive the test."""
    import os
    import signal
    p.stop(timeout=90)
    pids = json.loads((out / "pids.json").read_text()) if (out / "pids.json").exists() else {}
    left = []
    for name, pid in pids.items():
        try:
            os.kill(int(pid), 0)
            if not open(f"/proc/{int(pid)}/stat").read().split(") ", 1)[1].startswith("Z"):
                left.append(name)
                os.kill(int(pid), signal.SIGKILL)
        except (ProcessLookupError, ValueError, TypeError, FileNotFoundError):
            pass
    return left
