"""What every domain's scenario loader shares: one error type naming the file and
field at fault, field checks, ids that are safe key chunks, and the time-ordered,
validated event script (events.jsonl or events.jsonl.gz)."""
from __future__ import annotations

import gzip
import json
import math
import re
import warnings
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np
import shapely
from shapely.geometry import shape

from . import messages
from .geo import Projection
from .plan import END_TYPES, START_TYPES, MissionSpec, PlanSpec, TaskOrg, TimeConstraint

_NOT_IN_CHUNK = re.compile(r"[/*#?$\s]")
MAX_DURATION_S = 7 * 86400.0   # a week of scenario time: far more than an operation, bounded so nothing spins


class ScenarioError(ValueError):
    pass


def need(d: dict, key: str, where: str, types: type | tuple = object):
    if not isinstance(d, dict):
        raise ScenarioError(f"{where}: expected an object")
    if key not in d:
        raise ScenarioError(f"{where}: field '{key}': missing")
    v = d[key]
    if not isinstance(v, types) or isinstance(v, bool) and types is not bool:
        raise ScenarioError(f"{where}: field '{key}': expected {getattr(types, '__name__', types)}, got {type(v).__name__}")
    return v


def check_key_chunk(value: Any, where: str, name: str) -> str:
    """An id that becomes one Zenoh key chunk (unit, entity, mission, track, cff, sensor,
    plan, fusion group): a non-empty string without '/', '*', '#', '?', '$' or whitespace.
    Anything else would be published on keys nobody subscribes to (or be no key at all)."""
    if not isinstance(value, str) or not value:
        raise ScenarioError(f"{where}: field '{name}': expected a non-empty id string, got {value!r:.60}")
    bad = _NOT_IN_CHUNK.search(value)
    if bad:
        raise ScenarioError(f"{where}: field '{name}': id {value!r:.60} contains {bad.group()!r}; ids are Zenoh key "
                            f"chunks and may not contain '/', '*', '#', '?', '$' or whitespace")
    return value


def scenario_head(meta: dict, root: Path, where: str = "scenario.json") -> tuple[str, Projection, float]:
    """scenario.json's name (a key chunk; the folder's name when absent), its projection
    (`epsg`) and its duration (`duration_s`, positive, at most MAX_DURATION_S)."""
    name = meta.get("name", root.resolve().name)
    check_key_chunk(name, where if "name" in meta else f"{where} (no name: the folder name is used)", "name")
    epsg = need(meta, "epsg", where, int)
    try:
        proj = Projection(epsg)
    except Exception as e:   # pyproj raises its own CRSError (and ValueError for a geographic CRS)
        raise ScenarioError(f"{where}: field 'epsg': {e}") from None
    duration = number(need(meta, "duration_s", where, (int, float)), where, "duration_s", positive=True)
    if duration > MAX_DURATION_S:
        raise ScenarioError(f"{where}: field 'duration_s': {duration} is more than {MAX_DURATION_S:.0f} s (7 days)")
    return name, proj, duration


def new_id(d: dict, where: str, seen: set[str], what: str) -> tuple[str, str]:
    """An entry's `id` (a key chunk) not given before in its list (`seen`, which it joins),
    and `where` naming the entry by it."""
    ident = check_key_chunk(need(d, "id", where, str), where, "id")
    where += f" ({ident})"
    if ident in seen:
        raise ScenarioError(f"{where}: field 'id': duplicate {what} id")
    seen.add(ident)
    return ident, where


def check_default_eas(meta: dict, units: set[str] | dict) -> None:
    """scenario.json's `default_eas`, when given: a non-empty list of the plan's units."""
    dflt = meta.get("default_eas")
    if dflt is None:
        return
    if not isinstance(dflt, list) or not dflt:
        raise ScenarioError("scenario.json: field 'default_eas': expected a non-empty list of unit ids")
    for u in dflt:
        if not isinstance(u, str):
            raise ScenarioError(f"scenario.json: field 'default_eas': expected a unit id, got {type(u).__name__}")
        if u not in units:
            raise ScenarioError(f"scenario.json: field 'default_eas': unknown unit {u!r:.40}")


