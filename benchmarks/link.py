"""How much the emulated radio link (`saim-mesh link`) can carry and what it costs:
forwarding throughput and the proxy process's CPU with no delay or loss, and one-way
latency percentiles at 50 ms / 1 % loss. Writes bench/results/link.json."""
from __future__ import annotations

import argparse
import json
import os
import signal
import socket
import struct
import tempfile
import threading
import time
from pathlib import Path

from saim_mesh.launch.proc import Proc, clean_env, py
from . import results

from . import RESULTS

OUT = RESULTS / "link.json"


def _cpu_s(pid: int) -> float:
    """User + system CPU seconds of a process, from /proc."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class _Sink:
    """Accepts one connection and hands every read to `on_data` on its own thread."""

    def __init__(self, on_data) -> None:
        self.srv = socket.create_server(("127.0.0.1", 0))
        self.port = self.srv.getsockname()[1]
        self.thread = threading.Thread(target=self._run, args=(on_data,), daemon=True)
        self.thread.start()

    def _run(self, on_data) -> None:
        c, _ = self.srv.accept()
        with c:
            while b := c.recv(1 << 16):
                on_data(b)

    def join(self, timeout: float) -> None:
        self.thread.join(timeout)
        self.srv.close()
        if self.thread.is_alive():
            raise TimeoutError("the sink did not see the end of the stream")


def _link(target: int, tmp: str, *args: str) -> tuple[Proc, int]:
    p = Proc("link", [*py(), "link", "--listen", "0", "--to", str(target), *args], env=clean_env(), log_dir=tmp)
    return p, int(p.wait_for("link ready", 30).split()[2])


def _stop(p: Proc) -> dict:
    p.p.send_signal(signal.SIGTERM)
    p.p.wait(30)
    return json.loads(p.wait_for("stats ", 5)[len("stats "):])


def throughput(mb: int, tmp: str) -> dict:
    """`mb` MB through the process at full speed; CPU of the proxy over the transfer."""
    got = [0]
    sink = _Sink(lambda b: got.__setitem__(0, got[0] + len(b)))
    p, port = _link(sink.port, tmp)
    try:
        block = b"\x5a" * (1 << 16)
        n = mb * (1 << 20) // len(block)
        cpu0, t0 = _cpu_s(p.pid), time.monotonic()
        with socket.create_connection(("127.0.0.1", port)) as c:
            for _ in range(n):
                c.sendall(block)
        sink.join(300)
        wall, cpu = time.monotonic() - t0, _cpu_s(p.pid) - cpu0
        stats = _stop(p)
    finally:
        p.stop()
    assert got[0] == n * len(block) == stats["up"]["bytes"], (got[0], stats["up"])
    return {"bytes": got[0], "wall_s": round(wall, 3), "mb_per_s": round(got[0] / wall / 1e6, 1),
            "proxy_cpu_s": round(cpu, 2), "proxy_cores": round(cpu / wall, 2),
            "proxy_cpu_s_per_gb": round(cpu / (got[0] / 1e9), 1), "chunks": stats["up"]["chunks"]}


def latency(n: int, rate: float, delay_ms: float, loss: float, tmp: str) -> dict:
    """n small timestamped messages at `rate`/s; one-way latency from CLOCK_MONOTONIC,
    which both ends share (one host)."""
    lat: list[float] = []
    buf = bytearray()

    def on_data(b: bytes) -> None:
        now = time.monotonic_ns()
        buf.extend(b)
        while len(buf) >= 64:
            lat.append((now - struct.unpack(">q", buf[:8])[0]) / 1e6)
            del buf[:64]

    sink = _Sink(on_data)
    p, port = _link(sink.port, tmp, "--delay-ms", str(delay_ms), "--loss", str(loss), "--seed", "1")
    try:
        with socket.create_connection(("127.0.0.1", port)) as c:
            c.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            start = time.monotonic()
            for i in range(n):
                time.sleep(max(0.0, start + i / rate - time.monotonic()))   # pacing, not synchronisation
                c.sendall(struct.pack(">q", time.monotonic_ns()).ljust(64, b"\0"))
        sink.join(60)
        stats = _stop(p)
    finally:
        p.stop()
    assert len(lat) == n, (len(lat), n)
    s = sorted(lat)
    pct = lambda q: round(s[min(n - 1, int(q * n))], 1)   # noqa: E731
    return {"messages": n, "rate_per_s": rate, "delay_ms": delay_ms, "loss": loss,
            "p50_ms": pct(0.50), "p90_ms": pct(0.90), "p99_ms": pct(0.99), "max_ms": round(s[-1], 1),
            "min_ms": round(s[0], 1), "lost_chunks": stats["up"]["lost"], "chunks": stats["up"]["chunks"]}


def main(argv: list[str] | None = None) -> int:
    a = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    a.add_argument("--mb", type=int, default=200, help="MB pushed for the throughput run")
    a.add_argument("--messages", type=int, default=3000, help="messages of the latency run")
    a.add_argument("--rate", type=float, default=100.0, help="messages/s of the latency run")
    a.add_argument("--out", default=str(OUT))
    args = a.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench-link-") as tmp:
        res = {"throughput": throughput(args.mb, tmp),
               "latency_50ms_1pct": latency(args.messages, args.rate, 50, 0.01, tmp),
               "machine": f"{os.cpu_count()} cores, loopback; other work running on it"}
    results.write(args.out, res, echo=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
