"""What an EA peer on the live mesh hears of a stream of messages: the source's key group of
each message (`groupframes.grouper`, as a source publishing by group gives it) against the
groups its interest subscribes to (`bygroup.GroupIntake.interest`, as `LivePeer` computes them),
re-registered every flush span (`source.GROUP_SPAN_S`) on the EA's own state at that time, as
a peer takes each flush once the release stands at its start."""
from __future__ import annotations

from dissemination.keyspace import KeySpace
from saim_mesh.live.bygroup import GroupIntake
from saim_mesh.live.groupframes import grouper, streams_of
from saim_mesh.live.source import GROUP_SPAN_S
from saim_mesh.inprocess.runner import config_for, make_ea

ROOT = "heard"


def by_live_groups(sc, msgs: list, owner: str, cfg: dict | None = None, span: float = GROUP_SPAN_S) -> list:
    """The messages (in time order) `owner`'s live peer takes from `msgs` published by group."""
    cfg = cfg if cfg is not None else config_for(sc, owner)
    ea = make_ea(sc, owner, cfg)
    ea.start(0.0)
    intake = GroupIntake(KeySpace.of(sc, ROOT), 1 << 20, None, print, streams=streams_of(sc, ROOT),
                         interest=cfg.get("dissemination", {}))
    group_of = grouper(sc, ROOT)
    out, at = [], 0.0
    intake.interest(ea.domain)
    for m in sorted(msgs, key=lambda m: m.t):
        while m.t > at + span:   # a new flush: the interest on what the EA knows at its start
            at += span
            ea.advance(at)
            intake.interest(ea.domain)
        if intake.hears(group_of(m)):
            ea.submit(m)
            out.append(m)
    return out