def guarded(fname: str, fn: Callable, *args):
    """Run one file's loader; an error its checks did not foresee still names the file, in one line."""
    from .config import ConfigError   # (a plan's VOI overrides are checked against the domain's config)
    try:
        return fn(*args)
    except (ScenarioError, ConfigError):
        raise
    except (TypeError, ValueError, AttributeError, KeyError, IndexError) as e:
        raise ScenarioError(f"{fname}: unexpected {type(e).__name__} while loading: {e}") from e


def number(v: Any, where: str, name: str, positive: bool = False) -> float:
    """A finite number >= 0 (> 0 if `positive`), never a bool."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise ScenarioError(f"{where}: field '{name}': expected a number, got {type(v).__name__}")
    if not math.isfinite(v):
        raise ScenarioError(f"{where}: field '{name}': not a finite number ({v})")
    if v < 0 or positive and v == 0:
        raise ScenarioError(f"{where}: field '{name}': must be {'> 0' if positive else '>= 0'} (got {v})")
    return float(v)


def time_constraint(d: Any, where: str, allowed: tuple[str, ...]) -> TimeConstraint:
    """A mission's start or end constraint (`{"type": ..., "t": ...}`; None: unconstrained),
    read the same way by every domain."""
    if d is None:
        return TimeConstraint()
    typ = need(d, "type", where, str)
    if typ not in allowed:
        raise ScenarioError(f"{where}: field 'type': {typ!r} not one of {', '.join(allowed)}")
    if typ in ("ASAP", "ON-ORDER"):
        return TimeConstraint(typ)
    return TimeConstraint(typ, number(need(d, "t", where, (int, float)), where, "t"))


def read_json(p: Path) -> Any:
    try:
        return json.loads(p.read_text())
    except FileNotFoundError:
        raise ScenarioError(f"{p}: file missing") from None
    except OSError as e:
        raise ScenarioError(f"{p}: cannot read: {e.strerror or e}") from None
    except UnicodeDecodeError as e:
        raise ScenarioError(f"{p}: not UTF-8 text: {e.reason}") from None
    except json.JSONDecodeError as e:
        raise ScenarioError(f"{p}:{e.lineno}: invalid JSON: {e.msg}") from None
    except RecursionError:
        raise ScenarioError(f"{p}: invalid JSON: nested too deeply") from None


def open_events(root: Path):
    for name in ("events.jsonl", "events.jsonl.gz"):
        p = root / name
        if p.exists():
            try:
                return p, (gzip.open(p, "rt", encoding="utf-8") if name.endswith(".gz") else p.open(encoding="utf-8"))
            except OSError as e:
                raise ScenarioError(f"{p}: cannot read: {e.strerror or e}") from None
    raise ScenarioError(f"{root}: no events.jsonl or events.jsonl.gz")


def read_events(root: Path, check: Callable[[Any, str], None] | None = None) -> list:
    """The event script, decoded with the shared codec and time-ordered; `check(msg,
    where)` adds the domain's scenario-level checks (known units, times in range)."""
    p, fh = open_events(root)
    out = []
    last_t = 0.0
    lineno = 0
    try:
        with fh:
            for lineno, line in enumerate(fh, 1):
                if not line.strip():
                    continue
                try:
                    d = json.loads(line)
                except (json.JSONDecodeError, RecursionError) as e:
                    why = getattr(e, "msg", "nested too deeply")
                    raise ScenarioError(f"{p.name}:{lineno}: invalid JSON: {why}") from None
                try:
                    m = messages.from_dict(d)
                except messages.MessageError as e:
                    raise ScenarioError(f"{p.name}:{lineno}: {e}") from None
                if m.t < last_t:
                    raise ScenarioError(f"{p.name}:{lineno}: field 't': {m.t} is earlier than the line before ({last_t}); events must be time-ordered")
                last_t = m.t
                if check is not None:
                    check(m, f"{p.name}:{lineno}: {m.KIND} message")
                out.append(m)
    except (EOFError, zlib.error, gzip.BadGzipFile) as e:
        after = f" after line {lineno}" if lineno else ""
        raise ScenarioError(f"{p.name}:{lineno + 1}: truncated or corrupt gzip{after} ({e})") from None
    except UnicodeDecodeError as e:
        raise ScenarioError(f"{p.name}:{lineno + 1}: not UTF-8 text ({e.reason})") from None
    except OSError as e:
        raise ScenarioError(f"{p.name}:{lineno + 1}: cannot read: {e.strerror or e}") from None
    return out


