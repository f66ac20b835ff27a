"""Seeded, deterministic brigade scenario (issue 14): three battalions side by side plus
brigade troops, far larger than anything worth committing (`saim_mesh.ondemand` makes it).

Each battalion is the battalion generator's battle (`generator.build_sim`), shifted east
by its sector's width and with every id renamed (unit `A1` of 2nd BN is `2A1`, its
entities `2A1S1E01`, its missions `2A1-move`, its hostiles `2H3`, its overlay features
`2-OBJ-A`), so the same incident machinery and the same oracle label its ground truth.
1st BN fights the labelled scripted battle; 2nd and 3rd BN each a battle drawn from the
seed (`random_battle`), without the withdrawal order: an order to switch plans is
scenario-wide, and one battalion cannot switch the brigade's plan. The brigade troops
(cavalry troop, artillery battery, support company: company-sized, directly under BDE)
and the brigade HQ occupy positions south of the battalions' sectors.
"""
from __future__ import annotations

import heapq
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ea_agent.core.geo import Projection

from .battle_plan import DURATION, EPSG, ORIGIN_LONLAT, SQUAD_DX, SQUAD_DY, overlay_features
from .battle_plan import plan_doc as battalion_plan
from .generator import events as battalion_events
from .generator import lonlat_features, write_events
from .sim import INCIDENTS, Hostile, Sim, build_sim, place_entities

BATTALIONS = ("1", "2", "3")              # id prefixes: 1BN, 2BN, 3BN
ORDINAL = {"1": "1st", "2": "2nd", "3": "3rd"}
SECTOR_W = 13000.0                         # a battalion's boundary is 13 km wide (BND-BN: -500..12500)
BDE_BOX = (-500.0, -9000.0, 3 * SECTOR_W - 500.0, 22000.0)
SMALL_DURATION = 1200.0
REPORT_S = 30.0                            # the battalion's per-entity report interval
MULT = 3                                   # entities per battalion leaf: 3x the battalion scenario's
# brigade troops: company id -> (name, platoon centres in brigade metres)
TROOPS = {"CAV": ("Cavalry Troop", [(4000.0, -5000.0), (6000.0, -5000.0), (8000.0, -5000.0)]),
          "FA": ("Artillery Battery", [(14000.0, -4500.0), (16000.0, -4500.0)]),
          "SPT": ("Support Company", [(22000.0, -7000.0), (24000.0, -7000.0), (26000.0, -7000.0)])}
BDEHQ_XY = (19000.0, -6000.0)
DEFAULT_EAS = ["BDE", "1BN", "2BN", "3BN", "1A", "2B", "3C", "CAV", "1A2"]
RENAMED_KEYS = ("entity", "track", "mission", "unit", "requester", "issuer", "cff")   # event fields holding ids


def battalion_seeds(seed: int) -> list[int]:
    """One seed per battalion, drawn from the brigade's: each battalion a battle of its own."""
    rng = np.random.default_rng([seed, 14])
    return [int(s) for s in rng.integers(0, 2**31, size=len(BATTALIONS))]


@dataclass
class TroopSim(Sim):
    """The brigade troops and HQ: leaves that hold their positions all battle long."""
    centers: dict[str, tuple[float, float]] = field(default_factory=dict)

    def leaf_center(self, leaf: str, t: float):
        return self.centers[leaf]

    def reports_at(self, e: str, t: float) -> bool:
        return True


@dataclass
class Part:
    """One battalion's battle (or the troops) placed in the brigade: `dx` east, ids prefixed."""
    prefix: str
    dx: float
    sim: Sim

    def gid(self, local: str) -> str:
        return self.prefix + local

    def fid(self, local: str) -> str:
        return f"{self.prefix}-{local}" if self.prefix else local


