"""Seeded, deterministic kinematic simulator of ONE UV robot (paper 7), stepped by its
controller in 0.5 s steps of event time: it runs its recipe (goto a waypoint, patrol an
area as a loop of its corners, search an area as a lawnmower, a planned pursuit) and obeys
the task messages of its EA (`tasks.py`: pursue, drop, resume the patrol, hand off,
accept). It holds no copy of the EA's policy: without tasks a patroller never pursues.

What it decides itself is the recipe's own progress (arrived at the waypoint, found the
searched target) and how to follow a target (chase it while seen, else drive to where it
should be by now and circle there). Evaders follow scripted keyframes; faults are
scripted windows (stuck, waiting-gps, divergent drive, link loss), so the oracle knows
the truth. Each robot draws from its own random stream, so robots can run in separate
processes and still give the same run. Positions are local metres; reports leave in
lon/lat (`Frame` converts). The true state, step by step, is kept for the oracle
(`record`; `Team` puts the robots' records together).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely.geometry import Point

from . import tasks as task_messages

DT = 0.5
FAULTS = ("stuck", "gps", "diverge", "link")
GPS_TAU_S = 30.0      # correlation time of the GPS error


@dataclass
class Pursuit:
    target: str
    sector: str
    mission: str | None           # a planned pursue mission, or None for one the EA ordered
    last_t: float
    last_xy: tuple[float, float]
    last_v: tuple[float, float] = (0.0, 0.0)
    gone: bool = False            # truth: the target was seen outside the sector (logged once)


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def compass(heading: float) -> float:
    """Math radians -> compass degrees in [0, 360)."""
    return round((90.0 - math.degrees(heading)) % 360.0, 1) % 360.0   # 359.96 rounds to 360.0: that is 0


class Geo:
    """Local metres <-> lon/lat of the scenario (a projected CRS and the area's origin)."""

    def __init__(self, epsg: int, origin: tuple[float, float]):
        from ea_agent.core.geo import Projection
        self.proj, self.origin = Projection(epsg), origin

    def lonlat(self, xy) -> tuple[float, float]:
        lon, lat = self.proj.to_lonlat(float(xy[0]) + self.origin[0], float(xy[1]) + self.origin[1])
        return round(float(lon), 7), round(float(lat), 7)

    def xy(self, lon: float, lat: float) -> tuple[float, float]:
        x, y = self.proj.to_xy(lon, lat)
        return float(x) - self.origin[0], float(y) - self.origin[1]


class RobotSim:
    """One robot: its true state and the messages its radio sends, step by step."""

    def __init__(self, unit: dict, index: int, world: dict, missions: list[dict], evaders: dict[str, list],
                 faults: list[tuple[str, str, float, float]], duration: float, geo: Geo, seed: int = 7):
        self.id, self.kind, self.attrs = unit["id"], unit["kind"], unit["attrs"]
        self.world, self.geo, self.duration = world, geo, duration
        self.rng = np.random.default_rng([seed, index])
        self.faults = [f for f in faults if f[1] == self.id]
        self.obstacles = shapely.union_all([p.geom for p in world.values() if p.kind == "obstacle"])
        self.missions = [m for m in missions if m["unit"] == self.id]
        self.xy = np.array(unit["start"], float)
        self.heading = 0.0
        self.k = 0
        self.loop: list = []
        self.loop_i = 0
        self.pursuit: Pursuit | None = None
        self.held = False             # a pursuit the EA dropped, the patrol not resumed yet: stopped
        self.speed = 0.0
        self.times = np.arange(0.0, duration + DT / 2, DT)
        n = len(self.times)
        keys = {e: np.array(k, float) for e, k in evaders.items()}
        self.ev_pos = {e: np.column_stack([np.interp(self.times, k[:, 0], k[:, 1]),
                                           np.interp(self.times, k[:, 0], k[:, 2])]) for e, k in keys.items()}
        self.pos = np.zeros((n, 2))
        self.vel = np.zeros((n, 2))
        self.mode = [""] * n
        self.task: list = [None] * n
        self.goal: list = [None] * n
        self.link = np.ones(n, bool)
        self.visible = {e: np.zeros(n, bool) for e in self.ev_pos}
        self.log: list[dict] = []
        self.last_seen: dict[str, tuple[float, tuple]] = {}
        self.gps_err = np.zeros(2)
        self.out: list[dict] = []     # this step's messages
        self.taken: list = []         # tasks carried out, for the record
        self._begin(0.0)
        aim = self._aim(0, 0.0)
        if aim is not None:
            self.heading = math.atan2(aim[1] - self.xy[1], aim[0] - self.xy[0])

    @property
    def mission(self) -> dict | None:
        return self.missions[self.k] if self.k < len(self.missions) else None

    def fault(self, kind: str, t: float) -> bool:
        return any(f == kind and a <= t < b for f, _, a, b in self.faults)

    # -- recipes ---------------------------------------------------------------------------
    def _begin(self, t: float) -> None:
        """Start the current mission: build the loop of points it drives."""
        m = self.mission
        self.loop, self.loop_i = [], 0
        if m is None:
            return
        p = m.get("params", {})
        if m["type"] == "patrol":
            ring = list(self.world[p["area"]].geom.exterior.coords)[:-1]
            self.loop = [np.array(c) for c in ring]
            self.loop_i = int(np.argmin([np.hypot(*(c - self.xy)) for c in self.loop]))
        elif m["type"] == "search":
            x0, y0, x1, y1 = self.world[p["area"]].geom.bounds
            lane = 1.6 * self.attrs["sensor_range_m"]
            ys = np.arange(y0 + lane / 2, y1, lane)
            self.loop = [np.array(c) for i, y in enumerate(ys)
                         for c in (((x0, y), (x1, y)) if i % 2 == 0 else ((x1, y), (x0, y)))]
        elif m["type"] == "pursue":
            seen = self.last_seen.get(p["target"])
            lt, lxy = seen if seen else (t, tuple(self.xy))
            self.pursuit = Pursuit(p["target"], p["sector"], m["id"], lt, lxy)
            self.log.append({"t": t, "what": "commit", "robot": self.id, "target": p["target"], "sector": p["sector"]})

    def _next(self, t: float, ok: bool = True) -> None:
        m = self.mission
        if m is not None:
            self.emit(t, {"kind": "uv-agent", "sender": self.id, "to": "TEAM",
                          "act": "success" if ok else "failure", "task": m["id"]})
            self.log.append({"t": t, "what": "end", "robot": self.id, "mission": m["id"], "ok": ok})
        self.k += 1
        self.pursuit = None
        self.held = False
        self._begin(t)

    def _aim(self, i: int, t: float) -> np.ndarray | None:
        """Where the robot drives now (None: nowhere, it stops)."""
        if self.pursuit is not None:
            pu = self.pursuit
            if self.visible[pu.target][i]:
                return self.ev_pos[pu.target][i]
            dt = min(t - pu.last_t, 10.0)     # relocate: where the target should be by now
            guess = np.array(pu.last_xy) + dt * np.array(pu.last_v)
            if np.hypot(*(guess - self.xy)) < 20.0:   # there: search around it
                guess = guess + 15.0 * np.array([math.cos(0.2 * t), math.sin(0.2 * t)])
            return guess
        m = self.mission
        if m is None or self.held:
            return None
        if m["type"] == "goto":
            return np.array(self.world[m["params"]["waypoint"]].geom.coords[0])
        if self.loop:
            if np.hypot(*(self.loop[self.loop_i] - self.xy)) < 8.0:
                self.loop_i = (self.loop_i + 1) % len(self.loop)
            return self.loop[self.loop_i]
        return None

    # -- the EA's tasks --------------------------------------------------------------------
    def obey(self, task, i: int, t: float) -> None:
        """Carry out one task of the robot's EA (due at or before t)."""
        self.taken.append({"t": t, "op": type(task).__struct_config__.tag, "at": task.at, "n": task.n})
        if getattr(task, "sector", None) is not None and task.sector not in self.world:
            self.log.append({"t": t, "what": "refused", "robot": self.id, "why": f"unknown sector {task.sector}"})
            return
        if isinstance(task, (task_messages.Pursue, task_messages.Accept)):
            if isinstance(task, task_messages.Accept):
                self.emit(t, {"kind": "uv-agent", "sender": self.id, "to": task.frm, "act": "accept",
                              "task": task.task, "target": task.target})
                self.log.append({"t": t, "what": "accept", "robot": self.id, "from": task.frm, "target": task.target})
            if self.pursuit is not None and self.pursuit.target == task.target:
                return
            seen = self.last_seen.get(task.target)
            if seen is None and task.lon is not None and task.lat is not None:
                seen = (t, self.geo.xy(task.lon, task.lat))
            lt, lxy = seen if seen else (t, tuple(self.xy))
            self.pursuit = Pursuit(task.target, task.sector, None, max(lt, t), tuple(lxy))
            self.held = False
            self.log.append({"t": t, "what": "commit", "robot": self.id, "target": task.target, "sector": task.sector})
        elif isinstance(task, task_messages.Drop):
            pu = self.pursuit
            if pu is None or pu.target != task.target:
                return
            self.log.append({"t": t, "what": "drop", "robot": self.id, "target": pu.target, "why": task.why})
            if pu.mission is not None:
                self._next(t, ok=False)
            else:
                self.pursuit, self.held = None, True
        elif isinstance(task, task_messages.Resume):
            if self.pursuit is None:
                self.held = False
                self._begin(t)       # resume the patrol from the nearest corner
        elif isinstance(task, task_messages.Handoff):
            self.emit(t, {"kind": "uv-agent", "sender": self.id, "to": task.to, "act": "delegate",
                          "task": task.task, "target": task.target})
            self.log.append({"t": t, "what": "handoff", "robot": self.id, "to": task.to, "target": task.target})

    # -- what the robot itself decides -----------------------------------------------------------
    def _recipe(self, i: int, t: float) -> None:
        m = self.mission
        seen = [e for e in self.ev_pos if self.visible[e][i]]
        for e in seen:
            xy = self.ev_pos[e][i]
            v = (self.ev_pos[e][i] - self.ev_pos[e][i - 1]) / DT if i else np.zeros(2)
            self.last_seen[e] = (t, tuple(xy))
            if self.pursuit is not None and self.pursuit.target == e:
                pu = self.pursuit
                pu.last_t, pu.last_xy, pu.last_v = t, tuple(xy), tuple(v)
                if not pu.gone and not self.world[pu.sector].geom.contains(Point(xy)):
                    pu.gone = True   # truth for the oracle: what the EA should see and act on
                    self.log.append({"t": t, "what": "gone", "robot": self.id, "target": e, "sector": pu.sector})
        if self.pursuit is not None or m is None:
            return
        if m["type"] == "goto":
            wp = self.world[m["params"]["waypoint"]]
            if np.hypot(*(np.array(wp.geom.coords[0]) - self.xy)) <= float(wp.props.get("radius_m", 10.0)):
                self.log.append({"t": t, "what": "arrive", "robot": self.id, "mission": m["id"], "waypoint": wp.id})
                self._next(t)
        elif m["type"] == "search" and m["params"]["target"] in seen:
            self.log.append({"t": t, "what": "found", "robot": self.id, "target": m["params"]["target"]})
            self._next(t)

    # -- kinematics ------------------------------------------------------------------------------
    def _move(self, i: int, t: float) -> str:
        aim = self._aim(i, t)
        a = self.attrs
        vmax, turn = a["max_speed_mps"], math.radians(a["turn_rate_dps"]) * DT
        if self.fault("gps", t):
            self.speed = 0.0
            return "waiting-gps"
        if self.fault("stuck", t):
            self.speed = 0.0
            return "moving"
        if aim is None:
            self.speed = 0.0
            return "paused"
        d = aim - self.xy
        dist = float(np.hypot(*d))
        want = math.atan2(d[1], d[0])
        if self.fault("diverge", t):
            want = _wrap(want + math.pi * 0.9)
        err = _wrap(want - self.heading)
        self.heading = _wrap(self.heading + max(-turn, min(turn, err)))
        floor = 0.15 if self.kind == "ugv" else 0.8     # a UAV keeps flying through its turns
        v = vmax * max(floor, math.cos(min(abs(err), math.pi / 2)))
        if self.pursuit is not None and dist < 12.0:
            v = min(v, max(0.6, dist / 4.0))     # close behind the target: match its pace
        step = v * DT * np.array([math.cos(self.heading), math.sin(self.heading)])
        if self.kind == "ugv" and self._blocked(self.xy + step):
            for off in (0.35, -0.35, 0.7, -0.7, 1.05, -1.05, 1.4, -1.4, 1.75, -1.75):
                h = self.heading + off
                s = v * DT * np.array([math.cos(h), math.sin(h)])
                if not self._blocked(self.xy + s):
                    self.heading, step = _wrap(h), s
                    break
            else:
                step = np.zeros(2)
        self.xy = self.xy + step
        self.speed = float(np.hypot(*step)) / DT
        return "moving"

    def _blocked(self, xy: np.ndarray) -> bool:
        return self.obstacles.distance(Point(xy)) < self.attrs["radius_m"] + 1.5

    # -- messages ---------------------------------------------------------------------------------
    def emit(self, t: float, ev: dict) -> None:
        if not self.fault("link", t):
            d = {"t": round(t, 2), **ev}
            if "_xy" in d:
                d["lon"], d["lat"] = self.geo.lonlat(d.pop("_xy"))
            self.out.append(d)

    def _report(self, i: int, t: float, mode: str) -> None:
        sig = self.attrs["sigma_m"] * (6.0 if mode == "waiting-gps" else 1.0)
        a = math.exp(-DT / GPS_TAU_S)     # GPS error drifts slowly (it is not white noise)
        self.gps_err = a * self.gps_err + math.sqrt(1 - a * a) * self.rng.normal(0.0, 0.3, 2)
        xy = self.pos[i] + sig * self.gps_err
        self.emit(t, {"kind": "uv-state", "robot": self.id, "_xy": tuple(xy),
                      "speed_mps": round(self.speed, 2), "heading_deg": compass(self.heading),
                      "sigma_m": round(sig, 1), "mode": mode})
        for e in self.ev_pos:
            if self.visible[e][i]:
                s = self.attrs["sensor_sigma_m"]
                self.emit(t, {"kind": "uv-sighting", "robot": self.id, "target": e,
                              "_xy": tuple(self.ev_pos[e][i] + self.rng.normal(0.0, s * 0.5, 2)), "sigma_m": s})

    def step(self, i: int, tasks=()) -> list[dict]:
        """Step i (event time i x DT): sense, carry out the EA's tasks due by now (in (at, n)
        order), run the recipe, move; returns the messages the radio sends at this time."""
        t = float(self.times[i])
        self.out = []
        for e, p in self.ev_pos.items():
            self.visible[e][i] = np.hypot(*(p[i] - self.xy)) <= self.attrs["sensor_range_m"]
        for task in sorted(tasks, key=lambda x: x.sort_key()):
            self.obey(task, i, t)
        self._recipe(i, t)
        m = self.mission
        pu = self.pursuit
        self.task[i] = f"pursue:{pu.target}" if pu and not pu.mission else m["id"] if m else None
        self.goal[i] = m["params"]["waypoint"] if m and m["type"] == "goto" and not pu else None
        self.link[i] = not self.fault("link", t)
        self.pos[i] = self.xy.copy()
        mode = self._move(i, t) if i else ("moving" if m else "paused")
        self.mode[i] = mode
        self.vel[i] = self.speed * np.array([math.cos(self.heading), math.sin(self.heading)])
        self._report(i, t, mode)
        return self.out

    # -- the record, for the oracle ------------------------------------------------------------------
    def record(self) -> dict:
        """The robot's true run (arrays as lists): what `Team` needs, from any process."""
        return {"id": self.id, "pos": self.pos.tolist(), "vel": self.vel.tolist(), "mode": self.mode,
                "task": self.task, "goal": self.goal, "link": self.link.tolist(),
                "visible": {e: v.tolist() for e, v in self.visible.items()}, "log": self.log, "taken": self.taken}


class _Unit:
    def __init__(self, kind: str, attrs: dict):
        self.kind, self.attrs = kind, attrs


@dataclass
class Team:
    """The team's true run put together from every robot's record (what the oracle reads)."""
    world: dict
    units: list[dict]
    faults: list
    duration: float
    records: dict[str, dict]
    evaders: dict[str, list] = field(default_factory=dict)
    robots: dict = field(init=False)

    def __post_init__(self) -> None:
        by = {u["id"]: u for u in self.units}
        order = [u["id"] for u in self.units if u["kind"] in ("ugv", "uav")]
        self.robots = {r: _Unit(by[r]["kind"], by[r]["attrs"]) for r in order}
        self.times = np.arange(0.0, self.duration + DT / 2, DT)
        self.obstacles = shapely.union_all([p.geom for p in self.world.values() if p.kind == "obstacle"])
        keys = {e: np.array(k, float) for e, k in self.evaders.items()}
        self.ev_pos = {e: np.column_stack([np.interp(self.times, k[:, 0], k[:, 1]),
                                           np.interp(self.times, k[:, 0], k[:, 2])]) for e, k in keys.items()}
        rec = self.records
        self.pos = {r: np.array(rec[r]["pos"]) for r in order}
        self.vel = {r: np.array(rec[r]["vel"]) for r in order}
        self.mode = {r: rec[r]["mode"] for r in order}
        self.task = {r: rec[r]["task"] for r in order}
        self.goal = {r: rec[r]["goal"] for r in order}
        self.link = {r: np.array(rec[r]["link"], bool) for r in order}
        self.visible = {(r, e): np.array(v, bool) for r in order for e, v in rec[r]["visible"].items()}
        logs = sorted((ev["t"], order.index(r), j, ev) for r in order for j, ev in enumerate(rec[r]["log"]))
        self.log = [ev for *_, ev in logs]
        for ev in self.log:   # when the teammate accepted a handoff (the oracle's window)
            if ev["what"] == "handoff":
                acc = next((a["t"] for a in self.log if a["what"] == "accept" and a["robot"] == ev["to"]
                            and a["target"] == ev["target"] and a["t"] >= ev["t"]), None)
                ev["accept_t"] = acc      # None: the teammate did not accept (it was busy)
