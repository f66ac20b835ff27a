"""`saim-mesh robots` (to register: `robots` -> `saim_mesh.robots.main`): the closed loop's
processes and its driver."""
from __future__ import annotations

import argparse
from pathlib import Path


def parser() -> argparse.ArgumentParser:
    """`saim-mesh robots` and its subcommands (docs/cli.md is generated from it)."""
    ap = argparse.ArgumentParser(prog="saim-mesh robots", description="robots that obey their EAs over the mesh")
    sub = ap.add_subparsers(dest="cmd", required=True)

    def net(p: argparse.ArgumentParser) -> None:
        p.add_argument("--connect", required=True, help="the router's endpoint (tcp/127.0.0.1:PORT)")
        p.add_argument("--root", required=True)
        p.add_argument("--keys", help="folder of the signing keys and signers.json")
        p.add_argument("--until", type=float, default=None,
                       help="stop at this event time (default: the scenario's end)")
        p.add_argument("--deadline", type=float, default=600.0, help="wall seconds before giving up")
        p.add_argument("--pki", default=None, help="secure mode: certificates and keys (robots/secure.py)")
        p.add_argument("--scenario", default=None, help="the scenario folder (its task organization)")

    t = sub.add_parser("team", help="run the robot team on the mesh (hub, one process per robot and per EA)")
    t.add_argument("out", type=Path)
    t.add_argument("--until", type=float, default=None)
    t.add_argument("--mute", nargs="*", default=[], help="EAs that publish no task")
    t.add_argument("--forge", nargs="*", default=[], metavar="UNIT=IDENT",
                   help="UNIT's tasks also published signed by IDENT (refused by the robot)")
    t.add_argument("--seed", type=int, default=7)
    t.add_argument("--timeout", type=float, default=300.0)
    t.add_argument("--insecure", action="store_true", help="plain TCP, no access control (tasks stay signed)")
    r = sub.add_parser("robot", help="one robot's process")
    r.add_argument("--robot", required=True)
    r.add_argument("--seed", type=int, default=7)
    r.add_argument("--out", required=True, help="the robot's true run (JSON), written at the end")
    net(r)
    e = sub.add_parser("ea", help="one EA's process in the closed loop")
    e.add_argument("--unit", required=True)
    e.add_argument("--robots", nargs="+", required=True)
    e.add_argument("--out", required=True, help="its alerts (JSON lines)")
    e.add_argument("--mute", action="store_true", help="publish watermarks and no task")
    e.add_argument("--forge", default=None, help="also publish every task signed by this identity")
    net(e)
    h = sub.add_parser("hub", help="the loop's router")
    h.add_argument("--listen", required=True)
    h.add_argument("--pki", default=None)
    h.add_argument("--scenario", default=None)
    h.add_argument("--root", default=None)
    return ap


def main(argv: list[str] | None = None) -> int:
    a = parser().parse_args(argv)
    if a.cmd == "team":
        from .team import run_team
        forge = dict(x.split("=", 1) for x in a.forge)
        run_team(a.out, a.until, tuple(a.mute), forge, a.seed, a.timeout, secure=not a.insecure)
        return 0
    if a.cmd == "robot":
        from .robot import main as m
    elif a.cmd == "ea":
        from .ea import main as m
    else:
        from .hub import main as m
    return m(a)


def session_config(a, name: str, listen: list[str] | None = None):
    """The process's Zenoh config: secure (mTLS, the loop's access control) with --pki."""
    from ..launch.zenoh_config import config
    if not a.pki:
        return config(listen=listen, connect=[] if listen else [a.connect], mode="router" if listen else "client")
    from .. import scenario as S
    from . import secure
    sc = S.load(a.scenario, events=False)
    robots = sorted(u for u, x in sc.taskorg.units.items() if x.kind in ("ugv", "uav"))
    return secure.config(a.pki, name, a.root, sc.taskorg, robots, connect=None if listen else [a.connect],
                         listen=listen)
