"""EA parameters from `configs/ea.toml`, with per-EA overrides in `[ea.<UNIT>]`.

`configs/ea.toml` is also the schema: another file, an `[ea.<UNIT>]` table and code
overrides may only set keys it has, each to a value of the same type (an int is
accepted where the default is a float; a bool is never a number), tables stay
tables. Numbers are finite and never negative, and the keys in `POSITIVE` (periods,
sizes, radii a zero would break) must be > 0. A bad value is a `ConfigError` naming
the file, the table and the key.
"""
from __future__ import annotations

import copy
import math
import tomllib
from pathlib import Path
from typing import Any

DEFAULT_PATH = Path(__file__).resolve().parents[2] / "configs" / "ea.toml"

# Dotted keys that must be > 0 (others only >= 0). Keys not in the defaults are ignored.
POSITIVE = frozenset({
    "manager.fact_batch", "manager.epoch_s", "manager.unknown_scan_s",
    "watchman.interest_m",
    "dissemination.radius_m", "dissemination.block_share", "dissemination.reregister_s",
    "mesh.max_payload_bytes", "mesh.reject_alert", "mesh.max_held_mb",
    "voi.out_of_position_m", "voi.schedule_repeat_s", "voi.unknown_position_s", "voi.weapons_range_m",
    "voi.threat_radius_m", "voi.coordination_radius_m", "voi.projection_trend_s",
    "voa.expiry_s", "notify.budget_window_s",
})
CHOICES = {"mesh.fsync": ("alert", "urgent", "never")}   # string keys with a closed set of values


class ConfigError(ValueError):
    pass


def _type_name(v: Any) -> str:
    return {bool: "a boolean", int: "an integer", float: "a number", str: "a string", list: "a list",
            dict: "a table"}.get(type(v), type(v).__name__)


def _value(v: Any, default: Any, dotted: str, where: str, name: str) -> Any:
    """`v` checked against the type of `default`; raises ConfigError naming the field."""
    bad = f"{where}: field '{name}'"
    if isinstance(default, bool):
        if not isinstance(v, bool):
            raise ConfigError(f"{bad}: expected true or false, got {_type_name(v)} ({v!r:.40})")
        return v
    if isinstance(default, (int, float)):
        if (isinstance(v, bool) or not isinstance(v, (int, float))
                or isinstance(default, int) and isinstance(v, float)):
            want = "an integer" if isinstance(default, int) else "a number"
            raise ConfigError(f"{bad}: expected {want}, got {_type_name(v)} ({v!r:.40})")
        if not math.isfinite(v):
            raise ConfigError(f"{bad}: not a finite number ({v})")
        if dotted in POSITIVE and v <= 0:
            raise ConfigError(f"{bad}: must be > 0 (got {v})")
        if v < 0:
            raise ConfigError(f"{bad}: must be >= 0 (got {v})")
        return float(v) if isinstance(default, float) else v
    if isinstance(default, list):
        if not isinstance(v, list):
            raise ConfigError(f"{bad}: expected a list, got {_type_name(v)} ({v!r:.40})")
        if default:
            return [_value(x, default[0], dotted, where, f"{name}[{i}]") for i, x in enumerate(v)]
        return list(v)
    if isinstance(default, str):
        if not isinstance(v, str):
            raise ConfigError(f"{bad}: expected a string, got {_type_name(v)} ({v!r:.40})")
        if dotted in CHOICES and v not in CHOICES[dotted]:
            raise ConfigError(f"{bad}: {v!r:.40} not one of {', '.join(CHOICES[dotted])}")
        return v
    return v


