"""A peer's intake without processes: a batch's entries are taken exactly as the same
reports one by one (the batch path is the per-report loop unrolled), and the interest
is only recomputed when the cells it covers change, giving the keys a fresh one would."""
from __future__ import annotations

import queue
import random
import time
from dataclasses import replace
from pathlib import Path

import pytest

from dissemination.exact import exact
from dissemination.interest import Interest
from ea_agent.core.needs import Needs
from saim_mesh import messages as M
from saim_mesh import scenario as S
from saim_mesh.peer import Peer
from saim_mesh.replay import Replay
from saim_mesh.zconf import config

ROOT = "saim/intake"
SMALL = Path(__file__).resolve().parents[1] / "scenarios" / "small"


@pytest.fixture(scope="module")
def sc():
    return S.load(SMALL)


@pytest.fixture(scope="module")
def script(sc):
    rp = Replay(sc, config(["tcp/127.0.0.1:0"], None, sc=sc, root=ROOT), ROOT, log=lambda *a, **k: None)
    return [(i + 1, k, p, ev) for i, (ev, k, p, _) in enumerate(rp._prepare(sc.duration_s))
            if type(ev) is M.LocationReport]


def _peer(sc, wanted: set[str]) -> Peer:
    p = Peer(sc, "A", config(["tcp/127.0.0.1:0"], None, sc=sc, root=ROOT), ROOT, log=lambda *a, **k: None)
    p.want = exact(wanted, ROOT)
    p.tick_seq, p.clock_t = 400, 200.0
    p.last_seq = 5
    return p


def _entries(script) -> list[tuple[int, str, bytes]]:
    """Good reports and every kind of bad one a batch may carry, in seq order."""
    rows = [(seq, k, p) for seq, k, p, _ in script[:300]]
    (s1, k1, p1, e1), (s2, k2, _, e2) = script[40], script[41]
    bad = [
        (s1, k1, p1),                                                    # the same seq again: a duplicate
        (s1 + 1000, k1, M.encode(replace(e1, t=e1.t + 0.5))),            # ahead of the clock's seq: held
        (s2, k2, M.encode(replace(e2, lon=e2.lon + 0.001))),             # a seq already held, other bytes: contested
        (3, k1, p1),                                                     # already fed
        (301_000, k1, p1),                                                # too far ahead of the clock's seq
        (390, k1, M.encode(replace(e1, t=999.0))),                       # dated far ahead of the clock: deferred
        (391, k2, p1),                                                   # another entity's report on this key
        (392, k1, b"\xc1junk"),                                          # undecodable
        (393, k1.replace("/pos/", "/pos/x/"), p1),                       # not wanted
    ]
    rows = [r for r in rows if r[0] <= 380] + bad
    rows.sort(key=lambda r: r[0])
    return rows


def test_a_batch_is_taken_exactly_as_its_reports_one_by_one(sc, script):
    entries = _entries(script)
    wanted = {k for _, k, _ in entries if "/pos/x/" not in k}
    one, many = _peer(sc, wanted), _peer(sc, wanted)
    buf_one: list = []
    for seq, k, p in entries:
        one._take(seq, k, p, buf_one)
    buf_many: list = []
    many._take_entries(entries, buf_many)
    assert sorted(buf_one, key=lambda x: x[0]) == sorted(buf_many, key=lambda x: x[0])
    assert len(buf_many) > 250
    assert dict(one.pending) == dict(many.pending) and one.pending.bytes == many.pending.bytes
    assert one.contested == many.contested and len(many.contested) == 1
    assert one.flow["dropped"] == many.flow["dropped"] == 1
    assert one.gate.rejects.by_kind == many.gate.rejects.by_kind
    assert sum(many.gate.rejects.by_kind.values()) == 3   # far seq, foreign key, junk
    assert one.flow["deferred"] == many.flow["deferred"] == 1 and one.defer_t == many.defer_t == 999.0
    assert one.seen_t == many.seen_t > 0


def test_held_bytes_stay_bounded_on_the_batch_path(sc, script):
    entries = [(seq, k, p) for seq, k, p, _ in script[:300] if seq <= 380]
    p = _peer(sc, {k for _, k, _ in entries})
    p.tick_seq = 60
    p.max_held = 2000   # a few reports' worth: those not yet due are evicted, to come back from the store
    buf: list = []
    p._take_entries(entries, buf)
    due = sum(len(x) for q, _, x in entries if 5 < q <= 60)
    assert p.evicted and p.pending.bytes <= due + 2000 + max(len(x) for _, _, x in entries)
    assert {q for q, _ in buf} == set(p.pending) and all(q in p.pending for q, _, _ in entries if 5 < q <= 60)


