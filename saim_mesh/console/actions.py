"""The commander's actions: checking what the page asks (so bad input is a clear 400
and nothing is sent) and turning it into commands (docs/console.md section 1).

`Actions` is anything with `ack/silence/unsilence/set/confirm/cff/decide/inhibit/uninhibit` returning a CmdResult-like
dict `{req, kind, ok, error, t, unit}`; `CommandActions` is the real one, over any
way of running a command (`commands.send` on the mesh, `commands.apply` in process)."""
from __future__ import annotations

import itertools
import math
import os
from typing import Any, Callable, Protocol

from ea_agent import domains

PHASES = ("start", "end")
CFF_ACTIONS = ("confirm", "cancel")
PRIORITIES = ("flash", "immediate", "priority", "routine")
MATCHER_KEYS = ("types", "subjects", "priorities", "owners")
LABELS = ("subjects", "owner", "places", "category")   # what an inhibition rule's `equal` may name
MAX_FOR_S = 7 * 86400


class BadRequest(ValueError):
    """The page asked for something that cannot be done; the text says why."""


class Actions(Protocol):
    def ack(self, unit: str, alert: str) -> dict: ...
    def silence(self, unit: str, types: list[str], subjects: list[str], areas: list[str], until_t: float,
                comment: str) -> dict: ...
    def unsilence(self, unit: str, id: str) -> dict: ...
    def set(self, unit: str, key: str, value: float | int | list[float]) -> dict: ...
    def confirm(self, unit: str, mission: str, phase: str) -> dict: ...
    def cff(self, unit: str, cff: str, action: str) -> dict: ...
    def decide(self, unit: str, alert: str, option: str) -> dict: ...
    def inhibit(self, unit: str, id: str, source: dict, target: dict, equal: list[str], for_s: float,
                comment: str) -> dict: ...
    def uninhibit(self, unit: str, id: str) -> dict: ...
    def order(self, unit: str, action: str, plan: str, mission: str, at: float) -> dict: ...


ORDER_ACTIONS = ("execute-plan", "abort-plan", "start-mission", "end-mission")
ORDER_LEAD_S = 10.0    # event seconds between an order given and when it takes effect (every EA the same)
FIELDS = {"ack": ("unit", "alert"), "silence": ("unit", "types", "subjects", "areas", "for_s", "comment"),
          "unsilence": ("unit", "id"), "set": ("unit", "key", "value"), "confirm": ("unit", "mission", "phase"), "cff": ("unit", "cff", "action"),
          "decide": ("unit", "alert", "option"),
          "inhibit": ("unit", "id", "source", "target", "equal", "for_s", "comment"),
          "uninhibit": ("unit", "id"),
          "order": ("unit", "action", "plan", "mission", "in_s")}


def _text(body: dict, f: str, choices=None, default: str | None = None) -> str:
    v = body.get(f, default)
    if not isinstance(v, str) or not v.strip() and default is None:
        raise BadRequest(f"field {f!r}: expected a non-empty string, got {json_type(v)}")
    if len(v) > 512:
        raise BadRequest(f"field {f!r}: over 512 characters")
    if choices is not None and v not in choices:
        raise BadRequest(f"field {f!r}: {v[:60]!r} is not one of {', '.join(choices)}")
    return v


def _texts(body: dict, f: str, name: str | None = None) -> list[str]:
    v = body.get(f, [])
    name = name or f
    if not isinstance(v, list) or not all(isinstance(x, str) and x for x in v):
        raise BadRequest(f"field {name!r}: expected a list of non-empty strings")
    if len(v) > 64:
        raise BadRequest(f"field {name!r}: over 64 entries")
    if any(len(x) > 128 for x in v):
        raise BadRequest(f"field {name!r}: an entry over 128 characters")
    return v


