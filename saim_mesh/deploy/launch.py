"""Start one host's share of a deployment under its own supervisor: its routers
(listening on the host's addresses, linked to the routers the file names, wherever they
run), its TAK gateway, its EA peers (clients of the host's router), its consoles, then
its sources. A child that dies is reported and restarted with backoff, up to
`max_restarts` times (`--restarts`); one that dies once more is given up with one line
naming it (also in `given_up.json` beside `pids.json`, and in `summary.json`) and the
rest of the host goes on without it. Every child's output goes to its own log.
`mesh up` is this with one host on 127.0.0.1, free ports, and
optionally emulated router links (`link`).

The host's run ends when each of its EA peers said its summary or was given up
(`until_done`), at `timeout`, or when stopped (SIGTERM / Ctrl-C); a host whose routers
others still need keeps running after its EAs are done unless told otherwise.

A host that comes back (its machine or its supervisor died: every child dies with the
supervisor, `proc.die_with_parent`) keeps its state when started again on the same
output folder (`fresh=None`, `deploy --host` without `--fresh`): `host.json` there says
which deployment the folder belongs to (scenario, key root, host, its EAs and sources,
live or paced at which speed). When it matches, the EAs' alert logs, input journals,
notices and command logs and the sources' state folder (`sources/`: epochs and frame
journals) stay; each EA replays its input journal and each source resumes after what it
published, on the same clock (event time 0 at the same instant as before). Otherwise
(`fresh=True`, `mesh up`, a folder of another deployment or of none) they are deleted
first: a clean start."""
from __future__ import annotations

import json
import os
import shutil
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

from ..launch import zygote
from ..live.depend import home_of
from ..launch.supervise import Supervisor
from ..launch.proc import Proc, clean_env, leaf_env, py
from ..launch.zenoh_config import free_port
from .check import interface_addresses
from .file import Deployment, endpoint


class HostSupervisor(Supervisor):
    """The mesh's supervisor; a console that ended after its linger has finished too."""

    def finished(self, p: Proc) -> bool:
        return super().finished(p) or (p.exited() == 0 and p.find("console done") is not None)


@dataclass
class Plan:
    """What one host starts, resolved: endpoints with real ports, each process's router."""
    dep: Deployment
    host: str
    listen: dict[str, list[str]]          # local router -> its listen endpoints
    endpoints: dict[str, str]             # every router -> where others connect to it
    ports: dict[str, int]                 # local router -> its port
    links: dict[str, list[str]] = field(default_factory=dict)   # local router -> routers it connects to


def plan(dep: Deployment, host: str) -> Plan:
    """Resolve the host's addresses (or its interface's) and free ports for `port = 0`."""
    h = dep.hosts[host]
    addrs = list(h.addresses)
    if not addrs and h.interface:
        addrs = interface_addresses(h.interface) or []
        if not addrs:
            raise ValueError(f"host {host}: interface {h.interface} has no address to listen on")
    if not addrs:
        addrs = ["127.0.0.1"]
    listen, endpoints, ports = {}, {}, {}
    for n, r in dep.routers.items():
        if r.host == host:
            ports[n] = r.port or free_port(addrs[0])
            listen[n] = [endpoint(dep.proto(), a, ports[n]) for a in addrs]
            endpoints[n] = dep.endpoint(n, h.reach() or addrs[0], ports[n])
        else:
            endpoints[n] = dep.endpoint(n)
    return Plan(dep, host, listen, endpoints, ports, {n: list(r.links) for n, r in dep.routers.items()
                                                       if r.host == host})


STATE = "host.json"   # in the host's output folder: whose state it holds (`restart_state`)
EA_FILES = (".jsonl", ".input", ".notify.jsonl", ".cmdlog")   # an EA's alert log, input journal, notices, commands


