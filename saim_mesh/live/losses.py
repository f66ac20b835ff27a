"""What a live peer keeps so that a source's loss can be undone when it returns: per
source, what it carried (the units whose silence its loss explains, `Carried`), and the EA
as it stood just before the loss (`BeforeLosses`), so that the return rebuilds from there
rather than from event time 0. The peer decides when a source is lost or back
(`live/peer.py`); these parts only keep and give back."""
from __future__ import annotations

import copy
from dataclasses import dataclass

from ea_agent.core.snapshot import snapshot

from ..protocol import messages as M

LOCATION = M.LocationReport
TRACK = M.SensorTrack
RULE_UNITS = 64   # subjects per inhibition rule (the rules' own bound)


@dataclass
class BeforeLoss:
    """What a source's return rebuilds the EA from: its input record index `n` (the loss)
    and copies of the EA, the order, the held directives and commands just before it."""
    n: int
    ea: object
    order: object
    pending: list
    cmds: list


class Carried:
    """Per source, the units whose positions and the hostile tracks it carried: what the EA
    knows to be partial while that source is lost."""

    def __init__(self, taskorg):
        self.taskorg = taskorg
        self.by_source: dict[str, set[str]] = {}

    def note(self, source: str, kinds: set, items: list) -> None:
        """The facts of one of its frames (`kinds`: their types, found once by the caller)."""
        got = self.by_source.get(source)
        if got is None:
            got = self.by_source[source] = set()
        if LOCATION in kinds:
            unit_of = self.taskorg.entity_unit.get
            got.update(u for e in {m.entity for m in items if type(m) is LOCATION} if (u := unit_of(e)) is not None)
        if TRACK in kinds:   # a lost source's hostile tracks stand still where it last saw them
            got.update(m.track for m in items if type(m) is TRACK)

    def units_of(self, source: str) -> list[str]:
        """The units whose positions the source carried (the platoons: the units an EA monitors)."""
        to = self.taskorg
        return sorted({to.parent.get(u, u) if to.units[u].kind == "squad" else u
                       for u in self.by_source.get(source, ()) if u in to.units})

    def inhibit(self, ea, source: str, log) -> None:
        """While the loss stands, what the EA concludes about the units and hostile tracks
        the source reported (silent, late, off their route; a contact with a track that
        moved on) rests on a picture it knows to be partial, as the system problem says:
        those alerts are inhibited by it (logged, marked, not shown as new; docs/console.md).
        When the source is back the rebuilt EA raises what really fell due, marked late."""
        carried = sorted(self.by_source.get(source, set()) | set(self.units_of(source)))
        for i in range(0, len(carried), RULE_UNITS):
            try:
                ea.inhibit({"id": f"lost-{source}-{i // RULE_UNITS}", "source": {"types": ["unknown-position"],
                            "subjects": [source]}, "target": {"subjects": carried[i:i + RULE_UNITS]},
                            "for_s": 86400.0, "comment": f"source {source} lost: its units' silence is that loss"})
            except ValueError as e:   # a unit name the rules refuse: say so, monitoring goes on
                log(f"source {source}: no inhibition of its units' unknown positions: {e}", flush=True)


class BeforeLosses:
    """Per lost source, a copy of the EA, its order and held directives and commands as they
    stood before the loss (input record `n`): at every flap of a link, a return rebuilt from
    event time 0 would cost each EA beyond it its whole journal again (docs/deployment.md).
    The copies share what never changes (`share`: the scenario, the peer, the alert ids)."""

    def __init__(self, share: tuple, log):
        self.share, self.log = share, log
        self.kept: dict[str, BeforeLoss] = {}

    def keep(self, source: str, n: int, state: tuple) -> None:
        """`state`: (ea, order, pending directives, held commands), copied now."""
        try:
            ea, order, pending, cmds = snapshot(state, share=self.share)
        except (TypeError, copy.Error) as e:   # state that cannot be copied: the return rebuilds from 0
            self.log(f"source {source} lost: no copy of the EA to rebuild from ({e})", flush=True)
            return
        self.kept[source] = BeforeLoss(n, ea, order, pending, cmds)

    def take(self, source: str, records: list) -> BeforeLoss | None:
        """The copy to rebuild `source`'s return from, if it is the one made at its loss in
        these records (else None: rebuild from event time 0)."""
        b = self.kept.pop(source, None)
        if b is not None and b.n < len(records) and records[b.n][:2] == ["lost", source]:
            return b
        return None

    def forget_after(self, n: int) -> None:
        """Copies made after input record `n`: the rebuild takes those losses again."""
        for s, b in list(self.kept.items()):
            if b.n > n:
                del self.kept[s]
