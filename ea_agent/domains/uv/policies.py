"""Autonomous reactions (paper 7.4), decided by the EA on scenario time and carried out by
the robot: a robot's own EA publishes each decision about its robot as a task message
(`tasks.py`) that the robot's controller obeys; the robot holds no copy of these rules.
Every EA runs them for the robots it monitors (the operator's for all), on the robot's
OWN sightings and its plan state only, so the operator's EA reaches the decisions the
robot's EA took from the same reports.

Once per epoch (`step`, after the detectors):
- a pursuit whose robot saw its target outside the pursuit's sector this epoch is
  dropped and handed to a teammate whose patrol sector (else area) holds the target
  (a `handoff` candidate; tasks Handoff, Drop, Resume);
- a pursuit whose robot has not seen its target for `drop_s` is dropped and the patrol
  resumed (tasks Drop, Resume);
- a robot patrolling (patrol active, not suspended) that sees a target inside its patrol's
  sector commits to pursue it (task Pursue), unless it dropped that target less than
  `COOLDOWN_S` ago.
A delegation to us (agent `delegate`) is accepted when our patrol is active (task Accept);
an accept heard moves the pursuit from the delegating robot to the accepting one.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import shapely

from ea_agent.core.plan import MissionSpec

from . import tasks as task_messages
from .detectors.handoff import story_key

if TYPE_CHECKING:
    from .domain import UvDomain
    from .missions import Mission

COOLDOWN_S = 60.0     # no new pursuit of a target the robot dropped less than this ago


class Policies:
    def __init__(self, dom: "UvDomain"):
        self.dom = dom
        self.resume: dict[str, str] = {}   # pursue mission id -> suspended patrol id
        self.n = 0
        self.cooldown: dict[tuple[str, str], float] = {}   # (robot, target) -> no pursuit before
        self.outbox: list[task_messages._Task] = []    # tasks for our own robot (a robot's EA), drained by the loop
        self.task_n = 0

    # -- tasks ---------------------------------------------------------------------------
    def _epoch_of(self, t: float) -> float:
        """The end of the epoch a decision at `t` is taken in ((end - ep, end])."""
        ep = self.dom.ea.epoch_s
        return max(ep, math.ceil(round(t / ep, 9)) * ep)

    def _task(self, cls, robot: str, t: float, **fields) -> None:
        """A decision about `robot`: a task for its controller when we are its EA."""
        if robot != self.dom.owner:
            return
        self.task_n += 1
        self.outbox.append(cls(robot=robot, at=round(self._epoch_of(t) + task_messages.LAG_S, 6), n=self.task_n, **fields))

    def drain(self) -> list:
        out, self.outbox = self.outbox, []
        return out

    def _where(self, robot: str, target: str) -> dict:
        """Where the target was last seen (a sighting we heard), for the controller to relocate it."""
        own = self.dom.watchman.own.get((robot, target))
        tg = self.dom.watchman.targets.get(target)
        if own is not None and (tg is None or own[0] >= tg.t):
            return {"lon": own[3], "lat": own[4]}
        if tg is not None and tg.t != -math.inf:
            lon, lat = self.dom.proj.to_lonlat(tg.x, tg.y)
            return {"lon": round(float(lon), 7), "lat": round(float(lat), 7)}
        return {}

    # -- plan changes ------------------------------------------------------------------------
    def pursuing(self, robot: str, target: str | None = None) -> "Mission | None":
        for m in self.dom.active_of(robot):
            if m.TYPE == "pursue" and (target is None or m.params.get("target") == target):
                return m
        return None

    def commit_pursuit(self, patrol: "Mission | None", robot: str, target: str, sector: str | None,
                       t: float, kind: type = task_messages.Pursue, **extra) -> None:
        """`robot` pursues `target` (inside `sector`), suspending `patrol` if given."""
        dom = self.dom
        if robot not in dom.mine or self.pursuing(robot, target) is not None:
            return
        self.n += 1
        base = patrol.id if patrol is not None else robot
        spec = MissionSpec(f"{base}-pursue-{target}-{self.n}", robot, "pursue",
                           params={"target": target, "sector": sector})
        m = dom.add_mission(spec, t)
        if patrol is not None:
            dom.plan.state[patrol.id] = "suspended"
            self.resume[m.id] = patrol.id
        self._task(kind, robot, t, target=target, sector=sector, mission=m.id, **extra,
                   **self._where(robot, target))

    def drop_pursuit(self, m: "Mission", t: float, why: str = "lost") -> None:
        dom = self.dom
        if dom.plan is None or dom.plan.state.get(m.id) != "active":
            return
        target = m.params.get("target")
        dom.end_mission(m, t, advance=False)
        self.cooldown[(m.unit, target)] = t + COOLDOWN_S
        self._task(task_messages.Drop, m.unit, t, target=target, why=why, mission=m.id)
        patrol = self.resume.pop(m.id, None)
        if patrol is not None and dom.plan.state.get(patrol) == "suspended":
            dom.plan.state[patrol] = "active"
            self._task(task_messages.Resume, m.unit, t, mission=patrol)
        dom.advance_plan(t)

    def take_over(self, robot: str, target: str, sector: str | None, t: float, kind: type = task_messages.Pursue,
                  **extra) -> None:
        """`robot` takes a pursuit from a teammate, suspending its own patrol if any."""
        patrol = self._patrol(robot)
        if sector is None and patrol is not None:
            sector = patrol.params.get("sector") or patrol.params.get("area")
        self.commit_pursuit(patrol, robot, target, sector, t, kind, **extra)

    def _patrol(self, robot: str) -> "Mission | None":
        return next((m for m in self.dom.active_of(robot) if m.TYPE == "patrol"), None)

    def accepts(self, robot: str) -> bool:
        """Whether `robot` takes a delegated pursuit: it is patrolling (not pursuing)."""
        return self._patrol(robot) is not None and self.pursuing(robot) is None

    def transfer(self, frm: str, to: str, target: str | None, sector: str | None, task: str, t: float) -> None:
        dom = self.dom
        old = self.pursuing(frm, target) if target else None
        if old is None and task in dom.missions and dom.active(task):
            old = dom.missions[task]
        if old is not None and old.unit == frm:
            self.drop_pursuit(old, t, "handoff")
        if target and to in dom.mine:
            self.take_over(to, target, sector, t)

    # -- the decisions, once per epoch ---------------------------------------------------------
    def step(self, t: float, cands: list) -> None:
        dom = self.dom
        if dom.plan is None:
            return
        own = dom.watchman.own
        if not own and not any(m.TYPE == "pursue" for m, _ in dom.target_missions.values()):
            return   # no sighting yet and no pursuit: nothing to decide (the hot path of a quiet team)
        fresh = t - dom.ea.epoch_s
        targets = sorted({k[1] for k in own})
        active: dict[str, list] = {}   # one pass over the plan, not one per robot
        for spec in dom.plan.active():
            if spec.unit in dom.mine:
                active.setdefault(spec.unit, []).append(dom.missions[spec.id])
        for robot in sorted(active):
            ms = active[robot]
            m = next((x for x in ms if x.TYPE == "pursue"), None)
            if m is not None:
                self._pursuit(m, t, fresh, cands)
                continue
            patrol = next((x for x in ms if x.TYPE == "patrol"), None)
            if patrol is None or not targets:
                continue
            sector = patrol.params.get("sector") or patrol.params.get("area")
            if sector not in dom.world:
                continue
            for target in targets:
                seen = own.get((robot, target))
                if seen is None or seen[0] <= fresh or t < self.cooldown.get((robot, target), -math.inf):
                    continue
                if shapely.contains_xy(dom.world[sector].geom, seen[1], seen[2]):
                    self.commit_pursuit(patrol, robot, target, sector, seen[0])
                    break

    def _pursuit(self, m: "Mission", t: float, fresh: float, cands: list) -> None:
        dom = self.dom
        target, sector = m.params.get("target"), m.params.get("sector")
        start = dom.started_at(m)
        seen = dom.watchman.own.get((m.unit, target))
        last = max(seen[0], start) if seen is not None else start
        if seen is not None and seen[0] > fresh and seen[0] >= start and sector in dom.world and \
                not shapely.contains_xy(dom.world[sector].geom, seen[1], seen[2]):
            self.target_gone(m, target, t, cands, seen)
        elif t - last >= float(dom.uv["drop_s"]):
            self.drop_pursuit(m, t, "lost")

    def target_gone(self, m: "Mission", target: str, t: float, cands: list, seen: tuple) -> None:
        """Hand the pursuit to a teammate whose patrol holds the target, and drop it."""
        dom = self.dom
        to = self._teammate(m.unit, seen[1], seen[2])
        if to is not None:
            rid, area = to
            cands.append(dom.cand(t, "handoff", m, (m.unit, rid, target),
                                  f"{dom.name(m.unit)} hands pursuit of {target} to {dom.name(rid)} "
                                  f"(target entered {area})", story_key(dom, m.unit, rid, target, t), None,
                                  {"from": m.unit, "to": rid, "task": m.id, "target": target,
                                   "act": "policy", "places": [area]}))
            self._task(task_messages.Handoff, m.unit, t, target=target, to=rid, task=m.id)
        self.drop_pursuit(m, t, "gone")

    def _teammate(self, robot: str, x: float, y: float) -> tuple[str, str] | None:
        """The first teammate (by id) with a patrol in its recipe, not done, whose sector
        (else area) holds (x, y), and not pursuing as far as we know."""
        dom = self.dom
        for rid in dom.robot_ids:
            if rid == robot or self.pursuing(rid) is not None:
                continue
            for p in dom.plan.plan.missions:
                if p.unit != rid or p.type != "patrol" or dom.plan.state.get(p.id) == "done":
                    continue
                area = p.params.get("sector") or p.params.get("area")
                if area in dom.world and shapely.contains_xy(dom.world[area].geom, x, y):
                    return rid, area
        return None
