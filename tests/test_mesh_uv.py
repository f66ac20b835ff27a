"""The robot team on the mesh: every robot's EA and the operator's as Zenoh peers
(`mesh up`, secure), each hearing teammates only within communication range as its
subscriptions decide; their alerts equal the in-process run's, and a robot killed
mid-pursuit falls silent and raises no-status at its teammates within the configured
interval. Loopback, free ports, bounded time, every child reaped."""
from __future__ import annotations

import json
import math
import os
import signal
import uuid

import pytest

from ea_agent.domains.uv import load_uv_config
from ea_agent.domains.uv.messages import UvState
from saim_mesh import scenario as S
from saim_mesh.mesh import Proc, start_peer, start_replay, up
from saim_mesh.runner import run
from saim_mesh.zconf import free_port

from .conftest import ROOT

pytestmark = pytest.mark.timeout(300)
UV = ROOT / "scenarios" / "uv-team"


def load(path):
    return [json.loads(line) for line in open(path)]


def plan_alerts(alerts):
    """What the EAs raise from the plan and the states (not wall-clock presence notes)."""
    return [a for a in alerts if not a["details"].get("wall_clock_driven")]


def key(a):
    return (a["t"], a["type"], tuple(a["subjects"]), a["message"], a["priority"])


@pytest.fixture(scope="module")
def sc():
    return S.load(UV)


@pytest.fixture(scope="module")
def inproc(sc):
    eas = run(sc, [sc.taskorg.root, *sorted(u for u in sc.taskorg.units if u != sc.taskorg.root)])
    return {ea.owner: [json.loads(json.dumps(a.to_json_dict())) for a in ea.alerts] for ea in eas}


@pytest.fixture(scope="module")
def mesh_up(tmp_path_factory):
    out = tmp_path_factory.mktemp("uvmesh")
    res = up(str(UV), None, out, timeout=240, echo=lambda *a, **k: None)
    return res, {u: load(out / f"{u}.jsonl") for u in res["peers"]}


def test_mesh_up_runs_every_robot_and_the_operator_securely(mesh_up, sc):
    res, _ = mesh_up
    assert res["secure"] and not res["given_up"]
    assert set(res["peers"]) == set(sc.taskorg.units)   # TEAM and every robot have a peer


def test_every_robots_alerts_equal_the_in_process_run(mesh_up, inproc):
    _, alerts = mesh_up
    assert sum(len(v) for v in inproc.values()) > 20
    for unit, want in inproc.items():
        assert [key(a) for a in plan_alerts(alerts[unit])] == [key(a) for a in want], unit


def test_robots_hear_only_what_is_in_range(mesh_up, sc):
    """A robot's subscriptions are selective: it takes fewer messages than the operator,
    who hears every robot, and a ground robot (400 m radio) well under three quarters
    of them (the UAVs' 800 m radio covers most of the 1.5 km area)."""
    res, _ = mesh_up
    took = {u: s["messages"] for u, s in res["peers"].items()}
    team = took[sc.taskorg.root]
    assert team >= 0.95 * len(sc.events), took
    assert all(took[r] < team for r in took if r != sc.taskorg.root), took
    assert all(took[r] < 0.75 * team for r in took if sc.taskorg.units[r].kind == "ugv"), took


def _last_states(sc, t: float) -> dict[str, tuple[float, float, float]]:
    out: dict[str, tuple[float, float, float]] = {}
    for ev in sc.events:
        if ev.t > t:
            break
        if type(ev) is UvState:
            x, y = sc.projection.to_xy(ev.lon, ev.lat)
            out[ev.robot] = (ev.t, x, y)
    return out


def test_a_robot_killed_mid_pursuit_raises_no_status_at_its_teammates(tmp_path, sc):
    victim = "UGV1"   # pursues EV1 from t=372.5 (scenarios/uv-team)
    robots = sorted(u for u in sc.taskorg.units if u != sc.taskorg.root)
    units = [sc.taskorg.root, *robots]
    ep, root = f"tcp/127.0.0.1:{free_port()}", f"test/{uuid.uuid4().hex[:8]}"
    replay = start_replay(str(UV), ep, root, units, speed="10", window=0)
    procs: list[Proc] = [replay]
    try:
        replay.wait_for("ready", 60)
        for u in units:
            procs.append(start_peer(str(UV), u, ep, root, tmp_path / f"{u}.jsonl", u))
        replay.wait_for("t=400", 120)   # mid-pursuit
        os.kill(procs[1 + units.index(victim)].pid, signal.SIGKILL)   # no bye: it just dies
        line = replay.wait_for(f"radio {victim} silent", 60)
        silent_t = float(line.rsplit("t=", 1)[1])
        summaries = {p.name: json.loads(p.wait_for("summary ", 200)[8:]) for p in procs[1:] if p.name != victim}
        replay.p.wait(60)
    finally:
        for p in procs:
            p.stop()
    assert all(p.p.poll() is not None for p in procs)
    assert 400 <= silent_t < 500 and summaries
    last = _last_states(sc, silent_t - 1e-9)
    lt, vx, vy = last[victim]
    no_status_s = load_uv_config(None, sc.taskorg.root)["uv"]["no_status_s"]
    hearers = [sc.taskorg.root] + [r for r in robots if r != victim and r in last and math.dist(
        (vx, vy), last[r][1:]) < sc.taskorg.units[r].attrs["comm_range_m"] * 0.8]
    assert len(hearers) >= 2, hearers   # the operator and at least one teammate in range
    for u in hearers:
        got = [a for a in load(tmp_path / f"{u}.jsonl")
               if a["type"] == "no-status" and victim in a["subjects"] and a["t"] >= silent_t - 1]
        assert got, u
        assert lt + no_status_s - 0.01 <= got[0]["t"] <= lt + no_status_s + 1.0, (u, lt, got[0]["t"])
