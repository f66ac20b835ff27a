"""`scripts/netns-hosts`: the namespaced hosts of `netns.Hosts` from a shell (up, down,
cut, heal, rate, status, exec, cleanup), kept apart from the library the tests and
benchmarks use."""
from __future__ import annotations

import argparse
import atexit
import json
import os
import sys
from collections.abc import Sequence

from .netns import BASE, Hosts, NetnsError, cleanup, cleanup_stale, unavailable


def _prefix(a: argparse.Namespace) -> str:
    return a.prefix or f"{BASE}{a.name or 'cli'}-"


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="netns-hosts", description="Emulated hosts: a network namespace each, "
                                 "on one bridge, 198.18.0.0/24; silent cuts; tbf rates.")
    ap.add_argument("--name", help="names the set (namespaces sm-NAME-*); default cli")
    ap.add_argument("--prefix", help="the namespaces' prefix itself (overrides --name)")
    sub = ap.add_subparsers(dest="cmd", required=True)
    u = sub.add_parser("up", help="make N hosts (h0..), or --hosts a,b,c; they stay until `down`")
    u.add_argument("n", type=int, nargs="?")
    u.add_argument("--hosts", help="comma-separated host names instead of N")
    u.add_argument("--rate-kbit", type=int, help="tbf rate on every host link (kbit/s)")
    u.add_argument("--no-nft", action="store_true", help="cut by detaching bridge ports, not nft rules")
    sub.add_parser("down", help="remove the hosts, killing everything in them")
    for c, h in (("cut", "cut HOST off (or only the link HOST-PEER)"), ("heal", "undo a cut")):
        p = sub.add_parser(c, help=h)
        p.add_argument("host")
        p.add_argument("peer", nargs="?")
    r = sub.add_parser("rate", help="set (or with no KBIT remove) a host link's tbf rate")
    r.add_argument("host")
    r.add_argument("kbit", type=int, nargs="?")
    sub.add_parser("status", help="hosts, addresses, rates, cuts, processes (JSON)")
    e = sub.add_parser("exec", help="run a command inside HOST (replaces this process)")
    e.add_argument("host")
    e.add_argument("argv", nargs=argparse.REMAINDER)
    sub.add_parser("cleanup", help="remove leftovers: all under --prefix/--name, else those of dead runs (sm-<pid>-)")
    a = ap.parse_args(argv)
    try:
        if a.cmd == "cleanup":
            gone = cleanup(_prefix(a)) if a.prefix or a.name else cleanup_stale()
            print(f"removed {len(gone)} namespaces" + (f": {' '.join(gone)}" if gone else ""))
            return 0
        if a.cmd == "up":
            if why := unavailable():
                print(f"netns-hosts: cannot make hosts here: {why}", file=sys.stderr)
                return 3
            names: int | list[str] = a.hosts.split(",") if a.hosts else (a.n if a.n is not None else 2)
            hs = Hosts(names, rate_kbit=a.rate_kbit, prefix=_prefix(a), use_nft=False if a.no_nft else None)
            hs.up()
            atexit.unregister(hs.close)   # they outlive the CLI until `down`
            for h in hs.hosts.values():
                print(f"{h.name} {h.address} {h.netns}")
            return 0
        hs = Hosts.attach(_prefix(a))
        if a.cmd == "down":
            hs.close()
            print(f"removed {_prefix(a)}*")
        elif a.cmd in ("cut", "heal"):
            if a.peer:
                (hs.cut_link if a.cmd == "cut" else hs.heal_link)(a.host, a.peer)
            else:
                (hs.cut if a.cmd == "cut" else hs.heal)(a.host)
            print(json.dumps(hs.cuts()))
        elif a.cmd == "rate":
            hs.set_rate(a.host, a.kbit)
        elif a.cmd == "status":
            print(json.dumps(hs.status(), indent=1))
        elif a.cmd == "exec":
            argv2 = a.argv[1:] if a.argv[:1] == ["--"] else a.argv
            if not argv2:
                ap.error("exec HOST CMD...: no command")
            os.execvp("ip", hs.wrap(a.host, argv2))
        return 0
    except (NetnsError, KeyError, ValueError) as e:
        print(f"netns-hosts: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
