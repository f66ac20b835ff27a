"""Which sources an EA depends on, from its interest (issue 31.2).

A recorded scenario is published as one source per command post (`cp_shares`): each
child of the top unit publishes its subtree's positions, confirmations, calls for fire
and orders; the top's own command post publishes the rest and the hostile tracks its
sensors see. An EA closes an epoch only when every source it *depends on* has promised
it, so depending on a source it does not need would let a cut link to that source freeze
it. It depends on a source when the source carries a unit the EA follows by command (its
subtree, its chain of command's orders, its calls for fire) or by mission (units its plan
names), or carries the tracks while the EA watches places (threats near its units, the
areas of its control measures), or carries units the domain calls neighbours (under
another boundary near ours: the fratricide rule pairs them with ours). Friends passing
near for other reasons are not a dependency (positions around a call for fire's target).
In a domain whose units report their own places (the robot team: states and sightings by
place, `PLACED_BY_EVERY_SOURCE`), watching places depends on every source.
`test_depend` checks the result against an EA that hears everything.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Share:
    """What one command post's source publishes of a recorded scenario (`play.share`)."""
    units: tuple[str, ...] | None   # subtrees published (None: every unit)
    but: tuple[str, ...] = ()       # subtrees left to other sources
    tracks: bool = False            # the hostile tracks
    fusion: str | None = None       # a sensor group's fusion node: its tracks only, no unit

    def args(self) -> list[str]:
        """As `saim-mesh source` arguments."""
        if self.fusion is not None:
            return ["--fusion", self.fusion]
        out = ["--units", *self.units] if self.units else []
        out += ["--but", *self.but] if self.but else []
        return out + (["--tracks"] if self.tracks else [])

    def carries(self, taskorg) -> set[str]:
        if self.fusion is not None:
            return set()
        mine = set().union(*(taskorg.subtree(u) for u in self.units)) if self.units else set(taskorg.units)
        for u in self.but:
            mine -= set(taskorg.subtree(u))
        return mine


def cp_shares(sc) -> dict[str, Share]:
    """One source per child of the top unit (its subtree), one for the top's own command
    post (everything else, with the tracks the scenario gives), and one per sensor group:
    its fusion node beside its sensors, publishing the tracks it fuses from their hits."""
    to = sc.taskorg
    top = to.root
    kids = tuple(sorted(u for u, p in to.parent.items() if p == top))
    out = {f"cp.{k}": Share((k,)) for k in kids}
    out[f"cp.{top}"] = Share(None, kids, tracks=True)
    for g in sorted(sc.meta.get("fusion", {}).get("groups", {})):
        out[f"fusion.{g}"] = Share((), tracks=True, fusion=g)
    return out


def home_of(sc, source: str) -> str | None:
    """The unit whose command post a source runs at: `cp.<U>`'s U; a fusion node's, the
    nearest command post over every sensor of its group (fusion near its sensors)."""
    if source.startswith("cp."):
        return source[3:]
    if not source.startswith("fusion."):
        return None
    g = source[len("fusion."):]
    owners = {s["owner"] for s in sc.meta.get("fusion", {}).get("sensors", ()) if s.get("group") == g
              and s.get("owner") in sc.taskorg.units}
    if not owners:
        return sc.taskorg.root
    to = sc.taskorg
    chains = [[u, *to.ancestors(u)] for u in sorted(owners)]
    common = set(chains[0]).intersection(*chains[1:])
    return next(u for u in chains[0] if u in common)


def followed(dom) -> tuple[set[str], bool]:
    """The units an EA's state follows by command, mission or neighbourhood, and whether it watches
    places (hostile tracks near its units or in its control measures)."""
    n = dom.needs(0.0)
    to = dom.taskorg
    units = set(n.by.get("unit", ())) | set(n.by.get("issuer", ())) | set(n.by.get("requester", ()))
    units |= set(getattr(dom, "neighbours", frozenset)())   # geography among friends, from the plan
    for path in n.by.get("path", ()):
        owner = path.rsplit("/", 1)[-1]
        if owner in to.units:
            units |= set(to.subtree(owner))
    return units, bool(n.circles or n.boxes or n.whole or any(bs for _, bs in n.only))


def depends(sc, ea, sources: list[str], shares: dict[str, Share] | None = None) -> list[str]:
    """The sources among `sources` that `ea` depends on. A name whose share is unknown
    (not one of the command posts' sources) is always depended on."""
    shares = cp_shares(sc) if shares is None else shares
    units, places = followed(ea.domain)
    everywhere = getattr(ea.domain, "PLACED_BY_EVERY_SOURCE", False)   # robots report their own places
    to = sc.taskorg
    out = []
    for s in sources:
        sh = shares.get(s)
        if sh is None or (sh.tracks or everywhere) and places or units & sh.carries(to):
            out.append(s)
    return sorted(out)
