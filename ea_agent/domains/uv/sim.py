"""Seeded, deterministic kinematic simulator of a UV robot team (paper 7).

Robots (UGVs, UAVs) run their recipes in 0.5 s steps: goto a waypoint, patrol an area
(a loop of its corners), search an area (a lawnmower) and pursue evaders under the
policy the EA models (a patroller commits to pursue on sighting; a pursuit is dropped
when the target has been unseen for `drop_s`, or handed to the teammate whose sector
the target ran into). Evaders follow scripted keyframes. Faults are scripted windows
(stuck, waiting-gps, divergent drive, link loss), so the oracle knows the truth.
Positions are local metres; the generator converts the emitted ones to lon/lat.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.geometry import Point

DT = 0.5
FAULTS = ("stuck", "gps", "diverge", "link")
GPS_TAU_S = 30.0      # correlation time of the GPS error


@dataclass
class Pursuit:
    target: str
    sector: str
    mission: str | None           # a planned pursue mission, or None for a policy pursuit
    last_t: float
    last_xy: tuple[float, float]
    last_v: tuple[float, float] = (0.0, 0.0)


@dataclass
class Robot:
    id: str
    kind: str
    xy: np.ndarray
    heading: float                # radians, math convention (0 = east, counter-clockwise)
    attrs: dict
    missions: list[dict]
    k: int = 0                    # index of the current mission
    loop: list = field(default_factory=list)
    loop_i: int = 0
    pursuit: Pursuit | None = None
    cooldown: dict = field(default_factory=dict)   # target -> time before which no new pursuit
    speed: float = 0.0

    @property
    def mission(self) -> dict | None:
        return self.missions[self.k] if self.k < len(self.missions) else None


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def compass(heading: float) -> float:
    """Math radians -> compass degrees in [0, 360)."""
    return round((90.0 - math.degrees(heading)) % 360.0, 1) % 360.0   # 359.96 rounds to 360.0: that is 0


class Sim:
    """The true state of the world, step by step, and the messages the robots send."""

    def __init__(self, world: dict, units: list[dict], missions: list[dict], evaders: dict[str, list],
                 faults: list[tuple[str, str, float, float]], duration: float, seed: int = 7, drop_s: float = 30.0):
        self.world, self.duration, self.drop_s = world, duration, drop_s
        self.rng = np.random.default_rng(seed)
        self.faults = faults
        self.obstacles = shapely.union_all([p.geom for p in world.values() if p.kind == "obstacle"])
        self.robots: dict[str, Robot] = {}
        for u in units:
            if u["kind"] in ("ugv", "uav"):
                mine = [m for m in missions if m["unit"] == u["id"]]
                x, y = u["start"]
                self.robots[u["id"]] = Robot(u["id"], u["kind"], np.array([x, y], float), 0.0, u["attrs"], mine)
        self.ev_keys = {e: np.array(k, float) for e, k in evaders.items()}
        self.times = np.arange(0.0, duration + DT / 2, DT)
        n = len(self.times)
        self.ev_pos = {e: np.column_stack([np.interp(self.times, k[:, 0], k[:, 1]),
                                           np.interp(self.times, k[:, 0], k[:, 2])]) for e, k in self.ev_keys.items()}
        self.pos = {r: np.zeros((n, 2)) for r in self.robots}
        self.vel = {r: np.zeros((n, 2)) for r in self.robots}
        self.mode = {r: [""] * n for r in self.robots}
        self.task: dict[str, list] = {r: [None] * n for r in self.robots}
        self.goal: dict[str, list] = {r: [None] * n for r in self.robots}
        self.link = {r: np.ones(n, bool) for r in self.robots}
        self.visible = {(r, e): np.zeros(n, bool) for r in self.robots for e in self.ev_pos}
        self.log: list[dict] = []
        self.events: list[dict] = []
        self.last_seen: dict[tuple[str, str], tuple[float, tuple]] = {}
        self.gps_err = {r: np.zeros(2) for r in self.robots}
        for r in self.robots.values():
            self._begin(r, 0.0)
            aim = self._aim(r, 0, 0.0)
            if aim is not None:
                r.heading = math.atan2(aim[1] - r.xy[1], aim[0] - r.xy[0])

    # -- scripted faults -------------------------------------------------------------------
    def fault(self, rid: str, kind: str, t: float) -> bool:
        return any(f == kind and r == rid and a <= t < b for f, r, a, b in self.faults)

    # -- recipes ---------------------------------------------------------------------------
    def _begin(self, r: Robot, t: float) -> None:
        """Start r's current mission: build the loop of points it drives."""
        m = r.mission
        r.loop, r.loop_i = [], 0
        if m is None:
            return
        p = m.get("params", {})
        if m["type"] == "patrol":
            ring = list(self.world[p["area"]].geom.exterior.coords)[:-1]
            r.loop = [np.array(c) for c in ring]
            r.loop_i = int(np.argmin([np.hypot(*(c - r.xy)) for c in r.loop]))
        elif m["type"] == "search":
            x0, y0, x1, y1 = self.world[p["area"]].geom.bounds
            lane = 1.6 * r.attrs["sensor_range_m"]
            ys = np.arange(y0 + lane / 2, y1, lane)
            r.loop = [np.array(c) for i, y in enumerate(ys)
                      for c in (((x0, y), (x1, y)) if i % 2 == 0 else ((x1, y), (x0, y)))]
        elif m["type"] == "pursue":
            seen = self.last_seen.get((r.id, p["target"]))
            lt, lxy = seen if seen else (t, tuple(r.xy))
            r.pursuit = Pursuit(p["target"], p["sector"], m["id"], lt, lxy)
            self.log.append({"t": t, "what": "commit", "robot": r.id, "target": p["target"], "sector": p["sector"]})

    def _next(self, r: Robot, t: float, ok: bool = True) -> None:
        m = r.mission
        if m is not None:
            self.emit(r.id, t, {"kind": "uv-agent", "sender": r.id, "to": "TEAM",
                                "act": "success" if ok else "failure", "task": m["id"]})
            self.log.append({"t": t, "what": "end", "robot": r.id, "mission": m["id"], "ok": ok})
        r.k += 1
        r.pursuit = None
        self._begin(r, t)

    def _aim(self, r: Robot, i: int, t: float) -> np.ndarray | None:
        """Where r drives now (None: nowhere, it stops)."""
        if r.pursuit is not None:
            pu = r.pursuit
            if self.visible[(r.id, pu.target)][i]:
                return self.ev_pos[pu.target][i]
            dt = min(t - pu.last_t, 10.0)     # relocate: where the target should be by now
            guess = np.array(pu.last_xy) + dt * np.array(pu.last_v)
            if np.hypot(*(guess - r.xy)) < 20.0:   # there: search around it
                guess = guess + 15.0 * np.array([math.cos(0.2 * t), math.sin(0.2 * t)])
            return guess
        m = r.mission
        if m is None:
            return None
        if m["type"] == "goto":
            return np.array(self.world[m["params"]["waypoint"]].geom.coords[0])
        if r.loop:
            if np.hypot(*(r.loop[r.loop_i] - r.xy)) < 8.0:
                r.loop_i = (r.loop_i + 1) % len(r.loop)
            return r.loop[r.loop_i]
        return None

    # -- policies ----------------------------------------------------------------------------
    def _policy(self, r: Robot, i: int, t: float) -> None:
        m = r.mission
        seen = [e for e in self.ev_pos if self.visible[(r.id, e)][i]]
        for e in seen:
            xy = self.ev_pos[e][i]
            v = (self.ev_pos[e][i] - self.ev_pos[e][i - 1]) / DT if i else np.zeros(2)
            self.last_seen[(r.id, e)] = (t, tuple(xy))
            if r.pursuit is not None and r.pursuit.target == e:
                r.pursuit.last_t, r.pursuit.last_xy, r.pursuit.last_v = t, tuple(xy), tuple(v)
        pu = r.pursuit
        if pu is not None:
            sector = self.world[pu.sector].geom
            if pu.last_t == t and not sector.contains(Point(pu.last_xy)):
                self.log.append({"t": t, "what": "gone", "robot": r.id, "target": pu.target, "sector": pu.sector})
                self._handoff(r, pu, t)
                self._drop(r, t, "gone")
            elif t - pu.last_t > self.drop_s:
                self.log.append({"t": t, "what": "lost", "robot": r.id, "target": pu.target, "since": pu.last_t})
                self._drop(r, t, "lost")
            return
        if m is None:
            return
        if m["type"] == "goto":
            wp = self.world[m["params"]["waypoint"]]
            if np.hypot(*(np.array(wp.geom.coords[0]) - r.xy)) <= float(wp.props.get("radius_m", 10.0)):
                self.log.append({"t": t, "what": "arrive", "robot": r.id, "mission": m["id"], "waypoint": wp.id})
                self._next(r, t)
        elif m["type"] == "search" and m["params"]["target"] in seen:
            self.log.append({"t": t, "what": "found", "robot": r.id, "target": m["params"]["target"]})
            self._next(r, t)
        elif m["type"] == "patrol" and seen:
            sector = m["params"].get("sector") or m["params"]["area"]
            for e in seen:
                if self.world[sector].geom.contains(Point(self.ev_pos[e][i])) and t >= r.cooldown.get(e, -1.0):
                    self.commit(r, e, sector, t, tuple(self.ev_pos[e][i]))
                    break

    def commit(self, r: Robot, target: str, sector: str, t: float, xy: tuple) -> None:
        r.pursuit = Pursuit(target, sector, None, t, xy)
        self.log.append({"t": t, "what": "commit", "robot": r.id, "target": target, "sector": sector})

    def _drop(self, r: Robot, t: float, why: str) -> None:
        pu = r.pursuit
        assert pu is not None
        self.log.append({"t": t, "what": "drop", "robot": r.id, "target": pu.target, "why": why})
        r.cooldown[pu.target] = t + 60.0
        if pu.mission is not None:
            self._next(r, t, ok=False)
        else:
            r.pursuit = None
            self._begin(r, t)       # resume the patrol from the nearest corner

    def _handoff(self, r: Robot, pu: Pursuit, t: float) -> None:
        """Pass the pursuit to a patrolling teammate whose sector the target is in."""
        for q in self.robots.values():
            m = q.mission
            if q is r or q.pursuit is not None or m is None or m["type"] != "patrol" or not m["params"].get("sector"):
                continue
            if self.world[m["params"]["sector"]].geom.contains(Point(pu.last_xy)):
                task = f"{r.id}-pursue-{pu.target}"
                self.emit(r.id, t, {"kind": "uv-agent", "sender": r.id, "to": q.id, "act": "delegate",
                                    "task": task, "target": pu.target})
                self.emit(q.id, t + DT, {"kind": "uv-agent", "sender": q.id, "to": r.id, "act": "accept",
                                         "task": task, "target": pu.target})
                self.log.append({"t": t, "what": "handoff", "robot": r.id, "to": q.id, "target": pu.target,
                                 "accept_t": t + DT})
                self.commit(q, pu.target, m["params"]["sector"], t + DT, pu.last_xy)
                return

    # -- kinematics ------------------------------------------------------------------------------
    def _move(self, r: Robot, i: int, t: float) -> str:
        aim = self._aim(r, i, t)
        a = r.attrs
        vmax, turn = a["max_speed_mps"], math.radians(a["turn_rate_dps"]) * DT
        if self.fault(r.id, "gps", t):
            r.speed = 0.0
            return "waiting-gps"
        if self.fault(r.id, "stuck", t):
            r.speed = 0.0
            return "moving"
        if aim is None:
            r.speed = 0.0
            return "paused"
        d = aim - r.xy
        dist = float(np.hypot(*d))
        want = math.atan2(d[1], d[0])
        if self.fault(r.id, "diverge", t):
            want = _wrap(want + math.pi * 0.9)
        err = _wrap(want - r.heading)
        r.heading = _wrap(r.heading + max(-turn, min(turn, err)))
        floor = 0.15 if r.kind == "ugv" else 0.8     # a UAV keeps flying through its turns
        v = vmax * max(floor, math.cos(min(abs(err), math.pi / 2)))
        if r.pursuit is not None and dist < 12.0:
            v = min(v, max(0.6, dist / 4.0))     # close behind the target: match its pace
        step = v * DT * np.array([math.cos(r.heading), math.sin(r.heading)])
        if r.kind == "ugv" and self._blocked(r, r.xy + step):
            for off in (0.35, -0.35, 0.7, -0.7, 1.05, -1.05, 1.4, -1.4, 1.75, -1.75):
                h = r.heading + off
                s = v * DT * np.array([math.cos(h), math.sin(h)])
                if not self._blocked(r, r.xy + s):
                    r.heading, step = _wrap(h), s
                    break
            else:
                step = np.zeros(2)
        r.xy = r.xy + step
        r.speed = float(np.hypot(*step)) / DT
        return "moving"

    def _blocked(self, r: Robot, xy: np.ndarray) -> bool:
        return self.obstacles.distance(Point(xy)) < r.attrs["radius_m"] + 1.5

    # -- messages ---------------------------------------------------------------------------------
    def emit(self, rid: str, t: float, ev: dict) -> None:
        if not self.fault(rid, "link", t):
            self.events.append({"t": round(t, 2), **ev})

    def _report(self, r: Robot, i: int, t: float, mode: str) -> None:
        sig = r.attrs["sigma_m"] * (6.0 if mode == "waiting-gps" else 1.0)
        a = math.exp(-DT / GPS_TAU_S)     # GPS error drifts slowly (it is not white noise)
        self.gps_err[r.id] = a * self.gps_err[r.id] + math.sqrt(1 - a * a) * self.rng.normal(0.0, 0.3, 2)
        xy = self.pos[r.id][i] + sig * self.gps_err[r.id]
        self.emit(r.id, t, {"kind": "uv-state", "robot": r.id, "_xy": tuple(xy),
                            "speed_mps": round(r.speed, 2), "heading_deg": compass(r.heading),
                            "sigma_m": round(sig, 1), "mode": mode})
        for e in self.ev_pos:
            if self.visible[(r.id, e)][i]:
                s = r.attrs["sensor_sigma_m"]
                self.emit(r.id, t, {"kind": "uv-sighting", "robot": r.id, "target": e,
                                    "_xy": tuple(self.ev_pos[e][i] + self.rng.normal(0.0, s * 0.5, 2)),
                                    "sigma_m": s})

    def run(self) -> "Sim":
        for i, t in enumerate(self.times):
            t = float(t)
            for r in self.robots.values():
                for e, p in self.ev_pos.items():
                    self.visible[(r.id, e)][i] = np.hypot(*(p[i] - r.xy)) <= r.attrs["sensor_range_m"]
            for r in self.robots.values():
                self._policy(r, i, t)
            for r in self.robots.values():
                m = r.mission
                self.task[r.id][i] = (f"pursue:{r.pursuit.target}" if r.pursuit and not r.pursuit.mission
                                      else m["id"] if m else None)
                self.goal[r.id][i] = m["params"]["waypoint"] if m and m["type"] == "goto" and not r.pursuit else None
                self.link[r.id][i] = not self.fault(r.id, "link", t)
                self.pos[r.id][i] = r.xy.copy()
                mode = self._move(r, i, t) if i else ("moving" if r.mission else "paused")
                self.mode[r.id][i] = mode
                self.vel[r.id][i] = r.speed * np.array([math.cos(r.heading), math.sin(r.heading)])
                self._report(r, i, t, mode)
        return self
