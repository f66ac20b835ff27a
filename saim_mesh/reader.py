"""A read-side mesh peer (the console, the TAK gateway): its subscriptions go into one
queue taken by one thread, so the gate and the picture see one payload at a time, in
arrival order; nothing received can stop it (a bad payload, or a bug in handling it,
is counted). Once, at the first tick or when the mesh stays quiet, it asks the
situation store for the picture so far: a reader that joins late still shows it.

Subclasses name `keys()`, handle `take(key, payload)` and `stored(messages, t)`."""
from __future__ import annotations

import queue
import threading
from typing import Callable

from dissemination.groups import group_depth
from dissemination.keyspace import KeySpace

from . import batch as B
from . import messages as M
from . import storeq
from . import gate as G
from .security.sign import verifier_for


class MeshReader:
    NAME = "reader"

    def __init__(self, sc, conf, root: str, classes: tuple, log: Callable = print):
        self.sc, self.conf, self.classes, self.log = sc, conf, classes, log
        self.ks = KeySpace.of(sc, root)
        self.gate = G.Gate(sc.duration_s, log=log, verifier=verifier_for(conf, root))   # secure: authority signed
        self.q: queue.SimpleQueue = queue.SimpleQueue()
        self.session = None
        self.caught_up = False
        self.subs: list = []
        self.groups = B.groups_of(root, group_depth(sc.taskorg))   # as the replay cut them
        self.thread = threading.Thread(target=self._loop, name=f"{self.NAME}-feed", daemon=True)

    def keys(self) -> list[str]:
        raise NotImplementedError

    def take(self, key: str, payload: bytes) -> None:
        raise NotImplementedError

    def stored(self, messages: list, t: float) -> None:
        """The store's messages of our classes so far, and the time it reached."""
        raise NotImplementedError

    def opened(self, session) -> None:
        """Hook: declare publishers before the first payload is taken."""

    def closing(self) -> None:
        """Hook: undeclare them."""

    def open(self) -> None:
        import zenoh
        self.session = s = zenoh.open(self.conf)
        self.opened(s)
        put = self.q.put
        for k in self.keys():
            self.subs.append(s.declare_subscriber(k, lambda smp: put((str(smp.key_expr), smp.payload.to_bytes()))))
        self.thread.start()

    def close(self) -> None:
        self.q.put(None)
        if self.thread.is_alive():
            self.thread.join(5.0)
        for sub in self.subs:
            sub.undeclare()
        self.subs = []
        self.closing()
        if self.session is not None:
            self.session.close()
            self.session = None

    def _loop(self) -> None:
        while True:
            try:
                item = self.q.get(timeout=2.0)
            except queue.Empty:   # quiet: joined late (or after the end)? ask the store
                if not self.caught_up and self.session is not None:
                    self.caught_up = self.catch_up(timeout=2.0)
                continue
            if item is None:
                return
            try:
                if self.groups.is_batch(item[0]):   # a tick's reports of one group: each taken alone
                    for _, k, p in B.unpack(self.gate, self.groups, item[1], item[0]):
                        self.take(k, p)
                else:
                    self.take(*item)
            except Exception as e:   # a bug here must not end the feed: said, counted, skipped
                self.gate.rejects.add(M.MessageError("?", f"({self.NAME})", f"{type(e).__name__}: {e}"[:200]),
                                      item[0])

    def first_tick(self) -> None:
        """Call at the first clock tick: the picture before it comes from the store."""
        if not self.caught_up and self.session is not None:
            self.caught_up = True
            self.catch_up()

    def catch_up(self, timeout: float = 10.0) -> bool:
        """The picture so far from the situation store; False when no store answered."""
        if self.session is None:
            return False
        keys = sorted({self.ks.data(c) for c in self.classes})
        try:
            rep = storeq.query(self.session, self.ks, self.gate, 0, keys, timeout)
        except Exception as e:   # no store reachable (access control, no replay): live data only
            self.log(f"{self.NAME}: no catch-up from the store ({type(e).__name__})", flush=True)
            return False
        if rep is None:
            return False
        ms = [m for _, p in rep.entries if (m := self.gate.data(p, "store")) is not None and type(m) in self.classes]
        self.stored(ms, rep.t)
        return True
