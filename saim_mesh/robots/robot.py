"""One robot's process: its simulator (`ea_agent.domains.uv.sim.RobotSim`, no policy in it)
stepped in event time, its reports published as a live source, its EA's task frames
taken (signature checked, in sequence) and carried out at their `at`.

Determinism: step i (t_i) runs only once the EA's task stream promised t_i (its
watermark), so every task due by t_i is in hand; the robot never races its EA on the wall
clock. A frame that fails its check (a forged or misplaced signature, a bad struct) is
refused and counted, and the robot goes on waiting for its EA's own frames."""
from __future__ import annotations

import json
import math
import queue
import signal
import time
from pathlib import Path

import zenoh
import zenoh.ext as zx

from dissemination.keyspace import KeySpace
from ea_agent.core.messages import from_dict
from ea_agent.domains.uv import generator as G
from ea_agent.domains.uv import tasks as T

from ..live.source import LiveSource
from . import wire

CACHE = 100_000


class TaskInbox:
    """The EA's task frames, in their sequence: tasks due, and how far the EA promised."""

    def __init__(self, robot: str, root: str, ver, log=print):
        self.robot, self.key, self.ver, self.log = robot, wire.task_key(root, robot), ver, log
        self.epoch: int | None = None
        self.next_seq = 1
        self.held: dict[int, T.TaskFrame] = {}
        self.wm = -math.inf
        self.tasks: list = []
        self.refused: dict[str, int] = {}
        self.ended = False

    def take(self, key: str, payload: bytes) -> None:
        try:
            f = wire.open_frame(self.ver, key, payload, self.robot)
        except ValueError as e:
            why = str(e)[:160]
            self.refused[why] = self.refused.get(why, 0) + 1
            if self.refused[why] == 1:
                self.log(f"refused a task frame: {why}", flush=True)
            return
        if self.epoch is None or f.epoch > self.epoch:   # the EA (re)started: its seq starts at 1
            self.epoch, self.next_seq, self.held = f.epoch, 1, {}
        if f.epoch < self.epoch or f.seq < self.next_seq:
            return
        self.held[f.seq] = f
        while self.next_seq in self.held:
            g = self.held.pop(self.next_seq)
            self.next_seq += 1
            self.tasks += g.tasks
            self.wm = max(self.wm, g.wm)
            self.ended = self.ended or g.end

    def due(self, t: float) -> list:
        out = [x for x in self.tasks if x.at <= t]
        self.tasks = [x for x in self.tasks if x.at > t]
        return out


def run(robot: str, conf: zenoh.Config, root: str, keys: Path, out: Path, seed: int = 7,
        until: float | None = None, deadline_s: float = 600.0, log=print, linger: bool = True) -> dict:
    sim = G.robots(seed, only=[robot])[robot]
    ids = [u["id"] for u in G.UNITS if u["kind"] in ("ugv", "uav")]
    inbox = TaskInbox(robot, root, wire.verifier(keys, root, ids), log)
    q: queue.SimpleQueue = queue.SimpleQueue()
    end_t = sim.duration if until is None else min(until, sim.duration)
    steps = [(i, float(t)) for i, t in enumerate(sim.times) if t <= end_t + 1e-9]
    sent: list[dict] = []
    stop_wall = time.monotonic() + deadline_s
    with zenoh.open(conf) as s:
        src = LiveSource(s, KeySpace(root), robot, cache=CACHE)
        sub = zx.declare_advanced_subscriber(
            s, inbox.key, lambda smp: q.put((str(smp.key_expr), smp.payload.to_bytes())),
            history=zx.HistoryConfig(detect_late_publishers=True, max_samples=CACHE),
            recovery=zx.RecoveryConfig(heartbeat=True), subscriber_detection=True)
        log(f"ready robot {robot}", flush=True)

        def wait_until(cond) -> None:
            while not cond():
                left = stop_wall - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f"robot {robot}: its EA promised only {inbox.wm} (deadline)")
                try:
                    inbox.take(*q.get(timeout=min(left, 1.0)))
                except queue.Empty:
                    pass
        for i, t in steps:
            wait_until(lambda: inbox.wm >= t)
            evs = sim.step(i, inbox.due(t))
            for d in evs:
                src.put(from_dict(d))
            sent += evs
            src.watermark(t)
            if i % 200 == 0:
                log(f"robot {robot} t={t:.0f} ea_wm={inbox.wm}", flush=True)
        src.close(end=True)
        record = {**sim.record(), "events": sent, "refused": inbox.refused}
        Path(out).write_text(json.dumps(record))
        summary = {"robot": robot, "steps": len(steps), "events": len(sent), "tasks_taken": len(sim.taken),
                   "refused": sum(inbox.refused.values()), "commits": sum(e["what"] == "commit" for e in sim.log)}
        log("done " + json.dumps(summary), flush=True)
        wait_until(lambda: inbox.ended)   # our EA has our last frame
        log("summary " + json.dumps(summary), flush=True)
        if linger:   # the other EAs may still recover frames from our cache: the driver stops us
            signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM, signal.SIGINT})
            signal.sigwait({signal.SIGTERM, signal.SIGINT})
        sub.undeclare()
        src.stop()
    return summary


def main(a) -> int:
    from .cli import session_config
    conf = session_config(a, f"robot.{a.robot}")
    run(a.robot, conf, a.root, Path(a.keys or a.pki), Path(a.out), a.seed, a.until, a.deadline)
    return 0
