"""A source's durable journal (issue 31.1): what it published, served on srcj/<name> for
catch-up beyond the advanced publisher's in-memory cache. A late joiner that the cache
no longer covers gets the rest from the journal and raises what an EA fed everything
raises; a bad query is answered with an error and the source lives on."""
from __future__ import annotations

import json
import uuid

import msgspec
import pytest
import zenoh

from saim_mesh import scenario as S
from saim_mesh.live import play
from saim_mesh.live.srcjournal import (ASK_TIMEOUT_S, HELD, MAX_ASK_TIMEOUT_S, NONE_HELD, PACED, Asker,
                                      JournalQuery, Pacer, SourceJournal)
from saim_mesh.launch.proc import Proc, clean_env, py
from saim_mesh.launch.zenoh_config import free_port

from .conftest import SMALL, wait_until
from .test_live import in_process, load, plan_alerts, reap

pytestmark = pytest.mark.timeout(300)


class FakeQuery:
    def __init__(self, payload: bytes):
        self.payload = type("P", (), {"to_bytes": lambda _s: payload})()
        self.replies: list[bytes] = []
        self.qos: list[dict] = []
        self.error: bytes | None = None

    def reply(self, key, b, **qos):
        self.replies.append(b)
        self.qos.append(qos)

    def reply_err(self, b):
        self.error = b


def test_the_journal_keeps_every_epoch_and_answers_bad_queries_with_an_error(tmp_path):
    j = SourceJournal(tmp_path, "cp.x", 1)
    for seq in range(1, 6):
        j.append(seq, f"frame-{seq}".encode())
    j.close()
    j2 = SourceJournal(tmp_path, "cp.x", 2)   # restarted: a new epoch, the old one still served
    j2.append(1, b"new-1")
    assert j2.frames(1, 2, 4) == [b"frame-2", b"frame-3", b"frame-4"]
    assert j2.frames(1, 4, 99) == [b"frame-4", b"frame-5"] and j2.frames(2, 1, 1) == [b"new-1"]
    assert j2.frames(7, 1, 3) == []
    with pytest.raises(ValueError, match="seq 3 after 1"):
        j2.append(3, b"skipped one")
    q = FakeQuery(msgspec.msgpack.encode(JournalQuery(epoch=1, lo=1, hi=2)))
    j2.serve(q, "k")
    assert q.replies == [HELD, b"frame-1", b"frame-2"] and q.error is None
    for bad in (b"\xc1", msgspec.msgpack.encode({"epoch": -1, "lo": 1, "hi": 2}), b"x" * 300,
                msgspec.msgpack.encode({"epoch": 1, "lo": 1, "hi": 2, "extra": 1})):
        q = FakeQuery(bad)
        j2.serve(q, "k")
        assert q.error and not q.replies
    assert j2.errors == 4


def test_a_late_joiner_beyond_the_cache_catches_up_from_the_journal(tmp_path):
    sc = S.load(SMALL)
    ep, root = f"tcp/127.0.0.1:{free_port()}", f"test/{uuid.uuid4().hex[:8]}"
    procs = []
    try:
        procs.append(Proc("source-cp.all", [*py(), "source", str(SMALL), "--name", "cp.all", "--listen", ep,
                                            "--root", root, "--tracks", "--speed", "max", "--cache", "3",
                                            "--state", str(tmp_path / "state"), "--linger", "600"],
                          env=clean_env(), log_dir=tmp_path))
        procs[0].wait_for("end source cp.all", 120)   # all published before the EA exists
        procs.append(Proc("peer-A2", [*py(), "peer", "--scenario", str(SMALL), "--unit", "A2", "--connect", ep,
                                      "--root", root, "--sources", "cp.all", "--out", str(tmp_path / "A2.jsonl")],
                          env=clean_env(), log_dir=tmp_path))
        line = procs[1].wait_for("summary ", 180)
    finally:
        reap(procs)
    summary = json.loads(line.split(" ", 1)[1])
    assert summary["fetched"] > 3 and summary["gaps"] == 0 and summary["lost"] == {}, \
        {k: summary[k] for k in ("fetched", "gaps", "lost", "frames")}
    want = plan_alerts(in_process(sc, "A2", {"cp.all": list(play.share(sc, None, True))}))
    assert len(want) >= 5 and plan_alerts(load(tmp_path / "A2.jsonl")) == want


