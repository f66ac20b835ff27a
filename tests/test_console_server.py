"""The console's server (docs/console.md section 2): state snapshot, SSE, action endpoints."""
from __future__ import annotations

import io
import json
import threading
import time
from collections import Counter
from pathlib import Path

import warnings

import httpx
import pytest

with warnings.catch_warnings():   # starlette's notice about httpx2 is not ours to act on
    warnings.simplefilter("ignore")
    from starlette.testclient import TestClient

from saim_mesh.protocol import messages as M
from saim_mesh import scenario as S
from saim_mesh.protocol import wire as W
from saim_mesh.console.actions import CommandActions
from saim_mesh.console.feed import hook_inprocess, live_feed
from saim_mesh.scenario import mesh_units
from saim_mesh.console.server import Server, make_app
from saim_mesh.console.state import State

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def small():
    return S.load(ROOT / "scenarios" / "small")


@pytest.fixture(scope="module")
def uv():
    return S.load(ROOT / "scenarios" / "uv-team")


def alert(owner="A", n=1, t=100.0, typ="out-of-position", prio="immediate", **details):
    return M.Alert(t, owner, typ, "plan-constraint-violated", prio, ("A1",), f"alert {n}",
                   {"id": f"{owner}/{n}", "story": f"{owner}/{n}", **details})


def notice(kind="renotify", owner="A", n=1, to=None, t=220.0, count=1) -> dict:
    return {"kind": kind, "t": t, "owner": owner, "alert": f"{owner}/{n}", "story": f"{owner}/{n}",
            "type": "out-of-position", "priority": "immediate", "subjects": ["A1"], "message": f"alert {n}",
            "count": count, "to": to or owner, "due_t": 100.0}


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

    def inhibit(self, unit, id, source, target, equal, for_s, comment):
        return self._do("inhibit", unit, id=id, source=source, target=target, equal=equal, for_s=for_s,
                        comment=comment)

    def uninhibit(self, unit, id):
        return self._do("uninhibit", unit, id=id)


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
                         "actors", "silences", "quiet", "notices", "inhibits", "acked"}
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
    ("/api/inhibit", {"unit": "A", "source": ["contact"], "target": {"types": ["distance"]}}, "field 'source': expected an object"),
    ("/api/inhibit", {"unit": "A", "source": {"types": ["contact"]}}, "field 'target': expected an object"),
    ("/api/inhibit", {"unit": "A", "source": {}, "target": {"types": ["distance"]}}, "field 'source': give at least one"),
    ("/api/inhibit", {"unit": "A", "source": {"types": []}, "target": {"types": ["distance"]}}, "give at least one"),
    ("/api/inhibit", {"unit": "A", "source": {"kinds": ["contact"]}, "target": {"types": ["distance"]}},
     "field 'source.kinds': unexpected"),
    ("/api/inhibit", {"unit": "A", "source": {"types": ["no-such-type"]}, "target": {"types": ["distance"]}},
     "field 'source.types': unknown alert type 'no-such-type'"),
    ("/api/inhibit", {"unit": "A", "source": {"types": "contact"}, "target": {"types": ["distance"]}},
     "field 'source.types': expected a list"),
    ("/api/inhibit", {"unit": "A", "source": {"priorities": ["urgent"]}, "target": {"types": ["distance"]}},
     "field 'source.priorities': 'urgent' is not one of"),
    ("/api/inhibit", {"unit": "A", "source": {"types": ["contact"]}, "target": {"types": ["distance"]},
                      "equal": ["track"]}, "field 'equal': unknown label 'track'"),
    ("/api/inhibit", {"unit": "A", "source": {"types": ["contact"]}, "target": {"types": ["distance"]},
                      "equal": "subjects"}, "field 'equal': expected a list"),
    ("/api/inhibit", {"unit": "A", "source": {"types": ["contact"]}, "target": {"types": ["distance"]}, "for_s": -1},
     "field 'for_s'"),
    ("/api/inhibit", {"unit": "A", "source": {"types": ["contact"]}, "target": {"types": ["distance"]}, "for_s": "9"},
     "field 'for_s'"),
    ("/api/inhibit", {"unit": "A", "id": "a/b", "source": {"types": ["contact"]}, "target": {"types": ["distance"]}},
     "field 'id'"),
    ("/api/inhibit", {"unit": "A", "source": {"types": ["contact"]}, "target": {"types": ["distance"]}, "why": "x"},
     "unexpected field 'why'"),
    ("/api/inhibit", {"unit": "ZZ", "source": {"types": ["contact"]}, "target": {"types": ["distance"]}},
     "unknown unit 'ZZ'"),
    ("/api/uninhibit", {"unit": "A", "id": "r9"}, "unknown inhibition rule 'r9' on the EA of A"),
    ("/api/uninhibit", {"unit": "A"}, "field 'id'"),
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
        st.notice(notice("escalate", "A", 1, to="BN"))
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
    assert got["notice"] == notice("escalate", "A", 1, to="BN") and kinds.count("notice") == 1
    assert kinds.index("alert") < kinds.index("notice") < kinds.index("result")   # one each, in order
    assert 1 <= kinds.count("positions") <= 10 and "BN" in got["positions"]
    assert not server.thread.is_alive()


