"""Hostiles ahead of a moving unit and the commander's decision (paper 6.6.1,
Respond-To-Monitored-Red-Activity): ea_agent/domains/suo/detect/ahead.py watches
`voi.ahead_m` of a running movement's route (an attack's axis, or the corridor line when
there is none) ahead of its unit, `voi.ahead_width_m` either side; the mission class
answers with a `threat-ahead` alert whose `details.decision` lists the options and the
recommended one. `decide` (domain, `commands.apply`, CLI, console) carries one out.

Small synthetic scenarios in tmp_path, loaded with the scenario loader, one EA fed on
scenario time, as tests/test_check_families.py does. Geometry is in local metres
east/north of the generator's origin (UTM 11N); a platoon's entities stand 20 m apart in
a row centred on the given point (A1 has six, so that it can be strong enough to attack
a weak hostile at the attack's 3:1; the others two)."""
from __future__ import annotations

import json
import math

import numpy as np

import pytest

from ea_agent.domains.suo.messages import MissionConfirm
from saim_mesh import cli
from saim_mesh.authority import commands as C
from saim_mesh import scenario as S
from saim_mesh.protocol import wire as W
from saim_mesh.console.actions import BadRequest, CommandActions, validate
from saim_mesh.console.state import State

from .conftest import BATTALION, SMALL
from .synthetic import (EPOCH, EXPIRY_S, Force, alerts_of, box, end, feed, line, mission, near, play, start,
                        told, track)

AHEAD_M = 1500.0   # configs/ea.toml voi.ahead_m
WIDTH_M = 300.0    # voi.ahead_width_m

# A1 has six entities, the other platoons two
FORCE = Force({"A1": tuple(f"A1E{i}" for i in range(1, 7)), "A2": ("A2E1", "A2E2"), "B1": ("B1E1", "B1E2")},
              name="decisions")
write, at, path = FORCE.write, FORCE.at, FORCE.path


def scenario(tmp_path, missions, features=None):
    return FORCE.scenario(tmp_path, FEATURES if features is None else features, missions)


def stays(unit: str, x: float, y: float, t0: float = 10.0, t1: float = 2000.0) -> list:
    return FORCE.stays(unit, x, y, t0, t1)


def of(ea, typ: str, mission: str | None = None) -> list:
    return alerts_of(ea, typ, mission)


# ----------------------------------------------------------------------------- the ground
RTE_1 = line("RTE-1", "route", (-2000, 0), (6000, 0))
AA_E = box("AA-E", "assembly-area", 5800, -200, 6200, 200)
OBJ_E = box("OBJ-E", "objective", 3000, -300, 3400, 300)
AX_1 = line("AX-1", "route", (0, 0), (3000, 0))
NAI_N = box("NAI-N", "area", -500, 3000, 500, 3600)          # the branch's trigger, far north
BP_2 = box("BP-2", "battle-position", 1900, -1200, 2300, -800)  # the branch's task, ~2.2 km from A1's start
BP_A2 = box("BP-A2", "battle-position", -200, -5200, 200, -4800)
FEATURES = [RTE_1, AA_E, OBJ_E, AX_1, NAI_N, BP_2, BP_A2]

MOVE = mission("A1-move", "A1", "move", route="RTE-1", destination="AA-E")
BRANCH = mission("A-branch", "A1", "branch", trigger={"kind": "hostile-in-area", "area": "NAI-N", "min_strength": 1},
                 task="occupy", task_params={"position": "BP-2"}, owner="A")


def east(v: float = 5.0, t0: float = 100.0):
    """Standing at (0, 0) until t0, then east along RTE-1 at v m/s."""
    return lambda t: (max(0.0, t - t0) * v, 0.0)


def moving(unit: str = "A1", t1: float = 2000.0) -> list:
    """A1 moving east on its route from its start at t=100; A2 sitting far south."""
    return path(unit, 10, t1, east()) + stays("A2", 0, -3000, t1=t1) + [start(100, "A1-move", "A1")]


def threat(ea) -> object:
    ta = of(ea, "threat-ahead")
    assert len(ta) == 1, [(a.t, a.type, a.subjects) for a in ea.alerts]
    return ta[0]


# ============================================================ 1. a hostile on the route ahead
def test_a_hostile_on_the_route_1_km_ahead_asks_the_commander(tmp_path):
    sc = scenario(tmp_path, [MOVE])
    ea = play(sc, moving() + [track(150, "H1", 250 + 1000, 0)], 300)   # A1 is at x=250 at t=150
    a = threat(ea)
    assert near(a.t, 150.0), a.t
    assert a.subjects == ("A1", "H1") and a.priority == "immediate" and a.category == "adversarial-activity"
    assert a.owner == "A"
    d = a.details
    assert d["mission"] == "A1-move" and d["strength"] == 4 and d["tracks"] == ["H1"]
    assert d["decision"]["options"] == ["abort", "continue"] and d["decision"]["recommended"] == "abort"
    assert d["decision"]["branches"] == []
    assert "abort" in a.message and "A1" in a.message and "recommended" in a.message


