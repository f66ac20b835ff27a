"""The small-unit-operations domain: plan execution with the mission model and the
EA-manager API that mission methods post to (paper 6.5-6.6).

What each alert family detects lives in `detect/` (one component per family,
registered in `detect.DETECTORS`); how alerts read and merge lives in `render`.
The domain keeps the picture and the plan current, routes the monitoring API to
the component that owns it and runs the components once per epoch.
"""
from __future__ import annotations

import heapq
import math
from typing import Callable, TypeVar

import numpy as np

from ea_agent.core.alert import PRIORITIES, Alert, Candidate
from ea_agent.core.geo import Projection
from ea_agent.core.plan import PlanSpec, PlanState, TaskOrg, TimeConstraint

from . import render
from .detect import (ALERT_TYPES, BASE, CATEGORY, DETECTORS, Areas, Assumptions, Bands, Changes, Checkpoints, Contingencies,
                     Coordination, Coverage, Detector, EndStates, Escapes, FireSupport, Lines, LocationMonitors,
                     Presence, ReconProgress, ScheduleMonitors, Standoffs, Tempo, ThreatsAhead, Windows)
from .detect.ahead import branches_for
from .detect.assemble import Assembly
from .messages import CallForFire, LocationReport, MissionConfirm, Order, Reorganization, SensorTrack
from .missions import DEFAULT_PRIORITY, ContingentMission, Mission, make
from .picture import Picture, Watchman

__all__ = ["ALERT_TYPES", "CATEGORY", "SuoDomain"]

D = TypeVar("D", bound=Detector)


