"""Missions that change the plan: contingencies (branches, sequels) and reorganizations."""
from __future__ import annotations

from typing import ClassVar

from .base import Mission, mission


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
    ALTERNATIVE: ClassVar[bool] = False   # offered to the commander in place of the course of action running
    CHECKS = ("its trigger (contingency); once triggered, its task as a monitored mission from then",)

    def contingency_satisfied(self, ctx):
        return ctx.evaluate_trigger(self.params["trigger"])

    def post_execution_constraints(self, ctx):
        ctx.post_contingency(self)


@mission
class Branch(ContingentMission):
    """An alternative course of action (FM 3-0): besides its trigger, offered to the commander in
    place of a move when its unit meets hostiles ahead."""
    TYPE = "branch"
    ALTERNATIVE = True
    CHECKS = ContingentMission.CHECKS + ("offered in place of its unit's move when hostiles are ahead (threat-ahead)",)


@mission
class Sequel(ContingentMission):
    """What follows the current operation once its trigger holds (FM 3-0): never offered in
    place of the course of action running."""
    TYPE = "sequel"


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
    """The reorganization family as it is."""
    TYPE = "reorganize"
