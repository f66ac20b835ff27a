"""The SUO mission model (paper 6.5): a class hierarchy whose methods say how each
mission is monitored. The EA calls these methods; they post monitors back to the
EA through `ctx` (the domain's monitoring API), as the paper's methods post facts.

Non-leaf classes: MovementMission, OffensiveMission, PositionMission,
SecurityMission, CoordinationMission, ContingentMission, ReorganizationMission.
Leaf classes carry Army doctrine names (FM 3-90) in `TYPE`.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from ea_agent.core.mission import Mission as CoreMission, Registry

if TYPE_CHECKING:  # the domain implements the monitoring API used here
    from .domain import SuoDomain

REGISTRY = Registry()

DEFAULT_PRIORITY = {
    "fratricide": "flash", "contact": "flash", "call-for-fire": "flash",
    "out-of-position": "immediate", "coordination": "immediate", "contingency": "immediate",
    "distance": "immediate", "strength": "immediate", "proximity": "immediate",
    "schedule": "priority", "unknown-position": "priority", "monitored": "priority",
    "hostile-expected": "priority", "ave-of-approach": "routine",
}


mission = REGISTRY.leaf   # registers a leaf mission class under its doctrine name


class Mission(CoreMission):
    """Root of the SUO model: time constraints (from the core), places on the
    overlay, and how hostile activity near the unit is judged."""
    PARAMS = {
        "voi": "optional per-mission VOI overrides, e.g. {out_of_position_m: 100, schedule_s: 10}",
    }
    GEOMETRY_PARAMS: ClassVar[tuple[str, ...]] = ()   # params that name overlay features
    LOCATION_RULE: ClassVar[str] = "centroid"         # centroid | any | all members
    DESIRED_STRENGTH_RATIO: ClassVar[float] = 1.0     # friendly:hostile combat power wanted
    DEFAULT_PRIORITY = DEFAULT_PRIORITY

    def respond_to_monitored_red_activity(self, ctx: "SuoDomain", area: str, t: float,
                                          tracks: list[str], strength: int) -> None:
        ctx.monitored_candidate(self, area, t, tracks, strength, expected=False)

    def desired_strength_ratio(self) -> float:
        return self.DESIRED_STRENGTH_RATIO

    def red_alert_priority(self, kind: str, friendly_strength: int, hostile_strength: int,
                           distance_m: float, danger_close_m: float) -> str | None:
        """Priority of a proximity alert, or None when it is not worth giving."""
        if kind == "contact":
            return "flash"
        if kind == "distance":
            return "flash" if distance_m <= danger_close_m else "immediate"
        if hostile_strength <= 0:
            return None
        ratio = friendly_strength / hostile_strength
        return "immediate" if ratio < self.desired_strength_ratio() else "priority"


# ---------------------------------------------------------------- movement
class MovementMission(Mission):
    """Move along a route to a destination; judged by the unit's centroid."""
    PARAMS = {"route": "overlay route (LineString) the unit follows",
              "destination": "overlay feature the unit must reach"}
    REQUIRED = ("destination",)
    GEOMETRY_PARAMS = ("route", "destination")

    def location_constraints(self, ctx):
        if self.params.get("route"):
            ctx.post_location_monitor(self, self.params["route"], self.LOCATION_RULE, "route")

    def check_final_location(self, ctx, t):
        ctx.check_location(self, self.params["destination"], self.LOCATION_RULE, t, "destination")


@mission
class Move(MovementMission):
    TYPE = "move"


@mission
class TacticalRoadMarch(MovementMission):
    TYPE = "tactical-road-march"
    PRIORITY = {"schedule": "immediate"}   # march tables are tightly timed


@mission
class MovementToContact(MovementMission):
    TYPE = "movement-to-contact"
    DESIRED_STRENGTH_RATIO = 2.0


@mission
class FollowAndSupport(MovementMission):
    TYPE = "follow-and-support"
    PARAMS = {"supported": "unit followed"}
    UNIT_PARAMS = ("supported",)


@mission
class FollowAndAssume(MovementMission):
    TYPE = "follow-and-assume"
    PARAMS = {"supported": "unit whose mission may be assumed"}
    UNIT_PARAMS = ("supported",)


