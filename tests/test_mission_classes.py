"""Every leaf mission class its own behaviour (issue 34.2): no two leaf classes resolve to
the same monitoring methods, class constants and parameters; and for each class that used
to be another under a new name (suppress, disrupt, secure, seize, clear, follow-and-assume,
zone and area reconnaissance, branch and sequel) the condition its doctrine (FM 3-90) names
raises its alert, and the condition absent gives none.

Small synthetic scenarios on scenario time, with the builders of tests/synthetic.py
(geometry in local metres east/north of the generator's origin)."""
from __future__ import annotations

import inspect
import itertools

import pytest

from ea_agent.domains.suo.messages import LocationReport
from ea_agent.domains.suo.missions import REGISTRY, Occupy
from saim_mesh import cli

from .synthetic import (EPOCH, REPORT_S, Force, alerts_of, box, end, feed, line, ll, mission, near, play, start, track,
                        track_path)

FORCE = Force(name="mission-classes")
scenario, path = FORCE.scenario, FORCE.path


def stays(unit: str, x: float, y: float, t0: float = 10.0, t1: float = 1500.0) -> list:
    return FORCE.stays(unit, x, y, t0, t1)


def of(ea, typ: str, check: str | None = None) -> list:
    return [a for a in alerts_of(ea, typ) if check is None or a.details.get("check") == check]


# ============================================================ no two leaf classes the same
def behaviour(cls) -> tuple:
    """What a mission class does: every method it resolves (by the function object its
    hierarchy gives it), every class constant but its name and description, and its parameters."""
    methods = []
    for name in dir(cls):
        if name.startswith("__"):
            continue
        v = inspect.getattr_static(cls, name)
        if isinstance(v, (classmethod, staticmethod)):
            v = v.__func__
        if callable(v) or isinstance(v, property):
            methods.append((name, id(v)))
    consts = [(n, repr(getattr(cls, n))) for n in dir(cls) if n.isupper() and n not in ("TYPE", "CHECKS")]
    return tuple(sorted(methods)), tuple(sorted(consts)), tuple(sorted(cls.all_params()))


def same_behaviour(classes) -> list[tuple[str, str]]:
    sig = {c.TYPE: behaviour(c) for c in classes}
    return [(a, b) for a, b in itertools.combinations(sorted(sig), 2) if sig[a] == sig[b]]


def test_no_two_leaf_mission_classes_behave_the_same():
    assert same_behaviour(REGISTRY.values()) == []


def test_a_class_that_only_renames_its_parent_is_caught():
    class Renamed(Occupy):
        """A new name, nothing of its own."""
        TYPE = "renamed-occupy"
    assert same_behaviour([*REGISTRY.values(), Renamed]) == [("occupy", "renamed-occupy")]


def test_saim_mesh_missions_shows_what_each_class_checks(capsys):
    cli.main(["missions"])
    out = capsys.readouterr().out
    blocks = {}
    for chunk in out.split("\n"):
        if chunk and not chunk.startswith(" "):
            name = chunk.split()[0]
            blocks[name] = []
        elif chunk:
            blocks[name].append(chunk.strip())
    want = {"suppress": "weapons range through its fire window", "disrupt": "faster than its tempo",
            "secure": "no hostile in the objective while it runs", "seize": "by its `by` time",
            "clear": "no hostile on the objective at the end", "follow-and-assume": "assumed and monitored",
            "zone-reconnaissance": "front to rear", "area-reconnaissance": "coverage",
            "branch": "offered in place of its unit's move", "block": "names exactly one of area or line"}
    for typ, text in want.items():
        assert any(text in line_ for line_ in blocks[typ]), (typ, blocks[typ])
    assert "window" in " ".join(blocks["suppress"]) and "avenue" in " ".join(blocks["disrupt"])
    assert not any("offered in place" in x for x in blocks["sequel"])


