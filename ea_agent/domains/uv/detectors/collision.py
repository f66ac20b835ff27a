"""Collision (constraint-violation-projected): the closest point of approach within
`collision_m` in the next `collision_horizon_s`, from positions and velocities,
between teammates (numpy, all pairs at once) and against obstacle polygons
(shapely, once per epoch, only for moving robots)."""
from __future__ import annotations

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


def cpa(p: np.ndarray, v: np.ndarray, horizon: float) -> tuple[np.ndarray, np.ndarray]:
    """Time in [0, horizon] and distance of the closest approach of relative
    positions `p` moving at relative velocities `v` (both (..., 2))."""
    vv = (v * v).sum(-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        ts = np.where(vv > 1e-12, -(p * v).sum(-1) / vv, 0.0)
    ts = np.clip(ts, 0.0, horizon)
    q = p + v * ts[..., None]
    return ts, np.hypot(q[..., 0], q[..., 1])


def collisions(dom: "UvDomain", t: float, cands: list) -> None:
    uv = dom.uv
    lim, horizon, fresh = float(uv["collision_m"]), float(uv["collision_horizon_s"]), float(uv["no_status_s"])
    rs = [dom.robots[r] for r in dom.robot_ids if dom.robots[r].t != NEG and t - dom.robots[r].t <= fresh]
    if not rs or not any(r.id in dom.mine for r in rs):
        return
    pos = np.array([r.at(t) for r in rs])
    vel = np.array([(r.vx, r.vy) for r in rs])
    rad = np.array([r.radius for r in rs])
    mine = np.array([r.id in dom.mine for r in rs])
    if len(rs) > 1:
        p = pos[None, :, :] - pos[:, None, :]
        v = vel[None, :, :] - vel[:, None, :]
        ts, d = cpa(p, v, horizon)
        clear = d - rad[:, None] - rad[None, :]
        now = np.hypot(p[..., 0], p[..., 1]) - rad[:, None] - rad[None, :]
        hit = (clear <= lim) & ((ts > 0) | (now <= 0)) & (mine[:, None] | mine[None, :])
        hit = np.triu(hit, 1)
        for i, j in zip(*np.nonzero(hit)):
            a, b = rs[i].id, rs[j].id
            c = float(max(clear[i, j], 0.0))
            cands.append(dom.cand(t, "collision", None, (a, b),
                                  f"{dom.name(a)} and {dom.name(b)} may collide in {ts[i, j]:.1f} s "
                                  f"(closest {m_(c)})", ("collision", a, b), 10.0 / (c + 1.0),
                                  {"robots": [a, b], "in_s": round(float(ts[i, j]), 2), "clearance_m": round(c, 2)}))
    _obstacles(dom, t, rs, pos, vel, rad, mine, lim, horizon, cands)


def _obstacles(dom, t, rs, pos, vel, rad, mine, lim, horizon, cands) -> None:
    obs: Obstacles = dom.obstacles
    if obs.union is None:
        return
    idx = [i for i in range(len(rs)) if mine[i] and rs[i].speed > 0.05]   # parked robots hit nothing
    if not idx:
        return
    ends = pos[idx] + vel[idx] * horizon
    lines = shapely.linestrings(np.stack([pos[idx], ends], axis=1))
    d = shapely.distance(lines, obs.union) - rad[idx]
    for k in np.nonzero(d <= lim)[0].tolist():
        i = idx[k]
        r = rs[i]
        near = shapely.distance(obs.geoms, lines[k]) - rad[i]
        oid = obs.ids[int(np.argmin(near))]
        zone = dom.world[oid].geom.buffer(lim + rad[i])
        speed = float(np.hypot(*vel[i]))
        start = shapely.Point(pos[i])
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
