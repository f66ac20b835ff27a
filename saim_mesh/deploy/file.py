"""The deployment file (docs/deployment.md): which host runs which routers, EA peers,
sources, consoles and TAK gateway of a live mesh, and where the routers listen.

It is read whole and checked before anything starts: every problem is one line naming
the file, the host or router and the field (`parse` here; `check.check` against its
scenario and this machine; `check.load` raises `DeployError` with them all), never a
traceback. The same `Deployment` drives one host of
a real deployment (`saim-mesh deploy FILE --host NAME`) and the one-host `mesh up`
(built in code, with free ports: `port = 0`).
"""
from __future__ import annotations

import ipaddress
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

DEFAULT_PORT = 7447           # Zenoh's own default
NAME_RE = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")
DNS_RE = re.compile(r"^[A-Za-z0-9]([A-Za-z0-9.-]*[A-Za-z0-9])?$")
TOP_KEYS = {"scenario", "root", "secure", "pki", "speed", "live", "start", "until", "source_linger", "catch_up",
            "catch_up_kbit", "host",
            "router"}
HOST_KEYS = {"name", "addresses", "names", "interface", "attach", "eas", "sources", "fusion", "consoles", "tak"}
ROUTER_KEYS = {"name", "host", "cp", "port", "links"}
CONSOLE_KEYS = {"unit", "port"}
TAK_KEYS = {"cot", "listen_cot", "uids", "proto"}


class DeployError(ValueError):
    """A deployment that cannot run; `lines` says each thing wrong, one line each."""

    def __init__(self, lines: list[str]):
        super().__init__("\n".join(lines))
        self.lines = lines


@dataclass(frozen=True)
class Console:
    unit: str
    port: int = 0              # HTTP on 127.0.0.1 (0: a free port)


@dataclass(frozen=True)
class Tak:
    cot: tuple[str, ...] = ()          # where CoT goes (gateway --cot-url)
    listen_cot: tuple[str, ...] = ()   # where TAK PLI come in (gateway --listen-cot)
    uids: str | None = None            # uid -> entity map (path, relative to the file)
    proto: str = "xml"                 # CoT out as XML, or TAK protocol version 1 (protobuf)


@dataclass(frozen=True)
class Host:
    name: str
    addresses: tuple[str, ...] = ()    # where its routers listen and other hosts reach them
    names: tuple[str, ...] = ()        # DNS names (certificates; endpoints when no address)
    interface: str | None = None       # listen on this interface's addresses (checked on the host)
    attach: str | None = None          # the router its leaves attach to (default: its own, nearest CP)
    eas: tuple[str, ...] = ()
    sources: tuple[str, ...] = ()
    fusion: tuple[str, ...] = ()
    consoles: tuple[Console, ...] = ()
    tak: Tak | None = None

    def reach(self) -> str | None:
        """The address (or name) other hosts connect to."""
        return (self.addresses or self.names or (None,))[0]


@dataclass(frozen=True)
class RouterSpec:
    name: str
    host: str
    cp: str                    # the unit whose command post it serves
    port: int = DEFAULT_PORT   # 0: a free port (one host only)
    links: tuple[str, ...] = ()


