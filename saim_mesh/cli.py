"""`saim-mesh` command line: run, evaluate, missions, generate, validate, the mesh
(replay, peer, fusion, mesh up, deploy, certs) and a commander's commands (ack, silence, set,
confirm, cff)."""
from __future__ import annotations

import argparse
import json
import time
import math
import os
import sys
from collections import Counter
from pathlib import Path

from . import scenario as S
from .sinks import JsonlSink, TerminalSink

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_SCENARIO = ROOT / "scenarios" / "battalion"


def _speed(v: str) -> float | None:
    if v == "max":
        return None
    try:
        f = float(v)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--speed takes a factor or 'max', not {v!r}") from None
    if not math.isfinite(f) or f <= 0:
        raise argparse.ArgumentTypeError("--speed factor must be a finite number > 0")
    return f


def _seconds(v: str) -> float:
    """A finite, non-negative number of seconds (or metres)."""
    try:
        f = float(v)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, not {v!r}") from None
    if not math.isfinite(f) or f < 0:
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0, not {v!r}")
    return f


def _progress(frac: float) -> None:
    if sys.stderr.isatty():
        n = int(frac * 40)
        sys.stderr.write(f"\r[{'#' * n}{'.' * (40 - n)}] {frac * 100:5.1f}%")
        if frac >= 1.0:
            sys.stderr.write("\n")
        sys.stderr.flush()


def table(eas, alert_types=()) -> str:
    """Alerts by type per EA (like the paper's Fig. 7)."""
    cols = [ea.owner for ea in eas]
    counts = {ea.owner: Counter(a.type for a in ea.alerts) for ea in eas}
    seen = {t for c in cols for t in counts[c]}
    types = [t for t in (*alert_types, *sorted(seen - set(alert_types))) if any(counts[c][t] for c in cols)]
    w = max([len(t) for t in types] + [16])
    lines = [f"{'alert type':{w}} " + " ".join(f"{c:>6}" for c in cols),
             f"{'missions in plan':{w}} " + " ".join(
                 f"{sum(1 for m in ea.domain.missions.values() if ea.domain.in_plan(m)):>6}" for ea in eas)]
    for t in types:
        lines.append(f"{t:{w}} " + " ".join(f"{counts[c][t]:>6}" for c in cols))
    lines.append(f"{'total':{w}} " + " ".join(f"{len(ea.alerts):>6}" for ea in eas))
    lines.append(f"{'  of which flash':{w}} " + " ".join(
        f"{sum(1 for a in ea.alerts if a.priority == 'flash'):>6}" for ea in eas))
    return "\n".join(lines)


def cmd_run(a) -> int:
    from ea_agent import domains

    from .runner import config_for, default_eas, run
    sc = S.load(a.scenario)
    owners = a.ea or default_eas(sc)
    for o in owners:   # every bad input is reported before anything runs or is written
        if o not in sc.taskorg.units:
            raise KeyError(f"--ea {o}: unknown unit {o!r}: not in the task organization of {sc.name} "
                           f"({sc.root / 'plan.json'})")
        config_for(sc, o, a.config)
    from .cmdlog import read as read_commands
    cmds = read_commands(a.commands, set(sc.taskorg.units)) if a.commands else None
    sinks = [] if a.quiet else [TerminalSink()]
    out = open(a.out, "w", buffering=1) if a.out else None   # line-buffered; JsonlSink flushes each alert
    notice_sinks: list = []
    if out:
        sinks.append(JsonlSink(out))
        from .noticelog import NoticeLog, path_for
        nlog = NoticeLog(path_for(a.out))   # re-notifications and escalations, beside the alerts
        notice_sinks.append(nlog)
    try:
        consoles: list = []
        if a.console is not None:
            from .console.main import start_inprocess
            consoles.append(lambda eas: start_inprocess(sc, eas, a.console)[1])
        stops: list = []
        eas = run(sc, owners, sinks, voa=not a.no_voa, config_path=a.config, speed=a.speed, progress=_progress,
                  on_made=(lambda eas: stops.append(consoles[0](eas))) if consoles else None,
                  commands=cmds, armed=a.armed or a.console is not None, notice_sinks=notice_sinks)
    finally:
        if out:
            out.close()
            nlog.close()
    print()
    print(table(eas, tuple(domains.of(sc).ALERT_TYPES)))
    if stops:
        import time
        print(f"console: serving for {a.linger:.0f} s more (Ctrl-C to stop)", flush=True)
        try:
            time.sleep(a.linger)
        except KeyboardInterrupt:
            pass
        stops[0]()
    errs = sum(ea.stats["errors"] for ea in eas)
    if errs:
        print(f"\n{errs} bad inputs were counted and dropped; last: {eas[0].errors[-1:] or '-'}")
    return 0


def cmd_evaluate(a) -> int:
    from .evaluate import evaluate
    res = evaluate(S.load(a.scenario), config_path=a.config, commander=a.commander)
    if a.json:
        print(json.dumps(res, sort_keys=True))
    else:
        for k in ("events", "incidents", "recall", "alerts", "naive_alerts", "reduction", "unwanted",
                  "unwanted_share", "unwanted_flash", "by_type"):
            print(f"{k:15} {res[k]}")
        if "commander" in res:
            c = res["commander"]
            print(f"commander {c['model']}: shown {c['shown']} ({c['alerts_shown']} alerts, {c['renotifications']} "
                  f"re-notifications, {c['escalations']} escalations), worst {c['shown_per_commander_hour_worst']}"
                  f"/commander/hour, unwanted {c['unwanted_share']:.1%}, unwanted flash {c['unwanted_flash']}, "
                  f"priorities as unarmed: {c['priorities_equal']}")
        for m in res["missed"]:
            print("MISSED ", m)
        for u in res["unwanted_alerts"]:
            print("UNWANTED", u)
    return 0


