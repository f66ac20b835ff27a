"""Who is on the mesh, as one EA peer sees it: its superior, subordinates and the
fusion nodes (liveliness tokens), clean leaves (`bye`), and its subordinates'
health reports. Each change worth a commander's attention becomes a system-problem
alert on the peer; everything received is checked like any other payload."""
from __future__ import annotations

import zenoh

from . import wire as W


class Presence:
    def __init__(self, peer, s):
        self.peer = peer
        ks = peer.ks
        self.alive = s.liveliness().declare_subscriber(ks.alive("*", "*"), zenoh.handlers.FifoChannel(4096),
                                                       history=True)
        self.bye = s.declare_subscriber(ks.bye("*"), zenoh.handlers.FifoChannel(4096))
        self.health = s.declare_subscriber(ks.health("*"), zenoh.handlers.FifoChannel(4096))
        self.state: dict[str, str] = {}    # unit or fusion-<group> -> "up" / "down"
        self.clean: set[str] = set()       # said bye: its leaving is no alarm
        self.health_said: dict[str, int] = {}

    def _watched(self) -> set[str]:
        p = self.peer
        to = p.ea.domain.taskorg
        return (set(to.children(p.unit)) | set(to.subtree(p.unit)) | set(to.ancestors(p.unit)[:1])
                | {f"fusion-{g}" for g in p.fusion_groups})

    def take(self) -> None:
        p, gate = self.peer, self.peer.gate
        while (b := self.bye.try_recv()) is not None:
            key = str(b.key_expr)
            msg = gate.control(W.Bye, b.payload.to_bytes(), key)
            if msg is not None and p.ks.last(key) == [msg.unit]:
                self.clean.add(msg.unit)
        watch = None
        while (s := self.alive.try_recv()) is not None:
            unit = p.ks.last(str(s.key_expr), 2)[0]   # <root>/alive/<unit>/<zid>
            watch = watch if watch is not None else self._watched()
            if unit == p.unit or unit not in watch:
                continue
            self._change(unit, s.kind == zenoh.SampleKind.PUT)
        while (h := self.health.try_recv()) is not None:
            key = str(h.key_expr)
            msg = gate.control(W.Health, h.payload.to_bytes(), key)
            if msg is None or p.ks.last(key) != [msg.unit]:
                continue
            if msg.unit in p.ea.domain.taskorg.children(p.unit) and msg.rejects > self.health_said.get(msg.unit, 0):
                self.health_said[msg.unit] = msg.rejects
                kinds = ", ".join(f"{k} {n}" for k, n in sorted(msg.by_kind.items(), key=lambda x: -x[1])[:4])
                p.system_alert(msg.unit, "priority", f"EA of {p.ea.domain.taskorg.name(msg.unit)} rejected "
                               f"{msg.rejects} bad messages ({kinds}): someone may be feeding it junk",
                               event="rejects", rejects=msg.rejects)

    def _change(self, unit: str, up: bool) -> None:
        p = self.peer
        before = self.state.get(unit)
        self.state[unit] = "up" if up else "down"
        fusion = unit.startswith("fusion-")
        name = f"fusion node {unit[7:]}" if fusion else f"EA of {p.ea.domain.taskorg.name(unit)}"
        if not up:
            if unit in self.clean:
                return
            what = ("its tracks stop until it is back" if fusion
                    else "its picture and confirmations no longer reach us")
            p.system_alert(unit, "immediate", f"{name} left the mesh: {what}", event="left", left=True)
        else:
            self.clean.discard(unit)
            if before == "down":
                p.system_alert(unit, "routine", f"{name} is back on the mesh", event="back", left=False)
