"""A robot killed mid-pursuit on the live robot mesh (issue 51.5; the removed
tests/test_mesh_uv.py::test_a_robot_killed_mid_pursuit_raises_no_status_at_its_teammates):
its radio (its source, cp.UGV1) and its EA die with no goodbye while it pursues EV1; the
operator's EA and the EAs of its teammates within radio range of it (each robot's EA says
no-status only of a teammate within its comm range) raise a `no-status` alert naming it,
due `no_status_s` of event time after its last state."""
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
from saim_mesh.launch.proc import Proc, clean_env, py
from saim_mesh.launch.zenoh_config import free_port

from .conftest import ROOT
from .test_live import load, reap
from .test_live_coverage_fusion import sources

UV = ROOT / "scenarios" / "uv-team"
VICTIM = "UGV1"   # pursues EV1 from t=372.5 (scenarios/uv-team)
DIES_AT = 400.0   # event time its radio says its last


@pytest.mark.timeout(400)
def test_a_robot_killed_mid_pursuit_raises_no_status_at_the_operator_and_its_teammates(tmp_path):
    sc = S.load(UV)
    ep, root = f"tcp/127.0.0.1:{free_port()}", f"test/{uuid.uuid4().hex[:8]}"
    cfg = tmp_path / "ea.toml"   # a dead radio is declared lost sooner than by default: a shorter test
    cfg.write_text("[mesh]\nsource_silence_s = 5.0\nsource_end_wait_s = 3.0\n")
    srcs = sources(UV)
    assert f"cp.{VICTIM}" in srcs, srcs
    units = list(sc.taskorg.units)
    procs: list[Proc] = []
    try:
        router = Proc("router", [*py(), "router", "--scenario", str(UV), "--name", "hub", "--listen", ep, "--root",
                                 root], env=clean_env(), log_dir=tmp_path)
        procs.append(router)
        router.wait_for("router ready", 60)
        eas = {u: Proc(f"peer-{u}", [*py(), "peer", "--scenario", str(UV), "--unit", u, "--connect", ep, "--mode",
                                     "client", "--root", root, "--sources", *srcs, "--config", str(cfg), "--out",
                                     str(tmp_path / f"{u}.jsonl")], env=clean_env(), log_dir=tmp_path)
               for u in units}
        procs += eas.values()
        for u, p in eas.items():
            p.wait_for(f"ready {u}", 90)
        started = {}
        for n, argv in srcs.items():   # the victim's radio stops at DIES_AT and never says its stream ended
            until = ["--until", str(DIES_AT), "--keep-open"] if n == f"cp.{VICTIM}" else []
            started[n] = Proc(f"source-{n}", [*py(), *argv, "--connect", ep, "--mode", "client", "--root", root,
                                              "--speed", "20", "--state", str(tmp_path / "state"), "--linger", "60",
                                              *until], env=clean_env(), log_dir=tmp_path)
        procs += started.values()
        started[f"cp.{VICTIM}"].wait_for(f"end source cp.{VICTIM}", 180)
        for p in (started[f"cp.{VICTIM}"], eas[VICTIM]):   # the robot dies: no goodbye
            os.kill(p.pid, signal.SIGKILL)
            p.p.wait(10)
        summaries = {u: json.loads(p.wait_for("summary ", 240).split(" ", 1)[1]) for u, p in eas.items()
                     if u != VICTIM}
    finally:
        reap(procs)
    last = max(e.t for e in sc.events if type(e) is UvState and e.robot == VICTIM and e.t <= DIES_AT)
    no_status_s = load_uv_config(None, sc.taskorg.root)["uv"]["no_status_s"]
    at = last_states(sc, DIES_AT)
    _, vx, vy = at[VICTIM]
    robots = [u for u in units if u not in (sc.taskorg.root, VICTIM)]
    hearers = [sc.taskorg.root] + [r for r in robots if r in at and math.dist(
        (vx, vy), at[r][1:]) < sc.taskorg.units[r].attrs["comm_range_m"] * 0.8]
    assert len(hearers) >= 2, hearers   # the operator and at least one teammate in range
    for u in hearers:
        assert f"cp.{VICTIM}" in summaries[u]["depends"] and f"cp.{VICTIM}" in summaries[u]["lost"], summaries[u]
        got = [a for a in load(tmp_path / f"{u}.jsonl")
               if a["type"] == "no-status" and VICTIM in a["subjects"] and a["t"] > last]
        assert got, u
        assert last + no_status_s - 0.01 <= got[0]["t"] <= last + no_status_s + 1.0, (u, last, got[0]["t"])


def last_states(sc, t: float) -> dict[str, tuple[float, float, float]]:
    """Each robot's last state at or before `t`: (its time, x, y)."""
    out: dict[str, tuple[float, float, float]] = {}
    for ev in sc.events:
        if ev.t > t:
            break
        if type(ev) is UvState:
            x, y = sc.projection.to_xy(ev.lon, ev.lat)
            out[ev.robot] = (ev.t, x, y)
    return out
