"""`saim-mesh mesh up`: one OS process per unit EA, the fusion nodes and the replay, on
loopback, supervised: a child that dies is reported (which, exit code, last lines of
its log) and restarted with backoff while the rest keep running; every child's output
goes to its own log file under the output folder. Secure (mTLS + access control) by
default; `insecure=True` keeps the open mode for quick experiments."""
from __future__ import annotations

import json
import os
import time
from pathlib import Path

from . import zygote
from .proc import Proc, clean_env, leaf_env, py
from .zconf import free_port


from .scenario import mesh_units  # noqa: F401  (the replay launcher's callers)


def _sec(pki: str | Path | None) -> list[str]:
    return ["--pki", str(pki)] if pki else []


def start_replay(scenario: str, endpoint: str, root: str, wait: list[str], speed: str = "max",
                 linger: float = 30.0, window: float = 20.0, pki=None, log_dir=None, state=None,
                 name: str = "replay", net: list[str] | None = None, until: float | None = None) -> Proc:
    """`net`: the Zenoh arguments when not listening on `endpoint` (behind routers)."""
    return Proc(name, [*py(), "replay", scenario, *(net or ["--listen", endpoint]), "--root", root, "--speed", speed,
                       "--linger", str(linger), "--window", str(window), *_sec(pki),
                       *(["--state", str(state)] if state else []), *(["--until", str(until)] if until else []),
                       "--wait-peers", *wait],
                env=leaf_env(), log_dir=log_dir)


def _listen(endpoint: str) -> str:
    return ("tls" if endpoint.startswith("tls/") else "tcp") + "/127.0.0.1:0"


def _net(endpoint: str) -> list[str]:
    """A peer of the flat mesh: connect to the replay, listen for the others."""
    return ["--connect", endpoint, "--listen", _listen(endpoint)]


def start_peer(scenario: str, unit: str, endpoint: str, root: str, out: str | Path, name: str | None = None,
               extra: list[str] = (), pki=None, log_dir=None, net: list[str] | None = None) -> Proc:
    return Proc(name or unit, [*py(), "peer", "--scenario", scenario, "--unit", unit, *(net or _net(endpoint)),
                               "--root", root, "--out", str(out), *_sec(pki), *extra],
                env=leaf_env(), log_dir=log_dir,
                spawner=zygote.spawner())   # EA peers fork from one zygote (saim_mesh/zygote.py)


def start_fusion(scenario: str, group: str, endpoint: str, root: str, shuffle: int | None = None, pki=None,
                 log_dir=None, net: list[str] | None = None) -> Proc:
    return Proc(f"fusion-{group}", [*py(), "fusion", "--scenario", scenario, "--group", group,
                                    *(net or _net(endpoint)), "--root", root, *_sec(pki)]
                + (["--shuffle", str(shuffle)] if shuffle is not None else []), env=clean_env(), log_dir=log_dir)


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
        """Exited on its own after saying its summary (or, for the replay, its end)."""
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


