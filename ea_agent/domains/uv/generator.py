"""Writes the `uv-team` scenario folder from the seeded simulator (docs/uv-domain.md).

Three UGVs and two UAVs patrol, search and pursue two evaders over a 1.5 x 1.5 km
area near Fort Irwin (UTM 11N). The layout (places, team, recipes, evader keyframes,
scripted faults) is fixed here; `sim.py` runs each robot, obeying the tasks of its own
EA (`loop.py` closes the loop in process; `saim_mesh/robots` one process per robot on the
mesh), and `oracle.py` turns the team's true state into truth.json.

    python -m ea_agent.domains.uv.generator OUT [--seed N]
"""
from __future__ import annotations

import argparse
import gzip
import io
import json
from collections import Counter
from pathlib import Path

import numpy as np
from shapely.geometry import Point, Polygon, mapping
import shapely

from ea_agent.core.geo import Projection

from .loop import ClosedLoop
from .sim import Geo, RobotSim, Team
from .world import Place

EPSG = 32611
ORIGIN_EN = (536_000.0, 3_903_000.0)   # UTM 11N metres of the area's south-west corner (near Fort Irwin)
DURATION = 900.0
NAME = "uv-team"


def _box(x0: float, y0: float, x1: float, y1: float) -> Polygon:
    return Polygon([(x0, y0), (x1, y0), (x1, y1), (x0, y1)])


# id -> (kind, local geometry, props)
PLACES: dict[str, tuple[str, object, dict]] = {
    "OBS-1": ("obstacle", _box(620, 600, 820, 760), {"name": "building"}),
    "OBS-2": ("obstacle", Polygon([(1040, 240), (1200, 250), (1190, 380), (1060, 370)]), {"name": "pond"}),
    "OBS-3": ("obstacle", _box(330, 1080, 440, 1200), {"name": "ruin"}),
    "BASE": ("base", Point(750, 40), {"radius_m": 20}),
    "WP-1": ("waypoint", Point(330, 930), {"radius_m": 10}),
    "WP-2": ("waypoint", Point(1000, 930), {"radius_m": 10}),
    "WP-3": ("waypoint", Point(450, 330), {"radius_m": 10}),
    "WP-U1": ("waypoint", Point(750, 1000), {"radius_m": 20}),
    "WP-U2": ("waypoint", Point(1150, 450), {"radius_m": 20}),
    "WP-U3": ("waypoint", Point(860, 420), {"radius_m": 20}),
    "PA-NW": ("patrol-area", _box(200, 950, 660, 1380), {}),
    "PA-NE": ("patrol-area", Polygon([(860, 950), (860, 1380), (1360, 1380), (1360, 950)]), {}),
    "PA-S": ("patrol-area", _box(250, 180, 980, 480), {}),
    "SA-N": ("patrol-area", _box(100, 850, 1400, 1450), {"name": "UAV1 search area"}),
    "SA-E": ("patrol-area", _box(900, 450, 1450, 900), {"name": "UAV2 search area"}),
    "SEC-W": ("sector", _box(0, 800, 760, 1500), {}),
    "SEC-E": ("sector", _box(760, 800, 1500, 1500), {}),
    "SEC-S": ("sector", _box(0, 0, 1500, 560), {}),
    "SEC-C": ("sector", _box(700, 420, 1500, 820), {}),
}

UGV = {"max_speed_mps": 3.0, "turn_rate_dps": 45, "sensor_range_m": 60, "comm_range_m": 400, "radius_m": 0.5,
       "sigma_m": 1.0, "sensor_sigma_m": 2.0}
UAV = {"max_speed_mps": 10.0, "turn_rate_dps": 15, "sensor_range_m": 120, "comm_range_m": 800, "radius_m": 0.5,
       "sigma_m": 1.0, "sensor_sigma_m": 4.0}
UNITS = [
    {"id": "TEAM", "name": "Operator (team)", "kind": "team", "parent": None, "attrs": {}},
    {"id": "UGV1", "name": "Pioneer 1", "kind": "ugv", "parent": "TEAM", "attrs": UGV, "start": (300, 640)},
    {"id": "UGV2", "name": "Pioneer 2", "kind": "ugv", "parent": "TEAM", "attrs": UGV, "start": (1050, 620)},
    {"id": "UGV3", "name": "Pioneer 3", "kind": "ugv", "parent": "TEAM", "attrs": UGV, "start": (760, 100)},
    {"id": "UAV1", "name": "Quadrotor 1", "kind": "uav", "parent": "TEAM", "attrs": UAV, "start": (750, 40)},
    {"id": "UAV2", "name": "Quadrotor 2", "kind": "uav", "parent": "TEAM", "attrs": UAV, "start": (345, 443)},
]
ASAP = {"type": "ASAP"}


