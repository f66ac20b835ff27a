"""Publish one platoon's reports as a live source (saim_mesh.api.Source).

    python examples/publish_reports.py --mesh out/mesh --unit A2 --name cp.A2
    python examples/publish_reports.py --connect tcp/127.0.0.1:7447 --unit A2 --name reporter

Reads the platoon's positions from the scenario (a real reporter would read its GPS) and
publishes them in event time, with a watermark every 2 s of it: an EA that depends on this
source (`saim-mesh peer --sources NAME`) advances exactly as far as these watermarks promise.
On a secure mesh the certificates know the command posts' sources: name it cp.<UNIT>."""
import math

from saim_mesh.api import LocationReport, Source
from saim_mesh.scenario import load

import common


def main(a) -> None:
    sc = load(a.scenario)
    mine = set(sc.taskorg.subtree(a.unit))
    reports = [e for e in sc.events if type(e) is LocationReport and sc.taskorg.entity_unit.get(e.entity) in mine]
    with Source(sc, a.name, connect=a.connect, mesh=a.mesh, root=a.root) as src:
        for r in reports:
            src.watermark(math.ceil(r.t / 2.0) * 2.0 - 2.0)   # everything before this report's epoch is out
            src.report(r.entity, r.lon, r.lat, r.t)
    print(f"published {len(reports)} reports of {a.unit}")


if __name__ == "__main__":
    p = common.parser("A2")
    p.add_argument("--name", default="reporter")
    common.run("publish_reports", main, p.parse_args())
