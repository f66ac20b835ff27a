"""The closed loop's router on loopback: robots and EAs are its clients (since Zenoh 1.9
peers do not relay for each other; a router does)."""
from __future__ import annotations

import signal

import zenoh


def main(a) -> int:
    from .cli import session_config
    from .secure import ROUTER
    conf = session_config(a, f"router.{ROUTER}", listen=[a.listen])
    with zenoh.open(conf):
        print(f"hub ready {a.listen}", flush=True)
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM, signal.SIGINT})
        signal.sigwait({signal.SIGTERM, signal.SIGINT})
    return 0
