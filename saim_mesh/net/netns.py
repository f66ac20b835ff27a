"""Hosts emulated on one machine: one network namespace per host, joined by veth pairs to a
bridge, with real cuts and an optional rate per host link. Tests and benchmarks run the
mesh across these hosts to see what a real network does (a silent cut, a slow link) without
a proxy in the path (../shared/notes/live-mesh.md, "Emulating hosts and cuts here").

Layout (nothing is created in the root namespace, so deleting the namespaces removes
everything):

    <prefix>hub        the bridge br0; port p<i> per host (its alias is the host's name)
    <prefix><host>     eth0 (the other end of p<i>) with 198.18.0.<i+1>/24, and lo up

Cuts (`cuts.py`) are nftables drop rules on the hub's bridge (table `bridge saim`, chain `cuts`):
frames of a cut host, or between two cut-apart hosts, vanish without an error on either
side, like radio loss, so Zenoh finds out only when its lease expires. Without `nft`, a
host is cut by detaching its bridge port and a pair by a neighbour entry pointing at no
one (both silent too), said once. A rate is a `tc tbf` on both ends of the host's veth.

Names carry a prefix unique to the creating process (`sm-<pid>-<n>-`), so `cleanup_stale()`
can remove what a crashed run left without touching a live one's.

Namespaces themselves (commands, cleanup): `namespaces.py`. CLI (`scripts/netns-hosts`, `netns_cli.py`): up N / down / cut HOST [PEER] / heal HOST [PEER] / status /
exec HOST CMD... / cleanup.
"""
from __future__ import annotations

import atexit
import ipaddress
import json
import os
import re
import shutil
import signal
import subprocess
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from .cuts import Cuts
from .cuts import setup as cut_setup
from .namespaces import (BASE, BRIDGE, HUB, IFACE, NFT_CHAIN, NFT_TABLE, NOWHERE_MAC, SUBNET, _NAME,  # noqa: F401
                         NetnsError, _alive, _counter, _empty_namespace, _say_once, _stderr, cleanup, cleanup_stale,
                         namespaces, ns_pids, sh, stale_prefixes, unavailable)


@dataclass(frozen=True)
class Host:
    """One emulated host: its namespace, its address and its port on the hub's bridge."""
    name: str
    index: int
    netns: str
    address: str
    prefixlen: int
    port: str


