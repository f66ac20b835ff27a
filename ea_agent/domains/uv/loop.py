"""The robot team in closed loop, in one process: every robot's simulator obeys the tasks
its own EA publishes, every EA monitors what the robots report (issue 33.5).

The schedule is the one the mesh keeps with watermarks (`saim_mesh/robots`), so both give
the same run: at step i (event time t_i = i x DT) each robot takes the tasks due by t_i,
steps and reports; every EA takes the step's reports in (t, robot, emission) order (the
live order of sources named by robot id) and is advanced to t_i; the tasks it decided
are due at the end of their epoch + `tasks.LAG_S`, so at t_(i+1) at the earliest: a
robot's step i+1 waits only for its EA to have reached t_i.

    loop = ClosedLoop(robots, eas); loop.run()
"""
from __future__ import annotations

from typing import Callable, Iterable

from ea_agent.core.messages import from_dict

from .sim import RobotSim


class ClosedLoop:
    """`robots`: id -> RobotSim; `eas`: the EAs to run (an EA whose owner is a robot
    commands that robot, unless the robot is in `unheard`: its tasks are dropped)."""

    def __init__(self, robots: dict[str, RobotSim], eas: Iterable, unheard: Iterable[str] = (),
                 on_step: Callable[[int, float, list], None] | None = None):
        self.robots = dict(sorted(robots.items()))
        self.eas = list(eas)
        self.unheard = set(unheard)
        self.pending: dict[str, list] = {r: [] for r in self.robots}
        self.events: list[dict] = []
        self.on_step = on_step
        self.tasks: list = []         # every task published, in order
        self.drained: list[tuple[float, str, object]] = []   # (EA's time when published, owner, task)

    def step(self, i: int, t: float) -> list[dict]:
        evs: list[dict] = []
        for rid, robot in self.robots.items():
            due = [x for x in self.pending[rid] if x.at <= t]
            self.pending[rid] = [x for x in self.pending[rid] if x.at > t]
            evs += robot.step(i, due)
        msgs = [from_dict(d) for d in evs]
        for ea in self.eas:
            for m in msgs:
                ea.submit(m)
            ea.advance(t)
            got = ea.domain.policies.drain()
            self.tasks += got
            self.drained += [(t, ea.owner, x) for x in got]
            if ea.owner in self.pending and ea.owner not in self.unheard:
                self.pending[ea.owner] += got
        return evs

    def run(self) -> "ClosedLoop":
        first = next(iter(self.robots.values()))
        for ea in self.eas:
            ea.start(0.0)
        for i, t in enumerate(first.times):
            evs = self.step(i, float(t))
            self.events += evs
            if self.on_step is not None:
                self.on_step(i, float(t), evs)
        for ea in self.eas:
            ea.finish(first.duration)
        return self
