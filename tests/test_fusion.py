"""Forward fusion and adjudication."""
from __future__ import annotations

import random

import numpy as np

from saim_mesh import scenario as S
from ea_agent.core.adjudication import Adjudicator, Report
from saim_mesh.inprocess.evaluate import evaluate
from saim_mesh.fusion import FusionNode
from ea_agent.core.geo import Projection
from saim_mesh.protocol.messages import SensorHit

from .conftest import ROOT
from .test_evaluate import check_projections

SMALL_SENSORS = ROOT / "scenarios" / "small-sensors"


def test_adjudication_is_independent_of_arrival_order():
    reps = []
    for t in range(0, 60, 10):
        reps += [Report(t, "N", "N-1", 1000 + t, 5000, 5, 0.0, 0.0), Report(t + 1, "F", "F-7", 1100 + t, 5050, 6, 0.0, 0.0),
                 Report(t, "N", "N-2", 9000, 9000 - t, 3, 0.0, 0.0), Report(t + 2, "F", "F-9", 20000, 1, 4, 0.0, 0.0)]
    reps.append(Report(70, "F", "F-9", 20000, 1, 0, 0.0, 0.0))     # F-9 dropped at the end
    pictures = set()
    for seed in range(25):
        random.Random(seed).shuffle(reps)
        adj = Adjudicator()
        for r in reps:
            adj.update(r)
        pictures.add(tuple(sorted(adj.picture().items())))
    assert len(pictures) == 1
    pic = dict(next(iter(pictures)))
    assert set(pic) == {"F-7", "N-2"}                  # N-1 and F-7 are one entity; F-9 is gone
    assert pic["F-7"].strength == 6 and pic["F-7"].members == ("F/F-7", "N/N-1") and pic["F-7"].t == 51


def test_same_source_tracks_are_never_merged():
    adj = Adjudicator()
    adj.update(Report(1, "N", "N-1", 0, 0, 4, 0, 0))
    adj.update(Report(1, "N", "N-2", 100, 0, 4, 0, 0))
    assert set(adj.picture()) == {"N-1", "N-2"}


def test_fusion_node_tracks_a_group_and_ignores_false_alarms():
    proj = Projection(32611)
    x0, y0 = 540_000.0, 3_900_000.0
    node = FusionNode("N", proj)
    rng = np.random.default_rng(1)
    out = []
    for k in range(40):
        t = 1.0 + 5 * k
        cx, cy = x0 + 3.0 * (t - 1), y0
        pts = [(cx + ex + rng.normal(0, 25), cy + ey + rng.normal(0, 25))
               for ex, ey in rng.uniform(-60, 60, (6, 2)) if rng.random() < 0.85]
        pts += [(x0 + rng.uniform(-3000, 3000), y0 + rng.uniform(-3000, 3000))]      # one false alarm a scan
        for x, y in pts:
            lon, lat = proj.to_lonlat(x, y)
            out += node.add(SensorHit(t, "G1", float(lon), float(lat)))
    out += node.flush(205.0)
    live = {r.track for r in out if r.strength > 0}
    assert len(live) == 1, live                       # one confirmed track, no false ones
    last = [r for r in out if r.strength > 0][-1]
    x, y = proj.to_xy(last.lon, last.lat)
    assert abs(x - (x0 + 3.0 * (last.t - 1))) < 60 and abs(y - y0) < 60
    assert 5 <= last.strength <= 6 and 2.0 < last.speed < 4.0 and 45 < last.heading < 135


def test_battalion_with_sensors_meets_targets():
    res = evaluate(S.load(ROOT / "scenarios" / "battalion-sensors"))
    assert res["recall"] == 1.0, res["missed"]
    assert res["unwanted_share"] <= 0.05 and res["unwanted_flash"] == 0
    check_projections(res)
