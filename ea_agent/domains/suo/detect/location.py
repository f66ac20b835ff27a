"""Out-of-position: location monitors a mission posts while active (route, axis,
position, or the corridor from its start to where it goes) and the checks it asks for
at start and end (destination, objective). Monitors are judged when their unit moves
and, on every periodic scan, for units that did not (a unit that never moves from the
wrong place is told too)."""
from __future__ import annotations

import math
from collections import defaultdict
from typing import NamedTuple

import numpy as np
import shapely

from ea_agent.core.alert import Candidate, hms
from ea_agent.core.geo import bearing_name

from ..missions import Mission
from ..render import km
from .base import Changes, Detector
from .geometry import judged_distance, judged_distance_swept

_NAN_ALLOW = np.intc(0)   # shapely.lib.points' handle_nan: allow (shapely.points' default)


RECHECK_S = 30.0          # units that did not move are judged this often (they move nothing but the clock)
CORRIDOR_BACK_M = 300.0   # a corridor reaches this far behind its start (its start is an estimate: a
                          # halting unit's dead-reckoned centroid overshoots, a stale one lags)


class Anchor(NamedTuple):
    """A centroid monitor's last measured distance: where the unit was, from which geometry
    (a rebuilt corridor is a new one), and the nearest point of it once a message needed it."""
    geom: object
    x: float
    y: float
    d: float
    near: tuple[float, float] | None


