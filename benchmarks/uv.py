"""The robot domain's speed, against the paper (7.2, 7.4): a robot's EA takes two state
messages a second from itself and two from each teammate, and must detect every alert
within 1 s. For a team of 20 that is 40 messages/s per robot EA; we aim for 1,000x.

Measured in one run (written to bench/results/uv.json):
- messages/s of one robot's EA and of the operator's (TEAM) EA over a synthetic team of
  20 robots patrolling at 2 Hz, in process; baselines from the same run: the bare loop and
  msgpack decoding of the same stream;
- the robot team in closed loop over the mesh (`closed_loop`, issue 33.5): one simulator
  process per robot (`robot_processes`) obeying the task messages of its own EA (one
  process per EA), `evaluate` on the run it records, and whether its reports and alerts
  equal the closed loop in process;
- detection delay in scenario time on that run (the same as scenarios/uv-team): first
  matching alert minus the ground truth's onset, per incident (p50, p99, max);
- the team of 20 on the mesh at real time (`--live`): 21 EA peers (every robot and the
  operator) and a source per command post; each peer's wall latency from a report to the
  alerts it raised (p50, p99).
"""
from __future__ import annotations

import argparse
import gzip
import json
import math
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from ea_agent.core.geo import Projection
from ea_agent.domains.uv import load_uv_config, make_ea

from saim_mesh.protocol import messages
from saim_mesh import scenario as scenarios

from . import ROOT
from .ea import feed

EPSG, LON0, LAT0 = 32611, -116.60, 35.26
HZ = 2.0


