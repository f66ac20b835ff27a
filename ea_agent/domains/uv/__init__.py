"""Robot teams (paper section 7): UGV/UAV recipes, the nine UV alert types, two
audiences (robot controllers and the human operator) and autonomous policies."""
from __future__ import annotations

from pathlib import Path

from ea_agent.core.config import load_config
from ea_agent.core.manager import ExecutionAssistant, Sink

from .domain import ALERT_TYPES, CATEGORY, UvDomain
from .messages import UvAgent, UvSighting, UvState

NAME = "uv"
SOURCE_KINDS = (UvState, UvSighting, UvAgent)   # what the robots' own radios put on the live mesh
CONFIG_PATH = Path(__file__).resolve().parents[3] / "configs" / "uv.toml"


def load_uv_config(path=None, owner: str | None = None, overrides: dict | None = None) -> dict:
    """The effective parameters for one UV EA: `configs/uv.toml` is the defaults and the
    schema (as `configs/ea.toml` is for SUO); `path` may set any subset of its keys."""
    return load_config(path, owner, overrides, defaults=CONFIG_PATH)


def load(path, events: bool = True):
    """The UV scenario folder at `path` (scenario.json, world.geojson, plan.json, events)."""
    from .scenario import load as _load
    return _load(path, events=events)


def generate(out, seed: int = 7) -> dict:
    from .generator import write
    return write(Path(out), seed=seed)


def source_of(msg) -> str | None:
    """The unit whose own radio sends `msg` (a robot's state and sightings, an agent's
    messages): when that robot's EA peer dies, the replay stops sending them."""
    k = type(msg)
    if k is UvState or k is UvSighting:
        return msg.robot
    if k is UvAgent:
        return msg.sender
    return None


def make_ea(sc, owner: str, cfg: dict | None = None, sinks: list[Sink] | tuple = (), voa: bool = True,
            config_path=None) -> ExecutionAssistant:
    """A UV Execution Assistant for `owner` (TEAM or a robot) on a loaded scenario
    (`sc.taskorg`, `sc.plans`, `sc.initial_plan`, `sc.world`, `sc.projection`)."""
    cfg = cfg or load_uv_config(config_path, owner)
    dom = UvDomain(owner, sc.taskorg, sc.plans, sc.initial_plan, sc.world, sc.projection, cfg)
    return ExecutionAssistant(owner, dom, cfg, sinks, voa=voa)


def default_eas(sc) -> list[str]:
    """The scenario's default EAs, else the TEAM's and every robot's."""
    if sc.meta.get("default_eas"):
        return list(sc.meta["default_eas"])
    return mesh_units(sc)


def mesh_units(sc) -> list[str]:
    """Every unit has a peer: the TEAM (operator) and each robot."""
    to = sc.taskorg
    return [to.root] + sorted(u for u in to.units if u != to.root)


__all__ = ["make_ea", "load_uv_config", "ALERT_TYPES", "CATEGORY", "UvDomain", "NAME", "default_eas",
           "mesh_units", "CONFIG_PATH"]
