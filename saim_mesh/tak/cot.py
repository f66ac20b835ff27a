"""One Cursor-on-Target event: built with ElementTree, encoded to TAK protocol v1 with
takproto, and parsed back from either into a typed, checked `CoTEvent`.

Pure functions, no I/O. Parsing is the gateway's front door for whatever a TAK network
sends, so it is bounded (size), refuses DTDs (no entity expansion), and checks every
field it returns (coordinates, times); each refusal is a `CotError` naming the field."""
from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone
from typing import Iterable, Literal

import takproto
from google.protobuf.message import DecodeError
from takproto.proto import TakMessage

from . import types as T

UTC = timezone.utc
UNKNOWN = 9999999.0            # CoT's "unknown" for hae, ce and le
MAX_BYTES = 65536              # one event: TAK clients send a few hundred bytes
MAX_SKEW_S = 86400.0           # a PLI dated more than a day from now is not a position now
MAX_LIFE_S = 366 * 86400.0     # stale - start: longer is not a live event
YEARS = (2000, 2100)           # outside: a clock that was never set, or garbage
MESH = b"\xbf\x01\xbf"          # TAK protocol v1, mesh (UDP) header
STREAM = 0xBF                  # TAK protocol v1, stream (TCP) header: 0xbf <varint length> <message>
Proto = Literal["xml", "mesh", "stream"]
_DTD = re.compile(rb"<!\s*(DOCTYPE|ENTITY|ELEMENT|ATTLIST)", re.I)
_CTRL = re.compile(r"[\x00-\x1f\x7f]")


class CotError(ValueError):
    """A CoT event we refuse: `field` names what was wrong ('point.lat', 'uid', 'xml', ...)."""

    def __init__(self, field_: str, why: str):
        self.field = field_
        super().__init__(f"CoT field '{field_}': {why}")


@dataclass(frozen=True, slots=True)
class CoTEvent:
    """A parsed, checked event. `detail` holds each direct child of <detail> by tag (the
    first of a tag): its attributes, plus its text under '#text' when it has any; and the
    first grandchild of each tag under 'parent/child' (GeoChat's `__chat/chatgrp`)."""
    uid: str
    type: str
    how: str
    time: datetime
    start: datetime
    stale: datetime
    lat: float
    lon: float
    hae: float = UNKNOWN
    ce: float = UNKNOWN
    le: float = UNKNOWN
    callsign: str | None = None
    remarks: str | None = None
    detail: dict[str, dict[str, str]] = field(default_factory=dict)
    links: tuple[dict[str, str], ...] = ()
    format: str = "xml"


# -- building --------------------------------------------------------------------------
def iso(t: datetime) -> str:
    """CoT time: UTC, milliseconds, 'Z' (2026-05-01T10:00:00.000Z)."""
    return t.astimezone(UTC).strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z"


def _num(v: float, nd: int = 7) -> str:
    return repr(round(float(v), nd))


def sub(parent: ET.Element, tag: str, text: str | None = None, **attrs) -> ET.Element:
    """A child element; attribute values may be numbers (None values are left out)."""
    el = ET.SubElement(parent, tag, {k.rstrip("_"): str(v) for k, v in attrs.items() if v is not None})
    if text is not None:
        el.text = text
    return el


def element(uid: str, type_: str, lon: float, lat: float, time: datetime, stale: datetime, *,
            start: datetime | None = None, how: str = T.HOW_GPS, callsign: str | None = None,
            remarks: str | None = None, hae: float = UNKNOWN, ce: float = UNKNOWN, le: float = UNKNOWN,
            detail: Iterable[ET.Element] = ()) -> ET.Element:
    """The <event> element (so that a caller may still add to its <detail>)."""
    start = start or time
    if not (stale > start >= time - timedelta(seconds=1)):
        raise ValueError(f"{uid}: stale {iso(stale)} must be after start {iso(start)}")
    ev = ET.Element("event", {"version": "2.0", "uid": uid, "type": type_, "how": how,
                              "time": iso(time), "start": iso(start), "stale": iso(stale)})
    sub(ev, "point", lat=_num(lat), lon=_num(lon), hae=_num(hae, 1), ce=_num(ce, 1), le=_num(le, 1))
    det = sub(ev, "detail")
    if callsign is not None:
        sub(det, "contact", callsign=callsign)
    for el in detail:
        det.append(el)
    if remarks is not None:
        sub(det, "remarks", remarks)
    return ev


