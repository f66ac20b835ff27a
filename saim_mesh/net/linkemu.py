"""An emulated radio link: a user-space TCP proxy on loopback with one-way delay, loss
(as TCP shows it: a retransmission timeout and head-of-line blocking), an optional rate
limit, and cut/heal. `netem` is not in this kernel, and a proxy needs no root.

Each direction of each connection is a queue of chunks (<= CHUNK bytes) stamped with
the time they may be delivered; a writer task delivers them in order at that time."""
from __future__ import annotations

import asyncio
import collections
import math
import random
import threading

CHUNK = 1400          # bytes read at once: about one TCP segment
MIN_RTO = 0.2         # seconds: TCP's minimum retransmission timeout (Linux)
WINDOW = 4 << 20      # bytes queued per direction before the reader stops (TCP's window)
_EOF = b""            # queued after the last chunk: the peer closed its side
DIRECTIONS = ("up", "down")   # up: listen side -> target; down: target -> listen side


def _check_port(name: str, port: int, zero_ok: bool = False) -> int:
    if isinstance(port, bool) or not isinstance(port, int) or not (0 if zero_ok else 1) <= port <= 65535:
        raise ValueError(f"{name}: not a TCP port: {port!r} (expected an integer "
                         f"{0 if zero_ok else 1}..65535)")
    return port


class _Dir:
    """Counters of one direction, over all connections."""
    __slots__ = ("bytes", "chunks", "lost", "connections", "queued")

    def __init__(self) -> None:
        self.bytes = self.chunks = self.lost = self.connections = self.queued = 0

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in self.__slots__}


