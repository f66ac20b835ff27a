"""Alert ids that name one alert for ever within its EA.

An id is derived from what the alert says, not from how many came before it:
`<owner>/<whole second>.<digest>` (`<owner>/w<whole second>.<digest>` for a wall-clock-
driven system alert), the digest (16 bits, hex) over its type, subjects, priority, message
and event time: short enough to type in a TAK chat (`ack BN/942.8f85`). So an EA rebuilt from a copy taken before a source's loss, restarted from its input
journal or joining late gives the same alert the same id, and an alert the faulted run
adds (raised on a partial picture, a system problem) can never take a fault-free alert's
id, as a counter rewound with the copy did.

The registry is owned by whoever outlives a rebuild (the live peer) and shared with
every EA it builds: an id once issued for one alert is never issued for another. Two
different alerts with one second and digest take the next free `.k` suffix, in issue order; the same
alert raised again keeps its id."""
from __future__ import annotations

import hashlib
from typing import Any

from .alert import Alert


def signature(a: Alert) -> tuple:
    """What makes two alerts the same alert: never its marks (late, silenced, inhibited)."""
    return (a.type, tuple(sorted(a.subjects)), a.priority, a.message, round(float(a.t), 3))


def base_id(owner: str, a: Alert, wall: bool = False) -> str:
    sig = signature(a)
    h = hashlib.blake2b(repr(sig).encode(), digest_size=2).hexdigest()
    return f"{owner}/{'w' if wall else ''}{int(a.t)}.{h}"


class AlertIds:
    """Every id issued, and for which alert."""

    def __init__(self, owner: str):
        self.owner = owner
        self.issued: dict[str, tuple] = {}   # id -> the signature of the alert it names

    def issue(self, a: Alert, wall: bool = False) -> str:
        """The id of `a`: the one it had if it was issued before (a rebuild or a restart
        raising it again), else a new one no other alert ever had."""
        sig = signature(a)
        base = base_id(self.owner, a, wall)
        aid, k = base, 1
        while (had := self.issued.get(aid)) is not None and had != sig:
            aid, k = f"{base}.{k}", k + 1
        self.issued[aid] = sig
        return aid

    def __contains__(self, alert_id: Any) -> bool:
        return isinstance(alert_id, str) and alert_id in self.issued

    def __len__(self) -> int:
        return len(self.issued)

    def __deepcopy__(self, memo):   # shared by every copy of the EA: ids are never rewound
        return self
