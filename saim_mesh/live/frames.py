"""A live source's frames: a batch of its data messages and its watermark, numbered
`(source, epoch, seq)`. Typed and bounded before use (`decode`), like every payload.

Why our own numbering when `zenoh.ext` numbers samples too: Zenoh's sequence numbers and
entity ids restart with the process; `epoch` (persisted, bumped at each start) and
`seq` let an EA tell a restarted source from a duplicate, and make its input journal
replayable (../shared/notes/live-mesh.md)."""
from __future__ import annotations

from typing import Annotated, Literal

import msgspec

from ..protocol import messages as M
from ..protocol import gate as G
from ..protocol import wire as W

MAX_MSGS = 1024   # data messages in one frame

Name = Annotated[str, msgspec.Meta(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.\-]+$")]


class Frame(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True, omit_defaults=True):
    """`msgs`: encoded data messages (messages.encode), each with its event time inside.
    `wm`: the source's watermark after this frame: nothing at or before it will follow.
    `end`: the source finished (its watermark is +inf from now on). `groups`: a source
    publishing by key group (`groupframes`): each message's group (its journal's frames,
    and the flushes an EA assembles); absent otherwise."""
    v: Literal[1]
    source: Name
    epoch: Annotated[int, msgspec.Meta(ge=0, le=2**62)]
    seq: Annotated[int, msgspec.Meta(ge=1, le=W.SEQ_LIMIT)]
    wm: Annotated[float, msgspec.Meta(ge=-1.0, le=W.T_LIMIT)]
    msgs: Annotated[list[bytes], msgspec.Meta(max_length=MAX_MSGS)] = []
    end: bool = False
    groups: Annotated[list[str], msgspec.Meta(max_length=MAX_MSGS)] | None = None


_ENC = msgspec.msgpack.Encoder()
_DEC = msgspec.msgpack.Decoder(Frame)


def encode(f: Frame) -> bytes:
    return _ENC.encode(f)


def decode(payload: bytes, max_bytes: int) -> Frame:
    """A frame, or MessageError naming what was wrong (size first, before decoding)."""
    if len(payload) > max_bytes:
        raise M.MessageError("frame", "(bytes)", f"{len(payload)} bytes, over the {max_bytes} limit")
    try:
        return _DEC.decode(payload)
    except (msgspec.ValidationError, msgspec.DecodeError) as e:
        raise M.MessageError("frame", "(decode)", str(e)[:160]) from None


class FrameReader:
    """For a reader of the live mesh that is not an EA (the console, the TAK gateway): each
    frame checked (size, decoding, the key it came on), its messages checked one by one as
    the EAs check them (a frame is trusted by its key: only source.<name> may put on
    src/<name>; its messages are not signed one by one), and a clock: the event time every
    source heard so far has promised, the end once each of them has ended."""

    def __init__(self, ks, gate: G.Gate, t_max: float, log=print):
        self.ks, self.gate = ks, gate
        self.data_gate = G.Gate(t_max, gate.max_bytes, log=log)
        self.data_gate.rejects = gate.rejects   # one count of what was refused
        self.wm: dict[str, float] = {}
        self.ended: set[str] = set()

    def read(self, key: str, payload: bytes) -> list | None:
        """The frame's messages (checked), or None when the frame itself is refused (counted).
        A source publishing by key group (`groupframes`): its group frames' messages, and
        its progress frames' watermarks."""
        src = self.ks.src("")
        if key.startswith(src) and "/" in key[len(src):]:
            return self._read_group(key, payload, key[len(src):].split("/", 1))
        try:
            f = decode(payload, self.gate.max_bytes)
        except M.MessageError as e:
            self.gate.rejects.add(e, key)
            return None
        if key != self.ks.src(f.source):
            self.gate.rejects.add(M.MessageError("frame", "source", f"frame of {f.source!r} on {key[:80]}"), key)
            return None
        self._promise(f.source, f.wm, f.end)
        return [m for b in f.msgs if (m := self.data_gate.data(b, key)) is not None]

    def _promise(self, source: str, wm: float, end: bool) -> None:
        self.wm[source] = max(self.wm.get(source, -1.0), wm)
        if end:
            self.ended.add(source)

    def _read_group(self, key: str, payload: bytes, name_rest: list[str]) -> list | None:
        from . import groupframes as GF
        name, rest = name_rest
        try:
            x = GF.decode_on(payload, key, name, rest, self.gate.max_bytes)
        except M.MessageError as e:
            self.gate.rejects.add(e, key)
            return None
        if rest == GF.PROGRESS:
            self._promise(x.source, x.wm, x.end)
            return []
        return [m for b in x.msgs if (m := self.data_gate.data(b, key)) is not None]

    def clock(self) -> tuple[float, bool]:
        """(event time promised by every source heard and not ended, whether all have ended)."""
        live = [w for s, w in self.wm.items() if s not in self.ended]
        if live:
            return min(live), False
        return max(self.wm.values(), default=0.0), bool(self.wm)
