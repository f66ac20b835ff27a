"""The check families the mission classes compose (ea_agent/domains/suo/missions/ and
detect/): one small synthetic scenario per family, in process and on scenario time. Each
test asserts the alert (time, type, subjects, priority) where the plan is broken, and
its twin asserts silence where the plan is kept. Plus the scenario checks that guard
the new mission parameters and ON-ORDER orders, and `saim-mesh missions`.

Geometry is written in local metres east/north of the generator's origin (UTM 11N);
friendly units are two entities 20 m apart whose centroid is the given point."""
from __future__ import annotations

import re

import pytest

from ea_agent.domains.suo.messages import Order, Reorganization
from ea_agent.domains.suo.detect.location import RECHECK_S
from ea_agent.domains.suo.missions import REGISTRY
from saim_mesh import cli
from saim_mesh import scenario as S
from saim_mesh.inprocess.runner import config_for, make_ea

from .synthetic import (EPOCH, REPORT_S, Force, alerts_of, box, edited, end, line, mission, near, play, start,
                        track, track_path)

FORCE = Force(name="check-families")
write, scenario, at, path = FORCE.write, FORCE.scenario, FORCE.at, FORCE.path


def stays(unit: str, x: float, y: float, t0: float = 10.0, t1: float = 600.0) -> list:
    return FORCE.stays(unit, x, y, t0, t1)


def of(ea, typ: str) -> list:
    """Every alert of `typ`, the notifier's repeats included."""
    return alerts_of(ea, typ)


# ===================================================== 1. Check-Initial-Location, stationary units
BP_FAR = box("BP-FAR", "battle-position", 1900, -200, 2300, 200)    # ~2 km east of the platoon
BP_HOME = box("BP-HOME", "battle-position", -200, -200, 200, 200)   # where the platoon sits


@pytest.mark.parametrize("typ", ["defend", "occupy"])
def test_a_platoon_that_never_moves_from_the_wrong_place_is_told_at_its_start(tmp_path, typ):
    sc = scenario(tmp_path, [BP_FAR, BP_HOME], [mission("A1-hold", "A1", typ, position="BP-FAR")])
    ea = play(sc, stays("A1", 0, 0) + stays("A2", 0, -3000) + [start(100, "A1-hold", "A1")], 400)
    oop = of(ea, "out-of-position")
    assert oop, [a.type for a in ea.alerts]
    a = oop[0]
    assert near(a.t, 100.0), a.t
    assert a.subjects == ("A1",) and a.priority == "immediate" and a.category == "plan-constraint-violated"
    assert a.details["mission"] == "A1-hold" and a.details["check"] == "position"
    assert a.details["control_measure"] == "BP-FAR" and abs(a.details["distance_m"] - 1900) < 30
    assert len(oop) == 1   # judged again on every scan, but the same story is told once


@pytest.mark.parametrize("typ", ["defend", "occupy"])
def test_a_platoon_sitting_in_its_position_is_not_told(tmp_path, typ):
    sc = scenario(tmp_path, [BP_FAR, BP_HOME], [mission("A1-hold", "A1", typ, position="BP-HOME")])
    ea = play(sc, stays("A1", 0, 0) + stays("A2", 0, -3000) + [start(100, "A1-hold", "A1")], 400)
    assert not of(ea, "out-of-position")


def test_a_stationary_unit_is_rejudged_on_scenario_time(tmp_path):
    """100 m outside its position: within the 150 m threshold at its start. A commander
    lowers the threshold to 50 m at t=200; the unit never moves, yet the periodic scan
    tells it within a scan period (voi thresholds are read live)."""
    sc = scenario(tmp_path, [BP_HOME], [mission("A1-hold", "A1", "occupy", position="BP-HOME")])
    msgs = sorted(stays("A1", 300, 0) + stays("A2", 0, -3000) + [start(100, "A1-hold", "A1")], key=lambda m: m.t)
    ea = make_ea(sc, "A", config_for(sc, "A"))
    ea.start(0.0)
    for m in [m for m in msgs if m.t <= 200]:
        ea.submit(m)
    ea.advance(200.0)
    assert not of(ea, "out-of-position")
    ea.set_param("voi.out_of_position_m", 50.0, 200.0)
    for m in [m for m in msgs if 200 < m.t <= 400]:
        ea.submit(m)
    ea.finish(400.0)
    oop = of(ea, "out-of-position")
    assert oop and 200 < oop[0].t <= 200 + RECHECK_S + 2 * EPOCH, [a.t for a in oop]   # the next re-check
    assert oop[0].subjects == ("A1",) and oop[0].details["threshold_m"] == 50.0
    assert abs(oop[0].details["distance_m"] - 100) < 5


