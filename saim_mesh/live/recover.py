"""How a live peer recovers what an interruption cost it, from its input journal: a lost
source heard again (`rebuild`: a fresh EA, or the copy made at the loss, takes every input
since in event-time order as if the source had never been lost), and a restarted process
(`restart`: its journal replayed through a fresh EA, so it stands where it stood). The
peer decides when (`live/peer.py`); these take the journal again."""
from __future__ import annotations

import heapq

from ea_agent.core.alert import hms

from ..authority import commands as C
from ..authority import directives as D
from ..protocol import wire as W
from . import commanded
from .journal import records
from .order import EventTimeOrder


def rebuild(peer, source: str) -> None:
    """A lost source is heard again. Its facts since the loss cannot be put in order by
    the EA that went on without them, so a fresh EA takes every input journalled so far
    in event-time order as if the source had never been lost (the other losses stand),
    then waits for the source to catch up: what it raises that the old EA had not
    raised is given, marked late with when it was due; what both raised is not given
    again, and keeps its id (`ids.AlertIds`, shared by both). Alerts the old EA raised
    on the partial picture stay in the log (never withdrawn). A commander's commands to
    the old EA are journalled and taken again by the new one at their event time."""
    records = history(peer)
    since = peer.order.released
    peer.caught_up_to = max(peer.caught_up_to, peer.ea.now)
    peer._system(source, f"source {source} is back (its facts since {hms(since)} are taken late)",
                 event="source-back")
    peer.rebuilds += 1
    peer.rebuilding = source
    snap = peer.before_loss.take(source, records)
    if snap is not None:
        peer.ea, peer.order, peer.dirs.pending, peer.held_cmds = snap.ea, snap.order, snap.pending, snap.cmds
        start = snap.n + 1
        peer.log(f"source {source} back: EA rebuilt from its loss ({len(records) - start} records)", flush=True)
    else:   # from event time 0 (no copy: it could not be made, or the peer restarted since)
        peer.ea = peer.new_ea()
        peer.order = EventTimeOrder(peer.sources, max_buffered=peer._order_bound())
        peer.dirs.reset()
        peer.held_cmds = []
        start = 0
    lost_at = start - 1 if start else max((i for i, r in enumerate(records) if r[:2] == ["lost", source]),
                                          default=-1)
    peer.before_loss.forget_after(lost_at)   # losses while `source` was lost: taken again below
    waiting = peer.seq.hold.take_waiting()   # never journalled: offered again after the journal's frames
    returned = {source} | {r[1] for r in records if r[0] == "back"}
    try:
        for i in range(start, len(records)):
            rec = records[i]
            peer.at_record = i
            if rec[0] == "frame":
                peer.take(rec[1], "", journal=False)
            elif rec[0] == "dir":
                journalled_directive(peer, rec)
            elif rec[0] == "cmd":
                journalled_command(peer, rec)
            elif rec[0] == "lost" and rec[1] not in returned:
                peer.lose(rec[1], rec[3], journal=False)
    finally:
        peer.rebuilding, peer.at_record = None, None
        for src, q in waiting.items():
            for item in q:
                peer.seq.hold.wait(src, item)


def restart(peer) -> int:
    """A restarted peer (its host or process died): its input journal is replayed
    through the fresh EA first, so it stands where it stood; alerts its log holds were
    told already and are not given again, one the kill cut off before its log line is
    given now, marked late. Each source's sequence resumes after the last frame taken;
    what the sources sent meanwhile comes from their caches and journals, and what it
    raises up to their edge is marked late. Returns the records replayed."""
    if peer.journal is None or not peer.journal.path.exists():
        return 0
    recs = records(peer.journal.path)
    if not recs:
        return 0
    peer.history, peer.restoring = [], True
    try:
        for rec in recs:
            replay_record(peer, rec)
            peer.history.append(rec)
    finally:
        peer.history, peer.restoring, peer.at_record = None, False, None
    peer.restored = len(recs)
    peer.catching_up = True
    peer.log(f"restart: {len(recs)} input records replayed, EA at {hms(max(peer.ea.now, 0.0))}; "
             f"{len(peer.given)} alerts stand", flush=True)
    return len(recs)


def replay_record(peer, rec: list) -> None:
    """One input-journal record taken again, as the decision it records was taken live
    (a restart, or `journal.replay`: `history` holds the records before it); each
    source's sequence resumes after its frames."""
    peer.at_record = len(peer.history) if peer.history is not None else None
    if rec[0] == "frame":
        f = peer._frame(rec[1], "")
        if f is not None:
            peer.take(rec[1], "", journal=False, f=f)
            peer.seq.resume(f.source, f.epoch, f.seq + 1)
    elif rec[0] == "lost":
        peer.lose(rec[1], rec[3], journal=False)
    elif rec[0] == "dir":
        journalled_directive(peer, rec)
    elif rec[0] == "cmd":
        journalled_command(peer, rec)
    elif rec[0] == "peer":
        peer.peer_change(rec[1], rec[2])
    elif rec[0] == "back" and rec[1] in peer.order.lost and peer.rebuilding is None:
        rebuild(peer, rec[1])   # rebuilt where it was live (by key group: before the flush that brought it back)


def journalled_directive(peer, rec: list) -> None:
    """A directive as the input journal holds it (checked when it came): held again."""
    _, by, kind, body = rec
    d = D.decode(kind, body, 1 << 17)
    peer.dirs.reqs.add((by, d.req))
    commanded.hold(peer, D.Taken(by, d))


def journalled_command(peer, rec: list) -> None:
    """A commander's command as the input journal holds it (checked when it came):
    taken again at the event time it was taken, now if the EA is there (a restart),
    else when it gets there (a rebuilt EA behind it)."""
    _, t, kind, body = rec
    cls = W.COMMANDS.get(kind)
    if cls is None:   # a journal of another version: said, never a crash
        peer.log(f"input journal: unknown command kind {str(kind)[:32]!r} not taken again", flush=True)
        return
    cmd = W.decode_control(cls, body, peer.max_bytes)
    if t <= peer.ea.now:
        C.apply(peer.ea, cmd, t)
    else:
        peer._cmd_tie += 1
        heapq.heappush(peer.held_cmds, (t, peer._cmd_tie, kind, cmd))
        peer._apply()


def history(peer) -> list:
    """The input records so far (the journal's, flushed as written, or those a journal
    replay fed)."""
    if peer.history is not None:
        return list(peer.history)
    if peer.journal is None:
        raise RuntimeError("a live peer with no input journal cannot rebuild its EA when a source returns")
    return records(peer.journal.path)
