"""Every leaf mission class its own behaviour (issues 34.2 and 53.3): each checks what its
task means (FM 3-90) in monitoring hooks of its own, not by a constant its family's methods
read; no two leaf classes resolve to the same monitoring methods (two that differ only by
class attributes, a number, a priority table or a flag, are caught); and for each class the
condition its doctrine names raises its alert, while the same facts with the class's own hooks
removed (its family's base) do not.

Small synthetic scenarios on scenario time, with the builders of tests/synthetic.py
(geometry in local metres east/north of the generator's origin)."""
from __future__ import annotations

import inspect
import itertools

import pytest

from ea_agent.core.mission import Mission as CoreMission
from ea_agent.domains.suo.messages import LocationReport
from ea_agent.domains.suo.missions import REGISTRY, Isolate, Occupy
from saim_mesh import cli

from .synthetic import (EPOCH, REPORT_S, Force, alerts_of, along, box, end, feed, line, ll, mission, near, play, start,
                        track, track_path)

FORCE = Force(name="mission-classes")
scenario, path = FORCE.scenario, FORCE.path


def stays(unit: str, x: float, y: float, t0: float = 10.0, t1: float = 1500.0) -> list:
    return FORCE.stays(unit, x, y, t0, t1)


def of(ea, typ: str, check: str | None = None) -> list:
    return [a for a in alerts_of(ea, typ) if check is None or a.details.get("check") == check]


# ============================================ no class only a constant away from another or its base
# the methods the EA calls to monitor a mission (paper 6.5), and the hooks they call
HOOKS = ("location_constraints", "check_initial_location", "check_final_location", "contingency_satisfied",
         "execute_mission", "respond_to_threat_ahead", "post_execution_constraints", "plan_constraints",
         "red_alert_priority", "respond_to_monitored_red_activity", "desired_strength_ratio",
         "departure_by", "post_follow_band", "post_progress", "recheck_on_scan", "watch_area", "offered_in_place")


def methods(cls) -> tuple:
    """What a mission class does: every method it resolves, by the function object its
    hierarchy gives it. Class attributes (numbers, priority tables, flags) are not in it."""
    out = []
    for name in dir(cls):
        if name.startswith("__"):
            continue
        v = inspect.getattr_static(cls, name)
        if isinstance(v, (classmethod, staticmethod)):
            v = v.__func__
        if (callable(v) and not isinstance(v, type)) or isinstance(v, property):
            out.append((name, id(v)))
    return tuple(sorted(out))


def only_attributes_apart(classes) -> list[tuple[str, str]]:
    """Pairs of classes that resolve to the same methods: whatever their constants, they differ
    only by class attributes."""
    sig = {c.TYPE: methods(c) for c in classes}
    return [(a, b) for a, b in itertools.combinations(sorted(sig), 2) if sig[a] == sig[b]]


def without_own_hooks(classes) -> list[str]:
    """Classes with no monitoring hook of their own: their family's base under a new name, or
    it with other constants."""
    return sorted(c.TYPE for c in classes if not any(n in vars(c) for n in HOOKS))


def test_no_two_leaf_mission_classes_differ_only_by_class_attributes():
    assert only_attributes_apart(REGISTRY.values()) == []


def test_every_leaf_mission_class_has_a_monitoring_hook_of_its_own():
    assert without_own_hooks(REGISTRY.values()) == []
    assert all(issubclass(c, CoreMission) for c in REGISTRY.values())


def test_a_class_that_only_renames_its_parent_is_caught():
    class Renamed(Occupy):
        """A new name, nothing of its own."""
        TYPE = "renamed-occupy"
    assert only_attributes_apart([*REGISTRY.values(), Renamed]) == [("occupy", "renamed-occupy")]
    assert without_own_hooks([Renamed]) == ["renamed-occupy"]


