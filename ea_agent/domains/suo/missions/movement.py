"""Movement missions: along a route (or a corridor) to a destination."""
from __future__ import annotations

import math
from typing import ClassVar

from .base import Mission, _positive_problem, _post_by, _STANDOFF, _band_problem, _checks, _time_problem, mission


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
    """Go from one place to another (FM 3-90's movement): the point of it is being there when
    the plan needs the unit, so with `by` the unit is at its destination by then, not only at
    its end (out-of-position, check `by`)."""
    TYPE = "move"
    PARAMS = {"by": "optional scenario time by which the unit is at its destination (default: its end)"}
    CHECKS = MovementMission.CHECKS + ("at its destination by its `by` time (out-of-position)",)

    @classmethod
    def check_params(cls, params, overlay):
        return _time_problem(params, "by") or super().check_params(params, overlay)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        _post_by(self, ctx, "destination", self.LOCATION_RULE)


@mission
class TacticalRoadMarch(MovementMission):
    """A march in column (FM 3-90): march tables (its `checkpoints`: start point, checkpoints,
    release point) are tightly timed, so schedule and checkpoint alerts are IMMEDIATE; and the
    column keeps its march interval to the serial ahead (`ahead`, `interval_m` [min, max]):
    closing up or falling back breaks the march table of every serial behind (band)."""
    TYPE = "tactical-road-march"
    PARAMS = {"ahead": "optional march unit (serial) ahead of it in the column",
              "interval_m": "optional [min, max] distance to the serial ahead (needs ahead)"}
    UNIT_PARAMS = ("ahead",)
    PRIORITY = {"schedule": "immediate", "checkpoint": "immediate"}
    CHECKS = MovementMission.CHECKS + ("its march interval to the serial ahead kept (band)",)

    @classmethod
    def check_params(cls, params, overlay):
        if (params.get("ahead") is None) != (params.get("interval_m") is None):
            return ("ahead" if params.get("ahead") is None else "interval_m",
                    "a march interval needs both ahead and interval_m")
        problem = _band_problem({"band_m": params.get("interval_m")})
        if problem:
            return "interval_m", problem[1]
        return super().check_params(params, overlay)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        if self.params.get("ahead"):
            lo, hi = self.params["interval_m"]
            ctx.post_band(self, self.params["ahead"], float(lo), float(hi))


@mission
class MovementToContact(MovementMission):
    """Develops the situation and gains contact (FM 3-90): it expects the enemy (2:1 wanted
    before a threat is only PRIORITY), and it stops at its `limit` of advance: across it, the
    unit has gone beyond where the plan lets it look for contact (line, check `limit`)."""
    TYPE = "movement-to-contact"
    PARAMS = {"limit": "optional overlay line: its limit of advance, not crossed while it runs"}
    GEOMETRY_PARAMS = ("route", "destination", "limit")
    LINE_PARAMS = Mission.LINE_PARAMS + ("limit",)
    DESIRED_STRENGTH_RATIO = 2.0
    CHECKS = MovementMission.CHECKS + ("not across its limit of advance (line)",)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        if self.params.get("limit"):
            ctx.post_line(self, self.params["limit"], "limit")


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
        self.post_follow_band(ctx, float(lo), float(hi))

    def post_follow_band(self, ctx, lo: float, hi: float) -> None:
        ctx.post_band(self, self.params["supported"], lo, hi)


@mission
class FollowAndSupport(FollowMission):
    """Follows a committed unit to support it (FM 3-90): within its band of it, and behind it:
    with `toward` (the place the supported unit attacks or moves to), nearer that place than the
    supported unit is, it has passed the unit it supports (band, check `ahead`)."""
    TYPE = "follow-and-support"
    PARAMS = {"toward": "optional overlay feature the supported unit goes to: the follower stays farther from it"}
    GEOMETRY_PARAMS = ("route", "destination", "toward")
    CHECKS = FollowMission.CHECKS + ("not ahead of the supported unit towards where it goes (band)",)

    def post_follow_band(self, ctx, lo, hi):
        ctx.post_band(self, self.params["supported"], lo, hi, behind=self.params.get("toward"))


