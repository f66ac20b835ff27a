"""Small unit operations (paper section 6): missions, detectors and VOA heuristics."""
from __future__ import annotations

from ea_agent.core.manager import ExecutionAssistant, Sink
from ea_agent.core.config import load_config

from .domain import ALERT_TYPES, CATEGORY, SuoDomain


def make_ea(scenario, owner: str, cfg: dict | None = None, sinks: list[Sink] | tuple = (), voa: bool = True,
            config_path=None) -> ExecutionAssistant:
    """An SUO Execution Assistant for `owner` on a loaded scenario."""
    cfg = cfg or load_config(config_path, owner)
    dom = SuoDomain(owner, scenario.taskorg, scenario.plans, scenario.initial_plan, scenario.overlay,
                    scenario.projection, cfg)
    return ExecutionAssistant(owner, dom, cfg, sinks, voa=voa)


__all__ = ["make_ea", "ALERT_TYPES", "CATEGORY", "SuoDomain"]
