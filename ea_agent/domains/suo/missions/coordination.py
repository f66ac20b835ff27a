"""Coordination missions: two units at one place around one time."""
from __future__ import annotations

from .base import Mission, _positive_problem, mission


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
    """Two forces meet (FM 3-90): both at the link-up point in time and, with `join_m`, joined
    from then: after the link-up the unit stays within `join_m` of its partner while it runs,
    or the forces that met have come apart again (band)."""
    TYPE = "link-up"
    PARAMS = {"window": "optional [from, until]: the link-up made at the point in it, in place of at + fuzz_s "
                        "(coordination; detect/windows.py)",
              "join_m": "optional: from the link-up (at + fuzz, or the window's close) the unit stays within "
                        "this of its partner"}
    CHECKS = CoordinationMission.CHECKS + ("joined to its partner after the link-up (band)",)

    @classmethod
    def check_params(cls, params, overlay):
        return _positive_problem(params, "join_m", "expected a distance > 0 in metres") or \
            super().check_params(params, overlay)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        if self.params.get("join_m") is not None:
            w = self.params.get("window")
            since = float(w[1]) if w is not None else \
                float(self.params["at"]) + float(self.params.get("fuzz_s", ctx.voi(self, "schedule_s")))
            ctx.post_band(self, self.params["partner"], 0.0, float(self.params["join_m"]), since=since)


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