# ============================================================================ suppress
BP_HOME = box("BP-HOME", "battle-position", -200, -200, 200, 200)
TGT_NEAR = box("TGT-NEAR", "area", 700, -200, 1100, 200)     # 500 m from BP-HOME's centre
TGT_FAR = box("TGT-FAR", "area", 1700, -200, 2100, 200)      # 1.7 km from it (weapons range 1 km)


def _suppressing(tmp_path, target, window=(300, 600)):
    sc = scenario(tmp_path, [BP_HOME, TGT_NEAR, TGT_FAR],
                  [mission("A1-sup", "A1", "suppress", position="BP-HOME", target=target, window=list(window))])
    return play(sc, stays("A1", 0, 0) + stays("A2", 0, -3000) + [start(100, "A1-sup", "A1")], 800)


def test_a_suppression_whose_target_is_out_of_range_when_its_fires_are_due_is_told_then(tmp_path):
    ea = _suppressing(tmp_path, "TGT-FAR")
    fs = of(ea, "fire-support", "suppress")
    assert len(fs) == 1, [(a.t, a.type, a.message) for a in ea.alerts]
    a = fs[0]
    assert near(a.t, 300.0), a.t   # when the window opens, not at the mission's start
    assert a.subjects == ("A1",) and a.priority == "immediate" and a.details["target"] == "TGT-FAR"
    assert a.details["window"] == [300.0, 600.0] and 1650 < a.details["distance_m"] < 1750
    assert a.details["weapons_range_m"] == 1000.0


def test_a_suppression_in_range_of_its_target_is_silent(tmp_path):
    assert not of(_suppressing(tmp_path, "TGT-NEAR"), "fire-support")


def test_a_suppression_whose_window_is_past_is_silent(tmp_path):
    assert not of(_suppressing(tmp_path, "TGT-FAR", window=(20, 90)), "fire-support")


def test_a_unit_moving_out_of_range_inside_its_window_is_told_when_it_does(tmp_path):
    sc = scenario(tmp_path, [BP_HOME, TGT_NEAR], [mission("A1-sup", "A1", "suppress", position="BP-HOME",
                                                          target="TGT-NEAR", window=[300, 900])])
    # west at 5 m/s from t=400: 1 km from TGT-NEAR's edge (700) at x=-300, t=460
    msgs = path("A1", 10, 900, lambda t: (-5.0 * max(0.0, t - 400.0), 0.0)) + stays("A2", 0, -3000) + \
        [start(100, "A1-sup", "A1")]
    fs = of(play(sc, msgs, 900), "fire-support", "suppress")
    assert len(fs) == 1 and 460 <= fs[0].t <= 460 + REPORT_S + 2 * EPOCH, [a.t for a in fs]


# ============================================================================= disrupt
AVENUE = line("AA-N", "avenue-of-approach", (0, 6000), (0, 1000), width_m=1000)   # drawn the way the enemy comes


def _disrupting(tmp_path, hostile):
    sc = scenario(tmp_path, [BP_HOME, AVENUE],
                  [mission("A1-dis", "A1", "disrupt", position="BP-HOME", avenue="AA-N", by=600)])
    return play(sc, stays("A1", 0, 0) + stays("A2", 3000, -3000) + [start(100, "A1-dis", "A1")] + hostile, 900)


def test_a_hostile_still_advancing_down_the_avenue_after_the_time_is_a_tempo_not_broken(tmp_path):
    ea = _disrupting(tmp_path, track_path("H1", 100, 900, lambda t: (50.0, 6000.0 - 3.0 * t)))
    he = of(ea, "hostile-expected", "tempo")
    assert len(he) == 1, [(a.t, a.type, a.message) for a in ea.alerts]
    a = he[0]
    assert near(a.t, 600.0, REPORT_S + 2 * EPOCH), a.t
    assert a.subjects == ("A1", "H1") and a.details["avenue"] == "AA-N" and a.details["tracks"] == ["H1"]
    assert 2.8 <= a.details["speed_mps"] <= 3.2 and a.details["tempo_mps"] == 1.0
    assert a.category == "adversarial-activity" and "AA-N" in a.message


