"""The console's web server (docs/console.md section 2): the page, a JSON snapshot,
server-sent events for live updates and the action endpoints. Starlette under
uvicorn in a thread, bound to 127.0.0.1 only: the console is the commander's own."""
from __future__ import annotations

import asyncio
import contextlib
import json
import sys
import threading
import time
from pathlib import Path

import uvicorn
from starlette.applications import Starlette
from starlette.concurrency import run_in_threadpool
from starlette.requests import Request
from starlette.responses import FileResponse, HTMLResponse, JSONResponse, StreamingResponse
from starlette.routing import Mount, Route
from starlette.staticfiles import StaticFiles

from .actions import FIELDS, BadRequest, validate

STATIC = Path(__file__).resolve().parent / "static"
BATCH_S = 0.1          # events reach the browser at most this often
KEEPALIVE_S = 15.0
CLIENT_BACKLOG = 600   # batches a slow browser may fall behind before it is dropped
MAX_BODY = 65536


def sse(event: str, data) -> str:
    return f"event: {event}\ndata: {json.dumps(data, separators=(',', ':'))}\n\n"


class Hub:
    """Fans the state's events out to every connected browser, one queue each; a
    browser that stops reading is dropped rather than let its queue grow."""

    def __init__(self, state):
        self.state = state
        self.clients: set[asyncio.Queue] = set()
        self.closing = False

    async def run(self) -> None:
        while not self.closing:
            await asyncio.sleep(BATCH_S)
            self.flush()

    def flush(self) -> None:
        events = self.state.drain()   # drained even with nobody listening: nothing piles up
        if not events or not self.clients:
            return
        text = "".join(sse(e, d) for e, d in events)
        for q in list(self.clients):
            if q.qsize() >= CLIENT_BACKLOG:
                self.clients.discard(q)
                q.put_nowait(None)
            else:
                q.put_nowait(text)

    def close(self) -> None:
        self.closing = True
        for q in list(self.clients):
            q.put_nowait(None)

    async def stream(self, q: asyncio.Queue):
        try:
            yield sse("clock", {"t": self.state.t})
            while True:
                try:
                    text = await asyncio.wait_for(q.get(), KEEPALIVE_S)
                except asyncio.TimeoutError:
                    yield ": keepalive\n\n"
                    continue
                if text is None:
                    return
                yield text
        finally:
            self.clients.discard(q)


def make_app(state, actions, static_dir: Path | str = STATIC) -> Starlette:
    """The app; `actions` answers the POSTs (see actions.Actions)."""
    hub = Hub(state)
    static_dir = Path(static_dir)
    static_dir.mkdir(parents=True, exist_ok=True)

    async def index(request: Request):
        page = static_dir / "index.html"
        if page.is_file():
            return FileResponse(page)
        return HTMLResponse("<!doctype html><title>SAIM console</title><p>The page is not installed.</p>")

    async def api_state(request: Request):
        return JSONResponse(await run_in_threadpool(state.snapshot))

    async def api_alert(request: Request):
        """GET /api/alert?id=<owner>/<n>: one alert (an escalated one the page no longer holds)."""
        aid = request.query_params.get("id", "")
        a = state.find_alert(aid) if aid else None
        if a is None:
            why = "give ?id=<alert id>" if not aid else f"unknown alert {aid[:60]!r}: not among those this console kept"
            return JSONResponse({"ok": False, "error": why}, 404)
        return JSONResponse(a)

    async def events(request: Request):
        q: asyncio.Queue = asyncio.Queue()
        hub.clients.add(q)
        return StreamingResponse(hub.stream(q), media_type="text/event-stream",
                                 headers={"Cache-Control": "no-cache", "X-Accel-Buffering": "no"})

    def action(kind: str):
        async def endpoint(request: Request):
            raw = await request.body()
            if len(raw) > MAX_BODY:
                return _bad(f"request body over {MAX_BODY} bytes")
            try:
                body = json.loads(raw)
            except (ValueError, RecursionError) as e:
                return _bad(f"malformed JSON: {str(e)[:120]}")
            try:
                unit, fields = validate(kind, body, state)
                res = await run_in_threadpool(getattr(actions, kind), unit, **fields)
            except BadRequest as e:
                return _bad(str(e))
            except ValueError as e:   # commands.make names the field
                return _bad(f"{kind}: {e}")
            except TimeoutError as e:
                return JSONResponse({"ok": False, "error": f"no answer from the EA of {unit}: {e}"}, 504)
            if not res.get("ok"):
                return JSONResponse({"ok": False, "error": res.get("error") or "refused", "result": res}, 400)
            return JSONResponse({"ok": True, "result": res})
        return endpoint

    routes = [Route("/", index), Route("/api/state", api_state), Route("/api/alert", api_alert),
              Route("/events", events),
              *(Route(f"/api/{k}", action(k), methods=["POST"]) for k in FIELDS),
              Mount("/static", StaticFiles(directory=str(static_dir)), name="static")]

    @contextlib.asynccontextmanager
    async def lifespan(app):
        app.state.loop = asyncio.get_running_loop()
        task = app.state.loop.create_task(hub.run())
        try:
            yield
        finally:
            hub.close()
            task.cancel()

    app = Starlette(routes=routes, lifespan=lifespan)
    app.state.hub = hub
    app.state.loop = None
    return app


def _bad(text: str) -> JSONResponse:
    return JSONResponse({"ok": False, "error": text}, 400)


class Server:
    """uvicorn in a daemon thread. `start()` returns the URL once it listens (and says
    `console http://127.0.0.1:PORT/` on stdout); `stop()` ends open streams and returns."""

    def __init__(self, app: Starlette, port: int = 0, out=None):
        self.app, self.out = app, out or sys.stdout
        cfg = uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning", access_log=False,
                             lifespan="on", timeout_graceful_shutdown=2)
        self.server = uvicorn.Server(cfg)
        self.thread = threading.Thread(target=self.server.run, name="console-http", daemon=True)
        self.url = ""

    def start(self, timeout: float = 10.0) -> str:
        self.thread.start()
        end = time.monotonic() + timeout
        while not self.server.started:
            if not self.thread.is_alive() or time.monotonic() > end:
                raise RuntimeError("the console's web server did not start (is the port taken?)")
            time.sleep(0.02)
        port = self.server.servers[0].sockets[0].getsockname()[1]
        self.url = f"http://127.0.0.1:{port}/"
        print(f"console {self.url}", file=self.out, flush=True)
        return self.url

    def stop(self) -> None:
        hub, loop = self.app.state.hub, getattr(self.app.state, "loop", None)
        if loop is not None and not loop.is_closed():
            loop.call_soon_threadsafe(hub.close)   # open streams end: nothing holds the shutdown
        self.server.should_exit = True
        self.thread.join(5.0)