def cmd_missions(a) -> int:
    import importlib

    from ea_agent import domains
    domains.get(a.domain)
    registry = importlib.import_module(f"{domains.DOMAINS[a.domain]}.missions").REGISTRY
    for name, cls in sorted(registry.items()):
        parents = " < ".join(k.__name__ for k in cls.__mro__[1:-1])
        req = set(cls.required())
        params = ", ".join(f"{p}{'' if p in req else '?'}" for p in cls.all_params())
        rule = getattr(cls, "LOCATION_RULE", None)
        print(f"{name:22} [{parents}]{f' location={rule}' if rule else ''}\n{'':22} params: {params}")
        for c in getattr(cls, "CHECKS", ()):
            print(f"{'':22} checks: {c}")
        if getattr(cls, "PRIORITY", None):
            print(f"{'':22} priority: " + ", ".join(f"{k} {v}" for k, v in sorted(cls.PRIORITY.items())))
    return 0


def cmd_generate(a) -> int:
    from ea_agent import domains
    dom = domains.get(a.domain)
    extra = {"small": a.small, "sensors": a.sensors, "incidents": a.incidents} if a.domain == "suo" else {}
    if a.brigade:
        if a.domain != "suo":
            print("generate: --brigade is an SUO scenario: leave out --domain uv", file=sys.stderr)
            return 2
        extra["brigade"] = True
    try:
        print(json.dumps(dom.generate(Path(a.out), seed=a.seed, **extra)))
    except ValueError as e:
        print(f"generate: {e}", file=sys.stderr)
        return 2
    return 0


def cmd_validate(a) -> int:
    """Everything `run` would trip on: the whole scenario (events too), the default
    configuration of each default EA, and those EAs built and started on every plan."""
    from ea_agent.core.config import ConfigError

    from .runner import config_for, default_eas, make_ea
    sc = S.load(a.scenario)
    owners = default_eas(sc)
    for o in owners:   # `run` without --ea runs these
        if o not in sc.taskorg.units:
            raise S.ScenarioError(f"scenario.json: field 'default_eas': missing, and the built-in default EA "
                                  f"{o!r} is not a unit of this scenario (list the owners to run by default)")
    top = sc.taskorg.root
    for o in dict.fromkeys([*owners, top]):
        cfg = config_for(sc, o)
        try:
            ea = make_ea(sc, o, cfg)
            ea.start(0.0)
            if o == top:   # the top unit's EA monitors every mission: start each plan once
                for name in sc.plans:
                    ea.domain.execute_plan(name, 0.0)
        except ConfigError:
            raise
        except (KeyError, ValueError, TypeError) as e:
            raise S.ScenarioError(f"{sc.root}: the EA of {o} cannot start: {type(e).__name__}: "
                                  f"{e.args[0] if e.args else e}") from e
    places = getattr(sc, "overlay", None) or getattr(sc, "world", {})
    print(f"{sc.name}: {len(sc.taskorg.units)} units, {len(sc.taskorg.entity_unit)} entities, "
          f"{sum(len(p.missions) for p in sc.plans.values())} missions, {len(places)} places, "
          f"{len(sc.events)} events: OK")
    return 0


def cmd_replay(a) -> int:
    from .replay import main_replay
    from .zconf import config
    sc = S.load(a.scenario)
    root = a.root or f"saim/{sc.name}"
    conf = config(a.listen, a.connect, a.zenoh_config, a.multicast, a.pki, "replay", sc, root, **_zmode(a))
    sources, topo = None, None
    if a.topology:   # one client session per router: each unit's reports enter at its own command post
        from .net.topology import read_resolved
        topo, eps = read_resolved(a.topology)
        sources = {n: config(None, [ep], a.zenoh_config, False, a.pki, "replay", sc, root, mode="client",
                             routers=sorted(eps)) for n, ep in eps.items()}
    return main_replay(sc, conf, root, a.speed, a.wait_peers or [], a.linger, a.until, a.window, a.state,
                       sources, topo)


def _start_of(a) -> float | None:
    """--live: the wall time of event time 0 (--start ISO8601, default now)."""
    if not getattr(a, "live", False):
        return None
    return _instant(a.start) if a.start else time.time()


def _instant(text: str) -> float:
    from datetime import datetime, timezone
    try:
        d = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise ValueError(f"--start {text!r}: expected an ISO 8601 time, e.g. 2026-11-27T09:00:00Z") from None
    return (d if d.tzinfo else d.replace(tzinfo=timezone.utc)).timestamp()


def cmd_source(a) -> int:
    """Publish one source's stream: a command post's share of a recorded scenario, or reports
    from a file or standard input (docs/architecture.md, the live mesh)."""
    import zenoh

    from dissemination.keyspace import KeySpace

    from .live import play
    from .live.source import LiveSource
    from .zconf import config
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
    if a.file is None:
        msgs = play.share(sc, a.units, a.tracks, a.but or ())
    else:
        f = sys.stdin if a.file == "-" else open(a.file, encoding="utf-8")
        msgs = play.read_lines(f, a.format, a.entity, start)
    conf = config(a.listen, a.connect, a.zenoh_config, a.multicast, a.pki, f"source.{a.name}", sc, root, **_zmode(a))
    with zenoh.open(conf) as s:
        src = LiveSource(s, KeySpace.of(sc, root), a.name, a.state, cache=a.cache)
        print(f"ready source {a.name} epoch={src.epoch}", flush=True)
        n = play.publish(src, msgs, a.speed, start, until=a.until, paced_from=paced)
        src.close(end=not a.keep_open)
        print(f"end source {a.name} messages={n} frames={src.seq}", flush=True)
        if a.linger:
            time.sleep(a.linger)   # the publisher's cache serves late joiners and recoveries meanwhile
        src.stop()
    return 0


