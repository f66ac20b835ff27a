"""The oracle holds the EAs to what the sensors could see (the oracle: hostiles_at, areas'
tolerance and resolution), stories are per place (evaluate._no_news), fusion's max speed
(make_node, KalmanTracker) and orders switching plans in random battles (generator.py)."""
from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest
from shapely.geometry import Point

from ea_agent.core.alert import Alert
from ea_agent.core.geo import Projection
from ea_agent.domains.suo import generator as G
from ea_agent.domains.suo import oracle as O
from ea_agent.domains.suo.battle_plan import LANE_X, WITHDRAW_Y
from ea_agent.domains.suo.sim import Hostile, sensor_pos
from saim_mesh.inprocess.evaluate import _no_news
from saim_mesh.fusion import KalmanNode, make_node
from saim_mesh.fusion.tracker import KalmanTracker

ALL_SENSORS = [(sid, r) for sid, _g, _o, _k, r, *_ in G.SENSORS]
FEATS = G.overlay_features()


@pytest.fixture(scope="module")
def base():
    """A small random battle without an order (seed 3), its plan; hostiles replaced per test."""
    sim = G.build_sim(small=True, seed=3, incidents="random")
    assert sim.order is None
    return sim, G.plan_doc(sim)


def truth(base, hostiles, sensors=(), owners=("BN",)):
    sim, plan = base
    s = dataclasses.replace(sim, hostiles={h.id: h for h in hostiles}, sensors=list(sensors))
    return O.Truth(s, FEATS, plan, list(owners))


def south(hid, x, y0, appear=1000.0, v=5.0, strength=4, dy=0.0):
    """A group moving due south at `v` m/s along x from y0 (+dy) at t=1000, there from `appear`."""
    return Hostile(hid, [1000.0, 2400.0], [x, x], [y0 + dy, y0 + dy - v * 1400.0], strength, appear)


# -- 1. what the sensors could see ---------------------------------------------------------
def test_a_far_group_is_absent_only_where_hostiles_are_sensed(base):
    """A group kilometres from every sensor is absent from hostiles_at with sensors, present without."""
    far = Hostile("HF", [0.0, 5400.0], [-20000.0, -20000.0], [40000.0, 40000.0], 5, 0.0)
    for t in (500.0, 2000.0, 4000.0):
        for sid, r in ALL_SENSORS:   # really out of every sensor's reach
            sx, sy = sensor_pos(base[0], sid, t)
            assert math.hypot(sx + 20000.0, sy - 40000.0) > r + O.REACH_M
    sensed, unsensed = truth(base, [far], ALL_SENSORS), truth(base, [far])
    for t in (500.0, 2000.0, 4000.0):
        assert "HF" not in sensed.hostiles_at(t)
        assert unsensed.hostiles_at(t)["HF"] == (-20000.0, 40000.0, 5)


def test_a_group_coming_into_range_counts_after_three_covered_scans(base):
    """A group entering G1's range (3000 m + REACH_M) counts once covered at t, t-5 and t-10."""
    h = south("HS", 2000.0, 25000.0, appear=0.0, v=10.0)   # y = 35000 - 10 t; covered once y <= 19585
    first = next(t for t in np.arange(0.0, 2000.0, 5.0) if h.pos(t)[1] <= 16500.0 + 3000.0 + O.REACH_M)
    assert first == 1545.0
    sensed, unsensed = truth(base, [h], [("G1", 3000.0)]), truth(base, [h])
    assert sensed._covered(h, first) and not sensed._covered(h, first - 5.0)
    assert O.CONFIRM_S == (0.0, 5.0, 10.0)
    for t in (first - 5.0, first, first + 5.0):
        assert "HS" not in sensed.hostiles_at(t) and "HS" in unsensed.hostiles_at(t)
    assert "HS" in sensed.hostiles_at(first + 10.0)
    assert sensed.hostiles_at(first + 10.0)["HS"] == unsensed.hostiles_at(first + 10.0)["HS"]


def test_a_group_appearing_in_range_counts_from_its_third_scan(base):
    """A group appearing under G1 (all sensors on) is absent at its appearance and 5 s on, present 10 s on."""
    h = Hostile("HA", [0.0, 5400.0], [2000.0, 2000.0], [16500.0, 16500.0], 3, 1000.0)
    sensed, unsensed = truth(base, [h], ALL_SENSORS), truth(base, [h])
    assert "HA" not in sensed.hostiles_at(1000.0) and "HA" not in sensed.hostiles_at(1005.0)
    assert "HA" in sensed.hostiles_at(1010.0) and "HA" in unsensed.hostiles_at(1000.0)


