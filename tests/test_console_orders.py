"""The console's orders and live confirmations (issue 33): what the page asks is checked
(a clear 400, nothing sent), then published as a directive by the console's unit at the
page's event time plus `in_s`; a console that cannot publish directives says so."""
from __future__ import annotations

from pathlib import Path

import pytest
from starlette.testclient import TestClient

from saim_mesh import scenario as S
from saim_mesh.console.actions import CommandActions
from saim_mesh.console.server import make_app
from saim_mesh.console.state import State

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def small():
    return S.load(ROOT / "scenarios" / "small", events=False)


def console(sc, direct):
    st = State(sc, "BN")
    st.clock(1200.0)
    sent: list = []

    def run(unit, cmd):   # commands (not directives) are not what this test is about
        raise AssertionError(f"a command was sent: {cmd}")
    acts = CommandActions(run, st, direct=direct(sent) if direct else None)
    return TestClient(make_app(st, acts)), sent


def publishing(sent):
    def direct(unit, kind, fields):
        sent.append((unit, kind, fields))
        return f"req{len(sent)}"
    return direct


def test_an_order_is_published_as_the_consoles_unit_at_its_event_time(small):
    c, sent = console(small, publishing)
    r = c.post("/api/order", json={"unit": "BN", "action": "execute-plan", "plan": "withdrawal", "in_s": 30})
    assert r.status_code == 200, r.text
    assert r.json()["result"]["req"] == "req1"
    assert sent == [("BN", "order", {"action": "execute-plan", "plan": "withdrawal", "mission": "", "at": 1230.0})]
    assert c.post("/api/order", json={"unit": "BN", "action": "abort-plan"}).status_code == 200
    assert sent[-1][2]["at"] == 1210.0   # the default lead
    # on the live mesh a confirmation goes up the chain as a directive too
    assert c.post("/api/confirm", json={"unit": "A1", "mission": "A1-move", "phase": "start"}).status_code == 200
    assert sent[-1] == ("A1", "confirm", {"mission": "A1-move", "phase": "start", "at": 1210.0})


@pytest.mark.parametrize("body,text", [
    ({"unit": "BN", "action": "retreat"}, "field 'action'"),
    ({"unit": "BN", "action": "execute-plan", "plan": "nosuch"}, "unknown plan 'nosuch'"),
    ({"unit": "BN", "action": "execute-plan"}, "names its plan"),
    ({"unit": "BN", "action": "start-mission"}, "names its mission"),
    ({"unit": "BN", "action": "end-mission", "mission": "ZZ-9"}, "unknown mission 'ZZ-9'"),
    ({"unit": "BN", "action": "abort-plan", "plan": "main"}, "field 'plan'"),
    ({"unit": "BN", "action": "abort-plan", "in_s": -5}, "field 'in_s'"),
    ({"unit": "BN", "action": "abort-plan", "in_s": "soon"}, "field 'in_s'"),
    ({"unit": "BN", "action": "abort-plan", "at": 5}, "unexpected field 'at'"),
    ({"unit": "QQ", "action": "abort-plan"}, "unknown unit 'QQ'"),
])
def test_a_bad_order_is_a_400_and_nothing_is_published(small, body, text):
    c, sent = console(small, publishing)
    r = c.post("/api/order", json=body)
    assert r.status_code == 400 and text in r.json()["error"], r.text
    assert sent == []


def test_a_console_that_cannot_publish_directives_says_so(small):
    c, _ = console(small, None)
    r = c.post("/api/order", json={"unit": "BN", "action": "abort-plan"})
    assert r.status_code == 400 and "go over the mesh" in r.json()["error"]


def test_a_call_for_fire_the_console_never_heard_goes_to_the_ea_which_answers(small):
    st = State(small, "BN")
    sent, cmds = [], []

    def run(unit, cmd):
        cmds.append((unit, cmd.cff))
        return {"req": cmd.req, "kind": "cff", "ok": False, "error": "unknown call for fire 'F9'", "t": 0.0}
    c = TestClient(make_app(st, CommandActions(run, st, direct=publishing(sent))))
    r = c.post("/api/cff", json={"unit": "A2", "cff": "F9", "action": "confirm"})
    assert r.status_code == 400 and "unknown call for fire" in r.json()["error"]
    assert sent == [] and cmds == [("A2", "F9")]


def test_a_heard_call_for_fire_is_confirmed_as_a_directive(small):
    from saim_mesh.protocol import messages as M
    st = State(small, "BN")
    st.clock(1200.0)
    st.message(M.CallForFire(1190.0, "F1", "A2", 10.1, 50.2, 250.0))
    sent: list = []
    acts = CommandActions(lambda u, cmd: (_ for _ in ()).throw(AssertionError(cmd)), st, direct=publishing(sent))
    c = TestClient(make_app(st, acts))
    r = c.post("/api/cff", json={"unit": "A2", "cff": "F1", "action": "confirm"})
    assert r.status_code == 200, r.text
    assert sent == [("A2", "cff", {"cff": "F1", "requester": "A2", "lon": 10.1, "lat": 50.2, "radius_m": 250.0,
                                   "at": 1210.0})]
