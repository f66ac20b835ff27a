"""Small unit operations (paper section 6): missions, detectors and VOA heuristics."""
from __future__ import annotations

from ea_agent.core.manager import ExecutionAssistant, Sink
from ea_agent.core.config import DEFAULT_PATH, load_config

from .domain import ALERT_TYPES, CATEGORY, SuoDomain


def make_ea(scenario, owner: str, cfg: dict | None = None, sinks: list[Sink] | tuple = (), voa: bool = True,
            config_path=None) -> ExecutionAssistant:
    """An SUO Execution Assistant for `owner` on a loaded scenario."""
    cfg = cfg or load_config(config_path, owner)
    dom = SuoDomain(owner, scenario.taskorg, scenario.plans, scenario.initial_plan, scenario.overlay,
                    scenario.projection, cfg)
    return ExecutionAssistant(owner, dom, cfg, sinks, voa=voa)


NAME = "suo"
CONFIG_PATH = DEFAULT_PATH   # configs/ea.toml: the defaults and the schema of SUO parameters
DEFAULT_EAS = ("BN", "A", "B", "C", "A2")


def load(path, events: bool = True):
    """The SUO scenario folder at `path` (scenario.json, overlay.geojson, plan.json, events)."""
    from .scenario import load as _load
    return _load(path, events=events)


def org_changes(sc) -> list[tuple[float, str, str]]:
    """(t, unit, new parent) of the planned reorganizations, in time order: the replay
    keys each report by the command path as it will be then."""
    from .missions import REGISTRY, ReorganizationMission
    return sorted((m.start.t, m.params["subject"], m.params["new_parent"]) for m in sc.plan.missions
                  if issubclass(REGISTRY[m.type], ReorganizationMission) and m.start.t is not None)


def default_eas(sc) -> list[str]:
    return list(sc.meta.get("default_eas", DEFAULT_EAS))


def mesh_units(sc) -> list[str]:
    """Brigade, battalions, companies (brigade troops too) and platoons: every unit above
    squad level has a peer."""
    return sorted(u for u, x in sc.taskorg.units.items() if x.kind in ("brigade", "battalion", "company", "platoon"))


def generate(out, seed: int = 7, small: bool = False, sensors: bool = False, incidents: str = "scripted",
             brigade: bool = False) -> dict:
    """The battalion scenario, or (`brigade`) the brigade: three battalions and brigade troops."""
    if brigade:
        if sensors or incidents != "scripted":
            raise ValueError("the brigade draws its own battles and has no sensors: "
                             "leave out --sensors and --incidents with --brigade")
        from .brigade import write as write_brigade
        return write_brigade(out, small=small, seed=seed)
    from .generator import write
    return write(out, small=small, seed=seed, sensors=sensors, incidents=incidents)


__all__ = ["make_ea", "ALERT_TYPES", "CATEGORY", "SuoDomain", "NAME", "load", "default_eas", "mesh_units",
           "generate", "org_changes"]
