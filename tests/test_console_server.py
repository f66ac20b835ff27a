"""The console's server (docs/console.md section 2): state snapshot, SSE, action endpoints."""
from __future__ import annotations

import io
import json
import threading
import time
from pathlib import Path

import warnings

import httpx
import pytest

with warnings.catch_warnings():   # starlette's notice about httpx2 is not ours to act on
    warnings.simplefilter("ignore")
    from starlette.testclient import TestClient

from saim_mesh import messages as M
from saim_mesh import scenario as S
from saim_mesh import wire as W
from saim_mesh.console.actions import CommandActions
from saim_mesh.console.feed import MeshFeed, hook_inprocess
from saim_mesh.mesh import mesh_units
from saim_mesh.console.server import Server, make_app
from saim_mesh.console.state import State

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def small():
    return S.load(ROOT / "scenarios" / "small")


@pytest.fixture(scope="module")
def uv():
    return S.load(ROOT / "scenarios" / "uv-team")


def alert(owner="A", n=1, t=100.0, typ="out-of-position", prio="immediate"):
    return M.Alert(t, owner, typ, "plan-constraint-violated", prio, ("A1",), f"alert {n}", {"id": f"{owner}/{n}"})


class FakeActions:
    def __init__(self, answer=None, raise_=None):
        self.calls: list = []
        self.answer, self.raise_ = answer, raise_

    def _do(self, kind, unit, **f):
        self.calls.append((kind, unit, f))
        if self.raise_ is not None:
            raise self.raise_
        return self.answer or {"req": "r1", "kind": kind, "ok": True, "error": "", "t": 120.0, "unit": unit}

    def ack(self, unit, alert):
        return self._do("ack", unit, alert=alert)

    def silence(self, unit, types, subjects, areas, until_t, comment):
        return self._do("silence", unit, types=types, subjects=subjects, areas=areas, until_t=until_t,
                        comment=comment)

    def set(self, unit, key, value):
        return self._do("set", unit, key=key, value=value)

    def confirm(self, unit, mission, phase):
        return self._do("confirm", unit, mission=mission, phase=phase)

    def cff(self, unit, cff, action):
        return self._do("cff", unit, cff=cff, action=action)


def fed(sc, n=3000) -> State:
    st = State(sc)
    for ev in sc.events[:n]:
        st.message(ev)
        st.clock(ev.t)
    return st


def test_state_shape_small(small):
    st = fed(small)
    st.alert(alert())
    body = TestClient(make_app(st, FakeActions())).get("/api/state").json()
    assert set(body) == {"scenario", "unit", "units", "overlay", "positions", "tracks", "alerts", "counts", "t",
                         "actors", "silences"}
    assert body["scenario"] == small.name and body["unit"] == "BN" and "A2" in body["actors"]
    assert set(body["units"]) == set(small.taskorg.units)
    assert set(body["units"]["A1"]) == {"name", "kind", "parent", "mission", "mission_type", "state"}
    assert body["units"]["A1"]["parent"] == "A"
    # centroids for leaf units and their ancestors, in lon/lat
    for u in ("A1S1", "A1", "A", "BN"):
        lon, lat = body["positions"][u]
        assert -117 < lon < -116 and 35 < lat < 36
    assert body["tracks"] and all(len(v) == 3 for v in body["tracks"].values())
    feats = body["overlay"]["features"]
    assert body["overlay"]["type"] == "FeatureCollection" and len(feats) == len(small.overlay)
    assert all(-117 < c[0] < -116 for f in feats if f["geometry"]["type"] == "LineString"
               for c in f["geometry"]["coordinates"])
    assert body["alerts"][0]["details"]["id"] == "A/1" and body["counts"] == {"A": {"out-of-position": 1}}
    assert body["t"] == st.t > 0


def test_state_shape_uv(uv):
    st = fed(uv, 5000)
    body = TestClient(make_app(st, FakeActions())).get("/api/state").json()
    assert body["unit"] == "TEAM"
    assert {"TEAM", "UGV1", "UAV2"} <= set(body["positions"])
    assert len(body["overlay"]["features"]) == len(uv.world)
    assert body["units"]["UGV1"]["mission_type"] in ("goto", "patrol")


def test_mission_states_from_plan_confirmations_and_clock(small):
    st = State(small)
    ms = lambda: st.snapshot()["units"]["A1"]   # noqa: E731
    assert ms()["mission"] == "A1-move" and ms()["state"] == "pending"
    st.clock(301.0)   # START-NLT 300 passed unconfirmed
    assert ms()["state"] == "late"
    st.message(M.MissionConfirm(302.0, "A1-move", "A1", "start"))
    assert ms()["state"] == "active"
    st.clock(2161.0)  # END-NLT 2160 passed unconfirmed
    assert ms()["state"] == "late"
    st.message(M.MissionConfirm(2170.0, "A1-move", "A1", "end"))
    assert (ms()["mission"], ms()["mission_type"], ms()["state"]) == ("A1-attack", "attack", "pending")
    events = dict(st.drain())
    assert events["missions"]["A1"]["mission"] == "A1-attack"
    assert events["clock"] == {"t": 2161.0, "ticks": []}   # no wall stamps: not from a mesh tick