def _troops(small: bool, seed: int, duration: float) -> tuple[TroopSim, list[dict], list[dict]]:
    """The troops' sim, their overlay features (brigade metres) and their missions."""
    per_squad, hq = (2, 2) if small else (10, 12)
    sim = TroopSim(small=small, seed=seed, duration=duration, report_s=REPORT_S)
    u = sim.units = [{"id": "BDE", "name": "1st BDE", "echelon": "brigade", "parent": None,
                      "boundary": "BND-BDE", "weapons_range_m": 1000.0},
                     {"id": "BDEHQ", "name": "BDE HQ", "echelon": "squad", "parent": "BDE", "n": 4 if small else 24}]
    sim.centers["BDEHQ"] = BDEHQ_XY
    feats = [_feature("BND-BDE", "boundary", _box(*BDE_BOX), "BDE"),
             _feature("AA-BDE", "assembly-area", _box(BDEHQ_XY[0] - 300, BDEHQ_XY[1] - 300,
                                                      BDEHQ_XY[0] + 300, BDEHQ_XY[1] + 300), "BDE")]
    missions = [_occupy("BDEHQ-occupy", "BDEHQ", "AA-BDE")]
    for co, (name, centers) in TROOPS.items():
        u.append({"id": co, "name": name, "echelon": "company", "parent": "BDE"})
        xs, ys = [c[0] for c in centers], [c[1] for c in centers]
        hq_xy = (sum(xs) / len(xs), min(ys) - 500.0)
        u.append({"id": f"{co}HQ", "name": f"HQ, {name}", "echelon": "squad", "parent": co, "n": hq})
        sim.centers[f"{co}HQ"] = hq_xy
        feats.append(_feature(f"AA-{co}", "assembly-area",
                              _box(min(xs) - 500, hq_xy[1] - 300, max(xs) + 500, max(ys) + 500), co))
        missions.append(_occupy(f"{co}-occupy", co, f"AA-{co}"))
        for i, (x, y) in enumerate(centers, 1):
            p = f"{co}{i}"
            u.append({"id": p, "name": f"{i} PLT, {name}", "echelon": "platoon", "parent": co})
            feats.append(_feature(f"BP-{p}", "battle-position", _box(x - 300, y - 200, x + 300, y + 200), co))
            missions.append(_occupy(f"{p}-occupy", p, f"BP-{p}"))
            for s in (1, 2, 3, 4):
                u.append({"id": f"{p}S{s}", "name": f"{s} SQD, {i} PLT, {name}", "echelon": "squad",
                          "parent": p, "n": per_squad})
                sim.centers[f"{p}S{s}"] = (x + SQUAD_DX[s - 1], y + SQUAD_DY[s - 1])
    place_entities(sim, u, np.random.default_rng([seed, 14, 99]))
    sim.confirmations = sorted((0.0, m["id"], m["unit"], "start") for m in missions)
    return sim, feats, missions


def _box(x0: float, y0: float, x1: float, y1: float) -> list:
    return [[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]]


def _feature(fid: str, kind: str, rect: list, owner: str) -> dict:
    return {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": rect},
            "properties": {"id": fid, "kind": kind, "owner": owner}}


def _occupy(mid: str, unit: str, position: str) -> dict:
    return {"id": mid, "unit": unit, "type": "occupy", "start": {"type": "START-AT", "t": 0.0},
            "params": {"position": position}}


@dataclass
class BrigadeSim:
    """The brigade's true state: what the oracle reads of a battalion `Sim`, over the parts."""
    small: bool
    seed: int
    duration: float
    parts: list[Part]
    troops: TroopSim
    report_s: float = REPORT_S
    order: dict | None = None
    sensors: list = field(default_factory=list)
    units: list[dict] = field(default_factory=list)
    entity_leaf: dict[str, str] = field(default_factory=dict)
    entity_off: dict[str, tuple[float, float]] = field(default_factory=dict)
    report_phase: dict[str, float] = field(default_factory=dict)
    hostiles: dict[str, Hostile] = field(default_factory=dict)
    confirmations: list[tuple[float, str, str, str]] = field(default_factory=list)
    cffs: list[dict] = field(default_factory=list)
    mission_orders: list[dict] = field(default_factory=list)   # ON-ORDER missions ordered to start or end
    _where: dict[str, tuple[Part, str]] = field(default_factory=dict)   # global leaf or entity -> (part, local)

    @property
    def battalions(self) -> list[Part]:
        return self.parts[1:]

    def leaf_center(self, leaf: str, t: float):
        part, local = self._where[leaf]
        x, y = part.sim.leaf_center(local, t)
        return x + part.dx, y

    def entity_pos(self, e: str, t: float):
        part, local = self._where[e]
        x, y = part.sim.entity_pos(local, t)
        return x + part.dx, y

    def reports_at(self, e: str, t: float) -> bool:
        part, local = self._where[e]
        return part.sim.reports_at(local, t)

    def sensor_xy(self, sid: str, t: float) -> tuple[float, float]:
        raise KeyError(f"the brigade has no sensors ({sid!r})")


