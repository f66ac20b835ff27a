"""Builders of the small synthetic SUO scenarios the mission-model tests write to tmp_path:
control measures, missions, the task organization's scenario folder, location reports,
tracks and confirmations, and one EA fed on scenario time.

Geometry is written in local metres east/north of the generator's origin (UTM 11N); a
platoon's entities stand 20 m apart in a row east-west, centred on the given point."""
from __future__ import annotations

import json

from ea_agent.core.geo import Projection
from ea_agent.domains.suo.generator import ORIGIN_LONLAT
from ea_agent.domains.suo.messages import LocationReport, MissionConfirm, SensorTrack
from saim_mesh import scenario as S
from saim_mesh.inprocess.runner import config_for, make_ea

EPSG = 32611
PROJ = Projection(EPSG)
OX, OY = PROJ.to_xy(*ORIGIN_LONLAT)
EPOCH = 2.0        # configs/ea.toml manager.epoch_s: an alert found by a detector is dated at its epoch's end
REPORT_S = 10.0
EXPIRY_S = 720.0   # voa.expiry_s

# BN > A > (A1, A2), BN > B > B1: platoons hold their entities directly.
ORG = {"BN": ("battalion", None), "A": ("company", "BN"), "A1": ("platoon", "A"), "A2": ("platoon", "A"),
       "B": ("company", "BN"), "B1": ("platoon", "B")}
ENTITIES = {u: (f"{u}E1", f"{u}E2") for u, (kind, _) in ORG.items() if kind == "platoon"}


# ------------------------------------------------------------------------ the overlay and plan
def ll(x: float, y: float) -> list[float]:
    lon, lat = PROJ.to_lonlat(OX + x, OY + y)
    return [float(lon), float(lat)]


def box(fid: str, kind: str, x0: float, y0: float, x1: float, y1: float, **props) -> dict:
    ring = [ll(x0, y0), ll(x1, y0), ll(x1, y1), ll(x0, y1), ll(x0, y0)]
    return {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [ring]},
            "properties": {"id": fid, "kind": kind, **props}}


def line(fid: str, kind: str, *pts: tuple[float, float], **props) -> dict:
    return {"type": "Feature", "geometry": {"type": "LineString", "coordinates": [ll(x, y) for x, y in pts]},
            "properties": {"id": fid, "kind": kind, **props}}


def point(fid: str, x: float, y: float, kind: str = "checkpoint", **props) -> dict:
    return {"type": "Feature", "geometry": {"type": "Point", "coordinates": ll(x, y)},
            "properties": {"id": fid, "kind": kind, **props}}


def mission(mid: str, unit: str, typ: str, start: dict | None = None, end: dict | None = None,
            after: list[str] | None = None, **params) -> dict:
    m = {"id": mid, "unit": unit, "type": typ, "start": start or {"type": "ASAP"}, "params": params}
    if end is not None:
        m["end"] = end
    if after:
        m["after"] = after
    return m


def edited(missions: list[dict], mid: str, **params) -> list[dict]:
    """A copy of `missions` with mission `mid`'s params changed (None: removed)."""
    out = json.loads(json.dumps(missions))
    m = next(x for x in out if x["id"] == mid)
    for k, v in params.items():
        if v is None:
            m["params"].pop(k, None)
        else:
            m["params"][k] = v
    return out


