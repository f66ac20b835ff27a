"""The event generator standing in for SAIM: publishes a scenario's scripted events
into the mesh, and serves the situation store (the ordered log of everything
published so far) to peers that join late.

Every event carries a sequence number (Zenoh attachment). After every 2 s of
scenario time a clock tick says "everything up to seq N has been sent": one
publisher session and one priority keep Zenoh's delivery in order, so a peer that
sees the tick has every earlier message in its channels.
"""
from __future__ import annotations

import sys
import time
from bisect import bisect_right
from collections import Counter

import msgpack
import numpy as np
import zenoh

from dissemination.keyspace import KeySpace, matcher

from . import messages as M
from .scenario import Scenario

BLOCK = zenoh.CongestionControl.BLOCK
STORE_PRIORITY = zenoh.Priority.INTERACTIVE_HIGH


def seq_bytes(seq: int) -> bytes:
    return seq.to_bytes(8, "big")


class Replay:
    def __init__(self, sc: Scenario, conf: zenoh.Config, root: str, speed: float | None = None,
                 wait_peers: list[str] = (), tick_s: float = 2.0, wait_timeout: float = 60.0,
                 linger_s: float = 30.0, log=print, until: float | None = None, window_s: float = 20.0):
        groups = sc.meta.get("fusion", {}).get("groups", {})
        self.sc, self.conf = sc, conf
        self.ks = KeySpace(root, {sid: g for g, sids in groups.items() for sid in sids})
        self.speed, self.wait_peers, self.tick_s = speed, list(wait_peers), tick_s
        self.wait_timeout, self.linger_s, self.log = wait_timeout, linger_s, log
        self.entries: list[tuple[int, bytes]] = []
        self.by_key: dict[str, list[int]] = {}   # key -> its seqs: queries test each key once
        self.t = 0.0
        self.n_ticks = 0
        self.until = until
        self.window_s = window_s if speed is None else 0.0   # pacing only at max speed

    def _serve(self, q) -> None:
        """Answer store queries: entries after `since` whose key matches one of `keys`
        (all when keys is None), and the scenario time the log has reached."""
        while (query := q.try_recv()) is not None:
            req = msgpack.unpackb(query.payload.to_bytes()) if query.payload is not None else {}
            since, keys = int(req.get("since", 0)), req.get("keys")
            if keys is None:
                entries = self.entries[since:]
            else:
                match = matcher(keys)
                seqs = sorted(n for k, ns in self.by_key.items() if match(k) for n in ns[bisect_right(ns, since):])
                entries = [self.entries[n - 1] for n in seqs]
            query.reply(self.ks.store(), msgpack.packb({"t": self.t, "entries": entries}, use_bin_type=True),
                        priority=STORE_PRIORITY)   # overtakes the data queued ahead of it (dupes are dropped by seq)
            del query   # a query kept alive makes the asker wait out its timeout

    def _present(self, s) -> Counter:
        """Live peers per unit (two peers may run one unit's EA)."""
        units: Counter = Counter()
        for r in s.liveliness().get(self.ks.alive("*", "*"), timeout=2.0):
            if r.ok is not None:
                units[str(r.ok.key_expr).split("/")[-2]] += 1
        return units

    def _missing(self, s) -> list[str]:
        return sorted((Counter(self.wait_peers) - self._present(s)).elements())

    def _tick(self, s, t: float, end: bool = False) -> None:
        self.t = t
        self.n_ticks += 1
        s.put(self.ks.clock(), msgpack.packb({"t": t, "n": self.n_ticks, "seq": len(self.entries), "end": end,
                                              "w": time.time()}),
              congestion_control=BLOCK)

    def _prepare(self, end_t: float) -> list[tuple[object, str, bytes]]:
        """Keys and payloads for the whole script, before the clock starts: one bulk
        projection, and the task organization as it will be at each event's time."""
        sc = self.sc
        evs = [e for e in sc.events if e.t <= end_t]
        lon = np.array([getattr(e, "lon", 0.0) for e in evs])
        lat = np.array([getattr(e, "lat", 0.0) for e in evs])
        xs, ys = sc.projection.to_xy(lon, lat)
        to = sc.taskorg.copy()
        reorgs = sorted((m.start.t, m.params["subject"], m.params["new_parent"]) for m in sc.plan.missions
                        if m.type == "reorganize" and m.start.t is not None)
        out = []
        for ev, x, y in zip(evs, xs.tolist(), ys.tolist()):
            while reorgs and reorgs[0][0] <= ev.t:
                _, unit, parent = reorgs.pop(0)
                to.resubordinate(unit, parent)
            if type(ev) is M.Reorganization:
                to.resubordinate(ev.unit, ev.new_parent)
            out.append((ev, self.ks.key(ev, to, sc.projection, (x, y)), M.encode(ev)))
        return out

    def run(self) -> dict:
        sc = self.sc
        end_t = sc.duration_s if self.until is None else min(self.until, sc.duration_s)
        script = self._prepare(end_t)
        with zenoh.open(self.conf) as s:
            q = s.declare_queryable(self.ks.store(), zenoh.handlers.FifoChannel(64))
            # one declared publisher per key: a put then skips parsing and resolving the key
            pubs = {k: s.declare_publisher(k, congestion_control=BLOCK) for k in sorted({k for _, k, _ in script})}
            self.log(f"ready {s.info.zid()}", flush=True)
            deadline = time.monotonic() + self.wait_timeout
            while self.wait_peers and (missing := self._missing(s)):
                self._serve(q)
                if time.monotonic() > deadline:
                    raise TimeoutError(f"peers never came: {missing}")
            pacer = (Pacer(s, self.ks, set(sc.taskorg.units), self.window_s, lambda: self._serve(q), self.log)
                     if self.window_s > 0 else None)
            self.log("start", flush=True)
            t0 = time.monotonic()
            next_tick = self.tick_s
            for ev, key, payload in script:
                while ev.t >= next_tick:
                    if pacer:
                        pacer.wait(next_tick)
                    self._tick(s, next_tick)
                    self._serve(q)
                    if int(next_tick) % 100 == 0 and next_tick == int(next_tick):
                        self.log(f"t={next_tick:.0f}", flush=True)
                    next_tick += self.tick_s
                if self.speed:
                    while (wait := t0 + ev.t / self.speed - time.monotonic()) > 0:
                        self._serve(q)
                        time.sleep(min(wait, 0.005))
                self.entries.append((len(self.entries) + 1, payload))
                self.by_key.setdefault(key, []).append(len(self.entries))
                pubs[key].put(payload, attachment=seq_bytes(len(self.entries)))
            self._tick(s, end_t, end=True)
            self.log(f"end events={len(self.entries)} wall_s={time.monotonic() - t0:.2f}", flush=True)
            linger = time.monotonic() + self.linger_s   # keep serving the store while peers finish
            while time.monotonic() < linger and set(self._present(s)) & set(self.wait_peers or ["?"]):
                look = time.monotonic() + 0.5          # answer queries promptly, ask who is there less often
                while time.monotonic() < look:
                    self._serve(q)
                    time.sleep(0.002)
            return {"events": len(self.entries), "wall_s": time.monotonic() - t0}


