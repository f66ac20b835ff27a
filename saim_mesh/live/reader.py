"""A reader of the live mesh that is not an EA (the commander's console, the TAK gateway).

It subscribes to what the live mesh publishes: the sources' frames (`src/*`: the picture
and, from their watermarks, the clock), the EAs' alerts, notices and command logs. Every
payload goes through `gate.Gate` and must fit the key it came on; what passes goes to a
*view* (the console's state, the gateway's picture), which only ever sees checked
objects. One queue taken by one thread, so the gate and the view see one payload at a
time, in arrival order; nothing received can stop it (a bad payload, or a bug in the
view, is counted).

No ticks, no situation store, no batches: the sources' caches and journals serve a late
joiner."""
from __future__ import annotations

import queue
import threading
import time
from typing import Callable, Protocol

from dissemination.keyspace import KeySpace

from ..protocol import gate as G
from ..protocol import messages as M
from ..protocol import wire as W
from ..security.sign import verifier_for
from .frames import FrameReader


class View(Protocol):
    """What a reader hands on, checked. `alert` and `result` may return why they refuse
    what the reader could not know was wrong (counted as a reject)."""

    def data(self, msgs: list) -> None: ...

    def clock(self, t: float, end: bool, w: float | None = None) -> None: ...

    def alert(self, m: M.Alert) -> str | None: ...

    def result(self, res: W.CmdResult, owner: str) -> str | None: ...

    def notice(self, n: W.Notice) -> None: ...


class Checks:
    """alert/, cmdlog/ and notice/ payloads: checked by the gate and against their key,
    then to the view."""

    def __init__(self, ks: KeySpace, gate: G.Gate, view: View):
        self.ks, self.gate, self.view = ks, gate, view

    def keys(self) -> list[str]:
        return [f"{self.ks.root}/alert/**", self.ks.cmdlog("*"), self.ks.notice("*", "*")]

    def refuse(self, kind: str, field: str, why: str, key: str) -> None:
        self.gate.rejects.add(M.MessageError(kind, field, why), key)

    def take(self, key: str, payload: bytes) -> bool:
        """True when the key was one of ours (taken or refused), False otherwise."""
        fam = self.ks.family(key)
        if fam == "alert":
            m = self.gate.data(payload, key)
            if m is None:
                return True
            why = self.ks.mismatch(key, m) if type(m) is M.Alert else f"a {m.KIND} message on alert/ keys"
            why = why or self.view.alert(m)
            if why is not None:
                self.refuse(m.KIND, "(key)", why, key)
        elif fam == "cmdlog":
            res = self.gate.control(W.CmdResult, payload, key)
            if res is not None and (why := self.view.result(res, self.ks.last(key)[0])) is not None:
                self.refuse("cmdlog", "ref", why, key)
        elif fam == "notice":
            self.take_notice(key, payload)
        else:
            return False
        return True

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
            self.refuse("notice", "(key)", why, key)
        else:
            self.view.notice(n)


class Feed:
    """One Zenoh session's subscriptions into one queue taken by one thread: `take` gets
    (key, payload) one at a time; an exception in it is counted on the gate, never fatal."""

    def __init__(self, name: str, gate: G.Gate, take: Callable[[str, bytes], None]):
        self.name, self.gate, self.take = name, gate, take
        self.q: queue.SimpleQueue = queue.SimpleQueue()
        self.subs: list = []
        self.thread = threading.Thread(target=self._loop, name=f"{name}-feed", daemon=True)

    def subscribe(self, session, keys: list[str]) -> None:
        def put(smp) -> None:
            self.q.put((str(smp.key_expr), smp.payload.to_bytes()))
        self.subs += [session.declare_subscriber(k, put) for k in keys]
        self.thread.start()

    def stop(self) -> None:
        self.q.put(None)
        if self.thread.is_alive():
            self.thread.join(5.0)
        for sub in self.subs:
            sub.undeclare()
        self.subs = []

    def _loop(self) -> None:
        while (item := self.q.get()) is not None:
            self.take_safely(*item)

    def take_safely(self, key: str, payload: bytes) -> None:
        try:
            self.take(key, payload)
        except Exception as e:   # a bug here must not end the feed: said, counted, skipped
            self.gate.rejects.add(M.MessageError("?", f"({self.name})", f"{type(e).__name__}: {e}"[:200]), key)


class LiveReader:
    """The live mesh, read: frames of the sources for the data messages of `classes` and
    the clock (the event time every source heard has promised; the end once all ended),
    alerts, notices and command results, each checked, into `view`."""

    def __init__(self, sc, conf, root: str, classes: tuple, view: View, name: str = "reader",
                 log: Callable = print):
        self.sc, self.conf, self.classes, self.view, self.name, self.log = sc, conf, classes, view, name, log
        self.ks = KeySpace.of(sc, root)
        self.gate = G.Gate(sc.duration_s, log=log, verifier=verifier_for(conf, root))   # secure: authority signed
        self.frames = FrameReader(self.ks, self.gate, sc.duration_s, log)
        self.checks = Checks(self.ks, self.gate, view)
        self.feed = Feed(name, self.gate, self.take)
        self.session = None

    def keys(self) -> list[str]:
        return [*self.checks.keys(), f"{self.ks.src('*')}/**"]   # whole streams and key groups

    def open(self) -> None:
        import zenoh
        self.session = zenoh.open(self.conf)
        self.feed.subscribe(self.session, self.keys())

    def close(self) -> None:
        self.feed.stop()
        if self.session is not None:
            self.session.close()
            self.session = None

    def take(self, key: str, payload: bytes) -> None:
        """One payload from the mesh, checked, into the view (the feed's thread; tests call it)."""
        if self.ks.family(key) != "src":
            if not self.checks.take(key, payload):
                self.checks.refuse("?", "(key)", f"nothing of {self.name} comes on {key[:80]}", key)
            return
        msgs = self.frames.read(key, payload)
        if msgs is None:
            return
        self.view.data([m for m in msgs if type(m) in self.classes])
        # the wall time this reader heard the clock reach t: what the console's page measures
        # raise-to-render latency from (a stamp for the page, never a decision)
        self.view.clock(*self.frames.clock(), time.time())
