"""Plans: task organization (a mutable command hierarchy), missions in a partial
order with start/end temporal constraints, and the traversal state of a plan."""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any, Iterable

START_TYPES = ("ASAP", "ON-ORDER", "START-AT", "START-NLT", "START-NET")
END_TYPES = ("ASAP", "ON-ORDER", "END-AT", "END-NLT", "END-NET")


@dataclass(slots=True, frozen=True)
class TimeConstraint:
    """One of the Fig. 6 constraint types with its absolute scenario time."""
    type: str = "ASAP"
    t: float | None = None


@dataclass(slots=True)
class Unit:
    """A node of the command hierarchy. `kind` is the domain's word for it (an
    echelon, a robot type); `attrs` holds what only the domain reads (a weapons
    range, an owned boundary, a sensor footprint)."""
    id: str
    name: str
    kind: str
    parent: str | None
    entities: tuple[str, ...] = ()
    attrs: dict[str, Any] = field(default_factory=dict)


class TaskOrg:
    """The command hierarchy; changes at run time through reorganizations."""

    def __init__(self, units: Iterable[Unit]):
        self.units: dict[str, Unit] = {u.id: u for u in units}
        self.parent: dict[str, str | None] = {u.id: u.parent for u in self.units.values()}
        self.entity_unit: dict[str, str] = {e: u.id for u in self.units.values() for e in u.entities}
        self.version = 0
        self._cache: dict[str, tuple[str, ...]] = {}

    def copy(self) -> "TaskOrg":
        t = TaskOrg(Unit(u.id, u.name, u.kind, u.parent, u.entities, dict(u.attrs))
                    for u in self.units.values())
        t.parent = dict(self.parent)
        return t

    @property
    def root(self) -> str:
        return next(u for u, p in self.parent.items() if p is None)

    def children(self, unit: str) -> list[str]:
        return sorted(u for u, p in self.parent.items() if p == unit)

    def centroids(self, entity_pos) -> dict[str, tuple[float, float, int]]:
        """Each unit's centroid: the mean (lon, lat) of the latest positions of every
        entity in its subtree, with their count. `entity_pos`: entity -> (lon, lat, ...).
        Entities not in the organization are left out."""
        sums: dict[str, list[float]] = {}
        for e, p in entity_pos.items():
            u = self.entity_unit.get(e)
            if u is None:
                continue
            for v in (u, *self.ancestors(u)):
                s = sums.get(v)
                if s is None:
                    sums[v] = [p[0], p[1], 1]
                else:
                    s[0] += p[0]
                    s[1] += p[1]
                    s[2] += 1
        return {u: (s[0] / s[2], s[1] / s[2], int(s[2])) for u, s in sorted(sums.items())}

    def ancestors(self, unit: str) -> list[str]:
        out, p = [], self.parent.get(unit)
        while p is not None:
            out.append(p)
            if len(out) > len(self.parent):   # a cycle: never loop forever (loaders reject cycles)
                raise ValueError(f"cycle in the task organization above {unit!r}")
            p = self.parent.get(p)
        return out

    def cycle(self) -> list[str] | None:
        """A cycle in the parent links, as [A, B, ..., A], or None if the hierarchy is a tree."""
        done: set[str] = set()
        for start in sorted(self.parent):
            path: list[str] = []
            on_path: set[str] = set()
            u: str | None = start
            while u is not None and u not in done:
                if u in on_path:
                    return path[path.index(u):] + [u]
                path.append(u)
                on_path.add(u)
                u = self.parent.get(u)
            done |= on_path
        return None

    def subtree(self, unit: str) -> tuple[str, ...]:
        """`unit` and everything under it, sorted (cached per hierarchy version)."""
        hit = self._cache.get(unit)
        if hit is None:
            out, todo, seen = [], [unit], set()
            while todo:
                u = todo.pop()
                if u in seen:   # a cycle: never loop forever (loaders reject cycles)
                    raise ValueError(f"cycle in the task organization under {unit!r}")
                seen.add(u)
                out.append(u)
                todo.extend(self.children(u))
            hit = self._cache[unit] = tuple(sorted(out))
        return hit

    def is_under(self, unit: str, owner: str) -> bool:
        return unit == owner or owner in self.ancestors(unit)

    def resubordinate(self, unit: str, new_parent: str) -> None:
        if unit not in self.units or new_parent not in self.units:
            raise KeyError(f"reorganization names unknown unit {unit if unit not in self.units else new_parent!r}")
        if new_parent in self.subtree(unit):
            raise ValueError(f"cannot put {unit} under its own subordinate {new_parent}")
        self.parent[unit] = new_parent
        self.version += 1
        self._cache.clear()

    def nearest_with(self, unit: str, attr: str) -> str | None:
        """The nearest unit at or above `unit` whose `attrs` set `attr` (e.g. the
        unit whose boundary governs it)."""
        for u in [unit, *self.ancestors(unit)]:
            if self.units[u].attrs.get(attr) is not None:
                return u
        return None

    def path(self, unit: str) -> str:
        """'top/.../unit': the unit's place in the hierarchy (one key chunk per level)."""
        return "/".join(reversed([unit, *self.ancestors(unit)]))

    def name(self, unit: str) -> str:
        u = self.units.get(unit)
        return u.name if u else unit


