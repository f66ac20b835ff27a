"""The emulated radio link (saim_mesh/net/linkemu.py): plain sockets through it first,
then two Zenoh sessions (a router and a client) joined through it, then the process."""
from __future__ import annotations

import json
import random
import signal
import socket
import struct
import threading
import time

import pytest

from saim_mesh.net.linkemu import CHUNK, Link
from saim_mesh.launch.proc import Proc, clean_env, py
from saim_mesh.launch.zenoh_config import free_port

from .conftest import wait_until

pytestmark = pytest.mark.timeout(120)


class Sink:
    """A TCP server on loopback that keeps what each connection sends (and echoes it when
    asked), one thread per connection; `close()` reaps them all."""

    def __init__(self, echo: bool = False, reply: bytes = b"") -> None:
        self.echo, self.reply = echo, reply
        self.srv = socket.create_server(("127.0.0.1", 0))
        self.port = self.srv.getsockname()[1]
        self.data: list[bytearray] = []
        self.eof: list[bool] = []
        self.lock = threading.Lock()
        self.threads: list[threading.Thread] = []
        self.conns: list[socket.socket] = []
        self._stop = False
        t = threading.Thread(target=self._accept, daemon=True)
        t.start()
        self.threads.append(t)

    def _accept(self) -> None:
        while not self._stop:
            try:
                c, _ = self.srv.accept()
            except OSError:
                return
            with self.lock:
                i = len(self.data)
                self.data.append(bytearray())
                self.eof.append(False)
                self.conns.append(c)
            t = threading.Thread(target=self._serve, args=(c, i), daemon=True)
            t.start()
            self.threads.append(t)

    def _serve(self, c: socket.socket, i: int) -> None:
        try:
            if self.reply:
                c.sendall(self.reply)
            while b := c.recv(65536):
                with self.lock:
                    self.data[i] += b
                if self.echo:
                    c.sendall(b)
        except OSError:
            pass
        with self.lock:
            self.eof[i] = True

    def received(self, i: int = 0) -> bytes:
        with self.lock:
            return bytes(self.data[i]) if i < len(self.data) else b""

    def close(self) -> None:
        self._stop = True
        self.srv.shutdown(socket.SHUT_RDWR)   # wakes the thread blocked in accept()
        self.srv.close()
        for c in self.conns:
            try:
                c.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            c.close()
        for t in self.threads:
            t.join(5)
        assert not any(t.is_alive() for t in self.threads)


@pytest.fixture
def sink():
    s = Sink()
    yield s
    s.close()


def recv_exactly(c: socket.socket, n: int, timeout: float = 10.0) -> bytes:
    c.settimeout(timeout)
    buf = bytearray()
    while len(buf) < n:
        b = c.recv(n - len(buf))
        if not b:
            break
        buf += b
    return bytes(buf)


def test_round_trip_takes_at_least_twice_the_delay():
    echo = Sink(echo=True)
    try:
        with Link(free_port(), echo.port, delay_ms=100) as link, \
                socket.create_connection(("127.0.0.1", link.listen_port)) as c:
            for _ in range(3):
                t0 = time.monotonic()
                c.sendall(b"ping")
                assert recv_exactly(c, 4) == b"ping"
                rtt = time.monotonic() - t0
                assert 0.2 <= rtt < 5.0, rtt
            st = link.stats()
            assert st["up"]["bytes"] == st["down"]["bytes"] == 12
            assert st["up"]["lost"] == st["down"]["lost"] == 0
    finally:
        echo.close()


