"""Fratricide risk by the unit-boundary rule (paper 6.7.2), relaxed inside the lane of a
passage of lines: there the passing unit is expected inside the passed unit's boundary."""
from __future__ import annotations

import math
from collections import defaultdict
from math import hypot

import numpy as np
import shapely

from ea_agent.core.alert import Candidate

from ..missions import PassageOfLines
from ..render import km
from .base import Changes, Detector, platoon_of


def fratricide_pairs(pos: np.ndarray, bnd: np.ndarray, inside: np.ndarray, rng: np.ndarray,
                     dirty: np.ndarray, mine: np.ndarray) -> list[tuple[int, int, float]]:
    """Pairs of units at fratricide risk by the unit-boundary rule (paper 6.7.2).

    pos: (n,2) positions (NaN unknown); bnd: (n,) index of each unit's boundary;
    inside: (n,b) whether unit i is inside boundary k; rng: weapons range per unit;
    dirty: units whose position changed; mine: units of the EA owner.

    Two units inside their own boundaries never alert, even within range. A pair
    alerts when one is inside the other's boundary (and not its own) and within
    weapons range, or when both are outside their own boundaries and in range.
    Units sharing a boundary are one owner's business and are not paired.
    """
    n = len(pos)
    if n < 2 or not dirty.any():
        return []
    in_own = inside[np.arange(n), bnd]
    out = np.flatnonzero(~in_own & ~np.isnan(pos[:, 0]))   # a pair needs one of them outside its own
    if not len(out):
        return []
    # rows: the units outside their own boundary; for such a unit i the rule reduces to
    # "i inside j's boundary, or j outside its own too"
    d = np.hypot(pos[out, None, 0] - pos[None, :, 0], pos[out, None, 1] - pos[None, :, 1])
    in_range = d <= np.maximum(rng[out, None], rng[None, :])   # NaN compares False
    risk = in_range & (bnd[out, None] != bnd[None, :]) & (inside[out][:, bnd] | ~in_own[None, :])
    risk &= (dirty[out, None] | dirty[None, :]) & (mine[out, None] | mine[None, :])
    found = {}
    for r, j in zip(*np.nonzero(risk)):
        i = int(out[r])
        found[(min(i, int(j)), max(i, int(j)))] = float(d[r, j])
    return sorted((i, j, dist) for (i, j), dist in found.items())


