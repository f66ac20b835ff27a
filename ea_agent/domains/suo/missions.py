"""The SUO mission model (paper 6.5): a class hierarchy whose methods say how each
mission is monitored. The EA calls these methods; they post monitors back to the
EA through `ctx` (the domain's monitoring API), as the paper's methods post facts.

Non-leaf classes: MovementMission, OffensiveMission, PositionMission,
SecurityMission, CoordinationMission, ContingentMission, ReorganizationMission.
Leaf classes carry Army doctrine names (FM 3-90) in `TYPE`.
"""
from __future__ import annotations

import math
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
    "penetration": "immediate", "projected-penetration": "immediate", "escape": "immediate",
    "end-state": "immediate", "friendly-expected": "immediate", "band": "immediate", "threat-ahead": "immediate",
    "checkpoint": "priority", "line": "immediate", "standoff": "immediate", "fire-support": "immediate", "presence": "immediate",
}


mission = REGISTRY.leaf   # registers a leaf mission class under its doctrine name


class Mission(CoreMission):
    """Root of the SUO model: time constraints (from the core), places on the
    overlay, and how hostile activity near the unit is judged. Check-Initial-Location
    judges at once, from the current picture, every place constraint the mission posted
    (a unit that never moves is judged too); the EA re-checks them on scenario time."""
    PARAMS = {
        "voi": "optional per-mission VOI overrides, e.g. {out_of_position_m: 100, schedule_s: 10}",
    }
    GEOMETRY_PARAMS: ClassVar[tuple[str, ...]] = ()   # params that name overlay features
    LINE_PARAMS = ("route", "axis", "rear_line", "line", "obstacle", "line_of_departure")
    LOCATION_RULE: ClassVar[str] = "centroid"         # centroid | any | all members
    DESIRED_STRENGTH_RATIO: ClassVar[float] = 1.0     # friendly:hostile combat power wanted
    STANDOFF: ClassVar[bool] = False                  # keeps `standoff_m` from hostiles (screen, withdraw, ...)
    DEFAULT_PRIORITY = DEFAULT_PRIORITY
    CHECKS = ("start/end time constraints (Fig. 6); ON-ORDER against the superior's order",
              "place constraints judged at start, on every move and every scan (stationary units too)")

    def post_execution_constraints(self, ctx) -> None:
        super().post_execution_constraints(ctx)
        if self.STANDOFF:
            ctx.post_standoff(self)

    def plan_constraints(self, ctx: "SuoDomain") -> None:
        """Constraints that hold from the start of the plan, whatever the mission's own state."""

    def check_initial_location(self, ctx: "SuoDomain", t: float) -> None:
        ctx.start_location_constraints(self, t)

    def respond_to_monitored_red_activity(self, ctx: "SuoDomain", area: str, t: float,
                                          tracks: list[str], strength: int, kind: str = "monitored") -> None:
        ctx.monitored_candidate(self, area, t, tracks, strength, expected=False, kind=kind)

    def respond_to_threat_ahead(self, ctx: "SuoDomain", t: float, tracks: list[str], strength: int) -> None:
        """Hostiles on the stretch of route ahead of a moving unit: ask the commander (most
        missions do not move along a line and never get here)."""
        ctx.threat_ahead(self, t, tracks, strength, ["continue", "abort"], "continue")

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


def _checks(*more: str) -> tuple[str, ...]:
    return Mission.CHECKS + more


def _band_problem(params: dict) -> tuple[str, str] | None:
    """What is wrong with an optional `band_m` [min, max], if anything."""
    band = params.get("band_m")
    if band is None:
        return None
    if (not isinstance(band, list) or len(band) != 2 or not all(isinstance(x, (int, float)) and not
                                                                 isinstance(x, bool) and x == x for x in band)):
        return "band_m", "expected [min, max] in metres"
    if not 0 <= band[0] <= band[1]:
        return "band_m", f"min {band[0]} above max {band[1]} (or negative)"
    return None