class Link:
    """Forwards 127.0.0.1:listen_port -> 127.0.0.1:target_port for any number of
    connections, each direction independently delayed, lossy and rate-limited.
    Runs its own asyncio loop in a thread: `start()`, `stop()`, `cut()`, `heal()`,
    `stats()` are called from any other thread."""

    def __init__(self, listen_port: int, target_port: int, delay_ms: float = 0.0, loss: float = 0.0,
                 rate_bps: float | None = None, seed: int = 0, window: int = WINDOW) -> None:
        _check_port("listen_port", listen_port, zero_ok=True)
        _check_port("target_port", target_port)
        if not isinstance(delay_ms, (int, float)) or not math.isfinite(delay_ms) or delay_ms < 0:
            raise ValueError(f"delay_ms: expected a finite number >= 0, not {delay_ms!r}")
        if not isinstance(loss, (int, float)) or not 0 <= loss < 1:
            raise ValueError(f"loss: expected a probability in [0, 1), not {loss!r}")
        if rate_bps is not None and (not isinstance(rate_bps, (int, float))
                                     or not math.isfinite(rate_bps) or rate_bps <= 0):
            raise ValueError(f"rate_bps: expected a finite number > 0 (bits per second) or None, "
                             f"not {rate_bps!r}")
        if not isinstance(window, int) or window < CHUNK:
            raise ValueError(f"window: expected an integer >= {CHUNK} bytes, not {window!r}")
        self.listen_port, self.target_port = listen_port, target_port
        self.delay, self.loss, self.rate_bps, self.seed = delay_ms / 1000.0, float(loss), rate_bps, seed
        self.rto = max(MIN_RTO, 2 * self.delay)
        self.window = window
        self.counters = {d: _Dir() for d in DIRECTIONS}
        self.cuts = 0
        self._rng = random.Random(seed)   # one stream per link: deterministic for one connection
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._server: asyncio.Server | None = None
        self._healed: asyncio.Event | None = None
        self._tasks: set[asyncio.Task] = set()
        self._writers: set[asyncio.StreamWriter] = set()

    # ---- control, from any thread -------------------------------------------------
    def start(self, timeout: float = 10.0) -> "Link":
        """Listen, then return (the actual port is `listen_port` afterwards)."""
        if self._thread is not None:
            raise RuntimeError("Link already started")
        ready: list = []
        started = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(ready, started),
                                        name=f"link-{self.listen_port}", daemon=True)
        self._thread.start()
        if not started.wait(timeout):
            raise TimeoutError(f"link on port {self.listen_port} did not start in {timeout} s")
        if ready and isinstance(ready[0], BaseException):
            self._thread.join(timeout)
            self._thread = None
            raise ready[0]
        return self

    def stop(self, timeout: float = 10.0) -> None:
        """Close the listener and every connection, stop the loop, join the thread."""
        if self._thread is None or self._loop is None:
            return
        try:
            asyncio.run_coroutine_threadsafe(self._shutdown(), self._loop).result(timeout)
        finally:
            self._loop.call_soon_threadsafe(self._loop.stop)
            self._thread.join(timeout)
            self._thread = None

    def cut(self) -> None:
        """Nothing moves either way until `heal()`; data is held, new connections wait."""
        self._call(self._set_cut, True)

    def heal(self) -> None:
        """Held data flows again, in order; connections accepted meanwhile reach the target."""
        self._call(self._set_cut, False)

    @property
    def is_cut(self) -> bool:
        return self._healed is not None and not self._healed.is_set()

    def stats(self) -> dict:
        """Settings, cut state and, per direction (`up`: listen side -> target, `down`: back),
        bytes and chunks delivered, chunks that waited a retransmission timeout (`lost`),
        connections opened that way, and bytes held now (`queued`)."""
        return {"listen": self.listen_port, "target": self.target_port,
                "delay_ms": self.delay * 1000, "loss": self.loss, "rate_bps": self.rate_bps,
                "seed": self.seed, "cut": self.is_cut, "cuts": self.cuts,
                **{d: self.counters[d].as_dict() for d in DIRECTIONS}}

    def __enter__(self) -> "Link":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def _call(self, fn, *args) -> None:
        if self._loop is None or self._thread is None:
            raise RuntimeError("Link not started")

        async def apply() -> None:
            fn(*args)
        asyncio.run_coroutine_threadsafe(apply(), self._loop).result(10.0)

    def _set_cut(self, cut: bool) -> None:
        assert self._healed is not None
        if cut and self._healed.is_set():
            self.cuts += 1
            self._healed.clear()
        elif not cut:
            self._healed.set()

    # ---- the loop's thread -----------------------------------------------------------
    def _run(self, ready: list, started: threading.Event) -> None:
        loop = self._loop = asyncio.new_event_loop()
        try:
            self._healed = asyncio.Event()
            self._healed.set()
            try:
                self._server = loop.run_until_complete(asyncio.start_server(
                    self._accept, "127.0.0.1", self.listen_port, reuse_address=True))
                self.listen_port = self._server.sockets[0].getsockname()[1]
                ready.append(True)
            except BaseException as err:   # handed to start(), raised there
                ready.append(err)
                return
            finally:
                started.set()
            loop.run_forever()
        finally:
            loop.close()

    async def _shutdown(self) -> None:
        if self._server is not None:
            self._server.close()
        for w in list(self._writers):
            w.transport.abort()
        for t in list(self._tasks):
            t.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)

    def _track(self, coro) -> asyncio.Task:
        t = asyncio.get_running_loop().create_task(coro)
        self._tasks.add(t)
        t.add_done_callback(self._tasks.discard)
        return t

    async def _accept(self, c_reader: asyncio.StreamReader, c_writer: asyncio.StreamWriter) -> None:
        """One client: reach the target (once healed), then pipe both ways until both end."""
        self._tasks.add(asyncio.current_task())   # cancelled by stop() too
        self._writers.add(c_writer)
        self.counters["up"].connections += 1
        assert self._healed is not None
        try:
            await self._healed.wait()   # black-holed while cut: the SYN does not get through
            try:
                t_reader, t_writer = await asyncio.open_connection("127.0.0.1", self.target_port)
            except OSError:
                return   # nothing listens at the target: the client sees its connection close
            self._writers.add(t_writer)
            self.counters["down"].connections += 1
            pipes = [self._track(_Pipe(self, "up", c_reader, t_writer).run()),
                     self._track(_Pipe(self, "down", t_reader, c_writer).run())]
            # both directions ended, or one failed (a reset): then both sides are closed
            await asyncio.wait(pipes, return_when=asyncio.FIRST_EXCEPTION)
            for p in pipes:
                p.cancel()
            await asyncio.gather(*pipes, return_exceptions=True)
            self._writers.discard(t_writer)
            t_writer.transport.abort()
        except asyncio.CancelledError:
            pass   # stop(): asyncio's server would log a cancelled handler as an error
        finally:
            self._writers.discard(c_writer)
            c_writer.transport.abort()
            self._tasks.discard(asyncio.current_task())


