"""Numpy/shapely reasoners the detectors share: distances of units from control
measures, point-in-polygon matrices, which tracks are in which areas.

They only compute situations; detectors turn them into candidates and VOA
decides what is worth saying.
"""
from __future__ import annotations

import numpy as np
import shapely


def inside_matrix(pos: np.ndarray, polys: list) -> np.ndarray:
    """(n, len(polys)) containment of points in polygons; NaN points are outside. One
    broadcast GEOS call for every pair (a call per polygon on masked copies cost three times
    as much for a few polygons)."""
    if not polys or not len(pos):
        return np.zeros((len(pos), len(polys)), dtype=bool)
    x, y = pos[:, 0:1], pos[:, 1:2]
    arr = np.empty(len(polys), dtype=object)
    arr[:] = polys
    out = shapely.lib.contains_xy(arr, x, y)
    nan = np.isnan(x[:, 0])
    if nan.any():
        out[nan] = False
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


def judged_distance_swept(geom, p0: np.ndarray, p1: np.ndarray, rule: str) -> float | None:
    """As judged_distance, for members known only to lie between p0 and p1 (last report,
    dead-reckoned position): each member at its best point on that segment, so that a
    stale report alone never makes a unit out of position."""
    if len(p0) == 0:
        return None
    if rule == "centroid":
        p0, p1 = p0.mean(axis=0, keepdims=True), p1.mean(axis=0, keepdims=True)
    ds = shapely.distance(geom, shapely.linestrings(np.stack([p0, p1], axis=1)))
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


class PointCoords:
    """(x, y) of the overlay measures that are points, None for the others: read once per
    geometry, as shapely's accessors cost microseconds and detectors ask every epoch."""

    def __init__(self, dom) -> None:
        self.dom = dom
        self._hit: dict[str, tuple] = {}   # measure -> (its geometry, its x, y or None)

    def __call__(self, point: str) -> tuple[float, float] | None:
        g = self.dom.overlay[point].geom
        hit = self._hit.get(point)
        if hit is None or hit[0] is not g:
            hit = self._hit[point] = (g, (g.x, g.y) if g.geom_type == "Point" else None)
        return hit[1]