@pytest.mark.parametrize("where", [(1250, 600), (1250, -600), (-250, 0), (3250, 0)],
                         ids=["600m-left", "600m-right", "500m-behind", "3km-ahead"])
def test_a_hostile_beside_behind_or_far_ahead_is_not_a_threat_ahead(tmp_path, where):
    sc = scenario(tmp_path, [MOVE])
    ea = play(sc, moving() + [track(150, "H1", *where)], 300)   # A1 at x=1000 by t=300: 3 km stays > 1.5 km
    assert not of(ea, "threat-ahead")


def test_a_hostile_inside_the_width_of_the_route_is_ahead(tmp_path):
    """250 m to the side (within ahead_width_m = 300) counts: the width is either side."""
    sc = scenario(tmp_path, [MOVE])
    ea = play(sc, moving() + [track(150, "H1", 1250, -250)], 300)
    assert near(threat(ea).t, 150.0)


def test_the_watched_stretch_moves_with_the_unit(tmp_path):
    """A hostile 1950 m down the route is beyond ahead_m; it is told once the moving unit
    closes to 1500 m (A1 at 5 m/s from x=0 at t=100 reaches x=500 at t=200)."""
    sc = scenario(tmp_path, [MOVE])
    ea = play(sc, moving() + [track(110, "H1", 2000, 0)], 400)
    a = threat(ea)
    assert 195.0 <= a.t <= 215.0, a.t
    assert a.subjects == ("A1", "H1")


def test_a_far_track_does_not_decide_when_a_threat_ahead_is_told(tmp_path):
    """An in-process EA hears every track; a peer hears only those near its units. Both
    must tell a hostile ahead at the same moment: when the unit's own move brings it
    within ahead_m (A1 reports at t=203 from x=515, 1485 m short of H1), not at the next
    change of some track or unit 30 km away, nor at the next periodic scan (battalion-sensors' M
    told it 4 s later through the mesh than in process)."""
    sc = scenario(tmp_path, [MOVE])
    base = (path("A1", 13, 400, east()) + stays("A2", 0, -3000, t1=400)
            + [start(100, "A1-move", "A1"), track(110, "H1", 2000, 0)])
    alone, beside = (threat(play(sc, msgs, 400)) for msgs in (base, base + FORCE.elsewhere(101, 400)))
    assert told([alone]) == told([beside])
    assert near(alone.t, 203.0), alone.t


def test_several_hostiles_ahead_are_one_alert_unit_first_then_the_tracks(tmp_path):
    sc = scenario(tmp_path, [MOVE])
    ea = play(sc, moving() + [track(150, "H2", 1400, 100, 3), track(150, "H1", 900, -50, 2)], 300)
    a = threat(ea)
    assert a.subjects == ("A1", "H1", "H2")
    assert a.details["strength"] == 5 and a.details["tracks"] == ["H1", "H2"]


def test_a_mission_not_yet_started_watches_nothing_ahead(tmp_path):
    """The move is planned but never confirmed started: the unit is not moving on it."""
    sc = scenario(tmp_path, [MOVE])
    msgs = [m for m in moving() if type(m) is not MissionConfirm] + [track(150, "H1", 1000, 0)]
    ea = play(sc, msgs, 300)
    assert not of(ea, "threat-ahead")


def test_a_hostile_already_there_is_told_when_the_move_starts(tmp_path):
    sc = scenario(tmp_path, [MOVE])
    msgs = path("A1", 10, 400, east(t0=200)) + stays("A2", 0, -3000, t1=400) + [
        track(50, "H1", 1000, 0), start(200, "A1-move", "A1")]
    ea = play(sc, msgs, 400)
    a = threat(ea)
    assert 200.0 <= a.t <= 200.0 + 5.0 + 2 * EPOCH, a.t   # at its start, or the next scan


# ============================================================== 2. a branch the plan holds
def test_a_dormant_branch_for_the_unit_is_offered_and_recommended(tmp_path):
    sc = scenario(tmp_path, [MOVE, BRANCH])
    ea = play(sc, moving() + [track(150, "H1", 1250, 0)], 300)
    d = threat(ea).details["decision"]
    assert d["options"] == ["abort", "execute:A-branch", "continue"]
    assert d["recommended"] == "execute:A-branch" and d["branches"] == ["execute:A-branch"]
    assert ea.domain.plan.state["A-branch"] == "dormant"   # only offered: not executed


@pytest.mark.parametrize("other", [
    dict(BRANCH, params=dict(BRANCH["params"], owner="BN")),   # in the battalion's plan, not A's
    dict(BRANCH, unit="A2"),                                   # for another unit
    dict(BRANCH, type="sequel"),                               # a sequel is no alternative to the move
], ids=["owned-by-BN", "for-A2", "a-sequel"])
def test_a_branch_that_is_not_the_units_alternative_is_not_offered(tmp_path, other):
    sc = scenario(tmp_path, [MOVE, other])
    ea = play(sc, moving() + [track(150, "H1", 1250, 0)], 300)
    d = threat(ea).details["decision"]
    assert d["options"] == ["abort", "continue"] and d["recommended"] == "abort"