def test_a_hostile_halted_on_the_avenue_by_the_time_is_silent(tmp_path):
    # 3 m/s down the avenue until t=450, then halted
    ea = _disrupting(tmp_path, track_path("H1", 100, 900, lambda t: (50.0, 6000.0 - 3.0 * min(t, 450.0))))
    assert not of(ea, "hostile-expected")


def test_a_hostile_advancing_beside_the_avenue_or_going_back_up_it_is_silent(tmp_path):
    ea = _disrupting(tmp_path, track_path("H1", 100, 900, lambda t: (2500.0, 6000.0 - 3.0 * t))
                     + track_path("H2", 100, 900, lambda t: (0.0, 2000.0 + 3.0 * t)))
    assert not of(ea, "hostile-expected")


def test_a_slower_tempo_the_plan_accepts_is_silent(tmp_path):
    sc = scenario(tmp_path, [BP_HOME, AVENUE], [mission("A1-dis", "A1", "disrupt", position="BP-HOME",
                                                        avenue="AA-N", by=600, tempo_mps=4.0)])
    msgs = stays("A1", 0, 0) + stays("A2", 3000, -3000) + [start(100, "A1-dis", "A1")] + \
        track_path("H1", 100, 900, lambda t: (50.0, 6000.0 - 3.0 * t))
    assert not of(play(sc, msgs, 900), "hostile-expected")


# ===================================================== secure, seize and clear on an objective
OBJ_MID = box("OBJ-MID", "objective", 1000, -500, 2000, 500)


def _taking(tmp_path, typ, hostile, **params):
    """A1 from 800 m west of OBJ-MID onto it at 10 m/s from t=100 (on it from about t=120,
    every element by 150), ends at 300."""
    sc = scenario(tmp_path, [OBJ_MID], [mission("A1-obj", "A1", typ, objective="OBJ-MID", **params)])
    msgs = (stays("A1", 200, 0, 10, 100) + path("A1", 110, 400, lambda t: (min(1500.0, 200 + 10.0 * (t - 100)), 0.0))
            + stays("A2", 0, -3000) + [start(100, "A1-obj", "A1"), end(300, "A1-obj", "A1")] + hostile)
    return play(sc, msgs, 400)


HOSTILE_IN = [track(200, "H1", 2600, 900), track(230, "H1", 1700, 200), track(260, "H1", 1700, 200)]
HOSTILE_LEFT = [track(120, "H1", 1700, 200)]   # on the objective throughout


def test_a_hostile_entering_a_secured_objective_while_it_runs_is_a_penetration(tmp_path):
    ea = _taking(tmp_path, "secure", HOSTILE_IN)
    pen = of(ea, "penetration")
    assert pen and near(pen[0].t, 230.0), [(a.t, a.type) for a in ea.alerts]
    assert pen[0].subjects == ("H1",) and pen[0].details["place"] == "OBJ-MID"
    assert pen[0].details["mission"] == "A1-obj"


@pytest.mark.parametrize("typ", ["seize", "clear", "attack"])
def test_other_offensive_tasks_do_not_forbid_hostiles_in_the_objective(tmp_path, typ):
    assert not of(_taking(tmp_path, typ, HOSTILE_IN), "penetration")


def test_secure_asks_no_end_state_clearance_and_is_silent_with_no_hostile(tmp_path):
    assert not of(_taking(tmp_path, "secure", [track(120, "H1", 3500, 3000)]), "penetration")
    ea = _taking(tmp_path, "secure", HOSTILE_LEFT)
    assert not of(ea, "end-state") and of(ea, "penetration")


def test_clear_is_told_of_a_hostile_left_on_the_objective_and_seize_is_not(tmp_path):
    es = of(_taking(tmp_path, "clear", HOSTILE_LEFT), "end-state")
    assert len(es) == 1 and es[0].t == 300.0 and es[0].subjects == ("A1", "H1")
    assert not of(_taking(tmp_path, "seize", HOSTILE_LEFT), "end-state")