# ---------------------------------------------------------------- movement
class MovementMission(Mission):
    """Move along a route to a destination; judged by the unit's centroid. Without a
    route, the corridor from where the unit starts to its destination is its route."""
    PARAMS = {"route": "optional overlay route (LineString) the unit follows",
              "destination": "overlay feature the unit must reach",
              "checkpoints": "optional march table / recon progress: [{point, t}] reached near each time"}
    REQUIRED = ("destination",)
    GEOMETRY_PARAMS = ("route", "destination")
    CHECKS = _checks("on its route, or in the corridor from its start to its destination (out-of-position)",
                     "hostiles on the route ahead: recommend a branch or aborting the move (threat-ahead, a decision)",
                     "each checkpoint (march table SP/CP/RP, recon progress) reached near its time (checkpoint)",
                     "at its destination at the end (Check-Final-Location)",
                     "projected off its route or late at its destination (projections)")

    @classmethod
    def check_params(cls, params, overlay):
        table = params.get("checkpoints")
        if table is None:
            return None
        if not isinstance(table, list) or not table:
            return "checkpoints", "expected a list of {point, t}"
        last, seen = -math.inf, set()
        for i, cp in enumerate(table):
            if not isinstance(cp, dict) or set(cp) != {"point", "t"}:
                return f"checkpoints[{i}]", "expected {point, t}"
            if not isinstance(cp["point"], str):
                return f"checkpoints[{i}].point", "expected a control measure id"
            if cp["point"] in seen:   # each point is reached once: an out-and-back table needs two points
                return f"checkpoints[{i}].point", f"{cp['point']!r} is already in the table"
            seen.add(cp["point"])
            if cp["point"] not in overlay:
                return f"checkpoints[{i}].point", f"{cp['point']!r} is not in the overlay"
            t = cp["t"]
            if isinstance(t, bool) or not isinstance(t, (int, float)) or not math.isfinite(t) or t < 0:
                return f"checkpoints[{i}].t", "expected a finite time >= 0"
            if t < last:
                return f"checkpoints[{i}].t", f"{t} is before the checkpoint before it ({last})"
            last = t
        return None

    def location_constraints(self, ctx):
        if self.params.get("route"):
            ctx.post_location_monitor(self, self.params["route"], self.LOCATION_RULE, "route")
        else:
            ctx.post_corridor(self, self.params["destination"])
        if self.params.get("checkpoints"):
            ctx.post_checkpoints(self, self.params["checkpoints"])

    def check_final_location(self, ctx, t):
        ctx.check_location(self, self.params["destination"], self.LOCATION_RULE, t, "destination")

    def respond_to_threat_ahead(self, ctx, t, tracks, strength):
        """A move is not a fight: recommend a branch the plan holds for the unit, else aborting the move."""
        branches = [f"execute:{b}" for b in ctx.branches_for(self)]
        ctx.threat_ahead(self, t, tracks, strength, ["abort", *branches, "continue"],
                         branches[0] if branches else "abort")


@mission
class Move(MovementMission):
    """The movement family as it is."""
    TYPE = "move"


@mission
class TacticalRoadMarch(MovementMission):
    """March tables (its `checkpoints`: start point, checkpoints, release point) are tightly
    timed: schedule and checkpoint alerts are IMMEDIATE."""
    TYPE = "tactical-road-march"
    PRIORITY = {"schedule": "immediate", "checkpoint": "immediate"}


@mission
class MovementToContact(MovementMission):
    """Expects to meet the enemy: wants 2:1 before a threat is only PRIORITY."""
    TYPE = "movement-to-contact"
    DESIRED_STRENGTH_RATIO = 2.0


class FollowMission(MovementMission):
    """Follow another unit: besides its route, stay within a distance band of it."""
    PARAMS = {"supported": "unit followed",
              "band_m": "optional [min, max] distance to the supported unit (default [0, follow_max_m])"}
    REQUIRED = ("supported",)
    UNIT_PARAMS = ("supported",)
    CHECKS = MovementMission.CHECKS + ("within its distance band of the supported unit (band)",)

    @classmethod
    def check_params(cls, params, overlay):
        return super().check_params(params, overlay) or _band_problem(params)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        lo, hi = self.params.get("band_m") or (0.0, ctx.voi(self, "follow_max_m"))
        ctx.post_band(self, self.params["supported"], float(lo), float(hi))