def test_a_branch_whose_trigger_fired_is_not_offered_again(tmp_path):
    """H5 in NAI-N at t=120 fires the branch (executed by the EA): no longer dormant."""
    sc = scenario(tmp_path, [MOVE, BRANCH])
    ea = play(sc, moving() + [track(120, "H5", 0, 3300), track(150, "H1", 1250, 0)], 300)
    assert of(ea, "contingency") and ea.domain.plan.state["A-branch"] == "active"
    d = threat(ea).details["decision"]
    assert d["options"] == ["abort", "continue"] and d["recommended"] == "abort"


# ====================================================== 3. an attack: strong enough or not
ATTACK = mission("A1-atk", "A1", "attack", objective="OBJ-E")                 # the corridor to OBJ-E
ATTACK_AXIS = mission("A1-atk", "A1", "attack", objective="OBJ-E", axis="AX-1")


def _attacking(tmp_path, m, hostile_xy, strength):
    sc = scenario(tmp_path, [m])
    msgs = (stays("A1", 0, 0, t1=300) + stays("A2", 0, -3000, t1=300) + [start(100, "A1-atk", "A1")]
            + [track(150, "H1", *hostile_xy, strength)])
    return play(sc, msgs, 300)


@pytest.mark.parametrize("m", [ATTACK, ATTACK_AXIS], ids=["corridor", "axis"])
@pytest.mark.parametrize("strength, recommended", [(1, "continue"), (2, "continue"), (3, "abort"), (20, "abort")])
def test_an_attack_goes_on_when_three_times_as_strong_else_aborts(tmp_path, m, strength, recommended):
    """A1 has 6 members: 6/2 = 3 is the attack's DESIRED_STRENGTH_RATIO, 6/3 = 2 is short of it."""
    ea = _attacking(tmp_path, m, (1000, 0), strength)
    a = threat(ea)
    assert near(a.t, 150.0) and a.subjects == ("A1", "H1") and a.priority == "immediate"
    assert a.details["mission"] == "A1-atk" and a.details["strength"] == strength
    assert a.details["decision"]["options"] == ["continue", "abort"]
    assert a.details["decision"]["recommended"] == recommended


@pytest.mark.parametrize("m", [ATTACK, ATTACK_AXIS], ids=["corridor", "axis"])
def test_an_attack_with_a_hostile_beside_its_corridor_is_not_asked(tmp_path, m):
    ea = _attacking(tmp_path, m, (1000, 600), 20)
    assert not of(ea, "threat-ahead")


# ======================================================================= 4. the decision
NEXT = mission("A1-next", "A1", "occupy", start={"type": "START-NLT", "t": 300}, after=["A1-move"],
               position="BP-2")
MOVE_NLT = dict(MOVE, end={"type": "END-NLT", "t": 400})
A2_HOLD = mission("A2-hold", "A2", "occupy", position="BP-A2")   # A2 sits 2 km north of it: out of position
DECIDE_T = 160.0


def _north_after(t0: float):
    """A1 at (0, 0) until t0, then 20 m/s north, off its route (150 m off by t0 + 8 s)."""
    return lambda t: (0.0, max(0.0, t - t0) * 20.0)


def _decision_run(tmp_path, missions=(MOVE_NLT, NEXT, BRANCH, A2_HOLD)):
    """A1 standing on its route with a hostile 1 km ahead (the threat-ahead at t=152); A2
    out of its position from its start (an alert without a decision). Returns the EA at
    DECIDE_T, the messages after it, and the threat-ahead alert."""
    sc = scenario(tmp_path, list(missions))
    msgs = (path("A1", 10, 900, _north_after(DECIDE_T + 20)) + stays("A2", 0, -3000, t1=900)
            + [start(100, "A1-move", "A1"), start(100, "A2-hold", "A2"), track(150, "H1", 1000, 0)])
    ea = feed(sc, msgs, DECIDE_T)
    return ea, msgs, threat(ea)


def _go_on(ea, msgs, until: float = 900.0, since: float = DECIDE_T):
    ea = feed(None, msgs, until, ea=ea, since=since)
    ea.finish(until)
    return ea


def decide(ea, alert: str, option: str, t: float = DECIDE_T) -> W.CmdResult:
    return C.apply(ea, C.make("decide", alert=alert, option=option), t)


