"""What every command group's arguments share: times, speeds, Zenoh options, one-line failures."""
from __future__ import annotations

import argparse
import time
import math
import os
import sys
from pathlib import Path



ROOT = Path(__file__).resolve().parents[2]
DEFAULT_SCENARIO = ROOT / "scenarios" / "battalion"


def _speed(v: str) -> float | None:
    if v == "max":
        return None
    try:
        f = float(v)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--speed takes a factor or 'max', not {v!r}") from None
    if not math.isfinite(f) or f <= 0:
        raise argparse.ArgumentTypeError("--speed factor must be a finite number > 0")
    return f


def _seconds(v: str) -> float:
    """A finite, non-negative number of seconds (or metres)."""
    try:
        f = float(v)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, not {v!r}") from None
    if not math.isfinite(f) or f < 0:
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, not {v!r}")
    return f


def _positive(v: str) -> float:
    """A finite number > 0 (a rate)."""
    f = _seconds(v)
    if f == 0:
        raise argparse.ArgumentTypeError(f"expected a number > 0, not {v!r}")
    return f


def _count(v: str) -> int:
    """A whole number >= 0 (a count: restarts)."""
    try:
        n = int(v)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, not {v!r}") from None
    if n < 0:
        raise argparse.ArgumentTypeError(f"expected a whole number >= 0, not {v!r}")
    return n


def _progress(frac: float) -> None:
    if sys.stderr.isatty():
        n = int(frac * 40)
        sys.stderr.write(f"\r[{'#' * n}{'.' * (40 - n)}] {frac * 100:5.1f}%")
        if frac >= 1.0:
            sys.stderr.write("\n")
        sys.stderr.flush()


def _fail(what) -> int:
    """One line on stderr and exit code 2 (SAIM_MESH_DEBUG=1 re-raises for the traceback)."""
    if os.environ.get("SAIM_MESH_DEBUG"):
        raise
    print("saim-mesh: " + " ".join(str(what).split()), file=sys.stderr)
    return 2


class _Parser(argparse.ArgumentParser):
    """Usage errors in one line (`--help` still shows the usage)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


def _zmode(a) -> dict:
    """--mode and the routers: those of --topology (a resolved topology written by `mesh up`)
    and those named by --routers (a mesh launched by hand)."""
    routers: list[str] = []
    if getattr(a, "topology", None):
        from ..net.topology import routers_of_resolved
        routers = routers_of_resolved(a.topology)
    routers += [r for r in getattr(a, "routers", None) or () if r not in routers]
    return {"mode": getattr(a, "mode", None), "routers": routers}


_IP_PROTOS = ("tcp", "tls", "udp", "quic", "ws")
_PROTOS = (*_IP_PROTOS, "unixsock-stream", "unixpipe", "serial", "vsock")


def _endpoint(v: str) -> str:
    """A Zenoh locator, `<proto>/<address>` (tcp, tls, udp, quic and ws: `host:port`), checked
    as the arguments are read: a garbage endpoint is one line, exit 2, before any session."""
    proto, sep, addr = v.partition("/")
    addr = addr.split("#", 1)[0].split("?", 1)[0]
    if not sep or proto not in _PROTOS or not addr:
        raise argparse.ArgumentTypeError(f"{v[:80]!r} is not a Zenoh endpoint (<proto>/<address>, proto one of "
                                         f"{', '.join(_PROTOS)}; e.g. tcp/127.0.0.1:7447)")
    if proto in _IP_PROTOS:
        host, colon, port = addr.rpartition(":")
        if not colon or not host or not port.isdigit() or not 0 <= int(port) <= 65535:
            raise argparse.ArgumentTypeError(f"{v[:80]!r}: a {proto} endpoint is {proto}/<host>:<port 0-65535>")
    return v


def _zenoh_args(p) -> None:
    p.add_argument("--listen", nargs="*", type=_endpoint, metavar="ENDPOINT", help="e.g. tcp/127.0.0.1:7447")
    p.add_argument("--connect", nargs="*", type=_endpoint, metavar="ENDPOINT")
    p.add_argument("--zenoh-config", metavar="JSON5", help="default configs/zenoh-peer.json5")
    p.add_argument("--multicast", action="store_true",
                   help="discover peers by UDP multicast scouting (a LAN) instead of configured endpoints only")
    p.add_argument("--root", help="key-expression root (default saim/<scenario name>)")
    p.add_argument("--mode", choices=["peer", "client"], default=None,
                   help="Zenoh mode: client when attached to a router (mesh up --topology), peer otherwise")
    p.add_argument("--topology", metavar="JSON", help="the resolved topology `mesh up --topology` wrote "
                   "(its routers' identities are accepted as relays; an EA peer --connect'ed to another router "
                   "than its command post's says so in a system problem)")
    p.add_argument("--routers", nargs="+", metavar="NAME", help="secure mode: the routers this process hears "
                   "through (their identities router.NAME are accepted as relays; `saim-mesh certs --routers`)")
    p.add_argument("--pki", metavar="DIR", help="secure mode: mutual TLS with this folder's certificates "
                   "(saim-mesh certs) and the mesh's access-control rules; endpoints are then tls/...")


def _lines(lines: list[str], out=None) -> int:
    """Each problem on its own line (stderr by default), exit code 2."""
    for x in lines:
        print(x, file=out or sys.stderr)
    return 2


def _start_of(a) -> float | None:
    """--live: the wall time of event time 0 (--start ISO8601, default now)."""
    if not getattr(a, "live", False):
        return None
    return _instant(a.start) if a.start else time.time()


def _instant(text: str) -> float:
    from datetime import datetime, timezone
    try:
        d = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise ValueError(f"--start {text!r}: expected an ISO 8601 time, e.g. 2026-11-27T09:00:00Z") from None
    return (d if d.tzinfo else d.replace(tzinfo=timezone.utc)).timestamp()
