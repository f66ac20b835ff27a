"""Loading and validating a scenario folder (see docs/scenario-format.md).

Every error names the file, the feature or line, and the field, so that a broken
scenario is fixed in one look.
"""
from __future__ import annotations

import gzip
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import shapely
from shapely.geometry import shape

from ea_agent.core.plan import (ECHELONS, END_TYPES, START_TYPES, MissionSpec, PlanSpec, TaskOrg,
                                TimeConstraint, Unit)
from ea_agent.domains.suo.missions import REGISTRY

from . import messages as M
from .geo import Projection

AREA_KINDS = {"boundary", "objective", "battle-position", "assembly-area", "engagement-area", "area"}
LINE_KINDS = {"route", "phase-line", "avenue-of-approach"}
POINT_KINDS = {"decision-point", "checkpoint", "nai"}   # a Point with radius_m, or a Polygon
KINDS = AREA_KINDS | LINE_KINDS | POINT_KINDS


class ScenarioError(ValueError):
    pass


@dataclass(slots=True)
class ControlMeasure:
    """A named overlay feature in metres; `area` is what 'inside' means for it."""
    id: str
    kind: str
    owner: str | None
    geom: Any       # shapely geometry (projected)
    area: Any       # polygon used for containment tests
    props: dict = field(default_factory=dict)


@dataclass
class Scenario:
    name: str
    root: Path
    projection: Projection
    duration_s: float
    taskorg: TaskOrg
    plans: dict[str, PlanSpec]
    initial_plan: str
    overlay: dict[str, ControlMeasure]
    events: list
    meta: dict

    @property
    def plan(self) -> PlanSpec:
        return self.plans[self.initial_plan]

    def truth(self) -> dict:
        p = self.root / "truth.json"
        if not p.exists():
            raise ScenarioError(f"{p}: no ground-truth file in this scenario")
        return json.loads(p.read_text())


def _need(d: dict, key: str, where: str, types: type | tuple = object):
    if not isinstance(d, dict):
        raise ScenarioError(f"{where}: expected an object")
    if key not in d:
        raise ScenarioError(f"{where}: field '{key}': missing")
    v = d[key]
    if not isinstance(v, types) or isinstance(v, bool) and types is not bool:
        raise ScenarioError(f"{where}: field '{key}': expected {getattr(types, '__name__', types)}, got {type(v).__name__}")
    return v


def _read_json(p: Path) -> Any:
    try:
        return json.loads(p.read_text())
    except FileNotFoundError:
        raise ScenarioError(f"{p}: file missing") from None
    except json.JSONDecodeError as e:
        raise ScenarioError(f"{p}:{e.lineno}: invalid JSON: {e.msg}") from None


def load_overlay(p: Path, proj: Projection) -> dict[str, ControlMeasure]:
    fc = _read_json(p)
    feats = _need(fc, "features", p.name, list)
    out: dict[str, ControlMeasure] = {}
    for i, f in enumerate(feats):
        where = f"{p.name}: feature {i}"
        props = _need(f, "properties", where, dict)
        fid = _need(props, "id", where, str)
        where = f"{p.name}: feature {i} ({fid})"
        kind = _need(props, "kind", where, str)
        if kind not in KINDS:
            raise ScenarioError(f"{where}: field 'kind': unknown kind {kind!r} (one of {', '.join(sorted(KINDS))})")
        if fid in out:
            raise ScenarioError(f"{where}: field 'id': duplicate id {fid!r}")
        g = _need(f, "geometry", where, dict)
        try:
            geom = shape(g)
        except Exception as e:
            raise ScenarioError(f"{where}: field 'geometry': {e}") from None
        coords = shapely.get_coordinates(geom)
        if len(coords) == 0 or not all(math.isfinite(c) for c in coords.ravel()):
            raise ScenarioError(f"{where}: field 'geometry': empty or non-finite coordinates")
        if (abs(coords[:, 0]) > 180).any() or (abs(coords[:, 1]) > 90).any():
            raise ScenarioError(f"{where}: field 'geometry': coordinates are not WGS84 lon/lat")
        want = {"Polygon"} if kind in AREA_KINDS else {"LineString"} if kind in LINE_KINDS else {"Point", "Polygon"}
        if geom.geom_type not in want:
            raise ScenarioError(f"{where}: field 'geometry': a {kind} must be {' or '.join(sorted(want))}, not {geom.geom_type}")
        xy = shapely.transform(geom, lambda c: proj.to_xy_array(c))
        if kind in AREA_KINDS or xy.geom_type == "Polygon":
            area = xy
        elif kind == "avenue-of-approach":
            area = xy.buffer(float(props.get("width_m", 500.0)) / 2.0)
        elif kind in POINT_KINDS:
            area = xy.buffer(float(props.get("radius_m", 250.0)))
        else:
            area = xy.buffer(float(props.get("width_m", 100.0)) / 2.0)
        shapely.prepare(area)
        owner = props.get("owner")
        if owner is not None and not isinstance(owner, str):
            raise ScenarioError(f"{where}: field 'owner': expected a unit id string")
        out[fid] = ControlMeasure(fid, kind, owner, xy, area, dict(props))
    return out