def run_host(dep: Deployment, sc, host: str, out_dir: Path, *, echo=print, show: bool = True,
             timeout: float | None = 1800.0, until_done: bool = True, on_started=None, start: float | None = None,
             paced_start: float | None = None, link: dict | None = None, console_linger: float = 30.0,
             max_restarts: int = 10, fresh: bool | None = True,
             pki_said: tuple[str, str] | None = None) -> dict:
    """Start `host`'s processes and supervise them (see the module's docstring).

    `start` (live): the wall time of event time 0 (default: the file's, else the one
    this host ran on before (a restart), else 20 s from now). `paced_start`: with a speed,
    event time 0 for every source (default: the file's start, else a restart's earlier
    one, else 5 s after this host's EAs are ready). `on_started(sup, t0)`: called once
    the host's sources run. `link`: emulate each router link between local routers
    (delay_ms, loss; processes link-<lower>-<upper>: SIGUSR1 cuts, SIGUSR2 heals).
    `fresh`: True deletes what an earlier run left in `out_dir` (EA logs and journals,
    the sources' state); None keeps it when it belongs to this deployment (a restart:
    `restart_state`), else deletes it. `pki_said`: (who, how) for the one line that names a
    missing certificate (`mesh up --pki`: its own command to make them)."""
    from ..live.up import show_alerts, table
    from ..net import routed
    from ..net import topology as T
    from ..logs.sinks import COLOURS, RESET
    import sys
    from ea_agent.core.alert import hms
    pl = plan(dep, host)
    h = dep.hosts[host]
    to = sc.taskorg
    root = dep.root or f"saim/{sc.name}/live"
    out_dir.mkdir(parents=True, exist_ok=True)
    logs = out_dir / "logs"
    logs.mkdir(exist_ok=True)
    sources = dep.sources()
    units = list(h.eas)
    colours = COLOURS if sys.stdout.isatty() else None
    secure = ["--pki", str(dep.pki)] if dep.secure else []
    if dep.secure:
        _check_pki(dep, host, *(pki_said or ()))
    topo = dep.topology()
    topo.top = dep._top(to)
    resolved = out_dir / "topology.json"
    T.resolve(topo, pl.endpoints, resolved)
    live = dep.live
    if dep.start is not None:
        if live and start is None:
            start = _instant(dep.start)
        elif not live and paced_start is None:
            paced_start = _instant(dep.start)
    ident = {"scenario": sc.name, "root": root, "host": host, "eas": units, "sources": list(h.sources),
             "live": live, "speed": dep.speed}   # the same deployment: the same streams on the same clock
    prior, why = restart_state(out_dir, ident, fresh)
    if prior is None:
        cleared = clear_state(out_dir, units)
        if cleared or fresh is None:
            echo(f"host {host}: a clean start ({why}" + (f"; deleted {cleared} files of an earlier run"
                                                          if cleared else "") + ")", flush=True)
    else:
        if live and start is None:
            start = prior.get("start")
        if not live and paced_start is None and dep.speed != "max":
            paced_start = prior.get("paced_start")
        echo(f"host {host}: restart: keeping the state in {out_dir} ({why}); its EAs replay their input "
             f"journals, its sources resume after what they published" + (", on the same clock" if
                                                                          (start if live else paced_start) else "")
             + " (--fresh: a clean start)", flush=True)
    runs = (prior or {}).get("runs", []) + [{"wall": round(time.time(), 3), "pid": os.getpid(),
                                             "restart": prior is not None}]
    start = start if start is not None else time.time() + 20.0
    pki_of = str(Path(dep.pki).resolve()) if dep.secure else None   # for those who join (saim_mesh.api: mesh=)
    _write_state(out_dir, ident, start if live else None, paced_start, runs, pki_of)
    live_args = ["--live", "--start", _iso(start)] if live else []
    until_args = ["--until", str(dep.until)] if dep.until is not None else []
    where = lambda unit: ["--connect", pl.endpoints[dep.attach(host, unit, to)], "--mode", "client",  # noqa: E731
                          "--topology", str(resolved), *secure]
    sup = HostSupervisor(echo, max_restarts, pids_path=out_dir / "pids.json")
    summaries: dict[str, dict] = {}
    seen: dict[str, int] = {}
    shown = Counter()
    link_files: dict[str, Path] = {}
    consoles: list[Proc] = []
    t0 = time.monotonic()
    done_said = False
    stopped: BaseException | None = None
    try:
        local = [n for n in routed.parents_first(topo) if n in pl.listen]
        for n in local:   # parents first; a router above on another host is reached when it is up
            connect = []
            for up in pl.links[n]:
                if link is not None and up in pl.ports:
                    ep, link_files[f"{n}->{up}"] = routed.start_link(sup, n, up, pl.ports[up], dep.secure, link,
                                                                    out_dir, len(link_files))
                    connect.append(ep)
                else:
                    connect.append(pl.endpoints[up])
            routed.start_router(sup, dep.scenario, n, pl.listen[n], connect, root, resolved,
                                dep.pki if dep.secure else None, logs)
        if local:
            said = ", ".join(n + " on " + " ".join(pl.listen[n]) for n in local)
            echo(f"host {host}: routers {said}" + (f"; {len(link_files)} emulated links" if link_files else ""),
                 flush=True)
        if h.tak is not None:   # before the EA peers: it must hear their first alerts
            tak = [x for u in h.tak.cot for x in ("--cot-url", u)] + [x for u in h.tak.listen_cot
                                                                       for x in ("--listen-cot", u)]
            tak += ["--uids", h.tak.uids] if h.tak.uids else []
            tak += ["--proto", h.tak.proto] if h.tak.proto != "xml" else []
            sup.add(Proc("tak", [*py(), "tak", dep.scenario, *live_args, *tak, *where(to.root),
                                 "--root", root], env=clean_env(), log_dir=logs)).wait_for("tak ready", 60)
        armed = ["--armed"] if h.consoles else []   # a console watches: urgent alerts repeat until acked
        for u in units:
            sup.add(Proc(u, [*py(), "peer", "--scenario", dep.scenario, "--unit", u, *where(u), "--root", root,
                             "--sources", *sources, "--out", str(out_dir / f"{u}.jsonl"), *live_args, *armed],
                         env=leaf_env(), log_dir=logs,
                         spawner=zygote.spawner()))   # EA peers fork from one zygote (saim_mesh/launch/zygote.py)
        for u in units:
            sup.procs[u].wait_for(f"ready {u}", 120)
        if units:
            echo(f"host {host}: {len(units)} EA peers ready ({' '.join(units)})", flush=True)
        for c in h.consoles:
            p = sup.add(Proc(f"console-{c.unit}", [*py(), "console", dep.scenario, "--unit", c.unit,
                                                   *where(c.unit), "--root", root, "--port", str(c.port),
                                                   "--linger", str(console_linger)], env=clean_env(), log_dir=logs))
            consoles.append(p)
            echo(p.wait_for("console http", 60).split(" ", 1)[1] + f"  <- {c.unit}'s commander's console", flush=True)
        if not live and dep.speed != "max" and paced_start is None:   # one clock: event time 0 at this instant
            paced_start = time.time() + 5.0
            _write_state(out_dir, ident, None, paced_start, runs, pki_of)   # a restart keeps it
        pace_args = ["--start", _iso(paced_start)] if paced_start is not None and not live else []
        share = _share_args(sc)
        for name in h.sources:
            sup.add(Proc(name, [*py(), "source", dep.scenario, "--name", name, *share[name],
                                *where(home_of(sc, name) or name), "--root", root, "--speed", dep.speed,
                                "--state", str(out_dir / "sources"), "--linger", f"{dep.source_linger:g}",
                                *(["--yield-catch-up"] if dep.yielding() else []),
                                *(["--catch-up-kbit", f"{dep.catch_up_kbit:g}"] if dep.catch_up_kbit else []),
                                *live_args, *pace_args, *until_args], env=clean_env(), log_dir=logs))
        if h.sources:
            echo(f"host {host}: sources {', '.join(h.sources)} started", flush=True)
        if on_started is not None:
            on_started(sup, paced_start if not live else start)
        end = time.monotonic() + timeout if timeout is not None else float("inf")
        while time.monotonic() < end:
            sup.check()
            for u in units:
                if show:
                    seen[u] = show_alerts(out_dir / f"{u}.jsonl", seen.get(u, 0), echo, colours, RESET, hms, shown)
                if u not in summaries and (line := sup.procs[u].find("summary ")) is not None:
                    summaries[u] = json.loads(line[len("summary "):])
            lost = [u for u in units if u in sup.given_up and u not in summaries]
            if units and len(summaries) + len(lost) == len(units) and not done_said:
                done_said = True
                echo(f"host {host}: {len(summaries)} of {len(units)} EA peers done"
                     + (f" (given up: {' '.join(lost)})" if lost else ""), flush=True)
                if until_done:
                    break
            time.sleep(0.1)
        for p in consoles:   # a console stays up for its linger after the end
            try:
                p.p.wait(console_linger + 60)
            except Exception:   # one that does not end is stopped below
                pass
    except (KeyboardInterrupt, SystemExit) as e:   # stopped (SIGTERM, Ctrl-C): summarise, then go on stopping
        stopped = e
    finally:
        sup.stop()
    wall = time.monotonic() - t0
    result = {"host": host, "peers": summaries, "wall_s": round(wall, 1), "sources": sources, "events": sup.events,
              "secure": dep.secure, "start": start if live else None, "paced_start": paced_start, "root": root,
              "units": units, "topology": topo.to_dict(), "endpoints": pl.endpoints, "stopped": stopped is not None,
              "given_up": sorted(sup.given_up), "max_restarts": max_restarts}
    if link_files:   # bytes per router link (the emulated links' counters)
        result["links"] = routed.link_stats(link_files)
    (out_dir / "summary.json").write_text(json.dumps(result, indent=1, default=str))
    if units:
        echo(table(out_dir, units, sc))
    crashes = [e for e in sup.events if "exit_code" in e]
    echo(f"{len(summaries)} of {len(units)} EA peers done in {wall:.1f} s on host {host}, sources "
         f"{', '.join(h.sources) or 'none'}, {'mTLS + access control' if dep.secure else 'insecure'}; "
         f"{len(crashes)} crash(es), {sum(1 for e in sup.events if 'restarted' in e)} restart(s)"
         + (f", gave up on {' '.join(sorted(sup.given_up))} (--restarts {max_restarts})" if sup.given_up else "")
         + f"; alerts in {out_dir}/, logs in {logs}/" + (" (stopped)" if stopped is not None else ""))
    if stopped is not None:
        raise stopped
    return result


