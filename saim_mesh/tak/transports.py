"""The TAK network side, with pytak: senders (UDP multicast SA, TCP or TLS streams to a
TAK server) and listeners (UDP multicast or unicast, a TCP port), all in one asyncio loop
on its own thread, fed from the gateway's thread through bounded queues.

pytak makes the sockets (`protocol_factory`: its `udp://`, `tcp://`, `tls://` COT_URLs,
multicast membership and interface, the TLS client certificate from `PYTAK_TLS_*`) and
sends (`TXWorker.send_data`, which also turns XML into TAK protocol v1 with takproto when
`TAK_PROTO=1`: mesh framing on multicast, stream framing on TCP/TLS). A sender whose
peer is away reconnects with backoff; its queue keeps the newest events. Nothing a
listener receives can stop the loop: undecodable input is counted by the consumer."""
from __future__ import annotations

import asyncio
import threading
import warnings
from configparser import ConfigParser
from dataclasses import dataclass, field
from typing import Callable
from urllib.parse import urlparse

with warnings.catch_warnings():   # pytak warns at import about optional extras we do not use
    warnings.simplefilter("ignore")
    import pytak

from . import cot as C

MAX_QUEUE = 10_000
BACKOFF_S = (0.5, 30.0)


@dataclass
class TlsOptions:
    """The TLS client certificate for `tls://` COT_URLs (pytak's PYTAK_TLS_* settings)."""
    cert: str | None = None
    key: str | None = None
    ca: str | None = None
    password: str | None = None
    no_verify: bool = False
    no_hostname: bool = False
    server_name: str | None = None

    def settings(self) -> dict[str, str]:
        s = {"PYTAK_TLS_CLIENT_CERT": self.cert, "PYTAK_TLS_CLIENT_KEY": self.key,
             "PYTAK_TLS_CLIENT_CAFILE": self.ca, "PYTAK_TLS_CLIENT_PASSWORD": self.password,
             "PYTAK_TLS_SERVER_EXPECTED_HOSTNAME": self.server_name,
             "PYTAK_TLS_DONT_VERIFY": "1" if self.no_verify else None,
             "PYTAK_TLS_DONT_CHECK_HOSTNAME": "1" if self.no_hostname else None}
        return {k: v for k, v in s.items() if v}


def pytak_config(url: str, proto: str = "xml", mcast_if: str = "0.0.0.0", ttl: int = 1,
                 tls: TlsOptions | None = None):
    """A pytak configuration section for one COT_URL."""
    cp = ConfigParser(interpolation=None)
    cp["saim"] = {"COT_URL": url, "TAK_PROTO": "0" if proto == "xml" else "1",
                  "PYTAK_MULTICAST_LOCAL_ADDR": mcast_if, "PYTAK_MULTICAST_TTL": str(int(ttl)),
                  **(tls.settings() if tls else {})}
    return cp["saim"]


def check_url(url: str, listen: bool = False) -> str:
    """A COT_URL we can use: udp://, tcp:// or tls:// (listen: udp:// or tcp://) with host and port."""
    u = urlparse(url)
    base, _, _ = pytak.parse_cot_scheme(u.scheme)
    ok = ("udp", "tcp") if listen else ("udp", "tcp", "tls", "ssl")
    if base not in ok or not u.hostname or u.port is None:
        raise ValueError(f"{'listen' if listen else 'CoT'} URL {url!r}: expected "
                         f"{'|'.join(ok)}://HOST:PORT")
    return url


@dataclass
class Counters:
    sent: int = 0
    dropped: int = 0        # queue full: the oldest waiting event was dropped
    failed: int = 0         # a send that raised (the event is lost, the link reconnects)
    connects: int = 0
    last_error: str = ""


@dataclass
class _Sender:
    url: str
    config: object
    queue: asyncio.Queue
    n: Counters = field(default_factory=Counters)
    connected: asyncio.Event | None = None


