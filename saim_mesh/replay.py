"""The event generator standing in for SAIM: publishes a scenario's scripted events
into the mesh, and serves the situation store (the ordered log of everything
published so far) to peers that join late.

Every event carries a sequence number (Zenoh attachment). After every 2 s of
scenario time a clock tick says "everything up to seq N has been sent": one
publisher session and one priority keep Zenoh's delivery in order, so a peer that
sees the tick has every earlier message in its channels.
"""
from __future__ import annotations

import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path
from bisect import bisect_right
from collections import Counter

import numpy as np
import zenoh

from dissemination.keyspace import KeySpace, matcher

from ea_agent import domains

from . import messages as M
from . import wire as W
from .batch import Batcher, groups_of
from .radios import Radios
from .store import KeyIndex, Log
from .scenario import Scenario

BLOCK = zenoh.CongestionControl.BLOCK
STORE_PRIORITY = zenoh.Priority.INTERACTIVE_HIGH


def seq_bytes(seq: int) -> bytes:
    return seq.to_bytes(8, "big")


class Replay:
    def __init__(self, sc: Scenario, conf: zenoh.Config, root: str, speed: float | None = None,
                 wait_peers: list[str] = (), wait_timeout: float = 60.0,
                 linger_s: float = 30.0, log=print, until: float | None = None, window_s: float = 20.0,
                 state_path: str | Path | None = None, max_bytes: int = 65536):
        self.sc, self.conf = sc, conf
        self.ks = KeySpace.of(sc, root)
        self.speed, self.wait_peers = speed, list(wait_peers)
        self.tick_s = W.TICK_S   # peers check that tick n is at n x TICK_S
        self.wait_timeout, self.linger_s, self.log = wait_timeout, linger_s, log
        self.entries = Log()        # (seq, payload) of everything published, in a file (store.py)
        self.by_key = KeyIndex()    # key -> its seqs: queries test each key once
        self.t = 0.0
        self.n_ticks = 0
        self.until = until
        self.window_s = window_s if speed is None else 0.0   # pacing only at max speed
        self.gate = W.Gate(sc.duration_s, max_bytes, log=log)
        self.fusion_t: dict[str, float] = {}   # group -> clock time its tracks are out to
        self.state_path = Path(state_path) if state_path else None
        self.resumed_from: dict | None = None
        self.ingested = 0   # live reports taken in from ingest/** (a TAK gateway)
        self.entity_unit = {e: u.id for u in sc.taskorg.units.values() for e in u.entities}
        self.batcher: Batcher | None = None   # batched families go out per group and tick (batch.py)

    def _serve(self, q) -> None:
        """Answer store queries: entries after `since` whose key matches one of `keys`
        (all when keys is None), the scenario time the log has reached and how far each
        fusion node's tracks are out. A malformed query is counted and answered with nothing."""
        while (query := q.try_recv()) is not None:
            req = self.gate.control(W.StoreQuery, query.payload.to_bytes() if query.payload is not None
                                    else W.encode(W.make(W.StoreQuery)), self.ks.store())
            if req is not None:
                try:
                    entries = self._entries(req)
                except ValueError as e:   # a key expression Zenoh will not parse
                    self.gate.rejects.add(M.MessageError("storequery", "keys", str(e)[:160]), self.ks.store())
                    entries = None
                if entries is not None:
                    query.reply(self.ks.store(), W.encode(W.make(W.StoreReply, t=self.t, entries=entries,
                                                                       fusion=dict(self.fusion_t))),
                                priority=STORE_PRIORITY)   # overtakes the data queued ahead of it
            del query   # a query kept alive makes the asker wait out its timeout

    def _entries(self, req: W.StoreQuery) -> list[tuple[int, bytes]]:
        if req.keys is None:
            return self.entries[req.since:]
        match = matcher(req.keys)
        seqs = sorted(n for k, ns in self.by_key.items() if match(k) for n in ns[bisect_right(ns, req.since):])
        return [self.entries[n - 1] for n in seqs]

    def _take_fusion_ticks(self, sub) -> None:
        """Remember how far each fusion node's tracks are out: a restarted node resumes there."""
        while (smp := sub.try_recv()) is not None:
            key = str(smp.key_expr)
            ft = self.gate.control(W.FusionTick, smp.payload.to_bytes(), key)
            if ft is not None:
                g = self.ks.last(key)[0]
                self.fusion_t[g] = max(self.fusion_t.get(g, -1.0), ft.t)

    def _present(self, s) -> Counter:
        """Live peers per unit (two peers may run one unit's EA)."""
        units: Counter = Counter()
        for r in s.liveliness().get(self.ks.alive("*", "*"), timeout=2.0):
            if r.ok is not None:
                units[self.ks.last(str(r.ok.key_expr), 2)[0]] += 1
        return units

    def _missing(self, s) -> list[str]:
        return sorted((Counter(self.wait_peers) - self._present(s)).elements())

    def _tick(self, s, t: float, end: bool = False) -> None:
        self.t = t
        self.n_ticks += 1
        tick = W.make(W.Tick, t=t, n=self.n_ticks, seq=len(self.entries), end=end, w=time.time())
        s.put(self.ks.clock(), W.encode(tick),
              congestion_control=BLOCK)
        if self.state_path is not None:   # where a restarted replay resumes
            tmp = self.state_path.with_suffix(".tmp")
            tmp.write_text(json.dumps({"n": self.n_ticks, "t": t, "seq": len(self.entries),
                                       "fusion": self.fusion_t}))
            os.replace(tmp, self.state_path)

    def _ingest(self, s, sub, now: float) -> None:
        """Live reports from the TAK gateway (ingest/tak), into the ordered stream at
        scenario time `now`: checked, only friendly positions of known entities, keyed
        and stored like a scripted event (so a replay of the store is the same run)."""
        while (smp := sub.try_recv()) is not None:
            key = str(smp.key_expr)
            m = self.gate.data(smp.payload.to_bytes(), key)
            if m is None:
                continue
            why = (f"{m.KIND} is not taken from {key}" if key != self.ks.ingest("tak") or type(m) is not M.LocationReport
                   else None if m.entity in self.entity_unit else f"unknown entity {m.entity!r}")
            if why is not None:
                self.gate.rejects.add(M.MessageError(m.KIND, "entity" if "entity" in why else "(key)", why), key)
                continue
            m = replace(m, t=now)
            x, y = self.sc.projection.to_xy(m.lon, m.lat)
            k = self.ks.key(m, self.sc.taskorg, self.sc.projection, (float(x), float(y)))
            self.entries.append((len(self.entries) + 1, M.encode(m)))
            self.by_key.setdefault(k, []).append(len(self.entries))
            if self.batcher is None or not self.batcher.add(k, len(self.entries), self.entries[-1][1]):
                s.put(k, self.entries[-1][1], attachment=seq_bytes(len(self.entries)), congestion_control=BLOCK)
            self.ingested += 1

    def _prepare(self, end_t: float) -> list[tuple[object, str, bytes]]:
        """Keys and payloads for the whole script, before the clock starts: one bulk
        projection, and the task organization as it will be at each event's time."""
        sc = self.sc
        evs = [e for e in sc.events if e.t <= end_t]
        lon = np.array([getattr(e, "lon", 0.0) for e in evs])
        lat = np.array([getattr(e, "lat", 0.0) for e in evs])
        xs, ys = sc.projection.to_xy(lon, lat)
        to = sc.taskorg.copy()
        planned = getattr(domains.of(sc), "org_changes", None)   # a domain with a changing hierarchy
        reorgs = planned(sc) if planned else []
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
        start = self._resume(script)
        with zenoh.open(self.conf) as s:
            q = s.declare_queryable(self.ks.store(), zenoh.handlers.FifoChannel(64))
            fticks = s.declare_subscriber(self.ks.fusion_tick("*"), zenoh.handlers.FifoChannel(100_000))
            ingest = s.declare_subscriber(self.ks.ingest("*"), zenoh.handlers.FifoChannel(10_000))
            serve = lambda: (self._take_fusion_ticks(fticks), self._serve(q))
            # one declared publisher per key: a put then skips parsing and resolving the key
            self.batcher = batcher = Batcher(s, groups_of(self.ks.root), self.gate.max_bytes)
            pubs = {k: s.declare_publisher(k, congestion_control=BLOCK) for k in sorted({k for _, k, _ in script})
                    if batcher.groups.group(k) is None}
            self.log(f"ready {s.info.zid()}", flush=True)
            deadline = time.monotonic() + self.wait_timeout
            while self.wait_peers and (missing := self._missing(s)):
                serve()
                if time.monotonic() > deadline:
                    raise TimeoutError(f"peers never came: {missing}")
            pacer = (Pacer(s, self.ks, self.window_s, serve, self.log, self.gate) if self.window_s > 0 else None)
            source_of = getattr(domains.of(sc), "source_of", None)   # robots send their own state
            radios = Radios(s, self.ks, source_of, self.log) if source_of else None
            self.log("start" + (f" resumed n={self.n_ticks} t={self.t:.0f}" if self.resumed_from else ""), flush=True)
            t0 = time.monotonic() - (self.t / self.speed if self.speed else 0.0)
            next_tick = self.t + self.tick_s
            for ev, key, payload in script[start:]:
                while ev.t >= next_tick:
                    batcher.flush()
                    if pacer:
                        pacer.wait(next_tick)
                    self._tick(s, next_tick)
                    serve()
                    if int(next_tick) % 100 == 0 and next_tick == int(next_tick):
                        self.log(f"t={next_tick:.0f}", flush=True)
                    next_tick += self.tick_s
                if self.speed:
                    while (wait := t0 + ev.t / self.speed - time.monotonic()) > 0:
                        serve()
                        self._ingest(s, ingest, self.t)   # a live report while the script is quiet
                        time.sleep(min(wait, 0.005))
                self._ingest(s, ingest, max(self.t, min(ev.t, next_tick)))
                if radios is not None and radios.silent(ev):
                    continue
                self.entries.append((len(self.entries) + 1, payload))
                self.by_key.setdefault(key, []).append(len(self.entries))
                if not batcher.add(key, len(self.entries), payload):
                    pubs[key].put(payload, attachment=seq_bytes(len(self.entries)))
            batcher.flush()
            self._tick(s, end_t, end=True)
            self.log(f"end events={len(self.entries)} wall_s={time.monotonic() - t0:.2f}", flush=True)
            linger = time.monotonic() + self.linger_s   # keep serving the store while peers finish
            while time.monotonic() < linger and set(self._present(s)) & set(self.wait_peers or ["?"]):
                look = time.monotonic() + 0.5          # answer queries promptly, ask who is there less often
                while time.monotonic() < look:
                    serve()
                    time.sleep(0.002)
            return {"events": len(self.entries), "wall_s": time.monotonic() - t0, "rejects": self.gate.errors,
                    "batches": batcher.sent, "batched": batcher.entries,
                    "store_index_bytes": self.entries.nbytes + self.by_key.nbytes,
                    "ingested": self.ingested,
                    "silenced": radios.silenced if radios else 0}

    def _resume(self, script) -> int:
        """After a crash, take up where the last tick left off: the log up to its seq is
        rebuilt without publishing (peers have it), and the clock goes on from its tick.
        Returns the index of the first event still to publish."""
        if self.state_path is None or not self.state_path.exists():
            return 0
        try:
            st = json.loads(self.state_path.read_text())
            n, t, seq = int(st["n"]), float(st["t"]), int(st["seq"])
            fusion = {str(g): float(v) for g, v in dict(st.get("fusion", {})).items()}
        except (ValueError, KeyError, TypeError) as e:
            raise ValueError(f"{self.state_path}: unreadable replay state ({e}); remove it to start over") from None
        if not (0 <= seq <= len(script) and 0 <= t <= self.sc.duration_s and n >= 0):
            raise ValueError(f"{self.state_path}: replay state n={n} t={t} seq={seq} does not fit this scenario")
        for ev, key, payload in script[:seq]:
            self.entries.append((len(self.entries) + 1, payload))
            self.by_key.setdefault(key, []).append(len(self.entries))
        self.n_ticks, self.t, self.fusion_t = n, t, fusion
        self.resumed_from = st
        self.log(f"resuming after tick n={n} t={t:.0f} seq={seq}", flush=True)
        return seq


