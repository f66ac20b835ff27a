"""What a TAK user sees of the mesh: the latest friendly positions (per unit, optionally
per entity), fused hostile tracks, alerts and the scenario's overlay, turned into CoT.

Mesh-independent (decoded messages in, XML bytes out), so the same core serves the
gateway peer, the tests and the benchmark. Positions go out every `period_s` of scenario
time when they changed, and at least every `refresh_s` (a TAK client that joins late
gets everything within that); alerts go out at once.

What a TAK user sees (docs/tak.md):
- units: `a-f-G-U-C` at the centroid of their entities' latest reports, callsign = the
  unit's name in the task organization; echelon in the 2525B SIDC of `__saim`;
- entities (option): `a-f-G-U-C-I` at their last report, callsign = entity id;
- tracks: `a-h-G-U-C`, callsign `HOSTILE <track> (<strength>)`, course and speed;
- alerts: flash -> an emergency (`b-a-o-opn` Troops In Contact for adversarial activity,
  else `b-a-o-tbl` 911 Alert); an alert about a control measure -> `b-a-g` geofence
  breached, linked to the shape; others -> a spot marker `b-m-p-s-m` coloured by
  priority. Remarks carry priority, owner, time and message; `__saim` carries every field;
  an emergency whose alert its EA took an acknowledgement for is cancelled (`b-a-o-can`);
- overlay: areas as closed `u-d-f` polygons, lines as open `u-d-f` polylines, points
  with a radius as `u-d-c-c` circles, coloured by kind."""
from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from collections import OrderedDict
from dataclasses import dataclass, field
from datetime import datetime, timedelta, timezone

from ea_agent.core.alert import hms

from ..console.overlay import overlay_geojson
from . import cot as C
from . import types as T

TRACK_TTL_S = 600.0     # a track not reported for this long is no longer sent (as the console)
MAX_EMERGENCIES = 10_000   # alerts whose emergencies an acknowledgement can still cancel (the newest)


@dataclass
class Options:
    """How the picture is sent; times in seconds (period and refresh: scenario time)."""
    period_s: float = 10.0
    refresh_s: float = 60.0
    entities: bool = False
    pos_stale_s: float = 300.0
    alert_stale_s: float = 1800.0
    overlay_stale_s: float | None = None     # default: the scenario's duration plus an hour
    uid_prefix: str | None = None            # default: saim.<scenario name>
    epoch: datetime = field(default_factory=lambda: datetime.now(timezone.utc))


def _centroid(coords) -> tuple[float, float]:
    pts = coords[:-1] if len(coords) > 1 and coords[0] == coords[-1] else coords
    return sum(p[0] for p in pts) / len(pts), sum(p[1] for p in pts) / len(pts)


