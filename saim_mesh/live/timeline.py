"""When, on the wall clock, a live peer got where, and what it cost: the instant each
epoch boundary was released and each alert raised, the report-to-alert latencies live, and
the CPU of its loop. For benchmarks (a cut link's frozen epochs, alerts on time against a
fault-free run, `bench_live`, `bench_mesh`); one small object beside the peer's logic,
told what happened and never read by it."""
from __future__ import annotations

import math
import time


class Timeline:
    def __init__(self, epoch_s: float, live_start: float | None = None, limit: int = 20_000):
        self.epoch_s = epoch_s
        self.live_start = live_start       # wall time of event time 0 (live), else None
        self.limit = limit
        self.epochs: list[float] = []      # wall time boundary (k + 1) * epoch_s was released, k = 0, 1, ...
        self.alerts: list[list] = []       # [t, type, subjects, wall time raised]
        self.alert_lat: list[float] = []   # live: wall seconds from its epoch's close to an alert's raising
        self.due_lat: list[float] = []     # ... and from the alert's own event time
        self.t0 = time.monotonic()
        self.cpu0 = (time.thread_time(), time.process_time())
        self.cpu_first: float | None = None   # the loop's thread CPU when it first released a fact

    def released(self, r: float) -> None:
        if not math.isfinite(r):
            return
        if self.cpu_first is None:
            self.cpu_first = time.thread_time()
        now = round(time.time(), 3)
        ep = self.epoch_s
        while (len(self.epochs) + 1) * ep <= r + 1e-9 and len(self.epochs) < self.limit:
            self.epochs.append(now)

    def raised(self, a) -> None:
        now = time.time()
        if len(self.alerts) < self.limit:
            self.alerts.append([a.t, a.type, list(a.subjects), round(now, 3)])
        if self.live_start is not None and not a.details.get("wall_clock_driven"):
            # live: from the close of the epoch the alert falls in (on event time, the earliest
            # it can be raised: an epoch closes once every source promised it) to its raising;
            # `due_lat` from the alert's own time (a timer due mid-epoch waits for the close)
            t, ep = now - self.live_start, self.epoch_s
            self.alert_lat.append(t - math.ceil(a.t / ep - 1e-9) * ep)
            self.due_lat.append(t - a.t)

    def summary(self) -> dict:
        return {"alert_latencies_ms": [round(1000 * x, 2) for x in self.alert_lat[:5000]],
                "due_latencies_ms": [round(1000 * x, 2) for x in self.due_lat[:5000]],
                "wall_s": round(time.monotonic() - self.t0, 2),
                # CPU of the loop that decodes, orders and runs the EA, and of the whole process
                # (Zenoh's threads too): robust to this machine's varying share
                "thread_cpu_s": round(time.thread_time() - self.cpu0[0], 3),
                # of which before its first fact: opening the session (a TLS handshake in secure
                # mode), declarations, a restart's journal; a cost per peer, not per message
                "setup_thread_cpu_s": round((self.cpu_first or time.thread_time()) - self.cpu0[0], 3),
                "process_cpu_s": round(time.process_time() - self.cpu0[1], 3),
                "timeline": self.as_dict()}

    def as_dict(self) -> dict:
        return {"epoch_s": self.epoch_s, "epochs_wall": self.epochs, "alerts_wall": self.alerts}
