"""Start and end time constraints (Fig. 6) as timed monitors, with progressive
repeats: a mission late to start is reported at the VOI threshold, then again at
each longer delay in `repeats_s`. Every domain's missions post these the same way."""
from __future__ import annotations

from typing import Callable

from .alert import Candidate, hms
from .plan import TimeConstraint
from .timed import TimedMonitors


class Schedule:
    def __init__(self, timers: TimedMonitors, post: Callable[[Candidate], None], name: Callable[[str], str],
                 in_plan: Callable[[object], bool], threshold_s: Callable[[object], float], repeats_s: list[float]):
        self.timers, self.post_candidate, self.name, self.in_plan = timers, post, name, in_plan
        self.threshold_s, self.repeats_s = threshold_s, sorted(float(x) for x in repeats_s)

    def post(self, m, phase: str, tc: TimeConstraint) -> None:
        """Watch mission `m`'s `phase` ("start" or "end") against constraint `tc`."""
        if tc.type in ("ASAP", "ON-ORDER") or tc.t is None:
            return
        thr = self.threshold_s(m)
        steps = [x for x in self.repeats_s if x > thr]
        event, when = (phase, m.id), tc.t
        kind = tc.type.split("-")[1]

        def late(tf: float, mon, how: str) -> float | None:
            if not self.in_plan(m):
                return None
            off = tf - when if how == "late" else when - tf
            self.post_candidate(self.candidate(m, phase, tc, tf, off, how))
            if how == "late":
                nxt = [s for s in steps if s > off + 1e-9]
                return when + nxt[0] if nxt else None
            return None

        if kind == "NLT":
            self.timers.not_later_than(event, when + thr, late, tag=m.id)
        elif kind == "NET":
            self.timers.not_earlier_than(event, when - thr, late, tag=m.id)
        else:  # AT
            self.timers.near_time(event, when, thr, late, tag=m.id)

    def candidate(self, m, phase: str, tc: TimeConstraint, t: float, off: float, how: str) -> Candidate:
        verb = "starting" if phase == "start" else "ending"
        who = self.name(m.unit)
        if how == "late":
            text = f"{who} {how} {verb} {m.TYPE} ({tc.type} {hms(tc.t)}): {off:.0f} s {how}"
        else:
            text = f"{who} {phase}ed {m.TYPE} {off:.0f} s early ({tc.type} {hms(tc.t)})"
        return Candidate(t, "schedule", m.compute_priority("schedule"), (m.unit,), text,
                         key=("schedule", m.id, phase), measure=off,
                         details={"mission": m.id, "phase": phase, "constraint": tc.type,
                                  "planned_t": tc.t, "how": how, "off_s": round(off, 1)})
