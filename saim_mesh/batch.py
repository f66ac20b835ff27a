"""Reports of one key group and clock tick in one message (`dissemination/groups.py`).

The replay feeds every scripted report to a `Batcher` and flushes it before each
clock tick: a batched family's reports go out as one `Batch` per group, others
(sensor hits, orders, reorganizations, mission confirmations, calls for fire, fused
tracks) stay single and go out at once. Each entry keeps its own seq and key, so the
situation store, catch-up queries and seq dedup work per entry as before; a
receiver checks every entry like a single message (`unpack`, then the peer's own
seq rules and gate).
"""
from __future__ import annotations

from typing import Annotated

import msgspec
import zenoh

from dissemination.groups import GROUP_DEPTH, Groups
from dissemination.keyspace import template

from . import messages as M
from . import gate as G
from . import wire as W

MAX_ENTRIES = 4096
ENTRY_OVERHEAD = 24      # msgpack framing of one (seq, key, payload) entry, generously
Key = Annotated[str, msgspec.Meta(min_length=1, max_length=W.KEY_LIMIT)]


class Batch(W._Wire, kw_only=True):
    """(seq, key, payload) entries of one group, in seq order."""
    entries: Annotated[list[tuple[W.Seq, Key, bytes]], msgspec.Meta(min_length=1, max_length=MAX_ENTRIES)]


_DECODER = msgspec.msgpack.Decoder(Batch)


def groups_of(root: str, depth: int = GROUP_DEPTH) -> Groups:
    """The group layout of every registered message class with a key template (`depth`:
    `group_depth` of the scenario's task organization; replay and peers must agree)."""
    tpls = {}
    for cls in M.MESSAGE_TYPES.values():
        if getattr(cls, "KEY", None):
            t = template(cls)
            tpls.setdefault(t.family, t)
    return Groups(root, tpls, depth)


def decode(payload: bytes, max_bytes: int) -> Batch:
    """A batch, or MessageError naming what is wrong (size, shape, order)."""
    if len(payload) > max_bytes:
        raise M.MessageError("batch", "(bytes)", f"{len(payload)} bytes, over the {max_bytes} limit")
    try:
        b = _DECODER.decode(payload)
    except (msgspec.ValidationError, msgspec.DecodeError) as e:
        raise M.MessageError("batch", "(message)", str(e)[:200]) from None
    except Exception as e:   # a decoder bug must not kill a peer
        raise M.MessageError("batch", "(message)", f"undecodable: {type(e).__name__}") from None
    prev = -1
    for seq, _, _ in b.entries:
        if seq <= prev:
            raise M.MessageError("batch", "entries", f"seq {seq} after {prev}: not in increasing order")
        prev = seq
    return b


def unpack(gate: G.Gate, groups: Groups, payload: bytes, key: str) -> list[tuple[int, str, bytes]]:
    """The entries of a batch received on `key`, each on a key of that group; a bad
    batch is counted whole, an entry on a foreign key is counted and left out."""
    try:
        b = decode(payload, gate.max_bytes)
    except M.MessageError as e:
        gate.rejects.add(e, key)
        return []
    out = []
    for seq, k, p in b.entries:
        if groups.group(k) != key:
            gate.rejects.add(foreign(k, key), key)
            continue
        out.append((seq, k, p))
    return out


def foreign(entry_key: str, batch_key: str) -> M.MessageError:
    """An entry on a key outside the group its batch came on (counted, left out)."""
    return M.MessageError("batch", "(key)", f"entry key {entry_key[:80]!r} is not of group {batch_key[:80]!r}")


class Batcher:
    """Holds a tick's batched reports per group; `flush` sends them (before the tick)."""

    def __init__(self, session, groups: Groups, max_bytes: int = 65536,
                 congestion_control=zenoh.CongestionControl.BLOCK):
        self.s, self.groups, self.max_bytes, self.cc = session, groups, max_bytes, congestion_control
        self.open: dict[str, list[tuple[int, str, bytes]]] = {}
        self.size: dict[str, int] = {}
        self.pubs: dict[str, object] = {}
        self.sent = 0       # batch messages
        self.entries = 0    # reports in them

    def add(self, key: str, seq: int, payload: bytes) -> bool:
        """Take a report into its group's batch; False when its family stays single."""
        g = self.groups.group(key)
        if g is None:
            return False
        cost = len(payload) + len(key) + ENTRY_OVERHEAD
        if g in self.open and (self.size[g] + cost > self.max_bytes - 64 or len(self.open[g]) >= MAX_ENTRIES):
            self._send(g)
        self.open.setdefault(g, []).append((seq, key, payload))
        self.size[g] = self.size.get(g, 16) + cost
        return True

    def flush(self) -> None:
        """Send every open batch (call before publishing a clock tick)."""
        for g in list(self.open):
            self._send(g)

    def _send(self, g: str) -> None:
        entries = self.open.pop(g)
        self.size.pop(g, None)
        pub = self.pubs.get(g)
        if pub is None:
            pub = self.pubs[g] = self.s.declare_publisher(g, congestion_control=self.cc)
        pub.put(W.encode(Batch(v=W.VERSION, entries=entries)))
        self.sent += 1
        self.entries += len(entries)