def test_an_unsensed_group_near_a_platoon_is_no_contact(base):
    """Proximity truth only counts sensed groups: a group beside A1 that no sensor covers is no contact."""
    h = Hostile("HP", [0.0, 5400.0], [1700.0, 1700.0], [5000.0, 5000.0], 6, 0.0)
    sensed = truth(base, [h], [("G1", 3000.0)], owners=("A",))
    unsensed = truth(base, [h], owners=("A",))
    for tr in (sensed, unsensed):
        tr.proximity()
    assert any(i["type"] == "contact" and "HP" in i["subjects"] for i in unsensed.incidents)
    assert not any("HP" in i["subjects"] for i in sensed.incidents + sensed.situations)


# -- 2. area incidents: tolerance and resolution ---------------------------------------------
def dp1(tr):
    tr.areas()
    inc = [i for i in tr.incidents if "DP1" in i["subjects"]]
    sit = [s for s in tr.situations if "DP1" in s["subjects"]]
    return inc, sit


def test_a_group_grazing_an_area_edge_may_be_told_but_need_not(base):
    """A group inside DP1 by only 100 m (< TOLERANCE_M) gives a situation about DP1, no incident."""
    h = south("H1", 9400.0, 20010.0)   # DP1: r 500 around (9000, 17000); passes 400 m from its centre
    tr = truth(base, [h])
    assert any(tr.area["DP1"].contains(Point(*h.pos(t))) for t in tr.ticks if h.pos(t))   # it is inside
    inc, sit = dp1(tr)
    assert inc == []
    assert sit and all(s["about"] == ["DP1"] and s["accept"] == ["monitored"] for s in sit)


def test_a_group_going_deep_into_an_area_is_an_incident_from_when_it_came_near(base):
    """Through DP1's centre: an incident about DP1, at the first tick inside, t0 from TOLERANCE_M out - 15 s."""
    h = south("H1", 9000.0, 20010.0)   # y = 20010 - 5 (t - 1000): r 700 at t 1462, r 500 at 1502, r 300 at 1542
    inc, sit = dp1(truth(base, [h]))
    assert len(inc) == 1
    i = inc[0]
    assert (i["owner"], i["type"], i["subjects"], i["about"]) == ("BN", "monitored", ["DP1", "H1"], ["DP1"])
    assert (i["at"], i["t0"], i["t1"]) == (1505.0, 1465.0 - 15.0, 1545.0 + 45.0)
    assert O.TOLERANCE_M == 200.0
    assert sit and all(s["about"] == ["DP1"] for s in sit)


@pytest.mark.parametrize("dy, own", [(50.0, False), (250.0, True)])
def test_a_group_beside_one_already_near_is_no_new_group(base, dy, own):
    """A group appearing within RESOLVE_M (vs beyond it) of one already near DP1 has no incident of its own."""
    first = south("H1", 9000.0, 20010.0)
    second = south("H2", 9000.0, 20010.0, appear=1500.0, dy=dy)   # behind H1 by dy, on the same track
    assert (dy < O.RESOLVE_M) is not own
    inc, _ = dp1(truth(base, [first, second]))
    assert [i["subjects"] for i in inc if "H1" in i["subjects"]] == [["DP1", "H1"]]
    assert any("H2" in i["subjects"] for i in inc) is own


# -- 3. stories are per place --------------------------------------------------------------
def alert(t, place, strength=4):
    return Alert(t, "BN", "monitored", "adversarial-activity", "priority", ("H1",), f"Red activity at {place}",
                 {"place": place, "places": [place], "strength": strength})


ITEM = {"owner": "BN", "accept": ["monitored"], "subjects": ["DP1", "DP2", "H1"], "t0": 0.0, "t1": 1000.0}


def test_the_same_group_at_two_places_is_two_stories():
    """Same type and subjects at different places: neither alert is a repeat."""
    assert _no_news([alert(100.0, "DP1"), alert(200.0, "DP2")], [ITEM]) == []


def test_the_same_place_twice_without_change_is_a_repeat():
    """Same place twice with no severity change: the second is a repeat (a worse one is not)."""
    a, b = alert(100.0, "DP1"), alert(200.0, "DP1")
    assert _no_news([a, b], [ITEM]) == [b]
    assert _no_news([a, alert(200.0, "DP1", strength=5)], [ITEM]) == []   # 5 / 4 = STEP: news


