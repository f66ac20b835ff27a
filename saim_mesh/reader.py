"""The replay mesh's read side (the console, the TAK gateway on the replay): it follows
the replay's clock ticks and data keys, and once, at the first tick or when the mesh
stays quiet, asks the situation store for the picture so far, so that a reader that
joins late still shows it. Goes with the replay mesh (issue 51); the live mesh's readers
(`live.reader.LiveReader`) never import this module.

Alerts, notices and command results are checked as on the live mesh (`live.reader.Checks`);
what passes goes to the same views (`console.feed.ConsoleView`, `tak.gateway.TakView`)."""
from __future__ import annotations

import queue
from typing import Callable

from dissemination.groups import group_depth
from dissemination.keyspace import KeySpace

from . import batch as B
from . import gate as G
from . import messages as M
from . import storeq
from . import wire as W
from .live.reader import Checks, Feed, View
from .security.sign import verifier_for


class _QuietFeed(Feed):
    """A feed that, when the mesh stays quiet, asks the store once (joined late, or after the end)."""

    def __init__(self, name: str, gate: G.Gate, take: Callable, quiet: Callable[[], None]):
        super().__init__(name, gate, take)
        self.quiet = quiet

    def _loop(self) -> None:
        while True:
            try:
                item = self.q.get(timeout=2.0)
            except queue.Empty:
                self.quiet()
                continue
            if item is None:
                return
            self.take_safely(*item)


class MeshReader:
    """The replay mesh, read: its clock ticks, the data keys of `classes` (and the replay's
    batches of them), alerts, notices and command results, each checked, into `view`."""

    def __init__(self, sc, conf, root: str, classes: tuple, view: View, name: str = "reader",
                 log: Callable = print):
        self.sc, self.conf, self.classes, self.view, self.name, self.log = sc, conf, classes, view, name, log
        self.ks = KeySpace.of(sc, root)
        self.gate = G.Gate(sc.duration_s, log=log, verifier=verifier_for(conf, root))   # secure: authority signed
        self.checks = Checks(self.ks, self.gate, view)
        self.groups = B.groups_of(root, group_depth(sc.taskorg))   # as the replay cut them
        self.feed = _QuietFeed(name, self.gate, self.take, self._quiet)
        self.session = None
        self.caught_up = False

    def keys(self) -> list[str]:
        data = sorted({self.ks.data(c) for c in self.classes})
        return [self.ks.clock(), *self.checks.keys(), *data]

    def opened(self, session) -> None:
        """Hook: declare publishers before the first payload is taken."""

    def closing(self) -> None:
        """Hook: undeclare them."""

    def open(self) -> None:
        import zenoh
        self.session = zenoh.open(self.conf)
        self.opened(self.session)
        self.feed.subscribe(self.session, self.keys())

    def close(self) -> None:
        self.feed.stop()
        self.closing()
        if self.session is not None:
            self.session.close()
            self.session = None

    def take(self, key: str, payload: bytes) -> None:
        """One payload from the mesh (a batch: each report alone), checked, into the view."""
        if self.groups.is_batch(key):   # a tick's reports of one group
            for _, k, p in B.unpack(self.gate, self.groups, payload, key):
                self.take_one(k, p)
        else:
            self.take_one(key, payload)

    def take_one(self, key: str, payload: bytes) -> None:
        ks, gate = self.ks, self.gate
        fam = ks.family(key)
        if fam == "clock":
            tick = gate.control(W.Tick, payload, key)
            if tick is not None and not (tick.end and tick.t < self.sc.duration_s):
                self.first_tick()
                self.view.clock(tick.t, tick.end, tick.w)
            return
        if self.checks.take(key, payload):
            return
        m = gate.data(payload, key)
        if m is None:
            return
        why = ks.mismatch(key, m) if type(m) in self.classes else f"a {m.KIND} message on {fam}/ keys"
        if why is not None:
            gate.rejects.add(M.MessageError(m.KIND, "(key)", why), key)
        else:
            self.view.data([m])

    def _quiet(self) -> None:
        if not self.caught_up and self.session is not None:
            self.caught_up = self.catch_up(timeout=2.0)

    def first_tick(self) -> None:
        """At the first clock tick: the picture before it comes from the store."""
        if not self.caught_up and self.session is not None:
            self.caught_up = True
            self.catch_up()

    def stored(self, messages: list, t: float) -> None:
        """The store's messages so far (positions: the latest wins), and the time it reached:
        a replay that ended (and lingers) still ends the reader."""
        self.view.data(messages)
        if t > 0:
            self.view.clock(t, t >= self.sc.duration_s)

    def catch_up(self, timeout: float = 10.0) -> bool:
        """The picture so far from the situation store; False when no store answered."""
        if self.session is None:
            return False
        keys = sorted({self.ks.data(c) for c in self.classes})
        try:
            rep = storeq.query(self.session, self.ks, self.gate, 0, keys, timeout)
        except Exception as e:   # no store reachable (access control, no replay): live data only
            self.log(f"{self.name}: no catch-up from the store ({type(e).__name__})", flush=True)
            return False
        if rep is None:
            return False
        ms = [m for _, p in rep.entries if (m := self.gate.data(p, "store")) is not None and type(m) in self.classes]
        self.stored(ms, rep.t)
        return True


def console_feed(sc, conf, root: str, state, log: Callable = print) -> MeshReader:
    """The console on the replay mesh."""
    from .console.feed import ConsoleView, classes_of
    return MeshReader(sc, conf, root, classes_of(sc), ConsoleView(state), "console", log)


class TakFeed(MeshReader):
    """The TAK gateway on the replay mesh: PLI from TAK users go out on ingest/tak (the
    replay sequences them into the mesh); a late gateway takes positions and tracks from
    the store, not its time."""

    def __init__(self, sc, conf, root: str, picture, send: Callable[[bytes], None],
                 overlay_every: float | None = 300.0, log: Callable = print):
        from .tak.gateway import CLASSES, IDENTITY, TakView
        from ea_agent import domains
        self.identity = IDENTITY
        super().__init__(sc, conf, root, CLASSES.get(domains.of(sc).NAME, ()),
                         TakView(sc, picture, send, overlay_every), "tak", log)
        self.publisher = None

    def opened(self, session) -> None:
        import zenoh
        self.publisher = session.declare_publisher(self.ks.ingest(self.identity),
                                                   congestion_control=zenoh.CongestionControl.BLOCK)

    def closing(self) -> None:
        if self.publisher is not None:
            self.publisher.undeclare()
            self.publisher = None

    def publish(self, rep) -> None:
        """A checked LocationReport from a TAK client into the mesh (any thread)."""
        if self.publisher is not None:
            self.publisher.put(M.encode(rep))

    def stored(self, messages: list, t: float) -> None:
        self.view.data(messages)