@dataclass
class Deployment:
    scenario: str                       # path of the scenario folder
    hosts: dict[str, Host]
    routers: dict[str, RouterSpec]
    root: str | None = None             # key-expression root (default saim/<scenario>/live)
    secure: bool = True
    pki: Path | None = None             # certificates (saim-mesh certs --deploy)
    speed: str = "max"                  # the recorded battle's pace: "max" or a factor
    live: bool = False                  # event time is the wall clock from `start`
    start: str | None = None            # ISO 8601: event time 0 (live, or paced sources)
    until: float | None = None
    source_linger: float = 30.0
    path: Path | None = None            # the file it came from
    attach_map: dict[str, str] = field(default_factory=dict)   # unit -> router (a topology file's [attach])
    catch_up: str | None = None         # "yield" | "block" (the default)
    catch_up_kbit: float | None = None  # the sources' journals' pace (default with "yield": live/srcjournal.py)

    def yielding(self) -> bool:
        """Sources' recoveries and catch-ups yield to live traffic (live/source.py), asked
        for across radio links between hosts; not the default: it did not stop a router's
        links flapping after a heal (docs/history/deployment-notes.md)."""
        return self.catch_up == "yield"

    # -- who runs where ---------------------------------------------------------------
    def host_of(self, what: str, kind: str = "eas") -> str | None:
        return next((h.name for h in self.hosts.values() if what in getattr(h, kind)), None)

    def sources(self) -> list[str]:
        """Every live source the EAs may depend on: the command posts' and, on the wall
        clock, the TAK gateway's PLI (`tak`)."""
        pli = self.live and any(h.tak is not None and h.tak.listen_cot for h in self.hosts.values())
        return sorted([*(s for h in self.hosts.values() for s in h.sources), *(["tak"] if pli else [])])

    def eas(self) -> list[str]:
        return [u for h in self.hosts.values() for u in h.eas]

    def topology(self):
        """The routers as a `net.topology.Topology` (top: the router at the top unit's CP)."""
        from ..net import topology
        routers = {n: topology.Router(n, r.cp, r.links) for n, r in self.routers.items()}
        return topology.Topology(routers, {}, self._top())

    def _top(self, taskorg=None) -> str:
        cps = {r.cp for r in self.routers.values()}
        if taskorg is not None:
            top = taskorg.root
        else:   # the CP no other router's CP is under: the one with no links up
            top = next((r.cp for r in self.routers.values() if not r.links), None)
        return next((n for n, r in sorted(self.routers.items()) if r.cp == top), "") if top in cps else ""

    def attach(self, host: str, unit: str, taskorg) -> str:
        """The router a process of `host` acting for `unit` connects to: the host's `attach`,
        else the host's router serving the nearest command post at or above the unit, else
        any router of the host, else the router of the nearest command post anywhere."""
        h = self.hosts[host]
        if unit in self.attach_map:
            return self.attach_map[unit]
        if h.attach:
            return h.attach
        mine = {r.cp: n for n, r in sorted(self.routers.items(), reverse=True) if r.host == host}
        chain = (unit, *taskorg.ancestors(unit)) if unit in taskorg.units else ()
        for u in chain:
            if u in mine:
                return mine[u]
        if mine:
            return sorted(n for n, r in self.routers.items() if r.host == host)[0]
        every = {r.cp: n for n, r in sorted(self.routers.items(), reverse=True)}
        for u in chain:
            if u in every:
                return every[u]
        return self._top(taskorg) or sorted(self.routers)[0]

    def proto(self) -> str:
        return "tls" if self.secure else "tcp"

    def endpoint(self, router: str, address: str | None = None, port: int | None = None) -> str:
        """`tls/ADDR:PORT` where others connect to `router` (its host's first address)."""
        r = self.routers[router]
        return endpoint(self.proto(), address or self.hosts[r.host].reach() or "127.0.0.1",
                        r.port if port is None else port)


def endpoint(proto: str, address: str, port: int) -> str:
    try:
        if ipaddress.ip_address(address).version == 6:
            address = f"[{address}]"
    except ValueError:
        pass
    return f"{proto}/{address}:{port}"


# ------------------------------------------------------------------------- reading

class Errors:
    def __init__(self, where: str):
        self.where, self.lines = where, []

    def __call__(self, what: str) -> None:
        self.lines.append(f"{self.where}: {' '.join(str(what).split())}")


def _str(v, e, where: str, required: bool = False) -> str | None:
    if v is None:
        if required:
            e(f"{where}: missing")
        return None
    if not isinstance(v, str) or not v.strip():
        e(f"{where}: expected a non-empty string, not {v!r}")
        return None
    return v


def _strs(v, e, where: str) -> tuple[str, ...]:
    if v is None:
        return ()
    if not isinstance(v, list) or not all(isinstance(x, str) and x.strip() for x in v):
        e(f"{where}: expected a list of non-empty strings, not {v!r}")
        return ()
    return tuple(v)


