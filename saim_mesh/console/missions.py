"""Mission states for the console: pending, active, done, late, from the plan, the
confirmations heard (or, for robots, their task reports) and the scenario clock."""
from __future__ import annotations

from ea_agent import domains

AUTOMATIC = ("reorganize",)   # missions the EA executes itself, no confirmation heard
DEADLINES = ("START-AT", "START-NLT", "END-AT", "END-NLT")   # a time that must not pass unconfirmed


def _deadline(c) -> float | None:
    return c.t if c.type in DEADLINES and c.t is not None else None


class Missions:
    def __init__(self, sc, taskorg):
        self.sc, self.taskorg = sc, taskorg
        self.unit_plan: dict[str, str] = {u: sc.initial_plan for u in taskorg.units}
        self.specs = {m.id: m for p in sc.plans.values() for m in p.missions}
        self.started: dict[str, float] = {}
        self.ended: dict[str, float] = {}
        # robots have no human confirming starts: a task is under way once its predecessors are done
        self.implied_start = domains.of(sc).NAME == "uv"

    def take(self, m) -> bool:
        """One message; True when it may change a mission's state."""
        kind = m.KIND
        if kind == "mission":
            if m.mission not in self.specs:
                return False
            (self.started if m.phase == "start" else self.ended).setdefault(m.mission, m.t)
            return True
        if kind == "uv-agent":
            if m.act in ("success", "failure") and m.task in self.specs:
                self.ended.setdefault(m.task, m.t)
                return True
            return False
        if kind == "order":
            if m.action != "execute-plan" or m.plan not in self.sc.plans or m.issuer not in self.taskorg.units:
                return False
            for u in self.taskorg.subtree(m.issuer):
                self.unit_plan[u] = m.plan
            return True
        return False

    def state(self, m, t: float) -> str:
        if m.id in self.ended:
            return "done"
        if m.type in AUTOMATIC and m.start.t is not None:   # the EA carries it out at its time
            return "done" if t >= m.start.t else "pending"
        if m.id in self.started or self.implied_start and all(a in self.ended for a in m.after):
            dl = _deadline(m.end)
            return "late" if dl is not None and t > dl else "active"
        dl = _deadline(m.start)
        return "late" if dl is not None and t > dl else "pending"

    def current(self, t: float) -> dict[str, dict]:
        """{unit: {mission, mission_type, state}}: each unit's first mission not done
        (in plan order), or its last one when all are done."""
        out: dict[str, dict] = {}
        by_unit: dict[str, list] = {}
        for name in set(self.unit_plan.values()):
            for m in self.sc.plans[name].missions:
                if self.unit_plan.get(m.unit) == name:
                    by_unit.setdefault(m.unit, []).append(m)
        for u, ms in sorted(by_unit.items()):
            shown, st = ms[-1], "done"
            for m in ms:
                s = self.state(m, t)
                if s != "done":
                    shown, st = m, s
                    break
            out[u] = {"mission": shown.id, "mission_type": shown.type, "state": st}
        return out