def restart_state(out_dir: Path, ident: dict, fresh: bool | None) -> tuple[dict | None, str]:
    """(what `host.json` in `out_dir` holds, why) when the host restarts on that state;
    (None, why) when it starts clean: `fresh`, no earlier run there, or one of another
    deployment (its scenario, key root, host name, EAs, sources, live or speed differ)."""
    path = out_dir / STATE
    if fresh:
        return None, "asked for"
    try:
        prior = json.loads(path.read_text())
    except FileNotFoundError:
        return None, f"no earlier run in {out_dir}"
    except (OSError, ValueError) as e:
        return None, f"{path} unreadable ({type(e).__name__}: {e})"
    was = prior.get("deployment") if isinstance(prior, dict) else None
    if was != ident:
        diff = sorted(k for k in ident if not isinstance(was, dict) or was.get(k) != ident[k])
        return None, f"{out_dir} holds another deployment's state (its {', '.join(diff) or 'format'} differ)"
    n = len(prior.get("runs", []))
    return prior, f"run {n + 1} of this host on it"


def clear_state(out_dir: Path, units) -> int:
    """Delete what a run leaves for a restart: `units`' logs and journals, the sources'
    state folder, `host.json` (and those of the units it names). Returns the files deleted."""
    n = 0
    try:
        was = json.loads((out_dir / STATE).read_text()).get("deployment", {}).get("eas", [])
    except (OSError, ValueError, AttributeError):
        was = []
    for u in dict.fromkeys([*units, *(x for x in was if isinstance(x, str))]):
        for ext in EA_FILES:
            f = out_dir / f"{u}{ext}"
            if f.exists():
                f.unlink()
                n += 1
    src = out_dir / "sources"
    if src.exists():
        n += sum(1 for x in src.rglob("*") if x.is_file())
        shutil.rmtree(src)
    (out_dir / STATE).unlink(missing_ok=True)
    return n


