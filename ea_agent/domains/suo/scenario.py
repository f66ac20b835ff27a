"""Loading and validating a scenario folder (see docs/scenario-format.md).

Every error names the file, the feature or line, and the field, so that a broken
scenario is fixed in one look.
"""
from __future__ import annotations

import difflib
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ea_agent.core.plan import PlanSpec, TaskOrg, Unit

from ea_agent.core.geo import Projection
from ea_agent.core.scenario import (ScenarioBase, ScenarioError, check_default_eas,  # noqa: F401
                                    check_key_chunk, checked_taskorg, guarded, load_plans, need as _need, new_id,
                                    number as _number, read_events, read_json as _read_json, scenario_head, unit_entry)

from .event_checks import EventContext, load_events
from .overlay import ControlMeasure, article, load_overlay
from .detect.windows import param_problem as window_problem
from .missions import REGISTRY, ContingentMission, ReorganizationMission


ECHELONS = ("brigade", "battalion", "company", "platoon", "squad")   # the SUO task organization's unit kinds


@dataclass
class Scenario(ScenarioBase):
    overlay: dict[str, ControlMeasure] = field(default_factory=dict)


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
        uid, where, ech, parent = unit_entry(u, where, ids, "echelon", ECHELONS)
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
    taskorg = checked_taskorg(units, f"{p.name}: task_organization")
    voi_keys = _voi_keys()

    def check_mission(cls, params: dict, where: str, unit: str) -> None:
        """This domain's checks of one mission of a plan."""
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

    plans, initial = load_plans(doc, p.name, ids, REGISTRY, "see `saim-mesh missions`", check_mission)
    return taskorg, plans, initial


def _check_trigger(tr: Any, where: str, overlay: dict, ids: set[str]) -> None:
    where += " params.trigger"
    kind = _need(tr, "kind", where, str)
    kinds = ContingentMission.TRIGGERS
    if kind not in kinds:
        raise ScenarioError(f"{where}: field 'kind': {kind!r} not {' or '.join(kinds)}")
    for k in tr:
        if k not in kinds[kind]:
            raise ScenarioError(f"{where}: field '{k}': not read by {article(kind)} trigger "
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


def _load_meta(root: Path) -> tuple[dict, str, Projection, float, dict[str, list[str]] | None]:
    meta = _read_json(root / "scenario.json")
    where = "scenario.json"
    if not isinstance(meta, dict):
        raise ScenarioError(f"{where}: expected an object")
    name, proj, duration = scenario_head(meta, root, where)
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


def load(path: str | Path, events: bool = True) -> Scenario:
    root = Path(path)
    if not root.is_dir():
        raise ScenarioError(f"{root}: not a scenario folder")
    meta, name, proj, duration, groups = guarded("scenario.json", _load_meta, root)
    overlay = guarded("overlay.geojson", load_overlay, root / "overlay.geojson", proj)
    taskorg, plans, initial = guarded("plan.json", load_plan, root / "plan.json", overlay)
    for cm in overlay.values():
        if cm.owner is not None and cm.owner not in taskorg.units:
            raise ScenarioError(f"overlay.geojson: feature {cm.id}: field 'owner': unknown unit {cm.owner!r}")
    check_default_eas(meta, taskorg.units)
    evs: list = []
    if events:
        cx = EventContext(duration, taskorg, plans,
                          None if groups is None else {sid for sids in groups.values() for sid in sids})
        evs = guarded("events", load_events, root, cx)
    return Scenario(name, root, proj, duration, taskorg, plans, initial, evs, meta, overlay=overlay)
