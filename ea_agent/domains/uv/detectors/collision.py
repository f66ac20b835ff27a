"""Collision (constraint-violation-projected): the closest point of approach within
`collision_m` in the next `collision_horizon_s`, from positions and velocities,
between teammates (plain floats: a handful of robots) and against obstacle polygons
(shapely, once per epoch, only for moving ground vehicles: UAVs fly over obstacles)."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
import shapely

from ..render import m_
from ..watchman import NEG

if TYPE_CHECKING:
    from ..domain import UvDomain


class Obstacles:
    """The world's obstacle polygons, prepared for vectorised distance tests."""

    def __init__(self, world: dict):
        self.ids = sorted(p.id for p in world.values() if p.kind == "obstacle")
        self.geoms = np.array([world[i].geom for i in self.ids], dtype=object)
        self.union = shapely.union_all(self.geoms) if self.ids else None
        if self.union is not None:
            shapely.prepare(self.union)
            shapely.prepare(self.geoms)
        self.bounds = [tuple(world[i].geom.bounds) for i in self.ids]


def collisions(dom: "UvDomain", t: float, cands: list) -> None:
    uv = dom.uv
    lim, horizon, fresh = float(uv["collision_m"]), float(uv["collision_horizon_s"]), float(uv["no_status_s"])
    rs = [r for r in (dom.robots[x] for x in dom.robot_ids) if r.t != NEG and t - r.t <= fresh]
    mine = dom.mine
    if not rs or not any(r.id in mine for r in rs):
        return
    pos = [r.at(t) for r in rs]
    # Pairs: a handful of robots, so plain floats beat numpy; a pair that cannot come within
    # `lim` in the horizon (distance now minus relative speed x horizon) is skipped exactly.
    hyp = math.hypot
    for i, a in enumerate(rs):
        ax, ay = pos[i]
        for j in range(i + 1, len(rs)):
            b = rs[j]
            if a.id not in mine and b.id not in mine:
                continue
            px, py = pos[j][0] - ax, pos[j][1] - ay
            vx, vy = b.vx - a.vx, b.vy - a.vy
            radii = a.radius + b.radius
            now = hyp(px, py) - radii
            if now - hyp(vx, vy) * horizon > lim:
                continue
            vv = vx * vx + vy * vy
            ts = min(max(-(px * vx + py * vy) / vv if vv > 1e-12 else 0.0, 0.0), horizon)
            clear = hyp(px + vx * ts, py + vy * ts) - radii
            if clear <= lim and (ts > 0 or now <= 0):
                c = max(clear, 0.0)
                cands.append(dom.cand(t, "collision", None, (a.id, b.id),
                                      f"{dom.name(a.id)} and {dom.name(b.id)} may collide in {ts:.1f} s "
                                      f"(closest {m_(c)})", ("collision", a.id, b.id), 10.0 / (c + 1.0),
                                      {"robots": [a.id, b.id], "in_s": round(ts, 2), "clearance_m": round(c, 2)}))
    _obstacles(dom, t, rs, pos, lim, horizon, cands)


def _obstacles(dom, t, rs, pos, lim, horizon, cands) -> None:
    obs: Obstacles = dom.obstacles
    if obs.union is None:
        return
    # parked robots hit nothing; UAVs fly over obstacles (docs/uv-domain.md): ground vehicles
    # only, and only those whose path's box, widened by radius + lim, meets an obstacle's box
    idx = []
    for i, r in enumerate(rs):
        if r.kind != "ugv" or r.id not in dom.mine or r.speed <= 0.05:
            continue
        (x, y), m = pos[i], r.radius + lim
        ex, ey = x + r.vx * horizon, y + r.vy * horizon
        x0, x1, y0, y1 = min(x, ex) - m, max(x, ex) + m, min(y, ey) - m, max(y, ey) + m
        if any(x0 <= bx1 and bx0 <= x1 and y0 <= by1 and by0 <= y1 for bx0, by0, bx1, by1 in obs.bounds):
            idx.append(i)
    if not idx:
        return
    p = np.array([pos[i] for i in idx])
    vel = np.array([(rs[i].vx, rs[i].vy) for i in idx])
    rad = np.array([rs[i].radius for i in idx])
    lines = shapely.linestrings(np.stack([p, p + vel * horizon], axis=1))
    d = shapely.distance(lines, obs.union) - rad
    for k in np.nonzero(d <= lim)[0].tolist():
        r = rs[idx[k]]
        near = shapely.distance(obs.geoms, lines[k]) - rad[k]
        oid = obs.ids[int(np.argmin(near))]
        zone = dom.world[oid].geom.buffer(lim + rad[k])
        speed = float(np.hypot(*vel[k]))
        start = shapely.Point(p[k])
        if zone.contains(start) or speed < 1e-6:
            when = 0.0
        else:
            inter = lines[k].intersection(zone)
            when = min(horizon, float(shapely.distance(start, inter)) / speed) if not inter.is_empty else horizon
        c = float(max(near.min(), 0.0))
        cands.append(dom.cand(t, "collision", None, (r.id, oid),
                              f"{dom.name(r.id)} may hit obstacle {oid} in {when:.1f} s (closest {m_(c)})",
                              ("collision", r.id, oid), 10.0 / (c + 1.0),
                              {"robots": [r.id], "obstacle": oid, "places": [oid], "in_s": round(when, 2),
                               "clearance_m": round(c, 2)}))
