"""The event generator standing in for SAIM: publishes a scenario's scripted events
into the mesh, and serves the situation store (the ordered log of everything
published so far) to peers that join late.

Every event carries a sequence number (Zenoh attachment). After every 2 s of
scenario time a clock tick says "everything up to seq N has been sent": one
publisher session and one priority keep Zenoh's delivery in order, so a peer that
sees the tick has every earlier message in its channels.

Behind routers (`mesh up --topology`) the replay stands in for every command post's
own sources: it opens one client session per router (a *source*), publishes each
unit's reports through its own command post's router (so they start inside their
battalion) and serves the store per source there. Every source ticks; a peer takes a
tick once every source gave it (each source's path keeps its own order).
"""
from __future__ import annotations

import contextlib
from array import array
import json
import os
import sys
import time
from dataclasses import replace
from pathlib import Path
from bisect import bisect_left, bisect_right
from collections import Counter

import numpy as np
import zenoh

from dissemination.groups import group_depth
from dissemination.keyspace import KeySpace, matcher

from ea_agent import domains

from . import messages as M
from . import gate as G
from . import wire as W
from .batch import Batcher, groups_of
from .inbox import Inbox, Waker
from .pacer import Pacer
from .radios import Radios
from .store import KeyIndex, Log
from .scenario import Scenario
from .script import Script
from .security import sign

BLOCK = zenoh.CongestionControl.BLOCK
STORE_PRIORITY = zenoh.Priority.INTERACTIVE_HIGH


def seq_bytes(seq: int) -> bytes:
    return seq.to_bytes(8, "big")


