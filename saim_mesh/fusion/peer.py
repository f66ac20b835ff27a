"""A fusion node as a Zenoh peer: takes its sensor group's hits (in the replay's order,
by sequence number and clock ticks) and publishes fused tracks into the mesh.

A restarted node resumes where its predecessor stopped: it asks the situation store
for its group's hits so far and how far its tracks were out, re-runs the (deterministic)
fusion over them without publishing, and goes on. Tracks keep their numbers, and
peers get every track exactly once."""
from __future__ import annotations

import heapq
import json
import random
import signal
import sys
import time

import zenoh

from dissemination.keyspace import KeySpace, matcher
from saim_mesh import messages as M
from saim_mesh import storeq
from saim_mesh import gate as G
from saim_mesh import wire as W
from saim_mesh.scenario import Scenario

from . import make_node


BLOCK = zenoh.CongestionControl.BLOCK


def _eas_present(s, ks: KeySpace) -> bool:
    for r in s.liveliness().get(ks.alive("*", "*"), timeout=2.0):
        if r.ok is not None and not ks.last(str(r.ok.key_expr), 2)[0].startswith(("fusion-", "replay")):
            return True
    return False


class FusionPeer:
    def __init__(self, sc: Scenario, group: str, conf, root: str, shuffle: int | None = None,
                 linger_s: float = 30.0, log=print, max_bytes: int = 65536):
        self.sc, self.group, self.conf, self.linger_s, self.log = sc, group, conf, linger_s, log
        self.ks = KeySpace.of(sc, root)
        self.node = make_node(sc, group)
        self.rnd = random.Random(shuffle) if shuffle is not None else None
        self.gate = G.Gate(sc.duration_s, max_bytes, log=log)
        self.sent = 0
        self.log_out: list[tuple[str, bytes]] = []   # what we published, for peers that subscribe later
        self.heap: list = []                         # (seq, hit) waiting for their tick
        self.seen: set[int] = set()                  # seqs taken (the store and the live feed overlap)
        self.done_t = -1.0                           # clock time our tracks are out to
        self.resumed = False

    def serve(self, query) -> None:
        """Answered at once on Zenoh's thread: an EA waiting for its catch-up must not wait
        for our next clock tick (a paced replay may be waiting for that EA)."""
        req = self.gate.control(W.FusionQuery, query.payload.to_bytes() if query.payload is not None
                                else W.encode(W.make(W.FusionQuery)), self.ks.fusion_store(self.group))
        if req is None:
            return
        try:
            match = matcher(req.keys) if req.keys is not None else (lambda k: True)
            entries = [p for k, p in list(self.log_out) if match(k)]
        except ValueError as e:   # a key expression Zenoh will not parse: counted, an error answer
            self.gate.rejects.add(M.MessageError("fusionquery", "keys", str(e)[:160]), self.ks.fusion_store(self.group))
            query.reply_err(str(e)[:200].encode())
            return
        query.reply(self.ks.fusion_store(self.group), W.encode(W.make(W.FusionReply, entries=entries)))

    def _take_hit(self, seq: int, payload: bytes, key: str | None) -> None:
        """One hit by seq; `key` None for the store's entries (their keys were checked on the way in)."""
        if seq in self.seen or seq <= 0:
            return
        m = self.gate.data(payload, key or "store")
        if m is None:
            return
        why = "not a sensor hit" if type(m) is not M.SensorHit else key and self.ks.mismatch(key, m)
        if why:
            self.gate.rejects.add(M.MessageError(m.KIND, "(key)", why), key)
            return
        self.seen.add(seq)
        heapq.heappush(self.heap, (seq, m))

    def _resume(self, s) -> None:
        """Take the store's hits and our predecessor's progress; replay them silently."""
        rep = storeq.query(s, self.ks, self.gate, 0, [self.ks.data(M.SensorHit, group=self.group)])
        if rep is None:
            return
        done = rep.fusion.get(self.group, -1.0)
        for seq, p in rep.entries:
            self._take_hit(seq, p, None)
        if done < 0:
            return
        while self.heap and self.heap[0][1].t < done:   # what our predecessor had fused and sent
            self.node.add(heapq.heappop(self.heap)[1])
        self.node.flush(done)
        self.done_t, self.resumed = done, True
        self.log(f"resumed fusion-{self.group} at t={done:.0f} (track numbers from {self.node.seq})", flush=True)

    def run(self) -> dict:
        def stop(*_):
            raise SystemExit(0)
        signal.signal(signal.SIGTERM, stop)
        ks, group = self.ks, self.group
        with zenoh.open(self.conf) as s:
            store = s.declare_queryable(ks.fusion_store(group), self.serve)
            clock = s.declare_subscriber(ks.clock(), zenoh.handlers.FifoChannel(1_000_000))
            hits = s.declare_subscriber(ks.data(M.SensorHit, group=group), zenoh.handlers.FifoChannel(1_000_000))
            self._resume(s)
            token = s.liveliness().declare_token(ks.alive(f"fusion-{group}", str(s.info.zid())))
            print(f"ready fusion-{group}", flush=True)
            while True:
                smp = clock.recv()
                info = self.gate.control(W.Tick, smp.payload.to_bytes(), ks.clock())
                if info is None or info.t <= self.done_t:
                    continue
                while (h := hits.try_recv()) is not None:
                    att = h.attachment.to_bytes() if h.attachment is not None else b""
                    self._take_hit(int.from_bytes(att, "big") if len(att) == 8 else -1,
                                   h.payload.to_bytes(), str(h.key_expr))
                out = []
                while self.heap and self.heap[0][0] <= info.seq:
                    out += self.node.add(heapq.heappop(self.heap)[1])
                out += self.node.flush(info.t)
                if self.rnd is not None:
                    self.rnd.shuffle(out)   # tests: arrival order must not matter
                for tr in out:
                    x, y = self.sc.projection.to_xy(tr.lon, tr.lat)
                    key, payload = ks.key(tr, None, None, (x, y)), M.encode(tr)
                    self.log_out.append((key, payload))
                    s.put(key, payload, congestion_control=BLOCK)
                    self.sent += 1
                # after its tracks on the same session: an EA that sees this has them all
                s.put(ks.fusion_tick(group), W.encode(W.make(W.FusionTick, t=info.t, last=self.node.seq)),
                      congestion_control=BLOCK)
                self.done_t = info.t
                if info.end and info.t >= self.sc.duration_s:
                    break
            linger = time.monotonic() + self.linger_s   # keep answering catch-up queries while EAs finish
            while time.monotonic() < linger and _eas_present(s, ks):
                time.sleep(0.2)    # queries are answered by the callback meanwhile
            s.put(ks.bye(f"fusion-{group}"), W.encode(W.make(W.Bye, unit=f"fusion-{group}")))
            token.undeclare()
            store.undeclare()
        return {"group": group, "hits_in": self.node.stats["hits_in"], "tracks_out": self.sent,
                "resumed": self.resumed, "rejects": dict(self.gate.rejects.by_kind)}


def run_fusion_peer(sc: Scenario, group: str, conf, root: str, shuffle: int | None = None,
                    linger_s: float = 30.0) -> dict:
    return FusionPeer(sc, group, conf, root, shuffle, linger_s,
                      log=lambda *a, **k: print(*a, **k, file=sys.stdout)).run()


def main_fusion(sc: Scenario, group: str, conf, root: str, shuffle: int | None) -> int:
    print("summary " + json.dumps(run_fusion_peer(sc, group, conf, root, shuffle)), flush=True)
    return 0
