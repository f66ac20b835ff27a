"""What feeds the console's state: the mesh (a Zenoh session as `console.<U>`), or the
EAs of an in-process run: alerts, re-notifications and escalations (notices), command
results, the clock and the data messages it draws. Every mesh payload goes through
`gate.Gate` and must fit the key it came on; nothing received can stop the console (a
bad payload is counted).

No liveliness token: the replay's pacer waits for every `alive/<name>` it does not know
as fusion node or replay, and a console sends no acks, so a token would stall the
replay for its stall timeout. The console only listens and sends commands."""
from __future__ import annotations

import threading
from typing import Callable

import zenoh

from ea_agent import domains

from .. import messages as M
from .. import wire as W
from ..reader import MeshReader
from .actions import CommandActions, result_dict
from .state import State

CLASSES = {"suo": (M.LocationReport, M.SensorTrack, M.MissionConfirm, M.CallForFire, M.CallForFireConfirm,
                   M.Order, M.Reorganization),
           "uv": (M.UvState, M.UvSighting, M.UvAgent)}


class MeshFeed(MeshReader):
    """The console's mesh side (a `MeshReader`): each payload checked, into the state."""
    NAME = "console"

    def __init__(self, sc, conf: zenoh.Config, root: str, state: State, log: Callable = print):
        super().__init__(sc, conf, root, CLASSES.get(domains.of(sc).NAME, ()), log)
        self.state = state

    def keys(self) -> list[str]:
        r = self.ks.root
        data = sorted({self.ks.data(c) for c in self.classes})
        return [self.ks.clock(), f"{r}/alert/**", f"{r}/cmdlog/**", f"{r}/notice/**", *data]

    def take(self, key: str, payload: bytes) -> None:
        """One payload from the mesh, checked, into the state."""
        ks, gate, st = self.ks, self.gate, self.state
        fam = ks.family(key)
        if fam == "clock":
            tick = gate.control(W.Tick, payload, key)
            if tick is not None and not (tick.end and tick.t < self.sc.duration_s):
                self.first_tick()
                st.clock(tick.t, tick.end, tick.w)
            return
        if fam == "cmdlog":
            cls = getattr(W, "CmdResult", None)
            res = gate.control(cls, payload, key) if cls is not None else None
            if res is not None:
                st.result(result_dict(res, ks.last(key)[0]))
            return
        if fam == "notice":
            self.take_notice(key, payload)
            return
        m = gate.data(payload, key)
        if m is None:
            return
        ok = type(m) is M.Alert if fam == "alert" else type(m) in self.classes
        why = ks.mismatch(key, m) if ok else f"a {m.KIND} message on {fam}/ keys"
        if why is not None:
            gate.rejects.add(M.MessageError(m.KIND, "(key)", why), key)
        elif fam == "alert":
            st.alert(m)
        else:
            st.message(m)

    def take_notice(self, key: str, payload: bytes) -> None:
        """notice/<to>/<owner>: a re-notification (to = owner) or an escalation (to = the
        owner's superior), signed in secure mode; the key must name what it carries."""
        n = self.gate.control(W.Notice, payload, key, signed=True)
        if n is None:
            return
        to, owner = self.ks.last(key, 2)
        why = (f"a notice of {n.owner!r} on the key of {owner!r}" if n.owner != owner else
               f"a notice to {n.to!r} on the key of {to!r}" if n.to != to else
               f"a renotify notice to {to!r}, not its owner" if n.kind == "renotify" and to != owner else None)
        if why is not None:
            self.gate.rejects.add(M.MessageError("notice", "(key)", why), key)
            return
        d = {f: getattr(n, f) for f in n.__struct_fields__ if f != "v"}
        d["subjects"] = list(n.subjects)
        self.state.notice(d)

    def stored(self, messages: list, t: float) -> None:
        """At the first tick: every unit and confirmation so far (positions: the latest wins)."""
        for m in messages:
            self.state.message(m)
        if t > 0:   # a replay that ended (and lingers) still ends the console
            self.state.clock(t, t >= self.sc.duration_s)


