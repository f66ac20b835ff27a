"""The small-unit-operations domain: plan execution with the mission model, the
EA-manager API that mission methods post to, the 13 SUO alert types (Fig. 4) and
calls for fire, and the SUO VOA heuristics (merging, red-alert priority)."""
from __future__ import annotations

import heapq
import math
from collections import defaultdict

import numpy as np
import shapely

from ea_agent.core.alert import Alert, Candidate, highest, hms
from ea_agent.core.geo import Projection, bearing_name
from ea_agent.core.plan import MissionSpec, PlanSpec, PlanState, TaskOrg, TimeConstraint
from ea_agent.core.schedule import Schedule

from .messages import (CallForFire, CallForFireConfirm, LocationReport, MissionConfirm, Order, Reorganization,
                       SensorTrack)

from . import detectors as D
from .missions import REGISTRY, ContingentMission, Mission, make
from .picture import Picture, Watchman

CATEGORY = {
    "fratricide": "policy-constraint-violated", "call-for-fire": "policy-constraint-violated",
    "out-of-position": "plan-constraint-violated", "coordination": "plan-constraint-violated",
    "schedule": "plan-constraint-violated", "unknown-position": "reporting-requirement",
    "contingency": "contingency-plan-suggested", "monitored": "adversarial-activity",
    "ave-of-approach": "adversarial-activity", "hostile-expected": "adversarial-activity",
    "contact": "adversarial-activity", "distance": "adversarial-activity",
    "strength": "adversarial-activity", "proximity": "adversarial-activity",
}
ALERT_TYPES = tuple(k for k in CATEGORY if k != "call-for-fire")  # the 13 of Fig. 4
PROXIMITY_FAMILY = ("contact", "distance", "strength")
_BASE = Mission(MissionSpec("-", "-", "mission"))   # defaults for units without an active mission


def km(d: float) -> str:
    return f"{d:.0f} m" if d < 1000 else f"{d / 1000:.1f} km"


