"""Offensive missions: towards an objective, and what each leaves there."""
from __future__ import annotations

from typing import ClassVar

from .base import Mission, _checks, _positive_problem, _post_by, _time_problem, mission


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

    def location_constraints(self, ctx):
        if self.params.get("axis"):
            ctx.post_location_monitor(self, self.params["axis"], self.LOCATION_RULE, "axis")
        else:
            ctx.post_corridor(self, self.params["objective"])
        if self.params.get("line_of_departure"):
            ctx.post_line(self, self.params["line_of_departure"], "depart", self.departure_by(),
                          toward=self.params["objective"])

    def departure_by(self) -> float | None:
        """When its line of departure must be crossed (None: whenever it starts)."""
        return None

    def respond_to_threat_ahead(self, ctx, t, tracks, strength):
        """An attack expects the enemy: go on when strong enough for it (DESIRED_STRENGTH_RATIO), else abort."""
        ours = ctx.strength_of(self.unit)
        ok = strength <= 0 or ours / strength >= self.desired_strength_ratio()
        ctx.threat_ahead(self, t, tracks, strength, ["continue", "abort"], "continue" if ok else "abort")

    def check_final_location(self, ctx, t):
        ctx.check_location(self, self.params["objective"], self.FINAL_RULE, t, "objective")


@mission
class Attack(OffensiveMission):
    """A deliberate attack (FM 3-90): all members on the objective at the end, and launched at
    its time: with `h_hour`, the unit across its line of departure by then, or the attack the
    plan synchronized (fires, adjacent units) has not begun (line, check `depart`)."""
    TYPE = "attack"
    PARAMS = {"h_hour": "optional scenario time by which it crosses its line_of_departure (needs one)"}
    CHECKS = OffensiveMission.CHECKS + ("across its line of departure by its H-hour (line)",)

    @classmethod
    def check_params(cls, params, overlay):
        if params.get("h_hour") is not None and params.get("line_of_departure") is None:
            return "line_of_departure", "an H-hour needs the line of departure crossed at it"
        return _time_problem(params, "h_hour") or super().check_params(params, overlay)

    def departure_by(self):
        return float(self.params["h_hour"]) if self.params.get("h_hour") is not None else None


@mission
class HastyAttack(OffensiveMission):
    """Trades preparation for speed to exploit an opportunity (FM 3-90): partial, so its
    centroid on the objective is enough; and quick: with `within_s`, on the objective that long
    after its start, or the opportunity it was launched for is gone (out-of-position, check `by`)."""
    TYPE = "hasty-attack"
    PARAMS = {"within_s": "optional: on the objective this long after its start"}
    FINAL_RULE = "centroid"
    CHECKS = OffensiveMission.CHECKS + ("on the objective within its time from its start (out-of-position)",)

    @classmethod
    def check_params(cls, params, overlay):
        return _positive_problem(params, "within_s", "expected a time > 0 in seconds") or \
            super().check_params(params, overlay)

    def check_initial_location(self, ctx, t):
        super().check_initial_location(ctx, t)
        if self.params.get("within_s") is not None:
            ctx.post_deadline(self, t + float(self.params["within_s"]), self.params["objective"], self.FINAL_RULE)


@mission
class Seize(OffensiveMission):
    """Take possession (FM 3-90): its own elements on the objective at the end, and by its
    optional `by` (the time the plan needs the objective in hand) if that comes first. No
    judgement of hostiles left there: that is clear's."""
    TYPE = "seize"
    PARAMS = {"by": "optional scenario time by which all its elements are on the objective (default: its end)"}
    CHECKS = OffensiveMission.CHECKS + ("all its elements on the objective by its `by` time (out-of-position)",)

    @classmethod
    def check_params(cls, params, overlay):
        return _time_problem(params, "by") or super().check_params(params, overlay)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        _post_by(self, ctx, "objective", self.FINAL_RULE)


@mission
class Secure(OffensiveMission):
    """Protect the objective from the enemy while the mission runs (FM 3-90): a hostile in it at
    any time is a penetration (projected before it enters); no end-state clearance is asked."""
    TYPE = "secure"
    CHECKS = OffensiveMission.CHECKS + ("no hostile in the objective while it runs (penetration, projected before)",)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        ctx.post_penetration(self, self.params["objective"])


@mission
class Clear(OffensiveMission):
    """Remove all resistance: no hostile left on the objective at the end (end-state)."""
    TYPE = "clear"
    CHECKS = OffensiveMission.CHECKS + ("no hostile on the objective at the end (end-state)",)

    def check_final_location(self, ctx, t):
        super().check_final_location(ctx, t)
        ctx.check_end_state(self, self.params["objective"], t)


@mission
class Destroy(OffensiveMission):
    """Render the enemy ineffective: none escapes the objective, none is left at the end."""
    TYPE = "destroy"
    FINAL_RULE = "centroid"
    CHECKS = Clear.CHECKS + ("no hostile leaves the objective while it runs (escape)",)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        ctx.post_escape(self, self.params["objective"])

    def check_final_location(self, ctx, t):
        super().check_final_location(ctx, t)
        ctx.check_end_state(self, self.params["objective"], t)


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
    CHECKS = OffensiveMission.CHECKS + ("no hostile leaves the objective while it runs (escape)",)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        ctx.post_escape(self, self.params["objective"])


@mission
class Fix(OffensiveMission):
    """Keep the enemy from moving from a place for a period (FM 3-90): none escapes the
    objective, until its `until` if given (after it, the enemy may go: no escape told); 1:1 is
    enough."""
    TYPE = "fix"
    PARAMS = {"until": "optional scenario time the enemy is held there until (default: while it runs)"}
    FINAL_RULE = "centroid"
    DESIRED_STRENGTH_RATIO = 1.0
    CHECKS = OffensiveMission.CHECKS + ("no hostile leaves the objective while it runs, until its time (escape)",)

    @classmethod
    def check_params(cls, params, overlay):
        return _time_problem(params, "until") or super().check_params(params, overlay)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        until = self.params.get("until")
        ctx.post_escape(self, self.params["objective"], float(until) if until is not None else None)