def _tc(d: Any, where: str, allowed: tuple[str, ...]) -> TimeConstraint:
    if d is None:
        return TimeConstraint()
    typ = _need(d, "type", where, str)
    if typ not in allowed:
        raise ScenarioError(f"{where}: field 'type': {typ!r} not one of {', '.join(allowed)}")
    if typ in ("ASAP", "ON-ORDER"):
        return TimeConstraint(typ)
    t = _need(d, "t", where, (int, float))
    if not math.isfinite(t) or t < 0:
        raise ScenarioError(f"{where}: field 't': must be a finite time >= 0")
    return TimeConstraint(typ, float(t))


def load_plan(p: Path, overlay: dict[str, ControlMeasure]) -> tuple[TaskOrg, dict[str, PlanSpec], str]:
    doc = _read_json(p)
    units = []
    seen_entities: set[str] = set()
    for i, u in enumerate(_need(doc, "task_organization", p.name, list)):
        where = f"{p.name}: task_organization[{i}]"
        uid = _need(u, "id", where, str)
        where += f" ({uid})"
        ech = _need(u, "echelon", where, str)
        if ech not in ECHELONS:
            raise ScenarioError(f"{where}: field 'echelon': {ech!r} not one of {', '.join(ECHELONS)}")
        ents = u.get("entities", [])
        if not isinstance(ents, list) or not all(isinstance(e, str) for e in ents):
            raise ScenarioError(f"{where}: field 'entities': expected a list of entity ids")
        dup = seen_entities.intersection(ents)
        if dup:
            raise ScenarioError(f"{where}: field 'entities': {sorted(dup)[0]!r} already belongs to another unit")
        seen_entities.update(ents)
        bnd = u.get("boundary")
        if bnd is not None and (bnd not in overlay or overlay[bnd].kind != "boundary"):
            raise ScenarioError(f"{where}: field 'boundary': {bnd!r} is not a boundary in the overlay")
        wr = u.get("weapons_range_m")
        units.append(Unit(uid, str(u.get("name", uid)), ech, u.get("parent"), tuple(ents),
                          float(wr) if wr is not None else None, bnd))
    ids = {u.id for u in units}
    roots = [u.id for u in units if u.parent is None]
    if len(roots) != 1:
        raise ScenarioError(f"{p.name}: task_organization: field 'parent': need exactly one top unit, found {roots}")
    for u in units:
        if u.parent is not None and u.parent not in ids:
            raise ScenarioError(f"{p.name}: task_organization ({u.id}): field 'parent': unknown unit {u.parent!r}")
    taskorg = TaskOrg(units)
    plans: dict[str, PlanSpec] = {}
    for pname, ms in _need(doc, "plans", p.name, dict).items():
        specs: list[MissionSpec] = []
        mids: set[str] = set()
        for i, m in enumerate(ms):
            where = f"{p.name}: plans.{pname}[{i}]"
            mid = _need(m, "id", where, str)
            where += f" ({mid})"
            if mid in mids:
                raise ScenarioError(f"{where}: field 'id': duplicate mission id")
            mids.add(mid)
            unit = _need(m, "unit", where, str)
            if unit not in ids:
                raise ScenarioError(f"{where}: field 'unit': unknown unit {unit!r}")
            typ = _need(m, "type", where, str)
            cls = REGISTRY.get(typ)
            if cls is None:
                raise ScenarioError(f"{where}: field 'type': unknown mission type {typ!r} (see `saim-mesh missions`)")
            params = m.get("params", {})
            if not isinstance(params, dict):
                raise ScenarioError(f"{where}: field 'params': expected an object")
            for r in cls.required():
                if r not in params:
                    raise ScenarioError(f"{where}: field 'params.{r}': missing (required by {typ})")
            for g in cls.GEOMETRY_PARAMS:
                if params.get(g) is not None and params[g] not in overlay:
                    raise ScenarioError(f"{where}: field 'params.{g}': {params[g]!r} is not in the overlay")
            for g in cls.UNIT_PARAMS:
                if params.get(g) is not None and params[g] not in ids:
                    raise ScenarioError(f"{where}: field 'params.{g}': unknown unit {params[g]!r}")
            if typ in ("branch", "sequel"):
                _check_trigger(params["trigger"], where, overlay, ids)
                if params["task"] not in REGISTRY:
                    raise ScenarioError(f"{where}: field 'params.task': unknown mission type {params['task']!r}")
            after = m.get("after", [])
            if not isinstance(after, list):
                raise ScenarioError(f"{where}: field 'after': expected a list of mission ids")
            specs.append(MissionSpec(mid, unit, typ, _tc(m.get("start"), where + " start", START_TYPES),
                                     _tc(m.get("end"), where + " end", END_TYPES), tuple(after), params))
        for s in specs:
            for a in s.after:
                if a not in mids:
                    raise ScenarioError(f"{p.name}: plans.{pname} ({s.id}): field 'after': unknown mission {a!r}")
        plans[pname] = PlanSpec(pname, specs)
    initial = doc.get("initial_plan", "main")
    if initial not in plans:
        raise ScenarioError(f"{p.name}: field 'initial_plan': no plan named {initial!r}")
    return taskorg, plans, initial