def cmd_peer(a) -> int:
    from .peer import main_peer
    from .zconf import config
    sc = S.load(a.scenario, events=False)
    if a.unit not in sc.taskorg.units:
        raise KeyError(f"unknown unit {a.unit!r}: not in the task organization of {sc.name}")
    root = a.root or f"saim/{sc.name}"
    conf = config(a.listen, a.connect, a.zenoh_config, a.multicast, a.pki, f"ea.{a.unit}", sc, root, **_zmode(a))
    if a.sources:   # the live mesh: event time from the sources' own watermarks, no replay
        from .live.peer import main_live_peer
        return main_live_peer(sc, a.unit, conf, root, a.sources, a.out, a.config, a.deadline, _start_of(a), a.armed,
                              a.linger)
    misplaced = None
    if a.topology:   # attached to another command post's router: it works, but its reports cross a radio link
        from .net.topology import read_resolved
        topo, eps = read_resolved(a.topology)
        own = topo.router_of(a.unit, sc.taskorg)
        if eps[own] not in (a.connect or []):
            where = next((n for n, ep in eps.items() if ep in (a.connect or [])), "no router of the topology")
            misplaced = (f"EA of {sc.taskorg.units[a.unit].name} is attached to {where}, not to its command post's "
                         f"router {own}: its traffic crosses radio links it should not")
    return main_peer(sc, a.unit, conf, root, a.out, a.config, a.radius, a.deadline, a.connect, a.armed, misplaced)


def cmd_fusion(a) -> int:
    from .fusion.peer import main_fusion
    from .zconf import config
    sc = S.load(a.scenario, events=False)
    if a.group not in sc.meta.get("fusion", {}).get("groups", {}):
        raise KeyError(f"unknown fusion group {a.group!r}: not in {sc.name}'s scenario.json")
    root = a.root or f"saim/{sc.name}"
    conf = config(a.listen, a.connect, a.zenoh_config, a.multicast, a.pki, f"fusion.{a.group}", sc, root,
                  **_zmode(a))
    return main_fusion(sc, a.group, conf, root, a.shuffle)


def cmd_router(a) -> int:
    from .net.router import main_router
    from .zconf import config
    sc = S.load(a.scenario, events=False)
    root = a.root or f"saim/{sc.name}"
    routers = _zmode(a)["routers"] or [a.name]
    if a.name not in routers:
        raise KeyError(f"router {a.name!r} is not in the topology {a.topology} ({', '.join(routers)})")
    conf = config(a.listen, a.connect, a.zenoh_config, False, a.pki, f"router.{a.name}", sc, root, mode="router",
                  routers=routers)
    return main_router(a.name, conf, root)


def cmd_topology(a) -> int:
    from .net import topology as T
    sc = S.load(a.scenario, events=False)
    topo = T.load(a.file, sc.taskorg) if a.file else T.derive(sc.taskorg)
    if a.out:
        T.write(topo, a.out)
    units = __import__("saim_mesh.mesh", fromlist=["mesh_units"]).mesh_units(sc)
    for n, r in sorted(topo.routers.items()):
        leaves = [u for u in units if topo.router_of(u, sc.taskorg) == n]
        print(f"{n:>10}  cp {r.cp:<6} links {','.join(r.links) or '-':<10} {len(leaves):>3} EA peers: "
              f"{' '.join(leaves)}")
    return 0


def cmd_mesh(a) -> int:
    import signal

    from .mesh import up
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))   # stopped: still reap every child (up's finally)
    if a.replay and (a.live or a.sources_per_cp):
        raise ValueError("mesh up: --replay is the older mesh; --live and --sources-per-cp are the mesh with no centre")
    from ea_agent import domains
    if not a.replay and not (a.live or a.sources_per_cp) and domains.of(S.load(a.scenario, events=False)).NAME == "uv":
        print("mesh up: the robot team's mesh with no centre is `saim-mesh robots team OUT` (robots obeying their "
              "EAs); running the older replay mesh for this scenario (as --replay)", flush=True)
        a.replay = True
    if not a.replay:   # the mesh with no centre: sources per command post, no replay
        from .live.up import up as live_up
        for bad, flag in ((a.tak or a.tak_in or a.tak_uids, "--tak (run `saim-mesh tak --sources` beside it)"),
                          (a.pki, "--pki (it makes its own test PKI)"), (a.root, "--root"),
                          (a.window != 20.0, "--window (the sources pace themselves)"),
                          (a.restarts != 10, "--restarts")):
            if bad:
                raise ValueError(f"mesh up: {flag} is only for the older mesh (--replay)")
        res = live_up(a.scenario, a.units, Path(a.out_dir), "max" if a.speed is None else str(a.speed),
                      live=a.live, insecure=a.insecure, topology=a.topology, link=_link_args(a),
                      console=a.console, console_linger=a.console_linger)
        return 0 if len(res["peers"]) == len(a.units or res["peers"]) else 1
    res = up(a.scenario, a.units, Path(a.out_dir), "max" if a.speed is None else str(a.speed), window=a.window,
             insecure=a.insecure, pki=Path(a.pki) if a.pki else None, max_restarts=a.restarts, root=a.root,
             console=a.console, console_linger=a.console_linger, tak=_tak_args(a),
             topology=a.topology, link=_link_args(a))
    return 0 if len(res["peers"]) == len(a.units or res["peers"]) and not res["given_up"] else 1


def _link_args(a) -> dict | None:
    """`mesh up --topology ... --link-delay-ms D --link-loss P`: every router link emulated."""
    if a.topology is None or a.link_delay_ms is None and a.link_loss is None:
        return None
    if not 0.0 <= (a.link_loss or 0.0) < 1.0:
        raise ValueError(f"--link-loss {a.link_loss}: expected a share in [0, 1)")
    return {"delay_ms": a.link_delay_ms or 0.0, "loss": a.link_loss or 0.0}


