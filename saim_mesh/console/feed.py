"""What feeds the console's state: the live mesh (a Zenoh session as `console.<U>`,
read by `live.reader.LiveReader`), or the EAs of an in-process run: alerts,
re-notifications and escalations (notices), command results, the clock and the data
messages it draws. Every mesh payload goes through `gate.Gate` and must fit the key it
came on; nothing received can stop the console (a bad payload is counted). No
liveliness token: the console only listens and sends commands."""
from __future__ import annotations

import threading
from typing import Callable

from ea_agent import domains

from ..protocol import messages
from ..protocol import wire
from ..live.reader import LiveReader
from .actions import CommandActions, result_dict
from .state import State

CLASSES = {"suo": (messages.LocationReport, messages.SensorTrack, messages.MissionConfirm, messages.CallForFire,
                   messages.CallForFireConfirm, messages.Order, messages.Reorganization),
           "uv": (messages.UvState, messages.UvSighting, messages.UvAgent)}


def classes_of(sc) -> tuple:
    """The data messages the console draws, for the scenario's domain."""
    return CLASSES.get(domains.of(sc).NAME, ())


class ConsoleView:
    """What a reader checked, into the console's state (a `live.reader.View`)."""

    def __init__(self, state: State):
        self.state = state

    def data(self, msgs: list) -> None:
        for m in msgs:
            self.state.message(m)

    def clock(self, t: float, end: bool, w: float | None = None) -> None:
        self.state.clock(t, end, w)

    def alert(self, m: messages.Alert) -> None:
        self.state.alert(m)

    def result(self, res: wire.CmdResult, owner: str) -> None:
        self.state.result(result_dict(res, owner))

    def notice(self, n: wire.Notice) -> None:
        d = {f: getattr(n, f) for f in n.__struct_fields__ if f != "v"}
        d["subjects"] = list(n.subjects)
        self.state.notice(d)


def live_feed(sc, conf, root: str, state: State, log: Callable = print) -> LiveReader:
    """The console on the mesh (no centre, no store): the data it draws comes in the
    sources' frames (`src/<name>`), each message checked as an EA checks it; its clock is
    the event time every source it has heard has promised (the minimum watermark), the
    end when every one of them has ended."""
    return LiveReader(sc, conf, root, classes_of(sc), ConsoleView(state), "console-live", log)


def mesh_actions(feed, state: State, timeout: float = 10.0) -> CommandActions:
    """Commands on the mesh through `feed` (a reader: its `.session`, `.ks`, `.conf`), sent
    as this console's unit (the EA checks it commands it); their results come back on
    cmdlog/<unit> to every console. Signed as this console's identity in secure mode.
    Orders and confirmations are directives (saim_mesh/authority/directives.py), published once,
    taken by every EA they concern."""
    from ..security.sign import signer_for
    signer = signer_for(feed.conf)

    def run(unit: str, cmd):
        from ..authority import commands
        return commands.send(feed.session, feed.ks, unit, cmd, state.unit, timeout, signer)

    def direct(unit: str, kind: str, fields: dict) -> str:
        from ..authority import directives
        return directives.publish(feed.session, feed.ks.root, signer, unit, kind, **fields).req
    return CommandActions(run, state, push=False, direct=direct)


def hook_inprocess(eas: list, sc, state: State) -> CommandActions:
    """Tie the state to in-process EAs: alerts from their sinks, messages and time from
    the first EA's input; commands applied under a lock the EAs' inputs also take, so a
    command never lands in the middle of an epoch."""
    lock = threading.RLock()
    by_owner = {ea.owner: ea for ea in eas}

    def guard(ea, name: str, before=None):
        inner = getattr(ea, name)

        def call(x, *a):
            if before is not None:
                before(x)
            with lock:
                return inner(x, *a)
        setattr(ea, name, call)

    def notice(n) -> None:
        state.notice(n.to_json_dict())

    for i, ea in enumerate(eas):
        ea.sinks.append(state.alert)
        ea.notice_sinks.append(notice)   # its own re-notifications and escalations (the runner routes
        #                                  escalations to a superior's EA run here; the page needs them once)
        first = i == 0
        guard(ea, "submit", (lambda m: (state.message(m), state.clock(m.t))) if first else None)
        guard(ea, "advance", state.clock if first else None)
        guard(ea, "finish", (lambda t: state.clock(t, end=True)) if first else None)

    def run(unit: str, cmd):
        from ..authority import commands
        with lock:
            return commands.apply(by_owner[unit], cmd)
    return CommandActions(run, state, push=True)


def serve_inprocess(eas: list, sc, port: int = 0):
    """(server, state) for an in-process run: the console over these EAs."""
    from .server import Server, make_app
    owners = [ea.owner for ea in eas]
    top = min(owners, key=lambda u: len(sc.taskorg.ancestors(u))) if owners else None
    state = State(sc, top, actors=owners)
    actions = hook_inprocess(eas, sc, state)
    server = Server(make_app(state, actions), port)
    server.start()
    return server, state
