"""`python -m saim_mesh.tak SCENARIO --connect ... --cot-url ...`."""
from __future__ import annotations

import argparse
import sys

from .options import add_arguments


def main(argv: list[str] | None = None) -> int:
    """`python -m saim_mesh.tak SCENARIO ...`: the same gateway before the CLI wires
    `saim-mesh tak` (no --pki: the `tak` identity's certificate and rules come with it)."""
    from .. import scenario as S
    from ..launch.zenoh_config import config
    from .gateway import main_tak
    ap = argparse.ArgumentParser(prog="python -m saim_mesh.tak", description="the Cursor-on-Target gateway as a Zenoh peer")
    ap.add_argument("scenario")
    ap.add_argument("--listen", nargs="*", metavar="ENDPOINT")
    ap.add_argument("--connect", nargs="*", metavar="ENDPOINT")
    ap.add_argument("--zenoh-config", metavar="JSON5")
    ap.add_argument("--multicast", action="store_true")
    ap.add_argument("--root")
    add_arguments(ap)
    a = ap.parse_args(argv)
    sc = S.load(a.scenario, events=False)
    root = a.root or f"saim/{sc.name}"
    return main_tak(sc, config(a.listen, a.connect, a.zenoh_config, a.multicast, None, None, sc, root), root, a)


if __name__ == "__main__":
    sys.exit(main())
