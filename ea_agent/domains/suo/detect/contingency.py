"""Contingencies (branches and sequels): a trigger that holds starts the planned
task and suggests it to the commander."""
from __future__ import annotations

from ea_agent.core.alert import Candidate
from ea_agent.core.plan import MissionSpec

from ..missions import REGISTRY, ContingentMission
from .base import Changes, Detector
from .geometry import judged_distance


class Contingencies(Detector):
    """Dormant contingencies of our plan, re-checked when a unit under a trigger
    moved or a track in a trigger's area changed."""
    TYPES = {"contingency": "contingency-plan-suggested"}

    def reset(self) -> None:
        self.pending: dict[str, ContingentMission] = {}
        self.fired: set[str] = set()   # trigger areas fired this epoch (read by Areas)

    def post(self, m: ContingentMission) -> None:
        self.pending[m.id] = m
        self.dom.areas.reindex()

    def trigger_areas(self) -> set[str]:
        """Areas watched for hostiles because a trigger names them."""
        return {c.params["trigger"]["area"] for c in self.pending.values()
                if c.params["trigger"]["kind"] == "hostile-in-area"}

    def evaluate_trigger(self, tr: dict) -> bool:
        dom = self.dom
        if tr["kind"] == "hostile-in-area":
            return dom.areas.strength.get(tr["area"], 0) >= int(tr.get("min_strength", 1))
        pts = dom.pic.member_xy(tr["unit"])
        d = judged_distance(dom.overlay[tr["area"]].area, pts, tr.get("rule", "centroid"), dom.unit_pos.get(tr["unit"]))
        return d is not None and d <= float(tr.get("within_m", 0.0))

    def execute(self, m: ContingentMission, t: float) -> None:
        """The trigger holds: the EA executes the contingency. Its task becomes a monitored
        mission of the plan, started now, judged as its class says (Check-Initial-Location
        at once, its place constraints while it runs)."""
        dom = self.dom
        task_cls = REGISTRY[m.params["task"]]
        task = task_cls(MissionSpec(m.id, m.unit, task_cls.TYPE, m.spec.start, m.spec.end, (),
                                    dict(m.params.get("task_params", {})))).use_defaults(dom.priorities)
        dom.missions[m.id] = task
        dom.plan.state[m.id] = "ready"
        if dom.in_plan(task):
            task.post_execution_constraints(dom)
        dom.plan.start(m.id, t)
        dom.timers.occurred(("start", m.id), t)
        if dom.in_plan(task):
            task.check_initial_location(dom, t)
            dom.windows.start(task, t)

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        self.fired = set()
        if not self.pending or not (ch.tracks or ch.leaves or ch.rescan):
            return
        dom = self.dom
        strength = dom.areas.strength
        for mid, m in list(self.pending.items()):
            tr = m.params["trigger"]
            if ch.rescan and m.recheck_on_scan():
                pass   # what it waits on besides its trigger (the plan) changes without a report
            elif tr["kind"] == "unit-at":
                if tr["unit"] not in ch.units:   # no moved leaf under it (ch.units: those leaves and superiors)
                    continue
            elif not ch.tracks.intersection(dom.areas.tracks.get(tr["area"], ())):
                continue
            if not m.contingency_satisfied(dom):
                continue
            del self.pending[mid]
            self.fired.add(tr["area"])
            if tr["kind"] == "hostile-in-area":
                why = f"Red activity at {tr['area']} ({strength.get(tr['area'], 0)} entities)"
                subj = (m.unit,)
            else:
                why = f"{dom.name(tr['unit'])} at {tr['area']}"
                subj = (m.unit, tr["unit"])
            cands.append(Candidate(t, "contingency", m.compute_priority("contingency"), subj,
                                   f"{why} triggers contingency: {m.TYPE} {m.params['task']} by {dom.name(m.unit)}",
                                   key=("contingency", mid), friendly=tr["kind"] == "unit-at",
                                   details={"mission": mid, "trigger": tr, "places": [tr["area"]]}))
            self.execute(m, t)
            if tr["kind"] == "hostile-in-area":  # the contingency alert already told of this activity
                cands[-1].also = ((("monitored", tr["area"], None), float(strength.get(tr["area"], 0))),)
        if self.fired:
            dom.areas.reindex()
