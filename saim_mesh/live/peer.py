"""One unit's EA on a live mesh with no centre (issue 31): no replay, no global clock,
no global sequence. It subscribes to the streams of the sources it depends on and
advances on event time as far as every one of them has promised (`order.EventTimeOrder`:
the minimum watermark over the sources not declared lost), applying facts in
`(event time, source, epoch, seq)` order, so the same inputs give the same alerts
whatever the arrival order, speed or machine.

Composed of small parts: the frames' subscriber (zenoh.ext advanced subscriber: per
source order, recovery from the publisher's cache, late-joiner history, miss detection),
the order, the EA, the input journal (every frame taken and every loss decision, so
replaying it reproduces the run: `journal.replay`), the alert and notice logs.

Loss is a decision, logged: a depended source silent for `[mesh] source_silence_s` of wall
time is declared lost (journal, one system-problem alert naming it and what it degrades);
monitoring goes on with the others. When it comes back its facts are taken on a late path
and what they raise is marked late."""
from __future__ import annotations

import heapq
import math
import queue
import sys
import time

import zenoh

from dissemination.keyspace import KeySpace
from ea_agent.core.alert import hms
from ea_agent.core.ids import AlertIds

from ..authority import commands as C
from ..protocol import messages as M
from ..protocol import gate as G
from ..protocol import wire as W
from ..inprocess.runner import config_for, make_ea
from ..scenario import Scenario
from ..security.sign import signer_for
from . import frames as F
from . import commanded, recover
from . import groupframes as GF
from .authority import DirectiveIntake
from .bygroup import GroupIntake
from .depend import depends
from .journal import InputJournal
from .losses import BeforeLosses, Carried
from .order import EventTimeOrder
from .outputs import Outputs
from .liveness import SourceWatch
from .presence import PeerPresence
from .sequence import Sequencer
from .timeline import Timeline

BLOCK = zenoh.CongestionControl.BLOCK
CHECK_S = 0.05        # wall seconds between the loop's checks (retries, gaps, silences) while frames flow
ORDER_ITEM_BYTES = 320   # what one fact waiting in the order holds (a decoded report and its heap entry)
DATA = frozenset((M.LocationReport, M.SensorTrack, M.MissionConfirm, M.CallForFire, M.CallForFireConfirm, M.Order,
                  M.Reorganization))