def to_bytes(ev: ET.Element) -> bytes:
    return ET.tostring(ev, encoding="utf-8", xml_declaration=True)


def event(uid: str, type_: str, lon: float, lat: float, time: datetime, stale: datetime, **kw) -> bytes:
    """One CoT event as XML bytes (with its declaration, as TAK tools expect)."""
    return to_bytes(element(uid, type_, lon, lat, time, stale, **kw))


def encode(xml: bytes, proto: Proto = "xml") -> bytes:
    """XML as is, or TAK protocol v1 by takproto: 'mesh' for UDP, 'stream' for TCP/TLS."""
    if proto == "xml":
        return xml
    ver = takproto.TAKProtoVer.MESH if proto == "mesh" else takproto.TAKProtoVer.STREAM
    return bytes(takproto.xml2proto(xml, ver))


# -- parsing ---------------------------------------------------------------------------
def _time(v, name: str) -> datetime:
    if isinstance(v, int):   # protobuf: milliseconds since the epoch (0: absent)
        if v <= 0:
            raise CotError(name, "missing")
        try:
            t = datetime.fromtimestamp(v / 1000.0, UTC)
        except (OverflowError, OSError, ValueError):
            raise CotError(name, f"{v} ms is not a time") from None
    else:
        if not v:
            raise CotError(name, "missing")
        if len(v) > 40 or "T" not in v:
            raise CotError(name, f"{v[:40]!r} is not an ISO 8601 time")
        try:
            t = datetime.fromisoformat(v[:-1] + "+00:00" if v.endswith("Z") else v)
        except ValueError:
            raise CotError(name, f"{v[:40]!r} is not an ISO 8601 time") from None
        if t.tzinfo is None:
            raise CotError(name, f"{v[:40]!r} has no time zone (CoT times end in Z)")
    if not YEARS[0] <= t.year < YEARS[1]:
        raise CotError(name, f"{iso(t)} is outside the years {YEARS[0]}-{YEARS[1]}")
    return t.astimezone(UTC)


def _float(v, name: str, lo: float, hi: float, default: float | None = None) -> float:
    if v is None or v == "":
        if default is None:
            raise CotError(name, "missing")
        return default
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise CotError(name, f"{str(v)[:40]!r} is not a number") from None
    if not math.isfinite(x) or not lo <= x <= hi:
        raise CotError(name, f"{x} outside [{lo:g}, {hi:g}]")
    return x


def _text(v, name: str, limit: int = 256) -> str:
    if not v:
        raise CotError(name, "missing")
    if len(v) > limit or _CTRL.search(v):
        raise CotError(name, f"{v[:40]!r}: over {limit} characters or control characters")
    return v


def _xml(data: bytes, what: str) -> ET.Element:
    if _DTD.search(data):
        raise CotError(what, "a DTD or entity declaration (refused: no entity expansion)")
    try:
        return ET.fromstring(data)
    except ET.ParseError as e:
        raise CotError(what, f"malformed XML ({e})") from None


def _details(det: ET.Element | None) -> tuple[dict, tuple, str | None, str | None]:
    if det is None:
        return {}, (), None, None
    out: dict[str, dict[str, str]] = {}
    links = []
    for el in det:
        if el.tag == "link":
            links.append(dict(el.attrib))
            continue
        if el.tag not in out:
            d = dict(el.attrib)
            if el.text and el.text.strip():
                d["#text"] = el.text
            out[el.tag] = d
            for sub_ in el:   # one level down (bounded by the event's size)
                out.setdefault(f"{el.tag}/{sub_.tag}", dict(sub_.attrib))
    callsign = out.get("contact", {}).get("callsign")
    remarks = out.get("remarks", {}).get("#text")
    return out, tuple(links), callsign, remarks


