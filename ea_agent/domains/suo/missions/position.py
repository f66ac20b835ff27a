"""Position missions: hold a place, watch an engagement area, support."""
from __future__ import annotations

from typing import ClassVar

from .base import Mission, _positive_problem, _post_by, _band_problem, _checks, _time_problem, _window_problem, mission


class PositionMission(Mission):
    """Hold a position (battle position, support-by-fire position, ...) while active.

    Optional `engagement_area` is watched for hostiles (expected there) and must be
    within the unit's weapons range of the position (friendly-expected); with
    `expect_hostile_by` the plan expects hostiles there by that time (hostile-expected).
    """
    PARAMS = {"position": "overlay area the unit occupies",
              "engagement_area": "optional overlay area watched for hostile activity",
              "expect_hostile_by": "optional scenario time by which hostiles are expected there"}
    REQUIRED = ("position",)
    GEOMETRY_PARAMS = ("position", "engagement_area")
    DESIRED_STRENGTH_RATIO = 0.33  # prepared defenders accept 1:3
    CHECKS = _checks("in its position while it runs and at the end (out-of-position)",
                     "its position holds some friendly element while it runs (friendly-expected)",
                     "its engagement area within weapons range of the position (friendly-expected)",
                     "hostiles in its engagement area: expected activity; absent by a time (hostile-expected)")

    def location_constraints(self, ctx):
        ctx.post_location_monitor(self, self.params["position"], self.LOCATION_RULE, "position")
        ctx.post_held(self, self.params["position"])
        ea_ = self.params.get("engagement_area")
        if ea_:
            ctx.post_red_monitor(self, ea_, expected=True, expect_by=self.params.get("expect_hostile_by"))

    def check_initial_location(self, ctx, t):
        super().check_initial_location(ctx, t)
        if self.params.get("engagement_area"):
            ctx.check_coverage(self, self.params["position"], self.params["engagement_area"], t)

    def check_final_location(self, ctx, t):
        ctx.check_location(self, self.params["position"], self.LOCATION_RULE, t, "position")

    def respond_to_monitored_red_activity(self, ctx, area, t, tracks, strength, kind="monitored"):
        ctx.monitored_candidate(self, area, t, tracks, strength, expected=kind == "monitored", kind=kind)


@mission
class Defend(PositionMission):
    """An optional `rear_line` no hostile may cross (penetration); an absent expected enemy is IMMEDIATE."""
    TYPE = "defend"
    PARAMS = {"rear_line": "optional overlay line behind the defence that no hostile may cross"}
    GEOMETRY_PARAMS = ("position", "engagement_area", "rear_line")
    PRIORITY = {"hostile-expected": "immediate"}
    CHECKS = PositionMission.CHECKS + ("no hostile across its rear line (penetration)",)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        if self.params.get("rear_line"):
            ctx.post_penetration(self, self.params["rear_line"])


@mission
class Occupy(PositionMission):
    """Move into an area to control it (FM 3-90): both the move to it and its occupation are the
    task, so with `by` every element is in the position by then (out-of-position, check `by`)."""
    TYPE = "occupy"
    PARAMS = {"by": "optional scenario time by which all its elements are in the position"}
    CHECKS = PositionMission.CHECKS + ("all its elements in the position by its `by` time (out-of-position)",)

    @classmethod
    def check_params(cls, params, overlay):
        return _time_problem(params, "by") or super().check_params(params, overlay)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        _post_by(self, ctx, "position", "all")


@mission
class Retain(PositionMission):
    """Keep the enemy out of the position: a hostile in it is a penetration."""
    TYPE = "retain"
    CHECKS = PositionMission.CHECKS + ("no hostile enters the position (penetration, projected before)",)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        ctx.post_penetration(self, self.params["position"])


@mission
class Block(PositionMission):
    """Deny the enemy an area or an avenue (FM 3-90): it names exactly one of `area` (no
    hostile enters it) or `line` (no hostile crosses it); either is a penetration, projected
    before it happens."""
    TYPE = "block"
    PARAMS = {"area": "overlay area no hostile may enter (give this or line)",
              "line": "overlay line no hostile may cross (give this or area)"}
    GEOMETRY_PARAMS = ("position", "engagement_area", "area", "line")
    PRIORITY = {"hostile-expected": "immediate"}
    CHECKS = PositionMission.CHECKS + (
        "names exactly one of area or line (checked on load): no hostile enters its area or crosses its line "
        "(penetration, projected before)",)

    @classmethod
    def check_params(cls, params, overlay):
        area, line = params.get("area"), params.get("line")
        if (area is None) == (line is None):
            return ("area" if area is None else "line",
                    "a block names what it blocks: exactly one of area (a place) or line (an avenue)"
                    + (", not both" if area is not None else ""))
        if area is not None and area in overlay and overlay[area].geom.geom_type == "LineString":
            return "area", f"{area!r} is a line: give it as line, not area"
        return super().check_params(params, overlay)

    def blocked(self) -> str:
        return self.params.get("area") or self.params["line"]

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        ctx.post_penetration(self, self.blocked())


