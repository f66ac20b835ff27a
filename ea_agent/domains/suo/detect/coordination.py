"""Coordination: two units must both have an element at a point around a time
(link-up, relief in place, passage of lines)."""
from __future__ import annotations

import numpy as np

from ea_agent.core.alert import Candidate

from ..missions import Mission
from ..render import km
from .base import Changes, Detector
from .geometry import PointCoords, judged_distance


class Coordination(Detector):
    """A timer alerts when the meeting has not happened by its time; movers are
    checked each epoch and a met coordination stops its timer."""
    TYPES = {"coordination": "plan-constraint-violated"}

    def reset(self) -> None:
        self.pending: dict[str, tuple[Mission, str, str, float]] = {}
        self._point = PointCoords(self.dom)

    def post(self, m: Mission, partner: str, point: str, at: float, fuzz: float) -> None:
        dom = self.dom
        self.pending[m.id] = (m, partner, point, float(dom.voi(m, "coordination_radius_m")))

        def failed(tf, mon, how):
            if dom.in_plan(m):
                dom.ea.post(self.candidate(m, partner, point, tf))
            return None
        if m.params.get("window") is None:   # a link-up's or relief's window is its time (detect/windows.py)
            dom.timers.not_later_than(("coord", m.id), at + fuzz, failed, tag=m.id)

    def candidate(self, m: Mission, partner: str, point: str, t: float) -> Candidate:
        dom = self.dom
        geom = dom.overlay[point].geom
        far = []
        for u in (m.unit, partner):
            d = judged_distance(geom, dom.pic.member_xy(u), "any", None)
            far.append(f"{dom.name(u)} {'unknown' if d is None else km(d)}")
        return Candidate(t, "coordination", m.compute_priority("coordination"), (m.unit, partner),
                         f"{dom.name(m.unit)} and {dom.name(partner)} cannot {m.TYPE} at {point} as planned "
                         f"({', '.join(far)} away)", key=("coordination", m.id),
                         details={"mission": m.id, "point": point, "places": [point]})

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        if not ch.leaves:
            return
        dom = self.dom
        for mid, (m, partner, point, radius) in list(self.pending.items()):
            if m.unit not in ch.units and partner not in ch.units:
                continue
            # both must be there: the partner is not looked at while the unit is not
            if all(self._within(point, u, radius) for u in (m.unit, partner)):
                dom.timers.occurred(("coord", mid), t)
                del self.pending[mid]

    def _within(self, point: str, unit: str, radius: float) -> bool:
        """Whether some element of `unit` is within `radius` of `point` (as judged_distance
        "any", without its per-call overhead when the measure is a point)."""
        pic = self.dom.pic
        p = self._point(point)
        if p is None:
            d = judged_distance(self.dom.overlay[point].geom, pic.member_xy(unit), "any", None)
            return d is not None and d <= radius
        idx = pic.members[unit]
        if len(idx) == 0:
            return False
        xy = pic.xy[idx]
        # unknown members are NaN, which fmin skips (all unknown: NaN, never within)
        return bool(np.fmin.reduce(np.hypot(xy[:, 0] - p[0], xy[:, 1] - p[1])) <= radius)
