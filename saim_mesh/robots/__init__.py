"""Robots that obey their EAs over the mesh (issue 33.5): one process per robot runs its
simulator and carries out the task messages its own EA publishes, signed; one process per
EA monitors the robots' reports and publishes its policy decisions. Closed loop in event
time: a robot steps only as far as its EA has promised its decisions (docs/uv-domain.md).

    python -m saim_mesh.robots team OUT [--until S] [--mute UNIT] [--forge UNIT=IDENT]

`main(argv)` is the entry point (`saim-mesh robots ...` once registered)."""
from __future__ import annotations

from .cli import main

__all__ = ["main"]