def _m(mid: str, unit: str, typ: str, after: list[str] | None = None, **params) -> dict:
    return {"id": mid, "unit": unit, "type": typ, "start": ASAP, "end": ASAP, "after": after or [], "params": params}


MISSIONS = [
    _m("U1-goto", "UGV1", "goto", waypoint="WP-1"),
    _m("U1-patrol", "UGV1", "patrol", ["U1-goto"], area="PA-NW", sector="SEC-W"),
    _m("U2-goto", "UGV2", "goto", waypoint="WP-2"),
    _m("U2-patrol", "UGV2", "patrol", ["U2-goto"], area="PA-NE", sector="SEC-E"),
    _m("U3-goto", "UGV3", "goto", waypoint="WP-3"),
    _m("U3-patrol", "UGV3", "patrol", ["U3-goto"], area="PA-S", sector="SEC-S"),
    _m("A1-goto", "UAV1", "goto", waypoint="WP-U1"),
    _m("A1-search", "UAV1", "search", ["A1-goto"], area="SA-N", target="EV1"),
    _m("A1-home", "UAV1", "goto", ["A1-search"], waypoint="BASE"),
    _m("A2-goto", "UAV2", "goto", waypoint="WP-U2"),
    _m("A2-back", "UAV2", "goto", ["A2-goto"], waypoint="WP-U3"),
    _m("A2-search", "UAV2", "search", ["A2-back"], area="SA-E", target="EV2"),
    _m("A2-pursue", "UAV2", "pursue", ["A2-search"], target="EV2", sector="SEC-C"),
    _m("A2-home", "UAV2", "goto", ["A2-pursue"], waypoint="BASE"),
]

# Evader keyframes (t, x, y): positions between them are interpolated; before the first
# and after the last the evader stands still (out of everyone's sight).
EVADERS = {
    "EV1": [(0, 560, 1470), (170, 560, 1470), (370, 610, 1030), (440, 800, 1150), (520, 1000, 1250),
            (640, 1100, 1450), (740, 1480, 1480), (900, 1490, 1490)],
    "EV2": [(0, 540, 40), (280, 540, 40), (350, 530, 190), (420, 800, 300), (500, 1000, 560),
            (560, 1120, 700), (660, 1150, 900), (900, 1450, 1450)],
}

# Scripted faults (kind, robot, t0, t1): what the oracle knows happened.
FAULTS = [
    ("stuck", "UGV1", 60.0, 130.0),      # wheels spin: no motion while its goto is active, mode stays moving
    ("gps", "UGV2", 40.0, 95.0),         # waits for a GPS fix (mode waiting-gps): not stuck
    ("diverge", "UGV3", 70.0, 100.0),    # drives away from WP-3, then comes back
    ("link", "UGV3", 450.0, 475.0),      # radio silent: its states stop, then resume
]
INCIDENTS = [
    {"label": "UAV1 and UAV2 cross on a near-collision course south of the building", "t": 40, "types": ["collision"]},
    {"label": "UGV2 waits for GPS on its way to WP-2 (not stuck)", "t": 40, "types": []},
    {"label": "UGV1 stuck on its way to WP-1", "t": 60, "types": ["stuck"]},
    {"label": "UGV3 drives away from WP-3", "t": 70, "types": ["divergent"]},
    {"label": "UAV2 turns back sharply at WP-U2 for WP-U3 (not divergent)", "t": 80, "types": ["at-goal"]},
    {"label": "UGV3 link lost for 25 s", "t": 450, "types": ["no-status"]},
]


def world() -> dict[str, Place]:
    return {pid: Place(pid, kind, g, dict(props)) for pid, (kind, g, props) in PLACES.items()}


def robots(seed: int = 7, only: list[str] | None = None) -> dict[str, RobotSim]:
    """The team's robot simulators (each its own random stream), optionally some of them."""
    geo = Geo(EPSG, ORIGIN_EN)
    ids = [u["id"] for u in UNITS if u["kind"] in ("ugv", "uav")]
    return {u["id"]: RobotSim(u, ids.index(u["id"]), world(), MISSIONS, EVADERS, FAULTS, DURATION, geo, seed)
            for u in UNITS if u["id"] in ids and (only is None or u["id"] in only)}