def test_a_class_that_only_changes_a_number_a_priority_table_or_a_flag_is_caught():
    class Stronger(Isolate):
        """Isolate wanting 4:1, its schedule alerts FLASH, all its elements on the objective."""
        TYPE = "stronger-isolate"
        DESIRED_STRENGTH_RATIO = 4.0
        PRIORITY = {"schedule": "flash"}
        FINAL_RULE = "all"
    assert only_attributes_apart([*REGISTRY.values(), Stronger]) == [("isolate", "stronger-isolate")]
    assert without_own_hooks([Stronger]) == ["stronger-isolate"]


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
    return along(legs, (t - 200) * 5.0)


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


# ================================ each class its own meaning: an alert its family's base does not raise
def as_base(monkeypatch, typ: str) -> None:
    """The leaf class of `typ` monitors as its parent does: its own hooks removed (its
    parameters are still accepted, so the same plan loads)."""
    cls = REGISTRY[typ]
    own = [n for n in HOOKS if n in vars(cls)]
    assert own, f"{typ} has no monitoring hook of its own"
    for n in own:
        monkeypatch.delattr(cls, n)


def checked(ea, typ: str, check: str) -> list:
    return [a for a in alerts_of(ea, typ) if a.details.get("check") == check]


def _east(v: float, x0: float = 0.0, t0: float = 100.0, y: float = 0.0):
    return lambda t: (x0 + v * max(0.0, t - t0), y)


def _move_by(tmp_path):
    """A1 east at 5 m/s from t=100 to DEST-FAR (its edge at 5800: there at t=1260); due there by 600."""
    sc = scenario(tmp_path, [DEST_FAR], [mission("A1-move", "A1", "move", destination="DEST-FAR", by=600)])
    return play(sc, path("A1", 10, 800, _east(5.0)) + stays("A2", 0, -3000, 10, 800) + [start(100, "A1-move", "A1")],
                800)


def test_move_means_being_at_its_destination_by_its_time(tmp_path, monkeypatch):
    oop = checked(_move_by(tmp_path / "move"), "out-of-position", "by")
    assert len(oop) == 1 and near(oop[0].t, 600.0), [(a.t, a.message) for a in oop]
    assert oop[0].details["control_measure"] == "DEST-FAR"
    as_base(monkeypatch, "move")
    assert not checked(_move_by(tmp_path / "base"), "out-of-position", "by")


def _march(tmp_path, ahead_x: float):
    """A1 marches east at 5 m/s with A2 the serial ahead, `ahead_x` m in front of it; interval 100-500 m."""
    sc = scenario(tmp_path, [RTE_1, DEST_FAR], [mission("A1-march", "A1", "tactical-road-march", route="RTE-1",
                                                        destination="DEST-FAR", ahead="A2", interval_m=[100, 500])])
    msgs = (path("A1", 10, 600, _east(5.0)) + path("A2", 10, 600, _east(5.0, ahead_x))
            + [start(100, "A1-march", "A1")])
    return play(sc, msgs, 600)


def test_a_tactical_road_march_means_keeping_its_march_interval(tmp_path, monkeypatch):
    band = alerts_of(_march(tmp_path / "gap", 2000.0), "band")
    assert band and band[0].subjects == ("A1", "A2") and "too far" in band[0].message, [a.message for a in band]
    assert band[0].details["band_m"] == [100.0, 500.0]
    assert not alerts_of(_march(tmp_path / "kept", 300.0), "band")
    as_base(monkeypatch, "tactical-road-march")
    assert not alerts_of(_march(tmp_path / "base", 2000.0), "band")


LOA = line("PL-LOA", "phase-line", (1000, -2000), (1000, 2000))


def _contact(tmp_path):
    """A1 east at 5 m/s from t=100: across PL-LOA (x=1000), its limit of advance, at t=300."""
    sc = scenario(tmp_path, [RTE_1, DEST_FAR, LOA], [mission("A1-mtc", "A1", "movement-to-contact", route="RTE-1",
                                                             destination="DEST-FAR", limit="PL-LOA")])
    return play(sc, path("A1", 10, 500, _east(5.0)) + stays("A2", 0, -3000, 10, 500) + [start(100, "A1-mtc", "A1")],
                500)


