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
        self._watched: tuple = (None, [])
        self._box: tuple | None = None   # rebuilt when a corridor is added (see _near_any_line)
        self._box_lines = 0

    def org_changed(self) -> None:
        self._box = None   # the missions in our plan changed

    def _near_any_line(self, xy: np.ndarray) -> bool:
        """Whether any track is within the bounding box of any line a mission of ours may move
        along (built once per plan: most of the time no hostile is near any of them)."""
        dom = self.dom
        if self._box is None:
            boxes = [dom.overlay[m.params[k]].geom.bounds for m in dom.missions.values() if dom.in_plan(m)
                     for k in ("route", "axis") if m.params.get(k) in dom.overlay]
            boxes += [line.bounds for line in dom.location.lines.values()]
            if not boxes:
                return False
            b = np.array(boxes)
            w = float(dom.voi_cfg["ahead_width_m"]) * 4   # missions may widen theirs
            self._box = (b[:, 0].min() - w, b[:, 1].min() - w, b[:, 2].max() + w, b[:, 3].max() + w)
            self._box_lines = len(dom.location.lines)
        x0, y0, x1, y1 = self._box
        return bool(((xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)).any())

    def watched(self) -> list[tuple[Mission, object]]:
        """Running missions that move along a line, with it (recomputed when what runs, or a
        corridor, changes)."""
        dom = self.dom
        if dom.plan is None:
            return []
        key = (frozenset(mid for mid, st in dom.plan.state.items() if st == "active"),
               tuple(id(x) for x in dom.location.lines.values()))
        if key != self._watched[0]:
            self._watched = (key, self._compute_watched())
        return self._watched[1]

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

    def ahead(self, m: Mission, line, xy: np.ndarray, pts: np.ndarray) -> np.ndarray | None:
        """Which of the points `xy` (shapely `pts`) are on the watched stretch: along the line
        from the unit's place to `ahead_m` on, and within `ahead_width_m` of it (vectorised,
        after a bounding-box test: most of the time no track is anywhere near)."""
        dom = self.dom
        w = dom.voi(m, "ahead_width_m")
        x0, y0, x1, y1 = line.bounds
        box = (xy[:, 0] >= x0 - w) & (xy[:, 0] <= x1 + w) & (xy[:, 1] >= y0 - w) & (xy[:, 1] <= y1 + w)
        if not box.any():
            return None
        pos = dom.unit_now.get(m.unit) or dom.unit_pos.get(m.unit)
        if pos is None:
            return None
        s = line.project(shapely.Point(pos))
        along = shapely.line_locate_point(line, pts)
        return (box & (along >= s) & (along <= s + dom.voi(m, "ahead_m")) & (along < line.length)
                & (shapely.distance(line, pts) <= w))

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        dom = self.dom
        if not (ch.tracks or ch.rescan) or not dom.pic.tracks or float(dom.voi_cfg["ahead_m"]) <= 0.0:
            return
        tracks = dom.pic.tracks
        ids, xy = dom.pic.live_tracks()
        if len(dom.location.lines) != self._box_lines:
            self._box = None
        if not ids or not self._near_any_line(xy):
            return
        watched = self.watched()
        if not watched:
            return
        w = max(dom.voi(m, "ahead_width_m") for m, _ in watched)
        b = np.array([line.bounds for _, line in watched])
        x0, y0, x1, y1 = b[:, 0].min() - w, b[:, 1].min() - w, b[:, 2].max() + w, b[:, 3].max() + w
        if not ((xy[:, 0] >= x0) & (xy[:, 0] <= x1) & (xy[:, 1] >= y0) & (xy[:, 1] <= y1)).any():
            return   # no track anywhere near any moving unit's line
        pts = shapely.points(xy)
        for m, line in watched:
            hit = self.ahead(m, line, xy, pts)
            if hit is not None and hit.any():
                inside = [k for k, ok in zip(ids, hit.tolist()) if ok]
                m.respond_to_threat_ahead(dom, t, inside, sum(tracks[k].strength for k in inside))

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
    """Dormant branches of our plan that the unit would execute (the decision's other options)."""
    return sorted(c.id for c in dom.missions.values() if isinstance(c, ContingentMission) and c.unit == m.unit
                  and dom.in_plan(c) and dom.plan.state.get(c.id) == "dormant" and c.TYPE == "branch")
