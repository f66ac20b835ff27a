"""Autonomous reactions (paper 7.4), run inside the domain on scenario time so that
replaying the same messages gives the same plan and alerts.

- target-visible while patrolling: commit to `pursue` (a new active mission in our
  plan state; the patrol is suspended);
- lost-target past `drop_s`: drop the pursuit and resume the patrol;
- a handoff (delegate + accept) moves the pursuit from A to B;
- target-gone: drop the pursuit and hand it to a patrolling teammate (its patrol active,
  not suspended by a pursuit of its own) whose sector (else area) holds the target.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import shapely

from ea_agent.core.plan import MissionSpec

from .detectors.handoff import story_key

if TYPE_CHECKING:
    from .domain import UvDomain
    from .missions import Mission


class Policies:
    def __init__(self, dom: "UvDomain"):
        self.dom = dom
        self.resume: dict[str, str] = {}   # pursue mission id -> suspended patrol id
        self.n = 0

    def pursuing(self, robot: str, target: str) -> "Mission | None":
        for m in self.dom.active_of(robot):
            if m.TYPE == "pursue" and m.params.get("target") == target:
                return m
        return None

    def commit_pursuit(self, patrol: "Mission | None", robot: str, target: str, sector: str | None,
                       t: float) -> None:
        """`robot` pursues `target` (inside `sector`), suspending `patrol` if given."""
        dom = self.dom
        if robot not in dom.mine or self.pursuing(robot, target) is not None:
            return
        self.n += 1
        base = patrol.id if patrol is not None else robot
        spec = MissionSpec(f"{base}/pursue-{target}-{self.n}", robot, "pursue",
                           params={"target": target, "sector": sector})
        m = dom.add_mission(spec, t)
        if patrol is not None:
            dom.plan.state[patrol.id] = "suspended"
            self.resume[m.id] = patrol.id

    def drop_pursuit(self, m: "Mission", t: float) -> None:
        dom = self.dom
        if dom.plan is None or dom.plan.state.get(m.id) != "active":
            return
        dom.end_mission(m, t, advance=False)
        patrol = self.resume.pop(m.id, None)
        if patrol is not None and dom.plan.state.get(patrol) == "suspended":
            dom.plan.state[patrol] = "active"
        dom.advance_plan(t)

    def take_over(self, robot: str, target: str, sector: str | None, t: float) -> None:
        """`robot` takes a pursuit from a teammate, suspending its own patrol if any."""
        patrol = next((m for m in self.dom.active_of(robot) if m.TYPE == "patrol"), None)
        if sector is None and patrol is not None:
            sector = patrol.params.get("sector") or patrol.params.get("area")
        self.commit_pursuit(patrol, robot, target, sector, t)

    def transfer(self, frm: str, to: str, target: str | None, sector: str | None, task: str, t: float) -> None:
        dom = self.dom
        old = self.pursuing(frm, target) if target else None
        if old is None and task in dom.missions and dom.active(task):
            old = dom.missions[task]
        if old is not None and old.unit == frm:
            self.drop_pursuit(old, t)
        if target and to in dom.mine:
            self.take_over(to, target, sector, t)

    def target_gone(self, m: "Mission", target: str, t: float, cands: list) -> None:
        """Drop the pursuit; a teammate whose patrol area holds the target gets it."""
        dom = self.dom
        tg = dom.watchman.targets[target]
        self.drop_pursuit(m, t)
        for rid in dom.robot_ids:
            if rid == m.unit:
                continue
            for other in dom.active_of(rid):   # a patrolling teammate: not one busy with its own pursuit
                area = other.params.get("sector") or other.params.get("area")
                if other.TYPE == "patrol" and area in dom.world and \
                        shapely.contains_xy(dom.world[area].geom, tg.x, tg.y):
                    cands.append(dom.cand(t, "handoff", m, (m.unit, rid, target),
                                          f"{dom.name(m.unit)} hands pursuit of {target} to {dom.name(rid)} "
                                          f"(target entered {area})", story_key(dom, m.unit, rid, target, t), None,
                                          {"from": m.unit, "to": rid, "task": m.id, "target": target,
                                           "act": "policy", "places": [area]}))
                    return
