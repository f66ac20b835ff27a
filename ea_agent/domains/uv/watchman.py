"""The UV picture and watchman: per-robot state (projected metres, velocity, mode,
time) and per-target sightings, filtered by communication range.

This is the per-message hot path (robots report at 2 Hz, each EA hears itself and
its teammates), so a state costs one projection, one range test and a few attribute
writes; everything heavier runs once per epoch in the detectors.
"""
from __future__ import annotations

import math

from ea_agent.core.geo import Projection
from ea_agent.core.plan import TaskOrg

from .messages import UvAgent, UvSighting, UvState

ROBOT_KINDS = ("ugv", "uav")
NEG = -math.inf


class Robot:
    """What the EA believes about one robot; the progress fields are the event
    history the stuck and divergent detectors keep (paper 7.4)."""
    __slots__ = ("id", "kind", "x", "y", "vx", "vy", "speed", "heading", "mode", "sigma", "t", "n",
                 "max_speed", "turn_rate", "sensor_range", "comm_range", "radius",
                 "anchor_t", "anchor_x", "anchor_y", "anchor_h", "paused_t", "spin_until",
                 "ref_goal", "ref_d", "ref_t", "turn_until", "aligned", "silence")

    def __init__(self, rid: str, attrs: dict, kind: str = "ugv"):
        self.id = rid
        self.kind = kind        # "ugv" or "uav" (a UAV flies over obstacles)
        self.x = self.y = self.vx = self.vy = self.speed = self.heading = self.sigma = 0.0
        self.mode = "moving"
        self.t = NEG            # time of the last state heard
        self.n = 0              # states heard
        self.max_speed = float(attrs.get("max_speed_mps", 2.0))
        self.turn_rate = max(1e-3, float(attrs.get("turn_rate_dps", 45.0)))
        self.sensor_range = float(attrs.get("sensor_range_m", 60.0))
        self.comm_range = float(attrs.get("comm_range_m", math.inf))
        self.radius = float(attrs.get("radius_m", 0.5))
        self.anchor_t, self.anchor_x, self.anchor_y = NEG, 0.0, 0.0   # stuck: where it last moved from
        self.anchor_h = 0.0                                           # ... and its heading then
        self.spin_until = NEG         # a turn in place seen there could have finished by this time
        self.paused_t = NEG                                           # last paused / waiting-gps state
        self.ref_goal: str | None = None                              # divergent: best distance to goal
        self.ref_d = math.inf
        self.ref_t = NEG
        self.turn_until = NEG         # a turn toward the waypoint could have finished by this time
        self.aligned = True
        self.silence: tuple[float, bool] | None = None   # no-status of a teammate: (last state t, was in range)

    def at(self, t: float) -> tuple[float, float]:
        """Position extrapolated to t from the last state (dead reckoning)."""
        dt = t - self.t
        return self.x + self.vx * dt, self.y + self.vy * dt


class Target:
    """The last sighting of an evader heard by this EA."""
    __slots__ = ("id", "t", "x", "y", "by", "sigma")

    def __init__(self, tid: str):
        self.id, self.t, self.x, self.y, self.by, self.sigma = tid, NEG, 0.0, 0.0, "", 0.0


