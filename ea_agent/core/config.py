"""EA parameters from `configs/ea.toml`, with per-EA overrides in `[ea.<UNIT>]`."""
from __future__ import annotations

import copy
import tomllib
from pathlib import Path
from typing import Any

DEFAULT_PATH = Path(__file__).resolve().parents[2] / "configs" / "ea.toml"


class ConfigError(ValueError):
    pass


def _merge(base: dict, over: dict, where: str) -> dict:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if k not in out:
            raise ConfigError(f"{where}: unknown key '{k}'")
        if isinstance(out[k], dict):
            if not isinstance(v, dict):
                raise ConfigError(f"{where}.{k}: expected a table")
            out[k] = _merge(out[k], v, f"{where}.{k}")
        else:
            out[k] = v
    return out


def load_config(path: str | Path | None = None, owner: str | None = None,
                overrides: dict[str, Any] | None = None) -> dict:
    """The effective parameters for one EA: file defaults, then [ea.owner], then `overrides`."""
    p = Path(path) if path else DEFAULT_PATH
    try:
        raw = tomllib.loads(p.read_text())
    except (OSError, tomllib.TOMLDecodeError) as e:
        raise ConfigError(f"{p}: {e}") from None
    per_ea = raw.pop("ea", {})
    cfg = raw
    if owner and owner in per_ea:
        cfg = _merge(cfg, per_ea[owner], f"{p}: [ea.{owner}]")
    if overrides:
        cfg = _merge(cfg, overrides, "overrides")
    return cfg