def test_abort_ends_the_mission_its_monitors_and_what_follows_it(tmp_path):
    ea, msgs, a = _decision_run(tmp_path)
    assert ea.domain.plan.state["A1-move"] == "active"
    res = decide(ea, a.details["id"], "abort")
    assert res.ok and res.error == "" and res.kind == "decide" and res.ref == a.details["id"]
    assert ea.domain.plan.state["A1-move"] == "aborted"
    assert ea.domain.ahead.watched() == []
    ea = _go_on(ea, msgs)
    # A1 walks 14 km off its route, far past END-NLT 400: nothing more about the aborted move
    late = [x for x in ea.alerts if x.t > DECIDE_T and x.details.get("mission") == "A1-move"
            and x.type in ("out-of-position", "projected-out-of-position", "projected-late", "schedule",
                           "threat-ahead")]
    assert late == [], [(x.t, x.type) for x in late]
    # its successor waits for new orders: never ready, never monitored (START-NLT 300 passes unremarked)
    assert ea.domain.plan.state["A1-next"] == "pending"
    assert not [x for x in ea.alerts if x.details.get("mission") == "A1-next"]
    assert ea.domain.plan.state["A-branch"] == "dormant"


def test_continue_changes_nothing(tmp_path):
    """The twin of abort: the move is still monitored (off its route, late to end) and its
    successor follows when it ends."""
    ea, msgs, a = _decision_run(tmp_path)
    res = decide(ea, a.details["id"], "continue")
    assert res.ok and res.error == ""
    assert ea.domain.plan.state["A1-move"] == "active" and ea.domain.plan.state["A-branch"] == "dormant"
    assert [m.id for m, _ in ea.domain.ahead.watched()] == ["A1-move"]
    ea = _go_on(ea, msgs + [end(600, "A1-move", "A1")])
    oop = of(ea, "out-of-position", "A1-move")
    assert oop and DECIDE_T + 20 < oop[0].t <= DECIDE_T + 20 + 8 + 5 + 2 * EPOCH, [x.t for x in oop]
    # END-NLT 400 passed unconfirmed: foretold (projected-late), then told when 120 s late
    assert of(ea, "projected-late", "A1-move") and of(ea, "schedule", "A1-move")
    assert ea.domain.plan.state["A1-move"] == "done" and ea.domain.plan.state["A1-next"] != "pending"
    assert of(ea, "schedule", "A1-next")   # START-NLT 300 long past when it became ready


def test_executing_the_branch_monitors_its_task_from_the_decision(tmp_path):
    ea, msgs, a = _decision_run(tmp_path)
    assert a.details["decision"]["recommended"] == "execute:A-branch"
    assert not [x for x in ea.alerts if x.details.get("mission") == "A-branch"]   # dormant till now
    res = decide(ea, a.details["id"], "execute:A-branch")
    assert res.ok and res.error == "", res.error
    assert ea.domain.plan.state["A-branch"] == "active"
    ea = _go_on(ea, msgs, until=DECIDE_T + 30)
    oop = of(ea, "out-of-position", "A-branch")
    assert oop, [(x.t, x.type, x.details.get("mission")) for x in ea.alerts]
    assert near(oop[0].t, DECIDE_T), oop[0].t
    assert oop[0].subjects == ("A1",) and oop[0].details["control_measure"] == "BP-2"
    assert not of(ea, "contingency")   # the commander chose it: no trigger fired


def test_a_branch_executed_by_its_trigger_meanwhile_cannot_be_executed_again(tmp_path):
    ea, msgs, a = _decision_run(tmp_path)
    ea = feed(None, msgs + [track(170, "H5", 0, 3300)], 180.0, ea=ea, since=DECIDE_T)
    assert of(ea, "contingency") and ea.domain.plan.state["A-branch"] == "active"
    res = decide(ea, a.details["id"], "execute:A-branch", 180.0)
    assert not res.ok and "A-branch" in res.error and "not waiting" in res.error


@pytest.mark.parametrize("option, words", [
    ("execute:NOPE", ["'execute:NOPE'", "not an option", "abort, execute:A-branch, continue"]),
    ("retreat", ["'retreat'", "not an option"]),
    ("ABORT", ["'ABORT'", "not an option"]),
])
def test_an_option_not_in_the_alerts_list_is_refused_and_nothing_changes(tmp_path, option, words):
    ea, msgs, a = _decision_run(tmp_path)
    res = decide(ea, a.details["id"], option)
    assert not res.ok and res.kind == "decide" and res.ref == a.details["id"]
    for w in words:
        assert w in res.error, (w, res.error)
    assert ea.domain.plan.state["A1-move"] == "active" and ea.domain.plan.state["A-branch"] == "dormant"
    # the EA still works: A1 leaving its route is told, and the alert can still be decided
    assert decide(ea, a.details["id"], "continue").ok
    ea = _go_on(ea, msgs, until=300.0)
    assert of(ea, "out-of-position", "A1-move")


def test_an_unknown_alert_is_refused(tmp_path):
    ea, msgs, a = _decision_run(tmp_path)
    res = decide(ea, "A/999", "abort")
    assert not res.ok and "unknown alert" in res.error and "A/999" in res.error
    res = decide(ea, "B/1", "abort")
    assert not res.ok and "unknown alert" in res.error
    assert ea.domain.plan.state["A1-move"] == "active"
    ea = _go_on(ea, msgs, until=300.0)
    assert of(ea, "out-of-position", "A1-move")


