"""`saim-mesh robots` (to register: `robots` -> `saim_mesh.robots.main`): the closed loop's
processes and its driver."""
from __future__ import annotations

import argparse
from pathlib import Path


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="saim-mesh robots", description="robots that obey their EAs over the mesh")
    sub = ap.add_subparsers(dest="cmd", required=True)

    def net(p: argparse.ArgumentParser) -> None:
        p.add_argument("--connect", required=True, help="the router's endpoint (tcp/127.0.0.1:PORT)")
        p.add_argument("--root", required=True)
        p.add_argument("--keys", help="folder of the signing keys and signers.json")
        p.add_argument("--until", type=float, default=None, help="stop at this event time (default: the scenario's end)")
        p.add_argument("--deadline", type=float, default=600.0, help="wall seconds before giving up")

    t = sub.add_parser("team", help="run the robot team on the mesh (hub, one process per robot and per EA)")
    t.add_argument("out", type=Path)
    t.add_argument("--until", type=float, default=None)
    t.add_argument("--mute", nargs="*", default=[], help="EAs that publish no task")
    t.add_argument("--forge", nargs="*", default=[], metavar="UNIT=IDENT",
                   help="UNIT's tasks also published signed by IDENT (refused by the robot)")
    t.add_argument("--seed", type=int, default=7)
    t.add_argument("--timeout", type=float, default=300.0)
    r = sub.add_parser("robot", help="one robot's process")
    r.add_argument("--robot", required=True)
    r.add_argument("--seed", type=int, default=7)
    r.add_argument("--out", required=True, help="the robot's true run (JSON), written at the end")
    net(r)
    e = sub.add_parser("ea", help="one EA's process in the closed loop")
    e.add_argument("--scenario", required=True)
    e.add_argument("--unit", required=True)
    e.add_argument("--robots", nargs="+", required=True)
    e.add_argument("--out", required=True, help="its alerts (JSON lines)")
    e.add_argument("--mute", action="store_true", help="publish watermarks and no task")
    e.add_argument("--forge", default=None, help="also publish every task signed by this identity")
    net(e)
    h = sub.add_parser("hub", help="the loop's router")
    h.add_argument("--listen", required=True)
    a = ap.parse_args(argv)
    if a.cmd == "team":
        from .team import run_team
        forge = dict(x.split("=", 1) for x in a.forge)
        run_team(a.out, a.until, tuple(a.mute), forge, a.seed, a.timeout)
        return 0
    if a.cmd == "robot":
        from .robot import main as m
    elif a.cmd == "ea":
        from .ea import main as m
    else:
        from .hub import main as m
    return m(a)