def check_setting(cfg: dict, key: str, value: Any, tables: tuple[str, ...] = ("voi", "voa")) -> Any:
    """`value` for the dotted `key` of `cfg` (one of `tables`), checked as the config file
    is: a change made at run time obeys the same rules. Raises ConfigError."""
    where = "set"
    parts = key.split(".") if isinstance(key, str) else []
    if len(parts) < 2 or parts[0] not in tables or parts[0] not in cfg:
        known = ", ".join(t for t in tables if t in cfg)
        raise ConfigError(f"{where}: field '{key!s:.80}': unknown key (only keys of [{known}] can be set)")
    node: Any = cfg
    for i, p in enumerate(parts):
        if not isinstance(node, dict) or p not in node:
            at = ".".join(parts[:i]) or parts[0]
            known = ", ".join(sorted(node)) if isinstance(node, dict) else ""
            raise ConfigError(f"{where}: field '{key:.80}': unknown key (known in [{at}]: {known})")
        node = node[p]
    if isinstance(node, dict):
        raise ConfigError(f"{where}: field '{key:.80}': is a table; set one of its keys")
    out = _value(value, node, key, where, key)
    if isinstance(node, list) and node and not out:
        raise ConfigError(f"{where}: field '{key:.80}': must not be empty")
    return out


def _merge(base: dict, over: Any, where: str, section: str = "", table: str | None = None) -> dict:
    """`base` with `over` applied, every value checked against the one it replaces.
    `section` is the dotted schema path (e.g. "voi"), `table` the TOML table named in
    messages (e.g. "ea.A2.voi"; default: `section`)."""
    table = section if table is None else table
    label = f"{where}: [{table}]" if table else where
    if not isinstance(over, dict):
        raise ConfigError(f"{label}: expected a table, got {_type_name(over)} ({over!r:.40})")
    out = copy.deepcopy(base)
    for k, v in over.items():
        if k not in out:
            raise ConfigError(f"{label}: field '{k}': unknown key (known: {', '.join(sorted(out))})")
        dotted = f"{section}.{k}" if section else k
        if isinstance(out[k], dict):
            if not isinstance(v, dict):
                raise ConfigError(f"{label}: field '{k}': expected a table, got {_type_name(v)} ({v!r:.40})")
            out[k] = _merge(out[k], v, where, dotted, f"{table}.{k}" if table else k)
        else:
            out[k] = _value(v, out[k], dotted, label, k)
    return out


def _read(p: Path) -> dict:
    try:
        return tomllib.loads(p.read_text())
    except OSError as e:
        raise ConfigError(f"{p}: cannot read: {e.strerror or e}") from None
    except UnicodeDecodeError as e:
        raise ConfigError(f"{p}: not UTF-8 text: {e.reason}") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{p}: invalid TOML: {e}") from None


def _defaults(schema: Path) -> tuple[dict, dict]:
    """The schema (a domain's defaults file without [ea]) and that file's own [ea] tables."""
    raw = _read(schema)
    per_ea = raw.pop("ea", {})
    _merge(raw, raw, str(schema))   # the defaults obey their own rules too
    return raw, per_ea


def load_config(path: str | Path | None = None, owner: str | None = None,
                overrides: dict[str, Any] | None = None, defaults: str | Path | None = None) -> dict:
    """The effective parameters for one EA: the domain's `defaults` file (configs/ea.toml
    for small-unit operations, configs/uv.toml for robot teams), then the file at `path`
    (any subset of the default keys), then its [ea.owner], then `overrides`. Every [ea.*]
    table of the file is checked, not only the owner's."""
    schema = Path(defaults).resolve() if defaults else DEFAULT_PATH
    cfg, per_ea = _defaults(schema)
    p = schema
    if path and Path(path).resolve() != schema:
        p = Path(path)
        raw = _read(p)
        per_ea = raw.pop("ea", {})
        cfg = _merge(cfg, raw, str(p))
    if not isinstance(per_ea, dict):
        raise ConfigError(f"{p}: field 'ea': expected tables [ea.<UNIT>], got {_type_name(per_ea)}")
    mine = None
    for unit, over in per_ea.items():
        merged = _merge(cfg, over, str(p), "", f"ea.{unit}")
        if unit == owner:
            mine = merged
    if mine is not None:
        cfg = mine
    if overrides:
        cfg = _merge(cfg, overrides, "overrides")
    _check_inhibit(cfg, str(p))
    return cfg


def _check_inhibit(cfg: dict, where: str) -> None:
    """[[inhibit]] rules are checked here, with the file's name, not at the first alert."""
    from .inhibit import Inhibitor
    try:
        Inhibitor(cfg.get("inhibit", []), float(cfg.get("voa", {}).get("expiry_s", 720.0)), f"{where}: [[inhibit]]")
    except ValueError as e:
        raise ConfigError(str(e)) from None
