"""A live EA holds bounded memory (issue 31.7): frames that wait (out of sequence, or for
room in the event-time order while another source holds the bound back) are kept up to
half of `[mesh] max_held_mb`; beyond that a source's frames are dropped and fetched again
from its journal when there is room, so being behind never loses data. No network: the
journal's queryable is stood in for by the frames themselves."""
from __future__ import annotations

import pytest

from saim_mesh import scenario as S
from saim_mesh.live import play
from saim_mesh.live import peer as P
from saim_mesh.live import sequence as SQ
from saim_mesh.launch.zenoh_config import config

from .conftest import SMALL
from .test_live_rebuild import frames, keyed


class FakeSession:
    def put(self, *a, **k) -> None:
        pass


@pytest.fixture(scope="module")
def sc():
    return S.load(SMALL)


def test_a_peer_far_behind_drops_then_fetches_again_and_loses_nothing(sc, monkeypatch):
    a = frames("src.a", list(play.share(sc, ["A"], False)))
    b = frames("src.b", list(play.share(sc, None, True, ["A"])))
    by_seq = {i + 1: f for i, (_, f) in enumerate(a)}
    asked = []

    class Asker:   # the journal of src.a
        why = "done"

        def ask(self, session, key, epoch, lo, hi, read, budget_s=3.0):
            asked.append((lo, hi))
            return [(by_seq[s], read(by_seq[s])) for s in range(lo, min(hi, len(by_seq)) + 1)]
    monkeypatch.setattr(SQ, "Asker", Asker)

    def peer():
        return P.LivePeer(sc, "BN", config(["tcp/127.0.0.1:0"], None), "t/mem", ["src.a", "src.b"])

    ref = peer()
    for _, i, f in sorted([(t, 0, f) for t, f in a] + [(t, 1, f) for t, f in b], key=lambda x: x[:2]):
        ref.take(f, "")
    ref.ea.finish(ref.end_t())

    p = peer()
    p.session = FakeSession()
    p.max_held = 400_000
    p.order.max_buffered = 800
    peak = 0
    for _, f in a:                    # src.a runs far ahead: src.b has promised nothing yet
        p.receive(f, "")
        peak = max(peak, p.seq.hold.bytes)
    assert p.seq.dropped > 0 and p.seq.behind.get("src.a")
    assert peak <= p.max_held // 2 + max(len(f) for _, f in a)
    assert p.order.buffered() <= p.order.max_buffered
    for _, f in b:                    # src.b catches up; the loop's checks fetch src.a again
        p.receive(f, "")
        p.seq.retry()
        p.seq.refetch_behind()
    for _ in range(50):
        if not p.seq.behind.get("src.a") and not p.seq.hold.waiting_for("src.a"):
            break
        p.seq.retry()
        p.seq.refetch_behind()
    p.ea.finish(p.end_t())
    assert asked and p.seq.fetched >= p.seq.dropped and p.seq.gaps == 0
    assert keyed(p.given) == keyed(ref.given) and len(keyed(ref.given)) >= 5
