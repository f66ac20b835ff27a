"""End states: a seize, clear, secure or destroy mission ends with no hostile left on
its objective. Judged once, when the mission ends (Check-Final-Location), from the
adjudicated picture of that moment."""
from __future__ import annotations

import numpy as np
import shapely

from ea_agent.core.alert import Candidate

from ..missions import Mission
from .base import Detector


class EndStates(Detector):
    TYPES = {"end-state": "plan-constraint-violated"}

    def check(self, m: Mission, area: str, t: float) -> None:
        dom = self.dom
        tracks = dom.pic.tracks
        ids = sorted(tracks)
        if not ids:
            return
        xy = np.array([(tracks[k].x, tracks[k].y) for k in ids])
        left = [k for k, ok in zip(ids, shapely.contains_xy(dom.overlay[area].area, xy[:, 0], xy[:, 1])) if ok]
        strength = sum(tracks[k].strength for k in left)
        if strength <= 0:
            return
        dom.ea.post(Candidate(
            t, "end-state", m.compute_priority("end-state"), (m.unit, *left),
            f"{dom.name(m.unit)} ended {m.TYPE} with hostiles still on {area}: {strength} entities in "
            f"{len(left)} track{'s' if len(left) > 1 else ''}",
            key=("end-state", m.id), measure=float(strength), friendly=False,
            details={"mission": m.id, "place": area, "places": [area], "strength": strength, "tracks": left}))