class Picture:
    def __init__(self, sc, opts: Options | None = None):
        self.sc, self.o = sc, opts or Options()
        self.prefix = self.o.uid_prefix or f"saim.{sc.name}"
        self.taskorg = sc.taskorg.copy()
        self.t = 0.0
        self.ended = False
        self.entity_pos: dict[str, tuple[float, float, float]] = {}       # entity -> lon, lat, t
        self.tracks: dict[str, tuple] = {}                                # track -> lon, lat, strength, t, hdg, spd
        self.sent: dict[str, tuple[float, float, float]] = {}             # uid -> lon, lat, t sent
        self.counts: dict[str, int] = {}
        self._next = 0.0
        self._n_alert = 0
        self._units: dict | None = None        # unit centroids, until the next position or reorganization
        self.emergencies: OrderedDict[str, list[tuple]] = OrderedDict()   # alert id -> its emergencies on TAK
        self.urgent: OrderedDict[str, object] = OrderedDict()   # alert id -> the urgent alert (re-notifications)
        self.alert_uids: OrderedDict[str, str] = OrderedDict()  # CoT uid -> alert id (what TAK users acknowledge)
        self.overlay = {f["id"]: f for f in overlay_geojson(sc)["features"]}
        self.places = {}
        for fid, f in self.overlay.items():
            g = f["geometry"]
            c = g["coordinates"]
            self.places[fid] = (tuple(c) if g["type"] == "Point" else _centroid(c[0] if g["type"] == "Polygon" else c))
        self.centre = (_centroid(list(self.places.values())) if self.places else (0.0, 0.0))

    # -- helpers ---------------------------------------------------------------------
    def when(self, t: float) -> datetime:
        return self.o.epoch + timedelta(seconds=float(t))

    def uid(self, kind: str, ident: str) -> str:
        return f"{self.prefix}.{kind}.{ident}"

    def _count(self, kind: str, n: int = 1) -> None:
        self.counts[kind] = self.counts.get(kind, 0) + n

    # -- inputs ----------------------------------------------------------------------
    def clock(self, t: float, end: bool = False) -> None:
        self.t = max(self.t, float(t))
        self.ended = self.ended or end

    def message(self, m) -> None:
        """A decoded data message: positions, tracks, reorganizations (others ignored)."""
        k = m.KIND
        if k in ("location", "uv-state", "reorg"):
            self._units = None
        if k == "location":
            self.entity_pos[m.entity] = (m.lon, m.lat, m.t)
        elif k == "uv-state":
            self.entity_pos[m.robot] = (m.lon, m.lat, m.t)
        elif k == "track":
            self.tracks[m.track] = (m.lon, m.lat, m.strength, m.t, m.heading, m.speed)
        elif k == "uv-sighting":
            self.tracks[m.target] = (m.lon, m.lat, 1, m.t, None, None)
        elif k == "reorg":
            try:
                self.taskorg.resubordinate(m.unit, m.new_parent)
            except (KeyError, ValueError):
                pass

    # -- positions -------------------------------------------------------------------
    def unit_positions(self) -> dict[str, tuple[float, float, int]]:
        """Each unit's centroid over its subtree's entities (as the console computes it)."""
        if self._units is not None:
            return self._units
        self._units = self.taskorg.centroids(self.entity_pos)
        return self._units

    def _changed(self, uid: str, lon: float, lat: float, t: float) -> bool:
        last = self.sent.get(uid)
        return (last is None or abs(last[0] - lon) > 1e-6 or abs(last[1] - lat) > 1e-6
                or t - last[2] >= self.o.refresh_s)

    def unit_event(self, u: str, lon: float, lat: float, n: int, t: float) -> bytes:
        unit = self.taskorg.units[u]
        parent = self.taskorg.parent.get(u)
        tm = self.when(t)
        sidc = T.sidc(T.FRIENDLY_UNIT, unit.kind)
        saim = ET.Element("__saim", {"kind": "unit", "unit": u, "echelon": unit.kind, "parent": parent or "",
                                     "sidc": sidc, "entities": str(n), "t": f"{t:.3f}"})
        return C.event(self.uid("unit", u), T.FRIENDLY_UNIT, lon, lat, tm, tm + timedelta(seconds=self.o.pos_stale_s),
                       how=T.HOW_FUSED, callsign=unit.name, detail=[saim],
                       remarks=f"{unit.kind} {u}{f' ({self.taskorg.name(parent)})' if parent else ''}: "
                               f"centroid of {n} entities at {hms(t)}")

    def entity_event(self, e: str, lon: float, lat: float, t: float) -> bytes:
        u = self.taskorg.entity_unit.get(e)
        tm = self.when(t)
        saim = ET.Element("__saim", {"kind": "entity", "entity": e, "unit": u or "",
                                     "sidc": T.sidc(T.FRIENDLY_ENTITY), "t": f"{t:.3f}"})
        return C.event(self.uid("ent", e), T.FRIENDLY_ENTITY, lon, lat, tm, tm + timedelta(seconds=self.o.pos_stale_s),
                       how=T.HOW_GPS, callsign=e, detail=[saim],
                       remarks=f"{e} of {self.taskorg.name(u) if u else '?'}: reported at {hms(t)}")

    def track_event(self, k: str, lon: float, lat: float, strength: int, t: float, hdg=None, spd=None) -> bytes:
        tm = self.when(t)
        det = [ET.Element("__saim", {"kind": "track", "track": k, "strength": str(strength),
                                     "sidc": T.sidc(T.HOSTILE_TRACK), "t": f"{t:.3f}"})]
        if hdg is not None or spd is not None:
            det.append(ET.Element("track", {"course": f"{hdg or 0.0:.1f}", "speed": f"{spd or 0.0:.2f}"}))
        return C.event(self.uid("trk", k), T.HOSTILE_TRACK, lon, lat, tm, tm + timedelta(seconds=self.o.pos_stale_s),
                       how=T.HOW_FUSED, callsign=f"HOSTILE {k} ({strength})", detail=det,
                       remarks=f"fused hostile track {k}: {strength} entities at {hms(t)}")

    def due(self, t: float | None = None, force: bool = False) -> list[bytes]:
        """Position events due at scenario time `t` (default: the clock): every
        `period_s`, those that moved or were not sent for `refresh_s`."""
        t = self.t if t is None else float(t)
        if not force and t < self._next:
            return []
        self._next = t + self.o.period_s
        out: list[bytes] = []
        for u, (lon, lat, n) in sorted(self.unit_positions().items()):
            uid = self.uid("unit", u)
            if force or self._changed(uid, lon, lat, t):
                out.append(self.unit_event(u, lon, lat, n, t))
                self.sent[uid] = (lon, lat, t)
                self._count("unit")
        if self.o.entities:
            for e, (lon, lat, te) in sorted(self.entity_pos.items()):
                uid = self.uid("ent", e)
                if force or self._changed(uid, lon, lat, t):
                    out.append(self.entity_event(e, lon, lat, min(te, t)))
                    self.sent[uid] = (lon, lat, t)
                    self._count("entity")
        old = t - TRACK_TTL_S
        for k in [k for k, v in self.tracks.items() if v[3] < old]:
            del self.tracks[k]
        for k, (lon, lat, s, tt, hdg, spd) in sorted(self.tracks.items()):
            uid = self.uid("trk", k)
            if force or self._changed(uid, lon, lat, t):
                out.append(self.track_event(k, lon, lat, s, min(tt, t), hdg, spd))
                self.sent[uid] = (lon, lat, t)
                self._count("track")
        return out

    # -- alerts ----------------------------------------------------------------------
    def where(self, a) -> tuple[float, float]:
        """Where an alert is shown: its first subject with a known position (unit, entity,
        track), else a control measure it names, else its owner, else the overlay's centre."""
        units = None
        for s in a.subjects:
            if s in self.tracks:
                return self.tracks[s][0], self.tracks[s][1]
            if s in self.entity_pos:
                return self.entity_pos[s][0], self.entity_pos[s][1]
            if s in self.taskorg.units:
                units = units if units is not None else self.unit_positions()
                if s in units:
                    return units[s][0], units[s][1]
        d = a.details
        for k in ("control_measure", "area", "place", "point"):
            if isinstance(d.get(k), str) and d[k] in self.places:
                return self.places[d[k]]
        for p in d.get("places", []) if isinstance(d.get("places"), list) else []:
            if isinstance(p, str) and p in self.places:
                return self.places[p]
        units = units if units is not None else self.unit_positions()
        if a.owner in units:
            return units[a.owner][0], units[a.owner][1]
        return self.centre

    def alert_type(self, a) -> tuple[str, str | None]:
        """(CoT type, the overlay uid it is about for a geofence alert)."""
        if a.priority == "flash":
            return (T.CONTACT if a.category == "adversarial-activity" else T.EMERGENCY), None
        cm = a.details.get("control_measure") or a.details.get("area")
        if isinstance(cm, str) and cm in self.overlay:
            return T.GEOFENCE, self.uid("ovl", cm)
        return T.MARKER, None

    def alert_event(self, a) -> bytes:
        """One alert as CoT, at once (docstring of this module: which type)."""
        aid = a.details.get("id")
        self._n_alert += 1
        ident = (aid if isinstance(aid, str) and aid else f"{a.owner}/x{self._n_alert}").replace("/", "-")
        typ, fence = self.alert_type(a)
        lon, lat = self.where(a)
        if isinstance(aid, str) and aid:
            self.alert_uids[self.uid("alert", ident)] = aid
            self.alert_uids.move_to_end(self.uid("alert", ident))
            if len(self.alert_uids) > MAX_EMERGENCIES:
                self.alert_uids.popitem(last=False)
        tm = self.when(a.t)
        subj = " ".join(a.subjects[:6]) + (" ..." if len(a.subjects) > 6 else "")
        callsign = f"{a.priority.upper()} {a.type} {subj}".strip()[:80]
        det = [ET.Element("__saim", {"kind": "alert", "id": str(aid or ""), "owner": a.owner, "type": a.type,
                                     "category": a.category, "priority": a.priority,
                                     "subjects": json.dumps(list(a.subjects)), "t": f"{a.t:.3f}"})]
        if typ in T.EMERGENCY_NAMES:
            if isinstance(aid, str) and aid:   # one entry per uid: a re-notification re-sends the same uid
                entry = (self.uid("alert", ident), lon, lat, callsign)
                ems = self.emergencies.setdefault(aid, [])
                if all(e[0] != entry[0] for e in ems):
                    ems.append(entry)
                self.emergencies.move_to_end(aid)
                if len(self.emergencies) > MAX_EMERGENCIES:
                    self.emergencies.popitem(last=False)
            em = ET.Element("emergency", {"type": T.EMERGENCY_NAMES[typ]})
            em.text = callsign
            det.append(em)
            first = next((s for s in a.subjects if s in self.taskorg.units), a.owner)
            det.append(ET.Element("link", {"uid": self.uid("unit", first), "type": T.FRIENDLY_UNIT,
                                           "relation": "p-p"}))
        elif typ == T.GEOFENCE:
            det.append(ET.Element("link", {"uid": fence, "type": T.SHAPE, "relation": "p-p"}))
        else:
            det.append(ET.Element("color", {"argb": str(T.COLOURS[T.PRIORITY_COLOUR[a.priority]])}))
        self._count("alert")
        return C.event(self.uid("alert", ident), typ, lon, lat, tm, tm + timedelta(seconds=self.o.alert_stale_s),
                       how=T.HOW_FUSED, callsign=callsign, detail=det,
                       remarks=f"[{a.priority.upper()}] {a.owner} {hms(a.t)} {a.type}: {a.message}")

    def remember(self, a) -> None:
        """An urgent alert a re-notification may name later (the newest MAX_EMERGENCIES)."""
        aid = a.details.get("id")
        if isinstance(aid, str) and aid and a.priority in ("flash", "immediate"):
            self.urgent[aid] = a
            self.urgent.move_to_end(aid)
            if len(self.urgent) > MAX_EMERGENCIES:
                self.urgent.popitem(last=False)

    def renotified(self, alert_id: str) -> list[bytes]:
        """A re-notification of an unacknowledged alert: the same CoT uid sent again (TAK
        clients update the marker and raise its banner again), never a new marker."""
        a = self.urgent.get(alert_id)
        if a is None:
            return []
        self._count("renotify")
        return [self.alert_event(a)]

    def acknowledged(self, alert_id: str, owner: str, t: float) -> list[bytes]:
        """An alert its EA took an acknowledgement for: cancel the TAK emergencies it (and
        its repeats) raised, as ATAK cancels one (`b-a-o-can`, same uid, `cancel="true"`),
        so the banner goes from every TAK user's screen. Other alerts: nothing."""
        out = []
        self.urgent.pop(alert_id, None)
        for uid, lon, lat, callsign in self.emergencies.pop(alert_id, ()):
            tm = self.when(max(t, self.t))
            em = ET.Element("emergency", {"cancel": "true"})
            em.text = callsign
            det = [em, ET.Element("__saim", {"kind": "alert-cancel", "id": alert_id, "owner": owner,
                                             "t": f"{max(t, self.t):.3f}"})]
            out.append(C.event(uid, T.CANCEL, lon, lat, tm, tm + timedelta(seconds=self.o.pos_stale_s),
                               how=T.HOW_FUSED, callsign=callsign, detail=det,
                               remarks=f"[ACKNOWLEDGED] {owner} {hms(max(t, self.t))} {alert_id}"))
            self._count("cancel")
        return out

    def presence_event(self) -> bytes:
        """Who we are, first on every stream to a TAK server: a server registers a client by
        its first event (FreeTAKServer forwards nothing before it)."""
        now = datetime.now(timezone.utc)
        return C.event(self.uid("gateway", "cot"), "a-f-G-E-S", self.centre[0], self.centre[1], now,
                       now + timedelta(days=1), how="h-e", callsign=f"SAIM {self.sc.name}",
                       remarks="saim-mesh Cursor-on-Target gateway: units, tracks and alerts of the mesh")

    # -- overlay ---------------------------------------------------------------------
    def overlay_events(self, t: float | None = None) -> list[bytes]:
        """The scenario's control measures as TAK shapes (stale after the scenario)."""
        t = self.t if t is None else float(t)
        tm = self.when(t)
        life = self.o.overlay_stale_s or max(self.sc.duration_s - t, 0.0) + 3600.0
        out = []
        for fid, f in sorted(self.overlay.items()):
            g, props = f["geometry"], f["properties"]
            kind = props.get("kind", "area")
            colour = T.COLOURS[T.OVERLAY_COLOUR.get(kind, "grey")]
            det = [ET.Element("strokeColor", {"value": str(colour)}),
                   ET.Element("strokeWeight", {"value": "3.0"}),
                   ET.Element("labels_on", {"value": "true"}),
                   ET.Element("__saim", {"kind": "overlay", "id": fid, "measure": kind,
                                         "owner": str(props.get("owner") or "")})]
            if g["type"] == "Point":
                typ = T.CIRCLE
                lon, lat = g["coordinates"][:2]
                r = float(props.get("radius_m") or 250.0)
                shape = ET.Element("shape")
                C.sub(shape, "ellipse", major=r, minor=r, angle=360)
                det.insert(0, shape)
            else:
                typ = T.SHAPE
                ring = g["coordinates"][0] if g["type"] == "Polygon" else g["coordinates"]
                if g["type"] == "MultiPolygon":
                    ring = g["coordinates"][0][0]
                lon, lat = _centroid(ring)
                det[:0] = [ET.Element("link", {"point": f"{p[1]:.7f},{p[0]:.7f}"}) for p in ring]
                if g["type"] in ("Polygon", "MultiPolygon"):
                    det.append(ET.Element("fillColor", {"value": str((colour & 0x00FFFFFF) | 0x30000000)}))
            owner = props.get("owner")
            out.append(C.event(self.uid("ovl", fid), typ, lon, lat, tm, tm + timedelta(seconds=life),
                               how="h-e", callsign=fid, detail=det,
                               remarks=f"{kind} {fid}{f' of {owner}' if owner else ''} ({self.sc.name})"))
            self._count("overlay")
        return out