def test_positions_are_batched(small):
    st = State(small)
    st.drain()
    for ev in [e for e in small.events if type(e) is M.LocationReport][:2000]:
        st.message(ev)
    out = st.drain()
    assert [e for e, _ in out].count("positions") == 1
    assert st.drain() == []


@pytest.fixture
def client(small):
    st = fed(small, 500)
    st.alert(alert("A", 1))
    st.alert(alert("B", 1))
    fake = FakeActions()
    return TestClient(make_app(st, fake)), fake, st


def test_actions_call_the_actions_object(client):
    c, fake, st = client
    r = c.post("/api/ack", json={"unit": "A", "alert": "A/1"})
    assert r.status_code == 200 and r.json()["ok"] and r.json()["result"]["kind"] == "ack"
    r = c.post("/api/silence", json={"unit": "A", "types": ["out-of-position"], "subjects": [], "areas": [],
                                     "for_s": 600, "comment": "known"})
    assert r.status_code == 200
    assert fake.calls[-1] == ("silence", "A", {"types": ["out-of-position"], "subjects": [], "areas": [],
                                               "until_t": st.t + 600, "comment": "known"})
    assert c.post("/api/set", json={"unit": "A2", "key": "voi.out_of_position_m", "value": 300}).status_code == 200
    assert c.post("/api/confirm", json={"unit": "A1", "mission": "A1-move", "phase": "start"}).status_code == 200
    assert c.post("/api/cff", json={"unit": "A2", "cff": "CFF-1", "action": "cancel"}).status_code == 200
    assert [k for k, *_ in fake.calls] == ["ack", "silence", "set", "confirm", "cff"]


@pytest.mark.parametrize("path,body,text", [
    ("/api/ack", {"unit": "ZZ", "alert": "A/1"}, "unknown unit 'ZZ'"),
    ("/api/ack", {"unit": "A", "alert": "A/99"}, "unknown alert 'A/99'"),
    ("/api/ack", {"unit": "A", "alert": "B/1"}, "raised by the EA of B"),
    ("/api/ack", {"unit": "A", "alert": 7}, "field 'alert'"),
    ("/api/ack", {"unit": "A", "alert": "A/1", "x": 1}, "unexpected field 'x'"),
    ("/api/ack", [1, 2], "expected a JSON object"),
    ("/api/silence", {"unit": "A", "types": ["out-of-position"], "for_s": "10"}, "field 'for_s'"),
    ("/api/silence", {"unit": "A", "types": "out-of-position", "for_s": 10}, "field 'types'"),
    ("/api/silence", {"unit": "A", "for_s": 10}, "at least one of"),
    ("/api/silence", {"unit": "A", "types": ["no-such-type"], "for_s": 10}, "unknown alert type"),
    ("/api/silence", {"unit": "A", "areas": ["NO-SUCH-OBJ"], "for_s": 10}, "unknown area 'NO-SUCH-OBJ'"),
    ("/api/unsilence", {"unit": "A", "id": "s9"}, "unknown silence 's9'"),
    ("/api/set", {"unit": "A", "key": "voi.x", "value": "high"}, "field 'value'"),
    ("/api/set", {"unit": "A", "key": "voi.x", "value": True}, "field 'value'"),
    ("/api/set", {"unit": "A", "key": "manager.epoch_s", "value": 1}, "not a [voi] or [voa] setting"),
    ("/api/confirm", {"unit": "A1", "mission": "nope", "phase": "start"}, "unknown mission 'nope'"),
    ("/api/confirm", {"unit": "A1", "mission": "A1-move", "phase": "middle"}, "field 'phase'"),
    ("/api/cff", {"unit": "A2", "cff": "CFF-1", "action": "fire"}, "field 'action'"),
])
def test_bad_input_is_a_400_and_nothing_is_called(client, path, body, text):
    c, fake, _ = client
    r = c.post(path, json=body)
    assert r.status_code == 400, r.text
    assert r.json()["ok"] is False and text in r.json()["error"]
    assert fake.calls == []


def test_malformed_json_is_a_400(client):
    c, fake, _ = client
    r = c.post("/api/ack", content=b"{not json", headers={"content-type": "application/json"})
    assert r.status_code == 400 and "malformed JSON" in r.json()["error"] and fake.calls == []


