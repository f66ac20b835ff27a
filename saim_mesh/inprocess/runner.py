"""Run Execution Assistants in one process over a scenario's event script."""
from __future__ import annotations

import time
from typing import Callable, Iterable

from ea_agent import domains
from ea_agent.core.config import load_config
from ea_agent.core.manager import ExecutionAssistant, Sink

from ..authority import directives as D
from ..logs.cmdlog import Logged
from ..authority.commands import apply, tap
from ..fusion import make_node
from ..protocol.messages import SensorHit
from ..scenario import Scenario


def default_eas(sc: Scenario) -> list[str]:
    return domains.of(sc).default_eas(sc)


def config_for(sc: Scenario, owner: str, config_path=None, overrides: dict | None = None) -> dict:
    """`owner`'s parameters: the scenario's domain's defaults, then the given file."""
    return load_config(config_path, owner, overrides, defaults=domains.of(sc).CONFIG_PATH)


def make_ea(sc: Scenario, owner: str, cfg: dict, sinks=(), voa: bool = True) -> ExecutionAssistant:
    return domains.of(sc).make_ea(sc, owner, cfg, sinks, voa=voa)


class Fusion:
    """The scenario's fusion nodes (one per sensor group), run in process."""

    def __init__(self, sc: Scenario, groups: dict[str, list[str]]):
        self.nodes = {g: make_node(sc, g) for g in sorted(groups)}
        self.group_of = {sid: g for g, sids in groups.items() for sid in sids}
        self.next_t = min(n.window_end for n in self.nodes.values())

    @classmethod
    def of(cls, sc: Scenario) -> "Fusion | None":
        f = sc.meta.get("fusion")
        return cls(sc, f["groups"]) if f else None

    def flush(self, t: float) -> list:
        return [tr for n in self.nodes.values() for tr in n.flush(t)]

    def feed(self, ev) -> list:
        out = []
        if ev.t >= self.next_t:
            for n in self.nodes.values():
                out += n.flush(ev.t)
            self.next_t = min(n.window_end for n in self.nodes.values())
        if type(ev) is SensorHit:
            node = self.nodes.get(self.group_of.get(ev.sensor, ""))
            if node is not None:
                out += node.add(ev)
        return out


def wire_notices(eas: list[ExecutionAssistant], sinks: Iterable[Callable] = ()) -> None:
    """Each EA's notices to `sinks`, and its escalations to its superior's EA when that
    one runs here too (on the mesh they travel on notice/<superior>/<owner>); an
    escalation is then held to that commander's notice budget (`ea_agent.core.budget`)."""
    by_owner = {ea.owner: ea for ea in eas}
    sinks = list(sinks)

    def budget_of(ea):
        def of(unit: str):
            other = by_owner.get(unit)
            return other.notify.budget if other is not None else None
        return of

    def route(n) -> None:
        up = by_owner.get(n.to) if n.kind == "escalate" else None
        if up is not None:
            up.take_notice(n, budgeted=True)   # the sender asked its budget (budget_of)
    for ea in eas:
        ea.notify.budget_for = budget_of(ea)
        ea.notice_sinks.extend(sinks)
        ea.notice_sinks.append(route)


def run(sc: Scenario, owners: Iterable[str], sinks: Iterable[Sink] = (), voa: bool = True,
        config_path=None, speed: float | None = None,
        progress: Callable[[float], None] | None = None, overrides: dict | None = None,
        on_made: Callable[[list], None] | None = None, commands: list | None = None,
        armed: bool = False, notice_sinks: Iterable[Callable] = (),
        ack_after_s: float | None = None, directives: Iterable = ()) -> list[ExecutionAssistant]:
    """Feed every event to every EA in scenario-time order. speed=None runs as fast as
    possible; otherwise scenario time is paced at `speed` x wall-clock time.
    `commands`: a commander's commands (`cmdlog.Logged`, in time order), each applied
    after the EA reached its time, as the peer applied it after that clock tick;
    `armed`: urgent alerts are re-notified and escalated until acknowledged from the start
    (a console watching); `ack_after_s`: a modelled commander acknowledges each urgent alert
    that long after it (implies armed); `notice_sinks`: every EA's re-notifications and
    escalations. An escalation to a superior run here reaches that EA (`take_notice`).
    `directives` (`directives.Taken`): orders and confirmations over the mesh, each taken
    by every EA it concerns at its `at`, after the events before it, as a live peer does."""
    sinks = list(sinks)
    eas = []
    for o in owners:
        if o not in sc.taskorg.units:
            raise KeyError(f"unknown unit {o!r}: not in the task organization of {sc.name}")
        eas.append(make_ea(sc, o, config_for(sc, o, config_path, overrides), sinks, voa=voa))
    by_owner = {ea.owner: ea for ea in eas}
    wire_notices(eas, notice_sinks)
    if on_made is not None:   # e.g. a console hooks the EAs before they start
        on_made(eas)
    for ea in eas:
        if armed or ack_after_s is not None:
            ea.arm(ack_after_s)
        if commands:
            tap(ea)   # a `cff confirm` needs the calls for fire seen before it (the peer taps at start too)
        ea.start(0.0)
    cmds = [c for c in commands or () if c.unit in by_owner]
    dirs = sorted(directives, key=lambda tk: tk.sort_key())
    validate = None
    if dirs or any(isinstance(c.cmd, D.Taken) for c in cmds):
        from ..authority.plans import validator
        validate = validator(sc)
    if dirs:   # stable: commands first at equal times, directives in (at, by, n) order
        cmds = sorted(cmds + [Logged(ea.owner, tk.t, tk) for tk in dirs for ea in eas], key=lambda c: c.t)

    def command_until(t: float, end: bool = False) -> None:
        """Commands due before the events at time t: those of a time before t, and those of
        t itself taken before its facts (a replay-driven peer's, directives); a live peer's
        (`after`) come after the facts at their time, as it took them."""
        while cmds and (cmds[0].t < t or cmds[0].t == t and (end or not cmds[0].after)):
            c = cmds.pop(0)
            ea = by_owner[c.unit]
            if isinstance(c.cmd, D.Taken):   # after the facts before it, before those at its time
                ea.advance(c.t, strict=True)
                D.take(ea, c.cmd, validate)
                continue
            ea.advance(c.t, strict=not c.after)
            apply(ea, c.cmd, c.t)
    fusion = Fusion.of(sc)
    evs = sc.events
    n = len(evs)
    step = max(1, n // 200)
    t0 = time.monotonic()
    for i, ev in enumerate(evs):
        if cmds:
            command_until(ev.t)
        trs = fusion.feed(ev) if fusion is not None else ()   # tracks of closed windows: dated before ev
        if speed:
            wait = t0 + ev.t / speed - time.monotonic()
            if wait > 0:
                for ea in eas:   # everything before the earliest fact still to come is in
                    ea.advance(min([ev.t, *(tr.t for tr in trs)]) - 1e-9)
                time.sleep(wait)
        if fusion is not None:   # hits go to the fusion nodes; the EAs get their tracks
            for tr in trs:
                for ea in eas:
                    ea.submit(tr)
            if type(ev) is SensorHit:
                continue
        for ea in eas:
            ea.submit(ev)
        if progress and i % step == 0:
            progress(i / n)
    if fusion is not None:   # windows that closed after the last event (as a fusion peer does at the end)
        for tr in fusion.flush(sc.duration_s):
            for ea in eas:
                ea.submit(tr)
    command_until(sc.duration_s, end=True)
    for ea in eas:
        ea.finish(sc.duration_s)
    if progress:
        progress(1.0)
    return eas