def test_lossy_stream_arrives_complete_in_order_and_loss_follows_the_seeded_rng(sink):
    """20k segments at 5 % loss: every byte arrives, in order; the proxy drew one number per
    chunk from random.Random(seed) (only this direction carried data), so its lost counter
    is exactly what that generator says for that many chunks."""
    n, seed = 20_000, 7
    payload = b"".join(struct.pack(">I", i) * (CHUNK // 4) for i in range(n))
    with Link(free_port(), sink.port, delay_ms=5, loss=0.05, seed=seed) as link:
        with socket.create_connection(("127.0.0.1", link.listen_port)) as c:
            c.sendall(payload)
        wait_until(lambda: sink.eof and sink.eof[0], 60, "the sink sees the end of the stream")
        st = link.stats()
    got = sink.received()
    assert len(got) == len(payload)
    assert got == payload   # complete and in order
    up = st["up"]
    assert up["bytes"] == len(payload) and up["chunks"] >= n and up["queued"] == 0
    rng = random.Random(seed)
    assert up["lost"] == sum(rng.random() < 0.05 for _ in range(up["chunks"]))
    assert abs(up["lost"] - 0.05 * up["chunks"]) < 5 * (up["chunks"] * 0.05 * 0.95) ** 0.5
    assert st["down"]["bytes"] == st["down"]["lost"] == 0


def test_cut_holds_data_and_connections_heal_delivers_them_in_order(sink):
    with Link(free_port(), sink.port, delay_ms=10) as link:
        a = socket.create_connection(("127.0.0.1", link.listen_port))
        closing = socket.create_connection(("127.0.0.1", link.listen_port))
        a.sendall(b"before|")
        closing.sendall(b"x")
        wait_until(lambda: sink.received(0) == b"before|" and sink.received(1) == b"x", 10,
                   "data before the cut is delivered")
        link.cut()
        assert link.stats()["cut"] and link.stats()["cuts"] == 1
        a.sendall(b"during-1|")
        closing.sendall(b"last words")
        closing.close()
        late = socket.create_connection(("127.0.0.1", link.listen_port))   # accepted, black-holed
        late.sendall(b"hello from the cut")
        a.sendall(b"during-2|")
        time.sleep(0.5)   # nothing may move while cut: watched over a window, not waited on
        assert sink.received(0) == b"before|" and sink.received(1) == b"x"
        assert len(sink.data) == 2 and not sink.eof[1]
        st = link.stats()
        assert st["up"]["connections"] == 3 and st["down"]["connections"] == 2
        link.heal()
        assert not link.stats()["cut"]
        wait_until(lambda: sink.received(0) == b"before|during-1|during-2|", 10, "held data flows, in order")
        wait_until(lambda: len(sink.data) == 3 and sink.received(2) == b"hello from the cut", 10,
                   "the black-holed connection reaches the target")
        wait_until(lambda: sink.eof[1], 10, "a close made during the cut reaches the other side")
        assert sink.received(1) == b"xlast words"
        a.close()
        late.close()
        wait_until(lambda: all(sink.eof), 10, "every connection closed")
        assert link.stats()["down"]["connections"] == 3


def test_byte_counters_equal_the_bytes_sent_per_direction():
    reply = bytes(range(256)) * 300           # 76,800 bytes down
    srv = Sink(reply=reply)
    try:
        with Link(free_port(), srv.port, delay_ms=2, loss=0.02, seed=3) as link:
            sent = 0
            with socket.create_connection(("127.0.0.1", link.listen_port)) as c:
                assert recv_exactly(c, len(reply)) == reply
                for i in range(50):
                    msg = bytes([i]) * (100 + 37 * i)
                    c.sendall(msg)
                    sent += len(msg)
            wait_until(lambda: srv.eof and srv.eof[0], 10, "the server sees the close")
            st = link.stats()
        assert srv.received() == b"".join(bytes([i]) * (100 + 37 * i) for i in range(50))
        assert st["up"]["bytes"] == sent and st["down"]["bytes"] == len(reply)
        assert st["up"]["connections"] == st["down"]["connections"] == 1
        assert st["down"]["chunks"] >= len(reply) // CHUNK
        for d in ("up", "down"):
            assert 0 <= st[d]["lost"] <= st[d]["chunks"] and st[d]["queued"] == 0
    finally:
        srv.close()


def test_rate_limit_paces_the_stream(sink):
    data = b"r" * 50_000                        # 400 kbit at 800 kbit/s: at least 0.5 s
    with Link(free_port(), sink.port, rate_bps=800_000) as link:
        t0 = time.monotonic()
        with socket.create_connection(("127.0.0.1", link.listen_port)) as c:
            c.sendall(data)
        wait_until(lambda: len(sink.received()) == len(data), 30, "the stream arrives")
        assert time.monotonic() - t0 >= 0.5


@pytest.mark.parametrize("kw, word", [
    (dict(delay_ms=-1), "delay_ms"), (dict(loss=1.0), "loss"), (dict(loss=-0.1), "loss"),
    (dict(rate_bps=0), "rate_bps"), (dict(target_port=70000), "target_port"),
    (dict(listen_port="x"), "listen_port")])
def test_bad_arguments_are_named(kw, word):
    args = dict(listen_port=0, target_port=7447) | kw
    with pytest.raises(ValueError, match=word):
        Link(**args)


def test_a_port_in_use_is_an_error_from_start(sink):
    with pytest.raises(OSError):
        Link(sink.port, free_port()).start()


def test_the_process_cuts_heals_and_exits_with_stats(sink, tmp_path):
    stats = tmp_path / "link.json"
    p = Proc("link", [*py(), "link", "--listen", "0", "--to", str(sink.port), "--delay-ms", "10",
                      "--loss", "0.01", "--seed", "5", "--stats", str(stats)], env=clean_env(),
             log_dir=tmp_path)
    try:
        port = int(p.wait_for("link ready", 30).split()[2])
        with socket.create_connection(("127.0.0.1", port)) as c:
            c.sendall(b"one|")
            wait_until(lambda: sink.received() == b"one|", 10, "data through the process")
            p.p.send_signal(signal.SIGUSR1)
            p.wait_for("link cut", 10)
            assert json.loads(stats.read_text())["cut"] is True
            c.sendall(b"two|")
            time.sleep(0.3)   # watched for a window: nothing may arrive while cut
            assert sink.received() == b"one|"
            p.p.send_signal(signal.SIGUSR2)
            p.wait_for("link heal", 10)
            wait_until(lambda: sink.received() == b"one|two|", 10, "held data after heal")
            assert json.loads(stats.read_text())["cut"] is False
        p.p.send_signal(signal.SIGTERM)
        assert p.p.wait(10) == 0
        final = json.loads(p.wait_for("stats ", 5)[len("stats "):])
        assert final["up"]["bytes"] == 8 and final["cuts"] == 1
        assert json.loads(stats.read_text()) == final
    finally:
        p.stop()


@pytest.mark.parametrize("args, word", [
    (["--listen", "0", "--to", "70000"], "--to"), (["--listen", "abc", "--to", "7447"], "--listen"),
    (["--listen", "0", "--to", "7447", "--delay-ms", "-5"], "--delay-ms"),
    (["--listen", "0", "--to", "7447", "--loss", "1"], "--loss")])
def test_the_process_rejects_bad_arguments(args, word, capsys):
    from saim_mesh.cli import main
    with pytest.raises(SystemExit) as e:
        main(["link", *args])
    assert e.value.code == 2
    assert word in capsys.readouterr().err


# ---- real Zenoh through the link: a router and a client, as a radio link joins them ----
LEASE_MS = 2000


def zconf(mode: str, listen: str | None = None, connect: str | None = None):
    """Loopback only, no multicast, no shared memory (it would bypass the link), a 2 s lease.
    A client retries its router every second at most, so it is back soon after a heal."""
    import zenoh
    c = zenoh.Config()
    c.insert_json5("mode", json.dumps(mode))
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("transport/shared_memory/enabled", "false")
    c.insert_json5("transport/link/tx/lease", str(LEASE_MS))
    if listen:
        c.insert_json5("listen/endpoints", json.dumps([listen]))
    if connect:
        c.insert_json5("connect/endpoints", json.dumps([connect]))
        c.insert_json5("connect/retry", "{period_init_ms: 500, period_max_ms: 1000, period_increase_factor: 2}")
    return c


def drain(sub, until, timeout: float, what: str) -> list:
    """Samples from a channel subscriber until `until(samples)` holds, within a deadline."""
    got: list = []
    end = time.monotonic() + timeout
    while not until(got):
        if time.monotonic() > end:
            raise AssertionError(f"within {timeout} s: {what}; got {len(got)}")
        s = sub.try_recv()
        if s is None:
            time.sleep(0.005)
        else:
            got.append(s)
    return got


def publish_and_check(pub, sub, n: int, start: int = 0, timeout: float = 60.0) -> None:
    """n numbered messages, BLOCK: every one arrives once, in order."""
    for i in range(start, start + n):
        pub.put(struct.pack(">I", i))
    got = drain(sub, lambda g: len(g) >= n, timeout, f"{n} messages through the link")
    assert [struct.unpack(">I", s.payload.to_bytes())[0] for s in got] == list(range(start, start + n))


@pytest.fixture
def zlink():
    """A router session and a client session joined through a 50 ms / 1 % link."""
    import zenoh
    rport = free_port()
    with Link(free_port(), rport, delay_ms=50, loss=0.01, seed=1) as link, \
            zenoh.open(zconf("router", listen=f"tcp/127.0.0.1:{rport}")) as router, \
            zenoh.open(zconf("client", connect=f"tcp/127.0.0.1:{link.listen_port}")) as client:
        yield link, router, client


def test_zenoh_pubsub_through_a_lossy_link_arrives_complete_in_order(zlink):
    import zenoh
    link, router, client = zlink
    sub = router.declare_subscriber("test/data", zenoh.handlers.FifoChannel(1000))
    pub = client.declare_publisher("test/data", congestion_control=zenoh.CongestionControl.BLOCK)
    wait_until(lambda: pub.matching_status.matching, 20, "the client's publisher sees the subscriber")
    publish_and_check(pub, sub, 500)
    st = link.stats()
    assert st["up"]["connections"] == st["down"]["connections"] == 1
    assert st["up"]["bytes"] > 500 * 4 and st["down"]["bytes"] > 0


def test_zenoh_reconnects_after_a_cut_longer_than_the_lease(zlink):
    """Cut for 4 leases: the router sees the client's token go (DELETE); after the heal the
    client reconnects by itself, the token is back (PUT) and pub/sub works again."""
    import zenoh
    link, router, client = zlink
    alive = router.liveliness().declare_subscriber("test/alive/**", zenoh.handlers.FifoChannel(100),
                                                   history=True)
    token = client.liveliness().declare_token("test/alive/client")
    sub = router.declare_subscriber("test/data", zenoh.handlers.FifoChannel(1000))
    pub = client.declare_publisher("test/data", congestion_control=zenoh.CongestionControl.BLOCK)
    kinds = lambda g: [(s.kind, str(s.key_expr)) for s in g]   # noqa: E731
    first = drain(alive, lambda g: len(g) >= 1, 20, "the client's token seen at the router")
    assert kinds(first) == [(zenoh.SampleKind.PUT, "test/alive/client")]
    wait_until(lambda: pub.matching_status.matching, 20, "the publisher sees the subscriber")
    publish_and_check(pub, sub, 50)

    link.cut()
    cut_at = time.monotonic()
    gone = drain(alive, lambda g: len(g) >= 1, 4 * LEASE_MS / 1000, "the token gone during the cut")
    assert kinds(gone) == [(zenoh.SampleKind.DELETE, "test/alive/client")]
    assert time.monotonic() - cut_at >= 0.5 * LEASE_MS / 1000   # the lease, not a closed socket
    time.sleep(max(0.0, cut_at + 4 * LEASE_MS / 1000 - time.monotonic()))   # the cut lasts 4 leases
    link.heal()
    back = drain(alive, lambda g: len(g) >= 1, 30, "the token back after the heal")
    assert kinds(back) == [(zenoh.SampleKind.PUT, "test/alive/client")]
    wait_until(lambda: pub.matching_status.matching, 20, "the publisher sees the subscriber again")
    publish_and_check(pub, sub, 50, start=1000)
    st = link.stats()
    assert st["cuts"] == 1 and st["up"]["connections"] >= 2   # Zenoh's own reconnect, through the link
    token.undeclare()