def _needs(rng: random.Random, centres: list[tuple[float, float]]) -> Needs:
    return Needs(("pos/{place}/{path:entity}/{entity}", "trk/{place}/{track}", "ord/{issuer}"),
                 by={"issuer": frozenset({"A", "BN"}), "path": frozenset({"BN/A"})},
                 circles=tuple((x, y, 3000.0) for x, y in centres),
                 boxes=((500_000.0, 3_900_000.0, 504_000.0 + rng.choice((0.0, 2500.0)), 3_903_000.0),))


def test_the_interest_memo_gives_what_a_fresh_computation_gives(sc):
    from dissemination.keyspace import KeySpace
    ks = KeySpace(ROOT)
    rng = random.Random(7)
    memo = Interest(ks, 3000.0, 10)
    centres = [(510_000.0 + 900 * i, 3_910_000.0 + 700 * i) for i in range(6)]
    hits = 0
    for _ in range(200):
        # most steps move units a few metres (same cells), some across a cell edge
        step = 30.0 if rng.random() < 0.8 else 1500.0
        centres = [(x + rng.uniform(-step, step), y + rng.uniform(-step, step)) for x, y in centres]
        n = _needs(rng, centres)
        before = memo._last
        got = memo.cached(n)
        hits += memo._last is before
        assert got == Interest(ks, 3000.0, 10).of(n)
    assert 50 < hits < 200   # the memo served some, and moves across cells were recomputed


def test_eviction_on_the_batch_path_matches_one_by_one(sc, script):
    entries = [(seq, k, p) for seq, k, p, _ in script[:300] if seq <= 380]
    entries.insert(10, (entries[9][0], entries[9][1], b""))   # an empty payload on a held seq: contested
    peers = [_peer(sc, {k for _, k, _ in entries}) for _ in range(2)]
    bufs: list[list] = [[], []]
    for p in peers:
        p.tick_seq, p.max_held = 60, 2000
    for seq, k, x in entries:
        peers[0]._take(seq, k, x, bufs[0])
    peers[1]._take_entries(entries, bufs[1])
    one, many = peers
    assert sorted(bufs[0], key=lambda x: x[0]) == sorted(bufs[1], key=lambda x: x[0])
    assert dict(one.pending) == dict(many.pending) and one.pending.bytes == many.pending.bytes
    assert one.evicted and many.evicted and one.contested == many.contested
    assert one.gate.rejects.by_kind == many.gate.rejects.by_kind


# -- the clock: a queue filled by Zenoh's thread -------------------------------------------
class _Clock:
    """The peer's clock queue (payloads; None when a command woke it), fed by the test, or
    by `feed` when it runs dry; `get` returns at once where the real one would wait."""

    def __init__(self, feed=None):
        self.q: list[bytes | None] = []
        self.feed = feed

    def get(self, timeout: float):
        if not self.q and self.feed is not None:
            self.feed(self)
        if not self.q:
            time.sleep(min(timeout, 0.05))   # the real queue blocks for `timeout`: a shorter wait, same outcome
            raise queue.Empty
        return self.q.pop(0)

    def get_nowait(self):
        if not self.q:
            raise queue.Empty
        return self.q.pop(0)


class _NoPresence:
    def take(self) -> None:
        pass


def _tick(n: int, seq: int, **kw) -> bytes:
    from saim_mesh import wire as W
    return W.encode(W.make(W.Tick, t=2.0 * n, n=n, seq=seq, **kw))


def _clock_peer(sc) -> Peer:
    p = _peer(sc, set())
    p.presence = _NoPresence()
    p.tick_n, p.t, p.clock_t, p.tick_seq = None, 0.0, 0.0, 0
    return p


def test_the_clock_channel_gives_every_whole_tick_in_order(sc):
    p = _clock_peer(sc)
    ch = _Clock()
    ch.q = [_tick(1, 10), None, _tick(2, 20), b"junk", _tick(3, 30, src="r-A", of=2), _tick(3, 31, src="r-B", of=2)]
    got = p._next_ticks(ch)
    assert [(t.n, t.seq) for t in got] == [(1, 10), (2, 20), (3, 31)]
    assert p.tick_seq == 31 and p.clock_t == 6.0
    assert p.gate.rejects.by_kind.get("tick") == 1   # the junk, counted


