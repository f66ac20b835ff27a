"""What every example takes to reach a mesh, in one place (as zenoh-python's examples/common.py)."""
import argparse

from saim_mesh.api import MeshError


def parser(unit: str) -> argparse.ArgumentParser:
    """A parser with the mesh options every example takes; `unit` is its default unit."""
    p = argparse.ArgumentParser()
    p.add_argument("--scenario", default="scenarios/small")
    p.add_argument("--mesh", metavar="OUT", help="the output folder of `saim-mesh mesh up` (routers, root, pki)")
    p.add_argument("--connect", nargs="+", help="or an EA peer's endpoints (no routers, not secure)")
    p.add_argument("--root")
    p.add_argument("--unit", default=unit)
    return p


def run(name: str, main, args) -> None:
    """`main(args)` as the program: its return value the exit code, a MeshError one line."""
    try:
        raise SystemExit(main(args))
    except MeshError as e:
        raise SystemExit(f"{name}: {e}")