def lonlat_geometry(g: dict, where: str):
    """A GeoJSON geometry in WGS84 lon/lat as a shapely geometry, every point checked
    (NaN, out-of-range longitudes and latitudes are named, never projected)."""
    try:
        with warnings.catch_warnings():   # NaN coordinates warn on stderr; they are reported below
            warnings.simplefilter("ignore", RuntimeWarning)
            geom = shape(g)
    except Exception as e:   # shapely raises several unrelated types for malformed GeoJSON
        raise ScenarioError(f"{where}: field 'geometry': {type(e).__name__}: {e}") from None
    coords = shapely.get_coordinates(geom)
    if len(coords) == 0:
        raise ScenarioError(f"{where}: field 'geometry': no coordinates")
    bad = ~np.isfinite(coords).all(axis=1) | (np.abs(coords[:, 0]) > 180) | (np.abs(coords[:, 1]) > 90)
    if bad.any():
        lon, lat = coords[np.argmax(bad)]
        what = (f"lat {lat} is not a WGS84 latitude in [-90, 90]" if math.isfinite(lon) and abs(lon) <= 180
                else f"lon {lon} is not a WGS84 longitude in [-180, 180]")
        raise ScenarioError(f"{where}: field 'geometry': point ({lon}, {lat}): {what}")
    return geom


def place_feature(f: Any, where: str, kinds: tuple[str, ...] | list[str], seen: dict | set,
                  geom_types: Callable[[str], set[str]], proj: Projection,
                  key_id: bool = True) -> tuple[str, str, str, dict, Any]:
    """One GeoJSON feature of a scenario's places (SUO's overlay, UV's world), checked:
    (where naming it, its id, kind, properties, projected geometry). `geom_types(kind)` says
    which geometries a kind may have; the id is a key chunk when `key_id`, else non-empty."""
    props = need(f, "properties", where, dict)
    fid = need(props, "id", where, str)
    if key_id:
        check_key_chunk(fid, where, "id")
    elif not fid:
        raise ScenarioError(f"{where}: field 'id': empty")
    where = f"{where} ({fid})"
    kind = need(props, "kind", where, str)
    if kind not in kinds:
        raise ScenarioError(f"{where}: field 'kind': unknown kind {kind!r} (one of {', '.join(kinds)})")
    if fid in seen:
        raise ScenarioError(f"{where}: field 'id': duplicate id {fid!r}")
    geom = lonlat_geometry(need(f, "geometry", where, dict), where)
    want = geom_types(kind)
    if geom.geom_type not in want:
        raise ScenarioError(f"{where}: field 'geometry': a {kind} must be {' or '.join(sorted(want))}, "
                            f"not {geom.geom_type}")
    if not shapely.is_valid(geom):
        raise ScenarioError(f"{where}: field 'geometry': invalid {geom.geom_type} ({shapely.is_valid_reason(geom)})")
    xy = shapely.transform(geom, lambda c: proj.to_xy_array(c))
    if not np.isfinite(shapely.get_coordinates(xy)).all():
        raise ScenarioError(f"{where}: field 'geometry': cannot be projected to EPSG:{proj.epsg} "
                            f"(too far from the scenario's area)")
    return where, fid, kind, props, xy


def unit_entry(u: Any, where: str, seen: set[str], field: str, kinds: tuple[str, ...] | list[str]
               ) -> tuple[str, str, str, str | None]:
    """A task-organization entry's head: its id (new in `seen`), `where` naming it, its
    `field` (SUO's echelon, UV's kind) among `kinds`, and its parent (a unit id or None)."""
    uid, where = new_id(u, where, seen, "unit")
    kind = need(u, field, where, str)
    if kind not in kinds:
        raise ScenarioError(f"{where}: field '{field}': {kind!r} not one of {', '.join(kinds)}")
    parent = u.get("parent")
    if parent is not None and not isinstance(parent, str):
        raise ScenarioError(f"{where}: field 'parent': expected a unit id or null, got {type(parent).__name__}")
    return uid, where, kind, parent


