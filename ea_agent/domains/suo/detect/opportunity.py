"""New opportunities (Fig. 1): situations that favour the plan, not threats to it.

Two kinds, both "a place the plan cares about was cleared by the enemy's own move":
 - objective-clear: the hostiles on the objective of an offensive mission that has not
   ended (attack, seize, clear, secure, breach, hasty attack) withdrew, leaving it clear
   before the unit took it (it may go faster, or bypass);
 - enemy-withdrawn: the hostiles a position mission expected in its engagement area
   (defend, block, ...) left it, away from the unit (the fight it prepared may not come).

Told once per clearing, when no track is within LINGER_M of the area any more and the
tracks that were in it are still seen (or continued by a track near where they left),
each farther from every watching unit than the area's centre: a group that vanished
(lost by the sensors) or moved towards our units is no opportunity. Objectives an isolate, fix or destroy holds the enemy in are left to the
escape family: there the enemy leaving is a violation.
"""
from __future__ import annotations

import math

import shapely

from ea_agent.core.alert import Candidate

from ..missions import Mission
from ..missions.contingent import ContingentMission
from .base import Changes, Detector

OPPORTUNITY = "new-opportunity"
OBJECTIVE_TASKS = frozenset({"attack", "breach", "clear", "hasty-attack", "secure", "seize"})
HOLD_TASKS = frozenset({"fix", "isolate", "destroy"})   # the enemy leaving their objective is an escape
NOT_EA = frozenset({"contain"})                          # its engagement area holds the enemy in
LINGER_M = 200.0     # a track this near the area is still there (sensors place a group within ~200 m)
SAME_GROUP_M = 400.0  # a new track this near where a departed one was last seen continues it
DEFAULT_PRIORITY = "priority"   # it improves the plan, threatens nobody (paper 5: VOA; 6.8: flash is for lives)


class Opportunities(Detector):
    TYPES = {"objective-clear": OPPORTUNITY, "enemy-withdrawn": OPPORTUNITY}

    def reset(self) -> None:
        # (type, area) -> tracks seen inside while watched: track -> last (x, y) inside
        self.held: dict[tuple[str, str], dict[str, tuple[float, float]]] = {}
        self._key: tuple = ()
        self._cached: dict[tuple[str, str], list[Mission]] = {}

    def _watches(self) -> dict[tuple[str, str], list[Mission]]:
        """(type, area) -> the missions of our plan, ready or running, that watch it: derived
        again only when a plan state or our units changed (asked at every track change)."""
        dom = self.dom
        plan = dom.plan
        states = plan.state if plan is not None else None
        key = (plan, states, getattr(states, "version", None), dom.own_units)
        old = self._key
        if old and old[0] is plan and old[1] is states and old[2] == key[2] and old[3] is key[3]:
            return self._cached
        self._key = key
        self._cached = out = self._derive()
        return out

    def _derive(self) -> dict[tuple[str, str], list[Mission]]:
        dom = self.dom
        plan = dom.plan
        out: dict[tuple[str, str], list[Mission]] = {}
        if plan is None:
            return out
        held_in = {m.params.get("objective") for m in dom.missions.values() if m.TYPE in HOLD_TASKS}
        for m in dom.missions.values():
            if isinstance(m, ContingentMission) or plan.state.get(m.id) not in ("ready", "active") \
                    or not dom.in_plan(m):
                continue
            obj, ea_ = m.params.get("objective"), m.params.get("engagement_area")
            if m.TYPE in OBJECTIVE_TASKS and obj in dom.overlay and obj not in held_in:
                out.setdefault(("objective-clear", obj), []).append(m)
            if ea_ in dom.overlay and m.TYPE not in NOT_EA and m.TYPE not in HOLD_TASKS:
                out.setdefault(("enemy-withdrawn", ea_), []).append(m)
        return out

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        if not (ch.tracks or ch.rescan):
            return   # nothing it judges moved: whether a place is clear changes only with its tracks
        dom = self.dom
        watches = self._watches()
        for k in [k for k in self.held if k not in watches]:
            del self.held[k]   # nobody watches it any more: a later clearing is nobody's news
        if not watches:
            return
        tracks = dom.pic.tracks
        tids = sorted(tracks)
        xs = [tracks[k].x for k in tids]
        ys = [tracks[k].y for k in tids]
        for (typ, area), ms in sorted(watches.items(), key=lambda kv: kv[0]):
            geom = dom.overlay[area].area
            held = self.held.setdefault((typ, area), {})
            if tids:
                inside = shapely.contains_xy(geom, xs, ys).tolist()
                near = (shapely.distance(geom, shapely.points(list(zip(xs, ys)))) <= LINGER_M).tolist()
            else:
                inside, near = [], []
            for k, hit in zip(tids, inside):
                if hit:
                    held[k] = (tracks[k].x, tracks[k].y)
            if not held or any(near):
                continue
            # clear: where did the groups that were in it go? A track lost on the way (a
            # group seen as two tracks, a false alarm) is continued by a track near where
            # it was last inside, or by the others; all lost: nobody saw it leave
            gone = {k: (tracks[k].x, tracks[k].y) for k in held if k in tracks}
            for k, (x, y) in held.items():
                if k not in tracks:
                    succ = [j for j in tids if j not in held and math.hypot(tracks[j].x - x, tracks[j].y - y)
                            <= SAME_GROUP_M + LINGER_M]
                    if succ:
                        gone[succ[0]] = (tracks[succ[0]].x, tracks[succ[0]].y)
            self.held[(typ, area)] = {}
            if not gone:
                continue
            c = geom.centroid
            units = sorted({m.unit for m in ms})
            away = True
            for u in units:
                p = dom.unit_pos.get(u)
                if p is None:
                    continue
                ref = math.hypot(c.x - p[0], c.y - p[1])
                if any(math.hypot(x - p[0], y - p[1]) <= ref for x, y in gone.values()):
                    away = False
            if away:
                cands.append(self._cand(t, typ, area, ms, units, sorted(gone)))

    def _cand(self, t: float, typ: str, area: str, ms: list[Mission], units: list[str],
              gone: list[str]) -> Candidate:
        dom = self.dom
        names = ", ".join(dom.name(u) for u in units)
        what = (f"Opportunity: {area} clear of hostiles before {names} took it"
                if typ == "objective-clear" else
                f"Opportunity: the hostiles expected in {area} withdrew from it ({names})")
        prio = dom.priorities.get(typ, DEFAULT_PRIORITY)
        return Candidate(t, typ, prio, (*units, *gone), f"{what}: {', '.join(gone)} gone",
                         key=(typ, area), friendly=False,
                         details={"place": area, "places": [area], "missions": sorted(m.id for m in ms),
                                  "mission": sorted(m.id for m in ms)[0], "tracks": gone})
