"""Ground truth for what each tactical task asks beyond its place (doctrine, FM 3-90)."""
from __future__ import annotations

import math

import numpy as np
import shapely
from shapely.geometry import LineString, Point

from .spec import (
    ASSUME, CONTINGENT, DISRUPT, END_STATE, EPISODE_S, ESCAPE, FOLLOW, FOLLOW_MAX_M, FRIENDLY_ERR_M, HALT_M, HALT_S,
    LINE_MARGIN_M, MATERIAL, OBJECTIVE, RECON, ROUTE, STANDOFF, SUPPRESS, TEMPO_MPS, TEMPO_TREND_S, ZONE,
    TICK, TOLERANCE_M, _bands, _runs, geometry_params,
)


class Tasks:
    """What each task asks beyond its place (FM 3-90): escape, end state, the engagement
    area in range and held positions, bands, standoff, lines and times, checkpoints, fire
    support, hostiles ahead."""

    def check_families(self) -> None:
        """What each task forbids the enemy or asks of its unit beyond its place (FM 3-90):
        escape, end state, the engagement area in weapons range, the distance band."""
        for mid, m in self.missions.items():
            typ, p = m["type"], m["params"]
            self.only, self.soft = None, False
            if typ in CONTINGENT and mid in self.task_started:   # a triggered task is judged as its own type
                self.only, self.soft = p["owner"], mid in self.task_soft   # by the EA that holds it
                typ, p = p["task"], p.get("task_params", {})
                m = {**m, "type": typ, "params": p}
            if typ == "support-by-fire" and p.get("supported"):
                self._fire_support(mid, m, p)
            if mid not in self.started:
                continue
            v0, v1 = self.valid[mid]
            s, e = max(self.started[mid], v0), min(self.ended.get(mid, math.inf), v1)
            if s >= e:
                continue
            if typ in ESCAPE and p.get(ESCAPE[typ]):
                self._escape(mid, m, p[ESCAPE[typ]], s, e)
            if typ in END_STATE and mid in self.ended and self.ended[mid] < v1:
                self._end_state(mid, m, p["objective"], self.ended[mid])
            if p.get("engagement_area") and geometry_params(typ) == ("position", "engagement_area"):
                self._coverage(mid, m, p["position"], p["engagement_area"], s)
            if geometry_params(typ) == ("position", "engagement_area") or typ == "observe":
                self._held(mid, m, p["position"], s, e)
            if typ in FOLLOW:   # until it assumes the supported unit's mission: it no longer follows then
                self._band(mid, m, p["supported"], p.get("band_m") or (0.0, FOLLOW_MAX_M), s,
                           min(e, self.assumed.get(mid, math.inf)))
            if typ in SUPPRESS:
                self._suppress(mid, m, p, s, e)
            if typ in DISRUPT:
                self._tempo(mid, m, p, s, e)
            if typ == "seize" and p.get("by") is not None:
                self._seize_by(mid, m, p, float(p["by"]), s, e)
            if typ == "overwatch" and p.get("supported"):   # within its fires unless the plan says
                self._band(mid, m, p["supported"], p.get("band_m") or (0.0, self.thr(m, "weapons_range_m")), s, e)
            line = self._line_of(mid, m)
            if line is not None:
                self._ahead(mid, m, line, s, e)
            if p.get("checkpoints") and typ in ROUTE:
                self._checkpoints(mid, m, p["checkpoints"], s, e)
            if typ in RECON:
                self._recon(mid, m, s, e)
            if typ in STANDOFF:
                self._standoff(mid, m, s, e)
            if typ == "delay" and p.get("line"):
                self._line(mid, m, p["line"], float(p["until"]), s, e, hold=True)
            if typ == "breach" and p.get("obstacle"):
                self._line(mid, m, p["obstacle"], float(p["by"]), s, e, hold=False, toward=p["objective"])
        self.only, self.soft = None, False

    def _held(self, mid, m, position, s, e) -> None:
        """A position its mission must hold: some friendly element (anyone's) in it while it runs;
        near its edge (reports lag) either answer is fair."""
        near_g = self.area[position].buffer(FRIENDLY_ERR_M)
        deep = self.area[position].buffer(-FRIENDLY_ERR_M)
        shapely.prepare(near_g)
        shapely.prepare(deep)
        sure, maybe = [], []
        for k, t in enumerate(self.ticks):
            if not s <= t < e:
                continue
            xs, ys = self.everyone(k)
            if not shapely.contains_xy(near_g, xs, ys).any():
                sure.append(t)
            if deep.is_empty or not shapely.contains_xy(deep, xs, ys).any():
                maybe.append(t)
        for a, b in _runs(sure):
            if b - a >= 30:
                for o in self.owners_of(m["unit"], a):
                    # the unit told out of that position has been told this story; emptiness is told
                    # within 90 s (seconds of it are no news), for a triggered task once it must have fired
                    self.must(o, "friendly-expected", ["out-of-position"], [m["unit"]], a - self.slack,
                              max(a, self.task_due.get(mid, a)) + 90, f"{position} empty ({mid})", at=a)
        for a, b in _runs(maybe):
            for o in self.owners_of(m["unit"], a):
                self.may(o, ["friendly-expected", "out-of-position"], [m["unit"]], a - self.slack, b + self.slack)

    def _fire_support(self, mid, m, p) -> None:
        """Support by fire: in position (within out_of_position_m of it) when the supported unit
        crosses its line of departure, whether its own mission has started or not; its fires
        lift once the supported unit is within SPEC lift_m of the target, while it runs."""
        v0, v1 = self.valid[mid]
        sup, thr = p["supported"], self.thr(m, "out_of_position_m")
        owners = lambda t: self.owners_of(m["unit"], t)   # noqa: E731
        if p.get("line"):
            line, c = self.geom[p["line"]], self.area[p["target"]].centroid
            own = -1.0 if self._beyond_point(line, c) else 1.0
            far = [(t, self._beyond(line, sup, k, own)) for k, t in enumerate(self.ticks) if v0 <= t < v1]
            maybe = next((t for t, d in far if d > LINE_MARGIN_M - FRIENDLY_ERR_M), None)
            sure = next((t for t, d in far if d > LINE_MARGIN_M + FRIENDLY_ERR_M), None)
            if maybe is not None:
                gap = lambda t: self.area[p["position"]].distance(   # noqa: E731
                    Point(self.member_points(m["unit"], int(round(t / TICK))).mean(axis=0)))
                last = sure if sure is not None else maybe
                for o in owners(maybe):
                    if all(gap(t) > thr * MATERIAL for t in self.ticks if maybe <= t <= last):
                        self.must(o, "fire-support", [], [m["unit"], sup], maybe - 1, last + self.slack,
                                  f"{m['unit']} not in position when {sup} departs", at=maybe)
                    elif any(gap(t) > thr / MATERIAL for t in self.ticks if maybe <= t <= last):
                        self.may(o, ["fire-support"], [m["unit"], sup], maybe - 1, last + self.slack)
        if mid not in self.started:
            return
        s, e = max(self.started[mid], v0), min(self.ended.get(mid, math.inf), v1)
        lift = self.thr(m, "lift_m")
        d = [(t, self.area[p["target"]].distance(Point(self.member_points(sup, k).mean(axis=0))))
             for k, t in enumerate(self.ticks) if s <= t < e]
        maybe = next((t for t, x in d if x <= lift + FRIENDLY_ERR_M), None)
        sure = next((t for t, x in d if x <= lift - FRIENDLY_ERR_M), None)
        if maybe is not None:
            for o in owners(maybe):
                if sure is not None:
                    self.must(o, "fire-support", [], [m["unit"], sup], maybe - 1, sure + self.slack,
                              f"{m['unit']} lifts fires for {sup}", at=sure)
                else:
                    self.may(o, ["fire-support"], [m["unit"], sup], maybe - 1, e)

    def _standoff(self, mid, m, s, e) -> None:
        """Screens, bypasses, withdrawals and delays keep SPEC standoff_m from every hostile group:
        the first group well inside it in an episode (none near for EPISODE_S before) must be told;
        while groups are near its edge, alerts may be."""
        keep = self.thr(m, "standoff_m")
        near_ts, last_near, first_near, told = [], -math.inf, None, False
        for k, t in enumerate(self.ticks):
            if not s <= t < e:
                continue
            c = self.member_points(m["unit"], k).mean(axis=0)
            ds = {h: math.hypot(x - c[0], y - c[1]) for h, (x, y, _s) in self.hostiles_at(t).items()}
            near = [h for h, d in ds.items() if d < keep + TOLERANCE_M]
            if not near:
                continue
            if t - last_near >= EPISODE_S:
                first_near, told = t, False
            last_near = t
            near_ts.append(t)
            if not told and any(ds[h] < keep - TOLERANCE_M for h in near):
                for o in self.owners_of(m["unit"], t):
                    self.must(o, "standoff", [], [m["unit"], *near], first_near - 15, t + 30,
                              f"hostiles within {m['unit']}'s standoff ({mid})", at=t, about=[m["unit"]])
                told = True
        for a, b in _runs(near_ts):
            for o in self.owners_of(m["unit"], a):
                self.may(o, ["standoff"], [m["unit"]], a - 15, b + 30, about=[m["unit"]])

    def _beyond(self, line, unit: str, k: int, own: float) -> float:
        """How far the unit's centroid is across `line` from side `own` (+1 left, -1 right; < 0: not across)."""
        c = Point(self.member_points(unit, k).mean(axis=0))
        pos = line.project(c)
        a, b = line.interpolate(max(pos - 1.0, 0.0)), line.interpolate(min(pos + 1.0, line.length))
        left = (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x) >= 0
        d = line.distance(c)
        return d if (left and own < 0) or (not left and own > 0) else -d

    def _line(self, mid, m, lid, when, s, e, hold: bool, toward: str | None = None) -> None:
        """A delay holds forward of its line (the side it starts on) until `when`; a breach is
        past its obstacle (away from the side of its objective) by `when`. Across means more
        than LINE_MARGIN_M beyond; the EA's picture of a moving unit errs by up to FRIENDLY_ERR_M."""
        line = self.geom[lid]
        if hold:
            own = -1.0 if self._beyond(line, m["unit"], math.ceil(s / TICK - 1e-9), 1.0) > 0 else 1.0
        else:
            c = self.area[toward].centroid
            own = -1.0 if self._beyond_point(line, c) else 1.0
        far = {k: self._beyond(line, m["unit"], k, own) for k, t in enumerate(self.ticks) if s <= t < e}
        first = lambda d: next((self.ticks[k] for k, v in sorted(far.items()) if v > d), math.inf)   # noqa: E731
        sure, maybe = first(LINE_MARGIN_M + FRIENDLY_ERR_M), first(LINE_MARGIN_M - FRIENDLY_ERR_M)
        if not self.valid[mid][0] <= min(when, maybe) < self.valid[mid][1]:
            return
        for o in self.owners_of(m["unit"], min(when, maybe)):
            if hold:
                if sure < when - self.slack:
                    self.must(o, "line", [], [m["unit"]], maybe - 1, sure + self.slack, f"{mid} across {lid} early",
                              at=sure)
                if maybe < when:
                    self.may(o, ["line"], [m["unit"]], maybe - 1, when)
            elif e > when:   # a breach: across by its time
                if maybe > when + self.slack:
                    self.must(o, "line", [], [m["unit"]], when - 1, when + 5, f"{mid} not past {lid}", at=when)
                if sure > when - self.slack:
                    self.may(o, ["line"], [m["unit"]], when - 1, when + 5)

    @staticmethod
    def _beyond_point(line, c) -> bool:
        """Whether point `c` is on the left of `line` (walking along it)."""
        pos = line.project(c)
        a, b = line.interpolate(max(pos - 1.0, 0.0)), line.interpolate(min(pos + 1.0, line.length))
        return (b.x - a.x) * (c.y - a.y) - (b.y - a.y) * (c.x - a.x) >= 0

    def _checkpoints(self, mid, m, table, s, e) -> None:
        """A march table: the unit reaches each point (its centroid in the point's area, once
        the mission runs) within schedule_s of its time. Its reports lag the truth by up to
        `slack`: nearer the edge than that, either answer is fair."""
        fuzz = self.thr(m, "schedule_s")
        for cp in table:
            area, when = self.area[cp["point"]], float(cp["t"])
            g = self.geom[cp["point"]]
            at = (lambda c: g.distance(c) <= float(self.voi["checkpoint_m"])) if g.geom_type == "Point" else area.contains
            arrive = next((t for k, t in enumerate(self.ticks) if s <= t < e and
                           at(Point(self.member_points(m["unit"], k).mean(axis=0)))), math.inf)
            if not self.valid[mid][0] <= when + fuzz < self.valid[mid][1] or (math.isinf(arrive) and e <= when + fuzz):
                continue   # the plan changed, or the mission ended (no arrival is then a place question)
            for o in self.owners_of(m["unit"], when):
                if arrive > when + fuzz + self.slack:
                    self.must(o, "checkpoint", [], [m["unit"]], when + fuzz - 1, when + fuzz + 5,
                              f"{mid} late at {cp['point']}", at=when + fuzz)
                elif arrive > when + fuzz - self.slack:
                    self.may(o, ["checkpoint"], [m["unit"]], when + fuzz - 1, when + fuzz + 5)
                if arrive < when - fuzz - self.slack:   # seen up to `slack` before or after it happened
                    self.must(o, "checkpoint", [], [m["unit"]], arrive - self.slack, arrive + self.slack + 5,
                              f"{mid} early at {cp['point']}", at=arrive)
                elif arrive < when - fuzz + self.slack:
                    self.may(o, ["checkpoint"], [m["unit"]], arrive - self.slack, arrive + self.slack + 5)

    def _recon(self, mid, m, s, e) -> None:
        """A zone or area reconnaissance: the share of its area on a grid of cells some member
        came within sight of, against the share of its time gone by its `by` (or END-NLT/END-AT
        time); too little seen when it ends. Within 2 % of a threshold, either answer is fair."""
        p = m["params"]
        area = self.area[p["area"]]
        step, sight = self.thr(m, "recon_cell_m"), self.thr(m, "recon_sight_m")
        lag_max, complete = self.thr(m, "recon_lag"), self.thr(m, "recon_complete")
        x0, y0, x1, y1 = area.bounds
        cells = [(x, y) for y in np.arange(y0 + step / 2, y1, step) for x in np.arange(x0 + step / 2, x1, step)
                 if area.contains(Point(x, y))] or [area.representative_point().coords[0]]
        cells = np.array(cells)
        seen = np.zeros(len(cells), dtype=bool)
        bands = None
        if m["type"] in ZONE:   # depth from where the unit starts towards the zone's centre, front to rear
            c0 = self.member_points(m["unit"], min(int(math.ceil(s / TICK - 1e-9)), len(self.ticks) - 1)).mean(axis=0)
            ctr = area.centroid
            dx, dy = ctr.x - c0[0], ctr.y - c0[1]
            n = math.hypot(dx, dy)
            ux, uy = (dx / n, dy / n) if n > 1.0 else (0.0, -1.0)
            depth = cells[:, 0] * ux + cells[:, 1] * uy
            bands = np.floor((depth - depth.min()) / step + 1e-9).astype(int)

        def share() -> float:
            if bands is None:
                return float(seen.mean())
            nb = int(bands.max()) + 1
            ok = np.bincount(bands, weights=seen, minlength=nb) >= complete * np.bincount(bands, minlength=nb)
            return 1.0 if ok.all() else float(np.argmin(ok)) / nb
        end = m.get("end") or {}
        by = p.get("by")
        if by is None and end.get("type") in ("END-NLT", "END-AT"):
            by = end.get("t")
        behind, near = None, []
        for k, t in enumerate(self.ticks):
            if not s <= t <= e:
                continue
            pts = self.member_points(m["unit"], k)
            d = np.hypot(cells[:, None, 0] - pts[None, :, 0], cells[:, None, 1] - pts[None, :, 1]).min(axis=1)
            seen |= d <= sight
            if by is not None and by > s:
                lag = min(1.0, (t - s) / (by - s)) - share()
                if lag > lag_max - 0.02:
                    near.append(t)
                if lag > lag_max + 0.02 and behind is None:
                    behind = t
        unit = m["unit"]
        if behind is not None:   # judged every 30 s on the EA's scan
            for o in self.owners_of(unit, behind):
                self.must(o, "recon-progress", [], [unit], behind - self.slack, behind + 30 + self.slack + 5,
                          f"{mid} behind", at=behind)
        if near:
            for o in set(self.owners_of(unit, near[0])) | set(self.owners_of(unit, e)):
                self.may(o, ["recon-progress"], [unit], near[0] - self.slack, e + self.slack)
        if mid in self.ended and self.ended[mid] < self.valid[mid][1]:
            for o in self.owners_of(unit, e):
                if share() < complete - 0.02:
                    self.must(o, "recon-progress", [], [unit], e - 1, e + self.slack + 5, f"{mid} incomplete", at=e)
                elif share() < complete + 0.02:
                    self.may(o, ["recon-progress"], [unit], e - 1, e + self.slack + 5)

    def _line_of(self, mid, m):
        """The line a moving mission follows: its route or axis, or its corridor's line."""
        typ, p = m["type"], m["params"]
        if typ not in ROUTE | OBJECTIVE:
            return None
        if p.get("route") or p.get("axis"):   # as travelled: towards its destination or objective
            line = self.geom[p.get("route") or p.get("axis")]
            goal = self.area[p.get("destination") or p.get("objective")]
            return LineString(line.coords[::-1]) if goal.distance(Point(line.coords[0])) < \
                goal.distance(Point(line.coords[-1])) else line
        if mid in self.corridor_start:
            return self._corridor_line(self.corridor_start[mid], p.get("destination") or p.get("objective"))
        return None

    def _ahead(self, mid, m, line, s, e) -> None:
        """Hostiles on the stretch of line ahead of the unit (SPEC ahead_m, ahead_width_m): the
        commander must be asked once per episode about a group well inside it; one near its
        edges (where sensors and the unit's own reports err) may be told."""
        far, wide = self.thr(m, "ahead_m"), self.thr(m, "ahead_width_m")
        near_ts, who, first_near, last_deep = [], set(), None, -math.inf
        for k, t in enumerate(self.ticks):
            if not s <= t < e:
                continue
            hs = self.hostiles_at(t)
            if not hs:
                first_near = None
                continue
            d0 = line.project(Point(self.member_points(m["unit"], k).mean(axis=0)))
            place = {h: (line.project(Point(x, y)), line.distance(Point(x, y))) for h, (x, y, _s) in hs.items()}
            near = [h for h, (a, d) in place.items()
                    if d0 - TOLERANCE_M <= a <= d0 + far + TOLERANCE_M and a < line.length and d <= wide + TOLERANCE_M]
            if not near:
                first_near = None
                continue
            near_ts.append(t)
            who |= set(near)
            first_near = t if first_near is None else first_near
            deep = [h for h in near if d0 + TOLERANCE_M <= place[h][0] <= d0 + far - TOLERANCE_M
                    and place[h][1] <= wide - TOLERANCE_M]
            if deep:
                if t - last_deep >= EPISODE_S:
                    for o in self.owners_of(m["unit"], t):
                        self.must(o, "threat-ahead", [], [m["unit"], *near], first_near - 15, t + 30,
                                  f"hostiles ahead of {m['unit']} ({mid})", at=t, about=[m["unit"]])
                last_deep = t
        for a, b in _runs(near_ts):
            for o in self.owners_of(m["unit"], a):
                self.may(o, ["threat-ahead"], [m["unit"], *sorted(who)], a - 15, b + 30, about=[m["unit"]])

    def _escape(self, mid, m, area, s, e) -> None:
        """A group well inside the area while the mission runs that goes well beyond its edge."""
        geom = self.area[area]
        near_g, deep_g = _bands(geom)
        held: dict[str, float] = {}   # group -> when it was last well inside
        out_at: dict[str, float] = {}
        for t in self.ticks:
            if not s <= t < e:
                continue
            for h, (x, y, _st) in self.hostiles_at(t).items():
                pt = Point(x, y)
                if deep_g.contains(pt):
                    held[h] = t
                    out_at.pop(h, None)
                elif h in held and not geom.contains(pt):
                    out_at.setdefault(h, t)   # across the edge: it may be told from now
                    if not near_g.contains(pt):
                        for o in self.owners_of(m["unit"], t):
                            self.must(o, "escape", [], [h, area], out_at[h] - 15, t + 45, f"{h} escapes {area}",
                                      at=t, about=[area])
                            self.may(o, ["escape"], [h, area], held[h], t + 45, about=[area])
                        del held[h]
            for h in [h for h in held if h not in self.hostiles_at(t)]:   # gone: lost, not escaped
                del held[h]
        for h, t in out_at.items():   # crossed the edge, never well beyond it: may be told
            if h in held:
                for o in self.owners_of(m["unit"], t):
                    self.may(o, ["escape"], [h, area], t - 15, e + 45, about=[area])

    def _end_state(self, mid, m, area, t) -> None:
        geom = self.area[area]
        near_g, deep_g = _bands(geom)
        hs = self.hostiles_at(round(t / TICK) * TICK)
        deep = [h for h, (x, y, _s) in hs.items() if deep_g.contains(Point(x, y))]
        near = [h for h, (x, y, _s) in hs.items() if near_g.contains(Point(x, y))]
        for o in self.owners_of(m["unit"], t):
            if deep:
                self.must(o, "end-state", [], [m["unit"], *deep], t - 1, t + 5, f"{mid} ends with {deep} on {area}",
                          at=t, about=[m["unit"]])
            elif near:
                self.may(o, ["end-state"], [m["unit"], *near], t - 1, t + 5, about=[m["unit"]])

    def _coverage(self, mid, m, position, ea, s) -> None:
        gap = self.area[position].distance(self.area[ea])
        if gap > self._range(m["unit"], self.parent_at(s)):
            for o in self.owners_of(m["unit"], s):
                self.must(o, "friendly-expected", [], [m["unit"]], s - 1, s + 5, f"{ea} out of range of {position}",
                          at=s)

    def _band(self, mid, m, other, band, s, e) -> None:
        lo, hi = float(band[0]), float(band[1])
        thr = self.thr(m, "out_of_position_m")
        hits, peak = [], 0.0
        for k, t in enumerate(self.ticks):
            if s <= t < e:
                a, b = self.member_points(m["unit"], k).mean(axis=0), self.member_points(other, k).mean(axis=0)
                d = float(np.hypot(*(a - b)))
                off = d - hi if d > hi else lo - d
                if off > thr / MATERIAL:
                    hits.append(t)
                    peak = max(peak, off)
        for a, b in _runs(hits):
            for o in self.owners_of(m["unit"], a):
                if peak > 1.5 * thr and b - a >= 30:
                    self.must(o, "band", [], [m["unit"], other], a - self.slack, a + 60, f"{mid} out of band", at=a)
                self.may(o, ["band"], [m["unit"], other], a - self.slack, b + self.slack)

    def assume(self) -> None:
        """Follow and assume: the follower takes over the supported unit's mission once that unit
        has stood (its true centroid within HALT_M of one place) for the mission's `halt_s` short
        of its goal while its own mission runs and the follow mission does. It must be told, and
        from then the supported mission is judged as the follower's own (a mission of the
        follower's added to the plan, started then, ended with the follow mission). Standing
        within twice HALT_M may be told too (reports jitter and lag)."""
        self.assumed: dict[str, float] = {}
        for mid, m in list(self.missions.items()):
            if m["type"] not in ASSUME or mid not in self.started:
                continue
            p = m["params"]
            sup, halt = p["supported"], float(p.get("halt_s", HALT_S))
            v0, v1 = self.valid[mid]
            s, e = max(self.started[mid], v0), min(self.ended.get(mid, math.inf), v1)
            sure = maybe = None
            for sid, sm in self.missions.items():
                goal = sm["params"].get("destination") or sm["params"].get("objective")
                if sm["unit"] != sup or not goal or sid not in self.started:
                    continue
                a = max(self.started[sid], self.valid[sid][0], s)
                b = min(self.ended.get(sid, math.inf), self.valid[sid][1], e)
                ks = [k for k, t in enumerate(self.ticks) if a <= t < b]
                if not ks:
                    continue
                c = np.array([self.member_points(sup, k).mean(axis=0) for k in ks])
                # the EA sees the halt in reports up to `slack` old: standing for halt_s may be
                # told, standing that long after its reports caught up must be
                n, n_sure = int(round(halt / TICK)), int(round((halt + self.slack) / TICK))
                thr = self.thr(m, "out_of_position_m")
                for i in range(n, len(ks)):
                    t = self.ticks[ks[i]]
                    if self.area[goal].distance(Point(c[i])) <= thr + FRIENDLY_ERR_M:
                        continue
                    if float(np.hypot(*(c[i - n:i + 1] - c[i]).T).max()) <= 2 * HALT_M:
                        maybe = t if maybe is None else maybe
                    if i >= n_sure and float(np.hypot(*(c[i - n_sure:i + 1] - c[i]).T).max()) <= HALT_M / MATERIAL:
                        sure = (t, sid)
                        break
                if sure or maybe is not None:
                    break
            for o in self.owners_of(m["unit"], maybe) if maybe is not None else ():
                self.may(o, ["contingency"], [m["unit"], sup], maybe - self.slack, e + self.slack)
            if sure is None:
                continue
            t, sid = sure
            for o in self.owners_of(m["unit"], t):
                self.must(o, "contingency", [], [m["unit"], sup], maybe - self.slack, t + self.slack + 30,
                          f"{m['unit']} assumes {sid} ({sup} halted)", at=t)
            cid = f"{mid}>{sid}"
            src = self.missions[sid]
            self.missions[cid] = {"id": cid, "unit": m["unit"], "type": src["type"], "params": dict(src["params"])}
            self.valid[cid] = self.valid[mid]
            self.started[cid] = t
            if mid in self.ended:
                self.ended[cid] = self.ended[mid]
            self.assumed[mid] = t

    def _suppress(self, mid, m, p, s, e) -> None:
        """Suppression: through its window, while it runs, the target within the unit's weapons
        range of its centroid; within FRIENDLY_ERR_M of the range either answer is fair."""
        w0, w1 = (float(x) for x in p["window"])
        a, b = max(s, w0), min(e, w1)
        if a > b:
            return
        rng = self._range(m["unit"], self.parent_at(a))
        target = self.area[p["target"]]
        maybe = sure = None
        for k, t in enumerate(self.ticks):
            if not a <= t <= b:
                continue
            d = target.distance(Point(self.member_points(m["unit"], k).mean(axis=0)))
            if maybe is None and d > rng - FRIENDLY_ERR_M:
                maybe = t
            if d > rng + FRIENDLY_ERR_M:
                sure = t
                break
        if maybe is None:
            return
        for o in self.owners_of(m["unit"], maybe):
            if sure is not None:
                self.must(o, "fire-support", [], [m["unit"]], maybe - self.slack - 1, sure + self.slack + 35,
                          f"{m['unit']} cannot reach {p['target']} ({mid})", at=sure)
            self.may(o, ["fire-support"], [m["unit"]], maybe - self.slack - 1, b + self.slack + 35)

    def _tempo(self, mid, m, p, s, e) -> None:
        """Disruption: from `by`, while it runs, a group on the avenue advancing along it (as
        drawn) faster than the tempo over TEMPO_TREND_S. Sure: well inside the avenue and at
        least twice the tempo (and 1 m/s above it); maybe: near it and above half the tempo."""
        by, tempo = float(p["by"]), float(p.get("tempo_mps", TEMPO_MPS))
        line = self.geom[p["avenue"]]
        near_g, deep_g = _bands(self.area[p["avenue"]])
        first, sure = {}, None
        for t in self.ticks:
            if not max(s, by) <= t < e:
                continue
            now, then = self.hostiles_at(t), self.hostiles_at(t - TEMPO_TREND_S)
            for h, (x, y, _st) in now.items():
                if h not in then:
                    continue
                x0, y0, _ = then[h]
                v = (line.project(Point(x, y)) - line.project(Point(x0, y0))) / TEMPO_TREND_S
                if v > tempo / 2 and near_g.contains(Point(x, y)) and near_g.contains(Point(x0, y0)):
                    first.setdefault(h, t)
                    if sure is None and v >= max(2 * tempo, tempo + 1.0) and deep_g.contains(Point(x, y)) \
                            and deep_g.contains(Point(x0, y0)):
                        sure = (t, h)
        if not first:
            return
        unit, av = m["unit"], p["avenue"]
        for h, t in first.items():
            for o in self.owners_of(unit, t):
                self.may(o, ["hostile-expected"], [unit, h, av], t - 15, e + 45, about=[av])
        if sure is not None:
            t, h = sure
            for o in self.owners_of(unit, t):
                self.must(o, "hostile-expected", [], [unit, h, av], min(first.values()) - 15, t + 60 + self.slack,
                          f"{h} still advancing on {av} after {by:.0f} ({mid})", at=t, about=[av])

    def _seize_by(self, mid, m, p, by, s, e) -> None:
        """A seizure's time: all its elements on the objective by `by` while it runs (its end is
        judged as every mission's); within a MATERIAL step of the threshold either answer is fair."""
        if not s <= by < e or not self.valid[mid][0] <= by < self.valid[mid][1]:
            return
        thr = self.thr(m, "out_of_position_m")
        d = self.judged(self.area[p["objective"]], m["unit"], int(round(by / TICK)), "all")
        for o in self.owners_of(m["unit"], by) if d > thr / MATERIAL else ():
            if d > thr * MATERIAL:
                self.must(o, "out-of-position", [], [m["unit"]], by - 1, by + 5, f"{mid} not on {p['objective']} "
                          f"by {by:.0f}", at=by)
            else:
                self.may(o, ["out-of-position"], [m["unit"]], by - 1, by + 5)