class SuoDomain:
    # reports wait in the manager's batch; any other fact (its handler reads the picture) goes in at once
    BULK_FACTS = (LocationReport, SensorTrack)

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
        # alert type -> default priority: the mission model's table, then the EA's [priority]
        self.priorities = {**DEFAULT_PRIORITY, **cfg.get("priority", {})}
        bad = {k: v for k, v in self.priorities.items() if v not in PRIORITIES}
        if bad:
            k = sorted(bad)[0]
            raise ValueError(f"[priority] {k} = {bad[k]!r}: not one of {', '.join(PRIORITIES)}")
        self.base = Mission(BASE.spec).use_defaults(self.priorities)   # for units without an active mission
        self.pic = Picture(self.taskorg, proj)
        self.watchman = Watchman(self.pic, cfg)
        self.watch = self.watchman.watch   # the watchman is the domain's filter, called directly
        self.scan_s = float(cfg["manager"]["unknown_scan_s"])
        # told of each confirmation this EA infers itself (crossing a line of departure): a
        # peer publishes its own unit's up the chain of command (saim_mesh/authority/directives.py)
        self.inferred: list[Callable[[MissionConfirm], None]] = []
        self.next_scan = self.scan_s
        self.plan: PlanState | None = None
        self.missions: dict[str, Mission] = {}
        self.dirty_leaves: set[str] = set()
        self.dirty_tracks: set[str] = set()
        self.unit_pos: dict[str, tuple[float, float] | None] = {}
        self.unit_now: dict[str, tuple[float, float] | None] = {}
        self._reckon_until: float | None = -math.inf   # until when some member is dead-reckoned (None: not yet computed)
        self._reckon_h = 0.0
        self._unit_c: np.ndarray | None = None   # unit centroids of the last update (rows: pic.units)
        self._foreign = True
        self.assembly = Assembly()   # first entity-counting alerts wait for their group (detect/assemble.py)
        self.detectors: list[Detector] = [cls(self) for cls in DETECTORS]
        # the components the monitoring API routes to
        self.location = self._part(LocationMonitors)
        self.coordination = self._part(Coordination)
        self.schedule = self._part(ScheduleMonitors)
        self.areas = self._part(Areas)
        self.contingency = self._part(Contingencies)
        self.escape = self._part(Escapes)
        self.end_state = self._part(EndStates)
        self.coverage = self._part(Coverage)
        self.bands = self._part(Bands)
        self.ahead = self._part(ThreatsAhead)
        self.checkpoints = self._part(Checkpoints)
        self.lines = self._part(Lines)
        self.standoff = self._part(Standoffs)
        self.support = self._part(FireSupport)
        self.presence = self._part(Presence)
        self.recon = self._part(ReconProgress)
        self.tempo = self._part(Tempo)
        self.assume = self._part(Assumptions)
        self.windows = self._part(Windows)
        # fact kind -> the detectors that hear it, in DETECTORS order (a confirmed call for
        # fire warns the units near its target and meets a planned fire's window)
        self._fact_handlers: dict[type, list[Callable]] = {}
        for d in self.detectors:
            for k in d.FACTS:
                self._fact_handlers.setdefault(k, []).append(d.on_fact)
        # per-epoch hooks, bound once and only where a detector has one
        self._observers = [d.observe for d in self.detectors if type(d).observe is not Detector.observe]
        self._detectors = [d.detect for d in self.detectors if type(d).detect is not Detector.detect]
        self._reset_monitors()
        self._org_changed()

    def _part(self, cls: type[D]) -> D:
        return next(d for d in self.detectors if type(d) is cls)

    # -- wiring ----------------------------------------------------------------------
    def bind(self, ea) -> None:
        self.ea = ea
        self.timers = ea.timers
        for d in self.detectors:
            d.bind(ea)

    def _reset_monitors(self) -> None:
        for d in self.detectors:
            d.reset()
        self.auto: list[tuple[float, str]] = []
        self.areas.reindex()

    def watched_areas(self) -> set[str]:
        """Overlay areas this EA watches for hostiles (global monitors, missions, triggers)."""
        return set(self.areas.index.ids)

    def needs(self, radius_m: float):
        """What this EA must hear, for dissemination (imported here: the EA itself never needs it)."""
        from .needs import needs
        return needs(self, radius_m)

    def neighbours(self):
        """Units under neighbouring boundaries, whose positions the fratricide rule pairs with ours."""
        from .needs import neighbours
        return neighbours(self)

    def needs_before(self, msg):
        """What must be up to date before `msg` is applied (a call for fire's surroundings);
        asked of every message a peer takes: the common answer costs one type test."""
        if type(msg) is not CallForFire:
            return None
        from .needs import needs_before
        return needs_before(self, msg)

    def _org_changed(self) -> None:
        """Recompute everything that depends on the command hierarchy."""
        to = self.taskorg
        if self._unit_c is not None and not self._foreign:
            self._set_bbox()   # skipped while every entity was ours: the box it had, now that it counts
        self.own_units = set(to.subtree(self.owner))
        self.pic.rebuild(to)
        self.own_leaves = {u for u in self.pic.leaves if u in self.own_units}
        self.watchman.set_own(self.own_leaves)
        self._foreign = not all(self.watchman.own)   # some entity is not ours: the watchman's box matters
        self.leaves = self.pic.leaves
        self.leaf_i = {u: i for i, u in enumerate(self.leaves)}
        env = [u for u in sorted(self.own_units) if to.units[u].kind == "platoon"]
        self.env_units = env or [self.owner]
        self.unit_pos = {u: self.pic.centroid(u) for u in to.units}
        self.unit_now = {u: self.unit_now.get(u, self.unit_pos[u]) for u in to.units}
        self._up = {leaf: (leaf, *to.ancestors(leaf)) for leaf in self.leaves}
        self.own_rows = np.array([u in self.own_units for u in self.pic.units])
        self.leaf_xy = np.full((len(self.leaves), 2), np.nan)
        for d in self.detectors:
            d.org_changed()
        self.dirty_leaves |= set(self.leaves)

    def name(self, unit: str) -> str:
        return self.taskorg.name(unit)

    def voi(self, m: Mission, key: str) -> float:
        """A VOI threshold: the mission's override, else the EA's configuration."""
        default = self.voi_cfg[key]   # looked up first: an unknown key is an error even when overridden
        over = m.params.get("voi")     # asked for every report checked: no empty dict made per call
        return float(default if over is None else over.get(key, default))

    def in_plan(self, m: Mission) -> bool:
        if isinstance(m, ContingentMission):
            return m.params["owner"] == self.owner
        return m.unit in self.own_units

    def current_mission(self, unit: str) -> Mission:
        """The unit's active mission, or the nearest superior's; defaults otherwise."""
        if self.plan is not None:
            active = self.plan.active_by_unit()
            for u in [unit, *self.taskorg.ancestors(unit)]:
                if u in active:
                    return self.missions[active[u]]
        return self.base

    # -- plan execution (6.6.1) ------------------------------------------------------------
    def start(self, t: float) -> None:
        self.execute_plan(self.initial_plan, t)

    def execute_plan(self, name: str, t: float) -> None:
        if name not in self.plans:
            raise KeyError(f"order names unknown plan {name!r}")
        self.abort_plan(t)
        self.plan = PlanState(self.plans[name])
        self.missions = {s.id: make(s).use_defaults(self.priorities) for s in self.plans[name].missions}
        self.areas.post_plan_monitors()   # global monitors: decision points, NAIs, avenues of approach
        for m in self.missions.values():
            if self.in_plan(m):
                m.plan_constraints(self)
        self._advance_plan(t)

    def abort_plan(self, t: float) -> None:
        self.timers.clear()
        self._reset_monitors()
        self.plan = None
        self.missions = {}

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

    def _post_all_for(self, units: set[str], t: float) -> None:
        """Units newly in our subtree: monitor their ready and active missions too."""
        for mid, st in self.plan.state.items() if self.plan else ():
            m = self.missions[mid]
            if m.unit in units and st in ("ready", "active") and not isinstance(m, ContingentMission):
                m.post_execution_constraints(self)
                if st == "active":   # already running: judged from now, as at its start
                    m.check_initial_location(self, t)
                    self.windows.start(m, t)

    def on_confirm(self, c: MissionConfirm) -> None:
        if self.plan is None:
            return
        m = self.missions.get(c.mission)
        if m is None:
            raise KeyError(f"confirmation for unknown mission {c.mission!r}")
        if self.plan.state.get(m.id) == "aborted":
            return   # the commander aborted it: a late confirmation does not bring it back
        if c.phase == "start":
            if self.plan.state[m.id] == "dormant":
                self.plan.state[m.id] = "ready"
            elif self.plan.state[m.id] == "pending":   # started before its predecessors were confirmed
                self.plan.state[m.id] = "ready"         # done: monitored from now, as if it were ready
                if self.in_plan(m):
                    m.post_execution_constraints(self)
            self.plan.start(m.id, c.t)
            self.timers.occurred(("start", m.id), c.t)
            self.schedule.confirmed(m, "start", c.t)
            if self.in_plan(m):
                m.check_initial_location(self, c.t)
                self._end_by_time(m)
                self.windows.start(m, c.t)
        else:
            self.schedule.confirmed(m, "end", c.t)
            self._end(m, c.t)

    def _end(self, m: Mission, t: float) -> None:
        """Mission `m` ended (confirmed, or by its END-AT time): Check-Final-Location, then its monitors go."""
        self.plan.end(m.id, t)
        self.timers.occurred(("end", m.id), t)
        if self.in_plan(m):
            self.unit_pos[m.unit] = self.pic.centroid(m.unit)
            m.check_final_location(self, t)
        for d in self.detectors:
            d.end_mission(m.id)
        self._advance_plan(t)

    def _end_by_time(self, m: Mission) -> None:
        """A mission planned to end AT a time ends then even with no confirmation (once the
        schedule threshold has passed): it is judged where it stands."""
        end = m.spec.end
        if end.type != "END-AT" or end.t is None:
            return

        def ended(tf, mon, how):
            if self.plan is not None and self.plan.state.get(m.id) == "active" and self.missions.get(m.id) is m:
                self._end(m, tf)
            return None
        self.timers.not_later_than(("end", m.id), end.t + self.voi(m, "schedule_s"), ended, tag=m.id)

    def on_mission_order(self, o: Order) -> None:
        """A superior orders an ON-ORDER mission to start or end (only a superior may)."""
        if self.plan is None:
            return
        m = self.missions.get(o.mission)
        if m is None:
            raise KeyError(f"order for unknown mission {o.mission!r}")
        if o.issuer not in self.taskorg.ancestors(m.unit):
            raise ValueError(f"{o.issuer!r} is not a superior of {m.unit!r}: it cannot order {m.id!r}")
        self.schedule.order(m, "start" if o.action == "start-mission" else "end", o.t, o.issuer)

    def resubordinate(self, unit: str, new_parent: str, t: float) -> None:
        before = set(self.own_units)
        self.taskorg.resubordinate(unit, new_parent)
        self._org_changed()
        self._post_all_for(self.own_units - before, t)
        self.coverage.resubordinated(unit, t)

    def _auto_start(self, t: float) -> None:
        """Missions the EA executes itself (reorganizations) whose time has come."""
        while self.auto and self.auto[0][0] <= t:
            _, mid = heapq.heappop(self.auto)
            if self.plan and mid in self.missions and self.plan.state[mid] == "ready":
                self.plan.start(mid, t)
                self.timers.occurred(("start", mid), t)
                self.missions[mid].execute_mission(self, t)
                self.missions[mid].check_initial_location(self, t)
                self.plan.end(mid, t)
                self.timers.occurred(("end", mid), t)
                self._advance_plan(t)

    # -- the monitoring API that mission methods call (6.5) ----------------------------
    def post_time_constraint(self, m: Mission, phase: str, tc: TimeConstraint) -> None:
        self.schedule.post(m, phase, tc)

    def post_location_monitor(self, m: Mission, geom: str, rule: str, what: str) -> None:
        self.location.post(m, geom, rule, what)

    def check_location(self, m: Mission, geom_id: str, rule: str, t: float, what: str) -> None:
        self.location.check(m, geom_id, rule, t, what)

    def post_corridor(self, m: Mission, target: str) -> None:
        self.location.post_corridor(m, target)

    def start_location_constraints(self, m: Mission, t: float) -> None:
        self.location.start(m, t)

    def post_penetration(self, m: Mission, area: str) -> None:
        self.areas.post_red_monitor(m, area, expected=False, kind="penetration")

    def post_escape(self, m: Mission, area: str, until: float | None = None) -> None:
        self.escape.post(m, area, until)

    def check_end_state(self, m: Mission, area: str, t: float) -> None:
        self.end_state.check(m, area, t)

    def check_coverage(self, m: Mission, position: str, engagement_area: str, t: float) -> None:
        self.coverage.check(m, position, engagement_area, t)

    def post_held(self, m: Mission, position: str) -> None:
        self.coverage.post_held(m, position)

    def post_band(self, m: Mission, other: str, lo: float, hi: float, since: float | None = None,
                  behind: str | None = None) -> None:
        self.bands.post(m, other, lo, hi, since, behind)

    def check_joined(self, m: Mission, unit: str, other: str, within_m: float, when: float) -> None:
        self.bands.check_once(m, unit, other, within_m, when)

    def post_line(self, m: Mission, line: str, what: str, when: float | None = None,
                  toward: str | None = None) -> None:
        self.lines.post(m, line, what, when, toward)

    def start_by_crossing(self, m: Mission, t: float) -> None:
        """The unit crossed its line of departure: for the EA its mission has started (a local
        confirmation), unless a confirmation said so already."""
        if self.plan is not None and self.plan.state.get(m.id) == "ready":
            c = MissionConfirm(t, m.id, m.unit, "start", "local")
            self.on_confirm(c)
            for tell in self.inferred:
                tell(c)

    def post_fire_support(self, m: Mission, supported: str, line: str | None, target: str) -> None:
        self.support.post(m, supported, line, target)

    def post_presence(self, m: Mission, partner: str, point: str, lane: str | None = None) -> None:
        self.presence.post(m, partner, point, lane)

    def post_standoff(self, m: Mission, bypassed: str | None = None) -> None:
        self.standoff.post(m, bypassed)

    def post_checkpoints(self, m: Mission, table: list[dict]) -> None:
        self.checkpoints.post(m, table)

    def post_recon(self, m: Mission, area: str, by: float | None, progress: str = "coverage") -> None:
        self.recon.post(m, area, by, progress)

    def post_deadline(self, m: Mission, when: float, geom_id: str, rule: str) -> None:
        """Its unit at `geom_id` (by `rule`) by `when`, judged then if the mission still runs
        (a seizure's time: its end is judged by Check-Final-Location)."""
        def due(tf, mon, how):
            if self.plan is not None and self.plan.state.get(m.id) == "active" and self.missions.get(m.id) is m \
                    and self.in_plan(m):
                self.unit_pos[m.unit] = self.pic.centroid(m.unit)
                self.location.check(m, geom_id, rule, tf, "by")
            return None
        self.timers.not_later_than(("deadline", m.id, geom_id), when, due, tag=m.id)

    def post_suppression(self, m: Mission, target: str, t0: float, t1: float) -> None:
        self.support.post_window(m, target, t0, t1)

    def post_tempo(self, m: Mission, avenue: str, by: float, tempo_mps: float) -> None:
        self.tempo.post(m, avenue, by, tempo_mps)

    def post_assume(self, m: Mission, supported: str, halt_s: float) -> None:
        self.assume.post(m, supported, halt_s)

    def start_recon(self, m: Mission) -> None:
        self.recon.start(m)

    def check_recon(self, m: Mission, t: float) -> None:
        self.recon.check_final(m, t)

    def threat_ahead(self, m: Mission, t: float, tracks: list[str], strength: int, options: list[str],
                     recommended: str) -> None:
        self.ea.post(self.ahead.candidate(m, t, tracks, strength, options, recommended))

    def branches_for(self, m: Mission) -> list[str]:
        return branches_for(self, m)

    def strength_of(self, unit: str) -> int:
        """Friendly strength: the unit's members with a known position."""
        xy = self.pic.xy[self.pic.members[unit]]
        return int((~np.isnan(xy[:, 0])).sum())

    # -- decisions the commander takes on an alert that asked for one --------------------
    def decide(self, details: dict, option: str, t: float) -> str:
        """Carry out `option` of a decision alert (its `details`): abort the mission, execute
        a branch, or continue. Returns what was done; ValueError if it cannot be."""
        d = details.get("decision")
        if not d or option not in d.get("options", ()):
            raise ValueError(f"decide: {option!r} is not an option of this alert "
                             f"({', '.join(d['options']) if d else 'it asks for no decision'})")
        mid = details.get("mission")
        if self.plan is None or mid not in self.missions:
            raise ValueError(f"decide: mission {mid!r} is no longer in the plan")
        if option == "continue":
            return f"{mid} continues"
        if self.plan.state.get(mid) != "active":
            raise ValueError(f"decide: mission {mid!r} is not running ({self.plan.state.get(mid)})")
        if option == "abort":
            self._abort(mid)
            return f"{mid} aborted"
        branch = option.split(":", 1)[1]
        c = self.contingency.pending.get(branch)
        if c is None:
            raise ValueError(f"decide: branch {branch!r} is not waiting to be executed")
        del self.contingency.pending[branch]
        self._abort(mid)   # the branch replaces the course of action the alert was about
        self.contingency.execute(c, t)
        self.areas.reindex()
        return f"{mid} aborted, {branch} executed"

    def _abort(self, mid: str) -> None:
        self.plan.state[mid] = "aborted"   # not done: what follows it waits for new orders
        self.timers.cancel(mid)
        for det in self.detectors:
            det.end_mission(mid)

    def post_red_monitor(self, m: Mission, area: str, expected: bool, expect_by: float | None = None) -> None:
        self.areas.post_red_monitor(m, area, expected, expect_by)

    def monitored_candidate(self, m: Mission | None, area: str, t: float, tracks: list[str], strength: int,
                            expected: bool, kind: str = "monitored") -> None:
        self.areas.monitored_candidate(m, area, t, tracks, strength, expected, kind)

    def post_coordination(self, m: Mission, partner: str, point: str, at: float, fuzz: float) -> None:
        self.coordination.post(m, partner, point, at, fuzz)

    def post_contingency(self, m: ContingentMission) -> None:
        self.contingency.post(m)

    def evaluate_trigger(self, tr: dict) -> bool:
        return self.contingency.evaluate_trigger(tr)

    # -- watchman and facts ----------------------------------------------------------------
    def busy(self) -> bool:
        return bool(self.dirty_leaves or self.dirty_tracks or self.watchman.quiet or self.pic.adj.moving())

    def next_wakeup(self) -> float:
        return min(self.next_scan, self.auto[0][0] if self.auto else math.inf, self.assembly.next_due())

    def apply(self, facts: list) -> None:
        locs = [f for f in facts if type(f) is LocationReport]
        if len(locs) == len(facts):   # the usual batch: location reports only
            self.dirty_leaves |= self.pic.apply_locations(locs)
            return
        run: list = []   # reports (locations, tracks) since the last other fact
        for f in facts:
            k = type(f)
            if k is LocationReport or k is SensorTrack:
                run.append(f)
                continue
            self._apply_reports(run)   # a confirmation or a call for fire reads the picture:
            run = []                   # the reports before it, and none after (batches differ per peer)
            try:
                self._apply_one(f)
            except (KeyError, ValueError) as e:   # bad order/confirmation: counted, the rest goes on
                self.ea.error(f"{type(f).__name__} at t={f.t}: {e}")
        self._apply_reports(run)

    def _apply_reports(self, reports: list) -> None:
        """Location reports and tracks (independent parts of the picture), each kind in one call."""
        if not reports:
            return
        locs = [f for f in reports if type(f) is LocationReport]
        if locs:
            self.dirty_leaves |= self.pic.apply_locations(locs)
        if len(locs) < len(reports):
            self.dirty_tracks |= self.pic.apply_tracks([f for f in reports if type(f) is SensorTrack])

    def _apply_one(self, f) -> None:
        k = type(f)
        if k is MissionConfirm:
            self.on_confirm(f)
        elif k is Order:
            if f.action == "execute-plan":
                self.execute_plan(f.plan, f.t)
            elif f.action == "abort-plan":
                self.abort_plan(f.t)
            else:
                self.on_mission_order(f)
        elif k is Reorganization:
            self.resubordinate(f.unit, f.new_parent, f.t)
        elif (handles := self._fact_handlers.get(k)) is not None:
            for handle in handles:
                handle(f)

    def flush_quiet(self) -> None:
        """Bring the picture fully up to date with reports the watchman held back."""
        if self.watchman.quiet:
            self._reckoning_until()   # fixed before these reports change the velocities
            self.pic.apply_locations(self.watchman.quiet)
            self.watchman.quiet = []

    # -- detection at the end of each epoch ------------------------------------------
    def detect(self, t: float) -> list[Candidate]:
        self.flush_quiet()
        self.dirty_tracks |= self.pic.advance_tracks(t)
        dirty_units: set[str] = set()
        if self.dirty_leaves:
            up = self._up
            dirty_units = dirty_units.union(*[up[leaf] for leaf in self.dirty_leaves])
            self._update_positions(t)
        elif self.dirty_tracks or t >= self.next_scan or t <= self._reckoning_until():
            # members still dead-reckoned (their estimate moves on), or detectors will look
            # (a track changed, the periodic scan): they read where units are now, not where
            # they were at the last epoch this EA happened to close (an in-process EA closes
            # more epochs than a peer, which hears fewer messages)
            self._update_positions(t)
        ch = Changes(self.dirty_leaves, dirty_units, self.dirty_tracks, t >= self.next_scan)
        cands: list[Candidate] = []
        for observe in self._observers:
            observe(t, ch)
        for detect in self._detectors:
            detect(t, ch, cands)
        cands += self.assembly.due(t)   # after the detectors: a group's last offer counts
        if ch.rescan:
            self.next_scan = (math.floor(t / self.scan_s) + 1) * self.scan_s
        self._auto_start(t)
        self.dirty_leaves = set()
        self.dirty_tracks = set()
        return cands

    def _update_positions(self, t: float) -> None:
        """Leaf and unit centroids after movement, and the watchman's area of interest;
        `unit_now`: the centroids of members dead-reckoned to now (threat envelopes: a
        report up to a minute old puts a moving unit hundreds of metres off)."""
        horizon = float(self.voi_cfg["dead_reckon_s"])
        pic = self.pic
        leaf_c, unit_c = pic.positions(t, horizon)
        self.leaf_xy = leaf_c
        units = pic.units
        xs, ys, rxs, rys = unit_c.T.tolist()
        if (s := sum(xs) + sum(rxs)) == s:   # no NaN: every unit known (the usual case), built in C
            self.unit_pos = dict(zip(units, zip(xs, ys)))
            self.unit_now = dict(zip(units, zip(rxs, rys)))
        else:
            self.unit_pos = _by_unit(units, xs, ys)
            self.unit_now = _by_unit(units, rxs, rys)
        # when dead reckoning stops moving anyone: asked only on an epoch without reports
        self._reckon_until = None
        self._reckon_h = horizon
        self._unit_c = unit_c[:, :2]
        if self._foreign:   # the area of interest only filters entities not our own
            self._set_bbox()

    def _reckoning_until(self) -> float:
        """Scenario time until which some member is dead-reckoned, as of the last
        `_update_positions` (computed when first asked; the picture's velocities have
        not changed since: see `flush_quiet`)."""
        if self._reckon_until is None:
            pic = self.pic
            vel = pic.vel
            moving = (vel[:, 0] != 0.0) | (vel[:, 1] != 0.0)
            self._reckon_until = float(np.max(pic.moved_t, where=moving, initial=-math.inf)) + self._reckon_h
        return self._reckon_until

    def _set_bbox(self) -> None:
        """The watchman's area of interest around our units' centroids of the last update."""
        own = self._unit_c[self.own_rows]
        self.watchman.set_bbox(own[~np.isnan(own[:, 0])])

    # -- VOA heuristics: merging and rendering ------------------------------------------
    def merge(self, key, cands: list[Candidate]) -> Candidate:
        return render.merge(key, cands, self.name)

    def to_alert(self, c: Candidate) -> Alert:
        return render.to_alert(c, self.owner, CATEGORY)


def _by_unit(units: list[str], xs: list[float], ys: list[float]) -> dict[str, tuple[float, float] | None]:
    """Unit -> (x, y), None where unknown (NaN)."""
    return dict(zip(units, [None if x != x else (x, y) for x, y in zip(xs, ys)]))

