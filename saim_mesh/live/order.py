"""Event-time order over many sources, each with its own watermark (issue 31).

With no centre, every producer of facts is a *source* that publishes its own stream of
frames. A frame carries `(source, epoch, seq)`, some items (each with an event time `.t`)
and a *watermark* `wm`: "nothing at or before event time wm will follow from me". The
order below is the one stream processors use (Flink's per-partition watermarks with
idleness and `MAX_WATERMARK` for a finished source, Kafka Streams' `max.task.idle.ms`):

* items wait in a buffer (one time-sorted run per frame) and are released in
  `(t, source, epoch, seq, index in frame)` order, only up to the *bound*: the minimum
  watermark over the sources this EA depends on that are not declared lost;
* if every source keeps its watermark promise, whatever is released at bound B is every
  item with t <= B that will ever come, so the released sequence depends on the data only,
  never on how the frames of different sources interleave on arrival;
* "lost" is a decision the caller makes (and writes to its journal, so that a replay makes
  it again at the same place), never a wall-clock timeout taken here: idleness by wall clock
  is not reproducible;
* what a source sends at or before the bound already released (it was lost and came back,
  or broke its promise) can no longer be put in order: it goes to `late`, for the caller's
  late path, instead of being applied out of order.

Pure Python, no I/O: the caller feeds frames (`take`), decides losses (`lose`) and pulls
what is ready (`release`).
"""
from __future__ import annotations

import bisect
import heapq
import math
from dataclasses import dataclass
from typing import Generic, Iterable, Protocol, Sequence, TypeVar

INF = math.inf


class Timed(Protocol):
    """A fact with an event time (seconds, any epoch the sources share)."""

    @property
    def t(self) -> float: ...


T = TypeVar("T", bound=Timed)


@dataclass(slots=True)
class _Source:
    """What one source has told us so far."""
    epoch: int | None = None     # None: nothing taken yet
    seq: int = 0                 # the last seq taken in `epoch`
    wm: float = -INF             # max watermark received (+inf once ended)
    ended: bool = False


@dataclass(slots=True)
class _Run:
    """A taken frame's items not yet released, sorted by event time (ties in frame order):
    the order keeps runs, not items, and merges only what a release lets out."""
    key: tuple[str, int, int]    # (source, epoch, seq)
    times: list[float]
    items: list
    start: int = 0               # the first item not yet released


