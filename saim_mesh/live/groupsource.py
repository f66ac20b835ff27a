"""A command post's share of a recorded scenario published by key group (issue 50):
`python -m saim_mesh.live.groupsource SCENARIO --name cp.A --connect EP --root R
[--units U ...] [--but U ...] [--tracks] [--fusion G ...] [--state DIR] [--linger S]`, as
fast as possible. `saim-mesh source` gets the same with a flag once the CLI passes
`groups=grouper(sc, root)` to its `LiveSource` (saim_mesh/cli/mesh.py)."""
from __future__ import annotations

import argparse
import sys

import zenoh
from dissemination.keyspace import KeySpace

from .. import scenario as S
from ..launch.zenoh_config import config
from . import play
from .depend import Share
from .groupframes import grouper
from .source import LiveSource


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="groupsource")
    ap.add_argument("scenario")
    ap.add_argument("--name", required=True)
    ap.add_argument("--connect", action="append", default=[])
    ap.add_argument("--root", required=True)
    ap.add_argument("--units", nargs="*")
    ap.add_argument("--but", nargs="*", default=[])
    ap.add_argument("--tracks", action="store_true")
    ap.add_argument("--fusion")
    ap.add_argument("--state")
    ap.add_argument("--linger", type=float, default=0.0)
    a = ap.parse_args(argv)
    sc = S.load(a.scenario)
    sh = Share((), tracks=True, fusion=a.fusion) if a.fusion else Share(tuple(a.units) if a.units else None,
                                                                       tuple(a.but), a.tracks)
    with zenoh.open(config(None, a.connect, name=f"source.{a.name}", sc=sc, root=a.root)) as s:
        src = LiveSource(s, KeySpace.of(sc, a.root), a.name, a.state, groups=grouper(sc, a.root))
        print(f"ready source {a.name} epoch={src.epoch}", flush=True)
        n = play.publish(src, play.of_share(sc, sh))
        src.close()
        print(f"end source {a.name} messages={n} frames={src.seq} groups={len(src.group_pubs)}", flush=True)
        if a.linger:
            src.linger(a.linger, a.linger)
        src.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