def test_an_alert_that_asks_for_no_decision_is_refused(tmp_path):
    ea, msgs, a = _decision_run(tmp_path)
    oop = of(ea, "out-of-position", "A2-hold")
    assert oop, [(x.t, x.type) for x in ea.alerts]
    res = decide(ea, oop[0].details["id"], "abort")
    assert not res.ok and "asks for no decision" in res.error and oop[0].details["id"] in res.error
    assert ea.domain.plan.state["A2-hold"] == "active" and ea.domain.plan.state["A1-move"] == "active"
    assert decide(ea, a.details["id"], "abort").ok   # the EA still takes a good one


def test_a_mission_aborted_once_cannot_be_aborted_again(tmp_path):
    ea, msgs, a = _decision_run(tmp_path)
    assert decide(ea, a.details["id"], "abort").ok
    res = decide(ea, a.details["id"], "abort", DECIDE_T + 10)
    assert not res.ok and "A1-move" in res.error and "not running" in res.error
    assert ea.domain.plan.state["A1-move"] == "aborted"


def test_the_domain_decide_raises_valueerror_for_a_bad_option(tmp_path):
    ea, msgs, a = _decision_run(tmp_path)
    with pytest.raises(ValueError, match="not an option"):
        ea.domain.decide(a.details, "nope", DECIDE_T)
    with pytest.raises(ValueError, match="asks for no decision"):
        ea.domain.decide({"mission": "A1-move"}, "abort", DECIDE_T)
    assert ea.domain.decide(a.details, "continue", DECIDE_T) == "A1-move continues"
    assert ea.domain.decide(a.details, "abort", DECIDE_T) == "A1-move aborted"


def test_the_decide_command_is_checked_when_made():
    cmd = C.make("decide", alert="A/3", option="abort")
    assert type(cmd) is W.DecideCmd and (cmd.alert, cmd.option) == ("A/3", "abort") and cmd.req
    assert W.decode_control(W.DecideCmd, W.encode(cmd), 1 << 20) == cmd
    with pytest.raises(ValueError, match="option"):
        C.make("decide", alert="A/3")
    with pytest.raises(ValueError, match="decide"):
        C.make("decide", alert="A/3", option="")
    with pytest.raises(ValueError, match="decide"):
        C.make("decide", alert="A/3", option="x" * 129)


# ================================================================= 5. VOA: once per mission
def _watching(tmp_path, hostiles: list, until: float, missions=(MOVE,)):
    """A1 standing on its route with the move running from t=100, and these hostiles."""
    sc = scenario(tmp_path, list(missions))
    msgs = stays("A1", 0, 0, t1=until) + stays("A2", 0, -3000, t1=until) + [start(100, "A1-move", "A1")]
    return play(sc, msgs + hostiles, until)


GONE_T = 300.0   # H1 and H2 leave the picture (strength 0)
FIRST = [track(150, "H1", 1000, 0), track(210, "H2", 1200, 50),
         track(GONE_T, "H1", 1000, 0, 0), track(GONE_T, "H2", 1200, 50, 0)]


def test_the_commander_is_asked_once_per_mission_not_for_each_hostile(tmp_path):
    ea = _watching(tmp_path, FIRST, 600)
    a = threat(ea)
    assert near(a.t, 150.0) and a.subjects == ("A1", "H1")


def test_asked_again_for_new_hostiles_after_the_expiry(tmp_path):
    back = GONE_T + EXPIRY_S + 60
    ea = _watching(tmp_path, FIRST + [track(back, "H3", 800, 0)], back + 100)
    ta = of(ea, "threat-ahead")
    assert [x.subjects for x in ta] == [("A1", "H1"), ("A1", "H3")]
    assert near(ta[1].t, back) and ta[1].priority == "immediate" and not ta[1].details.get("repeat")
    assert ta[1].details["decision"]["options"] == ["abort", "continue"]


def test_not_asked_again_before_the_expiry(tmp_path):
    back = GONE_T + EXPIRY_S - 120
    ea = _watching(tmp_path, FIRST + [track(back, "H3", 800, 0)], back + 100)
    assert len(of(ea, "threat-ahead")) == 1


def test_a_threat_that_stays_ahead_is_one_story(tmp_path):
    """The expiry counts from when the story was last active: a hostile sitting ahead
    for longer than the expiry is not told again."""
    ea = _watching(tmp_path, [track(150, "H1", 1000, 0)], 150 + 2 * EXPIRY_S)
    assert len(of(ea, "threat-ahead")) == 1


def test_each_mission_is_asked_on_its_own(tmp_path):
    """The move ends and its successor (an attack) starts with the hostile still ahead:
    a new mission, a new question, well within the expiry."""
    atk = mission("A1-atk", "A1", "attack", after=["A1-move"], objective="OBJ-E")
    ea = _watching(tmp_path, [track(150, "H1", 1000, 0), end(250, "A1-move", "A1"), start(250, "A1-atk", "A1")],
                   400, missions=(MOVE, atk))
    ta = of(ea, "threat-ahead")
    assert [x.details["mission"] for x in ta] == ["A1-move", "A1-atk"], [(x.t, x.details["mission"]) for x in ta]
    assert near(ta[1].t, 250.0, 5.0 + 2 * EPOCH)