class Pacer:
    """At max speed, keep the replay at most `window_s` of scenario time ahead of the
    slowest EA peer. Without it the replay runs far ahead: tens of thousands of messages
    sit in flight, a catch-up answer queues behind them, and peers' memory fills up.

    EA peers (liveliness tokens of task-organization units; fusion nodes do not count)
    are waited for from the moment they appear until they report progress
    (`ack/<zid>`), and stop counting when their token goes or when they make no
    progress for `stall_s` of wall time."""

    def __init__(self, s, ks: KeySpace, window_s: float, serve, log, gate: W.Gate, stall_s: float = 30.0):
        self.window_s, self.serve, self.log, self.stall_s, self.gate = window_s, serve, log, stall_s, gate
        self.ks = ks
        self.acks = s.declare_subscriber(ks.ack("*", "*"), zenoh.handlers.FifoChannel(100_000))
        self.alive = s.liveliness().declare_subscriber(ks.alive("*", "*"), zenoh.handlers.FifoChannel(1024),
                                                       history=True)
        self.live: set[str] = set()          # EA peers, as "<unit>/<zid>"
        for r in s.liveliness().get(ks.alive("*", "*"), timeout=2.0):   # those here now, for sure
            if r.ok is not None and (p := self._ea(str(r.ok.key_expr))):
                self.live.add(p)
        self.done: dict[str, float] = {}     # peer -> last tick it processed
        self.moved = {z: time.monotonic() for z in self.live}   # peer -> wall time of its last progress
        self.ignored: set[str] = set()

    def _ea(self, key: str) -> str | None:
        """'<unit>/<zid>' of an EA peer's key (fusion nodes and the replay do not ack)."""
        unit_zid = self.ks.last(key, 2)
        if len(unit_zid) != 2 or unit_zid[0].startswith("fusion-") or unit_zid[0] == "replay":
            return None
        return "/".join(unit_zid)

    def _take(self) -> None:
        while (a := self.alive.try_recv()) is not None:
            p = self._ea(str(a.key_expr))
            if p is None:
                continue
            if a.kind == zenoh.SampleKind.PUT:
                self.live.add(p)
                self.moved.setdefault(p, time.monotonic())
            else:
                self.live.discard(p)
        while (a := self.acks.try_recv()) is not None:
            key = str(a.key_expr)
            ack = self.gate.control(W.Ack, a.payload.to_bytes(), key)
            p = self._ea(key)
            if ack is None or p is None:
                continue
            self.done[p] = max(self.done.get(p, -1.0), ack.t)
            self.moved[p] = time.monotonic()

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
                window_s: float = 20.0, state_path=None) -> int:
    res = Replay(sc, conf, root, speed, wait_peers, linger_s=linger_s, until=until, window_s=window_s,
                 state_path=state_path, log=lambda *a, **k: print(*a, **k, file=sys.stdout)).run()
    print("summary " + json.dumps(res), flush=True)
    return 0
