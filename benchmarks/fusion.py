"""Fusion benchmark: hits in, track reports out (the bandwidth saved), position error,
tracks per true object, identity changes and hits/s, for the scan-window averager, the
Kalman tracker and Stone Soup's standard multi-target tracker (constant-velocity Kalman,
Mahalanobis gating, global nearest neighbour, multi-measurement initiation) on the same
hits: the battalion with sensors and four data sets it lacks (lone vehicles, aircraft,
crossing paths, slow aircraft that orbit and turn hard). Writes bench/results/fusion.json.
Stone Soup's process noise is set by the data set's class (0.5 m^2/s^3 for ground
movers, 40 for aircraft); on the smaller data sets it is also run over a grid of
process noises (`stonesoup_q_grid`), so that its best setting is on record beside the
one compared. Stone Soup is a benchmark-only
dependency (`pip install stonesoup`); without it the reference is left out, saying so.
hits/s is per CPU second of the tracker's own loop (process time, the same for every
tracker: the machine's load moves wall time), the input's preparation left out of each."""
from __future__ import annotations

import argparse
import json
import math
import time
from collections import defaultdict
from datetime import datetime, timedelta
from pathlib import Path

import numpy as np

from saim_mesh import scenario as scenarios
from saim_mesh.fusion.datasets import DATASETS, DataSet
from saim_mesh.fusion.tracker import KalmanTracker

from . import ROOT

SS_Q = {"ground": 0.5, "air": 40.0}          # Stone Soup's process noise by the data set's class
SS_GRID = (0.1, 0.5, 2.0, 10.0, 40.0, 200.0, 1000.0)
EPOCH = datetime(2026, 1, 1)


# -- trackers on (t, sensor, x, y) scans ----------------------------------------------------
def scans(hits) -> list[tuple[float, str, np.ndarray, np.ndarray | None]]:
    """(t, sensor, hits k x 2, their heights or None where the sensor gives none) per scan."""
    out: dict[tuple[float, str], list] = defaultdict(list)
    for h in hits:
        out[(h.t, h.sensor)].append((h.x, h.y, np.nan if h.alt is None else h.alt))
    res = []
    for (t, s), v in sorted(out.items()):
        a = np.array(v)
        res.append((t, s, a[:, :2], a[:, 2] if np.isfinite(a[:, 2]).any() else None))
    return res


def feed_scans(tr: KalmanTracker, scans: list[tuple], window_s: float) -> list:
    """Every report the tracker makes of the scans, its windows closed on their event time."""
    reps, end = [], window_s
    for t, s, z, alt in scans:
        while t >= end:
            reps += tr.close_window(end)
            end += window_s
        tr.scan(t, s, z, alt)
    reps += tr.close_window(end)
    return reps


def run_kalman(ds: DataSet, window_s: float = 5.0) -> tuple[list[tuple], float]:
    tr = KalmanTracker("K", ds.sigma, window_s=window_s)
    sc = scans(ds.hits)
    t0 = time.process_time()
    reps = feed_scans(tr, sc, window_s)
    dt = time.process_time() - t0
    return [(r.t, r.track, r.x, r.y, r.vx, r.vy) for r in reps if r.strength > 0], len(ds.hits) / dt


def run_window(ds: DataSet) -> tuple[list[tuple], float]:
    """The averager (node.py) needs lon/lat: an identity-like projection stands in."""
    from saim_mesh.fusion.node import FusionNode
    from saim_mesh.protocol.messages import SensorHit

    class Flat:   # metres as 'degrees': the averager only projects and unprojects
        def to_xy(self, lon, lat):
            return lon, lat

        def to_lonlat(self, x, y):
            return x, y
    node = FusionNode("W", Flat())
    hits = [SensorHit(h.t, h.sensor, h.x, h.y) for h in ds.hits]
    t0 = time.process_time()
    reps = []
    for h in hits:
        reps += node.add(h)
    reps += node.flush(ds.duration_s)
    dt = time.process_time() - t0
    return [(r.t, r.track, r.lon, r.lat) for r in reps if r.strength > 0], len(hits) / dt


