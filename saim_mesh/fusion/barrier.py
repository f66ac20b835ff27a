"""The clock barrier for fused tracks: a peer holds each clock tick until every fusion
node has said its tracks up to that time are out (`fusion-tick/<group>`), so that every
peer takes each track at the same point of its stream, as the in-process run does.
A node that is gone or silent for `grace_s` of wall time is not waited for, and the
commander is told, until it publishes again."""
from __future__ import annotations

import time

from saim_mesh import wire as W
from saim_mesh.inbox import Inbox, Waker


class TrackBarrier:
    def __init__(self, peer, grace_s: float):
        self.peer, self.grace_s = peer, grace_s
        self.ftick = {g: -1.0 for g in peer.fusion_groups}   # clock time each node's tracks are out to
        self.lost: set[str] = set()
        self.sub: Inbox | None = None

    def open(self, s) -> None:
        if self.ftick:   # a node's marker wakes the wait (`Inbox`): no polling while a node is behind
            self.sub = Inbox(Waker(), 100_000)
            self.sub.decl = s.declare_subscriber(self.peer.ks.fusion_tick("*"), self.sub)

    def _take(self) -> None:
        while (m := self.sub.try_recv()) is not None:
            key = str(m.key_expr)
            g = key.rsplit("/", 1)[-1]
            ft = self.peer.gate.control(W.FusionTick, m.payload.to_bytes(), key)
            if g in self.ftick and ft is not None:
                self.ftick[g] = max(self.ftick[g], ft.t)

    def wait(self, t: float) -> None:
        """Return once every node still counted has its tracks out to `t`."""
        if self.sub is None:
            return
        p = self.peer
        give_up = None
        while True:
            self._take()
            p.presence.take()
            for g in [g for g in self.lost if self.ftick[g] >= t]:   # back on track
                self.lost.discard(g)
                p.system_alert(f"fusion-{g}", "routine", f"fusion node {g} is publishing tracks again",
                               event="fusion-back", fusion=g)
            behind = [g for g, ft in self.ftick.items() if ft < t and g not in self.lost]
            if not behind:
                return
            now = time.monotonic()
            give_up = give_up or now + self.grace_s
            if now > give_up:
                self.lost.update(behind)
                for g in behind:
                    p.system_alert(f"fusion-{g}", "immediate", f"fusion node {g} silent for {self.grace_s:.0f} s: "
                                   f"the clock goes on without its tracks", event="fusion-silent", fusion=g)
                return
            self.sub.waker.wait(min(0.05, give_up - now))   # woken by the next marker; the timeout sees a silence