class LivePeer:
    def __init__(self, sc: Scenario, unit: str, conf: zenoh.Config, root: str, sources: list[str],
                 out_path: str | None = None, config_path=None, log=print, silence_s: float | None = None,
                 live_start: float | None = None, armed: bool = False, max_bytes: int | None = None):
        if unit not in sc.taskorg.units:
            raise KeyError(f"unknown unit {unit!r}: not in the task organization of {sc.name}")
        if not sources:
            raise ValueError("a live peer needs the names of the sources it depends on (--sources)")
        self.sc, self.unit, self.conf, self.log = sc, unit, conf, log
        self.ks = KeySpace.of(sc, root)
        self.cfg = config_for(sc, unit, config_path)
        mesh = self.cfg["mesh"]
        silence_s = float(mesh["source_silence_s"] if silence_s is None else silence_s)
        self.max_bytes = int(max_bytes or mesh["max_payload_bytes"])
        # memory held for the order: frames waiting (out of sequence, or for room in the
        # order) up to half of it, facts in the order the other half; beyond, a source's
        # frames are dropped and fetched again from its journal when there is room
        self.max_held = int(float(mesh["max_held_mb"]) * 2**20)
        self.gate = G.Gate(W.T_LIMIT if live_start is not None else sc.duration_s, self.max_bytes, log=log)
        # a commander's commands are signed end to end (secure mode): checked by their own gate.
        # A source's frame is trusted by its key (only source.<name> may put on src/<name>),
        # its contents not signed one by one (issue 33: authority over the mesh)
        from ..security.sign import verifier_for
        self.cmd_gate = G.Gate(self.gate.t_max, self.max_bytes, log=log, verifier=verifier_for(conf, root))
        self.cmd_gate.rejects = self.gate.rejects   # one count of what was refused
        self.gate.rejects.on_flood = self._flood     # ... per sender: a flood is said (threat model)
        self.dirs = DirectiveIntake(root, self.cmd_gate)   # orders down, confirmations up (issue 33)
        from ..authority.plans import validator
        self.validate_plan = validator(sc)                   # plan versions checked as plan files are
        self.live_start = live_start          # wall time of event time 0 (--live), else None: recorded time
        self.ids = AlertIds(unit)   # every alert id issued, kept across rebuilds: never rewound
        self.armed = armed
        self.ea = self.new_ea()
        from ea_agent import domains
        # what a source's frame may carry: the picture's facts and the domain's own reports
        self.data_kinds = DATA | frozenset(getattr(domains.of(sc), "SOURCE_KINDS", ()))
        self.confirmed_up: set[tuple[str, str]] = set()   # (mission, phase) published up the chain
        # the sources its interest needs among those named: only these gate its epochs
        self.named = sorted(dict.fromkeys(sources))
        self.sources = depends(sc, self.ea, self.named)
        self.order = EventTimeOrder(self.sources, max_buffered=self._order_bound())
        self.journal = InputJournal(str(out_path).removesuffix(".jsonl") + ".input") if out_path else None
        self.signer = signer_for(conf)   # secure mode: our notices and confirmations are signed
        self.out = Outputs(self.ks, unit, out_path, mesh["fsync"], self.journal, self.signer)   # logs, the mesh
        self.session = None
        self.q: queue.SimpleQueue = queue.SimpleQueue()
        # the depended sources' liveness: heard when, promised how far, ended
        self.watch = SourceWatch(self.sources, silence_s, max(silence_s, float(mesh["source_join_s"])),
                                 float(mesh["source_end_wait_s"]))
        self.carried = Carried(sc.taskorg)   # per source, the units and tracks its loss leaves unsure
        self.late_from: float | None = None   # set while facts of a returning source are taken
        # each source's frames in its own sequence: held, fetched again, gaps (`sequence`)
        self.seq = Sequencer(self.take, self._frame, self.ks, log, lambda: self.max_held,
                             room=lambda: self.order.buffered() < self.order.max_buffered // 2,
                             session=lambda: self.session, also_held=lambda: self.bygroup.bytes)
        # sources publishing by key group: their flushes assembled from the groups its interest
        # hears, decided at a deterministic point (`_interest_at`)
        self.bygroup = GroupIntake(self.ks, self.max_bytes, self.gate, log, journal=self.seq.journal_frames,
                                   streams=GF.streams_of(sc, root), interest=self.cfg.get("dissemination", {}),
                                   room=self.seq.fits)
        self.frames = 0
        self.rebuilding: str | None = None    # the source whose return the EA is being rebuilt for
        self.caught_up_to = -math.inf         # what a rebuilt EA raises at or before this is late
        self.rebuilds = 0
        self.history: list | None = None      # journal replay: the records taken so far (else the file)
        self.at_record: int | None = None     # the index of the input record a replay is taking
        # per lost source, the EA as it stood just before the loss: its return rebuilds from there
        self.before_loss = BeforeLosses((self, self.sc, self.ids), log)
        self.presence = PeerPresence(unit, self.ks, self.gate)   # the other EAs it watches
        self.misplaced: str | None = None   # why it is on the wrong router: said once on the mesh
        self.restoring = False                # a restarted peer replaying its own input journal
        self.catching_up = False              # ... then taking what its sources sent while it was down
        self.heard_again: set[str] = set()    # ... the sources heard since it came back (their edge known)
        self.restored = 0                     # input records the restart replayed
        # a fresh peer (no journal to replay): per source, whether it was under way when we
        # joined (its first frame heard was not its first): what we raise up to its edge is late
        self.join_late: dict[str, bool] | None = None
        # commands journalled before a rebuild or a restart, taken again at their event time:
        # (t, tie, kind, command)
        self.held_cmds: list[tuple[float, int, str, object]] = []
        self._cmd_tie = 0
        self.timeline = Timeline(self.ea.epoch_s, live_start)   # for benchmarks: epochs, alerts, latency, CPU

    @property
    def session(self):
        """Its Zenoh session while it is on the mesh (`serve`), else None (a journal replay)."""
        return self.out.session

    @session.setter
    def session(self, s) -> None:
        self.out.session = s

    @property
    def given(self) -> list[M.Alert]:
        """Every alert given, in order (the log's)."""
        return self.out.given

    # -- sinks ---------------------------------------------------------------------------
    def _sink(self, a: M.Alert) -> None:
        if not self.out.fresh(a, self.restoring):
            return   # raised already (by the EA before a rebuild, or before a restart): never twice
        self.timeline.raised(a)
        due = self.late_from
        if due is None and (a.t <= self.caught_up_to or self.restoring) and not a.details.get("wall_clock_driven"):
            due = a.t   # a rebuilt or restarted EA raises what fell due while a source was lost or it was down
        self.out.give(a, due)

    def _notice(self, n) -> None:
        if not self.restoring:   # re-notifications and escalations of the past are not sent again
            self.out.notice(n)

    def new_ea(self):
        """A fresh EA at event time 0, as the peer starts and as a rebuild from the start takes
        its journal again: the alert ids shared (never rewound), the sinks this peer's, the
        missions it infers started told up the chain (a domain that infers none, the robot
        team's, has nothing to tell)."""
        ea = make_ea(self.sc, self.unit, self.cfg, sinks=[self._sink])
        ea.notify.ids = self.ids
        ea.notice_sinks.append(self._notice)
        inferred = getattr(ea.domain, "inferred", None)
        if inferred is not None:
            inferred.append(self._confirm_up)
        if self.armed:
            ea.arm()
        ea.start(0.0)
        return ea

    def _confirm_up(self, c) -> None:
        commanded.confirm_up(self, c)
    def _system(self, subject: str, text: str, priority: str = "immediate", **details) -> None:
        self.log(f"system {subject}: {text}", flush=True)
        self.ea.emit(M.Alert(round(max(self.ea.now, 0.0), 3), self.unit, "unknown-position", "system-problem",
                             priority, (subject,), text, {"source": subject, "wall_clock_driven": True, **details}))

    # -- the other EAs: who is on the mesh (liveliness tokens; a clean leave says bye) ---------
    def _alive(self, key: str, up: bool) -> None:
        """A liveliness token of another EA came or went (`PeerPresence.token`): a change
        worth saying is a decision written to the input journal, so a replay says the same."""
        ch = self.presence.token(key, up, self.ea.domain.taskorg)
        if ch is None:
            return
        if self.journal is not None:
            self.journal.peer(*ch)
        self.peer_change(*ch)

    def peer_change(self, unit: str, up: bool) -> None:
        name = f"EA of {self.ea.domain.taskorg.name(unit)}"
        self.presence.said(unit, up)
        if up:
            self._system(unit, f"{name} is back on the mesh", "routine", event="peer-back")
        else:
            self._system(unit, f"{name} left the mesh without a goodbye (its process, host or link is down): "
                               f"its picture and confirmations no longer reach us", event="peer-lost")

    def _flood(self, sender: str, n: int, kinds: list[str]) -> None:
        """A sender's refused messages passed a threshold: one system problem each time
        (100, 1,000, 10,000, ...), never one per message."""
        self._system(sender.split("/", 1)[-1], f"{n} messages from {sender} refused ({', '.join(kinds)}): "
                             f"a fault or someone feeding this EA junk", event="flood", refused=n, kinds=kinds)

    # -- input ---------------------------------------------------------------------------
    def receive(self, payload: bytes, key: str) -> None:
        """A frame off the wire: taken in its source's own sequence (`Sequencer.arrive`); of a
        source publishing by key group, its progress frames are (`bygroup`)."""
        grp = self.bygroup.split_key(key)
        if grp is None:
            f = self._frame(payload, key)
        elif grp[0] not in self.order.watermarks():
            return   # a source this EA does not depend on
        else:
            f = self.bygroup.arrive(payload, key, *grp)
            if f is None:   # a group frame (kept): a progress frame waiting for it may go now
                if self.seq.hold.waiting:
                    self.seq.retry()
                return
        if f is None:
            return
        self.heard(f)
        if not self.seq.arrive(payload, key, f):
            self.watch.heard_from(f.source)   # heard (not silent), but not kept: fetched again

    def heard(self, f) -> None:
        """A frame heard off the wire while catching up (restarted, or joined late): what the
        EA raises up to its sources' edge is the past, given late."""
        if self.catching_up:   # what the EA raises up to the sources' edge when it came back is late
            late = True
            if self.join_late is not None:   # a late joiner: only sources already under way count
                late = self.join_late.setdefault(f.source, f.seq > 1)
                if not late and len(self.join_late) == len(self.sources) and not any(self.join_late.values()):
                    self.join_late, self.catching_up = None, False   # it joined before any began
            if late:
                self.caught_up_to = max(self.caught_up_to, f.wm if math.isfinite(f.wm) else self.caught_up_to)
            self.heard_again.add(f.source)

    def _order_bound(self) -> int:
        return max(1000, self.max_held // 2 // ORDER_ITEM_BYTES)

    def _frame(self, payload: bytes, key: str):
        try:
            f = F.decode(payload, self.max_bytes)
        except M.MessageError as e:
            self.gate.rejects.add(e, key)
            return None
        if key and key != self.ks.src(f.source):
            self.gate.rejects.add(M.MessageError("frame", "source", f"frame of {f.source!r} on {key[:80]}"), key)
            return None
        if f.source not in self.order.watermarks():
            return None   # a source this EA does not depend on
        return f

    def take(self, payload: bytes, key: str, journal: bool = True, f=None, retrying: bool = False) -> bool:
        """One frame, in its source's sequence: checked, ordered, journalled; then everything
        the watermarks allow is applied. False when the order could not take it yet (kept
        waiting for `Sequencer.retry`, and the source's later frames queue behind it; `retrying`:
        it is the head of that queue, offered again)."""
        if f is None:
            f = self._frame(payload, key)
            if f is None:
                return True
        if not retrying and journal and self.seq.hold.waiting_for(f.source):
            self.seq.hold.wait(f.source, (payload, key, f))
            return False
        grouped = type(f) is GF.Progress or f.groups is not None
        if journal and grouped and f.source in self.order.lost and self.rebuilding is None:
            # back, by key group: the EA is rebuilt first, so that what it hears of this flush is
            # decided by the rebuilt EA (as an EA that never lost the source decides it), not by
            # the one that went on without it and is thrown away
            if self.journal is not None:
                self.journal.back(f.source)
            self.back(f.source)
        if journal and grouped and not self._interest_at(f.source):
            if not retrying:   # by key group: taken once the EA stands at the source's last promise
                self.seq.hold.wait(f.source, (payload, key, f))
            return False
        if type(f) is GF.Progress:   # by key group: the flush, once the groups it hears are here
            whole = self.bygroup.assemble(f)
            if whole is None:
                if not retrying:
                    self.seq.hold.wait(f.source, (payload, key, f))
                return False
            f, payload, key = whole, F.encode(whole), self.ks.src(whole.source)
        elif journal and f.groups is not None:   # a whole flush from its journal: what it hears of it
            f = self.bygroup.heard_only(f)
            payload = F.encode(f)
        if f.source in self.order.lost and self.rebuilding is None:   # back: rebuild as if never lost
            if journal and self.journal is not None:
                self.journal.back(f.source)
            self.back(f.source)
        items = self.gate.data_many(f.msgs, key or f"src/{f.source}")
        kinds = {type(m) for m in items}
        if not kinds <= self.data_kinds:
            for m in items:
                if type(m) not in self.data_kinds:
                    self.gate.rejects.add(M.MessageError(m.KIND, "(kind)", f"a {m.KIND} message in a source's "
                                                                           "frame"), key)
            items = [m for m in items if type(m) in self.data_kinds]
        self.carried.note(f.source, kinds, items)
        why = self.order.take(f.source, f.epoch, f.seq, f.wm, items, f.end)
        if why == "full":   # the order's buffer is full: offered again after the next release, never dropped
            if not retrying:
                self.seq.hold.wait(f.source, (payload, key, f))
            return False
        if why is not None:
            return True
        if journal and self.journal is not None:   # what was taken, in the order taken: replays to the same
            self.journal.frame(payload)
        self.frames += 1
        self.watch.took(f)
        self._apply()
        return True

    def _interest_at(self, source: str) -> bool:
        """Whether the next flush of a source publishing by key group may be taken now, and
        then the groups the EA hears for it (its interest now). Taken only once everything up
        to the source's last promise is released, so the EA's state, and the interest it
        gives, is the same whatever the arrival order: what the EA hears of the flush depends
        on the data alone (docs/architecture.md, "Key groups on the live mesh")."""
        wm = self.order.watermarks().get(source, -math.inf)
        if self.order.released < wm and source not in self.order.lost:
            return False
        self.bygroup.interest(self.ea.domain)
        return True

    def back(self, source: str) -> None:
        """A lost source is heard again: the EA is rebuilt as if it had never been lost
        (`recover.rebuild`)."""
        recover.rebuild(self, source)
    def restart(self) -> int:
        """A restarted peer stands where it stood: its input journal replayed through the
        fresh EA (`recover.restart`). Returns the records replayed."""
        return recover.restart(self)
    def join(self) -> None:
        """A fresh peer (no journal to replay) joining the mesh: a source already under way
        (the first frame heard of it is not its first) tells it the past, and what the EA
        raises up to that source's edge is given late, as after a restart."""
        self.join_late, self.catching_up = {}, True

    def replay_record(self, rec: list) -> None:
        """One input-journal record taken again, as it was taken live (`journal.replay`)."""
        recover.replay_record(self, rec)
    def lose(self, source: str, why: str, journal: bool = True) -> None:
        """Declare a depended source lost: monitoring goes on without it (a logged decision)."""
        if source in self.order.lost:
            return
        n = self.at_record if self.at_record is not None else self.journal.n if self.journal is not None else None
        if n is not None:
            self.before_loss.keep(source, n, (self.ea, self.order, list(self.dirs.pending), list(self.held_cmds)))
        if journal and self.journal is not None:
            self.journal.lost(source, self.order.released, why)
        self.order.lose(source, why)
        self.carried.inhibit(self.ea, source, self.log)
        units = self.carried.units_of(source)
        named = ", ".join(units[:8]) + (f" and {len(units) - 8} more" if len(units) > 8 else "")
        wm = self.order.watermarks()[source]
        since = f"since {hms(wm)}" if math.isfinite(wm) and wm >= 0 else "at all"
        self._system(source, f"reports of source {source} not received {since}"
                             f" ({why}); monitoring of {named or 'what it reports'} degraded",
                     event="source-lost", why=why, units=units, declared_wall=round(time.time(), 3))
        self._apply()

    def _apply(self) -> None:
        """Everything the watermarks allow, in event-time order; then the late path."""
        upto = None   # every source ended or is lost: all they sent is released, nothing beyond
        if self.live_start is not None and math.isfinite(self.order.bound()):
            upto = time.time() - self.live_start   # live: never ahead of the wall clock either
        if self.dirs.pending or self.held_cmds:
            lim = min(self.order.bound(), math.inf if upto is None else upto)
            while True:
                dt = self.dirs.pending[0][1].t if self.dirs.pending else math.inf
                ct = self.held_cmds[0][0] if self.held_cmds else math.inf
                if min(dt, ct) > lim or dt == ct == math.inf:   # nothing held is due (the bound may be inf)
                    break
                if dt <= ct:   # a directive takes effect after the facts before its `at`, before those at it
                    tk = self.dirs.due(lim)
                    for m in self.order.release(math.nextafter(tk.t, -math.inf)):
                        self.ea.submit(m)
                    self.ea.advance(tk.t, strict=True)
                    commanded.take_directive(self, tk)
                else:          # a journalled command, after the facts at its time, as it was taken
                    t, _, _, cmd = heapq.heappop(self.held_cmds)
                    for m in self.order.release(t):
                        self.ea.submit(m)
                    self.ea.advance(t)
                    C.apply(self.ea, cmd, t)
        for m in self.order.release(upto):
            self.ea.submit(m)
        r = self.order.released
        if math.isfinite(r) and r >= self.ea.epoch_end:   # an epoch can close (else facts keep batching)
            self.ea.advance(r)
        self.timeline.released(r)
        if self.catching_up and r >= self.caught_up_to > -math.inf and self._edge_known():
            self.catching_up = False
            self.log(f"{'late join' if self.join_late is not None else 'restart'}: caught up to {hms(r)}", flush=True)
        if self.order.late:
            late, self.order.late[:] = list(self.order.late), []
            self.late_from = min(m.t for _, m in late)
            try:
                for _, m in sorted(late, key=lambda x: x[1].t):
                    self.ea.submit(m)
                self.ea.advance(max(self.ea.now, r if math.isfinite(r) else self.ea.now) + self.ea.epoch_s)
            finally:
                self.late_from = None

    def _edge_known(self) -> bool:
        """A restarted peer knows the sources' edge once every source it depends on was
        heard since (or ended, or is lost) and no frame waits in its queue: a source that
        restarted with it (the same host) or whose cache is still arriving would move it."""
        return self.q.empty() and all(s in self.heard_again or s in self.watch.ended or s in self.order.lost
                                      for s in self.sources)

    def directive(self, key: str, payload: bytes) -> None:
        """A directive off the wire (`commanded.directive`)."""
        commanded.directive(self, key, payload)
    def command(self, key: str, payload: bytes) -> None:
        """A commander's command (`commanded.command`), answered on cmdlog/<unit>."""
        commanded.command(self, key, payload)
    def end_t(self) -> float:
        """Where the EA finishes: the scenario's end for a recorded battle, else the furthest
        any source promised or sent (never the wall clock: the same live and when the
        journal is replayed)."""
        if self.live_start is None:
            return self.sc.duration_s
        return max([self.ea.now, *self.watch.furthest()])

    def done(self, now: float) -> bool:
        """Every source ended, or ended and lost ones (at least one ended: a mesh where
        every source is silent keeps waiting for them); lost ones waited for a while
        (`[mesh] source_end_wait_s`), said once."""
        waiting = self.watch.rest_ended is not None
        if self.watch.finished(self.order.lost, now):
            return True
        if not waiting and self.watch.rest_ended is not None:
            self.log(f"every other source ended: waiting up to {self.watch.end_wait_s:g} s for "
                     f"{', '.join(sorted(set(self.order.lost) - self.watch.ended))} (lost) to come back", flush=True)
        return False

    # -- loop ------------------------------------------------------------------------------
    def run(self, deadline_s: float | None = None, linger_s: float = 0.0) -> dict:
        """On the mesh until the sources end (`serve.serve`)."""
        from .serve import serve
        return serve(self, deadline_s, linger_s)

    def summary(self) -> dict:
        return {"unit": self.unit, "depends": self.sources, "alerts": len(self.given), "rebuilds": self.rebuilds,
                "restored": self.restored, "frames": self.frames, "misses": self.seq.misses,
                "fetched": self.seq.fetched, "dropped": self.seq.dropped + self.bygroup.dropped,
                "gaps": self.seq.gaps + self.bygroup.gaps,
                "late_alerts": self.out.late, "lost": dict(self.order.lost), "released": self.order.released,
                "rejects": dict(self.gate.rejects.by_kind), "rejects_by_sender": dict(self.gate.rejects.by_sender),
                "messages": self.ea.n_in, **self.timeline.summary()}


def main_live_peer(sc: Scenario, unit: str, conf, root: str, sources: list[str], out: str | None, config_path=None,
                   deadline_s: float | None = None, live_start: float | None = None, armed: bool = False,
                   linger_s: float = 0.0, misplaced: str | None = None) -> int:
    p = LivePeer(sc, unit, conf, root, sources, out, config_path,
                 log=lambda *a, **k: print(*a, **k), live_start=live_start, armed=armed)
    p.misplaced = misplaced
    p.run(deadline_s, linger_s)
    sys.stdout.flush()
    return 0