def test_inprocess_hook_feeds_the_state(small):
    from saim_mesh.inprocess.runner import config_for, make_ea
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
        assert st.snapshot()["acked"] == [aid]   # a page opened later knows it was answered
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


# -- issue 30: stories, quiet alerts, notices, inhibition rules ------------------------------
def test_quiet_alerts_are_kept_apart_and_still_counted(small):
    """A silenced or inhibited alert is an `alert` event like any (the page puts it in its
    quiet view), kept in the snapshot's `quiet`, not its `alerts`; the Fig. 7 counts count
    every alert the EA logged, quiet or not."""
    st = State(small)
    st.drain()
    shown = alert("A", 1)
    hushed = alert("A", 2, t=110.0, silenced="console-1-s1")
    muted = alert("A", 3, t=120.0, typ="distance", inhibited_by={"rule": "r1", "source": "A/1"})
    for a in (shown, hushed, muted):
        st.alert(a)
    snap = st.snapshot()
    assert [a["details"]["id"] for a in snap["alerts"]] == ["A/1"]
    assert [a["details"]["id"] for a in snap["quiet"]] == ["A/2", "A/3"]
    assert snap["counts"] == {"A": {"out-of-position": 2, "distance": 1}}
    events = st.drain()
    assert [d["details"]["id"] for e, d in events if e == "alert"] == ["A/1", "A/2", "A/3"]
    assert dict(events)["counts"] == snap["counts"]
    assert st.known_alert("A/3") == "A"   # a quiet alert can still be acknowledged
    c = TestClient(make_app(st, FakeActions()))
    assert c.get("/api/alert", params={"id": "A/3"}).json() == muted.to_json_dict()
    r = c.get("/api/alert", params={"id": "A/9"})
    assert r.status_code == 404 and "unknown alert 'A/9'" in r.json()["error"]
    assert c.get("/api/alert").status_code == 404


def test_notices_are_events_one_each_and_kept_bounded(small):
    from saim_mesh.console import state as state_mod
    st = State(small)
    st.drain()
    st.alert(alert("A", 1))
    for i in range(state_mod.MAX_NOTICES + 5):
        st.notice(notice("renotify", "A", 1, count=i + 1))
    events = st.drain()
    ns = [d for e, d in events if e == "notice"]
    assert len(ns) == state_mod.MAX_NOTICES + 5 and ns[0]["count"] == 1
    kept = st.snapshot()["notices"]
    assert len(kept) == state_mod.MAX_NOTICES and kept[-1]["count"] == state_mod.MAX_NOTICES + 5   # the newest
    assert st.snapshot()["counts"] == {"A": {"out-of-position": 1}}   # a notice is not an alert


