"""Flow control for a source replaying as fast as possible (issue 31.2: "a max-speed replay
paces each source only against the EAs that subscribe to it"): nothing but BLOCK would
otherwise hold it back, and BLOCK closes a transport after 5 s, so a source that outruns
its slowest EA loses frames between routers and fills that EA's queue.

Each EA says how far it has got on `ack/<unit>/<source>` for every source it depends on
(`EaProgress`: when its released event time has moved `ACK_EVERY_S` on, so a few per
minute of event time). The source (`SourcePace`) hears only the acks of the EAs that
depend on it (the key names it: interest routing keeps the others' acks off its links)
and goes at most `LEAD_S` of event time past the slowest of them (Flink's credit-based
back pressure, in event time). An EA not heard for `STALE_S` of wall time (gone, cut off,
or no longer keeping up because another source holds it) no longer holds the source back:
a cut link or a dead EA stops nobody else. Before it waits, the source flushes what it
holds, so every EA can reach what the source allows (no deadlock: each waiting source has
promised up to at least the slowest EA's progress plus `LEAD_S` less an epoch). While it
waits it beats every `BEAT_S` (an empty frame, its watermark unchanged): an EA that has
taken all it promised would otherwise take a source held back by a slower EA for a
silent one, declare it lost and rebuild when it speaks again (the brigade at max speed
did, twice, in a fault-free run)."""
from __future__ import annotations

import math
import threading
import time

from ..protocol import messages as M
from ..protocol import gate as G
from ..protocol import wire as W

LEAD_S = 120.0        # event seconds a source may run ahead of the slowest EA depending on it
ACK_EVERY_S = 30.0    # event seconds between an EA's acks (and its first release)
STALE_S = 5.0         # wall seconds after which an EA's last ack no longer holds a source back
FIRST_S = 5.0         # wall seconds a source waits, past its first LEAD_S, for a first ack
BEAT_S = 2.0          # wall seconds between a waiting source's heartbeats (well inside `source_silence_s`)


class SourcePace:
    """The event time up to which a source may publish: the slowest fresh ack plus `LEAD_S`
    (unbounded once no EA acks at all). Thread-safe: acks arrive on Zenoh's threads."""

    def __init__(self, session, ks, name: str, lead_s: float = LEAD_S, stale_s: float = STALE_S,
                 first_s: float = FIRST_S, log=print, beat_s: float = BEAT_S):
        self.lead_s, self.stale_s, self.first_s, self.log = lead_s, stale_s, first_s, log
        self.beat_s = beat_s
        self.beats = 0
        self.acks: dict[str, tuple[float, float]] = {}   # unit -> (event time, wall time heard)
        self.cv = threading.Condition()
        self.limit = lead_s          # allowed without asking again
        self.waits = 0
        self.waited_s = 0.0
        self.rejects = G.Rejects(log)
        self.unpaced = False         # no EA ever acked within FIRST_S: the source went on unpaced
        self.blocked = threading.Event()   # set while it waits (for whoever watches it: a test) ...
        self.blocked_t = -math.inf         # ... for this event time
        self.sub = session.declare_subscriber(ks.ack("*", name), self._heard)

    def _heard(self, smp) -> None:
        key = str(smp.key_expr)
        try:
            a = W.decode_control(W.Ack, smp.payload.to_bytes(), 256)
        except M.MessageError as e:
            self.rejects.add(e, key)
            return
        unit = key.rsplit("/", 2)[-2]
        with self.cv:
            self.acks[unit] = (float(a.t), time.monotonic())
            self.cv.notify_all()

    def allowed(self, now: float | None = None) -> float:
        """Event time the source may publish up to now (+inf: nobody holds it back)."""
        now = time.monotonic() if now is None else now
        fresh = [t for t, heard in self.acks.values() if now - heard <= self.stale_s]
        if not fresh:
            return math.inf if self.acks or self.unpaced else self.lead_s
        return min(fresh) + self.lead_s

    def wait(self, t: float, flush, beat=None) -> None:
        """Return once event time `t` may be published; `flush()` first if it must wait,
        `beat()` every `beat_s` while it waits (called outside the lock: it publishes)."""
        if t <= self.limit:
            return
        with self.cv:
            self.limit = self.allowed()
        if t <= self.limit:
            return
        flush()
        t0 = last = time.monotonic()
        while True:
            with self.cv:
                self.blocked_t = t
                self.blocked.set()
                self.cv.notify_all()
                while t > (lim := self.allowed()):
                    if not self.acks and time.monotonic() - t0 > self.first_s:
                        self.unpaced = True
                        self.log(f"no EA acknowledged in {self.first_s:.0f} s: the source goes on unpaced", flush=True)
                        continue
                    if beat is not None and time.monotonic() - last >= self.beat_s:
                        break
                    self.cv.wait(timeout=min(0.1, self.beat_s))
                else:
                    self.limit = lim
                    self.blocked.clear()
                    break
            beat()
            self.beats += 1
            last = time.monotonic()
        self.waits += 1
        self.waited_s += time.monotonic() - t0

    def close(self) -> None:
        self.sub.undeclare()


class EaProgress:
    """An EA's acks: its released event time, on `ack/<unit>/<source>` for each source it
    depends on, first once it releases anything, then every `ACK_EVERY_S` of event time."""

    def __init__(self, ks, unit: str, every_s: float = ACK_EVERY_S):
        self.ks, self.unit, self.every_s = ks, unit, every_s
        self.last = -math.inf
        self.sent = 0

    def due(self, released: float) -> bool:
        return math.isfinite(released) and released >= self.last + self.every_s

    def send(self, session, released: float, sources) -> None:
        """Acks for `released` when due (nothing otherwise)."""
        if session is None or not self.due(released):
            return
        self.last = released
        payload = W.encode(W.make(W.Ack, t=released))
        for s in sources:
            session.put(self.ks.ack(self.unit, s), payload)
            self.sent += 1