def team(records: dict[str, dict]) -> Team:
    """The true run of the team from its robots' records (what the oracle reads)."""
    return Team(world(), UNITS, FAULTS, DURATION, records, EVADERS)


def simulate(out: Path, seed: int = 7, eas: list[str] | None = None, unheard=()) -> tuple[ClosedLoop, Team]:
    """The closed-loop run in process over the scenario folder's static files (the EAs
    need them): the robots obey their EAs."""
    from . import load, make_ea
    sc = load(out, events=False)
    owners = eas or list(sc.meta["default_eas"])
    loop = ClosedLoop(robots(seed), [make_ea(sc, o) for o in owners], unheard=unheard).run()
    return loop, team({r: s.record() for r, s in loop.robots.items()})


def _to_lonlat(proj: Projection, xy: np.ndarray) -> np.ndarray:
    lon, lat = proj.to_lonlat(xy[:, 0] + ORIGIN_EN[0], xy[:, 1] + ORIGIN_EN[1])
    return np.column_stack([lon, lat])


def _features(proj: Projection) -> list[dict]:
    out = []
    for pid, (kind, g, props) in PLACES.items():
        ll = shapely.transform(g, lambda c: np.round(_to_lonlat(proj, c), 7))
        out.append({"type": "Feature", "properties": {"id": pid, "kind": kind, **props}, "geometry": mapping(ll)})
    return out


def events_bytes(events: list[dict]) -> bytes:
    """events.jsonl.gz of the messages the robots sent, in the order the EAs took them."""
    buf = io.StringIO()
    for e in events:
        buf.write(json.dumps(e, separators=(",", ":")) + "\n")
    out = io.BytesIO()
    with gzip.GzipFile(fileobj=out, mode="wb", mtime=0, filename="") as gz:
        gz.write(buf.getvalue().encode())
    return out.getvalue()


def write_static(out: Path, seed: int = 7) -> dict:
    """scenario.json, world.geojson and plan.json; returns the meta."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    proj = Projection(EPSG)
    robots_ = [u["id"] for u in UNITS if u["kind"] in ("ugv", "uav")]
    meta = {"name": NAME, "domain": "uv", "epsg": EPSG, "duration_s": DURATION, "seed": seed,
            "default_eas": ["TEAM", *robots_], "keyspace": {"cell_m": 250}, "targets": sorted(EVADERS)}
    team_ = [{k: v for k, v in u.items() if k != "start"} for u in UNITS]
    plan = {"team": team_, "plans": {"main": MISSIONS}, "initial_plan": "main"}
    (out / "scenario.json").write_text(json.dumps(meta, indent=1) + "\n")
    (out / "world.geojson").write_text(json.dumps({"type": "FeatureCollection", "features": _features(proj)},
                                                  indent=1) + "\n")
    (out / "plan.json").write_text(json.dumps(plan, indent=1) + "\n")
    return meta


def write_run(out: Path, events: list[dict], tm: Team, owners: list[str]) -> dict:
    """events.jsonl.gz and truth.json of a closed-loop run (in process or on the mesh)."""
    from .oracle import ground_truth
    out = Path(out)
    (out / "events.jsonl.gz").write_bytes(events_bytes(events))
    truth = ground_truth(tm, owners=owners)
    truth["incidents_injected"] = INCIDENTS
    (out / "truth.json").write_text(json.dumps(truth, indent=1) + "\n")
    return {"events": len(events), "by_kind": dict(Counter(e["kind"] for e in events)),
            "incidents": len(truth["incidents"]), "situations": len(truth["situations"]),
            "by_type": dict(sorted(Counter(i["type"] for i in truth["incidents"]).items()))}


def write(out: Path, seed: int = 7) -> dict:
    """Write the scenario folder from the closed-loop run in process; returns a summary."""
    meta = write_static(out, seed)
    loop, tm = simulate(out, seed)
    return write_run(out, loop.events, tm, meta["default_eas"])


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--seed", type=int, default=7)
    a = ap.parse_args(argv)
    print(json.dumps(write(a.out, a.seed), indent=1))


if __name__ == "__main__":
    main()
