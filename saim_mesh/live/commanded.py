"""A commander's word on a live EA: directives (orders down, confirmations up) held until
the EA's event time reaches their `at`, commanders' commands taken at the EA's time and
answered, and what its EA infers of its own unit's missions confirmed up the chain.
Checked on the way in by `live/authority.py`; the peer calls these (`live/peer.py`)."""
from __future__ import annotations

import math

import zenoh

from ..authority import commands as C
from ..authority import directives as D
from ..protocol import messages as M
from ..protocol import wire as W


def confirm_up(peer, c) -> None:
    """Its EA inferred that one of its own unit's missions started (the unit crossed its
    line of departure): published up the chain once, as a confirmation signed by this
    EA, effective `CONFIRM_LEAD_S` later on an epoch's end (superiors that saw the
    crossing too have it by then). Not while a restart replays what was published before."""
    if c.unit != peer.unit or (c.mission, c.phase) in peer.confirmed_up:
        return
    peer.confirmed_up.add((c.mission, c.phase))
    if peer.restoring or peer.session is None:
        return
    peer.out.inputs_on_disk()
    at = math.ceil((c.t + D.CONFIRM_LEAD_S) / peer.ea.epoch_s) * peer.ea.epoch_s
    try:
        d = D.publish(peer.session, peer.ks.root, peer.signer, peer.unit, "confirm", at=at, mission=c.mission,
                      phase=c.phase)
    except (ValueError, zenoh.ZError) as e:   # never kills the peer: said, and the EA goes on
        peer.log(f"confirmation of {c.mission} {c.phase} not published: {e}", flush=True)
        return
    peer.log(f"confirmed up: {c.mission} {c.phase} at {at:.1f} (seen at {c.t:.1f}) req={d.req}", flush=True)


def directive(peer, key: str, payload: bytes) -> None:
    """A directive off the wire (or a late joiner's answer): checked, journalled, held
    until the EA's event time reaches its `at` (`_apply`), or taken at once, late."""
    got = peer.dirs.check(key, payload)
    if got is None:
        return
    tk, body = got
    if peer.journal is not None:
        peer.journal.directive(tk.by, D.KIND_OF[type(tk.d)], body)
    hold(peer, tk)


def hold(peer, tk: D.Taken) -> None:
    if tk.t <= peer.order.released:   # the EA is past it (cut off when it was issued): now, late
        take_directive(peer, tk, late=True)
    else:
        peer.dirs.hold(tk)
        peer._apply()


def take_directive(peer, tk: D.Taken, late: bool = False) -> None:
    due = tk.d.at
    if late:
        tk = D.at_least(tk, peer.ea.now)
    got = D.take(peer.ea, tk, peer.validate_plan)
    if got is None:
        return   # not for this EA
    ok, why = got
    if not ok:
        peer.gate.rejects.add(M.MessageError("directive", "(authority)", why), D.key(peer.ks.root, tk.by, "?"))
    res = D.result(tk, ok, tk.t, why, late, due)
    if peer.out.clog is not None:
        peer.out.clog.directive(peer.unit, tk, res)
    peer.out.result(res)
    peer.log(f"directive {res.kind} by {tk.by} at {tk.t:.1f} ok={ok}" + (f" error={res.error}" if res.error else ""),
             flush=True)


def serve_directives(peer, query) -> None:
    """A late joiner asks for the directives this EA took (each as it was received)."""
    try:
        query.reply(query.key_expr, D.wrap(peer.dirs.kept))
    except Exception as e:   # a bad query must not kill the peer
        peer.log(f"dirj: no answer to {str(query.key_expr)[:80]}: {e}", flush=True)


def joined(peer, payload: bytes) -> None:
    try:
        entries = D.unwrap(payload)
    except M.MessageError as e:
        peer.gate.rejects.add(e, peer.ks.root + "/dirj")
        return
    for k, p in entries:
        directive(peer, k, p)


def command(peer, key: str, payload: bytes) -> None:
    """A commander's command (docs/console.md 1), taken as every peer takes one
    (`commands.receive`) at the EA's time, answered on cmdlog/<unit>."""
    # taken after every fact at the EA's time (it advanced as far as its sources promised)
    res = C.receive(peer.ea, peer.unit, peer.ks.root, peer.cmd_gate, key, payload, peer.ea.now, peer.out.clog,
                    after=True, taken=lambda kind, cmd, t: journal_command(peer, kind, cmd, t))
    if res is None:
        return
    peer.out.result(res)
    peer.log(f"cmd {res.kind} req={res.req} ok={res.ok}" + (f" error={res.error}" if res.error else ""), flush=True)


def journal_command(peer, kind: str, cmd, t: float) -> None:
    if peer.journal is not None:
        peer.journal.command(t, kind, W.encode(cmd))