def _write_state(out_dir: Path, ident: dict, start: float | None, paced_start: float | None, runs: list,
                 pki: str | None = None) -> None:
    tmp = out_dir / (STATE + ".tmp")
    tmp.write_text(json.dumps({"deployment": ident, "start": start, "paced_start": paced_start, "runs": runs,
                               "pki": pki}, indent=1))
    os.replace(tmp, out_dir / STATE)   # a kill leaves the old one or the new one


def _share_args(sc) -> dict[str, list[str]]:
    from ..live.depend import cp_shares
    return {n: s.args() for n, s in cp_shares(sc).items()}


def _check_pki(dep: Deployment, host: str, who: str | None = None,
               how: str = "make the certificates with saim-mesh certs --deploy FILE") -> None:
    """Every identity this host runs has its certificate (Zenoh's connecting side would
    retry forever in silence: ../shared/notes/zenoh-security.md). `who` and `how` say, in
    the one line, who asked and how to make what is missing (`mesh up --pki` says its own)."""
    from ..security.pki import SecurityError, check_identity
    for ident in identities(dep, host):
        try:
            check_identity(dep.pki, ident)
        except SecurityError as e:
            raise SecurityError(f"{who or f'host {host}'}: {e} ({how})") from None


def identities(dep: Deployment, host: str) -> list[str]:
    """The certificate names of what `host` runs."""
    h = dep.hosts[host]
    return [*(f"router.{n}" for n, r in dep.routers.items() if r.host == host), *(f"ea.{u}" for u in h.eas),
            *(f"source.{s}" for s in h.sources), *(f"console.{c.unit}" for c in h.consoles),
            *(["tak"] if h.tak is not None else [])]


def _instant(text: str) -> float:
    from datetime import datetime, timezone
    d = datetime.fromisoformat(text.replace("Z", "+00:00"))
    return (d if d.tzinfo else d.replace(tzinfo=timezone.utc)).timestamp()


def _iso(t: float) -> str:
    from datetime import datetime, timezone
    return datetime.fromtimestamp(t, timezone.utc).isoformat()