# ================================================================================ 2. corridor
OBJ_E = box("OBJ-E", "objective", 3000, -300, 3400, 300)
AA_E = box("AA-E", "assembly-area", 3000, -300, 3400, 300)
CORRIDOR_CASES = [("attack", {"objective": "OBJ-E"}, "OBJ-E"), ("move", {"destination": "AA-E"}, "AA-E"),
                  ("seize", {"objective": "OBJ-E"}, "OBJ-E")]


def _east(drift_per_step: float):
    """From (0, 0) at t=100, 100 m east per report, drifting `drift_per_step` north per
    report, until 3200 m east (inside the objective), then about inside it."""
    def where(t):
        k = (t - 100.0) / REPORT_S
        if k <= 32:
            return 100.0 * k, drift_per_step * k
        return (3300.0, 250.0) if int(k) % 2 else (3100.0, -250.0)   # inside the objective, off the line
    return where


@pytest.mark.parametrize("typ, params, target", CORRIDOR_CASES)
def test_drifting_sideways_out_of_the_corridor_is_out_of_position(tmp_path, typ, params, target):
    sc = scenario(tmp_path, [OBJ_E, AA_E], [mission("A1-go", "A1", typ, **params)])
    msgs = stays("A1", 0, 0, 10, 100) + path("A1", 110, 300, _east(20.0)) + [start(100, "A1-go", "A1")]
    ea = play(sc, msgs, 300)
    oop = of(ea, "out-of-position")
    assert oop
    a = oop[0]
    # 20 m north per 10 s: 160 m off the start-to-objective line at t=180 (140 m at 170: within 150)
    assert near(a.t, 180.0), a.t
    assert a.subjects == ("A1",) and a.priority == "immediate"
    assert a.details["check"] == "corridor" and a.details["control_measure"] == target
    assert a.details["mission"] == "A1-go" and 150 < a.details["distance_m"] < 200


@pytest.mark.parametrize("typ, params, target", CORRIDOR_CASES)
def test_going_straight_to_the_objective_and_about_in_it_is_not_told(tmp_path, typ, params, target):
    sc = scenario(tmp_path, [OBJ_E, AA_E], [mission("A1-go", "A1", typ, **params)])
    msgs = stays("A1", 0, 0, 10, 100) + path("A1", 110, 600, _east(0.0)) + [start(100, "A1-go", "A1")]
    ea = play(sc, msgs, 600)
    assert not of(ea, "out-of-position")


def test_an_axis_when_given_replaces_the_corridor(tmp_path):
    """With an axis the unit is judged on the axis, not on the straight corridor."""
    axis = line("AX-1", "route", (0, 0), (1500, 1500), (3000, 0))
    sc = scenario(tmp_path, [OBJ_E, axis], [mission("A1-go", "A1", "attack", objective="OBJ-E", axis="AX-1")])
    msgs = stays("A1", 0, 0, 10, 100) + path("A1", 110, 300, _east(0.0)) + [start(100, "A1-go", "A1")]
    ea = play(sc, msgs, 300)
    oop = of(ea, "out-of-position")
    assert oop and oop[0].details["check"] == "axis" and oop[0].details["control_measure"] == "AX-1"


def _drift_then_hold(t):
    """_east(20) until 240 m north of the start line (t=220), then straight east at that offset."""
    x, y = _east(20.0)(t)
    return x, min(y, 240.0)


def test_a_unit_that_drifted_and_keeps_its_offset_stays_out_of_its_corridor(tmp_path):
    """The base case of the next test: 240 m off the start-to-objective line, told once."""
    sc = scenario(tmp_path, [OBJ_E], [mission("A1-go", "A1", "attack", objective="OBJ-E")])
    msgs = stays("A1", 0, 0, 10, 100) + path("A1", 110, 400, _drift_then_hold) + [start(100, "A1-go", "A1")]
    oop = of(play(sc, msgs, 400), "out-of-position")
    assert oop and near(oop[0].t, 180.0) and oop[0].details["check"] == "corridor"


def test_a_reorganization_elsewhere_does_not_move_a_units_corridor(tmp_path):
    sc = scenario(tmp_path, [OBJ_E], [mission("A1-go", "A1", "attack", objective="OBJ-E")])
    msgs = (stays("A1", 0, 0, 10, 100) + path("A1", 110, 400, _drift_then_hold) + [start(100, "A1-go", "A1")]
            + [Reorganization(150.0, "B1", "BN")])   # B1 (B company) goes under the battalion: nothing of A's
    oop = of(play(sc, msgs, 400), "out-of-position")
    assert oop and near(oop[0].t, 180.0)


