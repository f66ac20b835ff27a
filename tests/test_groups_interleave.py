"""A live peer hearing key groups (`LivePeer` with an in-process stand-in for its Zenoh
session): whatever order the progress and group frames of its sources arrive in, and
whenever its subscriptions follow its interest (a group newly subscribed gets the frames its
publisher's cache holds, as an advanced subscriber's history does), it raises exactly the
in-process run's alerts: what it hears of each flush is decided on event time."""
from __future__ import annotations

import math
import random
import time

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from dissemination.exact import _chunks_match
from saim_mesh.protocol import messages as M
from saim_mesh import scenario as S
from saim_mesh.live import groupframes as GF
from saim_mesh.live import play
from saim_mesh.live.peer import LivePeer
from saim_mesh.live.source import GROUP_SPAN_S
from saim_mesh.launch.zenoh_config import config

from .conftest import SMALL
from .test_live import in_process, plan_alerts

ROOT = "t/interleave"
NAMES = ("cp.A", "cp.rest")


@pytest.fixture(scope="module")
def world():
    sc = S.load(SMALL)
    streams = {"cp.A": list(play.share(sc, ["A"], False)), "cp.rest": list(play.share(sc, None, True, ["A"]))}
    wire = {}
    for name, msgs in streams.items():   # flushes of GROUP_SPAN_S, as a grouped source gives them
        group_of, counters, out, k = GF.grouper(sc, ROOT), {}, [], 0
        by: dict[float, list] = {}
        for m in msgs:
            by.setdefault(math.ceil(m.t / GROUP_SPAN_S) * GROUP_SPAN_S, []).append(m)
        ends = sorted(by)
        for i, end in enumerate(ends):
            ms = by[end]
            gfs, prog, _ = GF.split(name, 1, i + 1, end, [M.encode(m) for m in ms], [group_of(m) for m in ms],
                                    counters, end=i == len(ends) - 1)
            out.append((gfs, prog))
        wire[name] = out
    return sc, streams, wire


def run_peer(sc, unit: str, wire, rnd: random.Random) -> list:
    peer = LivePeer(sc, unit, config(["tcp/127.0.0.1:0"], None), ROOT, list(NAMES))
    key = peer.ks.src
    # each source's progress frames in order; its group frames anywhere from a little before to after theirs
    items = []
    for name in peer.sources:
        for i, (gfs, prog) in enumerate(wire[name]):
            items.append((i + rnd.random() * 3 - 1.5, f"{key(name)}/{GF.PROGRESS}", GF.encode(prog), None))
            items += [(i + rnd.random() * 6 - 3, f"{key(name)}/{gf.group}", GF.encode(gf), gf.group) for gf in gfs]
    items.sort(key=lambda x: x[0])
    # progress frames of one source keep their order (the sequencer's own job, tested elsewhere)
    pending = {n: [x for x in items if x[3] is None and x[1].split("/")[-2] == n] for n in peer.sources}
    order, pool, version = [], [], -1
    pi = {n: 0 for n in peer.sources}
    for x in items:
        if x[3] is None:
            n = x[1].split("/")[-2]
            x = pending[n][pi[n]]
            pi[n] += 1
        order.append(x)

    def wanted(group: str) -> bool:
        return "**" in peer.bygroup.want or any(_chunks_match(tuple(e.split("/")), group.split("/"))
                                                 for e in peer.bygroup.want)
    peer.bygroup.interest(peer.ea.domain)
    for _, k, payload, group in order:
        if group is not None and not wanted(group):
            pool.append((k, payload, group))   # not subscribed now: only a later subscription's history brings it
            continue
        peer.receive(payload, k)
        if peer.bygroup.version != version:   # re-declared: the new groups' cached frames come, in any order
            version = peer.bygroup.version
            rnd.shuffle(pool)
            for k2, p2, g2 in [x for x in pool if wanted(x[2])]:
                pool.remove((k2, p2, g2))
                peer.receive(p2, k2)
        peer.seq.checks(time.monotonic())
    for _ in range(1000):   # what waits for the release goes as the release reaches it
        if not peer.seq.hold.sources_waiting():
            break
        peer.seq.checks(time.monotonic())
        if peer.bygroup.version != version:
            version = peer.bygroup.version
            for k2, p2, g2 in [x for x in pool if wanted(x[2])]:
                pool.remove((k2, p2, g2))
                peer.receive(p2, k2)
    assert not peer.seq.hold.sources_waiting() and peer.bygroup.gaps == 0
    peer.ea.finish(sc.duration_s)
    peer.out.close()
    return peer.given


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), unit=st.sampled_from(["A2", "C", "B1"]))
def test_any_arrival_order_and_subscription_timing_gives_the_in_process_alerts(world, seed, unit):
    sc, streams, wire = world
    want = plan_alerts(in_process(sc, unit, streams))
    got = plan_alerts(run_peer(sc, unit, wire, random.Random(seed)))
    assert len(want) >= 3 and got == want
