"""`saim-mesh mesh up | source | sources | peer | router | topology | tak | link`: the
mesh's processes, one command each."""
from __future__ import annotations

import sys
from pathlib import Path

from .. import scenario as S
from .args import _count, _speed, _positive, _seconds, _zmode, _zenoh_args, _start_of, _instant, DEFAULT_SCENARIO


def cmd_source(a) -> int:
    """Publish one source's stream: a command post's share of a recorded scenario, or reports
    from a file or standard input (docs/architecture.md, the live mesh)."""
    import zenoh

    from dissemination.keyspace import KeySpace

    from ..live import play
    from ..live.source import LiveSource
    from ..launch.zenoh_config import config
    sc = S.load(a.scenario, events=a.file is None)
    for u in [*(a.units or ()), *(a.but or ())]:
        if u not in sc.taskorg.units:
            raise KeyError(f"--units/--but {u}: unknown unit {u!r}: not in the task organization of {sc.name}")
    root = a.root or f"saim/{sc.name}"
    start = _start_of(a)
    paced = None   # --speed with --start: event time 0 at that instant (sources paced together)
    if a.start and not a.live:
        if not a.speed:
            raise ValueError("--start without --live paces the stream: give --speed FACTOR too")
        paced = _instant(a.start)
    if a.fusion:
        if a.file is not None or a.units or a.but or a.tracks:
            raise ValueError("source --fusion: a fusion node publishes its tracks only (no --file, --units, "
                             "--but or --tracks)")
        msgs = play.fused(sc, a.fusion)
    elif a.file is None:
        msgs = play.share(sc, a.units, a.tracks, a.but or ())
    else:
        f = sys.stdin if a.file == "-" else open(a.file, encoding="utf-8")
        msgs = play.read_lines(f, a.format, a.entity, start)
    conf = config(a.listen, a.connect, a.zenoh_config, a.multicast, a.pki, f"source.{a.name}", sc, root, **_zmode(a))
    with zenoh.open(conf) as s:
        from ..live.groupframes import grouper
        src = LiveSource(s, KeySpace.of(sc, root), a.name, a.state, cache=a.cache, yielding=a.yield_catch_up,
                         catch_up_kbit=a.catch_up_kbit, groups=grouper(sc, root) if a.by_group else None)
        pace = None
        if not a.speed and not a.live:   # as fast as possible: no further ahead than its EAs allow
            from ..live.pace import SourcePace
            pace = SourcePace(s, src.ks, a.name)
        print(f"ready source {a.name} epoch={src.epoch}", flush=True)
        n = play.publish(src, msgs, a.speed, start, until=a.until, paced_from=paced, pace=pace)
        src.close(end=not a.keep_open)
        waited = f" waited={pace.waits}x/{pace.waited_s:.1f}s for its EAs" if pace is not None else ""
        print(f"end source {a.name} messages={n} frames={src.seq}{waited}", flush=True)
        if pace is not None:
            pace.close()
        stayed = src.linger(a.linger, a.linger_max) if a.linger else 0.0   # serving late joiners and catch-ups
        if (j := src.journal) is not None:
            print(f"source {a.name}: stayed {stayed:.0f} s after its end; its journal sent {j.served} frames, held "
                  f"back {j.pacer.withheld if j.pacer else 0} for its pace, answered {j.errors} bad asks", flush=True)
        src.stop()
    return 0


def cmd_peer(a) -> int:
    from ..launch.zenoh_config import config
    sc = S.load(a.scenario, events=False)
    if a.unit not in sc.taskorg.units:
        raise KeyError(f"unknown unit {a.unit!r}: not in the task organization of {sc.name}")
    root = a.root or f"saim/{sc.name}"
    conf = config(a.listen, a.connect, a.zenoh_config, a.multicast, a.pki, f"ea.{a.unit}", sc, root, **_zmode(a))
    import zenoh

    from ..live.peer import main_live_peer
    misplaced = None
    if a.topology:   # attached to another command post's router: said once it is on the mesh
        from ..net.topology import read_resolved
        topo, eps = read_resolved(a.topology)
        misplaced = topo.misplaced(a.unit, sc.taskorg, eps, list(a.connect or []))
    try:
        return main_live_peer(sc, a.unit, conf, root, a.sources, a.out, a.config, a.deadline, _start_of(a), a.armed,
                              a.linger, misplaced)
    except zenoh.ZError as e:   # nobody at its endpoints (its router down): one line, not a traceback
        if "Unable to connect" not in str(e):
            raise
        print(f"saim-mesh peer: EA of {a.unit} cannot join the mesh at {', '.join(a.connect or [])}: "
              f"{str(e).split(' at ')[0]}", file=sys.stderr, flush=True)
        return 4


