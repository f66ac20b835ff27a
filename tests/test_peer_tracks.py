"""A peer hears only the fused tracks inside its interest (cells near its units), an
in-process EA hears every track; both must raise the same alerts. Here one EA takes every
track and another, fed the same reports, only the tracks its own interest (recomputed
every `reregister_s`, as a peer does) lets through: on battalion-sensors their alerts are
equal. Before `ThreatsAhead` looked at a mission only when something it depends on
changed, M's threat-ahead at t=2402 came at 2406 without the far tracks (and so through
the mesh: bench_mesh's battalion-sensors, M)."""
from __future__ import annotations

import json

import pytest

from dissemination.exact import exact
from dissemination.interest import Interest
from dissemination.keyspace import KeySpace
from saim_mesh import scenario as S
from saim_mesh.messages import SensorHit
from saim_mesh.runner import Fusion, config_for, make_ea

from .conftest import ROOT

SENSORS = ROOT / "scenarios" / "battalion-sensors"


@pytest.fixture(scope="module")
def sensors():
    return S.load(SENSORS)


def both(sc, unit: str) -> tuple[list[str], list[str], int]:
    """(alerts with every track, alerts with the tracks of its interest, tracks left out)."""
    ks, cfg = KeySpace.of(sc, "saim"), config_for(sc, unit, None)
    every, near = make_ea(sc, unit, cfg, sinks=[]), make_ea(sc, unit, cfg, sinks=[])
    every.start(0.0)
    near.start(0.0)
    dis = cfg["dissemination"]
    interest = Interest(ks, float(dis["radius_m"]), int(dis["block_share"]))
    every_s = float(dis["reregister_s"])
    fusion, want, next_t, left_out = Fusion.of(sc), None, 0.0, 0

    def track(tr) -> None:
        nonlocal left_out
        every.submit(tr)
        if want(ks.key(tr, sc.taskorg, sc.projection)):
            near.submit(tr)
        else:
            left_out += 1
    for ev in sc.events:
        if ev.t >= next_t:   # re-register on what the EA knows by now
            near.advance(ev.t - 1e-9)
            want, next_t = exact(interest.keys(near.domain), ks.root), next_t + every_s
        for tr in fusion.feed(ev):
            track(tr)
        if type(ev) is not SensorHit:
            every.submit(ev)
            near.submit(ev)
    for tr in fusion.flush(sc.duration_s):
        track(tr)
    every.finish(sc.duration_s)
    near.finish(sc.duration_s)
    return ([json.dumps(a.to_json_dict(), sort_keys=True) for a in every.alerts],
            [json.dumps(a.to_json_dict(), sort_keys=True) for a in near.alerts], left_out)


@pytest.mark.parametrize("unit", ["M", "B", "A1"])
def test_an_ea_that_hears_only_the_tracks_near_it_raises_the_same_alerts(sensors, unit):
    every, near, left_out = both(sensors, unit)
    assert left_out > 0, "every track was inside the interest: the test shows nothing"
    assert every, f"{unit} raised no alert: the test shows nothing"
    assert near == every, [json.loads(x)["t"] for x in sorted(set(near) ^ set(every))]
