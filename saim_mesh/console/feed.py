"""What feeds the console's state: the mesh (a Zenoh session as `console.<U>`), or the
EAs of an in-process run. Every mesh payload goes through `wire.Gate` and must fit the
key it came on; nothing received can stop the console (a bad payload is counted).

No liveliness token: the replay's pacer waits for every `alive/<name>` it does not know
as fusion node or replay, and a console sends no acks, so a token would stall the
replay for its stall timeout. The console only listens and sends commands."""
from __future__ import annotations

import queue
import threading
from typing import Callable

import zenoh

from dissemination.keyspace import KeySpace
from ea_agent import domains

from .. import messages as M
from .. import wire as W
from .actions import CommandActions, result_dict
from .state import State

CLASSES = {"suo": (M.LocationReport, M.SensorTrack, M.MissionConfirm, M.CallForFire, M.CallForFireConfirm,
                   M.Order, M.Reorganization),
           "uv": (M.UvState, M.UvSighting, M.UvAgent)}


class MeshFeed:
    """Subscriptions into one queue, taken by one thread (the gate and the state see
    one payload at a time, in arrival order)."""

    def __init__(self, sc, conf: zenoh.Config, root: str, state: State, log: Callable = print):
        self.sc, self.conf, self.state, self.log = sc, conf, state, log
        self.ks = KeySpace.of(sc, root)
        self.gate = W.Gate(sc.duration_s, log=log)
        self.classes = CLASSES.get(domains.of(sc).NAME, ())
        self.q: queue.SimpleQueue = queue.SimpleQueue()
        self.session = None
        self.caught_up = False
        self.subs: list = []
        self.thread = threading.Thread(target=self._loop, name="console-feed", daemon=True)

    def keys(self) -> list[str]:
        r = self.ks.root
        data = sorted({self.ks.data(c) for c in self.classes})
        return [self.ks.clock(), f"{r}/alert/**", f"{r}/cmdlog/**", *data]

    def open(self) -> None:
        self.session = s = zenoh.open(self.conf)
        put = self.q.put
        for k in self.keys():
            self.subs.append(s.declare_subscriber(k, lambda smp: put((str(smp.key_expr), smp.payload.to_bytes()))))
        self.thread.start()

    def close(self) -> None:
        self.q.put(None)
        self.thread.join(5.0)
        for sub in self.subs:
            sub.undeclare()
        if self.session is not None:
            self.session.close()
            self.session = None

    def _loop(self) -> None:
        while True:
            try:
                item = self.q.get(timeout=2.0)
            except queue.Empty:   # quiet: joined late (or after the end)? ask the store
                if not self.caught_up:
                    self.caught_up = self.catch_up(timeout=2.0)
                continue
            if item is None:
                return
            try:
                self.take(*item)
            except Exception as e:   # a bug here must not end the feed: said, counted, skipped
                self.gate.rejects.add(M.MessageError("?", "(console)", f"{type(e).__name__}: {e}"[:200]), item[0])

    def take(self, key: str, payload: bytes) -> None:
        """One payload from the mesh, checked, into the state."""
        ks, gate, st = self.ks, self.gate, self.state
        fam = ks.family(key)
        if fam == "clock":
            tick = gate.control(W.Tick, payload, key)
            if tick is not None and not (tick.end and tick.t < self.sc.duration_s):
                if not self.caught_up:
                    self.caught_up = True
                    self.catch_up()
                st.clock(tick.t, tick.end, tick.w)
            return
        if fam == "cmdlog":
            cls = getattr(W, "CmdResult", None)
            res = gate.control(cls, payload, key) if cls is not None else None
            if res is not None:
                st.result(result_dict(res, ks.last(key)[0]))
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


    def catch_up(self, timeout: float = 10.0) -> bool:
        """The picture so far from the situation store, at the first tick: a console that
        joins late, or whose subscriptions reached the replay after its first messages,
        still shows every unit and confirmation (positions: the latest wins anyway)."""
        if self.session is None:
            return False
        keys = sorted({self.ks.data(c) for c in self.classes})
        req = W.encode(W.make(W.StoreQuery, since=0, keys=keys))
        try:
            replies = list(self.session.get(self.ks.store(), payload=req, timeout=timeout))
        except Exception as e:   # no store reachable (access control, no replay): live data only
            self.log(f"console: no catch-up from the store ({type(e).__name__})", flush=True)
            return False
        for r in replies:
            if r.ok is None:
                continue
            rep = self.gate.control(W.StoreReply, r.ok.payload.to_bytes(), str(r.ok.key_expr))
            for _, p in rep.entries if rep is not None else ():
                m = self.gate.data(p, "store")
                if m is not None and type(m) in self.classes:
                    self.state.message(m)
            if rep is not None:
                if rep.t > 0:   # a replay that ended (and lingers) still ends the console
                    self.state.clock(rep.t, rep.t >= self.sc.duration_s)
                return True
        return False


def mesh_actions(feed: MeshFeed, timeout: float = 10.0) -> CommandActions:
    """Commands on the mesh; their results come back on cmdlog/** to every console."""
    def run(unit: str, cmd):
        from .. import commands
        return commands.send(feed.session, feed.ks, unit, cmd, timeout)
    return CommandActions(run, feed.state, push=False)


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

    for i, ea in enumerate(eas):
        ea.sinks.append(state.alert)
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