def test_a_movement_to_contact_means_not_going_past_its_limit_of_advance(tmp_path, monkeypatch):
    ln = checked(_contact(tmp_path / "mtc"), "line", "limit")
    assert ln and 300 <= ln[0].t <= 300 + REPORT_S + 2 * EPOCH, [(a.t, a.message) for a in ln]
    assert ln[0].details["line"] == "PL-LOA" and "limit of advance" in ln[0].message
    as_base(monkeypatch, "movement-to-contact")
    assert not alerts_of(_contact(tmp_path / "base"), "line")


def _supporting(tmp_path):
    """A1 halts at x=1500 from t=400 on its way to DEST-FAR; A2, following it to DEST-BEHIND,
    goes on past it (at 5 m/s, 500 m behind it until then)."""
    ms = [mission("A1-move", "A1", "move", destination="DEST-FAR"),
          mission("A2-follow", "A2", "follow-and-support", supported="A1", destination="DEST-BEHIND",
                  toward="DEST-FAR", band_m=[0, 3000])]
    sc = scenario(tmp_path, [DEST_FAR, DEST_BEHIND], ms)
    msgs = (path("A1", 10, 900, _halts_at_400) + path("A2", 10, 900, _east(5.0, -500.0))
            + [start(100, "A1-move", "A1"), start(100, "A2-follow", "A2")])
    return play(sc, msgs, 900)


def test_follow_and_support_means_not_passing_the_unit_it_supports(tmp_path, monkeypatch):
    ahead = checked(_supporting(tmp_path / "fs"), "band", "ahead")
    # A2 at x=1500 at t=500: more than out_of_position_m past A1 some 30 s later
    assert ahead and 500 < ahead[0].t <= 560, [(a.t, a.message) for a in ahead]
    assert ahead[0].subjects == ("A2", "A1") and ahead[0].details["place"] == "DEST-FAR"
    as_base(monkeypatch, "follow-and-support")
    assert not checked(_supporting(tmp_path / "base"), "band", "ahead")


RTE_R = line("RTE-R", "route", (0, 0), (4000, 0))
DEST_R = box("DEST-R", "assembly-area", 3900, -200, 4300, 200)


def _route_recon(tmp_path):
    """A1 reconnoitres RTE-R by 900 but halts halfway along it (x=2000 from t=500)."""
    sc = scenario(tmp_path, [RTE_R, DEST_R], [mission("A1-rr", "A1", "route-reconnaissance",
                                                      {"type": "START-AT", "t": 100}, {"type": "END-NLT", "t": 900},
                                                      route="RTE-R", destination="DEST-R")])
    msgs = (path("A1", 10, 900, lambda t: (min(2000.0, 5.0 * max(0.0, t - 100.0)), 0.0))
            + stays("A2", 0, -3000, 10, 900) + [start(100, "A1-rr", "A1"), end(880, "A1-rr", "A1")])
    return play(sc, msgs, 900)


def test_a_route_reconnaissance_means_every_section_of_its_route_seen(tmp_path, monkeypatch):
    rp = alerts_of(_route_recon(tmp_path / "rr"), "recon-progress")
    assert rp and rp[0].details["area"] == "RTE-R", [(a.t, a.message) for a in rp]
    assert {a.details["check"] for a in rp} <= {"behind", "incomplete"}
    assert any(a.details["check"] == "incomplete" and a.details["seen"] < 0.7 for a in rp)
    as_base(monkeypatch, "route-reconnaissance")
    assert not alerts_of(_route_recon(tmp_path / "base"), "recon-progress")


LD = line("LD-1", "phase-line", (500, -2000), (500, 2000))


def _attack(tmp_path, h_hour):
    """A1 waits at x=0 until t=400, then east at 10 m/s: across LD-1 (x=500) at t=450."""
    sc = scenario(tmp_path, [OBJ_MID, LD], [mission("A1-atk", "A1", "attack", objective="OBJ-MID",
                                                    line_of_departure="LD-1", h_hour=h_hour)])
    return play(sc, path("A1", 10, 600, _east(10.0, 0.0, 400.0)) + stays("A2", 0, -3000, 10, 600), 600)


