"""A peer hears only what its interest lets through (its units' positions, tracks and
reports in cells near them); an in-process EA hears everything. Both must raise the same
alerts. Here one EA takes every message and another only those the live peer's
subscriptions let through: each message in the key group its source publishes it on
(`groupframes.grouper`), heard when the groups of the EA's interest (`bygroup.GroupIntake`,
recomputed every `reregister_s` on the EA's own state, as a peer does) take it in: on
battalion-sensors their alerts are equal.

Before detectors looked at a mission only when what it depends on changed (ThreatsAhead,
Standoffs, Checkpoints, Projections' samples, the places they read), M's threat-ahead at
t=2402 came at 2406 without the far tracks, and so through the mesh (bench_mesh's
battalion-sensors, M)."""
from __future__ import annotations

import json

import pytest

from dissemination.keyspace import KeySpace
from saim_mesh import scenario as S
from saim_mesh.live.bygroup import GroupIntake
from saim_mesh.live.groupframes import grouper, streams_of
from saim_mesh.protocol.messages import SensorHit
from saim_mesh.inprocess.runner import Fusion, config_for, make_ea

from .conftest import ROOT

SENSORS = ROOT / "scenarios" / "battalion-sensors"


@pytest.fixture(scope="module")
def sensors():
    return S.load(SENSORS)


def both(sc, unit: str) -> tuple[list[str], list[str], dict[str, int]]:
    """(alerts hearing everything, alerts hearing what the interest lets through, how many
    tracks and other messages were left out)."""
    ks, cfg = KeySpace.of(sc, "saim"), config_for(sc, unit, None)
    every, near = make_ea(sc, unit, cfg, sinks=[]), make_ea(sc, unit, cfg, sinks=[])
    every.start(0.0)
    near.start(0.0)
    dis = cfg["dissemination"]
    intake = GroupIntake(ks, 1 << 20, None, print, streams=streams_of(sc, ks.root), interest=dis)
    every_s = float(dis["reregister_s"])
    group_of = grouper(sc, ks.root)   # the organization as it is at each message's time: the source keys it so
    fusion, next_t = Fusion.of(sc), 0.0
    left_out = {"tracks": 0, "others": 0}

    def take(msg, what: str) -> None:
        every.submit(msg)
        if intake.hears(group_of(msg)):
            near.submit(msg)
        else:
            left_out[what] += 1
    for ev in sc.events:
        trs = fusion.feed(ev)   # tracks of windows that closed: dated before ev
        if ev.t >= next_t:   # re-register on what the EA knows by now (all before the earliest still to come)
            near.advance(min([ev.t, *(tr.t for tr in trs)]) - 1e-9)
            intake.interest(near.domain)
            next_t += every_s
        for tr in trs:
            take(tr, "tracks")
        if type(ev) is not SensorHit:
            take(ev, "others")
    for tr in fusion.flush(sc.duration_s):
        take(tr, "tracks")
    every.finish(sc.duration_s)
    near.finish(sc.duration_s)
    return ([json.dumps(a.to_json_dict(), sort_keys=True) for a in every.alerts],
            [json.dumps(a.to_json_dict(), sort_keys=True) for a in near.alerts], left_out)


@pytest.mark.parametrize("unit", ["M", "B", "A1", "R"])
def test_an_ea_that_hears_only_its_interest_raises_the_alerts_of_one_that_hears_everything(sensors, unit):
    every, near, left_out = both(sensors, unit)
    assert left_out["tracks"] > 0 and left_out["others"] > 0, f"nothing left out: the test shows nothing {left_out}"
    assert every, f"{unit} raised no alert: the test shows nothing"
    assert near == every, [json.loads(x)["t"] for x in sorted(set(near) ^ set(every))]
