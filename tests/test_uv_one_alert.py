"""One event, one alert (issue 34 item 4) in the robot team: a handoff of a pursuit is
one story, raised once at the handing robot's EA and at the operator's and updated (not
told again) on accept, while the receiver's EA raises its own; a turn in place holds the
stuck clock back until the turn could have completed, and no longer."""
from ea_agent.core.plan import MissionSpec, Unit
from ea_agent.domains.uv.messages import UvAgent

from .test_uv_alerts import PATROL1, PATROL2, ea, line, of, robot, run, scenario, sg, st, still


# -- a handoff is one story -------------------------------------------------------------------
def policy_then_agents():
    """E1 leaves UGV1's sector SEC1 into SEC2, UGV2's patrol area: the EAs' policy hands
    the pursuit to UGV2 (target-gone, about 5 s); then the robots' own delegate (8 s) and
    accept (8.5 s) of that pursuit, under the robot's own name for its task (as in
    scenarios/uv-team), not the EA's."""
    msgs = still("UGV1", 0, 0, 0, 20) + still("UGV2", 150, 0, 0, 20) \
        + [sg(2 + k / 2, "UGV1", "E1", 60 + 10 * k, 0) for k in range(10)]
    msgs.append(UvAgent(8.0, "UGV1", "UGV2", "delegate", "UGV1-pursue-E1", "E1"))
    msgs.append(UvAgent(8.5, "UGV2", "UGV1", "accept", "UGV1-pursue-E1", "E1"))
    return msgs


def handoff_story(e):
    keys = [k for k in e.voa.history if isinstance(k, tuple) and k[0] == "handoff"]
    assert len(keys) == 1, keys
    return e.voa.history[keys[0]]


def test_one_handoff_one_alert_per_audience_updated_on_accept():
    for owner, act in (("TEAM", "policy"), ("UGV1", "policy"), ("UGV2", "delegate")):
        e = ea(scenario([PATROL1, PATROL2]), owner)
        alerts = run(e, policy_then_agents(), 20)
        hand = of(alerts, "handoff")
        assert len(hand) == 1, (owner, [a.message for a in hand])
        a = hand[0]
        assert (a.details["from"], a.details["to"], a.details["target"], a.details["act"]) == \
            ("UGV1", "UGV2", "E1", act), owner
        assert set(a.subjects) == {"UGV1", "UGV2", "E1"}
        if owner == "UGV2":   # the receiver's own story: its acceptance closes it
            assert a.t == 8.0 and "delegated to us" in a.message
            assert not e.domain.handoffs
            continue
        assert a.t < 8.0 and of(alerts, "target-gone")       # raised once, by the policy
        story = handoff_story(e)
        assert story.t == a.t and story.seen == 8.5, owner   # the accept updated that story
        assert [m.TYPE for m in e.domain.active_of("UGV1")] == ["patrol"], owner
    team = ea(scenario([PATROL1, PATROL2]), "TEAM")
    run(team, policy_then_agents(), 20)
    assert [(m.TYPE, m.params["target"]) for m in team.domain.active_of("UGV2")] == [("pursue", "E1")]


def test_handoff_without_policy_raised_once_on_accept():
    """No policy judgement first (the handing EA did not see the target leave): the
    accept raises the story, once, at the handing robot's EA and the operator's."""
    msgs = still("UGV1", 0, 0, 0, 12) + still("UGV2", 150, 0, 0, 12) \
        + [sg(2 + k / 2, "UGV1", "E1", 30, 0) for k in range(16)] \
        + [UvAgent(6.0, "UGV1", "UGV2", "delegate", "P1/pursue-E1-1", "E1"),
           UvAgent(7.0, "UGV2", "UGV1", "accept", "P1/pursue-E1-1", "E1")]
    shared = MissionSpec("P2", "UGV2", "patrol", params={"area": "SEC2", "sector": "SEC1"})
    for owner, t in (("TEAM", 7.0), ("UGV1", 7.0), ("UGV2", 6.0)):
        hand = of(run(ea(scenario([PATROL1, shared]), owner), msgs, 12), "handoff")
        assert [a.t for a in hand] == [t], (owner, [a.message for a in hand])


def test_each_handoff_is_its_own_story():
    """E1 handed UGV1 -> UGV2, back, and to UGV2 again within the VOA expiry: three
    handoffs, three alerts (an accept ends its story), each told once."""
    shared = MissionSpec("P2", "UGV2", "patrol", params={"area": "SEC2", "sector": "SEC1"})
    msgs = still("UGV1", 0, 0, 0, 40) + still("UGV2", 150, 0, 0, 40) \
        + [sg(2 + k / 2, "UGV1", "E1", 30, 0) for k in range(8)]
    for t, a, b in ((6.0, "UGV1", "UGV2"), (20.0, "UGV2", "UGV1"), (30.0, "UGV1", "UGV2")):
        msgs += [UvAgent(t, a, b, "delegate", f"{a}-pursue-E1", "E1"),
                 UvAgent(t + 1.0, b, a, "accept", f"{a}-pursue-E1", "E1")]
    team = ea(scenario([PATROL1, shared]), "TEAM")
    hand = of(run(team, msgs, 40), "handoff")
    assert [(a.t, a.details["from"], a.details["to"]) for a in hand] == \
        [(7.0, "UGV1", "UGV2"), (21.0, "UGV2", "UGV1"), (31.0, "UGV1", "UGV2")]
    assert not team.domain.handoffs                              # every story closed by its accept
    ugv1 = of(run(ea(scenario([PATROL1, shared]), "UGV1"), msgs, 40), "handoff")
    assert [(a.t, a.details["act"]) for a in ugv1] == [(7.0, "accept"), (20.0, "delegate"), (31.0, "accept")]


