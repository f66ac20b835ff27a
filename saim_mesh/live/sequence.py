"""Each source's frames, in that source's own sequence, before the event-time order sees
them (issue 31.1; `LivePeer` composes one).

What can break a source's sequence on a lossy mesh, and what is done about it here:
- a frame comes ahead of a missing one (a late joiner gets the publisher's cache after
  newer frames; recovery is under way): it waits for it, at most `GAP_WAIT_S`, then the
  source's durable journal is asked (again, a bounded number of times, when the journal's
  replies were congested or nobody answered); what no journal holds is a gap, said and counted;
- the source restarted (a higher epoch): the rest of its last epoch comes from its
  journal first;
- the peer fell behind (frames held over half its memory bound): the source's frames are
  dropped as they come and fetched again from its journal, in sequence, when there is room;
- the order refused a frame as full: it waits, with its source's later frames behind it,
  and is offered again (`retry`) after a release.

Nothing here orders across sources or touches the EA: a frame in sequence goes to `take`
(the peer's), which answers False when the order could not take it yet."""
from __future__ import annotations

import time
from typing import Callable

from ..protocol import wire as W
from .held import Held
from .srcjournal import Asker

GAP_WAIT_S = 3.0      # wall seconds a frame that came early waits for the missing ones (recovery, history)
PATIENCE = 40         # asks of a journal that gave nothing over a congested link before the rest is a gap
NO_ANSWER_PATIENCE = 5   # asks of a journal nobody answered (no route to it now) before the rest is a gap
ASK_AGAIN = {"congested": PATIENCE, "paced": PATIENCE, "no answer": NO_ANSWER_PATIENCE}   # why an ask gave nothing -> asks before a gap
HELD_FRAMES = 20_000  # frames held per source meanwhile (beyond: dropped, recovered again or a gap)
REFETCH = 500         # frames asked of a journal at a time when fetching a source again

Take = Callable[..., bool]    # (payload, key, f=frame, retrying=bool) -> taken (False: not yet)
Read = Callable[[bytes, str], object]   # (payload, key) -> the frame checked as a live one, or None