def test_a_clear_whose_objective_holds_no_hostile_at_its_end_is_silent(tmp_path):
    """The hostile seen last far from the objective: nothing left to clear, nothing told."""
    assert not of(_taking(tmp_path, "clear", [track(120, "H1", 3500, 3000)]), "end-state")


def test_a_seize_not_on_its_objective_by_its_time_is_out_of_position_then(tmp_path):
    ea = _taking(tmp_path, "seize", [], by=110)   # at t=110 A1 is 700 m short of it
    oop = [a for a in of(ea, "out-of-position") if a.details["check"] == "by"]
    assert len(oop) == 1 and near(oop[0].t, 110.0), [(a.t, a.details.get("check")) for a in ea.alerts]
    assert oop[0].subjects == ("A1",) and oop[0].details["control_measure"] == "OBJ-MID"
    assert oop[0].details["rule"] == "all"


def test_a_seize_on_its_objective_by_its_time_is_silent(tmp_path):
    ea = _taking(tmp_path, "seize", [], by=250)
    assert not of(ea, "out-of-position"), [(a.t, a.message) for a in of(ea, "out-of-position")]


# ===================================================================== follow and assume
DEST_FAR = box("DEST-FAR", "assembly-area", 5800, -200, 6200, 200)
DEST_BEHIND = box("DEST-BEHIND", "assembly-area", 3800, -200, 4200, 200)


def _assuming(tmp_path, typ, leader, **extra):
    """A1 moves to DEST-FAR; A2 follows it (to DEST-BEHIND) with `typ`."""
    ms = [mission("A1-move", "A1", "move", destination="DEST-FAR"),
          mission("A2-follow", "A2", typ, supported="A1", destination="DEST-BEHIND", **extra)]
    sc = scenario(tmp_path, [DEST_FAR, DEST_BEHIND], ms)
    msgs = (path("A1", 10, 1200, leader) + path("A2", 10, 1200, lambda t: (leader(t)[0] - 500.0, 0.0))
            + [start(100, "A1-move", "A1"), start(100, "A2-follow", "A2")])
    return play(sc, msgs, 1200)


def _halts_at_400(t):   # east at 5 m/s from t=100, halted at x=1500 from t=400 (4.3 km short)
    return 5.0 * min(max(0.0, t - 100.0), 300.0), 0.0


def _keeps_going(t):
    return 5.0 * max(0.0, t - 100.0), 0.0


def test_a_follower_assumes_the_mission_of_a_unit_that_halts_and_says_so(tmp_path):
    ea = _assuming(tmp_path, "follow-and-assume", _halts_at_400)
    c = of(ea, "contingency", "assume")
    assert len(c) == 1, [(a.t, a.type, a.message) for a in ea.alerts]
    a = c[0]
    assert 400 + 180 - REPORT_S <= a.t <= 400 + 180 + REPORT_S + 2 * EPOCH, a.t   # standing within HALT_M
    assert a.subjects == ("A2", "A1") and a.details["assumed"] == "A1-move" and a.details["supported"] == "A1"
    assert "assumes" in a.message and "halted" in a.details["why"]
    cid = a.details["as"]
    assert ea.domain.plan.state[cid] == "active" and ea.domain.missions[cid].unit == "A2"
    assert ea.domain.missions[cid].TYPE == "move" and ea.domain.missions[cid].params["destination"] == "DEST-FAR"
    assert not of(ea, "band")   # it no longer follows the halted unit