# -- a turn in place is not stuck -------------------------------------------------------------------
GOTO1 = MissionSpec("G1", "UGV1", "goto", params={"waypoint": "WP1"})      # WP1 lies due east (90 deg)
SLOW_TURNER = Unit("UGV1", "UGV1", "ugv", "TEAM", attrs={"max_speed_mps": 2.0, "turn_rate_dps": 18.0,
                                                         "sensor_range_m": 60.0, "comm_range_m": 400.0,
                                                         "radius_m": 0.5})


def turn_in_place(r, t0, t1, h0, rate):
    """States of a robot at (0, 0) turning at `rate` deg/s from heading h0, twice a second."""
    return [st(t0 + k / 2, r, 0, 0, 0.0, h0 + rate * k / 2) for k in range(int((t1 - t0) * 2))]


def test_turn_in_place_for_exactly_the_stuck_interval_is_not_stuck():
    """Faces west, turns 180 deg at 18 deg/s in place for 10 s (the stuck interval) to face
    WP1, then drives off slowly, at 0.5 m/s: it has moved more than stuck_m only 2.5 s
    later, after its turn could have completed (180 / 18 + 1 s settle = 11 s)."""
    msgs = turn_in_place("UGV1", 0, 10, 270.0, 18.0) + line("UGV1", 0, 0, 0.5, 0, 10, 30)
    for owner in ("UGV1", "TEAM"):
        e = ea(scenario([GOTO1], [SLOW_TURNER, robot("UGV2")]), owner)
        assert not of(run(e, msgs, 30), "stuck"), owner


def test_turn_in_place_without_a_waypoint_is_not_stuck():
    """A patrolling quadrotor (15 deg/s) hovers and turns half round, 12 s, then flies on:
    no waypoint says how long its turn takes, so half a turn is allowed from where it is."""
    uav = Unit("UAV1", "UAV1", "uav", "TEAM", attrs={"max_speed_mps": 10.0, "turn_rate_dps": 15.0,
                                                      "sensor_range_m": 120.0, "comm_range_m": 800.0,
                                                      "radius_m": 0.5})
    patrol = MissionSpec("PA", "UAV1", "patrol", params={"area": "AREA1"})
    msgs = turn_in_place("UAV1", 0, 12, 0.0, 15.0) + line("UAV1", 0, 0, 0, -5, 12, 30)
    for owner in ("UAV1", "TEAM"):
        assert not of(run(ea(scenario([patrol], [robot("UGV1"), uav]), owner), msgs, 30), "stuck"), owner


def test_really_stuck_robot_still_is():
    """The same turn, then the robot stays put: stuck, stuck_s after its turn could have
    completed (180 / 18 + 1 s settle = 11 s). One that only jitters its heading in place,
    or never stops turning, is stuck too."""
    msgs = turn_in_place("UGV1", 0, 10, 270.0, 18.0) + still("UGV1", 0, 0, 10, 40, h=90)
    for owner in ("UGV1", "TEAM"):
        stuck = of(run(ea(scenario([GOTO1], [SLOW_TURNER, robot("UGV2")]), owner), msgs, 40), "stuck")
        assert stuck and 21.0 <= stuck[0].t <= 22.0 and stuck[0].details["still_s"] >= 10.0, owner
    jitter = [st(k / 2, "UGV1", 0, 0, 0.0, 90.0 + (5.0 if k % 2 else -5.0)) for k in range(50)]
    stuck = of(run(ea(scenario([GOTO1])), jitter, 25), "stuck")
    assert stuck and 10.0 <= stuck[0].t <= 11.5
    spinning = turn_in_place("UGV1", 0, 60, 270.0, 18.0)       # turns round and round, never moves
    stuck = of(run(ea(scenario([GOTO1], [SLOW_TURNER, robot("UGV2")])), spinning, 60), "stuck")
    assert stuck and stuck[0].t <= 10.0 + 180.0 / 18.0 + 1.0 + 10.0 + 5.0


def test_the_shipped_uv_team_tells_each_handoff_once_per_audience():
    """scenarios/uv-team (issue 34's done-when): each handoff is one alert at each EA that
    tells it (the handing robot's and the operator's at the policy's word, the receiver's
    on the delegate), never a second one on the accept."""
    from collections import Counter

    from saim_mesh import scenario as S
    from saim_mesh.inprocess.runner import run as run_all

    from .conftest import ROOT
    sc = S.load(ROOT / "scenarios" / "uv-team")
    told = Counter((ea.owner, a.details["from"], a.details["to"], a.details["target"])
                   for ea in run_all(sc, list(sc.taskorg.units)) for a in ea.alerts if a.type == "handoff")
    assert told and set(told.values()) == {1}, told
    ev1 = {owner for owner, frm, to, target in told if (frm, to, target) == ("UGV1", "UGV2", "EV1")}
    assert ev1 == {"TEAM", "UGV1", "UGV2"}, told
