"""Which Zenoh routers exist, which command post each serves, who attaches where and
which router links exist (docs/topology.md).

A topology file (TOML) names routers and links; by default one is derived from the
task organization: a router at the top unit's command post and one at every battalion
command post, each battalion router linked to the router of the nearest command post
above it. Every other process attaches, as a Zenoh client, to the router of its unit's
nearest command post (each command post's source publishes its units' reports through that
router, so position reports start inside their battalion). Checked before anything starts: a
topology naming unknown units or routers, a cycle, or a router nobody can reach is a
`TopologyError` naming what is wrong.
"""
from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

CP_KINDS = ("battalion",)   # echelons with a command post (and a router) below the top unit
_BAD = set("/*$#? ")


class TopologyError(ValueError):
    """A topology that cannot be run; the message names the file and what is wrong."""


@dataclass(frozen=True)
class Router:
    name: str
    cp: str                    # the unit whose command post it serves
    links: tuple[str, ...] = ()   # routers it connects to (towards the top)


@dataclass
class Topology:
    routers: dict[str, Router]
    attach: dict[str, str] = field(default_factory=dict)   # unit (or process name) -> router
    top: str = ""                                           # the router at the top unit's command post

    # -- questions ----------------------------------------------------------------------
    def router_of(self, unit: str, taskorg) -> str:
        """The router a unit's EA (and its reports) attach to: explicit, or the router of
        the nearest command post at or above it."""
        hit = self.attach.get(unit)
        if hit is not None:
            return hit
        cps = {r.cp: r.name for r in self.routers.values()}
        for u in (unit, *taskorg.ancestors(unit)):
            if u in cps:
                return cps[u]
        return self.top

    def misplaced(self, unit: str, taskorg, endpoints: dict[str, str], connect: list[str]) -> str | None:
        """Why an EA attached to `connect` is on the wrong router (None when it is on its own
        command post's): it works, but its reports and what it hears cross radio links that
        a well-placed EA spares."""
        own = self.router_of(unit, taskorg)
        if endpoints.get(own) in connect:
            return None
        where = next((n for n, ep in endpoints.items() if ep in connect), "no router of the topology")
        return (f"EA of {taskorg.name(unit)} is attached to {where}, not to its command post's router {own}: "
                f"its traffic crosses radio links it should not")

    def links(self) -> list[tuple[str, str]]:
        """Router links as (lower, upper), sorted."""
        return sorted((r.name, up) for r in self.routers.values() for up in r.links)

    def side(self, link: tuple[str, str]) -> set[str]:
        """The routers below a link (on its lower end's side)."""
        below, up = link
        adj: dict[str, set[str]] = {n: set() for n in self.routers}
        for a, b in self.links():
            if (a, b) != link:
                adj[a].add(b)
                adj[b].add(a)
        seen, todo = {below}, [below]
        while todo:
            for n in adj[todo.pop()] - seen:
                seen.add(n)
                todo.append(n)
        return seen

    def to_dict(self) -> dict:
        return {"top": self.top, "routers": {n: {"cp": r.cp, "links": list(r.links)} for n, r in
                                             sorted(self.routers.items())}, "attach": dict(sorted(self.attach.items()))}


def router_name(unit: str) -> str:
    return f"r-{unit}"


def derive(taskorg) -> Topology:
    """One router per battalion command post and one at the top unit."""
    top = taskorg.root
    cps = [top] + sorted(u for u, x in taskorg.units.items() if x.kind in CP_KINDS and u != top)
    routers = {}
    for u in cps:
        up = next((a for a in taskorg.ancestors(u) if a in cps), None)
        routers[router_name(u)] = Router(router_name(u), u, (router_name(up),) if up else ())
    return Topology(routers, {}, router_name(top))