def test_a_unit_first_heard_after_its_start_is_judged_in_its_corridor(tmp_path):
    sc = scenario(tmp_path, [OBJ_E], [mission("A1-go", "A1", "attack", objective="OBJ-E")])
    msgs = path("A1", 110, 400, _east(20.0)) + [start(100, "A1-go", "A1")]   # first report 10 s after the start
    oop = of(play(sc, msgs, 400), "out-of-position")
    assert oop and oop[0].details["check"] == "corridor"


def test_a_unit_resubordinated_under_us_mid_mission_is_judged_in_its_corridor(tmp_path):
    sc = scenario(tmp_path, [OBJ_E], [mission("B1-go", "B1", "attack", objective="OBJ-E")])
    msgs = (stays("A1", 0, -3000, 10, 400) + stays("B1", 0, 0, 10, 100) + path("B1", 110, 400, _east(20.0))
            + [start(100, "B1-go", "B1"), Reorganization(105.0, "B1", "A")])
    oop = of(play(sc, msgs, 400, owner="A"), "out-of-position")
    assert oop and oop[0].subjects == ("B1",) and oop[0].details["check"] == "corridor"


# ================================================================================ 3. ON-ORDER
def _on_order(tmp_path, phase: str = "start"):
    tc = {"type": "ON-ORDER"}
    m = mission("A1-atk", "A1", "attack", objective="OBJ-E", **({"start": tc} if phase == "start" else {"end": tc}))
    return scenario(tmp_path, [OBJ_E, BP_HOME], [m, mission("A2-hold", "A2", "occupy", position="BP-HOME")])


def _still():
    return stays("A1", 0, 0) + stays("A2", 0, 0)


def _sched(ea):
    return [a for a in of(ea, "schedule") if a.details.get("mission") == "A1-atk"]


@pytest.mark.parametrize("issuer", ["A", "BN"])
def test_on_order_start_within_the_threshold_of_the_superiors_order_is_silent(tmp_path, issuer):
    sc = _on_order(tmp_path)
    ea = play(sc, _still() + [Order(200.0, "start-mission", "main", issuer, "A1-atk"), start(220, "A1-atk", "A1")],
              500)
    assert not _sched(ea), [a.message for a in _sched(ea)]
    assert ea.domain.plan.state["A1-atk"] == "active" and ea.stats["errors"] == 0


def test_on_order_start_60_s_after_the_order_is_late_at_order_plus_threshold(tmp_path):
    sc = _on_order(tmp_path)
    ea = play(sc, _still() + [Order(200.0, "start-mission", "main", "A", "A1-atk"), start(260, "A1-atk", "A1")], 500)
    s = _sched(ea)
    assert len(s) == 1, [a.message for a in s]
    a = s[0]
    assert a.t == 230.0 and a.details["how"] == "late" and a.details["ordered_t"] == 200.0
    assert a.details["constraint"] == "ON-ORDER" and a.details["phase"] == "start"
    assert a.subjects == ("A1",) and a.priority == "immediate"   # an offensive mission's schedule is IMMEDIATE


def test_on_order_start_never_confirmed_is_late_at_order_plus_threshold(tmp_path):
    sc = _on_order(tmp_path)
    ea = play(sc, _still() + [Order(200.0, "start-mission", "main", "A", "A1-atk")], 500)
    s = _sched(ea)
    assert [(a.t, a.details["how"]) for a in s] == [(230.0, "late")]


def test_on_order_start_confirmed_without_an_order_is_unordered(tmp_path):
    sc = _on_order(tmp_path)
    ea = play(sc, _still() + [start(220, "A1-atk", "A1")], 500)
    s = _sched(ea)
    assert len(s) == 1 and s[0].details["how"] == "unordered" and s[0].t == 220.0
    assert s[0].subjects == ("A1",) and s[0].details["ordered_t"] is None


def test_on_order_end_is_judged_against_the_end_order(tmp_path):
    sc = _on_order(tmp_path, phase="end")
    ea = play(sc, _still() + [start(100, "A1-atk", "A1"), Order(300.0, "end-mission", "main", "A", "A1-atk"),
                              end(360, "A1-atk", "A1")], 500)
    s = _sched(ea)
    assert [(a.t, a.details["how"], a.details["phase"]) for a in s] == [(330.0, "late", "end")]


