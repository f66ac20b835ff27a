"""Coordination: two units must both have an element at a point around a time
(link-up, relief in place, passage of lines)."""
from __future__ import annotations

import math

import numpy as np

from ea_agent.core.alert import Candidate

from ..missions import Mission
from ..render import km
from .base import Changes, Detector
from .geometry import judged_distance


class Coordination(Detector):
    """A timer alerts when the meeting has not happened by its time; movers are
    checked each epoch and a met coordination stops its timer."""
    TYPES = {"coordination": "plan-constraint-violated"}

    def reset(self) -> None:
        self.pending: dict[str, tuple[Mission, str, str, float]] = {}

    def post(self, m: Mission, partner: str, point: str, at: float, fuzz: float) -> None:
        dom = self.dom
        self.pending[m.id] = (m, partner, point, float(dom.voi(m, "coordination_radius_m")))

        def failed(tf, mon, how):
            if dom.in_plan(m):
                dom.ea.post(self.candidate(m, partner, point, tf))
            return None
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
        near: dict[str, np.ndarray] = {}   # point -> every entity's distance from it (inf: unknown)
        for mid, (m, partner, point, radius) in list(self.pending.items()):
            if m.unit not in ch.units and partner not in ch.units:
                continue
            g = dom.overlay[point].geom
            # both must be there: the partner is not looked at while the unit is not
            if all(self._within(g, point, u, radius, near) for u in (m.unit, partner)):
                dom.timers.occurred(("coord", mid), t)
                del self.pending[mid]

    def _within(self, g, point: str, unit: str, radius: float, near: dict[str, np.ndarray]) -> bool:
        """Whether some element of `unit` is within `radius` of `g`. A point's distance from
        every entity is taken once per epoch (one numpy call for all of them, not one per
        unit); other measures are judged as before."""
        pic = self.dom.pic
        if g.geom_type != "Point":
            d = judged_distance(g, pic.member_xy(unit), "any", None)
            return d is not None and d <= radius
        ds = near.get(point)
        if ds is None:
            xy = pic.xy
            ds = near[point] = np.hypot(xy[:, 0] - g.x, xy[:, 1] - g.y)
            ds[np.isnan(ds)] = np.inf
        idx = pic.members[unit]
        if len(idx) == 0:
            return False
        d = float(ds[idx].min())
        return d != math.inf and d <= radius   # no member known: not there
