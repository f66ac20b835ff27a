"""Projected penetration (beyond the paper, as the other projections): before a hostile
enters an area no hostile may enter (block, retain, guard, a defence's rear line), from
how its track has been moving, only when the first of them would be in at least `[voi]
projection_min_lead_s` ahead (a projection is worth its name only before what it
projects); and a rear line crossed between two reports. The actual penetration is the
Areas component's alert of kind "penetration"; the projection sets that alert's history,
so VOA tells the story once unless the penetration proves much stronger."""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import shapely

from ea_agent.core.alert import Candidate, hms

from ..render import km
from .base import Changes, Detector

KEEP_S = 90.0     # track history kept
TREND_S = 30.0    # a velocity is measured over at least this much of it
MIN_SPEED = 1.0   # m/s: slower tracks are halted or noise


@dataclass(slots=True)
class Ray:
    """A moving track this epoch: where it is, where it heads within the horizon, the box
    of that ray (a cheap miss test per area) and the ray itself, built when first needed."""
    k: str
    x: float
    y: float
    tip: tuple[float, float]
    speed: float
    box: tuple[float, float, float, float]
    ray: object = None


class ProjectedPenetrations(Detector):
    TYPES = {"projected-penetration": "constraint-violation-projected"}

    def reset(self) -> None:
        self.hist: dict[str, deque] = {}
        self.boxes: dict[str, tuple] = {}   # area -> (its geometry, the bounds of it)

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

    def _moving(self, keys: list[str], horizon: float) -> list[Ray]:
        """The changed tracks with a trend long enough and a speed worth projecting, each with
        where its velocity takes it within the horizon (the same for every watched area)."""
        out = []
        for k in keys:
            h = self.hist.get(k)
            if not h or h[-1][0] - h[0][0] < TREND_S:
                continue
            (t0, x0, y0), (t1, x1, y1) = h[0], h[-1]
            vx, vy = (x1 - x0) / (t1 - t0), (y1 - y0) / (t1 - t0)
            speed = (vx * vx + vy * vy) ** 0.5
            if speed < MIN_SPEED:
                continue
            x2, y2 = x1 + vx * horizon, y1 + vy * horizon
            out.append(Ray(k, x1, y1, (x2, y2), speed, (min(x1, x2), min(y1, y2), max(x1, x2), max(y1, y2))))
        return out

    def _bounds(self, area: str, geom) -> tuple[float, float, float, float]:
        """An area's bounding box, kept while the area is the same geometry."""
        c = self.boxes.get(area)
        if c is None or c[0] is not geom:
            c = self.boxes[area] = (geom, geom.bounds)
        return c[1]

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
        moving = self._moving(sorted(ch.tracks & tracks.keys()), horizon)
        for area, m in watched:
            if dom.overlay[area].geom.geom_type == "LineString":
                self._crossed(t, area, m)
            geom = dom.overlay[area].area
            gx0, gy0, gx1, gy1 = self._bounds(area, geom)
            inside = dom.areas.tracks.get(area, set())
            coming = []
            for mv in moving:
                if mv.k in inside:
                    continue
                bx0, by0, bx1, by1 = mv.box
                if bx0 > gx1 or bx1 < gx0 or by0 > gy1 or by1 < gy0:   # the ray's box misses the area's
                    continue
                if mv.ray is None:
                    mv.ray = shapely.LineString([(mv.x, mv.y), mv.tip])
                if not mv.ray.intersects(geom):
                    continue
                lead = float(shapely.distance(shapely.Point(mv.x, mv.y), mv.ray.intersection(geom))) / mv.speed
                coming.append((lead, mv.k, mv.speed))
            if not coming:
                continue
            lead, first, speed = min(coming)
            if lead < dom.voi(m, "projection_min_lead_s"):
                continue   # the first comes in too soon for a projection: the actual penetration tells it
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
