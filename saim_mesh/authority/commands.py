"""A commander's commands to an EA (docs/console.md section 1): built and checked
(`make`), applied in process (`apply`), or sent over the mesh to a unit's EA peer and
answered on its command log (`send`). The console and the CLI share all three, so a
command means the same whichever way it reaches the EA."""
from __future__ import annotations

import queue
import time
import uuid
import weakref
from collections import OrderedDict

import msgspec
import zenoh

from ..protocol import messages as M
from ..protocol import gate as G
from ..protocol import wire as W

KIND_OF = {cls: kind for kind, cls in W.COMMANDS.items()}
CFF_BOOK = 1000   # calls for fire remembered per EA (the newest)
_BOOKS: "weakref.WeakKeyDictionary[object, OrderedDict]" = weakref.WeakKeyDictionary()


def new_req() -> str:
    return uuid.uuid4().hex[:16]


def make(kind: str, **fields) -> msgspec.Struct:
    """A command of `kind`, checked as the EA's gate checks it (ValueError naming the field).
    `req` is made up when not given."""
    cls = W.COMMANDS.get(kind)
    if cls is None:
        raise ValueError(f"unknown command kind {kind!r} (known: {', '.join(W.COMMANDS)})")
    fields.setdefault("req", new_req())
    try:
        cmd = W.make(cls, **fields)
    except TypeError as e:
        raise ValueError(f"{kind}: {e}") from None
    try:   # the constructor does not check types or bounds: the decoder does
        return W.decode_control(cls, W.encode(cmd), 1 << 20)
    except M.MessageError as e:
        raise ValueError(f"{kind}: {e.problem}") from None


REF_FIELD = {W.AckCmd: "alert", W.SilenceCmd: "id", W.UnsilenceCmd: "id", W.SetCmd: "key", W.ConfirmCmd: "mission",
             W.CffCmd: "cff", W.DecideCmd: "alert", W.InhibitCmd: "id", W.UninhibitCmd: "id"}


def result(cmd, ok: bool, t: float, error: str = "") -> W.CmdResult:
    ref = getattr(cmd, REF_FIELD.get(type(cmd), ""), "")
    return W.make(W.CmdResult, req=cmd.req, kind=KIND_OF.get(type(cmd), "?"), ok=ok, error=error[:1000],
                  t=max(0.0, min(float(t), W.T_LIMIT)), ref=ref[:128] if isinstance(ref, str) else "")


def to_dict(res: W.CmdResult) -> dict:
    return {f: getattr(res, f) for f in res.__struct_fields__}


# -- in process ----------------------------------------------------------------------------
def tap(ea) -> OrderedDict:
    """Remember the calls for fire `ea` sees (a `cff confirm` is built from one). Call it
    before messages arrive (the peer does, at start); idempotent."""
    book = _BOOKS.get(ea)
    if book is not None:
        return book
    book = _BOOKS[ea] = OrderedDict()
    inner, cff = ea._watch, M.CallForFire

    def watch(msg):
        if type(msg) is cff:
            book[msg.cff] = msg
            book.move_to_end(msg.cff)
            if len(book) > CFF_BOOK:
                book.popitem(last=False)
        return inner(msg)
    ea._watch = watch
    return book


def apply(ea, cmd, t: float | None = None) -> W.CmdResult:
    """Apply one command to an EA at scenario time `t` (default: the EA's latest time).
    Never raises for bad input: the answer says what was wrong and nothing changed.
    Any command arms repeats: a commander is in the loop."""
    t = ea.now if t is None else t
    book = tap(ea)
    ea.arm()
    try:
        k = type(cmd)
        if k is W.AckCmd:
            ea.ack(cmd.alert, t)
        elif k is W.SilenceCmd:
            ea.silence(cmd.id, cmd.types, cmd.subjects, cmd.areas, cmd.until_t, cmd.comment, t)
        elif k is W.UnsilenceCmd:
            ea.unsilence(cmd.id)
        elif k is W.SetCmd:
            ea.set_param(cmd.key, cmd.value, t)
            t = max(t, ea.epoch_end)   # the next epoch close
        elif k is W.ConfirmCmd:
            _confirm(ea, cmd, t)
        elif k is W.CffCmd:
            _cff(ea, book, cmd, t)
        elif k is W.DecideCmd:
            _decide(ea, cmd, t)
        elif k is W.InhibitCmd:
            ea.inhibit(rule_of(cmd))
        elif k is W.UninhibitCmd:
            ea.uninhibit(cmd.id)
        else:
            raise ValueError(f"not a command: {k.__name__}")
    except KeyError as e:
        return result(cmd, False, t, str(e.args[0] if e.args else e))
    except (ValueError, TypeError) as e:
        return result(cmd, False, t, str(e))
    return result(cmd, True, t)


