"""Start a topology's routers and the emulated radio links between them (`mesh up
--topology`): the top router first, then each router below once the one it links to
is up, each lower router connecting through a `saim-mesh link` process that delays,
loses and counts what crosses (bytes per router link come from there)."""
from __future__ import annotations

import json
from pathlib import Path

from . import topology as T
from ..launch.proc import Proc, clean_env, py
from ..launch.zenoh_config import free_port


def _ep(port: int, secure: bool) -> str:
    return f"{'tls' if secure else 'tcp'}/127.0.0.1:{port}"


def start_link(sup, lower: str, upper: str, to_port: int, secure: bool, link: dict, out_dir: Path,
               seed: int = 0) -> tuple[str, Path]:
    """An emulated radio link from router `lower` to `upper` (listening on loopback port
    `to_port`): a `saim-mesh link` process named link-<lower>-<upper>; returns the endpoint
    `lower` connects to instead and the link's stats file."""
    lp = free_port()
    name = f"link-{lower}-{upper}"
    st = out_dir / f"{name}.json"
    st.unlink(missing_ok=True)
    args = [*py(), "link", "--listen", str(lp), "--to", str(to_port),
            "--delay-ms", str(link.get("delay_ms", 0.0)), "--loss", str(link.get("loss", 0.0)),
            "--seed", str(seed), "--stats", str(st)]
    sup.add(Proc(name, args, env=clean_env(), log_dir=out_dir / "logs")).wait_for("link ready", 30)
    return _ep(lp, secure), st


def start_router(sup, scenario: str, name: str, listen: list[str], connect: list[str], root: str, resolved: Path,
                 pki=None, log_dir: Path | None = None, wait: float = 60.0) -> Proc:
    """One router process under `sup`, listening on `listen`, linked to `connect`;
    returns once it said it is ready."""
    sec = ["--pki", str(pki)] if pki else []
    p = sup.add(Proc(name, [*py(), "router", "--scenario", scenario, "--name", name, "--root", root,
                            "--listen", *listen, "--topology", str(resolved), *sec,
                            *(["--connect", *connect] if connect else [])], env=clean_env(), log_dir=log_dir))
    p.wait_for("router ready", wait)
    return p


def start(scenario: str, topo: T.Topology, out_dir: Path, root: str, sup, pki=None, link: dict | None = None,
          echo=print) -> tuple[dict[str, str], dict[str, Path], Path]:
    """Start every router and link under `sup` on loopback (`link` None: routers connect
    directly, nothing emulated or counted); returns the router endpoints leaves connect
    to, each link's stats file, and the resolved topology file."""
    logs = out_dir / "logs"
    ports = {n: free_port() for n in topo.routers}
    eps = {n: _ep(p, pki is not None) for n, p in ports.items()}
    resolved = out_dir / "topology.json"
    T.resolve(topo, eps, resolved)
    stats: dict[str, Path] = {}
    order = parents_first(topo)
    for n in order:
        connect = []
        for up in topo.routers[n].links:
            if link is None:   # no emulated link: straight to the router above
                connect.append(eps[up])
                continue
            ep, stats[f"{n}->{up}"] = start_link(sup, n, up, ports[up], pki is not None, link, out_dir, len(stats))
            connect.append(ep)
        start_router(sup, scenario, n, [eps[n]], connect, root, resolved, pki, logs)
    echo(f"topology: {len(topo.routers)} routers ({', '.join(order)}), {len(stats)} links"
         + (f" at {link.get('delay_ms', 0):g} ms / {100 * link.get('loss', 0):g} % loss" if link is not None else
            " (direct)"))
    return eps, stats, resolved


def parents_first(topo: T.Topology) -> list[str]:
    """Routers in start order: each after the one it links to."""
    return sorted(topo.routers, key=lambda n: len(_path_up(topo, n)))


def _path_up(topo: T.Topology, n: str) -> list[str]:
    out, seen = [], {n}
    while topo.routers[n].links:
        n = topo.routers[n].links[0]
        if n in seen:
            break
        seen.add(n)
        out.append(n)
    return out


def link_stats(stats: dict[str, Path]) -> dict[str, dict]:
    """Each link's counters (what its `saim-mesh link` process wrote)."""
    out = {}
    for name, path in stats.items():
        try:
            out[name] = json.loads(path.read_text())
        except (OSError, ValueError):
            out[name] = None
    return out
