"""One unit's Execution Assistant as a Zenoh peer (one OS process per unit).

The same EA core as `saim-mesh run`; only the source of facts (subscriptions
computed by `dissemination`) and the sinks (a durable alert log + the mesh) differ.
Every payload goes through `gate.Gate` before use, and nothing a peer receives can
stop it: a bad message is counted, a lost source or fusion node is an alert.
"""
from __future__ import annotations

import heapq
import math
from array import array
import json
import os
import queue
import resource
import signal
import sys
import time
from dataclasses import replace
from pathlib import Path

import msgspec
import zenoh

from dissemination.coarse import coarse
from dissemination.exact import exact
from dissemination.groups import group_depth
from dissemination.interest import Interest
from dissemination.keyspace import KeySpace

from . import cmdlog
from . import noticelog
from . import commands as C
from . import messages as M
from . import batch as B
from . import storeq
from . import gate as G
from . import wire as W
from .alertlog import AlertLog
from .cmdlog import CommandLog
from .fusion.barrier import TrackBarrier
from .intake import Held, Intake
from .keyfacts import KeyFacts
from .presence import Presence
from .runner import config_for, make_ea
from .scenario import Scenario
from .security.sign import signer_for, verifier_for
from .tickwait import SourceLost, TickWait

BLOCK = zenoh.CongestionControl.BLOCK
DEBUG = bool(os.environ.get("SAIM_DEBUG"))
TRIM_EVERY_S = 60.0   # scenario seconds between giving freed heap back to the system


def _malloc_trim():
    """glibc's malloc_trim, or None: Zenoh's threads free what they received, but the
    allocator keeps the pages (a brigade EA's PSS grew ~10 MB over a platoon's)."""
    try:
        import ctypes
        return ctypes.CDLL("libc.so.6").malloc_trim
    except (OSError, AttributeError):
        return None


SWEEP_S = 60.0   # scenario seconds between forgetting the received keys not heard since the last sweep
ACK_EVERY_S = 4.0   # scenario seconds between pacing acks (the replay's window is 20 s)


