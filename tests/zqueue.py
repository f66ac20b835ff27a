"""A queue fed by a Zenoh callback (the callback runs on a Python thread and never
blocks): tests wait on it with a bound instead of sleeping."""
from __future__ import annotations

import queue


class CallbackQueue:
    wait = 10.0   # default bound of a get, seconds

    def __init__(self):
        self.q: queue.Queue = queue.Queue()

    def __call__(self, x) -> None:
        self.q.put(x)

    def get(self, timeout: float | None = None):
        return self.q.get(timeout=self.wait if timeout is None else timeout)

    def drain(self) -> list:
        out = []
        while True:
            try:
                out.append(self.q.get_nowait())
            except queue.Empty:
                return out