def test_a_silent_clock_is_an_alert_then_an_exit_and_commands_are_taken_while_waiting(sc):
    from saim_mesh.peer import SourceLost
    p = _clock_peer(sc)
    p.silence_s, p.deadline_s = 0.3, 0.8
    taken = []
    p._commands = lambda: taken.append(p.cmdq.get_nowait())
    p.cmdq.put(("k", b"cmd"))
    with pytest.raises(SourceLost):
        p._next_ticks(_Clock())
    assert taken == [("k", b"cmd")]
    assert [a.details.get("event") for a in p.ea.alerts] == ["source-silent"]


def test_a_partial_tick_waits_for_its_other_source_and_names_the_one_that_came(sc):
    p = _clock_peer(sc)
    p.silence_s, p.deadline_s = 0.3, 5.0
    sent = []

    def feed(ch):   # the other source's part of tick 1 comes after the silence alert
        if p.ea.alerts and not sent:
            sent.append(1)
            ch.q.append(_tick(1, 11, src="r-B", of=2))
    ch = _Clock(feed)
    ch.q = [_tick(1, 10, src="r-A", of=2)]
    got = p._next_ticks(ch)
    assert [(t.n, t.src) for t in got] == [(1, "r-B")]
    texts = [a.message for a in p.ea.alerts]
    assert "not moving" in texts[0] and "came only from r-A" in texts[0] and "clock is back" in texts[1]


def test_a_replaced_plan_changes_the_signature_even_with_the_same_states(sc):
    p = _peer(sc, set())
    dom = p.ea.domain
    p.ea.start(0.0)
    name = dom.initial_plan
    before = p._plan_signature()
    for _ in range(20):   # the same plan again: a new state object, often at the freed one's address
        dom.execute_plan(name, 0.0)
        now = p._plan_signature()
        assert now != before
        before = now
    dom.plan.state[next(iter(dom.plan.state))] = "ready"
    assert p._plan_signature() != before


def test_the_peer_can_give_freed_heap_back_to_the_system():
    """glibc's malloc_trim is found here (every 60 scenario seconds, the peer calls it:
    a brigade EA's peak PSS was ~11 MB lower with it)."""
    from saim_mesh.peer import _malloc_trim
    trim = _malloc_trim()
    assert trim is not None and trim(0) in (0, 1)


def test_data_far_ahead_of_a_peer_that_fell_behind_is_fetched_when_due_never_lost(sc, script, monkeypatch):
    """Issue 31, 7: a peer more than `max_ahead_s` behind (stalled at a high replay speed)
    rejected real data as "too far ahead of the clock" and never got it back (a fusion node
    killed at speed 100: 731 real messages lost). Now it is deferred: not held (memory stays
    bounded), and fetched from the store once the clock comes within reach, exactly once."""
    from saim_mesh import wire as W
    entries = [(seq, k, p) for seq, k, p, ev in script if ev.t > 200.0 + 600.0][:50]
    assert len(entries) == 50
    p = _peer(sc, {k for _, k, _ in entries})
    p.tick_seq = entries[0][0]
    buf: list = []
    p._take_entries(entries, buf)
    assert not buf and not p.pending and p.pending.bytes == 0          # nothing held
    assert p.flow["deferred"] == len(entries) and not p.gate.rejects.by_kind   # nothing rejected either
    first_t = min(M.decode(x).t for _, _, x in entries)
    assert p.defer_t == first_t
    asked = []
    monkeypatch.setattr(p, "_catch_up", lambda keys, buf, tracks_after=-1.0: asked.append((keys, tracks_after)))
    p.ea.start(0.0)
    p.presence = type("P", (), {"take": lambda self: None})()

    def tick(t):
        p.clock_t = t
        p._on_tick(W.make(W.Tick, t=t, n=int(t / 2), seq=p.tick_seq), [])
    tick(first_t - 600.0 - 2.0)   # still out of reach: nothing asked
    assert asked == []
    tick(first_t - 600.0)         # within max_ahead_s of the earliest deferred time: fetched, once
    assert len(asked) == 1 and asked[0][1] == 200.0 and p.defer_t == float("inf")
    tick(first_t - 598.0)
    assert len(asked) == 1