# ======================================================================= 6. the CLI
def _parsed(monkeypatch, argv):
    seen = []
    from saim_mesh.cli import commands
    monkeypatch.setattr(commands, "cmd_command", lambda a: seen.append(commands._command_fields(a)) or 0)
    assert cli.main(argv) == 0
    return seen


def test_the_cli_parses_decide_into_its_command_fields(monkeypatch):
    seen = _parsed(monkeypatch, ["decide", "--scenario", "X", "--unit", "A", "--alert", "A/3", "--option", "abort"])
    assert seen == [("decide", {"alert": "A/3", "option": "abort"})]
    kind, fields = seen[0]
    assert type(C.make(kind, **fields)) is W.DecideCmd
    seen = _parsed(monkeypatch, ["decide", "--scenario", "X", "--unit", "BN", "--alert", "BN/28",
                                 "--option", "execute:BN-branch-ABF"])
    assert seen == [("decide", {"alert": "BN/28", "option": "execute:BN-branch-ABF"})]


@pytest.mark.parametrize("missing", ["--alert", "--option"])
def test_the_cli_requires_alert_and_option(monkeypatch, capsys, missing):
    argv = ["decide", "--scenario", "X", "--unit", "A", "--alert", "A/3", "--option", "abort"]
    i = argv.index(missing)
    del argv[i:i + 2]
    from saim_mesh.cli import commands
    monkeypatch.setattr(commands, "cmd_command", lambda a: pytest.fail("ran without " + missing))
    with pytest.raises(SystemExit) as e:
        cli.main(argv)
    assert e.value.code == 2 and missing in capsys.readouterr().err


def test_the_cli_refuses_an_unknown_unit_before_the_mesh(capsys):
    assert cli.main(["decide", "--scenario", str(SMALL), "--unit", "ZZ", "--alert", "ZZ/1", "--option", "abort"]) == 2
    assert "unknown unit 'ZZ'" in capsys.readouterr().err


# ===================================================================== 7. the console
@pytest.fixture
def console(tmp_path):
    """A's EA at DECIDE_T with its threat-ahead, and a console State that has seen its alerts."""
    ea, msgs, a = _decision_run(tmp_path)
    sc = S.load(tmp_path / "sc", events=False)
    st = State(sc)
    for x in ea.alerts:
        st.alert(x)
    st.clock(DECIDE_T)
    return ea, st, a


def test_console_validate_accepts_a_known_alert_of_that_unit(console):
    ea, st, a = console
    aid = a.details["id"]
    assert validate("decide", {"unit": "A", "alert": aid, "option": "abort"}, st) == (
        "A", {"alert": aid, "option": "abort"})
    # the option is the EA's to check against the alert's own list
    assert validate("decide", {"unit": "A", "alert": aid, "option": "execute:A-branch"}, st)[1]["option"] == \
        "execute:A-branch"


@pytest.mark.parametrize("body, text", [
    ({"unit": "A", "alert": "A/99", "option": "abort"}, "unknown alert 'A/99'"),
    ({"unit": "A", "alert": "B/1", "option": "abort"}, "unknown alert 'B/1'"),
    ({"unit": "A", "alert": "@"}, "field 'option'"),
    ({"unit": "A", "alert": "@", "option": ""}, "field 'option'"),
    ({"unit": "A", "alert": "@", "option": 3}, "field 'option'"),
    ({"unit": "A1", "alert": "@", "option": "abort"}, "raised by the EA of A, not A1"),
    ({"unit": "ZZ", "alert": "@", "option": "abort"}, "unknown unit 'ZZ'"),
    ({"unit": "A", "alert": "@", "option": "abort", "why": "x"}, "unexpected field 'why'"),
    ({"unit": "A", "option": "abort"}, "field 'alert'"),
], ids=["unknown-alert", "alert-of-another-console", "no-option", "empty-option", "option-not-text",
        "alert-of-another-unit", "unknown-unit", "extra-field", "no-alert"])
def test_console_validate_rejects(console, body, text):
    ea, st, a = console
    body = {k: (a.details["id"] if v == "@" else v) for k, v in body.items()}   # @: the threat-ahead's id
    with pytest.raises(BadRequest) as e:
        validate("decide", body, st)
    assert text in str(e.value), str(e.value)


