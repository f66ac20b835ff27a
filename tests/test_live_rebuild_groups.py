"""A lost source publishing by key group comes back (issue 50): its return rebuilds the EA
before the returning flush is assembled, so the groups the EA hears of that flush are the
rebuilt EA's interest (an EA that never lost the source), not the one that went on without
it; the alerts shown are the uncut run's, and the input journal replays to the same.
No network: group and progress frames are fed to the peer as its subscribers would."""
from __future__ import annotations

import math
import random
from collections import Counter

import pytest

from dissemination.keyspace import KeySpace
from saim_mesh import scenario as S
from saim_mesh.live import groupframes as GF
from saim_mesh.live import play
from saim_mesh.live.journal import replay
from saim_mesh.live.peer import LivePeer
from saim_mesh.launch.zenoh_config import config
from saim_mesh.protocol import messages as M

from .conftest import SMALL

EP, ROOT, UNIT = 2.0, "t/rebuildg", "A2"


@pytest.fixture(scope="module")
def sc():
    return S.load(SMALL)


def by_group(sc, name: str, msgs: list) -> list[tuple[float, list[tuple[str, bytes]]]]:
    """One flush per epoch of event time, as (watermark, [(key, payload) of its group frames,
    then its progress frame])."""
    group_of, ks = GF.grouper(sc, ROOT), KeySpace.of(sc, ROOT)
    by: dict[float, list] = {}
    for m in sorted(msgs, key=lambda m: m.t):
        by.setdefault(max(1, math.ceil(m.t / EP)) * EP, []).append((M.encode(m), group_of(m)))   # t=0: flush 1
    out, gseq = [], {}
    for k in range(1, int(max(by) / EP) + 2):
        end = k * EP
        got = by.get(end, [])
        gfs, prog, _ = GF.split(name, 1, k, end, [b for b, _ in got], [g for _, g in got], gseq)
        out.append((end, [(f"{ks.src(name)}/{gf.group}", GF.encode(gf)) for gf in gfs]
                    + [(f"{ks.src(name)}/{GF.PROGRESS}", GF.encode(prog))]))
    return out


def peer(sc, out=None) -> LivePeer:
    return LivePeer(sc, UNIT, config(["tcp/127.0.0.1:0"], None), ROOT, ["src.a", "src.b"], str(out) if out else None)


def shown(p: LivePeer) -> list[tuple]:
    return [(a.t, a.type, a.subjects, a.message) for a in p.given
            if a.category != "system-problem" and not a.details.get("inhibited_by")]


@pytest.mark.parametrize("seed", [None, 1, 2])
def test_a_source_by_group_back_after_a_loss_rebuilds_before_its_flush_and_replays(sc, tmp_path, seed):
    """`seed`: the returning source's backlog (its group and progress frames) comes in a
    shuffled order (recovery from several publishers' caches interleaves them), not flush by
    flush: whatever the order, the EA gets to the end with nothing missed."""
    a = by_group(sc, "src.a", list(play.share(sc, ["A"], False)))
    b = by_group(sc, "src.b", list(play.share(sc, None, True, ["A"])))
    merged = sorted([(t, 0, f) for t, f in a] + [(t, 1, f) for t, f in b], key=lambda x: x[:2])

    def feed(p, flush):
        for key, payload in flush:
            p.receive(payload, key)

    ref = peer(sc)
    for _, _, f in merged:
        feed(ref, f)
    ref.ea.finish(ref.end_t())
    want = shown(ref)
    assert want and ref.bygroup.gaps == 0

    cut, heal = 300.0, 900.0
    p = peer(sc, tmp_path / "A2.jsonl")
    for t, i, f in merged:
        if t <= cut:
            feed(p, f)
    p.lose("src.b", "test: link cut")
    for t, i, f in merged:
        if cut < t <= heal and i == 0:
            feed(p, f)
    backlog = [x for t, i, f in merged if t > cut and i == 1 and t <= heal for x in f]
    if seed is not None:
        random.Random(seed).shuffle(backlog)
    feed(p, backlog)                # healed: src.b's backlog, then both
    for t, i, f in merged:
        if t > heal:
            feed(p, f)
    p.ea.finish(p.end_t())
    p.journal.close()

    assert p.order.released == ref.order.released and not p.seq.hold.sources_waiting(), "stood still"
    assert p.rebuilds == 1 and p.bygroup.gaps == 0
    got = shown(p)
    assert not [k for k, n in Counter(got).items() if n > 1], "an alert shown twice"
    assert sorted(got) == sorted(want)

    def strip(alerts):
        return [{**d, "details": {k: v for k, v in d["details"].items() if k != "declared_wall"}}
                for d in (x.to_json_dict() for x in alerts)]
    assert strip(replay(peer(sc), tmp_path / "A2.input")) == strip(p.given)