def _tak_args(a) -> list[str] | None:
    """`mesh up --tak URL... [--tak-in URL...] [--tak-uids FILE]`: the gateway's own options."""
    if not a.tak:
        return None
    out = [x for u in a.tak for x in ("--cot-url", u)] + [x for u in a.tak_in or () for x in ("--listen-cot", u)]
    return out + (["--uids", a.tak_uids] if a.tak_uids else [])


def cmd_tak(a) -> int:
    from .tak.gateway import main_tak
    from .zconf import config
    sc = S.load(a.scenario, events=False)
    root = a.root or f"saim/{sc.name}"
    conf = config(a.listen, a.connect, a.zenoh_config, a.multicast, a.pki, "tak", sc, root, **_zmode(a))
    if a.live and not a.sources:
        raise ValueError("tak --live: give --sources too (the live mesh; the replay mesh has its own clock)")
    a.live_start = _start_of(a)
    return main_tak(sc, conf, root, a)


def cmd_certs(a) -> int:
    from ea_agent import domains

    from .security.pki import make_pki, names_for
    if a.deploy:   # each host's addresses and names in its processes' certificates
        from .deploy import certs
        from .deploy.file import DeployError, load
        try:
            dep, sc = load(a.deploy)
        except DeployError as e:
            return _lines(e.lines)
        out = Path(a.out) if a.out else dep.pki
        made = certs.make(dep, sc, out)
        sans = certs.sans_of(dep)
        print(f"{len(made)} identities in {out} (CA: {out / 'ca.pem'}); {sum(1 for n in sans if sans[n])} of them "
              "also name their host's addresses: "
              + "; ".join(f"{h.name} {' '.join((*h.addresses, *h.names)) or '-'}" for h in dep.hosts.values()))
        return 0
    sc = S.load(a.scenario, events=False)
    out = a.out or "out/pki"
    made = make_pki(Path(out), names_for(sc, a.units or domains.of(sc).mesh_units(sc), consoles=True))
    print(f"{len(made)} identities in {out} (CA: {Path(out) / 'ca.pem'}): {', '.join(sorted(made))}")
    return 0


def _lines(lines: list[str], out=None) -> int:
    """Each problem on its own line (stderr by default), exit code 2."""
    for x in lines:
        print(x, file=out or sys.stderr)
    return 2


def cmd_deploy(a) -> int:
    """`deploy init SCENARIO`, `deploy FILE --check [--host H]`, `deploy FILE --host H`."""
    from .deploy.file import DeployError, load
    if a.file == "init":
        if not a.scenario:
            raise ValueError("deploy init SCENARIO: give the scenario folder")
        from .deploy import init
        if not 1 <= a.port <= 65535:
            raise ValueError(f"deploy init: --port {a.port} out of range (1-65535)")
        sc = S.load(a.scenario, events=False)
        out = Path(a.out or f"deploy-{sc.name}.toml")
        try:
            dep = init.write(sc, a.scenario, out, addresses=a.addresses, port=a.port, consoles=not a.no_consoles,
                             secure=not a.insecure, pki=a.pki)
        except ValueError as e:   # --addresses
            raise ValueError(f"deploy init: {e}") from None
        print(f"{out}: {len(dep.hosts)} hosts ({', '.join(dep.hosts)}), {len(dep.routers)} routers, "
              f"{len(dep.eas())} EA peers, {len(dep.sources())} sources")
        return 0
    if a.scenario:
        raise ValueError(f"deploy {a.file}: unexpected {a.scenario!r} (deploy FILE --check | --host NAME; "
                         "deploy init SCENARIO)")
    try:
        dep, sc = load(a.file, a.host)
    except DeployError as e:
        return _lines(e.lines, sys.stdout if a.check else None)
    if a.check:
        where = f" host {a.host}: {len(dep.hosts[a.host].eas)} EA peers," if a.host else ""
        print(f"{a.file}: OK: {len(dep.hosts)} hosts, {len(dep.routers)} routers, {len(dep.eas())} EA peers, "
              f"{len(dep.sources())} sources;{where} {'secure' if dep.secure else 'insecure'}")
        return 0
    if not a.host:
        raise ValueError(f"deploy {a.file}: give --host NAME (one of {', '.join(dep.hosts)}) or --check")
    import signal

    from .deploy.launch import run_host
    from .security.pki import SecurityError
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))   # stopped: still reap every child (run_host's finally)
    out = Path(a.out_dir or f"out/deploy/{a.host}")
    try:
        res = run_host(dep, sc, a.host, out, show=not a.quiet, timeout=a.timeout, until_done=a.exit_when_done,
                       console_linger=a.console_linger, max_restarts=a.restarts, fresh=a.fresh or None)
    except (SecurityError, RuntimeError, TimeoutError) as e:   # a child that would not start: one line
        return _fail(e)
    except KeyboardInterrupt:
        return 130
    return 0 if len(res["peers"]) == len(res["units"]) or not a.exit_when_done else 1