class LocationMonitors(Detector):
    TYPES = {"out-of-position": "plan-constraint-violated"}

    def reset(self) -> None:
        self.monitors: dict[str, list[tuple[Mission, str, str, str]]] = defaultdict(list)   # only via post
        self.corridor_to: dict[str, tuple[Mission, str]] = {}   # mission -> (it, where its corridor leads)
        self.corridors: dict[str, object] = {}                   # mission -> corridor (built at start)
        self.lines: dict[str, object] = {}                       # ... the line of it (to the target's edge)
        self.corridor_of: dict[str, tuple] = {}                  # ... its start and the members it judges
        self.next_all = 0.0                                      # when units that did not move are judged next
        self.anchors: dict[tuple[str, str, str], Anchor] = {}   # (mission, geometry id, check) -> last measured
        self._rev = 0            # bumped whenever a monitor or corridor is added or dropped
        self._running: tuple | None = None   # (what it was built from, the running monitors: see _running_monitors)

    def post(self, m: Mission, geom: str, rule: str, what: str) -> None:
        self.monitors[m.id].append((m, geom, rule, what))
        self._rev += 1

    def post_corridor(self, m: Mission, target: str) -> None:
        """A route for a mission that has none: from where the unit is at its start to
        the nearest point of `target` (built by `start`, or as soon as the unit's
        position is known)."""
        self.corridor_to[m.id] = (m, target)

    def start(self, m: Mission, t: float) -> None:
        """Check-Initial-Location: build the mission's corridor from where its unit is,
        then judge every monitor it posted at once, whether the unit moves or not."""
        self._corridor(m)
        for _, geom, rule, what in list(self.monitors.get(m.id, ())):
            self.check(m, geom, rule, t, what)

    def _corridor(self, m: Mission, start: tuple[float, float] | None = None) -> None:
        """The corridor from `start` (default: the unit's centroid now) to the nearest point
        of its target, with the target itself (arriving is no departure from it); nothing
        while the unit's position is unknown."""
        if m.id not in self.corridor_to:
            return
        # where its members' reports, moved on by their velocity, put the unit now (a report
        # up to a minute old would start the corridor behind a moving unit)
        pos = start or self.dom.unit_now.get(m.unit) or self.dom.pic.centroid(m.unit)
        if pos is None:
            return
        area = self.dom.overlay[self.corridor_to[m.id][1]].area
        if m.id not in self.corridors:
            self.monitors[m.id].append((m, m.id, m.LOCATION_RULE, "corridor"))
        line = shapely.shortest_line(shapely.Point(pos), area)
        (x0, y0), (x1, y1) = line.coords
        n = max(((x1 - x0) ** 2 + (y1 - y0) ** 2) ** 0.5, 1e-9)
        back = CORRIDOR_BACK_M / n   # a unit a little behind where it was thought to start is not off it
        self.lines[m.id] = shapely.LineString([(x0 - (x1 - x0) * back, y0 - (y1 - y0) * back), (x1, y1)])
        self.corridors[m.id] = shapely.union(self.lines[m.id], area)
        self.corridor_of[m.id] = (pos, self.dom.pic.members[m.unit].copy())
        self._rev += 1

    def _pending_corridors(self) -> None:
        """Running missions whose corridor could not be built at their start (position unknown)."""
        plan = self.dom.plan
        for mid, (m, _) in list(self.corridor_to.items()):
            if mid not in self.corridors and plan is not None and plan.state.get(mid) == "active":
                self._corridor(m)

    def org_changed(self) -> None:
        """A reorganization moves a unit's centroid without any member moving: the start
        of a running mission's corridor moves with it (by the centroid of its new members
        less that of its old ones, now), so a unit already off its corridor stays off."""
        pic = self.dom.pic
        for mid in list(getattr(self, "corridors", ())):
            m = self.corridor_to[mid][0]
            (x, y), old = self.corridor_of[mid]
            new = pic.members[m.unit]
            if np.array_equal(old, new):
                continue
            a, b = pic.xy[old], pic.xy[new]
            a, b = a[~np.isnan(a[:, 0])], b[~np.isnan(b[:, 0])]
            if len(a) and len(b):
                dx, dy = (b.mean(axis=0) - a.mean(axis=0)).tolist()
                self._corridor(m, (x + dx, y + dy))

    def end_mission(self, mid: str) -> None:
        for _, g, _, what in self.monitors.get(mid, ()):
            self.anchors.pop((mid, g, what), None)
        self.monitors.pop(mid, None)
        self.corridors.pop(mid, None)
        self.lines.pop(mid, None)
        self.corridor_to.pop(mid, None)
        self._rev += 1

    def check(self, m: Mission, geom_id: str, rule: str, t: float, what: str) -> None:
        """A one-off check (start or end of a mission), alerted at once."""
        p0, p1 = self.dom.pic.swept(m.unit, t, float(self.dom.voi_cfg["dead_reckon_s"]))
        d = judged_distance_swept(self._geom(geom_id, what), p0, p1, rule)
        if d is not None and d > self.dom.voi(m, "out_of_position_m"):
            self.dom.ea.post(self._oop(m, geom_id, rule, what, t, d))

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        dom = self.dom
        every = ch.rescan and t >= self.next_all
        if not (ch.leaves or every) or dom.plan is None:
            return
        if every:
            self.next_all = t + RECHECK_S
        if every and len(self.corridors) < len(self.corridor_to):
            self._pending_corridors()
        cents, others = [], []
        for unit, c, o in self._running_monitors():
            if every or unit in ch.units:
                cents += c
                others += o
        if cents:
            cands.extend(self._centroid_candidates(t, cents))
        for m, g, rule, what in others:
            c = self._oop(m, g, rule, what, t)
            if c is not None:
                cands.append(c)

    def _running_monitors(self) -> list[tuple[str, list[tuple], list[tuple]]]:
        """Per active mission of ours with monitors, in the order they were posted: its unit, its
        centroid monitors (with what judging them needs: see _centroid_entry) and its other ones.
        Rebuilt only when a plan state, a monitor, a corridor, the organization or the threshold
        changed (scanning every mission per epoch was a large part of this detector's cost)."""
        dom = self.dom
        state = dom.plan.state
        version = getattr(state, "version", None)
        c = self._running
        thr = dom.voi_cfg["out_of_position_m"]   # thresholds are set live (commanders lower them)
        if (c is not None and version is not None and c[0] is dom.plan and c[1] is state and c[2] == version
                and c[3] is dom.own_units and c[4] == self._rev and c[6] == thr):
            return c[5]
        out = []
        for mid, mons in self.monitors.items():
            if not mons or state.get(mid) != "active":
                continue
            m = mons[0][0]
            ours = dom.in_plan(m)
            mine = [mon for mon in mons if (ours if mon[0] is m else dom.in_plan(mon[0]))]
            if mine:
                out.append((m.unit, [self._centroid_entry(mon) for mon in mine if mon[2] == "centroid"],
                            [mon for mon in mine if mon[2] != "centroid"]))
        self._running = (dom.plan, state, version, dom.own_units, self._rev, out, thr)
        return out

    def _centroid_entry(self, mon: tuple[Mission, str, str, str]) -> tuple:
        """A centroid monitor with its anchor key, geometry, threshold and the bound under which
        a distance is surely within it (a rebuilt corridor bumps the revision the running
        monitors are kept by, a threshold set anew rebuilds them)."""
        m, g, _, what = mon
        thr = self.dom.voi(m, "out_of_position_m")
        return mon, m.unit, (m.id, g, what), self._geom(g, what), thr, thr * (1.0 - 1e-9) - 1e-6

    def _centroid_candidates(self, t: float, entries: list[tuple]) -> list[Candidate]:
        """Centroid-judged monitors (entries of _centroid_entry). A distance is 1-Lipschitz in the
        position, so a unit whose last measured distance plus how far it moved since is still
        within the threshold is within it: only the others are measured (one vectorised call
        for all of them, straight to shapely.lib: the wrappers' overhead is most of the cost)."""
        unit_pos = self.dom.unit_pos
        anchors = self.anchors
        hypot = math.hypot
        judged = []    # (monitor, anchor key, threshold) of the monitors that may be out
        measure = []   # (anchor key, geometry, position) whose distance is not known
        for mon, unit, key, geom, thr, lim in entries:
            pos = unit_pos.get(unit)
            if not pos:
                continue
            a = anchors.get(key)
            if a is None or a.geom is not geom:
                measure.append((key, geom, pos))
            elif a.x != pos[0] or a.y != pos[1]:
                if a.d + hypot(pos[0] - a.x, pos[1] - a.y) < lim:
                    continue
                measure.append((key, geom, pos))
            judged.append((mon, key, thr))
        if not judged:
            return []
        if measure:
            pts = shapely.lib.points(np.array([pos for _, _, pos in measure], dtype=float), _NAN_ALLOW)
            ds = shapely.lib.distance(np.array([geom for _, geom, _ in measure], dtype=object), pts).tolist()
            for (key, geom, (x, y)), d in zip(measure, ds):
                anchors[key] = Anchor(geom, x, y, d, None)
        out = [(mon, key, anchors[key]) for mon, key, thr in judged if anchors[key].d > thr]
        need = [(key, a) for _, key, a in out if a.near is None]
        if need:   # the nearest points, for the bearing the message gives
            lines = shapely.lib.shortest_line(
                shapely.lib.points(np.array([(a.x, a.y) for _, a in need], dtype=float), _NAN_ALLOW),
                np.array([a.geom for _, a in need], dtype=object))
            near = shapely.lib.get_coordinates(lines, False, False, False)[1::2].tolist()
            for (key, a), p in zip(need, near):
                anchors[key] = a._replace(near=tuple(p))
        return [self._oop(m, g, rule, what, t, a.d, anchors[key].near) for (m, g, rule, what), key, a in out]

    def _geom(self, geom_id: str, what: str):
        """Routes and axes are judged by distance to the line; everything else to its area."""
        if what == "corridor":
            return self.corridors[geom_id]
        cm = self.dom.overlay[geom_id]
        return cm.geom if what in ("route", "axis") else cm.area

    def _oop(self, m: Mission, geom_id: str, rule: str, what: str, t: float, d: float | None = None,
             near: tuple[float, float] | None = None) -> Candidate | None:
        dom = self.dom
        pos = dom.unit_pos.get(m.unit)
        geom = self._geom(geom_id, what)
        if d is None:
            d = judged_distance(geom, dom.pic.member_xy(m.unit), rule, pos)
        thr = dom.voi(m, "out_of_position_m")
        if d is None or d <= thr:
            return None
        place = self.corridor_to[geom_id][1] if what == "corridor" else geom_id
        ref = f"should be in the corridor to {place}" if what == "corridor" else f"should be at {geom_id}"
        if what == "by":   # a time the plan names (a seizure's): judged then
            ref += f" by {hms(t)}"
        if pos is not None:
            if near is None:
                near = shapely.shortest_line(shapely.Point(pos), geom).coords[-1]
            ref += f" ({km(d)} {bearing_name(near[0] - pos[0], near[1] - pos[1])} of {dom.name(m.unit)})" if rule == "centroid" else f" ({rule} members within {km(thr)})"
        return Candidate(t, "out-of-position", m.compute_priority("out-of-position"), (m.unit,),
                         f"{dom.name(m.unit)} out of position for {m.TYPE} mission: {ref}",
                         key=("out-of-position", m.id, what), measure=d,
                         details={"mission": m.id, "control_measure": place, "rule": rule, "check": what,
                                  "distance_m": round(d, 1), "threshold_m": thr, "places": [place]})
