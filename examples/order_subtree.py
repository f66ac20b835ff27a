"""Order a unit's subtree as its commander (saim_mesh.api.Commander.order): every EA of the
subtree takes the order at the same event time, after the facts before it, and answers.

    python examples/order_subtree.py --mesh out/mesh --unit A --action abort-plan --at 600 --expect A2
    python examples/order_subtree.py --connect tcp/127.0.0.1:7447 --unit A --at 600 --expect A2

Prints each EA's answer (JSON); exit 0 when every EA named in --expect took it."""
import json

from saim_mesh.api import Commander

import common


def main(a) -> int:
    with Commander(a.scenario, a.unit, connect=a.connect, mesh=a.mesh, root=a.root) as cdr:
        print("ordered", flush=True)
        answers = cdr.order(a.action, at=a.at, plan=a.plan, mission=a.mission, expect=a.expect, wait_s=a.wait)
    for unit, answer in sorted(answers.items()):
        print(json.dumps({"unit": unit, **answer}))
    return 0 if all(answers.get(u, {}).get("ok") for u in a.expect) else 2


if __name__ == "__main__":
    p = common.parser("A")
    p.add_argument("--action", default="abort-plan",
                   choices=["execute-plan", "abort-plan", "start-mission", "end-mission"])
    p.add_argument("--plan", default="")
    p.add_argument("--mission", default="")
    p.add_argument("--at", type=float, required=True, help="event time it takes effect (seconds)")
    p.add_argument("--expect", nargs="*", default=[])
    p.add_argument("--wait", type=float, default=60.0, help="seconds to wait for the answers")
    common.run("order_subtree", main, p.parse_args())