def test_an_attack_means_crossing_its_line_of_departure_at_h_hour(tmp_path, monkeypatch):
    ln = checked(_attack(tmp_path / "late", 200), "line", "depart")
    assert len(ln) == 1 and near(ln[0].t, 200.0), [(a.t, a.message) for a in ln]
    assert ln[0].details["line"] == "LD-1" and "line of departure" in ln[0].message
    ea = _attack(tmp_path / "on-time", 500)
    assert not checked(ea, "line", "depart") and ea.domain.plan.state["A1-atk"] == "active"
    as_base(monkeypatch, "attack")
    assert not alerts_of(_attack(tmp_path / "base", 200), "line")


def _occupying(tmp_path):
    """A1 from x=-1000 east at 2 m/s from t=100 into BP-HOME (x from -200): all in by t=520; due by 300."""
    sc = scenario(tmp_path, [BP_HOME], [mission("A1-occ", "A1", "occupy", position="BP-HOME", by=300)])
    msgs = path("A1", 10, 700, lambda t: (min(0.0, -1000.0 + 2.0 * max(0.0, t - 100.0)), 0.0)) + \
        stays("A2", 0, -3000, 10, 700) + [start(100, "A1-occ", "A1")]
    return play(sc, msgs, 700)


def test_occupy_means_every_element_in_its_position_by_its_time(tmp_path, monkeypatch):
    oop = checked(_occupying(tmp_path / "occ"), "out-of-position", "by")
    assert len(oop) == 1 and near(oop[0].t, 300.0) and oop[0].details["rule"] == "all", [a.message for a in oop]
    as_base(monkeypatch, "occupy")
    assert not checked(_occupying(tmp_path / "base"), "out-of-position", "by")


PL_ABF = line("PL-ABF", "phase-line", (500, -2000), (500, 2000))


def _by_fire(tmp_path, closes: bool, target="TGT-NEAR"):
    """A1 in BP-HOME firing on `target`; if `closes`, it moves east from t=300 at 5 m/s (across
    PL-ABF, x=500, at t=400) towards it."""
    sc = scenario(tmp_path, [BP_HOME, TGT_NEAR, TGT_FAR, PL_ABF],
                  [mission("A1-abf", "A1", "attack-by-fire", position="BP-HOME", target=target, limit="PL-ABF")])
    where = _east(5.0, 0.0, 300.0) if closes else (lambda t: (0.0, 0.0))
    return play(sc, path("A1", 10, 600, where) + stays("A2", 0, -3000, 10, 600) + [start(100, "A1-abf", "A1")], 600)


def test_an_attack_by_fire_means_not_closing_with_its_target(tmp_path, monkeypatch):
    ln = checked(_by_fire(tmp_path / "closes", True), "line", "limit")
    assert ln and 400 <= ln[0].t <= 400 + REPORT_S + 2 * EPOCH, [(a.t, a.message) for a in ln]
    assert not alerts_of(_by_fire(tmp_path / "stays", False), "line")
    fe = alerts_of(_by_fire(tmp_path / "far", False, "TGT-FAR"), "friendly-expected")
    assert fe and "TGT-FAR" in fe[0].message, [a.message for a in fe]
    assert not alerts_of(_by_fire(tmp_path / "near", False), "friendly-expected")
    as_base(monkeypatch, "attack-by-fire")
    assert not alerts_of(_by_fire(tmp_path / "base", True), "line")
    assert not alerts_of(_by_fire(tmp_path / "base-far", False, "TGT-FAR"), "friendly-expected")


CP_LINK = box("CP-LINK", "checkpoint", 900, -100, 1100, 100)


def _linking(tmp_path):
    """A1 and A2 both at CP-LINK from t=100 (link-up at 300); A1 leaves east at 5 m/s from t=400."""
    sc = scenario(tmp_path, [CP_LINK], [mission("A1-link", "A1", "link-up", partner="A2", point="CP-LINK", at=300,
                                                join_m=300)])
    msgs = (path("A1", 10, 800, _east(5.0, 1000.0, 400.0)) + stays("A2", 1000, 0, 10, 800)
            + [start(100, "A1-link", "A1")])
    return play(sc, msgs, 800)


