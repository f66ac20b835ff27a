"""The UV mission model (paper 7): robot recipes whose methods say how each task is
monitored. The EA calls these methods; they post monitors back through `ctx` (the
UvDomain's monitoring API), the same method API as the SUO missions.

Moving tasks (goto, patrol, search, pursue) are watched for stuck; goto also for
at-goal and divergent; target tasks for sightings. Robots have no human to confirm
a start, so every recipe is executed by the EA itself (`AUTO_START`).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, ClassVar

from ea_agent.core.mission import Mission as CoreMission, Registry

if TYPE_CHECKING:  # the domain implements the monitoring API used here
    from .domain import UvDomain

REGISTRY = Registry()

DEFAULT_PRIORITY = {
    "collision": "flash",
    "lost-target": "immediate", "target-gone": "immediate", "target-visible": "immediate",
    "stuck": "immediate", "divergent": "immediate", "no-status": "priority",
    "handoff": "priority", "at-goal": "routine", "schedule": "priority",
}

mission = REGISTRY.leaf


class Mission(CoreMission):
    """Root of the UV model: time constraints from the core, world places by name,
    and whether the robot is expected to move (stuck applies)."""
    PARAMS = {"voi": "optional per-mission VOI overrides"}
    PLACE_PARAMS: ClassVar[tuple[str, ...]] = ()    # params naming world places
    PLACE_KINDS: ClassVar[dict[str, tuple[str, ...]]] = {}   # param -> allowed place kinds
    MOVING: ClassVar[bool] = True                   # stuck applies while active
    TARGET_PARAM: ClassVar[str | None] = None       # param naming the target watched
    DEFAULT_PRIORITY = DEFAULT_PRIORITY
    AUTO_START = True

    def goal(self) -> str | None:
        """The waypoint place this task drives to, if any (at-goal/divergent)."""
        return None

    def area(self) -> str | None:
        """The place the robot works in (patrol/search area), if any."""
        return self.params.get("area")

    def target(self) -> str | None:
        return self.params.get(self.TARGET_PARAM) if self.TARGET_PARAM else None

    def location_constraints(self, ctx: "UvDomain") -> None:
        if self.MOVING:
            ctx.watch_progress(self)
        if self.target():
            ctx.watch_target(self, self.target())

    def on_target_visible(self, ctx: "UvDomain", target: str, t: float) -> None:
        """A target was sighted while this task was active; most tasks only report it."""

    def on_lost_target(self, ctx: "UvDomain", target: str, t: float) -> None:
        """The watched target is lost past the policy interval."""


@mission
class Goto(Mission):
    """Drive to a waypoint; done when within its radius (at-goal)."""
    TYPE = "goto"
    PARAMS = {"waypoint": "world waypoint to reach"}
    REQUIRED = ("waypoint",)
    PLACE_PARAMS = ("waypoint",)
    PLACE_KINDS = {"waypoint": ("waypoint", "base")}

    def goal(self) -> str | None:
        return self.params["waypoint"]

    def location_constraints(self, ctx: "UvDomain") -> None:
        super().location_constraints(ctx)
        ctx.watch_goal(self, self.params["waypoint"])

    def check_final_location(self, ctx: "UvDomain", t: float) -> None:
        ctx.check_at_goal(self, self.params["waypoint"], t)


@mission
class Patrol(Mission):
    """Patrol an area; on a sighting commit to pursue (policy), inside `sector`."""
    TYPE = "patrol"
    PARAMS = {"area": "world patrol-area", "sector": "optional world sector for pursuits"}
    REQUIRED = ("area",)
    PLACE_PARAMS = ("area", "sector")
    PLACE_KINDS = {"area": ("patrol-area", "sector"), "sector": ("sector", "patrol-area")}

    # the commitment is the policies' (policies.step): a sighting inside the sector, no cooldown


@mission
class Search(Mission):
    """Search an area for a target; reports sightings."""
    TYPE = "search"
    PARAMS = {"area": "world area searched", "target": "target looked for"}
    REQUIRED = ("area", "target")
    PLACE_PARAMS = ("area",)
    PLACE_KINDS = {"area": ("patrol-area", "sector")}
    TARGET_PARAM = "target"

    def on_target_visible(self, ctx: "UvDomain", target: str, t: float) -> None:
        if target == self.params["target"]:   # found: the search is done
            ctx.end_mission(self, t)


@mission
class Pursue(Mission):
    """Follow a target inside a sector: lost-target, target-gone and handoff apply."""
    TYPE = "pursue"
    PARAMS = {"target": "target pursued", "sector": "world sector the pursuit is confined to"}
    REQUIRED = ("target", "sector")
    PLACE_PARAMS = ("sector",)
    PLACE_KINDS = {"sector": ("sector", "patrol-area")}
    TARGET_PARAM = "target"

    def area(self) -> str | None:
        return self.params.get("sector")

    # dropped by the policies (policies.step) when its robot has not seen the target for drop_s


@mission
class Photograph(Mission):
    """Photograph a target every `every_s`: a repeating near-time constraint per photo."""
    TYPE = "photograph"
    PARAMS = {"target": "target photographed", "every_s": "seconds between photos"}
    REQUIRED = ("target", "every_s")
    MOVING = False
    TARGET_PARAM = "target"

    def location_constraints(self, ctx: "UvDomain") -> None:
        ctx.post_photo_schedule(self, float(self.params["every_s"]))