class Reply:
    def __init__(self, ok: bytes | None = None, err: bytes | None = None):
        wrap = (lambda b: None if b is None else type("S", (), {"payload": type("P", (), {"to_bytes": lambda _s: b})()})())
        self.ok, self.err = wrap(ok), wrap(err)


class LossySession:
    """A journal behind a congested link: the `drop`-th frames (counted over the whole
    session) never arrive, as DROP replies at a full router queue (`HELD`, sent BLOCK,
    always does); each ask is recorded."""

    def __init__(self, journal: SourceJournal | None, drop=lambda n: False):
        self.journal, self.drop, self.sent, self.asks = journal, drop, 0, []

    def get(self, key, payload, timeout, consolidation):
        if self.journal is None:
            return []
        q = FakeQuery(payload)
        self.asks.append(msgspec.msgpack.decode(payload, type=JournalQuery))
        self.journal.serve(q, key)
        out = []
        for b in q.replies:
            if b in (HELD, PACED):   # sent BLOCK: never dropped
                out.append(Reply(ok=b))
                continue
            self.sent += 1
            if not self.drop(self.sent):
                out.append(Reply(ok=b))
        return out + ([Reply(err=q.error)] if q.error else [])


def frames_journal(tmp_path, n: int = 60, size: int = 1000) -> SourceJournal:
    j = SourceJournal(tmp_path, "cp.x", 1)
    for seq in range(1, n + 1):
        j.append(seq, seq.to_bytes(4, "big") + b"x" * size)
    return j


def seq_of(b: bytes) -> int:
    return int.from_bytes(b[:4], "big")


class Read:   # a frame as the asker's `read` gives it: its seq
    def __init__(self, b: bytes):
        self.seq = seq_of(b)


def seqs(got) -> list[int]:
    return [f.seq for _, f in got]


def test_an_asker_gets_every_frame_in_sequence_through_a_lossy_link(tmp_path):
    """Yielding replies dropped at a congested router leave holes: the asker keeps what
    came in sequence, asks again from the first one missing, and asks for less."""
    j = frames_journal(tmp_path)
    s = LossySession(j, drop=lambda n: n % 7 == 3)
    a = Asker(chunk=16_000)
    got = a.ask(s, "k", 1, 5, 60, Read, budget_s=30)
    assert seqs(got) == list(range(5, 61)) and a.why == "done"
    assert len(s.asks) > 4 and min(q.max_bytes for q in s.asks) < 16_000   # smaller asks after the holes
    assert all(q.lo >= p.lo for p, q in zip(s.asks, s.asks[1:]))            # never from the start again


def test_an_asker_stops_when_the_journal_holds_no_more_or_nobody_answers(tmp_path):
    j = frames_journal(tmp_path, n=10)
    s = LossySession(j)
    a = Asker()
    assert seqs(a.ask(s, "k", 1, 8, 50, Read)) == [8, 9, 10] and a.why == "none held"
    assert len(s.asks) == 2   # the frames, then "none held": no third ask
    gone = LossySession(None)
    assert a.ask(gone, "k", 1, 1, 5, Read) == [] and a.why == "no answer" and gone.asks == []


def test_the_journal_answers_at_most_the_bytes_asked_but_always_one_frame(tmp_path):
    j = frames_journal(tmp_path, n=10, size=1000)
    assert [seq_of(b) for b in j.frames(1, 1, 10, max_bytes=2500)] == [1, 2]
    assert [seq_of(b) for b in j.frames(1, 3, 10, max_bytes=10)] == [3]
    q = FakeQuery(msgspec.msgpack.encode(JournalQuery(epoch=1, lo=11, hi=20)))
    j.serve(q, "k")
    assert q.replies == [] and q.error == NONE_HELD


def test_a_journal_that_holds_frames_says_so_first_and_never_yielding(tmp_path):
    j = SourceJournal(tmp_path, "cp.x", 1, reply_qos={"priority": "low", "congestion_control": "drop"})
    for seq in (1, 2):
        j.append(seq, seq.to_bytes(4, "big") + b"x" * 10)
    q = FakeQuery(msgspec.msgpack.encode(JournalQuery(epoch=1, lo=1, hi=2)))
    j.serve(q, "k")
    assert q.replies[0] == HELD and [seq_of(b) for b in q.replies[1:]] == [1, 2]
    assert "priority" not in q.qos[0] and q.qos[0]["congestion_control"] != "drop"
    assert q.qos[1] == {"priority": "low", "congestion_control": "drop"}


