"""Schedule: missions late (or early) to start or end, as timed monitors of the
core Schedule; here so the SUO alert type has its place among the detectors."""
from __future__ import annotations

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

    def post(self, m: Mission, phase: str, tc: TimeConstraint) -> None:
        self.schedule.post(m, phase, tc)
