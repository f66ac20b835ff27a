"""The UV scenario side: the generated `scenarios/uv-team` loads, holds the scripted
incidents in its events, is reproducible from its seed, and broken files are
rejected with a ScenarioError naming the file and the field."""
from __future__ import annotations

import gzip
import json
import math
import shutil
from collections import defaultdict
from pathlib import Path

import numpy as np
import pytest

from ea_agent.core.scenario import ScenarioError
from ea_agent.domains.uv import generator as G
from ea_agent.domains.uv import messages as M
from ea_agent.domains.uv.scenario import load

ROOT = Path(__file__).resolve().parents[1]
UV = ROOT / "scenarios" / "uv-team"
ALERTS = {"at-goal", "stuck", "divergent", "no-status", "target-visible", "lost-target", "target-gone", "collision",
          "handoff"}


@pytest.fixture(scope="module")
def sc():
    return load(UV)


@pytest.fixture(scope="module")
def states(sc):
    """robot -> (t, x, y, speed, heading, mode) rows, in metres."""
    out = defaultdict(list)
    for m in sc.events:
        if type(m) is M.UvState:
            x, y = sc.projection.to_xy(m.lon, m.lat)
            out[m.robot].append((m.t, x, y, m.speed_mps, m.heading_deg, m.mode))
    return out


def test_loads_with_team_and_targets(sc):
    kinds = [u.kind for u in sc.taskorg.units.values()]
    assert sc.meta["domain"] == "uv" and sc.meta["epsg"] == 32611 and sc.meta["keyspace"] == {"cell_m": 250}
    assert kinds.count("ugv") >= 3 and kinds.count("uav") >= 2
    assert sc.taskorg.root == "TEAM"
    assert sc.meta["default_eas"] == ["TEAM", *[u["id"] for u in G.UNITS if u["kind"] != "team"]]
    sighted = {m.target for m in sc.events if type(m) is M.UvSighting}
    assert len(sighted) >= 2
    assert 800 <= sc.duration_s <= 1000 and all(m.t <= sc.duration_s for m in sc.events)
    assert {m.type for m in sc.plan.missions} >= {"goto", "patrol", "search", "pursue"}


def test_states_twice_a_second_with_valid_fields(states):
    for rows in states.values():
        t = np.array([r[0] for r in rows])
        assert np.median(np.diff(t)) == 0.5
        assert all(0 <= r[4] < 360 and 0 <= r[3] <= 100 for r in rows)


def test_link_loss_gap(states):
    gaps = {r: float(np.diff([row[0] for row in rows]).max()) for r, rows in states.items()}
    assert max(gaps.values()) > 5.0
    assert sum(g > 5.0 for g in gaps.values()) == 1          # one robot, once


def test_waiting_gps_period(states):
    gps = [row for row in states["UGV2"] if row[5] == "waiting-gps"]
    assert gps and gps[-1][0] - gps[0][0] >= 20 and all(row[3] == 0 for row in gps)


def test_stuck_period(states):
    rows = [row for row in states["UGV1"] if 60 <= row[0] < 130]
    assert rows and all(row[5] == "moving" and row[3] == 0 for row in rows)
    xy = np.array([row[1:3] for row in rows])
    assert np.hypot(*(xy - xy[0]).T).max() < 1.0              # GPS drift only


def test_divergence_and_sharp_turn(sc, states):
    wp = np.array(sc.world["WP-3"].geom.coords[0])
    d = {row[0]: math.hypot(row[1] - wp[0], row[2] - wp[1]) for row in states["UGV3"]}
    assert d[100.0] - d[72.0] > 30                           # drove away from its waypoint
    h = {row[0]: row[4] for row in states["UAV2"]}
    arrive = next(m.t for m in sc.events if type(m) is M.UvAgent and m.task == "A2-goto")
    turn = abs((h[arrive + 8] - h[arrive - 1] + 180) % 360 - 180)
    assert turn > 120                                        # turned back sharply at WP-U2


def test_near_collision(states):
    a = {row[0]: row[1:3] for row in states["UAV1"]}
    b = {row[0]: row[1:3] for row in states["UAV2"]}
    d = min(math.dist(a[t], b[t]) for t in a.keys() & b.keys())
    assert d < 5.0


def test_pursuit_handoff_and_sector_exit(sc):
    acts = [(m.act, m.sender, m.to) for m in sc.events if type(m) is M.UvAgent]
    assert ("delegate", "UGV1", "UGV2") in acts and ("accept", "UGV2", "UGV1") in acts
    assert ("failure", "UAV2", "TEAM") in acts
    sec = sc.world["SEC-W"].geom
    from shapely.geometry import Point
    outside = [m for m in sc.events if type(m) is M.UvSighting and m.robot == "UGV1" and m.target == "EV1"
               and not sec.contains(Point(sc.projection.to_xy(m.lon, m.lat)))]
    assert outside


def test_truth(sc):
    tr = sc.truth()
    assert tr["owners"] == sc.meta["default_eas"]
    inc = tr["incidents"]
    assert all(i["t0"] < i["t1"] and i["subjects"] and set(i["accept"]) <= ALERTS for i in inc)
    team = {i["type"] for i in inc if i["owner"] == "TEAM"}
    assert team >= {"no-status", "stuck", "target-visible", "lost-target", "target-gone", "collision", "handoff"}
    robots = {i["type"] for i in inc if i["owner"] != "TEAM"}
    assert robots >= {"at-goal", "stuck", "divergent", "lost-target", "target-visible", "collision", "no-status"}
    assert not any(i["type"] == "stuck" and "UGV2" in i["subjects"] for i in inc)     # waiting for GPS
    assert not any(s["accept"] == ["stuck"] and "UGV2" in s["subjects"] and s["t0"] < 95 for s in tr["situations"])
    assert not any(i["type"] == "divergent" and "UAV2" in i["subjects"] for i in inc)  # turning
    assert all(i["owner"] in tr["owners"] for i in inc + tr["situations"])