class Watchman:
    """Filters and applies incoming messages. States and sightings update the picture
    here (returning None); agent messages are facts for `UvDomain.apply`. Raises
    KeyError for unknown robots and ValueError for times going backwards: the
    manager counts them."""

    def __init__(self, owner: str, taskorg: TaskOrg, proj: Projection, reacquire_s: float, human: bool):
        self.owner = owner
        self.proj = proj
        self.to_xy = proj._fwd.transform   # the scalar projection: one point per message, no array made for it
        self.robots: dict[str, Robot] = {u.id: Robot(u.id, u.attrs, u.kind) for u in taskorg.units.values()
                                         if u.kind in ROBOT_KINDS}
        self.units = set(taskorg.units)
        self.me: Robot | None = self.robots.get(owner)
        self.hears_all = self.me is None          # the TEAM (operator) EA hears every robot
        self.targets: dict[str, Target] = {}
        self.reacquire_s = reacquire_s
        self.human = human
        self.seen: dict[tuple[str, str], float] = {}    # (observer, target) -> last sighting time
        # (robot, target) -> (t, x, y, lon, lat) of the robot's own latest sighting: what the
        # policies decide on, in every EA alike (the robot's own and the operator's)
        self.own: dict[tuple[str, str], tuple[float, float, float, float, float]] = {}
        self.acquired: list[tuple[float, str, str, int]] = []   # (t, robot, target, n) since last detect
        self.n_acq: dict[tuple[str, str], int] = {}
        self.dirty: set[str] = set()
        self.dirty_targets: set[str] = set()
        self.dropped = 0                          # out of comm range

    def _in_range(self, sender: str, x: float, y: float, extra: float = 0.0) -> bool:
        """(x, y) within our comm range (plus `extra`) of our own last position; before
        we have heard ourselves we hear everyone (and subscribe to everything)."""
        me = self.me
        if self.hears_all or sender == self.owner or me.t == NEG:
            return True
        dx, dy = x - me.x, y - me.y
        rng = me.comm_range + extra
        return dx * dx + dy * dy <= rng * rng

    def watch(self, msg):
        k = type(msg)
        if k is UvState:
            r = self.robots[msg.robot]            # KeyError: unknown robot, counted
            if msg.t < r.t:
                raise ValueError(f"state of {msg.robot} goes back in time ({msg.t} < {r.t})")
            x, y = self.to_xy(msg.lon, msg.lat)
            sender = msg.robot
            if sender != self.owner and not self._in_range(sender, x, y):
                self.dropped += 1
                return None
            h = msg.heading_deg
            v = msg.speed_mps
            rad = math.radians(h)
            r.x, r.y, r.speed, r.heading, r.sigma, r.mode, r.t = x, y, v, h, msg.sigma_m, msg.mode, msg.t
            r.vx, r.vy = v * math.sin(rad), v * math.cos(rad)   # compass heading: 0 north, 90 east
            r.n += 1
            if msg.mode != "moving":
                r.paused_t = msg.t
            self.dirty.add(sender)
            return None
        if k is UvSighting:
            if msg.robot not in self.robots:
                raise KeyError(f"sighting by unknown robot {msg.robot!r}")
            x, y = self.to_xy(msg.lon, msg.lat)
            if msg.robot != self.owner and not self.hears_all:
                s = self.robots[msg.robot]
                # judged by where the sender last was (a sender never heard is out of range),
                # and the sighting itself no farther than the sender could see from our range
                # (a sender that left our range since its last state we heard is not heard;
                # dissemination subscribes to comm + sensor range, see UvDomain.needs)
                if s.t == NEG or not self._in_range(msg.robot, s.x, s.y) or \
                        not self._in_range(msg.robot, x, y, s.sensor_range):
                    self.dropped += 1
                    return None
            self._sighting(msg, x, y)
            return None
        if k is UvAgent:
            if not self.hears_all and msg.sender != self.owner and msg.to != self.owner:
                self.dropped += 1   # a robot's EA hears only its own conversations (as subscribed)
                return None
            if msg.sender not in self.units or msg.to not in self.units:
                raise KeyError(f"agent message names unknown unit {msg.sender if msg.sender not in self.units else msg.to!r}")
            return msg
        raise ValueError(f"not a UV message: {k.__name__}")

    def _sighting(self, msg: UvSighting, x: float, y: float) -> None:
        tg = self.targets.get(msg.target)
        if tg is None:
            tg = self.targets[msg.target] = Target(msg.target)
        if msg.t >= tg.t:
            tg.t, tg.x, tg.y, tg.by, tg.sigma = msg.t, x, y, msg.robot, msg.sigma_m
        mine = self.own.get((msg.robot, msg.target))
        if mine is None or msg.t >= mine[0]:
            self.own[(msg.robot, msg.target)] = (msg.t, x, y, msg.lon, msg.lat)
        obs = (("*" if self.human else msg.robot), msg.target)
        last = self.seen.get(obs, NEG)
        if msg.t - last >= self.reacquire_s:   # first sighting, or again after being lost
            n = self.n_acq[obs] = self.n_acq.get(obs, 0) + 1
            self.acquired.append((msg.t, msg.robot, msg.target, n))
        if msg.t > last:
            self.seen[obs] = msg.t
        self.dirty_targets.add(msg.target)
