"""UV robot-team messages (paper 7): robot state at 2 Hz, target sightings, and
agent-to-agent task messages (delegate/accept/success/failure).

Each class carries its key template (`KEY`) from docs/uv-domain.md so
the mesh and the loader agree with the EA on where a message is published.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, ClassVar, Literal

import msgspec

from ea_agent.core.messages import (Lat, Lon, MessageError, NUMERIC, Text, Time, bounded, lonlat, number, register,
                                    text, time_of)

MAX_SPEED_MPS = 100.0
MODES = ("moving", "paused", "waiting-gps")
ACTS = ("delegate", "accept", "success", "failure")
Speed = bounded(0.0, MAX_SPEED_MPS)
Heading = Annotated[float, msgspec.Meta(ge=0.0, lt=360.0)]   # 360 itself is not a heading (it is 0)
Sigma = bounded(0.0, 1e6)


class _Typed:
    """Decoded straight into a typed struct (ea_agent.core.messages); no rule between fields."""
    TYPED: ClassVar[bool] = True
    __slots__ = ()

    def valid(self) -> bool:
        return True


def heading_of(d: dict, kind: str) -> float:
    """A heading in [0, 360): 360 itself is not a heading (it is 0)."""
    h = number(d, kind, "heading_deg", 0.0, 360.0)
    if h >= 360.0:
        raise MessageError(kind, "heading_deg", f"{h} outside [0, 360)")
    return h


@dataclass(slots=True, frozen=True)
class UvState(_Typed):
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
        k = cls.KIND
        t = time_of(d, k)
        r = text(d, k, "robot")
        lon, lat = lonlat(d, k)
        return cls(t, r, lon, lat, number(d, k, "speed_mps", 0.0, MAX_SPEED_MPS), heading_of(d, k),
                   number(d, k, "sigma_m", 0.0, 1e6), text(d, k, "mode", MODES))


@dataclass(slots=True, frozen=True)
class UvSighting(_Typed):
    """`robot`'s sensor sees `target` at (lon, lat) with error `sigma_m`."""
    KIND: ClassVar[str] = "uv-sighting"
    KEY: ClassVar[str] = "sgt/{place}/{robot}/{target}"
    t: Time
    robot: Text
    target: Text
    lon: Lon
    lat: Lat
    sigma_m: Sigma

    @classmethod
    def from_dict(cls, d: dict) -> "UvSighting":
        k = cls.KIND
        t = time_of(d, k)
        r, tg = text(d, k, "robot"), text(d, k, "target")
        lon, lat = lonlat(d, k)
        return cls(t, r, tg, lon, lat, number(d, k, "sigma_m", 0.0, 1e6))


@dataclass(slots=True, frozen=True)
class UvAgent(_Typed):
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

    @classmethod
    def from_dict(cls, d: dict) -> "UvAgent":
        k = cls.KIND
        return cls(time_of(d, k), text(d, k, "sender"), text(d, k, "to"), text(d, k, "act", ACTS),
                   text(d, k, "task"), text(d, k, "target", default=None))




register(UvState, UvSighting, UvAgent)