# -- 4. fusion max speed ---------------------------------------------------------------------
def fusion_sc(**fusion):
    return SimpleNamespace(name="t", projection=Projection(32611),
                           meta={"fusion": {"sensors": [{"id": "G1", "sigma_m": 25.0}], **fusion}})


@pytest.mark.parametrize("bad", ["fast", -1, 0, 0.0, 1000.5, float("nan"), float("inf"), True, None, [40]])
def test_a_bad_max_speed_is_refused_by_name(bad):
    """fusion.max_speed_mps not a number in (0, 1000] raises ValueError naming it."""
    with pytest.raises(ValueError, match="max_speed_mps"):
        make_node(fusion_sc(max_speed_mps=bad), "N")


@pytest.mark.parametrize("v", [40, 40.0, 1000, 0.5])
def test_a_valid_max_speed_sets_the_velocity_prior(v):
    """A valid fusion.max_speed_mps is the tracker's: v0 = max_speed / 3 (default 300 m/s)."""
    node = make_node(fusion_sc(max_speed_mps=v), "N")
    assert type(node) is KalmanNode and node.tracker.v0 == pytest.approx(v / 3.0)
    assert make_node(fusion_sc(), "N").tracker.v0 == pytest.approx(100.0)


def feed(hits, **kw):
    """One hit per 5 s window (scan at 1 + 5k, close at 5k + 5), then 12 empty windows."""
    tr = KalmanTracker("T", 25.0, **kw)
    reps, confirmed = [], set()
    for k in range(len(hits) + 12):
        if k < len(hits):
            tr.scan(1.0 + 5.0 * k, "s", np.array([hits[k]], dtype=float))
        reps += tr.close_window(5.0 * (k + 1))
        confirmed |= {t.id for t in tr.tracks if t.confirmed}
    return reps, confirmed


FALSE_ALARMS = [(0.0, 0.0), (1600.0, 300.0), (3300.0, 400.0), (4800.0, 900.0)]   # 1.5-1.7 km apart


def test_false_alarms_km_apart_are_no_track_at_ground_speed():
    """Single hits 1.5-1.7 km apart 5 s apart: a ghost at 300 m/s, nothing at max_speed_mps=40."""
    assert all(1500 <= math.dist(a, b) <= 2000 for a, b in zip(FALSE_ALARMS, FALSE_ALARMS[1:]))
    reps, confirmed = feed(FALSE_ALARMS, max_speed_mps=40.0)
    assert reps == [] and confirmed == set()
    reps, confirmed = feed(FALSE_ALARMS)   # the default, 300 m/s
    assert confirmed and any(r.strength > 0 for r in reps)


def test_a_lone_ground_vehicle_is_tracked_at_ground_speed():
    """A lone target at 10 m/s seen every 5 s is confirmed and reported with max_speed_mps=40."""
    rng = np.random.default_rng(0)
    hits = [(10.0 * (1.0 + 5.0 * k) + rng.normal(0, 25), 500.0 + rng.normal(0, 25)) for k in range(20)]
    reps, confirmed = feed(hits, max_speed_mps=40.0)
    live = [r for r in reps if r.strength > 0]
    assert len(confirmed) == 1 and live and {r.track for r in live} == confirmed
    assert live[0].t <= 21.0 and abs(live[-1].vx - 10.0) < 3.0


# -- 5. orders in random battles ----------------------------------------------------------------
@pytest.fixture(scope="module")
def battles():
    """The first seeds in 1..20 with and without an order, their events."""
    proj = Projection(G.EPSG)
    ox, oy = proj.to_xy(*G.ORIGIN_LONLAT)
    out = {}
    for seed in range(1, 21):
        sim = G.build_sim(small=True, seed=seed, incidents="random")
        key = sim.order is not None
        if key not in out:
            out[key] = (sim, G.events(sim, proj, ox, oy))
        if len(out) == 2:
            return out
    pytest.fail(f"seeds 1..20 have orders only {sorted(out)}")


