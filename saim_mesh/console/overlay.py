"""The scenario's map overlay (SUO control measures, UV places) as GeoJSON in lon/lat:
the scenario keeps projected shapely geometries; the browser's map wants WGS84."""
from __future__ import annotations

import shapely
from shapely.geometry import mapping


def _round(c):
    if isinstance(c, (list, tuple)) and c and isinstance(c[0], (int, float)):
        return [round(float(v), 6) for v in c]
    return [_round(x) for x in c]


def overlay_geojson(sc) -> dict:
    """A FeatureCollection of the scenario's overlay (`sc.overlay`) or world (`sc.world`)."""
    items = getattr(sc, "overlay", None) or getattr(sc, "world", None) or {}
    proj = sc.projection
    feats = []
    for fid, it in sorted(items.items()):
        try:
            g = mapping(shapely.transform(it.geom, proj.to_lonlat, interleaved=False))
            geom = {"type": g["type"], "coordinates": _round(g["coordinates"])}
        except Exception:   # a geometry pyproj or shapely cannot take: left off the map, not fatal
            continue
        props = {**getattr(it, "props", {}), "id": fid, "kind": it.kind}
        if getattr(it, "owner", None) is not None:
            props["owner"] = it.owner
        feats.append({"type": "Feature", "id": fid, "properties": props,
                      "geometry": geom})
    return {"type": "FeatureCollection", "features": feats}
