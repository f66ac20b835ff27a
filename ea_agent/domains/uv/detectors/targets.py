"""Adversarial activity (paper 7.4): target-visible, lost-target, target-gone.

Two audiences: a robot's own EA (the controller) is told of a lost target at once
(`lost_s`); the operator (human) only when reacquiring is deteriorating: unseen for
`lost_human_s`, or the target's last position farther than the robot can cover.
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import shapely

from ..render import m_
from ..watchman import NEG

if TYPE_CHECKING:
    from ..domain import UvDomain


def target_visible(dom: "UvDomain", t: float, cands: list) -> None:
    """Sightings that (re)acquire a target: report them and let the robot's active
    tasks react (a searcher is done; pursuits are the policies', `policies.step`)."""
    acq, dom.watchman.acquired = dom.watchman.acquired, []
    for ta, rid, target, n in sorted(acq):
        if rid not in dom.mine:
            continue
        tg = dom.watchman.targets[target]
        key = ("target-visible", target) if dom.human else ("target-visible", rid, target)
        again = " again" if n > 1 else ""
        cands.append(dom.cand(ta, "target-visible", None, (rid, target),
                              f"{dom.name(rid)} sees target {target}{again}", key, float(n),
                              {"robot": rid, "target": target, "acquisition": n, "x": round(tg.x, 1),
                               "y": round(tg.y, 1)}, friendly=False))
        for m in dom.active_of(rid):
            m.on_target_visible(dom, target, ta)


def _pursuits(dom: "UvDomain"):
    for mid, (m, target) in list(dom.target_missions.items()):
        if m.TYPE == "pursue" and m.unit in dom.mine and dom.active(mid):
            yield m, target


def last_seen(dom: "UvDomain", m, target: str) -> float:
    """When the pursuit last had its target: its last sighting heard, but never before
    the pursuit began (a pursuit taken over from a teammate starts its own clock, as the
    robot's controller does, even if we heard an older sighting)."""
    tg = dom.watchman.targets.get(target)
    start = dom.started_at(m)
    return max(tg.t, start) if tg is not None and tg.t != NEG else start


def lost_target(dom: "UvDomain", t: float, cands: list) -> None:
    uv = dom.uv
    lost_s, human_s = float(uv["lost_s"]), float(uv["lost_human_s"])
    for m, target in list(_pursuits(dom)):
        tg = dom.watchman.targets.get(target)
        last = last_seen(dom, m, target)
        unseen = t - last
        if unseen < lost_s:
            continue
        r = dom.robots[m.unit]
        far = None
        if tg is not None and tg.t != NEG and r.t != NEG:
            far = math.hypot(tg.x - r.x, tg.y - r.y)
        reach = r.sensor_range + r.max_speed * lost_s
        deteriorating = unseen >= human_s or (far is not None and far > reach)
        if not dom.human or deteriorating:
            where = "" if far is None else f", last seen {m_(far)} away"
            cands.append(dom.cand(t, "lost-target", m, (m.unit, target),
                                  f"{dom.name(m.unit)} lost target {target}: unseen for {unseen:.0f} s{where}",
                                  ("lost-target", m.id), unseen,
                                  {"mission": m.id, "target": target, "unseen_s": round(unseen, 1),
                                   "distance_m": None if far is None else round(far, 1),
                                   "deteriorating": deteriorating}))


def target_gone(dom: "UvDomain", t: float, cands: list) -> None:
    """The pursued target's last sighting is outside the pursuit's sector."""
    dirty = dom.watchman.dirty_targets
    for m, target in list(_pursuits(dom)):
        sector = m.params.get("sector")
        if target not in dirty or not sector or sector not in dom.world:
            continue
        tg = dom.watchman.targets[target]
        if shapely.contains_xy(dom.world[sector].geom, tg.x, tg.y):
            continue
        d = float(shapely.distance(dom.world[sector].geom, shapely.Point(tg.x, tg.y)))
        cands.append(dom.cand(t, "target-gone", m, (m.unit, target),
                              f"Target {target} left {dom.name(m.unit)}'s sector {sector} ({m_(d)} outside)",
                              ("target-gone", m.id), d, {"mission": m.id, "target": target, "sector": sector,
                                                         "places": [sector], "outside_m": round(d, 1)}))
