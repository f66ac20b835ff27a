"""Checkpoints: a march table (start point, checkpoints, release point) or a route
reconnaissance's expected progress, as near-time monitors (paper 6.6.4) on the event
"the unit reached the point", which this detector raises when the unit's centroid
(dead-reckoned to now) first comes within `checkpoint_m` of a point (or into an area)
while the mission runs."""
from __future__ import annotations

import math

import shapely

from ea_agent.core.alert import Candidate, hms

from ..missions import Mission
from .base import Changes, Detector


class Checkpoints(Detector):
    TYPES = {"checkpoint": "plan-constraint-violated"}

    def reset(self) -> None:
        self.waiting: dict[str, list[tuple[Mission, str]]] = {}   # mission -> checkpoints not yet reached
        self._points: dict[str, tuple] = {}   # measure -> (its geometry, its point's x, y or None)

    def post(self, m: Mission, table: list[dict]) -> None:
        dom = self.dom
        fuzz = dom.voi(m, "schedule_s")
        self.waiting[m.id] = [(m, cp["point"]) for cp in table]
        for cp in table:
            point, when = cp["point"], float(cp["t"])

            def off(tf, mon, how, point=point, when=when):
                if dom.in_plan(m):
                    dom.ea.post(self._cand(m, point, when, tf, how))
                return None
            dom.timers.near_time(("at", m.id, point), when, fuzz, off, tag=m.id)

    def end_mission(self, mid: str) -> None:
        self.waiting.pop(mid, None)

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        dom = self.dom
        if not self.waiting or not (ch.units or ch.rescan) or dom.plan is None:
            return
        for mid, left in list(self.waiting.items()):
            if not left or dom.plan.state.get(mid) != "active":
                continue
            m = left[0][0]
            if not ch.rescan and m.unit not in ch.units:   # its unit's reports and the scan only, not an epoch
                continue   # another unit's report closed (a peer may not hear that unit: see ThreatsAhead)
            pos = dom.unit_now.get(m.unit) or dom.unit_pos.get(m.unit)
            if pos is None:
                continue
            near = dom.voi(m, "checkpoint_m")
            reached = [pt for _, pt in left if self._reached(pt, pos, near)]
            for pt in reached:
                dom.timers.occurred(("at", mid, pt), t)
            if reached:
                self.waiting[mid] = [x for x in left if x[1] not in reached]

    def _reached(self, point: str, pos: tuple[float, float], near: float) -> bool:
        """Whether `pos` is within `near` of a point measure (GEOS's distance formula on its
        coordinates, read once), or inside an area."""
        cm = self.dom.overlay[point]
        hit = self._points.get(point)
        if hit is None or hit[0] is not cm.geom:
            g = cm.geom
            hit = self._points[point] = (g, (g.x, g.y) if g.geom_type == "Point" else None)
        p = hit[1]
        if p is None:
            return cm.area.contains(shapely.Point(pos))
        dx, dy = pos[0] - p[0], pos[1] - p[1]
        return math.sqrt(dx * dx + dy * dy) <= near

    def _cand(self, m: Mission, point: str, when: float, t: float, how: str) -> Candidate:
        dom = self.dom
        off = abs(t - when) if how == "early" else t - when
        text = (f"{dom.name(m.unit)} not at {point} by {hms(when)} ({m.TYPE} checkpoint): {off:.0f} s late"
                if how == "late" else
                f"{dom.name(m.unit)} at {point} {when - t:.0f} s early (planned {hms(when)}, {m.TYPE} checkpoint)")
        return Candidate(t, "checkpoint", m.compute_priority("checkpoint"), (m.unit,), text,
                         key=("checkpoint", m.id, point), measure=abs(when - t),
                         details={"mission": m.id, "point": point, "planned_t": when, "how": how,
                                  "off_s": round(abs(when - t), 1), "places": [point]})