def test_console_decide_end_to_end_in_process(console):
    """POST /api/decide through the console app to the EA in process (commands.apply)."""
    import warnings
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        from starlette.testclient import TestClient
    from saim_mesh.console.server import make_app

    ea, st, a = console
    actions = CommandActions(lambda unit, cmd: C.apply({"A": ea}[unit], cmd, DECIDE_T), st, push=True)
    c = TestClient(make_app(st, actions))
    aid = a.details["id"]
    r = c.post("/api/decide", json={"unit": "A", "alert": aid, "option": "execute:NOPE"})
    assert r.status_code == 400 and "not an option" in r.json()["error"], r.text
    assert ea.domain.plan.state["A1-move"] == "active"
    r = c.post("/api/decide", json={"unit": "A", "alert": aid, "option": "abort"})
    assert r.status_code == 200 and r.json()["ok"] and r.json()["result"]["kind"] == "decide", r.text
    assert ea.domain.plan.state["A1-move"] == "aborted"


# ======================================================================== 8. the oracle
@pytest.fixture(scope="module")
def battalion_truth():
    return json.loads((BATTALION / "truth.json").read_text())


def test_the_scripted_battalion_truth_has_the_threat_ahead_of_M(battalion_truth):
    inc = [i for i in battalion_truth["incidents"] if i["type"] == "threat-ahead"]
    assert inc, "no threat-ahead incident in scenarios/battalion/truth.json"
    m = [i for i in inc if i.get("about") == ["M"]]
    assert len(m) == 1, inc
    i = m[0]
    assert {"M", "H9"} <= set(i["subjects"]) and i["owner"] == "BN" and i["accept"] == ["threat-ahead"]
    assert i["t0"] <= 2420 and i["t1"] >= 2370 and i["t0"] <= i["at"] <= i["t1"]


def test_the_battalions_ea_asks_about_M_as_the_truth_says(battalion_truth):
    """BN's EA over the scripted battalion (~2 s): its threat-ahead alerts match the truth's
    incident (owner, window, about M) and none is unwanted; M's march offers the ABF branch."""
    from saim_mesh.inprocess.evaluate import _matches
    from saim_mesh.inprocess.runner import run

    sc = S.load(BATTALION)
    [ea] = run(sc, ["BN"])
    ta = [a for a in ea.alerts if a.type == "threat-ahead"]
    assert ta, "BN's EA never asked about the hostiles ahead of M"
    items = battalion_truth["incidents"] + battalion_truth["situations"]
    inc = [i for i in battalion_truth["incidents"] if i["type"] == "threat-ahead" and i.get("about") == ["M"]]
    assert inc and all(any(_matches(a, i) for a in ta) for i in inc), [(a.t, a.subjects) for a in ta]
    assert all(any(_matches(a, i) for i in items) for a in ta), [(a.t, a.subjects) for a in ta]
    a = next(a for a in ta if _matches(a, inc[0]))
    assert a.subjects[0] == "M" and "H9" in a.subjects and a.priority == "immediate"
    assert any(o.startswith("execute:") for o in a.details["decision"]["options"])
    assert a.details["decision"]["recommended"].startswith("execute:")


class _Oracle:
    """The oracle's threat-ahead labelling (`Truth._ahead`, `Truth._line_of`) on a made-up
    truth: unit U's centroid at unit(t), hostiles at hostiles(t) (id -> (x, y)), on 5 s ticks."""

    def __init__(self, unit, hostiles, t1: float, features=(), corridor_start=None):
        from shapely.geometry import LineString, Polygon

        from ea_agent.domains.suo import oracle as O
        self.O = O
        tr = O.Truth.__new__(O.Truth)
        tr.voi, tr.owners = O.SPEC, ["A"]
        tr.incidents, tr.situations = [], []
        tr.ticks = [k * O.TICK for k in range(int(t1 / O.TICK) + 1)]
        tr.geom, tr.area = {}, {}
        for fid, pts in features:
            g = LineString(pts) if len(pts) == 2 or pts[0] != pts[-1] else Polygon(pts)
            tr.geom[fid] = g
            tr.area[fid] = g
        tr.corridor_start = dict(corridor_start or {})
        tr.member_points = lambda u, k: np.array([unit(tr.ticks[k])])
        tr.hostiles_at = lambda t: {h: (x, y, 4) for h, (x, y) in hostiles(t).items()}
        tr.owners_of = lambda u, t: ["A"]
        self.tr = tr

    def run(self, m: dict, s: float = 0.0, e: float = math.inf):
        line = self.tr._line_of(m["id"], m)
        if line is not None:
            self.tr._ahead(m["id"], m, line, s, e)
        return line

    def musts(self):
        return [i for i in self.tr.incidents if i["type"] == "threat-ahead"]


ROUTE_O = ("RTE-1", [(-2000.0, 0.0), (6000.0, 0.0)])
AA_O = ("AA-E", [(5800.0, -200.0), (6200.0, -200.0), (6200.0, 200.0), (5800.0, 200.0), (5800.0, -200.0)])
OMOVE = {"id": "U-move", "unit": "U", "type": "move", "params": {"route": "RTE-1", "destination": "AA-E"}}


def _still(t):
    return (0.0, 0.0)