def test_a_link_up_means_the_forces_stay_joined_after_they_meet(tmp_path, monkeypatch):
    ea = _linking(tmp_path / "lu")
    band = alerts_of(ea, "band")
    # 300 m + out_of_position_m (150) apart at t=490
    assert band and 490 <= band[0].t <= 490 + REPORT_S + 2 * EPOCH, [(a.t, a.message) for a in band]
    assert band[0].subjects == ("A1", "A2") and not alerts_of(ea, "coordination")
    as_base(monkeypatch, "link-up")
    assert not alerts_of(_linking(tmp_path / "base"), "band")


def _following_on(tmp_path):
    """A sequel (occupy BP-2) after A1's move, triggered by hostiles in NAI-N (from t=150); the move ends at 400."""
    ms = [mission("A1-move", "A1", "move", destination="DEST-FAR"),
          mission("A-next", "A1", "sequel", trigger={"kind": "hostile-in-area", "area": "NAI-N"}, task="occupy",
                  task_params={"position": "BP-2"}, owner="A", follows="A1-move")]
    sc = scenario(tmp_path, [NAI_N, BP_2, DEST_FAR], ms)
    msgs = (path("A1", 10, 600, _east(5.0)) + stays("A2", 0, -3000, 10, 600)
            + [start(100, "A1-move", "A1"), end(400, "A1-move", "A1")]
            + track_path("H1", 150, 600, lambda t: (0.0, 3300.0)))   # standing in NAI-N: no track change after 400
    return play(sc, msgs, 600)


def test_a_sequel_means_not_before_the_mission_it_follows_is_done(tmp_path, monkeypatch):
    c = alerts_of(_following_on(tmp_path / "seq"), "contingency")
    assert len(c) == 1 and 400 <= c[0].t <= 400 + REPORT_S + 2 * EPOCH, [(a.t, a.message) for a in c]
    as_base(monkeypatch, "sequel")
    c = alerts_of(_following_on(tmp_path / "base"), "contingency")
    assert len(c) == 1 and c[0].t < 200, [(a.t, a.message) for a in c]


def _reorganizing(tmp_path, b1_x: float):
    """A2 (at 0, -3000) goes under B at t=200 and must be within 500 m of B's own by 400 (B1 at b1_x, -3000)."""
    sc = scenario(tmp_path, [], [mission("BN-reorg", "BN", "reorganize", {"type": "START-AT", "t": 200},
                                         subject="A2", new_parent="B", join_m=500, by=400)])
    msgs = stays("A1", 0, 0, 10, 600) + stays("A2", 0, -3000, 10, 600) + stays("B1", b1_x, -3000, 10, 600)
    return play(sc, msgs, 600, owner="BN")


def test_a_reorganization_means_the_unit_joined_to_its_new_superior_by_its_time(tmp_path, monkeypatch):
    ea = _reorganizing(tmp_path / "apart", 3000.0)
    band = checked(ea, "band", "joined")
    assert len(band) == 1 and near(band[0].t, 400.0) and band[0].subjects == ("A2", "B"), [a.message for a in band]
    assert 2950 < band[0].details["distance_m"] < 3050
    assert ea.domain.taskorg.parent["A2"] == "B"
    assert not checked(_reorganizing(tmp_path / "together", 300.0), "band", "joined")
    as_base(monkeypatch, "reorganize")
    assert not alerts_of(_reorganizing(tmp_path / "base", 3000.0), "band")


def test_an_area_reconnaissance_means_its_area_covered(tmp_path, monkeypatch):
    """A unit that never enters the area: behind, and incomplete at its end; the recon family
    measures nothing of its own."""
    rp = of(_recon(tmp_path / "area", "area-reconnaissance", lambda t: (1000.0, -900.0)), "recon-progress")
    assert rp and rp[0].details["progress"] == "coverage", [a.message for a in rp]
    as_base(monkeypatch, "area-reconnaissance")
    assert not of(_recon(tmp_path / "base", "area-reconnaissance", lambda t: (1000.0, -900.0)), "recon-progress")