def cmd_router(a) -> int:
    from ..net.router import main_router
    from ..launch.zenoh_config import config
    sc = S.load(a.scenario, events=False)
    root = a.root or f"saim/{sc.name}"
    routers = _zmode(a)["routers"] or [a.name]
    if a.name not in routers:
        raise KeyError(f"router {a.name!r} is not in the topology {a.topology} ({', '.join(routers)})")
    conf = config(a.listen, a.connect, a.zenoh_config, False, a.pki, f"router.{a.name}", sc, root, mode="router",
                  routers=routers)
    return main_router(a.name, conf, root)


def cmd_topology(a) -> int:
    from ..net import topology as T
    sc = S.load(a.scenario, events=False)
    topo = T.load(a.file, sc.taskorg) if a.file else T.derive(sc.taskorg)
    if a.out:
        T.write(topo, a.out)
    units = S.mesh_units(sc)
    for n, r in sorted(topo.routers.items()):
        leaves = [u for u in units if topo.router_of(u, sc.taskorg) == n]
        print(f"{n:>10}  cp {r.cp:<6} links {','.join(r.links) or '-':<10} {len(leaves):>3} EA peers: "
              f"{' '.join(leaves)}")
    return 0


def cmd_sources(a) -> int:
    """A scenario's command-post sources and the `saim-mesh source` arguments each needs:
    what a by-hand mesh starts beside its EAs (`mesh up` starts the same)."""
    import json

    from ..live.depend import cp_shares
    sc = S.load(a.scenario, events=False)
    shares = cp_shares(sc)
    to = sc.taskorg
    if a.json:
        print(json.dumps({n: {"args": sh.args(), "units": sorted(sh.carries(to)), "tracks": sh.tracks}
                          for n, sh in sorted(shares.items())}, indent=1))
        return 0
    for n, sh in sorted(shares.items()):
        k = len(sh.carries(to))
        said = (f"fusion node of sensor group {sh.fusion}: its tracks" if sh.fusion else
                f"{k} unit{'' if k == 1 else 's'}{', hostile tracks' if sh.tracks else ''}")
        print(f"{n:<10} saim-mesh source {a.scenario} --name {n} {' '.join(sh.args())}   # {said}")
    return 0


def cmd_mesh(a) -> int:
    import signal

    from ..live.up import up
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))   # stopped: still reap every child (up's finally)
    if a.pki and a.insecure:
        raise ValueError("mesh up: --pki and --insecure: certificates are for a secure mesh; give one of them")
    res = up(a.scenario, a.units, Path(a.out_dir), "max" if a.speed is None else str(a.speed),
             live=a.live, insecure=a.insecure, topology=a.topology, link=_link_args(a),
             console=a.console, console_linger=a.console_linger, max_restarts=a.restarts,
             tak=_live_tak(a), pki=Path(a.pki) if a.pki else None, root=a.root)
    return 0 if len(res["peers"]) == len(res["units"]) and not res["given_up"] else 1


def _link_args(a) -> dict | None:
    """`mesh up --topology ... --link-delay-ms D --link-loss P`: every router link emulated."""
    if a.topology is None or a.link_delay_ms is None and a.link_loss is None:
        return None
    if not 0.0 <= (a.link_loss or 0.0) < 1.0:
        raise ValueError(f"--link-loss {a.link_loss}: expected a share in [0, 1)")
    return {"delay_ms": a.link_delay_ms or 0.0, "loss": a.link_loss or 0.0}


def _live_tak(a):
    """`mesh up --tak URL... [--tak-in URL...] [--tak-uids FILE] [--tak-proto 0|1]` on the live
    mesh: the gateway as the launcher runs it (`deploy.file.Tak`), or None."""
    if not (a.tak or a.tak_in or a.tak_uids or a.tak_proto):
        return None
    if not a.tak:
        raise ValueError("mesh up: --tak-in, --tak-uids and --tak-proto go with --tak URL ... (where CoT goes)")
    if a.tak_in and not a.live:
        raise ValueError("mesh up: --tak-in takes TAK users' PLI on the wall clock: give --live too (a recorded "
                         "battle at --speed has no wall-clock event time to give them)")
    from ..deploy.file import Tak
    uids = str(Path(a.tak_uids).resolve()) if a.tak_uids else None
    if uids is not None and not Path(uids).is_file():
        raise ValueError(f"mesh up: --tak-uids {a.tak_uids}: no such file")
    return Tak(tuple(a.tak), tuple(a.tak_in or ()), uids, "1" if a.tak_proto == "1" else "xml")


def cmd_tak(a) -> int:
    from ..tak.gateway import main_tak
    from ..launch.zenoh_config import config
    sc = S.load(a.scenario, events=False)
    root = a.root or f"saim/{sc.name}"
    conf = config(a.listen, a.connect, a.zenoh_config, a.multicast, a.pki, "tak", sc, root, **_zmode(a))
    a.live_start = _start_of(a)
    return main_tak(sc, conf, root, a)