def test_unit_outside_the_consoles_command(small):
    st = State(small, "A")
    r = TestClient(make_app(st, FakeActions())).post("/api/set", json={"unit": "B", "key": "voi.x", "value": 1})
    assert r.status_code == 400 and "does not act for B" in r.json()["error"]


def test_errors_of_the_ea_and_of_make_are_400s(small):
    st = State(small)
    refused = FakeActions({"req": "r", "kind": "set", "ok": False, "error": "voi.x: unknown key", "t": 5.0})
    r = TestClient(make_app(st, refused)).post("/api/set", json={"unit": "A", "key": "voi.x", "value": 1})
    assert r.status_code == 400 and r.json()["error"] == "voi.x: unknown key" and r.json()["result"]["ok"] is False
    bad = FakeActions(raise_=ValueError("field 'value': out of range"))
    r = TestClient(make_app(st, bad)).post("/api/set", json={"unit": "A", "key": "voi.x", "value": -1})
    assert r.status_code == 400 and "out of range" in r.json()["error"]
    slow = FakeActions(raise_=TimeoutError("10 s"))
    r = TestClient(make_app(st, slow)).post("/api/set", json={"unit": "A", "key": "voi.x", "value": 1})
    assert r.status_code == 504 and r.json()["ok"] is False


def test_sse_delivers_alerts_and_batched_positions(small):
    st = State(small)
    out = io.StringIO()
    server = Server(make_app(st, FakeActions()), 0, out=out)
    url = server.start()
    assert out.getvalue() == f"console {url}\n" and url.startswith("http://127.0.0.1:")
    assert httpx.get(url).status_code == 200
    reports = [e for e in small.events if type(e) is M.LocationReport][:3000]

    def push():
        time.sleep(0.3)
        for ev in reports:
            st.message(ev)
            st.clock(ev.t)
        st.alert(alert("A", 1))
        st.result({"req": "r1", "kind": "ack", "ok": True, "error": "", "t": 1.0, "unit": "A"})
    try:
        events: list[tuple[str, dict]] = []
        with httpx.stream("GET", url + "events", timeout=10.0) as r:
            assert r.headers["content-type"].startswith("text/event-stream")
            threading.Thread(target=push, daemon=True).start()
            ev = None
            for line in r.iter_lines():
                if line.startswith("event: "):
                    ev = line[7:]
                elif line.startswith("data: "):
                    events.append((ev, json.loads(line[6:])))
                    if {"result", "counts"} <= {e for e, _ in events}:
                        break
    finally:
        server.stop()
    kinds = [e for e, _ in events]
    assert kinds[0] == "clock"
    got = dict((e, d) for e, d in events)
    assert got["alert"]["details"]["id"] == "A/1" and got["alert"]["owner"] == "A"
    assert got["counts"] == {"A": {"out-of-position": 1}}
    assert got["result"]["req"] == "r1"
    assert 1 <= kinds.count("positions") <= 10 and "BN" in got["positions"]
    assert not server.thread.is_alive()


def test_feed_checks_every_payload(small):
    st = State(small)
    feed = MeshFeed(small, None, "saim", st, log=lambda *a, **k: None)
    a = alert("A", 1)
    feed.take("saim/alert/A/out-of-position", M.encode(a))
    feed.take("saim/alert/B/out-of-position", M.encode(a))        # owner differs from the key
    feed.take("saim/alert/A/out-of-position", b"\x00junk")
    feed.take("saim/clock", b"junk")
    feed.take("saim/clock", W.encode(W.make(W.Tick, t=10.0, n=5, seq=3)))
    feed.take("saim/cmdlog/A", b"junk")
    ev = next(e for e in small.events if type(e) is M.LocationReport)
    feed.take(feed.ks.key(ev, small.taskorg, small.projection), M.encode(ev))
    assert st.known_alert("A/1") == "A" and len(st.alerts) == 1
    assert st.t == 10.0 and st.entity_pos
    assert feed.gate.rejects.total >= 3


def test_inprocess_hook_feeds_the_state(small):
    from saim_mesh.runner import config_for, make_ea
    eas = [make_ea(small, o, config_for(small, o)) for o in ("A", "A2")]
    st = State(small, "A", actors=["A", "A2"])
    actions = hook_inprocess(eas, small, st)
    for ea in eas:
        ea.start(0.0)
    for ev in small.events[:4000]:
        for ea in eas:
            ea.submit(ev)
    for ea in eas:
        ea.finish(small.duration_s)
    snap = st.snapshot()
    assert st.ended and snap["t"] == small.duration_s and "A" in snap["positions"]
    assert len(snap["alerts"]) == sum(len(ea.alerts) for ea in eas) > 0
    # actions through the endpoint, applied to the EA in process (commands.apply)
    c = TestClient(make_app(st, actions))
    aid = eas[0].alerts[0].details.get("id")
    if aid is not None:   # alert ids: ea_agent/core/notify.py
        r = c.post("/api/ack", json={"unit": "A", "alert": aid})
        assert r.status_code == 200, r.text
        assert r.json()["result"]["kind"] == "ack" and r.json()["result"]["unit"] == "A"
        assert ("result", r.json()["result"]) in st.drain()
    r = c.post("/api/set", json={"unit": "A", "key": "voi.no_such_key", "value": 1})
    assert r.status_code == 400 and r.json()["error"]