def receive(ea, unit: str, root: str, gate: G.Gate, key: str, payload: bytes, t: float,
            clog=None, after: bool = False, taken=None) -> W.CmdResult | None:
    """A command off the wire for `unit`'s EA, as every peer takes one: its key (to this
    unit, a known kind, a sender), the gate (size, type, signature in secure mode), the
    sender's authority in the task organization as the EA knows it now (reorganizations
    included); applied at `t` and logged (`clog`). Returns the result to answer on
    cmdlog/<unit>, a refusal when the command's req can be read, else None (counted).
    `taken(kind, cmd, t)` is told of every command applied (a live peer journals it)."""
    prefix = f"{root}/cmd/"
    to, kind, by = (key[len(prefix):].split("/") + ["", "", ""])[:3] if key.startswith(prefix) else ("", "", "")
    cls = W.COMMANDS.get(kind)
    if to != unit or cls is None or not by:
        why = (f"not a command to {unit}" if to != unit else
               f"unknown command kind {kind[:32]!r}" if cls is None else "no sender unit in the key")
        gate.rejects.add(M.MessageError("cmd", "(key)", why), key)
        return refusal(payload, kind, why, gate.max_bytes, t)
    cmd = gate.control(cls, payload, key, signed=True)
    if cmd is None:
        return refusal(payload, kind, gate.rejects.recent[-1] if gate.rejects.recent else "bad", gate.max_bytes, t)
    refused = authority(getattr(ea.domain, "taskorg", None), by, unit)
    if refused is not None:
        gate.rejects.add(M.MessageError("cmd", "(authority)", refused), key)
        return result(cmd, False, t, refused)
    res = apply(ea, cmd, t)
    if taken is not None:
        taken(kind, cmd, t)
    if clog is not None:
        clog.write(unit, t, cmd, res, after)
    return res


def refusal(payload: bytes, kind: str, why: str, max_bytes: int, t: float) -> W.CmdResult | None:
    """ok=false for a command we cannot take, if its req can be read (else silence)."""
    if len(payload) > max_bytes:
        return None
    try:
        req = msgspec.msgpack.decode(payload).get("req")
    except Exception:   # anything undecodable: no req to answer
        return None
    if not isinstance(req, str) or not 1 <= len(req) <= 64:
        return None
    return W.make(W.CmdResult, req=req, kind=kind[:32], ok=False, error=why[:1000], t=t)


def rule_of(cmd: W.InhibitCmd) -> dict:
    """The rule an `inhibit` command carries, as a config table would give it."""
    def m(spec: W.MatcherSpec) -> dict:
        return {k: list(getattr(spec, k)) for k in ("types", "subjects", "priorities", "owners") if getattr(spec, k)}
    d = {"id": cmd.id, "source": m(cmd.source), "target": m(cmd.target), "equal": list(cmd.equal),
         "comment": cmd.comment}
    if cmd.for_s > 0:
        d["for_s"] = cmd.for_s
    return d


def _confirm(ea, cmd: W.ConfirmCmd, t: float) -> None:
    dom = ea.domain
    if not hasattr(dom, "on_confirm"):
        raise ValueError("confirm: this EA's domain takes no mission confirmations")
    m = getattr(dom, "missions", {}).get(cmd.mission)
    if m is None:
        raise KeyError(f"confirm: unknown mission {cmd.mission!r} (not in the EA's plan)")
    ea.submit(M.MissionConfirm(t, cmd.mission, m.unit, cmd.phase, "local"))


