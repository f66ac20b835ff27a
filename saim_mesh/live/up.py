"""`saim-mesh mesh up --live`: the mesh with no centre on one host. One source per
command post (each company's subtree; the battalion's own units and the hostile tracks
its sensors see), one EA peer per unit advancing on those sources' watermarks, no
replay. Alerts are printed as the peers raise them (read from their durable logs), the
Fig. 7 table at the end. Supervised like `mesh up`: a child that dies is reported and
restarted (a restarted source takes a new epoch; a restarted peer starts a new log)."""
from __future__ import annotations

import json
import time
from collections import Counter
from pathlib import Path

from .. import zygote
from ..mesh import Supervisor, mesh_units
from ..proc import Proc, clean_env, leaf_env, py
from ..zconf import free_port
from .depend import cp_shares


def cp_sources(sc) -> dict[str, list[str]]:
    """name -> `saim-mesh source` arguments: one per child of the top unit (its subtree),
    and the top's own share (everything else, with the tracks): `depend.cp_shares`."""
    return {name: sh.args() for name, sh in cp_shares(sc).items()}


def up(scenario: str, units: list[str] | None, out_dir: Path, speed: str = "max", timeout: float = 1800.0,
       echo=print, live: bool = False, show: bool = True, until: float | None = None, on_started=None,
       start: float | None = None, insecure: bool = False, topology: str | None = None,
       link: dict | None = None, paced_start: float | None = None, console: int | None = None,
       console_linger: float = 30.0) -> dict:
    """`on_started(sup, t0)`: called once every source runs, with the wall time of event time 0 (a benchmark kills one). `start`
    (live): the wall time of event time 0 (default 20 s from now: everyone is up by then).
    `topology`: a topology file or "derive": one router per command post (`mesh up
    --topology`), each EA and each command post's source attached to its own command
    post's router, router links through emulated links when `link` is given (a benchmark
    cuts them: `sup.procs["link-<lower>-<upper>"]`, SIGUSR1 cuts, SIGUSR2 heals).
    `paced_start`: with a speed, the wall time of event time 0 for every source (default:
    5 s after every EA is ready). `console`: the top unit's commander's console on that
    port (0: a free one), drawing the sources' frames; the EAs armed (urgent alerts are
    re-notified and escalated until acknowledged)."""
    from .. import scenario as S
    from ..sinks import COLOURS, RESET
    from ea_agent.core.alert import hms
    import sys
    sc = S.load(scenario, events=False)
    units = units or mesh_units(sc)
    colours = COLOURS if sys.stdout.isatty() else None
    out_dir.mkdir(parents=True, exist_ok=True)
    logs = out_dir / "logs"
    logs.mkdir(exist_ok=True)
    root = f"saim/{sc.name}/live"
    sources = cp_sources(sc)
    topo = None
    if topology is not None:
        from ..net import topology as T
        topo = T.derive(sc.taskorg) if topology == "derive" else T.load(topology, sc.taskorg, set(sources))
    sec: list[str] = []
    if topo is not None:
        pki = None
        if not insecure:
            from ..security.pki import make_pki, names_for
            pki = out_dir / "pki"
            make_pki(pki, names_for(sc, consoles=True) + [f"router.{n}" for n in topo.routers])
    elif insecure:
        echo("WARNING: insecure mesh: no authentication, no access control; anyone on the network can "
             "feed this mesh positions and end its sources' streams")
        hub = f"tcp/127.0.0.1:{free_port()}"
    else:   # mTLS and access control; the one router is a relay every client's rules accept
        from ..security.pki import make_pki, names_for
        pki = out_dir / "pki"
        make_pki(pki, names_for(sc, consoles=True) + ["router.hub"])
        hub = f"tls/127.0.0.1:{free_port()}"
        hub_topo = out_dir / "topology.json"
        hub_topo.write_text(json.dumps({"topology": {"routers": {"hub": {"cp": sc.taskorg.root, "links": []}},
                                                     "attach": {}, "top": "hub"}, "endpoints": {"hub": hub}}))
        sec = ["--pki", str(pki), "--topology", str(hub_topo)]
    sup = Supervisor(echo, pids_path=out_dir / "pids.json")
    start = start if start is not None else time.time() + 20.0
    live_args = ["--live", "--start", _iso(start)] if live else []

    until_args = ["--until", str(until)] if until is not None else []
    summaries: dict[str, dict] = {}
    seen: dict[str, int] = {}
    shown = Counter()
    t0 = time.monotonic()
    con = None
    link_files: dict = {}
    try:
        if topo is not None:   # a router per command post, linked as the topology says
            from ..net import routed
            eps, link_files, resolved = routed.start(scenario, topo, out_dir, root, sup, pki, link, echo)
            secure = ["--pki", str(pki)] if pki else []
            where = lambda who: ["--connect", eps[topo.router_of(who, sc.taskorg)], "--mode", "client",  # noqa: E731
                                 "--topology", str(resolved), *secure]
        else:
            # one Zenoh router for this host; every EA and source a client of it (since Zenoh 1.9
            # peers do not relay for each other: ../shared/notes/live-mesh.md)
            router = sup.add(Proc("router", [*py(), "router", "--scenario", scenario, "--name", "hub",
                                             "--listen", hub, "--root", root, *sec], env=clean_env(), log_dir=logs))
            router.wait_for("router ready", 60)
            where = lambda who: ["--connect", hub, "--mode", "client", *sec]  # noqa: E731
        for u in units:
            for f in (f"{u}.jsonl", f"{u}.input", f"{u}.notify.jsonl", f"{u}.cmdlog"):
                (out_dir / f).unlink(missing_ok=True)
            armed = ["--armed"] if console is not None else []
            sup.add(Proc(u, [*py(), "peer", "--scenario", scenario, "--unit", u, *where(u), "--root", root,
                             "--sources", *sources, "--out", str(out_dir / f"{u}.jsonl"), *live_args, *armed],
                         env=leaf_env(), log_dir=logs,
                         spawner=zygote.spawner()))   # EA peers fork from one zygote (saim_mesh/zygote.py)
        for u in units:
            sup.procs[u].wait_for(f"ready {u}", 120)
        if console is not None:   # not supervised: it ends after its linger
            con = Proc("console", [*py(), "console", scenario, "--sources", *where("console"), "--root", root,
                                   "--port", str(console), "--linger", str(console_linger)],
                       env=clean_env(), log_dir=logs)
            echo(con.wait_for("console http", 60).split(" ", 1)[1] + "  <- the commander's console", flush=True)
        if not live and speed != "max":   # every source paced on one clock: event time 0 at this instant
            paced_start = paced_start if paced_start is not None else time.time() + 5.0
        pace_args = ["--start", _iso(paced_start)] if paced_start is not None and not live else []
        for name, args in sources.items():
            sup.add(Proc(name, [*py(), "source", scenario, "--name", name, *args, *where(name.removeprefix("cp.")),
                                "--root", root, "--speed", speed, "--state", str(out_dir / "sources"),
                                "--linger", "30", *live_args, *pace_args, *until_args],
                         env=clean_env(), log_dir=logs))
        if on_started is not None:
            on_started(sup, paced_start if not live else start)
        end = time.monotonic() + timeout
        while time.monotonic() < end and len(summaries) < len(units):
            sup.check()
            for u in units:
                p = sup.procs[u]
                if show:
                    seen[u] = _show(out_dir / f"{u}.jsonl", seen.get(u, 0), echo, colours, RESET, hms, shown)
                if u not in summaries and (line := p.find("summary ")) is not None:
                    summaries[u] = json.loads(line[len("summary "):])
            time.sleep(0.1)
        if con is not None:   # the page stays up for its linger after the end
            try:
                con.p.wait(console_linger + 60)
            except Exception:   # a console that does not end is stopped below
                pass
    finally:
        if con is not None:
            con.stop()
        sup.stop()
    wall = time.monotonic() - t0
    result = {"peers": summaries, "wall_s": round(wall, 1), "sources": sorted(sources), "events": sup.events,
              "secure": not insecure,
              "start": start if live else None, "paced_start": paced_start, "root": root, "units": units,
              "topology": topo.to_dict() if topo is not None else None}
    if link_files:   # bytes per router link (the emulated links' counters)
        from ..net.routed import link_stats
        result["links"] = link_stats(link_files)
    (out_dir / "summary.json").write_text(json.dumps(result, indent=1, default=str))
    echo(table(out_dir, units, sc))
    echo(f"{len(summaries)} of {len(units)} EA peers done in {wall:.1f} s, sources {', '.join(sources)}, "
         f"{'insecure' if insecure else 'mTLS + access control'}; "
         f"alerts in {out_dir}/, logs in {logs}/")
    return result


