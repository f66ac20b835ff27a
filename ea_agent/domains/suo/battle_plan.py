"""What the generated battalion is ordered to do: its sector's constants (the lanes, the
missions of each phase), the overlay of control measures and the plan document (task
organization, the main plan and the withdrawal branch). The battle that then happens,
true state and reports, is `generator`'s."""
from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from .generator import Sim

EPSG = 32611
ORIGIN_LONLAT = (-116.62, 35.22)   # south-west corner of the battalion sector
DURATION = 5400.0
WITHDRAW_Y = 7000.0   # the battle positions on PL BLUE the withdrawal plan falls back to
COMPANIES = ("A", "B", "C")
LANE_X = {"A1": 700, "A2": 2000, "A3": 3300, "B1": 4700, "B2": 6000, "B3": 7300,
          "C1": 8700, "C2": 10000, "C3": 11300}
SQUAD_DX = (-150.0, -50.0, 50.0, 150.0)
SQUAD_DY = (30.0, 0.0, -30.0, -60.0)
MOVE_PLT = {"A1": "move", "A2": "move", "A3": "move", "B1": "tactical-road-march", "B2": "move", "B3": "move",
            "C1": "movement-to-contact", "C2": "move", "C3": "follow-and-support"}
ATTACK_PLT = {"A1": "attack", "A2": "seize", "A3": "follow-and-assume", "B1": "attack", "B2": "clear",
              "B3": "breach", "C1": "secure", "C2": "destroy", "C3": "isolate"}
DEFEND_PLT = {"A1": "defend", "A2": "defend", "A3": "retain", "B1": "block", "B2": "defend", "B3": "occupy",
              "C1": "overwatch", "C2": "defend", "C3": "contain"}