def run_stonesoup(ds: DataSet, q: float = 0.5, gate: float = 4.0, min_points: int = 3,
                  delete_s: float = 35.0, v0: float = 100.0) -> tuple[list[tuple], float]:
    from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
    from stonesoup.deleter.time import UpdateTimeDeleter
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.initiator.simple import MultiMeasurementInitiator
    from stonesoup.measures import Mahalanobis
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel, ConstantVelocity
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.detection import Detection
    from stonesoup.types.state import GaussianState
    from stonesoup.updater.kalman import KalmanUpdater

    trans = CombinedLinearGaussianTransitionModel([ConstantVelocity(q), ConstantVelocity(q)])
    models = {s: LinearGaussian(4, (0, 2), np.diag([sg ** 2, sg ** 2])) for s, sg in ds.sigma.items()}
    default = next(iter(models.values()))
    predictor, updater = KalmanPredictor(trans), KalmanUpdater(default)
    hyp = DistanceHypothesiser(predictor, updater, Mahalanobis(), missed_distance=gate)
    assoc = GNNWith2DAssignment(hyp)
    deleter = UpdateTimeDeleter(timedelta(seconds=delete_s))
    prior = GaussianState(np.zeros((4, 1)), np.diag([0.0, v0 ** 2, 0.0, v0 ** 2]))
    initiator = MultiMeasurementInitiator(prior, deleter, assoc, updater, default, min_points=min_points)
    frames: dict[float, set] = defaultdict(set)
    for h in ds.hits:
        frames[h.t].add(Detection(np.array([[h.x], [h.y]]), timestamp=EPOCH + timedelta(seconds=h.t),
                                  measurement_model=models[h.sensor]))
    tracks: set = set()
    reps = []
    t0 = time.process_time()
    for t in sorted(frames):   # MultiTargetTracker's own loop, written out to read each frame's updates
        when, dets = EPOCH + timedelta(seconds=t), frames[t]
        hyps = assoc.associate(tracks, dets, when)
        used = set()
        for track, h in hyps.items():
            if h:
                track.append(updater.update(h))
                used.add(h.measurement)
                sv = track.state_vector
                reps.append((t, id(track), float(sv[0, 0]), float(sv[2, 0])))
            else:
                track.append(h.prediction)
        tracks -= deleter.delete_tracks(tracks)
        tracks |= initiator.initiate(dets - used, when)
    dt = time.process_time() - t0
    names = {}
    return [(t, names.setdefault(k, f"S-{len(names) + 1}"), x, y) for t, k, x, y in reps], len(ds.hits) / dt


# -- scoring ----------------------------------------------------------------------------
def nearest(ds: DataSet, t: float, x: float, y: float) -> tuple[str | None, float]:
    best, bd = None, math.inf
    for tid, path in ds.truths.items():
        p = path(t)
        if p is not None and (d := math.hypot(p[0] - x, p[1] - y)) < bd:
            best, bd = tid, d
    return best, bd


def dead_reckoned(ds: DataSet, reps: list[tuple], step: float = 5.0, assoc_m: float = 500.0,
                  extrapolate_s: float = 60.0) -> float | None:
    """RMSE of what a receiver holds between reports: the last report moved on by its
    velocity (as the EAs do, for at most `extrapolate_s`), every `step` s until the next."""
    by: dict[str, list[tuple]] = defaultdict(list)
    for r in reps:
        by[r[1]].append(r)
    errs = []
    for rs in by.values():
        rs.sort()
        for a, b in zip(rs, rs[1:] + [None]):
            end = b[0] if b is not None else a[0] + step
            t = a[0]
            while t < end:
                dt = min(t - a[0], extrapolate_s)
                _, d = nearest(ds, t, a[2] + a[4] * dt, a[3] + a[5] * dt)
                if d <= assoc_m:
                    errs.append(d)
                t += step
    return round(float(np.sqrt(np.mean(np.square(errs)))), 1) if errs else None


def score(ds: DataSet, reps: list[tuple], hits_per_s: float, assoc_m: float = 500.0) -> dict:
    errs, false = [], 0
    seq: dict[str, list[tuple[float, str]]] = defaultdict(list)
    for t, trk, x, y, *_ in reps:
        best, bd = nearest(ds, t, x, y)
        if bd > assoc_m:
            false += 1
            continue
        errs.append(bd)
        seq[best].append((t, trk))
    changes = sum(sum(1 for a, b in zip(v, v[1:]) if a[1] != b[1]) for v in (sorted(x) for x in seq.values()))
    return {"reports": len(reps), "hits_per_report": round(len(ds.hits) / max(1, len(reps)), 2),
            "rmse_m": round(float(np.sqrt(np.mean(np.square(errs)))), 1) if errs else None,
            "tracks_per_truth": round(float(np.mean([len({k for _, k in seq.get(t, [])}) for t in ds.truths])), 2),
            "id_changes": changes, "false_reports": false,
            "missed_truths": sorted(t for t in ds.truths if t not in seq), "hits_per_s": round(hits_per_s)}