class Network:
    """Senders and listeners on one asyncio loop (a daemon thread). `send` and `close`
    may be called from any thread; `on_data(data, source)` runs on the loop's thread."""

    def __init__(self, urls: list[str], proto: str = "xml", listen: list[str] = (), mcast_if: str = "0.0.0.0",
                 ttl: int = 1, tls: TlsOptions | None = None, on_data: Callable[[bytes, str], None] | None = None,
                 max_bytes: int = C.MAX_BYTES, max_queue: int = MAX_QUEUE, log: Callable = print,
                 hello: bytes | None = None):
        self.hello = hello    # sent first on every TCP/TLS connection: TAK servers take it as who we are
        self.urls = [check_url(u) for u in urls]
        self.listen_urls = [check_url(u, listen=True) for u in listen]
        self.proto, self.mcast_if, self.ttl, self.tls = proto, mcast_if, ttl, tls
        self.on_data = on_data or (lambda data, src: None)
        self.max_bytes, self.max_queue, self.log = max_bytes, max_queue, log
        self.loop = asyncio.new_event_loop()
        self.senders: list[_Sender] = []
        self.received = 0
        self.oversized = 0                     # stream events over max_bytes (their connection closed)
        self.listening: dict[str, str] = {}    # listen URL -> bound address
        self._servers: list = []
        self._tasks: list[asyncio.Task] = []
        self._conns: dict = {}                      # our TCP listeners' connections: writer -> task
        self._ready = threading.Event()
        self._error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, name="tak-network", daemon=True)

    # -- life cycle ------------------------------------------------------------------
    def start(self, timeout: float = 30.0) -> None:
        """Start the loop; returns once every listener is bound (their errors raise here)."""
        self.thread.start()
        if not self._ready.wait(timeout):
            raise TimeoutError("the TAK network loop did not start")
        if self._error is not None:
            raise self._error

    def _run(self) -> None:
        asyncio.set_event_loop(self.loop)
        try:
            self.loop.run_until_complete(self._setup())
        except BaseException as e:   # a listener that cannot bind: said by start()
            self._error = e
            self._ready.set()
            return
        self._ready.set()
        try:
            self.loop.run_forever()
        finally:
            self.loop.close()

    async def _setup(self) -> None:
        for url in self.urls:
            # udp:// alone would also bind a reader on the group that nobody reads (its queue grows)
            wo = "udp+wo://" + url.split("://", 1)[1] if urlparse(url).scheme == "udp" else url
            s = _Sender(url, pytak_config(wo, self.proto, self.mcast_if, self.ttl, self.tls),
                        asyncio.Queue(), connected=asyncio.Event())
            self.senders.append(s)
            self._tasks.append(asyncio.create_task(self._send_loop(s)))
        for url in self.listen_urls:
            await self._listen(url)

    def send(self, data: bytes) -> None:
        """Queue one event (XML bytes) for every sender (thread-safe, never blocks)."""
        if self.senders and not self.loop.is_closed():
            try:
                self.loop.call_soon_threadsafe(self._enqueue, data)
            except RuntimeError:   # the loop is closing
                pass

    def _enqueue(self, data: bytes) -> None:
        for s in self.senders:
            if s.queue.qsize() >= self.max_queue:
                s.queue.get_nowait()
                s.queue.task_done()
                s.n.dropped += 1
            s.queue.put_nowait(data)

    def flush(self, timeout: float = 10.0) -> bool:
        """Wait (bounded) until every queued event was handed to its socket."""
        if not self.thread.is_alive():
            return False

        async def all_sent():
            await asyncio.gather(*(s.queue.join() for s in self.senders))
        try:
            asyncio.run_coroutine_threadsafe(asyncio.wait_for(all_sent(), timeout), self.loop).result(timeout + 1)
            return True
        except Exception:   # timed out (a peer that is away): the rest is dropped
            return False

    def close(self, flush_s: float = 5.0) -> None:
        if not self.thread.is_alive():
            return
        if flush_s > 0:
            self.flush(flush_s)

        async def stop():
            for srv in self._servers:
                srv.close()
            for t in self._tasks:
                t.cancel()
            conns = list(self._conns.items())
            for w, _ in conns:   # closed, not cancelled: their readers end at EOF
                _close(w)
            if conns:
                await asyncio.wait([t for _, t in conns], timeout=5)
            await asyncio.gather(*self._tasks, return_exceptions=True)
        try:
            asyncio.run_coroutine_threadsafe(stop(), self.loop).result(10)
        except Exception:
            pass
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)

    def wait_connected(self, timeout: float = 30.0) -> bool:
        """Every sender has its socket (a TCP/TLS peer accepted us)."""
        async def all_up():
            await asyncio.gather(*(s.connected.wait() for s in self.senders))
        try:
            asyncio.run_coroutine_threadsafe(asyncio.wait_for(all_up(), timeout), self.loop).result(timeout + 1)
            return True
        except Exception:
            return False

    # -- senders ---------------------------------------------------------------------
    async def _send_loop(self, s: _Sender) -> None:
        backoff = BACKOFF_S[0]
        while True:
            writer = reader_task = None
            try:
                reader, writer = await pytak.protocol_factory(s.config)
                worker = pytak.TXWorker(s.queue, s.config, writer)
                s.n.connects += 1
                s.connected.set()
                backoff = BACKOFF_S[0]
                if not s.url.startswith("udp"):
                    if self.hello is not None:
                        await worker.send_data(self.hello)
                    if reader is not None:   # a TAK server sends us its clients' events: PLI in
                        reader_task = asyncio.create_task(self._read_stream(reader, s.url))
                while True:
                    data = await s.queue.get()
                    try:
                        await worker.send_data(data)
                        s.n.sent += 1
                    except Exception:
                        s.n.failed += 1
                        raise
                    finally:
                        s.queue.task_done()
                    if reader_task is not None and reader_task.done():
                        raise ConnectionError("the TAK server closed the connection")
            except asyncio.CancelledError:
                raise
            except Exception as e:   # refused, reset, TLS failure: said once per error, retried
                why = f"{type(e).__name__}: {e}"[:200]
                if why != s.n.last_error:
                    self.log(f"tak: {pytak.sanitize_url_credentials(s.url)}: {why}; retrying", flush=True)
                s.n.last_error = why
                s.connected.clear()
            finally:
                if reader_task is not None:
                    reader_task.cancel()
                _close(writer)
            await asyncio.sleep(backoff)   # a reconnect delay, not a synchronisation
            backoff = min(backoff * 2, BACKOFF_S[1])

    # -- listeners -------------------------------------------------------------------
    async def _listen(self, url: str) -> None:
        u = urlparse(url)
        if u.scheme.startswith("udp"):
            ro = urlparse(url.replace(u.scheme + "://", "udp+ro://", 1))
            reader, _ = await pytak.create_udp_client(ro, (self.mcast_if, 0), self.ttl)
            self.listening[url] = "%s:%d" % reader.sockname[:2]
            self._tasks.append(asyncio.create_task(self._read_datagrams(reader, url)))
        else:
            srv = await asyncio.start_server(lambda r, w: self._serve(r, w, url), u.hostname, u.port,
                                             limit=self.max_bytes)
            self._servers.append(srv)
            self.listening[url] = "%s:%d" % srv.sockets[0].getsockname()[:2]

    def _take(self, data: bytes, src: str) -> None:
        self.received += 1
        try:
            self.on_data(data, src)
        except Exception as e:   # the consumer's bug must not end the listener
            self.log(f"tak: input handler failed: {type(e).__name__}: {e}"[:200], flush=True)

    async def _read_datagrams(self, reader, url: str) -> None:
        while True:
            try:
                data, addr = await reader.recv()
            except asyncio.CancelledError:
                reader.close()
                raise
            except Exception as e:   # an ICMP error queued on the socket, a closed transport
                if isinstance(e, pytak.asyncio_dgram.TransportClosed):
                    return
                continue
            self._take(data, f"udp:{addr[0]}:{addr[1]}")

    async def _serve(self, reader: asyncio.StreamReader, writer, url: str) -> None:
        peer = writer.get_extra_info("peername")
        self._conns[writer] = asyncio.current_task()
        try:
            await self._read_stream(reader, f"tcp:{peer[0]}:{peer[1]}" if peer else url)
        finally:
            self._conns.pop(writer, None)
            _close(writer)

    async def _read_stream(self, reader: asyncio.StreamReader, src: str) -> None:  # noqa: C901
        """CoT events from a TCP stream: XML events one after another (split after
        `</event>`), or TAK protocol v1 stream framing (0xbf, varint length, message).
        An event over the size limit closes the connection (it cannot be resynchronised)."""
        while True:
            try:
                first = await reader.readexactly(1)
                if first[0] == C.STREAM:
                    head = first
                    while True:   # the varint length: at most 10 bytes
                        b = await reader.readexactly(1)
                        head += b
                        if not b[0] & 0x80 or len(head) > 11:
                            break
                    n = _varint(head[1:])
                    if n is None or n > self.max_bytes:
                        self.oversized += 1
                        return
                    data = head + await reader.readexactly(n)
                else:
                    data = first + await reader.readuntil(b"</event>")
            except asyncio.LimitOverrunError:
                self.oversized += 1
                return
            except (asyncio.IncompleteReadError, ConnectionError, OSError):
                return
            self._take(data.lstrip(), src)


def _varint(b: bytes) -> int | None:
    n = shift = 0
    for x in b:
        n |= (x & 0x7F) << shift
        if not x & 0x80:
            return n
        shift += 7
    return None


def _close(writer) -> None:
    if writer is None:
        return
    try:
        writer.close()
    except Exception:
        pass