def test_an_asker_whose_frames_are_all_dropped_says_congested_and_asks_for_less(tmp_path):
    """Every yielding frame dropped on a full link, the journal's `HELD` through: not "no
    answer" (a journal that is not there is given up for good), but congestion, asked
    again with smaller asks until the budget is spent."""
    j = frames_journal(tmp_path)
    s = LossySession(j, drop=lambda n: True)
    a = Asker(chunk=64_000)
    assert a.ask(s, "k", 1, 1, 60, Read, budget_s=0.2) == [] and a.why == "congested"
    assert len(s.asks) > 3 and s.asks[-1].max_bytes < 64_000


def test_a_pacer_grants_what_its_bucket_pays_for_at_most_a_burst_an_ask():
    """Frames in order while the bucket is not in debt, at most `burst` bytes to one ask
    (the askers share it), refilled at its rate."""
    t = [0.0]
    p = Pacer(1000, clock=lambda: t[0])
    assert p.grant([400] * 5) == 3            # 1000 -> -200
    assert p.grant([100]) == 0                # in debt
    t[0] = 0.5
    assert p.grant([100] * 10) == 3           # -200 + 500 = 300 -> 0
    t[0] = 100.0                              # full again, not more than its burst
    assert p.grant([600] * 5) == 2 and p.tokens == -200
    assert p.withheld == 2 + 1 + 7 + 3
    with pytest.raises(ValueError, match="must be > 0"):
        Pacer(0)


def test_a_paced_journal_sends_its_share_says_so_and_the_asker_comes_back_later(tmp_path):
    """k EAs catching up across one radio link each pull a copy: a yielding journal paces
    its answers over all of them together. An ask beyond the bucket gets what it pays for
    and `PACED` (BLOCK, after the frames); its asker stops there rather than asking again at
    once (each ask crosses the link too) and comes back for the rest, its ask size kept."""
    t = [0.0]
    j = frames_journal(tmp_path, n=30, size=1000)   # 1,004-byte frames
    j.pacer = Pacer(4000, clock=lambda: t[0])
    q = FakeQuery(msgspec.msgpack.encode(JournalQuery(epoch=1, lo=1, hi=30)))
    j.serve(q, "k")
    assert q.replies[0] == HELD and [seq_of(b) for b in q.replies[1:-1]] == [1, 2, 3, 4] and q.replies[-1] == PACED
    assert q.qos[-1]["congestion_control"] == zenoh.CongestionControl.BLOCK
    s = LossySession(j)
    a = Asker(chunk=64_000)
    assert a.ask(s, "k", 1, 5, 30, Read, budget_s=30) == [] and a.why == "paced" and len(s.asks) == 1
    t[0] = 2.0
    assert seqs(a.ask(s, "k", 1, 5, 30, Read, budget_s=30)) == [5, 6, 7, 8] and a.why == "paced"
    assert len(s.asks) == 2 and a.chunk == 64_000 and a.timeout == ASK_TIMEOUT_S
    t[0] = 100.0
    j.pacer.burst = 1e9
    assert seqs(a.ask(s, "k", 1, 9, 30, Read, budget_s=30)) == list(range(9, 31)) and a.why == "done"


class SlowLink(LossySession):
    """A router queue that drains slower than an ask waits: an ask that waits less than
    `needs` seconds gets only the journal's `HELD` (its frames come after it stopped
    listening); each ask's timeout is recorded."""

    def __init__(self, journal: SourceJournal, needs: float):
        super().__init__(journal)
        self.needs, self.timeouts = needs, []

    def get(self, key, payload, timeout, consolidation):
        self.timeouts.append(timeout)
        self.drop = (lambda n: False) if timeout >= self.needs else (lambda n: True)
        return super().get(key, payload, timeout, consolidation)