class Sequencer:
    """Per-source sequence numbers, the frames held outside the order (`hold`: early, or
    waiting for room), and catch-up from the sources' journals. `session()` is the peer's
    Zenoh session (None: no catch-up, e.g. a journal replay); `room()` says whether the
    order can take more facts now."""

    def __init__(self, take: Take, read: Read, ks, log, max_held: Callable[[], int], room: Callable[[], bool],
                 session: Callable[[], object], also_held: Callable[[], int] = lambda: 0):
        self.take, self.read, self.ks, self.log = take, read, ks, log
        self.also_held = also_held        # () -> bytes held elsewhere against the same bound (key groups' frames)
        self.max_held = max_held          # () -> bytes the peer may hold for the order (half of them here)
        self.room, self.session = room, session
        self.seq_of: dict[str, list[int]] = {}   # source -> [epoch, next seq expected]
        self.hold = Held(HELD_FRAMES)
        self.behind: dict[str, bool] = {}        # sources whose frames are dropped until fetched again
        self.askers: dict[str, Asker] = {}       # each source's journal asker, sized to what its link gives
        self.patience: dict[str, int] = {}       # asks that brought nothing over a congested link
        self.dropped = 0                         # frames dropped while behind (fetched again, or gaps)
        self.fetched = 0                         # frames caught up from sources' journals
        self.gaps = 0                            # frames that never came (beyond recovery and journals)
        self.misses = 0                          # frames the advanced subscriber said it missed

    def fits(self, n: int) -> bool:
        """Whether `n` more bytes may wait outside the order: what this holds and what is held
        elsewhere against the same bound (`also_held`) share half of the peer's `max_held`."""
        return self.hold.bytes + self.also_held() + n <= self.max_held() // 2

    def resume(self, source: str, epoch: int, next_seq: int) -> None:
        """The source's sequence goes on at `next_seq` of `epoch` (a journal replayed)."""
        self.seq_of[source] = [epoch, next_seq]

    def arrive(self, payload: bytes, key: str, f) -> bool:
        """A frame off the wire, taken now if it is the next of its source, else held,
        ignored (an old one) or dropped (behind: fetched again later). False when dropped:
        the source was heard, but its frame not kept."""
        st = self.seq_of.get(f.source)
        if st is not None and f.epoch > st[0]:   # the source restarted: the rest of its last epoch first
            self.catch_up(f.source, st[0], st[1], W.SEQ_LIMIT, take=True)
        if st is None or f.epoch > st[0]:   # first heard, or the source restarted: its seq starts at 1
            st = self.seq_of[f.source] = [f.epoch, 1]
            self.hold.reset_early(f.source)
        if f.epoch < st[0] or f.seq < st[1]:
            return True   # an old epoch's frame, or one taken already
        if self.behind.get(f.source) or not self.fits(len(payload)) and (
                f.seq > st[1] or self.hold.waiting_for(f.source)):
            if not self.behind.get(f.source):
                self.log(f"source {f.source}: over {self.max_held() >> 21} MB held: its frames from {st[1]} "
                         f"are fetched again from its journal when there is room", flush=True)
            self.behind[f.source] = True
            self.dropped += 1
            return False
        if f.seq > st[1]:
            if not self.hold.early_of(f.source):
                self.log(f"source {f.source}: frame {f.seq} came before {st[1]}: waiting for it", flush=True)
            self.hold.hold_early(f.source, f.seq, (payload, key, f), time.monotonic())
            return True
        self.take(payload, key, f=f)
        st[1] = f.seq + 1
        self.drain(f.source)
        return True

    def drain(self, source: str, force: bool = False) -> None:
        """Held frames now in sequence (or, `force`d after the wait, from the lowest held on:
        the missing ones are gone, counted as a gap)."""
        st, early = self.seq_of[source], self.hold.early_of(source)
        why, asked = "", 0
        if force and early and st[1] not in early:   # beyond recovery: the source's journal, if it keeps one
            got = self.catch_up(source, st[0], st[1], min(early) - 1)
            why = self.askers[source].why if source in self.askers else "no journal asked"
            if not got and self.patience.get(source, 0) < ASK_AGAIN.get(why, 0):
                # the frames are not gone, so no gap yet; asked again after `GAP_WAIT_S`. Congested:
                # the journal is there but its replies yield to live traffic on a slow link. Nobody
                # answering: no route to it now (a router link that flapped after a heal drops its
                # routes for a second; bench_hosts), or no journal at all: asked a few times only,
                # since the source's later frames wait here and its EA stands still meanwhile
                self.patience[source] = self.patience.get(source, 0) + 1
                self.hold.gap_since[source] = time.monotonic()
                return
            asked = self.patience.pop(source, 0) + 1
        if force and early and st[1] not in early:
            low = min(early)
            self.gaps += low - st[1]
            self.log(f"source {source}: frames {st[1]}..{low - 1} never came (its journal: {why or 'not asked'}, "
                     f"asked {asked} times): going on without them", flush=True)
            st[1] = low
        while (item := self.hold.pop_early(source, st[1])) is not None:
            payload, key, f = item
            self.take(payload, key, f=f)
            st[1] += 1

    def retry(self) -> None:
        """Offer the frames the order refused as full (or that wait for the release: key
        groups) again, each source's in its order, as long as one of them goes: one
        source's frame taken may let another's go."""
        moved = True
        while moved:
            moved = False
            for src in self.hold.sources_waiting():
                while (item := self.hold.head(src)) is not None:
                    payload, key, f = item
                    if not self.take(payload, key, f=f, retrying=True):
                        break                     # still full: it stays at the head
                    self.hold.done_head(src)
                    moved = True

    def refetch_behind(self) -> None:
        """Sources we fell behind on: their frames fetched again from their journals, in
        sequence, while there is room (what no journal holds is a gap, said and counted)."""
        for src in [s for s, b in self.behind.items() if b]:
            st = self.seq_of[src]
            while self.hold.bytes < self.max_held() // 4 and not self.hold.waiting_for(src) and self.room():
                n = 0
                for b, key, f in self.journal_frames(src, st[0], st[1], st[1] + REFETCH - 1):
                    if f.seq != st[1]:
                        continue
                    n += 1
                    self.fetched += 1
                    ok = self.take(b, key, f=f)
                    st[1] = f.seq + 1
                    if not ok:
                        break
                if not n:   # the journal has no more (the live edge, or no journal): live frames again
                    self.behind[src] = False
                    self.log(f"source {src}: caught up from its journal to {st[1] - 1}", flush=True)
                    break

    def checks(self, now: float) -> None:
        """The loop's periodic work: refused frames offered again, sources we fell behind on
        fetched again, and early frames that waited past `GAP_WAIT_S` drained."""
        if self.hold.waiting:
            self.retry()
        if self.behind:
            self.refetch_behind()
        for src, since in list(self.hold.gap_since.items()):
            if now - since > GAP_WAIT_S:
                self.drain(src, force=True)

    def catch_up(self, source: str, epoch: int, lo: int, hi: int, take: bool = False) -> int:
        """Frames lo..hi of a source's epoch from its durable journal (srcj/<name>): held
        for `drain`, or (`take`: an epoch that ended with a restart) taken now. How many came."""
        got = 0
        for b, key, f in self.journal_frames(source, epoch, lo, hi):
            got += 1
            if take:
                self.take(b, key, f=f)
            else:
                self.hold.hold_early(source, f.seq, (b, key, f), time.monotonic())
        if got:
            self.fetched += got
            self.log(f"source {source}: {got} frames of epoch {epoch} from its journal", flush=True)
        return got

    def journal_frames(self, source: str, epoch: int, lo: int, hi: int):
        """Frames lo..hi of a source's epoch from its durable journal, each checked as a live
        one; nothing without a session."""
        session = self.session()
        if session is None or lo > hi:
            return
        key = self.ks.src(source)   # the key its live frames come on

        def read(b: bytes):   # checked as a live frame (a bad one counted), once
            f = self.read(b, key)
            return f if f is not None and f.source == source and f.epoch == epoch else None
        asker = self.askers.get(source)
        if asker is None:
            asker = self.askers[source] = Asker()
        for b, f in asker.ask(session, self.ks.srcj(source), epoch, lo, hi, read):
            yield b, key, f
