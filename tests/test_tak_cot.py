"""Cursor-on-Target events (saim_mesh/tak/cot.py, picture.py): every kind the gateway
emits parses with takproto (XML, and XML -> TAK protocol v1 -> back) and passes type,
time and stale checks; bad input is refused with an error naming the field."""
from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET
from datetime import datetime, timedelta, timezone

import pytest
import takproto

from saim_mesh.protocol import messages as M
from saim_mesh.tak import cot as C
from saim_mesh.tak import types as T
from saim_mesh.tak.picture import Options, Picture

pytestmark = pytest.mark.timeout(120)
EPOCH = datetime(2026, 5, 1, 6, 0, 0, tzinfo=timezone.utc)
ISO_Z = re.compile(r"^\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z$")
NOW = datetime.now(timezone.utc)


def alert(prio="immediate", typ="out-of-position", cat="plan-constraint-violated", subjects=("A2",),
          details=None, t=300.0, owner="A2", n=1):
    return M.Alert(t, owner, typ, cat, prio, tuple(subjects), f"{typ} of {' '.join(subjects)} ({prio})",
                   {"id": f"{owner}/{n}", **(details or {})})


ALERTS = {   # name -> (alert, the CoT type a TAK user gets)
    "flash-contact": (alert("flash", "contact", "adversarial-activity", ("R", "H2"), n=1), T.CONTACT),
    "flash-fratricide": (alert("flash", "fratricide", "policy-constraint-violated", ("A2", "B1"), n=2), T.EMERGENCY),
    "immediate-geofence": (alert("immediate", details={"control_measure": "RTE-A2"}, n=3), T.GEOFENCE),
    "immediate-marker": (alert("immediate", "schedule", n=4), T.MARKER),
    "priority": (alert("priority", "unknown-position", "reporting-requirement", ("A1S3",), n=5), T.MARKER),
    "routine": (alert("routine", "monitored", "adversarial-activity", ("H4",), {"place": "EA-A"}, n=6), T.MARKER),
}


@pytest.fixture(scope="module")
def picture(small):
    p = Picture(small, Options(entities=True, epoch=EPOCH))
    for ev in small.events:
        if ev.t > 1500:
            break
        p.message(ev)
    p.clock(1500.0)
    return p


@pytest.fixture(scope="module")
def emitted(picture) -> dict[str, list[bytes]]:
    """Every kind of event the gateway emits, by kind."""
    out: dict[str, list[bytes]] = {"unit": [], "entity": [], "track": []}
    for b in picture.due(force=True):
        out[C.parse(b).detail["__saim"]["kind"]].append(b)
    for name, (a, _) in ALERTS.items():
        out[f"alert:{name}"] = [picture.alert_event(a)]
    out["overlay"] = picture.overlay_events()
    return out


def test_every_kind_is_emitted(emitted, picture):
    assert all(emitted[k] for k in ("unit", "entity", "track", "overlay"))
    assert {C.parse(b).type for b in emitted["overlay"]} == {T.SHAPE, T.CIRCLE}
    # units: callsigns from the task organization, echelon in the SIDC
    a2 = next(C.parse(b) for b in emitted["unit"] if C.parse(b).detail["__saim"]["unit"] == "A2")
    assert a2.callsign == "2 PLT, A CO" and a2.detail["__saim"]["sidc"] == "SFGPUC-----D---"


def _all(emitted):
    return [(k, b) for k, bs in emitted.items() for b in bs]


