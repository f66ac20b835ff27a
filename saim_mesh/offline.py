"""A peer without Zenoh: the real `Peer` fed the replay's stream for one unit (its
batches and singles routed to its coarse subscriptions by key expression, a replay's
situation store answering its catch-ups), tick by tick, on scenario time.

`bench_intake` times it against the in-process EA. (The zygote warms the live peer
instead: saim_mesh/live/warm.py.)"""
from __future__ import annotations

import collections
import time
from pathlib import Path

import zenoh

from dissemination.groups import group_depth

from . import wire as W
from .batch import Batcher, groups_of
from .peer import Peer
from .replay import Replay, seq_bytes

KEY_ROOT = "saim"


class _Bytes:
    __slots__ = ("b",)

    def __init__(self, b: bytes):
        self.b = b

    def to_bytes(self) -> bytes:
        return self.b


class _Sample:
    """What the peer reads of a Zenoh sample."""
    __slots__ = ("key_expr", "payload", "attachment")

    def __init__(self, key: str, payload: bytes, att: bytes | None):
        self.key_expr, self.payload = key, _Bytes(payload)
        self.attachment = _Bytes(att) if att is not None else None


class _Out:
    """The replay's side: every put in order, cut into ticks by `stream`."""

    def __init__(self):
        self.out: list[tuple[str, bytes, bytes | None]] = []

    def declare_publisher(self, key: str, **_):
        out = self.out
        return type("Pub", (), {"put": lambda _s, b, **__: out.append((key, b, None))})()


def stream(sc) -> list:
    """The replay's messages tick by tick, as it sends them at max speed (batched per
    group and tick): [(samples, (key, payload) entries in seq order, tick)]."""
    rp = Replay(sc, zenoh.Config(), KEY_ROOT, log=lambda *a, **k: None)
    script = rp._prepare(sc.duration_s)
    out = _Out()
    bat = Batcher(out, groups_of(KEY_ROOT, group_depth(sc.taskorg)), rp.gate.max_bytes)
    chunks: list = []
    added: list[tuple[str, bytes]] = []
    n, n_tick, next_t = 0, 0, W.TICK_S

    def tick(t: float, end: bool = False) -> None:
        nonlocal n_tick, added
        bat.flush()
        n_tick += 1
        chunks.append((out.out[:], added,
                       W.make(W.Tick, t=t, n=n_tick, seq=n, end=end, w=None, src="main", of=1)))
        out.out.clear()
        added = []
    for ev, key, payload, _ in script:
        while ev.t >= next_t:
            tick(next_t)
            next_t += W.TICK_S
        n += 1
        added.append((key, payload))
        if not bat.add(key, n, payload):
            out.out.append((key, payload, seq_bytes(n)))
    tick(sc.duration_s, end=True)
    return chunks


class _Sub:
    def __init__(self, key: str):
        self.ke, self.q = zenoh.KeyExpr(key), collections.deque()

    def try_recv(self):
        return self.q.popleft() if self.q else None

    def undeclare(self) -> None:
        pass


class _Session:
    """Subscriptions, and a replay's situation store (its own `_entries`) answering catch-ups."""

    def __init__(self, sc):
        self.store = Replay(sc, zenoh.Config(), KEY_ROOT, log=lambda *a, **k: None)

    def declare_subscriber(self, key: str, handler=None) -> _Sub:
        return _Sub(key)

    def put(self, *_a, **_k) -> None:
        pass

    def get(self, selector: str, payload: bytes, **_):
        st = self.store
        req = st.gate.control(W.StoreQuery, payload, selector)
        rep = W.make(W.StoreReply, t=st.t, entries=st._entries(req, "main") if req is not None else [])
        return [type("Reply", (), {"ok": _Sample(selector + "/main", W.encode(rep), None)})()]


def run(sc, unit: str, chunks) -> tuple[Peer, dict[str, float]]:
    """A fresh peer through `chunks` (`stream`): the peer, and main-thread CPU seconds per stage."""
    p = Peer(sc, unit, zenoh.Config(), KEY_ROOT, log=lambda *a, **k: None)
    s = p.session = _Session(sc)
    p.presence = type("Presence", (), {"take": lambda _s: None})()
    p.ea.start(0.0)
    p._resubscribe()
    cpu = dict.fromkeys(("receive", "ticks", "interest"), 0.0)
    buf: list = []
    routes: dict[str, list[_Sub]] = {}
    subs = None
    next_interest, last_sig = 0.0, p._plan_signature()
    for samples, added, tick in chunks:
        for key, b in added:   # published: in the store before the tick that covers it
            s.store._add("main", key, b)
        if subs is not p.zsubs or len(routes) > 50_000:
            routes, subs = {}, p.zsubs
        for key, b, att in samples:   # Zenoh's work: the sample into every subscription it matches
            to = routes.get(key)
            if to is None:
                ke = zenoh.KeyExpr(key)
                to = routes[key] = [x for x in p.zsubs.values() if x.ke.intersects(ke)]
            for x in to:
                x.q.append(_Sample(key, b, att))
        s.store.t = tick.t
        p.clock_t, p.tick_seq = tick.t, tick.seq
        k0 = time.thread_time()
        p._drain(buf)
        k1 = time.thread_time()
        if p._on_tick(tick, buf):
            cpu["receive"] += k1 - k0
            cpu["ticks"] += time.thread_time() - k1
            break
        sig = p._plan_signature()
        k2 = time.thread_time()
        if tick.t >= next_interest or sig != last_sig:
            p._resubscribe(buf)
            next_interest, last_sig = tick.t + p.interest_s, sig
        k3 = time.thread_time()
        cpu["receive"] += k1 - k0
        cpu["ticks"] += k2 - k1
        cpu["interest"] += k3 - k2
    return p, cpu

