"""The supervisor of one host's processes (`mesh up`, `deploy --host`): a child that dies
is reported (which, exit code, last lines of its log) and restarted with backoff while
the rest keep running, up to a limit, then given up with one line."""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

from .proc import Proc


class Supervisor:
    """Restart what dies, with backoff, up to `max_restarts` times per process; one that
    dies once more is given up (one line naming it, `given_up`, `given_up.json` beside
    `pids.json`) and the others go on. Remember what happened for the summary.

    The supervisor is part of its host: each child it starts (`Proc`, and the EA peers
    the zygote forks) gets SIGTERM from the kernel when the supervisor dies, even by
    kill -9 (`proc.die_with_parent`), so nothing runs on headless; started again on the
    same output folder, a `deploy --host` resumes from the journals (deploy/launch.py)."""

    def __init__(self, echo, max_restarts: int = 10, backoff_s: float = 0.5, pids_path: Path | None = None):
        self.procs: dict[str, Proc] = {}
        self.echo, self.max_restarts, self.backoff_s, self.pids_path = echo, max_restarts, backoff_s, pids_path
        self.events: list[dict] = []
        self.due: dict[str, float] = {}     # name -> wall time of its restart
        self.given_up: set[str] = set()

    def add(self, p: Proc) -> Proc:
        self.procs[p.name] = p
        self._write_pids()
        return p

    def finished(self, p: Proc) -> bool:
        """Exited on its own after saying its summary (an EA peer), its end (a source) or `tak done`."""
        return p.exited() == 0 and any(p.find(x) is not None for x in ("summary ", "end ", "tak done"))

    def check(self) -> None:
        now = time.monotonic()
        for name, p in self.procs.items():
            code = p.exited()
            if code is None or name in self.given_up or self.finished(p):
                continue
            if name not in self.due:
                ev = {"process": name, "exit_code": code, "start": p.starts, "last_lines": p.tail(5)}
                self.events.append(ev)
                self.echo(f"supervisor: {name} exited ({code}); last lines: " + " | ".join(ev["last_lines"][-3:]))
                if p.starts > self.max_restarts:
                    self.given_up.add(name)
                    ev["given_up"] = True
                    self._write_pids()   # given_up.json says so by the time the line does
                    self.echo(f"supervisor: gave up on {name}: died {p.starts} time{'s' * (p.starts != 1)}, "
                              f"restarted {p.starts - 1} (--restarts {self.max_restarts}); the rest of the mesh "
                              "goes on without it")
                    continue
                self.due[name] = now + min(8.0, self.backoff_s * 2 ** (p.starts - 1))
            elif now >= self.due[name]:
                del self.due[name]
                p.start()
                self.events.append({"process": name, "restarted": p.starts - 1})
                self._write_pids()   # its new pid in pids.json by the time the line says it
                self.echo(f"supervisor: restarted {name} (restart {p.starts - 1})")

    def _write_pids(self) -> None:
        """`pids.json` (name -> pid of its current run) and beside it `given_up.json` (the
        processes it stopped restarting, each with its deaths), both replaced whole."""
        if self.pids_path is not None:
            for path, doc in ((self.pids_path, {n: p.pid for n, p in self.procs.items()}),
                              (self.pids_path.with_name("given_up.json"),
                               {n: self.procs[n].starts for n in sorted(self.given_up)})):
                tmp = path.with_suffix(".tmp")
                tmp.write_text(json.dumps(doc))
                os.replace(tmp, path)

    def stop(self) -> None:
        for p in reversed(list(self.procs.values())):   # leaves before the routers they hang on
            p.stop()
