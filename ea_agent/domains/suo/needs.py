"""What an SUO EA must hear, for dissemination: by command, the positions of its
subtree, the orders of its chain of command and of its own subtree and the fires it called; by mission, the
confirmations of every unit its plan names; by geography, what is reported near its
units and in the control measures it watches."""
from __future__ import annotations

import numpy as np

from ea_agent.core.needs import Needs

from .messages import CallForFire, LocationReport, MissionConfirm, Order, Reorganization, SensorTrack
from .missions import ContingentMission

ENVELOPE_MARGIN_M = 1000.0   # a unit's spread around its centroid, and a track's move between re-registrations
TEMPLATES = tuple(c.KEY for c in (LocationReport, SensorTrack, MissionConfirm, Order, CallForFire, Reorganization))


def needs(dom, radius_m: float) -> Needs:
    to = dom.taskorg
    units = set(dom.own_units)
    for m in dom.missions.values():
        if dom.in_plan(m):
            units.add(m.unit)
            units.update(m.params[p] for p in type(m).UNIT_PARAMS if m.params.get(p))
        elif isinstance(m, ContingentMission) and m.params.get("owner") == dom.owner:   # ours, for another unit
            units.add(m.unit)
    # never narrower than the threat envelope: a commander who widens it at run time
    # (`set voi.threat_radius_m`) must hear the tracks it now takes in
    radius_m = max(radius_m, float(dom.voi_cfg["threat_radius_m"]) + ENVELOPE_MARGIN_M)
    circles = []
    for u in sorted(dom.own_units):
        p = dom.unit_pos.get(u)
        if p is not None and to.units[u].entities:
            circles.append((p[0], p[1], radius_m))
    boxes = tuple(dom.overlay[a].area.bounds for a in sorted(dom.watched_areas()))
    return Needs(TEMPLATES, by={"path": frozenset({to.path(dom.owner)}),
                                "issuer": frozenset([*dom.own_units, *to.ancestors(dom.owner)]),   # ours, and orders within our subtree
                                "requester": frozenset({dom.owner}),
                                "unit": frozenset(units)},
                 circles=tuple(circles), boxes=boxes, whole=("org",))


def needs_before(dom, msg) -> Needs | None:
    """What must be up to date before `msg` is applied: for a call for fire we make, every
    position near its target (CallsForFire judges it on every position we know, and the
    target is rarely within our geographic interest): the latest report in the cells
    around it, and of every entity we believe there (it may have left since we heard it).
    Own entities are always heard. Older reports than ours are dropped by the watchman."""
    if type(msg) is not CallForFire or msg.requester != dom.owner:
        return None
    pic = dom.pic
    x, y = pic.proj.to_xy(msg.lon, msg.lat)
    r = float(msg.radius_m)
    with np.errstate(invalid="ignore"):
        near = np.nonzero(np.hypot(pic.xy[:, 0] - x, pic.xy[:, 1] - y) <= r)[0].tolist()
    believed = frozenset(pic.ents[i] for i in near if pic.ent_leaf[i] not in dom.own_leaves)
    return Needs((LocationReport.KEY,), by={"entity": believed} if believed else {},
                 circles=((float(x), float(y), r),))


def neighbours(dom, margin_m: float = ENVELOPE_MARGIN_M) -> frozenset[str]:
    """Units under another boundary near ours, from the plan: the fratricide rule pairs our
    units with theirs when one strays across (paper 6.7.2), so their positions matter to
    this EA wherever they come from. Near: boundaries within the longest weapons range
    plus a margin. Static: a unit that strays beyond a neighbouring sector is not covered."""
    to = dom.taskorg
    mine = {b for u in dom.own_units if (b := to.nearest_with(u, "boundary")) is not None}
    if not mine:
        return frozenset()
    rng = max([float(dom.voi_cfg["weapons_range_m"])] +
              [float(r) for v in to.units.values() if (r := v.attrs.get("weapons_range_m")) is not None])
    polys = {u: dom.overlay[v.attrs["boundary"]].area for u, v in to.units.items() if v.attrs.get("boundary")
             and v.attrs["boundary"] in dom.overlay}
    near = {b for b, p in polys.items() if b not in mine
            and any(m in polys and p.distance(polys[m]) <= rng + margin_m for m in mine)}
    return frozenset(u for u in to.units if to.nearest_with(u, "boundary") in near)