@mission
class FollowAndSupport(FollowMission):
    """The follow family as it is: behind the supported unit, within its band."""
    TYPE = "follow-and-support"


@mission
class FollowAndAssume(FollowMission):
    """Ready to take over the supported unit's mission: the same band, kept tighter by plans."""
    TYPE = "follow-and-assume"


_STANDOFF = "no hostile within its standoff distance (standoff)"


@mission
class Withdraw(MovementMission):
    """Breaking contact: keeps its standoff; accepts 1:2 before a threat is IMMEDIATE."""
    TYPE = "withdraw"
    DESIRED_STRENGTH_RATIO = 0.5
    STANDOFF = True
    CHECKS = MovementMission.CHECKS + (_STANDOFF,)


@mission
class Delay(MovementMission):
    """Trades space for time: stays forward of its `line` until `until` (line); accepts 1:3
    before a threat is IMMEDIATE."""
    TYPE = "delay"
    PARAMS = {"line": "optional overlay line the unit holds forward of ...", "until": "... until this time"}
    GEOMETRY_PARAMS = ("route", "destination", "line")
    DESIRED_STRENGTH_RATIO = 0.33
    STANDOFF = True
    CHECKS = MovementMission.CHECKS + ("forward of its line until its time (line)", _STANDOFF)

    @classmethod
    def check_params(cls, params, overlay):
        if (params.get("line") is None) != (params.get("until") is None):
            return "line" if params.get("line") is None else "until", "a delay line needs both line and until"
        return super().check_params(params, overlay)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        if self.params.get("line"):
            ctx.post_line(self, self.params["line"], "hold", float(self.params["until"]))


@mission
class Bypass(MovementMission):
    """Moves around the enemy: keeps its standoff."""
    TYPE = "bypass"
    STANDOFF = True
    CHECKS = MovementMission.CHECKS + (_STANDOFF,)


@mission
class RouteReconnaissance(MovementMission):
    """One element on the route is enough; its `checkpoints` say how far along it should be when."""
    TYPE = "route-reconnaissance"
    LOCATION_RULE = "any"


# ---------------------------------------------------------------- offensive
class OffensiveMission(Mission):
    """Attack towards an objective along an axis (without one: the corridor from its
    start to the objective); all members must be on the objective at the end."""
    PARAMS = {"objective": "overlay objective area", "axis": "optional route/axis of advance",
              "line_of_departure": "optional overlay line: crossing it is the attack's start"}
    REQUIRED = ("objective",)
    GEOMETRY_PARAMS = ("objective", "axis", "line_of_departure")
    LOCATION_RULE = "centroid"
    FINAL_RULE: ClassVar[str] = "all"
    DESIRED_STRENGTH_RATIO = 3.0
    PRIORITY = {"schedule": "immediate"}
    CHECKS = _checks("on its axis, or in the corridor from its start to the objective (out-of-position)",
                     "crossing its line of departure is its start (no confirmation needed)",
                     "hostiles on the axis ahead: go on if strong enough, else abort (threat-ahead, a decision)",
                     "on the objective at the end (Check-Final-Location)")
    END_STATE: ClassVar[bool] = False   # no hostile left in the objective at the end
    ESCAPE: ClassVar[bool] = False      # no hostile leaves the objective while it runs

    def location_constraints(self, ctx):
        if self.params.get("axis"):
            ctx.post_location_monitor(self, self.params["axis"], self.LOCATION_RULE, "axis")
        else:
            ctx.post_corridor(self, self.params["objective"])
        if self.params.get("line_of_departure"):
            ctx.post_line(self, self.params["line_of_departure"], "depart", toward=self.params["objective"])
        if self.ESCAPE:
            ctx.post_escape(self, self.params["objective"])

    def respond_to_threat_ahead(self, ctx, t, tracks, strength):
        """An attack expects the enemy: go on when strong enough for it (DESIRED_STRENGTH_RATIO), else abort."""
        ours = ctx.strength_of(self.unit)
        ok = strength <= 0 or ours / strength >= self.desired_strength_ratio()
        ctx.threat_ahead(self, t, tracks, strength, ["continue", "abort"], "continue" if ok else "abort")

    def check_final_location(self, ctx, t):
        ctx.check_location(self, self.params["objective"], self.FINAL_RULE, t, "objective")
        if self.END_STATE:
            ctx.check_end_state(self, self.params["objective"], t)


