"""`saim-mesh router`: a Zenoh router in a Python process (no `zenohd` comes from the
package registries). It serves one command post: its leaves (EA peers, the
sources of that post, consoles) attach to it as clients, and it links to the router of
the command post above. It routes by interest, so a key crosses a router link only
when someone beyond it subscribes (../shared/notes/zenoh-routers.md).

It holds a liveliness token `<root>/rtr/<name>/<zid>`: a router that goes away, or a
link that breaks, shows as that token's DELETE on the far side.
"""
from __future__ import annotations

import json
import signal
import sys
import threading
import time

import zenoh

from dissemination.keyspace import KeySpace


def run(name: str, conf: zenoh.Config, root: str, log=print) -> int:
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    ks = KeySpace(root)
    with zenoh.open(conf) as s:
        token = s.liveliness().declare_token(ks.router(name, str(s.info.zid())))
        seen = s.liveliness().declare_subscriber(ks.router("*", "*"), zenoh.handlers.FifoChannel(1024), history=True)
        log(f"router ready {name} {s.info.zid()}", flush=True)
        t0 = time.monotonic()
        while not stop.wait(0.2):
            while (smp := seen.try_recv()) is not None:   # who is reachable: a log line per change
                other = ks.last(str(smp.key_expr), 2)[0]
                if other != name:
                    up = smp.kind == zenoh.SampleKind.PUT
                    log(f"router {other} {'reachable' if up else 'lost'} t_wall={time.monotonic() - t0:.1f}",
                        flush=True)
        n_links = len(list(s.info.routers_zid()))
        token.undeclare()
    log("summary " + json.dumps({"router": name, "routers_linked": n_links}), flush=True)
    return 0


def main_router(name: str, conf: zenoh.Config, root: str) -> int:
    return run(name, conf, root, log=lambda *a, **k: print(*a, **k, file=sys.stdout))
