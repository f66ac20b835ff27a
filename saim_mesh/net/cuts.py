"""Silent cuts between namespaced hosts (`netns.Hosts`), like radio loss: nftables drop
rules on the hub's bridge (table `bridge saim`, chain `cuts`), each tagged by what it cuts,
so what is cut is read back from the system; without `nft`, a host is cut by detaching its
bridge port and a pair by a neighbour entry pointing at no one (both silent too)."""
from __future__ import annotations

import itertools
import json
import shutil
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING

from .namespaces import BRIDGE, IFACE, NFT_CHAIN, NFT_TABLE, NOWHERE_MAC, NetnsError, _say_once, sh

if TYPE_CHECKING:
    from .netns import Host


def setup(hub: str, use_nft: bool | None, log: Callable[[str], None]) -> bool:
    """Make the cut table in the hub; False when cuts fall back to ports and neighbours
    (`use_nft` False, or None and nft missing or unusable here: said once)."""
    if use_nft is False:
        _say_once("nofallback", "netns: cuts by bridge-port detach / neighbour entry (nft not used)", log)
        return False
    if shutil.which("nft") is None:
        if use_nft:
            raise NetnsError("use_nft=True but no `nft` on PATH (apt-get install nftables)")
        _say_once("nonft", "netns: no `nft` (apt-get install nftables): a host is cut by detaching its bridge "
                  "port, a pair by a dead neighbour entry (both silent)", log)
        return False
    rules = (f"table bridge {NFT_TABLE} {{\n chain {NFT_CHAIN} {{ type filter hook forward priority 0; "
             f"policy accept; }}\n}}\n")
    try:
        sh(["ip", "netns", "exec", hub, "nft", "-f", "-"], "creating the cut table", input=rules)
    except NetnsError as e:
        if use_nft:
            raise
        _say_once("nftfail", f"netns: nft unusable ({e}); cutting by bridge-port detach instead", log)
        return False
    return True


class Cuts:
    """What cuts the hub's bridge between `hosts` (by name; the dict `Hosts` keeps), by nft
    rules when `nft`, else by ports and neighbour entries."""

    def __init__(self, hub: str, hosts: Mapping[str, Host], nft: bool):
        self.hub, self.hosts, self.nft = hub, hosts, nft

    def __getitem__(self, name: str) -> Host:
        try:
            return self.hosts[name]
        except KeyError:
            raise KeyError(f"no host {name!r} (hosts: {', '.join(self.hosts)})") from None

    def _ip(self, ns: str, *args: str, what: str) -> str:
        return sh(["ip", "-n", ns, *args], f"{what} ({ns})")

    def _nft(self, *args: str, what: str) -> str:
        return sh(["ip", "netns", "exec", self.hub, "nft", *args], what)

    def _rules(self) -> list[tuple[int, str]]:
        """(handle, comment) of every cut rule."""
        out = json.loads(self._nft("-j", "-a", "list", "chain", "bridge", NFT_TABLE, NFT_CHAIN,
                                   what="listing cut rules"))
        return [(r["rule"]["handle"], r["rule"].get("comment", "")) for r in out.get("nftables", []) if "rule" in r]

    def _drop(self, tag: str, *matches: list[str]) -> None:
        if any(c == tag for _, c in self._rules()):
            return
        for m in matches:
            self._nft("add", "rule", "bridge", NFT_TABLE, NFT_CHAIN, *m, "drop", "comment", f'"{tag}"',
                      what=f"adding drop rule {tag}")

    def _undrop(self, tag: str) -> None:
        for handle, c in self._rules():
            if c == tag:
                self._nft("delete", "rule", "bridge", NFT_TABLE, NFT_CHAIN, "handle", str(handle),
                          what=f"removing drop rule {tag}")

    def cut(self, host: str) -> None:
        """Cut the host off from every other, silently (frames dropped on the bridge)."""
        h = self[host]
        if self.nft:
            self._drop(f"host {host}", ["iifname", h.port], ["oifname", h.port])
        else:
            self._ip(self.hub, "link", "set", h.port, "nomaster", what=f"detaching {host}'s port")

    def heal(self, host: str) -> None:
        h = self[host]
        if self.nft:
            self._undrop(f"host {host}")
        else:
            self._ip(self.hub, "link", "set", h.port, "master", BRIDGE, what=f"re-attaching {host}'s port")

    def _pair(self, a: str, b: str) -> tuple[Host, Host, str]:
        ha, hb = self[a], self[b]
        if a == b:
            raise ValueError(f"a link from {a} to itself")
        x, y = sorted((a, b))
        return ha, hb, f"link {x} {y}"

    def cut_link(self, a: str, b: str) -> None:
        """Cut only what passes between hosts a and b (both ways); each still reaches the others."""
        ha, hb, tag = self._pair(a, b)
        if self.nft:
            self._drop(tag, ["iifname", ha.port, "oifname", hb.port], ["iifname", hb.port, "oifname", ha.port])
        else:
            for x, y in ((ha, hb), (hb, ha)):
                self._ip(x.netns, "neigh", "replace", y.address, "lladdr", NOWHERE_MAC, "dev", IFACE,
                         "nud", "permanent", what=f"pointing {x.name}'s neighbour {y.name} nowhere")

    def heal_link(self, a: str, b: str) -> None:
        ha, hb, tag = self._pair(a, b)
        if self.nft:
            self._undrop(tag)
        else:
            for x, y in ((ha, hb), (hb, ha)):
                sh(["ip", "-n", x.netns, "neigh", "del", y.address, "dev", IFACE], "restoring a neighbour",
                   check=False)

    def cuts(self) -> dict[str, list]:
        """What is cut now: {"hosts": [...], "links": [[a, b], ...]}, read from the system."""
        hosts: list[str] = []
        links: list[list[str]] = []
        if self.nft:
            for _, c in self._rules():
                kind, *names = c.split()
                if kind == "host" and names[0] not in hosts:
                    hosts.append(names[0])
                elif kind == "link" and names not in links:
                    links.append(names)
        else:
            out = json.loads(self._ip(self.hub, "-j", "link", "show", what="listing ports") or "[]")
            attached = {i["ifname"] for i in out if i.get("master") == BRIDGE}
            hosts = [h.name for h in self.hosts.values() if h.port not in attached]
            for a, b in itertools.combinations(self.hosts.values(), 2):
                neigh = json.loads(self._ip(a.netns, "-j", "neigh", "show", b.address, what="neighbours") or "[]")
                if any(n.get("lladdr") == NOWHERE_MAC for n in neigh):
                    links.append(sorted([a.name, b.name]))
        return {"hosts": sorted(hosts), "links": sorted(links)}