def _check(uid, type_, how, time, start, stale, lat, lon, hae, ce, le, det: ET.Element | None,
           fmt: str, now: datetime | None, skew_s: float, extra: dict | None = None) -> CoTEvent:
    uid = _text(uid, "uid")
    type_ = _text(type_, "type", 96)
    if not T.valid_type(type_):
        raise CotError("type", f"{type_[:40]!r} is not a CoT type (like a-f-G-U-C)")
    how = how or ""
    if how and (len(how) > 32 or _CTRL.search(how)):
        raise CotError("how", f"{how[:40]!r} is not a CoT how")
    t, st, sl = _time(time, "time"), _time(start, "start"), _time(stale, "stale")
    if sl < st:
        raise CotError("stale", f"{iso(sl)} before start {iso(st)}")
    if (sl - st).total_seconds() > MAX_LIFE_S:
        raise CotError("stale", f"{iso(sl)} more than a year after start {iso(st)}")
    if now is not None and abs((t - now).total_seconds()) > skew_s:
        raise CotError("time", f"{iso(t)} is more than {skew_s:g} s from now ({iso(now)})")
    lat_ = _float(lat, "point.lat", -90.0, 90.0)
    lon_ = _float(lon, "point.lon", -180.0, 180.0)
    hae_ = _float(hae, "point.hae", -1e7, 1e7, UNKNOWN)
    ce_ = _float(ce, "point.ce", 0.0, 1e7, UNKNOWN)
    le_ = _float(le, "point.le", 0.0, 1e7, UNKNOWN)
    detail, links, callsign, remarks = _details(det)
    if extra and extra.get("callsign") and callsign is None:   # protobuf: a typed field, not XML
        callsign = extra["callsign"]
        detail = {"contact": {"callsign": callsign}, **detail}
    if callsign is not None:
        callsign = _text(callsign, "detail.contact.callsign")
    return CoTEvent(uid, type_, how, t, st, sl, lat_, lon_, hae_, ce_, le_, callsign, remarks, detail, links, fmt)


def _varint(data: bytes, i: int) -> tuple[int, int]:
    """A protobuf varint at data[i:] (the TAK stream's length prefix) -> (value, next index)."""
    n = shift = 0
    for k in range(i, min(i + 10, len(data))):
        n |= (data[k] & 0x7F) << shift
        if not data[k] & 0x80:
            return n, k + 1
        shift += 7
    raise CotError("protobuf", "truncated or overlong length prefix")


def _proto(data: bytes, now, skew_s) -> CoTEvent:
    if data[:3] == MESH:
        body, fmt = data[3:], "mesh"
    else:   # stream framing; a mesh header of another version fails the length check
        n, i = _varint(data, 1)
        body, fmt = data[i:], "stream"
        if len(body) != n:
            raise CotError("protobuf", f"stream length prefix says {n} bytes, {len(body)} follow "
                           f"(truncated, or not TAK protocol version 1)")
    try:
        msg = TakMessage.FromString(body)
    except (DecodeError, ValueError, RuntimeError) as e:
        raise CotError("protobuf", f"undecodable TAK message ({str(e)[:80]})") from None
    if not msg.HasField("cotEvent"):
        raise CotError("protobuf", "no cotEvent in the TAK message")
    ev = msg.cotEvent
    det = None
    if ev.HasField("detail") and ev.detail.xmlDetail:
        raw = ev.detail.xmlDetail.encode("utf-8")
        if len(raw) > MAX_BYTES:
            raise CotError("detail", "xmlDetail over the size limit")
        det = _xml(b"<detail>" + raw + b"</detail>", "detail")
    extra = {"callsign": ev.detail.contact.callsign} if ev.HasField("detail") else None
    return _check(ev.uid, ev.type, ev.how, ev.sendTime, ev.startTime, ev.staleTime, ev.lat, ev.lon,
                  ev.hae, ev.ce, ev.le, det, fmt, now, skew_s, extra)


def parse(data: bytes, *, max_bytes: int = MAX_BYTES, now: datetime | None = None,
          skew_s: float = MAX_SKEW_S) -> CoTEvent:
    """One event from XML or TAK protocol v1 (mesh or stream framing). `now` (UTC) bounds
    how far `time` may be from it. Raises CotError (a ValueError) naming the bad field."""
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise CotError("bytes", f"expected bytes, got {type(data).__name__}")
    data = bytes(data)
    if len(data) > max_bytes:
        raise CotError("bytes", f"{len(data)} bytes, over the {max_bytes} limit")
    if not data.strip():
        raise CotError("bytes", "empty")
    if data[0] == STREAM:
        return _proto(data, now, skew_s)
    root = _xml(data.strip(), "xml")
    if root.tag != "event":
        raise CotError("xml", f"root element <{root.tag[:40]}>, not <event>")
    pt = root.find("point")
    if pt is None:
        raise CotError("point", "missing")
    a, p = root.attrib, pt.attrib
    return _check(a.get("uid"), a.get("type"), a.get("how"), a.get("time"), a.get("start"), a.get("stale"),
                  p.get("lat"), p.get("lon"), p.get("hae"), p.get("ce"), p.get("le"), root.find("detail"),
                  "xml", now, skew_s)
