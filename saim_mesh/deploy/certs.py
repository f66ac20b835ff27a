"""`saim-mesh certs --deploy FILE`: the mesh's certificates for real hosts. Every
identity a host runs (its routers, EAs, sources, consoles, TAK gateway) carries that
host's addresses and DNS names in its subject alternative names, beside 127.0.0.1 and
localhost: a process listening on the host's address must show it, since the
connecting side checks it (../shared/notes/zenoh-security.md). Identities the file runs
nowhere (observer, other units' consoles, ...) get loopback only. CN = identity, as
always: the access-control rules are unchanged."""
from __future__ import annotations

from pathlib import Path

from .file import Deployment
from .launch import identities


def sans_of(dep: Deployment) -> dict[str, list[str]]:
    """identity -> the addresses and names of the host it runs on."""
    out: dict[str, list[str]] = {}
    for h in dep.hosts.values():
        for ident in identities(dep, h.name):
            out.setdefault(ident, [])
            out[ident] += [x for x in (*h.addresses, *h.names) if x not in out[ident]]
    return out


def make(dep: Deployment, sc, out: Path | None = None, days: int = 30, echo=None) -> dict[str, tuple[Path, Path]]:
    """Make (or keep) the CA and every identity's certificate in `out` (default: the
    file's `pki`); a kept leaf whose names differ from the file's is made again."""
    from ..security.pki import make_pki, names_for
    sans = sans_of(dep)
    names = names_for(sc, consoles=True) + [f"router.{n}" for n in dep.routers]
    names += [n for n in sans if n not in names]
    return make_pki(out or dep.pki, names, days, echo=echo, sans=sans)
