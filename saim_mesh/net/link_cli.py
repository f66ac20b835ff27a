"""`saim-mesh link`: one emulated radio link (`linkemu.Link`) as its own process, cut by
SIGUSR1 and healed by SIGUSR2, its counters written as JSON at every change and at exit."""
from __future__ import annotations

import argparse
import collections
import json
import math
import os
import signal
import sys
import threading
from pathlib import Path

from .linkemu import Link

def _port(v: str) -> int:
    try:
        p = int(v)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a port: {v!r} (expected an integer 1..65535)") from None
    if not 1 <= p <= 65535:
        raise argparse.ArgumentTypeError(f"not a port: {p} (expected 1..65535)")
    return p


def _listen_port(v: str) -> int:
    return 0 if v.strip() == "0" else _port(v)


def _number(lo: float, hi: float | None, what: str):
    def parse(v: str) -> float:
        try:
            f = float(v)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, not {v!r}") from None
        if not math.isfinite(f) or f < lo or (hi is not None and f >= hi):
            raise argparse.ArgumentTypeError(f"{what}, not {v!r}")
        return f
    return parse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--listen", type=_listen_port, required=True, metavar="PORT",
                   help="port on 127.0.0.1 to accept connections on (0: a free port, printed)")
    p.add_argument("--to", type=_port, required=True, metavar="PORT", help="port on 127.0.0.1 to forward to")
    p.add_argument("--delay-ms", type=_number(0, None, "expected a delay >= 0 ms"), default=0.0,
                   help="one-way delay, each direction")
    p.add_argument("--loss", type=_number(0, 1, "expected a loss probability in [0, 1)"), default=0.0,
                   help="probability a ~1400-byte chunk waits a retransmission timeout")
    p.add_argument("--rate-kbps", type=_number(1e-9, None, "expected a rate > 0 kbit/s"), default=None,
                   help="rate limit per direction, kbit/s (default: none)")
    p.add_argument("--seed", type=int, default=0, help="seed of the loss draws")
    p.add_argument("--stats", metavar="FILE", help="stats JSON written on every cut/heal and at exit")


def write_stats(path: str | Path, stats: dict) -> None:
    """Atomically: a reader sees the old file or the new one, never half of one."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(stats, indent=1) + "\n")
    os.replace(tmp, path)


def cmd_link(a) -> int:
    """Run one link until SIGTERM/SIGINT; SIGUSR1 cuts it, SIGUSR2 heals it."""
    link = Link(a.listen, a.to, a.delay_ms, a.loss,
                rate_bps=a.rate_kbps * 1000 if a.rate_kbps else None, seed=a.seed)
    stop = threading.Event()
    requests: collections.deque[str] = collections.deque()
    wake = threading.Event()

    def on_signal(signum, _frame) -> None:   # only note it: the main loop acts
        requests.append({signal.SIGUSR1: "cut", signal.SIGUSR2: "heal"}.get(signum, "stop"))
        wake.set()

    for s in (signal.SIGUSR1, signal.SIGUSR2, signal.SIGTERM, signal.SIGINT):
        signal.signal(s, on_signal)
    link.start()
    print(f"link ready {link.listen_port}", flush=True)
    try:
        while not stop.is_set():
            wake.wait(1.0)
            wake.clear()
            while requests:
                r = requests.popleft()
                if r == "stop":
                    stop.set()
                    break
                link.cut() if r == "cut" else link.heal()
                print(f"link {r}", flush=True)
                if a.stats:
                    write_stats(a.stats, link.stats())
    finally:
        link.stop()
        st = link.stats()
        if a.stats:
            write_stats(a.stats, st)
        print(f"stats {json.dumps(st)}", flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="saim-mesh link", description=__doc__.splitlines()[0])
    add_arguments(p)
    return cmd_link(p.parse_args(argv))


if __name__ == "__main__":
    sys.exit(main())
