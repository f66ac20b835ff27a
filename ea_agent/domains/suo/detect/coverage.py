"""Friendly expected (the paper's EA Manager watches a place for activity "friendly or
enemy, expected or unexpected"; this is the friendly half): a position mission's
engagement area must be within its unit's weapons range of the position, or no one
covers it (judged when the mission starts); a position that must hold a unit (a battle
position, an observation post) holds some friendly element while its mission runs
(judged on each scan); and a unit resubordinated has a mission under its new superior."""
from __future__ import annotations

from math import hypot

import numpy as np
import shapely

from ea_agent.core.alert import Candidate

from ..missions import ContingentMission, Mission, ReorganizationMission
from ..render import km
from .base import Changes, Detector


HELD_SCAN_S = 30.0   # an empty position is looked for this often (emptiness that lasts seconds is no news)


class Coverage(Detector):
    TYPES = {"friendly-expected": "plan-constraint-violated"}

    def reset(self) -> None:
        self.held: dict[str, tuple[Mission, str]] = {}   # mission -> (it, the position it must hold)
        self.next_t = 0.0
        self._bounds: dict[str, tuple] = {}   # position -> (its area, the area's bounds)
        # position -> (its area, the positions array, entity row, x, y, distance to the edge) of
        # the element last found in it
        self._witness: dict[str, tuple] = {}

    def post_held(self, m: Mission, position: str) -> None:
        self.held[m.id] = (m, position)

    def end_mission(self, mid: str) -> None:
        self.held.pop(mid, None)

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        """Each scan: a held position with no friendly element in it (whoever's)."""
        dom = self.dom
        if not ch.rescan or not self.held or dom.plan is None or t < self.next_t:
            return
        self.next_t = t + HELD_SCAN_S
        xy = dom.pic.xy
        ok = xs = ys = None
        for mid, (m, pos) in self.held.items():
            if dom.plan.state.get(mid) != "active" or not dom.in_plan(m):
                continue
            area = dom.overlay[pos].area
            if self._still_held(pos, area, xy):
                continue
            if ok is None:
                ok = ~np.isnan(xy[:, 0])
                xs, ys = xy[ok, 0], xy[ok, 1]
            if not ok[dom.pic.members[m.unit]].any():
                continue   # where its unit is is not known yet: not known to be empty either
            hit = self._bounds.get(pos)
            if hit is None or hit[0] is not area:   # shapely's bounds cost microseconds: once per area
                hit = self._bounds[pos] = (area, area.bounds)
            x0, y0, x1, y1 = hit[1]
            box = (xs >= x0) & (xs <= x1) & (ys >= y0) & (ys <= y1)   # only these can be inside
            if box.any():
                idx = np.flatnonzero(box)
                inside = idx[shapely.contains_xy(area, xs[idx], ys[idx])]
                if len(inside):
                    self._keep_witness(pos, area, xy, np.flatnonzero(ok)[inside])
                    continue
            cands.append(Candidate(
                t, "friendly-expected", m.compute_priority("friendly-expected"), (m.unit,),
                f"{pos} holds no friendly element ({dom.name(m.unit)} {m.TYPE})",
                key=("friendly-expected", mid, pos),
                details={"mission": mid, "check": "empty", "position": pos, "places": [pos]}))

    def _still_held(self, pos: str, area, xy: np.ndarray) -> bool:
        """The element last found in the position is still there: it moved less than its
        distance to the area's edge then (one entity looked at, not every one)."""
        w = self._witness.get(pos)
        if w is None or w[0] is not area or w[1] is not xy:
            return False
        e, x0, y0, clear = w[2:]
        x, y = xy[e].tolist()
        return hypot(x - x0, y - y0) < clear

    def _keep_witness(self, pos: str, area, xy: np.ndarray, rows: np.ndarray) -> None:
        """Of the entities inside the position, the one deepest inside, to look at next."""
        if area.geom_type not in ("Polygon", "MultiPolygon"):
            return   # no inside to stay in
        d = shapely.distance(area.boundary, shapely.points(xy[rows]))
        k = int(np.argmax(d))
        x, y = xy[rows[k]].tolist()
        # less a millimetre: far more than the rounding of a distance of map coordinates
        self._witness[pos] = (area, xy, int(rows[k]), x, y, float(d[k]) - 1e-3)

    def resubordinated(self, unit: str, t: float) -> None:
        """A unit put under a new superior with no mission of its own or of a superior in the plan."""
        dom = self.dom
        if dom.plan is None or unit not in dom.own_units:
            return
        chain = (unit, *dom.taskorg.ancestors(unit))
        mine = [mid for mid, st in dom.plan.state.items() if st in ("pending", "ready", "active")
                and dom.missions[mid].unit in chain
                and not isinstance(dom.missions[mid], (ContingentMission, ReorganizationMission))]
        if mine:
            return
        dom.ea.post(Candidate(
            t, "friendly-expected", dom.base.compute_priority("friendly-expected"), (unit,),
            f"{dom.name(unit)} resubordinated to {dom.name(dom.taskorg.units[unit].parent)} with no mission in the plan",
            key=("friendly-expected", "org", unit), details={"check": "no-mission", "unit": unit}))

    def weapons_range(self, unit: str) -> float:
        to = self.dom.taskorg
        holder = to.nearest_with(unit, "weapons_range_m")
        return float(to.units[holder].attrs["weapons_range_m"]) if holder else float(self.dom.voi_cfg["weapons_range_m"])

    def check(self, m: Mission, position: str, engagement_area: str, t: float) -> None:
        dom = self.dom
        gap = float(shapely.distance(dom.overlay[position].area, dom.overlay[engagement_area].area))
        rng = self.weapons_range(m.unit)
        if gap <= rng:
            return
        dom.ea.post(Candidate(
            t, "friendly-expected", m.compute_priority("friendly-expected"), (m.unit,),
            f"{engagement_area} uncovered: {dom.name(m.unit)} in {position} is {km(gap)} from it, beyond its "
            f"{km(rng)} weapons range ({m.TYPE})",
            key=("friendly-expected", m.id, engagement_area), measure=gap - rng,
            details={"mission": m.id, "position": position, "engagement_area": engagement_area,
                     "gap_m": round(gap, 1), "weapons_range_m": rng, "places": [engagement_area, position]}))