class Peer(Intake, TickWait):
    """The EA, its subscriptions, its clock and its commands; receiving (`intake.Intake`)
    and waiting for ticks (`tickwait.TickWait`) are halves of it in their own modules."""
    def __init__(self, sc: Scenario, unit: str, conf: zenoh.Config, root: str, out_path: str | None = None,
                 config_path=None, radius_m: float | None = None, log=print, deadline_s: float | None = None,
                 connect: list[str] | None = None, armed: bool = False):
        self.sc, self.unit, self.conf = sc, unit, conf
        self.ks = KeySpace.of(sc, root)
        self.cfg = config_for(sc, unit, config_path)
        self.ea = make_ea(sc, unit, self.cfg, sinks=[self._sink])
        dis, mesh = self.cfg["dissemination"], self.cfg["mesh"]
        self.interest = Interest(self.ks, radius_m or dis["radius_m"], int(dis["block_share"]))
        self.gate = G.Gate(sc.duration_s, int(mesh["max_payload_bytes"]), log=log,
                           verifier=verifier_for(conf, root))   # secure mode: authority must come signed
        self.max_ahead, self.silence_s = float(mesh["max_ahead_s"]), float(mesh["clock_silence_s"])
        self.reject_alert = int(mesh["reject_alert"])
        self.alog = AlertLog(out_path, mesh["fsync"]) if out_path else None
        self.clog = CommandLog(cmdlog.path_for(out_path)) if out_path else None   # for a deterministic replay
        self.nlog = noticelog.NoticeLog(noticelog.path_for(out_path)) if out_path else None
        self.signer = signer_for(conf)   # secure mode: our escalations are signed (they cross routers)
        self.ea.notice_sinks.append(self._notice_sink)
        self.ea.inbox_sinks.append(self._notice_in)
        if armed:   # a commander's console watches this EA: urgent alerts repeat until acknowledged
            self.ea.arm()
        self.deadline_s, self.connect = deadline_s, connect or []
        self.log = log
        self.session = None
        self.replaying = False     # feeding the store's past at (re)join
        self.late = 0              # alerts raised late after a restart
        self.last_seq = 0
        self.t = 0.0
        self.clock_t = 0.0         # the latest valid tick received (bounds how far ahead data may be)
        self.subs: dict[str, None] = {}      # the fine interest (key expressions the EA needs)
        self.zsubs: dict[str, object] = {}   # coarse, non-overlapping Zenoh subscriptions covering it
        self.want = lambda key: False         # exact test of a received key against the fine interest
        self.groups = B.groups_of(root, group_depth(sc.taskorg))
        self.facts = KeyFacts(self.ks, self.groups, self.want)   # per received key: group, wanted, checks
        self.next_sweep = SWEEP_S
        self.flow = {"samples": 0, "batches": 0, "entries": 0, "dropped": 0, "deferred": 0}   # what the coarse subscriptions cost
        self.joined_t = 0.0
        self.tick_lat: list[float] = []
        # wall seconds per stage of the loop (waiting for ticks, receiving, the ticks with
        # the EA in them, re-registering): where a peer's time goes, for bench_mesh
        self.stage_s: dict[str, float] = dict.fromkeys(("wait", "receive", "ticks", "interest"), 0.0)
        # the main thread's own CPU time: "receive" from a tick's arrival through the drain
        # (the barrier wait included), "ticks" the rest of the loop (interest included);
        # set beside stage_s, it shows whether the EA got slower or only got less CPU
        self.stage_cpu_s: dict[str, float] = dict.fromkeys(("receive", "ticks"), 0.0)
        self.pending = Held()                 # seq -> payload, waiting for its tick
        self.max_held = int(mesh["max_held_mb"] * 2**20)
        self.max_seq_ahead = int(mesh["max_seq_ahead"])
        self.tick_seq = 0                     # the latest valid tick's seq
        self.evicted = False                  # held messages were dropped: the store has them
        self.defer_t = math.inf               # earliest time of a message deferred as too far ahead (intake._defer)
        self.defer_from = math.inf            # the clock when the first of them was deferred
        self.contested: set[int] = set()      # seqs that came with two different payloads
        self.direct: list = []    # heap of (t, n, message) not covered by the replay's sequence
        self.n_direct = 0
        self.seen_tracks: set[tuple[str, float]] = set()   # a restarted fusion node may repeat some
        self.fusion_groups = sorted(sc.meta.get("fusion", {}).get("groups", {}))
        self.barrier = TrackBarrier(self, float(mesh["fusion_grace_s"]))
        self.interest_s = float(dis["reregister_s"])
        self.alert_lat: list[float] = []
        self.seen_t = 0.0      # latest scenario time among received replay messages
        self.max_lead = 0.0    # how far the replay ran ahead of us (pacing keeps it small)
        self.tick_n: int | None = None   # number of the last clock tick taken
        self.tick_parts: dict[int, set[str]] = {}   # tick n -> sources that gave it (behind routers)
        self.n_sources = 1                          # how many sources tick (and serve the store)
        self.gaps = 0
        self.gap: tuple[float, float] | None = None   # set while a tick after a gap is processed
        self.silences = 0
        self.next_health = self.reject_alert
        self.presence: Presence | None = None
        self.cmdq: queue.SimpleQueue = queue.SimpleQueue()   # (key, payload) of commands, taken between ticks
        self._wake = lambda: None                           # wakes the clock wait when a command comes
        self.n_cmds = 0
        self.misplaced: str | None = None   # attached to the wrong router (said once joined)
        # SAIM_TRACE=DIR (bench_scale): every seq that reached us from the wire, written to
        # DIR/<unit>.recv at the end: what crossed each router link, per key family
        self.trace: array | None = array("I") if os.environ.get("SAIM_TRACE") else None
        self._notice_prefix = self.ks.notice(self.unit, "")
        C.tap(self.ea)   # a `cff confirm` needs the call for fire the EA saw
        self.needs_before = getattr(self.ea.domain, "needs_before", None)   # places to bring up to date first
        self.prefetched = 0   # messages fed for them

    # -- sinks -------------------------------------------------------------------------
    def _sink(self, a: M.Alert) -> None:
        if self.replaying:
            # the past from the store: a fresh joiner does not tell it again; a restarted
            # peer tells what fell while it was down (not in its log), marked late
            if self.alog is None or not self.alog.restarted or self.alog.already(a):
                return
            a = replace(a, details={**a.details, "late": True, "raised_at_t": self.joined_t})
            self.late += 1
        elif self.gap is not None:   # due while we were cut off from part of the mesh: raised now, marked
            cut = [round(self.gap[0], 1), round(self.gap[1], 1)]
            a = replace(a, details={**a.details, "late": True, "cut_off": cut})
            self.late += 1
        if self.alog:
            self.alog.write(a)
        if self.session is not None:
            self.session.put(self.ks.key(a, None, None), M.encode(a), congestion_control=BLOCK)

    def _notice_sink(self, n) -> None:
        """Our re-notification or escalation: logged and published (not while feeding the
        store's past at a (re)join: those were told, or fell, before we were here)."""
        if self.replaying:
            return
        if self.nlog:
            self.nlog(n)
        if self.session is not None:
            key = self.ks.notice(n.to, n.owner)
            payload = W.encode(W.notice_of(n))
            if self.signer is not None:
                payload = self.signer.sign(key, payload)
            self.session.put(key, payload, congestion_control=BLOCK)

    def _notice_in(self, n) -> None:
        """An escalation from a subordinate's EA: logged with our notices."""
        if self.nlog:
            self.nlog(n)

    def _on_notice(self, key: str, payload: bytes) -> None:
        """notice/<us>/<owner>: an escalation from below, checked (signature in secure
        mode, key against content, the owner under us in the task organization now)."""
        n = self.gate.control(W.Notice, payload, key, signed=True)
        if n is None:
            return
        owner = key.rsplit("/", 1)[-1]
        if owner == self.unit:
            return   # our own re-notification, heard back
        taskorg = getattr(self.ea.domain, "taskorg", None)
        why = (f"notice of {n.owner!r} on the key of {owner!r}" if n.owner != owner else
               f"a {n.kind} notice on our escalation key" if n.kind != "escalate" or n.to != self.unit else
               f"{owner} is not under {self.unit} in the task organization"
               if taskorg is None or owner not in taskorg.units or self.unit not in taskorg.ancestors(owner) else None)
        if why is not None:
            self._reject("notice", "(key)", why, key)
            return
        from ea_agent.core.notify import Notice
        self.ea.take_notice(Notice(n.kind, n.t, n.owner, n.alert, n.story, n.type, n.priority, tuple(n.subjects),
                                   n.message, n.count, n.to, n.due_t))

    def system_alert(self, subject: str, prio: str, text: str, **details) -> None:
        self.log(f"presence {subject} {details.get('event', '')} t={self.t:.0f}", flush=True)
        self.ea.emit(M.Alert(round(self.t, 3), self.unit, "unknown-position", "system-problem", prio, (subject,), text,
                             {"peer": subject, "wall_clock_driven": True, **details}))

    # -- subscriptions ----------------------------------------------------------------------
    def _resubscribe(self, buf: list | None = None) -> None:
        """Re-register when the interest changed. New keys catch up from the store:
        whatever was published on them since the last message we took is fetched, so a
        change of subscriptions never loses data (duplicates are dropped by seq)."""
        want = self.interest.keys(self.ea.domain) - {self.ks.clock()}
        new = sorted(want - self.subs.keys())
        if want != self.subs.keys():
            taskorg = getattr(self.ea.domain, "taskorg", None)
            paths = [taskorg.path(u) for u in taskorg.units] if taskorg is not None else []
            zwant = coarse(want, self.ks.root, self.groups, paths)
            for k in sorted(zwant - self.zsubs.keys()):   # declare new ones before dropping old ones
                self.zsubs[k] = self.session.declare_subscriber(k, zenoh.handlers.FifoChannel(1_000_000))
            for k in sorted(self.zsubs.keys() - zwant):
                self.zsubs.pop(k).undeclare()
            self.subs = dict.fromkeys(sorted(want))
            self.want = exact(want, self.ks.root, cache=False)   # `facts` remembers each key's answer
        if new and buf is not None:
            self._catch_up(new, buf)

    def _catch_up(self, keys: list[str] | None, buf: list, tracks_after: float = -1.0) -> None:
        """Fetch what was published on `keys` after the last message we took, from the
        situation store (duplicates are dropped by seq later) and the fusion nodes
        (their tracks carry no seq: only those after `tracks_after` are taken)."""
        self._fused(keys, tracks_after)
        _, entries = self._query_store(self.last_seq, keys)
        t_hi = self.clock_t + self.max_ahead
        for seq, p in entries:
            if seq > self.last_seq and seq not in self.pending and (m := self.gate.data(p, "store")) is not None:
                if m.t > t_hi:   # still too far ahead: fetched again when due (never held unbounded)
                    self._defer(m.t)
                    continue
                self.pending[seq] = p
                buf.append((seq, m))

    def _fused(self, keys: list[str] | None, tracks_after: float = -1.0) -> None:
        """Hold the fused tracks the fusion nodes published on `keys` (None: all) after
        `tracks_after`, each until its time: fused tracks are not in the replay's log."""
        for g in self.fusion_groups:
            req = W.encode(W.make(W.FusionQuery, keys=keys))
            for r in self.session.get(self.ks.fusion_store(g), payload=req, timeout=10.0):
                if r.ok is None:
                    continue
                rep = self.gate.control(W.FusionReply, r.ok.payload.to_bytes(), str(r.ok.key_expr))
                for p in rep.entries if rep else ():
                    if (m := self.gate.data(p, "store/fusion")) is not None and m.t > tracks_after:
                        if m.t > self.clock_t + self.max_ahead:
                            self._defer(m.t)
                        else:
                            self._hold(m)

    def _plan_signature(self) -> tuple:
        """Changes when a reorganization, a mission transition or a threshold set by the
        commander may change our interest."""
        dom = self.ea.domain
        plan = getattr(dom, "plan", None)
        st = plan.state if plan else {}
        ver = getattr(st, "version", None)   # changes with every state set, unique across plans: asked every tick
        states = ver if ver is not None else hash(tuple(sorted(st.items())))
        return dom.taskorg.version, states, len(self.ea.changes)   # a threshold may widen what we need

    def _query_store(self, since: int, keys: list[str] | None, timeout: float = 10.0):
        rep = storeq.query(self.session, self.ks, self.gate, since, keys, timeout, self.n_sources)
        return (rep.t, rep.entries) if rep is not None else (0.0, [])

    def _reject(self, kind: str, field: str, problem: str, key: str) -> None:
        self.gate.rejects.add(M.MessageError(kind, field, problem), key)

    def _hold(self, m) -> None:
        """A message outside the replay's sequence (a fused track), held until its time."""
        if type(m) is M.SensorTrack:
            k = (m.track, m.t)
            if k in self.seen_tracks:
                return
            self.seen_tracks.add(k)
        self.n_direct += 1
        heapq.heappush(self.direct, (m.t, self.n_direct, m))

    def _feed(self, items) -> None:
        """Submit `items` ((seq, message), in seq order); a fused track goes in before
        the first message of its time or later, where the in-process run puts it. A message the domain judges on
        places beyond our interest (`needs_before`) has them brought up to date first."""
        direct, submit = self.direct, self.ea.submit
        before = None if self.replaying else self.needs_before   # a late join feeds everything anyway
        for seq, m in items:
            if seq > self.last_seq:
                self.last_seq = seq
                while direct and direct[0][0] <= m.t:
                    submit(heapq.heappop(direct)[2])
                if before is not None and (needs := before(m)) is not None:
                    self._prefetch(needs, seq)
                submit(m)

    def _prefetch(self, needs, seq: int) -> None:
        """Feed the latest message before `seq` on each key of `needs`, from the situation
        store: what an in-process EA, which hears everything, knew there. Some we may
        have had already: the domain drops a report it has or has a newer one of."""
        keys = sorted(self.interest.of(needs) - {self.ks.clock()})
        if not keys or self.session is None:
            return
        rep = storeq.query(self.session, self.ks, self.gate, 0, keys, 10.0, self.n_sources, before=seq, latest=True)
        for _, p in rep.entries if rep is not None else ():
            if (m := self.gate.data(p, "store")) is not None:
                self.prefetched += 1
                self.ea.submit(m)

    # -- clock --------------------------------------------------------------------------
    def _on_tick(self, tick: W.Tick, buf: list) -> bool:
        """Feed the EA every message up to the tick's seq, in seq order, then advance it to
        the tick's time. True at the end tick."""
        if self.tick_n is not None and tick.n > self.tick_n + 1:
            # ticks went missing: we were cut off (frozen past our lease, or a broken
            # link) and everything sent meanwhile is lost. Take it from the store.
            self.log(f"gap t={self.t:.0f}..{tick.t:.0f}: catching up", flush=True)
            self.gaps += 1
            self.gap = (self.t, tick.t)   # what this tick raises was due while we were cut off: marked late
            # everything, not just what we subscribe to now: our interest moved on while
            # we were cut off (a link-up partner, a new sector), and the EA takes the gap
            # in one go; extra data only brings it closer to seeing everything
            self._catch_up(None, buf, tracks_after=self.t)
        if self.evicted:   # what we dropped to stay bounded comes back from the store
            self.evicted = False
            self._catch_up(sorted(self.subs), buf)
        if self.defer_t <= self.clock_t + self.max_ahead:   # what came too far ahead is within reach now
            since = self.defer_from
            self.defer_t = self.defer_from = math.inf
            self._catch_up(sorted(self.subs), buf, tracks_after=since)
        self._settle(buf, tick.seq)
        self._feed(self._due(buf, tick.seq))
        while self.direct and self.direct[0][0] <= tick.t:
            self.ea.submit(heapq.heappop(self.direct)[2])
        if DEBUG and int(tick.t) % 300 == 0:
            self.log(f"debug t={tick.t} facts={self.ea.stats['facts']} subs={len(self.subs)} buf={len(buf)} "
                     f"last_seq={self.last_seq} hw={tick.seq}", flush=True)
        self.t, self.tick_n = tick.t, tick.n
        if tick.t >= self.next_sweep:   # keys of cells entities have left: forgotten
            self.facts.sweep()
            self.next_sweep = tick.t + SWEEP_S
        self.presence.take()
        n_alerts = len(self.ea.alerts)
        try:
            if tick.end:
                self.ea.finish(tick.t)
            else:   # a tick at t promises what is before t: what is at t comes after it
                self.ea.advance(tick.t, strict=True)
        finally:
            self.gap = None
        if tick.w is not None:   # wall-clock latency from the tick's publication to its processing
            lat = time.time() - tick.w
            self.tick_lat.append(lat)
            self.alert_lat += [lat] * (len(self.ea.alerts) - n_alerts)
        return tick.end

    # -- a commander's commands (docs/console.md 1) ---------------------------------------
    def _on_cmd(self, smp) -> None:
        """Zenoh's thread: queue the command for the main loop and wake it."""
        self.cmdq.put((str(smp.key_expr), smp.payload.to_bytes()))
        self._wake()

    def _commands(self) -> None:
        """Apply every queued command at our current scenario time and answer each on
        cmdlog/<unit>. A bad one is counted and answered (when its req can be read)."""
        while True:
            try:
                key, payload = self.cmdq.get_nowait()
            except queue.Empty:
                return
            if key.startswith(self._notice_prefix):
                self._on_notice(key, payload)
                continue
            res = self._command(key, payload)
            if res is not None and self.session is not None:
                if res.t > self.sc.duration_s:   # a `set` after the last epoch: the gate bounds t
                    res = msgspec.structs.replace(res, t=self.sc.duration_s)
                self.session.put(self.ks.cmdlog(self.unit), W.encode(res), congestion_control=BLOCK)
                self.log(f"cmd {res.kind} req={res.req} ok={res.ok} t={res.t:.1f}"
                         + (f" error={res.error}" if res.error else ""), flush=True)

    def _command(self, key: str, payload: bytes) -> W.CmdResult | None:
        self.n_cmds += 1   # applied after the tick at self.t: `run --commands` does the same
        return C.receive(self.ea, self.unit, self.ks.root, self.gate, key, payload, self.t, self.clog)

    def _report_health(self) -> None:
        """Tell our superior (health/<unit>) when rejects pass the next threshold."""
        r = self.gate.rejects
        if r.total >= self.next_health:
            self.next_health *= 10
            self.session.put(self.ks.health(self.unit), W.encode(W.make(W.Health, unit=self.unit, rejects=r.total,
                                                                           by_kind=dict(r.by_kind))),
                             congestion_control=BLOCK)

    def _check_connected(self, s) -> None:
        if not self.connect:
            return
        end = time.monotonic() + 5.0
        while time.monotonic() < end:
            if list(s.info.peers_zid()) or list(s.info.routers_zid()):
                return
            time.sleep(0.05)
        msg = f"not connected: nothing answered at {', '.join(self.connect)} within 5 s (still trying)"
        self.log(msg, flush=True)
        print(f"saim-mesh peer {self.unit}: {msg}", file=sys.stderr, flush=True)

    # -- main loop --------------------------------------------------------------------------
    def run(self, join_timeout: float = 10.0) -> dict:
        def stop(*_):
            raise SystemExit(0)
        signal.signal(signal.SIGTERM, stop)
        self.ea.start(0.0)
        t_wall = time.monotonic()
        clockq: queue.SimpleQueue = queue.SimpleQueue()
        t_first = None
        try:
            with zenoh.open(self.conf) as s:
                self.session = s
                # a callback into our own queue (`_next_ticks`): Zenoh has put every sample
                # before a tick into its channel already when the tick is in this queue
                clock = s.declare_subscriber(self.ks.clock(), lambda smp: clockq.put(smp.payload.to_bytes()))
                self._wake = lambda: clockq.put(None)
                cmds = s.declare_subscriber(self.ks.cmd(self.unit, "*", "*"), self._on_cmd)
                notices = s.declare_subscriber(self.ks.notice(self.unit, "*"), self._on_cmd)   # escalations from below
                self._check_connected(s)
                self._resubscribe()
                self.presence = Presence(self, s)
                self.barrier.open(s)
                buf: list = []        # (seq, message) waiting for their clock tick, in arrival order
                self._late_join(join_timeout, buf)
                token = s.liveliness().declare_token(self.ks.alive(self.unit, str(s.info.zid())))
                ack_key = self.ks.ack(self.unit, str(s.info.zid()))
                self.log(f"ready {self.unit} joined_t={self.joined_t}" + (f" late_alerts={self.late}" if self.late
                                                                           else ""), flush=True)
                if self.misplaced:
                    self.system_alert(self.unit, "priority", self.misplaced, event="wrong-router")
                done = False
                next_interest = 0.0
                last_sig = self._plan_signature()
                next_ack = 0.0
                trim, next_trim = _malloc_trim(), TRIM_EVERY_S
                stage, cpu = self.stage_s, self.stage_cpu_s
                while not done:
                    # Take every tick already queued: one drain of the subscriber channels
                    # serves them all (every message up to the last tick's seq is already in it).
                    c0 = time.perf_counter()
                    ticks = self._next_ticks(clockq)
                    k0 = time.thread_time()
                    t_first = t_first or time.monotonic()
                    self.barrier.wait(ticks[-1].t)
                    c1 = time.perf_counter()
                    self._drain(buf)
                    c2 = time.perf_counter()
                    k2 = time.thread_time()
                    if ticks[-1].t >= next_ack and not ticks[-1].end:
                        # lets a max-speed replay pace itself (window 20 s): acked once taken in, not
                        # once worked through, so the next ticks come while we work on these
                        s.put(ack_key, W.encode(W.make(W.Ack, t=ticks[-1].t)))
                        next_ack = ticks[-1].t + ACK_EVERY_S
                    self.max_lead = max(self.max_lead, self.seen_t - ticks[0].t)
                    for tick in ticks:
                        done = self._on_tick(tick, buf)
                        if done:
                            break
                        sig = self._plan_signature()
                        if tick.t >= next_interest or sig != last_sig:   # moved on, or the plan/org changed
                            c3 = time.perf_counter()
                            self._resubscribe(buf)
                            stage["interest"] += time.perf_counter() - c3
                            next_interest, last_sig = tick.t + self.interest_s, sig
                    c4 = time.perf_counter()
                    cpu["receive"] += k2 - k0
                    cpu["ticks"] += time.thread_time() - k2
                    stage["wait"] += c1 - c0
                    stage["receive"] += c2 - c1
                    stage["ticks"] += c4 - c2
                    self._report_health()
                    self._commands()
                    if trim is not None and self.t >= next_trim:
                        trim(0)
                        next_trim = self.t + TRIM_EVERY_S
                s.put(self.ks.bye(self.unit), W.encode(W.make(W.Bye, unit=self.unit)))   # a clean leave is no lost peer
                token.undeclare()
                cmds.undeclare()
                notices.undeclare()
                clock.undeclare()
                self.session = None
        finally:
            if self.trace is not None:
                with open(Path(os.environ["SAIM_TRACE"]) / f"{self.unit}.recv", "wb") as f:
                    self.trace.tofile(f)
            if self.alog:
                self.alog.close()
            if self.clog:
                self.clog.close()
            if self.nlog:
                self.nlog.close()
        return self.summary(t_wall, t_first)

    def summary(self, t_wall: float, t_first: float | None) -> dict:
        ru = resource.getrusage(resource.RUSAGE_SELF)
        rss = ru.ru_maxrss / 1024.0
        by_p: dict[str, int] = {}
        for a in self.ea.alerts:
            by_p[a.priority] = by_p.get(a.priority, 0) + 1
        return {"unit": self.unit, "alerts": len(self.ea.alerts), "by_priority": by_p, "joined_t": self.joined_t,
                "late_alerts": self.late, "restarted": bool(self.alog and self.alog.restarted),
                "messages": self.ea.n_in, "facts": self.ea.stats["facts"], "ea_stats": dict(self.ea.stats), "bad_messages": self.gate.errors + self.ea.stats["errors"],
                "rejects": dict(self.gate.rejects.by_kind), "source_silences": self.silences,
                "subscriptions": len(self.subs), "zenoh_subscriptions": len(self.zsubs), **self.flow,
                "prefetched": self.prefetched,
                "cpu_s": round(ru.ru_utime + ru.ru_stime, 2), "sys_s": round(ru.ru_stime, 2),
                "minor_faults": ru.ru_minflt, "ctx_switches": {"voluntary": ru.ru_nvcsw, "involuntary": ru.ru_nivcsw},
                "peak_rss_mb": round(rss, 1), "max_lead_s": round(self.max_lead, 1),
                "gaps": self.gaps, "lost_fusion": sorted(self.barrier.lost),
                "wall_s": round(time.monotonic() - t_wall, 2),
                "active_s": round(time.monotonic() - (t_first or t_wall), 3),
                "tick_latency_ms": _pcts(self.tick_lat), "alert_latency_ms": _pcts(self.alert_lat),
                "stage_s": {k: round(v, 3) for k, v in self.stage_s.items()},
                "stage_cpu_s": {k: round(v, 3) for k, v in self.stage_cpu_s.items()},
                "alert_latencies_ms": [round(1000 * x, 3) for x in self.alert_lat[:5000]],
                "picture": self.picture()}

    def picture(self) -> dict:
        """The adjudicated hostile picture (domains with fused tracks), for identity checks."""
        adj = getattr(getattr(self.ea.domain, "pic", None), "adj", None)
        return {} if adj is None else {k: [round(e.x, 1), round(e.y, 1), e.strength, list(e.members)]
                                       for k, e in sorted(adj.picture().items())}

    def _late_join(self, timeout: float, buf: list) -> None:
        """Get the picture so far from the situation store and replay it: silently for a
        new joiner, raising what fell while we were down for a restarted peer."""
        t, entries = self._query_store(0, None, timeout)
        if not entries:
            return
        self.joined_t = t
        self.replaying = True
        try:
            # the fusion nodes' tracks so far go in with the store's past, each where the
            # in-process run takes it (`_feed`), silently too: a track already in a place
            # we watch was told before we joined, not news at our first tick
            self.clock_t = t
            self._fused(None)
            self._feed(sorted(((seq, m) for seq, p in entries if (m := self.gate.data(p, "store")) is not None),
                              key=lambda x: x[0]))
            while self.direct and self.direct[0][0] <= t:
                self.ea.submit(heapq.heappop(self.direct)[2])
            self.ea.advance(t, strict=True)
        finally:
            self.replaying = False
        self.t = self.clock_t = t
        self._resubscribe(buf)   # new keys catch up, fused tracks included