def test_bad_mission_orders_are_counted_errors_and_do_not_count_as_orders(tmp_path):
    """From a unit that is not a superior (a sibling platoon, another company), for an
    unknown mission, or for a mission that does not wait for an order: each is one
    counted error, nothing crashes, and none of them is the order the mission waits for."""
    sc = _on_order(tmp_path)
    bad = [Order(200.0, "start-mission", "main", "A2", "A1-atk"),
           Order(201.0, "start-mission", "main", "B", "A1-atk"),
           Order(202.0, "start-mission", "main", "A", "no-such-mission"),
           Order(203.0, "start-mission", "main", "A", "A2-hold")]
    ea = play(sc, _still() + bad + [start(220, "A1-atk", "A1")], 500)
    assert ea.stats["errors"] == 4, ea.errors
    assert "not a superior" in ea.errors[0] and "'A2'" in ea.errors[0]
    assert "not a superior" in ea.errors[1] and "'B'" in ea.errors[1]
    assert "no-such-mission" in ea.errors[2] and "A2-hold" in ea.errors[3]
    assert [a.details["how"] for a in _sched(ea)] == ["unordered"]
    assert ea.domain.plan.state["A1-atk"] == "active"


# ============================================================================= 4. penetration
# The held area's northern edge is at y = 200: BP-HOME and GUARD-1, and the rear line
# PL-REAR at y = 150 (a line is held 50 m either side). Hostiles come from the north
# along x = 0; the platoon sits at (0, -100).
GUARD_1 = box("GUARD-1", "area", -400, -600, 400, 200)
PL_REAR = line("PL-REAR", "phase-line", (-1500, 150), (1500, 150))
PENETRATION_CASES = [
    ("block", {"position": "BP-HOME", "area": "BP-HOME"}, "BP-HOME"),
    ("retain", {"position": "BP-HOME"}, "BP-HOME"),
    ("guard", {"position": "BP-HOME", "area": "GUARD-1"}, "GUARD-1"),
    ("defend", {"position": "BP-HOME", "rear_line": "PL-REAR"}, "PL-REAR"),
]
EDGE_Y = 200.0
PEN_FEATURES = [BP_HOME, GUARD_1, PL_REAR]


def _holder(tmp_path, typ, params):
    sc = scenario(tmp_path, PEN_FEATURES, [mission("A1-hold", "A1", typ, **params)])
    return stays("A1", 0, -100) + stays("A2", 3000, -3000) + [start(100, "A1-hold", "A1")], sc


@pytest.mark.parametrize("typ, params, area", PENETRATION_CASES)
def test_a_hostile_entering_a_held_area_is_a_penetration(tmp_path, typ, params, area):
    msgs, sc = _holder(tmp_path, typ, params)
    # seen 1.5 km north, then next 2.5 minutes later 30 m inside: no steady approach to project
    msgs += [track(150, "H1", 0, EDGE_Y + 1500), track(300, "H1", 0, EDGE_Y - 30)]
    ea = play(sc, msgs, 400)
    pen = of(ea, "penetration")
    assert pen, [a.type for a in ea.alerts]
    a = pen[0]
    assert near(a.t, 300.0), a.t
    assert a.subjects == ("H1",) and a.priority == "immediate" and a.category == "adversarial-activity"
    assert a.details["place"] == area and a.details["mission"] == "A1-hold"
    assert not of(ea, "projected-penetration")


@pytest.mark.parametrize("typ, params, area", PENETRATION_CASES)
def test_a_hostile_approaching_a_held_area_steadily_is_projected_before_it_enters(tmp_path, typ, params, area):
    msgs, sc = _holder(tmp_path, typ, params)
    # 5 m/s south from 1.5 km north of the edge at t=150: enters at t=450
    msgs += track_path("H1", 150, 520, lambda t: (0.0, EDGE_Y + 1500 - 5.0 * (t - 150)))
    ea = play(sc, msgs, 520)
    proj = of(ea, "projected-penetration")
    assert proj, [a.type for a in ea.alerts]
    p = proj[0]
    assert p.t <= 450 - 60, p.t   # told well before it enters (horizon 120 s)
    assert p.category == "constraint-violation-projected" and p.priority == "immediate"
    assert p.subjects == ("H1",) and p.details["place"] == area and p.details["mission"] == "A1-hold"
    assert abs(p.details["projected_t"] - 450) <= 20, p.details
    assert not [a for a in of(ea, "penetration") if a.t < 450]


def test_a_projected_penetration_and_the_penetration_it_foretold_are_one_story(tmp_path):
    msgs, sc = _holder(tmp_path, "block", {"position": "BP-HOME", "area": "BP-HOME"})
    msgs += track_path("H1", 150, 520, lambda t: (0.0, EDGE_Y + 1500 - 5.0 * (t - 150)))
    ea = play(sc, msgs, 520)
    story = of(ea, "projected-penetration") + of(ea, "penetration")
    assert [a.type for a in story] == ["projected-penetration"], [(a.t, a.type, a.subjects) for a in story]