def test_a_hasty_attack_means_on_its_objective_soon_after_its_start(tmp_path, monkeypatch):
    """A1 reaches OBJ-MID's edge at t=180 (centroid on it): due within 50 s of its start (100)."""
    oop = checked(_taking(tmp_path / "hasty", "hasty-attack", [], within_s=50), "out-of-position", "by")
    assert len(oop) == 1 and near(oop[0].t, 150.0) and oop[0].details["rule"] == "centroid", [a.t for a in oop]
    assert not checked(_taking(tmp_path / "in-time", "hasty-attack", [], within_s=150), "out-of-position", "by")
    as_base(monkeypatch, "hasty-attack")
    assert not checked(_taking(tmp_path / "base", "hasty-attack", [], within_s=50), "out-of-position", "by")


# out of the objective from t=250 (x 1500 -> 2600 at 10 m/s from 200)
LEAVES = [track(120, "H1", 1500, 0), track(180, "H1", 1500, 0)] + \
    track_path("H1", 200, 400, lambda t: (1500.0 + 10.0 * (t - 200.0), 0.0))


def test_a_fix_means_the_enemy_held_for_its_period_only(tmp_path, monkeypatch):
    assert of(_taking(tmp_path / "while", "fix", LEAVES), "escape")
    assert not of(_taking(tmp_path / "until", "fix", LEAVES, until=220), "escape")
    as_base(monkeypatch, "fix")
    assert not of(_taking(tmp_path / "base", "fix", LEAVES), "escape")


def test_isolate_and_destroy_mean_none_escapes_and_attack_does_not(tmp_path, monkeypatch):
    for typ in ("isolate", "destroy"):
        assert of(_taking(tmp_path / typ, typ, LEAVES), "escape"), typ
    assert not of(_taking(tmp_path / "attack", "attack", LEAVES), "escape")
    as_base(monkeypatch, "isolate")
    assert not of(_taking(tmp_path / "base", "isolate", LEAVES), "escape")


def test_clear_means_no_hostile_left_and_its_base_asks_nothing(tmp_path, monkeypatch):
    assert of(_taking(tmp_path / "clear", "clear", HOSTILE_LEFT), "end-state")
    as_base(monkeypatch, "clear")
    assert not of(_taking(tmp_path / "base", "clear", HOSTILE_LEFT), "end-state")


BYPASSED = box("OBJ-BYP", "objective", 1000, -500, 2000, 500)


def _bypassing(tmp_path, y: float):
    """A1 east at 5 m/s at y (through OBJ-BYP, x 1000..2000, if |y| < 500) to DEST-FAR."""
    sc = scenario(tmp_path, [BYPASSED, DEST_FAR], [mission("A1-byp", "A1", "bypass", destination="DEST-FAR",
                                                           bypassed="OBJ-BYP")])
    return play(sc, path("A1", 10, 600, _east(5.0, 0.0, 100.0, y)) + stays("A2", 0, -3000, 10, 600) +
                [start(100, "A1-byp", "A1")], 600)


def test_a_bypass_means_going_around_what_it_bypasses(tmp_path, monkeypatch):
    through = checked(_bypassing(tmp_path / "through", 0.0), "standoff", "bypassed")
    # 150 m (out_of_position_m) inside the west edge at x=1150: t=330
    assert through and 330 <= through[0].t <= 330 + REPORT_S + 2 * EPOCH, [(a.t, a.message) for a in through]
    assert through[0].details["place"] == "OBJ-BYP"
    as_base(monkeypatch, "bypass")
    assert not of(_bypassing(tmp_path / "base", 0.0), "standoff")


def test_a_branch_is_offered_and_its_base_is_not(tmp_path, monkeypatch):
    """The family's base (a contingency) is never offered in place of the move."""
    test_a_branch_is_offered_in_place_of_a_move_meeting_hostiles_and_a_sequel_is_not(tmp_path / "b", "branch", True)
    as_base(monkeypatch, "branch")
    test_a_branch_is_offered_in_place_of_a_move_meeting_hostiles_and_a_sequel_is_not(tmp_path / "base", "branch",
                                                                                     False)


