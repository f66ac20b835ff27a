"""A peer's subscriptions, from what its EA says it needs (`ea_agent.core.needs.Needs`:
its command subtree, the units and issuers it follows, the places it watches).
Recomputed as the EA's state changes; the peer re-registers when the set differs.
Nothing here knows a domain: the keys come from the domain's message templates."""
from __future__ import annotations

import math
from collections import defaultdict

from .keyspace import KeySpace, Template, block_of, cells_of_bounds, cells_within


class Interest:
    def __init__(self, ks: KeySpace, radius_m: float = 3000.0, block_share: int = 10):
        self.ks = ks
        self.radius = radius_m   # handed to the domain: how far around its units it listens
        self.block_share = block_share   # take a whole block when we need this many of its 16 cells
        self._tpl: dict[str, Template] = {}
        self._last: tuple[tuple, frozenset[str]] | None = None   # (what the keys depend on, the keys)

    def keys(self, dom) -> set[str]:
        """Key expressions for one EA's domain state."""
        return self.cached(dom.needs(self.radius))

    def cached(self, needs) -> set[str]:
        """`of`, recomputed only when the cells the needs cover or what they bind changed:
        units move metres between re-registrations, cells are kilometres wide."""
        memo = self._memo_key(needs)
        if self._last is not None and self._last[0] == memo:
            return set(self._last[1])
        out = self.of(needs)
        self._last = (memo, frozenset(out))
        return out

    def _memo_key(self, needs) -> tuple:
        size = self.ks.cell_m
        fl = math.floor
        spans = tuple((fl((x - r) / size), fl((x + r) / size), fl((y - r) / size), fl((y + r) / size))
                      for x, y, r in needs.circles)
        cells = lambda bs: tuple((fl(b[0] / size), fl(b[1] / size), fl(b[2] / size), fl(b[3] / size))   # noqa: E731
                                 for b in bs)
        only = tuple((text, cells(bs)) for text, bs in needs.only)
        return (needs.templates, tuple(sorted(needs.by.items())), needs.whole, spans, cells(needs.boxes), only)

    def of(self, needs) -> set[str]:
        r = self.ks.root
        out = {f"{r}/{fam}/**" for fam in needs.whole}
        places = self._places(needs)
        only = dict(needs.only)
        for text in needs.templates:
            tpl = self._tpl.get(text) or self._tpl.setdefault(text, Template(text))
            if tpl.family in needs.whole:
                continue
            for name, values in needs.by.items():
                if name in tpl.names:
                    out.update(f"{r}/{tpl.expr({name: v})}" for v in values)
            if "place" in tpl.names:
                pls = places if text not in only else self._places(needs, only[text])
                out.update(f"{r}/{tpl.expr({'place': pl})}" for pl in pls)
        return out

    def _places(self, needs, extra: tuple = ()) -> list[str]:
        """Place chunks ('<block>/<cell>' or '<block>/*') covering the needed circles and
        boxes (and `extra` boxes): cell by cell, or a whole block where most of it is needed."""
        size = self.ks.cell_m
        cells: set[str] = set()
        for x, y, rad in needs.circles:
            cells |= cells_within(x, y, rad, size)
        for b in (*needs.boxes, *extra):
            cells |= cells_of_bounds(b, size)
        blocks: dict[str, list[str]] = defaultdict(list)
        for c in cells:
            blocks[block_of(c)].append(c)
        out = []
        for b, cs in sorted(blocks.items()):   # coarsen: fewer, wider subscriptions where we need most of a block
            out += [f"{b}/*"] if len(cs) >= self.block_share else [f"{b}/{c}" for c in sorted(cs)]
        return out