def test_takproto_parses_every_event_and_round_trips(emitted):
    for kind, b in _all(emitted):
        ours = C.parse(b)
        tm = takproto.parse_proto(b)                     # XML as takproto reads it
        assert tm is not None and tm.cotEvent.uid == ours.uid and tm.cotEvent.type == ours.type, kind
        for proto in ("mesh", "stream"):
            wire = C.encode(b, proto)
            back = takproto.parse_proto(bytearray(wire))
            assert back.cotEvent.uid == ours.uid and back.cotEvent.type == ours.type, (kind, proto)
            assert back.cotEvent.staleTime == int(ours.stale.timestamp() * 1000), (kind, proto)
            again = C.parse(wire)
            assert again.format == proto
            assert (again.uid, again.type, again.how, again.time, again.start, again.stale, again.callsign,
                    again.remarks) == (ours.uid, ours.type, ours.how, ours.time, ours.start, ours.stale,
                                       ours.callsign, ours.remarks), (kind, proto)
            assert abs(again.lat - ours.lat) < 1e-9 and abs(again.lon - ours.lon) < 1e-9
            assert again.detail.get("__saim") == ours.detail.get("__saim")


def test_types_times_and_stale(emitted, picture):
    for kind, b in _all(emitted):
        root = ET.fromstring(b)
        for k in ("time", "start", "stale"):
            assert ISO_Z.match(root.get(k)), (kind, root.get(k))
        ev = C.parse(b)
        assert ev.stale > ev.start >= ev.time, kind
        assert T.valid_type(ev.type) and ev.uid.startswith(picture.prefix + ".")
        life = (ev.stale - ev.time).total_seconds()
        if kind in ("unit", "entity", "track"):
            assert T.affiliation(ev.type) == ("h" if kind == "track" else "f"), kind
            assert 60 <= life <= 900, (kind, life)   # positions: a few minutes
            want = EPOCH + timedelta(seconds=float(ev.detail["__saim"]["t"]))
            assert abs((ev.time - want).total_seconds()) < 0.002, kind
        elif kind.startswith("alert:"):
            assert T.affiliation(ev.type) is None and ev.type.startswith("b-")
            assert life >= 900, (kind, life)         # alerts stay longer
        else:
            assert ev.type.startswith("u-d-") and ev.stale >= EPOCH + timedelta(seconds=picture.sc.duration_s)
    for b in emitted["track"]:
        ev = C.parse(b)
        assert ev.type == T.HOSTILE_TRACK and ev.callsign.startswith("HOSTILE ")
        assert ev.detail["__saim"]["sidc"].startswith("SHGPUC")


@pytest.mark.parametrize("name", sorted(ALERTS))
def test_each_alert_priority_carries_its_content(emitted, picture, name):
    a, want = ALERTS[name]
    ev = C.parse(emitted[f"alert:{name}"][0])
    assert ev.type == want
    s = ev.detail["__saim"]
    assert (s["owner"], s["type"], s["priority"], s["category"], s["id"]) == (a.owner, a.type, a.priority,
                                                                               a.category, a.details["id"])
    assert json.loads(s["subjects"]) == list(a.subjects)
    assert ev.remarks.endswith(a.message) and a.priority.upper() in ev.remarks
    assert ev.uid == picture.uid("alert", a.details["id"].replace("/", "-"))
    if want in T.EMERGENCY_NAMES:
        assert ev.detail["emergency"]["type"] == T.EMERGENCY_NAMES[want]
        assert ev.links and ev.links[0]["uid"].startswith(picture.prefix + ".unit.")
    elif want == T.GEOFENCE:
        assert ev.links[0]["uid"] == picture.uid("ovl", "RTE-A2")
    else:
        assert int(ev.detail["color"]["argb"]) == T.COLOURS[T.PRIORITY_COLOUR[a.priority]]


def test_shapes_have_their_points(emitted, small):
    by_id = {C.parse(b).detail["__saim"]["id"]: C.parse(b) for b in emitted["overlay"]}
    assert set(by_id) == set(small.overlay)
    obj = by_id["OBJ-A"]                        # a polygon: closed
    assert obj.type == T.SHAPE and len(obj.links) >= 4 and obj.links[0] == obj.links[-1]
    rte = by_id["RTE-A2"]                       # a route: open polyline
    assert rte.type == T.SHAPE and len(rte.links) >= 2 and rte.links[0] != rte.links[-1]
    lat, lon = map(float, rte.links[0]["point"].split(","))
    assert 34 < lat < 36 and -118 < lon < -115
    nai = by_id["NAI-1"]                        # a point with a radius: a circle
    assert nai.type == T.CIRCLE and "shape" in nai.detail


