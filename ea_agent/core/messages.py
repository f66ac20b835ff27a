"""The typed, versioned wire form every domain's messages share (msgpack).

A message is a frozen dataclass with a `KIND` tag and a validating `from_dict`;
a domain registers its classes here (`register`) so that one decoder serves every
domain. `from_dict` raises `MessageError` naming the offending field, so a bad
message is counted and dropped instead of crashing a peer.

A class whose fields are annotated with bounded types (`Time`, `Lon`, `Lat`, `Text`,
`Finite`, `Literal[...]`: `TYPED = True`) is decoded straight from msgpack into a typed
msgspec struct (about 0.4 us against 3-4 us for dict-then-fields) and becomes the same
dataclass. Where every field is bounded already, msgspec builds the dataclass itself
after a look at the kind (0.7 us against 1.3 us for struct-then-dataclass: the hot path
of every position report); `encode` writes the kind and version first, so for a kind whose
fields are all required that look is a fixed prefix, not a pass over the message. The
typed decoders are never more lenient than `from_dict`: anything they refuse goes through
`from_dict`, which accepts it or names the bad field.
"""
from __future__ import annotations

import math
import sys
import typing
from dataclasses import MISSING, asdict, fields
from typing import Annotated, Any, Literal

import msgpack
import msgspec

VERSION = 1

class MessageError(ValueError):
    """A message that cannot be decoded; `field` names what was wrong."""

    def __init__(self, kind: str, field_name: str, problem: str):
        super().__init__(f"{kind} message: field '{field_name}': {problem}")
        self.kind = kind
        self.field = field_name
        self.problem = problem


def need(d: dict, kind: str, name: str, default: Any = ...):
    if name in d:
        return d[name]
    if default is ...:
        raise MessageError(kind, name, "missing")
    return default


def number(d: dict, kind: str, name: str, lo: float = -math.inf, hi: float = math.inf, default: Any = ...) -> float:
    v = need(d, kind, name, default)
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


def integer(d: dict, kind: str, name: str, lo: int = 0, default: Any = ...) -> int:
    v = need(d, kind, name, default)
    if isinstance(v, bool) or not isinstance(v, int):
        raise MessageError(kind, name, f"expected an integer, got {type(v).__name__}")
    if v < lo:
        raise MessageError(kind, name, f"{v} below {lo}")
    return v


def text(d: dict, kind: str, name: str, choices: tuple[str, ...] | None = None, default: Any = ...) -> str:
    v = need(d, kind, name, default)
    if v is None and default is None:
        return None  # type: ignore[return-value]
    if not isinstance(v, str) or not v:
        raise MessageError(kind, name, "expected a non-empty string")
    if choices and v not in choices:
        raise MessageError(kind, name, f"{label(v)} not one of {', '.join(choices)}")
    return v


NUMERIC = (float, int)
FLOAT_MAX = sys.float_info.max

# Bounded field types for typed decoding (NaN and infinities fail every bound).
Finite = Annotated[float, msgspec.Meta(ge=-FLOAT_MAX, le=FLOAT_MAX)]
Time = Annotated[float, msgspec.Meta(ge=0.0, le=FLOAT_MAX)]
Lon = Annotated[float, msgspec.Meta(ge=-180.0, le=180.0)]
Lat = Annotated[float, msgspec.Meta(ge=-90.0, le=90.0)]
Text = Annotated[str, msgspec.Meta(min_length=1)]
Count = Annotated[int, msgspec.Meta(ge=0)]


def bounded(lo: float, hi: float = FLOAT_MAX) -> Any:
    """A float field within [lo, hi]."""
    return Annotated[float, msgspec.Meta(ge=lo, le=hi)]


def time_of(d: dict, kind: str) -> float:
    return number(d, kind, "t", 0.0)


def lonlat(d: dict, kind: str) -> tuple[float, float]:
    return number(d, kind, "lon", -180.0, 180.0), number(d, kind, "lat", -90.0, 90.0)