def test_generator_is_deterministic(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    G.write(a, seed=7)
    G.write(b, seed=7)
    for f in ("events.jsonl.gz", "truth.json", "plan.json", "world.geojson", "scenario.json"):
        assert (a / f).read_bytes() == (b / f).read_bytes(), f
    assert (a / "events.jsonl.gz").read_bytes() == (UV / "events.jsonl.gz").read_bytes(), \
        "scenarios/uv-team is stale: python -m ea_agent.domains.uv.generator scenarios/uv-team"
    G.write(b, seed=8)
    assert (a / "events.jsonl.gz").read_bytes() != (b / "events.jsonl.gz").read_bytes()
    load(b)


# -- broken scenarios -------------------------------------------------------------------------------
@pytest.fixture()
def broken(tmp_path):
    d = tmp_path / "uv"
    shutil.copytree(UV, d)
    return d


def _edit(path: Path, fn) -> None:
    doc = json.loads(path.read_text())
    fn(doc)
    path.write_text(json.dumps(doc))


def _events(d: Path, lines: list[dict]) -> None:
    (d / "events.jsonl.gz").unlink()
    (d / "events.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))


def _mission(doc: dict, mid: str) -> dict:
    return next(m for m in doc["plans"]["main"] if m["id"] == mid)


def _feature(doc: dict, fid: str) -> dict:
    return next(f for f in doc["features"] if f["properties"]["id"] == fid)


STATE = {"kind": "uv-state", "robot": "UGV1", "lon": -116.6, "lat": 35.28, "speed_mps": 1.0, "heading_deg": 10.0,
         "sigma_m": 1.0, "mode": "moving"}


@pytest.mark.parametrize("fname, edit, words", [
    ("scenario.json", lambda d: d.pop("duration_s"), ["duration_s", "missing"]),
    ("scenario.json", lambda d: d.update(domain="suo"), ["domain"]),
    ("plan.json", lambda d: _mission(d, "U1-goto").update(type="teleport"), ["U1-goto", "'type'", "teleport"]),
    ("plan.json", lambda d: _mission(d, "U1-goto")["params"].update(waypoint="WP-9"), ["U1-goto", "params.waypoint"]),
    ("plan.json", lambda d: _mission(d, "U1-goto")["params"].update(waypoint="SEC-W"), ["params.waypoint", "sector"]),
    ("plan.json", lambda d: _mission(d, "U1-patrol")["params"].pop("area"), ["U1-patrol", "params.area", "missing"]),
    ("plan.json", lambda d: _mission(d, "U1-goto").update(unit="UGV9"), ["'unit'", "UGV9"]),
    ("plan.json", lambda d: _mission(d, "A1-search")["params"].update(target="EV9"), ["params.target", "EV9"]),
    ("plan.json", lambda d: d["team"][1].update(id="UGV/1"), ["team[1]", "'id'"]),
    ("plan.json", lambda d: d["team"][1]["attrs"].pop("sensor_range_m"), ["sensor_range_m"]),
    ("world.geojson", lambda d: _feature(d, "WP-1")["geometry"].update(coordinates=[float("nan"), 35.2]),
     ["WP-1", "geometry"]),
    ("world.geojson", lambda d: _feature(d, "OBS-1")["geometry"].update(type="Point", coordinates=[-116.6, 35.28]),
     ["OBS-1", "geometry", "Polygon"]),
])
def test_broken_files(broken, fname, edit, words):
    _edit(broken / fname, edit)
    with pytest.raises(ScenarioError) as e:
        load(broken)
    msg = str(e.value)
    assert fname.split(".")[0] in msg and all(w in msg for w in words), msg


@pytest.mark.parametrize("lines, words", [
    ([{**STATE, "t": 1.0}, {**STATE, "t": 2.0, "robot": "UGV9"}], ["events.jsonl:2", "'robot'", "UGV9"]),
    ([{**STATE, "t": 5.0}, {**STATE, "t": 4.0}], ["events.jsonl:2", "'t'", "earlier"]),
    ([{**STATE, "t": 1.0, "lat": float("nan")}], ["events.jsonl:1", "lat"]),
    ([{**STATE, "t": 1.0, "heading_deg": 360.0}], ["events.jsonl:1", "heading_deg"]),
    ([{**STATE, "t": 9999.0}], ["events.jsonl:1", "'t'", "duration_s"]),
    ([{"kind": "uv-agent", "t": 1.0, "sender": "UGV1", "to": "UGV7", "act": "delegate", "task": "x"}],
     ["events.jsonl:1", "'to'", "UGV7"]),
    ([{"kind": "uv-sighting", "t": 1.0, "robot": "EV1", "target": "EV2", "lon": -116.6, "lat": 35.28, "sigma_m": 2}],
     ["events.jsonl:1", "'robot'", "EV1"]),
])
def test_broken_events(broken, lines, words):
    _events(broken, lines)
    with pytest.raises(ScenarioError) as e:
        load(broken)
    msg = str(e.value)
    assert all(w in msg for w in words), msg


def test_events_gz_is_sorted_and_plain_json():
    with gzip.open(UV / "events.jsonl.gz", "rt") as fh:
        ts = [json.loads(line)["t"] for line in fh]
    assert ts == sorted(ts) and ts[0] == 0.0
