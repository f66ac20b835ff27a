"""Run Execution Assistants in one process over a scenario's event script."""
from __future__ import annotations

import time
from typing import Callable, Iterable

from ea_agent.core.config import load_config
from ea_agent.core.manager import ExecutionAssistant, Sink
from ea_agent.domains.suo import make_ea

from .scenario import Scenario

DEFAULT_EAS = ("BN", "A", "B", "C", "A2")


def default_eas(sc: Scenario) -> list[str]:
    return list(sc.meta.get("default_eas", DEFAULT_EAS))


def run(sc: Scenario, owners: Iterable[str], sinks: Iterable[Sink] = (), voa: bool = True,
        config_path=None, speed: float | None = None,
        progress: Callable[[float], None] | None = None, overrides: dict | None = None) -> list[ExecutionAssistant]:
    """Feed every event to every EA in scenario-time order. speed=None runs as fast as
    possible; otherwise scenario time is paced at `speed` x wall-clock time."""
    sinks = list(sinks)
    eas = []
    for o in owners:
        if o not in sc.taskorg.units:
            raise KeyError(f"unknown unit {o!r}: not in the task organization of {sc.name}")
        eas.append(make_ea(sc, o, load_config(config_path, o, overrides), sinks, voa=voa))
    for ea in eas:
        ea.start(0.0)
    evs = sc.events
    n = len(evs)
    step = max(1, n // 200)
    t0 = time.monotonic()
    for i, ev in enumerate(evs):
        if speed:
            wait = t0 + ev.t / speed - time.monotonic()
            if wait > 0:
                for ea in eas:
                    ea.advance(ev.t - 1e-9)
                time.sleep(wait)
        for ea in eas:
            ea.submit(ev)
        if progress and i % step == 0:
            progress(i / n)
    for ea in eas:
        ea.finish(sc.duration_s)
    if progress:
        progress(1.0)
    return eas
