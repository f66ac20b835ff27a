"""Coordination missions: two units at one place around one time."""
from __future__ import annotations

from .base import Mission, mission


class CoordinationMission(Mission):
    """Two units must both have an element at `point` around time `at`."""
    PARAMS = {"partner": "the coordinating unit", "point": "overlay coordination point",
              "at": "scenario time of the coordination", "fuzz_s": "allowed slack (default schedule_s)"}
    REQUIRED = ("partner", "point", "at")
    GEOMETRY_PARAMS = ("point",)
    UNIT_PARAMS = ("partner",)
    LOCATION_RULE = "any"
    CHECKS = ("both units with an element at the point within fuzz of `at` (coordination)",)

    def location_constraints(self, ctx):
        ctx.post_coordination(self, self.params["partner"], self.params["point"],
                              float(self.params["at"]), float(self.params.get("fuzz_s", ctx.voi(self, "schedule_s"))))


@mission
class LinkUp(CoordinationMission):
    """The coordination family as it is: both units meet at the point in time."""
    TYPE = "link-up"
    PARAMS = {"window": "optional [from, until]: the link-up made at the point in it, in place of at + fuzz_s "
                        "(coordination; detect/windows.py)"}


@mission
class ReliefInPlace(CoordinationMission):
    """The unit relieves `partner` at `point`: besides meeting there, no gap (the partner
    does not leave before the unit is in)."""
    TYPE = "relief-in-place"
    PARAMS = {"window": "optional [from, until]: both units at the point in it, in place of at + fuzz_s "
                        "(coordination; detect/windows.py)"}
    CHECKS = CoordinationMission.CHECKS + ("no gap: the relieved unit stays until the relieving one is in (presence)",)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        ctx.post_presence(self, self.params["partner"], self.params["point"])


@mission
class PassageOfLines(CoordinationMission):
    """The unit passes through `partner`'s position at `point`: its elements there keep to
    the optional `lane`."""
    TYPE = "passage-of-lines"
    PARAMS = {"lane": "optional overlay area: the passing unit's elements at the point keep inside it",
              "complete_window": "optional [from, until]: the passage complete (its end) in it "
                                 "(coordination; detect/windows.py)"}
    GEOMETRY_PARAMS = ("point", "lane")
    CHECKS = CoordinationMission.CHECKS + ("its elements at the point inside its lane (presence)",)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        if self.params.get("lane"):
            ctx.post_presence(self, self.params["partner"], self.params["point"], self.params["lane"])