def test_the_feed_takes_notices_that_fit_their_key(small):
    st = State(small)
    feed = live_feed(small, None, "saim", st, log=lambda *a, **k: None)
    assert "saim/notice/*/*" in feed.keys()

    def payload(**kw):
        d = {**notice(), **kw}
        return W.encode(W.make(W.Notice, **d))
    feed.take("saim/notice/A/A", payload())                                   # A's re-notification
    feed.take("saim/notice/BN/A", payload(kind="escalate", to="BN"))          # escalated to BN
    feed.take("saim/notice/BN/B", payload(kind="escalate", to="BN"))          # owner A on B's key
    feed.take("saim/notice/BN/A", payload(kind="escalate", to="B"))           # to B on BN's key
    feed.take("saim/notice/BN/A", payload(kind="renotify", to="BN"))          # a re-notification goes to its owner
    feed.take("saim/notice/A/A", b"\x00junk")
    got = [(d["kind"], d["to"]) for e, d in st.drain() if e == "notice"]
    assert got == [("renotify", "A"), ("escalate", "BN")]
    assert feed.gate.rejects.total == 4
    assert st.snapshot()["notices"][1] == notice("escalate", to="BN")


def test_inhibit_and_uninhibit_are_validated_sent_and_listed(small):
    """POST /api/inhibit builds the `inhibit` command (MatcherSpecs from the JSON objects);
    the rules in force that this console made are listed (`inhibits` in the snapshot and as
    an event) until lifted; a refused one is not listed; uninhibit names a listed rule."""
    st = fed(small, 500)
    st.alert(alert("A2", 1, typ="contact"))
    sent: list = []

    def run(unit, cmd):   # an EA that takes every command
        sent.append((unit, cmd))
        return W.make(W.CmdResult, req=cmd.req, kind="inhibit" if type(cmd) is W.InhibitCmd else "uninhibit",
                      ok=True, error="", t=st.t, ref=cmd.id)
    c = TestClient(make_app(st, CommandActions(run, st)))
    st.drain()
    body = {"unit": "A2", "id": "contact-mutes-distance", "source": {"types": ["contact"]},
            "target": {"types": ["distance", "strength"], "priorities": ["priority", "routine"]},
            "equal": ["subjects"], "for_s": 600, "comment": "one story"}
    r = c.post("/api/inhibit", json=body)
    assert r.status_code == 200, r.text
    assert r.json()["result"]["ref"] == "contact-mutes-distance"
    unit, cmd = sent[-1]
    assert unit == "A2" and type(cmd) is W.InhibitCmd and cmd.id == "contact-mutes-distance"
    assert cmd.source == W.MatcherSpec(types=["contact"])
    assert cmd.target == W.MatcherSpec(types=["distance", "strength"], priorities=["priority", "routine"])
    assert (cmd.equal, cmd.for_s, cmd.comment) == (["subjects"], 600.0, "one story")
    [rule] = c.get("/api/state").json()["inhibits"]
    assert rule == {"id": "contact-mutes-distance", "unit": "A2", "source": {"types": ["contact"]},
                    "target": {"types": ["distance", "strength"], "priorities": ["priority", "routine"]},
                    "equal": ["subjects"], "for_s": 600.0, "comment": "one story", "t": st.t,
                    "active_s": 600.0}
    assert dict(st.drain())["inhibits"] == [rule]
    # no id: the console names it; no for_s: the EA's voa.expiry_s (what the page assumes too)
    r = c.post("/api/inhibit", json={"unit": "A2", "source": {"subjects": ["H2"]}, "target": {"owners": ["A2"]}})
    assert r.status_code == 200, r.text
    auto = sent[-1][1]
    assert auto.id.startswith("console-") and auto.for_s == 0.0 and auto.equal == []
    assert {i["id"]: i["active_s"] for i in st.snapshot()["inhibits"]}[auto.id] == 720.0
    r = c.post("/api/uninhibit", json={"unit": "A", "id": "contact-mutes-distance"})
    assert r.status_code == 400 and "on the EA of A" in r.json()["error"]
    n = len(sent)
    r = c.post("/api/uninhibit", json={"unit": "A2", "id": "contact-mutes-distance"})
    assert r.status_code == 200 and len(sent) == n + 1 and type(sent[-1][1]) is W.UninhibitCmd
    assert [i["id"] for i in st.snapshot()["inhibits"]] == [auto.id]
    assert [i["id"] for i in dict(st.drain())["inhibits"]] == [auto.id]
    refuse = CommandActions(lambda u, cmd: {"req": cmd.req, "kind": "inhibit", "ok": False, "error": "64 rules",
                                            "t": st.t}, st)
    r = TestClient(make_app(st, refuse)).post("/api/inhibit", json={**body, "id": "r2"})
    assert r.status_code == 400 and r.json()["error"] == "64 rules"
    assert [i["id"] for i in st.snapshot()["inhibits"]] == [auto.id]