def _check_trigger(tr: Any, where: str, overlay: dict, ids: set[str]) -> None:
    where += " params.trigger"
    kind = _need(tr, "kind", where, str)
    if kind not in ("hostile-in-area", "unit-at"):
        raise ScenarioError(f"{where}: field 'kind': {kind!r} not hostile-in-area or unit-at")
    area = _need(tr, "area", where, str)
    if area not in overlay:
        raise ScenarioError(f"{where}: field 'area': {area!r} is not in the overlay")
    if kind == "unit-at" and _need(tr, "unit", where, str) not in ids:
        raise ScenarioError(f"{where}: field 'unit': unknown unit {tr['unit']!r}")


def _open_events(root: Path):
    for name in ("events.jsonl", "events.jsonl.gz"):
        p = root / name
        if p.exists():
            return p, (gzip.open(p, "rt") if name.endswith(".gz") else p.open())
    raise ScenarioError(f"{root}: no events.jsonl or events.jsonl.gz")


def load_events(root: Path) -> list:
    p, fh = _open_events(root)
    out = []
    last_t = 0.0
    with fh:
        for lineno, line in enumerate(fh, 1):
            if not line.strip():
                continue
            try:
                d = json.loads(line)
            except json.JSONDecodeError as e:
                raise ScenarioError(f"{p.name}:{lineno}: invalid JSON: {e.msg}") from None
            try:
                m = M.from_dict(d)
            except M.MessageError as e:
                raise ScenarioError(f"{p.name}:{lineno}: {e}") from None
            if m.t < last_t:
                raise ScenarioError(f"{p.name}:{lineno}: field 't': {m.t} is earlier than the line before ({last_t}); events must be time-ordered")
            last_t = m.t
            out.append(m)
    return out


def load(path: str | Path, events: bool = True) -> Scenario:
    root = Path(path)
    if not root.is_dir():
        raise ScenarioError(f"{root}: not a scenario folder")
    meta = _read_json(root / "scenario.json")
    epsg = _need(meta, "epsg", "scenario.json", int)
    try:
        proj = Projection(epsg)
    except Exception as e:
        raise ScenarioError(f"scenario.json: field 'epsg': {e}") from None
    overlay = load_overlay(root / "overlay.geojson", proj)
    taskorg, plans, initial = load_plan(root / "plan.json", overlay)
    for cm in overlay.values():
        if cm.owner is not None and cm.owner not in taskorg.units:
            raise ScenarioError(f"overlay.geojson: feature {cm.id}: field 'owner': unknown unit {cm.owner!r}")
    duration = float(_need(meta, "duration_s", "scenario.json", (int, float)))
    return Scenario(str(meta.get("name", root.name)), root, proj, duration, taskorg, plans, initial, overlay,
                    load_events(root) if events else [], meta)
