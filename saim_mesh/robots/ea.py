"""One EA's process in the robots' closed loop: it takes every robot's reports in event-time
order (`live.order.EventTimeOrder` over the robots' sources), advances the EA as far as all
of them promised, and, when it is a robot's own EA, publishes the tasks its policies
decided for that robot, signed, with the promise that no task due at or before
(released time + LAG_S) will follow.

Why its own loop and not `live.peer.LivePeer`: the peer takes only the battle domain's
data kinds from a source's frame and has no outbox for an EA's decisions (a hook named
in docs/uv-domain.md). The order, the frames and the source code are the live mesh's.

`mute`: publish the watermarks and no task (an EA whose commands are lost); `forge`:
also publish each task it decided signed as another identity, over a session of that
identity in secure mode (the access control drops it), else over ours (the robot refuses
the signature)."""
from __future__ import annotations

import json
import math
import queue
import signal
import time
from pathlib import Path

import zenoh
import zenoh.ext as zx

from ea_agent.domains.uv import tasks as T

from ..protocol import messages as M
from .. import scenario as S
from ..protocol import gate as G
from ..live import frames as F
from ..live.order import EventTimeOrder
from ..live.source import next_epoch
from ..inprocess.runner import config_for, make_ea
from . import wire

BLOCK = zenoh.CongestionControl.BLOCK
CACHE = 100_000


class Streams:
    """Each robot's frames taken in their own sequence (held until the missing ones come)."""

    def __init__(self, root: str, robots: list[str], order: EventTimeOrder, gate: G.Gate):
        self.root, self.order, self.gate = root, order, gate
        self.seq: dict[str, list[int]] = {}
        self.held: dict[str, dict[int, F.Frame]] = {r: {} for r in robots}
        self.frames = 0

    def take(self, key: str, payload: bytes) -> None:
        try:
            f = F.decode(payload, wire.MAX_BYTES)
        except M.MessageError as e:
            self.gate.rejects.add(e, key)
            return
        if f.source not in self.held or key != wire.src_key(self.root, f.source):
            self.gate.rejects.add(M.MessageError("frame", "source", f"frame of {f.source!r} on {key[:80]}"), key)
            return
        st = self.seq.get(f.source)
        if st is None or f.epoch > st[0]:
            st = self.seq[f.source] = [f.epoch, 1]
            self.held[f.source] = {}
        if f.epoch < st[0] or f.seq < st[1]:
            return
        held = self.held[f.source]
        held[f.seq] = f
        while st[1] in held:
            g = held.pop(st[1])
            st[1] += 1
            items = [m for b in g.msgs if (m := self.gate.data(b, key)) is not None]
            self.order.take(g.source, g.epoch, g.seq, g.wm, items, g.end)
            self.frames += 1


class _Same:
    """The session itself, as a context that does not close it."""

    def __init__(self, s):
        self.s = s

    def __enter__(self):
        return self.s

    def __exit__(self, *exc) -> None:
        return None