@mission
class Attack(OffensiveMission):
    """The offensive family as it is: all members on the objective at the end."""
    TYPE = "attack"


@mission
class HastyAttack(OffensiveMission):
    """Quick and partial: its centroid on the objective is enough."""
    TYPE = "hasty-attack"
    FINAL_RULE = "centroid"


@mission
class Seize(OffensiveMission):
    """Take possession: no hostile left on the objective at the end (end-state)."""
    TYPE = "seize"
    END_STATE = True
    CHECKS = OffensiveMission.CHECKS + ("no hostile on the objective at the end (end-state)",)


@mission
class Secure(OffensiveMission):
    """Take and protect: no hostile on the objective at the end (end-state)."""
    TYPE = "secure"
    END_STATE = True
    CHECKS = Seize.CHECKS


@mission
class Clear(OffensiveMission):
    """Remove all resistance: no hostile on the objective at the end (end-state)."""
    TYPE = "clear"
    END_STATE = True
    CHECKS = Seize.CHECKS


@mission
class Destroy(OffensiveMission):
    """Render the enemy ineffective: none escapes the objective, none is left at the end."""
    TYPE = "destroy"
    FINAL_RULE = "centroid"
    END_STATE = True
    ESCAPE = True
    CHECKS = Seize.CHECKS + ("no hostile leaves the objective while it runs (escape)",)


@mission
class Breach(OffensiveMission):
    """Through the obstacle: past its `obstacle` line by `by` (line); one element on the far
    side of the objective is enough at the end."""
    TYPE = "breach"
    PARAMS = {"obstacle": "optional overlay line of the obstacle ...", "by": "... the unit is past by this time"}
    GEOMETRY_PARAMS = ("objective", "axis", "line_of_departure", "obstacle")
    FINAL_RULE = "any"
    CHECKS = OffensiveMission.CHECKS + ("past its obstacle by its time (line)",)

    @classmethod
    def check_params(cls, params, overlay):
        if (params.get("obstacle") is None) != (params.get("by") is None):
            return "obstacle" if params.get("obstacle") is None else "by", "an obstacle needs both obstacle and by"
        return super().check_params(params, overlay)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        if self.params.get("obstacle"):
            ctx.post_line(self, self.params["obstacle"], "pass", float(self.params["by"]), toward=self.params["objective"])


@mission
class Isolate(OffensiveMission):
    """Seal the enemy off: no hostile leaves the objective while it runs (escape)."""
    TYPE = "isolate"
    FINAL_RULE = "centroid"
    ESCAPE = True
    CHECKS = OffensiveMission.CHECKS + ("no hostile leaves the objective while it runs (escape)",)


@mission
class Fix(OffensiveMission):
    """Keep the enemy where it is: none escapes the objective; 1:1 is enough."""
    TYPE = "fix"
    FINAL_RULE = "centroid"
    DESIRED_STRENGTH_RATIO = 1.0
    ESCAPE = True
    CHECKS = Isolate.CHECKS


# ---------------------------------------------------------------- position
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
    PENETRATION: ClassVar[bool] = False   # a hostile entering the position is a penetration
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
        if self.PENETRATION:
            ctx.post_penetration(self, self.params["position"])

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
    """The position family as it is."""
    TYPE = "occupy"


@mission
class Retain(PositionMission):
    """Keep the enemy out of the position: a hostile in it is a penetration."""
    TYPE = "retain"
    PENETRATION = True
    CHECKS = PositionMission.CHECKS + ("no hostile enters the position (penetration, projected before)",)


@mission
class Block(PositionMission):
    """Deny the enemy the position: a hostile in it is a penetration."""
    TYPE = "block"
    PRIORITY = {"hostile-expected": "immediate"}
    PENETRATION = True
    CHECKS = Retain.CHECKS