def test_an_asker_whose_frames_come_after_it_stopped_listening_waits_longer_next_time(tmp_path):
    """Like TCP's retransmission timer: answered but nothing in time doubles the wait, up to
    a bound; answers that come whole bring it back down."""
    j = frames_journal(tmp_path, n=10, size=100)
    s = SlowLink(j, needs=6.0)
    a = Asker()
    assert seqs(a.ask(s, "k", 1, 1, 10, Read, budget_s=5)) == list(range(1, 11)) and a.why == "done"
    assert s.timeouts[:2] == [ASK_TIMEOUT_S, 2 * ASK_TIMEOUT_S] and a.timeout == ASK_TIMEOUT_S
    never = SlowLink(j, needs=1e9)
    b = Asker()
    assert b.ask(never, "k", 1, 1, 10, Read, budget_s=0.2) == [] and b.why == "congested"
    assert max(never.timeouts) == MAX_ASK_TIMEOUT_S and len(never.timeouts) > 3


@pytest.mark.parametrize("yielding, first", [(True, 77), (False, 1)])
def test_a_yielding_source_leaves_a_long_gap_to_its_journal_not_its_cache(tmp_path, yielding, first):
    """A heal's recovery asked the cache for every missed frame at once, one copy per EA
    behind the link, and the copies held up the live frames of every source sharing it. A
    source that yields across radio links and keeps a journal caches only the last
    `YIELDING_CACHE` frames; the journal, asked in sizes that fit the link, has the rest.
    A late joiner's history from the cache shows what it holds: the last 4 of 80 frames,
    or all 80 for a source that does not yield."""
    import zenoh
    import zenoh.ext as zx

    from dissemination.keyspace import KeySpace
    from saim_mesh.live import frames as F
    from saim_mesh.live.source import HISTORY, YIELDING_CACHE, LiveSource
    from saim_mesh.launch.zenoh_config import config
    assert YIELDING_CACHE == 4
    ks = KeySpace(f"test/{uuid.uuid4().hex[:8]}")
    got: list[int] = []
    with zenoh.open(config(["tcp/127.0.0.1:0"], None)) as s:
        src = LiveSource(s, ks, "cp.test", tmp_path, yielding=yielding)
        for k in range(1, 81):
            src.heartbeat() if k > 1 else src.watermark(float(k))
        assert src.seq == 80 and len(src.journal.frames(src.epoch, 1, 80)) == 80
        assert (src.journal.pacer is not None) is yielding   # its journal paced too (a test above)
        zx.declare_advanced_subscriber(
            s, ks.src("cp.test"), lambda smp: got.append(F.decode(smp.payload.to_bytes(), 1 << 20).seq),
            history=zx.HistoryConfig(max_samples=HISTORY))
        wait_until(lambda: len(got) >= 80 - first + 1, 20, "the late joiner's history")
        assert got[0] == first and got[-1] == 80
        src.close()


class _Lingering:
    """A source's journal asked at the given (fake) times while the source lingers."""

    def __init__(self, asks: list[float]):
        self.t, self.asks = 0.0, sorted(asks)
        self.journal = type("J", (), {"asked_at": None})()

    def clock(self) -> float:
        return self.t

    def sleep(self, d: float) -> None:
        self.t += d
        while self.asks and self.asks[0] <= self.t:
            self.journal.asked_at = self.asks.pop(0)


@pytest.mark.parametrize("asks, stayed", [
    ([], 10.0),                        # nobody asked: its --linger
    ([3.0, 12.0, 21.0], 31.0),         # asked again within 10 s each time: 10 s after the last ask
    ([3.0, 25.0], 13.0),               # an ask after it left is not waited for
    ([float(k) for k in range(100)], 60.0),   # asked all the time: at most --linger-max
])
def test_a_source_lingers_while_its_journal_is_still_asked(asks, stayed):
    """A source that left 30 s after its end while the EAs beyond a healed radio link were
    still catching up from it (k EAs, k copies through one link) left them a gap: it stays
    while asked, within `--linger` of the last ask, at most `--linger-max`."""
    from saim_mesh.live.source import LiveSource
    fake = _Lingering(asks)
    src = object.__new__(LiveSource)   # only its journal matters here
    src.journal = fake.journal
    assert LiveSource.linger(src, 10.0, 60.0, clock=fake.clock, sleep=fake.sleep) == pytest.approx(stayed)
