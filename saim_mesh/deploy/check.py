"""What is wrong with a parsed deployment file against its scenario (units, sources, fusion
groups, consoles, ports) and against this machine (`--host`: its addresses, its
interface, ports in use), one line each; `load` reads, parses and checks a file whole."""
from __future__ import annotations

import ipaddress
import socket
from pathlib import Path

from .file import DeployError, Deployment, Errors, parse


def check(dep: Deployment, sc, host: str | None = None, where: str = "deployment") -> list[str]:
    """What is wrong with a parsed deployment against its scenario (one line each); with
    `host`, also whether this machine is that host (its addresses, its interface)."""
    from ..live.depend import cp_shares
    from ..scenario import mesh_units
    e = Errors(where)
    to = sc.taskorg
    units = set(mesh_units(sc))
    shares = set(cp_shares(sc))
    groups = set(sc.meta.get("fusion", {}).get("groups", {}))
    seen: dict[tuple[str, str], str] = {}
    for h in dep.hosts.values():
        w = f"host {h.name!r}"
        for kind, known, what in (("eas", units, "a unit that runs an EA peer"),
                                  ("sources", shares, "a command post's or a fusion node's source")):
            for x in getattr(h, kind):
                if kind == "eas" and x not in to.units:
                    e(f"{w}: eas: {x!r} is not a unit of {sc.name}'s task organization")
                elif x not in known:
                    e(f"{w}: {kind}: {x!r} is not {what} of {sc.name} ({', '.join(sorted(known))})")
                elif (kind, x) in seen:
                    other = seen[(kind, x)]
                    e(f"{w}: {kind}: {x} runs on two hosts ({other} and {h.name})" if other != h.name else
                      f"{w}: {kind}: {x} named twice")
                seen.setdefault((kind, x), h.name)
        for g in h.fusion:
            e(f"{w}: fusion: {g!r}: " + (f"on the live mesh a fusion node is a source: put fusion.{g} in this "
                                         "host's sources instead" if g in groups else
                                         f"no such fusion group in {sc.name} ({', '.join(sorted(groups)) or 'none'})"))
        ports: set[int] = set()
        for c in h.consoles:
            if c.unit not in units:
                e(f"{w}: console {c.unit!r}: not a unit that runs an EA peer (consoles act as console.<unit>)")
            if c.port and c.port in ports:
                e(f"{w}: console {c.unit}: port {c.port} used twice on this host")
            ports.add(c.port)
        if h.attach is not None and h.attach not in dep.routers:
            e(f"{w}: attach: {h.attach!r} is not a router of this file ({', '.join(sorted(dep.routers))})")
        if dep.secure and not (h.addresses or h.names):
            e(f"{w}: secure mode needs its addresses (or DNS names) in the file: its certificates carry them")
    if dep.live and dep.start is None and len(dep.hosts) > 1:
        e("live = true needs start (event time 0 must be the same instant on every host)")
    taks = [h.name for h in dep.hosts.values() if h.tak is not None]
    if len(taks) > 1:
        e(f"a TAK gateway on {len(taks)} hosts ({', '.join(taks)}): the identity 'tak' is one gateway")
    for s in sorted(shares - {x for (k, x) in seen if k == "sources"}):
        e(f"source {s} runs on no host: its units' reports would be missing (add it to a host's sources)")
    listen: dict[tuple[str, int], str] = {}
    before = len(e.lines)
    for r in dep.routers.values():
        w = f"router {r.name!r}"
        h = dep.hosts.get(r.host)
        if h is None:
            e(f"{w}: host {r.host!r} is not a host of this file ({', '.join(sorted(dep.hosts)) or 'none'})")
        if r.cp and r.cp not in to.units:
            e(f"{w}: cp {r.cp!r} is not a unit of {sc.name}'s task organization")
        for up in r.links:
            if up not in dep.routers:
                e(f"{w}: links to {up!r}: no such router ({', '.join(sorted(dep.routers))})")
            elif up == r.name:
                e(f"{w}: links to itself")
            elif h is not None and dep.routers[up].host != r.host and dep.hosts.get(dep.routers[up].host) is not None \
                    and dep.hosts[dep.routers[up].host].reach() is None:
                e(f"{w}: links to {up} on host {dep.routers[up].host}, which has no address or name to reach it at")
        if h is not None and r.port:
            for a in h.addresses or (h.interface,):
                if (a, r.port) in listen:
                    e(f"{w}: listens on {a} port {r.port} like router {listen[(a, r.port)]}")
                listen[(a, r.port)] = r.name
    routers_ok = len(e.lines) == before
    if routers_ok and dep.routers:
        from ..net import topology as T
        topo = dep.topology()
        topo.top = dep._top(to)
        try:
            T.check(topo, "routers")
        except T.TopologyError as x:
            e(str(x).replace("routers: ", "", 1).replace("the top unit's command post",
                                                        f"the top unit's command post ({to.root})"))
    for h in dep.hosts.values():   # leaves on a host without a router reach another host's
        if routers_ok and (h.attach is None or h.attach in dep.routers) and (h.eas or h.sources) and not any(
                r.host == h.name for r in dep.routers.values()):
            for u in (*h.eas, *(s.removeprefix("cp.") for s in h.sources)):
                r = dep.attach(h.name, u, to)
                if dep.hosts[dep.routers[r].host].reach() is None:
                    e(f"host {h.name!r}: {u} attaches to {r} on host {dep.routers[r].host}, which has no address")
                    break
    if host is not None:
        e.lines += this_host(dep, host, where)
    return e.lines


