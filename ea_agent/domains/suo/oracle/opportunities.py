"""Ground truth for new opportunities (Fig. 1): a place the plan cares about cleared by
the enemy's own move, away from our units.

 - objective-clear: the objective of an offensive task (OPPORTUNITY_OBJECTIVE) while it is
   ready or running, unless an isolate, fix or destroy of the plan holds the enemy there
   (their leaving is an escape);
 - enemy-withdrawn: the engagement area of any other task that names one (a contain's
   holds the enemy in).

A clearing begins when the last known group is out of the area and ends when every known
group is 2 x TOLERANCE_M beyond it (sensors place a group within TOLERANCE_M). It is an
incident when a group was deep inside (TOLERANCE_M within the edge) while watched, every
group that was in it is still known at the end, and each is AWAY_M farther from every
watching unit than the area's centre is; a group that vanished, or that left sideways, may
be told or not; one that left towards our units is no opportunity at all.
"""
from __future__ import annotations

import math

import numpy as np
from shapely.geometry import Point

from .spec import EPISODE_S, ESCAPE, TICK, TOLERANCE_M, TRACK_S, _bands

OPPORTUNITY_OBJECTIVE = {"attack", "breach", "clear", "hasty-attack", "secure", "seize"}
AWAY_M = 400.0   # how much farther from our units than the area's centre a group must end up


class Opportunities:
    """New opportunities: objectives and engagement areas left clear by a withdrawing enemy."""

    def _watched(self) -> dict[tuple[str, str], list[str]]:
        """(type, area) -> the missions that watch it."""
        held_in = {m["params"].get(ESCAPE[m["type"]]) for m in self.missions.values()
                   if m["type"] in ESCAPE and ESCAPE[m["type"]] == "objective"}
        out: dict[tuple[str, str], list[str]] = {}
        for mid, m in sorted(self.missions.items()):
            p = m["params"]
            if m["type"] in OPPORTUNITY_OBJECTIVE and p.get("objective") in self.area and p["objective"] not in held_in:
                out.setdefault(("objective-clear", p["objective"]), []).append(mid)
            ea_ = p.get("engagement_area")
            if ea_ in self.area and m["type"] not in ESCAPE:
                out.setdefault(("enemy-withdrawn", ea_), []).append(mid)
        return out

    def opportunities(self) -> None:
        for (typ, area), mids in sorted(self._watched().items()):
            for o in self.owners:
                self._clearings(o, typ, area, mids)

    def _watchers(self, o: str, mids: list[str], t: float) -> list[str]:
        out = []
        for mid in mids:
            r0, r1 = self._ready_interval(mid)
            unit = self.missions[mid]["unit"]
            if r0 <= t < r1 and unit in self.subtree(o, t):
                out.append(unit)
        return sorted(set(out))

    def _margins(self, units: list[str], k: int, area: str, groups: dict) -> list[float]:
        """Per group and watching unit: how much farther from the unit than the area's centre."""
        c = self.area[area].centroid
        out = []
        for u in units:
            p = self.member_points(u, k).mean(axis=0)
            ref = math.hypot(c.x - p[0], c.y - p[1])
            out += [math.hypot(x - p[0], y - p[1]) - ref for x, y in groups.values()]
        return out

    def _clearings(self, o: str, typ: str, area: str, mids: list[str]) -> None:
        geom = self.area[area]
        near_geom, deep = _bands(geom)
        wide = geom.buffer(2 * TOLERANCE_M)
        held: dict[str, bool] = {}   # group -> was deep inside
        ev = None                    # a clearing under way: [began, clear of near_geom at, margins at begin ok]
        last_told = -math.inf
        label = "objective clear" if typ == "objective-clear" else "expected enemy withdrew"
        for k, t in enumerate(self.ticks):
            units = self._watchers(o, mids, t)
            if not units:
                held, ev = {}, None
                continue
            hs = self.hostiles_at(t)
            pts = {h: Point(x, y) for h, (x, y, _s) in hs.items()}
            for h, p in pts.items():
                if geom.contains(p):
                    held[h] = held.get(h, False) or deep.contains(p)
            if not held:
                continue
            if any(geom.contains(p) for p in pts.values()):
                ev = None   # someone is (back) in it
                continue
            known = {h: hs[h][:2] for h in held if h in hs}
            if ev is None:
                ms = self._margins(units, k, area, known)
                ev = [t, None, bool(ms) and max(ms) > -AWAY_M]
                if ev[2]:   # the detector may see it clear from now on
                    self.may(o, [typ], sorted(held) + [area] + units, t - 15, t + EPISODE_S / 2, about=[area])
            if ev[1] is None and not any(near_geom.contains(p) for p in pts.values()):
                ev[1] = t
                if ev[2]:
                    self.may(o, [typ], sorted(held) + [area] + units, t - 15, t + 120, about=[area])
            if any(wide.contains(p) for p in pts.values()):
                continue
            began, at = ev[0], ev[1] if ev[1] is not None else t
            t1 = t + 45 + TRACK_S
            later = self.hostiles_at(t + TRACK_S)
            ms = self._margins(units, k, area, known)
            deep_held = any(held.values())
            complete = len(known) == len(held) and all(h in later for h in held)
            covered = all(self._watchers(o, mids, x) for x in np.arange(began - 15, t1 + TICK, TICK))
            if complete and deep_held and ms and min(ms) >= AWAY_M and covered and began - last_told >= EPISODE_S:
                self.must(o, typ, [], sorted(held) + [area] + units, began - 15, t1, f"{area} {label}", at=at,
                          about=[area])
                last_told = began
            elif ms and max(ms) > -AWAY_M:
                self.may(o, [typ], sorted(held) + [area] + units, began - 15, t1 + 30, about=[area])
            held, ev = {}, None
