"""An EA's snapshot (ea_agent/core/snapshot.py) goes on as the EA itself would: what a
rebuilt live peer starts from when a lost source returns."""
from __future__ import annotations

import threading

import pytest

from ea_agent.core.snapshot import snapshot
from saim_mesh import scenario as S
from saim_mesh.inprocess.runner import config_for, make_ea

from .conftest import SMALL


@pytest.mark.parametrize("unit", ["BN", "A", "A1", "B2"])
def test_a_snapshot_taken_mid_battle_raises_what_the_ea_raises_from_there(unit):
    sc = S.load(SMALL)
    got: tuple[list, list] = ([], [])
    ea = make_ea(sc, unit, config_for(sc, unit), sinks=[lambda a: got[0].append(a.to_json_dict())])
    ea.start(0.0)
    half = len(sc.events) // 2
    for ev in sc.events[:half]:
        ea.submit(ev)
        if ev.t >= ea.epoch_end:
            ea.advance(ev.t)
    copy = snapshot(ea, share=[sc])
    copy.sinks[:] = [lambda a: got[1].append(a.to_json_dict())]
    before = len(got[0])
    for ev in sc.events[half:]:
        for e in (ea, copy):
            e.submit(ev)
            if ev.t >= e.epoch_end:
                e.advance(ev.t)
    for e in (ea, copy):
        e.finish(sc.duration_s)
    assert got[1] and got[0][before:] == got[1]


def test_closures_are_copied_with_their_cells_and_shared_objects_are_not():
    shared = object()
    box = {"n": 0, "shared": shared}

    def bump():
        box["n"] += 1
    a = {"f": bump, "s": shared}
    b = snapshot(a, share=[shared])
    b["f"]()
    assert box["n"] == 0 and b["s"] is shared
    assert b["f"].__closure__[0].cell_contents["shared"] is shared


def test_state_that_cannot_be_copied_raises_type_error():
    with pytest.raises(TypeError):
        snapshot({"lock": threading.Lock()})
