"""Loading and validating a UV scenario folder (docs/uv-domain.md): scenario.json,
world.geojson, plan.json, events.jsonl[.gz], truth.json.

Every error is a ScenarioError naming the file, the feature, unit, mission or line,
and the field, so that a broken scenario is fixed in one look.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import shapely

from ea_agent.core.geo import Projection
from ea_agent.core.plan import PlanSpec, TaskOrg, Unit
from ea_agent.core.scenario import (ScenarioBase, ScenarioError, check_default_eas, check_key_chunk,
                                    checked_taskorg, guarded, load_plans, need, new_id, number, place_feature,
                                    read_events, read_json, scenario_head, unit_entry)

from . import messages   # registers the uv-* message kinds with the core codec
from .missions import REGISTRY
from .world import KINDS, Place

UNIT_KINDS = ("team", "ugv", "uav", "operator")
ROBOT_KINDS = ("ugv", "uav")
ROBOT_ATTRS = ("max_speed_mps", "turn_rate_dps", "sensor_range_m", "comm_range_m", "radius_m")
GEOM = {"obstacle": "Polygon", "waypoint": "Point", "patrol-area": "Polygon", "sector": "Polygon", "base": "Point"}


@dataclass
class UvScenario(ScenarioBase):
    world: dict[str, Place] = field(default_factory=dict)

    @property
    def robots(self) -> list[str]:
        return sorted(u.id for u in self.taskorg.units.values() if u.kind in ROBOT_KINDS)


def _load_meta(root: Path) -> tuple[dict, str, Projection, float]:
    where = "scenario.json"
    meta = read_json(root / where)
    if not isinstance(meta, dict):
        raise ScenarioError(f"{where}: expected an object")
    if meta.get("domain") != "uv":
        raise ScenarioError(f"{where}: field 'domain': expected \"uv\", got {meta.get('domain')!r:.40}")
    name, proj, duration = scenario_head(meta, root, where)
    ks = meta.get("keyspace")
    if ks is not None:
        number(need(ks, "cell_m", f"{where}: keyspace", (int, float)), f"{where}: keyspace", "cell_m", positive=True)
    targets = meta.get("targets")
    if targets is not None:
        if not isinstance(targets, list):
            raise ScenarioError(f"{where}: field 'targets': expected a list of target ids")
        for t in targets:
            check_key_chunk(t, where, "targets")
    return meta, name, proj, duration


def load_world(p: Path, proj: Projection) -> dict[str, Place]:
    fc = read_json(p)
    out: dict[str, Place] = {}
    for i, f in enumerate(need(fc, "features", p.name, list)):
        where, fid, kind, props, xy = place_feature(f, f"{p.name}: feature {i}", KINDS, out,
                                                    lambda kind: {GEOM[kind]}, proj)
        if props.get("radius_m") is not None:
            number(props["radius_m"], where, "radius_m", positive=True)
        shapely.prepare(xy)
        out[fid] = Place(fid, kind, xy, dict(props))
    return out


def _units(doc: dict, p: Path) -> TaskOrg:
    units: list[Unit] = []
    unit_ids: set[str] = set()
    for i, u in enumerate(need(doc, "team", p.name, list)):
        where = f"{p.name}: team[{i}]"
        uid, where, kind, parent = unit_entry(u, where, unit_ids, "kind", UNIT_KINDS)
        attrs = u.get("attrs", {})
        if not isinstance(attrs, dict):
            raise ScenarioError(f"{where}: field 'attrs': expected an object")
        for k in ROBOT_ATTRS if kind in ROBOT_KINDS else ():
            number(need(attrs, k, f"{where} attrs", (int, float)), where, f"attrs.{k}", positive=True)
        for k, v in attrs.items():
            if isinstance(v, (int, float)) and not isinstance(v, bool):
                number(v, where, f"attrs.{k}")
        ents = (uid,) if kind in ROBOT_KINDS else ()
        units.append(Unit(uid, str(u.get("name", uid)), kind, parent, ents, dict(attrs)))
    return checked_taskorg(units, f"{p.name}: team")


def _params(cls, params: Any, where: str, world: dict[str, Place], targets: set[str] | None) -> None:
    if not isinstance(params, dict):
        raise ScenarioError(f"{where}: field 'params': expected an object")
    for r in cls.required():
        if r not in params:
            raise ScenarioError(f"{where}: field 'params.{r}': missing (required by {cls.TYPE})")
    for k in cls.PLACE_PARAMS:
        v = params.get(k)
        if v is None:
            continue
        kinds = cls.PLACE_KINDS.get(k, KINDS)
        if not isinstance(v, str) or v not in world:
            raise ScenarioError(f"{where}: field 'params.{k}': {v!r:.60} names no feature of world.geojson")
        if world[v].kind not in kinds:
            raise ScenarioError(f"{where}: field 'params.{k}': {v!r} is a {world[v].kind}, not a {' or '.join(kinds)}")
    tp = cls.TARGET_PARAM
    if tp and params.get(tp) is not None:
        check_key_chunk(params[tp], where, f"params.{tp}")
        if targets is not None and params[tp] not in targets:
            raise ScenarioError(f"{where}: field 'params.{tp}': unknown target {params[tp]!r} (scenario.json targets)")
    if params.get("every_s") is not None:
        number(params["every_s"], where, "params.every_s", positive=True)
    voi = params.get("voi")
    if voi is not None:
        if not isinstance(voi, dict):
            raise ScenarioError(f"{where}: field 'params.voi': expected an object of thresholds")
        for k, v in voi.items():
            number(v, where, f"params.voi.{k}")


def load_plan(p: Path, world: dict[str, Place], targets: set[str] | None) -> tuple[TaskOrg, dict[str, PlanSpec], str]:
    doc = read_json(p)
    if not isinstance(doc, dict):
        raise ScenarioError(f"{p.name}: expected an object")
    taskorg = _units(doc, p)

    def check_mission(cls, params: dict, where: str, unit: str) -> None:
        """This domain's checks of one mission of a plan."""
        if taskorg.units[unit].kind not in ROBOT_KINDS:
            raise ScenarioError(f"{where}: field 'unit': {unit!r} is a {taskorg.units[unit].kind}, not a robot")
        _params(cls, params, where, world, targets)

    plans, initial = load_plans(doc, p.name, taskorg.units, REGISTRY, f"one of {', '.join(sorted(REGISTRY))}",
                                check_mission)
    return taskorg, plans, initial


