"""Typed, versioned messages and their msgpack wire form.

Every message is a frozen dataclass with a `KIND` tag. `from_dict` validates a
decoded mapping and raises `MessageError` naming the offending field, so that a
bad message can be counted and dropped instead of crashing a peer.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field
from typing import Any, ClassVar

import msgpack

VERSION = 1


class MessageError(ValueError):
    """A message that cannot be decoded; `field` names what was wrong."""

    def __init__(self, kind: str, field_name: str, problem: str):
        super().__init__(f"{kind} message: field '{field_name}': {problem}")
        self.kind = kind
        self.field = field_name
        self.problem = problem


def _get(d: dict, kind: str, name: str, default: Any = ...):
    if name in d:
        return d[name]
    if default is ...:
        raise MessageError(kind, name, "missing")
    return default


def _num(d: dict, kind: str, name: str, lo: float = -math.inf, hi: float = math.inf, default: Any = ...) -> float:
    v = _get(d, kind, name, default)
    if v is None and default is None:
        return None  # type: ignore[return-value]
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise MessageError(kind, name, f"expected a number, got {type(v).__name__}")
    v = float(v)
    if not math.isfinite(v):
        raise MessageError(kind, name, f"not a finite number ({v})")
    if not lo <= v <= hi:
        raise MessageError(kind, name, f"{v} outside [{lo}, {hi}]")
    return v


def _int(d: dict, kind: str, name: str, lo: int = 0, default: Any = ...) -> int:
    v = _get(d, kind, name, default)
    if isinstance(v, bool) or not isinstance(v, int):
        raise MessageError(kind, name, f"expected an integer, got {type(v).__name__}")
    if v < lo:
        raise MessageError(kind, name, f"{v} below {lo}")
    return v


def _str(d: dict, kind: str, name: str, choices: tuple[str, ...] | None = None, default: Any = ...) -> str:
    v = _get(d, kind, name, default)
    if v is None and default is None:
        return None  # type: ignore[return-value]
    if not isinstance(v, str) or not v:
        raise MessageError(kind, name, "expected a non-empty string")
    if choices and v not in choices:
        raise MessageError(kind, name, f"{_label(v)} not one of {', '.join(choices)}")
    return v


_NUM = (float, int)


def _time(d: dict, kind: str) -> float:
    return _num(d, kind, "t", 0.0)


def _lonlat(d: dict, kind: str) -> tuple[float, float]:
    return _num(d, kind, "lon", -180.0, 180.0), _num(d, kind, "lat", -90.0, 90.0)


@dataclass(slots=True, frozen=True)
class LocationReport:
    """A friendly entity's GPS position (from SAIM's network)."""
    KIND: ClassVar[str] = "location"
    t: float
    entity: str
    lon: float
    lat: float

    @classmethod
    def from_dict(cls, d: dict) -> "LocationReport":
        # Fast path for the most frequent message; anything odd takes the validating
        # path below, which names the bad field. NaN fails every comparison.
        t, e, lon, lat = d.get("t"), d.get("entity"), d.get("lon"), d.get("lat")
        if (type(t) in _NUM and type(lon) in _NUM and type(lat) in _NUM and type(e) is str and e
                and 0.0 <= t <= 1e15 and -180.0 <= lon <= 180.0 and -90.0 <= lat <= 90.0):
            return cls(float(t), e, float(lon), float(lat))
        k = cls.KIND
        lon, lat = _lonlat(d, k)
        return cls(_time(d, k), _str(d, k, "entity"), lon, lat)


@dataclass(slots=True, frozen=True)
class SensorTrack:
    """A fused hostile track: position, strength (entity count) and kinematics."""
    KIND: ClassVar[str] = "track"
    t: float
    track: str
    lon: float
    lat: float
    strength: int
    heading: float | None = None
    speed: float | None = None
    source: str = "fusion"

    @classmethod
    def from_dict(cls, d: dict) -> "SensorTrack":
        k = cls.KIND
        lon, lat = _lonlat(d, k)
        return cls(_time(d, k), _str(d, k, "track"), lon, lat, _int(d, k, "strength", 0),
                   _num(d, k, "heading", 0.0, 360.0, default=None),
                   _num(d, k, "speed", 0.0, default=None), _str(d, k, "source", default="fusion"))


@dataclass(slots=True, frozen=True)
class SensorHit:
    """One raw detection by one sensor (before fusion): where something was seen."""
    KIND: ClassVar[str] = "hit"
    t: float
    sensor: str
    lon: float
    lat: float

    @classmethod
    def from_dict(cls, d: dict) -> "SensorHit":
        k = cls.KIND
        lon, lat = _lonlat(d, k)
        return cls(_time(d, k), _str(d, k, "sensor"), lon, lat)


@dataclass(slots=True, frozen=True)
class MissionConfirm:
    """Confirmation that a unit started or ended a mission (from its EA, or local)."""
    KIND: ClassVar[str] = "mission"
    t: float
    mission: str
    unit: str
    phase: str  # "start" | "end"
    source: str = "message"  # "message" | "local"

    @classmethod
    def from_dict(cls, d: dict) -> "MissionConfirm":
        k = cls.KIND
        return cls(_time(d, k), _str(d, k, "mission"), _str(d, k, "unit"),
                   _str(d, k, "phase", ("start", "end")),
                   _str(d, k, "source", ("message", "local"), default="message"))


@dataclass(slots=True, frozen=True)
class Order:
    """An order from a superior: execute a (new) plan, or abort the current one."""
    KIND: ClassVar[str] = "order"
    t: float
    action: str  # "execute-plan" | "abort-plan"
    plan: str
    issuer: str

    @classmethod
    def from_dict(cls, d: dict) -> "Order":
        k = cls.KIND
        return cls(_time(d, k), _str(d, k, "action", ("execute-plan", "abort-plan")),
                   _str(d, k, "plan"), _str(d, k, "issuer"))


@dataclass(slots=True, frozen=True)
class CallForFire:
    """A request for indirect fire on a target; `radius_m` is the danger radius."""
    KIND: ClassVar[str] = "cff"
    t: float
    cff: str
    requester: str
    lon: float
    lat: float
    radius_m: float

    @classmethod
    def from_dict(cls, d: dict) -> "CallForFire":
        k = cls.KIND
        lon, lat = _lonlat(d, k)
        return cls(_time(d, k), _str(d, k, "cff"), _str(d, k, "requester"), lon, lat,
                   _num(d, k, "radius_m", 1.0, 100_000.0))


@dataclass(slots=True, frozen=True)
class CallForFireConfirm(CallForFire):
    """The requester confirmed the fire mission: everyone near the target is warned."""
    KIND: ClassVar[str] = "cff-confirm"


@dataclass(slots=True, frozen=True)
class Reorganization:
    """Resubordinate `unit` under `new_parent` (task organization change)."""
    KIND: ClassVar[str] = "reorg"
    t: float
    unit: str
    new_parent: str

    @classmethod
    def from_dict(cls, d: dict) -> "Reorganization":
        k = cls.KIND
        return cls(_time(d, k), _str(d, k, "unit"), _str(d, k, "new_parent"))


PRIORITIES = ("flash", "immediate", "priority", "routine")  # highest first


@dataclass(slots=True, frozen=True)
class Alert:
    """An alert as shown to a commander and sent on the mesh."""
    KIND: ClassVar[str] = "alert"
    t: float
    owner: str
    type: str
    category: str
    priority: str
    subjects: tuple[str, ...]
    message: str
    details: dict = field(default_factory=dict)

    @classmethod
    def from_dict(cls, d: dict) -> "Alert":
        k = cls.KIND
        subjects = _get(d, k, "subjects")
        if not isinstance(subjects, (list, tuple)) or not all(isinstance(s, str) for s in subjects):
            raise MessageError(k, "subjects", "expected a list of strings")
        details = _get(d, k, "details", {})
        if not isinstance(details, dict):
            raise MessageError(k, "details", "expected a mapping")
        return cls(_time(d, k), _str(d, k, "owner"), _str(d, k, "type"), _str(d, k, "category"),
                   _str(d, k, "priority", PRIORITIES), tuple(subjects), _str(d, k, "message"), details)

    def to_json_dict(self) -> dict:
        return {"t": self.t, "owner": self.owner, "type": self.type, "category": self.category,
                "priority": self.priority, "subjects": list(self.subjects),
                "message": self.message, "details": self.details}


Message = LocationReport | SensorTrack | SensorHit | MissionConfirm | Order | CallForFire | CallForFireConfirm | Reorganization | Alert

MESSAGE_TYPES: dict[str, type] = {c.KIND: c for c in (
    LocationReport, SensorTrack, SensorHit, MissionConfirm, Order, CallForFire, CallForFireConfirm, Reorganization, Alert)}


def _label(v: Any) -> str:
    """A value named in an error without rendering it: an attacker's value may be
    a thousand levels deep or a megabyte long."""
    if type(v) is str:
        return repr(v[:40])
    if type(v) in (int, float, bool) or v is None:
        return repr(v)[:40]
    return f"a {type(v).__name__}"


def from_dict(d: Any) -> Message:
    """Build a message from a decoded mapping with a `kind` key; raises MessageError."""
    if not isinstance(d, dict):
        raise MessageError("?", "(message)", f"expected a mapping, got {type(d).__name__}")
    kind = d.get("kind")
    cls = MESSAGE_TYPES.get(kind) if type(kind) is str else None
    if cls is None:
        raise MessageError("?", "kind", f"unknown message kind {_label(kind)}")
    return cls.from_dict(d)


def to_dict(msg: Message) -> dict:
    d = msg.to_json_dict() if isinstance(msg, Alert) else asdict(msg)
    d["kind"] = msg.KIND
    return d


def encode(msg: Message) -> bytes:
    """Wire form: msgpack map with a version `v` and a `kind` tag."""
    d = to_dict(msg)
    d["v"] = VERSION
    return msgpack.packb(d, use_bin_type=True)


def decode(data: bytes) -> Message:
    """Parse and validate wire bytes; raises MessageError on anything malformed."""
    try:
        d = msgpack.unpackb(data, raw=False, strict_map_key=True)
    except Exception as e:  # msgpack raises several unrelated types
        raise MessageError("?", "(bytes)", f"not valid msgpack: {e}") from None
    if not isinstance(d, dict):
        raise MessageError("?", "(message)", "expected a mapping")
    v, kind = d.get("v"), d.get("kind")
    kind = kind if type(kind) is str and kind in MESSAGE_TYPES else "?"
    if type(v) is not int or v != VERSION:   # `True == 1`: a bool is no version
        raise MessageError(kind, "v", f"unsupported version {_label(v)} (expected {VERSION})")
    try:
        return from_dict(d)
    except MessageError:
        raise
    except Exception as e:   # an odd shape the field checks did not foresee: still a rejection
        raise MessageError(kind, "(message)", f"undecodable: {type(e).__name__}") from None


class Decoder:
    """Decodes a stream of wire messages, counting and keeping the last errors instead of raising."""

    def __init__(self, keep: int = 20):
        self.ok = 0
        self.errors = 0
        self.recent: list[str] = []
        self._keep = keep

    def __call__(self, data: bytes) -> Message | None:
        try:
            m = decode(data)
        except MessageError as e:
            self.errors += 1
            self.recent = (self.recent + [str(e)])[-self._keep:]
            return None
        self.ok += 1
        return m
