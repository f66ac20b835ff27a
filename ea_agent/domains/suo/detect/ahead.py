"""Hostiles ahead (paper 6.6.1, Respond-To-Monitored-Red-Activity): a moving unit watches
the stretch of its route, axis or corridor ahead of it, and hostiles there are answered
by its mission class: a movement recommends aborting the move, or executing a branch the
plan holds for it; the alert asks the commander to decide (`saim-mesh command ... decide`
or the console), and the decision is carried out by the EA."""
from __future__ import annotations

import numpy as np
import shapely

from ea_agent.core.alert import Candidate

from ..missions import ContingentMission, Mission
from ..render import km
from .areas import ADVERSARIAL
from .base import Changes, Detector


class ThreatsAhead(Detector):
    TYPES = {"threat-ahead": ADVERSARIAL}

    def reset(self) -> None:
        self._towards_cache: dict[str, object] = {}
        # (state dict, its version, what runs, corridor ids, watched, each line's bounds)
        self._watched: tuple = (None, -1, None, None, [], [])
        self._box: tuple | None = None   # rebuilt when a corridor is added (see _near_any_line)
        self._box_lines = 0
        self._boxes_of: tuple | None = None   # (watched lines' bounds, their union box, each one's box, the width)
        self._found: dict[str, frozenset[str]] = {}   # mission id -> the tracks ahead at its last look

    def org_changed(self) -> None:
        self._box = None   # the missions in our plan changed

    def _near_any_line(self, live: list[tuple[str, float, float]]) -> bool:
        """Whether any track is within the bounding box of any line a mission of ours may move
        along (built once per plan: most of the time no hostile is near any of them). Plain
        floats: a handful of tracks costs less than one numpy call."""
        dom = self.dom
        if self._box is None:
            boxes = [dom.overlay[m.params[k]].geom.bounds for m in dom.missions.values() if dom.in_plan(m)
                     for k in ("route", "axis") if m.params.get(k) in dom.overlay]
            boxes += [line.bounds for line in dom.location.lines.values()]
            if not boxes:
                return False
            b = np.array(boxes)
            w = float(dom.voi_cfg["ahead_width_m"]) * 4   # missions may widen theirs
            self._box = (float(b[:, 0].min() - w), float(b[:, 1].min() - w),
                         float(b[:, 2].max() + w), float(b[:, 3].max() + w))
            self._box_lines = len(dom.location.lines)
        x0, y0, x1, y1 = self._box
        return any(x0 <= x <= x1 and y0 <= y <= y1 for _, x, y in live)

    def watched(self) -> list[tuple[Mission, object]]:
        """Running missions that move along a line, with it (recomputed when what runs, or a
        corridor, changes)."""
        return self._watched_with_bounds()[0]

    def _watched_with_bounds(self) -> tuple[list[tuple[Mission, object]], list[tuple[float, ...]]]:
        """watched(), and each line's bounds (shapely's bounds cost microseconds a call). What
        runs is only looked at again when a plan state changed since the last look."""
        dom = self.dom
        if dom.plan is None:
            return [], []
        states = dom.plan.state
        version = getattr(states, "version", None)
        lines = tuple(map(id, dom.location.lines.values()))
        old_states, old_version, old_active, old_lines = self._watched[:4]
        if version is not None and states is old_states and version == old_version and lines == old_lines:
            active = old_active
        else:
            active = frozenset(mid for mid, st in states.items() if st == "active")
        if (active, lines) != (old_active, old_lines) or old_states is None:
            out = self._compute_watched()
            self._watched = (states, version, active, lines, out, [line.bounds for _, line in out])
        elif states is not old_states or version != old_version:
            self._watched = (states, version, active, lines, *self._watched[4:])
        return self._watched[4], self._watched[5]

    def _compute_watched(self) -> list[tuple[Mission, object]]:
        dom = self.dom
        loc = dom.location
        out = []
        for mid, mons in loc.monitors.items():
            if dom.plan is None or dom.plan.state.get(mid) != "active" or not mons or not dom.in_plan(mons[0][0]):
                continue
            for m, geom, _rule, what in mons:
                if what in ("route", "axis"):
                    line = self._towards_cache.get(mid)
                    if line is None:
                        line = self._towards_cache[mid] = self._towards(m, dom.overlay[geom].geom)
                    out.append((m, line))
                    break
                if what == "corridor":
                    out.append((m, loc.lines[mid]))
                    break
        return out

    def _towards(self, m: Mission, line):
        """The line as travelled: towards the mission's destination or objective, whichever
        way it was drawn."""
        goal = m.params.get("destination") or m.params.get("objective")
        if goal is None:
            return line
        area = self.dom.overlay[goal].area
        a, b = shapely.Point(line.coords[0]), shapely.Point(line.coords[-1])
        return shapely.reverse(line) if area.distance(a) < area.distance(b) else line

    def ahead(self, m: Mission, line, xy: np.ndarray, pts: np.ndarray, box: np.ndarray) -> np.ndarray | None:
        """Which of the points `xy` (shapely `pts`) in the line's widened bounding box `box`
        are on the watched stretch: along the line from the unit's place to `ahead_m` on,
        and within `ahead_width_m` of it (vectorised)."""
        dom = self.dom
        w = dom.voi(m, "ahead_width_m")
        pos = dom.unit_now.get(m.unit) or dom.unit_pos.get(m.unit)
        if pos is None:
            return None
        s = line.project(shapely.Point(pos))
        along = shapely.line_locate_point(line, pts)
        return (box & (along >= s) & (along <= s + dom.voi(m, "ahead_m")) & (along < line.length)
                & (shapely.distance(line, pts) <= w))

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        """A watched mission is looked at when what it depends on changed: a report of its
        unit, the periodic scan (its dead-reckoned place moved on), or a change of a track
        that is ahead of it now or was at its last look. Never because a track elsewhere
        changed, nor at an epoch closed only because other messages came: an in-process EA
        hears every message and a peer only those near its units, and both must look at the
        same moments (a look also keeps a standing alert from expiring, `Voa.touch`)."""
        dom = self.dom
        if not dom.pic.tracks or float(dom.voi_cfg["ahead_m"]) <= 0.0:
            self._found.clear()   # nothing is ahead of anyone
            return
        watched, bounds = self._watched_with_bounds()
        found = self._found
        if not watched:
            found.clear()
            return
        due = [ch.rescan or m.unit in ch.units for m, _ in watched]
        if not ch.tracks and not any(due):
            return
        tracks = dom.pic.tracks
        # the live tracks (as Picture.live_tracks), on plain floats: bounding boxes first
        live = [(k, e.x, e.y) for k, e in sorted(tracks.items()) if e.strength > 0]
        if len(dom.location.lines) != self._box_lines:
            self._box = None
        (x0, y0, x1, y1), boxes = self._boxes(watched, bounds)
        near = ([(i, x, y) for i, (_, x, y) in enumerate(live) if x0 <= x <= x1 and y0 <= y <= y1]
                if live and self._near_any_line(live) else [])
        changed = ch.tracks
        xy = pts = None
        for (m, line), (bx0, by0, bx1, by1), again in zip(watched, boxes, due):
            before = found.get(m.id, frozenset())
            inbox = [i for i, x, y in near if bx0 <= x <= bx1 and by0 <= y <= by1]
            if not (again or changed.intersection(before) or any(live[i][0] in changed for i in inbox)):
                continue
            inside: list[str] = []
            if inbox:
                box = [False] * len(live)
                for i in inbox:
                    box[i] = True
                if xy is None:
                    xy = np.array([(x, y) for _, x, y in live]).reshape(-1, 2)
                    pts = shapely.points(xy)
                hit = self.ahead(m, line, xy, pts, np.array(box))
                if hit is not None and hit.any():
                    inside = [k for (k, _, _), ok in zip(live, hit.tolist()) if ok]
            if not (again or changed.intersection(before) or changed.intersection(inside)):
                continue   # only tracks that are not ahead changed: nothing to look at
            found[m.id] = frozenset(inside)
            if inside:
                m.respond_to_threat_ahead(dom, t, inside, sum(tracks[k].strength for k in inside))
        for mid in found.keys() - {m.id for m, _ in watched}:   # no longer watched
            del found[mid]

    def _boxes(self, watched: list, bounds: list) -> tuple[tuple[float, ...], list[tuple[float, ...]]]:
        """Each watched line's bounds widened by its mission's ahead width, and the bounds of
        them all widened by the widest (kept while the watched list and the width are the same)."""
        dom = self.dom
        width = dom.voi_cfg["ahead_width_m"]   # set live
        c = self._boxes_of
        if c is not None and c[0] is bounds and c[3] == width:
            return c[1], c[2]
        ws = [dom.voi(m, "ahead_width_m") for m, _ in watched]
        w = max(ws)
        union = (min(b[0] for b in bounds) - w, min(b[1] for b in bounds) - w,
                 max(b[2] for b in bounds) + w, max(b[3] for b in bounds) + w)
        boxes = [(b[0] - wm, b[1] - wm, b[2] + wm, b[3] + wm) for b, wm in zip(bounds, ws)]
        self._boxes_of = (bounds, union, boxes, width)
        return union, boxes

    def candidate(self, m: Mission, t: float, tracks: list[str], strength: int, options: list[str],
                  recommended: str) -> Candidate:
        dom = self.dom
        branches = [o for o in options if o.startswith("execute:")]
        how = {"abort": "abort the move", "continue": "continue"}
        rec = how.get(recommended, f"execute branch {recommended.split(':', 1)[-1]}")
        return Candidate(
            t, "threat-ahead", m.compute_priority("threat-ahead"), (m.unit, *tracks),
            f"Hostiles ahead of {dom.name(m.unit)} on its {m.TYPE} ({strength} entities within "
            f"{km(dom.voi(m, 'ahead_m'))}): decide: {' / '.join(options)} (recommended: {rec})",
            key=("threat-ahead", m.id), measure=float(strength), friendly=False,
            details={"mission": m.id, "strength": strength, "tracks": tracks,
                     "decision": {"options": options, "recommended": recommended, "branches": branches}})


def branches_for(dom, m: Mission) -> list[str]:
    """Dormant contingencies of our plan that the unit would execute in place of its move (the
    decision's other options): those whose class is an alternative (branches, not sequels)."""
    return sorted(c.id for c in dom.missions.values() if isinstance(c, ContingentMission) and c.offered_in_place()
                  and c.unit == m.unit and dom.in_plan(c) and dom.plan.state.get(c.id) == "dormant")
