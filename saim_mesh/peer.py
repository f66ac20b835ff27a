"""One unit's Execution Assistant as a Zenoh peer (one OS process per unit).

The same EA core as `saim-mesh run`; only the source of facts (subscriptions
computed by `dissemination`) and the sinks (JSON lines file + the mesh) differ.
"""
from __future__ import annotations

import heapq
import json
import os
import resource
import signal
import sys
import time

import msgpack
import zenoh

from dissemination.interest import Interest
from dissemination.keyspace import KeySpace
from ea_agent.core.config import load_config
from ea_agent.domains.suo import make_ea

from . import messages as M
from .scenario import Scenario
from .sinks import alert_line

BLOCK = zenoh.CongestionControl.BLOCK
DEBUG = bool(os.environ.get("SAIM_DEBUG"))


class Peer:
    def __init__(self, sc: Scenario, unit: str, conf: zenoh.Config, root: str, out_path: str | None = None,
                 config_path=None, radius_m: float | None = None, log=print):
        self.sc, self.unit, self.conf = sc, unit, conf
        self.ks = KeySpace(root)
        self.cfg = load_config(config_path, unit)
        self.ea = make_ea(sc, unit, self.cfg, sinks=[self._sink])
        dis = self.cfg["dissemination"]
        self.interest = Interest(self.ks, radius_m or dis["radius_m"], int(dis["block_share"]))
        self.out = open(out_path, "a") if out_path else None
        self.log = log
        self.session = None
        self.muted = False
        self.last_seq = 0
        self.t = 0.0
        self.subs: dict[str, object] = {}
        self.peers: dict[str, str] = {}       # unit -> "up" / "down"
        self.decoder = M.Decoder()
        self.joined_t = 0.0
        self.tick_lat: list[float] = []
        self.clean: set[str] = set()
        self.pending: set[int] = set()
        self.direct: list = []    # heap of (t, n, message) not covered by the replay's sequence
        self.n_direct = 0
        self.fusion_groups = sorted(sc.meta.get("fusion", {}).get("groups", {}))
        self.ftick = {g: -1.0 for g in self.fusion_groups}   # clock time each node's tracks are out to
        self.lost_groups: set[str] = set()
        self.ftick_sub = None
        self.interest_s = float(dis["reregister_s"])
        self.alert_lat: list[float] = []
        self.seen_t = 0.0      # latest scenario time among received replay messages
        self.max_lead = 0.0    # how far the replay ran ahead of us (pacing keeps it small)
        self.tick_n: int | None = None   # number of the last clock tick taken
        self.gaps = 0

    # -- sinks -------------------------------------------------------------------------
    def _sink(self, a: M.Alert) -> None:
        if self.muted:   # replaying the store: the commander is not told the past again
            return
        if self.out:
            self.out.write(alert_line(a) + "\n")
            self.out.flush()
        if self.session is not None:
            self.session.put(self.ks.key(a, None, None), M.encode(a), congestion_control=BLOCK)

    # -- subscriptions ----------------------------------------------------------------------
    def _resubscribe(self, buf: list | None = None) -> None:
        """Re-register when the interest changed. New keys catch up from the store:
        whatever was published on them since the last message we took is fetched, so a
        change of subscriptions never loses data (duplicates are dropped by seq)."""
        want = self.interest.keys(self.ea.domain) - {self.ks.clock()}
        new = sorted(want - self.subs.keys())
        for k in new:   # declare new ones before dropping old ones
            self.subs[k] = self.session.declare_subscriber(k, zenoh.handlers.FifoChannel(1_000_000))
        for k in sorted(self.subs.keys() - want):
            self.subs.pop(k).undeclare()
        if new and buf is not None:
            self._catch_up(new, buf)

    def _catch_up(self, keys: list[str], buf: list, tracks_after: float = -1.0) -> None:
        """Fetch what was published on `keys` after the last message we took, from the
        situation store (duplicates are dropped by seq later) and the fusion nodes
        (their tracks carry no seq: only those after `tracks_after` are taken)."""
        for g in self.fusion_groups:   # fused tracks are not in the replay's log: ask their nodes
            req = msgpack.packb({"keys": keys})
            for r in self.session.get(self.ks.fusion_store(g), payload=req, timeout=10.0):
                if r.ok is not None:
                    for p in msgpack.unpackb(r.ok.payload.to_bytes(), raw=False)["entries"]:
                        if (m := self.decoder(p)) is not None and m.t > tracks_after:
                            self.n_direct += 1
                            heapq.heappush(self.direct, (m.t, self.n_direct, m))
        _, entries = self._query_store(self.last_seq, keys)
        for seq, p in entries:
            if seq > self.last_seq and seq not in self.pending and (m := self.decoder(p)) is not None:
                self.pending.add(seq)
                heapq.heappush(buf, (seq, m))

    def _plan_signature(self) -> tuple:
        """Changes when a reorganization or a mission transition may change our interest."""
        dom = self.ea.domain
        states = tuple(sorted(dom.plan.state.items())) if dom.plan else ()
        return dom.taskorg.version, hash(states)

    def _query_store(self, since: int, keys: list[str] | None, timeout: float = 10.0):
        req = msgpack.packb({"since": since, "keys": keys})
        for r in self.session.get(self.ks.store(), payload=req, timeout=timeout):
            if r.ok is not None:
                d = msgpack.unpackb(r.ok.payload.to_bytes(), raw=False)
                return d["t"], d["entries"]
        return 0.0, []

    def _drain(self, buf: list) -> None:
        """Move received samples into the seq-ordered heap; a message that came twice
        (overlapping subscriptions) is decoded once."""
        pending = self.pending
        for sub in self.subs.values():
            while (s := sub.try_recv()) is not None:
                if s.attachment is None:   # not from the replay (fused tracks): held until their time comes
                    m = self.decoder(s.payload.to_bytes())
                    if m is not None:
                        self.n_direct += 1
                        heapq.heappush(self.direct, (m.t, self.n_direct, m))
                    continue
                seq = int.from_bytes(s.attachment.to_bytes(), "big")
                if seq <= self.last_seq or seq in pending:
                    continue
                m = self.decoder(s.payload.to_bytes())
                if m is not None:
                    pending.add(seq)
                    heapq.heappush(buf, (seq, m))
                    if m.t > self.seen_t:
                        self.seen_t = m.t

    def _feed(self, items) -> None:
        """Submit in seq order; a fused track goes in before the first message of its
        time or later, where the in-process run puts it."""
        direct, submit = self.direct, self.ea.submit
        for seq, m in sorted(items, key=lambda x: x[0]):
            if seq > self.last_seq:
                self.last_seq = seq
                while direct and direct[0][0] <= m.t:
                    submit(heapq.heappop(direct)[2])
                submit(m)

    def _await_tracks(self, t: float, timeout: float = 30.0) -> None:
        """Hold the clock at `t` until every fusion node has published its tracks up to it,
        so that every peer takes each track at the same point of its stream. A node
        silent for `timeout` s of wall time is not waited for again (and we say so)."""
        if self.ftick_sub is None:
            return
        give_up = None
        while True:
            while (m := self.ftick_sub.try_recv()) is not None:
                g = str(m.key_expr).split("/")[-1]
                if g in self.ftick:
                    self.ftick[g] = max(self.ftick[g], msgpack.unpackb(m.payload.to_bytes())["t"])
            behind = [g for g, ft in self.ftick.items() if ft < t and g not in self.lost_groups]
            if not behind:
                return
            now = time.monotonic()
            give_up = give_up or now + timeout
            if now > give_up:
                self.log(f"fusion node(s) {behind} silent for {timeout:.0f} s: going on without them", flush=True)
                self.lost_groups.update(behind)
                return
            time.sleep(0.0002)   # the node's marker is at most one of its ticks away

    # -- presence ---------------------------------------------------------------------------
    def _presence(self, ch, bye) -> None:
        while (b := bye.try_recv()) is not None:
            self.clean.add(str(b.key_expr).split("/")[-1])
        to = self.ea.domain.taskorg
        watch = set(to.children(self.unit)) | set(to.subtree(self.unit)) | set(to.ancestors(self.unit)[:1])
        while (s := ch.try_recv()) is not None:
            unit = str(s.key_expr).split("/")[-2]
            if DEBUG:
                self.log(f"debug presence {s.kind} {s.key_expr}", flush=True)
            if unit == self.unit or unit not in watch:
                continue
            up = s.kind == zenoh.SampleKind.PUT
            before = self.peers.get(unit)
            self.peers[unit] = "up" if up else "down"
            if not up and unit in self.clean:
                continue
            if up:
                self.clean.discard(unit)
            if not up:
                self._system_alert(unit, "immediate", f"EA of {to.name(unit)} left the mesh: its picture and "
                                   f"confirmations no longer reach us", left=True)
            elif before == "down":
                self._system_alert(unit, "routine", f"EA of {to.name(unit)} is back on the mesh", left=False)

    def _system_alert(self, unit: str, prio: str, text: str, left: bool) -> None:
        self.log(f"presence {unit} {'left' if left else 'back'} t={self.t:.0f}", flush=True)
        self.ea.emit(M.Alert(round(self.t, 3), self.unit, "unknown-position", "system-problem", prio, (unit,), text,
                             {"peer": unit, "left": left, "wall_clock_driven": True}))

    # -- main loop --------------------------------------------------------------------------
    def _on_tick(self, info: dict, buf: list, pres, bye) -> bool:
        """Feed the EA every message up to the tick's seq, in seq order, then advance it to
        the tick's time. True at the end tick."""
        if self.tick_n is not None and info["n"] > self.tick_n + 1:
            # ticks went missing: we were cut off (frozen past our lease, or a broken
            # link) and everything sent meanwhile is lost. Take it from the store.
            self.log(f"gap t={self.t:.0f}..{info['t']:.0f}: catching up", flush=True)
            self.gaps += 1
            self._catch_up(sorted(self.subs), buf, tracks_after=self.t)
        ready = []
        while buf and buf[0][0] <= info["seq"]:
            ready.append(heapq.heappop(buf))
        self.pending.difference_update(x[0] for x in ready)
        self._feed(ready)
        while self.direct and self.direct[0][0] <= info["t"]:
            self.ea.submit(heapq.heappop(self.direct)[2])
        if DEBUG and int(info["t"]) % 300 == 0:
            self.log(f"debug t={info['t']} facts={self.ea.stats['facts']} in={self.ea.stats['in']} "
                     f"subs={len(self.subs)} buf={len(buf)} last_seq={self.last_seq} hw={info['seq']}", flush=True)
        self.t, self.tick_n = info["t"], info["n"]
        self._presence(pres, bye)
        n_alerts = len(self.ea.alerts)
        if info["end"]:
            self.ea.finish(info["t"])
        else:
            self.ea.advance(info["t"])
        if "w" in info:   # wall-clock latency from the tick's publication to its processing
            lat = time.time() - info["w"]
            self.tick_lat.append(lat)
            self.alert_lat += [lat] * (len(self.ea.alerts) - n_alerts)
        return bool(info["end"])

    def run(self, join_timeout: float = 10.0) -> dict:
        def stop(*_):
            raise SystemExit(0)
        signal.signal(signal.SIGTERM, stop)
        self.ea.start(0.0)
        t_wall = time.monotonic()
        with zenoh.open(self.conf) as s:
            self.session = s
            clock = s.declare_subscriber(self.ks.clock(), zenoh.handlers.FifoChannel(1_000_000))
            self._resubscribe()
            pres = s.liveliness().declare_subscriber(self.ks.alive("*", "*"), zenoh.handlers.FifoChannel(1024),
                                                     history=True)
            bye = s.declare_subscriber(self.ks.bye("*"), zenoh.handlers.FifoChannel(1024))
            if self.fusion_groups:
                self.ftick_sub = s.declare_subscriber(self.ks.fusion_tick("*"), zenoh.handlers.FifoChannel(100_000))
            buf: list = []        # heap of (seq, message) waiting for their clock tick
            self._late_join(s, join_timeout, buf)
            token = s.liveliness().declare_token(self.ks.alive(self.unit, str(s.info.zid())))
            ack_key = self.ks.ack(str(s.info.zid()))
            self.log(f"ready {self.unit} joined_t={self.joined_t}", flush=True)
            done = False
            next_interest = 0.0
            last_sig = self._plan_signature()
            t_first = None
            while not done:
                # Block for the next tick, then take every tick already queued behind it:
                # one drain of the subscriber channels serves them all (every message up
                # to the last tick's seq is already in its channel).
                ticks = [clock.recv()]
                while len(ticks) < 64 and (more := clock.try_recv()) is not None:
                    ticks.append(more)
                if t_first is None:
                    t_first = time.monotonic()
                infos = [msgpack.unpackb(x.payload.to_bytes()) for x in ticks]
                self._await_tracks(infos[-1]["t"])
                self._drain(buf)
                self.max_lead = max(self.max_lead, self.seen_t - infos[0]["t"])
                for info in infos:
                    done = self._on_tick(info, buf, pres, bye)
                    if done:
                        break
                    sig = self._plan_signature()
                    if info["t"] >= next_interest or sig != last_sig:   # moved on, or the plan/org changed
                        self._resubscribe(buf)
                        next_interest, last_sig = info["t"] + self.interest_s, sig
                if not done:
                    s.put(ack_key, msgpack.packb(self.t))   # lets a max-speed replay pace itself
            s.put(self.ks.bye(self.unit), b"")   # a clean leave is not a lost peer
            token.undeclare()
            self.session = None
        if self.out:
            self.out.close()
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        by_p: dict[str, int] = {}
        for a in self.ea.alerts:
            by_p[a.priority] = by_p.get(a.priority, 0) + 1
        return {"unit": self.unit, "alerts": len(self.ea.alerts), "by_priority": by_p, "joined_t": self.joined_t,
                "facts": self.ea.stats["facts"], "bad_messages": self.decoder.errors + self.ea.stats["errors"],
                "subscriptions": len(self.subs), "peak_rss_mb": round(rss, 1), "max_lead_s": round(self.max_lead, 1),
                "gaps": self.gaps,
                "wall_s": round(time.monotonic() - t_wall, 2),
                "active_s": round(time.monotonic() - (t_first or t_wall), 3),
                "tick_latency_ms": _pcts(self.tick_lat), "alert_latency_ms": _pcts(self.alert_lat),
                "picture": self.picture()}

    def picture(self) -> dict:
        return {k: [round(e.x, 1), round(e.y, 1), e.strength, list(e.members)]
                for k, e in sorted(self.ea.domain.pic.adj.picture().items())}

    def _late_join(self, s, timeout: float, buf: list) -> None:
        """Get the picture so far from the situation store and replay it silently."""
        t, entries = self._query_store(0, None, timeout)
        if not entries:
            return
        self.muted = True
        try:
            self._feed([(seq, m) for seq, p in entries if (m := self.decoder(p)) is not None])
            self.ea.advance(t)
        finally:
            self.muted = False
        self.t = self.joined_t = t
        self._resubscribe(buf)   # new keys catch up, fused tracks included


def _pcts(xs: list[float]) -> dict:
    if not xs:
        return {}
    ys = sorted(xs)
    pick = lambda q: round(1000 * ys[min(len(ys) - 1, int(q * len(ys)))], 3)
    return {"n": len(ys), "p50": pick(0.50), "p99": pick(0.99), "max": round(1000 * ys[-1], 3)}


def main_peer(sc: Scenario, unit: str, conf, root: str, out: str | None, config_path=None,
              radius_m: float | None = None) -> int:
    p = Peer(sc, unit, conf, root, out, config_path, radius_m, log=lambda *a, **k: print(*a, **k, file=sys.stdout))
    summary = p.run()
    print("summary " + json.dumps(summary), flush=True)
    return 0