@pytest.mark.parametrize("typ, params, area", PENETRATION_CASES)
def test_a_hostile_that_stays_away_is_neither(tmp_path, typ, params, area):
    msgs, sc = _holder(tmp_path, typ, params)
    # 5 m/s east-west along a line 1.5 km north of the edge, and one sitting 900 m north
    msgs += track_path("H1", 150, 600, lambda t: (-1500.0 + 5.0 * (t - 150), EDGE_Y + 1500))
    msgs += track_path("H2", 150, 600, lambda t: (0.0, EDGE_Y + 900))
    ea = play(sc, msgs, 600)
    assert not of(ea, "penetration") and not of(ea, "projected-penetration")


def test_a_hostile_of_a_mission_without_penetration_check_is_no_penetration(tmp_path):
    """occupy holds its position but does not forbid hostiles in it: no penetration family."""
    msgs, sc = _holder(tmp_path, "occupy", {"position": "BP-HOME"})
    msgs += [track(150, "H1", 0, EDGE_Y + 1500), track(300, "H1", 0, EDGE_Y - 30)]
    ea = play(sc, msgs, 400)
    assert not of(ea, "penetration") and not of(ea, "projected-penetration")


def test_a_hostile_reported_beyond_the_rear_line_has_crossed_it(tmp_path):
    msgs, sc = _holder(tmp_path, "defend", {"position": "BP-HOME", "rear_line": "PL-REAR"})
    # 300 m in front of PL-REAR, then 30 s later 300 m behind it (20 m/s): across it
    msgs += [track(150, "H1", 0, 150 + 300), track(180, "H1", 0, 150 - 300), track(210, "H1", 0, 150 - 600)]
    ea = play(sc, msgs, 300)
    assert of(ea, "penetration") or of(ea, "projected-penetration")


# ================================================================================= 5. escape
OBJ_MID = box("OBJ-MID", "objective", 1000, -500, 2000, 500)
EA_MID = box("EA-MID", "engagement-area", 1000, -500, 2000, 500)
ESCAPE_CASES = [("isolate", {"objective": "OBJ-MID"}, "OBJ-MID"), ("fix", {"objective": "OBJ-MID"}, "OBJ-MID"),
                ("destroy", {"objective": "OBJ-MID"}, "OBJ-MID"),
                ("contain", {"position": "BP-HOME", "engagement_area": "EA-MID"}, "EA-MID")]


def _holding(tmp_path, typ, params, hostile: list):
    sc = scenario(tmp_path, [OBJ_MID, EA_MID, BP_HOME], [mission("A1-hold", "A1", typ, **params)])
    msgs = stays("A1", 0, 0) + stays("A2", 0, -3000) + [start(100, "A1-hold", "A1")] + hostile
    return play(sc, msgs, 400)


@pytest.mark.parametrize("typ, params, area", ESCAPE_CASES)
def test_a_hostile_held_inside_that_gets_well_out_escapes(tmp_path, typ, params, area):
    ea = _holding(tmp_path, typ, params, [track(150, "H1", 1500, 0), track(200, "H1", 1600, 100),
                                          track(300, "H1", 2000 + 350, 0)])
    esc = of(ea, "escape")
    assert esc, [a.type for a in ea.alerts]
    a = esc[0]
    assert near(a.t, 300.0), a.t
    assert a.subjects == ("H1",) and a.priority == "immediate" and a.category == "adversarial-activity"
    assert a.details["place"] == area and a.details["mission"] == "A1-hold" and a.details["tracks"] == ["H1"]
    assert len(esc) == 1


@pytest.mark.parametrize("typ, params, area", ESCAPE_CASES)
@pytest.mark.parametrize("last", [(1900, 400), (2000 + 120, 0)], ids=["inside", "at-the-edge"])
def test_a_hostile_that_stays_inside_or_at_the_edge_does_not_escape(tmp_path, typ, params, area, last):
    ea = _holding(tmp_path, typ, params, [track(150, "H1", 1500, 0), track(200, "H1", 1600, 100),
                                          track(300, "H1", *last)])
    assert not of(ea, "escape")


def test_a_hostile_that_leaves_before_the_mission_starts_does_not_escape(tmp_path):
    """Held means seen inside while the mission runs."""
    sc = scenario(tmp_path, [OBJ_MID], [mission("A1-hold", "A1", "isolate", objective="OBJ-MID")])
    msgs = stays("A1", 0, 0) + [track(50, "H1", 1500, 0), track(80, "H1", 2350, 0), start(100, "A1-hold", "A1"),
                                track(300, "H1", 2600, 0)]
    ea = play(sc, msgs, 400)
    assert not of(ea, "escape")


