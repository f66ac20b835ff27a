"""TAK clients' position reports (PLI) in: a CoT event from a person's ATAK becomes a
`LocationReport` for the scenario entity its uid is mapped to, so that the EA monitors
that person like any other entity.

Which entity: a mapping file (`[uids] "ANDROID-abc" = "A2S1E01"`, TOML or JSON), else a
rule: `uid` (the uid is the entity id), `callsign` (the callsign is), or `regex:PATTERN`
(the pattern's `entity` group, or its first group, taken from the uid). An unknown uid,
or an entity not in the task organization, is rejected and counted, never guessed."""
from __future__ import annotations

import json
import math
import re
import tomllib
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

from ..protocol.messages import LocationReport, MessageError
from . import cot as C

RULES = ("uid", "callsign")


@dataclass
class UidMap:
    """uid -> entity id, by table first, then by rule; and uid -> the unit an ATAK user
    acts for when acknowledging alerts (`units`, explicit; else the unit of the entity the
    `uids` table names: a rule never gives command authority)."""
    uids: dict[str, str] = field(default_factory=dict)
    rule: str | None = None
    units: dict[str, str] = field(default_factory=dict)

    def __post_init__(self):
        self._re = None
        if self.rule is not None and self.rule not in RULES:
            if not self.rule.startswith("regex:"):
                raise ValueError(f"uid rule {self.rule!r}: one of {', '.join(RULES)} or regex:PATTERN")
            try:
                self._re = re.compile(self.rule[len("regex:"):])
            except re.error as e:
                raise ValueError(f"uid rule {self.rule!r}: bad regular expression ({e})") from None
            if self._re.groups == 0:
                raise ValueError(f"uid rule {self.rule!r}: needs a group (named 'entity' or the first)")

    def entity(self, ev: C.CoTEvent) -> str | None:
        return self.entity_of(ev.uid, ev.callsign)

    def entity_of(self, uid: str, callsign: str | None = None) -> str | None:
        e = self.uids.get(uid)
        if e is not None or self.rule is None:
            return e
        if self.rule == "uid":
            return uid
        if self.rule == "callsign":
            return callsign
        m = self._re.fullmatch(uid)
        if m is None:
            return None
        return m.group("entity") if "entity" in self._re.groupindex else m.group(1)

    def unit(self, uid: str, entity_unit: dict[str, str]) -> str | None:
        """The unit the ATAK user `uid` acts for: the `units` table, else the unit of the
        entity the `uids` table maps it to (never by rule), else None."""
        u = self.units.get(uid)
        if u is not None:
            return u
        e = self.uids.get(uid)
        return entity_unit.get(e) if e is not None else None

    def commander(self, uid: str) -> bool:
        """A device that acts for a unit without being one of its monitored entities."""
        return uid in self.units and uid not in self.uids

    def check(self, entities, units=None) -> None:
        """Every mapped entity (and unit) must exist (a typo in the file is an error at start)."""
        bad = sorted(e for e in self.uids.values() if e not in entities)
        if bad:
            raise ValueError(f"uid map names entities not in the task organization: {', '.join(bad[:10])}")
        bad = sorted(u for u in self.units.values() if units is not None and u not in units)
        if bad:
            raise ValueError(f"uid map names units not in the task organization: {', '.join(bad[:10])}")


def load_uids(path: str | Path | None, rule: str | None = None) -> UidMap:
    """A UidMap from a TOML or JSON file (`uids` table of uid = entity; an optional `units`
    table of uid = unit, who may acknowledge alerts as that unit; an optional `rule` key)
    and/or a rule."""
    uids: dict[str, str] = {}
    units: dict[str, str] = {}
    if path is not None:
        p = Path(path)
        try:
            raw = p.read_bytes()
            d = json.loads(raw) if p.suffix == ".json" else tomllib.loads(raw.decode("utf-8"))
        except (OSError, ValueError, tomllib.TOMLDecodeError) as e:
            raise ValueError(f"{p}: cannot read the uid map ({e})") from None
        table = d.get("uids", {})
        if not isinstance(table, dict) or not all(isinstance(k, str) and isinstance(v, str) and k and v
                                                  for k, v in table.items()):
            raise ValueError(f"{p}: field 'uids': expected a table of uid = entity id strings")
        uids = dict(table)
        ut = d.get("units", {})
        if not isinstance(ut, dict) or not all(isinstance(k, str) and isinstance(v, str) and k and v
                                               for k, v in ut.items()):
            raise ValueError(f"{p}: field 'units': expected a table of uid = unit id strings")
        units = dict(ut)
        file_rule = d.get("rule")
        if file_rule is not None and not isinstance(file_rule, str):
            raise ValueError(f"{p}: field 'rule': expected a string")
        rule = rule or file_rule
    return UidMap(uids, rule, units)