class _Pipe:
    """One direction of one connection: a reader stamps chunks with their delivery time,
    a writer delivers them in order at that time (and not while the link is cut)."""

    def __init__(self, link: Link, direction: str, reader: asyncio.StreamReader,
                 writer: asyncio.StreamWriter) -> None:
        self.link, self.c = link, link.counters[direction]
        self.reader, self.writer = reader, writer
        self.queue: collections.deque[tuple[float, bytes, bool]] = collections.deque()
        self.queued = 0
        self.more = asyncio.Event()    # the queue got a chunk
        self.space = asyncio.Event()   # the queue fell below the window
        self.space.set()
        self.last = 0.0                # delivery time of the previous chunk: order is kept
        self.free = 0.0                # when the rate-limited link is free to send again

    async def run(self) -> None:
        """Ends when the far side's close has been delivered; raises on a reset."""
        ends = [asyncio.ensure_future(self._read()), asyncio.ensure_future(self._write())]
        try:
            await asyncio.gather(*ends)
        finally:
            for e in ends:
                e.cancel()
            self.c.queued -= self.queued

    def _stamp(self, n: int, now: float) -> tuple[float, bool]:
        link = self.link
        if link.rate_bps:
            self.free = max(now, self.free) + n * 8 / link.rate_bps
            now = self.free
        lost = n > 0 and link.loss > 0 and link._rng.random() < link.loss
        t = max(now + link.delay + (link.rto if lost else 0.0), self.last)
        self.last = t
        return t, lost

    async def _read(self) -> None:
        healed = self.link._healed
        loop = asyncio.get_running_loop()
        while True:
            await healed.wait()    # cut: the sender's window fills, as with TCP
            await self.space.wait()
            data = await self.reader.read(CHUNK)
            t, lost = self._stamp(len(data), loop.time())
            self.queue.append((t, data, lost))
            self.queued += len(data)
            self.c.queued += len(data)
            if self.queued >= self.link.window:
                self.space.clear()
            self.more.set()
            if not data:
                return

    async def _write(self) -> None:
        healed = self.link._healed
        loop = asyncio.get_running_loop()
        w = self.writer
        while True:
            while not self.queue:
                self.more.clear()
                await self.more.wait()
            await healed.wait()
            t = self.queue[0][0]
            now = loop.time()
            if t > now:
                await asyncio.sleep(t - now)
                continue   # the link may have been cut meanwhile
            out, eof = [], False
            while self.queue and self.queue[0][0] <= now:
                _, data, lost = self.queue.popleft()
                if not data:
                    eof = True
                    break
                out.append(data)
                self.queued -= len(data)
                self.c.queued -= len(data)
                self.c.bytes += len(data)
                self.c.chunks += 1
                self.c.lost += lost
            if out:
                w.write(b"".join(out))
                await w.drain()
            if self.queued < self.link.window:
                self.space.set()
            if eof:
                if w.can_write_eof():
                    w.write_eof()
                return
