"""A SUO scenario's recorded events checked against its plan as they are read: each
report's units, missions and times known, its kind allowed; every error names the line and
the field (docs/scenario-format.md)."""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

from ea_agent.core.alert import Alert
from ea_agent.core.plan import PlanSpec, TaskOrg
from ea_agent.core.scenario import ScenarioError, check_key_chunk, read_events

from . import messages

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
    if k is messages.LocationReport:   # unknown entities are fine (the EA counts and drops them); their ids must be keys
        if m.entity not in good:
            good.add(check_key_chunk(m.entity, where, "entity"))
        return
    if k is messages.SensorTrack:
        if m.track not in good:
            good.add(check_key_chunk(m.track, where, "track"))
        return
    if k is messages.SensorHit:
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

    if k is messages.MissionConfirm:
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
    elif k is messages.Order:
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
    elif k is messages.CallForFire or k is messages.CallForFireConfirm:
        unit("requester")
        if m.cff not in good:
            good.add(check_key_chunk(m.cff, where, "cff"))
    elif k is messages.Reorganization:
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
    dur, good, loc = cx.duration_s, cx.good, messages.LocationReport

    def check(m, where: str) -> None:
        if not (type(m) is loc and m.t <= dur and m.entity in good):   # the common case, checked
            _check_event(m, cx, where)
    return read_events(root, check)