def mesh_actions(feed: MeshFeed, timeout: float = 10.0) -> CommandActions:
    """Commands on the mesh, sent as this console's unit (the EA checks it commands it);
    their results come back on cmdlog/** to every console. Signed as this console's
    identity in secure mode. On the live mesh, orders and confirmations are directives
    (saim_mesh/directives.py): published once, taken by every EA they concern."""
    from ..security.sign import signer_for
    signer = signer_for(feed.conf)

    def run(unit: str, cmd):
        from .. import commands
        return commands.send(feed.session, feed.ks, unit, cmd, feed.state.unit, timeout, signer)

    def direct(unit: str, kind: str, fields: dict) -> str:
        from .. import directives as D
        return D.publish(feed.session, feed.ks.root, signer, unit, kind, **fields).req
    return CommandActions(run, feed.state, push=False, direct=direct if isinstance(feed, LiveFeed) else None)


def hook_inprocess(eas: list, sc, state: State) -> CommandActions:
    """Tie the state to in-process EAs: alerts from their sinks, messages and time from
    the first EA's input; commands applied under a lock the EAs' inputs also take, so a
    command never lands in the middle of an epoch."""
    lock = threading.RLock()
    by_owner = {ea.owner: ea for ea in eas}

    def guard(ea, name: str, before=None):
        inner = getattr(ea, name)

        def call(x, *a):
            if before is not None:
                before(x)
            with lock:
                return inner(x, *a)
        setattr(ea, name, call)

    def notice(n) -> None:
        state.notice(n.to_json_dict())

    for i, ea in enumerate(eas):
        ea.sinks.append(state.alert)
        ea.notice_sinks.append(notice)   # its own re-notifications and escalations (the runner routes
        #                                  escalations to a superior's EA run here; the page needs them once)
        first = i == 0
        guard(ea, "submit", (lambda m: (state.message(m), state.clock(m.t))) if first else None)
        guard(ea, "advance", state.clock if first else None)
        guard(ea, "finish", (lambda t: state.clock(t, end=True)) if first else None)

    def run(unit: str, cmd):
        from .. import commands
        with lock:
            return commands.apply(by_owner[unit], cmd)
    return CommandActions(run, state, push=True)


def serve_inprocess(eas: list, sc, port: int = 0):
    """(server, state) for an in-process run: the console over these EAs."""
    from .server import Server, make_app
    owners = [ea.owner for ea in eas]
    top = min(owners, key=lambda u: len(sc.taskorg.ancestors(u))) if owners else None
    state = State(sc, top, actors=owners)
    actions = hook_inprocess(eas, sc, state)
    server = Server(make_app(state, actions), port)
    server.start()
    return server, state


class LiveFeed(MeshFeed):
    """The console on the live mesh (no replay, no store): the data it draws comes in the
    sources' frames (`src/<name>`), each message checked as an EA checks it; its clock is
    the event time every source it has heard has promised (the minimum watermark), the
    end when every one of them has ended."""
    NAME = "console-live"

    def __init__(self, sc, conf: zenoh.Config, root: str, state: State, log: Callable = print):
        super().__init__(sc, conf, root, state, log)
        self.caught_up = True   # nothing to catch up from: the sources' caches serve history
        from ..live.frames import FrameReader
        self.frames = FrameReader(self.ks, self.gate, sc.duration_s, log)

    def keys(self) -> list[str]:
        r = self.ks.root
        return [f"{r}/alert/**", f"{r}/cmdlog/**", f"{r}/notice/**", self.ks.src("*")]

    def take(self, key: str, payload: bytes) -> None:
        if self.ks.family(key) != "src":
            return super().take(key, payload)
        msgs = self.frames.read(key, payload)
        if msgs is None:
            return
        for m in msgs:
            if type(m) in self.classes:
                self.state.message(m)
        t, end = self.frames.clock()
        self.state.clock(t, end)
