"""A source's missing frames beyond the publisher's cache come from its journal; a gap is
said with why the journal did not fill it (issue 32: after a heal, the deployment's EAs
logged hundreds of gaps whose journals never answered). Nobody answering is asked again a
few times (`NO_ANSWER_PATIENCE`), not for ever: the route to a journal vanishes for a second
when a router link flaps after a heal (bench_hosts: BDE's asks for cp.1BN's frames came back
at once, empty, and 150 frames became a gap), while waiting without end stood the EA still.
A fake session stands in for Zenoh (no sleeping: `drain(force=True)` is what the loop's
check calls after `GAP_WAIT_S`)."""
from __future__ import annotations

from types import SimpleNamespace

import msgspec

from dissemination.keyspace import KeySpace
from saim_mesh.live import frames as F
from saim_mesh.live.sequence import NO_ANSWER_PATIENCE, Sequencer
from saim_mesh.live.srcjournal import JournalQuery


def frame(seq: int) -> bytes:
    return F.encode(F.Frame(v=1, source="cp.a", epoch=1, seq=seq, wm=float(seq), msgs=[]))


class Session:
    """A `get` that finds no queryable (returns at once, no reply) until `answering`, then
    serves frame 2 as the source's journal does."""

    def __init__(self):
        self.answering, self.gets = False, 0

    def get(self, key, payload=None, timeout=None, consolidation=None):
        self.gets += 1
        if not self.answering:
            return []
        q = msgspec.msgpack.decode(payload, type=JournalQuery)
        ok = SimpleNamespace(payload=SimpleNamespace(to_bytes=lambda: frame(2)))
        return [SimpleNamespace(ok=ok, err=None)] if q.lo <= 2 <= q.hi else []


def sequencer(session):
    taken, said = [], []
    read = lambda b, key: F.decode(b, 1 << 20)   # noqa: E731

    def take(payload, key, f=None, retrying=False):
        taken.append(f.seq)
        return True
    seq = Sequencer(take, read, KeySpace("t"), lambda *a, **k: said.append(a[0]), lambda: 1 << 30,
                    room=lambda: True, session=lambda: session)
    for s in (1, 3, 4):
        b = frame(s)
        seq.arrive(b, "t/src/cp.a", read(b, ""))
    return seq, taken, said


def test_a_journal_nobody_answers_is_asked_a_few_times_then_a_gap_said_with_why():
    session = Session()
    seq, taken, said = sequencer(session)
    assert taken == [1]                       # 3 and 4 wait for 2
    for n in range(NO_ANSWER_PATIENCE):
        seq.drain("cp.a", force=True)
        assert taken == [1] and seq.gaps == 0 and session.gets == 3 * (n + 1)   # three tries each, nobody there
    seq.drain("cp.a", force=True)
    assert taken == [1, 3, 4] and seq.gaps == 1
    assert any(f"frames 2..2 never came (its journal: no answer, asked {NO_ANSWER_PATIENCE + 1} times)" in x
               for x in said), said


def test_a_journal_back_after_a_flap_fills_the_hole():
    """The route to the journal is gone at the first ask (a router link re-forming) and back
    at the next: the missing frame comes from it, no gap."""
    session = Session()
    seq, taken, said = sequencer(session)
    seq.drain("cp.a", force=True)
    assert taken == [1] and seq.gaps == 0
    session.answering = True
    seq.drain("cp.a", force=True)
    assert taken == [1, 2, 3, 4] and seq.gaps == 0 and seq.fetched == 1, said
    assert not any("never came" in x for x in said), said


def test_a_journal_that_answers_fills_the_hole():
    session = Session()
    session.answering = True
    seq, taken, said = sequencer(session)
    seq.drain("cp.a", force=True)
    assert taken == [1, 2, 3, 4] and seq.gaps == 0 and seq.fetched == 1, said
