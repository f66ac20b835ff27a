"""Follow a unit's alerts as its EA raises them (saim_mesh.api.Alerts).

    python examples/follow_alerts.py --mesh out/mesh --unit A2 --count 3     # beside `saim-mesh mesh up`
    python examples/follow_alerts.py --connect tcp/127.0.0.1:7447 --unit A2  # a lone EA peer"""

from saim_mesh.api import Alerts

import common


def main(a) -> None:
    with Alerts(a.scenario, connect=a.connect, mesh=a.mesh, root=a.root, units=[a.unit],
                priorities=a.priority) as alerts:
        print("following", flush=True)
        for _ in range(a.count):
            al = alerts.get(timeout=a.timeout)
            if al is None:
                raise SystemExit(f"no alert within {a.timeout} s")
            print(f"{al.details['id']} t={al.t:.0f} {al.priority} {al.type}: {al.message}", flush=True)


if __name__ == "__main__":
    p = common.parser("A2")
    p.add_argument("--priority", nargs="*", default=None, help="only these priorities")
    p.add_argument("--count", type=int, default=3)
    p.add_argument("--timeout", type=float, default=120.0)
    common.run("follow_alerts", main, p.parse_args())
