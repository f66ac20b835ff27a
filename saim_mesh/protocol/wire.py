"""Control messages of the mesh as typed, bounded msgspec structs, and the one place
where every payload a process receives is checked before use.

Data messages (positions, tracks, orders, alerts...) keep their validating decoder
in `messages.py`; the control messages between peers (a source's pace acks, bye)
and the commander's commands to an EA with its answers (docs/console.md
section 1) are here. Both go through `gate.Gate`
before use.
"""
from __future__ import annotations

from typing import Annotated, Literal

import msgspec

from . import messages as M

VERSION = 1
T_LIMIT = 1e9            # no scenario lasts 30 years: the outer bound of any time
SEQ_LIMIT = 2**53        # sequence numbers stay exact in every language that reads them
KEY_LIMIT = 512          # characters in one key expression (a signed envelope's key, a directive's)

Time = Annotated[float, msgspec.Meta(ge=0.0, le=T_LIMIT)]
Seq = Annotated[int, msgspec.Meta(ge=0, le=SEQ_LIMIT)]


class _Wire(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    v: Literal[1]    # required: a message without its version is not ours (build with `make`)


class Ack(_Wire, kw_only=True):
    """An EA has taken in a source's frames up to event time `t`: the source's pace
    (`saim_mesh/live/pace.py`, a source waits for its slowest EA)."""
    t: Time


class Bye(_Wire, kw_only=True):
    """A peer leaves cleanly: its liveliness DELETE is then no alarm."""
    unit: Annotated[str, msgspec.Meta(min_length=1, max_length=128)]


# -- the commander's console: commands to one unit's EA and its answer (docs/console.md 1)
Req = Annotated[str, msgspec.Meta(min_length=1, max_length=64)]
Name = Annotated[str, msgspec.Meta(min_length=1, max_length=128)]
Names = Annotated[list[Name], msgspec.Meta(max_length=64)]
Comment = Annotated[str, msgspec.Meta(max_length=512)]
Number = float | int


class AckCmd(_Wire, kw_only=True):
    """Acknowledge an alert (by its id, `<owner>/<n>`): its repeats stop."""
    req: Req
    alert: Name
    by: Annotated[str, msgspec.Meta(max_length=128)] = ""


class SilenceCmd(_Wire, kw_only=True):
    """Mark alerts matching every non-empty list as silenced until scenario time `until_t`."""
    req: Req
    id: Name
    types: Names = []
    subjects: Names = []
    areas: Names = []
    until_t: Time
    comment: Comment = ""


class UnsilenceCmd(_Wire, kw_only=True):
    req: Req
    id: Name


class SetCmd(_Wire, kw_only=True):
    """Change a `voi.*` or `voa.*` threshold from the next epoch on."""
    req: Req
    key: Name
    value: Number | Annotated[list[float], msgspec.Meta(max_length=32)]


class ConfirmCmd(_Wire, kw_only=True):
    """The commander confirms that a mission started or ended (a local MissionConfirm)."""
    req: Req
    mission: Name
    phase: Literal["start", "end"]


class CffCmd(_Wire, kw_only=True):
    """Confirm or cancel a call for fire the EA has seen."""
    req: Req
    cff: Name
    action: Literal["confirm", "cancel"]


class DecideCmd(_Wire, kw_only=True):
    """Answer an alert that asks for a decision (`details.decision.options`): the EA carries it out."""
    req: Req
    alert: Name
    option: Name


class MatcherSpec(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """Which alerts an inhibition rule's source or target is: every non-empty list must match."""
    types: Names = []
    subjects: Names = []
    priorities: Annotated[list[Literal["flash", "immediate", "priority", "routine"]], msgspec.Meta(max_length=4)] = []
    owners: Names = []


class InhibitCmd(_Wire, kw_only=True):
    """Add (or replace) an inhibition rule: while a `source` alert is active (`for_s`, 0:
    the EA's voa.expiry_s), `target` alerts sharing the `equal` labels are inhibited."""
    req: Req
    id: Name
    source: MatcherSpec
    target: MatcherSpec
    equal: Annotated[list[Literal["subjects", "owner", "places", "category"]], msgspec.Meta(max_length=4)] = []
    for_s: Annotated[float, msgspec.Meta(ge=0.0, le=T_LIMIT)] = 0.0
    comment: Comment = ""


class UninhibitCmd(_Wire, kw_only=True):
    req: Req
    id: Name


class Notice(_Wire, kw_only=True):
    """A re-notification of an unacknowledged urgent alert, or its escalation to the
    superior (`ea_agent.core.notify.Notice`); published on notice/<to>/<owner>. Not an alert."""
    kind: Literal["renotify", "escalate"]
    t: Time
    owner: Name
    alert: Name
    story: Name
    type: Name
    priority: Literal["flash", "immediate", "priority", "routine"]
    subjects: Names
    message: Annotated[str, msgspec.Meta(max_length=2000)]
    count: Annotated[int, msgspec.Meta(ge=1, le=1000)]
    to: Name
    due_t: Time


def notice_of(n) -> Notice:
    """The wire form of an EA's notice (`ea_agent.core.notify.Notice`)."""
    return make(Notice, **n.to_json_dict())


class CmdResult(_Wire, kw_only=True):
    """The EA's answer to command `req`: `t` is the scenario time it took effect; `ref`
    what it was about (the alert acknowledged, the silence, mission, call for fire or
    setting), so a listener that did not send it (the TAK gateway) can act on it."""
    req: Req
    kind: Annotated[str, msgspec.Meta(max_length=32)]
    ok: bool
    error: Annotated[str, msgspec.Meta(max_length=1000)] = ""
    t: Time
    ref: Annotated[str, msgspec.Meta(max_length=128)] = ""


COMMANDS: dict[str, type] = {"ack": AckCmd, "silence": SilenceCmd, "unsilence": UnsilenceCmd, "set": SetCmd,
                             "confirm": ConfirmCmd, "cff": CffCmd, "decide": DecideCmd,
                             "inhibit": InhibitCmd, "uninhibit": UninhibitCmd}
CONTROL = (Ack, Bye, *COMMANDS.values(), CmdResult, Notice)
_DECODERS = {c: msgspec.msgpack.Decoder(c) for c in CONTROL}
KINDS = (frozenset(M.MESSAGE_TYPES) | {c.__name__.lower() for c in CONTROL}
         | {"signed", "directive"})   # what rejects are counted under ("signed": a forged or replayed
                                      # envelope; "directive": an order or confirmation refused)
# a signed envelope is a msgpack ext (security/sign.py): no message, control or batch is one
ENVELOPE_HEADS = frozenset(bytes([b]) for b in (0xC7, 0xC8, 0xC9, *range(0xD4, 0xD9)))
_ENCODER = msgspec.msgpack.Encoder()


def make(cls: type, **fields) -> msgspec.Struct:
    """A control message of this version."""
    return cls(v=VERSION, **fields)


def encode(msg: msgspec.Struct) -> bytes:
    return _ENCODER.encode(msg)


def decode_control(cls: type, data: bytes, max_bytes: int) -> msgspec.Struct:
    """Decode one control payload into `cls`; raises MessageError and nothing else."""
    name = cls.__name__.lower()
    if len(data) > max_bytes:
        raise M.MessageError(name, "(bytes)", f"{len(data)} bytes, over the {max_bytes} limit")
    try:
        return _DECODERS[cls].decode(data)
    except (msgspec.ValidationError, msgspec.DecodeError) as e:
        raise M.MessageError(name, "(message)", str(e)[:200]) from None
    except Exception as e:   # a decoder bug must not kill a peer either
        raise M.MessageError(name, "(message)", f"undecodable: {type(e).__name__}") from None
