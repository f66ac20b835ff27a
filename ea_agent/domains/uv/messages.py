"""UV robot-team messages (paper 7): robot state at 2 Hz, target sightings, and
agent-to-agent task messages (delegate/accept/success/failure).

Each class carries its key template (`KEY`) from docs/uv-domain.md so
the mesh and the loader agree with the EA on where a message is published.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, ClassVar, Literal

import msgspec

from ea_agent.core.messages import Lat, Lon, NUMERIC, Text, Time, Typed, bounded, checked, register

MAX_SPEED_MPS = 100.0
MODES = ("moving", "paused", "waiting-gps")
ACTS = ("delegate", "accept", "success", "failure")
Speed = bounded(0.0, MAX_SPEED_MPS)
Heading = Annotated[float, msgspec.Meta(ge=0.0, lt=360.0)]   # 360 itself is not a heading (it is 0)
Sigma = bounded(0.0, 1e6)


@dataclass(slots=True, frozen=True)
class UvState(Typed):
    """A robot's own state report: position, speed, heading, GPS error and mode."""
    KIND: ClassVar[str] = "uv-state"
    KEY: ClassVar[str] = "st/{place}/{robot}"
    t: Time
    robot: Text
    lon: Lon
    lat: Lat
    speed_mps: Speed
    heading_deg: Heading
    sigma_m: Sigma
    mode: Literal["moving", "paused", "waiting-gps"]

    @classmethod
    def from_dict(cls, d: dict) -> "UvState":
        # Fast path for the most frequent message (NaN fails every comparison);
        # anything odd takes the validating path, which names the bad field.
        t, r, lon, lat = d.get("t"), d.get("robot"), d.get("lon"), d.get("lat")
        v, h, s, m = d.get("speed_mps"), d.get("heading_deg"), d.get("sigma_m"), d.get("mode")
        if (type(t) in NUMERIC and type(lon) in NUMERIC and type(lat) in NUMERIC and type(v) in NUMERIC
                and type(h) in NUMERIC and type(s) in NUMERIC and type(r) is str and r and m in MODES
                and 0.0 <= t <= 1e15 and -180.0 <= lon <= 180.0 and -90.0 <= lat <= 90.0
                and 0.0 <= v <= MAX_SPEED_MPS and 0.0 <= h < 360.0 and 0.0 <= s <= 1e6):
            return cls(float(t), r, float(lon), float(lat), float(v), float(h), float(s), m)
        return cls(**checked(cls, d))


@dataclass(slots=True, frozen=True)
class UvSighting(Typed):
    """`robot`'s sensor sees `target` at (lon, lat) with error `sigma_m`."""
    KIND: ClassVar[str] = "uv-sighting"
    KEY: ClassVar[str] = "sgt/{place}/{robot}/{target}"
    t: Time
    robot: Text
    target: Text
    lon: Lon
    lat: Lat
    sigma_m: Sigma


@dataclass(slots=True, frozen=True)
class UvAgent(Typed):
    """An agent-to-agent task message (paper 7.2): `sender` delegates `task` to `to`,
    `to` accepts it, or reports success/failure. `target` names a pursued target."""
    KIND: ClassVar[str] = "uv-agent"
    KEY: ClassVar[str] = "agm/{to}/{sender}"
    t: Time
    sender: Text
    to: Text
    act: Literal["delegate", "accept", "success", "failure"]
    task: Text
    target: Text | None = None


register(UvState, UvSighting, UvAgent)
