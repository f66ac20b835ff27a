"""Ordered presence of two units at one place: a relief in place leaves no gap (the
relieved unit does not leave the position before the relieving unit is in it), and a
passage of lines goes through its lane (the passing unit's elements near the point are
inside the `lane`). "At the point" means an element within `coordination_radius_m`."""
from __future__ import annotations

import math

import numpy as np
import shapely

from ea_agent.core.alert import Candidate

from ..missions import Mission
from .base import Changes, Detector
from .geometry import PointCoords


NEAR_M = 1500.0   # a unit's elements are no farther than this from its centroid


class Presence(Detector):
    TYPES = {"presence": "plan-constraint-violated"}

    def reset(self) -> None:
        # mission -> [it, partner, point, lane or None, partner was at the point, relieving unit arrived, told]
        self.watch: dict[str, list] = {}
        self._point = PointCoords(self.dom)

    def post(self, m: Mission, partner: str, point: str, lane: str | None) -> None:
        self.watch[m.id] = [m, partner, point, lane, False, False]

    def end_mission(self, mid: str) -> None:
        self.watch.pop(mid, None)

    def _at(self, unit: str, point: str, radius: float) -> np.ndarray:
        """The unit's members (positions) within `radius` of `point` (from a point, GEOS's
        own formula on plain numpy: no geometry built)."""
        xy = self.dom.pic.member_xy(unit)
        if len(xy) == 0:
            return xy
        p = self._point(point)
        if p is None:
            return xy[shapely.distance(self.dom.overlay[point].geom, shapely.points(xy)) <= radius]
        dx, dy = xy[:, 0] - p[0], xy[:, 1] - p[1]
        return xy[np.sqrt(dx * dx + dy * dy) <= radius]

    def _far(self, c: tuple[float, float], point: str, limit: float) -> bool:
        """Whether `c` is farther than `limit` from the measure."""
        p = self._point(point)
        if p is None:
            return self.dom.overlay[point].geom.distance(shapely.Point(c)) > limit
        dx, dy = c[0] - p[0], c[1] - p[1]
        return math.sqrt(dx * dx + dy * dy) > limit

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        dom = self.dom
        if not self.watch or dom.plan is None or not ch.units:
            return
        for mid, w in self.watch.items():
            m, partner, point, lane, was, arrived = w
            if dom.plan.state.get(mid) in ("done", "aborted") or not dom.in_plan(m):
                continue
            if m.unit not in ch.units and partner not in ch.units:
                continue   # nobody moved: nothing changed
            radius = dom.voi(m, "coordination_radius_m")
            if lane is not None:   # a passage: nothing to judge while the passing unit is nowhere near
                c = dom.unit_pos.get(m.unit)
                if c is None or self._far(c, point, radius + NEAR_M):
                    continue
            mine = self._at(m.unit, point, radius)
            if lane is None:   # relief in place
                theirs = len(self._at(partner, point, radius))
                w[4] = was or theirs > 0
                w[5] = arrived or len(mine) > 0
                if w[4] and not w[5] and theirs == 0:
                    cands.append(self._cand(m, partner, point, t, "gap",
                                            f"{dom.name(partner)} left {point} before {dom.name(m.unit)} relieved it"))
            elif len(mine):
                out = int((~shapely.contains_xy(dom.overlay[lane].area, mine[:, 0], mine[:, 1])).sum())
                if out:
                    cands.append(self._cand(m, partner, point, t, "lane",
                                            f"{dom.name(m.unit)} passing {dom.name(partner)} at {point} outside "
                                            f"{lane}: {out} element{'s' if out > 1 else ''}", lane))

    def _cand(self, m: Mission, partner: str, point: str, t: float, what: str, text: str,
              lane: str | None = None) -> Candidate:
        return Candidate(t, "presence", m.compute_priority("presence"), (m.unit, partner), text,
                         key=("presence", m.id, what),
                         details={"mission": m.id, "check": what, "point": point, "lane": lane,
                                  "places": [point] + ([lane] if lane else [])})
