"""The replay's script, compactly: every event to publish with its key, payload and
source, in order, worked out before the clock starts.

As a list of `(event, key, payload, source)` tuples it cost about 250 bytes per event
beside the event itself: a tuple, a bytes object and a key string each time, though an
entity's key repeats in every report until it changes cell. A brigade has 754k events:
that list took 266 MB beside the loaded scenario, this takes 121 MB. Here the keys and sources are
shared strings, and the payloads sit in one buffer with an end offset each. Reading
gives the same tuples, built as they are read.
"""
from __future__ import annotations

from array import array
from collections.abc import Iterator


class Script:
    """`(event, key, payload, source)` by index, like the list it replaces (`len`,
    indexing, slicing, iteration); `since` iterates from an index without a copy."""

    def __init__(self):
        self.events: list = []
        self.keys: list[str] = []
        self.sources: list[str] = []
        self._shared: dict[str, str] = {}
        self._buf = bytearray()
        self._blob: bytes | None = None     # the payloads, once `close`d
        self._ends = array("Q")             # payload i ends at _ends[i]

    def append(self, event, key: str, payload: bytes, source: str) -> None:
        if self._blob is not None:
            raise ValueError("the script is closed: nothing can be added to it")
        shared = self._shared
        self.events.append(event)
        self.keys.append(shared.setdefault(key, key))
        self.sources.append(shared.setdefault(source, source))
        self._buf += payload
        self._ends.append(len(self._buf))

    def close(self) -> Script:
        """Done adding: the payloads become one immutable buffer (read by slicing)."""
        if self._blob is None:
            self._blob, self._buf = bytes(self._buf), bytearray()
            self._shared = {}
        return self

    def __len__(self) -> int:
        return len(self.events)

    def payload(self, i: int) -> bytes:
        blob = self.close()._blob
        return blob[self._ends[i - 1] if i else 0:self._ends[i]]

    def __getitem__(self, i):
        if isinstance(i, slice):
            lo, hi, step = i.indices(len(self))
            return list(self.since(lo, hi)) if step == 1 else [self[j] for j in range(lo, hi, step)]
        n = len(self)
        if i < 0:
            i += n
        if not 0 <= i < n:
            raise IndexError("script index out of range")
        return self.events[i], self.keys[i], self.payload(i), self.sources[i]

    def since(self, start: int = 0, stop: int | None = None) -> Iterator[tuple]:
        """The entries from index `start` (to `stop`), in order."""
        blob, ends = self.close()._blob, self._ends
        evs, keys, srcs = self.events, self.keys, self.sources
        stop = len(evs) if stop is None else min(stop, len(evs))
        lo = ends[start - 1] if 0 < start <= len(ends) else 0
        for i in range(max(0, start), stop):
            hi = ends[i]
            yield evs[i], keys[i], blob[lo:hi], srcs[i]
            lo = hi

    def __iter__(self) -> Iterator[tuple]:
        return self.since(0)