# ============================================================================== 6. end state
def _ended(tmp_path, typ, hostile_xy):
    sc = scenario(tmp_path, [OBJ_MID], [mission("A1-obj", "A1", typ, objective="OBJ-MID")])
    msgs = (stays("A1", 800, 0, 10, 100) + path("A1", 110, 400, lambda t: (min(1500.0, 800 + 10.0 * (t - 100)), 0.0))
            + stays("A2", 0, -3000) + [start(100, "A1-obj", "A1"), end(300, "A1-obj", "A1")]
            + [track(120, "H1", *hostile_xy)])
    return play(sc, msgs, 400)


@pytest.mark.parametrize("typ", ["clear", "destroy"])
def test_ending_with_a_hostile_still_on_the_objective_is_an_end_state_alert(tmp_path, typ):
    ea = _ended(tmp_path, typ, (1700, 200))
    es = of(ea, "end-state")
    assert len(es) == 1, [a.type for a in ea.alerts]
    a = es[0]
    assert a.t == 300.0 and a.subjects == ("A1", "H1") and a.priority == "immediate"
    assert a.details["mission"] == "A1-obj" and a.details["place"] == "OBJ-MID" and a.details["tracks"] == ["H1"]
    assert a.details["strength"] == 4
    assert not [x for x in of(ea, "out-of-position") if x.details.get("check") == "objective"]   # it did arrive


@pytest.mark.parametrize("typ", ["clear", "destroy"])
def test_ending_with_the_objective_empty_is_silent(tmp_path, typ):
    ea = _ended(tmp_path, typ, (3000, 200))
    assert not of(ea, "end-state")


@pytest.mark.parametrize("typ", ["attack", "isolate", "seize", "secure"])
def test_missions_without_an_end_state_are_not_judged_on_hostiles_left(tmp_path, typ):
    ea = _ended(tmp_path, typ, (1700, 200))
    assert not of(ea, "end-state")


# ======================================================================= 7. friendly expected
EA_FAR = box("EA-FAR", "engagement-area", 1700, -200, 2100, 200)     # 1500 m from BP-HOME
EA_NEAR = box("EA-NEAR", "engagement-area", 700, -200, 1100, 200)    # 500 m from BP-HOME


def _covering(tmp_path, ea_id, attrs=None, typ="defend"):
    sc = scenario(tmp_path, [BP_HOME, EA_FAR, EA_NEAR],
                  [mission("A1-hold", "A1", typ, position="BP-HOME", engagement_area=ea_id)], attrs=attrs)
    return play(sc, stays("A1", 0, 0) + stays("A2", 0, -3000) + [start(100, "A1-hold", "A1")], 300)


@pytest.mark.parametrize("typ", ["defend", "support-by-fire"])
def test_an_engagement_area_beyond_weapons_range_is_friendly_expected_at_start(tmp_path, typ):
    ea = _covering(tmp_path, "EA-FAR", typ=typ)
    fe = of(ea, "friendly-expected")
    assert len(fe) == 1, [a.type for a in ea.alerts]
    a = fe[0]
    assert a.t == 100.0 and a.subjects == ("A1",) and a.priority == "immediate"
    assert a.category == "plan-constraint-violated"
    assert abs(a.details["gap_m"] - 1500) < 2 and a.details["weapons_range_m"] == 1000.0
    assert a.details["engagement_area"] == "EA-FAR" and a.details["mission"] == "A1-hold"


def test_an_engagement_area_within_weapons_range_is_silent(tmp_path):
    assert not of(_covering(tmp_path, "EA-NEAR"), "friendly-expected")


@pytest.mark.parametrize("who, rng, told", [("A1", 2000.0, False), ("A", 2000.0, False), ("A1", 1200.0, True)])
def test_the_units_own_weapons_range_is_what_counts(tmp_path, who, rng, told):
    """weapons_range_m of the unit, or of its nearest superior that has one, over voi.weapons_range_m."""
    ea = _covering(tmp_path, "EA-FAR", attrs={who: {"weapons_range_m": rng}})
    fe = of(ea, "friendly-expected")
    assert bool(fe) is told
    if told:
        assert fe[0].details["weapons_range_m"] == rng


# =========================================================================== 8. distance band
DEST_FAR = box("DEST-FAR", "assembly-area", 8000, -300, 8400, 300)


def _following(tmp_path, follower, leader, band=None):
    params = {"supported": "A1", "destination": "DEST-FAR"}
    if band is not None:
        params["band_m"] = band
    sc = scenario(tmp_path, [DEST_FAR], [mission("A2-follow", "A2", "follow-and-support", **params)])
    msgs = path("A1", 10, 400, leader) + path("A2", 10, 400, follower) + [start(100, "A2-follow", "A2")]
    return play(sc, msgs, 400)


def _leader(t):   # from 500 m east of the origin, 40 m east per report from t=110
    return 500.0 + 4.0 * max(0.0, t - 100.0), 0.0


