"""Timed monitors (paper 6.6.4): not-later-than, not-earlier-than, in-window, near-time.

Each monitor waits for a named event and fails if it comes too early or not in
time. Timers run on scenario time: `advance(now)` fires what is due, so nothing
ever blocks the manager loop.
"""
from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field
from typing import Callable, Hashable

# on_fail(t, monitor, how) -> optional new deadline (re-arm for a progressive repeat)
FailFn = Callable[[float, "Monitor", str], float | None]


@dataclass(slots=True)
class Monitor:
    event: Hashable
    kind: str             # not-later-than | not-earlier-than | in-window | near-time
    lo: float             # event before lo is early
    hi: float             # event not seen by hi is late
    on_fail: FailFn
    tag: Hashable = None
    active: bool = True
    fails: int = 0
    deadline: float = math.inf
    data: dict = field(default_factory=dict)


class TimedMonitors:
    def __init__(self) -> None:
        self._heap: list[tuple[float, int, Monitor]] = []
        self._by_event: dict[Hashable, list[Monitor]] = {}
        self._seq = 0
        self.occurred_at: dict[Hashable, float] = {}

    # -- the four monitor types -------------------------------------------------
    def not_later_than(self, event, t: float, on_fail: FailFn, tag=None, **data) -> Monitor:
        return self._add(Monitor(event, "not-later-than", -math.inf, t, on_fail, tag, data=data))

    def not_earlier_than(self, event, t: float, on_fail: FailFn, tag=None, **data) -> Monitor:
        return self._add(Monitor(event, "not-earlier-than", t, math.inf, on_fail, tag, data=data))

    def in_window(self, event, start: float, end: float, on_fail: FailFn, tag=None, **data) -> Monitor:
        return self._add(Monitor(event, "in-window", start, end, on_fail, tag, data=data))

    def near_time(self, event, t: float, fuzz: float, on_fail: FailFn, mode: str = "absolute",
                  now: float = 0.0, tag=None, **data) -> Monitor:
        """Event must occur within `fuzz` of `t`; `mode="relative"` counts t from `now`."""
        if mode not in ("absolute", "relative"):
            raise ValueError(f"near_time mode must be absolute or relative, not {mode!r}")
        at = t + now if mode == "relative" else t
        return self._add(Monitor(event, "near-time", at - fuzz, at + fuzz, on_fail, tag, data=data))

    # -- driving ------------------------------------------------------------------
    def _add(self, m: Monitor) -> Monitor:
        if m.event in self.occurred_at:  # event already happened: judge at once
            t = self.occurred_at[m.event]
            if t < m.lo:
                m.fails += 1
                m.on_fail(t, m, "early")
            m.active = False
            return m
        self._by_event.setdefault(m.event, []).append(m)
        self._arm(m, m.hi)
        return m

    def _arm(self, m: Monitor, deadline: float) -> None:
        m.deadline = deadline
        if math.isfinite(deadline):
            self._seq += 1
            heapq.heappush(self._heap, (deadline, self._seq, m))

    def occurred(self, event, t: float) -> None:
        """The awaited event happened at scenario time t: resolve its monitors."""
        self.occurred_at.setdefault(event, t)
        for m in self._by_event.pop(event, ()):
            if not m.active:
                continue
            m.active = False
            if t < m.lo:
                m.fails += 1
                m.on_fail(t, m, "early")
            elif t > m.deadline:   # it came after a deadline that had not fired yet (same epoch)
                m.fails += 1
                m.on_fail(m.deadline, m, "late")

    def next_deadline(self) -> float:
        while self._heap and not self._heap[0][2].active:
            heapq.heappop(self._heap)
        return self._heap[0][0] if self._heap else math.inf

    def advance(self, now: float) -> int:
        """Fire every timer due at or before `now`, in deadline order; returns how many
        failed. The epoch that ends at `now` holds the facts at `now`: an event at the very
        deadline was applied before this and still meets it, as "within fuzz seconds" says."""
        fired = 0
        while self._heap and self._heap[0][0] <= now:
            deadline, _, m = heapq.heappop(self._heap)
            if not m.active or deadline != m.deadline:
                continue
            m.fails += 1
            fired += 1
            again = m.on_fail(deadline, m, "late")
            if again is not None and again > deadline:
                self._arm(m, again)  # progressive repeat: still waiting, look again later
            else:
                m.active = False
        return fired

    def cancel(self, tag) -> None:
        for ms in self._by_event.values():
            for m in ms:
                if m.tag == tag:
                    m.active = False

    def clear(self) -> None:
        self._heap.clear()
        self._by_event.clear()
        self.occurred_at.clear()

    def pending(self) -> int:
        return sum(1 for ms in self._by_event.values() for m in ms if m.active)