class Pacer:
    """At max speed, keep the replay at most `window_s` of scenario time ahead of the
    slowest EA peer. Without it the replay runs far ahead: tens of thousands of messages
    sit in flight, a catch-up answer queues behind them, and peers' memory fills up.

    EA peers (liveliness tokens of task-organization units; fusion nodes do not count)
    are waited for from the moment they appear until they report progress
    (`ack/<zid>`), and stop counting when their token goes or when they make no
    progress for `stall_s` of wall time."""

    def __init__(self, s, ks: KeySpace, units: set[str], window_s: float, serve, log, stall_s: float = 30.0):
        self.units, self.window_s, self.serve, self.log, self.stall_s = units, window_s, serve, log, stall_s
        self.acks = s.declare_subscriber(ks.ack("*"), zenoh.handlers.FifoChannel(100_000))
        self.alive = s.liveliness().declare_subscriber(ks.alive("*", "*"), zenoh.handlers.FifoChannel(1024),
                                                       history=True)
        self.live: set[str] = set()          # EA peers' zids
        for r in s.liveliness().get(ks.alive("*", "*"), timeout=2.0):   # those here now, for sure
            if r.ok is not None and str(r.ok.key_expr).split("/")[-2] in units:
                self.live.add(str(r.ok.key_expr).split("/")[-1])
        self.done: dict[str, float] = {}     # zid -> last tick it processed
        self.moved = {z: time.monotonic() for z in self.live}   # zid -> wall time of its last progress
        self.ignored: set[str] = set()

    def _take(self) -> None:
        while (a := self.alive.try_recv()) is not None:
            unit, zid = str(a.key_expr).split("/")[-2:]
            if unit not in self.units:
                continue
            if a.kind == zenoh.SampleKind.PUT:
                self.live.add(zid)
                self.moved.setdefault(zid, time.monotonic())
            else:
                self.live.discard(zid)
        while (a := self.acks.try_recv()) is not None:
            zid = str(a.key_expr).split("/")[-1]
            self.done[zid] = max(self.done.get(zid, -1.0), msgpack.unpackb(a.payload.to_bytes()))
            self.moved[zid] = time.monotonic()

    def wait(self, t: float) -> None:
        need = t - self.window_s
        while True:
            self._take()
            behind = [z for z in self.live - self.ignored if self.done.get(z, -1.0) < need]
            if not behind:
                return
            now = time.monotonic()
            for z in behind:
                if now - self.moved[z] > self.stall_s:
                    self.log(f"pacing: peer {z} made no progress for {self.stall_s:.0f} s; not waiting for it",
                             flush=True)
                    self.ignored.add(z)
            self.serve()
            time.sleep(0.0005)   # a peer's next ack is at most one of its ticks away


def main_replay(sc: Scenario, conf, root: str, speed, wait_peers, linger_s: float, until=None,
                window_s: float = 20.0) -> int:
    Replay(sc, conf, root, speed, wait_peers, linger_s=linger_s, until=until, window_s=window_s,
           log=lambda *a, **k: print(*a, **k, file=sys.stdout)).run()
    return 0