def _number(v, e, where: str, low: float = 0.0) -> float | None:
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        e(f"{where}: expected a number, not {v!r}")
        return None
    if not math.isfinite(v) or v < low:
        e(f"{where}: expected a finite number >= {low:g}, not {v!r}")
        return None
    return float(v)


def _port(v, e, where: str, default: int, zero: bool = False) -> int:
    if v is None:
        return default
    if isinstance(v, bool) or not isinstance(v, int):
        e(f"{where}: expected a whole port number, not {v!r}")
        return default
    if not (0 if zero else 1) <= v <= 65535:
        e(f"{where}: port {v} out of range ({0 if zero else 1}-65535)")
        return default
    return v


def _bool(v, e, where: str, default: bool) -> bool:
    if v is None:
        return default
    if not isinstance(v, bool):
        e(f"{where}: expected true or false, not {v!r}")
        return default
    return v


def _unknown(d: dict, known: set[str], e, where: str) -> None:
    extra = sorted(set(d) - known)
    if extra:
        e(f"{where}: unknown keys {', '.join(map(repr, extra))} (known: {', '.join(sorted(known))})")


def _named_tables(doc: dict, kind: str, known: set[str], e, none: str):
    """Each `[[kind]]` table with a valid name not used before: (name, where, table);
    every problem on the way said once through `e`."""
    raw = doc.get(kind, [])
    if not isinstance(raw, list) or not all(isinstance(t, dict) for t in raw):
        e(f"{kind}: expected [[{kind}]] tables")
        raw = []
    if not raw:
        e(none)
    seen: set[str] = set()
    for i, t in enumerate(raw):
        name = t.get("name")
        where = f"{kind} #{i + 1}" + (f" {name!r}" if isinstance(name, str) else "")
        _unknown(t, known, e, where)
        if not isinstance(name, str) or not NAME_RE.match(name):
            e(f"{where}: name: expected letters, digits, '.', '_' or '-', not {name!r}")
            continue
        if name in seen:
            e(f"{where}: {kind} {name!r} named twice")
            continue
        seen.add(name)
        yield name, where, t


