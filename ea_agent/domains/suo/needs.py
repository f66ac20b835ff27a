"""What an SUO EA must hear, for dissemination: by command, the positions of its
subtree, the orders of its chain of command and of its own subtree and the fires it called; by mission, the
confirmations of every unit its plan names and of the fires it planned; by geography, what is reported near its
units and in the control measures it watches."""
from __future__ import annotations

import numpy as np

from ea_agent.core.needs import Needs
from ea_agent.core.plan import MissionSpec

from .detect.areas import LINGER_M
from .messages import CallForFire, LocationReport, MissionConfirm, Order, Reorganization, SensorTrack
from .missions import REGISTRY, ContingentMission

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
    places, followed = planned(dom)
    boxes = tuple(dom.overlay[a].area.bounds for a in sorted(dom.watched_areas()))
    # the hostile tracks there (only the tracks: own and friendly reports there are not what these checks read)
    ahead = tuple(dom.overlay[a].area.buffer(LINGER_M).bounds for a in sorted(places))
    paths = {to.path(dom.owner)} | {to.path(u) for u in followed if u in to.units and u not in dom.own_units}
    by = {"path": frozenset(paths),
          "issuer": frozenset([*dom.own_units, *to.ancestors(dom.owner)]),   # ours, and orders within our subtree
          "requester": frozenset({dom.owner}),
          "unit": frozenset(units)}
    fires, requesters = planned_fires(dom)
    if fires:   # their confirmations meet the fires' windows, wherever they land
        by["cff"] = fires
        # a requester outside our subtree: followed (its command post is a source we depend on)
        by["requester"] = by["requester"] | (requesters - dom.own_units)
    return Needs(TEMPLATES, by=by,
                 circles=tuple(circles), boxes=boxes, whole=("org",),
                 only=((SensorTrack.KEY, ahead),) if ahead else ())


class _Posts:
    """Stands in for the domain while a mission posts its place constraints, and records
    only what its checks will read beyond our own units: the places watched for hostiles
    (penetration, monitored and escape areas, a disrupt's avenue) and the units whose
    positions are followed (a follow-and-assume's supported unit). Anything else it
    posts is ignored; anything it reads is the domain's."""

    def __init__(self, dom):
        self.dom = dom
        self.places: set[str] = set()
        self.units: set[str] = set()
        self._assumed: set[str] = set()   # supported units whose missions were recorded

    def __getattr__(self, name):
        if name.startswith("post_"):
            return _ignore
        return getattr(self.dom, name)

    def post_penetration(self, m, area) -> None:
        self.places.add(area)

    def post_red_monitor(self, m, area, expected, expect_by=None) -> None:
        self.places.add(area)

    def post_escape(self, m, area) -> None:
        self.places.add(area)

    def post_tempo(self, m, avenue, by, tempo_mps) -> None:
        self.places.add(avenue)

    def post_assume(self, m, supported, halt_s) -> None:
        """Its supported unit's positions (is it halted?), and the places any mission of that
        unit it may take over will watch."""
        self.units.add(supported)
        if supported in self._assumed:
            return
        self._assumed.add(supported)
        for other in self.dom.missions.values():
            if other.unit == supported and not isinstance(other, ContingentMission):
                other.location_constraints(self)

    def mission(self, m) -> None:
        m.location_constraints(self)

    def contingency(self, c: ContingentMission) -> None:
        """Its trigger's area, and what its task will watch once it runs (built as
        `Contingencies.execute` builds it)."""
        tr = c.params["trigger"]
        if tr["kind"] == "hostile-in-area":
            self.places.add(tr["area"])
        task_cls = REGISTRY[c.params["task"]]
        task = task_cls(MissionSpec(c.id, c.unit, task_cls.TYPE, c.spec.start, c.spec.end, (),
                                    dict(c.params.get("task_params", {}))))
        if self.dom.in_plan(task):
            task.location_constraints(self)


def _ignore(*_a, **_k) -> None:
    return None


def planned(dom) -> tuple[frozenset[str], frozenset[str]]:
    """What the checks of our plan's missions will read once they run, beyond our units'
    surroundings: (places watched for hostiles, units whose positions are followed), for
    every mission of ours not done or aborted and every contingency of ours not yet
    fired. Heard from the plan's start, not from when a mission becomes ready: a check
    that starts then judges what the in-process EA, which hears everything, already
    knows (a hostile already in a secured objective, a track's progress along an
    avenue, where the supported unit has stood). Cached until the plan's state or the
    task organization changes."""
    plan = dom.plan
    if plan is None:
        return frozenset(), frozenset()
    st = plan.state
    key = (id(plan), getattr(st, "version", None), dom.taskorg.version, len(dom.missions))
    memo = getattr(dom, "_planned_memo", None)
    if memo is not None and memo[0] == key and key[1] is not None:
        return memo[1]
    rec = _Posts(dom)
    for mid, m in dom.missions.items():
        s = st.get(mid)
        if s in ("done", "aborted"):
            continue
        if isinstance(m, ContingentMission):
            if m.params.get("owner") == dom.owner:
                rec.contingency(m)
        elif dom.in_plan(m):
            rec.mission(m)
    out = frozenset(a for a in rec.places if a in dom.overlay), frozenset(rec.units)
    dom._planned_memo = (key, out)
    return out


def planned_fires(dom) -> tuple[frozenset[str], frozenset[str]]:
    """The calls for fire our plan's missions (not done or aborted) must see confirmed in a
    window (detect/windows.py), and their requesters: heard from the plan's start, as
    `planned` says why."""
    plan = dom.plan
    if plan is None:
        return frozenset(), frozenset()
    fires = [f for mid, m in dom.missions.items() if plan.state.get(mid) not in ("done", "aborted")
             and dom.in_plan(m) for f in _fires_of(m)]
    return frozenset(c for c, _ in fires), frozenset(r for _, r in fires)


def _fires_of(m) -> list[tuple[str, str]]:
    return [(f["cff"], f.get("requester") or m.unit) for f in m.params.get("fires") or ()]


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
