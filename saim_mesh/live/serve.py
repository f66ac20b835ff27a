"""The live peer on the mesh: its Zenoh session and declarations (an advanced subscriber
per source it depends on, commands, directives, the other EAs' liveliness and goodbyes), and
the one loop that takes whatever came, in arrival order, on one thread. The logic is the
peer's (`LivePeer`); this is only its wiring, so a journal replays through the same peer
without any of it."""
from __future__ import annotations

import json
import math
import queue
import signal
import time

import zenoh
import zenoh.ext as zx

from ..protocol import wire as W
from . import commanded
from . import groupframes as GF
from .pace import EaProgress
from .peer import BLOCK, CHECK_S
from .source import HISTORY


def serve(peer, deadline_s: float | None = None, linger_s: float = 0.0) -> dict:
    """Run `peer` on the mesh until its sources end (or `deadline_s` of wall time): its
    subscriptions, its liveliness token, its queryable of directives, and the loop that takes
    what comes one item at a time on this thread; its summary."""
    def stop(*_):
        raise SystemExit(0)
    signal.signal(signal.SIGTERM, stop)
    end_wall = time.monotonic() + deadline_s if deadline_s else math.inf
    try:
        if not peer.restart():
            peer.join()
        with zenoh.open(peer.conf) as s:
            peer.session = s
            put, came = peer.q.put, peer.watch.arrived

            def frames_of(name: str):   # a frame queued, its arrival noted: silence is the source's
                return lambda smp: (came(name), put((str(smp.key_expr), smp.payload.to_bytes())))
            # per source depended on: its whole stream, or its progress stream and the key groups
            # of the EA's interest (`bygroup`), re-declared as the interest changes; nothing else
            # crosses a link to us
            def declare(name: str, key: str):
                sub = zx.declare_advanced_subscriber(
                    s, key, frames_of(name), history=zx.HistoryConfig(detect_late_publishers=False, max_samples=HISTORY),
                    recovery=zx.RecoveryConfig(heartbeat=True), subscriber_detection=True)
                return sub, sub.sample_miss_listener(lambda miss: put(("miss", miss.nb)))
            peer.bygroup.interest(peer.ea.domain)
            subs = {(name, k): declare(name, key) for name in peer.sources
                    for k, key in ((None, peer.ks.src(name)), (GF.PROGRESS, f"{peer.ks.src(name)}/{GF.PROGRESS}"))}
            groups: dict = {}

            def regroup() -> None:   # the group subscriptions the interest wants now
                want = {(n, e) for n in peer.sources for e in peer.bygroup.want}
                for k in [k for k in groups if k not in want]:
                    for x in reversed(groups.pop(k)):
                        x.undeclare()
                for n, e in sorted(want - set(groups)):
                    groups[(n, e)] = declare(n, f"{peer.ks.src(n)}/{e}")
                regroup.version = peer.bygroup.version
            regroup()
            cmds = s.declare_subscriber(peer.ks.cmd(peer.unit, "*", "*"),
                                        lambda smp: put(("cmd", (str(smp.key_expr), smp.payload.to_bytes()))))
            dirs = s.declare_subscriber(f"{peer.ks.root}/dir/*/*",
                                        lambda smp: put(("dir", (str(smp.key_expr), smp.payload.to_bytes()))))
            dirj = s.declare_queryable(f"{peer.ks.root}/dirj/{peer.unit}", lambda q: put(("dirq", q)))
            token = s.liveliness().declare_token(peer.ks.alive(peer.unit, str(s.info.zid())))
            alive = s.liveliness().declare_subscriber(
                peer.ks.alive("*", "*"), lambda smp: put(("alive", (str(smp.key_expr),
                                                                    smp.kind == zenoh.SampleKind.PUT))),
                history=True)
            byes = s.declare_subscriber(peer.ks.bye("*"),
                                        lambda smp: put(("bye", (str(smp.key_expr), smp.payload.to_bytes()))))
            # a late joiner: the directives taken so far, from the other EAs' journals
            s.get(f"{peer.ks.root}/dirj/*", lambda r: put(("dirj", r.ok.payload.to_bytes())) if r.ok else None,
                  consolidation=zenoh.ConsolidationMode.NONE, timeout=10.0)
            peer.log(f"ready {peer.unit} sources={','.join(peer.sources)}"
                     + (f" (not depending on {','.join(sorted(set(peer.named) - set(peer.sources)))})"
                        if len(peer.sources) < len(peer.named) else ""), flush=True)
            if peer.misplaced:
                peer._system(peer.unit, peer.misplaced, "priority", event="wrong-router")
            peer.watch.started = time.monotonic()   # a source never heard is waited for from here
            next_check = 0.0
            progress = EaProgress(peer.ks, peer.unit)
            while not peer.done(time.monotonic()) and time.monotonic() < end_wall:
                try:   # frames waiting for the release (key groups) are offered again soon
                    key, payload = peer.q.get(timeout=CHECK_S if peer.seq.hold.sources_waiting() else 0.5)
                except queue.Empty:
                    key = None
                if key == "miss":
                    peer.seq.misses += payload
                    peer.log(f"missed {payload} frames beyond the publisher's cache", flush=True)
                elif key == "alive":
                    peer._alive(*payload)
                elif key == "bye":
                    peer.presence.bye(*payload)
                elif key is not None and not _authority(peer, key, payload):
                    peer.receive(payload, key)
                if peer.bygroup.version != regroup.version:
                    regroup()
                now = time.monotonic()
                if key is not None and now < next_check:
                    continue   # while frames flow, the checks below run every CHECK_S
                next_check = now + CHECK_S
                peer.out.inputs_on_disk()
                peer.seq.checks(now)   # refused frames again, sources fetched again, gaps waited out
                for src, why in peer.watch.silent(now, peer.order):
                    peer.lose(src, why)   # silence: a decision, journalled
                if peer.live_start is not None:
                    peer._apply()
                progress.send(s, peer.order.released, peer.sources)   # how far it got: its sources' pace
            _drain(peer)   # what came with the sources' last frames is taken, not dropped
            peer.ea.finish(peer.end_t())
            peer.log("end " + json.dumps({k: v for k, v in peer.summary().items()
                                          if k not in ("timeline", "alert_latencies_ms", "due_latencies_ms")},
                                         sort_keys=True), flush=True)
            linger_end = time.monotonic() + linger_s   # still answering commands (a late ack)
            while (left := linger_end - time.monotonic()) > 0:
                try:
                    key, payload = peer.q.get(timeout=left)
                except queue.Empty:
                    break
                if key == "cmd":
                    peer.command(*payload)
                elif key == "dirq":
                    commanded.serve_directives(peer, payload)
            s.put(peer.ks.bye(peer.unit), W.encode(W.make(W.Bye, unit=peer.unit)), congestion_control=BLOCK)
            for x in (cmds, dirs, dirj, alive, byes, token):
                x.undeclare()
            for pair in (*subs.values(), *groups.values()):
                for x in reversed(pair):
                    x.undeclare()
            peer.session = None
    finally:
        peer.out.close()   # its logs and its input journal
    summary = peer.summary()
    peer.log("summary " + json.dumps(summary, sort_keys=True), flush=True)
    return summary


def _drain(peer) -> None:
    """Commands and directives already queued when the sources ended (a fast replay ends
    before what an EA published on the way reaches its peers): taken now, late if past."""
    while True:
        try:
            key, payload = peer.q.get_nowait()
        except queue.Empty:
            return
        _authority(peer, key, payload)


def _authority(peer, key: str, payload) -> bool:
    """A commander's command or a directive (or a late joiner's question or answer about
    them) taken; False for anything else."""
    if key == "cmd":
        peer.command(*payload)
    elif key == "dir":
        peer.directive(*payload)
    elif key == "dirj":
        commanded.joined(peer, payload)
    elif key == "dirq":
        commanded.serve_directives(peer, payload)
    else:
        return False
    return True
