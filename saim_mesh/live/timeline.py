"""When, on the wall clock, a live peer got where: the instant each epoch boundary was
released and each alert raised. For benchmarks (a cut link's frozen epochs, alerts on time
against a fault-free run); one small object beside the peer's logic, never read by it."""
from __future__ import annotations

import math
import time


class Timeline:
    def __init__(self, epoch_s: float, limit: int = 20_000):
        self.epoch_s = epoch_s
        self.limit = limit
        self.epochs: list[float] = []      # wall time boundary (k + 1) * epoch_s was released, k = 0, 1, ...
        self.alerts: list[list] = []       # [t, type, subjects, wall time raised]

    def released(self, r: float) -> None:
        if not math.isfinite(r):
            return
        now = round(time.time(), 3)
        ep = self.epoch_s
        while (len(self.epochs) + 1) * ep <= r + 1e-9 and len(self.epochs) < self.limit:
            self.epochs.append(now)

    def raised(self, a) -> None:
        if len(self.alerts) < self.limit:
            self.alerts.append([a.t, a.type, list(a.subjects), round(time.time(), 3)])

    def as_dict(self) -> dict:
        return {"epoch_s": self.epoch_s, "epochs_wall": self.epochs, "alerts_wall": self.alerts}