def checked_taskorg(units: list, where: str) -> TaskOrg:
    """The task organization of `units` (core.plan.Unit): one top unit, every parent a unit,
    no cycle."""
    roots = [u.id for u in units if u.parent is None]
    if len(roots) != 1:
        raise ScenarioError(f"{where}: field 'parent': need exactly one top unit, found {roots}")
    ids = {u.id for u in units}
    for u in units:
        if u.parent is not None and u.parent not in ids:
            raise ScenarioError(f"{where} ({u.id}): field 'parent': unknown unit {u.parent!r}")
    taskorg = TaskOrg(units)
    cyc = taskorg.cycle()
    if cyc:
        raise ScenarioError(f"{where} ({cyc[0]}): field 'parent': cycle in the command "
                            f"hierarchy: {' -> '.join(cyc)} (every unit must lead up to {roots[0]})")
    return taskorg


def load_plans(doc: dict, fname: str, units: set[str] | dict, registry: dict, types_hint: str,
               check_mission: Callable[[type, dict, str, str], None]) -> tuple[dict[str, PlanSpec], str]:
    """plan.json's `plans` (each a list of missions, in order of `after`) and its
    `initial_plan`. `check_mission(cls, params, where, unit)` is the domain's own check of
    one mission; `types_hint` follows an unknown mission type's name in its error line."""
    plans: dict[str, PlanSpec] = {}
    for pname, ms in need(doc, "plans", fname, dict).items():
        check_key_chunk(pname, f"{fname}: plans", "name")
        if not isinstance(ms, list):
            raise ScenarioError(f"{fname}: plans.{pname}: expected a list of missions")
        specs: list[MissionSpec] = []
        mids: set[str] = set()
        for i, m in enumerate(ms):
            mid, where = new_id(m, f"{fname}: plans.{pname}[{i}]", mids, "mission")
            unit = need(m, "unit", where, str)
            if unit not in units:
                raise ScenarioError(f"{where}: field 'unit': unknown unit {unit!r}")
            typ = need(m, "type", where, str)
            cls = registry.get(typ)
            if cls is None:
                raise ScenarioError(f"{where}: field 'type': unknown mission type {typ!r} ({types_hint})")
            params = m.get("params", {})
            check_mission(cls, params, where, unit)
            after = m.get("after", [])
            if not isinstance(after, list) or not all(isinstance(a, str) for a in after):
                raise ScenarioError(f"{where}: field 'after': expected a list of mission ids")
            if mid in after:
                raise ScenarioError(f"{where}: field 'after': a mission cannot come after itself")
            specs.append(MissionSpec(mid, unit, typ, time_constraint(m.get("start"), where + " start", START_TYPES),
                                     time_constraint(m.get("end"), where + " end", END_TYPES), tuple(after), params))
        for sp in specs:
            for a in sp.after:
                if a not in mids:
                    raise ScenarioError(f"{fname}: plans.{pname} ({sp.id}): field 'after': unknown mission {a!r}")
        plan = PlanSpec(pname, specs)
        cyc = plan.cycle()
        if cyc:
            raise ScenarioError(f"{fname}: plans.{pname} ({cyc[0]}): field 'after': cycle "
                                f"{' -> '.join(reversed(cyc))} (each waits for the one before it, so none "
                                f"would ever become ready)")
        plans[pname] = plan
    initial = doc.get("initial_plan", "main")
    if not isinstance(initial, str) or initial not in plans:
        raise ScenarioError(f"{fname}: field 'initial_plan': no plan named {initial!r}")
    return plans, initial


@dataclass
class ScenarioBase:
    """What every domain's loaded scenario has; a domain adds its places (SUO's
    overlay, UV's world)."""
    name: str
    root: Path
    projection: Projection
    duration_s: float
    taskorg: TaskOrg
    plans: dict[str, PlanSpec]
    initial_plan: str
    events: list
    meta: dict

    @property
    def plan(self) -> PlanSpec:
        return self.plans[self.initial_plan]

    def truth(self) -> dict:
        """The ground truth the generator's oracle wrote (truth.json)."""
        p = self.root / "truth.json"
        if not p.exists():
            raise ScenarioError(f"{p}: no ground-truth file in this scenario")
        return json.loads(p.read_text())