def _pcts(xs: list[float]) -> dict:
    if not xs:
        return {}
    ys = sorted(xs)
    pick = lambda q: round(1000 * ys[min(len(ys) - 1, int(q * len(ys)))], 3)
    return {"n": len(ys), "p50": pick(0.50), "p99": pick(0.99), "max": round(1000 * ys[-1], 3)}


def main_peer(sc: Scenario, unit: str, conf, root: str, out: str | None, config_path=None,
              radius_m: float | None = None, deadline_s: float | None = None, connect: list[str] | None = None,
              armed: bool = False, misplaced: str | None = None) -> int:
    p = Peer(sc, unit, conf, root, out, config_path, radius_m, log=lambda *a, **k: print(*a, **k, file=sys.stdout),
             deadline_s=deadline_s, connect=connect, armed=armed)
    p.misplaced = misplaced
    try:
        summary = p.run()
    except SourceLost as e:
        print(f"saim-mesh peer {unit}: {e}", file=sys.stderr, flush=True)
        return 3
    except zenoh.ZError as e:   # its router (or the replay) is not there: say so; the supervisor retries
        print(f"saim-mesh peer {unit}: cannot join the mesh at {', '.join(connect or []) or 'no endpoint'}: "
              f"{str(e).split(' at /')[0]}", file=sys.stderr, flush=True)
        return 4
    print("summary " + json.dumps(summary), flush=True)
    return 0
