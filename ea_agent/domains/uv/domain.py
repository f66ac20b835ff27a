"""The UV robot-team domain: executes each robot's recipes (a partial order of
tasks) with the core PlanState, offers the monitoring API the mission methods post
to, and runs the detectors and policies once per epoch on scenario time.

Robots have no human confirming starts and ends, so the EA advances the recipes
itself: a ready task starts at its start time (ASAP: at once), a goto ends at
at-goal, other tasks at an END-AT time or a `uv-agent` success/failure.
"""
from __future__ import annotations

import heapq
import math

from ea_agent.core.alert import Alert, Candidate
from ea_agent.core.geo import Projection
from ea_agent.core.needs import Needs
from ea_agent.core.plan import MissionSpec, PlanSpec, PlanState, TaskOrg, TimeConstraint
from ea_agent.core.schedule import Schedule

from . import detectors
from . import render
from .detectors.collision import Obstacles
from .messages import UvAgent, UvSighting, UvState
from .missions import REGISTRY, Mission
from .policies import Policies
from .watchman import NEG, Watchman

CATEGORY, ALERT_TYPES = render.CATEGORY, render.ALERT_TYPES
AUDIENCES = ("controller", "human")
LIVE = ("active", "ready", "suspended")


class UvDomain:
    PLACED_BY_EVERY_SOURCE = True   # each robot's radio sends its own states and sightings

    def __init__(self, owner: str, taskorg: TaskOrg, plans: dict[str, PlanSpec], initial_plan: str,
                 world: dict, proj: Projection, cfg: dict):
        if owner not in taskorg.units:
            raise KeyError(f"unknown unit {owner!r}: not in the task organization")
        self.owner, self.taskorg, self.plans, self.initial_plan = owner, taskorg.copy(), plans, initial_plan
        self.world, self.proj, self.cfg = world, proj, cfg
        self.uv = cfg["uv"]
        self.audience = str(self.uv["audience"])
        if self.audience not in AUDIENCES:
            raise ValueError(f"[uv] audience {self.audience!r} not one of {', '.join(AUDIENCES)}")
        self.human = self.audience == "human"
        reacquire = float(self.uv["lost_human_s" if self.human else "lost_s"])
        self.watchman = Watchman(owner, self.taskorg, proj, reacquire, self.human)
        self.watch = self.watchman.watch   # the manager calls the watchman directly (hot path)
        self.robots = self.watchman.robots
        self.robot_ids = sorted(self.robots)
        self.mine = {r for r in self.robot_ids if self.taskorg.is_under(r, owner)}
        self.mine_sorted = sorted(self.mine)
        radius = float(self.uv["goal_radius_m"])
        self.goals = {p.id: (p.geom.centroid.x, p.geom.centroid.y, float(p.props.get("radius_m", radius)))
                      for p in world.values() if p.kind in ("waypoint", "base")}
        self.obstacles = Obstacles(world)
        self.policies = Policies(self)
        self.prio: dict[str, str] = dict(self.uv["priority"])
        self.latency: dict[str, float] = {k: float(v) for k, v in self.uv["latency_s"].items()}
        self.t0 = self.now = 0.0
        self.plan: PlanState | None = None
        self.missions: dict[str, Mission] = {}
        self.handoffs: dict[tuple[str, str, str], tuple[int, float]] = {}   # open handoff stories -> (n, last t)
        self.handoff_n = 0                          # handoff stories begun (their VOA keys never repeat)
        self._reset()

    def _reset(self) -> None:
        self.goal_missions: dict[str, tuple[Mission, str]] = {}
        self.target_missions: dict[str, tuple[Mission, str]] = {}
        self.photo_every: dict[str, float] = {}
        self.photos: dict[str, list] = {}          # mid -> [mission, k, due]
        self.auto: list[tuple[float, str]] = []    # (start time, mission) of ready tasks
        self.ends: list[tuple[float, str]] = []    # (END-AT time, mission)
        self.delegations: dict[tuple[str, str, str], UvAgent] = {}
        self.reported: dict[str, tuple[float, str]] = {}   # mid -> (t, act): success/failure heard, ended in detect
        self.since: dict = {}                      # latency: key -> first epoch the condition held
        self.posted_here: list[Candidate] = []

    # -- wiring ------------------------------------------------------------------------
    def bind(self, ea) -> None:
        self.ea = ea
        self.timers = ea.timers
        self.schedule = Schedule(ea.timers, ea.post, self.name, self.in_plan,
                                 lambda m: float(m.params.get("voi", {}).get("schedule_s", self.uv["schedule_s"])),
                                 self.uv["schedule_repeat_s"])

    def name(self, unit: str) -> str:
        return self.taskorg.name(unit)

    def in_plan(self, m: Mission) -> bool:
        return m.unit in self.mine

    def cand(self, t: float, typ: str, m: Mission | None, subjects: tuple, text: str, key, measure,
             details: dict, friendly: bool = True) -> Candidate:
        prio = (m.PRIORITY.get(typ) if m is not None else None) or self.prio.get(typ) or \
            Mission.DEFAULT_PRIORITY.get(typ, "priority")
        return Candidate(t, typ, prio, tuple(subjects), text, key=key, measure=measure, details=details,
                         friendly=friendly)

    # -- plan execution ----------------------------------------------------------------
    def start(self, t: float) -> None:
        self.t0 = self.now = t
        self.execute_plan(self.initial_plan, t)

    def execute_plan(self, name: str, t: float) -> None:
        if name not in self.plans:
            raise KeyError(f"unknown plan {name!r}")
        self.timers.clear()
        self._reset()
        spec = self.plans[name]
        self.plan = PlanState(PlanSpec(spec.name, list(spec.missions)))   # our copy: policies add tasks
        self.missions = {s.id: REGISTRY.make(s) for s in spec.missions}
        self.advance_plan(t)

    def advance_plan(self, t: float) -> None:
        for spec in self.plan.newly_ready():
            m = self.missions[spec.id]
            if self.in_plan(m):
                m.post_execution_constraints(self)
            tc = spec.start
            if tc.type == "ON-ORDER":
                continue   # waits for a uv-agent delegate naming it
            at = tc.t if tc.t is not None and tc.type in ("START-AT", "START-NET") else t
            heapq.heappush(self.auto, (max(at, t), m.id))

    def add_mission(self, spec: MissionSpec, t: float) -> Mission:
        """A task created at run time by a policy, active at once."""
        m = REGISTRY.make(spec)
        self.missions[m.id] = m
        self.plan.plan.missions.append(spec)
        self.plan.by_id[m.id] = spec
        self.plan.state[m.id] = "ready"
        if self.in_plan(m):
            m.post_execution_constraints(self)
        self.start_mission(m, t)
        return m

    def start_mission(self, m: Mission, t: float) -> None:
        self.plan.start(m.id, t)
        self.timers.occurred(("start", m.id), t)
        r = self.robots.get(m.unit)
        if r is not None and r.t != NEG:   # the stuck clock starts with the task
            r.anchor_t, r.anchor_x, r.anchor_y, r.anchor_h = max(r.anchor_t, t), r.x, r.y, r.heading
        if m.id in self.photo_every:
            self._arm_photo(m, 1, t + self.photo_every[m.id])
        tc = m.spec.end
        if tc.type == "END-AT" and tc.t is not None and m.TYPE != "goto":
            heapq.heappush(self.ends, (max(tc.t, t), m.id))
        if self.in_plan(m):
            m.check_initial_location(self, t)
            m.execute_mission(self, t)

    def end_mission(self, m: Mission, t: float, advance: bool = True) -> None:
        if self.plan is None or self.plan.state.get(m.id) == "done":
            return
        self.plan.end(m.id, t)
        self.timers.occurred(("end", m.id), t)
        if self.in_plan(m):
            m.check_final_location(self, t)
        for d in (self.goal_missions, self.target_missions, self.photos):
            d.pop(m.id, None)
        self.timers.cancel(m.id)
        if advance:
            self.advance_plan(t)

    def active(self, mid: str) -> bool:
        return self.plan is not None and self.plan.state.get(mid) == "active"

    def active_of(self, robot: str) -> list[Mission]:
        return [self.missions[s.id] for s in self.plan.active() if s.unit == robot] if self.plan else []

    def missions_of(self, robot: str) -> list[Mission]:
        """The robot's tasks not yet done (its current recipe)."""
        if self.plan is None:
            return []
        return [self.missions[s.id] for s in self.plan.plan.missions
                if s.unit == robot and self.plan.state[s.id] in LIVE]

    def moving_tasks(self) -> dict[str, Mission]:
        out: dict[str, Mission] = {}
        for s in self.plan.active() if self.plan else ():
            m = self.missions[s.id]
            if m.MOVING and m.unit in self.mine and m.unit not in out:
                out[m.unit] = m
        return out

    def started_at(self, m: Mission) -> float:
        return self.plan.started.get(m.id, self.t0) if self.plan else self.t0

    def sector_of(self, task: str, owner: str) -> str | None:
        """The sector of a handed-over task: its own if we know the task (a teammate's
        run-time pursuit we may not), else that of the task owner's patrol."""
        m = self.missions.get(task)
        if m is not None and m.params.get("sector"):
            return m.params["sector"]
        return self.patrol_sector(owner)

    def patrol_sector(self, robot: str) -> str | None:
        """Where `robot` may pursue: its live patrol's sector (else its area)."""
        for p in self.missions_of(robot):
            if p.TYPE == "patrol":
                return p.params.get("sector") or p.params.get("area")
        return None

    # -- the monitoring API mission methods call -----------------------------------------
    def post_time_constraint(self, m: Mission, phase: str, tc: TimeConstraint) -> None:
        self.schedule.post(m, phase, tc)

    def watch_progress(self, m: Mission) -> None:
        """Stuck applies to every active moving task (see `moving_tasks`)."""

    def watch_goal(self, m: Mission, place: str) -> None:
        if place not in self.goals:
            raise KeyError(f"{m.id}: waypoint {place!r} is not a waypoint of the world")
        self.goal_missions[m.id] = (m, place)

    def watch_target(self, m: Mission, target: str) -> None:
        self.target_missions[m.id] = (m, target)

    def post_photo_schedule(self, m: Mission, every_s: float) -> None:
        self.photo_every[m.id] = max(1.0, every_s)

    def check_at_goal(self, m: Mission, place: str, t: float) -> None:
        """A goto ends only at at-goal, so nothing is left to check."""

    def commit_pursuit(self, m: Mission, target: str, sector: str | None, t: float) -> None:
        self.policies.commit_pursuit(m, m.unit, target, sector, t)

    def drop_pursuit(self, m: Mission, t: float) -> None:
        self.policies.drop_pursuit(m, t)

    def _arm_photo(self, m: Mission, k: int, due: float) -> None:
        fuzz = float(self.uv["photo_window_s"])
        self.photos[m.id] = [m, k, due]

        def missed(tf, mon, how):
            if self.active(m.id) and self.in_plan(m):
                self.ea.post(self.cand(tf, "schedule", m, (m.unit, m.params["target"]),
                                       f"{self.name(m.unit)} missed photo {k} of {m.params['target']} "
                                       f"(due at {due:.0f} s)", ("schedule", m.id, "photo"), float(k),
                                       {"mission": m.id, "photo": k, "due_t": due, "how": how}))
                self._arm_photo(m, k + 1, due + self.photo_every[m.id])
            return None
        self.timers.near_time(("photo", m.id, k), due, fuzz, missed, tag=m.id)

    def _photos(self, t: float) -> None:
        fuzz = float(self.uv["photo_window_s"])
        for mid, (m, k, due) in list(self.photos.items()):
            obs = "*" if self.human else m.unit
            seen = self.watchman.seen.get((obs, m.params["target"]), NEG)
            if self.active(mid) and due - fuzz <= seen:
                self.timers.occurred(("photo", mid, k), seen)
                self._arm_photo(m, k + 1, due + self.photo_every[mid])

    # -- facts and detection -----------------------------------------------------------------
    def busy(self) -> bool:
        w = self.watchman
        return bool(w.dirty or w.dirty_targets or w.acquired or self.posted_here or self.since or self.reported)

    def next_wakeup(self) -> float:
        nxt = detectors.status.wakeup(self, self.now)
        for q in (self.auto, self.ends):
            if q:
                nxt = min(nxt, q[0][0])
        lost = float(self.uv["lost_s"])
        for m, target in detectors.targets._pursuits(self):
            last = detectors.targets.last_seen(self, m, target)
            nxt = min(nxt, last + lost if last + lost > self.now else self.now + lost)
        return nxt

    def apply(self, facts: list) -> None:
        for f in facts:
            try:
                if type(f) is UvAgent:
                    detectors.handoff.on_agent(self, f, self.posted_here)
            except (KeyError, ValueError) as e:   # a bad agent message is counted, the rest goes on
                self.ea.error(f"{type(f).__name__} at t={f.t}: {e}")

    def _due(self, t: float) -> None:
        """Start ready tasks whose time came; end tasks at their END-AT time."""
        while self.auto and self.auto[0][0] <= t:
            at, mid = heapq.heappop(self.auto)
            if self.plan and self.plan.state.get(mid) == "ready":
                self.start_mission(self.missions[mid], at)
        while self.ends and self.ends[0][0] <= t:
            at, mid = heapq.heappop(self.ends)
            if self.active(mid):
                self.end_mission(self.missions[mid], at)

    def detect(self, t: float) -> list[Candidate]:
        self.now = t
        cands, self.posted_here = self.posted_here, []
        if self.plan is not None:
            self._due(t)
            detectors.progress.track(self, t)
            detectors.progress.at_goal(self, t, cands)
            self._due(t)   # successors of reached goals start in the same epoch
            detectors.progress.divergent(self, t, cands)
            detectors.progress.stuck(self, t, cands)
            detectors.targets.target_visible(self, t, cands)
            detectors.targets.lost_target(self, t, cands)
            detectors.targets.target_gone(self, t, cands)
            self.policies.step(t, cands)
            self._end_reported()
            self._photos(t)
            self._due(t)
        detectors.status.no_status(self, t, cands)
        detectors.collision.collisions(self, t, cands)
        self.watchman.dirty = set()
        self.watchman.dirty_targets = set()
        return self._gate(t, cands)

    def report_end(self, m: Mission, t: float, act: str) -> None:
        """A robot reported its task done (`uv-agent` success/failure). The report comes
        with (often just before) the state and sightings that show why, so the task ends
        after this epoch's detectors judged them: at-goal of a goto that reports success
        on arrival, target-gone of a pursuit that fails because the target left."""
        self.reported[m.id] = (t, act)

    def _end_reported(self) -> None:
        reported, self.reported = self.reported, {}
        for mid, (tf, _) in sorted(reported.items(), key=lambda kv: (kv[1][0], kv[0])):
            if self.plan is not None and self.plan.state.get(mid) in LIVE:
                self.end_mission(self.missions[mid], tf)

    def _gate(self, t: float, cands: list[Candidate]) -> list[Candidate]:
        """Per-type latency: a persistent condition must hold this long before it is proposed."""
        out, held = [], set()
        for c in cands:
            lat = self.latency.get(c.type, 0.0)
            if lat <= 0:
                out.append(c)
                continue
            held.add(c.key)
            if t - self.since.setdefault(c.key, t) >= lat:
                out.append(c)
        self.since = {k: v for k, v in self.since.items() if k in held}
        return out

    def merge(self, key, cands: list[Candidate]) -> Candidate:
        return render.merge(key, cands)

    def to_alert(self, c: Candidate) -> Alert:
        return render.to_alert(c, self.owner, self.audience)

    # -- what this EA must hear (for the mesh) --------------------------------------------
    def needs(self, radius_m: float) -> Needs:
        """Exactly a superset of what the watchman accepts, so an EA fed by its mesh
        subscriptions alerts as one fed everything. The TEAM hears every robot and every
        agent message. A robot's EA: its own states and sightings, the agent messages it
        sends or receives, and states and sightings placed within `comm_range_m` of it,
        widened by how far it can move before the next re-registration
        (`max_speed_mps x [dissemination] reregister_s`) and, for sightings, by the
        teammates' sensor range (a sighting lies that far from its sender). Before its
        own first state it hears everything (as the watchman does). `radius_m`, the
        dissemination layer's geographic interest, is not used: comm range decides."""
        templates = (UvState.KEY, UvSighting.KEY, UvAgent.KEY)
        me = self.robots.get(self.owner)
        if me is None:   # the operator's EA hears every robot
            return Needs(templates, {"to": frozenset({self.owner})}, whole=("st", "sgt", "agm"))
        mine = frozenset({self.owner})
        by = {"robot": mine, "to": mine, "sender": mine}
        if me.t == NEG or not math.isfinite(me.comm_range):
            return Needs(templates, by, whole=("st", "sgt"))
        rereg = float(self.cfg.get("dissemination", {}).get("reregister_s", 0.0))
        sensor = max((r.sensor_range for r in self.robots.values()), default=0.0)
        rad = me.comm_range + me.max_speed * rereg + sensor
        return Needs(templates, by, circles=((float(me.x), float(me.y), rad),))
