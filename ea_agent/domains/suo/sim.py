"""The generated battalion's battle as it really happens: its units placed and moving
along the plan (`battle_plan`), the hostile groups, the labelled incidents, and what its
sensors see. The oracle reads this true state; `generator` turns it into the reports
and files of a scenario."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ea_agent.core.geo import Projection

from .battle_plan import COMPANIES, DURATION, LANE_X, SQUAD_DX, SQUAD_DY, WITHDRAW_Y, plan_doc

# Labelled incidents (what the scenario is built to show), for the record in truth.json.
INCIDENTS = [
    {"label": "A2 strays east into B CO's sector next to B1", "t": 900, "types": ["out-of-position", "fratricide"]},
    {"label": "B3 starts its move 180 s late", "t": 330, "types": ["schedule"]},
    {"label": "C3 ends its move 240 s late", "t": 2190, "types": ["schedule"]},
    {"label": "C1 starts its attack 150 s early", "t": 2250, "types": ["schedule"]},
    {"label": "A1 squad 3 radios out 1500-1800", "t": 1620, "types": ["unknown-position"]},
    {"label": "A3 misses the link-up with B1 at CP-LINK", "t": 3030, "types": ["coordination"]},
    {"label": "H3 at DP2 triggers the BN branch: M disrupts AA-DIAMOND from BP-M2", "t": 3500,
     "types": ["contingency", "ave-of-approach"]},
    {"label": "H3 still advancing down AA-DIAMOND at 3 m/s after 3900 (M's disrupt)", "t": 3900,
     "types": ["hostile-expected"]},
    {"label": "A1 on OBJ-A triggers A CO's sequel: A1 suppresses EA-A from OBJ-A", "t": 3600, "types": ["contingency"]},
    {"label": "EA-A beyond A1's weapons range from OBJ-A when its fires are due (3700-4000, its suppress)",
     "t": 3700, "types": ["fire-support"]},
    {"label": "A2 not on OBJ-A by 3300 (its seize)", "t": 3300, "types": ["out-of-position"]},
    {"label": "H6 on OBJ-C while C1 secures it", "t": 2100, "types": ["penetration"]},
    {"label": "H2 through NAI-1 and the recon screen; contact with R", "t": 1567, "types": ["monitored", "contact", "distance"]},
    {"label": "B2 defends EA-B: the expected enemy never comes", "t": 4800, "types": ["hostile-expected"]},
    {"label": "H4 attacks A CO, reinforced by H4B", "t": 4990, "types": ["contact", "strength", "distance", "monitored"]},
    {"label": "H5 comes within range of C2 and C3; H5B reinforces it in front of both", "t": 4481,
     "types": ["contact", "proximity", "ave-of-approach"]},
    {"label": "A2 calls for fire near A3", "t": 3900, "types": ["call-for-fire"]},
    {"label": "C3 strays 2 km east, out of its band behind C2", "t": 900, "types": ["out-of-position", "band"]},
    {"label": "BN orders M's march (ON-ORDER) at 2150; M starts 50 s later", "t": 2180, "types": ["schedule"]},
    {"label": "H6 breaks out of OBJ-C while C3 isolates it", "t": 3100, "types": ["escape"]},
    {"label": "B2 ends its clear with H7 still on OBJ-B", "t": 3600, "types": ["end-state"]},
    {"label": "H7 enters B1's blocking position, projected before it does", "t": 4100,
     "types": ["projected-penetration"]},
    {"label": "H10 infiltrates B1's blocking position", "t": 4300, "types": ["penetration", "contact"]},
    {"label": "H9 beside RTE-M ahead of M's march: abort, execute the ABF branch or continue?", "t": 2400,
     "types": ["threat-ahead"]},
    {"label": "B1 reaches CP-B1 150 s behind its march table", "t": 1080, "types": ["checkpoint"]},
    {"label": "B3 not through the obstacle OBS-B3 by 2900 (its breach)", "t": 2900, "types": ["line"]},
    {"label": "C2S4 passes C3 at CP-C outside the passage lane LANE-C", "t": 3990, "types": ["presence"]},
    {"label": "B crosses PL BLUE before M is in position to support it; M lifts fires as B nears OBJ-B", "t": 2420,
     "types": ["fire-support"]},
    {"label": "A2's engagement area EA-A is beyond its weapons range from BP-A2", "t": 3760,
     "types": ["friendly-expected"]},
]


def _interp(t: float, ts, vs) -> float:
    return float(np.interp(t, ts, vs))


@dataclass
class Hostile:
    id: str
    ts: list[float]
    xs: list[float]
    ys: list[float]
    strength: int
    appear: float
    vanish: float = DURATION + 1

    def pos(self, t: float):
        if not self.appear <= t < self.vanish:
            return None
        return _interp(t, self.ts, self.xs), _interp(t, self.ts, self.ys)


@dataclass
class Sim:
    """The true state of the world over time (what really happened)."""
    small: bool = False
    seed: int = 7
    duration: float = DURATION
    units: list[dict] = field(default_factory=list)
    entity_leaf: dict[str, str] = field(default_factory=dict)
    entity_off: dict[str, tuple[float, float]] = field(default_factory=dict)
    hostiles: dict[str, Hostile] = field(default_factory=dict)
    outages: dict[str, tuple[float, float]] = field(default_factory=dict)
    confirmations: list[tuple[float, str, str, str]] = field(default_factory=list)
    cffs: list[dict] = field(default_factory=list)
    report_s: float = 30.0
    report_phase: dict[str, float] = field(default_factory=dict)
    incidents: str = "scripted"                                          # or "random"
    paths: dict[str, tuple[list, list]] = field(default_factory=dict)    # platoon -> (ts, ys), drawn
    strays: dict[str, tuple[list, list]] = field(default_factory=dict)   # platoon -> (ts, dxs) off its lane
    detours: dict[str, tuple[list, list]] = field(default_factory=dict)  # squad -> (ts, dxs)
    reorg_t: float = 600
    drawn: list[dict] = field(default_factory=list)                      # what was drawn, for truth.json
    order: dict | None = None          # the battalion switches plans: {"t", "plan", "issuer"}
    # ON-ORDER missions ordered to start or end: [{"t", "mission", "phase", "issuer"}]
    mission_orders: list = field(default_factory=list)
    withdraw: dict[str, tuple[float, float]] = field(default_factory=dict)  # platoon -> (leaves, arrives)
    sensors: list[tuple[str, float]] = field(default_factory=list)      # (id, range m) when hostiles are sensed
    block_line: bool = False   # B1 blocks PL-B1-BLOCK (a line) instead of its battle position (an area)
    area_recon: bool = False   # R reconnoitres ZONE-R as an area (coverage) instead of a zone (depth)
    apart: set[str] = field(default_factory=set)   # hostiles sensed from a stream of their own (hits)

    # -- friendly movement ---------------------------------------------------------
    def platoon_y_path(self, p: str):
        if p in self.paths:
            return self.paths[p]
        if p == "B3":
            return [0, 480, 2100, 2400, 3600], [0, 0, 7000, 7000, 11000]
        if p == "C3":
            return [0, 300, 2400, 3600], [0, 0, 7000, 11000]
        if p == "C1":
            return [0, 300, 2100, 2250, 3450], [0, 0, 7000, 7000, 11000]
        return [0, 300, 2100, 2400, 3600], [0, 0, 7000, 7000, 11000]

    def platoon_center(self, p: str, t: float):
        ts, ys = self.platoon_y_path(p)
        x = LANE_X[p]
        if p in self.strays:
            x += _interp(t, *self.strays[p])
        w = self.withdraw.get(p)
        if w is not None and t > w[0]:   # ordered back to its phase-line battle position
            return x, _interp(t, list(w), [_interp(w[0], ts, ys), WITHDRAW_Y])
        return x, _interp(t, ts, ys)

    def sensor_xy(self, sid: str, t: float) -> tuple[float, float]:
        return sensor_pos(self, sid, t)

    def leaf_center(self, leaf: str, t: float):
        if leaf in ("R1", "R2", "R3"):
            return (1200.0, 2000.0, 2800.0)[int(leaf[1]) - 1], 15000.0
        if leaf in ("M1", "M2"):
            return 5850.0 if leaf == "M1" else 6150.0, _interp(t, [0, 2200, 2800], [2000, 2000, 8000])
        if leaf == "BNHQ":
            return 6000.0, -1000.0
        if leaf.endswith("HQ"):
            co = leaf[0]
            ys = [self.platoon_center(f"{co}{i}", t)[1] for i in (1, 2, 3)]
            return LANE_X[f"{co}2"], sum(ys) / 3 - 500.0
        p, s = leaf[:2], int(leaf[3]) - 1
        x, y = self.platoon_center(p, t)
        x, y = x + SQUAD_DX[s], y + SQUAD_DY[s]
        if leaf == "B1S4" and leaf in self.detours:   # to the link-up point and back
            x += _interp(t, [2800, 2980, 3100, 3300], [0, 4060 - x, 4060 - x, 0]) if 2800 < t < 3300 else 0
        elif leaf in self.detours:
            x += _interp(t, *self.detours[leaf])
        return x, y

    def entity_pos(self, e: str, t: float):
        cx, cy = self.leaf_center(self.entity_leaf[e], t)
        ox, oy = self.entity_off[e]
        return cx + ox, cy + oy

    def reports_at(self, e: str, t: float) -> bool:
        o = self.outages.get(self.entity_leaf[e])
        return not (o and o[0] <= t < o[1])


def _units(small: bool) -> list[dict]:
    per_squad = 2 if small else 10
    u = [{"id": "BN", "name": "1st BN", "echelon": "battalion", "parent": None, "boundary": "BND-BN",
          "weapons_range_m": 1000.0},
         {"id": "BNHQ", "name": "BN HQ", "echelon": "squad", "parent": "BN", "n": 2 if small else 8}]
    for co in COMPANIES:
        u.append({"id": co, "name": f"{co} CO", "echelon": "company", "parent": "BN", "boundary": f"BND-{co}"})
        u.append({"id": f"{co}HQ", "name": f"HQ, {co} CO", "echelon": "squad", "parent": co, "n": 2 if small else 6})
        for i in (1, 2, 3):
            p = f"{co}{i}"
            u.append({"id": p, "name": f"{i} PLT, {co} CO", "echelon": "platoon", "parent": co})
            for s in (1, 2, 3, 4):
                u.append({"id": f"{p}S{s}", "name": f"{s} SQD, {i} PLT, {co} CO", "echelon": "squad",
                          "parent": p, "n": per_squad})
    u.append({"id": "R", "name": "Recon PLT", "echelon": "platoon", "parent": "A"})
    for s in (1, 2, 3):
        u.append({"id": f"R{s}", "name": f"{s} SQD, Recon PLT", "echelon": "squad", "parent": "R", "n": 2 if small else 6})
    u.append({"id": "M", "name": "Mortar PLT", "echelon": "platoon", "parent": "BN"})
    for s in (1, 2):
        u.append({"id": f"M{s}", "name": f"{s} SEC, Mortar PLT", "echelon": "squad", "parent": "M", "n": 2 if small else 8})
    return u


def place_entities(sim: "Sim", units: list[dict], rng) -> None:
    """Each unit's `n` entities: a random offset within 25 m of its leaf's centre and a
    random phase of the report period (the order of draws is part of the seed's output)."""
    for u in units:
        for k in range(u.get("n", 0)):
            e = f"{u['id']}E{k + 1:02d}"
            sim.entity_leaf[e] = u["id"]
            sim.entity_off[e] = (float(rng.uniform(-25, 25)), float(rng.uniform(-25, 25)))
    for e in sorted(sim.entity_leaf):
        sim.report_phase[e] = float(rng.uniform(0, sim.report_s))


def build_sim(small: bool = False, seed: int = 7, incidents: str = "scripted", mult: int = 1,
              plan_switch: bool = True, report_s: float | None = None) -> Sim:
    """The true battle. `incidents`: "scripted" (the labelled INCIDENTS, the same for
    every seed: the seed moves offsets and noise) or "random" (draw_battle: each seed a
    different battle). `mult` scales entities per leaf; `plan_switch=False` drops a drawn
    order to execute the withdrawal plan (a plan switch is scenario-wide: a brigade's
    battalion cannot make it alone); `report_s` overrides the report interval."""
    if mult < 1:
        raise ValueError(f"mult must be a positive whole number, not {mult!r}")
    rng = np.random.default_rng(seed)
    sim = Sim(small=small, seed=seed, report_s=report_s or (60.0 if small else 30.0), incidents=incidents)
    sim.units = _units(small)
    for u in sim.units:
        if "n" in u:
            u["n"] *= mult
    place_entities(sim, sim.units, rng)
    if incidents == "random":
        from .random_battle import draw_battle   # it builds on this module's Sim
        draw_battle(sim, np.random.default_rng([seed, 11]))
        if not plan_switch:
            sim.order, sim.withdraw = None, {}
            sim.drawn = [d for d in sim.drawn if d["kind"] != "order"]
    elif incidents == "scripted":
        sim.strays = {"A2": ([900, 1200, 1400, 1700], [0, 2300, 2300, 0])}
        sim.detours = {"B1S4": ([], []), "C2S4": ([3800, 3980, 4100, 4300], [0, 440, 440, 0]),
                       "C3S4": ([3800, 3980, 4100, 4300], [0, -740, -740, 0])}
        H = Hostile
        sim.hostiles = {
            "H1": H("H1", [600, 5400], [-3000, -2500], [25000, 24000], 4, 600),
            "H2": H("H2", [1400, 2500, 3500, 4600], [2000] * 4, [19500, 16200, 16200, 19500], 5, 1400, 4600),
            "H3": H("H3", [2500, 4333], [6000, 6000], [20000, 14500], 8, 2500),
            "H4": H("H4", [3800, 5233], [1500, 1500], [16500, 12200], 6, 3800),
            "H4B": H("H4B", [3800, 5233], [1600, 1600], [16600, 12300], 6, 5100),
            "H5": H("H5", [3000, 4563], [10650, 10650], [20000, 12500], 7, 3000),
            "H5B": H("H5B", [3000, 4563], [10700, 10700], [20050, 12550], 7, 4700),
        }
        sim.outages = {"A1S3": (1500.0, 1800.0)}
        sim.strays["C3"] = ([600, 900, 1100, 1400], [0, 2000, 2000, 0])   # out of C2's band too
        sim.hostiles.update({
            # holds OBJ-C, then breaks out north while C3 isolates it
            "H6": H("H6", [1800, 2900, 3300], [9500, 9500, 9500], [11000, 11000, 13500], 3, 1800, 3500),
            # still on OBJ-B when B2 ends its clear, then into B1's blocking position
            "H7": H("H7", [3000, 3900, 4150], [5800, 5800, 4700], [11200, 11200, 11000], 3, 3000, 4500),
            # infiltrators that appear inside B1's blocking position (no approach to project)
            "H10": H("H10", [4300, 4600], [4750, 4750], [10950, 10950], 2, 4300, 4600),
            # a bypassed squad beside RTE-M, ahead of M's march
            "H9": H("H9", [2200, 2600], [6060, 6060], [5500, 5500], 2, 2200, 2600),
        })
        sim.mission_orders = [{"t": 2150.0, "mission": "M-march", "phase": "start", "issuer": "BN"}]
    else:
        raise ValueError(f"incidents must be 'scripted' or 'random', not {incidents!r}")
    c = sim.confirmations
    for p in LANE_X:
        ts, ys = sim.platoon_y_path(p)
        move_start = ts[1]
        move_end = ts[ys.index(7000)]
        atk_start = ts[3] if p != "C3" else move_end
        atk_end = ts[-1]
        c += [(move_start, f"{p}-move", p, "start"), (move_end, f"{p}-move", p, "end"),
              (atk_start, f"{p}-attack", p, "start"), (atk_end, f"{p}-attack", p, "end"),
              (max(3700.0, atk_end + 30.0), f"{p}-defend", p, "start")]
    for co in COMPANIES:
        c += [(300.0, f"{co}-mtc", co, "start"), (2400.0 if co == "C" else 2100.0, f"{co}-mtc", co, "end"),
              (2400.0, f"{co}-attack", co, "start"), (3600.0, f"{co}-attack", co, "end"), (3700.0, f"{co}-defend", co, "start")]
    c += [(0.0, "R-zone", "R", "start"), (1800.0, "R-zone", "R", "end"), (0.0, "R-screen", "R", "start"), (0.0, "M-occupy", "M", "start"), (2200.0, "M-occupy", "M", "end"),
          (2200.0, "M-march", "M", "start"), (2800.0, "M-march", "M", "end"), (2800.0, "M-sbf", "M", "start"),
          (0.0, "BNHQ-occupy", "BNHQ", "start"), (2800.0, "A3-linkup", "A3", "start"),
          (3800.0, "C2-passage", "C2", "start")]
    if sim.order is not None:   # the main plan ends with the order: its later confirmations never come
        main = {x["id"] for x in plan_doc(sim)["plans"]["main"]}
        c[:] = [x for x in c if not (x[1] in main and x[0] > sim.order["t"])]
        for p, (t0, t1) in sim.withdraw.items():
            c += [(t0, f"{p}-withdraw", p, "start")] + ([(t1, f"{p}-withdraw", p, "end")] if t1 < DURATION else [])
    c.sort()
    if incidents == "random":
        return sim
    sim.cffs = [
        {"t": 3900.0, "kind": "cff", "cff": "CFF-1", "requester": "A2", "x": 3000.0, "y": 11500.0, "radius_m": 600.0},
        {"t": 3960.0, "kind": "cff-confirm", "cff": "CFF-1", "requester": "A2", "x": 3000.0, "y": 11500.0, "radius_m": 600.0},
        {"t": 5000.0, "kind": "cff", "cff": "CFF-2", "requester": "A2", "x": 2000.0, "y": 16000.0, "radius_m": 600.0},
    ]
    return sim


# ------------------------------------------------------------------ sensors (forward fusion)
SENSORS = [  # id, fusion group, owner, kind, range m, Pd, sigma m, false alarms per scan
    ("G1", "N", "R", "ground", 3000.0, 0.85, 25.0, 0.1),
    ("G2", "N", "BN", "ground", 3500.0, 0.85, 25.0, 0.1),
    ("G3", "N", "C", "ground", 3500.0, 0.85, 25.0, 0.1),
    ("UAV1", "N", "BN", "uav", 4000.0, 0.8, 40.0, 0.1),
    ("VA2", "F", "A2", "vehicle", 3000.0, 0.85, 30.0, 0.1),
    ("VB2", "F", "B2", "vehicle", 3000.0, 0.85, 30.0, 0.1),
    ("VC2", "F", "C2", "vehicle", 3000.0, 0.85, 30.0, 0.1),
]
SENSOR_PERIOD = 5.0
MAX_GROUND_MPS = 40.0   # the sensors watch ground units: nothing they track moves faster


def sensor_pos(sim: "Sim", sid: str, t: float) -> tuple[float, float]:
    if sid == "G1":
        return 2000.0, 16500.0
    if sid == "G2":
        return 6000.0, 17000.0
    if sid == "G3":
        return 10650.0, 17000.0
    if sid == "UAV1":   # orbits the northern area every 15 minutes
        a = 2 * math.pi * t / 900.0
        return 6000.0 + 4500.0 * math.cos(a), 16000.0 + 2500.0 * math.sin(a)
    return sim.platoon_center(sid[1:], t)


def _sensed(sim: "Sim", groups: list[str], offs: dict, t: float, sx: float, sy: float, rng_m: float, pd: float,
            sigma: float, rng) -> list[tuple[float, float]]:
    """The noisy positions of the entities of `groups` a sensor at (sx, sy) detects at `t`,
    drawn from `rng` (each stream's draws in the same order as ever)."""
    pts = []
    for h in groups:
        p = sim.hostiles[h].pos(t)
        if p is None:
            continue
        for ex, ey in offs[h]:
            x, y = p[0] + ex, p[1] + ey
            if math.hypot(x - sx, y - sy) <= rng_m and rng.random() < pd:
                nx, ny = rng.normal(0, sigma, 2)
                pts.append((x + nx, y + ny))
    return pts


def hits(sim: "Sim", proj: Projection, ox: float, oy: float) -> list[tuple[float, int, dict]]:
    """Raw detections of hostile entities (and false alarms) by every sensor, from the true state.
    The groups in `sim.apart` are sensed from a stream of their own, after the others in each
    scan: adding them leaves what the sensors make of every other group as it was."""
    rng = np.random.default_rng(sim.seed + 2)
    own = np.random.default_rng([sim.seed, 2, 17])
    main = [h for h in sorted(sim.hostiles) if h not in sim.apart]
    apart = [h for h in sorted(sim.hostiles) if h in sim.apart]
    offs = {h: rng.uniform(-60, 60, (sim.hostiles[h].strength, 2)) for h in main}
    offs.update({h: own.uniform(-60, 60, (sim.hostiles[h].strength, 2)) for h in apart})
    out = []
    for sid, group, owner, kind, rng_m, pd, sigma, fa in SENSORS:
        phase = float(rng.uniform(0, SENSOR_PERIOD))
        t = phase
        while t < DURATION:
            sx, sy = sensor_pos(sim, sid, t)
            pts = _sensed(sim, main, offs, t, sx, sy, rng_m, pd, sigma, rng)
            for _ in range(rng.poisson(fa)):
                r, a = rng_m * math.sqrt(rng.random()), rng.uniform(0, 2 * math.pi)
                pts.append((sx + r * math.cos(a), sy + r * math.sin(a)))
            pts += _sensed(sim, apart, offs, t, sx, sy, rng_m, pd, sigma, own)
            for x, y in pts:
                lon, lat = proj.to_lonlat(x + ox, y + oy)
                out.append((round(t, 2), {"kind": "hit", "t": round(t, 2), "sensor": sid,
                                          "lon": round(float(lon), 7), "lat": round(float(lat), 7)}))
            t += SENSOR_PERIOD
    return out
