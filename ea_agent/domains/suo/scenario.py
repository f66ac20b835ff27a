"""Loading and validating a scenario folder (see docs/scenario-format.md).

Every error names the file, the feature or line, and the field, so that a broken
scenario is fixed in one look.
"""
from __future__ import annotations

import difflib
import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import shapely

from ea_agent.core.config import ConfigError
from ea_agent.core.plan import (END_TYPES, START_TYPES, MissionSpec, PlanSpec, TaskOrg, Unit)

from ea_agent.core.alert import Alert
from ea_agent.core.geo import Projection
from ea_agent.core.scenario import (MAX_DURATION_S, ScenarioBase, ScenarioError, check_key_chunk, lonlat_geometry, need as _need,  # noqa: F401
                                    number as _number, read_events, read_json as _read_json, time_constraint)

from . import messages as M
from .detect.windows import param_problem as window_problem
from .missions import REGISTRY, ContingentMission, ReorganizationMission

ECHELONS = ("brigade", "battalion", "company", "platoon", "squad")   # the SUO task organization's unit kinds
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


def _a(word: str) -> str:
    return f"{'an' if word[0] in 'aeio' else 'a'} {word}"


def _check_props(props: dict, kind: str, geom_type: str, where: str) -> None:
    """Nothing the loader would ignore: a property it reads only for other features, or a
    misspelling of one (see OVERLAY_PROPS)."""
    read = _read_props(kind, geom_type)
    for k in props:
        if k in read:
            continue
        if k in OVERLAY_PROPS:
            raise ScenarioError(f"{where}: field '{k}': not read for {_a(kind)} {geom_type} "
                                f"(it reads {', '.join(read)})")
        like = _like_prop(k)
        if like is not None:
            raise ScenarioError(f"{where}: field '{k}': unknown property, spelled like {like!r} ({_a(kind)} "
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


@dataclass
class Scenario(ScenarioBase):
    overlay: dict[str, ControlMeasure] = field(default_factory=dict)


def load_overlay(p: Path, proj: Projection) -> dict[str, ControlMeasure]:
    fc = _read_json(p)
    feats = _need(fc, "features", p.name, list)
    out: dict[str, ControlMeasure] = {}
    for i, f in enumerate(feats):
        where = f"{p.name}: feature {i}"
        props = _need(f, "properties", where, dict)
        fid = _need(props, "id", where, str)
        if not fid:
            raise ScenarioError(f"{where}: field 'id': empty")
        where = f"{p.name}: feature {i} ({fid})"
        kind = _need(props, "kind", where, str)
        if kind not in KINDS:
            raise ScenarioError(f"{where}: field 'kind': unknown kind {kind!r} (one of {', '.join(sorted(KINDS))})")
        if fid in out:
            raise ScenarioError(f"{where}: field 'id': duplicate id {fid!r}")
        g = _need(f, "geometry", where, dict)
        geom = lonlat_geometry(g, where)
        want = {"Polygon"} if kind in AREA_KINDS else {"LineString"} if kind in LINE_KINDS else {"Point", "Polygon"}
        if geom.geom_type not in want:
            raise ScenarioError(f"{where}: field 'geometry': a {kind} must be {' or '.join(sorted(want))}, not {geom.geom_type}")
        if not shapely.is_valid(geom):
            raise ScenarioError(f"{where}: field 'geometry': invalid {geom.geom_type} "
                                f"({shapely.is_valid_reason(geom)})")
        _check_props(props, kind, geom.geom_type, where)
        xy = shapely.transform(geom, lambda c: proj.to_xy_array(c))
        if not np.isfinite(shapely.get_coordinates(xy)).all():
            raise ScenarioError(f"{where}: field 'geometry': cannot be projected to EPSG:{proj.epsg} "
                                f"(too far from the scenario's area)")
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


def _unit_ref(v: Any, where: str, name: str, ids: set[str] | dict) -> str:
    if not isinstance(v, str):
        raise ScenarioError(f"{where}: field '{name}': expected a unit id, got {type(v).__name__}")
    if v not in ids:
        raise ScenarioError(f"{where}: field '{name}': unknown unit {v!r}")
    return v


def _area_ref(v: Any, where: str, name: str, overlay: dict) -> str:
    if not isinstance(v, str):
        raise ScenarioError(f"{where}: field '{name}': expected a control measure id, got {type(v).__name__}")
    if v not in overlay:
        raise ScenarioError(f"{where}: field '{name}': {v!r} is not in the overlay")
    return v


_NUMERIC_PARAMS = ("at", "fuzz_s", "expect_hostile_by", "until", "by")   # mission params read as times


def _voi_keys() -> set[str]:
    from ea_agent.core.config import load_config
    return {k for k, v in load_config()["voi"].items() if isinstance(v, (int, float)) and not isinstance(v, bool)}


def _check_params(cls, params: Any, where: str, prefix: str, overlay: dict, ids: set[str], voi_keys: set[str],
                  required: bool = True) -> None:
    """A mission's params against its class: required ones, control measures, units, numbers."""
    if not isinstance(params, dict):
        raise ScenarioError(f"{where}: field '{prefix.rstrip('.') or 'params'}': expected an object")
    unknown = cls.unknown_params(params)
    if unknown:   # before `required`: a misspelt required parameter is named as what it is
        known = sorted(cls.all_params())
        close = difflib.get_close_matches(unknown[0], known, n=1)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise ScenarioError(f"{where}: field '{prefix}{unknown[0]}': unknown parameter of {cls.TYPE} "
                            f"({hint}{cls.TYPE} knows {', '.join(known)}; see `saim-mesh missions`)")
    if required:
        for r in cls.required():
            if r not in params:
                raise ScenarioError(f"{where}: field '{prefix}{r}': missing (required by {cls.TYPE})")
    for g in cls.GEOMETRY_PARAMS:
        if params.get(g) is not None:
            _area_ref(params[g], where, prefix + g, overlay)
            if g in cls.LINE_PARAMS and overlay[params[g]].geom.geom_type != "LineString":
                raise ScenarioError(f"{where}: field '{prefix}{g}': {params[g]!r} is a "
                                    f"{overlay[params[g]].geom.geom_type}, not a line")
    for g in cls.UNIT_PARAMS:
        if params.get(g) is not None:
            _unit_ref(params[g], where, prefix + g, ids)
    for k in _NUMERIC_PARAMS:
        if params.get(k) is not None:
            _number(params[k], where, prefix + k)
    problem = cls.check_params(params, overlay) or window_problem(cls.TYPE, params, ids)
    if problem:
        raise ScenarioError(f"{where}: field '{prefix}{problem[0]}': {problem[1]}")
    voi = params.get("voi")
    if voi is not None:
        if not isinstance(voi, dict):
            raise ScenarioError(f"{where}: field '{prefix}voi': expected an object of VOI thresholds")
        for k, v in voi.items():
            if k not in voi_keys:
                raise ScenarioError(f"{where}: field '{prefix}voi.{k}': unknown VOI threshold "
                                    f"(one of {', '.join(sorted(voi_keys))})")
            _number(v, where, f"{prefix}voi.{k}")


def load_plan(p: Path, overlay: dict[str, ControlMeasure]) -> tuple[TaskOrg, dict[str, PlanSpec], str]:
    doc = _read_json(p)
    units = []
    seen_entities: set[str] = set()
    ids: set[str] = set()
    for i, u in enumerate(_need(doc, "task_organization", p.name, list)):
        where = f"{p.name}: task_organization[{i}]"
        uid = check_key_chunk(_need(u, "id", where, str), where, "id")
        where += f" ({uid})"
        if uid in ids:
            raise ScenarioError(f"{where}: field 'id': duplicate unit id")
        ids.add(uid)
        ech = _need(u, "echelon", where, str)
        if ech not in ECHELONS:
            raise ScenarioError(f"{where}: field 'echelon': {ech!r} not one of {', '.join(ECHELONS)}")
        parent = u.get("parent")
        if parent is not None and not isinstance(parent, str):
            raise ScenarioError(f"{where}: field 'parent': expected a unit id or null, got {type(parent).__name__}")
        ents = u.get("entities", [])
        if not isinstance(ents, list) or not all(isinstance(e, str) for e in ents):
            raise ScenarioError(f"{where}: field 'entities': expected a list of entity ids")
        for e in ents:
            check_key_chunk(e, where, "entities")
        dup = seen_entities.intersection(ents)
        if dup or len(set(ents)) != len(ents):
            first = sorted(dup)[0] if dup else next(e for e in ents if ents.count(e) > 1)
            raise ScenarioError(f"{where}: field 'entities': {first!r} already belongs to a unit")
        seen_entities.update(ents)
        bnd = u.get("boundary")
        if bnd is not None and (not isinstance(bnd, str) or bnd not in overlay or overlay[bnd].kind != "boundary"):
            raise ScenarioError(f"{where}: field 'boundary': {bnd!r} is not a boundary in the overlay")
        wr = u.get("weapons_range_m")
        attrs = {"boundary": bnd,
                 "weapons_range_m": _number(wr, where, "weapons_range_m", positive=True) if wr is not None else None}
        units.append(Unit(uid, str(u.get("name", uid)), ech, parent, tuple(ents), attrs))
    roots = [u.id for u in units if u.parent is None]
    if len(roots) != 1:
        raise ScenarioError(f"{p.name}: task_organization: field 'parent': need exactly one top unit, found {roots}")
    for u in units:
        if u.parent is not None and u.parent not in ids:
            raise ScenarioError(f"{p.name}: task_organization ({u.id}): field 'parent': unknown unit {u.parent!r}")
    taskorg = TaskOrg(units)
    cyc = taskorg.cycle()
    if cyc:
        raise ScenarioError(f"{p.name}: task_organization ({cyc[0]}): field 'parent': cycle in the command "
                            f"hierarchy: {' -> '.join(cyc)} (every unit must lead up to {roots[0]})")
    voi_keys = _voi_keys()
    plans: dict[str, PlanSpec] = {}
    for pname, ms in _need(doc, "plans", p.name, dict).items():
        check_key_chunk(pname, f"{p.name}: plans", "name")
        if not isinstance(ms, list):
            raise ScenarioError(f"{p.name}: plans.{pname}: expected a list of missions")
        specs: list[MissionSpec] = []
        mids: set[str] = set()
        for i, m in enumerate(ms):
            where = f"{p.name}: plans.{pname}[{i}]"
            mid = check_key_chunk(_need(m, "id", where, str), where, "id")
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
            _check_params(cls, params, where, "params.", overlay, ids, voi_keys)
            if issubclass(cls, ContingentMission):
                _check_trigger(params["trigger"], where, overlay, ids)
                task = params["task"]
                if not isinstance(task, str) or task not in REGISTRY:
                    raise ScenarioError(f"{where}: field 'params.task': unknown mission type {task!r}")
                # triggered, the task is a monitored mission: it needs what its class requires
                _check_params(REGISTRY[task], params.get("task_params", {}), where, "params.task_params.", overlay,
                              ids, voi_keys)
            if issubclass(cls, ReorganizationMission) and params["subject"] == taskorg.root:
                raise ScenarioError(f"{where}: field 'params.subject': the top unit {params['subject']!r} "
                                    f"cannot be resubordinated")
            if issubclass(cls, ReorganizationMission) and params["subject"] == params["new_parent"]:
                raise ScenarioError(f"{where}: field 'params.new_parent': a unit cannot be put under itself")
            after = m.get("after", [])
            if not isinstance(after, list) or not all(isinstance(a, str) for a in after):
                raise ScenarioError(f"{where}: field 'after': expected a list of mission ids")
            if mid in after:
                raise ScenarioError(f"{where}: field 'after': a mission cannot come after itself")
            specs.append(MissionSpec(mid, unit, typ, time_constraint(m.get("start"), where + " start", START_TYPES),
                                     time_constraint(m.get("end"), where + " end", END_TYPES), tuple(after), params))
        for s in specs:
            for a in s.after:
                if a not in mids:
                    raise ScenarioError(f"{p.name}: plans.{pname} ({s.id}): field 'after': unknown mission {a!r}")
        plan = PlanSpec(pname, specs)
        cyc = plan.cycle()
        if cyc:
            raise ScenarioError(f"{p.name}: plans.{pname} ({cyc[0]}): field 'after': cycle "
                                f"{' -> '.join(reversed(cyc))} (each waits for the one before it, so none "
                                f"would ever become ready)")
        plans[pname] = plan
    initial = doc.get("initial_plan", "main")
    if not isinstance(initial, str) or initial not in plans:
        raise ScenarioError(f"{p.name}: field 'initial_plan': no plan named {initial!r}")
    return taskorg, plans, initial


def _check_trigger(tr: Any, where: str, overlay: dict, ids: set[str]) -> None:
    where += " params.trigger"
    kind = _need(tr, "kind", where, str)
    kinds = ContingentMission.TRIGGERS
    if kind not in kinds:
        raise ScenarioError(f"{where}: field 'kind': {kind!r} not {' or '.join(kinds)}")
    for k in tr:
        if k not in kinds[kind]:
            raise ScenarioError(f"{where}: field '{k}': not read by {_a(kind)} trigger "
                                f"(it reads {', '.join(kinds[kind])})")
    _area_ref(_need(tr, "area", where), where, "area", overlay)
    if kind == "unit-at":
        _unit_ref(_need(tr, "unit", where), where, "unit", ids)
        if tr.get("within_m") is not None:
            _number(tr["within_m"], where, "within_m")
        if tr.get("rule", "centroid") not in ("centroid", "any", "all"):
            raise ScenarioError(f"{where}: field 'rule': {tr['rule']!r} not centroid, any or all")
    elif tr.get("min_strength") is not None:
        ms = tr["min_strength"]
        if isinstance(ms, bool) or not isinstance(ms, int) or ms < 0:
            raise ScenarioError(f"{where}: field 'min_strength': expected an integer >= 0, got {ms!r:.40}")


@dataclass
class EventContext:
    """What the events are checked against: every event must lie in [0, duration_s] and
    name units, missions, plans and sensors that exist."""
    duration_s: float = math.inf
    taskorg: TaskOrg | None = None
    plans: dict[str, PlanSpec] = field(default_factory=dict)
    sensors: set[str] | None = None   # sensors of the fusion groups (None: no fusion in this scenario)

    def __post_init__(self):
        self.mission_units: dict[str, set[str]] = {}
        for pl in self.plans.values():
            for m in pl.missions:
                self.mission_units.setdefault(m.id, set()).add(m.unit)
        # strings already known to be good key chunks (ids checked by the plan loader)
        self.good: set[str] = set(self.mission_units) | set(self.plans)
        if self.taskorg is not None:
            self.good |= set(self.taskorg.units) | set(self.taskorg.entity_unit)
        self.good |= self.sensors or set()


def _check_event(m, cx: EventContext, where: str) -> None:
    """The scenario-level checks of one decoded event (the message checks its own fields)."""
    if m.t > cx.duration_s:
        raise ScenarioError(f"{where}: field 't': {m.t} is after the end of the scenario "
                            f"(scenario.json duration_s = {cx.duration_s})")
    k = type(m)
    good = cx.good
    if k is M.LocationReport:   # unknown entities are fine (the EA counts and drops them); their ids must be keys
        if m.entity not in good:
            good.add(check_key_chunk(m.entity, where, "entity"))
        return
    if k is M.SensorTrack:
        if m.track not in good:
            good.add(check_key_chunk(m.track, where, "track"))
        return
    if k is M.SensorHit:
        if m.sensor not in good:
            good.add(check_key_chunk(m.sensor, where, "sensor"))
        if cx.sensors is None:
            raise ScenarioError(f"{where}: field 'sensor': a sensor hit, but scenario.json has no fusion groups")
        if m.sensor not in cx.sensors:
            raise ScenarioError(f"{where}: field 'sensor': {m.sensor!r} is in no fusion group of scenario.json")
        return
    if k is Alert:
        raise ScenarioError(f"{where}: field 'kind': an alert is an output of the EAs, not an input event")
    units = cx.taskorg.units if cx.taskorg is not None else None

    def unit(name: str) -> str:
        v = getattr(m, name)
        if v not in good:
            good.add(check_key_chunk(v, where, name))
        if units is not None and v not in units:
            raise ScenarioError(f"{where}: field '{name}': unknown unit {v!r}")
        return v

    if k is M.MissionConfirm:
        u = unit("unit")
        if m.mission not in good:
            good.add(check_key_chunk(m.mission, where, "mission"))
        if units is not None:
            owners = cx.mission_units.get(m.mission)
            if owners is None:
                raise ScenarioError(f"{where}: field 'mission': unknown mission {m.mission!r} (in no plan)")
            if u not in owners:
                raise ScenarioError(f"{where}: field 'unit': mission {m.mission!r} belongs to "
                                    f"{' or '.join(sorted(owners))}, not to {u!r}")
    elif k is M.Order:
        unit("issuer")
        if m.plan not in good:
            good.add(check_key_chunk(m.plan, where, "plan"))
        if units is not None and m.plan not in cx.plans:
            raise ScenarioError(f"{where}: field 'plan': no plan named {m.plan!r} in plan.json")
        if m.mission is not None and units is not None:
            if m.mission not in good:
                good.add(check_key_chunk(m.mission, where, "mission"))
            owners = cx.mission_units.get(m.mission)
            if owners is None:
                raise ScenarioError(f"{where}: field 'mission': unknown mission {m.mission!r} (in no plan)")
            phase = "start" if m.action == "start-mission" else "end"
            if not any(getattr(ms, phase).type == "ON-ORDER" for pl in cx.plans.values() for ms in pl.missions
                       if ms.id == m.mission):
                raise ScenarioError(f"{where}: field 'mission': {m.mission!r} does not {phase} ON-ORDER "
                                    f"(its plan says when)")
            if not any(m.issuer in cx.taskorg.ancestors(u) for u in owners):
                raise ScenarioError(f"{where}: field 'issuer': {m.issuer!r} is not a superior of "
                                    f"{' or '.join(sorted(owners))}, whose mission {m.mission!r} it orders")
    elif k is M.CallForFire or k is M.CallForFireConfirm:
        unit("requester")
        if m.cff not in good:
            good.add(check_key_chunk(m.cff, where, "cff"))
    elif k is M.Reorganization:
        u, parent = unit("unit"), unit("new_parent")
        if u == parent:
            raise ScenarioError(f"{where}: field 'new_parent': a unit cannot be put under itself")
        if cx.taskorg is not None and u == cx.taskorg.root:
            raise ScenarioError(f"{where}: field 'unit': the top unit {u!r} cannot be resubordinated")
    else:
        raise ScenarioError(f"{where}: field 'kind': {m.KIND!r} is not a small-unit operations message")


def load_events(root: Path, context: EventContext | None = None) -> list:
    """The event script, time-ordered; with a `context` (as `load` gives) also checked
    against the scenario: times within duration_s, known units, missions and plans."""
    cx = context or EventContext()
    dur, good, loc = cx.duration_s, cx.good, M.LocationReport

    def check(m, where: str) -> None:
        if not (type(m) is loc and m.t <= dur and m.entity in good):   # the common case, checked
            _check_event(m, cx, where)
    return read_events(root, check)


def _load_meta(root: Path) -> tuple[dict, str, Projection, float, dict[str, list[str]] | None]:
    meta = _read_json(root / "scenario.json")
    where = "scenario.json"
    if not isinstance(meta, dict):
        raise ScenarioError(f"{where}: expected an object")
    name = meta.get("name", root.resolve().name)
    check_key_chunk(name, where if "name" in meta else f"{where} (no name: the folder name is used)", "name")
    epsg = _need(meta, "epsg", where, int)
    try:
        proj = Projection(epsg)
    except Exception as e:   # pyproj raises its own CRSError (and ValueError for a geographic CRS)
        raise ScenarioError(f"{where}: field 'epsg': {e}") from None
    duration = _number(_need(meta, "duration_s", where, (int, float)), where, "duration_s", positive=True)
    if duration > MAX_DURATION_S:
        raise ScenarioError(f"{where}: field 'duration_s': {duration} is more than {MAX_DURATION_S:.0f} s (7 days)")
    groups = None
    if meta.get("fusion") is not None:
        fw = f"{where}: fusion"
        groups = _need(meta["fusion"], "groups", fw, dict)
        if not groups:
            raise ScenarioError(f"{fw}: field 'groups': no fusion group")
        owner: dict[str, str] = {}
        for g, sids in groups.items():
            check_key_chunk(g, f"{fw}.groups", "name")
            if not isinstance(sids, list):
                raise ScenarioError(f"{fw}.groups.{g}: expected a list of sensor ids")
            for sid in sids:
                check_key_chunk(sid, f"{fw}.groups.{g}", "sensor")
                if sid in owner:
                    raise ScenarioError(f"{fw}.groups.{g}: field 'sensor': {sid!r} is already in group {owner[sid]!r}")
                owner[sid] = g
        sensors = meta["fusion"].get("sensors", [])
        for i, sn in enumerate(sensors if isinstance(sensors, list) else [None]):
            if not isinstance(sn, dict):
                raise ScenarioError(f"{fw}.sensors[{i}]: expected an object")
            sg = sn.get("sigma_m", 30.0)
            if type(sg) not in (int, float) or not math.isfinite(sg) or sg <= 0:
                raise ScenarioError(f"{fw}.sensors[{i}] ({str(sn.get('id'))[:40]}): field 'sigma_m': expected a "
                                    f"finite number > 0 (the sensor's position noise), got {sg!r:.40}")
    return meta, name, proj, duration, groups


def _guarded(fname: str, fn, *args):
    """Run one file's loader; an error its checks did not foresee still names the file, in one line."""
    try:
        return fn(*args)
    except (ScenarioError, ConfigError):   # (plan.json's VOI overrides are checked against configs/ea.toml)
        raise
    except (TypeError, ValueError, AttributeError, KeyError, IndexError) as e:
        raise ScenarioError(f"{fname}: unexpected {type(e).__name__} while loading: {e}") from e


def load(path: str | Path, events: bool = True) -> Scenario:
    root = Path(path)
    if not root.is_dir():
        raise ScenarioError(f"{root}: not a scenario folder")
    meta, name, proj, duration, groups = _guarded("scenario.json", _load_meta, root)
    overlay = _guarded("overlay.geojson", load_overlay, root / "overlay.geojson", proj)
    taskorg, plans, initial = _guarded("plan.json", load_plan, root / "plan.json", overlay)
    for cm in overlay.values():
        if cm.owner is not None and cm.owner not in taskorg.units:
            raise ScenarioError(f"overlay.geojson: feature {cm.id}: field 'owner': unknown unit {cm.owner!r}")
    dflt = meta.get("default_eas")
    if dflt is not None:
        if not isinstance(dflt, list) or not dflt:
            raise ScenarioError("scenario.json: field 'default_eas': expected a non-empty list of unit ids")
        for u in dflt:
            _unit_ref(u, "scenario.json", "default_eas", taskorg.units)
    evs: list = []
    if events:
        cx = EventContext(duration, taskorg, plans,
                          None if groups is None else {sid for sids in groups.values() for sid in sids})
        evs = _guarded("events", load_events, root, cx)
    return Scenario(name, root, proj, duration, taskorg, plans, initial, evs, meta, overlay=overlay)
