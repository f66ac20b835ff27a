"""The examples under examples/ against the default mesh (issue 49.3): one `mesh up
scenarios/small` for the module, secure (mTLS, access control, signed commands) with its
EAs behind its router, joined through what it wrote in its output folder (`--mesh OUT`:
the router's endpoint and name, the key root, the PKI). Each example does its one thing
for real: alerts followed, an acknowledgement and an order taken by the EAs (their command
logs say so), a platoon's reports published to an EA that advances on them; and what keeps
one from joining is one line. Processes on loopback, reaped; waits on conditions.

The same mesh runs the top unit's commander's console (issue 31.4, `--console 0`), tried
last through its own HTTP API as the page uses it: the clock comes from the sources'
watermarks, positions from their frames, the EAs' alerts arrive, and an acknowledgement
reaches the EA that raised it (its command log says so)."""
from __future__ import annotations

import json
import subprocess
import sys
import time
import urllib.request

import pytest

from saim_mesh.api import Alerts, MeshError
from saim_mesh.launch.proc import Proc, clean_env, py
from saim_mesh.launch.zenoh_config import free_port

from .conftest import ROOT, SMALL, stop_supervised

pytestmark = pytest.mark.timeout(600)
EX = ROOT / "examples"
SPEED = 20.0   # 270 s of wall time for the whole battle: the module is done long before (teardown stops it)
END_T = 5400.0


@pytest.fixture(scope="module")
def mesh(tmp_path_factory):
    out = tmp_path_factory.mktemp("mesh")
    p = Proc("mesh-up", [*py(), "mesh", "up", str(SMALL), "--units", "BN", "A", "A2", "--speed", f"{SPEED:g}",
                         "--out-dir", str(out), "--console", "0"], env=clean_env(), log_dir=out)
    try:
        p.wait_for("host local: sources", 240)   # its router, EAs and sources are up
        yield out, p
    finally:
        left = stop_supervised(p, out)
    assert not left, f"children of mesh up still running (killed now): {left}"


def example(name: str, out, *args: str, timeout: float = 150.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(EX / name), "--scenario", str(SMALL), "--mesh", str(out), *args],
                          capture_output=True, text=True, timeout=timeout, env=clean_env(), cwd=ROOT)


def until(cond, timeout: float, what: str):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if v := cond():
            return v
        time.sleep(0.2)   # polling a file the EA appends to; bounded by the timeout
    raise AssertionError(f"no {what} within {timeout} s")


def logged(path) -> list[dict]:
    return [json.loads(x) for x in open(path) if x.endswith("\n")] if path.exists() else []


def event_now(out) -> float:
    """The mesh's event time now: its sources play from `paced_start` (host.json) at SPEED."""
    return (time.time() - json.loads((out / "host.json").read_text())["paced_start"]) * SPEED


def running(mesh):
    out, p = mesh
    assert p.exited() is None, f"mesh up ended early: {p.tail()}"
    return out


def test_what_keeps_one_from_joining_is_one_line(mesh, tmp_path):
    out = running(mesh)
    from saim_mesh.security.pki import make_pki
    ep = json.loads((out / "topology.json").read_text())["endpoints"]["hub"]
    with pytest.raises(MeshError, match="no topology.json"):
        Alerts(SMALL, mesh=tmp_path)
    with pytest.raises(MeshError, match="observer: .*ca.pem: file missing"):
        Alerts(SMALL, connect=[ep], routers=["hub"], pki=tmp_path / "nopki")
    with pytest.raises(MeshError, match=f"cannot connect to tls/127.0.0.1:{(port := free_port())}"):
        with Alerts(SMALL, connect=[f"tls/127.0.0.1:{port}"], routers=["hub"], pki=out / "pki"):
            pass
    make_pki(tmp_path / "other", ["observer"])   # another CA: the router refuses it
    with pytest.raises(MeshError, match="cannot connect .*refused this identity"):
        with Alerts(SMALL, mesh=out, pki=tmp_path / "other"):
            pass
    r = example("follow_alerts.py", tmp_path, "--count", "1")
    assert r.returncode == 1 and "Traceback" not in r.stderr, r.stderr
    assert r.stderr.strip().splitlines() == [f"follow_alerts: {tmp_path}: no topology.json: not the output folder "
                                             "of a running `saim-mesh mesh up` or `deploy` (its --out-dir)"]


def test_follow_alerts_on_the_secure_routed_mesh(mesh):
    out = running(mesh)
    r = example("follow_alerts.py", out, "--unit", "BN", "--count", "2", "--timeout", "120")
    assert r.returncode == 0, (r.stdout, r.stderr)
    lines = r.stdout.splitlines()
    assert lines[0] == "following" and len(lines) == 3, lines
    ids = [x.split()[0] for x in lines[1:]]
    assert all(i.startswith("BN/") for i in ids), ids
    # the very alerts BN's EA logged: through the router, checked, nothing made up
    until(lambda: set(ids) <= {a["details"]["id"] for a in logged(out / "BN.jsonl")}, 30, f"{ids} in BN.jsonl")


