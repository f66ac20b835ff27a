"""Friendly lines and times: a delay stays forward of its line until a time, a breach is
past its obstacle by a time, an attack's crossing of its line of departure is its
start (and, with an H-hour, is due by then), and a movement to contact does not cross its
limit of advance. The side a unit is on is judged from its reported centroid against
the line; "across" means more than `line_margin_m` beyond it, so report noise does not
flicker a unit standing on the line."""
from __future__ import annotations

import math

import shapely

from ea_agent.core.alert import Candidate, hms

from ..missions import Mission
from .base import Changes, Detector


_COORDS: dict[int, tuple] = {}   # id(line) -> (line, its coordinates): shapely's coords cost microseconds


def _coords(line) -> tuple:
    """The line's coordinates, read once per geometry (geometries are immutable; the line
    is kept with them so its id is never reused while cached)."""
    hit = _COORDS.get(id(line))
    if hit is None or hit[0] is not line:
        if len(_COORDS) > 4096:   # bounded: corridors come and go
            _COORDS.clear()
        hit = _COORDS[id(line)] = (line, tuple(line.coords))
    return hit[1]


def side(line, p) -> float:
    """Signed distance of point `p` from `line`: positive on its left (walking along it)."""
    coords = _coords(line)
    if len(coords) == 2:   # a straight line (most are): no geometry built
        (ax, ay), (bx, by) = coords
        dx, dy, px, py = bx - ax, by - ay, p[0] - ax, p[1] - ay
        n2 = dx * dx + dy * dy
        u = min(max((px * dx + py * dy) / n2, 0.0), 1.0) if n2 > 0 else 0.0
        d = math.hypot(px - u * dx, py - u * dy)
        return d if dx * py - dy * px >= 0 else -d
    pt = shapely.Point(p)
    s = line.project(pt)
    a, b = line.interpolate(max(s - 1.0, 0.0)), line.interpolate(min(s + 1.0, line.length))
    cross = (b.x - a.x) * (pt.y - a.y) - (b.y - a.y) * (pt.x - a.x)
    d = line.distance(pt)
    return d if cross >= 0 else -d


class Lines(Detector):
    TYPES = {"line": "plan-constraint-violated"}

    def reset(self) -> None:
        # mission -> (it, line id, what: hold | pass | depart, by time or None, the side it starts on)
        self.watch: dict[str, list] = {}

    def post(self, m: Mission, line: str, what: str, when: float | None, toward: str | None = None) -> None:
        """Watch `m`'s unit against `line`: "hold" (not across before `when`; its own side is
        where it is), "limit" (never across while it runs; its own side is where it is),
        "pass" (across by `when`) or "depart" (across is the mission's start; by `when` if given);
        for these two its own side is the one away from `toward` (its objective)."""
        start = None
        if toward is not None:
            c = self.dom.overlay[toward].area.centroid
            start = -1.0 if side(self.dom.overlay[line].geom, (c.x, c.y)) > 0 else 1.0
        self.watch.setdefault(m.id, []).append([m, line, what, when, start])
        if what in ("pass", "depart") and when is not None:
            dom = self.dom

            def late(tf, mon, how):
                if dom.in_plan(m):
                    dom.ea.post(self._cand(m, line, what, tf, when))
                return None
            dom.timers.not_later_than(("across", m.id, line), when, late, tag=m.id)

    def end_mission(self, mid: str) -> None:
        self.watch.pop(mid, None)

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        dom = self.dom
        if not self.watch or dom.plan is None or not (ch.units or ch.rescan):
            return
        for mid, items in list(self.watch.items()):
            state = dom.plan.state.get(mid)
            for it in items:
                m, lid, what, when, start = it
                if state not in (("ready", "active") if what == "depart" else ("active",)):
                    continue
                if m.unit not in ch.units and (start is not None or not ch.rescan):
                    continue   # it did not move: it did not cross (its side is first taken at its
                    # report or a scan, not at another unit's, which a peer may not hear)
                pos = dom.unit_pos.get(m.unit)   # as reported: dead reckoning overshoots a unit halting on its line
                if pos is None:
                    continue
                margin = dom.voi(m, "line_margin_m")
                d = side(dom.overlay[lid].geom, pos)
                if start is None:   # the side it starts on (or, standing on the line, the first it leaves to)
                    if abs(d) > margin:
                        it[4] = 1.0 if d > 0 else -1.0
                    continue
                if d * start >= -margin:
                    continue   # still on its side
                it[4] = -start   # across: from now the other side is its own
                if what == "hold" and when is not None and t < when:
                    cands.append(self._cand(m, lid, "hold", t, when))
                elif what == "limit":
                    cands.append(self._cand(m, lid, "limit", t, t))
                elif what == "pass":
                    dom.timers.occurred(("across", mid, lid), t)
                elif what == "depart":
                    if when is not None:
                        dom.timers.occurred(("across", mid, lid), t)
                    if state == "ready":
                        dom.start_by_crossing(m, t)

    def _cand(self, m: Mission, line: str, what: str, t: float, when: float) -> Candidate:
        who = self.dom.name(m.unit)
        text = (f"{who} across {line} {when - t:.0f} s before {hms(when)} ({m.TYPE}: hold forward of it until then)"
                if what == "hold" else f"{who} across {line}, its limit of advance ({m.TYPE})" if what == "limit"
                else f"{who} not across its line of departure {line} by {hms(when)} ({m.TYPE})" if what == "depart"
                else f"{who} not past {line} by {hms(when)} ({m.TYPE})")
        return Candidate(t, "line", m.compute_priority("line"), (m.unit,), text,
                         key=("line", m.id, line), measure=abs(when - t),
                         details={"mission": m.id, "line": line, "check": what, "planned_t": when,
                                  "off_s": round(abs(when - t), 1), "places": [line]})
