"""Ground truth for places: where units must be and where hostiles must not go."""
from __future__ import annotations

import math
from collections import defaultdict

import numpy as np
from shapely.geometry import LineString, Point
from shapely.ops import nearest_points

from .spec import (
    ANY_RULE, APPROACH_M, CONTINGENT, COORDINATION, CORRIDOR_BACK_M, EPISODE_S,
    FINAL_RULE, FRIENDLY_ERR_M, MATERIAL, OBJECTIVE, PENETRATION, REORGANIZATION,
    RESOLVE_M, ROUTE, TICK, TRACK_S, _bands,
    _runs, geometry_params,
)


class Places:
    """Where units must be and which places hostiles must not reach (paper 6.5, Fig. 4): out of
    position (routes, corridors, positions, objectives), coordination, contingencies, watched
    areas (NAIs, avenues, engagement areas, penetration), ordered presence."""

    def _corridor(self, start, dest: str):
        """Where a unit with no route may be on its way: the line from `start` (reaching
        CORRIDOR_BACK_M behind it) to the nearest point of its destination, and the destination."""
        line = self._corridor_line(start, dest)
        return line.union(self.area[dest]) if line is not None else self.area[dest]

    def _corridor_line(self, start, dest: str):
        c = Point(start)
        near = nearest_points(c, self.area[dest])[1]
        n = c.distance(near)
        if n <= 1.0:
            return None
        k = CORRIDOR_BACK_M / n
        return LineString([(c.x - (near.x - c.x) * k, c.y - (near.y - c.y) * k), (near.x, near.y)])

    def _shift(self, unit: str, tr: float) -> np.ndarray:
        """How far a reorganization at `tr` moves the unit's centroid with no member moving."""
        k = math.ceil(tr / TICK - 1e-9)
        def mean(sub):
            return np.concatenate([self.leaf_xy[leaf][k] + self.offsets[leaf] for leaf in self.leaves
                                   if leaf in sub]).mean(axis=0)
        return mean(self.subtree(unit, tr)) - mean(self.subtree(unit, tr - 1e-6))

    def out_of_position(self) -> None:
        for mid, m in self.missions.items():
            typ = m["type"]
            p = m["params"]
            self.only, self.soft = None, False
            if typ in CONTINGENT and mid in self.task_started:   # a triggered task: its own type from then,
                self.only, self.soft = p["owner"], mid in self.task_soft   # for the EA that holds it
                typ, p = m["params"]["task"], m["params"].get("task_params", {})
                self.started.setdefault(mid, self.task_started[mid])
            rule = "any" if typ in ANY_RULE else "centroid"
            cont = p.get("route") or p.get("axis") or p.get("position")
            if typ in CONTINGENT | REORGANIZATION or mid not in self.started:
                continue
            thr = self.thr(m, "out_of_position_m")
            v0, v1 = self.valid[mid]
            s, e = max(self.started[mid], v0), min(self.ended.get(mid, math.inf), v1)
            dest = p.get("destination") or p.get("objective")
            corridor = not cont and dest in self.area and typ in ROUTE | OBJECTIVE
            if cont or corridor:
                # a corridor starts again wherever a reorganization moves the unit's centroid
                # a corridor starts where the unit is at its start; it moves with the centroid
                # when a reorganization changes the unit's members
                shifts = [tr for tr, _, _ in self.reorgs if s < tr < e and
                          self.subtree(m["unit"], tr) != self.subtree(m["unit"], tr - 1e-6)]
                geom = (self.geom[cont] if (p.get("route") or p.get("axis")) else self.area[cont]) if cont else None
                if corridor:
                    start = self.member_points(m["unit"], math.ceil(s / TICK - 1e-9)).mean(axis=0)
                    geom = self._corridor(start, dest)
                    self.corridor_start[mid] = start
                hits: list[float] = []
                dist: dict[float, float] = {}
                for k, t in enumerate(self.ticks):
                    if s <= t < e:
                        while corridor and shifts and shifts[0] <= t:
                            start = start + self._shift(m["unit"], shifts.pop(0))
                            geom = self._corridor(start, dest)
                        d = self.judged(geom, m["unit"], k, rule)
                        if d > thr / MATERIAL:   # within a MATERIAL step of the threshold either answer is fair
                            hits.append(t)
                            dist[t] = d
                for a, b in _runs(hits):
                    over = [t for t in hits if a <= t <= b and dist[t] > thr]   # past the threshold itself
                    peak = max(dist[t] for t in hits if a <= t <= b)
                    for o in self.owners_of(m["unit"], a):
                        if peak > 1.5 * thr and over and over[-1] - over[0] >= 30:
                            at = over[0]   # a triggered task: not before it must have fired
                            self.must(o, "out-of-position", [], [m["unit"]], a - self.slack,
                                      max(at, self.task_due.get(mid, at)) + 60, f"{mid} off {cont or 'its corridor'}",
                                      at=at)
                        self.may(o, ["out-of-position"], [m["unit"]], a - self.slack, b + self.slack)
            dest = p.get("destination") or p.get("objective")
            geo = geometry_params(typ)
            if dest and math.isfinite(e) and dest in self.area and "destination" in geo or (
                    dest and math.isfinite(e) and "objective" in geo):
                k = int(round(e / TICK))
                d = self.judged(self.area[dest], m["unit"], k, FINAL_RULE.get(typ, rule))
                # within a MATERIAL step of the threshold either answer is fair (reports
                # are up to a report interval old when the end is confirmed)
                for o in self.owners_of(m["unit"], e) if d > thr / MATERIAL else ():
                    if d > thr * MATERIAL:
                        self.must(o, "out-of-position", [], [m["unit"]], e - 1, e + 5, f"{mid} not at {dest}", at=e)
                    else:
                        self.may(o, ["out-of-position"], [m["unit"]], e - 1, e + 5)
        self.only, self.soft = None, False

    def coordination(self) -> None:
        for mid, m in self.missions.items():
            if m["type"] not in COORDINATION:
                continue
            p = m["params"]
            dl = float(p["at"]) + float(p.get("fuzz_s", self.voi["schedule_s"]))
            if not self.valid[mid][0] <= dl < self.valid[mid][1]:
                continue
            radius = float(self.voi["coordination_radius_m"])
            ok = False
            for k, t in enumerate(self.ticks):
                if t > dl:
                    break
                if all(self.judged(self.geom[p["point"]], u, k, "any") <= radius for u in (m["unit"], p["partner"])):
                    ok = True
                    break
            if not ok:
                for o in self.owners_of(m["unit"], dl):
                    self.must(o, "coordination", [], [m["unit"], p["partner"]], dl - 1, dl + 5, f"{mid} failed", at=dl)

    def contingency(self) -> None:
        self.triggered_areas: dict[str, set[str]] = defaultdict(set)
        for mid, m in self.missions.items():
            if m["type"] not in CONTINGENT:
                continue
            owner, tr = m["params"]["owner"], m["params"]["trigger"]
            if owner not in self.owners:
                continue
            geom = self.area[tr["area"]]
            # sensors place hostiles within TOLERANCE_M: the trigger may fire once enough
            # strength is that near the area, and must once it is that far inside
            near_g, deep_g = _bands(geom)
            need = tr.get("min_strength", 1)
            t_near = t_in = None
            for k, t in enumerate(self.ticks):
                if not self.valid[mid][0] <= t < self.valid[mid][1]:
                    continue
                if tr["kind"] == "hostile-in-area":
                    hs = [(Point(x, y), st) for x, y, st in self.hostiles_at(t).values()]
                    if t_near is None and sum(st for p, st in hs if near_g.contains(p)) >= need:
                        t_near = t
                    if t_in is None and sum(st for p, st in hs if geom.contains(p)) >= need:
                        t_in = t
                    hit = sum(st for p, st in hs if deep_g.contains(p)) >= need
                    t0, at = (t if t_near is None else t_near) - 15, t if t_in is None else t_in
                else:
                    c = self.member_points(tr["unit"], k).mean(axis=0)
                    hit, t0, at = geom.distance(Point(c)) <= tr.get("within_m", 0.0), t - self.slack, t
                if hit:
                    self.must(owner, "contingency", [], [m["unit"]], t0, t + 40, f"{mid} triggered", at=at)
                    self.task_started[mid], self.task_due[mid] = t0 + 15, t   # its task runs from the trigger
                    self.triggered_areas[owner].add(tr["area"])
                    break
            else:
                if t_near is not None:   # it came near, never well inside: it may have fired, and its
                    self.may(owner, ["contingency"], [m["unit"]], t_near - 15, self.ticks[-1])   # task run
                    self.task_started[mid], self.task_due[mid] = t_near, t_near
                    self.task_soft.add(mid)

    def areas(self) -> None:
        """monitored / ave-of-approach / hostile-expected from true hostile positions."""
        for o in self.owners:
            watch: list[tuple[str, str, str | None]] = []  # (area, type, mission)
            for fid, p in self.props.items():
                if p.get("owner") == o and p["kind"] in ("decision-point", "nai"):
                    watch.append((fid, "monitored", None))
                elif p.get("owner") == o and p["kind"] == "avenue-of-approach":
                    watch.append((fid, "ave-of-approach", None))
            for mid, m in self.missions.items():
                geo = geometry_params(m["type"])
                for key in ("engagement_area", "area"):
                    a = m["params"].get(key)
                    if a and key in geo and key not in PENETRATION.get(m["type"], ()):
                        watch.append((a, "monitored", mid))
                held = next((m["params"][k] for k in PENETRATION.get(m["type"], ()) if m["params"].get(k)), None)
                if held:
                    watch.append((held, "penetration", mid))
            for area, typ, mid in watch:
                # An incident per hostile group that enters the area, unless it was near it
                # less than EPISODE_S before (the user still knows of it); sensors place a
                # group within TOLERANCE_M, so one that comes that far inside must be told,
                # from when it came that near; one that only grazes the edge may be.
                geom = self.area[area]
                near_geom, deep = _bands(geom)
                near_at: dict[float, list[str]] = {}
                last_near: dict[str, float] = {}
                entered: dict[str, list] = {}   # group -> [came near, came inside]: not yet deep inside
                entries: list[tuple[float, float, float, str]] = []
                for t in self.ticks:
                    if mid is not None:
                        r0, r1 = self._ready_interval(mid)
                        if not (r0 <= t < r1 and self.missions[mid]["unit"] in self.subtree(o, t)):
                            continue
                    hs = self.hostiles_at(t)
                    near = sorted(h for h, (x, y, s) in hs.items() if near_geom.contains(Point(x, y)))
                    if not near:
                        continue
                    near_at[t] = near
                    before = [g for g in near if last_near.get(g, -math.inf) >= t - TICK]   # there already
                    for h in near:
                        if t - last_near.get(h, -math.inf) >= EPISODE_S and not any(
                                math.hypot(hs[h][0] - hs[g][0], hs[h][1] - hs[g][1]) < RESOLVE_M for g in before):
                            entered[h] = [t, None]   # a group next to one already there is no new group to any sensor
                    for h in near:
                        last_near[h] = t
                    for h in [h for h in entered if h in near]:
                        p = Point(hs[h][0], hs[h][1])
                        if entered[h][1] is None and geom.contains(p):
                            entered[h][1] = t
                        if deep.contains(p):
                            t_near, t_in = entered.pop(h)
                            entries.append((t_near, t if t_in is None else t_in, t, h))
                first_seen: dict[str, float] = {}
                for tt in sorted(near_at):
                    for g in near_at[tt]:
                        first_seen.setdefault(g, tt)
                first = True
                for t_near, t_in, t, h in sorted(entries, key=lambda e: e[1]):
                    # a triggered contingency tells the first activity in its trigger area
                    if first and mid is None and area in getattr(self, "triggered_areas", {}).get(o, ()):
                        first = False
                        continue
                    first = False
                    # a group that only grazes the area, gone before the next track report,
                    # may be seen there or not
                    later_all = self.hostiles_at(t + TRACK_S)
                    later = later_all.get(h)
                    # one that closes within RESOLVE_M of a group already there by then is one
                    # group with it to any sensor: it may be told as new or not
                    merged = later is not None and any(
                        math.hypot(later[0] - x, later[1] - y) < RESOLVE_M for g, (x, y, _s) in later_all.items()
                        if g != h and g in near_at.get(t, ()) and first_seen.get(g, math.inf) < t_near)
                    if later is not None and geom.contains(Point(later[0], later[1])) and not merged:
                        self.must(o, typ, [], [h, area], t_near - 15, t + 45, f"{h} enters {area}", at=t_in,
                                  about=[area])
                for a, b in _runs(sorted(near_at)):
                    who = sorted({h for t, hs_ in near_at.items() if a <= t <= b for h in hs_})
                    self.may(o, [typ], who + [area], a - 15, b + 30, about=[area])
                if typ == "penetration":   # a group heading for it may be projected to enter
                    self._approach(o, area, mid)
            for mid, m in self.missions.items():
                by = m["params"].get("expect_hostile_by")
                if by is None:
                    continue
                r0, r1 = self._ready_interval(mid)
                if not r0 <= by < r1:
                    continue
                seen = any(self.area[m["params"]["engagement_area"]].contains(Point(x, y))
                           for t in self.ticks if r0 <= t <= by for x, y, s in self.hostiles_at(t).values())
                if not seen and m["unit"] in self.subtree(o, by):
                    self.must(o, "hostile-expected", [], [m["unit"]], by - 1, by + 5, f"{mid}: nobody came", at=by)

    def _approach(self, o: str, area: str, mid: str) -> None:
        """Groups that come within APPROACH_M of an area no hostile may enter while its
        mission watches it: a projection that they will enter is fair."""
        ring = self.area[area].buffer(APPROACH_M)
        r0, r1 = self._ready_interval(mid)
        near = [t for t in self.ticks if r0 <= t < r1 and self.missions[mid]["unit"] in self.subtree(o, t)
                and any(ring.contains(Point(x, y)) for x, y, _s in self.hostiles_at(t).values())]
        for a, b in _runs(near):
            who = sorted({h for t in self.ticks if a <= t <= b for h, (x, y, _s) in self.hostiles_at(t).items()
                          if ring.contains(Point(x, y))})
            self.may(o, ["projected-penetration"], who + [area], a - 15, b + 30, about=[area])

    def presence(self) -> None:
        """A relief in place leaves no gap; a passage of lines keeps its elements at the point
        inside its lane. From the plan's start (coordinations have no start of their own)."""
        radius = float(self.voi["coordination_radius_m"])
        for mid, m in self.missions.items():
            p = m["params"]
            if m["type"] not in ("relief-in-place", "passage-of-lines") or (
                    m["type"] == "passage-of-lines" and not p.get("lane")):
                continue
            v0, v1 = self.valid[mid]
            pt = self.geom[p["point"]]
            sure, maybe, was, came = [], [], False, False
            for k, t in enumerate(self.ticks):
                if not v0 <= t < v1:
                    continue
                mine = self.member_points(m["unit"], k)
                dm = np.array([pt.distance(Point(q)) for q in mine])
                if m["type"] == "passage-of-lines":
                    lane = self.area[p["lane"]]
                    out = [lane.distance(Point(q)) for q, d in zip(mine, dm) if d <= radius + FRIENDLY_ERR_M]
                    if any(o > FRIENDLY_ERR_M for o, d in zip(out, dm[dm <= radius + FRIENDLY_ERR_M])
                           if d <= radius - FRIENDLY_ERR_M):
                        sure.append(t)
                    if any(o > 0 for o in out):
                        maybe.append(t)
                else:
                    theirs = min(pt.distance(Point(q)) for q in self.member_points(p["partner"], k))
                    was |= theirs <= radius
                    came |= bool((dm <= radius).any())
                    if was and not came and theirs > radius + FRIENDLY_ERR_M:
                        sure.append(t)
                    if was and not came and theirs > radius - FRIENDLY_ERR_M:
                        maybe.append(t)
            what = "outside its lane" if m["type"] == "passage-of-lines" else "gap in the relief"
            for a, b in _runs(sure):
                if b - a >= 30:
                    for o in self.owners_of(m["unit"], a):
                        self.must(o, "presence", [], [m["unit"], p["partner"]], a - self.slack, a + 60,
                                  f"{mid}: {what}", at=a)
            for a, b in _runs(maybe):
                for o in self.owners_of(m["unit"], a):
                    self.may(o, ["presence"], [m["unit"], p["partner"]], a - self.slack, b + self.slack)