@pytest.mark.parametrize("xy, must, may", [
    ((1000.0, 0.0), True, True),      # well inside the stretch ahead
    ((1000.0, 250.0), False, True),   # near its edge (within TOLERANCE_M of the width): may be told
    ((1000.0, 600.0), False, False),  # beside
    ((-500.0, 0.0), False, False),    # behind
    ((3000.0, 0.0), False, False),    # far ahead
], ids=["ahead", "edge", "beside", "behind", "far"])
def test_the_oracle_labels_hostiles_ahead(xy, must, may):
    o = _Oracle(_still, lambda t: {"H1": xy} if 100 <= t <= 200 else {}, 400, [ROUTE_O, AA_O])
    o.run(OMOVE)
    got = o.musts()
    assert bool(got) is must, got
    if must:
        [i] = got
        assert i["owner"] == "A" and i["subjects"] == ["H1", "U"] and i["about"] == ["U"]
        assert (i["t0"], i["at"], i["t1"]) == (85.0, 100.0, 130.0)   # from 15 s before to 30 s after
    sit = [s for s in o.tr.situations if "threat-ahead" in s["accept"]]
    assert bool(sit) is may, sit


def test_the_oracle_tells_a_threat_ahead_once_per_episode():
    """Present 100-200 s and back at 300-400 s: one story; back after EPISODE_S: two."""
    def hostiles(gap):
        return lambda t: {"H1": (1000.0, 0.0)} if 100 <= t <= 200 or 200 + gap <= t <= 300 + gap else {}
    o = _Oracle(_still, hostiles(100), 1500, [ROUTE_O, AA_O])
    o.run(OMOVE)
    assert len(o.musts()) == 1
    o = _Oracle(_still, hostiles(800), 1500, [ROUTE_O, AA_O])
    o.run(OMOVE)
    assert [i["at"] for i in o.musts()] == [100.0, 1000.0]


def test_the_oracle_follows_the_corridor_when_there_is_no_route():
    m = {"id": "U-atk", "unit": "U", "type": "attack", "params": {"objective": "AA-E"}}
    o = _Oracle(_still, lambda t: {"H1": (1000.0, 0.0)} if t >= 100 else {}, 300, [AA_O],
                corridor_start={"U-atk": np.array([0.0, 0.0])})
    line = o.run(m)
    # from CORRIDOR_BACK_M behind the start (an estimate) to the objective's edge
    from ea_agent.domains.suo import oracle as O
    assert line is not None and line.length == pytest.approx(5800.0 + O.CORRIDOR_BACK_M)
    assert len(o.musts()) == 1
    # a position mission moves along no line: nothing ahead to watch
    hold = {"id": "U-hold", "unit": "U", "type": "occupy", "params": {"position": "AA-E"}}
    assert o.tr._line_of("U-hold", hold) is None


# ================================================================ once suspected bugs: each asserts the behaviour now
def test_an_end_confirmation_after_abort_does_not_ready_the_successor(tmp_path):
    ea, msgs, a = _decision_run(tmp_path)
    assert decide(ea, a.details["id"], "abort").ok
    ea = _go_on(ea, msgs + [end(500, "A1-move", "A1")])
    assert ea.domain.plan.state["A1-next"] == "pending"
    assert not [x for x in ea.alerts if x.t > DECIDE_T and x.details.get("mission") in ("A1-move", "A1-next")]


@pytest.mark.parametrize("where, told", [((1250, 0), True), ((-750, 0), False)], ids=["in-its-path", "behind"])
def test_ahead_is_towards_the_destination_whichever_way_the_route_is_drawn(tmp_path, where, told):
    drawn_back = line("RTE-1", "route", (6000, 0), (-2000, 0))
    sc = scenario(tmp_path, [MOVE], features=[drawn_back, AA_E])
    ea = play(sc, moving() + [track(150, "H1", *where)], 300)   # A1 at x=250 at t=150, going east to AA-E
    assert bool(of(ea, "threat-ahead")) is told


def test_a_missions_own_ahead_m_widens_what_the_ea_watches(tmp_path):
    """voi overrides in a mission's params hold for the watched stretch (2.5 km ahead: told
    with ahead_m 3000, not with the EA's 1500)."""
    for ahead_m, told in ((3000, True), (None, False)):
        voi = {"voi": {"ahead_m": ahead_m}} if ahead_m else {}
        sc = scenario(tmp_path / str(ahead_m), [dict(MOVE, params=dict(MOVE["params"], **voi))])
        msgs = stays("A1", 0, 0, t1=300) + stays("A2", 0, -3000, t1=300) + [start(100, "A1-move", "A1"),
                                                                           track(150, "H1", 2500, 0)]
        assert bool(of(play(sc, msgs, 300), "threat-ahead")) is told, ahead_m


def test_the_oracle_honours_a_missions_own_ahead_m():
    m = dict(OMOVE, params=dict(OMOVE["params"], voi={"ahead_m": 3000}))
    o = _Oracle(_still, lambda t: {"H1": (2500.0, 0.0)} if t >= 100 else {}, 300, [ROUTE_O, AA_O])
    o.run(m)
    assert len(o.musts()) == 1
