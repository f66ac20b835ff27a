"""A live source: one producer of facts (a unit's own reporter, a command post's share
of a recorded scenario, a TAK gateway's PLI) publishing its own stream of frames and
watermarks on `<root>/src/<name>`, with no clock and no sequencer but its own.

`zenoh.ext`'s advanced publisher keeps the per-source order, a cache that late joiners
and subscribers that missed samples (a cut link) recover from, and heartbeats that let
a subscriber detect what it missed (../shared/notes/live-mesh.md: a 15 s partition healed
with nothing lost). The epoch is persisted and bumped at each start when a state folder
is given (else the start time in ns, also increasing), so a restarted source is never
taken for a duplicate of its former self."""
from __future__ import annotations

import time
from pathlib import Path

import zenoh
import zenoh.ext as zx

from dissemination.keyspace import KeySpace

from ..protocol import messages as M
from . import frames as F
from . import groupframes as GF
from .srcjournal import CATCH_UP_KBIT, YIELDING, Pacer, SourceJournal

BLOCK = zenoh.CongestionControl.BLOCK
CACHE = 100_000        # frames kept for recovery and late joiners (a frame is one flush)
# frames an EA's subscriber asks of the publishers it finds when it is declared (a late
# joiner, a restarted EA: a source with no journal has nothing else to give it). It does not
# ask again when a publisher reappears: zenoh.ext's late-publisher detection asks the last
# `max_samples` at every liveliness PUT, a healed link's too, whatever the subscriber has, so
# k EAs behind a healed radio link pulled k copies of each source's whole history at each
# heal and each flap, and the link never recovered. A healed link's gap comes by range
# instead (the heartbeat's recovery, from the last frame delivered) and, beyond the cache,
# from the source's journal (`Sequencer`).
HISTORY = CACHE
# the cache of a source that yields across radio links and keeps a journal: a heal's
# recovery asks the cache for every frame missed at once, one copy per EA behind the link
# (k EAs on a host: k copies at the same moment), which filled the link and held up the
# live frames of other sources that share it. A small cache leaves the rest of the gap to
# the journal, whose answers are paced over all askers together (`Pacer`); what each cache
# size costs a healed host link is measured by bench_hosts (bench/results/hosts_cut_*).
YIELDING_CACHE = 4
FRAME_BYTES = 48_000   # a frame is flushed before it grows past this (the gate's bound is 64 KiB)
LINGER_S = 0.05        # the longest a lingering source holds a watermark back (wall seconds)
# by key group, the event time one flush spans at most, lingering or not: an EA decides
# what it hears of a flush from its interest at the flush's start (`LivePeer._interest_at`),
# so a flush is as long as a re-registration's period ([dissemination] reregister_s)
GROUP_SPAN_S = 30.0


def next_epoch(state_dir: str | Path | None, name: str) -> int:
    """The epoch of this start: one more than the last one persisted for `name`."""
    if state_dir is None:
        return time.time_ns()
    p = Path(state_dir) / f"{name}.epoch"
    p.parent.mkdir(parents=True, exist_ok=True)
    try:
        last = int(p.read_text().strip() or "0")
    except (OSError, ValueError):
        last = 0
    epoch = last + 1
    tmp = p.with_suffix(".tmp")
    tmp.write_text(f"{epoch}\n")
    tmp.replace(p)   # atomic: a kill leaves the old epoch or the new one, never half
    return epoch