class EventTimeOrder(Generic[T]):
    """Puts the items of many per-source frame streams in one deterministic event-time order.

    `sources` are the sources this EA depends on. A frame from any other source is dropped
    (counted in `unknown`) unless `add_source` named it first: a stranger must not be able to
    hold the bound back, nor fill the buffer.

    Public state, for the caller's counters and journal:
    `gaps[source]` missing seqs seen, `lost[source]` why it was declared lost,
    `late` (source, item) pairs that came at or before the released bound, `unknown` the
    number of frames from sources not depended on.
    """

    def __init__(self, sources: Iterable[str] = (), max_buffered: int = 1_000_000) -> None:
        if max_buffered < 1:
            raise ValueError(f"max_buffered must be at least 1, not {max_buffered}")
        self.max_buffered = max_buffered
        self._src: dict[str, _Source] = {}
        self.gaps: dict[str, int] = {}
        self.lost: dict[str, str] = {}
        self.late: list[tuple[str, T]] = []
        self.unknown = 0
        # (first unreleased t, source, epoch, seq, run): the key is unique (a frame is taken
        # once), so the run itself is never compared
        self._runs: list[tuple[float, str, int, int, _Run]] = []
        self._n = 0   # items buffered
        self._released = -INF
        for name in sources:
            self.add_source(name)

    def add_source(self, name: str) -> None:
        """Depend on `name` from now on (no-op if already known).

        Until it sends a frame or is lost, it holds the bound at -inf: a new dependency is
        waited for, not skipped. Its items at or before `released` are late."""
        if name not in self._src:
            self._src[name] = _Source()
            self.gaps[name] = 0

    def take(self, source: str, epoch: int, seq: int, wm: float, items: Sequence[T],
             end: bool = False) -> str | None:
        """Take one frame: None when taken, else why it was ignored.

        Reasons: "unknown source"; "bad time" (a NaN time or watermark cannot be ordered);
        "old epoch" (an epoch below the source's current one: a frame from before a
        restart); "duplicate" (same epoch, seq at or below the last taken: redeliveries
        are normal with at-least-once transport); "full" (see below).

        A higher epoch means the source restarted: its seq tracking starts again at this
        frame. A seq jump within an epoch is counted in `gaps` and the frame is taken (the
        missing frames, if they come later, are duplicates: holding the stream back for
        them would let one lost frame stop the mesh). Watermarks only rise; `end=True`
        makes the source's watermark +inf for good. Taking a frame from a lost source
        un-loses it.

        Memory bound: if buffering this frame's items would make more than `max_buffered`
        items wait, the frame is ignored with "full" and leaves no trace (not even its
        seq), so the caller offers it again after a `release` (before any later frame of
        the same source, or the later one is taken with a gap and this one becomes a
        duplicate). One exception: a frame from a source that currently holds the bound
        (its watermark is the bound, it is not lost) is always taken, since the buffer
        can only drain when the bound rises and refusing its frames would deadlock. So
        only the sources everybody waits for can push the buffer past the limit, and only
        until their watermark moves.
        """
        st = self._src.get(source)
        if st is None:
            self.unknown += 1
            return "unknown source"
        times = [float(x.t) for x in items]
        released = self._released
        fresh = 0
        for t in times:   # one pass: a NaN (it compares false both ways) and what is not late
            if t > released:
                fresh += 1
            elif not t <= released:
                return "bad time"
        if wm != wm:
            return "bad time"
        if st.epoch is not None:
            if epoch < st.epoch:
                return "old epoch"
            if epoch == st.epoch and seq <= st.seq:
                return "duplicate"
        if fresh and self._n + fresh > self.max_buffered and not self._holds(source, st):
            return "full"

        self.lost.pop(source, None)
        if st.epoch == epoch:
            self.gaps[source] += seq - st.seq - 1
        st.epoch, st.seq = epoch, seq
        if fresh != len(times):   # the late ones out, in one pass
            keep_t, keep = [], []
            for t, x in zip(times, items):
                if t <= released:
                    self.late.append((source, x))
                else:
                    keep_t.append(t)
                    keep.append(x)
            times, items = keep_t, keep
        if times:
            items = list(items)   # the caller's sequence is not kept
            if times != sorted(times):   # a stable sort by time: ties stay in frame order
                idx = sorted(range(len(times)), key=times.__getitem__)
                times, items = [times[k] for k in idx], [items[k] for k in idx]
            heapq.heappush(self._runs, (times[0], source, epoch, seq, _Run((source, epoch, seq), times, items)))
            self._n += len(times)
        st.wm = max(st.wm, float(wm))
        if end:
            st.ended, st.wm = True, INF
        return None

    def _holds(self, source: str, st: _Source) -> bool:
        """`source` is one of those the bound is waiting for."""
        return source not in self.lost and st.wm == self.bound()

    def lose(self, source: str, why: str) -> None:
        """Declare `source` lost: the bound stops waiting for it until it sends again.

        The caller decides (and journals) this; `why` is kept in `lost` for the record.
        A source this order does not depend on is a KeyError: losing a stranger is a bug
        in the caller, and silently recording it would hide that."""
        if source not in self._src:
            raise KeyError(source)
        self.lost[source] = why

    def bound(self) -> float:
        """How far the sources allow release: the minimum watermark over the depended
        sources that are not lost (-inf while one of them has sent nothing; +inf once all
        of them ended).

        If every source is lost (or there are none), the bound is the highest watermark
        any of them reached (-inf if none sent anything), not +inf: with nobody left to
        wait for, monitoring still must not run ahead of what some source promised.
        The bound can fall (a lost source with a low watermark comes back); `released`
        never does."""
        live = [st.wm for name, st in self._src.items() if name not in self.lost]
        if live:
            return min(live)
        return max((st.wm for st in self._src.values()), default=-INF)

    def release(self, upto: float | None = None) -> list[T]:
        """Every buffered item with t <= min(upto, bound()), in
        (t, source, epoch, seq, index in frame) order.

        `upto` lets the caller move in smaller steps than the sources allow (its own clock,
        a replay's pace). The released bound is remembered and only rises: an item that
        comes later at or before it is late."""
        b = self.bound()
        if upto is not None:
            b = min(b, upto)
        runs = self._runs
        pieces: list[tuple[tuple[str, int, int], list[float], list]] = []
        while runs and runs[0][0] <= b:
            r = heapq.heappop(runs)[4]
            k = bisect.bisect_right(r.times, b, r.start)
            pieces.append((r.key, r.times[r.start:k], r.items[r.start:k]))
            if k < len(r.times):
                r.start = k
                heapq.heappush(runs, (r.times[k], *r.key, r))
        self._released = max(self._released, b)
        if not pieces:
            return []
        if len(pieces) == 1:
            out = pieces[0][2]
        else:   # runs in (source, epoch, seq) order, then a stable sort by time alone
            pieces.sort(key=lambda p: p[0])
            times = [t for p in pieces for t in p[1]]
            items = [x for p in pieces for x in p[2]]
            out = [items[k] for k in sorted(range(len(times)), key=times.__getitem__)]
        self._n -= len(out)
        return out

    @property
    def released(self) -> float:
        """The highest bound released so far (-inf before the first release)."""
        return self._released

    def buffered(self) -> int:
        """How many items wait to be released."""
        return self._n

    def watermarks(self) -> dict[str, float]:
        """Each depended source's watermark (-inf: nothing yet; +inf: ended), lost or not."""
        return {name: st.wm for name, st in self._src.items()}


__all__ = ["EventTimeOrder", "Timed"]
