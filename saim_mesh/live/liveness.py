"""Whether the sources an EA depends on are still there (issue 31.3), on the wall clock:
when each was last heard, how far its frames promised, whether it ended. Silence is only
noticed here; declaring a source lost is the peer's decision, written to its input journal
so that a replay decides the same (`LivePeer.lose`)."""
from __future__ import annotations

import math
import time


class SourceWatch:
    def __init__(self, sources: list[str], silence_s: float, join_s: float, end_wait_s: float = 0.0):
        self.sources = sources
        self.silence_s = silence_s           # wall seconds a heard source may be silent
        self.join_s = join_s                 # ... one never heard, from the start
        self.end_wait_s = end_wait_s         # ... a lost one, once every other has ended
        self.rest_ended: float | None = None   # wall time every source not lost had ended
        self.heard: dict[str, float] = {}    # source -> wall time (monotonic) of its last frame
        self.promised: dict[str, float] = {}   # source -> the furthest watermark its frames gave
        self.ended: set[str] = set()
        self.started = time.monotonic()

    def heard_from(self, source: str) -> None:
        """A frame came (kept or not: the source is not silent)."""
        self.heard[source] = time.monotonic()

    def arrived(self, source: str, now: float | None = None) -> None:
        """A frame of `source` came off the wire (called on the subscriber's thread): the
        source is not silent, even while the EA is still busy with a backlog before it."""
        self.heard[source] = time.monotonic() if now is None else now

    def took(self, f) -> None:
        """A frame taken: its promise, and its end."""
        self.promised[f.source] = max(self.promised.get(f.source, -1.0), f.wm)   # finite, also in its last frame
        self.heard[f.source] = time.monotonic()
        if f.end:
            self.ended.add(f.source)

    def silent(self, now: float, order):
        """The depended sources, not ended nor lost, silent past their limit, whose promise
        holds the EA back: (source, why) for each, one at a time against the order as it is
        then (declaring one lost can release the EA past another's promise)."""
        for src in self.sources:
            if src in self.ended or src in order.lost:
                continue
            last = self.heard.get(src)
            quiet, limit = (now - self.started, self.join_s) if last is None else (now - last, self.silence_s)
            if quiet > limit and not self.promised.get(src, -math.inf) > order.released:
                yield src, (f"silent for {quiet:.0f} s" if last is not None else f"never heard in {quiet:.0f} s")

    def furthest(self) -> list[float]:
        """Every finite watermark promised."""
        return [w for w in self.promised.values() if math.isfinite(w)]

    def all_ended(self, lost) -> bool:
        """Every source ended, or ended and lost ones (at least one ended: a mesh where
        every source is silent keeps waiting for them)."""
        return bool(self.ended) and set(self.sources) <= self.ended | set(lost)

    def finished(self, lost, now: float) -> bool:
        """All ended (`all_ended`), and a lost source not ended given `end_wait_s` from
        then to come back: a link healed near the end still brings what it held, a source
        gone for good does not hold the EA for ever."""
        if not self.all_ended(lost):
            self.rest_ended = None
            return False
        if set(self.sources) <= self.ended:
            return True
        if self.rest_ended is None:
            self.rest_ended = now
        return now - self.rest_ended >= self.end_wait_s