@mission
class AttackByFire(PositionMission):
    """Direct fires on the enemy without closing with it (FM 3-90): 1:1 wanted; its `target`
    within its weapons range of the position (friendly-expected, at its start), and it does not
    cross its `limit` (the line short of the target): beyond it, it is assaulting, not attacking
    by fire (line, check `limit`)."""
    TYPE = "attack-by-fire"
    PARAMS = {"target": "optional overlay area its fires land on",
              "limit": "optional overlay line between the position and the target, not crossed while it runs"}
    GEOMETRY_PARAMS = ("position", "engagement_area", "target", "limit")
    LINE_PARAMS = Mission.LINE_PARAMS + ("limit",)
    DESIRED_STRENGTH_RATIO = 1.0
    CHECKS = PositionMission.CHECKS + ("its target within weapons range of the position (friendly-expected)",
                                       "not across its limit towards the target: no closing with it (line)")

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        if self.params.get("limit"):
            ctx.post_line(self, self.params["limit"], "limit")

    def check_initial_location(self, ctx, t):
        super().check_initial_location(ctx, t)
        if self.params.get("target"):
            ctx.check_coverage(self, self.params["position"], self.params["target"], t)


@mission
class SupportByFire(PositionMission):
    """Fires for a moving unit (`supported`): in position before it crosses its `line` (of
    departure), fires lifted when it comes within `lift_m` of the `target`; 1:1 wanted."""
    TYPE = "support-by-fire"
    PARAMS = {"supported": "optional unit whose attack it supports",
              "line": "optional line of departure of the supported unit",
              "target": "overlay area its fires land on (needed with supported)"}
    GEOMETRY_PARAMS = ("position", "engagement_area", "line", "target")
    UNIT_PARAMS = ("supported",)
    DESIRED_STRENGTH_RATIO = 1.0
    CHECKS = PositionMission.CHECKS + (
        "in position before the supported unit crosses its line of departure; fires lift when it nears "
        "the target (fire-support)",)

    @classmethod
    def check_params(cls, params, overlay):
        if params.get("supported") is not None and params.get("target") is None:
            return "target", "a supported unit needs the target the fires land on"
        if params.get("line") is not None and params.get("supported") is None:
            return "supported", "a line of departure needs the unit that crosses it"
        return super().check_params(params, overlay)

    def plan_constraints(self, ctx):
        """From the plan's start, not its own: the supported unit may depart before this
        mission is even ready, and that is what is checked."""
        if self.params.get("supported"):
            ctx.post_fire_support(self, self.params["supported"], self.params.get("line"), self.params["target"])


@mission
class Overwatch(PositionMission):
    """One element with eyes on is enough; an optional `supported` unit stays within its
    distance band of it (default [0, weapons_range_m]: within its fires)."""
    TYPE = "overwatch"
    LOCATION_RULE = "any"
    PARAMS = {"supported": "optional unit overwatched", "band_m": "optional [min, max] distance to it"}
    UNIT_PARAMS = ("supported",)
    CHECKS = PositionMission.CHECKS + ("the overwatched unit within its band (band)",)

    @classmethod
    def check_params(cls, params, overlay):
        return super().check_params(params, overlay) or _band_problem(params)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        if self.params.get("supported"):
            lo, hi = self.params.get("band_m") or (0.0, ctx.voi(self, "weapons_range_m"))
            ctx.post_band(self, self.params["supported"], float(lo), float(hi))


@mission
class Suppress(PositionMission):
    """Fires on a target for a time (FM 3-90): through its `window` the target must be within
    the unit's weapons range of where it is, or its fires cannot reach it (fire-support)."""
    TYPE = "suppress"
    PARAMS = {"target": "overlay area its fires land on",
              "window": "[from, until]: the scenario times its fires are due on the target"}
    REQUIRED = ("position", "target", "window")
    GEOMETRY_PARAMS = ("position", "engagement_area", "target")
    CHECKS = PositionMission.CHECKS + ("the target within its weapons range through its fire window (fire-support)",)

    @classmethod
    def check_params(cls, params, overlay):
        return _window_problem(params, "window") or super().check_params(params, overlay)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        w0, w1 = self.params["window"]
        ctx.post_suppression(self, self.params["target"], float(w0), float(w1))


@mission
class Contain(PositionMission):
    """Keep the enemy inside its engagement area: a hostile leaving it is an escape."""
    TYPE = "contain"
    CHECKS = PositionMission.CHECKS + ("no hostile leaves its engagement area (escape)",)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        if self.params.get("engagement_area"):
            ctx.post_escape(self, self.params["engagement_area"])


@mission
class Disrupt(PositionMission):
    """Break the enemy's formation and tempo on an avenue (FM 3-90): from `by`, a hostile on the
    `avenue` still advancing along it faster than `tempo_mps` is a tempo not broken (hostile-expected)."""
    TYPE = "disrupt"
    PARAMS = {"avenue": "overlay avenue of approach (a line, drawn the way the enemy comes)",
              "by": "scenario time by which its tempo on the avenue must be broken",
              "tempo_mps": "optional advance along the avenue that still counts as unbroken (default 1.0 m/s)"}
    REQUIRED = ("position", "avenue", "by")
    GEOMETRY_PARAMS = ("position", "engagement_area", "avenue")
    LINE_PARAMS = Mission.LINE_PARAMS + ("avenue",)
    TEMPO_MPS: ClassVar[float] = 1.0
    CHECKS = PositionMission.CHECKS + (
        "from its time, no hostile on its avenue still advancing along it faster than its tempo (hostile-expected)",)

    @classmethod
    def check_params(cls, params, overlay):
        return _positive_problem(params, "tempo_mps", "expected a speed > 0 in m/s") or super().check_params(params, overlay)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        ctx.post_tempo(self, self.params["avenue"], float(self.params["by"]),
                       float(self.params.get("tempo_mps", self.TEMPO_MPS)))
