"""`saim-mesh deploy init SCENARIO`: a deployment derived from the task organization,
one host per command post: the top unit's, and each unit directly under it that
commands units which themselves command (a company, a battalion: not a lone platoon or
a headquarters squad, whose EAs and sources stay at the top's post). Each host runs a
router linked to the top's, the EAs of the units it is the nearest post for, the
sources of the same shares (`live.depend.cp_shares`) and its commander's console."""
from __future__ import annotations

import ipaddress
import json
import os
from pathlib import Path

from .file import DEFAULT_PORT, Console, Deployment, Host, RouterSpec

CONSOLE_PORT = 8470


def command_posts(taskorg) -> list[str]:
    """The top unit, then each unit under it with grandchildren, sorted."""
    kids = lambda u: [c for c, p in taskorg.parent.items() if p == u]   # noqa: E731
    top = taskorg.root
    return [top] + sorted(u for u in kids(top) if any(kids(c) for c in kids(u)))


def _post_of(unit: str, posts: list[str], taskorg) -> str:
    for u in (unit, *taskorg.ancestors(unit)):
        if u in posts:
            return u
    return posts[0]


def addresses_for(spec: str | None, n: int, port: int) -> list[tuple[str, int]]:
    """(address, port) per host: a network (198.18.0.0/24: .1, .2, ... one port), a
    comma-separated list (one per host), one address (every host on it, ports port,
    port+1, ...), or nothing (127.0.0.1 that way: the whole deployment on this machine)."""
    spec = (spec or "127.0.0.1").strip()
    if "," in spec:
        addrs = [str(ipaddress.ip_address(a.strip())) for a in spec.split(",") if a.strip()]
        if len(addrs) != n:
            raise ValueError(f"--addresses: {len(addrs)} addresses for {n} hosts")
        return [(a, port) for a in addrs]
    if "/" in spec:
        net = ipaddress.ip_network(spec, strict=False)
        hosts = []
        for a in net.hosts():
            hosts.append((str(a), port))
            if len(hosts) == n:
                return hosts
        raise ValueError(f"--addresses {spec}: room for {len(hosts)} hosts, {n} needed")
    a = str(ipaddress.ip_address(spec))
    return [(a, port + i) for i in range(n)]


def derive(sc, scenario: str, addresses: str | None = None, port: int = DEFAULT_PORT, consoles: bool = True,
           secure: bool = True, pki: str | None = None) -> Deployment:
    from ..live.depend import cp_shares, home_of
    from ..scenario import mesh_units
    to = sc.taskorg
    posts = command_posts(to)
    where = addresses_for(addresses, len(posts), port)
    units = mesh_units(sc)
    hosts, routers = {}, {}
    shared = len({a for a, _ in where}) < len(where)   # hosts on one machine: one console port each
    for i, (cp, (addr, p)) in enumerate(zip(posts, where)):
        eas = tuple(u for u in units if _post_of(u, posts, to) == cp)
        srcs = tuple(sorted(s for s in cp_shares(sc) if _post_of(home_of(sc, s), posts, to) == cp))
        cons = (Console(cp, CONSOLE_PORT + i * shared),) if consoles and cp in units else ()
        hosts[cp] = Host(cp, (addr,), (), None, None, eas, srcs, (), cons, None)
        rn = f"r-{cp}"
        routers[rn] = RouterSpec(rn, cp, cp, p, () if cp == to.root else (f"r-{to.root}",))
    return Deployment(scenario, hosts, routers, f"saim/{sc.name}/live", secure, Path(pki) if pki else None)


def _q(x) -> str:
    return json.dumps(x)


def _list(xs) -> str:
    return "[" + ", ".join(_q(x) for x in xs) + "]"


def to_toml(dep: Deployment, sc_name: str) -> str:
    """The file `deploy init` writes: every field a host or router has, commented."""
    lines = [f"# saim-mesh deployment of {sc_name}: which host runs what (docs/deployment.md).",
             "# Check it with `saim-mesh deploy FILE --check`, make the certificates with",
             "# `saim-mesh certs --deploy FILE`, then on each host `saim-mesh deploy FILE --host NAME`.",
             "# Paths are relative to this file.", "",
             f"scenario = {_q(dep.scenario)}",
             f"root = {_q(dep.root)}   # key-expression root, the same on every host",
             f"secure = {'true' if dep.secure else 'false'}   # mTLS + access control",
             f"pki = {_q(str(dep.pki))}   # certificates: saim-mesh certs --deploy THIS_FILE" if dep.pki else
             '# pki = "pki"   # certificates (default: pki/ beside this file): saim-mesh certs --deploy THIS_FILE',
             'speed = "max"   # the recorded battle: "max" or a factor (1: real time)',
             "# live = true   # event time is the wall clock from `start`",
             '# start = "2026-11-27T09:00:00Z"   # event time 0 (live, or paced sources: the same on every host)',
             "# until = 1800   # end the sources at this event time",
             "# source_linger = 30   # seconds a source stays up after its end, and while its journal is still asked",
             '# catch_up = "yield"   # recoveries yield to live traffic (DROP, lower priority); default "block"',
             "# catch_up_kbit = 24   # with yield: each source's journal answers at most this, all askers together",
             ""]
    for h in dep.hosts.values():
        lines += ["[[host]]", f"name = {_q(h.name)}", f"addresses = {_list(h.addresses)}",
                  f"names = {_list(h.names)}                      # DNS names, in its certificates too",
                  "# interface = \"eth0\"            # listen on this interface's addresses",
                  f"eas = {_list(h.eas)}", f"sources = {_list(h.sources)}"]
        if h.consoles:
            lines.append("consoles = [" + ", ".join(f"{{unit = {_q(c.unit)}, port = {c.port}}}" for c in h.consoles)
                         + "]   # HTTP on 127.0.0.1")
        if h.attach:
            lines.append(f"attach = {_q(h.attach)}")
        if h.tak:
            lines.append(f"tak = {{cot = {_list(h.tak.cot)}, listen_cot = {_list(h.tak.listen_cot)}}}")
        elif h is next(iter(dep.hosts.values())):
            lines.append('# tak = {cot = ["udp://239.2.3.1:6969"], listen_cot = []}   # the Cursor-on-Target gateway')
        lines.append("")
    for r in dep.routers.values():
        lines += ["[[router]]", f"name = {_q(r.name)}", f"host = {_q(r.host)}", f"cp = {_q(r.cp)}",
                  f"port = {r.port}", f"links = {_list(r.links)}", ""]
    return "\n".join(lines)


def write(sc, scenario: str, out: Path, **kw) -> Deployment:
    """Derive and write a deployment file; the scenario (and pki) paths relative to it."""
    out = Path(out)
    rel = os.path.relpath(Path(scenario).resolve(), out.resolve().parent)
    pki = kw.pop("pki", None)
    dep = derive(sc, rel, pki=os.path.relpath(Path(pki).resolve(), out.resolve().parent) if pki else None, **kw)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(to_toml(dep, sc.name))
    return dep
