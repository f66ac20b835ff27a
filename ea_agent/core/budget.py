"""A commander's notice budget (issue 53): how many re-notifications and escalations one
commander may be shown, in proportion to the new alerts their own EA gives them.

Re-notifying what matters is right, but a commander who does not acknowledge (busy
fighting) would otherwise be told more and more: every unacknowledged urgent alert comes
back `times` times and every subordinate's escalates to them. The budget holds the
notices shown to one commander to `budget` x the new alerts their EA gave them (at least
`budget_min`) twice over: in any sliding window of `[notify] budget_window_s` of scenario
time (a storm of notices cannot spend at once what quiet hours earned), and since the
start (windows overlap: the window alone would let a run's notices exceed `budget` x its
alerts). Scenario time, never the wall clock: a run gives the same notices whatever the
machine did. An escalation of a flash alert (a threat to life) is always given: it is
counted, so the rest give way to it, but never held back; so is a flash alert's first
re-notification. `budget = 0` turns it off.
"""
from __future__ import annotations

import bisect
import logging

log = logging.getLogger(__name__)


class Budget:
    """One commander's notice budget, fed their own shown alerts (`alert`) and asked
    before each notice shown to them (`allow`)."""

    def __init__(self, unit: str, notify_cfg: dict):
        self.unit = unit
        self.ratio = float(notify_cfg.get("budget", 0.0))
        self.floor = float(notify_cfg.get("budget_min", 0.0))
        self.window = float(notify_cfg.get("budget_window_s", 0.0))
        self.alerts: list[float] = []    # scenario times of new alerts shown, within the window
        self.shown: list[float] = []     # scenario times of notices shown, within the window
        self.earned = 0                  # new alerts shown since the start
        self.given = 0
        self.dropped = 0                 # notices held back, for good
        self.forced = 0                  # flash escalations given past the budget

    @property
    def on(self) -> bool:
        return self.ratio > 0 and self.window > 0

    def _prune(self, t: float) -> None:
        """Forget what left the window (t - window, t]; times may come slightly out of
        order (a subordinate's EA closes its epochs on its own), hence the sorted lists."""
        lo = t - self.window
        for xs in (self.alerts, self.shown):
            k = bisect.bisect_right(xs, lo)
            if k:
                del xs[:k]

    def alert(self, t: float) -> None:
        """A new alert shown to this commander: it earns budget."""
        self.earned += 1
        if self.on:
            bisect.insort(self.alerts, t)
            self._prune(t)

    def limit(self, t: float) -> float:
        """The notices this commander may be shown in the window ending at `t`."""
        self._prune(t)
        return max(self.floor, self.ratio * sum(1 for x in self.alerts if x <= t))

    def _room(self, t: float) -> bool:
        """One more notice keeps within the window's limit and the run's."""
        return (len(self.shown) + 1 <= self.limit(t)
                and self.given + 1 <= max(self.floor, self.ratio * self.earned))

    def allow(self, t: float, force: bool = False) -> bool:
        """May a notice at `t` be shown? Counted when it is; `force` (a flash escalation):
        always, and it uses up budget as the others do."""
        if not self.on:
            self.given += 1
            return True
        room = self._room(t)
        if force or room:
            self.forced += not room
            bisect.insort(self.shown, t)
            self.given += 1
            return True
        self.dropped += 1
        return False

    def charge(self, t: float) -> None:
        """A notice shown to this commander without asking (an escalation from a peer on
        the mesh, whose EA cannot see this budget): counted, so the rest give way."""
        self.given += 1
        if self.on:
            bisect.insort(self.shown, t)
            self._prune(t)

    def stats(self) -> dict:
        return {"given": self.given, "dropped": self.dropped, "forced": self.forced}