def _matcher(body: dict, f: str, known_types: set[str]) -> dict:
    """An inhibition rule's source or target: {types, subjects, priorities, owners}, at
    least one non-empty (an empty matcher matches every alert)."""
    v = body.get(f)
    if not isinstance(v, dict):
        raise BadRequest(f"field {f!r}: expected an object with any of {', '.join(MATCHER_KEYS)}, got {json_type(v)}")
    extra = sorted(set(v) - set(MATCHER_KEYS))
    if extra:
        raise BadRequest(f"field '{f}.{extra[0][:40]}': unexpected (a matcher takes {', '.join(MATCHER_KEYS)})")
    m = {k: _texts(v, k, f"{f}.{k}") for k in MATCHER_KEYS if k in v}
    m = {k: x for k, x in m.items() if x}
    if not m:
        raise BadRequest(f"field {f!r}: give at least one of {', '.join(MATCHER_KEYS)} (an empty matcher matches "
                         f"every alert)")
    bad = [t for t in m.get("types", ()) if t not in known_types]
    if bad:
        raise BadRequest(f"field '{f}.types': unknown alert type {bad[0][:60]!r}")
    bad = [p for p in m.get("priorities", ()) if p not in PRIORITIES]
    if bad:
        raise BadRequest(f"field '{f}.priorities': {bad[0][:60]!r} is not one of {', '.join(PRIORITIES)}")
    return m


def _number(v: Any) -> bool:
    return type(v) in (int, float) and math.isfinite(v)


def json_type(v: Any) -> str:
    return {bool: "a boolean", int: "a number", float: "a number", str: "a string", list: "a list",
            dict: "an object", type(None): "nothing"}.get(type(v), type(v).__name__)


