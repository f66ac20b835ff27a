"""The overlay of a SUO scenario (overlay.geojson): its control measures read, checked
and projected, every error naming the feature and the field (docs/scenario-format.md)."""
from __future__ import annotations

import difflib
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import shapely

from ea_agent.core.geo import Projection
from ea_agent.core.scenario import ScenarioError, check_key_chunk, place_feature
from ea_agent.core.scenario import need as _need
from ea_agent.core.scenario import number as _number
from ea_agent.core.scenario import read_json as _read_json

AREA_KINDS = {"boundary", "objective", "battle-position", "assembly-area", "engagement-area", "area"}
LINE_KINDS = {"route", "phase-line", "avenue-of-approach", "obstacle"}
POINT_KINDS = {"decision-point", "checkpoint", "nai"}   # a Point with radius_m, or a Polygon
KINDS = AREA_KINDS | LINE_KINDS | POINT_KINDS

# The feature properties the loader reads. Any other property is the user's own description
# (a name, a note: the console shows them all), except one spelled like these (`radius`,
# `Width_M`, `widht_m`) or one of these where it is not read (`radius_m` on a polygon):
# both would be silently ignored, so both are errors.
OVERLAY_PROPS = {
    "id": "unique id of the control measure",
    "kind": "one of KINDS",
    "owner": "optional unit whose plan holds it",
    "width_m": "lines: width when used as an area (default 100; avenue-of-approach 500)",
    "radius_m": "decision-point, nai, checkpoint given as a Point: radius (default 250)",
}


def _read_props(kind: str, geom_type: str) -> tuple[str, ...]:
    """The OVERLAY_PROPS the loader reads for a feature of this kind and geometry."""
    size = ("width_m",) if kind in LINE_KINDS else ("radius_m",) if kind in POINT_KINDS and geom_type == "Point" else ()
    return ("id", "kind", "owner", *size)


def _norm(key: str) -> str:
    return re.sub(r"[^a-z0-9]", "", key.lower())


_PROP_SPELLINGS = {**{_norm(k): k for k in OVERLAY_PROPS},   # `Width_M`, `radius-m`; `radius` (no unit)
                   **{_norm(k[:-2]): k for k in OVERLAY_PROPS if k.endswith("_m")}}


def _like_prop(key: str) -> str | None:
    """The loader property `key` is a misspelling of (other case or punctuation, no unit
    suffix, a typo), or None for a descriptive property of the user's own."""
    hit = _PROP_SPELLINGS.get(_norm(key))
    if hit is None and len(key) > 3:
        close = difflib.get_close_matches(key.lower(), OVERLAY_PROPS, n=1, cutoff=0.85)
        hit = close[0] if close else None
    return hit


def article(word: str) -> str:
    return f"{'an' if word[0] in 'aeio' else 'a'} {word}"


def _check_props(props: dict, kind: str, geom_type: str, where: str) -> None:
    """Nothing the loader would ignore: a property it reads only for other features, or a
    misspelling of one (see OVERLAY_PROPS)."""
    read = _read_props(kind, geom_type)
    for k in props:
        if k in read:
            continue
        if k in OVERLAY_PROPS:
            raise ScenarioError(f"{where}: field '{k}': not read for {article(kind)} {geom_type} "
                                f"(it reads {', '.join(read)})")
        like = _like_prop(k)
        if like is not None:
            raise ScenarioError(f"{where}: field '{k}': unknown property, spelled like {like!r} ({article(kind)} "
                                f"{geom_type} reads {', '.join(read)}; other properties are descriptive)")


@dataclass(slots=True)
class ControlMeasure:
    """A named overlay feature in metres; `area` is what 'inside' means for it."""
    id: str
    kind: str
    owner: str | None
    geom: Any       # shapely geometry (projected)
    area: Any       # polygon used for containment tests
    props: dict = field(default_factory=dict)


def _geom_types(kind: str) -> set[str]:
    return {"Polygon"} if kind in AREA_KINDS else {"LineString"} if kind in LINE_KINDS else {"Point", "Polygon"}


def load_overlay(p: Path, proj: Projection) -> dict[str, ControlMeasure]:
    fc = _read_json(p)
    feats = _need(fc, "features", p.name, list)
    out: dict[str, ControlMeasure] = {}
    for i, f in enumerate(feats):
        where, fid, kind, props, xy = place_feature(f, f"{p.name}: feature {i}", sorted(KINDS), out, _geom_types,
                                                    proj, key_id=False)
        _check_props(props, kind, xy.geom_type, where)
        size = {k: _number(props[k], where, k, positive=True) for k in ("width_m", "radius_m")
                if props.get(k) is not None}
        if kind in AREA_KINDS or xy.geom_type == "Polygon":
            area = xy
        elif kind == "avenue-of-approach":
            area = xy.buffer(size.get("width_m", 500.0) / 2.0)
        elif kind in POINT_KINDS:
            area = xy.buffer(size.get("radius_m", 250.0))
        else:
            area = xy.buffer(size.get("width_m", 100.0) / 2.0)
        shapely.prepare(area)
        owner = props.get("owner")
        if owner is not None:
            check_key_chunk(owner, where, "owner")
        out[fid] = ControlMeasure(fid, kind, owner, xy, area, dict(props))
    return out