def run(scenario: Path, unit: str, conf: zenoh.Config, root: str, robots: list[str], out: Path,
        keys: Path | None = None, until: float | None = None, mute: bool = False, forge: str | None = None,
        deadline_s: float = 600.0, log=print, linger: bool = True, forge_conf: zenoh.Config | None = None) -> dict:
    sc = S.load(scenario, events=False)
    end_t = sc.duration_s if until is None else min(until, sc.duration_s)
    alerts: list[dict] = []
    ea = make_ea(sc, unit, config_for(sc, unit), sinks=[lambda a: alerts.append(a.to_json_dict())])
    ea.start(0.0)
    order: EventTimeOrder = EventTimeOrder(robots)
    gate = G.Gate(sc.duration_s, wire.MAX_BYTES, log=log)
    streams = Streams(root, robots, order, gate)
    commands = unit in robots
    sig = wire.signer(keys, f"ea.{unit}") if commands else None
    forger = wire.signer(keys, forge) if commands and forge else None
    tkey = wire.task_key(root, unit)
    epoch = next_epoch(None, unit)
    seq = 0
    decided: list = []
    q: queue.SimpleQueue = queue.SimpleQueue()
    stop_wall = time.monotonic() + deadline_s
    forged = 0
    with zenoh.open(conf) as s, (zenoh.open(forge_conf) if forger is not None and forge_conf is not None
                                 else _Same(s)) as fs:
        pub = zx.declare_advanced_publisher(
            s, tkey, congestion_control=BLOCK, cache=zx.CacheConfig(max_samples=CACHE),
            sample_miss_detection=zx.MissDetectionConfig(heartbeat=0.5), publisher_detection=True) \
            if commands else None

        def publish(tasks: list, wm: float, end: bool = False) -> None:
            nonlocal seq, forged
            if pub is None:
                return
            seq += 1
            f = T.TaskFrame(v=1, robot=unit, epoch=epoch, seq=seq, wm=wm, tasks=[] if mute else tasks, end=end)
            pub.put(wire.seal(sig, tkey, f))
            if forger is not None and tasks:   # someone else ordering our robot: its own session in secure mode
                fs.put(tkey, wire.seal(forger, tkey, T.TaskFrame(v=1, robot=unit, epoch=epoch, seq=seq, wm=wm,
                                                                  tasks=tasks)), congestion_control=BLOCK)
                forged += 1

        subs = [zx.declare_advanced_subscriber(
            s, wire.src_key(root, r), lambda smp: q.put((str(smp.key_expr), smp.payload.to_bytes())),
            history=zx.HistoryConfig(detect_late_publishers=True, max_samples=CACHE),
            recovery=zx.RecoveryConfig(heartbeat=True), subscriber_detection=True) for r in robots]
        publish([], T.LAG_S)   # nothing can be decided before the first epoch closes
        log(f"ready ea {unit} robots={','.join(robots)}", flush=True)
        advanced = -math.inf
        gave_up = False
        while advanced < end_t:
            left = stop_wall - time.monotonic()
            if left <= 0:   # no loss decision in this loop: say so, and keep what was monitored
                log(f"EA {unit}: deadline: the robots promised only {order.bound()}", flush=True)
                gave_up = True
                break
            try:
                streams.take(*q.get(timeout=min(left, 1.0)))
            except queue.Empty:
                continue
            b = min(order.bound(), end_t)
            if b <= advanced:
                continue
            for m in order.release(b):
                ea.submit(m)
            ea.advance(b)
            advanced = b
            tasks = ea.domain.policies.drain()
            decided += tasks
            publish(tasks, b + T.LAG_S)
        fin = end_t if not gave_up else max(advanced, 0.0)
        ea.finish(fin)
        tail = ea.domain.policies.drain()   # decided at the very end: due after the run
        decided += tail
        publish(tail, fin + T.LAG_S, end=True)
        Path(out).write_text("".join(json.dumps(a) + "\n" for a in alerts))
        summary = {"unit": unit, "alerts": len(alerts), "tasks": len(decided),
                   "published": 0 if mute else len(decided), "forged": forged, "frames": streams.frames,
                   "rejects": dict(gate.rejects.by_kind), "released": advanced, "gave_up": gave_up,
                   # states of teammates beyond its comm range, not heard (the robots' radios)
                   "out_of_range": getattr(getattr(ea.domain, "watchman", None), "dropped", 0)}
        log("summary " + json.dumps(summary), flush=True)
        if linger:   # our last frame may still be recovered from our cache: the driver stops us
            signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM, signal.SIGINT})
            signal.sigwait({signal.SIGTERM, signal.SIGINT})
        for x in subs:
            x.undeclare()
        if pub is not None:
            pub.undeclare()
    return summary


def main(a) -> int:
    from .cli import session_config
    conf = session_config(a, f"ea.{a.unit}")
    forge_conf = session_config(a, a.forge) if a.forge and a.pki else None   # the forger's own identity
    keys = a.keys or a.pki
    run(Path(a.scenario), a.unit, conf, a.root, a.robots, Path(a.out), Path(keys) if keys else None, a.until,
        a.mute, a.forge, a.deadline, forge_conf=forge_conf)
    return 0
