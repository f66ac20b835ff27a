"""Distance bands to another friendly unit: a follow-and-support or follow-and-assume
unit stays within [min, max] of the unit it follows. Judged, as out-of-position, by
how far outside the band the centroids are, beyond the out-of-position threshold.
A band may hold only from a time (`since`: forces that linked up stay joined), may also ask
the unit to stay behind the other on the way to a place (`behind`: a follower does not pass
the unit it supports), and may be judged once at a time (`check_once`: a reorganized unit
joined to its new superior by then)."""
from __future__ import annotations

import math

import numpy as np
import shapely

from ea_agent.core.alert import Candidate

from ..missions import Mission
from ..render import km
from .base import Changes, Detector


class Bands(Detector):
    TYPES = {"band": "plan-constraint-violated"}

    def reset(self) -> None:
        self.bands: dict[str, tuple[Mission, str, float, float]] = {}
        self.since: dict[str, float] = {}    # mission -> the time its band holds from
        self.behind: dict[str, str] = {}     # mission -> the place its unit stays behind the other on the way to

    def post(self, m: Mission, other: str, lo: float, hi: float, since: float | None = None,
             behind: str | None = None) -> None:
        self.bands[m.id] = (m, other, lo, hi)
        if since is not None:
            self.since[m.id] = since
        if behind is not None:
            self.behind[m.id] = behind

    def check_once(self, m: Mission, unit: str, other: str, hi: float, when: float) -> None:
        """At `when`, `unit` within `hi` of the rest of `other` (its other members: the unit may
        already be one of them), whatever `m`'s state then."""
        dom = self.dom

        def due(tf, mon, how):
            if not dom.in_plan(m):
                return None
            pic = dom.pic
            a = pic.centroid(unit)
            rest = np.setdiff1d(pic.members[other], pic.members[unit])   # the superior without the unit joining it
            pts = pic.xy[rest]
            pts = pts[~np.isnan(pts[:, 0])]
            if a is None or not len(pts):
                return None
            b = pts.mean(axis=0).tolist()
            d = math.hypot(a[0] - b[0], a[1] - b[1])
            thr = dom.voi(m, "out_of_position_m")
            if d - hi > thr:
                dom.ea.post(Candidate(
                    tf, "band", m.compute_priority("band"), (unit, other),
                    f"{dom.name(unit)} not joined to {dom.name(other)} by its {m.TYPE}'s time: {km(d)} apart "
                    f"(within {km(hi)} wanted)", key=("band", m.id, "joined"), measure=d - hi,
                    details={"mission": m.id, "unit": unit, "supported": other, "distance_m": round(d, 1),
                             "band_m": [0.0, hi],
                             "off_m": round(d - hi, 1), "threshold_m": thr, "check": "joined"}))
            return None
        dom.timers.not_later_than(("joined", m.id), when, due, tag=m.id)

    def end_mission(self, mid: str) -> None:
        self.bands.pop(mid, None)
        self.since.pop(mid, None)
        self.behind.pop(mid, None)

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        dom = self.dom
        if not self.bands or dom.plan is None or not (ch.units or ch.rescan):
            return
        for mid, (m, other, lo, hi) in self.bands.items():
            if dom.plan.state.get(mid) != "active" or not dom.in_plan(m):
                continue
            if not ch.rescan and m.unit not in ch.units and other not in ch.units:
                continue
            if t < self.since.get(mid, -math.inf):
                continue
            a, b = dom.unit_pos.get(m.unit), dom.unit_pos.get(other)
            if a is None or b is None:
                continue
            d = math.hypot(a[0] - b[0], a[1] - b[1])
            off = d - hi if d > hi else lo - d
            thr = dom.voi(m, "out_of_position_m")
            if mid in self.behind:
                self._ahead(t, m, other, a, b, thr, cands)
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

    def _ahead(self, t: float, m: Mission, other: str, a, b, thr: float, cands: list[Candidate]) -> None:
        """The unit nearer the place both go to than the unit it follows, by more than the threshold."""
        dom, place = self.dom, self.behind[m.id]
        area = dom.overlay[place].area
        da, db = area.distance(shapely.Point(a)), area.distance(shapely.Point(b))
        if db - da <= thr:
            return
        cands.append(Candidate(
            t, "band", m.compute_priority("band"), (m.unit, other),
            f"{dom.name(m.unit)} ahead of {dom.name(other)} it must {m.TYPE.replace('-', ' ')}: {km(db - da)} "
            f"nearer {place}", key=("band", m.id, "ahead"), measure=db - da,
            details={"mission": m.id, "supported": other, "ahead_m": round(db - da, 1), "place": place,
                     "threshold_m": thr, "check": "ahead"}))
