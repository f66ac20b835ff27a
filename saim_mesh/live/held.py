"""The frames a live peer keeps outside the event-time order, and the memory they take.

Two kinds, per source: *early* frames (one came ahead of a missing seq: it waits for it,
from recovery, the publisher's cache or the source's journal) and *waiting* frames (the
order was full: offered again, in sequence, once it has room). Their bytes are counted in
one place (`bytes`), which the peer's memory bound (`[mesh] max_held_mb`) is checked
against; nothing else adds or subtracts them."""
from __future__ import annotations

from collections import deque

Item = tuple   # (payload, key, frame)


class Held:
    def __init__(self, per_source: int):
        self.per_source = per_source
        self.early: dict[str, dict[int, Item]] = {}
        self.waiting: dict[str, deque[Item]] = {}
        self.gap_since: dict[str, float] = {}   # source -> when its oldest early frame began to wait
        self.bytes = 0

    # -- early frames ---------------------------------------------------------------------
    def early_of(self, src: str) -> dict[int, Item]:
        return self.early.setdefault(src, {})

    def reset_early(self, src: str) -> None:
        """A new epoch of the source: what waited for the old one's sequence goes."""
        old = self.early.pop(src, {})
        self.bytes -= sum(len(x[0]) for x in old.values())
        self.gap_since.pop(src, None)

    def hold_early(self, src: str, seq: int, item: Item, now: float) -> bool:
        """Keep a frame that came ahead of `seq`s missing before it (False: the source's
        share is full, dropped: it is fetched again or becomes a gap)."""
        early = self.early_of(src)
        if seq in early:
            return True
        if len(early) >= self.per_source:
            return False
        early[seq] = item
        self.bytes += len(item[0])
        self.gap_since.setdefault(src, now)
        return True

    def pop_early(self, src: str, seq: int) -> Item | None:
        early = self.early.get(src)
        item = early.pop(seq, None) if early else None
        if item is not None:
            self.bytes -= len(item[0])
        if not early:
            self.gap_since.pop(src, None)
        return item

    # -- frames the full order refused ------------------------------------------------------
    def waiting_for(self, src: str) -> bool:
        return bool(self.waiting.get(src))

    def wait(self, src: str, item: Item) -> None:
        self.waiting.setdefault(src, deque()).append(item)
        self.bytes += len(item[0])

    def head(self, src: str) -> Item | None:
        q = self.waiting.get(src)
        return q[0] if q else None

    def done_head(self, src: str) -> None:
        item = self.waiting[src].popleft()
        self.bytes -= len(item[0])

    def sources_waiting(self) -> list[str]:
        return [s for s, q in self.waiting.items() if q]

    def take_waiting(self) -> dict[str, deque[Item]]:
        """Every waiting frame, handed back (a rebuilt EA offers them again after its journal)."""
        out, self.waiting = self.waiting, {}
        self.bytes -= sum(len(x[0]) for q in out.values() for x in q)
        return out
