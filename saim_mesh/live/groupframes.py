"""A live source's frames by key group (issue 50; docs/architecture.md, "Key groups on
the live mesh"): what a source puts on each group's stream and on its progress stream,
and how an EA puts a flush back together from the groups it hears. Pure: no Zenoh.

A source flushes as before (`LiveSource._send`: flush k, a watermark); with groups, flush
k goes out as one `GroupFrame` per group that got messages (`<root>/src/<name>/<group>`,
numbered per group) and one `Progress` (`<root>/src/<name>/_p`, numbered k as the flush):
its watermark, and for each group of the flush the group's seq. Each message keeps its
index in the flush, so that the flush an EA assembles from the groups it hears is today's
frame k less the groups it does not hear, in the same order: the event-time order's ties
(event time, source, epoch, k, index) come out as in the in-process run. The source's
journal keeps the whole flush (a `frames.Frame` with each message's group), for catch-up.

An EA's `Assembler` takes progress and group frames in any arrival order and gives flush k
once it holds, for every group of the progress frame it hears, that group's frame: it never
waits for a group it does not hear, and a heard group's frame that does not come is a gap
it sees (`missing`), filled from the publisher's cache or the source's journal (`fill`)."""
from __future__ import annotations

import struct
from typing import Annotated, Callable, Literal

import msgspec

from ..protocol import messages as M
from ..protocol import wire as W
from . import frames as F

PROGRESS = "_p"   # the progress stream's last chunk: no data family is called so
Group = Annotated[str, msgspec.Meta(min_length=1, max_length=512, pattern=r"^[^*$#?]+$")]


class _GroupHead(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True, array_like=True):
    """What a group frame is before its messages: shared by the frame in memory and as sent."""
    v: Literal[1]
    source: F.Name
    epoch: Annotated[int, msgspec.Meta(ge=0, le=2**62)]
    group: Group
    seq: Annotated[int, msgspec.Meta(ge=1, le=W.SEQ_LIMIT)]
    at: Annotated[int, msgspec.Meta(ge=1, le=W.SEQ_LIMIT)]
    idx: Annotated[list[int], msgspec.Meta(max_length=F.MAX_MSGS)] = []


class GroupFrame(_GroupHead, frozen=True, forbid_unknown_fields=True, kw_only=True, array_like=True):
    """One group's messages of flush `at`: `seq` numbers this group's frames; `idx` is each
    message's index in the flush. An array, not a map: a group frame is small and there are
    many (field names were a third of its bytes over a radio link)."""
    msgs: Annotated[list[bytes], msgspec.Meta(max_length=F.MAX_MSGS)] = []


class Progress(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True, array_like=True):
    """Flush `seq` of a source: its watermark and, per group that got messages in it, that
    group's frame seq."""
    v: Literal[1]
    source: F.Name
    epoch: Annotated[int, msgspec.Meta(ge=0, le=2**62)]
    seq: Annotated[int, msgspec.Meta(ge=1, le=W.SEQ_LIMIT)]
    wm: Annotated[float, msgspec.Meta(ge=-1.0, le=W.T_LIMIT)]
    last: Annotated[dict[Group, int], msgspec.Meta(max_length=F.MAX_MSGS)] = {}
    end: bool = False


# A position report (the bulk of a radio link) travels in a group frame as an array of ints,
# [t in 1/100 s, entity, lon and lat in 1e-7 degrees], not as its 71-byte map: a third of
# its size. Lossless or not at all: `_pack` sends the array only when `_unpack` of it gives
# back the very bytes the source encoded (the map's layout and the floats exactly), so
# every EA decodes what the in-process run's EA decodes; any other message goes as bytes.
_LOC_HEAD = b"\x86\xa4kind\xa8location\xa1v\x01\xa1t\xcb"
_LOC_ENT = b"\xa6entity"
_LOC_LON, _LOC_LAT = b"\xa3lon\xcb", b"\xa3lat\xcb"
_T_Q, _DEG_Q = 100, 10_000_000
_F64 = struct.Struct(">d")
Packed = tuple[Annotated[int, msgspec.Meta(ge=0, le=2**53)], Annotated[str, msgspec.Meta(min_length=1, max_length=31)],
               Annotated[int, msgspec.Meta(ge=-1_800_000_000, le=1_800_000_000)],
               Annotated[int, msgspec.Meta(ge=-900_000_000, le=900_000_000)]]


def _unpack(p) -> bytes:
    """The wire bytes of the position report an array stands for (`_pack`)."""
    t, e, lon, lat = p
    eb = e.encode()
    if len(eb) > 31:   # a name `_pack` never packs (its map would not have this layout)
        raise M.MessageError("group frame", "msgs", f"a packed position's entity of {len(eb)} bytes (at most 31)")
    return b"".join((_LOC_HEAD, _F64.pack(t / _T_Q), _LOC_ENT, bytes([0xA0 + len(eb)]), eb,
                     _LOC_LON, _F64.pack(lon / _DEG_Q), _LOC_LAT, _F64.pack(lat / _DEG_Q)))