def parse(text: str, path: Path | None = None) -> tuple[Deployment | None, list[str]]:
    """The file's structure and types (no scenario needed): a Deployment, and every
    problem found, one line each."""
    e = Errors(str(path) if path else "deployment")
    base = path.parent if path else Path(".")
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as x:
        e(f"not valid TOML ({x})")
        return None, e.lines
    _unknown(doc, TOP_KEYS, e, "top level")
    scen = _str(doc.get("scenario"), e, "scenario", required=True)
    root = _str(doc.get("root"), e, "root")
    if root is not None and (set("*$#? ") & set(root) or root.startswith("/") or root.endswith("/") or "//" in root):
        e(f"root: {root!r} is not a key-expression prefix (no * $ # ? spaces, no empty chunk)")
        root = None
    pki = _str(doc.get("pki"), e, "pki")
    speed = doc.get("speed", "max")
    if speed != "max":
        f = _number(speed, e, "speed ('max' or a factor)")
        speed = "max" if f is None else f"{f:g}"
        if f == 0:
            e("speed: a factor must be > 0 (or 'max')")
    live = _bool(doc.get("live"), e, "live", False)
    start = _str(doc.get("start"), e, "start")
    if start is not None:
        from datetime import datetime
        try:
            datetime.fromisoformat(start.replace("Z", "+00:00"))
        except ValueError:
            e(f"start: {start!r} is not an ISO 8601 time (e.g. 2026-11-27T09:00:00Z)")
    until = _number(doc.get("until"), e, "until")
    linger = _number(doc.get("source_linger"), e, "source_linger")
    catch_up = _str(doc.get("catch_up"), e, "catch_up")
    if catch_up is not None and catch_up not in ("yield", "block"):
        e(f"catch_up: {catch_up!r} is not 'yield' or 'block'")
        catch_up = None
    catch_up_kbit = _number(doc.get("catch_up_kbit"), e, "catch_up_kbit")
    if catch_up_kbit == 0:
        e("catch_up_kbit: a pace must be > 0 kbit/s")
        catch_up_kbit = None
    hosts: dict[str, Host] = {}
    for name, where, h in _named_tables(doc, "host", HOST_KEYS, e, "no [[host]] entries"):
        addrs = []
        for a in _strs(h.get("addresses"), e, f"{where}: addresses"):
            try:
                addrs.append(str(ipaddress.ip_address(a)))
            except ValueError:
                e(f"{where}: addresses: {a!r} is not an IP address (DNS names go in 'names')")
        names = _strs(h.get("names"), e, f"{where}: names")
        for n in names:
            if not DNS_RE.match(n):
                e(f"{where}: names: {n!r} is not a DNS name")
        iface = _str(h.get("interface"), e, f"{where}: interface")
        if not addrs and not iface:
            e(f"{where}: give its addresses (or an interface to listen on)")
        consoles = []
        raw_c = h.get("consoles", [])
        if not isinstance(raw_c, list):
            e(f"{where}: consoles: expected a list of {{unit = ..., port = ...}}")
            raw_c = []
        for c in raw_c:
            if isinstance(c, str):
                c = {"unit": c}
            if not isinstance(c, dict):
                e(f"{where}: consoles: expected {{unit = ..., port = ...}}, not {c!r}")
                continue
            _unknown(c, CONSOLE_KEYS, e, f"{where}: console")
            u = _str(c.get("unit"), e, f"{where}: console unit", required=True)
            port = _port(c.get("port"), e, f"{where}: console {u} port", 0, zero=True)
            if u:
                consoles.append(Console(u, port))
        tak = None
        if "tak" in h:
            t = h["tak"]
            if not isinstance(t, dict):
                e(f"{where}: tak: expected a table {{cot = [...], listen_cot = [...], uids = ...}}")
            else:
                _unknown(t, TAK_KEYS, e, f"{where}: tak")
                uids = _str(t.get("uids"), e, f"{where}: tak uids")
                proto = str(t.get("proto", "xml"))
                if proto not in ("xml", "1"):
                    e(f"{where}: tak proto: {proto!r} is not xml or 1 (TAK protocol version 1, protobuf)")
                tak = Tak(_strs(t.get("cot"), e, f"{where}: tak cot"), _strs(t.get("listen_cot"), e, f"{where}: tak "
                                                                                 "listen_cot"),
                          str((base / uids).resolve()) if uids else None, proto)
        hosts[name] = Host(name, tuple(addrs), names, iface, _str(h.get("attach"), e, f"{where}: attach"),
                           _strs(h.get("eas"), e, f"{where}: eas"), _strs(h.get("sources"), e, f"{where}: sources"),
                           _strs(h.get("fusion"), e, f"{where}: fusion"), tuple(consoles), tak)
    routers: dict[str, RouterSpec] = {}
    for name, where, r in _named_tables(doc, "router", ROUTER_KEYS, e,
                                        "no [[router]] entries (every host's processes attach to a router)"):
        host = _str(r.get("host"), e, f"{where}: host", required=True)
        cp = _str(r.get("cp"), e, f"{where}: cp", required=True)
        routers[name] = RouterSpec(name, host or "", cp or "", _port(r.get("port"), e, f"{where}: port", DEFAULT_PORT),
                                   _strs(r.get("links"), e, f"{where}: links"))
    if scen is None:
        return None, e.lines
    sc_path = Path(scen) if Path(scen).is_absolute() else (base / scen)
    dep = Deployment(str(sc_path.resolve()) if path else scen, hosts, routers, root, _bool(doc.get("secure"), e,
                     "secure", True), (base / pki).resolve() if pki else (base / "pki").resolve(), speed, live,
                     start, until, 30.0 if linger is None else linger, path, catch_up=catch_up,
                     catch_up_kbit=catch_up_kbit)
    return dep, e.lines