class LiveSource:
    """Publish data messages and watermarks as one source. Not thread-safe: one writer."""

    groups = None        # a message -> its key group (None: one whole stream); set by __init__
    pending_t0 = 0.0     # event time of the first message pending

    def __init__(self, session, ks: KeySpace, name: str, state_dir: str | Path | None = None,
                 cache: int | None = None, frame_bytes: int = FRAME_BYTES, yielding: bool = False,
                 catch_up_kbit: float | None = None, groups=None):
        """`yielding` (across slow radio links): what it sends again for recoveries and
        catch-ups (its cache's and its journal's replies) yields to live traffic: DROP at a
        lower priority, so no router stalls on it and closes its links; the EAs ask again.
        Its journal's answers are then paced at `catch_up_kbit` (default `CATCH_UP_KBIT`)
        over all askers together: k EAs beyond one link pull k copies of a gap.
        `groups` (a message -> its key group, `grouper`): each flush goes out by group
        (`groupframes`: a stream per group, `src/<name>/<group>`, and the progress stream
        `src/<name>/_p`), so that each EA hears only the groups of its interest."""
        if cache is None:
            cache = YIELDING_CACHE if yielding and state_dir is not None else CACHE
        if cache < 1:
            raise ValueError(f"source {name}: --cache {cache}: at least 1 frame")
        F.Frame(v=1, source=name, epoch=0, seq=1, wm=0.0)   # the name is checked as a frame checks it
        self.name, self.ks = name, ks
        self.epoch = next_epoch(state_dir, name)
        self.seq = 0
        self.wm = -1.0
        self.frame_bytes = frame_bytes
        self.pending: list[bytes] = []
        self.size = 0
        self.last_sent = 0.0
        self.sent = 0
        # the durable journal (with a state directory), served for catch-up beyond the cache
        qos = YIELDING if yielding else None
        if catch_up_kbit is None and yielding:
            catch_up_kbit = CATCH_UP_KBIT
        pacer = Pacer(catch_up_kbit * 1000 / 8) if catch_up_kbit is not None else None
        self.journal = SourceJournal(state_dir, name, self.epoch, qos, pacer) if state_dir is not None else None
        # a restart (its journal holds earlier epochs) resumes after what it published then:
        # `publish` skips that many messages of the same stream, and nothing older follows
        self.published_before, self.resumed_epoch = 0, 0
        if self.journal is not None:
            self.published_before, wm, self.resumed_epoch = self.journal.before()
            self.wm = max(self.wm, wm)
        self.queryable = None
        if self.journal is not None:
            jkey = ks.srcj(name)
            self.queryable = session.declare_queryable(jkey, lambda q: self.journal.serve(q, jkey))
        self.groups, self.session, self.cache, self.qos = groups, session, cache, qos
        self.pending_groups: list[str] = []
        self.pending_t0 = 0.0                   # event time of the first message pending
        self.group_seq: dict[str, int] = {}     # each group's last frame seq
        self.group_pubs: dict[str, object] = {}
        # whole stream, or (by group) the progress stream; its heartbeat is periodic: one per source
        self.pub = self._publisher(ks.src(name) if groups is None else f"{ks.src(name)}/{GF.PROGRESS}", sporadic=False)

    def _publisher(self, key: str, sporadic: bool = True):
        """An advanced publisher: its cache, and miss detection. A group's heartbeat is
        sporadic (only after it published): periodic heartbeats of hundreds of idle group
        publishers fill a radio link (../shared/notes/live-mesh.md, "Key groups")."""
        miss = zx.MissDetectionConfig(sporadic_heartbeat=0.5) if sporadic else zx.MissDetectionConfig(heartbeat=0.5)
        return zx.declare_advanced_publisher(
            self.session, key, congestion_control=BLOCK,
            cache=zx.CacheConfig(max_samples=self.cache,
                                 replies_config=zx.RepliesConfig(**self.qos) if self.qos else None),
            sample_miss_detection=miss, publisher_detection=True)

    def put(self, msg: M.Message) -> None:
        """One data message; its event time must be after the watermark already given.
        ValueError or MessageError (naming the field) when it is not a valid message."""
        if msg.t <= self.wm:
            raise ValueError(f"source {self.name}: {msg.KIND} at t={msg.t} is not after its watermark {self.wm} "
                             f"(it promised nothing at or before it would follow)")
        b = M.encode(msg)
        M.decode(b)   # checked as every receiver will check it (a NaN, a bad id): MessageError here, not there
        if self.pending and (self.size + len(b) > self.frame_bytes or len(self.pending) >= F.MAX_MSGS):
            self._send(self.wm)
        if not self.pending:
            self.pending_t0 = msg.t
        self.pending.append(b)
        if self.groups is not None:
            self.pending_groups.append(self.groups(msg))
        self.size += len(b)

    def watermark(self, t: float, linger: bool = False) -> None:
        """Nothing at or before `t` will follow: flushes what is pending with that promise.
        `linger` (a replay as fast as possible): the promise rides on the next frame that
        fills up, at most `LINGER_S` of wall time later (Kafka's linger.ms): fewer, fuller
        frames cost every receiver less per message and change nothing it concludes (the
        order is by event time, not by frame), and no receiver waits long enough on a
        lingering source to take it for a silent one."""
        if t <= self.wm and not self.pending:
            return   # nothing new to say
        if linger and time.monotonic() - self.last_sent < LINGER_S and not (
                self.groups is not None and self.pending and t - self.pending_t0 >= GROUP_SPAN_S):
            self.wm = max(self.wm, t)
            return
        self._send(max(t, self.wm))

    def heartbeat(self) -> None:
        """An empty frame, the watermark unchanged: alive, held back (`pace.SourcePace`),
        not silent. Whatever is pending goes with it."""
        self._send(self.wm)

    def close(self, end: bool = True) -> None:
        """The last frame (`end`: the source is done: its watermark is +inf). The publisher
        (its cache, for late joiners and recoveries) and the journal's queryable stay until
        `stop` or the session's end: a source lingers to serve them."""
        self._send(self.wm, end=end)

    def linger(self, least_s: float, most_s: float, clock=time.monotonic, sleep=time.sleep) -> float:
        """Stay up after the end (the cache and the journal serve late joiners and
        catch-ups): at least `least_s`, then as long as the journal was asked within the
        last `least_s`, at most `most_s` in all. A source that left while EAs were still
        catching up from it (a healed link: k EAs pull k copies through one radio) left
        them a gap they could not fill. Returns the seconds it stayed."""
        start = clock()
        end = start + least_s
        while (now := clock()) < min(end, start + max(most_s, least_s)):
            sleep(min(1.0, end - now))
            asked = self.journal.asked_at if self.journal is not None else None
            if asked is not None:
                end = max(end, asked + least_s)
        return clock() - start

    def stop(self) -> None:
        """Undeclare the publisher and the journal's queryable; close the journal."""
        self.pub.undeclare()
        for p in self.group_pubs.values():
            p.undeclare()
        if self.queryable is not None:
            self.queryable.undeclare()
        if self.journal is not None:
            self.journal.close()

    def _send(self, wm: float, end: bool = False) -> None:
        self.seq += 1
        self.wm = max(self.wm, wm)
        if self.groups is not None:
            self._send_groups(end)
            return
        f = F.Frame(v=1, source=self.name, epoch=self.epoch, seq=self.seq, wm=self.wm, msgs=self.pending, end=end)
        payload = F.encode(f)
        if self.journal is not None:   # on disk before it is on the wire
            self.journal.append(self.seq, payload)
        self.pub.put(payload)
        self.sent += len(self.pending)
        self.pending, self.size = [], 0
        self.last_sent = time.monotonic()

    def _send_groups(self, end: bool) -> None:
        """Flush `seq` by group: the group frames first, then the progress frame that says
        which groups it holds (an EA that has it knows what it should have); the whole
        flush, each message's group with it, in the journal."""
        gfs, prog, whole = GF.split(self.name, self.epoch, self.seq, self.wm, self.pending, self.pending_groups,
                                    self.group_seq, end)
        if self.journal is not None:   # on disk before it is on the wire
            self.journal.append(self.seq, F.encode(whole))
        for gf in gfs:
            pub = self.group_pubs.get(gf.group)
            if pub is None:
                pub = self.group_pubs[gf.group] = self._publisher(f"{self.ks.src(self.name)}/{gf.group}")
            pub.put(GF.encode(gf))
        self.pub.put(GF.encode(prog))
        self.sent += len(self.pending)
        self.pending, self.pending_groups, self.size = [], [], 0
        self.last_sent = time.monotonic()
