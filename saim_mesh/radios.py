"""The replay stands in for the robots' radios: a message a unit's own systems send
(a robot's state, its sightings) goes out only while that unit's EA peer lives. A
robot whose process dies falls silent, as a robot that loses power does, and its
teammates' EAs notice (no-status). Units that never joined are not silenced: their
messages are the scenario's, as SAIM's reports are for SUO."""
from __future__ import annotations

from collections import Counter
from typing import Callable

import zenoh


class Radios:
    def __init__(self, s, ks, source_of: Callable[[object], str | None], log=print):
        self.ks, self.source_of, self.log = ks, source_of, log
        self.sub = s.liveliness().declare_subscriber(ks.alive("*", "*"), zenoh.handlers.FifoChannel(4096))
        self.live: Counter = Counter()   # unit -> live peers
        self.dead: set[str] = set()
        self.silenced = 0
        for r in s.liveliness().get(ks.alive("*", "*"), timeout=2.0):
            if r.ok is not None:
                self.live[ks.last(str(r.ok.key_expr), 2)[0]] += 1

    def _take(self, t: float) -> None:
        while (a := self.sub.try_recv()) is not None:
            unit = self.ks.last(str(a.key_expr), 2)[0]
            if a.kind == zenoh.SampleKind.PUT:
                self.live[unit] += 1
                if unit in self.dead:
                    self.dead.discard(unit)
                    self.log(f"radio {unit} back t={t:.1f}", flush=True)
            else:
                self.live[unit] = max(0, self.live[unit] - 1)
                if self.live[unit] == 0 and unit not in self.dead:
                    self.dead.add(unit)
                    self.log(f"radio {unit} silent t={t:.1f}", flush=True)

    def silent(self, ev) -> bool:
        """Whether `ev` is not sent because its source's peer is gone."""
        self._take(ev.t)
        u = self.source_of(ev)
        if u is not None and u in self.dead:
            self.silenced += 1
            return True
        return False
