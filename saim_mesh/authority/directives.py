"""Authority over the mesh (issue 33): what a commander orders flows down the chain of
command, what a unit confirms flows up, and every EA concerned takes it at the same event
time.

A *directive* is a signed fact with an effective event time `at`, published once by its
issuer on `<root>/dir/<by>/<kind>` (`by`: the unit whose console or EA issues it):

* `order` (execute-plan, abort-plan, start-mission, end-mission): for every EA of `by`'s
  subtree as the task organization stands in that EA (reorganizations included);
* `confirm` (a mission of `by` started or ended: confirmed at `by`'s console or inferred
  by its EA): for `by`'s EA and its superiors' EAs, the paper's "confirmation from a
  subordinate EA". An EA infers its own unit's start when the unit crosses its line of
  departure (where the plan says so) and publishes it signed as `ea.<by>`, effective
  `CONFIRM_LEAD_S` later on an epoch's end; a superior that saw the crossing itself
  already knows (taken, no change), one that did not starts the mission then.

Why an effective time instead of "when it arrives": arrival differs from EA to EA; the
issuer states when the directive takes effect (a few seconds of event time ahead of the
picture it sees) and every EA applies it after the facts before `at` and before those at
`at`, so their alerts stay identical and equal an in-process run given the same
directive (`runner.run(directives=...)`). An EA that gets it after it passed `at` (cut off
at the time) takes it at once, says so in its command log and marks it late.

Authority is checked twice: the signature (secure mode: only `console.<U>` and `ea.<U>`
sign `dir/<U>/...`, `security/sign.rules_for`), then the task organization (`refusal`):
an order for a mission of a unit outside the issuer's subtree, or a confirmation for a
mission that is not the issuer's, is refused and counted, and the refusal answered on the
EA's command log."""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Annotated, Literal

import msgspec

from ..protocol import messages as M
from ..protocol import wire as W

KINDS = ("order", "confirm", "decide", "cff", "reorganize", "plan")
# event seconds from a start an EA inferred to when its confirmation takes effect up the
# chain: as a console's order lead (console/actions.ORDER_LEAD_S), time to reach the
# superiors before their EAs pass it
CONFIRM_LEAD_S = 10.0
Name = W.Name
Req = Annotated[str, msgspec.Meta(min_length=1, max_length=64)]


