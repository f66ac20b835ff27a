"""Acknowledge an alert as the unit's commander (saim_mesh.api.Commander).

    python examples/acknowledge.py --mesh out/mesh --unit A2 --alert A2/330.c850
    python examples/acknowledge.py --connect tcp/127.0.0.1:7447 --unit A2 --alert A2/330.c850

Prints the EA's answer (JSON); exit 0 when it took the acknowledgement, else 2."""
import json

from saim_mesh.api import Commander

import common


def main(a) -> int:
    with Commander(a.scenario, a.unit, connect=a.connect, mesh=a.mesh, root=a.root) as cdr:
        answer = cdr.ack(a.alert)
    print(json.dumps(answer))
    return 0 if answer["ok"] else 2


if __name__ == "__main__":
    p = common.parser("A2")
    p.add_argument("--alert", required=True)
    common.run("acknowledge", main, p.parse_args())
