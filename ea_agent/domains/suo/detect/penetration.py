"""Projected penetration (beyond the paper, as the other projections): before a hostile
enters an area no hostile may enter (block, retain, guard, a defence's rear line), from
how its track has been moving; and a rear line crossed between two reports. The actual penetration is the Areas component's alert
of kind "penetration"; the projection sets that alert's history, so VOA tells the
story once unless the penetration proves much stronger."""
from __future__ import annotations

from collections import deque

import shapely

from ea_agent.core.alert import Candidate, hms

from ..render import km
from .base import Changes, Detector

KEEP_S = 90.0     # track history kept
TREND_S = 30.0    # a velocity is measured over at least this much of it
MIN_SPEED = 1.0   # m/s: slower tracks are halted or noise


class ProjectedPenetrations(Detector):
    TYPES = {"projected-penetration": "constraint-violation-projected"}

    def reset(self) -> None:
        self.hist: dict[str, deque] = {}

    def observe(self, t: float, ch: Changes) -> None:
        if not ch.tracks:
            return
        tracks = self.dom.pic.tracks
        for k in ch.tracks:
            e = tracks.get(k)
            if e is None:
                self.hist.pop(k, None)
                continue
            h = self.hist.setdefault(k, deque())
            if h and h[-1][0] >= t:
                h.pop()
            h.append((t, e.x, e.y))
            while h and h[0][0] < t - KEEP_S:
                h.popleft()

    def _crossed(self, t: float, area: str, m) -> None:
        """A line no hostile may cross: a track whose last move went across it has, even
        if no report put it inside the line's strip (a fast mover between two reports)."""
        dom = self.dom
        line = dom.overlay[area].geom
        gone = dom.areas.tracks.get(area, set())   # in the strip: the Areas component tells it
        over = [k for k, h in self.hist.items() if len(h) >= 2 and h[-1][0] == t and k not in gone
                and line.intersects(shapely.LineString([h[-2][1:], h[-1][1:]]))]
        if over:
            strength = sum(dom.pic.tracks[k].strength for k in over if k in dom.pic.tracks)
            dom.areas.monitored_candidate(m, area, t, sorted(over), strength, expected=False, kind="penetration")

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        dom = self.dom
        horizon = float(dom.voi_cfg["penetration_horizon_s"])
        if not ch.tracks or dom.plan is None or horizon <= 0.0:
            return
        watched = [(area, m) for area, mons in dom.areas.red_monitors.items() for m, _, kind in mons
                   if kind == "penetration" and dom.plan.state.get(m.id) in ("ready", "active") and dom.in_plan(m)]
        if not watched:
            return
        tracks = dom.pic.tracks
        for area, m in watched:
            if dom.overlay[area].geom.geom_type == "LineString":
                self._crossed(t, area, m)
            geom = dom.overlay[area].area
            inside = dom.areas.tracks.get(area, set())
            coming = []
            for k in sorted(ch.tracks & tracks.keys()):
                h = self.hist.get(k)
                if k in inside or not h or h[-1][0] - h[0][0] < TREND_S:
                    continue
                (t0, x0, y0), (t1, x1, y1) = h[0], h[-1]
                vx, vy = (x1 - x0) / (t1 - t0), (y1 - y0) / (t1 - t0)
                speed = (vx * vx + vy * vy) ** 0.5
                if speed < MIN_SPEED:
                    continue
                ray = shapely.LineString([(x1, y1), (x1 + vx * horizon, y1 + vy * horizon)])
                if not ray.intersects(geom):
                    continue
                lead = float(shapely.distance(shapely.Point(x1, y1), ray.intersection(geom))) / speed
                coming.append((lead, k, speed))
            if not coming:
                continue
            lead, first, speed = min(coming)
            ids = sorted(k for _, k, _ in coming)
            strength = sum(tracks[k].strength for k in ids)
            cands.append(Candidate(
                t, "projected-penetration", m.compute_priority("projected-penetration"), tuple(ids),
                f"Hostiles projected to enter {area} held by {dom.name(m.unit)} ({m.TYPE}) in {lead:.0f} s "
                f"(at {hms(t + lead)}): {strength} entities, {km(speed * lead)} out at {speed:.1f} m/s",
                key=("projected-penetration", area, m.id), measure=float(strength), friendly=False,
                details={"mission": m.id, "projects": "penetration", "place": area, "places": [area],
                         "projected_t": round(t + lead, 1), "lead_s": round(lead, 1), "strength": strength,
                         "tracks": ids},
                also=((("penetration", area, m.id), float(strength)),), projection=True))
