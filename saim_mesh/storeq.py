"""Ask the situation store: behind routers it is served per command post (each of the
replay's sources answers for the reports that entered at its router), so one query
gets several replies; they are merged here into one, in sequence order."""
from __future__ import annotations

import zenoh

from . import wire as W


def query(session, ks, gate: W.Gate, since: int = 0, keys: list[str] | None = None,
          timeout: float = 10.0) -> W.StoreReply | None:
    """Every store's entries after `since` on `keys` (all when None), merged; None when
    no store answered. `t` is the earliest time any store reached (a store behind a slow
    link may lag), and fusion progress the latest any store knows."""
    req = W.encode(W.make(W.StoreQuery, since=since, keys=keys))
    got: list[W.StoreReply] = []
    for r in session.get(ks.store(), payload=req, timeout=timeout, consolidation=zenoh.ConsolidationMode.NONE):
        if r.ok is not None and (rep := gate.control(W.StoreReply, r.ok.payload.to_bytes(), str(r.ok.key_expr))):
            got.append(rep)
    if not got:
        return None
    if len(got) == 1:
        return got[0]
    entries = sorted({seq: p for rep in got for seq, p in rep.entries}.items())
    fusion: dict[str, float] = {}
    for rep in got:
        for g, ft in rep.fusion.items():
            fusion[g] = max(fusion.get(g, -1.0), ft)
    return W.make(W.StoreReply, t=min(rep.t for rep in got), entries=entries, fusion=fusion)
