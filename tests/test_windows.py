"""Doctrinal time windows (issue 53): a link-up made in its window, a passage of lines
completed in its `complete_window`, a planned fire confirmed in its window. A window met is
silent; one that passes unmet is told once, at its close; nothing raises it twice (a late
fact, a snapshot going on). A bad window is refused on load, naming mission and field."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from ea_agent.core.snapshot import snapshot
from ea_agent.domains.suo.messages import CallForFireConfirm
from saim_mesh import scenario as S

from .conftest import ROOT
from .synthetic import EPOCH, Force, end, feed, ll, mission, point, start

F = Force()
CP = point("CP-AB", 0.0, 0.0)
WINDOW = [300.0, 600.0]
UNTIL = 1000.0


def link(typ: str = "link-up", **params) -> list[dict]:
    return [mission("A1-link", "A1", typ, partner="B1", point="CP-AB", at=450, **params)]


def sc_of(tmp_path, missions: list[dict]):
    return F.scenario(tmp_path, [CP], missions)


def away(t0: float, t1: float) -> list:
    return F.stays("A1", -3000, 0, t0, t1) + F.stays("B1", 3000, 0, t0, t1)


def there(t0: float, t1: float) -> list:
    return F.stays("A1", -50, 0, t0, t1) + F.stays("B1", 50, 0, t0, t1)


def windowed(ea, check: str | None = None) -> list:
    """The alerts the windows gave (the coordination detector's own carry no `window`)."""
    return [a for a in ea.alerts if "window" in a.details and (check is None or a.details["check"] == check)]


def run(sc, msgs: list, until: float = UNTIL):
    ea = feed(sc, msgs, until)
    ea.finish(until)
    return ea


# ------------------------------------------------------------------------ link-up, relief in place
@pytest.mark.parametrize("typ", ["link-up", "relief-in-place"])
def test_a_link_up_made_in_its_window_is_silent(tmp_path, typ):
    sc = sc_of(tmp_path, link(typ, window=WINDOW))
    ea = run(sc, [start(10, "A1-link", "A1")] + away(10, 390) + there(400, UNTIL))
    assert not windowed(ea)
    assert not [a for a in ea.alerts if a.type == "coordination"], [a.message for a in ea.alerts]


@pytest.mark.parametrize("typ", ["link-up", "relief-in-place"])
def test_a_link_up_window_passing_unmet_is_told_once_at_its_close(tmp_path, typ):
    sc = sc_of(tmp_path, link(typ, window=WINDOW))
    ea = run(sc, [start(10, "A1-link", "A1")] + away(10, UNTIL))
    got = windowed(ea)
    assert len(got) == 1, [a.message for a in got]
    a = got[0]
    assert a.type == "coordination" and a.priority == "immediate" and a.category == "plan-constraint-violated"
    assert WINDOW[1] <= a.t <= WINDOW[1] + EPOCH   # at the close, on event time
    assert a.details["how"] == "late" and a.details["mission"] == "A1-link" and set(a.subjects) == {"A1", "B1"}
    # the window is the link-up's time: the at + fuzz_s timer is not armed besides it
    assert len([x for x in ea.alerts if x.type == "coordination"]) == 1


def test_a_link_up_made_after_its_window_closed_is_not_told_again(tmp_path):
    sc = sc_of(tmp_path, link(window=WINDOW))
    ea = run(sc, [start(10, "A1-link", "A1")] + away(10, 690) + there(700, UNTIL))
    assert len(windowed(ea)) == 1 and WINDOW[1] <= windowed(ea)[0].t <= WINDOW[1] + EPOCH


def test_a_link_up_made_only_before_its_window_does_not_meet_it(tmp_path):
    sc = sc_of(tmp_path, link(window=WINDOW))
    ea = run(sc, [start(10, "A1-link", "A1")] + there(10, 200) + away(210, UNTIL))
    assert len(windowed(ea)) == 1


def test_a_link_up_made_before_its_window_and_still_held_meets_it(tmp_path):
    sc = sc_of(tmp_path, link(window=WINDOW))
    ea = run(sc, [start(10, "A1-link", "A1")] + there(10, UNTIL))
    assert not windowed(ea)


def test_without_a_window_the_link_up_keeps_its_at_and_fuzz(tmp_path):
    sc = sc_of(tmp_path, link())
    ea = run(sc, [start(10, "A1-link", "A1")] + away(10, UNTIL))
    assert not windowed(ea)
    assert len([a for a in ea.alerts if a.type == "coordination"]) == 1


def test_an_aborted_plan_raises_no_window(tmp_path):
    from ea_agent.domains.suo.messages import Order
    sc = sc_of(tmp_path, link(window=WINDOW))
    ea = run(sc, [start(10, "A1-link", "A1"), Order(100.0, "abort-plan", "main", "BN")] + away(10, UNTIL))
    assert not windowed(ea)


# ------------------------------------------------------------------------ passage of lines
def passage(**params) -> list[dict]:
    return [mission("A1-pass", "A1", "passage-of-lines", partner="B1", point="CP-AB", at=200, **params)]


@pytest.mark.parametrize("ended, told", [(450.0, None), (800.0, "late"), (None, "late"), (150.0, "early")])
def test_a_passage_complete_window(tmp_path, ended, told):
    sc = sc_of(tmp_path, passage(complete_window=WINDOW))
    msgs = [start(10, "A1-pass", "A1")] + there(10, UNTIL)
    if ended is not None:
        msgs.append(end(ended, "A1-pass", "A1"))
    got = windowed(run(sc, msgs), "complete_window")
    if told is None:
        assert not got, [a.message for a in got]
        return
    assert len(got) == 1, [a.message for a in got]
    a = got[0]
    assert a.type == "coordination" and a.priority == "immediate" and a.details["how"] == told
    at = WINDOW[1] if told == "late" else ended   # late: at the close; early: when it ends
    assert at <= a.t <= at + EPOCH


# ------------------------------------------------------------------------ planned fires
def fire_plan() -> list[dict]:
    return [mission("A1-abf", "A1", "attack-by-fire", position="BP-A1",
                    fires=[{"cff": "F1", "window": WINDOW}])]


BP = {"type": "Feature", "properties": {"id": "BP-A1", "kind": "battle-position"},
      "geometry": {"type": "Polygon", "coordinates": [[ll(-3100, -100), ll(-2900, -100), ll(-2900, 100),
                                                       ll(-3100, 100), ll(-3100, -100)]]}}


def confirm(t: float, cff: str = "F1", x: float = 5000.0, requester: str = "A1") -> CallForFireConfirm:
    return CallForFireConfirm(float(t), cff, requester, *ll(x, 0.0), 200.0)


def fires_run(tmp_path, extra: list, until: float = UNTIL, **fire):
    plan = fire_plan()
    plan[0]["params"]["fires"][0].update(fire)
    sc = F.scenario(tmp_path, [CP, BP], plan)
    return sc, run(sc, [start(10, "A1-abf", "A1")] + F.stays("A1", -3000, 0, 10, until) + extra, until)


@pytest.mark.parametrize("at, told", [(400.0, None), (None, "late"), (700.0, "late"), (100.0, "early")])
def test_a_planned_fire_confirmed_in_its_window(tmp_path, at, told):
    _, ea = fires_run(tmp_path, [] if at is None else [confirm(at)])
    got = windowed(ea, "fires")
    if told is None:
        assert not got, [a.message for a in got]
        return
    assert len(got) == 1, [a.message for a in got]
    a = got[0]
    assert a.type == "fire-support" and a.priority == "immediate" and a.details["cff"] == "F1"
    assert a.details["how"] == told and a.subjects == ("A1",)
    want = WINDOW[1] if told == "late" else at
    assert want <= a.t <= want + EPOCH


def test_a_confirmation_near_own_units_warns_them_and_meets_the_window(tmp_path):
    """One fact, two detectors: the call-for-fire warning and the planned fire's window."""
    _, ea = fires_run(tmp_path, [confirm(400.0, x=-3000.0)])
    assert [a for a in ea.alerts if a.type == "call-for-fire"]
    assert not windowed(ea, "fires")


def test_another_fire_confirmed_does_not_meet_the_window(tmp_path):
    _, ea = fires_run(tmp_path, [confirm(400.0, cff="F2")])
    assert len(windowed(ea, "fires")) == 1


def test_the_same_fire_confirmed_by_another_requester_does_not_meet_it(tmp_path):
    _, ea = fires_run(tmp_path, [confirm(400.0, requester="A2")])
    assert len(windowed(ea, "fires")) == 1
    _, ea = fires_run(tmp_path / "b", [confirm(400.0, requester="B1")], requester="B1")
    assert not windowed(ea, "fires")


def test_a_planned_fire_requested_outside_the_subtree_is_followed(tmp_path):
    """Its requester's command post is a source the EA depends on (live/depend.py): on the
    mesh the confirmation is in order before the window's close is judged."""
    from saim_mesh.live.depend import depends
    sc, ea = fires_run(tmp_path, [], until=50.0, requester="B1")
    assert "B1" in ea.domain.needs(3000.0).by["requester"]
    assert "cp.B" in depends(sc, ea, ["cp.A", "cp.B", "cp.BN"])


def test_what_an_ea_must_hear_includes_its_planned_fires(tmp_path):
    sc, ea = fires_run(tmp_path, [], until=50.0)
    assert ea.domain.needs(3000.0).by["cff"] == frozenset({"F1"})
    sc2 = sc_of(tmp_path / "b", link(window=WINDOW))
    assert "cff" not in feed(sc2, [], 10.0).domain.needs(3000.0).by   # no planned fire: no change


# ------------------------------------------------------------------------ snapshots
def test_a_snapshot_before_the_close_raises_once_in_each_copy(tmp_path):
    sc = sc_of(tmp_path, link(window=WINDOW))
    msgs = [start(10, "A1-link", "A1")] + away(10, UNTIL)
    a = feed(sc, msgs, 500.0)
    b = snapshot(a, share=[sc])
    for ea in (a, b):
        feed(sc, msgs, UNTIL, ea=ea, since=500.0).finish(UNTIL)
        assert len(windowed(ea)) == 1


def test_a_snapshot_after_the_close_does_not_raise_it_again(tmp_path):
    sc = sc_of(tmp_path, link(window=WINDOW))
    msgs = [start(10, "A1-link", "A1")] + away(10, 690) + there(700, UNTIL)
    a = feed(sc, msgs, 650.0)
    assert len(windowed(a)) == 1
    b = snapshot(a, share=[sc])
    feed(sc, msgs, UNTIL, ea=b, since=650.0).finish(UNTIL)
    assert len(windowed(b)) == 1   # the one it had: the copy's timer fired already


# ------------------------------------------------------------------------ validation
BAD = [
    (link(window=[600, 300]), "params.window", "not before"),
    (link(window=[300, float("nan")]), "params.window", "finite"),
    (link(window=[300]), "params.window", "[from, until]"),
    (link(window={"from": 300, "until": 600}), "params.window", "[from, until]"),
    (passage(complete_window=[900, 100]), "params.complete_window", "not before"),
    (fire_plan()[:0] + [mission("A1-abf", "A1", "attack-by-fire", position="BP-A1",
                                fires=[{"cff": "F1", "window": WINDOW, "windw": 1}])], "params.fires[0].windw",
     "unknown key"),
    ([mission("A1-abf", "A1", "attack-by-fire", position="BP-A1", fires=[{"cff": "F1"}])],
     "params.fires[0].window", "missing"),
    ([mission("A1-abf", "A1", "attack-by-fire", position="BP-A1", fires=[{"cff": "F1", "window": [5, 1]}])],
     "params.fires[0].window", "not before"),
    ([mission("A1-abf", "A1", "attack-by-fire", position="BP-A1",
              fires=[{"cff": "F1", "window": WINDOW, "requester": "Z9"}])], "params.fires[0].requester", "unknown unit"),
    (passage(window=WINDOW), "params.window", "unknown parameter"),   # a passage's window is complete_window
]


@pytest.mark.parametrize("missions, field, why", BAD)
def test_a_bad_window_is_refused_in_one_line(tmp_path, missions, field, why):
    d = F.write(tmp_path / "sc", [CP, BP], missions)
    with pytest.raises(S.ScenarioError) as e:
        S.load(d, events=False)
    msg = str(e.value)
    assert "\n" not in msg and f"({missions[0]['id']})" in msg and f"field '{field}'" in msg and why in msg, msg


def test_the_cli_refuses_a_bad_window_with_exit_2(tmp_path):
    d = F.write(tmp_path / "sc", [CP], link(window=[600, 300]))
    r = subprocess.run([sys.executable, "-m", "saim_mesh", "validate", str(d)], capture_output=True, text=True,
                       cwd=ROOT, timeout=120)
    assert r.returncode == 2 and "A1-link" in r.stderr and "params.window" in r.stderr, r.stderr


def test_a_good_window_loads(tmp_path):
    d = F.write(tmp_path / "sc", [CP, BP], link(window=WINDOW) + passage(complete_window=WINDOW)
                + fire_plan())
    plan = S.load(d, events=False)
    assert json.dumps(plan.plans["main"].missions[0].params["window"]) == "[300.0, 600.0]"


def test_a_branch_whose_task_has_a_window_arms_it_when_it_fires(tmp_path):
    task = {"partner": "B1", "point": "CP-AB", "at": 450, "window": WINDOW}
    br = mission("A1-br", "A1", "branch", owner="A", task="link-up", task_params=task,
                 trigger={"kind": "unit-at", "unit": "A1", "area": "CP-AB", "within_m": 5000})
    sc = sc_of(tmp_path, [br])
    ea = run(sc, away(10, UNTIL))
    got = windowed(ea)
    assert len(got) == 1 and got[0].details["mission"] == "A1-br", [a.message for a in ea.alerts]
    assert WINDOW[1] <= got[0].t <= WINDOW[1] + EPOCH


def test_a_peer_subscribes_to_its_planned_fires_confirmations(tmp_path):
    from dissemination.interest import Interest
    from dissemination.keyspace import KeySpace
    _, ea = fires_run(tmp_path, [], until=50.0)
    keys = Interest(KeySpace("saim"), 3000.0).of(ea.domain.needs(3000.0))
    assert any(k.startswith("saim/cff/") and k.endswith("/F1") for k in keys), sorted(keys)
