"""A peer's intake: samples drained from its subscriber channels into the list of
messages waiting for their clock tick, batch by batch, each entry checked like a single
message (seq rules, exact interest, size bound, gate, time, key against content).

A mixin of `Peer` (saim_mesh/peer.py): it reads and writes the peer's state."""
from __future__ import annotations

import bisect
from operator import itemgetter

from dissemination.keyspace import field_mismatch

from . import batch as B
from . import messages as M

_SEQ = itemgetter(0)


class Held(dict):
    """seq -> payload waiting for its tick, and the bytes they hold (bounded by the peer)."""

    def __init__(self):
        super().__init__()
        self.bytes = 0

    def __setitem__(self, seq: int, payload: bytes) -> None:
        old = super().get(seq)
        self.bytes += len(payload) - (len(old) if old is not None else 0)
        super().__setitem__(seq, payload)

    def pop(self, seq: int, default=None):
        v = super().pop(seq, None)
        if v is None:
            return default
        self.bytes -= len(v)
        return v

    def drop(self, seqs) -> None:
        """Forget every one of `seqs` (those fed to the EA at a tick)."""
        pop, n = super().pop, 0
        for q in seqs:
            v = pop(q, None)
            if v is not None:
                n += len(v)
        self.bytes -= n



class Intake:
    """`Peer`'s receiving half: `_drain` at every loop, before the ticks it serves."""

    @property
    def want(self):
        """The exact test of a received key against the EA's fine interest."""
        return self._want

    @want.setter
    def want(self, test) -> None:   # a new interest: what `facts` knew of keys' wanting is stale
        self._want = test
        if (facts := self.__dict__.get("facts")) is not None:
            facts.reset(test)

    def _drain(self, buf: list) -> None:
        """Move received samples into the list of messages waiting for their tick. A
        batch is decoded and each entry taken like a single message; whatever our
        coarse subscriptions let through beyond the EA's exact interest is dropped
        (counted) before decoding."""
        flow, is_batch, gate, trace = self.flow, self.groups.is_batch, self.gate, self.trace
        for sub in self.zsubs.values():
            while (s := sub.try_recv()) is not None:
                key = str(s.key_expr)
                flow["samples"] += 1
                if is_batch(key):
                    try:
                        entries = B.decode(s.payload.to_bytes(), gate.max_bytes).entries
                    except M.MessageError as e:   # counted whole
                        gate.rejects.add(e, key)
                        continue
                    flow["batches"] += 1
                    flow["entries"] += len(entries)
                    if trace is not None:
                        trace.extend(e[0] for e in entries if 0 < e[0] < 2**32)
                    self._take_entries(entries, buf, key)
                    continue
                att = s.attachment
                seq = None
                if att is not None:
                    raw = att.to_bytes()
                    seq = int.from_bytes(raw, "big") if len(raw) == 8 else -1
                    if seq < 0:
                        self._reject("?", "(seq)", f"attachment of {len(raw)} bytes is no sequence number", key)
                        continue
                    if trace is not None and 0 < seq < 2**32:
                        trace.append(seq)
                self._take(seq, key, s.payload.to_bytes(), buf)

    def _take(self, seq: int | None, key: str, payload: bytes, buf: list) -> None:
        """One message. A sequenced one is a batch of one (`_take_entries` has every
        rule); one outside the replay's sequence (a fused track) passes the same checks
        of interest, time and key, and is held until its time comes."""
        if seq is not None:
            self._take_entries([(seq, key, payload)], buf)
            return
        if not self.facts.of(key).wanted:   # `want` keeps no answers: `facts` does
            self.flow["dropped"] += 1
            return
        m = self.gate.data(payload, key)
        if m is None:
            return
        if m.t > self.clock_t + self.max_ahead:
            self._defer(m.t)   # not held; fetched from its fusion node when due
            return
        if (why := self.ks.mismatch(key, m)) is not None:
            self._reject(m.KIND, "(key)", why, key)
            return
        self._hold(m)

    def _take_entries(self, entries: list[tuple[int, str, bytes]], buf: list, batch: str | None = None) -> None:
        """A batch's entries (received on group key `batch`), each in turn: the per-report
        hot path, one `KeyFacts` lookup per entry. An entry on a key outside its batch's
        group is counted and left out. A seq that came with two different payloads is
        contested and settled by the store; a message that does not belong on its key,
        is rejected; one dated more than `max_ahead_s` ahead of the clock is deferred: not
        held, fetched from the store once the clock comes within reach. `buf` takes
        (seq, message) in arrival order: `_due` sorts it at the tick."""
        pending, data, facts = self.pending, self.gate.data, self.facts
        known, learn, gen, epoch = facts.get, facts.learn, facts.gen, facts.epoch
        held = super(Held, pending).__setitem__
        last = self.last_seq
        hi = self.tick_seq + self.max_seq_ahead
        t_hi = self.clock_t + self.max_ahead
        seen_t = self.seen_t
        add = buf.append
        dropped = 0
        for seq, key, payload in entries:
            f = known(key)
            if f is None or f.gen != gen:
                f = learn(key)
            else:
                f.seen = epoch
            if batch is not None and f.group != batch:
                self.gate.rejects.add(B.foreign(key, batch), batch)
                continue
            if seq <= last:
                continue
            prev = pending.get(seq)
            if prev is not None:
                if prev != payload:
                    self.contested.add(seq)
                continue
            if seq > hi:
                self._reject("?", "(seq)", f"seq {seq} is more than {self.max_seq_ahead} ahead of the "
                             f"clock's {self.tick_seq}", key)
                continue
            if not f.wanted:
                dropped += 1
                continue
            if pending.bytes + len(payload) > self.max_held:
                self._evict(buf)
            m = data(payload, key)
            if m is None:
                continue
            if m.t > t_hi:
                self._defer(m.t)   # not held; fetched from the store when due
                continue
            attrs, values = (f.attrs, f.values) if f.cls is type(m) else facts.checks(f, key, type(m))
            why = values if attrs is None else field_mismatch(zip(attrs, values), m) if attrs else None
            if why is not None:
                self._reject(m.KIND, "(key)", why, key)
                continue
            held(seq, payload)
            pending.bytes += len(payload)
            add((seq, m))
            if m.t > seen_t:
                seen_t = m.t
        self.seen_t = seen_t
        self.flow["dropped"] += dropped

    def _due(self, buf: list, upto: int) -> list:
        """The held (seq, message) pairs up to seq `upto`, in seq order, taken out of `buf`
        (one sort of mostly ordered runs per tick, not a heap operation per report)."""
        if not buf:
            return []
        buf.sort(key=_SEQ)
        i = bisect.bisect_right(buf, upto, key=_SEQ)
        ready = buf[:i]
        del buf[:i]
        self.pending.drop(q for q, _ in ready)
        return ready

    def _defer(self, t: float) -> None:
        """A message dated more than `max_ahead_s` ahead of our clock: a peer that fell
        behind (stalled in a fusion grace at a high replay speed) must never lose real data,
        nor hold an unbounded amount of it. Not held; when the clock comes within
        `max_ahead_s` of the earliest such time, everything on our keys after the last
        message taken is fetched again (`_on_tick`). Forged data is not in the store."""
        self.flow["deferred"] = self.flow.get("deferred", 0) + 1
        if t < self.defer_t:
            self.defer_t = t
        if self.clock_t < self.defer_from:
            self.defer_from = self.clock_t

    def _evict(self, buf: list) -> None:
        """Held messages passed `max_held_mb` (a flood of plausible junk): drop every one
        not yet due; when their ticks come, the store gives back the real ones."""
        due = self.tick_seq
        for q in [q for q in self.pending if q > due]:
            self.pending.pop(q)
        buf[:] = [(q, m) for q, m in buf if q <= due]
        if not self.evicted:
            self._reject("?", "(held)", f"over {self.max_held >> 20} MB of messages waiting for their tick: "
                         f"dropped, to be taken from the store", "")
        self.evicted = True

    def _settle(self, buf: list, upto: int) -> None:
        """Contested seqs (junk that carried a real message's number) take the store's version."""
        now = sorted(q for q in self.contested if q <= upto)
        if not now:
            return
        # every one said (up to 64 a tick: a flood of junk makes no unbounded line)
        self.log(f"contested seqs {now[:64]}{'...' if len(now) > 64 else ''}: taking the store's version", flush=True)
        _, entries = self._query_store(now[0] - 1, sorted(self.subs))
        truth = {seq: p for seq, p in entries if seq in self.contested}
        keep = [(q, m) for q, m in buf if q not in self.contested or q > upto]
        for q in now:
            self.contested.discard(q)
            self.pending.pop(q, None)
            if q in truth and (m := self.gate.data(truth[q], "store")) is not None:
                self.pending[q] = truth[q]
                keep.append((q, m))
        buf[:] = keep
