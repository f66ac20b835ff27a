"""Publish one platoon's reports as a live source (saim_mesh.api.Source).

    python examples/publish_reports.py --connect tcp/127.0.0.1:7447 --unit A2

Reads the platoon's positions from the scenario (a real reporter would read its GPS) and
publishes them in event time, with a watermark every 2 s of it: an EA that depends on this
source advances exactly as far as these watermarks promise."""
import argparse
import math

from saim_mesh.api import LocationReport, Source
from saim_mesh.scenario import load

p = argparse.ArgumentParser()
p.add_argument("--scenario", default="scenarios/small")
p.add_argument("--connect", nargs="+", required=True)
p.add_argument("--unit", default="A2")
p.add_argument("--name", default="reporter")
p.add_argument("--root")
a = p.parse_args()

sc = load(a.scenario)
mine = set(sc.taskorg.subtree(a.unit))
reports = [e for e in sc.events if type(e) is LocationReport and sc.taskorg.entity_unit.get(e.entity) in mine]

with Source(sc, a.name, connect=a.connect, root=a.root) as src:
    for r in reports:
        src.watermark(math.ceil(r.t / 2.0) * 2.0 - 2.0)   # everything before this report's epoch is out
        src.report(r.entity, r.lon, r.lat, r.t)
print(f"published {len(reports)} reports of {a.unit}")
