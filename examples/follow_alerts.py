"""Follow a unit's alerts as its EA raises them (saim_mesh.api.Alerts).

    python examples/follow_alerts.py --mesh out/mesh --unit A2 --count 3     # beside `saim-mesh mesh up`
    python examples/follow_alerts.py --connect tcp/127.0.0.1:7447 --unit A2  # a lone EA peer"""
import argparse

from saim_mesh.api import Alerts, MeshError


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
    p = argparse.ArgumentParser()
    p.add_argument("--scenario", default="scenarios/small")
    p.add_argument("--mesh", metavar="OUT", help="the output folder of `saim-mesh mesh up` (routers, root, pki)")
    p.add_argument("--connect", nargs="+", help="or an EA peer's endpoints (no routers, not secure)")
    p.add_argument("--root")
    p.add_argument("--unit", default="A2")
    p.add_argument("--priority", nargs="*", default=None, help="only these priorities")
    p.add_argument("--count", type=int, default=3)
    p.add_argument("--timeout", type=float, default=120.0)
    try:
        main(p.parse_args())
    except MeshError as e:
        raise SystemExit(f"follow_alerts: {e}")
