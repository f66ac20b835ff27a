"""Fratricide risk by the unit-boundary rule (paper 6.7.2), relaxed inside the lane of a
passage of lines: there the passing unit is expected inside the passed unit's boundary."""
from __future__ import annotations

from collections import defaultdict

import numpy as np
import shapely

from ea_agent.core.alert import Candidate

from ..missions import PassageOfLines
from ..render import km
from .base import Changes, Detector, platoon_of
from .geometry import inside_matrix


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
        self.outside = np.zeros(len(leaves), dtype=bool)
        self.own_poly = np.array([self.bnd_polys[b] if b >= 0 else None for b in self.leaf_bnd], dtype=object)
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

    def detect(self, t: float, ch: Changes, cands: list[Candidate]) -> None:
        dom = self.dom
        ok_l, leaf_i = self.frat_ok_l, dom.leaf_i
        rows = [leaf_i[u] for u in ch.leaves if ok_l[leaf_i[u]]]
        if not rows:
            return
        pos = dom.leaf_xy
        r = np.array(rows)
        self.outside[r] = False
        r = r[~np.isnan(pos[r, 0])]
        if len(r):
            self.outside[r] = ~shapely.contains_xy(self.own_poly[r], pos[r, 0], pos[r, 1])
        if not self.outside.any():
            return
        dirty = np.zeros(len(dom.leaves), dtype=bool)
        dirty[r] = True
        inside = inside_matrix(pos, self.bnd_polys)
        bnd = np.where(self.frat_ok, self.leaf_bnd, 0)
        pos = np.where(self.frat_ok[:, None], pos, np.nan)
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