@mission
class FollowAndAssume(FollowMission):
    """Ready to take over the supported unit's mission (FM 3-90): when that unit halts short of
    its goal for `halt_s`, or its mission is aborted (committed elsewhere), the EA says so and
    from then monitors that mission as the follower's own (contingency)."""
    TYPE = "follow-and-assume"
    PARAMS = {"halt_s": "optional: the supported unit standing this long short of its goal has halted (default 180)"}
    HALT_S: ClassVar[float] = 180.0
    CHECKS = FollowMission.CHECKS + (
        "the supported unit halted or its mission aborted: its mission assumed and monitored as the follower's "
        "(contingency)",)

    @classmethod
    def check_params(cls, params, overlay):
        return _positive_problem(params, "halt_s", "expected a time > 0 in seconds") or super().check_params(params, overlay)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        ctx.post_assume(self, self.params["supported"], float(self.params.get("halt_s", self.HALT_S)))


@mission
class Withdraw(MovementMission):
    """Breaking contact: keeps its standoff; accepts 1:2 before a threat is IMMEDIATE."""
    TYPE = "withdraw"
    DESIRED_STRENGTH_RATIO = 0.5
    CHECKS = MovementMission.CHECKS + (_STANDOFF,)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        ctx.post_standoff(self)


@mission
class Delay(MovementMission):
    """Trades space for time: stays forward of its `line` until `until` (line); accepts 1:3
    before a threat is IMMEDIATE."""
    TYPE = "delay"
    PARAMS = {"line": "optional overlay line the unit holds forward of ...", "until": "... until this time"}
    GEOMETRY_PARAMS = ("route", "destination", "line")
    DESIRED_STRENGTH_RATIO = 0.33
    CHECKS = MovementMission.CHECKS + ("forward of its line until its time (line)", _STANDOFF)

    @classmethod
    def check_params(cls, params, overlay):
        if (params.get("line") is None) != (params.get("until") is None):
            return "line" if params.get("line") is None else "until", "a delay line needs both line and until"
        return super().check_params(params, overlay)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        ctx.post_standoff(self)
        if self.params.get("line"):
            ctx.post_line(self, self.params["line"], "hold", float(self.params["until"]))


@mission
class Bypass(MovementMission):
    """Moves around an obstacle, position or enemy force to keep its momentum (FM 3-90): keeps
    its standoff, and stays out of the `bypassed` area (in it, it is not bypassing but going
    through: standoff, check `bypassed`)."""
    TYPE = "bypass"
    PARAMS = {"bypassed": "optional overlay area (the obstacle or enemy position) the unit goes around"}
    GEOMETRY_PARAMS = ("route", "destination", "bypassed")
    CHECKS = MovementMission.CHECKS + (_STANDOFF, "its centroid never inside the area it bypasses (standoff)")

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        ctx.post_standoff(self, self.params.get("bypassed"))


@mission
class RouteReconnaissance(MovementMission):
    """Information on a route (FM 3-90): one element on it is enough, its `checkpoints` say how
    far along it should be when, and every section of its `route` must be seen by `by` (or its
    END-NLT/END-AT time): a section left unseen is progress behind, or incomplete at its end
    (recon-progress)."""
    TYPE = "route-reconnaissance"
    PARAMS = {"by": "optional scenario time by which all of its route must be seen (default: its end time)"}
    LOCATION_RULE = "any"
    CHECKS = MovementMission.CHECKS + (
        "every section of its route seen: behind its time, or incomplete at its end (recon-progress)",)

    @classmethod
    def check_params(cls, params, overlay):
        return _time_problem(params, "by") or super().check_params(params, overlay)

    def by(self) -> float | None:
        if self.params.get("by") is not None:
            return float(self.params["by"])
        end = self.spec.end
        return float(end.t) if end.type in ("END-NLT", "END-AT") and end.t is not None else None

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        if self.params.get("route"):
            ctx.post_recon(self, self.params["route"], self.by())

    def check_initial_location(self, ctx, t):
        super().check_initial_location(ctx, t)
        ctx.start_recon(self)

    def check_final_location(self, ctx, t):
        super().check_final_location(ctx, t)
        ctx.check_recon(self, t)