@mission
class AttackByFire(PositionMission):
    """Fires from a position: 1:1 wanted."""
    TYPE = "attack-by-fire"
    DESIRED_STRENGTH_RATIO = 1.0


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
    """Judged as the position family (its fires are not modelled)."""
    TYPE = "suppress"


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
    """Judged as the position family (its fires are not modelled)."""
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
    RED_KIND: ClassVar[str] = "monitored"
    CHECKS = _checks("an element on station while it runs and at the end (out-of-position)",
                     "hostiles in the watched area: unexpected activity (monitored)")

    def location_constraints(self, ctx):
        ctx.post_location_monitor(self, self.params["position"], self.LOCATION_RULE, "position")
        if self.RED_KIND == "penetration":
            ctx.post_penetration(self, self.params["area"])
        else:
            ctx.post_red_monitor(self, self.params["area"], expected=False)

    def check_final_location(self, ctx, t):
        ctx.check_location(self, self.params["position"], self.LOCATION_RULE, t, "position")


@mission
class Screen(SecurityMission):
    """Early warning without decisive engagement: keeps its standoff."""
    TYPE = "screen"
    STANDOFF = True
    CHECKS = SecurityMission.CHECKS + (_STANDOFF,)


@mission
class Guard(SecurityMission):
    """Protects the main body: a hostile in the guarded area is a penetration; 1:1 wanted."""
    TYPE = "guard"
    DESIRED_STRENGTH_RATIO = 1.0
    RED_KIND = "penetration"
    CHECKS = _checks("an element on station while it runs and at the end (out-of-position)",
                     "no hostile enters the guarded area (penetration, projected before)")


@mission
class Observe(SecurityMission):
    """An observation post: its position must hold some friendly element while it runs."""
    TYPE = "observe"
    CHECKS = SecurityMission.CHECKS + ("its post holds some friendly element while it runs (friendly-expected)",)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        ctx.post_held(self, self.params["position"])


@mission
class AreaReconnaissance(SecurityMission):
    """Judged as the security family (progress through the area not yet checked)."""
    TYPE = "area-reconnaissance"


@mission
class ZoneReconnaissance(SecurityMission):
    """Judged as the security family (progress through the zone not yet checked)."""
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
    CHECKS = ("both units with an element at the point within fuzz of `at` (coordination)",)

    def location_constraints(self, ctx):
        ctx.post_coordination(self, self.params["partner"], self.params["point"],
                              float(self.params["at"]), float(self.params.get("fuzz_s", ctx.voi(self, "schedule_s"))))


@mission
class LinkUp(CoordinationMission):
    """The coordination family as it is: both units meet at the point in time."""
    TYPE = "link-up"


@mission
class ReliefInPlace(CoordinationMission):
    """The unit relieves `partner` at `point`: besides meeting there, no gap (the partner
    does not leave before the unit is in)."""
    TYPE = "relief-in-place"
    CHECKS = CoordinationMission.CHECKS + ("no gap: the relieved unit stays until the relieving one is in (presence)",)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        ctx.post_presence(self, self.params["partner"], self.params["point"])


@mission
class PassageOfLines(CoordinationMission):
    """The unit passes through `partner`'s position at `point`: its elements there keep to
    the optional `lane`."""
    TYPE = "passage-of-lines"
    PARAMS = {"lane": "optional overlay area: the passing unit's elements at the point keep inside it"}
    GEOMETRY_PARAMS = ("point", "lane")
    CHECKS = CoordinationMission.CHECKS + ("its elements at the point inside its lane (presence)",)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        if self.params.get("lane"):
            ctx.post_presence(self, self.params["partner"], self.params["point"], self.params["lane"])


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
    CHECKS = ("its trigger (contingency); once triggered, its task as a monitored mission from then",)

    def contingency_satisfied(self, ctx):
        return ctx.evaluate_trigger(self.params["trigger"])

    def post_execution_constraints(self, ctx):
        ctx.post_contingency(self)


@mission
class Branch(ContingentMission):
    """An alternative course of action: also offered when a moving unit meets hostiles ahead."""
    TYPE = "branch"


@mission
class Sequel(ContingentMission):
    """What follows once its trigger holds (never offered as an alternative to a move)."""
    TYPE = "sequel"


# ---------------------------------------------------------------- reorganization
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


make = REGISTRY.make