def this_host(dep: Deployment, host: str, where: str = "deployment") -> list[str]:
    """Whether this machine can be `host`: its addresses are this machine's, its interface exists."""
    e = Errors(where)
    h = dep.hosts.get(host)
    if h is None:
        e(f"--host {host}: not a host of this file ({', '.join(sorted(dep.hosts))})")
        return e.lines
    if h.interface is not None:
        try:
            socket.if_nametoindex(h.interface)
        except OSError:
            e(f"host {host!r}: interface {h.interface!r} does not exist on this machine")
            return e.lines
        have = interface_addresses(h.interface)
        for a in h.addresses:
            if have is not None and a not in have:
                e(f"host {host!r}: address {a} is not on interface {h.interface} ({', '.join(have) or 'none'})")
    for a in h.addresses:
        if not is_local(a):
            e(f"host {host!r}: address {a} is not one of this machine's (is this {host}?)")
        else:
            for r in dep.routers.values():
                if r.host == host and r.port and not is_local(a, r.port):
                    e(f"router {r.name!r}: port {r.port} on {a} is in use (is this host's mesh running already?)")
    return e.lines


def is_local(address: str, port: int = 0) -> bool:
    """Whether this machine can listen on `address` (and `port`): binding says so,
    namespaces included."""
    fam = socket.AF_INET6 if ipaddress.ip_address(address).version == 6 else socket.AF_INET
    try:
        with socket.socket(fam, socket.SOCK_STREAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)   # a port in TIME_WAIT is free to Zenoh too
            s.bind((address, port))
        return True
    except OSError:
        return False


def interface_addresses(name: str) -> list[str] | None:
    """The addresses on interface `name` (`ip -j addr`), None when `ip` cannot tell."""
    import json
    import subprocess
    try:
        out = subprocess.run(["ip", "-j", "addr", "show", "dev", name], capture_output=True, text=True, timeout=10)
        doc = json.loads(out.stdout) if out.returncode == 0 else None
    except (OSError, ValueError, subprocess.SubprocessError):
        return None
    if not doc:
        return None
    return [str(ipaddress.ip_address(a["local"])) for d in doc for a in d.get("addr_info", []) if "local" in a]


def load(path: str | Path, host: str | None = None):
    """Read, parse and check a deployment file: (Deployment, Scenario), or DeployError
    with every line that is wrong."""
    from .. import scenario as S
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except OSError as x:
        raise DeployError([f"{p}: cannot read the deployment file ({x.strerror or x})"]) from None
    except UnicodeDecodeError:
        raise DeployError([f"{p}: not a text file (UTF-8)"]) from None
    dep, lines = parse(text, p)
    if dep is None:
        raise DeployError(lines)
    try:
        sc = S.load(dep.scenario, events=False)
    except (S.ScenarioError, OSError, ValueError, KeyError) as x:
        raise DeployError(lines + [f"{p}: scenario {dep.scenario}: cannot load it ({' '.join(str(x).split())})"]) \
            from None
    lines += check(dep, sc, host, str(p))
    if lines:
        raise DeployError(lines)
    if dep.root is None:
        dep.root = f"saim/{sc.name}/live"
    return dep, sc
