"""`live.order.EventTimeOrder`: facts from many sources, each with its own watermark, come out
in one event-time order that depends on the data only, never on how the sources' frames
interleave on arrival (issue 31: a live mesh with no centre)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from saim_mesh.live.order import EventTimeOrder

SETTINGS = settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
INF = math.inf


@dataclass(frozen=True)
class Item:
    t: float
    tag: tuple = ()          # (source, epoch, seq, index in frame): identifies the item


@dataclass
class Frame:
    source: str
    epoch: int
    seq: int
    wm: float
    items: list = field(default_factory=list)
    end: bool = False

    def offer(self, o: EventTimeOrder):
        return o.take(self.source, self.epoch, self.seq, self.wm, self.items, self.end)


def frame(source, epoch, seq, wm, times=(), end=False) -> Frame:
    return Frame(source, epoch, seq, wm, [Item(float(t), (source, epoch, seq, i)) for i, t in enumerate(times)], end)


def ts(items) -> list[float]:
    return [x.t for x in items]


def key(x: Item) -> tuple:
    return (x.t, *x.tag)


# --------------------------------------------------------------------------- streams


@st.composite
def streams(draw) -> dict[str, list[Frame]]:
    """Per source, an honest frame stream: every item is later than every watermark sent
    before it, watermarks never fall; a source may restart (higher epoch, seq from 1) and
    may end. Small integer times, so that ties across sources and frames are common."""
    names = draw(st.lists(st.sampled_from(["b", "a", "c10", "c2", "Z"]), min_size=1, max_size=4, unique=True))
    out = {}
    for name in names:
        wm, epoch, seq, frames = 0, draw(st.integers(0, 3)), 0, []
        for j in range(draw(st.integers(1, 6))):
            if j and draw(st.integers(0, 4)) == 0:
                epoch, seq = epoch + 1, 0
            seq += draw(st.sampled_from([1, 1, 1, 2]))            # sometimes a gap
            times = [wm + d for d in draw(st.lists(st.integers(1, 6), max_size=4))]
            wm += draw(st.integers(0, 6))
            frames.append(frame(name, epoch, seq, float(wm), times))
        if draw(st.booleans()):
            frames[-1].end = True
        out[name] = frames
    return out


@st.composite
def runs(draw, s: dict[str, list[Frame]]):
    """One arrival interleaving that keeps each source's own order, redeliveries of frames
    already offered, and release() calls (with or without `upto`) at arbitrary points."""
    order = draw(st.permutations([name for name, fs in s.items() for _ in fs]))
    steps = []
    for name in order:
        steps.append(("frame", name))
        if draw(st.integers(0, 5)) == 0:
            steps.append(("again", draw(st.sampled_from(sorted(s)))))
        what = draw(st.sampled_from(["none", "none", "bound", "upto"]))
        if what == "bound":
            steps.append(("release", None))
        elif what == "upto":
            steps.append(("release", float(draw(st.integers(-2, 40)))))
    return steps


def expected(s: dict[str, list[Frame]]) -> list[tuple]:
    """What any run must release once every frame is in: every item up to the lowest final
    watermark, in (t, source, epoch, seq, index) order."""
    final = min(INF if fs[-1].end else max(f.wm for f in fs) for fs in s.values())
    return sorted(key(x) for fs in s.values() for f in fs for x in f.items if x.t <= final)


def play(s: dict[str, list[Frame]], steps, max_buffered: int = 1_000_000) -> list[tuple]:
    o = EventTimeOrder(s, max_buffered=max_buffered)
    nxt = {name: 0 for name in s}
    out: list[tuple] = []

    def release(upto):
        b = o.bound() if upto is None else min(o.bound(), upto)
        got = o.release(upto)
        assert all(x.t <= b for x in got), "released past the bound"
        out.extend(key(x) for x in got)

    for what, name in steps:
        if what == "frame":
            f = s[name][nxt[name]]
            nxt[name] += 1
            assert f.offer(o) is None
        elif what == "again" and nxt[name]:
            k = nxt[name] - 1 if nxt[name] == 1 else nxt[name] - 2
            assert s[name][k].offer(o) in ("duplicate", "old epoch")
        elif what == "release":
            release(name)
    release(None)
    assert o.late == []
    assert o.gaps == {n: sum(b.seq - a.seq - 1 for a, b in zip(fs, fs[1:]) if a.epoch == b.epoch) for n, fs in s.items()}
    return out


# --------------------------------------------------------------------------- (1) determinism


@SETTINGS
@given(st.data())
def test_any_interleaving_releases_the_same_sequence(data):
    s = data.draw(streams())
    want = expected(s)
    first = play(s, data.draw(runs(s)))
    second = play(s, data.draw(runs(s)))
    assert first == want
    assert second == want


# --------------------------------------------------------------------------- (2) the bound


def test_nothing_is_released_beyond_the_minimum_watermark():
    o = EventTimeOrder(["a", "b"])
    assert frame("a", 0, 1, 5.0, [1, 4, 6, 9]).offer(o) is None
    assert frame("b", 0, 1, 3.0, [2, 3.5]).offer(o) is None
    assert o.bound() == 3.0
    assert ts(o.release()) == [1, 2]
    assert o.released == 3.0
    assert ts(o.release(upto=100.0)) == []                  # upto never passes the bound
    assert frame("b", 0, 2, 8.0, [7]).offer(o) is None
    assert ts(o.release(upto=4.5)) == [3.5, 4]              # upto holds back below the bound
    assert ts(o.release()) == []                            # a is at 5: 6, 7, 9 wait
    assert o.bound() == 5.0 and o.buffered() == 3
    assert o.watermarks() == {"a": 5.0, "b": 8.0}


def test_a_silent_source_holds_everything_back_until_it_is_lost():
    o = EventTimeOrder(["a", "b", "quiet"])
    frame("a", 0, 1, 10.0, [1, 2, 11]).offer(o)
    frame("b", 0, 1, 6.0, [3, 7]).offer(o)
    assert o.bound() == -INF
    assert o.release() == [] and o.released == -INF
    o.lose("quiet", "no frame for 30 s")
    assert o.lost == {"quiet": "no frame for 30 s"}
    assert o.bound() == 6.0
    assert ts(o.release()) == [1, 2, 3]
    assert o.buffered() == 2


def test_a_lost_source_that_sends_again_is_waited_for_again():
    o = EventTimeOrder(["a", "b"])
    frame("a", 0, 1, 10.0, [9, 15]).offer(o)
    o.lose("b", "silent")
    assert o.bound() == 10.0
    assert ts(o.release()) == [9]
    assert frame("b", 0, 1, 12.0, [11]).offer(o) is None
    assert o.lost == {}
    assert frame("a", 0, 2, 30.0).offer(o) is None
    assert o.bound() == 12.0                                # b is waited for again
    assert ts(o.release()) == [11]
    o.lose("b", "silent again")
    assert ts(o.release()) == [15]
    assert frame("b", 0, 2, 13.0).offer(o) is None
    assert o.bound() == 13.0                                # the bound may fall ...
    assert o.release() == [] and o.released == 30.0         # ... what was released stays


def test_when_every_source_is_lost_the_bound_is_the_furthest_promise():
    o = EventTimeOrder(["a", "b"])
    frame("a", 0, 1, 4.0, [1, 5]).offer(o)
    frame("b", 0, 1, 7.0, [6, 9]).offer(o)
    o.lose("a", "silent")
    o.lose("b", "silent")
    assert o.bound() == 7.0
    assert ts(o.release()) == [1, 5, 6]
    assert EventTimeOrder().bound() == -INF
    none_sent = EventTimeOrder(["a"])
    none_sent.lose("a", "never heard")
    assert none_sent.bound() == -INF


def test_frames_of_strangers_are_dropped_until_added():
    o = EventTimeOrder(["a"])
    assert frame("x", 0, 1, 100.0, [1]).offer(o) == "unknown source"
    assert o.unknown == 1 and o.buffered() == 0 and "x" not in o.watermarks()
    o.add_source("x")
    assert o.watermarks() == {"a": -INF, "x": -INF}
    assert frame("a", 0, 1, 100.0, [2]).offer(o) is None
    assert o.release() == []                                # x, now depended on, holds it
    assert frame("x", 0, 1, 100.0, [1]).offer(o) is None
    assert ts(o.release()) == [1, 2]
    with pytest.raises(KeyError):
        o.lose("nobody", "?")


def test_a_time_that_cannot_be_ordered_is_refused():
    o = EventTimeOrder(["a"])
    assert frame("a", 0, 1, math.nan, [1]).offer(o) == "bad time"
    assert frame("a", 0, 1, 2.0, [math.nan]).offer(o) == "bad time"
    assert o.buffered() == 0 and o.watermarks() == {"a": -INF}
    assert frame("a", 0, 1, 2.0, [1]).offer(o) is None     # nothing of the refused frames stuck


# --------------------------------------------------------------------------- (3) duplicates, epochs, gaps


def test_duplicates_and_old_epochs_are_ignored_a_restart_is_taken_gaps_counted():
    o = EventTimeOrder(["a"])
    assert frame("a", 3, 1, 1.0, [1]).offer(o) is None
    assert frame("a", 3, 1, 1.0, [1]).offer(o) == "duplicate"
    assert frame("a", 3, 2, 2.0, [2]).offer(o) is None
    assert frame("a", 3, 5, 5.0, [5]).offer(o) is None     # 3 and 4 missing
    assert o.gaps == {"a": 2}
    assert frame("a", 3, 4, 4.0, [4]).offer(o) == "duplicate"
    assert frame("a", 2, 9, 9.0, [9]).offer(o) == "old epoch"
    assert frame("a", 4, 1, 6.0, [6]).offer(o) is None     # restarted: seq from 1 again
    assert frame("a", 4, 1, 6.0, [6]).offer(o) == "duplicate"
    assert frame("a", 3, 6, 6.0, [6]).offer(o) == "old epoch"
    assert frame("a", 4, 2, 3.0, [7]).offer(o) is None     # a lower watermark does not lower it
    assert o.gaps == {"a": 2}
    assert o.watermarks() == {"a": 6.0}
    assert ts(o.release()) == [1, 2, 5, 6]
    assert [x.tag for x in o.release(upto=INF)] == []      # 7 waits for the watermark


def test_ties_are_broken_by_source_epoch_seq_and_index():
    o = EventTimeOrder(["b", "a"])
    frame("b", 0, 1, 0.0, [1, 1]).offer(o)
    frame("a", 5, 1, 0.0, [1]).offer(o)
    frame("a", 6, 1, 0.0, [1]).offer(o)                     # restarted
    frame("a", 6, 2, 0.0, [1]).offer(o)
    frame("b", 0, 2, 2.0, [1]).offer(o)
    frame("a", 6, 3, 2.0).offer(o)
    assert [x.tag for x in o.release()] == [("a", 5, 1, 0), ("a", 6, 1, 0), ("a", 6, 2, 0),
                                            ("b", 0, 1, 0), ("b", 0, 1, 1), ("b", 0, 2, 0)]


# --------------------------------------------------------------------------- (4) late


def test_late_items_of_a_returning_source_go_to_the_late_path():
    o = EventTimeOrder(["a", "b"])
    frame("b", 0, 1, 2.0, [1]).offer(o)
    frame("a", 0, 1, 10.0, [3, 9, 12]).offer(o)
    o.lose("b", "link down")
    assert ts(o.release()) == [1, 3, 9]
    assert o.released == 10.0
    # b comes back with what it had while cut off: 5 and 10 can no longer be put in order
    assert frame("b", 0, 2, 11.0, [5, 10, 11]).offer(o) is None
    assert [(src, x.t) for src, x in o.late] == [("b", 5.0), ("b", 10.0)]
    assert o.lost == {} and o.buffered() == 2
    frame("a", 0, 2, 20.0).offer(o)
    frame("b", 0, 3, 20.0).offer(o)
    assert ts(o.release()) == [11, 12]                      # the normal path never sees 5, 10


def test_an_item_at_the_released_bound_is_late():
    o = EventTimeOrder(["a"])
    frame("a", 0, 1, 4.0, [4]).offer(o)
    assert ts(o.release()) == [4]
    frame("a", 0, 2, 6.0, [4, 4.5]).offer(o)                # a broke its promise with 4
    assert ts(x for _, x in o.late) == [4]
    assert o.buffered() == 1


# --------------------------------------------------------------------------- (5) end


def test_an_ended_source_no_longer_holds_the_bound():
    o = EventTimeOrder(["a", "b"])
    frame("a", 0, 1, 3.0, [1, 2], end=True).offer(o)
    frame("b", 0, 1, 50.0, [10, 40, 60]).offer(o)
    assert o.watermarks()["a"] == INF
    assert o.bound() == 50.0
    assert ts(o.release()) == [1, 2, 10, 40]
    frame("b", 0, 2, 70.0, [65], end=True).offer(o)
    assert o.bound() == INF
    assert ts(o.release()) == [60, 65]
    assert frame("a", 0, 2, 0.0).offer(o) is None           # a frame after the end does not undo it
    assert o.watermarks()["a"] == INF


# --------------------------------------------------------------------------- (6) memory


def test_a_full_buffer_refuses_frames_without_a_trace():
    o = EventTimeOrder(["a", "b"], max_buffered=3)
    assert frame("a", 0, 1, 5.0, [6, 7]).offer(o) is None
    assert frame("b", 0, 1, 2.0, [2]).offer(o) is None      # b holds the bound at 2
    assert o.buffered() == 3
    assert frame("a", 0, 2, 9.0, [8]).offer(o) == "full"
    assert o.buffered() == 3 and o.watermarks()["a"] == 5.0 and o.gaps["a"] == 0
    assert frame("a", 0, 2, 9.0).offer(o) is None           # a watermark alone is never refused
    assert frame("a", 0, 3, 9.0, [8]).offer(o) == "full"
    assert ts(o.release()) == [2]
    assert frame("a", 0, 3, 9.0, [8]).offer(o) is None      # offered again after a release: taken
    assert o.gaps["a"] == 0 and o.buffered() == 3


def test_the_source_everyone_waits_for_is_taken_even_when_full():
    """Refusing the frames of the source that holds the bound would deadlock: nothing can
    be released until its watermark rises."""
    o = EventTimeOrder(["a", "b"], max_buffered=2)
    frame("a", 0, 1, 50.0, [10, 20]).offer(o)
    assert frame("a", 0, 2, 60.0, [55]).offer(o) == "full"  # a does not hold the bound (b does)
    assert frame("b", 0, 1, 30.0, [5, 15]).offer(o) is None
    assert o.buffered() == 4
    assert ts(o.release()) == [5, 10, 15, 20]
    assert frame("a", 0, 2, 60.0, [55]).offer(o) is None


def test_late_items_do_not_count_against_the_buffer():
    o = EventTimeOrder(["a", "b"], max_buffered=1)
    frame("a", 0, 1, 12.0).offer(o)
    frame("b", 0, 1, 10.0).offer(o)
    o.release()
    frame("b", 0, 2, 11.0, [20]).offer(o)                  # b holds the bound, the buffer is full
    assert frame("a", 0, 2, 13.0, [1, 2, 3]).offer(o) is None
    assert len(o.late) == 3 and o.buffered() == 1
    assert frame("a", 0, 3, 14.0, [1, 30]).offer(o) == "full"


@SETTINGS
@given(st.data())
def test_a_small_buffer_with_backpressure_releases_the_same_sequence(data):
    """A caller that, on "full", keeps the frame, reads the other sources meanwhile and
    releases what it can ends with the same sequence as with unlimited memory; only the
    sources holding the bound ever push the buffer past its limit; and it never deadlocks:
    when nothing more can be taken, whatever is left is beyond every source's promise."""
    s = data.draw(streams())
    limit = data.draw(st.integers(1, 4))
    o = EventTimeOrder(s, max_buffered=limit)
    queue = {name: list(fs) for name, fs in s.items()}
    out: list[tuple] = []
    refused: set[str] = set()                              # since the last progress
    while True:
        ready = sorted(n for n, fs in queue.items() if fs and n not in refused)
        if not ready:
            got = o.release()
            out.extend(key(x) for x in got)
            if not got:
                break                                      # nothing can move any more
            refused.clear()
            continue
        name = data.draw(st.sampled_from(ready))
        f = queue[name][0]
        holds = name not in o.lost and o.watermarks()[name] == o.bound()
        before = o.buffered()
        got = f.offer(o)
        if got == "full":
            assert not holds and before + len(f.items) > limit and o.buffered() == before
            refused.add(name)
        else:
            assert got is None
            assert holds or o.buffered() == before or o.buffered() <= limit
            queue[name].pop(0)
            refused.clear()
        if data.draw(st.booleans()):
            out.extend(key(x) for x in o.release())
    assert out == expected(s)
    assert all(x.t > o.bound() for fs in queue.values() for f in fs for x in f.items)
    assert o.late == []
