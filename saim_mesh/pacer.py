"""The max-speed replay's pacing: stay a window of scenario time ahead of the slowest
EA peer, waking on its acks and tokens (`inbox.py`) instead of polling."""
from __future__ import annotations

import time

import zenoh

from dissemination.keyspace import KeySpace

from . import gate as G

from . import wire as W
from .inbox import Waker


class Pacer:
    """At max speed, keep the replay at most `window_s` of scenario time ahead of what the
    slowest EA peer has taken in (a peer acks ticks as it takes them, before working
    through them: up to two windows ahead of what it has processed). Without it the replay runs far ahead: tens of thousands of messages
    sit in flight, a catch-up answer queues behind them, and peers' memory fills up.

    EA peers (liveliness tokens of task-organization units; fusion nodes do not count)
    are waited for from the moment they appear until they report progress
    (`ack/<zid>`), and stop counting when their token goes or when they make no
    progress for `stall_s` of wall time."""

    def __init__(self, s, ks: KeySpace, window_s: float, serve, log, gate: G.Gate, box, stall_s: float = 30.0):
        """`box`: `Replay.inbox`, so that an ack or a token wakes the wait."""
        self.window_s, self.serve, self.log, self.stall_s, self.gate = window_s, serve, log, stall_s, gate
        self.ks = ks
        self.acks = box("acks", 100_000, s.declare_subscriber, ks.ack("*", "*"))
        self.alive = box("alive", 1024, s.liveliness().declare_subscriber, ks.alive("*", "*"), history=True)
        self.waker: Waker = self.acks.waker
        self.live: set[str] = set()          # EA peers, as "<unit>/<zid>"
        for r in s.liveliness().get(ks.alive("*", "*"), timeout=2.0):   # those here now, for sure
            if r.ok is not None and (p := self._ea(str(r.ok.key_expr))):
                self.live.add(p)
        self.done: dict[str, float] = {}     # peer -> last tick it took in
        self.moved = {z: time.monotonic() for z in self.live}   # peer -> wall time of its last progress
        self.ignored: set[str] = set()

    def _ea(self, key: str) -> str | None:
        """'<unit>/<zid>' of an EA peer's key (fusion nodes and the replay do not ack)."""
        unit_zid = self.ks.last(key, 2)
        if len(unit_zid) != 2 or unit_zid[0].startswith("fusion-") or unit_zid[0] == "replay":
            return None
        return "/".join(unit_zid)

    def _take(self) -> None:
        while (a := self.alive.try_recv()) is not None:
            p = self._ea(str(a.key_expr))
            if p is None:
                continue
            if a.kind == zenoh.SampleKind.PUT:
                self.live.add(p)
                self.moved.setdefault(p, time.monotonic())
            else:
                self.live.discard(p)
        while (a := self.acks.try_recv()) is not None:
            key = str(a.key_expr)
            ack = self.gate.control(W.Ack, a.payload.to_bytes(), key)
            p = self._ea(key)
            if ack is None or p is None:
                continue
            self.done[p] = max(self.done.get(p, -1.0), ack.t)
            self.moved[p] = time.monotonic()
            if p in self.ignored:   # it moves again (a link healed): wait for it again
                self.ignored.discard(p)
                self.log(f"pacing: peer {p} is making progress again", flush=True)

    def wait(self, t: float) -> None:
        need = t - self.window_s
        while True:
            self._take()
            behind = [z for z in self.live - self.ignored if self.done.get(z, -1.0) < need]
            if not behind:
                return
            now = time.monotonic()
            for z in behind:
                if now - self.moved[z] > self.stall_s:
                    self.log(f"pacing: peer {z} made no progress for {self.stall_s:.0f} s; not waiting for it",
                             flush=True)
                    self.ignored.add(z)
            self.serve()
            self.waker.wait(0.05)   # an ack, a token or a query wakes us; the timeout notices a stall