def test_acknowledge_reaches_the_ea_behind_the_router(mesh):
    out = running(mesh)
    alert = until(lambda: logged(out / "BN.jsonl"), 120, "an alert of BN")[-1]["details"]["id"]
    r = example("acknowledge.py", out, "--unit", "BN", "--alert", alert)
    assert r.returncode == 0, (r.stdout, r.stderr)
    answer = json.loads(r.stdout.strip().splitlines()[-1])
    assert answer["ok"] and answer["kind"] == "ack" and answer["ref"] == alert, answer
    until(lambda: [x for x in logged(out / "BN.cmdlog") if x.get("kind") == "ack" and alert in json.dumps(x)],
          30, f"the ack of {alert} in BN's command log")


def test_an_order_reaches_the_subtree_at_its_event_time(mesh):
    """A's commander orders abort-plan some 30 s of wall time ahead of the mesh's event time:
    A2's EA (A's subordinate) takes it when its sources' watermarks pass it, and answers."""
    out = running(mesh)
    at = float(int(event_now(out) + 30 * SPEED))
    assert at < END_T - 60 * SPEED, f"mesh up too far on ({at} s of event time): no time left for an order"
    r = example("order_subtree.py", out, "--unit", "A", "--action", "abort-plan", "--at", f"{at:g}",
                "--expect", "A2", "--wait", "120", timeout=200)
    assert r.returncode == 0, (r.stdout, r.stderr)
    answers = {a["unit"]: a for a in map(json.loads, r.stdout.splitlines()[1:])}
    assert answers["A2"]["ok"] and answers["A2"]["kind"] == "order" and answers["A2"]["t"] == at, answers
    rows = until(lambda: [x for x in logged(out / "A2.cmdlog") if x["kind"] == "dir.order"], 30, "A2's order row")
    assert [(x["by"], x["t"], x["ok"]) for x in rows] == [("A", at, True)]


def test_publish_reports_feeds_an_ea_behind_the_router(mesh, tmp_path):
    """One more EA (A1, which this mesh does not run) joins behind the mesh's router as
    `mesh up` starts its own, depending on one source, cp.A1; the example publishes A1's
    reports as that source: the EA takes every one of them and ends with the stream."""
    out = running(mesh)
    topo = json.loads((out / "topology.json").read_text())
    root = json.loads((out / "host.json").read_text())["deployment"]["root"]
    ea = Proc("ea-A1", [*py(), "peer", "--scenario", str(SMALL), "--unit", "A1", "--sources", "cp.A1",
                        "--connect", topo["endpoints"]["hub"], "--mode", "client", "--topology",
                        str(out / "topology.json"), "--pki", str(out / "pki"), "--root", root,
                        "--out", str(tmp_path / "A1.jsonl")], env=clean_env(), log_dir=tmp_path)
    try:
        ea.wait_for("ready A1", 120)
        r = example("publish_reports.py", out, "--unit", "A1", "--name", "cp.A1")
        assert r.returncode == 0 and r.stdout.startswith("published "), (r.stdout, r.stderr)
        n = int(r.stdout.split()[1])
        summary = json.loads(ea.wait_for("summary ", 120)[len("summary "):])
        assert ea.p.wait(60) == 0
    finally:
        ea.stop()
    assert n > 0 and summary["depends"] == ["cp.A1"] and summary["frames"] > 0, summary
    assert summary["messages"] >= n and not summary["rejects"] and not summary["lost"], summary


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


def test_the_console_draws_the_live_mesh_and_acks_reach_the_ea(mesh):
    out = running(mesh)
    url = mesh[1].wait_for("http://127.0.0.1:", 60).split()[0].rstrip("/")
    st = until(lambda: (s := get(f"{url}/api/state"))["t"] > 60 and s["positions"] and s, 120, "clock and positions")
    assert st["unit"] == "BN"
    acked = lambda: [json.dumps(x) for x in logged(out / "BN.cmdlog") if '"ack"' in json.dumps(x)]   # noqa: E731
    urgent = until(lambda: [a for a in get(f"{url}/api/state")["alerts"]   # one no other test acknowledged
                            if a["owner"] == "BN" and a["priority"] in ("flash", "immediate")
                            and not any(a["details"]["id"] in x for x in acked())], 200,
                   "an urgent alert of BN not acknowledged yet")
    aid = urgent[0]["details"]["id"]
    code, res = post(f"{url}/api/ack", {"unit": "BN", "alert": aid})
    assert code == 200 and res["ok"], res
    until(lambda: [x for x in acked() if aid in x], 60, f"the console's ack of {aid} in BN's command log")
    t_late = get(f"{url}/api/state")["t"]
    assert t_late >= st["t"]   # the clock only moves forward
