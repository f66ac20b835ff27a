"""A peer's wait for the replay's clock: whole ticks (every source gave them), in
order, checked against their time; a silent or incomplete clock is a system-problem
alert, then an exit at the deadline.

A mixin of `Peer` (saim_mesh/peer.py): it reads and writes the peer's state."""
from __future__ import annotations

import queue
import time

from . import wire as W


class SourceLost(RuntimeError):
    """No clock tick for longer than the peer's deadline."""


class TickWait:
    """`Peer`'s clock half: `_next_ticks` blocks until the next whole tick(s)."""

    def _valid_tick(self, tick: W.Tick) -> bool:
        if tick.end and tick.t < self.sc.duration_s:
            self._reject("tick", "end", f"an end tick at t={tick.t} before the scenario's end", self.ks.clock())
            return False
        # tick n is at n x TICK_S (the end tick may come early in number): a forged number
        # would make every real tick look stale
        if tick.n > tick.t / W.TICK_S + 1.5 or not tick.end and tick.n < tick.t / W.TICK_S - 1.5:
            self._reject("tick", "n", f"tick number {tick.n} does not fit its time {tick.t}", self.ks.clock())
            return False
        if self.tick_n is not None and tick.n <= self.tick_n or tick.t < self.t:
            return False   # a restarted replay repeats its last tick, or the store took us past it
        return True

    def _whole(self, tick: W.Tick) -> bool:
        """Behind routers each of the replay's sources ticks: a tick is whole once all of
        them gave it (their messages came by different paths, each in order)."""
        self.n_sources = tick.of
        if tick.of == 1:
            return True
        parts = self.tick_parts.setdefault(tick.n, set())
        parts.add(tick.src)
        if len(parts) < tick.of:
            if len(self.tick_parts) > 4096:   # sources that never complete: forget the oldest
                del self.tick_parts[min(self.tick_parts)]
            return False
        for n in [n for n in self.tick_parts if n <= tick.n]:
            del self.tick_parts[n]
        return True

    def _waiting_for(self) -> str:
        """Which sources' ticks are missing (named in a system-problem alert)."""
        if not self.tick_parts:
            return ""
        n = min(self.tick_parts)
        return f" (tick {n} came only from {', '.join(sorted(self.tick_parts[n]))}: a router link may be down)"

    def _next_ticks(self, clock: queue.SimpleQueue) -> list[W.Tick]:
        """Block for the next tick(s); a silent source is an alert, then an exit at the deadline.

        `clock` is filled by a callback on Zenoh's thread (tick payloads; None when a
        command came): a blocking wait costs nothing while idle, where polling a channel
        costs every waiting peer hundreds of wake-ups a second (57 peers on 2 cores)."""
        last = time.monotonic()
        said = False
        while True:
            if self.cmdq.qsize():   # a commander's command is taken while we wait, whatever the clock sends
                self._commands()
            try:
                raw = [clock.get(timeout=0.5)]
            except queue.Empty:
                raw = []
            while raw and len(raw) < 64:
                try:
                    raw.append(clock.get_nowait())
                except queue.Empty:
                    break
            raw = [x for x in raw if x is not None]   # None: a command woke us
            if not raw:
                self.presence.take()
                quiet = time.monotonic() - last
                if quiet > self.silence_s and not said:
                    said = True
                    self.silences += 1
                    self.system_alert("SAIM", "immediate", f"no clock from the source (replay) for "
                                      f"{self.silence_s:.0f} s: the picture is not moving{self._waiting_for()}",
                                      event="source-silent")
                if self.deadline_s is not None and quiet > self.deadline_s:
                    raise SourceLost(f"no clock from the source for {self.deadline_s:.0f} s: giving up")
                continue
            ticks = []
            for payload in raw:
                tick = self.gate.control(W.Tick, payload, self.ks.clock())
                if (tick is not None and self._valid_tick(tick) and (not ticks or tick.n > ticks[-1].n)
                        and self._whole(tick)):
                    ticks.append(tick)
            if not ticks:   # only parts of ticks (or junk): still waiting for some source
                if time.monotonic() - last > self.silence_s and not said:
                    said = True
                    self.silences += 1
                    self.system_alert("SAIM", "immediate", f"the clock is incomplete for {self.silence_s:.0f} s: "
                                      f"the picture is not moving{self._waiting_for()}", event="source-silent")
                if self.deadline_s is not None and time.monotonic() - last > self.deadline_s:
                    raise SourceLost(f"no whole clock tick for {self.deadline_s:.0f} s: giving up")
                continue
            if said:
                self.system_alert("SAIM", "routine", "the source's clock is back", event="source-back")
            self.clock_t = max(self.clock_t, ticks[-1].t)
            self.tick_seq = max(self.tick_seq, ticks[-1].seq)
            return ticks
