"""Follow and assume (FM 3-90): the follower takes over the supported unit's mission when
that unit halts short of its goal (its reported centroid within HALT_M of one place for
the mission's `halt_s` while its own mission runs) or its mission is aborted (it is
committed elsewhere). The follower's EA says so (a contingency alert) and from then
monitors that mission as the follower's own: a copy of it, for the follower, started now,
with no time constraints of its own (the follow mission's end is its end); the follow
band no longer holds."""
from __future__ import annotations

import math
from collections import deque

import shapely

from ea_agent.core.alert import Candidate
from ea_agent.core.plan import MissionSpec

from ..missions import Mission
from .base import Changes, Detector

HALT_M = 50.0   # a unit whose centroid stayed this near one place has not moved (reports jitter metres)


def goal_of(m: Mission) -> str | None:
    """Where a moving mission goes, if it goes anywhere: a halt short of it is a halt."""
    return m.params.get("destination") or m.params.get("objective")


class Assumptions(Detector):
    TYPES = {"contingency": "contingency-plan-suggested"}

    def reset(self) -> None:
        # follow mission -> [it, supported unit, halt_s, its mission watched, history deque[(t, x, y)], assumed id]
        self.watch: dict[str, list] = {}

    def post(self, m: Mission, supported: str, halt_s: float) -> None:
        self.watch[m.id] = [m, supported, halt_s, None, deque(), None]

    def end_mission(self, mid: str) -> None:
        w = self.watch.pop(mid, None)
        dom = self.dom
        if w is None or w[5] is None or dom.plan is None:
            return
        cid = w[5]   # the assumed mission ends with the follow mission (judged where it stands), or is aborted with it
        if dom.plan.state.get(cid) != "active":
            return
        if mid in dom.plan.ended:
            dom._end(dom.missions[cid], dom.plan.ended[mid])
        else:
            dom._abort(cid)

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        dom = self.dom
        if not self.watch or dom.plan is None:
            return
        state = dom.plan.state
        for mid, w in list(self.watch.items()):
            m, sup, halt_s, watched, hist, assumed = w
            if assumed is not None or state.get(mid) != "active" or not dom.in_plan(m):
                continue
            if not (sup in ch.units or ch.rescan):
                continue   # looked at when the supported unit reports, or on the scan (the same epochs in every peer)
            if watched is not None and state.get(watched) == "aborted":
                self._assume(w, watched, t, "its mission aborted", cands)
                continue
            now = dom.plan.active_by_unit().get(sup)
            if now != watched:   # its next mission (or none): a halt is measured from its start
                w[3], watched = now, now
                hist.clear()
            if watched is None:
                continue
            goal = goal_of(dom.missions[watched])
            pos = dom.unit_pos.get(sup)
            if goal is None or pos is None:
                continue
            if hist and hist[-1][0] >= t:
                hist.pop()
            hist.append((t, *pos))
            while len(hist) > 1 and hist[1][0] <= t - halt_s:
                hist.popleft()
            if hist[0][0] > t - halt_s:
                continue
            x, y = pos
            if any(math.hypot(px - x, py - y) > HALT_M for _, px, py in hist):
                continue
            if dom.overlay[goal].area.distance(shapely.Point(pos)) <= dom.voi(m, "out_of_position_m"):
                continue   # standing at its goal: arrived, not halted
            self._assume(w, watched, t, f"halted {halt_s:.0f} s short of {goal}", cands)

    def _assume(self, w: list, src_id: str, t: float, why: str, cands: list[Candidate]) -> None:
        """The follower takes over mission `src_id`: a copy of it for the follower, monitored from now."""
        dom = self.dom
        m, sup = w[0], w[1]
        src = dom.missions[src_id]
        cls = type(src)
        cid = f"{m.id}>{src_id}"
        copy = cls(MissionSpec(cid, m.unit, cls.TYPE, params=dict(src.params))).use_defaults(dom.priorities)
        w[5] = cid
        dom.bands.end_mission(m.id)   # it no longer follows
        dom.missions[cid] = copy
        dom.plan.state[cid] = "ready"
        copy.post_execution_constraints(dom)
        dom.plan.start(cid, t)
        dom.timers.occurred(("start", cid), t)
        copy.check_initial_location(dom, t)
        goal = goal_of(src)
        cands.append(Candidate(
            t, "contingency", m.compute_priority("contingency"), (m.unit, sup),
            f"{dom.name(m.unit)} assumes {dom.name(sup)}'s {src.TYPE} ({dom.name(sup)} {why}): "
            f"monitored as {dom.name(m.unit)}'s own from now ({m.TYPE})",
            key=("contingency", m.id, "assume"), friendly=True,
            details={"mission": m.id, "check": "assume", "assumed": src_id, "as": cid, "supported": sup,
                     "why": why, "places": [goal] if goal else []}))