def test_inprocess_notices_quiet_alerts_and_an_inhibition_rule(small):
    """Armed in-process EAs (A, A2; nobody acknowledging): every re-notification and
    escalation each EA gives reaches the state once, as `notice` events; an inhibition rule
    sent through the endpoint is in force on the EA, and the alerts it mutes are logged
    marked inhibited_by and kept quiet, while the counts count them."""
    from saim_mesh.inprocess.runner import config_for, make_ea, wire_notices
    eas = [make_ea(small, o, config_for(small, o, overrides={"notify": {"escalate_s": 120.0}})) for o in ("A", "A2")]
    wire_notices(eas)   # as the runner does: A2's escalations reach A's EA
    st = State(small, "A", actors=["A", "A2"])
    actions = hook_inprocess(eas, small, st)
    c = TestClient(make_app(st, actions))
    for ea in eas:
        ea.arm()
        ea.start(0.0)
    r = c.post("/api/inhibit", json={"unit": "A", "id": "contact-mutes", "source": {"types": ["contact"]},
                                     "target": {"types": ["distance", "strength"]}, "equal": ["subjects"]})
    assert r.status_code == 200, r.text
    assert "contact-mutes" in eas[0].notify.inhibitor.rules
    for ev in small.events:
        for ea in eas:
            ea.submit(ev)
    for ea in eas:
        ea.finish(small.duration_s)
    snap = st.snapshot()
    given = [n.to_json_dict() for ea in eas for n in ea.notices]
    assert sorted(map(str, snap["notices"])) == sorted(map(str, given))
    kinds = {(n["kind"], n["owner"], n["to"]) for n in snap["notices"]}
    assert {("renotify", "A", "A"), ("escalate", "A", "BN"), ("escalate", "A2", "A")} <= kinds
    assert [n.alert for n in eas[0].received] == [n["alert"] for n in snap["notices"]
                                                  if n["kind"] == "escalate" and n["owner"] == "A2"]
    muted = [a for a in eas[0].alerts if "inhibited_by" in a.details]
    assert {a.details["id"] for a in muted} == {a["details"]["id"] for a in snap["quiet"]} and muted
    assert all(a.details["inhibited_by"]["rule"] == "contact-mutes" for a in muted)
    assert not {a.details["id"] for a in muted} & {a["details"]["id"] for a in snap["alerts"]}
    logged = Counter((a.owner, a.type) for ea in eas for a in ea.alerts)
    assert {(o, t): n for o, c_ in snap["counts"].items() for t, n in c_.items()} == logged
    # lifted through the endpoint: gone from the EA and from the list
    r = c.post("/api/uninhibit", json={"unit": "A", "id": "contact-mutes"})
    assert r.status_code == 200 and eas[0].notify.inhibitor.rules == {} and st.snapshot()["inhibits"] == []