@pytest.mark.parametrize("typ, params, field", [
    ("tactical-road-march", {"destination": "DEST-FAR", "ahead": "A2"}, "interval_m"),
    ("tactical-road-march", {"destination": "DEST-FAR", "ahead": "A2", "interval_m": [500, 100]}, "interval_m"),
    ("attack", {"objective": "OBJ-MID", "h_hour": 200}, "line_of_departure"),
    ("move", {"destination": "DEST-FAR", "by": -1}, "by"),
    ("occupy", {"position": "BP-HOME", "by": "soon"}, "by"),
    ("link-up", {"partner": "A2", "point": "CP-LINK", "at": 300, "join_m": 0}, "join_m"),
    ("reorganize", {"subject": "A2", "new_parent": "B", "join_m": 500}, "by"),
    ("hasty-attack", {"objective": "OBJ-MID", "within_s": -5}, "within_s"),
    ("fix", {"objective": "OBJ-MID", "until": -5}, "until"),
    ("movement-to-contact", {"destination": "DEST-FAR", "limit": "OBJ-MID"}, "limit"),
], ids=lambda v: v if isinstance(v, str) else None)
def test_a_new_parameter_given_wrong_is_refused_naming_it(tmp_path, typ, params, field):
    from saim_mesh import scenario as scenarios
    with pytest.raises(scenarios.ScenarioError) as e:
        scenario(tmp_path, [DEST_FAR, OBJ_MID, BP_HOME, CP_LINK], [mission("A1-x", "A1", typ, **params)])
    assert "A1-x" in str(e.value) and f"params.{field}" in str(e.value), str(e.value)


def _post(tmp_path, leaves: bool):
    """A1 holds the observation post BP-HOME; if `leaves`, it goes east at 5 m/s from t=300."""
    watched = box("NAI-1", "area", 2000, -500, 3000, 500)
    sc = scenario(tmp_path, [BP_HOME, watched], [mission("A1-op", "A1", "observe", position="BP-HOME",
                                                         area="NAI-1")])
    where = _east(5.0, 0.0, 300.0) if leaves else (lambda t: (0.0, 0.0))
    return play(sc, path("A1", 10, 700, where) + stays("A2", 0, -3000, 10, 700) + [start(100, "A1-op", "A1")], 700)


def test_observe_means_its_post_never_left_empty(tmp_path, monkeypatch):
    fe = alerts_of(_post(tmp_path / "leaves", True), "friendly-expected")
    assert fe and fe[0].t > 300 and "BP-HOME" in fe[0].message, [(a.t, a.message) for a in fe]
    assert not alerts_of(_post(tmp_path / "holds", False), "friendly-expected")
    as_base(monkeypatch, "observe")
    assert not alerts_of(_post(tmp_path / "base", True), "friendly-expected")


def _overwatching(tmp_path, v: float):
    """A1 in BP-HOME overwatches A2, which moves east from x=0 at `v` m/s from t=100; band 0-1000 m."""
    sc = scenario(tmp_path, [BP_HOME], [mission("A1-ow", "A1", "overwatch", position="BP-HOME", supported="A2",
                                                band_m=[0, 1000])])
    msgs = stays("A1", 0, 0, 10, 700) + path("A2", 10, 700, _east(v, 0.0, 100.0, -300.0)) + \
        [start(100, "A1-ow", "A1")]
    return play(sc, msgs, 700)


def test_overwatch_means_the_overwatched_unit_kept_within_its_fires(tmp_path, monkeypatch):
    band = alerts_of(_overwatching(tmp_path / "away", 5.0), "band")
    assert band and band[0].subjects == ("A1", "A2") and band[0].t >= 280, [(a.t, a.message) for a in band]
    assert not alerts_of(_overwatching(tmp_path / "near", 0.5), "band")
    as_base(monkeypatch, "overwatch")
    assert not alerts_of(_overwatching(tmp_path / "base", 5.0), "band")