def build(small: bool = False, seed: int = 7) -> BrigadeSim:
    """The brigade's true battle (no events yet: cheap enough to count entities)."""
    duration = SMALL_DURATION if small else DURATION
    troops, _f, _m = _troops(small, seed, duration)
    parts = [Part("", 0.0, troops)]   # first: BDE heads the task organization
    for k, (pre, s) in enumerate(zip(BATTALIONS, battalion_seeds(seed))):
        sim = build_sim(small, s, "scripted" if k == 0 else "random", mult=1 if small else MULT,
                          plan_switch=False, report_s=REPORT_S)
        sim.duration = duration   # the small variant ends early: nothing after its end happens
        sim.confirmations = [c for c in sim.confirmations if c[0] <= duration]
        sim.mission_orders = [o for o in sim.mission_orders if o["t"] <= duration]
        sim.cffs = [c for c in sim.cffs if c["t"] <= duration]
        parts.append(Part(pre, k * SECTOR_W, sim))
    b = BrigadeSim(small, seed, duration, parts, troops)
    for part in parts:
        for u in part.sim.units:
            d = dict(u, id=part.gid(u["id"]))
            if part.prefix:
                d["parent"] = part.gid(u["parent"]) if u["parent"] else "BDE"
                d["name"] = f"{u['name']}, {ORDINAL[part.prefix]} BN" if u["id"] != "BN" else f"{ORDINAL[part.prefix]} BN"
                if "boundary" in u:
                    d["boundary"] = part.fid(u["boundary"])
            b.units.append(d)
            if d.get("n"):
                b._where[d["id"]] = (part, u["id"])
        for e, leaf in part.sim.entity_leaf.items():
            g = part.gid(e)
            b.entity_leaf[g] = part.gid(leaf)
            b.entity_off[g] = part.sim.entity_off[e]
            b.report_phase[g] = part.sim.report_phase[e]
            b._where[g] = (part, e)
        for h in part.sim.hostiles.values():
            b.hostiles[part.gid(h.id)] = Hostile(part.gid(h.id), h.ts, [x + part.dx for x in h.xs], h.ys,
                                                   h.strength, h.appear, h.vanish)
        b.confirmations += [(t, part.gid(m), part.gid(u), ph) for t, m, u, ph in part.sim.confirmations]
        b.mission_orders += [dict(o, mission=part.gid(o["mission"]), issuer=part.gid(o["issuer"]))
                             for o in part.sim.mission_orders]
        b.cffs += [dict(c, cff=part.gid(c["cff"]), requester=part.gid(c["requester"]), x=c["x"] + part.dx)
                   for c in part.sim.cffs]
    b.confirmations.sort()
    b.mission_orders.sort(key=lambda o: (o["t"], o["mission"]))
    b.cffs.sort(key=lambda c: (c["t"], c["cff"], c["kind"]))
    return b


def _renamer(part: Part, feature_ids: set[str], ids: set[str]):
    """Rename every id a plan's missions mention (units, missions, features) into `part`'s names."""
    def rn(v, key=None):
        if isinstance(v, dict):
            return {k: rn(x, k) for k, x in v.items()}
        if isinstance(v, list):
            return [rn(x, key) for x in v]
        if isinstance(v, str) and key not in ("type", "kind"):
            if v in feature_ids:
                return part.fid(v)
            if v in ids:
                return part.gid(v)
        return v
    return rn


def overlay(b: BrigadeSim) -> list[dict]:
    """Every battalion's control measures (renamed, shifted), the troops' and the brigade's."""
    feats = []
    for part in b.battalions:
        for f in overlay_features():
            p = dict(f["properties"], id=part.fid(f["properties"]["id"]))
            if "owner" in p:
                p["owner"] = part.gid(p["owner"])
            feats.append({"type": "Feature", "geometry": {"type": f["geometry"]["type"],
                                                          "coordinates": _shift(f["geometry"]["coordinates"], part.dx)},
                          "properties": p})
    return _troops(b.small, b.seed, b.duration)[1] + feats