def test_a_follower_falling_behind_its_band_is_a_band_alert_naming_both_units(tmp_path):
    # band [200, 800]: the follower stays at the origin, 980 m behind at t=220 (940 at 210: within 150)
    ea = _following(tmp_path, lambda t: (0.0, 0.0), _leader, band=[200, 800])
    b = of(ea, "band")
    assert b, [a.type for a in ea.alerts]
    a = b[0]
    assert near(a.t, 220.0), a.t
    assert a.subjects == ("A2", "A1") and a.priority == "immediate" and a.category == "plan-constraint-violated"
    assert a.details["mission"] == "A2-follow" and a.details["supported"] == "A1"
    assert a.details["band_m"] == [200.0, 800.0] and 150 < a.details["off_m"] <= 200
    assert "too far" in a.message


def test_a_follower_too_close_is_a_band_alert(tmp_path):
    ea = _following(tmp_path, lambda t: (_leader(t)[0] - 20.0, 0.0), _leader, band=[200, 800])
    b = of(ea, "band")
    assert b and near(b[0].t, 100.0, 6.0) and b[0].subjects == ("A2", "A1") and "too close" in b[0].message


def test_a_follower_keeping_its_band_is_silent(tmp_path):
    ea = _following(tmp_path, lambda t: (_leader(t)[0] - 500.0, 0.0), _leader, band=[200, 800])
    assert not of(ea, "band")


@pytest.mark.parametrize("gap, told", [(3500.0, True), (2900.0, False)])
def test_the_default_band_is_zero_to_follow_max(tmp_path, gap, told):
    ea = _following(tmp_path, lambda t: (_leader(t)[0] - gap, 0.0), _leader)
    b = of(ea, "band")
    assert bool(b) is told
    if told:
        assert b[0].details["band_m"] == [0.0, 3000.0]


# ===================================================================== 9. triggered contingency
NAI_N = box("NAI-N", "area", -500, 3000, 500, 3600)
BP_2 = box("BP-2", "battle-position", 1900, -200, 2300, 200)


def _contingency(tmp_path, a1_xy):
    br = mission("A-branch", "A1", "branch", trigger={"kind": "hostile-in-area", "area": "NAI-N", "min_strength": 1},
                 task="occupy", task_params={"position": "BP-2"}, owner="A")
    sc = scenario(tmp_path, [NAI_N, BP_2], [br])
    msgs = stays("A1", *a1_xy) + stays("A2", 0, -3000) + [track(150, "H1", 0, 5000), track(200, "H1", 0, 3300)]
    return play(sc, msgs, 400)


def test_a_triggered_branch_task_is_monitored_from_the_trigger(tmp_path):
    ea = _contingency(tmp_path, (0, 0))
    c = of(ea, "contingency")
    assert len(c) == 1 and near(c[0].t, 200.0) and c[0].details["mission"] == "A-branch"
    oop = of(ea, "out-of-position")
    assert oop, [a.type for a in ea.alerts]
    assert oop[0].t >= c[0].t and near(oop[0].t, 200.0)   # nothing before the trigger: dormant till then
    assert oop[0].subjects == ("A1",) and oop[0].priority == "immediate"
    assert oop[0].details["mission"] == "A-branch" and oop[0].details["control_measure"] == "BP-2"
    assert ea.domain.plan.state["A-branch"] == "active"


def test_a_triggered_branch_task_kept_is_silent(tmp_path):
    ea = _contingency(tmp_path, (2100, 0))
    assert of(ea, "contingency") and not of(ea, "out-of-position")


def test_an_untriggered_branch_is_not_monitored(tmp_path):
    br = mission("A-branch", "A1", "branch", trigger={"kind": "hostile-in-area", "area": "NAI-N"},
                 task="occupy", task_params={"position": "BP-2"}, owner="A")
    sc = scenario(tmp_path, [NAI_N, BP_2], [br])
    ea = play(sc, stays("A1", 0, 0) + [track(150, "H1", 0, 5000)], 400)
    assert not of(ea, "contingency") and not of(ea, "out-of-position")
    assert ea.domain.plan.state["A-branch"] == "dormant"


# ============================================================================== 10. validation
VAL_FEATURES = [BP_HOME, OBJ_E, AA_E, EA_NEAR, line("RTE-1", "route", (0, 0), (3000, 0)), PL_REAR]
GOOD = [mission("A1-atk", "A1", "attack", start={"type": "ON-ORDER"}, objective="OBJ-E", axis="RTE-1"),
        mission("A2-follow", "A2", "follow-and-support", supported="A1", destination="AA-E", route="RTE-1",
                band_m=[100, 900]),
        mission("B1-def", "B1", "defend", position="BP-HOME", engagement_area="EA-NEAR", rear_line="PL-REAR"),
        mission("A-branch", "A1", "branch", trigger={"kind": "hostile-in-area", "area": "BP-HOME"},
                task="occupy", task_params={"position": "BP-HOME"}, owner="A")]
