"""The detector component interface that SuoDomain composes.

A detector owns one alert family: the monitors mission methods post to it, the
state it keeps between epochs, and how it finds candidates. It is built with the
domain it reads (picture, task organization, plan, VOI thresholds) and never
talks to another detector except through the domain's named components.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar

from ea_agent.core.alert import Candidate
from ea_agent.core.plan import MissionSpec, TaskOrg

from ..missions import Mission

if TYPE_CHECKING:
    from ..domain import SuoDomain

BASE = Mission(MissionSpec("-", "-", "mission"))   # defaults for units without an active mission


@dataclass(slots=True)
class Changes:
    """What changed in the epoch being closed: detectors look only at these, so
    what did not change costs nothing."""
    leaves: set[str]   # leaf units with a new member position
    units: set[str]    # those leaves and all their superiors
    tracks: set[str]   # hostile tracks whose adjudicated state changed
    rescan: bool       # the periodic scan is due (silent units, expiry-driven reminders)


class Detector:
    """One alert family. Every hook has a do-nothing default; a detector overrides
    only what it needs."""
    TYPES: ClassVar[dict[str, str]] = {}   # alert type -> Fig. 1 category (assembled into CATEGORY)
    FACTS: ClassVar[tuple[type, ...]] = ()  # fact kinds routed to on_fact

    def __init__(self, dom: SuoDomain) -> None:
        self.dom = dom

    def bind(self, ea) -> None:
        """The EA manager exists: timers and post are available."""

    def reset(self) -> None:
        """Plan aborted or replaced: forget the monitors the old plan posted."""

    def org_changed(self) -> None:
        """The task organization changed (also called once at start)."""

    def end_mission(self, mid: str) -> None:
        """Mission `mid` ended: drop its monitors."""

    def on_fact(self, f) -> None:
        """A fact of one of the kinds in FACTS."""

    def observe(self, t: float, ch: Changes) -> None:
        """Epoch phase 1, before any detector runs: update state others read."""

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        """Epoch phase 2: append this epoch's candidates (timers and immediate
        checks post through the EA instead)."""


def platoon_of(taskorg: TaskOrg, unit: str) -> str:
    """The unit a fire-control alert names: the nearest platoon or higher."""
    for u in [unit, *taskorg.ancestors(unit)]:
        if taskorg.units[u].kind in ("platoon", "company", "battalion"):
            return u
    return unit
