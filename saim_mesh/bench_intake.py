"""The EA peer's own work, without Zenoh: the real `Peer` receiving the replay's stream
for one unit (its batches and singles, routed to its coarse subscriptions by key
expression, the situation store answering its catch-ups) and working its clock ticks,
against the in-process EA on the same scenario in the same run.

`bench_mesh` measures a live peer, where two processes and Zenoh's threads share two
noisy cores; this takes them away, so what is left is what the peer's Python costs
beside its EA: receiving (decode, checks, hold), tick bookkeeping and re-registration.
Each pass is a fresh peer; the best of `--repeat` passes is reported, per stage, in
main-thread CPU seconds. Results: bench/results/intake.json."""
from __future__ import annotations

import argparse
import collections
import json
import sys
import time
from pathlib import Path

import zenoh

from dissemination.groups import group_depth

from . import scenario as S
from . import wire as W
from .batch import Batcher, groups_of
from .bench_ea import feed
from .peer import Peer
from .replay import Replay, seq_bytes
from .runner import config_for, make_ea

ROOT = Path(__file__).resolve().parents[1]
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


def _same(a) -> tuple:
    """What makes two alerts the same alert (`alertlog.alert_key`)."""
    return (a.t, a.owner, a.type, tuple(a.subjects), a.message, a.priority)


def one_pass(sc, unit: str, chunks) -> dict:
    """A fresh peer through the whole stream: CPU seconds per stage and what it took in."""
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
    return {"cpu_s": cpu, "alerts": [_same(a) for a in p.ea.alerts],
            "messages": p.ea.n_in, "flow": dict(p.flow),
            "keys": {"held": len(p.facts), "sweeps": p.facts.epoch,   # the per-key cache at the end
                     "oldest_sweep_heard": min((f.seen for f in p.facts.values()), default=None)}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "battalion"))
    ap.add_argument("--unit", default="BN")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "intake.json"))
    a = ap.parse_args(argv)
    sc = S.load(a.scenario)
    chunks = stream(sc)
    passes, inproc = [], []
    for _ in range(a.repeat):   # interleaved: both see the same moments of this machine
        passes.append(one_pass(sc, a.unit, chunks))
        ea = make_ea(sc, a.unit, config_for(sc, a.unit, None), sinks=[])
        k = time.thread_time()
        feed(ea, sc)
        inproc.append((time.thread_time() - k, [_same(x) for x in ea.alerts]))
    best = {k: min(x["cpu_s"][k] for x in passes) for k in passes[0]["cpu_s"]}
    peer_s = sum(best.values())
    in_s = min(t for t, _ in inproc)
    res = {
        "scenario": Path(a.scenario).name, "unit": a.unit, "repeat": a.repeat,
        "events": len(sc.events), "messages": passes[0]["messages"], "flow": passes[0]["flow"],
        "keys": passes[0]["keys"],
        "peer_cpu_s": {k: round(v, 3) for k, v in best.items()}, "peer_s": round(peer_s, 3),
        "in_process_s": round(in_s, 3), "share_of_in_process": round(in_s / peer_s, 3),
        "beside_the_ea_s": round(peer_s - in_s, 3),
        "alerts": len(passes[0]["alerts"]),
        "alerts_equal_in_process": all(x["alerts"] == inproc[0][1] for x in passes),
        "note": "no Zenoh, no second process: the peer's Python beside its EA (best of the passes, "
                "main-thread CPU); bench_mesh measures the live peer",
    }
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(res, indent=1) + "\n")
    print(json.dumps(res, indent=1))
    return 0 if res["alerts_equal_in_process"] else 1


if __name__ == "__main__":
    sys.exit(main())
