"""The Kalman tracker (saim_mesh/fusion/tracker.py) on what the window averager could not
track: a lone vehicle, a 250 m/s target, two vehicles whose paths cross; reports carry
the time they describe and the velocity; bad parameters are refused by name."""
from __future__ import annotations

import math

import numpy as np
import pytest

from saim_mesh import scenario as S
from saim_mesh.fusion.kalman_node import KalmanNode
from saim_mesh.fusion.node import FusionNode
from saim_mesh.fusion.tracker import KalmanTracker
from saim_mesh.protocol.messages import SensorHit, SensorTrack

from .conftest import SMALL


def run(paths, sigma=25.0, pd=1.0, period=5.0, duration=300.0, seed=0, fa=0.0, **kw):
    """Feed one sensor's scans of true paths (callables t -> (x, y)); returns (tracker, reports)."""
    rng = np.random.default_rng(seed)
    tr = KalmanTracker("T", sigma, **kw)
    reports, t, end = [], 1.0, period
    while t < duration:
        while t >= end:
            reports += tr.close_window(end)
            end += period
        z = [np.add(p(t), rng.normal(0, sigma, 2)) for p in paths if rng.random() < pd]
        z += [rng.uniform(-5000, 5000, 2) for _ in range(rng.poisson(fa))]
        tr.scan(t, "s", np.array(z).reshape(-1, 2))
        t += period
    return tr, reports


def err(reports, truth):
    return [math.hypot(r.x - truth(r.t)[0], r.y - truth(r.t)[1]) for r in reports if r.strength > 0]


def test_a_lone_vehicle_is_one_confirmed_track_with_its_velocity():
    truth = lambda t: (5.0 * t, 1000.0)   # noqa: E731
    tr, reps = run([truth], pd=0.85, fa=0.3, seed=1)
    mine = [r for r in reps if r.strength > 0 and abs(r.y - 1000) < 300]
    assert mine and len({r.track for r in mine}) == 1
    assert mine[0].t <= 25.0   # confirmed within a few scans
    assert float(np.sqrt(np.mean(np.square(err(mine, truth))))) < 30.0   # raw hits: 35 m radial RMS
    vx, vy = np.mean([r.vx for r in mine[5:]]), np.mean([r.vy for r in mine[5:]])
    assert abs(vx - 5.0) < 0.7 and abs(vy) < 0.7
    assert all((r.t - 1.0) % 5.0 == 0 for r in mine)   # stamped at the scan it describes, not the window end


@pytest.mark.parametrize("speed", [100.0, 250.0, 300.0])
def test_a_fast_mover_keeps_one_track(speed):
    truth = lambda t: (speed * t, 0.3 * speed * t)   # noqa: E731
    _, reps = run([truth], sigma=50.0, duration=200.0, dr_m=None)   # every update reported
    live = [r for r in reps if r.strength > 0]
    assert len({r.track for r in live}) == 1 and len(live) >= 30
    assert max(err(live[3:], truth)) < 150.0
    assert abs(math.hypot(live[-1].vx, live[-1].vy) - speed * math.hypot(1, 0.3)) < 10.0


def test_crossing_vehicles_keep_their_identities():
    a = lambda t: (10.0 * t, 10.0 * t)            # noqa: E731
    b = lambda t: (10.0 * t, 3000.0 - 10.0 * t)   # noqa: E731   cross at t = 150 s
    _, reps = run([a, b], duration=300.0)
    live = [r for r in reps if r.strength > 0]
    owner = {}
    for r in live:
        near = "a" if math.hypot(r.x - a(r.t)[0], r.y - a(r.t)[1]) < math.hypot(r.x - b(r.t)[0], r.y - b(r.t)[1]) else "b"
        if abs(r.t - 150.0) > 30.0:   # away from the crossing: each track follows one vehicle
            owner.setdefault(r.track, set()).add(near)
    assert len(owner) == 2 and all(len(v) == 1 for v in owner.values()), owner
    assert {next(iter(v)) for v in owner.values()} == {"a", "b"}


def test_a_group_is_one_track_with_its_strength():
    offs = [(0, 0), (40, -30), (-50, 20), (20, 55)]
    paths = [lambda t, o=o: (4.0 * t + o[0], 2000.0 + o[1]) for o in offs]
    _, reps = run(paths, duration=200.0)
    live = [r for r in reps if r.strength > 0]
    assert len({r.track for r in live}) == 1 and max(r.strength for r in live) == 4


