"""What crosses each battalion's radio link to the brigade (issue 32, item 5: fit the radio).

Routers forward one copy of a sample per link, to where some subscriber is. On the live
mesh the bulk of that is the command posts' source frames (`src/<cp>`): each EA subscribes
only to the sources it depends on (live/depend.py), so a link from battalion X up to the
brigade carries cp.X's frames when some EA outside X's subtree depends on them, and down
the frames of every other source some EA of X's subtree depends on. This benchmark builds
those frames as a live source does (one per source per epoch, messages encoded as on the
wire), sends each direction's frames through a counting TCP link between two Zenoh
sessions made by `zconf.config` (secure mode aside), with the mesh's link compression off
and on, and writes bytes and kbit/s at 1x per link and direction to bench/results/radio.json.

Not counted (small beside the frames): alerts, notices and command results going up to a
console across the link, directives, liveliness and Zenoh's own control traffic."""
from __future__ import annotations

import argparse
import json
import math
import queue
import time
from pathlib import Path

import zenoh

from saim_mesh import messages as M
from saim_mesh import scenario as S
from saim_mesh.commands import _wait_matching
from saim_mesh.live import frames as F
from saim_mesh.live.depend import cp_shares, depends
from saim_mesh.live.play import EPOCH_S, share
from saim_mesh.scenario import mesh_units
from saim_mesh.net.linkemu import Link
from saim_mesh.ondemand import ensure
from saim_mesh.runner import config_for, make_ea
from saim_mesh.zconf import config, free_port

from . import ROOT

RATE_KBPS = 64.0   # a tactical data link (the figure)


def source_frames(sc) -> dict[str, list[bytes]]:
    """Each command post's source as frames: one per epoch with messages, numbered."""
    out = {}
    for name, sh in cp_shares(sc).items():
        by: dict[float, list[bytes]] = {}
        for m in share(sc, list(sh.units) if sh.units else None, sh.tracks, list(sh.but)):
            if math.isfinite(m.t):
                by.setdefault(math.ceil(m.t / EPOCH_S) * EPOCH_S, []).append(M.encode(m))
        out[name] = [F.encode(F.Frame(v=1, source=name, epoch=1, seq=i, wm=end - EPOCH_S, msgs=msgs))
                     for i, (end, msgs) in enumerate(sorted(by.items()), start=1)]
    return out


def dependencies(sc, units: list[str], sources: list[str]) -> dict[str, set[str]]:
    """Unit -> the sources its EA depends on."""
    out = {}
    for u in units:
        ea = make_ea(sc, u, config_for(sc, u, None), sinks=[])
        ea.start(0.0)
        out[u] = set(depends(sc, ea, sources))
    return out


def crossing(sc, deps: dict[str, set[str]], bn: str) -> dict[str, list[str]]:
    """The sources whose frames cross the link from `bn` to the top: up (its own, when an EA
    beyond its subtree depends on it) and down (the others an EA of its subtree depends on)."""
    inside = set(sc.taskorg.subtree(bn))
    own = f"cp.{bn}"
    up = [own] if any(own in d for u, d in deps.items() if u not in inside) else []
    down = sorted({s for u, d in deps.items() if u in inside for s in d} - {own})
    return {"up": up, "down": down}


def _session(compress: bool, **endpoints) -> zenoh.Session:
    conf = config(**endpoints)
    conf.insert_json5("transport/unicast/compression/enabled", "true" if compress else "false")
    return zenoh.open(conf)


def wire_bytes(streams: dict[str, list[bytes]], compress: bool) -> int:
    """Bytes on a TCP link for these sources' frames, in event-time order, one at a time
    (a paced source's frames go out one per batch)."""
    if not streams:
        return 0
    port, front = free_port(), free_port()
    got: queue.SimpleQueue = queue.SimpleQueue()
    order = sorted(((i, name) for name, fs in streams.items() for i in range(len(fs))))
    with Link(front, port) as link, _session(compress, listen=[f"tcp/127.0.0.1:{port}"]) as rx:
        rx.declare_subscriber("bench/src/*", lambda s: got.put(len(s.payload)))
        with _session(compress, connect=[f"tcp/127.0.0.1:{front}"], listen=[]) as tx:
            pubs = {n: tx.declare_publisher(f"bench/src/{n}") for n in streams}
            for p in pubs.values():
                if not _wait_matching(p, time.monotonic() + 30):
                    raise RuntimeError("the receiving session never matched")
            before = link.stats()["up"]["bytes"]
            for i, name in order:
                pubs[name].put(streams[name][i])
                got.get(timeout=30)
            return link.stats()["up"]["bytes"] - before


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="bench_radio", description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenario", help="default: the brigade, generated on demand into out/scenarios")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "radio.json"))
    a = ap.parse_args(argv)
    path = Path(a.scenario) if a.scenario else ensure("brigade", ROOT / "out" / "scenarios")
    t0 = time.monotonic()
    sc = S.load(path)
    frames = source_frames(sc)
    units = mesh_units(sc)
    deps = dependencies(sc, units, sorted(frames))
    top = sc.taskorg.root
    links = {}
    for bn in sorted(u for u, p in sc.taskorg.parent.items() if p == top):
        cross = crossing(sc, deps, bn)
        row = {}
        for way, names in cross.items():
            streams = {n: frames[n] for n in names}
            raw = sum(len(f) for fs in streams.values() for f in fs)
            plain, packed = wire_bytes(streams, False), wire_bytes(streams, True)
            per_s = 8 / 1000 / sc.duration_s
            row[way] = {"sources": names, "frames": sum(len(fs) for fs in streams.values()),
                        "by_family": {"src": {"bytes_payload": raw, "bytes_wire_plain": plain,
                                              "bytes_wire_compressed": packed}},
                        "kbps_1x_plain": round(plain * per_s, 2), "kbps_1x_compressed": round(packed * per_s, 2),
                        "compression_ratio": round(plain / packed, 3) if packed else None}
            print(f"{bn}-{top} {way}: {len(names)} sources, {row[way]['frames']} frames, "
                  f"{row[way]['kbps_1x_plain']} kbit/s plain, {row[way]['kbps_1x_compressed']} compressed", flush=True)
        links[f"{bn}-{top}"] = row
    worst_plain = max(r[w]["kbps_1x_plain"] for r in links.values() for w in r)
    worst = max(r[w]["kbps_1x_compressed"] for r in links.values() for w in r)
    out = {"scenario": path.name, "duration_s": sc.duration_s, "ea_peers": len(units), "sources": sorted(frames),
           "link_rate_kbps": RATE_KBPS, "links": links,
           "worst_direction_kbps_1x_plain": worst_plain, "worst_direction_kbps_1x_compressed": worst,
           "fits_link_1x_plain": worst_plain <= RATE_KBPS, "fits_link_1x_compressed": worst <= RATE_KBPS,
           "alerts_unchanged": "compression is Zenoh's transport (LZ4, negotiated per link): the same bytes "
                               "arrive (tests/test_compression.py), so every EA's input and alerts are unchanged",
           "not_counted": "alerts, notices, command results, directives, liveliness and Zenoh control traffic",
           "bench_wall_s": round(time.monotonic() - t0, 1)}
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(out, indent=1) + "\n")
    print(f"worst direction at 1x: {worst_plain} kbit/s plain, {worst} compressed (link {RATE_KBPS:.0f}); "
          f"-> {a.out}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
