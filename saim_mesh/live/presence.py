"""Which of the EAs this one watches are on the mesh: their liveliness tokens, and whether a
leave was clean (a goodbye) or not. It decides when a change is worth saying; the peer says
it (one system problem, journalled so a replay says the same)."""
from __future__ import annotations

from ..protocol import gate as G

from ..protocol import wire as W


class PeerPresence:
    def __init__(self, unit: str, ks, gate: G.Gate):
        self.unit, self.ks, self.gate = unit, ks, gate
        self.tokens: dict[str, set[str]] = {}   # another EA's unit -> its liveliness tokens now
        self.left: set[str] = set()             # ... gone without a goodbye (said)
        self.clean: set[str] = set()            # ... said goodbye

    def watched(self, to) -> set[str]:
        """Its subtree and its superior: whose loss degrades what this EA monitors."""
        return set(to.subtree(self.unit)) | set(to.ancestors(self.unit)[:1])

    def token(self, key: str, up: bool, to) -> tuple[str, bool] | None:
        """A liveliness token of another EA came or went: (unit, up) when that must be said
        (the last token of a watched EA went without a bye, or one that left is back), else None."""
        unit, zid = (self.ks.last(key, 2) + ["", ""])[:2]
        if unit == self.unit or unit not in to.units or unit not in self.watched(to):
            return None
        toks = self.tokens.setdefault(unit, set())
        was = bool(toks)
        (toks.add if up else toks.discard)(zid)
        if bool(toks) == was:
            return None
        if not toks and unit in self.clean:
            return None   # it finished and said so
        if up and unit not in self.left:
            return None   # first seen: nothing to say
        return unit, bool(toks)

    def said(self, unit: str, up: bool) -> None:
        (self.left.discard if up else self.left.add)(unit)

    def bye(self, key: str, payload: bytes) -> None:
        """A goodbye on bye/<unit>: checked, and only for the unit its key names."""
        msg = self.gate.control(W.Bye, payload, key)
        if msg is not None and self.ks.last(key) == [msg.unit]:
            self.clean.add(msg.unit)
