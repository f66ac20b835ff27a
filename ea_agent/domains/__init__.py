"""The domains this build knows, by the name a scenario.json gives in `domain`.

A domain is one package under `ea_agent/domains/` exporting: NAME, ALERT_TYPES,
CATEGORY, `load(path, events=True)` (its scenario), `make_ea(sc, owner, cfg=None,
sinks=(), voa=True, config_path=None)`, `default_eas(sc)`, `mesh_units(sc)` and
`generate(out, seed=...)`; its domain object answers `needs()` for dissemination.
"""
from __future__ import annotations

import importlib
import json
from pathlib import Path
from types import ModuleType

DOMAINS = {"suo": "ea_agent.domains.suo", "uv": "ea_agent.domains.uv"}
DEFAULT = "suo"


def get(name: str) -> ModuleType:
    if name not in DOMAINS:
        raise KeyError(f"unknown domain {name!r} (known: {', '.join(sorted(DOMAINS))})")
    return importlib.import_module(DOMAINS[name])


def name_of(path: str | Path) -> str:
    """The domain a scenario folder is written for (scenario.json `domain`, default suo).
    A missing or broken scenario.json is left to the domain's loader to report."""
    try:
        meta = json.loads((Path(path) / "scenario.json").read_text())
    except (OSError, ValueError, RecursionError):
        return DEFAULT
    d = meta.get("domain", DEFAULT) if isinstance(meta, dict) else DEFAULT
    return d if isinstance(d, str) else DEFAULT


def of(sc) -> ModuleType:
    """The domain package of a loaded scenario."""
    return get(sc.meta.get("domain", DEFAULT) if isinstance(sc.meta, dict) else DEFAULT)
