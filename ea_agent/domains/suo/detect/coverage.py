"""Friendly expected (the paper's EA Manager watches a place for activity "friendly or
enemy, expected or unexpected"; this is the friendly half): a position mission's
engagement area must be within its unit's weapons range of the position, or no one
covers it. Judged when the mission starts."""
from __future__ import annotations

import shapely

from ea_agent.core.alert import Candidate

from ..missions import Mission
from ..render import km
from .base import Detector


class Coverage(Detector):
    TYPES = {"friendly-expected": "plan-constraint-violated"}

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
