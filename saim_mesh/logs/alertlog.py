"""A peer's alerts as an append-only, durable JSON-lines log.

Why: an alert once due is never lost. Each alert is written and flushed as it is
raised (and fsynced, per policy), so a peer killed at any moment keeps what it
raised; a restarted peer reads the log to know what it already told its
commander and raises, marked late, what fell while it was down.

fsync policies: "alert" (after every alert: survives a machine crash), "urgent"
(only after flash and immediate alerts), "never" (the OS decides; survives the
process dying, not the machine).
"""
from __future__ import annotations

import json
import os
from collections import Counter
from pathlib import Path

from ..protocol.messages import Alert
from .sinks import alert_line

FSYNC = ("alert", "urgent", "never")


def alert_key(d: dict) -> tuple:
    """What makes two alerts the same alert (details may carry run-specific notes)."""
    return (d["t"], d["owner"], d["type"], tuple(d["subjects"]), d["message"], d["priority"])


class AlertLog:
    def __init__(self, path: str | Path, fsync: str = "alert"):
        if fsync not in FSYNC:
            raise ValueError(f"fsync policy {fsync!r} not one of {', '.join(FSYNC)}")
        self.path, self.fsync = Path(path), fsync
        self.raised: Counter = Counter()   # alerts already in the log (before this run)
        self.repaired = 0                  # a half-written last line, cut off by a kill
        self._read_existing()
        self.f = open(self.path, "a", encoding="utf-8")

    def _read_existing(self) -> None:
        if not self.path.exists():
            return
        data = self.path.read_bytes()
        keep = data.rfind(b"\n") + 1
        if keep < len(data):           # killed in the middle of a line: that alert was not logged
            with open(self.path, "r+b") as f:
                f.truncate(keep)
            self.repaired = 1
        for line in data[:keep].decode("utf-8", "replace").splitlines():
            try:
                d = json.loads(line)
                self.raised[alert_key(d)] += 1
            except (ValueError, KeyError, TypeError):
                self.repaired += 1

    @property
    def restarted(self) -> bool:
        return bool(self.raised)

    def already(self, a: Alert) -> bool:
        """True (once per logged copy) when this alert is in the log from before."""
        k = (a.t, a.owner, a.type, tuple(a.subjects), a.message, a.priority)
        if self.raised[k] > 0:
            self.raised[k] -= 1
            return True
        return False

    def write(self, a: Alert) -> None:
        self.f.write(alert_line(a) + "\n")
        self.f.flush()
        if self.fsync == "alert" or (self.fsync == "urgent" and a.priority in ("flash", "immediate")):
            os.fsync(self.f.fileno())

    def close(self) -> None:
        self.f.close()
