"""`saim-mesh mesh up`: the mesh, with no centre, on one host. One source per command
post (each company's subtree; the battalion's own units and the hostile tracks its
sensors see), one EA peer per unit advancing on those sources' watermarks. Alerts are
printed as the peers raise them (read from their durable logs), the Fig. 7 table at the
end. Supervised (saim_mesh/launch/supervise.py): a child that dies is reported
and restarted, up to `max_restarts` times each (`--restarts`; a restarted source takes a
new epoch and resumes after what it published, a restarted peer replays its input
journal), then given up with one line and the mesh goes on without it."""
from __future__ import annotations

import json
from collections import Counter
from pathlib import Path

from ..scenario import mesh_units
from .depend import cp_shares

LOCAL = "local"   # the one host's name in its deployment


def cp_sources(sc) -> dict[str, list[str]]:
    """name -> `saim-mesh source` arguments: one per child of the top unit (its subtree),
    and the top's own share (everything else, with the tracks): `depend.cp_shares`."""
    return {name: sh.args() for name, sh in cp_shares(sc).items()}


def one_host(sc, scenario: str, units: list[str], out_dir: Path, speed: str = "max", live: bool = False,
             until: float | None = None, insecure: bool = False, topology: str | None = None,
             console: int | None = None, tak=None, pki: Path | None = None, root: str | None = None):
    """The deployment `mesh up` runs: everything on this host at 127.0.0.1 with free ports;
    one router (`hub`), or a topology's routers (a file, or "derive": one per battalion
    command post and the top); a test PKI made under OUT_DIR/pki. Returns (deployment,
    topology or None)."""
    from ..deploy.file import Console, Deployment, Host, RouterSpec
    topo = None
    if topology is not None:
        from ..net import topology as T
        topo = T.derive(sc.taskorg) if topology == "derive" else T.load(topology, sc.taskorg, set(cp_shares(sc)))
        routers = {n: RouterSpec(n, LOCAL, r.cp, 0, r.links) for n, r in topo.routers.items()}
    else:   # one Zenoh router for this host; every EA and source a client of it (since Zenoh 1.9
        # peers do not relay for each other: ../shared/notes/live-mesh.md)
        routers = {"hub": RouterSpec("hub", LOCAL, sc.taskorg.root, 0, ())}
    if insecure:
        pki = None
    elif pki is None:   # a test PKI (else the operator's, checked by run_host); routers accepted as relays
        from ..security.pki import make_pki, names_for
        pki = out_dir / "pki"
        make_pki(pki, names_for(sc, consoles=True) + [f"router.{n}" for n in routers])
    cons = (Console(sc.taskorg.root, console),) if console is not None else ()
    host = Host(LOCAL, ("127.0.0.1",), (), None, None, tuple(units), tuple(cp_shares(sc)), (), cons, tak)
    dep = Deployment(scenario, {LOCAL: host}, routers, root or f"saim/{sc.name}/live", not insecure, pki, speed, live,
                     None, until, 30.0, None, dict(topo.attach) if topo is not None else {})
    return dep, topo


def up(scenario: str, units: list[str] | None, out_dir: Path, speed: str = "max", timeout: float = 1800.0,
       echo=print, live: bool = False, show: bool = True, until: float | None = None, on_started=None,
       start: float | None = None, insecure: bool = False, topology: str | None = None,
       link: dict | None = None, paced_start: float | None = None, console: int | None = None,
       console_linger: float = 30.0, max_restarts: int = 10, tak=None, pki: Path | None = None,
       root: str | None = None) -> dict:
    """`on_started(sup, t0)`: called once every source runs, with the wall time of event time 0 (a benchmark kills one). `start`
    (live): the wall time of event time 0 (default 20 s from now: everyone is up by then).
    `topology`: a topology file or "derive": one router per command post (`mesh up
    --topology`), each EA and each command post's source attached to its own command
    post's router, router links through emulated links when `link` is given (a benchmark
    cuts them: `sup.procs["link-<lower>-<upper>"]`, SIGUSR1 cuts, SIGUSR2 heals).
    `paced_start`: with a speed, the wall time of event time 0 for every source (default:
    5 s after every EA is ready). `console`: the top unit's commander's console on that
    port (0: a free one), drawing the sources' frames; the EAs armed (urgent alerts are
    re-notified and escalated until acknowledged). `max_restarts`: restarts per process
    before it is given up (the result's `given_up`). `tak`: a `deploy.file.Tak`, the
    Cursor-on-Target gateway started and supervised with the rest (its PLI a live source
    the EAs take when `live`). `pki`: certificates the operator made (default: a test PKI
    made under OUT_DIR/pki); `root`: the key-expression root.

    The one-host case of `saim-mesh deploy` (`deploy.launch.run_host`)."""
    from .. import scenario as S
    from ..deploy.launch import run_host
    sc = S.load(scenario, events=False)
    units = units or mesh_units(sc)
    out_dir.mkdir(parents=True, exist_ok=True)
    if insecure and topology is None:
        echo("WARNING: insecure mesh: no authentication, no access control; anyone on the network can "
             "feed this mesh positions and end its sources' streams")
    dep, topo = one_host(sc, scenario, units, out_dir, speed, live, until, insecure, topology, console, tak, pki, root)
    made_by = (f"mesh up --pki {pki}", f"make them with saim-mesh certs {scenario} --out {pki} --routers "
               f"{' '.join(dep.routers)}") if pki is not None else None
    res = run_host(dep, sc, LOCAL, out_dir, echo=echo, show=show, timeout=timeout, until_done=True, pki_said=made_by,
                   on_started=on_started, start=start, paced_start=paced_start, link=link,
                   console_linger=console_linger, max_restarts=max_restarts)
    res["topology"] = topo.to_dict() if topo is not None else None
    (out_dir / "summary.json").write_text(json.dumps(res, indent=1, default=str))
    return res


def show_alerts(path: Path, done: int, echo, colours, reset, hms, shown: Counter) -> int:
    """Print the alerts a peer logged since the last look (quiet ones left out)."""
    return _show(path, done, echo, colours, reset, hms, shown)


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