def _show(path: Path, done: int, echo, colours, reset, hms, shown: Counter) -> int:
    """Print the alerts a peer logged since the last look (quiet ones left out)."""
    try:
        with open(path, encoding="utf-8") as f:
            lines = f.readlines()
    except FileNotFoundError:
        return done
    for line in lines[done:]:
        if not line.endswith("\n"):
            return done
        done += 1
        a = json.loads(line)
        if "silenced" in a["details"] or "inhibited_by" in a["details"]:
            continue
        shown[a["priority"]] += 1
        tag = f"{a['priority'].upper():9}"
        if colours:
            tag = f"{colours[a['priority']]}{tag}{reset}"
        echo(f"{hms(a['t'])} {a['owner']:>5} {tag} {a['type']:16} {a['message']}", flush=True)
    return done


def table(out_dir: Path, units: list[str], sc) -> str:
    """The Fig. 7 table from the peers' alert logs: alerts by type per EA (system problems apart)."""
    from ea_agent import domains
    counts = {u: Counter() for u in units}
    for u in units:
        try:
            for line in open(out_dir / f"{u}.jsonl", encoding="utf-8"):
                if line.endswith("\n"):
                    a = json.loads(line)
                    counts[u]["system-problem" if a["category"] == "system-problem" else a["type"]] += 1
        except FileNotFoundError:
            pass
    types = [t for t in domains.of(sc).ALERT_TYPES if any(c[t] for c in counts.values())]
    types += ["system-problem"] if any(c["system-problem"] for c in counts.values()) else []
    w = max([len(t) for t in types] + [16])
    lines = [f"{'alert type':{w}} " + " ".join(f"{u:>6}" for u in units)]
    lines += [f"{t:{w}} " + " ".join(f"{counts[u][t]:>6}" for u in units) for t in types]
    lines.append(f"{'total':{w}} " + " ".join(f"{sum(counts[u].values()):>6}" for u in units))
    return "\n".join(lines)


def _iso(t: float) -> str:
    from datetime import datetime, timezone
    return datetime.fromtimestamp(t, timezone.utc).isoformat()
