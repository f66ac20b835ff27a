"""The closed-loop driver: the robot team on the mesh, one process per robot and one per EA
(the operator's and each robot's), on loopback behind one router; then the run's record
(events.jsonl.gz and truth.json from the robots' true runs, every EA's alerts).

One process per robot, not per team: a robot's only coupling to its teammates goes
through the EAs (a handoff is an agent message a teammate's EA answers), so nothing
shared needs a process of its own, and a robot that dies or falls silent is exactly one
process gone. Each robot draws from its own random stream, so the run is the same as the
in-process `ea_agent.domains.uv.loop.ClosedLoop`."""
from __future__ import annotations

import json
import sys
import time
import uuid
from pathlib import Path

from ea_agent.domains.uv import generator as G

from ..launch.proc import Proc, leaf_env
from ..launch.zenoh_config import free_port
from . import secure as S
from . import wire


def _py() -> list[str]:
    return [sys.executable, "-m", "saim_mesh.robots"]


def run_team(out: Path, until: float | None = None, mute: tuple[str, ...] = (), forge: dict[str, str] | None = None,
             seed: int = 7, timeout: float = 300.0, echo=print, secure: bool = True) -> dict:
    """Run the closed loop on the mesh into folder `out`; returns a summary. `mute`: EAs
    that publish no tasks; `forge`: unit -> an identity that also signs that EA's tasks
    (the robot must refuse them). A full run (no `until`) also writes the scenario folder.
    `secure`: mutual TLS and the loop's access control (robots/secure.py), else plain TCP
    (the tasks are signed either way)."""
    out = Path(out)
    meta = G.write_static(out, seed)
    units = list(meta["default_eas"])
    robots = sorted(u["id"] for u in G.UNITS if u["kind"] in ("ugv", "uav"))
    extra = sorted(set((forge or {}).values()) - {f"ea.{u}" for u in units})
    if secure:
        keys = out / "pki"
        S.make(keys, units, robots, extra)
    else:
        keys = out / "keys"
        wire.make_identities(keys, units, extra=extra)
    for d in ("alerts", "robots", "logs"):
        (out / d).mkdir(exist_ok=True)
    ep = f"{'tls' if secure else 'tcp'}/127.0.0.1:{free_port()}"
    root = f"robots/{uuid.uuid4().hex[:8]}"
    sec = ["--pki", str(keys), "--scenario", str(out)] if secure else []
    common = ["--connect", ep, "--root", root, "--keys", str(keys), "--deadline", str(timeout),
              *(sec or ["--scenario", str(out)])]
    common += ["--until", str(until)] if until is not None else []
    procs: list[Proc] = []
    t0 = time.monotonic()
    try:
        hub = Proc("hub", [*_py(), "hub", "--listen", ep, "--root", root, *sec], env=leaf_env(), log_dir=out / "logs")
        procs.append(hub)
        hub.wait_for("hub ready", 60)
        eas = {}
        for u in units:
            extra = (["--mute"] if u in mute else []) + (["--forge", forge[u]] if forge and u in forge else [])
            eas[u] = Proc(f"ea.{u}", [*_py(), "ea", "--unit", u, "--robots", *robots,
                                      "--out", str(out / "alerts" / f"{u}.jsonl"), *common, *extra],
                          env=leaf_env(), log_dir=out / "logs")
            procs.append(eas[u])
        for p in eas.values():
            p.wait_for("ready ea", 120)
        bots = {}
        for r in robots:
            bots[r] = Proc(f"robot.{r}", [*_py(), "robot", "--robot", r, "--seed", str(seed),
                                          "--out", str(out / "robots" / f"{r}.json"), *common],
                           env=leaf_env(), log_dir=out / "logs")
            procs.append(bots[r])
        end = time.monotonic() + timeout
        ea_sum = {u: json.loads(p.wait_for("summary ", max(1.0, end - time.monotonic()))[8:]) for u, p in eas.items()}
        bot_sum = {r: json.loads(p.wait_for("summary ", max(1.0, end - time.monotonic()))[8:]) for r, p in bots.items()}
        wall = time.monotonic() - t0
    finally:
        for p in procs:
            p.stop()
    records = {r: json.loads((out / "robots" / f"{r}.json").read_text()) for r in robots}
    events = [e for *_, e in sorted((e["t"], robots.index(r), j, e) for r in robots
                                     for j, e in enumerate(records[r]["events"]))]
    res = {"robot_processes": len(bots), "ea_processes": len(eas), "wall_s": round(wall, 1), "secure": secure,
           "scenario_s": until if until is not None else G.DURATION, "robots": bot_sum, "eas": ea_sum,
           "alerts": {u: [json.loads(x) for x in (out / "alerts" / f"{u}.jsonl").read_text().splitlines()]
                      for u in units}}
    if until is None:
        res["scenario"] = G.write_run(out, events, G.team({r: records[r] for r in robots}), units)
    else:
        res["events"] = events
    echo(json.dumps({k: v for k, v in res.items() if k not in ("alerts", "events")}), flush=True)
    return res
