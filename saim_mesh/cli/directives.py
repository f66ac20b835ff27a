"""`saim-mesh order` and `saim-mesh plan`: a commander's directives to its subtree over the
live mesh (saim_mesh/authority/directives.py), a thin layer over `api.Commander`. Each prints the
answers of the EAs that took or refused it (JSON lines) and exits 0 when every EA named
in --expect took it, 2 otherwise."""
from __future__ import annotations

import json
import sys


def add(sub, zenoh_args, seconds) -> None:
    """Register the two subcommands on `sub` (the CLI's subparsers)."""
    o = sub.add_parser("order", help="order a unit's subtree on the mesh (execute-plan, abort-plan, "
                                     "start-mission, end-mission, reorganize, decide), effective at an event time")
    _common(o, seconds)
    o.add_argument("--action", required=True, choices=list(ACTION_ARGS))
    o.add_argument("--plan", default="", help="execute-plan: the plan's name")
    o.add_argument("--mission", default="", help="start-mission, end-mission, decide: the mission's id")
    o.add_argument("--target", default="", help="reorganize: the unit put under --new-parent")
    o.add_argument("--new-parent", default="", help="reorganize: its new superior (in --unit's subtree)")
    o.add_argument("--alert", default="", help="decide: the alert that asked for a decision (e.g. A1/3)")
    o.add_argument("--option", default="", help="decide: abort, continue or branch:<id>")
    zenoh_args(o)
    o.set_defaults(fn=cmd_order)
    p = sub.add_parser("plan", help="publish a new plan version for a unit's subtree on the mesh: "
                                    "validated by each EA like a plan file, executed at an event time")
    _common(p, seconds)
    p.add_argument("--name", required=True, help="the plan's name (executed as NAME.vVERSION)")
    p.add_argument("--version", type=int, required=True)
    p.add_argument("--file", required=True, help="a JSON list of missions, as plan.json's plans lists them")
    zenoh_args(p)
    p.set_defaults(fn=cmd_plan)


# what each action of `order` reads; anything else given is refused, never ignored
ACTION_ARGS = {"execute-plan": ("plan",), "abort-plan": (), "start-mission": ("mission",),
               "end-mission": ("mission",), "reorganize": ("target", "new_parent"),
               "decide": ("alert", "mission", "option")}
ORDER_ARGS = tuple(dict.fromkeys(n for used in ACTION_ARGS.values() for n in used))


def _flag(name: str) -> str:
    return "--" + name.replace("_", "-")


def _common(p, seconds) -> None:
    p.add_argument("--scenario", required=True)
    p.add_argument("--unit", required=True, help="the commander's unit (identity console.<unit>)")
    p.add_argument("--at", type=seconds, required=True, help="event time it takes effect (s or H+hh:mm:ss)")
    p.add_argument("--expect", nargs="*", default=[], metavar="UNIT",
                   help="wait for these EAs' answers (they answer when their event time reaches --at)")
    p.add_argument("--timeout", type=seconds, default=10.0, help="seconds to wait for the answers")


def _commander(a):
    from ..api import Commander
    if a.listen or a.zenoh_config or a.multicast:
        raise ValueError("order/plan: give --connect ENDPOINT (a router or peer of the mesh); "
                         "--listen, --zenoh-config and --multicast are not used here")
    return Commander(a.scenario, a.unit, connect=a.connect or None, root=a.root, pki=a.pki, timeout=a.timeout)


def _report(got: dict[str, dict], expect: list[str]) -> int:
    for unit, res in sorted(got.items()):
        print(json.dumps({"unit": unit, **res}, sort_keys=True))
    missing = [u for u in expect if u not in got]
    if missing:
        print(f"no answer from {', '.join(missing)} within the timeout", file=sys.stderr)
    refused = [u for u in expect if u in got and not got[u].get("ok")]
    return 2 if missing or refused else 0


def cmd_order(a) -> int:
    used = ACTION_ARGS[a.action]
    extra = [_flag(n) for n in ORDER_ARGS if getattr(a, n) and n not in used]
    if extra:
        raise ValueError(f"order --action {a.action}: {', '.join(extra)} not used by this action "
                         f"(it reads {', '.join(map(_flag, used)) or 'nothing more'})")
    missing = [_flag(n) for n in used if not getattr(a, n)]
    if missing:
        raise ValueError(f"order --action {a.action}: {', '.join(missing)} required")
    with _commander(a) as c:
        try:
            if a.action == "reorganize":
                got = c.reorganize(a.target, a.new_parent, at=a.at, expect=a.expect)
            elif a.action == "decide":
                got = c.decision(a.alert, a.mission, a.option, at=a.at, expect=a.expect)
            else:
                got = c.order(a.action, at=a.at, plan=a.plan, mission=a.mission, expect=a.expect)
        except TimeoutError as e:
            print(f"order: {e}", file=sys.stderr)
            return 2
        return _report(got, a.expect)


def cmd_plan(a) -> int:
    try:
        with open(a.file, encoding="utf-8") as f:
            missions = json.load(f)
    except (OSError, ValueError) as e:
        raise ValueError(f"plan: --file {a.file}: {getattr(e, 'strerror', None) or e}") from None
    if not isinstance(missions, list):
        raise ValueError(f"plan: --file {a.file}: expected a JSON list of missions")
    with _commander(a) as c:
        try:
            got = c.publish_plan(a.name, a.version, missions, at=a.at, expect=a.expect)
        except TimeoutError as e:
            print(f"plan: {e}", file=sys.stderr)
            return 2
        return _report(got, a.expect)