def _check_of(tp: Any):
    """The check of one field's annotation: f(d, kind, name, default) -> value."""
    args = typing.get_args(tp)
    if typing.get_origin(tp) in (typing.Union, getattr(__import__("types"), "UnionType", None)) and type(None) in args:
        inner = [a for a in args if a is not type(None)]
        if len(inner) == 1:
            one = _check_of(inner[0])
            return lambda d, k, n, dflt: None if d.get(n, dflt) is None else one(d, k, n, dflt)
    if typing.get_origin(tp) is Literal and all(type(a) is str for a in args):
        return lambda d, k, n, dflt: text(d, k, n, args, dflt)
    base, meta = tp, msgspec.Meta()
    if typing.get_origin(tp) is Annotated:
        base = args[0]
        meta = next((m for m in tp.__metadata__ if isinstance(m, msgspec.Meta)), meta)
    if base is float:
        lo = meta.ge if meta.ge is not None else -math.inf
        hi = meta.le if meta.le is not None else math.inf
        lt = meta.lt
        if lt is None:
            return lambda d, k, n, dflt: number(d, k, n, lo, hi, dflt)

        def below(d, k, n, dflt):
            v = number(d, k, n, lo, lt, dflt)
            if v >= lt:
                raise MessageError(k, n, f"{v} outside [{lo}, {lt})")
            return v
        return below
    if base is str:
        return lambda d, k, n, dflt: text(d, k, n, None, dflt)
    if base is int:
        ge = meta.ge if meta.ge is not None else 0
        return lambda d, k, n, dflt: integer(d, k, n, ge, dflt)
    raise TypeError(f"no check for a field annotated {tp!r}")


_CHECKS: dict[type, list] = {}


def checked(cls: type, d: dict) -> dict:
    """The fields of message class `cls` out of `d`, each checked against its annotation
    (the bounds, choices and optionality the typed decoder checks) and named when bad: a
    message whose rules are all in its fields' types needs no `from_dict` of its own, and
    can never be more lenient here than on the typed path. Rules between fields stay in the
    class (e.g. a track's `at` at or before its `t`)."""
    plan = _CHECKS.get(cls)
    if plan is None:
        hints = typing.get_type_hints(cls, include_extras=True)
        plan = _CHECKS[cls] = [(f.name, _check_of(hints[f.name]), ... if f.default is MISSING else f.default)
                               for f in fields(cls)]
    k = cls.KIND
    return {n: check(d, k, n, dflt) for n, check, dflt in plan}


class Typed:
    """A message decoded straight into a typed struct (`register`), its `from_dict` checked
    from its fields' annotations (`checked`); `valid` holds any rule between fields."""
    TYPED: typing.ClassVar[bool] = True
    __slots__ = ()

    def valid(self) -> bool:
        return True

    @classmethod
    def from_dict(cls, d: dict):
        return cls(**checked(cls, d))



MESSAGE_TYPES: dict[str, type] = {}
_TYPED: dict[type, type] = {}          # typed struct -> the dataclass it becomes
_RULED: set[type] = set()              # typed classes with rules between fields (`valid`)
_typed_decoder: msgspec.msgpack.Decoder | None = None


def register(*classes: type) -> None:
    """Make message classes decodable; a kind may be registered once (by one class).
    Classes marked `TYPED` get a typed struct (their fields' annotations, every plain
    float made finite) in the one tagged decoder; such a class has `valid()`, its rules
    between fields (False sends the message through `from_dict`, which names the field)."""
    global _typed_decoder
    for c in classes:
        old = MESSAGE_TYPES.setdefault(c.KIND, c)
        if old is not c:
            raise ValueError(f"message kind {c.KIND!r} already registered by {old.__name__}")
        if getattr(c, "TYPED", False) and c not in _TYPED.values():
            _TYPED[_struct_of(c)] = c
            if any("valid" in vars(k) for k in c.__mro__[:-1] if getattr(k, "KIND", None)):
                _RULED.add(c)
    if _TYPED:
        _typed_decoder = msgspec.msgpack.Decoder(typing.Union[tuple(_TYPED)])   # type: ignore[misc]
        for c in _TYPED.values():
            if c.KIND not in _DIRECT and _bounded(c):
                _DIRECT[c.KIND] = msgspec.msgpack.Decoder(c)
                if (p := _prefix(c)) is not None:
                    _PREFIXED[p] = _DIRECT[c.KIND]


class _Head(msgspec.Struct):
    """A message's kind and version, the rest skipped: which direct decoder to use."""
    kind: str
    v: Literal[VERSION]   # type: ignore[valid-type]


_head = msgspec.msgpack.Decoder(_Head)
_DIRECT: dict[str, msgspec.msgpack.Decoder] = {}   # kind -> a decoder straight into its dataclass
_PREFIXED: dict[bytes, msgspec.msgpack.Decoder] = {}   # encode's prefix -> the same, no look at the kind


def _prefix(cls: type) -> bytes | None:
    """The bytes `encode` starts a `cls` message with (map header, `kind`, `v`), when they
    name it exactly: every field required and the header counting all of them, so a map
    with that prefix has no room for a second `kind` or `v`, nor a field twice (one
    missing makes the decoder refuse it). None for a class with defaults (the kind is read
    first, `_head`) or a name too long for the fixed layout (`decode`'s slice)."""
    fs = fields(cls)
    kind = cls.KIND.encode()
    if any(f.default is not MISSING or f.default_factory is not MISSING for f in fs) or len(fs) + 2 > 15 \
            or not 0 < len(kind) < 32:
        return None
    return bytes([0x80 + len(fs) + 2]) + b"\xa4kind" + bytes([0xA0 + len(kind)]) + kind + b"\xa1v" + bytes([VERSION])


