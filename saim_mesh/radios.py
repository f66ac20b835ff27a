"""The replay stands in for the robots' radios: a message a unit's own systems send
(a robot's state, its sightings) goes out only while that unit's EA peer lives. A
robot whose process dies falls silent, as a robot that loses power does, and its
teammates' EAs notice (no-status). Units that never joined are not silenced: their
messages are the scenario's, as SAIM's reports are for SUO.

Liveliness samples are hints, not the truth: a token is tracked by its full key (a
listing may name one token twice), a DELETE is confirmed by asking who is alive now
(a peer's tokens can be withdrawn when a neighbour that relayed them dies), and the
set is reconciled with such a query every RESYNC_S of scenario time, so a lost
DELETE is noticed too."""
from __future__ import annotations

from typing import Callable

import zenoh

RESYNC_S = 20.0
QUERY_S = 1.0


class Radios:
    def __init__(self, s, ks, source_of: Callable[[object], str | None], log=print):
        self.s, self.ks, self.source_of, self.log = s, ks, source_of, log
        self.sub = s.liveliness().declare_subscriber(ks.alive("*", "*"), zenoh.handlers.FifoChannel(4096))
        self.dead: set[str] = set()
        self.silenced = 0
        self.keys: set[tuple[str, str]] = self._query("*") or set()   # (unit, zid) of every live token
        self.next_sync = RESYNC_S

    def _query(self, unit: str) -> set[tuple[str, str]] | None:
        """Tokens alive now (of `unit`, or all for "*"); None when the query failed."""
        try:
            out = set()
            for r in self.s.liveliness().get(self.ks.alive(unit, "*"), timeout=QUERY_S):
                if r.ok is not None:
                    u, z = self.ks.last(str(r.ok.key_expr), 2)
                    out.add((u, z))
            return out
        except zenoh.ZError:
            return None

    def _units(self) -> set[str]:
        return {u for u, _ in self.keys}

    def _up(self, unit: str, t: float) -> None:
        if unit in self.dead:
            self.dead.discard(unit)
            self.log(f"radio {unit} back t={t:.1f}", flush=True)

    def _gone(self, unit: str, t: float) -> None:
        """`unit` has no token left as far as the samples say: ask before silencing it."""
        now = self._query(unit)
        if now:
            self.keys |= now   # withdrawn by a relay, still there
            return
        if unit not in self.dead:
            self.dead.add(unit)
            self.log(f"radio {unit} silent t={t:.1f}", flush=True)

    def _take(self, t: float) -> None:
        while (a := self.sub.try_recv()) is not None:
            u, z = self.ks.last(str(a.key_expr), 2)
            if a.kind == zenoh.SampleKind.PUT:
                self.keys.add((u, z))
                self._up(u, t)
            else:
                self.keys.discard((u, z))
                if u not in self._units():
                    self._gone(u, t)
        if t >= self.next_sync:
            self.next_sync = t + RESYNC_S
            now = self._query("*")
            if now is not None:
                lost = self._units() - {u for u, _ in now}
                self.keys = now
                for u in {u for u, _ in now}:
                    self._up(u, t)
                for u in sorted(lost):
                    self._gone(u, t)

    def silent(self, ev) -> bool:
        """Whether `ev` is not sent because its source's peer is gone."""
        self._take(ev.t)
        u = self.source_of(ev)
        if u is not None and u in self.dead:
            self.silenced += 1
            return True
        return False
