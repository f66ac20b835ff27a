"""Let a main loop block until something comes, instead of polling Zenoh's channels.

A replay at max speed spends most of its time waiting for the slowest peer's ack. It
used to poll every half millisecond: two thousand wake-ups a second, each taking the
CPU from the EA peers it waits for (on two cores, about as much CPU as the peer's own
EA). An `Inbox` is a Zenoh callback handler that queues what comes and wakes a shared
`Waker`. A reader calls `try_recv`, which has the shape of a Zenoh channel's, so it
reads an inbox as it read the channel. The main loop sleeps in `Waker.wait` until an
ack, a peer's token, a store query or a live report arrives, or the timeout passes.
"""
from __future__ import annotations

import queue
from collections import deque


class Waker:
    """Zenoh's threads `wake` it; the main loop `wait`s on it."""

    def __init__(self):
        self._q: queue.SimpleQueue = queue.SimpleQueue()

    def wake(self) -> None:
        self._q.put(None)

    def wait(self, timeout: float) -> bool:
        """Block until something woke us since the last wait, or `timeout` seconds pass.
        True when woken. Every wake-up that came meanwhile is taken: one pass of the
        caller's loop serves them all."""
        try:
            self._q.get(timeout=max(0.0, timeout))
        except queue.Empty:
            return False
        while True:
            try:
                self._q.get_nowait()
            except queue.Empty:
                return True


class Inbox:
    """A bounded FIFO filled by a Zenoh callback (samples, liveliness changes or queries).
    When it is full, what comes next is dropped and counted: a flood cannot grow the
    reader's memory without bound."""

    def __init__(self, waker: Waker, cap: int):
        self.waker, self.cap = waker, cap
        self.q: deque = deque()
        self.dropped = 0
        self.decl = None   # the Zenoh declaration feeding us (kept alive by whoever declared it)

    def __call__(self, item) -> None:   # Zenoh's thread
        if len(self.q) >= self.cap:
            self.dropped += 1
            return
        self.q.append(item)
        self.waker.wake()

    def try_recv(self):
        """The oldest item, or None (as a Zenoh channel's `try_recv`)."""
        return self.q.popleft() if self.q else None