class SuoDomain:
    def __init__(self, owner: str, taskorg: TaskOrg, plans: dict[str, PlanSpec], initial_plan: str,
                 overlay: dict, proj: Projection, cfg: dict):
        if owner not in taskorg.units:
            raise KeyError(f"unknown unit {owner!r}: not in the task organization")
        self.owner = owner
        self.taskorg = taskorg.copy()
        self.plans = plans
        self.initial_plan = initial_plan
        self.overlay = overlay
        self.cfg = cfg
        self.voi_cfg = cfg["voi"]
        self.pic = Picture(self.taskorg, proj)
        self.watchman = Watchman(self.pic, cfg)
        self.watch = self.watchman.watch   # the watchman is the domain's filter, called directly
        self.scan_s = float(cfg["manager"]["unknown_scan_s"])
        self.next_scan = self.scan_s
        self.plan: PlanState | None = None
        self.missions: dict[str, Mission] = {}
        self.dirty_leaves: set[str] = set()
        self.dirty_tracks: set[str] = set()
        self.unit_pos: dict[str, tuple[float, float] | None] = {}
        self.env_prev: dict[str, tuple[frozenset, float, int]] = {}
        self.area_prev: dict[str, frozenset] = {}
        self._reset_monitors()
        self._org_changed()

    # -- wiring ----------------------------------------------------------------------
    def bind(self, ea) -> None:
        self.ea = ea
        self.timers = ea.timers
        self.schedule = Schedule(ea.timers, ea.post, self.name, self.in_plan, lambda m: self.voi(m, "schedule_s"),
                                 self.voi_cfg["schedule_repeat_s"])

    def _reset_monitors(self) -> None:
        self.loc_monitors: dict[str, list[tuple[Mission, str, str, str]]] = defaultdict(list)
        self.red_monitors: dict[str, list[tuple[Mission, bool]]] = defaultdict(list)  # area -> missions
        self.coord: dict[str, tuple[Mission, str, str, float]] = {}
        self.contingencies: dict[str, ContingentMission] = {}
        self.global_areas: dict[str, str] = {}   # area -> alert type (monitored / ave-of-approach)
        self.auto: list[tuple[float, str]] = []
        self._areas_changed()

    def _areas_changed(self) -> None:
        ids = set(self.global_areas) | set(self.red_monitors) | {
            c.params["trigger"]["area"] for c in self.contingencies.values() if c.params["trigger"]["kind"] == "hostile-in-area"}
        self.area_index = D.AreaIndex({a: self.overlay[a].area for a in sorted(ids)})

    def watched_areas(self) -> set[str]:
        """Overlay areas this EA watches for hostiles (global monitors, missions, triggers)."""
        return set(self.area_index.ids)

    def _org_changed(self) -> None:
        """Recompute everything that depends on the command hierarchy."""
        to = self.taskorg
        self.own_units = set(to.subtree(self.owner))
        self.pic.rebuild(to)
        self.own_leaves = {u for u in self.pic.leaves if u in self.own_units}
        self.watchman.set_own(self.own_leaves)
        self.leaves = self.pic.leaves
        self.leaf_i = {u: i for i, u in enumerate(self.leaves)}
        bnd_units = sorted({to.nearest_with(u, 'boundary') for u in self.leaves if to.nearest_with(u, 'boundary')})
        self.bnd_polys = [self.overlay[to.units[b].attrs['boundary']].area for b in bnd_units]
        bi = {b: k for k, b in enumerate(bnd_units)}
        self.leaf_bnd = np.array([bi.get(to.nearest_with(u, 'boundary'), -1) for u in self.leaves])
        self.frat_ok = self.leaf_bnd >= 0
        dflt = float(self.voi_cfg["weapons_range_m"])
        self.leaf_rng = np.array([self._weapons_range(u, dflt) for u in self.leaves])
        self.leaf_mine = np.array([u in self.own_units for u in self.leaves])
        env = [u for u in sorted(self.own_units) if to.units[u].kind == "platoon"]
        self.env_units = env or [self.owner]
        self.unit_pos = {u: self.pic.centroid(u) for u in to.units}
        self._up = {leaf: (leaf, *to.ancestors(leaf)) for leaf in self.leaves}
        self.own_rows = np.array([u in self.own_units for u in self.pic.units])
        self.leaf_xy = np.full((len(self.leaves), 2), np.nan)
        self.outside = np.zeros(len(self.leaves), dtype=bool)
        self.leaf_own_poly = [self.bnd_polys[b] if b >= 0 else None for b in self.leaf_bnd]
        self.dirty_leaves |= set(self.leaves)

    def _weapons_range(self, unit: str, dflt: float) -> float:
        u = self.taskorg.nearest_with(unit, "weapons_range_m")
        return dflt if u is None else float(self.taskorg.units[u].attrs["weapons_range_m"])

    def name(self, unit: str) -> str:
        return self.taskorg.name(unit)

    def voi(self, m: Mission, key: str) -> float:
        """A VOI threshold: the mission's override, else the EA's configuration."""
        return float(m.params.get("voi", {}).get(key, self.voi_cfg[key]))

    def in_plan(self, m: Mission) -> bool:
        if isinstance(m, ContingentMission):
            return m.params["owner"] == self.owner
        return m.unit in self.own_units

    def current_mission(self, unit: str) -> Mission:
        """The unit's active mission, or the nearest superior's; defaults otherwise."""
        if self.plan is not None:
            active = {s.unit: s.id for s in self.plan.active()}
            for u in [unit, *self.taskorg.ancestors(unit)]:
                if u in active:
                    return self.missions[active[u]]
        return _BASE

    # -- plan execution (6.6.1) ------------------------------------------------------------
    def start(self, t: float) -> None:
        self.execute_plan(self.initial_plan, t)

    def execute_plan(self, name: str, t: float) -> None:
        if name not in self.plans:
            raise KeyError(f"order names unknown plan {name!r}")
        self.abort_plan(t)
        self.plan = PlanState(self.plans[name])
        self.missions = {s.id: make(s) for s in self.plans[name].missions}
        self.compute_plan_monitoring_data()
        self._advance_plan(t)

    def abort_plan(self, t: float) -> None:
        self.timers.clear()
        self._reset_monitors()
        self.plan = None
        self.missions = {}

    def compute_plan_monitoring_data(self) -> None:
        """Global monitors: decision points, NAIs and avenues of approach in our plan."""
        for cm in self.overlay.values():
            if cm.owner == self.owner and cm.kind in ("decision-point", "nai"):
                self.global_areas[cm.id] = "monitored"
            elif cm.owner == self.owner and cm.kind == "avenue-of-approach":
                self.global_areas[cm.id] = "ave-of-approach"
        self._areas_changed()

    def _advance_plan(self, t: float) -> None:
        for spec in self.plan.newly_ready():
            m = self.missions[spec.id]
            if isinstance(m, ContingentMission):
                self.plan.state[m.id] = "dormant"
                if self.in_plan(m):
                    m.post_execution_constraints(self)
                continue
            if self.in_plan(m):
                m.post_execution_constraints(self)
            if m.AUTO_START:
                at = spec.start.t if spec.start.t is not None else t
                heapq.heappush(self.auto, (max(at, t), m.id))

    def _post_all_for(self, units: set[str]) -> None:
        """Units newly in our subtree: monitor their ready and active missions too."""
        for mid, st in self.plan.state.items() if self.plan else ():
            m = self.missions[mid]
            if m.unit in units and st in ("ready", "active") and not isinstance(m, ContingentMission):
                m.post_execution_constraints(self)

    def on_confirm(self, c: MissionConfirm) -> None:
        if self.plan is None:
            return
        m = self.missions.get(c.mission)
        if m is None:
            raise KeyError(f"confirmation for unknown mission {c.mission!r}")
        if c.phase == "start":
            if self.plan.state[m.id] == "dormant":
                self.plan.state[m.id] = "ready"
            self.plan.start(m.id, c.t)
            self.timers.occurred(("start", m.id), c.t)
            if self.in_plan(m):
                m.check_initial_location(self, c.t)
        else:
            self.plan.end(m.id, c.t)
            self.timers.occurred(("end", m.id), c.t)
            if self.in_plan(m):
                self.unit_pos[m.unit] = self.pic.centroid(m.unit)
                m.check_final_location(self, c.t)
            self.loc_monitors.pop(m.id, None)
            for area in list(self.red_monitors):
                self.red_monitors[area] = [x for x in self.red_monitors[area] if x[0].id != m.id]
            self._advance_plan(c.t)

    def resubordinate(self, unit: str, new_parent: str, t: float) -> None:
        before = set(self.own_units)
        self.taskorg.resubordinate(unit, new_parent)
        self._org_changed()
        self._post_all_for(self.own_units - before)
        self.env_prev = {u: v for u, v in self.env_prev.items() if u in self.own_units}

    # -- the monitoring API that mission methods call (6.5) ----------------------------
    def post_time_constraint(self, m: Mission, phase: str, tc: TimeConstraint) -> None:
        self.schedule.post(m, phase, tc)

    def post_location_monitor(self, m: Mission, geom: str, rule: str, what: str) -> None:
        self.loc_monitors[m.id].append((m, geom, rule, what))

    def post_red_monitor(self, m: Mission, area: str, expected: bool, expect_by: float | None = None) -> None:
        self.red_monitors[area].append((m, expected))
        self._areas_changed()
        if expect_by is not None:
            def absent(tf, mon, how):
                if self.in_plan(m):
                    self.ea.post(Candidate(tf, "hostile-expected", m.compute_priority("hostile-expected"),
                                           (m.unit,), f"Expected hostile activity absent at {area} for "
                                           f"{self.name(m.unit)} {m.TYPE} (expected by {hms(float(expect_by))})",
                                           key=("hostile-expected", m.id), friendly=False,
                                           details={"mission": m.id, "area": area, "places": [area]}))
                return None
            self.timers.not_later_than(("hostile", m.id), float(expect_by), absent, tag=m.id)

    def post_coordination(self, m: Mission, partner: str, point: str, at: float, fuzz: float) -> None:
        self.coord[m.id] = (m, partner, point, float(self.voi(m, "coordination_radius_m")))

        def failed(tf, mon, how):
            if self.in_plan(m):
                self.ea.post(self._coordination_candidate(m, partner, point, tf))
            return None
        self.timers.not_later_than(("coord", m.id), at + fuzz, failed, tag=m.id)

    def _coordination_candidate(self, m: Mission, partner: str, point: str, t: float) -> Candidate:
        geom = self.overlay[point].geom
        far = []
        for u in (m.unit, partner):
            d = D.judged_distance(geom, self.pic.member_xy(u), "any", None)
            far.append(f"{self.name(u)} {'unknown' if d is None else km(d)}")
        return Candidate(t, "coordination", m.compute_priority("coordination"), (m.unit, partner),
                         f"{self.name(m.unit)} and {self.name(partner)} cannot {m.TYPE} at {point} as planned "
                         f"({', '.join(far)} away)", key=("coordination", m.id),
                         details={"mission": m.id, "point": point, "places": [point]})

    def post_contingency(self, m: ContingentMission) -> None:
        self.contingencies[m.id] = m
        self._areas_changed()

    def check_location(self, m: Mission, geom_id: str, rule: str, t: float, what: str) -> None:
        c = self._oop(m, geom_id, rule, what, t)
        if c is not None:
            self.ea.post(c)

    def monitored_candidate(self, m: Mission | None, area: str, t: float, tracks: list[str], strength: int,
                            expected: bool, kind: str = "monitored") -> None:
        prio = m.compute_priority(kind) if m is not None else _BASE.compute_priority(kind)
        where = f" ({'expected' if expected else 'unexpected'} for {self.name(m.unit)} {m.TYPE})" if m else ""
        label = "Enemy activity on ave of approach" if kind == "ave-of-approach" else "Red activity at"
        self.ea.post(Candidate(t, kind, prio, tuple(tracks), f"{label} {area}{where}: {strength} entities in "
                               f"{len(tracks)} track{'s' if len(tracks) > 1 else ''}",
                               key=(kind, area, m.id if m else None), measure=float(strength), friendly=False,
                               details={"place": area, "places": [area], "strength": strength,
                                        "mission": m.id if m else None, "expected": expected}))

    def evaluate_trigger(self, tr: dict) -> bool:
        if tr["kind"] == "hostile-in-area":
            return self._area_strength.get(tr["area"], 0) >= int(tr.get("min_strength", 1))
        pts = self.pic.member_xy(tr["unit"])
        d = D.judged_distance(self.overlay[tr["area"]].area, pts, tr.get("rule", "centroid"), self.unit_pos.get(tr["unit"]))
        return d is not None and d <= float(tr.get("within_m", 0.0))

    def execute_contingency(self, m: ContingentMission, t: float) -> None:
        self.plan.state[m.id] = "ready"
        task = REGISTRY[m.params["task"]]
        tp = dict(m.params.get("task_params", {}))
        if all(r in tp for r in task.required()):
            task(MissionSpec(m.id, m.unit, task.TYPE, m.spec.start, m.spec.end, (), tp)).post_execution_constraints(self)

    # -- watchman and facts ----------------------------------------------------------------
    def busy(self) -> bool:
        return bool(self.dirty_leaves or self.dirty_tracks or self.watchman.quiet)

    def next_wakeup(self) -> float:
        return min(self.next_scan, self.auto[0][0] if self.auto else math.inf)

    def apply(self, facts: list) -> None:
        locs = [f for f in facts if type(f) is LocationReport]
        if locs:
            self.dirty_leaves |= self.pic.apply_locations(locs)
        tracks = [f for f in facts if type(f) is SensorTrack]
        if tracks:
            self.dirty_tracks |= self.pic.apply_tracks(tracks)
        if len(locs) + len(tracks) == len(facts):
            return
        for f in facts:
            try:
                self._apply_one(f)
            except (KeyError, ValueError) as e:   # bad order/confirmation: counted, the rest goes on
                self.ea.error(f"{type(f).__name__} at t={f.t}: {e}")

    def _apply_one(self, f) -> None:
        k = type(f)
        if k is MissionConfirm:
            self.on_confirm(f)
        elif k is Order:
            if f.action == "execute-plan":
                self.execute_plan(f.plan, f.t)
            else:
                self.abort_plan(f.t)
        elif k is Reorganization:
            self.resubordinate(f.unit, f.new_parent, f.t)
        elif k is CallForFire or k is CallForFireConfirm:
            self._flush_quiet()
            self.on_cff(f)

    def _flush_quiet(self) -> None:
        if self.watchman.quiet:
            self.pic.apply_locations(self.watchman.quiet)
            self.watchman.quiet = []

    # -- calls for fire (6.7.2, case 1) -------------------------------------------------
    def on_cff(self, f) -> None:
        x, y = self.pic.proj.to_xy(f.lon, f.lat)
        d = np.hypot(self.pic.xy[:, 0] - x, self.pic.xy[:, 1] - y)
        near = np.nonzero(d <= f.radius_m)[0]
        confirm = type(f) is CallForFireConfirm
        if not confirm and f.requester != self.owner:
            return
        units: dict[str, list[float]] = defaultdict(list)
        for i in near.tolist():
            leaf = self.pic.ent_leaf[i]
            if confirm and leaf not in self.own_leaves:
                continue
            if not confirm and leaf in self.taskorg.subtree(f.requester):
                continue   # the requester's own elements are its own business
            units[self._platoon_of(leaf)].append(float(d[i]))
        if not units:
            return
        names = ", ".join(f"{self.name(u)} ({len(v)} within {km(min(v))})" for u, v in sorted(units.items()))
        text = (f"Planned fire {f.cff} by {self.name(f.requester)} near {names}" if confirm else
                f"Friendlies near target of {f.cff}: {names}; confirm before firing")
        self.ea.post(Candidate(f.t, "call-for-fire", "flash", tuple(sorted(units)), text,
                               key=("cff", f.cff, confirm), friendly=True,
                               details={"cff": f.cff, "requester": f.requester, "confirmed": confirm,
                                        "radius_m": f.radius_m}))

    def _platoon_of(self, unit: str) -> str:
        for u in [unit, *self.taskorg.ancestors(unit)]:
            if self.taskorg.units[u].kind in ("platoon", "company", "battalion"):
                return u
        return unit

    # -- detection at the end of each epoch ------------------------------------------
    def detect(self, t: float) -> list[Candidate]:
        self._flush_quiet()
        cands: list[Candidate] = []
        dirty_units: set[str] = set()
        if self.dirty_leaves:
            for leaf in self.dirty_leaves:
                dirty_units.update(self._up[leaf])
            leaf_c, unit_c = self.pic.centroids()
            self.leaf_xy = leaf_c
            self.unit_pos = {u: (None if x != x else (float(x), float(y)))
                             for u, (x, y) in zip(self.pic.units, unit_c.tolist())}
            own = unit_c[self.own_rows]
            own = own[~np.isnan(own[:, 0])]
            self.watchman.set_bbox(own)
            self._location_monitors(t, dirty_units, cands)
            self._coordination(t, dirty_units)
            self._fratricide(t, cands)
        rescan = t >= self.next_scan   # periodic, on scenario time: expiry-driven reminders
        if rescan or self.dirty_tracks or dirty_units.intersection(self.env_units):
            self._threats(t, cands, dirty_units, rescan)
        if self.dirty_tracks:
            self._areas(t, cands)          # also checks contingencies
        elif self.dirty_leaves and self.contingencies:
            self._contingencies(t, cands)
        if t >= self.next_scan:
            self._unknown_positions(t, cands)
            self.next_scan = (math.floor(t / self.scan_s) + 1) * self.scan_s
        while self.auto and self.auto[0][0] <= t:
            _, mid = heapq.heappop(self.auto)
            if self.plan and mid in self.missions and self.plan.state[mid] == "ready":
                self.plan.start(mid, t)
                self.timers.occurred(("start", mid), t)
                self.missions[mid].execute_mission(self, t)
                self.plan.end(mid, t)
                self.timers.occurred(("end", mid), t)
                self._advance_plan(t)
        self.dirty_leaves = set()
        self.dirty_tracks = set()
        return cands

    def _geom(self, geom_id: str, what: str):
        """Routes and axes are judged by distance to the line; everything else to its area."""
        return self.overlay[geom_id].geom if what in ("route", "axis") else self.overlay[geom_id].area

    def _oop(self, m: Mission, geom_id: str, rule: str, what: str, t: float, d: float | None = None) -> Candidate | None:
        pos = self.unit_pos.get(m.unit)
        geom = self._geom(geom_id, what)
        if d is None:
            d = D.judged_distance(geom, self.pic.member_xy(m.unit), rule, pos)
        thr = self.voi(m, "out_of_position_m")
        if d is None or d <= thr:
            return None
        ref = f"should be at {geom_id}"
        if pos is not None:
            near = shapely.shortest_line(shapely.Point(pos), geom).coords[-1]
            ref += f" ({km(d)} {bearing_name(near[0] - pos[0], near[1] - pos[1])} of {self.name(m.unit)})" if rule == "centroid" else f" ({rule} members within {km(thr)})"
        return Candidate(t, "out-of-position", m.compute_priority("out-of-position"), (m.unit,),
                         f"{self.name(m.unit)} out of position for {m.TYPE} mission: {ref}",
                         key=("out-of-position", m.id, what), measure=d,
                         details={"mission": m.id, "control_measure": geom_id, "rule": rule, "check": what,
                                  "distance_m": round(d, 1), "threshold_m": thr, "places": [geom_id]})

    def _location_monitors(self, t: float, dirty_units: set[str], cands: list) -> None:
        if self.plan is None:
            return
        todo = [mon for mid, mons in self.loc_monitors.items()
                if mons and mons[0][0].unit in dirty_units and self.plan.state.get(mid) == "active"
                for mon in mons if self.in_plan(mon[0])]
        cent = [mon for mon in todo if mon[2] == "centroid" and self.unit_pos.get(mon[0].unit)]
        if cent:   # one vectorised distance call for every centroid-judged monitor
            ds = shapely.distance(np.array([self._geom(g, w) for _, g, _, w in cent], dtype=object),
                                  shapely.points(np.array([self.unit_pos[m.unit] for m, _, _, _ in cent])))
            for (m, g, rule, what), d in zip(cent, ds.tolist()):
                if d > self.voi(m, "out_of_position_m"):
                    cands.append(self._oop(m, g, rule, what, t, d))
        for m, g, rule, what in todo:
            if rule != "centroid":
                c = self._oop(m, g, rule, what, t)
                if c is not None:
                    cands.append(c)

    def _coordination(self, t: float, dirty_units: set[str]) -> None:
        for mid, (m, partner, point, radius) in list(self.coord.items()):
            if m.unit not in dirty_units and partner not in dirty_units:
                continue
            g = self.overlay[point].geom
            ok = True
            for u in (m.unit, partner):
                d = D.judged_distance(g, self.pic.member_xy(u), "any", None)
                ok &= d is not None and d <= radius
            if ok:
                self.timers.occurred(("coord", mid), t)
                del self.coord[mid]

    def _fratricide(self, t: float, cands: list) -> None:
        """Only units outside their own boundary can be at risk (6.7.2), so the pair
        check runs only while some unit is outside; the inside test runs for movers."""
        rows = [self.leaf_i[u] for u in self.dirty_leaves if self.frat_ok[self.leaf_i[u]]]
        if not rows:
            return
        pos = self.leaf_xy
        r = np.array(rows)
        ok = ~np.isnan(pos[r, 0])
        polys = np.array([self.leaf_own_poly[i] for i in r[ok]], dtype=object)
        self.outside[r] = False
        if len(polys):
            self.outside[r[ok]] = ~shapely.contains_xy(polys, pos[r[ok], 0], pos[r[ok], 1])
        if not self.outside.any():
            return
        dirty = np.zeros(len(self.leaves), dtype=bool)
        dirty[r] = True
        inside = D.inside_matrix(pos, self.bnd_polys)
        bnd = np.where(self.frat_ok, self.leaf_bnd, 0)
        pos = np.where(self.frat_ok[:, None], pos, np.nan)
        groups: dict[tuple[str, str], list[tuple[str, str, float]]] = defaultdict(list)
        for i, j, d in D.fratricide_pairs(pos, bnd, inside, self.leaf_rng, dirty, self.leaf_mine):
            a, b = self.leaves[i], self.leaves[j]
            pa, pb = self._platoon_of(a), self._platoon_of(b)
            if (pa, a) > (pb, b):
                a, b, pa, pb = b, a, pb, pa
            groups[(pa, pb)].append((a, b, d))
        for (pa, pb), pairs in sorted(groups.items()):
            dmin = min(p[2] for p in pairs)
            squads = sorted({s for p in pairs for s in p[:2]})
            out_a = [s for s in squads if self.taskorg.is_under(s, pa) and not inside[self.leaf_i[s], bnd[self.leaf_i[s]]]]
            out_b = [s for s in squads if self.taskorg.is_under(s, pb) and not inside[self.leaf_i[s], bnd[self.leaf_i[s]]]]
            culprit = pa if out_a else pb
            other = pb if culprit == pa else pa
            cands.append(Candidate(t, "fratricide", "flash", tuple([pa, pb] + squads),
                                   f"Fratricide risk: {self.name(culprit)} out of its boundary within "
                                   f"{km(dmin)} of {self.name(other)}",
                                   key=("fratricide", pa, pb), measure=1000.0 / max(dmin, 1.0),
                                   details={"pairs": [[a, b, round(d, 1)] for a, b, d in sorted(pairs)],
                                            "outside_boundary": sorted(out_a + out_b), "min_distance_m": round(dmin, 1)}))

    def _threats(self, t: float, cands: list, dirty_units: set[str], rescan: bool = False) -> None:
        """Threat envelopes (6.7.1): tracks close enough to threaten each platoon.

        A unit is re-evaluated only when it moved or a track in or near its envelope
        changed, so what happens far away (which a mesh peer may never receive)
        cannot change its alerts."""
        radius = float(self.voi_cfg["threat_radius_m"])
        danger = float(self.voi_cfg["danger_close_m"])
        tids = sorted(self.pic.tracks)
        units = [u for u in self.env_units if self.unit_pos.get(u)]
        if not units:
            return
        upos = np.array([self.unit_pos[u] for u in units])
        if tids:
            tpos = np.array([(self.pic.tracks[k].x, self.pic.tracks[k].y) for k in tids])
            dist = D.distances(upos, tpos)
        close = (dist <= radius) if tids else np.zeros((len(units), 0), dtype=bool)
        moved = np.array([k in self.dirty_tracks for k in tids], dtype=bool)
        for ui, u in enumerate(units):
            prev0 = self.env_prev.get(u, (frozenset(),))[0]
            if not (rescan and prev0) and u not in dirty_units and not (close[ui] & moved).any() \
                    and not prev0 & self.dirty_tracks:
                continue
            if not close[ui].any():
                if self.env_prev.get(u, (frozenset(),))[0]:
                    self.env_prev[u] = (frozenset(), math.inf, 0)
                continue
            inn = np.nonzero(close[ui])[0]
            ids = frozenset(tids[k] for k in inn)
            prev = self.env_prev.get(u, (frozenset(), math.inf, 0))
            k_near = inn[np.argmin(dist[ui, inn])]
            nearest = float(dist[ui, k_near])
            strength = int(sum(self.pic.tracks[tids[k]].strength for k in inn))
            self.env_prev[u] = (ids, nearest, strength)
            m = self.current_mission(u)
            fs = len(self.pic.members[u])
            tr = self.pic.tracks[tids[k_near]]
            upx = self.unit_pos[u]
            where = f"{km(nearest)} {bearing_name(tr.x - upx[0], tr.y - upx[1])} of {self.name(u)}"
            base = dict(unit=u, nearest_track=tr.id, distance_m=round(nearest, 1), strength=strength,
                        friendly_strength=fs, tracks=sorted(ids), mission=m.id if m is not _BASE else None)
            subj = (u, *sorted(ids))
            group = ("prox", self.taskorg.parent.get(u) or u)
            rec = [(("threat", u, "distance"), 1000.0 / max(nearest, 1.0)), (("threat", u, "strength"), float(strength))]
            new = ids - prev[0]
            voa = self.ea.voa
            # A contact the user no longer remembers (expired) is told again as a contact;
            # "closer" and "stronger" only make sense against an alert the user remembers.
            remembered = voa.enabled and voa.last(("threat", u, "contact"), t) is not None
            if new or not remembered:
                p = m.red_alert_priority("contact", fs, strength, nearest, danger)
                again = not new
                cands.append(Candidate(t, "contact", "immediate" if again else p, subj,
                                       f"{'Contact continues' if again else 'Contact'}: {strength} hostile entities {where}",
                                       key=("threat", u, "contact"), friendly=False, merge_group=group, also=tuple(rec),
                                       details={**base, "new_tracks": sorted(new), "reminder": again}))
            if remembered or not voa.enabled:
                # Propose on every re-evaluation; VOA compares with what the user was last told.
                if not new:
                    p = m.red_alert_priority("distance", fs, strength, nearest, danger)
                    cands.append(Candidate(t, "distance", p, subj, f"Closest threat is now closer: {where}",
                                           key=("threat", u, "distance"), measure=1000.0 / max(nearest, 1.0),
                                           friendly=False, merge_group=group, details=dict(base)))
                p = m.red_alert_priority("strength", fs, strength, nearest, danger)
                if p is not None:
                    cands.append(Candidate(t, "strength", p, subj,
                                           f"Threat near {self.name(u)} stronger: {strength} hostile entities, "
                                           f"nearest {where}",
                                           key=("threat", u, "strength"), measure=float(strength), friendly=False,
                                           merge_group=group, details=dict(base)))

    def _areas(self, t: float, cands: list) -> None:
        tids = sorted(self.pic.tracks)
        xy = np.array([(self.pic.tracks[k].x, self.pic.tracks[k].y) for k in tids]) if tids else np.zeros((0, 2))
        members = self.area_index.members(xy)
        self._area_strength = {a: int(sum(self.pic.tracks[tids[k]].strength for k in idx)) for a, idx in members.items()}
        self._area_tracks = {a: {tids[k] for k in idx} for a, idx in members.items()}
        triggered_now = self._contingencies(t, cands) if self.contingencies else set()
        for area, idx in members.items():
            ids = [tids[k] for k in idx]
            if not self.dirty_tracks.intersection(ids):
                continue
            strength = self._area_strength[area]
            for m, expected in self.red_monitors.get(area, ()):
                if self.plan and self.plan.state.get(m.id) in ("ready", "active") and self.in_plan(m):
                    self.timers.occurred(("hostile", m.id), t)
                    m.respond_to_monitored_red_activity(self, area, t, ids, strength)
            kind = self.global_areas.get(area)
            if kind and area not in triggered_now:   # a triggered contingency says it already
                self.monitored_candidate(None, area, t, ids, strength, expected=False, kind=kind)

    _area_strength: dict[str, int] = {}
    _area_tracks: dict[str, set[str]] = {}

    def _contingencies(self, t: float, cands: list) -> set[str]:
        fired: set[str] = set()
        for mid, m in list(self.contingencies.items()):
            tr = m.params["trigger"]
            if tr["kind"] == "unit-at":
                if not any(self.taskorg.is_under(leaf, tr["unit"]) for leaf in self.dirty_leaves):
                    continue
            elif not self.dirty_tracks.intersection(self._area_tracks.get(tr["area"], ())):
                continue
            if not m.contingency_satisfied(self):
                continue
            del self.contingencies[mid]
            fired.add(tr["area"])
            if tr["kind"] == "hostile-in-area":
                why = f"Red activity at {tr['area']} ({self._area_strength.get(tr['area'], 0)} entities)"
                subj = (m.unit,)
            else:
                why = f"{self.name(tr['unit'])} at {tr['area']}"
                subj = (m.unit, tr["unit"])
            cands.append(Candidate(t, "contingency", m.compute_priority("contingency"), subj,
                                   f"{why} triggers contingency: {m.TYPE} {m.params['task']} by {self.name(m.unit)}",
                                   key=("contingency", mid), friendly=tr["kind"] == "unit-at",
                                   details={"mission": mid, "trigger": tr, "places": [tr["area"]]}))
            self.execute_contingency(m, t)
            if tr["kind"] == "hostile-in-area":  # the contingency alert already told of this activity
                cands[-1].also = ((("monitored", tr["area"], None), float(self._area_strength.get(tr["area"], 0))),)
        if fired:
            self._areas_changed()
        return fired

    def _unknown_positions(self, t: float, cands: list) -> None:
        thr = float(self.voi_cfg["unknown_position_s"])
        last_by_leaf = np.zeros(len(self.leaves))
        np.maximum.at(last_by_leaf, self.pic.ent_leaf_i, np.array(self.pic.seen))
        for k in np.nonzero(t - last_by_leaf > thr)[0].tolist():
            leaf = self.leaves[k]
            if leaf not in self.own_leaves:
                continue
            last = float(last_by_leaf[k])
            silent = t - last
            parent = self.taskorg.parent.get(leaf) or leaf
            cands.append(Candidate(t, "unknown-position", _BASE.compute_priority("unknown-position"), (leaf,),
                                   f"Unknown position: {self.name(leaf)} silent for {silent:.0f} s",
                                   key=("unknown-position", leaf), measure=silent, merge_group=("unknown", parent),
                                   details={"unit": leaf, "last_report_t": last, "silent_s": round(silent, 1)}))

    # -- VOA heuristics: merging and rendering ------------------------------------------
    def merge(self, key, cands: list[Candidate]) -> Candidate:
        parent = key[1]
        subjects = tuple(sorted({s for c in cands for s in c.subjects}))
        if key[0] == "unknown":
            units = [c.subjects[0] for c in cands]
            text = f"Unknown position: {len(units)} units of {self.name(parent)} silent ({', '.join(self.name(u) for u in units)})"
            typ = "unknown-position"
        else:
            typ = "proximity"
            text = f"Threats near {self.name(parent)}: " + "; ".join(c.message for c in cands)
        return Candidate(cands[0].t, typ, highest(c.priority for c in cands), subjects, text, key=key,
                         details={"parent": parent, "merged": [{"type": c.type, "subjects": list(c.subjects),
                                                                "message": c.message, "details": c.details}
                                                               for c in cands]})

    def to_alert(self, c: Candidate) -> Alert:
        det = dict(c.details)
        det["repeat"] = c.repeat
        return Alert(round(c.t, 3), self.owner, c.type, CATEGORY[c.type], c.priority, tuple(c.subjects), c.message, det)
