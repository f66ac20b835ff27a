"""Projection between WGS84 lon/lat and a metric CRS, done in bulk with pyproj."""
from __future__ import annotations

import math

import numpy as np
from pyproj import CRS, Transformer


class Projection:
    """Forward/inverse transforms for one scenario's metric CRS (e.g. a UTM zone)."""

    def __init__(self, epsg: int):
        self.epsg = epsg
        crs = CRS.from_epsg(epsg)
        if not crs.is_projected:
            raise ValueError(f"EPSG:{epsg} is not a projected (metric) CRS")
        self._fwd = Transformer.from_crs("EPSG:4326", crs, always_xy=True)
        self._inv = Transformer.from_crs(crs, "EPSG:4326", always_xy=True)

    def to_xy(self, lon, lat):
        """lon/lat (scalars or arrays) -> metres x/y."""
        return self._fwd.transform(lon, lat)

    def to_xy_inplace(self, lon: np.ndarray, lat: np.ndarray) -> None:
        """Project C-contiguous float64 arrays in place (lon becomes x, lat y): pyproj's
        in-place call skips the copies `to_xy` makes, a good share of its cost on the EA's
        batches of a few dozen reports."""
        self._fwd.transform(lon, lat, inplace=True)

    def to_lonlat(self, x, y):
        return self._inv.transform(x, y)

    def to_xy_array(self, lonlat: np.ndarray) -> np.ndarray:
        x, y = self._fwd.transform(lonlat[:, 0], lonlat[:, 1])
        return np.column_stack([x, y])


def bearing_name(dx: float, dy: float) -> str:
    """Eight-point compass direction of the vector (dx east, dy north)."""
    ang = (math.degrees(math.atan2(dx, dy)) + 360.0) % 360.0   # math: numpy scalars cost 10x here
    return ("N", "NE", "E", "SE", "S", "SW", "W", "NW")[int((ang + 22.5) // 45) % 8]
