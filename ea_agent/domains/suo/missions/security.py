"""Security and reconnaissance missions: keep station, watch an area."""
from __future__ import annotations

from typing import ClassVar

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
