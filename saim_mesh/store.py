"""The situation store's memory: every (seq, payload) the replay published, kept in
a file rather than as Python objects, so the replay's resident memory no longer grows
with the run (12 bytes of index per message instead of ~100 bytes of tuples, ints
and list slots beside each payload). Reads are `pread`s: a catch-up answer costs
what it returns, from the page cache.

`Log` answers like the list of `(seq, payload)` it replaces (append, len, index,
slice); `KeyIndex` like the dict of key -> seqs (`setdefault(k, []).append(n)`),
with the seqs packed in 4-byte arrays."""
from __future__ import annotations

import os
import tempfile
from array import array


class Log:
    def __init__(self, directory: str | None = None):
        self._f = tempfile.TemporaryFile(prefix="saim-store-", dir=directory)   # unlinked: gone with us
        self._fd = self._f.fileno()
        self._ends = array("Q")   # entry n ends at _ends[n - 1]; seqs are positions (seq n is entry n)
        self._size = 0

    def append(self, entry: tuple[int, bytes]) -> None:
        seq, payload = entry
        if seq != len(self._ends) + 1:
            raise ValueError(f"store entry {seq} appended after {len(self._ends)}: seqs must follow each other")
        os.pwrite(self._fd, payload, self._size)
        self._size += len(payload)
        self._ends.append(self._size)

    def __len__(self) -> int:
        return len(self._ends)

    def _one(self, i: int) -> tuple[int, bytes]:
        start = self._ends[i - 1] if i else 0
        return i + 1, os.pread(self._fd, self._ends[i] - start, start)

    def __getitem__(self, i):
        if isinstance(i, slice):
            lo, hi, step = i.indices(len(self._ends))
            if step != 1 or lo >= hi:
                return [self._one(j) for j in range(lo, hi, step)]
            start = self._ends[lo - 1] if lo else 0
            blob = os.pread(self._fd, self._ends[hi - 1] - start, start)   # one read for the whole range
            out, pos = [], 0
            for j in range(lo, hi):
                end = self._ends[j] - start
                out.append((j + 1, blob[pos:end]))
                pos = end
            return out
        n = len(self._ends)
        if i < 0:
            i += n
        if not 0 <= i < n:
            raise IndexError("store index out of range")
        return self._one(i)

    def __iter__(self):
        return iter(self[:])

    @property
    def nbytes(self) -> int:
        """Resident bytes of the index (the payloads are in the file)."""
        return self._ends.itemsize * len(self._ends)

    def close(self) -> None:
        self._f.close()


class KeyIndex(dict):
    """key -> its seqs in order, packed (`setdefault`'s default is ignored: always an array)."""

    def setdefault(self, key: str, default=None) -> array:
        got = self.get(key)
        if got is None:
            got = self[key] = array("I")
        return got

    @property
    def nbytes(self) -> int:
        return sum(a.itemsize * len(a) for a in self.values())
