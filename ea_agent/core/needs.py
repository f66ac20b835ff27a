"""What an EA needs to hear, in the domain's own terms. The domain says it; the
dissemination layer turns it into key expressions (and re-registers when it
changes). Neither side reads the other's internals."""
from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(frozen=True)
class Needs:
    """`templates` are the key templates (message classes' `KEY`) of every kind the EA
    listens to. `by` binds a template placeholder to the values wanted ("path": the
    command paths of subtrees we follow, "unit": units whose mission messages we need,
    "issuer": units whose orders we obey, ...): a template is subscribed once per value
    of each placeholder it has. `circles` (x, y, r) and `boxes` (x0, y0, x1, y1), in
    projected metres, select by `{place}`; `only` adds boxes for some templates alone. `whole` names families taken entirely.

    A domain may also say, per message, what must be up to date before the EA applies
    it: `domain.needs_before(msg) -> Needs | None` (a call for fire is judged on every
    position near its target, wherever that is). A peer then feeds the latest message
    on each of those keys before this one, as an in-process EA, which hears
    everything, would have had them."""
    templates: tuple[str, ...]
    by: dict[str, frozenset[str]] = field(default_factory=dict)
    circles: tuple[tuple[float, float, float], ...] = ()
    boxes: tuple[tuple[float, float, float, float], ...] = ()
    whole: tuple[str, ...] = ()
    # boxes selecting by `{place}` for some templates only, ((template, (box, ...)), ...):
    # the hostile tracks in places a plan will watch, not every report made there
    only: tuple[tuple[str, tuple[tuple[float, float, float, float], ...]], ...] = ()