def test_the_assumed_mission_is_monitored_as_the_followers_own(tmp_path):
    """The follower halts with the leader: once it assumed the move to DEST-FAR, its own
    arrival there is what counts at its end."""
    ms = [mission("A1-move", "A1", "move", destination="DEST-FAR"),
          mission("A2-follow", "A2", "follow-and-assume", supported="A1", destination="DEST-BEHIND")]
    sc = scenario(tmp_path, [DEST_FAR, DEST_BEHIND], ms)
    msgs = (path("A1", 10, 1200, _halts_at_400) + path("A2", 10, 1200, lambda t: (_halts_at_400(t)[0] - 500, 0.0))
            + [start(100, "A1-move", "A1"), start(100, "A2-follow", "A2"), end(1000, "A2-follow", "A2")])
    ea = play(sc, msgs, 1200)
    cid = of(ea, "contingency", "assume")[0].details["as"]
    at_end = [a for a in of(ea, "out-of-position") if a.details["mission"] == cid]
    assert at_end and at_end[-1].details["control_measure"] == "DEST-FAR" and near(at_end[-1].t, 1000.0)
    assert ea.domain.plan.state[cid] == "done"


def test_a_follower_whose_supported_unit_keeps_moving_assumes_nothing(tmp_path):
    ea = _assuming(tmp_path, "follow-and-assume", _keeps_going)
    assert not of(ea, "contingency")


def test_a_supported_unit_standing_at_its_goal_has_arrived_not_halted(tmp_path):
    ea = _assuming(tmp_path, "follow-and-assume", lambda t: (min(6000.0, 20.0 * max(0.0, t - 100.0)), 0.0))
    assert not of(ea, "contingency")


def test_a_follower_assumes_the_mission_of_a_unit_committed_elsewhere(tmp_path):
    """The supported unit's mission aborted (its commander's decision): assumed at once."""
    ms = [mission("A1-move", "A1", "move", destination="DEST-FAR"),
          mission("A2-follow", "A2", "follow-and-assume", supported="A1", destination="DEST-BEHIND")]
    sc = scenario(tmp_path, [DEST_FAR, DEST_BEHIND], ms)
    msgs = (path("A1", 10, 600, _keeps_going) + path("A2", 10, 600, lambda t: (_keeps_going(t)[0] - 500.0, 0.0))
            + [start(100, "A1-move", "A1"), start(100, "A2-follow", "A2")])
    ea = feed(sc, msgs, 300)
    ea.domain._abort("A1-move")
    ea = feed(sc, msgs, 600, ea=ea, since=300)
    ea.finish(600)
    c = of(ea, "contingency", "assume")
    assert len(c) == 1 and 300 < c[0].t <= 300 + REPORT_S + 2 * EPOCH, [(a.t, a.message) for a in ea.alerts]
    assert c[0].details["why"] == "its mission aborted" and c[0].details["assumed"] == "A1-move"


def test_follow_and_support_never_assumes(tmp_path):
    assert not of(_assuming(tmp_path, "follow-and-support", _halts_at_400), "contingency")


# ============================================================ zone and area reconnaissance
ZONE = box("ZONE-Z", "area", 0, 0, 2000, 1000)        # 2 km wide, 1 km deep: 4 bands of 250 m
SCREEN = box("SCREEN-Z", "area", -200, -1200, 2200, 1200)


def _recon(tmp_path, typ, where):
    """The unit starts south of the zone (its front is the south edge) at t=100 and must see
    all of it by 1300."""
    sc = scenario(tmp_path, [ZONE, SCREEN],
                  [mission("A1-recon", "A1", typ, {"type": "START-AT", "t": 100}, {"type": "END-NLT", "t": 1300},
                           position="SCREEN-Z", area="ZONE-Z")])
    msgs = path("A1", 10, 1300, where) + stays("A2", 0, -3000, 10, 1300) + [start(100, "A1-recon", "A1")]
    return play(sc, msgs, 1300)