def test_an_ordered_battle_switches_plans_in_its_events(battles):
    """One order event at the order time; no main-plan confirmation after it; every platoon's withdraw start."""
    sim, ev = battles[True]
    t = sim.order["t"]
    orders = [e for e in ev if e["kind"] == "order" and e["action"] == "execute-plan"]
    assert orders == [{"kind": "order", "t": t, "action": "execute-plan", "plan": "withdrawal", "issuer": "BN"}]
    main = {m["id"] for m in G.plan_doc(sim)["plans"]["main"]}
    missions = [e for e in ev if e["kind"] == "mission"]
    assert missions and not [e for e in missions if e["mission"] in main and e["t"] > t]
    assert any(e["mission"] in main for e in missions)
    assert sorted(sim.withdraw) == sorted(LANE_X)
    for p, (leave, arrive) in sim.withdraw.items():
        assert t < leave < arrive
        starts = [e for e in missions if e["mission"] == f"{p}-withdraw" and e["phase"] == "start"]
        assert [(e["t"], e["unit"]) for e in starts] == [(leave, p)]
        ends = [e["t"] for e in missions if e["mission"] == f"{p}-withdraw" and e["phase"] == "end"]
        assert ends == ([arrive] if arrive < G.DURATION else [])


def test_an_early_order_drops_the_main_plans_later_confirmations(monkeypatch):
    """An order at 3000 s (mid-attack): main-plan confirmations after it never come, earlier ones do."""
    from ea_agent.domains.suo import random_battle

    def draw(sim, rng):
        draw_battle(sim, rng)
        sim.order = {"t": 3000.0, "plan": "withdrawal", "issuer": "BN"}
        sim.withdraw = {p: (3050.0, 3850.0) for p in LANE_X}
    draw_battle = random_battle.draw_battle
    monkeypatch.setattr(random_battle, "draw_battle", draw)
    ordered = G.build_sim(small=True, seed=3, incidents="random")
    monkeypatch.undo()
    plain = G.build_sim(small=True, seed=3, incidents="random")
    assert plain.order is None and any(t > 3000.0 for t, *_ in plain.confirmations)   # seed 3 has no order
    main = {m["id"] for m in G.plan_doc(ordered)["plans"]["main"]}
    before = [c for c in plain.confirmations if c[0] <= 3000.0]
    assert [c for c in ordered.confirmations if c[1] in main] == before
    withdraw = [(t, f"{p}-withdraw", p, ph) for p in LANE_X for t, ph in ((3050.0, "start"), (3850.0, "end"))]
    assert [c for c in ordered.confirmations if c[1] not in main] == sorted(withdraw)


def test_a_battle_without_an_order_has_no_order_nor_withdrawal(battles):
    """No order: no order event, no withdraw confirmation, main plan valid throughout."""
    sim, ev = battles[False]
    assert sim.withdraw == {}
    assert not [e for e in ev if e["kind"] == "order" and e["action"] != "start-mission"
                or "withdraw" in e.get("mission", "")]
    # the only orders: BN's to start M's march (ON-ORDER), as the battle drew them
    assert [(e["t"], e["mission"], e["issuer"]) for e in ev if e["kind"] == "order"] == \
        [(o["t"], o["mission"], o["issuer"]) for o in sim.mission_orders]
    tr = O.Truth(sim, FEATS, G.plan_doc(sim), ["BN"])
    assert set(tr.valid.values()) == {(0.0, math.inf)}
    assert not any(m.endswith("-withdraw") for m in tr.valid)


def test_the_oracle_judges_each_plan_while_it_is_in_force(battles):
    """Main-plan missions valid until the order time, withdrawal missions from it."""
    sim, _ = battles[True]
    plan = G.plan_doc(sim)
    tr = O.Truth(sim, FEATS, plan, ["BN"])
    t = sim.order["t"]
    assert {tr.valid[m["id"]] for m in plan["plans"]["main"]} == {(0.0, t)}
    assert {tr.valid[m["id"]] for m in plan["plans"]["withdrawal"]} == {(t, math.inf)}


def test_platoons_fall_back_to_phase_line_blue_after_leaving(battles):
    """Each platoon keeps its path until it leaves, then moves steadily to WITHDRAW_Y and stays."""
    sim, _ = battles[True]
    for p, (leave, arrive) in sim.withdraw.items():
        ts, ys = sim.platoon_y_path(p)
        y_leave = float(np.interp(leave, ts, ys))
        assert sim.platoon_center(p, leave)[1] == pytest.approx(y_leave)
        assert sim.platoon_center(p, leave - 50.0)[1] == pytest.approx(float(np.interp(leave - 50.0, ts, ys)))
        assert y_leave > WITHDRAW_Y
        walk = [sim.platoon_center(p, t)[1] for t in np.linspace(leave, arrive, 9)]
        assert all(a > b for a, b in zip(walk, walk[1:]))
        assert walk[-1] == pytest.approx(WITHDRAW_Y)
        assert sim.platoon_center(p, arrive + 100.0)[1] == pytest.approx(WITHDRAW_Y)
