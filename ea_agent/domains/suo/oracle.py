"""Ground truth from the simulated true state, written apart from the detectors.

It samples the true world every TICK seconds (no report staleness, no GPS noise)
and says, per EA owner:
 - incidents: what the EA must alert, of which type(s), within which window;
 - situations: when an alert of a type is justified at all (a real situation
   exists), so that any alert outside every situation counts as unwanted.
VOI thresholds come from the same config file the EAs use (they are the user's
statement of what is worth knowing); clear incidents need a margin beyond them.
"""
from __future__ import annotations

import math
from collections import defaultdict

import numpy as np
from shapely.geometry import Point, Polygon, shape

from ea_agent.core.config import load_config
from .missions import REGISTRY, ContingentMission, ReorganizationMission

TICK = 5.0
SLACK = 40.0        # friendly reports may be up to one report interval old
PROX = ["contact", "distance", "strength", "proximity"]


def _runs(ts: list[float]) -> list[tuple[float, float]]:
    """Consecutive tick times -> [(first, last)] intervals."""
    out: list[list[float]] = []
    for t in ts:
        if out and t - out[-1][1] <= TICK + 1e-6:
            out[-1][1] = t
        else:
            out.append([t, t])
    return [(a, b) for a, b in out]


class Truth:
    def __init__(self, sim, feats: list[dict], plan: dict, owners: list[str]):
        self.sim, self.owners = sim, owners
        self.cfg = load_config()
        self.voi = self.cfg["voi"]
        self.geom: dict[str, object] = {}
        self.area: dict[str, object] = {}
        self.props: dict[str, dict] = {}
        for f in feats:
            p = f["properties"]
            g = shape(f["geometry"])
            self.geom[p["id"]] = g
            self.props[p["id"]] = p
            if isinstance(g, Polygon):
                self.area[p["id"]] = g
            elif isinstance(g, Point):
                self.area[p["id"]] = g.buffer(p.get("radius_m", 250.0))
            else:
                self.area[p["id"]] = g.buffer(p.get("width_m", 500.0 if p["kind"] == "avenue-of-approach" else 100.0) / 2)
        self.units = {u["id"]: u for u in plan["task_organization"]}
        self.missions = {m["id"]: m for m in plan["plans"][plan["initial_plan"]]}
        self.reorgs = sorted((m["start"]["t"], m["params"]["subject"], m["params"]["new_parent"])
                             for m in self.missions.values() if issubclass(REGISTRY[m["type"]], ReorganizationMission))
        self.ticks = np.arange(0.0, sim_duration(sim) + TICK / 2, TICK)
        self.leaves = sorted(u for u, d in self.units.items() if d["entities"])
        self.leaf_xy = {leaf: np.array([sim.leaf_center(leaf, t) for t in self.ticks]) for leaf in self.leaves}
        self.offsets = {leaf: np.array([sim.entity_off[e] for e in self.units[leaf]["entities"]]) for leaf in self.leaves}
        self._sub_cache: dict = {}
        self.started = {}
        self.ended = {}
        for m in self.missions.values():   # executed by the EA itself at its start time
            if REGISTRY[m["type"]].AUTO_START and m.get("start", {}).get("t") is not None:
                self.started[m["id"]] = self.ended[m["id"]] = m["start"]["t"]
        for t, mid, _unit, ph in sim.confirmations:
            (self.started if ph == "start" else self.ended).setdefault(mid, t)
        self.incidents: list[dict] = []
        self.situations: list[dict] = []

    # -- task organization over time ----------------------------------------------------
    def parent_at(self, t: float) -> dict[str, str | None]:
        par = {u: d.get("parent") for u, d in self.units.items()}
        for tr, subj, newp in self.reorgs:
            if tr <= t:
                par[subj] = newp
        return par

    def subtree(self, owner: str, t: float) -> set[str]:
        key = (owner, sum(1 for tr, _, _ in self.reorgs if tr <= t))
        hit = self._sub_cache.get(key)
        if hit is None:
            hit = self._sub_cache[key] = self._subtree(owner, t)
        return hit

    def _subtree(self, owner: str, t: float) -> set[str]:
        par = self.parent_at(t)
        out = {owner}
        changed = True
        while changed:
            changed = False
            for u, p in par.items():
                if p in out and u not in out:
                    out.add(u)
                    changed = True
        return out

    def platoon_of(self, unit: str, t: float) -> str:
        par = self.parent_at(t)
        u = unit
        while u is not None:
            if self.units[u]["echelon"] in ("platoon", "company", "battalion"):
                return u
            u = par[u]
        return unit

    def member_points(self, unit: str, k: int) -> np.ndarray:
        st = self.subtree(unit, self.ticks[k])
        return np.concatenate([self.leaf_xy[leaf][k] + self.offsets[leaf] for leaf in self.leaves if leaf in st])

    def judged(self, geom, unit: str, k: int, rule: str) -> float:
        pts = self.member_points(unit, k)
        if rule == "centroid":
            return geom.distance(Point(pts.mean(axis=0)))
        ds = [geom.distance(Point(p)) for p in pts]
        return min(ds) if rule == "any" else max(ds)

    def hostiles_at(self, t: float) -> dict[str, tuple[float, float, int]]:
        out = {}
        for h in self.sim.hostiles.values():
            p = h.pos(t)
            if p is not None:
                out[h.id] = (p[0], p[1], h.strength)
        return out

    def owners_of(self, unit: str, t: float) -> list[str]:
        return [o for o in self.owners if unit in self.subtree(o, t)]

    # -- recording ----------------------------------------------------------------------
    def must(self, owner, typ, accept, subjects, t0, t1, label=""):
        self.incidents.append({"owner": owner, "type": typ, "accept": sorted(set(accept) | {typ}),
                               "subjects": sorted(set(subjects)), "t0": round(t0, 1), "t1": round(t1, 1),
                               "label": label})
        self.may(owner, accept + [typ], subjects, t0, t1)

    def may(self, owner, accept, subjects, t0, t1):
        self.situations.append({"owner": owner, "accept": sorted(set(accept)), "subjects": sorted(set(subjects)),
                                "t0": round(t0, 1), "t1": round(t1, 1)})

    # -- per alert type ----------------------------------------------------------------------
    def thr(self, m: dict, key: str) -> float:
        return float(m["params"].get("voi", {}).get(key, self.voi[key]))

    def out_of_position(self) -> None:
        for mid, m in self.missions.items():
            cls = REGISTRY[m["type"]]
            p = m["params"]
            cont = p.get("route") or p.get("axis") or p.get("position")
            if issubclass(cls, (ContingentMission, ReorganizationMission)) or mid not in self.started:
                continue
            thr = self.thr(m, "out_of_position_m")
            s, e = self.started[mid], self.ended.get(mid, math.inf)
            if cont:
                geom = self.geom[cont] if (p.get("route") or p.get("axis")) else self.area[cont]
                hits, peak = [], 0.0
                for k, t in enumerate(self.ticks):
                    if s <= t < e:
                        d = self.judged(geom, m["unit"], k, cls.LOCATION_RULE)
                        if d > thr:
                            hits.append(t)
                            peak = max(peak, d)
                for a, b in _runs(hits):
                    for o in self.owners_of(m["unit"], a):
                        if peak > 1.5 * thr and b - a >= 30:
                            self.must(o, "out-of-position", [], [m["unit"]], a - SLACK, a + 60, f"{mid} off {cont}")
                        self.may(o, ["out-of-position"], [m["unit"]], a - SLACK, b + SLACK)
            dest = p.get("destination") or p.get("objective")
            if dest and math.isfinite(e) and dest in self.area and "destination" in cls.GEOMETRY_PARAMS or (
                    dest and math.isfinite(e) and "objective" in cls.GEOMETRY_PARAMS):
                k = int(round(e / TICK))
                rule = getattr(cls, "FINAL_RULE", cls.LOCATION_RULE)
                d = self.judged(self.area[dest], m["unit"], k, rule)
                if d > thr:
                    for o in self.owners_of(m["unit"], e):
                        self.must(o, "out-of-position", [], [m["unit"]], e - 1, e + 5, f"{mid} not at {dest}")

    def fratricide(self) -> None:
        hits: dict[tuple[str, str, str], list[float]] = defaultdict(list)
        for k, t in enumerate(self.ticks):
            par = self.parent_at(t)

            def bowner(u):
                while u is not None and not self.units[u].get("boundary"):
                    u = par[u]
                return u
            info = []
            for leaf in self.leaves:
                pts = self.member_points(leaf, k)
                b = bowner(leaf)
                c = pts.mean(axis=0)
                info.append((leaf, c, b, self.area[self.units[b]["boundary"]] if b else None,
                             self.units[leaf].get("weapons_range_m") or self._range(leaf, par)))
            for i in range(len(info)):
                a, ca, ba, pa_, ra = info[i]
                if ba is None:
                    continue
                in_own_a = pa_.contains(Point(ca))
                for j in range(i + 1, len(info)):
                    b, cb, bb, pb_, rb = info[j]
                    if bb is None or bb == ba:
                        continue
                    d = float(np.hypot(*(ca - cb)))
                    if d > max(ra, rb):
                        continue
                    in_own_b = pb_.contains(Point(cb))
                    if ((not in_own_a and pb_.contains(Point(ca))) or (not in_own_b and pa_.contains(Point(cb)))
                            or (not in_own_a and not in_own_b)):
                        pla, plb = sorted([self.platoon_of(a, t), self.platoon_of(b, t)])
                        for o in self.owners:
                            st = self.subtree(o, t)
                            if a in st or b in st:
                                hits[(o, pla, plb)].append(t)
        for (o, pla, plb), ts in hits.items():
            for a, b in _runs(ts):
                if b - a >= 30:
                    self.must(o, "fratricide", [], [pla, plb], a - SLACK, a + 60, f"{pla} and {plb}")
                self.may(o, ["fratricide"], [pla, plb], a - SLACK, b + SLACK)

    def _range(self, unit, par) -> float:
        u = unit
        while u is not None:
            if self.units[u].get("weapons_range_m"):
                return self.units[u]["weapons_range_m"]
            u = par[u]
        return float(self.voi["weapons_range_m"])

    def unknown_position(self) -> None:
        thr = float(self.voi["unknown_position_s"])
        rs = self.sim.report_s
        for leaf in self.leaves:
            ents = self.units[leaf]["entities"]
            silent = []
            for t in self.ticks:
                last = 0.0
                for e in ents:
                    ph = round(self.sim.report_phase[e], 2)
                    k = math.floor((t - ph) / rs)
                    while k >= 0 and not self.sim.reports_at(e, ph + k * rs):
                        k -= 1
                    if k >= 0:
                        last = max(last, ph + k * rs)
                if t - last > thr:
                    silent.append(t)
            for a, b in _runs(silent):
                par = self.parent_at(a)
                for o in self.owners_of(leaf, a):
                    self.must(o, "unknown-position", [], [leaf, par[leaf]], a - 1, a + 30, f"{leaf} silent")
                    self.may(o, ["unknown-position"], [leaf, par[leaf]], a - 1, b + 10)

    def schedule(self) -> None:
        thr_default = float(self.voi["schedule_s"])
        for mid, m in self.missions.items():
            for phase, actual in (("start", self.started.get(mid)), ("end", self.ended.get(mid))):
                tc = m.get(phase)
                if not tc or tc["type"] in ("ASAP", "ON-ORDER"):
                    continue
                thr = float(m["params"].get("voi", {}).get("schedule_s", thr_default))
                when, kind = tc["t"], tc["type"].split("-")[1]
                act = actual if actual is not None else math.inf
                if kind in ("NLT", "AT") and act > when + thr:
                    t = when + thr
                    for o in self.owners_of(m["unit"], t):
                        self.must(o, "schedule", [], [m["unit"]], t - 1, t + 5, f"{mid} {phase} late")
                        self.may(o, ["schedule"], [m["unit"]], t - 1, min(act, 1e9) + 1)
                if kind in ("NET", "AT") and act < when - thr:
                    for o in self.owners_of(m["unit"], act):
                        self.must(o, "schedule", [], [m["unit"]], act - 1, act + 5, f"{mid} {phase} early")

    def coordination(self) -> None:
        for mid, m in self.missions.items():
            if m["type"] not in ("link-up", "relief-in-place", "passage-of-lines"):
                continue
            p = m["params"]
            dl = float(p["at"]) + float(p.get("fuzz_s", self.voi["schedule_s"]))
            radius = float(self.voi["coordination_radius_m"])
            ok = False
            for k, t in enumerate(self.ticks):
                if t > dl:
                    break
                if all(self.judged(self.geom[p["point"]], u, k, "any") <= radius for u in (m["unit"], p["partner"])):
                    ok = True
                    break
            if not ok:
                for o in self.owners_of(m["unit"], dl):
                    self.must(o, "coordination", [], [m["unit"], p["partner"]], dl - 1, dl + 5, f"{mid} failed")

    def contingency(self) -> None:
        self.triggered_areas: dict[str, set[str]] = defaultdict(set)
        for mid, m in self.missions.items():
            if not issubclass(REGISTRY[m["type"]], ContingentMission):
                continue
            owner, tr = m["params"]["owner"], m["params"]["trigger"]
            if owner not in self.owners:
                continue
            for k, t in enumerate(self.ticks):
                if tr["kind"] == "hostile-in-area":
                    s = sum(st for x, y, st in self.hostiles_at(t).values() if self.area[tr["area"]].contains(Point(x, y)))
                    hit, slack = s >= tr.get("min_strength", 1), 15
                else:
                    c = self.member_points(tr["unit"], k).mean(axis=0)
                    hit, slack = self.area[tr["area"]].distance(Point(c)) <= tr.get("within_m", 0.0), SLACK
                if hit:
                    self.must(owner, "contingency", [], [m["unit"]], t - slack, t + 40, f"{mid} triggered")
                    self.triggered_areas[owner].add(tr["area"])
                    break

    def _ready_interval(self, mid: str) -> tuple[float, float]:
        m = self.missions[mid]
        ready = max([self.ended.get(a, math.inf) for a in m.get("after", [])], default=0.0)
        return ready, self.ended.get(mid, math.inf)

    def areas(self) -> None:
        """monitored / ave-of-approach / hostile-expected from true hostile positions."""
        for o in self.owners:
            watch: list[tuple[str, str, str | None]] = []  # (area, type, mission)
            for fid, p in self.props.items():
                if p.get("owner") == o and p["kind"] in ("decision-point", "nai"):
                    watch.append((fid, "monitored", None))
                elif p.get("owner") == o and p["kind"] == "avenue-of-approach":
                    watch.append((fid, "ave-of-approach", None))
            for mid, m in self.missions.items():
                cls = REGISTRY[m["type"]]
                for key in ("engagement_area", "area"):
                    a = m["params"].get(key)
                    if a and key in cls.GEOMETRY_PARAMS:
                        watch.append((a, "monitored", mid))
            for area, typ, mid in watch:
                present = []
                who: set[str] = set()
                for t in self.ticks:
                    if mid is not None:
                        r0, r1 = self._ready_interval(mid)
                        if not (r0 <= t < r1 and self.missions[mid]["unit"] in self.subtree(o, t)):
                            continue
                    inside = [h for h, (x, y, s) in self.hostiles_at(t).items() if self.area[area].contains(Point(x, y))]
                    if inside:
                        present.append(t)
                        who.update(inside)
                for i, (a, b) in enumerate(_runs(present)):
                    self.may(o, [typ], sorted(who) + [area], a - 15, b + 30)
                    if not (i == 0 and mid is None and area in getattr(self, "triggered_areas", {}).get(o, ())):
                        self.must(o, typ, [], sorted(who) + [area], a - 15, a + 45, f"hostiles at {area}")
            for mid, m in self.missions.items():
                by = m["params"].get("expect_hostile_by")
                if by is None:
                    continue
                r0, _ = self._ready_interval(mid)
                seen = any(self.area[m["params"]["engagement_area"]].contains(Point(x, y))
                           for t in self.ticks if r0 <= t <= by for x, y, s in self.hostiles_at(t).values())
                if not seen and m["unit"] in self.subtree(o, by):
                    self.must(o, "hostile-expected", [], [m["unit"]], by - 1, by + 5, f"{mid}: nobody came")

    def proximity(self) -> None:
        radius = float(self.voi["threat_radius_m"])
        expiry = float(self.cfg["voa"]["expiry_s"])
        gap = float(self.cfg["voa"]["suppress_hostile_s"])
        rd = float(self.cfg["voa"]["repeat"]["distance"])
        rs = float(self.cfg["voa"]["repeat"]["strength"])
        for o in self.owners:
            plts = sorted(u for u, d in self.units.items() if d["echelon"] == "platoon")
            for u in plts:
                state = {"prev": set(), "contact_t": -1e9, "dist_t": -1e9, "dist": math.inf, "str_t": -1e9, "str": 0}
                present = []
                for k, t in enumerate(self.ticks):
                    st = self.subtree(o, t)
                    if u not in st:
                        continue
                    c = self.member_points(u, k).mean(axis=0)
                    near = {h: (float(np.hypot(x - c[0], y - c[1])), s) for h, (x, y, s) in self.hostiles_at(t).items()}
                    near = {h: v for h, v in near.items() if v[0] <= radius}
                    if not near:
                        state["prev"] = set()
                        continue
                    present.append(t)
                    nearest = min(v[0] for v in near.values())
                    strength = sum(v[1] for v in near.values())
                    if t - state["contact_t"] >= expiry:   # first contact, or the last one forgotten
                        self.must(o, "contact", PROX, [u, *near], t - 15, t + 50, f"{sorted(near)} near {u}")
                        state.update(contact_t=t, dist_t=t, dist=nearest, str_t=t, str=strength)
                    elif nearest * rd * 1.03 <= state["dist"] and t - state["dist_t"] >= gap + TICK:
                        self.must(o, "distance", PROX, [u], t - 45, t + 60, f"threat closer to {u}")
                        state.update(dist_t=t, dist=nearest)
                    if strength >= rs * state["str"] and state["str"] > 0 and t - state["str_t"] >= gap + TICK:
                        self.must(o, "strength", PROX, [u], t - 15, t + 40, f"threat near {u} stronger")
                        state.update(str_t=t, str=strength)
                    state["prev"] = set(near)
                for a, b in _runs(present):
                    self.may(o, PROX, [u], a - 15, b + 30)

    def calls_for_fire(self) -> None:
        for c in self.sim.cffs:
            t = c["t"]
            k = int(round(t / TICK))
            near_leaves = set()
            for leaf in self.leaves:
                pts = self.member_points(leaf, k)
                if (np.hypot(pts[:, 0] - c["x"], pts[:, 1] - c["y"]) <= c["radius_m"]).any():
                    near_leaves.add(leaf)
            if c["kind"] == "cff":
                others = near_leaves - self.subtree(c["requester"], t)
                if others and c["requester"] in self.owners:
                    self.must(c["requester"], "call-for-fire", [], [self.platoon_of(x, t) for x in others], t - 1, t + 2,
                              f"{c['cff']} near friendlies")
            else:
                for o in self.owners:
                    mine = near_leaves & self.subtree(o, t)
                    if mine:
                        self.must(o, "call-for-fire", [], [self.platoon_of(x, t) for x in mine], t - 1, t + 2,
                                  f"{c['cff']} confirmed near {o}'s units")


def sim_duration(sim) -> float:
    from .generator import DURATION
    return DURATION


def ground_truth(sim, feats: list[dict], plan: dict, owners: list[str]) -> dict:
    tr = Truth(sim, feats, plan, owners)
    tr.contingency()
    for step in (tr.out_of_position, tr.fratricide, tr.unknown_position, tr.schedule, tr.coordination,
                 tr.areas, tr.proximity, tr.calls_for_fire):
        step()
    key = lambda d: (d["owner"], d["t0"], d.get("type", ""), d["subjects"])
    return {"owners": owners, "tick_s": TICK, "incidents": sorted(tr.incidents, key=key),
            "situations": sorted(tr.situations, key=key)}
