"""`saim-mesh ack | silence | set | confirm | cff | inhibit | decide | console`: a commander acting
on a unit's EA from a script, or from the web console."""
from __future__ import annotations

import argparse
import json

from .. import scenario as S
from .args import _seconds, _zmode, _zenoh_args


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
        from ..protocol import wire as W
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

    from ..authority import commands as C
    from ..scenario import mesh_units
    from ..launch.zenoh_config import config
    sc = S.load(a.scenario, events=False)
    if a.unit not in sc.taskorg.units:
        raise KeyError(f"unknown unit {a.unit!r}: not in the task organization of {sc.name}")
    kind, fields = _command_fields(a)
    cmd = C.make(kind, **fields)
    root = a.root or f"saim/{sc.name}"
    name = a.as_ or (f"console.{a.unit}" if a.unit in mesh_units(sc) else f"console.{sc.taskorg.root}")
    from ..security.sign import signer_for
    conf = config(None, a.connect, a.zenoh_config, a.multicast, a.pki, name, sc, root, **_zmode(a))
    signer = signer_for(conf)   # secure mode: signed as `name`
    with zenoh.open(conf) as session:
        res = C.send(session, KeySpace.of(sc, root), a.unit, cmd, C.by_of(name, a.unit), a.timeout, signer)
    print(json.dumps(C.to_dict(res)))
    return 0 if res.ok else 2


def cmd_console(a) -> int:
    from ..console.main import main_console
    from ..launch.zenoh_config import config
    sc = S.load(a.scenario, events=False)
    unit = a.unit or sc.taskorg.root
    if unit not in sc.taskorg.units:
        raise KeyError(f"unknown unit {unit!r}: not in the task organization of {sc.name}")
    root = a.root or f"saim/{sc.name}"
    conf = config(a.listen, a.connect, a.zenoh_config, a.multicast, a.pki, f"console.{unit}", sc, root, **_zmode(a))
    return main_console(sc, conf, root, unit, a.port, a.linger)


def add(sub) -> None:
    """Register a commander's commands and the console on `sub`."""
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
    co = sub.add_parser("console", help="the commander's console: a mesh peer serving a web page on 127.0.0.1")
    co.add_argument("scenario")
    co.add_argument("--unit", help="whose commander (default: the top unit); acts for the unit's subtree")
    co.add_argument("--port", type=int, default=8470, help="HTTP port on 127.0.0.1 (0: a free port)")
    co.add_argument("--linger", type=_seconds, default=30.0, help="seconds to stay up after the scenario's end")
    _zenoh_args(co)
    co.set_defaults(fn=cmd_console)