@mission
class Withdraw(MovementMission):
    TYPE = "withdraw"
    DESIRED_STRENGTH_RATIO = 0.5


@mission
class Delay(MovementMission):
    TYPE = "delay"
    DESIRED_STRENGTH_RATIO = 0.33


@mission
class Bypass(MovementMission):
    TYPE = "bypass"


@mission
class RouteReconnaissance(MovementMission):
    TYPE = "route-reconnaissance"
    LOCATION_RULE = "any"   # one element on the route is enough


# ---------------------------------------------------------------- offensive
class OffensiveMission(Mission):
    """Attack towards an objective; all members must be on it at the end."""
    PARAMS = {"objective": "overlay objective area", "axis": "optional route/axis of advance"}
    REQUIRED = ("objective",)
    GEOMETRY_PARAMS = ("objective", "axis")
    LOCATION_RULE = "centroid"
    FINAL_RULE: ClassVar[str] = "all"
    DESIRED_STRENGTH_RATIO = 3.0
    PRIORITY = {"schedule": "immediate"}

    def location_constraints(self, ctx):
        if self.params.get("axis"):
            ctx.post_location_monitor(self, self.params["axis"], self.LOCATION_RULE, "axis")

    def check_final_location(self, ctx, t):
        ctx.check_location(self, self.params["objective"], self.FINAL_RULE, t, "objective")


@mission
class Attack(OffensiveMission):
    TYPE = "attack"


@mission
class HastyAttack(OffensiveMission):
    TYPE = "hasty-attack"
    FINAL_RULE = "centroid"


@mission
class Seize(OffensiveMission):
    TYPE = "seize"


@mission
class Secure(OffensiveMission):
    TYPE = "secure"


@mission
class Clear(OffensiveMission):
    TYPE = "clear"


@mission
class Destroy(OffensiveMission):
    TYPE = "destroy"
    FINAL_RULE = "centroid"


@mission
class Breach(OffensiveMission):
    TYPE = "breach"
    FINAL_RULE = "any"


@mission
class Isolate(OffensiveMission):
    TYPE = "isolate"
    FINAL_RULE = "centroid"


@mission
class Fix(OffensiveMission):
    TYPE = "fix"
    FINAL_RULE = "centroid"
    DESIRED_STRENGTH_RATIO = 1.0


# ---------------------------------------------------------------- position
class PositionMission(Mission):
    """Hold a position (battle position, support-by-fire position, ...) while active.

    Optional `engagement_area` is watched for hostiles; with `expect_hostile_by` the
    plan expects them there by that time (hostile-expected alert if absent).
    """
    PARAMS = {"position": "overlay area the unit occupies",
              "engagement_area": "optional overlay area watched for hostile activity",
              "expect_hostile_by": "optional scenario time by which hostiles are expected there"}
    REQUIRED = ("position",)
    GEOMETRY_PARAMS = ("position", "engagement_area")
    DESIRED_STRENGTH_RATIO = 0.33  # prepared defenders accept 1:3

    def location_constraints(self, ctx):
        ctx.post_location_monitor(self, self.params["position"], self.LOCATION_RULE, "position")
        ea_ = self.params.get("engagement_area")
        if ea_:
            ctx.post_red_monitor(self, ea_, expected=True, expect_by=self.params.get("expect_hostile_by"))

    def respond_to_monitored_red_activity(self, ctx, area, t, tracks, strength):
        ctx.monitored_candidate(self, area, t, tracks, strength, expected=True)


@mission
class Defend(PositionMission):
    TYPE = "defend"
    PRIORITY = {"hostile-expected": "immediate"}


@mission
class Occupy(PositionMission):
    TYPE = "occupy"


@mission
class Retain(PositionMission):
    TYPE = "retain"


@mission
class Block(PositionMission):
    TYPE = "block"
    PRIORITY = {"hostile-expected": "immediate"}


@mission
class AttackByFire(PositionMission):
    TYPE = "attack-by-fire"
    DESIRED_STRENGTH_RATIO = 1.0


@mission
class SupportByFire(PositionMission):
    TYPE = "support-by-fire"
    DESIRED_STRENGTH_RATIO = 1.0


