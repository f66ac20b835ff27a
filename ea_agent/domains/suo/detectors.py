"""Specialized reasoners of the SUO domain, vectorised with numpy/shapely.

They only compute situations; the domain turns them into candidates and VOA
decides what is worth saying.
"""
from __future__ import annotations

import numpy as np
import shapely


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
    d = np.hypot(pos[:, None, 0] - pos[None, :, 0], pos[:, None, 1] - pos[None, :, 1])
    in_range = d <= np.maximum(rng[:, None], rng[None, :])   # NaN compares False
    in_own = inside[np.arange(n), bnd]
    in_other = inside[:, bnd]            # [i, j]: i inside j's boundary
    i_fault = ~in_own[:, None] & in_other
    risk = in_range & (bnd[:, None] != bnd[None, :]) & (
        i_fault | i_fault.T | (~in_own[:, None] & ~in_own[None, :]))
    risk &= (dirty[:, None] | dirty[None, :]) & (mine[:, None] | mine[None, :])
    ii, jj = np.nonzero(np.triu(risk, 1))
    return [(int(i), int(j), float(d[i, j])) for i, j in zip(ii, jj)]


def inside_matrix(pos: np.ndarray, polys: list) -> np.ndarray:
    """(n, len(polys)) containment of points in polygons; NaN points are outside."""
    out = np.zeros((len(pos), len(polys)), dtype=bool)
    ok = ~np.isnan(pos[:, 0])
    for k, poly in enumerate(polys):
        out[ok, k] = shapely.contains_xy(poly, pos[ok, 0], pos[ok, 1])
    return out


def distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(len(a), len(b)) Euclidean distances."""
    return np.hypot(a[:, None, 0] - b[None, :, 0], a[:, None, 1] - b[None, :, 1])


def judged_distance(geom, pts: np.ndarray, rule: str, centroid: tuple[float, float] | None) -> float | None:
    """Distance of a unit from a control measure, judged by the mission's rule:
    its centroid, its nearest member (any) or its farthest member (all)."""
    if rule == "centroid":
        if centroid is None:
            return None
        return float(shapely.distance(geom, shapely.Point(centroid)))
    if len(pts) == 0:
        return None
    if geom.geom_type == "Point":
        ds = np.hypot(pts[:, 0] - geom.x, pts[:, 1] - geom.y)
        return float(ds.min() if rule == "any" else ds.max())
    if geom.geom_type == "Polygon":   # fast path: members inside are at distance 0
        inside = shapely.contains_xy(geom, pts[:, 0], pts[:, 1])
        if inside.all() or (rule == "any" and inside.any()):
            return 0.0
    ds = shapely.distance(geom, shapely.points(pts))
    return float(ds.min() if rule == "any" else ds.max())


class AreaIndex:
    """Which tracks are in which areas, with a bounding-box prefilter."""

    def __init__(self, areas: dict[str, object]):
        self.ids = list(areas)
        self.polys = [areas[a] for a in self.ids]
        self.bounds = np.array([p.bounds for p in self.polys]) if self.polys else np.zeros((0, 4))

    def members(self, xy: np.ndarray) -> dict[str, np.ndarray]:
        """area id -> indices of the points inside it (only non-empty areas)."""
        out: dict[str, np.ndarray] = {}
        if len(xy) == 0 or not self.ids:
            return out
        x, y = xy[:, 0], xy[:, 1]
        b = self.bounds
        cand = (x[None, :] >= b[:, 0:1]) & (x[None, :] <= b[:, 2:3]) & (y[None, :] >= b[:, 1:2]) & (y[None, :] <= b[:, 3:4])
        for k in np.nonzero(cand.any(axis=1))[0]:
            idx = np.nonzero(cand[k])[0]
            hit = idx[shapely.contains_xy(self.polys[k], x[idx], y[idx])]
            if len(hit):
                out[self.ids[k]] = hit
        return out