def _rear_first(t):
    """From south of the zone straight to its rear (north) edge, then east along it and back
    along the middle: the rear is seen before the front."""
    if t < 200:
        return 1000.0, -300.0
    legs = [(1000, -300, 1000, 900), (1000, 900, 0, 900), (0, 900, 2000, 900), (2000, 900, 2000, 400),
            (2000, 400, 0, 400), (0, 400, 0, 100), (0, 100, 2000, 100)]
    s = (t - 200) * 5.0
    for x0, y0, x1, y1 in legs:
        n = abs(x1 - x0) + abs(y1 - y0)
        if s <= n:
            f = s / n
            return x0 + (x1 - x0) * f, y0 + (y1 - y0) * f
        s -= n
    return 2000.0, 100.0


ABREAST = Force({"A1": tuple(f"A1E{i}" for i in range(1, 6)), "A2": ("A2E1", "A2E2"), "B1": ("B1E1", "B1E2")},
                name="mission-classes-abreast")


def _abreast(t0: float, t1: float) -> list:
    """A1's five elements in a line abreast 400 m apart across the zone, from 300 m south of it
    at t0 to 100 m north of it at t1: the zone's depth passed front to rear, in step."""
    out, t = [], 10.0
    while t <= t1 + 200:
        y = -300.0 + 1400.0 * min(1.0, max(0.0, (t - t0) / (t1 - t0)))
        out += [LocationReport(t, f"A1E{i + 1}", *ll(200.0 + 400.0 * i, y)) for i in range(5)]
        t += REPORT_S
    return out


def test_a_zone_reconnaissance_that_sees_its_rear_before_its_front_is_behind(tmp_path):
    rp = of(_recon(tmp_path, "zone-reconnaissance", _rear_first), "recon-progress", "behind")
    assert rp, "no behind alert"
    assert rp[0].details["progress"] == "depth" and "depth" in rp[0].message


def test_an_area_reconnaissance_on_the_same_path_is_not_behind(tmp_path):
    """Coverage is the area's measure: the same path sees enough of it in time, in any order."""
    assert not of(_recon(tmp_path, "area-reconnaissance", _rear_first), "recon-progress", "behind")


def test_a_zone_reconnaissance_front_to_rear_in_step_is_silent(tmp_path):
    sc = ABREAST.scenario(tmp_path, [ZONE, SCREEN], [mission(
        "A1-recon", "A1", "zone-reconnaissance", {"type": "START-AT", "t": 100}, {"type": "END-NLT", "t": 1300},
        position="SCREEN-Z", area="ZONE-Z")])
    msgs = _abreast(100, 1100) + ABREAST.stays("A2", 0, -3000, 10, 1300) + \
        [start(100, "A1-recon", "A1"), end(1250, "A1-recon", "A1")]
    rp = of(play(sc, msgs, 1300), "recon-progress")
    assert not rp, [a.message for a in rp]


# ====================================================================== branch and sequel
RTE_1 = line("RTE-1", "route", (-2000, 0), (6000, 0))
NAI_N = box("NAI-N", "area", -500, 3000, 500, 3600)
BP_2 = box("BP-2", "battle-position", 1900, -1200, 2300, -800)


@pytest.mark.parametrize("typ, offered", [("branch", True), ("sequel", False)])
def test_a_branch_is_offered_in_place_of_a_move_meeting_hostiles_and_a_sequel_is_not(tmp_path, typ, offered):
    ms = [mission("A1-move", "A1", "move", route="RTE-1", destination="DEST-FAR"),
          mission("A-next", "A1", typ, trigger={"kind": "hostile-in-area", "area": "NAI-N"}, task="occupy",
                  task_params={"position": "BP-2"}, owner="A")]
    sc = scenario(tmp_path, [RTE_1, NAI_N, BP_2, DEST_FAR], ms)
    msgs = path("A1", 10, 400, lambda t: (max(0.0, t - 100) * 5.0, 0.0)) + stays("A2", 0, -3000, 10, 400) + \
        [start(100, "A1-move", "A1"), track(150, "H1", 1250, 0)]
    ta = of(play(sc, msgs, 300), "threat-ahead")
    assert len(ta) == 1
    assert ("execute:A-next" in ta[0].details["decision"]["options"]) is offered