def up(scenario: str, units: list[str] | None, out_dir: Path, speed: str = "max", timeout: float = 900.0,
       root: str | None = None, echo=print, window: float = 20.0, insecure: bool = False,
       pki: Path | None = None, max_restarts: int = 10, console: int | None = None,
       console_linger: float = 30.0, tak: list[str] | None = None, topology: str | None = None,
       link: dict | None = None, until: float | None = None) -> dict:
    """`topology`: a topology file, or "derive" (one router per battalion command post
    and one at the top); leaves then attach to their routers as clients, and every
    router link goes through an emulated radio link (`link`: delay_ms, loss)."""
    from . import scenario as S
    sc = S.load(scenario, events=False)
    units = units or mesh_units(sc)
    groups = sorted(sc.meta.get("fusion", {}).get("groups", {}))
    out_dir.mkdir(parents=True, exist_ok=True)
    logs = out_dir / "logs"
    logs.mkdir(exist_ok=True)
    for f in logs.glob("*.log"):
        f.unlink()
    root = root or f"saim/{sc.name}/{os.getpid()}"
    topo = None
    if topology is not None:
        from .net import topology as T
        procs = {"replay", "tak", "console", *(f"fusion-{g}" for g in groups)}
        topo = T.derive(sc.taskorg) if topology == "derive" else T.load(topology, sc.taskorg, procs)
    if insecure:
        echo("WARNING: insecure mesh: no authentication, no access control; anyone on the network can "
             "feed this mesh orders, positions and tracks")
        endpoint, pki = f"tcp/127.0.0.1:{free_port()}", None
    else:
        from .security.pki import make_pki, names_for
        pki = Path(pki or out_dir / "pki")
        make_pki(pki, names_for(sc, consoles=True) + [f"router.{n}" for n in (topo.routers if topo else ())])
        endpoint = f"tls/127.0.0.1:{free_port()}"
    state = out_dir / "replay.state"
    state.unlink(missing_ok=True)
    sup = Supervisor(echo, max_restarts, pids_path=out_dir / "pids.json")
    t0 = time.monotonic()
    summaries: dict[str, dict] = {}
    con: Proc | None = None
    link_files: dict[str, Path] = {}
    net = lambda who: _net(endpoint)   # noqa: E731  (flat mesh: everyone links to the replay)
    replay_net = None
    try:
        if topo is not None:
            from .net import routed
            eps, link_files, resolved = routed.start(scenario, topo, out_dir, root, sup, pki, link, echo)
            client = ["--mode", "client", "--topology", str(resolved)]
            net = lambda who: ["--connect", eps[topo.router_of(who, sc.taskorg)], *client]   # noqa: E731
            replay_net = client   # one session per router: each unit's reports enter at its own router
        replay = sup.add(start_replay(scenario, endpoint, root, units + [f"fusion-{g}" for g in groups], speed,
                                      window=window, pki=pki, log_dir=logs, state=state, net=replay_net,
                                      until=until))
        replay.wait_for("ready", 600)   # a brigade takes a while to load and key (754k events)
        if tak is not None:   # before the EA peers: it must hear their first alerts (supervised: restarted)
            sup.add(Proc("tak", [*py(), "tak", scenario, *net("tak"),
                                 "--root", root, *_sec(pki), *tak], env=clean_env(), log_dir=logs))
            sup.procs["tak"].wait_for("tak ready", 60)
        for g in groups:
            sup.add(start_fusion(scenario, g, endpoint, root, pki=pki, log_dir=logs, net=net(f"fusion-{g}")))
        for u in units:
            (out_dir / f"{u}.jsonl").unlink(missing_ok=True)
            (out_dir / f"{u}.cmdlog").unlink(missing_ok=True)
            armed = ["--armed"] if console is not None else []   # the console watches: urgent alerts repeat until acked
            sup.add(start_peer(scenario, u, endpoint, root, out_dir / f"{u}.jsonl", extra=armed, pki=pki, log_dir=logs,
                               net=net(u)))
        if console is not None:   # the top unit's commander's console (not supervised: it ends after its linger)
            con_net = net("console") if topo is not None else ["--connect", endpoint]
            con = Proc("console", [*py(), "console", scenario, *con_net, "--root", root,
                                   "--port", str(console), "--linger", str(console_linger), *_sec(pki)],
                       env=clean_env(), log_dir=logs)
            echo(con.wait_for("console http", 60).split(" ", 1)[1] + "  <- the commander's console", flush=True)
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            sup.check()
            for u in units:
                if u not in summaries and sup.finished(p := sup.procs[u]):
                    summaries[u] = json.loads(p.find("summary ")[len("summary "):])
            if len(summaries) + len(sup.given_up & set(units)) >= len(units):
                break
            time.sleep(0.05)
        else:
            echo(f"mesh: timed out after {timeout:.0f} s; peers without a summary: "
                 f"{sorted(set(units) - set(summaries))}")
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not sup.finished(replay) and replay.exited() is None:
            time.sleep(0.05)
        wall = time.monotonic() - t0
        if con is not None:   # the console stays up for its linger after the end
            con.p.wait(console_linger + 60)
    finally:
        if con is not None:
            con.stop()
        sup.stop()
    echo(f"{'peer':>6} {'alerts':>7} {'flash':>6} {'late':>5} {'facts':>7} {'subs':>5} {'rss MB':>7} {'wall s':>7}")
    for u, s in summaries.items():
        echo(f"{u:>6} {s['alerts']:>7} {s['by_priority'].get('flash', 0):>6} {s.get('late_alerts', 0):>5} "
             f"{s['facts']:>7} {s['subscriptions']:>5} {s['peak_rss_mb']:>7} {s['wall_s']:>7}")
    crashes = [e for e in sup.events if "exit_code" in e]
    echo(f"{len(summaries)} peers, wall {wall:.1f} s, {'insecure' if insecure else 'mTLS + access control'}; "
         f"{len(crashes)} crash(es), {sum(1 for e in sup.events if 'restarted' in e)} restart(s); "
         f"alerts in {out_dir}/, logs in {logs}/")
    for e in crashes:
        echo(f"  {e['process']} exited ({e['exit_code']}): {' | '.join(e['last_lines'][-2:])}")
    result = {"peers": summaries, "wall_s": wall, "events": sup.events, "replay": replay.lines,
              "secure": not insecure, "given_up": sorted(sup.given_up)}
    if topo is not None:
        from .net.routed import link_stats
        result["topology"] = topo.to_dict()
        result["links"] = link_stats(link_files)
    (out_dir / "summary.json").write_text(json.dumps(result, indent=1, default=str))
    return result