def _pack(b: bytes):
    """A message's bytes, or a position report's array when it gives back these bytes."""
    n = len(_LOC_HEAD)
    if not b.startswith(_LOC_HEAD) or len(b) < n + 19:
        return b
    el = b[n + 15] - 0xA0
    if b[n + 8:n + 15] != _LOC_ENT or not 0 < el < 32 or len(b) != n + 16 + el + 26:
        return b
    try:
        e = b[n + 16:n + 16 + el].decode()
        t = _F64.unpack_from(b, n)[0]
        lon = _F64.unpack_from(b, n + 16 + el + 5)[0]
        lat = _F64.unpack_from(b, n + 16 + el + 18)[0]
        p = (round(t * _T_Q), e, round(lon * _DEG_Q), round(lat * _DEG_Q))
    except (UnicodeDecodeError, ValueError, OverflowError):   # not text, NaN or infinite: as bytes
        return b
    if not (0 <= p[0] <= 2**53 and abs(p[2]) <= 1_800_000_000 and abs(p[3]) <= 900_000_000) or _unpack(p) != b:
        return b
    return p


class _GroupWire(_GroupHead, frozen=True, forbid_unknown_fields=True, kw_only=True, array_like=True):
    """A `GroupFrame` as sent: each message its bytes or, a position report, its array."""
    msgs: Annotated[list[bytes | Packed], msgspec.Meta(max_length=F.MAX_MSGS)] = []


_ENC = msgspec.msgpack.Encoder()
_DEC_G = msgspec.msgpack.Decoder(_GroupWire)
_DEC_P = msgspec.msgpack.Decoder(Progress)


def encode(x: GroupFrame | Progress) -> bytes:
    if type(x) is GroupFrame:
        return _ENC.encode(_GroupWire(v=x.v, source=x.source, epoch=x.epoch, group=x.group, seq=x.seq, at=x.at,
                                      idx=x.idx, msgs=[_pack(b) for b in x.msgs]))
    return _ENC.encode(x)


def decode_group(payload: bytes, max_bytes: int) -> GroupFrame:
    return _decode(_DEC_G, payload, max_bytes, "group frame")


def decode_progress(payload: bytes, max_bytes: int) -> Progress:
    return _decode(_DEC_P, payload, max_bytes, "progress frame")


def decode_on(payload: bytes, key: str, name: str, rest: str, max_bytes: int) -> GroupFrame | Progress:
    """The progress frame (`rest` is PROGRESS) or group frame that came on source `name`'s
    stream `rest`, checked against that key; MessageError naming what was wrong."""
    x = decode_progress(payload, max_bytes) if rest == PROGRESS else decode_group(payload, max_bytes)
    if x.source != name or rest != PROGRESS and x.group != rest:
        raise M.MessageError("frame", "source", f"frame of {x.source!r} on {key[:80]}")
    return x


def _decode(dec, payload: bytes, max_bytes: int, what: str):
    if len(payload) > max_bytes:
        raise M.MessageError(what, "(bytes)", f"{len(payload)} bytes, over the {max_bytes} limit")
    try:
        x = dec.decode(payload)
    except (msgspec.ValidationError, msgspec.DecodeError) as e:
        raise M.MessageError(what, "(decode)", str(e)[:160]) from None
    if isinstance(x, _GroupWire):
        if len(x.idx) != len(x.msgs):
            raise M.MessageError(what, "idx", f"{len(x.idx)} indexes for {len(x.msgs)} messages")
        x = GroupFrame(v=x.v, source=x.source, epoch=x.epoch, group=x.group, seq=x.seq, at=x.at, idx=x.idx,
                       msgs=[b if type(b) is bytes else _unpack(b) for b in x.msgs])
    return x


def split(source: str, epoch: int, seq: int, wm: float, msgs: list[bytes], groups: list[str],
          group_seq: dict[str, int], end: bool = False) -> tuple[list[GroupFrame], Progress, F.Frame]:
    """Flush `seq` as its group frames (advancing `group_seq`, the source's per-group
    counters), its progress frame, and the whole flush for the journal."""
    by: dict[str, tuple[list[int], list[bytes]]] = {}
    for i, (b, g) in enumerate(zip(msgs, groups, strict=True)):
        ix, ms = by.setdefault(g, ([], []))
        ix.append(i)
        ms.append(b)
    out, last = [], {}
    for g in sorted(by):
        n = group_seq[g] = group_seq.get(g, 0) + 1
        last[g] = n
        out.append(GroupFrame(v=1, source=source, epoch=epoch, group=g, seq=n, at=seq, idx=by[g][0], msgs=by[g][1]))
    prog = Progress(v=1, source=source, epoch=epoch, seq=seq, wm=wm, last=last, end=end)
    whole = F.Frame(v=1, source=source, epoch=epoch, seq=seq, wm=wm, msgs=msgs, end=end, groups=list(groups))
    return out, prog, whole


