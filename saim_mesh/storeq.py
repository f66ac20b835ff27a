"""Ask the situation store: behind routers it is served per command post (each of the
replay's sources answers for the reports that entered at its router), so one query
gets several replies; they are merged here into one, in sequence order."""
from __future__ import annotations

import time

import zenoh

from . import gate as G

from . import wire as W


def query(session, ks, gate: G.Gate, since: int = 0, keys: list[str] | None = None,
          timeout: float = 10.0, expect: int = 1, before: int = 0, latest: bool = False) -> W.StoreReply | None:
    """Every store's entries after `since` on `keys` (all when None), merged; None when
    no store answered. `t` is the earliest time any store reached (a store behind a slow
    link may lag), and fusion progress the latest any store knows. With `expect` stores
    (the replay's sources), ask again until all answered or `timeout` passed: right after
    a link heals, the far stores' queryables may not be declared here yet. `before`,
    `latest`: see `wire.StoreQuery` (a key's entries all enter by one source)."""
    req = W.encode(W.make(W.StoreQuery, since=since, keys=keys, before=before, latest=latest))
    end = time.monotonic() + timeout
    got: dict[str, W.StoreReply] = {}
    while True:
        for r in session.get(ks.store(), payload=req, timeout=max(0.1, end - time.monotonic()),
                             consolidation=zenoh.ConsolidationMode.NONE):
            if r.ok is None:
                continue
            key = str(r.ok.key_expr)
            if (rep := gate.control(W.StoreReply, r.ok.payload.to_bytes(), key)) is not None:
                got[ks.last(key)[0]] = rep
        if len(got) >= expect or time.monotonic() >= end:
            break
        time.sleep(0.2)   # a retry period, not a synchronisation: the next query asks them all again
    if not got:
        return None
    if len(got) == 1:
        return next(iter(got.values()))
    entries = sorted({seq: p for rep in got.values() for seq, p in rep.entries}.items())
    fusion: dict[str, float] = {}
    for rep in got.values():
        for g, ft in rep.fusion.items():
            fusion[g] = max(fusion.get(g, -1.0), ft)
    return W.make(W.StoreReply, t=min(rep.t for rep in got.values()), entries=entries, fusion=fusion)