def team_folder(out: Path, n: int = 20, duration_s: float = 600.0) -> Path:
    """A scenario folder: n robots, each patrolling its own 200 m square on a 5-wide grid
    (neighbours within radio range), reporting state at 2 Hz; in each row of five one
    robot stops for a while and one falls silent, so that alerts are raised."""
    proj = Projection(EPSG)
    x0, y0 = proj.to_xy(LON0, LAT0)
    team = [{"id": "TEAM", "name": "Operator", "kind": "team", "parent": None, "attrs": {}}]
    feats, missions, events = [], [], []

    def poly(pid: str, kind: str, cx: float, cy: float, half: float) -> None:
        ring = [(cx - half, cy - half), (cx + half, cy - half), (cx + half, cy + half), (cx - half, cy + half)]
        lon, lat = proj.to_lonlat(np.array([p[0] for p in ring]), np.array([p[1] for p in ring]))
        coords = [[round(a, 7), round(b, 7)] for a, b in zip(lon.tolist(), lat.tolist())]
        feats.append({"type": "Feature", "properties": {"id": pid, "kind": kind},
                      "geometry": {"type": "Polygon", "coordinates": [coords + coords[:1]]}})

    ts = np.arange(0.0, duration_s, 1.0 / HZ)
    for i in range(n):
        rid = f"R{i + 1:02d}"
        cx, cy = x0 + 300.0 * (i % 5), y0 + 300.0 * (i // 5)
        team.append({"id": rid, "name": f"Robot {i + 1}", "kind": "ugv", "parent": "TEAM",
                     "attrs": {"max_speed_mps": 3.0, "turn_rate_dps": 45, "sensor_range_m": 60,
                               "comm_range_m": 400, "radius_m": 0.5}})
        poly(f"PA-{rid}", "patrol-area", cx, cy, 100.0)
        poly(f"SEC-{rid}", "sector", cx, cy, 150.0)
        missions.append({"id": f"{rid}-patrol", "unit": rid, "type": "patrol", "start": {"type": "ASAP"},
                         "end": {"type": "ASAP"}, "after": [], "params": {"area": f"PA-{rid}",
                                                                          "sector": f"SEC-{rid}"}})
        ang = 2 * math.pi * ts / 400.0 + i   # a circle of 80 m radius at ~1.3 m/s
        xs, ys = cx + 80.0 * np.cos(ang), cy + 80.0 * np.sin(ang)
        stop = (i % 5 == 3) & (ts > 0.3 * duration_s) & (ts < 0.5 * duration_s)
        xs[stop], ys[stop] = xs[np.argmax(stop)], ys[np.argmax(stop)]
        lon, lat = proj.to_lonlat(xs, ys)
        hdg = (np.degrees(np.arctan2(np.cos(ang), -np.sin(ang))) % 360.0).round(1) % 360.0
        for k, t in enumerate(ts.tolist()):
            if i % 5 == 2 and 0.5 * duration_s <= t < 0.6 * duration_s:
                continue   # a radio gap: no-status
            events.append({"kind": "uv-state", "t": t, "robot": rid, "lon": round(float(lon[k]), 7),
                           "lat": round(float(lat[k]), 7), "speed_mps": 0.0 if stop[k] else 1.26,
                           "heading_deg": float(hdg[k]), "sigma_m": 1.0, "mode": "moving"})
    events.sort(key=lambda e: (e["t"], e["robot"]))
    out.mkdir(parents=True, exist_ok=True)
    (out / "scenario.json").write_text(json.dumps({
        "name": f"uv-bench-{n}", "domain": "uv", "epsg": EPSG, "duration_s": duration_s,
        "default_eas": ["TEAM", "R01"], "keyspace": {"cell_m": 250}}))
    (out / "world.geojson").write_text(json.dumps({"type": "FeatureCollection", "features": feats}))
    (out / "plan.json").write_text(json.dumps({"team": team, "plans": {"main": missions}, "initial_plan": "main"}))
    with gzip.open(out / "events.jsonl.gz", "wt") as f:
        f.writelines(json.dumps(e) + "\n" for e in events)
    return out


def throughput(sc, owner: str, repeat: int = 3) -> tuple[float, int]:
    best, alerts = math.inf, 0
    for _ in range(repeat):
        ea = make_ea(sc, owner, load_uv_config(None, owner))
        best, alerts = min(best, feed(ea, sc)), len(ea.alerts)
    return len(sc.events) / best, alerts


def pct(xs: list[float]) -> dict:
    if not xs:
        return {"n": 0}
    a = np.array(xs)
    return {"n": len(xs), "p50": round(float(np.percentile(a, 50)), 3), "p99": round(float(np.percentile(a, 99)), 3),
            "max": round(float(a.max()), 3)}


def detection_delays(folder: Path = ROOT / "scenarios" / "uv-team") -> dict:
    """Scenario seconds from each true incident's onset to the first alert matching it."""
    from saim_mesh.inprocess.evaluate import _matches
    from saim_mesh.inprocess.runner import run
    sc = scenarios.load(folder)
    truth = sc.truth()
    alerts = [a for ea in run(sc, truth["owners"]) for a in ea.alerts]
    delays, by_type = [], {}
    for inc in truth["incidents"]:
        hit = [a.t for a in alerts if _matches(a, inc)]
        if hit:
            d = max(0.0, min(hit) - inc["t0"])
            delays.append(d)
            by_type.setdefault(inc["type"], []).append(d)
    return {"incidents": len(truth["incidents"]), "detected": len(delays), "delay_s": pct(delays),
            "delay_s_by_type": {k: pct(v) for k, v in sorted(by_type.items())}}


def closed_loop(timeout: float = 600.0) -> tuple[dict, dict]:
    """The robot team with one simulator process per robot obeying its EA over the mesh
    (`saim_mesh.robots`): processes, wall time, `evaluate` on the run it records, whether
    the mesh's reports and alerts equal the closed loop in process; and the detection
    delays on that run."""
    from ea_agent.domains.uv import generator as uv_generator

    from saim_mesh.inprocess.evaluate import evaluate
    from saim_mesh.robots.team import run_team
    out = Path(tempfile.mkdtemp(prefix="uvloop-"))
    res = run_team(out, timeout=timeout, echo=lambda *a, **k: None)
    loop, _ = uv_generator.simulate(out)
    inproc = {ea.owner: [json.loads(json.dumps(a.to_json_dict())) for a in ea.alerts] for ea in loop.eas}
    ev = evaluate(scenarios.load(out))
    shipped = ROOT / "scenarios" / "uv-team" / "events.jsonl.gz"
    return {"robot_processes": res["robot_processes"], "ea_processes": res["ea_processes"], "secure": res["secure"],
            "wall_s": res["wall_s"], "scenario_s": res["scenario_s"],
            "x_real_time": round(res["scenario_s"] / res["wall_s"], 1),
            "tasks_published": sum(x["published"] for x in res["eas"].values()),
            "tasks_carried_out": sum(x["tasks_taken"] for x in res["robots"].values()),
            "tasks_refused": sum(x["refused"] for x in res["robots"].values()),
            "pursuits": sum(x["commits"] for x in res["robots"].values()),
            "alerts": sum(len(v) for v in res["alerts"].values()),
            "alerts_equal_in_process": res["alerts"] == inproc,
            "events_equal_in_process": (out / "events.jsonl.gz").read_bytes() == uv_generator.events_bytes(loop.events),
            "events_equal_shipped_scenario": (out / "events.jsonl.gz").read_bytes() == shipped.read_bytes(),
            "evaluate": {k: ev[k] for k in ("incidents", "recall", "alerts", "unwanted", "unwanted_share",
                                              "unwanted_flash", "by_type")},
            "alert_types": len(ev["by_type"])}, detection_delays(out)


def mesh_latency(n: int, duration_s: float, timeout: float = 400.0) -> dict:
    """The team on the mesh at real time (`mesh up --live`: event time is the wall clock):
    every robot's and the operator's EA peer, a source per command post, over a scenario as
    long as the run; each peer's latency from a report to the alerts it raised."""
    from saim_mesh.live.up import up
    folder = team_folder(Path(tempfile.mkdtemp(prefix="uvteam-")), n, duration_s)
    sc = scenarios.load(folder, events=False)
    out = Path(tempfile.mkdtemp(prefix="uvbench-"))
    t0 = time.monotonic()
    res = up(str(folder), None, out, "1", live=True, insecure=True, show=False, timeout=timeout,
             echo=lambda *a, **k: None)
    peers = res["peers"]
    lat = [v for s in peers.values() for v in s.get("alert_latencies_ms", [])]
    return {"peers": len(peers), "expected_peers": len(sc.taskorg.units), "wall_s": round(time.monotonic() - t0, 1),
            "scenario_s": duration_s, "alerts": sum(s["alerts"] for s in peers.values()),
            "alert_latency_ms": pct(lat)}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", type=int, default=20)
    p.add_argument("--mesh-s", type=float, default=120.0, help="scenario seconds of the real-time mesh run (0: skip)")
    p.add_argument("--out", default=str(ROOT / "bench" / "results" / "uv.json"))
    p.add_argument("--no-closed-loop", dest="closed_loop", action="store_false",
                   help="skip the robot team obeying its EAs over the mesh (one process per robot)")
    a = p.parse_args(argv)
    folder = team_folder(Path(tempfile.mkdtemp(prefix="uvteam-")), a.robots)
    sc = scenarios.load(folder)
    n = len(sc.events)
    t0 = time.perf_counter()
    for _ in sc.events:
        pass
    loop = n / (time.perf_counter() - t0)
    wire = [messages.encode(e) for e in sc.events]
    t0 = time.perf_counter()
    for w in wire:
        messages.decode(w)
    decode = n / (time.perf_counter() - t0)
    robot_rate, robot_alerts = throughput(sc, "R01")
    team_rate, team_alerts = throughput(sc, "TEAM")
    paper_rate = HZ * a.robots   # 2/s from itself and 2/s from each teammate
    res = {
        "team": a.robots, "state_hz": HZ, "events": n, "scenario_s": sc.duration_s,
        "paper_rate_msgs_per_s_per_robot_ea": paper_rate,
        "robot_ea_msgs_per_s": round(robot_rate), "robot_ea_x_paper_rate": round(robot_rate / paper_rate),
        "team_ea_msgs_per_s": round(team_rate), "team_ea_x_its_rate": round(team_rate / paper_rate),
        "alerts": {"R01": robot_alerts, "TEAM": team_alerts},
        "baseline_loop_msgs_per_s": round(loop), "baseline_msgpack_decode_per_s": round(decode),
        "robot_ea_share_of_decode": round(robot_rate / decode, 3),
        "python": platform.python_version(), "machine": platform.machine(),
    }
    if a.closed_loop:   # the shipped scenario is this run (made in process); delays from the mesh's record
        res["closed_loop"], res["detection_uv_team"] = closed_loop()
        res["robot_processes"] = res["closed_loop"]["robot_processes"]
        print(json.dumps(res["closed_loop"]), flush=True)
    else:
        res["detection_uv_team"] = detection_delays()
    print(json.dumps({k: res[k] for k in ("robot_ea_msgs_per_s", "robot_ea_x_paper_rate", "team_ea_msgs_per_s",
                                          "baseline_msgpack_decode_per_s")}), flush=True)
    if a.mesh_s > 0:
        res["mesh_real_time"] = mesh_latency(a.robots, a.mesh_s)
        print(json.dumps(res["mesh_real_time"]), flush=True)
    out = Path(a.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(res, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