@dataclass(slots=True)
class MissionSpec:
    """A mission as written in the plan (validated against the mission model on load)."""
    id: str
    unit: str
    type: str
    start: TimeConstraint = TimeConstraint()
    end: TimeConstraint = TimeConstraint()
    after: tuple[str, ...] = ()
    params: dict[str, Any] = field(default_factory=dict)


@dataclass(slots=True)
class PlanSpec:
    name: str
    missions: list[MissionSpec]

    def cycle(self) -> list[str] | None:
        """A cycle in the missions' `after` lists, as [a, b, ..., a], or None if they form a
        partial order (a cycle would leave its missions pending forever)."""
        after = {m.id: m.after for m in self.missions}
        state: dict[str, int] = {}   # 1: on the current path, 2: finished
        for root in after:
            if state.get(root):
                continue
            path, stack = [root], [iter(after[root])]
            state[root] = 1
            while stack:
                nxt = next(stack[-1], None)
                if nxt is None:
                    state[path.pop()] = 2
                    stack.pop()
                elif state.get(nxt) == 1:
                    return path[path.index(nxt):] + [nxt]
                elif not state.get(nxt) and nxt in after:
                    state[nxt] = 1
                    path.append(nxt)
                    stack.append(iter(after[nxt]))
        return None


_VERSIONS = itertools.count(1)   # one sequence for every plan's states: a replaced plan never repeats a version


class _States(dict):
    """Mission id -> state, counting its changes (what is derived from it is cached by them)."""

    def __init__(self, *args) -> None:
        super().__init__(*args)
        self.version = next(_VERSIONS)

    def __setitem__(self, key: str, value: str) -> None:
        dict.__setitem__(self, key, value)
        self.version = next(_VERSIONS)


class PlanState:
    """Traversal of a plan's partial order: pending -> ready -> active -> done."""

    def __init__(self, plan: PlanSpec):
        self.plan = plan
        self.by_id = {m.id: m for m in plan.missions}
        self.state: dict[str, str] = _States((m.id, "pending") for m in plan.missions)
        self._active: tuple[int, dict[str, str]] = (-1, {})
        self.started: dict[str, float] = {}
        self.ended: dict[str, float] = {}

    def newly_ready(self) -> list[MissionSpec]:
        """Pending missions whose predecessors are all done, now marked ready."""
        out = []
        for m in self.plan.missions:
            if self.state[m.id] == "pending" and all(self.state.get(a) == "done" for a in m.after):
                self.state[m.id] = "ready"
                out.append(m)
        return out

    def start(self, mid: str, t: float) -> None:
        self.state[mid] = "active"
        self.started.setdefault(mid, t)

    def end(self, mid: str, t: float) -> None:
        self.state[mid] = "done"
        self.ended.setdefault(mid, t)

    def active(self) -> list[MissionSpec]:
        return [m for m in self.plan.missions if self.state[m.id] == "active"]

    def active_by_unit(self) -> dict[str, str]:
        """Unit -> its active mission's id (the last in plan order if several); cached
        until a state changes, as this is asked for on every alert."""
        v = self.state.version
        if self._active[0] != v:
            self._active = (v, {s.unit: s.id for s in self.active()})
        return self._active[1]
