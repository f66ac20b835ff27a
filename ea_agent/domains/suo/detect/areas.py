"""Hostile activity in watched areas: global monitors of our plan (decision
points, NAIs, avenues of approach), areas missions watch (engagement areas,
screened areas) and hostiles a mission expects by a time (hostile-expected)."""
from __future__ import annotations

import math
from collections import defaultdict

import numpy as np
import shapely

from ea_agent.core.alert import Candidate, hms

from ..missions import Mission
from .assemble import hold_first
from .base import Changes, Detector
from .geometry import AreaIndex

ADVERSARIAL = "adversarial-activity"
SAME_GROUP_M = 400.0   # a new track this near where a track in the area was last seen ...
SAME_GROUP_S = 120.0   # ... this recently continues it
LINGER_M = 200.0       # a track that was in an area is still there while this near it (a halted
                       # group at the edge flickers in and out with its reports' noise)
BESIDE_M = 150.0       # a new track this near one already in the area reinforces it (its strength tells)


class Areas(Detector):
    """Owns which areas are watched and, each epoch tracks change, which tracks are
    in each (read by contingency triggers before the area alerts are made)."""
    TYPES = {"monitored": ADVERSARIAL, "ave-of-approach": ADVERSARIAL, "hostile-expected": ADVERSARIAL,
             "penetration": ADVERSARIAL}

    def __init__(self, dom) -> None:
        super().__init__(dom)
        self.strength: dict[str, int] = {}        # area -> hostile strength in it (last time tracks changed)
        self.tracks: dict[str, set[str]] = {}     # area -> tracks in it
        self._tids: list[str] = []
        self._members: dict[str, list[int]] = {}
        self.inside_t: dict[tuple[str, str], float] = {}   # (area, track) -> last time seen inside
        self.last_xy: dict[tuple[str, str], tuple[float, float]] = {}   # ... and where
        self.seen_in: dict[str, set[str]] = defaultdict(set)             # area -> tracks seen in it
        self._new: dict[str, list[str]] = {}               # area -> tracks new to it this epoch
        self._present: set[tuple[str, str]] = set()        # (area, track) in or at the edge at the last look
        self._eligible: set[tuple[str, str]] = set()       # (area, mission) watched now
        self._present_areas: set[str] = set()              # the areas in _present
        self._mon_v = 0                                    # counts changes of red_monitors
        self._elig_key: tuple = ()                         # what _eligible was derived from
        self._bounds: tuple = (None, [])                   # (index, its areas' bounds on plain floats)
        self._near_bounds: tuple = (None, [])
        self._stale = True

    def reset(self) -> None:
        # area -> (mission, hostiles expected there, alert kind: monitored | penetration)
        self.red_monitors: dict[str, list[tuple[Mission, bool, str]]] = defaultdict(list)
        self.global_areas: dict[str, str] = {}   # area -> alert type (monitored / ave-of-approach)
        self._mon_v = getattr(self, "_mon_v", 0) + 1
        self.dom.assembly.drop(lambda k: k[0] in self.TYPES)   # the old plan's watches tell nothing more

    def reindex(self) -> None:
        """The watched areas changed: rebuild the spatial index over all of them."""
        ids = (set(self.global_areas) | set(self.red_monitors) | self.dom.contingency.trigger_areas()
               | self.dom.escape.areas() | self.dom.tempo.areas())
        self.index = AreaIndex({a: self.dom.overlay[a].area for a in sorted(ids)})
        self.near_index = AreaIndex({a: self.dom.overlay[a].area.buffer(LINGER_M) for a in sorted(ids)})
        self._stale = True   # tracks already in a newly watched area are found at the next epoch

    def post_plan_monitors(self) -> None:
        """Global monitors: decision points, NAIs and avenues of approach in our plan."""
        owner = self.dom.owner
        for cm in self.dom.overlay.values():
            if cm.owner == owner and cm.kind in ("decision-point", "nai"):
                self.global_areas[cm.id] = "monitored"
            elif cm.owner == owner and cm.kind == "avenue-of-approach":
                self.global_areas[cm.id] = "ave-of-approach"
        self.reindex()

    def post_red_monitor(self, m: Mission, area: str, expected: bool, expect_by: float | None = None,
                         kind: str = "monitored") -> None:
        """Watch `area` for hostiles for mission `m`: activity there is told as `kind`
        (monitored, or penetration where no hostile may enter)."""
        dom = self.dom
        self.red_monitors[area].append((m, expected, kind))
        self._mon_v += 1
        self.reindex()
        if expect_by is not None:
            def absent(tf, mon, how):
                if dom.in_plan(m):
                    dom.ea.post(Candidate(tf, "hostile-expected", m.compute_priority("hostile-expected"),
                                          (m.unit,), f"Expected hostile activity absent at {area} for "
                                          f"{dom.name(m.unit)} {m.TYPE} (expected by {hms(float(expect_by))})",
                                          key=("hostile-expected", m.id), friendly=False,
                                          details={"mission": m.id, "area": area, "places": [area]}))
                return None
            dom.timers.not_later_than(("hostile", m.id), float(expect_by), absent, tag=m.id)

    def end_mission(self, mid: str) -> None:
        for area in list(self.red_monitors):
            self.red_monitors[area] = [x for x in self.red_monitors[area] if x[0].id != mid]
        self._mon_v += 1
        self.dom.assembly.drop(lambda k: k[0] in self.TYPES and len(k) == 3 and k[2] == mid)

    def monitored_candidate(self, m: Mission | None, area: str, t: float, tracks: list[str], strength: int,
                            expected: bool, kind: str = "monitored") -> None:
        dom = self.dom
        prio = m.compute_priority(kind) if m is not None else self.dom.base.compute_priority(kind)
        where = f" ({'expected' if expected else 'unexpected'} for {dom.name(m.unit)} {m.TYPE})" if m else ""
        label = {"ave-of-approach": "Enemy activity on ave of approach",
                 "penetration": "Penetration: hostiles in"}.get(kind, "Red activity at")
        key = (kind, area, m.id if m else None)
        new = self._new.get(area, [])
        c = Candidate(t, kind, prio, tuple(tracks), f"{label} {area}{where}: {strength} entities in "
                      f"{len(tracks)} track{'s' if len(tracks) > 1 else ''}",
                      key=key, measure=float(strength), friendly=False, news=bool(new), count=strength,
                      details={"place": area, "places": [area], "strength": strength,
                               "mission": m.id if m else None, "expected": expected, "new_tracks": new})
        # the first alert about a group there waits for the rest of it (assemble.py)
        if not hold_first(dom, c, new, bool(new)):
            dom.ea.post(c)

    def observe(self, t: float, ch: Changes) -> None:
        if not ch.tracks and not self._stale and not ch.rescan:
            return
        self._stale = False
        pic = self.dom.pic
        tids = sorted(pic.tracks)
        xy = [(pic.tracks[k].x, pic.tracks[k].y) for k in tids]
        members = self._inside(self.index, xy)
        self.strength = {a: int(sum(pic.tracks[tids[k]].strength for k in idx)) for a, idx in members.items()}
        self.tracks = {a: {tids[k] for k in idx} for a, idx in members.items()}
        self._tids, self._members = tids, members
        # A track that enters an area it was not seen in for the alert expiry is news
        # there (a new group at an NAI), whatever the area's alert history says.
        # A new track id where a track seen in the area has just gone is that group under
        # a new name (a fused track that broke), and one beside a track already there
        # reinforces it: neither is a new group (a stronger one is told by its strength).
        forget = float(self.dom.ea.voa.expiry)
        self._new = {}
        for a, ids in self.tracks.items():
            new = [k for k in sorted(ids) if (a, k) not in self._present   # there since the last look
                   and t - self.inside_t.get((a, k), -math.inf) >= forget]
            gone = [self.last_xy[(a, j)] for j in self.seen_in.get(a, ()) if j not in ids
                    and t - self.inside_t[(a, j)] < SAME_GROUP_S]
            new = [k for k in new if not any(math.hypot(pic.tracks[k].x - x, pic.tracks[k].y - y) <= SAME_GROUP_M
                                             for x, y in gone)]
            there = [(pic.tracks[j].x, pic.tracks[j].y) for j in ids if j not in new]
            new = [k for k in new if not any(math.hypot(pic.tracks[k].x - x, pic.tracks[k].y - y) <= BESIDE_M
                                             for x, y in there)]
            if new:
                self._new[a] = new
            for k in ids:
                self.last_xy[(a, k)] = (pic.tracks[k].x, pic.tracks[k].y)
                self.seen_in[a].add(k)
        # a track's time in an area is stamped when it changed, and at the periodic scan:
        # not at whichever epochs other tracks' changes closed (an in-process EA hears more
        # of those than a peer, and both must tell the same news)
        present = set()
        stamp, changed = ch.rescan, ch.tracks
        for a, idx in self._inside(self.near_index, xy).items():   # still there, or at its edge
            for i in idx:
                k = tids[i]
                was = self.inside_t.get((a, k))
                if (was is not None and t - was < forget) or k in self.tracks.get(a, ()):
                    if stamp or k in changed or was is None:
                        self.inside_t[(a, k)] = t
                    present.add((a, k))
        self._present = present
        self._present_areas = {a for a, _ in present}
        if len(self.inside_t) > 4 * max(1, len(tids)) * max(1, len(members)):   # bounded: drop the forgotten
            self.inside_t = {ak: s for ak, s in self.inside_t.items() if t - s < forget}
            self.last_xy = {ak: xy for ak, xy in self.last_xy.items() if ak in self.inside_t}
            self.seen_in = defaultdict(set)
            for a, k in self.inside_t:
                self.seen_in[a].add(k)

    def _inside(self, index: AreaIndex, xy: list[tuple[float, float]]) -> dict[str, list[int]]:
        """AreaIndex.members on plain floats (a handful of tracks and areas: the bounding boxes
        in Python, then one contains_xy call for every candidate pair, not one per area)."""
        if not xy or not index.ids:
            return {}
        cache = self._bounds if index is self.index else self._near_bounds
        if cache[0] is not index:
            cache = (index, [tuple(b) for b in index.bounds.tolist()])
            if index is self.index:
                self._bounds = cache
            else:
                self._near_bounds = cache
        ks, ii, px, py = [], [], [], []
        for k, (x0, y0, x1, y1) in enumerate(cache[1]):
            for i, (x, y) in enumerate(xy):
                if x0 <= x <= x1 and y0 <= y <= y1:
                    ks.append(k)
                    ii.append(i)
                    px.append(x)
                    py.append(y)
        out: dict[str, list[int]] = {}
        if not ks:
            return out
        polys = index.polys
        for k, i, inside in zip(ks, ii, shapely.contains_xy([polys[k] for k in ks], px, py).tolist()):
            if inside:
                out.setdefault(index.ids[k], []).append(i)
        return out

    def _eligible_now(self) -> set[tuple[str, str]]:
        """(area, mission) pairs watched now: derived again only when a plan state, the
        red monitors or our units changed."""
        dom = self.dom
        plan = dom.plan
        states = plan.state if plan else None
        key = (plan, states, getattr(states, "version", None), self._mon_v, dom.own_units)
        old = self._elig_key
        if (old and states is not None and old[1] is states and old[0] is plan and old[2] == key[2]
                and old[3] == key[3] and old[4] is key[4]):
            return self._eligible
        self._elig_key = key
        return {(area, m.id) for area, mons in self.red_monitors.items() for m, _, _ in mons
                if dom.plan and dom.plan.state.get(m.id) in ("ready", "active") and dom.in_plan(m)}

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        dom = self.dom
        # a mission whose watch begins (it became ready) is told what is already in its
        # area, stationary hostiles included: they would never show as a change
        eligible = self._eligible_now()
        begun, self._eligible = eligible - self._eligible, eligible
        # a group still in an area (or lingering at its edge) keeps what was told of it
        # alive, changed or not: it is no news when it next moves
        voa = dom.ea.voa   # at the scan, or where a track there changed (see observe)
        for area in self._present_areas if ch.rescan else {a for a, k in self._present if k in ch.tracks}:
            kind = self.global_areas.get(area)
            if kind:
                voa.touch((kind, area, None), t)
            for m, _, kind in self.red_monitors.get(area, ()):
                voa.touch((kind, area, m.id), t)
        if not ch.tracks and not begun:
            return
        fired = dom.contingency.fired   # a triggered contingency says it already
        tids = self._tids
        for area, idx in self._members.items():
            ids = [tids[k] for k in idx]
            changed = bool(ch.tracks.intersection(ids))
            strength = self.strength[area]
            for m, expected, kind in self.red_monitors.get(area, ()):
                if (area, m.id) in eligible and (changed or (area, m.id) in begun):
                    dom.timers.occurred(("hostile", m.id), t)
                    m.respond_to_monitored_red_activity(dom, area, t, ids, strength, kind)
            kind = self.global_areas.get(area)
            if changed and kind and area not in fired:
                self.monitored_candidate(None, area, t, ids, strength, expected=False, kind=kind)