class Fratricide(Detector):
    """Only units outside their own boundary can be at risk, so the pair check runs
    only while some unit is outside; the inside test runs for movers."""
    TYPES = {"fratricide": "policy-constraint-violated"}

    def org_changed(self) -> None:
        """Boundaries, weapons ranges and ownership per leaf, as arrays."""
        dom = self.dom
        to = dom.taskorg
        leaves = dom.leaves
        bnd_units = sorted({to.nearest_with(u, 'boundary') for u in leaves if to.nearest_with(u, 'boundary')})
        self.bnd_polys = [dom.overlay[to.units[b].attrs['boundary']].area for b in bnd_units]
        bi = {b: k for k, b in enumerate(bnd_units)}
        self.leaf_bnd = np.array([bi.get(to.nearest_with(u, 'boundary'), -1) for u in leaves])
        self.frat_ok = self.leaf_bnd >= 0
        self.frat_ok_l = self.frat_ok.tolist()
        dflt = float(dom.voi_cfg["weapons_range_m"])
        self.leaf_rng = np.array([self._weapons_range(u, dflt) for u in leaves])
        self.leaf_mine = np.array([u in dom.own_units for u in leaves])
        self.outside: set[int] = set()   # leaves last seen outside their own boundary
        self.leaf_bnd_l = self.leaf_bnd.tolist()
        self.bnd0 = np.where(self.frat_ok, self.leaf_bnd, 0)   # any boundary where none: those leaves have no position
        self.rows_n = np.arange(len(leaves))
        self.bnd_arr = np.array(self.bnd_polys, dtype=object)
        self.bnd_edges = [p.boundary if p.geom_type in ("Polygon", "MultiPolygon") else None for p in self.bnd_polys]
        # leaf -> (x, y, distance to its boundary's edge, inside) when last measured
        self._own: list[tuple[float, float, float, bool]] = [(math.nan, math.nan, -1.0, False)] * len(leaves)
        shapely.prepare(self.bnd_polys)   # containment is asked for every moving leaf each epoch
        self.platoon = {u: platoon_of(to, u) for u in leaves}

    def _weapons_range(self, unit: str, dflt: float) -> float:
        to = self.dom.taskorg
        u = to.nearest_with(unit, "weapons_range_m")
        return dflt if u is None else float(to.units[u].attrs["weapons_range_m"])

    def _lanes(self) -> list[tuple[set[str], set[str], object]]:
        """(passing unit's subtree, passed unit's subtree, lane area) of each passage of lines with a lane that
        has not ended (the lane is agreed beforehand, so it holds before the passage starts)."""
        dom = self.dom
        if dom.plan is None:
            return []
        to = dom.taskorg
        return [(set(to.subtree(m.unit)), set(to.subtree(m.params["partner"])), dom.overlay[m.params["lane"]].area)
                for m in dom.missions.values() if isinstance(m, PassageOfLines) and m.params.get("lane")
                and dom.plan.state.get(m.id) not in ("done", "aborted")]

    @staticmethod
    def _passing(a: str, b: str, xy: np.ndarray, lanes) -> bool:
        """Leaf `a` belongs to a passing unit, is inside its lane, and `b` to the unit it passes."""
        return any(a in mine and b in theirs and shapely.contains_xy(lane, xy[0], xy[1])
                   for mine, theirs, lane in lanes)

    def _in_own(self, i: int, x: float, y: float) -> bool:
        """Whether leaf i at (x, y) is inside its own boundary. A leaf that moved less than
        its distance to that boundary when last measured is on the same side, so the
        polygon is asked only near its edge (the test is inlined in detect)."""
        x0, y0, clear, ins = self._own[i]
        return ins if hypot(x - x0, y - y0) < clear else self._measure(i, x, y)

    def _measure(self, i: int, x: float, y: float) -> bool:
        """Leaf i inside its own boundary, asked of the polygon, and how far it may move
        before it must be asked again."""
        k = self.leaf_bnd_l[i]
        ins = bool(shapely.contains_xy(self.bnd_polys[k], x, y))
        edge = self.bnd_edges[k]
        # less a millimetre: far more than the rounding of map coordinates; a boundary that
        # is no polygon keeps no side, and is asked every time
        clear = float(shapely.distance(edge, shapely.Point(x, y))) - 1e-3 if edge is not None else -1.0
        self._own[i] = (x, y, clear, ins)
        return ins

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        dom = self.dom
        ok_l, leaf_i = self.frat_ok_l, dom.leaf_i
        if not ch.leaves:
            return
        xy = dom.leaf_xy.tolist()
        outside, own_l = self.outside, self._own
        moved = []
        rows = False
        for u in ch.leaves:
            i = leaf_i[u]
            if not ok_l[i]:
                continue
            rows = True
            x, y = xy[i]
            if x != x:   # position unknown
                outside.discard(i)
                continue
            moved.append(i)
            x0, y0, clear, ins = own_l[i]
            if not hypot(x - x0, y - y0) < clear:
                ins = self._measure(i, x, y)
            if ins:
                outside.discard(i)
            else:
                outside.add(i)
        if not (rows and outside):
            return
        n = len(dom.leaves)
        dirty = np.zeros(n, dtype=bool)
        dirty[moved] = True
        # where every leaf is now, inside its own boundary or not (reports held back by
        # the watchman may have moved leaves this epoch did not see move); only the rows
        # of leaves outside their own are needed whole (fratricide_pairs reads no others)
        in_own = self._in_own
        own = [ok_l[i] and x == x and in_own(i, x, y) for i, (x, y) in enumerate(xy)]
        inside = np.zeros((n, len(self.bnd_polys)), dtype=bool)
        bnd = self.bnd0
        inside[self.rows_n, bnd] = own
        out = [i for i in range(n) if ok_l[i] and not own[i] and xy[i][0] == xy[i][0]]
        if out:
            px = dom.leaf_xy[out]
            inside[out] = shapely.contains_xy(self.bnd_arr[None, :], px[:, 0, None], px[:, 1, None])
        pos = np.where(self.frat_ok[:, None], dom.leaf_xy, np.nan)
        to = dom.taskorg
        groups: dict[tuple[str, str], list[tuple[str, str, float]]] = defaultdict(list)
        lanes = None
        for i, j, d in fratricide_pairs(pos, bnd, inside, self.leaf_rng, dirty, self.leaf_mine):
            a, b = dom.leaves[i], dom.leaves[j]
            lanes = self._lanes() if lanes is None else lanes
            if lanes and (self._passing(a, b, pos[i], lanes) or self._passing(b, a, pos[j], lanes)):
                continue
            pa, pb = self.platoon[a], self.platoon[b]
            if (pa, a) > (pb, b):
                a, b, pa, pb = b, a, pb, pa
            groups[(pa, pb)].append((a, b, d))
        for (pa, pb), pairs in sorted(groups.items()):
            dmin = min(p[2] for p in pairs)
            squads = sorted({s for p in pairs for s in p[:2]})
            out_a = [s for s in squads if to.is_under(s, pa) and not inside[dom.leaf_i[s], bnd[dom.leaf_i[s]]]]
            out_b = [s for s in squads if to.is_under(s, pb) and not inside[dom.leaf_i[s], bnd[dom.leaf_i[s]]]]
            culprit = pa if out_a else pb
            other = pb if culprit == pa else pa
            cands.append(Candidate(t, "fratricide", "flash", tuple([pa, pb] + squads),
                                   f"Fratricide risk: {dom.name(culprit)} out of its boundary within "
                                   f"{km(dmin)} of {dom.name(other)}",
                                   key=("fratricide", pa, pb), measure=1000.0 / max(dmin, 1.0),
                                   details={"pairs": [[a, b, round(d, 1)] for a, b, d in sorted(pairs)],
                                            "outside_boundary": sorted(out_a + out_b), "min_distance_m": round(dmin, 1)}))
