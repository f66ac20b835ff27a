"""The root of the SUO mission model: the monitoring methods every mission has, the
registry of leaf classes, the default priorities and the small helpers the families share."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, ClassVar

from ea_agent.core.mission import Mission as CoreMission, Registry

if TYPE_CHECKING:  # the domain implements the monitoring API used here
    from ..domain import SuoDomain

REGISTRY = Registry()

DEFAULT_PRIORITY = {
    "fratricide": "flash", "contact": "flash", "call-for-fire": "flash",
    "out-of-position": "immediate", "coordination": "immediate", "contingency": "immediate",
    "distance": "immediate", "strength": "immediate", "proximity": "immediate",
    "schedule": "priority", "unknown-position": "priority", "monitored": "priority",
    "hostile-expected": "priority", "ave-of-approach": "routine",
    "penetration": "immediate", "projected-penetration": "immediate", "escape": "immediate",
    "end-state": "immediate", "friendly-expected": "immediate", "band": "immediate", "threat-ahead": "immediate",
    "checkpoint": "priority", "line": "immediate", "standoff": "immediate", "fire-support": "immediate",
    "presence": "immediate", "recon-progress": "priority",
}


mission = REGISTRY.leaf   # registers a leaf mission class under its doctrine name


class Mission(CoreMission):
    """Root of the SUO model: time constraints (from the core), places on the
    overlay, and how hostile activity near the unit is judged. Check-Initial-Location
    judges at once, from the current picture, every place constraint the mission posted
    (a unit that never moves is judged too); the EA re-checks them on scenario time."""
    PARAMS = {
        "voi": "optional per-mission VOI overrides, e.g. {out_of_position_m: 100, schedule_s: 10}",
        "fires": "optional planned fires [{cff, window: [from, until], requester?}]: each confirmed in its "
                 "window (fire-support; detect/windows.py)",
    }
    GEOMETRY_PARAMS: ClassVar[tuple[str, ...]] = ()   # params that name overlay features
    LINE_PARAMS = ("route", "axis", "rear_line", "line", "obstacle", "line_of_departure")
    LOCATION_RULE: ClassVar[str] = "centroid"         # centroid | any | all members
    DESIRED_STRENGTH_RATIO: ClassVar[float] = 1.0     # friendly:hostile combat power wanted
    DEFAULT_PRIORITY = DEFAULT_PRIORITY
    CHECKS = ("start/end time constraints (Fig. 6); ON-ORDER against the superior's order",
              "place constraints judged at start, on every move and every scan (stationary units too)")

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


_STANDOFF = "no hostile within its standoff distance (standoff)"


def _time_problem(params: dict, key: str) -> tuple[str, str] | None:
    """What is wrong with an optional scenario-time parameter `key`, if anything."""
    v = params.get(key)
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
        return key, "expected a scenario time >= 0"
    return None


def _post_by(mission, ctx, place: str, rule: str) -> None:
    """With an optional `by` time, the unit is at `place` (by `rule`) by then: what a move, a
    seize and an occupy are for (being there when the plan needs it), not only at the end."""
    if mission.params.get("by") is not None:
        ctx.post_deadline(mission, float(mission.params["by"]), mission.params[place], rule)


def _positive_problem(params: dict, key: str, expected: str) -> tuple[str, str] | None:
    """What is wrong with an optional parameter `key` that must be a number > 0, if anything."""
    v = params.get(key)
    if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0):
        return key, expected
    return None


def _window_problem(params: dict, key: str) -> tuple[str, str] | None:
    """What is wrong with a [from, until] window of scenario times `key`, if anything."""
    w = params.get(key)
    if w is None:
        return None
    if (not isinstance(w, list) or len(w) != 2 or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                                                           and math.isfinite(x) for x in w)):
        return key, "expected [from, until] in scenario seconds"
    if not 0 <= w[0] < w[1]:
        return key, f"from {w[0]} not before until {w[1]} (or negative)"
    return None