@dataclass(eq=False)
class Hosts:
    """Namespaced hosts on one bridge, as a context manager: everything made, and every
    process started, is gone after the `with` block, whatever happened inside it.

    `hosts`: a count (h0, h1, ...) or names. `rate_kbit`: a tbf rate for every host link
    or per host name (kbit/s, both directions). `use_nft`: None = nft when it works,
    else the fallback (said once); False forces the fallback. `sysctls`: kernel settings
    of each host's own network stack (e.g. `net.ipv4.tcp_notsent_lowat`), as a real host
    behind a radio link would be tuned.
    """
    hosts_spec: int | Sequence[str] = 2
    rate_kbit: int | Mapping[str, int | None] | None = None
    prefix: str | None = None
    subnet: str = SUBNET
    use_nft: bool | None = None
    stop_timeout: float = 3.0
    log: Callable[[str], None] = _stderr
    sysctls: Mapping[str, str | int] = field(default_factory=dict)
    hosts: dict[str, Host] = field(default_factory=dict, init=False)
    procs: list[subprocess.Popen] = field(default_factory=list, init=False)
    nft: bool = field(default=False, init=False)
    _made: list[str] = field(default_factory=list, init=False)   # namespaces made, in order
    _up: bool = field(default=False, init=False)

    def __post_init__(self) -> None:
        if self.prefix is None:
            self.prefix = f"{BASE}{os.getpid()}-{next(_counter)}-"
        if not self.prefix.startswith(BASE):
            raise ValueError(f"prefix {self.prefix!r} must start with {BASE!r} (cleanup finds leftovers by it)")
        names = [f"h{i}" for i in range(self.hosts_spec)] if isinstance(self.hosts_spec, int) else list(self.hosts_spec)
        net = ipaddress.ip_network(self.subnet)
        if not names:
            raise ValueError("no hosts")
        if len(names) > net.num_addresses - 2:
            raise ValueError(f"{len(names)} hosts do not fit in {net}")
        for n in names:
            if not _NAME.match(n) or n == HUB:
                raise ValueError(f"host name {n!r}: letters, digits, '_', '.', '-' (at most 64) and not {HUB!r}")
        if len(set(names)) != len(names):
            raise ValueError(f"a host named twice in {names}")
        for i, n in enumerate(names):
            self.hosts[n] = Host(n, i, f"{self.prefix}{n}", str(net[i + 1]), net.prefixlen, f"p{i}")

    # --- set up and tear down -------------------------------------------------------------

    @property
    def hub(self) -> str:
        return f"{self.prefix}{HUB}"

    def __enter__(self) -> Hosts:
        return self.up()

    def __exit__(self, *exc: Any) -> None:
        self.close()

    def up(self) -> Hosts:
        """Create the hub and the hosts; on any failure, remove what was made and raise."""
        if self._up:
            return self
        self._up = True
        atexit.register(self.close)
        try:
            clash = [n for n in namespaces() if n.startswith(self.prefix)]
            if clash:
                raise NetnsError(f"namespaces {clash} already exist: `scripts/netns-hosts cleanup --prefix "
                                 f"{self.prefix}` removes them")
            self._add_ns(self.hub)
            self._ip(self.hub, "link", "add", BRIDGE, "type", "bridge", what="creating the bridge")
            self._ip(self.hub, "link", "set", BRIDGE, "up", what="bringing the bridge up")
            self._ip(self.hub, "link", "set", "lo", "up", what="bringing lo up in the hub")
            for h in self.hosts.values():
                self._add_host(h)
            self.nft = cut_setup(self.hub, self.use_nft, self.log)
            rates = self.rate_kbit if isinstance(self.rate_kbit, Mapping) else {n: self.rate_kbit for n in self.hosts}
            for n, r in rates.items():
                if n not in self.hosts:
                    raise KeyError(f"rate for unknown host {n!r} (hosts: {', '.join(self.hosts)})")
                if r is not None:
                    self.set_rate(n, r)
        except BaseException:
            self.close()
            raise
        return self

    def _add_ns(self, ns: str) -> None:
        sh(["ip", "netns", "add", ns], f"creating namespace {ns}")
        self._made.append(ns)

    def _ip(self, ns: str, *args: str, what: str) -> str:
        return sh(["ip", "-n", ns, *args], f"{what} ({ns})")

    def _add_host(self, h: Host) -> None:
        self._add_ns(h.netns)
        sh(["ip", "link", "add", IFACE, "netns", h.netns, "type", "veth", "peer", "name", h.port, "netns", self.hub],
           f"creating the veth pair of host {h.name}")
        self._ip(self.hub, "link", "set", h.port, "alias", h.name, what=f"naming port {h.port}")
        self._ip(self.hub, "link", "set", h.port, "master", BRIDGE, what=f"attaching {h.port} to the bridge")
        self._ip(self.hub, "link", "set", h.port, "up", what=f"bringing {h.port} up")
        self._ip(h.netns, "link", "set", "lo", "up", what="bringing lo up")
        self._ip(h.netns, "addr", "add", f"{h.address}/{h.prefixlen}", "dev", IFACE, what=f"addressing {h.name}")
        self._ip(h.netns, "link", "set", IFACE, "up", what=f"bringing {h.name}'s {IFACE} up")
        for k, v in self.sysctls.items():
            sh(["ip", "netns", "exec", h.netns, "sysctl", "-q", "-w", f"{k}={v}"], f"setting {k} in host {h.name}")

    def close(self) -> None:
        """Stop every process started here, kill anything else in the namespaces, remove
        them (their bridge, veths and qdiscs go with them). Idempotent; tries everything
        and raises at the end if something could not be removed."""
        if not self._up:
            return
        self._up = False
        atexit.unregister(self.close)
        errors: list[str] = []
        for p in self.procs:
            if p.poll() is None:
                try:
                    os.killpg(p.pid, signal.SIGTERM)
                except ProcessLookupError:
                    pass
        end = time.monotonic() + self.stop_timeout
        for p in self.procs:
            try:
                p.wait(max(0.0, end - time.monotonic()))
            except subprocess.TimeoutExpired:
                pass
            try:
                os.killpg(p.pid, signal.SIGKILL)   # the group: children it left behind too
            except (ProcessLookupError, PermissionError):
                pass
            try:
                p.wait(5)
            except subprocess.TimeoutExpired:
                errors.append(f"process {p.pid} ({' '.join(map(str, p.args))[:80]}) survived SIGKILL")
        for ns in reversed(self._made):
            if left := _empty_namespace(ns):
                errors.append(f"{ns}: processes {left} survived SIGKILL")
        for ns in reversed(self._made):   # hosts first, the hub last
            try:
                sh(["ip", "netns", "del", ns], f"removing namespace {ns}")
            except NetnsError as e:
                if ns in namespaces():
                    errors.append(str(e))
        self._made.clear()
        if errors:
            raise NetnsError("teardown incomplete: " + "; ".join(errors))

    # --- processes -------------------------------------------------------------------------

    def __getitem__(self, name: str) -> Host:
        try:
            return self.hosts[name]
        except KeyError:
            raise KeyError(f"no host {name!r} (hosts: {', '.join(self.hosts)})") from None

    def address(self, name: str) -> str:
        return self[name].address

    def wrap(self, host: str, argv: Sequence[str]) -> list[str]:
        """`argv` as run inside `host` (for a supervisor that starts its own children;
        teardown still kills them, as it kills everything in the namespace)."""
        return ["ip", "netns", "exec", self[host].netns, *map(str, argv)]

    def run(self, host: str, argv: Sequence[str], *, log: str | Path | None = None,
            **popen: Any) -> subprocess.Popen:
        """Start `argv` inside `host`, in its own process group (teardown stops the group).
        `log`: append stdout and stderr to this file; else `popen` says (stdout=..., ...)."""
        popen.setdefault("stdin", subprocess.DEVNULL)
        f: IO[bytes] | None = None
        if log is not None:
            f = open(log, "ab")
            popen.update(stdout=f, stderr=subprocess.STDOUT)
        try:
            p = subprocess.Popen(self.wrap(host, argv), start_new_session=True, **popen)
        finally:
            if f is not None:
                f.close()
        self.procs.append(p)
        return p

    def check(self, host: str, argv: Sequence[str], timeout: float = 30.0) -> str:
        """Run a command in `host` to completion; its stdout, or NetnsError naming it."""
        return sh(self.wrap(host, argv), f"running in {host}", timeout=timeout)

    def pids(self, host: str) -> list[int]:
        return [p for p in ns_pids(self[host].netns) if _alive(p)]

    def kill(self, host: str) -> list[int]:
        """The host dies: SIGKILL every process in its namespace (its network stays)."""
        pids = self.pids(host)
        if left := _empty_namespace(self[host].netns):
            raise NetnsError(f"host {host}: processes {left} survived SIGKILL")
        for p in self.procs:
            if p.pid in pids:
                p.wait(5)
        return pids

    # --- rate, cuts ------------------------------------------------------------------------

    def set_rate(self, host: str, kbit: int | None) -> None:
        """A `tc tbf` rate (kbit/s, 1000 bit) on both ends of the host's link; None removes it.
        Burst: 50 ms of data, at least two full frames; queue: 400 ms."""
        h = self[host]
        for ns, dev in ((h.netns, IFACE), (self.hub, h.port)):
            if kbit is None:
                sh(["tc", "-n", ns, "qdisc", "del", "dev", dev, "root"], f"removing the rate of {host}", check=False)
                continue
            if kbit <= 0:
                raise ValueError(f"rate {kbit} kbit/s for {host}: must be positive")
            burst = max(2 * 1514, kbit * 1000 // 8 // 20)
            sh(["tc", "-n", ns, "qdisc", "replace", "dev", dev, "root", "tbf", "rate", f"{kbit}kbit",
                "burst", str(burst), "latency", "400ms"], f"limiting {host}'s link to {kbit} kbit/s")

    def rate(self, host: str) -> int | None:
        """The tbf rate on the host's side of its link (kbit/s), or None."""
        out = json.loads(sh(["tc", "-n", self[host].netns, "-j", "qdisc", "show", "dev", IFACE], "reading qdiscs")
                         or "[]")
        return next((q["options"]["rate"] * 8 // 1000 for q in out if q.get("kind") == "tbf"), None)

    def cut(self, host: str) -> None:
        """Cut the host off from every other, silently (frames dropped on the bridge)."""
        self._cuts().cut(host)

    def heal(self, host: str) -> None:
        self._cuts().heal(host)

    def cut_link(self, a: str, b: str) -> None:
        """Cut only what passes between hosts a and b (both ways); each still reaches the others."""
        self._cuts().cut_link(a, b)

    def heal_link(self, a: str, b: str) -> None:
        self._cuts().heal_link(a, b)

    def cuts(self) -> dict[str, list]:
        """What is cut now: {\"hosts\": [...], \"links\": [[a, b], ...]}, read from the system."""
        return self._cuts().cuts()

    def _cuts(self) -> Cuts:
        return Cuts(self.hub, self.hosts, self.nft)

    def status(self) -> dict[str, Any]:
        cuts = self.cuts()
        return {"prefix": self.prefix, "hub": self.hub, "cut_by": "nft" if self.nft else "link",
                "hosts": [{"name": h.name, "netns": h.netns, "address": h.address, "port": h.port,
                           "rate_kbit": self.rate(h.name), "cut": h.name in cuts["hosts"], "pids": self.pids(h.name)}
                          for h in self.hosts.values()],
                "links_cut": cuts["links"]}

    # --- the CLI's hosts outlive the CLI -----------------------------------------------------

    @classmethod
    def attach(cls, prefix: str, log: Callable[[str], None] = _stderr) -> Hosts:
        """The hosts made earlier under `prefix` (by `scripts/netns-hosts up`), read back from
        the system. Closing it removes them."""
        hub = f"{prefix}{HUB}"
        if hub not in namespaces():
            raise NetnsError(f"no hosts under prefix {prefix!r} (no namespace {hub}): `up` first")
        ports = json.loads(sh(["ip", "-n", hub, "-j", "link", "show"], "listing the hub's ports") or "[]")
        names: dict[int, str] = {}
        for p in ports:
            if re.fullmatch(r"p\d+", p["ifname"]) and p.get("ifalias"):
                names[int(p["ifname"][1:])] = p["ifalias"]
        order = [names[i] for i in sorted(names)]
        self = cls(order, prefix=prefix, log=log)
        for n, h in self.hosts.items():   # the addresses the hosts really have
            addrs = json.loads(sh(["ip", "-n", h.netns, "-j", "addr", "show", "dev", IFACE], "reading addresses"))
            a = next(x for i in addrs for x in i.get("addr_info", []) if x.get("family") == "inet")
            self.hosts[n] = Host(n, h.index, h.netns, a["local"], a["prefixlen"], h.port)
        self.nft = shutil.which("nft") is not None and bool(
            sh(["ip", "netns", "exec", hub, "nft", "list", "tables"], "listing nft tables", check=False).strip())
        self._made = [hub, *(h.netns for h in self.hosts.values())]
        self._up = True   # close() removes them; no atexit: they outlive this process on purpose
        return self
