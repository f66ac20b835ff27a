"""Entry points for the CLI: `saim-mesh console` / `mesh up --console` (a mesh peer)
and `saim-mesh run --console` (in process)."""
from __future__ import annotations

import signal
import sys
import threading
import time
from typing import Callable

from .feed import live_feed, mesh_actions, serve_inprocess
from .server import Server, make_app
from .state import State


def main_console(sc, conf, root: str, unit: str | None = None, port: int = 0, linger_s: float = 30.0) -> int:
    """Serve the console for the mesh at `conf` (the sources' frames, the clock from their
    watermarks) until every source ended plus `linger_s` (wall seconds), SIGTERM or
    Ctrl-C. `conf`: a zenoh.Config (zenoh_config.config(..., name=f"console.{unit}") under
    --pki). Returns the exit code."""
    unit = unit or sc.taskorg.root
    if unit not in sc.taskorg.units:
        print(f"saim-mesh console: unknown unit {unit!r}: not in the task organization of {sc.name}",
              file=sys.stderr, flush=True)
        return 2
    log = lambda *a, **k: print(*a, **k, file=sys.stdout)   # noqa: E731
    from ..scenario import mesh_units
    state = State(sc, unit, eligible=mesh_units(sc))   # acts for the EA peers under it, as organised now
    feed = live_feed(sc, conf, root, state, log=log)
    stop = threading.Event()
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, lambda *_: stop.set())
    feed.open()
    server = Server(make_app(state, mesh_actions(feed, state)), port)
    try:
        server.start()
        ended_at = None
        while not stop.wait(0.2):
            if state.ended and ended_at is None:
                ended_at = time.monotonic()
                log(f"end of scenario t={state.t:.0f}: serving {linger_s:.0f} s more", flush=True)
            if ended_at is not None and time.monotonic() - ended_at >= linger_s:
                break
    except KeyboardInterrupt:
        pass
    finally:
        server.stop()
        feed.close()
    r = feed.gate.rejects
    print(f"console done t={state.t:.0f} alerts={len(state.alert_owner)} rejects={r.total}", flush=True)
    return 0


def start_inprocess(sc, eas: list, port: int = 0) -> tuple[str, Callable[[], None]]:
    """Serve a console over in-process EAs (made, not yet run: hook before `ea.start`/
    the first `submit`). Returns (url, stop); prints `console URL` on stdout."""
    server, _ = serve_inprocess(eas, sc, port)
    return server.url, server.stop


__all__ = ["main_console", "start_inprocess", "Server", "make_app"]