def battalion(path: Path) -> tuple[DataSet, dict]:
    """The battalion-with-sensors hits as a data set in metres, its truths the hostile
    groups' true centres (the simulator's), each group one object."""
    from ea_agent.domains.suo.generator import ORIGIN_LONLAT, build_sim
    from saim_mesh.protocol.messages import SensorHit
    sc = scenarios.load(path)
    g = sc.meta["generator"]
    sim = build_sim(g["small"], g["seed"])
    ox, oy = sc.projection.to_xy(*ORIGIN_LONLAT)
    hs = [e for e in sc.events if type(e) is SensorHit]
    x, y = sc.projection.to_xy(np.array([h.lon for h in hs]), np.array([h.lat for h in hs]))
    from saim_mesh.fusion.datasets import Hit
    hits = [Hit(h.t, h.sensor, float(a) - ox, float(b) - oy, None) for h, a, b in zip(hs, x, y)]
    truths = {k: (lambda t, h=h: h.pos(t)) for k, h in sim.hostiles.items()}
    sigma = {s["id"]: float(s["sigma_m"]) for s in sc.meta["fusion"]["sensors"]}
    return DataSet("battalion", truths, hits, sigma, sc.duration_s, {k: "ground" for k in truths}), sc.meta["fusion"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--scenario", default=str(ROOT / "scenarios" / "battalion-sensors"))
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "fusion.json"))
    ap.add_argument("--no-stonesoup", action="store_true")
    ap.add_argument("--no-grid", action="store_true", help="skip Stone Soup's process-noise grid")
    a = ap.parse_args(argv)
    sets = [battalion(Path(a.scenario))[0], *(f() for f in DATASETS.values())]
    try:
        import stonesoup  # noqa: F401
        have_ss = not a.no_stonesoup
    except ImportError:
        have_ss = False
    out: dict = {"stonesoup": have_ss, "data_sets": {}}
    for ds in sets:
        kal = run_kalman(ds)
        row = {"hits_in": len(ds.hits), "truths": len(ds.truths),
               "kalman": {**score(ds, *kal), "rmse_dead_reckoned_m": dead_reckoned(ds, kal[0])},
               "window": score(ds, *run_window(ds))}
        if have_ss:
            q = SS_Q["air"] if set(ds.domain.values()) == {"air"} else SS_Q["ground"]
            row["stonesoup"] = {"q": q, **score(ds, *run_stonesoup(ds, q=q))}
            if ds.name != "battalion" and not a.no_grid:   # the battalion's run alone takes minutes
                row["stonesoup_q_grid"] = {}
                for gq in SS_GRID:
                    g = score(ds, *run_stonesoup(ds, q=gq))
                    row["stonesoup_q_grid"][str(gq)] = {k: g[k] for k in ("rmse_m", "tracks_per_truth", "id_changes")}
            k, s_ = row["kalman"], row["stonesoup"]
            row["kalman_vs_stonesoup"] = {
                "rmse_ratio": round(k["rmse_m"] / s_["rmse_m"], 3) if k["rmse_m"] and s_["rmse_m"] else None,
                "speed_ratio": round(k["hits_per_s"] / max(1, s_["hits_per_s"]), 1)}
        out["data_sets"][ds.name] = row
        print(ds.name, json.dumps({k: v for k, v in row.items() if k != "window"}), flush=True)
    out["note"] = ("hits_per_s: hits per CPU second of each tracker's loop; errors are to the true object's "
                   "centre (a battalion hostile is a group); Kalman reports are "
                   "dead-reckoned (sent when the receivers' extrapolation, now or 2.5 s ahead, errs by more than the "
                   "track's threshold: k x its own position sigma + 0.1 s of its speed, k = 3 on the ground with a "
                   "40 m floor, 4 in the air; or on a strength or domain change, or every 60 s): rmse_m is the "
                   "reports' own error, rmse_dead_reckoned_m what receivers hold every 5 s between them; the "
                   "window averager works in metres here through an identity projection; Stone Soup gets the same "
                   "hits, one frame per scan time, q=0.5 for ground data sets and 40 for air ones (stonesoup.q; "
                   "stonesoup_q_grid: its RMSE, tracks per truth and id changes at other q), gate 4 sigma, 3 points "
                   "to initiate, 35 s to delete; the orbit data set's radars give heights (the Kalman tracker's "
                   "motion model uses them; Stone Soup's tracks are 2D like the error)")
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
