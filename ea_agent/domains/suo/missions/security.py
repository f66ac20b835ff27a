"""Security and reconnaissance missions: keep station, watch an area."""
from __future__ import annotations

import math

from .base import Mission, _STANDOFF, _checks, mission


class SecurityMission(Mission):
    """Screen/observe an area: any element on station is enough; any hostile
    activity in the watched area is unexpected and reported at once."""
    PARAMS = {"position": "overlay area or line the unit keeps", "area": "overlay area watched"}
    REQUIRED = ("position", "area")
    GEOMETRY_PARAMS = ("position", "area")
    LOCATION_RULE = "any"
    DESIRED_STRENGTH_RATIO = 0.5
    PRIORITY = {"monitored": "immediate"}
    CHECKS = _checks("an element on station while it runs and at the end (out-of-position)",
                     "hostiles in the watched area: unexpected activity (monitored)")

    def location_constraints(self, ctx):
        ctx.post_location_monitor(self, self.params["position"], self.LOCATION_RULE, "position")
        self.watch_area(ctx)

    def watch_area(self, ctx) -> None:
        """Hostiles in the watched area are unexpected activity, told at once."""
        ctx.post_red_monitor(self, self.params["area"], expected=False)

    def check_final_location(self, ctx, t):
        ctx.check_location(self, self.params["position"], self.LOCATION_RULE, t, "position")


@mission
class Screen(SecurityMission):
    """Early warning without decisive engagement: keeps its standoff."""
    TYPE = "screen"
    CHECKS = SecurityMission.CHECKS + (_STANDOFF,)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        ctx.post_standoff(self)


@mission
class Guard(SecurityMission):
    """Protects the main body: a hostile in the guarded area is a penetration; 1:1 wanted."""
    TYPE = "guard"
    DESIRED_STRENGTH_RATIO = 1.0
    CHECKS = _checks("an element on station while it runs and at the end (out-of-position)",
                     "no hostile enters the guarded area (penetration, projected before)")

    def watch_area(self, ctx):
        """The guarded area is the main body's: a hostile in it has got past the guard."""
        ctx.post_penetration(self, self.params["area"])


@mission
class Observe(SecurityMission):
    """An observation post: its position must hold some friendly element while it runs."""
    TYPE = "observe"
    CHECKS = SecurityMission.CHECKS + ("its post holds some friendly element while it runs (friendly-expected)",)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        ctx.post_held(self, self.params["position"])


class ReconnaissanceMission(SecurityMission):
    """Reconnaissance of a zone or an area, finished by `by` (or the mission's END-NLT/END-AT
    time); hostiles found in it are what it looks for, and are reported at once as in the
    security family. How its progress is measured is its class's (`post_progress`)."""
    PARAMS = {"by": "optional scenario time by which all of it must be seen (default: its end time)"}

    def by(self) -> float | None:
        if self.params.get("by") is not None:
            return float(self.params["by"])
        end = self.spec.end
        return float(end.t) if end.type in ("END-NLT", "END-AT") and end.t is not None else None

    @classmethod
    def check_params(cls, params, overlay):
        by = params.get("by")
        if by is not None and (isinstance(by, bool) or not isinstance(by, (int, float)) or not math.isfinite(by) or by < 0):
            return "by", "expected a scenario time >= 0"
        return super().check_params(params, overlay)

    def location_constraints(self, ctx):
        super().location_constraints(ctx)
        self.post_progress(ctx)

    def post_progress(self, ctx) -> None:
        """How its progress through its area is measured: the family has no measure of its
        own (coverage is an area's, depth a zone's); its leaves give theirs."""

    def check_initial_location(self, ctx, t):
        super().check_initial_location(ctx, t)
        ctx.start_recon(self)

    def check_final_location(self, ctx, t):
        super().check_final_location(ctx, t)
        ctx.check_recon(self, t)


@mission
class AreaReconnaissance(ReconnaissanceMission):
    """A named area, in any order (FM 3-90): its elements come within sight of all of it."""
    TYPE = "area-reconnaissance"
    CHECKS = SecurityMission.CHECKS + (
        "coverage: the share of the area seen against the share of its time gone, and most of it seen at "
        "its end (recon-progress)",)

    def post_progress(self, ctx):
        ctx.post_recon(self, self.params["area"], self.by(), "coverage")


@mission
class ZoneReconnaissance(ReconnaissanceMission):
    """Everything between its boundaries, front to rear (FM 3-90): its progress is the depth of
    the zone passed (every band across it seen, from the side the unit starts on), against the
    share of its time gone; a gap left behind holds the depth there."""
    TYPE = "zone-reconnaissance"
    CHECKS = SecurityMission.CHECKS + (
        "progress front to rear: the depth of the zone passed (each band across it seen) against the share "
        "of its time gone, and most of its depth passed at its end (recon-progress)",)

    def post_progress(self, ctx):
        ctx.post_recon(self, self.params["area"], self.by(), "depth")