# ------------------------------------------------------------------------ a force and its reports
class Force:
    """The task organization ORG with `entities` per platoon: the scenario folder it is
    written to, and the location reports that put a unit's centroid where a test wants it."""

    def __init__(self, entities: dict[str, tuple[str, ...]] = ENTITIES, name: str = "synthetic"):
        self.entities = entities
        self.name = name

    def write(self, d, features: list[dict], missions: list[dict], events: list[dict] = (),
              attrs: dict | None = None):
        """A scenario folder: the task organization, `features`, one plan `main`; `attrs`:
        extra fields per unit (boundary, weapons_range_m, ...)."""
        d.mkdir(parents=True, exist_ok=True)
        org = [{"id": u, "name": u, "echelon": kind, "parent": parent, "entities": list(self.entities.get(u, ())),
                **(attrs or {}).get(u, {})} for u, (kind, parent) in ORG.items()]
        (d / "scenario.json").write_text(json.dumps({"name": self.name, "epsg": EPSG, "duration_s": 3600.0}))
        (d / "overlay.geojson").write_text(json.dumps({"type": "FeatureCollection", "features": features}))
        (d / "plan.json").write_text(json.dumps({"task_organization": org, "plans": {"main": missions},
                                                 "initial_plan": "main"}))
        (d / "events.jsonl").write_text("".join(json.dumps(e) + "\n" for e in events))
        return d

    def scenario(self, tmp_path, features: list[dict], missions: list[dict], attrs: dict | None = None):
        return S.load(self.write(tmp_path / "sc", features, missions, attrs=attrs), events=False)

    def at(self, t: float, unit: str, x: float, y: float) -> list:
        """Location reports putting `unit`'s centroid at (x, y)."""
        es = self.entities[unit]
        n = len(es)
        return [LocationReport(float(t), e, *ll(x + 20.0 * (i - (n - 1) / 2), y)) for i, e in enumerate(es)]

    def path(self, unit: str, t0: float, t1: float, where) -> list:
        """`unit` reporting every REPORT_S from t0 to t1 at where(t)."""
        out, t = [], t0
        while t <= t1:
            out += self.at(t, unit, *where(t))
            t += REPORT_S
        return out

    def stays(self, unit: str, x: float, y: float, t0: float, t1: float) -> list:
        """`unit` reporting every REPORT_S from t0 to t1 from the same place."""
        return self.path(unit, t0, t1, lambda t: (x, y))

    def elsewhere(self, t0: float, t1: float, unit: str = "B1") -> list:
        """A platoon and a hostile moving 30 km away, reported every 2 s. Another company's
        platoon (B1) and the far hostile are heard by an in-process EA (the hostile closes
        epochs) and not by company A's peer; a platoon of A's own (A2) is heard by both, but
        its reports close epochs that A1's alerts must not depend on either."""
        return ([m for t in range(int(t0), int(t1), 2) for m in self.at(t, unit, -30000.0 + 5 * t, 0.0)]
                + track_path("H9", t0, t1, lambda t: (-30000.0 + 5 * t, 30000.0), every=2.0))


# ------------------------------------------------------------------------ tracks, confirmations
def track(t: float, k: str, x: float, y: float, strength: int = 4) -> SensorTrack:
    return SensorTrack(float(t), k, *ll(x, y), strength, at=float(t))


def track_path(k: str, t0: float, t1: float, where, every: float = REPORT_S, strength: int = 4) -> list:
    out, t = [], t0
    while t <= t1:
        out.append(track(t, k, *where(t), strength))
        t += every
    return out


def start(t: float, mid: str, unit: str) -> MissionConfirm:
    return MissionConfirm(float(t), mid, unit, "start")


def end(t: float, mid: str, unit: str) -> MissionConfirm:
    return MissionConfirm(float(t), mid, unit, "end")


# ------------------------------------------------------------------------ one EA on scenario time
def feed(sc, msgs: list, until: float, owner: str = "A", ea=None, since: float = -1.0, cfg: dict | None = None):
    """`owner`'s EA (new, configured by `cfg` or the defaults; or `ea` going on) fed the
    messages dated in (since, until] in time order (stable: a confirmation after the
    reports of its instant), and advanced to `until` (not finished: more may follow)."""
    if ea is None:
        ea = make_ea(sc, owner, cfg if cfg is not None else config_for(sc, owner))
        ea.start(0.0)
    for m in sorted((m for m in msgs if since < m.t <= until), key=lambda m: m.t):
        ea.submit(m)
    ea.advance(until)
    return ea


def play(sc, msgs: list, until: float, owner: str = "A", cfg: dict | None = None):
    """As feed, from the start, and run to `until` on scenario time."""
    ea = feed(sc, msgs, until, owner, cfg=cfg)
    ea.finish(until)
    return ea


def alerts_of(ea, typ: str, mission: str | None = None) -> list:
    """Alerts of `typ`, of `mission` when given."""
    return [a for a in ea.alerts if a.type == typ
            and (mission is None or a.details.get("mission") == mission)]


def told(alerts) -> list[dict]:
    """What alerts say, without their ids and story ids (numbered over every alert the EA gave)."""
    out = []
    for a in alerts:
        d = a.to_json_dict()
        d["details"] = {k: v for k, v in d["details"].items() if k not in ("id", "story")}
        out.append(d)
    return out


def near(t: float, want: float, tol: float = 2 * EPOCH) -> bool:
    """At `want`, or within `tol` after it (by the end of the epoch after it, by default)."""
    return want <= t <= want + tol


def along(legs: list[tuple[float, float, float, float]], s: float) -> tuple[float, float]:
    """The point `s` metres along axis-parallel legs (x0, y0, x1, y1), or the last leg's end."""
    for x0, y0, x1, y1 in legs:
        n = abs(x1 - x0) + abs(y1 - y0)
        if s <= n:
            f = s / n
            return x0 + (x1 - x0) * f, y0 + (y1 - y0) * f
        s -= n
    return legs[-1][2], legs[-1][3]
