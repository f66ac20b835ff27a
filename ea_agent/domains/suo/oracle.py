"""Ground truth from the simulated true state, written apart from the detectors.

It samples the true world every TICK seconds (no report staleness, no GPS noise)
and says, per EA owner:
 - incidents: what happened that the owner must be told of, of which type(s), within
   which window (what happened, not what our VOA would say);
 - situations: when an alert of a type is justified at all (a real situation
   exists), so that any alert outside every situation counts as unwanted.

It is a specification, not a second copy of the EA: it imports nothing from
`ea_agent` (no mission classes, no config, no VOA policy). Thresholds are the
scenario's statement of what is worth knowing (SPEC, the figures the paper's
scenario uses); how each mission type is judged comes from the paper's definitions
(section 6.5, written out below); a threat's later incidents are labelled by fixed
severity steps of its own (CLOSER, STRONGER, EPISODE_S), not by the EA's repeat ratios.
"""
from __future__ import annotations

import math
from collections import defaultdict

import numpy as np
from shapely.geometry import LineString, Point, Polygon, shape
from shapely.ops import nearest_points

# What the commander said is worth knowing (the paper's scenario, 6.8); plans may
# override per mission (params.voi). Fixed here: the EAs read theirs from their config.
SPEC = {"out_of_position_m": 150.0, "schedule_s": 30.0, "unknown_position_s": 120.0,
        "weapons_range_m": 1000.0, "threat_radius_m": 2000.0, "coordination_radius_m": 300.0,
        "ahead_m": 1500.0, "ahead_width_m": 300.0,   # a unit is at a checkpoint this near its point:
        "checkpoint_m": 50.0, "standoff_m": 1000.0, "lift_m": 500.0}   # a moving unit's commander wants to know of hostiles
                                                     # this far ahead on its route, this near it
EPISODE_S = 720.0   # the paper's alert expiry (12 min): a threat back near a platoon, or a group back
                    # in a watched area, after this long away is news again
CLOSER = 2.0        # the nearest threat at half the distance of the last incident: a new one
STRONGER = 2.0      # the threats near a platoon twice as strong as at the last incident
MATERIAL = 1.25     # an alert counts for such an incident once the change reached this step
TOLERANCE_M = 200.0  # how well sensors place a hostile group (5 sigma of the scenario's 25-40 m)
CONFIRM_S = (0.0, 5.0, 10.0)   # a track is confirmed after 3 sensor scans (5 s apart) of it
REACH_M = 85.0      # a group's members stand up to this far from its centre (the sensors see members)
RESOLVE_M = 150.0   # groups nearer than this are one to any sensor of the scenario (sigma 25-40 m)
NO_VALUE_S = 90.0   # the paper (5): a hostile alert of the same type about the same unit has no
                    # value this long after the last; a change inside it is told when it ends

# How the paper judges a unit on each mission type (6.5): where its members must be
# (the rule: its centroid, any member, or all of them) and by which geometry.
ANY_RULE = {"area-reconnaissance", "guard", "link-up", "observe", "overwatch", "passage-of-lines",
            "relief-in-place", "route-reconnaissance", "screen", "zone-reconnaissance"}
FINAL_RULE = {"attack": "all", "clear": "all", "secure": "all", "seize": "all", "breach": "any",
              "destroy": "centroid", "fix": "centroid", "hasty-attack": "centroid", "isolate": "centroid"}
OBJECTIVE = {"attack", "breach", "clear", "destroy", "fix", "hasty-attack", "isolate", "secure", "seize"}
ROUTE = {"bypass", "delay", "follow-and-assume", "follow-and-support", "move", "movement-to-contact",
         "route-reconnaissance", "tactical-road-march", "withdraw"}
AREA = {"area-reconnaissance", "guard", "observe", "screen", "zone-reconnaissance"}   # position + area
COORDINATION = {"link-up", "passage-of-lines", "relief-in-place"}
CONTINGENT = {"branch", "sequel"}
REORGANIZATION = {"reorganize"}
AUTO_START = REORGANIZATION   # the EA executes it itself at its start time
LIFE = {"contact", "fratricide", "call-for-fire"}   # life-threatening: the paper's flash alerts
# What doctrine (FM 3-90) says each task forbids the enemy: to enter the held area (block, retain,
# guard; a defence's rear line), to leave it (fix, isolate, destroy: the objective; contain: the
# engagement area), to be left on the objective at the end (seize, clear, secure, destroy).
PENETRATION = {"block": "position", "retain": "position", "guard": "area", "defend": "rear_line"}
ESCAPE = {"fix": "objective", "isolate": "objective", "destroy": "objective", "contain": "engagement_area"}
END_STATE = {"seize", "clear", "secure", "destroy"}
FOLLOW = {"follow-and-support", "follow-and-assume"}
STANDOFF = {"screen", "bypass", "withdraw", "delay"}   # not to become decisively engaged   # stay within a distance band of the supported unit
FOLLOW_MAX_M = 3000.0   # the band's far edge unless the plan says (band_m)
FRIENDLY_MPS = 6.0      # the fastest a friendly unit moves (how far a stale report can be off)
LINE_MARGIN_M = 50.0    # a unit is across a line this far beyond it (the plan's statement)
FRIENDLY_ERR_M = 100.0  # how far the EA's picture of a moving friendly unit may be off (reports' age, noise)
CORRIDOR_BACK_M = 300.0  # a corridor reaches this far behind where the unit started (its start is an estimate)
APPROACH_M = 1000.0     # a group this near an area no hostile may enter may be projected to enter it


def geometry_params(typ: str) -> tuple[str, ...]:
    if typ in OBJECTIVE:
        return ("objective", "axis")
    if typ in ROUTE:
        return ("route", "destination")
    if typ in AREA:
        return ("position", "area")
    if typ in COORDINATION:
        return ("point",)
    if typ in CONTINGENT | REORGANIZATION:
        return ()
    return ("position", "engagement_area")


TICK = 5.0
TRACK_S = 10.0      # and one hostile track period: the slack of friendly-position incidents
PROX = ["contact", "distance", "strength", "proximity"]