def _command_fields(a) -> tuple[str, dict]:
    if a.cmd == "ack":
        return "ack", {"alert": a.alert, "by": a.by}
    if a.cmd == "silence":
        if a.lift:
            return "unsilence", {"id": a.id}
        if a.until is None:
            raise ValueError("silence: --until T (scenario time) is required, or --lift")
        return "silence", {"id": a.id, "types": a.types, "subjects": a.subjects, "areas": a.areas,
                           "until_t": a.until, "comment": a.comment}
    if a.cmd == "set":
        try:
            value = json.loads(a.value)
        except json.JSONDecodeError:
            raise ValueError(f"set: --value {a.value!r}: expected a number or a JSON list of numbers") from None
        return "set", {"key": a.key, "value": value}
    if a.cmd == "confirm":
        return "confirm", {"mission": a.mission, "phase": a.phase}
    if a.cmd == "decide":
        return "decide", {"alert": a.alert, "option": a.option}
    if a.cmd == "inhibit":
        if a.lift:
            return "uninhibit", {"id": a.id}
        from . import wire as W
        src = {k: v for k, v in (("types", a.source_types), ("subjects", a.source_subjects),
                                 ("priorities", a.source_priorities)) if v}
        tgt = {k: v for k, v in (("types", a.target_types), ("subjects", a.target_subjects),
                                 ("priorities", a.target_priorities)) if v}
        if not src or not tgt:
            raise ValueError("inhibit: give at least one --source-* and one --target-* matcher, or --lift")
        try:
            return "inhibit", {"id": a.id, "source": W.MatcherSpec(**src), "target": W.MatcherSpec(**tgt),
                               "equal": a.equal, "for_s": a.for_s or 0.0, "comment": a.comment}
        except TypeError as e:
            raise ValueError(f"inhibit: {e}") from None
    return "cff", {"cff": a.cff, "action": a.action}


def cmd_command(a) -> int:
    """Send one command to a unit's EA peer as `console.<unit>` (or --as) and print its
    answer as JSON; exit 0 if the EA took it, 2 if not (or no answer in time)."""
    import zenoh

    from dissemination.keyspace import KeySpace

    from . import commands as C
    from .mesh import mesh_units
    from .zconf import config
    sc = S.load(a.scenario, events=False)
    if a.unit not in sc.taskorg.units:
        raise KeyError(f"unknown unit {a.unit!r}: not in the task organization of {sc.name}")
    kind, fields = _command_fields(a)
    cmd = C.make(kind, **fields)
    root = a.root or f"saim/{sc.name}"
    name = a.as_ or (f"console.{a.unit}" if a.unit in mesh_units(sc) else f"console.{sc.taskorg.root}")
    from .security.sign import signer_for
    conf = config(None, a.connect, a.zenoh_config, a.multicast, a.pki, name, sc, root)
    signer = signer_for(conf)   # secure mode: signed as `name`
    with zenoh.open(conf) as session:
        res = C.send(session, KeySpace.of(sc, root), a.unit, cmd, C.by_of(name, a.unit), a.timeout, signer)
    print(json.dumps(C.to_dict(res)))
    return 0 if res.ok else 2


def cmd_console(a) -> int:
    from .console.main import main_console
    from .zconf import config
    sc = S.load(a.scenario, events=False)
    unit = a.unit or sc.taskorg.root
    if unit not in sc.taskorg.units:
        raise KeyError(f"unknown unit {unit!r}: not in the task organization of {sc.name}")
    root = a.root or f"saim/{sc.name}"
    conf = config(a.listen, a.connect, a.zenoh_config, a.multicast, a.pki, f"console.{unit}", sc, root, **_zmode(a))
    return main_console(sc, conf, root, unit, a.port, a.linger, live=a.sources)


def cmd_report(a) -> int:
    from .report import main_report
    return main_report(a.out, a.alerts, a.title)


def _fail(what) -> int:
    """One line on stderr and exit code 2 (SAIM_MESH_DEBUG=1 re-raises for the traceback)."""
    if os.environ.get("SAIM_MESH_DEBUG"):
        raise
    print("saim-mesh: " + " ".join(str(what).split()), file=sys.stderr)
    return 2


