"""Small-unit operations messages: friendly positions, hostile tracks and raw
sensor hits, mission confirmations, orders, calls for fire and reorganizations."""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar, Literal

from ea_agent.core.messages import Count, Lat, Lon, MessageError, NUMERIC, Text, Time, Typed, bounded, checked, register

DOMAINS = ("ground", "air")
Heading = bounded(0.0, 360.0)
Speed = bounded(0.0)
Alt = bounded(-500.0, 30000.0)
Radius = bounded(1.0, 100_000.0)


def _drop_defaults(msg, names: tuple[str, ...], defaults: tuple) -> dict:
    """The message's fields, without optional ones at their default (older peers' and
    files' form: a track without altitude is encoded as before)."""
    d = {f: getattr(msg, f) for f in msg.__dataclass_fields__}
    for n, v in zip(names, defaults):
        if d[n] == v:
            del d[n]
    return d


@dataclass(slots=True, frozen=True)
class LocationReport(Typed):
    """A friendly entity's GPS position (from SAIM's network)."""
    KIND: ClassVar[str] = "location"
    KEY: ClassVar[str] = "pos/{place}/{path:entity}/{entity}"
    t: Time
    entity: Text
    lon: Lon
    lat: Lat

    @classmethod
    def from_dict(cls, d: dict) -> "LocationReport":
        # Fast path for the most frequent message; anything odd takes the validating
        # path below, which names the bad field. NaN fails every comparison.
        t, e, lon, lat = d.get("t"), d.get("entity"), d.get("lon"), d.get("lat")
        if (type(t) in NUMERIC and type(lon) in NUMERIC and type(lat) in NUMERIC and type(e) is str and e
                and 0.0 <= t <= 1e15 and -180.0 <= lon <= 180.0 and -90.0 <= lat <= 90.0):
            return cls(float(t), e, float(lon), float(lat))
        return cls(**checked(cls, d))


@dataclass(slots=True, frozen=True)
class SensorTrack(Typed):
    """A fused hostile track: position, strength (entity count) and kinematics."""
    KIND: ClassVar[str] = "track"
    KEY: ClassVar[str] = "trk/{place}/{track}"
    t: Time
    track: Text
    lon: Lon
    lat: Lat
    strength: Count
    heading: Heading | None = None
    speed: Speed | None = None
    source: Text = "fusion"
    alt: Alt | None = None      # metres above ground, when the sensors give it
    domain: Literal["ground", "air"] = "ground"   # ground-only rules ignore air tracks
    at: Time | None = None       # the time the position describes (its last hit), at or before t;
    #                              t is when the report was issued (a fusion window's close)

    def valid(self) -> bool:
        return self.at is None or self.at <= self.t

    @classmethod
    def from_dict(cls, d: dict) -> "SensorTrack":
        f = checked(cls, d)
        if f["at"] is not None and f["at"] > f["t"]:
            raise MessageError(cls.KIND, "at", f"{f['at']} outside [0.0, {f['t']}]")
        return cls(**f)

    def to_json_dict(self) -> dict:
        return _drop_defaults(self, ("alt", "domain", "at"), (None, "ground", None))


@dataclass(slots=True, frozen=True)
class SensorHit(Typed):
    """One raw detection by one sensor (before fusion): where something was seen."""
    KIND: ClassVar[str] = "hit"
    KEY: ClassVar[str] = "hit/{group:sensor}/{sensor}"
    t: Time
    sensor: Text
    lon: Lon
    lat: Lat
    alt: Alt | None = None      # metres above ground, when the sensor measures it

    def to_json_dict(self) -> dict:
        return _drop_defaults(self, ("alt",), (None,))


@dataclass(slots=True, frozen=True)
class MissionConfirm(Typed):
    """Confirmation that a unit started or ended a mission (from its EA, or local)."""
    KIND: ClassVar[str] = "mission"
    KEY: ClassVar[str] = "msn/{unit}/{mission}"
    t: Time
    mission: Text
    unit: Text
    phase: Literal["start", "end"]
    source: Literal["message", "local"] = "message"


@dataclass(slots=True, frozen=True)
class Order(Typed):
    """An order from a superior: execute a (new) plan, abort the current one, or start or
    end one ON-ORDER mission by id (`mission`; `plan` names the plan it belongs to)."""
    KIND: ClassVar[str] = "order"
    KEY: ClassVar[str] = "ord/{issuer}"
    ACTIONS: ClassVar[tuple[str, ...]] = ("execute-plan", "abort-plan", "start-mission", "end-mission")
    t: Time
    action: Literal["execute-plan", "abort-plan", "start-mission", "end-mission"]
    plan: Text
    issuer: Text
    mission: Text | None = None

    def valid(self) -> bool:
        return self.mission is not None or not self.action.endswith("-mission")

    @classmethod
    def from_dict(cls, d: dict) -> "Order":
        f = checked(cls, d)
        if f["action"].endswith("-mission") and f["mission"] is None:
            raise MessageError(cls.KIND, "mission", f"an order to {f['action'].split('-')[0]} a mission must name it")
        return cls(**f)

    def to_json_dict(self) -> dict:
        return _drop_defaults(self, ("mission",), (None,))


@dataclass(slots=True, frozen=True)
class CallForFire(Typed):
    """A request for indirect fire on a target; `radius_m` is the danger radius."""
    KIND: ClassVar[str] = "cff"
    KEY: ClassVar[str] = "cff/{place}/{requester}/{cff}"
    t: Time
    cff: Text
    requester: Text
    lon: Lon
    lat: Lat
    radius_m: Radius


@dataclass(slots=True, frozen=True)
class CallForFireConfirm(CallForFire):
    """The requester confirmed the fire mission: everyone near the target is warned."""
    KIND: ClassVar[str] = "cff-confirm"


@dataclass(slots=True, frozen=True)
class Reorganization(Typed):
    """Resubordinate `unit` under `new_parent` (task organization change)."""
    KIND: ClassVar[str] = "reorg"
    KEY: ClassVar[str] = "org/{unit}"
    t: Time
    unit: Text
    new_parent: Text


register(LocationReport, SensorTrack, SensorHit, MissionConfirm, Order, CallForFire, CallForFireConfirm,
         Reorganization)
