"""A peer's subscriptions, from its plan, its units' positions and its place in the
command hierarchy. Recomputed as the EA's state changes; the peer re-registers
when the set differs."""
from __future__ import annotations

from ea_agent.domains.suo.missions import ContingentMission

from collections import defaultdict

from .keyspace import KeySpace, block_of, cells_of_bounds, cells_within, command_path

class Interest:
    def __init__(self, ks: KeySpace, radius_m: float = 3000.0, block_share: int = 10):
        self.ks = ks
        self.radius = radius_m
        self.block_share = block_share   # take a whole block when we need this many of its 16 cells

    def keys(self, dom) -> set[str]:
        """Key expressions for one SUO domain (an EA's state)."""
        r = self.ks.root
        to = dom.taskorg
        out = {self.ks.clock(), f"{r}/org/*"}
        # command: our subtree's positions, orders from us and our superiors
        out.add(f"{r}/pos/*/*/{command_path(to, dom.owner)}/**")
        for u in [dom.owner, *to.ancestors(dom.owner)]:
            out.add(f"{r}/ord/{u}")
        out.add(f"{r}/cff/*/*/{dom.owner}/*")
        # mission: confirmations of every unit our plan names
        units = set(dom.own_units)
        for m in dom.missions.values():
            if dom.in_plan(m):
                units.add(m.unit)
                units.update(m.params[p] for p in type(m).UNIT_PARAMS if m.params.get(p))
            elif isinstance(m, ContingentMission) and m.params.get("owner") == dom.owner:
                units.add(m.unit)
        out.update(f"{r}/msn/{u}/*" for u in units)
        # geography: cells near our units, and the control measures our plan watches
        cells: set[str] = set()
        for u in dom.own_units:
            p = dom.unit_pos.get(u)
            if p is not None and dom.taskorg.units[u].entities:
                cells |= cells_within(p[0], p[1], self.radius)
        for a in dom.watched_areas():
            cells |= cells_of_bounds(dom.overlay[a].area.bounds)
        blocks: dict[str, list[str]] = defaultdict(list)
        for c in cells:
            blocks[block_of(c)].append(c)
        for b, cs in blocks.items():   # coarsen: fewer, wider subscriptions where we need most of a block
            places = [f"{b}/*"] if len(cs) >= self.block_share else [f"{b}/{c}" for c in cs]
            for pl in places:
                out.update((f"{r}/pos/{pl}/**", f"{r}/trk/{pl}/*", f"{r}/cff/{pl}/**"))
        return out
