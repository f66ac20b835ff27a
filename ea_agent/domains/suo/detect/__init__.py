"""The SUO detectors, one module per alert family, and their registration.

DETECTORS is the one list to extend with a new family. Its order is the order
of Fig. 4 (CATEGORY and ALERT_TYPES follow it, and so do the CLI's columns) and
the order in which detectors run each epoch. Detectors are independent (the
manager sorts candidates before VOA) except that Contingencies runs before
Areas, which does not repeat the activity a fired contingency already told.
"""
from __future__ import annotations

from .ahead import ThreatsAhead
from .areas import Areas
from .assume import Assumptions
from .bands import Bands
from .base import BASE, Changes, Detector
from .checkpoints import Checkpoints
from .contingency import Contingencies
from .coordination import Coordination
from .coverage import Coverage
from .endstate import EndStates
from .escape import Escapes
from .fires import CallsForFire
from .fratricide import Fratricide
from .lines import Lines
from .location import LocationMonitors
from .opportunity import Opportunities
from .penetration import ProjectedPenetrations
from .presence import Presence
from .projection import Projections
from .recon import ReconProgress
from .schedule import ScheduleMonitors
from .standoff import Standoffs
from .support import FireSupport
from .tempo import Tempo
from .threats import ThreatEnvelopes
from .unknown import UnknownPositions
from .windows import Windows

DETECTORS: tuple[type[Detector], ...] = (
    Fratricide, CallsForFire, LocationMonitors, Coordination, ScheduleMonitors, UnknownPositions,
    Contingencies, Areas, ThreatEnvelopes, Projections,
    # the check families the mission classes compose beyond Fig. 4 (issue 13)
    Escapes, EndStates, Coverage, Bands, ProjectedPenetrations, ThreatsAhead, Checkpoints, Lines, Standoffs,
    FireSupport, Presence, ReconProgress, Tempo, Assumptions,
    Windows,   # doctrinal time windows (link-up, passage of lines, planned fires): in-window timers
    # new opportunities (Fig. 1, issue 53): what favours the plan
    Opportunities,
)

CATEGORY: dict[str, str] = {typ: cat for d in DETECTORS for typ, cat in d.TYPES.items()}
PROJECTED = tuple(k for k, c in CATEGORY.items() if c == "constraint-violation-projected")   # beyond the paper
ALERT_TYPES = tuple(k for k in CATEGORY if k != "call-for-fire")  # the 13 of Fig. 4, projections, check families

__all__ = ["DETECTORS", "CATEGORY", "ALERT_TYPES", "BASE", "Changes", "Detector", "Areas", "Assumptions", "Bands", "CallsForFire",
           "Checkpoints", "Contingencies", "Coordination", "Coverage", "EndStates", "Escapes", "FireSupport", "Fratricide",
           "Lines", "LocationMonitors", "Opportunities", "Presence", "ProjectedPenetrations", "ReconProgress",
           "ScheduleMonitors", "Standoffs", "Tempo", "ThreatEnvelopes", "ThreatsAhead", "UnknownPositions", "Windows"]