class Assembler:
    """One source's flushes put back together from its progress frames and the group frames
    of the groups `hears(group)` says this EA hears. Progress frames are taken in their
    sequence (the caller's `Sequencer` orders them); group frames may come before or after
    theirs. `ready(p)` is flush p.seq as a `frames.Frame` once every heard group's frame of
    it is here, else None (`missing` says which)."""

    def __init__(self, hears: Callable[[str], bool]):
        self.hears = hears
        self.groups: dict[tuple[int, int, str], GroupFrame] = {}   # (epoch, flush, group) -> frame
        self.bytes = 0

    def group(self, gf: GroupFrame, size: int = 0) -> None:
        k = (gf.epoch, gf.at, gf.group)
        if k not in self.groups:
            self.groups[k] = gf
            self.bytes += size

    def missing(self, p: Progress) -> list[str]:
        """The heard groups of flush `p` whose frames are not here."""
        return [g for g in sorted(p.last) if self.hears(g) and (p.epoch, p.seq, g) not in self.groups]

    def ready(self, p: Progress) -> F.Frame | None:
        if self.missing(p):
            return None
        parts = [self.groups.pop((p.epoch, p.seq, g)) for g in sorted(p.last) if (p.epoch, p.seq, g) in self.groups
                 and self.hears(g)]
        for g in p.last:   # frames of groups it no longer hears: dropped with their flush
            self.groups.pop((p.epoch, p.seq, g), None)
        pairs = sorted((i, b, gf.group) for gf in parts for i, b in zip(gf.idx, gf.msgs))
        return F.Frame(v=1, source=p.source, epoch=p.epoch, seq=p.seq, wm=p.wm, msgs=[b for _, b, _ in pairs],
                       end=p.end, groups=[g for _, _, g in pairs])

    def fill(self, whole: F.Frame) -> F.Frame:
        """Flush `whole.seq` from the source's journal (a gap in a heard group): its heard
        groups' messages, as `ready` would give them."""
        for k in [k for k in self.groups if k[:2] == (whole.epoch, whole.seq)]:
            del self.groups[k]
        gs = whole.groups if whole.groups is not None else []
        keep = [(b, g) for b, g in zip(whole.msgs, gs) if self.hears(g)] if whole.groups is not None \
            else [(b, "") for b in whole.msgs]
        return F.Frame(v=1, source=whole.source, epoch=whole.epoch, seq=whole.seq, wm=whole.wm,
                       msgs=[b for b, _ in keep], end=whole.end, groups=[g for _, g in keep])

    def forget_before(self, epoch: int, seq: int) -> None:
        """Group frames of flushes before `seq` of `epoch` (taken, or of an old epoch): gone."""
        for k in [k for k in self.groups if k[0] < epoch or k[0] == epoch and k[1] < seq]:
            del self.groups[k]
        if not self.groups:
            self.bytes = 0


def data_templates() -> list[str]:
    """The key templates of every data message kind the application knows (not the alert)."""
    from ea_agent.core.messages import MESSAGE_TYPES
    return sorted({c.KEY for c in MESSAGE_TYPES.values() if getattr(c, "KEY", None) and c is not M.Alert})


def streams_of(sc, root: str):
    """The key groups of a scenario's mesh (`dissemination.streams`)."""
    from dissemination.streams import Streams
    return Streams.of(root, sc.taskorg, data_templates())


def grouper(sc, root: str) -> Callable[[object], str]:
    """A source's map of each message (in event-time order) to its key group: its key
    (`KeySpace.key`) cut to its group. Command paths are the organization as the source
    knows it at the message's time: the plan's reorganizations from their start, and the
    reorganizations it publishes (`docs/keyspace.md`, "Key groups")."""
    from dissemination.keyspace import KeySpace
    ks, streams = KeySpace.of(sc, root), streams_of(sc, root)
    to, proj = sc.taskorg.copy(), sc.projection
    plan = getattr(sc, "plan", None)
    reorgs = sorted((m.start.t, m.params["subject"], m.params["new_parent"]) for m in getattr(plan, "missions", ())
                    if m.type == "reorganize" and m.params.get("subject") in to.units
                    and m.params.get("new_parent") in to.units)

    def move(u: str, p: str) -> None:
        try:
            to.resubordinate(u, p)
        except (KeyError, ValueError):   # a reorganization the organization refuses: the EAs refuse it too
            pass

    def group(m) -> str:
        while reorgs and reorgs[0][0] <= m.t:
            move(*reorgs.pop(0)[1:])
        try:
            g = streams.group(ks.key(m, to, proj))
        except (ValueError, AttributeError):   # a kind with no key: its own group
            g = getattr(m, "KIND", "other")
        if type(m) is M.Reorganization:
            move(m.unit, m.new_parent)
        return g
    return group
