"""`saim-mesh run | evaluate | missions | generate | validate | report`: EAs in one process, scored
against ground truth; scenarios made and checked."""
from __future__ import annotations

import json
import sys
from collections import Counter
from pathlib import Path

from .. import scenario as S
from ..logs.sinks import JsonlSink, TerminalSink
from .args import _speed, _seconds, _progress, DEFAULT_SCENARIO


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

    from ..inprocess.runner import config_for, default_eas, run
    sc = S.load(a.scenario)
    owners = a.ea or default_eas(sc)
    for o in owners:   # every bad input is reported before anything runs or is written
        if o not in sc.taskorg.units:
            raise KeyError(f"--ea {o}: unknown unit {o!r}: not in the task organization of {sc.name} "
                           f"({sc.root / 'plan.json'})")
        config_for(sc, o, a.config)
    from ..logs.cmdlog import read as read_commands
    cmds = read_commands(a.commands, set(sc.taskorg.units)) if a.commands else None
    sinks = [] if a.quiet else [TerminalSink()]
    out = open(a.out, "w", buffering=1) if a.out else None   # line-buffered; JsonlSink flushes each alert
    notice_sinks: list = []
    if out:
        sinks.append(JsonlSink(out))
        from ..logs.noticelog import NoticeLog, path_for
        nlog = NoticeLog(path_for(a.out))   # re-notifications and escalations, beside the alerts
        notice_sinks.append(nlog)
    try:
        consoles: list = []
        if a.console is not None:
            from ..console.main import start_inprocess
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
    from ..inprocess.evaluate import evaluate
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
                  f"/commander/hour ({c['shown_over_unwatched_worst']}x the unwatched run; "
                  f"{c['notices_dropped']} notices held back), unwanted {c['unwanted_share']:.1%}, "
                  f"unwanted flash {c['unwanted_flash']}, "
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

    from ..inprocess.runner import config_for, default_eas, make_ea
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


def cmd_report(a) -> int:
    from ..inprocess.report import main_report
    return main_report(a.out, a.alerts, a.title)


def add(sub) -> None:
    """Register the offline commands on `sub` (the CLI's subparsers)."""
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
    rep = sub.add_parser("report", help="a PNG of alerts by type per EA and a timeline by priority")
    rep.add_argument("out", help="the PNG to write")
    rep.add_argument("alerts", nargs="+", help="alert files (JSON lines) or folders of them (a mesh's out dir)")
    rep.add_argument("--title", default="")
    rep.set_defaults(fn=cmd_report)