class Replay:
    def __init__(self, sc: Scenario, conf: zenoh.Config, root: str, speed: float | None = None,
                 wait_peers: list[str] = (), wait_timeout: float = 60.0,
                 linger_s: float = 30.0, log=print, until: float | None = None, window_s: float = 20.0,
                 state_path: str | Path | None = None, max_bytes: int = 65536,
                 sources: dict[str, zenoh.Config] | None = None, topo=None):
        """`sources`: router name -> client config (behind routers; `topo` says which
        unit's reports go through which); without them one session with `conf`."""
        self.sc, self.conf = sc, conf
        self.confs = dict(sources) if sources else {"main": conf}
        self.topo = topo
        self.top = topo.top if topo is not None and sources else next(iter(self.confs))
        self.ks = KeySpace.of(sc, root)
        self.speed, self.wait_peers = speed, list(wait_peers)
        self.tick_s = W.TICK_S   # peers check that tick n is at n x TICK_S
        self.wait_timeout, self.linger_s, self.log = wait_timeout, linger_s, log
        self.entries = Log()        # (seq, payload) of everything published, in a file (store.py)
        # per source: key -> its seqs (queries test each key once), and all its seqs
        self.by_key: dict[str, KeyIndex] = {n: KeyIndex() for n in self.confs}
        self.src_seqs: dict[str, array] = {n: array("I") for n in self.confs}
        self.last_tick: dict[str, bytes] = {}   # per source: the last tick published (repeated while lingering)
        self.trace_len: array | None = array("I") if os.environ.get("SAIM_TRACE") else None
        self.t = 0.0
        self.n_ticks = 0
        self.until = until
        self.window_s = window_s if speed is None else 0.0   # pacing only at max speed
        self.gate = G.Gate(sc.duration_s, max_bytes, log=log)
        self.fusion_t: dict[str, float] = {}   # group -> clock time its tracks are out to
        self.state_path = Path(state_path) if state_path else None
        self.resumed_from: dict | None = None
        self.ingested = 0   # live reports taken in from ingest/** (a TAK gateway)
        self.entity_unit = {e: u.id for u in sc.taskorg.units.values() for e in u.entities}
        self.signer = sign.signer_for(conf)   # secure mode: authority goes out signed as `replay`
        self.batchers: dict[str, Batcher] = {}   # per source: batched families go out per group and tick (batch.py)
        self.waker = Waker()   # what we serve (queries, acks, tokens, live reports) wakes us: we block, not poll
        self.inboxes: dict[str, Inbox] = {}

    def inbox(self, name: str, cap: int, declare, key: str, **kw) -> Inbox:
        """Declare (a subscriber, queryable or liveliness subscriber) into an `Inbox` that wakes us."""
        box = self.inboxes[name] = Inbox(self.waker, cap)
        box.decl = declare(key, box, **kw)   # kept: a dropped declaration may be undeclared
        return box

    def _flush(self) -> None:
        """Every source's batches out, before the tick that covers them."""
        for b in self.batchers.values():
            b.flush()

    def _add(self, src: str, key: str, payload: bytes) -> int:
        """Into the store (as source `src` serves it); returns the entry's seq."""
        n = len(self.entries) + 1
        self.entries.append((n, payload))
        self.by_key[src].setdefault(key, []).append(n)
        self.src_seqs[src].append(n)
        if self.trace_len is not None:
            self.trace_len.append(len(payload))
        return n

    def _write_trace(self) -> None:
        """SAIM_TRACE=DIR: each seq's source, key family and size (bench_scale reads what
        crossed each router link from this and the peers' received seqs)."""
        import numpy as np
        n = len(self.entries) + 1
        src, fam = np.zeros(n, np.uint8), np.zeros(n, np.uint8)
        srcs, fams = sorted(self.by_key), sorted({self.ks.family(k) for idx in self.by_key.values() for k in idx})
        for si, name in enumerate(srcs):
            for k, seqs in self.by_key[name].items():
                ix = np.frombuffer(seqs, dtype=np.uint32) if isinstance(seqs, array) else np.array(seqs)
                src[ix], fam[ix] = si, fams.index(self.ks.family(k))
        np.savez(Path(os.environ["SAIM_TRACE"]) / "replay-trace.npz", src=src, fam=fam,
                 nbytes=np.array([0, *self.trace_len], np.uint32), sources=np.array(srcs), families=np.array(fams))

    def _source(self, ev, taskorg) -> str:
        """The source (router) an event enters by: its unit's command post's; the
        top's for what belongs to no unit (tracks of the brigade's sensors)."""
        if self.topo is None or len(self.confs) == 1:
            return self.top
        for f in ("entity", "unit", "issuer", "requester"):
            v = getattr(ev, f, None)
            if v is not None:
                unit = v if v in taskorg.units else taskorg.entity_unit.get(v)
                if unit is not None:
                    return self.topo.router_of(unit, taskorg)
        return self.top

    def _serve(self, q, src: str) -> None:
        """Answer store queries: entries after `since` whose key matches one of `keys`
        (all when keys is None), the scenario time the log has reached and how far each
        fusion node's tracks are out. A malformed query is counted and answered with nothing."""
        while (query := q.try_recv()) is not None:
            req = self.gate.control(W.StoreQuery, query.payload.to_bytes() if query.payload is not None
                                    else W.encode(W.make(W.StoreQuery)), self.ks.store(src))
            if req is not None:
                try:
                    entries = self._entries(req, src)
                except ValueError as e:   # a key expression Zenoh will not parse: an error answer, and we live
                    self.gate.rejects.add(M.MessageError("storequery", "keys", str(e)[:160]), self.ks.store(src))
                    entries = None
                    query.reply_err(str(e)[:200].encode())
                if entries is not None:
                    query.reply(self.ks.store(src), W.encode(W.make(W.StoreReply, t=self.t, entries=entries,
                                                                       fusion=dict(self.fusion_t))),
                                priority=STORE_PRIORITY)   # overtakes the data queued ahead of it
            del query   # a query kept alive makes the asker wait out its timeout

    def _entries(self, req: W.StoreQuery, src: str) -> list[tuple[int, bytes]]:
        if req.keys is None and not req.before and not req.latest:
            ns = self.src_seqs[src]
            return [self.entries[n - 1] for n in ns[bisect_right(ns, req.since):]]
        match = matcher(req.keys) if req.keys is not None else (lambda k: True)
        seqs = []
        for k, ns in self.by_key[src].items():
            if not match(k):
                continue
            lo = bisect_right(ns, req.since)
            hi = bisect_left(ns, req.before) if req.before else len(ns)
            if lo < hi:
                seqs += [ns[hi - 1]] if req.latest else ns[lo:hi]
        return [self.entries[n - 1] for n in sorted(seqs)]

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

    def _tick(self, sess: dict, t: float, end: bool = False) -> None:
        self.t = t
        self.n_ticks += 1
        w = time.time()
        for src, s in sess.items():   # every source: a peer takes the tick once all gave it
            tick = W.make(W.Tick, t=t, n=self.n_ticks, seq=len(self.entries), end=end, w=w, src=src, of=len(sess))
            self.last_tick[src] = W.encode(tick)
            s.put(self.ks.clock(), self.last_tick[src], congestion_control=BLOCK)
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
            n = self._add(self.top, k, M.encode(m))
            batcher = self.batchers.get(self.top)
            if batcher is None or not batcher.add(k, n, self.entries[-1][1]):
                s.put(k, self.entries[-1][1], attachment=seq_bytes(n), congestion_control=BLOCK)
            self.ingested += 1

    def _prepare(self, end_t: float) -> Script:
        """Keys and payloads for the whole script, before the clock starts: one bulk
        projection, and the task organization as it will be at each event's time
        (`(event, key, payload, source)` entries, kept compactly: `script.py`)."""
        sc = self.sc
        evs = [e for e in sc.events if e.t <= end_t]
        lon = np.array([getattr(e, "lon", 0.0) for e in evs])
        lat = np.array([getattr(e, "lat", 0.0) for e in evs])
        xs, ys = sc.projection.to_xy(lon, lat)
        to = sc.taskorg.copy()
        planned = getattr(domains.of(sc), "org_changes", None)   # a domain with a changing hierarchy
        reorgs = planned(sc) if planned else []
        out = Script()
        for i, (ev, x, y) in enumerate(zip(evs, xs.tolist(), ys.tolist())):
            while reorgs and reorgs[0][0] <= ev.t:
                _, unit, parent = reorgs.pop(0)
                to.resubordinate(unit, parent)
            if type(ev) is M.Reorganization:
                to.resubordinate(ev.unit, ev.new_parent)
            k = self.ks.key(ev, to, sc.projection, (x, y))   # signed with its place in the script: n = i + 1
            out.append(ev, k, sign.seal(self.signer, k, ev, M.encode(ev), i + 1), self._source(ev, to))
        return out.close()

    def run(self) -> dict:
        sc = self.sc
        end_t = sc.duration_s if self.until is None else min(self.until, sc.duration_s)
        script = self._prepare(end_t)
        start = self._resume(script)
        with contextlib.ExitStack() as stack:
            sess = {n: stack.enter_context(zenoh.open(c)) for n, c in sorted(self.confs.items())}
            s = sess[self.top]
            box = self.inbox
            qs = {n: box(f"store-{n}", 4096, x.declare_queryable, self.ks.store(n)) for n, x in sess.items()}
            fticks = box("fusion-ticks", 100_000, s.declare_subscriber, self.ks.fusion_tick("*"))
            ingest = box("ingest", 10_000, s.declare_subscriber, self.ks.ingest("*"))

            def serve() -> None:
                self._take_fusion_ticks(fticks)
                for n, q in qs.items():
                    self._serve(q, n)
            groups = groups_of(self.ks.root, group_depth(sc.taskorg))
            self.batchers = batchers = {n: Batcher(x, groups, self.gate.max_bytes) for n, x in sess.items()}
            # one declared publisher per key not batched (on its source's session): a put then skips parsing the key
            pubs = {(k, src): sess[src].declare_publisher(k, congestion_control=BLOCK)
                    for k, src in sorted(set(zip(script.keys, script.sources))) if groups.group(k) is None}
            self.log(f"ready {s.info.zid()}", flush=True)
            deadline = time.monotonic() + self.wait_timeout
            while self.wait_peers and (missing := self._missing(s)):
                serve()
                if time.monotonic() > deadline:
                    raise TimeoutError(f"peers never came: {missing}")
                self.waker.wait(0.05)   # a query is answered at once; who is here is asked 20 times a second
            pacer = (Pacer(s, self.ks, self.window_s, serve, self.log, self.gate, box) if self.window_s > 0
                     else None)
            source_of = getattr(domains.of(sc), "source_of", None)   # robots send their own state
            radios = Radios(s, self.ks, source_of, self.log) if source_of else None
            self.log("start" + (f" resumed n={self.n_ticks} t={self.t:.0f}" if self.resumed_from else ""), flush=True)
            t0 = time.monotonic() - (self.t / self.speed if self.speed else 0.0)
            next_tick = self.t + self.tick_s
            for ev, key, payload, src in script.since(start):
                while ev.t >= next_tick:
                    self._flush()
                    if pacer:
                        pacer.wait(next_tick)
                    self._tick(sess, next_tick)
                    serve()
                    if int(next_tick) % 100 == 0 and next_tick == int(next_tick):
                        self.log(f"t={next_tick:.0f}", flush=True)
                    next_tick += self.tick_s
                if self.speed:
                    while (wait := t0 + ev.t / self.speed - time.monotonic()) > 0:
                        serve()
                        self._ingest(s, ingest, self.t)   # a live report while the script is quiet
                        self.waker.wait(min(wait, 0.005))
                self._ingest(s, ingest, max(self.t, min(ev.t, next_tick)))
                if radios is not None and radios.silent(ev):
                    continue
                n = self._add(src, key, payload)
                if not batchers[src].add(key, n, payload):
                    pubs[key, src].put(payload, attachment=seq_bytes(n))
            self._flush()
            self._tick(sess, end_t, end=True)
            self.log(f"end events={len(self.entries)} wall_s={time.monotonic() - t0:.2f}", flush=True)
            if self.trace_len is not None:
                self._write_trace()
            linger = time.monotonic() + self.linger_s   # keep serving the store while peers finish
            while time.monotonic() < linger and set(self._present(s)) & set(self.wait_peers or ["?"]):
                for src, x in sess.items():   # the end again: a peer cut off when it went out still gets it
                    x.put(self.ks.clock(), self.last_tick[src], congestion_control=BLOCK)
                look = time.monotonic() + 0.5          # answer queries promptly, ask who is there less often
                while (left := look - time.monotonic()) > 0:
                    serve()
                    self.waker.wait(left)
            return {"events": len(self.entries), "wall_s": time.monotonic() - t0, "rejects": self.gate.errors,
                    "batches": sum(b.sent for b in batchers.values()),
                    "batched": sum(b.entries for b in batchers.values()),
                    "store_index_bytes": self.entries.nbytes + sum(k.nbytes for k in self.by_key.values())
                    + sum(a.itemsize * len(a) for a in self.src_seqs.values()),
                    "ingested": self.ingested,
                    "inbox_dropped": {k: b.dropped for k, b in self.inboxes.items() if b.dropped},
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
        for ev, key, payload, src in script.since(0, seq):
            self._add(src, key, payload)
        self.n_ticks, self.t, self.fusion_t = n, t, fusion
        self.resumed_from = st
        self.log(f"resuming after tick n={n} t={t:.0f} seq={seq}", flush=True)
        return seq


def main_replay(sc: Scenario, conf, root: str, speed, wait_peers, linger_s: float, until=None,
                window_s: float = 20.0, state_path=None, sources=None, topo=None) -> int:
    try:
        # a brigade's 57 peers take a while to start on two cores: a few seconds each
        res = Replay(sc, conf, root, speed, wait_peers, wait_timeout=max(60.0, 5.0 * len(wait_peers)),
                     linger_s=linger_s, until=until, window_s=window_s,
                     state_path=state_path, log=lambda *a, **k: print(*a, **k, file=sys.stdout),
                     sources=sources, topo=topo).run()
    except zenoh.ZError as e:   # a source's router is not there: say which; the supervisor retries
        print(f"saim-mesh replay: cannot reach a router of the topology: {str(e).split(' at /')[0]}",
              file=sys.stderr, flush=True)
        return 4
    print("summary " + json.dumps(res), flush=True)
    return 0