def _bounded(cls: type) -> bool:
    """Every field's annotation is already what the typed struct checks (no plain float
    to make finite): msgspec can then build the dataclass itself, at half the cost."""
    hints = typing.get_type_hints(cls, include_extras=True)
    return all(_finite(hints[f.name]) is hints[f.name] for f in fields(cls))


def _finite(tp: Any) -> Any:
    """A plain float (alone or in an optional) becomes a finite one: `from_dict` refuses NaN."""
    if tp is float:
        return Finite
    args = typing.get_args(tp)
    if typing.get_origin(tp) in (typing.Union, getattr(__import__("types"), "UnionType", None)) and float in args:
        return typing.Union[tuple(Finite if a is float else a for a in args)]
    return tp


def _struct_of(cls: type) -> type:
    hints = typing.get_type_hints(cls, include_extras=True)
    spec = []
    for f in fields(cls):
        tp = _finite(hints[f.name])
        spec.append((f.name, tp) if f.default is f.default_factory else (f.name, tp, f.default))   # type: ignore[misc]
    spec.append(("v", Literal[VERSION]))
    st = msgspec.defstruct(f"{cls.__name__}Wire", spec, kw_only=True, tag_field="kind", tag=cls.KIND,
                           array_like=False)
    return st


Message = Any   # an instance of one of MESSAGE_TYPES


def label(v: Any) -> str:
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
        raise MessageError("?", "kind", f"unknown message kind {label(kind)}")
    return cls.from_dict(d)


def to_dict(msg: Message) -> dict:
    d = msg.to_json_dict() if hasattr(msg, "to_json_dict") else asdict(msg)
    d["kind"] = msg.KIND
    return d


def encode(msg: Message) -> bytes:
    """Wire form: msgpack map with a `kind` tag and a version `v` first (`decode` reads
    them as a fixed prefix), then every field."""
    d = {"kind": msg.KIND, "v": VERSION}
    d.update(msg.to_json_dict() if hasattr(msg, "to_json_dict") else asdict(msg))
    return msgpack.packb(d, use_bin_type=True)


def decode(data: bytes) -> Message:
    """Parse and validate wire bytes; raises MessageError on anything malformed."""
    if type(data) is not bytes:   # a bytearray or memoryview (a socket's buffer): its slices are unhashable
        try:
            data = bytes(memoryview(data))
        except TypeError:
            raise MessageError("?", "(bytes)", f"expected bytes, got {type(data).__name__}") from None
    if len(data) > 6:   # `encode`'s fixed prefix (map header, kind, v) names the direct decoder
        pre = _PREFIXED.get(data[:10 + data[6] - 0xA0])
        if pre is not None:
            try:
                m = pre.decode(data)
            except Exception:   # refused: the paths below name the field
                pass
            else:
                if type(m) not in _RULED or m.valid():
                    return m
    direct = None
    if _DIRECT:
        try:
            direct = _DIRECT.get(_head.decode(data).kind)
            if direct is not None:
                m = direct.decode(data)
                if type(m) not in _RULED or m.valid():
                    return m
        except Exception:   # refused: the dict path below names the field
            pass
    if _typed_decoder is not None and direct is None:   # the typed struct would say what the direct decoder said
        try:
            s = _typed_decoder.decode(data)
        except Exception:   # refused: the dict path below accepts it or names the field
            pass
        else:
            cls = _TYPED[type(s)]
            m = cls(*msgspec.structs.astuple(s)[:-1])   # the struct's fields, then `v`
            if cls not in _RULED or m.valid():   # rules between fields (no `at` after `t`...)
                return m
    try:
        d = msgpack.unpackb(data, raw=False, strict_map_key=True)
    except Exception as e:  # msgpack raises several unrelated types
        raise MessageError("?", "(bytes)", f"not valid msgpack: {e}") from None
    if not isinstance(d, dict):
        raise MessageError("?", "(message)", "expected a mapping")
    v, kind = d.get("v"), d.get("kind")
    kind = kind if type(kind) is str and kind in MESSAGE_TYPES else "?"
    if type(v) is not int or v != VERSION:   # `True == 1`: a bool is no version
        raise MessageError(kind, "v", f"unsupported version {label(v)} (expected {VERSION})")
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
