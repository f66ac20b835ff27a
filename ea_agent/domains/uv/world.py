"""The UV world: named places (waypoints, patrol areas, sectors, obstacles, the
operator's base) in projected metres, as read from a scenario's world.geojson."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

KINDS = ("obstacle", "waypoint", "patrol-area", "sector", "base")


@dataclass(slots=True)
class Place:
    id: str
    kind: str            # one of KINDS
    geom: Any            # shapely geometry, projected metres
    props: dict = field(default_factory=dict)   # e.g. radius_m of a waypoint