def load(path: str | Path, taskorg, known_procs: set[str] = frozenset()) -> Topology:
    """Read and check a topology file against the scenario's task organization.

    [[router]]                    # one per command post
    name = "r-1BN"
    cp = "1BN"                    # a unit of the task organization
    links = ["r-BDE"]             # routers it connects to

    [attach]                      # optional: unit or process -> router (default: its nearest CP)
    "1A" = "r-1BN"
    """
    p = Path(path)
    try:
        doc = tomllib.loads(p.read_text())
    except OSError as e:
        raise TopologyError(f"{p}: cannot read the topology file ({e.strerror})") from None
    except tomllib.TOMLDecodeError as e:
        raise TopologyError(f"{p}: not valid TOML ({e})") from None
    unknown_keys = set(doc) - {"router", "attach"}
    if unknown_keys:
        raise TopologyError(f"{p}: unknown sections {sorted(unknown_keys)} (expected [[router]] and [attach])")
    raw = doc.get("router")
    if not isinstance(raw, list) or not raw:
        raise TopologyError(f"{p}: no [[router]] entries")
    routers: dict[str, Router] = {}
    for i, r in enumerate(raw):
        where = f"{p}: router #{i + 1}"
        if not isinstance(r, dict):
            raise TopologyError(f"{where}: not a table")
        extra = set(r) - {"name", "cp", "links"}
        if extra:
            raise TopologyError(f"{where}: unknown fields {sorted(extra)}")
        name, cp, links = r.get("name"), r.get("cp"), r.get("links", [])
        if not isinstance(name, str) or not name or _BAD & set(name):
            raise TopologyError(f"{where}: 'name' must be a non-empty string without / * $ # ? or spaces, "
                                f"not {name!r}")
        if name in routers:
            raise TopologyError(f"{where}: router {name!r} named twice")
        if not isinstance(cp, str) or cp not in taskorg.units:
            raise TopologyError(f"{where} ({name}): 'cp' {cp!r} is not a unit of the task organization")
        if not isinstance(links, list) or not all(isinstance(x, str) for x in links):
            raise TopologyError(f"{where} ({name}): 'links' must be a list of router names")
        routers[name] = Router(name, cp, tuple(links))
    attach = doc.get("attach", {})
    if not isinstance(attach, dict):
        raise TopologyError(f"{p}: [attach] must be a table of unit = router")
    for who, r in attach.items():
        if who not in taskorg.units and who not in known_procs:
            raise TopologyError(f"{p}: [attach] {who!r} is neither a unit of the task organization nor a "
                                f"process of the mesh ({', '.join(sorted(known_procs)) or 'none'})")
        if r not in routers:
            raise TopologyError(f"{p}: [attach] {who} = {r!r}: no such router ({', '.join(sorted(routers))})")
    top_cp = taskorg.root
    tops = [n for n, r in routers.items() if r.cp == top_cp]
    topo = Topology(routers, dict(attach), tops[0] if tops else "")
    check(topo, p)
    return topo


def check(topo: Topology, where: str | Path = "topology") -> None:
    """Links name known routers, no router links to itself, the router graph has no
    cycle and every router is reachable from the top."""
    if not topo.top:
        raise TopologyError(f"{where}: no router at the top unit's command post")
    for r in topo.routers.values():
        for up in r.links:
            if up not in topo.routers:
                raise TopologyError(f"{where}: router {r.name} links to {up!r}: no such router")
            if up == r.name:
                raise TopologyError(f"{where}: router {r.name} links to itself")
    seen: set[frozenset] = set()
    parent: dict[str, str] = {n: n for n in topo.routers}

    def find(n: str) -> str:
        while parent[n] != n:
            parent[n] = parent[parent[n]]
            n = parent[n]
        return n
    for a, b in topo.links():
        if frozenset((a, b)) in seen:
            raise TopologyError(f"{where}: routers {a} and {b} are linked twice")
        seen.add(frozenset((a, b)))
        ra, rb = find(a), find(b)
        if ra == rb:
            raise TopologyError(f"{where}: the link {a} -> {b} closes a cycle of router links (a tree is "
                                f"expected: a cycle would carry data twice)")
        parent[ra] = rb
    lost = sorted(n for n in topo.routers if find(n) != find(topo.top))
    if lost:
        raise TopologyError(f"{where}: routers unreachable from {topo.top}: {', '.join(lost)} (no link path)")


def write(topo: Topology, path: str | Path) -> None:
    """The TOML form of a topology (what `saim-mesh topology` prints)."""
    lines = ["# saim-mesh topology: routers at command posts, their links, and who attaches where", ""]
    for n, r in sorted(topo.routers.items(), key=lambda x: (x[1].links != (), x[0])):
        lines += ["[[router]]", f'name = "{n}"', f'cp = "{r.cp}"',
                  "links = [" + ", ".join(f'"{x}"' for x in r.links) + "]", ""]
    if topo.attach:
        lines.append("[attach]")
        lines += [f'"{k}" = "{v}"' for k, v in sorted(topo.attach.items())]
    Path(path).write_text("\n".join(lines) + "\n")


def resolve(topo: Topology, endpoints: dict[str, str], path: str | Path) -> dict:
    """What `mesh up --topology` hands every process: the topology plus each router's
    listen endpoint (leaves connect there), written as JSON."""
    doc = {"topology": topo.to_dict(), "endpoints": dict(sorted(endpoints.items()))}
    Path(path).write_text(json.dumps(doc, indent=1))
    return doc


def read_resolved(path: str | Path) -> tuple[Topology, dict[str, str]]:
    """The topology and router endpoints from a resolved file (bad files: TopologyError)."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text())
        t = doc["topology"]
        routers = {n: Router(n, str(r["cp"]), tuple(str(x) for x in r["links"])) for n, r in t["routers"].items()}
        topo = Topology(routers, {str(k): str(v) for k, v in t.get("attach", {}).items()}, str(t["top"]))
        eps = {str(k): str(v) for k, v in doc["endpoints"].items()}
    except OSError as e:
        raise TopologyError(f"{p}: cannot read the resolved topology ({e.strerror})") from None
    except (ValueError, KeyError, TypeError, AttributeError) as e:
        raise TopologyError(f"{p}: not a resolved topology ({type(e).__name__}: {e})") from None
    check(topo, p)
    missing = sorted(set(routers) - set(eps))
    if missing:
        raise TopologyError(f"{p}: no endpoint for routers {', '.join(missing)}")
    return topo, eps


def routers_of_resolved(path: str | Path) -> list[str]:
    return sorted(read_resolved(path)[0].routers)