def _bands(geom):
    """An area grown and shrunk by TOLERANCE_M: where a group may be told to be in it, and
    where it must be (the area itself when it is too small to shrink)."""
    deep = geom.buffer(-TOLERANCE_M)
    return geom.buffer(TOLERANCE_M), (geom if deep.is_empty else deep)


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
        self._hostiles: dict[float, dict] = {}
        # friendly reports may be up to one report interval old (plus a track period)
        self.slack = float(sim.report_s) + TRACK_S
        self.voi = SPEC
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
        # the plan in force over time: the initial one until an order switches plans (its
        # missions no longer count from then on), the ordered one from then on
        order = getattr(sim, "order", None)
        cut = float(order["t"]) if order else math.inf
        self.valid = {mid: (0.0, cut) for mid in self.missions}
        if order:
            for m in plan["plans"][order["plan"]]:
                self.missions[m["id"]] = m
                self.valid[m["id"]] = (cut, math.inf)
        self.reorgs = sorted((m["start"]["t"], m["params"]["subject"], m["params"]["new_parent"])
                             for m in self.missions.values() if m["type"] in REORGANIZATION)
        self.ticks = np.arange(0.0, sim.duration + TICK / 2, TICK)
        self.leaves = sorted(u for u, d in self.units.items() if d["entities"])
        self.leaf_xy = {leaf: np.array([sim.leaf_center(leaf, t) for t in self.ticks]) for leaf in self.leaves}
        self.offsets = {leaf: np.array([sim.entity_off[e] for e in self.units[leaf]["entities"]]) for leaf in self.leaves}
        self._sub_cache: dict = {}
        self.started = {}
        self.ended = {}
        for m in self.missions.values():   # executed by the EA itself at its start time
            if m["type"] in AUTO_START and m.get("start", {}).get("t") is not None:
                self.started[m["id"]] = self.ended[m["id"]] = m["start"]["t"]
        for t, mid, _unit, ph in sim.confirmations:
            (self.started if ph == "start" else self.ended).setdefault(mid, t)
        self.incidents: list[dict] = []
        self.situations: list[dict] = []
        self.task_started: dict[str, float] = {}   # triggered contingency -> when its task may have started
        self.task_due: dict[str, float] = {}       # ... and by when it must have
        self.corridor_start: dict[str, np.ndarray] = {}   # route-less mission -> where its corridor starts

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
        """The hostile groups there at `t` that the team could know of: all of them where
        tracks are reported from true positions, those within some sensor's range where
        hostiles are sensed (nobody can be told of a group no sensor covers), once some
        sensor has covered it for the scans a track needs to be confirmed."""
        out = self._hostiles.get(t)
        if out is not None:
            return out
        out = {}
        sensed = bool(getattr(self.sim, "sensors", ()))
        for h in self.sim.hostiles.values():
            p = h.pos(t)
            if p is not None and (not sensed or all(self._covered(h, t - dt) for dt in CONFIRM_S)):
                out[h.id] = (p[0], p[1], h.strength)
        if len(self._hostiles) > 4096:
            self._hostiles.clear()
        self._hostiles[t] = out
        return out

    def _covered(self, h, t: float) -> bool:
        """Whether hostile group `h` is within some sensor's range at `t`."""
        p = h.pos(t)
        return p is not None and any(math.hypot(p[0] - x, p[1] - y) <= r + REACH_M
                                     for x, y, r in ((*self.sim.sensor_xy(sid, t), r) for sid, r in self.sim.sensors))

    def owners_of(self, unit: str, t: float) -> list[str]:
        return [o for o in self.owners if unit in self.subtree(o, t)]

    # -- recording ----------------------------------------------------------------------
    def must(self, owner, typ, accept, subjects, t0, t1, label="", at=None, about=None):
        """An incident: `at` when it happened (detection delay is counted from it), t0..t1
        the window an alert about it is accepted in; `life`: it threatens lives (the paper's
        flash: first contact with the enemy, fratricide, fire called near friendlies);
        `about`: the subjects an alert must name to be about it (default: any of them)."""
        self.incidents.append({"owner": owner, "type": typ, "accept": sorted(set(accept) | {typ}),
                               "subjects": sorted(set(subjects)), "t0": round(t0, 1), "t1": round(t1, 1),
                               "at": round(t0 if at is None else at, 1), "life": typ in LIFE, "label": label,
                               **({"about": sorted(set(about))} if about else {})})
        self.may(owner, accept + [typ], subjects, t0, t1, about=about)

    def may(self, owner, accept, subjects, t0, t1, about=None):
        """A situation: alerts about it in t0..t1 are wanted but not required (`about`: as
        for an incident)."""
        self.situations.append({"owner": owner, "accept": sorted(set(accept)), "subjects": sorted(set(subjects)),
                                "t0": round(t0, 1), "t1": round(t1, 1), **({"about": sorted(about)} if about else {})})

    # -- per alert type ----------------------------------------------------------------------
    def thr(self, m: dict, key: str) -> float:
        return float(m["params"].get("voi", {}).get(key, self.voi[key]))

    def _corridor(self, start, dest: str):
        """Where a unit with no route may be on its way: the line from `start` (reaching
        CORRIDOR_BACK_M behind it) to the nearest point of its destination, and the destination."""
        line = self._corridor_line(start, dest)
        return line.union(self.area[dest]) if line is not None else self.area[dest]

    def _corridor_line(self, start, dest: str):
        c = Point(start)
        near = nearest_points(c, self.area[dest])[1]
        n = c.distance(near)
        if n <= 1.0:
            return None
        k = CORRIDOR_BACK_M / n
        return LineString([(c.x - (near.x - c.x) * k, c.y - (near.y - c.y) * k), (near.x, near.y)])

    def _shift(self, unit: str, tr: float) -> np.ndarray:
        """How far a reorganization at `tr` moves the unit's centroid with no member moving."""
        k = math.ceil(tr / TICK - 1e-9)
        def mean(sub):
            return np.concatenate([self.leaf_xy[leaf][k] + self.offsets[leaf] for leaf in self.leaves
                                   if leaf in sub]).mean(axis=0)
        return mean(self.subtree(unit, tr)) - mean(self.subtree(unit, tr - 1e-6))

    def out_of_position(self) -> None:
        for mid, m in self.missions.items():
            typ = m["type"]
            p = m["params"]
            if typ in CONTINGENT and mid in self.task_started:   # a triggered task: its own type from then
                typ, p = m["params"]["task"], m["params"].get("task_params", {})
                self.started.setdefault(mid, self.task_started[mid])
            rule = "any" if typ in ANY_RULE else "centroid"
            cont = p.get("route") or p.get("axis") or p.get("position")
            if typ in CONTINGENT | REORGANIZATION or mid not in self.started:
                continue
            thr = self.thr(m, "out_of_position_m")
            v0, v1 = self.valid[mid]
            s, e = max(self.started[mid], v0), min(self.ended.get(mid, math.inf), v1)
            dest = p.get("destination") or p.get("objective")
            corridor = not cont and dest in self.area and typ in ROUTE | OBJECTIVE
            if cont or corridor:
                # a corridor starts again wherever a reorganization moves the unit's centroid
                # a corridor starts where the unit is at its start; it moves with the centroid
                # when a reorganization changes the unit's members
                shifts = [tr for tr, _, _ in self.reorgs if s < tr < e and
                          self.subtree(m["unit"], tr) != self.subtree(m["unit"], tr - 1e-6)]
                geom = (self.geom[cont] if (p.get("route") or p.get("axis")) else self.area[cont]) if cont else None
                if corridor:
                    start = self.member_points(m["unit"], math.ceil(s / TICK - 1e-9)).mean(axis=0)
                    geom = self._corridor(start, dest)
                    self.corridor_start[mid] = start
                hits: list[float] = []
                dist: dict[float, float] = {}
                for k, t in enumerate(self.ticks):
                    if s <= t < e:
                        while corridor and shifts and shifts[0] <= t:
                            start = start + self._shift(m["unit"], shifts.pop(0))
                            geom = self._corridor(start, dest)
                        d = self.judged(geom, m["unit"], k, rule)
                        if d > thr / MATERIAL:   # within a MATERIAL step of the threshold either answer is fair
                            hits.append(t)
                            dist[t] = d
                for a, b in _runs(hits):
                    over = [t for t in hits if a <= t <= b and dist[t] > thr]   # past the threshold itself
                    peak = max(dist[t] for t in hits if a <= t <= b)
                    for o in self.owners_of(m["unit"], a):
                        if peak > 1.5 * thr and over and over[-1] - over[0] >= 30:
                            at = over[0]   # a triggered task: not before it must have fired
                            self.must(o, "out-of-position", [], [m["unit"]], a - self.slack,
                                      max(at, self.task_due.get(mid, at)) + 60, f"{mid} off {cont or 'its corridor'}",
                                      at=at)
                        self.may(o, ["out-of-position"], [m["unit"]], a - self.slack, b + self.slack)
            dest = p.get("destination") or p.get("objective")
            geo = geometry_params(typ)
            if dest and math.isfinite(e) and dest in self.area and "destination" in geo or (
                    dest and math.isfinite(e) and "objective" in geo):
                k = int(round(e / TICK))
                d = self.judged(self.area[dest], m["unit"], k, FINAL_RULE.get(typ, rule))
                # within a MATERIAL step of the threshold either answer is fair (reports
                # are up to a report interval old when the end is confirmed)
                for o in self.owners_of(m["unit"], e) if d > thr / MATERIAL else ():
                    if d > thr * MATERIAL:
                        self.must(o, "out-of-position", [], [m["unit"]], e - 1, e + 5, f"{mid} not at {dest}", at=e)
                    else:
                        self.may(o, ["out-of-position"], [m["unit"]], e - 1, e + 5)

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
                    self.must(o, "fratricide", [], [pla, plb], a - self.slack, a + 60, f"{pla} and {plb}", at=a)
                self.may(o, ["fratricide"], [pla, plb], a - self.slack, b + self.slack)

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
            silent, since = [], {}
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
                    since.setdefault(last, t)
            for a, b in _runs(silent):
                par = self.parent_at(a)
                # it happened when the silence passed the threshold, between two ticks
                crossed = max((lst + thr for lst, t in since.items() if t == a), default=a)
                for o in self.owners_of(leaf, a):
                    self.must(o, "unknown-position", [], [leaf, par[leaf]], crossed - 1, crossed + 30,
                              f"{leaf} silent", at=crossed)
                    self.may(o, ["unknown-position"], [leaf, par[leaf]], crossed - 1, b + 10)

    def schedule(self) -> None:
        thr_default = float(self.voi["schedule_s"])
        for mid, m in self.missions.items():
            for phase, actual in (("start", self.started.get(mid)), ("end", self.ended.get(mid))):
                tc = m.get(phase)
                if tc and tc["type"] == "ON-ORDER":
                    self._on_order(mid, m, phase, actual)
                if not tc or tc["type"] in ("ASAP", "ON-ORDER"):
                    continue
                thr = float(m["params"].get("voi", {}).get("schedule_s", thr_default))
                when, kind = tc["t"], tc["type"].split("-")[1]
                act = actual if actual is not None else math.inf
                v0, v1 = self.valid[mid]
                if not v0 <= when + thr < v1:   # the plan was changed before it was due
                    continue
                if kind in ("NLT", "AT") and act > when + thr:
                    t = when + thr
                    for o in self.owners_of(m["unit"], t):
                        self.must(o, "schedule", [], [m["unit"]], t - 1, t + 5, f"{mid} {phase} late", at=t)
                        self.may(o, ["schedule"], [m["unit"]], t - 1, min(act, 1e9) + 1)
                if kind in ("NET", "AT") and act < when - thr:
                    for o in self.owners_of(m["unit"], act):
                        self.must(o, "schedule", [], [m["unit"]], act - 1, act + 5, f"{mid} {phase} early", at=act)

    def _on_order(self, mid: str, m: dict, phase: str, actual: float | None) -> None:
        """An ON-ORDER phase comes within the schedule threshold of its superior's order;
        one that comes with no order at all, or well before it, is an incident when it comes."""
        thr = float(m["params"].get("voi", {}).get("schedule_s", self.voi["schedule_s"]))
        order = next((o["t"] for o in getattr(self.sim, "mission_orders", ())
                      if o["mission"] == mid and o["phase"] == phase), None)
        v0, v1 = self.valid[mid]
        if order is not None and (actual is None or actual > order + thr) and v0 <= order + thr < v1:
            t = order + thr
            for o in self.owners_of(m["unit"], t):
                self.must(o, "schedule", [], [m["unit"]], t - 1, t + 5, f"{mid} {phase} late on order", at=t)
                self.may(o, ["schedule"], [m["unit"]], t - 1, min(actual or 1e9, 1e9) + 1)
        elif actual is not None and (order is None or actual < order - thr) and v0 <= actual < v1:
            for o in self.owners_of(m["unit"], actual):
                self.must(o, "schedule", [], [m["unit"]], actual - 1, actual + 5,
                          f"{mid} {phase} without an order", at=actual)
                if order is not None:   # told again when the order comes: the same story
                    self.may(o, ["schedule"], [m["unit"]], actual - 1, order + 5)

    def check_families(self) -> None:
        """What each task forbids the enemy or asks of its unit beyond its place (FM 3-90):
        escape, end state, the engagement area in weapons range, the distance band."""
        for mid, m in self.missions.items():
            typ, p = m["type"], m["params"]
            if typ == "support-by-fire" and p.get("supported"):
                self._fire_support(mid, m, p)
            if mid not in self.started:
                continue
            v0, v1 = self.valid[mid]
            s, e = max(self.started[mid], v0), min(self.ended.get(mid, math.inf), v1)
            if s >= e:
                continue
            if typ in ESCAPE and p.get(ESCAPE[typ]):
                self._escape(mid, m, p[ESCAPE[typ]], s, e)
            if typ in END_STATE and mid in self.ended and self.ended[mid] < v1:
                self._end_state(mid, m, p["objective"], self.ended[mid])
            if p.get("engagement_area") and geometry_params(typ) == ("position", "engagement_area"):
                self._coverage(mid, m, p["position"], p["engagement_area"], s)
            if geometry_params(typ) == ("position", "engagement_area") or typ == "observe":
                self._held(mid, m, p["position"], s, e)
            if typ in FOLLOW:
                self._band(mid, m, p["supported"], p.get("band_m") or (0.0, FOLLOW_MAX_M), s, e)
            if typ == "overwatch" and p.get("supported"):   # within its fires unless the plan says
                self._band(mid, m, p["supported"], p.get("band_m") or (0.0, self.thr(m, "weapons_range_m")), s, e)
            line = self._line_of(mid, m)
            if line is not None:
                self._ahead(mid, m, line, s, e)
            if p.get("checkpoints") and typ in ROUTE:
                self._checkpoints(mid, m, p["checkpoints"], s, e)
            if typ in STANDOFF:
                self._standoff(mid, m, s, e)
            if typ == "delay" and p.get("line"):
                self._line(mid, m, p["line"], float(p["until"]), s, e, hold=True)
            if typ == "breach" and p.get("obstacle"):
                self._line(mid, m, p["obstacle"], float(p["by"]), s, e, hold=False, toward=p["objective"])

    def _held(self, mid, m, position, s, e) -> None:
        """A position its mission must hold: some friendly element (anyone's) in it while it runs;
        near its edge (reports lag) either answer is fair."""
        near_g = self.area[position].buffer(FRIENDLY_ERR_M)
        deep = self.area[position].buffer(-FRIENDLY_ERR_M)
        sure, maybe = [], []
        for k, t in enumerate(self.ticks):
            if not s <= t < e:
                continue
            pts = [Point(q) for leaf in self.leaves for q in self.leaf_xy[leaf][k] + self.offsets[leaf]]
            if not any(near_g.contains(q) for q in pts):
                sure.append(t)
            if deep.is_empty or not any(deep.contains(q) for q in pts):
                maybe.append(t)
        for a, b in _runs(sure):
            if b - a >= 30:
                for o in self.owners_of(m["unit"], a):
                    self.must(o, "friendly-expected", [], [m["unit"]], a - self.slack, a + 60,
                              f"{position} empty ({mid})", at=a)
        for a, b in _runs(maybe):
            for o in self.owners_of(m["unit"], a):
                self.may(o, ["friendly-expected"], [m["unit"]], a - self.slack, b + self.slack)

    def _fire_support(self, mid, m, p) -> None:
        """Support by fire: in position (within out_of_position_m of it) when the supported unit
        crosses its line of departure, whether its own mission has started or not; its fires
        lift once the supported unit is within SPEC lift_m of the target, while it runs."""
        v0, v1 = self.valid[mid]
        sup, thr = p["supported"], self.thr(m, "out_of_position_m")
        owners = lambda t: self.owners_of(m["unit"], t)   # noqa: E731
        if p.get("line"):
            line, c = self.geom[p["line"]], self.area[p["target"]].centroid
            own = -1.0 if self._beyond_point(line, c) else 1.0
            far = [(t, self._beyond(line, sup, k, own)) for k, t in enumerate(self.ticks) if v0 <= t < v1]
            maybe = next((t for t, d in far if d > LINE_MARGIN_M - FRIENDLY_ERR_M), None)
            sure = next((t for t, d in far if d > LINE_MARGIN_M + FRIENDLY_ERR_M), None)
            if maybe is not None:
                gap = lambda t: self.area[p["position"]].distance(   # noqa: E731
                    Point(self.member_points(m["unit"], int(round(t / TICK))).mean(axis=0)))
                last = sure if sure is not None else maybe
                for o in owners(maybe):
                    if all(gap(t) > thr * MATERIAL for t in self.ticks if maybe <= t <= last):
                        self.must(o, "fire-support", [], [m["unit"], sup], maybe - 1, last + self.slack,
                                  f"{m['unit']} not in position when {sup} departs", at=maybe)
                    elif any(gap(t) > thr / MATERIAL for t in self.ticks if maybe <= t <= last):
                        self.may(o, ["fire-support"], [m["unit"], sup], maybe - 1, last + self.slack)
        if mid not in self.started:
            return
        s, e = max(self.started[mid], v0), min(self.ended.get(mid, math.inf), v1)
        lift = self.thr(m, "lift_m")
        d = [(t, self.area[p["target"]].distance(Point(self.member_points(sup, k).mean(axis=0))))
             for k, t in enumerate(self.ticks) if s <= t < e]
        maybe = next((t for t, x in d if x <= lift + FRIENDLY_ERR_M), None)
        sure = next((t for t, x in d if x <= lift - FRIENDLY_ERR_M), None)
        if maybe is not None:
            for o in owners(maybe):
                if sure is not None:
                    self.must(o, "fire-support", [], [m["unit"], sup], maybe - 1, sure + self.slack,
                              f"{m['unit']} lifts fires for {sup}", at=sure)
                else:
                    self.may(o, ["fire-support"], [m["unit"], sup], maybe - 1, e)

    def _standoff(self, mid, m, s, e) -> None:
        """Screens, bypasses, withdrawals and delays keep SPEC standoff_m from every hostile group:
        the first group well inside it in an episode (none near for EPISODE_S before) must be told;
        while groups are near its edge, alerts may be."""
        keep = self.thr(m, "standoff_m")
        near_ts, last_near, first_near, told = [], -math.inf, None, False
        for k, t in enumerate(self.ticks):
            if not s <= t < e:
                continue
            c = self.member_points(m["unit"], k).mean(axis=0)
            ds = {h: math.hypot(x - c[0], y - c[1]) for h, (x, y, _s) in self.hostiles_at(t).items()}
            near = [h for h, d in ds.items() if d < keep + TOLERANCE_M]
            if not near:
                continue
            if t - last_near >= EPISODE_S:
                first_near, told = t, False
            last_near = t
            near_ts.append(t)
            if not told and any(ds[h] < keep - TOLERANCE_M for h in near):
                for o in self.owners_of(m["unit"], t):
                    self.must(o, "standoff", [], [m["unit"], *near], first_near - 15, t + 30,
                              f"hostiles within {m['unit']}'s standoff ({mid})", at=t, about=[m["unit"]])
                told = True
        for a, b in _runs(near_ts):
            for o in self.owners_of(m["unit"], a):
                self.may(o, ["standoff"], [m["unit"]], a - 15, b + 30, about=[m["unit"]])

    def _beyond(self, line, unit: str, k: int, own: float) -> float:
        """How far the unit's centroid is across `line` from side `own` (+1 left, -1 right; < 0: not across)."""
        c = Point(self.member_points(unit, k).mean(axis=0))
        pos = line.project(c)
        a, b = line.interpolate(max(pos - 1.0, 0.0)), line.interpolate(min(pos + 1.0, line.length))
        left = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x) >= 0
        d = line.distance(c)
        return d if (left and own < 0) or (not left and own > 0) else -d

    def _line(self, mid, m, lid, when, s, e, hold: bool, toward: str | None = None) -> None:
        """A delay holds forward of its line (the side it starts on) until `when`; a breach is
        past its obstacle (away from the side of its objective) by `when`. Across means more
        than LINE_MARGIN_M beyond; the EA's picture of a moving unit errs by up to FRIENDLY_ERR_M."""
        line = self.geom[lid]
        if hold:
            own = -1.0 if self._beyond(line, m["unit"], math.ceil(s / TICK - 1e-9), 1.0) > 0 else 1.0
        else:
            c = self.area[toward].centroid
            own = -1.0 if self._beyond_point(line, c) else 1.0
        far = {k: self._beyond(line, m["unit"], k, own) for k, t in enumerate(self.ticks) if s <= t < e}
        first = lambda d: next((self.ticks[k] for k, v in sorted(far.items()) if v > d), math.inf)   # noqa: E731
        sure, maybe = first(LINE_MARGIN_M + FRIENDLY_ERR_M), first(LINE_MARGIN_M - FRIENDLY_ERR_M)
        if not self.valid[mid][0] <= min(when, maybe) < self.valid[mid][1]:
            return
        for o in self.owners_of(m["unit"], min(when, maybe)):
            if hold:
                if sure < when - self.slack:
                    self.must(o, "line", [], [m["unit"]], maybe - 1, sure + self.slack, f"{mid} across {lid} early",
                              at=sure)
                if maybe < when:
                    self.may(o, ["line"], [m["unit"]], maybe - 1, when)
            elif e > when:   # a breach: across by its time
                if maybe > when + self.slack:
                    self.must(o, "line", [], [m["unit"]], when - 1, when + 5, f"{mid} not past {lid}", at=when)
                if sure > when - self.slack:
                    self.may(o, ["line"], [m["unit"]], when - 1, when + 5)

    @staticmethod
    def _beyond_point(line, c) -> bool:
        """Whether point `c` is on the left of `line` (walking along it)."""
        pos = line.project(c)
        a, b = line.interpolate(max(pos - 1.0, 0.0)), line.interpolate(min(pos + 1.0, line.length))
        return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x) >= 0

    def _checkpoints(self, mid, m, table, s, e) -> None:
        """A march table: the unit reaches each point (its centroid in the point's area, once
        the mission runs) within schedule_s of its time. Its reports lag the truth by up to
        `slack`: nearer the edge than that, either answer is fair."""
        fuzz = self.thr(m, "schedule_s")
        for cp in table:
            area, when = self.area[cp["point"]], float(cp["t"])
            g = self.geom[cp["point"]]
            at = (lambda c: g.distance(c) <= float(self.voi["checkpoint_m"])) if g.geom_type == "Point" else area.contains
            arrive = next((t for k, t in enumerate(self.ticks) if s <= t < e and
                           at(Point(self.member_points(m["unit"], k).mean(axis=0)))), math.inf)
            if not self.valid[mid][0] <= when + fuzz < self.valid[mid][1] or (math.isinf(arrive) and e <= when + fuzz):
                continue   # the plan changed, or the mission ended (no arrival is then a place question)
            for o in self.owners_of(m["unit"], when):
                if arrive > when + fuzz + self.slack:
                    self.must(o, "checkpoint", [], [m["unit"]], when + fuzz - 1, when + fuzz + 5,
                              f"{mid} late at {cp['point']}", at=when + fuzz)
                elif arrive > when + fuzz - self.slack:
                    self.may(o, ["checkpoint"], [m["unit"]], when + fuzz - 1, when + fuzz + 5)
                if arrive < when - fuzz - self.slack:   # seen up to `slack` before or after it happened
                    self.must(o, "checkpoint", [], [m["unit"]], arrive - self.slack, arrive + self.slack + 5,
                              f"{mid} early at {cp['point']}", at=arrive)
                elif arrive < when - fuzz + self.slack:
                    self.may(o, ["checkpoint"], [m["unit"]], arrive - self.slack, arrive + self.slack + 5)

    def _line_of(self, mid, m):
        """The line a moving mission follows: its route or axis, or its corridor's line."""
        typ, p = m["type"], m["params"]
        if typ not in ROUTE | OBJECTIVE:
            return None
        if p.get("route") or p.get("axis"):   # as travelled: towards its destination or objective
            line = self.geom[p.get("route") or p.get("axis")]
            goal = self.area[p.get("destination") or p.get("objective")]
            return LineString(line.coords[::-1]) if goal.distance(Point(line.coords[0])) < \
                goal.distance(Point(line.coords[-1])) else line
        if mid in self.corridor_start:
            return self._corridor_line(self.corridor_start[mid], p.get("destination") or p.get("objective"))
        return None

    def _ahead(self, mid, m, line, s, e) -> None:
        """Hostiles on the stretch of line ahead of the unit (SPEC ahead_m, ahead_width_m): the
        commander must be asked once per episode about a group well inside it; one near its
        edges (where sensors and the unit's own reports err) may be told."""
        far, wide = self.thr(m, "ahead_m"), self.thr(m, "ahead_width_m")
        near_ts, who, first_near, last_deep = [], set(), None, -math.inf
        for k, t in enumerate(self.ticks):
            if not s <= t < e:
                continue
            hs = self.hostiles_at(t)
            if not hs:
                first_near = None
                continue
            d0 = line.project(Point(self.member_points(m["unit"], k).mean(axis=0)))
            place = {h: (line.project(Point(x, y)), line.distance(Point(x, y))) for h, (x, y, _s) in hs.items()}
            near = [h for h, (a, d) in place.items()
                    if d0 - TOLERANCE_M <= a <= d0 + far + TOLERANCE_M and a < line.length and d <= wide + TOLERANCE_M]
            if not near:
                first_near = None
                continue
            near_ts.append(t)
            who |= set(near)
            first_near = t if first_near is None else first_near
            deep = [h for h in near if d0 + TOLERANCE_M <= place[h][0] <= d0 + far - TOLERANCE_M
                    and place[h][1] <= wide - TOLERANCE_M]
            if deep:
                if t - last_deep >= EPISODE_S:
                    for o in self.owners_of(m["unit"], t):
                        self.must(o, "threat-ahead", [], [m["unit"], *near], first_near - 15, t + 30,
                                  f"hostiles ahead of {m['unit']} ({mid})", at=t, about=[m["unit"]])
                last_deep = t
        for a, b in _runs(near_ts):
            for o in self.owners_of(m["unit"], a):
                self.may(o, ["threat-ahead"], [m["unit"], *sorted(who)], a - 15, b + 30, about=[m["unit"]])

    def _escape(self, mid, m, area, s, e) -> None:
        """A group well inside the area while the mission runs that goes well beyond its edge."""
        geom = self.area[area]
        near_g, deep_g = _bands(geom)
        held: dict[str, float] = {}   # group -> when it was last well inside
        out_at: dict[str, float] = {}
        for t in self.ticks:
            if not s <= t < e:
                continue
            for h, (x, y, _st) in self.hostiles_at(t).items():
                pt = Point(x, y)
                if deep_g.contains(pt):
                    held[h] = t
                    out_at.pop(h, None)
                elif h in held and not geom.contains(pt):
                    out_at.setdefault(h, t)   # across the edge: it may be told from now
                    if not near_g.contains(pt):
                        for o in self.owners_of(m["unit"], t):
                            self.must(o, "escape", [], [h, area], out_at[h] - 15, t + 45, f"{h} escapes {area}",
                                      at=t, about=[area])
                            self.may(o, ["escape"], [h, area], held[h], t + 45, about=[area])
                        del held[h]
            for h in [h for h in held if h not in self.hostiles_at(t)]:   # gone: lost, not escaped
                del held[h]
        for h, t in out_at.items():   # crossed the edge, never well beyond it: may be told
            if h in held:
                for o in self.owners_of(m["unit"], t):
                    self.may(o, ["escape"], [h, area], t - 15, e + 45, about=[area])

    def _end_state(self, mid, m, area, t) -> None:
        geom = self.area[area]
        near_g, deep_g = _bands(geom)
        hs = self.hostiles_at(round(t / TICK) * TICK)
        deep = [h for h, (x, y, _s) in hs.items() if deep_g.contains(Point(x, y))]
        near = [h for h, (x, y, _s) in hs.items() if near_g.contains(Point(x, y))]
        for o in self.owners_of(m["unit"], t):
            if deep:
                self.must(o, "end-state", [], [m["unit"], *deep], t - 1, t + 5, f"{mid} ends with {deep} on {area}",
                          at=t, about=[m["unit"]])
            elif near:
                self.may(o, ["end-state"], [m["unit"], *near], t - 1, t + 5, about=[m["unit"]])

    def _coverage(self, mid, m, position, ea, s) -> None:
        gap = self.area[position].distance(self.area[ea])
        if gap > self._range(m["unit"], self.parent_at(s)):
            for o in self.owners_of(m["unit"], s):
                self.must(o, "friendly-expected", [], [m["unit"]], s - 1, s + 5, f"{ea} out of range of {position}",
                          at=s)

    def _band(self, mid, m, other, band, s, e) -> None:
        lo, hi = float(band[0]), float(band[1])
        thr = self.thr(m, "out_of_position_m")
        hits, peak = [], 0.0
        for k, t in enumerate(self.ticks):
            if s <= t < e:
                a, b = self.member_points(m["unit"], k).mean(axis=0), self.member_points(other, k).mean(axis=0)
                d = float(np.hypot(*(a - b)))
                off = d - hi if d > hi else lo - d
                if off > thr / MATERIAL:
                    hits.append(t)
                    peak = max(peak, off)
        for a, b in _runs(hits):
            for o in self.owners_of(m["unit"], a):
                if peak > 1.5 * thr and b - a >= 30:
                    self.must(o, "band", [], [m["unit"], other], a - self.slack, a + 60, f"{mid} out of band", at=a)
                self.may(o, ["band"], [m["unit"], other], a - self.slack, b + self.slack)

    def presence(self) -> None:
        """A relief in place leaves no gap; a passage of lines keeps its elements at the point
        inside its lane. From the plan's start (coordinations have no start of their own)."""
        radius = float(self.voi["coordination_radius_m"])
        for mid, m in self.missions.items():
            p = m["params"]
            if m["type"] not in ("relief-in-place", "passage-of-lines") or (
                    m["type"] == "passage-of-lines" and not p.get("lane")):
                continue
            v0, v1 = self.valid[mid]
            pt = self.geom[p["point"]]
            sure, maybe, was, came = [], [], False, False
            for k, t in enumerate(self.ticks):
                if not v0 <= t < v1:
                    continue
                mine = self.member_points(m["unit"], k)
                dm = np.array([pt.distance(Point(q)) for q in mine])
                if m["type"] == "passage-of-lines":
                    lane = self.area[p["lane"]]
                    out = [lane.distance(Point(q)) for q, d in zip(mine, dm) if d <= radius + FRIENDLY_ERR_M]
                    if any(o > FRIENDLY_ERR_M for o, d in zip(out, dm[dm <= radius + FRIENDLY_ERR_M])
                           if d <= radius - FRIENDLY_ERR_M):
                        sure.append(t)
                    if any(o > 0 for o in out):
                        maybe.append(t)
                else:
                    theirs = min(pt.distance(Point(q)) for q in self.member_points(p["partner"], k))
                    was |= theirs <= radius
                    came |= bool((dm <= radius).any())
                    if was and not came and theirs > radius + FRIENDLY_ERR_M:
                        sure.append(t)
                    if was and not came and theirs > radius - FRIENDLY_ERR_M:
                        maybe.append(t)
            what = "outside its lane" if m["type"] == "passage-of-lines" else "gap in the relief"
            for a, b in _runs(sure):
                if b - a >= 30:
                    for o in self.owners_of(m["unit"], a):
                        self.must(o, "presence", [], [m["unit"], p["partner"]], a - self.slack, a + 60,
                                  f"{mid}: {what}", at=a)
            for a, b in _runs(maybe):
                for o in self.owners_of(m["unit"], a):
                    self.may(o, ["presence"], [m["unit"], p["partner"]], a - self.slack, b + self.slack)

    def coordination(self) -> None:
        for mid, m in self.missions.items():
            if m["type"] not in COORDINATION:
                continue
            p = m["params"]
            dl = float(p["at"]) + float(p.get("fuzz_s", self.voi["schedule_s"]))
            if not self.valid[mid][0] <= dl < self.valid[mid][1]:
                continue
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
                    self.must(o, "coordination", [], [m["unit"], p["partner"]], dl - 1, dl + 5, f"{mid} failed", at=dl)

    def contingency(self) -> None:
        self.triggered_areas: dict[str, set[str]] = defaultdict(set)
        for mid, m in self.missions.items():
            if m["type"] not in CONTINGENT:
                continue
            owner, tr = m["params"]["owner"], m["params"]["trigger"]
            if owner not in self.owners:
                continue
            geom = self.area[tr["area"]]
            # sensors place hostiles within TOLERANCE_M: the trigger may fire once enough
            # strength is that near the area, and must once it is that far inside
            near_g, deep_g = _bands(geom)
            need = tr.get("min_strength", 1)
            t_near = t_in = None
            for k, t in enumerate(self.ticks):
                if not self.valid[mid][0] <= t < self.valid[mid][1]:
                    continue
                if tr["kind"] == "hostile-in-area":
                    hs = [(Point(x, y), st) for x, y, st in self.hostiles_at(t).values()]
                    if t_near is None and sum(st for p, st in hs if near_g.contains(p)) >= need:
                        t_near = t
                    if t_in is None and sum(st for p, st in hs if geom.contains(p)) >= need:
                        t_in = t
                    hit = sum(st for p, st in hs if deep_g.contains(p)) >= need
                    t0, at = (t if t_near is None else t_near) - 15, t if t_in is None else t_in
                else:
                    c = self.member_points(tr["unit"], k).mean(axis=0)
                    hit, t0, at = geom.distance(Point(c)) <= tr.get("within_m", 0.0), t - self.slack, t
                if hit:
                    self.must(owner, "contingency", [], [m["unit"]], t0, t + 40, f"{mid} triggered", at=at)
                    self.task_started[mid], self.task_due[mid] = t0 + 15, t   # its task runs from the trigger
                    self.triggered_areas[owner].add(tr["area"])
                    break
            else:
                if t_near is not None:   # it came near, never well inside: it may have fired
                    self.may(owner, ["contingency"], [m["unit"]], t_near - 15, self.ticks[-1])

    def _ready_interval(self, mid: str) -> tuple[float, float]:
        m = self.missions[mid]
        v0, v1 = self.valid[mid]
        ready = max([self.ended.get(a, math.inf) for a in m.get("after", [])], default=0.0)
        return max(ready, v0), min(self.ended.get(mid, math.inf), v1)

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
                geo = geometry_params(m["type"])
                for key in ("engagement_area", "area"):
                    a = m["params"].get(key)
                    if a and key in geo and not (m["type"] in PENETRATION and PENETRATION[m["type"]] == key):
                        watch.append((a, "monitored", mid))
                held = m["params"].get(PENETRATION.get(m["type"], ""))
                if held:
                    watch.append((held, "penetration", mid))
            for area, typ, mid in watch:
                # An incident per hostile group that enters the area, unless it was near it
                # less than EPISODE_S before (the user still knows of it); sensors place a
                # group within TOLERANCE_M, so one that comes that far inside must be told,
                # from when it came that near; one that only grazes the edge may be.
                geom = self.area[area]
                near_geom, deep = _bands(geom)
                near_at: dict[float, list[str]] = {}
                last_near: dict[str, float] = {}
                entered: dict[str, list] = {}   # group -> [came near, came inside]: not yet deep inside
                entries: list[tuple[float, float, float, str]] = []
                for t in self.ticks:
                    if mid is not None:
                        r0, r1 = self._ready_interval(mid)
                        if not (r0 <= t < r1 and self.missions[mid]["unit"] in self.subtree(o, t)):
                            continue
                    hs = self.hostiles_at(t)
                    near = sorted(h for h, (x, y, s) in hs.items() if near_geom.contains(Point(x, y)))
                    if not near:
                        continue
                    near_at[t] = near
                    before = [g for g in near if last_near.get(g, -math.inf) >= t - TICK]   # there already
                    for h in near:
                        if t - last_near.get(h, -math.inf) >= EPISODE_S and not any(
                                math.hypot(hs[h][0] - hs[g][0], hs[h][1] - hs[g][1]) < RESOLVE_M for g in before):
                            entered[h] = [t, None]   # a group next to one already there is no new group to any sensor
                    for h in near:
                        last_near[h] = t
                    for h in [h for h in entered if h in near]:
                        p = Point(hs[h][0], hs[h][1])
                        if entered[h][1] is None and geom.contains(p):
                            entered[h][1] = t
                        if deep.contains(p):
                            t_near, t_in = entered.pop(h)
                            entries.append((t_near, t if t_in is None else t_in, t, h))
                first_seen: dict[str, float] = {}
                for tt in sorted(near_at):
                    for g in near_at[tt]:
                        first_seen.setdefault(g, tt)
                first = True
                for t_near, t_in, t, h in sorted(entries, key=lambda e: e[1]):
                    # a triggered contingency tells the first activity in its trigger area
                    if first and mid is None and area in getattr(self, "triggered_areas", {}).get(o, ()):
                        first = False
                        continue
                    first = False
                    # a group that only grazes the area, gone before the next track report,
                    # may be seen there or not
                    later_all = self.hostiles_at(t + TRACK_S)
                    later = later_all.get(h)
                    # one that closes within RESOLVE_M of a group already there by then is one
                    # group with it to any sensor: it may be told as new or not
                    merged = later is not None and any(
                        math.hypot(later[0] - x, later[1] - y) < RESOLVE_M for g, (x, y, _s) in later_all.items()
                        if g != h and g in near_at.get(t, ()) and first_seen.get(g, math.inf) < t_near)
                    if later is not None and geom.contains(Point(later[0], later[1])) and not merged:
                        self.must(o, typ, [], [h, area], t_near - 15, t + 45, f"{h} enters {area}", at=t_in,
                                  about=[area])
                for a, b in _runs(sorted(near_at)):
                    who = sorted({h for t, hs_ in near_at.items() if a <= t <= b for h in hs_})
                    self.may(o, [typ], who + [area], a - 15, b + 30, about=[area])
                if typ == "penetration":   # a group heading for it may be projected to enter
                    self._approach(o, area, mid)
            for mid, m in self.missions.items():
                by = m["params"].get("expect_hostile_by")
                if by is None:
                    continue
                r0, r1 = self._ready_interval(mid)
                if not r0 <= by < r1:
                    continue
                seen = any(self.area[m["params"]["engagement_area"]].contains(Point(x, y))
                           for t in self.ticks if r0 <= t <= by for x, y, s in self.hostiles_at(t).values())
                if not seen and m["unit"] in self.subtree(o, by):
                    self.must(o, "hostile-expected", [], [m["unit"]], by - 1, by + 5, f"{mid}: nobody came", at=by)

    def _approach(self, o: str, area: str, mid: str) -> None:
        """Groups that come within APPROACH_M of an area no hostile may enter while its
        mission watches it: a projection that they will enter is fair."""
        ring = self.area[area].buffer(APPROACH_M)
        r0, r1 = self._ready_interval(mid)
        near = [t for t in self.ticks if r0 <= t < r1 and self.missions[mid]["unit"] in self.subtree(o, t)
                and any(ring.contains(Point(x, y)) for x, y, _s in self.hostiles_at(t).values())]
        for a, b in _runs(near):
            who = sorted({h for t in self.ticks if a <= t <= b for h, (x, y, _s) in self.hostiles_at(t).items()
                          if ring.contains(Point(x, y))})
            self.may(o, ["projected-penetration"], who + [area], a - 15, b + 30, about=[area])

    def proximity(self) -> None:
        """A threat within the threat radius of a platoon is contact (a new episode after
        EPISODE_S with none near); within an episode, the nearest threat at 1/CLOSER of
        the distance of the last incident, or the threats near it STRONGER times as
        strong, is a new incident. An alert counts for it from when the change reached
        the MATERIAL step (it is news by then), to a minute after. Positions of hostiles
        are known to sensors within TOLERANCE_M: a threat that only grazes the envelope's
        edge may be told or not; one that comes TOLERANCE_M inside it must be, from when it
        came within TOLERANCE_M of the edge."""
        radius = float(self.voi["threat_radius_m"])
        outer, inner = radius + TOLERANCE_M, radius - TOLERANCE_M
        for o in self.owners:
            plts = sorted(u for u, d in self.units.items() if d["echelon"] == "platoon")
            for u in plts:
                last_near, dist, dist_t0, strength, str_t0 = -1e9, math.inf, None, 0, None
                present: list[float] = []
                pending = None   # an episode whose contact is not yet certain: (began, first within radius)
                told = {"distance": -math.inf, "strength": -math.inf}
                for k, t in enumerate(self.ticks):
                    st = self.subtree(o, t)
                    if u not in st:
                        continue
                    c = self.member_points(u, k).mean(axis=0)
                    near = {h: (float(np.hypot(x - c[0], y - c[1])), s) for h, (x, y, s) in self.hostiles_at(t).items()}
                    near = {h: v for h, v in near.items() if v[0] <= outer}
                    if not near:
                        continue
                    present.append(t)
                    nearest = min(v[0] for v in near.values())
                    total = sum(v[1] for v in near.values() if v[0] <= radius)
                    total_out = sum(v[1] for v in near.values())   # as strong as sensors could make it
                    if t - last_near >= EPISODE_S:   # first contact, or back after a long quiet
                        pending = (t, None)
                    last_near = t
                    if pending is not None:
                        began, within = pending
                        if within is None and nearest <= radius:
                            pending = began, within = (began, t)
                        if nearest <= inner:
                            self.must(o, "contact", PROX, [u, *near], began - 15, t + 15 + self.slack,
                                      f"{sorted(near)} near {u}", at=within, about=[u])
                            dist, dist_t0, strength, str_t0 = nearest, None, total, None
                            told = {"distance": t, "strength": t}
                            pending = None
                        continue
                    if dist_t0 is None and max(nearest - TOLERANCE_M, 0.0) * MATERIAL <= dist:   # sensors err
                        dist_t0 = t
                    if nearest * CLOSER <= dist and t - told["distance"] >= NO_VALUE_S:
                        self.must(o, "distance", PROX, [u], dist_t0 - 15, t + 60, f"threat closer to {u}", at=dist_t0,
                                  about=[u])
                        dist, dist_t0 = nearest, None
                        told["distance"] = t
                    if str_t0 is None and total_out >= MATERIAL * strength:
                        str_t0 = t
                    if total >= STRONGER * strength and t - told["strength"] >= NO_VALUE_S:
                        self.must(o, "strength", PROX, [u], str_t0 - 15, t + 40, f"threat near {u} stronger", at=str_t0,
                                  about=[u])
                        strength, str_t0 = total, None
                        told["strength"] = t
                for a, b in _runs(present):
                    self.may(o, PROX, [u], a - 15, b + 30, about=[u])

    def calls_for_fire(self) -> None:
        for c in self.sim.cffs:
            t = c["t"]
            k = int(round(t / TICK))
            near_leaves, loose = set(), set()
            for leaf in self.leaves:
                pts = self.member_points(leaf, k)
                d = np.hypot(pts[:, 0] - c["x"], pts[:, 1] - c["y"]).min()
                if d <= c["radius_m"]:
                    near_leaves.add(leaf)
                if d <= c["radius_m"] + self.slack * FRIENDLY_MPS:   # as far as a report's age can put it
                    loose.add(leaf)
            for o in self.owners:   # friendly reports are up to `slack` old: near the edge either answer is fair
                mine = loose & self.subtree(o, t)
                if mine:
                    self.may(o, ["call-for-fire"], [self.platoon_of(x, t) for x in mine], t - 1, t + 2)
            if c["kind"] == "cff":
                others = near_leaves - self.subtree(c["requester"], t)
                if others and c["requester"] in self.owners:
                    self.must(c["requester"], "call-for-fire", [], [self.platoon_of(x, t) for x in others], t - 1, t + 2,
                              f"{c['cff']} near friendlies", at=t)
            else:
                for o in self.owners:
                    mine = near_leaves & self.subtree(o, t)
                    if mine:
                        self.must(o, "call-for-fire", [], [self.platoon_of(x, t) for x in mine], t - 1, t + 2,
                                  f"{c['cff']} confirmed near {o}'s units", at=t)


def ground_truth(sim, feats: list[dict], plan: dict, owners: list[str]) -> dict:
    tr = Truth(sim, feats, plan, owners)
    tr.contingency()
    for step in (tr.out_of_position, tr.fratricide, tr.unknown_position, tr.schedule, tr.coordination,
                 tr.areas, tr.proximity, tr.calls_for_fire, tr.check_families, tr.presence):
        step()
    key = lambda d: (d["owner"], d["t0"], d.get("type", ""), d["subjects"])
    return {"owners": owners, "tick_s": TICK, "incidents": sorted(tr.incidents, key=key),
            "situations": sorted(tr.situations, key=key)}