ORDER_OK = {"kind": "order", "t": 50, "action": "start-mission", "plan": "main", "issuer": "A", "mission": "A1-atk"}


def _edited(mid, **params):
    return edited(GOOD, mid, **params)


def test_the_well_formed_scenario_loads(tmp_path):
    sc = S.load(write(tmp_path / "sc", VAL_FEATURES, GOOD, [ORDER_OK]))
    assert [type(e).__name__ for e in sc.events] == ["Order"] and sc.events[0].mission == "A1-atk"


@pytest.mark.parametrize("missions, events, expect", [
    (_edited("A-branch", task_params={}), [], ["plans.main[3]", "A-branch", "params.task_params.position", "missing"]),
    (_edited("A-branch", task="defend", task_params={"position": "BP-HOME", "rear_line": "BP-HOME"}), [],
     ["A-branch", "params.task_params.rear_line", "not a line"]),
    (_edited("A2-follow", band_m=[800, 200]), [], ["A2-follow", "params.band_m", "800", "200"]),
    (_edited("A2-follow", band_m=[-5, 200]), [], ["A2-follow", "params.band_m"]),
    (_edited("A2-follow", band_m=[100]), [], ["A2-follow", "params.band_m", "[min, max]"]),
    (_edited("A2-follow", band_m="far"), [], ["A2-follow", "params.band_m", "[min, max]"]),
    (_edited("A2-follow", route="AA-E"), [], ["A2-follow", "params.route", "'AA-E'", "Polygon", "not a line"]),
    (_edited("A1-atk", axis="OBJ-E"), [], ["A1-atk", "params.axis", "not a line"]),
    (_edited("B1-def", rear_line="BP-HOME"), [], ["B1-def", "params.rear_line", "not a line"]),
    (GOOD, [dict(ORDER_OK, mission="no-such")], ["events.jsonl:1", "field 'mission'", "unknown mission", "no-such"]),
    (GOOD, [dict(ORDER_OK, issuer="A2")], ["events.jsonl:1", "field 'issuer'", "'A2'", "not a superior", "A1-atk"]),
    (GOOD, [dict(ORDER_OK, issuer="B")], ["events.jsonl:1", "field 'issuer'", "not a superior"]),
], ids=["task-param-missing", "task-line-param-polygon", "band-min-above-max", "band-negative", "band-one-number",
        "band-not-a-list", "route-polygon", "axis-polygon", "rear-line-polygon", "order-unknown-mission",
        "order-from-sibling", "order-from-other-company"])
def test_broken_check_family_inputs_name_the_field(tmp_path, missions, events, expect):
    with pytest.raises(S.ScenarioError) as e:
        S.load(write(tmp_path / "sc", VAL_FEATURES, missions, events))
    for part in expect:
        assert part in str(e.value), (part, str(e.value))


# ======================================================================= 11. saim-mesh missions
def test_missions_lists_checks_for_every_mission_class(capsys):
    assert cli.main(["missions"]) == 0
    out = capsys.readouterr().out
    blocks: dict[str, list[str]] = {}
    name = None
    for ln in out.splitlines():
        if ln and not ln.startswith(" "):
            name = ln.split()[0]
            blocks[name] = []
        elif name is not None:
            blocks[name].append(ln.strip())

    def says(n, word):
        return any(re.search(word, x) for x in blocks[n] if x.startswith("checks: "))

    assert set(blocks) == set(REGISTRY)
    for n, lines in blocks.items():
        checks = [x for x in lines if x.startswith("checks: ")]
        assert checks and all(len(x) > len("checks: ") + 10 for x in checks), n
    for n in ("clear", "destroy"):
        assert says(n, r"\(end-state\)"), n
    assert not says("seize", "end-state") and not says("secure", "end-state") and says("secure", "penetration")
    for n in ("isolate", "fix", "destroy", "contain"):
        assert says(n, r"\(escape\)"), n
    for n in ("block", "retain", "guard", "defend", "secure"):
        assert says(n, "penetration"), n
    for n in ("follow-and-support", "follow-and-assume"):
        assert says(n, r"\(band\)"), n
    assert says("defend", r"\(friendly-expected\)") and says("attack", "corridor") and says("move", "corridor")
    assert says("attack", "ON-ORDER") and says("branch", "contingency")
    assert not says("attack", "end-state") and not says("occupy", "penetration") and not says("screen", "penetration")