def _rect(x0, y0, x1, y1):
    return [[[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]]


def overlay_features() -> list[dict]:
    """Control measures in local metres (converted to lon/lat when written)."""
    F = []

    def add(fid, kind, gtype, coords, owner=None, **props):
        F.append({"type": "Feature", "geometry": {"type": gtype, "coordinates": coords},
                  "properties": {"id": fid, "kind": kind, **({"owner": owner} if owner else {}), **props}})
    add("BND-BN", "boundary", "Polygon", _rect(-500, -2500, 12500, 22000), "BN")
    for k, co in enumerate(COMPANIES):
        add(f"BND-{co}", "boundary", "Polygon", _rect(4000 * k, -2500 if k else -2500, 4000 * (k + 1), 22000), co)
        add(f"PL-BLUE-{co}", "phase-line", "LineString", [[4000 * k, 7000], [4000 * (k + 1), 7000]], co)
        add(f"OBJ-{co}", "objective", "Polygon", _rect(4000 * k + 200, 10400, 4000 * (k + 1) - 200, 11600), co)
    for p, x in LANE_X.items():
        add(f"RTE-{p}", "route", "LineString", [[x, 0], [x, 3500], [x, 7000]], p[0])
        add(f"BP-{p}-BLUE", "battle-position", "Polygon", _rect(x - 300, 6700, x + 300, 7300), p[0])
        add(f"BP-{p}", "battle-position", "Polygon", _rect(x - 300, 10700, x + 300, 11300), p[0])
    add("RTE-A3-ATK", "route", "LineString", [[3300, 7000], [3300, 11000]], "A")
    add("AA-BN", "assembly-area", "Polygon", _rect(5700, -1300, 6300, -700), "BN")
    add("BP-M1", "battle-position", "Polygon", _rect(5600, 1700, 6400, 2300), "BN")
    add("BP-M2", "battle-position", "Polygon", _rect(5600, 7700, 6400, 8300), "BN")
    add("RTE-M", "route", "LineString", [[6000, 2000], [6000, 8000]], "BN")
    add("SCREEN-R", "area", "Polygon", _rect(800, 14700, 3200, 15300), "BN")
    add("NAI-SCREEN", "nai", "Polygon", _rect(0, 15500, 4000, 19000), "R")
    add("ZONE-R", "area", "Polygon", _rect(0, 14200, 4000, 15400), "R")
    add("NAI-1", "nai", "Point", [2000, 17500], "BN", radius_m=700)
    add("NAI-A", "nai", "Point", [1500, 15000], "A", radius_m=500)
    add("DP1", "decision-point", "Point", [9000, 17000], "BN", radius_m=500)
    add("DP2", "decision-point", "Point", [6000, 16500], "BN", radius_m=500)
    add("AA-DIAMOND", "avenue-of-approach", "LineString", [[6000, 21000], [6000, 12000]], "BN", width_m=1000)
    add("AA-RUBY", "avenue-of-approach", "LineString", [[10650, 21000], [10650, 12000]], "C", width_m=1000)
    add("EA-A", "engagement-area", "Polygon", _rect(1000, 12500, 3000, 14000), "A")
    add("EA-B", "engagement-area", "Polygon", _rect(5000, 12000, 7000, 14000), "B")
    add("CP-LINK", "checkpoint", "Point", [4000, 9000], "BN", radius_m=300)
    add("OBS-B3", "obstacle", "LineString", [[LANE_X["B3"] - 400, 9000], [LANE_X["B3"] + 400, 9000]], "B")
    add("PL-AMBER", "phase-line", "LineString", [[0, 9000], [12000, 9000]], "BN")
    add("LANE-C", "area", "Polygon", _rect(10700, 10600, 10950, 11400), "C")   # C2's passage lane: C2S4 keeps west of it
    for name, y in (("SP-B1", 0), ("CP-B1", 3500), ("RP-B1", 7000)):   # B1's march table
        add(name, "checkpoint", "Point", [LANE_X["B1"], y], "B", radius_m=250)
    add("CP-C", "checkpoint", "Point", [10650, 11000], "C", radius_m=300)
    # a line B1 may block instead of its position: in front of BP-B1, across its lane west of the
    # avenue down x = 6000 (groups that halt just short of a line would be projected to cross it)
    add("PL-B1-BLOCK", "phase-line", "LineString", [[4000, 11450], [5000, 11450]], "B")
    return F


def plan_doc(sim: "Sim") -> dict:
    to = []
    for u in sim.units:
        d = {k: u[k] for k in ("id", "name", "echelon", "parent") if k in u}
        for k in ("boundary", "weapons_range_m"):
            if k in u:
                d[k] = u[k]
        d["entities"] = sorted(e for e, leaf in sim.entity_leaf.items() if leaf == u["id"])
        to.append(d)
    M = []

    def m(mid, unit, typ, start=None, end=None, after=(), **params):
        d = {"id": mid, "unit": unit, "type": typ}
        if start:
            d["start"] = {"type": start[0], "t": start[1]} if start[1] is not None else {"type": start[0]}
        if end:
            d["end"] = {"type": end[0], "t": end[1]}
        if after:
            d["after"] = list(after)
        d["params"] = params
        M.append(d)
    for p in LANE_X:
        co = p[0]
        extra = {"supported": "C2"} if p == "C3" else {}
        if p == "B1":   # its march table: CP-B1 planned 150 s before B1 can make it
            extra = {"checkpoints": [{"point": "SP-B1", "t": 300}, {"point": "CP-B1", "t": 1050},
                                     {"point": "RP-B1", "t": 2100}]}
        m(f"{p}-move", p, MOVE_PLT[p], ("START-NLT", 300), ("END-NLT", 2160),
          route=f"RTE-{p}", destination=f"BP-{p}-BLUE", **extra)
        atk = ({"route": "RTE-A3-ATK", "destination": "BP-A3", "supported": "A2"} if p == "A3"
               else {"objective": f"OBJ-{co}", "line_of_departure": f"PL-BLUE-{co}"})
        if p == "B3":   # through the obstacle belt in its lane, planned faster than it can go
            atk.update(obstacle="OBS-B3", by=2900)
        if p == "A2":   # OBJ-A wanted in hand by 3300: A2 gets there at about 3450
            atk.update(by=3300)
        start = ("START-NET", 2400) if p == "C1" else ("START-NLT", 2400)
        m(f"{p}-attack", p, ATTACK_PLT[p], start, ("END-NLT", 3660), after=[f"{p}-move"], **atk)
        dfd = {"position": f"BP-{p}"}
        if p == "A2":
            dfd.update(engagement_area="EA-A", expect_hostile_by=4800)
        if p == "B2":
            dfd.update(engagement_area="EA-B", expect_hostile_by=4800)
        if DEFEND_PLT[p] == "block":   # what it blocks: the battle position itself, or the line north of it
            dfd.update({"line": f"PL-{p}-BLOCK"} if sim.block_line else {"area": f"BP-{p}"})
        m(f"{p}-defend", p, DEFEND_PLT[p], ("START-NLT", 3760), None, after=[f"{p}-attack"], **dfd)
    for co in COMPANIES:
        m(f"{co}-mtc", co, "movement-to-contact", ("START-NLT", 300), ("END-NLT", 2460), destination=f"PL-BLUE-{co}")
        m(f"{co}-attack", co, "hasty-attack", ("START-NLT", 2460), ("END-NLT", 3660), after=[f"{co}-mtc"],
          objective=f"OBJ-{co}")
        m(f"{co}-defend", co, "defend", ("START-NLT", 3760), None, after=[f"{co}-attack"], position=f"OBJ-{co}")
    # R is also to reconnoitre the ground south of its screen by 1800; it never leaves the
    # screen line, so it sees a third of it (before R-screen: that is R's mission for threats)
    m("R-zone", "R", "area-reconnaissance" if sim.area_recon else "zone-reconnaissance", ("START-AT", 0),
      ("END-NLT", 1800), position="SCREEN-R", area="ZONE-R")
    m("R-screen", "R", "screen", ("START-AT", 0), None, position="SCREEN-R", area="NAI-SCREEN")
    m("M-occupy", "M", "occupy", ("START-AT", 0), ("END-AT", 2200), position="BP-M1")
    m("M-march", "M", "tactical-road-march", ("ON-ORDER", None), ("END-NLT", 2900), after=["M-occupy"],
      route="RTE-M", destination="BP-M2")
    m("M-sbf", "M", "support-by-fire", ("START-NLT", 2900), None, after=["M-march"], position="BP-M2",
      supported="B", line="PL-BLUE-B", target="OBJ-B")   # planned after B departs: not in position by then
    m("BNHQ-occupy", "BNHQ", "occupy", ("START-AT", 0), None, position="AA-BN")
    m("BN-reorg-R", "BN", "reorganize", ("START-AT", sim.reorg_t), None, subject="R", new_parent="BN")
    m("A3-linkup", "A3", "link-up", None, None, partner="B1", point="CP-LINK", at=3000)
    m("C2-passage", "C2", "passage-of-lines", None, None, partner="C3", point="CP-C", at=4000, lane="LANE-C")
    # hostiles at DP2: M is to break their tempo down AA-DIAMOND by 3900 (H3 keeps coming until 4333)
    m("BN-branch-disrupt", "M", "branch", None, None, owner="BN", task="disrupt",
      trigger={"kind": "hostile-in-area", "area": "DP2", "min_strength": 1},
      task_params={"position": "BP-M2", "avenue": "AA-DIAMOND", "by": 3900})
    # A1 on OBJ-A: it is to suppress EA-A from there 3700-4000 (1.5 km away: beyond its range)
    m("A-sequel-suppress", "A1", "sequel", None, None, owner="A", task="suppress",
      trigger={"kind": "unit-at", "unit": "A1", "area": "OBJ-A", "within_m": 0.0},
      task_params={"position": "OBJ-A", "target": "EA-A", "window": [3700, 4000]})
    alt = [{"id": f"{p}-withdraw", "unit": p, "type": "withdraw", "start": {"type": "ASAP"},
            "params": {"destination": f"BP-{p}-BLUE"}} for p in LANE_X]
    alt[list(LANE_X).index("C1")].update(type="delay", params={"destination": "BP-C1-BLUE", "line": "PL-AMBER",
                                                                "until": 4850})   # C1 delays north of PL AMBER
    return {"task_organization": to, "plans": {"main": M, "withdrawal": alt}, "initial_plan": "main"}
