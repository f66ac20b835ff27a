"""What leaves a live peer, and the promise it keeps: an alert once given is never given
twice, whatever rebuilds (a source back) and restarts (a process or host back) replay,
and nothing leaves before the input frames that caused it are on disk (a restart replays
them, so it stands where it stood and tells nobody anything twice).

Its alerts go to the alert log and the mesh; re-notifications and escalations to the
notice log and the mesh (signed in secure mode: they cross routers); results of commands
and directives to the command log and the mesh. `LivePeer` composes one; its EA's sinks
call it."""
from __future__ import annotations

from dataclasses import replace

import zenoh

from ..logs import cmdlog
from ..protocol import messages as M
from ..logs import noticelog
from ..protocol import wire as W
from ..logs.alertlog import AlertLog
from .journal import InputJournal

BLOCK = zenoh.CongestionControl.BLOCK


class Outputs:
    def __init__(self, ks, unit: str, out_path: str | None, fsync: str, journal: InputJournal | None, signer):
        self.ks, self.unit, self.journal, self.signer = ks, unit, journal, signer
        self.alog = AlertLog(out_path, fsync) if out_path else None
        self.nlog = noticelog.NoticeLog(noticelog.path_for(out_path)) if out_path else None
        self.clog = cmdlog.CommandLog(cmdlog.path_for(out_path)) if out_path else None
        self.session = None                   # the peer's, while it is on the mesh
        self.emitted: set[tuple] = set()      # (t, type, subjects, message) of every alert given and shown
        self.muted: set[tuple] = set()        # ... given inhibited
        self.given: list[M.Alert] = []        # every alert given, in order (the log's)
        self.late = 0                         # ... of them marked late

    def fresh(self, a: M.Alert, restoring: bool) -> bool:
        """Whether `a` is news: not given already (by the EA before a rebuild, or, while a
        restart replays the input journal, before the restart: then it stands as given).
        An alert given inhibited (never shown) that a rebuilt EA raises uninhibited is news."""
        key = (a.t, a.type, a.subjects, a.message)
        quiet = "inhibited_by" in a.details
        if key in self.emitted or quiet and key in self.muted:
            return False
        (self.muted if quiet else self.emitted).add(key)
        if restoring and self.alog is not None and self.alog.already(a):
            self.given.append(a)   # told before the restart: never twice
            return False
        return True

    def give(self, a: M.Alert, due: float | None) -> M.Alert:
        """Give a fresh alert (`due`: it fell due then and is raised late, so marked)."""
        if due is not None:
            a = replace(a, details={**a.details, "late": True, "due_from": round(due, 3)})
            self.late += 1
        self.given.append(a)
        self.inputs_on_disk()
        if self.alog:
            self.alog.write(a)
        if self.session is not None:
            self.session.put(self.ks.key(a, None, None), M.encode(a), congestion_control=BLOCK)
        return a

    def inputs_on_disk(self) -> None:
        """The input journal's buffered frames written out before anything they caused leaves
        the peer (an alert, a notice, a confirmation): a restart replays them and never tells
        it twice."""
        if self.journal is not None:
            self.journal.flush()

    def notice(self, n) -> None:
        """A re-notification or an escalation up the chain (`ea_agent/core/notify.py`)."""
        self.inputs_on_disk()
        if self.nlog:
            self.nlog(n)
        if self.session is not None:   # signed in secure mode: an escalation crosses the router
            key = self.ks.notice(n.to, n.owner)
            payload = W.encode(W.notice_of(n))
            self.session.put(key, payload if self.signer is None else self.signer.sign(key, payload),
                             congestion_control=BLOCK)

    def result(self, res) -> None:
        """A command's or a directive's result, on cmdlog/<unit> (the command log writes itself
        where the command is taken)."""
        if self.session is not None:
            self.session.put(self.ks.cmdlog(self.unit), W.encode(res), congestion_control=BLOCK)

    def close(self) -> None:
        for x in (self.alog, self.nlog, self.journal, self.clog):
            if x is not None:
                x.close()