class OrderDirective(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """An order of `by` to its subtree: execute a plan, abort it, start or end a mission."""
    v: Literal[1]
    req: Req
    n: Annotated[int, msgspec.Meta(ge=1, le=W.SEQ_LIMIT)]   # the issuer's own count: (at, by, n) orders them
    at: W.Time
    action: Literal["execute-plan", "abort-plan", "start-mission", "end-mission"]
    plan: Annotated[str, msgspec.Meta(max_length=128)] = ""
    mission: Annotated[str, msgspec.Meta(max_length=128)] = ""


class ConfirmDirective(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """`by` confirms that its mission started or ended."""
    v: Literal[1]
    req: Req
    n: Annotated[int, msgspec.Meta(ge=1, le=W.SEQ_LIMIT)]
    at: W.Time
    mission: Name
    phase: Literal["start", "end"]


class DecideDirective(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """`by`'s decision on an alert that asked for one (`option`: abort, continue, or
    branch:<id>): every EA of `by`'s subtree that runs `mission` carries it out."""
    v: Literal[1]
    req: Req
    n: Annotated[int, msgspec.Meta(ge=1, le=W.SEQ_LIMIT)]
    at: W.Time
    alert: Name
    mission: Name
    option: Name


class CffDirective(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """A call for fire confirmed by `by` (the requester or a superior of it): every EA takes
    it, so each warns of its own units near the target."""
    v: Literal[1]
    req: Req
    n: Annotated[int, msgspec.Meta(ge=1, le=W.SEQ_LIMIT)]
    at: W.Time
    cff: Name
    requester: Name
    lon: Annotated[float, msgspec.Meta(ge=-180.0, le=180.0)]
    lat: Annotated[float, msgspec.Meta(ge=-90.0, le=90.0)]
    radius_m: Annotated[float, msgspec.Meta(gt=0.0, le=100_000.0)]


class ReorganizeDirective(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """`by` puts `unit` (one of its subordinates) under `new_parent` (in its subtree): every
    EA takes the change, so all agree on the chain of command from `at` on."""
    v: Literal[1]
    req: Req
    n: Annotated[int, msgspec.Meta(ge=1, le=W.SEQ_LIMIT)]
    at: W.Time
    unit: Name
    new_parent: Name


class PlanDirective(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """A new plan version for `by`'s subtree (`missions`: the plan's missions as JSON, as a
    plan file lists them): every EA of the subtree validates it and executes it at `at`
    as plan `<name>.v<version>`."""
    v: Literal[1]
    req: Req
    n: Annotated[int, msgspec.Meta(ge=1, le=W.SEQ_LIMIT)]
    at: W.Time
    name: Annotated[str, msgspec.Meta(min_length=1, max_length=48, pattern=r"^[A-Za-z0-9_\-]+$")]
    version: Annotated[int, msgspec.Meta(ge=1, le=1_000_000)]
    missions: Annotated[bytes, msgspec.Meta(max_length=48 * 1024)]

    @property
    def plan(self) -> str:
        return f"{self.name}.v{self.version}"


Directive = OrderDirective | ConfirmDirective | DecideDirective | CffDirective | ReorganizeDirective | PlanDirective
TYPES: dict[str, type] = {"order": OrderDirective, "confirm": ConfirmDirective, "decide": DecideDirective,
                          "cff": CffDirective, "reorganize": ReorganizeDirective, "plan": PlanDirective}
KIND_OF = {c: k for k, c in TYPES.items()}
_DEC = {c: msgspec.msgpack.Decoder(c) for c in TYPES.values()}


@dataclass(frozen=True, slots=True)
class Taken:
    """A directive as an EA takes it: who issued it and what."""
    by: str
    d: Directive

    @property
    def t(self) -> float:
        return self.d.at

    def sort_key(self) -> tuple:
        return (self.d.at, self.by, self.d.n, self.d.req)


def key(root: str, by: str, kind: str) -> str:
    return f"{root}/dir/{by}/{kind}"


def make(kind: str, **fields) -> Directive:
    """A directive checked as an EA's gate checks it (ValueError naming what is wrong)."""
    cls = TYPES.get(kind)
    if cls is None:
        raise ValueError(f"unknown directive kind {kind!r} (known: {', '.join(KINDS)})")
    try:
        d = cls(v=W.VERSION, **fields)
        return decode(kind, msgspec.msgpack.encode(d), 1 << 16)
    except TypeError as e:
        raise ValueError(f"{kind}: {e}") from None
    except M.MessageError as e:
        raise ValueError(f"{kind}: {e.problem}") from None


def decode(kind: str, payload: bytes, max_bytes: int):
    """One directive payload (already out of its envelope); raises MessageError only."""
    cls = TYPES.get(kind)
    if cls is None:
        raise M.MessageError("directive", "(key)", f"unknown directive kind {kind[:32]!r}")
    if len(payload) > max_bytes:
        raise M.MessageError("directive", "(bytes)", f"{len(payload)} bytes, over the {max_bytes} limit")
    try:
        d = _DEC[cls].decode(payload)
    except (msgspec.ValidationError, msgspec.DecodeError) as e:
        raise M.MessageError("directive", "(message)", str(e)[:200]) from None
    except Exception as e:   # a decoder bug must not kill a peer
        raise M.MessageError("directive", "(message)", f"undecodable: {type(e).__name__}") from None
    if not math.isfinite(d.at):
        raise M.MessageError("directive", "at", "not a finite event time")
    if kind == "decide" and d.option != "continue" and d.option != "abort" and not d.option.startswith("branch:"):
        raise M.MessageError("directive", "option", f"{d.option[:64]!r}: abort, continue or branch:<id>")
    if kind == "order":
        if d.action == "execute-plan" and not d.plan:
            raise M.MessageError("directive", "plan", "execute-plan names no plan")
        if d.action in ("start-mission", "end-mission") and not d.mission:
            raise M.MessageError("directive", "mission", f"{d.action} names no mission")
    return d


def parse_key(root: str, k: str) -> tuple[str, str] | None:
    """(by, kind) of a directive's key, None when it is not one."""
    prefix = f"{root}/dir/"
    if not k.startswith(prefix):
        return None
    parts = k[len(prefix):].split("/")
    if len(parts) != 2 or not parts[0] or parts[1] not in TYPES:
        return None
    return parts[0], parts[1]


def concerns(domain, unit: str, tk: Taken) -> bool:
    """Whether `unit`'s EA considers this directive at all (the key space carries every
    directive to every EA): an order from itself or a superior, or one naming a mission of
    its subtree (which it may have to refuse); a confirmation from itself or a subordinate.
    Anything else is not for it: ignored, not refused."""
    to = domain.taskorg
    if tk.by == unit:
        return True
    if isinstance(tk.d, ConfirmDirective):
        return tk.by in to.units and unit in to.ancestors(tk.by)
    if isinstance(tk.d, (CffDirective, ReorganizeDirective)):
        return True   # every EA: each warns of its own units near the target; all keep one chain of command
    if tk.by in to.units and tk.by in to.ancestors(unit):
        return True
    if isinstance(tk.d, PlanDirective):
        return False
    m = (getattr(domain, "missions", {}) or {}).get(tk.d.mission) if tk.d.mission else None
    return m is not None and (m.unit == unit or unit in to.ancestors(m.unit))


def refusal(domain, tk: Taken, validate=None) -> str | None:
    """Why the EA refuses a directive that concerns it (None: it takes it), judged when
    it takes effect: the task organization and plan as this EA knows them then decide who
    may order or confirm what."""
    to = domain.taskorg
    d = tk.d
    missions = getattr(domain, "missions", {}) or {}
    if tk.by not in to.units:
        return f"{tk.by[:64]!r} is not a unit of the task organization"
    if isinstance(d, OrderDirective):
        if d.action in ("start-mission", "end-mission"):
            m = missions.get(d.mission)
            if m is None:
                return f"unknown mission {d.mission[:64]!r} (not in the plan this EA runs)"
            if tk.by != m.unit and tk.by not in to.ancestors(m.unit):
                return f"{tk.by} does not command {m.unit}: it cannot order {d.mission[:64]!r}"
        elif d.action == "execute-plan" and d.plan not in (getattr(domain, "plans", None) or {}):
            return f"unknown plan {d.plan[:64]!r}"
        return None
    if isinstance(d, PlanDirective):
        if validate is None:
            return "this EA cannot validate plan versions (no scenario to check them against)"
        try:
            spec = validate(d.plan, d.missions)
        except ValueError as e:
            return str(e)[:800]
        mine = {tk.by, *to.subtree(tk.by)} if tk.by in to.units else set()
        outside = sorted({m.unit for m in spec.missions} - mine)
        if outside:
            return f"plan {d.plan}: missions for {', '.join(outside[:5])}, outside {tk.by}'s subtree"
        return None
    if isinstance(d, DecideDirective):
        m = missions.get(d.mission)
        if m is None:
            return f"unknown mission {d.mission[:64]!r} (not in the plan this EA runs)"
        if tk.by != m.unit and tk.by not in to.ancestors(m.unit):
            return f"{tk.by} does not command {m.unit}: it cannot decide on {d.mission[:64]!r}"
        return None
    if isinstance(d, CffDirective):
        if d.requester not in to.units:
            return f"unknown requester {d.requester[:64]!r}"
        if tk.by != d.requester and tk.by not in to.ancestors(d.requester):
            return f"{tk.by} does not command {d.requester}: it cannot confirm its call for fire"
        return None
    if isinstance(d, ReorganizeDirective):
        for u in (d.unit, d.new_parent):
            if u not in to.units:
                return f"unknown unit {u[:64]!r}"
        if tk.by not in to.ancestors(d.unit):
            return f"{tk.by} does not command {d.unit}: it cannot reorganize it"
        if d.new_parent != tk.by and tk.by not in to.ancestors(d.new_parent):
            return f"{d.new_parent} is not in {tk.by}'s subtree"
        if d.new_parent == d.unit or d.unit in [d.new_parent, *to.ancestors(d.new_parent)]:
            return f"{d.new_parent} is {d.unit} or under it: a cycle"
        return None
    m = missions.get(d.mission)
    if m is None:
        return f"unknown mission {d.mission[:64]!r} (not in the plan this EA runs)"
    if m.unit != tk.by:
        return f"mission {d.mission[:64]!r} is {m.unit}'s: {tk.by} cannot confirm it"
    return None


def apply(ea, tk: Taken, validate=None) -> None:
    """Carry it out in `ea` at its time (the caller advanced the EA to `at`)."""
    d, t = tk.d, tk.d.at
    if isinstance(d, OrderDirective):
        ea.submit(M.Order(t, d.action, d.plan, tk.by, d.mission or None))
        return
    if isinstance(d, CffDirective):
        ea.submit(M.CallForFireConfirm(t, d.cff, d.requester, d.lon, d.lat, d.radius_m))
        return
    if isinstance(d, ReorganizeDirective):
        ea.submit(M.Reorganization(t, d.unit, d.new_parent))
        return
    if isinstance(d, PlanDirective):   # validated by `refusal`: the new version, then executed
        ea.domain.plans = {**ea.domain.plans, d.plan: validate(d.plan, d.missions)}
        ea.submit(M.Order(t, "execute-plan", d.plan, tk.by, None))
        return
    if isinstance(d, DecideDirective):
        ea.domain.decide({"decision": {"options": [d.option]}, "mission": d.mission}, d.option, t)
        if d.alert.rsplit("/", 1)[0] == ea.owner:
            try:
                ea.ack(d.alert, t)
            except KeyError:
                pass   # not repeating: nothing to stop
        return
    m = ea.domain.missions[d.mission]
    state = ea.domain.plan.state.get(d.mission) if ea.domain.plan is not None else None
    if state == "done" or d.phase == "start" and state == "active":
        return   # this EA knew it already (it saw the unit cross its line of departure too)
    ea.submit(M.MissionConfirm(t, d.mission, m.unit, d.phase, "local" if tk.by == ea.owner else "message"))


def result(tk: Taken, ok: bool, t: float, error: str = "", late: bool = False, due: float | None = None
           ) -> W.CmdResult:
    """The EA's answer; `due`: the `at` it named, when taken `late` at `t`."""
    kind = KIND_OF[type(tk.d)]
    d = tk.d
    ref = (d.mission if isinstance(d, (ConfirmDirective, DecideDirective)) else d.cff if isinstance(d, CffDirective)
           else d.unit if isinstance(d, ReorganizeDirective) else d.plan if isinstance(d, PlanDirective)
           else (d.mission or d.plan or d.action))
    due = tk.d.at if due is None else due
    err = error or (f"taken late: due at {due:.0f} s, the EA was past it" if late else "")
    return W.make(W.CmdResult, req=tk.d.req, kind=kind, ok=ok, error=err[:1000],
                  t=max(0.0, min(float(t), W.T_LIMIT)), ref=str(ref)[:128])


def take(ea, tk: Taken, validate=None) -> tuple[bool, str] | None:
    """`ea` takes a due directive (advanced to its `at` by the caller): None when it does
    not concern this EA (ignored), else (taken, why refused). The same in a peer and in
    process (`runner.run(directives=...)`), so both give the same alerts."""
    dom = ea.domain
    if not concerns(dom, ea.owner, tk):
        return None
    why = refusal(dom, tk, validate)
    if why is not None:
        return False, why
    try:
        apply(ea, tk, validate)
    except (KeyError, ValueError) as e:   # the domain's own check said no
        return False, str(e.args[0] if e.args else e)[:500]
    return True, ""


def at_least(tk: Taken, t: float) -> Taken:
    """The directive taken late, at `t` (the EA was past its `at`)."""
    return Taken(tk.by, msgspec.structs.replace(tk.d, at=max(tk.d.at, t))) if t > tk.d.at else tk


def wrap(entries: list[tuple[str, bytes]]) -> bytes:
    """A late joiner's answer: the directives an EA took, each (key, payload as received)."""
    return msgspec.msgpack.encode([[k, p] for k, p in entries])


_WRAPPED = msgspec.msgpack.Decoder(
    Annotated[list[tuple[Annotated[str, msgspec.Meta(max_length=W.KEY_LIMIT)],
                         Annotated[bytes, msgspec.Meta(max_length=64 * 1024)]]], msgspec.Meta(max_length=10_000)])


def unwrap(payload: bytes) -> list[tuple[str, bytes]]:
    """Raises MessageError only."""
    if len(payload) > 64 * 2**20:
        raise M.MessageError("directive", "(bytes)", "a directive journal answer over 64 MB")
    try:
        return [(k, p) for k, p in _WRAPPED.decode(payload)]
    except (msgspec.ValidationError, msgspec.DecodeError) as e:
        raise M.MessageError("directive", "(journal)", str(e)[:200]) from None


def publish(session, root: str, signer, by: str, kind: str, pub=None, **fields):
    """Make, sign (secure mode: `signer` is `by`'s console or EA) and put one directive as
    `by`; returns it. `pub`: a publisher declared on its key (to have waited for matching)."""
    import time

    import zenoh
    n = signer.next_n() if signer is not None else time.time_ns() // 1000
    d = make(kind, req=fields.pop("req", None) or _req(), n=n, **fields)
    k = key(root, by, kind)
    body = msgspec.msgpack.encode(d)
    payload = body if signer is None else signer.sign(k, body, n)
    if pub is not None:
        pub.put(payload)
    else:
        session.put(k, payload, congestion_control=zenoh.CongestionControl.BLOCK)
    return d


def _req() -> str:
    import uuid
    return uuid.uuid4().hex[:16]
