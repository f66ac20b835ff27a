"""Distance bands to another friendly unit: a follow-and-support or follow-and-assume
unit stays within [min, max] of the unit it follows. Judged, as out-of-position, by
how far outside the band the centroids are, beyond the out-of-position threshold."""
from __future__ import annotations

import math

from ea_agent.core.alert import Candidate

from ..missions import Mission
from ..render import km
from .base import Changes, Detector


class Bands(Detector):
    TYPES = {"band": "plan-constraint-violated"}

    def reset(self) -> None:
        self.bands: dict[str, tuple[Mission, str, float, float]] = {}

    def post(self, m: Mission, other: str, lo: float, hi: float) -> None:
        self.bands[m.id] = (m, other, lo, hi)

    def end_mission(self, mid: str) -> None:
        self.bands.pop(mid, None)

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        dom = self.dom
        if not self.bands or dom.plan is None or not (ch.units or ch.rescan):
            return
        for mid, (m, other, lo, hi) in self.bands.items():
            if dom.plan.state.get(mid) != "active" or not dom.in_plan(m):
                continue
            if not ch.rescan and m.unit not in ch.units and other not in ch.units:
                continue
            a, b = dom.unit_pos.get(m.unit), dom.unit_pos.get(other)
            if a is None or b is None:
                continue
            d = math.hypot(a[0] - b[0], a[1] - b[1])
            off = d - hi if d > hi else lo - d
            thr = dom.voi(m, "out_of_position_m")
            if off <= thr:
                continue
            how = "too far from" if d > hi else "too close to"
            cands.append(Candidate(
                t, "band", m.compute_priority("band"), (m.unit, other),
                f"{dom.name(m.unit)} {how} {dom.name(other)} it must {m.TYPE.replace('-', ' ')}: {km(d)} apart "
                f"(band {km(lo)}-{km(hi)})",
                key=("band", mid), measure=off,
                details={"mission": mid, "supported": other, "distance_m": round(d, 1), "band_m": [lo, hi],
                         "off_m": round(off, 1), "threshold_m": thr}))