class _Parser(argparse.ArgumentParser):
    """Usage errors in one line (`--help` still shows the usage)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {' '.join(message.split())} (see {self.prog} --help)\n")


def _zmode(a) -> dict:
    """--mode and the routers of --topology (a resolved topology written by `mesh up`)."""
    routers: list[str] = []
    if getattr(a, "topology", None):
        from .net.topology import routers_of_resolved
        routers = routers_of_resolved(a.topology)
    return {"mode": getattr(a, "mode", None), "routers": routers}


def _zenoh_args(p) -> None:
    p.add_argument("--listen", nargs="*", metavar="ENDPOINT", help="e.g. tcp/127.0.0.1:7447")
    p.add_argument("--connect", nargs="*", metavar="ENDPOINT")
    p.add_argument("--zenoh-config", metavar="JSON5", help="default configs/zenoh-peer.json5")
    p.add_argument("--multicast", action="store_true",
                   help="discover peers by UDP multicast scouting (a LAN) instead of configured endpoints only")
    p.add_argument("--root", help="key-expression root (default saim/<scenario name>)")
    p.add_argument("--mode", choices=["peer", "client"], default=None,
                   help="Zenoh mode: client when attached to a router (mesh up --topology), peer otherwise")
    p.add_argument("--topology", metavar="JSON", help="the resolved topology `mesh up --topology` wrote "
                   "(its routers' identities are accepted as relays)")
    p.add_argument("--pki", metavar="DIR", help="secure mode: mutual TLS with this folder's certificates "
                   "(saim-mesh certs) and the mesh's access-control rules; endpoints are then tls/...")


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else list(argv)
    if args[:1] == ["robots"]:   # the robot team that obeys its EAs has its own subcommands
        from .robots.cli import main as robots_main
        return robots_main(args[1:])
    p = _Parser(prog="saim-mesh", description=__doc__)
    sub = p.add_subparsers(dest="cmd", required=True)
    sub.add_parser("robots", help="robots that obey their EAs over the mesh: robots team OUT | robot | ea | hub "
                                  "(saim-mesh robots -h)")
    r = sub.add_parser("run", help="run EAs in one process over a scenario")
    r.add_argument("scenario", nargs="?", default=str(DEFAULT_SCENARIO))
    r.add_argument("--ea", nargs="+", metavar="UNIT", help="owners (default: BN, every company, one platoon)")
    r.add_argument("--speed", type=_speed, default=None, metavar="FACTOR|max")
    r.add_argument("--out", metavar="FILE", help="write alerts as JSON lines")
    r.add_argument("--config", metavar="TOML", help="EA parameters (default configs/ea.toml)")
    r.add_argument("--no-voa", action="store_true", help="naive baseline: every candidate is an alert")
    r.add_argument("--quiet", action="store_true", help="do not print alerts as they come")
    r.add_argument("--console", type=int, default=None, metavar="PORT",
                   help="serve the commander's console on 127.0.0.1:PORT (0: a free port) during the run")
    r.add_argument("--linger", type=_seconds, default=30.0, help="seconds the console stays up after the run")
    r.add_argument("--commands", nargs="+", metavar="CMDLOG",
                   help="apply a commander's commands as logged by mesh peers (<unit>.cmdlog): replays a run "
                        "with a console in the loop to the same alerts")
    r.add_argument("--armed", action="store_true",
                   help="a commander watches from the start (as under `mesh up --console`): unacknowledged flash "
                        "and immediate alerts are re-notified and escalated ([notify]; --out FILE: notices in "
                        "FILE's .notify.jsonl); --console implies it")
    r.set_defaults(fn=cmd_run)
    e = sub.add_parser("evaluate", help="score alerts against the scenario's ground truth")
    e.add_argument("scenario", nargs="?", default=str(DEFAULT_SCENARIO))
    e.add_argument("--json", action="store_true")
    e.add_argument("--config", metavar="TOML")
    e.add_argument("--commander", choices=["none", "slow", "diligent"],
                   help="also run the EAs armed with a modelled commander (none: never acknowledges; slow: "
                        "acknowledges each urgent alert after 5 min; diligent: after 30 s) and score what they saw")
    e.set_defaults(fn=cmd_evaluate)
    mi = sub.add_parser("missions", help="list a domain's mission model")
    mi.add_argument("--domain", default="suo", choices=["suo", "uv"])
    mi.set_defaults(fn=cmd_missions)
    g = sub.add_parser("generate", help="generate a scenario (seeded, deterministic): the battalion, or --domain uv")
    g.add_argument("out")
    g.add_argument("--domain", default="suo", choices=["suo", "uv"])
    g.add_argument("--small", action="store_true", help="small fast variant for tests")
    g.add_argument("--brigade", action="store_true",
                   help="suo: a brigade (three battalions and brigade troops, ~4,000 entities; with --small ~350)")
    g.add_argument("--seed", type=int, default=7)
    g.add_argument("--sensors", action="store_true", help="raw sensor hits instead of ready-made tracks")
    g.add_argument("--incidents", default="scripted", choices=["scripted", "random"],
                   help="suo: the labelled scripted battle, or one drawn at random from the seed")
    g.set_defaults(fn=cmd_generate)
    v = sub.add_parser("validate", help="load a scenario and report what is wrong")
    v.add_argument("scenario")
    v.set_defaults(fn=cmd_validate)
    rp = sub.add_parser("replay", help="publish a scenario's events into the mesh (stands in for SAIM)")
    rp.add_argument("scenario")
    rp.add_argument("--speed", type=_speed, default=None, metavar="FACTOR|max")
    rp.add_argument("--wait-peers", nargs="*", metavar="UNIT",
                    help="start when these peers are present (name a unit twice to wait for two of its peers)")
    rp.add_argument("--linger", type=_seconds, default=30.0, help="seconds to keep serving the store at the end")
    rp.add_argument("--window", type=_seconds, default=20.0, metavar="S",
                    help="at max speed, stay at most S of scenario time ahead of the slowest peer (0: no pacing)")
    rp.add_argument("--until", type=_seconds, default=None, help="stop at this scenario time")
    rp.add_argument("--state", metavar="FILE", help="progress file: a restarted replay resumes from it")
    _zenoh_args(rp)
    rp.set_defaults(fn=cmd_replay)
    pe = sub.add_parser("peer", help="run one unit's EA as a Zenoh peer")
    pe.add_argument("--scenario", required=True)
    pe.add_argument("--unit", required=True)
    pe.add_argument("--out", metavar="FILE", help="append alerts as JSON lines")
    pe.add_argument("--config", metavar="TOML")
    pe.add_argument("--armed", action="store_true",
                    help="a console watches: unacknowledged flash and immediate alerts are re-notified and "
                         "escalated to the superior ([notify])")
    pe.add_argument("--radius", type=_seconds, default=None,
                    help="geographic interest radius around our units (m); default: [dissemination] in the config")
    pe.add_argument("--deadline", type=_seconds, default=None, metavar="S",
                    help="exit (code 3) after S seconds of wall time without a clock tick from the source")
    pe.add_argument("--sources", nargs="+", metavar="NAME",
                    help="the live mesh: no replay; advance on the event time these sources' watermarks promise")
    pe.add_argument("--live", action="store_true", help="with --sources: event time is the wall clock from --start")
    pe.add_argument("--start", metavar="ISO8601", help="--live: the instant of event time 0 (default now)")
    pe.add_argument("--linger", type=_seconds, default=0.0,
                    help="with --sources: seconds to keep answering commands after every source ended")
    _zenoh_args(pe)
    pe.set_defaults(fn=cmd_peer)
    so = sub.add_parser("source", help="publish one source's stream (reports and watermarks) into the live mesh")
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
    so.add_argument("--cache", type=int, default=None, metavar="N",
                    help="frames the publisher keeps in memory for recovery and late joiners (default 100000)")
    so.add_argument("--keep-open", action="store_true", help="do not send the end-of-stream mark at the end")
    so.add_argument("--until", type=_seconds, default=None, metavar="T", help="end the stream at event time T")
    so.add_argument("--linger", type=_seconds, default=0.0, help="seconds to stay up after the last frame")
    _zenoh_args(so)
    so.set_defaults(fn=cmd_source)
    fu = sub.add_parser("fusion", help="run one sensor group's fusion node as a Zenoh peer")
    fu.add_argument("--scenario", required=True)
    fu.add_argument("--group", required=True)
    fu.add_argument("--shuffle", type=int, default=None, help="publish each window's tracks in a seeded random order")
    _zenoh_args(fu)
    fu.set_defaults(fn=cmd_fusion)
    me = sub.add_parser("mesh", help="mesh up SCENARIO: one process per unit's EA, a source per command post, "
                                     "no centre (--replay: the older mesh behind one replay process)")
    me.add_argument("action", choices=["up"])
    me.add_argument("scenario", nargs="?", default=str(DEFAULT_SCENARIO))
    me.add_argument("--live", action="store_true",
                    help="the mesh with no centre: a source per command post, EA peers on event time, no replay; "
                         "event time is the wall clock (use --sources-per-cp for a recorded battle at --speed)")
    me.add_argument("--sources-per-cp", action="store_true",
                    help="the default: the sources play the recorded battle at --speed (max: as fast as they can)")
    me.add_argument("--replay", action="store_true",
                    help="the older mesh: one replay process is every EA's clock and sequencer (a global tick, "
                         "its store for late joiners); kept to compare with and for --tak, --pki, --window")
    me.add_argument("--units", nargs="+", metavar="UNIT", help="default: battalion, companies, platoons")
    me.add_argument("--speed", type=_speed, default=None, metavar="FACTOR|max")
    me.add_argument("--out-dir", default="out/mesh")
    me.add_argument("--window", type=_seconds, default=20.0, metavar="S",
                    help="at max speed, the replay stays at most S of scenario time ahead of the slowest peer (0: off)")
    me.add_argument("--insecure", action="store_true",
                    help="no mTLS, no access control (quick experiments only: anyone can feed the mesh)")
    me.add_argument("--pki", metavar="DIR", help="certificates (default OUT_DIR/pki, made if absent)")
    me.add_argument("--restarts", type=int, default=10, help="restarts per process before giving up on it")
    me.add_argument("--root", help="key-expression root (default saim/<scenario>/<pid>)")
    me.add_argument("--console", type=int, nargs="?", const=8470, default=None, metavar="PORT",
                    help="also start the top unit's commander's console on 127.0.0.1:PORT (default 8470; 0: free)")
    me.add_argument("--tak", nargs="+", metavar="URL",
                    help="also start the Cursor-on-Target gateway sending to these URLs "
                         "(udp://239.2.3.1:6969 for TAK clients on the LAN, tcp://HOST:8087 for a TAK server)")
    me.add_argument("--tak-in", nargs="+", metavar="URL", help="the gateway listens for TAK PLI here (e.g. "
                    "udp://239.2.3.1:6969, tcp://127.0.0.1:PORT)")
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

    ce = sub.add_parser("certs", help="make a test CA and a certificate per identity of a scenario's mesh")
    ce.add_argument("scenario", nargs="?", default=str(DEFAULT_SCENARIO))
    ce.add_argument("--out", default=None, help="where the certificates go (default out/pki; with --deploy: "
                    "the file's pki)")
    ce.add_argument("--units", nargs="+", metavar="UNIT", help="EA identities (default: battalion, companies, platoons)")
    ce.add_argument("--deploy", metavar="TOML", help="a deployment file: the scenario is the file's, and each host's "
                    "addresses and names go into its processes' certificates")
    ce.set_defaults(fn=cmd_certs)

    de = sub.add_parser("deploy", help="the live mesh across hosts: deploy init SCENARIO | deploy FILE --check | "
                                       "deploy FILE --host NAME (docs/deployment.md)")
    de.add_argument("file", metavar="FILE|init", help="a deployment file (TOML), or init to write one")
    de.add_argument("scenario", nargs="?", help="init: the scenario folder")
    de.add_argument("--check", action="store_true",
                    help="say what is wrong with the file, one line each (exit 2), and start nothing; with --host, "
                         "also whether this machine is that host")
    de.add_argument("--host", metavar="NAME", help="run this host's routers, EAs, sources, consoles, TAK gateway")
    de.add_argument("--out-dir", help="alerts, logs, state (default out/deploy/HOST)")
    de.add_argument("--exit-when-done", action="store_true",
                    help="stop once this host's EA peers are done (by default the host runs until stopped: other "
                         "hosts may still need its routers and sources)")
    de.add_argument("--timeout", type=_seconds, default=None, metavar="S", help="stop after S seconds")
    de.add_argument("--quiet", action="store_true", help="do not print alerts as they come")
    de.add_argument("--fresh", action="store_true",
                    help="a clean start: delete the EAs' logs and journals and the sources' state an earlier run left "
                         "in --out-dir (default: a restart keeps them when they are this deployment's)")
    de.add_argument("--restarts", type=int, default=10, help="restarts per process before giving up on it")
    de.add_argument("--console-linger", type=_seconds, default=300.0, metavar="S",
                    help="seconds a console stays up after the scenario's end")
    de.add_argument("--out", metavar="TOML", help="init: the file to write (default deploy-<scenario>.toml)")
    de.add_argument("--addresses", metavar="NET|ADDR[,ADDR...]",
                    help="init: one address per host from a network (198.18.0.0/24: .1, .2, ...), a list, or one "
                         "address for all (ports then differ; default 127.0.0.1: this machine)")
    de.add_argument("--port", type=int, default=7447, help="init: the routers' port (default 7447)")
    de.add_argument("--no-consoles", action="store_true", help="init: no commander's console per host")
    de.add_argument("--insecure", action="store_true", help="init: secure = false (no mTLS, no access control)")
    de.add_argument("--pki", metavar="DIR", help="init: where the certificates will be (default pki/ beside the file)")
    de.set_defaults(fn=cmd_deploy)
    for name, help_, fields in (
            ("ack", "acknowledge an alert: its re-notifications and escalation stop", [
                ("--alert", dict(required=True, help="alert id, <owner>/<n>")), ("--by", dict(default=""))]),
            ("silence", "silence matching alerts until a scenario time (or --lift one)", [
                ("--id", dict(required=True)), ("--types", dict(nargs="*", default=[])),
                ("--subjects", dict(nargs="*", default=[])), ("--areas", dict(nargs="*", default=[])),
                ("--until", dict(type=_seconds, help="scenario time the silence ends")),
                ("--comment", dict(default="")), ("--lift", dict(action="store_true", help="end silence --id"))]),
            ("set", "change a voi.* or voa.* threshold of the EA from its next epoch", [
                ("--key", dict(required=True, help="e.g. voi.out_of_position_m")),
                ("--value", dict(required=True, help="a number or a JSON list of numbers"))]),
            ("confirm", "confirm that a mission started or ended", [
                ("--mission", dict(required=True)), ("--phase", dict(required=True, choices=["start", "end"]))]),
            ("cff", "confirm or cancel a call for fire the EA has seen", [
                ("--cff", dict(required=True)), ("--action", dict(required=True, choices=["confirm", "cancel"]))]),
            ("inhibit", "add an inhibition rule: while a source alert is active, matching target alerts sharing "
                        "the --equal labels are logged marked inhibited_by, not shown (or --lift one)", [
                ("--id", dict(required=True)),
                ("--source-types", dict(nargs="*", default=[])), ("--source-subjects", dict(nargs="*", default=[])),
                ("--source-priorities", dict(nargs="*", default=[],
                                             choices=["flash", "immediate", "priority", "routine"])),
                ("--target-types", dict(nargs="*", default=[])), ("--target-subjects", dict(nargs="*", default=[])),
                ("--target-priorities", dict(nargs="*", default=[],
                                             choices=["flash", "immediate", "priority", "routine"])),
                ("--equal", dict(nargs="*", default=["subjects"], choices=["subjects", "owner", "places", "category"],
                                 help="labels source and target must share (default: subjects)")),
                ("--for", dict(dest="for_s", type=_seconds, default=None,
                               help="scenario seconds a source alert stays active (default: voa.expiry_s)")),
                ("--comment", dict(default="")), ("--lift", dict(action="store_true", help="lift rule --id"))]),
            ("decide", "answer an alert that asks for a decision (threat-ahead: continue, abort, execute:BRANCH)", [
                ("--alert", dict(required=True, help="alert id, <owner>/<n>")),
                ("--option", dict(required=True, help="one of the alert's details.decision.options"))])):
        c = sub.add_parser(name, help=help_)
        c.add_argument("--scenario", required=True)
        c.add_argument("--unit", required=True, help="the unit whose EA takes the command")
        for flag, kw in fields:
            c.add_argument(flag, **kw)
        c.add_argument("--as", dest="as_", metavar="IDENTITY",
                       help="certificate to act as (default console.<unit>, else the top unit's console)")
        c.add_argument("--timeout", type=_seconds, default=10.0, help="seconds to wait for the EA's answer")
        _zenoh_args(c)
        c.set_defaults(fn=cmd_command)
    from . import cli_directives
    cli_directives.add(sub, _zenoh_args, _seconds)   # order, plan: directives to a subtree (issue 33)
    co = sub.add_parser("console", help="the commander's console: a mesh peer serving a web page on 127.0.0.1")
    co.add_argument("scenario")
    co.add_argument("--unit", help="whose commander (default: the top unit); acts for the unit's subtree")
    co.add_argument("--port", type=int, default=8470, help="HTTP port on 127.0.0.1 (0: a free port)")
    co.add_argument("--linger", type=_seconds, default=30.0, help="seconds to stay up after the scenario's end")
    co.add_argument("--sources", action="store_true",
                    help="the live mesh (no replay): draw the sources' frames, the clock from their watermarks")
    _zenoh_args(co)
    co.set_defaults(fn=cmd_console)
    from .tak.gateway import add_arguments as tak_arguments
    tk = sub.add_parser("tak", help="the Cursor-on-Target gateway: the mesh's picture and alerts to TAK, "
                                    "TAK PLI in as location reports (docs/tak.md)")
    tk.add_argument("scenario")
    tak_arguments(tk)
    _zenoh_args(tk)
    tk.set_defaults(fn=cmd_tak)
    from .net.linkemu import add_arguments as link_arguments, cmd_link
    li = sub.add_parser("link", help="an emulated radio link: a TCP proxy on loopback with delay, loss, "
                                     "cut (SIGUSR1) and heal (SIGUSR2)")
    link_arguments(li)
    li.set_defaults(fn=cmd_link)
    rep = sub.add_parser("report", help="a PNG of alerts by type per EA and a timeline by priority")
    rep.add_argument("out", help="the PNG to write")
    rep.add_argument("alerts", nargs="+", help="alert files (JSON lines) or folders of them (a mesh's out dir)")
    rep.add_argument("--title", default="")
    rep.set_defaults(fn=cmd_report)
    a = p.parse_args(argv)
    from ea_agent.core.config import ConfigError
    try:
        return a.fn(a)
    except BrokenPipeError:
        return 0
    except KeyboardInterrupt:
        print("saim-mesh: interrupted", file=sys.stderr)
        return 130
    except (S.ScenarioError, ConfigError) as err:   # they name file, place and field
        return _fail(err)
    except KeyError as err:   # an unknown unit; str() of a KeyError would quote its message
        return _fail(err.args[0] if err.args else err)
    except ValueError as err:   # from a loader that does not name its file: still one line
        return _fail(f"{type(err).__name__}: {err}")
    except OSError as err:   # a file not found or unreadable (--out, --config, ...)
        return _fail(f"{err.filename}: {err.strerror}" if err.filename and err.strerror else err)


if __name__ == "__main__":
    sys.exit(main())