def validate(kind: str, body: Any, state) -> tuple[str, dict]:
    """(unit, fields for the Actions method) or BadRequest naming the problem."""
    if not isinstance(body, dict):
        raise BadRequest(f"expected a JSON object, got {json_type(body)}")
    extra = sorted(set(body) - set(FIELDS[kind]))
    if extra:
        raise BadRequest(f"unexpected field {extra[0]!r} (a {kind} takes {', '.join(FIELDS[kind])})")
    unit = _text(body, "unit")
    if unit not in state.taskorg.units:
        raise BadRequest(f"unknown unit {unit[:60]!r}: not in the task organization of {state.sc.name}")
    if unit not in state.actors:
        raise BadRequest(f"this console does not act for {unit} (it acts for {', '.join(state.actors)})")
    if kind in ("ack", "decide"):
        aid = _text(body, "alert")
        owner = state.known_alert(aid)
        if owner is None:
            raise BadRequest(f"unknown alert {aid[:60]!r}: this console has not seen it")
        if owner != unit:
            raise BadRequest(f"alert {aid} was raised by the EA of {owner}, not {unit}")
        if kind == "decide":   # the EA checks the option against the alert's own list
            return unit, {"alert": aid, "option": _text(body, "option")}
        return unit, {"alert": aid}
    known = set(domains.of(state.sc).ALERT_TYPES) | {t for c in state.counts.values() for t in c}
    if kind == "silence":
        f = {k: _texts(body, k) for k in ("types", "subjects", "areas")}
        if not any(f.values()):
            raise BadRequest("a silence needs at least one of types, subjects, areas (it would silence everything)")
        bad = [t for t in f["types"] if t not in known]
        if bad:
            raise BadRequest(f"unknown alert type {bad[0][:60]!r}")
        places = {(x.get("properties") or {}).get("id") for x in state.overlay.get("features", ())}
        bad = [a for a in f["areas"] if a not in places]
        if bad:
            raise BadRequest(f"unknown area {bad[0][:60]!r}: not a control measure of {state.sc.name}")
        for_s = body.get("for_s")
        if not _number(for_s) or not 0 < for_s <= 7 * 86400:
            raise BadRequest(f"field 'for_s': expected seconds of scenario time in (0, 604800], got {for_s!r:.60}")
        return unit, {**f, "until_t": state.t + float(for_s), "comment": _text(body, "comment", default="")}
    if kind == "unsilence":
        sid = _text(body, "id")
        if sid not in state.silences:
            raise BadRequest(f"unknown silence {sid[:60]!r}: not one in force that this console made")
        if state.silences[sid]["unit"] != unit:
            raise BadRequest(f"silence {sid} is on the EA of {state.silences[sid]['unit']}, not {unit}")
        return unit, {"id": sid}
    if kind == "inhibit":
        rid = body.get("id")
        if rid is None or rid == "":
            rid = ""   # the console names it
        elif not isinstance(rid, str) or not rid.strip() or len(rid) > 64 or any(c in rid for c in "/*$#?"):
            raise BadRequest(f"field 'id': expected a rule name (up to 64 characters, no / * $ # ?), got "
                             f"{rid!r:.60}")
        source, target = _matcher(body, "source", known), _matcher(body, "target", known)
        equal = body.get("equal", [])
        if not isinstance(equal, list) or not all(isinstance(x, str) for x in equal):
            raise BadRequest(f"field 'equal': expected a list of labels ({', '.join(LABELS)})")
        bad = [x for x in equal if x not in LABELS]
        if bad:
            raise BadRequest(f"field 'equal': unknown label {bad[0][:40]!r} (known: {', '.join(LABELS)})")
        for_s = body.get("for_s", 0)
        if not _number(for_s) or not 0 <= for_s <= MAX_FOR_S:
            raise BadRequest(f"field 'for_s': expected seconds of scenario time in [0, {MAX_FOR_S}] (0: the EA's "
                             f"voa.expiry_s), got {for_s!r:.60}")
        return unit, {"id": rid, "source": source, "target": target, "equal": list(dict.fromkeys(equal)),
                      "for_s": float(for_s), "comment": _text(body, "comment", default="")}
    if kind == "uninhibit":
        rid = _text(body, "id")
        if not state.known_inhibit(unit, rid):
            mine = state.inhibit_ids(unit)
            raise BadRequest(f"unknown inhibition rule {rid[:60]!r} on the EA of {unit}: not one in force that this "
                             f"console made (in force: {', '.join(mine) or 'none'})")
        return unit, {"id": rid}
    if kind == "set":
        key = _text(body, "key")
        if not key.startswith(("voi.", "voa.")):
            raise BadRequest(f"field 'key': {key[:60]!r} is not a [voi] or [voa] setting (e.g. voi.out_of_position_m)")
        v = body.get("value")
        ok = _number(v) or isinstance(v, list) and 0 < len(v) <= 64 and all(_number(x) for x in v)
        if not ok:
            raise BadRequest(f"field 'value': expected a number or a list of numbers, got {json_type(v)}")
        return unit, {"key": key, "value": v}
    if kind == "order":   # to the unit's whole subtree, at the console's event time + in_s
        action = _text(body, "action", ORDER_ACTIONS)
        plan = _text(body, "plan", default="") if action == "execute-plan" else ""
        mission = _text(body, "mission", default="") if action in ("start-mission", "end-mission") else ""
        for f, v in (("plan", body.get("plan")), ("mission", body.get("mission"))):
            if v not in (None, "") and not (f == "plan" and plan or f == "mission" and mission):
                raise BadRequest(f"field {f!r}: an {action} order names no {f}")
        if action == "execute-plan" and not plan:
            raise BadRequest("field 'plan': an execute-plan order names its plan")
        if action == "execute-plan" and plan not in state.sc.plans:
            raise BadRequest(f"unknown plan {plan[:60]!r}: {state.sc.name} has {', '.join(state.sc.plans)}")
        if mission:
            spec = state.missions.specs.get(mission)
            if spec is None:
                raise BadRequest(f"unknown mission {mission[:60]!r}: in no plan of {state.sc.name}")
        elif action in ("start-mission", "end-mission"):
            raise BadRequest(f"field 'mission': an {action} order names its mission")
        in_s = body.get("in_s", ORDER_LEAD_S)
        if not _number(in_s) or not 0 <= in_s <= 3600:
            raise BadRequest(f"field 'in_s': expected event seconds from now in [0, 3600], got {in_s!r:.60}")
        return unit, {"action": action, "plan": plan, "mission": mission, "at": state.t + float(in_s)}
    if kind == "confirm":
        mid = _text(body, "mission")
        if mid not in state.missions.specs:
            raise BadRequest(f"unknown mission {mid[:60]!r}: in no plan of {state.sc.name}")
        return unit, {"mission": mid, "phase": _text(body, "phase", PHASES)}
    return unit, {"cff": _text(body, "cff"), "action": _text(body, "action", CFF_ACTIONS)}


def result_dict(res: Any, unit: str | None = None) -> dict:
    """A CmdResult (msgspec struct or dict) as the JSON the page gets."""
    if isinstance(res, dict):
        d = dict(res)
    else:
        d = {f: getattr(res, f, None) for f in ("req", "kind", "ok", "error", "t", "ref")}
    d.pop("v", None)
    if unit is not None:
        d.setdefault("unit", unit)
    return d


