"""Follow a unit's alerts as its EA raises them (saim_mesh.api.Alerts).

    python examples/follow_alerts.py --connect tcp/127.0.0.1:7447 --unit A2 --count 3"""
import argparse

from saim_mesh.api import Alerts

p = argparse.ArgumentParser()
p.add_argument("--scenario", default="scenarios/small")
p.add_argument("--connect", nargs="+", required=True)
p.add_argument("--unit", default="A2")
p.add_argument("--priority", nargs="*", default=None, help="only these priorities")
p.add_argument("--count", type=int, default=3)
p.add_argument("--timeout", type=float, default=120.0)
p.add_argument("--root")
a = p.parse_args()

with Alerts(a.scenario, connect=a.connect, units=[a.unit], priorities=a.priority, root=a.root) as alerts:
    print("following", flush=True)
    for _ in range(a.count):
        al = alerts.get(timeout=a.timeout)
        if al is None:
            raise SystemExit(f"no alert within {a.timeout} s")
        print(f"{al.details['id']} t={al.t:.0f} {al.priority} {al.type}: {al.message}", flush=True)
