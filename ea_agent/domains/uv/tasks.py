"""Task messages: a robot's EA's policy decisions, as its robot's controller takes them
(issue 33.5: robots obey their EAs; paper 7.4: the EA adjusts the robot's behaviour).

Each decision is a typed struct with the robot it is for, the event time `at` at which
the controller takes it and the EA's own count `n` ((at, n) orders them). `at` is the end
of the epoch the decision was taken in plus `LAG_S`, so it depends on the data only (the
same in process, on the mesh and when a journal is replayed), and once the EA has been
advanced to event time r it can promise that no task at or before r + LAG_S will follow:
the watermark of its task stream, on which the robot's clock waits (closed loop in event
time, no wall-clock race).

- `Pursue`: leave the patrol (suspended) and follow `target` inside `sector`;
- `Drop`: stop following `target` (a planned pursuit fails, the recipe goes on);
- `Resume`: resume the suspended patrol `mission`;
- `Handoff`: tell teammate `to` (an agent `delegate`) to take over `target`;
- `Accept`: accept `frm`'s delegation (an agent `accept`) and follow `target`.
"""
from __future__ import annotations

from typing import Annotated, Literal, Union

import msgspec

LAG_S = 0.5            # a decision taken at epoch end T is carried out at T + LAG_S (the robot's next step)
VERSION = 1

Id = Annotated[str, msgspec.Meta(min_length=1, max_length=64, pattern=r"^[A-Za-z0-9_.\-]+$")]
Mid = Annotated[str, msgspec.Meta(min_length=1, max_length=128)]
At = Annotated[float, msgspec.Meta(ge=0.0, le=1e9)]
Count = Annotated[int, msgspec.Meta(ge=1, le=2**53)]
Lon = Annotated[float, msgspec.Meta(ge=-180.0, le=180.0)]
Lat = Annotated[float, msgspec.Meta(ge=-90.0, le=90.0)]


class _Task(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True, tag_field="op"):
    robot: Id
    at: At
    n: Count

    def sort_key(self) -> tuple:
        return (self.at, self.n)


class Pursue(_Task, tag="pursue"):
    target: Id
    sector: Id
    mission: Mid                 # the EA's pursue mission
    lon: Lon | None = None       # where the target was last seen (sighting heard), if known
    lat: Lat | None = None


class Drop(_Task, tag="drop"):
    target: Id
    why: Literal["lost", "gone", "handoff"]
    mission: Mid


class Resume(_Task, tag="resume"):
    mission: Mid                 # the patrol resumed


class Handoff(_Task, tag="handoff"):
    target: Id
    to: Id
    task: Mid


class Accept(_Task, tag="accept"):
    target: Id
    frm: Id
    task: Mid
    sector: Id
    mission: Mid
    lon: Lon | None = None
    lat: Lat | None = None


Task = Union[Pursue, Drop, Resume, Handoff, Accept]
TYPES: tuple[type, ...] = (Pursue, Drop, Resume, Handoff, Accept)
OPS = tuple(c.__struct_config__.tag for c in TYPES)


class TaskFrame(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """What an EA publishes to its robot: tasks (in (at, n) order) and its promise `wm`:
    no task at or before `wm` will follow. `seq` counts frames from 1 (the robot takes them
    in sequence); `epoch` tells a restarted EA from a repeat."""
    v: Literal[1]
    robot: Id
    epoch: Annotated[int, msgspec.Meta(ge=0, le=2**62)]
    seq: Count
    wm: Annotated[float, msgspec.Meta(ge=-1.0, le=1e9)]
    tasks: Annotated[list[Task], msgspec.Meta(max_length=256)] = []
    end: bool = False


_ENC = msgspec.msgpack.Encoder()
_DEC = msgspec.msgpack.Decoder(TaskFrame)


class TaskError(ValueError):
    """A task frame refused: says why in one line."""


def encode(f: TaskFrame) -> bytes:
    return _ENC.encode(f)


def decode(payload: bytes, max_bytes: int = 1 << 16) -> TaskFrame:
    """A task frame, checked (size, types, bounds, every task for the frame's robot)."""
    if len(payload) > max_bytes:
        raise TaskError(f"task frame of {len(payload)} bytes, over the {max_bytes} limit")
    try:
        f = _DEC.decode(payload)
    except (msgspec.ValidationError, msgspec.DecodeError) as e:
        raise TaskError(f"task frame: {str(e)[:160]}") from None
    for t in f.tasks:
        if t.robot != f.robot:
            raise TaskError(f"task frame of {f.robot} carries a task for {t.robot}")
    return f