@mission
class Overwatch(PositionMission):
    TYPE = "overwatch"
    LOCATION_RULE = "any"


@mission
class Suppress(PositionMission):
    TYPE = "suppress"


@mission
class Contain(PositionMission):
    TYPE = "contain"


@mission
class Disrupt(PositionMission):
    TYPE = "disrupt"


# ---------------------------------------------------------------- security / recon
class SecurityMission(Mission):
    """Screen/observe an area: any element on station is enough; any hostile
    activity in the watched area is unexpected and reported at once."""
    PARAMS = {"position": "overlay area or line the unit keeps", "area": "overlay area watched"}
    REQUIRED = ("position", "area")
    GEOMETRY_PARAMS = ("position", "area")
    LOCATION_RULE = "any"
    DESIRED_STRENGTH_RATIO = 0.5
    PRIORITY = {"monitored": "immediate"}

    def location_constraints(self, ctx):
        ctx.post_location_monitor(self, self.params["position"], self.LOCATION_RULE, "position")
        ctx.post_red_monitor(self, self.params["area"], expected=False)


@mission
class Screen(SecurityMission):
    TYPE = "screen"


@mission
class Guard(SecurityMission):
    TYPE = "guard"
    DESIRED_STRENGTH_RATIO = 1.0


@mission
class Observe(SecurityMission):
    TYPE = "observe"   # observation post


@mission
class AreaReconnaissance(SecurityMission):
    TYPE = "area-reconnaissance"


@mission
class ZoneReconnaissance(SecurityMission):
    TYPE = "zone-reconnaissance"


# ---------------------------------------------------------------- coordination
class CoordinationMission(Mission):
    """Two units must both have an element at `point` around time `at`."""
    PARAMS = {"partner": "the coordinating unit", "point": "overlay coordination point",
              "at": "scenario time of the coordination", "fuzz_s": "allowed slack (default schedule_s)"}
    REQUIRED = ("partner", "point", "at")
    GEOMETRY_PARAMS = ("point",)
    UNIT_PARAMS = ("partner",)
    LOCATION_RULE = "any"

    def location_constraints(self, ctx):
        ctx.post_coordination(self, self.params["partner"], self.params["point"],
                              float(self.params["at"]), float(self.params.get("fuzz_s", ctx.voi(self, "schedule_s"))))


@mission
class LinkUp(CoordinationMission):
    TYPE = "link-up"


@mission
class ReliefInPlace(CoordinationMission):
    TYPE = "relief-in-place"


@mission
class PassageOfLines(CoordinationMission):
    TYPE = "passage-of-lines"


# ---------------------------------------------------------------- contingent
class ContingentMission(Mission):
    """A branch or sequel: executed only when its trigger holds.

    trigger: {"kind": "hostile-in-area", "area": ID, "min_strength": N}
          or {"kind": "unit-at", "unit": ID, "area": ID}
    `owner` is the unit whose plan holds the contingency (only its EA monitors it).
    """
    PARAMS = {"trigger": "condition that activates the contingency", "task": "mission type to execute",
              "owner": "unit whose plan holds this contingency"}
    REQUIRED = ("trigger", "task", "owner")
    UNIT_PARAMS = ("owner",)

    def contingency_satisfied(self, ctx):
        return ctx.evaluate_trigger(self.params["trigger"])

    def post_execution_constraints(self, ctx):
        ctx.post_contingency(self)


@mission
class Branch(ContingentMission):
    TYPE = "branch"


@mission
class Sequel(ContingentMission):
    TYPE = "sequel"


# ---------------------------------------------------------------- reorganization
class ReorganizationMission(Mission):
    """Changes the task organization when executed (dynamic resubordination)."""
    PARAMS = {"subject": "unit that changes hands", "new_parent": "its new superior"}
    REQUIRED = ("subject", "new_parent")
    UNIT_PARAMS = ("subject", "new_parent")
    AUTO_START = True

    def location_constraints(self, ctx):
        pass

    def execute_mission(self, ctx, t):
        ctx.resubordinate(self.params["subject"], self.params["new_parent"], t)


@mission
class Reorganize(ReorganizationMission):
    TYPE = "reorganize"


make = REGISTRY.make