def _decide(ea, cmd: W.DecideCmd, t: float) -> None:
    """The commander's answer to an alert that asked for a decision: the EA's domain carries
    it out (abort the mission, execute a branch, continue); the alert counts as acknowledged."""
    a = next((x for x in reversed(ea.alerts) if x.details.get("id") == cmd.alert), None)
    if a is None:
        raise KeyError(f"decide: unknown alert {cmd.alert[:80]!r}: not issued by the EA of {ea.owner}")
    decide = getattr(ea.domain, "decide", None)
    if decide is None or "decision" not in a.details:
        raise ValueError(f"decide: alert {cmd.alert} asks for no decision")
    decide(a.details, cmd.option, t)
    try:
        ea.ack(cmd.alert, t)
    except KeyError:
        pass   # not repeating (no console armed repeats for it): nothing to stop


def _cff(ea, book: OrderedDict, cmd: W.CffCmd, t: float) -> None:
    c = book.get(cmd.cff)
    if c is None:
        raise KeyError(f"cff: unknown call for fire {cmd.cff!r} (not seen by the EA of {ea.owner}, or cancelled)")
    if cmd.action == "cancel":
        del book[cmd.cff]
        return
    ea.submit(M.CallForFireConfirm(t, c.cff, c.requester, c.lon, c.lat, c.radius_m))


# -- over the mesh ---------------------------------------------------------------------------
def authority(taskorg, by: str, unit: str) -> str | None:
    """Why the console of `by` may not command `unit`'s EA in the hierarchy as it is now
    (None: it may). A commander acts for their own unit and its subordinates; after a
    reorganization, the new superior does and the old one no longer does."""
    if by == unit:
        return None
    if taskorg is None or by not in taskorg.units:
        return f"the console of {by[:64]!r} does not command {unit} (not a unit above it)"
    above = taskorg.ancestors(unit)
    if by not in above:
        chain = "/".join([*reversed(above), unit])
        return f"the console of {by} does not command {unit} (its chain of command is now {chain})"
    return None


def by_of(identity: str, unit: str) -> str:
    """The unit a command is sent for: `console.<U>` sends as U (access control holds it
    to that); any other identity (the all-units `console`, open mode) as the unit itself."""
    return identity.removeprefix("console.") if identity.startswith("console.") else unit


def send(session, ks, unit: str, cmd, by: str, timeout: float = 10.0, signer=None) -> W.CmdResult:
    """Publish `cmd` to `unit`'s EA as the console of unit `by` and wait for its answer
    (same `req`). No answer in time (no EA peer, or access control dropped the command)
    is a failed result, not an error. `signer` (security.sign.signer_for, secure mode)
    signs it: the EA checks who sent it even through a router."""
    kind = KIND_OF[type(cmd)]
    end = time.monotonic() + timeout
    answers: queue.SimpleQueue = queue.SimpleQueue()
    gate = G.Gate(W.T_LIMIT)
    sub = session.declare_subscriber(ks.cmdlog(unit), lambda s: answers.put(s.payload.to_bytes()))
    key = ks.cmd(unit, kind, by)
    pub = session.declare_publisher(key, congestion_control=zenoh.CongestionControl.BLOCK)
    try:
        if not _wait_matching(pub, end):
            return result(cmd, False, 0.0, f"no EA of {unit} listening within {timeout:.0f} s")
        pub.put(W.encode(cmd) if signer is None else signer.sign(key, W.encode(cmd)))
        while (left := end - time.monotonic()) > 0:
            try:
                payload = answers.get(timeout=left)
            except queue.Empty:
                break
            res = gate.control(W.CmdResult, payload, ks.cmdlog(unit))
            if res is not None and res.req == cmd.req:
                return res
        return result(cmd, False, 0.0, f"no answer from the EA of {unit} within {timeout:.0f} s "
                                       f"(not running, or access control refused the command)")
    finally:
        pub.undeclare()
        sub.undeclare()


def _wait_matching(pub, end: float) -> bool:
    """Until some subscriber (the EA peer) matches the publisher, or `end`."""
    changes: queue.SimpleQueue = queue.SimpleQueue()
    listener = pub.declare_matching_listener(lambda st: changes.put(st.matching))
    try:
        ok = pub.matching_status.matching
        while not ok and (left := end - time.monotonic()) > 0:
            try:
                ok = changes.get(timeout=left)
            except queue.Empty:
                break
        return ok
    finally:
        listener.undeclare()
