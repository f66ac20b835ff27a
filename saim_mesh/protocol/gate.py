"""The one place where every payload a process receives is checked before use: `Gate`,
a size bound before decoding, an exact version, times inside the scenario's clock, and a
`MessageError` (the project's own rejection) for everything else, so that no payload can
raise anything a peer does not expect; `Rejects` counts what it refused, per kind and per
sender, and says a flood once per threshold rather than once per payload."""
from __future__ import annotations

import time

from . import messages as M
from .wire import ENVELOPE_HEADS, KINDS, decode_control


FLOOD_THRESHOLDS = (100, 1_000, 10_000, 100_000, 1_000_000)   # refusals per sender that are said
MAX_SENDERS = 256      # senders counted by name (beyond: under "(others)")
_SENDER_CHUNK = {"src": 0, "srcj": 0, "dir": 0, "cmd": 2, "alert": 0, "notice": 1, "bye": 0,
                 "ack": 0, "cmdlog": 0}


def sender_of(key: str) -> str:
    """Who put a payload, as its key says (a source's name, a command's console unit, an
    EA's unit): `family/<name>`; the family alone for keys that name nobody."""
    parts = key.split("/")
    for i, p in enumerate(parts):
        c = _SENDER_CHUNK.get(p)
        if c is not None and i + 1 + c < len(parts):
            return f"{p}/{parts[i + 1 + c][:64]}"
    return "(unknown)" if not key else "(other keys)"


class Rejects:
    """Counts rejected payloads per kind and per sender (as its key names it) and logs each
    kind once with a sample, then a summary at most every `every_s` of wall time: a flood
    costs a counter, not a log. `on_flood(sender, n, kinds)` is called when a sender's
    refusals reach each of `FLOOD_THRESHOLDS` (the owner raises a system problem)."""

    def __init__(self, log=None, every_s: float = 10.0, sample_chars: int = 160, on_flood=None):
        self.log, self.every_s, self.sample_chars = log, every_s, sample_chars
        self.on_flood = on_flood
        self.by_kind: dict[str, int] = {}
        self.by_sender: dict[str, int] = {}
        self.kinds_of: dict[str, set[str]] = {}
        self.total = 0
        self.recent: list[str] = []
        self._said: dict[str, int] = {}
        self._next = 0.0

    def add(self, err: M.MessageError, key: str = "") -> None:
        self.total += 1
        kind = err.kind if err.kind in KINDS else "undecodable" if err.kind == "?" else "other"
        n = self.by_kind[kind] = self.by_kind.get(kind, 0) + 1
        self.recent = (self.recent + [str(err)[:self.sample_chars]])[-20:]
        who = sender_of(key)
        if who not in self.by_sender and len(self.by_sender) >= MAX_SENDERS:
            who = "(others)"
        ns = self.by_sender[who] = self.by_sender.get(who, 0) + 1
        ks = self.kinds_of.setdefault(who, set())
        if len(ks) < 16:
            ks.add(kind)
        if ns in FLOOD_THRESHOLDS and self.on_flood is not None:
            self.on_flood(who, ns, sorted(ks))
        if self.log is None:
            return
        if n == 1:
            self.log(f"reject {kind} on {key[:120]}: {str(err)[:self.sample_chars]}", flush=True)
            self._said[kind] = 1
            return
        now = time.monotonic()
        if now >= self._next:
            self._next = now + self.every_s
            new = {k: v - self._said.get(k, 0) for k, v in self.by_kind.items() if v > self._said.get(k, 0)}
            if new:
                self.log("rejects since last said: " + ", ".join(f"{k} {v}" for k, v in sorted(new.items())),
                         flush=True)
                self._said = dict(self.by_kind)


class Gate:
    """Every payload in: size bound, then typed decoding, then times inside the clock.

    `t_max` is the scenario's end: a message dated after it can only be a forgery or
    a fault, and holding it would cost memory until the end of time. `verifier`
    (security.sign.Verifier) opens signed envelopes (a msgpack ext, where a message is a
    map) and, in secure mode, refuses authority that comes unsigned; without one a signed
    envelope cannot be checked and is refused."""

    def __init__(self, t_max: float, max_bytes: int = 65536, log=None, verifier=None):
        self.t_max = float(t_max)
        self.verifier = verifier
        self.max_bytes = max_bytes
        self.rejects = Rejects(log)
        self.ok = 0

    def _bound(self, kind: str, t: float) -> None:
        if t > self.t_max:
            raise M.MessageError(kind, "t", f"{t} after the scenario's end ({self.t_max})")

    def data(self, payload: bytes | None, key: str = "") -> M.Message | None:
        """A data message, or None (counted) when it is bad."""
        try:
            if payload is None:
                raise M.MessageError("?", "(bytes)", "no payload")
            if len(payload) > self.max_bytes:
                raise M.MessageError("?", "(bytes)", f"{len(payload)} bytes, over the {self.max_bytes} limit")
            if payload[:1] in ENVELOPE_HEADS:
                signed_key, body = self._open(payload, key)
                m = M.decode(body)
                self.verifier.bind(signed_key, m)
            else:
                m = M.decode(payload)
                if self.verifier is not None:
                    self.verifier.unsigned(m)
            self._bound(m.KIND, m.t)
        except M.MessageError as e:
            self.rejects.add(e, key)
            return None
        self.ok += 1
        return m

    def data_many(self, payloads: list[bytes], key: str = "") -> list[M.Message]:
        """`data` for each of a frame's messages, the bad ones left out (counted): the same
        checks without a call per message (a frame carries up to a thousand); a signed one
        goes through `data`."""
        out: list[M.Message] = []
        append, decode, max_bytes, t_max = out.append, M.decode, self.max_bytes, self.t_max
        guarded = self.verifier.guarded if self.verifier is not None else ()
        slow = 0
        for b in payloads:
            if len(b) <= max_bytes and b[:1] not in ENVELOPE_HEADS:
                try:
                    m = decode(b)
                    if m.t > t_max:
                        self._bound(m.KIND, m.t)
                    if type(m) in guarded:
                        self.verifier.unsigned(m)
                except M.MessageError as e:
                    self.rejects.add(e, key)
                    continue
                append(m)
            elif (m := self.data(b, key)) is not None:   # counted there
                slow += 1
                append(m)
        self.ok += len(out) - slow
        return out

    def _open(self, payload: bytes, key: str) -> tuple[str, bytes]:
        if self.verifier is None:
            raise M.MessageError("signed", "(envelope)", "a signed message, and no signers' keys here to check it")
        return self.verifier.open(payload, key)

    def control(self, cls: type, payload: bytes | None, key: str = "", signed: bool = False):
        """A control message of type `cls`, or None (counted) when it is bad. `signed`
        (a command): an envelope is opened, and required in secure mode."""
        try:
            if payload is None:
                raise M.MessageError(cls.__name__.lower(), "(bytes)", "no payload")
            if signed and len(payload) <= self.max_bytes:
                if payload[:1] in ENVELOPE_HEADS:
                    _, payload = self._open(payload, key)
                elif self.verifier is not None and self.verifier.require:
                    raise M.MessageError(cls.__name__.lower(), "(signature)",
                                         "an unsigned command: commands must be signed in secure mode")
            m = decode_control(cls, payload, self.max_bytes)
            t = getattr(m, "t", None)
            if t is not None:
                self._bound(cls.__name__.lower(), t)
        except M.MessageError as e:
            self.rejects.add(e, key)
            return None
        self.ok += 1
        return m

    @property
    def errors(self) -> int:
        return self.rejects.total
