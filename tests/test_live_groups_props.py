"""Key groups under random battles (issue 50.1): the small battle with a platoon moved off
its route from some moment, and a platoon resubordinated to another company by a published
reorganization to the battalion; its two command-post sources publish by key group, their
group and progress frames arrive interleaved and shuffled within each flush, and an EA's live
peer (`LivePeer`, as its subscribers would feed it: no network) takes only the groups its
interest hears. Its alerts are, every time, those of the in-process EA that hears every
message. Plan versions are not drawn here (`tests/test_directives.py` sends them live).

Not drawn: a platoon resubordinated to another *company*. That company's EA never heard the
platoon's confirmations before the move (not in its interest then) and tells a late start
the in-process EA, which heard them, does not (docs/architecture.md, "Key groups", limits)."""
from __future__ import annotations

import math
import random
from dataclasses import replace

import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from saim_mesh import scenario as S
from saim_mesh.live import play
from saim_mesh.live.peer import LivePeer
from saim_mesh.launch.zenoh_config import config
from saim_mesh.protocol import messages as M

from .conftest import SMALL
from .test_live import in_process, plan_alerts
from .test_live_rebuild_groups import ROOT, by_group

pytestmark = pytest.mark.timeout(900)
SC = S.load(SMALL)
PLATOONS = ["A1", "A2", "A3", "B1", "B2", "C1", "C3", "R"]
SUPERIORS = ["BN"]   # see the module's docstring: not another company


def moved(msgs: list, platoon: str, t0: float, dx_m: float, dy_m: float) -> list:
    """The platoon's (and its squads') positions from `t0` on, shifted by (dx, dy) metres."""
    to = SC.taskorg
    mine = {e for e, u in to.entity_unit.items() if u == platoon or to.parent.get(u) == platoon}
    out = []
    for m in msgs:
        if type(m) is M.LocationReport and m.entity in mine and m.t >= t0:
            k = 111_320.0 * math.cos(math.radians(m.lat))
            m = replace(m, lon=m.lon + dx_m / k, lat=m.lat + dy_m / 110_540.0)
        out.append(m)
    return out


@settings(max_examples=4, deadline=None, derandomize=True, suppress_health_check=list(HealthCheck),
          phases=(Phase.explicit, Phase.generate))   # a failing battle is told as drawn: shrinking one costs minutes
@given(unit=st.sampled_from(["A2", "A", "B"]), platoon=st.sampled_from(PLATOONS),
       t0=st.floats(300.0, 4000.0), dx=st.floats(-3000.0, 3000.0), dy=st.floats(-3000.0, 3000.0),
       reorg=st.one_of(st.none(), st.tuples(st.sampled_from(PLATOONS), st.sampled_from(SUPERIORS),
                                            st.floats(200.0, 4500.0))),
       seed=st.integers(0, 2**16))
def test_a_live_peer_on_its_key_groups_raises_the_in_process_alerts(unit, platoon, t0, dx, dy, reorg, seed):
    a = moved(list(play.share(SC, ["A"], False)), platoon, t0, dx, dy)
    b = moved(list(play.share(SC, None, True, ["A"])), platoon, t0, dx, dy)
    if reorg is not None and SC.taskorg.parent.get(reorg[0]) != reorg[1]:
        b = sorted([*b, M.Reorganization(round(reorg[2], 1), reorg[0], reorg[1])], key=lambda m: m.t)
    want = plan_alerts(in_process(SC, unit, {"src.a": a, "src.b": b}))

    rnd = random.Random(seed)
    flushes = {"src.a": by_group(SC, "src.a", a), "src.b": by_group(SC, "src.b", b)}
    for fl in flushes.values():
        for _, frames in fl:
            rnd.shuffle(frames)   # a flush's group and progress frames in any order
    peer = LivePeer(SC, unit, config(["tcp/127.0.0.1:0"], None), ROOT, ["src.a", "src.b"], log=lambda *x, **k: None)
    left = {s: list(reversed(fl)) for s, fl in flushes.items()}
    while any(left.values()):   # the two sources' flushes interleaved at random, each in its order
        src = rnd.choice([s for s, fl in left.items() if fl])
        for key, payload in left[src].pop()[1]:
            peer.receive(payload, key)
    peer.ea.finish(peer.end_t())
    assert peer.bygroup.gaps == 0 and peer.order.lost == {}
    assert plan_alerts(peer.given) == want
