"""A live peer's intake of sources that publish by key group (`groupframes`): their
group frames kept per source until the progress frame of their flush is in sequence,
then the flush assembled from the groups this EA hears, as one `frames.Frame` that the
peer takes exactly as a whole stream's frame (ordered, journalled, replayed the same).

A progress frame waits (the `Sequencer`'s waiting queue, offered again on every check)
until every heard group of it is here; a heard group's frame missing `GAP_WAIT_S` after
its progress frame came is asked of the source's journal (its whole flush, each message's
group with it), and what no journal holds is a gap, said and counted. A group it does not
hear is never waited for.

Group frames kept for assembly count against the peer's memory bound (`[mesh] max_held_mb`)
with the frames its `Sequencer` holds (`bytes`, the sequencer's `held`): one the bound has
no room for is dropped, counted, and its flush filled from the source's journal, as a
whole stream's frame beyond the bound is fetched again."""
from __future__ import annotations

import time
from typing import Callable

from dissemination.exact import _chunks_match
from dissemination.interest import Interest

from ..protocol import messages as M
from . import frames as F
from . import groupframes as GF
from .sequence import GAP_WAIT_S


class GroupIntake:
    """`hears(group)`: whether this EA hears a group (its subscriptions). `journal(source,
    epoch, lo, hi)`: the source's journal's whole flushes (`Sequencer.journal_frames`)."""

    def __init__(self, ks, max_bytes: int, gate, log, journal: Callable | None = None, streams=None,
                 interest: dict | None = None, room: Callable[[int], bool] | None = None):
        self.ks, self.max_bytes, self.gate, self.log = ks, max_bytes, gate, log
        self.journal = journal
        self.streams = streams   # None: every group is heard
        dis = interest or {}
        self.finder = Interest(ks, float(dis.get("radius_m", 3000.0)), int(dis.get("block_share", 10)))
        self.want: frozenset[str] = frozenset({"**"})   # group expressions heard (relative to a source's prefix)
        self.version = 0                                # bumped when `want` changes (serve re-declares)
        self._match = None
        self._heard: dict[str, bool] = {}
        self.asm: dict[str, GF.Assembler] = {}
        self.waiting_since: dict[tuple[str, int, int], float] = {}
        self.gaps = 0          # group frames never received (beyond recovery and the journal)
        self.filled = 0        # flushes filled from a journal
        self.prefix = ks.src("")
        self.last: dict[str, tuple[int, int, F.Frame]] = {}   # source -> its last flush assembled (offered again)
        # memory: `room(n)` says whether n more bytes may be held (None: no bound); the bytes
        # of the group frames kept, per source and frame, so that what leaves is subtracted
        self.room = room
        self.sizes: dict[str, dict[tuple[int, int, str], int]] = {}
        self.bytes = 0
        self.dropped = 0       # group frames dropped for want of room (their flushes come from a journal)

    def hears(self, group: str) -> bool:
        got = self._heard.get(group)
        if got is None:
            if len(self._heard) >= 8192:
                self._heard.clear()
            got = self._heard[group] = self._match is None or self._match(group)
        return got

    def interest(self, dom) -> frozenset[str]:
        """The groups the EA's interest needs now (`Interest` -> `Streams.subscriptions`):
        what it hears from here on, and what it subscribes to."""
        if self.streams is None:
            return self.want
        want = frozenset(self.streams.subscriptions(self.finder.keys(dom)))
        if want != self.want:
            self.want, self.version = want, self.version + 1
            pats = [tuple(e.split("/")) for e in want]
            self._match = None if "**" in want else (lambda g: any(_chunks_match(p, g.split("/")) for p in pats))
            self._heard = {}
        return want

    def split_key(self, key: str) -> tuple[str, str] | None:
        """(source, group or `PROGRESS`) of a key group's stream; None for a whole stream."""
        if not key.startswith(self.prefix):
            return None
        rest = key[len(self.prefix):]
        if "/" not in rest:
            return None
        name, g = rest.split("/", 1)
        return name, g

    def arrive(self, payload: bytes, key: str, name: str, rest: str):
        """A progress frame (returned, for the sequencer) or a group frame (kept; None).
        Refused (counted, None) when it does not decode or is not of the key's source/group."""
        try:
            x = GF.decode_on(payload, key, name, rest, self.max_bytes)
        except M.MessageError as e:
            self.gate.rejects.add(e, key)
            return None
        if rest == GF.PROGRESS:
            return x
        k = (x.epoch, x.at, x.group)
        sizes = self.sizes.setdefault(name, {})
        if k in sizes:
            return None
        if self.room is not None and not self.room(len(payload)):
            self.dropped += 1   # its flush waits GAP_WAIT_S, then comes from the source's journal
            return None
        self.assembler(name).group(x, len(payload))   # kept even if not heard now: the interest may grow
        sizes[k] = len(payload)
        self.bytes += len(payload)
        return None

    def _forget(self, name: str) -> None:
        """The bytes of the group frames of `name` its assembler no longer holds, subtracted."""
        sizes, kept = self.sizes.get(name), self.asm[name].groups if name in self.asm else {}
        if not sizes:
            return
        for k in [k for k in sizes if k not in kept]:
            self.bytes -= sizes.pop(k)

    def assembler(self, name: str) -> GF.Assembler:
        a = self.asm.get(name)
        if a is None:
            a = self.asm[name] = GF.Assembler(self.hears)
        return a

    def assemble(self, p: GF.Progress) -> F.Frame | None:
        """Flush `p.seq` from the heard groups, or None while one of them is missing (asked
        of the journal once it waited `GAP_WAIT_S`; a gap when no journal holds it)."""
        got = self.last.get(p.source)
        if got is not None and got[:2] == (p.epoch, p.seq):   # assembled before, refused by a full order
            return got[2]
        asm = self.assembler(p.source)
        f = asm.ready(p)
        k = (p.source, p.epoch, p.seq)
        if f is None:
            since = self.waiting_since.setdefault(k, time.monotonic())
            if time.monotonic() - since < GAP_WAIT_S:
                return None
            missing = asm.missing(p)
            whole = None
            if self.journal is not None:
                for _, _, w in self.journal(p.source, p.epoch, p.seq, p.seq):
                    if w.seq == p.seq:
                        whole = w
            if whole is not None:
                f = asm.fill(whole)
                self.filled += 1
            else:
                self.gaps += len(missing)
                self.log(f"source {p.source}: groups {', '.join(missing)[:200]} of its flush {p.seq} never came "
                         f"(its journal: none held): going on without them", flush=True)
                for g in missing:   # what is here of the flush, without them
                    asm.groups[(p.epoch, p.seq, g)] = GF.GroupFrame(v=1, source=p.source, epoch=p.epoch, group=g,
                                                                   seq=p.last[g], at=p.seq)
                f = asm.ready(p)
        self.waiting_since.pop(k, None)
        asm.forget_before(p.epoch, p.seq + 1)
        self._forget(p.source)
        self.last[p.source] = (p.epoch, p.seq, f)
        return f

    def heard_only(self, f: F.Frame) -> F.Frame:
        """A whole flush (a source's journal's, caught up by the sequencer): the groups this
        EA hears, as an assembled flush holds them (the same whether it came live or not)."""
        if f.groups is None:
            return f
        got = self.assembler(f.source).fill(f)
        self._forget(f.source)
        return got