def test_false_alarms_alone_confirm_nothing():
    _, reps = run([], fa=0.5, duration=600.0, seed=3)
    assert len({r.track for r in reps}) <= 1   # 60 false alarms in 10 km x 10 km


def test_bad_parameters_are_refused_by_name():
    with pytest.raises(ValueError, match="sensor 'X': position sigma must be finite"):
        KalmanTracker("T", {"X": float("nan")}).scan(1.0, "X", np.zeros((1, 2)))
    with pytest.raises(ValueError, match="M-of-N"):
        KalmanTracker("T", m=4, n=3)
    with pytest.raises(ValueError, match="process noise"):
        KalmanTracker("T", q=float("inf"))


def test_the_node_tracks_a_lone_vehicle_the_window_averager_never_reports():
    """1 vehicle at 5 m/s seen by one sensor: the Kalman node reports it (time of the
    scan, heading, speed); the window node confirms nothing (it needs 2 hits per sensor)."""
    sc = S.load(SMALL, events=False)
    ox, oy = sc.projection.to_xy(*sc.projection.to_lonlat(0.0, 0.0))
    x0, y0 = sc.projection.to_xy(-116.56, 35.30)
    rng = np.random.default_rng(4)
    hits = []
    for k in range(60):
        t = 2.0 + 5.0 * k
        x, y = x0 + 5.0 * t + rng.normal(0, 20), y0 + rng.normal(0, 20)
        lon, lat = sc.projection.to_lonlat(x, y)
        hits.append(SensorHit(t, "G1", float(lon), float(lat)))
    kal, win = KalmanNode("N", sc.projection, {"G1": 20.0}, dr_m=None), FusionNode("N", sc.projection)
    got = {"kal": [], "win": []}
    for h in hits:
        got["kal"] += kal.add(h)
        got["win"] += win.add(h)
    got["kal"] += kal.flush(400.0)
    got["win"] += win.flush(400.0)
    assert got["win"] == []
    live = [r for r in got["kal"] if r.strength > 0]
    assert len(live) >= 50 and len({r.track for r in live}) == 1
    assert all((r.at - 2.0) % 5.0 == 0 and r.at <= r.t and r.t % 5.0 == 0 for r in live)   # described / issued
    assert abs(np.mean([r.speed for r in live[10:]]) - 5.0) < 1.0
    assert abs(np.mean([r.heading for r in live[10:]]) - 90.0) < 10.0


def test_the_scenario_chooses_the_tracker():
    """`fusion.tracker` in scenario.json: the runner and the fusion peer build the same
    kind of node (make_node); an unknown tracker is refused by name."""
    from saim_mesh.fusion import make_node
    sc = S.load(SMALL.parent / "small-sensors", events=False)
    node = make_node(sc, "N")   # the default
    assert type(node) is KalmanNode and node.tracker.sigma_of("UAV1") == 40.0
    sc.meta["fusion"] = {**sc.meta["fusion"], "tracker": "window"}
    assert type(make_node(sc, "N")) is FusionNode
    sc.meta["fusion"]["tracker"] = "magic"
    with pytest.raises(ValueError, match="fusion.tracker 'magic' is not one of window, kalman"):
        make_node(sc, "N")


def test_an_aircraft_is_an_air_track_and_no_ground_threat():
    """A slow aircraft at 2,100 m (7,000 ft) over a company: an air track (by height), and
    the SUO picture keeps no hostile for it; a fast one with no height is air by speed."""
    from ea_agent.domains.suo.picture import Picture
    sc = S.load(SMALL, events=False)
    x0, y0 = sc.projection.to_xy(-116.58, 35.29)
    node = KalmanNode("N", sc.projection, {"G1": 20.0})
    reps = []
    for k in range(40):
        t = 1.0 + 5.0 * k
        lon, lat = sc.projection.to_lonlat(x0 + 40.0 * t, y0)
        reps += node.add(SensorHit(t, "G1", float(lon), float(lat), 2100.0 + (k % 3)))
    reps += node.flush(300.0)
    live = [r for r in reps if r.strength > 0]
    assert live and {r.domain for r in live} == {"air"} and abs(live[-1].alt - 2101.0) < 5
    pic = Picture(sc.taskorg, sc.projection)
    pic.apply_tracks(live)
    assert pic.tracks == {}
    ground = [SensorTrack(r.t, r.track, r.lon, r.lat, r.strength, r.heading, r.speed, r.source) for r in live]
    pic.apply_tracks(ground)
    assert len(pic.tracks) == 1                        # the same reports on the ground: a hostile
    _, fast = run([lambda t: (200.0 * t, 0.0)], sigma=50.0, duration=100.0)
    assert {r.domain for r in fast if r.strength > 0} == {"air"}
    _, slow = run([lambda t: (8.0 * t, 0.0)], duration=100.0)
    assert {r.domain for r in slow if r.strength > 0} == {"ground"}
    assert SensorTrack.from_dict({"t": 1, "track": "k", "lon": 1, "lat": 2, "strength": 1, "domain": "air",
                                  "alt": 2100}).domain == "air"
    with pytest.raises(ValueError, match="field 'domain'"):
        SensorTrack.from_dict({"t": 1, "track": "k", "lon": 1, "lat": 2, "strength": 1, "domain": "space"})
    with pytest.raises(ValueError, match="field 'alt'"):
        SensorHit.from_dict({"t": 1, "sensor": "G1", "lon": 1, "lat": 2, "alt": float("nan")})