class CommandActions:
    """Actions as commands: built by `commands.make`, run by `run(unit, cmd)`; with
    `push`, results go to the state's event stream too (in process: no cmdlog to hear)."""

    def __init__(self, run: Callable[[str, Any], Any], state=None, push: bool = False, direct=None,
                 lead_s: float = ORDER_LEAD_S):
        """`direct(unit, kind, fields)`: publish a directive (saim_mesh/authority/directives.py) as
        `unit` on the live mesh: orders to the subtree, confirmations up the chain
        (None: an in-process console cannot)."""
        self.run, self.state, self.push, self.direct, self.lead_s = run, state, push, direct, lead_s
        self._n = itertools.count(1)
        self._tag = f"console-{os.getpid()}"

    def _do(self, unit: str, kind: str, **fields) -> dict:
        from ..authority import commands   # the EA side's module (docs/console.md section 1)
        cmd = commands.make(kind, req=f"{self._tag}-{next(self._n)}", **fields)
        d = result_dict(self.run(unit, cmd), unit)
        if self.state is not None:
            if kind in ("silence", "unsilence"):
                self.state.silenced(unit, cmd, bool(d.get("ok")))
            if kind in ("inhibit", "uninhibit"):
                self.state.inhibited(unit, cmd, bool(d.get("ok")))
            if self.push:
                self.state.result(d)
        return d

    def ack(self, unit, alert):
        return self._do(unit, "ack", alert=alert, by=f"console.{self.state.unit if self.state else unit}")

    def silence(self, unit, types, subjects, areas, until_t, comment):
        sid = f"{self._tag}-s{next(self._n)}"
        return self._do(unit, "silence", id=sid, types=types, subjects=subjects, areas=areas, until_t=until_t,
                        comment=comment)

    def unsilence(self, unit, id):
        return self._do(unit, "unsilence", id=id)

    def set(self, unit, key, value):
        return self._do(unit, "set", key=key, value=value)

    def confirm(self, unit, mission, phase):
        if self.direct is not None:   # live: a confirmation goes up the chain, at one event time for all
            at = (self.state.t if self.state is not None else 0.0) + self.lead_s
            return self._directed(unit, "confirm", mission=mission, phase=phase, at=at)
        return self._do(unit, "confirm", mission=mission, phase=phase)

    def order(self, unit, action, plan, mission, at):
        if self.direct is None:
            return {"req": "", "kind": "order", "ok": False, "t": at, "unit": unit, "ref": action,
                    "error": "orders to a subtree go over the mesh (saim-mesh console); an in-process console cannot"}
        return self._directed(unit, "order", action=action, plan=plan, mission=mission, at=at)

    def _directed(self, unit: str, kind: str, **fields) -> dict:
        """Sent: the EAs' own answers follow on cmdlog/** (the page shows each)."""
        try:
            req = self.direct(unit, kind, fields)
        except ValueError as e:
            return {"req": "", "kind": kind, "ok": False, "error": str(e)[:500], "t": fields["at"], "unit": unit}
        return {"req": req, "kind": kind, "ok": True, "error": "", "t": fields["at"], "unit": unit,
                "ref": fields.get("mission") or fields.get("plan") or fields.get("action", "")}

    def cff(self, unit, cff, action):
        m = self.state.cff_message(cff) if self.direct is not None and action == "confirm" and self.state else None
        if m is not None:   # live: every EA hears the confirmation, each warns of its own units near the target
            return self._directed(unit, "cff", cff=cff, requester=m.requester, lon=m.lon, lat=m.lat,
                                  radius_m=m.radius_m, at=self.state.t + self.lead_s)
        return self._do(unit, "cff", cff=cff, action=action)

    def decide(self, unit, alert, option):
        mission = self._mission_of(alert) if self.direct is not None else None
        if mission:   # live: the decision reaches every EA of the unit's subtree that runs the mission
            at = (self.state.t if self.state is not None else 0.0) + self.lead_s
            return self._directed(unit, "decide", alert=alert, mission=mission, option=option, at=at)
        return self._do(unit, "decide", alert=alert, option=option)

    def _mission_of(self, alert: str) -> str | None:
        """The mission a decision alert is about, as the page saw the alert."""
        if self.state is None:
            return None
        for d in [*self.state.alerts, *getattr(self.state, "quiet", ())]:
            if d.get("details", {}).get("id") == alert:
                return d["details"].get("mission")
        return None

    def inhibit(self, unit, id, source, target, equal, for_s, comment):
        """`source`/`target`: {types, subjects, priorities, owners} (msgspec makes the
        MatcherSpec structs); no `id`: this console names the rule."""
        return self._do(unit, "inhibit", id=id or f"{self._tag}-i{next(self._n)}", source=source, target=target,
                        equal=equal, for_s=for_s, comment=comment)

    def uninhibit(self, unit, id):
        return self._do(unit, "uninhibit", id=id)
