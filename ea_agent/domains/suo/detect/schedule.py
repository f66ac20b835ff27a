"""Schedule: missions late (or early) to start or end, as timed monitors of the
core Schedule; and ON-ORDER phases, checked against the order that starts or ends
them (the relative near-time monitor of 6.6.4): a phase confirmed without its order,
or not within the schedule threshold of it, is a schedule alert."""
from __future__ import annotations

from ea_agent.core.alert import Candidate, hms
from ea_agent.core.plan import TimeConstraint
from ea_agent.core.schedule import Schedule

from ..missions import Mission
from .base import Detector


class ScheduleMonitors(Detector):
    TYPES = {"schedule": "plan-constraint-violated"}

    def bind(self, ea) -> None:
        dom = self.dom
        self.schedule = Schedule(ea.timers, ea.post, dom.name, dom.in_plan, lambda m: dom.voi(m, "schedule_s"),
                                 dom.voi_cfg["schedule_repeat_s"])

    def reset(self) -> None:
        self.ordered: dict[tuple[str, str], float] = {}  # (mission, phase) -> when its order came

    def post(self, m: Mission, phase: str, tc: TimeConstraint) -> None:
        self.schedule.post(m, phase, tc)

    @staticmethod
    def on_order(m: Mission, phase: str) -> bool:
        return getattr(m.spec, phase).type == "ON-ORDER"

    def order(self, m: Mission, phase: str, t: float, issuer: str) -> None:
        """The superior ordered `phase` of `m` at `t`: it must follow within the threshold."""
        dom = self.dom
        if not self.on_order(m, phase):
            raise ValueError(f"mission {m.id!r} does not {phase} ON-ORDER (its plan says when)")
        if (m.id, phase) in self.ordered:
            return   # a repeated order changes nothing
        self.ordered[(m.id, phase)] = t
        thr = dom.voi(m, "schedule_s")

        def off(tf: float, mon, how: str) -> None:
            if dom.in_plan(m):
                dom.ea.post(self._cand(m, phase, tf, abs(tf - t), how, t))
            return None
        dom.timers.near_time((phase, m.id), 0.0, thr, off, mode="relative", now=t, tag=m.id)

    def confirmed(self, m: Mission, phase: str, t: float) -> None:
        """A phase was confirmed: one that waits for an order and had none is told."""
        if self.on_order(m, phase) and (m.id, phase) not in self.ordered and self.dom.in_plan(m):
            self.dom.ea.post(self._cand(m, phase, t, 0.0, "unordered", None))

    def _cand(self, m: Mission, phase: str, t: float, off: float, how: str, ordered_t: float | None) -> Candidate:
        who = self.dom.name(m.unit)
        if how == "unordered":
            text = f"{who} {phase}ed {m.TYPE} without an order (ON-ORDER)"
        elif how == "late":
            text = f"{who} late {phase}ing {m.TYPE} ordered at {hms(ordered_t)}: {off:.0f} s late"
        else:
            text = f"{who} {phase}ed {m.TYPE} {off:.0f} s before it was ordered at {hms(ordered_t)}"
        return Candidate(t, "schedule", m.compute_priority("schedule"), (m.unit,), text,
                         key=("schedule", m.id, phase), measure=off,
                         details={"mission": m.id, "phase": phase, "constraint": "ON-ORDER", "how": how,
                                  "ordered_t": ordered_t, "off_s": round(off, 1)})