def load_events(root: Path, duration: float, taskorg: TaskOrg, targets: set[str] | None) -> list:
    """The event script, time-ordered, within [0, duration_s], naming known robots."""
    robots = {u.id for u in taskorg.units.values() if u.kind in ROBOT_KINDS}
    units = set(taskorg.units)

    def known(v: str, where: str, name: str, pool: set[str], what: str) -> None:
        if v not in pool:
            check_key_chunk(v, where, name)
            raise ScenarioError(f"{where}: field '{name}': unknown {what} {v!r}")

    def check(m, where: str) -> None:
        if m.t > duration:
            raise ScenarioError(f"{where}: field 't': {m.t} is after the end of the scenario "
                                f"(scenario.json duration_s = {duration})")
        k = type(m)
        if k is messages.UvState or k is messages.UvSighting:
            known(m.robot, where, "robot", robots, "robot")
            if k is messages.UvSighting:
                check_key_chunk(m.target, where, "target")
                if targets is not None and m.target not in targets:
                    raise ScenarioError(f"{where}: field 'target': unknown target {m.target!r} (scenario.json targets)")
        elif k is messages.UvAgent:
            known(m.sender, where, "sender", units, "unit")
            known(m.to, where, "to", units, "unit")
            check_key_chunk(m.task, where, "task")
        else:
            raise ScenarioError(f"{where}: field 'kind': {m.KIND!r} is not a UV input message")
    return read_events(root, check)


def load(path: str | Path, events: bool = True) -> UvScenario:
    root = Path(path)
    if not root.is_dir():
        raise ScenarioError(f"{root}: not a scenario folder")
    meta, name, proj, duration = guarded("scenario.json", _load_meta, root)
    targets = set(meta["targets"]) if meta.get("targets") is not None else None
    world = guarded("world.geojson", load_world, root / "world.geojson", proj)
    taskorg, plans, initial = guarded("plan.json", load_plan, root / "plan.json", world, targets)
    check_default_eas(meta, taskorg.units)
    evs = guarded("events", load_events, root, duration, taskorg, targets) if events else []
    return UvScenario(name, root, proj, duration, taskorg, plans, initial, evs, meta, world=world)