# -- bad input -------------------------------------------------------------------------
def good(**over) -> bytes:
    t = over.pop("t", None) or datetime.now(timezone.utc)   # at call time: a PLI goes stale after 5 min
    ev = C.element("ANDROID-1", "a-f-G-U-C", -116.5, 35.2, t, t + timedelta(minutes=5), callsign="ALPHA")
    for k, v in over.items():
        if k in ("lat", "lon"):
            ev.find("point").set(k, v)
        elif v is None:
            del ev.attrib[k]
        else:
            ev.set(k, v)
    return C.to_bytes(ev)


def _proto_truncated() -> bytes:
    return C.encode(good(), "stream")[:-7]


BAD = [
    ("malformed XML", b"<event uid='x'><point", "xml"),
    ("not an event", b"<?xml version='1.0'?><foo/>", "xml"),
    ("DTD", b"<?xml version='1.0'?><!DOCTYPE e [<!ENTITY a 'aaaa'>]><event uid='&a;'/>", "xml"),
    ("entity bomb", b"<!DOCTYPE lolz [<!ENTITY lol \"lol\"><!ENTITY lol2 \"&lol;&lol;\">]><event/>", "xml"),
    ("truncated protobuf", _proto_truncated(), "protobuf"),
    ("mesh garbage", C.MESH + b"\xff\xff\xff\xff", "protobuf"),
    ("missing uid", good(uid=None), "uid"),
    ("missing type", good(type=None), "type"),
    ("bad type", good(type="hello world"), "type"),
    ("lat=200", good(lat="200"), "point.lat"),
    ("lon=-181", good(lon="-181"), "point.lon"),
    ("lat=NaN", good(lat="NaN"), "point.lat"),
    ("lat not a number", good(lat="north"), "point.lat"),
    ("time far in the future", good(t=NOW + timedelta(days=30)), "time"),
    ("time far in the past", good(t=NOW - timedelta(days=30)), "time"),
    ("year 1970", good(time="1970-01-01T00:00:00Z", start="1970-01-01T00:00:00Z"), "time"),
    ("time not ISO", good(time="yesterday"), "time"),
    ("stale before start", good(stale=C.iso(NOW - timedelta(hours=1))), "stale"),
    ("oversized", good()[:-8] + b"<detail>" + b"x" * 70000 + b"</detail></event>", "bytes"),
    ("empty", b"", "bytes"),
]


@pytest.mark.parametrize("name,data,field", BAD, ids=[b[0] for b in BAD])
def test_bad_input_is_refused_naming_the_field(name, data, field):
    with pytest.raises(C.CotError) as e:
        C.parse(data, now=NOW)
    assert e.value.field == field and field in str(e.value)
    assert isinstance(e.value, ValueError)


def test_good_input_in_every_framing_is_taken():
    for proto in ("xml", "mesh", "stream"):
        ev = C.parse(C.encode(good(), proto), now=NOW)
        assert (ev.uid, ev.callsign, ev.lat, ev.lon) == ("ANDROID-1", "ALPHA", 35.2, -116.5)


def test_unknown_uid_and_other_pli_refusals_are_counted(small):
    from saim_mesh.tak.pli import PliIn, UidMap
    pli = PliIn(small, UidMap({"ANDROID-1": "A2S1E01"}))
    assert pli.take(good(), 100.0) == M.LocationReport(100.0, "A2S1E01", -116.5, 35.2)
    assert pli.take(good(uid="ANDROID-2"), 100.0) is None and pli.rejects == {"unknown-uid": 1}
    assert pli.take(good(lat="200"), 100.0) is None and pli.rejects["point.lat"] == 1
    assert pli.take(b"<event", 100.0) is None and pli.rejects["malformed"] == 1
    assert "not mapped" in pli.last_error or "200" in pli.last_error or pli.last_error
    with pytest.raises(ValueError, match="not in the task organization"):
        PliIn(small, UidMap({"ANDROID-1": "NOPE"}))