class PliIn:
    """Bytes from a TAK network -> checked LocationReports; every refusal counted by reason.

    `own` is the uid prefix of the gateway's own events (heard back on a multicast group):
    skipped, not counted as rejects; so are events that are not friendly atoms (pings,
    chat, markers): a TAK network carries many such."""

    def __init__(self, sc, uids: UidMap, own: str = "saim.", max_bytes: int = C.MAX_BYTES,
                 skew_s: float = C.MAX_SKEW_S, clock=None):
        self.sc, self.uids, self.own, self.max_bytes, self.skew_s = sc, uids, own, max_bytes, skew_s
        self.entities = set(sc.taskorg.entity_unit)
        uids.check(self.entities, set(sc.taskorg.units))
        self.clock = clock or (lambda: datetime.now(timezone.utc))
        self.accepted = 0
        self.skipped: dict[str, int] = {}
        self.rejects: dict[str, int] = {}
        self.last_error = ""

    @property
    def rejected(self) -> int:
        return sum(self.rejects.values())

    def _no(self, reason: str, why: str) -> None:
        self.rejects[reason] = self.rejects.get(reason, 0) + 1
        self.last_error = why[:200]

    def parse(self, data: bytes) -> C.CoTEvent | None:
        """One event from a TAK network, checked (`cot.parse`), or None (counted)."""
        try:
            return C.parse(data, max_bytes=self.max_bytes, now=self.clock(), skew_s=self.skew_s)
        except C.CotError as e:
            self._no("bytes" if e.field == "bytes" else "malformed" if e.field in ("xml", "protobuf", "detail")
                     else e.field, str(e))
            return None

    def take(self, data: bytes, t: float) -> LocationReport | None:
        """One event received at scenario time `t` -> a LocationReport, or None (counted)."""
        ev = self.parse(data)
        return None if ev is None else self.take_event(ev, t)

    def take_event(self, ev: C.CoTEvent, t: float) -> LocationReport | None:
        """A parsed event -> a LocationReport, or None (skipped or counted)."""
        now = self.clock()
        if ev.uid.startswith(self.own):
            self.skipped["own"] = self.skipped.get("own", 0) + 1
            return None
        if not ev.type.startswith("a-f-"):
            self.skipped["not-pli"] = self.skipped.get("not-pli", 0) + 1
            return None
        if ev.stale < now:
            self._no("stale", f"{ev.uid}: stale since {C.iso(ev.stale)}")
            return None
        entity = self.uids.entity(ev)
        if entity is None and self.uids.commander(ev.uid):   # a commander's device, not a monitored entity
            self.skipped["commander"] = self.skipped.get("commander", 0) + 1
            return None
        if entity is None:
            self._no("unknown-uid", f"uid {ev.uid[:80]!r} is not mapped to an entity")
            return None
        if entity not in self.entities:
            self._no("unknown-entity", f"uid {ev.uid[:80]!r} -> {entity[:40]!r}: not an entity of {self.sc.name}")
            return None
        try:   # validated like every other report (the codec's own checks)
            rep = LocationReport.from_dict({"t": float(t), "entity": entity, "lon": ev.lon, "lat": ev.lat})
            x, y = self.sc.projection.to_xy(rep.lon, rep.lat)
        except MessageError as e:
            self._no("report", str(e))
            return None
        if not (math.isfinite(x) and math.isfinite(y)):
            self._no("point", f"{ev.uid}: ({ev.lon}, {ev.lat}) cannot be projected to the scenario's area")
            return None
        self.accepted += 1
        return rep
