"""Zenoh configuration: the JSON5 file in configs/ plus endpoints chosen at run time."""
from __future__ import annotations

import json
import socket
from pathlib import Path

import zenoh

DEFAULT = Path(__file__).resolve().parents[2] / "configs" / "zenoh-peer.json5"
# A router's links may cross a radio of tens of kbit/s, where one full batch (16 KB: the
# file's batch_size) takes 2 s at 64 kbit/s. Zenoh reads a batch whole within the lease:
# at the file's 2 s lease (for leaves: a dead process is noticed at once) a router link
# that carries full batches (a catch-up after a heal) expires though data flows. This alone
# did not stop the brigade's router links flapping after a heal (docs/history/deployment-notes.md).
ROUTER_LEASE_MS = 10_000   # Zenoh's own default: five full batches at 64 kbit/s


def free_port(host: str = "127.0.0.1") -> int:
    """A port nobody listens on at `host` now (the OS's choice; v4 or v6)."""
    with socket.socket(socket.AF_INET6 if ":" in host else socket.AF_INET) as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def config(listen: list[str] | None = None, connect: list[str] | None = None,
           path: str | Path | None = None, multicast: bool = False, pki: str | Path | None = None,
           name: str | None = None, sc=None, root: str | None = None, mode: str | None = None,
           routers: list[str] = ()) -> zenoh.Config:
    """The JSON5 file, with endpoints chosen at run time; `multicast` turns on UDP
    multicast scouting (the file's default is off: tests and CI stay on loopback).
    With `pki` (a folder made by `saim-mesh certs`), the session is `name`'s identity
    over mutual TLS and carries the mesh's access-control rules, made from scenario `sc`.
    `mode` "client" (a leaf behind a router) or "router" (`saim-mesh router`): no
    scouting at all, so the hierarchy of routers stays as the topology says (gossip
    would let routers link around it); `routers` are the router identities whose
    relayed traffic the access-control rules accept."""
    conf = zenoh.Config.from_file(str(path or DEFAULT))
    if mode is not None:
        if mode not in ("peer", "client", "router"):
            raise ValueError(f"zenoh mode {mode!r}: expected peer, client or router")
        conf.insert_json5("mode", json.dumps(mode))
        if mode != "peer":
            conf.insert_json5("scouting/gossip/enabled", "false")
            conf.insert_json5("transport/shared_memory/enabled", "false")   # it would bypass an emulated link
        if mode == "router":
            conf.insert_json5("transport/link/tx/lease", str(ROUTER_LEASE_MS))
        if mode == "client":
            listen = []
    if multicast:
        conf.insert_json5("scouting/multicast/enabled", "true")
    if listen is not None:
        conf.insert_json5("listen/endpoints", json.dumps(listen))
    if connect is not None:
        conf.insert_json5("connect/endpoints", json.dumps(connect))
    if pki is not None:
        from ..scenario import mesh_units
        from ..security.acl import secure_config
        groups = sorted(sc.meta.get("fusion", {}).get("groups", {}))
        conf = secure_config(conf, pki, name, root, mesh_units(sc), groups, sc.taskorg, routers)
    return conf