def test_dead_reckoning_sends_few_reports_and_keeps_the_receivers_close():
    """A vehicle at 10 m/s that turns once: with dead reckoning (here at 50 m, twice the
    track's own position sigma, no motion allowance, a 30 s heartbeat) the receivers get a
    report only when their extrapolation of the last one errs by more than that, yet at
    every scan their extrapolation stays within 50 m of the estimate."""
    def truth(t):
        return (10.0 * t, 0.0) if t < 150 else (1500.0, 10.0 * (t - 150))
    strict = {"dr_k": 2.0, "dr_lag_s": 0.0, "heartbeat_s": 30.0}
    every = [r for r in run([truth], duration=300.0, dr_m=None)[1] if r.strength > 0]
    few = [r for r in run([truth], duration=300.0, **strict)[1] if r.strength > 0]
    assert len(few) * 3 <= len(every) and len({r.track for r in few}) == 1
    assert any(abs(r.t - 150) <= 20 for r in few)               # the turn is told at once
    assert max(b.t - a.t for a, b in zip(few, few[1:])) <= 30.0  # heartbeat
    for r in every:   # what a receiver extrapolates at each update's time, against the estimate then
        last = max((x for x in few if x.t <= r.t), key=lambda x: x.t)
        dx, dy = last.x + last.vx * (r.t - last.t) - r.x, last.y + last.vy * (r.t - last.t) - r.y
        assert math.hypot(dx, dy) <= 50.0 + 1e-6, (r.t, last.t)


def test_default_dead_reckoning_waits_for_the_heartbeat_the_receivers_can_bridge():
    """Defaults: a straight 10 m/s vehicle is reported at least every 60 s (the EAs
    extrapolate for up to 60 s) and less often than with a 30 s heartbeat."""
    def truth(t):
        return (10.0 * t, 0.0)
    dflt = [r for r in run([truth], duration=600.0)[1] if r.strength > 0]
    short = [r for r in run([truth], duration=600.0, heartbeat_s=30.0)[1] if r.strength > 0]
    assert max(b.t - a.t for a, b in zip(dflt, dflt[1:])) <= 60.0
    assert len(dflt) < len(short)


def test_a_halted_vehicle_is_reported_without_velocity():
    """A velocity within the track's own noise is sent as zero, so receivers do not drift
    a halted vehicle; a moving one is sent with its velocity."""
    _, still = run([lambda t: (500.0, 500.0)], duration=300.0, dr_m=None)
    _, moving = run([lambda t: (10.0 * t, 0.0)], duration=300.0, dr_m=None)
    still = [r for r in still if r.strength > 0]
    moving = [r for r in moving if r.strength > 0 and r.t > 60]
    assert still and all(r.vx == 0.0 and r.vy == 0.0 for r in still[3:])
    assert moving and all(abs(math.hypot(r.vx, r.vy) - 10.0) < 3.0 for r in moving)


def test_an_error_of_two_seconds_of_flight_is_no_news():
    """A 250 m/s aircraft flying straight: its reports' small velocity errors grow past
    50 m within a scan or two; allowing 2 s of its motion cuts the reports it needs."""
    def truth(t):
        return (250.0 * t, 0.0)
    lag = [r for r in run([truth], sigma=60.0, duration=300.0)[1] if r.strength > 0]
    none = [r for r in run([truth], sigma=60.0, duration=300.0, dr_lag_s=0.0)[1] if r.strength > 0]
    assert len({r.track for r in lag}) == 1 and len(lag) < len(none)