def _shift(coords, dx: float):
    if isinstance(coords[0], (int, float)):
        return [coords[0] + dx, coords[1]]
    return [_shift(c, dx) for c in coords]


def plan_doc(b: BrigadeSim) -> dict:
    """The brigade's plan: the task organization and every battalion's plans, renamed, with the troops'."""
    to = []
    for u in b.units:
        d = {k: u[k] for k in ("id", "name", "echelon", "parent", "boundary", "weapons_range_m") if k in u}
        d["entities"] = []
        to.append(d)
    ents: dict[str, list[str]] = {}
    for e, leaf in b.entity_leaf.items():
        ents.setdefault(leaf, []).append(e)
    for d in to:
        d["entities"] = sorted(ents.get(d["id"], []))
    plans: dict[str, list] = {"main": [], "withdrawal": []}
    fids = {f["properties"]["id"] for f in overlay_features()}
    for part in b.battalions:
        doc = battalion_plan(part.sim)
        ids = {u["id"] for u in part.sim.units} | {m["id"] for pl in doc["plans"].values() for m in pl}
        rn = _renamer(part, fids, ids)
        for name, ms in doc["plans"].items():
            plans[name] += [rn(m) for m in ms]
    plans["main"] = _troops(b.small, b.seed, b.duration)[2] + plans["main"]
    return {"task_organization": to, "plans": plans, "initial_plan": "main"}


def events(b: BrigadeSim, proj: Projection, ox: float, oy: float):
    """Every part's events (the battalion generator's), renamed, merged in time order."""
    streams = []
    for part in b.parts:
        evs = battalion_events(part.sim, proj, ox + part.dx, oy)
        if part.prefix:
            for e in evs:
                for k in RENAMED_KEYS:
                    if k in e:
                        e[k] = part.gid(e[k])
        streams.append(evs)
    return heapq.merge(*streams, key=lambda e: e["t"])   # stable: ties keep the parts' order


def write(out: Path, small: bool = False, seed: int = 7) -> dict:
    """Generate the brigade scenario folder `out`; returns a summary."""
    from . import oracle
    out.mkdir(parents=True, exist_ok=True)
    proj = Projection(EPSG)
    ox, oy = proj.to_xy(*ORIGIN_LONLAT)
    b = build(small, seed)
    feats = overlay(b)
    meta = {"name": "brigade-small" if small else "brigade", "epsg": EPSG, "duration_s": b.duration,
            "generator": {"seed": seed, "small": small, "brigade": True}, "default_eas": DEFAULT_EAS,
            "description": "1st BDE: 1st, 2nd and 3rd BN side by side move to PL BLUE, attack and defend; "
                           "brigade troops hold the rear (Fort Irwin, UTM 11N)"}
    (out / "scenario.json").write_text(json.dumps(meta, indent=1) + "\n")
    (out / "overlay.geojson").write_text(json.dumps({"type": "FeatureCollection",
                                                     "features": lonlat_features(feats, proj, ox, oy)}) + "\n")
    plan = plan_doc(b)
    (out / "plan.json").write_text(json.dumps(plan, indent=1) + "\n")
    n = [0]

    def counted(evs):
        for e in evs:
            n[0] += 1
            yield e
    write_events(out, counted(events(b, proj, ox, oy)))
    truth = oracle.ground_truth(b, feats, plan, meta["default_eas"])
    truth["incidents_injected"] = [
        {"battalion": part.gid("BN"), "incidents": INCIDENTS if part.sim.incidents == "scripted" else part.sim.drawn,
         "ids": f"the battalion's own: prefix {part.prefix!r} for units, missions and hostiles, "
                f"'{part.prefix}-' for places"} for part in b.battalions]
    (out / "truth.json").write_text(json.dumps(truth, indent=1) + "\n")
    return {"events": n[0], "entities": len(b.entity_leaf), "incidents": len(truth["incidents"]),
            "situations": len(truth["situations"])}
