"""Acknowledge an alert as the unit's commander (saim_mesh.api.Commander).

    python examples/acknowledge.py --connect tcp/127.0.0.1:7447 --unit A2 --alert A2/330.c850"""
import argparse
import json

from saim_mesh.api import Commander

p = argparse.ArgumentParser()
p.add_argument("--scenario", default="scenarios/small")
p.add_argument("--connect", nargs="+", required=True)
p.add_argument("--unit", default="A2")
p.add_argument("--alert", required=True)
p.add_argument("--root")
a = p.parse_args()

with Commander(a.scenario, a.unit, connect=a.connect, root=a.root) as cdr:
    answer = cdr.ack(a.alert)
print(json.dumps(answer))
raise SystemExit(0 if answer["ok"] else 2)
