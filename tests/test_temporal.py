"""The 8 temporal constraint types (Fig. 6) and the 4 timed monitors (6.6.4)."""
import pytest

from ea_agent.core.config import load_config
from ea_agent.core.manager import ExecutionAssistant
from ea_agent.core.plan import MissionSpec, PlanSpec, TimeConstraint
from ea_agent.core.timed import TimedMonitors
from ea_agent.domains.suo.domain import SuoDomain
from saim_mesh.protocol.messages import MissionConfirm


def ea_with(sc, missions, owner="A"):
    cfg = load_config()
    dom = SuoDomain(owner, sc.taskorg, {"main": PlanSpec("main", missions)}, "main", sc.overlay, sc.projection, cfg)
    ea = ExecutionAssistant(owner, dom, cfg)
    ea.start(0.0)
    return ea


def schedule_alerts(sc, start, end, confirms, until=2000.0):
    m = MissionSpec("m1", "A1", "move", start, end, (), {"destination": "BP-A1-BLUE"})
    ea = ea_with(sc, [m])
    for t, phase in confirms:
        ea.submit(MissionConfirm(t, "m1", "A1", phase))
    ea.finish(until)
    return [(a.t, a.details["phase"], a.details["how"]) for a in ea.alerts if a.type == "schedule"]


TC = TimeConstraint


@pytest.mark.parametrize("start, end, confirms, expect", [
    (TC("ASAP"), TC("ASAP"), [(1500, "start"), (1900, "end")], []),
    (TC("ON-ORDER"), TC("ON-ORDER"), [(700, "start")], [(700, "start", "unordered")]),   # no order came
    (TC("START-AT", 100), TC(), [(100, "start")], []),
    (TC("START-AT", 100), TC(), [(200, "start")], [(130, "start", "late")]),
    (TC("START-AT", 100), TC(), [(50, "start")], [(50, "start", "early")]),
    (TC("START-NLT", 100), TC(), [(125, "start")], []),
    (TC("START-NLT", 100), TC(), [(200, "start")], [(130, "start", "late")]),
    (TC("START-NET", 100), TC(), [(80, "start")], []),
    (TC("START-NET", 100), TC(), [(40, "start")], [(40, "start", "early")]),
    (TC(), TC("END-AT", 300), [(0, "start"), (310, "end")], []),
    (TC(), TC("END-AT", 300), [(0, "start"), (250, "end")], [(250, "end", "early")]),
    (TC(), TC("END-NLT", 300), [(0, "start"), (400, "end")], [(330, "end", "late")]),
    (TC(), TC("END-NLT", 300), [(0, "start"), (280, "end")], []),
    (TC(), TC("END-NET", 300), [(0, "start"), (200, "end")], [(200, "end", "early")]),
    (TC(), TC("END-NET", 300), [(0, "start"), (900, "end")], []),
])
def test_constraint_types(small, start, end, confirms, expect):
    assert schedule_alerts(small, start, end, confirms) == expect


def test_lateness_repeats_progressively(small):
    # never started: alerts at 30 s late, then (120 s late is inside the 120 s suppression) 300 s, 600 s
    got = schedule_alerts(small, TC("START-NLT", 100), TC(), [])
    assert [t for t, _, _ in got] == [130.0, 400.0, 700.0]


def test_mission_override_of_schedule_threshold(small):
    m = MissionSpec("m1", "A1", "move", TC("START-NLT", 100), TC(), (), {"destination": "BP-A1-BLUE",
                                                                         "voi": {"schedule_s": 10}})
    ea = ea_with(small, [m])
    ea.submit(MissionConfirm(125, "m1", "A1", "start"))
    ea.finish(500)
    assert [a.t for a in ea.alerts if a.type == "schedule"] == [110.0]


def test_start_monitor_waits_for_predecessor(small):
    a = MissionSpec("a", "A1", "move", TC(), TC(), (), {"destination": "BP-A1-BLUE"})
    b = MissionSpec("b", "A1", "attack", TC("START-NET", 1000), TC(), ("a",), {"objective": "OBJ-A"})
    ea = ea_with(small, [a, b])
    assert ea.domain.plan.state["b"] == "pending"
    ea.submit(MissionConfirm(500, "a", "A1", "end"))
    ea.advance(600)
    assert ea.domain.plan.state["b"] == "ready"
    ea.submit(MissionConfirm(700, "b", "A1", "start"))
    ea.finish(800)
    assert [(x.t, x.details["how"]) for x in ea.alerts if x.type == "schedule"] == [(700.0, "early")]


def _mon():
    fails = []
    return TimedMonitors(), fails, (lambda t, m, how: fails.append((m.kind, t, how)))


def test_timed_monitor_types():
    tm, fails, cb = _mon()
    tm.not_later_than("a", 10, cb)
    tm.not_earlier_than("b", 10, cb)
    tm.in_window("c", 10, 20, cb)
    tm.near_time("d", 5, 2, cb, mode="relative", now=10)     # must occur in [13, 17]
    tm.occurred("b", 5)            # early
    tm.occurred("c", 15)           # fine
    tm.occurred("d", 16)           # fine
    assert tm.advance(9) == 0
    assert tm.advance(25) == 1     # 'a' never came
    assert fails == [("not-earlier-than", 5, "early"), ("not-later-than", 10, "late")]
    assert tm.pending() == 0


def test_timed_monitor_event_before_monitor_and_rearm():
    tm, fails, cb = _mon()
    tm.occurred("x", 3)
    tm.in_window("x", 5, 9, cb)              # judged at once: 3 is early
    assert fails == [("in-window", 3, "early")]
    calls = []
    tm.not_later_than("y", 10, lambda t, m, how: calls.append(t) or (t + 10 if t < 30 else None))
    tm.advance(100)
    assert calls == [10, 20, 30]


def test_timed_monitor_cancel():
    tm, fails, cb = _mon()
    tm.not_later_than("a", 10, cb, tag="m1")
    tm.cancel("m1")
    tm.advance(100)
    assert fails == []
