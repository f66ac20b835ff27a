"""Loading a scenario for the application: scenario.json names its domain
(`"domain": "uv"`, default small-unit operations); that domain's loader reads
and checks the rest."""
from __future__ import annotations

from pathlib import Path

from ea_agent import domains
from ea_agent.core.scenario import ScenarioBase, ScenarioError, check_key_chunk  # noqa: F401


def load(path: str | Path, events: bool = True):
    name = domains.name_of(path)
    try:
        dom = domains.get(name)
    except KeyError as e:
        raise ScenarioError(f"{Path(path) / 'scenario.json'}: field 'domain': {e.args[0]}") from None
    return dom.load(path, events=events)


# What the application reads of any domain's loaded scenario: every domain's scenario is one.
Scenario = ScenarioBase


def mesh_units(sc) -> list[str]:
    """The units of a scenario that run an EA peer on a mesh (its domain says which)."""
    return domains.of(sc).mesh_units(sc)
