"""What crosses each battalion's radio link to the brigade (issue 32, item 5: fit the radio).

Routers forward one copy of a sample per link, to where some subscriber is. On the live
mesh the bulk of that is the command posts' sources publishing by key group (issue 50,
`live/groupframes.py`): each flush as one frame per group on `src/<cp>/<group>` and a
progress frame on `src/<cp>/_p`. Each EA subscribes to the progress streams of the sources it
depends on (live/depend.py) and to the groups of its interest (`Interest` ->
`Streams.subscriptions`), so a link from battalion X up to the brigade carries a group
frame of a source of X's subtree when some EA outside that subtree hears the group at the
time, and down the frames of the other sources' groups some EA of X's subtree hears. This
benchmark builds those frames as a live source does (one flush per source per epoch,
messages encoded as on the wire), works out each EA's interest every 30 s of event time
from its plan and its units' reported places (as its EA knows them: the mean of its
entities' last reports), sends each direction's frames through a counting TCP link between
two Zenoh sessions made by `zenoh_config.config` (secure mode aside), with the mesh's link
compression off and on, and writes bytes and kbit/s at 1x per link and direction, and per
group family (`by_group`), to bench/results/radio.json.

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

from saim_mesh.protocol import messages as M
from saim_mesh import scenario as S
from saim_mesh.authority.commands import _wait_matching
from dataclasses import replace

from dissemination.exact import _chunks_match
from dissemination.interest import Interest
from dissemination.keyspace import KeySpace
from saim_mesh.live import groupframes as GF
from saim_mesh.live.depend import cp_shares, depends
from saim_mesh.live.play import EPOCH_S, of_share
from saim_mesh.scenario import mesh_units
from saim_mesh.net.linkemu import Link
from saim_mesh.ondemand import ensure
from saim_mesh.inprocess.runner import config_for, make_ea
from saim_mesh.launch.zenoh_config import config, free_port

from . import ROOT

RATE_KBPS = 64.0   # a tactical data link (the figure)


SPAN_S = 30.0   # an EA's interest is re-registered this often (a grouped flush spans at most this)


def source_frames(sc) -> dict[str, list[tuple[float, list[GF.GroupFrame], bytes]]]:
    """Each source as flushes, one per epoch with messages: (its epoch's end, its group
    frames, its progress frame encoded)."""
    out = {}
    for name, sh in cp_shares(sc).items():
        group_of = GF.grouper(sc, "bench")
        by: dict[float, tuple[list[bytes], list[str]]] = {}
        for m in of_share(sc, sh):
            if math.isfinite(m.t):
                ms, gs = by.setdefault(math.ceil(m.t / EPOCH_S) * EPOCH_S, ([], []))
                ms.append(M.encode(m))
                gs.append(group_of(m))
        counters: dict[str, int] = {}
        out[name] = []
        for i, (end, (ms, gs)) in enumerate(sorted(by.items()), start=1):
            gfs, prog, _ = GF.split(name, 1, i, end - EPOCH_S, ms, gs, counters)
            out[name].append((end, gfs, GF.encode(prog)))
    return out


def interests(sc, units: list[str], span: float = SPAN_S) -> dict[str, list[list[tuple[str, ...]]]]:
    """Unit -> per `span` of event time, the group expressions (as chunk tuples) its EA hears:
    its plan's needs at the start, its units' circles where their entities last reported."""
    ks = KeySpace.of(sc, "bench")
    streams = GF.streams_of(sc, "bench")
    to, proj = sc.taskorg, sc.projection
    n = int(math.ceil(sc.duration_s / span)) + 1
    last: dict[str, tuple[float, float]] = {}
    snaps: list[dict[str, tuple[float, float]]] = []
    evs = iter(sorted((e for e in sc.events if type(e) is M.LocationReport), key=lambda e: e.t))
    e = next(evs, None)
    for w in range(n):
        while e is not None and e.t <= w * span:
            last[e.entity] = proj.to_xy(e.lon, e.lat)
            e = next(evs, None)
        snaps.append(dict(last))
    out = {}
    for u in units:
        cfg = config_for(sc, u, None)
        ea = make_ea(sc, u, cfg, sinks=[])
        ea.start(0.0)
        dom = ea.domain
        dis = cfg["dissemination"]
        it = Interest(ks, float(dis["radius_m"]), int(dis["block_share"]))
        needs = dom.needs(it.radius)
        r = needs.circles[0][2] if needs.circles else it.radius
        rows = []
        for snap in snaps:
            circles = []
            for v in sorted(dom.own_units):
                pts = [snap[x] for x in to.units[v].entities if x in snap]
                if pts:
                    circles.append((sum(p[0] for p in pts) / len(pts), sum(p[1] for p in pts) / len(pts), r))
            want = streams.subscriptions(it.of(replace(needs, circles=tuple(circles))))
            rows.append([tuple(x.split("/")) for x in sorted(want)])
        out[u] = rows
    return out


def group_crossing(sc, frames, deps, heard, bn: str, span: float = SPAN_S) -> dict[str, dict]:
    """Per direction of the link from `bn` to the top: the progress and group frames that
    cross it (payloads), by source and group family."""
    inside = set(sc.taskorg.subtree(bn))
    out = {}
    for way in ("up", "down"):
        beyond = [u for u in deps if (u not in inside) == (way == "up")]
        streams: dict[str, list[bytes]] = {}
        fams: dict[str, int] = {}
        for name, flushes in frames.items():
            home = name[3:] if name.startswith("cp.") else None
            mine = home in inside if home is not None else False
            if mine != (way == "up"):
                continue
            eas = [u for u in beyond if name in deps[u]]
            if not eas:
                continue
            seq = []
            for end, gfs, prog in flushes:
                w = min(int((end - EPOCH_S) // span), len(heard[eas[0]]) - 1)
                pats = {p for u in eas for p in heard[u][w]}
                for gf in gfs:
                    parts = gf.group.split("/")
                    if any(_chunks_match(p, parts) for p in pats):
                        b = GF.encode(gf)
                        seq.append(b)
                        fams[gf.group.split("/", 1)[0]] = fams.get(gf.group.split("/", 1)[0], 0) + len(b)
                seq.append(prog)
                fams["_p"] = fams.get("_p", 0) + len(prog)
            streams[name] = seq
        out[way] = (streams, fams)
    return out


def dependencies(sc, units: list[str], sources: list[str]) -> dict[str, set[str]]:
    """Unit -> the sources its EA depends on."""
    out = {}
    for u in units:
        ea = make_ea(sc, u, config_for(sc, u, None), sinks=[])
        ea.start(0.0)
        out[u] = set(depends(sc, ea, sources))
    return out


def _session(compress: bool, **endpoints) -> zenoh.Session:
    conf = config(**endpoints)
    conf.insert_json5("transport/unicast/compression/enabled", "true" if compress else "false")
    return zenoh.open(conf)


def wire_bytes(streams: dict[str, list[bytes]], compress: bool) -> int:
    """Bytes on a TCP link for these sources' frames, in event-time order, one at a time
    (a paced source's frames go out one per batch). One key per source: a group's key is
    declared once per link (Zenoh maps it to an id), so its length is not counted per frame."""
    if not streams:
        return 0
    port, front = free_port(), free_port()
    got: queue.SimpleQueue = queue.SimpleQueue()
    order = sorted(((i, name) for name, fs in streams.items() for i in range(len(fs))))
    with Link(front, port) as link, _session(compress, listen=[f"tcp/127.0.0.1:{port}"]) as rx:
        rx.declare_subscriber("bench/src/*", lambda s: got.put(len(s.payload)))   # one key per source
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
    heard = interests(sc, units)
    top = sc.taskorg.root
    links = {}
    for bn in sorted(u for u, p in sc.taskorg.parent.items() if p == top):
        cross = group_crossing(sc, frames, deps, heard, bn)
        row = {}
        for way, (streams, fams) in cross.items():
            names = sorted(streams)
            raw = sum(len(f) for fs in streams.values() for f in fs)
            plain, packed = wire_bytes(streams, False), wire_bytes(streams, True)
            per_s = 8 / 1000 / sc.duration_s
            row[way] = {"sources": names, "frames": sum(len(fs) for fs in streams.values()),
                        "by_family": {"src": {"bytes_payload": raw, "bytes_wire_plain": plain,
                                              "bytes_wire_compressed": packed}},
                        "by_group": {f: {"bytes_payload": b, "kbps_1x_payload": round(b * per_s, 2)}
                                     for f, b in sorted(fams.items())},
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
           "alerts_unchanged": "a packed position unpacks to the source's exact bytes or is not packed "
                               "(tests/test_groups_frames.py), and compression is Zenoh's transport (LZ4, "
                               "negotiated per link: the same bytes arrive, tests/test_compression.py), so every "
                               "EA's input and alerts are unchanged",
           "not_counted": "alerts, notices, command results, directives, liveliness and Zenoh control traffic "
                          "(a group's sporadic heartbeats among them)",
           "by_group_means": "payload bytes of the group frames of each family (and `_p`, the progress "
                             "frames) that cross the direction: those some EA beyond it hears at the time",
           "bench_wall_s": round(time.monotonic() - t0, 1)}
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(out, indent=1) + "\n")
    print(f"worst direction at 1x: {worst_plain} kbit/s plain, {worst} compressed (link {RATE_KBPS:.0f}); "
          f"-> {a.out}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