def test_reach_follows_a_planned_reorganization(small):
    """R leaves A for BN at 600 s (the small plan's reorganization): A's console acts for R
    before, not after, and the page is told; BN's acts for R throughout."""
    a, bn = State(small, "A", eligible=mesh_units(small)), State(small, "BN", eligible=mesh_units(small))
    assert a.actors == ["A", "A1", "A2", "A3", "R"] and "R" in bn.actors and "A1S1" not in a.actors
    for st in (a, bn):
        st.clock(599.0)
        st.drain()
    assert "R" in a.actors
    a.clock(600.0)
    bn.clock(600.0)
    assert a.actors == ["A", "A1", "A2", "A3"] and "R" in bn.actors
    org = dict(a.drain())["org"]
    assert org["parents"]["R"] == "BN" and org["actors"] == ["A", "A1", "A2", "A3"]
    assert a.snapshot()["units"]["R"]["parent"] == "BN"
    fake = FakeActions()
    r = TestClient(make_app(a, fake)).post("/api/set", json={"unit": "R", "key": "voi.x", "value": 1})
    assert r.status_code == 400 and "does not act for R" in r.json()["error"] and fake.calls == []
    r = TestClient(make_app(bn, fake)).post("/api/set", json={"unit": "R", "key": "voi.x", "value": 1})
    assert r.status_code == 200 and fake.calls[-1][:2] == ("set", "R")


def test_an_unplanned_reorganization_message_moves_the_reach(small):
    a = State(small, "A", eligible=mesh_units(small))
    a.message(M.Reorganization(50.0, "A3", "B"))
    assert "A3" not in a.actors and a.snapshot()["units"]["A3"]["parent"] == "B"
    a.message(M.Reorganization(60.0, "A3", "A3S1"))   # under its own subordinate: ignored, no crash
    assert a.snapshot()["units"]["A3"]["parent"] == "B"


def test_silences_are_listed_with_areas_lifted_and_expire(small):
    st = fed(small, 500)
    sent: list = []

    def run(unit, cmd):   # an EA that takes every command
        sent.append((unit, cmd))
        return {"req": cmd.req, "kind": type(cmd).__name__, "ok": True, "error": "", "t": st.t}
    c = TestClient(make_app(st, CommandActions(run, st)))
    r = c.post("/api/silence", json={"unit": "A2", "types": [], "subjects": [], "areas": ["OBJ-A"],
                                     "for_s": 300, "comment": "expected"})
    assert r.status_code == 200, r.text
    assert sent[-1][1].areas == ["OBJ-A"] and sent[-1][1].until_t == st.t + 300
    [s1] = c.get("/api/state").json()["silences"]
    assert s1["unit"] == "A2" and s1["areas"] == ["OBJ-A"] and s1["comment"] == "expected"
    assert dict(st.drain())["silences"] == [s1]
    r = c.post("/api/unsilence", json={"unit": "A2", "id": "nope"})
    assert r.status_code == 400 and "unknown silence 'nope'" in r.json()["error"]
    r = c.post("/api/unsilence", json={"unit": "A", "id": s1["id"]})
    assert r.status_code == 400 and "on the EA of A2" in r.json()["error"]
    n = len(sent)
    assert c.post("/api/unsilence", json={"unit": "A2", "id": s1["id"]}).status_code == 200
    assert len(sent) == n + 1 and type(sent[-1][1]) is W.UnsilenceCmd and sent[-1][1].id == s1["id"]
    assert c.get("/api/state").json()["silences"] == [] and dict(st.drain())["silences"] == []
    # a refused silence is not listed; an accepted one drops out when it expires
    refuse = CommandActions(lambda u, cmd: {"req": cmd.req, "kind": "silence", "ok": False, "error": "no",
                                            "t": st.t}, st)
    assert TestClient(make_app(st, refuse)).post(
        "/api/silence", json={"unit": "A2", "types": ["contact"], "for_s": 10}).status_code == 400
    assert st.silences == {}
    assert c.post("/api/silence", json={"unit": "A2", "types": ["contact"], "for_s": 10}).status_code == 200
    st.drain()
    st.clock(st.t + 10.0)
    assert dict(st.drain())["silences"] == [] and st.snapshot()["silences"] == []