def add(sub) -> None:
    """Register the mesh's process commands on `sub`."""
    pe = sub.add_parser("peer", help="run one unit's EA as a Zenoh peer on the event time of its sources")
    pe.add_argument("--scenario", required=True)
    pe.add_argument("--unit", required=True)
    pe.add_argument("--out", metavar="FILE", help="append alerts as JSON lines")
    pe.add_argument("--config", metavar="TOML")
    pe.add_argument("--armed", action="store_true",
                    help="a console watches: unacknowledged flash and immediate alerts are re-notified and "
                         "escalated to the superior ([notify])")
    pe.add_argument("--deadline", type=_seconds, default=None, metavar="S",
                    help="stop after S seconds of wall time, with its summary as at a normal end")
    pe.add_argument("--sources", nargs="+", metavar="NAME", required=True,
                    help="the sources it depends on (`saim-mesh sources`): it advances on the event time their "
                         "watermarks promise")
    pe.add_argument("--live", action="store_true", help="event time is the wall clock from --start")
    pe.add_argument("--start", metavar="ISO8601", help="--live: the instant of event time 0 (default now)")
    pe.add_argument("--linger", type=_seconds, default=0.0,
                    help="seconds to keep answering commands after every source ended")
    _zenoh_args(pe)
    pe.set_defaults(fn=cmd_peer)
    so = sub.add_parser("source", help="publish one source's stream (reports and watermarks) into the mesh")
    so.add_argument("scenario")
    so.add_argument("--name", required=True, help="the source's name (e.g. the command post: cp.A)")
    so.add_argument("--units", nargs="+", metavar="UNIT",
                    help="publish the scenario's events of these units' subtrees (default: every unit)")
    so.add_argument("--but", nargs="+", metavar="UNIT", help="leave out these units' subtrees (another source's)")
    so.add_argument("--tracks", action="store_true", help="also the scenario's hostile tracks")
    so.add_argument("--file", metavar="PATH|-", help="publish reports from this file (- : standard input)")
    so.add_argument("--format", choices=["jsonl", "nmea", "gpx"], default="jsonl")
    so.add_argument("--entity", help="nmea, gpx: whose reports these are")
    so.add_argument("--speed", type=_speed, default=None, metavar="FACTOR|max")
    so.add_argument("--live", action="store_true", help="event time is the wall clock from --start")
    so.add_argument("--start", metavar="ISO8601", help="--live: the instant of event time 0 (default now); "
                    "with --speed: event time 0 is at that instant (sources paced together)")
    so.add_argument("--state", metavar="DIR", help="keep the source's epoch here (bumped at each start) and its "
                    "durable journal of frames, served for catch-up beyond the publisher's cache")
    so.add_argument("--by-group", action="store_true",
                    help="publish one stream per key group (docs/keyspace.md, \"Key groups\") instead of one "
                         "stream of everything: each EA hears only the groups of its interest")
    so.add_argument("--cache", type=int, default=None, metavar="N",
                    help="frames the publisher keeps in memory for recovery and late joiners (default 100000; "
                    "4 with --yield-catch-up and --state: its journal gives the rest, paced)")
    so.add_argument("--fusion", nargs="+", metavar="GROUP",
                    help="a sensor group's fusion node: the tracks it fuses from its sensors' hits (raw hits "
                         "stay in this process; `saim-mesh sources` names it fusion.GROUP)")
    so.add_argument("--keep-open", action="store_true", help="do not send the end-of-stream mark at the end")
    so.add_argument("--yield-catch-up", action="store_true",
                    help="recoveries and journal catch-ups yield to live traffic (DROP, lower priority): "
                         "across slow radio links, where a router stalled on them closes its links; its "
                         "journal's answers are paced (--catch-up-kbit)")
    so.add_argument("--catch-up-kbit", type=_positive, default=None, metavar="KBIT",
                    help="the journal's answers over all askers together, at most KBIT kbit/s (default: "
                         "24 with --yield-catch-up, under half of a 64 kbit/s radio; else unpaced)")
    so.add_argument("--until", type=_seconds, default=None, metavar="T", help="end the stream at event time T")
    so.add_argument("--linger", type=_seconds, default=5.0,
                    help="seconds to stay up after the last frame, and longer while its journal is still asked "
                         "(within that many seconds), up to --linger-max (default 5; 0: leave at once)")
    so.add_argument("--linger-max", type=_seconds, default=600.0, metavar="S",
                    help="the longest a source stays after its end while it is still asked (default 600)")
    _zenoh_args(so)
    so.set_defaults(fn=cmd_source)
    me = sub.add_parser("mesh", help="mesh up SCENARIO: one process per unit's EA, a source per command post, "
                                     "no centre")
    me.add_argument("action", choices=["up"])
    me.add_argument("scenario", nargs="?", default=str(DEFAULT_SCENARIO))
    me.add_argument("--live", action="store_true",
                    help="event time is the wall clock (default: the sources play the recorded battle at --speed)")
    me.add_argument("--units", nargs="+", metavar="UNIT", help="default: battalion, companies, platoons")
    me.add_argument("--speed", type=_speed, default=None, metavar="FACTOR|max")
    me.add_argument("--out-dir", default="out/mesh")
    me.add_argument("--insecure", action="store_true",
                    help="no mTLS, no access control (quick experiments only: anyone can feed the mesh)")
    me.add_argument("--pki", metavar="DIR",
                    help="the mesh's certificates (saim-mesh certs SCENARIO --out DIR --routers hub; with --topology "
                         "its routers' names); default: a test PKI made under OUT_DIR/pki")
    me.add_argument("--restarts", type=_count, default=10, metavar="N",
                    help="restart each process that dies (EA peer, source, router, console, TAK gateway) up to N "
                         "times (default 10), then give up on it with one line and go on without it (0: never "
                         "restart)")
    me.add_argument("--root",
                    help="key-expression root (default saim/<scenario>/live)")
    me.add_argument("--console", type=int, nargs="?", const=8470, default=None, metavar="PORT",
                    help="also start the top unit's commander's console on 127.0.0.1:PORT (default 8470; 0: free)")
    me.add_argument("--tak", nargs="+", metavar="URL",
                    help="also start the Cursor-on-Target gateway sending to these URLs "
                         "(udp://239.2.3.1:6969 for TAK clients on the LAN, tcp://HOST:8087 for a TAK server)")
    me.add_argument("--tak-in", nargs="+", metavar="URL", help="the gateway listens for TAK PLI here (e.g. "
                    "udp://239.2.3.1:6969, tcp://127.0.0.1:PORT)")
    me.add_argument("--tak-proto", choices=["0", "1"], default=None,
                    help="CoT out as XML (0, the default) or TAK protocol version 1 (protobuf)")
    me.add_argument("--tak-uids", metavar="FILE", help="TAK uid -> entity map, and [units]: uid -> unit for acknowledgements "
                    "(configs/tak-uids.example.toml)")
    me.add_argument("--console-linger", type=_seconds, default=300.0, metavar="S",
                    help="seconds the console stays up after the scenario's end")
    me.set_defaults(fn=cmd_mesh)
    me.add_argument("--topology", nargs="?", const="derive", default=None, metavar="TOML",
                    help="routers at command posts (a topology file; without FILE: one router per battalion "
                    "command post and one at the top, from the task organization); leaves attach as clients")
    me.add_argument("--link-delay-ms", type=_seconds, default=None, metavar="MS",
                    help="with --topology: one-way delay of every emulated router link")
    me.add_argument("--link-loss", type=float, default=None, metavar="P",
                    help="with --topology: share of segments lost (then retransmitted) on every router link")

    ro = sub.add_parser("router", help="a Zenoh router (router mode) for one command post")
    ro.add_argument("--scenario", required=True)
    ro.add_argument("--name", required=True, help="the router's name in the topology")
    _zenoh_args(ro)
    ro.set_defaults(fn=cmd_router)

    tp = sub.add_parser("topology", help="show (or write) a scenario's router topology")
    tp.add_argument("scenario", nargs="?", default=str(DEFAULT_SCENARIO))
    tp.add_argument("--file", metavar="TOML", help="check and show this topology instead of the derived one")
    tp.add_argument("--out", metavar="TOML", help="write the topology as TOML")
    tp.set_defaults(fn=cmd_topology)

    sr = sub.add_parser("sources", help="list a scenario's command-post sources and the `source` arguments each needs")
    sr.add_argument("scenario", nargs="?", default=str(DEFAULT_SCENARIO))
    sr.add_argument("--json", action="store_true", help="as JSON: name -> args, units carried, tracks")
    sr.set_defaults(fn=cmd_sources)

    from ..tak.options import add_arguments as tak_arguments
    tk = sub.add_parser("tak", help="the Cursor-on-Target gateway: the mesh's picture and alerts to TAK, "
                                    "TAK PLI in as location reports (docs/tak.md)")
    tk.add_argument("scenario")
    tak_arguments(tk)
    _zenoh_args(tk)
    tk.set_defaults(fn=cmd_tak)
    from ..net.link_cli import add_arguments as link_arguments, cmd_link
    li = sub.add_parser("link", help="an emulated radio link: a TCP proxy on loopback with delay, loss, "
                                     "cut (SIGUSR1) and heal (SIGUSR2)")
    link_arguments(li)
    li.set_defaults(fn=cmd_link)
