"""The oracle's core: the true world sampled every TICK seconds and the record of incidents."""
from __future__ import annotations

import math

import numpy as np
from shapely.geometry import Point, Polygon, shape

from .spec import (AUTO_START, CONFIRM_S, LIFE, REACH_M, REORGANIZATION, SPEC, TICK, TRACK_S)


class TruthBase:
    """The truth's state: the plan in force, the task organization and the true positions over
    time, what sensors could see, and how incidents and situations are recorded."""
    soft = False               # while set, an incident is recorded as a situation: it may be told, or not
    only: str | None = None    # while set, only this owner's EA is told (a contingency's holder)

    def __init__(self, sim, feats: list[dict], plan: dict, owners: list[str]):
        self.sim, self.owners = sim, owners
        self._hostiles: dict[float, dict] = {}
        # friendly reports may be up to one report interval old (plus a track period)
        self.slack = float(sim.report_s) + TRACK_S
        self.voi = SPEC
        self.geom: dict[str, object] = {}
        self.area: dict[str, object] = {}
        self.props: dict[str, dict] = {}
        for f in feats:
            p = f["properties"]
            g = shape(f["geometry"])
            self.geom[p["id"]] = g
            self.props[p["id"]] = p
            if isinstance(g, Polygon):
                self.area[p["id"]] = g
            elif isinstance(g, Point):
                self.area[p["id"]] = g.buffer(p.get("radius_m", 250.0))
            else:
                self.area[p["id"]] = g.buffer(p.get("width_m", 500.0 if p["kind"] == "avenue-of-approach" else 100.0) / 2)
        self.units = {u["id"]: u for u in plan["task_organization"]}
        self.missions = {m["id"]: m for m in plan["plans"][plan["initial_plan"]]}
        # the plan in force over time: the initial one until an order switches plans (its
        # missions no longer count from then on), the ordered one from then on
        order = getattr(sim, "order", None)
        cut = float(order["t"]) if order else math.inf
        self.valid = {mid: (0.0, cut) for mid in self.missions}
        if order:
            for m in plan["plans"][order["plan"]]:
                self.missions[m["id"]] = m
                self.valid[m["id"]] = (cut, math.inf)
        self.reorgs = sorted((m["start"]["t"], m["params"]["subject"], m["params"]["new_parent"])
                             for m in self.missions.values() if m["type"] in REORGANIZATION)
        self.ticks = np.arange(0.0, sim.duration + TICK / 2, TICK)
        self.leaves = sorted(u for u, d in self.units.items() if d["entities"])
        self.leaf_xy = {leaf: np.array([sim.leaf_center(leaf, t) for t in self.ticks]) for leaf in self.leaves}
        self.offsets = {leaf: np.array([sim.entity_off[e] for e in self.units[leaf]["entities"]]) for leaf in self.leaves}
        self._sub_cache: dict = {}
        self._everyone: tuple = (-1, None)
        self.started = {}
        self.ended = {}
        for m in self.missions.values():   # executed by the EA itself at its start time
            if m["type"] in AUTO_START and m.get("start", {}).get("t") is not None:
                self.started[m["id"]] = self.ended[m["id"]] = m["start"]["t"]
        for t, mid, _unit, ph in sim.confirmations:
            (self.started if ph == "start" else self.ended).setdefault(mid, t)
        self.incidents: list[dict] = []
        self.situations: list[dict] = []
        self.task_started: dict[str, float] = {}   # triggered contingency -> when its task may have started
        self.task_due: dict[str, float] = {}       # ... and by when it must have
        self.task_soft: set[str] = set()           # ... those that may have fired, or not: their task's incidents
                                                    # are only situations (`soft`)
        self.corridor_start: dict[str, np.ndarray] = {}   # route-less mission -> where its corridor starts

    # -- task organization over time ----------------------------------------------------

    def parent_at(self, t: float) -> dict[str, str | None]:
        par = {u: d.get("parent") for u, d in self.units.items()}
        for tr, subj, newp in self.reorgs:
            if tr <= t:
                par[subj] = newp
        return par

    def subtree(self, owner: str, t: float) -> set[str]:
        key = (owner, sum(1 for tr, _, _ in self.reorgs if tr <= t))
        hit = self._sub_cache.get(key)
        if hit is None:
            hit = self._sub_cache[key] = self._subtree(owner, t)
        return hit

    def _subtree(self, owner: str, t: float) -> set[str]:
        par = self.parent_at(t)
        out = {owner}
        changed = True
        while changed:
            changed = False
            for u, p in par.items():
                if p in out and u not in out:
                    out.add(u)
                    changed = True
        return out

    def platoon_of(self, unit: str, t: float) -> str:
        par = self.parent_at(t)
        u = unit
        while u is not None:
            if self.units[u]["echelon"] in ("platoon", "company", "battalion"):
                return u
            u = par[u]
        return unit

    def member_points(self, unit: str, k: int) -> np.ndarray:
        st = self.subtree(unit, self.ticks[k])
        return np.concatenate([self.leaf_xy[leaf][k] + self.offsets[leaf] for leaf in self.leaves if leaf in st])

    def everyone(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Every member's true x and y at tick k (cached for the tick last asked: a brigade
        has thousands, and each held position asks of every one)."""
        if self._everyone[0] != k:
            pts = np.concatenate([self.leaf_xy[leaf][k] + self.offsets[leaf] for leaf in self.leaves])
            self._everyone = (k, (pts[:, 0].copy(), pts[:, 1].copy()))
        return self._everyone[1]

    def judged(self, geom, unit: str, k: int, rule: str) -> float:
        pts = self.member_points(unit, k)
        if rule == "centroid":
            return geom.distance(Point(pts.mean(axis=0)))
        ds = [geom.distance(Point(p)) for p in pts]
        return min(ds) if rule == "any" else max(ds)

    def hostiles_at(self, t: float) -> dict[str, tuple[float, float, int]]:
        """The hostile groups there at `t` that the team could know of: all of them where
        tracks are reported from true positions, those within some sensor's range where
        hostiles are sensed (nobody can be told of a group no sensor covers), once some
        sensor has covered it for the scans a track needs to be confirmed."""
        out = self._hostiles.get(t)
        if out is not None:
            return out
        out = {}
        sensed = bool(getattr(self.sim, "sensors", ()))
        for h in self.sim.hostiles.values():
            p = h.pos(t)
            if p is not None and (not sensed or all(self._covered(h, t - dt) for dt in CONFIRM_S)):
                out[h.id] = (p[0], p[1], h.strength)
        if len(self._hostiles) > 4096:
            self._hostiles.clear()
        self._hostiles[t] = out
        return out

    def _covered(self, h, t: float) -> bool:
        """Whether hostile group `h` is within some sensor's range at `t`."""
        p = h.pos(t)
        return p is not None and any(math.hypot(p[0] - x, p[1] - y) <= r + REACH_M
                                     for x, y, r in ((*self.sim.sensor_xy(sid, t), r) for sid, r in self.sim.sensors))

    def owners_of(self, unit: str, t: float) -> list[str]:
        """The EAs whose units include `unit` (while a triggered contingency's task is judged:
        only the contingency's owner, the one EA that holds and executes it)."""
        return [o for o in self.owners if unit in self.subtree(o, t) and (self.only is None or o == self.only)]

    # -- recording ----------------------------------------------------------------------

    def must(self, owner, typ, accept, subjects, t0, t1, label="", at=None, about=None):
        """An incident: `at` when it happened (detection delay is counted from it), t0..t1
        the window an alert about it is accepted in; `life`: it threatens lives (the paper's
        flash: first contact with the enemy, fratricide, fire called near friendlies);
        `about`: the subjects an alert must name to be about it (default: any of them)."""
        if self.soft:   # judged on a task that may not be running at all
            self.may(owner, accept + [typ], subjects, t0, t1, about=about)
            return
        self.incidents.append({"owner": owner, "type": typ, "accept": sorted(set(accept) | {typ}),
                               "subjects": sorted(set(subjects)), "t0": round(t0, 1), "t1": round(t1, 1),
                               "at": round(t0 if at is None else at, 1), "life": typ in LIFE, "label": label,
                               **({"about": sorted(set(about))} if about else {})})
        self.may(owner, accept + [typ], subjects, t0, t1, about=about)

    def may(self, owner, accept, subjects, t0, t1, about=None):
        """A situation: alerts about it in t0..t1 are wanted but not required (`about`: as
        for an incident)."""
        self.situations.append({"owner": owner, "accept": sorted(set(accept)), "subjects": sorted(set(subjects)),
                                "t0": round(t0, 1), "t1": round(t1, 1), **({"about": sorted(about)} if about else {})})

    # -- per alert type ----------------------------------------------------------------------

    def thr(self, m: dict, key: str) -> float:
        return float(m["params"].get("voi", {}).get(key, self.voi[key]))

    def _ready_interval(self, mid: str) -> tuple[float, float]:
        m = self.missions[mid]
        v0, v1 = self.valid[mid]
        ready = max([self.ended.get(a, math.inf) for a in m.get("after", [])], default=0.0)
        return max(ready, v0), min(self.ended.get(mid, math.inf), v1)

    def _range(self, unit, par) -> float:
        u = unit
        while u is not None:
            if self.units[u].get("weapons_range_m"):
                return self.units[u]["weapons_range_m"]
            u = par[u]
        return float(self.voi["weapons_range_m"])
