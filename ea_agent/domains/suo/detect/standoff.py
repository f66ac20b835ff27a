"""Standoff: a screen, a bypass, a withdrawal or a delay keeps its distance from the enemy
(`standoff_m`, by default the weapons range): a hostile nearer than that to the unit's
centroid means it is becoming decisively engaged, against its task. One story per
mission while hostiles stay near (VOA is touched), told again after the expiry. A bypass
also keeps its centroid out of the area it bypasses (going through it is no bypass)."""
from __future__ import annotations

import numpy as np
import shapely

from ea_agent.core.alert import Candidate

from ..missions import Mission
from ..render import km
from .base import Changes, Detector


class Standoffs(Detector):
    TYPES = {"standoff": "plan-constraint-violated"}

    def reset(self) -> None:
        self.watch: dict[str, Mission] = {}
        self.found: dict[str, frozenset[str]] = {}   # mission id -> the tracks too near at its last look
        self.bypassed: dict[str, str] = {}           # mission id -> the area its unit stays out of

    def post(self, m: Mission, bypassed: str | None = None) -> None:
        self.watch[m.id] = m
        if bypassed is not None:
            self.bypassed[m.id] = bypassed

    def end_mission(self, mid: str) -> None:
        self.watch.pop(mid, None)
        self.found.pop(mid, None)
        self.bypassed.pop(mid, None)

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        """A mission is looked at when what it depends on changed: a report of its unit,
        the periodic scan (its dead-reckoned place moved on), or a change of a track that
        is too near now or was at its last look; not when a unit or a track elsewhere
        changed, which an in-process EA hears and a peer may not (see ThreatsAhead)."""
        dom = self.dom
        if not self.watch or dom.plan is None or not (ch.tracks or ch.units or ch.rescan):
            return
        if self.bypassed and (ch.units or ch.rescan):
            self._through(t, ch, cands)
        tracks = dom.pic.tracks
        # the live tracks (as Picture.live_tracks), on plain floats
        live = [(k, e.x, e.y) for k, e in sorted(tracks.items()) if e.strength > 0]
        if not live:
            self.found.clear()
            return
        changed = ch.tracks
        ids = xy = None
        for mid, m in self.watch.items():
            if dom.plan.state.get(mid) != "active" or not dom.in_plan(m):
                continue
            again = ch.rescan or m.unit in ch.units
            before = self.found.get(mid, frozenset())
            if not (again or changed):
                continue
            pos = dom.unit_now.get(m.unit) or dom.unit_pos.get(m.unit)
            if pos is None:
                continue
            keep = dom.voi(m, "standoff_m")
            px, py = pos
            inside: list[str] = []
            if any(abs(x - px) < keep and abs(y - py) < keep for _, x, y in live):
                if ids is None:
                    ids = [k for k, _, _ in live]
                    xy = np.array([(x, y) for _, x, y in live]).reshape(-1, 2)
                d = np.hypot(xy[:, 0] - pos[0], xy[:, 1] - pos[1])
                inside = [k for k, ok in zip(ids, (d < keep).tolist()) if ok]
            if not (again or changed.intersection(before) or changed.intersection(inside)):
                continue   # only tracks that are not near changed: nothing to look at
            self.found[mid] = frozenset(inside)
            if not inside:
                continue
            key = ("standoff", mid)
            dom.ea.voa.touch(key, t)   # still too near: the same story
            nearest = float(d.min())
            cands.append(Candidate(
                t, "standoff", m.compute_priority("standoff"), (m.unit, *inside),
                f"{dom.name(m.unit)} within {km(nearest)} of hostiles on its {m.TYPE} (standoff {km(keep)}): "
                f"{sum(tracks[k].strength for k in inside)} entities",
                key=key, measure=keep - nearest, friendly=False,
                details={"mission": mid, "distance_m": round(nearest, 1), "standoff_m": keep, "tracks": inside}))

    def _through(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        """Units inside the area they bypass, by more than the out-of-position threshold."""
        dom = self.dom
        for mid, area in self.bypassed.items():
            m = self.watch[mid]
            if dom.plan.state.get(mid) != "active" or not dom.in_plan(m) or not (ch.rescan or m.unit in ch.units):
                continue
            pos = dom.unit_pos.get(m.unit)
            if pos is None:
                continue
            geom = dom.overlay[area].area
            p = shapely.Point(pos)
            depth = geom.exterior.distance(p) if geom.geom_type == "Polygon" and geom.contains(p) else 0.0
            if depth <= dom.voi(m, "out_of_position_m"):
                continue
            cands.append(Candidate(
                t, "standoff", m.compute_priority("standoff"), (m.unit,),
                f"{dom.name(m.unit)} {km(depth)} inside {area}, which its {m.TYPE} goes around",
                key=("standoff", mid, "bypassed"), measure=depth,
                details={"mission": mid, "check": "bypassed", "place": area, "depth_m": round(depth, 1),
                         "places": [area]}))
