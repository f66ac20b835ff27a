"""Missions that change the plan: contingencies (branches, sequels) and reorganizations."""
from __future__ import annotations

from typing import ClassVar

from .base import Mission, _positive_problem, _time_problem, mission


class ContingentMission(Mission):
    """A branch or sequel: executed only when its trigger holds.

    trigger: {"kind": "hostile-in-area", "area": ID, "min_strength": N}
          or {"kind": "unit-at", "unit": ID, "area": ID, "within_m": M, "rule": R} (TRIGGERS)
    `owner` is the unit whose plan holds the contingency (only its EA monitors it).
    """
    PARAMS = {"trigger": "condition that activates the contingency (one of TRIGGERS)",
              "task": "mission type to execute",
              "task_params": "the task's own parameters (what its class requires; checked against it)",
              "owner": "unit whose plan holds this contingency"}
    # trigger kind -> the keys its evaluation reads (detect/contingency.py, the oracle)
    TRIGGERS: ClassVar[dict[str, dict[str, str]]] = {
        "hostile-in-area": {"kind": "hostile-in-area", "area": "overlay feature watched",
                            "min_strength": "optional hostile strength in it that triggers (default 1)"},
        "unit-at": {"kind": "unit-at", "unit": "unit whose arrival triggers", "area": "overlay feature it reaches",
                    "within_m": "optional distance from the feature that counts (default 0)",
                    "rule": "optional centroid (default), any or all members"},
    }
    REQUIRED = ("trigger", "task", "owner")
    UNIT_PARAMS = ("owner",)
    CHECKS = ("its trigger (contingency); once triggered, its task as a monitored mission from then",)

    def contingency_satisfied(self, ctx):
        return ctx.evaluate_trigger(self.params["trigger"])

    def offered_in_place(self) -> bool:
        """Offered to the commander in place of the course of action running (threat-ahead)."""
        return False

    def recheck_on_scan(self) -> bool:
        """Its trigger judged again on every periodic scan, not only when what it watches changes."""
        return False

    def post_execution_constraints(self, ctx):
        ctx.post_contingency(self)


@mission
class Branch(ContingentMission):
    """An alternative course of action (FM 3-0): besides its trigger, offered to the commander in
    place of a move when its unit meets hostiles ahead."""
    TYPE = "branch"
    CHECKS = ContingentMission.CHECKS + ("offered in place of its unit's move when hostiles are ahead (threat-ahead)",)

    def offered_in_place(self):
        return True


@mission
class Sequel(ContingentMission):
    """What follows the current operation once its trigger holds (FM 3-0): never offered in
    place of the course of action running, and with `follows` (the mission it follows) not begun
    before that mission is done: its trigger holding while it runs is not yet the sequel's time
    (contingency)."""
    TYPE = "sequel"
    PARAMS = {"follows": "optional id of the mission it follows: not executed until that one is done"}
    CHECKS = ContingentMission.CHECKS + ("not executed before the mission it follows is done (contingency)",)

    def contingency_satisfied(self, ctx):
        after = self.params.get("follows")
        if after is not None and (ctx.plan is None or ctx.plan.state.get(after) != "done"):
            return False
        return super().contingency_satisfied(ctx)

    def recheck_on_scan(self):
        """The mission it follows ends without a report in its trigger area: judged on each scan."""
        return self.params.get("follows") is not None


class ReorganizationMission(Mission):
    """Changes the task organization when executed (dynamic resubordination)."""
    PARAMS = {"subject": "unit that changes hands", "new_parent": "its new superior"}
    REQUIRED = ("subject", "new_parent")
    UNIT_PARAMS = ("subject", "new_parent")
    AUTO_START = True
    CHECKS = ("executed by the EA itself at its start time: the task organization changes",)

    def location_constraints(self, ctx):
        pass

    def execute_mission(self, ctx, t):
        ctx.resubordinate(self.params["subject"], self.params["new_parent"], t)


@mission
class Reorganize(ReorganizationMission):
    """Restores a unit to effectiveness under a new superior (FM 3-90's reorganization): the
    task organization changes at its start and, with `join_m` and `by`, the subject is within
    `join_m` of its new superior by then: a unit resubordinated on paper but not yet with it is a
    reorganization not complete (band, check `joined`)."""
    TYPE = "reorganize"
    PARAMS = {"join_m": "optional distance from its new superior the subject is within by `by`",
              "by": "optional scenario time of that (needs join_m)"}
    CHECKS = ReorganizationMission.CHECKS + ("the subject joined to its new superior by its time (band)",)

    @classmethod
    def check_params(cls, params, overlay):
        if (params.get("join_m") is None) != (params.get("by") is None):
            return "join_m" if params.get("join_m") is None else "by", "a join needs both join_m and by"
        return (_positive_problem(params, "join_m", "expected a distance > 0 in metres")
                or _time_problem(params, "by") or super().check_params(params, overlay))

    def execute_mission(self, ctx, t):
        super().execute_mission(ctx, t)
        if self.params.get("join_m") is not None:
            ctx.check_joined(self, self.params["subject"], self.params["new_parent"], float(self.params["join_m"]),
                             max(t, float(self.params["by"])))
